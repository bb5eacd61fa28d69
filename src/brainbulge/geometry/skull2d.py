"""The 2D hemidisk's skull as an obstacle: the paper's arc, and a rigid shell (an extension).

:class:`SkullArc2D` is the paper's skull (docs/model.md section 4, the default): the circle
``r = R`` outside the opening, of zero thickness and with a sharp edge at the opening angles.

:class:`RigidSkull2D` is an extension, a rigid body of finite thickness. The skull is a
circular shell of inner radius ``R`` and thickness ``T`` with an opening of
angle ``beta`` centred at angle ``theta_o``. Its cut edges are rounded with radius ``rho``
inside the bone (the sharp shell opened by a disk of radius ``rho``): the body is the set of
points within ``rho`` of a *core*, the part of the annulus ``R + rho <= r <= R + T - rho``
that lies ``rho`` or more behind the end faces. Its inner surface is the circle ``r = R``,
the end faces are the rays at ``theta_o -+ beta/2`` as in the sharp shell, and between them a
circle of radius ``rho`` cuts off each corner: the rounding removes bone (an area
``(1 - pi/4) rho^2`` per edge) and adds none, so no bone reaches into the opening.

The gap ``g(x) = dist(x, core) - rho`` is positive outside the skull, negative inside it. In
coordinates about the nearer end face (``t`` along it, ``s`` into the bone):

- where the radial projection of ``x`` onto the core's radii lies in the core,
  ``dist = max(R + rho - r, r - (R + T - rho), 0)``;
- otherwise ``dist`` is the distance to the core's end segment ``s = rho``.

It is written with NGSolve coefficient functions of the deformed position ``x = X + u`` so that
the contact residual and tangent come from symbolic differentiation; :meth:`gap_numpy` is the
same formula for arrays (tests, plots).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import ngsolve as ngs
import numpy as np

from brainbulge.errors import InputError


def _opening_frame(x: np.ndarray, center_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Radius ``r`` and angle ``delta`` from the opening's centre (in (-pi, pi]) of points
    ``x`` (n, 2) [length, rad]."""
    th = math.radians(center_deg)
    xr = x[:, 0] * math.cos(th) + x[:, 1] * math.sin(th)
    yr = -x[:, 0] * math.sin(th) + x[:, 1] * math.cos(th)
    return np.hypot(xr, yr), np.arctan2(yr, xr)


