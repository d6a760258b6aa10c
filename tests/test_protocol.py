"""Rough, graded and preloaded brushes: the protocol engine against theory.

Soft-limit targets are the elastic-foundation formulas of `brushcore.model.theory`
(DESIGN.md, "Rough, graded and preloaded brushes").  They ignore the
pillars' interaction through the half space, which the solver keeps; every
soft-limit tolerance below is derived from the measured interaction of the
same geometry (the flat brush's deficit), never fitted.
"""

from __future__ import annotations

from dataclasses import replace

import math
import warnings

import numpy as np
import pytest
import xarray as xr
from conftest import punch_params

from brushcore import (BrushParams, ParameterError, SolverOptions, Waypoint, simulate,  # the public API
                       theory)
from brushcore.numerics.halfspace.convolution import Convolver
from brushcore.model.solve import run, run_protocol_curve
from brushcore.model.layout import build_labels
from brushcore.numerics.linear.operator import BrushOperator
from brushcore.numerics.linear.precondition import BlockInverse, coarse_inverse
from brushcore.numerics.events.protocol import dispatches
from brushcore.numerics.events.waypoints import loop_energy, positive_work, preload_protocol

EXACT = SolverOptions.exact()  # CG to 1e-8, global cascades: reference results


def _retraction(curve) -> tuple[float, float]:
    """F_ad and W = integral of max(F, 0) dd over the last retraction branch."""
    r = curve.retraction
    return float(curve.force[r].max()), positive_work(curve.displacement[r], curve.force[r])


def _today(params: BrushParams, options: SolverOptions = SolverOptions()):
    # the full grid: protocols do not fold symmetric brushes onto a quadrant
    _, curve, applications = run(params, replace(options, symmetry=False))
    return float(curve.force.max()), float(np.trapezoid(curve.force, curve.displacement)), \
        applications


# --- flat brushes stay what they are --------------------------------------------

FLAT = BrushParams("regular", 16, 0.01, 64)


@pytest.mark.parametrize("preload", [0.0, 30.0, 400.0])
def test_flat_brush_with_preload_is_todays_pull_off(preload):
    """Equal heights: any preload, any common height, today's F_ad and W, at today's cost."""
    f0, w0, apps0 = _today(FLAT)
    heights = np.full(FLAT.n_pillars, 7.25)
    _, _, curve, apps = run_protocol_curve(FLAT, preload_protocol(preload), heights=heights)
    f, w = _retraction(curve)
    assert f == pytest.approx(f0, rel=1e-9) and w == pytest.approx(w0, rel=1e-9)
    assert apps == apps0, f"{apps} operator applications, today {apps0}"
    # the approach is the full-contact line: it ends at the preload
    assert curve.force[curve.waypoint_step[0]] == pytest.approx(-preload, abs=1e-12)
    # all energy is dissipated: the approach is returned on the way back
    assert loop_energy(curve.displacement, curve.force) == pytest.approx(w0, rel=1e-9)


def test_flat_brush_takes_the_pull_offs_preconditioner():
    """A flat brush under the standard protocol is today's pull-off, so it
    takes the pull-off's limit on dense blocks too: one pillar of 1,965
    elements (between `BlockInverse.MAX_BLOCK` and `MAX_BLOCK_PROTOCOL`)
    gets the tiles, as `run` does, and the same curve at the same cost
    (before: dense blocks, 3.2 GB for a graded random 8 x 8 brush at
    1024^2).  The general engine, which a rough brush or a cycle needs,
    keeps them."""
    params = BrushParams("random", 1, 0.455, 128)
    _, today, apps0 = run(params)
    _, op, curve, apps = run_protocol_curve(params, preload_protocol(0.0))
    assert BlockInverse.MAX_BLOCK < op.elements.size < BlockInverse.MAX_BLOCK_PROTOCOL
    assert op.preconditioner == "tiles"
    assert np.array_equal(curve.force, today.force) and apps == apps0
    flat, rough = np.zeros(3), np.array([0.0, 0.0, 1e-3])
    assert dispatches(flat, preload_protocol(2.0))
    assert not dispatches(rough, preload_protocol(2.0))
    assert not dispatches(flat, (Waypoint("force", -2.0), Waypoint("force", 1.0),
                                 Waypoint("separation")))


@pytest.mark.parametrize("preload", [0.0, 400.0])
def test_general_engine_reproduces_flat_pull_off(preload):
    """The event engine itself (no dispatch) on a flat brush: same F_ad and W.

    Both find the same events from CG solves to 1e-8; the engine's states
    are affine extrapolations of re-solved stresses instead of d sigma_1,
    so they differ by CG error only: 1e-6 leaves two orders of margin.
    """
    f0, w0, _ = _today(FLAT, EXACT)
    _, _, curve, _ = run_protocol_curve(FLAT, preload_protocol(preload), EXACT,
                                        heights=np.full(16, -3.0), dispatch=False)
    f, w = _retraction(curve)
    assert f == pytest.approx(f0, rel=1e-6) and w == pytest.approx(w0, rel=1e-6)


# --- one pillar ----------------------------------------------------------------

@pytest.mark.parametrize("kbar", [math.inf, 1e-3])
@pytest.mark.parametrize("height,preload", [(0.0, 0.0), (11.0, 50.0), (-4.0, 500.0)])
def test_single_pillar_pulls_off_at_kendall(kbar, height, preload):
    """One flat pillar: any height and preload, today's single-punch result (Kendall).

    The engine's F_ad is today's within CG error (1e-6, see above); today's
    radius-8 punch is Kendall's force within its discretisation, +3.7 %
    measured (4.9 % at radius 6, test_physics: < 3 % from radius 20).
    """
    params = punch_params(8, kbar=kbar)
    f0, _, _ = _today(params, EXACT)
    _, _, curve, _ = run_protocol_curve(params, preload_protocol(preload), EXACT,
                                        heights=np.array([height]), dispatch=False)
    f, _ = _retraction(curve)
    assert f == pytest.approx(f0, rel=1e-6)
    area = float(curve.attached_elements[0])  # h = 1
    kendall = theory.kendall_force(theory.equivalent_radius(area), 1.0, 1.0)
    assert abs(f / kendall - 1) < 0.05, f"F_ad / Kendall = {f / kendall:.4f}"
    assert curve.let_go[0] > height  # it lets go in tension, above its first touch


# --- soft limit: the elastic foundation ------------------------------------------

#: Four pillars of radius 6 h on 128^2, 64 h = 10.7 radii apart (phi = 0.028).
SOFT_RADIUS, SOFT_GRID, SOFT_KBAR = 6, 128, 1e-6


def _soft(n_pillars: int = 4) -> BrushParams:
    return BrushParams("regular", n_pillars, SOFT_KBAR, SOFT_GRID,
                       phi=n_pillars * math.pi * SOFT_RADIUS**2 / SOFT_GRID**2)


@pytest.fixture(scope="module")
def soft_reference():
    """f_c of one isolated pillar with the same footprint, and the flat brush's
    interaction deficit eps = 1 - F_ad / (N f_c) (measured 1.9 %)."""
    _, _, single, _ = run_protocol_curve(punch_params(SOFT_RADIUS, kbar=SOFT_KBAR),
                                         preload_protocol(0.0))
    f_c = float(single.force.max())
    _, _, flat, _ = run_protocol_curve(_soft(), preload_protocol(0.0))
    eps = 1.0 - float(flat.force.max()) / (4 * f_c)
    # Neighbours always cost something, and less than the 7.5 % the dense
    # solver finds for 16 pillars at phi 0.07 (closer, and more of them).
    assert 0 < eps < 0.05, eps
    return f_c, eps


def test_soft_flat_brush_against_an_independent_dense_solver():
    """4 x 4 soft pillars close together (128^2, phi = 0.07, kbar = 1e-6) let
    go at 0.925 N f_c by an independent dense solver (the project's design
    notes), f_c the force of one pillar of the same footprint alone: the
    neighbours' fields cost 7.5 % even in the soft limit.  Given to three
    digits (5e-4) with CG at rtol 1e-4: 1e-3."""
    from test_geometry import _single_pillar_force

    params = BrushParams("regular", 16, 1e-6, 128, phi=0.07, allow_coarse=True)
    labels = build_labels(params)
    _, curve, _ = run(params, labels=labels)
    f_c = min(_single_pillar_force(labels == q) for q in range(16))
    assert float(curve.force.max()) / (16 * f_c) == pytest.approx(0.925, abs=1e-3)


def _tolerance(eps: float) -> float:
    """Interaction bound for the soft-limit comparisons.

    A neighbour changes a pillar's let-go force in proportion to its own
    force.  In the flat brush every neighbour pulls with f_c at the moment
    of let-go, which costs eps; in the rough and graded brushes below every
    pillar force stays within [-f_c, f_c] (the preload is chosen so), so
    each pillar's let-go force moves by at most eps f_c, and F_ad, one sum
    of pillar forces, by at most eps.  2e-3 covers CG (rtol 1e-4) and the
    stretch lambda = f_c / k, which ignores the contact compliance
    (k / k_c ~ 1e-5 here).
    """
    return eps + 2e-3


def _heights_run(heights_over_lambda, f_c, protocol_of=None, options=SolverOptions()):
    params = _soft(len(heights_over_lambda))
    k = theory.stiffness_from_kbar(SOFT_KBAR, 1.0, params.side)
    lam = f_c / k
    z = np.asarray(heights_over_lambda, dtype=float) * lam
    # Approach until the shortest pillar is compressed by 0.1 lambda: a soft
    # spring closes a flat face only against the neighbours' field once its
    # force is ~0.01 f_c, so 0.1 f_c attaches every element.
    preload = k * np.sum(z - z.min() + 0.1 * lam)
    protocol = preload_protocol(preload) if protocol_of is None else protocol_of(z, lam, k)
    _, op, curve, apps = run_protocol_curve(params, protocol, options, heights=z)
    return z, k, lam, op, curve, apps


def test_soft_rough_brush_follows_discrete_foundation_formula(soft_reference):
    f_c, eps = soft_reference
    z, k, lam, op, curve, _ = _heights_run([0.0, 0.3, 0.6, 0.9], f_c)
    assert curve.attached_at_waypoint[0].all(), "the preload must attach every element"
    f_ad, _ = _retraction(curve)
    target = theory.foundation_pull_off(z, np.full(4, k), f_c)
    assert abs(f_ad / target - 1) < _tolerance(eps), (f_ad / target, eps)
    # each pillar lets go a stretch lambda above its height (its own f_c)
    assert curve.let_go == pytest.approx(z + lam, rel=_tolerance(eps))
    # load sharing at F_ad: tallest pillar in compression... sum is F_ad
    assert curve.pillar_force_at_peak.sum() == pytest.approx(f_ad, rel=1e-9)


def test_soft_uniform_spread_matches_closed_form(soft_reference):
    """Heights evenly spread over a band of width w = 0.5 lambda, ends included.

    For w <= lambda the brush lets go when its shortest pillar does, with
    every pillar attached: F_ad = N k (lambda - mean z) = N f_c (1 - w / 2
    lambda), the closed form, exactly for any N >= 2 with evenly spaced
    heights that include both ends (checked against the discrete formula).
    """
    f_c, eps = soft_reference
    w = 0.5
    z, k, lam, _, curve, _ = _heights_run(np.linspace(0.0, w, 4), f_c)
    f_ad, _ = _retraction(curve)
    closed = float(theory.uniform_spread_pull_off(w)) * 4 * f_c
    assert theory.foundation_pull_off(z, np.full(4, k), f_c) == pytest.approx(closed, rel=1e-12)
    assert abs(f_ad / closed - 1) < _tolerance(eps), (f_ad / closed, eps)


def test_foundation_formula_limits():
    """Pure theory: the discrete formula converges to the uniform closed form
    (midpoint sampling error < 1 / N), and bimodal stiffness gives 0.75."""
    n = 400
    for w in (0.25, 0.5, 1.0, 2.0):
        z = (np.arange(n) + 0.5) / n * w
        value = theory.foundation_pull_off(z, np.ones(n), 1.0) / n
        assert value == pytest.approx(float(theory.uniform_spread_pull_off(w)), abs=1.0 / n)
    k = np.array([1.0, 1.0, 2.0, 2.0])
    assert theory.foundation_pull_off(np.zeros(4), k, 1.0) / 4 == pytest.approx(0.75)
    with pytest.raises(ValueError, match=r"k_eff must be finite and > 0 .*got inf"):
        theory.foundation_pull_off(np.zeros(2), np.array([1.0, np.inf]), 1.0)  # was NaN
    assert theory.bimodal_stiffness_pull_off(2.0, 0.5) == pytest.approx(0.75)
    expected = {0.1: 0.784, 0.2: 0.634, 0.5: 0.343, 1.0: 0.115}
    for s, value in expected.items():
        assert theory.gaussian_spread_pull_off(s) == pytest.approx(value, abs=6e-4)


def test_soft_half_k_half_2k_brush_holds_three_quarters(soft_reference):
    """Equal heights, springs k and 2k in a checkerboard: 0.75 N f_c."""
    f_c, eps = soft_reference
    params = _soft()
    k = theory.stiffness_from_kbar(SOFT_KBAR, 1.0, params.side)
    stiffness = np.array([k, 2 * k, 2 * k, k])
    _, _, curve, _ = run_protocol_curve(params, preload_protocol(0.0),
                                        compliance=params.h**2 / stiffness)
    ratio = float(curve.force.max()) / (0.75 * 4 * f_c)
    assert abs(ratio - 1) < _tolerance(eps), (ratio, eps)


