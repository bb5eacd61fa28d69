"""``brainbulge plan``: search the craniectomy flap's centre and diameter for the least tissue
damage.

Every (centre, diameter) pair is one 3D scenario on one shared brain mesh (the flap is a
boundary condition), run on a local Dask cluster (or ``--scheduler``), warm-started from the
finished plan of the next smaller flap at the same centre. Candidate centres are spread evenly
over the skull's convexity above the swelling (``--centres N``) or given (``--centre X Y Z``,
repeated); a flap that reaches the fixed base or crosses the midline is left out, one that
reaches the fixed superior band is clipped there. Writes ``plan.csv``, ``pareto.png``,
``centres.png``, ``report.md`` and one folder per plan; rerun the same command on the same
``--out`` to resume.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from brainbulge.cli import (
    add_output_options,
    finish_run,
    positive_float,
    require,
    start_run,
    whole_number,
)

#: flap diameters the planner accepts [mm] (reported clinical areas 9.5-205 cm^2)
DIAMETER_RANGE_MM = (40.0, 200.0)
#: candidate centres at most
MAX_CENTRES = 100
#: the ``[plan]`` table of the run file: key -> the option it records
CONFIG_OPTIONS = {"swell": "--swell", "swelling": "--swelling", "steps": "--steps",
                  "tolerance": "--tolerance", "linear_solver": "--linear-solver",
                  "edge_radius_mm": "--skull-edge-radius", "mesh": "--mesh", "tets": "--tets",
                  "labels": "--labels", "label_map": "--label-map",
                  "diameters_mm": "--diameters", "centres_mm": "--centre",
                  "n_centres": "--centres", "strain_threshold": "--threshold"}


def add_parser(sub: Any) -> None:
    from brainbulge.geometry.brain.defaults import EDGE_RADIUS_MM
    from brainbulge.results.plan_defaults import (
        DIAMETERS_MM,
        LINEAR_SOLVER,
        N_CENTRES,
        STRAIN_THRESHOLD,
    )

    p = sub.add_parser("plan", help="search the flap's centre and size for the least damage",
                       description=__doc__)
    p.add_argument("--swell", choices=("both", "left", "right"), required=True,
                   help="hemisphere(s) whose white matter swells")
    p.add_argument("--swelling", type=positive_float("--swelling"), default=1.1,
                   help="target Js of the white matter (paper: 1.1)")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--mesh", default=None, help="brain.npz written by `brainbulge mesh`")
    src.add_argument("--labels", default=None,
                     help="NIfTI label map (default: the ICBM152 template)")
    p.add_argument("--label-map", default=None,
                   help="label preset or JSON file of --labels (default synthseg)")
    p.add_argument("--tets", type=whole_number("--tets"), default=100_000,
                   help="mesh size built here in tets (default 100000)")
    p.add_argument("--diameters", type=float, nargs="+", default=list(DIAMETERS_MM),
                   metavar="MM", help="flap diameters [mm] (default "
                   f"{' '.join(f'{d:g}' for d in DIAMETERS_MM)})")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--centres", type=int, default=None, metavar="N",
                       help=f"N candidate centres spread over the convexity (default "
                       f"{N_CENTRES}; even with --swell both)")
    where.add_argument("--centre", type=float, nargs=3, action="append", default=None,
                       metavar=("X", "Y", "Z"),
                       help="a candidate centre on the skull [mm, RAS]; repeat for more")
    p.add_argument("--threshold", type=positive_float("--threshold"),
                   default=STRAIN_THRESHOLD,
                   help="principal strain above which tissue counts as strained (default "
                   f"{STRAIN_THRESHOLD:g}: Bain & Meaney 2000)")
    p.add_argument("--steps", type=int, default=4, help="initial load steps of a cold start")
    p.add_argument("--tolerance", type=positive_float("--tolerance"), default=1e-9,
                   help="Newton's tolerance at full load (default 1e-9)")
    p.add_argument("--linear-solver", choices=("pardiso", "krylov"), default=LINEAR_SOLVER,
                   help=f"linear solver (default {LINEAR_SOLVER}: GMRES + AMG)")
    p.add_argument("--skull-edge-radius", type=positive_float("--skull-edge-radius"),
                   default=EDGE_RADIUS_MM,
                   help="rounding radius of the skull's cut edge, in the bone outside the "
                   f"opening [mm] (default {EDGE_RADIUS_MM:g}; small flaps converge faster "
                   "with less, see docs/known-limits.md)")
    p.add_argument("--scheduler", default=None,
                   help="address of a running Dask scheduler (default: a local cluster); "
                   "'serial' runs in this process")
    p.add_argument("--workers", type=int, default=None, help="local worker processes")
    add_output_options(p, "plan-out")
    p.set_defaults(func=run_command)


def common_config(args: argparse.Namespace) -> dict[str, Any]:
    """The options every plan shares (a :class:`CraniectomyCase` as a dict)."""
    config = {"swell": args.swell, "swelling": args.swelling, "steps": args.steps,
              "tolerance": args.tolerance, "linear_solver": args.linear_solver,
              "edge_radius_mm": args.skull_edge_radius}
    if args.mesh is not None:
        config["mesh"] = args.mesh
    else:
        config["tets"] = args.tets
        if args.labels is not None:
            config["labels"] = args.labels
            config["label_map"] = args.label_map or "synthseg"
    return config


def run_command(args: argparse.Namespace) -> int:
    from brainbulge.cli import checks

    require(args.label_map is None or args.labels is not None,
            "--label-map describes the codes of --labels; give --labels too, or drop it")
    for d in args.diameters:
        checks.number("--diameters", d, *DIAMETER_RANGE_MM, " mm")
    require(len(set(args.diameters)) == len(args.diameters),
            f"--diameters {' '.join(f'{d:g}' for d in args.diameters)} repeats a value")
    if args.centres is not None:
        checks.number("--centres", args.centres, 1, MAX_CENTRES, integer=True)
        require(args.swell != "both" or args.centres % 2 == 0,
                f"--centres {args.centres} must be even with --swell both (half on each side)")
    for c in args.centre or []:
        require(all(abs(v) <= checks.FLAP_CENTRE_MM for v in c),
                f"--centre {' '.join(f'{v:g}' for v in c)} is not near the skull: give a "
                f"point on it, each coordinate within +-{checks.FLAP_CENTRE_MM:g} mm (RAS)")
    checks.number("--threshold", args.threshold, 1e-3, 1.0)
    if args.workers is not None:
        checks.number("--workers", args.workers, 1, 256, integer=True)
    checks.scheduler(args.scheduler)
    common = common_config(args)
    checks.brain_case({**common, "flap": "none"})  # the flaps are checked on the mesh
    config = {"command": "plan", "plan": {
        **common,
        "diameters_mm": [float(d) for d in args.diameters],
        **({"centres_mm": [list(c) for c in args.centre]} if args.centre else
           {"n_centres": args.centres}),
        "strain_threshold": args.threshold}}
    config["plan"] = {k: v for k, v in config["plan"].items() if v is not None}
    resume = (Path(args.out) / "study.json").is_file() and not args.overwrite
    out = start_run(args, config, resume=resume)
    n_ok, n_run, best = run_plan_command(out, common, args)
    if n_ok < n_run:
        from brainbulge.cli.study import StudyIncomplete

        raise StudyIncomplete(f"{n_run - n_ok} of {n_run} plans did not complete; the report "
                              f"covers the others; rerun the same command to retry them "
                              f"(see {out}/study.json)")
    finish_run(out, f"recommended {best}" if best else "")
    if best:
        print(f"recommended flap: {best} (see {out}/report.md)")
    return 0


def run_plan_command(out: Path, common: dict[str, Any], args: argparse.Namespace
                     ) -> tuple[int, int, str | None]:
    """Build or reuse the shared mesh, place the candidates, run the plan; return (plans
    completed, plans run, the recommended plan's name)."""
    from brainbulge.results.plan_report import plan_rows, recommend
    from brainbulge.studies.craniectomy import case_from_dict, prepare_study_mesh
    from brainbulge.studies.plan import centres_for, plan_cases, run_plan, shared_mesh

    mesh = prepare_study_mesh(out, common)
    base = {k: v for k, v in common.items() if k not in ("tets", "labels", "label_map")}
    base = case_from_dict({**base, "mesh": str(Path(mesh).resolve()), "flap": "none"})
    bm = shared_mesh(str(base.mesh))
    centres = centres_for(bm, args.swell, args.centres, args.centre, base.superior_band())
    cases = plan_cases(base, bm, centres, args.diameters)
    rows = run_plan(cases, out, scheduler=args.scheduler, workers=args.workers,
                    threshold=args.threshold)
    n_run = sum(1 for c in cases if not c.extra.get("refused"))
    best, _, _ = recommend(plan_rows(cases, rows))
    return sum(1 for r in rows if r.get("complete")), n_run, (
        None if best is None else best["name"])
