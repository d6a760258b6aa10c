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

import numpy as np

from brushcore.numerics.convolution import Convolver
from brushcore.numerics.precondition import BlockInverse
from brushcore.numerics.tiles import TileCoarse
from brushcore.numerics.kernel import self_compliance


class BrushOperator:
    """Matrix-free A = P_C (K + S) P_C over the attached pillar elements.

    Parameters
    ----------
    convolver : the DC-FFT convolution K for the grid
    labels : pillar index per element, -1 outside pillars, shape (n, n)
    compliance : spring compliance h^2 / k_p per pillar, shape (N,)
        [length / stress]; 0 for rigid pillars
    h : element size [length]
    e_star : effective modulus [stress]

    Notes
    -----
    Vectors are compressed to the attached elements in the order of
    `elements[attached]`.  `detach` shrinks the set; it never grows during
    a pull-off.  `attach` grows it again (approach and re-attachment, see
    `brushcore.numerics.protocol`).
    """

    def __init__(self, convolver: Convolver, labels: np.ndarray, compliance: np.ndarray,
                 h: float, e_star: float, use_block: bool = True, coarse: bool = True) -> None:
        self.conv = convolver
        flat = labels.ravel()
        self.elements = np.flatnonzero(flat >= 0)  # flat n x n indices of pillar elements
        self.pillar_of = flat[self.elements].astype(np.intp)
        self.n_pillars = int(labels.max()) + 1
        self.compliance = np.asarray(compliance, dtype=float)
        self.diag = self_compliance(e_star, h)
        self._padded = convolver.padded_index(self.elements)
        self.conv.buffer[...] = 0.0
        self.attached = np.ones(self.elements.size, dtype=bool)
        self.block = (BlockInverse(self.elements, self.pillar_of, convolver.n,
                                   self.compliance, h, e_star, coarse,
                                   getattr(convolver, "mirrored", False))
                      if use_block and BlockInverse.fits(self.pillar_of) else None)
        # Pillars too large for dense blocks: the two-level tile preconditioner.
        self.tiles = (TileCoarse(self.elements, self.pillar_of, convolver.n,
                                 self.compliance, h, e_star)
                      if use_block and self.block is None
                      and TileCoarse.fits(self.elements, self.pillar_of, convolver.n)
                      else None)
        self._update()

    def _update(self) -> None:
        self.idx = self._padded[self.attached]
        if self.block is not None:
            self._bpos = self.block.pos[self.attached]
        if self.tiles is not None:
            self._tpos = self.tiles.tile_of[self.attached]
        self.pl = self.pillar_of[self.attached]
        self.counts = np.bincount(self.pl, minlength=self.n_pillars)
        # Sherman-Morrison for the per-pillar block (c I + s 1 1^T)^-1.
        s = self.compliance
        self._sm = (s / (self.diag + s * self.counts))[self.pl]

    @property
    def size(self) -> int:
        """Number of attached elements."""
        return int(self.idx.size)

    def detach(self, which: np.ndarray, stress: np.ndarray | None = None) -> np.ndarray | None:
        """Detach attached elements given by a boolean mask over the compressed vector.

        With ``stress`` (compressed, before detaching) and the block
        preconditioner, returns the stresses of the remaining elements after
        each pillar's exact local response to the loss (other pillars'
        field held fixed); otherwise None.
        """
        gone = self.idx[which]
        self.conv.buffer.ravel()[gone] = 0.0
        pos = np.flatnonzero(self.attached)[which]
        local = None
        if self.block is not None:
            local = self.block.detach(pos, stress, None if stress is None else self._bpos)
        if self.tiles is not None:
            self.tiles.detach(pos)
        self.attached[pos] = False
        self._update()
        return None if local is None else local[~which]

    def attach(self, positions: np.ndarray) -> None:
        """Attach detached elements given by operator-order indices (into `elements`).

        Their buffer entries are already zero (`detach` cleared them); the
        block preconditioner is bordered with the new elements.
        """
        positions = np.asarray(positions, dtype=np.intp)
        if positions.size == 0:
            return
        if self.attached[positions].any():
            raise ValueError("attach: some elements are already attached")
        if self.block is not None:
            self.block.attach(positions)
        if self.tiles is not None:
            self.tiles.attach(positions)
        self.attached[positions] = True
        self._update()

    def field(self, x: np.ndarray) -> np.ndarray:
        """Half-space displacement K x [length] at every pillar element
        (operator order) from attached-element stresses x [stress]; one
        operator application."""
        buf = self.conv.buffer.ravel()
        buf[self.idx] = x
        return self.conv.apply_buffer().ravel()[self._padded]

    def spring(self, x: np.ndarray) -> np.ndarray:
        """Spring part S x of A x (compressed) [length]."""
        if self.compliance.any():
            return (self.compliance * self.pillar_sums(x))[self.pl]
        return np.zeros_like(x)

    def apply_with_field(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(A x, K x at every pillar element) from one operator application."""
        full = self.field(x)
        return full[self.attached] + self.spring(x), full

    def far_field_uncertainty(self, pillar_change: np.ndarray) -> np.ndarray | None:
        """See `BlockInverse.far_field_uncertainty` (None without blocks)."""
        if self.block is None:
            return None
        return self.block.far_field_uncertainty(pillar_change, self._bpos)

    @property
    def has_local_solver(self) -> bool:
        """Whether per-pillar exact inverses are available (see `detach`)."""
        return self.block is not None

    def pillar_sums(self, x: np.ndarray) -> np.ndarray:
        """Sum of a compressed vector over each pillar, shape (N,)."""
        return np.bincount(self.pl, weights=x, minlength=self.n_pillars)

    def apply(self, x: np.ndarray) -> np.ndarray:
        """A x: displacement [length] from attached-element stresses x [stress]."""
        buf = self.conv.buffer.ravel()
        buf[self.idx] = x
        y = self.conv.apply_buffer().ravel()[self.idx]
        if self.compliance.any():
            y += (self.compliance * self.pillar_sums(x))[self.pl]
        return y

    def precondition(self, r: np.ndarray) -> np.ndarray:
        """Per-pillar block inverse.

        With the dense blocks (`BlockInverse`) each pillar's own elastic and
        spring coupling is inverted exactly.  Pillars too large for dense
        blocks take the two-level tile preconditioner (`TileCoarse`), and
        where even that does not fit, (c I + s_p 1 1^T)^-1 with c = K_ii,
        applied by Sherman-Morrison: exact on the spring part, so the
        iteration count stays flat even for very soft springs where S
        dominates.
        """
        if self.block is not None:
            return self.block.apply(r, self._bpos)
        if self.tiles is not None:
            return self.tiles.apply(r, self._tpos, self.diag)
        return (r - self._sm * self.pillar_sums(r)[self.pl]) / self.diag
