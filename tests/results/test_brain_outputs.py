"""The named outputs of a 3D scenario: what each key means, on prescribed fields and on a
solved toy brain (docs/outputs.md)."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest

from brainbulge.geometry.brain import MidSagittalPlane
from brainbulge.results.measures.brain_metrics import (
    MONRO_MNI_MM,
    TEMPLATE_BOX_MM,
    MonroLocation,
    interpolate_p1,
    locate_monro,
    monro_midline_shift_mm,
)
from brainbulge.results.measures.summary import constraint_statistics
from simple_meshes import box_mesh

PLANE = MidSagittalPlane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))


def test_p1_interpolation_is_exact_for_a_linear_field() -> None:
    nodes, tets = box_mesh(4, -10.0, 10.0)
    A = np.array([[1.0, 2.0, -1.0], [0.5, 0.0, 3.0], [0.0, -1.0, 1.0]])
    u = nodes @ A.T + 1.0
    pts = np.random.default_rng(0).uniform(-9.9, 9.9, (200, 3))
    got, found = interpolate_p1(nodes, tets, u, pts)
    assert found.all()
    assert got == pytest.approx(pts @ A.T + 1.0, abs=1e-9)
    _, outside = interpolate_p1(nodes, tets, u, np.array([[20.0, 0.0, 0.0]]))
    assert not outside.any()


def test_the_monro_shift_on_a_synthetic_shifted_plane() -> None:
    """The mid-sagittal plane moves by ``s`` to the left around the Monro level and by up
    to 15 mm more above z = 10 mm: the clinical shift is ``s`` (signed: left negative), the
    whole-plane maximum is at the top."""
    nodes, tets = box_mesh(16, -40.0, 40.0)  # nodes every 5 mm: the kink at z = 10 is exact
    s = -2.5
    u = np.zeros_like(nodes)
    u[:, 0] = s - 0.5 * np.maximum(nodes[:, 2] - 10.0, 0.0)
    monro = MonroLocation((0.0, 0.0, 0.0), "template")
    got = monro_midline_shift_mm(nodes, tets, u, PLANE, monro)
    assert got["midline_shift_mm"] == pytest.approx(s, rel=1e-9)
    assert got["midline_shift_samples"] == 41 * 11  # the 40 x 10 mm window, 1 mm spacing
    whole = monro_midline_shift_mm(nodes, tets, u, PLANE, monro, window_mm=(40.0, 40.0))
    assert whole["midline_shift_mm"] == pytest.approx(s - 15.0)
    # a shift towards the patient's right is positive
    assert monro_midline_shift_mm(nodes, tets, -u, PLANE, monro)["midline_shift_mm"] > 0


def test_the_monro_location_from_template_labels_or_bounding_box() -> None:
    lo, hi = (np.asarray(b) for b in TEMPLATE_BOX_MM)
    nodes, tets = box_mesh(6, 0.0, 1.0)
    template = lo + nodes * (hi - lo)  # a mesh with the template's bounding box
    no_csf = np.zeros(len(tets), dtype=bool)
    depth = np.full(len(tets), 30.0)
    found = locate_monro(template, tets, no_csf, depth, PLANE)
    assert found.source == "template" and found.point_mm == pytest.approx(MONRO_MNI_MM)
    # half the template's size: no ventricles -> the template's location mapped by the box
    small = 0.5 * template
    found = locate_monro(small, tets, no_csf, depth, PLANE)
    assert found.source == "bounding box"
    assert found.point_mm == pytest.approx(0.5 * np.asarray(MONRO_MNI_MM) * [0, 1, 1])
    # deep CSF near the midline: the ventricles' centroid plus the template's offset
    centroids = small[tets].mean(axis=1)
    vent = np.linalg.norm(centroids - [0.0, -10.0, 5.0], axis=1) < 12.0
    found = locate_monro(small, tets, vent, depth, PLANE)
    assert found.source == "labels"
    assert found.point_mm[0] == pytest.approx(0.0)
    assert abs(found.point_mm[2] - 5.0 - 0.5 * 1.7) < 3.0


def test_constraint_statistics_of_je() -> None:
    """``|J/Js - 1|``: volume-weighted median and p95, the single worst point raw, per
    region."""
    Js = np.full(100, 1.1)
    dev = np.linspace(0.0, 0.099, 100)  # |Je - 1| = 0, 0.001, ..., 0.099
    J = Js * (1 + dev * np.where(np.arange(100) % 2, 1, -1))
    regions = np.where(np.arange(100) < 50, 1, 0)  # indices into the names
    st = constraint_statistics(J, Js, np.ones(100), regions, ["gray_left", "white_left"])
    assert st["median_abs_Je_minus_1"] == pytest.approx(0.049)
    assert st["p95_abs_Je_minus_1"] == pytest.approx(0.094)
    assert st["raw_max_abs_Je_minus_1"] == pytest.approx(0.099)
    assert st["abs_Je_minus_1_by_region"]["white_left"]["raw_max"] == pytest.approx(0.049)
    assert st["abs_Je_minus_1_by_region"]["gray_left"]["median"] == pytest.approx(0.074)


# --- a solved toy brain ----------------------------------------------------------------
@pytest.fixture(scope="module")
def toy_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, Path]:
    """The toy brain (docs/own-mri.md), left white matter swelling to Js = 1.1 under a
    custom flap over the left hemisphere."""
    from brainbulge.model.brain import CraniectomyCase
    from brainbulge.studies.craniectomy import run_brain
    from toy_brain import toy_mesh

    root = tmp_path_factory.mktemp("toy")
    bm = toy_mesh(root / "mesh")
    case = CraniectomyCase(mesh=str(root / "mesh" / "brain.npz"), flap="custom", swell="left",
                           swelling=1.1, steps=2)
    summary = run_brain(case, root / "run", brain_mesh=bm)
    return summary, root / "run"


def test_swelling_and_white_matter_volumes(toy_run) -> None:
    """``swelling_volume_ml`` is the added volume (Js - 1) x the swelling white matter's
    volume, ``white_matter_volume_ml`` that reference volume; the brain grows by it."""
    s, _ = toy_run
    assert s["swelling_volume_ml"] == pytest.approx(0.1 * s["white_matter_volume_ml"], rel=0.01)
    grown = s["deformed_volume_ml"] - s["brain_volume_ml"]
    assert grown == pytest.approx(s["swelling_volume_ml"], rel=0.01)


def test_midline_and_stress_keys_of_a_solved_brain(toy_run) -> None:
    s, run = toy_run
    assert s["monro_location_source"] == "labels"  # the toy has a left lateral ventricle
    # the swelling moves the midline (its sign is tested on a synthetic shifted plane: on
    # this toy the flap over the swelling side decides it)
    assert abs(s["midline_shift_mm"]) > 1e-3
    # the whole plane's largest lateral displacement bounds the Monro level's: the same
    # interpolation on a grid that contains the Monro window's points
    assert abs(s["max_midline_displacement_mm"]) >= abs(s["midline_shift_mm"])
    assert s["mean_hydrostatic_stress_over_shear_modulus"] == pytest.approx(
        s["mean_hydrostatic_stress_kpa"] / s["shear_modulus_kpa"])
    assert not any("pressure_mmhg" in k or "icp" in k.lower()
                   for k in s if k not in s["deprecated_keys"])
    assert s["median_abs_Je_minus_1"] <= s["p95_abs_Je_minus_1"] <= s["raw_max_abs_Je_minus_1"]
    assert s["p95_abs_Je_minus_1"] < 0.1
    for stem in ("principal_strain", "radial_stretch", "tangential_stretch"):
        # the value exceeded in 0.1 ml lies between the p99 (0.1 ml is far less than 1 %
        # of the toy's parenchyma) and the maximum over the same points
        assert s[f"p99_{stem}"] <= s[f"peak_{stem}"] <= s[f"max_{stem}"]
    assert set(s["abs_Je_minus_1_by_region"]) >= {"white_left", "gray_right"}
    on_disk = json.loads((run / "summary.json").read_text())
    assert on_disk["midline_shift_mm"] == pytest.approx(s["midline_shift_mm"])


def test_a_brain_run_writes_the_declared_keys(toy_run) -> None:
    """``summary.json`` of a 3D run has exactly the keys ``results/measures/schema.py`` declares for
    the brain (the toy has CSF: its ventricle), and the printout's keys among them."""
    from brainbulge.results.measures import schema

    s, run = toy_run
    on_disk = json.loads((run / "summary.json").read_text())
    assert set(on_disk) == set(s)
    undeclared, missing = schema.check(on_disk, schema.BRAIN)
    assert not undeclared, f"keys written but not declared in the schema: {undeclared}"
    assert not missing, f"keys declared for every brain run but not written: {missing}"
    assert set(schema.argmaxes(schema.CSF)) <= set(on_disk)  # declared when there is CSF
    from output_files import written_fields

    in_npz, point, cell = written_fields(run)
    assert in_npz == point == schema.field_names()
    assert cell == schema.field_names(cell=True)
    line = schema.printout(on_disk, ("swelling_reached", "midline_shift_mm",
                                     "bulge_volume_ml"), schema.BRAIN)
    assert line == (f"Js = {s['swelling_reached']:.3f}, midline shift = "
                    f"{s['midline_shift_mm']:+.3g} mm, bulge volume = "
                    f"{s['bulge_volume_ml']:.3g} ml")


