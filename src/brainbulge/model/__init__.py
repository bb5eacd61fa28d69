"""The boundary-value problem: regions -> materials, swelling, boundary and contact conditions."""

from brainbulge.model.problem import Contact, Obstacle, Problem

__all__ = ["Contact", "Obstacle", "Problem"]
