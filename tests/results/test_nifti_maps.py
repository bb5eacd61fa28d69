"""The NIfTI maps of a 3D run (results/export/nifti.py) on a toy brain segmented on an
oblique, non-RAS grid (x flipped, rotated 20 deg about z and 10 deg about x):

- every map loads with nibabel and nilearn, on the label image's own shape and affine;
- the map lies on the tissue of that image (the located voxels are the segmentation's);
- the values are the solution's: where NGSolve's own point location (``mesh(x, y, z)``)
  finds the same element, equal to float32 rounding; at a voxel centre on a mesh vertex,
  the displacement is the vertex's;
- the damage masks are the strain map thresholded in the parenchyma;
- a mesh file that does not record its image grid gives no maps, with a warning.
"""

from __future__ import annotations

import dataclasses

import nibabel as nib
import numpy as np
import pytest

from brainbulge.geometry.brain import build_brain_mesh, load_tissue_image
from brainbulge.results.export.nifti import (
    MAPS,
    damage_mask_name,
    locate_voxels,
    map_files,
    voxel_values,
)
from brainbulge.results.export.writers import vertex_fields
from brainbulge.results.measures.fields import output_fields, sample
from brainbulge.results.measures.plan_defaults import DAMAGE_THRESHOLDS
from brainbulge.results.measures.recovery import recovered_gradient
from brainbulge.studies.craniectomy import solve_brain, write_brain_outputs
from toy_brain import toy_labels


