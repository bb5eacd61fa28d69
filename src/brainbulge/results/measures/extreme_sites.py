"""Where the 3D stretch and strain extremes are, and the extremes of element values.

A maximum over single points says little unless one knows where it is: the largest radial
stretch of a brain mesh may sit deep in the bulge (where the stretch is expected) or at one
corner of a gray-white interface, where the stiffness and the swelling jump and the field is
singular. For each reported extreme (``max_principal_strain``, ``max_radial_stretch``,
``min_radial_stretch``, ``max_tangential_stretch``: parenchyma, outside the band around the
flap's rim) :func:`extreme_sites` gives

- the point: its ``region``, ``rim_distance_mm`` (to the flap's rim, the curve where the
  cutting cylinder meets the skull's inner surface), ``under_flap`` (inside the cutting
  cylinder), ``depth_mm`` (below the skull's inner surface), ``swelling_distance_mm`` (to the
  nearest swelling element's centroid; 0 inside one), ``at_interface`` (its element
  touches another region, where the stiffness or the swelling jumps and the field is
  singular) and ``interface_distance_mm`` (to the nearest node on such an interface). On a
  coarse brain mesh nearly every parenchyma element touches an interface (the cortex is
  thinner than an element), so the distance says more than the flag there; an extreme whose
  element recurs in several scenarios is a property of that element, not of the load;
- the ``peak_set``: the 0.1 ml of that tissue with the most extreme values (the set whose
  ``threshold`` is the summary's ``peak_*``): its median rim distance, depth and distance to
  an interface, and the shares of it under the flap and at interfaces. A peak set near the
  rim is a "ring around the opening"; one under the flap, away from the rim, is "deep
  inside the bulge".

:func:`element_extremes` gives the same extremes of the element values (the stretches of the
element-constant deformation gradient of the P1 displacement, what a linear tetrahedron such
as Abaqus' C3D4H reports per element), ``element_max_*`` / ``element_min_*``, with their
sites: the recovered gradient of the summaries is smoother than element values.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from brainbulge.results.measures.fields import (
    max_principal_strain,
    radial_directions,
    right_cauchy_green,
    stretch_along,
    tangential_stretch,
)
from brainbulge.results.measures.schema import ELEMENT_SITES, EXTREMES, SITES

#: (summary key, field, kind) of the extremes whose sites are reported
SITE_KEYS = tuple((key, EXTREMES[key[4:]][0], key[:3]) for key in SITES)


@dataclass
class SiteContext:
    """What locating a point in a brain mesh needs (lengths mm).

    ``nodes``/``tets``/``regions`` (one name per tet) the mesh; ``swelling`` a mask of the
    swelling tets; ``rim_distance(X)``, ``under_flap(X)`` and ``depth(X)`` functions of
    reference points."""

    nodes: np.ndarray
    tets: np.ndarray
    regions: np.ndarray
    swelling: np.ndarray
    rim_distance: Callable[[np.ndarray], np.ndarray]
    under_flap: Callable[[np.ndarray], np.ndarray]
    depth: Callable[[np.ndarray], np.ndarray]

    def __post_init__(self) -> None:
        self.centroids = self.nodes[self.tets].mean(axis=1)
        self._tree = cKDTree(self.centroids)
        sw = self.centroids[self.swelling]
        self._swell_tree = cKDTree(sw) if len(sw) else None
        # a node shared by tets of different regions lies on an interface
        codes = np.unique(self.regions, return_inverse=True)[1].ravel()
        lo = np.full(len(self.nodes), codes.max() + 1)
        hi = np.full(len(self.nodes), -1)
        for k in range(self.tets.shape[1]):
            np.minimum.at(lo, self.tets[:, k], codes)
            np.maximum.at(hi, self.tets[:, k], codes)
        self.interface_node = lo != hi
        pts = self.nodes[self.interface_node]
        self._interface_tree = cKDTree(pts) if len(pts) else None

    def interface_distance(self, X: np.ndarray) -> np.ndarray:
        """Distance [mm] from each point to the nearest node on a region interface."""
        if self._interface_tree is None:
            return np.full(len(X), np.inf)
        return self._interface_tree.query(X)[0]

    def containing_tets(self, X: np.ndarray) -> np.ndarray:
        """Index of the tet that contains each point (the nearest centroid's when none of the
        16 nearest does, e.g. a point on a curved boundary)."""
        k = min(16, len(self.tets))
        _, cand = self._tree.query(X, k=k)
        cand = np.atleast_2d(cand).reshape(len(X), k)
        out = cand[:, 0].copy()
        for i, (x, cs) in enumerate(zip(X, cand, strict=True)):
            for c in cs:
                v = self.nodes[self.tets[c]]
                try:
                    lam = np.linalg.solve((v[1:] - v[0]).T, x - v[0])
                except np.linalg.LinAlgError:
                    continue
                if lam.min() >= -1e-9 and lam.sum() <= 1 + 1e-9:
                    out[i] = c
                    break
        return out

    def describe(self, X: np.ndarray, tets: np.ndarray | None = None) -> list[dict]:
        """The site of each point of ``X`` (see the module docstring); ``tets``: their
        elements, when known."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        tets = self.containing_tets(X) if tets is None else np.asarray(tets)
        if self._swell_tree is not None:
            d_sw = self._swell_tree.query(X)[0]
            d_sw[self.swelling[tets]] = 0.0
        else:
            d_sw = np.full(len(X), np.inf)
        rim, under, depth = self.rim_distance(X), self.under_flap(X), self.depth(X)
        at_if = self.interface_node[self.tets[tets]].any(axis=1)
        d_if = self.interface_distance(X)
        return [{"X_mm": [round(float(c), 2) for c in X[i]],
                 "region": str(self.regions[tets[i]]),
                 "rim_distance_mm": round(float(rim[i]), 2),
                 "under_flap": bool(under[i]),
                 "depth_mm": round(float(depth[i]), 2),
                 "swelling_distance_mm": (round(float(d_sw[i]), 2) if np.isfinite(d_sw[i])
                                          else None),
                 "at_interface": bool(at_if[i]),
                 "interface_distance_mm": round(float(d_if[i]), 2)} for i in range(len(X))]

    def peak_set(self, X: np.ndarray, weights: np.ndarray) -> dict[str, float]:
        """Where a set of points (e.g. the 0.1 ml of the largest values) lies: medians and
        volume shares."""
        tets = self._tree.query(X)[1]  # the nearest centroid is enough for shares
        w = np.asarray(weights, dtype=float)
        total = float(w.sum())
        return {
            "volume_ml": total / 1000.0,
            "median_rim_distance_mm": round(_weighted_median(self.rim_distance(X), w), 2),
            "median_depth_mm": round(_weighted_median(self.depth(X), w), 2),
            "share_under_flap": round(float(w[self.under_flap(X)].sum()) / total, 3),
            "share_at_interface": round(
                float(w[self.interface_node[self.tets[tets]].any(axis=1)].sum()) / total, 3),
            "median_interface_distance_mm": round(
                _weighted_median(self.interface_distance(X), w), 2),
        }


