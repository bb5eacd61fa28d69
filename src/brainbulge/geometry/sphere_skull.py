"""A spherical rigid skull with polar openings: the analytic 3D verification obstacle.

The skull is a spherical shell of inner radius ``R`` and thickness ``T`` with a circular
opening (polar half-angle ``cap_deg`` around the +z axis, and around -z too when
``both_poles``). As :class:`RigidSkull2D` in 2D, its cut faces have rounded edges of radius
``rho``: the skull is the sharp shell opened by a ball of radius ``rho``, the set of points
within ``rho`` of a *core*, the shell ``R + rho <= |x| <= R + T - rho`` at least ``rho``
outside the opening cone. Its cut face is the cone; its inner surface is exactly ``|x| = R``
up to ``rho`` from the cone and then turns outward on a torus of radius ``rho`` into the cut
face. No bone lies inside the cone.

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
        p = np.stack([s, t], axis=1)
        r = np.hypot(s, t)
        tc = math.radians(self.cap_deg)
        # the core in the half-plane: R1 <= |p| <= R2 on the far side of the line parallel to
        # the cone's ray at distance rho, {p . m >= rho} with m the ray's outward normal
        e = np.array([math.sin(tc), math.cos(tc)])
        m = np.array([math.cos(tc), -math.sin(tc)])

        def corner(radius: float) -> np.ndarray:
            return rho * m + math.sqrt(radius**2 - rho**2) * e

        if tc == 0:  # no opening: the whole shell (its core the shell R1 <= |p| <= R2)
            m = np.zeros(2)
            rho_line = -np.inf
        else:
            rho_line = rho
        inside = (r >= R1) & (r <= R2) & (p @ m >= rho_line)
        # candidates on the core's boundary: the radial projections onto the two arcs where
        # they lie beyond the line, and the projection onto the line's segment between them
        best = np.full(len(s), np.inf)
        c = np.zeros_like(p)
        ray = p / np.maximum(r, 1e-300)[:, None]
        for radius in (R1, R2):
            q = radius * ray
            ok = q @ m >= rho_line
            dist = np.where(ok, np.linalg.norm(p - q, axis=1), np.inf)
            take = dist < best
            best, c = np.where(take, dist, best), np.where(take[:, None], q, c)
        if tc > 0:
            lo, hi = corner(R1) @ e, corner(R2) @ e
            q = rho * m + np.clip(p @ e, lo, hi)[:, None] * e
            dist = np.linalg.norm(p - q, axis=1)
        else:
            dist = np.full(len(s), np.inf)
        take = dist < best
        c = np.where(take[:, None], q, c)
        c = np.where(inside[:, None], p, c)
        cs, ct = c[:, 0], c[:, 1]
        # back to 3D
        ex = np.where(s > 0, x[:, 0] / np.maximum(s, 1e-300), 1.0)
        ey = np.where(s > 0, x[:, 1] / np.maximum(s, 1e-300), 0.0)
        sign_z = np.where(x[:, 2] < 0, -1.0, 1.0) if self.both_poles else 1.0
        c = np.stack([cs * ex, cs * ey, sign_z * ct], axis=1)
        d = x - c
        dist = np.linalg.norm(d, axis=1)
        n = d / np.maximum(dist, 1e-300)[:, None]
        return dist - rho, n