def test_far_apart_soft_pillars_follow_the_foundation_within_a_fraction_of_a_percent():
    """The elastic foundation where the interaction is small: four pillars of
    radius 8 h on 512^2, 256 h = 32 radii apart (phi = 0.003), where the flat
    brush's deficit eps is ~0.2 % (1.9 % at the 10.7 radii above, which is
    those tests' tolerance: they could not see a 1-2 % error of the formula;
    a physics referee's find).  The same bound, eps + 2e-3 (`_tolerance`),
    for unequal heights (the discrete formula) and for springs k and 2k
    (0.75 N f_c); measured 0.19 % and 0.13 % off by the referee."""
    radius, grid = 8, 512
    params = BrushParams("regular", 4, SOFT_KBAR, grid, phi=4 * math.pi * radius**2 / grid**2)
    _, _, single, _ = run_protocol_curve(punch_params(radius, kbar=SOFT_KBAR),
                                         preload_protocol(0.0))
    f_c = float(single.force.max())
    _, _, flat, _ = run_protocol_curve(params, preload_protocol(0.0))
    eps = 1.0 - float(flat.force.max()) / (4 * f_c)
    assert 0 < eps < 4e-3, eps  # a quarter of the close brush's, or less
    k = theory.stiffness_from_kbar(SOFT_KBAR, 1.0, params.side)
    lam = f_c / k
    z = np.array([0.0, 0.3, 0.6, 0.9]) * lam
    preload = k * np.sum(z - z.min() + 0.1 * lam)  # every pillar attached (as _heights_run)
    _, _, curve, _ = run_protocol_curve(params, preload_protocol(preload), heights=z)
    assert curve.attached_at_waypoint[0].all()
    f_ad, _ = _retraction(curve)
    target = theory.foundation_pull_off(z, np.full(4, k), f_c)
    assert abs(f_ad / target - 1) < _tolerance(eps), (f_ad / target, eps)
    stiffness = np.array([k, 2 * k, 2 * k, k])
    _, _, curve, _ = run_protocol_curve(params, preload_protocol(0.0),
                                        compliance=params.h**2 / stiffness)
    ratio = float(curve.force.max()) / (0.75 * 4 * f_c)
    assert abs(ratio - 1) < _tolerance(eps), (ratio, eps)


# --- energy and cycles ---------------------------------------------------------------

def test_loop_energy_is_dissipation(soft_reference):
    """From first touch to separation the work done on the brush is >= 0, and a
    cycle in which nothing attaches or detaches returns every bit of it."""
    f_c, _ = soft_reference

    def cycle(z, lam, k):
        preload = k * np.sum(z - z.min() + 0.1 * lam)
        d_back = z.min() - 0.05 * lam  # still compressed: nothing lets go
        return (Waypoint("force", -preload), Waypoint("displacement", d_back),
                Waypoint("force", -preload), Waypoint("separation"))

    z, k, lam, _, curve, _ = _heights_run([0.0, 0.4, 0.2, 0.7], f_c, cycle)
    d, f = curve.displacement, curve.force
    total = loop_energy(d, f)
    scale = float(np.sum(np.abs(f[1:] + f[:-1]) * np.abs(np.diff(d)))) / 2
    assert total > 0
    i0, _, i2, _ = curve.waypoint_step
    closed = loop_energy(d[i0:i2 + 1], f[i0:i2 + 1])
    # the same affine F(d) both ways: zero to round-off of the O(1e5) d values
    assert abs(closed) < 1e-9 * scale, (closed, scale)
    # every element of the retraction segment: monotone, tensile where it lets go
    assert np.all(np.diff(d[curve.retraction]) >= 0)


def test_a_gap_closed_inside_a_cascade_is_solved_in_contact(monkeypatch):
    """A gap that a cascade's re-solve closes at fixed d overlaps; attached
    with no stress, its contact stays violated until sigma is re-solved.  A
    protocol energy auditor's brush (alternately rigid and kbar 1e-3 pillars,
    drawn heights, a tilted gap map, three cycles) left -5.5e-3 of the
    engine's gap scale on an attached element after a cascade in exact mode;
    re-solved, what is left is CG's (1e-8): every attached gap within 1e-6."""
    from brushcore.numerics.events import protocol as engine

    worst = []
    cascade = engine._Engine._cascade

    def checked(self):
        cascade(self)
        g, _ = self._gaps()
        attached = self.op.attached
        if bool(np.any(attached)):
            worst.append(float(np.min(g[attached] / self.scale)))

    monkeypatch.setattr(engine._Engine, "_cascade", checked)
    n = 49
    tilt = 0.05 * (np.arange(n) - n / 2) / n * np.ones((n, 1))
    params = BrushParams("regular", 16, 1e-3, n,
                         heights=np.random.default_rng(5).normal(0, 0.2, 16),
                         kbar_values=np.where(np.arange(16) % 2 == 0, np.inf, 1e-3),
                         gap_map=tilt)
    cycles = [Waypoint("force", -1.5)] + [Waypoint("displacement", 1.0),
                                          Waypoint("force", -1.5)] * 3
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        simulate(params, EXACT, protocol=[*cycles, Waypoint("separation")])
    assert len(worst) > 100 and min(worst) > -1e-6, min(worst)


def test_reattachment_in_two_cycles(soft_reference):
    """Pull until two pillars have let go, press again, pull off: the contact
    and the pull-off of the second cycle are those of a single cycle."""
    f_c, _ = soft_reference
    heights = [0.0, 0.3, 0.6, 0.9]

    def two_cycles(z, lam, k):
        preload = k * np.sum(z - z.min() + 0.1 * lam)
        return (Waypoint("force", -preload), Waypoint("displacement", 1.45 * lam),
                Waypoint("force", -preload), Waypoint("separation"))

    _, _, _, _, single, _ = _heights_run(heights, f_c, options=EXACT)
    z, k, lam, op, curve, _ = _heights_run(heights, f_c, two_cycles, options=EXACT)
    _, pulled, pressed, _ = curve.attached_at_waypoint
    pillars = np.bincount(op.pillar_of, weights=pulled, minlength=4)
    assert np.count_nonzero(pillars) == 2, f"attached elements per pillar {pillars}"
    assert pressed.all(), "re-pressing attaches every element again"
    # the same contact at the same preload is the same state: same pull-off
    f1, w1 = _retraction(single)
    f2, w2 = _retraction(curve)
    assert f2 == pytest.approx(f1, rel=1e-6) and w2 == pytest.approx(w1, rel=1e-6)
    assert loop_energy(curve.displacement, curve.force) > loop_energy(
        single.displacement, single.force)  # two pull-offs dissipate more than one


ROUGH9 = BrushParams("regular", 9, 0.003, 48,
                     heights=np.array([0.2, 0.0, -0.1, 0.05, 0.15, -0.2, 0.0, 0.1, -0.05]))


def _pull(ds, k: int) -> tuple[float, float, float]:
    """F_ad / F_K, W / W_K and the cycle's energy of retraction branch k of a file."""
    pull = ds.isel(pull=k)
    return (float(pull.pull_adhesive_force_normalized),
            float(pull.pull_work_of_separation_normalized), float(pull.pull_cycle_energy))


def test_every_retraction_of_a_cycle_has_its_own_pull_off():
    """Pulled off completely, a brush keeps no memory: each cycle of
    (press to P_k, separate) pulls off as a fresh run pressed to P_k, and
    the cycles' energies add up to the protocol's dissipated energy."""
    loads = (0.01, 2.0)  # 8 of 9 pillars pressed on, then all 9
    cycles = simulate(ROUGH9, EXACT, protocol=[w for p in loads for w in
                                               (Waypoint("force", -p), Waypoint("separation"))])
    assert cycles.sizes["pull"] == 2
    for k, p in enumerate(loads):
        fresh = simulate(ROUGH9, EXACT, protocol=[Waypoint("force", -p), Waypoint("separation")])
        f, w, energy = _pull(cycles, k)
        # other warm starts along another path: CG's 1e-8 separates them
        assert f == pytest.approx(float(fresh.adhesive_force_normalized), rel=1e-6), (k, p)
        assert w == pytest.approx(float(fresh.work_of_separation_normalized), rel=1e-6), (k, p)
        assert energy == pytest.approx(float(fresh.dissipated_energy), rel=1e-6), (k, p)
        assert float(cycles.pull_contact_area_at_end[k]) == 0
    assert _pull(cycles, 1)[:2] == (float(cycles.adhesive_force_normalized),
                                    float(cycles.work_of_separation_normalized))
    assert float(cycles.pull_cycle_energy.sum()) == pytest.approx(
        float(cycles.dissipated_energy), rel=1e-12)
    # the two loads press different contacts: the pulls differ (so the test can fail)
    assert abs(_pull(cycles, 0)[0] / _pull(cycles, 1)[0] - 1) > 1e-3


def test_a_partial_retraction_is_a_pull_of_its_own():
    """A retraction stopped short of separation is the first pull, with the
    contact it left; it is the last pull of the protocol that stops there."""
    back = (Waypoint("force", -1.0), Waypoint("displacement", 25.0))  # 3 of 9 pillars let go
    cycles = simulate(ROUGH9, protocol=[*back, Waypoint("force", -1.0), Waypoint("separation")])
    with pytest.warns(UserWarning, match="last retraction ends in contact: adhesive_force is "
                      "the largest force it reached, not a pull-off"):
        prefix = simulate(ROUGH9, protocol=list(back))
    first, last = (int(v) for v in cycles.isel(pull=0)[["pull_first_step", "pull_last_step"]]
                   .to_array())
    assert cycles.branch.values[first] == 0 and set(cycles.branch.values[first + 1:last + 1]) \
        == {1}  # the turning point, then the retraction leg
    assert _pull(cycles, 0)[:2] == (float(prefix.adhesive_force_normalized),
                                    float(prefix.work_of_separation_normalized))
    left = cycles.pull_contact_area_at_end.values
    assert 0 < left[0] < float(cycles.contact_area[first]) and left[1] == 0


def test_cli_runs_a_protocol_and_reports_every_pull(tmp_path, capsys):
    from brushcore.cli import main
    from brushcore.data.io import read_curve

    out = tmp_path / "cycles.nc"
    text = "force:-0.5, separation, force:-2, separation"
    rc = main(["simulate", "--layout", "regular", "--pillars", "9", "--kbar", "0.003",
               "--grid", "48", "--roughness", "0.3", "--out", str(out), "--quiet",
               "--protocol", text])
    printed = capsys.readouterr().out
    assert rc == 0 and "retraction 0: F_ad/F_K" in printed and "retraction 1:" in printed
    assert "partial retraction" not in printed  # both pull off
    ds = read_curve(out)
    assert ds.sizes["pull"] == 2 and ds.attrs["protocol"].count("separation") == 2
    pytest.importorskip("compliance_checker")
    from test_cf import cf_errors

    assert cf_errors(out, tmp_path) == []  # the pull dimension and its variables
    from brushcore.data import figures

    legend = figures.rough_loop(ds).axes[0].get_legend().get_texts()
    marked = [t.get_text() for t in legend if t.get_text().startswith("retraction ")]
    assert marked == [rf"retraction {k}: $\bar F_{{ad}}$ = {f:.3g}"
                      for k, f in enumerate(ds.pull_adhesive_force_normalized.values)]


def test_cli_marks_a_retraction_that_ends_in_contact(tmp_path, capsys):
    """A retraction to a displacement that leaves the soft brush in contact
    never reached a peak: its F_ad line says it is not a pull-off."""
    from brushcore.cli import main

    rc = main(["simulate", "--layout", "regular", "--pillars", "9", "--kbar", "1e-3",
               "--grid", "48", "--out", str(tmp_path / "p.nc"), "--quiet", "--protocol",
               "force:-1, displacement:25, force:-1, separation"])
    lines = capsys.readouterr().out.splitlines()
    first = next(line for line in lines if line.startswith("retraction 0:"))
    last = next(line for line in lines if line.startswith("retraction 1:"))
    assert rc == 0 and "in contact at its end: 100.0%" in first
    assert "(a partial retraction: F_ad is the largest force it reached" in first
    assert "partial" not in last and "in contact at its end: 0.0%" in last


@pytest.mark.parametrize("text,message", [
    ("force:-1, push:2", "waypoint 1 ('push:2') is of no kind in"),
    ("force:-1, separation:3", "waypoint 1 ('separation:3') takes no value"),
    ("force, separation", "waypoint 0 ('force') needs a finite number after 'force:'"),
    ("force:1e400, separation", "needs a finite number"),
    ("displacement:nan", "needs a finite number"),
    (" , ", "it holds no waypoint"),
    ("force:-5000, separation", "waypoint 0 is a force of -5000 F_K"),
    ("force=-1, separation", "no kind in ('force', 'displacement', 'separation'); a colon "
                             "joins a kind and its value (force:-1)"),
    ("force:-1; separation", "needs a finite number after 'force:'; commas separate"),
])
def test_cli_refuses_bad_protocols_before_any_work(tmp_path, capsys, text, message):
    from brushcore.cli import main

    out = tmp_path / "curve.nc"
    rc = main(["simulate", "--layout", "regular", "--pillars", "16", "--kbar", "0.1",
               "--grid", "64", "--out", str(out), "--quiet", "--protocol", text])
    err = capsys.readouterr().err
    assert rc == 2 and f"--protocol {text} is invalid" in err and message in err, err
    assert "allowed" in err and not out.exists()


@pytest.mark.parametrize("first,message", [
    ("force:2", "waypoint 0 is a tensile force of 2 F_K: from the first touch, where only "
                "the highest pillars touch, it pulls on the pillars that touch there"),
    ("displacement:3", "waypoint 0, displacement 3 d_K, lies above the first touch at d = "
                       "0.3 d_K and pulls on the pillars that touch there"),
])
def test_a_first_waypoint_that_pulls_from_first_touch_is_said_to(tmp_path, capsys, first,
                                                                  message):
    """A brush with heights touches with its highest pillar first: a tensile
    first waypoint (a preload of the wrong sign, say) or a displacement above
    that touch pulls that pillar off (as 'separation' first does here), and is said
    to; a later retraction from no contact at all is said to have no F_ad.
    A flat brush, in full contact at first touch, may be pulled from there
    without a word."""
    from brushcore.cli import main

    heights = tmp_path / "h.txt"
    heights.write_text("0.3\n0\n-0.1\n0.1\n")
    out = tmp_path / "curve.nc"
    args = ["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "0.1", "--grid",
            "41", "--quiet", "--protocol"]
    with pytest.warns(UserWarning) as caught:
        assert main([*args, f"{first}, separation", "--heights", str(heights),
                     "--out", str(out)]) == 0
    said = " ".join(str(w.message) for w in caught)
    assert message in said and "(a preload P is force:-P)" in said, said
    alone = tmp_path / "sep.nc"
    assert main([*args, "separation", "--heights", str(heights), "--out", str(alone)]) == 0
    assert float(xr.open_dataset(out).adhesive_force_normalized) == pytest.approx(
        float(xr.open_dataset(alone).adhesive_force_normalized), rel=1e-9)
    with pytest.warns(UserWarning, match=r"retraction 1 starts with no pillar in contact: "
                      r"its adhesive_force is NaN"):
        assert main([*args, "separation, displacement:0.31, force:1, separation", "--heights",
                     str(heights), "--out", str(tmp_path / "twice.nc")]) == 0
    with warnings.catch_warnings(record=True) as flat:
        warnings.simplefilter("always")  # flat: in full contact at once, no first touch to say
        assert main([*args, f"{first}, separation", "--out", str(tmp_path / "f.nc")]) == 0
    said = [str(w.message) for w in flat]
    f_ad = float(xr.open_dataset(tmp_path / "f.nc").adhesive_force_normalized)
    assert 0 < f_ad < 2  # so force:2 lies beyond the pull-off, and is said to be
    assert said == (["waypoint 0 (force:2) was not reached: the brush let go first, at its "
                     "adhesive force, and the leg ended at separation (F = 0)"]
                    if first == "force:2" else []), said


