"""Headline numbers of a sweep beside the paper's (He, Li & Popov 2020, §4).

The reductions used by both the summary table and the figures live here:
averaging over seeds, the soft-plateau value, where the plateau starts, and
the N^(1/4) prefactor fit.  Everything works on whatever part of the paper's
grid a sweep contains; a missing case gives NaN here and "n/a" in the table.
On a sweep over several grids every case is taken at the finest grid it ran
on (`brushcore.data.views.finest_grid`), and the table says how many elements
a pillar radius spans there, marking fewer than 4 as under-resolved.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import astuple, dataclass, fields
from pathlib import Path

import numpy as np
import xarray as xr
from scipy import stats

from brushcore.model import theory
from brushcore.model.layout import pillars_differ
from brushcore.data.aggregate import GRID_DIM
from brushcore.data.io import markdown_table, write_text_atomic
from brushcore.data.views import (finest_grid, flat_slice, kbar_index, phi_note, phi_slice,
                                  shape_slice, without_brushes_as_made)
from brushcore.data.convergence import SMALLEST, UNDER_RESOLVED_RADIUS

#: F_ad within this relative distance of the soft plateau counts as on it.
PLATEAU_RTOL = 0.05
NOT_AVAILABLE = "n/a"


def seed_mean(sweep: xr.Dataset, name: str, layout: str, n_pillars: int) -> xr.DataArray:
    """One variable against kbar for one brush, averaged over the seeds run.

    Returns
    -------
    xarray.DataArray
        Indexed by kbar, only where at least one seed ran (may be empty).
    """
    if layout not in sweep.layout or n_pillars not in sweep.n_pillars:
        return xr.DataArray(np.array([]), dims="kbar", coords={"kbar": np.array([])})
    if GRID_DIM in sweep.dims:  # only the variables needed, not the padded curves
        keep = list(dict.fromkeys([name, "adhesive_force_normalized"]))
        sweep = finest_grid(sweep[keep])
    values = sweep[name].sel(layout=layout, n_pillars=n_pillars)
    return values.mean("seed", skipna=True).dropna("kbar")


def seed_note(sweep: xr.Dataset, name: str, layout: str, n_pillars: int, kbar: float) -> str:
    """How many seeds a random brush's seed mean rests on, and their scatter,
    as a note: "" for a sweep of one seed or another layout; else "F_ad mean
    of k seeds m, SD s, 95 % t-interval of that mean +- t s / sqrt(k)" (sample SD,
    Student's t with k - 1 degrees of freedom: 4.30 for three seeds, not
    1.96), saying when seeds are missing."""
    if sweep.sizes.get("seed", 1) < 2 or layout != "random" or layout not in sweep.layout:
        return ""  # flat lattices run seed 0 only: nothing drawn, nothing missing
    runs = sweep[name].sel(layout=layout, n_pillars=n_pillars)
    at = kbar_index(runs.kbar.values, kbar)
    if at is None:
        return ""
    values = runs.isel(kbar=at).values.ravel()
    values = values[np.isfinite(values)]
    k, total = int(values.size), int(sweep.sizes["seed"])
    missing = f" ({total - k} of {total} seeds missing)" if k < total else ""
    if k < 2:
        return f"; F_ad of {k} seed{missing}"
    sd = float(np.std(values, ddof=1))
    half = float(stats.t.ppf(0.975, k - 1)) * sd / math.sqrt(k)
    # the mean itself: a row whose value is N^1/4 / F_ad shows a different number
    return (f"; F_ad mean of {k} seeds {_fmt(float(values.mean()), 4)}, SD {_fmt(sd, 2)}, "
            f"95 % t-interval of that mean +- {_fmt(half, 2)}" + missing)


def value_at(sweep: xr.Dataset, name: str, layout: str, n_pillars: int, kbar: float) -> float:
    """Seed-averaged value of one case, NaN when the case was not run."""
    series = seed_mean(sweep, name, layout, n_pillars)
    at = kbar_index(series.kbar.values, kbar)
    return math.nan if at is None else float(series.values[at])


def rigid_end(sweep: xr.Dataset, layout: str, n_pillars: int) -> tuple[float, float]:
    """(kbar, F_ad) at the stiffest kbar run, the numerical rigid limit."""
    series = seed_mean(sweep, "adhesive_force_normalized", layout, n_pillars)
    if series.size == 0:
        return math.nan, math.nan
    return float(series.kbar[-1]), float(series[-1])


def soft_plateau(sweep: xr.Dataset, layout: str, n_pillars: int) -> tuple[float, float]:
    """(kbar, F_ad) at the softest kbar run, taken as the soft plateau."""
    series = seed_mean(sweep, "adhesive_force_normalized", layout, n_pillars)
    if series.size == 0:
        return math.nan, math.nan
    return float(series.kbar[0]), float(series[0])


def on_plateau(sweep: xr.Dataset, layout: str, n_pillars: int,
               rtol: float = PLATEAU_RTOL) -> bool:
    """Whether the softest kbar run lies on the soft plateau: the next softest
    gives F_ad within ``rtol`` of it (False with fewer than two kbar: a
    plateau cannot be told from one point, nor from a sweep that stops short
    of it)."""
    series = seed_mean(sweep, "adhesive_force_normalized", layout, n_pillars)
    return series.size >= 2 and abs(float(series[1]) - float(series[0])) <= rtol * abs(
        float(series[0]))


#: N the paper ran per layout (its Figs. 6-8): its numbers are quoted beside these only.
PAPER_BRUSHES = {"regular": (64, 256, 576, 2304), "random": (64, 220, 425, 1620)}
#: kbar above which the paper calls pillars rigid (its Fig. 6 and §4).
PAPER_RIGID_KBAR = 1.0


def plateau_onset(
    sweep: xr.Dataset, layout: str, n_pillars: int, rtol: float = PLATEAU_RTOL
) -> float:
    """Largest kbar below which F_ad stays within `rtol` of the soft plateau.

    The plateau value is F_ad at the softest kbar run.  NaN with fewer than
    two kbar values (a plateau cannot be told from one point).
    """
    series = seed_mean(sweep, "adhesive_force_normalized", layout, n_pillars)
    if series.size < 2:
        return math.nan
    plateau = float(series[0])
    onset = float(series.kbar[0])
    for kbar, force in zip(series.kbar.values, series.values):
        if abs(force - plateau) > rtol * abs(plateau):
            break
        onset = float(kbar)
    return onset


def fit_soft_prefactor(n_pillars: Sequence[float], force: Sequence[float]) -> dict[str, float]:
    """Fit F = c N^(1/4) (and, with >= 2 distinct N, F = c' N^p) in log space.

    Returns
    -------
    dict
        ``prefactor`` c, ``ratio`` 1/c (the paper's "1.2 to 1.3"),
        ``exponent`` p and ``free_prefactor`` c' (NaN when not fittable).
    """
    n = np.asarray(n_pillars, dtype=float)
    f = np.asarray(force, dtype=float)
    ok = np.isfinite(n) & np.isfinite(f) & (n > 0) & (f > 0)
    n, f = n[ok], f[ok]
    out = {"prefactor": math.nan, "ratio": math.nan, "exponent": math.nan,
           "free_prefactor": math.nan}
    if n.size == 0:
        return out
    log_c = float(np.mean(np.log(f) - np.log(np.asarray(theory.soft_limit(n)))))
    out["prefactor"] = math.exp(log_c)
    out["ratio"] = math.exp(-log_c)
    if np.unique(n).size >= 2:
        slope, intercept = np.polyfit(np.log(n), np.log(f), 1)
        out["exponent"] = float(slope)
        out["free_prefactor"] = math.exp(float(intercept))
    return out


@dataclass(frozen=True)
class Row:
    """One line of the summary table (values already formatted as text)."""

    quantity: str
    layout: str
    n_pillars: str
    kbar: str
    value: str
    paper: str
    note: str


def _fmt(value: float, digits: int = 3) -> str:
    if value is None or math.isnan(value):
        return NOT_AVAILABLE
    return f"{value:.{digits}g}"  # inf stays "inf": kbar = inf is a rigid run, not a gap


def _brushes(sweep: xr.Dataset) -> list[tuple[str, int]]:
    return [(str(lay), int(n)) for lay in sweep.layout.values for n in sweep.n_pillars.values
            if seed_mean(sweep, "adhesive_force_normalized", str(lay), int(n)).size]


def _hexagonal_note(layout: str, n: int, phi: float) -> str:
    """For a hexagonal brush, its rigid limit at its local filling factor."""
    if layout != "hexagonal" or not math.isfinite(phi):
        return ""
    return (f"; its lattice's (phi/fill)^-1/4 = {_fmt(theory.hexagonal_rigid_limit(phi, n))} "
            "(approximate)")


def headline_rows(
    sweep: xr.Dataset, *, fig5_layout: str = "regular", fig5_n_pillars: int = 256,
    fig5_kbar: float = 0.455, fig5_shape: str = "disc"
) -> list[Row]:
    """The paper's headline numbers and ours, one `Row` each.

    Parameters
    ----------
    sweep : dataset from `brushcore.data.aggregate.build_sweep`; its flat
        brushes enter (`brushcore.data.views.flat_slice`), discs except
        for the Fig. 5a row.
    fig5_layout, fig5_n_pillars, fig5_kbar, fig5_shape : the config's Fig. 5
        brush at its first kbar (a `shape_label` for the shape); the
        paper's, quoted in its text, is regular 16 x 16 discs at 0.455.
        A NaN kbar (a config without a Fig. 5 brush) leaves its row out.
        Of a sweep of several phi, the rows are of one (`phi_slice`: the
        one nearest the paper's 0.12), which the rigid-limit row names.
    """
    sweep = phi_slice(sweep)
    phi = float(sweep.attrs.get("phi", math.nan))
    scalars = [v for v in sweep.data_vars if "step" not in sweep[v].dims and "case" not in
               sweep[v].dims]
    full = sweep[scalars]  # the graded cases' rows (`spread_rows`) read the rough dimensions
    fig5 = finest_grid(flat_slice(sweep[scalars], fig5_shape))
    sweep = finest_grid(flat_slice(sweep[scalars]))
    rigid_theory = theory.rigid_limit(phi) if math.isfinite(phi) else math.nan
    papers = (fig5_layout == "regular" and fig5_shape == "disc" and fig5_n_pillars == 256
              and math.isclose(fig5_kbar, 0.455, rel_tol=1e-9))
    rows = []
    if not math.isnan(fig5_kbar):  # NaN: fig5.kbar [] ran no Fig. 5 brush
        rows.append(Row(
            "F_ad (normalised), Fig. 5a", fig5_layout, str(fig5_n_pillars), _fmt(fig5_kbar),
            _fmt(value_at(fig5, "adhesive_force_normalized", fig5_layout, fig5_n_pillars,
                          fig5_kbar)), "~1.8" if papers else "",
            "close to the rigid limit" if papers else
            f"the config's Fig. 5 brush ({fig5_shape} pillars); the paper's ~1.8 is regular "
            "16 x 16 discs at kbar 0.455"))
    phi_text = f"phi = {_fmt(phi)} requested" + (
        f" (every row: {shown} shown)" if (shown := phi_note(sweep)) else "")
    if not math.isfinite(phi) and "phi_actual" in sweep:  # tables: each its own phi
        realised = sweep["phi_actual"].values
        if np.isfinite(realised).any():
            low, high = np.nanmin(realised), np.nanmax(realised)
            rigid_theory = float(theory.rigid_limit(float(np.nanmean(realised))))
            phi_text = (f"phi = {_fmt(float(np.nanmean(realised)))} realised, the mean over "
                        "the brushes" + (f" ({_fmt(low)}-{_fmt(high)})" if high > low else ""))
    rows.append(Row("rigid limit phi^-1/4 (eq. 5)", "", "", "", _fmt(rigid_theory), "1.7",
                    phi_text))
    brushes = _brushes(sweep)
    for layout, n in brushes:
        kbar, force = rigid_end(sweep, layout, n)
        rigid = kbar > PAPER_RIGID_KBAR
        rows.append(Row("F_ad at the stiffest kbar (rigid limit)", layout, str(n), _fmt(kbar),
                        _fmt(force), "slightly above 1.7" if rigid and _papers(layout, n) else "",
                        ("Fig. 6, kbar > 1" if rigid else
                         f"NOT RIGID: the stiffest kbar run is {_fmt(kbar)}, the paper's rigid "
                         f"range is kbar > {PAPER_RIGID_KBAR:g}")
                        + _hexagonal_note(layout, n, phi)
                        + seed_note(sweep, "adhesive_force_normalized", layout, n, kbar)))
    plateau: dict[str, list[tuple[int, float]]] = {}  # layout -> (N, F_ad) on the plateau
    reached_by = {(layout, n): on_plateau(sweep, layout, n) for layout, n in brushes}
    for layout, n in brushes:
        kbar, force = soft_plateau(sweep, layout, n)
        reached = reached_by[layout, n]
        if reached:  # only plateau values enter the fit
            plateau.setdefault(layout, []).append((n, force))
        rows.append(Row("N^1/4 / F_ad on the soft plateau (softest kbar)", layout, str(n),
                        _fmt(kbar), _fmt(float(theory.soft_limit(n)) / force),
                        "1.2-1.3" if reached and _papers(layout, n) else "",
                        ("Fig. 7" if reached else
                         f"NOT ON THE PLATEAU: the two softest kbar differ by more than "
                         f"{PLATEAU_RTOL:.0%}; run softer kbar (left out of the fit)")
                        + seed_note(sweep, "adhesive_force_normalized", layout, n, kbar)))
    # One fit per layout: pooled, a layout's prefactor offset would enter the slope.
    for layout in dict.fromkeys(layout for layout, _ in brushes):
        points = plateau.get(layout, [])
        fit = fit_soft_prefactor([n for n, _ in points], [f for _, f in points])
        of = sum(1 for lay, _ in brushes if lay == layout)
        # the paper's range is of its brushes: beside a fit resting on them only
        papers = bool(points) and all(_papers(layout, n) for n, _ in points)
        rows.append(Row("N^1/4 / F_ad, fit over N", layout, "", "", _fmt(fit["ratio"]),
                        "1.2-1.3" if papers else "",
                        f"free power-law exponent {_fmt(fit['exponent'])} (eq. 6: 0.25); "
                        f"{len(points)} of {of} brushes on the plateau"))
    big = seed_mean(sweep, "adhesive_force_normalized", "regular", 2304)
    enhancement = float(big.max()) if big.size else math.nan
    ran = math.isfinite(enhancement)
    if "regular" in sweep.layout.values:  # a sweep of tables or random brushes: no row
        rows.append(Row("enhancement F_ad / F_K, 2304 pillars (max over kbar)", "regular",
                        "2304", "", _fmt(enhancement), "~6" if ran else "",
                        "Fig. 6a soft plateau" if ran else "not run"))
    for layout, n in brushes:
        rows.append(_resolution_row(sweep, layout, n))
    paper_onset = {64: "~1e-3", 2304: "~1e-5"}
    for layout, n in brushes:
        reached = reached_by[layout, n]
        onset = plateau_onset(sweep, layout, n)
        kbars = seed_mean(sweep, "adhesive_force_normalized", layout, n).kbar.values
        on_all = reached and kbars.size > 0 and onset == float(kbars.max())
        rows.append(Row(f"kbar where the soft plateau is reached (within {PLATEAU_RTOL:.0%})",
                        layout, str(n), "",
                        _fmt(onset, 2) if reached else NOT_AVAILABLE,
                        paper_onset.get(n, "") if reached and _papers(layout, n) else "",
                        ("Fig. 6" + ("; every kbar run lies on it, the stiffest included "
                                     "(few or far-apart pillars)" if on_all else ""))
                        if reached else "no plateau in the kbar run"))
    rows.extend(spread_rows(full))  # discs, as the flat rows but Fig. 5a
    return rows


def spread_rows(sweep: xr.Dataset, shape: str = "disc") -> list[Row]:
    """F_ad of every graded case (stiffness spread C > 0, ``kbar_spread``):
    one `Row` per brush, kbar, roughness and C, at the preload the flat rows
    take (0, else the smallest run).  The flat rows select C = 0
    (`flat_slice`), so these cases left no trace in the summary before.

    The note gives F_ad of the same brush at C = 0 where it ran and, on
    equal heights where the let-go stretch is at least `theory.MIN_FOUNDATION_STRETCH`
    d_K, the elastic-foundation soft limit: N^(1/4) G(C) for many pillars
    (`theory.lognormal_stiffness_pull_off`) and for the stiffnesses these
    seeds drew.
    """
    if "kbar_spread" not in sweep.dims or not (sweep.kbar_spread.values > 0).any():
        return []
    sweep = finest_grid(shape_slice(without_brushes_as_made(sweep), shape))
    preload = 0.0 if 0.0 in sweep.preload.values else float(sweep.preload.min())
    force = sweep["adhesive_force_normalized"].sel(preload=preload)
    phi = float(sweep.attrs.get("phi", math.nan))
    at = f"; preload {preload:g} F_K" if preload else ""
    rows = []
    for layout in sweep.layout.values:
        for n in sweep.n_pillars.values:
            for rough in sweep.roughness.values:
                for kbar in sweep.kbar.values:
                    runs = force.sel(layout=layout, n_pillars=n, roughness=rough, kbar=kbar)
                    for spread in sweep.kbar_spread.values:
                        seeds = runs.sel(kbar_spread=spread).values
                        seeds = seeds[np.isfinite(seeds)]
                        if spread == 0 or not seeds.size:
                            continue
                        rows.append(_spread_row(
                            str(layout), int(n), float(kbar), float(rough), float(spread),
                            seeds, runs, phi, at))
    return rows


def _spread_row(layout: str, n: int, kbar: float, rough: float, spread: float,
                seeds: np.ndarray, runs: xr.DataArray, phi: float, at: str) -> Row:
    """`spread_rows`' row of one graded case (``runs``: its brush against
    kbar_spread and seed)."""
    notes = [f"mean of {seeds.size} seed{'s' if seeds.size > 1 else ''}"
             + (f" ({_fmt(seeds.min())}-{_fmt(seeds.max())})" if seeds.size > 1 else "")]
    flat = runs.sel(kbar_spread=0.0).values if 0.0 in runs.kbar_spread.values else []
    flat = np.asarray(flat)[np.isfinite(flat)]
    if flat.size:
        notes.append(f"C = 0: {_fmt(float(flat.mean()))}")
    lam = float(theory.foundation_stretch(n, phi, kbar)) if math.isfinite(phi) else math.nan
    if rough == 0 and lam >= theory.MIN_FOUNDATION_STRETCH:
        ran = [int(s) for s, v in zip(runs.seed.values, runs.sel(kbar_spread=spread).values)
               if math.isfinite(v)]
        root = float(theory.soft_limit(n))
        notes.append(f"soft limit (elastic foundation, lambda {_fmt(lam, 2)} d_K): "
                     f"N^1/4 G(C) = {_fmt(root * theory.lognormal_stiffness_pull_off(spread))}"
                     f" for many pillars, "
                     f"{_fmt(root * theory.drawn_stiffness_pull_off(n, spread, ran))} for "
                     "these seeds' stiffnesses")
    rough_text = f", roughness {rough:g} d_K" if rough else ""
    return Row(f"F_ad (normalised), stiffness spread C = {spread:g}{rough_text}", layout,
               str(n), _fmt(kbar), _fmt(float(seeds.mean())), "", "; ".join(notes) + at)


def _papers(layout: str, n_pillars: int) -> bool:
    """Whether the paper ran this brush (its numbers are quoted beside it only)."""
    return n_pillars in PAPER_BRUSHES.get(layout, ())


def _resolution_row(sweep: xr.Dataset, layout: str, n_pillars: int) -> Row:
    """Elements per pillar radius of a brush (finest grid run), marked when under-resolved."""
    if "pillar_radius_elements" not in sweep:
        return Row("pillar radius in elements", layout, str(n_pillars), "", NOT_AVAILABLE, "",
                   "not recorded in this sweep")
    radius = seed_mean(sweep, "pillar_radius_elements", layout, n_pillars)
    # the narrowest pillar's where pillars differ: one coarse pillar sets the mesh error
    narrow = seed_mean(sweep, SMALLEST, layout, n_pillars) if SMALLEST in sweep else radius
    unequal = bool(np.any(pillars_differ(narrow, radius)))
    radius = narrow
    grid = seed_mean(sweep, "grid_used", layout, n_pillars) if "grid_used" in sweep else radius
    r_min = float(radius.min()) if radius.size else math.nan
    grids = sorted({int(g) for g in np.asarray(grid.values) if math.isfinite(g)}) \
        if "grid_used" in sweep else []
    note = f"grid {', '.join(map(str, grids))}" if grids else ""
    if unequal:  # one row name whatever the pillars, so that summaries line up
        note = (note + "; " if note else "") + "the narrowest pillar's (pillars differ)"
    if math.isfinite(r_min) and r_min < UNDER_RESOLVED_RADIUS:
        note = (note + "; " if note else "") + \
            f"UNDER-RESOLVED (< {UNDER_RESOLVED_RADIUS:g} elements): not converged in h"
    return Row("pillar radius in elements (finest grid run)", layout, str(n_pillars), "",
               _fmt(r_min), "", note)


def write_summary(rows: Sequence[Row], csv_path: str | Path, md_path: str | Path | None = None
                  ) -> None:
    """Write the rows as CSV (and optionally as a Markdown table)."""
    header = [f.name for f in fields(Row)]
    text = io.StringIO(newline="")
    writer = csv.writer(text)
    writer.writerow(header)
    writer.writerows(astuple(r) for r in rows)
    write_text_atomic(csv_path, text.getvalue())  # a killed job leaves no half a table
    if md_path is not None:
        write_text_atomic(md_path, markdown_table(header, (astuple(r) for r in rows)))
