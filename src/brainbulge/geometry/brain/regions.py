"""Tissue and hemisphere tags per tetrahedron, sampled from the label image.

Each tetrahedron's tissue fractions are estimated from 15 interior sample points read from the
label image (nearest voxel, through the inverse affine); voxels outside the brain but inside the
envelope (the layer under the skull) are CSF. A plain majority vote would shrink thin
structures (the CSF layer, the cortex) by 5-20 % at coarse sizes, so the tag is
first the majority tissue, then, tissue by tissue, the tets of over-full tissues that hold most
of an under-full one are handed over (least fraction lost first) until every tissue's mesh
volume matches its voxel volume to ``volume_tolerance``. Interfaces between regions are then
element faces, so they conform by construction. The hemisphere is the side of the
mid-sagittal plane the centroid lies on.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.ndimage as ndi

from brainbulge.geometry.brain.labels import CSF, TISSUES, TissueImage
from brainbulge.geometry.brain.quality import tet_volumes_mm3

LEFT, RIGHT = 0, 1
SIDES = {LEFT: "left", RIGHT: "right"}

# barycentric sample points: centroid, 4 towards the vertices, 4 towards the faces, 6 edges
_a, _b = 0.5854101966249685, 0.1381966011250105
_SAMPLES = np.array(
    [[0.25] * 4]
    + [[_a if i == j else _b for j in range(4)] for i in range(4)]
    + [[0.1 if i == j else 0.3 for j in range(4)] for i in range(4)]
    + [[0.4 if k in (i, j) else 0.1 for k in range(4)] for i in range(4) for j in range(i + 1, 4)]
)


@dataclass(frozen=True)
class MidSagittalPlane:
    """The plane splitting left from right hemisphere: a point and the normal towards right (mm)."""

    point_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    normal: tuple[float, float, float] = (1.0, 0.0, 0.0)

    @classmethod
    def through_centroid(cls, image: TissueImage) -> MidSagittalPlane:
        """The world plane x = const through the brain's centroid (RAS+: +x is right)."""
        idx = np.argwhere(image.tissue > 0).mean(axis=0)
        centre = image.affine[:3, :3] @ idx + image.affine[:3, 3]
        return cls((float(centre[0]), 0.0, 0.0), (1.0, 0.0, 0.0))

    def side(self, points_mm: np.ndarray) -> np.ndarray:
        """``LEFT`` (0) or ``RIGHT`` (1) for each point."""
        d = (points_mm - np.asarray(self.point_mm)) @ np.asarray(self.normal)
        return (d > 0).astype(np.int8)


def sample_tissue(image: TissueImage, points_mm: np.ndarray) -> np.ndarray:
    """Tissue codes at world points (nearest voxel); 0 outside the brain."""
    inv = np.linalg.inv(image.affine)
    ijk = points_mm @ inv[:3, :3].T + inv[:3, 3]
    return ndi.map_coordinates(image.tissue, ijk.T, order=0, mode="constant", cval=0)


