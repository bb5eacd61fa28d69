"""The paper's sharp 2D skull edge (``--skull-edge-radius 0``, MINI): the sector sweep with
and without 2D rezoning, the measured reason rezoning is kept.

Each of the 32 sector scenarios (Js 1.2, h 0.05 R) is run in this process with
``run_hemidisk`` on the half domain (``--full-domain``: the whole hemidisk), once with
rezoning and once without (``--rezone on|off|both``). Per scenario: load reached, Newton
iterations, rezonings and the wall time; then the count that reached full load.

Rerun: ``python benchmarks/bench_sharp_edge_2d.py`` (about 5 min alone; ``--out DIR`` keeps
the run folders, a temporary folder otherwise).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path


def sweep(out: Path, rezone: bool, full: bool) -> list[dict]:
    from brainbulge.errors import ConvergenceError
    from brainbulge.studies.hemidisk import run_hemidisk, sector_scenarios

    rows = []
    for scenario in sector_scenarios():
        config = dict(scenario)
        name = config.pop("name")
        config.update(skull_edge_radius=0.0, element="mini", rezone=rezone, full_domain=full)
        start = time.perf_counter()
        try:
            summary = run_hemidisk(config, out / name)
        except ConvergenceError:  # the partial summary is on disk
            summary = json.loads((out / name / "summary.json").read_text())
        rows.append({"name": name, "load": summary["load_reached"],
                     "newton": summary["newton_iterations"], "rezones": summary["rezones"],
                     "wall": time.perf_counter() - start})
        print(f"{name}: load {rows[-1]['load']:.3f}, {rows[-1]['newton']} Newton", flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rezone", choices=("on", "off", "both"), default="both")
    ap.add_argument("--full-domain", action="store_true")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = a.out or Path(tmp)
        runs = {flag: sweep(out / f"rezone-{flag}", flag == "on", a.full_domain)
                for flag in (("on", "off") if a.rezone == "both" else (a.rezone,))}
    domain = "whole hemidisk" if a.full_domain else "half domain"
    print(f"\nsharp edge, MINI, {domain}\n")
    print("| rezoning | full load | Newton, all 32 | stopped (load) |")
    print("|---|---|---|---|")
    for flag, rows in runs.items():
        stopped = ", ".join(f"{r['name']} ({r['load']:.2f})" for r in rows if r["load"] < 1)
        print(f"| {flag} | {sum(r['load'] >= 1 for r in rows)} of {len(rows)} | "
              f"{sum(r['newton'] for r in rows)} | {stopped or '-'} |")


if __name__ == "__main__":
    main()
