"""Nothing outside ``--out`` is touched and nothing waits for good: links, FIFOs and devices
where brainbulge expects its own files and folders, ``--out`` links to nothing, a read-only
``--out``.

The studies here run their scenarios in this process with a stand-in task (the folder, its
record, its checks and the runner are real); each test takes about a second.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import signal
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import brainbulge.studies.hemidisk as hd
import brainbulge.studies.suites as suites
from brainbulge.atomic import atomic_output
from brainbulge.cli import main
from brainbulge.studies.runner import _read_json, _readable, run_study
from fake_results import one_line

STUDY = ["study", "hemidisk-sector", "--alphas", "20", "--betas", "30"]



@contextlib.contextmanager
def deadline(seconds: int) -> Iterator[None]:
    """Fail (TimeoutError) instead of hanging the tests if the block waits for good."""

    def expired(signum, frame):
        raise TimeoutError(f"still waiting after {seconds} s")

    previous = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def tree(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def small_task(scenario: dict, scenario_dir: str) -> dict:
    with atomic_output(Path(scenario_dir) / "fields.npz") as tmp:
        np.savez(tmp, x=np.arange(10.0))
    return {"x": 1.0}


def in_process_study(name, scenarios, out, scheduler, workers=None) -> int:
    rows = run_study(scenarios, small_task, out, scheduler="serial", progress=False,
                     outputs=("fields.npz",))
    return sum(1 for r in rows if r["complete"])


@pytest.fixture
def study(tmp_path, monkeypatch) -> Path:
    """A finished study folder (two scenarios), and a folder of someone else's next to it."""
    monkeypatch.setattr(suites, "run_named_study", in_process_study)
    out = tmp_path / "study"
    assert main([*STUDY, "--out", str(out)]) == 0
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "summary.json").write_text('{"theirs": true}')
    (elsewhere / "error.json").write_text('{"theirs": true}')
    (elsewhere / "notes.log").write_text("their log\n")
    return out


def _scenario(out: Path) -> Path:
    return next(p for p in sorted(out.iterdir()) if p.is_dir())


def _link_scenario(out: Path) -> Path:
    folder = _scenario(out)
    for f in folder.iterdir():
        f.unlink()
    folder.rmdir()
    folder.symlink_to(out.parent / "elsewhere", target_is_directory=True)
    return folder


def _link_log(out: Path) -> Path:
    (out / "brainbulge.log").unlink()
    (out / "brainbulge.log").symlink_to(out.parent / "elsewhere" / "notes.log")
    return out / "brainbulge.log"


def _fifo_fields(out: Path) -> Path:
    fields = _scenario(out) / "fields.npz"
    fields.unlink()
    os.mkfifo(fields)
    return fields


def _device_fields(out: Path) -> Path:
    fields = _scenario(out) / "fields.npz"
    fields.unlink()
    fields.symlink_to("/dev/zero")
    return fields


def _fifo_journal(out: Path) -> Path:
    os.mkfifo(out / ".brainbulge.journal")
    return out / ".brainbulge.journal"


@pytest.mark.parametrize("plant,kind", [
    (_link_scenario, "a symbolic link"), (_link_log, "a symbolic link"),
    (_fifo_fields, "a FIFO"), (_device_fields, "a symbolic link"),
    (_fifo_journal, "a FIFO"),
], ids=["scenario folder -> elsewhere", "log -> elsewhere", "fields.npz FIFO",
        "fields.npz -> /dev/zero", "journal FIFO"])
def test_resume_never_goes_through_a_link_nor_waits_on_a_fifo(study, capsys, plant, kind
                                                             ) -> None:
    elsewhere = study.parent / "elsewhere"
    before = tree(elsewhere)
    planted = plant(study)
    capsys.readouterr()
    with deadline(30):  # a run that waits on the FIFO fails here instead of hanging
        started = time.monotonic()
        code = main([*STUDY, "--out", str(study)])
        took = time.monotonic() - started
    line = one_line(capsys)
    assert code == 2 and took < 10
    assert f"cannot resume in {study}: {planted} is {kind}" in line and "move it away" in line
    assert tree(elsewhere) == before  # nothing outside --out created, changed or deleted
    assert not (study / ".brainbulge.lock").exists()
    assert json.loads((study / "status.json").read_text())["status"] == "complete"
    planted.unlink()  # moved away as the line says: the rerun resumes
    if plant is _link_scenario:
        planted.mkdir()
    assert main([*STUDY, "--out", str(study)]) == 0
    assert tree(elsewhere) == before


