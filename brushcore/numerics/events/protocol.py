"""Event-driven loading protocols: approach to a preload, retraction, cycles.

The brush may be rough (an offset z_i per element, per-pillar protrusion
being the common case) and graded (a spring compliance h^2 / k_p per
pillar).  With the tip of pillar p at t_p = d - z_i - f_p / k_p (offsets
taken per element), an attached element satisfies u_i + f_p / k_p = d - z_i,
a detached one keeps the gap g_i = d - z_i - f_p / k_p - u_i >= 0.  An
element attaches when its gap closes (g_i <= 0, zero-range adhesion) and
detaches when its tensile stress exceeds sigma_c; compression never
detaches (README, "Rough, graded and preloaded brushes").

For a fixed attached set everything is affine in d:

    sigma(d) = sigma(d_now) + (d - d_now) sigma_1,  A sigma_1 = 1,

and so are the surface displacement u = K sigma and the gaps.  The next
event, an element reaching sigma_c or a gap closing, or the waypoint (a
target force or displacement), is therefore found exactly from two
solutions: no step size on either branch.  At an attachment the new
element carries no stress (its gap is zero), so sigma(d) is unchanged and
only sigma_1 is re-solved.  After a detachment the stresses are re-solved
at the same d until nothing exceeds sigma_c and no gap is closed (the
unstable cascades), exactly as in `pulloff.pull_off`.

A flat brush (all offsets equal) under the standard protocol (approach to
a preload, retract to separation) is dispatched to `pulloff.pull_off`: its
retraction branch is the flat pull-off shifted by the first-touch position,
its approach a straight line, and it costs exactly what that pull-off does.
"""

from __future__ import annotations

import contextlib
import math

import numpy as np

from brushcore.numerics.platform.backend import namespace
from brushcore.numerics.linear.cg import ConvergenceError, pcg_image
from brushcore.numerics.linear.operator import BrushOperator
from brushcore.numerics.options import SolverOptions
from brushcore.numerics.events.decisions import (PRECISION_BAND, SETTLE_FLOOR, SETTLE_SAFETY,
                                                 band_margin, margins, settles)
from brushcore.numerics.events.pulloff import Progress, SolverError, pull_off
from brushcore.numerics.events.waypoints import (APPROACH, RETRACT, START, ProtocolCurve,
                                                 Waypoint)

#: Relative round-off of a gap, g = d - z - f_p / k_p - u, in units of its
#: terms' sum: below it a gap is zero whatever the pillar's spring.
ROUND_OFF = 16 * float(np.finfo(np.float64).eps)


def is_flat(offsets: np.ndarray) -> bool:
    """Whether every element sits at the same height (a flat brush); 1-D offsets."""
    xp = namespace(offsets)
    return bool(offsets.shape[0] == 0 or xp.all(offsets == offsets[0]))


def dispatches(offsets: np.ndarray, protocol: tuple[Waypoint, ...]) -> bool:
    """Whether `run_protocol` sends this run to `pulloff.pull_off`: a flat
    brush (every offset equal) under the standard protocol (approach to a
    preload, retract to separation)."""
    return standard_preload(protocol) is not None and is_flat(offsets)


def standard_preload(protocol: tuple[Waypoint, ...]) -> float | None:
    """The preload of an (approach to force <= 0, separation) protocol, else None."""
    if (len(protocol) == 2 and protocol[0].kind == "force" and protocol[0].value <= 0
            and protocol[1].kind == "separation"):
        return -protocol[0].value
    return None


