"""Benchmark of the craniectomy planner: a (diameters x centres) plan on one shared mesh.

Run ``python benchmarks/bench_plan.py [--tets 100000 | --mesh brain.npz] [--diameters 80 100
120 140 160] [--centres 10] [--swell left] [--workers 2] [--edge-radius MM] [--out DIR]``:
builds (or reads) the ICBM152 mesh, places the centres, runs the plan on a local Dask cluster
(``--workers``) or ``--scheduler serial``, and prints one row per plan (Newton iterations,
warm start, solve s)
and the totals: plans run, wall time, time per plan, the recommendation. ``--cold`` runs
every plan from ``Js = 1`` (no warm starts), for comparison; ``--linear-solver`` overrides
``brainbulge plan``'s default (GMRES + AMG).
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

from brainbulge.results.measures.plan_defaults import LINEAR_SOLVER
from brainbulge.runtime import configure as configure_runtime


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tets", type=int, default=100_000)
    ap.add_argument("--mesh", default=None, help="a brain.npz (instead of --tets)")
    ap.add_argument("--diameters", type=float, nargs="+", default=[80, 100, 120, 140, 160])
    ap.add_argument("--centres", type=int, default=10)
    ap.add_argument("--swell", default="left")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scheduler", default=None)
    ap.add_argument("--tolerance", type=float, default=1e-9)
    ap.add_argument("--cold", action="store_true", help="no warm starts")
    ap.add_argument("--linear-solver", default=LINEAR_SOLVER, choices=["pardiso", "krylov"],
                    help=f"default: {LINEAR_SOLVER}, as `brainbulge plan`")
    ap.add_argument("--edge-radius", type=float, default=None,
                    help="skull edge radius [mm] (default: the product's)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    configure_runtime()

    from brainbulge.model.brain import CraniectomyCase
    from brainbulge.results.present.plan_report import plan_rows, recommend
    from brainbulge.studies import plan as planner
    from brainbulge.studies.craniectomy import prepare_study_mesh

    out = Path(args.out or tempfile.mkdtemp(prefix="bench-plan-"))
    t0 = time.perf_counter()
    mesh = args.mesh or str(prepare_study_mesh(out, {"tets": args.tets}))
    t_mesh = time.perf_counter() - t0
    radius = {} if args.edge_radius is None else {"edge_radius_mm": args.edge_radius}
    base = CraniectomyCase(flap="none", swell=args.swell, mesh=str(Path(mesh).resolve()),
                           linear_solver=args.linear_solver, tolerance=args.tolerance, **radius)
    bm = planner.shared_mesh(base.mesh)
    centres = planner.centres_for(bm, args.swell, args.centres, None, base.superior_band())
    cases = planner.plan_cases(base, bm, centres, args.diameters)
    if args.cold:  # every plan its own: no smaller flap at its centre to start from
        cases = [dataclasses.replace(c, extra={**c.extra, "centre_index": k})
                 for k, c in enumerate(cases)]
    t1 = time.perf_counter()
    rows = planner.run_plan(cases, out, scheduler=args.scheduler, workers=args.workers)
    wall = time.perf_counter() - t1
    table = plan_rows(cases, rows)
    print("| plan | diameter mm | area cm2 | Newton its | warm start | solve s | strained ml |")
    print("|---|---|---|---|---|---|---|")
    for r, raw in zip(table, rows, strict=True):
        if r["note"].startswith("does not fit"):
            continue
        print(f"| {r['name']} | {r['diameter_mm']:g} | {r['flap_area_cm2'] or 0:.1f} | "
              f"{r['newton_iterations']} | {raw.get('warm_start_converged')} | "
              f"{r['wall_time_s'] or 0:.0f} | {r['strained_volume_ml'] or 0:.2f} |")
    n_run = sum(1 for c in cases if not c.extra.get("refused"))
    n_ok = sum(1 for r in rows if r.get("complete"))
    best, _, _ = recommend(table)
    print(f"\nmesh {len(bm.tets):,} tets ({t_mesh:.0f} s); {len(cases)} candidates, {n_run} fit, "
          f"{n_ok} complete; plan wall time {wall:.0f} s = {wall / 60:.1f} min, "
          f"{wall / max(n_run, 1):.0f} s per plan ({args.workers} workers); recommended "
          f"{best['name'] if best else None}; results in {out}")


if __name__ == "__main__":
    main()
