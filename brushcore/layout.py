"""Pillar layouts as label maps on the n x n grid.

An element belongs to pillar p when its centre lies inside p's disc.  The
label map holds the pillar index per element and -1 elsewhere; everything
downstream (springs, snapshots, counts) works from it, so any layout
(or a per-pillar stiffness) plugs in without touching the solver.
"""

from __future__ import annotations

import math

import numpy as np

from .params import FLOOR_RADIUS_ELEMENTS, MAX_PHI_ERROR, BrushParams, ParameterError


def regular_centres(n_pillars: int, side: float) -> np.ndarray:
    """Centres of a sqrt(N) x sqrt(N) lattice of pitch L / sqrt(N), shape (N, 2) [length].

    N = 1 gives one punch in the middle of the square.
    """
    m = math.isqrt(n_pillars)
    pitch = side / m
    c = (np.arange(m) + 0.5) * pitch
    yy, xx = np.meshgrid(c, c, indexing="ij")
    return np.column_stack([yy.ravel(), xx.ravel()])


def random_centres(n_pillars: int, side: float, radius: float, gap: float,
                   seed: int, max_attempts: int = 2000) -> np.ndarray:
    """Random sequential addition of N equal discs inside the L x L square.

    Parameters
    ----------
    n_pillars : number of discs N
    side : square side L [length]
    radius : disc radius a_p [length]
    gap : minimum distance between disc edges [length]
    seed : seed of numpy's default Generator
    max_attempts : rejected trials allowed per disc before giving up

    Returns
    -------
    numpy.ndarray, shape (N, 2)
        Centres (y, x) [length], every disc fully inside the square.

    Raises
    ------
    ParameterError
        When a disc cannot be placed within ``max_attempts`` trials (N and
        phi too dense for random sequential addition, whose jamming limit
        for discs is a covered fraction of about 0.547).
    """
    rng = np.random.default_rng(seed)
    lo, hi = radius, side - radius
    if hi < lo:
        raise ParameterError("n_pillars", n_pillars, "fewer or smaller pillars",
                             f"pillar radius {radius:.3g} > L/2 = {side / 2:.3g}")
    min_dist2 = (2.0 * radius + gap) ** 2
    # A cell grid of size >= the exclusion distance: only 3 x 3 neighbours matter.
    cell = math.sqrt(min_dist2)
    ncell = max(1, int(side // cell))
    cell = side / ncell
    grid: dict[tuple[int, int], list[int]] = {}
    centres = np.empty((n_pillars, 2))
    for p in range(n_pillars):
        for _ in range(max_attempts):
            c = rng.uniform(lo, hi, size=2)
            cy, cx = int(c[0] // cell), int(c[1] // cell)
            ok = True
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    for q in grid.get((cy + dy, cx + dx), ()):
                        if np.sum((centres[q] - c) ** 2) <= min_dist2:
                            ok = False
                            break
                    if not ok:
                        break
                if not ok:
                    break
            if ok:
                centres[p] = c
                grid.setdefault((cy, cx), []).append(p)
                break
        else:
            raise ParameterError(
                "n_pillars", n_pillars, "fewer pillars, a smaller phi or a smaller min_gap",
                f"random layout: only {p} discs of radius {radius:.3g} with gap {gap:.3g} "
                f"fitted, {max_attempts} trials failed for the next")
    return centres


def label_map(centres: np.ndarray, radius: float, n: int, h: float) -> np.ndarray:
    """Pillar index of each element (-1 outside all pillars), shape (n, n).

    Each disc only touches the elements in its bounding box, so the cost is
    O(N a^2), not O(N n^2).
    """
    labels = np.full((n, n), -1, dtype=np.int32)
    r_el = radius / h
    for p, (cy, cx) in enumerate(centres / h):
        i0, i1 = max(0, int(math.floor(cy - r_el)) - 1), min(n, int(math.ceil(cy + r_el)) + 1)
        j0, j1 = max(0, int(math.floor(cx - r_el)) - 1), min(n, int(math.ceil(cx + r_el)) + 1)
        yy = np.arange(i0, i1)[:, None] + 0.5 - cy
        xx = np.arange(j0, j1)[None, :] + 0.5 - cx
        inside = yy**2 + xx**2 <= r_el**2
        block = labels[i0:i1, j0:j1]
        if np.any(block[inside] >= 0):
            raise ParameterError(f"pillar {p} overlaps another on the grid: allowed layouts "
                                 "whose pillars do not share elements")
        block[inside] = p
    return labels


def build_labels(params: BrushParams) -> np.ndarray:
    """The label map of a parameter set, checked so that every pillar has elements.

    Raises
    ------
    ParameterError
        If a pillar covers no element centre (grid too coarse) or a random
        layout cannot be packed.
    """
    if params.layout == "regular":
        centres = regular_centres(params.n_pillars, params.side)
    else:
        centres = random_centres(params.n_pillars, params.side, params.pillar_radius,
                                 params.min_gap * params.h, params.seed)
    labels = label_map(centres, params.pillar_radius, params.grid, params.h)
    check_discretisation(params, labels)
    return labels


def check_discretisation(params: BrushParams, labels: np.ndarray) -> None:
    """Refuse a label map that misrepresents the requested brush.

    Every pillar must cover an element; unless ``params.allow_coarse``, the
    realised filling factor must lie within MAX_PHI_ERROR of the requested
    one (the pillar radius rule is checked by `BrushParams` itself).

    Raises
    ------
    ParameterError
        Naming ``grid``, with the smallest grid that would do where it can
        be computed, and the realised values.
    """
    counts = np.bincount(labels[labels >= 0], minlength=params.n_pillars)
    r = params.pillar_radius_elements
    if np.any(counts == 0):
        raise ParameterError(
            "grid", params.grid, f"grid >= {math.ceil(FLOOR_RADIUS_ELEMENTS * params.grid / r)}",
            f"{int(np.sum(counts == 0))} pillars of radius {r:.3g} elements cover no "
            "element centre")
    phi_actual = float(counts.sum()) / labels.size
    error = phi_actual / params.phi - 1.0
    if abs(error) > MAX_PHI_ERROR and not params.allow_coarse:
        raise ParameterError(
            "grid", params.grid, "a finer grid (or allow_coarse to run it anyway)",
            f"phi is realised as {phi_actual:.4g} instead of {params.phi:g} "
            f"({100 * error:+.1f} %, more than {100 * MAX_PHI_ERROR:g} %) with a pillar "
            f"radius of {r:.3g} elements")
