"""The study runner: order, resume, failure isolation, name checks; serially and on a real
two-worker LocalCluster."""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import pytest
from distributed import Client

import _study_tasks as tasks
import brainbulge
from brainbulge.errors import InputError
from brainbulge.studies.runner import (
    local_cluster,
    run_study,
    shared_scheduler,
    worker_env,
)

TASK = tasks.counting_task


def _scenarios(n: int, **extra: object) -> list[dict]:
    return [{"name": f"s{i:02d}", "x": i, **extra} for i in range(n)]


def _read(path: Path) -> dict:
    return json.loads(path.read_text())


def test_serial_results_in_input_order_with_files(tmp_path: Path) -> None:
    scenarios = _scenarios(5)[::-1]  # not in sorted order
    rows = run_study(scenarios, TASK, tmp_path, scheduler="serial", progress=False)

    assert [r["name"] for r in rows] == [s["name"] for s in scenarios]
    assert [r["square"] for r in rows] == [s["x"] ** 2 for s in scenarios]
    assert all(r["complete"] is True for r in rows)
    for row in rows:
        folder = tmp_path / row["name"]
        assert _read(folder / "summary.json") == row
        assert _read(folder / "result.json") == {"square": row["square"]}
        assert not (folder / "error.json").exists()
        assert tasks.calls(folder) == 1
        assert row["pid"] == os.getpid()  # serial means in this process
    study = _read(tmp_path / "study.json")
    assert [e["name"] for e in study["scenarios"]] == [s["name"] for s in scenarios]
    assert {e["status"] for e in study["scenarios"]} == {"complete"}
    assert study["scenarios"][0]["scenario"] == scenarios[0]
    assert (study["n_complete"], study["n_failed"], study["n_pending"]) == (5, 0, 0)
    assert not list(tmp_path.rglob("*.tmp"))  # atomic writes leave no temporaries


def test_resume_skips_finished_scenarios(tmp_path: Path) -> None:
    first = run_study(_scenarios(3), TASK, tmp_path, scheduler="serial", progress=False)
    second = run_study(_scenarios(4), TASK, tmp_path, scheduler="serial", progress=False)

    assert second[:3] == first  # loaded from summary.json, identical
    assert second[3]["square"] == 9
    assert [tasks.calls(tmp_path / f"s{i:02d}") for i in range(4)] == [1, 1, 1, 1]
    study = _read(tmp_path / "study.json")
    assert [e.get("resumed", False) for e in study["scenarios"]] == [True, True, True, False]


def test_changed_scenario_is_recomputed(tmp_path: Path) -> None:
    run_study(_scenarios(2), TASK, tmp_path, scheduler="serial", progress=False)
    changed = _scenarios(2)
    changed[1]["x"] = 7
    rows = run_study(changed, TASK, tmp_path, scheduler="serial", progress=False)
    assert [r["square"] for r in rows] == [0, 49]
    assert [tasks.calls(tmp_path / n) for n in ("s00", "s01")] == [1, 2]


def test_failure_is_recorded_and_the_others_complete(tmp_path: Path) -> None:
    scenarios = _scenarios(4)
    scenarios[1]["fail"] = True
    rows = run_study(scenarios, TASK, tmp_path, scheduler="serial", progress=False)

    assert [r["complete"] for r in rows] == [True, False, True, True]
    assert rows[1] == {
        "name": "s01",
        "complete": False,
        "error": "RuntimeError: boom in s01 second line of the message",
    }
    error = _read(tmp_path / "s01" / "error.json")
    assert error["error"] == rows[1]["error"] and error["complete"] is False
    assert "Traceback" in error["traceback"]
    assert not (tmp_path / "s01" / "summary.json").exists()
    study = _read(tmp_path / "study.json")
    assert study["scenarios"][1]["status"] == "failed"
    assert study["scenarios"][1]["error"] == rows[1]["error"]

    # Rerun with the cause fixed: only the failed scenario runs again, its error is gone.
    scenarios[1]["fail"] = False
    rows = run_study(scenarios, TASK, tmp_path, scheduler="serial", progress=False)
    assert all(r["complete"] for r in rows)
    assert [tasks.calls(tmp_path / s["name"]) for s in scenarios] == [1, 2, 1, 1]
    assert not (tmp_path / "s01" / "error.json").exists()


