"""Top-level study tasks for tests/test_runner.py, importable by Dask worker processes.

Workers do not inherit pytest's ``sys.path``; the cluster test puts this folder on the workers'
``PYTHONPATH``.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any


def counting_task(scenario: dict[str, Any], scenario_dir: Path) -> dict[str, Any]:
    """Appends one line to ``<scenario_dir>/calls.txt`` per call (counts executions), writes a
    result file, fails when ``scenario["fail"]`` and sleeps ``scenario["sleep_s"]``."""
    started = time.time()
    with open(scenario_dir / "calls.txt", "a", encoding="utf-8") as fh:
        fh.write(f"{os.getpid()}\n")
    time.sleep(scenario.get("sleep_s", 0.0))
    if scenario.get("fail"):
        raise RuntimeError(f"boom in {scenario['name']}\nsecond line of the message")
    x = scenario["x"]
    (scenario_dir / "result.json").write_text(json.dumps({"square": x * x}))
    threads = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "NGS_NUM_THREADS")}
    return {"square": x * x, "pid": os.getpid(), "threads": threads, "started": started}


def non_json_task(scenario: dict[str, Any], scenario_dir: Path) -> dict[str, Any]:
    """Returns a summary that is not JSON-serialisable."""
    return {"value": object()}


def not_a_dict_task(scenario: dict[str, Any], scenario_dir: Path) -> list[int]:
    """Returns a list instead of a summary dict."""
    return [1, 2, 3]


def calls(scenario_dir: Path) -> int:
    """How many times ``counting_task`` ran in ``scenario_dir``."""
    path = Path(scenario_dir) / "calls.txt"
    return len(path.read_text().splitlines()) if path.exists() else 0


def logging_task(scenario: dict[str, Any], scenario_dir: Path) -> dict[str, Any]:
    """Logs one INFO line on the package's logger, as a solver's load steps do."""
    import logging

    logging.getLogger("brainbulge").info("load 0.5000: 3 Newton iterations (%s)", scenario["name"])
    return {"logged": True}
