"""Mirror symmetry: a brush symmetric about both mid-lines, solved on one quadrant.

A label map unchanged by the flips y -> L - y and x -> L - x (every regular
brush, with equal springs) has a symmetric solution: each detachment happens
in all four images of an element at once (the full solver keeps them
together with its tie tolerance).  The stress then lives on one quadrant,
and the field there is a symmetric convolution (Martucci, IEEE Trans.
Signal Process. 42 (1994) 1038):

    u_Q = C3( C2(sigma_Q) * K^[:n, :n] ) / (2n)^2,

with C2 / C3 the unnormalised DCT-II / DCT-III of length n along each axis
(FFTW's REDFT10 / REDFT01) and K^ the real spectrum of the 2n x 2n DC-FFT
kernel.  Each axis transforms length n where the DC-FFT transforms 2n, on
n/2 non-zero rows: about a quarter of the work on a quarter of the unknowns.
The quadrant kept is the one at the far corner (rows and columns n/2 ... n-1);
its mirror lines lie half an element before its first row and column.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from brushcore.numerics.halfspace.convolution import HAVE_PYFFTW, HostBuffers, planning
from brushcore.numerics.halfspace.kernel import wrapped_kernel

if HAVE_PYFFTW:
    import pyfftw


class MirrorConvolver(HostBuffers):
    """u = K * sigma on the quadrant of a field symmetric about both mid-lines.

    Same interface as `brushcore.numerics.halfspace.convolution.Convolver`, with
    ``n`` the quadrant's size (half the grid): an operator built on it sees
    the quadrant as its grid.

    Parameters
    ----------
    grid : size of the full grid (even, elements per side)
    h, e_star, threads, use_pyfftw, single : as for `Convolver`
    """

    #: The operator's images: see `brushcore.numerics.halfspace.kernel.folded_coefficient`.
    mirrored = True

    def __init__(self, grid: int, h: float = 1.0, e_star: float = 1.0, threads: int = 1,
                 use_pyfftw: bool = True, single: bool = False) -> None:
        if grid % 2:
            raise ValueError(f"mirror symmetry needs an even grid, got {grid}")
        self.full = grid
        self.n = grid // 2
        self.threads = threads
        self.single = single
        self.applications = 0
        spectrum = np.fft.rfft2(wrapped_kernel(grid, h, e_star)).real[:grid, :grid]
        self.spectrum = np.ascontiguousarray(spectrum)
        self.backend = "pyfftw" if (use_pyfftw and HAVE_PYFFTW) else "scipy"
        # Both transform libraries leave the factor (2 grid)^2 of the pair to us.
        self._scaled = (self.spectrum / float(4 * grid * grid)).astype(self.real_dtype)
        if self.backend == "pyfftw":
            self._plan()
        else:
            self._real_in = np.zeros((self.n, grid))
            self._real_out = np.zeros((self.n, grid))

    def _plan(self) -> None:
        m, g = self.n, self.full
        empty = pyfftw.empty_aligned
        real = self.real_dtype
        self._real_in = empty((m, g), dtype=real)
        self._work = empty((g, g), dtype=real)
        self._real_out = empty((m, g), dtype=real)
        flags = ("FFTW_MEASURE",)
        dct2, dct3 = ["FFTW_REDFT10"], ["FFTW_REDFT01"]
        with planning():
            self._rows_fwd = pyfftw.FFTW(self._real_in, self._work[:m], axes=(1,),
                                         direction=dct2, flags=flags, threads=self.threads)
            self._cols_fwd = pyfftw.FFTW(self._work, self._work, axes=(0,), direction=dct2,
                                         flags=flags, threads=self.threads)
            self._cols_bwd = pyfftw.FFTW(self._work, self._work, axes=(0,), direction=dct3,
                                         flags=flags, threads=self.threads)
            self._rows_bwd = pyfftw.FFTW(self._work[:m], self._real_out, axes=(1,),
                                         direction=dct3, flags=flags, threads=self.threads)
        self._real_in[:] = 0.0  # planning with FFTW_MEASURE scribbles on buffers

    @property
    def buffer(self) -> np.ndarray:
        """The zero-padded quadrant input, shape (n, 2n); columns n: must stay zero."""
        return self._real_in

    def padded_index(self, flat: np.ndarray) -> np.ndarray:
        """Flat indices into the (n, 2n) buffers from flat indices of the n x n quadrant."""
        row, col = np.divmod(np.asarray(flat, dtype=np.intp), self.n)
        return row * self.full + col

    def apply_buffer(self) -> np.ndarray:
        """Convolve `buffer`; returns the (n, 2n) output whose first n columns are u.

        The output is overwritten by the next call.
        """
        self.applications += 1
        m = self.n
        if self.backend == "pyfftw":
            return self._pruned(self._work, self._work)
        import scipy.fft as sfft

        padded = np.zeros((self.full, self.full))
        padded[:m] = self._real_in
        spec = sfft.dctn(padded, type=2, workers=self.threads)
        spec *= self.spectrum
        self._real_out[...] = sfft.idctn(spec, type=2, workers=self.threads)[:m]
        return self._real_out


@lru_cache(maxsize=2)
def cached_mirror_convolver(grid: int, h: float, e_star: float, threads: int,
                            single: bool = False) -> MirrorConvolver:
    """One MirrorConvolver per (grid, h, E*, threads, precision) in a process:
    plans are costly."""
    return MirrorConvolver(grid, h, e_star, threads, single=single)


@dataclass(frozen=True)
class Quadrant:
    """The far-corner quadrant of a doubly mirror-symmetric brush.

    Attributes
    ----------
    labels : quadrant label map (rows and columns n/2 ... n-1 of the grid),
        pillars renumbered 0 ... N/4 - 1, -1 outside pillars
    images : full-grid pillar index of each quadrant pillar and of its
        images under the y flip, the x flip and both, shape (N/4, 4)
    """

    labels: np.ndarray
    images: np.ndarray

    def unfold_field(self, quadrant: np.ndarray) -> np.ndarray:
        """The full-grid field of a quadrant field (mirrored about both mid-lines)."""
        top = np.concatenate([quadrant[::-1, ::-1], quadrant[::-1]], axis=1)
        bottom = np.concatenate([quadrant[:, ::-1], quadrant], axis=1)
        return np.concatenate([top, bottom], axis=0)

    def unfold_pillars(self, values: np.ndarray) -> np.ndarray:
        """Per-pillar values in full label order from per-quadrant-pillar values."""
        out = np.empty(self.images.size, dtype=np.asarray(values).dtype)
        for k in range(4):
            out[self.images[:, k]] = values
        return out


def _flip_map(labels: np.ndarray, flipped: np.ndarray) -> np.ndarray | None:
    """Pillar p -> pillar of p's mirror image, or None if the flip is no relabelling."""
    inside = labels >= 0
    if not np.array_equal(inside, flipped >= 0):
        return None
    pairs = np.unique(np.stack([labels[inside], flipped[inside]]), axis=1)
    n_pillars = int(labels.max()) + 1
    if pairs.shape[1] != n_pillars or np.unique(pairs[1]).size != n_pillars:
        return None  # a pillar's image is split over pillars, or pillars merge
    image = np.empty(n_pillars, dtype=np.intp)
    image[pairs[0]] = pairs[1]
    return image


