"""Preconditioned conjugate gradients that fail loudly."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


class ConvergenceError(RuntimeError):
    """CG did not reach its tolerance, or produced non-finite numbers."""


def pcg(apply: Callable[[np.ndarray], np.ndarray],
        precondition: Callable[[np.ndarray], np.ndarray],
        b: np.ndarray, x0: np.ndarray, rtol: float, max_iter: int) -> tuple[np.ndarray, int]:
    """Solve A x = b for symmetric positive definite A.

    Parameters
    ----------
    apply : x -> A x
    precondition : r -> M^-1 r (symmetric positive definite)
    b : right-hand side
    x0 : starting guess (warm start)
    rtol : stop when ||b - A x|| <= rtol ||b||
    max_iter : iterations allowed

    Returns
    -------
    x, iterations

    Raises
    ------
    ConvergenceError
        With the residual history's last values when the tolerance is not
        met in ``max_iter`` iterations or a NaN/inf appears.
    """
    x = x0.copy()
    r = b - apply(x)
    bnorm = float(np.linalg.norm(b))
    target = rtol * bnorm
    rnorm = float(np.linalg.norm(r))
    if rnorm <= target:
        return x, 0
    z = precondition(r)
    p = z.copy()
    rz = float(r @ z)
    history = [rnorm / bnorm]
    for it in range(1, max_iter + 1):
        q = apply(p)
        pq = float(p @ q)
        if not np.isfinite(pq) or pq <= 0.0:
            raise ConvergenceError(f"CG broke down at iteration {it}: p.Ap = {pq!r} "
                                   f"(operator not positive definite or non-finite)")
        alpha = rz / pq
        x += alpha * p
        r -= alpha * q
        rnorm = float(np.linalg.norm(r))
        history.append(rnorm / bnorm)
        if not np.isfinite(rnorm):
            raise ConvergenceError(f"CG produced a non-finite residual at iteration {it}")
        if rnorm <= target:
            return x, it
        z = precondition(r)
        rz_new = float(r @ z)
        p *= rz_new / rz
        p += z
        rz = rz_new
    raise ConvergenceError(
        f"CG did not converge in {max_iter} iterations: relative residual "
        f"{history[-1]:.3e} > rtol {rtol:.1e} (size {b.size}; last residuals "
        f"{', '.join(f'{h:.2e}' for h in history[-5:])})")
