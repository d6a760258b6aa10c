"""Per-pillar block preconditioner: the exact inverse of each pillar's own block.

Within a pillar the operator is B_p = K_pp + s_p 1 1^T (elastic self
interaction plus the spring), and it couples to other pillars only through
the comparatively weak far field of K.  Inverting each B_p exactly leaves CG
only the inter-pillar interaction to resolve.  When elements detach, the
inverse of the reduced block follows from a rank-|D| downdate,

    G' = G - G[:, D] G[D, D]^-1 G[D, :],

which leaves exact zeros in the rows and columns of D, so no refactorisation
is ever needed.
"""

from __future__ import annotations

import numpy as np

from .kernel import love_coefficient


class BlockInverse:
    """Stacked inverses G_p of the per-pillar blocks, padded to a common size.

    Parameters
    ----------
    elements : flat n x n indices of the pillar elements (operator order)
    pillar_of : pillar index of each element
    n : grid size
    compliance : h^2 / k_p per pillar [length / stress]
    h, e_star : element size [length] and modulus [stress]
    """

    def __init__(self, elements: np.ndarray, pillar_of: np.ndarray, n: int,
                 compliance: np.ndarray, h: float, e_star: float) -> None:
        n_pillars = compliance.size
        order = np.argsort(pillar_of, kind="stable")
        counts = np.bincount(pillar_of, minlength=n_pillars)
        self.m = int(counts.max())
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        slot = np.empty(elements.size, dtype=np.intp)
        slot[order] = np.arange(elements.size) - np.repeat(starts, counts)
        self.pos = pillar_of * self.m + slot  # element -> position in the (N, m) stack
        iy, ix = np.divmod(elements, n)
        yy = np.zeros((n_pillars, self.m))
        xx = np.zeros((n_pillars, self.m))
        yy.ravel()[self.pos] = iy * h
        xx.ravel()[self.pos] = ix * h
        valid = np.zeros((n_pillars, self.m), dtype=bool)
        valid.ravel()[self.pos] = True
        self.inv = np.zeros((n_pillars, self.m, self.m))
        # Pillars with the same footprint up to translation share one inverse.
        shapes: dict[bytes, list[int]] = {}
        for p in range(n_pillars):
            k = counts[p]
            key = np.stack([yy[p, :k] - yy[p, 0], xx[p, :k] - xx[p, 0]]).tobytes()
            shapes.setdefault(key + compliance[p].tobytes(), []).append(p)
        for group in shapes.values():
            p = group[0]
            k = counts[p]
            dy = yy[p, :k, None] - yy[p, None, :k]
            dx = xx[p, :k, None] - xx[p, None, :k]
            block = love_coefficient(dy, dx, h, e_star) + compliance[p]
            self.inv[group, :k, :k] = np.linalg.inv(block)
        self._work = np.zeros((n_pillars, self.m))

    @staticmethod
    def fits(pillar_of: np.ndarray, budget_bytes: float = 4.0e8, max_block: int = 2500) -> bool:
        """Whether the stacked inverses fit the memory budget and block size limit."""
        counts = np.bincount(pillar_of)
        m = int(counts.max())
        return m <= max_block and counts.size * m * m * 8.0 <= budget_bytes

    def detach(self, elements: np.ndarray, stress: np.ndarray | None = None,
               attached_pos: np.ndarray | None = None) -> np.ndarray | None:
        """Downdate the inverses for detached elements (operator-order indices).

        If the current stresses are given (compressed over the attached set
        before detaching, with `attached_pos` their stack positions), also
        return each pillar's exact response to losing those elements with the
        field of the other pillars held fixed: sigma_p - G[:, D] G[D, D]^-1
        sigma_p[D] (the same Schur complement as the downdate).
        """
        pos = self.pos[elements]
        pil, slot = np.divmod(pos, self.m)
        w = None
        if stress is not None:
            w = self._work
            w.ravel()[attached_pos] = stress
        for p in np.unique(pil):
            d = slot[pil == p]
            g = self.inv[p]
            cols = g[:, d]
            rhs = cols.T if w is None else np.column_stack([cols.T, w[p, d]])
            x = np.linalg.solve(g[np.ix_(d, d)], rhs)
            g -= cols @ x[:, : self.m]
            g[d, :] = 0.0  # exact in exact arithmetic; remove round-off
            g[:, d] = 0.0
            if w is not None:
                w[p] -= cols @ x[:, self.m]
                w[p, d] = 0.0
        if w is None:
            return None
        out = w.ravel()[attached_pos].copy()
        w.ravel()[attached_pos] = 0.0
        return out

    def apply(self, r: np.ndarray, attached_pos: np.ndarray) -> np.ndarray:
        """z = blockdiag(G_p) r for a compressed residual over the attached elements."""
        w = self._work
        w.ravel()[attached_pos] = r
        z = np.matmul(self.inv, w[:, :, None])[:, :, 0]
        w.ravel()[attached_pos] = 0.0
        return z.ravel()[attached_pos]
