"""Analytic reference solutions and the paper's normalisations (pure functions).

Every formula the tests and the figures compare against lives here, so the
solver, the tests and the plots cannot drift apart.  Units are whatever the
caller uses consistently (the package default is E* = dgamma = h = 1): the
arguments ``radius``, ``major``, ``minor``, ``side`` and ``h``
are lengths, ``area`` a length squared, ``e_star`` a stress, ``dgamma`` an
energy per area, ``stiffness`` or ``spring`` a force per length; ``kbar``,
``phi`` and ``n_pillars`` are dimensionless.  Each function's docstring
gives its result's unit.

The closed forms take NumPy arrays (or lists) as well as numbers, broadcast
together, for a curve over kbar or N (a plot): numbers in give a Python
float, computed as before they took arrays (bit for bit), arrays in an
array, equal to the numbers' results to round-off (`work_scale` within 3
ulp, measured; NumPy squares by multiplying, Python's ``**`` calls
``pow``).  Array-likes are taken as arrays (an xarray DataArray's labels
are dropped).  `kendall_scales` (one run's units) and `foundation_pull_off`
(one brush's pillars) stay scalar.

References
----------
He, Li & Popov, Lubricants 8 (2020) 94 ("the paper"), eqs. 5, 6, 20-27.
Kendall, J. Phys. D 4 (1971) 1186.
Pohrt & Popov, Facta Univ. Mech. Eng. 13 (2015) 3-10.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TypeAlias

import numpy as np

from brushcore.model.lattices import hexagonal_fill
from brushcore.numerics.halfspace.kernel import self_compliance  # noqa: F401 - a limit like the rest

#: A closed form's argument or result: a number, or an array of them.
Values: TypeAlias = float | np.ndarray


def _value(x: object) -> float | np.ndarray:
    """``x`` as a Python float where it is one number (so that the formulas'
    scalar arithmetic stays Python's, as before they took arrays), else as
    an array of floats."""
    values = np.asarray(x, dtype=float)
    return float(values) if values.ndim == 0 else values


def _out(result: object) -> float | np.ndarray:
    """A result as a Python float where the arguments were numbers (NumPy
    gives a 0-d float64 there), else the array."""
    return float(result) if np.ndim(result) == 0 else result


def _sqrt(x: float | np.ndarray) -> float | np.ndarray:
    """math.sqrt of a number (a ValueError below 0, as before arrays were
    taken), np.sqrt of an array (NaN there); both correctly rounded."""
    return math.sqrt(x) if isinstance(x, float) else np.sqrt(x)


#: Griffith energy balance over one square element of side h under a flat
#: punch's edge singularity (Pohrt & Popov 2015, eq. 14):
#: beta = [4 ln(1 + sqrt 2) - (4/3)(sqrt 2 - 1)] / (2 pi).
BETA = (4.0 * math.log(1.0 + math.sqrt(2.0)) - 4.0 / 3.0 * (math.sqrt(2.0) - 1.0)) / (
    2.0 * math.pi
)


def critical_stress(e_star: Values, dgamma: Values, h: Values) -> Values:
    """Mesh-dependent detachment stress sigma_c = sqrt(E* dgamma / (beta h)).

    Parameters
    ----------
    e_star : effective modulus E* [stress]
    dgamma : work of adhesion [energy / area]
    h : element size [length]

    Returns
    -------
    float or ndarray
        Critical tensile stress [stress] (Pohrt & Popov 2015).
    """
    return _out(_sqrt(_value(e_star) * _value(dgamma) / (BETA * _value(h))))


def flat_punch_stiffness(radius: Values, e_star: Values) -> Values:
    """Normal stiffness 2 a E* of a rigid circular flat punch [force / length]."""
    return _out(2.0 * _value(radius) * _value(e_star))


def elliptic_punch_stiffness(major: Values, minor: Values, e_star: Values) -> Values:
    """Normal stiffness pi a E* / K(e) of a rigid elliptic flat punch [force / length].

    Galin's solution (Contact Problems in the Theory of Elasticity, 1961;
    Johnson, Contact Mechanics, 1985, ch. 3), 2 a E* for a circle: the
    pressure p0 (1 - x^2/a^2 - y^2/b^2)^(-1/2) over the ellipse
    of semi-axes a >= b displaces it uniformly by 2 p0 b K(e) / E*, with
    K the complete elliptic integral of the first kind of eccentricity
    e = sqrt(1 - b^2/a^2), and carries 2 pi a b p0.  ``major`` and
    ``minor`` are the semi-axes [length], in either order.
    """
    from scipy.special import ellipk  # argument m = e^2

    a, b = _semi_axes(major, minor)
    return _out(math.pi * a * _value(e_star) / _value(ellipk(1.0 - (b / a) ** 2)))


def _semi_axes(major: Values, minor: Values) -> tuple[Values, Values]:
    """The larger and the smaller of two semi-axes, element-wise [length]."""
    major, minor = _value(major), _value(minor)
    return _value(np.maximum(major, minor)), _value(np.minimum(major, minor))


#: Electrostatic capacitance of a thin square plate of unit side, in
#: Gaussian units (a disc of radius a: 2a/pi), known to about six digits
#: from boundary-element and random-walk computations.
SQUARE_PLATE_CAPACITANCE = 0.3667874


def square_punch_stiffness(side: Values, e_star: Values) -> Values:
    """Normal stiffness pi E* C s of a rigid square flat punch of side s
    [force / length].

    A flat punch's stiffness is pi E* times the capacitance C of a thin
    conducting plate of its shape: uniform displacement over the footprint
    is uniform potential over the plate, with the same 1/r kernel
    (Boussinesq's 1/(pi E* r) for the charge's 1/r), so the total force is
    pi E* C times the displacement; a disc (C = 2a/pi) gives 2 a E*.  For a
    square, C = `SQUARE_PLATE_CAPACITANCE` s: 1.0212 times the disc of
    equal area.
    """
    return _out(math.pi * _value(e_star) * SQUARE_PLATE_CAPACITANCE * _value(side))


def elliptic_punch_initiation_force(major: Values, minor: Values, e_star: Values,
                                    dgamma: Values) -> Values:
    """Force sqrt(8 pi E* dgamma a b^2) at which a rigid elliptic flat punch
    starts to let go, at the ends of its major axis [force].

    From Galin's pressure (`elliptic_punch_stiffness`): at distance s inside
    the edge point (a cos t, b sin t) it is p0 / sqrt(2 s L), with
    L = sqrt(cos^2 t / a^2 + sin^2 t / b^2), so the energy release rate is
    G = pi p0^2 / (2 E* L), largest where L is least: L = 1/a at the ends of
    the major axis.  G = dgamma there, with p0 = F / (2 pi a b), gives the
    force; (b/a)^(1/4) times Kendall's force of the disc of equal area, and
    Kendall's for a = b.  What follows is not a collapse: the contact
    shrinks from the ends and the force can rise further, so F_ad lies
    above this.  ``major`` and ``minor`` are the semi-axes [length], in
    either order.
    """
    a, b = _semi_axes(major, minor)
    return _out(_sqrt(8.0 * math.pi * _value(e_star) * _value(dgamma) * a * b * b))


def kendall_force(radius: Values, e_star: Values, dgamma: Values) -> Values:
    """Kendall's pull-off force sqrt(8 pi E* dgamma a^3) of a flat punch [force]."""
    return _out(_sqrt(8.0 * math.pi * _value(e_star) * _value(dgamma) * _value(radius)**3))


