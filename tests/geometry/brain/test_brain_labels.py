"""Label images -> tissues: presets, custom maps, and one-line errors for bad input."""

from __future__ import annotations

import json

import nibabel as nib
import numpy as np
import pytest

from brainbulge.errors import InputError
from brainbulge.geometry.brain.labels import (
    CEREBELLUM,
    CSF,
    GRAY,
    WHITE,
    load_tissue_image,
    read_label_map,
    tissue_image_from_labels,
)


def _aseg_like() -> np.ndarray:
    labels = np.zeros((12, 12, 12), dtype=np.int16)
    labels[2:10, 2:10, 2:10] = 3  # left cortex
    labels[4:8, 4:8, 4:8] = 2  # left white
    labels[5:7, 5:7, 5:7] = 4  # left lateral ventricle
    labels[2:4, 2:4, 2:4] = 8  # left cerebellum cortex
    return labels


def test_freesurfer_preset_maps_aseg_codes() -> None:
    image = tissue_image_from_labels(_aseg_like(), np.eye(4), "synthseg")
    t = image.tissue
    assert t[2, 2, 2] == CEREBELLUM and t[5, 5, 5] == CSF and t[4, 4, 4] == WHITE
    assert t[9, 9, 9] == GRAY and t[0, 0, 0] == 0
    v = image.volumes_ml()
    assert v["csf"] == pytest.approx(8 / 1000) and v["cerebellum"] == pytest.approx(8 / 1000)


def test_gmwmcsf_preset_and_json_map(tmp_path) -> None:
    labels = np.zeros((6, 6, 6), dtype=np.uint8)
    labels[1:5, 1:5, 1:5] = 2
    labels[2:4, 2:4, 2:4] = 3
    labels[1, 1, 1] = 1
    image = tissue_image_from_labels(labels, np.diag([2.0, 2.0, 2.0, 1.0]), "gmwmcsf")
    assert image.voxel_volume_mm3 == pytest.approx(8.0)
    assert image.volumes_ml()["white"] == pytest.approx(8 * 8 / 1000)
    path = tmp_path / "map.json"
    path.write_text(json.dumps({"gray": [2], "white": [3], "csf": [1]}))
    assert read_label_map(path) == {"gray": [2], "white": [3], "csf": [1]}


def _one_line(err: pytest.ExceptionInfo) -> str:
    msg = str(err.value)
    assert "\n" not in msg and len(msg) < 300
    return msg


def test_unreadable_file_is_one_line_error(tmp_path) -> None:
    bad = tmp_path / "labels.nii.gz"
    bad.write_bytes(b"not a nifti file")
    with pytest.raises(InputError) as err:
        load_tissue_image(bad, "freesurfer")
    assert "cannot read" in _one_line(err)
    with pytest.raises(InputError) as err:
        load_tissue_image(tmp_path / "missing.nii.gz", "freesurfer")
    _one_line(err)


def test_non_integer_labels_rejected(tmp_path) -> None:
    prob = np.random.default_rng(0).random((8, 8, 8)).astype(np.float32)
    path = tmp_path / "prob.nii.gz"
    nib.save(nib.Nifti1Image(prob, np.eye(4)), str(path))
    with pytest.raises(InputError) as err:
        load_tissue_image(path, "freesurfer")
    assert "non-integer" in _one_line(err)


def test_missing_labels_and_empty_region() -> None:
    with pytest.raises(InputError) as err:
        tissue_image_from_labels(np.full((5, 5, 5), 99), np.eye(4), "freesurfer")
    assert "codes occur" in _one_line(err)
    only_gray = np.zeros((5, 5, 5), dtype=int)
    only_gray[1:4, 1:4, 1:4] = 3
    with pytest.raises(InputError) as err:
        tissue_image_from_labels(only_gray, np.eye(4), "freesurfer")
    assert "'white' is empty" in _one_line(err)


@pytest.mark.parametrize("voxel_mm", [0.01, 12.0])
def test_absurd_voxel_size(voxel_mm: float) -> None:
    with pytest.raises(InputError) as err:
        tissue_image_from_labels(_aseg_like(), np.diag([voxel_mm] * 3 + [1.0]), "freesurfer")
    assert "voxel size" in _one_line(err)


def test_bad_label_map(tmp_path) -> None:
    with pytest.raises(InputError) as err:
        read_label_map("no-such-preset")
    _one_line(err)
    path = tmp_path / "bad.json"
    path.write_text("{not json")
    with pytest.raises(InputError):
        read_label_map(path)
    path.write_text(json.dumps({"gray": [1], "white": [2], "bone": [3]}))
    with pytest.raises(InputError) as err:
        read_label_map(path)
    assert "unknown tissue" in _one_line(err)
