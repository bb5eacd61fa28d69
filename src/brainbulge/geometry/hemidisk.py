"""The 2D hemidisk of docs/model.md sections 4-5 (plane strain).

A half disk of radius ``R`` over the base ``y = 0``. Boundaries: ``base`` (the straight edge,
clamped), ``skull`` (the curved edge against the rigid skull) and ``opening`` (the curved edge
over the craniectomy, an arc of ``beta`` degrees centred at ``opening_center`` degrees).
Regions: ``swelling`` (a sector of ``alpha`` degrees centred on the symmetry axis, full radius,
or a disk) and ``tissue``.

With ``half`` the mesh covers only the half ``x >= 0`` of a case symmetric about the axis
``x = 0`` (sector and opening centred on it): the axis is the boundary ``symmetry``, where
the mirror image asks ``u_x = 0``.

The domain is glued from pie slices between all break angles, so the mesh conforms to the
sector edges and has vertices at the opening corners; the mesh size is ``h`` and ``h_corner``
near the singular points (opening corners, sector edges on the boundary), set through netgen's
local size restrictions. The ``max_*`` / ``min_*`` summary keys are extremes outside disks of
radius ``edge_exclusion`` around the singular points, and they sit on the rims of those disks,
where the ``r^-1/2`` field is steep: ``h_rim`` refines the mesh along these circles so that the
extremes converge (docs/verification.md: all within 1 % at 15k DOFs with a 0.003 R rim, against
61k DOFs without rim refinement).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import ngsolve as ngs
import numpy as np
from netgen.meshing import MeshingParameters
from netgen.occ import Circle, Glue, MoveTo, OCCGeometry

from brainbulge.errors import InputError

#: the arc is refined to the edge's mesh size this far [deg] to either side of an opening's
#: edge: the tissue next to the edge slides 10-35 edge elements of ``rho/3`` under the skull
#: and wraps the rounding into the opening (alpha 80, beta 30-120, Js 1.2)
EDGE_BAND = 8.0


@dataclass(frozen=True)
class Hemidisk:
    """Geometry parameters (angles in degrees, lengths in the model's unit)."""

    R: float = 1.0
    alpha_deg: float | None = 80.0  # swelling sector angle; None when a disk swells
    beta_deg: float = 60.0  # opening angle
    opening_center_deg: float = 90.0
    disk: tuple[float, float, float] | None = None  # (cx, cy, radius) of a swelling disk
    half: bool = False  # mesh only x >= 0, the axis x = 0 a boundary named "symmetry"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.R) and self.R > 0):
            raise InputError(f"radius R = {self.R} must be a positive number")
        if self.alpha_deg is not None and not 0 < self.alpha_deg <= 180:
            raise InputError(f"sector angle alpha = {self.alpha_deg} must lie in (0, 180] deg")
        if self.alpha_deg is None and self.disk is None:
            raise InputError("give a swelling sector angle alpha or a swelling disk")
        if self.alpha_deg is not None and self.disk is not None:
            raise InputError("give either a swelling sector (alpha) or a disk, not both")
        if not 0 <= self.beta_deg <= 180:
            raise InputError(f"opening angle beta = {self.beta_deg} must lie in [0, 180] deg")
        lo = self.opening_center_deg - self.beta_deg / 2
        hi = self.opening_center_deg + self.beta_deg / 2
        if self.beta_deg > 0 and (lo < -1e-9 or hi > 180 + 1e-9):
            raise InputError(
                f"opening [{lo:g}, {hi:g}] deg leaves the curved boundary [0, 180] deg; "
                "move --opening-center or reduce beta"
            )
        if self.half and not self.symmetric:
            raise InputError("only a case symmetric about the axis (a sector, the opening "
                             "centred at 90 deg) can be meshed as a half domain")
        if self.disk is not None:
            cx, cy, rd = self.disk
            if not (rd > 0 and cy - rd > 0 and math.hypot(cx, cy) + rd < self.R):
                raise InputError(
                    f"disk (centre ({cx}, {cy}), radius {rd}) must lie strictly inside the "
                    f"hemidisk of radius {self.R}"
                )

    @property
    def symmetric(self) -> bool:
        """Whether the case is its own mirror image about the axis ``x = 0``: a sector
        (always centred on the axis) under an opening centred at 90 deg, or no opening."""
        return self.disk is None and (self.beta_deg == 0 or self.opening_center_deg == 90)

    @property
    def opening_angles_deg(self) -> tuple[float, float]:
        b = self.beta_deg / 2
        return self.opening_center_deg - b, self.opening_center_deg + b

    @property
    def sector_angles_deg(self) -> tuple[float, float] | None:
        if self.alpha_deg is None:
            return None
        return 90 - self.alpha_deg / 2, 90 + self.alpha_deg / 2

    def singular_points(self) -> list[tuple[float, float]]:
        """Where the fields are singular (order r^-1/2): opening corners, and the ends of the
        sector edges on the constrained boundary (curved edge and base centre)."""
        angles: list[float] = []
        if self.beta_deg > 0:
            angles += list(self.opening_angles_deg)
        pts = [self._on_arc(a) for a in angles]
        if self.sector_angles_deg is not None and self.alpha_deg < 180:
            pts += [self._on_arc(a) for a in self.sector_angles_deg]
            pts.append((0.0, 0.0))
        return [p for p in pts if not self.half or p[0] >= -1e-12 * self.R]

    def project(self, label: str, X: np.ndarray) -> np.ndarray:
        """Closest points (n, 2) of the curve named ``label`` to ``X`` (n, 2): the arc
        (``skull``, ``opening``), the ``base``, the half domain's ``symmetry`` axis, the swelling
        disk's ``interface``, or for
        other lines between regions (the sector edges) the nearest radial line."""
        X = np.array(X, dtype=float)
        if label in ("skull", "opening"):
            return self.R * X / np.linalg.norm(X, axis=1, keepdims=True)
        if label == "base":
            X[:, 1] = 0.0
            return X
        if label == "symmetry":
            X[:, 0] = 0.0
            return X
        if label == "interface" and self.disk is not None:
            c = np.array(self.disk[:2])
            d = X - c
            return c + self.disk[2] * d / np.linalg.norm(d, axis=1, keepdims=True)
        if self.sector_angles_deg is None:
            return X
        angles = np.radians(np.array(self.sector_angles_deg))
        dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # (2, 2)
        theta = np.arctan2(X[:, 1], X[:, 0])
        k = np.argmin(np.abs(theta[:, None] - angles[None]), axis=1)
        return (X * dirs[k]).sum(1, keepdims=True) * dirs[k]

    def rim_points(self, radius: float, spacing: float) -> np.ndarray:
        """Points (n, 2) at most ``spacing`` apart on the circles of ``radius`` around the
        singular points, those inside the hemidisk [length]."""
        if not (radius > 0 and spacing > 0):
            return np.zeros((0, 2))
        n = max(8, math.ceil(2 * math.pi * radius / spacing))
        t = 2 * math.pi * np.arange(n) / n
        circle = radius * np.stack([np.cos(t), np.sin(t)], axis=1)
        pts = (np.array(self.singular_points()).reshape(-1, 1, 2) + circle).reshape(-1, 2)
        inside = (pts[:, 1] >= 0) & (np.linalg.norm(pts, axis=1) <= self.R)
        if self.half:
            inside &= pts[:, 0] >= 0
        return pts[inside]

    def edge_band_points(self, spacing: float) -> np.ndarray:
        """Points (n, 2) ``spacing`` apart along the arc, and ``2 spacing`` inside it, from
        :data:`EDGE_BAND` degrees inside the opening to as many under the skull at each
        opening edge: where the tissue wraps a rounded skull edge [length]."""
        if self.beta_deg <= 0:
            return np.zeros((0, 2))
        pts = []
        n = max(2, math.ceil(2 * math.radians(EDGE_BAND) * self.R / spacing))
        for edge in self.opening_angles_deg:
            t = np.radians(np.linspace(edge - EDGE_BAND, edge + EDGE_BAND, n + 1))
            for r in (self.R, self.R - 2 * spacing):
                pts.append(r * np.stack([np.cos(t), np.sin(t)], axis=1))
        pts = np.concatenate(pts)
        keep = pts[:, 1] >= 0
        if self.half:
            keep &= pts[:, 0] >= 0
        return pts[keep]

    def _on_arc(self, deg: float) -> tuple[float, float]:
        t = math.radians(deg)
        return self.R * math.cos(t), self.R * math.sin(t)

    def mesh(
        self,
        h: float = 0.05,
        h_corner: float | None = None,
        h_rim: float | None = None,
        rim: float = 0.0,
        h_edge: float | None = None,
    ) -> ngs.Mesh:
        """Second-order (curved) triangle mesh of element size ``h``, ``h_corner`` (default
        ``h/5``) at the singular points, ``h_rim`` on the circles of radius ``rim`` around
        them (:meth:`rim_points`; no rim refinement when ``h_rim`` is None) and ``h_edge``
        along the arc at the opening's edges (:meth:`edge_band_points`) [length]."""
        if not (h > 0 and math.isfinite(h)) or h > self.R:
            raise InputError(f"mesh size {h} must be positive and at most R = {self.R}")
        hc = h_corner if h_corner is not None else h / 5
        breaks = {0.0, 90.0, 180.0} if self.half else {0.0, 180.0}
        if self.beta_deg > 0:
            breaks |= set(self.opening_angles_deg)
        if self.sector_angles_deg is not None:
            breaks |= set(self.sector_angles_deg)
        top = 90.0 if self.half else 180.0  # the half domain ends at the axis
        breaks_sorted = sorted(b for b in breaks if b <= top)
        o_lo, o_hi = self.opening_angles_deg
        s_lo, s_hi = self.sector_angles_deg or (math.nan, math.nan)
        slices = []
        for a0, a1 in zip(breaks_sorted[:-1], breaks_sorted[1:], strict=True):
            if a1 - a0 < 1e-9:
                continue
            mid = 0.5 * (a0 + a1)
            face = _pie_slice(self.R, a0, a1)
            arc = max(face.edges, key=lambda e: _edge_radius(e))
            arc.name = "opening" if (self.beta_deg > 0 and o_lo <= mid <= o_hi) else "skull"
            for e in face.edges:
                if e is not arc and abs(_edge_mid(e)[1]) < 1e-9 * self.R:
                    e.name = "base"
                elif self.half and e is not arc and abs(_edge_mid(e)[0]) < 1e-9 * self.R:
                    e.name = "symmetry"
            face.faces.name = "swelling" if s_lo <= mid <= s_hi else "tissue"
            slices.append(face)
        shape = Glue(slices)
        if self.disk is not None:
            cx, cy, rd = self.disk
            disk = Circle((cx, cy), rd).Face()
            disk.faces.name = "swelling"
            disk.edges.name = "interface"
            shape = Glue([shape - disk, disk])
        mp = MeshingParameters(maxh=h, grading=0.25)
        for px, py in self.singular_points():
            mp.RestrictH(x=px, y=py, z=0, h=hc)
        if h_rim is not None:
            for px, py in self.rim_points(rim, h_rim):
                mp.RestrictH(x=float(px), y=float(py), z=0, h=h_rim)
        if h_edge is not None:
            for px, py in self.edge_band_points(h_edge):
                mp.RestrictH(x=float(px), y=float(py), z=0, h=h_edge)
        if self.disk is not None:
            cx, cy, rd = self.disk
            n = max(16, int(2 * math.pi * rd / hc / 2))
            for k in range(n):
                t = 2 * math.pi * k / n
                mp.RestrictH(x=cx + rd * math.cos(t), y=cy + rd * math.sin(t), z=0, h=hc * 2)
        mesh = ngs.Mesh(OCCGeometry(shape, dim=2).GenerateMesh(mp=mp))
        mesh.Curve(2)
        return mesh


def _pie_slice(R: float, a0: float, a1: float):
    """The sector ``a0 <= theta <= a1`` [deg] of the disk of radius ``R`` (a face)."""
    n = max(2, int(math.ceil((a1 - a0) / 30)))
    wp = MoveTo(0, 0)
    for k in range(n + 1):
        t = math.radians(a0 + (a1 - a0) * k / n)
        wp = wp.LineTo(2 * R * math.cos(t), 2 * R * math.sin(t))
    wedge = wp.Close().Face()
    return wedge * Circle((0, 0), R).Face()


def _edge_mid(e) -> tuple[float, float]:
    p = e.center if hasattr(e, "center") else None
    if p is None:  # pragma: no cover - older netgen
        s, t = e.start, e.end
        return 0.5 * (s.x + t.x), 0.5 * (s.y + t.y)
    return p.x, p.y


def _edge_radius(e) -> float:
    x, y = _edge_mid(e)
    return math.hypot(x, y)
