"""The craniectomy planner (``brainbulge plan``) on the toy head of docs/own-mri.md.

A mirror-symmetric ellipsoid brain (no ventricle, mid-sagittal plane x = 0, ~1000 tets):

- candidate centres are spread evenly over the convexity of the swelling side; for both
  sides they are mirror images;
- the fitting rule: a flap reaching the fixed base is refused, one reaching the superior band
  is clipped there (the band stays fixed), one reaching far over the midline is refused;
- the recommendation rule and the Pareto front on synthetic tables;
- one plan end to end (one centre, two diameters): files and columns, the larger flap warm-
  started from the smaller one gives the cold start's answer, a larger flap lowers the bulge
  height, a rerun resumes;
- (slow) for left swelling a flap on the left shifts the midline less and bulges higher than
  its mirror image on the right (and strains more tissue); a flap mirrored across the midline
  with swelling on both sides mirrors the midline shift and keeps the damage.
"""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest

from brainbulge.errors import InputError
from brainbulge.geometry.brain.boundaries import SuperiorBand
from brainbulge.geometry.brain.flap_fit import (
    attach_flap,
    convexity_centres,
    convexity_faces,
    fit_flap,
    mirrored,
    signed_lateral_mm,
)
from brainbulge.model.brain import CraniectomyCase
from brainbulge.results.present.plan_report import COLUMNS, pareto_front, recommend
from brainbulge.solver import SolverOptions
from brainbulge.studies.plan import plan_cases, run_plan
from toy_brain import toy_labels

BAND = SuperiorBand()
#: the toy head is 12 x 10 x 9 cm: flaps of 7-8 cm are its 12-14 cm
SMALL, LARGE = 70.0, 80.0


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    """The symmetric toy brain, saved as ``brain.npz``; (mesh path, BrainMesh)."""
    from brainbulge.geometry.brain import build_brain_mesh, load_tissue_image, save_brain_mesh
    from brainbulge.geometry.brain.regions import MidSagittalPlane

    folder = tmp_path_factory.mktemp("toy")
    image = load_tissue_image(toy_labels(folder / "seg.nii.gz", ventricles=False), "synthseg")
    bm = build_brain_mesh(image, target_tets=1000, midsagittal=MidSagittalPlane())
    save_brain_mesh(bm, folder, figures=False)
    return str(folder / "brain.npz"), bm


def _base(mesh: str, **kw) -> CraniectomyCase:
    return CraniectomyCase(flap="none", swell=kw.pop("swell", "left"), steps=2, mesh=mesh, **kw)


# --- candidates --------------------------------------------------------------------------
def test_candidates_are_spread_evenly_over_the_swelling_side(toy) -> None:
    _, bm = toy
    centres = convexity_centres(bm, "left", 5, BAND)
    assert np.all(signed_lateral_mm(bm, centres) < -BAND.width_mm / 2)
    d = np.linalg.norm(centres[:, None] - centres[None], axis=2)
    np.fill_diagonal(d, np.inf)
    nearest = d.min(axis=1)
    assert nearest.min() > 0.5 * nearest.max()  # no two crowd together
    # every point of the convexity is nearer to a centre than the centres are to each other
    faces = bm.nodes_mm[bm.faces].mean(axis=1)[convexity_faces(bm, "left", BAND)]
    cover = np.linalg.norm(faces[:, None] - centres[None], axis=2).min(axis=1).max()
    assert cover < nearest.max()
    right = convexity_centres(bm, "right", 5, BAND)
    assert np.all(signed_lateral_mm(bm, right) > BAND.width_mm / 2)


def test_both_sides_get_mirror_images(toy) -> None:
    _, bm = toy
    centres = convexity_centres(bm, "both", 4, BAND)
    left, right = centres[:2], centres[2:]
    assert np.all(signed_lateral_mm(bm, left) < 0) and np.all(signed_lateral_mm(bm, right) > 0)
    assert np.allclose(right, mirrored(bm, left))
    with pytest.raises(InputError, match="even"):
        convexity_centres(bm, "both", 3, BAND)


