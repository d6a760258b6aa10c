"""The paper's Figures 5-8 drawn from a sweep dataset (matplotlib, no pyplot).

`convergence` draws a mesh-refinement study (`brushcore.data.convergence`),
`lattices` compares layouts and pillar shapes of the same N.

Each ``figN`` function takes the dataset of `brushcore.data.aggregate.build_sweep`
and returns a `matplotlib.figure.Figure`; `save` writes it.  Figures are
built on the object API with the Agg canvas, so no global pyplot state or GUI
backend is involved.  Brushes or layouts absent from a sweep are skipped, and
a panel with nothing to show says so instead of failing.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import xarray as xr
import matplotlib
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter

from brushcore.model import theory
from brushcore.model.lattices import hexagonal_lattice
from brushcore.model.inputs import parse_protocol
from brushcore.model.layout_file import FILE_LAYOUT_PREFIX, curve_layout
from brushcore.model.shapes import parse_shape_label
from brushcore.data.aggregate import SHAPE_DIM
from brushcore.data.io import write_atomic
from brushcore.data.views import (SHOWN_SHAPE, finest_grid, flat_slice, kbar_index,
                                  shape_slice, snapshots)
from brushcore.data.convergence import (MIXED, PHI_ACTUAL, QUANTITIES, STUDY_FLAGS, TOUCHING,
                                        flag_radii, phi_spread, phi_varies,
                                        resolution_flag, touching_grids)
from brushcore.data.summary import fit_soft_prefactor, on_plateau, seed_mean, soft_plateau

K_LABEL = r"$\bar k = k / (E^* L)$"
FAD_LABEL = r"$\bar F_{ad} = F_{ad} / F_K$"
W_LABEL = r"$\bar W = W / (2\pi a_0^2 \Delta\gamma)$"
#: The convergence figure's words for `resolution_flag`'s flags.
RESOLUTION_TEXT = {"under_resolved": "under-resolved",
                   "coarsest_under_resolved": "coarsest under-resolved"}
#: Colours of the layouts and markers of the pillar shapes in the lattice figure.
LAYOUT_COLORS = {"regular": "C0", "hexagonal": "C1", "random": "C2"}
SHAPE_MARKERS = {"disc": ("o", "-"), "square": ("s", "--"), "ellipse": ("D", ":")}
#: The hexagonal lattice's rigid limit at its local filling factor (dash-dot).
HEX_LINE = (0, (6, 2, 1, 2))
HEX_LABEL = r"hexagonal rigid limit $(\varphi/\mathrm{fill})^{-1/4}$ (approx.)"
#: Fig. 7's marker of each generated layout; others (files) take OTHER_MARKERS in turn.
LAYOUT_MARKERS = {"regular": "s", "random": "o", "hexagonal": "h"}
OTHER_MARKERS = ("^", "v", "D", "P", "X", "<", ">", "p", "*")
#: Fig. 8 draws eq. 27 only where it exceeds this (W of a compact punch is 1).
SOFT_WORK_FLOOR = 0.3
#: The rough figure draws the elastic foundation's soft limit at kbar up to
#: this: every pillar still attached at F_ad, which stiffer brushes are not.
SOFT_LIMIT_KBAR = 0.01
# detached / attached pillar element on a white background (no pillar)
SNAPSHOT_CMAP = ListedColormap(["white", "0.8", "tab:red"])


def _layout_styles(layouts: Sequence[str]) -> dict[str, tuple[str, str]]:
    """(colour, marker) of each layout: its own for the generated ones, and
    for the others (brushes of one's own) one each in turn, so that two
    files are told apart."""
    styles, other = {}, 0
    for layout in layouts:
        if layout in LAYOUT_COLORS:
            styles[layout] = (LAYOUT_COLORS[layout], LAYOUT_MARKERS[layout])
        else:
            styles[layout] = (f"C{3 + other % 7}", OTHER_MARKERS[other % len(OTHER_MARKERS)])
            other += 1
    return styles


def _new_figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _layouts(sweep: xr.Dataset) -> list[str]:
    return [str(v) for v in sweep.layout.values]


def _shape_text(label: str) -> str:
    """A `shape_label` for people: "disc", "square at 30°", "ellipse 2:1 at 30°"."""
    shape = parse_shape_label(label)
    text = shape["shape"] + (f" {shape['aspect']:g}:1" if shape["shape"] == "ellipse" else "")
    return text + (f" at {shape['orientation']:g}°" if shape["orientation"] else "")


def _panel_title(index: int, layout: str) -> str:
    """"(a) regular", "(b) hexagonal", ...: one panel per layout that ran."""
    return f"({chr(ord('a') + index)}) {layout}"


def _brush_colors(n_pillars: Sequence[int]) -> dict[int, str]:
    """One colour per N, stable across figures and panels."""
    return {int(n): f"C{i}" for i, n in enumerate(sorted(n_pillars))}


def _no_data(ax, message: str) -> None:
    ax.text(0.5, 0.5, message, ha="center", va="center", transform=ax.transAxes)


def _phi(sweep: xr.Dataset, layout: str | None = None, n_pillars: int | None = None
         ) -> float:
    """The filling factor a layout's theory lines take: the sweep's, or for a
    brush read from a file (layout "file_..."), the file's own; with
    ``n_pillars``, the one brush's as realised (its curves' mean
    ``phi_actual``), as its data are normalised (regular 256 and 2304
    realise 0.117 of 0.12 at 512^2, which put its soft-work line 1.2 %
    low)."""
    if "phi_actual" in sweep and layout is not None and (
            n_pillars is not None or layout.startswith(FILE_LAYOUT_PREFIX)):
        realised = sweep["phi_actual"].sel(layout=layout)
        if n_pillars is not None:
            realised = realised.sel(n_pillars=n_pillars)
        if bool(realised.notnull().any()):
            return float(realised.mean(skipna=True))
    return float(sweep.attrs.get("phi", math.nan))


def _case(sweep: xr.Dataset, layout: str, n_pillars: int, kbar: float,
          seed: int) -> xr.Dataset | None:
    """One case of a sweep without a grid dimension, or None when absent."""
    try:
        case = sweep.sel(layout=layout, n_pillars=n_pillars, seed=seed)
    except KeyError:
        return None
    at = kbar_index(case["kbar"].values, kbar)
    return None if at is None else case.isel(kbar=at)


def _curve(sweep: xr.Dataset, layout: str, n_pillars: int, kbar: float, seed: int):
    """(d, F) normalised of one run without padding, or None when absent."""
    case = _case(sweep, layout, n_pillars, kbar, seed)
    if case is None:
        return None
    d = case["displacement_normalized"].values
    f = case["force_normalized"].values
    ok = np.isfinite(d) & np.isfinite(f)
    return (d[ok], f[ok]) if ok.any() else None


def _grid_used(sweep: xr.Dataset, layout: str, n_pillars: int, kbar: float,
               seed: int) -> int | None:
    """The grid `finest_grid` drew a case at, or None (a sweep without grids)."""
    case = _case(sweep[["grid_used"]], layout, n_pillars, kbar, seed) \
        if "grid_used" in sweep else None
    value = math.nan if case is None else float(case["grid_used"])
    return int(value) if math.isfinite(value) else None


def fig5(
    sweep: xr.Dataset,
    *,
    n_pillars: int = 256,
    kbar: Sequence[float] = (0.455, 0.005, 0.001),
    layout: str = "regular",
    seed: int = 0,
    shape: str = "disc",
) -> Figure:
    """Fig. 5: F-d curves of one brush at a few kbar, contact snapshots beside.

    Numbered dots on each curve mark the steps of the snapshots to its right
    (red: attached element, grey: detached, white: no pillar): the label map
    itself, so squares, ellipses and lattices show as they were meshed.
    `shape` (a `shape_label`) picks the pillars where the sweep holds
    several shapes and names them in the title; of a sweep with rough
    cases the flat brushes are drawn.
    """
    if SHAPE_DIM in sweep.dims:
        sweep = shape_slice(sweep, shape)
    sweep = finest_grid(flat_slice(sweep, None))  # one curve per case: the best-resolved one
    cases = [k for k in kbar if _curve(sweep, layout, n_pillars, k, seed) is not None]
    n_snap = int(sweep.sizes.get("snapshot", 0))
    rows = max(len(cases), 1)
    fig = _new_figure(3.2 + 1.3 * n_snap, 2.4 * rows)
    grid = fig.add_gridspec(rows, 1 + n_snap, width_ratios=[3.0] + [1.0] * n_snap)
    side = math.isqrt(n_pillars)
    name = f"{side} x {side}" if layout == "regular" and side * side == n_pillars else str(n_pillars)
    pillars = "" if shape == "disc" else f" ({_shape_text(shape)})"
    fig.suptitle(f"{layout} brush, N = {name} pillars{pillars}")
    if not cases:
        _no_data(fig.add_subplot(grid[0, :]), f"no flat {layout} runs with N = {n_pillars}")
        return fig
    for row, k in enumerate(cases):
        d, f = _curve(sweep, layout, n_pillars, k, seed)
        ax = fig.add_subplot(grid[row, 0])
        ax.plot(d, f, color="C0", lw=1.2)
        # A preloaded case is drawn as its loop: approach (F < 0), then retraction.
        loop = ", from the preload" if float(np.min(f)) < 0.0 else ""
        ax.set_title(f"({chr(ord('a') + row)}) " + r"$\bar k$" + f" = {_kbar_text(k)}{loop}",
                     loc="left")
        ax.set_xlabel(r"$\bar d = d / d_K$")
        ax.set_ylabel(r"$\bar F = F / F_K$")
        snap = snapshots(sweep, layout, n_pillars, k, seed, grid=_grid_used(
            sweep, layout, n_pillars, k, seed))
        if snap is None:
            if n_snap:  # the sweep keeps one grid's maps (`build_sweep`): say so
                grids = sorted({int(g) for g in sweep["case_grid"].values}) \
                    if "case_grid" in sweep else []
                kept = f" (kept on n = {', '.join(map(str, grids))} only)" if grids else ""
                empty = fig.add_subplot(grid[row, 1:])
                empty.set_axis_off()
                _no_data(empty, f"no contact snapshots of this case in the sweep{kept}")
            continue
        # Numbered in the order of their steps: a protocol's file keeps the
        # "maximum force" map after "separated", though it comes first.
        stored = [int(s) for s in snap["snapshot_step"].values]
        order = sorted(range(len(stored)), key=lambda j: (stored[j] < 0, stored[j]))
        steps = [stored[j] for j in order]
        for slot, j in enumerate(order):
            image_ax = fig.add_subplot(grid[row, 1 + slot])
            image_ax.set_axis_off()
            if stored[j] < 0:
                continue
            image_ax.imshow(snap["contact_snapshot"].values[j] + 1, cmap=SNAPSHOT_CMAP,
                            vmin=0, vmax=2, interpolation="nearest", origin="lower")
            image_ax.set_title(f"{slot + 1}: {snap['snapshot_label'].values[j]}", fontsize=7)
        # One dot per distinct step; snapshots sharing a step share its label ("1,2").
        for step in sorted({s for s in steps if 0 <= s < d.size}):
            label = ",".join(str(j + 1) for j, s in enumerate(steps) if s == step)
            ax.plot(d[step], f[step], "o", ms=4, color="C3")
            ax.annotate(label, (d[step], f[step]), textcoords="offset points",
                        xytext=(3, 3), fontsize=7)
    if n_snap:  # the maps' colour key
        fig.legend(handles=[Patch(color=SNAPSHOT_CMAP(2), label="attached"),
                            Patch(color=SNAPSHOT_CMAP(1), label="detached")],
                   loc="upper right", ncols=2, fontsize=7, frameon=False)
    return fig


def _shape_note(sweep: xr.Dataset) -> str:
    """" (disc pillars)" where the sweep is one shape of several (`shape_slice`)."""
    shape = sweep.attrs.get(SHOWN_SHAPE)
    return f" ({shape} pillars)" if shape else ""


def _per_brush_panels(sweep: xr.Dataset, title: str) -> tuple[Figure, dict[str, object]]:
    layouts = _layouts(sweep)
    fig = _new_figure(4.2 * max(len(layouts), 1), 3.6)
    # One y range for every layout: the panels are read against each other.
    axes = fig.subplots(1, max(len(layouts), 1), squeeze=False, sharey=True)[0]
    fig.suptitle(title + _shape_note(sweep))
    return fig, dict(zip(layouts, axes))


def _brush_series(sweep: xr.Dataset, name: str, layout: str) -> list[tuple[int, xr.DataArray]]:
    """(N, seed-mean of `name` against kbar) for every brush of a layout that ran."""
    series = [(int(n), seed_mean(sweep, name, layout, int(n))) for n in sweep.n_pillars.values]
    return [(n, s) for n, s in series if s.size]


def _rigid_x(kbars: np.ndarray) -> float:
    """Where rigid pillars (kbar = inf) are drawn on a log kbar axis: one
    decade right of the decade tick at or above the stiffest finite kbar, so
    that its "rigid" label never meets that tick's (at 1 when none is finite)."""
    finite = kbars[np.isfinite(kbars)]
    return 10.0 ** (np.ceil(np.log10(finite.max())) + 1) if finite.size else 1.0


