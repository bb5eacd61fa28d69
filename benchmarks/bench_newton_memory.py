"""Peak memory of the Newton phase, phase by phase, on a saved brain mesh.

Builds the default 3D scenario (left flap, both-sided swelling, the case's defaults with the
Krylov solver) on ``--mesh`` (a ``brain.npz`` of ``brainbulge mesh``), sets the load of the
first load step and runs ``--iterations`` Newton iterations of the production code, each
phase's peak resident memory measured on its own: the kernel's high-water mark (``VmHWM``)
is reset (``/proc/self/clear_refs`` 5) when a phase starts and read when it ends.

    python benchmarks/bench_newton_memory.py --mesh /path/to/brain.npz [--iterations 2]

Phases: the problem (mesh, skull, forms), the closed-form tangent's set-up (the Newton
solver), then per Newton iteration the tangent (assembly and the free part), the linear
system (contact elimination, the Krylov blocks), the AMG set-up (hierarchies of the
displacement block and of the Schur approximation; the first iteration only), GMRES, and
the rest (residuals of the line search). Columns: peak MB in the phase, RSS MB at its end.
The last lines give what must not change with a memory lever: Newton's scaled residuals
and the GMRES iterations per solve.
"""

from __future__ import annotations

import argparse
import functools
import time
from pathlib import Path

from brainbulge.runtime import configure as configure_runtime


def _status_mb(key: str) -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return float(line.split()[1]) / 1024
    return float("nan")


class PhasePeaks:
    """Peak and end RSS of consecutive phases (Linux ``VmHWM``, reset at each mark)."""

    def __init__(self) -> None:
        self.rows: list[tuple[str, float, float, float]] = []
        self.label = "start"
        self.t0 = time.perf_counter()
        self._reset()

    @staticmethod
    def _reset() -> None:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")

    def mark(self, next_label: str) -> None:
        """End the current phase (its peak and end RSS), start ``next_label``."""
        t = time.perf_counter()
        self.rows.append((self.label, _status_mb("VmHWM"), _status_mb("VmRSS"), t - self.t0))
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
        lines = ["| phase | peak MB | end MB | s |", "|---|---|---|---|"]
        lines += [f"| {label} | {peak:,.0f} | {end:,.0f} | {dt:.1f} |"
                  for label, peak, end, dt in self.rows]
        top = max(self.rows[1:], key=lambda r: r[1])
        lines.append(f"\nhighest peak: {top[1]:,.0f} MB ({top[0]})")
        return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", type=Path, required=True, help="brain.npz of brainbulge mesh")
    ap.add_argument("--iterations", type=int, default=2, help="Newton iterations (default 2)")
    args = ap.parse_args()
    configure_runtime()
    peaks = PhasePeaks()
    peaks.mark("problem")

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
    peaks.wrap(ns, "tangent", "tangent", "linear system")
    peaks.wrap(ns.linear, "setup", "AMG set-up", "linear system")
    peaks.wrap(ns.linear, "_krylov", "GMRES", "residual, line search")
    form.set_load(1.0 / case.steps)
    ns.newton(form.gfu.vec, ns.opt.intermediate_tolerance)
    peaks.mark("end")
    print(f"{form.mesh.ne:,} tets, {len(ns.free):,} free DOFs\n")
    print(peaks.table())
    print("Newton |R|:", " ".join(f"{r:.6e}" for r in ns.history[-1]))
    print("GMRES iterations:", ns.linear.stats.iterations)


if __name__ == "__main__":
    main()
