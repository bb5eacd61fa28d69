"""The 3D edge-radius benchmark: its runs' names, command lines and step control (no solve
here)."""

import pytest

import bench_edge_radius_3d as er
from brainbulge.studies import craniectomy


@pytest.mark.parametrize("run", [er.EdgeRun("left", "both", 2.0, 100_000),
                                 er.EdgeRun("frontal", "right", 0.5, 400_000, capped=True)])
def test_a_run_is_read_back_from_its_folder_name(run):
    assert er.EdgeRun.parse(run.name) == run


def test_other_folders_are_no_runs():
    assert er.EdgeRun.parse("baseline-8mm-1cm-base-csf") is None


def test_a_stopped_run_is_resumed_and_any_other_replaced(tmp_path):
    run = er.EdgeRun("frontal", "left", 1.0, 100_000)
    argv = run.argv(tmp_path / "mesh.npz", tmp_path)
    assert argv[argv.index("--skull-edge-radius") + 1] == "1"
    assert argv[argv.index("--flap") + 1] == "frontal" and "--overwrite" in argv
    (tmp_path / "restart.npz").write_bytes(b"")
    assert "--overwrite" not in run.argv(tmp_path / "mesh.npz", tmp_path)


def test_capped_runs_solve_with_the_resolved_edges_step_control(monkeypatch):
    from brainbulge.model.hemidisk import RESOLVED_EDGE_STEPS

    monkeypatch.setattr(craniectomy, "SolverOptions", craniectomy.SolverOptions)
    seen = {}

    def main(argv):
        seen["options"] = craniectomy.SolverOptions(steps=3, tolerance=1e-8)
        return 0

    monkeypatch.setattr("brainbulge.cli.main", main)
    assert er.capped_main(["brain"]) == 0
    options = seen["options"]
    ramp, newton = RESOLVED_EDGE_STEPS
    assert options.ramp.steps == 3 and options.newton.tolerance == 1e-8
    assert all(getattr(options.ramp, k) == v for k, v in ramp.items())
    assert all(getattr(options.newton, k) == v for k, v in newton.items())
