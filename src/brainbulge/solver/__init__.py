"""The solve: :func:`solve` runs the route a :class:`Strategy` chooses for a problem
(:mod:`.strategy`: the load ramp, 2D rezoning, a warm start); each route is walked by the
one continuation driver (:mod:`.driver`) over small path classes (the load ramp :mod:`.ramp`
with its restart file :mod:`.restart`, the rezoning ramp in :mod:`.remesh`), each step Newton
(:mod:`.newton`) on the discrete equations (:mod:`.equations`) of the mixed u-p form
(:mod:`.mixed`), with the skull contact's active set (:mod:`.contact`), the linear solvers
(:mod:`.linear`) and fast paths (:mod:`.fast`). Every tunable is a field of the options tree
(:mod:`.option_groups`, frozen groups of :class:`SolverOptions`); results in
:mod:`.options`."""

from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.options import Failure, Solution, SolverOptions, StepRecord
from brainbulge.solver.ramp import NewtonSolver
from brainbulge.solver.strategy import Rezoning, Route, Strategy, solve

__all__ = ["Failure", "MixedForm", "NewtonSolver", "Rezoning", "Route", "Solution",
           "SolverOptions", "StepRecord", "Strategy", "solve"]
