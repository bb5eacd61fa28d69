"""The boundary-value problem: regions -> materials, swelling, boundary and contact conditions.

The names are loaded on first use, so the cases' option declarations
(:mod:`brainbulge.model.options`), which the command line's parser reads, do not load NGSolve.
"""

from __future__ import annotations

from brainbulge.lazy import lazy_names

__all__ = ["Contact", "Obstacle", "Problem"]

__getattr__, __dir__ = lazy_names(__name__, globals(), dict.fromkeys(__all__, "problem"))
