"""The swelling-disk case as the paper's Figure 1B sets it up: the opening inclined off the
symmetry axis, five disks at different places relative to it."""

from __future__ import annotations

import math

import ngsolve as ngs
import numpy as np
import pytest

from brainbulge.studies.hemidisk import case_from_dict, disk_scenarios


def _boundary_angles(mesh: ngs.Mesh, name: str) -> np.ndarray:
    """Polar angles [deg] of the vertices of boundary ``name``."""
    names = mesh.GetBoundaries()
    nrs = np.unique([v.nr for el in mesh.Elements(ngs.BND) if names[el.index] == name
                     for v in el.vertices])
    pts = np.array([mesh.vertices[n].point for n in nrs])
    return np.degrees(np.arctan2(pts[:, 1], pts[:, 0]))


@pytest.fixture(scope="module")
def cases():
    return [case_from_dict({k: v for k, v in sc.items() if k != "name"})
            for sc in disk_scenarios(mesh_size=0.1)]


def test_the_opening_is_inclined_off_the_axis(cases) -> None:
    mesh = cases[0].mesh()
    opening = _boundary_angles(mesh, "opening")
    lo, hi = opening.min(), opening.max()
    assert hi - lo == pytest.approx(cases[0].beta, abs=1e-6)
    centre = (lo + hi) / 2
    assert abs(centre - 90.0) >= 15.0  # off the symmetry axis, by a visible angle
    skull = _boundary_angles(mesh, "skull")
    # the skull covers the rest of the curve, on both sides of the opening
    assert skull.min() == pytest.approx(0.0, abs=1e-6)
    assert skull.max() == pytest.approx(180.0, abs=1e-6)
    assert not np.any((skull > lo + 1e-6) & (skull < hi - 1e-6))
    assert all(c.opening_center == cases[0].opening_center for c in cases)


def test_five_disks_at_different_places_relative_to_the_opening(cases) -> None:
    lo, hi = cases[0].geometry.opening_angles_deg
    angles = [math.degrees(math.atan2(c.disk[1], c.disk[0])) for c in cases]
    assert len(cases) == 5 and len(set(np.round(angles, 6))) == 5
    under_opening = [lo - 1e-9 <= a <= hi + 1e-9 for a in angles]
    assert any(under_opening) and not all(under_opening)  # under the opening and the skull
    for c in cases:
        assert c.contact == "sliding" and c.swelling == pytest.approx(1.3)
        mesh = c.mesh()
        area = ngs.Integrate(mesh.MaterialCF({"swelling": 1.0}, default=0.0), mesh)
        assert area == pytest.approx(math.pi * c.disk[2] ** 2, rel=0.02)
