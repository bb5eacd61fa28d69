"""A hemidisk run that stops before full load says why, and a study keeps its results:
``table.csv`` reports its last converged state (``converged`` false, ``load_reached``) with
its error, and the grid figure draws it as far as it got, labelled with the swelling reached."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from brainbulge.results.export.writers import VertexFields
from brainbulge.studies import hemidisk as hd


def _fields(scale: float) -> VertexFields:
    pts = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.5, 0.5]])
    vals = 1 + scale * np.array([-0.1, 0.0, 0.1, 0.2])
    return VertexFields(pts, np.array([[0, 1, 3], [0, 3, 2]]), np.zeros(2, dtype=int), ["a"],
                        {"u": np.zeros((4, 2)), "lambda_n": vals, "lambda_t": vals}, {})


def _study(tmp_path):
    """Three sliding scenarios: complete, stopped at load 0.5 (partial results on disk, as
    ``run_hemidisk`` leaves them) and failed without any result; their runner rows."""
    scenarios = [
        {"name": f"sliding_a{a}_b30", "alpha": float(a), "beta": 30.0, "contact": "sliding",
         "swelling": 1.2}
        for a in (20, 40, 60)
    ]
    done, stopped, failed = (tmp_path / sc["name"] for sc in scenarios)
    for d, scale in ((done, 1.0), (stopped, 10.0)):
        d.mkdir()
        hd.save_vertex_fields(d / "fields.npz", _fields(scale))
    (stopped / "summary.json").write_text(json.dumps(
        {"case": "sliding_a40_b30", "inputs": {"alpha": 40.0}, "converged": False,
         "load_reached": 0.5, "max_radial_stretch": 1.7, "failure_site": [0.2, 1.0]}))
    failed.mkdir()
    rows = [
        {"name": scenarios[0]["name"], "complete": True, "converged": True,
         "load_reached": 1.0, "max_radial_stretch": 1.3},
        {"name": scenarios[1]["name"], "complete": False, "error": "Newton diverged at 0.5"},
        {"name": scenarios[2]["name"], "complete": False, "error": "mesh failed"},
    ]
    return scenarios, rows


def test_table_keeps_a_stopped_scenarios_partial_results(tmp_path) -> None:
    scenarios, rows = _study(tmp_path)
    hd.write_study_table(rows, scenarios, tmp_path / "table.csv")
    table = {r["alpha"]: r for r in csv.DictReader(open(tmp_path / "table.csv"))}
    assert table["20.0"]["converged"] == "True" and table["20.0"]["error"] == ""
    stopped = table["40.0"]
    assert stopped["converged"] == "False"
    assert float(stopped["load_reached"]) == 0.5
    assert float(stopped["max_radial_stretch"]) == 1.7
    assert stopped["error"] == "Newton diverged at 0.5"
    assert table["60.0"]["load_reached"] == "" and table["60.0"]["error"] == "mesh failed"


def test_grid_draws_a_stopped_scenario_labelled(tmp_path, saved_figures) -> None:
    scenarios, rows = _study(tmp_path)
    paths = hd.sector_figures(tmp_path, scenarios, rows)
    assert [p.name for p in paths] == ["grid_lambda_n_sliding.png", "grid_lambda_t_sliding.png"]
    assert all(p.is_file() for p in paths) and len(saved_figures) == 2
    fig = saved_figures[0]
    cells = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"][:3]  # alpha 20, 40, 60
    notes = [[t.get_text() for t in ax.texts if t.get_color() == "red"] for ax in cells]
    assert notes == [[], ["stopped at Js 1.100"], ["no result"]]  # 1 + 0.5 (1.2 - 1)
    assert len(cells[0].collections) == 1 and len(cells[1].collections) == 1
    assert len(cells[2].collections) == 0
    # the colour range is the complete run's: the stopped one's larger stretches do not
    # rescale it (lambda_n of the complete run spans 0.9-1.2)
    vmin, vmax = cells[0].collections[0].get_clim()
    assert vmax < 1.3 and vmin > 0.7


def test_cli_message_tells_stopped_from_failed(tmp_path) -> None:
    """The study's closing message counts the scenarios that stopped before full load (their
    partial results kept; a rerun repeats them) apart from those that failed otherwise."""
    from brainbulge.studies.suites import incomplete_text

    scenarios, _ = _study(tmp_path)
    (tmp_path / scenarios[0]["name"] / "summary.json").write_text(
        json.dumps({"name": scenarios[0]["name"], "complete": True, "converged": True}))
    for sc in scenarios[1:]:
        (tmp_path / sc["name"] / "error.json").write_text(json.dumps({"error": "x"}))
    text = incomplete_text(tmp_path, scenarios)
    assert text.startswith("1 stopped before full load")
    assert "1 failed (rerun the same command to retry them)" in text
    assert text.endswith(f"see {tmp_path}/study.json")


def test_a_stop_on_the_rounded_cut_edge_gets_its_own_advice() -> None:
    """Stopped with the largest unbalanced force on a rounded cut edge, the message says so
    instead of suggesting more steps or a finer mesh; elsewhere the solver's advice stays."""
    from brainbulge.model.hemidisk import HemidiskCase
    from brainbulge.solver.options import DIVERGENCE_ADVICE, Failure, Solution

    case = HemidiskCase(alpha=80, beta=30, contact="sliding", skull="rigid",
                        skull_edge_radius=0.05)
    skull = case.obstacle
    centres = skull.edge_centres()
    half = np.radians(15.0 + skull.rounding_deg)  # the corners, rho behind the end faces
    assert skull.rounding_deg == pytest.approx(np.degrees(np.arcsin(0.05 / 1.05)))
    np.testing.assert_allclose(centres, 1.05 * np.array(
        [[np.cos(np.pi / 2 - half), np.sin(np.pi / 2 - half)],
         [np.cos(np.pi / 2 + half), np.sin(np.pi / 2 + half)]]))
    on_edge = centres[1] + 0.05 * np.array([1.0, 0.0])  # on the left rounding
    np.testing.assert_allclose(skull.gap_numpy(on_edge[None]), [0.0], atol=1e-12)
    assert skull.near_cut_edge(on_edge) and not skull.near_cut_edge(np.array([0.0, 0.5]))
    def stopped(site) -> Solution:
        return Solution(None, 0.5, False, failure=Failure(0.6, 0.1, 0.5, site))

    text = hd.stopped_message(case, stopped(on_edge))
    assert DIVERGENCE_ADVICE not in text and "rounded cut edge" in text
    assert text.startswith("Newton diverged at load 0.6")
    for elsewhere in (np.array([0.0, 0.5]), None):
        sol = stopped(elsewhere)
        assert hd.stopped_message(case, sol) == sol.message
        assert sol.message.endswith(DIVERGENCE_ADVICE)
    # Taylor-Hood sliding on the sharp edge: take MINI there
    sharp = HemidiskCase(contact="sliding", skull_edge_radius=0.0, element="taylor-hood")
    assert hd.stopped_message(sharp, stopped(None)).endswith(hd.SHARP_EDGE_ADVICE)
    mini = HemidiskCase(contact="sliding", skull_edge_radius=0.0, element="mini")
    assert hd.stopped_message(mini, stopped(None)).endswith(DIVERGENCE_ADVICE)


def test_sector_study_starts_large_sectors_in_narrow_openings_first() -> None:
    scenarios = hd.sector_scenarios() + hd.disk_scenarios()
    ordered = sorted(scenarios, key=lambda sc: -hd.expected_cost(sc))
    assert {sc["name"] for sc in ordered[:2]} == {"noslip_a80_b30", "sliding_a80_b30"}
    assert {sc["name"] for sc in ordered[2:4]} == {"noslip_a60_b30", "sliding_a60_b30"}
    assert hd.expected_cost(scenarios[-1]) == 1.0  # a disk
