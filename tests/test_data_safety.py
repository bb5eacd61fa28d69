"""Nothing lost, nothing hidden: locks, manifests, disk full, signals, restart files.

The runs here are fakes of ``run_hemidisk`` (no solve) so that each test takes well under a
second, except the two that start a second Python process.
"""

from __future__ import annotations

import errno
import json
import logging
import os
import signal
import socket
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import brainbulge.studies.hemidisk as hd
from brainbulge.atomic import JOURNAL, atomic_output, atomic_write_text, note_written
from brainbulge.cli import main
from brainbulge.errors import InputError
from brainbulge.results.records.output_folder import LOCK_FILE, claim_output_dir, read_manifest
from brainbulge.results.records.run_record import atomic_write_json
from fake_results import SUMMARY, one_line

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
FAST = ["hemidisk", "--mesh-size", "0.3", "--steps", "1"]


def fake_run(files: dict[str, bytes], error: BaseException | None = None):
    """A stand-in for ``run_hemidisk``: writes ``files``, then raises ``error`` or returns."""

    def run(case, out, progress=False):
        for name, data in files.items():
            (Path(out) / name).parent.mkdir(parents=True, exist_ok=True)
            if data:  # as brainbulge writes: atomically, and so into the manifest
                with atomic_output(Path(out) / name) as tmp:
                    tmp.write_bytes(data)
            else:  # what a full disk leaves
                (Path(out) / name).write_bytes(data)
                note_written(Path(out) / name)
        if error is not None:
            raise error
        return SUMMARY

    return run


def status(out: Path) -> dict:
    return json.loads((out / "status.json").read_text())



# --------------------------------------------------------------------------- manifest


def test_the_manifest_lists_what_a_run_wrote_and_overwrite_deletes_only_that(
        tmp_path, monkeypatch, capsys) -> None:
    out = tmp_path / "out"
    monkeypatch.setattr(hd, "run_hemidisk", fake_run({"fields.vtu": b"v", "sub/a.npz": b"a"}))
    assert main([*FAST, "--out", str(out)]) == 0
    assert set(read_manifest(out)) == {"run.json", "run.toml", "status.json", "brainbulge.log",
                                       "fields.vtu", "sub/a.npz"}
    assert not (out / LOCK_FILE).exists() and status(out)["status"] == "complete"

    (out / "sub" / "mine.txt").write_text("a user's file")  # refused, nothing deleted
    before = sorted(p.name for p in out.rglob("*"))
    assert main([*FAST, "--out", str(out), "--overwrite"]) == 2
    assert "sub/mine.txt" in one_line(capsys)
    assert sorted(p.name for p in out.rglob("*")) == before

    (out / "sub" / "mine.txt").unlink()
    monkeypatch.setattr(hd, "run_hemidisk", fake_run({"other.vtu": b"o"}))
    assert main([*FAST, "--out", str(out), "--overwrite"]) == 0
    assert not (out / "fields.vtu").exists() and not (out / "sub").exists()
    assert "other.vtu" in read_manifest(out)


def test_overwrite_never_clears_the_current_folder_or_an_ancestor(tmp_path, monkeypatch,
                                                                  capsys) -> None:
    project = tmp_path / "project"
    (project / "data").mkdir(parents=True)
    (project / "run.toml").write_text("command = 'hemidisk'\n[hemidisk]\n")
    (project / "data" / "scan.nii").write_bytes(b"MRI")
    monkeypatch.chdir(project / "data")
    for out in (".", "..", str(tmp_path)):
        assert main(["run", str(project / "run.toml"), "--out", out, "--overwrite"]) == 2
        assert "current folder" in one_line(capsys)
    assert (project / "data" / "scan.nii").read_bytes() == b"MRI"


def test_results_are_readable_as_the_umask_allows(tmp_path) -> None:
    old = os.umask(0o027)
    try:
        path = atomic_write_json(tmp_path / "a.json", {"x": 1})
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o640
    path = atomic_write_json(tmp_path / "b.json", {"x": 1})
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~old


# --------------------------------------------------------------------------- lock


HOLD = ("import sys, time\n"
        "from brainbulge.results.records.output_folder import claim_output_dir\n"
        "claim_output_dir(sys.argv[1], overwrite=False)\n"
        "print('locked', flush=True)\n"
        "time.sleep(120)\n")


