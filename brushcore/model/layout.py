"""Pillar layouts as label maps on the n x n grid.

An element belongs to pillar p when its centre lies inside p's
cross-section (a disc, square or ellipse, see `shapes`).  The label map
holds the pillar index per element and -1 elsewhere; everything
downstream (springs, snapshots, counts) works from it, so any layout
(or a per-pillar stiffness) plugs in without touching the solver.

Layouts: "regular" (square lattice), "random" (random sequential
addition), "hexagonal" (triangular lattice, see `hexagonal_centres`) and
"file" (a label map or an image, see `layout_file`, or a table of disc
and ellipse pillars drawn on any grid, see `pillar_table`).  Pillars of one map
never touch: no two different pillars share an element edge (4-neighbour
adjacency); a shared corner is allowed.  (Random discs on a grid coarser
than 512 are the exception: their gap is a fixed length, `random_gap`,
which can be less than one of those elements; so are a table's discs,
whose gap is the table's.)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from brushcore.model.lattices import hexagonal_lattice, hexagonal_pitch
from brushcore.model.labelmap import check_not_touching, pillar_element_counts
from brushcore.model.layout_file import check_file_values, read_label_map
from brushcore.model.pillar_table import PillarTable, is_table, read_pillar_table
from brushcore.model.params import (FLOOR_RADIUS_ELEMENTS, MAX_GRID, MAX_PHI_ERROR, MIN_GRID,
                                    RANDOM_GAP_GRID, BrushParams)
from brushcore.validation import ParameterError, is_integer, require
from brushcore.model.shapes import PillarShape


def random_gap(params: BrushParams) -> float:
    """The smallest gap between the edges of a random layout's pillars
    [length]: ``min_gap`` elements of the `RANDOM_GAP_GRID` grid, the same
    length L min_gap / 512 whatever ``params.grid``.  On a grid coarser
    than 512 it spans less than an element, so neighbouring footprints may
    share an edge there: the mesh's error, which a refinement study sees."""
    return params.min_gap * params.side / RANDOM_GAP_GRID


