"""The paper's trends of the sector study (its section 3.1), checked on a study's table.

Each trend restates one of the paper's five observations on its sector sweep, with the same
direction and, where the paper says "markedly", a stated threshold (:data:`MARKED`):

(i)   a wider opening lowers the maximal deformation and with it the maximal stretches
      (alpha and contact fixed, beta up: ``max_displacement`` and both stretch maxima);
(ii)  the radial stretch is largest deep inside the bulge (under the opening, away from its
      edges), and its maximum rises quickly with the swelling (beta and contact fixed, alpha
      up);
(iii) the tangential stretch is largest at the opening's edge (in a drop-shaped zone);
(iv)  the maximal radial stretch is markedly higher with frictional contact without sliding
      than with frictionless sliding (alpha, beta fixed);
(v)   the maximal tangential stretch is markedly higher with frictionless sliding than with
      frictional contact without sliding (alpha, beta fixed).

:func:`check_trends` counts the comparisons where each holds, once with the edge-excluded
maxima (``max_*``, outside disks of radius ``edge_exclusion`` around the singular points) and
once with the raw maxima (``raw_max_*``, the paper's "up to 1.7", which sit at the opening's
corners where the field is singular). (ii) and (iii) locate the edge-excluded maxima
(``argmax_*``; the raw maxima sit at the corners by construction). Two maxima within
:data:`TIE` of each other are a tie: it does not fail a direction.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from brainbulge.results.records.run_record import atomic_write_text

#: a maximum "around the opening's edge" lies within this distance of a corner [R]
EDGE_NEIGHBOURHOOD = 0.15
#: "markedly higher": the larger maximum exceeds the smaller by at least this fraction
MARKED = 0.05
#: a tie: two maxima within this fraction of each other are not a failure of a trend's
#: direction (a change of the mesh moves maxima by more than this), nor markedly different
TIE = 0.005


@dataclass(frozen=True)
class Trend:
    """One trend's verdict: ``held`` of ``cases`` comparisons, for one kind of maximum;
    ``marked``: how many of them by at least :data:`MARKED` (None: the paper states no
    qualifier)."""

    label: str
    statement: str
    maxima: str  # "edge-excluded" or "raw"
    held: int
    cases: int
    evidence: str
    marked: int | None = None

    @property
    def verdict(self) -> str:
        """``holds`` (every comparison, markedly where the paper says so), ``holds, not
        markedly``, ``inverted`` (no comparison) or ``differs`` (some)."""
        if self.cases == 0:
            return "no data"
        if self.held == self.cases:
            if self.marked is None or self.marked == self.cases:
                return "holds"
            return "holds, not markedly"
        return "inverted" if self.held == 0 else "differs"


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


def _num(row: dict[str, Any], key: str) -> float:
    return float(row[key])


def check_trends(rows: Sequence[dict[str, Any]]) -> list[Trend]:
    """The verdicts of trends (i)-(v) on the completed rows of a sector study's table
    (dicts with ``alpha``, ``beta``, ``contact``, ``converged`` and the summary keys)."""
    done = _complete(rows)
    by_key = {(r["contact"], float(r["alpha"]), float(r["beta"])): r for r in done}
    trends: list[Trend] = []
    for prefix, maxima in (("", "edge-excluded"), ("raw_", "raw")):
        keys = ("max_displacement", f"{prefix}max_radial_stretch",
                f"{prefix}max_tangential_stretch")
        held, cases, worst = _monotone(by_key, keys, vary=2, rising=False)
        trends.append(Trend("(i)", "a wider opening lowers the maximal deformation and "
                            "stretches", maxima, held, cases, worst))
    hits = [r for r in done if r.get("argmax_radial_stretch") is not None]
    ok = [r for r in hits if _under_opening(r["argmax_radial_stretch"], r)]
    trends.append(Trend("(ii)", "the radial stretch is largest deep inside the bulge",
                        "edge-excluded", len(ok), len(hits), _miss(hits, ok,
                                                                   "argmax_radial_stretch")))
    for prefix, maxima in (("", "edge-excluded"), ("raw_", "raw")):
        held, cases, worst = _monotone(by_key, (f"{prefix}max_radial_stretch",), vary=1,
                                       rising=True)
        trends.append(Trend("(ii)", "the radial maximum rises with the swelling (alpha)",
                            maxima, held, cases, worst))
    hits = [r for r in done if r.get("argmax_tangential_stretch") is not None]
    ok = [r for r in hits if _near_edge(r["argmax_tangential_stretch"], r)]
    trends.append(Trend("(iii)", "the tangential stretch is largest at the opening's edge",
                        "edge-excluded", len(ok), len(hits),
                        _miss(hits, ok, "argmax_tangential_stretch")))
    for label, field, higher, statement in (
        ("(iv)", "radial_stretch", "noslip",
         "the radial maximum is markedly higher without sliding than with sliding"),
        ("(v)", "tangential_stretch", "sliding",
         "the tangential maximum is markedly higher with sliding than without sliding"),
    ):
        lower = "sliding" if higher == "noslip" else "noslip"
        pairs = [(by_key[(higher, a, b)], by_key[(lower, a, b)]) for c, a, b in by_key
                 if c == higher and (lower, a, b) in by_key]
        for prefix, maxima in (("", "edge-excluded"), ("raw_", "raw")):
            key = f"{prefix}max_{field}"
            ratios = [_num(hi, key) / _num(lo, key) for hi, lo in pairs]
            evidence = (f"{higher} / {lower} {min(ratios):.3f}-{max(ratios):.3f}"
                        if ratios else "")
            trends.append(Trend(label, statement, maxima, sum(r >= 1 - TIE for r in ratios),
                                len(ratios), evidence,
                                marked=sum(r >= 1 + MARKED for r in ratios)))
    return trends


def _monotone(by_key: dict, keys: Sequence[str], vary: int, rising: bool
              ) -> tuple[int, int, str]:
    """Comparisons of consecutive scenarios along ``alpha`` (``vary = 1``) or ``beta`` (2)
    with the rest fixed: how many of ``keys`` rise (``rising``) or fall, of how many, and
    the first that does not."""
    held = cases = 0
    worst = ""
    groups: dict[tuple, list[float]] = {}
    for k in by_key:
        groups.setdefault(tuple(v for i, v in enumerate(k) if i != vary), []).append(k[vary])
    for rest, values in sorted(groups.items()):
        values = sorted(values)
        for v0, v1 in zip(values[:-1], values[1:], strict=True):
            r0, r1 = (by_key[(*rest[:vary], v, *rest[vary:])] for v in (v0, v1))
            for key in keys:
                cases += 1
                if ((_num(r1, key) > _num(r0, key)) == rising
                        or abs(_num(r1, key) / _num(r0, key) - 1) <= TIE):
                    held += 1
                elif not worst:
                    name = "alpha" if vary == 1 else "beta"
                    worst = (f"e.g. {rest[0]} {'beta' if vary == 1 else 'alpha'} {rest[1]:g}: "
                             f"{key} {_num(r0, key):.3f} at {name} {v0:g}, "
                             f"{_num(r1, key):.3f} at {name} {v1:g}")
    return held, cases, worst


def _miss(hits: list[dict], ok: list[dict], key: str) -> str:
    miss = next((r for r in hits if r not in ok), None)
    if miss is None:
        return ""
    x, y = (float(c) for c in miss[key][:2])
    return (f"e.g. {miss['contact']} alpha {float(miss['alpha']):g} beta "
            f"{float(miss['beta']):g} at ({x:.2f}, {y:.2f}) R")


def trends_markdown(trends: Sequence[Trend]) -> str:
    """The verdicts as a Markdown table."""
    lines = ["| trend | statement | maxima | holds in | markedly | verdict | evidence |",
             "|---|---|---|---|---|---|---|"]
    for t in trends:
        marked = "" if t.marked is None else f"{t.marked} of {t.cases}"
        lines.append(f"| {t.label} | {t.statement} | {t.maxima} | {t.held} of {t.cases} | "
                     f"{marked} | {t.verdict} | {t.evidence} |")
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
        "corners and the sector's ends, where the fields are singular; raw maxima sit there. "
        f"\"Markedly\": by at least {MARKED:.0%}; maxima within {TIE:.1%} of each other are "
        "a tie, which does not fail a direction.",
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