def test_heights_with_a_common_offset_beside_displacement_waypoints_are_said_to():
    """A displacement waypoint is absolute: heights given as measured (7.6 d_K
    each, a lab's) moved it by their mean.  Said where a displacement
    waypoint reads it, not where forces alone do, nor for offsets."""
    offsets = np.array([0.2, -0.1, 0.0, -0.1])
    cycle = [Waypoint("force", -1.0), Waypoint("displacement", 1.0), Waypoint("separation")]
    base = BrushParams("regular", 4, 0.1, 41)
    with pytest.warns(UserWarning, match=r"the heights given have a mean of 7\.5 d_K against "
                      r"a spread of 0\.122: displacement waypoints are absolute"):
        simulate(replace(base, heights=offsets + 7.5), protocol=cycle)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        simulate(replace(base, heights=offsets), protocol=cycle)
        simulate(replace(base, heights=offsets + 7.5),
                 protocol=[Waypoint("force", -1.0), Waypoint("separation")])
    # a first displacement above the touch and absolute heights: each said
    with pytest.warns(UserWarning) as caught:
        simulate(replace(base, heights=offsets + 7.5),
                 protocol=[Waypoint("displacement", 8.0), Waypoint("separation")])
    said = [str(w.message) for w in caught]
    assert any("waypoint 0, displacement 8 d_K, lies above the first touch" in m
               for m in said), said
    assert any("the heights given have a mean of 7.5 d_K" in m for m in said), said


def test_waypoint_kinds_read_in_any_case_and_separation_takes_no_value():
    """"Force:-1, Separation" is the protocol in lower case; Python's
    Waypoint("separation", 3) is refused as the CLI's 'separation:3' is."""
    from brushcore.model.inputs import parse_protocol

    assert parse_protocol("Force: -1, SEPARATION") == (Waypoint("force", -1.0),
                                                        Waypoint("separation"))
    with pytest.raises(ParameterError, match=r"waypoint value=3.0 is invalid: allowed none "
                                             r"for a separation waypoint"):
        Waypoint("separation", 3)
    # a force or displacement without its target once meant a target of 0
    for kind in ("force", "displacement"):
        with pytest.raises(ParameterError, match=rf"waypoint value=None is invalid: allowed a "
                                                 rf"finite number: a {kind} waypoint needs"):
            Waypoint(kind)
    assert Waypoint("force", 0) == Waypoint("force", 0.0)


def test_cli_refuses_a_preload_beside_a_protocol(tmp_path, capsys):
    from brushcore.cli import main

    out = tmp_path / "curve.nc"
    rc = main(["simulate", "--layout", "regular", "--pillars", "16", "--kbar", "0.1",
               "--grid", "64", "--out", str(out), "--quiet", "--preload", "1",
               "--protocol", "force:-1, separation"])
    err = capsys.readouterr().err
    assert rc == 2 and "--preload 1.0 is invalid: allowed 0 when a --protocol" in err, err
    assert "pillar radius" not in err, err  # refused before the layout's line: one line
    assert not out.exists()


def test_retraction_split_by_waypoints_is_one_branch():
    """F_ad and W are taken over the retraction branch, not its last waypoint leg.

    A retraction that stops at a displacement or a force on its way out
    follows the same path as one that does not: the same F_ad and W (it
    once kept only the last leg: W/W_K 3.28 instead of 42.59, measured
    against an independent dense solver that gives 42.59).  A protocol
    that ends in an approach takes them over its last retraction, not over
    the approach after it (W once came out as 0).
    """
    heights = np.array([0.2, 0.0, -0.1, 0.05, 0.15, -0.2, 0.0, 0.1, -0.05])
    params = BrushParams("regular", 9, 0.003, 48, heights=heights)
    load = Waypoint("force", -1.0)

    def pulled(*protocol):
        ds = simulate(params, EXACT, protocol=protocol)
        return float(ds.adhesive_force_normalized), float(ds.work_of_separation_normalized), ds

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # pulled off: nothing to warn of
        f, w, _ = pulled(load, Waypoint("separation"))
        for stop in (Waypoint("displacement", 24.0), Waypoint("displacement", 24.6),
                     Waypoint("force", 0.2)):
            f_split, w_split, _ = pulled(load, stop, Waypoint("separation"))
            # one more recorded point on a straight segment: round-off only
            assert f_split == pytest.approx(f, rel=1e-12) and \
                w_split == pytest.approx(w, rel=1e-12)
    with pytest.warns(UserWarning, match="last retraction ends in contact"):
        f_back, w_back, ds = pulled(load, Waypoint("displacement", 1.5), Waypoint("force", -0.5))
    branch = ds.retraction.values.astype(bool)
    legs = ds.branch.values[branch]
    assert set(legs) == {0, 1} and legs[0] == 0, legs  # the turning point, then leg 1
    d, force = ds.displacement.values, ds.force_normalized.values
    assert w_back > 0 and f_back == pytest.approx(force[branch].max(), rel=1e-12)
    assert np.all(np.diff(d[branch]) > 0)  # the final approach is not in it


def test_protocol_that_never_retracts_reports_no_pull_off(tmp_path):
    """An approach alone has no adhesive force or work of separation: NaN, not
    the largest force of the approach (it once reported 0, the first touch's)."""
    from brushcore.data.io import read_curve, write_curve

    heights = np.array([0.2, 0.0, -0.1, 0.05, 0.15, -0.2, 0.0, 0.1, -0.05])
    with pytest.warns(UserWarning, match="never retracts: adhesive_force and work"):
        ds = simulate(BrushParams("regular", 9, 0.003, 48, heights=heights),
                      protocol=[Waypoint("force", -1.0)])
    assert not ds.retraction.values.any()
    for name in ("adhesive_force_normalized", "work_of_separation_normalized",
                 "displacement_at_adhesive_force"):
        assert np.isnan(float(ds[name])), name
    assert np.isnan(ds.pillar_force_at_adhesive_force.values).all()
    assert int(ds.snapshot_step.values[-1]) == -1
    assert float(ds.force_normalized.values[-1]) == pytest.approx(-1.0, rel=1e-6)
    write_curve(ds, tmp_path / "approach.nc")
    assert np.isnan(float(read_curve(tmp_path / "approach.nc").adhesive_force))
    # Back from -1 to -0.5 F_K: a retraction, but never in tension (it gave
    # F_ad = -0.5, the least compressive force, as a "maximum tensile force").
    with pytest.warns(UserWarning) as caught:
        ds = simulate(BrushParams("regular", 9, 0.003, 48, heights=heights),
                      protocol=[Waypoint("force", -1.0), Waypoint("force", -0.5)])
    said = [str(w.message) for w in caught]
    assert any("retraction 0 stays compressive: its adhesive_force is NaN" in m
               for m in said), said
    assert not any("the largest force it reached" in m for m in said), said  # F_ad NaN
    assert ds.retraction.values.any() and float(ds.force.max()) <= 0
    assert np.isnan(float(ds.adhesive_force_normalized))
    assert float(ds.work_of_separation_normalized) == 0.0
    assert int(ds.snapshot_step.values[-1]) == -1
    write_curve(ds, tmp_path / "compressive.nc")
    assert np.isnan(float(read_curve(tmp_path / "compressive.nc").adhesive_force))


def test_empty_protocol_is_refused():
    """It was an IndexError from deep in the engine."""
    from brushcore import ParameterError

    with pytest.raises(ParameterError, match=r"^protocol=\[\] is invalid: allowed at least one"):
        simulate(FLAT, protocol=[])


def _fattened(labels: np.ndarray) -> np.ndarray:
    """``labels`` with every pillar grown by one row (the audit's t11.py)."""
    below = np.roll(labels, 1, axis=0)
    grow = (labels < 0) & (below >= 0)
    out = labels.copy()
    out[grow] = below[grow]
    return out


@pytest.mark.parametrize("params", [FLAT, replace(FLAT, roughness=0.1, preload=0.5)],
                         ids=["flat", "protocol"])
@pytest.mark.parametrize("make", [
    lambda lab, p: _fattened(lab),  # right count and shape: ran with the default hash
    lambda lab, p: np.roll(lab, 3, axis=1),
    lambda lab, p: build_labels(BrushParams("regular", 9, 0.01, p.grid)),  # failed mid-run
    lambda lab, p: lab[::2, ::2],  # failed after the whole pull-off
    lambda lab, p: lab.astype(float) + 0.5,
    lambda lab, p: [[0, 1], [2]],
], ids=["fattened", "shifted", "nine_pillars", "32x32", "float", "ragged"])
def test_a_label_map_other_than_the_parameters_own_is_refused(params, make, monkeypatch):
    from brushcore import ParameterError
    from brushcore.model import curve

    def no_solve(*args, **kwargs):
        raise AssertionError("solved before refusing the labels")
    monkeypatch.setattr(curve, "run", no_solve)
    monkeypatch.setattr(curve, "run_protocol_curve", no_solve)
    labels = make(build_labels(params), params)
    with pytest.raises(ParameterError, match=r"^labels=.* is invalid \(.*layout='file'.*\): "
                                             r"allowed None or the map build_labels\(params\)"):
        simulate(params, labels=labels)


def test_the_parameters_own_label_map_is_accepted():
    """The CLI passes the map it built and printed: same curve, same hash."""
    a = simulate(FLAT)
    b = simulate(FLAT, labels=build_labels(FLAT).astype(np.int64))
    assert float(b.adhesive_force) == float(a.adhesive_force)
    assert b.attrs["parameter_hash"] == a.attrs["parameter_hash"]


@pytest.mark.parametrize("args, kwargs, message", [
    ((FLAT, None), {}, r"^options=None is invalid: allowed a SolverOptions: SolverOptions\(\)"),
    ((FLAT, {"rtol": 1e-6}), {},
     r"^options=\{'rtol': 1e-06\} is invalid: allowed a SolverOptions"),
    ((SolverOptions(), FLAT), {}, r"^params='<SolverOptions>' is invalid: allowed a BrushParams"),
    ((FLAT,), {"protocol": Waypoint("separation")},
     (r"^protocol=Waypoint\(kind='separation', value=0.0\) is invalid \(a single Waypoint: "
      r"put it in a list\): allowed None or a list of Waypoint, e.g. \[Waypoint\('force', "
      r"-1.0\)")),
    ((FLAT,), {"protocol": [("force", -1.0), ("separation", 0.0)]},
     r"^protocol=\[\('force', -1.0\), .* \(element 0 is a tuple: write Waypoint\(kind, value\)\)"),
    ((FLAT,), {"protocol": [Waypoint("force", -1.0), {"kind": "separation"}]},
     r"^protocol=.* \(element 1 is a dict: write Waypoint"),
    ((FLAT,), {"protocol": "separation"},
     r"^protocol='separation' is invalid: allowed None or a list"),
    ((FLAT,), {"protocol": [Waypoint("force", -1e300), Waypoint("separation")]},
     r"^protocol=.* is invalid \(waypoint 0 is a force of -1e\+300 F_K\): allowed force "
     r"waypoints in \[-1000, 1000\] F_K"),  # was an rtol=1e-303 the user never set
    ((FLAT,), {"progress": 5},
     r"^progress=5 is invalid: allowed None or a function"),  # was a TypeError mid-solve
], ids=["options_none", "options_dict", "swapped", "bare_waypoint", "tuples", "dict", "str",
        "huge_force", "progress"])
def test_containers_of_the_wrong_kind_are_refused_before_any_work(args, kwargs, message,
                                                                   monkeypatch):
    """They were TypeError and AttributeError from inside simulate."""
    from brushcore import ParameterError
    from brushcore.model import curve

    def no_work(*a, **k):
        raise AssertionError("built the layout before refusing")
    monkeypatch.setattr(curve, "build_labels", no_work)
    with pytest.raises(ParameterError, match=message):
        simulate(*args, **kwargs)


def test_a_tuple_of_waypoints_is_a_protocol():
    listed = simulate(FLAT, protocol=[Waypoint("force", -0.5), Waypoint("separation")])
    tupled = simulate(FLAT, protocol=(Waypoint("force", -0.5), Waypoint("separation")))
    assert float(tupled.adhesive_force) == float(listed.adhesive_force)


# --- numerics ---------------------------------------------------------------------------

def _soft_blocks(compliance: float, seed: int, detached: float):
    """The soft 4-pillar operator with block inverses, a random ``detached``
    fraction of its elements let go; and its generator."""
    comp = np.full(4, compliance)
    op = BrushOperator(Convolver(SOFT_GRID), build_labels(_soft()), comp, 1.0, 1.0)
    rng = np.random.default_rng(seed)
    op.detach(rng.random(op.size) < detached)
    return op, rng


def _off_fresh(op: BrushOperator) -> float:
    """Largest difference of op's block inverses from ones built afresh on
    its attached set, relative to their largest entry."""
    fresh = BlockInverse(op.elements, op.pillar_of, SOFT_GRID, op.compliance, 1.0, 1.0)
    fresh.detach(np.flatnonzero(~op.attached))
    assert np.array_equal(fresh._live, op.block._live)
    return float(np.abs(op.block.inv - fresh.inv).max() / np.abs(fresh.inv).max())