# --- fitting rule ------------------------------------------------------------------------
def test_a_flap_reaching_the_base_is_refused(toy) -> None:
    _, bm = toy
    low = bm.envelope.centre_mm() + np.array([-60.0, 0.0, -25.0])
    fit = fit_flap(bm, low, 90.0, BAND)
    assert not fit.fits and "fixed base" in fit.reason
    with pytest.raises(InputError, match="does not fit"):
        attach_flap(bm, fit)


def test_a_flap_over_the_band_is_clipped_there_and_far_over_the_midline_refused(toy) -> None:
    _, bm = toy
    top = bm.envelope.centre_mm() + np.array([-30.0, 0.0, 60.0])
    fit = fit_flap(bm, top, 60.0, BAND)
    assert fit.fits and fit.clipped_cm2 > 0
    assert not (fit.mask & bm.superior_faces(BAND)).any()
    attach_flap(bm, fit)
    names = bm.boundary_names("custom", BAND)
    assert np.all(names[bm.superior_faces(BAND)] == "superior")  # the bone strip stays
    wide = fit_flap(bm, top, 90.0, BAND)
    assert not wide.fits and "midline" in wide.reason


def test_a_lateral_flap_fits_whole(toy) -> None:
    _, bm = toy
    centre = convexity_centres(bm, "left", 1, BAND)[0]
    fit = fit_flap(bm, centre, SMALL, BAND)
    assert fit.fits and fit.clipped_cm2 == 0
    disk = np.pi * (SMALL / 20) ** 2
    assert disk < fit.area_cm2 < 1.5 * disk  # the cylinder on a curved skull: a bit more


def test_refused_flaps_stay_in_the_plan_marked(toy) -> None:
    mesh, bm = toy
    low = bm.envelope.centre_mm() + np.array([-60.0, 0.0, -25.0])
    cases = plan_cases(_base(mesh), bm, [low], [SMALL, 90.0])
    assert [c.name for c in cases] == ["c00-d70", "c00-d90"]
    assert "fixed base" in cases[1].extra["refused"]
    with pytest.raises(InputError, match="fits"):
        run_plan(cases[1:], Path(mesh).parent / "nothing", scheduler="serial")


# --- recommendation ----------------------------------------------------------------------
def _row(name, area, damage, converged=True):
    return {"name": name, "flap_area_cm2": area, "strained_volume_ml": damage,
            "converged": converged, "diameter_mm": area}


def test_recommendation_is_the_smallest_flap_within_tolerance() -> None:
    rows = [_row("a", 80, 20.0), _row("b", 110, 10.5), _row("c", 140, 10.0),
            _row("d", 200, 10.2), _row("e", 60, 1.0, converged=False)]
    best, least, bound = recommend(rows)
    assert least == 10.0 and bound == pytest.approx(11.0)  # 10 % of the least
    assert best["name"] == "b"
    best, _, bound = recommend(rows, rel_tol=0.01)
    assert bound == pytest.approx(10.5) and best["name"] == "b"  # the 0.5 ml floor
    best, _, _ = recommend(rows, rel_tol=0.0, abs_tol=0.1)
    assert best["name"] == "c"
    assert recommend([_row("x", 1, 1, converged=False)])[0] is None


def test_pareto_front() -> None:
    area = np.array([80, 110, 140, 200, 120])
    damage = np.array([20, 10.5, 10, 10.2, 15])
    assert pareto_front(area, damage).tolist() == [True, True, True, False, False]


# --- one plan end to end -----------------------------------------------------------------
@pytest.fixture(scope="module")
def plan(toy, tmp_path_factory):
    """Left swelling, one lateral centre, two diameters (the larger warm-started)."""
    mesh, bm = toy
    out = tmp_path_factory.mktemp("plan")
    centre = convexity_centres(bm, "left", 1, BAND)
    cases = plan_cases(_base(mesh), bm, centre, [LARGE, SMALL])
    rows = run_plan(cases, out, scheduler="serial", progress=False)
    return out, cases, {r["name"]: r for r in rows}