@pytest.mark.parametrize(
    ("task", "message"),
    [
        (tasks.non_json_task, "TypeError: object is not JSON serialisable"),
        (tasks.not_a_dict_task, "TypeError: task returned list, not a dict summary"),
    ],
)
def test_bad_summaries_are_failures(tmp_path: Path, task, message: str) -> None:
    (row,) = run_study([{"name": "a"}], task, tmp_path, scheduler="serial", progress=False)
    assert row == {"name": "a", "complete": False, "error": message}


@pytest.mark.parametrize(
    "scenarios",
    [
        [{"name": "a/b"}],
        [{"name": ".."}],
        [{"name": ".hidden"}],
        [{"name": "has space"}],
        [{"name": ""}],
        [{"name": "x" * 101}],
        [{"name": "study.json"}],
        [{"name": "ok"}, {"name": "OK"}],  # clash on case-insensitive filesystems
        [{"x": 1}],
        [{"name": 3}],
        ["s1"],
        {"name": "a"},
        [{"name": "a", "obj": object()}],
    ],
)
def test_bad_scenarios_are_rejected_before_anything_runs(tmp_path: Path, scenarios) -> None:
    out = tmp_path / "study"
    with pytest.raises(InputError):
        run_study(scenarios, TASK, out, scheduler="serial", progress=False)
    assert not out.exists()


def test_task_by_module_path_and_progress_bar(tmp_path: Path, capsys, monkeypatch) -> None:
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)  # a terminal: a bar
    rows = run_study(
        [{"name": "a", "p": Path("/x"), "t": (1, 2)}],
        "brainbulge.studies.runner:echo_task",
        tmp_path,
        scheduler="serial",
    )
    assert rows == [{"name": "a", "p": "/x", "t": [1, 2], "complete": True}]
    assert "1/1" in capsys.readouterr().err
    monkeypatch.setattr(sys.stderr, "isatty", lambda: False, raising=False)  # a log: no bar
    run_study([{"name": "b"}], "brainbulge.studies.runner:echo_task", tmp_path / "2",
              scheduler="serial")
    assert "\r" not in capsys.readouterr().err
    with pytest.raises(InputError, match="cannot import task"):
        run_study([{"name": "a"}], "brainbulge.studies.runner:nope", tmp_path, scheduler="serial")


def test_local_cluster_two_workers(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # Worker processes import tasks by module name: give them the tests folder and the sources
    # (the package may not be installed) through the environment they inherit.
    src = Path(brainbulge.__file__).resolve().parents[1]
    paths = [str(Path(tasks.__file__).parent), str(src), os.environ.get("PYTHONPATH", "")]
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in paths if p))
    monkeypatch.setenv("OMP_NUM_THREADS", "4")  # the runner must still give workers 1 thread

    scenarios = _scenarios(6, sleep_s=0.3)
    scenarios[2]["fail"] = True
    start = time.perf_counter()
    rows = run_study(scenarios, TASK, tmp_path, n_workers=2, progress=False)
    elapsed = time.perf_counter() - start

    assert [r["name"] for r in rows] == [s["name"] for s in scenarios]
    assert [r["complete"] for r in rows] == [True, True, False, True, True, True]
    assert rows[2]["error"].startswith("RuntimeError: boom in s02")
    done = [r for r in rows if r["complete"]]
    assert [r["square"] for r in done] == [0, 1, 9, 16, 25]
    pids = {r["pid"] for r in done}
    assert os.getpid() not in pids and len(pids) == 2  # two worker processes shared the work
    threads = worker_env(2)["OMP_NUM_THREADS"]  # cores // 2: 1 on 2 cores
    assert all(r["threads"] == {"OMP_NUM_THREADS": threads, "NGS_NUM_THREADS": threads}
               for r in done)
    assert os.environ["OMP_NUM_THREADS"] == "4"  # parent environment restored
    assert elapsed < 30

    # Resume on an existing scheduler (address): everything finished is loaded, only the
    # failed scenario runs again (and fails again); the runner leaves that cluster running.
    with local_cluster(1) as address, Client(address) as client:
        rows2 = run_study(scenarios, TASK, tmp_path, scheduler=address)
        assert len(client.scheduler_info()["workers"]) == 1
    assert rows2 == rows
    assert [tasks.calls(tmp_path / s["name"]) for s in scenarios] == [1, 1, 2, 1, 1, 1]


