"""Process-wide tuning of a brainbulge run, applied on request and never at import.

``configure()`` is what the ``brainbulge`` command calls first, what a study worker calls
before its scenario and what the benchmarks call; a Python user calls it before importing
NGSolve (which loads MKL) to get the command line's speed. Each setting leaves a value the
user chose alone, and every one of them changes how fast the process runs, not what it
computes:

- ``KMP_BLOCKTIME=0``: Intel OpenMP's threads (MKL PARDISO) otherwise spin 200 ms after each
  parallel region and take the cores from NGSolve's assembly threads (the 2D headline
  2.8 s -> 1.6 s on 2 cores). Read when OpenMP starts.
- ``MKL_CBWR=AUTO``: MKL's conditional numerical reproducibility; without it PARDISO on two
  threads gave solutions differing by ~1e-12 from one run to the next, so a rerun from
  ``run.toml`` was not bit for bit. Read when MKL loads.
- glibc keeps large freed arrays on the heap (:mod:`brainbulge.heap`;
  ``BRAINBULGE_KEEP_HEAP=0`` switches it off): the 1.54M-tet solve 1,145 -> 853 s.
- NGSolve's compiler calls go through ``ccache``
  (:func:`brainbulge.solver.compile_cache.use_compiler_cache`, which puts a ``c++`` link
  first on ``PATH``; ``BRAINBULGE_NO_CCACHE=1`` switches it off).

Calling it again changes nothing.
"""

from __future__ import annotations

import os
import signal

#: signals that stop a run as Ctrl-C does (status written, children ended, exit 130): a batch
#: system's time limit (SIGTERM; SLURM's ``--signal`` sends SIGUSR1 or SIGUSR2 before it, SGE's
#: soft limit SIGXCPU or SIGUSR1), a closed terminal or SSH connection (SIGHUP)
STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP, signal.SIGUSR1, signal.SIGUSR2, signal.SIGXCPU)
#: environment defaults for the thread and math libraries (a value set by the user wins)
ENVIRONMENT = {"KMP_BLOCKTIME": "0", "MKL_CBWR": "AUTO"}

#: ``BRAINBULGE_KEEP_HEAP=0`` leaves glibc's heap thresholds at their defaults
KEEP_HEAP = "BRAINBULGE_KEEP_HEAP"


def configure() -> dict[str, bool]:
    """Apply the process-wide tuning; returns what was switched on (``environment``,
    ``keep_heap``, ``compiler_cache``)."""
    from brainbulge.heap import keep_large_arrays_mapped
    from brainbulge.solver.compile_cache import use_compiler_cache

    for key, value in ENVIRONMENT.items():
        os.environ.setdefault(key, value)
    keep_heap = os.environ.get(KEEP_HEAP, "1") != "0" and keep_large_arrays_mapped()
    return {"environment": True, "keep_heap": keep_heap, "compiler_cache": use_compiler_cache()}