def rotation(axis: int, deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    i, j = [a for a in range(3) if a != axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


@pytest.fixture(scope="module")
def oblique(tmp_path_factory):
    folder = tmp_path_factory.mktemp("oblique")
    straight = nib.load(toy_labels(folder / "straight.nii.gz"))
    n = np.asarray(straight.shape)
    linear = rotation(0, 10.0) @ rotation(2, 20.0) @ np.diag([-3.0, 3.0, 3.0])  # LAS, oblique
    affine = np.eye(4)
    affine[:3, :3] = linear
    affine[:3, 3] = -linear @ ((n - 1) / 2)  # the ellipsoid's centre at the origin
    path = folder / "seg.nii.gz"
    nib.save(nib.Nifti1Image(np.asanyarray(straight.dataobj), affine), path)
    image = load_tissue_image(path, "synthseg")
    bm = build_brain_mesh(image, target_tets=1000)
    run = solve_brain({"flap": "left", "steps": 1, "tolerance": 1e-6}, folder / "run",
                      brain_mesh=bm)
    write_brain_outputs(run, folder / "run")
    return {"path": path, "affine": affine, "shape": tuple(n), "run": run,
            "maps": folder / "run" / "maps"}


def test_every_map_loads_on_the_label_image_grid(oblique) -> None:
    from nilearn import image as nimg

    names = sorted(p.name for p in oblique["maps"].iterdir())
    assert names == sorted(map_files())
    for name in names:
        if not name.endswith(".nii.gz"):
            continue
        img = nib.load(oblique["maps"] / name)
        assert img.shape[:3] == oblique["shape"]
        np.testing.assert_allclose(img.affine, oblique["affine"], atol=1e-6)
        assert nib.aff2axcodes(img.affine) == nib.aff2axcodes(oblique["affine"])
        assert nimg.load_img(oblique["maps"] / name).shape == img.shape  # nilearn reads it
    u = nib.load(oblique["maps"] / "displacement.nii.gz")
    assert u.shape == (*oblique["shape"], 1, 3) and u.header.get_intent()[0] == "vector"
    strain = nib.load(oblique["maps"] / "max_principal_strain.nii.gz")
    assert strain.get_data_dtype() == np.float32


def test_the_map_lies_on_the_tissue_of_the_image(oblique) -> None:
    labels = np.asanyarray(nib.load(oblique["path"]).dataobj)
    brain = labels > 0
    strain = np.asanyarray(nib.load(oblique["maps"] / "max_principal_strain.nii.gz").dataobj)
    mapped = np.isfinite(strain)
    dice = 2 * np.sum(brain & mapped) / (brain.sum() + mapped.sum())
    assert dice > 0.9
    tissue = np.asanyarray(nib.load(oblique["maps"] / "tissue.nii.gz").dataobj)
    white = np.isin(labels, [2, 41])
    assert np.mean(tissue[white] == 2) > 0.85  # white matter where the image has it
    assert np.array_equal(tissue > 0, mapped)  # NaN exactly outside the tissue


def test_values_are_the_solution_at_the_voxel_centres(oblique) -> None:
    run = oblique["run"]
    form, bm = run.form, run.bm
    G = recovered_gradient(form.mesh, form.output_displacement())
    vf = vertex_fields(form, bm.envelope.centre_mm(), gradient=G)
    hits = locate_voxels(vf.points, vf.cells, bm.image_grid)
    values = voxel_values(form, hits, bm.envelope.centre_mm(), None, G)
    ijk = np.stack(np.unravel_index(hits.index, bm.image_grid.shape), axis=1)
    M = bm.image_grid.index_to_mesh()
    centres = ijk @ M[:3, :3].T + M[:3, 3]
    np.testing.assert_allclose(values["X"], centres, atol=1e-9)
    located = form.mesh(*centres.T)  # NGSolve's own point location
    assert np.all(located["nr"] >= 0)
    same = located["nr"] == hits.element
    assert same.mean() > 0.99  # the rest lie on shared faces
    expected = output_fields(sample(form, located, gradient=G), bm.envelope.centre_mm())
    for stem, (field, _, _) in MAPS.items():
        a, b = np.asarray(expected[field])[same], values[field][same]
        scale = np.abs(a).max()
        assert np.abs(a - b).max() <= 1e-6 * scale, stem
    # the written file holds these values
    strain = np.asanyarray(nib.load(oblique["maps"] / "max_principal_strain.nii.gz").dataobj)
    np.testing.assert_array_equal(strain.ravel()[hits.index], values["max_principal_strain"])


def test_a_voxel_centre_on_a_mesh_vertex_takes_its_displacement(oblique) -> None:
    run = oblique["run"]
    form, bm = run.form, run.bm
    vf = vertex_fields(form, bm.envelope.centre_mm())
    v = int(np.argmin(np.linalg.norm(vf.points - bm.envelope.centre_mm(), axis=1)))
    grid = bm.image_grid
    shift = np.eye(4)  # move the grid so that voxel (20, 20, 20) lies on vertex v
    shift[:3, 3] = vf.points[v] - (grid.index_to_mesh() @ [20.0, 20.0, 20.0, 1.0])[:3]
    on_vertex = dataclasses.replace(grid, to_mesh=shift @ grid.to_mesh)
    hits = locate_voxels(vf.points, vf.cells, on_vertex)
    at = np.flatnonzero(hits.index == np.ravel_multi_index((20, 20, 20), grid.shape))
    values = voxel_values(form, hits, bm.envelope.centre_mm(), None, None)
    u = values["u"][at[0]]
    np.testing.assert_allclose(u, vf.point_data["u"][v],
                               rtol=1e-6, atol=1e-6 * np.abs(vf.point_data["u"]).max())


def test_damage_masks_threshold_the_strain_in_the_parenchyma(oblique) -> None:
    strain = np.asanyarray(nib.load(oblique["maps"] / "max_principal_strain.nii.gz").dataobj)
    tissue = np.asanyarray(nib.load(oblique["maps"] / "tissue.nii.gz").dataobj)
    parenchyma = np.isin(tissue, [1, 2, 4, 5])
    for threshold in DAMAGE_THRESHOLDS.values():
        mask = np.asanyarray(nib.load(oblique["maps"] /
                                      f"{damage_mask_name(threshold)}.nii.gz").dataobj)
        assert mask.dtype == np.uint8
        np.testing.assert_array_equal(mask == 1, parenchyma & (np.nan_to_num(strain) > threshold))
    deformed = np.asanyarray(nib.load(oblique["maps"] / "tissue_deformed.nii.gz").dataobj)
    assert 0 < np.sum(deformed != tissue) < 0.2 * np.sum(tissue > 0)  # moved, not elsewhere


def test_a_mesh_without_its_image_grid_gives_no_maps(oblique, tmp_path, caplog) -> None:
    run = dataclasses.replace(oblique["run"], bm=dataclasses.replace(oblique["run"].bm,
                                                                     image_grid=None))
    write_brain_outputs(run, tmp_path)
    assert not (tmp_path / "maps").exists()
    assert "no NIfTI maps" in caplog.text
    assert (tmp_path / "summary.json").is_file()
