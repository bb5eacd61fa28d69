"""A craniectomy study's ``table.csv``, ``comparison.png``, ``report.md`` and ``report.html``:
the scenarios' clinical measures side by side, each scenario's sections and the study's
surface views (interactive in ``report.html``)."""

from __future__ import annotations

from pathlib import Path

from brainbulge.results.measures import schema
from brainbulge.results.present.html_report import views_marker, write_report_html
from brainbulge.results.present.views3d import write_study_surfaces
from brainbulge.results.records.run_record import atomic_output, atomic_write_text

#: summary keys of the comparison table and figure -> (label, unit), declared in
#: :mod:`brainbulge.results.measures.schema`
COMPARISON = {key: (schema.label(key), schema.unit(key, schema.BRAIN)) for key in (
    "midline_shift_mm", "bulge_volume_ml", "max_displacement", "max_principal_strain",
    "max_radial_stretch", "max_tangential_stretch", "mean_hydrostatic_stress_kpa")}


def write_comparison(out_dir: Path, scenarios: list[dict], rows: list[dict]) -> list[Path]:
    """``table.csv`` (inputs and summary keys per scenario) and ``comparison.png``."""
    import csv

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    keys: list[str] = []
    for r in rows:
        keys += [k for k, v in r.items() if k not in keys and not isinstance(v, (list, dict))]
    with atomic_output(out_dir / "table.csv") as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["name", "flap", "swell", *keys])
        for sc, r in zip(scenarios, rows, strict=True):
            w.writerow([sc["name"], sc["flap"], sc["swell"], *[r.get(k) for k in keys]])
    done = [(sc, r) for sc, r in zip(scenarios, rows, strict=True) if r.get("complete")]
    fig, axes = plt.subplots(1, len(COMPARISON), figsize=(3.0 * len(COMPARISON), 3.6))
    labels = [f"{sc['flap']}\n{sc['swell']}" for sc, _ in done]
    colours = ["#1f77b4" if sc["flap"] == "left" else "#d62728" for sc, _ in done]
    for ax, (key, (label, unit)) in zip(axes, COMPARISON.items(), strict=True):
        vals = [float(r.get(key) or 0.0) for _, r in done]
        ax.bar(range(len(vals)), vals, color=colours)
        ax.set_xticks(range(len(vals)), labels, fontsize=7)
        ax.set_title(f"{label} [{unit}]", fontsize=9)
        ax.axhline(0, color="k", lw=0.5)
    fig.suptitle("craniectomy scenarios: flap (blue left, red frontal) x swelling side")
    fig.tight_layout()
    with atomic_output(out_dir / "comparison.png") as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return [out_dir / "table.csv", out_dir / "comparison.png"]


def write_report(out_dir: Path, scenarios: list[dict], rows: list[dict]) -> Path:
    """``report.md``: the comparison table and figure, and each scenario's sections; and
    ``report.html``, with the scenarios' interactive 3D views."""
    out_dir = Path(out_dir)
    lines = [
        "# Craniectomy scenarios",
        "",
        f"White-matter swelling Js 1 -> {scenarios[0].get('swelling', 1.1):g}, frictionless "
        "sliding on the rigid skull, "
        "traction-free flap (docs/model.md section 6). Midline shift: positive towards the "
        "patient's right.",
        "",
        "| scenario | " + " | ".join(f"{lab} [{u}]" for lab, u in COMPARISON.values()) + " |",
        "|---" * (len(COMPARISON) + 1) + "|",
    ]
    for sc, r in zip(scenarios, rows, strict=True):
        if not r.get("complete"):
            lines.append(f"| {sc['name']} | failed: {r.get('error', '')} |")
            continue
        vals = " | ".join(f"{float(r.get(k) or 0):.4g}" for k in COMPARISON)
        lines.append(f"| {sc['name']} | {vals} |")
    lines += ["", "![comparison](comparison.png)", "", views_marker("."), ""]
    for view in write_study_surfaces(out_dir, [sc["name"] for sc, r in zip(scenarios, rows,
                                                                          strict=True)
                                               if r.get("complete")]):
        lines += [f"![{view.stem}]({view.name})", ""]
    for sc, r in zip(scenarios, rows, strict=True):
        if r.get("complete"):
            lines += [f"## {sc['name']}", "", f"![{sc['name']}]({sc['name']}/sections.png)", ""]
            strain_map = f"{sc['name']}/maps/max_principal_strain.png"  # NIfTI maps' figure
            if (out_dir / strain_map).is_file():
                lines += [f"![{sc['name']}: strain map]({strain_map})", ""]
    atomic_write_text(out_dir / "report.md", "\n".join(lines))
    write_report_html(out_dir / "report.md")
    return out_dir / "report.md"
