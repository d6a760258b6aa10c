"""How far other pillars' stress changes can move a pillar's stresses (a bound).

A local cascade updates each pillar exactly with the others held fixed
(`brushcore.numerics.linear.precondition.BlockInverse.detach`,
`brushcore.numerics.linear.pillar_solve.PillarSolver`); what it misses is the other
pillars' far field.  Stress changes of summed magnitude L_q = sum |d sigma|
over pillar q's elements move the surface under pillar p by at most
R_pq L_q, with R the influence coefficient at the closest approach of the
two footprints; element i of p answers a displacement of magnitude U with
at most U sum_j |G_p[i, j]| (its `reach`).  Both block classes and the
tile path share the geometry here.
"""

from __future__ import annotations

import numpy as np

from brushcore.numerics.halfspace.kernel import image_coordinate, images, love_coefficient


def near_influence(cy: np.ndarray, cx: np.ndarray, radius: np.ndarray, h: float,
                   e_star: float, mirrored: bool) -> np.ndarray:
    """Influence between pillars at the closest approach of their footprints.

    Parameters
    ----------
    cy, cx : pillar centroids [length], shape (N,)
    radius : largest distance of a pillar's element centre from its
        centroid [length], shape (N,)
    h, e_star : element size [length] and modulus [stress]
    mirrored : the grid is a mirror quadrant (`brushcore.numerics.halfspace.mirror`):
        each pillar also feels the other pillars' three images

    Returns
    -------
    (N, N) array [length / stress], zero on the diagonal (a pillar's own
    images belong to its own block or local solve).
    """
    r_near = np.zeros((cy.size, cy.size))
    for sy, sx in images(mirrored):
        iy, ix = image_coordinate(cy, sy, h), image_coordinate(cx, sx, h)
        dist = np.hypot(cy[:, None] - iy[None], cx[:, None] - ix[None])
        gap = np.maximum(dist - radius[:, None] - radius[None, :], h)
        r_near += love_coefficient(gap, 0.0, h, e_star)
    np.fill_diagonal(r_near, 0.0)
    return r_near


class FarFieldBound:
    """sum_q R_near[p, q] L_q per pillar, in O(N) per few changed pillars.

    Parameters
    ----------
    r_near : (N, N) influence at closest approach (`near_influence`)
    """

    #: Pillars whose change is weighed pair by pair.
    FEW_CHANGED = 32

    def __init__(self, r_near: np.ndarray) -> None:
        self.r_near = r_near
        self.r_near_max = r_near.max(axis=1)

    def shift(self, change: np.ndarray) -> np.ndarray:
        """Largest far-field displacement at each pillar [length] for summed
        stress changes ``change`` per pillar [stress].

        Between global solves a few pillars change much (the detaching ones
        and their neighbours) and every other one a little; those are
        bounded by each pillar's largest R_near, not summed pair by pair (an
        N x N product per cascade round: 3 ms at N = 1620).
        """
        changed = np.flatnonzero(change)
        if changed.size <= self.FEW_CHANGED:
            return self.r_near[:, changed] @ change[changed]
        big = changed[np.argpartition(change[changed], -self.FEW_CHANGED)[-self.FEW_CHANGED:]]
        rest = max(float(change.sum() - change[big].sum()), 0.0)
        return self.r_near[:, big] @ change[big] + self.r_near_max * rest
