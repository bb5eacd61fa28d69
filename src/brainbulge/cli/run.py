"""``brainbulge run RUN.toml``: any command described by a TOML file.

The file has the shape of the ``run.toml`` every output folder holds, so a run (a hemidisk,
a brain, a study, a mesh, a plan, the demo, the reproduction) is repeated with ``brainbulge
run OUT/run.toml --out NEW``::

    command = "hemidisk"

    [case]        # what is simulated
    alpha = 80.0
    beta = 60.0
    contact = "sliding"

    [solver]      # how it is discretised and solved
    mesh_size = 0.05

Options left out take their defaults; a table or option the command does not know (a typo
such as ``[caes]``, an option outside its table) is refused, naming the nearest valid one.
Run files with one ``[hemidisk]`` or ``[brain]`` table of all options (written by earlier
versions) load too.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
from pathlib import Path
from typing import Any

from brainbulge.cli import add_cluster_options, add_output_options
from brainbulge.errors import InputError

#: the commands a run file can describe
COMMANDS = ("hemidisk", "brain", "study", "mesh", "plan", "demo", "reproduce")
#: the reproduction's run file: key -> the option it records
REPRODUCE_OPTIONS = {"tets": "--tets", "fix": "--fix"}


def add_parser(sub: Any) -> None:
    p = sub.add_parser("run", help="run any command described by a TOML file (a run.toml)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("config", type=Path, help="TOML file (e.g. a previous run.toml)")
    add_cluster_options(p, "studies, plans, the demo")
    add_output_options(p, "run-out")
    p.set_defaults(func=run_command)


def case_fields(cls: type) -> dict[str, None]:
    """A case dataclass's options, as a table's schema."""
    return dict.fromkeys(f.name for f in dataclasses.fields(cls))


def schema(command: str, config: dict[str, Any]) -> dict[str, Any]:
    """The tables and options a run file of ``command`` may hold (from the case
    dataclasses and the tables the commands record)."""
    top: dict[str, Any] = {"command": None}
    if command in ("hemidisk", "brain"):
        case = _case_class(command)
        fields = case_fields(case) | ({"contact_method": None} if command == "hemidisk" else {})
        return top | {"case": fields, "solver": fields, command: fields}
    if command == "study":
        study = config.get("study")
        fields = case_fields(_case_class("brain" if study == "craniectomy" else "hemidisk"))
        return top | {"study": None, "scenarios": [fields | {"name": None}]}
    if command in ("mesh", "plan"):
        from brainbulge.cli import mesh, plan

        options = (mesh if command == "mesh" else plan).CONFIG_OPTIONS
        return top | {command: dict.fromkeys(options)}
    if command == "demo":
        from brainbulge.studies.suites import demo_plan

        tables = demo_plan(bool(config.get("quick")))
        return top | {"quick": None} | {k: dict.fromkeys(v) for k, v in tables.items()}
    return top | dict.fromkeys(REPRODUCE_OPTIONS)


def _case_class(command: str) -> type:
    if command == "brain":
        from brainbulge.model.brain import CraniectomyCase

        return CraniectomyCase
    from brainbulge.model.hemidisk import HemidiskCase

    return HemidiskCase


def run_command(args: argparse.Namespace) -> int:
    from brainbulge.results.records.config_file import check_keys
    from brainbulge.results.records.run_record import load_config

    config = load_config(args.config)
    command = config.get("command")
    if command not in COMMANDS:
        raise InputError(
            f"{args.config}: 'command' must be one of {', '.join(COMMANDS)}, got {command!r}"
        )
    check_keys(config, schema(command, config), str(args.config))
    from brainbulge.cli import checks

    if command == "study":  # the other commands check --scheduler themselves
        checks.cluster(args.scheduler, args.workers, args.worker_wait)
    elif args.workers is not None:
        checks.number("--workers", args.workers, *checks.WORKERS, integer=True)
    if command in ("hemidisk", "brain"):
        from brainbulge.model.problem import case_options

        table = case_options(config, command, str(args.config))
        if command == "brain":
            from brainbulge.cli.brain import run_case as run_brain_case

            return run_brain_case(args, checks.brain_case(table))  # checked before --out
        from brainbulge.cli.hemidisk import run_case

        return run_case(args, checks.hemidisk_case(table))
    if command == "study":
        from brainbulge.cli.study import run_scenarios
        from brainbulge.studies.suites import STUDIES

        if config.get("study") not in STUDIES:
            raise InputError(f"{args.config}: 'study' must be one of {', '.join(STUDIES)}, "
                             f"got {config.get('study')!r}")
        if not config.get("scenarios"):
            raise InputError(f"{args.config}: the study has no [[scenarios]]; give at least one")
        return run_scenarios(args, config["study"], config["scenarios"])
    argv = _argv(command, config, str(args.config))
    command_args = _parse([command, *argv], str(args.config))
    for name in ("out", "overwrite", "scheduler", "workers", "worker_wait"):
        if hasattr(command_args, name):
            setattr(command_args, name, getattr(args, name))
    command_args.config = args.config  # the run file: an input, never deleted
    return int(command_args.func(command_args) or 0)


def _argv(command: str, config: dict[str, Any], where: str) -> list[str]:
    """The command line a run file of ``mesh``, ``plan``, ``demo`` or ``reproduce``
    records."""
    if command == "demo":
        from brainbulge.studies.suites import demo_plan

        quick = config.get("quick", False)
        if not isinstance(quick, bool):
            raise InputError(f"{where}: quick = {quick!r} must be true or false")
        plan = demo_plan(quick)
        changed = sorted(k for k in plan if k in config and config[k] != plan[k])
        if changed:
            raise InputError(f"{where}: the demo's [{changed[0]}] is fixed (only quick = true "
                             "or false chooses); run a study for other scenarios")
        return ["--quick"] if quick else []
    if command == "reproduce":
        options, table = REPRODUCE_OPTIONS, config
    else:
        from brainbulge.cli import mesh, plan

        options = (mesh if command == "mesh" else plan).CONFIG_OPTIONS
        table = config.get(command, {})
    argv: list[str] = []
    for key, value in table.items():
        if key not in options:
            continue  # "command" of the reproduction's file
        if isinstance(value, bool) or isinstance(value, dict):
            raise InputError(f"{where}: {key} = {value!r} must be a number, text or a list")
        items = value if isinstance(value, list) else [value]
        if key == "centres_mm":  # one --centre X Y Z per centre
            for centre in items:
                argv += [options[key], *map(str, centre if isinstance(centre, list) else
                                             [centre])]
            continue
        argv += [options[key], *map(str, items)]
    return argv


def _parse(argv: list[str], where: str) -> argparse.Namespace:
    """``argv`` parsed as the command line would be; a bad value is an `InputError` naming
    the run file."""
    from brainbulge.cli import build_parser

    errors = io.StringIO()
    try:
        with contextlib.redirect_stderr(errors):
            return build_parser().parse_args(argv)
    except SystemExit:
        message = errors.getvalue().strip().removeprefix("error: ").split("; see `")[0]
        raise InputError(f"{where}: {message}; correct it in the run file") from None
