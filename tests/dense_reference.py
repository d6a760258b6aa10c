"""An independent dense solver of the model, for the tests only.

Written from the design notes (the physics, the conventions of rough and
preloaded brushes) and He, Li & Popov (2020) sections 2-4 by sessions that
did not read brushcore's solver, and sharing no code with it: Love's
coefficient by its own primitive, a dense influence matrix over the pillar
elements (no FFT, no preconditioner, no CG), `numpy.linalg.solve` for every
attached set, and the exact event-driven pull-off and protocol.  Only the
label map (the geometry, an input) comes from brushcore.

Conventions: E*, dgamma, h in one unit system; tensile stress and force
positive; d > 0 away from the substrate; pillar p carries the spring k_p
(inf: rigid) and the protrusion z_p (a larger z touches first), an element
the offset z_i = z_p - gap_i.  Attached: u_i + f_p / k_p = d - z_i;
detached: g_i = d - z_i - f_p / k_p - u_i >= 0.  An element detaches when
sigma_i > sigma_c and attaches when g_i <= 0; at fixed d every element
past its threshold changes state in the same round, round after round.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: Mean displacement of an h x h square under its own uniform pressure p,
#: in p h / E* (Love's coefficient averaged over the square, closed form).
CBAR = (4.0 * math.log(1.0 + math.sqrt(2.0)) - 4.0 / 3.0 * (math.sqrt(2.0) - 1.0)) / math.pi
#: Its centre value, 4 ln(1 + sqrt 2) / pi, in p h / E*.
CENTRE = 4.0 * math.log(1.0 + math.sqrt(2.0)) / math.pi


def _primitive(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """G(X, Y) = X asinh(Y / |X|) + Y asinh(X / |Y|), whose mixed derivative
    is 1 / sqrt(X^2 + Y^2); 0 where its factor is 0."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return (np.where(x != 0.0, x * np.arcsinh(y / np.abs(x)), 0.0)
                + np.where(y != 0.0, y * np.arcsinh(x / np.abs(y)), 0.0))


def love_square(dx, dy, h: float = 1.0, e_star: float = 1.0) -> np.ndarray:
    """Surface displacement [length] at offset (dx, dy) from the centre of an
    h x h square under unit uniform pressure, on a half space of modulus E*."""
    a = 0.5 * h
    return (_primitive(dx + a, dy + a) - _primitive(dx + a, dy - a)
            - _primitive(dx - a, dy + a) + _primitive(dx - a, dy - a)) / (math.pi * e_star)


def critical_stress(e_star: float = 1.0, dgamma: float = 1.0, h: float = 1.0) -> float:
    """sigma_c at which the elastic energy under one element, (1/2) sigma h^2
    CBAR sigma h / E*, equals dgamma h^2 (Pohrt & Popov 2015)."""
    return math.sqrt(2.0 * e_star * dgamma / (CBAR * h))


def mean_self_compliance_by_quadrature(order: int = 24, cells: int = 16) -> float:
    """Love's coefficient averaged over its own unit square by Gauss-Legendre
    quadrature on sub-squares: CBAR, independently of its closed form."""
    g, w = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(-0.5, 0.5, cells + 1)
    half = 0.5 * np.diff(edges)
    pts = np.concatenate([half[i] * g + 0.5 * (edges[i + 1] + edges[i]) for i in range(cells)])
    wts = np.concatenate([half[i] * w for i in range(cells)])
    x, y = np.meshgrid(pts, pts)
    return float(np.sum(love_square(x, y) * wts[:, None] * wts[None, :]))


