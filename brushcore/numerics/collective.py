"""The pillars' collective mode for the tile path: a coarse space of one vector a pillar.

The tile preconditioner (`brushcore.numerics.tiles`) inverts each pillar's
own block approximately and leaves the pillars' interaction to CG, as the
dense blocks do.  Its slowest part is collective: a rigid pillar that loses
elements drops force, and every other pillar's contact answers that change
of the far field together.  The dense-block path carries this mode with a
balancing coarse space (`brushcore.numerics.precondition.BlockInverse`);
this is the same space over the tile preconditioner M^-1:

    z_p = M_p^-1 1,   c_p = 1^T z_p,   E = C (I + R C),
    P = Z E^-1 Z^T + (I - Z C^-1 U^T) M^-1 (I - U C^-1 Z^T),

with U the pillars' indicator vectors and R the monopole influence between
pillar centroids (on a mirror quadrant with the images, a pillar's own
images on the diagonal, since the tiles leave them out).  Both terms are
positive semi-definite whatever R's accuracy, so P is SPD as long as E is,
and a stale E (refactorised only when some c_p moved by DRIFT) stays valid.
One application costs two pillar sums and an N x N product beside M^-1.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from brushcore.numerics.kernel import folded_coefficient, love_coefficient


def centroid_influence(elements: np.ndarray, pillar_of: np.ndarray, n: int, h: float,
                       e_star: float, mirrored: bool) -> np.ndarray:
    """Monopole influence R between pillar centroids [length / stress], (N, N):
    zero on the diagonal, or on a quadrant the pillar's own images there."""
    n_pillars = int(pillar_of.max()) + 1
    iy, ix = np.divmod(elements, n)
    counts = np.bincount(pillar_of, minlength=n_pillars)
    cy = np.bincount(pillar_of, weights=iy * h, minlength=n_pillars) / counts
    cx = np.bincount(pillar_of, weights=ix * h, minlength=n_pillars) / counts
    if mirrored:
        r = folded_coefficient(cy[:, None], cx[:, None], cy[None], cx[None], h, e_star)
        r[np.diag_indices(n_pillars)] -= love_coefficient(0.0, 0.0, h, e_star)
        return r
    r = love_coefficient(cy[:, None] - cy[None], cx[:, None] - cx[None], h, e_star)
    np.fill_diagonal(r, 0.0)
    return r


class CollectiveMode:
    """The balancing coarse space over the pillars for a per-pillar preconditioner.

    Parameters
    ----------
    r : (N, N) monopole influence (`centroid_influence`) [length / stress]
    z : M_p^-1 1 of every pillar over all its elements (operator order),
        zero where detached [stress / length]
    pillar_of : pillar of each element (operator order)
    """

    #: Refactorise E once some pillar's c moved by this fraction since the last.
    DRIFT = 0.25

    def __init__(self, r: np.ndarray, z: np.ndarray, pillar_of: np.ndarray) -> None:
        self._r = r
        self.z = z
        self._pillar_of = pillar_of
        self.factorisations = 0
        self._c_factor = np.zeros(r.shape[0])
        self.valid = False  # until `refactorise`

    @property
    def c(self) -> np.ndarray:
        """c_p = 1^T z_p per pillar [stress / length]."""
        return np.bincount(self._pillar_of, weights=self.z, minlength=self._r.shape[0])

    def refactorise(self) -> None:
        """E^-1 from the current c (`valid` False where E is not positive definite)."""
        self.valid = self._factorise()

    def _factorise(self) -> bool:
        """E^-1 from the current c; False where E is not positive definite
        (monopoles of interleaved footprints), and the mode is left out."""
        c = self.c
        dead = c <= 0.0
        e = np.diag(c) + c[:, None] * self._r * c[None, :]
        e[dead, :] = 0.0
        e[:, dead] = 0.0
        e[dead, dead] = 1.0
        try:
            factor = np.linalg.cholesky(e)
        except np.linalg.LinAlgError:
            return False
        eye = np.eye(c.size)
        inv_factor = np.linalg.solve(factor, eye)
        self._e_inverse = inv_factor.T @ inv_factor
        self._e_inverse[dead, :] = 0.0
        self._e_inverse[:, dead] = 0.0
        self._c_factor = c
        self._c_inverse = np.divide(1.0, c, out=np.zeros_like(c), where=~dead)
        self.factorisations += 1
        return True

    def update(self, pillars: np.ndarray, z_of: Callable[[int], None]) -> None:
        """After the given pillars changed: ``z_of(p)`` rewrites their part of
        `z`; E is refactorised once one of their c drifted by DRIFT."""
        for p in pillars:
            z_of(int(p))
        c = self.c
        ref = self._c_factor[pillars]
        if np.any(np.abs(c[pillars] - ref) > self.DRIFT * ref):
            self.valid = self._factorise()
        else:  # E stays, C^-1 follows c: P stays SPD (see the module notes)
            self._c_inverse = np.divide(1.0, c, out=np.zeros_like(c), where=c > 0.0)

    def apply(self, r: np.ndarray, z: np.ndarray, pl: np.ndarray,
              inner: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """P r for a compressed residual r over the attached elements, with
        ``z`` and ``pl`` the coarse vectors and pillars there and ``inner``
        the per-pillar preconditioner M^-1."""
        n_pillars = self._r.shape[0]
        t = np.bincount(pl, weights=z * r, minlength=n_pillars)  # Z^T r
        y1 = self._e_inverse @ t
        out = inner(r - (t * self._c_inverse)[pl])
        sums = np.bincount(pl, weights=out, minlength=n_pillars)
        out += z * (y1 - sums * self._c_inverse)[pl]
        return out
