"""How far the cascade certificate's bound is from deciding rounds. Asserts nothing.

    python benchmarks/certificate_ceiling.py random 220 1e-3 --grid 256
    python benchmarks/certificate_ceiling.py random 64 1e-4              # the sweep's grid, 512

A soft random brush spends most of its time in cascade rounds, each a
global solve whose first application only computes the warm start's
residual (docs/SPEED.md, "Where a random brush's time goes").  A round
may skip its solve when `pulloff._certain_detachments` proves that no
decision could flip; its rigorous far-field bound rarely can.  This script runs one
curve with a certificate tried in every round (the run itself takes every
round's global solve, so its curve is the global cascade's) and, after
each round's solve, re-solves to rtol 1e-10 for the round's exact stresses
x*.  With e = x* - sigma1, the warm start's true error, it prints

* how many rounds today's certificate decides;
* the oracle ceilings: rounds a bound equal to X |e_i| would decide (every
  element farther than X |e_i| from the threshold, at least one above it),
  for X = 1 ... 100;
* on the elements where today's certificate is unsure, its two terms over
  |e_i|: the far-field bound (x FAR_FIELD_SAFETY) and the noise (the last
  solve's tolerance), each as a median per round, then percentiles over
  rounds.

The probe wraps `pulloff.pcg`, `pulloff._certain_detachments` and
`pulloff._Backoff`; the re-solves make it several times slower than the
curve (random 64 at kbar 1e-4 on 512^2: 157 s).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from brushcore import BrushParams, SolverOptions, simulate
from brushcore.numerics.events import pulloff

FACTORS = (1, 3, 10, 30, 100)


class _Probe:
    """The wrapped solver steps and what they saw."""

    def __init__(self) -> None:
        self.rounds = 0
        self.certified = 0
        self.oracle = dict.fromkeys(FACTORS, 0)
        self.ratios: list[float] = []  # far-field bound / |e| where it blocks
        self.noise_ratios: list[float] = []  # the previous solve's tolerance / |e| there
        self._attempt: tuple | None = None  # (sigma1, threshold, far-field bound, noise) of the last try
        self._pcg = pulloff.pcg
        self._certify = pulloff._certain_detachments

    def certify(self, op, sigma1, threshold, reference, noise):
        """Today's verdict, counted, and the bound kept for the next solve."""
        self.rounds += 1
        verdict = self._certify(op, sigma1, threshold, reference, noise)
        self.certified += verdict is not None and bool(verdict.any())
        far = pulloff.far_field_bound(op, sigma1, reference)
        if far is not None:
            self._attempt = (sigma1.copy(), threshold, far, noise)
        return None  # the global solve decides, as in cascade="global"

    def pcg(self, apply, precondition, b, x0, *args, **kwargs):
        """The solver's solve; after a certificate try, also the exact one."""
        x, iterations = self._pcg(apply, precondition, b, x0, *args, **kwargs)
        if self._attempt is not None:
            sigma1, threshold, far, noise = self._attempt
            self._attempt = None
            exact, _ = self._pcg(apply, precondition, b, x, 1e-10, 20000)
            self._score(sigma1, threshold, far, noise, exact)
        return x, iterations

    def _score(self, sigma1, threshold, far, noise, exact) -> None:
        error = np.abs(exact - sigma1)
        gap = sigma1 - threshold
        for factor in FACTORS:
            margin = factor * error
            if bool(np.any(gap >= margin)) and not bool(np.any(np.abs(gap) < margin)):
                self.oracle[factor] += 1
        blocking = (np.abs(gap) < far + noise) & (error > 0.0)
        if blocking.any():
            self.ratios.append(float(np.median(far[blocking] / error[blocking])))
            self.noise_ratios.append(float(np.median(noise / error[blocking])))


class _AlwaysTry(pulloff._Backoff):
    """A certificate in every local cascade round."""

    def due(self) -> bool:
        return True

    def record(self, certified: bool) -> None:
        pass


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("layout")
    parser.add_argument("n_pillars", type=int)
    parser.add_argument("kbar", type=float)
    parser.add_argument("--grid", type=int, default=512)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    probe = _Probe()
    pulloff.pcg, pulloff._certain_detachments = probe.pcg, probe.certify
    pulloff._Backoff = _AlwaysTry
    params = BrushParams(layout=args.layout, n_pillars=args.n_pillars, kbar=args.kbar,
                         grid=args.grid, seed=args.seed)
    start = time.perf_counter()
    curve = simulate(params, SolverOptions())
    print(f"{args.layout} N = {args.n_pillars}, kbar = {args.kbar:g}, {args.grid}^2: "
          f"{curve.attrs['events']} events, {probe.rounds} rounds with a certificate try, "
          f"{time.perf_counter() - start:.0f} s")
    print(f"today's certificate decides {probe.certified} rounds")
    print("a bound of X |e_i| would decide: " + ", ".join(
        f"X = {x}: {n} ({100.0 * n / max(probe.rounds, 1):.0f} %)" for x, n in probe.oracle.items()))
    for name, ratios in (("far-field bound", probe.ratios), ("noise (tolerance)", probe.noise_ratios)):
        if ratios:
            p10, p50, p90 = np.percentile(ratios, [10, 50, 90])
            print(f"today's {name} / |e_i| where the certificate is unsure, per-round medians: "
                  f"p10 {p10:.3g}, p50 {p50:.3g}, p90 {p90:.3g} ({len(ratios)} rounds)")


if __name__ == "__main__":
    main()
