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

from brainbulge.cli import (
    add_output_options,
    finish_run,
    positive_float,
    progress_bar,
    require,
    start_run,
    whole_number,
)
from brainbulge.geometry.brain.defaults import (
    EDGE_RADIUS_MM,
    FIXATIONS,
    LARGE_TETS,
    SUPERIOR_ELEVATION_DEG,
    SUPERIOR_WIDTH_MM,
    VOLUME_OF,
)


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "brain", help="3D craniectomy: white-matter swelling bulging through a flap",
        description=__doc__,
    )
    p.add_argument("--flap", choices=("frontal", "left", "right", "custom", "none"),
                   default="left",
                   help="the craniectomy (custom needs --flap-centre; none: intact skull)")
    p.add_argument("--swell", choices=("both", "left", "right"), default="both",
                   help="hemisphere(s) whose white matter swells")
    p.add_argument("--swelling", type=positive_float("--swelling"), default=1.1,
                   help="target Js of the white matter (paper: 1.1)")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--mesh", default=None, help="brain.npz written by `brainbulge mesh`")
    src.add_argument("--tets", type=whole_number("--tets"), default=30_000,
                     help="build a mesh of about this many tets (default 30000)")
    p.add_argument("--labels", default=None, help="NIfTI label map (default: ICBM152 template)")
    p.add_argument("--label-map", default=None,
                   help="label preset (freesurfer, aseg, synthseg, gmwmcsf) or JSON file of "
                   "--labels (default synthseg)")
    p.add_argument("--brain-volume", type=positive_float("--brain-volume"), default=None,
                   help="scale the head so that the --volume-of volume is this [ml]")
    p.add_argument("--volume-of", choices=VOLUME_OF, default="intracranial",
                   help="what --brain-volume sets: the intracranial volume (incl. CSF, the "
                   "default), the brain (cerebral gray + white matter; the paper's 1108 ml) or "
                   "the white matter")
    p.add_argument("--flap-centre", type=float, nargs=3, metavar=("X", "Y", "Z"), default=None,
                   help="centre of a custom flap on the skull [mm, RAS]")
    p.add_argument("--flap-diameter", type=positive_float("--flap-diameter"), default=None,
                   help="diameter of a custom flap [mm]")
    p.add_argument("--fibres", default=None,
                   help="4D NIfTI (nx, ny, nz, 3) of axon directions, e.g. DTI V1, in world "
                   "axes (default: radial from the brain's centre)")
    p.add_argument("--steps", type=int, default=4, help="initial number of load steps")
    p.add_argument("--tolerance", type=positive_float("--tolerance"), default=1e-9,
                   help="Newton's tolerance on the scaled residual at full load (default 1e-9)")
    p.add_argument("--element", choices=("mini", "taylor-hood"), default="mini")
    p.add_argument("--linear-solver", choices=("pardiso", "krylov"), default=None,
                   help="direct, or GMRES with AMG blocks (default: from the size, krylov "
                   f"from {LARGE_TETS:,} tets)")
    p.add_argument("--coarse-tets", type=whole_number("--coarse-tets"), default=None,
                   help="mesh sequencing: solve first on a mesh of about this many tets, then "
                   "finish on the fine mesh from its solution (MINI; default: none, the load is "
                   "ramped on the mesh itself)")
    p.add_argument("--refine", type=int, default=None,
                   help="mesh at tets / 8^K and refine it uniformly K times (0-3); with "
                   "--coarse-tets tets / 8^K the sequencing meshes are nested (default: 1 "
                   f"from {LARGE_TETS:,} tets, else 0)")
    p.add_argument("--coarse-mesh", default=None,
                   help="mesh sequencing with this brain.npz as the coarse mesh (with --mesh)")
    p.add_argument("--material", default="paper", help="tissue preset: paper or paper-pa")
    p.add_argument("--edge-exclusion", type=float, default=5.0,
                   help="band around the flap rim left out of max_*/min_* [mm]")
    p.add_argument("--skull-edge-radius", type=float, default=EDGE_RADIUS_MM,
                   help="rounding radius of the skull's cut edge, in the bone outside the "
                   f"opening [mm] (default {EDGE_RADIUS_MM:g})")
    p.add_argument("--fix", choices=FIXATIONS, default="inferior+superior",
                   help="fixed part of the outer surface: the inferior surface, or that and "
                   "the band along the superior midline (the paper's Figure 6; default)")
    p.add_argument("--superior-width", type=float, default=SUPERIOR_WIDTH_MM,
                   help="width of the fixed superior band across the mid-sagittal plane [mm] "
                   f"(default {SUPERIOR_WIDTH_MM:g}: the superior sagittal sinus)")
    p.add_argument("--superior-elevation", type=float, default=SUPERIOR_ELEVATION_DEG,
                   help="the superior band covers the midline above this elevation seen from "
                   f"the brain centre [deg] (default {SUPERIOR_ELEVATION_DEG:g})")
    add_output_options(p, "brain-out")
    p.set_defaults(func=run_command)


def config_from_args(args: argparse.Namespace) -> dict[str, Any]:
    return {
        "flap": args.flap,
        "swell": args.swell,
        "swelling": args.swelling,
        "tets": args.tets,
        "mesh": args.mesh,
        "labels": args.labels,
        "label_map": args.label_map or "synthseg",
        "brain_volume_ml": args.brain_volume,
        "volume_of": args.volume_of,
        "flap_centre_mm": tuple(args.flap_centre) if args.flap_centre else None,
        "flap_diameter_mm": args.flap_diameter,
        "fibres": args.fibres,
        "steps": args.steps,
        "tolerance": args.tolerance,
        "element": args.element,
        "linear_solver": args.linear_solver,
        "material": args.material,
        "edge_exclusion_mm": args.edge_exclusion,
        "edge_radius_mm": args.skull_edge_radius,
        "fix": args.fix,
        "superior_width_mm": args.superior_width,
        "superior_elevation_deg": args.superior_elevation,
        "coarse_tets": args.coarse_tets,
        "coarse_mesh": args.coarse_mesh,
        "refine": args.refine,
    }


def run_command(args: argparse.Namespace) -> int:
    from brainbulge.cli.checks import brain_case

    require(args.label_map is None or args.labels is not None or args.mesh is not None,
            "--label-map describes the codes of --labels; give --labels too, or drop "
            "--label-map")
    return run_case(args, brain_case(config_from_args(args)))  # checked before --out


def run_case(args: argparse.Namespace, case: Any) -> int:
    from brainbulge.model.brain import SOLVER_FIELDS
    from brainbulge.model.problem import case_tables
    from brainbulge.results.schema import BRAIN, printout
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

