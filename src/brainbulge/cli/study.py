"""``brainbulge study NAME``: the paper's sweeps, in parallel on Dask, resumable.

Rerunning the same command on the same ``--out`` resumes: finished scenarios are kept.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from brainbulge.cli import add_cluster_options, add_output_options, finish_run, start_run
from brainbulge.cli.options import add_case_options, field_default
from brainbulge.errors import InputError, StudyIncomplete
from brainbulge.studies.suites import STUDIES

#: the hemidisk case's options a hemidisk study takes from the command line
HEMIDISK_OPTIONS = ("mesh_size", "corner_mesh_size", "rim_mesh_size", "skull")
#: the brain case's options the craniectomy study takes from the command line
CRANIECTOMY_OPTIONS = ("tets", "mesh", "swelling", "fix")


def add_parser(sub: Any) -> None:
    p = sub.add_parser("study", help="run a sweep of scenarios (resumable)", description=__doc__)
    p.add_argument("name", choices=STUDIES)
    add_cluster_options(p)
    from brainbulge.model.brain_case import CraniectomyCase
    from brainbulge.model.hemidisk import HemidiskCase

    add_case_options(p, HemidiskCase, names=("steps",), default_text={  # of every study
        "steps": f"default {HemidiskCase.steps} for hemidisk, {CraniectomyCase.steps} for "
        "craniectomy studies"})
    hemidisk = p.add_argument_group("hemidisk studies (options of the case)")
    add_case_options(hemidisk, HemidiskCase, names=HEMIDISK_OPTIONS)  # type: ignore[arg-type]
    brain = p.add_argument_group("craniectomy study (options of the case)")
    add_case_options(brain, CraniectomyCase, names=CRANIECTOMY_OPTIONS)  # type: ignore[arg-type]
    p.add_argument(
        "--alphas", type=float, nargs="+", default=None, help="sector angles [deg] (sector study)"
    )
    p.add_argument(
        "--betas", type=float, nargs="+", default=None, help="opening angles [deg] (sector study)"
    )
    add_output_options(p, "study-out")
    p.set_defaults(func=run_command)


def scenarios_for(name: str, args: argparse.Namespace) -> list[dict[str, Any]]:
    from brainbulge.studies import hemidisk as hd

    if name == "craniectomy":
        from brainbulge.model.brain_case import CraniectomyCase
        from brainbulge.studies.craniectomy import craniectomy_scenarios

        return craniectomy_scenarios(**{  # each recorded in every scenario
            key: getattr(args, key, field_default(CraniectomyCase, key))
            for key in (*CRANIECTOMY_OPTIONS, "steps")})
    from brainbulge.model.hemidisk import HemidiskCase

    common = {"mesh_size": HemidiskCase.mesh_size,
              "steps": getattr(args, "steps", HemidiskCase.steps),
              "skull": HemidiskCase.skull}  # recorded in every scenario
    for key in HEMIDISK_OPTIONS:  # the others only when given: a rerun of an older study
        if hasattr(args, key):  # folder keeps its scenarios
            common[key] = getattr(args, key)
    if name == "hemidisk-sector":
        return hd.sector_scenarios(
            alphas=args.alphas or hd.SECTOR_ALPHAS, betas=args.betas or hd.SECTOR_BETAS, **common
        )
    return hd.disk_scenarios(**common)


def run_command(args: argparse.Namespace) -> int:
    from brainbulge.cli import checks

    checks.cluster(args.scheduler, args.workers, args.worker_wait)
    for option in ("alphas", "betas"):
        values = getattr(args, option) or []
        if len(set(values)) < len(values):
            raise InputError(f"--{option} {' '.join(f'{v:g}' for v in values)} repeats a "
                             "value; give each once")
    return run_scenarios(args, args.name, scenarios_for(args.name, args))


def run_scenarios(args: argparse.Namespace, name: str, scenarios: list[dict[str, Any]]) -> int:
    """Check every scenario of study ``name``, claim ``--out`` (resumed if it holds this
    study), run them and report; the exit code."""
    from brainbulge.cli import checks
    from brainbulge.studies.runner import validate_scenarios
    from brainbulge.studies.suites import incomplete_text, run_named_study

    validate_scenarios(scenarios)  # names: present, unique
    for sc in scenarios:  # check every scenario before anything starts: exit 2, not 4
        if name == "craniectomy":
            checks.brain_case(sc)
        else:
            checks.hemidisk_case({k: v for k, v in sc.items() if k != "name"})
    out_path = Path(args.out)
    resume = (out_path / "study.json").is_file() and not args.overwrite
    out = start_run(
        args, {"command": "study", "study": name, "scenarios": scenarios}, resume=resume
    )
    n_ok = run_named_study(name, scenarios, out, getattr(args, "scheduler", None),
                           getattr(args, "workers", None))
    if n_ok < len(scenarios):
        raise StudyIncomplete(
            f"{len(scenarios) - n_ok} of {len(scenarios)} scenarios did not complete: "
            f"{incomplete_text(out, scenarios)}"
        )
    finish_run(out)
    return 0
