"""Run many scenarios in parallel on a Dask cluster, resumably, with a progress bar.

A *study* is a list of scenarios, each a plain JSON-able dict with a unique, filesystem-safe
``"name"``. `run_study` calls ``task(scenario, scenario_dir)`` once per scenario, each in its own
folder ``out_dir/<name>/``, and records the outcome there:

``summary.json``
    the summary dict returned by ``task`` plus ``"name"`` and ``"complete": true``; written
    atomically, and only when ``task`` succeeded. A rerun with the same ``out_dir`` loads it
    instead of recomputing the scenario (resume after a crash, an interruption or a failure).
``error.json``
    ``{"name", "complete": false, "error": "<one-line message>", "traceback"}`` when ``task``
    raised; the study goes on with the other scenarios and retries this one on the next run.
``scenario.json``
    the scenario as run. If a scenario's parameters change between runs but its name does not,
    the stale summary is not trusted and the scenario is recomputed.

``out_dir/study.json`` lists every scenario with its status (``pending``, ``complete`` or
``failed``); it is rewritten after each scenario finishes, so it also shows live progress.

Where the scenarios run (``scheduler``):

* ``None`` (default): a `distributed.LocalCluster` of ``n_workers`` (default 2) worker
  *processes*, each running one scenario at a time with ``OMP_NUM_THREADS``,
  ``MKL_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``, ``NGS_NUM_THREADS`` and ``NUMBA_NUM_THREADS``
  set to cores / ``n_workers`` (at least 1), so that the workers neither oversubscribe the
  cores nor leave them idle; closed at the end. Worker processes are *spawned*: a script
  calling `run_study` must guard its top level with ``if __name__ == "__main__":``.
* ``"serial"``: one after the other in this process: no pickling, breakpoints and profilers work;
  for debugging and fast tests.
* an address such as ``"tcp://10.0.0.5:8786"``: an existing scheduler (e.g. a ``dask-jobqueue``
  cluster on an HPC system). Only the client is closed at the end, not the cluster. Workers
  must see ``out_dir`` at the same path (shared filesystem) and have brainbulge installed.

``task`` is sent to worker processes by pickling, which stores a module-level function by
reference (``module.function``): it must be a top-level function of a module that the
*workers* can import, not a lambda, closure or a function defined in a notebook or ``__main__``.
It may also be given as a string ``"package.module:function"``, resolved on the worker. Workers
started by a `LocalCluster` inherit this process's environment (e.g. ``PYTHONPATH``) but not its
``sys.path`` changes.

>>> import tempfile
>>> out = Path(tempfile.mkdtemp())
>>> rows = run_study([{"name": "a", "x": 2}, {"name": "b", "x": 3}], echo_task, out,
...                  scheduler="serial", progress=False)
>>> [(row["name"], row["x"], row["complete"]) for row in rows]
[('a', 2, True), ('b', 3, True)]
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import re
import sys
import traceback
import uuid
import zipfile
from collections.abc import Callable, Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from tqdm.auto import tqdm

from brainbulge.atomic import open_regular, read_regular
from brainbulge.errors import InputError
from brainbulge.results.records.output_folder import refresh_manifest
from brainbulge.results.records.run_record import atomic_write_json
from brainbulge.studies.cluster import (
    THREAD_VARIABLES,
    local_cluster,
    shared_scheduler,
    worker_env,
)
from brainbulge.studies.tasks import (
    Task,
    echo_task,
    execute,
    execute_on_worker,
    one_line,
    resolve_task,
    to_json,
)

__all__ = ["SERIAL", "THREAD_VARIABLES", "Task", "echo_task", "local_cluster", "run_study",
           "shared_scheduler", "validate_scenarios", "worker_env"]

logger = logging.getLogger(__name__)

#: ``scheduler`` value for in-process, one-after-the-other execution.
SERIAL = "serial"

#: Scenario names: start with a letter or digit, then letters, digits, ``_``, ``-``, ``.``.
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,99}")

#: Names ending so (ignoring case) would collide with files the runner, the run record, the
#: log and the study's reports write into ``out_dir`` (``study.json``, ``run.toml``,
#: ``brainbulge.log``, ``report.md``, ``report.html``, ``table.csv``, its figures, ...).
RESERVED_SUFFIXES = (".json", ".toml", ".log", ".md", ".html", ".csv", ".png", ".npz", ".vtu",
                     ".pvd", ".xdmf", ".h5")

CONNECT_TIMEOUT = "10s"  #: how long to try to reach an existing Dask scheduler

SUMMARY_FILE = "summary.json"
ERROR_FILE = "error.json"
SCENARIO_FILE = "scenario.json"
STUDY_FILE = "study.json"


# --------------------------------------------------------------------------- helpers


def validate_scenarios(scenarios: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Check names (present, filesystem-safe, unique even ignoring case, not reserved) and that
    each scenario is JSON-able; return the scenarios as JSON values. Raises `InputError`."""
    if isinstance(scenarios, Mapping) or not isinstance(scenarios, list | tuple):
        raise InputError("scenarios must be a list of dicts, each with a 'name'")
    seen: dict[str, str] = {}
    normalised = []
    for i, scenario in enumerate(scenarios):
        if not isinstance(scenario, Mapping):
            raise InputError(f"scenario #{i} is a {type(scenario).__name__}, not a dict")
        name = scenario.get("name")
        if not isinstance(name, str) or not name:
            raise InputError(f"scenario #{i} has no 'name'; give every scenario a unique name")
        if name.lower().endswith(RESERVED_SUFFIXES):
            raise InputError(
                f"scenario name {name!r} is reserved: names ending in "
                f"{', '.join(RESERVED_SUFFIXES)} are the study's own files; choose another name")
        if not NAME_PATTERN.fullmatch(name):
            raise InputError(
                f"scenario name {name!r} is not allowed; use up to 100 letters, digits, '_', "
                "'-' or '.', starting with a letter or digit"
            )
        if name.lower() in seen:
            raise InputError(
                f"scenario name {name!r} is used twice (as {seen[name.lower()]!r}); names must"
                " be unique, ignoring case"
            )
        seen[name.lower()] = name
        try:
            normalised.append(to_json(dict(scenario)))
        except (TypeError, ValueError) as exc:
            raise InputError(f"scenario {name!r} is not JSON-serialisable: {exc}") from exc
    return normalised


