"""One scenario as a task: resolving ``package.module:function``, running it in a worker, and
turning what it returns (or raises) into JSON the study runner records."""

from __future__ import annotations

import importlib
import json
import logging
import traceback
from collections.abc import Callable, Mapping
from pathlib import Path, PurePath
from typing import Any

from brainbulge.atomic import note_written
from brainbulge.errors import BrainbulgeError, InputError
from brainbulge.results.records.run_record import atomic_write_json

#: a task: ``f(scenario, scenario_dir) -> summary``, or its import path
Task = Callable[[dict[str, Any], Path], Mapping[str, Any]] | str


def echo_task(scenario: dict[str, Any], scenario_dir: Path) -> dict[str, Any]:
    """Demo task: writes ``echo.json`` with the scenario and returns it as the summary.

    Raises `InputError` if the scenario has ``"fail": true`` (to exercise error handling).
    """
    if scenario.get("fail"):
        raise InputError(f"scenario {scenario['name']} asked to fail")
    atomic_write_json(Path(scenario_dir) / "echo.json", to_json(scenario))
    return dict(scenario)


def json_default(value: Any) -> Any:
    if isinstance(value, PurePath):
        return str(value)
    if isinstance(value, set | frozenset):
        return sorted(value)
    if hasattr(value, "tolist") and callable(value.tolist):  # numpy scalar or array
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def to_json(value: Any) -> Any:
    """``value`` as it reads back from JSON (tuples -> lists, paths -> str, numpy -> lists)."""
    return json.loads(json.dumps(value, default=json_default, allow_nan=True))


def one_line(exc: BaseException, limit: int = 300) -> str:
    """A one-line description of ``exc``: its own message for brainbulge errors (already
    user-facing), ``Type: message`` otherwise."""
    text = " ".join(str(exc).split())
    if not isinstance(exc, BrainbulgeError):
        text = f"{type(exc).__name__}: {text}" if text else type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


def resolve_task(task: Task) -> Callable[[dict[str, Any], Path], Mapping[str, Any]]:
    if callable(task):
        return task
    module_name, sep, attr = str(task).partition(":")
    if not sep:
        module_name, _, attr = str(task).rpartition(".")
    if not module_name or not attr:
        raise InputError(f"task {task!r} must be 'package.module:function'")
    try:
        func = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as exc:
        raise InputError(f"cannot import task {task!r}: {exc}") from exc
    if not callable(func):
        raise InputError(f"task {task!r} is not callable")
    return func


def execute(task: Task, scenario: dict[str, Any], scenario_dir: str) -> dict[str, Any]:
    """Run one scenario (on a worker); never raises for errors of ``task`` itself.

    Returns ``{"ok": True, "summary": {...}}`` or ``{"ok": False, "error", "traceback"}``; the
    summary is checked to be a JSON-able mapping here, where the failure belongs.
    """
    try:
        func = resolve_task(task)
        summary = func(dict(scenario), Path(scenario_dir))
        if not isinstance(summary, Mapping):
            raise TypeError(f"task returned {type(summary).__name__}, not a dict summary")
        return {"ok": True, "summary": to_json(dict(summary))}
    except Exception as exc:  # noqa: BLE001 - recorded, the study goes on
        return {"ok": False, "error": one_line(exc), "traceback": traceback.format_exc()}


#: each scenario's own log on a cluster (INFO and above), next to its results
SCENARIO_LOG = "brainbulge.log"


def execute_on_worker(task: Task, scenario: dict[str, Any], scenario_dir: str) -> dict[str, Any]:
    """`execute` in a worker process, after the process-wide tuning of a run
    (:func:`brainbulge.runtime.configure`: the heap is per process), logging the scenario's
    progress (load steps, Newton, warnings) to ``scenario_dir/brainbulge.log`` as it runs."""
    from brainbulge.runtime import configure

    configure()
    log = logging.getLogger("brainbulge")
    level = log.level
    try:
        handler = logging.FileHandler(Path(scenario_dir) / SCENARIO_LOG)
    except OSError:  # no log file is no reason to lose the scenario
        return execute(task, scenario, scenario_dir)
    note_written(Path(scenario_dir) / SCENARIO_LOG, tracked=False)  # it grows as it runs
    handler.setLevel(logging.INFO)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(message)s"))
    log.addHandler(handler)
    log.setLevel(logging.INFO if level in (logging.NOTSET, 0) else min(level, logging.INFO))
    try:
        return execute(task, scenario, scenario_dir)
    finally:
        log.removeHandler(handler)
        handler.close()
        log.setLevel(level)
