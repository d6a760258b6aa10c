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
at its next event and reported with how far it got.  Every run's FFT plans
and library choice are made before its clock starts (`plan`: with a fresh
``BRUSHCORE_WISDOM_DIR`` they would fall into the first timed run) and
their time is printed beside it.
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

from brushcore import BrushParams, ParameterError, SolverOptions, simulate
from brushcore.model.solve import host_library
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


def plan(params: BrushParams, threads: int) -> float:
    """Seconds to make (or read from the cache) the FFT plans and the library
    choice a default run of ``params`` uses, spent before the clock: with a
    fresh ``BRUSHCORE_WISDOM_DIR`` they took 10-12 s per precision at 512^2
    (about 40 s at 1024^2 and 160 s at 2048^2 by `planner_flags`), a cost
    once per machine, which the first timed run would otherwise carry."""
    t = time.perf_counter()
    for single in (False, True):
        library = host_library(params, SolverOptions(precision="mixed" if single else
                                                     "double"))
        Convolver(params.grid, threads=threads, single=single, library=library)
        if params.grid % 2 == 0:
            MirrorConvolver(params.grid, threads=threads, single=single)
    return time.perf_counter() - t


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
        planning = plan(params, 1)
        for label, options in runs.items():
            t = time.perf_counter()
            out[label] = (simulate(params, options), time.perf_counter() - t)
    ref = out["exact reference"][0]
    print(f"regular N=256 kbar=0.455 grid {grid}, one thread (FFT planning before the "
          f"clock: {planning:.1f} s)")
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
    planning = plan(params, threads)
    t = time.perf_counter()
    state = {"planning": planning}

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
                      "planning": planning,
                      "peak_gib": peak, "fold": int(ds.attrs["symmetry_fold"]),
                      "f": float(ds.adhesive_force_normalized),
                      "w": float(ds.work_of_separation_normalized)}))


def fine(specs: list[str], grid: int, threads: int, limit: float) -> int:
    """Run each case in its own process and print its row; the number of
    cases that failed (a refused case, a crash)."""
    print(f"grid {grid}, {threads} thread(s); each case in its own process, its FFT "
          "planning before the clock (plan s)")
    print(f"{'case':>24} {'fold':>4} {'apps':>6} {'wall s':>8} {'plan s':>7} {'peak GiB':>9} "
          f"{'F_ad/F_K':>9} {'W/W_K':>9}")
    failed = 0
    for spec in specs:
        proc = subprocess.run([sys.executable, __file__, "child", spec, "--grid", str(grid),
                               "--threads", str(threads), "--limit", str(limit)],
                              capture_output=True, text=True)
        if proc.returncode:  # a child killed (out of memory: SIGKILL) says nothing
            last = (proc.stderr.strip().splitlines() or [f"exit status {proc.returncode}"])[-1]
            print(f"{spec:>24} failed: {last}", flush=True)
            failed += 1
            continue
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        if "stopped" in r:  # the limit is read at events: a long cascade overruns it
            print(f"{spec:>24} stopped at the first event after {limit:.0f} s: after "
                  f"{r['stopped']:.0f} s (planning {r['planning']:.1f} s before), at event "
                  f"{r.get('events', 0)}, {r.get('attached', '?')} of {r.get('total', '?')} "
                  f"elements attached, peak {r['peak_gib']:.2f} GiB", flush=True)
            continue
        print(f"{spec:>24} {r['fold']:4d} {r['apps']:6d} {r['wall']:8.1f} {r['planning']:7.1f} "
              f"{r['peak_gib']:9.2f} {r['f']:9.5f} {r['w']:9.5f}", flush=True)
    return failed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("what", choices=["ratio", "target", "fine", "child"],
                        help="what to measure (child: one case of fine, internal)")
    parser.add_argument("cases", nargs="*", help="fine: layout:N:kbar, e.g. random:64:inf "
                                                 "(default regular:2304:0.455)")
    parser.add_argument("--grid", type=int, default=None,
                        help="ratio: one grid (default 512, 1024 and 2048); target: default "
                             "1024; fine: default 2048")
    parser.add_argument("--threads", type=int, default=1, help="fine: threads per case")
    parser.add_argument("--limit", type=float, default=900.0,
                        help="fine: stop a curve at the first event after this many seconds "
                             "and report how far it got")
    args = parser.parse_intermixed_args()
    if args.what != "fine" and args.what != "child" and (args.cases or args.threads != 1
                                                          or args.limit != 900.0):
        parser.error(f"{args.what} runs one thread and takes no cases or --limit")
    try:
        if args.what == "ratio":
            ratio([args.grid] if args.grid else [512, 1024, 2048])
        elif args.what == "target":
            target(args.grid or 1024)
        elif args.what == "child":
            _child(args.cases[0], args.grid or 2048, args.threads, args.limit)
        elif fine(args.cases or ["regular:2304:0.455"], args.grid or 2048, args.threads,
                  args.limit):
            sys.exit(1)
    except ParameterError as exc:  # target on a grid its brush cannot run on
        sys.exit(f"{args.what}: {exc}")


if __name__ == "__main__":
    main()
