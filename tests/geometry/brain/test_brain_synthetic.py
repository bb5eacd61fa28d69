"""Brain meshes of synthetic label images (nested ellipsoids, rotated anisotropic voxels).

Known geometry: a brain ellipsoid (semi-axes 60, 50, 45 mm) with a gray rind 7 mm thick around
white matter, a CSF "ventricle" and a spherical "cerebellum", sampled on a grid whose voxels
are 1.1 x 0.9 x 1.0 mm and rotated at random (so every step must go through the affine).
"""

from __future__ import annotations

import ngsolve as ngs
import nibabel as nib
import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from brainbulge.cli import main as cli_main
from brainbulge.errors import InputError
from brainbulge.geometry.brain import (
    RigidSkull,
    build_brain_mesh,
    load_brain_mesh,
    save_brain_mesh,
    tissue_image_from_labels,
    to_ngsolve,
)
from brainbulge.geometry.brain.boundaries import Flap
from brainbulge.geometry.brain.regions import MidSagittalPlane

SEMI_AXES_MM = np.array([60.0, 50.0, 45.0])
RIND_MM = 7.0
VENTRICLE_MM = np.array([14.0, 10.0, 8.0])
CEREBELLUM_CENTRE_MM = np.array([0.0, -30.0, -22.0])
CEREBELLUM_RADIUS_MM = 16.0


