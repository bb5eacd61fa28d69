"""Output folders, run records (run.toml/run.json), status files and config loading."""

from __future__ import annotations

import json
import sys
from datetime import datetime
from enum import Enum
from importlib.metadata import version
from pathlib import Path

import numpy as np
import pytest

import brainbulge
from brainbulge.errors import InputError
from brainbulge.results.records import run_record
from brainbulge.results.records.run_record import (
    load_config,
    mark_status,
    prepare_output_dir,
    write_run_record,
)

# --------------------------------------------------------------------------- output folder


def test_prepare_creates_nested_and_accepts_empty(tmp_path: Path) -> None:
    out = tmp_path / "a" / "b"
    assert prepare_output_dir(out, overwrite=False) == out and out.is_dir()
    assert prepare_output_dir(out, overwrite=False) == out  # empty: fine again


def test_prepare_refuses_non_empty(tmp_path: Path) -> None:
    (tmp_path / "keep.txt").write_text("data")
    with pytest.raises(InputError) as info:
        prepare_output_dir(tmp_path, overwrite=False)
    assert str(info.value) == (
        f"output folder {tmp_path} exists and is not empty; pass --overwrite or choose another"
        " --out"
    )
    assert "\n" not in str(info.value)
    assert (tmp_path / "keep.txt").read_text() == "data"


def test_overwrite_clears_a_previous_run_only(tmp_path: Path) -> None:
    run = tmp_path / "run"
    prepare_output_dir(run, overwrite=False)
    (run / "sub").mkdir()
    (run / "sub" / "old.vtu").write_text("x")
    write_run_record(run, {"a": 1}, ["bb"], files={"sub/old.vtu"})
    assert prepare_output_dir(run, overwrite=True) == run
    assert run.is_dir() and not any(run.iterdir())

    write_run_record(run, {"a": 1}, ["bb"])
    (run / "mine.txt").write_text("a user's")  # not in the manifest: nothing is deleted
    with pytest.raises(InputError, match=r"1 file\(s\) brainbulge did not write or that "
                       r"changed since \(mine.txt\)"):
        prepare_output_dir(run, overwrite=True)
    assert sorted(p.name for p in run.iterdir()) == ["mine.txt", "run.json", "run.toml"]

    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("precious")
    with pytest.raises(InputError, match="refusing to delete"):
        prepare_output_dir(foreign, overwrite=True)
    assert (foreign / "thesis.tex").read_text() == "precious"


def test_resume_needs_a_study(tmp_path: Path) -> None:
    (tmp_path / "s00").mkdir()
    with pytest.raises(InputError, match="no study.json"):
        prepare_output_dir(tmp_path, overwrite=False, resume=True)
    (tmp_path / "study.json").write_text("{}")
    assert prepare_output_dir(tmp_path, overwrite=False, resume=True) == tmp_path
    assert (tmp_path / "s00").is_dir()  # nothing deleted
    new = tmp_path / "new"
    assert prepare_output_dir(new, overwrite=False, resume=True).is_dir()
    with pytest.raises(InputError, match="contradict"):
        prepare_output_dir(tmp_path, overwrite=True, resume=True)


def test_a_stopped_3d_run_folder_can_be_resumed(tmp_path: Path) -> None:
    (tmp_path / "summary.json").write_text("{}")
    with pytest.raises(InputError, match="no study.json or restart.npz"):
        prepare_output_dir(tmp_path, overwrite=False, resume=True)
    (tmp_path / "restart.npz").write_bytes(b"state")
    assert prepare_output_dir(tmp_path, overwrite=False, resume=True) == tmp_path
    assert (tmp_path / "restart.npz").read_bytes() == b"state"  # kept


def test_prepare_refuses_a_file(tmp_path: Path) -> None:
    target = tmp_path / "f"
    target.write_text("")
    with pytest.raises(InputError, match="is a file"):
        prepare_output_dir(target, overwrite=True)


# --------------------------------------------------------------------------- run record


class Side(Enum):
    LEFT = "left"


