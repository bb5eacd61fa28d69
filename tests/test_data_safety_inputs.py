"""Nothing lost, nothing silently wrong: inputs inside ``--out``, files that are not ours,
all-or-nothing ``--overwrite``, closed run files, inputs refused before ``--out`` is claimed.

Each test takes well under a second: the runs are fakes of the solvers (the folder, its
record and its checks are real).
"""

from __future__ import annotations

import gzip
import json
import os
import struct
from pathlib import Path

import nibabel as nib
import numpy as np
import pytest

import brainbulge.studies.craniectomy as cr
import brainbulge.studies.hemidisk as hd
from brainbulge.atomic import atomic_output
from brainbulge.cli import checks, main
from brainbulge.errors import InputError
from brainbulge.results.records.output_folder import claim_output_dir, read_manifest

FAST = ["hemidisk", "--mesh-size", "0.3", "--steps", "1"]
SUMMARY = {"max_displacement": 0.1, "min_radial_stretch": 0.9, "max_radial_stretch": 1.1,
           "min_tangential_stretch": 0.9, "max_tangential_stretch": 1.2, "max_penetration": 0.0,
           "max_skull_crossing": 0.0}
BRAIN = {"swelling_reached": 1.1, "max_displacement": 1.0, "midline_shift_mm": 0.1,
         "bulge_volume_ml": 10.0, "max_principal_strain": 0.1, "max_penetration_mm": 0.0}


def one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0], err
    return err[0]


