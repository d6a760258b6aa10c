"""Mesh-refinement studies: extrapolate a result to h -> 0 with its observed order.

The detachment stress sigma_c = C sqrt(E* dgamma / h) makes every brushcore
number a number *for one resolution*.  Given one result f on three or more
grids, this module fits

    f(h) = f0 + C h^p                                                    (1)

with the observed order p, and returns the extrapolated value f0, an error
estimate, p, and flags that say when (1) does not describe the data.

Method
------
* Three grids: (1) through the three points exactly.  With a constant
  refinement ratio r = h2/h1 = h3/h2 this is Richardson's closed form
  p = ln[(f3 - f2)/(f2 - f1)] / ln r, f0 = f1 + (f1 - f2)/(r^p - 1);
  with uneven ratios p is the root of
  (f3 - f2)/(f2 - f1) = (h3^p - h2^p)/(h2^p - h1^p), which is monotone in p
  (Celik et al. 2008 solve the same equation by fixed-point iteration).
* Four or more grids: least squares of (1) by variable projection: for a
  fixed p, f0 and C are a linear least-squares problem; p minimises the
  residual over a bounded interval.
* Error estimate (``error``): the half-width U of an uncertainty band about
  f0.  Roache's GCI and Eca & Hoekstra's U are built as the uncertainty of
  the finest value f1; since |f1 - f0| <= U / 1.25, the band f0 +- U holds
  f1 as well, and it is about f0 that the band was measured to hold the
  limit (below).
  - three grids: Roache's grid convergence index of the finest grid,
    GCI = Fs |f1 - f2| / (r21^p - 1) (Roache 1998, Celik et al. 2008).
  - four or more grids: after Eca & Hoekstra (2014), who fit scattered data
    by least squares: U = Fs |fit(h1) - f0| + sigma + |f1 - fit(h1)|, sigma
    the standard deviation of the fit (the fit is kept, flagged
    ``non_monotone``, when the values oscillate, as long as its order and
    residual pass).
  - Fs = 1.25 only where the observed order is one the data can be trusted
    with (``trusted_order``, 0.5 ... 1.1: Eca & Hoekstra's band about the
    expected order, here 1), the values are monotone and (four or more
    grids) the three finest do not diverge; otherwise Fs = 3, and
    the correction |f1 - f0| is the larger of those with the observed
    order and with the nearest trusted one (Roache's Fs = 3 where the order
    is not confirmed; an observed p of 3.9 would otherwise give the tightest
    band of all).  The safety factor used is returned (``safety_factor``).
  - Measured (`benchmarks/extrapolation_coverage.py`, 1,000 draws of
    f0 + C h^p, a 3 % mesh error on the coarsest grid, Gaussian scatter of
    0.1 % per grid): the band f0 +- U holds the true limit in 94.6-100 % of
    the fits kept on 256/512/1024 for true orders 0.7-1.5, and 96-100 % on
    four grids to 2048; but for a true order of 0.5 (0.6) only in 65 % (85 %)
    and 86 % (91 %), since scatter makes such data look like p ~ 0.75.
    With 0.3 % scatter: 65-94 % and 89-99 % (p 0.7-1.5), of the 57-81 % and
    65-91 % of fits kept: three grids cannot tell that much scatter from
    mesh error; use four or more.  Read about f1, f1 +- U holds the limit
    in 97-100 % at p >= 1, but 38-70 % (3 grids) at p 0.5-0.7.
  The GCI is returned for every fit (``gci``), and the half range of the raw
  values, (max f - min f)/2, always (``spread``): the uncertainty Stern et
  al. (2001) use for oscillatory convergence, where no extrapolation exists.
* Flags, never a silent number:
  ``too_few_grids`` (fewer than ``min_grids`` values that are not NaN),
  ``non_monotone`` (successive differences change sign: oscillatory
  convergence; with three grids (1) has no solution and f0 is NaN),
  ``poor_fit`` (order outside ``order_range``, no positive order (the
  differences grow under refinement), an rms residual above
  ``max_relative_residual`` of the range of f, or an infinite value),
  ``not_asymptotic`` (four or more grids whose three finest values move
  apart ever faster, monotone with no positive order: the fit rests on the
  coarse grids; the value is kept, with Fs = 3; an oscillating fine end is
  ``non_monotone``).
  `extrapolate_sweep` adds ``untrusted_order`` (an order outside
  ``trusted_order`` where no other flag is raised: Fs 3 for that alone)
  and, per case, ``mixed_settings`` (the accuracy settings its grids' curves
  ran with differently, `mixed_settings`).
  Where a flag makes (1) meaningless, f0 and the error are NaN; the order
  that was observed is kept (negative when the differences grow under
  refinement, on three grids, even ratios or not), NaN when none was
  (oscillation, no root within ``order_bounds`` or their negatives with
  uneven ratios, the two finest values equal beside a third, or a
  least-squares order at its search bound, which is where four or more
  diverging values send it); the raw values stay with the caller (and in
  `extrapolate_sweep`'s output).

All functions are pure.  h is any length proportional to the element size;
brushcore uses h/L = 1/n (n elements per side of the square L x L), so the
brush (L, pillars, k-bar) is the same on every grid.

References
----------
Roache, P. J. (1998) Verification and Validation in Computational Science and
Engineering, Hermosa, ch. 5; Roache, J. Fluids Eng. 116 (1994) 405-413.
Celik, Ghia, Roache, Freitas, Coleman & Raad, J. Fluids Eng. 130 (2008)
078001 ("Procedure for estimation and reporting of uncertainty due to
discretization in CFD applications").
Stern, Wilson, Coleman & Paterson, J. Fluids Eng. 123 (2001) 793-802.
Eca & Hoekstra, J. Comput. Phys. 262 (2014) 104-130 ("A procedure for the
estimation of the numerical uncertainty of CFD calculations based on grid
refinement studies").
"""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr
from scipy import optimize

