"""The flap's opening on the skull's inner surface is the nominal flap, whatever the rounding.

A spherical skull (inner radius R = 80 mm) with a 120 mm flap: the nominal opening is the
spherical cap inside the cutting cylinder of radius a = 60 mm, of area ``2 pi R (R -
sqrt(R^2 - a^2))`` = 136 cm^2. The effective opening is the part of the inner surface where the
skull with the flap lies farther than the intact skull (by more than 0.01 mm), measured by
sampling the sphere at equal-area points (uniform in z and in longitude). The rounding of the
cut edge lies in the bone, so the opening stays nominal for edge radii 2-8 mm (a rounding
made by eroding and dilating the cutter grew it by ~50 % at 8 mm).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from brainbulge.geometry.brain import RigidSkull
from brainbulge.geometry.brain.boundaries import Flap
from brainbulge.geometry.brain.brain_mesh import FREE_GAP_MM
from brainbulge.geometry.brain.envelope import IntracranialEnvelope
from brainbulge.geometry.sphere_skull import SphericalSkull

R_MM = 80.0
FLAP_RADIUS_MM = 60.0
NOMINAL_MM2 = 2 * math.pi * R_MM * (R_MM - math.sqrt(R_MM**2 - FLAP_RADIUS_MM**2))


@pytest.fixture(scope="module")
def sphere_envelope() -> IntracranialEnvelope:
    spacing = 2.0
    g = np.arange(-110.0, 110.0 + spacing, spacing)
    X = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1)
    affine = np.diag([spacing, spacing, spacing, 1.0])
    affine[:3, 3] = g[0]
    return IntracranialEnvelope((np.linalg.norm(X, axis=-1) - R_MM).astype(np.float32), affine)


def equal_area_sphere_points(n: int = 400_000, seed: int = 0) -> np.ndarray:
    """Random points on ``|x| = R``, uniform in area (Archimedes: uniform in z)."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(-R_MM, R_MM, n)
    lon = rng.uniform(0, 2 * math.pi, n)
    s = np.sqrt(R_MM**2 - z**2)
    return np.stack([s * np.cos(lon), s * np.sin(lon), z], axis=1)


@pytest.mark.parametrize("edge_radius_mm", [2.0, 4.0, 8.0])
def test_the_opening_on_a_sphere_skull_is_the_nominal_flap(sphere_envelope,
                                                           edge_radius_mm) -> None:
    flap = Flap("cap", (0.0, 0.0, R_MM), (0.0, 0.0, 1.0), FLAP_RADIUS_MM)
    skull = RigidSkull(sphere_envelope, flap, edge_radius_mm)
    x = equal_area_sphere_points()
    phi_env, _ = skull.envelope_distance(x, gradient=False)
    phi, _ = skull.signed_distance(x, gradient=False)
    free = phi_env - phi > FREE_GAP_MM
    opening_mm2 = free.mean() * 4 * math.pi * R_MM**2
    assert opening_mm2 == pytest.approx(NOMINAL_MM2, rel=0.02)
    # outside the cutter the skull is the intact one (to round-off)
    outside = flap.cutter_distance(x)[0] > 0
    assert np.abs(phi[outside] - phi_env[outside]).max() < 1e-12
    # the analytic spherical skull, rounded the same way, has the same opening
    sphere = SphericalSkull(R=R_MM, cap_deg=math.degrees(math.asin(FLAP_RADIUS_MM / R_MM)),
                            thickness=30.0, edge_radius=edge_radius_mm)
    analytic = sphere.gap_and_normal(x)[0] > FREE_GAP_MM
    assert analytic.mean() * 4 * math.pi * R_MM**2 == pytest.approx(NOMINAL_MM2, rel=0.02)


def test_the_rounding_curves_outward_from_the_rim(sphere_envelope) -> None:
    """On the inner surface inside the rim the gap is the torus's, ``sqrt(r^2 + s^2) - r``
    with ``s`` the distance into the cutter; the opening's middle is far from any skull."""
    r = 8.0
    flap = Flap("cap", (0.0, 0.0, R_MM), (0.0, 0.0, 1.0), FLAP_RADIUS_MM)
    skull = RigidSkull(sphere_envelope, flap, r)
    s = np.array([0.5, 2.0, 5.0])
    radius = FLAP_RADIUS_MM - s
    x = np.stack([radius, 0 * s, np.sqrt(R_MM**2 - radius**2)], axis=1)
    gap = -skull.signed_distance(x, gradient=False)[0]
    assert gap == pytest.approx(np.sqrt(r**2 + s**2) - r, abs=0.05)
    assert -skull.signed_distance(np.array([[0.0, 0.0, R_MM]]))[0][0] > 20.0


