"""What `benchmarks/paper_claims.py` reads of a `brainbulge reproduce` folder, and the row
each claim's measure returns."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: "markedly" (the paper's qualifier) and "significantly": by at least this fraction
MARKED = 0.05
#: the paper's "up to" values are met when ours reach this fraction of them (their
#: deviation from 1 for stretches, the value for strains)
UP_TO_TOLERANCE = 0.8
#: 2D sliding scenarios that wait for the sliding solver that releases points past the edge
WAITING = {"sliding_a80_b30"}


@dataclass
class Row:
    """One line of the claims table."""

    ours: str
    verdict: str  # holds | differs | not measured | same setup | other setup | context
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



def up_to(value: float, paper: float, stretch: bool = True) -> bool:
    """Whether ``value`` meets the paper's "up to ``paper``" (:data:`UP_TO_TOLERANCE`)."""
    if stretch:
        return abs(value - 1) >= UP_TO_TOLERANCE * abs(paper - 1)
    return value >= UP_TO_TOLERANCE * paper
