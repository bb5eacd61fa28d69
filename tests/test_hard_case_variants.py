"""The hard-case benchmark's contact variants: their gaps are distances with exact gradients."""

import math

import numpy as np

from bench_hard_cases import region_gap
from edge_contact import segment_gap, smooth_gap, smooth_gap_gradient


def test_region_gap_is_the_distance_to_the_skull_region_with_its_gradient():
    """``S = {r >= 1, |delta| >= 15 deg}`` about the vertical: ``g = 1 - r`` under the arc,
    the distance to the edge point just past it, minus the distance to the edge's ray
    inside ``S``; ``grad g`` matches central differences away from the edge."""
    R, beta, centre = 1.0, 30.0, 90.0
    edge = np.array([math.cos(math.radians(75)), math.sin(math.radians(75))])
    pts = np.array([
        [math.cos(math.radians(60)) * 0.9, math.sin(math.radians(60)) * 0.9],  # under the arc
        0.98 * np.array([math.cos(math.radians(80)), math.sin(math.radians(80))]),  # past it
        1.1 * np.array([math.cos(math.radians(70)), math.sin(math.radians(70))]),  # inside S
    ])
    g, n = region_gap(R, beta, centre, pts)
    assert math.isclose(g[0], 0.1, rel_tol=1e-12)
    assert math.isclose(g[1], float(np.linalg.norm(pts[1] - edge)), rel_tol=1e-12)
    assert math.isclose(g[2], -1.1 * math.sin(math.radians(5)), rel_tol=1e-12)
    eps = 1e-7
    for k in range(2):
        e = np.zeros(2)
        e[k] = eps
        fd = (region_gap(R, beta, centre, pts + e)[0] - region_gap(R, beta, centre, pts - e)[0])
        np.testing.assert_allclose(fd / (2 * eps), n[:, k], atol=1e-6)


def test_segment_gap_is_signed_and_its_gradient_exact():
    """The edge point's distance from a segment's line is positive on the right of a -> b
    (outside the tissue on its left), and its gradient in (a, b) matches central
    differences."""
    C = np.array([0.3, -0.2])
    a, b = np.array([0.0, 0.0]), np.array([1.0, 0.1])
    g, grad = segment_gap(C, a, b)
    assert g > 0
    assert segment_gap(np.array([0.3, 0.5]), a, b)[0] < 0
    eps = 1e-7
    z = np.concatenate([a, b])
    for j in range(4):
        e = np.zeros(4)
        e[j] = eps
        fd = (segment_gap(C, *np.split(z + e, 2))[0] - segment_gap(C, *np.split(z - e, 2))[0])
        assert abs(fd / (2 * eps) - grad[j]) < 1e-6


def test_smooth_gap_gradient_is_exact_and_the_gap_continuous_across_a_vertex():
    """The interpolated-normal gap's exact gradient (implicit in the projection) matches
    central differences, and the gap of a point over a boundary vertex is the same from the
    two segments that share it (a C1 boundary)."""
    C = np.array([0.45, 1.02])
    z = np.array([0.2, 0.97, 0.4, 0.98, 0.6, 0.95, 0.8, 0.88])
    grad = smooth_gap_gradient(C, z)
    fd = np.array([(smooth_gap(C, z + e) - smooth_gap(C, z - e)) / 2e-6
                   for e in np.eye(8) * 1e-6])
    np.testing.assert_allclose(grad, fd, atol=1e-8)
    # points swept over the vertex (0.6, 0.95) at 0.03 from it: each projects onto one of
    # the two segments that share it, and the gap varies continuously from one to the other
    v, second = np.array([0.6, 0.95]), np.concatenate([z[2:], [1.0, 0.75]])
    gaps = []
    for angle in np.linspace(-0.3, 0.3, 61):
        point = v + 0.03 * np.array([np.sin(angle), np.cos(angle)])
        found = [g for g in (smooth_gap(point, z), smooth_gap(point, second)) if g is not None]
        assert found, angle
        gaps.append(found[0])
    assert np.max(np.abs(np.diff(gaps))) < 2e-4


def _full_gradients(C, nodes, blend):
    """The gap's gradient over all five ``nodes`` from each segment ``C`` projects onto."""
    out = []
    for first in (0, 1):
        z = nodes[first:first + 4].ravel()
        grad = smooth_gap_gradient(C, z, blend)
        if grad is not None:
            full = np.zeros(10)
            full[2 * first:2 * first + 8] = grad
            out.append(full)
    return out