def test_old_keys_are_aliases_for_one_release(toy_run) -> None:
    s, _ = toy_run
    for old, new in (("midline_shift_monro_mm", "midline_shift_mm"),
                     ("max_pressure_kpa", "max_hydrostatic_stress_kpa")):
        assert s[old] == s[new] and s["deprecated_keys"][old] == new
    # keys whose names misled are gone: a tissue stress in "mmHg", a volume called swelling
    for gone in ("mean_pressure_mmhg", "white_matter_swelling_ml"):
        assert gone not in s and gone not in s["deprecated_keys"]


def test_a_segmentation_without_ventricles_warns(tmp_path: Path,
                                                 caplog: pytest.LogCaptureFixture) -> None:
    from toy_brain import toy_mesh

    bm = toy_mesh(tmp_path, ventricles=False)
    centroids = bm.nodes_mm[bm.tets].mean(axis=1)
    depth = -bm.skull(None).envelope_distance(centroids, gradient=False)[0]
    found = locate_monro(bm.nodes_mm, bm.tets, bm.tissue == 3, depth, bm.midsagittal)
    assert found.source == "bounding box"
    from brainbulge.results.measures import brain_summary

    with caplog.at_level(logging.WARNING, logger="brainbulge"):
        brain_summary.warn_if_guessed(found)
    assert "bounding box" in caplog.text