from brushcore.data.aggregate import GRID_DIM
from brushcore.model import provenance
from brushcore.model.params import MAX_PHI_ERROR
from brushcore.validation import is_integer, is_real, normalise, require

#: Results the workflow extrapolates.
QUANTITIES = ("adhesive_force_normalized", "work_of_separation_normalized")
#: Under this many elements per pillar radius a result is marked under-resolved.
UNDER_RESOLVED_RADIUS = 4.0
#: The fit's flags, as `Extrapolation` fields and ``{q}_{flag}`` variables.
FIT_FLAGS = ("non_monotone", "poor_fit", "too_few_grids", "not_asymptotic")
#: A fit whose observed order lies outside `ConvergenceOptions.trusted_order`
#: and that no other flag explains: its error carries Fs 3 for that alone.
ORDER_FLAG = "untrusted_order"
#: Every ``{q}_{flag}`` variable of `extrapolate_sweep`, as the table and the
#: figure name them.
STUDY_FLAGS = (*FIT_FLAGS, ORDER_FLAG)
#: Sweep variable counting pillar pairs that share an element edge on a grid
#: (`brushcore.model.labelmap.count_touching_pairs`): flagged in the table.
TOUCHING = "touching_pillar_pairs"
#: Sweep variable of the narrowest pillar's radius [elements] on a grid
#: (`brushcore.model.layout.smallest_radius_elements`): what the flags read.
SMALLEST = "smallest_radius_elements"
#: The filling factor each grid realises (sweep.nc's), carried beside the raw values.
PHI_ACTUAL = "phi_actual"
#: Solver settings that set a curve's accuracy (sweep.nc's ``run_{name}``
#: where they differ between curves): a case whose grids ran with different
#: ones mixes their errors into the mesh's.
ACCURACY_SETTINGS = ("rtol", "max_iter", "tie_rtol", "lookahead", "cascade", "precision",
                     "early_decisions", "settle_decisions")
#: Study variable naming, per case, the `ACCURACY_SETTINGS` that differ between its grids.
MIXED = "mixed_settings"


def flag_radii(conv: xr.Dataset) -> tuple[xr.DataArray, xr.DataArray]:
    """The radii [elements] the resolution flags read on the finest and the
    coarsest grid run of each case of `extrapolate_sweep`'s dataset: the
    narrowest pillar's (`SMALLEST`) where the study has it, else the mean
    pillar radius (a study of curves written before it was recorded)."""
    name = SMALLEST if f"{SMALLEST}_finest" in conv else "pillar_radius_elements"
    finest = conv[f"{name}_finest"]
    # a study written before the coarsest radius was: no coarsest flag
    return finest, conv.get(f"{name}_coarsest", xr.full_like(finest, np.inf))


def resolution_flag(finest: float, coarsest: float) -> tuple[str, float] | None:
    """The study's resolution flag and the radius behind it: ("under_resolved",
    finest) where the finest grid's pillar radius [elements] is under
    `UNDER_RESOLVED_RADIUS`, else ("coarsest_under_resolved", coarsest) where
    the fit rests on a coarsest grid under it, else None (NaN counts as
    resolved).  The table and the figure flag alike."""
    if finest < UNDER_RESOLVED_RADIUS:
        return "under_resolved", finest
    if coarsest < UNDER_RESOLVED_RADIUS:
        return "coarsest_under_resolved", coarsest
    return None


def touching_grids(counts: np.ndarray) -> np.ndarray:
    """Where a `TOUCHING` count marks pillars that share an element edge
    (> 0; NaN, a curve written before the count, does not), elementwise."""
    return np.nan_to_num(counts) > 0


#: Relative range of the realised phi over a case's grids beyond which they
#: hold different brushes, not one refined: twice the grid rule's 5 %, which
#: only allow_coarse lets a grid exceed.
PHI_SPREAD_FLAG = 2 * MAX_PHI_ERROR


def phi_spread(phi: np.ndarray) -> float:
    """(max - min) / mean of the realised filling factors of a case's grids
    (the finite ones; NaN where none is)."""
    phi = np.asarray(phi, dtype=float)
    phi = phi[np.isfinite(phi)]
    return float((phi.max() - phi.min()) / phi.mean()) if phi.size else math.nan


def phi_varies(phi: np.ndarray) -> bool:
    """The ``phi_varies`` flag: the grids realise filling factors more than
    `PHI_SPREAD_FLAG` apart (e.g. N = 64 with allow_coarse on 64, 96 and 128:
    0.0625, 0.111, 0.125), so the fit runs through different brushes."""
    return phi_spread(phi) > PHI_SPREAD_FLAG


#: Numeric settings within this factor of each other count as one: a protocol's
#: rtol is scaled per curve by its pillars' stiffness span, which moves a
#: little with the grid (9.89e-5 to 9.91e-5 over 128-256^2 for one brush).
SETTINGS_FACTOR = 1.5


def settings_differ(values: Sequence[str]) -> bool:
    """Whether recorded setting values (text) differ: numbers by more than
    `SETTINGS_FACTOR` (or in sign, or one of them 0), anything else at all."""
    if len(set(values)) < 2:
        return False
    try:
        numbers = np.array([float(v) for v in values])
    except ValueError:
        return True  # text ("local", "global"), or a bool's "True"/"False"
    low, high = np.abs(numbers).min(), np.abs(numbers).max()
    if low == 0 or np.any(np.sign(numbers) != np.sign(numbers[0])):
        return bool(high > 0)
    return bool(high / low > SETTINGS_FACTOR)


