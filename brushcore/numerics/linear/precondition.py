"""Per-pillar block preconditioner: the exact inverse of each pillar's own block.

Within a pillar the operator is B_p = K_pp + s_p 1 1^T (elastic self
interaction plus the spring), and it couples to other pillars only through
the comparatively weak far field of K.  Inverting each B_p exactly leaves CG
only the inter-pillar interaction to resolve.  When elements detach, the
inverse of the reduced block follows from a rank-|D| downdate,

    G' = G - G[:, D] G[D, D]^-1 G[D, :],

which leaves exact zeros in the rows and columns of D, so no refactorisation
is ever needed.

What the blocks miss is the pillars' interaction through the half space.
Its slowest part is collective: pillar forces acting on each other through
the far field.  A coarse space with one vector per pillar, z_p = G_p 1 (the
pillar's own response to a unit displacement), carries it: Z^T A Z is
diag(c) + C R C with c_p = 1^T G_p 1 and R the influence coefficient between
pillar centroids (monopole approximation of the off-diagonal blocks).  The
balancing two-level preconditioner built on it stays symmetric positive
definite whatever the approximation, so CG still converges to the exact
solution; E is refactorised only when the pillars' c have drifted.  The same
monopole model bounds how much the far field of other pillars can move an
element's stress (`far_field_uncertainty`), which lets cascades run pillar
by pillar without changing their outcome.

A detachment's warm start uses the same blocks: the pillar that lost
elements is solved exactly with the others held (the downdate's Schur
complement, `detach`), and the other pillars' answer to that change is
estimated by the `WarmStart` the blocks own
(`brushcore.numerics.linear.warm_start`).  The operations on the stacked
inverses that know nothing of the geometry (the downdate of one block,
packed storage, the block-diagonal product) are in
`brushcore.numerics.linear.stacks`.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from brushcore.numerics.platform.backend import CPU
from brushcore.numerics.halfspace.farfield import FarFieldBound, near_influence
from brushcore.numerics.halfspace.kernel import love_coefficient, pillar_influence
from brushcore.numerics.linear.stacks import pack_index, remove_slots, stack_times
from brushcore.numerics.linear.warm_start import WarmStart


def _spd_inverse(e: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric positive definite matrix from its Cholesky
    factor (LAPACK potrf + potri, N^3 flops: half of an LU inverse's).

    Raises
    ------
    numpy.linalg.LinAlgError
        If ``e`` is not positive definite.
    """
    factor, lower = sla.cho_factor(e, check_finite=False)
    inv, info = sla.lapack.dpotri(factor, lower=lower)
    if info:
        raise np.linalg.LinAlgError(f"potri: info {info}")
    tri = np.tril(inv) if lower else np.triu(inv)  # potri fills one triangle
    return tri + np.tril(tri, -1).T if lower else tri + np.triu(tri, 1).T