def equivalent_radius(area: Values) -> Values:
    """Radius a0 = sqrt(A / pi) of the compact punch with the same area [length]."""
    return _out(_sqrt(_value(area) / math.pi))


def force_scale(area: Values, e_star: Values, dgamma: Values) -> Values:
    """Kendall force sqrt(8 pi E* dgamma a0^3) of the compact punch of area A
    (a0 = sqrt(A / pi)), the paper's eq. 20 scale F_K [force]."""
    return kendall_force(equivalent_radius(area), e_star, dgamma)


def displacement_scale(area: Values, e_star: Values, dgamma: Values) -> Values:
    """Kendall's critical displacement sqrt(2 pi dgamma a0 / E*), eq. 21 [length]."""
    return _out(_sqrt(2.0 * math.pi * _value(dgamma) * equivalent_radius(area)
                      / _value(e_star)))


def work_scale(area: Values, dgamma: Values) -> Values:
    """Work of separation 2 pi a0^2 dgamma of the compact punch, eq. 23 [energy]."""
    return _out(2.0 * math.pi * equivalent_radius(area) ** 2 * _value(dgamma))


@dataclass(frozen=True)
class KendallScales:
    """The units of a brush's normalised results, those of the compact punch
    of its real contact area A (eqs. 20-23).

    Parameters
    ----------
    area : real contact area A, the pillar elements' [length^2]
    force : F_K = sqrt(8 pi E* dgamma a0^3), a0 = sqrt(A / pi) [force]
    displacement : d_K = sqrt(2 pi dgamma a0 / E*) [length]
    work : W_K = 2 pi a0^2 dgamma [energy]
    """

    area: float
    force: float
    displacement: float
    work: float


