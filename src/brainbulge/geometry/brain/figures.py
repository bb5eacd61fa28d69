"""Figures of the brain mesh: region sections and boundary conditions on the surface (PNG)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from brainbulge.atomic import atomic_output
from brainbulge.geometry.brain.boundaries import SuperiorBand  # noqa: E402
from brainbulge.geometry.brain.brain_mesh import BrainMesh  # noqa: E402
from brainbulge.geometry.brain.labels import TISSUES  # noqa: E402

_TISSUE_COLOURS = {"gray": "#9e9e9e", "white": "#f5f0dc", "csf": "#4f8fd6",
                   "cerebellum": "#c77d3b", "brainstem": "#8a4f9e"}
_BC_COLOURS = {"base": "#d62728", "superior": "#ff7f0e", "skull": "#bdbdbd", "flap": "#2ca02c"}
#: the default fixed superior band, shown in the boundary figure
DEFAULT_SUPERIOR = SuperiorBand()
_BC_LABELS = {"base": "base (fixed)", "superior": "superior (fixed)",
              "skull": "skull (sliding)", "flap": "flap (traction-free)"}


def plot_sections(mesh: BrainMesh, path: str | Path, centre_mm: np.ndarray | None = None,
                  pixel_mm: float = 0.75) -> Path:
    """Sagittal, coronal and axial sections through ``centre_mm`` coloured by tissue, with the
    left hemisphere shaded darker; each pixel shows the tet whose centroid is nearest."""
    centroids = mesh.nodes_mm[mesh.tets].mean(axis=1)
    tree = cKDTree(centroids)
    c = mesh.envelope.centre_mm() if centre_mm is None else np.asarray(centre_mm, float)
    lo, hi = mesh.nodes_mm.min(axis=0) - 2, mesh.nodes_mm.max(axis=0) + 2
    names = list(TISSUES.values())
    colours = np.array([matplotlib.colors.to_rgb(_TISSUE_COLOURS[n]) for n in names])
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.4))
    phi_tol = 0.0
    for ax, (normal_axis, title) in zip(axes, [(0, "sagittal"), (1, "coronal"), (2, "axial")],
                                        strict=True):
        u_axis, v_axis = [a for a in range(3) if a != normal_axis]
        us = np.arange(lo[u_axis], hi[u_axis], pixel_mm)
        vs = np.arange(lo[v_axis], hi[v_axis], pixel_mm)
        uu, vv = np.meshgrid(us, vs)
        pts = np.zeros((uu.size, 3))
        pts[:, normal_axis] = c[normal_axis]
        pts[:, u_axis], pts[:, v_axis] = uu.ravel(), vv.ravel()
        _, nearest = tree.query(pts)
        from brainbulge.geometry.brain.skull import RigidSkull

        inside = RigidSkull(mesh.envelope).envelope_distance(pts, gradient=False)[0] < phi_tol
        rgb = colours[mesh.tissue[nearest] - 1] * np.where(mesh.side[nearest] == 0, 0.8, 1.0
                                                           )[:, None]
        rgb[~inside] = 1.0
        ax.imshow(rgb.reshape(*uu.shape, 3), origin="lower",
                  extent=(us[0], us[-1], vs[0], vs[-1]))
        axis_names = "xyz"
        ax.set_title(f"{title} ({axis_names[normal_axis]} = {c[normal_axis]:.0f} mm)")
        ax.set_xlabel(f"{axis_names[u_axis]} (mm)")
        ax.set_ylabel(f"{axis_names[v_axis]} (mm)")
        if normal_axis != 2:
            ax.axhline(mesh.base_z_mm, color="#d62728", lw=0.8, ls="--")
    handles = [matplotlib.patches.Patch(color=_TISSUE_COLOURS[n], label=n) for n in names]
    fig.legend(handles=handles, loc="lower center", ncol=len(names))
    fig.suptitle(f"brain mesh: {len(mesh.tets):,} tets (left hemisphere darker; "
                 f"dashed: base cut plane)")
    fig.tight_layout(rect=(0, 0.06, 1, 0.95))
    with atomic_output(Path(path)) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return Path(path)


def plot_boundaries(mesh: BrainMesh, path: str | Path, flaps: list[str] | None = None,
                    superior: SuperiorBand | None = DEFAULT_SUPERIOR) -> Path:
    """Outer surface coloured fixed base / fixed superior band / sliding skull / flap, one row
    per flap, five views."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    flaps = list(mesh.flaps) if flaps is None else flaps
    views = [(10, 180, "left"), (10, 0, "right"), (10, 90, "front"), (80, 90, "above"),
             (-60, 90, "below")]
    fig = plt.figure(figsize=(4 * len(views), 4 * len(flaps)))
    tri = mesh.nodes_mm[mesh.faces]
    for row, flap in enumerate(flaps):
        names = mesh.boundary_names(flap, superior)
        colour = np.array([matplotlib.colors.to_rgb(_BC_COLOURS[n]) for n in names])
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normal /= np.linalg.norm(normal, axis=1)[:, None]
        for col, (elev, azim, label) in enumerate(views):
            ax = fig.add_subplot(len(flaps), len(views), row * len(views) + col + 1,
                                 projection="3d")
            e, a = np.radians(elev), np.radians(azim)
            eye = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
            shade = 0.45 + 0.55 * np.clip(normal @ eye, 0, 1)
            visible = normal @ eye > -0.05
            pc = Poly3DCollection(tri[visible], facecolors=colour[visible] * shade[visible, None],
                                  edgecolors="none")
            ax.add_collection3d(pc)
            lo, hi = mesh.nodes_mm.min(axis=0), mesh.nodes_mm.max(axis=0)
            ax.set_xlim(lo[0], hi[0])
            ax.set_ylim(lo[1], hi[1])
            ax.set_zlim(lo[2], hi[2])
            ax.set_box_aspect(hi - lo)
            ax.view_init(elev, azim)
            ax.set_axis_off()
            ax.set_title(f"flap '{flap}' ({mesh.flap_area_cm2(flap):.0f} cm²), {label}")
    handles = [matplotlib.patches.Patch(color=c, label=_BC_LABELS[n])
               for n, c in _BC_COLOURS.items() if superior is not None or n != "superior"]
    fig.legend(handles=handles, loc="lower center", ncol=4)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    with atomic_output(Path(path)) as tmp:
        fig.savefig(tmp, dpi=80)
    plt.close(fig)
    return Path(path)
