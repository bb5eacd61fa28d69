"""Views of the deformed brain surface coloured by a field, in the layout of the paper's
Figure 9 (PNG, matplotlib only: headless, no OpenGL).

The outer surface of the parenchyma (the tets that are not CSF filler; outward triangles) is
drawn at its deformed position
``x = X + u`` in an orthographic projection along a view direction ``d``: triangles facing
the viewer (``n . d < 0`` with ``n`` the deformed outward normal) are painted back to front
(painter's algorithm, by their centroid's depth), each in the colour of the mean of its
vertices' values, darkened by a Lambert factor ``0.55 + 0.45 |n . d|`` so that the shape
reads. The flap's rim (edges between flap and skull faces) is drawn in black.

Two views: ``"above"`` (looking down the -z axis, the patient's right on the right, anterior
up) and ``"flap"`` (looking at the flap's centre from outside, superior up). Colour ranges come
from the data (:func:`shared_ranges`: percentiles of the surface's vertices; stretches and
``Je`` centred on 1), shared across scenarios by :func:`plot_study_surfaces`, so that pictures
compare; the colour bars say so.

``surface.npz`` also keeps ``Je`` and the transverse and sagittal :class:`Cut` of the
parenchyma through the sections' centre, for the interactive ``view.html``
(:mod:`brainbulge.results.present.webview`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib import colors as mcolors  # noqa: E402
from matplotlib.collections import LineCollection, PolyCollection  # noqa: E402

from brainbulge.atomic import atomic_output
from brainbulge.geometry.brain.boundaries import faces_once
from brainbulge.results.present.figures import (  # noqa: E402
    CMAPS,
    LABELS,
    _limits,
    _save,
    centred_on_one,
    range_note,
)
from brainbulge.results.present.sections import (  # noqa: E402
    PLANES,
    section_centre_mm,
    section_triangles,
)

#: the four fields of the paper's Figure 9: (point-data key, title)
SURFACE_FIELDS: dict[str, str] = {
    "u_magnitude": "|u| [mm]",
    "max_principal_strain": "max principal strain",
    "lambda_n": r"radial stretch $\lambda_n$",
    "lambda_t": r"tangential stretch $\lambda_t$",
}
#: the fields kept in ``surface.npz`` and shown by ``view.html``: the four above and Je
VIEW_FIELDS: dict[str, str] = {**SURFACE_FIELDS, "Je": "elastic volume ratio Je = J/Js"}
#: the sections kept for ``view.html`` (as in ``sections.png``)
CUT_PLANES = ("transverse", "sagittal")
VIEWS = ("above", "flap")
#: parenchyma faces within this distance of the skull surface's flap count as the flap's
FLAP_DEPTH_MM = 8.0
RIM = {"color": "black", "lw": 1.2}


@dataclass
class Cut:
    """A planar section of the parenchyma (:func:`~brainbulge.results.present.sections.
    section_triangles`): reference ``points`` (p, 3) mm, ``triangles`` (t, 3), displacement
    ``u`` (p, 3) mm and nodal ``fields`` there."""

    points: np.ndarray
    triangles: np.ndarray
    u: np.ndarray
    fields: dict[str, np.ndarray]


@dataclass
class Surface:
    """A deformed outer surface: reference ``points`` (n, 3) mm, outward ``faces`` (f, 3),
    displacement ``u`` (n, 3) mm, nodal ``fields`` (name -> (n,)), the faces under the flap
    ``flap_faces`` (bool (f,)), ``flap_direction`` (unit vector from the brain's centre to the
    flap) and the flap's ``rim`` (e, 2): edges between points, drawn as a line (default: the
    boundary of ``flap_faces``); ``cuts``: sections of the parenchyma by plane name
    (:data:`CUT_PLANES`), with the ``cut_centre`` (mm) they pass through."""

    points: np.ndarray
    faces: np.ndarray
    u: np.ndarray
    fields: dict[str, np.ndarray]
    flap_faces: np.ndarray
    flap_direction: np.ndarray
    rim: np.ndarray | None = None
    cuts: dict[str, Cut] = dataclasses.field(default_factory=dict)
    cut_centre: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.rim is None:
            self.rim = _rim_edges(np.asarray(self.faces), np.asarray(self.flap_faces, bool))

    def save(self, path: Path) -> Path:
        """``surface.npz`` of a scenario: what :func:`plot_study_surfaces` and ``view.html``
        read."""
        cuts = {}
        for plane, c in self.cuts.items():
            cuts |= {f"cut_{plane}_points": c.points, f"cut_{plane}_triangles": c.triangles,
                     f"cut_{plane}_u": c.u,
                     **{f"cut_{plane}_field_{k}": v for k, v in c.fields.items()}}
        if self.cut_centre is not None:
            cuts["cut_centre"] = self.cut_centre
        with atomic_output(Path(path)) as tmp:
            np.savez_compressed(tmp, points=self.points, faces=self.faces, u=self.u,
                                flap_faces=self.flap_faces,
                                flap_direction=self.flap_direction, rim=self.rim,
                                **{f"field_{k}": v for k, v in self.fields.items()}, **cuts)
        return Path(path)

    @classmethod
    def load(cls, path: Path) -> Surface:
        d = np.load(path)
        fields = {k[len("field_"):]: d[k] for k in d.files if k.startswith("field_")}
        cuts = {}
        for plane in CUT_PLANES:
            pre = f"cut_{plane}_"
            if pre + "points" in d.files:
                cuts[plane] = Cut(d[pre + "points"], d[pre + "triangles"], d[pre + "u"],
                                  {k[len(pre + "field_"):]: d[k] for k in d.files
                                   if k.startswith(pre + "field_")})
        return cls(d["points"], d["faces"], d["u"], fields, d["flap_faces"],
                   d["flap_direction"], d["rim"] if "rim" in d.files else None, cuts,
                   d["cut_centre"] if "cut_centre" in d.files else None)

    def surface_values(self, name: str) -> np.ndarray:
        """Field ``name`` at the vertices of the faces (the points off the surface carry
        no value of it)."""
        return np.asarray(self.fields[name], dtype=float)[np.unique(self.faces)]


def view_frame(view: str, flap_direction: np.ndarray) -> np.ndarray:
    """Rows: the screen's right and up axes and the view direction ``d`` (into the screen)."""
    if view == "above":
        return np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])
    d = -np.asarray(flap_direction, dtype=float)
    d /= np.linalg.norm(d)
    up = np.array([0.0, 0.0, 1.0]) - d[2] * d
    if np.linalg.norm(up) < 1e-6:  # a flap on the vertex: anterior up
        up = np.array([0.0, 1.0, 0.0]) - d[1] * d
    up /= np.linalg.norm(up)
    return np.array([np.cross(d, up), up, d])


