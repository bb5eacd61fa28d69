"""Rezoning of a 2D Lagrangian mesh through the current deformation.

The solid is hyperelastic, so its state at a load depends only on the reference domain and
the load, not on the path: the mesh may be exchanged between load steps. When tissue slides
around a rigid corner, the reference triangles there are sheared flat by ``x = phi(X) =
X + u(X)``; a new reference mesh whose *image* is well shaped removes that distortion:

1. the deformed domain ``phi(Omega)`` is meshed afresh (netgen): its boundary and the
   interfaces between regions are the images of the old ones, resampled with the mesh size
   ``h`` and ``h_corner`` at the images of the singular points;
2. each new vertex ``x`` is pulled back, ``X = phi^-1(x)``, by Newton's method on
   ``X + u(X) = x`` (``F = I + grad u``); vertices on boundaries and interfaces are moved onto
   the exact reference curves (``project``);
3. the new mesh takes these reference coordinates: the same domain, regions and boundary
   names, straight-sided triangles, and ``u(X)`` from the old state as the new start.

Written by hand: no meshing library we use remeshes through a deformation map.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import ngsolve as ngs
import numpy as np
from netgen.geom2d import SplineGeometry
from netgen.meshing import MeshingParameters
from scipy.spatial import cKDTree

from brainbulge.errors import ConvergenceError

#: mesh size growth away from a singular point, ``h(d) = h_corner + GRADING_SLOPE d``
GRADING_SLOPE = 0.3

Projector = Callable[[str, np.ndarray], np.ndarray]


@dataclass
class Rezoned:
    """A new reference mesh and the old displacement at its vertices [length]."""

    mesh: ngs.Mesh
    u_vertices: np.ndarray


@dataclass
class Topology:
    X: np.ndarray  # (nv, 2) reference vertex coordinates
    tris: np.ndarray  # (ne, 3) vertex numbers
    region: np.ndarray  # (ne,) index into regions
    regions: list[str]


def triangle_quality(x: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Shape quality ``q = 4 sqrt(3) A / (l1^2 + l2^2 + l3^2)`` of triangles with vertex
    coordinates ``x`` (1 equilateral, 0 degenerate, < 0 inverted)."""
    a, b, c = (x[tris[:, k]] for k in range(3))
    area = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
                  - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    l2 = ((b - a) ** 2).sum(1) + ((c - b) ** 2).sum(1) + ((a - c) ** 2).sum(1)
    return 4 * np.sqrt(3) * area / l2


def vertex_values(mesh: ngs.Mesh, cf: ngs.CoefficientFunction, X: np.ndarray,
                  inward: np.ndarray | None = None) -> np.ndarray:
    """``cf`` at reference points ``X`` (n, dim); a point outside the mesh (a straight-sided
    mesh misses slivers of a curved boundary) is moved towards its point of ``inward`` until
    it is found, else its row is NaN."""
    vals = np.full((len(X), cf.dim), np.nan)
    todo = np.arange(len(X))
    for s in (0.0, 1e-6, 1e-4, 1e-3, 1e-2, 0.1, 0.3, 0.6, 0.9) if inward is not None else (0.0,):
        P = X[todo] if s == 0 else X[todo] + s * (inward[todo] - X[todo])
        mips = mesh(*P.T)
        inside = mips["nr"] >= 0
        if np.any(inside):
            vals[todo[inside]] = np.asarray(cf(mips[inside]), dtype=float).reshape(-1, cf.dim)
        todo = todo[~inside]
        if not len(todo):
            break
    return vals


def deformed_quality(mesh: ngs.Mesh, u: ngs.CoefficientFunction) -> np.ndarray:
    """:func:`triangle_quality` of the deformed straight triangles ``X_i + u(X_i)``."""
    top = topology(mesh)
    return triangle_quality(top.X + vertex_values(mesh, u, top.X), top.tris)


