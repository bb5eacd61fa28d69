"""Benchmark of one 3D craniectomy scenario (left flap, both-sided swelling, Js 1 -> 1.1).

Run ``python benchmarks/bench_brain.py [--sizes 30000 100000 400000] [--steps 2]
[--variants baseline direct krylov] [--edge-radius MM] [--tolerance TOL]``. Each (size,
variant) runs in a fresh subprocess (its own peak memory): the ICBM152 mesh is built (or reused from
``--cache DIR``), then solved. A run stopped mid-way (killed, out of time) continues from its
restart file with ``--resume``; without it every run starts at Js = 1.

Variants (the same mesh, model and outputs):

- ``baseline``: the straightforward approach: Taylor-Hood P2/P1, the energy interpreted,
  PARDISO on every Newton matrix;
- ``direct``: MINI (P1 + condensed bubble / P1), the energy compiled to machine code, PARDISO;
- ``krylov``: MINI, compiled, GMRES with AMG blocks at Eisenstat-Walker tolerances;
- ``th-krylov``: Taylor-Hood, compiled, GMRES with a two-level cycle on the P2 block (the
  P1 part's AMG inside Gauss-Seidel sweeps): a Taylor-Hood reference on meshes beyond
  PARDISO's reach here.

``--refine K`` builds the fine meshes by Netgen at N / 8^K and K uniform refinements
(cached as ``brain_N_rK``); with ``--flat`` the new surface nodes stay at their midpoints
(cached as ``brain_N_rK_flat``): every mesh of the family has the Netgen mesh's geometry
exactly, as a Taylor-Hood solution on it sees it (a comparison of elements on one geometry).
``BRAINBULGE_KEEP_HEAP=0`` in the environment returns freed arrays to the system (glibc's
default; ``brainbulge.heap`` keeps them: faster, a little more memory).

The table gives tets, DOFs, mesh time, solve time (assembly / linear solve), the whole run
with its outputs, Newton and Krylov iterations, peak resident memory, the midline shift, the
bulge volume and the penetration; then, per size with a baseline, each variant's speed-up
over it: in the whole solve when both reach Js = 1.1, and always per Newton iteration (a run
that stops early reports its partial summary, marked as such). Each run logs its Newton
residuals to ``CACHE/run_N_VARIANT.log``. ``--tolerance`` sets Newton's stopping tolerance at
full load for every variant: the Taylor-Hood baseline stalls above the default 1e-9 on the
brain (|R| ~ 3e-6-7e-6), so its whole-solve ratio is measured at e.g. ``--tolerance 1e-5``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from brainbulge.geometry.brain.skull import EDGE_RADIUS_MM
from brainbulge.runtime import configure as configure_runtime
from memory import peak_mb

VARIANTS = {
    "baseline": {"element": "taylor-hood", "linear_solver": "pardiso", "compile": False},
    "direct": {"element": "mini", "linear_solver": "pardiso", "compile": True},
    "krylov": {"element": "mini", "linear_solver": "krylov", "compile": True},
    "th-krylov": {"element": "taylor-hood", "linear_solver": "krylov", "compile": True},
}


def mesh_tag(target_tets: int, refine: int = 0, flat: bool = False) -> str:
    """``N``, ``N_rK`` or ``N_rK_flat``: the name of a mesh in the cache and of its runs."""
    if not refine:  # nothing refined: flat or not, the Netgen mesh
        return f"{target_tets}"
    return f"{target_tets}_r{refine}" + ("_flat" if flat else "")


def cached_mesh(target_tets: int, cache: Path, refine: int = 0, flat: bool = False):
    """The ICBM152 brain mesh of about ``target_tets`` tets (Netgen at ``target_tets /
    8**refine``, refined ``refine`` times, new surface nodes left at their midpoints if
    ``flat``), built once into ``cache``."""
    from brainbulge.geometry.brain import build_brain_mesh, load_brain_mesh, save_brain_mesh

    path = cache / f"brain_{mesh_tag(target_tets, refine, flat)}" / "brain.npz"
    if path.is_file():
        return load_brain_mesh(path)
    bm = build_brain_mesh(target_tets=target_tets, refinements=refine,
                          refine_onto_envelope=not flat)
    save_brain_mesh(bm, path.parent, figures=False)
    return bm


def one(target_tets: int, steps: int, cache: Path, variant: str,
        edge_radius_mm: float = EDGE_RADIUS_MM, resume: bool = False,
        refine: int = 0, tolerance: float = 1e-9,
        flat: bool = False) -> dict:
    import logging

    from brainbulge.errors import ConvergenceError
    from brainbulge.studies.craniectomy import run_brain

    cache.mkdir(parents=True, exist_ok=True)
    tag = mesh_tag(target_tets, refine, flat)
    logging.basicConfig(  # per-iteration residuals and Krylov counts, for a slow run
        level=logging.DEBUG, filename=cache / f"run_{tag}_{variant}.log", filemode="w",
        format="%(asctime)s %(name)s %(message)s")
    for noisy in ("matplotlib", "PIL"):
        logging.getLogger(noisy).setLevel(logging.WARNING)
    t0 = time.perf_counter()
    bm = cached_mesh(target_tets, cache, refine, flat)
    t_mesh = time.perf_counter() - t0
    out = cache / f"run_{tag}_{variant}"
    restart = out / "restart.npz"  # left by a run that was stopped
    if not resume:  # a timing from Js = 1
        restart.unlink(missing_ok=True)
    t1 = time.perf_counter()
    try:
        s = run_brain({"flap": "left", "swell": "both", "steps": steps,
                       "edge_radius_mm": edge_radius_mm, "tolerance": tolerance,
                       **VARIANTS[variant]},
                      out, brain_mesh=bm)
    except ConvergenceError:  # stopped before Js = 1.1: its partial summary is on disk
        s = json.loads((out / "summary.json").read_text())
    t_run = time.perf_counter() - t1
    return {
        "tets": s["elements"], "dofs": s["dofs"], "mesh_s": t_mesh, "solve_s": s["wall_time_s"],
        "assembly_s": s["assembly_time_s"], "linear_s": s["linear_solve_time_s"],
        "newton": s["newton_iterations"], "steps": s["load_steps"],
        "linear_its": s["linear_iterations"], "run_s": t_run, "converged": s["converged"],
        "peak_mb": peak_mb(),
        "shift_mm": s["midline_shift_mm"], "bulge_ml": s["bulge_volume_ml"],
        "penetration_mm": s["max_penetration_mm"], "variant": variant,
        # the solver's word: a restart file of another problem is not resumed
        "resumed_at": s.get("resumed_from_load", 0.0), "load_reached": s.get("load_reached", 1.0),
    }


HEADER = (f"{'target':>8} {'variant':>9} {'tets':>8} {'dofs':>8} {'mesh s':>7} {'solve s':>8} "
          f"{'asm s':>7} {'lin s':>7} {'run s':>7} {'newton':>6} {'lin its':>7} {'peak MB':>8} "
          f"{'shift mm':>8} {'bulge ml':>8} {'pen mm':>8}")


def row(n: int, r: dict) -> str:
    return (f"{n:>8} {r['variant']:>9} {r['tets']:>8} {r['dofs']:>8} {r['mesh_s']:>7.0f} "
            f"{r['solve_s']:>8.0f} {r['assembly_s']:>7.0f} {r['linear_s']:>7.0f} "
            f"{r['run_s']:>7.0f} {r['newton']:>6} {r['linear_its']:>7} {r['peak_mb']:>8.0f} "
            f"{r['shift_mm']:>8.2f} {r['bulge_ml']:>8.1f} {r['penetration_mm']:>8.1e}")


def main() -> int:
    configure_runtime()
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[30_000, 100_000, 400_000])
    parser.add_argument("--steps", type=int, default=2)
    parser.add_argument("--cache", type=Path, default=Path("bench-brain"))
    parser.add_argument("--variants", nargs="+", choices=list(VARIANTS),
                        default=["direct", "krylov"], help="what to compare (see above)")
    parser.add_argument("--edge-radius", type=float, default=EDGE_RADIUS_MM,
                        help="rounded cut edge of the skull at the flap [mm] (the brain "
                             "command's --skull-edge-radius)")
    parser.add_argument("--refine", type=int, default=0, metavar="K",
                        help="fine meshes by K uniform refinements of Netgen's mesh at N / 8^K")
    parser.add_argument("--flat", action="store_true",
                        help="with --refine: new surface nodes stay at their midpoints (the "
                             "Netgen mesh's geometry exactly)")
    parser.add_argument("--tolerance", type=float, default=1e-9,
                        help="Newton's tolerance on the scaled residual at full load, for "
                             "every variant (the brain command's --tolerance)")
    parser.add_argument("--resume", action="store_true",
                        help="continue a stopped run from its restart file (CACHE/run_N_VARIANT/"
                             "restart.npz); the times then cover only this part")
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        r = one(args.one, args.steps, args.cache, args.variants[0], args.edge_radius,
                args.resume, args.refine, args.tolerance, args.flat)
        print("RESULT " + json.dumps(r), flush=True)
        return 0
    print(HEADER, flush=True)
    results: dict[tuple[int, str], dict] = {}
    for n, variant in ((n, v) for n in args.sizes for v in args.variants):
        cmd = [sys.executable, __file__, "--one", str(n), "--steps", str(args.steps),
               "--cache", str(args.cache), "--variants", variant,
               "--edge-radius", str(args.edge_radius),
               "--refine", str(args.refine), "--tolerance", str(args.tolerance)]
        cmd += ["--resume"] if args.resume else []
        cmd += ["--flat"] if args.flat else []
        res = subprocess.run(cmd, capture_output=True, text=True)
        lines = [ln for ln in res.stdout.splitlines() if ln.startswith("RESULT ")]
        if not lines:
            tail = (res.stderr.strip().splitlines() or ["?"])[-1]
            print(f"{n:>8} {variant:>8} failed: {tail}", flush=True)
            continue
        results[n, variant] = json.loads(lines[-1][7:])
        print(row(n, results[n, variant]), flush=True)
        if not results[n, variant]["converged"]:
            print(f"{'':>8} {variant:>8}: stopped at load {results[n, variant]['load_reached']:.3f}"
                  " (partial run: compare its time per Newton iteration)", flush=True)
        if results[n, variant].get("resumed_at"):
            print(f"{'':>8} {variant:>8}: resumed at load {results[n, variant]['resumed_at']:.3f}"
                  "; the times above are of this part only", flush=True)
    for n in args.sizes:
        base = results.get((n, "baseline"))
        if base is None:
            continue
        for v in args.variants:
            r = results.get((n, v))
            if v != "baseline" and r is not None:
                if base["converged"] and r["converged"]:
                    print(f"{n:>8} {v:>8}: {base['solve_s'] / r['solve_s']:.1f}x faster than "
                          f"the baseline in the solve, {base['run_s'] / r['run_s']:.1f}x in the "
                          "whole run", flush=True)
                per_it = [x["solve_s"] / max(x["newton"], 1) for x in (base, r)]
                print(f"{n:>8} {v:>8}: {per_it[0] / per_it[1]:.1f}x faster per Newton iteration "
                      f"({per_it[0]:.1f} s against {per_it[1]:.1f} s)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
