"""The named outputs of a 3D craniectomy scenario (docs/model.md sections 3 and 6).

Every key says what its value is (lengths mm, volumes ml, stresses kPa):

- ``midline_shift_mm``: the clinical midline shift, the lateral displacement of the
  mid-sagittal parenchyma at the level of the foramen of Monro (the septum pellucidum),
  positive towards the patient's right (:func:`~brainbulge.results.measures.brain_metrics.
  monro_midline_shift_mm`); ``monro_location_mm`` and ``monro_location_source`` say where it
  was measured (``template`` coordinates, the segmentation's ``labels``, or the template's
  location mapped by the ``bounding box``, which is also logged as a warning).
- ``max_midline_displacement_mm``: the largest lateral displacement of any parenchyma that
  starts on the mid-sagittal plane, at any height (the same 1 mm grid of the plane as the
  Monro shift's, over the whole brain).
- ``white_matter_volume_ml``: reference volume of the white matter that swells;
  ``swelling_volume_ml`` (from the summary): the added volume ``int (Js - 1) dV``, i.e.
  ``(Js - 1)`` times that volume.
- ``mean_hydrostatic_stress_kpa``: the volume mean over the parenchyma of ``-p`` (positive in
  compression), a tissue stress that scales with the shear modulus; its ratio to the
  parenchyma's mean shear modulus ``mu = c1 + c2`` is
  ``mean_hydrostatic_stress_over_shear_modulus``. Neither is an intracranial pressure.
- ``max_hydrostatic_stress_kpa`` / ``min_hydrostatic_stress_kpa``: its extremes (all tissue).

Keys of earlier releases stay one release as aliases (:data:`DEPRECATED_ALIASES`), listed in
the summary under ``deprecated_keys``; they are declared with the others in
:mod:`brainbulge.results.measures.schema`.
"""

from __future__ import annotations

import logging
import re
from typing import TYPE_CHECKING, Any

import numpy as np

from brainbulge.results.measures import schema
from brainbulge.results.measures.brain_metrics import (
    MonroLocation,
    locate_monro,
    monro_midline_shift_mm,
)

if TYPE_CHECKING:
    from brainbulge.geometry.brain import BrainMesh
    from brainbulge.solver.mixed import MixedForm

log = logging.getLogger("brainbulge")

#: old key -> the key that now holds its value (kept one release)
DEPRECATED_ALIASES = schema.deprecated_aliases()
#: old keys whose value is their own: ``max_abs_J_minus_Js`` / ``raw_max_abs_J_minus_Js``
#: (the summary's single-point maxima of ``|J - Js|``) are superseded by the ``*_abs_Je_minus_1``
#: statistics
DEPRECATED_DERIVED = schema.deprecated_derived()


def brain_outputs(
    bm: BrainMesh,
    form: MixedForm,
    u_mm: np.ndarray,
    parenchyma: str,
    swell_sides: tuple[str, ...],
    skull: Any = None,
) -> dict[str, Any]:
    """The midline, volume and stress keys of the module docstring.

    ``u_mm``: displacement at ``bm``'s nodes; ``parenchyma``: regex of the parenchyma's
    region names; ``swell_sides``: the hemispheres whose white matter swells; ``skull``: the
    run's rigid skull, if the caller has it (its envelope distance is the intact skull's)."""
    names = bm.material_names()
    rx = re.compile(f"^(?:{parenchyma})$")
    par_tets = np.array([bool(rx.match(str(n))) for n in names])
    par_nodes = np.zeros(len(bm.nodes_mm), dtype=bool)
    par_nodes[bm.tets[par_tets].ravel()] = True
    centroids = bm.nodes_mm[bm.tets].mean(axis=1)
    skull = skull if skull is not None else bm.skull(None)
    depth = -skull.envelope_distance(centroids, gradient=False)[0]
    monro = locate_monro(bm.nodes_mm, bm.tets, np.char.startswith(names.astype(str), "csf"),
                         depth, bm.midsagittal)
    out: dict[str, Any] = {}
    out.update(monro_midline_shift_mm(bm.nodes_mm, bm.tets, u_mm, bm.midsagittal, monro,
                                      tissue_tets=par_tets))
    out["monro_location_mm"] = list(monro.point_mm)
    out["monro_location_source"] = monro.source
    warn_if_guessed(monro)
    reach = float(np.ceil(np.abs(bm.nodes_mm - np.asarray(monro.point_mm)).max()))
    whole = monro_midline_shift_mm(bm.nodes_mm, bm.tets, u_mm, bm.midsagittal, monro,
                                   tissue_tets=par_tets, window_mm=(reach, reach))
    out["max_midline_displacement_mm"] = whole["midline_shift_mm"]
    out["max_midline_displacement_point_mm"] = whole["midline_shift_point_mm"]
    vols = bm.region_volumes_ml()
    out["white_matter_volume_ml"] = float(sum(vols.get(f"white_{s}", 0.0) for s in swell_sides))
    mean_stress, mu = _parenchyma_means(form, parenchyma)
    out["mean_hydrostatic_stress_kpa"] = mean_stress
    out["shear_modulus_kpa"] = mu
    out["mean_hydrostatic_stress_over_shear_modulus"] = mean_stress / mu
    return out


def warn_if_guessed(monro: MonroLocation) -> None:
    """One warning when the foramen of Monro was placed by the bounding box alone."""
    if monro.source == "bounding box":
        log.warning("midline shift: the segmentation has no ventricles to locate the foramen "
                    "of Monro; measured at the template's location mapped by the brain's "
                    "bounding box (%s mm), a rough guess",
                    ", ".join(f"{c:.0f}" for c in monro.point_mm))


def _parenchyma_means(form: MixedForm, parenchyma: str) -> tuple[float, float]:
    """Volume means over the parenchyma of ``-p`` and of the shear modulus ``mu`` (kPa)."""
    import ngsolve as ngs

    rx = re.compile(f"^(?:{parenchyma})$")
    regions = set(form.mesh.GetMaterials())
    mask = form.mesh.MaterialCF({r: 1.0 for r in regions if rx.match(r)}, default=0.0)
    mu = form.mesh.MaterialCF(
        {r: float(form.problem.materials[r].shear_modulus) for r in regions if rx.match(r)},
        default=0.0)
    vol = ngs.Integrate(mask, form.mesh)
    return (float(ngs.Integrate(-form.p * mask, form.mesh) / vol),
            float(ngs.Integrate(mu, form.mesh) / vol))


def add_deprecated_aliases(out: dict[str, Any]) -> dict[str, Any]:
    """Add the keys of earlier releases (one release more) and list them under
    ``deprecated_keys`` (old key -> the key to use)."""
    for old, new in DEPRECATED_ALIASES.items():
        if new in out:
            out[old] = out[new]
    present = {**DEPRECATED_ALIASES, **DEPRECATED_DERIVED}
    out["deprecated_keys"] = {old: new for old, new in present.items() if old in out}
    return out
