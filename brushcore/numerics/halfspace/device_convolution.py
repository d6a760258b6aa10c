"""Non-periodic DC-FFT convolution on any array namespace (the GPU's convolver).

The same operation as `brushcore.numerics.halfspace.convolution.Convolver`: the n x n
stress is zero-padded to 2n x 2n and multiplied by the wrapped kernel's
spectrum.  Here the padding is left to the FFT (``s=(2n, 2n)``) and one
2-D real transform pair does the work: on a GPU one cuFFT call per
direction beats the CPU convolver's four pruned passes, and CuPy caches
the cuFFT plans, so each grid is planned once per process.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np

from brushcore.numerics.platform.backend import Backend
from brushcore.numerics.halfspace.kernel import wrapped_kernel


class DeviceConvolver:
    """u = K * sigma on an n x n grid, arrays in ``backend``'s namespace.

    Parameters
    ----------
    n : grid size (elements per side)
    h : element size [length]
    e_star : effective modulus E* [stress]
    backend : where the arrays live (`brushcore.numerics.platform.backend`)

    Notes
    -----
    The buffer is the flat n x n grid itself (`padded_index` is the
    identity); `flat_buffer` and `apply_flat` are what `BrushOperator` uses.
    """

    mirrored = False

    def __init__(self, n: int, h: float, e_star: float, backend: Backend) -> None:
        self.n = n
        self.applications = 0
        self.array_backend = backend
        xp = backend.xp
        # The wrapped kernel is even in both axes, so its spectrum is real;
        # both are computed where the arrays live.
        spectrum = xp.real(xp.fft.rfftn(wrapped_kernel(n, h, e_star, xp)))
        self.spectrum = xp.asarray(spectrum, copy=True)
        self.flat_buffer = xp.zeros(n * n, dtype=xp.float64)

    def padded_index(self, flat: np.ndarray) -> np.ndarray:
        """Flat indices into `flat_buffer` (the grid's own)."""
        return np.asarray(flat, dtype=np.intp)

    def apply_flat(self) -> Any:
        """K * `flat_buffer` as a flat n x n array [length] (a new array)."""
        self.applications += 1
        xp, n = self.array_backend.xp, self.n
        grid = xp.reshape(self.flat_buffer, (n, n))
        spec = xp.fft.rfftn(grid, s=(2 * n, 2 * n), axes=(0, 1))
        spec *= self.spectrum
        out = xp.fft.irfftn(spec, s=(2 * n, 2 * n), axes=(0, 1))
        return xp.reshape(out[:n, :n], (n * n,))

    def __call__(self, stress: Any) -> Any:
        """Displacement [length] from an n x n stress field [stress] (a new array)."""
        xp = self.array_backend.xp
        self.flat_buffer = xp.reshape(xp.asarray(stress, copy=True), (self.n * self.n,))
        out = self.apply_flat()
        self.flat_buffer = xp.zeros(self.n * self.n, dtype=xp.float64)
        return xp.reshape(out, (self.n, self.n))


@lru_cache(maxsize=4)
def cached_device_convolver(n: int, h: float, e_star: float, backend: Backend
                            ) -> DeviceConvolver:
    """One DeviceConvolver per (grid, h, E*, backend) in a process."""
    return DeviceConvolver(n, h, e_star, backend)