def _break_before_rigid(x_inf: float, x: np.ndarray, *values: np.ndarray
                        ) -> tuple[np.ndarray, ...]:
    """x and values with a NaN between the finite kbar and the rigid point at
    ``x_inf``, so that no line joins them: the axis between holds no
    measurement."""
    arrays = tuple(np.asarray(a, dtype=float) for a in (x, *values))
    if arrays[0].size < 2 or arrays[0][-1] != x_inf:
        return arrays
    return tuple(np.insert(a, a.size - 1, np.nan) for a in arrays)


def _kbar_x(kbar, x_inf: float) -> np.ndarray:
    """kbar values as x positions: rigid ones at ``x_inf``."""
    k = np.asarray(kbar, dtype=float)
    return np.where(np.isinf(k), x_inf, k)


def _rigid_ticks(ax, kbars: np.ndarray, x_inf: float) -> None:
    """Decade ticks over the finite kbar, and "rigid" at ``x_inf`` where rigid ran."""
    if not np.isinf(kbars).any():
        return
    finite = kbars[np.isfinite(kbars)]
    ticks = ([10.0**e for e in range(int(np.floor(np.log10(finite.min()))),
                                     int(np.ceil(np.log10(finite.max()))) + 1)]
             if finite.size else [])
    ax.set_xticks([*ticks, x_inf], [f"$10^{{{round(np.log10(t))}}}$" for t in ticks] + ["rigid"])
    ax.xaxis.set_minor_formatter(NullFormatter())


