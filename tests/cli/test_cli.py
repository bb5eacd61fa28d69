"""The command line: bad input gives one line and a non-zero exit, nothing half-written;
the README's Python example runs."""

from __future__ import annotations

import json
import re
import socket
import subprocess
import sys
from pathlib import Path

import nibabel as nib
import numpy as np
import pytest

from brainbulge.atomic import atomic_output, atomic_write_text
from brainbulge.cli import main

ROOT = Path(__file__).resolve().parents[2]

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
    # options checked before --out is touched (a finished run given as --out stays as it is)
    (["hemidisk", "--steps", "0", "--out", "{run}", "--overwrite"], "steps"),
    (["hemidisk", "--mesh-size", "0", "--out", "{run}", "--overwrite"], "mesh size"),
    (["hemidisk", "--material", "jelly", "--out", "{run}", "--overwrite"], "preset"),
    (["hemidisk", "--skull-edge-radius", "0.5", "--out", "{run}", "--overwrite"], "edge radius"),
    (["hemidisk", "--alpha", "200", "--out", "{run}"], "alpha"),
    (["hemidisk", "--out", "{run}"], "--overwrite"),
    (["hemidisk", "--out", "{user_file}"], "is a file"),
    (["hemidisk", "--out", "{tmp}", "--overwrite"], "holds the current folder"),
    (["hemidisk", "--out", ".", "--overwrite"], "current folder"),
    (["hemidisk", "--out", "{tmp}/..", "--overwrite"], "current folder"),
    (["hemidisk", "--out", ""], "--out is empty"),
    (["hemidisk", "--out", "{run_with_notes}", "--overwrite"], "notes.txt"),
    (["hemidisk", "--out", "{old_run}", "--overwrite"], "no list of the files"),
    (["mesh", "--tets", "20000", "--out", "{run}", "--overwrite", "--refine", "9"], "--refine"),
    # hemidisk ranges: a refusal with the range instead of hours of meshing or a crash
    (["hemidisk", "--mesh-size", "1e-6"], "[0.005, 1]"),
    (["hemidisk", "--mesh-size", "nan"], "mesh size"),
    (["hemidisk", "--corner-mesh-size", "1e-9"], "corner mesh size"),
    (["hemidisk", "--rim-mesh-size", "2"], "rim mesh size"),
    (["hemidisk", "--edge-exclusion", "5"], "edge exclusion"),
    (["hemidisk", "--edge-exclusion", "nan"], "edge exclusion"),
    (["hemidisk", "--radius", "1e-12"], "radius"),
    (["hemidisk", "--disk", "0", "0.5", "0"], "disk radius"),
    (["hemidisk", "--disk", "0", "nan", "0.1"], "disk"),
    (["hemidisk", "--swelling", "3"], "[0.5, 2]"),
    (["hemidisk", "--steps", "100000"], "steps"),
    (["hemidisk", "--opening-center", "nan"], "opening"),
    (["hemidisk", "--alpha", "x"], "--help"),
    # TOML files: wrong types and values are input errors (exit 2), not internal ones
    (["run", "{toml:alpha = 'eighty'}"], "alpha = 'eighty' must be a number"),
    (["run", "{toml:R = 1e-12}"], "radius"),
    (["run", "{toml:steps = 2.5}"], "whole number"),
    (["run", "{toml:contact = 3}"], "text"),
    (["run", "{toml:rezone = 'yes'}"], "true or false"),
    (["run", "{toml:disk = [0.0, 0.5]}"], "disk"),
    (["run", "{toml:mesh_size = '0.1'}"], "mesh_size"),
    (["run", "{brain_toml:extra = 5}"], "table"),
    (["run", "{toml:banana = 1}"], "banana"),
    (["run", "{brain_toml:steps = 'four'}"], "steps"),
    (["run", "{brain_toml:mesh = '{text_file}'}"], "not a brain.npz"),
    (["run", "{tmp}/missing.toml"], "cannot read"),
    # brain inputs
    (["brain", "--mesh", "{text_file}"], "not a brain.npz"),
    (["brain", "--mesh", "{truncated_npz}"], "not a brain.npz"),
    (["brain", "--mesh", "{foreign_npz}"], "not a brain.npz"),
    (["brain", "--mesh", "{empty_file}"], "not a brain.npz"),
    (["brain", "--mesh", "{tmp}"], "no such file"),
    (["brain", "--flap", "custom", "--flap-centre", "1000", "1000", "1000"], "near the skull"),
    (["brain", "--label-map", "freesurfer"], "--labels"),
    (["brain", "--edge-exclusion", "nan"], "edge exclusion"),
    (["brain", "--skull-edge-radius", "nan"], "edge radius"),
    (["brain", "--steps", "5000"], "steps"),
    (["brain", "--tets", "100000000"], "tets"),
    (["brain", "--swelling", "0"], "swelling Js = 0.0 must be a number in [0.5, 2]"),
    # mesh inputs
    (["mesh", "--tets", "5000"], "below 25,000"),
    (["mesh", "--tets", "100000", "--refine", "2"], "--tets 100000 / 8^2 is below 25,000"),
    (["brain", "--tets", "10000"], "give --tets 25000 or more"),
    (["mesh", "--tets", "100000000"], "[25,000, 5,000,000]"),
    (["mesh", "--refine", "7"], "--refine"),
    (["mesh", "--label-map", "m.json"], "--labels"),
    (["mesh", "--flap", "custom"], "flap-centre"),
    (["mesh", "--flap", "custom", "--flap-centre", "1000", "0", "0"], "near the skull"),
    (["mesh", "--csf-layer", "nan"], "csf-layer"),
    (["mesh", "--labels", "{text_file}"], "label image"),
    # a user's segmentation (1,000 ml) meshed too coarse for Netgen: refused up front
    (["mesh", "--labels", "{cube_labels}", "--label-map", "gmwmcsf", "--tets", "3000"],
     "too coarse for 1,000 ml of labelled tissue"),
    (["mesh", "--labels", "{cube_labels}", "--label-map", "gmwmcsf", "--tets", "40000",
      "--refine", "2"], "give --tets 339904 or more"),
    (["brain", "--labels", "{cube_labels}", "--label-map", "gmwmcsf", "--tets", "3000"],
     "give --tets 5311 or more"),
    # studies: every scenario checked before anything starts (exit 2, not 4)
    (["study", "hemidisk-sector", "--scheduler", "not a url"], "scheduler"),
    (["study", "hemidisk-sector", "--steps", "0"], "steps"),
    (["study", "hemidisk-disk", "--mesh-size", "1e-6"], "mesh size"),
    (["study", "craniectomy", "--mesh", "{text_file}"], "not a brain.npz"),
    (["study", "hemidisk-sector", "--workers", "1000"], "workers"),
    (["demo", "--scheduler", "http//x"], "scheduler"),
    (["study", "hemidisk-sector", "--scheduler", "tcp://127.0.0.1:{closed_port}"],
     "no Dask scheduler reachable"),
    (["demo", "--scheduler", "127.0.0.1:{closed_port}"], "no Dask scheduler reachable"),
    (["reproduce", "--scheduler", "tcp://127.0.0.1:{closed_port}"],
     "no Dask scheduler reachable"),
    (["study", "hemidisk-sector", "--scheduler", "tcp://127.0.0.1:99999"], "[1, 65535]"),
    (["demo", "--workers", "0"], "workers"),
    (["study", "hemidisk-sector", "--out", "{run}"], "--overwrite"),
    (["study", "hemidisk-disk", "--out", "{study}"], "'hemidisk-sector'"),
    (["study", "hemidisk-sector", "--alphas", "20", "--out", "{study}"], "16 scenarios, not 8"),
    # run files are closed: a misspelt table or option is named, never ignored
    (["run", "{toml:alpah = 70.0}"], "unknown option alpah in [hemidisk]; did you mean 'alpha'"),
    (["run", "{toml:alpha = 70.0\n[caes]}"], "unknown table [caes]; did you mean [case]?"),
    (["run", "{brain_toml:flaps = 'left'}"], "did you mean 'flap'?"),
    # checked before --out is claimed, however cheap or costly the check
    (["study", "hemidisk-sector", "--alphas", "20", "20"], "repeats a value"),
    (["brain", "--fibres", "{cube_labels}"], "expected (nx, ny, nz, 3)"),
    (["brain", "--fibres", "{text_file}"], "cannot read fibre image"),
    (["hemidisk", "--out", "{tmp}/" + "x" * 300], "choose a shorter --out"),
    (["mesh", "--tets", "1.5"], "--tets must be a whole number"),
    # plans: the search's own options, checked before a mesh is built
    (["plan", "--swell", "left", "--swelling", "3"], "[0.5, 2]"),
    (["plan", "--swell", "left", "--diameters", "0"], "[40, 200] mm"),
    (["plan", "--swell", "both", "--centres", "3"], "must be even with --swell both"),
    (["plan", "--swell", "left", "--threshold", "-1"], "--threshold = -1.0 must be a number"),
    (["plan", "--swell", "left", "--workers", "0"], "workers"),
]