def rezone(
    mesh: ngs.Mesh,
    u: ngs.CoefficientFunction,
    project: Projector,
    h: float,
    h_corner: float,
    corners: Sequence[tuple[float, float]] = (),
    rim_points: np.ndarray | None = None,
    h_rim: float | None = None,
) -> Rezoned:
    """A reference mesh of ``mesh``'s domain that ``X + u(X)`` maps onto a fresh netgen mesh
    of the deformed domain (sizes ``h``, ``h_corner`` at the images of ``corners``, ``h_rim``
    at the images of the reference points ``rim_points`` (n, 2))."""
    top = topology(mesh)
    U = vertex_values(mesh, u, top.X)
    if not np.all(np.isfinite(U)):
        raise ConvergenceError("rezoning: the displacement is not finite at every vertex")
    x = top.X + U
    corner_ids = _nearest_vertices(top.X, corners)
    # every refined point with its size: the corners' and the rim points' images
    x_fine = x[corner_ids] if len(corner_ids) else np.zeros((0, 2))
    h_fine = np.full(len(x_fine), h_corner)
    if rim_points is not None and len(rim_points) and h_rim is not None:
        x_rim = rim_points + vertex_values(mesh, u, rim_points)
        keep = np.all(np.isfinite(x_rim), axis=1)
        x_fine = np.concatenate([x_fine, x_rim[keep]])
        h_fine = np.concatenate([h_fine, np.full(int(keep.sum()), h_rim)])

    def size(p: np.ndarray) -> np.ndarray:
        if not len(x_fine):
            return np.full(len(p), h)
        d = np.linalg.norm(p[:, None, :] - x_fine[None], axis=2)
        return np.minimum(h, np.min(h_fine + GRADING_SLOPE * d, axis=1))

    geo = SplineGeometry()
    point_id: dict[int, int] = {}
    chain_pts: list[tuple[str, np.ndarray, np.ndarray]] = []  # label, x, X of each chain
    for label, verts, left, right in _chains(mesh, top, set(corner_ids.tolist())):
        xs, Xs = _resample(x[verts], top.X[verts], size)
        Xs[1:-1] = project(label, Xs[1:-1])
        ids = []
        for k, (px, py) in enumerate(xs):
            end = verts[0] if k == 0 else verts[-1] if k == len(xs) - 1 else None
            if end is not None and end in point_id:
                ids.append(point_id[end])
                continue
            ids.append(geo.AppendPoint(float(px), float(py)))
            if end is not None:
                point_id[end] = ids[-1]
        for a, b in zip(ids[:-1], ids[1:], strict=True):
            geo.Append(["line", a, b], leftdomain=left, rightdomain=right, bc=label)
        chain_pts.append((label, xs, Xs))
    for k, name in enumerate(top.regions):
        geo.SetMaterial(k + 1, name)
    mp = MeshingParameters(maxh=h, grading=0.25)
    for (px, py), hp in zip(x_fine, h_fine, strict=True):
        mp.RestrictH(x=float(px), y=float(py), z=0, h=float(hp))
    ngmesh = geo.GenerateMesh(mp=mp)
    coords = ngmesh.Coordinates()
    x_new = np.array(coords[:, :2], dtype=float)

    X_new = _pull_back(mesh, u, top, x, x_new)
    # vertices on boundaries and interfaces: the reference point of the chain's resampling
    # where netgen kept it, else (a point netgen added) projected onto the exact curve
    on_chain = np.zeros(len(x_new), dtype=bool)
    for _label, xs, Xs in chain_pts:
        dist, idx = cKDTree(xs).query(x_new)
        hit = dist < 1e-9 * h
        X_new[hit] = Xs[idx[hit]]
        on_chain |= hit
    for seg in ngmesh.Elements1D():
        label = ngmesh.GetBCName(seg.index - 1)
        vs = np.array([v.nr - 1 for v in seg.vertices])
        vs = vs[~on_chain[vs]]
        if len(vs):
            X_new[vs] = project(label, X_new[vs])
    new_top_tris = np.array([[v.nr - 1 for v in el.vertices] for el in ngmesh.Elements2D()])
    q = triangle_quality(X_new, new_top_tris)
    if np.any(q <= 0):
        raise ConvergenceError(
            f"rezoning: {int(np.sum(q <= 0))} pulled-back triangles are inverted; "
            "the deformation is too large for a remesh at this state"
        )
    # u = x - X at the vertices: the new deformed mesh is netgen's; on boundaries and
    # interfaces u(X) instead, so that those vertices lie on the deformed curved boundary,
    # not on its chords (which cut into a convex obstacle the tissue wraps around)
    U_new = x_new - X_new
    on_curve = np.zeros(len(x_new), dtype=bool)
    for seg in ngmesh.Elements1D():
        on_curve[[v.nr - 1 for v in seg.vertices]] = True
    centroid = np.zeros_like(X_new)  # of one triangle at each vertex: "inward"
    centroid[new_top_tris.ravel()] = np.repeat(X_new[new_top_tris].mean(axis=1), 3, axis=0)
    idx = np.flatnonzero(on_curve)
    U_curve = vertex_values(mesh, u, X_new[idx], inward=centroid[idx])
    good = np.all(np.isfinite(U_curve), axis=1)
    U_new[idx[good]] = U_curve[good]
    for _ in range(3):  # a vertex that folds a deformed triangle goes back onto the chord
        folded = new_top_tris[triangle_quality(X_new + U_new, new_top_tris) <= 0.05]
        if not len(folded):
            break
        back = np.unique(folded)
        U_new[back] = (x_new - X_new)[back]
    coords[:, 0] = X_new[:, 0]
    coords[:, 1] = X_new[:, 1]
    return Rezoned(ngs.Mesh(ngmesh), U_new)


