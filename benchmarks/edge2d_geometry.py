"""The resolved-edge prototype's geometry (:mod:`bench_edge_2d`): the skull opened by a disk
of radius ``rho`` (:class:`OpenedSkull`, beside ``RigidSkull2D``'s turned rounding) and the
hemidisk's mesh, or its half, resolved along the arc at the edge (:func:`mesh`)."""

from __future__ import annotations

import math

import numpy as np

THICKNESS = 2.0  # [R]: the skull's thickness, beyond any bulge


class OpenedSkull:
    """``S`` opened by a disk of radius ``rho`` (the union of the disks of radius ``rho``
    inside ``S``): the arc ends ``rho`` into the bone, the end face stays on the nominal
    edge ray. ``g = dist(x, E) - rho`` with ``E`` the eroded set ``{r >= R + rho} and
    {distance from the edge's line >= rho on the skull's side}`` (exact outside ``S``)."""

    def __init__(self, R: float, beta_deg: float, rho: float) -> None:
        self.R, self.half, self.rho = R, math.radians(beta_deg) / 2, rho

    def gap_and_normal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R1, rho, h = self.R + self.rho, self.rho, self.half
        # the opening's frame: centre on +x' (the y axis of the mesh), sides mirrored
        xr, yr = x[:, 1], -x[:, 0]
        sgn = np.where(yr < 0, -1.0, 1.0)
        ya = np.abs(yr)
        m = np.array([-math.sin(h), math.cos(h)])  # normal of the edge's line, to the bone
        e = np.array([math.cos(h), math.sin(h)])
        s = xr * m[0] + ya * m[1]  # signed distance from the edge's line
        r = np.hypot(xr, ya)
        # the corner of E: on the circle r = R1, at distance rho from the line
        tc = math.sqrt(R1**2 - rho**2)
        cx, cy = tc * e[0] + rho * m[0], tc * e[1] + rho * m[1]
        # candidate nearest points: radial projection on the circle (if in H), projection on
        # the line s = rho (if r >= R1 there), the corner
        px_c, py_c = R1 * xr / np.maximum(r, 1e-300), R1 * ya / np.maximum(r, 1e-300)
        ok_c = px_c * m[0] + py_c * m[1] >= rho
        t = xr * e[0] + ya * e[1]
        px_l, py_l = t * e[0] + rho * m[0], t * e[1] + rho * m[1]
        ok_l = np.hypot(px_l, py_l) >= R1
        d_c = np.where(ok_c, np.abs(r - R1), np.inf)
        d_l = np.where(ok_l, np.abs(s - rho), np.inf)
        d_k = np.hypot(xr - cx, ya - cy)
        inside = (r >= R1) & (s >= rho)
        d = np.minimum(np.minimum(d_c, d_l), d_k)
        # nearest point and the outward normal (from E to x)
        use_c = (d_c <= d_l) & (d_c <= d_k)
        use_l = ~use_c & (d_l <= d_k)
        qx = np.where(use_c, px_c, np.where(use_l, px_l, cx))
        qy = np.where(use_c, py_c, np.where(use_l, py_l, cy))
        dx, dy = xr - qx, ya - qy
        dist = np.maximum(np.hypot(dx, dy), 1e-300)
        nx, ny = dx / dist, dy / dist
        g = np.where(inside, -d, d) - rho
        nx, ny = np.where(inside, -nx, nx), np.where(inside, -ny, ny)
        ny = ny * sgn
        # back to the mesh's frame: x = -y', y = x'
        return g, np.column_stack([-ny, nx])


def mesh(R: float, alpha: float, beta: float, h: float, hc: float, rho: float,
         band: tuple[float, float] = (8.0, 8.0), half: bool = True):
    """The hemidisk, or its left half ``90 <= theta <= 180`` deg with the boundary
    ``symmetry`` on the axis (boundaries ``skull``, ``opening``, ``base``); ``hc`` along the
    arc within ``band`` degrees (opening side, skull side) of the edge, ``h/5`` at the sector
    edge's end [length, deg]."""
    import ngsolve as ngs
    from netgen.meshing import MeshingParameters
    from netgen.occ import Glue, OCCGeometry

    from brainbulge.geometry.hemidisk import _edge_mid, _edge_radius, _pie_slice

    lo = 90.0 if half else 0.0
    edges = [90 + beta / 2] + ([] if half else [90 - beta / 2])
    sector = [90 + alpha / 2] + ([] if half else [90 - alpha / 2])
    breaks = sorted({lo, 180.0, *edges, *sector})
    slices = []
    for a0, a1 in zip(breaks[:-1], breaks[1:], strict=True):
        mid = 0.5 * (a0 + a1)
        face = _pie_slice(R, a0, a1)
        arc = max(face.edges, key=_edge_radius)
        arc.name = "opening" if abs(mid - 90) < beta / 2 else "skull"
        for e in face.edges:
            if e is arc:
                continue
            x, y = _edge_mid(e)
            if abs(y) < 1e-9 * R:
                e.name = "base"
            elif half and abs(x) < 1e-9 * R:
                e.name = "symmetry"
        face.faces.name = "swelling" if abs(mid - 90) < alpha / 2 else "tissue"
        slices.append(face)
    mp = MeshingParameters(maxh=h, grading=0.25)
    for e in edges:
        sgn = 1 if e > 90 else -1
        a_open, a_skull = e - sgn * band[0], e + sgn * band[1]
        n = max(2, math.ceil(abs(a_skull - a_open) * math.pi / 180 * R / hc))
        for k in range(n + 1):
            t = math.radians(a_open + (a_skull - a_open) * k / n)
            for depth in (0.0, 2 * hc):
                rr = R - depth
                mp.RestrictH(x=rr * math.cos(t), y=rr * math.sin(t), z=0, h=hc)
    for s in sector:
        t = math.radians(s)
        mp.RestrictH(x=R * math.cos(t), y=R * math.sin(t), z=0, h=h / 5)
    m = ngs.Mesh(OCCGeometry(Glue(slices), dim=2).GenerateMesh(mp=mp))
    m.Curve(2)
    return m