#: exit code of each case: 2 (bad input) unless listed
EXIT = {"infeasible": 3}


def _finished_run(folder: Path, command: str = "hemidisk", manifest: bool = True) -> None:
    """A finished brainbulge run, as the CLI leaves it (record, results, manifest)."""
    from brainbulge.results.records.output_folder import claim_output_dir
    from brainbulge.results.records.run_record import mark_status, write_run_record

    claimed = claim_output_dir(folder, overwrite=False)
    write_run_record(folder, {"command": command, command: {"alpha": 80.0}}, ["brainbulge"])
    atomic_write_text(folder / "summary.json", '{"max_displacement": 0.17}\n')
    with atomic_output(folder / "fields.vtu") as tmp:
        tmp.write_bytes(bytes(range(256)))
    mark_status(folder, "complete")
    claimed.release()
    if not manifest:  # written by a brainbulge without manifests
        record = json.loads((folder / "run.json").read_text())
        del record["files"]
        (folder / "run.json").write_text(json.dumps(record))


def _finished_study(folder: Path) -> None:
    from brainbulge.cli import build_parser
    from brainbulge.cli.study import scenarios_for
    from brainbulge.results.records.output_folder import claim_output_dir
    from brainbulge.results.records.run_record import mark_status, write_run_record

    args = build_parser().parse_args(["study", "hemidisk-sector", "--alphas", "20", "40"])
    scenarios = scenarios_for("hemidisk-sector", args)
    claimed = claim_output_dir(folder, overwrite=False)
    write_run_record(folder, {"command": "study", "study": "hemidisk-sector",
                              "scenarios": scenarios}, ["brainbulge"])
    atomic_write_text(folder / "study.json", '{"n_scenarios": 16}\n')
    (folder / scenarios[0]["name"]).mkdir()
    atomic_write_text(folder / scenarios[0]["name"] / "summary.json", '{"complete": true}\n')
    mark_status(folder, "complete")
    claimed.release()


