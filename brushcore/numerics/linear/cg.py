"""Preconditioned conjugate gradients that fail loudly."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from brushcore.numerics.platform.backend import namespace


class ConvergenceError(RuntimeError):
    """CG did not reach its tolerance, or produced non-finite numbers."""


#: CG's words where it ran out of iterations, the one failure that more
#: iterations (``max_iter``) can mend; the events re-raise the message with
#: their place appended, so the words are what travels.
OUT_OF_ITERATIONS = "did not converge in"


def ran_out_of_iterations(exc: BaseException) -> bool:
    """Whether ``exc`` is CG's running out of iterations (`OUT_OF_ITERATIONS`)."""
    return isinstance(exc, ConvergenceError) and OUT_OF_ITERATIONS in str(exc)


def pcg(apply: Callable[[np.ndarray], np.ndarray],
        precondition: Callable[[np.ndarray], np.ndarray],
        b: np.ndarray, x0: np.ndarray, rtol: float, max_iter: int,
        decided: Callable[[np.ndarray, np.ndarray, float], bool] | None = None,
        settled: Callable[[np.ndarray, np.ndarray, float], bool] | None = None,
        floor: float = 0.0,
        on_stop: Callable[[np.ndarray, np.ndarray, np.ndarray], None] | None = None,
        ) -> tuple[np.ndarray, int]:
    """Solve A x = b for symmetric positive definite A.

    Parameters
    ----------
    apply : x -> A x
    precondition : r -> M^-1 r (symmetric positive definite)
    b : right-hand side
    x0 : starting guess (warm start)
    rtol : stop when the preconditioned residual z = M^-1 (b - A x), an
        estimate of the error of x in the units of x, satisfies
        max|z| <= rtol max|x|.  A residual criterion relative to b would
        not do: with very soft springs x is ~1e-8 of b/diag(A), so a small
        residual can still leave x wrong in every digit that matters.
    max_iter : iterations allowed
    decided : optional early exit: decided(x, z, zmax) is asked after each
        iteration whose correction is still above the tolerance, with z the
        error estimate per element and zmax = max|z|; True stops there (a
        caller that needs only what x decides, not x itself)
    settled : optional condition on the tolerance: settled(x, z, zmax) must
        also hold before CG stops at rtol, unless max|z| <= floor max|x|
        (a caller whose next step depends on comparisons that the error
        could still flip)
    floor : the relative error at which CG stops whether settled or not
    on_stop : optional, called once as on_stop(x, r, z) with CG's residual
        r (b - A x, updated recursively) and z = M^-1 r of the iterate
        returned (what a caller estimates a functional of the true solution
        from)

    Returns
    -------
    x, iterations

    Raises
    ------
    ConvergenceError
        With the residual history's last values when the tolerance is not
        met in ``max_iter`` iterations or a NaN/inf appears.
    """
    # One loop serves both: a pcg_image whose image is empty.
    xp = namespace(b)
    empty = xp.empty(0, dtype=xp.float64)
    x, _, iterations = pcg_image(lambda p: (apply(p), empty), precondition, b, x0,
                                 apply(x0), empty, rtol, max_iter, decided, settled, floor,
                                 on_stop)
    return x, iterations


def pcg_image(apply: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
              precondition: Callable[[np.ndarray], np.ndarray],
              b: np.ndarray, x0: np.ndarray, ax0: np.ndarray, y0: np.ndarray,
              rtol: float, max_iter: int,
              decided: Callable[[np.ndarray, np.ndarray, float], bool] | None = None,
              settled: Callable[[np.ndarray, np.ndarray, float], bool] | None = None,
              floor: float = 0.0,
              on_stop: Callable[[np.ndarray, np.ndarray, np.ndarray], None] | None = None,
              ) -> tuple[np.ndarray, np.ndarray, int]:
    """`pcg` that also carries a linear image y = Y x of the iterate.

    The brush operator's application computes the half-space field on the
    whole grid, of which A keeps the attached elements; the protocol engine
    also needs that field at the detached ones (their gaps).  Carrying it
    along (y += alpha Y p) costs nothing, and a warm start whose A x0 and
    Y x0 are known (from the previous state) costs no application either.

    Parameters
    ----------
    apply : p -> (A p, Y p)
    precondition, b, x0, rtol, max_iter, decided, settled, floor, on_stop : as in `pcg`
    ax0, y0 : A x0 and Y x0

    Returns
    -------
    x, Y x, iterations
    """
    xp = namespace(b)
    x, y = xp.asarray(x0, copy=True), xp.asarray(y0, copy=True)
    r = b - ax0
    z = precondition(r)
    history: list[float] = []

    def converged() -> bool:
        xmax = float(xp.max(xp.abs(x))) if x.shape[0] else 0.0
        zmax = float(xp.max(xp.abs(z))) if z.shape[0] else 0.0
        if not math.isfinite(zmax):
            raise ConvergenceError(f"CG produced a non-finite correction after "
                                   f"{len(history)} iterations")
        if xmax > 0:
            history.append(zmax / xmax)
        if zmax <= rtol * xmax:
            return settled is None or settled(x, z, zmax) or zmax <= floor * xmax
        return decided is not None and decided(x, z, zmax)

    def stop(iterations: int) -> tuple[np.ndarray, np.ndarray, int]:
        if on_stop is not None:
            on_stop(x, r, z)
        return x, y, iterations

    if converged():
        return stop(0)
    p = xp.asarray(z, copy=True)
    rz = float(r @ z)
    for it in range(1, max_iter + 1):
        q, yq = apply(p)
        pq = float(p @ q)
        if not math.isfinite(pq) or pq <= 0.0:
            raise ConvergenceError(f"CG broke down at iteration {it}: p.Ap = {pq!r} "
                                   f"(operator not positive definite or non-finite)")
        alpha = rz / pq
        x += alpha * p
        y += alpha * yq
        r -= alpha * q
        z = precondition(r)
        if converged():
            return stop(it)
        rz_new = float(r @ z)
        p *= rz_new / rz
        p += z
        rz = rz_new
    raise ConvergenceError(
        f"CG {OUT_OF_ITERATIONS} {max_iter} iterations: relative correction "
        f"{history[-1] if history else float('nan'):.3e} > rtol {rtol:.1e} (size {b.size}; "
        f"last values {', '.join(f'{h:.2e}' for h in history[-5:])})")