def draw_surface(ax, s: Surface, field: str, view: str, vmin: float, vmax: float,
                 cmap: str) -> mcolors.ScalarMappable:
    """Paint the surface's facing triangles on ``ax`` (see the module docstring)."""
    R = view_frame(view, s.flap_direction)
    x = s.points + s.u
    tri = x[s.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    facing = n @ R[2] < 0
    depth = tri.mean(axis=1) @ R[2]
    order = np.flatnonzero(facing)[np.argsort(-depth[facing])]  # farthest first
    screen = tri[order] @ R[:2].T  # (k, 3, 2)
    norm = mcolors.Normalize(vmin, vmax)
    mappable = plt.cm.ScalarMappable(norm=norm, cmap=cmap)
    value = np.asarray(s.fields[field], dtype=float)[s.faces[order]].mean(axis=1)
    rgba = mappable.to_rgba(value)
    rgba[:, :3] *= (0.55 + 0.45 * np.abs(n[order] @ R[2]))[:, None]
    ax.add_collection(PolyCollection(screen, facecolors=rgba, edgecolors=rgba, linewidths=0.3))
    if len(s.rim):  # the rim's edges on the viewer's side of the brain's centre
        mid = x[s.rim].mean(axis=1)
        near = (mid - x.mean(axis=0)) @ R[2] < 0
        ax.add_collection(LineCollection(x[s.rim[near]] @ R[:2].T, **RIM))
    all_xy = x @ R[:2].T
    lo, hi = all_xy.min(axis=0), all_xy.max(axis=0)
    pad = 0.03 * (hi - lo).max()
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_axis_off()
    return mappable


def _rim_edges(faces: np.ndarray, flap: np.ndarray) -> np.ndarray:
    """Edges (e, 2) of the flap faces that are not shared by two flap faces."""
    f = faces[flap]
    if len(f) == 0:
        return np.zeros((0, 2), dtype=int)
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    uniq, counts = np.unique(e, axis=0, return_counts=True)
    return uniq[counts == 1]


def _cmap(field: str) -> str:
    return CMAPS.get(field, "viridis")


def plot_surface_views(s: Surface, path: str | Path, title: str = "",
                       ranges: dict[str, tuple[float, float]] | None = None,
                       dpi: int = 100) -> Path:
    """One scenario: the four fields (columns) seen from above and from the flap (rows);
    colour ranges from its data (:func:`shared_ranges`) unless given."""
    ranges = {**shared_ranges([s]), **(ranges or {})}
    fig, axes = plt.subplots(len(VIEWS), len(SURFACE_FIELDS), squeeze=False,
                             figsize=(3.3 * len(SURFACE_FIELDS), 3.2 * len(VIEWS)),
                             layout="constrained")
    for col, (field, label) in enumerate(SURFACE_FIELDS.items()):
        m = None
        for row, view in enumerate(VIEWS):
            m = draw_surface(axes[row][col], s, field, view, *ranges[field], _cmap(field))
            if col == 0:
                axes[row][col].text(-0.05, 0.5, "from above" if view == "above" else
                                    "from the flap", transform=axes[row][col].transAxes,
                                    rotation=90, ha="right", va="center", fontsize=9)
        fig.colorbar(m, ax=[axes[r][col] for r in range(len(VIEWS))], orientation="horizontal",
                     shrink=0.8, label=LABELS.get(field, label) if field != "u_magnitude"
                     else label)
    fig.suptitle((f"{title}\n" if title else "") + ranges_note(), fontsize=10)
    return _save(fig, path, dpi=dpi, bbox_inches=None)


def ranges_note() -> str:
    """How :func:`shared_ranges` chooses the colour ranges, for a figure's title."""
    return (f"colour ranges: |u| and strain {range_note('u_magnitude', from_zero=True)}, "
            f"stretches {range_note('lambda_n')}")


def shared_ranges(surfaces: Sequence[Surface]) -> dict[str, tuple[float, float]]:
    """Per field (of :data:`VIEW_FIELDS` that all ``surfaces`` have), one colour range over
    the values at their surface vertices (:meth:`Surface.surface_values`; the points off the
    surface hold no value): 0 to the largest upper percentile
    (:data:`~brainbulge.results.present.figures.RANGE_PERCENTILES`) for |u| and strain, from the
    percentiles and symmetric about 1 for stretches and Je
    (:func:`~brainbulge.results.present.figures.range_note`)."""
    out: dict[str, tuple[float, float]] = {}
    for name in VIEW_FIELDS:
        if not all(name in s.fields for s in surfaces):
            continue
        lo, hi = _limits(name, [s.surface_values(name) for s in surfaces])
        out[name] = (lo, hi) if centred_on_one(name) else (0.0, max(hi, 1e-6))
    return out


def plot_study_surfaces(surfaces: dict[str, Surface], path: str | Path, view: str,
                        dpi: int = 90) -> Path:
    """The paper's Figure 9 for a study: scenarios (rows) x the four fields (columns), one
    view, one colour range per field shared by all scenarios."""
    ranges = shared_ranges(list(surfaces.values()))
    n = len(surfaces)
    fig, axes = plt.subplots(n, len(SURFACE_FIELDS), squeeze=False,
                             figsize=(2.8 * len(SURFACE_FIELDS), 2.6 * n + 0.8),
                             layout="constrained")
    for col, (field, label) in enumerate(SURFACE_FIELDS.items()):
        m = None
        for row, (name, s) in enumerate(surfaces.items()):
            m = draw_surface(axes[row][col], s, field, view, *ranges[field], _cmap(field))
            if col == 0:
                axes[row][col].text(-0.05, 0.5, name, transform=axes[row][col].transAxes,
                                    rotation=90, ha="right", va="center", fontsize=8)
        fig.colorbar(m, ax=[axes[r][col] for r in range(n)], orientation="horizontal",
                     shrink=0.8, aspect=30, label=label)
    fig.suptitle(f"deformed surface seen {'from above' if view == 'above' else 'from the flap'}"
                 f"\n{ranges_note()}, shared by the scenarios", fontsize=10)
    return _save(fig, path, dpi=dpi, bbox_inches=None)


def brain_surface(nodes: np.ndarray, tets: np.ndarray, brain_tets: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The boundary of the tets in ``brain_tets`` (bool): triangles (f, 3) oriented outward
    (away from their tet's fourth vertex) and the tet of each."""
    T = np.asarray(tets)[brain_tets]
    owner = np.flatnonzero(brain_tets)
    local = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    tri = T[:, local].reshape(-1, 3)
    once = faces_once(tri)
    tri, tet = tri[once], np.repeat(owner, 4)[once]
    opposite = np.asarray(tets)[tet, np.tile(np.arange(4), len(T))[once]]  # face k: not k
    X = np.asarray(nodes, dtype=float)
    n = np.cross(X[tri[:, 1]] - X[tri[:, 0]], X[tri[:, 2]] - X[tri[:, 0]])
    inward = np.einsum("ij,ij->i", n, X[opposite] - X[tri[:, 0]]) > 0
    tri[inward] = tri[inward][:, [0, 2, 1]]
    return tri, tet


def write_surface_views(vf, bm, flap: str, out_dir: Path, title: str = "") -> Path:
    """A scenario's ``surface.png`` and ``surface.npz``: the surface of the parenchyma (the
    brain without the CSF filler around it) of the brain mesh ``bm`` (a
    :class:`~brainbulge.geometry.brain.BrainMesh`) with its vertex fields ``vf`` (a
    :class:`~brainbulge.results.export.writers.VertexFields` on ``bm``'s nodes; its regions named
    ``csf_*`` are the filler): each field at a vertex is the mean of the element values of the
    parenchyma tets around it. The flap's rim is
    that of the skull surface's flap."""
    centre = np.asarray(bm.envelope.centre_mm(), dtype=float)
    csf = np.array([str(n).startswith("csf") for n in vf.region_names] + [False])
    brain = ~csf[np.asarray(vf.regions)]
    faces, _ = brain_surface(vf.points, vf.cells, brain)
    fields = {}
    vid = np.asarray(vf.cells)[brain].ravel()
    count = np.maximum(np.bincount(vid, minlength=len(vf.points)), 1)
    for k in VIEW_FIELDS:
        if k in vf.cell_data:
            cell = np.repeat(np.asarray(vf.cell_data[k], dtype=float)[brain], 4)
            fields[k] = np.bincount(vid, weights=cell, minlength=len(vf.points)) / count
    if flap in bm.flaps:
        # the parenchyma faces under the flap: nearest to a flap face of the outer surface,
        # within FLAP_DEPTH_MM of it (not the walls of a ventricle below the flap)
        from scipy.spatial import cKDTree

        outer = vf.points[np.asarray(bm.faces)].mean(axis=1)
        dist, near = cKDTree(outer).query(vf.points[faces].mean(axis=1))
        on_flap = np.asarray(bm.flap_faces[flap], dtype=bool)
        mask = on_flap[near] & (dist < FLAP_DEPTH_MM)
        rim = _rim_edges(np.asarray(bm.faces), on_flap)  # on the skull surface: a clean curve
        direction = np.asarray(bm.flaps[flap].centre_mm, dtype=float) - centre
    else:  # intact skull: seen from the left
        mask = np.zeros(len(faces), dtype=bool)
        rim = np.zeros((0, 2), dtype=int)
        direction = np.array([-1.0, 0.0, 0.0])
    u = np.asarray(vf.point_data["u"], dtype=float)
    cut_centre = section_centre_mm(bm, flap)
    s = Surface(np.asarray(vf.points, dtype=float), faces, u, fields, mask,
                direction / np.linalg.norm(direction), rim,
                cuts_of(vf.points, np.asarray(vf.cells)[brain], u, fields, cut_centre),
                cut_centre)
    s.save(Path(out_dir) / "surface.npz")
    from brainbulge.results.present.webview import write_view_html

    write_view_html(s, Path(out_dir) / "view.html", title=title)
    return plot_surface_views(s, Path(out_dir) / "surface.png", title=title)


def cuts_of(points: np.ndarray, tets: np.ndarray, u: np.ndarray,
            fields: dict[str, np.ndarray], centre: np.ndarray) -> dict[str, Cut]:
    """The :data:`CUT_PLANES` sections of the tets ``tets`` through ``centre`` (mm), with
    ``u`` and the nodal ``fields`` interpolated on them."""
    names = list(fields)
    stacked = np.column_stack([u] + [fields[k] for k in names])
    cuts = {}
    for plane in CUT_PLANES:
        sec = section_triangles(points, tets, stacked, centre, np.eye(3)[PLANES[plane][0]])
        cuts[plane] = Cut(sec.points, sec.triangles, sec.values[:, :3],
                          {k: sec.values[:, 3 + i] for i, k in enumerate(names)})
    return cuts


def write_study_surfaces(out_dir: Path, names: Sequence[str]) -> list[Path]:
    """``surfaces-above.png`` and ``surfaces-flap.png`` of a study from its scenarios'
    ``surface.npz`` (those that have one)."""
    surfaces = {n: Surface.load(Path(out_dir) / n / "surface.npz") for n in names
                if (Path(out_dir) / n / "surface.npz").is_file()}
    if not surfaces:
        return []
    return [plot_study_surfaces(surfaces, Path(out_dir) / f"surfaces-{view}.png", view)
            for view in VIEWS]