def _weighted_median(v: np.ndarray, w: np.ndarray) -> float:
    order = np.argsort(v)
    cum = np.cumsum(w[order])
    return float(v[order][np.searchsorted(cum, cum[-1] / 2)])


def _extreme_set(v: np.ndarray, w: np.ndarray, allowed: Callable[[np.ndarray], np.ndarray],
                 kind: str, volume_mm3: float) -> tuple[int, np.ndarray] | None:
    """Index of the extreme allowed point and the indices of the allowed points with the
    most extreme values up to ``volume_mm3``; only the top of ``v`` is looked at."""
    s = v if kind == "max" else -v
    n = len(s)
    m = min(n, 4096)
    while True:
        top = np.argpartition(s, n - m)[n - m:] if m < n else np.arange(n)
        top = top[np.argsort(s[top])[::-1]]
        top = top[allowed(top)]
        if m == n or (len(top) and w[top].sum() >= volume_mm3):
            break
        m = min(n, 8 * m)
    if not len(top):
        return None
    k = int(np.searchsorted(np.cumsum(w[top]), volume_mm3)) + 1
    return int(top[0]), top[:k]


def extreme_sites(ctx: SiteContext, X: np.ndarray, fields: dict[str, np.ndarray],
                  weights: np.ndarray, allowed: Callable[[np.ndarray], np.ndarray],
                  peak_volume_mm3: float) -> dict[str, dict]:
    """Site and peak set of each extreme of :data:`SITE_KEYS` over the integration points
    ``X`` (``fields`` there, ``weights`` their volumes in mm^3); ``allowed(indices)`` says
    which points count (the parenchyma outside the rim band, as for ``max_*``)."""
    out: dict[str, dict] = {}
    for key, field, kind in SITE_KEYS:
        found = _extreme_set(np.asarray(fields[field]), weights, allowed, kind,
                             peak_volume_mm3)
        if found is None:
            continue
        i, peak = found
        site = ctx.describe(X[i:i + 1])[0]
        site["value"] = float(fields[field][i])
        site["peak_set"] = {"threshold": float(fields[field][peak[-1]]),
                            **ctx.peak_set(X[peak], weights[peak])}
        out[key] = site
    return out