def _kbar_axes(ax, title: str, ylabel: str, kbars: np.ndarray, x_inf: float) -> None:
    """Log kbar axis (rigid pillars at ``x_inf``), panel title and labels
    shared by Figs. 6 and 8."""
    ax.set_xscale("log")
    _rigid_ticks(ax, kbars, x_inf)
    ax.set_title(title, loc="left")
    ax.set_xlabel(K_LABEL)
    ax.set_ylabel(ylabel)


def fig6(sweep: xr.Dataset) -> Figure:
    """Fig. 6: adhesive force against kbar (log axis) per N, one panel per layout.

    The rigid limit phi^(-1/4) (eq. 5) is the solid black line; the compact
    punch F_ad = 1 is dotted; a hexagonal panel adds each N's lattice at its
    local filling factor (`theory.hexagonal_rigid_limit`, dash-dot).  With
    several seeds the bars span min to max.
    Rigid pillars (kbar = inf) are drawn at "rigid" (`_rigid_x`), not joined
    to the finite kbar.
    """
    sweep = finest_grid(sweep)
    fig, axes = _per_brush_panels(sweep, "Adhesive force against pillar stiffness")
    colors = _brush_colors(sweep.n_pillars.values)
    kbars = np.asarray(sweep.kbar.values, dtype=float)
    x_inf = _rigid_x(kbars)
    for index, (layout, ax) in enumerate(axes.items()):
        phi = _phi(sweep, layout)
        brushes = _brush_series(sweep, "adhesive_force_normalized", layout)
        for n, series in brushes:
            runs = sweep["adhesive_force_normalized"].sel(layout=layout, n_pillars=n)
            runs = runs.sel(kbar=series.kbar)
            low, high = runs.min("seed", skipna=True), runs.max("seed", skipna=True)
            x, y, lo, hi = _break_before_rigid(x_inf, _kbar_x(series.kbar, x_inf), series,
                                               low, high)
            seeds = int(runs.notnull().any("kbar").sum())  # seeds this brush ran
            ax.errorbar(x, y, yerr=[y - lo, hi - y], marker="o", ms=4, capsize=2,
                        color=colors[n], label=f"N = {n}" + (
                            f" (mean, min-max of {seeds} seeds)" if seeds > 1 else ""))
        _kbar_axes(ax, _panel_title(index, layout), FAD_LABEL, kbars, x_inf)
        if not brushes:
            _no_data(ax, f"no flat {layout} runs")
            continue
        if math.isfinite(phi):
            ax.axhline(theory.rigid_limit(phi), color="k", lw=1.2,
                       label=rf"rigid limit $\varphi^{{-1/4}}$ = {theory.rigid_limit(phi):.2f}")
            if layout == "hexagonal":  # N that no lattice fills stand denser
                for i, (n, _) in enumerate(brushes):
                    ax.axhline(theory.hexagonal_rigid_limit(phi, n), color=colors[n],
                               ls=HEX_LINE, lw=1.0, label=HEX_LABEL if i == 0 else None)
        ax.axhline(1.0, color="k", lw=0.8, ls=":", label="compact punch")
        ax.legend(fontsize=7)
    return fig