def test_plan_writes_its_table_figures_and_report(plan) -> None:
    out, cases, rows = plan
    assert [c.name for c in cases] == ["c00-d70", "c00-d80"]  # smallest first
    for f in ("plan.csv", "pareto.png", "centres.png", "report.md", "study.json"):
        assert (out / f).is_file(), f
    for c in cases:
        for f in ("summary.json", "fields.vtu", "sections.png", "state.npz"):
            assert (out / c.name / f).is_file(), f
    with open(out / "plan.csv") as fh:
        table = list(csv.DictReader(fh))
    assert tuple(table[0]) == COLUMNS
    assert [r["converged"] for r in table] == ["True", "True"]
    for r in table:
        assert float(r["strained_volume_ml"]) >= 0 and float(r["flap_area_cm2"]) > 0
        assert 0 < float(r["p99_principal_strain"]) < 1
    report = (out / "report.md").read_text()
    assert "**c00-d" in report and "134.8" in report and "12 cm" in report


def test_the_plan_page_draws_every_flap_where_it_lies(plan) -> None:
    """``report.html``: the head with each plan's flap outline coloured by each damage
    measure (the plan's own values), the recommended flap highlighted; the larger flap's
    outline lies farther from the centre, about at its radius."""
    import base64

    out, cases, rows = plan
    page = (out / "report.html").read_text()
    scene = json.loads(re.search(r'<script type="application/json" id="plan-0">(.*?)</script>',
                                 page, re.S).group(1))
    layers = {layer["name"]: layer for layer in scene["layers"]}
    best = re.search(r"\*\*(c\d\d-d\d+)\*\*", (out / "report.md").read_text()).group(1)
    assert {"head", "flaps", f"recommended {best}"} <= set(layers)

    def arr(b64: str) -> np.ndarray:
        return np.frombuffer(base64.b64decode(b64), dtype=np.float32)

    pts = arr(layers["flaps"]["X"]).reshape(-1, 3)
    bulge = arr(layers["flaps"]["values"]["max_displacement_mm"])
    assert set(scene["fields"]) >= {"strained_volume_ml", "abs_midline_shift_mm"}
    centre = np.array([cases[0].extra["centre_on_skull_mm"]], float)
    reach = {}
    for c in cases:
        mine = np.isclose(bulge, rows[c.name]["max_displacement"], rtol=1e-6)
        assert mine.any()
        reach[c.flap_diameter_mm] = np.linalg.norm(pts[mine] - centre, axis=1).mean()
    assert SMALL / 2 * 0.6 < reach[SMALL] < reach[LARGE] < LARGE / 2 * 1.4


def test_the_larger_flap_starts_from_the_smaller_one_and_lowers_the_bulge(plan) -> None:
    _, _, rows = plan
    small, large = rows["c00-d70"], rows["c00-d80"]
    assert small["warm_start_from"] is None
    assert large["warm_start_from"] == "c00-d70" and large["warm_start_converged"]
    assert large["max_displacement"] < small["max_displacement"]
    # the strained volume does not grow beyond the estimate's resolution (one tet's share)
    assert large["strained_volume_ml"] <= small["strained_volume_ml"] + 0.5
    assert large["rim_volume_ml"] > 0 and large["rim_max_principal_strain"] is not None


def test_a_warm_start_gives_the_cold_start_answer(plan, tmp_path) -> None:
    out, cases, rows = plan
    from brainbulge.studies.craniectomy import run_brain

    cold = run_brain(cases[1], tmp_path, brain_mesh=_fresh_mesh(cases[1]))
    warm = rows["c00-d80"]
    for key in ("max_displacement", "midline_shift_mm", "bulge_volume_ml",
                "p99_principal_strain"):
        assert warm[key] == pytest.approx(cold[key], rel=2e-3, abs=1e-4), key


