"""Linear-solver benchmark: the MINI tangent of the brain, direct (PARDISO) against Krylov.

For each mesh size: build (or load from ``--cache``) the ICBM152 brain mesh, set up the
white-matter swelling problem (``Js = 1.1`` in both hemispheres, left flap open), solve the
load step ``--load`` by Newton's method (with the Krylov solver), then take the tangent at
that state with the right-hand side of the next load step (``--load + 0.25``) as system 1 and
the tangent after one Newton step on it as system 2. Each solver runs in a fresh process (so
its peak memory is its own) on system 1 (set-up + solve) and on system 2 (the Krylov solvers
reuse their AMG set-up). Prints one table row per solver.

The skull is clamped (``base|skull``), a stand-in for the contact with the rigid skull.

    python benchmarks/bench_linear.py --tets 30000 100000
    python benchmarks/bench_linear.py --tets 30000 --variants gmres-simple --rtols 1e-2 1e-4

Columns: setup_s (AMG set-up, PARDISO factorisation counted in solve), solve_s (system 1),
its (Krylov iterations), res (true relative residual), err (relative difference from the
PARDISO solution), reuse_s / reuse_its (system 2, hierarchy reused), peak_mb (process peak
RSS) and extra_mb (the solver's own: peak RSS during the solves minus the RSS before them).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from brainbulge.runtime import configure as configure_runtime
from memory import peak_mb, status_mb

#: Krylov variants: the product's SIMPLE Schur approximation, and for comparison an AMG
#: cycle on the pressure mass weighted by 1/mu (or by one 1/mu_max) plus C.
VARIANTS = {"gmres-simple": None, "gmres-mass": "weighted", "gmres-mass-unweighted": "unweighted"}


def pressure_schur_mass(form, free: np.ndarray, weighted: bool = True):
    """Pressure mass matrix weighted by ``1 / mu`` (CSR over the free pressure DOFs);
    ``weighted=False``: ``M_p / mu_max`` (the unweighted mass with one scale)."""
    import ngsolve as ngs
    import scipy.sparse as sp

    mesh = form.mesh
    mats = form.problem.materials
    if weighted:
        inv_mu = mesh.MaterialCF({r: 1.0 / m.shear_modulus for r, m in mats.items()}, default=0)
    else:
        inv_mu = ngs.CF(1.0 / form.mu_max)
    _, *ps = form.fes.TrialFunction()
    _, *qs = form.fes.TestFunction()
    m = ngs.BilinearForm(form.fes, symmetric=False)
    m += sum((p * q for p, q in zip(ps[1:], qs[1:], strict=True)), ps[0] * qs[0]) * inv_mu * ngs.dx
    m.Assemble()
    M = sp.csr_matrix(m.mat.CSR())
    rng = form.fes.Range(0)
    free_p = free[(free < rng.start) | (free >= rng.stop)]
    return M[free_p][:, free_p].tocsr()


def mass_schur_solver(mass):
    """A :class:`BlockKrylovSolver` whose Schur approximation is ``mass + C``."""
    from brainbulge.solver.linear.krylov import BlockKrylovSolver

    class MassSchur(BlockKrylovSolver):
        def schur_matrix(self, a_diag, Bt, C):
            n_p = len(self.ip)
            self.stats.schur_builds += 1
            return (mass + C[:n_p][:, :n_p]).tocsr()

    return MassSchur


# --- building the systems (main process) ---------------------------------------------
def brain_system(tets: int, cache: Path, load: float, out: Path) -> dict:
    """Assemble and save the two systems; returns mesh/DOF facts and timings."""
    import scipy.sparse as sp

    from brainbulge.geometry.brain import build_brain_mesh, load_brain_mesh, save_brain_mesh
    from brainbulge.model.brain import CraniectomyCase, brain_problem
    from brainbulge.model.problem import Problem
    from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions
    from brainbulge.solver.linear.krylov import BlockKrylovSolver
    from brainbulge.solver.linear.layout import displacement_layout
    from brainbulge.solver.options import KrylovOptions

    info: dict = {}
    path = cache / f"brain_{tets}" / "brain.npz"
    t0 = time.perf_counter()
    if path.exists():
        bm = load_brain_mesh(path)
    else:
        bm = build_brain_mesh(target_tets=tets)
        save_brain_mesh(bm, path.parent, flap="left", figures=False)
    info["mesh_s"] = time.perf_counter() - t0
    full = brain_problem(bm, CraniectomyCase(flap="left", swell="both", swelling=1.1))
    problem = Problem(full.mesh, full.materials, full.swelling, clamped="base|skull")
    form = MixedForm(problem, element="mini", compile_energy=True)
    ns = NewtonSolver(form, SolverOptions(tolerance=1e-8))
    ns.linear = BlockKrylovSolver.from_form(form, KrylovOptions(max_iterations=2000), rtol=1e-6)
    x = form.gfu.vec
    t0 = time.perf_counter()
    steps = max(1, round(load / 0.25))
    for k in range(1, steps + 1):
        form.set_load(load * k / steps)
        ok = ns.newton().converged
        if not ok:
            raise RuntimeError(f"Newton failed at load {load * k / steps}")
    info["state_s"] = time.perf_counter() - t0
    info["tets"] = form.mesh.ne
    form.set_load(min(load + 0.25, 1.0))

    def system():
        """The tangent at ``x`` and the bubble-condensed residual (as Newton forms them)."""
        ns.equations.residual(x)
        K = ns.equations.tangent(x)
        rhs = x.CreateVector()
        rhs.data = ns.equations.res
        r = rhs.FV().NumPy()
        if ns.equations.closed is not None:  # the closed-form MINI tangent condenses by itself
            r[:] += ns.equations.closed.extend_trans(r)
        else:
            rhs.data += form.a.harmonic_extension_trans * rhs
        return K, rhs

    t0 = time.perf_counter()
    K1, rhs1 = system()
    info["assembly_s"] = time.perf_counter() - t0
    dx = ns.equations.newton_direction(x)  # one Newton step: the next tangent
    if isinstance(dx, tuple):  # (dx, contact multiplier steps)
        dx = dx[0]
    x.data -= dx
    K2, rhs2 = system()
    free = ns.equations.free
    lay = displacement_layout(form, free)
    mass_w = pressure_schur_mass(form, free)
    mass_u = pressure_schur_mass(form, free, weighted=False)
    arrays = {"is_u": ns.equations.is_u_free, "coords": lay.coords, "vertex": lay.vertex,
              "component": lay.component}
    for name, K, rhs in (("1", K1, rhs1), ("2", K2, rhs2)):
        arrays[f"rhs{name}"] = rhs.FV().NumPy()[free]
        sp.save_npz(out / f"K{name}.npz", K)
    np.savez(out / "system.npz", **arrays)
    sp.save_npz(out / "mass_weighted.npz", mass_w)
    sp.save_npz(out / "mass_unweighted.npz", mass_u)
    info["dofs"] = int(K1.shape[0])
    info["dofs_u"] = int(ns.equations.is_u_free.sum())
    info["nnz"] = int(K1.nnz)
    return info


# --- one solver in a fresh process ----------------------------------------------------


def _reset_peak() -> float:
    """Reset the peak-RSS counter (Linux: ``clear_refs`` 5) and return the current RSS."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass
    return status_mb("VmRSS")


