"""``brainbulge demo``: the paper in miniature on the embedded default data, with a report.

Runs the hemidisk headline case (alpha 80, beta 60, Js 1.2) with both contact conditions,
a small sector sweep, the six 3D craniectomy scenarios ({left unilateral, frontal} flap x
{both, left, right} white-matter swelling, Js 1.1) on a coarse ICBM152 brain, and writes
``report.md`` with the figures and tables and ``report.html``, the same as one page that opens
offline in a browser, with an interactive 3D view of each deformed brain. ``--quick`` shrinks
everything for a smoke test (two 3D scenarios).
"""

from __future__ import annotations

import argparse
from typing import Any

from brainbulge.cli import add_cluster_options, add_output_options, finish_run, start_run


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "demo", help="reproduce the paper in miniature and write a report", description=__doc__
    )
    p.add_argument("--quick", action="store_true", help="coarse meshes, fewer scenarios")
    add_cluster_options(p)
    add_output_options(p, "brainbulge-demo")
    p.set_defaults(func=run_command)


def run_command(args: argparse.Namespace) -> int:
    from brainbulge.cli import checks
    from brainbulge.results.present.report import write_demo_report
    from brainbulge.studies.runner import shared_scheduler
    from brainbulge.studies.suites import (
        brain_meshes_meanwhile,
        demo_plan,
        demo_scenarios,
        run_named_study,
    )

    checks.cluster(args.scheduler, args.workers, args.worker_wait)
    plan = demo_plan(args.quick)
    out = start_run(args, {"command": "demo", "quick": args.quick, **plan})
    parts = demo_scenarios(plan)
    headline, sweep, brain = parts["headline"], parts["sweep"], parts["brain"]
    with shared_scheduler(args.scheduler, args.workers) as scheduler:  # one set of workers
        with brain_meshes_meanwhile(scheduler, out / "brain", brain):
            print(f"1/3 headline case, both contact conditions -> {out / 'headline'}")
            ok1 = run_named_study("hemidisk-sector", headline, out / "headline", scheduler)
            print(f"2/3 sector sweep ({len(sweep)} runs) -> {out / 'sweep'}")
            ok2 = run_named_study("hemidisk-sector", sweep, out / "sweep", scheduler)
        print(f"3/3 craniectomy on the ICBM152 brain ({len(brain)} runs) -> {out / 'brain'}")
        ok3 = run_named_study("craniectomy", brain, out / "brain", scheduler)
    report = write_demo_report(out, headline, sweep, brain)
    total = len(headline) + len(sweep) + len(brain)
    finish_run(out, f"{ok1 + ok2 + ok3} of {total} scenarios complete")
    print(f"report: {report.with_suffix('.html')} (open it in a browser) and {report.name}")
    return 0
