"""A small mesh-refinement study on one core, without Snakemake (prints, asserts nothing).

    python benchmarks/convergence_study.py --pillars 64 --kbar inf 1e-6 \
        --grids 128 256 512 --out results/study

Runs each (kbar, grid) once (curve files already in --out are reused), then
prints the values per grid, the realised filling factor, the pillar radius in
elements, the wall time, and the extrapolation of F_ad and W to h -> 0
(`brushcore.data.convergence`), for the whole grid set and for every subset of
three grids given with --subsets.
"""

from __future__ import annotations

import argparse
import itertools
import math
import time
from pathlib import Path

import numpy as np

from brushcore import BrushParams, SolverOptions, simulate
from brushcore.data.aggregate import build_sweep
from brushcore.data.convergence import QUANTITIES, extrapolate_sweep
from brushcore.data.extrapolation import extrapolate
from brushcore.data.convergence_report import convergence_table, to_markdown
from brushcore.data.io import write_curve
from brushcore.numerics.platform.threads import pin_threads


def _kbar(text: str) -> float:
    return math.inf if text == "inf" else float(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, allow_abbrev=False,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--layout", default="regular")
    parser.add_argument("--pillars", type=int, default=64)
    parser.add_argument("--kbar", type=_kbar, nargs="+", default=[math.inf, 1e-6])
    parser.add_argument("--grids", type=int, nargs="+", default=[128, 256, 512])
    parser.add_argument("--phi", type=float, default=0.12)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--subsets", action="store_true",
                        help="also extrapolate every subset of three grids")
    parser.add_argument("--out", type=Path, default=Path("results/study"))
    args = parser.parse_args()
    pin_threads(args.threads)
    args.out.mkdir(parents=True, exist_ok=True)
    paths = []
    for kbar in args.kbar:
        for grid in sorted(args.grids):
            # every parameter in the name: a rerun with another phi must not reuse these
            path = args.out / (f"{args.layout}_N{args.pillars}_kbar{kbar!r}_grid{grid}"
                               f"_phi{args.phi!r}.nc")
            if not path.exists():
                t0 = time.perf_counter()
                params = BrushParams(args.layout, args.pillars, kbar, grid, phi=args.phi)
                write_curve(simulate(params, SolverOptions()), path)
                print(f"kbar {kbar:g} grid {grid}: {time.perf_counter() - t0:.1f} s", flush=True)
            paths.append(path)
    sweep = build_sweep(paths)
    for kbar in args.kbar:
        case = sweep.sel(layout=args.layout, n_pillars=args.pillars, kbar=kbar, seed=0)
        print(f"\nkbar = {kbar:g}")
        print("grid  radius[el]  phi_actual  F_ad/F_K   W/W_K       wall[s]")
        for g in sweep.grid.values:
            c = case.sel(grid=g)
            print(f"{int(g):5d} {float(c.pillar_radius_elements):9.2f} "
                  f"{float(c.phi_actual):11.5f} {float(c.adhesive_force_normalized):9.5f} "
                  f"{float(c.work_of_separation_normalized):11.5g} {float(c.wall_time_s):8.1f}")
        if args.subsets:
            grids = [int(g) for g in sweep.grid.values]
            for q in QUANTITIES:
                for sub in itertools.combinations(grids, 3):
                    e = extrapolate(1.0 / np.array(sub, dtype=float),
                                    case[q].sel(grid=list(sub)).values)
                    flags = [f for f in ("non_monotone", "poor_fit", "too_few_grids")
                             if getattr(e, f)]
                    print(f"  {q[:22]:22s} {sub}: f0 = {e.value:.5g} ± {e.error:.2g}, "
                          f"p = {e.order:.3g} {','.join(flags)}")
    print()
    print(to_markdown(convergence_table(extrapolate_sweep(sweep))))


if __name__ == "__main__":
    main()
