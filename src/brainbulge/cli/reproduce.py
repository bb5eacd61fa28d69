"""``brainbulge reproduce``: the paper's studies at full resolution (long; resumable).

1. ``sector/``: alpha in {20, 40, 60, 80} x beta in {30, 60, 90, 120} x {no-slip, sliding},
   Js 1.2, mesh size 0.05 R (Figures 2-4);
2. ``disk/``: five positions of a swelling disk, Js 1.3, sliding (Figure 5);
3. ``craniectomy/``: the six 3D scenarios on the ICBM152 brain scaled to the paper's 1108 ml.

Rerun the same command to resume: finished scenarios are kept. The paper's brain had 1.28M
tetrahedra; the default ``--tets 100000`` (111k tets) takes ~10 min per 3D scenario on 2
cores (direct solver, measured under load); the paper's size needs the scalable solver of
the performance work.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from brainbulge.cli import add_output_options, finish_run, start_run
from brainbulge.cli.study import StudyIncomplete, incomplete_text, run_study_and_report
from brainbulge.results.run_record import atomic_write_json


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "reproduce", help="the paper's studies at full resolution (long; resumable)",
        description=__doc__,
    )
    p.add_argument("--tets", type=int, default=100_000, help="3D brain mesh size (tets)")
    p.add_argument("--mesh-size", type=float, default=0.05, help="2D element size [R]")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address or 'serial'")
    p.add_argument("--workers", type=int, default=None, help="local worker processes")
    add_output_options(p, "brainbulge-reproduce")
    p.set_defaults(func=run_command)


def plan(args: argparse.Namespace) -> dict[str, list[dict[str, Any]]]:
    from brainbulge.cli import checks
    from brainbulge.studies import hemidisk as hd
    from brainbulge.studies.craniectomy import case_from_dict, craniectomy_scenarios

    checks.scheduler(args.scheduler)
    brain = craniectomy_scenarios(tets=args.tets, brain_volume_ml=1108.0, steps=4)
    for sc in brain:
        case_from_dict(sc)  # validate before touching --out
    return {
        "sector": hd.sector_scenarios(mesh_size=args.mesh_size, steps=4),
        "disk": hd.disk_scenarios(mesh_size=args.mesh_size, steps=4),
        "craniectomy": brain,
    }


def run_command(args: argparse.Namespace) -> int:
    parts = plan(args)
    out_path = Path(args.out)
    resume = (out_path / "study.json").is_file() and not args.overwrite
    out = start_run(args, {"command": "reproduce", "tets": args.tets}, resume=resume)
    atomic_write_json(out / "study.json", {"study": "reproduce", "parts": list(parts)})
    names = {"sector": "hemidisk-sector", "disk": "hemidisk-disk", "craniectomy": "craniectomy"}
    failed, texts = 0, []
    for i, (part, scenarios) in enumerate(parts.items(), start=1):
        print(f"{i}/{len(parts)} {part} ({len(scenarios)} runs) -> {out / part}")
        ok = run_study_and_report(names[part], scenarios, out / part, args.scheduler,
                                  args.workers)
        if ok < len(scenarios):
            failed += len(scenarios) - ok
            texts.append(f"{part}: {incomplete_text(out / part, scenarios)}")
    if failed:
        raise StudyIncomplete(f"{failed} scenarios did not complete ({'; '.join(texts)})")
    finish_run(out)
    return 0
