"""Inexact Newton: how tightly an iterative linear solve needs to solve ``K dx = R``."""

from __future__ import annotations


def forcing_term(eta: float, ratio: float, norm: float, tolerance: float, eta_max: float,
                 eta_min: float) -> float:
    """Relative tolerance of the next inexact linear solve (Eisenstat & Walker 1996, choice 2).

    ``eta_k = 0.9 (|R_k| / |R_k-1|)^2``, kept above ``0.9 eta_k-1^2`` while that is above
    0.1 (no sudden over-solving), not below ``0.1 tol/|R_k|`` (a linear residual below
    what the Newton tolerance needs buys nothing), and capped at ``eta_max``.
    and not below ``eta_min`` (the tightest; both are ``options.linear``'s). The cap wins over
    that floor: GMRES measures its residual in another norm than
    Newton's scaled one. (With the floor winning, the 1.54M-tet brain's last iteration ran
    at 0.06 instead of 1e-4 and still converged, but a 1.19M-tet brain's Newton stalled at
    |R| 1.5e-7, tolerance 1e-9: three iterations at 6e-4 lowered it by 3 %.)
    """
    eta_new = 0.9 * ratio**2
    if 0.9 * eta**2 > 0.1:
        eta_new = max(eta_new, 0.9 * eta**2)
    eta_new = max(eta_new, 0.1 * tolerance / max(norm, 1e-300))
    return float(min(max(eta_new, eta_min), eta_max))
