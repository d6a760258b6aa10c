"""Boussinesq fields of multipole sources at pillar centroids (pure functions).

The far-field warm start (`brushcore.numerics.linear.warm_start.WarmStart`)
needs, at each pillar's centroid, the surface displacement caused by stress
changes elsewhere, with its gradient and Hessian.  A change of moments M0
(its total) and M1 (its first moment about the source's centroid), in
units of C = h^2 / (pi E*), displaces the surface at offset R by

    phi = M0 / R + M1 . R / R^3

to dipole order (Johnson, Contact Mechanics §3.2, a point load and its
first correction); the gradient and Hessian below are its derivatives in
closed form.
"""

from __future__ import annotations

import numpy as np

from brushcore.numerics.halfspace.kernel import image_coordinate, images


def field_terms(moments: np.ndarray, source: np.ndarray, target: np.ndarray,
                centroids: tuple[np.ndarray, np.ndarray], h: float,
                mirrored: bool) -> np.ndarray:
    """Displacement, gradient and Hessian at each target centroid.

    Parameters
    ----------
    moments : (3, P) per (source, target) pair: M0, M1_y, M1_x of the source
        [length^2, length^3, length^3: C sum dsigma and C sum dsigma (x - c),
        C = h^2 / (pi E*) in length / stress x length]
    source, target : (P,) pillar indices of each pair
    centroids : (cy, cx) of all pillars [length]
    h : element size [length] (the images lie at -h - y)
    mirrored : add the three images of each source (the quadrant of a
        field mirrored about y = -h/2 and x = -h/2)

    Returns
    -------
    numpy.ndarray, shape (6, N)
        Summed over the pairs of each target: phi [length], d phi/dy,
        d phi/dx [1], and 1/2 H_yy, H_yx, 1/2 H_xx [1 / length], so that
        phi + g . d + 1/2 d^T H d is the Taylor expansion about the
        centroid at offset d.
    """
    cy, cx = centroids
    a, my, mx = moments
    terms = np.zeros((6, cy.size))
    for sy, sx in images(mirrored):  # a mirrored source's moment flips sign too
        dy = cy[target] - image_coordinate(cy[source], sy, h)
        dx = cx[target] - image_coordinate(cx[source], sx, h)
        r2 = dy * dy + dx * dx
        inv_r = 1.0 / np.sqrt(np.where(r2 > 0.0, r2, np.inf))
        i2 = inv_r * inv_r
        i3 = inv_r * i2
        i5 = i3 * i2
        py, px = sy * my, sx * mx
        dot = py * dy + px * dx
        i7 = 15.0 * dot * i5 * i2
        values = [a * inv_r + dot * i3,
                  (py - a * dy) * i3 - 3.0 * dy * dot * i5,
                  (px - a * dx) * i3 - 3.0 * dx * dot * i5]
        for u, v, mu, mv, same in [(dy, dy, py, py, 1.0), (dy, dx, py, px, 0.0),
                                   (dx, dx, px, px, 1.0)]:
            values.append((3.0 * a * u * v - same * a * r2 - 3.0 * (mu * v + mv * u + same * dot))
                          * i5 + i7 * u * v)
        for k, value in enumerate(values):
            terms[k] += np.bincount(target, weights=value, minlength=cy.size)
    terms[3:] *= np.array([0.5, 1.0, 0.5])[:, None]  # H symmetric: H_yx counted twice
    return terms
