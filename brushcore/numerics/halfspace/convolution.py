"""Non-periodic convolution with the half-space kernel by pruned DC-FFT.

The stress lives on an n x n grid and is zero-padded to 2n x 2n (Liu, Wang &
Liu 2000).  A plain 2-D real FFT pair would transform 2n rows of which n
are zero going in, and return 2n rows of which n are discarded.  We do the
two axes separately and skip those rows: rows (length 2n, n of them) ->
columns (length 2n, n + 1 of them) -> multiply by the real kernel spectrum ->
columns back -> only the first n rows back.  That is 3/4 of the work of a
full pair.  FFTW plans are made once per grid (with wisdom cached on disk)
and reused for every application; scipy.fft is the fallback without pyfftw,
and Intel MKL (`brushcore.numerics.platform.mkl`) the faster choice where the
``mkl`` extra is installed.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import io
import os
import pickle
import sys
import threading
from collections.abc import Iterator
from functools import lru_cache
from pathlib import Path

import numpy as np

from brushcore.numerics.platform import mkl
from brushcore.numerics.platform.backend import CPU
from brushcore.numerics.halfspace.kernel import wrapped_kernel

try:  # pyfftw is a declared dependency; the fallback keeps the package importable
    import pyfftw

    HAVE_PYFFTW = True
except ImportError:  # pragma: no cover - exercised only where pyfftw is missing
    HAVE_PYFFTW = False

_WISDOM_LOCK = threading.Lock()


def cache_dir() -> Path:
    """This machine's brushcore cache (``BRUSHCORE_WISDOM_DIR``, else
    ``$XDG_CACHE_HOME/brushcore`` or ``~/.cache/brushcore``)."""
    # an empty variable as unset: "" put the cache in the working folder
    return Path(os.environ.get("BRUSHCORE_WISDOM_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "brushcore"))


#: Wisdom with its checksum (`_save_wisdom`); the file before it, a bare
#: tuple, is still read where the new one is missing and left as it was,
#: for versions that read only it.
WISDOM_FILE, OLD_WISDOM_FILE = "fftw-wisdom-v2.pickle", "fftw-wisdom.pickle"


def _wisdom_path() -> Path:
    return cache_dir() / WISDOM_FILE


@contextlib.contextmanager
def machine_lock(name: str) -> Iterator[None]:
    """Hold the lock file ``name`` in `cache_dir` (one process at a time on
    this machine); without a writable cache, no lock."""
    path = cache_dir() / name
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fh = open(path, "a")
    except OSError:
        yield
        return
    with fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:  # say why a run stands still (minutes at 2048^2)
            # a note, not a warning: warnings as errors must not fail the run
            print(f"brushcore: waiting for another brushcore process on this machine: it "
                  f"holds {path} while it plans or times its FFTs (once per grid and "
                  "machine; its plans are then shared)", file=sys.stderr, flush=True)
            fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _wisdom_lock() -> contextlib.AbstractContextManager[None]:
    """Serialise planning across processes on this machine.

    FFTW_MEASURE picks algorithms by timing, so two jobs planning at once
    under different load could pick different plans and round differently.
    With the lock the first job plans and saves wisdom; every later job
    imports it and gets the same plans, hence bit-identical results.
    """
    return machine_lock("fftw-wisdom.lock")


def _wisdom_digest(wisdom: tuple) -> str:
    """SHA-256 of exported wisdom (a tuple of bytes, one per precision)."""
    return hashlib.sha256(b"\0".join(wisdom)).hexdigest()


def _load_wisdom() -> tuple | None:
    """Import this machine's wisdom, if any and intact.

    Stored with its digest (files from before 2026-12-07 without): FFTW's
    importer does not refuse damaged wisdom but aborts the process in an
    assertion (3 bytes changed in the text: ``planner.c: assertion failed``,
    exit 134 and no message), and every later run on the machine with it.

    Returns
    -------
    tuple or None
        The wisdom imported (one bytes per precision), None where none was
        or where it came from `OLD_WISDOM_FILE`.
    """
    path = _wisdom_path()
    if not path.exists():
        path = cache_dir() / OLD_WISDOM_FILE
    try:
        data = path.read_bytes()
    except OSError:
        return None  # no or unreadable wisdom: plan afresh
    try:
        stored = _PlainUnpickler(io.BytesIO(data)).load()
    except Exception:  # noqa: BLE001 - any damage (a changed length byte: MemoryError,
        stored = None  # OverflowError, a module name: ImportError) is planned afresh
    wisdom = stored.get("wisdom") if isinstance(stored, dict) else stored
    intact = (isinstance(wisdom, tuple) and all(isinstance(w, bytes) for w in wisdom)
              and (not isinstance(stored, dict) or stored.get("sha256") == _wisdom_digest(wisdom)))
    if not intact:
        print(f"brushcore: FFTW wisdom in {path} is damaged (unreadable, or its checksum "
              "does not match); planning afresh, and the next save replaces it",
              file=sys.stderr, flush=True)
        return None
    try:
        pyfftw.import_wisdom(wisdom)
    except (ValueError, TypeError):
        return None
    # the old file's wisdom counts as none loaded: the save writes it in the new one
    return wisdom if path.name == WISDOM_FILE else None


class _PlainUnpickler(pickle.Unpickler):
    """Reads dicts, tuples, bytes and str only: the wisdom file names no
    class, and one that does is damaged (or planted; pickle would import and
    call what it names)."""

    def find_class(self, module: str, name: str):
        raise pickle.UnpicklingError(f"the wisdom file names {module}.{name}")


def save_to_cache(name: str, data: bytes) -> None:
    """Write ``data`` to the file ``name`` in `cache_dir`, atomically (a
    concurrent job never reads half a file); a read-only cache is skipped,
    which only costs the work of finding the data again next time."""
    path = cache_dir() / name
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())  # a crash must not leave a renamed, half-written file
        os.replace(tmp, path)
    except OSError as exc:  # a full or read-only cache: leave no temporary behind
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
        _note_unusable_cache(path.parent, exc)


#: Cache folders already said to be unusable (once per process, not per save).
_UNUSABLE_SAID: set[Path] = set()


def _note_unusable_cache(folder: Path, exc: OSError) -> None:
    """Say once that the cache cannot be written: plans it lacks are made
    afresh in every run (seconds at 512^2, minutes at 2048^2), and
    concurrent jobs plan without the machine's lock, so they may round
    differently.  (A cache that holds every plan a run needs is not written
    to, so a read-only one that does is never said.)"""
    if folder in _UNUSABLE_SAID:
        return
    _UNUSABLE_SAID.add(folder)
    # a note, not a warning: warnings as errors must not fail the run
    print(f"brushcore: cannot write the cache {folder} ({exc.strerror or exc}): FFT plans "
          "it lacks are made afresh in every run and not shared between jobs; set "
          "BRUSHCORE_WISDOM_DIR to a writable folder", file=sys.stderr, flush=True)


def _entries(wisdom: tuple) -> list[list[bytes]]:
    """Wisdom as its sorted lines per precision: FFTW exports the entries it
    imported in another order (same length, other bytes)."""
    return [sorted(w.splitlines()) for w in wisdom]


def _save_wisdom(loaded: tuple | None = None) -> None:
    """Save this process's wisdom, unless it is the wisdom ``loaded`` (no new
    plans: no write, and a read-only cache that holds the plans is no error)."""
    wisdom = pyfftw.export_wisdom()
    if loaded is not None and _entries(wisdom) == _entries(loaded):
        return
    save_to_cache(_wisdom_path().name,
                  pickle.dumps({"wisdom": wisdom, "sha256": _wisdom_digest(wisdom)}))


#: Grids (elements per side) whose `Convolver` plans with FFTW_PATIENT.
PATIENT_GRIDS = range(256, 1025)


def planner_flags(n: int) -> tuple[str, ...]:
    """FFTW planner effort for the `Convolver` of an n x n grid.

    FFTW_PATIENT tries more algorithms than FFTW_MEASURE and finds faster
    plans for the pruned pair where brushcore spends its time.  Measured
    on one core, both plans in one process, alternating: 0.82-0.89x the
    time per application at n = 256, 512 and 1024 in single precision and
    at 512 in double, for 5, 12 and 40 s of planning (single precision),
    once per machine (wisdom is cached on disk).  At n = 2048 it saves 2 %
    for 160 s of planning, and below 256 its seconds of planning outweigh
    what a curve there saves.  The mirrored quadrant's DCTs gained nothing (`MirrorConvolver`
    keeps FFTW_MEASURE, so regular brushes' results are unchanged).
    """
    return ("FFTW_PATIENT",) if n in PATIENT_GRIDS else ("FFTW_MEASURE",)


@contextlib.contextmanager
def planning() -> Iterator[None]:
    """Make FFTW plans inside this block: wisdom loaded first and saved after,
    one planner at a time on this machine (see `_wisdom_lock`)."""
    with _WISDOM_LOCK, _wisdom_lock():
        loaded = _load_wisdom()
        yield
        _save_wisdom(loaded)


class HostBuffers:
    """What `BrushOperator` sees of a convolver whose buffers are NumPy arrays.

    Subclasses provide ``buffer`` (the padded input) and ``apply_buffer``.
    """

    #: Arrays are NumPy arrays (see `brushcore.numerics.platform.backend`).
    array_backend = CPU

    @property
    def flat_buffer(self) -> np.ndarray:
        """`buffer` as a flat view (written at `padded_index` positions)."""
        return self.buffer.ravel()

    def apply_flat(self) -> np.ndarray:
        """`apply_buffer` as a flat view (float32 with single transforms)."""
        return self.apply_buffer().ravel()

    @property
    def real_dtype(self) -> str:
        """Precision of the planned transforms: float32 with ``single``."""
        return "float32" if self.single and self.backend in ("pyfftw", "mkl") else "float64"

    def _pruned(self, work: np.ndarray, product: np.ndarray) -> np.ndarray:
        """The planned pyfftw transforms: rows of the n data rows only, columns
        of the zero-padded ``work``, the kernel product, and back.

        ``product`` is ``work`` seen as real numbers (itself where it is
        real), multiplied in place by `_scaled` of the same shape."""
        work[self.n:] = 0.0  # zero padding, overwritten by the in-place columns
        self._rows_fwd.execute()
        self._cols_fwd.execute()
        np.multiply(product, self._scaled, out=product)
        self._cols_bwd.execute()
        self._rows_bwd.execute()
        return self._real_out

    def __call__(self, stress: np.ndarray) -> np.ndarray:
        """Displacement [length] from an n x n stress field [stress] (a new array)."""
        n = self.n
        self._real_in[:, :n] = stress
        return self.apply_buffer()[:, :n].astype(np.float64)


class Convolver(HostBuffers):
    """u = K * sigma on an n x n grid (non-periodic), with reusable FFT plans.

    Parameters
    ----------
    n : grid size (elements per side)
    h : element size [length]
    e_star : effective modulus E* [stress]
    threads : FFT threads (FFTW's threaded plans, or MKL's passes cut
        into slabs)
    use_pyfftw : use pyfftw when available (False forces scipy.fft)
    single : single-precision transforms (pyfftw and MKL; 1.4-1.8x faster,
        relative error ~1e-7, see `SolverOptions.precision`); the scipy
        fallback stays in double precision
    library : "fftw" (pyfftw, or scipy.fft where it is missing) or "mkl"
        (`brushcore.numerics.platform.mkl`; see `SolverOptions.fft_library`)
    """

    #: A plain grid: no mirror images (see `brushcore.numerics.halfspace.mirror`).
    mirrored = False

    def __init__(self, n: int, h: float = 1.0, e_star: float = 1.0, threads: int = 1,
                 use_pyfftw: bool = True, single: bool = False, library: str = "fftw") -> None:
        self.n = n
        self.threads = threads
        self.single = single
        self.applications = 0
        spectrum = np.fft.rfft2(wrapped_kernel(n, h, e_star))
        # The wrapped kernel is even in both axes, so its spectrum is real.
        self.spectrum = np.ascontiguousarray(spectrum.real)
        if library == "mkl":
            self.backend = "mkl"
        else:
            self.backend = "pyfftw" if (use_pyfftw and HAVE_PYFFTW) else "scipy"
        if self.backend == "mkl":
            real = self.real_dtype
            self._real_in = np.zeros((n, 2 * n), dtype=real)
            self._half = np.zeros((2 * n, n + 1), dtype="complex64" if real == "float32"
                                  else "complex128")
            self._real_out = np.zeros((n, 2 * n), dtype=real)
            # MKL's backward transforms are normalised: the kernel stays unscaled.
            self._scaled = np.repeat(self.spectrum.astype(real), 2, axis=1)
        elif self.backend == "pyfftw":
            self._plan()
            # FFTW transforms are unnormalised: fold 1/(2n)^2 into the kernel.
            # Repeated for each (re, im) pair, the product is a real one on the
            # spectrum's float view: 0.08 against 0.15 ms complex x real at
            # n = 512 in float32, and the same numbers (a * s - b * 0 = a * s).
            scaled = (self.spectrum / float(4 * n * n)).astype(self.real_dtype)
            self._scaled = np.repeat(scaled, 2, axis=1)
        else:
            self._real_in = np.zeros((n, 2 * n))
            self._real_out = np.zeros((n, 2 * n))

    def _plan(self) -> None:
        n, nc = self.n, self.n + 1
        empty = pyfftw.empty_aligned
        real = self.real_dtype
        self._real_in = empty((n, 2 * n), dtype=real)
        self._half = empty((2 * n, nc), dtype="complex64" if real == "float32" else "complex128")
        self._real_out = empty((n, 2 * n), dtype=real)
        self._half_real = self._half.view(real)  # for the kernel product
        flags = planner_flags(n)
        with planning():
            # In-place column transforms measured ~1.5x faster than out-of-place.
            self._rows_fwd = pyfftw.FFTW(self._real_in, self._half[:n], axes=(1,),
                                         flags=flags, threads=self.threads)
            self._cols_fwd = pyfftw.FFTW(self._half, self._half, axes=(0,),
                                         flags=flags, threads=self.threads)
            self._cols_bwd = pyfftw.FFTW(self._half, self._half, axes=(0,),
                                         direction="FFTW_BACKWARD", flags=flags,
                                         threads=self.threads)
            self._rows_bwd = pyfftw.FFTW(self._half[:n], self._real_out, axes=(1,),
                                         direction="FFTW_BACKWARD", flags=flags,
                                         threads=self.threads)
        self._real_in[:] = 0.0  # planning with FFTW_MEASURE scribbles on buffers
        self._half[:] = 0.0

    @property
    def buffer(self) -> np.ndarray:
        """The zero-padded input, shape (n, 2n); columns n: must stay zero.

        Callers write stress at flat indices of this layout (see
        `padded_index`) and must zero entries they no longer use.
        """
        return self._real_in

    def padded_index(self, flat: np.ndarray) -> np.ndarray:
        """Flat indices into the (n, 2n) buffers from flat indices of an n x n grid."""
        row, col = np.divmod(np.asarray(flat, dtype=np.intp), self.n)
        return row * (2 * self.n) + col

    def apply_buffer(self) -> np.ndarray:
        """Convolve `buffer`; returns the (n, 2n) output whose first n columns are u.

        The output is overwritten by the next call.
        """
        self.applications += 1
        n = self.n
        if self.backend == "mkl":
            return mkl.pruned_pair(self._real_in, self._half, self._scaled, self._real_out,
                                   self.threads)
        if self.backend == "pyfftw":
            return self._pruned(self._half, self._half_real)
        import scipy.fft as sfft

        spec = sfft.rfft2(self._real_in, s=(2 * n, 2 * n), workers=self.threads)
        spec *= self.spectrum
        self._real_out[...] = sfft.irfft2(spec, s=(2 * n, 2 * n), workers=self.threads)[:n]
        return self._real_out


@lru_cache(maxsize=4)
def cached_convolver(n: int, h: float, e_star: float, threads: int,
                     single: bool = False, library: str = "fftw") -> Convolver:
    """One Convolver per (grid, h, E*, threads, precision, library) in a
    process: plans are costly."""
    return Convolver(n, h, e_star, threads, single=single, library=library)