def synthetic_labels(seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(labels in FreeSurfer aseg codes, affine) of the nested-ellipsoid brain."""
    spacing = np.array([1.1, 0.9, 1.0])
    rot = Rotation.random(random_state=seed).as_matrix()
    shape = np.ceil(2 * 72 / spacing).astype(int)
    linear = rot @ np.diag(spacing)
    offset = -linear @ ((shape - 1) / 2)
    affine = np.eye(4)
    affine[:3, :3], affine[:3, 3] = linear, offset
    ijk = np.indices(shape).reshape(3, -1).T
    x = ijk @ linear.T + offset
    r_outer = np.sum((x / SEMI_AXES_MM) ** 2, axis=1)
    r_inner = np.sum((x / (SEMI_AXES_MM - RIND_MM)) ** 2, axis=1)
    r_vent = np.sum((x / VENTRICLE_MM) ** 2, axis=1)
    r_cb = np.linalg.norm(x - CEREBELLUM_CENTRE_MM, axis=1) / CEREBELLUM_RADIUS_MM
    left = x[:, 0] < 0
    labels = np.zeros(len(x), dtype=np.int16)
    labels[r_outer <= 1] = np.where(left, 3, 42)[r_outer <= 1]
    labels[r_inner <= 1] = np.where(left, 2, 41)[r_inner <= 1]
    labels[r_vent <= 1] = np.where(left, 4, 43)[r_vent <= 1]
    labels[r_cb <= 1] = np.where(left, 8, 47)[r_cb <= 1]
    return labels.reshape(shape), affine


@pytest.fixture(scope="module")
def synthetic_image():
    labels, affine = synthetic_labels()
    return tissue_image_from_labels(labels, affine, "freesurfer")


@pytest.fixture(scope="module")
def synthetic_mesh(synthetic_image):
    return build_brain_mesh(synthetic_image, target_tets=25_000,
                            midsagittal=MidSagittalPlane())


def test_voxel_volumes_match_the_ellipsoids(synthetic_image) -> None:
    v = synthetic_image.volumes_ml()
    brain = 4 / 3 * np.pi * np.prod(SEMI_AXES_MM) / 1000
    assert sum(v.values()) == pytest.approx(brain, rel=0.01)
    vent = 4 / 3 * np.pi * np.prod(VENTRICLE_MM) / 1000
    assert v["csf"] == pytest.approx(vent, rel=0.03)
    cb = 4 / 3 * np.pi * CEREBELLUM_RADIUS_MM**3 / 1000
    assert v["cerebellum"] == pytest.approx(cb, rel=0.02)


def test_region_volumes_within_2_percent(synthetic_mesh) -> None:
    mesh_vol = synthetic_mesh.tissue_volumes_ml()
    for name in ("gray", "white", "csf", "cerebellum"):
        assert mesh_vol[name] == pytest.approx(synthetic_mesh.voxel_volumes_ml[name], rel=0.02)
    # the skull leaves a CSF layer: intracranial volume > brain, by ~ area x layer
    assert mesh_vol["csf"] > 1.5 * 4 / 3 * np.pi * np.prod(VENTRICLE_MM) / 1000


def test_tags_quality_and_sides(synthetic_mesh) -> None:
    q = synthetic_mesh.quality()
    assert q["inverted_tets"] == 0 and q["min_volume_mm3"] > 0
    assert q["min_dihedral_deg"] >= 10.0
    assert 15_000 < q["tets"] < 40_000
    regions = synthetic_mesh.region_volumes_ml()
    # a symmetric body: equal halves (the thin CSF layer and ventricle sample noisier)
    for tissue, tol in (("gray", 0.05), ("white", 0.05), ("csf", 0.15), ("cerebellum", 0.1)):
        left, right = regions[f"{tissue}_left"], regions[f"{tissue}_right"]
        assert left == pytest.approx(right, rel=tol), tissue
    centroids = synthetic_mesh.nodes_mm[synthetic_mesh.tets].mean(axis=1)
    assert np.all((centroids[:, 0] > 0) == (synthetic_mesh.side == 1))


def test_boundaries(synthetic_mesh) -> None:
    m = synthetic_mesh
    zc = m.nodes_mm[m.faces][:, :, 2].mean(axis=1)
    assert m.base.any() and np.all(zc[m.base] < m.base_z_mm) and np.all(zc[~m.base] >= m.base_z_mm)
    for name in ("left", "right", "frontal"):
        assert not np.any(m.flap_faces[name] & m.base)
    # this small head (565 ml) cannot hold a bifrontal flap twice the 12 cm one: only larger
    assert m.flap_area_cm2("frontal") > 1.1 * m.flap_area_cm2("left")
    # mirror images up to the voxelisation of the rotated grid and the face-wise flap edge
    assert m.flap_area_cm2("left") == pytest.approx(m.flap_area_cm2("right"), rel=0.1)
    left_x = m.nodes_mm[m.faces[m.flap_faces["left"]]][:, :, 0].mean()
    assert left_x < -20


def test_to_ngsolve_volumes_and_boundaries(synthetic_mesh) -> None:
    from brainbulge.geometry.brain.boundaries import SuperiorBand, face_areas_mm2
    from brainbulge.geometry.brain.export import brain_summary

    band = SuperiorBand()
    mesh = to_ngsolve(synthetic_mesh, flap="left", superior=band)
    assert set(mesh.GetBoundaries()) == {"base", "superior", "skull", "flap"}
    superior = ngs.Integrate(1, mesh, ngs.BND, definedon=mesh.Boundaries("superior")) / 100
    # a 1 cm band over the vertex of this 12 cm long head (the left flap, a 12 cm one on a
    # small head, takes part of it)
    whole = brain_summary(synthetic_mesh)["superior"]["area_cm2"]
    assert whole > 5 and 0 < superior < whole
    names = synthetic_mesh.boundary_names("left", band)
    areas = face_areas_mm2(synthetic_mesh.nodes_mm, synthetic_mesh.faces)
    assert superior == pytest.approx(areas[names == "superior"].sum() / 100, rel=1e-9)
    regions = synthetic_mesh.region_volumes_ml()
    assert set(mesh.GetMaterials()) == set(regions)
    for name, vol_ml in regions.items():
        assert ngs.Integrate(1, mesh, definedon=mesh.Materials(name)) / 1000 == pytest.approx(
            vol_ml, rel=1e-9)
    flap = ngs.Integrate(1, mesh, ngs.BND, definedon=mesh.Boundaries("flap")) / 100
    assert flap == pytest.approx(synthetic_mesh.flap_area_cm2("left"), rel=1e-9)
    n = ngs.specialcf.normal(3)  # outward normals: divergence theorem gives the volume
    total = ngs.Integrate(n[0] * ngs.x, mesh, ngs.BND) / 1000
    assert total == pytest.approx(sum(regions.values()), rel=1e-9)


def test_rigid_skull_signed_distance(synthetic_mesh) -> None:
    skull = RigidSkull(synthetic_mesh.envelope)
    # surface nodes lie on the skull; points pushed out along the normal penetrate by that much
    surf = np.unique(synthetic_mesh.faces)
    pts = synthetic_mesh.nodes_mm[surf]
    phi, grad = skull.signed_distance(pts)
    assert np.abs(phi).max() < 0.3
    assert np.linalg.norm(grad, axis=1) == pytest.approx(1.0, abs=0.1)
    out = pts + 2.0 * grad
    assert skull.signed_distance(out)[0] == pytest.approx(2.0, abs=0.2)
    assert np.all(skull.signed_distance(np.zeros((1, 3)))[0] < -30)
    # finite-difference gradient
    rng = np.random.default_rng(3)
    x = pts[:50] + rng.normal(scale=3.0, size=(50, 3))
    h = 1e-3
    fd = np.stack([(skull.signed_distance(x + h * e)[0] - skull.signed_distance(x - h * e)[0])
                   / (2 * h) for e in np.eye(3)], axis=1)
    assert np.abs(fd - skull.signed_distance(x)[1]).max() < 0.1


def test_flap_removes_obstacle_with_rounded_edge(synthetic_mesh) -> None:
    flap: Flap = synthetic_mesh.flaps["left"]
    skull = synthetic_mesh.skull("left", edge_radius_mm=3.0)
    c, a = np.asarray(flap.centre_mm), np.asarray(flap.axis)
    bulge = c[None] + np.outer([2.0, 10.0, 30.0], a)
    assert np.all(skull.signed_distance(bulge)[0] < 0)  # no obstacle in the opening
    m = synthetic_mesh
    surface = m.nodes_mm[np.unique(m.faces)]
    far = surface[flap.cutter_distance(surface)[0] > 10.0]
    assert len(far) > 100
    intact = RigidSkull(synthetic_mesh.envelope).signed_distance(far + 1.0)[0]
    assert skull.signed_distance(far + 1.0)[0] == pytest.approx(intact)
    # 1 mm outside the skull surface: penetration far from the cutter, none inside it, and a
    # smooth transition (gradient = finite differences) within the rounded rim
    surface_out = surface + 1.0 * RigidSkull(m.envelope).signed_distance(surface)[1]
    d_cut = flap.cutter_distance(surface_out)[0]
    phi, grad = skull.signed_distance(surface_out)
    assert np.abs(phi[d_cut > 6.0] - 1.0).max() < 0.25  # surface nodes sit on chords
    assert np.all(phi[d_cut < -6.0] < 0)
    rim = surface_out[np.abs(d_cut) < 4.0]
    assert len(rim) > 20
    h = 1e-3
    fd = np.stack([(skull.signed_distance(rim + h * e)[0] - skull.signed_distance(rim - h * e)[0])
                   / (2 * h) for e in np.eye(3)], axis=1)
    assert np.abs(fd - skull.signed_distance(rim)[1]).max() < 0.1
    # the distances alone (the summary's tests of millions of points) are the same numbers
    for pts in (rim, surface_out, far + 1.0):
        assert np.array_equal(skull.signed_distance(pts, gradient=False)[0],
                              skull.signed_distance(pts)[0])
        assert np.array_equal(skull.envelope_distance(pts, gradient=False)[0],
                              skull.envelope_distance(pts)[0])
    assert skull.signed_distance(rim, gradient=False)[1] is None


def test_scaling_to_brain_volume(synthetic_image) -> None:
    mesh = build_brain_mesh(synthetic_image, target_tets=8_000, brain_volume_ml=400.0)
    # scaled on the voxel volume; the coarse mesh's chords cut ~1 % off the smooth surface
    assert mesh.tet_volumes_mm3().sum() / 1000 == pytest.approx(400.0, rel=0.02)
    ratio = mesh.tissue_volumes_ml()["white"] / mesh.voxel_volumes_ml["white"]
    assert ratio == pytest.approx(1.0, rel=0.02)


def test_save_load_roundtrip(synthetic_mesh, tmp_path) -> None:
    paths = save_brain_mesh(synthetic_mesh, tmp_path, flap="frontal")
    for key in ("vtu", "npz", "json", "sections", "boundaries"):
        assert paths[key].is_file() and paths[key].stat().st_size > 0
    back = load_brain_mesh(paths["npz"])
    assert np.array_equal(back.tets, synthetic_mesh.tets)
    assert back.flap_area_cm2("frontal") == pytest.approx(synthetic_mesh.flap_area_cm2("frontal"))


@pytest.mark.slow
def test_cli_mesh_on_user_labels(tmp_path, capsys) -> None:
    labels, affine = synthetic_labels(seed=5)
    path = tmp_path / "aseg.nii.gz"
    nib.save(nib.Nifti1Image(labels, affine), str(path))
    out = tmp_path / "out"
    code = cli_main(["mesh", "--out", str(out), "--labels", str(path), "--label-map", "aseg",
                     "--tets", "6000", "--flap", "custom", "--flap-centre", "0", "0", "60",
                     "--flap-diameter", "80", "--no-figures"])
    assert code == 0, capsys.readouterr().err
    assert (out / "mesh.json").is_file() and (out / "brain.vtu").is_file()
    bad = tmp_path / "bad.nii.gz"
    bad.write_text("garbage")
    code = cli_main(["mesh", "--out", str(tmp_path / "o2"), "--labels", str(bad)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith("error: cannot read") and "\n" not in err


@pytest.fixture(scope="module")
def coarse_and_refined(synthetic_image):
    """Netgen's mesh at 4k target tets, and the 32k-tet mesh built from it by one refinement
    (new surface nodes onto the skull's inner surface)."""
    coarse = build_brain_mesh(synthetic_image, target_tets=4_000, brain_volume_ml=400.0)
    fine = build_brain_mesh(synthetic_image, target_tets=32_000, brain_volume_ml=400.0,
                            refinements=1)
    return coarse, fine


def test_refined_mesh_is_nested_in_the_netgen_mesh(coarse_and_refined) -> None:
    """``refinements=1``: Netgen's mesh at a size of 1/8, refined: its nodes come first and
    unchanged, eight times the tets, the new surface nodes on the skull's inner surface, the
    tissue volumes those of the image as on a mesh built directly."""
    coarse, fine = coarse_and_refined
    assert len(fine.tets) == 8 * len(coarse.tets)
    assert np.array_equal(fine.nodes_mm[: len(coarse.nodes_mm)], coarse.nodes_mm)
    # tissues tagged and fitted on the Netgen mesh: each child keeps its parent's (children
    # come in blocks of eight), so the interfaces are the Netgen mesh's
    assert np.array_equal(fine.tissue.reshape(-1, 8), np.repeat(coarse.tissue[:, None], 8, 1))
    assert fine.quality()["inverted_tets"] == 0
    skull = fine.skull(None)
    new_surface = np.setdiff1d(np.unique(fine.faces), np.arange(len(coarse.nodes_mm)))
    gap_new = np.abs(skull.envelope_distance(fine.nodes_mm[new_surface], gradient=False)[0])
    midpoints = fine.nodes_mm[coarse.faces].mean(axis=1)  # chord points, for scale
    gap_chord = np.abs(skull.envelope_distance(midpoints, gradient=False)[0])
    assert np.median(gap_new) < 1e-3 < np.median(gap_chord)
    for tissue in ("white", "gray"):
        ratio = fine.tissue_volumes_ml()[tissue] / fine.voxel_volumes_ml[tissue]
        assert ratio == pytest.approx(1.0, rel=0.02)
    assert set(fine.flaps) == set(coarse.flaps)
    assert fine.flap_area_cm2("frontal") == pytest.approx(coarse.flap_area_cm2("frontal"),
                                                            rel=0.1)


def test_flat_refinement_keeps_the_netgen_geometry(synthetic_image, coarse_and_refined) -> None:
    """``refine_onto_envelope=False``: the new surface nodes stay at the midpoints of the
    coarse surface edges, so the refined mesh has exactly the coarse mesh's volume (the
    refinement onto the envelope adds the chords' gap, > 0.1 % here)."""
    from brainbulge.results.measures.brain_metrics import brain_volume_ml

    coarse, moved = coarse_and_refined
    flat = build_brain_mesh(synthetic_image, target_tets=32_000, brain_volume_ml=400.0,
                            refinements=1, refine_onto_envelope=False)
    v_coarse = brain_volume_ml(coarse.nodes_mm, coarse.tets)
    assert brain_volume_ml(flat.nodes_mm, flat.tets) == pytest.approx(v_coarse, rel=1e-12)
    assert brain_volume_ml(moved.nodes_mm, moved.tets) > (1 + 1e-3) * v_coarse
    edges = np.sort(coarse.faces[:, [0, 1]], axis=1)
    mid = coarse.nodes_mm[edges].mean(axis=1)
    d, _ = cKDTree(flat.nodes_mm).query(mid)
    assert d.max() < 1e-9  # every surface edge's midpoint is a node


def test_too_coarse_a_mesh_to_refine_is_refused(synthetic_image) -> None:
    from brainbulge.errors import InputError

    with pytest.raises(InputError, match="fewer refinements or more tets"):
        build_brain_mesh(synthetic_image, target_tets=30_000, refinements=2)


@pytest.mark.slow
def test_cli_mesh_refine(tmp_path, capsys) -> None:
    """``brainbulge mesh --refine 1``: eight times Netgen's tets, recorded in mesh.json."""
    import json

    labels, affine = synthetic_labels(seed=5)
    path = tmp_path / "aseg.nii.gz"
    nib.save(nib.Nifti1Image(labels, affine), str(path))
    runs = {}
    for refine in ("0", "1"):
        out = tmp_path / f"r{refine}"
        code = cli_main(["mesh", "--out", str(out), "--labels", str(path), "--label-map",
                         "aseg", "--tets", "6000" if refine == "0" else "48000", "--refine",
                         refine, "--no-figures"])
        assert code == 0, capsys.readouterr().err
        runs[refine] = json.loads((out / "mesh.json").read_text())["tets"]
    assert runs["1"] == 8 * runs["0"]


@pytest.mark.parametrize("volume_of", ["brain", "white"])
def test_scaling_to_the_brain_or_its_white_matter(synthetic_image, volume_of) -> None:
    """``volume_of`` picks what ``brain_volume_ml`` sets: 0.7 of the image's gray + white (or
    white) matter comes out so in the mesh, and the other tissues shrink by the same ratio."""
    voxel = synthetic_image.volumes_ml()
    before = voxel["white"] + (voxel["gray"] if volume_of == "brain" else 0.0)
    mesh = build_brain_mesh(synthetic_image, target_tets=8_000, brain_volume_ml=0.7 * before,
                            volume_of=volume_of)
    vols = mesh.tissue_volumes_ml()
    after = vols["white"] + (vols["gray"] if volume_of == "brain" else 0.0)
    assert after == pytest.approx(0.7 * before, rel=0.03)
    assert vols["cerebellum"] == pytest.approx(0.7 * voxel["cerebellum"], rel=0.03)
    with pytest.raises(InputError, match="volume_of"):
        build_brain_mesh(synthetic_image, target_tets=8_000, brain_volume_ml=100.0,
                         volume_of="skull")
