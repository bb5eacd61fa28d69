"""The NIfTI maps of a 3D run (results/export/nifti.py) on a toy brain segmented on an
oblique, non-RAS grid (x flipped, rotated 20 deg about z and 10 deg about x):

- every map loads with nibabel and nilearn, on the label image's own shape and affine;
- the map lies on the tissue of that image (the located voxels are the segmentation's);
- the voxels are located in the elements NGSolve's own point location (``mesh(x, y, z)``)
  finds; the maps of fields linear in the element (displacement, pressure) are the solution
  NGSolve evaluates at the voxel centres, to float32 rounding; those of the strains within
  their interpolation error; at a voxel centre on a mesh vertex every map is the vertex's;
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
    map_fields,
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


@pytest.fixture(scope="module")
def located(oblique):
    """The vertex fields, the voxels located and their values, and the solution NGSolve
    evaluates at the voxel centres by its own point location (``mesh(x, y, z)``)."""
    run = oblique["run"]
    form, bm = run.form, run.bm
    G = recovered_gradient(form.mesh, form.output_displacement())
    vf = vertex_fields(form, bm.envelope.centre_mm(), gradient=G, corners=map_fields())
    hits = locate_voxels(vf.points, vf.cells, bm.image_grid)
    ijk = np.stack(np.unravel_index(hits.index, bm.image_grid.shape), axis=1)
    M = bm.image_grid.index_to_mesh()
    centres = ijk @ M[:3, :3].T + M[:3, 3]
    points = form.mesh(*centres.T)
    exact = output_fields(sample(form, points, gradient=G), bm.envelope.centre_mm())
    return {"vf": vf, "hits": hits, "centres": centres, "ngsolve": points, "exact": exact,
            "values": voxel_values(hits, vf.corner_data)}


def test_the_voxels_are_located_as_ngsolve_locates_them(located) -> None:
    hits, vf, centres = located["hits"], located["vf"], located["centres"]
    assert np.all(located["ngsolve"]["nr"] >= 0)
    assert np.mean(located["ngsolve"]["nr"] == hits.element) > 0.99  # the rest on faces
    corners = vf.points[vf.cells[hits.element]]
    np.testing.assert_allclose(np.einsum("nk,nkc->nc", hits.weights, corners), centres,
                               atol=1e-9)
    assert hits.weights.min() > -1e-8


def test_linear_fields_are_the_solution_at_the_voxel_centres(located, oblique) -> None:
    """The MINI element's displacement and pressure are linear in each element: their maps
    are the solution at the voxel centres, to float32 rounding."""
    assert oblique["run"].case.element == "mini"
    same = located["ngsolve"]["nr"] == located["hits"].element
    for field in ("u", "pressure"):
        exact, mapped = np.asarray(located["exact"][field]), located["values"][field]
        err = np.abs(mapped - exact).reshape(len(exact), -1).max(axis=1) / np.abs(exact).max()
        print(field, err[same].max(), err[~same].max(initial=0), np.sort(err)[-5:])
        assert err[same].max() <= 1e-6, field
    strain = np.asanyarray(nib.load(oblique["maps"] / "max_principal_strain.nii.gz").dataobj)
    np.testing.assert_array_equal(strain.ravel()[located["hits"].index],
                                  located["values"]["max_principal_strain"])


def test_the_strain_maps_interpolation_error(located) -> None:
    """Stretches and strains come from the recovered gradient, and each map holds their
    vertex values interpolated: the median error a small fraction of their range (the
    largest at region interfaces, where the vertex values average both sides)."""
    for field in ("max_principal_strain", "lambda_n", "lambda_t", "Je"):
        exact, mapped = np.asarray(located["exact"][field]), located["values"][field]
        spread = np.percentile(exact, 99) - np.percentile(exact, 1)
        err = np.abs(mapped - exact) / spread
        print(field, np.median(err), np.percentile(err, 95), err.max())
        assert np.median(err) < 0.1 and np.percentile(err, 95) < 0.3, field


def test_a_voxel_centre_on_a_mesh_vertex_takes_its_values(oblique, located) -> None:
    bm, vf = oblique["run"].bm, located["vf"]
    v = int(np.argmin(np.linalg.norm(vf.points - bm.envelope.centre_mm(), axis=1)))
    grid = bm.image_grid
    shift = np.eye(4)  # move the grid so that voxel (20, 20, 20) lies on vertex v
    shift[:3, 3] = vf.points[v] - (grid.index_to_mesh() @ [20.0, 20.0, 20.0, 1.0])[:3]
    on_vertex = dataclasses.replace(grid, to_mesh=shift @ grid.to_mesh)
    hits = locate_voxels(vf.points, vf.cells, on_vertex)
    at = np.flatnonzero(hits.index == np.ravel_multi_index((20, 20, 20), grid.shape))[0]
    values = voxel_values(hits, vf.corner_data)
    corner = np.flatnonzero(vf.cells[hits.element[at]] == v)[0]
    for stem, (field, _, _) in MAPS.items():  # the value at the element's own vertex
        own = vf.corner_data[field][hits.element[at], corner]
        np.testing.assert_allclose(values[field][at], own, rtol=1e-6,
                                   atol=1e-6 * np.abs(own).max(), err_msg=stem)
    np.testing.assert_allclose(values["u"][at], vf.point_data["u"][v], rtol=1e-6)


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


def test_the_study_report_shows_each_scenarios_strain_map(oblique, tmp_path) -> None:
    import shutil

    from brainbulge.results.present.craniectomy_report import write_report

    scenario = tmp_path / "left-flap_both-swelling"
    shutil.copytree(oblique["maps"], scenario / "maps")
    write_report(tmp_path, [{"name": scenario.name}], [{"complete": True}])
    report = (tmp_path / "report.md").read_text()
    assert f"]({scenario.name}/maps/max_principal_strain.png)" in report
    html = (tmp_path / "report.html").read_text()
    assert html.count("data:image/png;base64") >= 1  # inlined: the page opens offline


def test_docs_list_every_map() -> None:
    from pathlib import Path

    page = (Path(__file__).resolve().parents[2] / "docs" / "outputs.md").read_text()
    section = page.split("## NIfTI maps", 1)[1].split("\n## ", 1)[0]
    listed = {line.split("`")[1] for line in section.splitlines() if line.startswith("| `")}
    assert listed == set(map_files())


def test_a_mesh_file_keeps_its_image_grid(oblique, tmp_path) -> None:
    from brainbulge.geometry.brain import load_brain_mesh, save_brain_mesh

    grid = oblique["run"].bm.image_grid
    save_brain_mesh(oblique["run"].bm, tmp_path, figures=False)
    loaded = load_brain_mesh(tmp_path / "brain.npz").image_grid
    assert loaded.shape == grid.shape and loaded.source == str(oblique["path"].resolve())
    np.testing.assert_array_equal(loaded.affine, grid.affine)
    np.testing.assert_array_equal(loaded.to_mesh, grid.to_mesh)


def test_a_scaled_brain_still_lies_on_its_image(oblique) -> None:
    """``brain_volume_ml`` scales the mesh about the envelope's centre: the grid carries the
    scaling, so the voxels located in the scaled mesh are still the image's tissue."""
    image = load_tissue_image(oblique["path"], "synthseg")
    bm = build_brain_mesh(image, target_tets=1000, brain_volume_ml=900.0)
    assert not np.allclose(bm.image_grid.to_mesh, np.eye(4))
    np.testing.assert_allclose(bm.image_grid.affine, oblique["affine"], atol=1e-6)  # float32 header
    hits = locate_voxels(bm.nodes_mm, bm.tets, bm.image_grid, weights=False)
    mapped = np.zeros(oblique["shape"], dtype=bool)
    mapped.ravel()[hits.index] = True
    brain = np.asanyarray(nib.load(oblique["path"]).dataobj) > 0
    assert 2 * np.sum(brain & mapped) / (brain.sum() + mapped.sum()) > 0.9


def test_the_deformed_label_map_gains_the_swelling_volume(oblique) -> None:
    """Incompressible tissue that swells by ``swelling_volume_ml`` takes that much more
    room: the deformed label map counts it in voxels (to the voxels' resolution; on the
    111k-tet template 60,395 voxels of 1 mm^3 for 60.44 ml)."""
    import json

    summary = json.loads((oblique["maps"].parent / "summary.json").read_text())
    voxel_ml = abs(np.linalg.det(oblique["affine"][:3, :3])) / 1000
    count = {name: np.count_nonzero(np.asanyarray(nib.load(
        oblique["maps"] / f"{name}.nii.gz").dataobj)) for name in ("tissue", "tissue_deformed")}
    gained = (count["tissue_deformed"] - count["tissue"]) * voxel_ml
    assert gained == pytest.approx(summary["swelling_volume_ml"], rel=0.25)
