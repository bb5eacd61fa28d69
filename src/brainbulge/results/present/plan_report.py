"""The craniectomy plan's table, figures and report.

- ``plan.csv``: one row per (centre, diameter), refused and failed plans included.
- ``pareto.png``: flap area against each damage measure (:data:`MEASURES`), the Pareto front
  (no other plan has a smaller or equal area and a smaller or equal damage, one of them
  strictly) marked.
- ``centres.png``: the skull surface seen from the side of each hemisphere with candidates,
  each centre coloured by the least strained volume of its diameters.
- ``report.md``: the recommendation (:func:`recommend`) against the 12 cm guideline and the
  median clinical flap area; ``report.html`` the same with the head in 3D, every candidate
  flap drawn where it lies, coloured by a damage measure of choice (:func:`plan_scene`).

**The recommendation rule.** Among the plans that converged, the least strained volume
``V_min`` sets a tolerance ``V_min + max(RECOMMEND_REL_TOL V_min, RECOMMEND_ABS_TOL_ML)``;
the recommended plan is the one of smallest flap area within it (equal areas: the less
damage). A larger flap within the tolerance removes more bone for a damage the estimate
cannot tell apart.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from brainbulge.results.present.html_report import block_marker
from brainbulge.results.records.run_record import atomic_output, atomic_write_text

if TYPE_CHECKING:
    from brainbulge.geometry.brain import BrainMesh
    from brainbulge.model.brain import CraniectomyCase

#: the damage measure the recommendation minimises
PRIMARY = "strained_volume_ml"
#: damage measures of the Pareto figure: key -> (label, unit); midline shift as |shift|
MEASURES = {
    "strained_volume_ml": ("strained volume", "ml"),
    "p99_principal_strain": ("p99 principal strain", "-"),
    "rim_max_principal_strain": ("peak strain 5-10 mm from the rim", "-"),
    "rim_max_tangential_stretch": ("peak lambda_t 5-10 mm from the rim", "-"),
    "max_displacement_mm": ("bulge height max |u|", "mm"),
    "abs_midline_shift_mm": ("|midline shift|", "mm"),
}
#: tolerance of the recommendation: relative to the least damage, and its floor [ml]
RECOMMEND_REL_TOL = 0.10
RECOMMEND_ABS_TOL_ML = 0.5
#: the clinical guideline: a unilateral flap of at least 12 cm diameter
GUIDELINE_DIAMETER_MM = 120.0
#: median reported flap area [cm^2] (reported range 9.5-205 cm^2)
MEDIAN_CLINICAL_AREA_CM2 = 134.8
COLUMNS = ("name", "centre_index", "side", "centre_x_mm", "centre_y_mm", "centre_z_mm",
           "diameter_mm", "flap_area_cm2", "clipped_area_cm2", "converged",
           "max_displacement_mm", "p99_principal_strain", "strained_volume_ml",
           "strained_volume_fraction", "midline_shift_mm", "rim_max_principal_strain",
           "rim_max_tangential_stretch", "rim_p95_principal_strain", "bulge_volume_ml",
           "newton_iterations", "warm_start_from", "wall_time_s", "note")


def plan_rows(cases: list[CraniectomyCase], results: list[dict[str, Any]]
              ) -> list[dict[str, Any]]:
    """One flat row (:data:`COLUMNS`) per case from its run's summary row."""
    rows = []
    for case, r in zip(cases, results, strict=True):
        centre = case.extra.get("centre_on_skull_mm") or case.flap_centre_mm
        done = bool(r.get("complete"))
        shift = r.get("midline_shift_mm")
        rows.append({
            "name": case.name, "centre_index": case.extra.get("centre_index"),
            "side": case.extra.get("side"),
            "centre_x_mm": centre[0], "centre_y_mm": centre[1], "centre_z_mm": centre[2],
            "diameter_mm": case.flap_diameter_mm,
            "flap_area_cm2": r.get("plan_flap_area_cm2", case.extra.get("flap_area_cm2")),
            "clipped_area_cm2": case.extra.get("clipped_area_cm2"),
            "converged": done and bool(r.get("converged")),
            "max_displacement_mm": r.get("max_displacement"),
            "p99_principal_strain": r.get("p99_principal_strain"),
            "strained_volume_ml": r.get("strained_volume_ml"),
            "strained_volume_fraction": r.get("strained_volume_fraction"),
            "midline_shift_mm": shift,
            "abs_midline_shift_mm": None if shift is None else abs(shift),
            "rim_max_principal_strain": r.get("rim_max_principal_strain"),
            "rim_max_tangential_stretch": r.get("rim_max_tangential_stretch"),
            "rim_p95_principal_strain": r.get("rim_p95_principal_strain"),
            "bulge_volume_ml": r.get("bulge_volume_ml"),
            "newton_iterations": r.get("newton_iterations"),
            "warm_start_from": r.get("warm_start_from"),
            "wall_time_s": r.get("wall_time_s"),
            "note": "" if done else r.get("error", "not run"),
        })
    return rows


