"""Which library's FFTs are faster for a whole-grid pair on this machine.

Neither library wins everywhere: MKL is faster on an Intel Xeon, while on
an AMD EPYC (2026-12-03, pruned pair in single precision, medians of alternating
rounds): FFTW 0.85 / 4.75 / 22.8 / 127 ms against MKL 1.12 / 5.44 / 24.1 /
119 ms at n = 256 / 512 / 1024 / 2048 on one thread, and on two 0.58 /
1.89 / 15.9 / 95 against 0.86 / 3.08 / 15.6 / 75 ms; a soft random curve
(random 1620 at kbar 1e-5, 512^2, two jobs side by side) 81.9 s on FFTW
against 89.6 s on MKL, the mean of four runs each.  So the faster library
depends on the processor, the grid and the threads, and is found as FFTW
finds its plans: by timing both, once per machine and case, and
remembering the answer (``fft-library.json`` beside FFTW's wisdom, under a
lock, so that concurrent jobs share one answer and the same case runs on
the same library, rounding alike, in every later job on this machine).
Answers are kept per processor model and library versions: a cluster's
nodes may share one home directory, and with it the cache, across
different processors, and an upgrade of either library may turn the
answer.
"""

from __future__ import annotations

import json
import platform
import time
from functools import lru_cache

import numpy as np

from brushcore.numerics.halfspace.convolution import (Convolver, cache_dir, machine_lock, planner_flags,
                                            save_to_cache)

#: Alternating rounds of the timing; the median of each library's rounds counts.
ROUNDS = 5
#: Seconds a round of one library's applications lasts, at least.
ROUND_SECONDS = 0.05


def _path():
    return cache_dir() / "fft-library.json"


@lru_cache(maxsize=1)
def processor() -> str:
    """This machine's processor model (Linux's /proc/cpuinfo, else what
    `platform` knows)."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


@lru_cache(maxsize=1)
def versions() -> str:
    """The two libraries' versions as the answers are keyed by them."""
    from importlib.metadata import PackageNotFoundError, version

    def installed(name: str) -> str:
        try:
            return version(name)
        except PackageNotFoundError:
            return "none"

    return f"pyfftw {installed('pyfftw')}, mkl_fft {installed('mkl_fft')}"


def _key(n: int, threads: int, single: bool) -> str:
    precision = "float32" if single else "float64"
    return f"{processor()} ({versions()}): n={n} threads={threads} {precision}"


def _load() -> dict:
    try:
        with open(_path()) as fh:
            data = json.load(fh)
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):
        return {}  # none yet, or unreadable: time afresh


def _save(data: dict) -> None:
    save_to_cache(_path().name, json.dumps(data, indent=1, sort_keys=True).encode())


def time_pairs(n: int, h: float, e_star: float, threads: int,
               single: bool) -> dict[str, float]:
    """ms per pruned pair of an n x n grid on FFTW and on MKL: the median of
    `ROUNDS` alternating rounds.  The convolvers are dropped afterwards (the
    run builds the winner again: FFTW's plans from the wisdom saved here)."""
    stress = np.random.default_rng(0).random((n, n))
    convolvers = {lib: Convolver(n, h, e_star, threads, single=single, library=lib)
                  for lib in ("fftw", "mkl")}
    repeats = {}
    for lib, conv in convolvers.items():
        t = time.perf_counter()
        conv(stress)  # warm: first touches of the work arrays
        repeats[lib] = max(1, int(ROUND_SECONDS / max(time.perf_counter() - t, 1e-6)))
    rounds: dict[str, list[float]] = {lib: [] for lib in convolvers}
    for _ in range(ROUNDS):
        for lib, conv in convolvers.items():
            t = time.perf_counter()
            for _ in range(repeats[lib]):
                conv(stress)
            rounds[lib].append((time.perf_counter() - t) / repeats[lib] * 1e3)
    return {lib: float(np.median(ms)) for lib, ms in rounds.items()}


@lru_cache(maxsize=None)  # one answer a process, even where the cache is read-only
def faster_library(n: int, h: float, e_star: float, threads: int, single: bool) -> str:
    """"fftw" or "mkl", whichever ran the whole-grid pair of this case
    faster on this machine (timed the first time, then remembered).

    Parameters
    ----------
    n : grid (elements per side)
    h, e_star : element size [length] and contact modulus [stress] (the
        convolver's kernel; they do not change the timing)
    threads : FFT threads of the run
    single : single-precision transforms
    """
    key = _key(n, threads, single)
    with machine_lock("fft-library.lock"):
        data = _load()
        entry = data.get(key)
        if not (isinstance(entry, dict) and entry.get("library") in ("fftw", "mkl")):
            ms = time_pairs(n, h, e_star, threads, single)
            entry = {"library": min(ms, key=ms.get), **{f"{lib}_ms": v for lib, v in ms.items()}}
            data[key] = entry
            _save(data)
    return entry["library"]


def bare_fft_pair_ms(n: int, repeats: int = 40) -> float:
    """ms for rfft2 + irfft2 of a 2n x 2n array, pyfftw, one thread, planned
    with the effort `Convolver` uses for n (`planner_flags`): the reference
    an operator application is measured against (benchmarks)."""
    import pyfftw

    a = pyfftw.empty_aligned((2 * n, 2 * n), dtype="float64")
    b = pyfftw.empty_aligned((2 * n, n + 1), dtype="complex128")
    flags = planner_flags(n)
    fwd = pyfftw.FFTW(a, b, axes=(0, 1), flags=flags, threads=1)
    bwd = pyfftw.FFTW(b, a, axes=(0, 1), direction="FFTW_BACKWARD", flags=flags, threads=1)
    a[:] = np.random.default_rng(0).random(a.shape)
    fwd.execute()
    bwd.execute()
    t = time.perf_counter()
    for _ in range(repeats):
        fwd.execute()
        bwd.execute()
    return (time.perf_counter() - t) / repeats * 1e3
