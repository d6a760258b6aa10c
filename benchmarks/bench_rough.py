"""Cost of a rough, preloaded pull-off against the flat one.

    python benchmarks/bench_rough.py                 # 16 x 16, kbar 0.455, 512^2
    python benchmarks/bench_rough.py --grid 256 --lookahead 0 0.001 0.01

Prints operator applications, wall time, F_ad / F_K and W / W_K of the flat
brush (the pull-off from full contact) and of the rough brush
(roughness S d_K, approach to P F_K, retraction) for each lookahead, with
the rough runs' ratio of applications to the flat one.  Asserts nothing.
Measured on one core (16 x 16, kbar 0.455, S = 1, P = 1, seed 0, 512^2):
flat 881 applications (14 s); rough exact 16482 (18.7x, 264 s, 4041
approach events: the contact spreads over each flat tip element by
element); lookahead 0.01: 2397 (2.7x), F_ad equal to 4 digits.  Those
figures predate the mirror-symmetric pull-off: with it the flat brush took
669 applications and lookahead 0.01 2542 (3.8x) on 2026-12-05
(`--lookahead 0.01`, 512^2).
"""

from __future__ import annotations

import argparse
import time

from brushcore import BrushParams, SolverOptions, simulate
from brushcore.numerics.platform.threads import pin_threads


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, allow_abbrev=False,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--grid", type=int, default=512)
    parser.add_argument("--pillars", type=int, default=256)
    parser.add_argument("--kbar", type=float, default=0.455)
    parser.add_argument("--roughness", type=float, default=1.0)
    parser.add_argument("--preload", type=float, default=1.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--lookahead", type=float, nargs="+", default=[0.0, 0.01])
    args = parser.parse_args()
    pin_threads(1)
    base = dict(layout="regular", n_pillars=args.pillars, kbar=args.kbar, grid=args.grid,
                seed=args.seed)

    def row(label: str, params: BrushParams, options: SolverOptions, ref: int | None) -> int:
        t0 = time.perf_counter()
        ds = simulate(params, options)
        apps = int(ds.attrs["operator_applications"])
        ratio = "" if ref is None else f"{apps / ref:6.2f}x"
        print(f"{label:24s} {apps:8d} {ratio:>8s} {time.perf_counter() - t0:8.1f} s  "
              f"F_ad/F_K {float(ds.adhesive_force_normalized):.6f}  "
              f"W/W_K {float(ds.work_of_separation_normalized):.6f}", flush=True)
        return apps

    print(f"{'case':24s} {'applic.':>8s} {'ratio':>8s} {'wall':>10s}")
    flat = row("flat (today)", BrushParams(**base), SolverOptions(), None)
    rough = BrushParams(**base, roughness=args.roughness, preload=args.preload)
    for lookahead in args.lookahead:
        row(f"rough, lookahead {lookahead:g}", rough, SolverOptions(lookahead=lookahead), flat)


if __name__ == "__main__":
    main()
