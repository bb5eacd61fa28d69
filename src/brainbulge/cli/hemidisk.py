"""``brainbulge hemidisk``: one 2D hemidisk case (docs/model.md sections 4-5)."""

from __future__ import annotations

import argparse
from typing import Any

from brainbulge.cli import add_output_options, finish_run, progress_bar, start_run
from brainbulge.cli.options import add_case_options, case_config


def add_parser(sub: Any) -> None:
    from brainbulge.model.hemidisk import DISK_SWELLING, SECTOR_SWELLING, HemidiskCase

    p = sub.add_parser(
        "hemidisk", help="a swelling sector or disk bulging through an opening", description=__doc__
    )
    add_case_options(p, HemidiskCase, {
        "swelling": f"default {SECTOR_SWELLING:g} for a sector, {DISK_SWELLING:g} for a disk"})
    add_output_options(p, "hemidisk-out")
    p.set_defaults(func=run_command)


def config_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The case options given on the command line (the case supplies the others)."""
    from brainbulge.model.hemidisk import HemidiskCase

    return case_config(args, HemidiskCase)


def run_command(args: argparse.Namespace) -> int:
    from brainbulge.cli.checks import hemidisk_case

    return run_case(args, hemidisk_case(config_from_args(args)))  # checked before --out


def run_case(args: argparse.Namespace, case: Any) -> int:
    from brainbulge.model.hemidisk import SOLVER_FIELDS
    from brainbulge.model.problem import case_tables
    from brainbulge.results.measures.schema import HEMIDISK, extremes, printout
    from brainbulge.studies.hemidisk import run_hemidisk

    config = {"command": "hemidisk", **case_tables(case, SOLVER_FIELDS)}
    out = start_run(args, config)
    summary = run_hemidisk(case, out, progress=progress_bar())
    finish_run(out)
    print(printout(summary, ("max_displacement", *extremes()[:4], "max_penetration",
                             "max_skull_crossing"), HEMIDISK))
    return 0
