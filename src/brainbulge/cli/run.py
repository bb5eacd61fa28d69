"""``brainbulge run CASE.toml``: any command described by a TOML file.

The file has the shape of the ``run.toml`` every output folder holds, so a run is repeated
with ``brainbulge run OUT/run.toml --out NEW``::

    command = "hemidisk"

    [case]        # what is simulated
    alpha = 80.0
    beta = 60.0
    contact = "sliding"

    [solver]      # how it is discretised and solved
    mesh_size = 0.05

Options left out take their defaults; run files with one ``[hemidisk]`` or ``[brain]`` table
of all options (written by earlier versions) load too.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from brainbulge.cli import add_output_options
from brainbulge.errors import InputError

COMMANDS = ("hemidisk", "brain")


def add_parser(sub: Any) -> None:
    p = sub.add_parser("run", help="run a case described by a TOML file", description=__doc__)
    p.add_argument("config", type=Path, help="TOML file (e.g. a previous run.toml)")
    add_output_options(p, "run-out")
    p.set_defaults(func=run_command)


def run_command(args: argparse.Namespace) -> int:
    from brainbulge.results.run_record import load_config

    config = load_config(args.config)
    command = config.get("command")
    if command not in COMMANDS:
        raise InputError(
            f"{args.config}: 'command' must be one of {', '.join(COMMANDS)}, got {command!r}"
        )
    from brainbulge.cli import checks
    from brainbulge.model.problem import case_options

    table = case_options(config, command, str(args.config))

    if command == "brain":
        from brainbulge.cli.brain import run_case as run_brain_case

        return run_brain_case(args, checks.brain_case(table))  # checked before --out
    from brainbulge.cli.hemidisk import run_case

    return run_case(args, checks.hemidisk_case(table))