def _read_json(path: Path) -> Any:
    """The JSON in ``path``; None if it is missing, unreadable, not JSON or not a regular
    file (a link, a FIFO: never followed, never waited on)."""
    try:
        return json.loads(read_regular(path).decode("utf-8"))
    except (OSError, ValueError, RecursionError):
        return None


def stopped_summary(scenario_dir: Path) -> dict[str, Any] | None:
    """The ``summary.json`` a task left in ``scenario_dir`` for a run that stopped before
    full load and raised (``"converged": false``: the last converged state's keys, e.g.
    ``load_reached`` and ``failure_site``; the hemidisk and brain tasks write one), without
    its ``inputs``; None if there is none (a completed scenario's summary says
    ``"complete": true`` and has no ``converged`` false)."""
    summary = _read_json(Path(scenario_dir) / SUMMARY_FILE)
    if not isinstance(summary, dict) or summary.get("converged") is not False:
        return None
    return {k: v for k, v in summary.items() if k != "inputs"}


def _readable(path: Path) -> bool:
    """``path`` is a complete file: an ``.npz`` whose members all pass their checksums, a
    ``.json`` that parses, anything else not empty."""
    try:
        # a link or a FIFO is not a result (and is never waited on)
        with open_regular(path) as fh:
            if path.suffix == ".npz":
                with zipfile.ZipFile(fh) as archive:
                    return archive.testzip() is None
            if path.suffix == ".json":
                json.loads(fh.read().decode("utf-8"))
                return True
            return os.fstat(fh.fileno()).st_size > 0
    except (OSError, ValueError, RecursionError, zipfile.BadZipFile, EOFError):
        return False


def _finished_summary(scenario_dir: Path, scenario_json: dict[str, Any],
                      outputs: tuple[str, ...] = ()) -> dict | None:
    """The stored summary if the scenario finished before with the same parameters and its
    ``outputs`` (files the study reads afterwards) are all there and readable."""
    summary = _read_json(scenario_dir / SUMMARY_FILE)
    if not isinstance(summary, dict) or summary.get("complete") is not True:
        return None
    broken = [name for name in outputs if not _readable(scenario_dir / name)]
    if broken:
        logger.warning("scenario %s: %s missing or unreadable; recomputing it",
                       scenario_json["name"], ", ".join(broken))
        return None
    stored = _read_json(scenario_dir / SCENARIO_FILE)
    if stored is not None and stored != scenario_json:
        logger.warning(
            "scenario %s changed since its summary was written; recomputing it",
            scenario_json["name"],
        )
        return None
    return summary