def mixed_settings(sweep: xr.Dataset, values: xr.DataArray) -> xr.DataArray | None:
    """Per case, the `ACCURACY_SETTINGS` whose recorded values differ between
    the grids where ``values`` is finite (`settings_differ`), space-separated
    ("" where none do).

    Parameters
    ----------
    sweep : aggregated sweep; its ``run_{name}`` variables (text, present
        only where a setting differs between any of its curves) are read.
    values : a result on (cases..., grid); NaN where a grid was not run.

    Returns
    -------
    xarray.DataArray or None
        Text on the case dimensions; None where the sweep records none of
        the settings as differing.
    """
    names = [n for n in ACCURACY_SETTINGS if f"run_{n}" in sweep]
    if not names:
        return None
    cases = [d for d in values.dims if d != GRID_DIM]
    ran = values.transpose(*cases, GRID_DIM).notnull().values
    differ = []
    for name in names:
        text = sweep[f"run_{name}"].broadcast_like(values).transpose(*cases, GRID_DIM).values
        rows = text.reshape(-1, text.shape[-1])
        differ.append([settings_differ([str(v) for v, r in zip(row, run) if r])
                       for row, run in zip(rows, ran.reshape(rows.shape))])
    out = [" ".join(n for n, d in zip(names, differ) if d[i]) for i in range(len(differ[0]))]
    case = values.isel({GRID_DIM: 0}, drop=True).transpose(*cases)
    text = case.copy(data=np.array(out, dtype=str).reshape(case.shape))
    text.attrs = {"long_name": "accuracy settings that differ between the case's grids "
                               "(space-separated; sweep.nc's run_* give their values); '' "
                               "where none do"}
    return text


#: The case's flags beyond the fit's, as int8 variables of `extrapolate_sweep`
#: (the tables' and the figure's words for the same tests).
CASE_FLAGS = {
    "under_resolved": "the narrowest pillar's radius on the finest grid run is under "
                      f"{UNDER_RESOLVED_RADIUS:g} elements",
    "coarsest_under_resolved": "the finest grid resolves the pillars but the fit's coarsest "
                               f"grid gives them under {UNDER_RESOLVED_RADIUS:g} elements",
    "touching_pillars": "two pillars' footprints share an element edge on some grid run",
    "phi_varies": f"the realised filling factors of the grids run spread by more than "
                  f"{PHI_SPREAD_FLAG:g} of their mean: different brushes, not one refined",
}


def case_flags(conv: xr.Dataset, values: xr.DataArray) -> dict[str, xr.DataArray]:
    """`CASE_FLAGS` of each case of a study (``values``: a result on
    (cases..., grid), NaN where a grid was not run: phi_varies reads its
    grids), int8 on the case dimensions; a flag whose input the study lacks
    (touching counts, the realised phi) is left out.  The tables read them
    per quantity."""
    with np.errstate(invalid="ignore"):  # NaN where a case never ran: no flag
        return _case_flags(conv, values)


def _case_flags(conv: xr.Dataset, values: xr.DataArray) -> dict[str, xr.DataArray]:
    finest, coarsest = flag_radii(conv)
    named = xr.apply_ufunc(lambda f, c: (resolution_flag(f, c) or ("",))[0], finest, coarsest,
                           vectorize=True, output_dtypes=[object])
    tests = {"under_resolved": named == "under_resolved",
             "coarsest_under_resolved": named == "coarsest_under_resolved"}
    if TOUCHING in conv:  # a count exists only where a curve ran (NaN elsewhere)
        tests["touching_pillars"] = xr.apply_ufunc(touching_grids, conv[TOUCHING]).any(GRID_DIM)
    if PHI_ACTUAL in conv:  # over the grids where ``values`` has a value
        tests["phi_varies"] = xr.apply_ufunc(
            lambda phi: phi_varies(phi), conv[PHI_ACTUAL].where(values.notnull()),
            input_core_dims=[[GRID_DIM]], vectorize=True, output_dtypes=[bool])
    return {name: test.astype(np.int8).assign_attrs(
        long_name=f"{CASE_FLAGS[name]} (1 = yes)", units="1",
        flag_values=np.array([0, 1], dtype=np.int8), flag_meanings="no yes")
        for name, test in tests.items()}


