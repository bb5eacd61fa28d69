"""Large freed arrays kept in the process (brainbulge.heap): glibc's mmap/trim thresholds.

Each check runs in a fresh interpreter: the setting is made when brainbulge is imported.
"""

from __future__ import annotations

import ctypes
import json
import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux") or not hasattr(ctypes.CDLL(None), "mallinfo2"),
    reason="glibc's mallopt/mallinfo2 only",
)

PROBE = r"""
import ctypes, json, numpy as np
import brainbulge
from brainbulge import heap

class M(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks",
                "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")]

info = ctypes.CDLL(None).mallinfo2
info.restype = M

def rss_mb():
    with open("/proc/self/status") as fh:
        return next(int(ln.split()[1]) for ln in fh if ln.startswith("VmRSS")) / 1024

before = info()
a = np.ones(25_000_000)  # 200 MB, touched
during, rss_with = info(), rss_mb()
del a
after, rss_kept = info(), rss_mb()
released = heap.release_free_memory()
print(json.dumps({
    "mmapped": during.hblkhd - before.hblkhd, "heap_in_use": during.uordblks - before.uordblks,
    "arena_shrank": after.arena < during.arena,
    "freed_kept": after.fordblks - during.fordblks,
    "rss_with": rss_with, "rss_kept": rss_kept, "rss_released": rss_mb(),
    "released": released}))
"""


def probe(**env: str) -> dict:
    environ = {k: v for k, v in os.environ.items() if not k.startswith(("MALLOC_", "BRAINBULGE"))}
    out = subprocess.run([sys.executable, "-c", PROBE], env={**environ, **env},
                         capture_output=True, text=True, check=True).stdout
    return json.loads(out.splitlines()[-1])


def test_glibc_default_maps_large_arrays_on_their_own() -> None:
    """Switched off (``BRAINBULGE_KEEP_HEAP=0``), a 200 MB array is mmapped on its own and
    unmapped when freed (glibc's default)."""
    r = probe(BRAINBULGE_KEEP_HEAP="0")
    assert r["mmapped"] >= 200_000_000
    assert r["rss_kept"] < r["rss_with"] - 150


def test_kept_heap_reuses_freed_arrays_until_released() -> None:
    """By default (brainbulge imported): the array comes from the heap (not mmapped), stays
    resident as free heap when freed, and :func:`heap.release_free_memory` returns it."""
    r = probe()
    assert r["mmapped"] < 100_000_000 and r["heap_in_use"] >= 200_000_000
    assert not r["arena_shrank"] and r["freed_kept"] >= 200_000_000 - (1 << 20)
    assert r["rss_kept"] > r["rss_with"] - 50
    assert r["released"] and r["rss_released"] < r["rss_kept"] - 150


def test_glibc_environment_of_the_user_wins() -> None:
    """A user's own ``MALLOC_MMAP_THRESHOLD_`` is left alone (brainbulge sets nothing)."""
    r = probe(MALLOC_MMAP_THRESHOLD_="65536")
    assert r["mmapped"] >= 200_000_000
