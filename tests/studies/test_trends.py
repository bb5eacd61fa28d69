"""The sector study's trends test the paper's statements: same direction, "markedly" as a
stated threshold; an inverted trend is reported as such."""

from __future__ import annotations

import math

from brainbulge.studies.trends import MARKED, TIE, check_trends, trends_markdown


def _rows(radial_noslip_over_sliding: float, tangential_sliding_over_noslip: float):
    """A synthetic 2 x 2 x 2 sweep that follows the paper's trends (i)-(iii), with the
    given ratios of the contacts' radial and tangential maxima."""
    rows = []
    for contact in ("noslip", "sliding"):
        for alpha in (40.0, 80.0):
            for beta in (60.0, 120.0):
                radial = 1.0 + alpha / 400 - beta / 2000  # rises with alpha, falls with beta
                tangential = 1.2 - beta / 2000
                if contact == "noslip":
                    radial *= radial_noslip_over_sliding
                else:
                    tangential *= tangential_sliding_over_noslip
                corner = math.radians(90 - beta / 2)
                rows.append({
                    "contact": contact, "alpha": alpha, "beta": beta, "converged": True,
                    "max_displacement": 0.2 - beta / 1000,
                    "max_radial_stretch": radial, "raw_max_radial_stretch": radial + 0.1,
                    "max_tangential_stretch": tangential,
                    "raw_max_tangential_stretch": tangential + 0.2,
                    "argmax_radial_stretch": [0.0, 0.6],
                    "argmax_tangential_stretch": [0.97 * math.cos(corner),
                                                  0.97 * math.sin(corner)],
                })
    return rows


def _verdicts(rows) -> dict[tuple[str, str, str], str]:
    return {(t.label, t.statement, t.maxima): t.verdict for t in check_trends(rows)}


def test_the_papers_trends_hold_on_rows_that_follow_them() -> None:
    verdicts = _verdicts(_rows(1 + 2 * MARKED, 1 + 2 * MARKED))
    assert len(verdicts) == 10  # (i), (ii) growth, (iv), (v) with both maxima; 2 locations
    assert set(verdicts.values()) == {"holds"}


def test_an_inverted_contact_trend_is_reported_inverted() -> None:
    """Sliding with the larger radial and the smaller tangential maximum: the opposite of
    the paper's (iv) and (v)."""
    trends = check_trends(_rows(1 / 1.1, 1 / 1.1))
    for t in trends:
        if t.label in ("(iv)", "(v)"):
            assert t.verdict == "inverted" and t.held == 0 and t.cases == 4
        else:
            assert t.verdict == "holds"
    assert "| (v) | the tangential maximum is markedly higher with sliding" in (
        trends_markdown(trends))


def test_markedly_needs_the_threshold() -> None:
    trends = check_trends(_rows(1 + MARKED / 5, 1 + MARKED / 5))
    contact = [t for t in trends if t.label in ("(iv)", "(v)")]
    assert contact and all(t.verdict == "holds, not markedly" for t in contact)
    assert all(t.marked == 0 and t.held == t.cases for t in contact)


def test_a_narrower_opening_with_less_deformation_differs_from_trend_i() -> None:
    rows = _rows(1.2, 1.2)
    for r in rows:
        if r["contact"] == "sliding" and r["alpha"] == 80.0 and r["beta"] == 120.0:
            r["max_displacement"] = 1.0  # the wider opening deforms more here
    (i,) = [t for t in check_trends(rows) if t.label == "(i)" and t.maxima == "raw"]
    assert i.verdict == "differs" and i.held == i.cases - 1
    assert "max_displacement" in i.evidence


def test_a_tie_within_the_tolerance_is_not_a_failure_and_beyond_it_is() -> None:
    """A wider opening whose stretch maximum rises by half the tie tolerance still holds
    trend (i); by twice the tolerance it differs. The same for the contacts' ratio in (v)."""
    def wider_rises(rise: float) -> str:
        rows = _rows(1 + 2 * MARKED, 1 + 2 * MARKED)
        pick = {r["beta"]: r for r in rows if r["contact"] == "noslip" and r["alpha"] == 80.0}
        pick[120.0]["max_tangential_stretch"] = pick[60.0]["max_tangential_stretch"] * (1 + rise)
        return next(t.verdict for t in check_trends(rows)
                    if t.label == "(i)" and t.maxima == "edge-excluded")

    def sliding_lower(drop: float) -> str:
        return next(t.verdict for t in check_trends(_rows(1 + 2 * MARKED, 1 - drop))
                    if t.label == "(v)" and t.maxima == "edge-excluded")

    assert wider_rises(TIE / 2) == "holds"
    assert wider_rises(2 * TIE) == "differs"
    assert sliding_lower(TIE / 2) == "holds, not markedly"
    assert sliding_lower(2 * TIE) == "inverted"