def contents(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (hidden ones too) and its bytes."""
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def write(path: Path, data: bytes) -> None:
    """As brainbulge writes a result: atomically, so into the folder's manifest."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(path) as tmp:
        tmp.write_bytes(data)


def fake_hemidisk(files: dict[str, bytes], meanwhile=None):
    def run(case, out, progress=False):
        for name, data in files.items():
            write(Path(out) / name, data)
        if meanwhile is not None:
            meanwhile(Path(out))
        return SUMMARY

    return run


@pytest.fixture
def mesh_folder(tmp_path, monkeypatch) -> Path:
    """A folder ``M`` as ``brainbulge mesh --out M`` leaves it (a stand-in brain.npz)."""
    folder = tmp_path / "M"
    claimed = claim_output_dir(folder, overwrite=False)
    from brainbulge.results.records.run_record import mark_status, write_run_record

    write_run_record(folder, {"command": "mesh", "mesh": {"tets": 30000}}, ["brainbulge"])
    write(folder / "brain.npz", b"the mesh")
    write(folder / "mesh.json", b"{}")
    mark_status(folder, "complete")
    claimed.release()
    monkeypatch.setattr(checks, "brain_npz", lambda path, what="--mesh": None)
    return folder


# --------------------------------------------------------------------------- inputs


@pytest.mark.parametrize("argv", [
    ["brain", "--mesh", "{M}/brain.npz"],
    ["brain", "--mesh", "{M}"],  # a mesh folder is read through its brain.npz
    ["study", "craniectomy", "--mesh", "{M}/brain.npz"],
])
def test_an_input_inside_out_is_never_deleted_by_overwrite(mesh_folder, monkeypatch, argv
                                                           ) -> None:
    import brainbulge.studies.suites as suites

    monkeypatch.setattr(cr, "run_brain", lambda case, out, progress=False: (
        write(Path(out) / "summary.json", b"{}"), BRAIN)[1])
    monkeypatch.setattr(suites, "run_named_study", lambda name, sc, out, *a: len(sc))
    argv = [a.replace("{M}", str(mesh_folder)) for a in argv]
    assert main([*argv, "--out", str(mesh_folder), "--overwrite"]) == 0
    assert (mesh_folder / "brain.npz").read_bytes() == b"the mesh"
    assert not (mesh_folder / "mesh.json").exists()  # the earlier run's other files go
    # the mesh stays listed as brainbulge's: the next --overwrite is not refused for it
    assert "brain.npz" in read_manifest(mesh_folder)
    assert main([*argv, "--out", str(mesh_folder), "--overwrite"]) == 0
    assert (mesh_folder / "brain.npz").read_bytes() == b"the mesh"


def test_a_kept_input_is_not_reported_as_a_result(mesh_folder, monkeypatch, capsys) -> None:
    def interrupted(case, out, progress=False):
        raise KeyboardInterrupt

    monkeypatch.setattr(cr, "run_brain", interrupted)
    argv = ["brain", "--mesh", str(mesh_folder / "brain.npz"), "--out", str(mesh_folder)]
    assert main([*argv, "--overwrite"]) == 130
    assert "stopped before any results were written" in one_line(capsys)
    assert (mesh_folder / "brain.npz").read_bytes() == b"the mesh"


def test_a_run_file_inside_out_is_read_and_kept(tmp_path, monkeypatch) -> None:
    out = tmp_path / "out"
    monkeypatch.setattr(hd, "run_hemidisk", fake_hemidisk({"fields.vtu": b"v"}))
    assert main([*FAST, "--out", str(out)]) == 0
    toml = (out / "run.toml").read_text()
    assert main(["run", str(out / "run.toml"), "--out", str(out), "--overwrite"]) == 0
    assert (out / "run.toml").read_text() == toml  # the same run, recorded again


# --------------------------------------------------------------------------- manifest


def test_files_that_appear_during_a_run_are_not_listed_nor_deleted(tmp_path, monkeypatch,
                                                                   capsys) -> None:
    out = tmp_path / "out"

    def others(out: Path) -> None:
        (out / "analysis.ipynb").write_text("a notebook saved here meanwhile")
        sub = claim_output_dir(out / "sub", overwrite=False)  # another run, in a subfolder
        write(out / "sub" / "fields.vtu", b"theirs")
        sub.release()

    monkeypatch.setattr(hd, "run_hemidisk", fake_hemidisk({"fields.vtu": b"v"}, others))
    assert main([*FAST, "--out", str(out)]) == 0
    manifest = read_manifest(out)
    st = (out / "fields.vtu").stat()
    assert manifest["fields.vtu"] == (st.st_size, st.st_mtime_ns)
    assert not {"analysis.ipynb", "sub/fields.vtu", "sub/run.json"} & set(manifest)
    before = contents(out)
    assert main([*FAST, "--out", str(out), "--overwrite"]) == 2
    assert "analysis.ipynb" in one_line(capsys)
    assert contents(out) == before


def test_a_result_changed_since_it_was_written_is_not_deleted(tmp_path, monkeypatch,
                                                              capsys) -> None:
    out = tmp_path / "out"
    monkeypatch.setattr(hd, "run_hemidisk", fake_hemidisk({"fields.vtu": b"v"}))
    assert main([*FAST, "--out", str(out)]) == 0
    (out / "fields.vtu").write_bytes(b"edited by hand")  # now the user's
    assert main([*FAST, "--out", str(out), "--overwrite"]) == 2
    assert "changed since (fields.vtu)" in one_line(capsys)
    assert (out / "fields.vtu").read_bytes() == b"edited by hand"


def test_the_journal_of_a_killed_run_lists_its_files(tmp_path) -> None:
    out = tmp_path / "out"
    folder = claim_output_dir(out, overwrite=False)
    write(out / "fields.vtu", b"v")
    (out / ".brainbulge.lock").unlink()  # as a SIGKILL leaves it: lock gone, no run.json
    folder.lock = None
    assert set(read_manifest(out)) == {"fields.vtu"}
    claim_output_dir(out, overwrite=True).release()
    assert not (out / "fields.vtu").exists()


# --------------------------------------------------------------------------- all or nothing


def test_a_failed_overwrite_leaves_the_previous_result_intact(tmp_path, monkeypatch,
                                                              capsys) -> None:
    out = tmp_path / "out"
    monkeypatch.setattr(hd, "run_hemidisk",
                        fake_hemidisk({"a.vtu": b"a", "sub/b.npz": b"b", "z.png": b"z"}))
    assert main([*FAST, "--out", str(out)]) == 0
    before = contents(out)
    rename = os.rename

    def stuck(src, dst, *args, **kwargs):  # as chattr +i or a read-only subfolder
        if Path(src).name == "sub" or Path(src).name == "b.npz":
            raise PermissionError(1, "Operation not permitted", str(src))
        return rename(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "rename", stuck)
    assert main([*FAST, "--out", str(out), "--overwrite"]) == 2
    line = one_line(capsys)
    assert f"cannot remove {out / 'sub' / 'b.npz'}" in line and "nothing was deleted" in line
    assert contents(out) == before  # every file back, byte for byte; no hidden leftovers
    assert json.loads((out / "status.json").read_text())["status"] == "complete"
    monkeypatch.setattr(os, "rename", rename)
    monkeypatch.setattr(hd, "run_hemidisk", fake_hemidisk({"c.vtu": b"c"}))
    assert main([*FAST, "--out", str(out), "--overwrite"]) == 0  # then it works
    assert not (out / "sub").exists() and not (out / "a.vtu").exists()


# --------------------------------------------------------------------------- run files


@pytest.mark.parametrize("text,words", [
    ("[caes]\nalpha = 70.0\n", "unknown table [caes]; did you mean [case]?"),
    ("alpha = 70.0\n", "unknown option alpha; it belongs in [case]"),
    ("[case]\nalpah = 70.0\n", "unknown option alpah in [case]; did you mean 'alpha'?"),
    ("[output]\nformat = 'vtu'\n", "unknown table [output]; valid tables here:"),
    ("[case]\nalpha = 70.0\n[solver]\nmesh = 0.1\n",
     "unknown option mesh in [solver]; did you mean 'mesh_size'?"),
])
def test_a_run_file_is_closed(tmp_path, capsys, text, words) -> None:
    toml = tmp_path / "case.toml"
    toml.write_text('command = "hemidisk"\n' + text)
    assert main(["run", str(toml), "--out", str(tmp_path / "out")]) == 2
    assert words in one_line(capsys)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("text,words", [
    ("[case.alpah]\nx = 1\n", "unknown table [case.alpah]; [case] holds options only"),
    ("[cas.alpha]\nx = 1\n", "unknown table [cas]; did you mean [case]?"),
    ("[solver.extra]\nx = 1\n", "unknown table [solver.extra]; [solver] holds options only"),
])
def test_an_unknown_table_is_named_as_a_table(tmp_path, capsys, text, words) -> None:
    toml = tmp_path / "case.toml"
    toml.write_text('command = "hemidisk"\n' + text)
    assert main(["run", str(toml), "--out", str(tmp_path / "out")]) == 2
    line = one_line(capsys)
    assert words in line and "did you mean 'alpha'" not in line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("value", ["[" * 100_000 + "]" * 100_000,
                                   "{a = " * 3000 + "1" + "}" * 3000])
def test_a_run_file_nested_thousands_deep_is_invalid_toml(tmp_path, capsys, value) -> None:
    toml = tmp_path / "case.toml"
    toml.write_text(f'command = "hemidisk"\n[case]\nalpha = {value}\n')
    assert main(["run", str(toml), "--out", str(tmp_path / "out")]) == 2
    assert f"invalid TOML in {toml}: tables or lists nested too deeply" in one_line(capsys)
    assert not (tmp_path / "out").exists()


def test_a_run_file_with_a_byte_order_mark_is_read(tmp_path, monkeypatch) -> None:
    seen = []
    monkeypatch.setattr(hd, "run_hemidisk", lambda case, out, progress=False: (
        seen.append(case.alpha), SUMMARY)[1])
    toml = tmp_path / "case.toml"  # as Notepad saves "UTF-8 with BOM"
    toml.write_bytes(b"\xef\xbb\xbf" + b'command = "hemidisk"\r\n[case]\r\nalpha = 70.0\r\n')
    assert main(["run", str(toml), "--out", str(tmp_path / "out")]) == 0
    assert seen == [70.0]


@pytest.mark.parametrize("name", ["table.csv", "Report.MD", "brainbulge.log", "report.html",
                                  "STUDY.JSON", "comparison.png"])
def test_a_scenario_named_as_a_file_of_the_study_is_refused(tmp_path, capsys, name) -> None:
    toml = tmp_path / "study.toml"
    toml.write_text('command = "study"\nstudy = "hemidisk-sector"\n'
                    f'[[scenarios]]\nname = "{name}"\nalpha = 60.0\n')
    assert main(["run", str(toml), "--out", str(tmp_path / "out")]) == 2
    assert f"scenario name {name!r} is reserved" in one_line(capsys)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("codes,words", [
    ("[2.5]", "must be a list of whole numbers, got [2.5]"),
    ("[true]", "got [true]"),
    ('"3"', 'got "3"'),
    ("[[3]]", "got [[3]]"),
])
def test_a_label_code_that_is_not_a_whole_number_is_refused(tmp_path, capsys, codes, words
                                                           ) -> None:
    from toy_brain import toy_labels

    labels = toy_labels(tmp_path / "seg.nii.gz")
    label_map = tmp_path / "map.json"
    label_map.write_text(f'{{"gray": {codes}, "white": [2, 41]}}')
    assert main(["mesh", "--labels", str(labels), "--label-map", str(label_map),
                 "--out", str(tmp_path / "out")]) == 2
    assert words in one_line(capsys)
    assert not (tmp_path / "out").exists()


def test_a_label_map_nested_too_deeply_or_with_a_byte_order_mark(tmp_path) -> None:
    from brainbulge.errors import InputError
    from brainbulge.geometry.brain.labels import read_label_map

    deep = tmp_path / "deep.json"
    deep.write_text('{"gray": ' + "[" * 100_000 + "]" * 100_000 + "}")
    with pytest.raises(InputError, match="nested too deeply"):
        read_label_map(deep)
    bom = tmp_path / "bom.json"
    bom.write_bytes(b'\xef\xbb\xbf{"gray": [3, 42.0], "white": [2]}')
    assert read_label_map(bom) == {"gray": [3, 42], "white": [2]}


def test_a_brain_run_file_is_closed_too(tmp_path, capsys) -> None:
    toml = tmp_path / "case.toml"
    toml.write_text('command = "brain"\n[case]\nflap = "left"\nswel = "left"\n')
    assert main(["run", str(toml), "--out", str(tmp_path / "out")]) == 2
    assert "did you mean 'swell'?" in one_line(capsys)


def test_run_files_of_studies_meshes_plans_and_the_demo_run(tmp_path, monkeypatch) -> None:
    import brainbulge.cli.demo as demo
    import brainbulge.cli.mesh as mesh
    import brainbulge.studies.suites as suites

    ran = []
    monkeypatch.setattr(suites, "run_named_study",
                        lambda name, sc, out, *a: ran.append((name, len(sc))) or len(sc))
    out = tmp_path / "study"
    assert main(["study", "hemidisk-sector", "--alphas", "20", "--betas", "30",
                 "--out", str(out)]) == 0
    assert main(["run", str(out / "run.toml"), "--out", str(tmp_path / "again")]) == 0
    assert ran == [("hemidisk-sector", 2), ("hemidisk-sector", 2)]
    assert (tmp_path / "again" / "run.toml").read_text() == (out / "run.toml").read_text()

    seen = []
    monkeypatch.setattr(mesh, "run", lambda args: seen.append(
        (args.tets, args.flap_centre, args.csf_layer, args.out)) or 0)
    toml = tmp_path / "mesh.toml"
    toml.write_text('command = "mesh"\n[mesh]\ntets = 40000\nflap_centre_mm = [-60, 0, 50]\n'
                    "csf_layer_mm = 2.0\n")
    assert main(["run", str(toml), "--out", str(tmp_path / "m")]) == 0
    assert seen == [(40000, [-60.0, 0.0, 50.0], 2.0, str(tmp_path / "m"))]

    monkeypatch.setattr(demo, "run_command", lambda args: seen.append(args.quick) or 0)
    import tomli_w

    from brainbulge.results.records.config_file import toml_ready
    from brainbulge.studies.suites import demo_plan

    toml.write_text(tomli_w.dumps(toml_ready({"command": "demo", "quick": True,
                                              **demo_plan(True)})))
    assert main(["run", str(toml)]) == 0 and seen[-1] is True

    import brainbulge.cli.plan as plan
    import brainbulge.cli.reproduce as reproduce

    monkeypatch.setattr(plan, "run_command", lambda args: seen.append(
        (args.swell, args.diameters_mm, args.centres_mm, args.tets)) or 0)
    toml.write_text('command = "plan"\n[plan]\nswell = "left"\ntets = 30000\n'
                    "diameters_mm = [80.0, 100.0]\ncentres_mm = [[-60, 0, 50], [-50, 10, 60]]\n")
    assert main(["run", str(toml)]) == 0
    assert seen[-1] == ("left", [80.0, 100.0], [[-60.0, 0.0, 50.0], [-50.0, 10.0, 60.0]], 30000)
    monkeypatch.setattr(reproduce, "run_command", lambda args: seen.append(
        (args.tets, args.fix)) or 0)
    toml.write_text('command = "reproduce"\ntets = 30000\nfix = "inferior"\n')
    assert main(["run", str(toml)]) == 0 and seen[-1] == (30000, "inferior")


def test_a_bad_value_in_a_run_file_is_one_line_naming_the_file(tmp_path, capsys) -> None:
    toml = tmp_path / "mesh.toml"
    toml.write_text('command = "mesh"\n[mesh]\ntets = "many"\n')
    assert main(["run", str(toml), "--out", str(tmp_path / "m")]) == 2
    line = one_line(capsys)
    assert str(toml) in line and "--tets must be a whole number" in line


# --------------------------------------------------------------------------- before --out


def _huge_nifti(path: Path, dims: tuple[int, int, int], vector: bool = False) -> Path:
    """A 2x2x2 image whose header claims ``dims`` voxels (a corrupt or hostile header)."""
    shape = (2, 2, 2, 3) if vector else (2, 2, 2)
    small = path.with_suffix("")
    nib.save(nib.Nifti1Image(np.ones(shape, np.int16), np.eye(4)), small)
    raw = bytearray(small.read_bytes())
    raw[40:56] = struct.pack("<8h", 4 if vector else 3, *dims, 3 if vector else 1, 1, 1, 1)
    path.write_bytes(gzip.compress(bytes(raw)))
    return path


def test_a_label_image_larger_than_memory_is_refused_from_its_header(tmp_path, capsys) -> None:
    labels = _huge_nifti(tmp_path / "huge.nii.gz", (30000, 30000, 30000))
    assert labels.stat().st_size < 1000
    assert main(["mesh", "--labels", str(labels), "--out", str(tmp_path / "out")]) == 2
    line = one_line(capsys)
    assert "declares 30000 x 30000 x 30000 voxels" in line and "memory is available" in line
    assert not (tmp_path / "out").exists()


def test_a_fibre_image_of_the_wrong_shape_is_refused_before_out(tmp_path, capsys) -> None:
    fibres = tmp_path / "v1.nii.gz"
    nib.save(nib.Nifti1Image(np.zeros((4, 4, 4, 2), np.float32), np.eye(4)), fibres)
    assert main(["brain", "--fibres", str(fibres), "--out", str(tmp_path / "out")]) == 2
    assert "expected (nx, ny, nz, 3)" in one_line(capsys)
    huge = _huge_nifti(tmp_path / "big.nii.gz", (30000, 30000, 30000), vector=True)
    assert main(["brain", "--fibres", str(huge), "--out", str(tmp_path / "out")]) == 2
    assert "memory is available" in one_line(capsys)
    assert not (tmp_path / "out").exists()


def test_a_label_code_in_two_tissues_is_named(tmp_path, capsys) -> None:
    from toy_brain import toy_labels

    labels = toy_labels(tmp_path / "seg.nii.gz")
    label_map = tmp_path / "map.json"
    label_map.write_text(json.dumps({"gray": [3, 42], "white": [2, 41, 3]}))
    assert main(["mesh", "--labels", str(labels), "--label-map", str(label_map),
                 "--out", str(tmp_path / "out")]) == 2
    assert "lists code 3 in both 'gray' and 'white'" in one_line(capsys)


@pytest.mark.parametrize("argv,words", [
    (["study", "hemidisk-sector", "--alphas", "20", "20"], "--alphas 20 20 repeats a value"),
    (["study", "hemidisk-sector", "--betas", "30", "60", "30"], "repeats a value"),
    (["mesh", "--tets", "1e12"], "in [25,000, 5,000,000]"),
    (["brain", "--tets", "2e4"], "below 25,000"),
])
def test_options_are_refused_before_out_is_claimed(tmp_path, capsys, argv, words) -> None:
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out)]) == 2
    assert words in one_line(capsys)
    assert not out.exists()


