"""The solve, as a pipeline: the mixed u-p form (:mod:`.mixed`), the load ramp (:mod:`.ramp`,
with its restart file :mod:`.restart`) calling Newton with a line search (:mod:`.newton`) on
the discrete equations (:mod:`.equations`), the skull contact's active set (:mod:`.contact`),
the linear solvers (:mod:`.linear`), fast paths (:mod:`.fast`) and mesh changes during a
solve (:mod:`.remesh`); options (one dataclass, the continuations', the Krylov solver's
and the hotspot's tunables in frozen groups) and results in :mod:`.options`."""

from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.options import Failure, Solution, SolverOptions, StepRecord
from brainbulge.solver.ramp import NewtonSolver
from brainbulge.solver.strategy import Rezoning, Route, Sequenced, Strategy, solve

__all__ = ["Failure", "MixedForm", "NewtonSolver", "Rezoning", "Route", "Sequenced", "Solution",
           "SolverOptions", "StepRecord", "Strategy", "solve"]
