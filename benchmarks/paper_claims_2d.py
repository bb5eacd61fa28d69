"""The measures of the paper's 2D claims (its section 3) on a reproduce folder."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from paper_run import BAND, MARKED, WAITING, Row, Run, band, excess_text

#: docs/model.md's section on the 2D skull, as a link from docs/paper.md
SKULL_SECTION = "model.md#10-the-2d-skull-and-its-edge"


# --- 2D measures ------------------------------------------------------------------------
def _angle_from_axis(p) -> float:
    return abs(90.0 - math.degrees(math.atan2(float(p[1]), float(p[0]))))


def _scenario(sc: dict) -> str:
    if sc.get("alpha") is not None:
        return f"{sc['contact']} alpha {float(sc['alpha']):g} beta {float(sc['beta']):g}"
    return sc["name"]


def m_headline(run: Run) -> Row:
    have = [n for n in ("noslip_a80_b60", "sliding_a80_b60") if n in run.sector]
    if len(have) < 2:
        return Row("headline case missing", "not measured", "run the sector study")
    return Row("alpha 80, beta 60, Js 1.2, base clamped, opening traction-free",
               "same setup")


def _max_u_site(vf) -> tuple[float, float, float]:
    i = int(np.argmax(vf.point_data["u_magnitude"]))
    p = vf.points[i]
    return float(vf.point_data["u_magnitude"][i]), _angle_from_axis(p), float(np.hypot(*p))


def m_noslip_bulge(run: Run) -> Row:
    vf = run.fields("sector", "noslip_a80_b60")
    if vf is None:
        return Row("no result", "not measured", "headline no-slip case missing")
    u, ang, r = _max_u_site(vf)
    ok = ang < 5.0
    return Row(f"largest |u| {u:.3f} R at {ang:.1f} deg from the axis, r = {r:.2f} R",
               "holds" if ok else "differs",
               "" if ok else "the largest displacement is off the symmetry axis")


def _skull_slide_deg(vf, beta: float) -> tuple[float, float]:
    """Largest angular slide [deg] of skull-arc vertices towards the opening and away from
    it."""
    X = vf.points
    r = np.hypot(X[:, 0], X[:, 1])
    th = np.degrees(np.arctan2(X[:, 1], X[:, 0]))
    on_skull = (r > 1 - 1e-6) & (np.abs(th - 90) > beta / 2 + 1e-6)
    if not on_skull.any():
        return 0.0, 0.0
    x = X + vf.point_data["u"][:, :2]
    th1 = np.degrees(np.arctan2(x[:, 1], x[:, 0]))
    towards = np.where(th[on_skull] < 90, th1[on_skull] - th[on_skull],
                       th[on_skull] - th1[on_skull])
    return float(max(towards.max(), 0.0)), float(max(-towards.min(), 0.0))


def _edge_outward(vf, beta: float, width: float = 10.0) -> float:
    """Mean radial displacement [R] of the opening's surface within ``width`` deg of its
    edges: how far the tissue turns outward around the edge."""
    X = vf.points
    r = np.hypot(X[:, 0], X[:, 1])
    off = np.abs(np.degrees(np.arctan2(X[:, 1], X[:, 0])) - 90)
    near = (r > 1 - 1e-6) & (off <= beta / 2) & (off >= beta / 2 - width)
    radial = np.einsum("ij,ij->i", vf.point_data["u"][near, :2], X[near] / r[near, None])
    return float(radial.mean()) if near.any() else 0.0


def m_sliding_rotation(run: Run) -> Row:
    vs, vn = run.fields("sector", "sliding_a80_b60"), run.fields("sector", "noslip_a80_b60")
    if vs is None or vn is None:
        return Row("no result", "not measured", "headline cases missing")
    towards, away = _skull_slide_deg(vs, 60.0)
    es, en = _edge_outward(vs, 60.0), _edge_outward(vn, 60.0)
    slides = max(towards, away) > 0.1
    turns = es > (1 + MARKED) * en
    ours = (f"skull-side tissue slides up to {towards:.2f} deg towards the opening and "
            f"{away:.2f} deg away from it (no-slip 0); the opening's surface within 10 deg of "
            f"its edges moves out {es:.4f} R with sliding, {en:.4f} R without")
    if slides and turns:
        return Row(ours, "holds")
    why = []
    if towards < 0.1:
        why.append("the tissue at the edge slides under the skull, away from the opening, not "
                   "out of it: our held arc (the material arc held to r <= R past the "
                   f"opening's edge, [docs/model.md, section 10]({SKULL_SECTION})), not the "
                   "paper's edge; with the edge released and rounded (rho 0.03 R, "
                   "benchmarks/bench_edge_2d.py) the material 0.16 deg under the skull's edge "
                   "ends 1.4 deg inside the opening, turned out round the edge")
    if not turns:
        why.append("the tissue next to the edge does not turn out more with sliding")
    return Row(ours, "differs" if not (slides and turns) else "holds", "; ".join(why))


def m_sweep(run: Run) -> Row:
    n = len(run.sector)
    waiting = [m for m in run.sector_missing if m in WAITING]
    other = [m for m in run.sector_missing if m not in WAITING]
    text = (f"alpha 20-80 x beta 30, 60, 90, 120 x both contacts, Js 1.2: {n} of "
            f"{n + len(run.sector_missing)} complete")
    why = []
    if waiting:
        why.append(f"{', '.join(waiting)} waits for the sliding solver that releases points "
                   "past the opening's edge")
    if other:
        why.append(f"did not complete: {', '.join(other)}")
    return Row(text, "same setup" if not run.sector_missing else "differs",
               "; ".join(why) or "the paper shows its betas only in a figure (Figure 3)")


def m_area_ratio(run: Run) -> Row:
    devs = []
    for name, s in run.sector.items():
        vf = run.fields("sector", name)
        if vf is None:
            continue
        c = vf.cells
        X = vf.points
        x = X + vf.point_data["u"][:, :2]

        def area(P, c=c):
            a, b, d = P[c[:, 0]], P[c[:, 1]], P[c[:, 2]]
            return 0.5 * np.abs((b - a)[:, 0] * (d - a)[:, 1] - (b - a)[:, 1] * (d - a)[:, 0])

        A0, A1 = area(X).sum(), area(x).sum()
        expected = float(s["alpha"]) / 180.0 * (float(s["swelling"]) - 1)
        devs.append(abs((A1 - A0) / A0 - expected) / expected)
    if not devs:
        return Row("no result", "not measured", "sector study missing")
    worst = max(devs)
    return Row(f"deformed area of the P1 mesh: dA/A within {100 * worst:.2f} % of alpha/pi "
               f"(J - 1) in all {len(devs)} complete cases",
               "by construction" if worst < 0.02 else "differs",
               "the pressure enforces the integral of J - Js, so the added area is the "
               "swelling's" if worst < 0.02 else "the constraint J = Js holds only weakly "
               "(per element pressure space)")


def _sweep_max(run: Run, key: str) -> tuple[float, dict] | None:
    rows = [s for s in run.sector.values() if s.get(key) is not None]
    if not rows:
        return None
    best = max(rows, key=lambda s: float(s[key]))
    return float(best[key]), best


#: a bulge that reaches this far [R] beyond the skull arc where the skull is folds over it
CROSSING = 0.05
#: a maximum this many exclusion radii or less from a singular point sits on the exclusion
#: circle: its value is set by the radius (the field there grows as the radius shrinks)
ON_CIRCLE = 1.5


def _on_exclusion_circle(s: dict, stem: str) -> bool:
    """Whether the edge-excluded maximum ``max_<stem>`` of scenario ``s`` lies next to the
    circle around a singular point (within :data:`ON_CIRCLE` exclusion radii)."""
    loc, pts = s.get(f"argmax_{stem}"), s.get("singular_points") or []
    r = float(s.get("edge_exclusion") or 0)
    if loc is None or not pts or r <= 0:
        return False
    d = min(math.dist((float(loc[0]), float(loc[1])), (float(p[0]), float(p[1]))) for p in pts)
    return d <= ON_CIRCLE * r


def m_up_to_2d(stem: str) -> Callable[[Run], Row]:
    """The paper's "up to 1.7" of ``stem``: the primary measure is the largest edge-excluded
    maximum over the cases whose bulge does not fold over the skull (crossing <
    :data:`CROSSING`), within :data:`~paper_run.BAND` of 1.7 (:func:`~paper_run.band`);
    when that maximum sits on the exclusion circle around a singular point, the verdict is
    "singular": the value is the radius's, not the bulge's."""
    def measure(run: Run) -> Row:
        raw = _sweep_max(run, f"raw_max_{stem}")
        exc = _sweep_max(run, f"max_{stem}")
        if raw is None or exc is None:
            return Row("no result", "not measured", "sector study missing")
        flat = [s for s in run.sector.values()
                if float(s.get("max_skull_crossing") or 0) < CROSSING]
        if not flat:
            return Row("no result", "not measured", "every case folds over the skull")
        best = max(flat, key=lambda s: float(s[f"max_{stem}"]))
        value = float(best[f"max_{stem}"])
        loc = best.get(f"argmax_{stem}")
        where = f" at ({loc[0]:.2f}, {loc[1]:.2f}) R" if loc else ""
        ours = (f"outside the edge disks, without the cases whose bulge folds over the skull "
                f"(crossing >= {CROSSING:g} R): {value:.2f} ({_scenario(best)}{where}; "
                f"{excess_text(value, 1.7)}); with them {exc[0]:.2f} ({_scenario(exc[1])}); "
                f"raw (all points) {raw[0]:.2f} ({_scenario(raw[1])})")
        if _on_exclusion_circle(best, stem):
            return Row(ours, "singular",
                       f"the maximum sits on the circle of radius {best['edge_exclusion']:g} R "
                       "around a singular corner, where the field grows as the radius shrinks "
                       "(stress ~ r^-1/2, docs/verification.md): its value is the radius's")
        position = band(value, 1.7)
        if position == "within":
            return Row(ours, "holds")
        return Row(ours, "differs", f"{position} the paper's 1.7 (band +-{BAND:.0%} of the "
                   "excess)")
    return measure


def _trend_measure(label: str) -> Callable[[Run], Row]:
    def measure(run: Run) -> Row:
        from brainbulge.studies.trends import check_trends

        rows = [dict(s) for s in run.sector.values()]
        trends = [t for t in check_trends(rows) if t.label == label]
        if not trends:
            return Row("no result", "not measured", "sector study missing")
        parts, verdicts = [], []
        for t in trends:
            marked = "" if t.marked is None else f", markedly {t.marked}"
            parts.append(f"{t.statement} ({t.maxima}): {t.held} of {t.cases}{marked}; "
                         f"{t.verdict}" + (f" ({t.evidence})" if t.evidence else ""))
            verdicts.append(t.verdict)
        verdict = "holds" if all(v == "holds" for v in verdicts) else "differs"
        why = "" if verdict == "holds" else TREND_REASONS[label](run.sector.values())
        return Row("; ".join(parts), verdict, why)
    return measure


def _why_i(rows) -> str:
    """The largest relative rise among the comparisons where a wider opening did not lower a
    maximum (edge-excluded)."""
    by = {(s["contact"], float(s["alpha"]), float(s["beta"])): s for s in rows}
    worst = 0.0
    for (c, a, b), s in by.items():
        wider = sorted(bb for cc, aa, bb in by if cc == c and aa == a and bb > b)
        if not wider:
            continue
        s1 = by[(c, a, wider[0])]
        for key in ("max_displacement", "max_radial_stretch", "max_tangential_stretch"):
            if float(s1[key]) > float(s[key]):
                worst = max(worst, float(s1[key]) / float(s[key]) - 1)
    return (f"where a wider opening does not lower a maximum it raises it by at most "
            f"{100 * worst:.1f} %: the maxima outside the edge disks of wide openings hardly "
            "change with beta (mesh size and edge exclusion decide such differences)")


def _where(rows, key: str, test) -> dict[str, int]:
    """Where the ``argmax`` ``key`` of the rows that fail ``test`` lies: at the centre of
    the base (the sector's apex), near the opening's edge, or elsewhere."""
    out = {"at the sector's apex on the base": 0, "near the opening's edge": 0, "elsewhere": 0}
    for s in rows:
        x = s.get(key)
        if x is None or test(x, s):
            continue
        b = math.radians(float(s["beta"]) / 2)
        corner = min(math.dist(x[:2], (sg * math.sin(b), math.cos(b))) for sg in (1, -1))
        if math.hypot(*x[:2]) < 0.1:
            out["at the sector's apex on the base"] += 1
        elif corner < 0.2:
            out["near the opening's edge"] += 1
        else:
            out["elsewhere"] += 1
    return {k: v for k, v in out.items() if v}


def _why_ii(rows) -> str:
    from brainbulge.studies.trends import _under_opening

    where = _where(rows, "argmax_radial_stretch", _under_opening)
    failing = [s for s in rows if s.get("argmax_radial_stretch") is not None
               and not _under_opening(s["argmax_radial_stretch"], s)]
    circle = sum(_on_exclusion_circle(s, "radial_stretch") for s in failing)
    return ("the radial maximum lies " + ", ".join(f"{k} in {n} cases" for k, n in
                                                   where.items() if n)
            + f"; {circle} of them on the circle around the opening's corner, where the "
            "field is singular (sectors wider than the opening)")


def _why_iii(rows) -> str:
    from brainbulge.studies.trends import _near_edge

    where = _where(rows, "argmax_tangential_stretch", _near_edge)
    return ("outside the excluded disks the tangential maximum lies " + ", ".join(
        f"{k} in {n} cases" for k, n in where.items()) + "; the corner itself is excluded "
        "(edge exclusion), and the raw maximum there grows with refinement")


def _ratio_text(rows, field: str, higher: str) -> tuple[int, int, float, float]:
    lower = "sliding" if higher == "noslip" else "noslip"
    by = {(s["contact"], float(s["alpha"]), float(s["beta"])): s for s in rows}
    r = [float(by[(higher, a, b)][field]) / float(by[(lower, a, b)][field])
         for c, a, b in by if c == higher and (lower, a, b) in by]
    return sum(x > 1 for x in r), len(r), min(r), max(r)


def _ratio_lower(rows, field: str, higher: str) -> int:
    """How many ``higher / lower`` ratios of ``field`` fall below the 0.5 % tie."""
    from brainbulge.studies.trends import TIE

    lower = "sliding" if higher == "noslip" else "noslip"
    by = {(s["contact"], float(s["alpha"]), float(s["beta"])): s for s in rows}
    return sum(float(by[(higher, a, b)][field]) < (1 - TIE) * float(by[(lower, a, b)][field])
               for c, a, b in by if c == higher and (lower, a, b) in by)


def _why_iv(rows) -> str:
    held, n, lo, hi = _ratio_text(rows, "max_radial_stretch", "noslip")
    return (f"no-slip's radial maximum is the larger in {held} of {n} cases but by "
            f"{100 * (lo - 1):+.1f} to {100 * (hi - 1):+.1f} %: the direction holds, the size "
            "the paper calls marked does not")


def _why_v(rows) -> str:
    held, n, lo, hi = _ratio_text(rows, "max_tangential_stretch", "sliding")
    lower = _ratio_lower(rows, "max_tangential_stretch", "sliding")
    direction = ("the direction holds" if not lower else
                 f"lower with sliding beyond the 0.5 % tie in {lower}")
    return (f"sliding's tangential maximum is strictly the larger in {held} of {n} cases, "
            f"from {100 * (lo - 1):+.1f} to {100 * (hi - 1):+.1f} %: {direction}, and "
            "marked only in the few cases the trend's 'markedly' counts; the tissue does turn "
            "out round the rounded edge (3.2-sliding-rotation), and the sharp edge's maxima "
            "are mostly lower with sliding too (studies.md); cause not found")


#: the measured reason why each trend does not hold as stated
TREND_REASONS = {"(i)": _why_i, "(ii)": _why_ii, "(iii)": _why_iii, "(iv)": _why_iv,
                 "(v)": _why_v}


def m_disk_opening(run: Run) -> Row:
    if not run.disk:
        return Row("no result", "not measured", "disk study missing")
    s = next(iter(run.disk.values()))
    c = float(s.get("opening_center", 90.0))
    b = float(s.get("beta", 60.0))
    return Row(f"disk case: opening centred {90 - c:+.0f} deg off the axis (spans "
               f"{c - b / 2:g}-{c + b / 2:g} deg); sector case centred", "same setup",
               "the paper's figure gives no angle: 30 deg is ours")


def m_axons(run: Run) -> Row:
    return Row("n radial from the hemidisk's centre (the brain's centre in 3D), lambda_t "
               "perpendicular (3D: largest stretch in the plane normal to n)", "same setup")


def _disk_stats(run: Run) -> list[dict]:
    out = []
    for name, s in sorted(run.disk.items()):
        vf = run.fields("disk", name)
        if vf is None:
            continue
        cx, cy, rd = (float(v) for v in s["disk"])
        X = vf.points
        d = np.hypot(X[:, 0] - cx, X[:, 1] - cy) / rd
        corners = [np.asarray(p) for p in s.get("singular_points", [])]
        away = np.hypot(X[:, 0], X[:, 1]) > 0.02  # no radial direction at the centre
        for p in corners:
            away &= np.hypot(*(X - p[:2]).T) > float(s.get("edge_exclusion", 0.05))
        st = {"name": name.removeprefix("disk_")}
        for f in ("lambda_n", "lambda_t"):
            v = vf.point_data[f]
            i_max = np.flatnonzero(away)[np.argmax(v[away])]
            i_min = np.flatnonzero(away)[np.argmin(v[away])]
            st[f"{f}_max"], st[f"{f}_min"] = float(v[i_max]), float(v[i_min])
            st[f"{f}_dmax"], st[f"{f}_dmin"] = float(d[i_max]), float(d[i_min])
        # area share (vertex-lumped) of the hemidisk outside twice the disk's radius that a
        # stretch moves by more than 2 %
        c = vf.cells
        P = X[c]
        tri = 0.5 * np.abs((P[:, 1, 0] - P[:, 0, 0]) * (P[:, 2, 1] - P[:, 0, 1])
                           - (P[:, 1, 1] - P[:, 0, 1]) * (P[:, 2, 0] - P[:, 0, 0]))
        lam = np.maximum(np.abs(vf.point_data["lambda_n"] - 1),
                         np.abs(vf.point_data["lambda_t"] - 1))[c].mean(axis=1)
        far = d[c].mean(axis=1) > 2
        st["affected_far"] = float(tri[far & (lam > 0.02)].sum() / tri.sum())
        st["unaffected"] = float(tri[lam <= 0.02].sum() / tri.sum())
        st["far_share"] = float(tri[far].sum() / tri.sum())
        out.append(st)
    return out


def m_disk_setup(run: Run) -> Row:
    if not run.disk:
        return Row("no result", "not measured", "disk study missing")
    s = next(iter(run.disk.values()))
    return Row(f"{len(run.disk)} positions, disk radius {float(s['disk'][2]):g} R, Js "
               f"{float(s['swelling']):g}, sliding", "same setup" if len(run.disk) == 5
               else "differs", "the paper gives neither the disk's size nor its positions: "
               "ours are five points on an arc 0.55 R from the centre")


def m_local_event(run: Run) -> Row:
    st = _disk_stats(run)
    if not st:
        return Row("no result", "not measured", "disk study missing")
    dmax = max(max(s["lambda_n_dmax"], s["lambda_t_dmax"], s["lambda_n_dmin"],
                   s["lambda_t_dmin"]) for s in st)
    calm = min(s["unaffected"] for s in st)
    ok = dmax <= 2.0 and calm >= 0.5
    return Row(f"extremes of lambda_n, lambda_t within {dmax:.2f} disk radii of the disk's "
               f"centre in all {len(st)}; both stretches within 2 % of 1 over at least "
               f"{100 * calm:.0f} % of the hemidisk", "holds" if ok else "differs",
               "" if ok else "an extreme lies away from the disk, or most of the hemidisk "
               "is strained")


def m_insensitive(run: Run) -> Row:
    st = _disk_stats(run)
    if len(st) < 2:
        return Row("no result", "not measured", "disk study missing")
    ranges = {f: (min(s[f] for s in st), max(s[f] for s in st))
              for f in ("lambda_n_max", "lambda_t_max", "affected_far")}
    spread = max((hi - lo) / (hi - 1 if hi > 1 else 1) for f, (lo, hi) in ranges.items()
                 if f != "affected_far")
    ok = spread < 0.25
    return Row(f"max lambda_n {ranges['lambda_n_max'][0]:.3f}-{ranges['lambda_n_max'][1]:.3f}, "
               f"max lambda_t {ranges['lambda_t_max'][0]:.3f}-{ranges['lambda_t_max'][1]:.3f} "
               f"over the positions; area off by > 2 % beyond 2 radii "
               f"{100 * ranges['affected_far'][0]:.1f}-{100 * ranges['affected_far'][1]:.1f} %",
               "holds" if ok else "differs",
               "" if ok else "the extremes' excess over 1 varies by more than 25 % with the "
               "position (a disk near the opening bulges it)")




def m_shear_edge(run: Run, text_3d: str = "") -> Row:
    """"Large shear stresses around the opening edge": the headline cases' maximum shear
    stress (outside the edge disks) lies within ``EDGE_NEIGHBOURHOOD`` of an opening corner;
    ``text_3d``: the brain's part, shown beside it."""
    from brainbulge.studies.trends import EDGE_NEIGHBOURHOOD

    rows = [run.sector.get(n) for n in ("noslip_a80_b60", "sliding_a80_b60")]
    if not all(r and r.get("argmax_shear_stress") is not None for r in rows):
        return Row(text_3d or "no result", "not measured",
                   "the run has no shear-stress output (it predates it)")
    parts, ok = [], True
    for r in rows:
        loc = r["argmax_shear_stress"]
        beta = math.radians(float(r["beta"]) / 2)
        d = min(math.dist(loc[:2], (sx * math.sin(beta), math.cos(beta))) for sx in (-1, 1))
        ok &= d <= EDGE_NEIGHBOURHOOD
        raw = float(r["raw_max_shear_stress"])
        parts.append(f"{r['contact']}: max {float(r['max_shear_stress']):.3g} kPa at "
                     f"{d:.3f} R from the opening's corner, on the edge disk's circle (the "
                     f"stress is singular there, 5-analytical-punch; over all points "
                     f"{raw:.3g} kPa)")
    ours = "2D headline: " + "; ".join(parts) + (f"; {text_3d}" if text_3d else "")
    return Row(ours, "holds" if ok else "differs", "" if ok else
               f"a maximum lies farther than {EDGE_NEIGHBOURHOOD:g} R from the corners")


# --- the analytical comparison: the inverted punch's singularity at the opening's edge -----
#: the band of distances from the opening's corner [R] over which the exponents are fitted:
#: beyond a few corner elements, within the corner's neighbourhood
EDGE_FIT_RANGE = (0.008, 0.1)
#: rings of the stress fit
RINGS = 8
#: the analysis's exponents (docs/verification.md): the opening's profile rises as d^(1/2)
#: from the edge, the stress falls as r^(-1/2); a fit farther than EXPONENT_TOLERANCE fails
PROFILE_EXPONENT, STRESS_EXPONENT, EXPONENT_TOLERANCE = 0.5, -0.5, 0.1


def edge_exponents(vf, beta: float, fit: tuple[float, float] = EDGE_FIT_RANGE
                   ) -> tuple[float, float]:
    """The exponents of the fields near the opening's corner at ``90 - beta/2`` deg on the
    arc ``r = 1`` (the sector's vertex fields ``vf``, lengths in R): ``(s_u, s_tau)``, the
    log-log slopes of the opening's radial displacement against the arc distance ``d`` from
    the corner (``w ~ d^s_u``, vertices of the opening with ``d`` in ``fit``), and of the
    area-weighted RMS of the maximum shear stress over ``RINGS`` log-spaced rings ``r`` in
    ``fit`` around the corner (``tau ~ r^s_tau``; vertex values, each vertex weighing a
    third of its triangles' areas). The inverted punch gives 1/2 and -1/2."""
    X, u = vf.points[:, :2], vf.point_data["u"][:, :2]
    radius = np.hypot(X[:, 0], X[:, 1])
    theta = np.degrees(np.arctan2(X[:, 1], X[:, 0]))
    edge = 90.0 - beta / 2
    corner = np.array([math.cos(math.radians(edge)), math.sin(math.radians(edge))])
    d = np.radians(theta - edge)
    opening = (radius > 1 - 1e-9) & (d >= fit[0]) & (d <= fit[1])
    w = np.einsum("ij,ij->i", u[opening], X[opening] / radius[opening, None])
    w0 = float(u[np.argmin(np.linalg.norm(X - corner, axis=1))] @ corner)
    s_u = float(np.polyfit(np.log(d[opening]), np.log(w - w0), 1)[0])
    cells = np.asarray(vf.cells)
    e1, e2 = X[cells[:, 1]] - X[cells[:, 0]], X[cells[:, 2]] - X[cells[:, 0]]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    weight = np.bincount(cells.ravel(), np.repeat(area / 3, 3), minlength=len(X))
    tau = vf.point_data["max_shear_stress"]
    r = np.linalg.norm(X - corner, axis=1)
    edges = np.geomspace(*fit, RINGS + 1)
    mid, rms = [], []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        ring = (r >= a) & (r < b)
        if not ring.any():  # a coarse mesh: no vertex in this ring
            continue
        mid.append(math.sqrt(a * b))
        rms.append(math.sqrt(np.sum(weight[ring] * tau[ring] ** 2) / np.sum(weight[ring])))
    s_tau = float(np.polyfit(np.log(mid), np.log(rms), 1)[0])
    return s_u, s_tau


#: the small-strain runs of the comparison: 1 % swelling of the headline sector, the bulk
#: element size and two corner sizes [R]
SMALL_SWELLING, SMALL_H, SMALL_CORNERS = 1.01, 0.02, (0.004, 0.002)


def small_strain_exponents(contact: str, corner: float) -> tuple[float, float]:
    """:func:`edge_exponents` of the headline sector (alpha 80, beta 60) at 1 % swelling,
    ``contact`` on the paper's skull, bulk size ``SMALL_H`` and corner size ``corner`` [R]:
    the small-strain limit that the inverted punch describes (about 10 s each)."""
    from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem
    from brainbulge.results.export.writers import vertex_fields
    from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions

    case = HemidiskCase(contact=contact, mesh_size=SMALL_H, corner_mesh_size=corner,
                        swelling=SMALL_SWELLING, steps=1, edge_exclusion=0.0,
                        skull_edge_radius=0.0, element="mini",  # the punch's sharp edge
                        full_domain=True)
    form = MixedForm(hemidisk_problem(case), element=case.element)
    sol = NewtonSolver(form, SolverOptions(steps=case.steps)).solve()
    if not sol.converged:
        raise ValueError(f"the small-strain {contact} run did not converge: {sol.message}")
    return edge_exponents(vertex_fields(form, np.zeros(2)), case.beta)


def m_analytical(run: Run) -> Row:
    """The inverted punch's singularity, fitted from our small-strain fields at two corner
    mesh sizes (the reproduce run's own meshes are too coarse at the corner for a fit)."""
    parts, ok = [], True
    for contact in ("sliding", "noslip"):
        fits = [small_strain_exponents(contact, c) for c in SMALL_CORNERS]
        parts.append(f"{contact}: profile exponent " + " / ".join(f"{u:.3f}" for u, _ in fits)
                     + ", stress exponent " + " / ".join(f"{t:.3f}" for _, t in fits))
        ok &= all(abs(u - PROFILE_EXPONENT) <= EXPONENT_TOLERANCE
                  and abs(t - STRESS_EXPONENT) <= EXPONENT_TOLERANCE for u, t in fits)
    ours = (f"Js {SMALL_SWELLING:g}, headline sector, corner elements "
            + " / ".join(f"{c:g}" for c in SMALL_CORNERS) + " R, fitted over "
            f"{EDGE_FIT_RANGE[0]:g}-{EDGE_FIT_RANGE[1]:g} R from the corner: "
            + "; ".join(parts) + " (the analysis: 0.5 and -0.5, docs/verification.md)")
    return Row(ours, "holds" if ok else "differs", "" if ok else "an exponent is more than "
               f"{EXPONENT_TOLERANCE:g} from the analysis's")

