"""The solver's options tree: every field of every group of :class:`SolverOptions` declares
its default, unit, range and reason, the default lies in the range, and a value outside it
is refused with a message that names the field."""

from __future__ import annotations

import dataclasses
import math

import pytest

from brainbulge.errors import InputError
from brainbulge.model.options import label
from brainbulge.solver import SolverOptions
from brainbulge.solver.contrast import contrast_path
from brainbulge.solver.options import ContrastOptions

GROUPS = [f for f in dataclasses.fields(SolverOptions)
          if dataclasses.is_dataclass(getattr(SolverOptions(), f.name))]
LEAVES = [(g.name, type(getattr(SolverOptions(), g.name)), f)
          for g in GROUPS for f in dataclasses.fields(getattr(SolverOptions(), g.name))]


def test_the_tree_has_the_continuations_groups() -> None:
    assert {g.name for g in GROUPS} >= {"contrast", "sequencing", "rezoning", "warm_start",
                                        "krylov", "hotspot"}
    for g in GROUPS:
        group = getattr(SolverOptions(), g.name)
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(group, dataclasses.fields(group)[0].name, 1)


@pytest.mark.parametrize(("group", "cls", "f"), LEAVES,
                         ids=[f"{g}.{f.name}" for g, _, f in LEAVES])
def test_each_field_has_a_default_unit_range_and_reason(group, cls, f) -> None:
    assert f.default is not dataclasses.MISSING
    assert len(f.metadata["help"]) > 40  # the reason for the default, not just a name
    assert f.metadata["unit"].strip()
    lo, hi = f.metadata["range"]
    assert lo <= f.default <= hi and lo < hi
    integer = isinstance(f.default, int)
    above = hi + 1 if integer else hi * 2 + 1
    below = lo - 1 if integer else (lo / 2 if lo > 0 else -1.0)
    for bad in (above, below, math.nan):
        with pytest.raises(InputError, match=label(f)):
            cls(**{f.name: bad})
    if integer:
        with pytest.raises(InputError, match="whole number"):
            cls(**{f.name: f.default + 0.5})


def test_the_contrast_path_follows_its_options() -> None:
    """Start and factor reach the path: 2 -> 20 in one factor of 10; a start above the
    model's contrast leaves the model's alone."""
    materials = {"white": _Mu(666.0), "csf": _Mu(33.3)}
    assert contrast_path(materials, ContrastOptions(factor=10.0)) == [2.0, pytest.approx(20.0)]
    assert contrast_path(materials, ContrastOptions(start=50.0)) == [pytest.approx(20.0)]
    assert len(contrast_path(materials, ContrastOptions())) == 3


@dataclasses.dataclass
class _Mu:
    shear_modulus: float