def _fresh_mesh(case):
    from brainbulge.model.brain import brain_mesh_for

    return brain_mesh_for(case)  # loads the mesh and opens the case's flap by the same rule


def test_a_rerun_resumes(plan) -> None:
    out, cases, rows = plan
    stamps = {c.name: (out / c.name / "summary.json").stat().st_mtime_ns for c in cases}
    again = run_plan(cases, out, scheduler="serial", progress=False)
    assert all(r["complete"] for r in again)
    study = json.loads((out / "study.json").read_text())
    assert all(e.get("resumed") for e in study["scenarios"])
    assert stamps == {c.name: (out / c.name / "summary.json").stat().st_mtime_ns
                      for c in cases}


# --- physics across centres (slow) -------------------------------------------------------
@pytest.mark.slow
def test_left_swelling_is_best_relieved_on_the_left_and_a_mirrored_flap_mirrors(
        toy, tmp_path) -> None:
    mesh, bm = toy
    centres = convexity_centres(bm, "both", 2, BAND)  # one left, its mirror image right
    rows = run_plan(plan_cases(_base(mesh), bm, centres, [SMALL]), tmp_path / "left",
                    scheduler="serial", progress=False)
    left, right = rows
    assert left["complete"] and right["complete"]
    assert left["max_displacement"] > right["max_displacement"]  # the swollen side bulges
    # a flap over the swelling relieves the midline; the swollen tissue that expands through
    # it is strained more than the confined tissue under a contralateral flap, so the
    # strained volume alone does not favour it (known-limits.md, "What the planner ranks")
    assert abs(left["midline_shift_mm"]) < abs(right["midline_shift_mm"])
    assert left["strained_volume_ml"] > right["strained_volume_ml"]
    both = run_plan(plan_cases(_base(mesh, swell="both"), bm, centres, [SMALL]),
                    tmp_path / "both", scheduler="serial", progress=False)
    a, b = both
    assert a["midline_shift_mm"] == pytest.approx(-b["midline_shift_mm"], rel=0.2, abs=0.05)
    # integral measures: the mesh is not mirror-symmetric (the mirrored flaps' areas differ
    # by ~4 %), and its single-vertex bulge height by ~18 %
    for key in ("strained_volume_ml", "bulge_volume_ml", "p99_principal_strain"):
        assert a[key] == pytest.approx(b[key], rel=0.1, abs=0.3), key


