"""A case's options, each declared once: default, unit, allowed range and help text.

A case dataclass declares each field with :func:`option`; its ``__post_init__`` calls
:func:`check_ranges`, the one check of every range, and the command line builds its
options from the same fields (:mod:`brainbulge.cli.options`), so the help, the checks of a
command line, a run file and the Python API agree.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from brainbulge.errors import InputError


def option(default: Any, help: str, *, unit: str = "", range: tuple[Any, Any] | None = None,
           label: str = "", hint: str = "", flag: str = "", choices: tuple[str, ...] = (),
           metavar: tuple[str, ...] = (), solver: bool = False, internal: bool = False,
           factory: Any = None) -> Any:
    """A dataclass field with its description.

    Args:
        default: the value left out means (ignored with ``factory``).
        help: what the option says (one phrase).
        unit: the unit shown after the range (``" R"``, ``" deg"``).
        range: ``(lo, hi)`` allowed, both included; a bound may be the name of another field
            (``"mesh_size"``). ``None``: no range.
        label: the name errors use (default the field's name with spaces).
        hint: what the range means, shown in errors.
        flag: the command-line option (default ``--`` and the name with dashes).
        choices: the allowed values of a text option.
        metavar: the names of a list option's items.
        solver: the option says how the case is solved (a run file's ``[solver]`` table),
            not what is simulated (``[case]``).
        internal: not a command-line option (set through a run file or the Python API).
        factory: makes a mutable default (``dict``).
    """
    metadata = {"help": help, "unit": unit, "range": range, "label": label, "hint": hint,
                "flag": flag, "choices": choices, "metavar": metavar, "solver": solver,
                "internal": internal}
    if factory is not None:
        return dataclasses.field(default_factory=factory, metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def number(name: str, value: Any, lo: float, hi: float, unit: str = "",
           integer: bool = False, hint: str = "") -> None:
    """``lo <= value <= hi`` (a finite number; a whole one if ``integer``), else a one-line
    `InputError` naming ``name``, the value and the range."""
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    if ok and integer:
        ok = isinstance(value, int)
    if not (ok and math.isfinite(value) and lo <= value <= hi):
        kind, fmt = ("a whole number", "{:,.0f}") if integer else ("a number", "{:g}")
        raise InputError(f"{name} = {value!r} must be {kind} in [{fmt.format(lo)}, "
                         f"{fmt.format(hi)}]{unit}" + (f" ({hint})" if hint else ""))


def label(f: dataclasses.Field) -> str:
    """The name errors give field ``f``."""
    return f.metadata.get("label") or f.name.replace("_", " ")


def bounds(case: Any, f: dataclasses.Field) -> tuple[float, float]:
    """The range of field ``f`` of ``case``, bounds named by another field resolved."""
    return tuple(getattr(case, b) if isinstance(b, str) else b  # type: ignore[return-value]
                 for b in f.metadata["range"])


def check_ranges(case: Any) -> None:
    """Every field of ``case`` with a range and a value (``None`` is left out) lies in it;
    of a list, every item."""
    for f in dataclasses.fields(case):
        value = getattr(case, f.name)
        if f.metadata.get("range") is None or value is None:
            continue
        for item in value if isinstance(value, list | tuple) else [value]:
            number(label(f), item, *bounds(case, f), f.metadata["unit"],
                   integer=_integer(f.type), hint=f.metadata["hint"])


def _integer(tp: Any) -> bool:
    """A field of type ``int`` or ``int | None`` (also as the annotation's text)."""
    return tp is int or str(tp).replace(" ", "") in ("int", "int|None", "None|int")


def solver_fields(cls: type) -> tuple[str, ...]:
    """The fields of case ``cls`` that say how it is solved (a run file's ``[solver]``)."""
    return tuple(f.name for f in dataclasses.fields(cls) if f.metadata.get("solver"))