def coarse_inverse(c: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """E^-1 of the pillar-level coarse space, E = diag(c) + C R C with
    c_p = 1^T z_p (module docstring), and C^-1 (0 where c_p = 0).

    A pillar without elements gets a zero row and column of E^-1, so that
    until the next factorisation a pillar that regains elements (`attach`)
    is preconditioned by its block alone.  A unit entry there (E inverted
    with a decoupled unit row) weighed its coarse vector by 1 in the units
    of c^-1: the preconditioner then depended on the unit system (a rough
    138-pillar brush at 128^2 took 6,036 applications with h = E* = 1 and
    7,212 with h in metres, the same curve).

    Raises
    ------
    numpy.linalg.LinAlgError
        If E is not positive definite (monopoles of overlapping footprints).
    """
    e = np.diag(c) + c[:, None] * r * c[None, :]
    dead = c <= 0.0
    e[dead, :] = 0.0
    e[:, dead] = 0.0
    e[dead, dead] = 1.0  # decoupled, so that E stays positive definite
    inverse = _spd_inverse(e)
    inverse[dead, dead] = 0.0
    return inverse, np.divide(1.0, c, out=np.zeros_like(c), where=~dead)


#: Bytes a preconditioner's stored blocks may take (the dense per-pillar
#: inverses, the tiles' coarse blocks, and what `attach` borders them with):
#: the workflow's memory request counts what a brush's take
#: (`brushcore.model.cost.peak_mb`; README, "Time and memory a job asks for").
MEMORY_BUDGET = 4e9


class BlockInverse:
    """Stacked inverses G_p of the per-pillar blocks, padded to a common size.

    Parameters
    ----------
    elements : flat n x n indices of the pillar elements (operator order)
    pillar_of : pillar index of each element
    n : grid size
    compliance : h^2 / k_p per pillar [length / stress]
    h, e_star : element size [length] and modulus [stress]
    coarse : allow the pillar-level coarse space (used for 1 < N <= MAX_COARSE
        when the pillars are coupled enough, see COUPLING_PER_PILLAR)
    mirrored : the grid is the quadrant of a field mirrored about both
        mid-lines (`brushcore.numerics.halfspace.mirror`): every influence includes
        the three images, and each block is the exact diagonal block of the
        folded operator (a pillar near a mirror line feels its own images)
    single : apply the blocks from a float32 copy (`_blocks_times`), for an
        operator whose transforms are single precision already; `single`
        is also the attribute its `refined` solves turn off
    threads : threads that share each application's unpacked stack
        (`brushcore.numerics.platform.threads.stacked_matmul`)
    """

    #: Where the stacks live (`DeviceBlocks` sets its device's backend).
    backend = CPU
    #: Blocks applied in single precision (see the ``single`` parameter).
    single = False
    def __init__(self, elements: np.ndarray, pillar_of: np.ndarray, n: int,
                 compliance: np.ndarray, h: float, e_star: float,
                 coarse: bool = True, mirrored: bool = False, single: bool = False,
                 threads: int = 1) -> None:
        n_pillars = compliance.size
        self.threads = threads
        counts = self._layout(elements, pillar_of, n, compliance, h, e_star, mirrored)
        self.inv = np.zeros((n_pillars, self.m, self.m))
        for group in self._shape_groups(counts):
            p = group[0]
            self.inv[group, :counts[p], :counts[p]] = np.linalg.inv(
                self._block(p, np.arange(counts[p])))
        self._work = np.zeros((n_pillars, self.m))
        self._remaining = counts.copy()  # attached elements per pillar
        self.interacting = 1 < n_pillars <= self.MAX_INTERACTION
        # The application streams the stacked inverses from memory.  Large
        # blocks are applied from packed upper triangles (BLAS spmv), which
        # halves the bytes (6.8 -> 3.6 ms for 64 blocks of 491); an operator
        # with single-precision transforms applies a float32 copy instead
        # (the float64 stack stays for downdates and `refined` solves).
        self.single = single and self.interacting  # `_blocks_times` needs `_z`
        packed_from = self.SINGLE_PACKED_MIN_BLOCK if self.single else self.PACKED_MIN_BLOCK
        self._pack_index = pack_index(self.m) if self.m >= packed_from else None
        self._copy = None  # what `_blocks_times` applies instead of `inv`
        if self.single:
            shape = (self.m, self.m) if self._pack_index is None else self._pack_index.shape
            self._copy = np.zeros((n_pillars,) + shape, dtype=np.float32)
        elif self._pack_index is not None:
            self._copy = np.zeros((n_pillars,) + self._pack_index.shape)
        self._drifted: set[int] = set()  # pillars whose c moved since the last factorisation
        # Elastic inverses H_p = K_pp^-1 of pillars that regained elements
        # (`attach`; pull-offs never attach, so they hold none), kept where
        # the stack, its packed copy and the H's fit BORDER_BUDGET.
        self._elastic: dict[int, np.ndarray] = {}
        self._bordering = 2.5 * self.inv.nbytes <= self.BORDER_BUDGET
        self.factorisations = 0
        self.coarse = coarse and self.interacting and n_pillars <= self.MAX_COARSE
        self._refresh_copy(np.arange(n_pillars))
        if self.interacting:
            self._r, r_near = self._interaction(counts)
            self._bound = FarFieldBound(r_near)
            self._z = self.inv.sum(axis=2)
            # sum |G_p| per slot (see `reach`), for the pillars not in
            # _reach_stale: only a certificate reads it, and most rounds try
            # none (`pulloff._Backoff`), so `reach` computes it there (a pass
            # over a block of 495 costs ~0.5 ms), not at every downdate.
            self._reach = np.zeros_like(self._z)
            self._reach_stale: set[int] = set(range(n_pillars))
            # max_p sum_q R_pq c_q: the far-field displacement of a pillar
            # when all pillars carry their own unit-displacement load.
            self.coupling = float((self._r @ self._z.sum(axis=1)).max())
            self.coarse = self.coarse and self.coupling >= self.COUPLING_PER_PILLAR * n_pillars
        # the other pillars' answer to a detachment (`detach`)
        self.warm_start = WarmStart(self, counts, n) if self.interacting else None
        if self.coarse:
            self._factorise()

    def _layout(self, elements: np.ndarray, pillar_of: np.ndarray, n: int,
                compliance: np.ndarray, h: float, e_star: float, mirrored: bool) -> np.ndarray:
        """Host-side geometry: each element's slot in the (N, m) stack (`pos`),
        coordinates, the coefficient table and the attached slots; returns
        the element count per pillar."""
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
        # Kept for `attach`, which borders a block with elements it lost.
        self._yy, self._xx, self._h, self._e_star = yy, xx, h, e_star
        self._mirrored = mirrored
        self._iyy = np.zeros((n_pillars, self.m), dtype=np.intp)
        self._ixx = np.zeros((n_pillars, self.m), dtype=np.intp)
        self._iyy.ravel()[self.pos] = iy
        self._ixx.ravel()[self.pos] = ix
        # Blocks look their coefficients up at integer offsets: evaluating Love's
        # formula for m^2 pairs per pillar costs more than inverting at m ~ 2000.
        off = np.arange(2 * n if mirrored else n) * h
        self._table = self._coefficient_table(off, h, e_star)
        self._compliance = np.asarray(compliance, dtype=float)
        self._live = np.arange(self.m)[None, :] < counts[:, None]  # attached slots
        return counts

    @staticmethod
    def _coefficient_table(off: np.ndarray, h: float, e_star: float) -> np.ndarray:
        """Love's coefficients at every pair of offsets ``off`` (rows y, columns x)."""
        return love_coefficient(off[:, None], off[None, :], h, e_star)

    def _shape_groups(self, counts: np.ndarray) -> list[list[int]]:
        """Pillars with the same footprint up to translation (and the same
        spring) share one inverse: groups of pillar indices."""
        yy, xx, compliance = self._yy, self._xx, self._compliance
        shapes: dict[bytes, list[int]] = {}
        for p in range(compliance.size):
            k = counts[p]
            key = np.stack([yy[p, :k] - yy[p, 0], xx[p, :k] - xx[p, 0]]).tobytes()
            if self._mirrored:  # the images make the distance to the mirror lines matter
                key += np.array([yy[p, 0], xx[p, 0]]).tobytes()
            shapes.setdefault(key + compliance[p].tobytes(), []).append(p)
        return list(shapes.values())

    def _interaction(self, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Monopole influence between pillar centroids, and at the closest
        approach of two footprints (for the uncertainty bound), shape (N, N)."""
        yy, xx, h, e_star = self._yy, self._xx, self._h, self._e_star
        cy = yy.sum(axis=1) / counts
        cx = xx.sum(axis=1) / counts
        self._centroids = cy, cx  # also for the warm start (`WarmStart`)
        # Diagonals are zero: a pillar's own images are in its block.
        r = pillar_influence(cy, cx, h, e_star, self._mirrored)
        # For the uncertainty bound: the influence at the closest approach
        # of two footprints, not at their centroids (close random pillars).
        reach = np.sqrt(((yy - cy[:, None]) ** 2 + (xx - cx[:, None]) ** 2)
                        * (np.arange(self.m)[None, :] < counts[:, None])).max(axis=1)
        return r, near_influence(cy, cx, reach, h, e_star, self._mirrored)

    #: Largest pillar (elements) with a dense inverse in a pull-off (`fits`).
    MAX_BLOCK = 1500
    #: ... and in a protocol run that the general engine takes (a flat brush
    #: under the standard protocol goes to the pull-off, with MAX_BLOCK),
    #: whose cascades are all global solves, so
    #: the tiles' extra applications are not won back by cheaper local
    #: rounds (rough 4 x 4 brush, preload 0.5, at 256^2 with the tiles
    #: forced on pillars of 491 elements: 93,619 applications and 158 s
    #: against 7,428 and 63 s; not measured between 1,500 and 2,500).
    MAX_BLOCK_PROTOCOL = 2500
    #: Largest pillar count with a coarse space (its dense N x N factor).
    MAX_COARSE = 2000
    #: A coarse space needs coupling >= this times N.  Its solve costs ~N^2 per
    #: application and ~N^3 per refactorisation while what it saves grows with
    #: the coupling (soft springs decouple the pillars); break-even measured
    #: on 512 grids near coupling N / 500 (64 pillars: 0.2, 1620 pillars: 3).
    COUPLING_PER_PILLAR = 0.002
    #: Smallest block size applied from packed storage (one BLAS call per
    #: pillar; below it one batched matmul over all pillars is faster).
    PACKED_MIN_BLOCK = 128
    #: ... in single precision, where the batched matmul is faster for
    #: longer (one core, phi 0.12: 0.33 against 0.78 ms at m = 128, 1.06
    #: against 0.82 ms at 256, 2.6 against 1.6 ms at 495).
    SINGLE_PACKED_MIN_BLOCK = 256
    #: Largest pillar count with the N x N pillar interaction matrix.
    MAX_INTERACTION = 4000
    #: Refactorise E once REFACTOR_FRACTION x max(1, N / REFACTOR_PILLARS)
    #: of the pillars changed c by > 25 %: the fraction grows with N so that
    #: the ~N^3 refactorisations cost ~N^2 per pillar that drifts, as the
    #: coarse products do.  A stale E keeps the preconditioner SPD and costs
    #: few applications (random 1620 at kbar 1, 512^2: 4,572 at 0.02 with 72
    #: refactorisations of 0.12 s, 4,671 at 0.05, 4,750 at 0.1, 4,941 with
    #: none); at N = 425 one costs ~2 ms and 0.1 lost 2 % (3,105 -> 3,173).
    REFACTOR_FRACTION = 0.02
    REFACTOR_PILLARS = 400
    #: Bytes the stacks may take with the elastic inverses that `attach`
    #: borders (the stack, its packed copy and the elastic inverses).
    BORDER_BUDGET = MEMORY_BUDGET

    def _block(self, p: int, slots: np.ndarray) -> np.ndarray:
        """Pillar p's block of the operator over the given slots [length / stress]."""
        return self._coefficients(p, slots, p, slots) + self._compliance[p]

    def _coefficients(self, q: int | np.ndarray, rows: np.ndarray, p: int,
                      cols: np.ndarray) -> np.ndarray:
        """Half-space influence of pillar p's slots ``cols`` on pillar q's
        slots ``rows`` [length / stress], images included on a mirror grid;
        ``q`` may also give each row's pillar."""
        t = self._table
        iy, ix = self._iyy[q, rows][:, None], self._ixx[q, rows][:, None]
        jy, jx = self._iyy[p, cols][None], self._ixx[p, cols][None]
        dy, dx = np.abs(iy - jy), np.abs(ix - jx)
        block = t[dy, dx]
        if self._mirrored:  # the images: see `folded_coefficient`
            sy, sx = iy + jy + 1, ix + jx + 1
            block = block + t[sy, dx] + t[dy, sx] + t[sy, sx]
        return block

    def _factorise(self) -> None:
        c = self._z.sum(axis=1)
        try:
            self._e_inverse, self._c_inverse = coarse_inverse(c, self._r)
        except np.linalg.LinAlgError:
            # Monopoles of overlapping or interleaved footprints need not give
            # a positive definite E; the blocks alone remain a valid preconditioner.
            self.coarse = False
            return
        # float32 copy for `single` applications: half the bytes to read, and
        # at N = 1620 (10 MB) it can stay in the last-level cache.  Made
        # whenever the blocks' copy is float32 (the build-time choice), not
        # by `single`, which `refined` turns off for a while.
        single = self._copy is not None and self._copy.dtype == np.float32
        self._e_inverse_single = self._e_inverse.astype(np.float32) if single else None
        self._c_factor = c
        self.factorisations += 1

    @classmethod
    def fits(cls, pillar_of: np.ndarray, budget_bytes: float = MEMORY_BUDGET,
             max_block: int | None = None) -> bool:
        """Whether the stacked inverses (and their packed copy) fit the memory
        budget and the block size limit.

        4 GB keeps a 2048^2 curve within 8 GB.  Larger pillars take the tile
        preconditioner (`brushcore.numerics.linear.tiles`) with exact local
        responses on small FFT grids (`brushcore.numerics.linear.pillar_solve`):
        2-3x the applications of the blocks, but each block application
        and downdate streams N m^2 numbers, so from m ~ 1,500 up the tiles
        are faster.  Measured, wall time tiles / blocks: 1.3 and 1.1 at m =
        1,000 (16 pillars on 365^2, kbar 1e-4 and rigid; random 2.1 and
        1.2), 0.5-0.8 at m = 1,960 (16 pillars on 512^2, 64 on 1024^2,
        rigid to kbar 1e-4, regular and random).  The limits are fixed,
        not read from the machine: the same problem takes the same path
        everywhere.  ``max_block`` defaults to MAX_BLOCK.
        """
        max_block = cls.MAX_BLOCK if max_block is None else max_block
        m, stack_bytes = cls.stack_size(pillar_of)
        # the stack and its copy for the application: half its bytes at most
        return m <= max_block and stack_bytes * 1.5 <= budget_bytes

    @staticmethod
    def stack_size(pillar_of: np.ndarray) -> tuple[int, float]:
        """The largest block m and the bytes of the (N, m, m) stack of inverses."""
        counts = np.bincount(pillar_of)
        m = int(counts.max())
        return m, counts.size * m * m * 8.0

    def detach(self, elements: np.ndarray, stress: np.ndarray | None = None,
               attached_pos: np.ndarray | None = None) -> np.ndarray | None:
        """Downdate the inverses for detached elements (operator-order indices).

        If the current stresses are given (compressed over the attached set
        before detaching, with `attached_pos` their stack positions), also
        return each pillar's exact response to losing those elements with the
        field of the other pillars held fixed: sigma_p - G[:, D] G[D, D]^-1
        sigma_p[D] (the same Schur complement as the downdate), to which
        `warm_start` (where the pillars interact) adds the other pillars'
        answer to that change.
        """
        pos = self.pos[elements]
        pil, slot = np.divmod(pos, self.m)
        w = None
        if stress is not None:
            w = self._work
            w.ravel()[attached_pos] = stress
        touched = np.unique(pil)
        self._remaining -= np.bincount(pil, minlength=self._remaining.size)
        respond = w is not None and self.warm_start is not None
        live_before = self._live[touched].copy() if respond else None
        self._live[pil, slot] = False
        before = list(w[touched].copy()) if respond else None
        for p in touched:
            d = slot[pil == p]
            g = self.inv[p]
            self._downdate_elastic(int(p), d)
            if self._remaining[p] == 0:  # the whole pillar lets go: nothing to solve
                g[...] = 0.0
                if w is not None:
                    w[p] = 0.0
                continue
            response = remove_slots(g, d, None if w is None else w[p, d])
            if w is not None:
                w[p] -= response
                w[p, d] = 0.0
        self._refresh(touched)
        if w is None:
            return None
        if respond:
            self.warm_start.respond(touched, live_before, before)
        out = w.take(attached_pos)
        w.fill(0.0)
        return out

    # The work vector, as the warm start (`WarmStart`) reads and writes it
    # (`DeviceBlocks` keeps it flat).
    def _subtract_all(self, values: np.ndarray) -> None:
        """Subtract an (N, m) stack from the work vector."""
        self._work -= values

    def _row(self, p: int) -> np.ndarray:
        """Pillar p's slots of the work vector (a view)."""
        return self._work[p]

    def _set_row(self, p: int, values: np.ndarray) -> None:
        """Set pillar p's slots of the work vector."""
        self._work[p] = values

    def attach(self, elements: np.ndarray) -> None:
        """Update the inverses of pillars that regain elements (operator-order indices).

        Bordering G itself, G' = [[G + G b s^-1 b^T G, -G b s^-1], ...] with
        s = B_aa - b^T G b, is O(m^2) but unstable for soft springs: B = K +
        c 1 1^T with c = h^2 / k up to ~1e4 K_ii, and s is a difference of
        numbers ~c, so errors compound (measured: 1e-7, 1e-2, 1e2 relative
        after 2, 3, 4 updates at c = 1e4).  The elastic block alone has no
        such term: each pillar that regains elements keeps H = K_pp^-1,
        borders it (its Schur complement K_aa - k^T H k is well conditioned),
        and adds the spring back in closed form, G = H - c u u^T / (1 + c q)
        with u = H 1, q = 1^T u (Sherman-Morrison), O(m^2) an update where
        inverting afresh is O(m^3) (a rough 8 x 8 brush at 512^2 spent 16 %
        of its time in those inversions, pillars of 491 elements).  Where
        H does not fit the budget the touched blocks are inverted afresh.
        """
        pos = self.pos[elements]
        pil, slot = np.divmod(pos, self.m)
        touched = np.unique(pil)
        for p in touched:
            new = slot[pil == p]
            old = np.flatnonzero(self._live[p])
            self._live[p, new] = True
            if self._bordering:
                self.inv[p] = self._bordered(int(p), old, new)
            else:
                live = np.flatnonzero(self._live[p])
                g = self.inv[p]
                g[...] = 0.0
                g[np.ix_(live, live)] = np.linalg.inv(self._block(p, live))
        self._remaining += np.bincount(pil, minlength=self._remaining.size)
        self._refresh(touched)

    def _bordered(self, p: int, old: np.ndarray, new: np.ndarray) -> np.ndarray:
        """Pillar p's block inverse G after its slots ``new`` join ``old``,
        from the bordered elastic inverse (see `attach`), shape (m, m)."""
        h_old = self._elastic.get(p)
        if h_old is None:  # first return of this pillar: its elastic inverse afresh
            h_old = np.zeros((self.m, self.m))
            if old.size:
                h_old[np.ix_(old, old)] = np.linalg.inv(self._coefficients(p, old, p, old))
        k = self._coefficients(p, old, p, new)
        hk = h_old[np.ix_(old, old)] @ k
        s_inv = np.linalg.inv(self._coefficients(p, new, p, new) - k.T @ hk)
        x = hk @ s_inv
        h = h_old
        h[np.ix_(old, old)] += x @ hk.T
        h[np.ix_(old, new)] = -x
        h[np.ix_(new, old)] = -x.T
        h[np.ix_(new, new)] = s_inv
        self._elastic[p] = h
        u = h.sum(axis=1)  # zero off the live slots
        c = self._compliance[p]
        return h - (c / (1.0 + c * u.sum())) * np.outer(u, u)

    def _downdate_elastic(self, p: int, gone: np.ndarray) -> None:
        """Remove slots ``gone`` from pillar p's elastic inverse, if it has one."""
        h = self._elastic.get(p)
        if h is None:
            return
        if self._remaining[p] == 0:
            del self._elastic[p]
            return
        remove_slots(h, gone)

    def _refresh(self, touched: np.ndarray) -> None:
        """The application's copy, coarse vectors and (when drifted) the
        coarse factor of the pillars whose blocks changed."""
        self._refresh_copy(touched)
        if self.interacting:
            for p in touched:  # views: a fancy-indexed copy of large blocks costs more
                g = self.inv[p]
                self._z[p] = g.sum(axis=1)
                self._reach_stale.add(int(p))
                if self.warm_start is not None:
                    self.warm_start.refresh(p, g)
        if self.coarse:
            self._note_drift(touched, self._z[touched].sum(axis=1))

    def _note_drift(self, touched: np.ndarray, c: np.ndarray) -> None:
        """Mark the touched pillars whose c (host values) moved by > 25 % since
        the last factorisation, and refactorise E once enough have
        (REFACTOR_FRACTION)."""
        ref = self._c_factor[touched]
        self._drifted.update(touched[np.abs(c - ref) > 0.25 * ref].tolist())
        n = self._z.shape[0]
        if len(self._drifted) > self.REFACTOR_FRACTION * n * max(1.0, n / self.REFACTOR_PILLARS):
            self._factorise()
            self._drifted = set()

    def far_field_uncertainty(self, pillar_change: np.ndarray,
                              attached_pos: np.ndarray) -> np.ndarray | None:
        """Bound on the stress change the other pillars' far field can cause.

        Stress changes of summed magnitude L_q = sum |d sigma| over pillar
        q's elements move the surface under pillar p by at most R_pq L_q, R
        taken at the closest approach of the two footprints; whatever the
        shape of that movement, element i of p responds by at most
        sum_j |G_p[i, j]| per unit (``_reach``).  Returns that first-order
        bound per attached element (compressed), or None without the
        interaction matrix; callers add a safety factor for the second order.

        The shape matters: a soft pillar's spring makes its response to a
        uniform displacement (z_p = G_p 1) tiny, but not its response to a
        tilt, which its elastic face resists alone.  A bound on |z_p| alone
        (x30) let brushes at kbar <= 1e-4 end cascades elsewhere than the
        global solver (W up to 0.7 % off for random 64 at kbar 1e-5).
        """
        if not self.interacting:
            return None if self.inv.shape[0] > 1 else np.zeros(attached_pos.size)
        shift = self._bound.shift(np.abs(pillar_change))
        return (self.reach() * shift[:, None]).ravel()[attached_pos]

    def reach(self) -> np.ndarray:
        """sum_j |G_p[i, j]| per pillar and slot, shape (N, m) [stress /
        length]: each element's largest stress response to a unit
        displacement of any shape over its pillar (see
        `far_field_uncertainty`), brought up to date for the pillars whose
        blocks changed since it was last read."""
        for p in self._reach_stale:
            self._reach[p] = np.abs(self.inv[p]).sum(axis=1)
        self._reach_stale.clear()
        return self._reach

    def _refresh_copy(self, touched: np.ndarray) -> None:
        """The application's copy of the touched pillars' inverses."""
        if self._copy is None:
            return
        for p in touched:
            if self._pack_index is None:
                self._copy[p] = self.inv[p]
            else:  # into the copy, casting, without a temporary
                np.take(self.inv[p].ravel(), self._pack_index, out=self._copy[p])

    def _blocks_times(self, w: np.ndarray) -> np.ndarray:
        """blockdiag(G_p) w for the stacked (N, m) vector w.

        From the float32 copy while `single`, with each pillar's total
        then set to its exact value (G_p 1)^T w_p: a soft spring makes
        G_p nearly singular along 1 (the pillar's uniform mode, eigenvalue
        ~1 / (m h^2 / k_p)), and float32 round-off of G_p's O(1) entries
        would swamp that eigenvalue and could make the preconditioner
        indefinite there.  The round-off left in the other directions is
        ~1e-7 relative, as in the single-precision transforms.
        """
        if not self.single:  # a float64 copy is a packed one
            if self._copy is None or self._copy.dtype != np.float64:
                return stack_times(self.inv, False, w, self._remaining, self.threads)
            return stack_times(self._copy, True, w, self._remaining, self.threads)
        z = stack_times(self._copy, self._pack_index is not None, w.astype(np.float32),
                         self._remaining, self.threads).astype(np.float64)
        gap = (self._z * w).sum(axis=1) - z.sum(axis=1)  # z is 0 off the live slots
        live = np.maximum(self._remaining, 1)
        z += (gap / live)[:, None] * self._live
        return z

    def apply(self, r: np.ndarray, attached_pos: np.ndarray) -> np.ndarray:
        """Preconditioned residual for a compressed residual over the attached elements.

        blockdiag(G_p) r, balanced with the coarse space when it is on:

            P = Z E^-1 Z^T + (I - Z E^-1 W^T) G (I - W E^-1 Z^T),

        with W y = ((I + R C) y)_p 1 on pillar p (the monopole model of A Z)
        and E = Z^T W = C (I + R C), C = diag(c).  Then W E^-1 = C^-1 and
        E^-1 W^T = C^-1 per pillar, so one product with E^-1 per application
        is left and R never has to be applied (it is only in E).  E^-1 is
        formed at each refactorisation (`_spd_inverse`): one matrix-vector
        product reads it once, where the two triangular solves of a
        Cholesky factor read theirs twice and serially (N = 1620: 0.20
        against 1.85 ms, and 0.06 ms from the float32 copy while `single`;
        random 1620 at kbar 1 spent a fifth of its time in those solves).
        """
        w = self._work
        w.ravel()[attached_pos] = r
        if self.coarse:
            t = (self._z * w).sum(axis=1)  # Z^T r
            if self.single:  # as the blocks: refined solves take float64
                y1 = (self._e_inverse_single @ t.astype(np.float32)).astype(np.float64)
            else:
                y1 = self._e_inverse @ t
            w.ravel()[attached_pos] -= (t * self._c_inverse)[attached_pos // self.m]
        z = self._blocks_times(w)
        w.fill(0.0)  # a memset, not a scatter: zero off the attached slots too
        if self.coarse:
            z += self._z * (y1 - z.sum(axis=1) * self._c_inverse)[:, None]
        return z.take(attached_pos)
