"""Output folders that are safe to share: a lock per folder, a manifest of what was written.

A brainbulge command *claims* its ``--out`` folder before writing anything into it:

* the folder is checked first, read-only: ``--out ''``, a file, a folder in use by another
  run, a non-empty folder without ``--overwrite`` / resume, files brainbulge did not write,
  or (on resume) a folder of another study or other options are refused with one line;
* then the folder is created (if missing) and locked: ``.brainbulge.lock`` is created
  exclusively (``os.link`` of a complete temporary file, so it is never half-written) with
  the owner's process id, host and start time. A lock whose process is gone (same host) is
  stale: it is removed with a warning. A second run into the same folder is refused;
* ``--overwrite`` deletes only the files listed in the folder's manifest that are as
  brainbulge wrote them (same size and modification time), never an input of the command
  (``--mesh``, ``--labels``, a run file...), the current folder or one of its ancestors. It is
  all or nothing: the old files are first moved aside into one hidden folder, which is deleted
  only once all of them are there; if one cannot be moved, those moved go back and the folder
  is as it was;
* while the run goes on, every file a brainbulge process writes into the folder (this one,
  its Dask workers) is appended to the folder's journal (``.brainbulge.journal``) as it is
  written, with its size and modification time; the manifest (``run.json["files"]``: path
  relative to the folder -> ``[size, mtime_ns]``, or null for logs) is made from it on every
  status change; releasing the folder writes it a last time and removes the journal and the
  lock. A file that appears in the folder by other means (a notebook saved there, another
  run's results in a subfolder) is never listed. A resumed run's manifest stays listed; a
  killed run's journal counts as its manifest.
"""

from __future__ import annotations

import errno
import json
import logging
import os
import shutil
import socket
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from brainbulge.atomic import JOURNAL, read_regular
from brainbulge.errors import InputError
from brainbulge.results.records.manifest import (
    ASIDE,
    LOCK_FILE,
    MANIFEST_KEY,
    Manifest,
    check_no_special_entries,
    clear_listed,
    config_paths,
    folder_files,
    ignored,
    is_input,
    matches,
    read_journal,
    read_manifest,
    resolve_inputs,
)

log = logging.getLogger(__name__)

__all__ = [
    "LOCK_FILE",
    "OutputFolder",
    "check_out_path",
    "claim_output_dir",
    "config_paths",
    "folder_files",
    "prepare_output_dir",
    "read_manifest",
    "refresh_manifest",
]

#: Files that mark a folder as written by brainbulge.
RUN_MARKERS = ("run.json", "run.toml", "status.json", "study.json")
#: Files that make a folder resumable (a study, a 3D run stopped mid-way).
RESUMABLE = ("study.json", "restart.npz")
#: Folders claimed by this process (their manifests are refreshed by `refresh_manifest`).
_CLAIMED: dict[Path, OutputFolder] = {}
#: Room kept for the names brainbulge writes inside ``--out`` (scenario folders of up to 100
#: characters and their files) [characters]
NAME_ROOM = 160


def _is_run_folder(path: Path) -> bool:
    return any((path / name).is_file() for name in RUN_MARKERS)


