"""The brush operator A = P_C (K + S) P_C on the attached set C, and its preconditioner.

For an attached element i of pillar p the half-space surface follows the
pillar face: u_i = d - dl_p with the spring extension dl_p = (h^2 / k_p) *
sum_{j in p, attached} sigma_j (paper eqs. 11-19).  Writing u = K sigma gives

    (K sigma)_i + (h^2 / k_p) sum_{j in p} sigma_j = d     for i in C,

a symmetric positive definite system.  Summing per pillar with a label map
(np.bincount) is the paper's "discriminant matrix" convolution without its
limits on pillar size and gap, and allows a different k per pillar.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from brushcore.numerics.halfspace.convolution import Convolver
from brushcore.numerics.linear.device_blocks import DeviceBlocks
from brushcore.numerics.linear.precondition import BlockInverse
from brushcore.numerics.linear.pillar_solve import PillarSolver
from brushcore.numerics.linear.tiles import TileCoarse
from brushcore.numerics.halfspace.kernel import self_compliance


class BrushOperator:
    """Matrix-free A = P_C (K + S) P_C over the attached pillar elements.

    Parameters
    ----------
    convolver : the DC-FFT convolution K for the grid (`Convolver`, a mirror
        quadrant's `MirrorConvolver` or a device's)
    labels : pillar index per element, -1 outside pillars, shape (n, n)
    compliance : spring compliance h^2 / k_p per pillar, shape (N,)
        [length / stress]; 0 for rigid pillars
    h : element size [length]
    e_star : effective modulus [stress]
    use_block : precondition with the per-pillar blocks or tiles (default);
        False takes the "diagonal" preconditioner, Sherman-Morrison on the
        springs alone (tests and benchmarks compare)
    coarse : add the pillar-level coarse space to the blocks (default)
    precise : makes a double-precision twin of a single-precision
        ``convolver`` (same grid), for the solves that need more digits
        than float32 transforms give (`refined`); None where the
        transforms are double already
    max_block : largest pillar (elements) with a dense block inverse on
        the host; larger ones take the tiles (`BlockInverse.fits`)

    Notes
    -----
    Arrays live where the convolver's (``convolver.array_backend``): NumPy
    on the CPU, CuPy on a GPU; `elements` (the geometry) is always a NumPy
    array.  Vectors are compressed to the attached elements in the order of
    `elements[attached]`.  `detach` shrinks the set; it never grows during
    a pull-off.  `attach` grows it again (approach and re-attachment, see
    `brushcore.numerics.events.protocol`).
    """

    def __init__(self, convolver: Convolver, labels: np.ndarray, compliance: np.ndarray,
                 h: float, e_star: float, use_block: bool = True, coarse: bool = True,
                 precise: Callable[[], Convolver] | None = None,
                 max_block: int = BlockInverse.MAX_BLOCK) -> None:
        self.conv = convolver
        self._precise = precise
        threads = getattr(convolver, "threads", 1)  # the job's FFT threads share the stacks too
        self.refined_applications = 0  # applications made by the twin (`refined`)
        self.backend = be = convolver.array_backend
        xp = be.xp
        flat = labels.ravel()
        self.elements = np.flatnonzero(flat >= 0)  # flat n x n indices of pillar elements
        pillar_of = flat[self.elements].astype(np.intp)
        self.n_pillars = int(labels.max()) + 1
        compliance = np.asarray(compliance, dtype=float)
        self._springs = bool(compliance.any())
        self.pillar_of = be.asarray(pillar_of)
        self.compliance = be.asarray(compliance)
        self.diag = self_compliance(h=h, e_star=e_star)
        self._padded = be.asarray(convolver.padded_index(self.elements))
        self.conv.flat_buffer[...] = 0.0
        self.attached = xp.ones(self.elements.size, dtype=xp.bool)
        self.block: BlockInverse | None = None
        if use_block and be.on_host and BlockInverse.fits(pillar_of, max_block=max_block):
            self.block = BlockInverse(self.elements, pillar_of, convolver.n, compliance, h,
                                      e_star, coarse, getattr(convolver, "mirrored", False),
                                      single=precise is not None, threads=threads)
        elif use_block and not be.on_host and DeviceBlocks.fits_device(pillar_of, be):
            self.block = DeviceBlocks(self.elements, pillar_of, convolver.n, compliance, h,
                                      e_star, coarse, backend=be)
        # Pillars too large for dense blocks: the two-level tile preconditioner
        # (host only; a device falls back to Sherman-Morrison).
        self.tiles: TileCoarse | None = None
        if (use_block and be.on_host and self.block is None
                and TileCoarse.fits(self.elements, pillar_of, convolver.n)):
            self.tiles = TileCoarse(self.elements, pillar_of, convolver.n, compliance, h, e_star,
                                    threads=threads,
                                    mirrored=getattr(convolver, "mirrored", False),
                                    coarse=coarse)
        # ... and their exact local responses on small FFT grids (local cascades).
        self.local: PillarSolver | None = None
        if self.tiles is not None:
            self.local = PillarSolver(self.elements, pillar_of, convolver.n, compliance, h,
                                      e_star, getattr(convolver, "mirrored", False), self.tiles)
        self._update()

    def _update(self, kept: Any = None) -> None:
        """The attached elements' indices, from `attached`, or after a
        detachment from the previous ones by ``kept`` (a boolean mask over
        them): the same arrays, without a pass over every pillar element
        (a soft random brush detaches thousands of times a curve)."""
        xp = self.backend.xp
        if kept is None:
            self.idx = self._padded[self.attached]
            if self.block is not None:
                self._bpos = self.block.pos[self.attached]
            if self.tiles is not None:
                self._tpos = self.tiles.tile_of[self.attached]
            self.pl = self.pillar_of[self.attached]
        else:
            self.idx = self.idx[kept]
            if self.block is not None:
                self._bpos = self._bpos[kept]
            if self.tiles is not None:
                self._tpos = self._tpos[kept]
            self.pl = self.pl[kept]
        self.counts = self.backend.bincount(self.pl, minlength=self.n_pillars)
        if self.tiles is not None:  # the touched pillars' z_p have changed
            self._tz = self.tiles.z[self.attached] if self.tiles.coarse else None
        if self.block is None and self.tiles is None:
            # Sherman-Morrison for the per-pillar block (c I + s 1 1^T)^-1.
            s = self.compliance
            self._sm = (s / (self.diag + s * xp.astype(self.counts, xp.float64)))[self.pl]

    @property
    def preconditioner(self) -> str:
        """Which preconditioner runs: "blocks" (exact per-pillar inverses,
        `BlockInverse` or `DeviceBlocks`), "tiles" (`TileCoarse`) or
        "diagonal" (Sherman-Morrison on the springs alone)."""
        if self.block is not None:
            return "blocks"
        return "tiles" if self.tiles is not None else "diagonal"

    @property
    def size(self) -> int:
        """Number of attached elements."""
        return int(self.idx.shape[0])

    def detach(self, which: Any, stress: Any = None) -> Any:
        """Detach attached elements given by a boolean mask over the compressed vector.

        With ``stress`` (compressed, before detaching) and a local solver
        (the block preconditioner, or `PillarSolver` with the tiles), returns
        the stresses of the remaining elements after each pillar's exact
        local response to the loss (other pillars' field held fixed);
        otherwise None.
        """
        be = self.backend
        gone = self.idx[which]
        be.put(self.conv.flat_buffer, gone, 0.0)
        pos = be.flatnonzero(self.attached)[which]
        local = None
        if self.block is not None:
            local = self.block.detach(pos, stress, None if stress is None else self._bpos)
        if self.tiles is not None:
            self.tiles.detach(pos)
        be.put(self.attached, pos, False)
        self._update(~which)
        if self.local is not None and stress is not None:
            full = _spread_host(self.attached.size, pos, which, stress, self.attached)
            self.local.respond(full, self.attached, pos)
            return full[self.attached]
        return None if local is None else local[~which]

    def attach(self, positions: Any) -> None:
        """Attach detached elements given by operator-order indices (into `elements`).

        Their buffer entries are already zero (`detach` cleared them); the
        block preconditioner is bordered with the new elements.
        """
        xp = self.backend.xp
        positions = xp.asarray(positions, dtype=xp.int64)
        if positions.shape[0] == 0:
            return
        if bool(xp.any(self.attached[positions])):
            raise ValueError("attach: some elements are already attached")
        if self.block is not None:
            self.block.attach(positions)
        if self.tiles is not None:
            self.tiles.attach(positions)
        self.backend.put(self.attached, positions, True)
        self._update()

    @property
    def can_refine(self) -> bool:
        """Whether `refined` has more precise transforms to switch to."""
        return self._precise is not None

    @contextlib.contextmanager
    def refined(self) -> Iterator[None]:
        """Apply with the double-precision twin of the convolver, and the
        block preconditioner in double precision, inside the block."""
        single, self.conv = self.conv, self._precise()
        self.conv.flat_buffer[...] = 0.0  # entries left from an earlier use
        start = self.conv.applications
        blocks_single = self.block is not None and self.block.single
        if blocks_single:
            self.block.single = False
        try:
            yield
        finally:
            self.refined_applications += self.conv.applications - start
            self.conv = single
            if blocks_single:
                self.block.single = True

    def _gather(self, where: Any) -> Any:
        """The convolved buffer at ``where``, in double precision whatever
        the transforms' (single-precision transforms: `SolverOptions.precision`)."""
        xp = self.backend.xp
        return xp.astype(xp.take(self.conv.apply_flat(), where), xp.float64, copy=False)

    def _scatter(self, x: Any) -> None:
        """Write attached-element stresses x into the convolver's buffer,
        cast to its precision first (the same rounding as the scatter's
        own cast; 2x faster for a float32 buffer than casting in it)."""
        buf = self.conv.flat_buffer
        self.backend.put(buf, self.idx, self.backend.xp.astype(x, buf.dtype, copy=False))

    def field(self, x: Any) -> Any:
        """Half-space displacement K x [length] at every pillar element
        (operator order) from attached-element stresses x [stress]; one
        operator application."""
        self._scatter(x)
        return self._gather(self._padded)

    def spring(self, x: Any) -> Any:
        """Spring part S x of A x (compressed) [length]."""
        if self._springs:
            return self.backend.xp.take(self.compliance * self.pillar_sums(x), self.pl)
        return self.backend.xp.zeros_like(x)

    def apply_with_field(self, x: Any) -> tuple[Any, Any]:
        """(A x, K x at every pillar element) from one operator application."""
        full = self.field(x)
        return full[self.attached] + self.spring(x), full

    def far_field_uncertainty(self, pillar_change: Any) -> Any:
        """See `BlockInverse.far_field_uncertainty` (None without a local solver)."""
        if self.local is not None:
            return self.local.far_field_uncertainty(pillar_change, self.pl)
        if self.block is None:
            return None
        return self.block.far_field_uncertainty(pillar_change, self._bpos)

    @property
    def has_local_solver(self) -> bool:
        """Whether per-pillar exact responses are available (see `detach`)."""
        return self.block is not None or self.local is not None

    def pillar_sums(self, x: Any) -> Any:
        """Sum of a compressed vector over each pillar, shape (N,)."""
        return self.backend.bincount(self.pl, weights=x, minlength=self.n_pillars)

    def apply(self, x: Any) -> Any:
        """A x: displacement [length] from attached-element stresses x [stress]."""
        self._scatter(x)
        y = self._gather(self.idx)
        if self._springs:
            y += self.backend.xp.take(self.compliance * self.pillar_sums(x), self.pl)
        return y

    def precondition(self, r: Any) -> Any:
        """Per-pillar block inverse.

        With the dense blocks (`BlockInverse`, `DeviceBlocks` on a device)
        each pillar's own elastic and spring coupling is inverted exactly.
        Pillars too large for dense blocks take the two-level tile
        preconditioner (`TileCoarse`, host only), and where even that does
        not fit (or on a device without room for blocks), (c I + s_p 1 1^T)^-1
        with c = K_ii, applied by Sherman-Morrison: exact on the spring part,
        so the iteration count stays flat even for very soft springs where S
        dominates.
        """
        if self.block is not None:
            return self.block.apply(r, self._bpos)
        if self.tiles is not None:
            return self.tiles.apply(r, self._tpos, self.diag, self.pl, self._tz)
        return (r - self._sm * self.pillar_sums(r)[self.pl]) / self.diag


def _spread_host(total: int, gone: np.ndarray, which: np.ndarray, stress: np.ndarray,
                 attached: np.ndarray) -> np.ndarray:
    """Compressed stresses from before a detachment (``which`` over them)
    as a vector over all ``total`` elements: the attached ones after it,
    and the ``gone`` ones (operator order), zero elsewhere."""
    full = np.zeros(total)
    full[attached] = stress[~which]
    full[gone] = stress[which]
    return full
