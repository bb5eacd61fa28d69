"""The solver's options tree: every tunable of a solve, each declared once in a frozen group
with :func:`~brainbulge.model.options.option` (default, unit, range and the reason for the
default); a group checks its ranges when built. :class:`~brainbulge.solver.options.
SolverOptions` holds one of each:

- ``ramp`` (:class:`RampOptions`): the load ramp's steps and the driver's step control (cut,
  growth) (:mod:`brainbulge.solver.ramp`, :mod:`brainbulge.solver.driver`);
- ``newton`` (:class:`NewtonOptions`): Newton's iterations, tolerances and updates
  (:mod:`brainbulge.solver.newton`);
- ``linear`` (:class:`LinearOptions`): the linear solver and the inexact Newton's Krylov
  tolerances (:mod:`brainbulge.solver.inexact`);
- ``krylov``, ``hotspot``: the Krylov solver's budget and AMG, the hotspot relaxation;
- ``rezoning``, ``warm_start``: the 2D rezoning and the start from another state.
"""

from __future__ import annotations

from dataclasses import dataclass

from brainbulge.errors import InputError
from brainbulge.model.options import check_ranges, option

LINEAR_SOLVERS = ("pardiso", "krylov")

#: the unit of a dimensionless field
RATIO = " [-]"


class OptionGroup:
    """A frozen group of options, its fields declared with
    :func:`~brainbulge.model.options.option`: built only with every value in its range."""

    def __post_init__(self) -> None:
        check_ranges(self)


@dataclass(frozen=True)
class RezoningOptions(OptionGroup):
    """2D rezoning during the load ramp (:mod:`brainbulge.solver.remesh.rezoning`)."""

    q_min: float = option(
        0.2, "rezone when the smallest deformed triangle quality 4 sqrt(3) A / sum l^2 falls "
        "below this (above 1: after every accepted step)", unit=RATIO, range=(0.0, 2.0))
    equilibration_iterations: int = option(
        8, "Newton iterations allowed to equilibrate a carried-over state on the new mesh "
        "before the rezoning counts as failed: in the sector study each rezoning that "
        "succeeded converged in 4, each that failed stood at 3e-4-1e-2 after 14-20",
        unit=" iterations", range=(1, 1000))
    max_rezones: int = option(
        50, "mesh exchanges in one solve before the ramp goes on without rezoning",
        unit=" rezonings", range=(0, 10_000))


@dataclass(frozen=True)
class WarmStartOptions(OptionGroup):
    """Newton from a given start state (another flap's solution) before the load is ramped
    instead (:func:`brainbulge.studies.craniectomy.solve_brain`'s ``start``)."""

    max_iterations: int = option(
        8, "Newton iterations from the start state: about what a cold ramp of a large flap "
        "takes (21k tets, 120 mm: 8, the same from the 100 mm flap's state, with the exact "
        "tangent), so a start that does not help costs at most a ramp",
        unit=" iterations", range=(1, 1000))
    krylov_iterations: int = option(
        200, "GMRES iterations of one linear solve from the start state: a larger flap's "
        "start frees the tissue under the newly opened ring at full pressure; on the "
        "111k-tet template (80 -> 100 mm) GMRES stood at 6e-3 after 1,000 iterations, twice, "
        "150 s before the ramp; converging solves there take <= ~170",
        unit=" iterations", range=(1, 100_000))


@dataclass(frozen=True)
class HotspotOptions(OptionGroup):
    """The hotspot relaxation between Newton iterations
    (:mod:`brainbulge.solver.fast.hotspot`; on or off: ``hotspot_relaxation``)."""

    share: float = option(
        0.5, "the hotspot: the fewest vertices holding this share of the scaled |R|^2 (at "
        "1.40M tets 90-100 % sat at three CSF vertices of the flap rim)", unit=RATIO,
        range=(0.01, 1.0))
    max_vertices: int = option(
        16, "a hotspot of more vertices is left to Newton (a residual spread over the body "
        "is Newton's job); no other value measured", unit=" vertices", range=(1, 100_000))
    rings: int = option(
        2, "rings of neighbours solved with the hotspot (with them 4 fine iterations instead "
        "of 7 at 1.40M tets; no other value measured)", unit=" rings", range=(0, 10))
    max_iterations: int = option(
        30, "Newton iterations of one local solve (a cap: the result is kept only when the "
        "global residual falls); no other value measured", unit=" iterations",
        range=(1, 1000))


