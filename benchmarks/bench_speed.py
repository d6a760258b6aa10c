"""Speed and memory figures (README, "Speed and memory"; docs/SPEED.md). Prints tables; asserts nothing.

    python benchmarks/bench_speed.py ratio          # one application / bare FFT pair
    python benchmarks/bench_speed.py target         # 16 x 16, kbar 0.455 at 1024^2
    python benchmarks/bench_speed.py fine --grid 2048 --threads 2 regular:2304:0.455 ...

``ratio``: ms of one operator application on the whole grid (pruned DC-FFT)
on FFTW and, where mkl_fft is installed, on MKL (``SolverOptions.fft_library``),
and on the quadrant of a mirror-symmetric brush (DCT-II/III), in double and
in single precision (the default, ``SolverOptions.precision``), beside a
bare double-precision r2c + c2r pair of the padded 2n x 2n grid on pyfftw
and, where mkl_fft is installed, on MKL; each ratio is against the faster
of the two bare pairs (the stricter reference); one thread.

``target``: the issue's case on one thread, four ways in one run: the whole
grid all in double (the algorithm before mirror symmetry), the quadrant all
in double (before early-decided rounds), the default, and the exact
reference; applications, wall, F_ad, W and their deviation from the
reference.

``fine``: each case in its own process (so the peak memory is its own):
applications, wall, peak resident memory, F_ad, W; a curve still running
after ``--limit`` seconds (default 900, the issue's 15 minutes) is stopped
and reported with how far it got.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np
from threadpoolctl import threadpool_limits

from brushcore import BrushParams, SolverOptions, simulate
from brushcore.numerics.platform import mkl
from brushcore.numerics.halfspace.convolution import Convolver
from brushcore.numerics.halfspace.mirror import MirrorConvolver
from brushcore.numerics.platform.threads import pin_threads

from brushcore.numerics.halfspace.fft_choice import bare_fft_pair_ms  # noqa: E402


def _ms(conv, fill: int, repeats: int = 20) -> float:
    conv.buffer[:, :fill] = np.random.default_rng(0).random((conv.buffer.shape[0], fill))
    conv.apply_buffer()
    t = time.perf_counter()
    for _ in range(repeats):
        conv.apply_buffer()
    return (time.perf_counter() - t) / repeats * 1e3


def mkl_pair_ms(n: int, repeats: int = 10) -> float:
    """ms for MKL's own rfft2 + irfft2 of a 2n x 2n double array, one thread
    (MKL's sequential layer, `brushcore.numerics.platform.mkl`)."""
    fft = mkl._module()
    a = np.random.default_rng(0).random((2 * n, 2 * n))
    b = fft.rfft2(a)
    out = np.empty_like(a)
    fft.irfft2(b, s=a.shape, out=out)
    t = time.perf_counter()
    for _ in range(repeats):
        fft.rfft2(a, out=b)
        fft.irfft2(b, s=a.shape, out=out)
    return (time.perf_counter() - t) / repeats * 1e3


def ratio(grids: list[int]) -> None:
    libraries = ("fftw", "mkl") if mkl.available() else ("fftw",)
    print("ratio = ms / the faster bare double FFT pair (FFTW's or MKL's); "
          "64 = double, 32 = single-precision transforms")
    print(f"{'grid':>6} {'pair ms':>8} {'mkl pair':>8} " + " ".join(
        f"{lib + ' ' + str(b):>9}" for lib in libraries for b in (64, 32))
        + f" {'quad 64':>8} {'quad 32':>8}")
    with threadpool_limits(1):
        for n in grids:
            fftw_pair = bare_fft_pair_ms(n, 10)
            mkl_pair = mkl_pair_ms(n) if mkl.available() else float("nan")
            pair = np.nanmin([fftw_pair, mkl_pair])
            cells = [_ms(Convolver(n, single=single, library=lib), n)
                     for lib in libraries for single in (False, True)]
            cells += [_ms(MirrorConvolver(n, single=single), n // 2) for single in (False, True)]
            print(f"{n:6d} {fftw_pair:8.2f} {mkl_pair:8.2f} " + " ".join(f"{c / pair:8.2f}" for c in cells)
                  + "   (ms: " + ", ".join(f"{c:.2f}" for c in cells) + ")", flush=True)


def _row(label: str, ds, wall: float, ref=None) -> str:
    f, w = float(ds.adhesive_force), float(ds.work_of_separation)
    dev = ""
    if ref is not None:
        dev = (f" {f / float(ref.adhesive_force) - 1:+9.1e}"
               f" {w / float(ref.work_of_separation) - 1:+9.1e}")
    return (f"{label:>22} {ds.attrs['operator_applications']:6d} {wall:8.1f} "
            f"{float(ds.adhesive_force_normalized):9.5f} "
            f"{float(ds.work_of_separation_normalized):9.5f}{dev}")


def target(grid: int) -> None:
    params = BrushParams("regular", 256, 0.455, grid)
    runs = {"whole grid (before)": SolverOptions(symmetry=False, precision="double",
                                                 early_decisions=False),
            "quadrant, all double": SolverOptions(precision="double", early_decisions=False),
            "default (quadrant)": SolverOptions(),
            "exact reference": SolverOptions.exact()}
    out = {}
    with threadpool_limits(1):
        for label, options in runs.items():
            t = time.perf_counter()
            out[label] = (simulate(params, options), time.perf_counter() - t)
    ref = out["exact reference"][0]
    print(f"regular N=256 kbar=0.455 grid {grid}, one thread")
    print(f"{'run':>22} {'apps':>6} {'wall s':>8} {'F_ad/F_K':>9} {'W/W_K':>9} "
          f"{'dF':>9} {'dW':>9}")
    for label, (ds, wall) in out.items():
        print(_row(label, ds, wall, ref))


class _Stop(Exception):
    pass


def _child(spec: str, grid: int, threads: int, limit: float) -> None:
    layout, n_pillars, kbar = spec.split(":")
    params = BrushParams(layout, int(n_pillars), float(kbar), grid)
    pin_threads(threads)  # FFTW plans and BLAS, as a workflow job does
    t = time.perf_counter()
    state = {}

    def progress(events: int, attached: int, total: int) -> None:
        state.update(events=events, attached=attached, total=total)
        if time.perf_counter() - t > limit:
            raise _Stop

    try:
        ds = simulate(params, progress=progress)
    except _Stop:
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
        print(json.dumps({"stopped": time.perf_counter() - t, "peak_gib": peak, **state}))
        return
    wall = time.perf_counter() - t
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
    print(json.dumps({"apps": int(ds.attrs["operator_applications"]), "wall": wall,
                      "peak_gib": peak, "fold": int(ds.attrs["symmetry_fold"]),
                      "f": float(ds.adhesive_force_normalized),
                      "w": float(ds.work_of_separation_normalized)}))


def fine(specs: list[str], grid: int, threads: int, limit: float) -> None:
    print(f"grid {grid}, {threads} thread(s); each case in its own process")
    print(f"{'case':>24} {'fold':>4} {'apps':>6} {'wall s':>8} {'peak GiB':>9} "
          f"{'F_ad/F_K':>9} {'W/W_K':>9}")
    for spec in specs:
        proc = subprocess.run([sys.executable, __file__, "child", spec, "--grid", str(grid),
                               "--threads", str(threads), "--limit", str(limit)],
                              capture_output=True, text=True)
        if proc.returncode:  # a child killed (out of memory: SIGKILL) says nothing
            last = (proc.stderr.strip().splitlines() or [f"exit status {proc.returncode}"])[-1]
            print(f"{spec:>24} failed: {last}", flush=True)
            continue
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        if "stopped" in r:
            print(f"{spec:>24} stopped after {r['stopped']:.0f} s at event {r.get('events', 0)}, "
                  f"{r.get('attached', '?')} of {r.get('total', '?')} elements attached, "
                  f"peak {r['peak_gib']:.2f} GiB", flush=True)
            continue
        print(f"{spec:>24} {r['fold']:4d} {r['apps']:6d} {r['wall']:8.1f} "
              f"{r['peak_gib']:9.2f} {r['f']:9.5f} {r['w']:9.5f}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("what", choices=["ratio", "target", "fine", "child"])
    parser.add_argument("cases", nargs="*", help="layout:N:kbar (fine)")
    parser.add_argument("--grid", type=int, default=None)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--limit", type=float, default=900.0,
                        help="fine: stop a curve after this many seconds and report how far it got")
    args = parser.parse_intermixed_args()
    if args.what == "ratio":
        ratio([args.grid] if args.grid else [512, 1024, 2048])
    elif args.what == "target":
        target(args.grid or 1024)
    elif args.what == "child":
        _child(args.cases[0], args.grid or 2048, args.threads, args.limit)
    else:
        fine(args.cases or ["regular:2304:0.455"], args.grid or 2048, args.threads, args.limit)


if __name__ == "__main__":
    main()