def _ok(rows: list[dict[str, Any]], key: str) -> list[dict[str, Any]]:
    return [r for r in rows if r.get("converged") and _finite(r.get(key))
            and _finite(r.get("flap_area_cm2"))]


def _finite(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def pareto_front(area: np.ndarray, damage: np.ndarray) -> np.ndarray:
    """Mask of the Pareto-optimal points of (area, damage), both to be minimised: no other
    point has ``area <=`` and ``damage <=`` with one of them strict."""
    a, d = np.asarray(area, float), np.asarray(damage, float)
    dominated = ((a[None, :] <= a[:, None]) & (d[None, :] <= d[:, None])
                 & ((a[None, :] < a[:, None]) | (d[None, :] < d[:, None])))
    return ~dominated.any(axis=1)


def recommend(rows: list[dict[str, Any]], key: str = PRIMARY,
              rel_tol: float = RECOMMEND_REL_TOL, abs_tol: float = RECOMMEND_ABS_TOL_ML
              ) -> tuple[dict[str, Any] | None, float, float]:
    """The recommended row (module docstring), the least damage and the tolerance's upper
    bound; None when no plan converged."""
    ok = _ok(rows, key)
    if not ok:
        return None, math.nan, math.nan
    least = min(r[key] for r in ok)
    bound = least + max(rel_tol * least, abs_tol)
    within = [r for r in ok if r[key] <= bound]
    best = min(within, key=lambda r: (r["flap_area_cm2"], r[key]))
    return best, least, bound


def write_plan_table(path: Path, rows: list[dict[str, Any]]) -> Path:
    """``plan.csv`` (:data:`COLUMNS`), atomically."""
    with atomic_output(Path(path)) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for r in rows:
            w.writerow(["" if r.get(k) is None else r.get(k) for k in COLUMNS])
    return Path(path)


def write_pareto_figure(path: Path, rows: list[dict[str, Any]]) -> Path:
    """``pareto.png``: one panel per damage measure against the flap area."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(14, 8), layout="constrained")
    sc = None
    for ax, (key, (label, unit)) in zip(axes.ravel(), MEASURES.items(), strict=True):
        ok = _ok(rows, key)
        ax.set_xlabel("flap area [cm2]")
        ax.set_ylabel(f"{label} [{unit}]")
        ax.axvline(MEDIAN_CLINICAL_AREA_CM2, color="0.6", ls=":", lw=1)
        if not ok:
            ax.text(0.5, 0.5, "no converged plan", ha="center", transform=ax.transAxes)
            continue
        a = np.array([r["flap_area_cm2"] for r in ok])
        d = np.array([r[key] for r in ok])
        dia = np.array([r["diameter_mm"] for r in ok])
        sc = ax.scatter(a, d, c=dia, cmap="viridis", s=22, zorder=2)
        front = pareto_front(a, d)
        order = np.argsort(a[front])
        ax.plot(a[front][order], d[front][order], "-o", color="#d62728", mfc="none", ms=9,
                lw=1.2, zorder=3, label="Pareto front")
        ax.legend(fontsize=7, loc="best")
    if sc is not None:
        fig.colorbar(sc, ax=axes, label="diameter [mm]", shrink=0.6)
    fig.suptitle("craniectomy plan: flap area against damage (dotted: median clinical area "
                 f"{MEDIAN_CLINICAL_AREA_CM2} cm2)")
    with atomic_output(Path(path)) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return Path(path)


def write_centre_map(path: Path, rows: list[dict[str, Any]], bm: BrainMesh,
                     key: str = PRIMARY) -> Path:
    """``centres.png``: the outer surface seen from each hemisphere's side (anterior to the
    right on the left view, to the left on the right view), each candidate centre coloured by
    the least ``key`` over its diameters and labelled with that diameter."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    sides = sorted({r["side"] for r in rows if r.get("side")}) or ["left"]
    best: dict[int, dict[str, Any]] = {}
    for r in _ok(rows, key):
        i = r["centre_index"]
        if i not in best or r[key] < best[i][key]:
            best[i] = r
    values = [r[key] for r in best.values()]
    vmin, vmax = (min(values), max(values)) if values else (0.0, 1.0)
    fig, axes = plt.subplots(1, len(sides), figsize=(6.5 * len(sides), 5.2), squeeze=False)
    nodes, faces = bm.nodes_mm, bm.faces
    normals = np.cross(nodes[faces[:, 1]] - nodes[faces[:, 0]],
                       nodes[faces[:, 2]] - nodes[faces[:, 0]])
    sc = None
    for ax, side in zip(axes[0], sides, strict=True):
        view = -1.0 if side == "left" else 1.0  # the viewer on the patient's left or right
        facing = normals[:, 0] * view > 0
        depth = nodes[faces[facing]].mean(axis=1)[:, 0] * view
        tri = faces[facing][np.argsort(depth)]
        y = nodes[:, 1] * (-view)  # anterior to the right, seen from the left
        polys = np.stack([y[tri], nodes[tri][:, :, 2]], axis=-1)
        ax.add_collection(PolyCollection(polys, facecolor="0.85", edgecolor="0.7", lw=0.2))
        for r in rows:
            if r.get("side") != side:
                continue
            i = r["centre_index"]
            xy = (r["centre_y_mm"] * (-view), r["centre_z_mm"])
            if i in best and best[i] is r:
                sc = ax.scatter(*xy, c=[r[key]], cmap="magma_r", vmin=vmin, vmax=vmax,
                                s=160, edgecolor="k", zorder=3)
                ax.annotate(f"c{i:02d}\n{r['diameter_mm']:g} mm", xy, fontsize=7,
                            ha="center", va="bottom", xytext=(0, 9),
                            textcoords="offset points")
            elif i not in best:
                ax.scatter(*xy, marker="x", color="k", s=40, zorder=3)
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_title(f"{side} hemisphere (seen from the {side})")
        ax.set_xlabel("posterior <- y [mm] -> anterior" if side == "left"
                      else "anterior <- y [mm] -> posterior")
        ax.set_ylabel("z [mm]")
    if sc is not None:
        fig.colorbar(sc, ax=axes.ravel().tolist(),
                     label=f"least {MEASURES[key][0]} [{MEASURES[key][1]}]", shrink=0.8)
    fig.suptitle("candidate flap centres (x: no converged plan)")
    with atomic_output(Path(path)) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return Path(path)