class LayoutError(ValueError):
    """Generated pillars overlap or leave the square; `build_labels` names the parameters.

    ``grid_helps``: whether a finer grid could draw the layout (pillars that
    meet on the grid), not one that leaves the square on every grid.
    """

    def __init__(self, message: str, grid_helps: bool = True) -> None:
        super().__init__(message)
        self.grid_helps = grid_helps


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
                   seed: int, max_attempts: int = 2000, what: str = "discs") -> np.ndarray:
    """Random sequential addition of N equal discs inside the L x L square.

    Parameters
    ----------
    n_pillars : number of discs N
    side : square side L [length]
    radius : disc radius a_p [length]
    gap : minimum distance between disc edges [length]
    seed : seed of numpy's default Generator
    max_attempts : rejected trials allowed per disc before giving up
    what : what the discs are, as a refusal names them ("discs", or the
        pillars whose circumscribed discs they are)

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
                f"random layout: only {p} {what} of radius {radius / side:.3g} L with gaps "
                f"of at least {gap / side * RANDOM_GAP_GRID:.3g} L/{RANDOM_GAP_GRID} "
                "(the minimum gap) "
                f"fitted, {max_attempts} trials failed for the next")
    return centres


def hexagonal_centres(n_pillars: int, side: float) -> np.ndarray:
    """Centres of a triangular lattice of N pillars in the L x L square, shape (N, 2) [length].

    The N = r x c pillars (`lattices.hexagonal_lattice`) stand in r rows of
    c, every other row shifted by half a pitch p, rows p sqrt(3)/2 apart, so that
    each pillar's nearest neighbours are all p away.  The pitch is the
    largest for which the lattice, with a margin of p/2 beyond the outer
    centres (the regular lattice's rule: the wall gap is half the pillar
    gap), fits the square; the lattice is centred, so the empty band the
    factorisation leaves is split between opposite sides.  The pitch thus
    follows from N and L alone; phi sets the pillar size.  Where r / c is
    not 2 / sqrt(3) the lattice covers only a part of the square
    (`lattices.hexagonal_fill`, 0.767 for N = 64), where the pillars stand
    denser than N / L^2.
    """
    lattice = hexagonal_lattice(n_pillars)
    if lattice is None:  # BrushParams refuses such N with a message
        raise ValueError(f"{n_pillars} pillars do not fill a hexagonal lattice")
    rows, cols = lattice
    shift = 0.5 if rows > 1 else 0.0
    dy = math.sqrt(3.0) / 2.0
    pitch = hexagonal_pitch(rows, cols, side)
    i, j = np.divmod(np.arange(n_pillars), cols)
    y = i * dy * pitch
    x = (j + shift * (i % 2)) * pitch
    y += 0.5 * (side - y.max() - y.min())
    x += 0.5 * (side - (cols - 1 + shift) * pitch)
    return np.column_stack([y, x])


def label_map(centres: np.ndarray, radius: float | np.ndarray, n: int, h: float
              ) -> np.ndarray:
    """Pillar index of each element (-1 outside all pillars), shape (n, n):
    discs of ``radius`` (one for all, or one a pillar) [length] at
    ``centres`` (y, x) [length] on n x n elements of size ``h``.

    Each disc only touches the elements in its bounding box, so the cost is
    O(N a^2), not O(N n^2).
    """
    labels = np.full((n, n), -1, dtype=np.int32)
    radii = np.broadcast_to(np.asarray(radius, dtype=float), (len(centres),))
    for p, (cy, cx) in enumerate(centres / h):
        r_el = radii[p] / h
        i0, i1 = max(0, int(math.floor(cy - r_el)) - 1), min(n, int(math.ceil(cy + r_el)) + 1)
        j0, j1 = max(0, int(math.floor(cx - r_el)) - 1), min(n, int(math.ceil(cx + r_el)) + 1)
        yy = np.arange(i0, i1)[:, None] + 0.5 - cy
        xx = np.arange(j0, j1)[None, :] + 0.5 - cx
        inside = yy**2 + xx**2 <= r_el**2
        block = labels[i0:i1, j0:j1]
        if np.any(block[inside] >= 0):  # discs that touch where an element centre lies
            q = int(block[inside & (block >= 0)][0])
            raise ParameterError("grid", n, "a grid whose element centres no two pillars "
                                 "share", f"pillars {q} and {p} share an element")
        block[inside] = p
    return labels


def shape_label_map(centres: np.ndarray, shape: PillarShape, area: float, n: int,
                    h: float) -> np.ndarray:
    """Label map of equal pillars of any shape, shape (n, n) (-1 outside all pillars).

    Parameters
    ----------
    centres : pillar centres (y, x), shape (N, 2) [length]
    shape : the cross-section of every pillar
    area : cross-section A_p of one pillar [length^2]
    n, h : elements per side and element size [length]

    Raises
    ------
    LayoutError
        If two pillars claim the same element, or a pillar reaches beyond
        the L x L square (naming the pillars).
    """
    return shapes_label_map(centres, [shape] * len(centres), np.full(len(centres), area), n, h)


#: Relative slack of `shapes_label_map`'s check that pillars lie inside the square.
EDGE_SLACK = 1e-12


def shapes_label_map(centres: np.ndarray, shapes: Sequence[PillarShape], areas: np.ndarray,
                     n: int, h: float) -> np.ndarray:
    """`shape_label_map` with a shape and an area [length^2] for each pillar
    (a pillar table's discs and ellipses).

    Raises
    ------
    LayoutError
        As `shape_label_map`.
    """
    labels = np.full((n, n), -1, dtype=np.int32)
    side = n * h
    # a hair of slack: a pillar that touches the edge (a table's, checked in
    # units of L) must not be refused by rounding in units of elements
    slack = EDGE_SLACK * n
    for p, (cy, cx) in enumerate(centres / h):
        shape, area = shapes[p], float(areas[p])
        ey, ex = (e / h for e in shape.half_extents(area))
        if cy - ey < -slack or cx - ex < -slack or cy + ey > n + slack or cx + ex > n + slack:
            raise LayoutError(f"pillar {p} at (y, x) = ({cy * h:.4g}, {cx * h:.4g}) reaches "
                              f"beyond the {side:.4g} x {side:.4g} square", grid_helps=False)
        i0, i1 = max(0, int(math.floor(cy - ey)) - 1), min(n, int(math.ceil(cy + ey)) + 1)
        j0, j1 = max(0, int(math.floor(cx - ex)) - 1), min(n, int(math.ceil(cx + ex)) + 1)
        yy = (np.arange(i0, i1)[:, None] + 0.5 - cy) * h
        xx = (np.arange(j0, j1)[None, :] + 0.5 - cx) * h
        inside = shape.contains(yy, xx, area)
        block = labels[i0:i1, j0:j1]
        if np.any(block[inside] >= 0):
            q = int(block[inside & (block >= 0)][0])
            raise LayoutError(f"pillars {q} and {p} overlap on the grid")
        block[inside] = p
    return labels


def pillar_shape(params: BrushParams) -> PillarShape:
    """The cross-section of the pillars of a generated layout."""
    return PillarShape(params.shape, params.aspect, params.orientation)


def generated_centres(params: BrushParams) -> np.ndarray:
    """Pillar centres (y, x) of a regular, random or hexagonal layout, shape (N, 2) [length].

    The random layout keeps the circumscribed discs of the pillars apart by
    `random_gap` (exact for discs, conservative for squares and ellipses,
    which keep the orientation of ``params``); it is one brush on every
    grid: the centres scale with L, and nothing else depends on the grid.
    """
    if params.layout == "regular":
        return regular_centres(params.n_pillars, params.side)
    if params.layout == "hexagonal":
        return hexagonal_centres(params.n_pillars, params.side)
    radius = (params.pillar_radius if params.shape == "disc"
              else pillar_shape(params).circumradius(params.pillar_area))
    try:
        return random_centres(params.n_pillars, params.side, radius,
                              random_gap(params), params.seed,
                              what="discs" if params.shape == "disc" else
                              f"{params.shape}s (their circumscribed discs)")
    except ParameterError as exc:
        if params.min_gap > 1.0:
            raise
        # the gap is at its least: a smaller one is no way out
        raise ParameterError(exc.name, exc.value, "fewer pillars or a smaller phi",
                             exc.reason) from None


#: Grids tried above a refused one for the grid a message suggests: the
#: realised phi is not monotone in the grid (regular 16 at phi 0.05: 64
#: refused, 65 runs, 68 refused), so the next grid that passes is searched.
GRID_HINT_TRIES = 64


def next_grid(make: Callable[[int], BrushParams], start: int) -> int | None:
    """The smallest grid from ``start`` on at which the brush passes every check.

    Parameters
    ----------
    make : grid -> the parameters of the brush on that grid (raising
        `ParameterError` where a grid fails the pillar radius rule)
    start : first grid tried

    Returns
    -------
    int or None
        The grid, or None when none up to `MAX_GRID` passes the radius rule
        or ``GRID_HINT_TRIES`` grids past it all fail the layout's checks.

    Raises
    ------
    ParameterError
        The layout's own error where no grid can help: one about another
        parameter than the grid or phi (a random brush too dense to pack,
        whose gap scales with L, fails alike on every grid; trying 64 of
        them took minutes for 100,000 pillars).
    """
    tries = 0
    for grid in range(max(start, 1), MAX_GRID + 1):
        try:
            params = make(grid)
        except ParameterError:
            continue  # below the radius rule's grid: no label map to build
        try:
            _checked_labels(params)
            return grid
        except ParameterError as exc:
            if exc.name not in ("grid", "phi"):
                raise
            tries += 1
            if tries >= GRID_HINT_TRIES:
                return None
    return None


def next_common_grid(makes: Sequence[Callable[[int], BrushParams]], start: int) -> int | None:
    """The smallest grid from ``start`` on at which every brush of ``makes``
    passes every check (`next_grid` of each, raised until they agree); None
    where one has no such grid."""
    grid = start
    for _ in range(GRID_HINT_TRIES):
        found = [next_grid(make, grid) for make in makes]
        if None in found:
            return None
        if min(found) == max(found):
            return found[0]
        grid = max(found)
    return None


def grid_hint(exc: ParameterError, make: Callable[[int], BrushParams], grid: int,
              others: Sequence[Callable[[int], BrushParams]] = ()) -> ParameterError:
    """``exc`` suggesting the next grid above ``grid`` that passes every check.

    The pillar radius rule alone names a grid that the filling factor's
    check may refuse (random 64 square pillars: 82 by the radius, refused
    at +5.3 % phi); this names one that runs, for ``make`` and for the
    ``others`` that share its grid (a config's brushes: a grid that runs
    one of them only would be refused again for the next).  Errors about
    other parameters, and grid errors with no such grid, come back unchanged;
    where the search meets an error no grid can fix (a random brush too
    dense to pack), that error comes back.
    """
    if exc.name != "grid" or not (is_integer(grid) and MIN_GRID <= grid <= MAX_GRID):
        return exc  # a grid out of range is told its range, not a neighbour
    try:
        found = next_common_grid([make, *others], grid + 1)
    except ParameterError as unfixable:  # no grid runs it: say why instead
        return unfixable
    if found is None:
        return exc
    coarse = (", or allow_coarse to run it anyway" if "allow_coarse to run it anyway"
              in exc.allowed else "")
    which = "every brush that shares it" if others else "the pillars"
    params = make(found)
    if params.allow_coarse:  # phi was not checked there: say what it comes out as
        labels = build_labels(params)
        phi = f"realises phi as {np.count_nonzero(labels >= 0) / labels.size:.3g} " \
              f"(allow_coarse: not checked; {params.phi:g} asked for)"
    else:
        phi = f"realises phi within {100 * MAX_PHI_ERROR:g} %"
    return ParameterError("grid", exc.value, f"grid {found}, the next that resolves {which} "
                          f"and {phi}" + coarse, exc.reason)


def hinted_params(make: Callable[[int], BrushParams], grid: int,
                  others: Sequence[Callable[[int], BrushParams]] = ()) -> BrushParams:
    """``make(grid)``, a grid it refuses naming the next grid that passes every
    check (`grid_hint`) for it and the ``others`` on the same grid, not only
    the pillar radius rule (the CLI's and the workflow's way to build a
    brush from what the user typed)."""
    try:
        return make(grid)
    except ParameterError as exc:
        raise grid_hint(exc, make, grid, others) from None


def build_labels(params: BrushParams) -> np.ndarray:
    """The label map of a parameter set, checked so that every pillar has elements.

    Regular and random layouts of discs are painted by `label_map` from
    centres whose construction keeps the discs apart.  Other shapes, the
    hexagonal lattice and file layouts are also checked for touching
    pillars (a shared element edge).

    Raises
    ------
    ParameterError
        If a pillar covers no element centre (grid too coarse), a random
        layout cannot be packed, pillars overlap, touch or leave the
        square, or a layout file does not fit (see `layout_file`); a grid
        that fails names the next one that passes (`grid_hint`).
    """
    try:
        return _checked_labels(params)
    except ParameterError as exc:
        if params.layout == "file" and not is_table(params.layout_file):
            raise  # a map or image fits its own grid only
        def make(grid: int) -> BrushParams:
            # a gap map fits one grid only, and the label map does not depend on it
            return replace(params, grid=grid, gap_map=None)

        hinted = grid_hint(exc, make, params.grid)
        if hinted is exc and smallest_pillar(params):
            # a table's smallest disc may need more grids than the search tries:
            # search on from where it is resolved wherever it sits
            floor = min(_table_grid_floor(params), MAX_GRID) - 1
            hinted = grid_hint(exc, make, max(params.grid, floor))
            if hinted is not exc:  # not the first grid that passes: one from the floor
                hinted = ParameterError(hinted.name, hinted.value, hinted.allowed.replace(
                    ", the next that", ", on which the smallest disc is three elements "
                    "across wherever it sits, that", 1), hinted.reason)
        raise hinted from None


def _checked_labels(params: BrushParams) -> np.ndarray:
    """`build_labels` without the search for a grid to suggest."""
    if params.layout == "file" and is_table(params.layout_file):
        # Discs apart (the table's check) may share element edges on a grid too
        # coarse for their gap: counted, as for random discs, not refused.
        table = read_pillar_table(params.layout_file)
        labels = table_labels(table, params.grid)
        _check_file_matches(params, table.n_pillars, table.phi, "pi sum r^2")
        check_discretisation(params, labels)
        _check_pillar_widths(params, labels, "grid", params.grid, "a finer grid")
        return labels
    if params.layout == "file":
        labels = read_label_map(params.layout_file, params.grid)
        _check_file_matches(params, int(labels.max()) + 1,
                            float(np.count_nonzero(labels >= 0)) / labels.size)
        check_discretisation(params, labels)
        _check_pillar_widths(params, labels, "layout_file", params.layout_file,
                             "the layout drawn finer")
        return labels
    centres = generated_centres(params)
    if params.shape == "disc" and params.layout in ("regular", "random"):
        labels = label_map(centres, params.pillar_radius, params.grid, params.h)
    else:
        try:
            labels = shape_label_map(centres, pillar_shape(params), params.pillar_area,
                                     params.grid, params.h)
        except LayoutError as exc:
            raise ParameterError("phi", params.phi, "a smaller phi, fewer pillars, a more "
                                 "compact shape" + (" or a finer grid" if exc.grid_helps
                                                    else ""), str(exc)) from None
        check_not_touching(labels, "phi", params.phi)
    check_discretisation(params, labels)
    return labels


def _check_file_matches(params: BrushParams, n_file: int, phi_file: float,
                        phi_meaning: str = "") -> None:
    """The file's pillar count and filling factor (a map's realised one, a
    table's pi sum r^2) must be the parameters' own (`brushcore.file_params`
    sets them)."""
    check_file_values(params.layout_file, {"n_pillars": params.n_pillars, "phi": params.phi},
                      {"n_pillars": n_file, "phi": phi_file}, phi_meaning)


def table_labels(table: PillarTable, grid: int) -> np.ndarray:
    """A pillar table's label map on ``grid`` x ``grid`` elements (the table
    is in units of L, so the element size is 1 / grid), drawn as
    generated discs (`label_map`) and ellipses (`shapes_label_map`) are."""
    if not table.has_ellipses:
        return label_map(table.centres, table.radii, grid, 1.0 / grid)
    shapes = [table.shape(p) for p in range(table.n_pillars)]
    try:
        return shapes_label_map(table.centres, shapes, math.pi * table.radii**2, grid,
                                1.0 / grid)
    except LayoutError as exc:  # inside the square and apart: pillars meet on this grid
        raise ParameterError("grid", grid, "a grid whose element centres no two pillars "
                             "share", str(exc)) from None


def generated_table(params: BrushParams) -> PillarTable:
    """A generated layout of discs as a pillar table (units of L), to run it
    on other grids or give it measured heights (`save_pillar_table`).

    Raises
    ------
    ParameterError
        For square pillars (a table holds discs and ellipses) and for file
        layouts.
    """
    require(params.layout != "file", "layout", params.layout,
            "a generated layout (regular, hexagonal, random): a file brush is its file")
    require(params.shape != "square", "shape", params.shape,
            "disc or ellipse: a pillar table holds discs and ellipses")
    centres = generated_centres(params) / params.side
    radii = np.full(params.n_pillars, params.pillar_radius / params.side)
    if params.shape == "disc":
        return PillarTable(centres, radii)
    return PillarTable(centres, radii, np.full(params.n_pillars, float(params.aspect)),
                       np.full(params.n_pillars, float(params.orientation)))


#: A disc of this radius [elements] holds an element whose four edge neighbours
#: lie in it wherever it sits (the element nearest its centre is within
#: sqrt(1/2), those neighbours within 1 + sqrt(1/2)): `_check_pillar_widths`.
WIDE_RADIUS_ELEMENTS = 1.0 + math.sqrt(0.5)


def smallest_pillar(params: BrushParams) -> float | None:
    """A pillar table's narrowest pillar half-width in elements on
    ``params.grid`` (a disc's radius, an ellipse's semi-minor axis), None
    for other layouts (whose pillars the radius rule reads alike)."""
    if params.layout != "file" or not is_table(params.layout_file):
        return None
    return float(read_pillar_table(params.layout_file).narrowest.min()) * params.grid


def smallest_radius_elements(params: BrushParams, labels: np.ndarray) -> float:
    """The narrowest pillar's radius on ``params.grid`` [elements]: what the
    resolution flags read, since one coarse pillar sets a brush's mesh error.

    A generated brush's pillars are alike: its radius rule's
    (`BrushParams.narrowest_radius_elements`; an ellipse's semi-minor axis).
    A pillar table's smallest disc; a label map's or image's smallest pillar
    as the equal-area radius of its elements.
    """
    if params.layout != "file":
        return params.narrowest_radius_elements
    smallest = smallest_pillar(params)
    if smallest is not None:
        return smallest
    counts = pillar_element_counts(labels, int(labels.max()) + 1)
    return math.sqrt(float(counts.min()) / math.pi)


def pillars_differ(narrowest: float, mean: float) -> bool:
    """Whether a brush's narrowest pillar radius lies clearly under its mean
    equal-area radius (by over 1 %): unequal or elliptic pillars, which the
    messages and the summary name as such."""
    return narrowest < 0.99 * mean


def _table_grid_floor(params: BrushParams) -> int:
    """The grid from which a table's smallest disc covers an element centre
    (allow_coarse) or is three elements across (`WIDE_RADIUS_ELEMENTS`)
    wherever it sits: where `build_labels` searches a grid to suggest."""
    smallest = float(read_pillar_table(params.layout_file).narrowest.min())  # [L]
    floor = FLOOR_RADIUS_ELEMENTS if params.allow_coarse else WIDE_RADIUS_ELEMENTS
    return math.ceil(floor / smallest)


def _check_pillar_widths(params: BrushParams, labels: np.ndarray, name: str, value: object,
                         finer: str) -> None:
    """Refuse a file layout with a pillar no element of which has all four
    edge neighbours in the pillar (at most two elements across: a strip of
    width 1 or 2, a 2 x 2 block), unless ``params.allow_coarse``.

    The radius rule of `BrushParams` takes a file's mean equal-area radius,
    which one large pillar can lift over the rule while others are single
    elements.  Judged per pillar, by each element's distance to the nearest
    element outside all pillars: the paper's finest brush (2304 pillars on
    512^2, 12-14 elements each) has an element at sqrt(2) in every pillar,
    a strip two elements wide none beyond 1.
    """
    if params.allow_coarse:
        return
    from scipy import ndimage  # noqa: PLC0415 - file layouts only

    depth = ndimage.distance_transform_edt(np.pad(labels >= 0, 1))[1:-1, 1:-1]
    deepest = ndimage.maximum(depth, labels, index=np.arange(params.n_pillars))
    thin = np.flatnonzero(np.asarray(deepest) < math.sqrt(2.0) - 1e-9)
    if thin.size:
        counts = pillar_element_counts(labels, params.n_pillars)
        raise ParameterError(
            name, value, f"{finer}, every pillar at least three elements across (or "
            "allow_coarse to run it anyway)",
            f"{thin.size} of {params.n_pillars} pillars are at most two elements across, "
            f"pillar {int(thin[0])} of {int(counts[thin[0]])} elements among them: too coarse "
            "for a meaningful detachment criterion"
            + ("; in an image, stray dark pixels are pillars too: clean them away"
               if str(value).lower().endswith(".png") else ""))


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
    counts = pillar_element_counts(labels, params.n_pillars)
    # an ellipse's semi-minor axis, as the radius rule reads it: its
    # equal-area radius would suggest a grid that still misses its centres;
    # a table's smallest disc, not the mean one (a stub among pillars)
    smallest = smallest_pillar(params)
    r = smallest or params.narrowest_radius_elements
    what = "semi-minor axis" if params.shape == "ellipse" else "radius"
    if np.any(counts == 0):
        empty = int(np.sum(counts == 0))
        raise ParameterError(
            "grid", params.grid, f"grid >= {math.ceil(FLOOR_RADIUS_ELEMENTS * params.grid / r)}",
            f"{empty} of {params.n_pillars} pillars cover no element centre; the smallest "
            f"disc's radius is {r:.3g} elements" if smallest else
            f"{empty} pillar{'s' * (empty != 1)} of {what} {r:.3g} elements cover"
            f"{'s' * (empty == 1)} no element centre")
    phi_actual = float(counts.sum()) / labels.size
    error = phi_actual / params.phi - 1.0
    if abs(error) > MAX_PHI_ERROR and not params.allow_coarse:
        raise ParameterError(
            "grid", params.grid, "a finer grid (or allow_coarse to run it anyway)",
            f"phi is realised as {phi_actual:.4g} instead of {params.phi:g} "
            f"({100 * error:+.1f} %, more than {100 * MAX_PHI_ERROR:g} %) with a pillar "
            f"{what} of {r:.3g} elements")
