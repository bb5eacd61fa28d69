"""Tissue-damage measures of a craniectomy plan, over the parenchyma (CSF apart).

Taken at the integration points where the summary takes its percentiles
(:func:`.summary.solution_summary`: order-4 points, stretches and strains
from the recovered gradient), weighted by their reference volumes ``dV``:

- ``strained_volume_ml``: the reference volume of parenchyma whose maximum principal
  Green-Lagrange strain exceeds ``threshold``, ``int_parenchyma [E_max > threshold] dV /
  1000``. The default threshold 0.18 is the strain at which 50 % of axons were injured in
  vitro (Bain & Meaney 2000, cited by the paper). Counted everywhere, the flap's rim
  included: its singular peak covers a vanishing volume. ``strained_volume_fraction`` is its
  share of the parenchyma.
- ``rim_max_principal_strain``, ``rim_max_tangential_stretch`` (peaks) and
  ``rim_p95_principal_strain``: over the *rim band*, the parenchyma whose reference position
  lies between ``rim_band_mm[0]`` and ``rim_band_mm[1]`` (default 5-10 mm) from the flap's
  rim, the curve where the cutting cylinder meets the skull's inner surface, on either side of
  it. The distance is ``hypot(d_cut, phi_env)`` with ``d_cut`` the signed distance to the
  cylinder and ``phi_env`` to the skull's inner surface (exact away from the cylinder's axis).
  At the rim itself the field is singular (order ``r^-1/2`` in the stress); at a fixed offset
  it compares between flaps. ``rim_volume_ml``: the band's parenchyma volume.

The other measures of a plan are the scenario's summary keys: ``p99_principal_strain``
(parenchyma outside the 5 mm edge-exclusion band), ``max_displacement`` (the bulge height),
``midline_shift_mm`` (at the foramen of Monro) and the flap's area.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from brainbulge.results.measures.plan_defaults import RIM_BAND_MM, STRAIN_THRESHOLD
from brainbulge.results.measures.summary import CHUNK, PointFields, weighted_percentiles

if TYPE_CHECKING:
    from brainbulge.geometry.brain import Flap, RigidSkull

MM3_PER_ML = 1000.0


def rim_distance_mm(X: np.ndarray, flap: Flap, skull: RigidSkull, beyond: float) -> np.ndarray:
    """Distance [mm] of reference points ``X`` from the flap's rim, ``hypot(d_cut, phi_env)``;
    ``inf`` where ``|d_cut| >= beyond`` (not evaluated: the skull's spline is the cost)."""
    d_cut, _ = flap.cutter_distance(X)
    near = np.abs(d_cut) < beyond
    out = np.full(len(X), np.inf)
    if near.any():
        phi_env, _ = skull.envelope_distance(X[near], gradient=False)
        out[near] = np.hypot(d_cut[near], phi_env)
    return out


def damage_measures(
    points: PointFields,
    flap: Flap,
    skull: RigidSkull,
    parenchyma: str,
    threshold: float = STRAIN_THRESHOLD,
    rim_band_mm: tuple[float, float] = RIM_BAND_MM,
) -> dict[str, float | None]:
    """The measures of the module docstring from the solved state's fields at the summary's
    integration points (:func:`~brainbulge.results.measures.summary.point_fields`); ``parenchyma``:
    regex of the parenchyma's region names."""
    if not 0 < threshold < 10:
        raise ValueError(f"strain threshold {threshold!r} must lie in (0, 10)")
    lo, hi = rim_band_mm
    in_par = points.in_regions(parenchyma)
    strain = points.fields["max_principal_strain"]
    stretch_t = points.fields["lambda_t"]
    rim = np.zeros(len(points.X), dtype=bool)
    for a in range(0, len(points.X), CHUNK):
        r = rim_distance_mm(points.X[a:a + CHUNK], flap, skull, beyond=hi)
        rim[a:a + CHUNK] = (r >= lo) & (r <= hi)
    w = points.q.weights
    rim &= in_par
    volume = float(w[in_par].sum())
    strained = float(w[in_par & (strain > threshold)].sum())
    out: dict[str, float | None] = {
        "strain_threshold": float(threshold),
        "strained_volume_ml": strained / MM3_PER_ML,
        "strained_volume_fraction": strained / volume if volume > 0 else None,
        "parenchyma_volume_ml": volume / MM3_PER_ML,
        "rim_band_mm": [float(lo), float(hi)],
        "rim_volume_ml": float(w[rim].sum()) / MM3_PER_ML,
        "rim_max_principal_strain": None,
        "rim_max_tangential_stretch": None,
        "rim_p95_principal_strain": None,
    }
    if rim.any():
        out["rim_max_principal_strain"] = float(strain[rim].max())
        out["rim_max_tangential_stretch"] = float(stretch_t[rim].max())
        out["rim_p95_principal_strain"] = float(
            weighted_percentiles(strain[rim], w[rim], (95,))[0])
    return out
