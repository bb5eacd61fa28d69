"""Homogeneous states with closed-form answers (docs/model.md section 8)."""

from __future__ import annotations

import ngsolve as ngs
import numpy as np
import pytest

from brainbulge.errors import InfeasibleError, InputError
from brainbulge.materials import MooneyRivlin, Ogden
from brainbulge.model import Problem
from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions, solve

GRAY = MooneyRivlin(0.28, 333.0)
SYMMETRY = {0: "xmin", 1: "ymin", 2: "zmin"}


def _l2_error(mesh: ngs.Mesh, a: ngs.CoefficientFunction, b: ngs.CoefficientFunction) -> float:
    return float(np.sqrt(ngs.Integrate(ngs.InnerProduct(a - b, a - b), mesh)))


@pytest.mark.parametrize("element", ["taylor-hood", "mini"])
@pytest.mark.parametrize("dim", [2, 3])
def test_free_swelling_is_uniform_and_stress_free(dim, element, box2d, box3d) -> None:
    """Uniform Js, only rigid motion suppressed (symmetry planes): ``u = (Js^(1/d) - 1) X``;
    zero stress in 3D, zero in-plane stress in plane strain (F33 = 1)."""
    mesh = box2d if dim == 2 else box3d
    Js = 1.3
    problem = Problem(mesh, {"tissue": GRAY}, {"tissue": Js}, clamped_components=SYMMETRY)
    sol = solve(problem, element, SolverOptions(steps=2))
    assert sol.converged and sol.load == 1.0
    X = ngs.CF((ngs.x, ngs.y, ngs.z)[:dim])
    assert _l2_error(mesh, sol.form.u, (Js ** (1 / dim) - 1) * X) < 1e-8
    # stress from the closed form at a point, with the solver's p
    F = np.eye(3)
    F[:dim, :dim] *= Js ** (1 / dim)
    p = sol.form.p(mesh(0.4, 0.3, 0.2) if dim == 3 else mesh(0.4, 0.3))
    tau = GRAY.kirchhoff_stress(F, p)
    assert np.abs(tau[:dim, :dim]).max() < 1e-7 * GRAY.shear_modulus
    if dim == 3:
        assert abs(p) < 1e-7 * GRAY.shear_modulus
    else:  # plane strain: the out-of-plane stress holds F33 = 1
        assert abs(tau[2, 2]) > 1e-3 * GRAY.shear_modulus


def test_a_finished_solve_leaves_no_equations_behind(box3d) -> None:
    """``solve`` frees its Newton solver's equations (reference cycles, which live until
    Python's cycle collector runs) before it returns: at 1.40M tets their closed-form
    tangent set-up had held 1.2 GB through the outputs. The solution stays whole."""
    import gc

    from brainbulge.solver.equations import MixedEquations

    problem = Problem(box3d, {"tissue": GRAY}, {"tissue": 1.3}, clamped_components=SYMMETRY)
    gc.collect()
    gc.disable()  # only the solve's own collection may run
    try:
        sol = solve(problem, "mini", SolverOptions(steps=2))
        alive = sum(isinstance(o, MixedEquations) for o in gc.get_objects())
    finally:
        gc.enable()
    assert sol.converged and alive == 0
    X = ngs.CF((ngs.x, ngs.y, ngs.z))
    assert _l2_error(box3d, sol.form.u, (1.3 ** (1 / 3) - 1) * X) < 1e-8


def test_free_swelling_independent_of_stiffness_scale(box3d) -> None:
    """With swelling as the only load, the deformation depends on c1/c2, not on the scale."""
    Js = {"tissue": 1.2}
    mats = [MooneyRivlin(0.28, 333.0), MooneyRivlin(0.00028, 0.333)]
    us = []
    for m in mats:
        sol = solve(Problem(box3d, {"tissue": m}, Js, clamped_components=SYMMETRY))
        us.append(sol.form.u(box3d(0.9, 0.8, 0.7)))
    np.testing.assert_allclose(us[0], us[1], rtol=1e-8)