def mirror_quadrant(labels: np.ndarray, compliance: np.ndarray) -> Quadrant | None:
    """The quadrant problem of a brush symmetric about both mid-lines, or None.

    Symmetric means: the grid is even, both flips map pillars onto pillars
    of the same spring compliance, and no pillar crosses a mid-line (a
    pillar's images are other pillars, so its spring sums over the quadrant
    alone).

    Parameters
    ----------
    labels : pillar index per element, -1 outside pillars, shape (n, n)
    compliance : spring compliance per pillar [length / stress]
    """
    n = labels.shape[0]
    if labels.ndim != 2 or labels.shape[1] != n or n % 2 or n < 4 or labels.max() < 0:
        return None
    map_y = _flip_map(labels, labels[::-1])
    map_x = _flip_map(labels, labels[:, ::-1])
    if map_y is None or map_x is None:
        return None
    compliance = np.asarray(compliance, dtype=float)
    if not (np.array_equal(compliance[map_y], compliance)
            and np.array_equal(compliance[map_x], compliance)):
        return None
    m = n // 2
    corner = labels[m:, m:]
    own = np.unique(corner[corner >= 0])
    outside = labels.copy()
    outside[m:, m:] = -1
    if own.size * 4 != int(labels.max()) + 1 or np.isin(own, outside).any():
        return None
    quad = np.where(corner >= 0, np.searchsorted(own, corner), -1)
    images = np.stack([own, map_y[own], map_x[own], map_y[map_x[own]]], axis=1)
    return Quadrant(quad.astype(labels.dtype), images)