def run_protocol(op: BrushOperator, offsets: np.ndarray, sigma_c: float, h: float,
                 options: SolverOptions, protocol: tuple[Waypoint, ...],
                 progress: Progress | None = None, dispatch: bool = True) -> ProtocolCurve:
    """Run a protocol from first touch.

    Parameters
    ----------
    op : operator over all pillar elements, all attached (as built)
    offsets : z_i per pillar element in operator order [length]; larger z
        reaches the substrate first
    sigma_c : critical tensile stress [stress]
    h : element size [length]
    options : tolerances; ``lookahead`` > 0 batches near events (see
        `_Engine._cascade`), 0 (default) is exact; ``cascade`` applies to
        the dispatched flat case only, the general engine always re-solves
        globally after a detachment (with each pillar's local response as
        the warm start)
    protocol : waypoints, see `Waypoint` and `preload_protocol`
    progress : called as progress(events, attached, total) after each event
    dispatch : send a flat brush under the standard protocol to
        `pulloff.pull_off` (identical result and cost); False forces the
        general engine (for tests)

    Returns
    -------
    ProtocolCurve
    """
    xp = op.backend.xp
    offsets = op.backend.asarray(offsets, dtype=float)
    if offsets.shape != (op.size,) or not bool(xp.all(op.attached)):
        raise ValueError("run_protocol needs a fully attached operator and one offset per "
                         "pillar element")
    if not bool(xp.all(xp.isfinite(offsets))):
        raise ValueError("offsets must be finite")
    if dispatch and dispatches(offsets, protocol):
        return _flat(op, float(offsets[0]) if offsets.shape[0] else 0.0,
                     standard_preload(protocol), sigma_c, h, options, progress)
    return _Engine(op, offsets, sigma_c, h, options, progress).run(protocol)