def test_every_skull_of_an_envelope_shares_its_spline_and_a_pickle_makes_it_again(
        sphere_envelope, monkeypatch) -> None:
    """The spline filter (~0.7 s on the template) runs once per envelope, however many
    skulls (flaps) use it, and again after a pickle (the coefficients are not shipped to a
    worker): the same distances."""
    import pickle

    import scipy.ndimage as ndi

    filtered = []
    spline_filter = ndi.spline_filter
    monkeypatch.setattr(ndi, "spline_filter",
                        lambda *a, **k: filtered.append(1) or spline_filter(*a, **k))
    flap = Flap("cap", (0.0, 0.0, R_MM), (0.0, 0.0, 1.0), FLAP_RADIUS_MM)
    copy = pickle.loads(pickle.dumps(sphere_envelope))
    intact, flapped = RigidSkull(copy, None), RigidSkull(copy, flap)
    x = equal_area_sphere_points(1000) * 0.9  # inside, 8 mm from the sphere
    flapped.signed_distance(x)
    phi, grad = intact.envelope_distance(x)
    assert len(filtered) == 1  # made again after the pickle, once for both skulls
    phi0, grad0 = RigidSkull(sphere_envelope, None).envelope_distance(x)
    assert np.array_equal(phi, phi0) and np.array_equal(grad, grad0)
    assert phi == pytest.approx(-0.1 * R_MM, abs=0.05)  # the distance to the sphere


def test_the_cut_ends_halfway_between_the_opening_and_other_skull_in_its_cylinder() -> None:
    """A skull that curves back into the cutting cylinder within its depth (the middle
    cranial fossa under a fronto-temporo-parietal flap) is not cut: the cut ends halfway
    between the opening's deepest node (30 mm) and that skull's shallowest (50 mm)."""
    from brainbulge.geometry.brain.boundaries import clear_of_other_skull

    flap = Flap("side", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), FLAP_RADIUS_MM)  # cut 60 mm deep
    angle = np.linspace(0, 2 * math.pi, 12, endpoint=False)
    ring = np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], axis=1)
    opening = np.vstack([ring * r + np.array([0, 0, -d])
                         for d, r in ((0.0, 5.0), (15.0, 40.0), (30.0, 59.0))])
    fossa = ring * 58.0 + np.array([0.0, 0.0, -50.0])
    assert flap.contains(fossa).all()  # the cylinder 60 mm deep opens it
    cleared = clear_of_other_skull(flap, opening, fossa)
    assert cleared.depth_mm == pytest.approx(40.0)
    assert not cleared.contains(fossa).any()
    assert cleared.contains(opening).all()
    # other skull beyond the depth or outside the cylinder: the flap stays as it is
    for other in (ring * 58.0 + np.array([0, 0, -70.0]), ring * 61.0 + np.array([0, 0, -50.0])):
        assert clear_of_other_skull(flap, opening, other) is flap


def test_the_cutters_smooth_inside_distance_has_no_crease_at_its_edges() -> None:
    """Inside the cutter, near the edge where its wall meets its floor, ``max`` of the two
    distances turns its gradient by 90 degrees across the bisector (where the skull's normal
    creased and Newton stagnated at a pressed contact point); the smooth inside distance
    keeps the zero level and the faces' gradients and matches its finite differences."""
    flap = Flap("low", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), FLAP_RADIUS_MM, floor_z_mm=-500.0,
                depth_mm=40.0)
    # on the bisector of the wall (radius 60) and the floor (40 mm deep), 2.4 mm inside both
    on = np.array([[FLAP_RADIUS_MM - 2.4, 0.0, -40.0 + 2.4]])
    h = 1e-4
    across = np.array([[h, 0.0, h]])  # across the bisector
    crease = flap.cutter_distance(on + across)[1] - flap.cutter_distance(on - across)[1]
    assert np.linalg.norm(crease) > 1.0  # max(w): the gradient jumps
    phi, grad = flap.cutter_distance(on, smooth_inside=True)
    jump = (flap.cutter_distance(on + across, smooth_inside=True)[1]
            - flap.cutter_distance(on - across, smooth_inside=True)[1])
    assert np.linalg.norm(jump) < 1e-3
    fd = np.array([(flap.cutter_distance(on + h * e, smooth_inside=True)[0]
                    - flap.cutter_distance(on - h * e, smooth_inside=True)[0])[0] / (2 * h)
                   for e in np.eye(3)])
    np.testing.assert_allclose(grad[0], fd, atol=1e-6)
    assert phi[0] == pytest.approx(-2.4 * 2 ** -0.25, rel=1e-9)
    # the same level zero and the same distance near one face
    x = np.array([[30.0, 0.0, -10.0], [59.0, 0.0, -10.0], [61.0, 0.0, -10.0], [0, 0, -39.0]])
    plain, smooth = flap.cutter_distance(x), flap.cutter_distance(x, smooth_inside=True)
    np.testing.assert_array_equal(plain[0] < 0, smooth[0] < 0)
    np.testing.assert_allclose(smooth[0][1:], plain[0][1:], rtol=1e-3)
    np.testing.assert_allclose(smooth[1][1:], plain[1][1:], atol=1e-3)
