"""Pin the threads of FFTW and BLAS to what the scheduler granted.

Several jobs share a machine under Snakemake; oversubscribed BLAS threads
slowed this solver sevenfold on a 2-core machine (DESIGN.md).
"""

from __future__ import annotations

import os

_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
         "NUMEXPR_NUM_THREADS", "BRUSHCORE_THREADS")


def pin_threads(n: int) -> int:
    """Limit BLAS/OpenMP pools of this process and FFTW plans to ``n`` threads.

    Returns
    -------
    int
        The thread count now in force (>= 1).
    """
    n = max(1, int(n))
    for var in _VARS:
        os.environ[var] = str(n)
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=n)
    return n


def fft_threads() -> int:
    """Threads for FFTW plans: BRUSHCORE_THREADS if set, else 1."""
    try:
        return max(1, int(os.environ.get("BRUSHCORE_THREADS", "1")))
    except ValueError:
        return 1
