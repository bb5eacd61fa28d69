"""Large freed arrays stay in the process (brainbulge.heap): glibc's mmap/trim thresholds."""

from __future__ import annotations

import ctypes
import subprocess
import sys

import numpy as np
import pytest

from brainbulge import heap

glibc = pytest.mark.skipif(
    not sys.platform.startswith("linux") or not hasattr(ctypes.CDLL(None), "mallinfo2"),
    reason="glibc's mallopt/mallinfo2 only",
)


class _Mallinfo2(ctypes.Structure):
    _fields_ = [
        (name, ctypes.c_size_t)
        for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks",
                     "uordblks", "fordblks", "keepcost")
    ]


def _mallinfo() -> _Mallinfo2:
    f = ctypes.CDLL(None).mallinfo2
    f.restype = _Mallinfo2
    return f()


@glibc
def test_large_array_comes_from_the_heap_and_stays_mapped(monkeypatch) -> None:
    """A 200 MB array is not mmapped on its own (``hblkhd`` unchanged), and after it is
    freed the heap keeps the memory (``arena`` does not shrink back), so the next array of
    that size reuses touched pages."""
    monkeypatch.delenv(heap.OPT_OUT, raising=False)
    assert heap.keep_large_arrays_mapped()  # idempotent: brainbulge's import did it already
    n = 25_000_000  # 200 MB of float64
    before = _mallinfo()
    a = np.ones(n)
    during = _mallinfo()
    assert during.hblkhd - before.hblkhd < a.nbytes // 2, "the array was mmapped on its own"
    assert during.uordblks - before.uordblks >= a.nbytes  # in use, on the heap
    del a
    after = _mallinfo()
    assert after.arena >= during.arena, "the freed heap was returned to the system"
    assert after.fordblks - during.fordblks >= n * 8 - (1 << 20)  # kept as free heap


@glibc
def test_default_glibc_mmaps_large_arrays_and_opt_out() -> None:
    """The contrast: with ``BRAINBULGE_KEEP_HEAP=0`` a fresh process mmaps the same array
    (glibc's default), and the function reports that it did nothing."""
    code = (
        "import ctypes, numpy as np, brainbulge\n"
        "from brainbulge import heap\n"
        "class M(ctypes.Structure):\n"
        "    _fields_ = [(f'f{i}', ctypes.c_size_t) for i in range(10)]\n"
        "f = ctypes.CDLL(None).mallinfo2; f.restype = M\n"
        "b = f().f4; a = np.ones(25_000_000); print(f().f4 - b, heap.keep_large_arrays_mapped())\n"
    )
    env = {"BRAINBULGE_KEEP_HEAP": "0", "PATH": ""}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True).stdout.split()
    assert int(out[0]) >= 200_000_000 and out[1] == "False"


def _rss_mb() -> float:
    with open("/proc/self/status") as fh:
        return next(int(ln.split()[1]) for ln in fh if ln.startswith("VmRSS")) / 1024


@glibc
def test_release_gives_the_kept_memory_back(monkeypatch) -> None:
    """Freed heap stays resident until :func:`heap.release_free_memory`, which returns it."""
    monkeypatch.delenv(heap.OPT_OUT, raising=False)
    heap.keep_large_arrays_mapped()
    a = np.ones(25_000_000)  # 200 MB, touched
    with_array = _rss_mb()
    del a
    kept = _rss_mb()
    assert kept > with_array - 50  # still resident
    assert heap.release_free_memory()
    assert _rss_mb() < kept - 150
