"""Threads: pinned to what the scheduler granted, and shared out by slabs.

Several jobs share a machine under Snakemake; oversubscribed BLAS threads
slowed this solver sevenfold on a 2-core machine.  Within a
job granted T threads, the largest streams (MKL's FFT passes, the stacked
preconditioner inverses) are cut into T slabs along an axis whose items
are computed independently, one slab per thread of a `Team`, so that the
numbers are the same to the bit whatever T.
"""

from __future__ import annotations

import os
import threading
import warnings
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache

import numpy as np

from brushcore.validation import ParameterError, is_integer, is_real, require

#: Most threads a job may ask for (the workflow's schema says the same): far
#: beyond any node, and 100,000 crashed FFTW's planner.
MAX_THREADS = 256

_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
         "NUMEXPR_NUM_THREADS", "BRUSHCORE_THREADS")


def pin_threads(n: int) -> int:
    """Limit BLAS/OpenMP pools of this process and FFTW plans to ``n`` threads.

    Parameters
    ----------
    n : threads, an integer in [1, `MAX_THREADS`] (NumPy integers and
        integral floats such as 2.0 too; 0, 2.5 or "x" are refused, not
        read as 1, 2 or a bare int() error)

    Returns
    -------
    int
        The thread count now in force.
    """
    ok = is_integer(n) or (is_real(n) and float(n).is_integer())
    require(ok and 1 <= n <= MAX_THREADS, "threads", n, f"an integer in [1, {MAX_THREADS}]")
    n = int(n)
    cpus = usable_cpus()
    if n > cpus:  # 256 threads on 2 cores took 9.8 s of overhead to a 0.0 s solve
        warnings.warn(f"{n} threads on {cpus} usable CPU{'s' * (cpus != 1)}: threads beyond "
                      f"the CPUs slow the run; at most {cpus} can help", stacklevel=2)
    for var in _VARS:
        os.environ[var] = str(n)
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=n)
    return n


def usable_cpus() -> int:
    """CPUs this process may run on: its affinity (what a scheduler's cgroup
    or taskset granted), else the machine's count."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity on this platform
        return os.cpu_count() or 1


def fft_threads() -> int:
    """Threads for FFTW plans: BRUSHCORE_THREADS if set, else 1.

    Raises
    ------
    ParameterError
        If BRUSHCORE_THREADS is set to anything but an integer in [1,
        `MAX_THREADS`] or empty (a typo once ran silently on one thread).
    """
    text = os.environ.get("BRUSHCORE_THREADS", "").strip() or "1"  # empty: as unset
    try:
        n = int(text)
    except ValueError:
        n = 0
    if not 1 <= n <= MAX_THREADS:
        raise ParameterError("BRUSHCORE_THREADS", text, f"an integer in [1, {MAX_THREADS}] "
                             "(the environment variable; or leave it unset for 1)")
    return n


def slab(count: int, i: int, threads: int) -> tuple[int, int]:
    """Bounds [lo, hi) of slab i of ``count`` items cut into ``threads``."""
    return count * i // threads, count * (i + 1) // threads


class Team:
    """The calling thread and threads - 1 pool threads running one task
    together; they may meet at ``barrier``.  Their work must release the
    GIL (NumPy's loops and BLAS, mkl_fft) to run in parallel."""

    def __init__(self, threads: int) -> None:
        self.threads = threads
        self.barrier = threading.Barrier(threads)
        self._pool = ThreadPoolExecutor(threads - 1, thread_name_prefix="brushcore")

    def _guarded(self, task: Callable[[int], None], i: int) -> None:
        try:
            task(i)
        except BaseException:
            self.barrier.abort()  # the others would wait forever
            raise

    def run(self, task: Callable[[int], None]) -> None:
        """task(i) for i = 0 ... threads - 1, i = 0 on the calling thread;
        raises the first error any of them raised."""
        futures = [self._pool.submit(self._guarded, task, i) for i in range(1, self.threads)]
        errors: list[BaseException] = []
        try:
            self._guarded(task, 0)
        except BaseException as exc:
            errors.append(exc)
        errors += [e for e in (f.exception() for f in futures) if e is not None]
        if errors:
            self.barrier.reset()
            cause = [e for e in errors if not isinstance(e, threading.BrokenBarrierError)]
            raise (cause or errors)[0]


def team(threads: int) -> Team:
    """One team per thread count (>= 2) in a process (a forked child gets
    its own: the parent's pool threads do not exist there)."""
    return _team(threads, os.getpid())


@lru_cache(maxsize=None)
def _team(threads: int, pid: int) -> Team:
    return Team(threads)


def in_slabs(count: int, threads: int, work: Callable[[int, int], None]) -> None:
    """work(lo, hi) for ``count`` items cut into slabs, one per thread of a
    `Team` (at most one thread an item; one thread runs work(0, count) on
    the caller).  ``work`` must release the GIL to run in parallel."""
    threads = max(1, min(threads, count))
    if threads == 1:
        work(0, count)
        return
    team(threads).run(lambda i: work(*slab(count, i, threads)))


def stacked_matmul(a: np.ndarray, b: np.ndarray, threads: int,
                   runs: list[tuple[int, int]] | None = None) -> np.ndarray:
    """np.matmul(a, b) of stacks with one leading axis, its slabs on
    ``threads`` threads: the same numbers, each item's product being
    computed alone.  Memory-bound stacks (the tile preconditioner's coarse
    inverses at 2048^2: 142 MB an application) take about 1/T the time
    (two threads: 6.8-7.4 against 13.0-13.8 ms for 64 inverses of 527^2).

    With ``runs`` ([start, stop) item ranges) only those items are
    multiplied, each by the same call on the same memory as without, and
    the others are zero: for a stack whose other items are zero blocks
    (pillars that have let go), where skipping them saves more than the
    calls cost.
    """
    shape = a.shape[:-1] + b.shape[-1:]
    dtype = np.result_type(a, b)
    # every item written, or the skipped ones left zero
    out = np.empty(shape, dtype=dtype) if runs is None else np.zeros(shape, dtype=dtype)
    spans = [(0, a.shape[0])] if runs is None else runs

    def work(lo: int, hi: int) -> None:
        for start, stop in spans:
            start, stop = max(start, lo), min(stop, hi)
            if start < stop:
                np.matmul(a[start:stop], b[start:stop], out=out[start:stop])

    in_slabs(a.shape[0], threads, work)
    return out
