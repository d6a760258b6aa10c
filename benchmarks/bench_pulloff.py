"""Speed benchmark of the pull-off solver. Prints a table; asserts nothing.

    python benchmarks/bench_pulloff.py            # the three 512 cases, three modes
    python benchmarks/bench_pulloff.py --grid 256 --quick   # no exact mode: no dF, dW

A case the grid does not resolve (48 x 48 pillars below 492^2) is skipped
with the reason.

For each case and mode (exact = global cascades with CG to 1e-8; default =
certified local cascades with CG to 1e-4; global = global cascades with CG
to 1e-4):
operator applications, ms per application (whole run / applications),
wall time, F_ad and W, and their deviation from the exact mode.  The
header line gives one convolution beside a bare real FFT pair (forward +
inverse) of the padded 2n x 2n grid, same library, one thread.
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np
from threadpoolctl import threadpool_limits

from brushcore import BrushParams, ParameterError, SolverOptions, simulate
from brushcore.numerics.halfspace.convolution import Convolver
from brushcore.numerics.halfspace.fft_choice import bare_fft_pair_ms

CASES = [("regular", 256, 0.455), ("regular", 64, 1e-3), ("regular", 2304, 1e-4)]


def application_ms(n: int, repeats: int = 40) -> float:
    """ms per pruned DC-FFT operator application on an n x n grid."""
    conv = Convolver(n)
    conv.buffer[:, :n] = np.random.default_rng(0).random((n, n))
    conv.apply_buffer()
    t = time.perf_counter()
    for _ in range(repeats):
        conv.apply_buffer()
    return (time.perf_counter() - t) / repeats * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--grid", type=int, default=512)
    parser.add_argument("--quick", action="store_true",
                        help="skip the exact mode (then no deviations are printed)")
    args = parser.parse_args()
    with threadpool_limits(1):
        pair = bare_fft_pair_ms(args.grid)
        app = application_ms(args.grid)
        print(f"grid {args.grid}: convolution {app:.2f} ms, bare FFT pair {pair:.2f} ms, "
              f"ratio {app / pair:.2f}")
        head = (f"{'case':>24} {'mode':>7} {'apps':>6} {'ms/app':>7} {'wall s':>7} "
                f"{'F_ad/F_K':>9} {'W/W_K':>9} {'dF':>9} {'dW':>9}")
        print(head)
        for layout, n_pillars, kbar in CASES:
            try:
                params = BrushParams(layout, n_pillars, kbar, args.grid)
            except ParameterError as exc:
                print(f"{layout} N={n_pillars} k={kbar:g}".rjust(24) + f" skipped: {exc}")
                continue
            modes = {"exact": SolverOptions.exact(), "default": SolverOptions(),
                     "global": SolverOptions(cascade="global")}
            ref = None
            for mode, options in modes.items():
                if args.quick and mode == "exact":
                    continue
                t = time.perf_counter()
                ds = simulate(params, options)
                wall = time.perf_counter() - t
                ref = ds if mode == "exact" else ref
                apps = ds.attrs["operator_applications"]
                f = float(ds.adhesive_force_normalized)
                w = float(ds.work_of_separation_normalized)
                df = dw = float("nan")
                if ref is not None:
                    df = float(ds.adhesive_force) / float(ref.adhesive_force) - 1
                    dw = float(ds.work_of_separation) / float(ref.work_of_separation) - 1
                print(f"{layout} N={n_pillars} k={kbar:g}".rjust(24)
                      + f" {mode:>7} {apps:6d} {wall / apps * 1e3:7.2f} {wall:7.1f} "
                      f"{f:9.4f} {w:9.4f} {df:9.1e} {dw:9.1e}", flush=True)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak resident memory of this process: {peak:.0f} MiB")


if __name__ == "__main__":
    main()
