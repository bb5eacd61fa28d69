"""The rigid skull as an obstacle for frictionless contact: a signed distance with gradient.

``phi(x) > 0`` is penetration into the skull (mm), ``phi < 0`` is inside the intracranial space.
Without a flap ``phi`` is the envelope's smoothed signed distance (cubic-spline interpolated on
its grid, gradient by central differences of the same spline). With a flap, the skull solid
``{phi_env > 0}`` is intersected with the outside of the flap's cutting cylinder, and the convex
cut edge is rounded with radius ``edge_radius_mm`` (the SDF of the intersection eroded and
dilated by that radius):

    u = (d_skull + r, d_cut + r),   d = |max(u, 0)| + min(max(u), 0) - r,   phi = -d

with ``d_skull = -phi_env`` and ``d_cut = -(distance to the cylinder)`` the standard (negative
inside) distances of the two sets.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage as ndi

from brainbulge.geometry.brain.boundaries import Flap
from brainbulge.geometry.brain.defaults import EDGE_RADIUS_MM
from brainbulge.geometry.brain.envelope import IntracranialEnvelope


class RigidSkull:
    """Rigid skull around ``envelope`` with an optional craniectomy ``flap`` (mm units)."""

    def __init__(self, envelope: IntracranialEnvelope, flap: Flap | None = None,
                 edge_radius_mm: float = EDGE_RADIUS_MM) -> None:
        self.envelope = envelope
        self.flap = flap
        self.edge_radius_mm = float(edge_radius_mm)
        self._inv = np.linalg.inv(envelope.affine)
        sdf = envelope.sdf_mm.astype(np.float64)
        self._coeffs = ndi.spline_filter(sdf, order=3, mode="nearest")

    def envelope_distance(self, points_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance to the intact skull's inner surface (mm, positive outside) and
        its gradient (n, 3): the C2 cubic spline of the sampled distance and its exact
        derivative."""
        ijk = points_mm @ self._inv[:3, :3].T + self._inv[:3, 3]
        phi, g_index = cubic_spline_value_and_gradient(self._coeffs, ijk)
        grad = g_index @ self._inv[:3, :3]
        # outside the grid: add the distance to it
        shape = np.array(self.envelope.sdf_mm.shape) - 1
        beyond = np.maximum(-ijk, 0) + np.maximum(ijk - shape, 0)
        spacing = np.linalg.norm(self.envelope.affine[:3, :3], axis=0)
        phi = phi + np.linalg.norm(beyond * spacing, axis=1)
        return phi, grad

    def signed_distance(self, points_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``phi`` (n,) in mm, positive = penetration into the skull, and ``grad phi`` (n, 3).

        Vectorised over ``points_mm`` of shape (n, 3) in world millimetres.
        """
        pts = np.atleast_2d(np.asarray(points_mm, dtype=float))
        phi_env, g_env = self.envelope_distance(pts)
        if self.flap is None:
            return phi_env, g_env
        r = self.edge_radius_mm
        d_cut, g_cut = self.flap.cutter_distance(pts)
        # standard distances (negative inside) of the skull solid and of the cutter's outside
        u = np.stack([-phi_env + r, -d_cut + r], axis=1)
        gu = np.stack([-g_env, -g_cut], axis=1)  # (n, 2, 3)
        upos = np.maximum(u, 0.0)
        norm = np.linalg.norm(upos, axis=1)
        d = norm + np.minimum(u.max(axis=1), 0.0) - r
        first = (u[:, 0] >= u[:, 1]).astype(float)
        weight = np.where((norm > 0)[:, None], upos / np.where(norm > 0, norm, 1.0)[:, None],
                          np.stack([first, 1 - first], axis=1))
        grad_d = np.einsum("nk,nkd->nd", weight, gu)
        return -d, -grad_d

    def gap_and_normal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The contact obstacle's view (:class:`PointObstacle`): gap ``g = -phi`` (mm,
        positive in the intracranial space or the flap opening) and ``grad g = -grad phi``."""
        phi, grad = self.signed_distance(x)
        return -phi, -grad


def cubic_spline_value_and_gradient(coeffs: np.ndarray,
                                    ijk: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Value and gradient (per index unit) of the 3D cubic B-spline with coefficients
    ``coeffs`` (``scipy.ndimage.spline_filter(..., order=3)``) at index points ``ijk`` (n, 3):

        f(x) = sum_abc c[i0+a, j0+b, k0+c] w_a(tx) w_b(ty) w_c(tz),   i0 = floor(x) - 1,

    with the cubic B-spline weights ``w`` of the fractional parts ``t`` and, for the gradient,
    their derivatives (coefficient indices clamped to the grid, as ``mode="nearest"``).

    ``scipy.ndimage.map_coordinates`` gives the value only (the gradient took six more calls
    of central differences) and ``scipy.interpolate.NdBSpline`` one derivative per call; the
    64 coefficients of a point are gathered once here for the value and all three
    derivatives, which is what the contact's every residual needs.
    """
    ijk = np.asarray(ijk, dtype=float)
    base = np.floor(ijk)
    t = ijk - base
    s = 1.0 - t
    # (n, 3, 4) weights of the four coefficients around each point, and their derivatives
    w = np.stack([s**3, 3 * t**3 - 6 * t**2 + 4, -3 * t**3 + 3 * t**2 + 3 * t + 1, t**3],
                 axis=-1) / 6
    dw = np.stack([-(s**2), 3 * t**2 - 4 * t, -3 * t**2 + 2 * t + 1, t**2], axis=-1) / 2
    shape = np.array(coeffs.shape)
    idx = np.clip(base.astype(np.int64)[:, :, None] - 1 + np.arange(4), 0,
                  (shape - 1)[None, :, None])  # (n, 3, 4)
    flat = ((idx[:, 0, :, None, None] * shape[1] + idx[:, 1, None, :, None]) * shape[2]
            + idx[:, 2, None, None, :])
    c = coeffs.reshape(-1)[flat]  # (n, 4, 4, 4)
    cz = np.einsum("nabc,nc->nab", c, w[:, 2])
    dcz = np.einsum("nabc,nc->nab", c, dw[:, 2])
    cyz = np.einsum("nab,nb->na", cz, w[:, 1])
    value = np.einsum("na,na->n", cyz, w[:, 0])
    grad = np.stack([
        np.einsum("na,na->n", cyz, dw[:, 0]),
        np.einsum("nab,nb,na->n", cz, dw[:, 1], w[:, 0]),
        np.einsum("nab,nb,na->n", dcz, w[:, 1], w[:, 0]),
    ], axis=1)
    return value, grad