def fig7(sweep: xr.Dataset) -> Figure:
    """Fig. 7: soft-plateau adhesive force against N, log-log, with N^(1/4).

    The plateau value is F_ad at the softest kbar run for each brush; a
    brush whose two softest kbar differ by more than `PLATEAU_RTOL` has not
    reached it (`brushcore.data.summary.on_plateau`) and is drawn in grey
    with its layout's marker, left out of the fit.  Each layout gets its own
    fit F = c N^(1/4), drawn in its colour, with 1/c (the paper's 1.2-1.3)
    and the free exponent printed on the plot.
    """
    sweep = finest_grid(sweep)
    fig = _new_figure(4.6, 3.8)
    ax = fig.add_subplot()
    ax.set_title("Soft plateau of the adhesive force" + _shape_note(sweep))
    fitted: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # layout -> plateau (N, F)
    styles = _layout_styles(_layouts(sweep))
    off = []  # (N, F) of brushes whose softest kbar is not on the plateau
    for layout in _layouts(sweep):
        points = [(int(n), *soft_plateau(sweep, layout, int(n)),
                   on_plateau(sweep, layout, int(n))) for n in sweep.n_pillars.values]
        points = [point for point in points if math.isfinite(point[2])]
        off += [(layout, n, f) for n, _, f, reached in points if not reached]
        points = [(n, k, f) for n, k, f, reached in points if reached]
        if not points:
            continue
        n, k, f = map(np.asarray, zip(*points))
        fitted[layout] = (n, f)
        ax.plot(n, f, styles[layout][1], ms=6, mfc="none",
                color=styles[layout][0], label=f"{layout} (min " + r"$\bar k$"
                + f" = {k.min():g})")
    for layout in dict.fromkeys(lay for lay, _, _ in off):  # grey, the layout's marker
        n_off, f_off = zip(*[(n, f) for lay, n, f in off if lay == layout])
        ax.plot(n_off, f_off, styles[layout][1], ms=6, color="0.55",
                label=f"{layout}: not on a plateau (not fitted)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    # Plain 1-2-5 ticks: decade-only log ticks say little over a range like 64 ... 2304.
    for axis, subs in ((ax.xaxis, (1.0, 2.0, 5.0)), (ax.yaxis, np.arange(1.0, 10.0))):
        axis.set_major_locator(LogLocator(subs=subs))
        axis.set_major_formatter(ScalarFormatter())
        axis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("number of pillars N")
    ax.set_ylabel(FAD_LABEL + " (soft plateau)")
    drawn = [int(v) for n, _ in fitted.values() for v in n] + [n for _, n, _ in off]
    if not drawn:
        _no_data(ax, "no flat runs")
        return fig
    span = np.geomspace(min(drawn) / 1.5, max(drawn) * 1.5, 50)
    ax.plot(span, theory.soft_limit(span), "k-", lw=1.2, label=r"$N^{1/4}$ (eq. 6)")
    if not fitted:  # nothing to fit: say so, and still explain the grey points
        ax.text(0.03, 0.97, "no brush on its soft plateau: no fit", transform=ax.transAxes,
                va="top", fontsize=8)
        ax.legend(fontsize=7, loc="lower right")
        return fig
    # One fit per layout (the paper's 1.2-1.3 is a range; pooled layouts
    # would put one layout's prefactor offset into the other's slope).
    lines = [r"$N^{1/4}/\bar F_{ad}$ = 1/c (paper 1.2-1.3):"]
    for layout, (n, f) in fitted.items():
        fit = fit_soft_prefactor(n, f)
        ax.plot(span, fit["prefactor"] * theory.soft_limit(span), "--", lw=1,
                color=styles[layout][0],
                label=rf"{layout} fit ${fit['prefactor']:.3f}\,N^{{1/4}}$")
        line = f"{layout} {fit['ratio']:.2f}"
        if math.isfinite(fit["exponent"]):
            line += f", free exponent {fit['exponent']:.3f}"
        if len(set(n.tolist())) == 1:
            line += f" (one N only, {int(n[0])}: no test of the exponent)"
        lines.append(line)
    ax.text(0.03, 0.97, "\n".join(lines), transform=ax.transAxes, va="top", fontsize=7,
            bbox={"facecolor": "white", "alpha": 0.85, "edgecolor": "none"})
    ax.legend(fontsize=7, loc="lower right")
    return fig


def fig8(sweep: xr.Dataset) -> Figure:
    """Fig. 8: work of separation against kbar per N, with the soft limit of eqs. 25-26.

    Dashed lines of the same colour are W_S = 2 sqrt(phi/pi) / (sqrt(N) kbar)
    (`brushcore.model.theory.soft_work`); W = 1 is the rigid compact punch.
    Rigid pillars (kbar = inf) are drawn at "rigid" (`_rigid_x`), not joined
    to the finite kbar.
    """
    sweep = finest_grid(sweep)
    fig, axes = _per_brush_panels(sweep, "Work of separation against pillar stiffness")
    colors = _brush_colors(sweep.n_pillars.values)
    kbars = np.asarray(sweep.kbar.values, dtype=float)
    x_inf = _rigid_x(kbars)
    for index, (layout, ax) in enumerate(axes.items()):
        phi = _phi(sweep, layout)
        brushes = _brush_series(sweep, "work_of_separation_normalized", layout)
        for n, series in brushes:
            ax.plot(*_break_before_rigid(x_inf, _kbar_x(series.kbar, x_inf), series), "o-",
                    ms=4, color=colors[n], label=f"N = {n}")
            if math.isfinite(phi):
                # Only where the springs' energy matters; it falls as 1/kbar (0 if rigid).
                kbar = series.kbar.values
                soft = np.asarray(theory.soft_work(n, _phi(sweep, layout, n), kbar))
                keep = soft >= SOFT_WORK_FLOOR
                ax.plot(kbar[keep], soft[keep], "--", lw=1, color=colors[n])
        ax.set_yscale("log")
        _kbar_axes(ax, _panel_title(index, layout), W_LABEL, kbars, x_inf)
        if not brushes:
            _no_data(ax, f"no flat {layout} runs")
            continue
        ax.axhline(1.0, color="k", lw=0.8, ls=":", label="compact punch")
        ax.plot([], [], "k--", lw=1,
                label=r"soft limit $2\sqrt{\varphi/\pi}/(\sqrt{N}\bar k)$ (eqs. 25-26)")
        ax.legend(fontsize=7)
    return fig


def _shape_labels(sweep: xr.Dataset) -> list[str]:
    """Pillar shapes of a sweep: its shape coordinate, or discs only."""
    return [str(v) for v in sweep[SHAPE_DIM].values] if SHAPE_DIM in sweep.dims else ["disc"]


def _lattice_series(sweep: xr.Dataset, n_pillars: int) -> list[tuple[str, str, xr.DataArray]]:
    """(layout, shape, F_ad on (kbar, seed)) of every brush of N pillars that ran."""
    out = []
    for shape in _shape_labels(sweep):
        one = shape_slice(sweep, shape)["adhesive_force_normalized"]
        for layout in _layouts(sweep):
            runs = one.sel(layout=layout, n_pillars=n_pillars)
            runs = runs.dropna("kbar", how="all")
            if runs.sizes["kbar"]:
                out.append((layout, shape, runs))
    return out


def lattices(sweep: xr.Dataset) -> Figure:
    """Adhesive force against kbar for every (layout, shape) of the same N.

    One panel per N run with more than one layout or shape.  Colour is the
    layout, marker and line style the pillar shape; with several seeds
    (random layouts) the dots are the mean and the bars span min to max.
    Rigid pillars (kbar = inf) are drawn at "rigid" (`_rigid_x`), not joined
    to the finite kbar.  Black lines: the rigid limit phi^(-1/4) (eq. 5, dashed) and
    the soft limit N^(1/4) of discs (eq. 6, dotted: other shapes let go below
    Kendall's force); grey dash-dot: the hexagonal lattice's rigid limit at its
    local filling factor phi / fill (`theory.hexagonal_rigid_limit`).

    Parameters
    ----------
    sweep : flat brushes of a sweep with every shape (`flat_slice(sweep, None)`).
    """
    sweep = finest_grid(sweep[["adhesive_force_normalized"]])
    series = {int(n): _lattice_series(sweep, int(n)) for n in sweep.n_pillars.values}
    compared = {n: s for n, s in series.items() if len(s) > 1} or \
        {n: s for n, s in series.items() if s}
    fig = _new_figure(5.2 * max(len(compared), 1), 4.0)
    axes = fig.subplots(1, max(len(compared), 1), squeeze=False)[0]
    fig.suptitle("Adhesive force of lattices and pillar shapes of the same N")
    if not compared:
        _no_data(axes[0], "no runs")
        return fig
    phi = _phi(sweep)
    kbars = np.asarray(sweep.kbar.values, dtype=float)
    x_inf = _rigid_x(kbars)
    for index, (ax, (n, brushes)) in enumerate(zip(axes, compared.items())):
        for layout, shape, runs in brushes:
            x, mean, low, high = _break_before_rigid(
                x_inf, _kbar_x(runs.kbar.values, x_inf), runs.mean("seed", skipna=True),
                runs.min("seed", skipna=True), runs.max("seed", skipna=True))
            marker, line = SHAPE_MARKERS.get(parse_shape_label(shape)["shape"], ("^", "-."))
            ax.errorbar(x, mean, yerr=[mean - low, high - mean], marker=marker, ls=line, ms=4,
                        capsize=2, color=LAYOUT_COLORS.get(layout, f"C{3 + index}"),
                        mfc="none" if shape != "disc" else None,
                        label=f"{layout}, {_shape_text(shape)}")
        if math.isfinite(phi):
            ax.axhline(theory.rigid_limit(phi), color="k", ls="--", lw=0.8,
                       label=r"rigid limit $\varphi^{-1/4}$")
            if any(b[0] == "hexagonal" for b in brushes) and hexagonal_lattice(n):
                ax.axhline(theory.hexagonal_rigid_limit(phi, n), color="0.45",
                           ls=HEX_LINE, lw=1.0, label=HEX_LABEL)
        # Kendall's force per pillar: squares and ellipses let go below it
        ax.axhline(theory.soft_limit(n), color="k", ls=":", lw=0.8,
                   label=r"soft limit $N^{1/4}$ (discs)")
        ax.set_xscale("log")
        _rigid_ticks(ax, kbars, x_inf)
        ax.set_title(f"({chr(ord('a') + index)}) N = {n}", loc="left")
        ax.set_xlabel(K_LABEL)
        ax.set_ylabel(FAD_LABEL)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # off the data
    return fig


def _rough_series(sweep: xr.Dataset, name: str, layout: str, n: int, kbar: float,
                  **at: float) -> tuple[xr.DataArray, xr.DataArray, xr.DataArray]:
    """Seed mean, min and max of a rough-sweep variable for one brush and kbar."""
    runs = sweep[name].sel(layout=layout, n_pillars=n, kbar=kbar, kbar_spread=0.0, **at)
    return (runs.mean("seed", skipna=True), runs.min("seed", skipna=True),
            runs.max("seed", skipna=True))


def _rough_ready(sweep: xr.Dataset, fig: Figure) -> bool:
    if "roughness" in sweep.dims and 0.0 in sweep.kbar_spread.values:
        return True
    _no_data(fig.add_subplot(), "no rough runs in this sweep")
    return False


def _given(sweep: xr.Dataset, layout: str) -> str:
    """What a brush as made was given ("heights kbar_values"; ``given_inputs``),
    "" for a brush of drawn or no heights."""
    if "given_inputs" not in sweep or layout not in sweep.layout.values:
        return ""
    values = np.ravel(sweep["given_inputs"].sel(layout=layout).values)
    return " ".join(sorted({name for v in values for name in str(v).split()}))


#: A brush's given arrays (`BrushParams.given_inputs`) in a title's words:
#: kbar_values stand for --kbar-file and --kbar-factors alike.
GIVEN_WORDS = {"kbar_values": "pillar stiffnesses", "gap_map": "gap map"}


def _rough_brush_title(what: str, layout: str, n_pillars: int, given: str,
                       width: float) -> str:
    """A rough figure's title, wrapped to its ``width`` [in]: a rough brush,
    or a brush as made with what it was given."""
    words = ", ".join(GIVEN_WORDS.get(name, name) for name in given.split())
    brush = (f"the {layout} brush as made ({words} given)" if given
             else f"a rough {layout} brush")
    return textwrap.fill(f"{what} {brush}, N = {n_pillars}", max(30, int(11 * width)))


def _heights_text(roughness: float, given: str) -> str:
    """A panel's heights: "roughness S d_K", or "heights given"."""
    return "heights given" if "heights" in given.split() else (
        f"roughness {roughness:g} " + r"$d_K$")


def rough_roughness(sweep: xr.Dataset, layout: str = "regular", n_pillars: int = 256
                    ) -> Figure:
    """Adhesive force against roughness per kbar, one panel per preload.

    Bars span the seeds.  Dashed lines are the soft limit (elastic foundation,
    every pillar attached, large N): N^(1/4) G(S d_K / lambda) with G
    `theory.gaussian_spread_pull_off` and lambda `theory.foundation_stretch`,
    drawn for kbar <= `SOFT_LIMIT_KBAR` where it applies.
    """
    sweep = finest_grid(sweep)  # one value per case: the best-resolved one
    fig = _new_figure(4.2 * max(1, sweep.sizes.get("preload", 1)), 3.6)
    if not _rough_ready(sweep, fig):
        return fig
    preloads = [float(p) for p in sweep.preload.values]
    axes = fig.subplots(1, len(preloads), squeeze=False)[0]
    phi = _phi(sweep, layout, n_pillars)
    kbars = [float(k) for k in sweep.kbar.values]
    colors = {k: f"C{i}" for i, k in enumerate(kbars)}
    s_axis = np.asarray(sweep.roughness.values, dtype=float)
    given = _given(sweep, layout)  # heights given, not drawn: no Gaussian soft limit
    soft_drawn = False
    protocol = sweep.attrs.get("protocol_normalized")  # its loads stand for the preload
    for ax, preload in zip(axes, preloads):
        for kbar in kbars:
            mean, low, high = _rough_series(sweep, "adhesive_force_normalized", layout,
                                            n_pillars, kbar, preload=preload)
            if not np.isfinite(mean.values).any():
                continue
            ax.errorbar(s_axis, mean, yerr=[mean - low, high - mean], marker="o", ms=4,
                        capsize=2, color=colors[kbar], label=rf"$\bar k$ = {_kbar_text(kbar)}")
            if np.isfinite(kbar) and kbar <= SOFT_LIMIT_KBAR and s_axis.max() > 0 and not given:
                span = np.linspace(0.0, s_axis.max(), 60)
                lam = float(theory.foundation_stretch(n_pillars, phi, kbar))
                soft = [theory.gaussian_spread_pull_off(s / lam) for s in span]
                ax.plot(span, theory.soft_limit(n_pillars) * np.asarray(soft), "--", lw=1,
                        color=colors[kbar])
                soft_drawn = True
        ax.set_title(f"preload {preload:g} " + r"$F_K$" if protocol is None else
                     "last retraction of\n" + textwrap.fill(protocol, 36), fontsize=8)
        ax.set_xlabel(r"roughness $S$ [$d_K$]")
        ax.set_ylabel(FAD_LABEL)
    if soft_drawn:
        axes[0].plot([], [], "k--", lw=1, label="soft limit (elastic foundation)")
    _side_legend(fig, axes)
    fig.suptitle(_rough_brush_title("Adhesive force of", layout, n_pillars, given,
                                    fig.get_figwidth()))
    return fig


def _side_legend(fig: Figure, axes) -> None:
    """One legend for panels that share their lines, right of them, where it
    covers no data (a legend per panel sat on the curves)."""
    handles: dict[str, object] = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, handle)
    if handles:
        # centred: at the top it ran into the title of a one-panel figure
        fig.legend(list(handles.values()), list(handles), loc="outside right center", fontsize=7)


