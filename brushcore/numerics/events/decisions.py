"""When a solve may stop: the decision margins of cascades and events.

A cascade round or an event decides which elements detach next; CG's
error, and float32's where the transforms are single precision, must not
be able to flip that decision.  `decides` lets a cascade round stop short
of the tolerance once its iterate decides the round; `settles` lets a
solve at the tolerance stop only once no decision lies within its error;
both read each element's margin (`margins`, `band_margin`).  Shared by the
pull-off (`brushcore.numerics.events.pulloff`) and the protocol engine
(`brushcore.numerics.events.protocol`).
"""

from __future__ import annotations


#: Margin, in CG error estimates, by which every element must clear the
#: threshold before a cascade round stops short of the tolerance: its own
#: estimate times DECISION_SAFETY plus the largest one times DECISION_FLOOR.
#: With 3, every round that stopped early on random 1620
#: at kbar 1, random 220 at kbar 1e-3 and random 64 at kbar 1e-4 (512^2,
#: 3,814 rounds, each re-solved to 1e-11 in double) decided as the true
#: solution does, with 8 % fewer applications on the first and 4 % on the
#: second than with 10; 1 with a floor of 0.1 got 6 of 1,304 rounds of the
#: first wrong.
DECISION_SAFETY = 3.0
#: The error estimate z = M^-1 r is first order: the inter-pillar coupling
#: carries some of a large z to elements whose own z is small, hence a floor
#: on every element's margin.  Measured at the first iterate of 1,200
#: cascade solves (random 220 kbar 1e-4 and random 64 rigid at 512^2, regular
#: 256 kbar 0.455; true solution at rtol 1e-11): margins of 10 |z_i| + 0.3
#: max|z| and of 3 |z_i| + 0.3 max|z| never mis-decided an element.
DECISION_FLOOR = 0.3


def margins(safety: float, z, zmax: float, xp):
    """Each element's margin: ``safety`` times its own error estimate plus
    DECISION_FLOOR times the largest (shared by `decides`, `settles` and
    the protocol engine's settled events)."""
    return safety * xp.abs(z) + DECISION_FLOOR * zmax


def band_margin(band: float, x, xp) -> float:
    """``band`` times max|x|: the float32 part of every margin (0 in double)."""
    return band * float(xp.max(xp.abs(x))) if band else 0.0


def decides(threshold: float, xp, stopped: list[float], band: float = 0.0):
    """CG early exit for a cascade round: stop once the iterate detaches at
    least one element and every element clears the threshold by its margin
    (DECISION_SAFETY times its own error estimate plus DECISION_FLOOR times
    the largest).

    Per element, not the largest estimate for all: after a local update the
    error sits on the few pillars the detachment moved, while the elements
    closest to the threshold are often elsewhere (random 220 at kbar 1e-4,
    512^2: 70 % of its solves end at the warm start, against 50 % with 10
    max|z| for every element).  Such a round only decides which
    elements go next; its stresses are re-solved before anything is
    recorded that enters F_ad or W (the cascade's last round, where nothing
    exceeds the threshold, always runs to the tolerance, and forces recorded
    inside a cascade lie on a vertical drop).  The largest error estimate it
    stopped at is appended to ``stopped``.  Every margin also holds ``band``
    times max|x| (`PRECISION_BAND` while the transforms are float32).
    """
    def decided(x, z, zmax: float) -> bool:
        margin = margins(DECISION_SAFETY, z, zmax, xp) + band_margin(band, x, xp)
        done = (bool(xp.any(x >= threshold + margin))
                and not bool(xp.any(xp.abs(x - threshold) < margin)))
        if done:
            stopped.append(zmax)
        return done
    return decided


#: Margin, in CG error estimates, that a settled decision leaves (`settles`).
SETTLE_SAFETY = 3.0
#: Relative error at which a solve stops unsettled: near-ties closer than
#: this are ties.  Single-precision transforms stop at
#: `SolverOptions.MIXED_MIN_RTOL` and hand over to double (`BrushOperator.refined`).
SETTLE_FLOOR = 1e-9
#: Error, relative to the largest stress, that float32 transforms leave in
#: a converged solution and CG's error estimate cannot see (it converges on
#: the float32 operator): up to 1.45e-5 (README, "Mixed precision"; float32
#: CG to 1e-7 against double to 1e-11 on six random curves, 512^2).  While
#: the transforms are float32 every decision margin holds this much more,
#: and a solve that only this band leaves unsettled is handed to double at
#: once.  Twice the largest error measured: a band of 1.5e-5 left random
#: 1620 at kbar 1e-5 (a near-tie) on the branch exact mode does not take
#: on some FFTW plans (docs/SPEED.md, the sweep's row).
PRECISION_BAND = 3e-5


def settles(threshold: float | None, tie: float, xp, verdicts: list[bool],
             band: float = 0.0, cut: bool = True, sure_ties: bool = False):
    """Condition on CG's tolerance: no decision that the error could flip.

    At the tolerance CG's error is still ~rtol of the largest stress, and a
    soft random brush's pillars reach sigma_c within less than that of each
    other, so which element goes next would follow CG's rounding, not the
    model (measured: random 1620 at kbar 3e-6, 512^2, W moved 4.6e-4 with
    the warm start alone).  A solve is settled once every element lies
    farther from ``threshold`` (which elements a cascade round detaches)
    than its margin, SETTLE_SAFETY times its own error estimate plus
    DECISION_FLOOR times the largest (per element, as in `decides`), and,
    when none exceeds it, farther from the cut below the largest stress
    (which elements the next event detaches; those within ``tie`` of the
    largest go together) than its margin and the largest's together.  Each
    verdict is appended to ``verdicts``.  Margins also hold ``band`` times
    max|x| (`PRECISION_BAND` while the transforms are float32); a solve
    unsettled only by the band stops there (more float32 iterations cannot
    settle it) with its verdict False, which hands it to double.  Without
    ``cut`` only the threshold is settled (the protocol engine's next event
    is not the largest stress's).  With ``sure_ties`` the elements tied with
    the largest must also lie inside the tie by their margins and its (a
    run on float32 transforms, whose ties are coincidences: 9.2e-8 apart in
    float32 and 5.4e-7 in double, within CG's error of each other, put random
    1620 at kbar 1e-5 (512^2) on its other branch on some FFTW plans, W 3.4e-4
    off exact mode); without, a tie stands as solved (the mirror images of a
    regular brush, run in double, are ties to round-off).
    """
    def clear(x, margin) -> bool:
        verdict = True
        if threshold is not None:
            verdict = not bool(xp.any(xp.abs(x - threshold) < margin))
        if cut and verdict and (threshold is None or not bool(xp.any(x >= threshold))):
            top = int(xp.argmax(x))
            peak = float(x[top])
            verdict = (int(xp.count_nonzero(x >= peak - margin - float(margin[top])))
                       == int(xp.count_nonzero(x >= peak * (1.0 - tie))))
            if verdict and sure_ties:  # each tied one inside the tie by its margins
                edge = peak * (1.0 - tie)
                verdict = not bool(xp.any((x >= edge) & (x - margin - float(margin[top]) < edge)
                                          & (x < peak)))
        return verdict

    def settled(x, z, zmax: float) -> bool:
        margin = margins(SETTLE_SAFETY, z, zmax, xp)
        verdicts.append(clear(x, margin + band_margin(band, x, xp)))
        return verdicts[-1] or (band > 0.0 and clear(x, margin))
    return settled