def kendall_scales(area: float, e_star: float, dgamma: float) -> KendallScales:
    """`KendallScales` of the real contact area ``area`` [length^2] (numbers:
    one run's units; the scale functions take arrays)."""
    return KendallScales(area, force_scale(area, e_star, dgamma),
                         displacement_scale(area, e_star, dgamma), work_scale(area, dgamma))


def stiffness_from_kbar(kbar: Values, e_star: Values, side: Values) -> Values:
    """Pillar spring stiffness k = kbar E* L (eq. 22) [force / length] (inf for rigid)."""
    return _out(_value(kbar) * _value(e_star) * _value(side))


def rigid_limit(phi: Values) -> Values:
    """Normalised adhesive force of a rigid flat brush, phi^(-1/4) (eq. 5)."""
    return _out(_value(phi)**-0.25)


def hexagonal_rigid_limit(phi: Values, n_pillars: int | np.ndarray) -> Values:
    """Eq. 5 at a hexagonal lattice's local filling factor, (phi / fill)^(-1/4).

    An N that no lattice fills covers ``fill`` (`lattices.hexagonal_fill`)
    of the square, so its pillars stand at phi / fill where they stand.  An
    approximation, not a limit: against the same grid's regular lattice,
    measured within 0.2-1.5 % at phi = 0.12 (N = 16, 64; 128^2-512^2) and
    2-3 % above the hexagonal brush at phi = 0.05.

    Raises
    ------
    ValueError
        For an N that fills no hexagonal lattice.
    """
    counts = np.asarray(n_pillars)
    fill = (hexagonal_fill(int(counts)) if counts.ndim == 0 else  # the lattice is counted
            np.reshape([hexagonal_fill(int(n)) for n in counts.ravel()], counts.shape))
    return rigid_limit(_value(phi) / fill)


def soft_limit(n_pillars: int | np.ndarray) -> Values:
    """Normalised adhesive force of independent soft pillars, N^(1/4) (eq. 6)."""
    return _out(_value(n_pillars) ** 0.25)


def soft_work(n_pillars: int | np.ndarray, phi: Values, kbar: Values) -> Values:
    """Normalised work of separation stored in soft springs, eqs. 25-27.

    Each of the N springs carries f = N^(-3/4) F_K at pull-off and stores
    f^2 / (2k); normalising by 2 pi a0^2 dgamma with a0 = L sqrt(phi / pi)
    and k = kbar E* L gives W_S = 2 sqrt(phi / pi) / (sqrt(N) kbar).  The
    paper prints the last step of eq. 27 as sqrt(phi) / (sqrt(N) kbar),
    smaller by 2 / sqrt(pi) = 1.128; eqs. 25-26 give the form used here.

    Parameters
    ----------
    n_pillars : N [-]
    phi : filling factor A / L^2 [-]
    kbar : normalised spring stiffness k / (E* L) [-]

    Returns
    -------
    W_S / (2 pi a0^2 dgamma) [-]
    """
    n = np.asarray(n_pillars, dtype=float)  # np.sqrt whatever n is: as before
    return _out(2.0 * _sqrt(_value(phi) / math.pi) / (np.sqrt(n) * _value(kbar)))


def spring_punch_work(pull_off: Values, spring: Values, contact: Values) -> Values:
    """Work to separate one punch on a spring that detaches at once [energy].

    Under displacement control the punch and its spring are in series, so
    the force rises linearly with compliance 1/k + 1/k_c up to the pull-off
    force and then drops to zero: W = f^2 (1/k + 1/k_c) / 2.

    Parameters
    ----------
    pull_off : the punch's pull-off force f [force]
    spring : spring stiffness k [force / length]
    contact : the contact's own stiffness k_c, 2 a E* for a flat punch
        [force / length]
    """
    return _out(0.5 * _value(pull_off)**2 * (1.0 / _value(spring) + 1.0 / _value(contact)))


# --- Rough, graded and preloaded brushes: the elastic-foundation limit --------
# Separated soft pillars do not interact: pillar i carries k_eff,i (d - d0_i)
# (tensile positive) from its zero-force position d0_i until it lets go at its
# own critical force f_c, i.e. at d0_i + lambda_i with lambda_i = f_c / k_eff,i
# (a flat punch on a spring lets go at f_c whatever the spring; README,
# "Rough, graded and preloaded brushes").  Pillars in compression count with
# their (negative) force and never let go.