def _no_false_zoom(ax, span: float = 0.05) -> None:
    """Keep a y axis from magnifying differences below ``span`` of its values
    (a flat brush's F_ad at two preloads differs by CG's 1e-7, which
    matplotlib's autoscale and offset label drew as a steep drop)."""
    lo, hi = ax.get_ylim()
    scale = max(abs(lo), abs(hi))
    if hi - lo < span * scale:
        middle = 0.5 * (lo + hi)
        ax.set_ylim(middle - 0.5 * span * scale, middle + 0.5 * span * scale)
    ax.ticklabel_format(axis="y", useOffset=False)


def rough_preload(sweep: xr.Dataset, layout: str = "regular", n_pillars: int = 256
                  ) -> Figure:
    """Adhesive force against preload per kbar, one panel per roughness."""
    sweep = finest_grid(sweep)  # one value per case: the best-resolved one
    fig = _new_figure(4.2 * max(1, sweep.sizes.get("roughness", 1)), 3.6)
    if not _rough_ready(sweep, fig):
        return fig
    given = _given(sweep, layout)
    # a panel per roughness this brush ran (a brush given heights: S = 0 alone)
    ran = sweep["adhesive_force_normalized"].sel(layout=layout, n_pillars=n_pillars,
                                                 kbar_spread=0.0)
    roughs = [float(r) for r in sweep.roughness.values
              if np.isfinite(ran.sel(roughness=r).values).any()] or [0.0]
    axes = fig.subplots(1, len(roughs), squeeze=False)[0]
    kbars = [float(k) for k in sweep.kbar.values]
    p_axis = np.asarray(sweep.preload.values, dtype=float)
    protocol = sweep.attrs.get("protocol_normalized")  # one protocol: preload 0 alone
    first = _first_load(protocol)
    if first is not None:  # the load its first waypoint presses to, not "preload 0"
        p_axis = np.full_like(p_axis, first)
    for ax, rough in zip(axes, roughs):
        for i, kbar in enumerate(kbars):
            mean, low, high = _rough_series(sweep, "adhesive_force_normalized", layout,
                                            n_pillars, kbar, roughness=rough)
            if not np.isfinite(mean.values).any():
                continue
            ax.errorbar(p_axis, mean, yerr=[mean - low, high - mean], marker="o", ms=4,
                        capsize=2, color=f"C{i}", label=rf"$\bar k$ = {_kbar_text(kbar)}")
        ax.set_title(_heights_text(rough, given) if protocol is None else
                     _heights_text(rough, given) + ", last retraction of\n"
                     + textwrap.fill(protocol, 36), fontsize=8 if protocol else 9)
        ax.set_xlabel(r"preload [$F_K$]" if protocol is None else
                      r"load of the protocol's first waypoint [$F_K$]" if first is not None
                      else r"preload [$F_K$] (0: the protocol starts with a displacement)")
        ax.set_ylabel(FAD_LABEL)
        _no_false_zoom(ax)
    _side_legend(fig, axes)
    fig.suptitle(_rough_brush_title("Adhesive force against preload of", layout, n_pillars,
                                    given, fig.get_figwidth()))
    return fig