def test_files_in_the_runner_are_read_only_when_regular(tmp_path) -> None:
    """Resume through the Python API (no claimed folder): a FIFO, a link to a device and a
    link to a good file are not results, read at once."""
    good = tmp_path / "good.npz"
    np.savez(good, x=np.arange(3.0))
    os.mkfifo(tmp_path / "fifo.npz")
    (tmp_path / "zero.npz").symlink_to("/dev/zero")
    (tmp_path / "link.npz").symlink_to(good)
    (tmp_path / "link.json").symlink_to(tmp_path / "elsewhere.json")
    (tmp_path / "elsewhere.json").write_text('{"theirs": true}')
    os.mkfifo(tmp_path / "fifo.json")
    with deadline(10):
        assert _readable(good)
        for name in ("fifo.npz", "zero.npz", "link.npz", "fifo.json"):
            assert not _readable(tmp_path / name), name
        assert _read_json(tmp_path / "link.json") is None
        assert _read_json(tmp_path / "fifo.json") is None


@pytest.mark.parametrize("target", ["missing", "loop"])
def test_an_out_that_links_to_nothing_is_named(tmp_path, capsys, target) -> None:
    out = tmp_path / "out"
    out.symlink_to(tmp_path / "missing" if target == "missing" else out)
    assert main(["hemidisk", "--out", str(out)]) == 2
    assert f"--out {out} is a symbolic link to nothing" in one_line(capsys)
    assert out.is_symlink() and not (tmp_path / "missing").exists()


@pytest.mark.parametrize("code,where", [(errno.EACCES, "out"), (errno.EROFS, "out"),
                                        (errno.EROFS, "tmp")])
def test_a_read_only_out_is_told_to_choose_a_writable_out(tmp_path, monkeypatch, capsys,
                                                          code, where) -> None:
    out = tmp_path / "out"

    def refused(case, folder, progress=False):  # the folder itself, or a temporary file
        name = str(folder) if where == "out" else "/tmp/tmpXYZ"
        raise OSError(code, os.strerror(code), name)

    monkeypatch.setattr(hd, "run_hemidisk", refused)
    assert main(["hemidisk", "--mesh-size", "0.3", "--steps", "1", "--out", str(out)]) == 2
    line = one_line(capsys)
    assert "choose a writable --out" in line and "readable" not in line


# --------------------------------------------------------------------------- reports

HOSTILE = ('<script>alert(1)</script> <img src=x onerror=alert(2)> '
           '<a href="javascript:alert(3)">x</a> <!-- brainbulge-3d-plan -->')


def _elements(page: str) -> Counter:
    """How many elements of each tag the page has (what a browser would build)."""
    from html.parser import HTMLParser

    found: Counter = Counter()

    class Tags(HTMLParser):
        def handle_starttag(self, tag, attrs):
            found[tag] += 1

    Tags().feed(page)
    return found


def _report(folder: Path, text: str) -> str:
    from brainbulge.results.present.html_report import block_marker, markdown_html

    folder.mkdir()
    md = folder / "report.md"
    md.write_text("\n".join([
        f"# Study in {text}", "", f"A note: {text}", "", f"- {text}", "",
        "| scenario | note |", "|---|---|", f"| a | {text} |", "",
        f"[{text}](table.csv)", "", block_marker("plan"), ""]))
    return markdown_html(md, {"plan": "<div class=\"ours\">our block</div>"})


def test_a_report_renders_user_text_as_text(tmp_path) -> None:
    """Headings, paragraphs, lists, table cells and link texts of a report, each holding
    tags and a marker: the page has exactly the elements of the same report with plain text,
    and our own block is still put in."""
    clean = _report(tmp_path / "clean", "plain words")
    hostile = _report(tmp_path / "hostile", HOSTILE)
    assert _elements(hostile) == _elements(clean)
    assert "&lt;script&gt;" in hostile and hostile.count('<div class="ours">') == 1