@pytest.mark.parametrize("compliance", [0.0, 1e4])
def test_block_attach_equals_fresh_inverse(compliance):
    """Detaching and re-attaching elements in pieces leaves the per-pillar
    inverses of a freshly built preconditioner (soft springs included)."""
    op, rng = _soft_blocks(compliance, 0, 0.6)
    for chunk in np.array_split(rng.permutation(np.flatnonzero(~op.attached)), 5):
        op.attach(chunk)
    assert _off_fresh(op) < 1e-10


@pytest.mark.parametrize("compliance", [0.0, 1e4])
def test_bordered_attach_stays_exact_element_by_element(compliance):
    """The elastic bordering of `BlockInverse.attach` one element at a time,
    364 times with detachments in between (a contact spreading over a tip),
    keeps every block within 1e-9 of a fresh inverse (measured 1.7e-15
    rigid, 1.9e-11 at c = 1e4, where bordering G itself diverged after 4
    updates)."""
    op, rng = _soft_blocks(compliance, 1, 0.8)
    for i, e in enumerate(rng.permutation(np.flatnonzero(~op.attached))):
        op.attach(np.array([e]))
        if i % 7 == 6:  # let two go again now and then
            op.detach(np.isin(np.arange(op.size), rng.choice(op.size, 2, replace=False)))
    assert op.block._elastic, "the bordering path ran"
    assert _off_fresh(op) < 1e-9


def test_a_contact_made_on_the_approach_costs_the_same_in_any_unit_system():
    """The coarse space of a pillar that regains elements before E's next
    factorisation must not weigh it in the units of c^-1: with h in metres
    and E* in pascals the same rough brush took 18 % more applications
    (4,087 against 3,479 on 97^2, 64 pillars, the coarse space on) while
    h = E* = 1 had happened to sit near the right weight.  Now both take
    the same path: 3,445 applications."""
    runs = [simulate(BrushParams("regular", 64, 1e-2, 97, roughness=0.3, preload=2.0,
                                 h=h, e_star=e_star))
            for h, e_star in ((1.0, 1.0), (1e-6, 2e6))]
    counts = [ds.attrs["operator_applications"] for ds in runs]
    assert abs(counts[1] - counts[0]) <= 0.01 * counts[0], counts
    for name in ("adhesive_force_normalized", "work_of_separation_normalized"):
        values = [float(ds[name]) for ds in runs]
        assert values[1] == pytest.approx(values[0], rel=1e-6), name


def test_dead_pillars_take_no_coarse_weight():
    """`coarse_inverse` leaves zero rows and columns of E^-1 where a pillar
    has no elements, and inverts the rest as if they were absent."""
    c = np.array([2.0, 0.0, 3.0])
    r = np.array([[0.0, 5.0, 0.1], [5.0, 0.0, 7.0], [0.1, 7.0, 0.0]])
    e_inverse, c_inverse = coarse_inverse(c, r)
    assert not e_inverse[1].any() and not e_inverse[:, 1].any()
    live = np.array([0, 2])
    alive = np.diag(c[live]) + c[live, None] * r[np.ix_(live, live)] * c[None, live]
    assert np.allclose(e_inverse[np.ix_(live, live)], np.linalg.inv(alive), rtol=1e-12)
    assert np.array_equal(c_inverse, [0.5, 0.0, 1.0 / 3.0])


def test_positive_work_splits_zero_crossings():
    d = np.array([0.0, 1.0, 1.0, 3.0])
    f = np.array([-1.0, 1.0, -1.0, 3.0])
    # (0.5 * 0.5 * 1) + 0 + (0.5 * 1.5 * 3)
    assert positive_work(d, f) == pytest.approx(0.25 + 2.25)


def test_each_retractions_work_is_positive_work_over_its_steps():
    """What a user integrates from a curve file, `brushcore.positive_work` over a
    branch's steps (pull_first_step .. pull_last_step), is the file's W of
    that branch; clipping F at 0 before a trapezoid sum is not (a retraction
    from a preload starts with a segment through F = 0)."""
    import brushcore

    params = BrushParams("regular", 9, 0.01, 48, heights=np.linspace(-0.2, 0.2, 9))
    curve = simulate(params, protocol=[Waypoint("force", -2.0), Waypoint("displacement", 3.0),
                                       Waypoint("force", -2.0), Waypoint("separation")])
    d, f = curve.displacement.values, curve.force.values
    clipped = []
    for pull in range(curve.sizes["pull"]):
        a, b = int(curve.pull_first_step[pull]), int(curve.pull_last_step[pull])
        assert brushcore.positive_work(d[a:b + 1], f[a:b + 1]) == pytest.approx(
            float(curve.pull_work_of_separation[pull]), rel=1e-12)
        clipped.append(np.trapezoid(np.maximum(f[a:b + 1], 0.0), d[a:b + 1])
                       / float(curve.pull_work_of_separation[pull]))
    assert max(clipped) > 1.01, clipped


# --- tips, tilts and rough rigid brushes (through the Python API) --------------------

def _sphere_tip(radius: float, pillar: float, kbar: float) -> tuple[float, object]:
    """One pillar whose tip is a sphere of radius R [h] (gap map r^2 / 2R)."""
    params = punch_params(pillar, kbar=kbar)
    n = params.grid
    y, x = np.mgrid[0:n, 0:n] + 0.5 - n / 2
    _, _, curve, _ = run_protocol_curve(params, preload_protocol(theory.jkr_pull_off(radius, 1)),
                                        gap_map=(y**2 + x**2) / (2 * radius))
    return _retraction(curve)[0], curve


def test_spherical_tip_is_jkr_whatever_the_spring():
    """A sphere on a pillar: F_ad -> 1.5 pi R dgamma on a rigid mount and a soft spring.

    The criterion resolves the contact edge at pull-off, radius a_c =
    (9 pi R^2 / 8)^(1/3) h-units: 9.2 h at R = 12 h, 23 h at R = 60 h.
    Measured errors +20 %, +9.7 %, +5.7 % at R = 12, 30, 60 h: first order
    in h / a_c (error x a_c / h = 1.9, 1.4, 1.3), so the test asks for that
    order (error x a_c / h < 2) and for the error to halve from 12 h to 60 h.
    On the rigid mount (fixed grips) the contact shrinks stably past F_ad
    and then jumps off, in one cascade at a fixed d, at (5/6) pi R dgamma:
    measured 1.17 and 1.11 times that at R = 12 and 60 h (1.04 at 30 h),
    with the jump starting at a contact radius a_j of 4.1 and 11.7 elements.
    The error is again within the first-order rule (error x a_j / h = 0.70,
    0.25, 1.30; not monotone, as the ring the jump starts from is one
    element wide), so the test asks for 0 < error x a_j / h < 2.
    """
    errors = []
    for radius, pillar in ((12.0, 12.0), (60.0, 32.0)):
        rigid, curve = _sphere_tip(radius, pillar, math.inf)
        assert _sphere_tip(radius, pillar, 1e-4)[0] == pytest.approx(rigid, rel=1e-3), \
            "the spring must not matter"
        error = rigid / theory.jkr_pull_off(radius, 1.0) - 1
        a_c = (9 * math.pi * radius**2 / 8) ** (1 / 3)
        assert 0 < error * a_c < 2, (radius, error)
        errors.append(error)
        # The jump: the first step at the displacement of the last contact.
        r = curve.retraction
        d, f, el = curve.displacement[r], curve.force[r], curve.attached_elements[r]
        d_jump = d[np.flatnonzero(el > 0)[-1]]
        jump = np.flatnonzero(d == d_jump)[0]
        jump_error = f[jump] / theory.jkr_fixed_grips_pull_off(radius, 1.0) - 1
        a_j = math.sqrt(el[jump] / math.pi)
        assert 0 < jump_error * a_j < 2, (radius, jump_error, a_j)
    assert errors[1] < errors[0] / 2, errors


def _flat_punch_fields(params: BrushParams) -> dict:
    return {k: getattr(params, k) for k in ("layout", "n_pillars", "kbar", "grid", "phi")}


def test_tilted_rigid_pillar_closes_progressively_and_weakens():
    """A linear gap map across a rigid flat tip: the contact closes element by
    element on the approach, and at a fixed preload the pull-off falls with tilt."""
    base = punch_params(8)
    n = base.grid
    x = np.arange(n) + 0.5 - n / 2
    forces = []
    for tilt in (0.0, 0.02, 0.05, 0.1):  # gap per element, in d_K
        gap = np.broadcast_to(tilt * x[None, :], (n, n))
        ds = simulate(BrushParams(**_flat_punch_fields(base), preload=0.5, gap_map=gap))
        forces.append(float(ds.adhesive_force_normalized))
        # The file gives the map back in d_K, as it went in, and in metres.
        np.testing.assert_allclose(ds.gap_map_normalized.values, gap, rtol=1e-14, atol=0)
        d_k = float(ds.displacement[-1] / ds.displacement_normalized[-1])
        np.testing.assert_allclose(ds.gap_map.values, gap * d_k, rtol=1e-12, atol=0)
        approach = ds.contact_area.values[ds.direction.values <= 0]
        if tilt > 0:
            assert approach[0] < approach[-1] and np.all(np.diff(approach) >= 0)
            assert np.count_nonzero(np.diff(approach)) > 10, "contact must grow in many events"
    assert all(a > b for a, b in zip(forces, forces[1:])), forces


def test_rigid_rough_brush_loses_with_roughness_and_regains_with_preload():
    """Rigid pillars cannot absorb height differences: at a fixed preload F_ad
    falls as the roughness grows, and more preload brings pillars back into
    contact (measured 1.595, 1.551, 1.433, 1.133 for S = 0 ... 0.2 d_K;
    1.433 -> 1.496 from P = 0.5 to 2 F_K, where all 16 pillars touch)."""
    def run_(roughness, preload):
        ds = simulate(BrushParams("regular", 16, math.inf, 64, roughness=roughness,
                                  preload=preload, seed=1))
        return float(ds.adhesive_force_normalized), int(ds.pillars_in_contact_at_preload)

    by_roughness = [run_(s, 0.5)[0] for s in (0.0, 0.05, 0.1, 0.2)]
    assert all(a > b for a, b in zip(by_roughness, by_roughness[1:])), by_roughness
    low, high = run_(0.1, 0.5), run_(0.1, 2.0)
    assert high[0] > low[0] and high[1] >= low[1], (low, high)


def test_transposing_layout_and_heights_changes_nothing(tmp_path):
    from brushcore.model.layout_file import file_params, save_label_map

    params = BrushParams("regular", 16, 0.05, 64, roughness=0.2, preload=0.3, seed=4)
    path = save_label_map(build_labels(params).T, tmp_path / "transposed.npy")
    double = SolverOptions(precision="double")  # invariance up to round-off
    a = simulate(params, double)
    # the labels carry the heights (drawn from the seed, in label order)
    b = simulate(file_params(path, 0.05, roughness=0.2, preload=0.3, seed=4), double)
    for name in ("adhesive_force", "work_of_separation", "dissipated_energy"):
        assert float(b[name]) == pytest.approx(float(a[name]), rel=1e-8), name
    assert np.allclose(b.pillar_y.values, a.pillar_x.values)
    assert np.array_equal(b.pillar_height.values, a.pillar_height.values)


# --- the Python API and the command line ------------------------------------------------

def test_flat_params_with_preload_keep_todays_numbers():
    today = simulate(FLAT, SolverOptions(symmetry=False))  # protocols solve the whole grid
    ds = simulate(BrushParams("regular", 16, 0.01, 64, preload=1.5))
    for name in ("adhesive_force", "work_of_separation", "adhesive_force_normalized"):
        assert float(ds[name]) == pytest.approx(float(today[name]), rel=1e-9), name
    assert ds.attrs["operator_applications"] == today.attrs["operator_applications"]
    assert float(ds.force_normalized[ds.direction == -1].min()) == pytest.approx(-1.5)
    assert int(ds.pillars_in_contact_at_preload) == 16
    assert float(ds.pillar_force_at_adhesive_force.sum()) == pytest.approx(
        float(ds.adhesive_force), rel=1e-9)
    # defaults: today's attributes and hash, no new variables
    assert "roughness" not in today.attrs and "branch" not in today


def test_per_pillar_inputs_are_exported_in_label_order():
    kbar = np.linspace(0.01, 0.1, 16)
    heights = np.linspace(-0.2, 0.2, 16)
    ds = simulate(BrushParams("regular", 16, 0.05, 64, heights=heights, kbar_values=kbar,
                              preload=1.0))
    assert np.array_equal(ds.pillar_kbar.values, kbar)
    assert np.allclose(ds.pillar_height_normalized.values, heights, rtol=1e-12)
    pitch = 64 / 4  # pillar i * 4 + j at ((i + 1/2) pitch, (j + 1/2) pitch)
    i, j = np.divmod(np.arange(16), 4)
    assert np.allclose(ds.pillar_y.values, (i + 0.5) * pitch)
    assert np.allclose(ds.pillar_x.values, (j + 0.5) * pitch)
    assert np.all(np.isfinite(ds.pillar_let_go_displacement.values))


@pytest.mark.parametrize("params", [FLAT, BrushParams("random", 16, 0.01, 64, seed=3)],
                         ids=["regular_quadrant", "random"])
def test_flat_pull_off_exports_pillar_forces_that_sum_to_f_ad(params):
    ds = simulate(params)
    assert ds.attrs["symmetry_fold"] == (4 if params.layout == "regular" else 1)
    force = ds.pillar_force_at_adhesive_force
    assert force.dims == ("pillar",) and force.attrs["units"] == "N"
    assert np.array_equal(ds.pillar.values, np.arange(16))
    assert float(force.sum()) == pytest.approx(float(ds.adhesive_force), rel=1e-9)
    assert np.all(force.values > 0)
    assert np.all(np.isfinite(ds.pillar_let_go_displacement.values))