def _first_load(protocol: str | None) -> float | None:
    """The preload [F_K] a protocol's first waypoint presses to
    ("force:-2.0, ..." gives 2), or None (no protocol, or it starts
    otherwise)."""
    if not protocol:
        return None
    first = parse_protocol(protocol)[0]
    return -first.value if first.kind == "force" else None


def _pull_ranges(curve: xr.Dataset) -> list[tuple[int, int]]:
    """(first, last) step of every retraction branch; files without ``pull_*``
    (written before 2026-12-06) give their last one, ``retraction``."""
    if "pull_first_step" in curve:
        return list(zip(curve["pull_first_step"].values.tolist(),
                        curve["pull_last_step"].values.tolist()))
    back = np.flatnonzero(curve["retraction"].values) if "retraction" in curve else []
    return [(int(back[0]), int(back[-1]))] if len(back) else []


def rough_loop(curve: xr.Dataset) -> Figure:
    """The approach-retract loop (every cycle of a protocol) with the contact
    at the first waypoint (the preload) and at F_ad.

    Left: F / F_K against d / d_K, approaches and retractions in two colours
    (compression is negative), the preload and each retraction's F_ad
    marked.  Right: the contact maps the curve file keeps at those two
    stages (red attached, grey detached pillar elements).
    """
    fig = _new_figure(10.5, 3.6)
    ax, *maps = fig.subplots(1, 3, width_ratios=[1.6, 1, 1])
    d = curve["displacement_normalized"].values
    f = curve["force_normalized"].values
    pulls = _pull_ranges(curve) or [(0, d.size - 1)]
    # Approaches run from the end of one pull (first touch) to the start of the next.
    starts = [0] + [last for _, last in pulls]
    ends = [first for first, _ in pulls] + [d.size - 1]
    for k, (a, b) in enumerate(zip(starts, ends)):
        if b > a:
            ax.plot(d[a:b + 1], f[a:b + 1], color="C0", lw=1,
                    label="approach" if k == 0 else None)
    for k, (a, b) in enumerate(pulls):
        ax.plot(d[a:b + 1], f[a:b + 1], color="C3", lw=1, label="retraction" if k == 0 else None)
        i = a + int(np.argmax(f[a:b + 1]))
        if f[i] > 0:
            name = rf"$\bar F_{{ad}}$ = {f[i]:.3g}" if len(pulls) == 1 else \
                rf"retraction {k}: $\bar F_{{ad}}$ = {f[i]:.3g}"
            ax.plot(d[i], f[i], "^", color="k" if k == len(pulls) - 1 else "0.5", label=name)
    i_pre = int(np.nanargmin(f))
    ax.plot(d[i_pre], f[i_pre], "kv", label=rf"largest load {-f[i_pre]:.3g} $F_K$"
            if len(pulls) > 1 else rf"preload {-f[i_pre]:.3g} $F_K$")
    ax.axhline(0.0, color="0.6", lw=0.5)
    ax.set_xlabel(r"$\bar d = d / d_K$")
    ax.set_ylabel(r"$\bar F = F / F_K$ (tensile > 0)")
    ax.legend(fontsize=7)
    labels = [str(s) for s in curve["snapshot_label"].values] if "snapshot_label" in curve else []
    first = labels[0] if labels and labels[0] != "maximum force" else "preload"
    for axm, stage in zip(maps, (first, "maximum force")):
        axm.set_axis_off()
        if stage not in labels:
            _no_data(axm, f"no map at {stage}")
            continue
        state = curve["contact_snapshot"].isel(snapshot=labels.index(stage)).values
        axm.imshow(state + 1, cmap=SNAPSHOT_CMAP, vmin=0, vmax=2, origin="lower",
                   interpolation="nearest")
        title = {"preload": "the preload", "maximum force": r"$F_{ad}$"}.get(stage, stage)
        axm.set_title("contact at " + title, fontsize=9)
    a = curve.attrs
    fig.suptitle(f"{curve_layout(a)} brush, N = {a.get('n_pillars')}, "
                 rf"$\bar k$ = {float(a.get('kbar', math.nan)):g}, "
                 + _heights_text(float(a.get('roughness', 0.0)), str(a.get("given_inputs", "")))
                 + f", seed {a.get('seed')}")
    return fig


