"""Event-driven, displacement-controlled pull-off (exact for the model).

For a fixed attached set C the stresses scale with the pull displacement,
sigma(d) = d sigma_1(C) (flat pillars at equal height), so F(d) is linear
through the origin between detachment events.  We therefore jump straight
to the next event d = sigma_c / max sigma_1, detach the element(s) that
reach sigma_c, and re-solve at the same d until no element exceeds sigma_c
(the unstable cascades of the paper's Fig. 5).  No step size is involved;
F_ad is the largest event force and W is the exact area under the piecewise
linear curve.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from brushcore.numerics.linear.cg import ConvergenceError, pcg
from brushcore.numerics.linear.operator import BrushOperator
from brushcore.numerics.options import SolverOptions
from brushcore.numerics.events.decisions import PRECISION_BAND, SETTLE_FLOOR, decides, settles


class SolverError(RuntimeError):
    """The pull-off could not be completed consistently."""


@dataclass(frozen=True)
class PullOffCurve:
    """Raw result of one pull-off (units of the inputs).

    Attributes
    ----------
    displacement : pull displacement d per step [length], non-decreasing
    force : tensile force F per step [force]
    attached_elements : attached element count per step
    attached_pillars : pillars with at least one attached element per step
    detach_step : per pillar element (operator order), the first step at
        which it is detached
    events : detachment events (jumps in d)
    cg_iterations : CG iterations over all solves
    pillar_force_at_peak : force of each pillar [force] at the largest force
        (load sharing at F_ad)
    symmetry_fold : 4 when solved on one quadrant of a mirror-symmetric
        brush and unfolded (`brushcore.numerics.halfspace.mirror`), else 1
    preconditioner : `BrushOperator.preconditioner` of the run
    """

    displacement: np.ndarray
    force: np.ndarray
    attached_elements: np.ndarray
    attached_pillars: np.ndarray
    detach_step: np.ndarray
    events: int
    cg_iterations: int
    pillar_force_at_peak: np.ndarray | None = None
    symmetry_fold: int = 1
    preconditioner: str = ""


Progress = Callable[[int, int, int], None]

#: Safety factor on the first-order far-field bound
#: (`BlockInverse.far_field_uncertainty`), for the second order: the
#: neighbours' own response feeding back.  Measured: 1 and 3 both reproduce
#: the global cascade to round-off on regular and random brushes from kbar
#: 1e-6 to rigid.
FAR_FIELD_SAFETY = 3.0


def _spread(op: BrushOperator, x: np.ndarray, attached: np.ndarray | None = None
            ) -> np.ndarray:
    """A compressed vector over the attached elements (``attached``, by
    default the operator's now) as a vector over all pillar elements
    (operator order), zero at the detached ones."""
    be = op.backend
    attached = op.attached if attached is None else attached
    full = be.xp.zeros(attached.shape[0], dtype=be.xp.float64)
    be.put(full, be.flatnonzero(attached), x)
    return full


def far_field_bound(op: BrushOperator, sigma1: np.ndarray,
                    reference: np.ndarray) -> np.ndarray | None:
    """How far the other pillars' far field can move each attached element's
    stress since the last global solve (``reference``, see `_spread`):
    FAR_FIELD_SAFETY times `BrushOperator.far_field_uncertainty` of the
    pillars' summed |change|; None without a local solver.  The far-field
    part of `_certain_detachments`' margin, without the solve's noise."""
    xp = op.backend.xp
    moved = xp.abs(_spread(op, sigma1) - reference)
    change = op.backend.bincount(op.pillar_of, weights=moved, minlength=op.n_pillars)
    bound = op.far_field_uncertainty(change)
    return None if bound is None else FAR_FIELD_SAFETY * bound


def _certain_detachments(op: BrushOperator, sigma1: np.ndarray, threshold: float,
                         reference: np.ndarray, noise: float) -> np.ndarray | None:
    """Elements that exceed the threshold whatever the far field does, or None.

    After local updates sigma1 is exact within each pillar but holds the
    other pillars' field at the last global solve (``reference``, over all
    pillar elements, see `_spread`).  If every element is either above the
    threshold or below it by more than the possible far-field change, the
    global solve would detach exactly the elements above it, so the cascade
    can go on without one.  Otherwise (None) a global solve decides.

    A pillar's far field is bounded by the sum of |change| over its elements,
    not by the change of its total: a soft pillar's spring holds its total
    force nearly fixed while a detachment shifts its load across the face,
    which moves a neighbour's stresses all the same.
    """
    xp = op.backend.xp
    bound = far_field_bound(op, sigma1, reference)
    if bound is None:
        return None
    bound = bound + noise
    over = sigma1 - bound >= threshold
    unsure = (sigma1 + bound >= threshold) & ~over
    return None if bool(xp.any(unsure)) else over


class _Backoff:
    """When a local cascade round tries `_certain_detachments`: every round
    while certificates succeed, ever more rarely while they fail.

    A round that does not try takes the global solve that a failed
    certificate leads to, so skipping one that would fail changes nothing.
    The bound certifies few rounds on most brushes (measured at 512^2: 9 of
    477 on regular 256 at kbar 1e-4, 0 of 8,060 on random 1620 at kbar 1e-5;
    9 of 485 on regular 64 at kbar 0.455 at 1024^2) and costs about a fifth
    of an application each time (3.0 of 54 s on random 1620 at kbar 1e-5).
    After TRIES failures in a row it skips one round, after 2 TRIES three,
    then seven: the gap between tries doubles DOUBLINGS times, to 31
    skipped rounds about 250 rounds in; a success starts over.
    """

    TRIES = 8
    DOUBLINGS = 5

    def __init__(self) -> None:
        self.failures = 0
        self.wait = 0

    def due(self) -> bool:
        """Whether this round tries the certificate."""
        if self.wait:
            self.wait -= 1
            return False
        return True

    def record(self, certified: bool) -> None:
        """The outcome of a try."""
        self.failures = 0 if certified else self.failures + 1
        self.wait = 2 ** min(self.failures // self.TRIES, self.DOUBLINGS) - 1


def _solve_stresses(op: BrushOperator, options: SolverOptions, x0: np.ndarray,
                    threshold: float | None
                    ) -> tuple[np.ndarray, float, int, float | None, np.ndarray]:
    """Unit-displacement stresses of the attached elements [stress per length],
    their error estimate (CG's tolerance, or where an early-decided cascade
    round stopped), the CG iterations taken, for a round that stopped
    early the sum of the true solution's stresses estimated to second order
    (else None), and the preconditioned residual z = M^-1 r where the solve
    stopped (each element's error estimate, `_event_peak`).

    With float32 transforms (`BrushOperator.can_refine`) decisions keep
    PRECISION_BAND more margin, and a solve unsettled only by it goes on in
    double.

    An early-decided round's x is good enough for its decisions, not for
    its force: 9 % low after the tenth round of a 2 x 2 brush's cascade
    (regular 4, kbar 0.455, 45^2), against an independent dense solver.  With
    A x* = b = 1 the force is h^2 d 1.x* = h^2 d b.A^-1 b, and b.A^-1 b =
    1.x + x.r + r.A^-1 r for any x with residual r, so 1.x + x.r + r.z
    (z = M^-1 r) errs only by r.(A^-1 - M^-1) r: 3.6e-5 F_K there (8e-5 of
    that force); it is capped by the state before it (`_Recorder.record`).
    """
    xp = op.backend.xp
    b = xp.ones(op.size, dtype=xp.float64)
    stopped: list[float] = []
    verdicts: list[bool] = []
    ends: list[tuple] = []  # (x, r, z) where each solve stopped
    tie = options.tie_rtol + options.lookahead

    sure = op.can_refine  # float32 transforms: ties are coincidences (`settles`)

    def conditions(band: float) -> tuple:
        return ((decides(threshold, xp, stopped, band)
                 if threshold is not None and options.early_decisions else None),
                settles(threshold, tie, xp, verdicts, band, sure_ties=sure)
                if options.settle_decisions else None)
    band = PRECISION_BAND if op.can_refine else 0.0  # float32 transforms
    floor = SolverOptions.MIXED_MIN_RTOL if op.can_refine else SETTLE_FLOOR
    x, it = pcg(op.apply, op.precondition, b, x0, options.rtol, options.max_iter,
                *conditions(band), floor, lambda *end: ends.append(end))
    if verdicts and not verdicts[-1] and not stopped and op.can_refine:
        with op.refined():  # unsettled at float32's digits
            x, more = pcg(op.apply, op.precondition, b, x, options.rtol,
                          options.max_iter, *conditions(0.0), SETTLE_FLOOR,
                          lambda *end: ends.append(end))
        it += more
    total = None
    _, r, z = ends[-1]
    if stopped:  # an entry only where the last solve stopped early
        total = float(xp.sum(x)) + float(x @ r) + float(r @ z)
    return x, max(stopped + [options.rtol * float(xp.max(x))]), it, total, z


def _event_peak(sigma1, z, xp) -> tuple[float, float]:
    """The largest unit stress as solved, and as the event's displacement
    takes it: corrected by its own error estimate z (x + M^-1 r), since
    d = sigma_c / peak sets the threshold every decision of the cascade is
    measured against, and its error would decide near-ties that the
    solves' settled margins leave to the model.  An independent dense
    solver built one: two soft pillars, one 1.4e-6 under sigma_c during the
    other's cascade, where the first solve's peak was 2.9e-6 low (CG's
    tolerance), let go together and W was 2 % off; z at the peak was its
    error to 2e-4 of it.  The correction costs nothing beyond z, which on
    float32 transforms the caller takes from a residual in double (one
    application an event: float32's own z cannot see its error)."""
    top = int(xp.argmax(sigma1))
    peak = float(sigma1[top])
    return peak, peak + float(z[top])


class _Recorder:
    """The curve as it is pulled: one row per solve or event, and the pillar
    forces at the largest force so far."""

    def __init__(self, op: BrushOperator, h: float) -> None:
        self.op, self.h = op, h
        xp = op.backend.xp
        self.disp, self.force = [0.0], [0.0]
        self.n_el, self.n_pil = [op.size], [int(xp.count_nonzero(op.counts))]
        self.best = -np.inf
        self.best_pillars = xp.zeros(op.n_pillars, dtype=xp.float64)

    def __len__(self) -> int:
        return len(self.disp)

    def record(self, d: float, x: np.ndarray, total: float | None = None) -> None:
        """A row at displacement ``d`` with unit-displacement stresses ``x``
        (``total``: their sum where better known than sum(x))."""
        xp = self.op.backend.xp
        force = d * self.h * self.h * (float(xp.sum(x)) if total is None else total)
        if total is not None and self.disp[-1] == d:
            # At fixed d, F = d 1.A_C^-1 1 only falls as C shrinks (the
            # maximum of 2 1.x - x.A x over fewer unknowns): an estimate
            # never rises above the state before it, nor becomes F_ad.
            force = min(force, self.force[-1])
        self.disp.append(d)
        self.force.append(force)
        if self.force[-1] > self.best:  # one bincount per event: free next to a solve
            self.best = self.force[-1]
            self.best_pillars = d * self.h * self.h * self.op.pillar_sums(x)
        self.n_el.append(self.op.size)
        self.n_pil.append(int(xp.count_nonzero(self.op.counts)))

    def curve(self, d: float, detach_step: np.ndarray, events: int,
              cg_iterations: int) -> PullOffCurve:
        """The curve after complete separation at ``d``, on the host."""
        be = self.op.backend
        self.disp.append(d)
        self.force.append(0.0)
        self.n_el.append(0)
        self.n_pil.append(0)
        # The only per-element data to cross from a device.
        return PullOffCurve(np.asarray(self.disp), np.asarray(self.force),
                            np.asarray(self.n_el), np.asarray(self.n_pil),
                            be.to_host(detach_step), events, cg_iterations,
                            be.to_host(self.best_pillars),
                            preconditioner=self.op.preconditioner)


def pull_off(op: BrushOperator, sigma_c: float, h: float, options: SolverOptions,
             progress: Progress | None = None) -> PullOffCurve:
    """Pull the brush off from full contact until every element has detached.

    Parameters
    ----------
    op : operator over all pillar elements, all attached
    sigma_c : critical tensile stress [stress]
    h : element size [length]
    options : tolerances and the (default 0) lookahead window
    progress : called as progress(events, attached, total) after each event

    Returns
    -------
    PullOffCurve
    """
    be = op.backend
    xp = be.xp
    total = op.size
    detach_step = xp.full(total, -1, dtype=xp.int64)
    rows = _Recorder(op, h)
    cg_iters = 0
    events = 0
    d = 0.0

    def solve(x0: np.ndarray, threshold: float | None = None
              ) -> tuple[np.ndarray, float, float | None]:
        nonlocal cg_iters
        try:
            x, error, it, total_sum, z = _solve_stresses(op, options, x0, threshold)
        except ConvergenceError as exc:
            raise ConvergenceError(f"{exc} at event {events}, d = {d:.6g}, "
                                   f"{op.size} of {total} elements attached") from None
        cg_iters += it
        return x, error, total_sum, z

    local = options.cascade == "local" and op.has_local_solver
    backoff = _Backoff()

    def detach(mask: np.ndarray, stress: np.ndarray) -> np.ndarray:
        """Detach, returning the stresses of the rest.

        Where the per-pillar inverses exist the stresses are updated by each
        pillar's exact local response and its neighbours' first-order one
        (`BlockInverse.detach`): the next global solve's warm start or the
        local cascade's state.
        """
        step = len(rows)  # the next recorded step is the first without them
        positions = be.flatnonzero(op.attached)[mask]
        be.put(detach_step, positions, step)
        updated = op.detach(mask, stress)
        return stress[~mask] if updated is None else updated

    # unit-displacement stresses, warm started from zero
    sigma1, error, _, z = solve(xp.zeros(total, dtype=xp.float64))
    while op.size:
        if op.can_refine:
            # Float32 transforms: the event's d from a residual in double.  d
            # sets the threshold of its whole cascade, and float32's error in
            # the peak (6.3e-6 of it, invisible to the float32 z) flipped a
            # round's element 2.6e-6 from it: random 1620 at kbar 1e-5 (512^2)
            # on its other branch on some FFTW plans (W 3.4e-4 off exact
            # mode).  One double application an event: +2.5-11 % on random
            # curves measured (README, "Mixed precision").
            with op.refined():
                z = op.precondition(xp.ones(op.size, dtype=xp.float64) - op.apply(sigma1))
        peak, corrected = _event_peak(sigma1, z, xp)
        if not np.isfinite(peak) or peak <= 0.0 or not corrected > 0.0:
            raise SolverError(f"no tensile stress at event {events} (max sigma_1 = {peak!r}) "
                              f"with {op.size} elements attached")
        d_next = sigma_c / corrected
        if d_next < d * (1.0 - 1e-12):
            raise SolverError(f"contact set inconsistent: next event d = {d_next:.9g} lies "
                              f"before the current d = {d:.9g}")
        d = max(d, d_next)
        events += 1
        rows.record(d, sigma1)
        mask = sigma1 >= peak * (1.0 - options.tie_rtol - options.lookahead)
        threshold = sigma_c * (1.0 - options.tie_rtol) / d
        # Re-solve at fixed d until no attached element exceeds sigma_c.
        # The stresses of the last global solve over all pillar elements,
        # spread only when a certificate reads them (few rounds try one).
        solved, reference = (sigma1, xp.asarray(op.attached, copy=True)), None
        while True:
            sigma1 = detach(mask, sigma1)
            if not op.size:
                break
            if local and backoff.due():
                if reference is None:
                    reference = _spread(op, solved[0], solved[1])
                mask = _certain_detachments(op, sigma1, threshold, reference, error)
                certified = mask is not None and bool(xp.any(mask))
                backoff.record(certified)
                if certified:
                    continue  # decided without a global solve
            sigma1, error, total_sum, z = solve(sigma1, threshold)
            solved, reference = (sigma1, xp.asarray(op.attached, copy=True)), None
            rows.record(d, sigma1, total_sum)
            mask = sigma1 >= threshold
            if not bool(xp.any(mask)):
                break
        if progress is not None:
            progress(events, op.size, total)
    return rows.curve(d, detach_step, events, cg_iters)