def worker(folder: Path, variant: str, rtol: float) -> dict:
    import scipy.sparse as sp

    from brainbulge.solver.linear.direct import PardisoSolver
    from brainbulge.solver.linear.krylov import BlockKrylovSolver
    from brainbulge.solver.linear.layout import DisplacementLayout
    from brainbulge.solver.options import KrylovOptions

    d = np.load(folder / "system.npz")
    systems = [(sp.load_npz(folder / f"K{n}.npz").tocsr(), d[f"rhs{n}"]) for n in "12"]
    base = _reset_peak()
    row: dict = {"variant": variant, "rtol": rtol}
    if variant == "pardiso":
        solver = PardisoSolver()
        t0 = time.perf_counter()
        x = solver.solve(*systems[0])
        row.update(setup_s=0.0, solve_s=time.perf_counter() - t0, its=0)
        t0 = time.perf_counter()
        solver.solve(*systems[1])
        row.update(reuse_s=time.perf_counter() - t0, reuse_its=0)
        np.save(folder / "x_pardiso.npy", x)
    else:
        mass = VARIANTS[variant]
        cls = (BlockKrylovSolver if mass is None
               else mass_schur_solver(sp.load_npz(folder / f"mass_{mass}.npz")))
        lay = DisplacementLayout(d["coords"], d["vertex"], d["component"])
        solver = cls(d["is_u"], lay, KrylovOptions(max_iterations=3000), rtol=rtol)
        K, r = systems[0]
        t0 = time.perf_counter()
        solver.setup(K)
        row["setup_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        x = solver.solve(K, r)
        row.update(solve_s=time.perf_counter() - t0, its=solver.stats.iterations[-1])
        t0 = time.perf_counter()
        solver.solve(*systems[1])
        row.update(reuse_s=time.perf_counter() - t0, reuse_its=solver.stats.iterations[-1],
                   setups=solver.stats.setups)
    K, r = systems[0]
    row["res"] = float(np.linalg.norm(r - K @ x) / np.linalg.norm(r))
    ref_path = folder / "x_pardiso.npy"
    if ref_path.exists():
        xd = np.load(ref_path)
        row["err"] = float(np.linalg.norm(x - xd) / np.linalg.norm(xd))
    row["peak_mb"] = peak_mb()
    row["extra_mb"] = status_mb("VmHWM") - base
    return row


def run_worker(folder: Path, variant: str, rtol: float) -> dict:
    cmd = [sys.executable, __file__, "--worker", str(folder), variant, str(rtol)]
    out = subprocess.run(cmd, capture_output=True, text=True, env=os.environ.copy())
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
    if out.returncode != 0 or not lines:
        tail = (out.stderr.strip().splitlines() or ["?"])[-1]
        return {"variant": variant, "rtol": rtol, "failed": tail}
    return json.loads(lines[-1])


COLS = ("variant", "rtol", "setup_s", "solve_s", "its", "res", "err", "reuse_s", "reuse_its",
        "peak_mb", "extra_mb")


def fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.3g}" if abs(v) >= 1e-3 or v == 0 else f"{v:.1e}"
    return str(v)


