"""The command line: bad input gives one line and a non-zero exit, nothing half-written;
the README's Python example runs."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from brainbulge.cli import main

ROOT = Path(__file__).resolve().parents[1]

BAD = [
    (["hemidisk", "--alpha", "0"], "alpha"),
    (["hemidisk", "--alpha", "181"], "alpha"),
    (["hemidisk", "--beta", "-1"], "beta"),
    (["hemidisk", "--beta", "190"], "beta"),
    (["hemidisk", "--swelling", "0"], "Js"),
    (["hemidisk", "--swelling", "-2"], "Js"),
    (["hemidisk", "--swelling", "nan"], "Js"),
    (["hemidisk", "--disk", "0", "0.95", "0.2"], "disk"),
    (["hemidisk", "--beta", "120", "--opening-center", "10"], "opening"),
    (["hemidisk", "--material", "jelly"], "preset"),
    (["hemidisk", "--mesh-size", "0"], "mesh size"),
    (["hemidisk", "--mesh-size", "5"], "mesh size"),
    (["hemidisk", "--steps", "0"], "steps"),
    (["hemidisk", "--radius", "-1"], "radius"),
    (["hemidisk", "--beta", "0", "--mesh-size", "0.3"], "infeasible"),
    (["hemidisk", "--beta", "0", "--contact", "noslip", "--mesh-size", "0.3"], "infeasible"),
    (["study", "hemidisk-sector", "--workers", "0"], "workers"),
    (["study", "hemidisk-sector", "--alphas", "200"], "alpha"),
    (["study", "hemidisk-sector", "--rim-mesh-size", "0"], "rim mesh size"),
    (["brain", "--flap", "custom"], "flap-centre"),
    (["brain", "--swelling", "3"], "swelling"),
    (["brain", "--steps", "0"], "steps"),
    (["brain", "--tets", "10"], "tets"),
    (["brain", "--material", "jelly"], "preset"),
    (["brain", "--skull-edge-radius", "20"], "edge radius"),
    (["brain", "--edge-exclusion", "-1"], "edge exclusion"),
    (["brain", "--tolerance", "0.1"], "tolerance"),
    (["brain", "--mesh", "missing/brain.npz"], "does not exist"),
    (["brain", "--mesh", str(ROOT), "--labels", "seg.nii.gz"], "--mesh fixes the geometry"),
    (["brain", "--fibres", "missing_V1.nii.gz"], "fibre image"),
    (["study", "craniectomy", "--tets", "10"], "tets"),
    (["study", "craniectomy", "--swelling", "0.1"], "swelling"),
]


@pytest.mark.parametrize("argv,message", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_input_table(argv, message, tmp_path, capsys) -> None:
    out = tmp_path / "out"
    code = main([*argv, "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0
    assert err and err[-1].startswith("error:") and message in err[-1], err
    # nothing corrupt: either no folder, or a run record with a failed status
    if out.exists():
        assert (out / "status.json").is_file()
        assert not (out / "summary.json").exists() or "infeasible" not in message


def test_bad_toml(tmp_path, capsys) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text("command = 'hemidisk'\n[hemidisk\nalpha = 3\n")
    assert main(["run", str(cfg), "--out", str(tmp_path / "o")]) == 2
    assert "line" in capsys.readouterr().err
    cfg.write_text("command = 'hemidisk'\n[hemidisk]\nbanana = 3\n")
    assert main(["run", str(cfg), "--out", str(tmp_path / "o")]) == 2
    assert "banana" in capsys.readouterr().err
    assert main(["run", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "o")]) == 2


def test_existing_output_folder_is_not_overwritten(tmp_path, capsys) -> None:
    out = tmp_path / "o"
    out.mkdir()
    (out / "precious.txt").write_text("keep me")
    assert main(["hemidisk", "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert (out / "precious.txt").read_text() == "keep me"


def test_hemidisk_run_and_rerun_from_record(tmp_path) -> None:
    out = tmp_path / "hd"
    argv = ["hemidisk", "--contact", "noslip", "--mesh-size", "0.15", "--out", str(out)]
    assert main(argv) == 0
    for f in ("summary.json", "fields.vtu", "fields.png", "run.toml", "run.json", "status.json"):
        assert (out / f).is_file(), f
    import meshio

    vtu = meshio.read(out / "fields.vtu")
    for field in ("u", "lambda_n", "lambda_t", "J", "Je", "Js", "pressure", "max_principal_strain"):
        assert field in vtu.point_data
    again = tmp_path / "again"
    assert main(["run", str(out / "run.toml"), "--out", str(again)]) == 0
    import json

    a = json.loads((out / "summary.json").read_text())
    b = json.loads((again / "summary.json").read_text())
    assert a["max_radial_stretch"] == b["max_radial_stretch"]  # bit for bit


def test_version() -> None:
    r = subprocess.run(
        [sys.executable, "-m", "brainbulge.cli", "--version"], capture_output=True, text=True
    )
    assert r.returncode == 0 and "brainbulge" in r.stdout


def test_readme_python_example() -> None:
    text = (ROOT / "README.md").read_text()
    code = re.search(r"## Python API\s+```python\n(.*?)```", text, re.S).group(1)
    exec(compile(code, "README.md", "exec"), {})


def test_study_passes_mesh_sizes_to_its_scenarios() -> None:
    from brainbulge.cli import build_parser
    from brainbulge.cli.study import scenarios_for

    argv = ["study", "hemidisk-sector", "--mesh-size", "0.1", "--corner-mesh-size", "0.02",
            "--rim-mesh-size", "0.003", "--out", "x"]
    sc = scenarios_for("hemidisk-sector", build_parser().parse_args(argv))
    assert len(sc) == 32
    assert all((s["mesh_size"], s["corner_mesh_size"], s["rim_mesh_size"]) == (0.1, 0.02, 0.003)
               for s in sc)
    plain = scenarios_for("hemidisk-disk", build_parser().parse_args(["study", "hemidisk-disk"]))
    assert all("rim_mesh_size" not in s for s in plain)  # defaults stay the case's own