class _Study:
    """Bookkeeping of one `run_study` call: records, statuses and ``study.json``."""

    def __init__(self, scenarios: list[dict[str, Any]], out_dir: Path,
                 outputs: tuple[str, ...] = ()) -> None:
        self.scenarios = scenarios
        self.out_dir = out_dir
        self.outputs = outputs
        self.results: list[dict[str, Any] | None] = [None] * len(scenarios)
        self.status = ["pending"] * len(scenarios)
        self.resumed = [False] * len(scenarios)
        self.started = datetime.now(UTC).isoformat(timespec="seconds")

    def scenario_dir(self, i: int) -> Path:
        return self.out_dir / self.scenarios[i]["name"]

    def load_finished(self) -> list[int]:
        """Load finished scenarios; prepare folders of the others; return the others."""
        pending = []
        for i, scenario in enumerate(self.scenarios):
            folder = self.scenario_dir(i)
            if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
                raise InputError(f"{folder} is a link or a file, not a scenario folder that "
                                 "brainbulge made; move it away and rerun")
            summary = _finished_summary(folder, scenario, self.outputs)
            if summary is not None:
                self.results[i], self.status[i], self.resumed[i] = summary, "complete", True
                continue
            folder.mkdir(parents=True, exist_ok=True)
            for stale in (SUMMARY_FILE, ERROR_FILE):
                (folder / stale).unlink(missing_ok=True)
            atomic_write_json(folder / SCENARIO_FILE, scenario)
            pending.append(i)
        return pending

    def record(self, i: int, outcome: dict[str, Any]) -> dict[str, Any]:
        """Write ``summary.json`` or ``error.json`` for scenario ``i``; return its row."""
        name = self.scenarios[i]["name"]
        if outcome["ok"]:
            summary = {k: v for k, v in outcome["summary"].items() if k not in ("name", "complete")}
            row = {"name": name, **summary, "complete": True}
            atomic_write_json(self.scenario_dir(i) / SUMMARY_FILE, row)
            self.status[i] = "complete"
        else:
            row = {"name": name, "complete": False, "error": outcome["error"]}
            atomic_write_json(
                self.scenario_dir(i) / ERROR_FILE,
                {**row, "traceback": outcome.get("traceback", "")},
            )
            self.status[i] = "failed"
            logger.warning("scenario %s failed: %s", name, outcome["error"])
        self.results[i] = row
        return row

    def write(self) -> Path:
        entries = []
        for i, scenario in enumerate(self.scenarios):
            entry: dict[str, Any] = {"name": scenario["name"], "status": self.status[i]}
            if self.resumed[i]:
                entry["resumed"] = True
            if self.status[i] == "failed":
                entry["error"] = self.results[i]["error"]
            entry["scenario"] = scenario
            entries.append(entry)
        counts = {s: self.status.count(s) for s in ("complete", "failed", "pending")}
        path = atomic_write_json(
            self.out_dir / STUDY_FILE,
            {
                "n_scenarios": len(self.scenarios),
                **{f"n_{s}": n for s, n in counts.items()},
                "started": self.started,
                "updated": datetime.now(UTC).isoformat(timespec="seconds"),
                "scenarios": entries,
            },
        )
        refresh_manifest(self.out_dir)  # the files written so far, for --overwrite
        return path


# --------------------------------------------------------------------------- the runner


