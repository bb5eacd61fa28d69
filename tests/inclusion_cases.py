"""A soft swelling sphere (CSF-like, mu 10x smaller) in a stiff ball, octant with symmetry
planes, and its swollen state reached by Newton's method (the displacement block of that
tangent is indefinite there): shared by the linear-solver and inexact-Newton tests."""

from __future__ import annotations

from brainbulge.geometry.inclusion import inclusion_mesh
from brainbulge.materials import MooneyRivlin
from brainbulge.model import Problem
from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions

SOFT = MooneyRivlin(0.03, 33.3)
STIFF = MooneyRivlin(0.28, 333.0)


def _inclusion_problem() -> Problem:
    """A soft swelling sphere (Js 1.3) in a stiff ball, octant with symmetry planes."""
    mesh = inclusion_mesh(3, A=0.3, h=0.3, h_inclusion=0.15)
    return Problem(
        mesh,
        {"inclusion": SOFT, "matrix": STIFF},
        {"inclusion": 1.3},
        clamped_components={0: "sym_x", 1: "sym_y", 2: "sym_z"},
    )


def swollen_state():
    """Form, Newton solver and the tangent/right-hand side of a Newton step at a swollen
    state (load 0.7 of Js = 1.3 converged, then the load raised to 1)."""
    problem = _inclusion_problem()
    form = MixedForm(problem, element="mini")
    ns = NewtonSolver(form, SolverOptions(tolerance=1e-10))
    for load in (0.4, 0.7):
        form.set_load(load)
        assert ns.newton().converged
    x = form.gfu.vec
    K1 = ns.equations.tangent(x)
    form.set_load(1.0)
    r = ns.equations.residual(x)
    rhs = x.CreateVector()
    rhs.FV().NumPy()[:] = r
    rhs.data += form.a.harmonic_extension_trans * rhs
    return form, ns, K1, rhs.FV().NumPy()[ns.equations.free].copy()
