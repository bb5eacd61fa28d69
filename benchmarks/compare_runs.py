"""Compare the summaries of 3D runs against a reference run (a 2 % check).

Run ``python benchmarks/compare_runs.py --ref LABEL=DIR LABEL=DIR ...``: each ``DIR`` is a
run folder with ``summary.json`` (a ``brainbulge brain --out DIR`` or a bench run
``CACHE/run_N_VARIANT``). Prints a markdown table of the summary quantities, each run's value
with its difference from the reference relative to the reference's magnitude, a ``*`` where
that exceeds ``--rtol`` (default 2 %), and the count of such quantities per run.

The default quantities are those a mesh can converge: the shifts, displacements, volumes,
the mean pressure and the volume percentiles of stretch and strain (docs/outputs.md, "In 3D,
compare the percentiles"). ``--keys`` picks others, e.g. the extremes ``max_radial_stretch``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

#: summary keys compared by default
KEYS = (
    "midline_shift_mm", "midline_shift_monro_mm", "max_displacement",
    "max_vertical_displacement", "min_vertical_displacement", "mean_hydrostatic_stress_kpa",
    "swelling_volume_ml", "deformed_volume_ml", "bulge_volume_ml",
    "p95_radial_stretch", "p99_radial_stretch", "p05_radial_stretch", "p01_radial_stretch",
    "p95_tangential_stretch", "p99_tangential_stretch", "p05_tangential_stretch",
    "p01_tangential_stretch", "p95_principal_strain", "p99_principal_strain",
)


def relative_difference(value: float, ref: float) -> float:
    """``(value - ref) / |ref|``; infinite when the reference is 0 and the value is not."""
    if ref == 0:
        return 0.0 if value == 0 else float("inf")
    return (value - ref) / abs(ref)


def comparison_table(runs: dict[str, dict], ref: str, keys: tuple[str, ...],
                     rtol: float) -> tuple[str, dict[str, list[str]]]:
    """The markdown table and, per run, the keys whose difference exceeds ``rtol``."""
    names = list(runs)
    lines = ["| quantity | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
    over: dict[str, list[str]] = {n: [] for n in names}
    for key in keys:
        r = runs[ref].get(key)
        cells = []
        for n in names:
            v = runs[n].get(key)
            if v is None:
                cells.append("-")
            elif n == ref or r is None:
                cells.append(f"{v:.4g}")
            else:
                d = relative_difference(v, r)
                flag = "*" if abs(d) > rtol else ""
                if flag:
                    over[n].append(key)
                cells.append(f"{v:.4g} ({100 * d:+.1f} %{flag})")
        lines.append(f"| {key} | " + " | ".join(cells) + " |")
    return "\n".join(lines), over


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", metavar="LABEL=DIR", help="runs to compare")
    parser.add_argument("--ref", required=True, metavar="LABEL=DIR", help="the reference run")
    parser.add_argument("--rtol", type=float, default=0.02, help="flag differences above this")
    parser.add_argument("--keys", nargs="+", default=list(KEYS), help="summary keys to compare")
    args = parser.parse_args(argv)
    runs: dict[str, dict] = {}
    for spec in [*args.runs, args.ref]:
        label, _, folder = spec.rpartition("=")
        path = Path(folder) / "summary.json"
        if not path.is_file():
            print(f"error: no summary.json in {folder}: give run folders", file=sys.stderr)
            return 2
        try:
            runs[label or folder] = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            print(f"error: cannot read {path}: {exc}; rerun that case", file=sys.stderr)
            return 2
    ref = args.ref.rpartition("=")[0] or args.ref.rpartition("=")[2]
    table, over = comparison_table(runs, ref, tuple(args.keys), args.rtol)
    print(table)
    for name, keys in over.items():
        if name != ref:
            print(f"{name}: {len(keys)} of {len(args.keys)} beyond {100 * args.rtol:g} %"
                  + (f" ({', '.join(keys)})" if keys else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
