"""The measures of the paper's 3D claims (its sections 4 and 5) on a reproduce folder."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from paper_run import BAND, MARKED, Row, Run, band, excess_text

# --- 3D measures ------------------------------------------------------------------------
SCENARIO_ORDER = [f"{flap}-flap_{side}-swelling" for flap in ("left", "frontal")
                  for side in ("both", "left", "right")]


def _brain_mesh_volumes(run: Run) -> dict[str, float] | None:
    path = run.root / "craniectomy" / "mesh" / "brain.npz"
    if not path.is_file():
        return None
    from brainbulge.geometry.brain import load_brain_mesh

    bm = load_brain_mesh(path)
    vols = bm.tissue_volumes_ml()
    vols["total"] = float(bm.tet_volumes_mm3().sum() / 1000)
    vols["tets"] = len(bm.tets)
    vols["nodes"] = len(bm.nodes_mm)
    vols["flaps_cm2"] = {n: bm.flap_area_cm2(n) for n in ("left", "frontal") if n in bm.flaps}
    return vols


def _template_volumes() -> dict[str, float]:
    from brainbulge.geometry.brain.template import icbm152_tissue_image

    return {k: float(v) for k, v in icbm152_tissue_image().volumes_ml().items()}


def m_brain_volume(run: Run) -> Row:
    v = _brain_mesh_volumes(run)
    if v is None:
        return Row("no mesh", "not measured", "3D part missing")
    gw = v["gray"] + v["white"]
    t = _template_volumes()
    factor = (v["white"] / t["white"]) ** (1 / 3)
    ok = abs(gw / 1108 - 1) < 0.05
    return Row(f"gray + white matter {gw:.0f} ml (white {v['white']:.0f} ml, whole mesh with "
               f"CSF and cerebellum {v['total']:.0f} ml); the ICBM152 template scaled by "
               f"{factor:.3f} in length ({factor**3:.3f} in volume)",
               "holds" if ok else "differs",
               "" if ok else "we scale the white matter to half of 1,108 ml, the paper's own "
               f"assumption behind its swelling volumes; the template's white matter is "
               f"{100 * t['white'] / (t['white'] + t['gray']):.0f} % of its gray + white matter, "
               "so both cannot hold")


def m_surface(run: Run) -> Row:
    return Row("ICBM152 template (an average of many heads, 1 mm): its smooth intracranial "
               "envelope has no cortical folds to measure", "other setup",
               "another subject: the paper's MRI is not public. The paper's 0.252 mm cannot be "
               "a cortical thickness (the cortex is 1-4.5 mm thick, far more than one of its "
               "0.9 mm voxels): most likely 0.252 cm, 2.5 mm")


def m_mri(run: Run) -> Row:
    return Row("ICBM152 2009a template, 1 mm isotropic (197 x 233 x 189 voxels)", "other setup",
               "another subject: the paper's MRI is not public")


def m_mesh(run: Run) -> Row:
    v = _brain_mesh_volumes(run)
    if v is None:
        return Row("no mesh", "not measured", "3D part missing")
    return Row(f"{v['tets']:,} linear tets, {v['nodes']:,} nodes; MINI elements (P1 "
               "displacement + bubble, continuous P1 pressure per region)",
               "same setup" if v["tets"] > 1_000_000 else "differs",
               "" if v["tets"] > 1_000_000 else "mesh size: this run's mesh is "
               f"{1_275_808 / v['tets']:.0f}x coarser than the paper's")


def m_materials(run: Run) -> Row:
    from brainbulge.materials.presets import PRESETS

    p = PRESETS["paper"]
    return Row(", ".join(f"{k} {c1:g} / {c2:g}" for k, (c1, c2) in p.items()) + " kPa",
               "same setup")


def m_boundary(run: Run) -> Row:
    s = next(iter(run.brain.values()), None)
    fix = (s or {}).get("inputs", {}).get("fix", "inferior+superior")
    return Row(f"base fixed{', superior CSF band fixed' if 'superior' in fix else ''}; "
               "frictionless contact with a rigid skull elsewhere; regions bonded; no skin",
               "same setup")


def m_swelling(run: Run) -> Row:
    n = len(run.brain)
    return Row(f"{n} of 6 scenarios complete, white matter Js 1 -> 1.1",
               "same setup" if n == 6 else "differs",
               "" if n == 6 else f"did not complete: {', '.join(run.brain_missing)}")


def m_flaps(run: Run) -> Row:
    v = _brain_mesh_volumes(run)
    if v is None or len(v["flaps_cm2"]) < 2:
        return Row("no mesh", "not measured", "3D part missing")
    a = v["flaps_cm2"]
    return Row(f"nominal areas: frontal {a['frontal']:.0f} cm2, left {a['left']:.0f} cm2, ratio "
               f"{a['frontal'] / a['left']:.2f}", "by construction",
               "the flaps' diameters are inputs chosen for the paper's \"twice\"; the paper "
               "counts removed skull elements, whose ratio 4,279 / 2,494 is 1.72")


def _pairs(run: Run, key: str) -> list[tuple[str, float, float]]:
    out = []
    for side in ("both", "left", "right"):
        lf, ff = run.brain.get(f"left-flap_{side}-swelling"), run.brain.get(
            f"frontal-flap_{side}-swelling")
        if lf and ff and lf.get(key) is not None and ff.get(key) is not None:
            out.append((side, float(lf[key]), float(ff[key])))
    return out


def m_frontal_smaller_displacement(run: Run) -> Row:
    pairs = _pairs(run, "max_displacement")
    if not pairs:
        return Row("no result", "not measured", "3D scenarios missing")
    ok = all(f <= (1 - MARKED) * u for _, u, f in pairs)
    text = "; ".join(f"{side}: unilateral {u:.2f} mm, frontal {f:.2f} mm" for side, u, f in pairs)
    return Row("largest displacement " + text, "holds" if ok else "differs",
               "" if ok else "in some scenario the frontal flap's largest displacement is not "
               f"{100 * MARKED:.0f} % below the unilateral one's")


def m_midline(run: Run) -> Row:
    if not run.brain:
        return Row("no result", "not measured", "3D scenarios missing")
    parts = [f"{n.replace('-flap_', '/').replace('-swelling', '')} "
             f"{float(s['midline_shift_mm']):+.2f}"
             for n, s in sorted(run.brain.items()) if s.get("midline_shift_mm") is not None]
    return Row("midline shift at the foramen of Monro [mm]: " + ", ".join(parts), "holds",
               "the paper gives no number; ours are small for swelling of 28-55 ml")


def _recurring(run: Run, kind: str, key: str) -> dict[str, int]:
    """How many scenarios share each ``kind`` (``extreme_sites`` or ``element_sites``) site
    of ``key``: a site that recurs under other flaps and swelling sides belongs to one
    element of the mesh, not to the load."""
    where = [tuple(s.get(kind, {}).get(key, {}).get("X_mm", ())) for s in run.brain.values()]
    return {str(list(w)): where.count(w) for w in where if w}


def _site_text(site: dict) -> str:
    return (f"{site['region']}, {site['rim_distance_mm']:.0f} mm from the rim, "
            f"{'under' if site['under_flap'] else 'not under'} the flap, depth "
            f"{site['depth_mm']:.0f} mm, {site.get('interface_distance_mm', float('nan')):.1f}"
            " mm from a tissue interface")


def _brain_extreme(run: Run, key: str, paper: float, stretch: bool,
                   place: Callable[[dict], bool], place_text: str) -> Row:
    """Our extremes against the paper's "up to" / "down to" ``paper`` at the place ``place``
    accepts (a site, or a peak set given as its median rim distance and share under the flap).
    The primary measure is what the paper's contour plots show at the end of their colour
    bar and what is stable under refinement: the 0.1 ml peak (``peak_*``; ``p01_*`` for a
    minimum), the most extreme over the scenarios. It holds when that is within
    :data:`~paper_run.BAND` of the paper's value (:func:`~paper_run.band`) and its 0.1 ml
    peak set lies in that place in most scenarios; the single-point and element values are
    shown beside it (they change by up to 45 % between meshes: not verdicts)."""
    if not run.brain:
        return Row("no result", "not measured", "3D scenarios missing")
    is_max = key.startswith("max_")
    vol_key = key.replace("max_", "peak_") if is_max else key.replace("min_", "p01_")
    pick = max if is_max else min
    vals = {n: s for n, s in run.brain.items() if s.get(key) is not None}
    if not vals:
        return Row("no result", "not measured", "3D summaries without this key")
    n_vol = pick(vals, key=lambda n: float(vals[n][vol_key]))
    vol = float(vals[n_vol][vol_key])
    n_pt = pick(vals, key=lambda n: float(vals[n][key]))
    n_el = pick(vals, key=lambda n: float(vals[n].get(f"element_{key}", vals[n][key])))
    pt, el = vals[n_pt], vals[n_el]
    pt_site = pt.get("extreme_sites", {}).get(key)
    el_site = el.get("element_sites", {}).get(key)
    rec_pt, rec_el = _recurring(run, "extreme_sites", key), _recurring(run, "element_sites", key)
    ours = [f"{'peak (0.1 ml)' if is_max else 'p01'} {vol:.3f} ({n_vol}; "
            f"{excess_text(vol, paper, stretch)})"]
    for label, value, site, rec in (
            ("point", float(pt[key]), pt_site, rec_pt),
            ("element", float(el.get(f"element_{key}", el[key])), el_site, rec_el)):
        text = f"{label} {value:.3f} ({n_pt if label == 'point' else n_el})"
        if site:
            text += f" at {_site_text(site)}"
            n_rec = rec.get(str(site["X_mm"]), 1)
            if n_rec > 1:
                text += (f", the extreme of one element in {n_rec} of {len(run.brain)} "
                         "scenarios whatever the flap (an interface singularity)")
        ours.append(text)
    peak_places = []
    for s in vals.values():
        ps = s.get("extreme_sites", {}).get(key, {}).get("peak_set")
        if ps:
            peak_places.append(place({"rim_distance_mm": ps["median_rim_distance_mm"],
                                      "under_flap": ps["share_under_flap"] > 0.5,
                                      "depth_mm": ps["median_depth_mm"]}))
    ours.append(f"0.1 ml peak sets {place_text} in {sum(peak_places)} of {len(peak_places)} "
                "scenarios")
    reasons = []
    where = band(vol, paper, stretch)
    if where != "within":
        reasons.append(f"{where} the paper's {paper:g}: the 0.1 ml {'peak' if is_max else 'p01'}"
                       f" reaches {excess_text(vol, paper, stretch)} (band +-{BAND:.0%}); "
                       f"{SENSITIVITY}")
    if peak_places and 2 * sum(peak_places) <= len(peak_places):
        reasons.append(f"the 0.1 ml peak set is not {place_text} in "
                       f"{len(peak_places) - sum(peak_places)} of {len(peak_places)} scenarios")
    return Row("; ".join(ours), "differs" if reasons else "holds", "; ".join(reasons))


#: what the 3D sensitivity and edge-radius studies (benchmarks/bench_sensitivity_3d.py,
#: bench_edge_radius_3d.py) found for the
#: magnitudes, quoted in every 3D magnitude row that differs
SENSITIVITY = ("cause not found: on the 111k template one change at a time (edge radius "
               "8 / 4 / 2 mm, superior band 0 / 1 / 2 cm, base 10 mm lower / higher, CSF x10; "
               "x0.1 did not converge; the mesh 111k -> 428k tets, 0.004 at most) "
               "moves these 0.1 ml peaks by 0.024 at most, the sharper edge away "
               "from the paper (the edge radius 8 / 4 / 2 / 1 mm in all six scenarios: "
               "0.024 at most, a smaller radius away from the paper or level within 0.002; "
               "bench_edge_radius_3d.py); sampling the vertices instead (nodal values, as a "
               "contour plot shows) lifts the tangential peak 5-25 mm from the rim to "
               "1.23-1.29, not the radial ones (docs/performance.md, bench_sensitivity_3d.py)")


def _swelling_text(run: Run) -> str:
    v = sorted({round(float(s.get("swelling_volume_ml", 0)), 0) for s in run.brain.values()})
    return "/".join(f"{x:.0f}" for x in v) + " ml"


def m_radial_max(run: Run) -> Row:
    return _brain_extreme(run, "max_radial_stretch", 1.3, True,
                          lambda s: s["under_flap"] and s["rim_distance_mm"] > 15,
                          "deep in the bulge (under the flap, > 15 mm from the rim)")


def m_radial_min(run: Run) -> Row:
    return _brain_extreme(run, "min_radial_stretch", 0.7, True,
                          lambda s: s["rim_distance_mm"] < 25, "around the opening (< 25 mm "
                          "from the rim)")


def m_tangential_max(run: Run) -> Row:
    return _brain_extreme(run, "max_tangential_stretch", 1.3, True,
                          lambda s: s["rim_distance_mm"] < 25,
                          "in a ring around the opening (< 25 mm from the rim)")


def m_strain_max(run: Run) -> Row:
    return _brain_extreme(run, "max_principal_strain", 0.30, False,
                          lambda s: s["rim_distance_mm"] < 25,
                          "at the opening (< 25 mm from the rim)")


def m_displacement_centre(run: Run) -> Row:
    """The largest displacement's place (``argmax_displacement``): under the flap and more
    than 15 mm from its rim (the bulge's centre) in every scenario."""
    have = {n: s for n, s in run.brain.items() if s.get("argmax_displacement")}
    path = run.root / "craniectomy" / "mesh" / "brain.npz"
    if not have or not path.is_file():
        return Row("the summaries of this run give the largest displacement's value, not its "
                   "place", "not measured", "the run predates `argmax_displacement`")
    from brainbulge.geometry.brain import load_brain_mesh
    from brainbulge.geometry.brain.skull import RigidSkull

    bm = load_brain_mesh(path)
    parts, ok = [], True
    for n, s in sorted(have.items()):
        flap = bm.flaps[n.split("-flap_")[0]]
        X = np.asarray([s["argmax_displacement"]], dtype=float)
        cut = flap.cutter_distance(X)[0]
        rim = float(np.hypot(cut, RigidSkull(bm.envelope).envelope_distance(
            X, gradient=False)[0])[0])
        centre = bool(cut[0] < 0) and rim > 15
        ok &= centre
        parts.append(f"{n}: {float(s['max_displacement']):.2f} mm, "
                     f"{'under' if cut[0] < 0 else 'not under'} the flap, {rim:.0f} mm from "
                     "the rim")
    return Row("largest |u| at " + "; ".join(parts), "holds" if ok else "differs",
               "" if ok else "in some scenario the largest displacement is not under the "
               "flap, > 15 mm from its rim")


def m_three_zones(run: Run) -> Row:
    rows = [m_radial_max(run), m_radial_min(run), m_tangential_max(run)]
    if any(r.verdict == "not measured" for r in rows):
        return Row("no result", "not measured", "3D scenarios missing")
    ok = all(r.verdict == "holds" for r in rows)
    return Row("3D: see the three rows above; 2D: trends (ii) and (iii)",
               "holds" if ok else "differs",
               "" if ok else "not every zone is where, or as strong as, the paper says")


def m_tangential_28(run: Run) -> Row:
    one = {n: s for n, s in run.brain.items() if "both" not in n}
    if not one:
        return Row("no result", "not measured", "3D scenarios missing")
    n = max(one, key=lambda k: float(one[k]["peak_tangential_stretch"]))
    s = one[n]
    white = float(s.get("white_matter_volume_ml", 0)) * 2
    sw = float(s["swelling_volume_ml"])
    peak = float(s["peak_tangential_stretch"])
    elem = float(s.get("element_max_tangential_stretch", s["max_tangential_stretch"]))
    where = band(peak, 1.3)
    return Row(f"one hemisphere swelling {sw:.1f} ml ({100 * sw / white:.1f} % of all white "
               f"matter): peak (0.1 ml) lambda_t {peak:.3f} ({excess_text(peak, 1.3)}), "
               f"point {float(s['max_tangential_stretch']):.3f}, element {elem:.3f} ({n})",
               "holds" if where == "within" else "differs",
               "" if where == "within" else f"{where} the paper's 1.3 by the 0.1 ml peak "
               f"(band +-{BAND:.0%}); the swelling volume matches; {SENSITIVITY}")


def _peak_places(run: Run, key: str, place: Callable[[dict], bool]) -> dict[str, bool]:
    """Scenario -> whether the 0.1 ml peak set of ``key`` lies where ``place`` accepts."""
    out = {}
    for n, s in run.brain.items():
        ps = s.get("extreme_sites", {}).get(key, {}).get("peak_set")
        if ps:
            out[n] = place({"rim_distance_mm": ps["median_rim_distance_mm"],
                            "under_flap": ps["share_under_flap"] > 0.5,
                            "depth_mm": ps["median_depth_mm"]})
    return out


#: the paper's places of the three zones: (summary key, place, its words)
ZONES = (("max_radial_stretch", lambda s: s["under_flap"] and s["rim_distance_mm"] > 15,
          "radial maximum deep in the bulge"),
         ("min_radial_stretch", lambda s: s["rim_distance_mm"] < 25,
          "radial minimum around the opening"),
         ("max_tangential_stretch", lambda s: s["rim_distance_mm"] < 25,
          "tangential maximum in a ring round the opening"))


def m_locations_common(run: Run) -> Row:
    """The abstract's "locations of maximum stretch the same in all bulging brains": in
    every scenario each zone's 0.1 ml peak set lies where the paper puts it (:data:`ZONES`)."""
    if not run.brain:
        return Row("no result", "not measured", "3D scenarios missing")
    parts, missing = [], []
    for key, place, words in ZONES:
        at = _peak_places(run, key, place)
        parts.append(f"{words}: {sum(at.values())} of {len(at)} scenarios")
        missing += [f"{words} ({n})" for n, ok in sorted(at.items()) if not ok]
    return Row("0.1 ml peak sets: " + "; ".join(parts), "differs" if missing else "holds",
               "not where the paper puts it: " + ", ".join(missing) if missing else "")


def m_strain_in_excess(run: Run) -> Row:
    """The abstract's "strains in excess of 30 %" for 28-56 ml: the 0.1 ml peak of the
    maximum principal strain at least 0.30 in some scenario (single points and elements
    beside it)."""
    if not run.brain:
        return Row("no result", "not measured", "3D scenarios missing")
    n = max(run.brain, key=lambda k: float(run.brain[k]["peak_principal_strain"]))
    s = run.brain[n]
    peak = float(s["peak_principal_strain"])
    ours = (f"peak (0.1 ml) {peak:.3f} ({n}), point {float(s['max_principal_strain']):.3f}, "
            f"element {float(s.get('element_max_principal_strain', float('nan'))):.3f}; "
            f"swelling {_swelling_text(run)}")
    if peak >= 0.30:
        return Row(ours, "holds")
    return Row(ours, "differs", f"no 0.1 ml of tissue exceeds 30 % (the peak is "
               f"{excess_text(peak, 0.30, False)}); only single points and elements do, and "
               "they grow under refinement (interface singularities)")


def m_release(run: Run) -> Row:
    return Row("not modelled: every scenario swells with the flap already open (Js 1 -> 1.1 "
               "against the skull with the opening); no state swollen under the intact skull "
               "is released", "not modelled",
               "with the flap closed the swelling is infeasible (an incompressible tissue in a "
               "rigid closed skull: `--flap none` exits with that message), so there is no "
               "swollen, strained state to release without a compressible or perfused tissue, "
               "which the paper does not model either")


def m_shear_edge_3d(run: Run) -> str:
    """Where the 3D maximum shear stress's 0.1 ml peak sets lie, as text ("" without them)."""
    at = _peak_places(run, "max_shear_stress", lambda s: s["rim_distance_mm"] < 25)
    if not at:
        return ""
    peaks = [float(s["peak_shear_stress"]) for s in run.brain.values()
             if s.get("peak_shear_stress") is not None]
    return (f"3D: 0.1 ml peak of the maximum shear stress {min(peaks):.3g}-{max(peaks):.3g} kPa"
            f", its peak set within 25 mm of the rim in {sum(at.values())} of {len(at)} "
            "scenarios")


def m_context(text: str) -> Callable[[Run], Row]:
    def measure(run: Run) -> Row:
        return Row(text, "context")
    return measure


def m_clinical_volumes(run: Run) -> Row:
    if not run.brain:
        return Row("no result", "not measured", "3D scenarios missing")
    return Row(f"our swelling volumes {_swelling_text(run)}: below 50-150 ml, at the low end of "
               "27-127 ml", "by construction", "the swelling volumes follow from the white "
               "matter's volume, to which the template is scaled (5-swelling-volumes)")


def m_drops(run: Run) -> Row:
    return Row("shape not measured; the sector figures (grid_lambda_t_*.png) show the zones",
               "not measured", "no measure of a zone's shape")


def m_frontal_lower(run: Run) -> Row:
    keys = ("max_displacement", "p95_principal_strain", "p95_radial_stretch",
            "p95_tangential_stretch")
    parts, ok = [], True
    for key in keys:
        pairs = _pairs(run, key)
        if not pairs:
            return Row("no result", "not measured", "3D scenarios missing")
        for _side, u, f in pairs:
            du, df = (u - 1, f - 1) if "stretch" in key else (u, f)
            if not df <= (1 - MARKED) * du:
                ok = False
        ratio = [(f - 1) / (u - 1) if "stretch" in key else f / u for _, u, f in pairs]
        parts.append(f"{key} frontal / unilateral {min(ratio):.2f}-{max(ratio):.2f}"
                     + (" (of the excess over 1)" if "stretch" in key else ""))
    return Row("; ".join(parts), "holds" if ok else "differs",
               "" if ok else f"some frontal value is not {100 * MARKED:.0f} % below the "
               "unilateral one for the same swelling")


def m_swelling_volumes(run: Run) -> Row:
    both = [float(s["swelling_volume_ml"]) for n, s in run.brain.items() if "both" in n]
    one = [float(s["swelling_volume_ml"]) for n, s in run.brain.items() if "both" not in n]
    if not both or not one:
        return Row("no result", "not measured", "3D scenarios missing")
    ok = (abs(np.mean(both) / 56 - 1) < 0.05 and abs(np.mean(one) / 28 - 1) < 0.05)
    return Row(f"both hemispheres {min(both):.1f}-{max(both):.1f} ml, one {min(one):.1f}-"
               f"{max(one):.1f} ml", "by construction" if ok else "differs",
               "the template is scaled so that its white matter is half of 1,108 ml" if ok
               else "the template's white matter is not half of its brain")


def m_damage(run: Run) -> Row:
    if not run.brain:
        return Row("no result", "not measured", "3D scenarios missing")
    peak = {n: float(s["peak_principal_strain"]) for n, s in run.brain.items()}
    p99 = {n: float(s["p99_principal_strain"]) for n, s in run.brain.items()}
    over18 = sorted(n for n, v in peak.items() if v > 0.18)
    over21 = sorted(n for n, v in peak.items() if v > 0.21)
    return Row(f"peak strain (0.1 ml) {min(peak.values()):.3f}-{max(peak.values()):.3f}, p99 "
               f"{min(p99.values()):.3f}-{max(p99.values()):.3f}: above 18 % in "
               f"{len(over18)} of {len(peak)} scenarios, above 21 % in {len(over21)}",
               "holds" if over18 else "differs",
               "" if over18 else "no 0.1 ml of tissue reaches 18 %")


