"""Process-wide tuning (brainbulge.runtime): applied by ``configure()``, never at import."""

from __future__ import annotations

import ctypes
import json
import os
import subprocess
import sys

import pytest

IMPORT_CHANGES_NOTHING = (
    "import json, os; e = dict(os.environ); import brainbulge, brainbulge.solver, "
    "brainbulge.studies; print(json.dumps(sorted(set(os.environ.items()) ^ set(e.items()))))"
)

MMAPPED_AFTER_IMPORT = r"""
import ctypes, numpy as np
import brainbulge, brainbulge.solver, brainbulge.studies
info = ctypes.CDLL(None).mallinfo2
info.restype = type("M", (ctypes.Structure,), {"_fields_": [(n, ctypes.c_size_t) for n in (
    "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
    "fordblks", "keepcost")]})
before = info().hblkhd
a = np.ones(25_000_000)  # 200 MB
print(info().hblkhd - before)
"""

CONFIGURE = r"""
import json, os
from brainbulge.runtime import configure
first = configure()
path = os.environ["PATH"]
second = configure()
print(json.dumps({"first": first, "second": second, "path_kept": os.environ["PATH"] == path,
                  "env": {k: os.environ.get(k) for k in ("KMP_BLOCKTIME", "MKL_CBWR")}}))
"""


def _clean_env(**env: str) -> dict[str, str]:
    keep = {k: v for k, v in os.environ.items()
            if not k.startswith(("MALLOC_", "BRAINBULGE", "KMP_", "MKL_CBWR"))}
    return {**keep, **env}


def _configure(**env: str) -> dict:
    out = subprocess.run([sys.executable, "-c", CONFIGURE], env=_clean_env(**env),
                         capture_output=True, text=True, check=True).stdout
    return json.loads(out.splitlines()[-1])


def test_importing_the_package_leaves_the_environment_unchanged() -> None:
    """``import brainbulge`` (and its solver and study layers) sets no variable and leaves
    ``PATH`` alone, also where the tuning's variables are unset."""
    out = subprocess.run([sys.executable, "-c", IMPORT_CHANGES_NOTHING], env=_clean_env(),
                         capture_output=True, text=True, check=True).stdout
    assert json.loads(out.splitlines()[-1]) == []  # the variables added, removed or changed


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or not hasattr(ctypes.CDLL(None), "mallinfo2"),
    reason="glibc's mallinfo2 only",
)
def test_importing_the_package_leaves_the_allocator_alone() -> None:
    """After the import a large array is still mapped on its own (glibc's default), i.e. the
    heap thresholds were not changed."""
    out = subprocess.run([sys.executable, "-c", MMAPPED_AFTER_IMPORT], env=_clean_env(),
                         capture_output=True, text=True, check=True).stdout
    assert int(out.split()[-1]) >= 200_000_000


def test_configure_sets_defaults_and_keeps_the_users_values() -> None:
    r = _configure()
    assert r["env"] == {"KMP_BLOCKTIME": "0", "MKL_CBWR": "AUTO"}
    assert r["first"]["environment"]
    r = _configure(KMP_BLOCKTIME="200", MKL_CBWR="COMPATIBLE")
    assert r["env"] == {"KMP_BLOCKTIME": "200", "MKL_CBWR": "COMPATIBLE"}


def test_configure_twice_changes_nothing_more() -> None:
    r = _configure()
    assert r["path_kept"] and r["first"] == r["second"]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's heap only")
def test_the_heap_setting_can_be_switched_off_and_yields_to_glibcs_own() -> None:
    """``BRAINBULGE_KEEP_HEAP=0``, or glibc's own ``MALLOC_MMAP_THRESHOLD_`` set by the user,
    leave the allocator alone."""
    assert not _configure(BRAINBULGE_KEEP_HEAP="0")["first"]["keep_heap"]
    assert not _configure(MALLOC_MMAP_THRESHOLD_="65536")["first"]["keep_heap"]


def test_the_compiler_cache_can_be_switched_off() -> None:
    r = _configure(BRAINBULGE_NO_CCACHE="1")
    assert r["first"]["compiler_cache"] is False