def _flat(op: BrushOperator, z0: float, preload: float, sigma_c: float, h: float,
          options: SolverOptions, progress: Progress | None) -> ProtocolCurve:
    """Today's pull-off, shifted to first touch at d = z0, behind a linear approach.

    In full contact sigma = (d - z0) sigma_1, so the preload is reached at
    d_P = z0 - P / k with k = F/d of the first segment, and the retraction
    back to z0 retraces the same line: the pull-off after it is the flat one.
    """
    total = op.size
    curve = pull_off(op, sigma_c, h, options, progress)
    d_rel, f = curve.displacement, curve.force
    head = 0
    if preload > 0:  # first touch and the preload point precede the flat pull-off's curve
        head = 2
        d_rel = np.concatenate([[0.0, -preload * d_rel[1] / f[1]], d_rel])
        f = np.concatenate([[0.0, -preload], f])
    n_el = np.concatenate([np.full(head, total), curve.attached_elements])
    n_pil = np.concatenate([np.full(head, curve.attached_pillars[0]), curve.attached_pillars])
    steps = d_rel.size
    branch = np.ones(steps, dtype=np.int64)
    direction = np.full(steps, RETRACT, dtype=np.int64)
    branch[0], direction[0] = -1, START
    if preload > 0:
        branch[1], direction[1] = 0, APPROACH
    disp = d_rel + z0
    detach_step = curve.detach_step + head
    peak = int(np.argmax(f))
    last = np.zeros(op.n_pillars, dtype=np.int64)
    np.maximum.at(last, op.backend.to_host(op.pillar_of), detach_step)
    return ProtocolCurve(
        displacement=disp, force=f, attached_elements=n_el, attached_pillars=n_pil,
        branch=branch, direction=direction, waypoint_step=np.array([head // 2, steps - 1]),
        attach_step=np.zeros(total, dtype=np.int64), detach_step=detach_step,
        pillar_force_at_peak=curve.pillar_force_at_peak, peak_step=peak, let_go=disp[last],
        attached_at_waypoint=(np.ones(total, dtype=bool), np.zeros(total, dtype=bool)),
        attached_at_peak=detach_step > peak, events=curve.events,
        cg_iterations=curve.cg_iterations,
        pulls=np.array([[head // 2, steps - 1]]))  # from the preload point on


class _Engine:
    """State of one general protocol run (see `run_protocol`).

    Full-length arrays (operator order, every pillar element) hold the
    stresses at the current d (`sig`), the unit response (`sig1`), and the
    surface displacements they cause (`u`, `u1`); detached entries of the
    stresses are zero.
    """

    MAX_CASCADE = 100_000

    def __init__(self, op: BrushOperator, offsets: np.ndarray, sigma_c: float, h: float,
                 options: SolverOptions, progress: Progress | None) -> None:
        self.op, self.z, self.sigma_c, self.h = op, offsets, sigma_c, h
        self.be = be = op.backend
        self.xp = xp = be.xp
        self.options, self.progress = options, progress
        self.total = op.size
        self.cp = op.compliance[op.pillar_of]  # spring compliance per element
        # Displacement scale of one element at sigma_c: the unit of the gap
        # tolerance and of the tie window between events.
        self.scale = sigma_c * op.diag
        # ... and of a gap: once a pillar touches, its other gaps close at
        # most at K_ii / (K_ii + h^2 / k_p) of the rate before (`_closed`).
        self.gap_unit = self.scale * op.diag / (op.diag + self.cp)
        # The detached elements whose gap closing is the event `_next` found
        # (attached in the cascade's first round).
        self._closing = xp.zeros(self.total, dtype=xp.bool)
        # The attached elements whose stress reaching sigma_c is that event
        # (detached in the cascade's first round: `_next` corrects the event
        # by CG's error estimate, so their stress as solved may lie under it).
        self._reaching = xp.zeros(self.total, dtype=xp.bool)
        # sigma's and sigma_1's error estimates where `_next` took them, and
        # sigma's, full length, once moved to the event or target: what the
        # force and pillar forces recorded there are corrected by.
        self._drift: tuple[np.ndarray, np.ndarray] | None = None
        self._fix: np.ndarray | None = None
        # Float32 transforms: a tie between events must be sure (`_stress_event`).
        self.sure_ties = op.can_refine
        self.cg_iters = 0
        self.events = 0
        n = self.total
        f64 = xp.float64
        self.sig = xp.zeros(n, dtype=f64)
        self.sig1 = xp.zeros(n, dtype=f64)
        self.u = xp.zeros(n, dtype=f64)
        self.u1 = xp.zeros(n, dtype=f64)
        self.attach_step = xp.full(n, -1, dtype=xp.int64)
        self.detach_step = xp.full(n, -1, dtype=xp.int64)
        self.let_go = xp.full(op.n_pillars, math.nan, dtype=f64)
        self.rec: dict[str, list] = {k: [] for k in ("d", "f", "el", "pil", "br", "dir")}
        self.leg, self.dir = -1, START
        self.peak = self._no_peak()
        self.d = float(xp.max(offsets)) if n else 0.0
        # Whether u, u1 are no longer K sig, K sig1 (after detachments, which
        # zero entries and update sig locally); attaching keeps them exact.
        self._stale_u = self._stale_u1 = False

    def _no_peak(self) -> tuple:
        """(force, step, pillar forces, attached mask) before any tensile step."""
        xp = self.xp
        return (-np.inf, -1, xp.zeros(self.op.n_pillars, dtype=xp.float64),
                xp.zeros(self.total, dtype=xp.bool))

    # --- linear algebra -------------------------------------------------
    def _solve(self, rhs: np.ndarray, x: np.ndarray, y: np.ndarray | None,
               threshold: float | None = None, rtol: float | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
        """Solve A x = rhs on the attached set from the full-length warm start
        x (zero where detached) whose field y = K x is given, or None when
        unknown (one application), to ``rtol`` (by default the options').
        Returns x and its field, full length.

        With a ``threshold`` (a cascade's sigma_c) and ``settle_decisions``,
        a solve at the tolerance goes on while an attached element lies
        within its error margin of the threshold (`decisions.settles`), so
        that which elements detach follows the model, not CG's rounding: a
        pillar 9.7e-5 under sigma_c during its neighbour's cascade, with CG's
        error at 1e-4 of the largest stress, let go 2 % of d early (W 2.9e-3
        off exact mode and an independent dense solver, rough 4 x 4 at kbar
        1e-4, 64^2, 2026-12-07).
        """
        op = self.op
        att = op.attached
        xp = self.xp
        if op.size == 0:
            return xp.zeros(self.total, dtype=xp.float64), xp.zeros(self.total, dtype=xp.float64)
        rtol = self.options.rtol if rtol is None else rtol
        x0 = x[att]
        if y is None:
            y = op.field(x0)
        ax0 = y[att] + op.spring(x0)
        verdicts: list[bool] = []

        def settled(band: float):
            if threshold is None or not self.options.settle_decisions:
                return None
            return settles(threshold, 0.0, xp, verdicts, band, cut=False)

        refine = op.can_refine  # float32 transforms: a band more, then double
        try:
            xs, y, it = pcg_image(op.apply_with_field, op.precondition, rhs, x0, ax0, y,
                                  rtol, self.options.max_iter, None,
                                  settled(PRECISION_BAND if refine else 0.0),
                                  SolverOptions.MIXED_MIN_RTOL if refine else SETTLE_FLOOR)
            if verdicts and not verdicts[-1] and refine:
                with op.refined():  # the field afresh: float32's would stay in it
                    y = op.field(xs)
                    xs, y, more = pcg_image(op.apply_with_field, op.precondition, rhs, xs,
                                            y[att] + op.spring(xs), y, rtol,
                                            self.options.max_iter, None, settled(0.0),
                                            SETTLE_FLOOR)
                it += more
        except ConvergenceError as exc:
            raise ConvergenceError(f"{exc} at event {self.events}, d = {self.d:.6g}, "
                                   f"{op.size} of {self.total} elements attached") from None
        self.cg_iters += it
        out = xp.zeros(self.total, dtype=xp.float64)
        out[att] = xs
        return out, y

    def _solve_state(self, threshold: float | None = None, rtol: float | None = None) -> None:
        """sigma at the current d on the current set, and its field (settled
        against ``threshold``, see `_solve`)."""
        att = self.op.attached
        self.sig, self.u = self._solve(self.d - self.z[att], self.sig,
                                       None if self._stale_u else self.u, threshold, rtol)
        self._stale_u = False

    def _solve_unit(self, rtol: float | None = None) -> None:
        """sigma_1 (unit displacement response) on the current set, and its field."""
        self.sig1, self.u1 = self._solve(self.xp.ones(self.op.size, dtype=self.xp.float64),
                                         self.sig1,
                                         None if self._stale_u1 else self.u1, None, rtol)
        self._stale_u1 = False

    def _errors(self) -> tuple[np.ndarray, np.ndarray]:
        """CG's error estimates M^-1 r of sigma and sigma_1 on the attached
        set, from their residuals as they stand: the fields are current
        between events (moves and attachments keep them K sigma), so this
        costs two preconditioner applications and no transform.  sigma is
        carried across moves and attachments, whose gaps close only to the
        field's accuracy, so its error grows along a leg beyond what its
        last solve's estimate says (5.7e-5 of sigma_c at a retraction's
        start against 6.7e-6 estimated then, 48^2 ramped gap map)."""
        op, att = self.op, self.op.attached
        sig, sig1 = self.sig[att], self.sig1[att]
        if self._stale_u:  # not reached between events; kept right if it ever is
            self.u, self._stale_u = op.field(sig), False
        if self._stale_u1:
            self.u1, self._stale_u1 = op.field(sig1), False
        err = op.precondition(self.d - self.z[att] - self.u[att] - op.spring(sig))
        err1 = op.precondition(1.0 - self.u1[att] - op.spring(sig1))
        return err, err1

    # --- bookkeeping ------------------------------------------------------
    def _pillar_force(self, sig: np.ndarray) -> np.ndarray:
        att = self.op.attached
        return self.h**2 * self.be.bincount(self.op.pillar_of[att], weights=sig[att],
                                            minlength=self.op.n_pillars)

    def _force(self) -> float:
        return self.h**2 * float(self.xp.sum(self.sig))

    def _record(self) -> None:
        """One row of the curve.  Right after a move the force is that of
        sigma corrected by its error estimate (`_fix`), as the event itself
        was placed: a random 64 brush's F_ad (kbar 1e-2, 128^2) was 1.1e-5
        off exact mode with the force as carried, 3.9e-7 corrected."""
        r, op = self.rec, self.op
        sig = self.sig if self._fix is None else self.sig + self._fix
        self._fix = None
        f = self.h**2 * float(self.xp.sum(sig))
        r["d"].append(self.d)
        r["f"].append(f)
        r["el"].append(op.size)
        r["pil"].append(int(self.xp.count_nonzero(op.counts)))
        r["br"].append(self.leg)
        r["dir"].append(self.dir)
        if self.dir == RETRACT and f > self.peak[0]:
            self.peak = (f, len(r["d"]) - 1, self._pillar_force(sig),
                          self.xp.asarray(op.attached, copy=True))

    def _gaps(self) -> tuple[np.ndarray, np.ndarray]:
        """Gap and its rate d g / d d of every element (meaningful where detached)."""
        op = self.op
        s = self.be.bincount(op.pillar_of, weights=self.sig, minlength=op.n_pillars)
        s1 = self.be.bincount(op.pillar_of, weights=self.sig1, minlength=op.n_pillars)
        g = self.d - self.z - self.cp * s[op.pillar_of] - self.u
        g1 = 1.0 - self.cp * s1[op.pillar_of] - self.u1
        return g, g1

    def _closed(self, g: np.ndarray) -> np.ndarray:
        """Which gaps count as closed: g_i <= tie_rtol sigma_c K_ii times
        K_ii / (K_ii + h^2 / k_p), and never below the round-off of g's terms.

        Gaps that close together are the tie of mirror images, not a batch:
        once one element of a pillar touches, the pillar's tip rides on the
        substrate and its other gaps close at most at K_ii / (K_ii + h^2 /
        k_p) of the rate before, so a length that ties rigid pillars' faces
        (tie_rtol sigma_c K_ii, 1e-7 of an element's displacement at sigma_c)
        spans a window of d growing as 1 / k on soft ones.  It attached
        elements 8e-4 of d early at kbar 1e-4 and whole faces at their first
        touch at kbar 1e-8 (F_ad 31 % off on a 2 x 2 brush), against an
        independent dense solver of issue 11's conventions.
        """
        xp = self.xp
        spring = self.d - self.z - g - self.u  # f_p / k_p
        span = abs(self.d) + xp.abs(self.z) + xp.abs(spring) + xp.abs(self.u)
        return g <= xp.maximum(self.options.tie_rtol * self.gap_unit, ROUND_OFF * span)

    # --- events -------------------------------------------------------------
    def _attach(self, which: np.ndarray) -> None:
        """Attach elements (full-length mask) whose gap is closed: they carry
        no stress yet, so sigma at this d is unchanged."""
        pos = self.be.flatnonzero(which)
        self.op.attach(pos)
        self.be.put(self.attach_step, pos, len(self.rec["d"]))  # the next record holds them
        self.be.put(self.detach_step, pos, -1)

    def _detach(self, which: np.ndarray) -> None:
        """Detach elements (full-length mask), warm-starting sigma with each
        pillar's exact local response."""
        op = self.op
        att = op.attached
        mask = which[att]
        before = op.counts > 0
        local = op.detach(mask, self.sig[att])
        self.detach_step[which] = len(self.rec["d"])  # the next record lacks them
        self.sig[which] = 0.0
        self.sig1[which] = 0.0
        if local is not None:
            self.sig[op.attached] = local
        self._stale_u = self._stale_u1 = True
        gone = before & (op.counts == 0)
        self.let_go[gone] = self.d

    def _cascade(self) -> None:
        """At fixed d: attach closed gaps, detach overloaded elements, re-solve,
        until the state is consistent; then the unit response for the next leg.

        With ``options.lookahead`` > 0 the first round also attaches gaps
        below lookahead x sigma_c K_ii x K_ii / (K_ii + h^2 / k_p) (`gap_unit`:
        a window of d that does not grow as 1 / k) and detaches stresses above
        (1 - lookahead) sigma_c: fewer events, approximate (default 0: exact).
        """
        tie, ahead = self.options.tie_rtol, self.options.lookahead
        xp = self.xp
        recorded = False
        for _ in range(self.MAX_CASCADE):
            att = self.op.attached
            g, _ = self._gaps()
            closed = self._closed(g)
            if not recorded:  # the first round: the event's own gaps too
                closed = closed | self._closing
            close = ~att & (closed | (g <= ahead * self.gap_unit))
            # Attached early (lookahead), sigma jumps.  In a later round every
            # gap that closed did so under the last re-solve, at fixed d, so it
            # overlaps: attached with no stress, its contact stays violated
            # until sigma is re-solved (a rocking soft pillar on retraction,
            # -5.5e-3 sigma_c K_ii left in exact mode: a protocol energy
            # auditor's graded brush, test_protocol).
            jump = close if recorded else close & ~closed
            over = att & (self.sig >= self.sigma_c * (1.0 - tie - ahead))
            if not recorded:  # the first round: the event's own stresses too
                over = over | self._reaching
            ahead = 0.0  # only the event itself is batched
            if bool(xp.any(close)):
                self._attach(close)
            if not recorded:  # the event point, after attaching, before detaching
                self._record()
                recorded = True
            if not (bool(xp.any(over)) or bool(xp.any(jump))):
                break
            if bool(xp.any(over)):
                self._detach(over)
            self._solve_state(self.sigma_c * (1.0 - tie))
            self._record()
        else:
            raise SolverError(f"cascade at d = {self.d:.9g} did not settle in "
                              f"{self.MAX_CASCADE} rounds")
        self._solve_unit()

    def _next(self, s: int, wp: Waypoint) -> tuple[float, bool]:
        """Distance t >= 0 along direction s to the next event or the target,
        and whether the target is what comes first.

        With ``settle_decisions`` an event and a target closer together than
        CG's tolerance (rtol of d) are decided after solving tighter (to
        SETTLE_FLOOR at most): a preload 3e-6 short of a gap's closing
        brought the element into contact at the tolerance, and F_ad moved
        1 % (an independent dense solver's 2 x 2 brush, 41^2)."""
        rtol = self.options.rtol
        while True:
            t_event, t_stress, reach, rtol = self._events(s, rtol)
            t_target = self._target(s, wp)
            if not (np.isfinite(t_target) and np.isfinite(t_event)
                    and self.options.settle_decisions and rtol > SETTLE_FLOOR
                    and abs(t_target - t_event) <= rtol * (abs(self.d) + t_event + self.scale)):
                break
            rtol = max(rtol * 0.01, SETTLE_FLOOR)
            self._tighten(rtol)
        tie = self.options.tie_rtol * (abs(self.d) + self.scale)
        if t_target <= t_event + tie and np.isfinite(t_target):
            return t_target, True
        if t_stress <= t_event:
            self.be.put(self._reaching, self.be.flatnonzero(self.op.attached)[reach], True)
        return t_event, False

    def _events(self, s: int, rtol: float) -> tuple[float, float, np.ndarray | None, float]:
        """Distance to the next event along direction s, to the first stress
        reaching sigma_c and which elements reach it (`_stress_event`), and
        the tolerance the solves now hold; marks the gaps that close first
        (`_closing`)."""
        xp = self.xp
        att = self.op.attached
        self._closing[...] = False  # in place (no fresh mask an event; no .fill in the array API)
        self._reaching[...] = False
        t_stress, reach, rtol = self._stress_event(s, rtol)
        t_event = t_stress
        if not bool(xp.all(att)):
            g, g1 = self._gaps()
            gap, rate_g = g[~att], s * g1[~att]
            closing = rate_g < 0
            if bool(xp.any(closing)):
                t = xp.where(closing, gap / xp.where(closing, -rate_g, 1.0), xp.inf)
                t = xp.maximum(t, 0.0)
                t_event = min(t_event, float(xp.min(t)))
                # The gap that closes first attaches whatever g's round-off
                # after the move (`_closed` takes its ties).
                first = t <= t_event
                self.be.put(self._closing, self.be.flatnonzero(~att)[first], True)
        return t_event, t_stress, reach, rtol

    def _target(self, s: int, wp: Waypoint) -> float:
        """Distance along direction s to the waypoint's target (inf where
        there is none ahead)."""
        if wp.kind == "force":
            f1 = self.h**2 * float(self.xp.sum(self.sig1))
            t = (wp.value - self._force()) / (s * f1) if f1 != 0 else -1.0
            return t if t >= 0 else np.inf  # else the force moves away from it
        if wp.kind == "displacement":
            return abs(wp.value - self.d)
        return np.inf

    def _stress_event(self, s: int, rtol: float
                      ) -> tuple[float, np.ndarray | None, float]:
        """Distance t >= 0 along direction s at which the first attached
        elements reach sigma_c, and which (a mask over the attached ones:
        those within tie_rtol of sigma_c there), or (inf, None); and the
        tolerance the solves now hold (``rtol``, or tighter).

        Taken from sigma and sigma_1 corrected by their error estimates
        (`_errors`), as `pulloff` corrects its event's peak: CG's error moved
        a cascade 7.5e-5 of d early, where it split in two (a ramped gap map
        at kbar 0.01, 48^2: 138 events against exact mode's and an
        independent dense solver's 137).  With ``settle_decisions`` both are
        solved tighter while an element not tied with the first lies within
        its error margin of sigma_c there, as `decisions.settles` settles its
        cut: which elements go together follows the model, not the rounding.
        """
        xp = self.xp
        att = self.op.attached
        self._drift = None
        # float32's unseen error, until a tightening has solved in double
        band = PRECISION_BAND if self.op.can_refine and rtol >= self.options.rtol else 0.0
        if not bool(xp.any(s * self.sig1[att] > 0)):  # nothing loads (an approach)
            return np.inf, None, rtol
        while True:
            err, err1 = self._errors()
            self._drift = (err, err1)
            sig, sig1 = self.sig[att] + err, self.sig1[att] + err1
            rate = s * sig1
            up = rate > 0
            if not bool(xp.any(up)):
                return np.inf, None, rtol
            t_all = xp.maximum(xp.where(up, (self.sigma_c - sig) / xp.where(up, rate, 1.0),
                                        xp.inf), 0.0)
            first = int(xp.argmin(t_all))
            t = float(t_all[first])
            below = xp.where(up, rate * (t_all - t), xp.inf)  # under sigma_c at t
            reach = below <= self.options.tie_rtol * self.sigma_c
            if not self.options.settle_decisions or rtol <= SETTLE_FLOOR:
                return t, reach, rtol
            e = xp.abs(err) + t * xp.abs(err1)  # of sigma at t
            margin = margins(SETTLE_SAFETY, e, float(xp.max(e)), xp)
            margin = margin + band_margin(band, sig + t * sig1, xp)
            margin = margin + rate * float(margin[first] / rate[first])  # t's own error
            # float32's ties are coincidences: each inside the tie by its margin
            # (as `decisions.settles` with sure_ties)
            unsure = self.sure_ties and bool(xp.any(
                reach & (below > 0) & (below + margin > self.options.tie_rtol * self.sigma_c)))
            if not (bool(xp.any(~reach & (below < margin))) or unsure):
                return t, reach, rtol
            rtol, band = max(rtol * 0.01, SETTLE_FLOOR), 0.0
            self._tighten(rtol)

    def _tighten(self, rtol: float) -> None:
        """Re-solve sigma and sigma_1 at the current d to ``rtol``, in double
        precision (their fields afresh where the transforms were float32)."""
        op = self.op
        with op.refined() if op.can_refine else contextlib.nullcontext():
            if op.can_refine:  # float32's fields would stay in the double solves
                self._stale_u = self._stale_u1 = True
            self._solve_state(rtol=rtol)
            self._solve_unit(rtol)

    def _direction(self, wp: Waypoint) -> int:
        """+1 retract, -1 approach, 0 when the target is reached."""
        if wp.kind == "separation":
            return 0 if self.op.size == 0 else RETRACT
        if wp.kind == "displacement":
            return int(np.sign(wp.value - self.d))
        f = self._force()
        # Relative to the target: a soft brush's preload may lie far below
        # one element's force at sigma_c (2.6e-8 F_K brings every pillar of
        # a 2 x 2 brush at kbar 1e-8 into contact), and a tolerance of rtol
        # h^2 sigma_c turned at first touch.  A target of zero takes that one.
        tol = self.options.rtol * (abs(wp.value) or self.h**2 * self.sigma_c)
        if abs(f - wp.value) <= tol:
            return 0
        return APPROACH if f > wp.value else RETRACT

    def _move(self, s: int, t: float) -> None:
        if self._drift is not None:  # sigma's error moves as sigma does
            err, err1 = self._drift
            self._fix = self.xp.zeros(self.total, dtype=self.xp.float64)
            self.be.put(self._fix, self.be.flatnonzero(self.op.attached), err + s * t * err1)
            self._drift = None
        self.d += s * t
        self.sig += s * t * self.sig1
        self.u += s * t * self.u1

    def run(self, protocol: tuple[Waypoint, ...]) -> ProtocolCurve:
        op, xp, be = self.op, self.xp, self.be
        touch = self._closed(self.d - self.z)  # nothing attached: g = d - z
        if bool(xp.any(~touch)):
            op.detach(~touch)
        self.u1[...] = 0.0  # of sig1 = 0, the warm start
        self.attach_step[touch] = 0
        self._solve_unit()
        self._record()  # first touch: no force
        waypoint_step, at_waypoint = [], []
        # The retraction branches: the retraction waypoints that follow one
        # another (a retraction split by a waypoint is one branch), from a
        # turn out of an approach to the next turn back into one, both
        # turning points included.
        pulls, moving = [], START
        for k, wp in enumerate(protocol):
            self.leg = k
            s = self._direction(wp)
            if s == RETRACT and moving != RETRACT:
                pulls.append([len(self.rec["d"]) - 1, None])
                self.peak = self._no_peak()
            elif s == APPROACH and moving == RETRACT:
                pulls[-1][1] = len(self.rec["d"]) - 1
            moving = s or moving
            while s != 0:
                self.dir = s
                t, reached = self._next(s, wp)
                if not np.isfinite(t):
                    if op.size == 0 and s == RETRACT:
                        break  # let go before a tensile target: nothing more to pull
                    raise SolverError(f"waypoint {k} ({wp}) cannot be reached from d = "
                                      f"{self.d:.9g}: no event and no target ahead")
                self._move(s, t)
                if reached:
                    if wp.kind == "displacement":
                        self.d = wp.value  # no round-off drift
                    self._record()
                    break
                self.events += 1
                self._cascade()
                if self.progress is not None:
                    self.progress(self.events, op.size, self.total)
                if wp.kind == "separation" and op.size == 0:
                    break
            waypoint_step.append(len(self.rec["d"]) - 1)
            at_waypoint.append(xp.asarray(op.attached, copy=True))
        r = self.rec
        if pulls and pulls[-1][1] is None:
            pulls[-1][1] = len(r["d"]) - 1
        _, i_peak, pillar_force, attached_peak = self.peak
        host = be.to_host  # the curve comes back to the host at the end
        return ProtocolCurve(
            displacement=np.asarray(r["d"]), force=np.asarray(r["f"]),
            attached_elements=np.asarray(r["el"]), attached_pillars=np.asarray(r["pil"]),
            branch=np.asarray(r["br"]), direction=np.asarray(r["dir"]),
            waypoint_step=np.asarray(waypoint_step), attach_step=host(self.attach_step),
            detach_step=host(self.detach_step), pillar_force_at_peak=host(pillar_force),
            peak_step=i_peak, let_go=host(self.let_go),
            attached_at_waypoint=tuple(host(a) for a in at_waypoint),
            attached_at_peak=host(attached_peak), events=self.events, cg_iterations=self.cg_iters,
            pulls=np.array(pulls, dtype=np.int64).reshape(-1, 2))
