"""Figures of 2D fields (matplotlib), in the layouts of the paper's Figures 2-4."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.tri as mtri  # noqa: E402
import numpy as np  # noqa: E402

from brainbulge.results.export.writers import VertexFields  # noqa: E402
from brainbulge.results.records.run_record import atomic_output  # noqa: E402

LABELS = {
    "u_magnitude": "|u|",
    "u_vertical": "vertical displacement",
    "lambda_n": r"radial stretch $\lambda_n$",
    "lambda_t": r"tangential stretch $\lambda_t$",
    "max_principal_strain": "max principal strain",
    "pressure": "pressure [kPa]",
    "J": "J",
    "Je": r"elastic volume ratio $J_e = J/J_s$",
}
#: fields drawn on a diverging scale centred on 1 (no deformation), symmetric about it
CENTRED_ON_ONE = ("lambda_n", "lambda_t", "Je")
CMAPS = {**dict.fromkeys(CENTRED_ON_ONE, "RdBu_r"), "pressure": "coolwarm"}
#: the percentiles of a field's values that set its colour range (the extremes of a few
#: nodes at a singular point would wash out the rest)
RANGE_PERCENTILES = (0.5, 99.5)


def _triangulation(vf: VertexFields, deformed: bool, mask: np.ndarray | None = None):
    xy = vf.points + (vf.point_data["u"] if deformed else 0.0)
    return mtri.Triangulation(xy[:, 0], xy[:, 1], vf.cells, mask=mask)


def _limits(field: str, values: Sequence[np.ndarray]) -> tuple[float, float]:
    """One colour range for ``field`` over all ``values`` (arrays): from the lowest to the
    highest of their :data:`RANGE_PERCENTILES`, symmetric about 1 for
    :data:`CENTRED_ON_ONE` fields (stretch red, compression blue)."""
    lo = min(float(np.percentile(v, RANGE_PERCENTILES[0])) for v in values)
    hi = max(float(np.percentile(v, RANGE_PERCENTILES[1])) for v in values)
    if centred_on_one(field):
        d = max(abs(hi - 1), abs(1 - lo), 1e-6)
        return 1 - d, 1 + d
    return lo, hi if hi > lo else lo + 1e-12


def range_note(field: str, from_zero: bool = False) -> str:
    """How :func:`_limits` chose the colour range of ``field``, for a legend; ``from_zero``:
    the range of a field not centred on 1 starts at 0 instead (3D views)."""
    lo, hi = RANGE_PERCENTILES
    if centred_on_one(field):
        return f"centred on 1, {lo:g}-{hi:g}th percentiles"
    if from_zero:
        return f"0 to the {hi:g}th percentile"
    return f"{lo:g}-{hi:g}th percentiles"


def centred_on_one(field: str) -> bool:
    """Whether ``field`` is a stretch or volume ratio (:data:`CENTRED_ON_ONE`, any
    ``lambda*``), drawn on a diverging scale centred on 1."""
    return field in CENTRED_ON_ONE or field.startswith("lambda")


def _draw(ax, vf: VertexFields, field: str, vmin: float, vmax: float, mask=None):
    tri = _triangulation(vf, deformed=True, mask=mask)
    return ax.tripcolor(
        tri,
        vf.point_data[field],
        shading="gouraud",
        cmap=CMAPS.get(field, "viridis"),
        vmin=vmin,
        vmax=vmax,
    )


def plot_fields(
    vf: VertexFields,
    path: Path,
    title: str = "",
    fields: Sequence[str] = ("u_magnitude", "u_vertical", "lambda_n", "lambda_t"),
    mark: Sequence[float] | None = None,
) -> Path:
    """Panels of fields on the deformed configuration; ``mark`` (a deformed position, e.g.
    a stopped run's ``failure_site``) is drawn as a red cross on each."""
    fig, axes = plt.subplots(1, len(fields), figsize=(4.2 * len(fields), 2.8), squeeze=False)
    for ax, f in zip(axes[0], fields, strict=True):
        vmin, vmax = _limits(f, [vf.point_data[f]])
        im = _draw(ax, vf, f, vmin, vmax)
        _outline(ax, vf)
        if mark is not None:
            ax.plot(mark[0], mark[1], "x", color="red", markersize=8, mew=2,
                    label="largest unbalanced force")
        ax.set_title(LABELS.get(f, f), fontsize=10)
        fig.colorbar(im, ax=ax, shrink=0.8)
    fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def plot_side_by_side(
    left: VertexFields,
    right: VertexFields,
    path: Path,
    labels: tuple[str, str] = ("no-slip", "sliding"),
    fields: Sequence[str] = ("u_magnitude", "u_vertical", "lambda_n", "lambda_t"),
    title: str = "",
) -> Path:
    """The paper's layout: left half of the disk from one run, right half from the other."""
    fig, axes = plt.subplots(1, len(fields), figsize=(4.2 * len(fields), 2.8), squeeze=False)
    for ax, f in zip(axes[0], fields, strict=True):
        vmin, vmax = _limits(f, [left.point_data[f], right.point_data[f]])
        _draw(ax, left, f, vmin, vmax, mask=_half(left, keep_left=True))
        im = _draw(ax, right, f, vmin, vmax, mask=_half(right, keep_left=False))
        _outline(ax, left)
        ax.axvline(0, color="k", lw=0.5)
        ax.set_title(f"{LABELS.get(f, f)}\n{labels[0]} | {labels[1]}", fontsize=9)
        fig.colorbar(im, ax=ax, shrink=0.8)
    fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def plot_grid(
    panels: dict[tuple[float, float], VertexFields],
    field: str,
    path: Path,
    row_label: str = "beta",
    col_label: str = "alpha",
    title: str = "",
    notes: dict[tuple[float, float], str] | None = None,
) -> Path:
    """A grid of one field: rows and columns indexed by the two keys of ``panels`` (and of
    ``notes``). A cell with a note (a run that stopped early: its last converged state, or
    no panel at all) shows the note in red below it; the colour range comes from the cells
    without notes when there are any, so that a stopped run's extremes do not rescale the
    complete ones."""
    notes = notes or {}
    rows = sorted({k[0] for k in (*panels, *notes)})
    cols = sorted({k[1] for k in (*panels, *notes)})
    fig, axes = plt.subplots(
        len(rows), len(cols), figsize=(2.6 * len(cols), 1.6 * len(rows)), squeeze=False
    )
    ranged = [v.point_data[field] for k, v in panels.items() if k not in notes] or [
        v.point_data[field] for v in panels.values()]
    vmin, vmax = _limits(field, ranged) if ranged else (0.0, 1.0)
    im = None
    for i, rv in enumerate(rows):
        for j, cv in enumerate(cols):
            ax = axes[i][j]
            ax.set_axis_off()
            if (rv, cv) in panels:
                im = _draw(ax, panels[(rv, cv)], field, vmin, vmax)
                ax.set_aspect("equal")
            if (rv, cv) in notes:
                ax.text(0.5, -0.02 if (rv, cv) in panels else 0.5, notes[(rv, cv)],
                        transform=ax.transAxes, ha="center", va="top", fontsize=7,
                        color="red")
            if i == 0:
                ax.set_title(f"{col_label} = {cv:g}", fontsize=8)
            if j == 0:
                ax.text(-1.25, 0.5, f"{row_label} = {rv:g}", fontsize=8, rotation=90, va="center")
    if im is not None:
        fig.colorbar(im, ax=axes, shrink=0.6, label=LABELS.get(field, field))
    # above the figure (the tight bounding box takes it in): inside it, the two lines
    # overlapped the column titles of a one-row grid
    fig.suptitle(f"{title or LABELS.get(field, field)}\n(colour range shared: "
                 f"{range_note(field)})", fontsize=10, y=1.0, va="bottom")
    return _save(fig, path)


def plot_row(
    panels: Sequence[tuple[str, VertexFields]], field: str, path: Path, title: str = ""
) -> Path:
    """One field for several runs side by side (e.g. the five disk positions)."""
    return plot_rows(panels, (field,), path, title=title or LABELS.get(field, field))


def plot_rows(
    panels: Sequence[tuple[str, VertexFields]],
    fields: Sequence[str],
    path: Path,
    title: str = "",
    opening_deg: tuple[float, float] | None = None,
) -> Path:
    """Several fields (rows, one colour scale each) for several runs (columns), as the
    paper's disk figure does with ``lambda_n`` and ``lambda_t``; ``opening_deg``: the
    opening's angular extent [deg], drawn as a thick arc on every panel."""
    fig, axes = plt.subplots(len(fields), len(panels),
                             figsize=(3.0 * len(panels), 2.0 * len(fields)), squeeze=False)
    for i, (row, field) in enumerate(zip(axes, fields, strict=True)):
        vmin, vmax = _limits(field, [v.point_data[field] for _, v in panels])
        im = None
        for ax, (label, vf) in zip(row, panels, strict=True):
            im = _draw(ax, vf, field, vmin, vmax)
            _outline(ax, vf, opening_deg)
            if i == 0:
                ax.set_title(label, fontsize=8)
        if im is not None:
            fig.colorbar(im, ax=row, shrink=0.7, label=LABELS.get(field, field))
    notes = "; ".join(range_note(f) for f in dict.fromkeys(fields))
    fig.suptitle(f"{title or ', '.join(LABELS.get(f, f) for f in fields)} (colour range "
                 f"shared: {notes})", fontsize=10)
    return _save(fig, path)


def _half(vf: VertexFields, keep_left: bool) -> np.ndarray:
    cx = vf.points[vf.cells, 0].mean(axis=1)
    return cx > 0 if keep_left else cx < 0


def _outline(ax, vf: VertexFields, opening_deg: tuple[float, float] | None = None) -> None:
    """The undeformed boundary (a semicircle and its base) as a thin line, and the opening's
    arc ``opening_deg`` [deg] as a thick one."""
    r = np.sqrt((vf.points**2).sum(axis=1)).max()
    t = np.linspace(0, np.pi, 200)
    ax.plot(r * np.cos(t), r * np.sin(t), color="0.3", lw=0.6, ls="--")
    if opening_deg is not None:
        t = np.radians(np.linspace(*opening_deg, 60))
        ax.plot(r * np.cos(t), r * np.sin(t), color="tab:red", lw=2.0)
    ax.set_aspect("equal")
    ax.set_axis_off()


def _save(fig, path: Path, dpi: int = 130, bbox_inches: str | None = "tight") -> Path:
    """Write ``fig`` to ``path`` atomically and close it (every results figure ends here)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_output(path) as tmp:
            fig.savefig(tmp, dpi=dpi, bbox_inches=bbox_inches)
    finally:
        plt.close(fig)
    return path