def test_flat_pillar_variables_are_the_protocols():
    """Same names, units and long names as a protocol's file, and the same
    values as the preloaded run (which is this pull-off on the whole grid);
    the quadrant solve unfolds them to the right pillars."""
    whole = simulate(FLAT, SolverOptions(symmetry=False))
    protocol = simulate(replace(FLAT, preload=1.5))
    folded = simulate(FLAT)
    for name in ("pillar_y", "pillar_x", "pillar_force_at_adhesive_force",
                 "pillar_let_go_displacement"):
        assert whole[name].attrs == protocol[name].attrs, name
        assert np.allclose(whole[name].values, protocol[name].values, rtol=1e-9), name
        assert np.allclose(folded[name].values, whole[name].values, rtol=1e-4), name
    assert whole.pillar.attrs == protocol.pillar.attrs
    assert whole.attrs["pillar_order"] == protocol.attrs["pillar_order"]
    # the corner pillars carry more than the middle ones (measured 26.02 and 25.16)
    force = folded.pillar_force_at_adhesive_force.values
    assert force[0] > force[5] * 1.02


@pytest.mark.parametrize("kbar, spread", [(1e-8, 1e-6), (1e-4, 1e-3)])
def test_soft_separated_pillars_share_the_load_equally(kbar, spread):
    """Springs much softer than the half space carry the load: every pillar
    of a separated soft brush pulls F_ad / N; what is left is the elastic
    coupling, of order kbar (regular 3 x 3, phi 0.05, 64^2: spread 1.1e-8
    at kbar 1e-8, 1.1e-4 at 1e-4; no mirror fold, the middle pillar crosses
    both mid-lines)."""
    ds = simulate(BrushParams("regular", 9, kbar, 64, phi=0.05))
    force = ds.pillar_force_at_adhesive_force.values
    assert ds.attrs["symmetry_fold"] == 1
    assert np.ptp(force) / force.mean() < spread
    assert force.mean() == pytest.approx(float(ds.adhesive_force) / 9, rel=1e-12)


def test_spread_draws_are_reproducible_and_have_the_asked_moments():
    from brushcore.model.draws import gaussian_heights, lognormal_kbar

    k = lognormal_kbar(0.4, 0.3, 200_000, seed=5)
    assert k.mean() == pytest.approx(0.4, rel=5e-3) and k.std() / k.mean() == pytest.approx(
        0.3, rel=1e-2)  # sampling error of 2e5 draws: ~1e-3 and ~3e-3
    assert np.array_equal(gaussian_heights(1.0, 16, 3), gaussian_heights(1.0, 16, 3))
    assert not np.array_equal(gaussian_heights(1.0, 16, 3), gaussian_heights(1.0, 16, 4))


@pytest.mark.parametrize("seed", [0, 1, 7])
def test_heights_and_stiffnesses_of_one_seed_are_independent(seed):
    """A rough, graded brush draws its heights and stiffnesses from one seed
    on two streams: drawn from one stream, tall pillars were the stiff ones
    (correlation 1; F_ad +23 %, W -24 % over six seeds of a graded rough 4 x 4
    brush, a mutation helper's figures) and no test saw it.  Independent
    draws of 4,000 correlate within 4 / sqrt(4000) = 0.063 (measured 0.014,
    -0.004, -0.006)."""
    from brushcore.model.draws import gaussian_heights, lognormal_kbar

    n = 4000
    corr = np.corrcoef(gaussian_heights(1.0, n, seed), np.log(lognormal_kbar(1.0, 0.5, n, seed)))
    assert abs(corr[0, 1]) < 4 / math.sqrt(n)


def test_the_foundation_stretch_is_a_pillars_kendall_force_over_its_spring():
    """The rough figure's soft limit: lambda = f_c / k with f_c Kendall's force
    of one pillar (radius a0 / sqrt(N)) and k = kbar E* L, in d_K; recomputed
    here in units of its own (E* 2, dgamma 3, L 1000)."""
    e_star, dgamma, side = 2.0, 3.0, 1000.0
    for n, phi, kbar in [(4, 0.12, 1e-3), (256, 0.12, 1e-4), (64, 0.05, 1e-2)]:
        a0 = side * math.sqrt(phi / math.pi)
        f_c = theory.kendall_force(a0 / math.sqrt(n), e_star, dgamma)
        d_k = theory.displacement_scale(math.pi * a0**2, e_star, dgamma)
        want = f_c / theory.stiffness_from_kbar(kbar, e_star, side) / d_k
        assert float(theory.foundation_stretch(n, phi, kbar)) == pytest.approx(want, rel=1e-12)


