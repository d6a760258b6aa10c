"""Love's influence coefficients of an elastic half space (pure functions).

Love (1929) / Johnson, Contact Mechanics §3.9: the surface displacement at
(x, y) due to unit pressure on the square |x'| <= h/2, |y'| <= h/2 is

    u = [f(x+a, y+a) - f(x+a, y-a) - f(x-a, y+a) + f(x-a, y-a)] / (pi E*)

with a = h/2 and f(x, y) = x asinh(y/|x|) + y asinh(x/|y|), an antiderivative
of 1/r in x and y up to terms that cancel in the double difference.  The
asinh form avoids the cancellation of the usual log-ratio form far away.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def _f(x: Any, y: Any, xp: Any = np) -> Any:
    asinh = np.arcsinh if xp is np else xp.asinh
    with np.errstate(divide="ignore", invalid="ignore"):
        ax = xp.abs(x)
        ay = xp.abs(y)
        tx = xp.where(ax > 0.0, x * asinh(y / xp.where(ax > 0.0, ax, 1.0)), 0.0)
        ty = xp.where(ay > 0.0, y * asinh(x / xp.where(ay > 0.0, ay, 1.0)), 0.0)
    return tx + ty


def love_coefficient(x: Any, y: Any, h: float, e_star: float, xp: Any = np) -> Any:
    """Displacement at offset (x, y) from the centre of a uniformly loaded square.

    Parameters
    ----------
    x, y : offsets from the loaded element's centre [length]
    h : element side [length]
    e_star : effective modulus E* [stress]
    xp : array namespace of x and y (NumPy, or a device's: see `wrapped_kernel`)

    Returns
    -------
    array of ``xp``
        Displacement per unit pressure [length / stress].
    """
    if xp is np:
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
    a = 0.5 * h
    u = (_f(x + a, y + a, xp) - _f(x + a, y - a, xp) - _f(x - a, y + a, xp)
         + _f(x - a, y - a, xp))
    return u / (np.pi * e_star)


def wrapped_kernel(n: int, h: float, e_star: float, xp: Any = np) -> Any:
    """Influence coefficients on the 2n x 2n DC-FFT grid in wrap-around order.

    Row/column i holds offset i h for i < n and (i - 2n) h for i > n; the
    middle line i = n is never reached by a non-periodic n x n convolution
    and is set to zero (Liu, Wang & Liu, Wear 243 (2000) 101).

    ``xp`` evaluates it in a device's namespace: a card computes the 4n^2
    coefficients in milliseconds, where the host takes seconds at n = 2048.

    Returns
    -------
    array of ``xp``, shape (2n, 2n)
        Kernel [length / stress].
    """
    idx = xp.arange(2 * n, dtype=xp.float64)  # whole numbers: exact in float64
    off = xp.where(idx < n, idx, idx - 2 * n) * h
    kern = love_coefficient(off[:, None], off[None, :], h, e_star, xp)
    kern[n, :] = 0.0
    kern[:, n] = 0.0
    return kern


def dense_influence_matrix(n: int, h: float, e_star: float) -> np.ndarray:
    """The full (n^2 x n^2) influence matrix, for brute-force checks on small grids."""
    iy, ix = np.divmod(np.arange(n * n), n)
    dx = (ix[:, None] - ix[None, :]) * h
    dy = (iy[:, None] - iy[None, :]) * h
    return love_coefficient(dy, dx, h, e_star)


def self_compliance(*, h: float, e_star: float) -> float:
    """Centre displacement of an h x h square (side h [length]) under unit pressure,
    4 ln(1+sqrt2) h / (pi E*) [length / stress]; keyword-only, since this
    module's other functions take (h, e_star) in that order."""
    return 4.0 * math.log(1.0 + math.sqrt(2.0)) * h / (math.pi * e_star)


def folded_coefficient(ya: np.ndarray, xa: np.ndarray, yb: np.ndarray, xb: np.ndarray,
                       h: float, e_star: float) -> np.ndarray:
    """Influence of element b and its three mirror images on element a.

    Coordinates [length] are element centres in the quadrant of a field that
    is mirror-symmetric about y = -h/2 and x = -h/2 (see
    `brushcore.numerics.halfspace.mirror`); the image of y is -h - y.  This is the
    operator the quadrant problem solves, so sums of it are the exact
    influence between quadrant elements.

    Returns
    -------
    numpy.ndarray
        Displacement at a per unit pressure on b and its images [length / stress].
    """
    dy, sy = ya - yb, ya + yb + h
    dx, sx = xa - xb, xa + xb + h
    return (love_coefficient(dy, dx, h, e_star) + love_coefficient(sy, dx, h, e_star)
            + love_coefficient(dy, sx, h, e_star) + love_coefficient(sy, sx, h, e_star))


def pillar_index_centroids(pillar_of: np.ndarray, iy: np.ndarray, ix: np.ndarray, h: float,
                           n_pillars: int) -> tuple[np.ndarray, np.ndarray]:
    """Each pillar's centroid (y, x) [length] from its elements' grid rows
    ``iy`` and columns ``ix`` (``pillar_of`` labels each element), in the
    index convention of the kernel: element i at i h, so that a mirror line
    lies at -h/2 (`image_coordinate`); `brushcore.model.rough.pillar_centroids`
    measures from the square's corner, (i + 1/2) h."""
    counts = np.bincount(pillar_of, minlength=n_pillars)
    cy = np.bincount(pillar_of, weights=iy * h, minlength=n_pillars) / counts
    cx = np.bincount(pillar_of, weights=ix * h, minlength=n_pillars) / counts
    return cy, cx


def pillar_influence(cy: np.ndarray, cx: np.ndarray, h: float, e_star: float,
                     mirrored: bool) -> np.ndarray:
    """Monopole influence between pillar centroids (cy, cx) [length], images
    included on a mirror quadrant, zero on the diagonal (a pillar's own
    field is in its block), shape (N, N) [length / stress]: R of the
    preconditioners' pillar-level coarse space."""
    if mirrored:
        r = folded_coefficient(cy[:, None], cx[:, None], cy[None], cx[None], h, e_star)
    else:
        r = love_coefficient(cy[:, None] - cy[None], cx[:, None] - cx[None], h, e_star)
    np.fill_diagonal(r, 0.0)
    return r


#: Signs (sy, sx) of an element's images on a mirror quadrant (see
#: `folded_coefficient`): (1, 1) is the element itself, -1 reflects that
#: coordinate about its mirror line.
MIRROR_IMAGES = ((1, 1), (-1, 1), (1, -1), (-1, -1))


def images(mirrored: bool) -> tuple[tuple[int, int], ...]:
    """The (sy, sx) image signs to sum over: all four on a mirror quadrant,
    the element alone on a whole grid."""
    return MIRROR_IMAGES if mirrored else MIRROR_IMAGES[:1]


def image_coordinate(c: np.ndarray, sign: int, h: float) -> np.ndarray:
    """A coordinate [length] of an image: c itself for sign +1, its mirror
    image -h - c for -1 (mirror line at -h/2)."""
    return c if sign > 0 else -h - c
