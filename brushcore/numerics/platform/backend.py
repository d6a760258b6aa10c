"""The one place that knows where arrays live: NumPy, CuPy or a strict array-API namespace.

The engine (operator, CG, preconditioner, pull-off and protocol engines)
is written against ``backend.xp``, an array-API namespace, plus the few
calls the standard lacks (`bincount`, `put`, `flatnonzero`),
which each backend provides natively:

- ``cpu``: NumPy (the default).  Every helper is the plain NumPy call, so the
  CPU path pays nothing for the abstraction.
- ``gpu``: CuPy, imported only when chosen (an optional backend costs
  nothing to those who do not use it), seen through `array_api_compat.cupy`
  (CuPy 13 lacks some array-API names, e.g. ``bool``, ``concat``,
  ``asarray(copy=...)``).  cuFFT plans are cached by CuPy's plan cache,
  float64 throughout.
- ``strict``: `array_api_strict` on the CPU, for tests: a call that would
  not port to another namespace fails here without a GPU.  Its helpers
  reach into the wrapped NumPy array, as CuPy's native calls would.

`resolve_backend` validates a name and what it needs (CuPy, a card)
before any work starts.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from functools import lru_cache
from types import ModuleType
from typing import Any

import numpy as np

from brushcore.validation import ParameterError

#: Backends a user may choose (``strict`` is for tests).
BACKENDS = ("cpu", "gpu", "strict")
#: What the CLI and the workflow offer.
USER_BACKENDS = ("cpu", "gpu")
GPU_INSTALL = "pip install 'brushcore[gpu]'"


@dataclass(frozen=True)
class Backend:
    """An array namespace and the few operations that differ between namespaces.

    Parameters
    ----------
    name : "cpu", "gpu" or "strict"
    xp : the array-API namespace (numpy, array_api_compat.cupy, array_api_strict)
    native : the library itself (numpy, cupy, array_api_strict), for the
        calls the standard lacks and for the device
    """

    name: str
    xp: ModuleType = field(repr=False, compare=False)
    native: ModuleType = field(repr=False, compare=False)

    @property
    def on_host(self) -> bool:
        """Whether arrays are NumPy arrays (the CPU-specialised kernels apply)."""
        return self.name == "cpu"

    # --- moving data ----------------------------------------------------
    def asarray(self, x: Any, dtype: Any = None) -> Any:
        """A device array from host data (a no-op for NumPy arrays on cpu)."""
        if self.name == "cpu":
            return np.asarray(x, dtype=dtype)
        if self._on_device(x):
            return self.xp.asarray(x, dtype=None if dtype is None else self._dtype(dtype))
        if dtype is None:
            dtype = np.asarray(x).dtype
        return self.xp.asarray(np.asarray(x, dtype=dtype), dtype=self._dtype(dtype))

    def _on_device(self, x: Any) -> bool:
        """Whether ``x`` is already an array of this backend."""
        if self.name == "gpu":
            return isinstance(x, self.native.ndarray)
        return type(x).__module__.startswith(self.native.__name__)

    def _dtype(self, dtype: Any) -> Any:
        """The namespace's dtype object for a NumPy dtype."""
        return getattr(self.xp, np.dtype(dtype).name)

    def to_host(self, x: Any) -> np.ndarray:
        """A NumPy array from a device array (a no-op on cpu)."""
        if self.name == "gpu":
            return self.native.asnumpy(x)
        if self.name == "strict":
            return np.asarray(x._array)
        return np.asarray(x)

    # --- what the array API lacks ----------------------------------------
    def flatnonzero(self, mask: Any) -> Any:
        """Indices of the true entries of a 1-D boolean array."""
        if self.name == "strict":
            return self.xp.nonzero(mask)[0]
        return self.native.flatnonzero(mask)

    def bincount(self, index: Any, weights: Any = None, minlength: int = 0) -> Any:
        """Sum of ``weights`` (or counts) per integer label, length >= ``minlength``."""
        if self.name == "strict":
            w = None if weights is None else weights._array
            out = np.bincount(index._array, weights=w, minlength=minlength)
            return self.xp.asarray(out)
        if self.name == "gpu" and index.shape[0] == 0:
            # CuPy before cupy#9951 (2026) raises on an empty index where NumPy
            # gives zeros, and a pull-off's last detachment empties it.
            dtype = self.xp.int64 if weights is None else weights.dtype
            return self.xp.zeros(minlength, dtype=dtype)
        return self.native.bincount(index, weights=weights, minlength=minlength)

    def put(self, target: Any, index: Any, values: Any) -> None:
        """target[index] = values in place: an integer index along the first
        axis (entries of a 1-D target, rows or blocks of a stacked one)."""
        if self.name == "strict":
            v = values._array if hasattr(values, "_array") else values
            target._array[index._array] = v
            return
        target[index] = values

    # --- the device ---------------------------------------------------------
    def synchronize(self) -> None:
        """Wait for queued device work (for timing); no-op on the host."""
        if self.name == "gpu":
            self.native.cuda.Device().synchronize()

    def free_memory(self) -> float:
        """Free device memory [bytes], including CuPy's cached pool blocks; inf on the host."""
        if self.name != "gpu":
            return float("inf")
        free, _ = self.native.cuda.runtime.memGetInfo()
        pool = self.native.get_default_memory_pool()
        return float(free + pool.total_bytes() - pool.used_bytes())

    @property
    def device_name(self) -> str:
        """The card's name, or "cpu"."""
        if self.name != "gpu":
            return "cpu"
        cuda = self.native.cuda
        props = cuda.runtime.getDeviceProperties(cuda.Device().id)
        name = props["name"]
        return name.decode() if isinstance(name, bytes) else str(name)

    @property
    def device_memory_bytes(self) -> int:
        """Total memory of the card [bytes]; 0 on the host."""
        if self.name != "gpu":
            return 0
        return int(self.native.cuda.runtime.memGetInfo()[1])


