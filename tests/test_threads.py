"""Work shared out by slabs (`brushcore.numerics.platform.threads`): the same
numbers whatever the thread count, and errors that reach the caller."""

from __future__ import annotations

import os

import numpy as np
import pytest

from brushcore.numerics.platform.threads import slab, stacked_matmul, team


def test_slabs_cover_the_items_once():
    for count in (1, 2, 7, 64, 513):
        for threads in (1, 2, 3, 5):
            bounds = [slab(count, i, threads) for i in range(threads)]
            assert bounds[0][0] == 0 and bounds[-1][1] == count
            assert all(a[1] == b[0] for a, b in zip(bounds, bounds[1:]))


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_stacked_matmul_gives_the_same_bits_on_any_thread_count(dtype):
    """Stacks of matrix-vector products as the preconditioners form them
    ((N, m, m) @ (N, m, 1)), more threads than items included."""
    rng = np.random.default_rng(3)
    for n_items in (1, 3, 64):
        a = rng.standard_normal((n_items, 37, 37)).astype(dtype)
        b = rng.standard_normal((n_items, 37, 1)).astype(dtype)
        one = np.matmul(a, b)
        for threads in (2, 3, 5):
            got = stacked_matmul(a, b, threads)
            assert got.dtype == one.dtype and np.array_equal(got, one), (n_items, threads)


@pytest.mark.parametrize("m", [8, 64, 70])
def test_products_over_the_live_pillars_are_the_whole_products(m):
    """Skipping the pillars that have let go (zero blocks) gives the whole
    stack's product bit for bit, on any thread count and however the live
    pillars are split into runs; small blocks take the whole product."""
    from brushcore.numerics.linear.stacks import RUNS_MIN_BLOCK, live_runs

    rng = np.random.default_rng(m)
    for trial in range(40):
        n = int(rng.integers(1, 30))
        a = rng.normal(size=(n, m, m)).astype(np.float32 if trial % 2 else np.float64)
        remaining = rng.integers(0, 3, size=n) * (rng.random(n) < rng.random())
        a[remaining == 0] = 0.0
        b = rng.normal(size=(n, m, 1)).astype(a.dtype)
        runs = live_runs(a, remaining)
        if m < RUNS_MIN_BLOCK or remaining.all():
            assert runs is None
        else:
            covered = np.zeros(n, dtype=int)
            for start, stop in runs:
                covered[start:stop] += 1
            assert np.array_equal(covered, (remaining > 0).astype(int)), (runs, remaining)
        for threads in (1, 2, 3):
            assert np.array_equal(stacked_matmul(a, b, threads, runs), np.matmul(a, b))


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_packed_products_are_scipys_spmv_on_any_thread_count(dtype):
    """The packed blocks' products through SciPy's exported BLAS pointer
    (`brushcore.numerics.platform.spmv`) are SciPy's f2py spmv to the bit, against
    the dense symmetric product to round-off, and zero off ``which``."""
    from scipy.linalg import blas

    from brushcore.numerics.linear.stacks import pack_index
    from brushcore.numerics.platform.spmv import packed_products

    rng = np.random.default_rng(5)
    m, n_items = 41, 9
    dense = rng.standard_normal((n_items, m, m))
    dense = (dense + dense.transpose(0, 2, 1)).astype(dtype)
    stack = np.stack([d.ravel()[pack_index(m)] for d in dense])
    w = rng.standard_normal((n_items, m)).astype(dtype)
    which = np.array([0, 2, 3, 7, 8])
    spmv = blas.sspmv if dtype == np.float32 else blas.dspmv
    for threads in (1, 2, 3, 8):
        z = packed_products(stack, w, which, threads)
        assert z.dtype == dtype
        for p in range(n_items):
            if p in which:
                assert np.array_equal(z[p], spmv(m, 1.0, stack[p], w[p])), (p, threads)
            else:
                assert not z[p].any()
    eps = np.finfo(dtype).eps
    assert np.allclose(z[which], np.einsum("pij,pj->pi", dense, w)[which],
                       rtol=0, atol=100 * eps * m)
    with pytest.raises(TypeError, match="float32 or float64"):
        packed_products(stack.astype(np.float64), w.astype(np.float32), which)


def test_team_raises_a_threads_error_and_recovers():
    """A thread that fails does not leave the others waiting at the barrier:
    its error reaches the caller, and the team works afterwards."""
    crew = team(2)

    def failing(i: int) -> None:
        if i == 1:
            raise ValueError("slab 1 failed")
        crew.barrier.wait()

    with pytest.raises(ValueError, match="slab 1 failed"):
        crew.run(failing)
    done = []
    crew.run(lambda i: (crew.barrier.wait(), done.append(i)))
    assert sorted(done) == [0, 1]


def test_a_forked_child_gets_its_own_team():
    """The parent's pool threads do not survive a fork; a child that used
    the parent's team would wait forever."""
    import multiprocessing

    crew = team(2)
    crew.run(lambda i: None)  # the parent's pool thread exists now
    with multiprocessing.get_context("fork").Pool(1) as pool:
        got = pool.apply_async(_sum_on_two_threads).get(timeout=60)
    assert got == 2 * 64 * 64


def _sum_on_two_threads() -> float:
    a = np.ones((2, 64, 64))
    return float(stacked_matmul(a, np.ones((2, 64, 1)), 2).sum())


@pytest.mark.parametrize("value", ["two", "0", "1000", "2.5"])
def test_a_bad_thread_count_in_the_environment_is_refused(monkeypatch, value):
    """BRUSHCORE_THREADS outside [1, MAX_THREADS] names itself, where it once
    ran on one thread without a word; unset or empty, it means 1."""
    from brushcore.numerics.platform.threads import fft_threads
    from brushcore.validation import ParameterError

    monkeypatch.setenv("BRUSHCORE_THREADS", value)
    with pytest.raises(ParameterError, match=r"BRUSHCORE_THREADS=.* is invalid: allowed an "
                                             r"integer in \[1, 256\]"):
        fft_threads()
    monkeypatch.setenv("BRUSHCORE_THREADS", "3")
    assert fft_threads() == 3
    monkeypatch.setenv("BRUSHCORE_THREADS", "")
    assert fft_threads() == 1
    monkeypatch.delenv("BRUSHCORE_THREADS")
    assert fft_threads() == 1


@pytest.mark.parametrize("value", [0, -3, 2.5, "x", True, float("nan"), 10**9])
def test_pin_threads_refuses_what_it_cannot_run(value):
    """pin_threads, the call INTERFACE.md's first snippet makes, read 0 and -3
    as 1 and 2.5 as 2, and "x" raised int()'s bare ValueError (the Python
    API helper's find): now the threads error every other layer gives."""
    from brushcore import ParameterError
    from brushcore.numerics.platform.threads import MAX_THREADS, pin_threads

    before = int(os.environ.get("OMP_NUM_THREADS", "1"))
    with pytest.raises(ParameterError, match=rf"threads=.* is invalid: allowed an integer in "
                                             rf"\[1, {MAX_THREADS}\]"):
        pin_threads(value)
    assert pin_threads(np.int64(1)) == 1 and pin_threads(1.0) == 1
    pin_threads(before)
