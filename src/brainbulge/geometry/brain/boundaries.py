"""The outer surface of the brain mesh: fixed base and superior band, sliding skull contact
and craniectomy flaps.

Faces of the outer surface whose centroid lies below the cut plane ``z = base_z_mm`` (world RAS,
mm; default about foramen-magnum level) are the fixed ``base``; a :class:`SuperiorBand` along
the superior midline, where the falx and the superior sagittal sinus tie the brain to the
skull, is fixed too (the paper's Figure 6); the rest slides on the ``skull`` except on a flap,
where the skull is removed. A :class:`Flap` is the part of the skull inside a
cylinder along the outward normal at the flap centre, of circular (``half_length_mm = 0``) or
stadium cross-section (a disk of ``radius_mm`` swept over ``2 half_length_mm`` along
``long_axis``): the rigid-skull obstacle (:mod:`.skull`) uses the same cylinder as its cutter,
so the traction-free faces and the opening in the obstacle agree.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from brainbulge.errors import InputError
from brainbulge.geometry.brain.defaults import (
    FLAP_DIAMETER_RANGE_MM,
    SUPERIOR_ELEVATION_DEG,
    SUPERIOR_ELEVATION_RANGE_DEG,
    SUPERIOR_WIDTH_MM,
    SUPERIOR_WIDTH_RANGE_MM,
    UNILATERAL_DIAMETER_MM,
)
from brainbulge.geometry.brain.envelope import IntracranialEnvelope

# outward faces of a positively oriented tet (a, b, c, d): opposite d, c, b, a
_TET_FACES = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])

#: Directions (RAS) from the brain centre to the centres of the named flaps.
LEFT_FTP_DIRECTION = (-1.0, 0.1, 0.45)
FRONTAL_DIRECTION = (0.0, 1.0, 0.55)
#: Bifrontal flap antero-posterior extent (mm); its width is set by the area ratio.
FRONTAL_AP_DIAMETER_MM = 120.0
#: Depth (mm, below the frontal centre along its axis) down to which the bifrontal flap cuts,
#: so that its lateral ends reach the temporal squama.
FRONTAL_DEPTH_MM = 120.0
#: The bifrontal flap's lower edge: this fraction of the height above the lowest point
#: (z = -19 mm in MNI space, above the orbital roofs).
FRONTAL_FLOOR_FRACTION = 0.35


#: ``k`` of the cutter's smooth inside distance (:meth:`Flap.cutter_distance`).
INSIDE_EXPONENT = 4


@dataclass(frozen=True)
class SuperiorBand:
    """The outer surface within ``width_mm / 2`` of the mid-sagittal plane and at least
    ``elevation_deg`` above the horizontal through the brain centre (seen from it)."""

    width_mm: float = SUPERIOR_WIDTH_MM
    elevation_deg: float = SUPERIOR_ELEVATION_DEG

    def __post_init__(self) -> None:
        lo, hi = SUPERIOR_WIDTH_RANGE_MM
        if not lo < self.width_mm <= hi:
            raise InputError(f"superior band width {self.width_mm} mm must lie in ({lo:g}, "
                             f"{hi:g}] (default {SUPERIOR_WIDTH_MM:g}: the superior sagittal "
                             "sinus)")
        lo, hi = SUPERIOR_ELEVATION_RANGE_DEG
        if not lo <= self.elevation_deg < hi:
            raise InputError(f"superior band elevation {self.elevation_deg} deg must lie in "
                             f"[{lo:g}, {hi:g})")

    def contains(self, points_mm: np.ndarray, plane_point_mm, plane_normal,
                 centre_mm: np.ndarray) -> np.ndarray:
        """True for points (n, 3) in the band (mm)."""
        off = (points_mm - np.asarray(plane_point_mm)) @ np.asarray(plane_normal, float)
        d = points_mm - np.asarray(centre_mm)
        elevation = np.degrees(np.arcsin(d[:, 2] / np.linalg.norm(d, axis=1)))
        return (np.abs(off) <= self.width_mm / 2) & (elevation >= self.elevation_deg)


def boundary_faces(tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Faces (k, 3) of the outer surface, outward oriented, and the tet each belongs to."""
    faces = tets[:, _TET_FACES].reshape(-1, 3)
    outer = faces_once(faces)
    owner = np.repeat(np.arange(len(tets)), 4)
    return faces[outer], owner[outer]


