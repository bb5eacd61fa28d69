"""Voxel centres inside tetrahedra: the kernel of the NIfTI maps' point location (numba).

Written by hand because NGSolve's point location (``mesh(x, y, z)`` on arrays) costs ~40 us
per voxel on the 111k-tet brain, about 85 s for the template's 2M tissue voxels; here each tet
visits the voxel centres of its bounding box (docs/design.md, "NIfTI maps"). Compiled on
first use (cached on disk), so importing the maps' module stays cheap.
"""

from __future__ import annotations

import numba
import numpy as np

#: a voxel centre belongs to a tetrahedron when every barycentric coordinate is at least
#: this (in index space: a few rounding errors of coordinates ~100 voxels)
INSIDE_TOLERANCE = -1e-9


@numba.njit(cache=True)
def rasterise_tets(corners: np.ndarray, shape: np.ndarray) -> np.ndarray:  # pragma: no cover
    """``element`` (nx * ny * nz,) int32 (C order): for each voxel centre ``(i, j, k)`` the
    last tetrahedron (index into ``corners``, (ne, 4, 3) corner positions in voxel index
    space) whose barycentric coordinates there are all >= :data:`INSIDE_TOLERANCE`, -1 for
    none. Each tetrahedron tests the voxel centres of its bounding box only."""
    nx, ny, nz = shape[0], shape[1], shape[2]
    element = np.full(nx * ny * nz, -1, dtype=np.int32)
    for e in range(corners.shape[0]):
        c = corners[e]
        lo = np.empty(3, dtype=np.int64)
        hi = np.empty(3, dtype=np.int64)
        for d in range(3):
            lo[d] = max(int(np.ceil(min(c[0, d], c[1, d], c[2, d], c[3, d]))), 0)
            hi[d] = min(int(np.floor(max(c[0, d], c[1, d], c[2, d], c[3, d]))), shape[d] - 1)
        if lo[0] > hi[0] or lo[1] > hi[1] or lo[2] > hi[2]:
            continue
        # T = [c0 - c3, c1 - c3, c2 - c3] (columns); its inverse by cofactors
        a = c[0, 0] - c[3, 0]
        b = c[1, 0] - c[3, 0]
        cc = c[2, 0] - c[3, 0]
        d_ = c[0, 1] - c[3, 1]
        e_ = c[1, 1] - c[3, 1]
        f = c[2, 1] - c[3, 1]
        g = c[0, 2] - c[3, 2]
        h = c[1, 2] - c[3, 2]
        k_ = c[2, 2] - c[3, 2]
        det = a * (e_ * k_ - f * h) - b * (d_ * k_ - f * g) + cc * (d_ * h - e_ * g)
        if det == 0.0:
            continue
        inv = 1.0 / det
        m00 = (e_ * k_ - f * h) * inv
        m01 = (cc * h - b * k_) * inv
        m02 = (b * f - cc * e_) * inv
        m10 = (f * g - d_ * k_) * inv
        m11 = (a * k_ - cc * g) * inv
        m12 = (cc * d_ - a * f) * inv
        m20 = (d_ * h - e_ * g) * inv
        m21 = (b * g - a * h) * inv
        m22 = (a * e_ - b * d_) * inv
        for i in range(lo[0], hi[0] + 1):
            px = i - c[3, 0]
            for j in range(lo[1], hi[1] + 1):
                py = j - c[3, 1]
                for k in range(lo[2], hi[2] + 1):
                    pz = k - c[3, 2]
                    l0 = m00 * px + m01 * py + m02 * pz
                    l1 = m10 * px + m11 * py + m12 * pz
                    l2 = m20 * px + m21 * py + m22 * pz
                    if (l0 >= INSIDE_TOLERANCE and l1 >= INSIDE_TOLERANCE
                            and l2 >= INSIDE_TOLERANCE
                            and 1.0 - l0 - l1 - l2 >= INSIDE_TOLERANCE):
                        element[(i * ny + j) * nz + k] = e
    return element


@numba.njit(cache=True)
def barycentric_weights(corners: np.ndarray, element: np.ndarray, index: np.ndarray,
                        shape: np.ndarray) -> np.ndarray:  # pragma: no cover
    """(n, 4) barycentric coordinates of the voxel centres ``index`` (flat, C order) in their
    tetrahedra ``element`` (corner positions ``corners`` in voxel index space)."""
    ny, nz = shape[1], shape[2]
    out = np.empty((index.shape[0], 4))
    for n in range(index.shape[0]):
        flat = index[n]
        c = corners[element[n]]
        px = flat // (ny * nz) - c[3, 0]
        py = (flat // nz) % ny - c[3, 1]
        pz = flat % nz - c[3, 2]
        a, b, cc = c[0, 0] - c[3, 0], c[1, 0] - c[3, 0], c[2, 0] - c[3, 0]
        d_, e_, f = c[0, 1] - c[3, 1], c[1, 1] - c[3, 1], c[2, 1] - c[3, 1]
        g, h, k_ = c[0, 2] - c[3, 2], c[1, 2] - c[3, 2], c[2, 2] - c[3, 2]
        inv = 1.0 / (a * (e_ * k_ - f * h) - b * (d_ * k_ - f * g) + cc * (d_ * h - e_ * g))
        l0 = ((e_ * k_ - f * h) * px + (cc * h - b * k_) * py + (b * f - cc * e_) * pz) * inv
        l1 = ((f * g - d_ * k_) * px + (a * k_ - cc * g) * py + (cc * d_ - a * f) * pz) * inv
        l2 = ((d_ * h - e_ * g) * px + (b * g - a * h) * py + (a * e_ - b * d_) * pz) * inv
        out[n, 0], out[n, 1], out[n, 2], out[n, 3] = l0, l1, l2, 1.0 - l0 - l1 - l2
    return out