def test_the_help_defaults_are_accepted_as_written(capsys) -> None:
    from brainbulge.cli import build_parser

    with pytest.raises(SystemExit):
        build_parser().parse_args(["mesh", "--help"])
    assert "(default 1e5;" in capsys.readouterr().out
    args = build_parser().parse_args(["mesh", "--tets", "1e5"])
    assert args.tets == 100_000 and isinstance(args.tets, int)


@pytest.mark.parametrize("command", ["brain", "mesh"])
def test_the_help_states_the_least_tets_that_is_enforced(capsys, command) -> None:
    import re

    from brainbulge.cli import build_parser

    with pytest.raises(SystemExit):
        build_parser().parse_args([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    least = int(re.search(r"ICBM152 template at least (\d+) x 8\^K", text)[1])
    per_ml = float(re.search(r"--labels image at least ([\d.]+) per ml", text)[1])
    checks.mesh_tets(least, 0, template=True)
    checks.mesh_tets(least * 8, 1, template=True)
    with pytest.raises(InputError, match=f"below {least:,}"):
        checks.mesh_tets(least - 1, 0, template=True)
    with pytest.raises(InputError, match="too coarse"):
        checks.mesh_tets(int(per_ml * 1000 * 0.98), 0, template=False, labelled_ml=1000.0)
    checks.mesh_tets(int(per_ml * 1000 * 1.02), 0, template=False, labelled_ml=1000.0)


def test_an_over_long_out_is_refused_in_one_line(tmp_path, capsys) -> None:
    for out in (tmp_path / ("x" * 300), tmp_path / "/".join(["y" * 200] * 25)):
        assert main([*FAST, "--out", str(out)]) == 2
        assert "choose a shorter --out" in one_line(capsys)


# --------------------------------------------------------------------------- resume


def fields_task(scenario: dict, scenario_dir: str) -> dict:
    """A scenario that writes its fields (and counts its runs)."""
    folder = Path(scenario_dir)
    np.savez(folder / "fields.npz", x=np.arange(2000.0))
    runs = folder / "runs"
    runs.write_text(str(int(runs.read_text()) + 1 if runs.exists() else 1))
    return {"x": 1}


def test_resume_recomputes_a_scenario_whose_fields_are_lost_or_corrupt(tmp_path, caplog
                                                                       ) -> None:
    from brainbulge.studies.runner import run_study

    scenarios = [{"name": n} for n in ("lost", "cut", "flipped", "fine")]

    def run() -> list[dict]:
        return run_study(scenarios, fields_task, tmp_path, scheduler="serial",
                         progress=False, outputs=("fields.npz",))

    run()
    (tmp_path / "lost" / "fields.npz").unlink()
    cut = tmp_path / "cut" / "fields.npz"
    cut.write_bytes(cut.read_bytes()[:500])
    flipped = tmp_path / "flipped" / "fields.npz"
    data = bytearray(flipped.read_bytes())
    data[200] ^= 0xFF  # inside the array: the checksum fails
    flipped.write_bytes(bytes(data))
    rows = run()
    assert all(r["complete"] for r in rows)
    assert {s["name"]: (tmp_path / s["name"] / "runs").read_text() for s in scenarios} == {
        "lost": "2", "cut": "2", "flipped": "2", "fine": "1"}
    assert "lost: fields.npz missing or unreadable; recomputing it" in caplog.text
