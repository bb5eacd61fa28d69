"""The boundary-value problem: regions -> materials, swelling, boundary and contact conditions.

The names are loaded on first use, so the cases' option declarations
(:mod:`brainbulge.model.options`), which the command line's parser reads, do not load NGSolve.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["Contact", "Obstacle", "Problem"]


def __getattr__(name: str) -> Any:
    if name not in __all__:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.problem"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