def test_a_second_process_is_refused_and_a_dead_ones_lock_is_stale(tmp_path, capsys,
                                                                   caplog) -> None:
    out = tmp_path / "out"
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(out)], env=ENV,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        assert main([*FAST, "--out", str(out)]) == 2
        line = one_line(capsys)
        assert "in use by another brainbulge run" in line and str(holder.pid) in line
        assert sorted(p.name for p in out.iterdir()) == [JOURNAL, LOCK_FILE]  # no status
    finally:
        holder.kill()
        holder.wait()
    with caplog.at_level(logging.WARNING):
        folder = claim_output_dir(out, overwrite=False)  # the holder is gone: stale
    assert "stale lock" in caplog.text
    assert json.loads((out / LOCK_FILE).read_text())["pid"] == os.getpid()
    folder.release()
    assert not (out / LOCK_FILE).exists()


def test_a_lock_of_another_host_is_respected(tmp_path) -> None:
    (tmp_path / LOCK_FILE).write_text(json.dumps(
        {"pid": 1, "host": socket.gethostname() + "-elsewhere", "started": time.time()}))
    with pytest.raises(InputError, match="in use"):
        claim_output_dir(tmp_path, overwrite=False)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    (tmp_path / LOCK_FILE).write_text(json.dumps(
        {"pid": int(dead), "host": socket.gethostname(), "started": time.time() - 5}))
    claim_output_dir(tmp_path, overwrite=False).release()


# --------------------------------------------------------------------------- failures


@pytest.mark.parametrize("code,words", [(errno.ENOSPC, "no space left on device"),
                                        (errno.EROFS, "read-only file system")])
def test_disk_full_or_read_only_is_one_line_and_a_true_status(tmp_path, monkeypatch, capsys,
                                                              code, words) -> None:
    out = tmp_path / "out"
    error = OSError(code, os.strerror(code), str(out / "fields.vtu"))
    monkeypatch.setattr(hd, "run_hemidisk",
                        fake_run({"fields.png": b"png", "fields.vtu": b""}, error))
    assert main([*FAST, "--out", str(out)]) == 2
    line = one_line(capsys)
    assert line.startswith(f"error: cannot write {out / 'fields.vtu'}: {words}")
    assert ("free some space" if code == errno.ENOSPC else "writable --out") in line
    assert status(out)["status"] == "failed" and words in status(out)["message"]
    assert (out / "fields.png").read_bytes() == b"png"  # results so far kept
    assert (out / "fields.vtu").exists() == (code != errno.ENOSPC)  # no empty leftovers
    assert not (out / LOCK_FILE).exists()


def test_an_unexpected_exit_still_leaves_a_true_status(tmp_path, monkeypatch) -> None:
    out = tmp_path / "out"
    monkeypatch.setattr(hd, "run_hemidisk", fake_run({"fields.vtu": b"v"}, SystemExit(3)))
    with pytest.raises(SystemExit):
        main([*FAST, "--out", str(out)])
    assert status(out)["status"] == "failed" and not (out / LOCK_FILE).exists()


def test_an_interruption_says_truthfully_what_is_kept(tmp_path, monkeypatch, capsys) -> None:
    out = tmp_path / "out"
    monkeypatch.setattr(hd, "run_hemidisk", fake_run({}, KeyboardInterrupt()))
    assert main([*FAST, "--out", str(out)]) == 130
    assert "before any results were written" in one_line(capsys)
    assert status(out)["status"] == "incomplete"
    # a study's bookkeeping (scenario records, logs, restart files) is no result either
    monkeypatch.setattr(hd, "run_hemidisk", fake_run(
        {"study.json": b"{}", "a/scenario.json": b"{}", "a/brainbulge.log": b"x",
         "a/restart.npz": b"x"}, KeyboardInterrupt()))
    assert main([*FAST, "--out", str(tmp_path / "o1")]) == 130
    assert "before any results were written" in one_line(capsys)
    monkeypatch.setattr(hd, "run_hemidisk", fake_run({"fields.vtu": b"v"}, KeyboardInterrupt()))
    assert main([*FAST, "--out", str(tmp_path / "o2")]) == 130
    assert "results finished so far are kept" in one_line(capsys)