# --- the command -------------------------------------------------------------------------
@pytest.mark.parametrize("argv, message", [
    (["--swell", "left", "--diameters", "300"], "[40, 200] mm"),
    (["--swell", "left", "--diameters", "100", "100"], "repeats"),
    (["--swell", "both", "--centres", "3"], "even"),
    (["--swell", "left", "--centres", "0"], "--centres"),
    (["--swell", "left", "--centre", "500", "0", "0"], "--centre 500 0 0"),
    (["--swell", "left", "--threshold", "2"], "--threshold"),
    (["--swell", "left", "--skull-edge-radius", "20"], "edge radius = 20"),
    (["--swell", "left", "--mesh", "missing/brain.npz"], "does not exist"),
    (["--swell", "left", "--label-map", "m.json"], "--labels"),
    (["--swell", "left", "--scheduler", "not a url"], "scheduler"),
])
def test_bad_input_is_one_line_before_out_is_touched(argv, message, tmp_path, capsys) -> None:
    from brainbulge.cli import main

    out = tmp_path / "plan"
    assert main(["plan", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not out.exists()


@pytest.mark.slow
def test_the_command_end_to_end(toy, tmp_path, capsys) -> None:
    from brainbulge.cli import main

    mesh, bm = toy
    c = convexity_centres(bm, "left", 1, BAND)[0]
    out = tmp_path / "plan"
    argv = ["plan", "--swell", "left", "--mesh", mesh, "--centre", *map(str, c), "--diameters",
            "70", "80", "--steps", "2", "--scheduler", "serial", "--out", str(out)]
    assert main(argv) == 0
    assert "recommended flap: c00-d" in capsys.readouterr().out
    assert main(argv) == 0  # resumes
    assert json.loads((out / "status.json").read_text())["status"] == "complete"


def test_a_start_whose_krylov_solve_fails_ramps_at_once(plan, tmp_path, monkeypatch) -> None:
    """A start state whose first GMRES solve fails is given up after that one solve (a
    tighter retry with a fresh preconditioner cost 150 s at 111k tets): the load ramps."""
    import dataclasses

    from brainbulge.errors import ConvergenceError
    from brainbulge.solver.linear.krylov import BlockKrylovSolver
    from brainbulge.studies import craniectomy
    from brainbulge.studies.plan import STATE_FILE, _state_key, load_state

    out, cases, _ = plan
    case = dataclasses.replace(cases[1], linear_solver="krylov")
    bm = _fresh_mesh(case)
    calls = []
    solve = BlockKrylovSolver.solve

    def failing_first(self, *args, **kwargs):
        calls.append((id(self), self.maxiter))
        if len(calls) == 1:
            raise ConvergenceError("GMRES stalled (test)")
        return solve(self, *args, **kwargs)

    monkeypatch.setattr(BlockKrylovSolver, "solve", failing_first)

    def start(form) -> bool:
        source = out / cases[0].name / STATE_FILE
        return load_state(form, source, _state_key(cases[0], bm))

    run = craniectomy.solve_brain(case, tmp_path, brain_mesh=bm, start=start)
    assert calls[0][1] == SolverOptions().warm_start.krylov_iterations
    assert calls[1][0] != calls[0][0]  # the next solve is the ramp's, not a retry
    assert run.started is False and run.sol.converged


def test_damage_measures_weigh_the_parenchyma_and_fall_with_the_threshold(plan, tmp_path
                                                                        ) -> None:
    """From the summary's sampled fields: the parenchyma volume is the mesh's (the order-4
    weights integrate a tet exactly), the strained volume falls as the threshold rises, lies
    within the parenchyma, and at the default threshold is the plan's."""
    from brainbulge.results.measures.plan_measures import damage_measures
    from brainbulge.results.measures.summary import point_fields
    from brainbulge.studies.craniectomy import PARENCHYMA, solve_brain
    from brainbulge.studies.plan import STATE_FILE, _state_key, load_state

    out, cases, rows = plan
    case = cases[1]
    bm = _fresh_mesh(case)
    run = solve_brain(case, tmp_path, brain_mesh=bm, start=lambda form: load_state(
        form, out / case.name / STATE_FILE, _state_key(case, bm)))
    assert run.started and run.sol.newton_iterations <= 1
    points = point_fields(run.form, bm.envelope.centre_mm())
    flap, skull = bm.flaps["custom"], bm.skull("custom", case.edge_radius_mm)
    by = {t: damage_measures(points, flap, skull, PARENCHYMA, t) for t in (0.02, 0.08, 0.18)}
    parenchyma = sum(v for k, v in bm.region_volumes_ml().items()
                     if re.fullmatch(PARENCHYMA, k))
    assert by[0.18]["parenchyma_volume_ml"] == pytest.approx(parenchyma, rel=1e-9)
    strained = [by[t]["strained_volume_ml"] for t in (0.02, 0.08, 0.18)]
    assert parenchyma >= strained[0] >= strained[1] >= strained[2] >= 0
    assert strained[0] > strained[2]  # the threshold matters on this state
    assert 0 < by[0.18]["rim_volume_ml"] < parenchyma
    assert by[0.18]["strained_volume_ml"] == pytest.approx(
        rows[case.name]["strained_volume_ml"], rel=1e-6, abs=1e-9)
