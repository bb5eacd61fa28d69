"""Thread pools of the numerical libraries under the solvers.

NGSolve assembles with its own task threads and MKL PARDISO factorises with OpenMP; the
vector work between them (norms, dot products, Gram-Schmidt) goes through NumPy's OpenBLAS,
whose pthreads spin-wait ~0.2 s after every call on vectors above ~10k entries. On two cores
those spinning threads then slow NGSolve's next assembly: a hemidisk residual took 40-50 ms
after a solve against 10-11 ms with OpenBLAS on one thread (13k DOFs, measured). Vector work
of this size gains nothing from threads, so Newton runs it on one next to the direct solver
(the Krylov path's long vectors keep their threads: the 111k-tet brain was 10 % slower on
one; its Gram-Schmidt is limited inside the Krylov loop).
"""

from __future__ import annotations

from contextlib import AbstractContextManager


def serial_openblas() -> AbstractContextManager:
    """Context in which OpenBLAS (NumPy's and NGSolve's) runs on one thread; MKL (PARDISO)
    and NGSolve's task manager keep theirs. (threadpoolctl is imported here, not at the
    package's import: importing it sets ``KMP_DUPLICATE_LIB_OK``.)"""
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController().select(internal_api="openblas").limit(limits=1)


def available_cores() -> int:
    """The cores this process may use (its CPU affinity)."""
    import os

    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)
