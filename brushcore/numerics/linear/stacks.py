"""Stacks of per-pillar block inverses: downdate one block, pack one, multiply the stack.

The block preconditioner (`brushcore.numerics.linear.precondition`) keeps
one inverse G_p per pillar in an (N, m, m) stack, padded to the largest
pillar with zero rows and columns.  What acts on such a stack without
knowing the pillars' geometry lives here: removing slots from one block's
inverse (a Schur-complement downdate), the packed upper-triangle layout of
large blocks (BLAS spmv's), and the block-diagonal product with a stacked
(N, m) vector over the pillars that still have elements.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import blas

from brushcore.numerics.platform.spmv import packed_products
from brushcore.numerics.platform.threads import stacked_matmul

#: Smallest block size whose products skip the pillars that have let go
#: (`live_runs`): one call per run of remaining pillars costs ~1.5 us,
#: a block of 21 ~0.15 us and one of 148 ~6 us in a curve (float32).
RUNS_MIN_BLOCK = 64


def remove_slots(g: np.ndarray, gone: np.ndarray, values: np.ndarray | None = None
                 ) -> np.ndarray | None:
    """Remove slots ``gone`` from the inverse g of a symmetric block, in place:
    g - g[:, D] g[D, D]^-1 g[D, :], the inverse of the block without them
    (zero rows and columns at D).  With ``values`` on D, also return
    g[:, D] g[D, D]^-1 values (from the same solve), what a vector g b loses
    with them; else None."""
    cols = g[:, gone]
    rhs = cols.T if values is None else np.column_stack([cols.T, values])
    x = np.linalg.solve(g[np.ix_(gone, gone)], rhs)
    if gone.size == 1 and g.dtype == np.float64:
        # One slot (most cascade rounds): an outer product, applied in place
        # (g^T is Fortran-ordered) without the m x m temporary: ~4x faster at
        # m = 495.  With no sum to order, gemm gives the same numbers
        # (blas dger does not: it fuses the product into the update).
        blas.dgemm(-1.0, x[:, : g.shape[0]].T, cols.T, 1.0, g.T, overwrite_c=True)
    else:
        g -= cols @ x[:, : g.shape[0]]
    g[gone, :] = 0.0  # exact in exact arithmetic; remove round-off
    g[:, gone] = 0.0
    return None if values is None else cols @ x[:, g.shape[0]]


def pack_index(m: int) -> np.ndarray:
    """Flat indices into an m x m block of its upper triangle, packed
    column by column (BLAS spmv's layout)."""
    rows, cols = np.triu_indices(m)
    order = np.lexsort((rows, cols))
    return rows[order] * m + cols[order]


def stack_times(stack: np.ndarray, packed: bool, w: np.ndarray,
                remaining: np.ndarray, threads: int = 1) -> np.ndarray:
    """blockdiag(stack_p) w for stacked (N, m) w: one batched matmul (over
    the runs of pillars with elements left where blocks are large,
    `live_runs`), or one BLAS spmv per pillar with elements left from
    packed ``stack`` (float32 or float64, as w); either way in slabs of
    pillars on ``threads`` threads, the same numbers on any thread count."""
    if not packed:
        runs = live_runs(stack, remaining)
        return stacked_matmul(stack, w[:, :, None], threads, runs)[:, :, 0]
    # detached pillars have G_p = 0
    return packed_products(stack, w, np.flatnonzero(remaining), threads)


def live_runs(stack: np.ndarray, remaining: np.ndarray) -> list[tuple[int, int]] | None:
    """The runs [start, stop) of pillars with elements left, for
    `stacked_matmul` to skip the others' zero blocks; None (all of
    them) for small blocks or when every pillar remains."""
    if stack.shape[-1] < RUNS_MIN_BLOCK:
        return None
    alive = remaining > 0
    if alive.all():
        return None
    edges = np.flatnonzero(np.diff(alive, prepend=False, append=False)).tolist()
    return list(zip(edges[::2], edges[1::2]))
