"""Two-level tile preconditioner for pillars too large for dense block inverses.

A dense inverse of a pillar's block costs m^2 memory and m^3 time for a
pillar of m elements: 0.5 GB and minutes for one pillar of the 8 x 8 brush
at 2048^2 (m ~ 7,850).  The half-space operator K is of order -1 (its symbol
falls as 1/|q|), so a point-Jacobi preconditioner fails on the smooth modes,
where K is largest: CG needs ~ sqrt(radius / h) iterations.  (The exact
local responses that the blocks give come from small per-pillar FFT solves
on this path, `brushcore.numerics.linear.pillar_solve`, preconditioned by
`apply_pillar`.)

Grouping each pillar's elements into a x a tiles splits the residual into
its tile means, solved exactly on the coarse block K_c = R K R^T + s c c^T
(R sums over a tile's attached elements, c holds their counts), and what
varies inside a tile, where K is close to its diagonal:

    M^-1 = R^T K_c^-1 R + (I - Pi) / K_ii,      Pi = R^T diag(c)^-1 R,

with Pi the orthogonal projection onto tile-wise constants.  Both terms are
positive semi-definite on complementary subspaces, so M is SPD whatever
K_c's accuracy.  Keeping the plain Jacobi part off the smooth modes is what
makes it work: added to them (additive two-level) it leaves CG where it was.
Measured on the first solve of the 8 x 8 brush (rigid and k = 1e-3): 11-14
iterations at a = 2-4 against 37-54 for Jacobi with Sherman-Morrison and 4-7
for the dense blocks, the same at 512^2 and 1024^2: the count depends on a,
not on m.  Each application streams the stacked inverses, N mc^2 numbers
for mc tiles a pillar (0.45-0.8 ns each, against 20-40 ns a grid cell for
the padded FFTs), so a is the smallest side >= 2 that keeps them within
STACK_PER_CELL numbers per cell of the n x n grid, about a tenth of the
application, and at most MAX_TILES tiles a pillar (memory, N MAX_TILES^2
whatever the pillar size).  Larger tiles cost a few iterations (first
solve from zero to rtol 1e-6, random 64 rigid: 16 / 15 / 16 / 17 / 23 at
a = 2 / 3 / 4 / 5 / 8 on 1024^2, 17 / 19 / 21 at a = 3 / 5 / 6 on 2048^2),
so the bound is where fewer bytes stop paying: on 1024^2, 517 tiles a
pillar at a = 2 took 12.9 ms an application beside 20 ms of FFTs, 243 at
a = 3 took 3.7 ms.

K_c is assembled once per pillar shape from whole boxes less their holes
(`tile_block`), kept exact as elements detach or attach (one row of K per
changed element, aggregated by tile: m^2 over a whole curve), and its inverse is
refreshed when a pillar's attached count moved by REFRESH since the last
inversion, or a tile empty then has elements again; between refreshes the
stale inverse still gives an SPD M.
Across pillars, M is balanced with the block path's pillar-level coarse
space (`brushcore.numerics.linear.precondition`), one vector z_p = M_p^-1 1 a
pillar: it carries the pillars' forces acting on each other, about 40 %
of what the tiles missed against dense blocks (random 64 rigid on 1024^2:
9,749 against 11,115 applications; docs/SPEED.md).
Images of the mirrored quadrant are left out of K_c: they are neighbour
coupling, which block preconditioners leave to CG anyway, and leaving them
out lets equal pillars share one assembly.
"""

from __future__ import annotations

import numpy as np

from brushcore.numerics.halfspace.kernel import (love_coefficient, pillar_index_centroids,
                                                 pillar_influence, self_compliance)
from brushcore.numerics.linear.precondition import MEMORY_BUDGET, BlockInverse, coarse_inverse
from brushcore.numerics.platform.threads import stacked_matmul