def run_study(
    scenarios: list[dict[str, Any]],
    task: Task,
    out_dir: Path,
    scheduler: str | None = None,
    n_workers: int | None = None,
    progress: bool = True,
    cost: Callable[[dict[str, Any]], float] | None = None,
    outputs: tuple[str, ...] = (),
) -> list[dict[str, Any]]:
    """Run ``task(scenario, out_dir / name)`` for every scenario; return the summaries in input
    order.

    Each returned row is the task's summary with ``"name"`` and ``"complete": True`` (as also
    stored in ``summary.json``; a scenario completed by an earlier run is loaded, not rerun), or
    ``{"name", "complete": False, "error": "<one-line message>"}`` for a scenario whose task
    raised. Failures do not stop the study; check ``row["complete"]``.

    Parameters
    ----------
    scenarios
        JSON-able dicts, each with a unique filesystem-safe ``"name"`` (see
        `validate_scenarios`); values are passed to ``task`` unchanged.
    task
        Top-level function ``task(scenario, scenario_dir) -> dict`` importable by the workers,
        or its path ``"package.module:function"``. It writes its files into ``scenario_dir``
        (created beforehand) and returns a JSON-able summary.
    out_dir
        Study folder (created if missing; see `results.records.run_record.prepare_output_dir`
        with ``resume=True`` for CLI use).
    scheduler
        None: a local cluster of worker processes; ``"serial"``: in this process, one after
        the other; otherwise the address of a running Dask scheduler.
    n_workers
        Worker processes of the local cluster (default 2, at most the number of scenarios to
        run); ignored otherwise.
    progress
        Show a tqdm progress bar over finished scenarios when stderr is a terminal; a log
        line (INFO) per finished scenario in any case.
    cost
        Expected relative run time of a scenario (any positive scale). On a cluster the
        scenarios start in order of decreasing cost (Dask task priorities), so that the
        longest do not start last and leave one worker busy while the others idle; serial
        runs keep the input order.
    outputs
        Files of a scenario's folder that the caller reads afterwards (e.g. ``fields.npz``
        for figures): a scenario finished before whose outputs are missing or unreadable
        (truncated, a failed checksum) is run again.

    Raises
    ------
    InputError
        Invalid scenarios or names, an unimportable task path, or ``n_workers < 1``.
    """
    normalised = validate_scenarios(scenarios)
    if n_workers is not None and n_workers < 1:
        raise InputError(f"n_workers must be at least 1, not {n_workers}")
    if isinstance(task, str):
        resolve_task(task)  # fail early, here, on a typo
    elif not callable(task):
        raise InputError(f"task must be a function or 'module:function', not {task!r}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)

    study = _Study(normalised, out_dir, tuple(outputs))
    pending = study.load_finished()
    study.write()
    if len(pending) < len(scenarios):
        logger.info(
            "resuming: %d of %d scenarios already complete",
            len(scenarios) - len(pending),
            len(scenarios),
        )

    bar = tqdm(
        total=len(scenarios),
        initial=len(scenarios) - len(pending),
        unit="scenario",
        desc=f"study {out_dir.name}",
        disable=not progress or not pending or not sys.stderr.isatty(),
    )
    try:
        if not pending:
            pass
        elif scheduler == SERIAL:
            for i in pending:
                outcome = execute(task, dict(scenarios[i]), str(study.scenario_dir(i)))
                _finish(study, bar, i, outcome)
        else:
            if cost is not None:  # the longest first
                pending = sorted(pending, key=lambda i: -float(cost(scenarios[i])))
            _run_distributed(study, bar, pending, scenarios, task, scheduler, n_workers)
    finally:
        bar.close()
        study.write()
    return [row if row is not None else {} for row in study.results]


def _finish(study: _Study, bar: Any, i: int, outcome: dict[str, Any]) -> None:
    study.record(i, outcome)
    study.write()
    bar.update(1)
    n_failed = study.status.count("failed")
    if n_failed:
        bar.set_postfix(failed=n_failed)
    logger.info("study %s: %d of %d scenarios finished (%d failed)", study.out_dir.name,
                len(study.status) - study.status.count("pending"), len(study.status), n_failed)


def _run_distributed(
    study: _Study,
    bar: Any,
    pending: list[int],
    scenarios: list[dict[str, Any]],
    task: Task,
    scheduler: str | None,
    n_workers: int | None,
) -> None:
    """Submit the pending scenarios to a Dask cluster and record them as they finish."""
    from distributed import Client, as_completed

    with contextlib.ExitStack() as stack:
        if scheduler is None:
            address = stack.enter_context(local_cluster(min(n_workers or 2, len(pending))))
            client = stack.enter_context(Client(address, set_as_default=False))
        else:
            try:
                client = stack.enter_context(
                    Client(scheduler, set_as_default=False, timeout=CONNECT_TIMEOUT))
            except (OSError, ValueError) as exc:
                raise InputError(
                    f"cannot connect to Dask scheduler {scheduler}: {one_line(exc)}"
                ) from exc

        index: dict[Any, int] = {}
        futures = []
        for rank, i in enumerate(pending):  # in this order: Dask's priority, higher first
            future = client.submit(
                execute_on_worker,
                task,
                dict(scenarios[i]),
                str(study.scenario_dir(i)),
                key=f"scenario-{study.scenarios[i]['name']}-{uuid.uuid4().hex[:8]}",
                pure=False,
                priority=len(pending) - rank,
            )
            index[future.key] = i
            futures.append(future)
        for future in as_completed(futures, loop=client.loop):
            i = index[future.key]
            try:
                outcome = future.result()
            except Exception as exc:  # noqa: BLE001 - e.g. KilledWorker: the worker died
                outcome = {
                    "ok": False,
                    "error": one_line(exc),
                    "traceback": "".join(traceback.format_exception(exc)),
                }
            future.release()
            _finish(study, bar, i, outcome)