# --- helpers ----------------------------------------------------------------------------
def topology(mesh: ngs.Mesh) -> Topology:
    if mesh.dim != 2:
        raise ValueError("rezoning is implemented for 2D meshes")
    X = np.array([v.point for v in mesh.vertices])[:, :2]
    tris, region = [], []
    for el in mesh.Elements(ngs.VOL):
        tris.append([v.nr for v in el.vertices])
        region.append(el.index)
    names = list(mesh.GetMaterials())
    unique = list(dict.fromkeys(names))
    remap = np.array([unique.index(n) for n in names])
    return Topology(X, np.array(tris), remap[np.array(region)], unique)


def _nearest_vertices(X: np.ndarray, points: Sequence[tuple[float, float]]) -> np.ndarray:
    if not len(points):
        return np.zeros(0, dtype=int)
    _, idx = cKDTree(X).query(np.asarray(points, dtype=float))
    return np.unique(idx)


def _chains(mesh: ngs.Mesh, top: Topology, corners: set[int]
            ) -> list[tuple[str, list[int], int, int]]:
    """Feature curves of the mesh (boundary, and edges between regions) as vertex chains
    ``(label, vertices, left domain, right domain)`` (domains 1-based, 0 outside), broken
    where the label or the adjacent regions change, at junctions and at ``corners``."""
    edge_tris: dict[tuple[int, int], list[int]] = defaultdict(list)
    for t, tri in enumerate(top.tris):
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            edge_tris[(min(a, b), max(a, b))].append(t)
    names = mesh.GetBoundaries()
    seg_name = {}
    for el in mesh.Elements(ngs.BND):
        a, b = (v.nr for v in el.vertices)
        seg_name[(min(a, b), max(a, b))] = names[el.index]
    features: dict[tuple[int, int], tuple[str, int, int]] = {}
    for (a, b), ts in edge_tris.items():
        if len(ts) == 2 and top.region[ts[0]] == top.region[ts[1]]:
            continue
        label = seg_name.get((a, b), "interface")
        features[(a, b)] = (label, *_sides(top, a, b, ts))
    nbrs: dict[int, list[int]] = defaultdict(list)
    for a, b in features:
        nbrs[a].append(b)
        nbrs[b].append(a)

    def kind(a: int, b: int) -> tuple[str, frozenset]:
        label, left, right = features[(min(a, b), max(a, b))]
        return label, frozenset((left, right))

    breaks = {v for v, n in nbrs.items() if len(n) != 2} | (corners & set(nbrs))
    breaks |= {v for v, (p, q) in ((v, n) for v, n in nbrs.items() if len(n) == 2)
               if kind(v, p) != kind(v, q)}
    chains, seen = [], set()
    starts = sorted(breaks) or [min(nbrs)]
    for s in starts:
        for nb in nbrs[s]:
            if (min(s, nb), max(s, nb)) in seen:
                continue
            verts = [s, nb]
            seen.add((min(s, nb), max(s, nb)))
            while verts[-1] not in breaks and verts[-1] != s:
                nxt = [w for w in nbrs[verts[-1]] if (min(verts[-1], w), max(verts[-1], w))
                       not in seen]
                if not nxt:
                    break
                seen.add((min(verts[-1], nxt[0]), max(verts[-1], nxt[0])))
                verts.append(nxt[0])
            label, left, right = features[(min(verts[0], verts[1]), max(verts[0], verts[1]))]
            if verts[0] > verts[1]:  # stored for (min, max): orient to the walk
                left, right = right, left
            chains.append((label, verts, left, right))
    return chains


def _sides(top: Topology, a: int, b: int, ts: list[int]) -> tuple[int, int]:
    """Domains (region + 1, 0 outside) left and right of the directed edge ``a -> b``."""
    left = right = 0
    d = top.X[b] - top.X[a]
    for t in ts:
        c = next(v for v in top.tris[t] if v not in (a, b))
        e = top.X[c] - top.X[a]
        if d[0] * e[1] - d[1] * e[0] > 0:
            left = int(top.region[t]) + 1
        else:
            right = int(top.region[t]) + 1
    return left, right