def test_local_cluster_starts_the_costliest_first(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    src = Path(brainbulge.__file__).resolve().parents[1]
    paths = [str(Path(tasks.__file__).parent), str(src), os.environ.get("PYTHONPATH", "")]
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in paths if p))
    scenarios = _scenarios(5, sleep_s=0.05)
    cost = {0: 2.0, 1: 0.5, 2: 9.0, 3: 1.0, 4: 3.0}
    rows = run_study(scenarios, TASK, tmp_path, n_workers=1, progress=False,
                     cost=lambda sc: cost[sc["x"]])

    assert [r["name"] for r in rows] == [s["name"] for s in scenarios]  # the input order
    started = sorted(rows, key=lambda r: r["started"])
    assert [r["square"] for r in started] == [4, 16, 0, 9, 1]  # x = 2, 4, 0, 3, 1


def test_studies_in_a_row_share_one_set_of_workers(tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """``shared_scheduler(None)`` starts one local cluster for several studies (the demo's
    three); a given scheduler ("serial" here) is passed through unchanged."""
    src = Path(brainbulge.__file__).resolve().parents[1]
    paths = [str(Path(tasks.__file__).parent), str(src), os.environ.get("PYTHONPATH", "")]
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in paths if p))
    with shared_scheduler(None, 2) as scheduler:
        assert scheduler.startswith("tcp://")
        first = run_study(_scenarios(4, sleep_s=0.2), TASK, tmp_path / "a", scheduler=scheduler,
                          progress=False)
        second = run_study(_scenarios(4, sleep_s=0.2), TASK, tmp_path / "b",
                           scheduler=scheduler, progress=False)
    pids = {r["pid"] for r in first}
    assert len(pids) == 2 and {r["pid"] for r in second} == pids
    with shared_scheduler("serial") as scheduler:
        assert scheduler == "serial"


def test_workers_share_the_cores() -> None:
    """cores // workers threads each, at least one, in every thread-count variable."""
    assert set(worker_env(2, cores=2).values()) == {"1"}
    assert set(worker_env(1, cores=2).values()) == {"2"}
    assert set(worker_env(3, cores=8).values()) == {"2"}
    assert set(worker_env(4, cores=2).values()) == {"1"}
    assert set(worker_env(1, cores=2)) >= {"OMP_NUM_THREADS", "MKL_NUM_THREADS",
                                           "NGS_NUM_THREADS", "NUMBA_NUM_THREADS"}


def test_a_worker_logs_each_scenario_into_its_folder(tmp_path: Path) -> None:
    """On a worker the package's INFO lines of a scenario go to its ``brainbulge.log`` as it
    runs; the logger is left as it was."""
    import logging

    from brainbulge.studies.tasks import execute_on_worker

    log = logging.getLogger("brainbulge")
    handlers, level = list(log.handlers), log.level
    out = execute_on_worker(tasks.logging_task, {"name": "s00"}, str(tmp_path))
    assert out["ok"]
    assert "load 0.5000: 3 Newton iterations (s00)" in (tmp_path / "brainbulge.log").read_text()
    assert log.handlers == handlers and log.level == level


def test_a_3d_study_s_mesh_is_built_on_a_worker_meanwhile(tmp_path: Path,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    """``brain_meshes_meanwhile`` builds the study's shared mesh on the cluster while the
    block runs (here: nothing in this process meshes) and the 3D study then reuses it."""
    from brainbulge.studies.craniectomy import attach_study_meshes, craniectomy_scenarios
    from brainbulge.studies.suites import brain_meshes_meanwhile
    from toy_brain import toy_labels

    src = Path(brainbulge.__file__).resolve().parents[1]
    paths = [str(Path(tasks.__file__).parent), str(src), os.environ.get("PYTHONPATH", "")]
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in paths if p))
    labels = toy_labels(tmp_path / "seg.nii.gz")
    scenarios = craniectomy_scenarios(labels=str(labels), label_map="synthseg", tets=1000)
    out = tmp_path / "brain"
    with shared_scheduler(None, 1) as scheduler, brain_meshes_meanwhile(scheduler, out,
                                                                       scenarios):
        pass
    mesh = out / "mesh" / "brain.npz"
    assert mesh.is_file()
    built = mesh.stat().st_mtime_ns
    attached = attach_study_meshes(out, scenarios)  # found, not built again
    assert attached[0]["mesh"] == str(mesh) and mesh.stat().st_mtime_ns == built
    with brain_meshes_meanwhile("serial", tmp_path / "none", scenarios):
        pass
    assert not (tmp_path / "none").exists()
