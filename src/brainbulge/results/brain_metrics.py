"""Clinical metrics of the 3D brain (MODEL.md sections 3 and 6) from nodal arrays.

Pure numpy on a linear tet mesh: reference nodes ``X`` (n, 3) in mm, tets (m, 4), nodal
displacements ``u`` (n, 3) in mm; the deformed position is ``x = X + u`` and each tet maps
affinely (P1 geometry). No solver is needed, so these functions are tested on meshes with
prescribed displacements.

- :func:`midline_shift_mm`: largest lateral displacement of tissue that starts on the
  mid-sagittal plane, signed (positive towards the patient's right, +x in RAS).
- :func:`bulge_volume_ml`: tissue volume outside the intact skull in the deformed configuration.
- :func:`brain_volume_ml`, :func:`swelling_volume_ml`, :func:`prescribed_swelling_volume_ml`.

1 ml = 1000 mm^3.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache
from typing import TYPE_CHECKING

import numpy as np

from brainbulge.geometry.brain.tetmesh import tet_volumes_mm3

if TYPE_CHECKING:
    from brainbulge.geometry.brain import MidSagittalPlane

MM3_PER_ML = 1000.0

# Approximate position of the foramen of Monro (interventricular foramen) in MNI space (mm) for
# the ICBM152 template: midline, just behind the anterior commissure, ~12 mm above the AC-PC
# line. Good to a few mm; only meaningful for meshes in MNI coordinates (the default template).
MONRO_MNI_MM: tuple[float, float, float] = (0.0, -2.0, 12.0)


def monro_z_range_mm(half_width_mm: float = 5.0,
                     monro_mm: tuple[float, float, float] = MONRO_MNI_MM) -> tuple[float, float]:
    """The band ``z_monro +- half_width_mm`` (mm) for :func:`midline_shift_mm` at the level of
    the foramen of Monro."""
    z = float(monro_mm[2])
    return (z - half_width_mm, z + half_width_mm)


def midline_shift_mm(
    nodes_mm: np.ndarray,
    u_mm: np.ndarray,
    plane: MidSagittalPlane,
    tol_mm: float = 1.0,
    region_mask: np.ndarray | None = None,
    z_range_mm: tuple[float, float] | None = None,
) -> dict:
    """Largest lateral displacement of the tissue that starts on the mid-sagittal plane (mm).

    With ``n`` the plane's unit normal (towards the patient's right) and ``p`` its point, the
    midline nodes are those with ``|(X - p) . n| <= tol_mm`` in the reference configuration,
    optionally also in ``region_mask`` (bool per node, e.g. parenchyma nodes) and with
    ``z_range_mm[0] <= X_z <= z_range_mm[1]``. Their lateral displacement is ``d = u . n`` and
    the shift is the ``d`` of largest ``|d|``, so it is signed: positive towards the right.

    Returns ``{"midline_shift_mm": float, "midline_shift_point_mm": [x, y, z] (reference
    position of that node), "midline_nodes": int}``; with no midline node the shift is ``nan``
    and the point ``None``.
    """
    X = np.asarray(nodes_mm, dtype=float)
    u = np.asarray(u_mm, dtype=float)
    n = np.asarray(plane.normal, dtype=float)
    n = n / np.linalg.norm(n)
    on_plane = np.abs((X - np.asarray(plane.point_mm, dtype=float)) @ n) <= tol_mm
    if region_mask is not None:
        on_plane &= np.asarray(region_mask, dtype=bool)
    if z_range_mm is not None:
        on_plane &= (X[:, 2] >= z_range_mm[0]) & (X[:, 2] <= z_range_mm[1])
    idx = np.flatnonzero(on_plane)
    if idx.size == 0:
        return {"midline_shift_mm": float("nan"), "midline_shift_point_mm": None,
                "midline_nodes": 0}
    d = u[idx] @ n
    k = int(np.argmax(np.abs(d)))
    return {"midline_shift_mm": float(d[k]),
            "midline_shift_point_mm": [float(c) for c in X[idx[k]]],
            "midline_nodes": int(idx.size)}


def brain_volume_ml(nodes_mm: np.ndarray, tets: np.ndarray,
                    u_mm: np.ndarray | None = None) -> float:
    """Volume of the mesh (ml), deformed by ``u_mm`` if given: ``sum_e s_e V_e(X + u) / 1000``
    with ``s_e`` the sign of the reference volume, so a mesh of mixed orientation counts
    positive and an inverted element counts negative."""
    return float(_oriented_volumes_mm3(nodes_mm, tets, u_mm).sum() / MM3_PER_ML)


def swelling_volume_ml(nodes_mm: np.ndarray, tets: np.ndarray, u_mm: np.ndarray,
                       mask_tets: np.ndarray) -> float:
    """Volume added to the swelling region (ml): ``sum_{e in mask} (v_e - V_e) / 1000``, the
    deformed minus the reference volume of the masked tets (bool or index array)."""
    t = np.asarray(tets)[np.asarray(mask_tets)]
    dv = _oriented_volumes_mm3(nodes_mm, t, u_mm) - _oriented_volumes_mm3(nodes_mm, t, None)
    return float(dv.sum() / MM3_PER_ML)


def prescribed_swelling_volume_ml(nodes_mm: np.ndarray, tets: np.ndarray,
                                  js_tets: np.ndarray) -> float:
    """The growth volume of MODEL.md section 3, ``sum_e (Js_e - 1) V_e / 1000`` (ml), with
    ``Js`` per tet and ``V_e`` the reference volume. For incompressible tissue (``Je = 1``)
    it equals :func:`swelling_volume_ml` of the swelling region."""
    v = np.abs(tet_volumes_mm3(np.asarray(nodes_mm, dtype=float), np.asarray(tets)))
    return float(((np.asarray(js_tets, dtype=float) - 1.0) * v).sum() / MM3_PER_ML)


def bulge_volume_ml(
    nodes_mm: np.ndarray,
    tets: np.ndarray,
    u_mm: np.ndarray,
    phi_env: Callable[[np.ndarray], np.ndarray],
    order: int = 2,
    margin_mm: float | None = None,
) -> float:
    """Tissue volume outside the intact skull in the deformed configuration (ml).

    ``V_bulge = integral over the deformed mesh of [phi_env(x) > 0] dx / 1000``, with
    ``phi_env(points (k, 3)) -> (k,)`` a signed distance in mm, positive outside the skull's
    inner surface, e.g. ``lambda x: skull.envelope_distance(x, gradient=False)[0]``.

    Each deformed tet is split into ``order**3`` equal sub-tets (the regular Kuhn subdivision
    with ``order`` segments per edge); ``phi_env`` is sampled at the lattice points and
    interpolated linearly in each sub-tet, and the volume where that linear function is
    positive is integrated in closed form (:func:`positive_fraction`). This is exact when
    ``phi_env`` is affine (a plane), continuous in ``u`` (no jumps as a sample point crosses the
    surface) and converges as ``O((h / order)^2)``: on a surface of curvature radius ``R`` the
    error is a layer about ``h^2 / (6 R order^2)`` thick (``h`` the mesh size). Measured on a
    ball of radius ``R = 10 h / 3`` in a cube mesh: 4.5 % at ``order = 1``, 1.1 % at 2, 0.28 %
    at 4. Sampling the indicator at ``order**3`` points instead is first order and jumps with
    ``u``.

    With sliding contact, tissue pressed onto the skull (``phi`` at most the contact
    tolerance) counts too: about the mean penetration times the contact area. To count only
    tissue that left through the flap, pass ``lambda x: np.minimum(skull.envelope_distance(x)[0],
    -skull.signed_distance(x)[0])`` (outside the intact skull and not inside the skull solid).

    Only tets that can reach the outside are evaluated: those with
    ``max_vertex phi_env > -margin``; the default margin, the tet's longest deformed edge, is
    safe for a distance function (1-Lipschitz), which makes the cost scale with the surface
    rather than the volume.
    """
    if order < 1:
        raise ValueError(f"order must be >= 1, got {order}")
    X = np.asarray(nodes_mm, dtype=float)
    T = np.asarray(tets)
    x = X + np.asarray(u_mm, dtype=float)
    orient = np.sign(tet_volumes_mm3(X, T))
    phi_nodes = np.asarray(phi_env(x), dtype=float)
    P = x[T]  # (m, 4, 3)
    if margin_mm is None:
        edges = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
        margin = np.max([np.linalg.norm(P[:, a] - P[:, b], axis=1) for a, b in edges], axis=0)
    else:
        margin = np.full(len(T), float(margin_mm))
    cand = np.flatnonzero(phi_nodes[T].max(axis=1) > -margin)
    if cand.size == 0:
        return 0.0
    vol = orient[cand] * tet_volumes_mm3(x, T[cand])  # deformed, oriented (mm^3)
    bary, subtets = _kuhn_subdivision(order)
    total = 0.0
    for chunk in np.array_split(np.arange(cand.size), max(1, cand.size * len(bary) // 2_000_000)):
        pts = np.einsum("pk,mkd->mpd", bary, P[cand[chunk]])  # lattice points (c, p, 3)
        phi = np.asarray(phi_env(pts.reshape(-1, 3)), dtype=float).reshape(len(chunk), -1)
        frac = positive_fraction(phi[:, subtets]).mean(axis=1)  # equal sub-tet volumes
        total += float((frac * vol[chunk]).sum())
    return total / MM3_PER_ML


def positive_fraction(f: np.ndarray) -> np.ndarray:
    """Fraction of a tet's volume where the linear function with vertex values ``f`` (..., 4)
    is positive.

    With ``f_a > 0`` the positive and ``f_j <= 0`` the others (cases by the number positive):

    - 1: ``f_a^3 / prod_j (f_a - f_j)``;  3: one minus that formula for the non-positive vertex;
    - 2 (``x, y > 0 >= c, d``): ``(x^2 y^2 - (c + d) x y (x + y) + cd (x^2 + x y + y^2))
      / ((x - c)(x - d)(y - c)(y - d))``;

    the closed forms of ``sum_i max(f_i, 0)^3 / prod_{j != i} (f_i - f_j)`` with no division by
    a difference of same-signed values, so they stay exact for equal values.
    """
    f = np.asarray(f, dtype=float)
    shape = f.shape[:-1]
    f = f.reshape(-1, 4)
    pos = f > 0
    npos = pos.sum(axis=1)
    out = (npos == 4).astype(float)
    order = np.argsort(~pos, axis=1, kind="stable")  # positive vertices first
    g = np.take_along_axis(f, order, axis=1)
    for count in (1, 2, 3):
        sel = npos == count
        if not sel.any():
            continue
        a, b, c, d = g[sel].T
        if count == 1:
            out[sel] = a**3 / ((a - b) * (a - c) * (a - d))
        elif count == 3:
            out[sel] = 1.0 - (-d) ** 3 / ((a - d) * (b - d) * (c - d))
        else:
            num = a * a * b * b - (c + d) * a * b * (a + b) + c * d * (a * a + a * b + b * b)
            out[sel] = num / ((a - c) * (a - d) * (b - c) * (b - d))
    return np.clip(out, 0.0, 1.0).reshape(shape)


@cache
def _kuhn_subdivision(k: int) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric lattice points (p, 4) of a tet with ``k`` segments per edge and the ``k^3``
    sub-tets (k^3, 4) of its Kuhn subdivision, as indices into the points.

    The tet is mapped to ``{k >= y1 >= y2 >= y3 >= 0}`` (vertices 0, e1, e1+e2, e1+e2+e3
    scaled by k); the unit cubes' Kuhn simplices that lie inside it tile it.
    """
    lattice = [(i, j, l) for i in range(k + 1) for j in range(i + 1) for l in range(j + 1)]
    index = {p: n for n, p in enumerate(lattice)}
    perms = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]
    subtets = []
    for corner in np.ndindex(k, k, k):
        for perm in perms:
            path = [np.array(corner)]
            for axis in perm:
                path.append(path[-1] + np.eye(3, dtype=int)[axis])
            keys = [tuple(int(c) for c in p) for p in path]
            if all(p in index for p in keys):
                subtets.append([index[p] for p in keys])
    y = np.array(lattice, dtype=float) / k
    # y = (l1 + l2 + l3, l2 + l3, l3) with l the barycentric weights of vertices 1..3
    bary = np.stack([1 - y[:, 0], y[:, 0] - y[:, 1], y[:, 1] - y[:, 2], y[:, 2]], axis=1)
    sub = np.array(subtets, dtype=np.intp)
    assert len(sub) == k**3
    return bary, sub


def _oriented_volumes_mm3(nodes_mm: np.ndarray, tets: np.ndarray,
                          u_mm: np.ndarray | None) -> np.ndarray:
    X = np.asarray(nodes_mm, dtype=float)
    T = np.asarray(tets)
    ref = tet_volumes_mm3(X, T)
    if u_mm is None:
        return np.abs(ref)
    return np.sign(ref) * tet_volumes_mm3(X + np.asarray(u_mm, dtype=float), T)