SLOW = ("import subprocess, sys, time\n"
        "from pathlib import Path\n"
        "import brainbulge.studies.hemidisk as hd\n"
        "from brainbulge.cli import main\n"
        "def slow(case, out, progress=False):\n"
        "    from brainbulge.atomic import atomic_write_text\n"
        "    atomic_write_text(Path(out) / 'fields.png', 'png')\n"
        "    child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(120)'])\n"
        "    (Path(out) / 'child.pid').write_text(str(child.pid))\n"
        "    time.sleep(120)\n"
        "hd.run_hemidisk = slow\n"
        "sys.exit(main(sys.argv[1:]))\n")


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP, signal.SIGUSR1,
                                    signal.SIGUSR2, signal.SIGXCPU])
def test_sigterm_ends_child_processes_and_leaves_a_true_status(tmp_path, signum) -> None:
    import psutil

    out = tmp_path / "out"
    # as from a terminal, also when the tests themselves run under nohup (SIGHUP ignored)
    run = subprocess.Popen([sys.executable, "-c", SLOW, *FAST, "--out", str(out)], env=ENV,
                           stderr=subprocess.PIPE, text=True,
                           preexec_fn=lambda: signal.signal(signal.SIGHUP, signal.SIG_DFL))
    try:
        for _ in range(600):
            if (out / "child.pid").is_file() and (out / "child.pid").read_text():
                break
            time.sleep(0.1)
        child = int((out / "child.pid").read_text())
        assert psutil.pid_exists(child)
        run.send_signal(signum)  # SIGHUP: the terminal closed; SIGUSR1/2, SIGXCPU: a batch
        # system's warning before its time limit (SLURM's --signal, SGE's soft limit)
        _, err = run.communicate(timeout=60)
    finally:
        run.kill()
    assert run.returncode == 130
    assert err.strip().splitlines() == [f"interrupted: results finished so far are kept in {out}"]
    assert status(out) | {"time": None} == {
        "status": "incomplete", "message": f"stopped by {signal.Signals(signum).name}",
        "time": None}
    assert not psutil.pid_exists(child) or psutil.Process(child).status() == "zombie"
    assert not (out / LOCK_FILE).exists() and "fields.png" in read_manifest(out)


DROPPED = ("import os, signal, sys, time, weakref\n"
           "import brainbulge.studies.hemidisk as hd\n"
           "from brainbulge.cli import main\n"
           "class Thing: pass\n"
           "def finaliser(ref):\n"
           "    os.kill(os.getpid(), signal.SIGTERM)\n"
           "    for _ in range(10000): pass  # the handler runs here, inside the callback\n"
           "def slow(case, out, progress=False):\n"
           "    thing = Thing()\n"
           "    ref = weakref.ref(thing, finaliser)\n"
           "    del thing\n"
           "    time.sleep(120)\n"
           "hd.run_hemidisk = slow\n"
           "sys.exit(main(sys.argv[1:]))\n")


def test_a_stop_that_lands_in_a_finaliser_still_stops_the_run(tmp_path) -> None:
    """Python drops an exception raised inside a finaliser (a weakref callback, ``__del__``):
    a signal that arrives there must still end the run, in one line."""
    out = tmp_path / "out"
    run = subprocess.Popen([sys.executable, "-c", DROPPED, *FAST, "--out", str(out)], env=ENV,
                           stderr=subprocess.PIPE, text=True)
    try:
        _, err = run.communicate(timeout=60)
    finally:
        run.kill()
    assert run.returncode == 130, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("interrupted: "), err
    assert status(out)["message"] == "stopped by SIGTERM"


QUICK = ("import sys\n"
         "import brainbulge.studies.hemidisk as hd\n"
         "from brainbulge.cli import main\n"
         "hd.run_hemidisk = lambda case, out, progress=False: " + repr(SUMMARY) + "\n"
         "sys.exit(main(sys.argv[1:]))\n")


def test_nohup_keeps_a_run_going_when_the_terminal_closes(tmp_path) -> None:
    out = tmp_path / "out"
    run = subprocess.Popen([sys.executable, "-c", SLOW, *FAST, "--out", str(out)], env=ENV,
                           stderr=subprocess.PIPE, text=True,
                           preexec_fn=lambda: signal.signal(signal.SIGHUP, signal.SIG_IGN))
    try:
        for _ in range(600):
            if (out / "child.pid").is_file() and (out / "child.pid").read_text():
                break
            time.sleep(0.1)
        run.send_signal(signal.SIGHUP)  # ignored, as under nohup
        time.sleep(1.0)
        assert run.poll() is None and status(out)["status"] == "running"
    finally:
        run.terminate()
        run.communicate(timeout=60)


