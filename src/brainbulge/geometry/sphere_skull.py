"""A spherical rigid skull with polar openings: the analytic 3D verification obstacle.

The skull is a spherical shell of inner radius ``R`` and thickness ``T`` with a circular
opening (polar half-angle ``cap_deg`` around the +z axis, and around -z too when
``both_poles``). As :class:`RigidSkull2D` in 2D, its cut faces have rounded edges of radius
``rho``: the skull is the set of points within ``rho`` of a *core*, the shell
``R + rho <= |x| <= R + T - rho`` outside the opening cone, so its inner surface is exactly
``|x| = R`` up to the opening and then turns outward on a torus of radius ``rho``.

Gap ``g(x) = |x - c(x)| - rho`` with ``c(x)`` the closest core point, normal
``n = (x - c) / |x - c|``: positive outside the skull, negative inside.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from brainbulge.errors import InputError


@dataclass(frozen=True)
class SphericalSkull:
    """Shell of inner radius ``R`` [length] with an opening of half-angle ``cap_deg``."""

    R: float = 1.0
    cap_deg: float = 30.0
    thickness: float = 0.2
    edge_radius: float = 0.05
    both_poles: bool = False

    def __post_init__(self) -> None:
        if not 0 < 2 * self.edge_radius < self.thickness:
            raise InputError(
                f"skull edge radius {self.edge_radius} must be positive and below half the "
                f"thickness {self.thickness}"
            )
        if not 0 <= self.cap_deg < 90:
            raise InputError(f"cap half-angle {self.cap_deg} must lie in [0, 90) degrees")

    def gap_and_normal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``g`` (n,) and ``grad g`` (n, 3) at points ``x`` (n, 3) [length]."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        rho = self.edge_radius
        R1, R2 = self.R + rho, self.R + self.thickness - rho
        # meridian half-plane coordinates: s = distance from the axis, t = height
        s = np.hypot(x[:, 0], x[:, 1])
        t = np.abs(x[:, 2]) if self.both_poles else x[:, 2]
        theta = np.arctan2(s, t)  # polar angle from the pole
        r = np.hypot(s, t)
        tc = math.radians(self.cap_deg)
        in_cone = theta < tc
        # outside the cone: closest core point along the same ray; inside: on the cut ray
        e = np.array([math.sin(tc), math.cos(tc)])
        along = np.clip(np.where(in_cone, s * e[0] + t * e[1], r), R1, R2)
        cs = np.where(in_cone, along * e[0], along * s / np.maximum(r, 1e-300))
        ct = np.where(in_cone, along * e[1], along * t / np.maximum(r, 1e-300))
        # back to 3D
        ex = np.where(s > 0, x[:, 0] / np.maximum(s, 1e-300), 1.0)
        ey = np.where(s > 0, x[:, 1] / np.maximum(s, 1e-300), 0.0)
        sign_z = np.where(x[:, 2] < 0, -1.0, 1.0) if self.both_poles else 1.0
        c = np.stack([cs * ex, cs * ey, sign_z * ct], axis=1)
        d = x - c
        dist = np.linalg.norm(d, axis=1)
        n = d / np.maximum(dist, 1e-300)[:, None]
        return dist - rho, n
