"""The benchmarks' memory readings of their own process (Linux), in MB."""

from __future__ import annotations

import resource


def peak_mb() -> float:
    """Peak resident memory of this process so far [MB] (``ru_maxrss``)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def status_mb(key: str) -> float:
    """A memory line of ``/proc/self/status`` [MB]: ``VmRSS`` (now), ``VmHWM`` (the peak
    since the last reset); NaN where the kernel does not give it."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return float(line.split()[1]) / 1024
    return float("nan")
