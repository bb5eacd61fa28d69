"""The outputs of a run, declared once: the keys of ``summary.json`` and the fields of
``fields.vtu``/``fields.npz``, each with its unit, meaning and the runs that write it.

:data:`KEYS` lists the keys, :data:`FIELDS` the fields: each :class:`Key` is one row of the
tables of docs/outputs.md (:func:`markdown_table` writes them; ``tests/test_docs.py`` checks
the page against it), with the names it covers, their unit, what they mean, the cases that
write them (``hemidisk``, the 2D runs of :mod:`brainbulge.studies.hemidisk`, and ``brain``,
the 3D runs of :mod:`brainbulge.studies.craniectomy`) and, for a key not in every run, when
it is written. The writers name the stretch and strain families by :func:`stem_key` of
:data:`EXTREMES` and :data:`PERCENTILES`, the extremes with sites by :data:`SITES`, and take
the deprecated aliases from :func:`deprecated_aliases`; the study reports take their labels
and units (:func:`label`, :func:`unit`), the command line its printout (:func:`printout`).
:func:`check` lists a summary's undeclared and missing keys (the tests run a hemidisk and a
brain through it).

Units: ``length`` is the case's length unit (:data:`LENGTH_UNIT`: the hemidisk's radius R,
the brain's mm), ``-`` dimensionless, an empty unit a name, flag, count or table.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

HEMIDISK = "hemidisk"
BRAIN = "brain"
BOTH = frozenset({HEMIDISK, BRAIN})
#: the cases' length unit (``length`` in :attr:`Key.unit`)
LENGTH_UNIT = {HEMIDISK: "R", BRAIN: "mm"}

#: summary key stem -> (field name, extreme kinds): the stretches and the strain whose
#: ``max_*``/``min_*``, ``raw_*``, ``argmax_*``, ``pXX_*`` and ``peak_*`` are reported
EXTREMES = {
    "radial_stretch": ("lambda_n", ("max", "min")),
    "tangential_stretch": ("lambda_t", ("max", "min")),
    "principal_strain": ("max_principal_strain", ("max",)),
    "shear_stress": ("max_shear_stress", ("max",)),
}
#: volume percentiles reported per extreme kind: ``p95_*``, ``p99_*`` for maxima and ``p05_*``,
#: ``p01_*`` for minima
PERCENTILES = {"max": (95, 99), "min": (5, 1)}
#: the prefix of the stem of the 3D CSF filler's stretches and strain (``max_csf_*``, ...)
CSF = "csf_"
#: the short names of the fields in labels (the printout, the study's comparison)
FIELD_LABELS = {"lambda_n": "lambda_n", "lambda_t": "lambda_t",
                "max_principal_strain": "principal strain",
                "max_shear_stress": "max shear stress"}


def stem_key(measure: str, stem: str, prefix: str = "") -> str:
    """The key of ``measure`` (``max``, ``min``, ``raw_max``, ``raw_min``, ``argmax``,
    ``p95``, ..., ``peak``) of the :data:`EXTREMES` stem ``stem``, e.g. ``raw_max_csf_
    radial_stretch`` (``prefix`` before the stem: ``csf_`` for the CSF)."""
    return f"{measure}_{prefix}{stem}"


def extremes(prefix: str = "") -> tuple[str, ...]:
    """``max_*``/``min_*`` of :data:`EXTREMES`."""
    return tuple(stem_key(k, s, prefix) for s, (_, kinds) in EXTREMES.items() for k in kinds)


def raws(prefix: str = "") -> tuple[str, ...]:
    """``raw_max_*``/``raw_min_*``: the extremes over all points."""
    return tuple(stem_key(f"raw_{k}", s, prefix) for s, (_, kinds) in EXTREMES.items()
                 for k in kinds)


def argmaxes(prefix: str = "") -> tuple[str, ...]:
    """``argmax_*``: where the maxima are."""
    return tuple(stem_key("argmax", s, prefix) for s in EXTREMES)


def percentiles(prefix: str = "") -> tuple[str, ...]:
    """``pXX_*``: the volume percentiles of :data:`PERCENTILES`."""
    return tuple(stem_key(f"p{q:02d}", s, prefix) for s, (_, kinds) in EXTREMES.items()
                 for k in kinds for q in PERCENTILES[k])


def peaks(prefix: str = "") -> tuple[str, ...]:
    """``peak_*``: the values exceeded in a small volume, of the maxima."""
    return tuple(stem_key("peak", s, prefix) for s in EXTREMES)


@dataclass(frozen=True)
class Key:
    """One row of the key tables: the keys ``names``, their ``unit`` (``length``: the case's
    length unit), ``meaning``, the ``cases`` that write them, ``when`` they are written
    (empty: in every run of those cases), ``shown``: the key cell of the docs table when not
    the names (a family by its pattern), ``labels``: short names per key for tables and the
    printout, ``fmt``: the printout's format, ``instead``: for a deprecated key, the key to
    use instead (per name), ``alias``: a deprecated key holds the value of that key."""

    names: tuple[str, ...]
    unit: str
    meaning: str
    cases: frozenset[str] = BOTH
    when: str = ""
    shown: str = ""
    labels: tuple[str, ...] = ()
    fmt: str = ".4g"
    instead: tuple[str, ...] = ()
    alias: bool = False


def _k(names: str | tuple[str, ...], unit: str, meaning: str, **kw: Any) -> Key:
    return Key((names,) if isinstance(names, str) else tuple(names), unit, meaning, **kw)


_STRETCH_LABELS = {f"{k}_{s}": f"{k} {FIELD_LABELS[f]}"
                   for s, (f, kinds) in EXTREMES.items() for k in kinds}
_PERCENT = "p95_*`, `p99_*` (of the `max_*` keys), `p05_*`, `p01_*` (of the `min_*` keys)"
_B, _H = frozenset({BRAIN}), frozenset({HEMIDISK})
_WITH_CSF = "only when the mesh has CSF"
#: the extremes whose sites ``extreme_sites`` and whose element values ``element_*`` are
SITES = ("max_principal_strain", "max_radial_stretch", "min_radial_stretch",
         "max_tangential_stretch", "max_shear_stress")
#: those with element values ``element_*`` too (kinematic: the stress needs a material)
ELEMENT_SITES = SITES[:4]

#: every key of ``summary.json``, in the order of the docs' tables
KEYS: tuple[Key, ...] = (
    _k("case", "", "the case's name (`hemidisk`; `left-flap_both-swelling`, ...)"),
    _k("inputs", "", "every parameter of the case (as in `run.toml`)"),
    _k("converged", "", "whether the full load was reached"),
    _k("load_reached", "-", "the load factor reached, 0–1 (Js = 1 + load (Js_target − 1))"),
    _k(("load_steps", "rejected_steps", "newton_iterations"), "", "accepted load steps, "
       "steps cut in half and retried, total Newton iterations", labels=(
           "load steps", "rejected steps", "Newton iterations")),
    _k("resumed_from_load", "-", "the load of the restart file (`restart.npz` in the output "
       "folder) the ramp went on from; 0 when it started at Js = 1 (no restart file, or one "
       "of another problem)"),
    _k("final_residual", "-", "Newton's scaled residual at the last accepted load step (the "
       "reached one of `--tolerance`); null when no step was accepted"),
    _k(("wall_time_s", "assembly_time_s", "linear_solve_time_s"), "s",
       "solver time and its two main parts", labels=("wall time",)),
    _k("linear_iterations", "", "Krylov iterations over the whole run (0 with the direct "
       "solver)"),
    _k(("elements", "dofs"), "", "mesh elements, unknowns (of the mesh solved: the half "
       "hemidisk for a symmetric case)"),
    _k("max_displacement", "length", "largest \\|u\\| over all points (no exclusion: the "
       "displacement is bounded everywhere)", labels=("max |u|",)),
    _k("argmax_displacement", "length", "reference position of `max_displacement`"),
    _k(("max_vertical_displacement", "min_vertical_displacement"), "length",
       "extremes of u_y (2D) or u_z (3D, superior positive)"),
    _k(extremes()[:2], "-", "extremes of λ_n (axonal stretch) over the points outside the "
       "edge disks (2D: radius `edge_exclusion` round each singular point; 3D: the rim band "
       "`edge_exclusion_mm`). Where the field is singular (the opening's corners) such an "
       "extreme sits on the disk's circle and is the radius's value: it grows as the radius "
       "shrinks; `argmax_*` says where it is, `pXX_*`/`peak_*` are the region measures",
       labels=tuple(_STRETCH_LABELS[n] for n in extremes()[:2]), fmt=".4f"),
    _k(extremes()[2:4], "-", "extremes of λ_t over the same points (the same caveat)",
       labels=tuple(_STRETCH_LABELS[n] for n in extremes()[2:4]), fmt=".4f"),
    _k(extremes()[4:5], "-", "largest maximum principal Green–Lagrange strain, edge points "
       "excluded", labels=(_STRETCH_LABELS[extremes()[4]],), fmt=".3g"),
    _k(extremes()[5:], "kPa", "largest maximum shear stress (σ1 − σ3)/2 of the Cauchy "
       "stress, edge points excluded: the deviator's (the pressure drops out); the paper's "
       "\"large shear stresses around the opening edge\", singular there as the inverse "
       "square root of the distance ([verification.md](verification.md))",
       labels=(_STRETCH_LABELS[extremes()[5]],), fmt=".3g"),
    _k(raws(), "-", "the same over all points (kPa for the shear stress)",
       shown="`raw_max_*`, `raw_min_*`"),
    _k(percentiles(), "-", "volume percentiles over the same points as `max_*`/`min_*`: "
       "e.g. `p95_principal_strain` is the strain that 95 % of that volume stays below "
       "(MPS95 of brain-injury studies); mesh-convergent where the extremes are not (below); "
       "kPa for the shear stress", shown=f"`{_PERCENT}"),
    _k(argmaxes(), "length", "reference position of `max_radial_stretch` / "
       "`max_tangential_stretch` / `max_principal_strain` / `max_shear_stress`"),
    _k(("median_abs_Je_minus_1", "p95_abs_Je_minus_1"), "-", "how well `J = Js` holds: "
       "volume median and 95th percentile of \\|J/Js − 1\\| over all points. The constraint "
       "holds in the weak sense of the pressure space (∫ q (J − Js) dV = 0 for every pressure "
       "test function q), not pointwise"),
    _k("raw_max_abs_Je_minus_1", "-", "the largest \\|J/Js − 1\\| at a single point (a "
       "staircase corner of a tissue interface in 3D)"),
    _k("abs_Je_minus_1_by_region", "-", 'per region: `{"median", "p95", "raw_max"}` of '
       "\\|J/Js − 1\\|"),
    _k("inverted_points", "-", "integration points where the element is inverted (J ≤ 0), "
       "with a warning in the log: their stress is undefined and left out of the stress "
       "keys (0 in a sound solution)"),
    _k(("max_abs_J_minus_Js", "raw_max_abs_J_minus_Js"), "-", "deprecated (one release): "
       "the largest \\|J − Js\\| without / with the edge points; use the keys above",
       instead=("p95_abs_Je_minus_1", "raw_max_abs_Je_minus_1")),
    _k("integral_J_minus_Js", "length² (2D), mm³ (3D)", "∫ (J − Js) dV, ~0"),
    _k("max_penetration", "length", "deepest penetration into the skull (for no-slip, of "
       "the opening boundary, the only part in contact)", labels=("penetration",),
       fmt=".2g"),
    _k("max_contact_pressure", "kPa", "largest skull contact pressure",
       when="only with contact (brain; hemidisk: sliding, or no-slip on the `rigid` skull)"),
    _k("message", "", "why the solver stopped", when="only when not converged"),
    _k("failure_site", "length", "the deformed position of the vertex with the largest "
       "unbalanced force in the last Newton attempt; the message names it too, and the "
       "hemidisk's `fields.png` marks it with a red cross (its title says the swelling "
       "reached, `stopped at Js 1.125, load 0.623`). Where to look in the partial results, "
       "or to refine. When it lies on the skull's rounded cut edge (within two edge radii of "
       "a rounding's centre), the hemidisk's message ends not with the generic advice (more "
       "`--steps`, a finer mesh) but with what holds there: the tissue pressed around the "
       "edge is squeezed in a thin layer, which a finer mesh sharpens and more steps do not "
       "get past, a known limit for small openings with large swelling regions "
       "([known-limits.md](known-limits.md#2d-hemidisk)).",
       when="only when a load step could not be taken"),
    # --- the hemidisk's
    _k("rezones", "", "how often the mesh was exchanged by rezoning (`--rezone`, on by "
       "default; docs/design.md); the fields are on the last mesh", cases=_H),
    _k("swelling_volume", "R²", "added area ∫ (Js − 1) dA", cases=_H),
    _k("swelling_area_ratio_expected", "-", "added area / hemidisk area from the inputs "
       "(`alpha/180 (Js − 1)` for a sector)", cases=_H),
    _k(("max_pressure", "min_pressure"), "kPa", "extremes of the pressure", cases=_H),
    _k("edge_exclusion", "R", "radius of the excluded disks (`--edge-exclusion` × R)",
       cases=_H),
    _k("singular_points", "R", "their centres: the opening's corners and, for a sector, "
       "where its edges meet the arc and the centre of the base", cases=_H),
    _k("max_skull_crossing", "R", "how far the deformed tissue reaches into the skull, 0 "
       "when nowhere. Rounded edge: the deepest point of the deformed arc (8 points per "
       "segment, the end face included) inside the rounded skull. Sharp edge: the largest "
       "\\|x\\| − R > 0 of the deformed vertices where the skull is (the bulge folding "
       "back over the edge, or the opening's surface next to it crossing the arc, which "
       "`max_penetration` of the held arc does not see)", cases=_H,
       labels=("skull crossing",), fmt=".3g"),
    _k("boundary_self_crossings", "-", "pairs of the deformed outer boundary's segments "
       "(chords between vertices) that cross each other: 0 unless the surface folds onto "
       "itself, which the model has no tissue self-contact to prevent", cases=_H),
    # --- the brain's
    _k("swelling_reached", "-", "the white-matter Js reached", cases=_B, labels=("Js",),
       fmt=".3f"),
    _k("edge_exclusion_mm", "mm", "width of the excluded band around the flap rim", cases=_B),
    _k("midline_shift_mm", "mm", "the clinical midline shift: lateral displacement of the "
       "mid-sagittal parenchyma at the level of the foramen of Monro (the septum "
       "pellucidum), **positive towards the patient's right**. `u` is interpolated at the "
       "points of a 1 mm grid on the mid-sagittal plane within ±20 mm (anterior-posterior) "
       "and ±5 mm (inferior-superior) of the foramen; the value of largest magnitude",
       cases=_B, labels=("midline shift",), fmt="+.3g"),
    _k("midline_shift_point_mm", "mm", "reference position of that value", cases=_B),
    _k("midline_shift_samples", "", "how many grid points lay in parenchyma", cases=_B),
    _k("monro_location_mm", "mm", "where the foramen was placed", cases=_B),
    _k("monro_location_source", "", "how the foramen was placed: `template` (the ICBM152 "
       "template's MNI coordinates (0, −2, 12) mm, for meshes with the template's bounding "
       "box), `labels` (a user's segmentation: the centroid of its ventricles, i.e. CSF "
       "deeper than 15 mm and within 25 mm of the midline, plus the template's offset from "
       "its ventricles to its foramen scaled by the bounding boxes), `bounding box` (no "
       "ventricles: the template's location mapped by the brain's bounding box; a rough "
       "guess, logged as a warning)", cases=_B),
    _k(("max_midline_displacement_mm", "max_midline_displacement_point_mm"), "mm", "the "
       "largest lateral displacement of the parenchyma on the mid-sagittal plane, at any "
       "height (signed as above; interpolated on the plane's 1 mm grid, as the Monro shift "
       "is, so it is never smaller than that), and its reference position", cases=_B),
    _k("midline_shift_monro_mm", "mm", "deprecated (one release): = `midline_shift_mm`",
       cases=_B, instead=("midline_shift_mm",), alias=True),
    _k("bulge_volume_ml", "ml", "volume of the deformed mesh (tissue and CSF) pushed out "
       "through the flap: outside the intact skull surface and not inside the bone",
       cases=_B, labels=("bulge volume",), fmt=".3g"),
    _k(("brain_volume_ml", "deformed_volume_ml"), "ml", "volume of the whole mesh (tissue "
       "and CSF) before and after", cases=_B),
    _k("swelling_volume_ml", "ml", "volume added by swelling, ∫ (Js − 1) dV = (Js − 1) × "
       "`white_matter_volume_ml`; the brain grows by it (`deformed_volume_ml` − "
       "`brain_volume_ml`, within 1 %)", cases=_B),
    _k("white_matter_volume_ml", "ml", "reference volume of the white matter that swells",
       cases=_B),
    _k("flap_nominal_area_cm2", "cm²", "area of the flap as specified: the outer faces "
       "whose centroid lies inside its cutter", cases=_B),
    _k("flap_area_cm2", "cm²", "the brain surface the skull leaves free with the flap open, "
       "measured on the mesh (the flap's faces and the faces where the skull with the flap "
       "is > 0.01 mm farther than the intact skull); within ~1.5 % of "
       "`flap_nominal_area_cm2` (the rounding of the cut edge lies in the bone)", cases=_B),
    _k(("max_hydrostatic_stress_kpa", "min_hydrostatic_stress_kpa"), "kPa", "extremes of "
       "the hydrostatic stress −p (positive in compression) over the whole mesh (CSF "
       "included)", cases=_B),
    _k("mean_hydrostatic_stress_kpa", "kPa", "its volume mean over the parenchyma. A tissue "
       "stress that scales with the shear modulus (about 500× between the `paper` and "
       "`paper-pa` presets), **not an intracranial pressure**", cases=_B,
       labels=("mean hydrostatic stress",)),
    _k("shear_modulus_kpa", "kPa", "the parenchyma's volume-mean shear modulus mu = c1 + c2",
       cases=_B),
    _k("mean_hydrostatic_stress_over_shear_modulus", "-", "the mean hydrostatic stress over "
       "it (compares across presets)", cases=_B),
    _k(("max_pressure_kpa", "min_pressure_kpa"), "kPa", "deprecated (one release): the "
       "extremes above", cases=_B, alias=True,
       instead=("max_hydrostatic_stress_kpa", "min_hydrostatic_stress_kpa")),
    _k("deprecated_keys", "", "the deprecated keys present, each with the key to use "
       "instead", cases=_B),
    _k("max_penetration_mm", "mm", "= `max_penetration`", cases=_B, labels=("penetration",),
       fmt=".2g"),
    _k(peaks(), "-", "the value exceeded in 0.1 ml of the same points as `max_*`: the peak "
       "to compare between meshes and scenarios (a maximum of single points jumps by ±45 % "
       "between meshes of one geometry; this one by 0-7 %); kPa for the shear stress",
       cases=_B),
    _k((*extremes(CSF), *raws(CSF), *percentiles(CSF), *peaks(CSF)), "-", "stretch and "
       "strain extremes, percentiles and peaks in the CSF filler, reported apart", cases=_B,
       when=_WITH_CSF, shown="`max_csf_*`, `min_csf_*`, `raw_*_csf_*`, `pXX_csf_*`, "
       "`peak_csf_*`"),
    _k(argmaxes(CSF), "mm", "reference positions of the CSF's maxima", cases=_B,
       when=_WITH_CSF, shown="`argmax_csf_*`"),
    _k("csf_max_principal_strain", "-", "the largest principal strain in the CSF (same as "
       "`max_csf_principal_strain`; null without CSF)", cases=_B),
    _k("extreme_sites", "", "where `max_principal_strain`, `max_radial_stretch`, "
       "`min_radial_stretch`, `max_tangential_stretch` and `max_shear_stress` are: for "
       "each, `X_mm` (reference "
       "position), `value`, `region`, `rim_distance_mm` (to the flap's rim), `under_flap` "
       "(inside the flap's cutting cylinder), `depth_mm` (below the skull's inner surface), "
       "`swelling_distance_mm` (to the nearest swelling element; 0 inside one), "
       "`at_interface` (its element touches another region), `interface_distance_mm`, and "
       "`peak_set`: the 0.1 ml of the most extreme values (`threshold` = `peak_*`; "
       "`volume_ml`, `median_rim_distance_mm`, `median_depth_mm`, "
       "`median_interface_distance_mm`, `share_under_flap`, `share_at_interface`). A peak "
       "set near the rim is a ring around the opening, one under the flap and away from the "
       "rim lies deep in the bulge; on a coarse mesh nearly every parenchyma element touches "
       "an interface, and an extreme whose `X_mm` recurs in other scenarios belongs to one "
       "element, not to the load (`results/measures/extreme_sites.py`)", cases=_B),
    _k((*(f"element_{n}" for n in ELEMENT_SITES), "element_sites"), "-",
       "the same extremes of the element values (the stretches of the element-constant "
       "gradient of the P1 displacement, what a linear tetrahedron reports per element) over "
       "the same parenchyma outside the rim band, and their sites (as above, without "
       "`peak_set`). The recovered gradient of `max_*` smooths element values: compare the "
       "source's \"up to\" values with both ([paper.md](paper.md))", cases=_B),
)

#: the vertex fields of ``fields.vtu`` and ``fields.npz`` (``point_<field>``), written by
#: both cases; ``fields.vtu`` has the element averages of those not in :data:`POINT_ONLY` as
#: cell data, with ``region``
FIELDS: tuple[Key, ...] = (
    _k("u", "length", "displacement (3 components; z = 0 in 2D)"),
    _k("u_magnitude", "length", "\\|u\\|"),
    _k("u_vertical", "length", "u_y (2D) or u_z (3D)"),
    _k(("lambda_n", "lambda_t", "max_principal_strain"), "-", "as above"),
    _k("max_shear_stress", "kPa", "as above"),
    _k(("J", "Je", "Js"), "-", "as above"),
    _k("pressure", "kPa", "as above"),
    _k("contact_pressure", "kPa", "skull contact pressure at the vertex: the force per "
       "reference area of the exact nodal multiplier of the active set, lambda \\|grad g\\| "
       "(0 everywhere in a run without contact)"),
    _k("contact_status", "", "1 on the contact boundary and touching the skull, 0 on it but "
       "separated, −1 elsewhere (interior, base, 3D flap; everywhere in a run without "
       "contact)"),
)
#: the fields that ``fields.vtu`` has as point data only
POINT_ONLY = ("contact_pressure", "contact_status")

#: key name -> its declaration
BY_NAME: dict[str, Key] = {n: k for k in KEYS for n in k.names}


def declared(case: str, always: bool = False) -> set[str]:
    """The keys that runs of ``case`` write; with ``always``, those written by every run."""
    return {n for k in KEYS if case in k.cases and not (always and k.when) for n in k.names}


def field_names(cell: bool = False) -> set[str]:
    """The fields of ``fields.vtu``'s point data (``fields.npz``: ``point_<field>``); with
    ``cell``, those of its cell data."""
    return ({n for k in FIELDS for n in k.names} - (set(POINT_ONLY) if cell else set())
            | ({"region"} if cell else set()))


def check(summary: dict[str, Any], case: str) -> tuple[list[str], list[str]]:
    """``(undeclared, missing)``: the keys of ``summary`` not declared for ``case``, and the
    keys every run of ``case`` writes that it lacks."""
    return (sorted(set(summary) - declared(case)),
            sorted(declared(case, always=True) - set(summary)))


def deprecated_aliases() -> dict[str, str]:
    """Deprecated key -> the key whose value it holds (kept one release)."""
    return {old: new for k in KEYS if k.alias for old, new in zip(k.names, k.instead,
                                                                   strict=True)}


def deprecated_derived() -> dict[str, str]:
    """Deprecated key of its own value -> the key to use instead."""
    return {old: new for k in KEYS if k.instead and not k.alias
            for old, new in zip(k.names, k.instead, strict=True)}


def unit(name: str, case: str) -> str:
    """The unit of key ``name`` in runs of ``case`` (``length`` made the case's unit)."""
    return BY_NAME[name].unit.replace("length", LENGTH_UNIT[case])


def label(name: str) -> str:
    """The short name of key ``name`` in tables and the printout (default: the key)."""
    k = BY_NAME[name]
    i = k.names.index(name)
    return k.labels[i] if i < len(k.labels) else name


def printout(summary: dict[str, Any], names: tuple[str, ...], case: str) -> str:
    """One line of the keys ``names`` of ``summary``: ``label = value unit, ...`` (units
    ``-`` and empty left out)."""
    parts = []
    for n in names:
        u = unit(n, case)
        u = "" if u in ("", "-") else f" {u}"
        parts.append(f"{label(n)} = {summary[n]:{BY_NAME[n].fmt}}{u}")
    return ", ".join(parts)


def markdown_table(cases: frozenset[str], keys: tuple[Key, ...] = KEYS,
                   head: str = "key") -> str:
    """The docs table (``| key | unit | meaning |``) of the ``keys`` (:data:`KEYS` or
    :data:`FIELDS`) written by exactly ``cases``."""
    lines = [f"| {head} | unit | meaning |", "|---|---|---|"]
    for k in keys:
        if k.cases != cases:
            continue
        shown = k.shown or ", ".join(f"`{n}`" for n in k.names)
        when = f"{k.when}: " if k.when else ""
        lines.append(f"| {shown} | {k.unit} | {when}{k.meaning} |")
    return "\n".join(lines)
