"""The figure of a mesh-refinement study (`brushcore.data.convergence`):
F_ad and W against 1/n per case, with the extrapolation drawn in.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence

import numpy as np
import xarray as xr
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from brushcore.data.convergence import (MIXED, PHI_ACTUAL, QUANTITIES, STUDY_FLAGS, TOUCHING,
                                        flag_radii, phi_spread, phi_varies,
                                        resolution_flag, touching_grids)
from brushcore.data.figures.common import (FAD_LABEL, W_LABEL, kbar_text, new_figure,
                                           no_data)


#: The convergence figure's words for `resolution_flag`'s flags.
RESOLUTION_TEXT = {"under_resolved": "under-resolved",
                   "coarsest_under_resolved": "coarsest under-resolved"}


#: Labels of the quantities the convergence figure draws.
CONVERGENCE_LABELS = {
    "adhesive_force_normalized": FAD_LABEL,
    "work_of_separation_normalized": W_LABEL,
}


def _convergence_cases(conv: xr.Dataset, quantity: str) -> list[dict[str, object]]:
    """Case coordinates (every dim but grid) with at least one finite value."""
    raw = conv[quantity]
    dims = [d for d in raw.dims if d != "grid"]
    stacked = raw.stack(case=dims) if dims else raw.expand_dims(case=[0])
    keep = np.isfinite(stacked).any("grid").values
    cases = []
    for i in np.flatnonzero(keep):
        one = stacked.isel(case=int(i))
        cases.append({d: one[d].values.item() for d in dims})
    return cases


#: Characters of a convergence panel's flag line (x-small type, 4.6 in wide).
FLAG_LINE_CHARS = 58


def _value_text(value: object) -> str:
    """A case coordinate in a title: a number as %g, a label as it is."""
    try:
        return f"{float(value):g}"
    except (TypeError, ValueError):
        return str(value)


def convergence(
    conv: xr.Dataset,
    *,
    quantities: Sequence[str] = QUANTITIES,
) -> Figure:
    """F_ad and W against the element size h/L = 1/n, one panel per case.

    Parameters
    ----------
    conv : dataset of `brushcore.data.convergence.extrapolate_sweep`.
    quantities : variables to draw, one column each per case.

    Returns
    -------
    matplotlib.figure.Figure
        Rows: cases (layout, N, kbar, seed); columns: quantities.  Dots are
        the grids run (open where two pillars' footprints share an element
        edge, ``touching_pillar_pairs``), the dashed line f0 + C h^p, the bar
        at h = 0 the extrapolated value with its error; flags are written in
        red.
    """
    cases = _convergence_cases(conv, quantities[0])
    n_rows, n_cols = max(len(cases), 1), len(quantities)
    fig = new_figure(3.2 * n_cols, 1.9 * n_rows + 0.4)
    axes = fig.subplots(n_rows, n_cols, squeeze=False)
    if not cases:
        no_data(axes[0][0], "no case with results")
        return fig
    h_all = conv["h"].values
    h_line = np.linspace(0.0, float(np.nanmax(h_all)) * 1.05, 200)
    for row, case in enumerate(cases):
        title = (f"{case.get('layout', '')} N={case.get('n_pillars', '')}, "
                 rf"$\bar k$={kbar_text(float(case.get('kbar', math.nan)))}")
        if case.get("seed", 0):
            title += f", seed {case['seed']}"
        # the other case dimensions (phi, shape, the rough ones), which tell rows apart
        title += "".join(f", {name} {_value_text(value)}" for name, value in case.items()
                         if name not in ("layout", "n_pillars", "kbar", "seed"))
        finest, coarsest = (float(r.sel(case)) for r in flag_radii(conv))
        for col, q in enumerate(quantities):
            ax = axes[row][col]
            values = conv[q].sel(case).values
            ok = np.isfinite(values)
            touch = ok & (touching_grids(conv[TOUCHING].sel(case).values)
                          if TOUCHING in conv else False)
            ax.plot(h_all[ok & ~touch], values[ok & ~touch], "o", color="C0")
            ax.plot(h_all[touch], values[touch], "o", mfc="none", color="C0")
            f0 = float(conv[f"{q}_extrapolated"].sel(case))
            p = float(conv[f"{q}_order"].sel(case))
            c = float(conv[f"{q}_coefficient"].sel(case))
            if math.isfinite(f0) and math.isfinite(p) and math.isfinite(c):
                err = float(conv[f"{q}_error"].sel(case))
                ax.plot(h_line, f0 + c * h_line**p, "--", color="C1")
                ax.errorbar([0.0], [f0], yerr=[err], fmt="s", color="C1", capsize=3)
                fs = float(conv[f"{q}_safety_factor"].sel(case))  # 3: an untrusted order
                ax.text(0.03, 0.95, f"$f_0$ = {f0:.4g} ± {err:.2g}, p = {p:.2f}, Fs {fs:g}",
                        ha="left", va="top", transform=ax.transAxes, fontsize="small")
            flags = [f.replace("_", " ") for f in STUDY_FLAGS
                     if f"{q}_{f}" in conv and int(conv[f"{q}_{f}"].sel(case))]
            resolution = resolution_flag(finest, coarsest)  # as the table flags
            if resolution:
                name, r = resolution
                flags.append(f"{RESOLUTION_TEXT[name]} ({r:.1f} el./radius)")
            if touch.any():
                grids = ", ".join(str(int(g)) for g in conv["grid"].values[touch])
                flags.append(f"touching pillars (n = {grids})")
            phi = conv[PHI_ACTUAL].sel(case).values[ok] if PHI_ACTUAL in conv else None
            if phi is not None and phi_varies(phi):
                flags.append(f"phi varies ({phi_spread(phi):.2f} of its mean)")
            if MIXED in conv and str(conv[MIXED].sel(case).values):
                flags.append(f"mixed settings ({conv[MIXED].sel(case).values})")
            # between the title and the plot: on no point, no tick label; wrapped
            # to the panel's width (three flags and a radius overran it)
            lines = textwrap.wrap(", ".join(flags), FLAG_LINE_CHARS)
            if lines:
                ax.text(0.5, 1.01, "\n".join(lines), color="tab:red", ha="center",
                        va="bottom", transform=ax.transAxes, fontsize="x-small")
            ax.set_xlim(left=-0.02 * h_line[-1], right=h_line[-1])
            ax.set_title(title, fontsize="small", pad=6 + 7 * len(lines))
            ax.set_ylabel(CONVERGENCE_LABELS.get(q, q))
            if row == n_rows - 1:
                ax.set_xlabel("element size $h/L = 1/n$")
    handles = [
        Line2D([], [], marker="o", ls="", color="C0", label="grids run"),
        Line2D([], [], ls="--", color="C1", label=r"fit $f_0 + C h^p$"),
        Line2D([], [], marker="s", ls="", color="C1", label=r"$f_0$ ± error at $h = 0$"),
    ]
    if TOUCHING in conv and bool(touching_grids(conv[TOUCHING].values).any()):
        handles.append(Line2D([], [], marker="o", mfc="none", ls="", color="C0",
                              label="grid where pillars touch"))
    fig.legend(handles=handles, loc="outside upper center", ncols=len(handles),
               fontsize="small")
    return fig