def test_heights_and_gaps_in_metres_are_hinted_at(tmp_path):
    """Heights of a measured brush written in metres (2e-6) read as 2e-6 d_K
    ran without a word; every value under 1e-4 d_K is now said, naming the
    unit, and heights of a real scatter are not."""
    from brushcore.model.inputs import with_input_files

    base = BrushParams("regular", 4, 0.1, 32)
    metres = tmp_path / "m.txt"
    metres.write_text("2e-6\n1e-6\n-1e-6\n0\n")
    with pytest.warns(UserWarning, match=r"heights .*m.txt: every value is under 0.0001 d_K "
                                         r"\(the largest 2e-06\); they are read in units "
                                         r"of d_K"):
        with_input_files(base, {"heights": metres})
    gaps = tmp_path / "g.npy"
    np.save(gaps, np.full((32, 32), 3e-7))
    with pytest.warns(UserWarning, match=r"gap_map .*g.npy: every value is under"):
        with_input_files(base, {"gap_map": gaps})
    real = tmp_path / "r.txt"
    real.write_text("0.3\n0\n-0.2\n0.1\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with_input_files(base, {"heights": real})


@pytest.mark.parametrize("content,flag,message", [
    ("0.1\n" * 15, "--heights", "it holds 15 values"),
    ("0.1\n" * 5 + "nan\n" + "0.1\n" * 10, "--heights", "line 6 holds nan"),
    ("0.1\n" * 15 + "0\n", "--kbar-file", "line 16 holds 0.0"),
    ("0.1\n" * 15 + "1e-11\n", "--kbar-file", "line 16 holds 1e-11"),  # under MIN_KBAR
    ("0.1\n" * 3 + "abc\n", "--kbar-file", "line 4: 'abc' is not a number"),
    ("1\n" * 15 + "0\n", "--kbar-factors", "(line 16 holds 0.0): allowed finite factors > 0"),
    ("1\n" * 15 + "inf\n", "--kbar-factors", "line 16 holds inf"),
    # 0.1 x 1e-9 falls under MIN_KBAR: the product is refused, named by the factors' file
    ("1\n" * 15 + "1e-9\n", "--kbar-factors", "(pillar 15: factor 1e-09 makes it 1e-10): "
                                              "allowed factors whose products with --kbar = 0.1 "
                                              "lie in [1e-09, inf]"),
    # a value out of range, caught by BrushParams: named by its file too
    ("0.1\n" * 15 + "1e4\n", "--heights", "(pillar 15 is 10000.0): allowed one value per"),
])
def test_cli_refuses_bad_files_before_any_work(tmp_path, capsys, content, flag, message):
    from brushcore.cli import main

    bad = tmp_path / "values.txt"
    bad.write_text(content)
    out = tmp_path / "curve.nc"
    rc = main(["simulate", "--layout", "regular", "--pillars", "16", "--kbar", "0.1",
               "--grid", "64", "--out", str(out), "--quiet", flag, str(bad)])
    err = capsys.readouterr().err
    assert rc == 2 and flag in err and str(bad) in err and message in err, err
    assert not out.exists() and list(tmp_path.iterdir()) == [bad]


def test_stiffness_factors_scale_kbar_and_leave_rigid_brushes_rigid(tmp_path, capsys):
    """--kbar-factors f is --kbar-file kbar * f; at kbar = inf every pillar
    is rigid (a brush given stiffnesses all the same, which pulls off as
    the flat rigid brush); with --kbar-file or --kbar-spread beside it the
    run is refused."""
    from brushcore.cli import main
    from brushcore.model.inputs import with_input_files

    factors = np.geomspace(0.25, 4.0, 16)
    np.savetxt(tmp_path / "f.txt", factors)
    np.save(tmp_path / "k.npy", 0.02 * factors)
    base = BrushParams("regular", 16, 0.02, 64, preload=1.0)
    scaled = with_input_files(base, {"kbar_factors": tmp_path / "f.txt"})
    given = with_input_files(base, {"kbar_file": tmp_path / "k.npy"})
    assert np.array_equal(scaled.kbar_values, given.kbar_values)
    assert scaled.given_inputs == "kbar_values" and scaled.kbar == 0.02
    rigid = with_input_files(replace(base, kbar=math.inf), {"kbar_factors": tmp_path / "f.txt"})
    assert np.all(rigid.kbar_values == math.inf) and rigid.given_inputs == "kbar_values"
    flat_rigid = simulate(replace(base, kbar=math.inf, preload=0.0))
    graded_rigid = simulate(replace(rigid, preload=0.0))  # the approach engine: same brush
    for name in ("adhesive_force_normalized", "work_of_separation_normalized"):
        assert float(graded_rigid[name]) == pytest.approx(float(flat_rigid[name]), rel=1e-6)
    args = ["simulate", "--layout", "regular", "--pillars", "16", "--kbar", "0.02", "--grid",
            "64", "--quiet", "--kbar-factors", str(tmp_path / "f.txt")]
    for extra, flag in ((["--kbar-file", str(tmp_path / "k.npy")], "--kbar-factors"),
                        (["--kbar-spread", "0.3"], "--kbar-spread")):
        assert main([*args, *extra, "--out", str(tmp_path / "no.nc")]) == 2
        assert flag in capsys.readouterr().err
    assert not (tmp_path / "no.nc").exists()


def test_value_files_are_read_as_data(tmp_path):
    """Numbers as a data file writes them, nothing Python's float() would also
    take; broken .npy files refused, not crashed on (an empty one was an
    EOFError, a .npz under a .npy name an AttributeError)."""
    from brushcore import ParameterError
    from brushcore.model.inputs import read_pillar_values

    def read(name: str, data: bytes):
        (tmp_path / name).write_bytes(data)
        return read_pillar_values(tmp_path / name, 4, "heights")

    assert read("bom.txt", b"\xef\xbb\xbf0.5\n1\n2\n3\n").tolist() == [0.5, 1, 2, 3]
    with open(tmp_path / "upper.NPY", "wb") as fh:  # np.save would append ".npy"
        np.save(fh, np.arange(4.0))
    assert read_pillar_values(tmp_path / "upper.NPY", 4, "heights").tolist() == [0, 1, 2, 3]
    for shape in ((4, 1), (1, 4)):  # a column or a row is one value a pillar too
        np.save(tmp_path / "column.npy", np.arange(4.0).reshape(shape))
        assert read_pillar_values(tmp_path / "column.npy", 4, "heights").tolist() == [0, 1, 2, 3]
    np.save(tmp_path / "square.npy", np.zeros((2, 2)))
    with pytest.raises(ParameterError, match=r"shape \(2, 2\)\): allowed 4 values, one per"):
        read_pillar_values(tmp_path / "square.npy", 4, "heights")
    for token in ("1_0", "\u0661", "0x10"):
        with pytest.raises(ParameterError, match=rf"line 1: '{token}' is not a number"):
            read("odd.txt", f"{token}\n1\n2\n3\n".encode())
    with pytest.raises(ParameterError, match=r"empty\.npy.*a readable \.npy file"):
        read("empty.npy", b"")
    np.savez(tmp_path / "archive.npz", a=np.zeros(4))
    with pytest.raises(ParameterError, match=r"archive, not one array"):
        read("archive.npy", (tmp_path / "archive.npz").read_bytes())
    # A decimal comma is two values: the count is off, and the message says why.
    with pytest.raises(ParameterError, match=r"line 1 holds 2 values;.*write decimals with a point"):
        read("comma.txt", b"0,5\n1,5\n2,5\n3,5\n")
    # columns (labels beside values, a 2 x 2 block) would pass for four values: refused
    with pytest.raises(ParameterError, match=r"line 1 holds 2 values: a file of columns"):
        read("table.txt", b"0 0.5\n1 1.5\n")
    assert read("csv.txt", b"0.5, 1.5,2.5 ,3.5\n").tolist() == [0.5, 1.5, 2.5, 3.5]
    # A count that fits does not make decimal commas right: said, where no value has a point.
    with pytest.warns(UserWarning, match=r"line 1 '0,5 1,5' is read as values that commas "
                                         r"separate, and the file has no decimal point"):
        assert read("pairs.txt", b"0,5 1,5\n").tolist() == [0, 5, 1, 5]


@pytest.mark.parametrize("flag,value", [("--preload", "-1"), ("--roughness", "-0.5"),
                                        ("--kbar-spread", "nan")])
def test_cli_refuses_negative_loads_and_spreads(tmp_path, capsys, flag, value):
    from brushcore.cli import main

    out = tmp_path / "curve.nc"
    rc = main(["simulate", "--layout", "regular", "--pillars", "16", "--kbar", "0.1",
               "--grid", "64", "--out", str(out), "--quiet", flag, value])
    assert rc == 2 and flag in capsys.readouterr().err and not out.exists()


def test_gap_map_file_shape_is_checked(tmp_path):
    from brushcore.model.inputs import read_gap_map

    np.save(tmp_path / "g.npy", np.zeros((8, 9)))
    with pytest.raises(Exception, match="shape"):
        read_gap_map(tmp_path / "g.npy", 8)
    (tmp_path / "g.txt").write_text("0 0\n0 inf\n")
    with pytest.raises(Exception, match="line 2, column 2, holds inf"):
        read_gap_map(tmp_path / "g.txt", 2)


def test_cg_carries_the_field_of_its_iterate():
    """pcg_image: the same iterate as pcg, and y = K x at every pillar element
    without applying K to x (what the engine reads the gaps from)."""
    from brushcore.numerics.linear.cg import pcg, pcg_image

    params = BrushParams("regular", 4, 0.01, 64, phi=0.2)
    op = BrushOperator(Convolver(64), build_labels(params), np.full(4, 1 / 0.64), 1.0, 1.0)
    op.detach(np.random.default_rng(1).random(op.size) < 0.3)
    b = np.linspace(1.0, 2.0, op.size)
    x0 = np.zeros(op.size)
    x, _ = pcg(op.apply, op.precondition, b, x0, 1e-10, 500)
    xi, y, _ = pcg_image(op.apply_with_field, op.precondition, b, x0, np.zeros(op.size),
                         np.zeros(op.elements.size), 1e-10, 500)
    assert np.allclose(xi, x, rtol=1e-8, atol=1e-12 * np.abs(x).max())
    assert np.allclose(y, op.field(xi), rtol=1e-9, atol=1e-12 * np.abs(y).max())


def test_rough_curve_and_sweep_are_cf_clean(tmp_path):
    """The new variables (pillar dimension, flags, NaN let-go) and the sweep's
    rough dimensions pass the same CF-1.10 check as today's files."""
    pytest.importorskip("compliance_checker")
    from test_cf import cf_errors

    from brushcore.data.aggregate import build_sweep, write_sweep
    from brushcore.data.views import flat_slice
    from brushcore.data.io import write_curve

    files = []
    for i, (roughness, preload) in enumerate(((0.0, 0.0), (0.2, 1.0), (0.0, 1.0))):
        path = tmp_path / f"c{i}.nc"
        gap = np.zeros((64, 64)) if i == 1 else None
        write_curve(simulate(BrushParams("regular", 4, 0.01, 64, roughness=roughness,
                                         preload=preload, gap_map=gap)), path)
        files.append(path)
    assert cf_errors(files[1], tmp_path) == []
    sweep = build_sweep(files, keep_snapshots=[("regular", 4)])
    assert sweep.adhesive_force.dims[-3:] == ("roughness", "preload", "kbar_spread")
    # the flat brush at preload 0 ran no approach: NaN, and the variable says why
    energy = sweep.dissipated_energy_normalized.squeeze()
    assert np.isnan(float(energy.sel(roughness=0.0, preload=0.0)))
    assert float(energy.sel(roughness=0.0, preload=1.0)) > 0
    assert "flat brush at preload 0" in energy.attrs["comment"]
    assert "flat brush at preload 0" in sweep.pillars_in_contact_at_preload.attrs["comment"]
    # the height scatter the seed drew, beside the S asked for; 0 for the flat brushes
    sd = sweep.pillar_height_sd_normalized.squeeze()
    drawn = xr.open_dataset(files[1]).pillar_height_normalized.values
    assert float(sd.sel(roughness=0.2, preload=1.0)) == pytest.approx(np.std(drawn), rel=1e-12)
    assert float(sd.sel(roughness=0.0, preload=0.0)) == 0.0
    assert float(sd.sel(roughness=0.0, preload=1.0)) == 0.0
    # d at F_ad in d_K, the curve's own normalised d at its largest force
    flat_curve = xr.open_dataset(files[0])
    d_ad = flat_curve.displacement_normalized.values[int(np.argmax(flat_curve.force.values))]
    at = sweep.squeeze().sel(roughness=0.0, preload=0.0)
    assert float(at.displacement_at_adhesive_force_normalized) == pytest.approx(d_ad, rel=1e-12)
    assert float(at.force_unit_F_K) == flat_curve.attrs["force_unit_F_K"]
    # every paper its curves cite, once; the libraries the curves ran on
    from brushcore.model.curve_format import REFERENCES, ROUGH_REFERENCE
    from brushcore.model.provenance import software_versions

    assert sweep.attrs["references"] == f"{REFERENCES}; {ROUGH_REFERENCE}"
    assert sweep.attrs["simulation_software_versions"] == software_versions()
    # beside a file of older code (the rough reference without its doi, no versions)
    older = xr.open_dataset(files[1]).load()
    older.attrs["references"] = f"{REFERENCES}; He, Li & Popov, J. Adhesion (2021)"
    del older.attrs["software_versions"]
    write_curve(older, tmp_path / "older.nc")
    mixed = build_sweep([files[0], tmp_path / "older.nc", files[2]], keep_snapshots=[])
    assert mixed.attrs["references"] == f"{REFERENCES}; {ROUGH_REFERENCE}"
    assert mixed.attrs["simulation_software_versions"] == \
        f"not recorded; {software_versions()}"
    per_case = mixed.run_software_versions.squeeze()  # which case ran on which
    assert str(per_case.sel(roughness=0.2, preload=1.0).values) == ""
    assert str(per_case.sel(roughness=0.0, preload=0.0).values) == software_versions()
    write_sweep(sweep, tmp_path / "sweep.nc")
    assert cf_errors(tmp_path / "sweep.nc", tmp_path) == []
    flat = flat_slice(sweep)  # today's four dimensions, the flat case's numbers
    assert flat.adhesive_force.dims == ("layout", "n_pillars", "kbar", "seed", "grid")
    assert float(flat.adhesive_force.squeeze()) == pytest.approx(
        float(build_sweep(files[:1]).adhesive_force.squeeze()), rel=1e-12)
    # a study that always presses on: its smallest preload stands for the flat brush,
    # whose pull-off does not depend on it (the quadrant's CG tolerance apart)
    pressed = flat_slice(build_sweep(files[1:], keep_snapshots=[("regular", 4)]))
    for name in ("adhesive_force", "work_of_separation"):
        assert float(pressed[name].squeeze()) == pytest.approx(float(flat[name].squeeze()),
                                                               rel=1e-5), name
    assert pressed.sizes["case"] == 1
    # the rough figures draw this sweep (grid dimension included): one point per roughness
    from brushcore.data import figures

    fig = figures.rough_roughness(sweep, "regular", 4)
    line = fig.axes[0].lines[0]
    assert len(line.get_xdata()) == sweep.sizes["roughness"]
    assert figures.rough_preload(sweep, "regular", 4).axes


def test_a_sweep_of_cycles_keeps_every_pull(tmp_path):
    """Curves that follow one protocol aggregate with their pulls along
    ``pull`` (NaN-padded) and the protocol as an attribute; curves of two
    protocols are refused, naming both files; the sweep is CF-clean."""
    from brushcore.data.aggregate import AggregationError, build_sweep, write_sweep
    from brushcore.data.io import write_curve

    cycles = [Waypoint("force", -1.0), Waypoint("displacement", 25.0), Waypoint("force", -1.0),
              Waypoint("separation")]
    files = []
    for kbar in (0.003, math.inf):
        files.append(tmp_path / f"k{kbar}.nc")
        write_curve(simulate(replace(ROUGH9, kbar=kbar), protocol=cycles), files[-1])
    sweep = build_sweep(files, keep_snapshots=[])
    assert sweep.attrs["protocol_normalized"] == "force:-1.0, displacement:25.0, force:-1.0, " \
        "separation"
    assert sweep.pull.values.tolist() == [0, 1] and "0 = the first" in sweep.pull.long_name
    for path in files:
        curve = xr.open_dataset(path)
        at = sweep.sel(kbar=float(curve.attrs["kbar"])).squeeze()
        for name in ("pull_adhesive_force_normalized", "pull_work_of_separation_normalized",
                     "pull_cycle_energy_normalized", "pull_contact_area_at_end"):
            assert at[name].dims == ("pull",)
            assert np.array_equal(at[name].values, curve[name].values), name
        assert float(at.dissipated_energy_normalized) == float(
            curve.dissipated_energy_normalized)
    # preload 0 is a label here: the coordinate and the preload figure say so
    assert "the protocol gives the loads" in sweep.preload.attrs["comment"]
    from brushcore.data import figures

    ax = figures.rough_preload(sweep, "regular", 9).axes[0]
    assert ax.get_xlabel() == "load of the protocol's first waypoint [$F_K$]"
    assert "last retraction of" in ax.get_title()
    xs = {float(x) for line in ax.get_lines() for x in np.ravel(line.get_xdata())}
    assert xs == {1.0}, xs  # the first waypoint's 1 F_K, not preload 0
    write_sweep(sweep, tmp_path / "sweep.nc")
    pytest.importorskip("compliance_checker")
    from test_cf import cf_errors

    assert cf_errors(tmp_path / "sweep.nc", tmp_path) == []
    other = tmp_path / "other.nc"
    write_curve(simulate(replace(ROUGH9, kbar=0.01), protocol=cycles[:2]), other)
    with pytest.raises(AggregationError, match=r"disagree on protocol_normalized.*other\.nc"):
        build_sweep([*files, other])


def test_loop_and_load_sharing_figures_show_the_curve():
    """The one-curve figures mark F_ad and the preload of the curve and sum to F_ad."""
    from brushcore.data import figures

    ds = simulate(BrushParams("regular", 16, 0.01, 64, roughness=0.5, preload=1.0, seed=1))
    fig = figures.rough_loop(ds)
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert f"= {float(ds.adhesive_force_normalized):.3g}" in labels[2]
    assert labels[3] == "preload 1 $F_K$"  # the protocol stopped at exactly the preload
    sharing = figures.load_sharing(ds)
    y = sharing.axes[0].collections[0].get_offsets()[:, 1]
    # pillar forces at F_ad add up to F_ad: the mean of F_p / (F_ad / N) is 1
    assert np.mean(y) == pytest.approx(1.0, rel=1e-6)
    flat = figures.load_sharing(simulate(FLAT))  # forces only, at height 0
    assert np.mean(flat.axes[0].collections[0].get_offsets()[:, 1]) == pytest.approx(1.0)


def test_large_loads_tighten_the_tolerance():
    """Roughness and preload of 1000 units: CG's rtol, relative to stresses
    1000 times a pull-off's, gave F_ad 12 % high and a negative dissipated
    energy (-74 W_K) at the default.  The loop energy is a difference of
    integrals ~X^2 W_K, so the protocol's rtol shrinks as (10 / X)^2
    (`solve.load_options`); shrinking it as 10 / X left it 29 % low on seed
    5 (2.7 % on seed 3, the one this test had run).  Over seeds 0-7 both
    now agree with rtol 1e-10: F_ad within 1e-4 (4.6e-6 measured), the loop
    energy within 2 % (5.4e-3 measured).  Loads of 10 units and less keep
    the rtol asked for; the scaled rtol stops at MIN_RTOL."""
    from brushcore.model.solve import LOAD_SPAN, load_options

    for seed in range(8):
        params = BrushParams("regular", 16, math.inf, 64, roughness=1000.0, preload=1000.0,
                             seed=seed)
        ds = simulate(params)
        ref = simulate(params, SolverOptions(rtol=1e-10))
        assert float(ds.adhesive_force_normalized) == pytest.approx(
            float(ref.adhesive_force_normalized), rel=1e-4), seed
        assert float(ds.dissipated_energy_normalized) == pytest.approx(
            float(ref.dissipated_energy_normalized), rel=0.02), seed
        assert float(ds.dissipated_energy_normalized) > 0
        assert ds.attrs["rtol"] <= 1e-8 * (1 + 1e-9)  # what ran is recorded
    assert load_options(SolverOptions(), LOAD_SPAN) == SolverOptions()
    assert load_options(SolverOptions(rtol=1e-10), 1e3).rtol == SolverOptions.MIN_RTOL
    assert load_options(SolverOptions(precision="mixed"), 1e4).rtol == 1e-6


def test_loads_a_displacement_or_a_gap_map_reaches_tighten_the_tolerance():
    """A protocol pressed by a displacement, or heights given as a gap map,
    reaches loads no force waypoint announces: the tolerance follows what
    the run reached (run again, said) and the gap map's scatter.  Rigid 16
    pillars, roughness 5 d_K, pressed to 1000 F_K (64^2): the dissipated
    energy was 0.6662 by displacement at rtol 1e-4 against 0.6358 by force
    (rtol 1e-8); the README's roughness-300 case given as a gap map and a
    displacement waypoint gave -11.97 W_K for +0.398 (an input helper's
    probes, 2026-12-07)."""
    params = BrushParams("regular", 16, math.inf, 64, roughness=5.0, seed=0)
    with warnings.catch_warnings():  # a force waypoint's load is known before: no rerun
        warnings.simplefilter("error", UserWarning)
        force = simulate(params, protocol=[Waypoint("force", -1000.0), Waypoint("separation")])
    turn = float(force.displacement_normalized.values[int(np.argmin(force.force.values))])
    with pytest.warns(UserWarning, match="reached a load of 1e[+]03 F_K.*run again at rtol 1e-08"):
        pressed = simulate(params, protocol=[Waypoint("displacement", turn),
                                             Waypoint("separation")])
    assert pressed.attrs["rtol"] == pytest.approx(force.attrs["rtol"], rel=1e-6)
    assert force.attrs["rtol"] == pytest.approx(1e-8)
    # the cost counts both runs (the first at rtol 1e-4), as the wall time does
    assert pressed.attrs["operator_applications"] > 1.05 * force.attrs["operator_applications"]
    assert float(pressed.dissipated_energy_normalized) == pytest.approx(
        float(force.dissipated_energy_normalized), rel=1e-3)
    # the same offsets as a gap map: their scatter sets the tolerance before the run
    heights = force.pillar_height_normalized.values
    labels = build_labels(params)
    gap = np.where(labels >= 0, -heights[np.maximum(labels, 0)], 0.0) * 60.0
    mapped = simulate(BrushParams("regular", 16, math.inf, 64, gap_map=gap),
                      protocol=[Waypoint("force", -1.0), Waypoint("separation")])
    assert np.std(gap[labels >= 0]) > 100.0
    assert mapped.attrs["rtol"] < 1e-4 * (10.0 / 100.0) ** 2


def test_given_heights_and_springs_reach_their_own_pillars():
    """Per-pillar inputs through the public API land on their pillars (label
    order) with the right units: a soft pillar lets go once its spring
    carries f_c, at d = f_c / k_i + its height (in d_K).

    Heights 0, 20, 40, 60 d_K at equal kbar 1e-2: successive let-go
    displacements 20.69, 20.71, 20.28 d_K apart (measured; the pillars'
    elastic interaction moves each f_c / k = 9 d_K a little), 5 % allowed.
    Stiffness k, 2k, 4k, 8k at equal heights: the gaps halve, f_c (1/k_i -
    1/k_j), 2.03 and 1.99 measured, 4 % allowed.  Reversed inputs, or heights
    off by a factor, fail both."""
    k = 1e-2
    heights = BrushParams("regular", 4, k, 128, phi=0.05, preload=20.0,
                          heights=np.array([0.0, 20.0, 40.0, 60.0]))
    ds = simulate(heights)
    d_k = float(ds.displacement[1] / ds.displacement_normalized[1])  # the curve's own d_K
    gaps = np.diff(ds.pillar_let_go_displacement.values) / d_k
    assert gaps == pytest.approx([20.0] * 3, rel=0.05), gaps
    springs = BrushParams("regular", 4, 1e-4, 128, phi=0.05, preload=0.1,
                          kbar_values=np.array([1e-4, 2e-4, 4e-4, 8e-4]))
    let_go = simulate(springs).pillar_let_go_displacement.values
    gaps = -np.diff(let_go)
    assert gaps[0] / gaps[1] == pytest.approx(2.0, rel=0.04), gaps
    assert gaps[1] / gaps[2] == pytest.approx(2.0, rel=0.04), gaps


def test_a_near_tie_inside_a_cascade_follows_exact_mode():
    """Graded 4 x 4 brush at kbar 1e-4, preloaded: during one pillar's cascade
    a neighbour comes within 9.7e-5 of sigma_c, under CG's error at the
    default tolerance (1e-4 of the largest stress, 3.9 sigma_c there).  The
    cascade's solves are settled against sigma_c and the events taken from
    the stresses corrected by their error estimates, so the neighbour stays,
    as in exact mode and an independent dense solver (W 885.92857): with
    neither it let go 2 % of d early (472 events, W 2.9e-3 off), with the
    settled cascade alone W was 1.7e-6 off and F_ad 2.6e-6 (2026-12-07)."""
    heights = np.random.default_rng(5).normal(0.0, 0.5, 16)  # [d_K]
    params = BrushParams("regular", 16, 1e-4, 64, heights=heights, preload=2.0)
    got, want = simulate(params), simulate(params, EXACT)
    for name in ("work_of_separation_normalized", "adhesive_force_normalized"):
        assert abs(float(got[name]) / float(want[name]) - 1.0) < 1e-6, name
    assert got.attrs["events"] == want.attrs["events"] == 473


def test_an_event_is_taken_where_the_model_puts_it_not_cg():
    """A gap map ramped along y (0.02 d_K an element, kbar 0.01, preload
    F_K, 48^2): the event a retraction cascade starts at was 7.5e-5 of d
    early with the stresses as CG left them (their error builds up along
    the approach, whose attachments re-solve only sigma_1), and the cascade
    split in two: 138 events against exact mode's and an independent dense
    solver's 137, F_ad and W 1.1e-5 off.  Corrected by the residual's error
    estimate the event falls where exact mode's does."""
    ramp = 0.02 * np.arange(48.0)[:, None] * np.ones((1, 48))  # [d_K]
    params = BrushParams("regular", 4, 0.01, 48, gap_map=ramp, preload=1.0)
    got, want = simulate(params), simulate(params, EXACT)
    assert got.attrs["events"] == want.attrs["events"] == 137
    for name in ("work_of_separation_normalized", "adhesive_force_normalized"):
        assert abs(float(got[name]) / float(want[name]) - 1.0) < 5e-6, name


def test_a_preload_just_short_of_a_gap_closing_leaves_it_open():
    """A 2 x 2 brush of unequal heights (kbar 1e-2, 41^2) pressed to 1 - 1e-6
    of the force at which its 208th element touches on the approach: the
    preload comes first, so 207 elements hold it and F_ad is that contact's
    (1 % under the 208's).  At CG's tolerance the gap's closing and the
    target were 3e-6 apart in force, and the element attached (an
    independent dense solver found it); an event and a target closer than
    the tolerance are now decided on tighter solves."""
    params = BrushParams("regular", 4, 1e-2, 41, heights=[0.0, 0.3, -0.2, 0.1])
    pressed = simulate(params, EXACT, protocol=[Waypoint("force", -2.0),
                                                Waypoint("separation")])
    area, force = pressed.contact_area.values, pressed.force_normalized.values
    touch = int(np.flatnonzero((area[:-1] == 207.0) & (area[1:] == 208.0))[0]) + 1
    preload = -float(force[touch]) * (1.0 - 1e-6)  # [F_K]
    want = simulate(replace(params, preload=preload), EXACT)
    got = simulate(replace(params, preload=preload))
    assert float(want.contact_area_at_preload) == float(got.contact_area_at_preload) == 207.0
    assert abs(float(got.adhesive_force_normalized)
               / float(want.adhesive_force_normalized) - 1.0) < 1e-6


def test_mirror_images_reach_sigma_c_together():
    """A 4 x 4 brush of unequal heights (kbar 1e-3, 56^2, preload F_K) whose
    last pillars let go in pairs of mirror images, equal stresses to 1e-13:
    at CG's tolerance one of a pair reached sigma_c first, its cascade then
    took another course, and W was 2.4e-3 off exact mode (360 events against
    361; an independent dense solver agrees with exact mode).  Elements
    within their error margin of the event's are solved tighter until the
    tie is decided; without settling (the control) the pair still splits, so
    the tie is real and settling is what decides it."""
    heights = np.random.default_rng(72).normal(0.0, 0.3, 16)  # [d_K]
    params = BrushParams("regular", 16, 1e-3, 56, heights=heights, preload=1.0)
    got, want = simulate(params), simulate(params, EXACT)
    unsettled = simulate(params, SolverOptions(settle_decisions=False))
    w = float(want.work_of_separation_normalized)
    assert got.attrs["events"] == want.attrs["events"] == 361
    assert abs(float(got.work_of_separation_normalized) / w - 1.0) < 1e-6
    assert abs(float(unsettled.work_of_separation_normalized) / w - 1.0) > 1e-3


def test_a_tensile_target_beyond_the_pull_off_is_said():
    """force:5 on a brush that lets go at 1.60 F_K ends its leg at separation
    (the Waypoint's rule), said in a warning; a reachable force:1 is not;
    the integral of F dd is labelled as stored energy besides the losses
    where a protocol ends in contact (an energy auditor's finds)."""
    params = BrushParams("regular", 16, 0.01, 64, roughness=0.3)

    def run(target: float, end: tuple[Waypoint, ...] = (Waypoint("separation"),)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            ds = simulate(params, protocol=[Waypoint("force", -2.0), Waypoint("force", target),
                                            Waypoint("force", -2.0), *end])
        return ds, [str(w.message) for w in caught]

    far, said = run(5.0)
    assert any("waypoint 1 (force:5) was not reached: the brush let go first" in w
               for w in said), said
    assert float(far.force_normalized[int(far.snapshot_step[1])]) == 0.0  # at separation
    assert float(far.adhesive_force_normalized) < 5.0
    near, said = run(1.0)
    assert not any("was not reached" in w for w in said), said
    assert float(near.force_normalized[int(near.snapshot_step[1])]) == pytest.approx(1.0)
    assert "ends in contact adds the elastic energy" in far.dissipated_energy.attrs["comment"]
    # a leg that starts apart has nothing to let go of: not said (a diff reviewer's find)
    _, said = run(-2.0, (Waypoint("separation"), Waypoint("force", 0.05)))
    assert not any("was not reached" in w for w in said), said


def test_the_soft_limit_line_is_drawn_only_where_springs_take_the_stretch():
    """The rough figure's elastic-foundation line N^(1/4) G(S d_K / lambda)
    holds where a pillar's let-go stretch lambda dwarfs the half space's own
    displacement at F_ad (0.72-0.77 d_K): regular 256 at kbar 0.01 (lambda
    0.61 d_K) lay 1.6x below it at S = 0 and 3.5x above it at S = 1 (a
    review helper's check of the shipped rough config), and the line was
    drawn for every kbar <= 0.01 whatever N.  Now at lambda >= 3 d_K only:
    kbar 1e-3 (lambda 6.1) is drawn, 0.01 and 0.455 are not, for N = 256;
    for N = 16, kbar 0.01 (lambda 4.9) is drawn."""
    from brushcore.data import figures
    from brushcore.data.figures.rough import MIN_FOUNDATION_STRETCH

    def sweep(n_pillars: int) -> xr.Dataset:
        kbars = [0.001, 0.01, 0.455, math.inf]
        rough = [0.0, 0.3, 1.0]
        shape = (1, 1, len(kbars), 1, len(rough), 1, 1)
        dims = ("layout", "n_pillars", "kbar", "seed", "roughness", "preload", "kbar_spread")
        values = np.linspace(3.0, 1.0, np.prod(shape)).reshape(shape)
        return xr.Dataset(
            {"adhesive_force_normalized": (dims, values),
             "phi_actual": (dims, np.full(shape, 0.12))},
            coords={"layout": ["regular"], "n_pillars": [n_pillars], "kbar": kbars,
                    "seed": [0], "roughness": rough, "preload": [0.5], "kbar_spread": [0.0]},
            attrs={"phi": 0.12})

    for n_pillars, drawn in ((256, {0.001}), (16, {0.001, 0.01})):
        fig = figures.rough_roughness(sweep(n_pillars), "regular", n_pillars)
        ax = fig.axes[0]
        dashed = {line.get_color() for line in ax.lines  # not the legend's empty key
                  if line.get_linestyle() == "--" and len(line.get_xdata())}
        kbar_of = {c.get_label(): c for c in ax.containers}  # errorbars, by their legend
        colors = {float(label.split("= ")[1].replace("$", "").replace("rigid", "inf")):
                  container.lines[0].get_color() for label, container in kbar_of.items()}
        want = {colors[k] for k in drawn}
        assert dashed == want, (n_pillars, dashed, colors)
        for k in drawn:
            assert float(theory.foundation_stretch(n_pillars, 0.12, k)) >= MIN_FOUNDATION_STRETCH
    # rough_preload's panels (one per roughness) share one y range (they did
    # not: 0.6-1.8 beside 1.6-1.8, the figures referee's find)
    panels = figures.rough_preload(sweep(256), "regular", 256).axes[:3]
    assert len({ax.get_ylim() for ax in panels}) == 1, [ax.get_ylim() for ax in panels]


def test_rough_roughness_draws_each_seed_at_its_drawn_height_spread():
    """`rough_roughness` drew F_ad at the roughness S asked for alone, though a
    brush of few pillars draws far from it (16 at S = 1: 1.23 and 0.52 for
    two seeds), so part of a seed bar was that scatter (the figures
    referee's find).  Each seed is now also an open marker at the SD of its
    heights as drawn (`pillar_height_sd_normalized`), under a key and an x
    label that say which is which; a sweep without the SD draws as before."""
    from brushcore.data import figures
    from brushcore.data.aggregate import HEIGHT_SD
    from brushcore.data.figures.rough import DRAWN_SPREAD_LABEL

    dims = ("layout", "n_pillars", "kbar", "seed", "roughness", "preload", "kbar_spread")
    force = np.array([[2.0, 2.0], [1.5, 1.3], [0.6, 0.4]]).T.reshape(1, 1, 1, 2, 3, 1, 1)
    drawn = np.array([[0.0, 0.0], [0.37, 0.16], [1.23, 0.52]]).T.reshape(force.shape)
    sweep = xr.Dataset({"adhesive_force_normalized": (dims, force), HEIGHT_SD: (dims, drawn)},
                       coords={"layout": ["regular"], "n_pillars": [16], "kbar": [math.inf],
                               "seed": [0, 1], "roughness": [0.0, 0.3, 1.0], "preload": [0.5],
                               "kbar_spread": [0.0]}, attrs={"phi": 0.12})

    def open_points(fig) -> set[tuple[float, float]]:
        return {(round(float(x), 9), float(y)) for line in fig.axes[0].lines
                if line.get_markerfacecolor() == "none"
                for x, y in zip(line.get_xdata(), line.get_ydata())}

    fig = figures.rough_roughness(sweep, "regular", 16)
    assert open_points(fig) == {(s, f) for s, f in zip(drawn.ravel(), force.ravel())}
    assert DRAWN_SPREAD_LABEL in [t.get_text() for t in fig.legends[0].get_texts()]
    assert "as drawn (open)" in fig.axes[0].get_xlabel()
    assert [float(x) for x in fig.axes[0].containers[0].lines[0].get_xdata()] == [0.0, 0.3, 1.0]
    before = figures.rough_roughness(sweep.drop_vars(HEIGHT_SD), "regular", 16)
    assert open_points(before) == set() and before.axes[0].get_xlabel() == r"roughness $S$ [$d_K$]"


def test_rough_loop_keys_the_colours_of_its_contact_maps():
    """`rough_loop`'s contact maps had no colour key, where Fig. 5's have one
    (the figures referee's find); and their grey is not "detached" alone: at
    the preload of a rough brush it is a pillar that never touched.  The key
    names both colours, and with several cycles the loop's key says that
    colour is the branch (approach, retraction) of every cycle."""
    from brushcore.data import figures
    from brushcore.data.figures.common import SNAPSHOT_CMAP
    from matplotlib.colors import to_rgba

    ds = simulate(BrushParams("regular", 9, 0.455, 48, roughness=1.0, preload=0.2))
    at_preload = ds.contact_snapshot.values[0]
    assert (at_preload == 0).any() and (at_preload == 1).any()  # short pillars never touched
    fig = figures.rough_loop(ds)
    assert len(fig.legends) == 1, fig.legends
    key = {t.get_text(): to_rgba(h.get_facecolor())
           for t, h in zip(fig.legends[0].get_texts(), fig.legends[0].legend_handles)}
    assert key == {"attached": to_rgba(SNAPSHOT_CMAP(2)),
                   "not in contact (detached or never touched)": to_rgba(SNAPSHOT_CMAP(1))}
    loop = [t.get_text() for t in fig.axes[0].get_legend().get_texts()][:2]
    assert loop == ["approach", "retraction"]  # one cycle
    cycles = simulate(ROUGH9, protocol=[Waypoint("force", -0.5), Waypoint("separation"),
                                        Waypoint("force", -1.0), Waypoint("separation")])
    loop = [t.get_text() for t in figures.rough_loop(cycles).axes[0].get_legend().get_texts()]
    assert loop[:2] == ["approaches (every cycle)", "retractions (every cycle)"], loop


# --- The stiffness spread C (kbar_spread) in the figures and the summary -------------------

SPREAD_DIMS = ("layout", "n_pillars", "kbar", "seed", "roughness", "preload", "kbar_spread")


def _spread_sweep(spreads=(0.0, 0.25, 0.5)) -> xr.Dataset:
    """A synthetic graded sweep: regular 16, kbar 1e-3, 0.1 and rigid, two
    seeds, roughness 0 and 0.3, preload 0.5, the spreads given; as the
    workflow runs it: rigid pillars at C = 0 alone, the flat lattice
    (S = 0, C = 0) seed 0 alone, and seed 1 of kbar 0.1 at S = 0, C = 0.5
    missing (a failed job)."""
    kbars, seeds, roughs = [1e-3, 0.1, math.inf], [0, 1], [0.0, 0.3]
    shape = (1, 1, len(kbars), len(seeds), len(roughs), 1, len(spreads))
    force = (2.0 - np.arange(np.prod(shape)).reshape(shape) % 17 * 0.05)
    for i, kbar in enumerate(kbars):
        for j, spread in enumerate(spreads):
            if math.isinf(kbar) and spread > 0:
                force[0, 0, i, :, :, 0, j] = np.nan
            if spread == 0:
                force[0, 0, i, 1, 0, 0, j] = np.nan
    if 0.5 in spreads:
        force[0, 0, 1, 1, 0, 0, spreads.index(0.5)] = np.nan
    return xr.Dataset(
        {"adhesive_force_normalized": (SPREAD_DIMS, force),
         "phi_actual": (SPREAD_DIMS, np.full(shape, 0.12))},
        coords={"layout": ["regular"], "n_pillars": [16], "kbar": kbars, "seed": seeds,
                "roughness": roughs, "preload": [0.5], "kbar_spread": list(spreads)},
        attrs={"phi": 0.12})


def test_lognormal_stiffness_pull_off_is_the_foundation_of_the_drawn_stiffnesses():
    """F_ad of equal-height soft pillars of lognormal stiffness (mean k, CV
    C: `lognormal_kbar`, the kbar_spread): each lets go at its own stretch
    f_c / k_i, stiffest first, so F / (N f_c) = max_x x Phi((-ln x -
    sigma^2/2) / sigma).  It matches the exact discrete formula
    (`foundation_pull_off`) of 2e5 draws (sorted: O(N log N)) to 2e-3, is 1
    at C = 0 and falls with C; `drawn_stiffness_pull_off` is that formula
    of a seed's own draws, and the solver's soft brush (regular 16, kbar
    1e-4, lambda 490 d_K, 64^2) lies within its flat brush's distance from
    N^(1/4) (the half space's interaction, 9 %) of it."""
    from brushcore.model.draws import lognormal_kbar

    spreads = (0.1, 0.25, 0.5, 1.0)
    closed = theory.lognormal_stiffness_pull_off(np.array(spreads))
    assert theory.lognormal_stiffness_pull_off(0.0) == 1.0
    assert np.all(np.diff(closed) < 0) and closed[0] < 1.0
    for spread, value in zip(spreads, closed):
        k = np.sort(lognormal_kbar(1.0, spread, 200_000, 3))[::-1]  # stiffest lets go first
        held = np.cumsum(k[::-1])[::-1]  # the force / d of the pillars still held
        assert value == pytest.approx((held / k).max() / k.size, abs=2e-3), spread
    few = lognormal_kbar(1.0, 0.5, 16, 0)
    assert theory.drawn_stiffness_pull_off(16, 0.5, [0]) == pytest.approx(
        theory.foundation_pull_off(np.zeros(16), few, 1.0) / 16, rel=1e-12)
    flat = float(simulate(BrushParams("regular", 16, 1e-4, 64)).adhesive_force_normalized)
    interaction = 1.0 - flat / float(theory.soft_limit(16))
    assert 0 < interaction < 0.1, flat
    assert float(theory.foundation_stretch(16, 0.12, 1e-4)) > 100  # the springs take it all
    for spread, seed in ((0.25, 0), (0.5, 0), (0.5, 1)):
        ds = simulate(BrushParams("regular", 16, 1e-4, 64, kbar_spread=spread, seed=seed))
        model = float(theory.soft_limit(16)) * theory.drawn_stiffness_pull_off(16, spread, [seed])
        assert float(ds.adhesive_force_normalized) / model == pytest.approx(
            1.0, abs=interaction), (spread, seed)


def test_rough_spread_draws_the_sweep_against_the_stiffness_spread():
    """The stiffness spread C reached no figure (the rough ones select C = 0).
    `rough_spread` draws F_ad against C per kbar, a panel per roughness: the
    seed mean with min-max bars, hollow where fewer seeds ran than the brush
    did (not the flat lattice's seed 0 alone), and on equal heights the soft
    limit N^(1/4) G(C) (dashed) and that of the seeds' own stiffnesses
    (dotted), only where a kbar's let-go stretch is at least 3 d_K; a sweep
    of C = 0 alone draws a placeholder."""
    from brushcore.data import figures
    from brushcore.data.figures.paper import FEWER_SEEDS_LABEL
    from brushcore.data.figures.rough import SEED_LIMIT_LABEL, SPREAD_LIMIT_LABEL

    sweep = _spread_sweep()
    fig = figures.rough_spread(sweep, "regular", 16)
    flat, rough = fig.axes[:2]
    assert "roughness 0 " in flat.get_title() and "roughness 0.3 " in rough.get_title()
    assert len({ax.get_ylim() for ax in (flat, rough)}) == 1  # read against each other
    for ax, s in ((flat, 0.0), (rough, 0.3)):
        for container in ax.containers:
            kbar = float(container.get_label().split("= ")[1].replace("$", "")
                         .replace("rigid", "inf"))
            runs = sweep.adhesive_force_normalized.sel(kbar=kbar, roughness=s).squeeze()
            mean = runs.mean("seed").values
            ran = np.isfinite(mean)
            x, y = container.lines[0].get_data()
            assert np.array_equal(x, sweep.kbar_spread.values[ran]), kbar
            np.testing.assert_allclose(y, mean[ran], rtol=1e-12)
            bars = container.lines[2][0].get_segments()  # min-max over the seeds
            np.testing.assert_allclose([b[:, 1] for b in bars], np.stack(
                [runs.min("seed").values[ran], runs.max("seed").values[ran]], axis=1))
        assert [c.get_label() for c in ax.containers][-1] == r"$\bar k$ = rigid"
    hollow = [(line.get_xdata().tolist(), line.get_ydata().tolist()) for line in flat.lines
              if line.get_markerfacecolor() == "white" and len(line.get_xdata())]
    half = float(sweep.adhesive_force_normalized.sel(kbar=0.1, roughness=0.0, seed=0,
                                                     kbar_spread=0.5).squeeze())
    assert hollow == [([0.5], [half])], hollow  # seed 1 missing; not C = 0's seed 0 alone
    dashed = [line for line in flat.lines if line.get_linestyle() == "--" and
              len(line.get_xdata())]
    dotted = [line for line in flat.lines if line.get_linestyle() == ":" and
              len(line.get_xdata())]
    assert len(dashed) == len(dotted) == 1  # kbar 1e-3 (lambda 49 d_K) alone: one limit
    x, y = dashed[0].get_data()
    np.testing.assert_allclose(y, 2.0 * theory.lognormal_stiffness_pull_off(x), rtol=1e-12)
    x, y = dotted[0].get_data()
    np.testing.assert_allclose(
        y, [2.0 * theory.drawn_stiffness_pull_off(16, c, [0, 1]) for c in x], rtol=1e-12)
    assert not [line for line in rough.lines if line.get_linestyle() in ("--", ":")
                and len(line.get_xdata())]  # unequal heights: not the closed form's case
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert {SPREAD_LIMIT_LABEL, SEED_LIMIT_LABEL, FEWER_SEEDS_LABEL} <= set(labels), labels
    soft = _spread_sweep().sel(kbar=[0.1, math.inf])  # lambda 0.49 d_K: no soft limit
    assert not [line for line in figures.rough_spread(soft, "regular", 16).axes[0].lines
                if line.get_linestyle() == "--"]
    flat_only = figures.rough_spread(_spread_sweep((0.0,)), "regular", 16)
    assert [t.get_text() for t in flat_only.axes[0].texts] == [
        "no stiffness spread in this sweep\n(kbar_spread: 0)"]
    one = figures.rough_spread(_spread_sweep((0.5,)), "regular", 16)  # one C > 0: drawn
    assert one.axes[0].containers and not one.axes[0].texts


def test_rough_figures_draw_the_smallest_spread_when_0_did_not_run():
    """`kbar_spread: [0.5]` alone made every rough figure a "no rough runs"
    placeholder (they selected C = 0).  They now draw the smallest C that
    ran and say so in their title."""
    from brushcore.data import figures

    sweep = _spread_sweep((0.25, 0.5))
    for name in ("rough_roughness", "rough_preload"):
        fig = getattr(figures, name)(sweep, "regular", 16)
        assert not fig.axes[0].texts, name
        title = " ".join(fig._suptitle.get_text().split())  # wrapped to the figure's width
        assert "stiffness spread C = 0.25 (the smallest run)" in title, title
        ys = {float(y) for ax in fig.axes for c in ax.containers
              for y in np.ravel(c.lines[0].get_ydata())}
        want = sweep.adhesive_force_normalized.sel(kbar_spread=0.25).mean("seed").values
        assert ys == {float(v) for v in np.ravel(want) if np.isfinite(v)}, name
        # the Gaussian-heights soft limit assumes equal stiffness: not drawn at C > 0
        assert not [line for ax in fig.axes for line in ax.lines
                    if line.get_linestyle() == "--" and len(line.get_xdata())], name
    # rough_preload's shared y range holds every panel's points: the zoom guard
    # ran on the first panel alone and fixed the range to its 1.47-1.54, which
    # cut off roughness 0.5's 0.97 (a run of regular 16 at C = 0.25)
    narrow = sweep.sel(kbar=[1e-3, 0.1]).copy(deep=True)
    narrow["adhesive_force_normalized"][:] = np.reshape([1.488, 1.493, 1.538, 0.972], (
        1, 1, 2, 1, 2, 1, 1))
    for fig in (figures.rough_preload(narrow, "regular", 16),
                figures.rough_spread(narrow, "regular", 16)):
        for ax in fig.axes[:2]:
            low, high = ax.get_ylim()
            ys = [float(y) for c in ax.containers for y in np.ravel(c.lines[0].get_ydata())]
            assert ys and all(low <= y <= high for y in ys), (ys, low, high)
    fig = figures.rough_roughness(_spread_sweep(), "regular", 16)  # C = 0 ran: as before
    assert "spread" not in fig._suptitle.get_text()
    assert [line for line in fig.axes[0].lines
            if line.get_linestyle() == "--" and len(line.get_xdata())]  # kbar 1e-3's limit


def test_rough_roughness_does_not_zoom_into_rounding():
    """With one roughness value rough_roughness's y axis read
    "1e-12+1.354190643" (matplotlib's autoscale of two F_ad equal to
    rounding); it takes `_no_false_zoom` as rough_preload does."""
    from brushcore.data import figures

    sweep = _spread_sweep((0.0,)).sel(roughness=[0.0], kbar=[0.1, math.inf])
    sweep["adhesive_force_normalized"][:] = 1.354190643 + np.array(
        [0.0, 1e-12]).reshape(1, 1, 2, 1, 1, 1, 1)
    ax = figures.rough_roughness(sweep, "regular", 16).axes[0]
    ax.figure.canvas.draw()
    low, high = ax.get_ylim()
    assert high - low >= 0.049 * 1.354190643, (low, high)
    assert ax.yaxis.get_offset_text().get_text() == ""


def test_one_curve_figures_state_the_spread_and_the_preload():
    """`rough_loop` and `load_sharing` named kbar and roughness alone: a
    graded, preloaded curve read as the flat one.  Both titles now state
    the stiffness spread C and the preload (the first load of a protocol)."""
    from brushcore.data import figures

    ds = simulate(BrushParams("regular", 9, 0.01, 48, kbar_spread=0.5, preload=1.0, seed=1))
    loop = figures.rough_loop(ds)._suptitle.get_text()
    sharing = figures.load_sharing(ds).axes[0].get_title()
    for title in (loop, sharing):
        assert "stiffness spread C = 0.5" in title and "preload 1 $F_K$" in title, title
        assert "roughness 0 $d_K$" in title and "seed 1" in title, title
    legend = [t.get_text() for t in figures.rough_loop(simulate(FLAT)).axes[0].get_legend()
              .get_texts()]
    assert "preload 0 $F_K$" in legend, legend  # not "preload -0"
    protocol = simulate(ROUGH9, protocol=[Waypoint("force", -0.5), Waypoint("separation")])
    title = figures.rough_loop(protocol)._suptitle.get_text()
    assert "first load 0.5 $F_K$" in title and "spread" not in title, title


def test_the_summary_has_a_row_per_graded_case():
    """The summary selected C = 0 (`flat_slice`): every graded case vanished
    from it.  Now a row per brush, kbar, roughness and C > 0 gives its seed
    mean, the C = 0 value, and on equal heights of a soft brush the soft
    limits N^(1/4) G(C) and of the seeds' own stiffnesses."""
    from brushcore.data.summary import headline_rows

    sweep = _spread_sweep()
    rows = [r for r in headline_rows(sweep, fig5_n_pillars=16) if "spread" in r.quantity]
    # kbar 1e-3 and 0.1 (rigid runs C = 0 alone) x S 0, 0.3 x C 0.25, 0.5
    assert len(rows) == 8, [r.quantity for r in rows]
    force = sweep.adhesive_force_normalized
    for row in rows:
        rough = 0.3 if "roughness 0.3" in row.quantity else 0.0
        spread = float(row.quantity.split("C = ")[1].split(",")[0])
        runs = force.sel(kbar=float(row.kbar), roughness=rough, kbar_spread=spread).squeeze()
        assert row.value == f"{float(runs.mean('seed')):.3g}", row
        flat = force.sel(kbar=float(row.kbar), roughness=rough, kbar_spread=0.0)
        assert f"C = 0: {float(flat.mean('seed').squeeze()):.3g}" in row.note, row
        soft = float(row.kbar) == 1e-3 and rough == 0.0
        assert ("soft limit" in row.note) == soft, row
        if soft:
            limit = 2.0 * theory.lognormal_stiffness_pull_off(spread)
            assert f"N^1/4 G(C) = {limit:.3g}" in row.note, row
        assert row.note.endswith("preload 0.5 F_K"), row  # the smallest preload ran
    assert not [r for r in headline_rows(_spread_sweep((0.0,)), fig5_n_pillars=16)
                if "spread" in r.quantity]
