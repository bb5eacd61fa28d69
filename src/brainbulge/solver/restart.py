"""The restart file: the converged state after every accepted load step (as Abaqus' restart).

A ramp that finds a file of the same problem (``key`` and the number of DOFs) resumes from
its load instead of ``t = 0``: a long 3D run that is stopped loses at most one load step. The
file (``.npz``, written atomically) holds the state ``x``, the contact multipliers
``lam0, lam1, ...``, the load ``t``, the next step ``dt``, the last increment and its
``last_dt`` (the predictor's), and the accepted steps so far.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import TYPE_CHECKING

import ngsolve as ngs
import numpy as np

from brainbulge.atomic import note_written
from brainbulge.solver.options import Solution, StepRecord
from brainbulge.solver.state import State

if TYPE_CHECKING:
    from brainbulge.solver.mixed import MixedForm

log = logging.getLogger("brainbulge")

NEEDED = ("key", "ndof", "t", "dt", "last_dt", "x", "increment", "steps", "rejected")


def write(path: Path, key: str, form: MixedForm, x: ngs.BaseVector, t: float, dt: float,
          increment: ngs.BaseVector, last_dt: float, sol: Solution) -> None:
    """The converged state ``x`` at load ``t`` and what the next step needs."""
    steps = np.array([[s.load, s.newton_iterations, s.augmentations, s.residual,
                       s.max_penetration] for s in sol.steps])
    tmp = path.with_name(path.name + ".tmp.npz")
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(tmp, key=key, ndof=len(x), t=t, dt=dt, last_dt=last_dt,
             x=x.FV().NumPy(), increment=increment.FV().NumPy(),
             steps=steps, rejected=sol.rejected_steps,
             **{f"lam{i}": v for i, v in enumerate(State(form).multipliers)})
    os.replace(tmp, path)
    note_written(path)  # in the output folder's manifest


def read(path: Path, key: str, form: MixedForm, sol: Solution
         ) -> tuple[float, float, ngs.BaseVector, float] | None:
    """Restore the form's state (and ``sol``'s steps) from a restart file of this problem;
    returns ``(t, dt, increment, last_dt)``, or ``None`` if there is none."""
    if not path.is_file():
        return None
    x = form.gfu.vec
    n_lam = len(form.point_contacts)
    try:  # a truncated or foreign file (BadZipFile, EOFError, zlib.error, ...) is skipped
        with np.load(path, allow_pickle=False) as f:
            data = {k: f[k] for k in f.files}
        if any(k not in data for k in NEEDED):
            raise ValueError("arrays missing")
    except Exception as exc:  # noqa: BLE001
        log.warning("restart file %s unreadable (%s): starting from Js = 1", path,
                    " ".join(str(exc).split()) or type(exc).__name__)
        return None
    if (str(data["key"]) != key or int(data["ndof"]) != len(x)
            or any(f"lam{i}" not in data for i in range(n_lam))):
        log.info("restart file %s is of another problem: starting from Js = 1", path)
        return None
    t = float(data["t"])
    x.FV().NumPy()[:] = data["x"]
    increment = x.CreateVector()
    increment.FV().NumPy()[:] = data["increment"]
    State(form).set_multipliers([data[f"lam{i}"] for i in range(n_lam)])
    form.set_load(t)
    sol.steps = [StepRecord(float(a), int(b), int(c), float(d), float(e))
                 for a, b, c, d, e in data["steps"].reshape(-1, 5)]
    sol.rejected_steps = int(data["rejected"])
    log.info("resuming from %s at load %.4f", path, t)
    return t, float(data["dt"]), increment, float(data["last_dt"])
