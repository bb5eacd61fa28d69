"""A batch job's life: a real study killed at a random point by SIGKILL (out of memory, the
time limit's last word), SIGTERM (the time limit) or SIGUSR1 (SLURM's ``--signal``), then
resumed by the same command, ends with the summaries of an uninterrupted run.

Heavy (four small studies, real solves: about 5 minutes on 2 cores): ``pytest -m slow``.
"""

from __future__ import annotations

import json
import math
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
STUDY = ["study", "hemidisk-sector", "--alphas", "20", "40", "--betas", "30",
         "--mesh-size", "0.2", "--steps", "2", "--scheduler", "serial"]
#: keys of a summary that measure the run, not the solution
TIMINGS = ("wall_time_s", "assembly_time_s", "linear_solve_time_s")


def _run(out: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "brainbulge", *STUDY, "--out", str(out)],
                            env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)


def _summaries(out: Path) -> dict[str, dict]:
    found = {}
    for path in sorted(out.glob("*/summary.json")):
        data = json.loads(path.read_text())
        found[path.parent.name] = {k: v for k, v in data.items()
                                   if k not in TIMINGS and k != "resumed_from_load"}
    return found


def _close(a, b, rel: float = 1e-6) -> bool:
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k], rel) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_close(x, y, rel) for x, y in zip(a, b, strict=True))
    if isinstance(a, float | int) and isinstance(b, float | int) and not isinstance(a, bool):
        return math.isclose(a, b, rel_tol=rel, abs_tol=1e-12)
    return a == b


@pytest.mark.slow
def test_a_study_killed_at_random_and_resumed_ends_as_an_uninterrupted_one(tmp_path) -> None:
    started = time.monotonic()
    whole = _run(tmp_path / "whole")
    assert whole.wait(900) == 0, whole.stderr.read()
    took = time.monotonic() - started
    reference = _summaries(tmp_path / "whole")
    assert len(reference) == 4

    rng = random.Random(70)
    for signum in (signal.SIGKILL, signal.SIGTERM, signal.SIGUSR1):
        out = tmp_path / signum.name
        run = _run(out)
        at = rng.uniform(0.15, 0.85) * took
        try:
            run.wait(at)
        except subprocess.TimeoutExpired:
            os.kill(run.pid, signum)
        code = run.wait(120)
        status = json.loads((out / "status.json").read_text())["status"]
        done = len(_summaries(out))
        print(f"{signum.name} at {at:.1f} s of {took:.1f} s: exit {code}, {done} of 4 "
              "scenarios finished before the resume")
        if signum == signal.SIGKILL:
            assert code == -signal.SIGKILL and status == "running"  # the lock is stale
        else:  # stopped as a batch system asks: a true status, no lock
            assert code == 130, run.stderr.read()
            assert status == "incomplete" and not (out / ".brainbulge.lock").exists()
        again = _run(out)
        assert again.wait(900) == 0, again.stderr.read()
        assert json.loads((out / "status.json").read_text())["status"] == "complete"
        assert _close(_summaries(out), reference), (signum.name, at)
