"""The continuation in the regions' stiffness contrast (:mod:`brainbulge.solver.contrast`):
its path of contrasts, the capped materials, and that the path ends at the model's own
equilibrium (the capped ball of contact_cases with a matrix 20x softer than its inclusion,
sequenced from the coarse mesh, against the fine mesh's own load ramp)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from brainbulge.materials.ogden import Ogden
from brainbulge.model.brain import tissue_materials
from brainbulge.solver import NewtonSolver, SolverOptions
from brainbulge.solver.contrast import capped_materials, contrast, contrast_path
from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.options import ContrastOptions
from brainbulge.solver.remesh.sequencing import solve_sequenced
from contact_cases import GRAY, A, _capped_ball

PATH = ContrastOptions()

SOFT = GRAY.scaled(1 / 20)


@pytest.mark.parametrize("preset", ["paper", "paper-pa"])
def test_the_brains_path_goes_from_the_parenchymas_contrast_to_the_csfs(preset) -> None:
    mats = tissue_materials(preset)
    path = contrast_path(mats, PATH)
    assert path[0] == PATH.start
    assert path[-1] == pytest.approx(mats["white"].shear_modulus / mats["csf"].shear_modulus)
    assert 19 < path[-1] < 21  # white over CSF
    steps = np.diff(np.log(path))
    assert np.all(steps > 0) and np.all(steps <= math.log(PATH.factor) + 1e-12)
    assert len(path) == 3


def test_a_problem_of_low_contrast_takes_one_step() -> None:
    assert contrast_path({"a": GRAY, "b": GRAY}, PATH) == [1.0]
    mats = {"a": GRAY, "b": GRAY.scaled(0.6)}
    assert contrast_path(mats, PATH) == [pytest.approx(1 / 0.6)]


def test_capped_materials_raise_the_soft_ones_only() -> None:
    ogden = Ogden(c=(10.0, -2.0), alpha=(2.0, -2.0))  # mu = 12
    mats = {"stiff": GRAY, "soft": SOFT, "ogden": ogden}
    capped = capped_materials(mats, 4.0)
    floor = GRAY.shear_modulus / 4
    assert capped["stiff"] is GRAY
    assert capped["soft"].shear_modulus == pytest.approx(floor)
    assert capped["soft"].c1 / capped["soft"].c2 == pytest.approx(SOFT.c1 / SOFT.c2)
    assert capped["ogden"].shear_modulus == pytest.approx(floor)
    assert capped["ogden"].alpha == ogden.alpha
    assert contrast(capped) == pytest.approx(4.0)
    assert capped_materials(mats, 1e9)["soft"] is SOFT  # the model's contrast: unchanged


def _soft_matrix_forms() -> tuple[MixedForm, MixedForm]:
    """The capped ball with a matrix 20x softer than the swelling inclusion, coarse and fine."""
    def form(h: float, h_inclusion: float) -> MixedForm:
        _, problem = _capped_ball(h=h, h_inclusion=h_inclusion, cap_deg=35)
        return MixedForm(dataclasses.replace(problem, materials={"inclusion": GRAY,
                                                                 "matrix": SOFT}),
                         element="mini")
    return form(0.3, A / 2), form(0.15, A / 3)


def test_the_path_ends_at_the_models_equilibrium() -> None:
    options = SolverOptions(steps=2)
    _, reference = _soft_matrix_forms()
    assert NewtonSolver(reference, options).solve().converged
    coarse, fine = _soft_matrix_forms()
    sol, record = solve_sequenced(coarse, fine, options)
    assert sol.converged and record.fine_converged
    # the path's Newton solves at full load, one per contrast, in one record (not load steps)
    assert len(contrast_path(fine.problem.materials, PATH)) == 3
    assert [s.load for s in sol.steps] == [1.0]
    assert sol.newton_iterations >= 3
    assert record.initial_residual > options.newton.tolerance
    x, x_ref = fine.u.vec.FV().NumPy(), reference.u.vec.FV().NumPy()
    assert np.abs(x - x_ref).max() < 1e-4 * np.abs(x_ref).max()
    lam, lam_ref = fine.point_contacts[0].lam, reference.point_contacts[0].lam
    assert np.abs(lam - lam_ref).max() < 1e-4 * lam_ref.max()


def test_a_step_without_progress_ends_the_path_and_the_ramp_takes_over() -> None:
    """A contrast step whose residual does not fall fast enough gives up (here: a
    requirement no Newton iteration meets); mesh sequencing then ramps the fine mesh's load
    and still reaches the model's equilibrium."""
    options = SolverOptions(steps=2, contrast=ContrastOptions(progress_iterations=1,
                                                                progress_factor=1e-30))
    coarse, fine = _soft_matrix_forms()
    sol, record = solve_sequenced(coarse, fine, options)
    assert record.coarse_converged and not record.fine_converged
    assert sol.converged and sol.steps[-1].load == 1.0 and len(sol.steps) >= 2  # the ramp
    _, reference = _soft_matrix_forms()
    assert NewtonSolver(reference, options).solve().converged
    x, x_ref = fine.u.vec.FV().NumPy(), reference.u.vec.FV().NumPy()
    assert np.abs(x - x_ref).max() < 1e-4 * np.abs(x_ref).max()
