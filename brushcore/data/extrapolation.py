"""Extrapolate one result to h -> 0 with its observed order (a mesh-refinement fit).

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
    With 0.3 % scatter: 85-99.8 % and 93-99 % (p 0.7-1.5; 65-94 % and
    89-99 % before `steep_order`'s floor), of the 57-81 % and 65-91 % of
    fits kept: three grids cannot tell that much scatter from mesh error;
    use four or more.  Read about f1, f1 +- U holds the limit
    in 97-100 % at p >= 1, but 38-70 % (3 grids) at p 0.5-0.7.
  - Above ``steep_order`` (2) the error is at least the full range of the
    values, max f - min f: an observed order that steep is mostly two values
    lying close by chance, and the correction shrinks with their difference
    (a referee's draws, 256/512/1024, 0.3 % scatter, true p 0.5-1.5: the
    kept three-grid bands with observed p in (2, 3] held the limit in 59 %,
    in (3, 4] in 20 %, a quarter of the fits kept; with the floor 93 % of
    all kept bands against 82 %, every fit still kept; real curves do it:
    regular 16 rigid on 256/384/768, p 3.7, 1.5524 +- 0.0121 where fits
    that include 1024^2 put the limit at 1.49-1.54; +- 0.0222 with the floor).
    It applies to four or more grids too, where such orders are rarer.
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
  `brushcore.data.convergence.extrapolate_sweep` adds ``untrusted_order`` (an order outside
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

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from brushcore.validation import is_integer, is_real, normalise, require

#: The fit's flags, as `Extrapolation` fields and ``{q}_{flag}`` variables.
FIT_FLAGS = ("non_monotone", "poor_fit", "too_few_grids", "not_asymptotic")
#: A fit whose observed order lies outside `ConvergenceOptions.trusted_order`
#: and that no other flag explains: its error carries Fs 3 for that alone.
ORDER_FLAG = "untrusted_order"


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
    steep_order : above this observed order the error is at least the full
        range of the values (module doc) [-].
    """

    min_grids: int = 3
    order_range: tuple[float, float] = (0.3, 4.0)
    safety_factor: float = 1.25
    scattered_safety_factor: float = 3.0
    trusted_order: tuple[float, float] = (0.5, 1.1)
    max_relative_residual: float = 0.1
    order_bounds: tuple[float, float] = (0.02, 12.0)
    flat_rtol: float = 1e-12
    steep_order: float = 2.0

    def trusts(self, order: float | np.ndarray) -> np.ndarray:
        """Whether observed orders lie in `trusted_order` (its low end observed
        to rounding counts: p = 0.5 on exact data), elementwise; NaN is not."""
        low, high = self.trusted_order
        order = np.asarray(order, dtype=float)
        with np.errstate(invalid="ignore"):
            return (low * (1 - 1e-9) <= order) & (order <= high)

    def __post_init__(self) -> None:
        normalise(self, ("min_grids",), ("safety_factor", "scattered_safety_factor",
                                         "max_relative_residual", "flat_rtol",
                                         "steep_order"))
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
        require(is_real(self.steep_order) and self.steep_order > 0, "steep_order",
                self.steep_order, "a number > 0 (inf: no floor)")


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
    h : element sizes, in any unit proportional to h (brushcore uses 1/n,
        dimensionless).
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
    if p > opts.steep_order:  # two values close by chance, not fast convergence
        error = max(error, scale)
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