def write_plan_report(out_dir: Path, cases: list[CraniectomyCase],
                      results: list[dict[str, Any]], bm: BrainMesh,
                      threshold: float) -> list[Path]:
    """``plan.csv``, ``pareto.png``, ``centres.png``, ``report.md`` and ``report.html`` in
    ``out_dir``."""
    out_dir = Path(out_dir)
    rows = plan_rows(cases, results)
    paths = [write_plan_table(out_dir / "plan.csv", rows),
             write_pareto_figure(out_dir / "pareto.png", rows),
             write_centre_map(out_dir / "centres.png", rows, bm)]
    paths.append(atomic_write_text(out_dir / "report.md",
                                   report_text(rows, cases[0], threshold)))
    from brainbulge.results.present.html_report import write_report_html
    from brainbulge.results.present.webview import views_html

    paths.append(write_report_html(out_dir / "report.md",
                                   {"plan": views_html([plan_scene(out_dir, rows, bm)], "plan")}))
    return paths


#: the flap outlines of the plan's 3D view: width and height above the head [mm]; the
#: recommended flap's outline has a wider halo in RECOMMENDED_COLOUR below its own
FLAP_LINE_MM = (1.6, 0.8)
RECOMMENDED_LINE_MM = (4.5, 0.4)
RECOMMENDED_COLOUR = (0.0, 0.75, 0.3)
#: the colour scale of the damage measures (as in ``centres.png``)
MEASURE_CMAP = "magma_r"