@pytest.fixture
def workspace(tmp_path, monkeypatch):
    """A user's project folder: a finished run, a finished study, the user's own files."""
    _finished_run(tmp_path / "run")
    _finished_run(tmp_path / "run_with_notes")
    (tmp_path / "run_with_notes" / "notes.txt").write_text("my notes")
    _finished_run(tmp_path / "old_run", manifest=False)
    _finished_study(tmp_path / "study")
    (tmp_path / "thesis.tex").write_text("\\section{Results}\n")
    (tmp_path / "text.npz").write_text("nodes, tets\n1 2 3\n")
    (tmp_path / "empty.npz").write_bytes(b"")
    cube = np.zeros((52, 52, 52), dtype=np.uint8)  # 1,000 ml in 2 mm voxels
    cube[1:51, 1:51, 1:51] = 2  # gray
    cube[11:41, 11:41, 11:41] = 3  # white
    nib.save(nib.Nifti1Image(cube, np.diag([2.0, 2.0, 2.0, 1.0])), tmp_path / "cube.nii.gz")
    np.savez(tmp_path / "foreign.npz", a=np.arange(3))
    np.savez(tmp_path / "whole.npz", nodes_mm=np.zeros((100, 3)), tets=np.zeros((100, 4)))
    data = (tmp_path / "whole.npz").read_bytes()
    (tmp_path / "truncated.npz").write_bytes(data[: len(data) // 2])
    (tmp_path / "whole.npz").unlink()
    work = tmp_path / "work"  # the current folder: inside the project
    work.mkdir()
    (work / "run.toml").write_text("command = 'hemidisk'\n[hemidisk]\nalpha = 80.0\n")
    monkeypatch.chdir(work)
    return tmp_path


def _expand(arg: str, tmp: Path) -> str:
    names = {"{run}": "run", "{run_with_notes}": "run_with_notes", "{old_run}": "old_run",
             "{study}": "study", "{user_file}": "thesis.tex", "{text_file}": "text.npz",
             "{truncated_npz}": "truncated.npz", "{foreign_npz}": "foreign.npz",
             "{empty_file}": "empty.npz", "{cube_labels}": "cube.nii.gz"}
    for key, name in names.items():
        arg = arg.replace(key, str(tmp / name))
    arg = arg.replace("{tmp}", str(tmp))
    if "{closed_port}" in arg:
        arg = arg.replace("{closed_port}", str(closed_port()))
    for kind, command in (("{toml:", "hemidisk"), ("{brain_toml:", "brain")):
        if arg.startswith(kind):
            path = tmp / "cfg" / f"{abs(hash(arg))}.toml"
            path.parent.mkdir(exist_ok=True)
            path.write_text(f"command = '{command}'\n[{command}]\n{arg[len(kind):-1]}\n")
            arg = str(path)
    return arg


def closed_port() -> int:
    """A local TCP port nothing listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _tree(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes()
            for p in sorted(root.rglob("*")) if p.is_file() and "cfg" not in p.parts
            and "new" not in p.parts}


@pytest.mark.parametrize("argv,message", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_input_table(argv, message, workspace, capsys) -> None:
    """One line, the right exit code, no traceback, and nothing of the user's changed."""
    tmp = workspace
    argv = [_expand(a, tmp) for a in argv]
    new = tmp / "new"
    if "--out" not in argv:
        argv += ["--out", str(new)]
    before = _tree(tmp)
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse: malformed values
        code = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == EXIT.get(message, 2), err
    assert len(err) == 1 and err[0].startswith("error:") and message in err[0], err
    assert "Traceback" not in err[0]
    assert _tree(tmp) == before  # the finished runs and the user's files, byte for byte
    assert not list(tmp.rglob(".brainbulge.lock"))
    if new.exists():  # only a run that started (infeasible) wrote, with a true status
        assert message == "infeasible"
        assert json.loads((new / "status.json").read_text())["status"] == "failed"


def test_the_table_covers_every_command(capsys) -> None:
    """Each command that ``brainbulge --help`` lists has bad-input rows in the table."""
    with pytest.raises(SystemExit):
        main(["--help"])
    help_text = capsys.readouterr().out
    listed = help_text.split("commands:", 1)[1]
    commands = set(re.findall(r"^ {4}([a-z][a-z-]*) ", listed, re.M))
    assert {"hemidisk", "brain", "study", "mesh", "run"} <= commands  # the help was read
    assert commands <= {argv[0] for argv, _ in BAD}


def test_a_dask_scheduler_passes_the_probe_and_another_server_does_not(monkeypatch) -> None:
    from distributed import LocalCluster

    from brainbulge.cli import checks
    from brainbulge.errors import InputError

    monkeypatch.setattr(checks, "SCHEDULER_PROBE_S", 1.0)
    with LocalCluster(n_workers=1, processes=False, protocol="tcp://",
                      dashboard_address=":0") as cluster:
        address = cluster.scheduler_address
        checks.scheduler(address)
        checks.scheduler(address.removeprefix("tcp://").replace("127.0.0.1", "localhost"))
    with pytest.raises(InputError, match="refused"):
        checks.scheduler(address)
    with socket.socket() as server:  # accepts, says nothing (as a stuck or foreign server)
        server.bind(("127.0.0.1", 0))
        server.listen()
        port = server.getsockname()[1]
        with pytest.raises(InputError, match="not a Dask scheduler"):
            checks.scheduler(f"tcp://127.0.0.1:{port}")
    checks.scheduler("inproc://127.0.0.1:1")  # in-process addresses are not probed


def test_a_coarse_mesh_of_a_segmentation_is_refused_or_warned(caplog) -> None:
    from brainbulge.cli import checks
    from brainbulge.errors import InputError

    with pytest.raises(InputError, match=r"give --tets 5311 or more \(from 13277"):
        checks.mesh_tets(5000, 0, template=False, labelled_ml=1000.0)
    with caplog.at_level("WARNING"):
        checks.mesh_tets(8000, 0, template=False, labelled_ml=1000.0)
    assert "Netgen may retry for minutes; from --tets 13277" in caplog.text
    caplog.clear()
    with caplog.at_level("WARNING"):
        checks.mesh_tets(13_277, 0, template=False, labelled_ml=1000.0)
        checks.mesh_tets(3000, 0, template=False, labelled_ml=200.0)  # a small phantom
    assert caplog.text == ""


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
    # physics apart from numerics: what is simulated in [case], how in [solver]
    import tomllib

    record = tomllib.loads((out / "run.toml").read_text())
    assert record["case"]["contact"] == "noslip" and record["case"]["alpha"] == 80.0
    assert record["solver"]["mesh_size"] == 0.15 and "mesh_size" not in record["case"]
    # a run file of one [hemidisk] table (the older layout) gives the same run
    old = tmp_path / "old.toml"
    flat = {**record["case"], **record["solver"]}
    old.write_text("command = 'hemidisk'\n[hemidisk]\n" + "".join(
        f"{k} = {json.dumps(v)}\n" for k, v in flat.items() if not isinstance(v, dict)))
    assert main(["run", str(old), "--out", str(tmp_path / "old")]) == 0
    c = json.loads((tmp_path / "old" / "summary.json").read_text())
    assert c["max_radial_stretch"] == a["max_radial_stretch"]


def test_run_file_with_an_option_in_both_tables_is_refused(tmp_path, capsys) -> None:
    cfg = tmp_path / "both.toml"
    cfg.write_text("command = 'hemidisk'\n[case]\nsteps = 2\n[solver]\nsteps = 3\n")
    assert main(["run", str(cfg), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "steps given in both [case] and [solver]" in err and "\n" not in err.strip()
    assert not (tmp_path / "o").exists()


def test_version() -> None:
    r = subprocess.run(
        [sys.executable, "-m", "brainbulge", "--version"], capture_output=True, text=True
    )
    assert r.returncode == 0 and "brainbulge" in r.stdout


def test_readme_python_example(capsys) -> None:
    """The README's example solves its case in one call (the command's lines printed too)
    and prints its headline; the fields
    it returns are incompressible: the deformed area of the mesh (straight triangles moved
    by the vertex displacements) is the swollen one (``int J = int Js``, Js = 1.2 in the
    sector), to the discretisation's error."""
    text = (ROOT / "README.md").read_text()
    code = re.search(r"## Python API\s+.*?```python\n(.*?)```", text, re.S).group(1)
    names: dict = {}
    exec(compile(code, "README.md", "exec"), names)
    out = capsys.readouterr().out.splitlines()  # the command's lines, then the example's
    printed = re.fullmatch(r"(\S+) True", out[-1])
    assert printed and out[0].startswith("results in "), out
    r = names["r"]
    assert r.converged and float(printed.group(1)) == r.summary["max_displacement"]
    f = r.fields

    def areas(x: np.ndarray) -> np.ndarray:
        a, b, c = (x[f["cells"][:, i]] for i in range(3))
        return 0.5 * np.abs(np.cross(b - a, c - a))

    area = areas(f["points"])
    swollen = np.sum(area * f["Js"][f["cells"]].mean(axis=1))
    deformed = np.sum(areas(f["points"] + f["u"]))
    assert swollen - area.sum() > 0.05 * area.sum()
    assert deformed == pytest.approx(swollen, rel=2e-3)
    # the sliding headline's top of the bulge, 0.1562 R at h = 0.05 (docs/verification.md)
    assert r.summary["max_displacement"] == pytest.approx(0.156, rel=0.02)


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
