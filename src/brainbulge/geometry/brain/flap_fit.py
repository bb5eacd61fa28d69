"""Where a craniectomy flap may go: candidate centres on the skull's convexity, and the rule
that every flap must fit on the skull above the fixed base.

**Convexity.** The convexity of a hemisphere is the part of the brain's outer surface (the
skull's inner surface) whose direction from the brain centre lies within
:data:`CONVEXITY_HALF_ANGLE_DEG` of the hemisphere's lateral axis (the mid-sagittal plane's
normal, away from the midline) and at least :data:`CONVEXITY_ELEVATION_DEG` above the
horizontal, above the fixed base: the lateral vault over the hemisphere's swelling white
matter, where a unilateral decompressive flap is centred.

**Candidate centres** (:func:`convexity_centres`) are spread evenly over it: a centroidal
Voronoi tessellation of the convexity's faces (Lloyd's iteration, area-weighted, from a
farthest-point start at the guideline fronto-temporo-parietal centre), each generator moved
to the nearest face centroid. For both hemispheres the right centres are the mirror images
of the left ones in the mid-sagittal plane (a flap's centre is projected onto the skull along
the ray from the brain centre), so a symmetric head gets symmetric flaps.

**Fitting rule** (:func:`fit_flap`). A flap is the skull inside its cutting cylinder
(:class:`~brainbulge.geometry.brain.boundaries.Flap`). It

- is refused when the cylinder reaches a face of the fixed base (the flap must lie on the
  skull above the fixed base);
- is clipped at the fixed superior band: the band's faces inside the cylinder stay fixed, as
  the strip of bone over the superior sagittal sinus that a surgeon leaves (with a warning);
- may reach over the midline beyond the band (the cylinder wraps a large flap over the
  vault) by at most :data:`OTHER_SIDE_MAX_FRACTION` of its area, and is refused beyond: a
  unilateral flap stays over its hemisphere;
- is refused when nothing is left.

Lengths in mm, areas in cm^2.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from brainbulge.errors import InputError
from brainbulge.geometry.brain.boundaries import (
    LEFT_FTP_DIRECTION,
    Flap,
    SuperiorBand,
    custom_flap,
    face_areas_mm2,
)
from brainbulge.geometry.brain.brain_mesh import BrainMesh

log = logging.getLogger("brainbulge")

#: the convexity: directions from the brain centre within this angle of the lateral axis
CONVEXITY_HALF_ANGLE_DEG = 60.0
#: ... and at least this far above the horizontal through the brain centre [deg]
CONVEXITY_ELEVATION_DEG = 0.0
#: the largest share of a flap's area beyond the band on the other hemisphere
OTHER_SIDE_MAX_FRACTION = 0.10
#: half-width of the midline strip a unilateral flap may reach into when no superior band
#: is fixed [mm] (the band's default half-width)
MIDLINE_HALF_WIDTH_MM = 5.0
#: Lloyd iterations of the centroidal Voronoi tessellation
LLOYD_ITERATIONS = 30


@dataclass(frozen=True)
class FlapFit:
    """Whether a flap fits (the rule of the module docstring), and how much was clipped.

    ``reason``: why it does not fit (empty if it does); ``area_cm2``: the flap's area on the
    outer surface after clipping; ``clipped_cm2``: the band's area inside the cylinder, kept
    fixed; ``mask``: the flap's faces (empty when it does not fit)."""

    flap: Flap
    fits: bool
    reason: str
    area_cm2: float
    clipped_cm2: float
    mask: np.ndarray


def signed_lateral_mm(bm: BrainMesh, points_mm: np.ndarray) -> np.ndarray:
    """Signed distance from the mid-sagittal plane [mm], positive on the patient's right."""
    n = np.asarray(bm.midsagittal.normal, float)
    n = n / np.linalg.norm(n)
    return (np.asarray(points_mm, float) - np.asarray(bm.midsagittal.point_mm)) @ n


