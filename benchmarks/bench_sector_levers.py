"""Sector-study scenarios under solver variants that change the Newton path: time and results.

For each scenario (default: the three slowest of ``brainbulge study hemidisk-sector`` and the
headline case) and each variant, one in-process run of the study's task:

- ``default``: the product;
- ``no-rezoning``: ``rezone = false`` (the reference mesh to full load);
- ``steps-8``: 8 initial load steps instead of 4;
- ``no-relaxation``: without the residual-hotspot relaxation
  (:class:`brainbulge.solver.fast.hotspot.HotspotRelaxation`);
- ``step:CAP:SLIDE`` (e.g. ``step:0.3:2``): the rounded edge's step control with the Newton
  update capped at ``CAP`` of a vertex's smallest edge and load steps sized to ``SLIDE``
  element sizes (:data:`brainbulge.model.hemidisk.RESOLVED_EDGE_STEPS`);
- ``edge-ratio:N``: the rounded edge's arc meshed at its radius over ``N``
  (:data:`brainbulge.model.hemidisk.EDGE_MESH_RATIO`).

Prints CPU seconds of the task, Newton iterations, rezonings, the load reached, and the
largest relative difference of the summary's field numbers (extremes, percentiles,
displacements, pressures, volumes) to ``default``, with the key where it occurs. A variant
whose results stay within the solver's tolerance of ``default`` (1e-6) only changes the
path; a larger difference means the variant changed the discretisation (another rezoned
mesh, or none).

Rerun with ``python benchmarks/bench_sector_levers.py`` (``--scenarios noslip_a80_b30``,
``--variants default no-rezoning``); each run takes seconds to minutes. The rounded edge's
step control: ``--scenarios noslip_a80_b30 sliding_a80_b30 sliding_a60_b30 sliding_a80_b60
--variants step:0.3:2 step:0.3:3 step:0.4:2 edge-ratio:2 step:0.4:3 step:0.4:4 step:0.5:3``.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import brainbulge.model.hemidisk as hemidisk
from brainbulge.errors import ConvergenceError
from brainbulge.solver.fast.hotspot import HotspotRelaxation
from brainbulge.studies.hemidisk import sector_scenarios, study_task

VARIANTS = ("default", "no-rezoning", "steps-8", "no-relaxation")
SCENARIOS = ("noslip_a80_b30", "sliding_a80_b30", "sliding_a60_b30", "noslip_a80_b60")
#: summary keys that say how the solve went, not what it computed
SOLVE_KEYS = {"wall_time_s", "assembly_time_s", "linear_solve_time_s", "linear_iterations",
              "newton_iterations", "load_steps", "rejected_steps", "final_residual", "rezones",
              "elements", "dofs", "load_reached", "resumed_from_load", "edge_exclusion",
              "swelling_area_ratio_expected"}


def run(scenario: dict, variant: str, out: Path) -> tuple[float, dict]:
    """CPU seconds and the summary of one run of ``scenario`` under ``variant``."""
    sc = dict(scenario)
    if variant == "no-rezoning":
        sc["rezone"] = False
    elif variant == "steps-8":
        sc["steps"] = 8
    applies = HotspotRelaxation.applies
    steps, ratio = hemidisk.RESOLVED_EDGE_STEPS, hemidisk.EDGE_MESH_RATIO
    if variant == "no-relaxation":
        HotspotRelaxation.applies = staticmethod(lambda form: False)
    elif variant.startswith("step:"):
        cap, slide = (float(v) for v in variant.split(":")[1:])
        hemidisk.RESOLVED_EDGE_STEPS = ({**steps[0], "slide": slide},
                                        {**steps[1], "step_cap": cap})
    elif variant.startswith("edge-ratio:"):
        hemidisk.EDGE_MESH_RATIO = float(variant.split(":")[1])
    folder = out / f"{sc['name']}_{variant}"
    t0 = time.process_time()
    try:
        summary = study_task(sc, folder)
    except ConvergenceError:  # a stopped run keeps its last converged state's summary
        summary = json.loads((folder / "summary.json").read_text())
    finally:
        HotspotRelaxation.applies = applies
        hemidisk.RESOLVED_EDGE_STEPS, hemidisk.EDGE_MESH_RATIO = steps, ratio
    return time.process_time() - t0, summary


def largest_difference(a: dict, b: dict) -> tuple[float, str]:
    """Largest relative difference of the numeric field values of two summaries."""
    worst, where = 0.0, ""
    for key, va in a.items():
        vb = b.get(key)
        if (key in SOLVE_KEYS or isinstance(va, bool) or not isinstance(va, (int, float))
                or not isinstance(vb, (int, float))):
            continue
        scale = max(abs(va), abs(vb), 1e-3)  # near-zero values compared on a 1e-3 scale
        if abs(va - vb) / scale > worst:
            worst, where = abs(va - vb) / scale, key
    return worst, where


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--scenarios", nargs="+", default=list(SCENARIOS))
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS),
                    help=f"{', '.join(VARIANTS)}, step:CAP:SLIDE or edge-ratio:N")
    args = ap.parse_args()
    scenarios = {s["name"]: s for s in sector_scenarios(mesh_size=0.05, steps=4)}
    variants = ["default", *[v for v in args.variants if v != "default"]]
    print("scenario | variant | CPU s | Newton its | rezonings | load | largest diff to default")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.scenarios:
            ref = None
            for variant in variants:
                cpu, s = run(scenarios[name], variant, Path(tmp))
                ref = s if ref is None else ref
                diff, key = largest_difference(ref, s)
                print(f"{name} | {variant} | {cpu:.1f} | {s['newton_iterations']} | "
                      f"{s['rezones']} | {s['load_reached']:.4f} | {diff:.1e} {key}", flush=True)


if __name__ == "__main__":
    main()
