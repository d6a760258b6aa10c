"""The solver against contact-mechanics theory and the paper's limits."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import full_contact_stiffness, punch_params

from brushcore import BrushParams, SolverOptions, simulate, theory
from brushcore.model.solve import run
from brushcore.model.layout import build_labels


def _a0(ds) -> float:
    return theory.equivalent_radius(ds.attrs["real_contact_area"])


@pytest.fixture(scope="module")
def rigid_punches():
    return {a: simulate(punch_params(a)) for a in (10, 20, 30, 40, 50, 60)}


def test_detachment_constant_is_the_energy_balance_of_one_element():
    """sigma_c = sqrt(E* dgamma / (beta h)): one element under a uniform stress
    sigma stores (1/2) sigma h^2 w_mean, with w_mean = c sigma h / E* its mean
    displacement; setting that to dgamma h^2 gives beta = c / 2.  c is
    integrated here from the influence coefficient (tested against the
    Boussinesq integral in test_numerics), not taken from the closed form in
    theory: Gauss-Legendre, 200^2 points on one quadrant of the element
    (the edges' weak singularities lie on its boundary), 1e-10 converged."""
    from brushcore.numerics.halfspace.kernel import love_coefficient

    nodes, weights = np.polynomial.legendre.leggauss(200)
    x, w = 0.25 * (nodes + 1), 0.25 * weights  # [0, 1/2]
    c = 4 * float(np.sum(np.outer(w, w) * love_coefficient(*np.meshgrid(x, x), 1.0, 1.0)))
    assert theory.BETA == pytest.approx(c / 2, rel=1e-8)
    assert 1 / math.sqrt(theory.BETA) == pytest.approx(1.45370, abs=1e-5)  # C of the paper's ref. 18
    assert theory.critical_stress(2.0, 3.0, 0.5) == pytest.approx(
        math.sqrt(2.0 * 3.0 / (c / 2 * 0.5)), rel=1e-8)


@pytest.mark.parametrize("a", [20, 30, 40])
def test_flat_punch_stiffness_is_2aE(rigid_punches, a):
    """The staircase disc's stiffness is 2 a0 E* to first order in h / a0: the
    error times a0 / h is 0.115-0.118 at a = 10 ... 40 (measured), so < 1.5 %
    from a = 20 on."""
    ds = rigid_punches[a]
    ratio = full_contact_stiffness(ds) / theory.flat_punch_stiffness(_a0(ds), 1.0)
    assert abs(ratio - 1) < 0.015, f"a={a}: stiffness / 2aE* = {ratio:.4f}"
    # the staircase is softer, by a first-order term: (ratio - 1) a0 / h
    assert -0.13 < (ratio - 1) * _a0(ds) < -0.10, f"a={a}: {(ratio - 1) * _a0(ds):.4f}"


@pytest.mark.parametrize("a", [20, 30, 40])
def test_flat_punch_pull_off_is_kendall(rigid_punches, a):
    """Kendall within 2 %: the staircase edge puts F_ad 0.2-1.7 % above it for
    a = 10 ... 60 elements (measured), not monotone in a (below)."""
    ds = rigid_punches[a]
    ratio = float(ds.adhesive_force) / theory.kendall_force(_a0(ds), 1.0, 1.0)
    assert 1 < ratio < 1.02, f"a={a}: F_ad / Kendall = {ratio:.4f}"
    assert float(ds.adhesive_force_normalized) == pytest.approx(ratio, rel=1e-12)


@pytest.mark.parametrize("a", [30, 40])
def test_displacement_scale_is_kendalls_critical_displacement(rigid_punches, a):
    """Eq. 21: d_K = F_K / (2 a0 E*), Kendall's critical displacement of a rigid
    flat punch.  So the normalised pull-off displacement is F_ad/F_K over the
    secant stiffness F_ad/d there in units of 2 a0 E*, exactly (1e-9), and
    about 1: the force's +0.6-1.6 % and the staircase's stiffness, -0.3 to
    -0.4 % and lower once edge elements have gone (the peak may follow the
    first event), put it within 2.5 % (1.0139 measured at a = 40).  d_K is
    also the unit of roughness, heights and gap maps."""
    ds = rigid_punches[a]
    peak = int(np.argmax(ds.force.values))
    d_bar = float(ds.displacement_normalized[peak])
    secant = float(ds.force[peak] / ds.displacement[peak]) / theory.flat_punch_stiffness(
        _a0(ds), 1.0)
    assert d_bar == pytest.approx(float(ds.adhesive_force_normalized) / secant, rel=1e-9)
    assert d_bar == pytest.approx(1.0, abs=0.025), d_bar


def test_kendall_is_approached_as_the_punch_spans_more_elements(rigid_punches):
    """Kendall's force within 1 % from a = 40 elements on (measured +0.62,
    +0.55, +0.45 % at a = 40, 50, 60; +1.63 % at 30, +1.70 % at 10).  From
    above on these punches, but that is no law of the model: the element
    pattern at the edge scatters it (a physics referee's punches: within
    ±0.6 % from a = 24 on, -0.002 % at a = 128; a pillar of 3.6 elements
    1.3 % below), so the band is two-sided.

    A detachment stress off by 1 % moves F_ad by about 1 %, so this band
    pins sigma_c: C = sqrt(2) in place of 1.4537 (sigma_c 2.7 % low) gives
    F_ad about 2 % under Kendall and fails, as it passed the 3 % bands before.
    """
    ratios = [float(rigid_punches[a].adhesive_force)
              / theory.kendall_force(_a0(rigid_punches[a]), 1.0, 1.0) for a in (40, 50, 60)]
    assert all(abs(r - 1) < 0.01 for r in ratios), ratios


def test_mesh_convergence_of_stiffness(rigid_punches):
    """The stiffness converges to 2 a0 E* at first order in h / a0: extrapolated
    from a = 10, 20, 40 elements it is 1 within 1e-3 (measured 0.99987, order
    1.01), with the errors shrinking grid by grid."""
    from brushcore.data.extrapolation import extrapolate

    radii = (10, 20, 40)
    ratios = [full_contact_stiffness(rigid_punches[a]) / (2 * _a0(rigid_punches[a])) for a in radii]
    err = [abs(r - 1) for r in ratios]
    assert err[0] > err[1] > err[2], f"stiffness errors {err} do not decrease with a/h"
    fit = extrapolate([1 / _a0(rigid_punches[a]) for a in radii], ratios)
    assert fit.value == pytest.approx(1.0, abs=1e-3), fit
    assert 0.8 < fit.order < 1.2, fit


def test_units_scale_out():
    """E* = 2, dgamma = 3, h = 0.5 give the same stiffness / 2 a0 E* and
    F_ad / Kendall as units of 1, to round-off: a dropped factor of h or E*
    would show here as a factor 2 (the other tests run in units of 1)."""
    from dataclasses import replace

    base = punch_params(20)
    ratios = []
    for e_star, dgamma, h in ((1.0, 1.0, 1.0), (2.0, 3.0, 0.5)):
        ds = simulate(replace(base, e_star=e_star, dgamma=dgamma, h=h))
        a0 = _a0(ds)
        ratios.append((full_contact_stiffness(ds) / theory.flat_punch_stiffness(a0, e_star),
                       float(ds.adhesive_force) / theory.kendall_force(a0, e_star, dgamma),
                       float(ds.adhesive_force_normalized),
                       float(ds.work_of_separation_normalized)))
    np.testing.assert_allclose(ratios[1], ratios[0], rtol=1e-9)


def test_punch_on_spring_keeps_rigid_pull_off(rigid_punches):
    """Displacement control: a spring in series only rescales d, never the force."""
    rigid = float(rigid_punches[20].adhesive_force)
    for kbar in (1e-4, 1e-2, 1.0):
        ds = simulate(punch_params(20, kbar=kbar))
        assert float(ds.adhesive_force) == pytest.approx(rigid, rel=1e-6), kbar
        # ... and the work gains the spring energy f^2 / 2k; only the short unstable
        # cascade after the peak runs at fixed d instead of fixed punch position.
        k = kbar * ds.attrs["side_length"]
        w_rigid = float(rigid_punches[20].work_of_separation)
        assert float(ds.work_of_separation) == pytest.approx(
            w_rigid + rigid**2 / (2 * k), rel=1e-3), kbar


def _four_pillars(kbar: float, **kw) -> BrushParams:
    # Pillars of radius 8 h, 128 h = 16 radii apart.  The far field of the
    # neighbours tilts each pillar's stress by ~ 4 a^2 / (pi r^2) ~ 0.5 %;
    # at 8 radii apart that was a measured 3 % loss of F_ad.
    return BrushParams("regular", 4, kbar, 256, phi=4 * math.pi * 64 / 256**2, **kw)


@pytest.fixture(scope="module")
def single_pillar():
    return simulate(punch_params(8))


@pytest.mark.parametrize("kbar", [1e-5, 1e-4])
def test_soft_separated_pillars_share_load_equally(single_pillar, kbar):
    """Eq. 3: N soft pillars hold N times one pillar's Kendall force, less the
    neighbours' tilt of each pillar's stress (~0.5 %, `_four_pillars`):
    -0.82 % measured, so below 1 and within 1.5 % of it."""
    ds = simulate(_four_pillars(kbar))
    ratio = float(ds.adhesive_force) / (4 * float(single_pillar.adhesive_force))
    assert -0.015 < ratio - 1 < 0, f"kbar={kbar}: F_ad / (4 f_1) = {ratio:.4f}"


def test_soft_work_approaches_spring_energy(single_pillar):
    """Eqs. 25-27: as k -> 0 the work of separation is the energy of N stretched springs.

    Soft pillars all let go at once, so W is the energy stored at that
    moment: per pillar f^2 (1/k + 1/k_c) / 2 with f = F_ad / N.
    """
    kc = full_contact_stiffness(single_pillar)
    errors = []
    for kbar in (1e-2, 1e-3, 1e-5):
        ds = simulate(_four_pillars(kbar))
        k = kbar * ds.attrs["side_length"]
        f = float(ds.adhesive_force) / 4
        w = float(ds.work_of_separation)
        errors.append(abs(w / (4 * f**2 / (2 * k)) - 1))
        if kbar <= 1e-3:  # series spring + contact; neighbours add ~0.2 % compliance
            assert w == pytest.approx(4 * theory.spring_punch_work(f, k, kc), rel=5e-3), kbar
    assert errors[0] > errors[1] > errors[2] and errors[2] < 1e-3, errors
    # Eqs. 25-26 take each pillar's force as Kendall's, N^(1/4) F_K in all;
    # W goes as the force squared, so W / W_S is (F_ad / N^(1/4) F_K)^2, up
    # to the contact's own compliance (1.8e-4 measured: 1.05702 against
    # 1.05683).  This pins W's normalisation (eq. 23) to F's (eq. 20).
    ratio = float(ds.work_of_separation_normalized) / float(
        theory.soft_work(4, ds.attrs["phi_actual"], 1e-5))
    expected = (float(ds.adhesive_force_normalized) / float(theory.soft_limit(4))) ** 2
    assert ratio == pytest.approx(expected, rel=1e-3), f"W / W_S(eq. 27) = {ratio:.5f}"


def test_rigid_regular_brush_is_near_phi_limit():
    """Eq. 5: rigid brush F_ad/F_K ~ phi^-1/4 (the paper finds slightly above for N >= 64).

    Measured: 1.010 for 8 x 8 on 256, 1.076 for 16 x 16 on 256; only 0.93 for
    4 x 4, whose few large pillars are no homogeneous brush.
    """
    ds = simulate(BrushParams("regular", 64, math.inf, 256, phi=0.12))
    ratio = float(ds.adhesive_force_normalized) / theory.rigid_limit(ds.attrs["phi_actual"])
    # "Slightly above", and this model's 1.010 to 0.005: sigma_c 3 % off
    # moved it to 0.981 or 1.042.
    assert ratio > 1 and ratio == pytest.approx(1.010, abs=0.005), \
        f"F_ad / phi^-1/4 = {ratio:.4f}"


@pytest.mark.parametrize("transform", ["transpose", "flip_x", "flip_y", "rot180"])
def test_layout_symmetries_leave_results_unchanged(transform):
    params = BrushParams("random", 12, 0.05, 64, phi=0.15, seed=3)
    labels = build_labels(params)
    moved = {"transpose": labels.T, "flip_x": labels[:, ::-1], "flip_y": labels[::-1],
             "rot180": labels[::-1, ::-1]}[transform]
    results = []
    for lab in (labels, np.ascontiguousarray(moved)):
        # Double precision: invariance up to round-off (single-precision
        # transforms round at ~1e-7, see SolverOptions.precision).
        _, curve, _ = run(params, SolverOptions(precision="double"), labels=lab)
        work = np.trapezoid(curve.force, curve.displacement)
        results.append((curve.force.max(), work, curve.events))
    (f0, w0, e0), (f1, w1, e1) = results
    assert f1 == pytest.approx(f0, rel=1e-8) and w1 == pytest.approx(w0, rel=1e-8)
    assert e0 == e1


def test_paper_fig5a_case_on_256_grid():
    """16 x 16 pillars, kbar = 0.455, phi = 0.12: the paper reports F_ad/F_K ~ 1.8 on 512.

    The band is the paper's; the pin is this model's value on 256^2 (1.8386,
    reproduced by two independent dense solvers in audits), to 1e-3 (CG's
    tolerance moves it ~1e-5): a critical stress 3 % off (C in sigma_c)
    moved it to 1.786 or 1.896, inside the band but not the pin."""
    ds = simulate(BrushParams("regular", 256, 0.455, 256, phi=0.12))
    f = float(ds.adhesive_force_normalized)
    assert 1.75 <= f <= 1.92, f"F_ad/F_K = {f:.4f}"
    assert f == pytest.approx(1.8386, rel=1e-3), f"F_ad/F_K = {f:.4f}"


def test_curve_is_consistent():
    ds = simulate(BrushParams("regular", 16, 0.01, 64))
    d, f = ds.displacement.values, ds.force.values
    assert np.all(np.diff(d) >= 0), "displacement must never decrease"
    assert f[0] == 0 and f[-1] == 0 and ds.contact_area.values[-1] == 0
    assert float(ds.adhesive_force) == pytest.approx(f.max())
    # the work is the exact area under a piecewise linear curve through the origin
    segs = 0.5 * (f[1:] + f[:-1]) * np.diff(d)
    assert float(ds.work_of_separation) == pytest.approx(segs.sum(), rel=1e-12)
    assert ds.attrs["operator_applications"] > 0 and ds.attrs["events"] >= 1
    snap = ds.contact_snapshot.values
    assert (snap[0] == 1).sum() == ds.attrs["real_contact_area"]  # start: all attached
    assert list(ds.snapshot_label.values)[2] == "maximum force"


def test_every_curve_names_its_units_d_k_and_f_k() -> None:
    """d_K and F_K of the realised area are written on every curve, flat ones
    too (a user converting measured heights reads d_K from a first flat run):
    the ratios of the dimensional to the normalised columns, and the theory's."""
    curve = simulate(BrushParams("regular", 16, 0.01, 64))
    a = curve.attrs
    d_k = theory.displacement_scale(a["real_contact_area"], a["e_star"], a["dgamma"])
    f_k = theory.force_scale(a["real_contact_area"], a["e_star"], a["dgamma"])
    assert a["displacement_unit_d_K"] == pytest.approx(d_k, rel=1e-14)
    assert a["force_unit_F_K"] == pytest.approx(f_k, rel=1e-14)
    moved = curve["displacement_normalized"].values != 0
    assert np.allclose(curve["displacement"].values[moved]
                       / curve["displacement_normalized"].values[moved], d_k, rtol=1e-14)
    assert float(curve["adhesive_force"] / curve["adhesive_force_normalized"]) == \
        pytest.approx(f_k, rel=1e-14)


def test_a_brushs_units_are_known_before_its_run() -> None:
    """`brushcore.unit_scales` gives the F_K, d_K, W_K and A a curve will record,
    from the realised area (32 elements a pillar here, where phi L^2 / N asks
    for 30.72), so measured heights can be put in d_K before a run; in SI
    units too (the curve's attributes and its normalised columns agree)."""
    from brushcore import unit_scales

    for params in (BrushParams("regular", 64, 0.01, 128),
                   BrushParams("random", 16, 0.1, 96, seed=2, e_star=2.6667e6, dgamma=0.05,
                               h=2.34375e-6)):
        scales = unit_scales(params)
        curve = simulate(params)
        a = curve.attrs
        assert (scales.area, scales.force, scales.displacement) == (
            a["real_contact_area"], a["force_unit_F_K"], a["displacement_unit_d_K"])
        assert float(curve.work_of_separation / curve.work_of_separation_normalized) == \
            pytest.approx(scales.work, rel=1e-14)
    assert unit_scales(BrushParams("regular", 64, 0.01, 128)).area == 64 * 32


def test_a_near_tie_follows_the_event_displacement_not_cg_rounding(tmp_path):
    """Two soft pillars whose stiffnesses differ by 7.4e-4: during the first
    one's cascade the second comes within 1.4e-6 of sigma_c and stays (an
    independent dense solver and exact mode: they let go at d 850.24 and
    867.09 d_K, W 1044.0025 W_K).  The event displacement d = sigma_c / peak
    sets the threshold of the whole cascade; the first solve's peak, 2.9e-6
    low at CG's tolerance, put the second pillar over it, both let go
    together and W was 2 % off.  The peak corrected by its error estimate
    decides it as the model does."""
    from brushcore import file_params

    labels = build_labels(BrushParams("regular", 16, 1e-4, 64))
    two = np.where(labels == 8, 0, np.where(labels == 13, 1, -1))
    np.save(tmp_path / "two.npy", two)
    kbar = 1e-4 * np.array([1.0, 1.0 - 7.4194e-4 * 1.002])
    params = file_params(tmp_path / "two.npy", 1e-4, kbar_values=kbar)
    got, want = simulate(params), simulate(params, SolverOptions.exact())
    let_go = got.pillar_let_go_displacement.values
    assert let_go[1] / let_go[0] - 1.0 > 0.01  # apart, as in exact mode
    np.testing.assert_allclose(let_go, want.pillar_let_go_displacement.values, rtol=1e-6)
    w = float(want.work_of_separation_normalized)
    assert abs(float(got.work_of_separation_normalized) / w - 1.0) < 1e-6


#: Closed forms over arrays: each with arguments that broadcast, (3, 1)
#: against (4,) where it takes two or more.
_KBAR = np.array([[1e-6], [1e-3], [math.inf]])
_N = np.array([1, 16, 64, 256])
_BROADCAST = {
    "critical_stress": (np.array([[1.0], [2e9]]), 0.05, np.array([1e-6, 1.0])),
    "flat_punch_stiffness": (np.array([[0.5], [2.0]]), np.array([1.0, 3.0])),
    "elliptic_punch_stiffness": (np.array([[1.0], [3.0]]), np.array([0.5, 1.0, 2.0]), 1.0),
    "square_punch_stiffness": (np.array([1.0, 2.0]), 3.0),
    "elliptic_punch_initiation_force": (np.array([[1.0], [3.0]]), np.array([0.5, 1.0, 2.0]),
                                        1.0, 2.0),
    "kendall_force": (np.array([[0.5], [4.0]]), 2.0, np.array([0.1, 1.0, 3.0])),
    "equivalent_radius": (np.array([1.0, 50.0, 1e4]),),
    "force_scale": (np.array([[1.0], [1e4]]), 1.0, np.array([0.5, 2.0])),
    "displacement_scale": (np.array([[1.0], [1e4]]), np.array([0.5, 2.0]), 1.0),
    "work_scale": (np.array([[1.0], [1e4]]), np.array([0.5, 2.0])),
    "stiffness_from_kbar": (_KBAR, 1.0, _N.astype(float)),
    "rigid_limit": (np.array([0.01, 0.12, 0.5]),),
    "hexagonal_rigid_limit": (np.array([[0.05], [0.12]]), np.array([16, 56, 64])),
    "soft_limit": (_N,),
    "soft_work": (_N, 0.12, _KBAR),
    "spring_punch_work": (np.array([[1.0], [2.0]]), _KBAR[:, 0], 3.0),
    "uniform_spread_pull_off": (np.array([0.0, 0.5, 1.0, 3.0]),),
    "gaussian_spread_pull_off": (np.array([0.0, 0.1, 1.0]),),
    "bimodal_stiffness_pull_off": (np.array([[1.0], [2.0], [10.0]]), np.array([0.1, 0.5, 0.9])),
    "jkr_pull_off": (np.array([[1.0], [2.0]]), np.array([0.5, 1.0])),
    "jkr_fixed_grips_pull_off": (np.array([[1.0], [2.0]]), np.array([0.5, 1.0])),
    "foundation_stretch": (_N, np.array([[0.05], [0.12]]), np.array([[1e-4], [1e-2]])),
}


@pytest.mark.parametrize("name", sorted(_BROADCAST))
def test_closed_forms_take_arrays_and_give_floats_for_numbers(name):
    """Each closed form over broadcast arrays (a curve over kbar or N for a
    plot) is its value at each point; numbers give a Python float as before
    (soft_limit, soft_work and foundation_stretch gave np.float64,
    uniform_spread_pull_off a 0-d array); lists are taken as arrays."""
    f = getattr(theory, name)
    args = _BROADCAST[name]
    got = f(*args)
    shape = np.broadcast_shapes(*(np.shape(a) for a in args))
    assert isinstance(got, np.ndarray) and got.shape == shape and got.dtype == float
    points = np.broadcast_arrays(*(np.asarray(a) for a in args))
    for index in np.ndindex(shape):
        scalar = f(*(p[index].item() for p in points))
        assert type(scalar) is float, index
        # NumPy squares by multiplying, Python's ** calls pow: work_scale's last bits
        assert got[index] == pytest.approx(scalar, rel=1e-15, abs=0), index
    listed = f(*(a.tolist() if isinstance(a, np.ndarray) else a for a in args))
    np.testing.assert_array_equal(listed, got)


def test_closed_forms_over_arrays_are_the_formulas():
    """Against the formulas written out, over kbar and N as a plot takes them."""
    kbar = np.geomspace(1e-6, 1.0, 7)
    n = np.array([4, 16, 64, 256, 1024])
    phi = 0.12
    np.testing.assert_allclose(theory.soft_work(n[:, None], phi, kbar),
                               2 * np.sqrt(phi / np.pi) / (np.sqrt(n[:, None]) * kbar),
                               rtol=1e-15)
    np.testing.assert_allclose(theory.foundation_stretch(n[:, None], phi, kbar),
                               2 * n[:, None]**-0.75 * np.sqrt(phi / np.pi) / kbar, rtol=1e-15)
    np.testing.assert_allclose(theory.soft_limit(n), n**0.25, rtol=1e-15)
    a = np.linspace(0.5, 20.0, 9)
    np.testing.assert_allclose(theory.kendall_force(a, 2.0, 0.3),
                               np.sqrt(8 * np.pi * 2.0 * 0.3 * a**3), rtol=1e-15)
    area = np.pi * a**2  # a disc: its equivalent radius is a, its scales Kendall's
    np.testing.assert_allclose(theory.equivalent_radius(area), a, rtol=1e-15)
    np.testing.assert_allclose(theory.force_scale(area, 2.0, 0.3),
                               theory.kendall_force(a, 2.0, 0.3), rtol=1e-15)
    np.testing.assert_allclose(theory.displacement_scale(area, 2.0, 0.3),
                               np.sqrt(2 * np.pi * 0.3 * a / 2.0), rtol=1e-15)
    np.testing.assert_allclose(theory.work_scale(area, 0.3), 2 * np.pi * a**2 * 0.3,
                               rtol=1e-15)
    h = np.array([0.25, 1.0, 4.0])
    np.testing.assert_allclose(theory.critical_stress(2.0, 0.3, h),
                               np.sqrt(2.0 * 0.3 / (theory.BETA * h)), rtol=1e-15)
    assert theory.rigid_limit([0.0625, 1.0]).tolist() == [2.0, 1.0]
    # a number outside a formula's domain is refused as before; an array holds NaN there
    with pytest.raises(ValueError, match="math domain"):
        theory.kendall_force(-1.0, 1.0, 1.0)
    with pytest.warns(RuntimeWarning, match="invalid value"):
        assert np.isnan(theory.kendall_force(np.array([-1.0, 1.0]), 1.0, 1.0)).tolist() == [
            True, False]
