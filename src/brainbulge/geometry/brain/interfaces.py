"""Tissue interfaces fitted to smooth surfaces: interface nodes moved onto smoothed label levels.

Tissue tags are per tetrahedron (:func:`regions.tag_tissue`), so the interfaces between tissues
are element faces: staircases whose faces tilt ~45 deg from the true normal and overstate the
area ~1.55x (a sphere, ``benchmarks/bench_interfaces.py``). Strain maxima sit on such steps
and grow under refinement. This module fits the tagged interfaces to the label surfaces:

1. Level sets. For each tissue ``c`` the voxel mask ``M_c`` (CSF: CSF or background, the layer
   under the skull) gives a signed distance, negative inside, Gaussian-smoothed (``sigma =
   smoothing_voxels``): ``phi_c = G_sigma * (d(x, M_c) - d(x, not M_c) -+ h/2)``, ``h`` the
   voxel size (the half-voxel shift makes voxel-centre distances distances to the voxel
   faces, as in :mod:`envelope`), sampled by trilinear interpolation through the affine. The
   surface between tissues ``a`` and ``b`` is the zero level of
   ``psi_ab = ((phi_a + o_a) - (phi_b + o_b)) / 2`` (negative on ``a``'s side, ``|grad| ~ 1``),
   ``o_c`` per-tissue level offsets (mm, step 5).
2. Teeth. An interior tet whose tag differs from at least 3 of its 4 face neighbours' takes
   their most frequent tag ``n``, where ``phi_n + o_n < phi_own + o_own + teeth_margin_mm``
   at its centroid (a tooth the label surfaces clearly confirm -- a sub-element structure,
   e.g. a small ventricle -- stays); ``teeth_passes`` sweeps.
3. Moves. Interface nodes (their tets carry more than one tissue) move, except those of the
   outer layer's tets (the CSF under the skull, thinner than the elements, is a
   volume-matched dither of that layer: it stays as tagged) and those of unresolved
   interfaces (at the Newton point ``x*`` below, either tissue reaches less than ``d = h_e/2``
   into its side: ``phi_a(x* - d n) > -d/2`` or ``phi_b(x* + d n) > -d/2``, ``n`` the unit
   gradient, ``h_e`` the node's mean edge: a coarse mesh's cortex or sulcal CSF). Each node
   takes ``newton_steps`` Newton steps ``dx = -psi_ab grad(psi_ab) / |grad(psi_ab)|^2`` for
   its two tissues of largest adjacent volume, each capped at ``step_cap h_e``; their
   free neighbours relax towards their neighbours' mean by ``relax``. Guard: a node's step is
   halved (4 times, then dropped) while any of its tets would fall below
   ``min_volume_ratio`` of its volume before fitting, or its minimum dihedral angle below
   ``min(theta_0, min_dihedral_deg)`` (``theta_0`` its own before): no tet inverts.
4. Re-tagging (``retag``, from the second of ``rounds``): a tet next to an interface takes
   the tissue of least ``phi_c + o_c`` at its centroid among its own and its neighbours',
   if that is negative -- a staircase cell cut off by the fitted surface changes sides.
5. Volumes. Targets: the image's voxel volumes scaled to the mesh (``V_c^* =
   N_c v_vox V_mesh / V_icv``, CSF the rest, as :func:`regions.tag_tissue`). After each
   round ``o_c <- o_c - 2 k (V_c^* - V_c) / A_c`` (``A_c``: the tissue's interface area,
   ``k = 0.7`` damping, ``|o_c| <= 1 mm``, ``o_CSF = 0``): a resolved surface moves out by
   its volume error over its area. What the offsets cannot reach (pinned or unresolved
   interfaces) is handed over in whole tets at the end (:func:`balance_volumes`), so every
   tissue ends within ``volume_tolerance`` of its target.

The outer surface (the skull's inner surface) is not touched. All lengths mm, volumes mm^3.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.ndimage as ndi
from scipy.sparse import coo_matrix, csr_matrix

from brainbulge.geometry.brain.labels import CSF, TISSUES, TissueImage
from brainbulge.geometry.brain.quality import dihedral_angles_deg, tet_volumes_mm3
from brainbulge.geometry.brain.regions import (
    exchange_volumes,
    tissue_fractions,
)

log = logging.getLogger("brainbulge")

#: Local vertex numbers of the face opposite each vertex of a tet.
_FACES = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
_N_CODES = len(TISSUES) + 1


@dataclass
class TissueLevelSets:
    """Smoothed signed distances ``phi_c`` (mm, negative inside tissue ``c``) on crops of the
    label grid: ``phi[c]`` a float32 array, ``origin[c]`` the crop's first voxel index;
    ``inverse``: the world -> index affine of the label grid."""

    phi: dict[int, np.ndarray]
    origin: dict[int, np.ndarray]
    inverse: np.ndarray

    def sample(self, code: int, points_mm: np.ndarray) -> np.ndarray:
        """``phi_code`` at world points (trilinear; outside the crop the crop's edge value)."""
        ijk = points_mm @ self.inverse[:3, :3].T + self.inverse[:3, 3] - self.origin[code]
        return ndi.map_coordinates(self.phi[code], ijk.T, order=1, mode="nearest")

    def gradient(self, code: int, points_mm: np.ndarray, h_mm: float = 0.5) -> np.ndarray:
        """``grad phi_code`` at world points (central differences of step ``h_mm``), (n, 3)."""
        return np.stack([(self.sample(code, points_mm + h_mm * e)
                          - self.sample(code, points_mm - h_mm * e)) / (2 * h_mm)
                         for e in np.eye(3)], axis=1)


def tissue_level_sets(image: TissueImage, codes: np.ndarray, smoothing_voxels: float = 1.0,
                      margin_voxels: int = 8) -> TissueLevelSets:
    """The smoothed signed distance of each tissue in ``codes`` (see module docstring, 1.)."""
    spacing = np.linalg.norm(image.affine[:3, :3], axis=0)
    half = 0.5 * float(spacing.mean())
    phi, origin = {}, {}
    for code in (int(c) for c in codes):
        full = (image.tissue == code) | ((image.tissue == 0) if code == CSF else False)
        idx = np.argwhere(full)
        if len(idx) == 0:
            continue
        lo = np.maximum(idx.min(axis=0) - margin_voxels, 0)
        hi = np.minimum(idx.max(axis=0) + margin_voxels + 1, full.shape)
        mask = full[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
        sdf = np.where(mask, half - ndi.distance_transform_edt(mask, sampling=spacing),
                       ndi.distance_transform_edt(~mask, sampling=spacing) - half)
        phi[code] = ndi.gaussian_filter(sdf, smoothing_voxels).astype(np.float32)
        origin[code] = lo.astype(float)
    return TissueLevelSets(phi, origin, np.linalg.inv(image.affine))


def face_neighbours(tets: np.ndarray) -> np.ndarray:
    """(m, 4) index of the tet across the face opposite each vertex, -1 on the outer surface."""
    faces = np.sort(tets[:, _FACES].reshape(-1, 3), axis=1)
    owner = np.repeat(np.arange(len(tets)), 4)
    order = np.lexsort(faces.T[::-1])
    f, o = faces[order], owner[order]
    same = np.flatnonzero(np.all(f[1:] == f[:-1], axis=1))
    out = np.full(4 * len(tets), -1)
    out[order[same]] = o[same + 1]
    out[order[same + 1]] = o[same]
    return out.reshape(-1, 4)


def remove_teeth(tissue: np.ndarray, neighbours: np.ndarray, passes: int = 3,
                 level: np.ndarray | None = None, margin: np.ndarray | float = 0.0
                 ) -> np.ndarray:
    """Tags with "teeth" removed (module docstring, 2.): an interior tet whose tag differs from
    at least 3 of its face neighbours' takes their most frequent tag. With ``level`` ((m, 6):
    ``phi_c + o_c`` at each centroid) only where that tissue's level is lower there than the
    tet's own plus ``margin`` (mm, per tet or one): a tooth that the label surfaces confirm
    (a coarse mesh's dither of a thin structure, which holds its volume) stays."""
    tissue = tissue.copy()
    has = neighbours >= 0
    rows = np.arange(len(tissue))
    for _ in range(passes):
        nb = np.where(has, tissue[np.maximum(neighbours, 0)], -1)
        differ = (has & (nb != tissue[:, None])).sum(axis=1)
        counts = np.stack([(nb == c).sum(axis=1) for c in range(_N_CODES)], axis=1)
        counts[rows, tissue] = -1
        new = np.argmax(counts, axis=1)
        flip = (differ >= 3) & has.all(axis=1)
        if level is not None:
            flip &= level[rows, new] < level[rows, tissue] + margin
        if not flip.any():
            break
        tissue[flip] = new[flip]
    return tissue


def _node_tet_matrix(tets: np.ndarray, n_nodes: int) -> csr_matrix:
    """Sparse (n_nodes, m) incidence of nodes in tets."""
    rows = tets.ravel()
    cols = np.repeat(np.arange(len(tets)), 4)
    return coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_nodes, len(tets))).tocsr()