def test_run_toml_round_trips_the_resolved_config(tmp_path: Path) -> None:
    config = {
        "name": "frontal",
        "seed": None,
        "mesh": {"h_mm": 2.5, "refine": (1, 2), "file": Path("/data/brain.msh"), "skip": None},
        "material": {"mu_kpa": np.float64(1.5), "side": Side.LEFT, "flags": np.array([1, 0])},
        "study": {"random_seed": 42, "thetas": [0.0, 1.5e-3]},
        "swell": [{"region": "white", "theta": 1.1}, {"region": "gray", "theta": 1.05}],
    }
    toml_path = write_run_record(tmp_path, config, ["brainbulge", "solve", "--out", "x"])
    assert toml_path == tmp_path / "run.toml"
    assert load_config(toml_path) == {
        "name": "frontal",
        "mesh": {"h_mm": 2.5, "refine": [1, 2], "file": "/data/brain.msh"},
        "material": {"mu_kpa": 1.5, "side": "left", "flags": [1, 0]},
        "study": {"random_seed": 42, "thetas": [0.0, 1.5e-3]},
        "swell": [{"region": "white", "theta": 1.1}, {"region": "gray", "theta": 1.05}],
    }
    assert config["mesh"]["refine"] == (1, 2)  # the caller's config is not modified

    record = json.loads((tmp_path / "run.json").read_text())
    assert record["command"] == ["brainbulge", "solve", "--out", "x"]
    assert record["brainbulge_version"] == brainbulge.__version__
    assert record["python_version"] == ".".join(map(str, sys.version_info[:3]))
    assert record["platform"]
    assert record["seed"] == 42  # nested random_seed found
    assert record["packages"]["numpy"] == version("numpy")
    assert record["packages"]["dask"] == version("dask")
    assert set(record["packages"]) <= set(run_record.RECORDED_PACKAGES)
    assert datetime.fromisoformat(record["start_time"]).tzinfo is not None


def test_run_record_defaults(tmp_path: Path) -> None:
    write_run_record(tmp_path, {"seed": 7}, None)
    record = json.loads((tmp_path / "run.json").read_text())
    assert record["command"] == sys.argv
    assert record["seed"] == 7
    write_run_record(tmp_path, {}, [])
    assert json.loads((tmp_path / "run.json").read_text())["seed"] is None


def test_unrecordable_config_is_an_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"config\.mesh\.bad: object"):
        write_run_record(tmp_path, {"mesh": {"bad": object()}}, [])
    with pytest.raises(InputError, match="None inside a list"):
        write_run_record(tmp_path, {"a": [1, None]}, [])


# --------------------------------------------------------------------------- status


@pytest.mark.parametrize("status", ["running", "complete", "incomplete", "failed"])
def test_mark_status(tmp_path: Path, status: str) -> None:
    mark_status(tmp_path, "running")
    path = mark_status(tmp_path, status, "Newton failed\nat step 3")
    data = json.loads(path.read_text())
    assert path == tmp_path / "status.json"
    assert data["status"] == status and data["message"] == "Newton failed at step 3"
    assert datetime.fromisoformat(data["time"]).tzinfo is not None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["status.json"]  # no temporaries


def test_mark_status_rejects_unknown(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="status must be one of"):
        mark_status(tmp_path, "done")
    assert not (tmp_path / "status.json").exists()


# --------------------------------------------------------------------------- load_config


def test_load_config_reports_the_line_of_a_syntax_error(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text('[mesh]\nh_mm = 2.0\nflap = "frontal\n')
    with pytest.raises(InputError) as info:
        load_config(path)
    message = str(info.value)
    assert message.startswith(f"invalid TOML in {path}, line 3: ")
    assert "\n" not in message


@pytest.mark.parametrize("kind", ["missing", "folder", "binary"])
def test_load_config_unreadable(tmp_path: Path, kind: str) -> None:
    path = tmp_path / "c.toml"
    if kind == "folder":
        path.mkdir()
    elif kind == "binary":
        path.write_bytes(b"a = '\xff\xfe'\n")
    with pytest.raises(InputError) as info:
        load_config(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)
