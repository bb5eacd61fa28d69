"""Solver benchmark: the 3D swelling inclusion (docs/model.md section 8) at three mesh sizes.

Prints elements, DOFs, assembly s/iteration, linear solve s/iteration, Newton iterations,
peak memory and the radial-map error. Rerun with ``python benchmarks/bench_solver.py``
(``--sizes 0.3 0.2 0.15`` to choose mesh sizes, ``--element mini`` for P1-bubble/P1).
"""

from __future__ import annotations

import argparse
import time

import ngsolve as ngs
import numpy as np

from brainbulge.geometry.inclusion import inclusion_mesh
from brainbulge.materials import MooneyRivlin
from brainbulge.model import Problem
from brainbulge.runtime import configure as configure_runtime
from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions
from memory import peak_mb

A, JS = 0.2, 1.3


def run(h: float, element: str) -> dict:
    mesh = inclusion_mesh(3, A=A, h=h, h_inclusion=h / 2)
    gray = MooneyRivlin(0.28, 333.0)
    problem = Problem(
        mesh,
        {"inclusion": gray, "matrix": gray},
        {"inclusion": JS},
        clamped_components={0: "sym_x", 1: "sym_y", 2: "sym_z"},
    )
    t0 = time.perf_counter()
    form = MixedForm(problem, element=element)
    solver = NewtonSolver(form, SolverOptions(steps=2))
    sol = solver.solve()
    wall = time.perf_counter() - t0
    its = max(sol.newton_iterations, 1)
    R = 0.6
    d = np.ones(3) / np.sqrt(3)
    u = np.asarray(form.u(mesh(*(R * d))))
    r = np.linalg.norm(R * d + u)
    exact = (R**3 + (JS - 1) * A**3) ** (1 / 3)
    # the whole field: an incompressible radial map is fixed by the volume it must add,
    # r^3 = R^3 + (Js - 1) A^3 outside the inclusion, r = Js^(1/3) R inside (docs/model.md s.8)
    X = ngs.CF((ngs.x, ngs.y, ngs.z))
    Rcf = ngs.sqrt(ngs.x**2 + ngs.y**2 + ngs.z**2) + 1e-14
    r_ex = ngs.IfPos(Rcf - A, (Rcf**3 + (JS - 1) * A**3) ** (1 / 3), JS ** (1 / 3) * Rcf)
    u_ex = (r_ex / Rcf - 1) * X
    err = ngs.Integrate(ngs.InnerProduct(form.u - u_ex, form.u - u_ex), mesh, order=6)
    ref = ngs.Integrate(ngs.InnerProduct(u_ex, u_ex), mesh, order=6)
    return {
        "h": h,
        "elements": mesh.ne,
        "dofs": form.fes.ndof,
        "newton": sol.newton_iterations,
        "assembly_s_per_it": solver.t_assembly / its,
        "solve_s_per_it": solver.t_solve / its,
        "wall_s": wall,
        "peak_mb": peak_mb(),
        "radius_error": abs(r - exact) / exact,
        "u_L2_error": float(np.sqrt(err / ref)),
        "converged": sol.converged,
    }


def main() -> None:
    configure_runtime()
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", type=float, nargs="+", default=[0.3, 0.2, 0.14])
    ap.add_argument("--element", default="taylor-hood", choices=("taylor-hood", "mini"))
    args = ap.parse_args()
    cols = (
        "h",
        "elements",
        "dofs",
        "newton",
        "assembly_s_per_it",
        "solve_s_per_it",
        "wall_s",
        "peak_mb",
        "radius_error",
        "u_L2_error",
        "converged",
    )
    print(f"3D inclusion benchmark, element {args.element}")
    print(" | ".join(cols))
    for h in args.sizes:
        row = run(h, args.element)
        print(
            " | ".join(f"{row[c]:.3g}" if isinstance(row[c], float) else str(row[c]) for c in cols),
            flush=True,
        )


if __name__ == "__main__":
    main()