def test_a_closed_pipe_or_a_full_stdout_does_not_fail_a_run(tmp_path) -> None:
    out = tmp_path / "out"
    run = subprocess.Popen([sys.executable, "-c", QUICK, *FAST, "--out", str(out)], env=ENV,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    run.stdout.close()  # `| head -0`: nobody reads what it prints
    _, err = run.communicate(timeout=120)
    assert run.returncode == 0 and err == b""
    assert status(out)["status"] == "complete"
    with open("/dev/full", "w") as full:  # `> /dev/full`
        done = subprocess.run([sys.executable, "-c", QUICK, *FAST, "--out", str(out),
                               "--overwrite"], env=ENV, stdout=full, stderr=subprocess.PIPE,
                              timeout=120)
    assert done.returncode == 0 and done.stderr == b""
    assert status(out)["status"] == "complete"


def test_a_failure_with_no_inode_left_still_marks_the_run_failed(tmp_path, monkeypatch,
                                                                 capsys) -> None:
    import tempfile

    out = tmp_path / "out"

    def no_inodes(case, out, progress=False):
        def refuse(*args, **kwargs):  # every new file fails from now on
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        monkeypatch.setattr(tempfile, "mkstemp", refuse)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(Path(out) / "fields.vtu"))

    monkeypatch.setattr(hd, "run_hemidisk", no_inodes)
    assert main([*FAST, "--out", str(out)]) == 2
    assert "free some space" in one_line(capsys)
    assert status(out)["status"] == "failed" and "no space left" in status(out)["message"]
    assert not (out / LOCK_FILE).exists()


NETGEN = ("import sys, time\n"
          "from pathlib import Path\n"
          "import brainbulge.geometry.brain.tetmesh as tm\n"
          "def stuck(*args):\n"
          "    Path(sys.argv[1]).write_text('meshing')\n"
          "    time.sleep(120)\n"
          "tm._netgen_tets_here = stuck\n"
          "tm._netgen_tets(None, 1.0, 1, 1)\n")


def test_the_meshing_child_ends_with_its_parent_however_it_ends(tmp_path) -> None:
    import psutil

    flag = tmp_path / "meshing"
    parent = subprocess.Popen([sys.executable, "-c", NETGEN, str(flag)], env=ENV)
    try:
        for _ in range(600):
            if flag.exists():
                break
            time.sleep(0.1)
        children = psutil.Process(parent.pid).children()
        assert len(children) == 1
        parent.kill()  # SIGKILL: no handler of the parent runs
        parent.wait(timeout=30)
        gone, alive = psutil.wait_procs(children, timeout=30)
    finally:
        parent.kill()
    assert not alive


def test_a_server_that_is_not_dask_is_refused_in_one_line(tmp_path, monkeypatch,
                                                          capsys) -> None:
    import http.server
    import threading

    from brainbulge.cli import checks

    monkeypatch.setattr(checks, "SCHEDULER_PROBE_S", 1.0)
    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args) -> None:  # the server's log is not brainbulge's
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        address = f"tcp://127.0.0.1:{server.server_address[1]}"
        assert main(["study", "hemidisk-disk", "--scheduler", address,
                     "--out", str(tmp_path / "out")]) == 2
    finally:
        server.shutdown()
        server.server_close()
    line = one_line(capsys)
    assert address in line and "not a Dask scheduler" in line
    assert not (tmp_path / "out").exists()


CLUSTER = ("import sys\n"
           "import brainbulge.studies.suites as suites\n"
           "from brainbulge.cli import main\n"
           "from brainbulge.studies.runner import run_study\n"
           "def study(name, scenarios, out, scheduler, workers=None):\n"
           "    scenarios = [{**sc, 'x': 1, 'sleep_s': 120} for sc in scenarios]\n"
           "    rows = run_study(scenarios, '_study_tasks:counting_task', out, scheduler)\n"
           "    return sum(1 for r in rows if r.get('complete'))\n"
           "suites.run_named_study = study\n"
           "if __name__ == '__main__':\n"
           "    sys.exit(main(sys.argv[1:]))\n")


