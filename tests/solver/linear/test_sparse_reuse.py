"""Pattern-reusing slicing and addition agree with SciPy's, on one pattern and after a change."""

import numpy as np
import scipy.sparse as sp

from brainbulge.solver.linear.sparse_reuse import (
    PatternAdd,
    PatternGather,
    PatternProject,
)


def _matrix(seed: int, n: int = 60, density: float = 0.1) -> sp.csr_matrix:
    rng = np.random.default_rng(seed)
    M = sp.random(n, n, density=density, random_state=rng, format="csr")
    return (M + M.T + sp.identity(n)).tocsr()


def test_gather_matches_scipy_slicing_and_reuses_its_plan() -> None:
    K = _matrix(0)
    rows = np.array([0, 3, 4, 10, 11, 40, 59])
    cols = np.array([1, 3, 7, 10, 20, 40])
    plan = PatternGather(lambda M: M[rows][:, cols])
    for scale in (1.0, -2.5):  # same pattern, new values
        K2 = K.copy()
        K2.data = K2.data * scale + np.arange(K2.nnz)
        got = plan(K2)
        assert (abs(got - K2[rows][:, cols]) > 0).nnz == 0
    assert plan.plans == 1
    other = _matrix(1)  # another pattern: a new plan, still exact
    assert (abs(plan(other) - other[rows][:, cols]) > 0).nnz == 0
    assert plan.plans == 2


def test_gather_fills_the_entries_the_transform_adds() -> None:
    K = _matrix(2, n=10)

    def pad_explicit(M):  # two identity rows with explicit (zero) entries on the diagonal
        coo = M.tocoo()
        return sp.csr_matrix((np.concatenate([coo.data, [0.0, 0.0]]),
                              (np.concatenate([coo.row, [10, 11]]),
                               np.concatenate([coo.col, [10, 11]]))), shape=(12, 12))

    plan = PatternGather(pad_explicit, fill=lambda M: 7.0)
    got = plan(K).toarray()
    assert np.allclose(got[:10, :10], K.toarray())
    assert np.allclose(np.diag(got)[10:], 7.0)


def test_add_on_the_pattern_matches_scipy_and_falls_back_outside_it() -> None:
    K = _matrix(3)
    inside = sp.csr_matrix((np.array([1.5, -2.0]), ([0, 5], [0, 5])), shape=K.shape)
    add = PatternAdd()
    expected = (K + inside).toarray()
    got = add(K.copy(), inside)
    assert np.allclose(got.toarray(), expected)
    assert got.nnz == K.nnz  # the result keeps K's pattern
    i, j = next((i, j) for i in range(60) for j in range(60) if K[i, j] == 0)
    outside = sp.csr_matrix((np.array([3.0]), ([i], [j])), shape=K.shape)
    assert np.allclose(add(K.copy(), outside).toarray(), (K + outside).toarray())


def test_add_searches_positions_once_per_pattern_of_the_added_matrix() -> None:
    K = _matrix(4)
    coo = K.tocoo()
    pick = np.arange(0, K.nnz, 7)  # entries inside K's pattern, in scrambled order
    pick = pick[::-1]

    def inside(values: np.ndarray) -> sp.coo_matrix:
        return sp.coo_matrix((values, (coo.row[pick], coo.col[pick])), shape=K.shape)

    add = PatternAdd()
    for seed in (5, 6):  # same pattern, new values: the positions are reused
        M = inside(np.random.default_rng(seed).normal(size=len(pick)))
        got = add(K.copy(), M)
        assert np.allclose(got.toarray(), (K + M).toarray())
        assert got.nnz == K.nnz
    assert add.plans == 1
    fewer = sp.coo_matrix((np.ones(3), (coo.row[:3], coo.col[:3])), shape=K.shape)
    assert np.allclose(add(K.copy(), fewer).toarray(), (K + fewer).toarray())
    assert add.plans == 2


def test_gathered_matrices_share_the_plans_read_only_index_arrays() -> None:
    K = _matrix(7)
    rows = np.arange(0, 60, 2)
    plan = PatternGather(lambda M: M[rows][:, rows])
    first, second = plan(K), plan(K * 2.0)
    assert np.shares_memory(first.indices, second.indices)  # no copy per matrix
    assert not first.indices.flags.writeable and not first.indptr.flags.writeable
    assert np.allclose(second.toarray(), 2 * K[rows][:, rows].toarray())
    # a plan fed with those matrices recognises their pattern without comparing it
    inner = PatternGather(lambda M: M[:5][:, :5])
    assert np.allclose(inner(first).toarray(), first[:5][:, :5].toarray())
    assert np.allclose(inner(second).toarray(), second[:5][:, :5].toarray())
    assert inner.plans == 1 and inner.comparisons == 0  # recognised in O(1)
    inner(K[rows][:, rows])  # the same pattern in arrays of its own: compared
    assert inner.plans == 1 and inner.comparisons == 1


