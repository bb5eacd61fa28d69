"""Mixed u-p formulation, Newton with load stepping, linear solvers."""

from brainbulge.solver.mixed import MixedForm
from brainbulge.solver.newton import NewtonSolver, Solution, SolverOptions, solve

__all__ = ["MixedForm", "NewtonSolver", "Solution", "SolverOptions", "solve"]