@pytest.mark.slow
def test_ctrl_c_on_a_study_is_one_line_without_the_workers_tracebacks(tmp_path) -> None:
    """Ctrl-C in a terminal reaches every process of the job: the workers must leave it to
    the command, which ends them."""
    script = tmp_path / "study_cli.py"
    script.write_text(CLUSTER)
    out = tmp_path / "out"
    env = {**ENV, "PYTHONPATH": f"{ROOT / 'src'}{os.pathsep}{ROOT / 'tests'}"}
    run = subprocess.Popen([sys.executable, str(script), "study", "hemidisk-disk", "--workers",
                            "2", "--out", str(out)], env=env, stderr=subprocess.PIPE,
                           text=True, start_new_session=True,
                           preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        for _ in range(1200):  # until both workers run a scenario
            if len(list(out.glob("disk_*/calls.txt"))) >= 2:
                break
            time.sleep(0.1)
        os.killpg(run.pid, signal.SIGINT)  # as the terminal sends it
        _, err = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            os.killpg(run.pid, signal.SIGKILL)
    assert run.returncode == 130
    assert err.strip().splitlines() == [
        f"interrupted: stopped before any results were written; {out} holds the run record "
        "only; rerun the same command to resume"]
    assert status(out)["status"] == "incomplete"


def test_a_truncated_restart_file_is_skipped_with_a_warning(tmp_path, caplog) -> None:
    from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem
    from brainbulge.solver import MixedForm, Solution, restart

    path = tmp_path / "restart.npz"
    np.savez(path, key="k", ndof=3, x=np.arange(1000.0))
    path.write_bytes(path.read_bytes()[:300])
    form = MixedForm(hemidisk_problem(HemidiskCase(mesh_size=0.3, skull_edge_radius=0.0)))
    with caplog.at_level(logging.WARNING):
        assert restart.read(path, "k", form, Solution(form, 0.0, False)) is None
    assert "unreadable" in caplog.text
    np.savez(path, a=np.arange(3))  # a foreign npz: the same
    assert restart.read(path, "k", form, Solution(form, 0.0, False)) is None


# --------------------------------------------------------------------------- studies


def test_a_study_folder_of_other_scenarios_is_refused_unless_overwrite(tmp_path, capsys,
                                                                       monkeypatch) -> None:
    import brainbulge.studies.suites as study

    out = tmp_path / "study"
    calls = []

    def fake(name, scenarios, out, scheduler, workers):
        for sc in scenarios:
            (out / sc["name"]).mkdir(exist_ok=True)
            atomic_write_text(out / sc["name"] / "summary.json", "{}")
        atomic_write_text(out / "study.json", "{}")
        calls.append(name)
        return len(scenarios)

    monkeypatch.setattr(study, "run_named_study", fake)
    argv = ["study", "hemidisk-sector", "--alphas", "20", "--betas", "30", "--out", str(out)]
    assert main(argv) == 0
    assert main(argv) == 0  # the same study resumes
    before = sorted(p.relative_to(out).as_posix() for p in out.rglob("*"))
    assert main(["study", "hemidisk-disk", "--out", str(out)]) == 2
    assert "holds a study of 'hemidisk-sector'" in one_line(capsys)
    assert main([*argv[:3], "40", *argv[4:]]) == 2
    assert "other scenarios (noslip_a20_b30, sliding_a20_b30)" in one_line(capsys)
    assert main([*argv, "--steps", "2"]) == 2
    assert "other options (scenario noslip_a20_b30, scenario sliding_a20_b30)" in one_line(
        capsys)
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*")) == before
    assert main(["study", "hemidisk-disk", "--out", str(out), "--overwrite"]) == 0
    assert not (out / "noslip_a20_b30").exists() and calls[-1] == "hemidisk-disk"


def test_study_progress_is_plain_lines_in_a_log(tmp_path, caplog) -> None:
    from brainbulge.studies.runner import echo_task, run_study

    with caplog.at_level(logging.INFO):
        run_study([{"name": "a"}, {"name": "b"}], echo_task, tmp_path, scheduler="serial")
    assert "2 of 2 scenarios finished (0 failed)" in caplog.text
