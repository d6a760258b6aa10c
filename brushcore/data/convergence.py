"""Mesh-refinement studies of a sweep: per case (layout, N, kbar, seed, ...),
extrapolate F_ad and W over its grids (`brushcore.data.extrapolation`),
flag what the fit cannot see (under-resolved pillars, touching pillars, a
filling factor that varies between grids, accuracy settings that differ),
and write the study as netCDF.

h/L = 1/n (n elements per side of the square L x L), so the brush (L,
pillars, k-bar) is the same on every grid.
"""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import xarray as xr

from brushcore.data.aggregate import GRID_DIM
from brushcore.data.extrapolation import FIT_FLAGS, ORDER_FLAG, ConvergenceOptions, extrapolate
from brushcore.model import provenance
from brushcore.model.params import MAX_PHI_ERROR

#: Results the workflow extrapolates.
QUANTITIES = ("adhesive_force_normalized", "work_of_separation_normalized")
#: Under this many elements per pillar radius a result is marked under-resolved.
UNDER_RESOLVED_RADIUS = 4.0
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


#: Per-quantity outputs of `extrapolate_sweep`: suffix -> (long-name template, is_flag).
_OUTPUTS = {
    "extrapolated": ("{q} extrapolated to h -> 0", False),
    "error": ("half-width U of the uncertainty band about the extrapolated {q} (Roache's "
              "GCI or after Eca & Hoekstra; at least the range of the values where the "
              "order exceeds 2); the band also holds the finest {q}", False),
    "order": ("observed order p of {q} = f0 + C h^p", False),
    "coefficient": ("coefficient C of {q} = f0 + C h^p, h = 1/n", False),
    "finest": ("{q} on the finest grid run", False),
    "spread": ("half range of {q} over the grids", False),
    "gci": ("grid convergence index of the finest {q}, absolute (Roache; Fs 1.25 at a "
            "trusted order on monotone values whose finest three do not diverge, else 3 on "
            "the larger correction of the observed and the nearest trusted order; on three "
            "grids the error, but where the order exceeds 2 and the values' range is "
            "larger)", False),
    "n_grids": ("grids with a value of {q} (not NaN)", False),
    "safety_factor": ("safety factor Fs of the {q} error (1.25 at a trusted order on "
                      "monotone values whose finest three do not diverge, else 3)", False),
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
                      f"carries Fs {opts.scattered_safety_factor:g}, and above order "
                      f"{opts.steep_order:g} is at least the values' range (1 = yes)",
            units="1",
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
        "steep_order": opts.steep_order,
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
    for name in ("simulation_git_commits", "simulation_code_sha256"):
        if name in sweep.attrs:  # the code of the curves, not of this study
            out[name] = sweep.attrs[name]
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
    back as NaN; ``{q}_n_grids`` is 0 there, a true count, stored without a
    fill (xarray reads it as integers).
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
            # one type however the study was run (from a file's sweep or in memory);
            # {q}_n_grids is a count everywhere (0 where none ran): no fill, so
            # that it reads back as integers
            count = name.endswith("_n_grids") and not bool(var.isnull().any())
            if count:
                out[name] = var.astype(np.int64)
            enc[name] = {"dtype": "int64", "_FillValue": None if count else np.int64(-1)}
    write_dataset_atomic(out, path, enc)
