"""A shared contact case: a ball octant with a swelling inclusion in a spherical skull."""

from __future__ import annotations

import ngsolve as ngs
import numpy as np

from brainbulge.geometry.inclusion import inclusion_mesh
from brainbulge.geometry.sphere_skull import SphericalSkull
from brainbulge.materials import MooneyRivlin
from brainbulge.model import Problem
from brainbulge.model.problem import Contact
from brainbulge.solver.mixed import MixedForm

GRAY = MooneyRivlin(0.28, 333.0)
#: inclusion radius and its swelling ratio
A, JS = 0.2, 1.3


def _capped_ball(h: float, h_inclusion: float, cap_deg: float):
    """Ball octant with a swelling inclusion, sliding in a spherical skull with polar caps."""
    mesh = inclusion_mesh(3, A=A, h=h, h_inclusion=h_inclusion)
    skull = SphericalSkull(R=1.0, cap_deg=cap_deg, thickness=0.2, edge_radius=0.05,
                           both_poles=True)
    problem = Problem(
        mesh,
        {"inclusion": GRAY, "matrix": GRAY},
        {"inclusion": JS},
        clamped_components={0: "sym_x", 1: "sym_y", 2: "sym_z"},
        contacts=[Contact("outer", skull)],
    )
    return mesh, problem


def _forms(element: str = "mini") -> tuple[MixedForm, MixedForm]:
    coarse = MixedForm(_capped_ball(h=0.3, h_inclusion=A / 2, cap_deg=35)[1], element=element)
    fine = MixedForm(_capped_ball(h=0.15, h_inclusion=A / 3, cap_deg=35)[1], element=element)
    return coarse, fine


def _coords(mesh: ngs.Mesh) -> np.ndarray:
    return np.array([v.point for v in mesh.vertices])