def tissue_fractions(image: TissueImage, nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Estimated volume fraction of each tissue code (columns 0..5) in each tetrahedron."""
    pts = np.einsum("sk,mkd->msd", _SAMPLES, nodes[tets])
    codes = sample_tissue(image, pts.reshape(-1, 3)).reshape(len(tets), len(_SAMPLES))
    codes[codes == 0] = CSF
    return np.stack([(codes == c).mean(axis=1) for c in range(len(TISSUES) + 1)], axis=1)


def tag_tissue(
    image: TissueImage,
    nodes: np.ndarray,
    tets: np.ndarray,
    intracranial_volume_ml: float | None = None,
    plane: MidSagittalPlane | None = None,
    volume_tolerance: float = 0.005,
    max_passes: int = 60,
) -> np.ndarray:
    """Tissue code (1..5) of each tetrahedron, volume-matched to the voxel volumes.

    Targets: the image's voxel volume of every tissue but CSF, scaled by mesh volume /
    ``intracranial_volume_ml`` (the envelope's voxel volume; default: the mesh volume); CSF
    takes the rest of the mesh volume. With a ``plane`` the targets are per tissue and
    hemisphere (tets stay on their side), so that every ``{tissue}_{side}`` region matches.
    """
    frac = tissue_fractions(image, nodes, tets)
    vol = tet_volumes_mm3(nodes, tets)
    n_codes = len(TISSUES) + 1
    total = vol.sum()
    scale = 1.0 if intracranial_volume_ml is None else total / (intracranial_volume_ml * 1000)
    tissue_idx = np.argwhere(image.tissue > 0)
    codes = image.tissue[tuple(tissue_idx.T)].astype(np.int64)
    if plane is None:
        tet_side = np.zeros(len(tets), dtype=np.int64)
        voxel_side = np.zeros(len(codes), dtype=np.int64)
    else:
        tet_side = plane.side(nodes[tets].mean(axis=1)).astype(np.int64)
        world = tissue_idx @ image.affine[:3, :3].T + image.affine[:3, 3]
        voxel_side = plane.side(world).astype(np.int64)
    n_sides = 2 if plane is not None else 1
    voxel = np.bincount(codes + n_codes * voxel_side, minlength=n_codes * n_sides)
    target = voxel * image.voxel_volume_mm3 * scale
    side_total = np.bincount(tet_side, weights=vol, minlength=n_sides)
    for side in range(n_sides):
        block = slice(side * n_codes, (side + 1) * n_codes)
        others = target[block].sum() - target[block][CSF]
        target[side * n_codes + CSF] = side_total[side] - others
    target[::n_codes] = 0.0  # background
    # fractions per (tissue, side) class: a tet holds only classes of its own side
    frac_cls = np.zeros((len(tets), n_codes * n_sides))
    for side in range(n_sides):
        on = tet_side == side
        frac_cls[on, side * n_codes:(side + 1) * n_codes] = frac[on]
    frac_cls[:, target <= 0] = 0.0
    bias = 1e-6 * (np.arange(frac_cls.shape[1]) % n_codes == CSF)
    tag = np.argmax(frac_cls + bias, axis=1)
    exchange_volumes(tag, frac_cls, vol, target, volume_tolerance, max_passes)
    return (tag % n_codes).astype(np.int8)


def exchange_volumes(tag: np.ndarray, frac: np.ndarray, vol: np.ndarray, target: np.ndarray,
                     volume_tolerance: float, max_passes: int) -> None:
    """Relabel whole tets in place until every class's volume ``sum(vol[tag == c])`` is
    within ``volume_tolerance`` (relative) of ``target[c]`` (mm^3), or ``max_passes`` passes:
    each pass the most under-full class takes tets that hold some of it from over-full ones,
    then the most over-full gives tets away, least image fraction ``frac`` (tets x classes)
    lost first."""
    for _ in range(max_passes):
        if _relative_error(tag, vol, target).max() < volume_tolerance:
            break
        _fill_shortest(tag, frac, vol, target)
        _drain_fullest(tag, frac, vol, target)


def _relative_error(tag: np.ndarray, vol: np.ndarray, target: np.ndarray) -> np.ndarray:
    mesh_vol = np.bincount(tag, weights=vol, minlength=len(target))
    return np.abs(mesh_vol - target)[target > 0] / target[target > 0]


def _move(tag: np.ndarray, frac: np.ndarray, vol: np.ndarray, donor: int, receiver: int,
          amount: float) -> float:
    """Relabel up to ``amount`` (mm^3) of ``donor`` tets that hold some ``receiver`` tissue,
    least fraction lost first; returns the volume moved."""
    cand = np.flatnonzero((tag == donor) & (frac[:, receiver] > 0))
    cand = cand[np.argsort(frac[cand, donor] - frac[cand, receiver], kind="stable")]
    moved = np.cumsum(vol[cand])
    n = int(np.searchsorted(moved, amount, side="right"))
    tag[cand[:n]] = receiver
    return float(moved[n - 1]) if n else 0.0


def _fill_shortest(tag: np.ndarray, frac: np.ndarray, vol: np.ndarray, target: np.ndarray
                   ) -> None:
    """The most under-full tissue takes tets from over-full ones, none pushed below target."""
    excess = np.bincount(tag, weights=vol, minlength=len(target)) - target
    short = int(np.argmin(np.where(target > 0, excess / np.maximum(target, 1.0), np.inf)))
    deficit = -excess[short]
    for donor in np.argsort(-excess):
        if excess[donor] <= 0 or deficit <= 0:
            break
        deficit -= _move(tag, frac, vol, int(donor), short, min(deficit, excess[donor]))


def _drain_fullest(tag: np.ndarray, frac: np.ndarray, vol: np.ndarray, target: np.ndarray
                   ) -> None:
    """The most over-full tissue gives tets to the others, under-full ones first (each up to its
    deficit), then to its neighbours (which pass the volume on in later passes)."""
    excess = np.bincount(tag, weights=vol, minlength=len(target)) - target
    full = int(np.argmax(np.where(target > 0, excess / np.maximum(target, 1.0), -np.inf)))
    surplus = excess[full]
    for receiver in np.argsort(excess / np.maximum(target, 1.0)):
        if surplus <= 0:
            break
        if receiver == full or target[receiver] <= 0:
            continue
        room = -excess[receiver] if excess[receiver] < 0 else surplus
        surplus -= _move(tag, frac, vol, full, int(receiver), min(surplus, room))


def tissue_volumes_ml(nodes: np.ndarray, tets: np.ndarray, tissue: np.ndarray
                      ) -> dict[str, float]:
    """Mesh volume of each tissue (ml)."""
    vol = tet_volumes_mm3(nodes, tets)
    return {name: float(vol[tissue == code].sum() / 1000) for code, name in TISSUES.items()}