def test_vertex_blend_makes_the_gap_gradient_continuous_over_a_vertex():
    """Within ``blend`` of a vertex the gap turns into the vertex gap ``(C - x_v) . N_v``:
    its exact gradient matches central differences, and for points swept over the vertex
    the gradient with respect to all nodes varies continuously, where without the blend it
    jumps between the vertex's two segments."""
    nodes = np.array([[0.2, 0.97], [0.4, 0.98], [0.6, 0.95], [0.8, 0.88], [1.0, 0.75]])
    z = nodes[0:4].ravel()
    C = np.array([0.59, 0.955])  # near the vertex (0.6, 0.95), inside the blend
    grad = smooth_gap_gradient(C, z, 0.2)
    fd = np.array([(smooth_gap(C, z + e, 0.2) - smooth_gap(C, z - e, 0.2)) / 2e-6
                   for e in np.eye(8) * 1e-6])
    np.testing.assert_allclose(grad, fd, atol=1e-8)
    jumps = {}
    for blend in (0.0, 0.2):
        grads = []
        for dx in np.linspace(-0.004, 0.004, 41):
            found = _full_gradients(nodes[2] + np.array([dx, 0.01]), nodes, blend)
            assert found, dx
            grads.append(found[0])
        jumps[blend] = np.max(np.linalg.norm(np.diff(grads, axis=0), axis=1))
    assert jumps[0.0] > 0.1  # the unblended gradient jumps at the vertex
    assert jumps[0.2] < 0.02  # steps of 2e-4 in position: a continuous gradient


def test_offset_mesh_has_no_vertex_at_the_edge_and_the_edge_starts_outside_the_tissue():
    """The ``-offset`` meshes move the opening's break points half a corner element into the
    opening: the default mesh has a boundary vertex at each skull edge, the offset one none
    within a third of a corner element, and each edge point starts outside the tissue (its
    gap to the C1 boundary at rest is positive: the chord of the segment under it lies
    inside the circle)."""
    import ngsolve as ngs

    from bench_hard_cases import edge_points, offset_mesh
    from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem
    from brainbulge.solver.mixed import MixedForm
    from edge_contact import SmoothEdgeContact

    case = HemidiskCase(alpha=80.0, beta=60.0, contact="sliding", skull_edge_radius=0.0,
                        full_domain=True)
    edges = edge_points(case.R, case.beta, case.opening_center)

    def nearest(mesh):
        names = mesh.GetBoundaries()
        on = {v.nr for el in mesh.Elements(ngs.BND) if names[el.index] in ("skull", "opening")
              for v in el.vertices}
        X = np.array([mesh.vertices[v].point for v in sorted(on)])
        return min(np.linalg.norm(X - e, axis=1).min() for e in edges)

    assert nearest(case.mesh()) < 1e-9
    mesh = offset_mesh(case)
    assert nearest(mesh) > case.corner_h / 3
    form = MixedForm(hemidisk_problem(case, mesh), element=case.element)
    edge = SmoothEdgeContact(form, "skull|opening", edges)
    assert np.all(edge.g > 0)


def test_opened_skull_gap_is_the_distance_to_the_opened_region():
    """``S`` opened by a disk of radius ``rho``: ``g = 1 - r`` under the arc, the distance
    to the nominal edge's ray (end face) in the opening above ``R + rho``, and the rounded
    corner's distance (centre at ``rho`` from both); ``grad g`` matches central differences."""
    from edge2d_geometry import OpenedSkull

    rho, half = 0.03, math.radians(30)
    skull = OpenedSkull(1.0, 60.0, rho)
    e = np.array([math.cos(half), math.sin(half)])  # the edge's ray in the opening's frame
    m = np.array([-math.sin(half), math.cos(half)])
    c = math.sqrt((1 + rho) ** 2 - rho**2) * e + rho * m  # the rounding's centre

    def mesh_frame(p: np.ndarray) -> np.ndarray:  # the opening's centre is on +y
        return np.array([-p[1], p[0]])

    under = 0.9 * np.array([math.cos(math.radians(50)), math.sin(math.radians(50))])
    face = 1.3 * e - 0.05 * m  # in the opening, 0.05 from the end face
    corner = c - 0.02 * (m + e) / math.sqrt(2)  # inside the rounding's quarter, 0.02 off it
    pts = np.array([mesh_frame(under), mesh_frame(face), mesh_frame(corner)])
    g, n = skull.gap_and_normal(pts)
    assert math.isclose(g[0], 0.1, rel_tol=1e-12)
    assert math.isclose(g[1], 0.05, rel_tol=1e-12)
    assert math.isclose(g[2], 0.02 - rho, abs_tol=1e-12)  # negative: inside the bone
    rng = np.random.default_rng(1)
    x = np.array([-0.5, 0.87]) + 0.15 * rng.standard_normal((200, 2))
    _, n = skull.gap_and_normal(x)
    eps = 1e-7
    for k in range(2):
        d = np.zeros(2)
        d[k] = eps
        fd = skull.gap_and_normal(x + d)[0] - skull.gap_and_normal(x - d)[0]
        np.testing.assert_allclose(fd / (2 * eps), n[:, k], atol=1e-5)
