"""The convergence study as tables: one row per (case, quantity), the raw
value on every grid beside the extrapolation of `brushcore.data.convergence`,
its error, order and flags, as CSV and Markdown."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import xarray as xr

if TYPE_CHECKING:
    import pandas as pd

from brushcore.data.aggregate import GRID_DIM
from brushcore.data.io import markdown_table, write_text_atomic
from brushcore.model.params import MAX_PHI_ERROR
from brushcore.data.convergence import (ACCURACY_SETTINGS, CASE_FLAGS, MIXED,
                                        PHI_ACTUAL, PHI_SPREAD_FLAG, QUANTITIES, SETTINGS_FACTOR,
                                        SMALLEST, STUDY_FLAGS, UNDER_RESOLVED_RADIUS, case_flags,
                                        flag_radii, phi_spread)

_SHORT = {"adhesive_force_normalized": "F_ad", "work_of_separation_normalized": "W"}


def convergence_table(conv: xr.Dataset,
                      quantities: Sequence[str] = QUANTITIES) -> pd.DataFrame:
    """One row per (case, quantity) that was run on at least one grid.

    Returns
    -------
    pandas.DataFrame
        Case columns, the quantity, one column ``n=<grid>`` per grid with the
        raw value, the finest radius in elements, ``phi_spread`` (the realised
        filling factor's range over those grids relative to its mean, where the
        study has ``phi_actual``: phi^(-1/4) moves by a quarter of it), the
        extrapolated value, error,
        order, the safety factor the error was built with (1.25 or 3), the
        spread (half the range over the grids, also where a flag leaves no
        extrapolation) and the flags (as a comma-separated ``flags_raised`` column, not
        ``flags``, which pandas holds as an attribute; besides
        the fit's and ``untrusted_order``, ``under_resolved``,
        ``coarsest_under_resolved``, ``touching_pillars``, ``phi_varies`` and
        ``mixed_settings(...)``, see `write_tables`).
    """
    import pandas as pd

    case_dims = [d for d in conv[f"{quantities[0]}_extrapolated"].dims]
    grids = [int(g) for g in conv[GRID_DIM].values]
    rows = []

    def by_case(ds: xr.Dataset) -> xr.Dataset:
        return ds.stack(case=case_dims) if case_dims else ds.expand_dims(case=[0])

    stacked = by_case(conv)
    # convergence.nc's case flags, each quantity on its own grids (phi_varies)
    case = {q: by_case(xr.Dataset(case_flags(conv, conv[q]))) for q in quantities}
    for i in range(stacked.sizes["case"]):
        one = stacked.isel(case=i)
        for q in quantities:
            raw = one[q].values
            if not np.any(np.isfinite(raw)):
                continue
            row = {d: one[d].values.item() for d in case_dims}
            row["quantity"] = _SHORT.get(q, q)
            for g, v in zip(grids, raw):
                row[f"n={g}"] = float(v)
            row["radius_elements_finest"] = float(one["pillar_radius_elements_finest"])
            if f"{SMALLEST}_finest" in one:  # a study of curves that record it
                row["smallest_radius_elements_finest"] = float(flag_radii(one)[0])
            if PHI_ACTUAL in one:  # how far the staircase's phi moves between the grids
                row["phi_spread"] = phi_spread(one[PHI_ACTUAL].values[np.isfinite(raw)])
            # spread: half the range over the grids, what a flagged row still says
            for s in ("extrapolated", "error", "order", "safety_factor", "spread"):
                row[s] = float(one[f"{q}_{s}"])
            flags = [f for f in STUDY_FLAGS if f"{q}_{f}" in one and int(one[f"{q}_{f}"])]
            flags += [f for f in CASE_FLAGS if f in case[q] and int(case[q][f].isel(case=i))]
            if MIXED in one and str(one[MIXED].values):
                flags.append(f"{MIXED}({str(one[MIXED].values).replace(' ', '+')})")
            row["flags_raised"] = ",".join(flags)
            rows.append(row)
    return pd.DataFrame(rows)


def _fmt(value: object) -> str:
    if isinstance(value, float):
        if math.isnan(value):
            return "NaN"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return f"{value:.5g}"
    return str(value)


def to_markdown(table: pd.DataFrame) -> str:
    """The table in Markdown, numbers to 5 digits (`io.markdown_table`; no
    optional dependency such as tabulate)."""
    cols = [str(c) for c in table.columns]
    return markdown_table(cols, ([_fmt(row[c]) for c in table.columns]
                                 for _, row in table.iterrows()))


def write_tables(conv: xr.Dataset, csv_path: str | Path, md_path: str | Path,
                 quantities: Sequence[str] = QUANTITIES) -> None:
    """Write `convergence_table` as CSV (full precision) and Markdown (5 digits)."""
    table = convergence_table(conv, quantities)
    write_text_atomic(csv_path, table.to_csv(index=False))
    header = ("Results extrapolated to h -> 0 with f = f0 + C h^p (observed order p); "
              "error = Roache's GCI (3 grids) or Eca & Hoekstra's least-squares "
              "uncertainty (>= 4 grids), with the safety factor in its column (1.25 at a "
              "trusted order on monotone values whose fine end converges, else 3 with the "
              "correction at the nearest trusted order), and at least the values' full "
              "range above order 2; a three-grid band held an exact limit in about 85 % "
              "of kept fits, a four-grid one in 99 % (a single rigid punch), less at true "
              "orders near 0.5 or with large scatter (README, \"Converged numbers\"). "
              "phi_spread: the realised filling "
              "factor's range over the grids relative to its mean (the rigid limit "
              "phi^-1/4 moves by a quarter of it). spread: half the range of the values "
              "over the grids (where a flag leaves no extrapolation, a lower bound on "
              "the largest mesh error among the grids, not on the finest's, and no error "
              "bar). "
              f"under_resolved: the narrowest pillar's radius on the finest grid < "
              f"{UNDER_RESOLVED_RADIUS:g} elements (smallest_radius_elements_finest; it "
              "differs from radius_elements_finest, the mean equal-area radius, for an "
              "ellipse, its semi-minor axis, and a table's or map's smallest pillar); "
              "coarsest_under_resolved: the fit's coarsest grid is under-resolved (the fit "
              "rests on a grid whose own mesh error is a few per cent); "
              "touching_pillars: on some grid two pillars' footprints share an element "
              "edge (random discs on grids coarser than 512); "
              f"phi_varies: phi_spread > {PHI_SPREAD_FLAG:g}, so the grids hold different "
              "brushes, not one refined (only allow_coarse lets a grid's phi be more "
              f"than {100 * MAX_PHI_ERROR:g} % off): the fit is no h -> 0 limit of one brush; "
              "untrusted_order: the observed order lies outside "
              f"{conv.attrs.get('trusted_order', 'the trusted range')} and no other flag "
              "is raised, so the error carries Fs "
              f"{conv.attrs.get('scattered_safety_factor', 3):g} for that alone, and above "
              f"order {conv.attrs.get('steep_order', 2):g} is at least the values' range; "
              "mixed_settings(rtol+...): the grids' curves ran with different solver "
              f"settings (numbers more than {SETTINGS_FACTOR:g}x apart) among "
              f"{', '.join(ACCURACY_SETTINGS)} (sweep.nc's run_* give the values), so "
              "their solver errors differ and mix into the fit.\n\n")
    write_text_atomic(md_path, header + to_markdown(table))


def write_study(sweep: xr.Dataset, nc_path: str | Path, csv_path: str | Path,
                md_path: str | Path, figure_paths: Sequence[str | Path]) -> xr.Dataset:
    """The convergence study of a sweep, written: `extrapolate_sweep`'s dataset
    (netCDF), its tables (CSV, Markdown) and `figures.convergence` (each of
    ``figure_paths``).  The workflow's rule and ``brushcore converge`` share it.

    Returns
    -------
    The study's dataset.
    """
    from brushcore.data import figures  # noqa: PLC0415 - matplotlib only when drawing
    from brushcore.data.convergence import extrapolate_sweep, write_dataset

    conv = extrapolate_sweep(sweep)
    write_dataset(conv, nc_path)
    write_tables(conv, csv_path, md_path)
    fig = figures.convergence(conv)
    for path in figure_paths:
        figures.save(fig, path)
    return conv