def main() -> None:
    configure_runtime()
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tets", type=int, nargs="+", default=[30_000, 100_000],
                    help="target tetrahedra of the brain meshes")
    ap.add_argument("--cache", type=Path, default=Path.home() / ".cache/brainbulge/bench",
                    help="where brain meshes are kept between runs")
    ap.add_argument("--load", type=float, default=0.5, help="load factor of the state")
    ap.add_argument("--rtol", type=float, default=1e-8)
    ap.add_argument("--rtols", type=float, nargs="*", default=[],
                    help="extra tolerances for the first Krylov variant (inexact Newton)")
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS),
                    choices=list(VARIANTS))
    ap.add_argument("--no-pardiso", action="store_true")
    ap.add_argument("--worker", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        folder, variant, rtol = args.worker
        print(json.dumps(worker(Path(folder), variant, float(rtol))), flush=True)
        return
    args.cache.mkdir(parents=True, exist_ok=True)
    print(f"cores: {os.cpu_count()} (timings are noisy on a shared machine)")
    for tets in args.tets:
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp)
            info = brain_system(tets, args.cache, args.load, folder)
            print(f"\nbrain, target {tets} tets: {info['tets']} tets, {info['dofs']} free DOFs "
                  f"({info['dofs_u']} displacement), nnz {info['nnz']}, assembly "
                  f"{info['assembly_s']:.1f} s, state (Newton to load {args.load}) "
                  f"{info['state_s']:.0f} s", flush=True)
            print(" | ".join(COLS), flush=True)
            jobs = [] if args.no_pardiso else [("pardiso", args.rtol)]
            jobs += [(v, args.rtol) for v in args.variants]
            jobs += [(args.variants[0], t) for t in args.rtols]
            for variant, rtol in jobs:
                row = run_worker(folder, variant, rtol)
                if "failed" in row:
                    print(f"{variant} | {rtol:g} | failed: {row['failed']}", flush=True)
                    continue
                print(" | ".join(fmt(row.get(c, "")) for c in COLS), flush=True)


if __name__ == "__main__":
    main()