@pytest.mark.parametrize("dim", [3])
@pytest.mark.parametrize(
    "material,nominal",
    [
        (GRAY, lambda lam: (lam - lam**-2) * (GRAY.c1 + GRAY.c2 / lam)),
        (
            Ogden(c=(2.0,), alpha=(5.0,)),
            lambda lam: 2.0 * (lam**4.0 - lam ** (-2.5 - 1)),
        ),
    ],
    ids=["mooney-rivlin", "ogden"],
)
def test_uniaxial_incompressible_bar(dim, material, nominal) -> None:
    """Nominal stress of a homogeneous uniaxial stretch: ``P = (lam - lam^-2)(c1 + c2/lam)``
    for Mooney-Rivlin; ``P = sum c_i (lam^(a_i - 1) - lam^(-a_i/2 - 1))`` for Ogden."""
    from conftest import unit_box_mesh

    box3d = unit_box_mesh(3, h=1.0)  # homogeneous: a coarse mesh is exact
    lam = 1.4
    problem = Problem(
        box3d,
        {"tissue": material},
        clamped_components=SYMMETRY,
        displacements={"xmax": (lam - 1.0, None, None)},
    )
    form = MixedForm(problem)
    solver = NewtonSolver(form, SolverOptions(steps=4))
    sol = solver.solve()
    assert sol.converged
    # reaction on xmax = residual paired with a unit x-displacement of that face
    w = ngs.GridFunction(form.fes)
    w.components[0].Set(ngs.CF((1, 0, 0)), ngs.BND, definedon=box3d.Boundaries("xmax"))
    r = form.gfu.vec.CreateVector()
    form.a.Apply(form.gfu.vec, r)
    reaction = ngs.InnerProduct(r, w.vec)  # reference area is 1
    assert reaction == pytest.approx(nominal(lam), rel=1e-6)
    # lateral contraction lam^(-1/2)
    assert 1 + form.u(box3d(1.0, 1.0, 1.0))[1] == pytest.approx(lam**-0.5, rel=1e-8)


def test_tangent_matches_finite_differences(box2d) -> None:
    """The assembled tangent equals the central difference of the residual."""
    problem = Problem(box2d, {"tissue": GRAY}, {"tissue": 1.3}, clamped_components=SYMMETRY)
    form = MixedForm(problem)
    form.set_load(0.7)
    eq = NewtonSolver(form).equations
    rng = np.random.default_rng(0)
    x = form.gfu.vec
    x.FV().NumPy()[:] = 0.02 * rng.standard_normal(len(x))
    K = eq.tangent(x)
    v = np.zeros(len(x))
    v[eq.free] = rng.standard_normal(len(eq.free))
    eps = 1e-6
    xp, xm = x.CreateVector(), x.CreateVector()
    xp.FV().NumPy()[:] = x.FV().NumPy() + eps * v
    xm.FV().NumPy()[:] = x.FV().NumPy() - eps * v
    fd = (eq.residual(xp) - eq.residual(xm))[eq.free] / (2 * eps)
    Kv = K @ v[eq.free]
    assert np.linalg.norm(Kv - fd) < 1e-6 * np.linalg.norm(Kv)


def test_newton_converges_quadratically() -> None:
    from brainbulge.geometry.inclusion import inclusion_mesh

    mesh = inclusion_mesh(2, A=0.3, h=0.15)
    problem = Problem(
        mesh,
        {"inclusion": GRAY, "matrix": GRAY},
        {"inclusion": 1.3},
        clamped_components={0: "sym_x", 1: "sym_y"},
    )
    form = MixedForm(problem)
    solver = NewtonSolver(form, SolverOptions(steps=1, tolerance=1e-13))
    sol = solver.solve()
    assert sol.converged
    hist = [h for h in sol.newton_results[0].residuals if h > 1e-12]
    assert len(hist) >= 4
    # quadratic: log r_{k+1} / log r_k approaches 2 in the last iterations
    rates = [np.log(hist[k + 1]) / np.log(hist[k]) for k in range(len(hist) - 1) if hist[k] < 0.1]
    assert max(rates) > 1.7, hist


def test_closed_domain_is_infeasible(box2d) -> None:
    """Swelling with every boundary clamped: a clear error, not a hang."""
    problem = Problem(box2d, {"tissue": GRAY}, {"tissue": 1.2}, clamped="xmin|ymin|xmax|free")
    with pytest.raises(InfeasibleError, match="closed domain"):
        solve(problem)