def _listing(names: list[str], limit: int = 3) -> str:
    shown = ", ".join(names[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")


# --------------------------------------------------------------------------- checks


def check_out_path(path: Path | str, overwrite: bool) -> Path:
    """Refuse an ``--out`` that cannot be right, before anything is touched: empty, a name
    too long for the file system, a file, or (with ``overwrite``) the current folder or one of
    its ancestors."""
    if str(path).strip() == "":
        raise InputError("--out is empty; give the name of a folder for the results")
    path = Path(path)
    name_max, path_max = _name_limits(path)
    long = [part for part in path.parts if len(os.fsencode(part)) > name_max]
    if long:
        raise InputError(f"--out: the name {long[0][:40]}... has {len(os.fsencode(long[0]))} "
                         f"characters, more than the {name_max} the file system allows; choose "
                         "a shorter --out")
    full = len(os.fsencode(os.path.abspath(path)))
    if full + NAME_ROOM > path_max:
        raise InputError(f"--out is {full} characters long as a full path; the results need "
                         f"{NAME_ROOM} more, and the file system allows {path_max}: choose a "
                         "shorter --out")
    if path.is_symlink() and not path.exists():
        raise InputError(f"--out {path} is a symbolic link to nothing (its target is missing, "
                         "or the link loops); remove the link or choose another --out")
    if path.exists() and not path.is_dir():
        raise InputError(f"output folder {path} exists and is a file; choose another --out")
    if overwrite and path.exists():
        here, target = Path.cwd().resolve(), path.resolve()
        if target == here or target in here.parents or target == Path.home().resolve():
            raise InputError(
                f"--overwrite would clear {path}, which holds the current folder (or is your "
                "home folder); choose a new folder for --out"
            )
    return path


def _name_limits(path: Path) -> tuple[int, int]:
    """The longest file name and path [bytes] where ``path`` would be created."""
    here = Path(os.path.abspath(path))
    while not here.exists() and here != here.parent:
        here = here.parent
    try:
        return os.pathconf(here, "PC_NAME_MAX"), os.pathconf(here, "PC_PATH_MAX")
    except (OSError, ValueError):
        return 255, 4096


def _normalised(config: Any) -> Any:
    """``config`` as it reads back from ``run.toml``."""
    import tomllib

    import tomli_w

    from brainbulge.results.records.config_file import toml_ready

    return tomllib.loads(tomli_w.dumps(toml_ready(config)))


def _differences(stored: Any, new: Any, where: str = "") -> list[str]:
    if isinstance(stored, dict) and isinstance(new, dict):
        out = []
        for key in sorted(set(stored) | set(new)):
            out += _differences(stored.get(key), new.get(key), f"{where}.{key}" if where else key)
        return out
    if (isinstance(stored, list) and isinstance(new, list) and len(stored) == len(new)
            and where == "scenarios"):
        names = [str(s.get("name")) if isinstance(s, dict) else "?" for s in new]
        return [f"scenario {n}" for n, a, b in zip(names, stored, new, strict=True) if a != b]
    return [] if stored == new else [where or "configuration"]


def _names(config: dict[str, Any]) -> list[str]:
    return [str(s.get("name")) for s in config.get("scenarios") or [] if isinstance(s, dict)]


def _check_same_run(path: Path, config: dict[str, Any] | None) -> None:
    """On resume: the folder's ``run.toml`` must describe the same command and options."""
    toml = path / "run.toml"
    if config is None or not toml.is_file():
        return
    from brainbulge.results.records.config_file import load_config

    stored, new = load_config(toml), _normalised(config)
    if stored == new:
        return
    what = "a study" if "study" in stored or "study" in new else "a stopped run"
    if stored.get("command") != new.get("command") or stored.get("study") != new.get("study"):
        name = stored.get("study") or stored.get("command")
        detail = f"of {name!r}"
    elif "scenarios" in stored and len(stored.get("scenarios") or []) != len(
            new.get("scenarios") or []):
        detail = (f"with {len(stored['scenarios'])} scenarios, not "
                  f"{len(new.get('scenarios') or [])}")
    elif _names(stored) != _names(new):
        detail = f"with other scenarios ({_listing(_names(stored))})"
    else:
        detail = f"with other options ({_listing(_differences(stored, new))})"
    raise InputError(
        f"output folder {path} holds {what} {detail}; pass --overwrite to replace it, or "
        "choose another --out"
    )


def _inspect(path: Path, overwrite: bool, resume: bool, config: dict[str, Any] | None,
             locked: bool = False, inputs: frozenset[Path] = frozenset()) -> str:
    """What to do with ``path``: "fresh" (missing or empty), "resume" or "clear"; read-only.

    Raises `InputError` for every folder that must not be used."""
    if overwrite and resume:
        raise InputError("--overwrite and --resume contradict each other; pass only one")
    if not path.is_dir():
        return "fresh"
    if not locked:
        _check_lock(path)
    try:
        present = folder_files(path)
        empty = not present and not any(
            p.name not in (LOCK_FILE, JOURNAL) for p in path.iterdir())
    except OSError as exc:
        raise InputError(f"cannot read output folder {path}: {exc.strerror or exc}") from exc
    if empty:
        return "fresh"
    if resume:
        if not any((path / name).is_file() for name in RESUMABLE):
            raise InputError(
                f"cannot resume: output folder {path} is not empty and holds no study.json"
                " or restart.npz; choose another --out"
            )
        check_no_special_entries(path)
        _check_same_run(path, config)
        return "resume"
    if not overwrite:
        raise InputError(
            f"output folder {path} exists and is not empty; pass --overwrite or choose"
            " another --out"
        )
    manifest = read_manifest(path)
    if manifest is None:
        if _is_run_folder(path):
            raise InputError(
                f"output folder {path} has no list of the files brainbulge wrote (run.json "
                "\"files\"), so --overwrite cannot tell them from yours; delete it yourself "
                "or choose another --out"
            )
        raise InputError(
            f"output folder {path} is not empty and is not a brainbulge output (no run.json"
            " or study.json); refusing to delete it, choose another --out"
        )
    foreign = sorted(f for f, sig in present.items()
                     if (f not in manifest or not matches(sig, manifest[f]))
                     and not is_input(path / f, inputs))
    if foreign:
        raise InputError(
            f"output folder {path} holds {len(foreign)} file(s) brainbulge did not write or "
            f"that changed since ({_listing(foreign)}); --overwrite never deletes those: move "
            "them away or choose another --out"
        )
    return "clear"


# --------------------------------------------------------------------------- the lock


def _pid_alive(pid: int, since: float) -> bool:
    """True if process ``pid`` runs and started before ``since`` (else the id was reused)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        import psutil

        proc = psutil.Process(pid)
        if proc.status() == psutil.STATUS_ZOMBIE:
            return False
        return proc.create_time() <= since + 1.0
    except Exception:  # noqa: BLE001 - psutil missing or the process just ended
        return True


def _read_object(path: Path) -> dict[str, Any] | None:
    """The JSON object in the regular file ``path``; None when unreadable or not an object."""
    try:
        data = json.loads(read_regular(path).decode("utf-8"))
    except (OSError, ValueError, RecursionError):
        return None
    return data if isinstance(data, dict) else None


def _stale(lock: Path, owner: dict[str, Any] | None) -> bool:
    """A lock is stale if its process (on this host) is gone, or it is unreadable and old."""
    if owner is None:
        try:
            return time.time() - lock.stat().st_mtime > 60
        except OSError:
            return True
    if owner.get("host") != socket.gethostname():
        return False  # another machine's process: cannot tell, assume it runs
    try:
        return not _pid_alive(int(owner["pid"]), float(owner.get("started", time.time())))
    except (KeyError, TypeError, ValueError):
        return True


def _in_use(path: Path, owner: dict[str, Any] | None) -> InputError:
    who = (f"process {owner.get('pid')} on {owner.get('host')}, since "
           f"{time.strftime('%Y-%m-%d %H:%M', time.localtime(owner.get('started', 0)))}"
           if owner else "another process")
    return InputError(
        f"output folder {path} is in use by another brainbulge run ({who}); wait for it to "
        f"finish or choose another --out (if no run is active, delete {path / LOCK_FILE})"
    )


def _check_lock(path: Path) -> None:
    lock = path / LOCK_FILE
    if lock.exists() or lock.is_symlink():
        owner = _read_object(lock)
        if not _stale(lock, owner):
            raise _in_use(path, owner)


def _acquire_lock(path: Path) -> Path:
    """Create ``path/.brainbulge.lock`` exclusively; remove a stale one first."""
    lock = path / LOCK_FILE
    owner = {"pid": os.getpid(), "host": socket.gethostname(), "started": time.time()}
    tmp = path / f"{LOCK_FILE}.{os.getpid()}.tmp"
    try:
        tmp.write_text(json.dumps(owner), encoding="utf-8")
        for attempt in range(2):
            try:
                os.link(tmp, lock)
                return lock
            except FileExistsError:
                other = _read_object(lock)
                if attempt or not _stale(lock, other):
                    raise _in_use(path, other) from None
                log.warning("removing the stale lock of a run that is no longer running "
                            "(%s)", f"process {other.get('pid')}" if other else "unreadable")
                lock.unlink(missing_ok=True)
    except OSError as exc:
        raise InputError(
            f"cannot write into output folder {path}: {exc.strerror or exc}; choose a "
            "writable --out"
        ) from exc
    finally:
        tmp.unlink(missing_ok=True)
    raise _in_use(path, _read_object(lock))  # pragma: no cover - loop always returns/raises


# --------------------------------------------------------------------------- the folder


@dataclass
class OutputFolder:
    """A claimed output folder: locked by this process until `release`."""

    path: Path
    created: bool
    previous: Manifest = field(default_factory=dict)
    lock: Path | None = None
    journal: bool = False  # True once this process's journal is started
    resumed: bool = False  # the folder holds an earlier run that this one goes on with

    def manifest(self) -> Manifest:
        """The files brainbulge wrote here that are still as written: those of the journal
        and of the earlier manifest (resume, kept inputs), with ``run.json``."""
        now = folder_files(self.path) if self.path.is_dir() else {}
        listed = {**self.previous, **read_journal(self.path)}
        found = {f: sig for f, sig in listed.items() if f in now and matches(now[f], sig)}
        return {**found, "run.json": None}

    def written(self) -> set[str]:
        """The names of `manifest` that this run wrote (not those of the earlier manifest)."""
        journal = read_journal(self.path)
        return {f for f in self.manifest() if f in journal}

    def record_files(self) -> None:
        """Write the manifest into ``run.json`` (if the run record exists)."""
        from brainbulge.atomic import atomic_write_json

        run_json = self.path / "run.json"
        if (record := _read_object(run_json)) is None:
            return
        record[MANIFEST_KEY] = {f: None if sig is None else list(sig)
                                for f, sig in sorted(self.manifest().items())}
        atomic_write_json(run_json, record)

    def drop_empty_files(self) -> list[str]:
        """Delete the empty files this run created (e.g. left by a full disk)."""
        dropped = []
        for name in sorted(self.written() - set(self.previous)):
            target = self.path / name
            with ignored(OSError):
                if target.is_file() and not target.is_symlink() and target.stat().st_size == 0:
                    target.unlink()
                    dropped.append(name)
        return dropped

    def release(self) -> None:
        """Refresh the manifest (best effort) and remove the journal and the lock; if the
        manifest cannot be written (a full disk) the journal stays: it lists the files."""
        _CLAIMED.pop(self.path.resolve(), None)
        try:
            if self.journal:  # else the claim failed: the folder's record is left as it was
                self.record_files()
                (self.path / JOURNAL).unlink(missing_ok=True)
                self.journal = False
        except OSError as exc:  # e.g. the disk is full: the lock still goes
            log.info("could not update the file list in %s: %s", self.path / "run.json",
                        exc.strerror or exc)
        if self.lock is not None:
            self.lock.unlink(missing_ok=True)
            self.lock = None


def claim_output_dir(
    path: Path | str, overwrite: bool, resume: bool = False,
    config: dict[str, Any] | None = None, inputs: Any = (),
) -> OutputFolder:
    """Check, create, lock and (``overwrite``) clear the output folder ``path``.

    Refused with `InputError` (nothing touched): see the module docstring. On ``resume``
    the folder must hold ``study.json`` or ``restart.npz`` and, if it has a ``run.toml``,
    the same ``config``. ``inputs`` (paths the command reads) are never deleted. Release the
    returned folder with `OutputFolder.release`.
    """
    path = check_out_path(path, overwrite)
    protected = resolve_inputs(inputs)
    _inspect(path, overwrite, resume, config, inputs=protected)  # everything read-only first
    created = not path.exists()
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create output folder {path}: {exc.strerror or exc}; choose "
                         "a writable --out") from exc
    try:
        lock = _acquire_lock(path)
    except InputError:
        if created:
            with ignored(OSError):
                path.rmdir()
        raise
    folder = OutputFolder(path, created, lock=lock)
    try:
        action = _inspect(path, overwrite, resume, config, locked=True, inputs=protected)
        for old in path.glob(f"{ASIDE}*"):  # left by an --overwrite that was killed
            shutil.rmtree(old, ignore_errors=True)
        manifest = read_manifest(path) or {}
        if action == "clear":
            folder.previous = clear_listed(path, manifest, protected)
        elif action == "resume":
            folder.resumed = True
            now = folder_files(path)
            folder.previous = {f: sig for f, sig in manifest.items()
                               if f in now and matches(now[f], sig)}
        _start_journal(path)
        folder.journal = True
    except BaseException:
        folder.release()
        raise
    _CLAIMED[path.resolve()] = folder
    return folder


def _start_journal(path: Path) -> None:
    """An empty journal in ``path`` (replacing that of a killed run, already read)."""
    tmp = path / f"{JOURNAL}.{os.getpid()}.tmp"
    try:
        tmp.write_bytes(b"")
        os.replace(tmp, path / JOURNAL)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise InputError(f"cannot write into output folder {path}: {exc.strerror or exc}; "
                         "choose a writable --out") from exc


def refresh_manifest(path: Path) -> None:
    """Update the manifest of the claimed folder holding ``path`` (no-op if none)."""
    if not _CLAIMED:
        return
    here = Path(path).resolve()
    for root, folder in list(_CLAIMED.items()):
        if here == root or root in here.parents:
            try:
                folder.record_files()
            except OSError as exc:
                if exc.errno not in (errno.ENOSPC, errno.EDQUOT):
                    raise
            return


def prepare_output_dir(path: Path, overwrite: bool, resume: bool = False) -> Path:
    """Check, create and (``overwrite``) clear ``path`` without keeping a lock; for scripts.

    The same rules as `claim_output_dir`: a non-empty folder is refused unless
    ``overwrite`` (only the files of its manifest are deleted) or ``resume`` (it holds
    ``study.json`` or ``restart.npz``, reused as is)."""
    folder = claim_output_dir(path, overwrite, resume)
    _CLAIMED.pop(folder.path.resolve(), None)
    (folder.path / JOURNAL).unlink(missing_ok=True)
    if folder.lock is not None:
        folder.lock.unlink(missing_ok=True)
    return folder.path
