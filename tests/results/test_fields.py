"""Output fields of docs/model.md section 3 on deformations with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from brainbulge.results.measures.fields import (
    det3,
    largest_eigenvalue,
    max_principal_strain,
    output_fields,
    radial_directions,
    right_cauchy_green,
    sample,
    stretch_along,
    tangential_stretch,
)


def test_stretches_of_a_rotated_stretch() -> None:
    """F = Q diag(a, b, c): C = diag(a^2, b^2, c^2) whatever the rotation Q."""
    a, b, c = 1.3, 0.8, 1.1
    th = 0.7
    Q = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])
    F = (Q @ np.diag([a, b, c]))[None]
    C = F.transpose(0, 2, 1) @ F
    n = np.array([[1.0, 0.0, 0.0]])
    assert stretch_along(C, n)[0] == pytest.approx(a)
    assert tangential_stretch(C, n, dim=3)[0] == pytest.approx(max(b, c))  # largest in plane
    assert tangential_stretch(C, n, dim=2)[0] == pytest.approx(b)  # in-plane perpendicular
    assert max_principal_strain(C)[0] == pytest.approx(0.5 * (a**2 - 1))


@pytest.mark.parametrize("spectrum", ["random", "double-top", "double-bottom", "triple", "zero"])
def test_largest_eigenvalue_matches_lapack(spectrum: str) -> None:
    """The closed form against ``numpy.linalg.eigvalsh`` on rotated spectra, including
    (nearly) repeated eigenvalues, where ``acos`` is least accurate."""
    rng = np.random.default_rng(1)
    n = 2000
    lam = {"random": rng.uniform(-2.0, 3.0, (n, 3)),
           "double-top": np.array([0.7, 1.2, 1.2 + 1e-12]) * np.ones((n, 1)),
           "double-bottom": np.array([0.9, 0.9, 1.4]) * np.ones((n, 1)),
           "triple": np.full((n, 3), 1.1),
           "zero": np.zeros((n, 3))}[spectrum]
    Q = np.linalg.qr(rng.standard_normal((n, 3, 3)))[0]
    A = Q @ (lam[:, :, None] * np.swapaxes(Q, 1, 2))
    A = 0.5 * (A + np.swapaxes(A, 1, 2))
    expected = np.linalg.eigvalsh(A)[:, -1]
    assert np.abs(largest_eigenvalue(A) - expected).max() <= 1e-7 * max(1.0, np.abs(lam).max())


def test_determinant_and_cauchy_green_match_numpy() -> None:
    F = np.eye(3) + 0.4 * np.random.default_rng(3).standard_normal((1000, 3, 3))
    F[0] = np.diag([2.0, 0.5, 1e-9])  # nearly singular
    assert np.allclose(det3(F), np.linalg.det(F), rtol=1e-12, atol=1e-14)
    assert np.allclose(right_cauchy_green(F), np.swapaxes(F, 1, 2) @ F, rtol=1e-14, atol=1e-14)
    assert not np.allclose(right_cauchy_green(F), F @ np.swapaxes(F, 1, 2))  # not F F^T


def test_tangential_stretch_3d_oblique_direction() -> None:
    rng = np.random.default_rng(0)
    F = np.eye(3) + 0.3 * rng.standard_normal((3, 3))
    C = (F.T @ F)[None]
    n = np.array([[1.0, 2.0, 2.0]]) / 3.0
    # brute force: maximise |F t| over unit t perpendicular to n
    e1 = np.cross(n[0], [1.0, 0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n[0], e1)
    ts = [np.cos(p) * e1 + np.sin(p) * e2 for p in np.linspace(0, np.pi, 20001)]
    brute = max(np.linalg.norm(F @ t) for t in ts)
    assert tangential_stretch(C, n, dim=3)[0] == pytest.approx(brute, rel=1e-7)


def test_radial_directions() -> None:
    X = np.array([[3.0, 4.0], [0.0, 0.0]])
    n = radial_directions(X, np.zeros(2))
    np.testing.assert_allclose(n, [[0.6, 0.8, 0.0], [0.0, 0.0, 0.0]])


def test_summary_is_the_same_when_evaluated_in_chunks(monkeypatch) -> None:
    """The summary evaluates the fields a chunk of integration points at a time (memory of
    the 1.54M-tet brain); chunks of any size give the same extremes, locations and integrals."""
    import brainbulge.results.measures.summary as summary
    from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem
    from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions

    case = HemidiskCase(alpha=80, beta=60, swelling=1.2, contact="noslip", mesh_size=0.1,
                        skull_edge_radius=0.0)
    geo = case.geometry
    solver = NewtonSolver(MixedForm(hemidisk_problem(case)), SolverOptions(steps=2))
    sol = solver.solve()
    assert sol.converged

    def run() -> dict:
        return summary.solution_summary(sol, np.zeros(2), geo.singular_points(), 0.05)

    whole = run()
    monkeypatch.setattr(summary, "CHUNK", 97)  # uneven: the last chunk is short
    chunked = run()
    assert len(sol.form.mesh.ngmesh.Elements2D()) * 6 > 10 * 97  # several chunks
    for key in ("max_radial_stretch", "min_tangential_stretch", "max_principal_strain",
                "raw_max_radial_stretch", "max_displacement", "integral_J_minus_Js",
                "p95_radial_stretch", "p05_tangential_stretch", "p99_principal_strain",
                "swelling_volume", "max_abs_J_minus_Js", "argmax_radial_stretch",
                "median_abs_Je_minus_1", "p95_abs_Je_minus_1"):
        assert chunked[key] == pytest.approx(whole[key], rel=1e-12, abs=1e-15), key
    assert chunked["abs_Je_minus_1_by_region"] == whole["abs_Je_minus_1_by_region"]


def test_tissue_summary_reads_the_fields_one_copy_at_a_time(monkeypatch) -> None:
    """With ``tissue``, the extremes and percentiles of the tissue's and the CSF's points
    are taken from fields cut out one at a time (:class:`Selected`), not from copies of
    all fields at once: the same numbers as the copies give. The swelling target is one
    array for ``Js`` and ``fields["Js"]``."""
    import brainbulge.results.measures.summary as summary
    from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem
    from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions

    case = HemidiskCase(alpha=80, beta=60, swelling=1.2, contact="noslip", mesh_size=0.1)
    solver = NewtonSolver(MixedForm(hemidisk_problem(case)), SolverOptions(steps=2))
    sol = solver.solve()
    assert sol.converged
    points = summary.point_fields(sol.form, np.zeros(2))
    assert points.Js is points.fields["Js"]
    tissue = sorted(set(sol.form.mesh.GetMaterials()))[0]
    sel = points.in_regions(tissue)
    assert 0 < sel.sum() < len(sel)
    cut = summary.Selected(points.fields, sel)
    assert set(cut) == set(points.fields) and len(cut) == len(points.fields)
    assert "J" in cut and "no-such-field" not in cut
    for k, v in points.fields.items():
        assert np.array_equal(cut[k], v[sel]), k

    def run() -> dict:
        return summary.solution_summary(sol, np.zeros(2), case.geometry.singular_points(),
                                        0.05, tissue=tissue, points=points, peak_volume=1e-3)

    lazy = run()
    monkeypatch.setattr(summary, "Selected", lambda f, s: {k: v[s] for k, v in f.items()})
    copied = run()
    assert any(k.startswith("p95_csf_") for k in lazy)
    assert lazy == copied


def test_points_know_their_region() -> None:
    """Each sampled point's region (kept instead of NGSolve's point array) is the region
    of the element NGSolve maps it into."""
    from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem
    from brainbulge.results.measures.quadrature import quadrature_points
    from brainbulge.results.measures.summary import point_fields
    from brainbulge.solver import MixedForm

    case = HemidiskCase(alpha=80, beta=60, swelling=1.2, mesh_size=0.1, skull_edge_radius=0.0)
    form = MixedForm(hemidisk_problem(case))
    mesh = form.mesh
    regions = sorted(set(mesh.GetMaterials()))
    assert len(regions) > 1
    points = point_fields(form, np.zeros(2))
    assert points.q.points is None
    q = quadrature_points(mesh, order=4)
    assert np.array_equal(points.X, q.X)
    for r in regions:
        expected = q(mesh.MaterialCF({r: 1.0}, default=0.0)) > 0.5
        assert expected.any()
        assert np.array_equal(points.in_regions(r), expected), r
    assert not points.in_regions("no-such-region").any()
    assert points.in_regions("|".join(regions)).all()


def test_argmax_locations_carry_their_maxima_outside_the_exclusion_disks() -> None:
    """Each ``argmax_*`` is where its ``max_*`` is: the field evaluated afresh at that point
    gives the reported maximum, and the point lies outside every edge-exclusion disk."""
    from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem
    from brainbulge.results.measures.recovery import recovered_gradient
    from brainbulge.results.measures.summary import solution_summary
    from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions

    case = HemidiskCase(alpha=80, beta=60, swelling=1.2, contact="noslip", mesh_size=0.2,
                        skull_edge_radius=0.0)
    corners = case.geometry.singular_points()
    form = MixedForm(hemidisk_problem(case))
    solver = NewtonSolver(form, SolverOptions(steps=2))
    sol = solver.solve()
    assert sol.converged
    s = solution_summary(sol, np.zeros(2), corners, case.edge_exclusion)
    G = recovered_gradient(form.mesh, form.output_displacement())  # as the summary's
    for stem, field in (("radial_stretch", "lambda_n"), ("tangential_stretch", "lambda_t"),
                        ("principal_strain", "max_principal_strain")):
        X = np.array(s[f"argmax_{stem}"])
        assert min(np.linalg.norm(X - np.array(c)) for c in corners) > case.edge_exclusion
        value = output_fields(sample(form, form.mesh(*X), gradient=G), np.zeros(2))[field]
        assert float(np.ravel(value)[0]) == pytest.approx(s[f"max_{stem}"], rel=1e-9), stem
        assert s[f"max_{stem}"] < s[f"raw_max_{stem}"]  # the excluded corners peak higher


def test_volume_percentiles_converge_where_a_singular_maximum_does_not() -> None:
    """``f = r^(-1/2)`` on the unit disk, the order of a corner singularity: the area fraction
    with ``f <= v`` is ``1 - v^-4``, so the 95th area percentile is ``0.05^(-1/4) = 2.1147``,
    the 99th ``3.1623`` and the 5th ``0.95^(-1/4) = 1.0129``. ``field_percentiles`` over the
    quadrature points of two meshes (a vertex at the singular point) gives them within the
    quadrature error, while the largest value grows as ``h^(-1/2)``; the points are weighted
    by their areas (unweighted, the percentile is off by ~4 %)."""
    import ngsolve as ngs
    from netgen.geom2d import SplineGeometry

    from brainbulge.results.measures.quadrature import quadrature_points
    from brainbulge.results.measures.summary import field_percentiles

    results = []
    for h in (0.1, 0.05):
        geo = SplineGeometry()
        geo.AddCircle((0, 0), 1, bc="outer")
        geo.AddPoint(0, 0, maxh=h)  # a mesh vertex at the singular point, as at a corner
        mesh = ngs.Mesh(geo.GenerateMesh(maxh=h))
        mesh.Curve(4)
        q = quadrature_points(mesh, order=4)
        f = np.hypot(q.X[:, 0], q.X[:, 1]) ** -0.5
        fields = {"lambda_n": f, "lambda_t": f, "max_principal_strain": f}
        keep = np.ones(len(f), dtype=bool)
        p = field_percentiles(fields, q.weights, keep)
        assert q.weights.sum() == pytest.approx(np.pi, rel=1e-6)
        assert p["p95_radial_stretch"] == pytest.approx(0.05**-0.25, rel=3e-3)
        assert p["p99_radial_stretch"] == pytest.approx(0.01**-0.25, rel=1e-2)
        assert p["p05_tangential_stretch"] == pytest.approx(0.95**-0.25, rel=5e-3)
        assert p["p95_principal_strain"] == p["p95_radial_stretch"]
        assert np.percentile(f, 95) < 0.98 * 0.05**-0.25  # unweighted: off
        results.append((f.max(), p["p95_radial_stretch"]))
    (max_coarse, p95_coarse), (max_fine, p95_fine) = results
    assert max_fine > 1.3 * max_coarse
    assert p95_fine == pytest.approx(p95_coarse, rel=3e-3)
    # a selection: only the points kept count
    half = q.X[:, 0] > 0
    assert field_percentiles(fields, q.weights, half)["p95_radial_stretch"] == pytest.approx(
        0.05**-0.25, rel=3e-3)
    assert field_percentiles(fields, q.weights, np.zeros(len(f), dtype=bool)) == {}


@pytest.mark.parametrize("n", [50, 5_000, 200_000])
def test_weighted_percentiles_sort_only_the_tail_and_match_numpy(n: int) -> None:
    """The tail selection gives numpy's weighted inverted-cdf percentiles exactly, with
    graded weights, ties and values concentrated in the tail."""
    from brainbulge.results.measures.summary import weighted_percentiles

    rng = np.random.default_rng(n)
    for v, w in (
        (rng.normal(size=n), rng.uniform(0.1, 1, n)),
        (np.round(rng.normal(size=n), 1), rng.uniform(0, 1, n) ** 4),  # ties, graded weights
        (np.where(rng.uniform(size=n) < 0.97, 1.0, rng.uniform(1, 5, n)), np.ones(n)),
        (rng.uniform(size=n), np.where(rng.uniform(size=n) < 0.01, 100.0, 0.01)),  # heavy few
    ):
        for qs in ((95, 99), (5, 1), (50,)):
            expected = np.percentile(v, qs, weights=w, method="inverted_cdf")
            np.testing.assert_array_equal(weighted_percentiles(v, w, qs), expected)
    with pytest.raises(ValueError, match="all be"):
        weighted_percentiles(v, w, (5, 95))


@pytest.mark.parametrize("n", [7, 5_000, 200_000])
def test_the_value_exceeded_in_a_volume(n: int) -> None:
    """``exceeded_in``: the largest ``t`` whose super-level set ``{v >= t}`` holds the
    volume, against a full sort; on a field uniform over a unit volume it is the quantile."""
    from brainbulge.results.measures.summary import exceeded_in

    rng = np.random.default_rng(n)
    v, w = np.round(rng.normal(size=n), 2), rng.uniform(0, 1, n) ** 3  # ties, graded
    for volume in (1e-9, 0.3, 0.1 * w.sum(), w.sum(), 2 * w.sum()):
        order = np.argsort(v)[::-1]
        above = np.cumsum(w[order])
        expected = v[order][min(np.searchsorted(above, volume), n - 1)]
        got = exceeded_in(v, w, volume)
        assert got == expected
        if volume <= w.sum():
            assert w[v >= got].sum() >= volume * (1 - 1e-12)
            assert w[v > got].sum() < volume
    x = (np.arange(n) + 0.5) / n  # v = x on [0, 1], cells of volume 1/n
    assert exceeded_in(x, np.full(n, 1 / n), 0.1) == pytest.approx(0.9, abs=1.5 / n)


def test_mini_outputs_are_those_of_its_p1_part() -> None:
    """MINI's sampled displacement gradient is that of its P1 part: the element mean of the
    full ``grad u`` (the bubbles' gradients average to zero over each element, where they do
    vary), constant on each straight element, with ``det F`` the element's deformed area over
    its reference area."""
    import ngsolve as ngs

    from brainbulge.geometry.ngsolve_arrays import element_vertices, vertex_coordinates
    from brainbulge.model.hemidisk import HemidiskCase, hemidisk_problem
    from brainbulge.results.measures.fields import det3, sample
    from brainbulge.results.measures.quadrature import quadrature_points
    from brainbulge.solver import MixedForm, NewtonSolver, SolverOptions

    case = HemidiskCase(alpha=80, beta=60, swelling=1.2, contact="noslip", mesh_size=0.1,
                        skull_edge_radius=0.0, element="mini")
    form = MixedForm(hemidisk_problem(case), element="mini")
    assert NewtonSolver(form, SolverOptions(steps=2)).solve().converged
    mesh = form.mesh
    q = quadrature_points(mesh, order=4)
    els, _ = element_vertices(mesh)
    n_el = len(els)
    nq = len(q.weights) // n_el
    s = sample(form, q.points)
    F = s.F[:, :2, :2].reshape(n_el, nq, 2, 2)
    G = np.asarray(ngs.Grad(form.u)(q.points)).reshape(n_el, nq, 2, 2)
    w = q.weights.reshape(n_el, nq)
    def mean(A: np.ndarray) -> np.ndarray:  # volume mean over each element
        return np.einsum("eq,eqij->eij", w, A) / w.sum(axis=1)[:, None, None]

    np.testing.assert_allclose(mean(F) - np.eye(2), mean(G), atol=1e-10)
    assert np.ptp(G, axis=1).max() > 1e-3  # the full gradient varies inside elements
    # straight (interior) elements: F constant, det F the deformed area ratio
    on_bnd = np.zeros(mesh.nv, dtype=bool)
    for el in mesh.Elements(ngs.BND):
        on_bnd[[v.nr for v in el.vertices]] = True
    inner = ~on_bnd[els].any(axis=1)
    assert inner.sum() > 50
    assert np.ptp(F[inner], axis=1).max() < 1e-10
    X = vertex_coordinates(mesh)
    x = X + np.asarray(form.u(mesh(X[:, 0], X[:, 1]))).reshape(-1, 2)

    def area(P: np.ndarray) -> np.ndarray:
        a, b = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
        return 0.5 * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])

    J = det3(s.F).reshape(n_el, nq)[inner, 0]
    np.testing.assert_allclose(J, area(x[els[inner]]) / area(X[els[inner]]), rtol=1e-9)


def test_max_shear_stress_of_simple_shear_is_the_closed_form() -> None:
    """Simple shear ``F = I + gamma e1 e2`` of incompressible Mooney-Rivlin: ``sigma =
    c1 b - c2 b^-1 - p I`` gives ``sigma_12 = mu gamma``, ``sigma_11 - sigma_22 = mu
    gamma^2``, so the in-plane maximum shear stress is ``mu gamma sqrt(1 + gamma^2 / 4)``
    (``sigma_33`` lies between the in-plane principal stresses). The Ogden form of the same
    solid (no closed-form stress: central differences of its energy) gives the same."""
    from brainbulge.materials.mooney_rivlin import MooneyRivlin
    from brainbulge.materials.ogden import Ogden
    from brainbulge.results.measures.fields import max_shear_stress

    c1, c2 = 0.28, 333.0
    gamma = np.array([0.0, 0.1, 0.3])
    F = np.tile(np.eye(3), (3, 1, 1))
    F[:, 0, 1] = gamma
    expected = (c1 + c2) * gamma * np.sqrt(1 + gamma**2 / 4)
    assert max_shear_stress(F, MooneyRivlin(c1, c2)) == pytest.approx(expected, abs=1e-9)
    ogden = Ogden(c=(c1, -c2), alpha=(2.0, -2.0), eps=1e-12)
    assert max_shear_stress(F, ogden) == pytest.approx(expected, rel=1e-5, abs=1e-6)
    # a dilatation (the swelling's Js) adds no shear
    assert max_shear_stress(1.1 ** (1 / 3) * F[:1], MooneyRivlin(c1, c2))[0] == pytest.approx(
        0.0, abs=1e-9)


def test_max_shear_stress_of_an_inverted_gradient_is_nan_without_a_warning() -> None:
    """``det F <= 0`` has no stress: NaN there (the summary leaves it out and says so), no
    numpy warning on the user's screen, and the other points are unaffected."""
    import warnings

    from brainbulge.materials.mooney_rivlin import MooneyRivlin
    from brainbulge.results.measures.fields import max_shear_stress

    F = np.tile(np.eye(3), (2, 1, 1))
    F[0, 0, 1] = 0.2
    F[1, 0, 0] = -1.0  # a reflection: det F = -1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tau = max_shear_stress(F, MooneyRivlin(0.28, 333.0))
    assert np.isnan(tau[1]) and np.isfinite(tau[0]) and tau[0] > 0