def load_sharing(curve: xr.Dataset) -> Figure:
    """Force of every pillar at F_ad against its height.

    Forces are in units of the mean pillar force at F_ad (F_ad / N), heights
    in d_K; colour is the pillar's kbar.  Equal load sharing is the line at 1;
    a rough stiff brush loads its tallest pillars, a soft one spreads the load.
    A flat pull-off's file holds the forces alone: its pillars stand at
    height 0 on the brush's kbar.
    """
    fig = _new_figure(5.0, 3.8)
    ax = fig.subplots()
    if "pillar_force_at_adhesive_force" not in curve:
        _no_data(ax, "no per-pillar forces in this curve")
        return fig
    force = curve["pillar_force_at_adhesive_force"].values
    mean = float(curve["adhesive_force"]) / force.size
    flat = "pillar_height_normalized" not in curve
    height = np.zeros(force.size) if flat else curve["pillar_height_normalized"].values
    kbar = (np.full(force.size, float(curve.attrs["kbar"])) if flat
            else curve["pillar_kbar"].values)
    finite = np.isfinite(kbar)
    art = ax.scatter(height, force / mean, c=np.where(finite, kbar, np.nan), s=12,
                     cmap="viridis", label="pillars")
    if finite.any() and np.ptp(kbar[finite]) > 0:
        fig.colorbar(art, ax=ax, label=r"pillar $\bar k$")
    ax.axhline(1.0, color="0.5", lw=0.8, ls="--", label="equal sharing")
    ax.axhline(0.0, color="0.7", lw=0.5)
    ax.set_xlabel(r"pillar height $z_p / d_K$")
    ax.set_ylabel(r"pillar force at $F_{ad}$ / ($F_{ad}/N$), tensile > 0")
    ax.legend(fontsize=7)
    a = curve.attrs
    ax.set_title(f"N = {a.get('n_pillars')}, " + rf"$\bar k$ = {float(a.get('kbar')):g}, "
                 + _heights_text(float(a.get('roughness', 0.0)), str(a.get("given_inputs", ""))),
                 fontsize=9)
    return fig


