"""``benchmarks/compare_runs.py``: the comparison of runs against a reference."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "compare_runs.py"


@pytest.fixture(scope="module")
def compare_runs():
    spec = importlib.util.spec_from_file_location("compare_runs", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _run(folder: Path, **summary) -> str:
    folder.mkdir()
    (folder / "summary.json").write_text(json.dumps(summary))
    return str(folder)


def test_flags_the_differences_beyond_the_tolerance(compare_runs, tmp_path, capsys) -> None:
    ref = _run(tmp_path / "ref", midline_shift_mm=-4.0, bulge_volume_ml=50.0)
    near = _run(tmp_path / "near", midline_shift_mm=-3.96, bulge_volume_ml=51.5)
    rc = compare_runs.main(["TH=" + near, "--ref", "MINI=" + ref,
                            "--keys", "midline_shift_mm", "bulge_volume_ml", "absent"])
    out = capsys.readouterr().out
    assert rc == 0
    assert "| midline_shift_mm | -3.96 (+1.0 %) | -4 |" in out  # relative to |ref|
    assert "| bulge_volume_ml | 51.5 (+3.0 %*) | 50 |" in out
    assert "| absent | - | - |" in out
    assert "TH: 1 of 3 beyond 2 % (bulge_volume_ml)" in out


def test_a_folder_without_a_summary_is_a_clear_error(compare_runs, tmp_path, capsys) -> None:
    ref = _run(tmp_path / "ref", midline_shift_mm=-4.0)
    assert compare_runs.main([str(tmp_path), "--ref", ref]) == 2
    assert "no summary.json" in capsys.readouterr().err
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "summary.json").write_text('{"midline_shift_mm": ')  # a run killed mid-write
    assert compare_runs.main([str(broken), "--ref", ref]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: cannot read") and err.count("\n") == 1


def test_relative_difference(compare_runs) -> None:
    assert compare_runs.relative_difference(-3.0, -4.0) == pytest.approx(0.25)
    assert compare_runs.relative_difference(0.0, 0.0) == 0.0
    assert compare_runs.relative_difference(1.0, 0.0) == float("inf")