class TileCoarse:
    """Per-pillar coarse blocks over a x a tiles, stacked and padded.

    Parameters
    ----------
    elements, pillar_of, n, compliance, h, e_star : as for
        `brushcore.numerics.linear.precondition.BlockInverse`
    tile : tile side a in elements (default: `tile_size`)
    threads : threads that share each application's stacked inverses
        (`brushcore.numerics.platform.threads.stacked_matmul`)
    mirrored : the grid is a mirror quadrant (the coarse space's R
        includes the images)
    coarse : allow the block path's pillar-level coarse space
        (`brushcore.numerics.linear.precondition`), with z_p = M_p^-1 1 from the
        tiles' own pillar blocks, under the same rule (1 < N <=
        `BlockInverse.MAX_COARSE`, coupling >= `BlockInverse.COUPLING_PER_PILLAR` N)
    """

    #: Most tiles a pillar may have (bounds the memory per pillar to 8 MB twice).
    MAX_TILES = 1024
    #: Most stacked coarse-inverse entries, N mc^2, per cell of the n x n grid.
    STACK_PER_CELL = 5.0
    #: Refresh a pillar's inverse once its attached count moved by this fraction.
    REFRESH = 0.1
    #: Rows of K gathered at once during assembly (bounds the temporary to ~100 MB).
    CHUNK_ELEMENTS = 12_000_000

    def __init__(self, elements: np.ndarray, pillar_of: np.ndarray, n: int,
                 compliance: np.ndarray, h: float, e_star: float,
                 tile: int | None = None, threads: int = 1, mirrored: bool = False,
                 coarse: bool = True) -> None:
        n_pillars = compliance.size
        self.threads = threads
        self.a = tile_size(elements, pillar_of, n) if tile is None else tile
        iy, ix = np.divmod(elements, n)
        self._iy, self._ix = iy, ix
        dy, dx = _from_corner(iy, ix, pillar_of, n_pillars)
        uniq, tile_index = np.unique(_tile_key(dy, dx, pillar_of, n, self.a),
                                     return_inverse=True)
        tile_pillar = uniq // (n * n)
        per_pillar = np.bincount(tile_pillar, minlength=n_pillars)
        self.mc = int(per_pillar.max())
        first = np.concatenate([[0], np.cumsum(per_pillar)[:-1]])
        slot = np.arange(uniq.size) - first[tile_pillar]
        self.tile_of = (pillar_of * self.mc + slot[tile_index]).astype(np.intp)
        self._slot = slot[tile_index]  # tile slot within its pillar, per element
        self._pillar_of = pillar_of
        self.members = np.split(np.argsort(pillar_of, kind="stable"),
                                np.cumsum(np.bincount(pillar_of, minlength=n_pillars))[:-1])
        self._live = np.ones(elements.size, dtype=bool)
        self.counts = np.bincount(self.tile_of, minlength=n_pillars * self.mc).astype(float)
        # K by offset within a pillar (what `_coarse_rows` reads): 0.1 MB
        # for the pillars of 7,850 elements at 2048^2, not the grid's 32 MB.
        span = np.arange(int(max(dy.max(), dx.max())) + 1) * h
        self._table = love_coefficient(span[:, None], span[None, :], h, e_star)
        self._compliance = np.asarray(compliance, dtype=float)
        self.kc = np.zeros((n_pillars, self.mc, self.mc))
        shapes: dict[bytes, list[int]] = {}
        for p in range(n_pillars):
            e = self.members[p]
            shapes.setdefault(np.stack([dy[e], dx[e]]).tobytes(), []).append(p)
        for group in shapes.values():
            e = self.members[group[0]]
            self.kc[group] = tile_block(dy[e], dx[e], self._slot[e], self.a, self.mc, h,
                                        e_star)
        self.inv = np.zeros_like(self.kc)
        self._factor_count = np.zeros(n_pillars)
        self._inverted = np.zeros((n_pillars, self.mc), dtype=bool)  # tiles with a coarse row
        self.refreshes = 0
        self._refresh(np.arange(n_pillars))
        self._setup_coarse(h, e_star, mirrored, coarse)

    def _setup_coarse(self, h: float, e_star: float, mirrored: bool, coarse: bool) -> None:
        """The pillar-level coarse space, where the rule allows it and E is
        positive definite: R, and each pillar's z_p = M_p^-1 1 (`z`, over
        all elements in operator order, zero at detached ones)."""
        n_pillars = self._compliance.size
        self.z = np.zeros(self._pillar_of.size)
        self.coarse = coarse and 1 < n_pillars <= BlockInverse.MAX_COARSE
        if not self.coarse:
            return
        cy, cx = pillar_index_centroids(self._pillar_of, self._iy, self._ix, h, n_pillars)
        self._r = pillar_influence(cy, cx, h, e_star, mirrored)
        self._diag = self_compliance(h=h, e_star=e_star)
        self._coarse_vectors(np.arange(n_pillars))
        if self.coarse:  # else E was not positive definite
            coupling = float((self._r @ self._c).max())
            self.coarse = coupling >= BlockInverse.COUPLING_PER_PILLAR * n_pillars

    def _coarse_vectors(self, pillars: np.ndarray) -> None:
        """z_p of the given pillars, and E = diag(c) + C R C inverted anew
        (N is small where pillars are this large: E costs less than a
        round's bookkeeping).  An E that is not positive definite
        (overlapping monopoles) turns the coarse space off; the tiles alone
        remain a valid preconditioner."""
        for p in pillars:
            members = self.members[p]
            live = members[self._live[members]]
            self.z[members] = 0.0
            if live.size:
                self.z[live] = self.apply_pillar(int(p), np.ones(live.size), live, self._diag)
        c = np.bincount(self._pillar_of, weights=self.z, minlength=self._compliance.size)
        try:
            self._e_inverse, self._c_inverse = coarse_inverse(c, self._r)
        except np.linalg.LinAlgError:
            self.coarse = False
            return
        self._c = c

    @classmethod
    def fits(cls, elements: np.ndarray, pillar_of: np.ndarray, n: int,
             budget_bytes: float = MEMORY_BUDGET) -> bool:
        """Whether the coarse blocks and their inverses fit the memory budget."""
        n_pillars = int(pillar_of.max()) + 1
        mc = max_tiles(elements, pillar_of, n, tile_size(elements, pillar_of, n))
        return 2.0 * n_pillars * mc * mc * 8.0 <= budget_bytes

    def _coarse_rows(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """R_rows K R_cols^T over the tiles of one pillar, shape (mc, mc) [length / stress]."""
        out = np.zeros((self.mc, self.mc))
        step = max(1, self.CHUNK_ELEMENTS // max(cols.size, 1))
        cy, cx, cs = self._iy[cols], self._ix[cols], self._slot[cols]
        for start in range(0, rows.size, step):
            r = rows[start:start + step]
            k = self._table[np.abs(self._iy[r][:, None] - cy[None]),
                            np.abs(self._ix[r][:, None] - cx[None])]
            # Sum over the column tiles (one bincount), then over the row tiles.
            flat = (np.arange(r.size)[:, None] * self.mc + cs[None]).ravel()
            by_col = np.bincount(flat, weights=k.ravel(),
                                 minlength=r.size * self.mc).reshape(r.size, self.mc)
            rows_at = (self._slot[r][:, None] * self.mc + np.arange(self.mc)[None]).ravel()
            out += np.bincount(rows_at, weights=by_col.ravel(),
                               minlength=self.mc * self.mc).reshape(self.mc, self.mc)
        return out

    def _refresh(self, pillars: np.ndarray) -> None:
        """Invert K_c + s c c^T of the given pillars over their occupied tiles."""
        c = self.counts.reshape(-1, self.mc)[pillars]
        block = self.kc[pillars] + (self._compliance[pillars, None, None]
                                    * c[:, :, None] * c[:, None, :])
        dead = c == 0.0
        block[dead[:, :, None] | dead[:, None, :]] = 0.0
        block[:, np.arange(self.mc), np.arange(self.mc)] += dead  # 1 on dead diagonals
        inv = np.linalg.inv(block)
        inv[dead[:, :, None] | dead[:, None, :]] = 0.0
        self.inv[pillars] = inv
        self._factor_count[pillars] = c.sum(axis=1)
        self._inverted[pillars] = ~dead
        self.refreshes += pillars.size

    def _change(self, positions: np.ndarray, sign: float) -> None:
        """Move elements (operator order) out of (sign -1) or into (+1) the attached set."""
        pillars = self._pillar_of[positions]
        touched = np.unique(pillars)
        for p in touched:
            d = positions[pillars == p]
            if sign < 0:
                self._live[d] = False
            rest = self.members[p][self._live[self.members[p]]]  # C' or, attaching, C
            # sum over C x C minus over C' x C' = D x C' + C' x D + D x D
            cross = self._coarse_rows(d, rest)
            delta = cross + cross.T + self._coarse_rows(d, d)
            self.kc[p] += sign * delta
            if sign > 0:
                self._live[d] = True
        np.add.at(self.counts, self.tile_of[positions], sign)
        counts = self.counts.reshape(-1, self.mc)[touched]
        moved = np.abs(counts.sum(axis=1) - self._factor_count[touched]) > self.REFRESH * (
            np.maximum(self._factor_count[touched], 1.0))
        # A tile that was empty at the last inversion has no coarse row: its
        # elements would see only (r - mean) / K_ii, which is zero for a lone
        # element, and M^-1 would be singular there.
        moved |= ((counts > 0) & ~self._inverted[touched]).any(axis=1)
        if moved.any():
            self._refresh(touched[moved])
        if self.coarse:
            self._coarse_vectors(touched)

    def detach(self, positions: np.ndarray) -> None:
        """Remove detached elements (operator-order indices) from the coarse blocks."""
        self._change(np.asarray(positions, dtype=np.intp), -1.0)

    def attach(self, positions: np.ndarray) -> None:
        """Add re-attached elements (operator-order indices) to the coarse blocks."""
        self._change(np.asarray(positions, dtype=np.intp), 1.0)

    def apply(self, r: np.ndarray, tile_pos: np.ndarray, diag: float,
              pillar: np.ndarray | None = None, z: np.ndarray | None = None) -> np.ndarray:
        """M^-1 r for a compressed residual r over the attached elements,
        balanced with the pillar-level coarse space when it is on (as
        `BlockInverse.apply`, with the tiles in place of the blocks).

        ``tile_pos`` is `tile_of` over the attached elements and ``diag``
        the self-compliance K_ii [length / stress]; ``pillar`` and ``z``,
        the pillar index and `z` over them, are derived when not given
        (the operator keeps them from one detachment to the next).
        """
        if not self.coarse:
            return self._two_level(r, tile_pos, diag)
        pillar = tile_pos // self.mc if pillar is None else pillar
        z = self.z[self._live] if z is None else z
        n_pillars = self._c.size
        t = np.bincount(pillar, weights=z * r, minlength=n_pillars)  # Z^T r
        y = self._e_inverse @ t
        out = self._two_level(r - (t * self._c_inverse)[pillar], tile_pos, diag)
        sums = np.bincount(pillar, weights=out, minlength=n_pillars)
        out += z * (y - sums * self._c_inverse)[pillar]
        return out

    def _two_level(self, r: np.ndarray, tile_pos: np.ndarray, diag: float) -> np.ndarray:
        """The tiles' own M^-1 r (module docstring)."""
        sums = np.bincount(tile_pos, weights=r, minlength=self.counts.size)
        mean = np.divide(sums, self.counts, out=np.zeros_like(sums), where=self.counts > 0)
        coarse = stacked_matmul(self.inv, sums.reshape(-1, self.mc, 1), self.threads).ravel()
        return coarse[tile_pos] + (r - mean[tile_pos]) / diag

    def apply_pillar(self, p: int, r: np.ndarray, members: np.ndarray,
                     diag: float) -> np.ndarray:
        """M^-1 r on pillar p alone, for a residual over its attached
        ``members`` (operator-order indices; ``diag`` as for `apply`): the
        local solves of `brushcore.numerics.linear.pillar_solve`."""
        slot = self._slot[members]
        sums = np.bincount(slot, weights=r, minlength=self.mc)
        counts = self.counts[p * self.mc:(p + 1) * self.mc]
        mean = np.divide(sums, counts, out=np.zeros_like(sums), where=counts > 0)
        return (self.inv[p] @ sums)[slot] + (r - mean[slot]) / diag


def _box_sums(field: np.ndarray, a: int) -> np.ndarray:
    """Sums of ``field`` over a x a boxes: out[y, x] = sum of field[y + u, x + v]
    for 0 <= u, v < a (a slice sum, no cumulative sums: exact order, no cancellation)."""
    ny, nx = field.shape[0] - a + 1, field.shape[1] - a + 1
    out = np.zeros((ny, nx))
    for u in range(a):
        for v in range(a):
            out += field[u:u + ny, v:v + nx]
    return out


def tile_block(dy: np.ndarray, dx: np.ndarray, slot: np.ndarray, a: int, mc: int,
               h: float, e_star: float) -> np.ndarray:
    """R K R^T over one whole pillar's a x a tiles, shape (mc, mc) [length / stress].

    The direct sum gathers m^2 coefficients (62 M for a pillar of 7,850
    elements: 98 s for the 64 shapes of a random brush at 2048^2).  Here
    each tile is its full a x a box less its holes (box cells outside the
    pillar): full box against full box is one table entry per pair of
    tiles, a hole against a full box one entry of the box-summed kernel per
    (hole, tile), and hole against hole the kernel itself, so the work is
    ~ mc^2 + holes x mc + holes^2, with holes only in the rim's tiles.

    Parameters
    ----------
    dy, dx : the pillar's element offsets from its lower corner [elements]
    slot : each element's tile slot, 0 .. T-1 for the pillar's T tiles in
        (dy // a, dx // a) order (as `TileCoarse` numbers them)
    a : tile side [elements]
    mc : tile slots a pillar (rows of the result)
    h : element side [length]
    e_star : effective modulus E* [stress]
    """
    n_tiles = int(slot.max()) + 1
    ty = np.zeros(n_tiles, dtype=np.intp)
    tx = np.zeros(n_tiles, dtype=np.intp)
    ty[slot], tx[slot] = dy // a, dx // a
    span = int(max(ty.max(), tx.max())) + 1  # tiles along the longer side
    reach = a * span + a  # largest |offset| any sum below needs, plus a box
    ar = np.abs(np.arange(-reach, reach + 1)) * h
    k = love_coefficient(ar[:, None], ar[None, :], h, e_star)  # K(y, x), |y|, |x| <= reach
    # g[y, x] = sum of K(y - u, x - v) over the box 0 <= u, v < a: a hole at
    # offset y, x from a tile's corner against that whole tile.
    g = _box_sums(k, a)  # index y + reach - a + 1
    g0 = reach - a + 1
    # Full box against full box at corner offset a (i, j): sum over both boxes.
    bb = _box_sums(g, a)  # index y + g0 (box start 0 of the first box)
    # Holes: cells of each tile's box that are not pillar elements.
    cells = np.zeros((n_tiles, a, a), dtype=bool)
    cells[slot, dy % a, dx % a] = True
    hole_tile, hu, hv = np.nonzero(~cells)
    hy, hx = a * ty[hole_tile] + hu, a * tx[hole_tile] + hv  # from the pillar's corner
    block = bb[a * (ty[:, None] - ty[None, :]) + g0, a * (tx[:, None] - tx[None, :]) + g0]
    per_tile = np.zeros((n_tiles, n_tiles))  # holes of tile s against tile t's box
    pairs = np.zeros(n_tiles * n_tiles)  # holes of tile s against holes of tile t
    # Rows of holes at a time: a ragged footprint (a layout file's) can have
    # as many holes as elements, and the temporaries must stay bounded.
    step = max(1, TileCoarse.CHUNK_ELEMENTS // max(hy.size, n_tiles))
    for lo in range(0, hy.size, step):
        y, x, t = hy[lo:lo + step, None], hx[lo:lo + step, None], hole_tile[lo:lo + step]
        np.add.at(per_tile, t, g[y - a * ty[None, :] + g0, x - a * tx[None, :] + g0])
        both = k[y - hy[None, :] + reach, x - hx[None, :] + reach]
        flat = (t[:, None] * n_tiles + hole_tile[None, :]).ravel()
        pairs += np.bincount(flat, weights=both.ravel(), minlength=pairs.size)
    block -= per_tile + per_tile.T
    block += pairs.reshape(n_tiles, n_tiles)
    out = np.zeros((mc, mc))
    out[:n_tiles, :n_tiles] = block
    return out


def _from_corner(iy: np.ndarray, ix: np.ndarray, pillar_of: np.ndarray,
                 n_pillars: int) -> tuple[np.ndarray, np.ndarray]:
    """Element offsets from their pillar's lower corner [elements]: tiles start
    there, so equal footprints tile alike."""
    y0 = np.full(n_pillars, np.iinfo(np.intp).max)
    x0 = np.full(n_pillars, np.iinfo(np.intp).max)
    np.minimum.at(y0, pillar_of, iy)
    np.minimum.at(x0, pillar_of, ix)
    return iy - y0[pillar_of], ix - x0[pillar_of]


def _tile_key(dy: np.ndarray, dx: np.ndarray, pillar_of: np.ndarray, n: int,
              a: int) -> np.ndarray:
    """A key per element, equal for the elements of one a x a tile of one pillar."""
    return (pillar_of.astype(np.int64) * n + dy // a) * n + dx // a


def max_tiles(elements: np.ndarray, pillar_of: np.ndarray, n: int, a: int) -> int:
    """Most a x a tiles any pillar covers."""
    iy, ix = np.divmod(elements, n)
    n_pillars = int(pillar_of.max()) + 1
    dy, dx = _from_corner(iy, ix, pillar_of, n_pillars)
    return int(np.bincount(np.unique(_tile_key(dy, dx, pillar_of, n, a)) // (n * n)).max())


def tile_size(elements: np.ndarray, pillar_of: np.ndarray, n: int) -> int:
    """Smallest tile side a >= 2 [elements] giving at most MAX_TILES tiles a
    pillar and a stack of N mc^2 <= STACK_PER_CELL n^2 coarse entries."""
    n_pillars = int(pillar_of.max()) + 1
    most = min(TileCoarse.MAX_TILES, int(np.sqrt(TileCoarse.STACK_PER_CELL * n * n / n_pillars)))
    a = 2
    while max_tiles(elements, pillar_of, n, a) > most:
        a += 1
    return a
