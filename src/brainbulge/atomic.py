"""Atomic output files: a result is either complete on disk or not there.

Written by hand: the standard library has the parts (``tempfile``, ``os.replace``), not the
whole. At the bottom of the package (no brainbulge imports) so that every layer, meshing
included, writes its files through it.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any


@contextmanager
def atomic_output(path: Path) -> Iterator[Path]:
    """A temporary path next to ``path`` to write to; renamed onto ``path`` when the block ends.

    The temporary name (``.NAME.XXXX.tmp.EXT``) keeps ``path``'s extension, so writers that
    choose the format by it (meshio, matplotlib, ``np.savez``) work unchanged. On success the
    file gets the permissions the user's umask allows (not ``mkstemp``'s 0600), is synced to
    disk and replaces ``path`` in one step; on any error (a full disk mid-write) it is deleted
    and ``path`` is left as it was: readers never see a truncated or empty result.
    """
    path = Path(path)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.",
                                suffix=f".tmp{path.suffix}")
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp's 0600 would hide results from others
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (see `atomic_output`)."""
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def _umask() -> int:
    """The process's umask, read without changing it where the system allows."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)  # elsewhere: set and restore at once
    os.umask(mask)
    return mask


def atomic_write_json(path: Path, data: Any) -> Path:
    """Write ``data`` as indented JSON to ``path`` atomically (see `atomic_write_text`)."""
    return atomic_write_text(path, json.dumps(data, indent=2, allow_nan=True) + "\n")