@dataclass(frozen=True)
class SkullArc2D:
    """The paper's 2D skull: the arc ``r = R`` at angles outside the opening of ``beta_deg``
    centred at ``center_deg`` (zero thickness, sharp edges at ``center_deg -+ beta_deg/2``).

    The sliding condition holds on the material arc, the part of the tissue's boundary that
    lies on the skull at rest: it slides without friction on the circle and may separate
    inward. As an obstacle for that boundary the gap is

        g(x) = R - |x|,       grad g = -x / |x|,

    on the whole circle: a point of the material arc that slides past the edge's angle stays
    on the circle's side (releasing it there made the material corner, which sits at the
    sharp edge, alternate between pressed and free, and the Newton iteration with it). The
    opening is traction-free and meets no obstacle; :meth:`crossing` reports how far the
    deformed tissue reaches beyond the arc where the skull is.
    """

    R: float = 1.0
    beta_deg: float = 60.0
    center_deg: float = 90.0

    @property
    def _half(self) -> float:
        """Half the opening angle [rad], less a round-off margin: the opening's corner
        vertices, at the edge's angle exactly, belong to the skull."""
        return math.radians(self.beta_deg) / 2 - 1e-9

    def gap(self, x: ngs.CoefficientFunction) -> ngs.CoefficientFunction:
        """``g(x)`` for a 2-vector CF ``x`` [length]."""
        return self.R - ngs.sqrt(x[0] * x[0] + x[1] * x[1] + 1e-30)

    def gap_numpy(self, x: np.ndarray) -> np.ndarray:
        """``g`` at points ``x`` of shape (n, 2) [length]."""
        return self.gap_and_normal(x)[0]

    def gap_and_normal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``g`` and ``grad g = -x/|x|`` at points ``x`` (n, 2) [length, -]."""
        r = np.hypot(x[:, 0], x[:, 1])
        return self.R - r, -x / np.maximum(r, 1e-300)[:, None]

    def crossing(self, x: np.ndarray) -> float:
        """``max_skull_crossing``: the largest ``|x| - R > 0`` of points ``x`` (n, 2) at
        angles outside the opening (where the skull is), 0 when none [length]: how far the
        deformed tissue reaches beyond the skull (a bulge folding back over it)."""
        r, delta = _opening_frame(np.asarray(x, dtype=float), self.center_deg)
        beyond = (r - self.R)[np.abs(delta) >= self._half]
        return float(max(beyond.max(initial=0.0), 0.0))


@dataclass(frozen=True)
class RigidSkull2D:
    """Skull shell: inner radius ``R``, opening ``beta_deg`` centred at ``center_deg``,
    thickness ``thickness`` and cut-edge radius ``edge_radius`` [length]."""

    R: float = 1.0
    beta_deg: float = 60.0
    center_deg: float = 90.0
    thickness: float = 0.2
    edge_radius: float = 0.02

    def __post_init__(self) -> None:
        if not 0 < 2 * self.edge_radius < self.thickness:
            raise InputError(
                f"skull edge radius {self.edge_radius} must be positive and below half the "
                f"thickness {self.thickness}"
            )
        if 0 < self.beta_deg and not self.edge_radius < (self.R + self.edge_radius) * (
                math.sin(math.radians(self.beta_deg / 2))):
            raise InputError(f"skull edge radius {self.edge_radius} is too large for an "
                             f"opening of {self.beta_deg} deg; give a smaller radius")

    @property
    def _core(self) -> tuple[float, float, float, float]:
        """``R1 = R + rho``, ``R2 = R + T - rho``, half the opening ``beta/2`` [rad] and
        ``rho``: the core is ``R1 <= r <= R2`` with ``s >= rho``."""
        rho = self.edge_radius
        return self.R + rho, self.R + self.thickness - rho, math.radians(self.beta_deg) / 2, rho

    @property
    def _segment(self) -> tuple[float, float]:
        """The core's end segment ``s = rho`` runs over ``t0 <= t <= t1`` [length]."""
        R1, R2, _, rho = self._core
        return math.sqrt(R1 * R1 - rho * rho), math.sqrt(R2 * R2 - rho * rho)

    @property
    def rounding_deg(self) -> float:
        """How far the rounding reaches along the arc behind each end face [deg]: the
        circle ``r = R`` is the skull's surface from ``beta/2`` plus this on."""
        t0, _ = self._segment
        return math.degrees(math.atan2(self.edge_radius, t0))

    def gap(self, x: ngs.CoefficientFunction) -> ngs.CoefficientFunction:
        """``g(x)`` for a 2-vector CF ``x`` [length]."""
        R1, R2, half, rho = self._core
        if half == 0:  # no opening: the core is the whole annulus
            r = ngs.sqrt(x[0] * x[0] + x[1] * x[1] + 1e-30)
            return ngs.IfPos(R1 - r, R1 - r, ngs.IfPos(r - R2, r - R2, 0)) - rho
        t0, t1 = self._segment
        c, s = math.cos(math.radians(self.center_deg)), math.sin(math.radians(self.center_deg))
        xr = x[0] * c + x[1] * s  # coordinates rotated so the opening centre is at angle 0
        ay = ngs.IfPos(-x[0] * s + x[1] * c, -x[0] * s + x[1] * c, x[0] * s - x[1] * c)
        r = ngs.sqrt(xr * xr + ay * ay + 1e-30)
        t = xr * math.cos(half) + ay * math.sin(half)  # along the nearer end face
        depth = -xr * math.sin(half) + ay * math.cos(half)  # into the bone from that face
        tc = ngs.IfPos(t0 - t, t0, ngs.IfPos(t - t1, t1, t))
        d_seg = ngs.sqrt((t - tc) ** 2 + (depth - rho) ** 2 + 1e-30)
        band = ngs.IfPos(R1 - r, R1 - r, ngs.IfPos(r - R2, r - R2, 0))
        r_core = ngs.IfPos(R1 - r, R1, ngs.IfPos(r - R2, R2, r))
        radial = depth * r_core - rho * r  # > 0: the radial projection lies in the core
        return ngs.IfPos(radial, ngs.IfPos(d_seg - band, band, d_seg), d_seg) - rho

    def edge_centres(self) -> np.ndarray:
        """Centres of the two rounded cut edges (the core's corners, ``rho`` from the arc
        and from the end face), shape (2, 2) [length]."""
        _, _, half, rho = self._core
        t0, _ = self._segment
        th = math.radians(self.center_deg)
        centres = []
        for side in (-1.0, 1.0):
            xr = t0 * math.cos(half) - rho * math.sin(half)
            yr = side * (t0 * math.sin(half) + rho * math.cos(half))
            centres.append((xr * math.cos(th) - yr * math.sin(th),
                            xr * math.sin(th) + yr * math.cos(th)))
        return np.array(centres)

    def near_cut_edge(self, x: np.ndarray, within: float = 2.0) -> bool:
        """Whether the point ``x`` (2,) [length] lies within ``within`` edge radii of a
        rounded cut edge's centre (on the rounding, or on the tissue pressed around it)."""
        d = np.linalg.norm(self.edge_centres() - np.asarray(x, dtype=float)[:2], axis=1)
        return bool(d.min() < within * self.edge_radius)

    def gap_numpy(self, x: np.ndarray) -> np.ndarray:
        """``g`` at points ``x`` of shape (n, 2) [length]."""
        return self.gap_and_normal(x)[0]

    def gap_and_normal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``g`` and ``grad g`` at points ``x`` of shape (n, 2) [length, -].

        ``grad g`` is the unit vector from the nearest point of the core to ``x`` (pointing
        out of the skull), zero inside the core; with it the skull also serves the exact
        active-set contact (:mod:`brainbulge.solver.contact.points`).
        """
        R1, R2, half, rho = self._core
        t0, t1 = self._segment
        th = math.radians(self.center_deg)
        xr = x[:, 0] * math.cos(th) + x[:, 1] * math.sin(th)
        yr = -x[:, 0] * math.sin(th) + x[:, 1] * math.cos(th)
        side = np.where(yr < 0, -1.0, 1.0)
        ay = np.abs(yr)
        r = np.hypot(xr, ay)
        ch, sh = math.cos(half), math.sin(half)
        t, depth = xr * ch + ay * sh, -xr * sh + ay * ch
        dt, dn = t - np.clip(t, t0, t1), depth - rho  # from the segment's nearest point
        d_seg = np.hypot(dt, dn)
        band = np.maximum.reduce([R1 - r, r - R2, np.zeros_like(r)])
        use_band = (half == 0) | (depth * np.clip(r, R1, R2) >= rho * r) & (band <= d_seg)
        g = np.where(use_band, band, d_seg) - rho
        sign = np.where(R1 - r > 0, -1.0, np.where(r - R2 > 0, 1.0, 0.0))
        safe_r = np.maximum(r, 1e-300)
        safe_d = np.maximum(d_seg, 1e-300)
        gx = np.where(use_band, sign * xr / safe_r, (dt * ch - dn * sh) / safe_d)
        gy = side * np.where(use_band, sign * ay / safe_r, (dt * sh + dn * ch) / safe_d)
        c, s = math.cos(th), math.sin(th)
        return g, np.column_stack([gx * c - gy * s, gx * s + gy * c])
