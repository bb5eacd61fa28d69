"""Restart files: a solve stopped after some load steps resumes where it stopped and ends in
the state of an uninterrupted solve (sliding contact: its multipliers are restored too)."""

from __future__ import annotations

import numpy as np
import pytest

from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem
from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions

CASE = HemidiskCase(alpha=80, beta=60, swelling=1.2, contact="sliding", mesh_size=0.15,
                    skull_edge_radius=0.0)


class Stop(Exception):
    """Stands for the end of a job's allotted time (a kill) in the middle of a load step."""


def _solver(path, key: str = "case A", stop_above: float | None = None) -> NewtonSolver:
    form = MixedForm(hemidisk_problem(CASE), element="mini")  # the sharp edge's element
    solver = NewtonSolver(form, SolverOptions(steps=4, checkpoint=path, checkpoint_key=key))
    solver.loads = []  # the load of each Newton solve
    newton = solver.newton

    def logged(x, *args, **kwargs):
        solver.loads.append(form.load.Get())
        if stop_above is not None and form.load.Get() > stop_above:
            raise Stop
        return newton(x, *args, **kwargs)

    solver.newton = logged
    return solver


def test_a_stopped_solve_resumes_from_its_last_load_step(tmp_path) -> None:
    path = tmp_path / "restart.npz"
    reference = _solver(None)
    ref = reference.solve()
    assert ref.converged and len(ref.steps) >= 3  # loads 0.25, 0.625 (step grown), 1

    first = _solver(path, stop_above=0.3)
    with pytest.raises(Stop):
        first.solve()
    assert path.is_file()  # written after each accepted step: load 0.25

    second = _solver(path)
    sol = second.solve()
    assert sol.converged
    assert sol.resumed_from == pytest.approx(ref.steps[0].load) and ref.resumed_from == 0
    assert second.loads[0] == pytest.approx(ref.steps[1].load)  # the stopped step, again
    assert [s.load for s in sol.steps] == pytest.approx([s.load for s in ref.steps])
    # the same state, multipliers and predictor as the uninterrupted solve had there
    assert [s.newton_iterations for s in sol.steps] == [s.newton_iterations for s in ref.steps]
    x, x_ref = (s.form.gfu.vec.FV().NumPy() for s in (second, reference))
    assert np.abs(x - x_ref).max() <= 1e-8 * np.abs(x_ref).max()
    lam, lam_ref = (s.form.point_contacts[0].lam for s in (second, reference))
    assert lam_ref.max() > 0
    assert np.abs(lam - lam_ref).max() <= 1e-6 * lam_ref.max()


def test_a_restart_file_of_another_problem_is_ignored(tmp_path) -> None:
    path = tmp_path / "restart.npz"
    with pytest.raises(Stop):
        _solver(path, stop_above=0.3).solve()
    other = _solver(path, key="case B")
    sol = other.solve()
    assert sol.converged and sol.resumed_from == 0  # said so in the summary too
    assert other.loads[0] == pytest.approx(0.25)  # started from Js = 1
    path.write_bytes(b"not an npz file")
    unreadable = _solver(path)
    assert unreadable.solve().converged
    assert unreadable.loads[0] == pytest.approx(0.25)