def test_a_study_report_escapes_error_messages(tmp_path) -> None:
    """A craniectomy study whose scenarios failed with messages holding tags (an error text
    quotes a path or a value the user gave)."""
    from brainbulge.results.present.craniectomy_report import write_report

    pages = {}
    for kind, error in (("clean", "plain words"), ("hostile", HOSTILE)):
        out = tmp_path / kind
        out.mkdir()
        write_report(out, [{"name": "left_flap"}, {"name": "frontal"}],
                     [{"complete": False, "error": f"{error} in {out}"}] * 2)
        pages[kind] = (out / "report.html").read_text()
    assert _elements(pages["hostile"]) == _elements(pages["clean"])
    assert "alert(1)" in pages["hostile"] and "<script>alert" not in pages["hostile"]


# --------------------------------------------------------------------------- schedulers


def test_a_scheduler_without_workers_is_said_at_once_and_refused_after_the_wait(
        tmp_path, monkeypatch, caplog, capsys) -> None:
    import subprocess
    import sys

    from distributed import LocalCluster

    from brainbulge.cli import checks
    from brainbulge.errors import InputError

    monkeypatch.setattr(checks, "SCHEDULER_PROBE_S", 1.0)
    monkeypatch.setattr(checks, "WORKER_POLL_S", 0.2)
    with LocalCluster(n_workers=0, processes=False, protocol="tcp://",
                      dashboard_address=":0") as cluster:
        address = cluster.scheduler_address
        started = time.monotonic()
        with pytest.raises(InputError, match="no workers joined it in 2 s; start workers"):
            checks.scheduler(address, worker_wait=2.0)
        assert time.monotonic() - started < 2.0 + 2 * checks.SCHEDULER_PROBE_S + 1.0
        assert f"no workers at {address}; waiting up to 2 s" in caplog.text
        out = tmp_path / "out"
        assert main([*STUDY, "--scheduler", address, "--worker-wait", "1",
                     "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert "no workers joined it in 1 s" in err[-1] and not out.exists()
        caplog.clear()
        worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker",
                                   address, "--nthreads", "1", "--no-dashboard"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            checks.scheduler(address, worker_wait=120.0)  # returns once the worker joined
        finally:
            worker.terminate()
            worker.wait(30)
        assert "a worker joined" in caplog.text


def test_the_worker_wait_is_an_option_with_a_range(capsys) -> None:
    from brainbulge.cli import build_parser, checks

    with pytest.raises(SystemExit):
        build_parser().parse_args(["study", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert (f"(default {checks.WORKER_WAIT_S:g}; range [{checks.WORKER_WAIT_RANGE[0]:g}, "
            f"{checks.WORKER_WAIT_RANGE[1]:g}])") in text
    assert main([*STUDY, "--worker-wait", "-1", "--out", "x"]) == 2
    assert "--worker-wait" in one_line(capsys)


@pytest.mark.parametrize("argv,words", [
    (["mesh", "--labels", "{fifo}"], "label image {fifo} is not a regular file"),
    (["brain", "--labels", "{fifo}"], "label image {fifo} is not a regular file"),
    (["brain", "--fibres", "{fifo}"], "fibre image {fifo} does not exist or is not a regular"),
    (["mesh", "--labels", "/dev/zero"], "label image /dev/zero is not a regular file"),
    (["run", "{fifo}"], "cannot read config {fifo}: not a regular file"),
    (["brain", "--mesh", "{fifo}"], "no such file"),
])
def test_an_input_that_is_not_a_regular_file_is_refused_at_once(tmp_path, capsys, argv, words
                                                                ) -> None:
    fifo = tmp_path / "input.fifo"
    os.mkfifo(fifo)
    out = tmp_path / "out"
    with deadline(20):
        assert main([*(a.replace("{fifo}", str(fifo)) for a in argv), "--out", str(out)]) == 2
    assert words.replace("{fifo}", str(fifo)) in one_line(capsys)
    assert not out.exists()
