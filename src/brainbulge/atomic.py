"""Atomic output files: a result is either complete on disk or not there.

Written by hand: the standard library has the parts (``tempfile``, ``os.replace``), not the
whole. At the bottom of the package (no brainbulge imports) so that every layer, meshing
included, writes its files through it.
"""

from __future__ import annotations

import errno
import json
import os
import stat
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, BinaryIO


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
    note_written(path)


def open_regular(path: Path | str, follow_links: bool = False) -> BinaryIO:
    """``path`` opened for reading in binary if it is a regular file; `OSError` (``EINVAL``,
    naming it) if it is a FIFO, a device, a socket or a folder, and (unless
    ``follow_links``) ``ELOOP`` if it is a symbolic link. Opened without blocking and checked
    before a byte is read, so that nothing put where a file is expected can hang a run or
    make it read elsewhere."""
    flags = os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC | (0 if follow_links else os.O_NOFOLLOW)
    fd = os.open(path, flags)
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(errno.EINVAL, "not a regular file", str(path))
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_regular(path: Path | str, follow_links: bool = False) -> bytes:
    """The bytes of ``path`` if it is a regular file (`open_regular`)."""
    with open_regular(path, follow_links) as fh:
        return fh.read()


#: The journal of a claimed output folder: one JSON line ``[path, size, mtime_ns]`` per file
#: a brainbulge process (this one, a Dask worker, the mesher) wrote into it, appended as each
#: is written; the folder's manifest is made from it (`brainbulge.results.records.output_folder`).
JOURNAL = ".brainbulge.journal"


def note_written(path: Path | str, tracked: bool = True) -> None:
    """Record ``path`` in the journal of the nearest enclosing claimed output folder, if any,
    with its size [bytes] and modification time [ns] (``tracked``) or without (a log that
    grows while it runs). Best effort: a file left out is one ``--overwrite`` refuses to
    delete, never one it deletes wrongly."""
    p = Path(os.path.abspath(path))
    for folder in p.parents:
        journal = folder / JOURNAL
        if not journal.is_file():
            continue
        try:
            st = os.lstat(p)
            rel = p.relative_to(folder).as_posix()
            entry = [rel, st.st_size, st.st_mtime_ns] if tracked else [rel, None, None]
            fd = os.open(journal, os.O_WRONLY | os.O_APPEND)
            try:
                os.write(fd, (json.dumps(entry) + "\n").encode("utf-8"))
            finally:
                os.close(fd)
        except OSError:
            pass
        return


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


