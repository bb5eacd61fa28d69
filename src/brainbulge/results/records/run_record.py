"""Output folders and reproducibility records, shared by every CLI command.

A run's output folder holds, besides its results:

``run.toml``
    the exact, fully resolved configuration; ``load_config`` reads it back, so
    ``brainbulge run out/run.toml --out NEW`` repeats the run.
``run.json``
    provenance: command line, brainbulge / Python / platform / library versions, start time,
    random seed (if the configuration has one) and the git commit of the source tree.
``status.json``
    ``{"status": "running" | "complete" | "incomplete" | "failed", "message", "time"}``,
    so a crashed or interrupted run is recognisable from its folder alone.

``run.json["files"]`` lists every file the run wrote (the manifest ``--overwrite`` deletes,
see :mod:`brainbulge.results.records.output_folder`). All JSON/TOML files are written atomically
(temporary file in the same folder, then ``os.replace``), readable as the user's umask
allows: a reader never sees half a file, even after a crash.

>>> import tempfile
>>> out = prepare_output_dir(Path(tempfile.mkdtemp()) / "run1", overwrite=False)
>>> toml_path = write_run_record(out, {"seed": 7, "mesh": {"h_mm": 2.0}}, ["brainbulge", "x"])
>>> load_config(toml_path)
{'seed': 7, 'mesh': {'h_mm': 2.0}}
>>> mark_status(out, "complete").name
'status.json'
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from collections.abc import Mapping
from datetime import UTC, datetime
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import tomli_w

from brainbulge import __version__
from brainbulge.atomic import atomic_output, atomic_write_json, atomic_write_text
from brainbulge.errors import InputError
from brainbulge.results.records.config_file import load_config, toml_ready
from brainbulge.results.records.output_folder import RUN_MARKERS, refresh_manifest

__all__ = [
    "STATUSES",
    "atomic_output",
    "atomic_write_json",
    "atomic_write_text",
    "is_run_folder",
    "load_config",
    "mark_status",
    "prepare_output_dir",
    "toml_ready",
    "write_run_record",
]

#: Allowed values of ``status.json["status"]``.
STATUSES = ("running", "complete", "incomplete", "failed")

#: Distributions whose versions go into ``run.json`` (those installed).
RECORDED_PACKAGES = (
    "numpy",
    "scipy",
    "ngsolve",
    "pypardiso",
    "meshio",
    "matplotlib",
    "dask",
    "distributed",
    "nibabel",
    "nilearn",
)

# --------------------------------------------------------------------------- output folder


def is_run_folder(path: Path) -> bool:
    """True if ``path`` holds a brainbulge run record, status or study file."""
    return any((Path(path) / name).is_file() for name in RUN_MARKERS)


def prepare_output_dir(path: Path, overwrite: bool, resume: bool = False) -> Path:
    """Check, create and (``overwrite``) clear the output folder ``path``; return it.

    See `brainbulge.results.records.output_folder.prepare_output_dir` (and `claim_output_dir`, which
    also locks the folder, for commands)."""
    from brainbulge.results.records.output_folder import prepare_output_dir as prepare

    return prepare(path, overwrite, resume)


# --------------------------------------------------------------------------- configuration


# --------------------------------------------------------------------------- provenance


def _package_versions() -> dict[str, str]:
    versions = {}
    for name in RECORDED_PACKAGES:
        try:
            versions[name] = version(name)
        except PackageNotFoundError:
            continue
    return versions


def _git_commit() -> str | None:
    """Commit (``+dirty`` if modified) of the source tree brainbulge runs from, if any."""
    src = Path(__file__).resolve().parent
    try:
        head = subprocess.run(
            ["git", "-C", str(src), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=5,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(src), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=5,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return f"{head}+dirty" if dirty else head or None


def _find_seed(config: Mapping[str, Any]) -> Any:
    """The first ``seed`` / ``random_seed`` value in ``config``, searched breadth-first."""
    queue: list[Mapping[str, Any]] = [config]
    while queue:
        table = queue.pop(0)
        for key in ("seed", "random_seed"):
            if table.get(key) is not None:
                return table[key]
        queue.extend(v for v in table.values() if isinstance(v, Mapping))
    return None


def write_run_record(
    out_dir: Path, config: Mapping[str, Any], command: list[str] | None,
    files: Mapping[str, Any] | set[str] | None = None,
) -> Path:
    """Write ``run.toml`` (the resolved ``config``) and ``run.json`` (provenance) into
    ``out_dir``; return the path of ``run.toml``.

    ``command`` is the command line to record (``sys.argv`` if None). ``config`` must be
    convertible by `toml_ready` (tuples, paths, enums, dataclasses, numpy values are
    converted; None values are dropped). ``files`` (the manifest of a resumed run: names, or
    names -> ``(size, mtime_ns)`` as written) are listed in ``run.json["files"]`` with
    ``run.toml`` and ``run.json``.
    """
    out_dir = Path(out_dir)
    start = datetime.now(UTC).isoformat(timespec="seconds")
    try:
        table = toml_ready(config)
    except TypeError as exc:
        raise InputError(f"configuration cannot be recorded: {exc}") from exc
    toml_path = atomic_write_text(out_dir / "run.toml", tomli_w.dumps(table))
    record = {
        "command": list(sys.argv if command is None else command),
        "brainbulge_version": __version__,
        "git_commit": _git_commit(),
        "python_version": platform.python_version(),
        "python_implementation": platform.python_implementation(),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "packages": _package_versions(),
        "start_time": start,
        "seed": _find_seed(table),
        "config_file": toml_path.name,
        "files": _file_list(files, toml_path),
    }
    atomic_write_json(out_dir / "run.json", record)
    return toml_path


def _file_list(files: Mapping[str, Any] | set[str] | None, toml_path: Path
               ) -> dict[str, list[int] | None]:
    """``files`` as ``run.json["files"]``, with ``run.toml`` (as written) and ``run.json``."""
    listed = dict(files) if isinstance(files, Mapping) else dict.fromkeys(files or ())
    st = toml_path.stat()
    listed |= {toml_path.name: (st.st_size, st.st_mtime_ns), "run.json": None}
    return {f: None if sig is None else list(sig) for f, sig in sorted(listed.items())}


def mark_status(out_dir: Path, status: str, message: str = "") -> Path:
    """Write ``status.json`` ``{"status", "message", "time"}`` atomically; return its path.

    ``status`` is one of `STATUSES`: "running" (started), "complete", "incomplete"
    (stopped early, e.g. not all load steps or scenarios finished) or "failed".
    """
    if status not in STATUSES:
        raise ValueError(f"status must be one of {', '.join(STATUSES)}, not {status!r}")
    record = {
        "status": status,
        "message": " ".join(str(message).split()),
        "time": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    path = Path(out_dir) / "status.json"
    try:
        atomic_write_json(path, record)
    except OSError:
        if not path.is_file():
            raise
        # no room for a new file (no free inode, a full disk): the status still has to
        # change, so it is written over the old one, in the blocks it already has
        with open(path, "r+b") as fh:
            fh.write((json.dumps(record, indent=2) + "\n").encode("utf-8"))
            fh.truncate()
    refresh_manifest(Path(out_dir))
    return path
