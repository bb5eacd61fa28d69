"""The paper's trends of the sector study (its section 3.1), checked on a study's table.

Each trend is a statement about the summaries of the ``hemidisk-sector`` scenarios; for each,
:func:`check_trends` counts the cases where it holds, once with the edge-excluded maxima
(``max_*``, outside disks of radius ``edge_exclusion`` around the singular points) and once
with the raw maxima (``raw_max_*``, the paper's "up to 1.7", which sit at the opening's
corners where the field is singular):

(i)   the maximum stretches fall as the opening widens (alpha and contact fixed, beta up);
(ii)  the radial (axonal) stretch is largest deep inside the bulge: under the opening, away
      from its edges;
(iii) the tangential (shear) stretch is largest around the opening's edge;
(iv)  sliding lowers the maximum radial stretch against no-slip (alpha, beta fixed);
(v)   sliding lowers the maximum tangential stretch against no-slip (alpha, beta fixed).

(ii) and (iii) use the reference positions ``argmax_*`` of the edge-excluded maxima (the raw
maxima sit at the corners by construction, so only the edge-excluded ones are checked).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from brainbulge.results.run_record import atomic_write_text

#: a maximum "around the opening's edge" lies within this distance of a corner [R]
EDGE_NEIGHBOURHOOD = 0.15


@dataclass(frozen=True)
class Trend:
    """One trend's verdict: ``held`` of ``cases`` comparisons, for one kind of maximum."""

    label: str
    statement: str
    maxima: str  # "edge-excluded" or "raw"
    held: int
    cases: int
    evidence: str

    @property
    def verdict(self) -> str:
        if self.cases == 0:
            return "no data"
        if self.held == self.cases:
            return "holds"
        return "holds mostly" if self.held >= 0.75 * self.cases else "does not hold"


def _complete(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r for r in rows if r.get("converged") and r.get("alpha") not in (None, "")]


def _corners(row: dict[str, Any]) -> list[tuple[float, float]]:
    """The opening's corners ``R (cos, sin)(90 -+ beta/2)`` [R] of a scenario row."""
    b = math.radians(float(row["beta"]) / 2)
    return [(math.sin(b), math.cos(b)), (-math.sin(b), math.cos(b))]


def _under_opening(point: Sequence[float], row: dict[str, Any]) -> bool:
    """Whether ``point`` (reference, [R]) lies under the opening and away from its edge."""
    x, y = float(point[0]), float(point[1])
    angle = math.degrees(math.atan2(y, x))
    away = min(math.dist((x, y), c) for c in _corners(row)) > EDGE_NEIGHBOURHOOD
    return abs(angle - 90.0) < float(row["beta"]) / 2 and away and math.hypot(x, y) < 0.95


def _near_edge(point: Sequence[float], row: dict[str, Any]) -> bool:
    return min(math.dist((float(point[0]), float(point[1])), c)
               for c in _corners(row)) <= EDGE_NEIGHBOURHOOD


