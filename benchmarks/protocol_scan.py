"""Protocol runs at the default settings against exact mode, over drawn brushes.

    python benchmarks/protocol_scan.py                  # seeds 1000-1399, 240 s at most
    python benchmarks/protocol_scan.py --first 5000 --count 50 --limit 600

Each seed draws a small regular brush (2 x 2 on 41^2, 3 x 3 on 49^2 or
4 x 4 on 56^2), kbar from 1e-5 to 1e-1, heights normal(0, S) d_K with S
from 0.01 to 2, equal springs or spread ones, and two cycles (force:-P1,
separation, force:-P2, separation; P from 0.3 to 5 F_K): the near-ties of
mirror images, graded brushes and preloads near gap closings that decided
protocol runs by CG's rounding before 2026-12-07.  Prints, per brush, the
largest relative difference of the pulls' F_ad and W between the defaults
and `SolverOptions.exact()` and both event counts; then how many exceed
2e-4, the largest and median differences and how many event counts agree.
Asserts nothing.  Measured 2026-12-07 (one thread) on the 212 brushes of
seeds 1000-1399 that an independent dense solver's scan had drawn in its
240 s, the defaults against that scan's exact-mode values: W within
1.8e-6 (1.98e-3 before, 6 brushes above 2e-4), F_ad within 1.0e-6
(5.5e-5), median W 1.7e-8 (2.9e-6), 208 of 212 event counts equal.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from brushcore import BrushParams, SolverOptions, Waypoint, simulate
from brushcore.numerics.platform.threads import pin_threads


def draw(seed: int) -> tuple[BrushParams, tuple[Waypoint, ...]]:
    """Seed's brush and its two-cycle protocol."""
    rng = np.random.default_rng(seed)
    n_pillars, grid = [(4, 41), (16, 56), (9, 49)][rng.integers(3)]
    kbar = float(10 ** rng.uniform(-5, -1))
    spread = float(10 ** rng.uniform(-2, 0.3))  # [d_K]
    p1, p2 = (float(x) for x in rng.choice([0.3, 1.0, 2.0, 5.0], 2))
    heights = rng.normal(0.0, spread, n_pillars)
    springs = kbar * np.exp(rng.normal(0.0, 0.5, n_pillars)) if rng.integers(2) else None
    params = BrushParams("regular", n_pillars, kbar, grid, heights=heights, kbar_values=springs)
    return params, (Waypoint("force", -p1), Waypoint("separation"), Waypoint("force", -p2),
                    Waypoint("separation"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, allow_abbrev=False,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--first", type=int, default=1000, help="first seed")
    parser.add_argument("--count", type=int, default=400, help="seeds to try")
    parser.add_argument("--limit", type=float, default=240.0,
                        help="stop drawing after this many seconds")
    args = parser.parse_args()
    pin_threads(1)
    warnings.simplefilter("ignore")  # first-touch and coarse-grid notes
    rows = []
    start = time.perf_counter()
    print(f"{'seed':>6s} {'N':>3s} {'kbar':>9s} {'dF_ad':>9s} {'dW':>9s} {'events':>11s}")
    for seed in range(args.first, args.first + args.count):
        if time.perf_counter() - start > args.limit:
            break
        params, protocol = draw(seed)
        want, got = (simulate(params, options, protocol=protocol)
                     for options in (SolverOptions.exact(), SolverOptions()))
        d_f, d_w = (float(np.max(np.abs(got[name].values / want[name].values - 1.0)))
                    for name in ("pull_adhesive_force_normalized",
                                 "pull_work_of_separation_normalized"))
        events = (int(want.attrs["events"]), int(got.attrs["events"]))
        rows.append((d_f, d_w, events[0] == events[1]))
        print(f"{seed:6d} {params.n_pillars:3d} {params.kbar:9.2e} {d_f:9.1e} {d_w:9.1e} "
              f"{events[0]:5d}/{events[1]:<5d}", flush=True)
    if not rows:
        return
    d_f, d_w, same = (np.array(column) for column in zip(*rows))
    print(f"{len(rows)} brushes in {time.perf_counter() - start:.0f} s: "
          f"{int(np.sum(d_w > 2e-4))} with W above 2e-4 of exact mode, "
          f"{int(np.sum(d_f > 2e-4))} with F_ad; largest W {d_w.max():.1e}, F_ad "
          f"{d_f.max():.1e}; median W {np.median(d_w):.1e}; "
          f"{int(same.sum())} of {len(rows)} event counts equal")


if __name__ == "__main__":
    main()
