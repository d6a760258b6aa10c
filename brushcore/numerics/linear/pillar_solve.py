"""Exact per-pillar responses on small FFT grids, for pillars without dense inverses.

The local cascade of the block path (`brushcore.numerics.linear.precondition`)
answers a detachment with each pillar's exact response, the other pillars
held fixed: with D the detached elements of pillar p and p' the rest,

    B_p'p' d sigma = B_p'D sigma_D,      B = K + s_p 1 1^T,

which the dense inverse gives as a Schur complement.  Pillars of thousands
of elements (the 8 x 8 brush at 2048^2: 7,860) have no dense inverse, but
the same system is small: K restricted to one pillar is a convolution over
the pillar's bounding box, one FFT pair on a grid twice the box (200^2
against the 2048^2 of a global application), solved by CG with the tile
preconditioner's block of that pillar (`TileCoarse.apply_pillar`).  The
small transforms run on planned FFTW (`BoxTransforms`).  On a
mirror quadrant the pillar's own three images enter the same way: an
image's influence depends on i + j, a convolution of the flipped box.

What the local response leaves out is the far field of the other pillars'
changes, bounded as on the block path (`brushcore.numerics.halfspace.farfield`), with
the reach sum_j |G_p[i, j]| <= REACH / K_ii in place of the dense rows.
"""

from __future__ import annotations

import numpy as np
import scipy.fft as sfft

from brushcore.numerics.linear.cg import pcg
from brushcore.numerics.halfspace.convolution import HAVE_PYFFTW, planning
from brushcore.numerics.halfspace.farfield import FarFieldBound, near_influence
from brushcore.numerics.halfspace.kernel import (love_coefficient, pillar_index_centroids,
                                                 self_compliance)
from brushcore.numerics.linear.tiles import TileCoarse