@dataclass(frozen=True)
class KrylovOptions(OptionGroup):
    """GMRES with AMG blocks (:class:`~brainbulge.solver.linear.krylov.BlockKrylovSolver`)."""

    max_iterations: int = option(
        1000, "GMRES iterations per linear solve, all restarts included (converging solves on "
        "the 111k-tet template take <= ~170)", unit=" iterations", range=(1, 1_000_000))
    restart: int = option(
        200, "GMRES restart length (basis vectors kept: 1.7 GB at 1.08M unknowns); with 100 "
        "the 1.40M-tet brain's fine-stage tangent stalled at 5.6e-2 after 200 iterations, it "
        "converges in 157 without a restart", unit=" vectors", range=(1, 100_000))
    schur_drop: float = option(
        0.05, "couplings of the SIMPLE Schur approximation weaker than this times "
        "sqrt(|S_ii S_jj|) are lumped onto the diagonal before its AMG: on the 111k-tet "
        "brain one tangent 55 -> 37 GMRES iterations, the scenario 906 -> 481 GMRES and "
        "13 -> 10 Newton iterations, 129 -> 69 s linear solves", unit=RATIO,
        range=(0.0, 1.0))
    smoother_sweeps: int = option(
        1, "symmetric Gauss-Seidel sweeps on each side of the AMG's coarse correction, on "
        "every level: at 1.40M tets 157 GMRES iterations (157 s) with one, 101 (171 s) with "
        "three; one forward and one backward sweep instead: 224 (188 s)", unit=" sweeps",
        range=(1, 20))


@dataclass(frozen=True)
class RampOptions(OptionGroup):
    """The load ramp (:mod:`brainbulge.solver.ramp`) and the step control of the
    continuation driver (:mod:`brainbulge.solver.driver`) it is walked with."""

    steps: int = option(
        5, "initial number of equal load steps from Js = 1 to the target (the cases set "
        "their own, 4: --steps)", unit=" steps", range=(1, 1000))
    min_step: float = option(
        1e-3, "smallest load increment before the ramp gives up with a Failure: a step "
        "cut ten times from 1/1 (2^-10 ~ 1e-3); a ramp stuck that long is stuck at a "
        "limit of the model, not of the step", unit=RATIO, range=(1e-12, 1.0),
        label="min_step")
    intermediate_tolerance: float = option(
        1e-6, "Newton's tolerance on the scaled residual below full load (never tighter "
        "than newton.tolerance): the material is hyperelastic, an intermediate state is only "
        "the start of the next step (its extrapolation starts ~1e-3 away); saves about one "
        "Newton iteration per intermediate step (2D headline: 20 -> 18)", unit=RATIO,
        range=(1e-14, 1e-1), label="intermediate_tolerance")
    cut: float = option(
        0.5, "a failed load step is cut by this factor and tried again from the last "
        "converged state (bisection: the classical choice; no other value measured)",
        unit=RATIO, range=(0.01, 0.99))
    grow: float = option(
        1.5, "a load step that converged within fast_iterations lets the next one grow by "
        "this factor (less than the cut's inverse, so a cut step is not regrown at once; "
        "no other value measured)", unit=RATIO, range=(1.0, 10.0))
    slide: float = option(
        0.0, "after an accepted step the next is scaled by slide / (the largest "
        "displacement increment of a vertex in units of its smallest edge), clipped to "
        "[cut, grow] (0: grow after easy steps instead). On a resolved skull edge the "
        "tissue wrapping the rounding moves farthest in element sizes, and the capped "
        "Newton updates cost about that motion over newton.step_cap",
        unit=" element sizes", range=(0.0, 100.0))
    predictor: bool = option(
        True, "start each load step from the last increment extrapolated (False: from the "
        "last converged state). On the resolved skull edge the extrapolation carries the "
        "tissue along the chord of the rounding into the skull (2D headline: 180 Newton "
        "iterations with it, 99 without)")
    fast_iterations: int = option(
        4, "Newton iterations within which a converged load step counts as easy (the next "
        "grows): a full step from a good predictor converges quadratically in 2-4",
        unit=" iterations", range=(0, 1000), label="fast_iterations")


