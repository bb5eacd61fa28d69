"""The demo's ``report.md`` and ``report.html``: what was run, the figures and the tables of
its three studies (the HTML page with the interactive 3D views of the craniectomy scenarios).

Each scenario's numbers are read back from its ``summary.json``; a scenario without one is
reported as failed.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from brainbulge.results.present.html_report import views_marker, write_report_html
from brainbulge.results.records.run_record import atomic_write_text

#: the hemidisk columns of the demo's tables (keys of :mod:`brainbulge.results.measures.schema`)
REPORT_KEYS = (
    "max_displacement",
    "max_radial_stretch",
    "min_radial_stretch",
    "max_tangential_stretch",
    "min_tangential_stretch",
    "max_principal_strain",
    "max_penetration",
    "newton_iterations",
    "wall_time_s",
)
#: the craniectomy columns of the demo's table
BRAIN_REPORT_KEYS = ("midline_shift_mm", "bulge_volume_ml", "max_displacement",
                     "max_principal_strain", "max_radial_stretch", "max_tangential_stretch",
                     "max_penetration_mm", "newton_iterations", "wall_time_s")


def _summary(folder: Path) -> dict[str, Any] | None:
    f = folder / "summary.json"
    return json.loads(f.read_text()) if f.is_file() else None


def _table(rows: list[tuple[str, dict[str, Any] | None]], keys=REPORT_KEYS) -> list[str]:
    lines = ["| case | " + " | ".join(keys) + " |", "|---" * (len(keys) + 1) + "|"]
    for name, s in rows:
        if s is None:
            lines.append(f"| {name} | " + " | ".join("failed" for _ in keys) + " |")
            continue
        vals = [f"{s.get(k):.4g}" if isinstance(s.get(k), float) else str(s.get(k)) for k in keys]
        lines.append(f"| {name} | " + " | ".join(vals) + " |")
    return lines


def write_demo_report(
    out: Path, headline: list[dict], sweep: list[dict], brain: list[dict] | None = None
) -> Path:
    """``report.md`` (what was run, the figures, the tables) and ``report.html``."""
    lines = [
        "# brainbulge demo report",
        "",
        "Weickenmeier et al., *Bulging brains* (J. Elasticity 2017), in miniature: a plane-strain",
        "hemidisk whose sector of angle alpha swells to Js = 1.2 and bulges through a skull",
        "opening of angle beta in the paper's skull arc; no-slip or frictionless sliding on it.",
        "",
        "## Headline case: alpha = 80 deg, beta = 60 deg",
        "",
        "![no-slip (left) and sliding (right)](headline/side_by_side.png)",
        "",
    ]
    lines += _table([(sc["name"], _summary(out / "headline" / sc["name"])) for sc in headline])
    lines += ["", "## Sector sweep", ""]
    for contact in ("noslip", "sliding"):
        for field in ("lambda_n", "lambda_t"):
            png = out / "sweep" / f"grid_{field}_{contact}.png"
            if png.is_file():
                lines.append(f"![{field} {contact}](sweep/{png.name})")
                lines.append("")
    lines += _table([(sc["name"], _summary(out / "sweep" / sc["name"])) for sc in sweep])
    if brain:
        lines += [
            "",
            "## 3D craniectomy on the ICBM152 brain",
            "",
            "White matter swells to Js = 1.1 in one hemisphere or both; the brain slides on the",
            "rigid skull and bulges through a left unilateral or a bifrontal flap. Midline shift",
            "is positive towards the patient's right. Per scenario: `brain/<case>/sections.png`.",
            "",
            "![comparison](brain/comparison.png)",
            "",
            views_marker("brain"),
            "",
        ]
        rows = [(sc["name"], _summary(out / "brain" / sc["name"])) for sc in brain]
        lines += _table(rows, BRAIN_REPORT_KEYS)
        for sc in brain:
            if (out / "brain" / sc["name"] / "sections.png").is_file():
                lines += ["", f"![{sc['name']}](brain/{sc['name']}/sections.png)"]
    lines += [
        "",
        "Full tables: `headline/table.csv`, `sweep/table.csv`, `brain/table.csv`. Fields for "
        "ParaView:",
        "`*/<case>/fields.vtu` (use *Warp By Vector* on `u`).",
        "",
        "`max_*`/`min_*` leave out disks of radius 0.05 R around the singular points (opening",
        "corners, sector edges on the boundary); `raw_*` in the tables are over all points.",
    ]
    path = out / "report.md"
    atomic_write_text(path, "\n".join(lines) + "\n")
    write_report_html(path)
    return path