def mirrored(bm: BrainMesh, points_mm: np.ndarray) -> np.ndarray:
    """Mirror images of points in the mid-sagittal plane [mm]."""
    n = np.asarray(bm.midsagittal.normal, float)
    n = n / np.linalg.norm(n)
    d = signed_lateral_mm(bm, points_mm)
    return np.asarray(points_mm, float) - 2 * d[:, None] * n


def convexity_faces(bm: BrainMesh, side: str, band: SuperiorBand | None = None) -> np.ndarray:
    """Mask of the outer faces on the convexity of hemisphere ``side`` (module docstring),
    outside the superior ``band``'s half-width from the mid-sagittal plane."""
    if side not in ("left", "right"):
        raise InputError(f"side must be 'left' or 'right', got {side!r}")
    centroids = bm.nodes_mm[bm.faces].mean(axis=1)
    half = band.width_mm / 2 if band is not None else MIDLINE_HALF_WIDTH_MM
    outward = 1.0 if side == "right" else -1.0
    lateral = signed_lateral_mm(bm, centroids) * outward
    d = centroids - bm.envelope.centre_mm()
    d /= np.linalg.norm(d, axis=1)[:, None]
    n = np.asarray(bm.midsagittal.normal, float)
    cos_lateral = d @ (outward * n / np.linalg.norm(n))
    elevation = np.degrees(np.arcsin(d[:, 2]))
    return ((lateral > half) & (cos_lateral >= np.cos(np.radians(CONVEXITY_HALF_ANGLE_DEG)))
            & (elevation >= CONVEXITY_ELEVATION_DEG) & ~bm.base)


