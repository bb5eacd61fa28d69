"""Errors a user can act on. Each carries a one-line message: what is wrong, what to do.

The CLI turns them into ``error: <message>`` and a non-zero exit code; a traceback is shown
only with ``--debug``.
"""


class BrainbulgeError(Exception):
    """Base class: a problem with a one-line, user-facing message."""

    exit_code = 1


class InputError(BrainbulgeError, ValueError):
    """Invalid parameters, files or configuration (exit code 2)."""

    exit_code = 2


class InfeasibleError(BrainbulgeError):
    """The problem has no solution, e.g. swelling inside a closed rigid container (exit 3)."""

    exit_code = 3


class ConvergenceError(BrainbulgeError):
    """Newton's method failed even at the smallest allowed load step (exit code 4)."""

    exit_code = 4


class MeshError(BrainbulgeError):
    """A mesh is unusable: inverted or degenerate elements, missing regions (exit code 5)."""

    exit_code = 5


class StudyIncomplete(BrainbulgeError):
    """Some scenarios of a study did not complete; those that did are kept (exit code 4)."""

    exit_code = 4
