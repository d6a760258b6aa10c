"""How N pillars fill a hexagonal lattice: pure counting, no geometry.

Kept apart from `layout` so that `params` can refuse an impossible N at
construction time without importing the layout builders.
"""

from __future__ import annotations

import math

#: A hexagonal lattice of N = rows x columns pillars is accepted when
#: rows / columns lies within this factor of the ideal 2 / sqrt(3) (rows of
#: a triangular lattice are sqrt(3)/2 pitches apart, so r / c = 2 / sqrt(3)
#: fills a square); further off, the lattice leaves a wide empty band.
HEX_ASPECT_TOLERANCE = 1.5


def _best_pair(n_pillars: int) -> tuple[float, int, int]:
    """(log mismatch, rows, columns) of the best factor pair, more rows on a tie."""
    pairs = [(n_pillars // c, c) for c in range(1, n_pillars + 1) if n_pillars % c == 0]
    err, minus_r, c = min((abs(math.log(r / c * math.sqrt(3) / 2)), -r, c) for r, c in pairs)
    return err, -minus_r, c


def hexagonal_lattice(n_pillars: int) -> tuple[int, int] | None:
    """Rows and columns (r, c), r c = N, of the hexagonal lattice of N pillars.

    Among the factor pairs of N the one whose ratio r / c is closest (in
    log) to 2 / sqrt(3) is taken; None when even that one is more than
    HEX_ASPECT_TOLERANCE off (N = 2, 3, 5, 7, 8, any prime > 3, ...).
    """
    err, rows, cols = _best_pair(n_pillars)
    return (rows, cols) if err <= math.log(HEX_ASPECT_TOLERANCE) else None


def nearest_hexagonal_counts(n_pillars: int) -> tuple[int | None, int]:
    """The nearest counts below (None if none) and above N that `hexagonal_lattice` accepts."""
    lower = next((m for m in range(n_pillars - 1, 0, -1) if hexagonal_lattice(m)), None)
    upper = next(m for m in range(n_pillars + 1, 2 * n_pillars + 8) if hexagonal_lattice(m))
    return lower, upper


def hexagonal_pitch(rows: int, cols: int, side: float) -> float:
    """Pitch p of an r x c hexagonal lattice in the L x L square [length].

    The largest p for which the lattice with a margin of p/2 beyond its
    outer centres fits: c + 1/2 pitches wide (every other row shifted by
    p/2), (r - 1) sqrt(3)/2 + 1 pitches high.
    """
    shift = 0.5 if rows > 1 else 0.0
    return side / max(cols + shift, (rows - 1) * math.sqrt(3.0) / 2.0 + 1.0)


def hexagonal_fill(n_pillars: int) -> float:
    """Fraction of the square covered by the lattice's hexagonal cells, N (sqrt(3)/2) p^2 / L^2.

    1 for a lattice that fills the square; below 1 the pillars stand
    denser than N / L^2 (locally phi / fill) and the rest of the square is
    an empty band.  E.g. 0.767 for N = 64 (8 x 8), 0.862 for N = 56 (8 x 7).
    """
    lattice = hexagonal_lattice(n_pillars)
    if lattice is None:
        raise ValueError(f"{n_pillars} pillars do not fill a hexagonal lattice")
    p = hexagonal_pitch(*lattice, 1.0)
    return n_pillars * math.sqrt(3.0) / 2.0 * p * p