def plan_scene(out_dir: Path, rows: list[dict[str, Any]], bm: BrainMesh) -> dict[str, Any]:
    """The plan's 3D view: the head (outer surface of ``bm``) with the outline of every
    candidate flap that ran (its folder's ``surface.npz``) coloured by the chosen damage
    measure (:data:`MEASURES`; grey: not converged), the recommended one in green, and a
    cross at the centre of each candidate that did not run (refused)."""
    from brainbulge.results.present.views3d import Surface
    from brainbulge.results.present.webview import (
        colour_maps,
        field_info,
        frame,
        line_layer,
        mesh_layer,
        presets,
        ribbons,
    )

    X, faces = np.asarray(bm.nodes_mm, float), np.asarray(bm.faces)
    centre = np.asarray(bm.envelope.centre_mm(), float)
    best = recommend(rows)[0]
    layers = [mesh_layer(X, None, faces, name="head", color=(0.86, 0.84, 0.8))]
    pts, tris, vals, crosses = [], [], {k: [] for k in MEASURES}, []
    for r in rows:
        npz = Path(out_dir) / str(r["name"]) / "surface.npz"
        if not npz.is_file():
            c = np.array([r["centre_x_mm"], r["centre_y_mm"], r["centre_z_mm"]], float)
            crosses.append(c + 4.0 * np.array([[[-1, 0, 0], [1, 0, 0]], [[0, -1, 0], [0, 1, 0]],
                                               [[0, 0, -1], [0, 0, 1]]]))
            continue
        rim = Surface.load(npz).rim
        if best is not None and r["name"] == best["name"]:
            p, t = ribbons(X, rim, centre, *RECOMMENDED_LINE_MM)
            layers.append(mesh_layer(p, None, t, name=f"recommended {r['name']}",
                                     color=RECOMMENDED_COLOUR))
        p, t = ribbons(X, rim, centre, *FLAP_LINE_MM)
        tris.append(t + sum(len(q) for q in pts))
        pts.append(p)
        for k in MEASURES:
            v = r.get(k)
            vals[k].append(np.full(len(p), v if r.get("converged") and _finite(v) else -1e30))
    if pts:
        layers.append(mesh_layer(np.concatenate(pts), None, np.concatenate(tris), name="flaps",
                                 values={k: np.concatenate(v) for k, v in vals.items()}))
    if crosses:
        c = np.concatenate(crosses).reshape(-1, 3)
        layers.append(line_layer(c, None, np.arange(len(c)).reshape(-1, 2),
                                 name="refused", color=(0.1, 0.1, 0.1)))
    ranges = {}
    for k in MEASURES:
        ok = [r[k] for r in _ok(rows, k)]
        ranges[k] = (min(ok), max(ok)) if ok else (0.0, 1.0)
    direction = (None if best is None else np.array(
        [best["centre_x_mm"], best["centre_y_mm"], best["centre_z_mm"]]) - centre)
    caption = ("Each candidate flap's outline, coloured by the chosen damage measure (grey: "
               "did not converge; crosses: refused centres). "
               + (f"Green: the recommended {best['name']}." if best else "No recommendation."))
    return {"title": "candidate flaps on the head",
            "fields": field_info(ranges, {k: f"{lab} [{u}]" for k, (lab, u) in MEASURES.items()},
                                 dict.fromkeys(MEASURES, "least to most over the converged "
                                               "plans"), dict.fromkeys(MEASURES, MEASURE_CMAP)),
            "cmaps": colour_maps([MEASURE_CMAP]), "layers": layers, "caption": caption,
            "views": presets(direction), **frame(X[np.unique(faces)])}


