"""Command line: ``brushcore simulate ...`` writes one curve file."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .cg import ConvergenceError
from .params import LAYOUTS, BrushParams, ParameterError, SolverOptions
from .pulloff import SolverError


def _kbar(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"kbar={text!r} is invalid: allowed a number in (0, inf]; 'inf' means rigid") from None
    return value


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (exposed for documentation and tests)."""
    parser = argparse.ArgumentParser(prog="brushcore", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    sim = sub.add_parser("simulate", help="pull one brush off and write its curve (netCDF)")
    sim.add_argument("--layout", choices=LAYOUTS, required=True)
    sim.add_argument("--pillars", type=int, required=True, help="number of pillars N")
    sim.add_argument("--kbar", type=_kbar, required=True,
                     help="spring stiffness k/(E* L); 'inf' for rigid pillars")
    sim.add_argument("--grid", type=int, required=True, help="elements per side n")
    sim.add_argument("--phi", type=float, default=0.12, help="filling factor (0, 0.5]")
    sim.add_argument("--seed", type=int, default=0, help="seed of the random layout")
    sim.add_argument("--min-gap", type=float, default=1.0,
                     help="minimum gap between random pillars [elements]")
    sim.add_argument("--e-star", type=float, default=1.0, help="effective modulus E*")
    sim.add_argument("--dgamma", type=float, default=1.0, help="work of adhesion")
    sim.add_argument("--h", type=float, default=1.0, help="element size")
    sim.add_argument("--rtol", type=float, default=SolverOptions.rtol, help="CG tolerance")
    sim.add_argument("--lookahead", type=float, default=0.0,
                     help="approximate: detach within this relative window (default exact)")
    sim.add_argument("--cascade", choices=("global", "local"), default=SolverOptions.cascade,
                     help="local: per-pillar cascades where they provably do not change "
                          "the result (default); global: re-solve after every round (reference)")
    sim.add_argument("--threads", type=int, default=1, help="FFT/BLAS threads")
    sim.add_argument("--out", type=Path, required=True, help="output netCDF file")
    sim.add_argument("--quiet", action="store_true", help="no progress on stderr")
    return parser


class _Progress:
    """Prints detached fraction and events to stderr at most every 2 s."""

    def __init__(self) -> None:
        self.t0 = self.last = time.monotonic()

    def __call__(self, events: int, attached: int, total: int) -> None:
        now = time.monotonic()
        if now - self.last >= 2.0:
            self.last = now
            print(f"\r  {100 * (1 - attached / total):5.1f}% detached, {events} events, "
                  f"{now - self.t0:6.1f} s", end="", file=sys.stderr, flush=True)


def _simulate(args: argparse.Namespace) -> int:
    from .io import write_curve
    from .curve import simulate
    from .threads import pin_threads

    try:
        params = BrushParams(layout=args.layout, n_pillars=args.pillars, kbar=args.kbar,
                             grid=args.grid, phi=args.phi, seed=args.seed,
                             min_gap=args.min_gap, e_star=args.e_star, dgamma=args.dgamma,
                             h=args.h)
        options = SolverOptions(rtol=args.rtol, lookahead=args.lookahead, cascade=args.cascade)
        if args.threads < 1:
            raise ParameterError(f"threads={args.threads} is invalid: allowed an integer >= 1")
        pin_threads(args.threads)
        # The layout is built (and checked) before any solve starts.
        ds = simulate(params, options, progress=None if args.quiet else _Progress())
    except ParameterError as exc:
        print(f"brushcore: error: {exc}", file=sys.stderr)
        return 2
    except (ConvergenceError, SolverError) as exc:
        print(f"\nbrushcore: solver failed: {exc}", file=sys.stderr)
        return 1
    write_curve(ds, args.out)
    if not args.quiet:
        print("", file=sys.stderr)
    print(f"F_ad/F_K = {float(ds.adhesive_force_normalized):.4f}  "
          f"W/W_K = {float(ds.work_of_separation_normalized):.4f}  "
          f"events = {ds.attrs['events']}  operator applications = "
          f"{ds.attrs['operator_applications']}  time = {ds.attrs['wall_time_s']:.1f} s  "
          f"-> {args.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``brushcore`` command."""
    args = build_parser().parse_args(argv)
    if args.command == "simulate":
        return _simulate(args)
    return 2  # pragma: no cover - argparse enforces the sub-command


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
