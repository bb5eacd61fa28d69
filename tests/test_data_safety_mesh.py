"""Every input file checked whole before ``--out`` is claimed: a ``--mesh`` file's arrays
(index range, finite coordinates, known codes, element volumes) and a fibre image's values.

No tampered file may reach NGSolve or Netgen (a bad index crashed the process), end in an
"internal error", or run to a wrong result.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import nibabel as nib
import numpy as np
import pytest

from brainbulge.cli import main
from fake_results import one_line


@pytest.fixture(scope="module")
def toy(tmp_path_factory) -> Path:
    from toy_brain import toy_mesh

    folder = tmp_path_factory.mktemp("toy")
    toy_mesh(folder)
    return folder / "brain.npz"


def _tampered(toy: Path, path: Path, change) -> Path:
    with np.load(toy) as d:
        arrays = {k: d[k] for k in d.files}
    change(arrays)
    np.savez(path, **arrays)
    return path


def _set(name: str, index, value):
    def change(a):
        a[name] = a[name].copy()
        a[name][index] = value
    return change


def _swap_first_two(a):  # every tet inverted: each one's orientation flipped
    a["tets"] = a["tets"][:, [1, 0, 2, 3]]


def _float_tets(a):
    a["tets"] = a["tets"].astype(float)


def _repeat_node(a):  # a tet with a repeated node: no volume
    a["tets"] = a["tets"].copy()
    a["tets"][5, 1] = a["tets"][5, 0]


def _too_large(a):
    a["tets"] = a["tets"].copy()
    a["tets"][3, 2] = len(a["nodes_mm"]) + 1000


MESHES = [
    (_too_large, 2, "tets refers to node"),
    (_set("tets", (0, 0), -1), 2, "tets refers to node -1"),
    (_set("nodes_mm", (7, 1), np.nan), 2, "1 nodes have a NaN or infinite coordinate"),
    (_set("nodes_mm", (7, 2), np.inf), 2, "NaN or infinite coordinate"),
    (_set("tissue", 0, 9), 2, "tissue holds 9, not one of 1 (gray)"),
    (_set("side", 4, 7), 2, "side holds 7"),
    (_set("faces", (2, 0), 10**6), 2, "faces refers to node 1000000"),
    (_set("face_tet", 1, 10**6), 2, "face_tet holds 1000000"),
    (_float_tets, 2, "tets holds float64 values, not whole numbers"),
    (_repeat_node, 5, "and 1 degenerate (no volume)"),
    (_swap_first_two, 5, "tetrahedra inverted (negative volume)"),
]


@pytest.mark.parametrize("change,code,words", MESHES,
                         ids=[w.split(",")[0][:40] for _, _, w in MESHES])
def test_a_tampered_mesh_is_refused_before_out(toy, tmp_path, capsys, change, code, words
                                               ) -> None:
    mesh = _tampered(toy, tmp_path / "brain.npz", change)
    out = tmp_path / "out"
    assert main(["brain", "--mesh", str(mesh), "--flap", "custom", "--out", str(out)]) == code
    line = one_line(capsys)
    assert words in line and str(mesh) in line and "rebuild" in line
    assert not out.exists()


def test_every_tet_inverted_is_refused_with_the_count(toy, tmp_path, capsys) -> None:
    mesh = _tampered(toy, tmp_path / "brain.npz", _swap_first_two)
    with np.load(mesh) as d:
        n = len(d["tets"])
    assert main(["brain", "--mesh", str(mesh), "--flap", "custom",
                 "--out", str(tmp_path / "out")]) == 5
    assert f"{n} of {n} tetrahedra inverted" in one_line(capsys)


def test_the_toy_mesh_itself_passes(toy) -> None:
    from brainbulge.cli import checks

    checks.brain_npz(toy)  # the checks refuse only what is wrong
    with zipfile.ZipFile(toy) as archive:
        assert "tets.npy" in archive.namelist()


# --------------------------------------------------------------------------- fibre images


def _fibres(path: Path, value) -> Path:
    v = np.zeros((6, 6, 6, 3), np.float32)
    v[..., 0] = 1.0
    v[2, 3, 1] = value
    nib.save(nib.Nifti1Image(v, np.diag([40.0, 40.0, 40.0, 1.0])), path)
    return path


@pytest.mark.parametrize("value,words", [
    ((np.nan, 0.0, 0.0), "1 voxels with a NaN or infinite component"),
    ((np.inf, 1.0, 0.0), "NaN or infinite"),
])
def test_fibre_values_are_checked_before_meshing(tmp_path, capsys, monkeypatch, value, words
                                                 ) -> None:
    import brainbulge.geometry.brain as brain

    def no_meshing(*args, **kwargs):
        raise AssertionError("meshing started before the fibre image was checked")

    monkeypatch.setattr(brain, "build_brain_mesh", no_meshing)
    fibres = _fibres(tmp_path / "v1.nii.gz", value)
    out = tmp_path / "out"
    assert main(["brain", "--fibres", str(fibres), "--out", str(out)]) == 2
    line = one_line(capsys)
    assert words in line and str(fibres) in line
    assert not out.exists()  # the corrected rerun into the same folder is not refused
