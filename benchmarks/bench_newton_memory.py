"""Peak memory of the Newton phase, phase by phase, on a saved brain mesh.

Builds the default 3D scenario (left flap, both-sided swelling, the case's defaults with the
Krylov solver) on ``--mesh`` (a ``brain.npz`` of ``brainbulge mesh``), sets the load of the
first load step and runs ``--iterations`` Newton iterations of the production code, each
phase's peak resident memory measured on its own: the kernel's high-water mark (``VmHWM``)
is reset (``/proc/self/clear_refs`` 5) when a phase starts and read when it ends.

    python benchmarks/bench_newton_memory.py --mesh /path/to/brain.npz [--iterations 2]

Phases: the problem (mesh, skull, forms), the closed-form tangent's set-up (the Newton
solver), then per Newton iteration the tangent (assembled on the free DOFs), the linear
system (contact elimination, the Krylov blocks), the AMG set-up (hierarchies of the
displacement block and of the Schur approximation; the first iteration only), GMRES, and
the rest (residuals of the line search). Columns: peak MB in the phase, RSS MB at its end.
The last lines give what must not change with a memory lever: Newton's scaled residuals
and the GMRES iterations per solve.

With ``--trace`` the table adds what Python's ``tracemalloc`` sees (NumPy's arrays among it,
not NGSolve's or Numba's own memory): the live memory at the phase's peak and at its end.
Freed arrays stay on the process's heap (``brainbulge.heap``), so the RSS follows the
highest live memory so far; the traced columns show what each phase holds.
"""

from __future__ import annotations

import argparse
import functools
import time
import tracemalloc
from pathlib import Path

from brainbulge.runtime import configure as configure_runtime
from memory import status_mb


class PhasePeaks:
    """Peak and end RSS of consecutive phases (Linux ``VmHWM``, reset at each mark)."""

    def __init__(self) -> None:
        self.rows: list[tuple[str, float, float, float, float, float]] = []
        self.label = "start"
        self.t0 = time.perf_counter()
        self._reset()

    @staticmethod
    def _reset() -> None:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        tracemalloc.reset_peak()

    @classmethod
    def start(cls, ap: argparse.ArgumentParser, first: str) -> tuple[argparse.Namespace,
                                                                    PhasePeaks]:
        """Parse ``ap``'s arguments (with ``--trace``), set up the runtime as the command line
        does, start tracing when asked and the first phase ``first``."""
        ap.add_argument("--trace", action="store_true",
                        help="also the live memory that tracemalloc sees (slower)")
        args = ap.parse_args()
        configure_runtime()
        if args.trace:
            tracemalloc.start()
        peaks = cls()
        peaks.mark(first)
        return args, peaks

    def mark(self, next_label: str) -> None:
        """End the current phase (its peak and end RSS), start ``next_label``."""
        t = time.perf_counter()
        live, live_peak = (v / 2**20 for v in tracemalloc.get_traced_memory())
        self.rows.append((self.label, status_mb("VmHWM"), status_mb("VmRSS"), t - self.t0,
                          live_peak, live))
        self.label, self.t0 = next_label, t
        self._reset()

    def wrap(self, obj, name: str, label: str, after: str) -> None:
        """Make ``obj.name`` a phase ``label``, followed by the phase ``after``."""
        method = getattr(obj, name)

        @functools.wraps(method)
        def phase(*args, **kwargs):
            self.mark(label)
            try:
                return method(*args, **kwargs)
            finally:
                self.mark(after)

        setattr(obj, name, phase)

    def table(self) -> str:
        traced = tracemalloc.is_tracing()
        lines = ["| phase | peak MB | end MB | s |" + (" traced peak MB | traced end MB |"
                                                       if traced else ""),
                 "|---|---|---|---|" + ("---|---|" if traced else "")]
        for label, peak, end, dt, live_peak, live in self.rows:
            lines.append(f"| {label} | {peak:,.0f} | {end:,.0f} | {dt:.1f} |"
                         + (f" {live_peak:,.0f} | {live:,.0f} |" if traced else ""))
        top = max(self.rows[1:], key=lambda r: r[1])
        lines.append(f"\nhighest peak: {top[1]:,.0f} MB ({top[0]})")
        return "\n".join(lines)