def _node_matrix(seed: int, nodes: int = 20) -> sp.csr_matrix:
    """A vector-P1-like tangent: 3 DOFs per node (numbered component by component, as
    NGSolve's VectorH1), every DOF of two coupled nodes coupled, unsymmetric values."""
    rng = np.random.default_rng(seed)
    G = sp.random(nodes, nodes, density=0.15, random_state=rng, format="csr")
    G = ((G + G.T + sp.identity(nodes)) != 0).astype(float)
    pattern = sp.kron(np.ones((3, 3)), G, format="csr")  # dof = component * nodes + node
    K = pattern.copy()
    K.data = rng.normal(size=K.nnz)
    return K


def _normals(rows_per_point: list[list[int]], n: int, seed: int) -> sp.csc_matrix:
    rng = np.random.default_rng(seed)
    vals, rows, cols = [], [], []
    for j, dofs in enumerate(rows_per_point):
        v = rng.normal(size=len(dofs))
        vals += list(v / np.linalg.norm(v))
        rows += dofs
        cols += [j] * len(dofs)
    return sp.csc_matrix((vals, (rows, cols)), shape=(n, len(rows_per_point)))


def test_projection_on_the_pattern_matches_the_dense_formula_and_keeps_its_plan() -> None:
    """In place on K's values (no second copy of them), which restore() puts back; a new
    call restores first."""
    nodes = 20
    K = _node_matrix(8, nodes)
    K0 = K.toarray()
    n = K.shape[0]
    points = [[c * nodes + a for c in range(3)] for a in (2, 5, 7)]
    points.append([0 * nodes + 9, 2 * nodes + 9])  # a node with one component held
    project = PatternProject()
    for seed in (0, 1):  # same constrained DOFs, new normals: one plan
        N = _normals(points, n, seed)
        P = (N @ N.T).toarray()
        Pi = np.eye(n) - P
        want = Pi @ K0 @ Pi + 0.7 * P
        got = project(K, N, 0.7)
        np.testing.assert_allclose(got.toarray(), want, atol=1e-13)
        assert got.nnz == K.nnz  # K's pattern
        assert np.shares_memory(got.data, K.data)
        np.testing.assert_allclose(K.toarray(), want, atol=1e-13)
    assert project.plans == 1  # planned, not SciPy's products
    project.restore()
    np.testing.assert_array_equal(K.toarray(), K0)
    N = _normals(points[:2], n, 2)  # another active set: a new plan
    P = (N @ N.T).toarray()
    Pi = np.eye(n) - P
    np.testing.assert_allclose(project(K, N, 0.7).toarray(), Pi @ K0 @ Pi + 0.7 * P,
                               atol=1e-13)
    assert project.plans == 2
    project.restore()
    project.restore()  # twice: nothing more to put back
    np.testing.assert_array_equal(K.toarray(), K0)


def _add_entry(K: sp.csr_matrix, i: int, j: int) -> sp.csr_matrix:
    assert K[i, j] == 0 and K[j, i] == 0
    return (K + sp.csr_matrix(([1.0], ([i], [j])), shape=K.shape)).tocsr()


def test_projection_falls_back_to_scipy_off_the_node_structure() -> None:
    """Where a constrained DOF's column is not its row's transpose: SciPy's products, K
    left alone; an unsymmetric entry away from the constrained rows and columns does not
    matter."""
    K = _node_matrix(9)
    n = K.shape[0]
    N = _normals([[1, 21, 41]], n, 3)
    P = (N @ N.T).toarray()
    Pi = np.eye(n) - P
    far = next(j for j in range(n) if j not in (1, 21, 41) and K[0, j] == 0 and K[j, 0] == 0)
    near = next(i for i in range(n) if K[i, 21] == 0 and K[21, i] == 0)
    for K1, plans in ((_add_entry(K, 0, far), 1), (_add_entry(K, near, 21), 0)):
        K0 = K1.toarray()
        project = PatternProject()
        np.testing.assert_allclose(project(K1, N, 2.0).toarray(),
                                   Pi @ K0 @ Pi + 2.0 * P, atol=1e-13)
        assert project.plans == plans  # 0: SciPy's products
        project.restore()
        np.testing.assert_array_equal(K1.toarray(), K0)