@dataclass(frozen=True)
class ConvergenceOptions:
    """Settings of the extrapolation.

    Parameters
    ----------
    min_grids : fewest finite values that give an extrapolation (>= 3: three
        unknowns f0, C, p).
    order_range : (low, high] of plausible observed orders; outside it the
        fit is flagged poor.  brushcore's edge-stress criterion is expected
        near p = 1/2 ... 1 for forces; 0.3 ... 4 leaves room on both sides.
    safety_factor : Roache's Fs of the grid convergence index (1.25 when the
        order is observed from three or more grids and trusted).
    scattered_safety_factor : Fs where the order is not trusted or the values
        are not monotone (3, Roache; Eca & Hoekstra 2014).
    trusted_order : [low, high] of observed orders with which the data are
        taken to be in the asymptotic range: Eca & Hoekstra's 0.5 ... p_th +
        0.1 with the first order p_th = 1 that the edge criterion's mesh error
        shows (measured p of F_ad 0.75-1.35 in the studies; faster observed
        convergence is mostly grid-to-grid scatter):
        ``safety_factor`` inside, ``scattered_safety_factor`` outside.
    max_relative_residual : largest rms residual of the least-squares fit
        (four or more grids), relative to max f - min f, before the fit is
        flagged poor.
    order_bounds : interval searched for p (least squares and uneven
        three-grid roots; its negative for three grids that diverge) [-].
    flat_rtol : successive differences below this fraction of max |f| count
        as zero: the sequence is converged to rounding, f0 = f1, error 0.
    """

    min_grids: int = 3
    order_range: tuple[float, float] = (0.3, 4.0)
    safety_factor: float = 1.25
    scattered_safety_factor: float = 3.0
    trusted_order: tuple[float, float] = (0.5, 1.1)
    max_relative_residual: float = 0.1
    order_bounds: tuple[float, float] = (0.02, 12.0)
    flat_rtol: float = 1e-12

    def trusts(self, order: float | np.ndarray) -> np.ndarray:
        """Whether observed orders lie in `trusted_order` (its low end observed
        to rounding counts: p = 0.5 on exact data), elementwise; NaN is not."""
        low, high = self.trusted_order
        order = np.asarray(order, dtype=float)
        with np.errstate(invalid="ignore"):
            return (low * (1 - 1e-9) <= order) & (order <= high)

    def __post_init__(self) -> None:
        normalise(self, ("min_grids",), ("safety_factor", "scattered_safety_factor",
                                         "max_relative_residual", "flat_rtol"))
        require(is_integer(self.min_grids) and self.min_grids >= 3, "min_grids",
                self.min_grids, "an integer >= 3 (three unknowns f0, C, p)")
        for name in ("order_range", "trusted_order", "order_bounds"):
            pair = getattr(self, name)
            require(isinstance(pair, (tuple, list)) and len(pair) == 2
                    and all(is_real(v) and math.isfinite(v) for v in pair)
                    and 0 <= pair[0] < pair[1] and (name != "order_bounds" or pair[0] > 0),
                    name, pair, "(low, high) with 0 <= low < high"
                    + (", low > 0" if name == "order_bounds" else ""))
            # A list would stay mutable (and unhashable) inside a frozen object.
            object.__setattr__(self, name, (float(pair[0]), float(pair[1])))
        for name in ("safety_factor", "scattered_safety_factor", "max_relative_residual"):
            value = getattr(self, name)
            require(is_real(value) and math.isfinite(value) and value > 0, name, value,
                    "a finite number > 0")
        require(self.safety_factor <= self.scattered_safety_factor, "safety_factor",
                self.safety_factor, f"at most scattered_safety_factor "
                f"({self.scattered_safety_factor:g})")
        require(is_real(self.flat_rtol) and 0 <= self.flat_rtol < 1, "flat_rtol",
                self.flat_rtol, "a number in [0, 1)")


@dataclass(frozen=True)
class Extrapolation:
    """Result of fitting f(h) = f0 + C h^p.

    Attributes
    ----------
    value : extrapolated f0 [units of f]; NaN when flagged meaningless.
    error : half-width U of the uncertainty band about ``value`` (which
        holds ``finest`` too) [units of f]
        (see module doc).
    order : observed order p [-].
    coefficient : C [units of f / units of h^p].
    finest : f on the finest grid used [units of f].
    spread : half range (max f - min f)/2 of the finite values [units of f].
    gci : Roache's grid convergence index of the finest grid [units of f].
    residual : rms residual of the fit [units of f] (0 for three grids).
    n_grids : finite values used.
    safety_factor : Fs the error was built with (1.25 or 3; NaN without an
        error) [-].
    non_monotone, poor_fit, too_few_grids, not_asymptotic : flags (see
        module doc).
    """

    value: float
    error: float
    order: float
    coefficient: float
    finest: float
    spread: float
    gci: float
    residual: float
    n_grids: int
    safety_factor: float
    non_monotone: bool
    poor_fit: bool
    too_few_grids: bool
    not_asymptotic: bool = False

    @property
    def ok(self) -> bool:
        """True when no flag is raised."""
        return not (self.non_monotone or self.poor_fit or self.too_few_grids
                    or self.not_asymptotic)


_NAN = math.nan


