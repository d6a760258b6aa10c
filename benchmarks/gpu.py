"""GPU figures (README, "On a GPU"). Prints a table; asserts nothing.

    python benchmarks/gpu.py                       # the issue's cases on the card (< 5 min)
    python benchmarks/gpu.py --with-4096           # also 16 x 16 at 4096^2
    python benchmarks/gpu.py --backend cpu --grid 256   # CPU smoke check of this script

Cases: 16 x 16 pillars, kbar = 0.455 at 512^2, 1024^2, 2048^2, and the
rigid 8 x 8 brush at 1024^2, 2048^2 (``--grid`` replaces the grids).  Per
case: operator applications of the whole pull-off, ms of one application
(the brush operator, timed alone), its ratio to a bare r2c + c2r pair of
the padded 2n x 2n grid (cuFFT on the card, pyfftw on the CPU), wall time
of the curve, F_ad / F_K, W / W_K and the preconditioner taken.  Every
curve is solved on the whole grid (the device has no symmetry fold), so
CPU and GPU rows compare.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from brushcore import BrushParams, ParameterError, SolverOptions, simulate
from brushcore.cli import ScriptHelp
from brushcore.model.solve import grid_convolver, spring_compliance
from brushcore.model.layout import build_labels
from brushcore.numerics.platform.backend import Backend, resolve_backend
from brushcore.numerics.linear.operator import BrushOperator

from brushcore.numerics.halfspace.fft_choice import bare_fft_pair_ms  # noqa: E402
from bench_speed import plan  # noqa: E402 - a sibling script: FFT plans before the clock

#: (label, pillars, kbar, grids) of the issue.
CASES = (("16x16 kbar 0.455", 256, 0.455, (512, 1024, 2048)),
         ("rigid 8x8", 64, math.inf, (1024, 2048)))


def _timed(backend: Backend, call, repeats: int) -> float:
    """Mean ms of ``call()`` on the device (synchronised), after one warm-up."""
    call()
    backend.synchronize()
    t = time.perf_counter()
    for _ in range(repeats):
        call()
    backend.synchronize()
    return (time.perf_counter() - t) / repeats * 1e3


def fft_pair_ms(backend: Backend, n: int, repeats: int = 20) -> float:
    """One r2c + c2r pair of the padded 2n x 2n grid [ms]."""
    if backend.on_host:
        return bare_fft_pair_ms(n, repeats)
    xp = backend.xp
    field = backend.asarray(np.random.default_rng(0).random((2 * n, 2 * n)))
    return _timed(backend, lambda: xp.fft.irfftn(xp.fft.rfftn(field), s=field.shape),
                  repeats)


def application_ms(params: BrushParams, backend: Backend, repeats: int = 20) -> float:
    """One application of the brush operator, all elements attached [ms]."""
    labels = build_labels(params)
    op = BrushOperator(grid_convolver(params, backend, SolverOptions()), labels,
                       spring_compliance(params, params.n_pillars), params.h, params.e_star,
                       use_block=False)
    x = backend.xp.ones(op.size, dtype=backend.xp.float64)
    return _timed(backend, lambda: op.apply(x), repeats)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, allow_abbrev=False,
                                     formatter_class=ScriptHelp)
    parser.add_argument("--backend", choices=("gpu", "cpu"), default="gpu")
    parser.add_argument("--grid", type=int, nargs="+", action="extend",
                        help="grid(s) for every case instead of the issue's "
                             "(--grid 256 512, or --grid given twice)")
    parser.add_argument("--with-4096", action="store_true",
                        help="also 16 x 16, kbar 0.455 at 4096^2 (memory and time)")
    args = parser.parse_args(argv)
    try:
        backend = resolve_backend(args.backend)
    except ParameterError as exc:
        print(f"benchmarks/gpu.py: {exc}", file=sys.stderr)
        return 2
    memory = backend.device_memory_bytes / 2**30
    print(f"device: {backend.device_name}" + (f", {memory:.0f} GiB" if memory else ""))
    cases = [(label, n, kbar, tuple(args.grid) if args.grid else grids)
             for label, n, kbar, grids in CASES]
    if args.with_4096:
        cases.append(("16x16 kbar 0.455", 256, 0.455, (4096,)))
    # The first curve of a process pays for CuPy compiling its kernels: not a case.
    t = time.perf_counter()
    simulate(BrushParams("regular", 256, 0.455, 256, backend=args.backend),
             SolverOptions(symmetry=False))
    backend.synchronize()
    print(f"warm-up curve (16x16 at 256^2, kernels compiled): {time.perf_counter() - t:.1f} s",
          flush=True)
    print(f"{'case':>18} {'grid':>5} {'apps':>6} {'ms/app':>7} {'pair ms':>8} {'ratio':>6} "
          f"{'wall s':>7} {'F_ad/F_K':>9} {'W/W_K':>8} preconditioner", flush=True)
    for label, n_pillars, kbar, grids in cases:
        for grid in grids:
            try:
                params = BrushParams("regular", n_pillars, kbar, grid, backend=args.backend)
                build_labels(params)
            except ParameterError as exc:  # a grid that does not resolve this brush
                print(f"{label:>18} {grid:5d} skipped: {exc}", flush=True)
                continue
            app = application_ms(params, backend)
            pair = fft_pair_ms(backend, grid)
            if backend.on_host:  # FFTW's plans before the clock (cuFFT's: the warm-up)
                plan(params, 1)
            t = time.perf_counter()
            ds = simulate(params, SolverOptions(symmetry=False))
            backend.synchronize()
            wall = time.perf_counter() - t
            print(f"{label:>18} {grid:5d} {ds.attrs['operator_applications']:6d} {app:7.2f} "
                  f"{pair:8.2f} {app / pair:6.2f} {wall:7.1f} "
                  f"{float(ds.adhesive_force_normalized):9.5f} "
                  f"{float(ds.work_of_separation_normalized):8.5f} "
                  f"{ds.attrs['preconditioner']}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