def report_text(rows: list[dict[str, Any]], base: CraniectomyCase, threshold: float) -> str:
    """``report.md``: the recommendation, its setting against the guideline, the table."""
    best, least, bound = recommend(rows)
    n_ok = len(_ok(rows, PRIMARY))
    lines = [
        "# Craniectomy plan",
        "",
        f"White-matter swelling Js 1 -> {base.swelling:g} ({base.swell}), {len(rows)} "
        f"candidate flaps, {n_ok} converged. Damage: parenchyma (CSF apart) whose maximum "
        f"principal strain exceeds {threshold:g} (Bain & Meaney 2000: 50 % of axons injured "
        "in vitro at 0.18), as a reference volume.",
        "",
        "## Recommendation",
        "",
    ]
    if best is None:
        lines += ["No plan converged: nothing to recommend.", ""]
    else:
        guideline = [r for r in _ok(rows, PRIMARY)
                     if r["diameter_mm"] == GUIDELINE_DIAMETER_MM]
        least_row = min(_ok(rows, PRIMARY), key=lambda r: r[PRIMARY])
        lines += [
            f"**{best['name']}**: the flap of {best['diameter_mm']:g} mm centred at "
            f"({best['centre_x_mm']:.0f}, {best['centre_y_mm']:.0f}, "
            f"{best['centre_z_mm']:.0f}) mm, {best['flap_area_cm2']:.1f} cm2, strained "
            f"volume {best[PRIMARY]:.2f} ml.",
            "",
            f"Rule: the smallest flap whose strained volume is within max("
            f"{RECOMMEND_REL_TOL:.0%}, {RECOMMEND_ABS_TOL_ML:g} ml) of the least "
            f"({least:.2f} ml, {least_row['name']}), i.e. at most {bound:.2f} ml.",
            "",
            f"- Against the guideline (a unilateral flap of >= "
            f"{GUIDELINE_DIAMETER_MM / 10:g} cm): the recommended flap is "
            + ("smaller" if best["diameter_mm"] < GUIDELINE_DIAMETER_MM else
               "as large" if best["diameter_mm"] == GUIDELINE_DIAMETER_MM else "larger")
            + f" ({best['diameter_mm'] / 10:g} cm)"
            + (f"; the best {GUIDELINE_DIAMETER_MM / 10:g} cm flap of the plan "
               f"({min(guideline, key=lambda r: r[PRIMARY])['name']}) strains "
               f"{min(r[PRIMARY] for r in guideline):.2f} ml." if guideline else "."),
            f"- Against the median clinical flap area ({MEDIAN_CLINICAL_AREA_CM2} cm2; "
            f"reported 9.5-205 cm2): {best['flap_area_cm2']:.1f} cm2, "
            f"{best['flap_area_cm2'] / MEDIAN_CLINICAL_AREA_CM2:.0%} of it.",
            "",
        ]
    lines += [block_marker("plan"), "", "![pareto](pareto.png)", "", "![centres](centres.png)",
              "", "## Plans", "",
              "| plan | diameter mm | area cm2 | strained ml | p99 strain | rim peak strain "
              "| max abs u mm | midline shift mm | note |", "|---" * 9 + "|"]

    def f(v: Any, fmt: str) -> str:
        return format(v, fmt) if _finite(v) else "-"

    for r in rows:
        lines.append(
            f"| {r['name']} | {r['diameter_mm']:g} | {f(r['flap_area_cm2'], '.1f')} | "
            f"{f(r['strained_volume_ml'], '.2f')} | {f(r['p99_principal_strain'], '.3f')} | "
            f"{f(r['rim_max_principal_strain'], '.3f')} | "
            f"{f(r['max_displacement_mm'], '.2f')} | {f(r['midline_shift_mm'], '+.2f')} | "
            f"{r['note']} |")
    return "\n".join(lines) + "\n"