def foundation_pull_off(d0: np.ndarray, k_eff: np.ndarray, f_c: float | np.ndarray
                        ) -> float:
    """Adhesive force of independent pillars, all attached [force].

    F_ad = max_j sum_{i : d_i >= d_j} k_eff,i (d_j - d0_i), with d_j =
    d0_j + f_c,j / k_eff,j the displacement at which pillar j lets go (the
    force just before it does).  Exact for the elastic-foundation model.

    Parameters
    ----------
    d0 : zero-force displacement of each pillar [length] (its first-touch d;
        larger means it lets go later)
    k_eff : effective stiffness of each pillar, finite and > 0 [force /
        length]: its spring in series with its contact (2 a E* for a disc),
        finite for a rigid spring too
    f_c : critical force of each pillar (or one for all) [force]

    Raises
    ------
    ValueError
        Where a k_eff is not finite and positive (the maximum would be NaN).
    """
    d0 = np.asarray(d0, dtype=float)
    k = np.asarray(k_eff, dtype=float)
    bad = k[~(np.isfinite(k) & (k > 0))]
    if bad.size:
        raise ValueError(f"k_eff must be finite and > 0 (a spring in series with its "
                         f"contact, 2 a E* for a disc), got {float(bad[0])!r}")
    let_go = d0 + np.broadcast_to(np.asarray(f_c, dtype=float), d0.shape) / k
    attached = let_go[None, :] >= let_go[:, None]  # [j, i]: i still holds at d_j
    force = (attached * k[None, :] * (let_go[:, None] - d0[None, :])).sum(axis=1)
    return float(force.max())


def uniform_spread_pull_off(width: Values) -> Values:
    """F_ad / (N f_c) of many equal pillars with heights uniform over a band
    of width w, in units of the stretch lambda = f_c / k_eff:
    1 - w / 2 for w <= 1, 1 / (2 w) beyond."""
    w = np.asarray(width, dtype=float)
    return _out(np.where(w <= 1.0, 1.0 - 0.5 * w, 0.5 / np.maximum(w, 1.0)))


def gaussian_spread_pull_off(s: Values) -> Values:
    """F_ad / (N f_c) of many equal pillars with Gaussian heights of standard
    deviation s (units of lambda = f_c / k_eff), large N.

    With x = (d - z) / lambda ~ Normal(mu, s), F / (N f_c) = E[x; x < 1] =
    mu Phi(a) - s phi(a), a = (1 - mu) / s, maximised over mu numerically.
    Values 0.784, 0.634, 0.343, 0.115 at s = 0.1, 0.2, 0.5, 1.  An array of
    s is maximised element by element (~1 ms each).
    """
    spreads = np.asarray(s, dtype=float)
    if spreads.ndim:
        return np.reshape([_gaussian_spread(float(x)) for x in spreads.ravel()], spreads.shape)
    return _gaussian_spread(float(spreads))


def _gaussian_spread(s: float) -> float:
    """`gaussian_spread_pull_off` of one spread s."""
    from scipy.optimize import minimize_scalar
    from scipy.stats import norm

    if s == 0:
        return 1.0

    def minus_force(mu: float) -> float:
        a = (1.0 - mu) / s
        return -(mu * norm.cdf(a) - s * norm.pdf(a))

    res = minimize_scalar(minus_force, bounds=(1.0 - 10.0 * s, 1.0 + 10.0 * s),
                          method="bounded", options={"xatol": 1e-12})
    return float(-res.fun)


def lognormal_stiffness_pull_off(cv: Values) -> Values:
    """F_ad / (N f_c) of many equal-height pillars whose stiffnesses are
    lognormal of mean k and coefficient of variation C (`draws.lognormal_kbar`,
    the ``kbar_spread``), large N, every pillar attached.

    Pillar i pulls k_i d until it lets go at its own stretch f_c / k_i: the
    stiffest go first.  With x = d k / f_c and X = k_i / k (lognormal, mean
    1, sigma^2 = ln(1 + C^2)), F / (N f_c) = x E[X; X < 1/x] = x Phi((-ln x
    - sigma^2 / 2) / sigma), maximised over x numerically: 1 at C = 0,
    0.802, 0.640, 0.489, 0.354 at C = 0.1, 0.25, 0.5, 1 (a Monte Carlo of
    2e5 draws of `lognormal_kbar` agrees to 1e-3).  Like `gaussian_spread_pull_off`
    independent of k: a soft brush's F_ad / F_K is N^(1/4) times this.  An
    array of C is maximised element by element.
    """
    spreads = np.asarray(cv, dtype=float)
    if spreads.ndim:
        return np.reshape([_lognormal_stiffness(float(c)) for c in spreads.ravel()],
                          spreads.shape)
    return _lognormal_stiffness(float(spreads))


