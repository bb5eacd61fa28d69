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

from brainbulge.cli import add_cluster_options, add_output_options, finish_run, require, start_run
from brainbulge.cli.options import add_case_options, case_config, field_default, flag


def _fields() -> dict[str, Any]:
    """The fields the ``[plan]`` table of a run file holds, by name: the case's options the
    plans share and the planner's own."""
    import dataclasses

    from brainbulge.model.brain_case import CraniectomyCase
    from brainbulge.studies.plan_options import CASE_OPTIONS, PlanOptions

    case = {f.name: f for f in dataclasses.fields(CraniectomyCase) if f.name in CASE_OPTIONS}
    return case | {f.name: f for f in dataclasses.fields(PlanOptions)}


def __getattr__(name: str) -> Any:
    if name == "CONFIG_OPTIONS":  # the ``[plan]`` table: key -> the option it records
        return {key: flag(f) for key, f in _fields().items()}
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def add_parser(sub: Any) -> None:
    from brainbulge.model.brain_case import CraniectomyCase
    from brainbulge.studies.plan_options import CASE_OPTIONS, DEFAULT_TEXT, PlanOptions

    p = sub.add_parser("plan", help="search the flap's centre and size for the least damage",
                       description=__doc__)
    source = p.add_mutually_exclusive_group()
    add_case_options(source, CraniectomyCase, DEFAULT_TEXT, names=("mesh", "labels"))
    add_case_options(p, CraniectomyCase, DEFAULT_TEXT, required=("swell",),
                     names=tuple(n for n in CASE_OPTIONS if n not in ("mesh", "labels")))
    where = p.add_mutually_exclusive_group()
    add_case_options(where, PlanOptions, DEFAULT_TEXT, names=("n_centres", "centres_mm"))
    add_case_options(p, PlanOptions, DEFAULT_TEXT, names=("diameters_mm", "strain_threshold"))
    add_cluster_options(p)
    add_output_options(p, "plan-out")
    p.set_defaults(func=run_command)


def common_config(args: argparse.Namespace) -> dict[str, Any]:
    """The options every plan shares (a :class:`CraniectomyCase` as a dict), each recorded:
    those given, else the planner's defaults
    (:data:`~brainbulge.studies.plan_options.CASE_DEFAULTS`), else the case's; the mesh, or
    what it is built from."""
    from brainbulge.model.brain_case import CraniectomyCase
    from brainbulge.studies.plan_options import CASE_DEFAULTS, CASE_OPTIONS

    given = case_config(args, CraniectomyCase)  # the parser has CASE_OPTIONS of the case
    source = ("mesh",) if "mesh" in given else ("tets", "labels", "label_map") if (
        "labels" in given) else ("tets",)
    return {k: given.get(k, CASE_DEFAULTS.get(k, field_default(CraniectomyCase, k)))
            for k in CASE_OPTIONS if k not in ("mesh", "tets", "labels", "label_map")
            or k in source}


def plan_options(args: argparse.Namespace) -> Any:
    """The checked :class:`~brainbulge.studies.plan_options.PlanOptions` of the command
    line."""
    from brainbulge.studies.plan_options import PlanOptions

    return PlanOptions(**case_config(args, PlanOptions))


def run_command(args: argparse.Namespace) -> int:
    from brainbulge.cli import checks

    require(not hasattr(args, "label_map") or hasattr(args, "labels"),
            "--label-map describes the codes of --labels; give --labels too, or drop it")
    options = plan_options(args)
    if options.n_centres is not None:
        require(args.swell != "both" or options.n_centres % 2 == 0,
                f"--centres {options.n_centres} must be even with --swell both (half on each "
                "side)")
    for c in options.centres_mm or []:
        require(all(abs(v) <= checks.FLAP_CENTRE_MM for v in c),
                f"--centre {' '.join(f'{v:g}' for v in c)} is not near the skull: give a "
                f"point on it, each coordinate within +-{checks.FLAP_CENTRE_MM:g} mm (RAS)")
    checks.cluster(args.scheduler, args.workers, args.worker_wait)
    common = common_config(args)
    checks.brain_case({**common, "flap": "none"})  # the flaps are checked on the mesh
    config = {"command": "plan", "plan": {
        **common,
        "diameters_mm": list(options.diameters_mm),
        **({"centres_mm": [list(c) for c in options.centres_mm]} if options.centres_mm else
           {"n_centres": options.n_centres}),
        "strain_threshold": options.strain_threshold}}
    config["plan"] = {k: v for k, v in config["plan"].items() if v is not None}
    resume = (Path(args.out) / "study.json").is_file() and not args.overwrite
    out = start_run(args, config, resume=resume)
    n_ok, n_run, best = run_plan_command(out, common, args, options)
    if n_ok < n_run:
        from brainbulge.cli.study import StudyIncomplete

        raise StudyIncomplete(f"{n_run - n_ok} of {n_run} plans did not complete; the report "
                              f"covers the others; rerun the same command to retry them "
                              f"(see {out}/study.json)")
    finish_run(out, f"recommended {best}" if best else "")
    if best:
        print(f"recommended flap: {best} (see {out}/report.md)")
    return 0


def run_plan_command(out: Path, common: dict[str, Any], args: argparse.Namespace,
                     options: Any) -> tuple[int, int, str | None]:
    """Build or reuse the shared mesh, place the candidates, run the plan; return (plans
    completed, plans run, the recommended plan's name)."""
    from brainbulge.results.present.plan_report import plan_rows, recommend
    from brainbulge.studies.craniectomy import case_from_dict, prepare_study_mesh
    from brainbulge.studies.plan import centres_for, plan_cases, run_plan, shared_mesh

    mesh = prepare_study_mesh(out, common)
    base = {k: v for k, v in common.items() if k not in ("tets", "labels", "label_map")}
    base = case_from_dict({**base, "mesh": str(Path(mesh).resolve()), "flap": "none"})
    bm = shared_mesh(str(base.mesh))
    centres = centres_for(bm, base.swell, options.n_centres, options.centres_mm,
                          base.superior_band())
    cases = plan_cases(base, bm, centres, options.diameters_mm)
    rows = run_plan(cases, out, scheduler=args.scheduler, workers=args.workers,
                    threshold=options.strain_threshold)
    n_run = sum(1 for c in cases if not c.extra.get("refused"))
    best, _, _ = recommend(plan_rows(cases, rows))
    return sum(1 for r in rows if r.get("complete")), n_run, (
        None if best is None else best["name"])
