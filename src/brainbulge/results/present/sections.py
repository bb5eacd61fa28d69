"""Planar sections of 3D tet fields: exact plane cuts of the mesh, drawn deformed (PNG).

:func:`section_triangles` cuts a linear tet mesh by a plane in the reference configuration: a
tet whose vertices lie on both sides is cut in a triangle (one vertex apart) or a quadrilateral
(two and two), split into triangles; nodal values are interpolated linearly along the cut
edges, so a linear field is reproduced exactly. Cut points are shared between the tets that
share the edge, so the section is a conforming triangle mesh whose boundary edges are the
section's outline.

:func:`plot_sections` draws fields on such sections at the deformed positions ``X + u`` of
the cut points, projected on the plane (the out-of-plane displacement is not shown).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.tri as mtri  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

from brainbulge.results.present.figures import CMAPS, LABELS, _limits, _save  # noqa: E402

# name -> (normal axis, horizontal axis, vertical axis, (left, right) and (bottom, top) labels)
# in RAS+ world coordinates (x right, y anterior, z superior).
PLANES: dict[str, tuple[int, int, int, tuple[str, str], tuple[str, str]]] = {
    "transverse": (2, 0, 1, ("L", "R"), ("P", "A")),  # viewed from above
    "sagittal": (0, 1, 2, ("P", "A"), ("I", "S")),  # viewed from the right
    "coronal": (1, 0, 2, ("L", "R"), ("I", "S")),  # viewed from behind
}
PLANES["axial"] = PLANES["transverse"]

UNDEFORMED_OUTLINE = {"color": "black", "lw": 0.6}
DEFORMED_OUTLINE = {"color": "#e600e6", "lw": 0.9}

# For each 4-bit code of "vertex above the plane", the cut edges (above, not above) in cyclic
# order around the section polygon.
_CUT_EDGES: dict[int, list[tuple[int, int]]] = {}
for _code in range(1, 15):
    _up = [v for v in range(4) if _code >> v & 1]
    _down = [v for v in range(4) if not _code >> v & 1]
    if len(_up) == 2:
        (_p, _q), (_r, _s) = _up, _down
        _CUT_EDGES[_code] = [(_p, _r), (_p, _s), (_q, _s), (_q, _r)]
    else:
        _CUT_EDGES[_code] = [(a, b) for a in _up for b in _down]


class Section(NamedTuple):
    """A planar section: cut ``points`` (p, 3) in the reference configuration, ``values``
    (p, ...) interpolated there, ``triangles`` (t, 3) into the points and the ``tet`` (t,)
    each triangle came from."""

    points: np.ndarray
    values: np.ndarray
    triangles: np.ndarray
    tet: np.ndarray

    def area(self, points: np.ndarray | None = None) -> float:
        """Total area of the triangles (at ``points`` if given, e.g. deformed)."""
        p = self.points if points is None else points
        t = p[self.triangles]
        return float(0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]),
                                          axis=1).sum())

    def boundary_edges(self) -> np.ndarray:
        """Edges (e, 2) that belong to one triangle only: the outline of the section."""
        return boundary_edges(self.triangles)


def section_triangles(nodes: np.ndarray, tets: np.ndarray, values: np.ndarray,
                      point: np.ndarray, normal: np.ndarray) -> Section:
    """Cut the tet mesh by the plane through ``point`` with ``normal`` (reference
    configuration).

    With ``s = (X - point) . normal`` per node, a vertex is above when ``s > 0``. An edge from
    ``a`` (above) to ``b`` (not above) is cut at ``X_a + t (X_b - X_a)``, ``t = s_a / (s_a -
    s_b)``, where the values are ``v_a + t (v_b - v_a)``. Vertices lying on the plane belong
    below, so a face in the plane is drawn once (by the tet above it); zero-area triangles are
    dropped. ``values`` is per node, shape (n,) or (n, k). Vectorised: only the tets that
    straddle the plane are processed.
    """
    X = np.asarray(nodes, dtype=float)
    T = np.asarray(tets)
    V = np.asarray(values)
    nrm = np.asarray(normal, dtype=float)
    nrm = nrm / np.linalg.norm(nrm)
    s = (X - np.asarray(point, dtype=float)) @ nrm
    above = s[T] > 0
    code = above @ np.array([1, 2, 4, 8])
    cut = np.flatnonzero((code > 0) & (code < 15))
    code = code[cut]
    starts, ends, tri_local, tri_tet = [], [], [], []
    n_points = 0
    for c, edges in _CUT_EDGES.items():
        sel = cut[code == c]
        if sel.size == 0:
            continue
        loc = np.array(edges)
        starts.append(T[sel][:, loc[:, 0]].ravel())
        ends.append(T[sel][:, loc[:, 1]].ravel())
        k = len(edges)
        fan = np.array([[0, 1, 2]] if k == 3 else [[0, 1, 2], [0, 2, 3]])
        base = n_points + k * np.arange(sel.size)
        tri_local.append((base[:, None, None] + fan[None]).reshape(-1, 3))
        tri_tet.append(np.repeat(sel, len(fan)))
        n_points += k * sel.size
    if n_points == 0:
        return Section(np.zeros((0, 3)), np.zeros((0,) + V.shape[1:], V.dtype),
                       np.zeros((0, 3), np.intp), np.zeros(0, np.intp))
    a, b = np.concatenate(starts), np.concatenate(ends)
    # one point per cut edge; an edge ending on the plane is cut at its end node
    on_node = s[b] == 0
    lo, hi = np.where(on_node, b, np.minimum(a, b)), np.where(on_node, b, np.maximum(a, b))
    keys = lo.astype(np.int64) * len(X) + hi
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    a, b = a[first], b[first]
    t = s[a] / (s[a] - s[b])
    points = X[a] + t[:, None] * (X[b] - X[a])
    points[s[b] == 0] = X[b[s[b] == 0]]
    tv = t.reshape((-1,) + (1,) * (V.ndim - 1))
    vals = V[a] + tv * (V[b] - V[a])
    triangles = inverse.ravel()[np.concatenate(tri_local)]
    tet = np.concatenate(tri_tet)
    p = points[triangles]
    area2 = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    keep = area2 > 1e-12 * max(float(area2.max()), 1e-300)
    return Section(points, vals, triangles[keep], tet[keep])


def boundary_edges(triangles: np.ndarray) -> np.ndarray:
    """Edges (e, 2), sorted node pairs, that belong to exactly one triangle."""
    e = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                triangles[:, [2, 0]]]), axis=1)
    n = int(e.max()) + 1 if len(e) else 1
    keys, counts = np.unique(e[:, 0].astype(np.int64) * n + e[:, 1], return_counts=True)
    once = keys[counts == 1]
    return np.stack([once // n, once % n], axis=1)


def plot_sections(
    nodes_mm: np.ndarray,
    tets: np.ndarray,
    u_mm: np.ndarray,
    fields: dict[str, np.ndarray],
    centre_mm: np.ndarray,
    path: str | Path,
    planes: Sequence[str] = ("transverse", "sagittal"),
    ranges: dict[str, tuple[float, float]] | None = None,
    outline: bool = True,
    title: str = "",
    tet_mask: np.ndarray | None = None,
    dpi: int = 110,
) -> Path:
    """One PNG of nodal ``fields`` (rows) on sections through ``centre_mm`` (columns), in mm.

    Planes are named in RAS+ world axes: ``"transverse"`` (``z`` = const, viewed from above, the
    patient's right on the right), ``"sagittal"`` (``x`` = const, anterior on the right),
    ``"coronal"``. The mesh (only the tets in ``tet_mask``, if given) is cut in the reference
    configuration and drawn at the deformed positions ``X + u`` projected on the plane, with
    Gouraud shading. ``ranges`` fixes the colour range of a field (so that scenarios
    compare); otherwise the 0.5-99.5 percentiles of the section values are used, symmetric
    about 1 for stretches (``lambda*``). With ``outline``, the reference section's boundary is
    drawn in black and the deformed one in magenta.
    """
    X = np.asarray(nodes_mm, dtype=float)
    u = np.asarray(u_mm, dtype=float)
    T = np.asarray(tets) if tet_mask is None else np.asarray(tets)[np.asarray(tet_mask)]
    names = list(fields)
    stacked = np.column_stack([u] + [np.asarray(fields[f], dtype=float) for f in names])
    centre = np.asarray(centre_mm, dtype=float)
    ranges = ranges or {}
    sections = {}
    for plane in planes:
        normal_axis = PLANES[plane][0]
        sections[plane] = section_triangles(X, T, stacked, centre, np.eye(3)[normal_axis])

    fig, axes = plt.subplots(len(names), len(planes), figsize=(4.4 * len(planes),
                                                               3.6 * len(names)),
                             squeeze=False)
    fig.subplots_adjust(left=0.09, right=0.97, bottom=0.04, top=0.93, wspace=0.25, hspace=0.28)
    for row, name in enumerate(names):
        field_key = _field_key(name)
        vals = [sec.values[:, 3 + row] for sec in sections.values() if len(sec.triangles)]
        vmin, vmax = ranges.get(name) or (_limits(field_key, vals) if vals else (0.0, 1.0))
        im = None
        for col, plane in enumerate(planes):
            ax = axes[row][col]
            im = _draw_section(ax, sections[plane], plane, 3 + row, name, vmin, vmax, outline)
            if row == 0:
                normal_axis = PLANES[plane][0]
                ax.set_title(f"{plane} ({'xyz'[normal_axis]} = {centre[normal_axis]:.0f} mm)",
                             fontsize=10)
        if im is not None:
            fig.colorbar(im, ax=list(axes[row]), shrink=0.85, label=LABELS.get(field_key, name))
    if title:
        fig.suptitle(title, fontsize=11)
    return _save(fig, path, dpi=dpi, bbox_inches=None)


def section_centre_mm(bm, flap: str | None) -> np.ndarray:
    """Where a scenario's sections cross (mm): the flap centre of the brain mesh ``bm``
    pulled half way towards the brain centre (inside the tissue), or the brain centre
    without a flap."""
    centre = np.asarray(bm.envelope.centre_mm(), dtype=float)
    if flap not in bm.flaps:
        return centre
    return 0.5 * (np.asarray(bm.flaps[flap].centre_mm, dtype=float) + centre)


def _field_key(name: str) -> str:
    """The key of ``results.figures.LABELS``/``CMAPS`` for a display name like ``"|u|"``."""
    aliases = {"|u|": "u_magnitude", "max principal strain": "max_principal_strain"}
    return aliases.get(name, name)


def _draw_section(ax, sec: Section, plane: str, column: int, name: str, vmin: float,
                  vmax: float, outline: bool):
    _, h, v, (left, right), (bottom, top) = PLANES[plane]
    ax.set_aspect("equal")
    ax.set_xlabel(f"{'xyz'[h]} (mm)  [{left} | {right}]", fontsize=8)
    ax.set_ylabel(f"{'xyz'[v]} (mm)  [{bottom} | {top}]", fontsize=8)
    ax.tick_params(labelsize=7)
    if len(sec.triangles) == 0:
        ax.text(0.5, 0.5, "plane misses the mesh", transform=ax.transAxes, ha="center")
        return None
    ref = sec.points[:, [h, v]]
    cur = ref + sec.values[:, [h, v]]
    tri = mtri.Triangulation(cur[:, 0], cur[:, 1], sec.triangles)
    im = ax.tripcolor(tri, sec.values[:, column], shading="gouraud", vmin=vmin, vmax=vmax,
                      cmap=CMAPS.get(_field_key(name), "viridis"))
    if outline:
        edges = sec.boundary_edges()
        ax.add_collection(LineCollection(ref[edges], **UNDEFORMED_OUTLINE))
        ax.add_collection(LineCollection(cur[edges], **DEFORMED_OUTLINE))
    for text, x, y, ha, va in [(left, 0.01, 0.5, "left", "center"),
                               (right, 0.99, 0.5, "right", "center"),
                               (bottom, 0.5, 0.01, "center", "bottom"),
                               (top, 0.5, 0.99, "center", "top")]:
        ax.text(x, y, text, transform=ax.transAxes, ha=ha, va=va, fontsize=8, color="0.35")
    lo = np.minimum(ref.min(axis=0), cur.min(axis=0))
    hi = np.maximum(ref.max(axis=0), cur.max(axis=0))
    pad = 0.03 * (hi - lo).max()
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    return im