def test_closed_domain_without_swelling_is_fine(box2d) -> None:
    """Every boundary clamped and ``Js = 1``: the rest state, ``u = 0`` and ``p = 0``."""
    problem = Problem(box2d, {"tissue": GRAY}, {"tissue": 1.0}, clamped="xmin|ymin|xmax|free")
    sol = solve(problem)
    assert sol.converged and sol.load == 1.0
    assert _l2_error(box2d, sol.form.u, ngs.CF((0, 0))) == 0.0
    assert _l2_error(box2d, sol.form.p, ngs.CF(0)) == 0.0


def test_closed_domain_whose_swelling_adds_no_volume_is_solved() -> None:
    """A clamped quarter disk (radius 1) whose inclusion (radius ``A``) swells by ``Js`` and
    whose matrix shrinks by ``Jm`` with ``int (Js - 1) dV = 0``: not infeasible, and the
    incompressible radial answer holds, ``r = sqrt(Js) R`` for ``R < A`` and
    ``r^2 = Js A^2 + Jm (R^2 - A^2)`` outside (``r = 1`` at the clamped rim)."""
    from brainbulge.geometry.inclusion import inclusion_mesh

    A, Js = 0.5, 1.3
    mesh = inclusion_mesh(2, A=A, h=0.2, h_inclusion=0.1)
    area = {r: ngs.Integrate(ngs.CF(1), mesh, definedon=mesh.Materials(r))
            for r in ("inclusion", "matrix")}
    Jm = 1 - (Js - 1) * area["inclusion"] / area["matrix"]  # no net volume on this mesh
    problem = Problem(mesh, {"inclusion": GRAY, "matrix": GRAY},
                      {"inclusion": Js, "matrix": Jm}, clamped="outer",
                      clamped_components={0: "sym_x", 1: "sym_y"})
    sol = solve(problem)
    assert sol.converged and sol.load == 1.0
    for R in (0.2, 0.4, 0.6, 0.8, 0.95):
        X = np.array([R, R]) / np.sqrt(2)
        r = np.linalg.norm(X + np.array(sol.form.u(mesh(*X))))
        exact = np.sqrt(Js) * R if R < A else np.sqrt(Js * A**2 + Jm * (R**2 - A**2))
        assert r == pytest.approx(exact, abs=1e-4), R


def _two_zone_inclusion() -> Problem:
    """Octant of a ball with a swelling soft inclusion: two pressure zones."""
    from brainbulge.geometry.inclusion import inclusion_mesh

    mesh = inclusion_mesh(3, A=0.3, h=0.4, h_inclusion=0.2)
    return Problem(mesh, {"inclusion": MooneyRivlin(0.03, 33.3),
                          "matrix": MooneyRivlin(0.28, 333.0)}, {"inclusion": 1.2},
                   clamped_components={0: "sym_x", 1: "sym_y", 2: "sym_z"})


def _residual_and_tangent(form: MixedForm) -> tuple[np.ndarray, np.ndarray]:
    """Residual and dense tangent at a fixed random state at load 0.8."""
    form.set_load(0.8)
    x = form.gfu.vec
    x.FV().NumPy()[:] = np.random.default_rng(0).normal(scale=1e-3, size=len(x))
    ns = NewtonSolver(form)
    return ns.equations.residual(x), ns.equations.tangent(x).toarray()