def faces_once(faces: np.ndarray) -> np.ndarray:
    """True at the faces (k, 3) of vertex indices whose vertex set occurs once: the
    boundary faces among all faces of a set of tets.

    Each face becomes one integer (its sorted vertices in base ``n``), sorted once: on the
    1.40M-tet brain's 5.6M faces 7 s -> 1 s against ``np.unique(..., axis=0)``."""
    key = np.sort(np.asarray(faces, dtype=np.int64), axis=1)
    n = int(key.max(initial=0)) + 1
    if n ** 3 >= 2**63:  # a mesh beyond 2M vertices: rows compared as rows
        _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        return counts[inverse.ravel()] == 1
    code = (key[:, 0] * n + key[:, 1]) * n + key[:, 2]
    order = np.argsort(code)
    same = code[order[1:]] == code[order[:-1]]
    repeated = np.zeros(len(code), dtype=bool)
    repeated[order[1:][same]] = True
    repeated[order[:-1][same]] = True
    return ~repeated


def face_areas_mm2(nodes: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Triangle areas (mm^2)."""
    p = nodes[faces]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


@dataclass(frozen=True)
class Flap:
    """A craniectomy: the skull removed inside a cylinder through ``centre_mm`` along ``axis``.

    ``axis`` is the outward normal at the centre; the cross-section is a disk of ``radius_mm``
    swept over ``[-half_length_mm, half_length_mm]`` along ``long_axis`` (perpendicular to the
    axis). Only the skull within ``depth_mm`` below the centre (default ``radius_mm``) is cut.
    """

    name: str
    centre_mm: tuple[float, float, float]
    axis: tuple[float, float, float]
    radius_mm: float
    half_length_mm: float = 0.0
    long_axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    depth_mm: float | None = None
    floor_z_mm: float | None = None
    meta: dict = field(default_factory=dict, compare=False)

    def cutter_distance(self, points_mm: np.ndarray, smooth_inside: bool = False
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance (mm, negative inside) to the cutting cylinder, and its gradient.

        The cutter is the intersection of the infinite cylinder (``w_1 = dist - R < 0``), the
        half-space ``w_2 = -(axial + depth) < 0`` and, with a floor, ``w_3 = floor_z - z <
        0``: outside, ``|max(w, 0)|`` (exact outside a corner); inside, ``max(w)``, whose
        gradient jumps on the bisector of every edge of the cutter. With ``smooth_inside``
        the inside value is ``-(sum_i (-w_i)^-k)^(-1/k)`` (``k`` = :data:`INSIDE_EXPONENT`):
        the same zero level and gradient on the faces, smooth inside (within ``2^(-1/k)``
        of ``max(w)`` on a bisector, within 0.3 % where the next face is 3x as far), as the
        rigid skull's normal at a rounded cut edge needs (a crease there stalls Newton)."""
        a = np.asarray(self.axis, float)
        e = np.asarray(self.long_axis, float)
        e = e - (e @ a) * a
        e /= np.linalg.norm(e)
        rel = points_mm - np.asarray(self.centre_mm)
        axial = rel @ a
        perp = rel - axial[:, None] * a
        along = np.clip(perp @ e, -self.half_length_mm, self.half_length_mm)
        off = perp - along[:, None] * e
        dist = np.linalg.norm(off, axis=1)
        radial_dir = off / np.maximum(dist, 1e-12)[:, None]
        depth = self.radius_mm if self.depth_mm is None else self.depth_mm
        # intersection of the infinite cylinder (dist < R), the half-space axial > -depth and,
        # with a floor, z > floor: exact outside a corner, max of the distances inside
        columns = [dist - self.radius_mm, -(axial + depth)]
        grads = [radial_dir, -np.broadcast_to(a, radial_dir.shape)]
        if self.floor_z_mm is not None:
            columns.append(self.floor_z_mm - points_mm[:, 2])
            grads.append(np.broadcast_to(np.array([0.0, 0.0, -1.0]), radial_dir.shape))
        w = np.stack(columns, axis=1)
        wpos = np.maximum(w, 0.0)
        outside = np.linalg.norm(wpos, axis=1)
        phi = outside + np.minimum(w.max(axis=1), 0.0)
        inside = outside == 0
        nearest = np.eye(w.shape[1])[np.argmax(w, axis=1)]
        # wpos / |wpos| is a unit vector for any |wpos| > 0 (a floor such as 1e-12 under the
        # norm shrank the gradient of points within 1e-12 mm of the surface: contact's
        # normal jumped there)
        weight = np.where(inside[:, None], nearest,
                          wpos / np.where(inside, 1.0, outside)[:, None])
        if smooth_inside:
            deep = inside & (w.max(axis=1) < -1e-9)  # (on a face: max(w) = 0 as it is)
            depth_k = (-w[deep]) ** -float(INSIDE_EXPONENT)
            phi[deep] = -depth_k.sum(axis=1) ** (-1 / INSIDE_EXPONENT)
            # d phi / d w_i = (phi / w_i)^(k + 1)
            weight[deep] = (phi[deep, None] / w[deep]) ** (INSIDE_EXPONENT + 1)
        grad = np.einsum("nk,knd->nd", weight, np.stack(grads))
        return phi, grad

    def contains(self, points_mm: np.ndarray) -> np.ndarray:
        """True for points inside the cutting cylinder."""
        return self.cutter_distance(points_mm)[0] < 0

    def depth_below_centre_mm(self, points_mm: np.ndarray) -> np.ndarray:
        """``-(X - c) . a`` (mm): how far below the centre along the axis each point lies."""
        return -(np.atleast_2d(points_mm) - np.asarray(self.centre_mm)) @ np.asarray(self.axis)

    @property
    def diameter_mm(self) -> float:
        """Short diameter of the opening (mm)."""
        return 2 * self.radius_mm


def clear_of_other_skull(flap: Flap, opening_mm: np.ndarray, other_mm: np.ndarray) -> Flap:
    """``flap`` with its cut ending halfway between its opening and the rest of the skull.

    ``opening_mm``: the nodes of the opening's faces; ``other_mm``: the other nodes of the
    skull's inner surface. The cut reaches ``depth_mm`` below the centre; a skull that
    curves back into the cylinder within that depth (the middle cranial fossa under a
    fronto-temporo-parietal flap: 9 faces, 2 cm^2, 47-60 mm deep on the template) would be
    opened there too, its bone relieved by ``sqrt(r^2 + d^2) - r`` at a depth ``d`` inside
    the cutter, and the cutter's inner corner, where ``Flap.cutter_distance`` takes the max
    of two distances, puts a crease into the skull's normal there. With ``D_o`` the
    opening's deepest node and ``D_x`` the shallowest other node inside the cylinder and
    deeper than ``D_o``, the depth becomes ``min(depth, (D_o + D_x) / 2)``; unchanged when
    no such node lies within the depth."""
    depth = flap.radius_mm if flap.depth_mm is None else flap.depth_mm
    deepest_open = float(flap.depth_below_centre_mm(opening_mm).max(initial=-np.inf))
    bottomless = replace(flap, depth_mm=np.inf)
    other = np.atleast_2d(other_mm)
    below = flap.depth_below_centre_mm(other)
    inside = bottomless.contains(other) & (below > deepest_open)
    if not inside.any():
        return flap
    shallowest_other = float(below[inside].min())
    if shallowest_other >= depth:
        return flap
    return replace(flap, depth_mm=0.5 * (deepest_open + shallowest_other))


def _surface_normal(envelope: IntracranialEnvelope, point_mm: np.ndarray) -> np.ndarray:
    h = 1.0
    phi = [envelope_phi(envelope, point_mm + h * np.eye(3)[i]) -
           envelope_phi(envelope, point_mm - h * np.eye(3)[i]) for i in range(3)]
    n = np.array(phi)
    return n / np.linalg.norm(n)


def envelope_phi(envelope: IntracranialEnvelope, point_mm: np.ndarray) -> float:
    """Envelope signed distance (mm) at one point (trilinear)."""
    import scipy.ndimage as ndi

    ijk = envelope.world_to_index(np.atleast_2d(point_mm))
    return float(ndi.map_coordinates(envelope.sdf_mm, ijk.T, order=1, mode="nearest")[0])


def custom_flap(envelope: IntracranialEnvelope, centre_mm: tuple[float, float, float],
                diameter_mm: float, name: str = "custom") -> Flap:
    """A circular flap of ``diameter_mm`` centred where the ray from the brain centre through
    ``centre_mm`` meets the skull (so the centre need only be near the skull)."""
    lo, hi = FLAP_DIAMETER_RANGE_MM
    if not lo <= diameter_mm <= hi:
        raise InputError(f"flap diameter {diameter_mm} mm is outside {lo:g}-{hi:g} mm: give it "
                         "in mm")
    direction = np.asarray(centre_mm, float) - envelope.centre_mm()
    if np.linalg.norm(direction) < 1e-6:
        raise InputError("flap centre is the brain centre: give a point on the skull (mm)")
    centre = envelope.surface_point_along(direction)
    axis = _surface_normal(envelope, centre)
    return Flap(name, tuple(centre.tolist()), tuple(axis.tolist()), diameter_mm / 2)


def unilateral_flap(envelope: IntracranialEnvelope, side: str,
                    diameter_mm: float = UNILATERAL_DIAMETER_MM) -> Flap:
    """Fronto-temporo-parietal flap over the ``"left"`` or ``"right"`` hemisphere."""
    d = np.array(LEFT_FTP_DIRECTION)
    if side == "right":
        d[0] = -d[0]
    elif side != "left":
        raise InputError(f"side must be 'left' or 'right', got {side!r}")
    return custom_flap(envelope, envelope.centre_mm() + d, diameter_mm, name=side)


def frontal_flap(envelope: IntracranialEnvelope, nodes: np.ndarray, faces: np.ndarray,
                 allowed: np.ndarray, area_ratio: float = 2.0,
                 ap_diameter_mm: float = FRONTAL_AP_DIAMETER_MM,
                 floor_z_mm: float | None = None) -> Flap:
    """Bifrontal flap: a stadium over both frontal lobes above ``floor_z_mm`` (default: 35 %
    of the height above the lowest point, sparing the orbital roofs), widened until its area
    on the surface is ``area_ratio`` times that of the left unilateral flap (faces in
    ``allowed`` only)."""
    z = nodes[:, 2]
    if floor_z_mm is None:
        floor_z_mm = float(z.min() + FRONTAL_FLOOR_FRACTION * (z.max() - z.min()))
    base = custom_flap(envelope, envelope.centre_mm() + np.array(FRONTAL_DIRECTION),
                       ap_diameter_mm, name="frontal")
    areas = face_areas_mm2(nodes, faces)
    centroids = nodes[faces].mean(axis=1)
    left = unilateral_flap(envelope, "left")
    target = area_ratio * areas[allowed & left.contains(centroids)].sum()

    def flap(half_length: float) -> Flap:
        return Flap("frontal", base.centre_mm, base.axis, base.radius_mm, half_length,
                    (1.0, 0.0, 0.0), depth_mm=FRONTAL_DEPTH_MM, floor_z_mm=floor_z_mm)

    lo, hi = 0.0, 200.0
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if areas[allowed & flap(mid).contains(centroids)].sum() < target:
            lo = mid
        else:
            hi = mid
    return flap(0.5 * (lo + hi))
