"""The default brain: the ICBM152 template meshed at a coarse size (30k target tets), as
the quick demo builds and saves it (its ``brain/mesh/brain.npz``, read back here)."""

from __future__ import annotations

import numpy as np
import pytest

from brainbulge.geometry.brain import TISSUES, build_brain_mesh, load_brain_mesh, to_ngsolve


@pytest.fixture(scope="module")
def icbm_mesh(quick_demo):
    _, out = quick_demo
    return load_brain_mesh(out / "brain" / "mesh" / "brain.npz")


def test_region_volumes_match_voxels(icbm_mesh) -> None:
    mesh_vol = icbm_mesh.tissue_volumes_ml()
    for name in TISSUES.values():
        assert mesh_vol[name] == pytest.approx(icbm_mesh.voxel_volumes_ml[name], rel=0.02), name
    # the template's brain mask is ~1.88 l; with the cisterns and the CSF layer ~2.0 l
    assert 1850 < sum(mesh_vol.values()) < 2150
    assert set(icbm_mesh.region_volumes_ml()) == {
        f"{t}_{s}" for t in TISSUES.values() for s in ("left", "right")}


def test_quality(icbm_mesh) -> None:
    q = icbm_mesh.quality()
    assert q["inverted_tets"] == 0
    assert q["min_dihedral_deg"] >= 10.0
    assert 15_000 < q["tets"] < 50_000


def test_cerebellum_and_brainstem_sit_where_they_should(icbm_mesh) -> None:
    c = icbm_mesh.nodes_mm[icbm_mesh.tets].mean(axis=1)
    cb = c[icbm_mesh.tissue == 4].mean(axis=0)
    bs = c[icbm_mesh.tissue == 5].mean(axis=0)
    assert cb[1] < -45 and cb[2] < -20  # posterior fossa (MNI mm)
    assert abs(bs[0]) < 5 and bs[1] > cb[1] and bs[2] < -15


def test_base_only_below_the_cut_plane(icbm_mesh) -> None:
    m = icbm_mesh
    zc = m.nodes_mm[m.faces][:, :, 2].mean(axis=1)
    assert -65 < m.base_z_mm < -45  # about foramen magnum level in MNI space
    assert m.base.any() and np.all(zc[m.base] < m.base_z_mm)
    assert not np.any(zc[~m.base] < m.base_z_mm)


def test_flap_areas(icbm_mesh) -> None:
    m = icbm_mesh
    left, right, frontal = (m.flap_area_cm2(n) for n in ("left", "right", "frontal"))
    assert 110 < left < 170  # a 12 cm opening on a curved skull
    assert right == pytest.approx(left, rel=0.05)
    assert frontal / left == pytest.approx(2.0, rel=0.05)
    zc = m.nodes_mm[m.faces][:, :, :].mean(axis=1)
    assert zc[m.flap_faces["left"], 0].max() < 10 and zc[m.flap_faces["right"], 0].min() > -10
    assert zc[m.flap_faces["frontal"], 1].mean() > 20


def test_ngsolve_mesh_of_the_template(icbm_mesh) -> None:
    import ngsolve as ngs

    mesh = to_ngsolve(icbm_mesh, flap="frontal")
    vol = icbm_mesh.region_volumes_ml()["white_left"]
    assert ngs.Integrate(1, mesh, definedon=mesh.Materials("white_left")) / 1000 == (
        pytest.approx(vol, rel=1e-9))
    flap = ngs.Integrate(1, mesh, ngs.BND, definedon=mesh.Boundaries("flap")) / 100
    assert flap == pytest.approx(icbm_mesh.flap_area_cm2("frontal"), rel=1e-9)


def test_skull_obstacle_is_open_over_the_flap(icbm_mesh) -> None:
    skull = icbm_mesh.skull("left", edge_radius_mm=3.0)
    flap = icbm_mesh.flaps["left"]
    out = np.asarray(flap.centre_mm) + 10 * np.asarray(flap.axis)
    assert skull.signed_distance(out[None])[0][0] < 0
    intact = icbm_mesh.skull(None)
    assert intact.signed_distance(out[None])[0][0] == pytest.approx(10.0, abs=0.5)


@pytest.mark.parametrize("name", ["left", "right", "frontal"])
def test_the_skull_opens_over_the_flap_only(icbm_mesh, name) -> None:
    """The obstacle is relieved (skull with the flap farther than the intact skull) only
    over the flap's faces: with each unilateral cutter 60 mm deep, 2 cm^2 of the middle
    cranial fossa opened too, and the cutter's inner corner creased the skull's normal
    there (Newton stagnated at a contact point on it)."""
    m = icbm_mesh
    assert m.free_area_cm2(name) == pytest.approx(m.flap_area_cm2(name), abs=0.01)
    others = np.setdiff1d(np.unique(m.faces), np.unique(m.faces[m.flap_faces[name]]))
    assert not m.flaps[name].contains(m.nodes_mm[others]).any()


@pytest.mark.slow
def test_paper_sized_mesh_quality_and_volumes() -> None:
    """Paper-sized mesh (the paper: 1.28M tets for 1108 ml): here ~400k tets of the template."""
    mesh = build_brain_mesh(target_tets=400_000, brain_volume_ml=1108.0)
    q = mesh.quality()
    assert q["inverted_tets"] == 0 and q["min_dihedral_deg"] >= 10.0
    assert 300_000 < q["tets"] < 550_000
    assert mesh.tet_volumes_mm3().sum() / 1000 == pytest.approx(1108.0, rel=0.01)
    vols = mesh.tissue_volumes_ml()
    for name in TISSUES.values():
        assert vols[name] == pytest.approx(mesh.voxel_volumes_ml[name], rel=0.02), name


@pytest.mark.slow
def test_fitted_interfaces_solve_the_left_flap_left_swelling_scenario(tmp_path, caplog) -> None:
    """The template with fitted tissue interfaces solves the left flap / left swelling
    scenario without a rejected load step (with the left cutter 60 mm deep, a pressed
    contact point on its inner corner in the middle cranial fossa stalled Newton beyond
    load 0.95), every tangent in PARDISO's symmetric mode: its pressure zones have small
    islands (two CSF tets sharing a vertex), whose singular pressure constants defeated
    Bunch-Kaufman's 2x2 pivots (relative residuals up to 1e2, LU for the rest of the run)."""
    import logging

    from brainbulge.studies.craniectomy import run_brain

    mesh = build_brain_mesh(target_tets=30_000, fit_tissue_interfaces=True)
    with caplog.at_level(logging.DEBUG, logger="brainbulge.solver.linear.direct"):
        summary = run_brain({"flap": "left", "swell": "left", "steps": 2}, tmp_path,
                            brain_mesh=mesh)
    assert summary["converged"]
    assert summary["rejected_steps"] == 0
    assert summary["newton_iterations"] <= 8
    misses = [r for r in caplog.records if "PARDISO symmetric mode" in r.getMessage()]
    assert not misses, misses[0].getMessage()