def held_mb(root, seen: set[int] | None = None) -> float:
    """MB of the NumPy arrays reachable from ``root`` (attributes, containers, sparse
    matrices), each buffer counted once across calls sharing ``seen``."""
    import numpy as np

    seen = set() if seen is None else seen
    total = 0
    stack = [root]
    while stack:
        obj = stack.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, np.ndarray):
            base = obj
            while isinstance(base.base, np.ndarray):
                base = base.base
            if id(base) not in seen or base is obj:
                seen.add(id(base))
                total += base.nbytes
            continue
        if isinstance(obj, dict):
            stack.extend(obj.values())
        elif isinstance(obj, (list, tuple, set)):
            stack.extend(obj)
        elif hasattr(obj, "__dict__") and type(obj).__module__.split(".")[0] in (
                "brainbulge", "scipy", "pyamg", "__main__"):
            stack.extend(v for k, v in vars(obj).items() if k != "form")
    return total / 2**20


def held_table(eq) -> str:
    """What the Newton equations' parts hold after the last iteration (MB, shared arrays
    counted at their first owner)."""
    seen: set[int] = set()
    lin = eq.linear
    parts = [("closed-form tangent (pattern, bubble operators)", eq.closed),
             ("free-part plan (NGSolve's tangent only)", eq._free_part),
             ("contact elimination plan", eq._project_elimination),
             ("Krylov block plans", lin._block_plans),
             ("displacement AMG (plan, hierarchy)", lin.amg_u),
             ("Schur AMG", lin.amg_p)]
    lines = ["| part | MB |", "|---|---|"]
    lines += [f"| {name} | {held_mb(obj, seen):,.0f} |" for name, obj in parts]
    ml = getattr(lin.amg_u, "ml", None)
    for i, lvl in enumerate(ml.levels if ml is not None else []):
        lines.append(f"| displacement AMG level {i}: " + ", ".join(
            f"{name} {held_mb(getattr(lvl, name), set()):,.0f}" for name in ("A", "P", "R")
            if hasattr(lvl, name)) + " |  |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", type=Path, required=True, help="brain.npz of brainbulge mesh")
    ap.add_argument("--iterations", type=int, default=2, help="Newton iterations (default 2)")
    args, peaks = PhasePeaks.start(ap, "problem")

    from brainbulge.model.brain import brain_mesh_for, brain_problem, case_skull
    from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions
    from brainbulge.studies.craniectomy import case_from_dict

    case = case_from_dict({"mesh": str(args.mesh), "flap": "left", "swell": "both",
                           "linear_solver": "krylov"})
    bm = brain_mesh_for(case)
    problem = brain_problem(bm, case, case_skull(bm, case))
    form = MixedForm(problem, element=case.element, compile_energy=case.compile)
    peaks.mark("closed-form set-up")
    ns = NewtonSolver(form, SolverOptions(steps=case.steps, tolerance=case.tolerance,
                                          linear_solver="krylov",
                                          max_iterations=args.iterations))
    peaks.mark("residual, line search")
    eq = ns.equations
    peaks.wrap(eq, "tangent", "tangent", "linear system")
    peaks.wrap(eq.linear, "setup", "AMG set-up", "linear system")
    peaks.wrap(eq.linear, "_krylov", "GMRES", "residual, line search")
    form.set_load(1.0 / case.steps)
    result = ns.newton(ns.opt.ramp.intermediate_tolerance)
    peaks.mark("end")
    print(f"{form.mesh.ne:,} tets, {len(eq.free):,} free DOFs\n")
    print(peaks.table())
    print(held_table(eq))
    print("Newton |R|:", " ".join(f"{r:.6e}" for r in result.residuals))
    print("GMRES iterations:", eq.linear.stats.iterations)


if __name__ == "__main__":
    main()