class PillarSolver:
    """Local solves B_pp x = r of single pillars, and the far-field bound.

    Parameters
    ----------
    elements, pillar_of, n, compliance, h, e_star, mirrored : as for
        `brushcore.numerics.linear.precondition.BlockInverse`
    tiles : the tile preconditioner, whose per-pillar blocks precondition
        the local solves
    """

    #: Bound on sum_j |G_p[i, j]| K_ii, the reach of a pillar's inverse.
    #: Measured on the dense blocks (regular and random brushes of 64-220
    #: pillars at 256^2 and 512^2, rigid to kbar 1e-5, at every third event
    #: of the pull-off): 2.53-2.61, the same inside a contact and at its
    #: edge, since G behaves like the half space's inverse, whose rows are
    #: local; 2 G_ii K_ii, and G_ii grows as a contact grows (a principal
    #: submatrix's inverse has the smaller diagonal), so the interior of a
    #: large contact is the worst case.  3 leaves 15 % to spare.
    REACH = 3.0
    #: Relative tolerance of the local solves (against the largest response).
    RTOL = 1e-9
    #: CG iterations a local solve may take.
    MAX_ITER = 500

    def __init__(self, elements: np.ndarray, pillar_of: np.ndarray, n: int,
                 compliance: np.ndarray, h: float, e_star: float, mirrored: bool,
                 tiles: TileCoarse) -> None:
        n_pillars = compliance.size
        self._transforms = BoxTransforms()
        self._h, self._e_star, self._mirrored = h, e_star, mirrored
        self._compliance = np.asarray(compliance, dtype=float)
        self._tiles = tiles
        self._pillar_of = pillar_of
        iy, ix = np.divmod(elements, n)
        self._members = tiles.members
        y0 = np.array([iy[m].min() for m in self._members])
        x0 = np.array([ix[m].min() for m in self._members])
        self._corner = np.stack([y0, x0], axis=1)
        self._box = np.stack([[iy[m].max() + 1 for m in self._members] - y0,
                              [ix[m].max() + 1 for m in self._members] - x0], axis=1)
        # Each member's flat index in its pillar's box.
        self._in_box = np.empty(elements.size, dtype=np.intp)
        for p, m in enumerate(self._members):
            self._in_box[m] = (iy[m] - y0[p]) * self._box[p, 1] + (ix[m] - x0[p])
        self._spectra: dict[int, np.ndarray] = {}
        cy, cx = pillar_index_centroids(pillar_of, iy, ix, h, n_pillars)
        radius = np.zeros(n_pillars)
        np.maximum.at(radius, pillar_of, np.hypot(iy * h - cy[pillar_of], ix * h - cx[pillar_of]))
        self.bound = (FarFieldBound(near_influence(cy, cx, radius, h, e_star, mirrored))
                      if n_pillars > 1 else None)
        self.diag = self_compliance(h=h, e_star=e_star)

    def _fft_shape(self, p: int) -> tuple[int, int]:
        by, bx = self._box[p]
        return sfft.next_fast_len(2 * int(by)), sfft.next_fast_len(2 * int(bx), real=True)

    def _kernel_spectra(self, p: int) -> np.ndarray:
        """Transforms of pillar p's kernels: direct, and on a quadrant the
        three images, each for the box flipped along the image's axes."""
        if p in self._spectra:
            return self._spectra[p]
        (by, bx), (y0, x0) = self._box[p], self._corner[p]
        py, px = self._fft_shape(p)
        ky = np.arange(py)
        ky = np.where(ky < by, ky, ky - py)  # offsets a - c, wrapped
        kx = np.arange(px)
        kx = np.where(kx < bx, kx, kx - px)
        # Image offset: iy + jy + 1 = 2 y0 + by + (a - c') with c' = by - 1 - c.
        dys = [ky] + ([2 * y0 + by + ky] if self._mirrored else [])
        dxs = [kx] + ([2 * x0 + bx + kx] if self._mirrored else [])
        kernels = [love_coefficient(dy[:, None] * self._h, dx[None, :] * self._h,
                                    self._h, self._e_star) for dy in dys for dx in dxs]
        spectra = sfft.rfft2(np.stack(kernels))
        self._spectra[p] = spectra
        return spectra

    def _convolve(self, p: int, box: np.ndarray) -> np.ndarray:
        """Displacement over pillar p's box [length] from stresses on it
        [stress], images included on a quadrant."""
        spectra = self._kernel_spectra(p)
        shape = self._fft_shape(p)
        sources = [box]
        if self._mirrored:  # in the order of the kernels: (y, x) direct or flipped
            sources = [box, box[:, ::-1], box[::-1, :], box[::-1, ::-1]]
        return self._transforms(np.stack(sources), spectra, shape)

    def _operator(self, p: int, where: np.ndarray, values: np.ndarray,
                  at: np.ndarray) -> np.ndarray:
        """B_p restricted: displacement at members ``at`` from stresses
        ``values`` on members ``where`` (operator-order indices)."""
        box = np.zeros(self._box[p])
        box.ravel()[self._in_box[where]] = values
        field = self._convolve(p, box).ravel()[self._in_box[at]]
        return field + self._compliance[p] * values.sum()

    def respond(self, full: np.ndarray, attached: np.ndarray, gone: np.ndarray) -> None:
        """Update ``full`` (stresses over all elements, operator order) in
        place with each pillar's exact response to losing ``gone``.

        ``attached`` is the attached mask after the loss; ``gone`` the
        operator-order indices just detached, whose entries are zeroed.
        """
        pillars = self._pillar_of[gone]
        for p in np.unique(pillars):
            d = gone[pillars == p]
            members = self._members[p]
            rest = members[attached[members]]
            if rest.size:
                rhs = self._operator(p, d, full[d], rest)
                full[rest] += self._solve(p, rest, rhs)
            full[d] = 0.0

    def _solve(self, p: int, rest: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """B_p'p'^-1 rhs over the attached members ``rest`` of pillar p."""
        x, _ = pcg(lambda v: self._operator(p, rest, v, rest),
                   lambda r: self._tiles.apply_pillar(p, r, rest, self.diag),
                   rhs, np.zeros_like(rhs), self.RTOL, self.MAX_ITER)
        return x

    def far_field_uncertainty(self, pillar_change: np.ndarray,
                              pillar_of: np.ndarray) -> np.ndarray:
        """Bound on each attached element's stress change from the other
        pillars' summed changes ``pillar_change`` [stress] (first order;
        see `brushcore.numerics.halfspace.farfield`); ``pillar_of`` per attached element."""
        if self.bound is None:
            return np.zeros(pillar_of.size)
        shift = self.bound.shift(np.abs(pillar_change))
        return (self.REACH / self.diag) * shift[pillar_of]


class BoxTransforms:
    """The local solves' convolutions on planned FFTW transforms (double
    precision, one thread), one plan pair per number of sources and
    transform shape; scipy.fft without pyfftw.

    Pillars' boxes come in a few transform shapes (`next_fast_len` rounds
    their doubled sides), so a curve makes a few plans, kept in FFTW's
    wisdom like the whole grid's.  A pair on the 200^2 grid of a pillar of
    radius 50 (the 8 x 8 brush at 2048^2), one thread, 2026-12-04 on an
    AMD EPYC: 0.31 ms planned, against 1.06 on scipy.fft and 1.13 on MKL
    (0.08 / 0.15 / 0.16 ms on 100^2; four sources on a quadrant, 200^2:
    0.87 / 4.07 / 3.36 ms); planning took 0.2-0.4 s a shape without wisdom.
    """

    def __init__(self) -> None:
        self._plans: dict[tuple[int, int, int], tuple] = {}

    def _plan(self, count: int, shape: tuple[int, int]) -> tuple:
        key = (count, *shape)
        if key not in self._plans:
            import pyfftw

            py, px = shape
            real = pyfftw.empty_aligned((count, py, px), "float64")
            half = pyfftw.empty_aligned((count, py, px // 2 + 1), "complex128")
            product = pyfftw.empty_aligned((py, px // 2 + 1), "complex128")
            field = pyfftw.empty_aligned((py, px), "float64")
            with planning():
                forward = pyfftw.FFTW(real, half, axes=(1, 2), flags=("FFTW_MEASURE",))
                backward = pyfftw.FFTW(product, field, axes=(0, 1), direction="FFTW_BACKWARD",
                                       flags=("FFTW_MEASURE",))
            self._plans[key] = (real, half, product, forward, backward)
        return self._plans[key]

    def __call__(self, sources: np.ndarray, spectra: np.ndarray,
                 shape: tuple[int, int]) -> np.ndarray:
        """sum_k of sources[k] convolved with the kernel whose spectrum is
        spectra[k] (``rfft2`` at ``shape``), over the sources' box.

        Parameters
        ----------
        sources : (k, by, bx) stresses [stress]
        spectra : (k, py, px // 2 + 1) kernel spectra [length / stress]
        shape : (py, px), the transform grid (at least twice the box)
        """
        count, by, bx = sources.shape
        if not HAVE_PYFFTW:  # pragma: no cover - pyfftw is a declared dependency
            field = sfft.irfft2((sfft.rfft2(sources, s=shape) * spectra).sum(axis=0), s=shape)
            return field[:by, :bx]
        real, half, product, forward, backward = self._plan(count, tuple(shape))
        real[...] = 0.0  # planning and larger boxes of the same shape leave values
        real[:, :by, :bx] = sources
        forward()
        if count == 1:
            np.multiply(half[0], spectra[0], out=product)
        else:
            np.sum(half * spectra, axis=0, out=product)
        return backward()[:by, :bx].copy()
