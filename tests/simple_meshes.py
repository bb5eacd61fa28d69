"""Small structured meshes for tests (numpy only)."""

from __future__ import annotations

import numpy as np


def box_mesh(n: int, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Cube [lo, hi]^3, n^3 cells, each split into the 6 Kuhn tets (conforming)."""
    g = np.linspace(lo, hi, n + 1)
    nodes = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    idx = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    corner = idx[:-1, :-1, :-1].ravel()
    step = np.array([(n + 1) ** 2, n + 1, 1])
    tets = []
    for perm in [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]:
        offs = np.cumsum([0] + [step[a] for a in perm])
        tets.append(corner[:, None] + offs[None])
    return nodes, np.concatenate(tets)