def check_trends(rows: Sequence[dict[str, Any]]) -> list[Trend]:
    """The verdicts of trends (i)-(v) on the completed rows of a sector study's table
    (dicts with ``alpha``, ``beta``, ``contact``, ``converged`` and the summary keys)."""
    done = _complete(rows)
    by_key = {(r["contact"], float(r["alpha"]), float(r["beta"])): r for r in done}
    trends: list[Trend] = []
    for prefix, maxima in (("", "edge-excluded"), ("raw_", "raw")):
        held = cases = 0
        worst = ""
        for contact in sorted({k[0] for k in by_key}):
            for alpha in sorted({k[1] for k in by_key}):
                betas = sorted(b for c, a, b in by_key if c == contact and a == alpha)
                for b0, b1 in zip(betas[:-1], betas[1:], strict=True):
                    r0, r1 = by_key[(contact, alpha, b0)], by_key[(contact, alpha, b1)]
                    for field in ("radial_stretch", "tangential_stretch"):
                        cases += 1
                        if r1[f"{prefix}max_{field}"] <= r0[f"{prefix}max_{field}"]:
                            held += 1
                        elif not worst:
                            worst = (f"e.g. {contact} alpha {alpha:g}: {field} "
                                     f"{r0[f'{prefix}max_{field}']:.3f} at beta {b0:g}, "
                                     f"{r1[f'{prefix}max_{field}']:.3f} at beta {b1:g}")
        trends.append(Trend("(i)", "max stretches fall as the opening widens", maxima, held,
                            cases, worst))
    for label, statement, key, test in (
        ("(ii)", "radial maximum deep inside the bulge", "argmax_radial_stretch",
         _under_opening),
        ("(iii)", "tangential maximum around the opening's edge",
         "argmax_tangential_stretch", _near_edge),
    ):
        hits = [r for r in done if r.get(key) is not None]
        ok = [r for r in hits if test(r[key], r)]
        miss = next((r for r in hits if r not in ok), None)
        evidence = "" if miss is None else (
            f"e.g. {miss['contact']} alpha {float(miss['alpha']):g} beta "
            f"{float(miss['beta']):g} at ({miss[key][0]:.2f}, {miss[key][1]:.2f}) R")
        trends.append(Trend(label, statement, "edge-excluded", len(ok), len(hits), evidence))
    for label, field in (("(iv)", "radial_stretch"), ("(v)", "tangential_stretch")):
        for prefix, maxima in (("", "edge-excluded"), ("raw_", "raw")):
            pairs = [(by_key[k], by_key[("sliding", *k[1:])]) for k in by_key
                     if k[0] == "noslip" and ("sliding", *k[1:]) in by_key]
            ok = [p for p in pairs if p[1][f"{prefix}max_{field}"] <= p[0][f"{prefix}max_{field}"]]
            ratios = [p[1][f"{prefix}max_{field}"] / p[0][f"{prefix}max_{field}"] for p in pairs]
            evidence = (f"sliding / no-slip {min(ratios):.3f}-{max(ratios):.3f}"
                        if ratios else "")
            word = field.split("_")[0]
            trends.append(Trend(label, f"sliding lowers the {word} maximum", maxima, len(ok),
                                len(pairs), evidence))
    return trends


def trends_markdown(trends: Sequence[Trend]) -> str:
    """The verdicts as a Markdown table."""
    lines = ["| trend | statement | maxima | holds in | verdict | evidence |",
             "|---|---|---|---|---|---|"]
    for t in trends:
        lines.append(f"| {t.label} | {t.statement} | {t.maxima} | {t.held} of {t.cases} | "
                     f"{t.verdict} | {t.evidence} |")
    return "\n".join(lines) + "\n"


def write_sector_report(out_dir: Path, scenarios: Sequence[dict], rows: Sequence[dict]) -> Path:
    """``report.md`` of a sector study: completion, the trends table and the figures."""
    merged = [{**sc, **r} for sc, r in zip(scenarios, rows, strict=True)]
    trends = check_trends(merged)
    done = sum(1 for r in rows if r.get("complete"))
    crossing = [r.get("max_skull_crossing") for r in merged if r.get("converged")]
    crossing = [c for c in crossing if c is not None]
    lines = [
        "# Hemidisk sector study",
        "",
        f"{done} of {len(scenarios)} scenarios complete (`table.csv` has every summary key).",
        "",
        "## The paper's trends (section 3.1)",
        "",
        trends_markdown(trends),
        "Edge-excluded maxima leave out disks of radius `edge_exclusion` around the opening's "
        "corners and the sector's ends, where the fields are singular; raw maxima sit there.",
    ]
    if crossing:
        lines += ["", f"Largest `max_skull_crossing` (tissue beyond the skull arc): "
                      f"{max(crossing):.3g} R."]
    figures = sorted(p.name for p in Path(out_dir).glob("*.png"))
    if figures:
        lines += ["", "## Figures", ""] + [f"![{name}]({name})" for name in figures]
    path = Path(out_dir) / "report.md"
    atomic_write_text(path, "\n".join(lines) + "\n")
    return path