def _lognormal_stiffness(cv: float) -> float:
    """`lognormal_stiffness_pull_off` of one coefficient of variation C."""
    from scipy.optimize import minimize_scalar
    from scipy.stats import norm

    if cv == 0:
        return 1.0
    sigma = math.sqrt(math.log1p(cv * cv))

    def minus_force(log_x: float) -> float:  # x = exp(log_x): the stretch d k / f_c
        return -math.exp(log_x) * norm.cdf((-log_x - 0.5 * sigma**2) / sigma)

    res = minimize_scalar(minus_force, bounds=(-12.0 * sigma - 1.0, 1.0), method="bounded",
                          options={"xatol": 1e-12})
    return float(-res.fun)


def drawn_stiffness_pull_off(n_pillars: int, cv: float, seeds) -> float:
    """F_ad / (N f_c) of the elastic foundation (equal heights, every pillar
    attached) for the stiffnesses a graded brush of N pillars draws at
    spread C (`draws.lognormal_kbar`, as `rough.pillar_inputs` draws them),
    the mean over ``seeds``: `foundation_pull_off` of each draw.  Independent
    of kbar (the draws scale with it).  A brush of few pillars lies above
    the many-pillar `lognormal_stiffness_pull_off`: 16 pillars at C = 0.5
    give 0.615 and 0.651 for seeds 0 and 1, against 0.489.
    """
    from brushcore.model.draws import lognormal_kbar

    forces = [foundation_pull_off(np.zeros(n_pillars),
                                  lognormal_kbar(1.0, float(cv), n_pillars, int(seed)), 1.0)
              for seed in seeds]
    return float(np.mean(forces)) / n_pillars


def bimodal_stiffness_pull_off(ratio: Values = 2.0, fraction: Values = 0.5) -> Values:
    """F_ad / (N f_c) of equal-height pillars, a fraction q with stiffness k
    and the rest with ratio * k (ratio >= 1): the stiff ones let go at
    lambda / ratio, the soft ones at lambda; 0.75 for half k, half 2k.

    Parameters
    ----------
    ratio : stiffness of the stiff pillars over the soft ones' (>= 1) [-]
    fraction : share q of the soft pillars [-]
    """
    ratio, fraction = _value(ratio), _value(fraction)
    at_stiff = fraction / ratio + (1.0 - fraction)
    at_soft = fraction
    return _out(np.maximum(at_stiff, at_soft))


def jkr_pull_off(radius: Values, dgamma: Values) -> Values:
    """JKR pull-off force 1.5 pi R dgamma of a sphere under load control, or of
    a sphere on any spring once the contact is unstable [force]."""
    return _out(1.5 * math.pi * _value(radius) * _value(dgamma))


def jkr_fixed_grips_pull_off(radius: Values, dgamma: Values) -> Values:
    """Force (5/6) pi R dgamma at which a JKR sphere on a rigid mount
    (displacement control) jumps out of contact [force]."""
    return _out(5.0 / 6.0 * math.pi * _value(radius) * _value(dgamma))


#: The elastic foundation's soft limit holds (the figures and the summary
#: quote it) where a pillar's let-go stretch lambda (`foundation_stretch`, in
#: d_K) is at least
#: this: the springs then take most of the pull-off displacement (the half
#: space's own is 0.72-0.77 d_K at F_ad for the default sweep's brushes at
#: kbar 100), as the model assumes.  Below
#: it the line fails: regular 256 at kbar 0.01 (lambda 0.6) lies 1.6x below
#: the line at S = 0 and 3.5x above it at S = 1 (a review helper's check);
#: at kbar 1e-3 (lambda 6) the data follow its shape, 1/1.25 below.
MIN_FOUNDATION_STRETCH = 3.0


def foundation_stretch(n_pillars: int | np.ndarray, phi: Values, kbar: Values) -> Values:
    """Let-go stretch lambda = f_c / k of one soft pillar in units of d_K.

    In the soft limit each of the N pillars holds Kendall's force of its own
    radius, f_c = N^(-3/4) F_K, on a spring k = kbar E* L; with F_K / d_K =
    2 E* a0 and a0 = L sqrt(phi / pi): lambda / d_K = 2 N^(-3/4) sqrt(phi /
    pi) / kbar.  A roughness S (in d_K) is s = S d_K / lambda stretches.

    Parameters
    ----------
    n_pillars : N [-]
    phi : filling factor A / L^2 [-]
    kbar : normalised spring stiffness k / (E* L) [-]
    """
    return _out(2.0 * _value(n_pillars)**-0.75 * _sqrt(_value(phi) / math.pi)
                / np.asarray(kbar, dtype=float))
