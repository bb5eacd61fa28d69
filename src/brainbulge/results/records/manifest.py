"""The manifest of an output folder: which of its files brainbulge wrote, as written.

Every file a brainbulge process writes into a claimed folder is appended to the folder's
journal (`brainbulge.atomic.note_written`) with its size and modification time; the manifest
(``run.json["files"]``) is made from it. A file counts as brainbulge's only while it is as
written: one changed since, or one that appeared by other means, is the user's. `clear_listed`
deletes the listed files all or nothing. Used by :mod:`brainbulge.results.records.output_folder`.
"""

from __future__ import annotations

import json
import os
import shutil
import stat
import tempfile
from pathlib import Path, PurePosixPath
from typing import Any

from brainbulge.atomic import JOURNAL, read_regular
from brainbulge.errors import InputError

#: The lock file of a folder in use (not part of any manifest).
LOCK_FILE = ".brainbulge.lock"
#: Key of the manifest in ``run.json``.
MANIFEST_KEY = "files"

#: Prefix of the folder ``--overwrite`` moves the old files into before deleting them.
ASIDE = ".brainbulge-old."
Signature = tuple[int, int, int]
#: A manifest: relative path -> (size, mtime_ns) as written, or None (a log, an old manifest)
Manifest = dict[str, tuple[int, int] | None]


# --------------------------------------------------------------------------- listing


def _is_temporary(name: str) -> bool:
    """Temporary files of brainbulge's atomic writes (``.NAME.XXXX.tmp[.EXT]``,
    ``NAME.tmp.npz``)."""
    return name in (LOCK_FILE, JOURNAL) or name.startswith(f"{LOCK_FILE}.") or (
        name.startswith(".") and (name.endswith(".tmp") or ".tmp." in name)
    ) or name.endswith(".tmp.npz")


def folder_files(path: Path) -> dict[str, Signature]:
    """Every file (and symbolic link) under ``path``, as ``relative posix path -> (inode,
    size, mtime_ns)``; subfolders are walked without following links; the lock and the
    temporary files of atomic writes are left out."""
    root = Path(path)
    found: dict[str, Signature] = {}
    for dirpath, dirnames, filenames in os.walk(root, followlinks=False):
        here = Path(dirpath)
        links = [d for d in dirnames if (here / d).is_symlink()]
        dirnames[:] = [d for d in dirnames if d not in links and not d.startswith(ASIDE)]
        for name in (*filenames, *links):
            if _is_temporary(name):
                continue
            try:
                st = (here / name).lstat()
            except OSError:
                continue
            found[(here / name).relative_to(root).as_posix()] = (st.st_ino, st.st_size,
                                                                st.st_mtime_ns)
    return found


def check_no_special_entries(path: Path) -> None:
    """Refuse (`InputError`) a folder to resume in that holds a symbolic link, a FIFO, a
    device or a socket anywhere: brainbulge writes none, and going on would read, write or
    delete through it (outside the folder) or wait on it for good."""
    for dirpath, dirnames, filenames in os.walk(path, followlinks=False):
        here = Path(dirpath)
        for name in (*dirnames, *filenames):
            entry = here / name
            try:
                mode = entry.lstat().st_mode
            except OSError:
                continue
            kind = ("a symbolic link" if stat.S_ISLNK(mode) else None if stat.S_ISREG(mode)
                    or stat.S_ISDIR(mode) else "a FIFO" if stat.S_ISFIFO(mode)
                    else "a socket" if stat.S_ISSOCK(mode) else "a device file")
            if kind is not None:
                raise InputError(
                    f"cannot resume in {path}: {entry} is {kind}, which brainbulge never "
                    "writes (resuming would go through it); move it away and rerun, or "
                    "choose another --out")


def read_manifest(path: Path) -> Manifest | None:
    """The files listed in ``path/run.json`` and in a journal left by a killed run, as
    `Manifest` (``None`` if there is neither). Lists of names (older runs) read as files
    without signatures."""
    path = Path(path)
    try:
        record = json.loads(read_regular(path / "run.json").decode("utf-8"))
    except (OSError, ValueError, RecursionError):
        record = None
    files = record.get(MANIFEST_KEY) if isinstance(record, dict) else None
    manifest: Manifest | None = None
    if isinstance(files, list) and all(isinstance(f, str) for f in files):
        manifest = dict.fromkeys(files)
    elif isinstance(files, dict):
        manifest = {name: _signature(sig) for name, sig in files.items()}
    journal = read_journal(path)
    if journal:
        manifest = {**(manifest or {}), **journal}
    if manifest is None:
        return None
    return {f: sig for f, sig in manifest.items() if _safe_relative(f)}


