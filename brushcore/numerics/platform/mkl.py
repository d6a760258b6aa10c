"""Intel MKL's FFTs for the whole-grid pruned pair (the optional ``mkl`` extra).

`Convolver` does the same four passes with MKL (through the ``mkl_fft``
package) as with FFTW: rows of the n data rows, columns of the zero-padded
grid, the kernel product, columns back, the first n rows back.  Measured
on one core of an Intel Xeon (2.6 GHz, n = 512, both in one process,
alternating): 4.6 against FFTW's 6.7 ms a pair in single precision and 9.2
against 10.6 ms in double; a soft random curve 25-27 % faster.

MKL runs here on its sequential layer (no OpenMP runtime beside FFTW's and
OpenBLAS's).  With T > 1 FFT threads the passes are cut into T slabs of
rows or columns, each transformed by one thread of a
`brushcore.numerics.platform.threads.Team` (mkl_fft releases the GIL), meeting at a
barrier between passes.  Every row and column is transformed
as in one thread, so the numbers are the same to the bit whatever T.
Measured with T = 2 on the 2-core Intel Xeon, single precision, against one
thread and against FFTW's two-thread plans: 3.7 against 5.3-6.0 and 4.9 ms
at n = 512, 14.8 against 21-22 and 26.6 ms at 1024, 74 against 111-138 and
131 ms at 2048 (no gain at 256).
"""

from __future__ import annotations

import importlib.util
import os
import threading
from functools import lru_cache
from types import ModuleType

import numpy as np

from brushcore.numerics.platform.threads import slab, team


def available() -> bool:
    """Whether ``mkl_fft`` is installed (without loading MKL)."""
    return importlib.util.find_spec("mkl_fft") is not None


@lru_cache(maxsize=1)
def _module() -> ModuleType:
    """mkl_fft, loaded on MKL's sequential layer: MKL reads the variable
    when it loads, and a one-thread job must not start an OpenMP pool."""
    os.environ.setdefault("MKL_THREADING_LAYER", "SEQUENTIAL")
    import mkl_fft

    return mkl_fft


def pruned_pair(real_in: np.ndarray, work: np.ndarray, spectrum: np.ndarray,
                real_out: np.ndarray, threads: int = 1) -> np.ndarray:
    """The pruned convolution pair on MKL, in place in ``work``.

    Parameters
    ----------
    real_in : (n, 2n) real input, columns n: zero
    work : (2n, n + 1) complex work array (rows n: are zeroed here)
    spectrum : the kernel's real spectrum repeated per (re, im) pair,
        (2n, 2 (n + 1)), unscaled: MKL's backward transforms divide by
        their length
    real_out : (n, 2n) real output, of which columns :n are the field
    threads : threads that share the passes (slabs of rows or columns; at
        most n // 2: MKL transforms a lone row or column with other
        round-off than a batch)

    Returns
    -------
    ``real_out``
    """
    threads = max(1, min(threads, real_in.shape[0] // 2))
    if threads == 1:  # one slab: the whole grid, on the calling thread
        _slab(0, 1, _ALONE, real_in, work, spectrum, real_out)
        return real_out
    crew = team(threads)
    crew.run(lambda i: _slab(i, threads, crew.barrier, real_in, work, spectrum, real_out))
    return real_out


#: The barrier of a lone slab: passes at once.
_ALONE = threading.Barrier(1)


def _slab(i: int, threads: int, barrier: threading.Barrier, real_in: np.ndarray,
          work: np.ndarray, spectrum: np.ndarray, real_out: np.ndarray) -> None:
    """Thread i's share of `pruned_pair`: its slab of rows, then of
    columns (transform, kernel product, transform back), then of rows."""
    fft = _module()
    n = real_in.shape[0]
    lo, hi = slab(n, i, threads)
    work[n + lo:n + hi] = 0.0  # the zero padding, overwritten by the in-place columns
    fft.rfft(real_in[lo:hi], axis=1, out=work[lo:hi])
    barrier.wait()
    left, right = slab(n + 1, i, threads)
    columns = work[:, left:right]
    fft.fft(columns, axis=0, out=columns)
    product = work.view(real_in.dtype)[:, 2 * left:2 * right]
    np.multiply(product, spectrum[:, 2 * left:2 * right], out=product)
    fft.ifft(columns, axis=0, out=columns)
    barrier.wait()
    fft.irfft(work[lo:hi], n=2 * n, axis=1, out=real_out[lo:hi])