def _assert_same(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> None:
    for u, v in zip(a, b, strict=True):
        np.testing.assert_allclose(v, u, rtol=1e-9, atol=1e-12 * np.abs(u).max())


def _no_compiler() -> bool:
    """True when NGSolve cannot compile here (no ``ngscxx`` or no C++ compiler): the
    compiled energy then falls back to the interpreted one and a comparison proves nothing."""
    import shutil

    from brainbulge.solver.compile_cache import find_ngscxx

    return find_ngscxx() is None or shutil.which("c++") is None


needs_compiler = pytest.mark.skipif(_no_compiler(), reason="no C++ compiler for NGSolve")


@needs_compiler
def test_energy_compiled_to_machine_code_gives_the_same_residual_and_tangent() -> None:
    """``compile_energy=True`` (on for brain cases) changes the speed, not the numbers."""
    problem = _two_zone_inclusion()
    _assert_same(*(_residual_and_tangent(MixedForm(problem, element="mini",
                                                   compile_energy=native))
                   for native in (False, True)))


@pytest.mark.parametrize("element,native", [("taylor-hood", False), ("mini", False),
                                            pytest.param("mini", True,
                                                         marks=[needs_compiler, pytest.mark.slow])])
def test_energy_split_per_pressure_zone_gives_the_same_residual_and_tangent(
        element, native, monkeypatch) -> None:
    """``sum_z int_z psi + p_z (J - Js)`` (faster to differentiate) is the one-expression
    energy ``int psi + (sum_z p_z)(J - Js)``: same residual and tangent, interpreted or
    compiled."""
    from brainbulge.solver import mixed

    problem = _two_zone_inclusion()
    out = []
    for split in (False, True):
        monkeypatch.setattr(mixed, "split_energy", lambda *a, _s=split: _s)
        form = MixedForm(problem, element=element, compile_energy=native and split)
        assert form.split_zones == split and len(form.pressure_zones) == 2
        out.append(_residual_and_tangent(form))
    _assert_same(*out)


def test_when_the_energy_is_split() -> None:
    from brainbulge.solver.mixed import SPLIT_MIN_ELEMENTS, split_energy

    assert not split_energy(10**6, 1, native=False)  # one zone: nothing to split
    assert split_energy(100, 2, native=False)  # interpreted: always
    assert not split_energy(SPLIT_MIN_ELEMENTS - 1, 4, native=True)  # compiling 4x costs more
    assert split_energy(SPLIT_MIN_ELEMENTS, 4, native=True)


def test_intermediate_load_steps_stop_at_the_looser_tolerance() -> None:
    """Below full load Newton stops at ``intermediate_tolerance``, at full load at
    ``tolerance``: fewer iterations, the same final state (hyperelastic: path independent)."""
    from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem

    case = HemidiskCase(alpha=80, beta=60, swelling=1.2, contact="noslip", mesh_size=0.1,
                        skull_edge_radius=0.0)
    sols = []
    for itol in (1e-9, 1e-5):
        form = MixedForm(hemidisk_problem(case))
        solver = NewtonSolver(form, SolverOptions(steps=4, tolerance=1e-9,
                                                  intermediate_tolerance=itol))
        sol = solver.solve()
        assert sol.converged
        finals = [r.norm for r in sol.newton_results]
        assert finals[-1] <= 1e-9
        sols.append((sol, solver, form.gfu.vec.FV().NumPy().copy(), finals))
    (tight, _, x_tight, f_tight), (loose, _, x_loose, f_loose) = sols
    assert max(f_tight) <= 1e-9
    assert max(f_loose[:-1]) <= 1e-5 and max(f_loose[:-1]) > 1e-9  # stopped early below load 1
    assert loose.newton_iterations < tight.newton_iterations
    assert np.linalg.norm(x_loose - x_tight) <= 1e-6 * np.linalg.norm(x_tight)
    with pytest.raises(InputError, match="tolerance = 0.0 must be a number in"):
        SolverOptions(tolerance=0.0)
    with pytest.raises(InputError, match="intermediate_tolerance"):
        SolverOptions(intermediate_tolerance=-1e-6)


@pytest.mark.parametrize("bad", [{"max_iterations": -1}, {"max_iterations": 1.5},
                                 {"eta_max": 1.0}, {"eta_max": 1e-12}])
def test_options_out_of_range_are_refused_by_name(bad) -> None:
    (name,) = bad
    with pytest.raises(InputError, match=name):
        SolverOptions(**bad)


def test_a_slow_newton_solve_logs_its_iterations(box2d, caplog) -> None:
    """Past ``slow_newton_s`` of a Newton solve every iteration is logged at INFO (a long
    fine-mesh solve shows progress); before that at DEBUG only."""
    import logging

    problem = Problem(box2d, {"tissue": GRAY}, {"tissue": 1.2}, clamped_components=SYMMETRY)
    with caplog.at_level(logging.INFO, logger="brainbulge"):
        solve(problem, element="mini")
    assert not [r for r in caplog.records if "newton 0:" in r.getMessage()]
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="brainbulge"):
        solve(problem, element="mini", options=SolverOptions(slow_newton_s=-1.0))
    lines = [r for r in caplog.records if "newton" in r.getMessage() and "|R|" in r.getMessage()]
    assert lines and all(r.levelno == logging.INFO for r in lines)