class Brush:
    """The pillar elements of a label map, their offsets and springs, and the
    dense influence matrix K over them.

    Parameters
    ----------
    labels : (n, n) int, -1 no pillar, 0 ... N-1 the pillar
    k : spring stiffness per pillar or one for all [force / length]; inf rigid
    z : protrusion per pillar [length, or d_K with ``in_d_k``] (default 0)
    gap : extra gap per element, (n, n) [length, or d_K with ``in_d_k``] (default 0)
    in_d_k : whether z and gap are in units of this brush's d_K
    """

    def __init__(self, labels: np.ndarray, k, z=None, gap=None, *, h: float = 1.0,
                 e_star: float = 1.0, dgamma: float = 1.0, in_d_k: bool = False) -> None:
        labels = np.asarray(labels)
        self.h, self.e_star, self.dgamma = h, e_star, dgamma
        self.index = np.flatnonzero(labels.ravel() >= 0)
        self.pillar = labels.ravel()[self.index].astype(np.int64)
        self.n_pillars = int(self.pillar.max()) + 1
        self.m = self.index.size
        rows, cols = np.divmod(self.index, labels.shape[1])
        kernel = love_square((cols[:, None] - cols[None, :]) * h,
                             (rows[:, None] - rows[None, :]) * h, h, e_star)
        k = np.broadcast_to(np.asarray(k, dtype=float), (self.n_pillars,))
        self.compliance = np.where(np.isinf(k), 0.0, h * h / np.where(np.isinf(k), 1.0, k))
        self.kernel = kernel
        self.sigma_c = critical_stress(e_star, dgamma, h)
        a0 = math.sqrt(self.m * h * h / math.pi)
        self.F_K = math.sqrt(8.0 * math.pi * e_star * dgamma * a0**3)
        self.d_K = math.sqrt(2.0 * math.pi * dgamma * a0 / e_star)
        self.W_K = 2.0 * math.pi * a0 * a0 * dgamma
        unit = self.d_K if in_d_k else 1.0
        offsets = np.zeros(self.m)
        if z is not None:
            offsets += unit * np.asarray(z, dtype=float)[self.pillar]
        if gap is not None:
            offsets -= unit * np.asarray(gap, dtype=float).ravel()[self.index]
        self.z = offsets

    def _solve(self, on: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Stresses of the elements ``on`` for right-hand sides ``rhs`` (columns),
        and each pillar's spring stretch f_p / k_p (rows by pillar).

        Solved with each sprung pillar's stretch t_p as an unknown of its own,
        K s + t_p = rhs and h^2 sum_p s - k_p t_p = 0, not as K + (h^2 / k_p)
        1 1^T: at kbar 1e-8 that rank-one term is ~1e6 times K, whose part
        that shares a face's stress would keep only ~1e-8 of its digits.  The
        gaps take t_p as solved (h^2 / k_p times sum s would multiply the
        stresses' round-off by 1e6 again).
        """
        pillar = self.pillar[on]
        sprung = np.unique(pillar[self.compliance[pillar] > 0])
        m, q = on.size, sprung.size
        a = np.zeros((m + q, m + q))
        a[:m, :m] = self.kernel[np.ix_(on, on)]
        col = np.searchsorted(sprung, pillar)
        has = np.isin(pillar, sprung)
        a[np.flatnonzero(has), m + col[has]] = 1.0
        a[m + col[has], np.flatnonzero(has)] = self.h * self.h
        a[m + np.arange(q), m + np.arange(q)] = -self.h * self.h / self.compliance[sprung]
        x = np.linalg.solve(a, np.vstack([rhs, np.zeros((q, rhs.shape[1]))]))
        stretch = np.zeros((self.n_pillars, rhs.shape[1]))
        stretch[sprung] = x[m:]
        return x[:m], stretch

    def affine(self, attached: np.ndarray) -> dict[str, np.ndarray | float]:
        """Stresses, force and gaps on ``attached`` as slope and intercept in d."""
        on, off = np.flatnonzero(attached), np.flatnonzero(~attached)
        s1, s0 = np.zeros(self.m), np.zeros(self.m)
        stretch = np.zeros((self.n_pillars, 2))
        if on.size:
            x, stretch = self._solve(on, np.column_stack([np.ones(on.size), -self.z[on]]))
            s1[on], s0[on] = x[:, 0], x[:, 1]
        p1 = np.bincount(self.pillar, s1, self.n_pillars)
        p0 = np.bincount(self.pillar, s0, self.n_pillars)
        g1, g0 = np.zeros(self.m), np.zeros(self.m)
        if off.size:
            coupling = self.kernel[np.ix_(off, on)]
            q = self.pillar[off]
            g1[off] = 1.0 - stretch[q, 0] - coupling @ s1[on]
            g0[off] = -self.z[off] - stretch[q, 1] - coupling @ s0[on]
        h2 = self.h * self.h
        return dict(s1=s1, s0=s0, f1=h2 * s1.sum(), f0=h2 * s0.sum(), g1=g1, g0=g0,
                    p1=h2 * p1, p0=h2 * p0)


@dataclass
class PullOff:
    """A flat pull-off: event displacements, the force just before each event
    and after every cascade round, F_ad and W (units of the inputs)."""

    d_events: np.ndarray
    f_before: np.ndarray
    round_forces: list[list[float]]
    adhesive_force: float
    work: float
    pillar_forces_at_peak: np.ndarray


def pull_off(brush: Brush, tie_rtol: float = 1e-9) -> PullOff:
    """Exact event-driven pull-off of a flat brush from full contact.

    For a fixed attached set sigma = d sigma_1; the next event is at d =
    sigma_c / max sigma_1, where every element at or above sigma_c (within
    ``tie_rtol``) detaches, round after round at that d.  W is the exact
    area of the piecewise linear curve.
    """
    attached = np.ones(brush.m, dtype=bool)
    s1 = brush.affine(attached)["s1"]
    h2, threshold = brush.h ** 2, brush.sigma_c * (1.0 - tie_rtol)
    d_events, f_before, rounds, peaks = [], [], [], []
    work, d_last = 0.0, 0.0
    while attached.any():
        d = brush.sigma_c / s1[attached].max()
        slope = h2 * s1.sum()
        work += 0.5 * slope * (d * d - d_last * d_last)
        d_events.append(d)
        f_before.append(d * slope)
        peaks.append(d * h2 * np.bincount(brush.pillar, s1, brush.n_pillars))
        rounds.append([])
        go = attached & (d * s1 >= threshold)
        go[np.argmax(np.where(attached, s1, -np.inf))] = True  # the event's own element
        while go.any():
            attached &= ~go
            s1 = brush.affine(attached)["s1"]
            rounds[-1].append(d * h2 * s1.sum())
            go = attached & (d * s1 >= threshold)
        d_last = d
    peak = int(np.argmax(f_before))
    return PullOff(np.array(d_events), np.array(f_before), rounds, f_before[peak], work,
                   peaks[peak])


@dataclass
class Protocol:
    """A protocol's curve (one point at each event before its change, and
    after every cascade round and at each waypoint) and what it yields."""

    d: list[float] = field(default_factory=list)
    force: list[float] = field(default_factory=list)
    direction: list[int] = field(default_factory=list)  # -1 approach, +1 retract, 0 start
    events: int = 0
    pillars_at_preload: int | None = None

    def pulls(self) -> list[np.ndarray]:
        """Index runs of the retracting points, each from its turning point."""
        out, run = [], None
        for i, s in enumerate(self.direction):
            if s > 0:
                run = run if run is not None else ([i - 1] if i else [])
                run.append(i)
            elif s < 0 and run is not None:
                out.append(np.array(run))
                run = None
        return out + ([np.array(run)] if run is not None else [])

    def pull_summary(self) -> list[tuple[float, float]]:
        """(F_ad, W = int max(F, 0) dd) of every pull."""
        d, f = np.array(self.d), np.array(self.force)
        return [(float(f[p].max()), sum(_positive_area(d[i], f[i], d[j], f[j])
                                        for i, j in zip(p[:-1], p[1:])))
                for p in self.pulls()]

    def loop_energy(self) -> float:
        """int F dd over the whole protocol (trapezoids of the linear pieces)."""
        d, f = np.array(self.d), np.array(self.force)
        return float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(d)))


def _positive_area(d0: float, f0: float, d1: float, f1: float) -> float:
    """Exact int max(F, 0) dd for F linear from (d0, f0) to (d1, f1)."""
    if d1 == d0 or (f0 <= 0 and f1 <= 0):
        return 0.0
    if f0 >= 0 and f1 >= 0:
        return 0.5 * (f0 + f1) * (d1 - d0)
    dz = d0 + (d1 - d0) * f0 / (f0 - f1)
    return 0.5 * f0 * (dz - d0) if f0 > 0 else 0.5 * f1 * (d1 - dz)


def protocol(brush: Brush, waypoints: list[tuple], tie_rtol: float = 1e-13) -> Protocol:
    """Exact event-driven protocol from first touch (d = max z_i).

    ``waypoints``: ("force", F) with F tensile positive (a preload P is
    -P), ("displacement", d) an absolute d, ("separation",).  Ties are taken
    as a displacement, tie_rtol d_K at the current rates (never as a gap
    length: a soft pillar's gaps close at a rate ~ k / (E* a)), plus
    round-off guards of 1e-12 relative on the stress and 1e-13 sigma_c K_ii
    on the gap.
    """
    b, res = brush, Protocol()
    sc, tie_d = b.sigma_c, tie_rtol * b.d_K
    gap_floor = 1e-13 * b.sigma_c * b.kernel[0, 0]
    attached = np.zeros(b.m, dtype=bool)
    state = b.affine(attached)

    def due(d: float, s: int) -> tuple[np.ndarray, np.ndarray]:
        sig, gap = state["s1"] * d + state["s0"], state["g1"] * d + state["g0"]
        rate_s, rate_g = s * state["s1"], -s * state["g1"]
        go = attached & ((sig >= sc * (1.0 - 1e-12))
                         | ((rate_s > 0) & (sc - sig <= tie_d * rate_s)))
        come = ~attached & ((gap <= gap_floor) | ((rate_g > 0) & (gap <= tie_d * rate_g)))
        return go, come

    def record(d: float, s: int) -> None:
        res.d.append(d)
        res.force.append(state["f1"] * d + state["f0"])
        res.direction.append(s)

    def cascade(d: float, s: int, log: bool) -> None:
        nonlocal attached, state
        go, come = due(d, s)
        while go.any() or come.any():
            attached = (attached & ~go) | come
            state = b.affine(attached)
            if log:
                record(d, s)
            go, come = due(d, s)

    d = float(b.z.max())
    cascade(d, -1, log=False)  # first touch: the elements at max z
    record(d, 0)
    approached = False
    for wp in waypoints:
        kind = wp[0]
        while True:
            f = state["f1"] * d + state["f0"]
            if kind == "force":
                target = float(wp[1])
                if abs(f - target) <= 1e-12 * abs(target) + 1e-13 * b.F_K:
                    break
                s = -1 if f > target else 1
            elif kind == "displacement":
                target = float(wp[1])
                if abs(d - target) <= 1e-13 * b.d_K:
                    break
                s = -1 if target < d else 1
            else:
                if not attached.any():
                    break
                s = 1
            approached |= s < 0
            sig, gap = state["s1"] * d + state["s0"], state["g1"] * d + state["g0"]
            rate_s, rate_g = s * state["s1"], -s * state["g1"]
            up, closing = attached & (rate_s > 0), ~attached & (rate_g > 0)
            step = min(np.min(np.maximum((sc - sig[up]) / rate_s[up], 0.0), initial=np.inf),
                       np.min(np.maximum(gap[closing] / rate_g[closing], 0.0), initial=np.inf))
            to_target = np.inf
            if kind == "force" and s * state["f1"] * (target - f) > 0:
                to_target = (target - f) / (s * state["f1"])
            elif kind == "displacement":
                to_target = abs(target - d)
            if not np.isfinite(min(step, to_target)):
                raise RuntimeError(f"waypoint {wp!r} cannot be reached from d = {d}")
            if to_target <= step:
                d = target if kind == "displacement" else d + s * to_target
                record(d, s)
                break
            d += s * step
            res.events += 1
            if s > 0:
                record(d, s)  # the state before the drop
            cascade(d, s, log=True)
        if res.pillars_at_preload is None and approached and kind == "force":
            res.pillars_at_preload = np.unique(b.pillar[attached]).size
    return res
