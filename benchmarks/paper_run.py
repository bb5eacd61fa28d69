"""What `benchmarks/paper_claims.py` reads of a `brainbulge reproduce` folder, and the row
each claim's measure returns."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: "markedly" (the paper's qualifier) and "significantly": by at least this fraction
MARKED = 0.05
#: an "up to" / "down to" value is met when ours is within this fraction of it, both ways
#: (of its excess over 1 for stretches, of the value for strains): 1.3 admits 1.225-1.375,
#: 0.7 admits 0.625-0.775, 30 % admits 22.5-37.5 %
BAND = 0.25
#: the verdicts, in the order the page states them
VERDICTS = ("holds", "differs", "singular", "by construction", "not measured", "not modelled",
            "same setup", "other setup", "context")
#: 2D sliding scenarios that wait for the sliding solver that releases points past the edge
WAITING = {"sliding_a80_b30"}


@dataclass
class Row:
    """One line of the claims table."""

    ours: str
    verdict: str  # one of VERDICTS
    why: str = ""


@dataclass
class Run:
    """The parts of a reproduce folder that the claims read."""

    root: Path
    sector: dict[str, dict] = field(default_factory=dict)  # scenario name -> summary (+ inputs)
    disk: dict[str, dict] = field(default_factory=dict)
    brain: dict[str, dict] = field(default_factory=dict)
    sector_missing: list[str] = field(default_factory=list)
    brain_missing: list[str] = field(default_factory=list)
    run_info: dict[str, Any] = field(default_factory=dict)

    def fields(self, part: str, name: str):
        from brainbulge.results.export.writers import load_vertex_fields

        path = self.root / part / name / "fields.npz"
        return load_vertex_fields(path) if path.is_file() else None


def load_run(root: Path) -> Run:
    run = Run(Path(root))
    for part, target, missing in (("sector", run.sector, run.sector_missing),
                                  ("disk", run.disk, None),
                                  ("craniectomy", run.brain, run.brain_missing)):
        folder = run.root / part
        if not folder.is_dir():
            continue
        for sc in sorted(p for p in folder.iterdir() if (p / "scenario.json").is_file()):
            scenario = json.loads((sc / "scenario.json").read_text())
            summary = sc / "summary.json"
            if summary.is_file():
                s = json.loads(summary.read_text())
                s = {**scenario, **s, "name": sc.name}
                if s.get("converged", True) and s.get("load_reached", 1.0) >= 1.0 - 1e-12:
                    target[sc.name] = s
                    continue
            if missing is not None:
                missing.append(sc.name)
    for name in ("run.json", "status.json"):
        path = run.root / name
        if path.is_file():
            run.run_info[name] = json.loads(path.read_text())
    return run



def band(value: float, paper: float, stretch: bool = True) -> str:
    """Where ``value`` lies against the paper's "up to" / "down to" ``paper``: ``within``
    :data:`BAND` of it (of the excess over 1 for a stretch), ``below`` or ``above`` (in the
    sense of the excess: a stretch 0.8 is "below" the paper's 0.7, it falls less far)."""
    ours, theirs = (value - 1, paper - 1) if stretch else (value, paper)
    ratio = ours / theirs
    return "within" if abs(ratio - 1) <= BAND else ("below" if ratio < 1 else "above")


def excess_text(value: float, paper: float, stretch: bool = True) -> str:
    """``value`` as a percentage of the paper's excess over 1 (of the value for a strain)."""
    ours, theirs = (value - 1, paper - 1) if stretch else (value, paper)
    return f"{100 * ours / theirs:.0f} % of the paper's {'excess' if stretch else 'value'}"