def _resample(x: np.ndarray, X: np.ndarray, size: Callable[[np.ndarray], np.ndarray]
              ) -> tuple[np.ndarray, np.ndarray]:
    """Points along the deformed polyline ``x`` spaced by ``size`` (ends kept), and the
    reference points at the same polyline parameter on ``X``."""
    sub = 8
    s_seg = np.linspace(0, 1, sub + 1)[:-1]
    dense_t = (np.arange(len(x) - 1)[:, None] + s_seg[None]).ravel()
    dense_t = np.append(dense_t, len(x) - 1)
    dense_x = _at(x, dense_t)
    ds = np.linalg.norm(np.diff(dense_x, axis=0), axis=1)
    mid = 0.5 * (dense_x[1:] + dense_x[:-1])
    n_cum = np.concatenate([[0.0], np.cumsum(ds / size(mid))])
    n = max(1, int(round(n_cum[-1])))
    t = np.interp(np.linspace(0, n_cum[-1], n + 1), n_cum, dense_t)
    t[0], t[-1] = 0, len(x) - 1
    return _at(x, t), _at(X, t)


def _at(poly: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Piecewise-linear point of the polyline ``poly`` at parameter ``t`` in [0, n-1]."""
    k = np.clip(np.floor(t).astype(int), 0, len(poly) - 2)
    s = (t - k)[:, None]
    return (1 - s) * poly[k] + s * poly[k + 1]


def _pull_back(mesh: ngs.Mesh, u: ngs.CoefficientFunction, top: Topology, x: np.ndarray,
               x_new: np.ndarray, iterations: int = 8) -> np.ndarray:
    """``X`` with ``X + u(X) = x_new``: start from the deformed straight triangles'
    barycentric map, then Newton with ``F = I + grad u``."""
    X = top.X[cKDTree(x).query(x_new)[1]]  # outside every straight triangle: nearest vertex
    # point location among the deformed straight triangles nearest by centroid (written by
    # hand: matplotlib's trifinder refuses a triangulation with one flipped triangle)
    k = min(12, len(top.tris))
    _, cand = cKDTree(x[top.tris].mean(axis=1)).query(x_new, k=k)
    cand = cand.reshape(len(x_new), k)
    t = top.tris[cand]  # (n, k, 3)
    a, b, c = x[t[..., 0]], x[t[..., 1]], x[t[..., 2]]
    T = np.stack([b - a, c - a], axis=-1)  # (n, k, 2, 2)
    det = T[..., 0, 0] * T[..., 1, 1] - T[..., 0, 1] * T[..., 1, 0]
    rhs = x_new[:, None, :] - a
    with np.errstate(divide="ignore", invalid="ignore"):
        l1 = (rhs[..., 0] * T[..., 1, 1] - rhs[..., 1] * T[..., 0, 1]) / det
        l2 = (T[..., 0, 0] * rhs[..., 1] - T[..., 1, 0] * rhs[..., 0]) / det
    inside_k = (det > 0) & (l1 >= -1e-9) & (l2 >= -1e-9) & (l1 + l2 <= 1 + 1e-9)
    hit = inside_k.any(axis=1)
    j = np.argmax(inside_k, axis=1)
    rows = np.flatnonzero(hit)
    tt = t[rows, j[rows]]
    lam1, lam2 = l1[rows, j[rows]][:, None], l2[rows, j[rows]][:, None]
    A, B, C = top.X[tt[:, 0]], top.X[tt[:, 1]], top.X[tt[:, 2]]
    X[rows] = A + lam1 * (B - A) + lam2 * (C - A)
    grad = ngs.Grad(u)
    scale = max(1.0, float(np.abs(x).max()))
    for _ in range(iterations):
        mips = mesh(X[:, 0], X[:, 1])
        ok = mips["nr"] >= 0
        if not np.any(ok):
            break
        uv = np.asarray(u(mips[ok]), dtype=float).reshape(-1, 2)
        G = np.asarray(grad(mips[ok]), dtype=float).reshape(-1, 2, 2)
        r = x_new[ok] - X[ok] - uv
        if np.max(np.abs(r), initial=0.0) < 1e-12 * scale:
            break
        step = np.linalg.solve(np.eye(2)[None] + G, r[..., None])[..., 0]
        idx = np.flatnonzero(ok)
        for _halving in range(6):  # keep the iterates inside the mesh
            trial = X[idx] + step
            inside = mesh(trial[:, 0], trial[:, 1])["nr"] >= 0
            X[idx[inside]] = trial[inside]
            idx, step = idx[~inside], 0.5 * step[~inside]
            if not len(idx):
                break
    return X