def interface_pairs(incidence: csr_matrix, tissue: np.ndarray, vol: np.ndarray,
                    fixed: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interface nodes (more than one tissue among their tets, not ``fixed``) and, for each,
    its two tissues of largest adjacent tet volume ``(a, b)``."""
    onehot = np.zeros((len(tissue), _N_CODES))
    onehot[np.arange(len(tissue)), tissue] = vol
    share = np.asarray(incidence @ onehot)
    nodes = np.flatnonzero(((share > 0).sum(axis=1) > 1) & ~fixed)
    order = np.argsort(-share[nodes], axis=1)
    return nodes, order[:, 0], order[:, 1]


def _guarded_move(nodes: np.ndarray, tets: np.ndarray, incidence: csr_matrix, idx: np.ndarray,
                  step: np.ndarray, vol0: np.ndarray, dih0: np.ndarray,
                  min_volume_ratio: float, min_dihedral_deg: float) -> np.ndarray:
    """``nodes`` with ``idx`` moved by ``step``, each step halved (4 times, then dropped) while
    one of its tets fails the guard (module docstring, 3.)."""
    affected = np.unique(incidence[idx].indices)
    sub = tets[affected]
    floor = np.minimum(dih0[affected], min_dihedral_deg)
    scale = np.ones(len(idx))
    local = np.full(len(nodes), -1)
    local[idx] = np.arange(len(idx))
    for attempt in range(6):
        trial = nodes.copy()
        trial[idx] += scale[:, None] * step
        bad = ((tet_volumes_mm3(trial, sub) < min_volume_ratio * vol0[affected])
               | (dihedral_angles_deg(trial, sub).min(axis=1) < floor))
        if not bad.any():
            return trial
        culprits = local[sub[bad].ravel()]
        culprits = np.unique(culprits[culprits >= 0])
        scale[culprits] = 0.5 * scale[culprits] if attempt < 4 else 0.0
    return nodes  # unreachable in practice: all steps dropped restores the passing state


def fit_interfaces(nodes: np.ndarray, tets: np.ndarray, tissue: np.ndarray, image: TissueImage,
                   intracranial_volume_ml: float | None = None, smoothing_voxels: float = 1.0,
                   rounds: int = 5, newton_steps: int = 2, step_cap: float = 0.5,
                   min_volume_ratio: float = 0.25, min_dihedral_deg: float = 10.0,
                   teeth_passes: int = 3, teeth_margin_mm: float = 1.0, retag: bool = True,
                   volume_tolerance: float = 0.005,
                   level_sets: TissueLevelSets | None = None, relax: float = 0.5,
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Nodes (mm) and tissue tags with the tagged interfaces fitted to the smoothed label
    surfaces (module docstring); the outer surface's nodes stay. ``intracranial_volume_ml``:
    the envelope's voxel volume that the image's volumes are scaled from (default: the mesh's).
    """
    tissue = np.asarray(tissue).astype(np.int64)
    nodes = np.asarray(nodes, dtype=float).copy()
    codes = np.unique(tissue)
    if len(codes) < 2:
        return nodes, tissue.astype(np.int8)
    ls = level_sets or tissue_level_sets(image, codes, smoothing_voxels)
    codes = np.array([c for c in codes if c in ls.phi])
    neighbours = face_neighbours(tets)
    incidence = _node_tet_matrix(tets, len(nodes))
    adjacency = _edge_adjacency(tets, len(nodes))
    fixed = np.zeros(len(nodes), dtype=bool)
    fixed[_outer_face_nodes(tets, neighbours)] = True
    # the outer layer's interfaces (the CSF under the skull, thinner than the elements, is a
    # volume-matched dither of the layer's tets) stay as tagged: its tets' nodes do not move
    outer_layer = fixed[tets].any(axis=1)
    pinned = fixed.copy()
    pinned[tets[outer_layer]] = True
    vol0 = tet_volumes_mm3(nodes, tets)
    dih0 = dihedral_angles_deg(nodes, tets).min(axis=1)
    target = _target_volumes(image, vol0.sum(), intracranial_volume_ml)
    offset = np.zeros(_N_CODES)
    edge = _mean_edge_mm(nodes, tets)
    margin = teeth_margin_mm
    tissue = remove_teeth(tissue, neighbours, teeth_passes,
                          _centroid_levels(ls, offset, nodes, tets, codes), margin)
    for r in range(rounds):
        if retag and r > 0:
            tissue = _retag(ls, offset, nodes, tets, tissue, neighbours, codes, fixed)
            tissue = remove_teeth(tissue, neighbours, teeth_passes,
                                  _centroid_levels(ls, offset, nodes, tets, codes), margin)
        vol = tet_volumes_mm3(nodes, tets)
        idx, a, b = interface_pairs(incidence, tissue, vol, pinned)
        ok = np.isin(a, codes) & np.isin(b, codes)
        ok[ok] = _resolved(ls, offset, nodes[idx[ok]], a[ok], b[ok], edge[idx[ok]])
        idx, a, b = idx[ok], a[ok], b[ok]
        for _ in range(newton_steps):
            psi, grad = _pair_level(ls, offset, nodes[idx], a, b)
            g2 = np.maximum(np.einsum("ij,ij->i", grad, grad), 1e-6)
            step = -(psi / g2)[:, None] * grad
            length = np.linalg.norm(step, axis=1)
            cap = step_cap * edge[idx]
            step *= np.minimum(1.0, cap / np.maximum(length, 1e-12))[:, None]
            nodes = _guarded_move(nodes, tets, incidence, idx, step, vol0, dih0,
                                  min_volume_ratio, min_dihedral_deg)
            if relax:
                ring = np.setdiff1d(np.unique(tets[incidence[idx].indices]), idx)
                ring = ring[~fixed[ring]]
                step = relax * (_neighbour_mean(nodes, adjacency, ring) - nodes[ring])
                nodes = _guarded_move(nodes, tets, incidence, ring, step, vol0, dih0,
                                      min_volume_ratio, min_dihedral_deg)
        vol = tet_volumes_mm3(nodes, tets)
        err = _update_offsets(offset, nodes, tets, tissue, neighbours, vol, target, codes)
        log.info("interfaces round %d: %d nodes, worst volume error %.2f %%, offsets %s",
                 r + 1, len(idx), 100 * err, np.round(offset[codes], 2))
        if err < volume_tolerance and r >= 1:
            break
    tissue = balance_volumes(image, nodes, tets, tissue, target, volume_tolerance)
    return nodes, tissue.astype(np.int8)


def balance_volumes(image: TissueImage, nodes: np.ndarray, tets: np.ndarray,
                    tissue: np.ndarray, target: np.ndarray, volume_tolerance: float = 0.005,
                    max_passes: int = 60) -> np.ndarray:
    """Tags with every tissue's volume within ``volume_tolerance`` of ``target`` (mm^3): what
    the level offsets cannot move (unresolved, pinned interfaces; teeth removed from a dither)
    is handed over in whole tets that hold both tissues, least image fraction lost first
    (:func:`regions.tag_tissue`'s exchange, on the fitted nodes)."""
    frac = tissue_fractions(image, nodes, tets)
    frac[np.arange(len(tets)), tissue] = np.maximum(frac[np.arange(len(tets)), tissue], 1e-3)
    vol = tet_volumes_mm3(nodes, tets)
    tag = tissue.astype(np.int64).copy()
    exchange_volumes(tag, frac, vol, target, volume_tolerance, max_passes)
    return tag


def _outer_face_nodes(tets: np.ndarray, neighbours: np.ndarray) -> np.ndarray:
    """Nodes on the outer surface."""
    t, f = np.nonzero(neighbours < 0)
    return np.unique(tets[t[:, None], _FACES[f]])


def _mean_edge_mm(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Mean length of the edges at each node (mm), over its tets' edges through it."""
    i, j = np.triu_indices(4, 1)
    a, b = tets[:, i].ravel(), tets[:, j].ravel()
    length = np.linalg.norm(nodes[a] - nodes[b], axis=1)
    total = np.bincount(a, length, len(nodes)) + np.bincount(b, length, len(nodes))
    count = np.bincount(a, minlength=len(nodes)) + np.bincount(b, minlength=len(nodes))
    return total / np.maximum(count, 1)


def _resolved(ls: TissueLevelSets, offset: np.ndarray, points: np.ndarray, a: np.ndarray,
              b: np.ndarray, edge: np.ndarray, depth: float = 0.5) -> np.ndarray:
    """Whether the mesh resolves each node's interface: at the node's Newton point
    ``x* = x - psi grad(psi) / |grad(psi)|^2``, both tissues reach ``depth`` edge lengths
    into their sides, ``phi_a(x* - d n) < -d / 2`` and ``phi_b(x* + d n) < -d / 2`` with
    ``d = depth h`` and ``n = grad(psi) / |grad(psi)|`` (from ``a`` to ``b``). A structure
    thinner than that (a coarse mesh's cortex, sulcal CSF, the CSF under the skull) is tagged
    as a volume-matched dither of whole tets: its nodes stay."""
    psi, grad = _pair_level(ls, offset, points, a, b)
    g2 = np.maximum(np.einsum("ij,ij->i", grad, grad), 1e-6)
    target = points - (psi / g2)[:, None] * grad
    d = (depth * edge)[:, None] * grad / np.sqrt(g2)[:, None]
    inside_a = np.zeros(len(points))
    inside_b = np.zeros(len(points))
    for code in np.unique(np.concatenate([a, b])):
        for sel, out, sign in ((a == code, inside_a, -1.0), (b == code, inside_b, 1.0)):
            if sel.any():
                out[sel] = ls.sample(int(code), target[sel] + sign * d[sel]) + offset[code]
    half = 0.5 * depth * edge
    return (inside_a < -half) & (inside_b < -half)


def _edge_adjacency(tets: np.ndarray, n_nodes: int) -> csr_matrix:
    """Sparse (n, n) node adjacency along the tets' edges (ones)."""
    i, j = np.triu_indices(4, 1)
    a, b = tets[:, i].ravel(), tets[:, j].ravel()
    adj = coo_matrix((np.ones(2 * len(a)), (np.r_[a, b], np.r_[b, a])),
                     shape=(n_nodes, n_nodes)).tocsr()
    adj.data[:] = 1.0  # duplicates (an edge in several tets) summed: count it once
    return adj


def _neighbour_mean(nodes: np.ndarray, adjacency: csr_matrix, idx: np.ndarray) -> np.ndarray:
    """Mean position of the edge neighbours of each node in ``idx`` (mm)."""
    adj = adjacency[idx]
    return (adj @ nodes) / np.asarray(adj.sum(axis=1))


def _pair_level(ls: TissueLevelSets, offset: np.ndarray, points: np.ndarray, a: np.ndarray,
                b: np.ndarray, gradient: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """``psi_ab`` and its gradient at ``points`` for per-point tissue pairs ``(a, b)``."""
    psi = np.zeros(len(points))
    grad = np.zeros((len(points), 3))
    for code in np.unique(np.concatenate([a, b])):
        for sel, sign in ((a == code, 0.5), (b == code, -0.5)):
            if sel.any():
                psi[sel] += sign * (ls.sample(int(code), points[sel]) + offset[code])
                if gradient:
                    grad[sel] += sign * ls.gradient(int(code), points[sel])
    return psi, grad


def _centroid_levels(ls: TissueLevelSets, offset: np.ndarray, nodes: np.ndarray,
                     tets: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """``phi_c + o_c`` at every tet's centroid, (m, 6); +inf for tissues without a level."""
    centroids = nodes[tets].mean(axis=1)
    level = np.full((len(tets), _N_CODES), np.inf)
    for code in codes:
        level[:, code] = ls.sample(int(code), centroids) + offset[code]
    return level


def _retag(ls: TissueLevelSets, offset: np.ndarray, nodes: np.ndarray, tets: np.ndarray,
           tissue: np.ndarray, neighbours: np.ndarray, codes: np.ndarray, fixed: np.ndarray
           ) -> np.ndarray:
    """Tets next to an interface take the tissue of least ``phi_c + o_c`` at their centroid
    among their own and their neighbours' tissues, if that level is negative there."""
    nb = np.where(neighbours >= 0, tissue[np.maximum(neighbours, 0)], tissue[:, None])
    near = np.flatnonzero(np.any(nb != tissue[:, None], axis=1) & ~fixed[tets].any(axis=1))
    centroids = nodes[tets[near]].mean(axis=1)
    level = np.full((len(near), _N_CODES), np.inf)
    for code in codes:
        cand = np.any(nb[near] == code, axis=1) | (tissue[near] == code)
        if cand.any():
            level[cand, code] = ls.sample(int(code), centroids[cand]) + offset[code]
    best = np.argmin(level, axis=1)
    change = (level[np.arange(len(near)), best] < 0) & (best != tissue[near])
    out = tissue.copy()
    out[near[change]] = best[change]
    return out


def _target_volumes(image: TissueImage, mesh_mm3: float, icv_ml: float | None) -> np.ndarray:
    """Voxel volume of each tissue code scaled to the mesh (mm^3); CSF takes the rest."""
    counts = np.bincount(image.tissue.ravel().astype(np.int64), minlength=_N_CODES)
    scale = 1.0 if icv_ml is None else mesh_mm3 / (icv_ml * 1000)
    target = counts[:_N_CODES] * image.voxel_volume_mm3 * scale
    target[0] = 0.0
    target[CSF] = mesh_mm3 - (target.sum() - target[CSF])
    return target


def _update_offsets(offset: np.ndarray, nodes: np.ndarray, tets: np.ndarray,
                    tissue: np.ndarray, neighbours: np.ndarray, vol: np.ndarray,
                    target: np.ndarray, codes: np.ndarray, damping: float = 0.7,
                    max_offset_mm: float = 1.0) -> float:
    """``o_c <- o_c - 2 (V_c^* - V_c) / A_c`` (module docstring, 5.); returns the worst
    relative volume error before the update."""
    mesh = np.bincount(tissue, weights=vol, minlength=_N_CODES)
    t, f = np.nonzero((neighbours >= 0) & (tissue[np.maximum(neighbours, 0)] != tissue[:, None]))
    p = nodes[tets[t[:, None], _FACES[f]]]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    area_c = np.bincount(tissue[t], weights=area, minlength=_N_CODES)
    worst = 0.0
    for c in codes:
        if target[c] <= 0 or area_c[c] <= 0:
            continue
        worst = max(worst, abs(mesh[c] - target[c]) / target[c])
        if c != CSF:
            offset[c] = np.clip(offset[c] - damping * 2 * (target[c] - mesh[c]) / area_c[c],
                                -max_offset_mm, max_offset_mm)
    return worst
