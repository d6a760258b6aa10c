"""Views of a sweep (``sweep.nc`` as `brushcore.data.aggregate` builds it):
the slices that the figures, the summary and a reader's analysis take.

`flat_slice` gives the flat disc brushes the paper's figures show,
`shape_slice` one pillar shape, `phi_slice` one filling factor, `snapshots` the contact maps of one case
and `finest_grid` each case at the finest grid it ran on.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from brushcore.model.layout_file import FILE_LAYOUT_PREFIX
from brushcore.data.aggregate import GRID_DIM, PHI_DIM, ROUGH_DIMS, SHAPE_DIM, SHAPE_NUMBERS


def flat_slice(sweep: xr.Dataset, shape: str | None = "disc") -> xr.Dataset:
    """The flat brushes of a sweep (roughness and kbar_spread 0) of one shape.

    A sweep of flat brushes is returned as it is; in one with rough cases the
    ROUGH_DIMS are selected at 0 (NaN everywhere when no flat case ran), and
    the pillar shape at `shape` (`shape_slice`), so that the paper's figures
    and summary see the four base dimensions.  ``shape=None`` keeps every shape.
    Where no run was at preload 0 the smallest preload stands for it: a flat
    brush pulls off as from full contact whatever the preload (within CG's
    tolerance), so a rough study that always presses on still has its flat
    brushes.  Cases given heights, stiffness or a gap map (``given_inputs``:
    brushes as made) are left out (`without_brushes_as_made`): they are not
    flat, whatever their roughness coordinate says.
    """
    sweep = shape_slice(without_brushes_as_made(sweep), shape)
    if not set(ROUGH_DIMS) & set(sweep.dims):
        return sweep
    at = {d: 0.0 for d in ROUGH_DIMS}
    if "preload" in sweep.dims and 0.0 not in sweep["preload"].values:
        at["preload"] = float(sweep["preload"].min())
    flat = sweep.reindex({d: [v] for d, v in at.items()}).isel({d: 0 for d in ROUGH_DIMS})
    flat = flat.drop_vars(list(ROUGH_DIMS))
    case_vars = [d for d in ROUGH_DIMS if f"case_{d}" in flat.variables]
    if case_vars:  # keep the snapshots of flat cases only
        keep = np.logical_and.reduce([flat[f"case_{d}"].values == at[d] for d in case_vars])
        flat = flat.isel(case=np.flatnonzero(keep)).drop_vars([f"case_{d}" for d in case_vars])
    return flat


def without_brushes_as_made(sweep: xr.Dataset) -> xr.Dataset:
    """The sweep with every case given heights, stiffness or a gap map
    (``given_inputs``) set to NaN, the layouts left with no case dropped (and
    their snapshots), and without ``given_inputs``: the brushes a flat
    theory speaks of."""
    if "given_inputs" not in sweep:
        return sweep
    given = sweep["given_inputs"] != ""
    out = sweep.drop_vars("given_inputs")
    if not bool(given.any()):
        return out
    masked = [name for name, var in out.data_vars.items()
              if set(given.dims) <= set(var.dims) and np.issubdtype(var.dtype, np.floating)]
    out = out.assign({name: out[name].where(~given) for name in masked})
    ran = out["n_steps"].notnull().any(dim=[d for d in given.dims if d != "layout"])
    kept = [str(v) for v in out.layout.values[ran.values]]
    out = out.sel(layout=kept)
    if "case_layout" in out.variables:
        keep = np.isin(out["case_layout"].values.astype(str), kept)
        out = out.isel(case=np.flatnonzero(keep))
    return out


def shape_slice(sweep: xr.Dataset, shape: str | None = "disc") -> xr.Dataset:
    """The brushes of one pillar shape (a `shape_label`), without the shape dimension.

    A sweep without SHAPE_DIM holds discs only and is returned as it is for
    "disc" (and for None, which keeps every shape); a shape that did not run
    gives NaN everywhere.  Snapshots of other shapes are dropped.
    """
    if shape is None or (SHAPE_DIM not in sweep.dims and shape == "disc"):
        return sweep
    if SHAPE_DIM not in sweep.dims:  # discs only: nothing of this shape
        return sweep.where(False)
    out = sweep.reindex({SHAPE_DIM: [shape]}).isel({SHAPE_DIM: 0}).drop_vars(
        [SHAPE_DIM, *SHAPE_NUMBERS], errors="ignore")  # sweeps before the numbers lack them
    name = f"case_{SHAPE_DIM}"
    if name in out.variables:
        out = out.isel(case=np.flatnonzero(out[name].values == shape)).drop_vars(name)
    out.attrs[SHOWN_SHAPE] = shape  # one shape of several: figures say which
    return out


#: Attribute of a `shape_slice` taken from a sweep of several shapes.
SHOWN_SHAPE = "pillar_shape_shown"


#: The paper's filling factor (He, Li & Popov 2020): of a sweep of several,
#: the figures and the summary show the one nearest it (`shown_phi`).
PAPER_PHI = 0.12
#: Attributes of a `phi_slice` taken from a sweep of several phi: the phi
#: shown, and every phi the generated brushes ran (figures say "0.12 of 0.08,
#: 0.12, 0.2").
SHOWN_PHI = "phi_shown"
PHIS_RUN = "phi_run"


def _ran(sweep: xr.Dataset) -> xr.DataArray | None:
    """Where a case ran (``n_steps``, else F_ad, finite), or None where the sweep holds neither."""
    for name in ("n_steps", "adhesive_force_normalized"):
        if name in sweep:
            return sweep[name].notnull()
    return None


def _is_file(layout: object) -> bool:
    return str(layout).startswith(FILE_LAYOUT_PREFIX)


def swept_phis(sweep: xr.Dataset) -> list[float]:
    """The filling factors the generated brushes (not files) of a sweep ran,
    ascending: the ``phi`` coordinate, or its attribute ``phi`` where the sweep
    has one (an empty list where that is NaN)."""
    if PHI_DIM not in sweep.dims:
        phi = float(sweep.attrs.get("phi", np.nan))
        return [phi] if np.isfinite(phi) else []
    values = np.asarray(sweep[PHI_DIM].values, dtype=float)
    ran = _ran(sweep)
    generated = [str(v) for v in sweep.layout.values if not _is_file(v)]
    if ran is None or not generated:
        return values.tolist()
    ran = ran.sel(layout=generated)
    hit = ran.any([d for d in ran.dims if d != PHI_DIM]).values
    return values[hit].tolist()


def shown_phi(phis) -> float:
    """Of several filling factors, the one nearest `PAPER_PHI` (the smaller
    of two as near); NaN of none."""
    phis = [float(p) for p in phis]
    return min(phis, key=lambda p: (abs(p - PAPER_PHI), p)) if phis else float("nan")


def phi_slice(sweep: xr.Dataset, phi: float | None = None) -> xr.Dataset:
    """The brushes of one filling factor, without the phi dimension.

    A sweep without PHI_DIM (one phi) is returned as it is.  Otherwise the
    generated brushes are taken at ``phi`` (None: `shown_phi` of those they
    ran), a brush read from a file at its own phi (the one it ran), and the
    attribute ``phi`` becomes the one shown; `SHOWN_PHI` and `PHIS_RUN` say
    which of which, for figures to name (as `SHOWN_SHAPE` does).  A phi not
    run gives NaN for the generated brushes.  Snapshots of other phi are
    dropped.
    """
    if PHI_DIM not in sweep.dims:
        return sweep
    values = np.asarray(sweep[PHI_DIM].values, dtype=float)
    run = swept_phis(sweep)
    chosen = shown_phi(run or values) if phi is None else float(phi)
    hit = np.flatnonzero(np.isclose(values, chosen, rtol=CASE_RTOL, atol=0.0))
    ran = _ran(sweep)
    index = np.full(sweep.sizes["layout"], hit[0] if hit.size else 0, dtype=np.int64)
    missing = np.zeros(sweep.sizes["layout"], dtype=bool)
    own = {}  # a file brush's phi, where it ran
    for i, layout in enumerate(sweep.layout.values):
        if _is_file(layout) and ran is not None:
            one = ran.isel(layout=i)
            at = np.flatnonzero(one.any([d for d in one.dims if d != PHI_DIM]).values)
            if at.size:
                index[i] = at[0]
                own[str(layout)] = float(values[at[0]])
                continue
        missing[i] = not hit.size
    out = sweep.isel({PHI_DIM: xr.DataArray(index, dims="layout")}).drop_vars(PHI_DIM)
    if missing.any():  # the phi was not run: NaN, as `shape_slice` gives an unrun shape
        gone = xr.DataArray(missing, dims="layout", coords={"layout": out.layout})
        floats = [n for n, v in out.data_vars.items()
                  if "layout" in v.dims and np.issubdtype(v.dtype, np.floating)]
        out = out.assign({n: out[n].where(~gone) for n in floats})
    name = f"case_{PHI_DIM}"
    if name in out.variables:
        case_phi = np.asarray(out[name].values, dtype=float)
        layouts = out["case_layout"].values.astype(str)
        want = np.array([own.get(lay, chosen) for lay in layouts], dtype=float)
        keep = np.isclose(case_phi, want, rtol=CASE_RTOL, atol=0.0)
        out = out.isel(case=np.flatnonzero(keep)).drop_vars(name)
    out.attrs["phi"] = chosen
    out.attrs[SHOWN_PHI] = chosen  # one phi of several: figures say which
    out.attrs[PHIS_RUN] = np.asarray(run, dtype=np.float64)
    return out


def phi_note(sweep: xr.Dataset) -> str:
    """"phi = 0.12 of 0.08, 0.12, 0.2" for a `phi_slice` of a sweep of
    several phi, "" otherwise."""
    if SHOWN_PHI not in sweep.attrs:
        return ""
    run = ", ".join(f"{float(p):g}" for p in np.atleast_1d(sweep.attrs.get(PHIS_RUN, [])))
    return f"phi = {float(sweep.attrs[SHOWN_PHI]):g}" + (f" of {run}" if run else "")


#: Relative tolerance a case's kbar and rough values are matched to: a
#: config's values as they survive the curve file names.
CASE_RTOL = 1e-9


def kbar_index(kbars: np.ndarray, kbar: float) -> int | None:
    """Position of ``kbar`` among ``kbars`` (to `CASE_RTOL`; inf matches inf),
    None if it was not run."""
    hit = np.flatnonzero(np.isclose(kbars, kbar, rtol=CASE_RTOL, atol=0.0))
    return int(hit[0]) if hit.size else None


def snapshots(sweep: xr.Dataset, layout: str, n_pillars: int, kbar: float, seed: int = 0,
              *, shape: str = "disc", grid: int | None = None, phi: float | None = None,
              **rough: float):
    """Contact snapshots of one case, or None when the sweep did not keep them.

    Parameters
    ----------
    sweep : dataset of `build_sweep`
    layout, n_pillars, kbar, seed : the case
    shape : its pillars' `brushcore.model.shapes.shape_label` (where the
        sweep holds several shapes)
    grid : the grid whose maps are wanted (None: whichever the sweep kept);
        a curve drawn at another grid must not take their step numbers
    phi : the filling factor asked for, where the sweep holds several (None:
        the one nearest `PAPER_PHI` of those kept for the case)
    rough : its ``roughness``, ``preload`` and ``kbar_spread`` (each 0, the
        flat brush, unless given; where the sweep holds rough cases)

    Returns
    -------
    xarray.Dataset or None
        ``contact_snapshot(snapshot, y, x)`` (1 attached, 0 detached, -1 no
        pillar; NaN, the fill, for a stage the run never reached, read
        through xarray), ``snapshot_step`` and ``snapshot_label`` of that
        case: its own snapshots, without the padding of cases with fewer.
    """
    unknown = set(rough) - set(ROUGH_DIMS)
    if unknown:
        raise TypeError(f"snapshots: unknown case keys {sorted(unknown)}; "
                        f"allowed shape and {', '.join(ROUGH_DIMS)}")
    if "contact_snapshot" not in sweep:
        return None
    hit = (
        (sweep["case_layout"] == layout)
        & (sweep["case_n_pillars"] == n_pillars)
        & np.isclose(sweep["case_kbar"], kbar, rtol=CASE_RTOL, atol=0.0)
        & (sweep["case_seed"] == seed)
    )
    # a case key the sweep has no coordinate for holds its one value: disc and flat
    # (a sweep of flat brushes asked for roughness 0.3 returned the flat brush's maps)
    if f"case_{SHAPE_DIM}" in sweep.variables:
        hit = hit & (sweep[f"case_{SHAPE_DIM}"] == shape)
    elif shape != "disc":
        return None
    if grid is not None and "case_grid" in sweep.variables:
        hit = hit & (sweep["case_grid"] == int(grid))
    for name in ROUGH_DIMS:
        if f"case_{name}" in sweep.variables:
            hit = hit & np.isclose(sweep[f"case_{name}"], float(rough.get(name, 0.0)),
                                   rtol=CASE_RTOL, atol=0.0)
        elif float(rough.get(name, 0.0)) != 0.0:
            return None
    idx = np.flatnonzero(hit.values)
    if idx.size and f"case_{PHI_DIM}" in sweep.variables:
        phis = np.asarray(sweep[f"case_{PHI_DIM}"].values, dtype=float)[idx]
        want = shown_phi(phis) if phi is None else float(phi)
        idx = idx[np.isclose(phis, want, rtol=CASE_RTOL, atol=0.0)]
    if idx.size == 0:
        return None
    names = [n for n in ("contact_snapshot", "snapshot_step", "snapshot_label") if n in sweep]
    case = sweep[names].isel(case=int(idx[0]))
    if "snapshot_label" in case:  # not the padding of a case with fewer snapshots
        case = case.isel(snapshot=np.flatnonzero(case["snapshot_label"].values != ""))
    return case


def finest_grid(sweep: xr.Dataset, ran: str = "adhesive_force_normalized") -> xr.Dataset:
    """Each case at the finest grid it was run on, without the ``grid`` dimension.

    Figures and the summary show one value per case; on a refinement sweep
    that is the best-resolved one.  A sweep without ``grid`` (older files) is
    returned unchanged.

    Parameters
    ----------
    sweep : dataset of `build_sweep`.
    ran : variable whose finite values mark the grids a case ran on.

    Returns
    -------
    xarray.Dataset
        Every variable with a ``grid`` dimension reduced to its value at the
        finest grid run (NaN where the case never ran; text, "" there), plus ``grid_used``
        (elements per side of that grid, NaN where none).
    """
    if GRID_DIM not in sweep.dims:
        return sweep
    sweep = sweep.sortby(GRID_DIM)
    rank = xr.DataArray(np.arange(sweep.sizes[GRID_DIM]), dims=GRID_DIM)
    done = np.isfinite(sweep[ran])
    finest = rank == rank.where(done).max(GRID_DIM)  # one True per case that ran
    at, ran_at_all = finest.argmax(GRID_DIM), finest.any(GRID_DIM)  # for text
    out = sweep.copy()
    for name, var in sweep.data_vars.items():
        if GRID_DIM not in var.dims:
            continue
        if np.issubdtype(var.dtype, np.number):
            # Exactly one unmasked value survives, so the sum is that value.
            out[name] = var.where(finest).sum(GRID_DIM, min_count=1).assign_attrs(var.attrs)
        else:  # text (``run_*``): the finest grid's entry, "" where none ran
            out[name] = (var.isel({GRID_DIM: at}).where(ran_at_all, "")
                         .astype(var.dtype).assign_attrs(var.attrs))
    out["grid_used"] = (
        sweep[GRID_DIM].astype(np.float64).where(finest).sum(GRID_DIM, min_count=1)
        .assign_attrs(units="1", long_name="elements per side n of the finest grid run")
    )
    return out.drop_vars(GRID_DIM)