def _signature(value: Any) -> tuple[int, int] | None:
    if (isinstance(value, list) and len(value) == 2
            and all(isinstance(v, int) and not isinstance(v, bool) for v in value)):
        return (value[0], value[1])
    return None


def read_journal(path: Path) -> Manifest:
    """The files the journal of ``path`` lists (the last entry of each); {} if none."""
    found: Manifest = {}
    try:
        lines = read_regular(Path(path) / JOURNAL).decode("utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return found
    for line in lines:
        try:
            name, size, mtime = json.loads(line)
        except (ValueError, TypeError):
            continue  # a line cut short by a kill
        if isinstance(name, str):
            found[name] = _signature([size, mtime])
    return found


def matches(sig: Signature, listed: tuple[int, int] | None) -> bool:
    """A file (``sig``: inode, size, mtime_ns) is as brainbulge wrote it."""
    return listed is None or tuple(sig[1:]) == tuple(listed)


def _safe_relative(name: str) -> bool:
    p = PurePosixPath(name)
    return bool(name) and not p.is_absolute() and ".." not in p.parts



def is_input(target: Path, inputs: frozenset[Path]) -> bool:
    """``target`` is (or lies in) one of the command's input files or folders."""
    if not inputs:
        return False
    try:
        real = target.resolve()
    except OSError:
        return False
    return real in inputs or any(p in inputs for p in real.parents)


def resolve_inputs(paths: Any) -> frozenset[Path]:
    """The existing files among ``paths`` (None and missing ones left out), resolved (links
    followed); for a folder, its ``brain.npz`` (a mesh folder is read through it)."""
    found = set()
    for p in paths:
        if not isinstance(p, str | os.PathLike) or str(p).strip() == "":
            continue
        try:
            real = Path(p).expanduser().resolve()
            if real.is_dir():
                real = real / "brain.npz"
            if real.is_file():
                found.add(real)
        except (OSError, RuntimeError, ValueError):
            continue
    return frozenset(found)


def config_paths(config: Any) -> list[str]:
    """Every text value of ``config`` (nested tables and lists): the candidates for the
    files a command reads (`resolve_inputs` keeps those that exist)."""
    if isinstance(config, dict):
        return [p for v in config.values() for p in config_paths(v)]
    if isinstance(config, list | tuple):
        return [p for v in config for p in config_paths(v)]
    return [config] if isinstance(config, str | os.PathLike) else []


def clear_listed(path: Path, manifest: Manifest, inputs: frozenset[Path] = frozenset()) -> Manifest:
    """Delete the files of ``manifest`` in ``path`` (not the command's ``inputs``), all or
    nothing: each is moved into one hidden folder, deleted once all are there; if one cannot
    be moved, those moved go back and `InputError` says which and what to do. Return the
    entries kept (inputs); the subfolders left empty are removed."""
    root = path.resolve()
    kept: Manifest = {}
    aside = Path(tempfile.mkdtemp(prefix=ASIDE, dir=path))
    moved: list[str] = []
    folders = set()
    try:
        for name in sorted(manifest):
            target = path / name
            if not (target.is_symlink() or target.is_file()):
                continue
            if root not in target.parent.resolve().parents and target.parent.resolve() != root:
                continue  # reached through a link out of the folder: not ours to delete
            if is_input(target, inputs):
                kept[name] = manifest[name]
                continue
            (aside / name).parent.mkdir(parents=True, exist_ok=True)
            os.rename(target, aside / name)
            moved.append(name)
            folders.update(p for p in PurePosixPath(name).parents if str(p) != ".")
    except OSError as exc:
        for name in reversed(moved):
            with ignored(OSError):
                os.rename(aside / name, path / name)
        shutil.rmtree(aside, ignore_errors=True)
        raise InputError(
            f"--overwrite cannot remove {target} of the earlier run "
            f"({(exc.strerror or str(exc)).lower()}), so nothing was deleted; make it "
            "removable (write permission on its folder, chattr -i) or choose another --out"
        ) from None
    shutil.rmtree(aside, ignore_errors=True)
    for sub in sorted(folders, key=lambda p: len(p.parts), reverse=True):
        with ignored(OSError):
            (path / sub).rmdir()  # only if empty
    return kept


class ignored:
    def __init__(self, *exc: type[BaseException]) -> None:
        self.exc = exc

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind: Any, value: Any, tb: Any) -> bool:
        return kind is not None and issubclass(kind, self.exc)
