"""The energy is the single source of truth: the closed-form Kirchhoff stress of docs/model.md must
equal ``tau = (d psi / d F) F^T`` of the very energy the solver differentiates."""

from __future__ import annotations

import math

import ngsolve as ngs
import numpy as np
import pytest

from brainbulge.errors import InputError
from brainbulge.materials import MooneyRivlin, Ogden, neo_hookean, preset

_MESH = ngs.Mesh(ngs.unit_square.GenerateMesh(maxh=1.0))
_MIP = _MESH(0.3, 0.3)


def _random_F(rng: np.random.Generator) -> np.ndarray:
    F = np.eye(3) + 0.3 * rng.standard_normal((3, 3))
    if np.linalg.det(F) < 0.2:
        F[:, 0] *= -1 if np.linalg.det(F) < 0 else 1
        F = F + np.eye(3)
    return F


def _energy_gradient(material, F: np.ndarray, p: float, Js: float) -> tuple[np.ndarray, float]:
    """``d psi/dF`` of the solver's NGSolve energy ``psibar + p (J - Js)`` by symbolic Diff."""
    params = [ngs.Parameter(float(v)) for v in F.ravel()]
    Fcf = ngs.CF(tuple(params), dims=(3, 3))
    psi = material.psi_iso(Fcf) + p * (ngs.Det(Fcf) - Js)
    P = np.array([psi.Diff(q)(_MIP) for q in params]).reshape(3, 3)
    return P, psi(_MIP)


@pytest.mark.parametrize("c1,c2", [(0.28, 333.0), (1.0, 0.0), (0.56, 0.666)])
def test_closed_form_kirchhoff_equals_energy_derivative(c1: float, c2: float) -> None:
    rng = np.random.default_rng(1)
    mat = MooneyRivlin(c1, c2)
    for _ in range(5):
        F = _random_F(rng)
        p, Js = rng.normal(scale=10.0), 1.0 + rng.random()
        P, _ = _energy_gradient(mat, F, p, Js)
        tau_energy = P @ F.T
        tau_closed = mat.kirchhoff_stress(F, p)
        np.testing.assert_allclose(tau_closed, tau_energy, rtol=1e-9, atol=1e-9 * (c1 + c2))


def test_pressure_sign_convention() -> None:
    """With ``+p (J - Js)`` in the energy, ``p`` is tension-positive: at ``Fbar = I`` the
    stress is ``tau = J p I``, so the reported pressure ``-tr(sigma)/3`` equals ``-p``."""
    mat = MooneyRivlin(0.28, 333.0)
    F = 1.1 * np.eye(3)
    tau = mat.kirchhoff_stress(F, p=-5.0)
    J = 1.1**3
    np.testing.assert_allclose(tau, J * -5.0 * np.eye(3), atol=1e-10)
    sigma = tau / J
    assert -np.trace(sigma) / 3 == pytest.approx(5.0)  # compression positive


def test_numpy_energy_matches_ngsolve_energy() -> None:
    rng = np.random.default_rng(2)
    for mat in (MooneyRivlin(0.3, 2.0), Ogden(c=(1.0, 0.5), alpha=(3.0, -1.5))):
        for _ in range(3):
            F = _random_F(rng)
            _, psi_ng = _energy_gradient(mat, F, 0.0, 1.0)
            assert mat.psi_iso_numpy(F) == pytest.approx(psi_ng, rel=1e-8, abs=1e-10)


def test_ogden_reduces_to_mooney_rivlin() -> None:
    """``MR(c1, c2) = Ogden(c = (c1, -c2), alpha = (2, -2))``: same energy, same stress."""
    c1, c2 = 0.28, 3.33
    mr = MooneyRivlin(c1, c2)
    og = Ogden(c=(c1, -c2), alpha=(2.0, -2.0))
    assert og.shear_modulus == pytest.approx(mr.shear_modulus)
    rng = np.random.default_rng(3)
    for _ in range(3):
        F = _random_F(rng)
        P_mr, psi_mr = _energy_gradient(mr, F, 1.0, 1.1)
        P_og, psi_og = _energy_gradient(og, F, 1.0, 1.1)
        assert psi_og == pytest.approx(psi_mr, rel=1e-8)
        np.testing.assert_allclose(P_og, P_mr, rtol=1e-6, atol=1e-6)


def test_neo_hookean_is_c2_zero() -> None:
    nh = neo_hookean(2.0)
    assert nh.c2 == 0 and nh.shear_modulus == 2.0


@pytest.mark.parametrize(
    "make",
    [
        lambda: MooneyRivlin(-1.0, 0.5),
        lambda: MooneyRivlin(0.0, 0.0),
        lambda: MooneyRivlin(math.nan, 1.0),
        lambda: MooneyRivlin(1.0, math.inf),
        lambda: Ogden(c=(1.0,), alpha=(0.0,)),
        lambda: Ogden(c=(1.0, 2.0), alpha=(2.0,)),
        lambda: Ogden(c=(-1.0,), alpha=(2.0,)),
        lambda: preset("nonsense"),
    ],
)
def test_bad_parameters_are_rejected_with_one_line(make) -> None:
    with pytest.raises(InputError) as err:
        make()
    assert "\n" not in str(err.value)


def test_presets() -> None:
    paper, pa = preset("paper"), preset("paper-pa")
    assert paper["white"].shear_modulus == pytest.approx(666.56)
    assert pa["gray"].c2 == pytest.approx(paper["gray"].c2 / 1000)
    for name in ("gray", "white", "cerebellum", "csf"):
        assert paper[name].c2 / paper[name].c1 == pytest.approx(1190, rel=0.08)
