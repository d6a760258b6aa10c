"""Packed symmetric products of a stack of blocks, on the job's threads.

The block preconditioner applies large pillars' inverses from packed upper
triangles (`brushcore.numerics.linear.precondition`), one BLAS spmv per pillar:
half the bytes of the full blocks, and memory-bound (random N = 1620 at
2048^2 streams 325 MB of float32 an application).  SciPy's f2py wrapper
(`scipy.linalg.blas.sspmv`) holds the GIL, so a second thread cannot share
the stack.  The same BLAS routine called through the function pointer that
SciPy exports for Cython (`scipy.linalg.cython_blas`), by ctypes, releases
it: each pillar's product is computed as before, by the same routine, so
the numbers are the same to the bit on any thread count.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from functools import lru_cache

import numpy as np

from brushcore.numerics.platform.threads import in_slabs

_P = ctypes.c_void_p
_SPMV = ctypes.CFUNCTYPE(None, ctypes.c_char_p, _P, _P, _P, _P, _P, _P, _P, _P)


@lru_cache(maxsize=None)
def _routine(name: str) -> Callable[..., None]:
    """BLAS ``name`` (sspmv or dspmv; Fortran-style arguments, all by
    reference) from SciPy's exported function pointers; a CFUNCTYPE call
    drops the GIL."""
    import scipy.linalg.cython_blas as cython_blas

    api = ctypes.pythonapi
    api.PyCapsule_GetName.restype = ctypes.c_char_p
    api.PyCapsule_GetName.argtypes = [ctypes.py_object]
    api.PyCapsule_GetPointer.restype = ctypes.c_void_p
    api.PyCapsule_GetPointer.argtypes = [ctypes.py_object, ctypes.c_char_p]
    capsule = cython_blas.__pyx_capi__[name]
    return _SPMV(api.PyCapsule_GetPointer(capsule, api.PyCapsule_GetName(capsule)))


def packed_products(stack: np.ndarray, w: np.ndarray, which: np.ndarray,
                    threads: int = 1) -> np.ndarray:
    """z_p = S_p w_p for the packed symmetric blocks S_p of ``which``, zero
    for the other items.

    Parameters
    ----------
    stack : (N, m (m + 1) / 2) upper triangles packed column by column
        (BLAS spmv's layout), float32 or float64, C-contiguous
    w : (N, m) vectors of the same dtype, C-contiguous
    which : indices of the items to multiply (the others are zero blocks)
    threads : threads that share the items (slabs of ``which``)

    Returns
    -------
    numpy.ndarray, shape (N, m), dtype of ``w``
    """
    if stack.dtype != w.dtype or stack.dtype not in (np.float32, np.float64):
        raise TypeError(f"packed_products: stack {stack.dtype} and w {w.dtype} must be "
                        "the same float32 or float64")
    stack, w = np.ascontiguousarray(stack), np.ascontiguousarray(w)
    m = w.shape[1]
    z = np.zeros_like(w)
    single = stack.dtype == np.float32
    spmv = _routine("sspmv" if single else "dspmv")
    scalar = ctypes.c_float if single else ctypes.c_double
    # Arguments by reference, kept alive by these names during the calls.
    n, one, alpha, beta = ctypes.c_int(m), ctypes.c_int(1), scalar(1.0), scalar(0.0)
    refs = [ctypes.byref(v) for v in (n, one, alpha, beta)]
    a0, w0, z0 = stack.ctypes.data, w.ctypes.data, z.ctypes.data
    da, dw = stack.strides[0], w.strides[0]
    which = np.asarray(which, dtype=np.intp)

    def work(lo: int, hi: int) -> None:
        rn, r1, ra, rb = refs
        for p in which[lo:hi].tolist():
            spmv(b"U", rn, ra, a0 + p * da, w0 + p * dw, r1, rb, z0 + p * dw, r1)

    in_slabs(which.size, threads, work)
    return z
