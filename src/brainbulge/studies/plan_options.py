"""The planner's own options (``brainbulge plan``, a run file's ``[plan]`` table), each
declared once with default, unit, range and help (:func:`~brainbulge.model.options.option`);
the options every plan shares are those of :class:`~brainbulge.model.brain_case.
CraniectomyCase`, with the planner's defaults (:data:`CASE_DEFAULTS`). Light: the parser reads
it without the solver stack."""

from __future__ import annotations

from dataclasses import dataclass

from brainbulge.errors import InputError
from brainbulge.model.options import check_ranges, option
from brainbulge.results.measures.plan_defaults import (
    DIAMETERS_MM,
    LINEAR_SOLVER,
    N_CENTRES,
    STRAIN_THRESHOLD,
)

#: flap diameters the planner accepts [mm] (reported clinical areas 9.5-205 cm^2)
DIAMETER_RANGE_MM = (40.0, 200.0)
#: candidate centres at most
MAX_CENTRES = 100
#: the mesh the planner builds when none is given [tets]: ~111k tets of the template
PLAN_TETS = 100_000
#: the case's options every plan shares, as ``brainbulge plan`` takes them (``swell`` is
#: required: the convexity searched lies above it)
CASE_OPTIONS = ("swell", "swelling", "mesh", "labels", "label_map", "tets", "steps",
                "tolerance", "linear_solver", "edge_radius_mm")
#: the planner's defaults of the case's options (the others: the case's)
CASE_DEFAULTS = {"tets": PLAN_TETS, "linear_solver": LINEAR_SOLVER}


@dataclass
class PlanOptions:
    """Where flaps are tried and how they are judged (lengths in mm)."""

    diameters_mm: tuple[float, ...] = option(
        DIAMETERS_MM, "flap diameters", unit=" mm", range=DIAMETER_RANGE_MM,
        label="--diameters", flag="--diameters", metavar=("MM",))
    n_centres: int | None = option(
        None, "N candidate centres spread over the convexity (even with --swell both)",
        range=(1, MAX_CENTRES), label="--centres", flag="--centres")
    centres_mm: list[list[float]] | None = option(
        None, "a candidate centre on the skull (RAS); repeat for more", unit=" mm",
        flag="--centre", metavar=("X", "Y", "Z"))
    strain_threshold: float = option(
        STRAIN_THRESHOLD, "principal strain above which tissue counts as strained (Bain & "
        "Meaney 2000)", range=(1e-3, 1.0), label="--threshold", flag="--threshold")

    def __post_init__(self) -> None:
        self.diameters_mm = tuple(float(d) for d in self.diameters_mm)
        check_ranges(self)
        if len(set(self.diameters_mm)) < len(self.diameters_mm):
            raise InputError(f"--diameters {' '.join(f'{d:g}' for d in self.diameters_mm)} "
                             "repeats a value; give each once")


#: how the help states the defaults that are not a plain value
DEFAULT_TEXT = {"n_centres": f"default {N_CENTRES}",
                "tets": f"default {PLAN_TETS}",
                "linear_solver": f"default {LINEAR_SOLVER}: GMRES + AMG",
                "labels": "default: the ICBM152 template"}