def _prepare(h: Sequence[float], f: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Finite (h, f) pairs sorted finest first; checks h."""
    h = np.asarray(h, dtype=np.float64).ravel()
    f = np.asarray(f, dtype=np.float64).ravel()
    if h.shape != f.shape:
        raise ValueError(f"h and f differ in length: {h.size} and {f.size}")
    if np.any(~np.isfinite(h)) or np.any(h <= 0):
        raise ValueError(f"h={h.tolist()} is invalid: allowed finite values > 0")
    keep = ~np.isnan(f)  # NaN: not run; +-inf stays, for the caller to flag
    h, f = h[keep], f[keep]
    order = np.argsort(h)
    h, f = h[order], f[order]
    if np.any(np.diff(h) <= 0):
        raise ValueError(f"h={h.tolist()} is invalid: two grids with the same h")
    return h, f


def is_monotone(f_finest_first: np.ndarray, atol: float = 0.0) -> bool:
    """True when successive differences never change sign (zeros ignored).

    Parameters
    ----------
    f_finest_first : values ordered by increasing h.
    atol : differences with magnitude <= atol count as zero.
    """
    d = np.diff(np.asarray(f_finest_first, dtype=np.float64))
    s = np.sign(np.where(np.abs(d) <= atol, 0.0, d))
    s = s[s != 0]
    return bool(np.all(s == s[0])) if s.size else True


def _ratio_gap(p: float, h: np.ndarray, target: float) -> float:
    """(h3^p - h2^p)/(h2^p - h1^p) - target, with h scaled so h1 = 1."""
    x = h / h[0]
    return (x[2] ** p - x[1] ** p) / (x[1] ** p - 1.0) - target


def _three_grid_order(h: np.ndarray, f: np.ndarray, bounds: tuple[float, float]) -> float:
    """Observed order through three points, negative where the differences
    grow under refinement (as Richardson's closed form gives on even ratios);
    NaN where the values oscillate or no order within ``bounds`` (or their
    negatives) fits."""
    if f[1] == f[0]:
        return _NAN  # the two finest agree beside a third that differs: no order
    target = (f[2] - f[1]) / (f[1] - f[0])
    if not target > 0:
        return _NAN  # oscillation: the caller flags it
    r21, r32 = h[1] / h[0], h[2] / h[1]
    if math.isclose(r21, r32, rel_tol=1e-9):
        return math.log(target) / math.log(r21)  # Richardson's closed form
    # the ratio of differences runs from 0 (p -> -inf) through ln r32 / ln r21
    # (p -> 0) to inf: below that middle the differences grow, p < 0
    lo, hi = bounds if target > math.log(r32) / math.log(r21) else (-bounds[1], -bounds[0])
    g_lo, g_hi = _ratio_gap(lo, h, target), _ratio_gap(hi, h, target)
    if not np.isfinite(g_lo) or not np.isfinite(g_hi) or g_lo * g_hi > 0:
        return _NAN
    return float(optimize.brentq(_ratio_gap, lo, hi, args=(h, target), xtol=1e-12))


def _linear_fit(x: np.ndarray, f: np.ndarray, p: float) -> tuple[float, float, float]:
    """f0, C (for scaled x) and rms residual of f = f0 + C x^p at fixed p."""
    design = np.column_stack([np.ones_like(x), x**p])
    coef, *_ = np.linalg.lstsq(design, f, rcond=None)
    resid = f - design @ coef
    return float(coef[0]), float(coef[1]), float(np.sqrt(np.mean(resid**2)))


def _least_squares_order(x: np.ndarray, f: np.ndarray, bounds: tuple[float, float]) -> float:
    """p minimising the residual of the variable-projection fit (x scaled, x1 = 1)."""
    lo, hi = bounds
    # A log-spaced scan first: the residual can have several minima in p.
    grid = np.geomspace(lo, hi, 241)
    res = np.array([_linear_fit(x, f, p)[2] for p in grid])
    i = int(np.argmin(res))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    if a == b:
        return float(grid[i])
    sol = optimize.minimize_scalar(
        lambda p: _linear_fit(x, f, p)[2], bounds=(a, b), method="bounded",
        options={"xatol": 1e-10},
    )
    return float(sol.x) if sol.fun <= res[i] else float(grid[i])


def _extrapolate_sorted(
    h: np.ndarray, f: np.ndarray, opts: ConvergenceOptions
) -> tuple[float, float, float, float]:
    """(f0, C, p, rms residual) of (1) on sorted finite data, NaN p on failure."""
    x = h / h[0]  # scaled: x1 = 1, so C x^p stays representable for any p
    if h.size == 3:
        p = _three_grid_order(h, f, opts.order_bounds)
        if not np.isfinite(p) or p <= 0:
            return _NAN, _NAN, p, 0.0
        f0 = f[0] + (f[0] - f[1]) / (x[1] ** p - 1.0)
        c_scaled, resid = f[0] - f0, 0.0
    else:
        p = _least_squares_order(x, f, opts.order_bounds)
        f0, c_scaled, resid = _linear_fit(x, f, p)
    return f0, c_scaled / h[0] ** p, p, resid


def extrapolate(
    h: Sequence[float], f: Sequence[float], options: ConvergenceOptions | None = None
) -> Extrapolation:
    """Extrapolate f(h) = f0 + C h^p to h -> 0 with the observed order p.

    Parameters
    ----------
    h : element sizes (any length proportional to h; brushcore uses 1/n) [length].
    f : the result on each grid [any units]; NaN marks a grid not run.
    options : `ConvergenceOptions`; defaults when None.

    Returns
    -------
    Extrapolation
        f0, error, p and the flags.  Flagged cases carry NaN where (1) is
        meaningless, and always the finest value and the raw spread.

    Raises
    ------
    ValueError
        If h and f differ in length, an h is not positive and finite, or two
        grids share an h.
    """
    opts = options or ConvergenceOptions()
    h, f = _prepare(h, f)
    n = int(h.size)
    finest = float(f[0]) if n else _NAN
    spread = float(0.5 * (f.max() - f.min())) if n else _NAN

    def result(value=_NAN, error=_NAN, order=_NAN, coef=_NAN, gci=_NAN, resid=_NAN, fs=_NAN,
               non_monotone=False, poor_fit=False, too_few=False,
               not_asymptotic=False) -> Extrapolation:
        return Extrapolation(float(value), float(error), float(order), float(coef), finest,
                             spread, float(gci), float(resid), n, float(fs),
                             bool(non_monotone), bool(poor_fit), bool(too_few),
                             bool(not_asymptotic))

    if np.any(np.isinf(f)):  # an infinite result is no grid "not run": flag it
        return result(poor_fit=True, too_few=n < opts.min_grids)
    if n < opts.min_grids:
        return result(too_few=True)
    flat = opts.flat_rtol * float(np.max(np.abs(f)))
    if np.all(np.abs(np.diff(f)) <= flat):
        # Converged to rounding: nothing to extrapolate, and no order to observe.
        return result(value=finest, error=0.0, gci=0.0, resid=0.0)
    monotone = is_monotone(f, atol=flat)
    # Four or more grids: does the fine end diverge?  A fit can follow the
    # coarse grids while the three finest move apart ever faster (8 x 8 rigid
    # on 256-2048: p 0.41 over four, differences growing over the finest
    # three).  An oscillating fine end is already non_monotone.
    fine_end = n > 3 and _diverging(h[:3], f[:3], flat)
    if not monotone and n == 3:
        # Three points that oscillate admit no f0 + C h^p with p > 0.
        return result(non_monotone=True)

    f0, coef, p, resid = _extrapolate_sorted(h, f, opts)
    if n > 3 and not opts.order_bounds[0] * (1 + 1e-6) < p < opts.order_bounds[1] * (1 - 1e-6):
        p = _NAN  # the least squares ran into its search bound: no order was observed
    if not np.isfinite(p) or p <= 0:
        # Differences grow under refinement: no limit exists.  A negative
        # observed order (constant ratio) is still reported: it says how fast;
        # an infinite one (two equal values beside a third) is not an order.
        return result(order=p if np.isfinite(p) else _NAN, resid=resid,
                      non_monotone=not monotone, poor_fit=True, not_asymptotic=fine_end)
    lo, hi = opts.order_range
    scale = float(f.max() - f.min())
    poor = not (lo < p <= hi) or resid > opts.max_relative_residual * scale
    trusted = bool(opts.trusts(p))
    t_lo, t_hi = opts.trusted_order
    orders = (p,) if trusted else (p, min(max(p, t_lo), t_hi))
    fs = (opts.safety_factor if trusted and monotone and not fine_end
          else opts.scattered_safety_factor)
    # Roache's GCI of the finest grid, from the two finest values.
    gci = fs * max(abs(f[0] - f[1]) / ((h[1] / h[0]) ** q - 1.0) for q in orders)
    if n == 3:
        error = gci
    else:
        # Eca & Hoekstra (2014): U = Fs |fit(h1) - f0| + sigma + |f1 - fit(h1)|,
        # sigma the standard deviation of the fit.
        fit1 = f0 + coef * h[0] ** p
        sigma = resid * math.sqrt(n / (n - 3))
        x = h / h[0]
        correction = max(abs(c) for c in (fit1 - f0, *(
            _linear_fit(x, f, q)[1] for q in orders[1:])))  # C x1^q = fit(h1) - f0
        error = fs * correction + sigma + abs(f[0] - fit1)
    if poor:
        # Report the order that was observed, but no limit built on it, nor
        # a GCI (on three grids the error, which is NaN here).
        return result(order=p, coef=coef, resid=resid, non_monotone=not monotone,
                      poor_fit=True, not_asymptotic=fine_end)
    return result(value=f0, error=error, order=p, coef=coef, gci=gci, resid=resid, fs=fs,
                  non_monotone=not monotone, not_asymptotic=fine_end)


def _diverging(h: np.ndarray, f: np.ndarray, flat: float) -> bool:
    """Whether three monotone values (finest first) move apart ever faster
    under refinement: no positive observed order.

    Decided without solving for the order, which a search bound would cut:
    (h3^p - h2^p) / (h2^p - h1^p) grows with p from ln(h3/h2) / ln(h2/h1)
    at p -> 0, so a positive order exists exactly when the differences'
    ratio (f3 - f2) / (f2 - f1) lies above that (above 1 on doubling
    grids).  Two finest values that agree beside a third converge.
    """
    if np.all(np.abs(np.diff(f)) <= flat) or not is_monotone(f, atol=flat):
        return False
    if f[1] == f[0]:
        return False
    ratio = (f[2] - f[1]) / (f[1] - f[0])
    return not ratio > math.log(h[2] / h[1]) / math.log(h[1] / h[0])


# ---------------------------------------------------------------------------
# Sweep datasets
# ---------------------------------------------------------------------------

#: Per-quantity outputs of `extrapolate_sweep`: suffix -> (long-name template, is_flag).
_OUTPUTS = {
    "extrapolated": ("{q} extrapolated to h -> 0", False),
    "error": ("half-width U of the uncertainty band about the extrapolated {q} (Roache's "
              "GCI or after Eca & Hoekstra); the band also holds the finest {q}", False),
    "order": ("observed order p of {q} = f0 + C h^p", False),
    "coefficient": ("coefficient C of {q} = f0 + C h^p, h = 1/n", False),
    "finest": ("{q} on the finest grid run", False),
    "spread": ("half range of {q} over the grids", False),
    "gci": ("grid convergence index of the finest {q}, absolute (Roache; Fs 1.25 at a "
            "trusted order, else 3 on the larger correction of the observed and the nearest "
            "trusted order; on three grids it is the error itself)", False),
    "n_grids": ("grids with a value of {q} (not NaN)", False),
    "safety_factor": ("safety factor Fs of the {q} error (1.25 at a trusted order, else 3)",
                      False),
    "non_monotone": ("{q} oscillates under refinement (1 = yes)", True),
    "poor_fit": ("{q} does not follow f0 + C h^p with a plausible order (1 = yes)", True),
    "too_few_grids": ("fewer than {min_grids} grids with a finite {q} (1 = yes)", True),
    "not_asymptotic": ("{q} on the three finest grids moves apart ever faster (their "
                       "differences grow under refinement; 1 = yes)", True),
}


def _apply(values: np.ndarray, h: np.ndarray, opts: ConvergenceOptions) -> tuple[float, ...]:
    e = extrapolate(h, values, opts)
    return (e.value, e.error, e.order, e.coefficient, e.finest, e.spread, e.gci,
            float(e.n_grids), e.safety_factor, float(e.non_monotone), float(e.poor_fit),
            float(e.too_few_grids), float(e.not_asymptotic))


def _end_index(values: np.ndarray, end: int) -> int:
    """Index (along grid, ascending n) of the coarsest (``end`` 0) or finest
    (``end`` -1) finite value, -1 if none."""
    idx = np.flatnonzero(~np.isnan(values))  # an inf is a value (flagged), not a grid not run
    return int(idx[end]) if idx.size else -1


def _end_grid(sweep: xr.Dataset, values: xr.DataArray,
              position: int) -> tuple[xr.DataArray, xr.DataArray]:
    """Per case, the index along ``grid`` and the n of the coarsest (``position``
    0) or finest (-1) grid where ``values`` is finite (-1 and NaN where none)."""
    at = xr.apply_ufunc(_end_index, values, kwargs={"end": position},
                        input_core_dims=[[GRID_DIM]], vectorize=True, output_dtypes=[np.int64])
    grid_n = xr.where(at >= 0, sweep[GRID_DIM].isel({GRID_DIM: at.clip(min=0)}, drop=True),
                      np.nan)
    return at, grid_n.astype(np.float64)


def extrapolate_sweep(
    sweep: xr.Dataset,
    quantities: Sequence[str] = QUANTITIES,
    options: ConvergenceOptions | None = None,
) -> xr.Dataset:
    """Extrapolate every case of a sweep to h -> 0 along its ``grid`` dimension.

    Parameters
    ----------
    sweep : aggregated sweep with a ``grid`` dimension (coordinate: elements
        per side n) beside the case dimensions (layout, n_pillars, kbar, seed,
        and any other); NaN where a combination was not run.  If it holds
        ``pillar_radius_elements`` (same dims) that is used, else the nominal
        radius n sqrt(phi / (pi N)) with the ``phi`` coordinate or attribute.
    quantities : variables to extrapolate.
    options : `ConvergenceOptions`; defaults when None.

    Returns
    -------
    xarray.Dataset
        On the case dimensions: ``{q}_extrapolated``, ``{q}_error``,
        ``{q}_order``, ``{q}_coefficient``, ``{q}_finest`` (on
        ``{q}_finest_grid``), ``{q}_spread``, ``{q}_gci``, ``{q}_n_grids``,
        ``{q}_safety_factor`` and the int8 flags ``{q}_{flag}`` for each of
        `FIT_FLAGS`; the raw values ``{q}`` on (cases..., grid);
        ``finest_grid`` and ``pillar_radius_elements_finest`` of the finest
        grid run (first quantity), ``pillar_radius_elements_coarsest`` of the
        coarsest, and ``smallest_radius_elements_{finest,coarsest}`` where the
        sweep has the narrowest pillar's radius (`flag_radii`); ``h`` = 1/n
        on ``grid``; ``touching_pillar_pairs`` and ``phi_actual`` on
        (cases..., grid) where the sweep has them; ``{q}_untrusted_order``
        (`ORDER_FLAG`); ``mixed_settings`` (`mixed_settings`) where the
        sweep's curves differ in an accuracy setting; the int8 case flags
        of `case_flags`.

    Raises
    ------
    ValueError
        If the sweep has no ``grid`` dimension or lacks a quantity.
    """
    opts = options or ConvergenceOptions()
    if GRID_DIM not in sweep.dims:
        raise ValueError(f"the sweep has no '{GRID_DIM}' dimension (dims: {dict(sweep.sizes)})")
    missing = [q for q in quantities if q not in sweep]
    if missing:
        raise ValueError(f"the sweep lacks {missing}")
    sweep = sweep.sortby(GRID_DIM)
    n = sweep[GRID_DIM].astype(np.float64)
    h = xr.DataArray(1.0 / n.values, dims=GRID_DIM, coords={GRID_DIM: sweep[GRID_DIM]},
                     attrs={"units": "1", "long_name": "element size h / L = 1/n"})
    out: dict[str, xr.DataArray] = {}
    for q in quantities:
        raw = sweep[q]
        results = xr.apply_ufunc(
            _apply, raw, kwargs={"h": h.values, "opts": opts},
            input_core_dims=[[GRID_DIM]], output_core_dims=[[]] * len(_OUTPUTS),
            vectorize=True, output_dtypes=[np.float64] * len(_OUTPUTS),
        )
        units = raw.attrs.get("units", "1")
        for (suffix, (long_name, is_flag)), da in zip(_OUTPUTS.items(), results):
            attrs = {"long_name": long_name.format(q=q, min_grids=opts.min_grids)}
            if is_flag:
                da = da.astype(np.int8)
                attrs.update(units="1", flag_values=np.array([0, 1], dtype=np.int8),
                             flag_meanings="no yes")
            elif suffix in ("order", "n_grids", "safety_factor"):
                attrs["units"] = "1"
            else:
                attrs["units"] = units  # h = 1/n is dimensionless, so C has q's units
            out[f"{q}_{suffix}"] = da.assign_attrs(attrs)
        # The scattered safety factor for an untrusted order alone: poor fits
        # have no error, and the other flags name their own cause.
        order = out[f"{q}_order"]
        others = sum(out[f"{q}_{f}"] for f in ("poor_fit", "non_monotone", "not_asymptotic"))
        trusted = order.copy(data=opts.trusts(order.values))
        untrusted = np.isfinite(order) & (others == 0) & ~trusted
        out[f"{q}_{ORDER_FLAG}"] = untrusted.astype(np.int8).assign_attrs(
            long_name=f"observed order of {q} outside the trusted range "
                      f"{list(opts.trusted_order)} and no other flag raised, so its error "
                      f"carries Fs {opts.scattered_safety_factor:g} (1 = yes)", units="1",
            flag_values=np.array([0, 1], dtype=np.int8), flag_meanings="no yes")
        out[q] = raw.copy()
        # {q}_finest comes from here: NaN on a grid where the other quantity
        # is finite (a protocol without retraction has no W) moves it
        out[f"{q}_finest_grid"] = _end_grid(sweep, raw, -1)[1].assign_attrs(
            units="1", long_name=f"elements per side n of the finest grid with a finite {q}")
    # Finest and coarsest grid run per case (finite first quantity), and their
    # resolution: the fit rests on the coarsest as much as on the finest.
    anyq = sweep[quantities[0]]
    for end, position in (("finest", -1), ("coarsest", 0)):
        at, grid_n = _end_grid(sweep, anyq, position)
        idx = at.clip(min=0)
        if end == "finest":
            out["finest_grid"] = grid_n.assign_attrs(
                units="1", long_name=f"elements per side n of the finest grid run (with a "
                                     f"finite {quantities[0]})")
        if "pillar_radius_elements" in sweep:
            rad = sweep["pillar_radius_elements"].isel({GRID_DIM: idx}, drop=True)
            rad = xr.where(at >= 0, rad, np.nan)
        else:
            phi = sweep["phi"] if "phi" in sweep.coords else float(sweep.attrs.get("phi", np.nan))
            rad = grid_n * np.sqrt(phi / (np.pi * sweep["n_pillars"].astype(np.float64)))
        out[f"pillar_radius_elements_{end}"] = rad.assign_attrs(
            units="1", long_name=f"pillar radius a_p / h on the {end} grid run [elements]")
        if SMALLEST in sweep:  # unequal or elliptic pillars: the narrowest sets the error
            small = sweep[SMALLEST].isel({GRID_DIM: idx}, drop=True)
            out[f"{SMALLEST}_{end}"] = xr.where(at >= 0, small, np.nan).assign_attrs(
                units="1", long_name=f"the narrowest pillar's radius / h on the {end} grid "
                                     "run [elements], which the resolution flags read")
    if TOUCHING in sweep:  # random discs on grids coarser than 512: a mesh error to see
        out[TOUCHING] = sweep[TOUCHING].copy()
    if PHI_ACTUAL in sweep:  # the staircase's filling factor moves F_ad from grid to grid
        out[PHI_ACTUAL] = sweep[PHI_ACTUAL].copy()
    mixed = mixed_settings(sweep, anyq)
    if mixed is not None:  # e.g. one grid at rtol 1e-3: its solver error joins the mesh's
        out[MIXED] = mixed
    ds = xr.Dataset(out).assign_coords(h=h)
    ds = ds.assign(case_flags(ds, anyq))
    ds.attrs = {
        "title": "brushcore mesh-refinement study: results extrapolated to h -> 0",
        "Conventions": "CF-1.10",
        "comment": ("f(h) = f0 + C h^p with the observed order p; error = half-width of "
                    "a band about f0: Roache's GCI (3 grids) or a least-squares uncertainty "
                    "after Eca & Hoekstra (>= 4 grids); f0 is NaN where a flag makes the fit "
                    "meaningless. The error covers the mesh only: a random brush is one "
                    "realisation (its seed), and the scatter between seeds (random 64 at "
                    "256^2: 1.8 % rigid, 4.0 % at kbar 1e-4, SD of F_ad over 3 seeds) is "
                    "not in it"),
        "references": ("Roache (1998); Celik et al., J. Fluids Eng. 130 (2008) 078001; "
                       "Eca & Hoekstra, J. Comput. Phys. 262 (2014) 104; "
                       "Stern et al., J. Fluids Eng. 123 (2001) 793"),
        "order_range": f"({opts.order_range[0]}, {opts.order_range[1]}]",
        "safety_factor": opts.safety_factor,
        "scattered_safety_factor": opts.scattered_safety_factor,
        "trusted_order": f"[{opts.trusted_order[0]}, {opts.trusted_order[1]}]",
        "max_relative_residual": opts.max_relative_residual,
        "min_grids": opts.min_grids,
        "under_resolved_radius_elements": UNDER_RESOLVED_RADIUS,
        **_provenance(sweep),
    }
    return ds


def _provenance(sweep: xr.Dataset) -> dict[str, object]:
    """History, version and the sweep this study was extrapolated from, so
    that an extrapolated value can be traced back to its curve files."""
    now = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    grids = ", ".join(str(int(g)) for g in sweep[GRID_DIM].values)
    out: dict[str, object] = {
        "history": f"{now} extrapolated over grids {grids} by brushcore.data.convergence"
                   + (f"\n{sweep.attrs['history']}" if "history" in sweep.attrs else ""),
        "date_created": now,
        "brushcore_version": provenance.version(),
        "git_commit": provenance.git_commit(),
        "source": provenance.source(),
    }
    if "source_digest_sha256" in sweep.attrs:
        out["sweep_source_digest_sha256"] = sweep.attrs["source_digest_sha256"]
    if "simulation_git_commits" in sweep.attrs:  # the code of the curves, not of this study
        out["simulation_git_commits"] = sweep.attrs["simulation_git_commits"]
    # Not the sweep's units_convention ("h in m"): every value here is
    # normalised, and the coordinate h is h / L = 1/n.
    for name in ("e_star", "dgamma"):
        if name in sweep.attrs:
            out[name] = sweep.attrs[name]
    return out


#: A study's grid numbers and counts, stored as integers (NaN where none ran:
#: the fill; ``{q}_n_grids`` 0 there).
INTEGER_SUFFIXES = ("finest_grid", "n_grids")


def _ran(conv: xr.Dataset, name: str) -> xr.DataArray | None:
    """Where the cases of flag ``name`` have values: a quantity's flag where
    that quantity has a value on some grid (``{q}_n_grids`` > 0), a case flag
    where any grid ran (``finest_grid``); None where the study lacks it."""
    for q in QUANTITIES:
        if name.startswith(f"{q}_") and f"{q}_n_grids" in conv:
            return conv[f"{q}_n_grids"] > 0
    return conv["finest_grid"].notnull() if "finest_grid" in conv else None


def write_dataset(conv: xr.Dataset, path: str | Path) -> None:
    """Write `extrapolate_sweep`'s dataset (or a part of it) to netCDF4 atomically.

    CF: no fill on coordinates; flags as int8 with the fill -1 where their
    case has no value (a flag of 0 there would read as a case that passed),
    grid numbers and counts as int64 with the fill -1, which xarray reads
    back as NaN; ``{q}_n_grids`` is 0 there, a true count.
    """
    from brushcore.data.aggregate import COUNT_VARIABLES
    from brushcore.data.io import write_dataset_atomic

    out = conv.copy()
    enc: dict[str, dict[str, object]] = {name: {"_FillValue": None} for name in conv.coords}
    for name, var in conv.data_vars.items():
        ran = _ran(conv, name) if var.dtype == np.int8 else None
        if ran is not None and set(var.dims) >= set(ran.dims):
            out[name] = var.where(ran).assign_attrs(var.attrs)
            enc[name] = {"dtype": "int8", "_FillValue": np.int8(-1)}
        elif name.endswith(INTEGER_SUFFIXES) or name in COUNT_VARIABLES:
            # one type however the study was run (from a file's sweep or in memory)
            enc[name] = {"dtype": "int64", "_FillValue": np.int64(-1)}
    write_dataset_atomic(out, path, enc)