#: What a refused "gpu" allows: the choice holds only where a card is usable.
_GPU_ALLOWED = "'cpu' here; 'gpu' where CuPy and a CUDA device are"


def _import_cupy() -> tuple[ModuleType, ModuleType]:
    """CuPy and its array-API view, with a usable card, or ParameterError
    naming what is missing."""
    try:
        cupy = importlib.import_module("cupy")
    except ImportError:
        raise ParameterError("backend", "gpu", _GPU_ALLOWED,
                             f"CuPy is not installed: {GPU_INSTALL}") from None
    try:
        count = int(cupy.cuda.runtime.getDeviceCount())
    except Exception:  # CUDARuntimeError without a driver
        count = 0
    if count < 1:
        raise ParameterError("backend", "gpu", _GPU_ALLOWED,
                             "no CUDA device visible (check nvidia-smi and "
                             "CUDA_VISIBLE_DEVICES)")
    try:
        compat = importlib.import_module("array_api_compat.cupy")
    except ImportError:
        raise ParameterError("backend", "gpu", _GPU_ALLOWED,
                             f"array-api-compat is not installed: {GPU_INSTALL}") from None
    return compat, cupy


def namespace(x: Any) -> Any:
    """The array-API namespace of ``x``: numpy for NumPy arrays (the CPU path
    as it always was), else array_api_compat's view when installed (CuPy's
    own namespace lacks some standard names), else the array's own."""
    if isinstance(x, np.ndarray):
        return np
    try:
        from array_api_compat import array_namespace
    except ImportError:
        return x.__array_namespace__()
    return array_namespace(x)


@lru_cache(maxsize=None)
def resolve_backend(name: str = "cpu") -> Backend:
    """The backend called ``name``, checked before any work.

    Raises
    ------
    ParameterError
        For an unknown name, or "gpu" without CuPy or without a visible
        CUDA device, or "strict" without array-api-strict.
    """
    if name not in BACKENDS:
        raise ParameterError("backend", name, "'cpu' (the default) or 'gpu'")
    if name == "cpu":
        return CPU
    if name == "strict":
        try:
            strict = importlib.import_module("array_api_strict")
        except ImportError:
            raise ParameterError("backend", name, "'cpu' (the default) or 'gpu'",
                                 "array-api-strict is not installed: "
                                 "pip install array-api-strict") from None
        return Backend("strict", strict, strict)
    return Backend("gpu", *_import_cupy())


CPU = Backend("cpu", np, np)
