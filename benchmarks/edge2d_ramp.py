"""A load ramp for the resolved-edge prototype (:mod:`bench_edge_2d`): increments sized by how
far the tissue slides near the skull's edge, a predictor, every Newton iteration counted.

:func:`ramp` raises the load factor from 0 to 1 with Newton (``newton(tol)``, the product's
Newton solve at the current load) at each load. After an accepted step the next increment
is ``dt * clip(target / slide, 1/2, grow)``, with ``slide`` the largest displacement
increment of the boundary vertices within ``band`` degrees of the edge and
``target`` a fraction of the edge's mesh size; a failed step is halved. The predictor
extrapolates the last increment (``secant``) or starts from the last state (``none``).
Below full load Newton stops at ``inter_tol``, at full load at ``final_tol``. The iteration
count is that of every Newton solve, failed attempts included.
"""

from __future__ import annotations

import sys
import time

import numpy as np


def ramp(newton, form, *, boundary_dofs: np.ndarray, dt0: float, target: float,
         predictor: str = "secant", inter_tol: float = 1e-6, final_tol: float = 1e-9,
         grow: float = 2.0, dt_max: float = 1.0, dt_min: float = 1e-3, budget: int = 10**9,
         after_step=None, finish=None, verbose: bool = False) -> dict:
    """Ramp ``form``'s load to 1 with ``newton(tol) -> (converged, iterations, |R|)``, one
    Newton solve at the form's load from its state; ``boundary_dofs``
    (k, 2): the displacement DOFs of the vertices whose slide sizes the increments;
    ``after_step(x, t)``: called after each accepted step below full load (e.g. a multiplier
    update; returns the number of extra Newton iterations it spent); ``finish(x)``: called
    at full load, returns its Newton iterations and whether it converged. Returns the load
    reached, all Newton iterations, accepted / rejected steps and the per-step record."""
    x = form.gfu.vec
    x_prev = x.CreateVector()
    x_prev.data = x
    inc = None
    t, dt, last_dt = 0.0, dt0, 0.0
    steps: list[tuple] = []
    rejected = 0
    total = 0
    start = time.perf_counter()
    while t < 1 - 1e-12 and total < budget:
        dt = min(dt, 1 - t, dt_max)
        final = t + dt >= 1 - 1e-12
        form.set_load(t + dt)
        if inc is not None and predictor == "secant":
            x.data = x_prev + (dt / last_dt) * inc
        ok, its, norm = newton(final_tol if final else inter_tol)
        total += its
        if not ok:
            rejected += 1
            x.data = x_prev
            if verbose:
                print(f"  load {t + dt:.4f} dt {dt:.4f}: failed after {its} ({norm:.1e})",
                      file=sys.stderr)
            dt *= 0.5
            if dt < dt_min:
                break
            continue
        d = x.FV().NumPy() - x_prev.FV().NumPy()
        slide = float(np.max(np.linalg.norm(d[boundary_dofs], axis=1)))
        inc = x.CreateVector()
        inc.data = x - x_prev
        x_prev.data = x
        t += dt
        last_dt = dt
        extra = after_step(x, t) if after_step is not None and t < 1 - 1e-12 else 0
        total += extra
        x_prev.data = x
        steps.append((t, dt, its, extra, slide))
        if verbose:
            print(f"  load {t:.4f} dt {dt:.4f}: {its} its (+{extra}), slide {slide:.2e}",
                  file=sys.stderr)
        dt = dt * float(np.clip(target / max(slide, 1e-300), 0.5, grow))
    x.data = x_prev
    form.load.Set(t)
    ok = t >= 1 - 1e-12
    if ok and finish is not None:
        extra, ok = finish(x)
        total += extra
        if verbose:
            print(f"  finish: {extra} its, converged {ok}", file=sys.stderr)
    return {"load": t, "newton_all": total, "accepted": len(steps), "rejected": rejected,
            "converged": ok, "steps": steps,
            "wall_ramp_s": time.perf_counter() - start}