# --- the paper's Figure 9: deformed surface views ---------------------------------------
def test_surface_views_are_drawn_and_show_the_flap(toy_run) -> None:
    """``surface.png``: not blank (most of each panel is painted), with the flap's rim in
    black; seen from the flap, the brain surface under the flap faces the viewer and carries
    the largest |u|."""
    import matplotlib.image as mpimg

    from brainbulge.results.present.views3d import Surface, view_frame

    _, run = toy_run
    img = mpimg.imread(run / "surface.png")[..., :3]
    painted = (img < 0.95).any(axis=2).mean()
    assert painted > 0.25
    black = (img.max(axis=2) < 0.1).sum()
    assert black > 200  # the rim lines (and little else is black)
    s = Surface.load(run / "surface.npz")
    R = view_frame("flap", s.flap_direction)
    x = s.points + s.u
    tri = x[s.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    # the parenchyma surface under the flap (jagged: tet faces) faces the viewer on the whole
    net = n[s.flap_faces].sum(axis=0) / np.linalg.norm(n[s.flap_faces], axis=1).sum()
    assert net @ R[2] < -0.3
    assert len(s.rim) > 10
    u_face = s.fields["u_magnitude"][s.faces].mean(axis=1)
    assert u_face[s.flap_faces].mean() > 1.5 * u_face[~s.flap_faces].mean()


def test_study_surfaces_share_one_colour_range_per_field(toy_run, tmp_path: Path) -> None:
    from brainbulge.results.present.views3d import Surface, shared_ranges, write_study_surfaces

    _, run = toy_run
    s = Surface.load(run / "surface.npz")
    double = Surface(s.points, s.faces, 2 * s.u, {k: v.copy() for k, v in s.fields.items()},
                     s.flap_faces, s.flap_direction)
    double.fields["u_magnitude"] *= 2
    ranges = shared_ranges([s, double])
    assert ranges["u_magnitude"][1] == pytest.approx(
        np.percentile(double.surface_values("u_magnitude"), 99.5))
    lo, hi = ranges["lambda_n"]
    assert lo + hi == pytest.approx(2.0)  # symmetric about 1
    for name, surf in (("a", s), ("b", double)):
        (tmp_path / name).mkdir()
        surf.save(tmp_path / name / "surface.npz")
    paths = write_study_surfaces(tmp_path, ["a", "b", "missing"])
    assert [p.name for p in paths] == ["surfaces-above.png", "surfaces-flap.png"]
    assert all(p.stat().st_size > 10_000 for p in paths)


def test_the_solved_toy_brain_reports_where_its_extremes_are(toy_run) -> None:
    """Each site is the point of the summary's extreme (same value), outside the rim band;
    its peak set holds the 0.1 ml that ``peak_*`` is the threshold of; element maxima of
    the unsmoothed gradient are at least as extreme as the recovered field's percentiles."""
    s, _ = toy_run
    sites = s["extreme_sites"]
    assert set(sites) == {"max_principal_strain", "max_radial_stretch", "min_radial_stretch",
                          "max_tangential_stretch", "max_shear_stress"}
    for key, site in sites.items():
        assert site["value"] == pytest.approx(s[key], rel=1e-12)
        assert site["rim_distance_mm"] >= s["edge_exclusion_mm"] - 1e-6
        assert site["region"].split("_")[0] in {"gray", "white", "cerebellum", "brainstem"}
        peak = site["peak_set"]
        assert peak["volume_ml"] >= 0.1 - 1e-9
        if key.startswith("max_"):  # its threshold is the summary's peak_*
            assert peak["threshold"] == pytest.approx(s[key.replace("max_", "peak_")])
        assert 0.0 <= site["peak_set"]["share_under_flap"] <= 1.0
    assert s["element_max_principal_strain"] >= s["p99_principal_strain"]
    assert s["element_min_radial_stretch"] <= s["p01_radial_stretch"]
    assert set(s["element_sites"]) == set(sites) - {"max_shear_stress"}  # kinematic only
    # the maximum shear stress [kPa]: positive, its 0.1 ml peak below its maximum
    assert 0 < s["peak_shear_stress"] <= s["max_shear_stress"] <= s["raw_max_shear_stress"]
