"""The hard-case benchmark's 3D rows: which runs its flags select, their command lines, and
the rows read from a run's summary (no solve here)."""

import math

import pytest

import bench_hard_cases_3d as h3
from bench_hard_cases import parser, selected


@pytest.mark.parametrize(("flags", "two", "three"), [
    ([], ["a80b30", "a60b30", "a80b60"], []),
    (["--flap"], [], ["flap"]),
    (["--edge-radius", "--taylor-hood", "--long"], [], ["edge-radius", "taylor-hood", "long"]),
    (["--3d", "--cases", "a60b30"], ["a60b30"], ["study"]),
])
def test_flags_select_the_2d_cases_only_without_a_3d_case_unless_named(flags, two, three):
    assert selected(parser().parse_args(flags)) == (two, three)


def test_taylor_hood_runs_are_the_chosen_scenarios_on_the_demo_mesh():
    runs = h3.runs_for(["taylor-hood"], ["frontal-flap_right-swelling"])
    assert len(runs) == 1 and runs[0].meshes() == [h3.DEMO_TETS]
    argv = " ".join(runs[0].argv)
    assert "--element taylor-hood --flap frontal --swell right --steps 4" in argv
    assert len(h3.runs_for(["taylor-hood"])) == 6


def test_command_resolves_the_cached_meshes_and_the_output_folder(tmp_path):
    """With the meshes in the cache nothing is built: the placeholders become their paths."""
    (tmp_path / f"mesh_{h3.PLAN_TETS}").mkdir()
    (tmp_path / f"mesh_{h3.PLAN_TETS}" / "brain.npz").write_bytes(b"")
    (ramped,) = h3.runs_for(["edge-radius"])
    argv = h3.command(ramped, tmp_path / "out", tmp_path)
    assert argv[1:3] == ["-m", "brainbulge"]
    assert argv[argv.index("--mesh") + 1] == str(tmp_path / "mesh_100000" / "brain.npz")
    assert argv[argv.index("--out") + 1] == str(tmp_path / "out")
    assert "{" not in " ".join(h3.command(h3.runs_for(["flap"])[0], tmp_path / "o", tmp_path))


def test_rows_report_gmres_only_for_krylov_runs():
    s = {"converged": False, "load_reached": 1.0, "newton_iterations": 9,
         "linear_iterations": 0, "final_residual": 1.55e-5, "wall_time_s": 99.0,
         "elements": 110937, "bulge_volume_ml": 57.7, "midline_shift_mm": -2.96,
         "inputs": {"linear_solver": "pardiso"}}
    row = h3.row_from_summary(s, "edge-2mm", "ramped")
    assert row["gmres"] is None
    text = h3.format_row({**row, "run_s": 120.0, "peak_mb": None})
    assert "| 110,937 | False | 1.000 | 9 | - | 1.6e-05 | 99 | 120 | - |" in text
    row = h3.row_from_summary({**s, "linear_iterations": 786, "midline_shift_mm": math.nan,
                               "inputs": {"linear_solver": "krylov"}}, "c", "v")
    assert row["gmres"] == 786
    assert "| 786 |" in h3.format_row({**row, "run_s": 1.0, "peak_mb": 2190.0})
    assert "| 57.7 | - | - |" in h3.format_row({**row, "run_s": 1.0, "peak_mb": 2190.0})


def test_peak_memory_is_read_from_gnu_time():
    report = "\tUser time (seconds): 1.0\n\tMaximum resident set size (kbytes): 2097152\n"
    assert h3.peak_mb(report) == 2048.0
    assert h3.peak_mb("Command exited with non-zero status 4\n") is None


def test_a_start_that_stalled_reports_its_iterations_and_residual_from_its_message():
    """A failed Newton solve from a given state leaves no load-step record: its iterations
    and last residual are those its message gives."""
    s = {"converged": False, "load_reached": 1.0, "load_steps": 0, "newton_iterations": 0,
         "final_residual": None, "linear_iterations": 1292,
         "message": "Newton did not converge at load 1.0000 from the given state (|R| = "
                    "3.09e-05 after 14 iterations)"}
    row = h3.row_from_summary(s, "edge-2mm", "ramped")
    assert (row["newton"], row["residual"], row["gmres"]) == (14, 3.09e-5, 1292)
    converged = {**s, "converged": True, "load_steps": 3, "newton_iterations": 13}
    assert h3.row_from_summary(converged, "c", "v")["newton"] == 13


def test_a_stopped_run_reports_its_accepted_load_steps_and_last_residual_from_its_log():
    log = """2026-12-06 22:34:22,301 INFO     newton 4: |R| = 7.993e-07 (564 s)
2026-12-06 22:34:22,512 INFO   load 0.2500: 4 Newton iterations, |R| = 7.99e-07
2026-12-06 22:44:43,089 INFO   load 0.6250: not converged (|R| = 1.76e-05), cutting step
2026-12-06 22:46:54,634 INFO   load 0.4375: 3 Newton iterations, |R| = 1.68e-07
2026-12-06 22:50:06,353 INFO     newton 2: |R| = 1.476e-04 (191 s)
"""
    row = h3.row_from_log(log, "taylor-hood", "left-flap_both-swelling")
    assert (row["load"], row["newton"], row["residual"]) == (0.4375, 7, 1.476e-4)
    text = h3.format_row({**row, "run_s": 3000.0, "peak_mb": None})
    assert "| stopped | 0.438 | 7+ | - | 1.5e-04 |" in text
    assert h3.row_from_log("", "c", "v")["load"] == 0.0
