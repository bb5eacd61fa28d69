"""Threaded CSR products: the same result as SciPy's serial kernel, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from brainbulge.solver import threaded_csr
from brainbulge.solver.threaded_csr import ThreadedCSR, row_blocks, threaded


def _banded(m: int, n: int, per_row: int, seed: int = 0) -> sp.csr_matrix:
    """Rows of uneven length (0 .. 2 per_row entries), some empty."""
    rng = np.random.default_rng(seed)
    counts = rng.integers(0, 2 * per_row, m)
    rows = np.repeat(np.arange(m), counts)
    cols = (rows * n // m + rng.integers(-50, 50, len(rows))) % n
    return sp.csr_matrix((rng.standard_normal(len(rows)), (rows, cols)), shape=(m, n))


@pytest.mark.parametrize("shape", [(20_000, 20_000), (5_000, 20_000), (20_000, 3_000)])
@pytest.mark.parametrize("parts", [2, 3])
def test_the_product_is_the_serial_one_bit_for_bit(monkeypatch, shape, parts) -> None:
    monkeypatch.setattr(threaded_csr, "MIN_NNZ", 1000)
    monkeypatch.setattr(threaded_csr, "threads", lambda: parts)
    A = _banded(*shape, per_row=12)
    T = threaded(A)
    assert isinstance(T, ThreadedCSR) and np.shares_memory(T.data, A.data)
    x = np.random.default_rng(1).standard_normal(shape[1])
    assert np.array_equal(T @ x, A @ x)
    assert np.array_equal(T @ x[:, None], (A @ x)[:, None])
    assert np.array_equal(T.dot(x), A @ x)


def test_row_blocks_split_the_non_zeros_evenly() -> None:
    A = _banded(10_000, 10_000, per_row=20, seed=3)
    for parts in (1, 2, 4, 7):
        b = row_blocks(A.indptr, parts)
        assert b[0] == 0 and b[-1] == A.shape[0] and np.all(np.diff(b) > 0)
        nnz = np.diff(A.indptr[b])
        assert len(nnz) == parts
        assert np.max(np.abs(nnz - A.nnz / parts)) <= np.diff(A.indptr).max()


def test_small_and_other_matrices_are_left_alone() -> None:
    A = _banded(100, 100, per_row=3)
    x = np.ones(100)
    assert np.array_equal(threaded(A) @ x, A @ x)  # below MIN_NNZ: the serial kernel
    C = A.tocsc()
    assert threaded(C) is C
    T = threaded(A)
    assert threaded(T) is T


def test_a_forked_child_uses_a_pool_of_its_own(monkeypatch) -> None:
    """After a fork the parent's pool threads do not exist in the child: its products must
    not wait for them (they would hang)."""
    import multiprocessing as mp

    monkeypatch.setattr(threaded_csr, "MIN_NNZ", 1000)
    monkeypatch.setattr(threaded_csr, "threads", lambda: 2)
    A = _banded(20_000, 20_000, per_row=12)
    x = np.ones(20_000)
    expected = A @ x
    assert np.array_equal(threaded(A) @ x, expected)  # the parent's pool now exists
    ctx = mp.get_context("fork")
    with ctx.Pool(1) as pool:
        result = pool.apply_async(_product_in_child, (A, x)).get(timeout=60)
    assert np.array_equal(result, expected)


def _product_in_child(A: sp.csr_matrix, x: np.ndarray) -> np.ndarray:
    return threaded(A) @ x
