"""The 2D hemidisk's skull as an obstacle: the paper's arc, and a rigid shell (an extension).

:class:`SkullArc2D` is the paper's skull (docs/model.md section 4, the default): the circle
``r = R`` outside the opening, of zero thickness and with a sharp edge at the opening angles.

:class:`RigidSkull2D` is an extension, a rigid body of finite thickness. The skull is a
circular shell of inner radius ``R`` and thickness ``T`` with an opening of
angle ``beta`` centred at angle ``theta_o``. Its cut faces have rounded edges of radius ``rho``:
the body is the set of points within ``rho`` of a *core*, the annular sector
``R + rho <= r <= R + T - rho`` outside the opening, so that its inner surface is exactly the
circle ``r = R`` up to the opening angles and then turns outward on a circle of radius ``rho``.

The gap ``g(x) = dist(x, core) - rho`` is positive outside the skull, negative inside it:

- at angles covered by the skull, ``dist = max(R + rho - r, r - (R + T - rho), 0)``;
- in the opening, ``dist`` is the distance to the nearer end segment of the core.

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

    @property
    def _core(self) -> tuple[float, float, float, float]:
        rho = self.edge_radius
        return self.R + rho, self.R + self.thickness - rho, math.radians(self.beta_deg) / 2, rho

    def gap(self, x: ngs.CoefficientFunction) -> ngs.CoefficientFunction:
        """``g(x)`` for a 2-vector CF ``x`` [length]."""
        R1, R2, half, rho = self._core
        c, s = math.cos(math.radians(self.center_deg)), math.sin(math.radians(self.center_deg))
        xr = x[0] * c + x[1] * s  # coordinates rotated so the opening centre is at angle 0
        yr = -x[0] * s + x[1] * c
        r = ngs.sqrt(xr * xr + yr * yr + 1e-30)
        delta = ngs.atan2(yr, xr)
        band = ngs.IfPos(R1 - r, R1 - r, ngs.IfPos(r - R2, r - R2, 0))
        # end segment on the side of the point: direction e = (cos, +-sin) of `half`
        ey = ngs.IfPos(delta, math.sin(half), -math.sin(half))
        ex = math.cos(half)
        t = xr * ex + yr * ey
        t = ngs.IfPos(R1 - t, R1, ngs.IfPos(t - R2, R2, t))
        d_end = ngs.sqrt((xr - t * ex) ** 2 + (yr - t * ey) ** 2 + 1e-30)
        in_opening = half - ngs.IfPos(delta, delta, -delta)  # > 0 inside the opening
        return ngs.IfPos(in_opening, d_end, band) - rho

    def edge_centres(self) -> np.ndarray:
        """Centres ``(R + rho) (cos, sin)(theta_o -+ beta/2)`` of the two rounded cut edges,
        shape (2, 2) [length]."""
        R1, _, half, _ = self._core
        th = math.radians(self.center_deg) + np.array([-half, half])
        return R1 * np.column_stack([np.cos(th), np.sin(th)])

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
        th = math.radians(self.center_deg)
        xr = x[:, 0] * math.cos(th) + x[:, 1] * math.sin(th)
        yr = -x[:, 0] * math.sin(th) + x[:, 1] * math.cos(th)
        r = np.hypot(xr, yr)
        delta = np.arctan2(yr, xr)
        band = np.maximum.reduce([R1 - r, r - R2, np.zeros_like(r)])
        ey = np.where(delta > 0, math.sin(half), -math.sin(half))
        ex = math.cos(half)
        t = np.clip(xr * ex + yr * ey, R1, R2)
        dx, dy = xr - t * ex, yr - t * ey
        d_end = np.hypot(dx, dy)
        opening = np.abs(delta) < half
        g = np.where(opening, d_end, band) - rho
        sign = np.where(R1 - r > 0, -1.0, np.where(r - R2 > 0, 1.0, 0.0))
        safe_r = np.maximum(r, 1e-300)
        safe_d = np.maximum(d_end, 1e-300)
        gxr = np.where(opening, dx / safe_d, sign * xr / safe_r)
        gyr = np.where(opening, dy / safe_d, sign * yr / safe_r)
        c, s = math.cos(th), math.sin(th)
        return g, np.column_stack([gxr * c - gyr * s, gxr * s + gyr * c])