#: Labels of the quantities the convergence figure draws.
CONVERGENCE_LABELS = {
    "adhesive_force_normalized": FAD_LABEL,
    "work_of_separation_normalized": r"$\bar W$",
}


def _kbar_text(kbar: float) -> str:
    return "rigid" if math.isinf(kbar) else f"{kbar:.3g}"


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
    fig = _new_figure(3.2 * n_cols, 1.9 * n_rows + 0.4)
    axes = fig.subplots(n_rows, n_cols, squeeze=False)
    if not cases:
        _no_data(axes[0][0], "no case with results")
        return fig
    h_all = conv["h"].values
    h_line = np.linspace(0.0, float(np.nanmax(h_all)) * 1.05, 200)
    for row, case in enumerate(cases):
        title = (f"{case.get('layout', '')} N={case.get('n_pillars', '')}, "
                 rf"$\bar k$={_kbar_text(float(case.get('kbar', math.nan)))}")
        if case.get("seed", 0):
            title += f", seed {case['seed']}"
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


def save(fig: Figure, path: str | Path, dpi: int = 150) -> None:
    """Write a figure (format from the suffix; none: matplotlib's default format,
    its suffix added, as savefig does) atomically, creating the directory."""
    path = Path(path)
    if not path.suffix:
        path = path.with_name(f"{path.name}.{matplotlib.rcParams['savefig.format']}")
    write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format=path.suffix[1:].lower()))
