"""Keep large freed arrays in the process instead of returning them to the system.

glibc's ``malloc`` serves every block above its mmap threshold (dynamic, at most 32 MB) by
a fresh ``mmap`` and unmaps it on ``free``. A solver at 1.5M tets makes and drops arrays of
0.1-0.6 GB every Newton iteration (the tangent's values, gathered copies, Krylov bases), so
each of them page-faults its memory in again. On this virtual machine that costs: copying
a 69M-double array (0.55 GB) into a new array took 1.7-5.5 s, into a touched buffer 0.05 s
(measured; the host backs freed guest pages lazily). ``mallopt(M_MMAP_THRESHOLD, 1 GiB)``
puts blocks up to 1 GiB on the heap, ``mallopt(M_TRIM_THRESHOLD, 2 GiB)`` keeps up to 2 GiB
of freed heap mapped, so a new array of a size seen before reuses touched pages.

Applied by :func:`brainbulge.runtime.configure` (the command line, study workers and the
benchmarks call it; ``BRAINBULGE_KEEP_HEAP=0`` switches it off), never at import. At
1.54M tets, with GMRES keeping only its basis: solve 853 s against 1,145 s, peak 10,784
against 10,421 MiB (docs/performance.md). With GMRES's preconditioned basis still kept it
had raised the peak to 12,535 MiB.

No library exposes ``mallopt`` (NumPy allocates through ``malloc``), hence the few lines of
ctypes. The glibc environment variables ``MALLOC_MMAP_THRESHOLD_`` / ``MALLOC_TRIM_THRESHOLD_``
do the same but are read when the process starts, too late for a Python package.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

#: ``mallopt`` parameter numbers (glibc's malloc.h).
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3

#: Blocks up to this size come from the heap (bytes; glibc's dynamic threshold stops at
#: 32 MiB, a set one may be larger: glibc 2.36 accepts 1 GiB).
MMAP_THRESHOLD = 1 << 30
#: Freed memory at the top of the heap kept mapped up to this size (bytes; ``mallopt``
#: takes a C int).
TRIM_THRESHOLD = (1 << 31) - 1


def _libc():
    """glibc through ctypes, or None (another C library or system)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.mallopt, libc.malloc_trim  # noqa: B018 - glibc has both, musl neither
    except (OSError, AttributeError):
        return None
    return libc


def keep_large_arrays_mapped(
    mmap_threshold: int = MMAP_THRESHOLD, trim_threshold: int = TRIM_THRESHOLD
) -> bool:
    """Set glibc's mmap and trim thresholds (bytes) for this process.

    Returns whether they were set: not on other C libraries or systems, not when the user
    chose glibc's own ``MALLOC_MMAP_THRESHOLD_`` / ``MALLOC_TRIM_THRESHOLD_``.
    """
    if "MALLOC_MMAP_THRESHOLD_" in os.environ or "MALLOC_TRIM_THRESHOLD_" in os.environ:
        return False
    libc = _libc()
    if libc is None:
        return False
    mallopt = libc.mallopt
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    ok = mallopt(M_MMAP_THRESHOLD, int(mmap_threshold)) == 1
    return mallopt(M_TRIM_THRESHOLD, int(trim_threshold)) == 1 and ok


def release_free_memory() -> bool:
    """Give the heap's free pages back to the system (glibc ``malloc_trim(0)``, which also
    releases whole free pages inside the heap): where a phase's work arrays are done with,
    e.g. the solver's before the outputs, so that they do not add to the next phase's peak.
    Returns whether memory was released."""
    libc = _libc()
    if libc is None:
        return False
    libc.malloc_trim.argtypes = (ctypes.c_size_t,)
    libc.malloc_trim.restype = ctypes.c_int
    return libc.malloc_trim(0) == 1
