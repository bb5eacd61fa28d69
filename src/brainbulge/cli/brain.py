"""``brainbulge brain``: one 3D craniectomy scenario on an MRI brain (docs/model.md section 6).

White matter swells (``Js: 1 -> --swelling``) in one hemisphere or both; the brain slides
without friction on the rigid skull and bulges through the flap. The mesh is built from the
ICBM152 template (or ``--labels``) with about ``--tets`` tetrahedra, or read from ``--mesh``
(a ``brain.npz`` of ``brainbulge mesh``). The same command run again on the ``--out`` of a
run that was stopped (killed, out of time) resumes from its ``restart.npz``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from brainbulge.cli import add_output_options, finish_run, progress_bar, require, start_run
from brainbulge.cli.options import add_case_options, case_config, option_names

#: the case's options of which one gives the mesh
MESH_SOURCE = ("mesh", "tets")


def add_parser(sub: Any) -> None:
    from brainbulge.model.brain_case import DEFAULT_TEXT, CraniectomyCase

    p = sub.add_parser(
        "brain", help="3D craniectomy: white-matter swelling bulging through a flap",
        description=__doc__,
    )
    add_case_options(p.add_mutually_exclusive_group(), CraniectomyCase, DEFAULT_TEXT,
                     names=MESH_SOURCE)
    add_case_options(p, CraniectomyCase, DEFAULT_TEXT,
                     names=option_names(CraniectomyCase, *MESH_SOURCE))
    add_output_options(p, "brain-out")
    p.set_defaults(func=run_command)


def config_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The case options given on the command line (the case supplies the others)."""
    from brainbulge.model.brain_case import CraniectomyCase

    return case_config(args, CraniectomyCase)


def run_command(args: argparse.Namespace) -> int:
    from brainbulge.cli.checks import brain_case

    require(not hasattr(args, "label_map") or hasattr(args, "labels") or hasattr(args, "mesh"),
            "--label-map describes the codes of --labels; give --labels too, or drop "
            "--label-map")
    return run_case(args, brain_case(config_from_args(args)))  # checked before --out


def run_case(args: argparse.Namespace, case: Any) -> int:
    from brainbulge.model.brain_case import SOLVER_FIELDS
    from brainbulge.model.problem import case_tables
    from brainbulge.results.measures.schema import BRAIN, printout
    from brainbulge.studies.craniectomy import run_brain

    config = {"command": "brain", **case_tables(case, SOLVER_FIELDS)}
    # a folder with a restart file (a run stopped mid-way) is resumed, unless --overwrite
    resume = (Path(args.out) / "restart.npz").is_file() and not args.overwrite
    out = start_run(args, config, resume=resume)
    s = run_brain(case, out, progress=progress_bar())
    finish_run(out)
    print(printout(s, ("swelling_reached", "max_displacement", "midline_shift_mm",
                       "bulge_volume_ml", "max_principal_strain", "max_penetration_mm"), BRAIN))
    return 0

