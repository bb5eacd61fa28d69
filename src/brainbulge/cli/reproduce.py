"""``brainbulge reproduce``: the paper's studies at its resolution (long; resumable).

1. ``sector/``: alpha in {20, 40, 60, 80} x beta in {30, 60, 90, 120} x {no-slip, sliding},
   Js 1.2, mesh size 0.05 R (Figures 2-3);
2. ``disk/``: five positions of a swelling disk under an opening inclined 30 deg off the
   symmetry axis, Js 1.3, sliding (Figure 4);
3. ``craniectomy/``: the six 3D scenarios on the ICBM152 brain, scaled so that its white
   matter is half the paper's 1108 ml brain (10 % swelling: 55 / 28 ml, as the paper's),
   at the paper's resolution by default (the paper: 1,275,808 tets; here Netgen meshes at
   ``--tets / 8`` and the mesh is refined once, ~1.4M tets). The six scenarios share one
   mesh (``craniectomy/mesh/``), the compiled energy (cached on disk) and, per worker, the
   loaded meshes; each ramps its load on that mesh; from 400k tets on
   they run one at a time (one worker: ~10 GB each at 1.4M tets) with the Krylov solver.

Rerun the same command to resume: finished scenarios are kept, a scenario stopped mid-way
goes on from its last load step. ``--tets 30000`` (21k tets) gives the 3D part in minutes.
"""

from __future__ import annotations

import argparse
import contextlib
from pathlib import Path
from typing import Any

from brainbulge.cli import add_cluster_options, add_output_options, finish_run, start_run
from brainbulge.errors import StudyIncomplete
from brainbulge.geometry.brain.defaults import FIXATIONS, LARGE_TETS
from brainbulge.results.records.run_record import atomic_write_json
from brainbulge.studies.suites import PAPER_TETS


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "reproduce", help="the paper's studies at its resolution (long; resumable)",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--tets", type=int, default=PAPER_TETS,
                   help=f"3D brain mesh size in tets (default {PAPER_TETS}: ~1.4M)")
    from brainbulge.model.brain_case import CraniectomyCase
    from brainbulge.model.hemidisk import HemidiskCase

    p.add_argument("--fix", choices=FIXATIONS, default=CraniectomyCase.fix,
                   help="fixed part of the brain's outer surface (3D)")
    p.add_argument("--mesh-size", type=float, default=HemidiskCase.mesh_size,
                   help="2D element size [R]")
    add_cluster_options(p, workers_note=f" (3D part: 1 from {LARGE_TETS:,} tets on)")
    add_output_options(p, "brainbulge-reproduce")
    p.set_defaults(func=run_command)


def plan(args: argparse.Namespace) -> dict[str, list[dict[str, Any]]]:
    """The three parts, every scenario checked before ``--out`` is touched."""
    from brainbulge.cli import checks
    from brainbulge.studies.suites import paper_parts

    checks.cluster(args.scheduler, getattr(args, "workers", None),
                   getattr(args, "worker_wait", checks.WORKER_WAIT_S))
    return paper_parts(args.tets, args.fix, args.mesh_size)


def run_command(args: argparse.Namespace) -> int:
    from brainbulge.studies.runner import shared_scheduler
    from brainbulge.studies.suites import (
        brain_meshes_meanwhile,
        incomplete_text,
        run_named_study,
    )

    parts = plan(args)
    out_path = Path(args.out)
    resume = (out_path / "study.json").is_file() and not args.overwrite
    out = start_run(args, {"command": "reproduce", "tets": args.tets, "fix": args.fix},
                    resume=resume)
    atomic_write_json(out / "study.json", {"study": "reproduce", "parts": list(parts)})
    names = {"sector": "hemidisk-sector", "disk": "hemidisk-disk"}
    done: dict[str, int] = {}
    step = iter(range(1, len(parts) + 1))
    two_d = [p for p in parts if p in names]
    with contextlib.ExitStack() as stack:
        if two_d:  # one set of workers for the 2D parts, the 3D meshes built meanwhile
            scheduler = stack.enter_context(shared_scheduler(args.scheduler, args.workers))
            if "craniectomy" in parts:
                stack.enter_context(brain_meshes_meanwhile(scheduler, out / "craniectomy",
                                                           parts["craniectomy"]))
        for part in two_d:
            print(f"{next(step)}/{len(parts)} {part} ({len(parts[part])} runs) -> {out / part}")
            done[part] = run_named_study(names[part], parts[part], out / part, scheduler)
    if "craniectomy" in parts:
        scenarios = parts["craniectomy"]
        print(f"{next(step)}/{len(parts)} craniectomy ({len(scenarios)} runs) -> "
              f"{out / 'craniectomy'}")
        done["craniectomy"] = _run_brain_part(scenarios, out / "craniectomy", args)
    failed, texts = 0, []
    for part, scenarios in parts.items():
        if done[part] < len(scenarios):
            failed += len(scenarios) - done[part]
            texts.append(f"{part}: {incomplete_text(out / part, scenarios)}")
    if failed:
        raise StudyIncomplete(f"{failed} scenarios did not complete ({'; '.join(texts)})")
    finish_run(out)
    return 0


def _run_brain_part(scenarios: list[dict[str, Any]], out: Path,
                    args: argparse.Namespace) -> int:
    from brainbulge.studies.craniectomy import run_study_with_report

    workers = args.workers
    if workers is None and args.scheduler is None and args.tets >= LARGE_TETS:
        workers = 1
    return run_study_with_report(out, scenarios, args.scheduler, workers)
