"""The small-strain limit of the hemidisk against the inverted punch (docs/verification.md,
"The opening's edge"): near the opening's corner the bulge's profile rises as ``d^(1/2)`` and
the stress falls as ``r^(-1/2)``. The exponents are fitted from our fields at two corner mesh
sizes; a fit outside ``0.5 +- 0.1`` fails."""

from __future__ import annotations

import pytest

from paper_claims_2d import (
    EXPONENT_TOLERANCE,
    PROFILE_EXPONENT,
    SMALL_CORNERS,
    STRESS_EXPONENT,
    small_strain_exponents,
)


@pytest.mark.parametrize("contact", ["sliding", "noslip"])
def test_the_fields_at_the_openings_edge_have_the_inverted_punchs_exponents(
        contact: str) -> None:
    fits = [small_strain_exponents(contact, corner) for corner in SMALL_CORNERS]
    for s_u, s_tau in fits:
        assert s_u == pytest.approx(PROFILE_EXPONENT, abs=EXPONENT_TOLERANCE), fits
        assert s_tau == pytest.approx(STRESS_EXPONENT, abs=EXPONENT_TOLERANCE), fits
    # the fits are the field's, not the mesh's: they agree between the two corner sizes
    (u1, t1), (u2, t2) = fits
    assert abs(u1 - u2) < 0.05 and abs(t1 - t2) < 0.05, fits