def element_fields(nodes: np.ndarray, tets: np.ndarray, u: np.ndarray,
                   centre: np.ndarray) -> dict[str, np.ndarray]:
    """Element values of the stretches and strain: ``F = I + Grad u`` of the linear
    interpolant of the nodal displacements ``u`` (constant per tet), ``n`` radial from
    ``centre`` at the tet's centroid."""
    X = nodes[tets]
    D = np.transpose(X[:, 1:] - X[:, :1], (0, 2, 1))  # columns: edge vectors
    U = np.transpose(u[tets][:, 1:] - u[tets][:, :1], (0, 2, 1))
    F = np.eye(3) + U @ np.linalg.inv(D)
    C = right_cauchy_green(F)
    n = radial_directions(X.mean(axis=1), centre)
    return {"max_principal_strain": max_principal_strain(C),
            "lambda_n": stretch_along(C, n),
            "lambda_t": tangential_stretch(C, n, 3)}


def element_extremes(ctx: SiteContext, u: np.ndarray, centre: np.ndarray,
                     allowed: np.ndarray) -> dict[str, object]:
    """``element_<key>`` for each extreme of :data:`SITE_KEYS` over the tets ``allowed``
    (mask), and their sites under ``element_sites``."""
    if not allowed.any():
        return {}
    vals = element_fields(ctx.nodes, ctx.tets, u, centre)
    idx = np.flatnonzero(allowed)
    out: dict[str, object] = {}
    sites: dict[str, dict] = {}
    for key, field, kind in SITE_KEYS:
        if key not in ELEMENT_SITES:
            continue
        v = vals[field][idx]
        t = int(idx[np.argmax(v) if kind == "max" else np.argmin(v)])
        out[f"element_{key}"] = float(vals[field][t])
        site = ctx.describe(ctx.centroids[t:t + 1], np.array([t]))[0]
        site["value"] = out[f"element_{key}"]
        sites[key] = site
    out["element_sites"] = sites
    return out


def brain_extreme_sites(bm, flap_name: str, skull, swell_sides: tuple[str, ...],
                        band_mm: float, tissue: str, points, u_mm: np.ndarray,
                        peak_volume_mm3: float) -> dict[str, object]:
    """``extreme_sites`` (points), ``element_*`` extremes and ``element_sites`` of a 3D
    scenario: ``bm`` its :class:`~brainbulge.geometry.brain.BrainMesh`, ``skull`` its
    :class:`~brainbulge.geometry.brain.skull.RigidSkull` with the flap ``flap_name`` open,
    ``band_mm`` the rim band left out, ``tissue`` the parenchyma's region regex, ``points``
    the state's :class:`~brainbulge.results.measures.summary.PointFields`, ``u_mm`` the nodal
    displacements."""
    import re

    flap = bm.flaps[flap_name]

    def rim_distance(X: np.ndarray) -> np.ndarray:
        return np.hypot(flap.cutter_distance(X)[0],
                        skull.envelope_distance(X, gradient=False)[0])

    regions = bm.material_names().astype(str)
    swelling = np.isin(regions, [f"white_{s}" for s in swell_sides])
    ctx = SiteContext(bm.nodes_mm, bm.tets, regions, swelling, rim_distance,
                      lambda X: flap.cutter_distance(X)[0] < 0,
                      lambda X: -skull.envelope_distance(X, gradient=False)[0])
    rx = re.compile(f"^(?:{tissue})$")
    in_tissue = points.in_regions(tissue)

    def allowed(idx: np.ndarray) -> np.ndarray:
        return in_tissue[idx] & (rim_distance(points.X[idx]) >= band_mm)

    centre = bm.envelope.centre_mm()
    par_tets = np.array([bool(rx.match(r)) for r in regions])
    out: dict[str, object] = {"extreme_sites": extreme_sites(
        ctx, points.X, points.fields, points.q.weights, allowed, peak_volume_mm3)}
    out.update(element_extremes(ctx, u_mm, centre,
                                par_tets & (rim_distance(ctx.centroids) >= band_mm)))
    return out