@dataclass(frozen=True)
class NewtonOptions(OptionGroup):
    """Newton's method (:mod:`brainbulge.solver.newton`)."""

    max_iterations: int = option(
        20, "Newton iterations per attempt at one load (a converging attempt takes 2-10 in "
        "the studies; more only postpones the cut)", unit=" iterations", range=(1, 10_000),
        label="max_iterations")
    tolerance: float = option(
        1e-9, "on the scaled residual at full load (force / (mu L^(d-1)), volume / |Omega|): "
        "round-off of the assembled residual sits near 1e-12, the summaries' numbers are "
        "converged to their printed digits", unit=RATIO, range=(1e-14, 1e-1))
    min_line_step: float = option(
        1 / 1024, "an update whose residual is not finite (an inverted element) is halved "
        "down to this fraction before the iteration gives up (ten halvings)", unit=RATIO,
        range=(1e-12, 1.0), label="min_line_step")
    backtrack: float = option(
        0.5, "an update whose residual is not finite is multiplied by this (halving)",
        unit=RATIO, range=(0.01, 0.99))
    slow_newton_s: float = option(
        30.0, "a Newton solve running longer than this logs each iteration at INFO (else "
        "DEBUG), so a long fine-mesh solve shows its progress (negative: always)",
        unit=" s", range=(-1.0, 1e9), label="slow_newton_s")
    step_cap: float = option(
        0.0, "a trust region on the Newton update: it is scaled so that no vertex moves "
        "more than this fraction of its smallest incident edge (0: off). On the resolved "
        "skull edge a full update moved the tissue around the rounding by several edge "
        "elements and inverted the fillet's elements; 0.3 was the best of 0.2-1 measured",
        unit=RATIO, range=(0.0, 100.0), label="step_cap")
    closed_form: bool = option(
        True, "the closed-form MINI residual and tangent where they apply (fast/"
        "mini_tangent, mini_plane; False: NGSolve's, the same to round-off, slower)",
        label="closed_form")
    hotspot_relaxation: bool = option(
        True, "local solves at residual hotspots between Newton iterations (MINI, where it "
        "applies: fast/hotspot; with them 4 fine iterations instead of 7 at 1.40M tets)",
        label="hotspot_relaxation")


@dataclass(frozen=True)
class LinearOptions(OptionGroup):
    """The linear solver and the inexact Newton's Krylov tolerances
    (:mod:`brainbulge.solver.linear`, :mod:`brainbulge.solver.inexact`)."""

    solver: str = option(
        "pardiso", "pardiso (direct) or krylov (GMRES with AMG blocks, inexact Newton; the "
        "cases' default from 400k tets, where PARDISO runs out of memory)",
        choices=LINEAR_SOLVERS, label="linear_solver")
    eta_min: float = option(
        1e-10, "the tightest relative tolerance of an inexact Newton's Krylov solve (the "
        "floor of the forcing term): near GMRES's round-off at 1e6 unknowns", unit=RATIO,
        range=(1e-16, 1e-2), label="eta_min")
    eta_max: float = option(
        1e-4, "the loosest relative tolerance of an inexact Newton's Krylov solve (the "
        "forcing term's cap): with the floor winning instead a 1.19M-tet brain's Newton "
        "stalled at |R| 1.5e-7", unit=RATIO, range=("eta_min", 0.999), label="eta_max")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.solver not in LINEAR_SOLVERS:
            raise InputError(f"unknown linear solver {self.solver!r}; choose one of "
                             f"{', '.join(LINEAR_SOLVERS)}")
