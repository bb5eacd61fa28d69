"""Hemidisk benchmark: the headline case's solve and the whole sector study.

Prints, for the headline case (alpha 80, beta 60, Js 1.2, default mesh) with each contact
condition, the solve's wall time (``wall_time_s`` of its summary: load ramp, assembly and
linear solves, without meshing and output files), Newton iterations, DOFs and the bulge
height; then, unless ``--no-study``, the wall time of ``brainbulge study hemidisk-sector``
(32 scenarios on a local Dask cluster of ``--workers`` processes, start-up, figures and
report included) and how many scenarios completed, and per scenario its solve time, Newton
iterations, accepted and rejected load steps and rezonings, longest first.

Rerun with ``python benchmarks/bench_hemidisk.py`` (``--skull rigid`` for the rigid-shell
extension, ``--repeat 3`` for the median of three headline solves, ``--keep DIR`` to keep the
study folder, e.g. to compare two versions' ``summary.json`` files).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def headline(contact: str, skull: str, out: Path) -> dict:
    folder = out / f"headline_{contact}"
    subprocess.run(
        [sys.executable, "-m", "brainbulge", "hemidisk", "--contact", contact, "--skull",
         skull, "--out", str(folder), "--overwrite"],
        check=True, capture_output=True,
    )
    return json.loads((folder / "summary.json").read_text())


def scenario_table(folder: Path) -> list[str]:
    """One line per scenario of a study folder, the longest solve first."""
    rows = []
    for path in sorted(folder.glob("*/summary.json")):
        s = json.loads(path.read_text())
        state = ("complete" if s.get("converged", True)
                 else f"stopped at load {s['load_reached']:.3f}")
        rows.append((s["wall_time_s"], f"{path.parent.name} | {s['wall_time_s']:.1f} | "
                     f"{s['newton_iterations']} | {s['load_steps']} | {s['rejected_steps']} | "
                     f"{s['rezones']} | {state}"))
    return [line for _, line in sorted(rows, reverse=True)]


def study(skull: str, workers: int, out: Path) -> tuple[float, int, int]:
    folder = out / "sector"
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "brainbulge", "study", "hemidisk-sector", "--skull", skull,
         "--workers", str(workers), "--out", str(folder), "--overwrite"],
        capture_output=True,
    )
    wall = time.perf_counter() - t0
    rows = (folder / "table.csv").read_text().splitlines()[1:]
    done = sum(1 for r in rows if ",True," in r)
    return wall, done, len(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--skull", choices=("paper", "rigid"), default="paper")
    ap.add_argument("--repeat", type=int, default=1, help="headline solves per contact")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--no-study", action="store_true")
    ap.add_argument("--keep", type=Path, default=None, help="write the runs here and keep them")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) if args.keep is None else args.keep
        out.mkdir(parents=True, exist_ok=True)
        print(f"hemidisk benchmark, skull {args.skull}")
        print("case | contact | solve s (median) | Newton its | DOFs | bulge top [R]")
        for contact in ("noslip", "sliding"):
            runs = [headline(contact, args.skull, out) for _ in range(args.repeat)]
            s = runs[-1]
            wall = statistics.median(r["wall_time_s"] for r in runs)
            print(f"headline a80 b60 | {contact} | {wall:.2f} | {s['newton_iterations']} | "
                  f"{s['dofs']} | {s['max_vertical_displacement']:.4f}", flush=True)
        if not args.no_study:
            wall, done, n = study(args.skull, args.workers, out)
            print(f"sector study ({args.workers} workers) | both | {wall:.1f} | "
                  f"{done} of {n} complete | |", flush=True)
            print("scenario | solve s | Newton its | load steps | rejected | rezonings | result")
            print("\n".join(scenario_table(out / "sector")))


if __name__ == "__main__":
    main()
