"""Element quality of tetrahedral meshes: dihedral angles, volumes, aspect."""

from __future__ import annotations

import numpy as np


def tet_volumes_mm3(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes (mm^3) of tetrahedra, positive for right-handed vertex order."""
    p = nodes[tets]
    return np.einsum("ij,ij->i", p[:, 1] - p[:, 0],
                     np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6


_OPPOSITE_FACES = ((1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2))


def dihedral_angles_deg(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """The six interior dihedral angles (degrees) of each tetrahedron, shape (m, 6)."""
    p = nodes[tets]
    normals = []
    for i, (a, b, c) in enumerate(_OPPOSITE_FACES):
        n = np.cross(p[:, b] - p[:, a], p[:, c] - p[:, a])
        outward = np.sign(np.einsum("ij,ij->i", n, p[:, a] - p[:, i]))
        normals.append(n * (outward / np.linalg.norm(n, axis=1))[:, None])
    angles = [180.0 - np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", normals[i],
                                                             normals[j]), -1.0, 1.0)))
              for i in range(4) for j in range(i + 1, 4)]
    return np.stack(angles, axis=1)


def quality_stats(nodes: np.ndarray, tets: np.ndarray) -> dict[str, float | int]:
    """Summary: counts, min/max dihedral (deg), elements under 10 deg, volume range (mm^3)."""
    dihedral = dihedral_angles_deg(nodes, tets)
    dmin = dihedral.min(axis=1)
    vol = tet_volumes_mm3(nodes, tets)
    return {
        "nodes": int(len(nodes)),
        "tets": int(len(tets)),
        "min_dihedral_deg": float(dmin.min()),
        "max_dihedral_deg": float(dihedral.max()),
        "p01_min_dihedral_deg": float(np.percentile(dmin, 0.1)),
        "tets_below_10deg": int((dmin < 10).sum()),
        "inverted_tets": int((vol <= 0).sum()),
        "min_volume_mm3": float(vol.min()),
        "max_volume_mm3": float(vol.max()),
    }