def convexity_centres(bm: BrainMesh, swell: str, n: int,
                      band: SuperiorBand | None = None) -> np.ndarray:
    """``n`` candidate flap centres (n, 3) [mm] spread evenly over the convexity above the
    swelling: hemisphere ``swell`` (``left``/``right``), or both (``n`` even: ``n / 2`` on the
    left and their mirror images on the right)."""
    if not isinstance(n, int) or n < 1:
        raise InputError(f"--centres {n!r} must be a whole number of at least 1")
    if swell == "both":
        if n % 2:
            raise InputError(f"--centres {n} must be even with --swell both: half of them on "
                             "each hemisphere's convexity, as mirror images")
        left = convexity_centres(bm, "left", n // 2, band)
        return np.vstack([left, mirrored(bm, left)])  # custom_flap projects onto the skull
    mask = convexity_faces(bm, swell, band)
    centroids = bm.nodes_mm[bm.faces].mean(axis=1)[mask]
    if len(centroids) < n:
        raise InputError(f"the {swell} convexity has {len(centroids)} faces, fewer than "
                         f"--centres {n}; ask for fewer centres or a finer mesh")
    weights = face_areas_mm2(bm.nodes_mm, bm.faces)[mask]
    start = np.array(LEFT_FTP_DIRECTION)
    if swell == "right":
        start[0] = -start[0]
    d = centroids - bm.envelope.centre_mm()
    first = int(np.argmax(d @ start / np.linalg.norm(d, axis=1)))
    generators = centroids[_farthest_points(centroids, n, first)]
    for _ in range(LLOYD_ITERATIONS):
        _, owner = cKDTree(generators).query(centroids)
        mass = np.bincount(owner, weights, minlength=n)
        moved = np.stack([np.bincount(owner, weights * centroids[:, k], minlength=n)
                          for k in range(3)], axis=1)
        keep = mass > 0
        generators[keep] = moved[keep] / mass[keep, None]
    _, nearest = cKDTree(centroids).query(generators)
    return centroids[nearest]


def _farthest_points(points: np.ndarray, n: int, first: int) -> np.ndarray:
    """Indices of ``n`` points chosen greedily, each the farthest from those before."""
    chosen = [first]
    dist = np.linalg.norm(points - points[first], axis=1)
    for _ in range(n - 1):
        chosen.append(int(np.argmax(dist)))
        dist = np.minimum(dist, np.linalg.norm(points - points[chosen[-1]], axis=1))
    return np.array(chosen)


def fit_flap(bm: BrainMesh, centre_mm, diameter_mm: float, band: SuperiorBand | None = None,
             name: str = "custom") -> FlapFit:
    """The circular flap of ``diameter_mm`` centred on the skull at ``centre_mm`` (projected
    along the ray from the brain centre, :func:`custom_flap`) and whether it fits (module
    docstring); nothing is changed on ``bm``."""
    flap = custom_flap(bm.envelope, tuple(float(c) for c in centre_mm), float(diameter_mm),
                       name=name)
    centroids = bm.nodes_mm[bm.faces].mean(axis=1)
    area = face_areas_mm2(bm.nodes_mm, bm.faces)
    inside = flap.contains(centroids)
    empty = np.zeros(len(bm.faces), dtype=bool)

    def refused(reason: str) -> FlapFit:
        return FlapFit(flap, False, reason, 0.0, 0.0, empty)

    if (inside & bm.base).any():
        return refused(f"reaches the fixed base (z < {bm.base_z_mm:.0f} mm)")
    probe = dataclasses.replace(bm, flaps={}, flap_faces={})  # the same arrays, no flaps
    try:
        probe.add_flap(flap)
    except InputError:
        return refused("covers no face of the skull surface")
    flap, mask = probe.flaps[name], probe.flap_faces[name]  # (the cut's depth as added)
    in_band = bm.superior_faces(band) if band is not None else empty
    clipped = mask & in_band
    mask = mask & ~in_band
    if not mask.any():
        return refused("lies on the superior band only")
    half = band.width_mm / 2 if band is not None else MIDLINE_HALF_WIDTH_MM
    side = np.sign(signed_lateral_mm(bm, np.atleast_2d(flap.centre_mm))[0]) or 1.0
    across = mask & (signed_lateral_mm(bm, centroids) * side < -half)
    share = area[across].sum() / area[mask].sum()
    if share > OTHER_SIDE_MAX_FRACTION:
        return refused(f"reaches over the midline with {share:.0%} of its area (at most "
                       f"{OTHER_SIDE_MAX_FRACTION:.0%})")
    return FlapFit(flap, True, "", float(area[mask].sum() / 100),
                   float(area[clipped].sum() / 100), mask)


def open_flap(bm: BrainMesh, centre_mm, diameter_mm: float, band: SuperiorBand | None = None,
              name: str = "custom") -> FlapFit:
    """The one rule that turns a requested flap (a centre near the skull and a diameter) into
    the flap open on ``bm``: :func:`fit_flap`, then
    :func:`attach_flap` (an `InputError` saying why if it does not fit). Every custom flap,
    of ``brainbulge mesh``, ``brain`` and ``plan``, is made here."""
    fit = fit_flap(bm, centre_mm, diameter_mm, band, name)
    attach_flap(bm, fit)
    return fit


def attach_flap(bm: BrainMesh, fit: FlapFit) -> None:
    """Open the fitted flap on ``bm`` (``bm.flaps[name]`` and its clipped faces): the flap is
    a boundary condition, the mesh stays as it is."""
    if not fit.fits:
        raise InputError(f"flap {fit.flap.name!r} of {fit.flap.diameter_mm:g} mm at "
                         f"({', '.join(f'{c:.0f}' for c in fit.flap.centre_mm)}) mm does not "
                         f"fit: it {fit.reason}")
    if fit.clipped_cm2 > 0:
        log.warning("flap of %g mm at (%s) mm reaches the fixed superior band: %.1f cm2 of "
                    "bone over the sinus stay fixed", fit.flap.diameter_mm,
                    ", ".join(f"{c:.0f}" for c in fit.flap.centre_mm), fit.clipped_cm2)
    bm.flaps[fit.flap.name] = fit.flap
    bm.flap_faces[fit.flap.name] = fit.mask
