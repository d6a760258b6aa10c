"""The paper's Figures 5-8 drawn from a sweep dataset, `lattices`, which
compares layouts and pillar shapes of the same N, and `rigid_phi`, the rigid
limit against the filling factor of a sweep of several phi.

Each function takes the dataset of `brushcore.data.aggregate.build_sweep`
and returns a `matplotlib.figure.Figure`.  Of a sweep of several phi the
figures but `rigid_phi` draw one (`brushcore.data.views.phi_slice`: the one
nearest the paper's 0.12) and say which in their title.  Brushes or layouts absent from a
sweep are skipped, and a panel with nothing to show says so instead of
failing.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence

import numpy as np
import xarray as xr
from matplotlib.figure import Figure
from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter

from brushcore.model import theory
from brushcore.model.lattices import hexagonal_lattice
from brushcore.model.shapes import parse_shape_label
from brushcore.data.aggregate import PHI_DIM, SHAPE_DIM
from brushcore.data.views import (SHOWN_SHAPE, finest_grid, flat_slice, kbar_index, phi_note,
                                  phi_slice, shape_slice, snapshots, swept_phis)
from brushcore.data.summary import fit_soft_prefactor, on_plateau, seed_mean, soft_plateau
from brushcore.data.figures.common import (FAD_LABEL, HEX_LABEL, HEX_LINE, K_LABEL, LAYOUT_COLORS,
                                           SHAPE_MARKERS, SNAPSHOT_CMAP, W_LABEL,
                                           break_before_rigid, brush_colors, kbar_axes, kbar_text,
                                           kbar_x, layout_styles, new_figure, no_data, panel_title,
                                           rigid_ticks, rigid_x, seed_range, shape_text,
                                           snapshot_key, sweep_layouts, sweep_phi, title_notes)


#: Fig. 8 draws eq. 27 only where it exceeds this (W of a compact punch is 1).
SOFT_WORK_FLOOR = 0.3


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
    sweep = phi_slice(sweep)  # of several phi, the one nearest the paper's, said in the title
    sweep = finest_grid(flat_slice(sweep, None))  # one curve per case: the best-resolved one
    cases = [k for k in kbar if _curve(sweep, layout, n_pillars, k, seed) is not None]
    n_snap = int(sweep.sizes.get("snapshot", 0))
    rows = max(len(cases), 1)
    fig = new_figure(3.2 + 1.3 * n_snap, 2.4 * rows)
    grid = fig.add_gridspec(rows, 1 + n_snap, width_ratios=[3.0] + [1.0] * n_snap)
    side = math.isqrt(n_pillars)
    name = f"{side} x {side}" if layout == "regular" and side * side == n_pillars else str(n_pillars)
    pillars = title_notes("" if shape == "disc" else shape_text(shape), phi_note(sweep))
    fig.suptitle(_wrapped(fig, f"{layout} brush, N = {name} pillars{pillars}"))
    if not cases:
        no_data(fig.add_subplot(grid[0, :]), f"no flat {layout} runs with N = {n_pillars}")
        return fig
    for row, k in enumerate(cases):
        d, f = _curve(sweep, layout, n_pillars, k, seed)
        ax = fig.add_subplot(grid[row, 0])
        ax.plot(d, f, color="C0", lw=1.2)
        # A preloaded case is drawn as its loop: approach (F < 0), then retraction.
        loop = ", from the preload" if float(np.min(f)) < 0.0 else ""
        ax.set_title(f"({chr(ord('a') + row)}) " + r"$\bar k$" + f" = {kbar_text(k)}{loop}",
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
                no_data(empty, f"no contact snapshots of this case in the sweep{kept}")
            continue
        # Numbered in the order of their steps: a protocol's file keeps the
        # "maximum force" map after "separated", though it comes first.
        # (a stage never reached reads as NaN, the fill, through xarray: -1 here)
        stored = [int(s) if np.isfinite(s) else -1
                  for s in np.asarray(snap["snapshot_step"].values, dtype=float)]
        order = sorted(range(len(stored)), key=lambda j: (stored[j] < 0, stored[j]))
        steps = [stored[j] for j in order]
        names = [str(snap["snapshot_label"].values[j]) for j in order]
        for slot, shown in enumerate(_snapshot_panels(steps)):
            image_ax = fig.add_subplot(grid[row, 1 + slot])
            image_ax.set_axis_off()
            j = order[shown[0]]
            if stored[j] < 0:
                continue
            image_ax.imshow(snap["contact_snapshot"].values[j] + 1, cmap=SNAPSHOT_CMAP,
                            vmin=0, vmax=2, interpolation="nearest", origin="lower")
            image_ax.set_title(_snapshot_title(shown, names), fontsize=7)
        # One dot per distinct step; snapshots sharing a step share its label ("1,2").
        for step in sorted({s for s in steps if 0 <= s < d.size}):
            label = ",".join(str(j + 1) for j, s in enumerate(steps) if s == step)
            ax.plot(d[step], f[step], "o", ms=4, color="C3")
            ax.annotate(label, (d[step], f[step]), textcoords="offset points",
                        xytext=(3, 3), fontsize=7)
    if n_snap:  # the maps' colour key
        snapshot_key(fig, loc="upper right")
    return fig


def _snapshot_panels(steps: Sequence[int]) -> list[list[int]]:
    """The snapshots each of Fig. 5's map panels draws, as indices into
    ``steps`` (the snapshots' steps in the order of the curve, -1 for a
    stage never reached).

    Snapshots of one step share one panel, as they share one dot on the
    curve ("1,2"): where nothing detaches before the maximum, "start" and
    "before maximum" are the same step, whose map two panels drew twice.
    A stage never reached keeps its own (empty) panel.
    """
    panels: dict[int, list[int]] = {}
    for j, step in enumerate(steps):
        panels.setdefault(step if step >= 0 else -1 - j, []).append(j)
    return list(panels.values())


def _snapshot_title(shown: Sequence[int], names: Sequence[str]) -> str:
    """A map panel's title: its snapshots' numbers as on the curve's dot
    ("1,2") and their stages, one per line ("1,2: start\n= before maximum")."""
    return ",".join(str(j + 1) for j in shown) + ": " + "\n= ".join(names[j] for j in shown)


def _wrapped(fig: Figure, title: str) -> str:
    """A title wrapped to the figure's width (a one-panel figure clipped
    "... (phi = 0.12 of 0.08, 0.12, 0.2)" at both ends)."""
    return textwrap.fill(title, max(30, int(10 * fig.get_figwidth())))


def _shape_note(sweep: xr.Dataset) -> str:
    """" (disc pillars)" where the sweep is one shape of several (`shape_slice`),
    " (phi = 0.12 of 0.08, 0.12, 0.2)" where it is one phi of several
    (`phi_slice`), both joined where both."""
    shape = sweep.attrs.get(SHOWN_SHAPE)
    return title_notes(f"{shape} pillars" if shape else "", phi_note(sweep))


def _per_brush_panels(sweep: xr.Dataset, title: str) -> tuple[Figure, dict[str, object]]:
    layouts = sweep_layouts(sweep)
    fig = new_figure(4.2 * max(len(layouts), 1), 3.6)
    # One y range for every layout: the panels are read against each other.
    axes = fig.subplots(1, max(len(layouts), 1), squeeze=False, sharey=True)[0]
    fig.suptitle(_wrapped(fig, title + _shape_note(sweep)))
    if not layouts:  # a sweep of brushes as made alone: said, not a blank panel
        no_data(axes[0], "no flat runs (brushes given heights, stiffnesses or a gap map\n"
                         "are drawn in rough_*.png)")
    return fig, dict(zip(layouts, axes))


def _brush_series(sweep: xr.Dataset, name: str, layout: str) -> list[tuple[int, xr.DataArray]]:
    """(N, seed-mean of `name` against kbar) for every brush of a layout that ran."""
    series = [(int(n), seed_mean(sweep, name, layout, int(n))) for n in sweep.n_pillars.values]
    return [(n, s) for n, s in series if s.size]


def _kbar_figure(sweep: xr.Dataset, title: str) -> tuple:
    """What Figs. 6 and 8 start from: the sweep at each case's finest grid,
    the figure and its panel per layout, a colour per N, the kbar values and
    the x of the rigid column (`rigid_x`); of a sweep of several phi, one
    (`phi_slice`), which the title names."""
    sweep = finest_grid(phi_slice(sweep))
    fig, axes = _per_brush_panels(sweep, title)
    kbars = np.asarray(sweep.kbar.values, dtype=float)
    return sweep, fig, axes, brush_colors(sweep.n_pillars.values), kbars, rigid_x(kbars)


def _panels(sweep: xr.Dataset, axes: dict, name: str):
    """Per layout of ``axes``: its index, name, axes, filling factor and the
    seed-mean series of ``name`` per N (`_brush_series`)."""
    for index, (layout, ax) in enumerate(axes.items()):
        yield index, layout, ax, sweep_phi(sweep, layout), _brush_series(sweep, name, layout)


#: Legend entry of the hollow markers `_fewer_seeds` draws.
FEWER_SEEDS_LABEL = "hollow: a mean of fewer seeds than the brush ran"


def _seed_runs(sweep: xr.Dataset, name: str, layout: str, n: int,
               series: xr.DataArray) -> xr.DataArray:
    """Every seed's ``name`` of one brush at the kbar of its seed mean ``series``."""
    return sweep[name].sel(layout=layout, n_pillars=n).sel(kbar=series.kbar)


def _seeds_ran(runs: xr.DataArray) -> int:
    """Seeds that ran the brush at any kbar (``runs``: `_seed_runs`)."""
    return int(runs.notnull().any("kbar").sum())


def _fewer_seeds(ax, runs: xr.DataArray, series: xr.DataArray, x_inf: float,
                 color: str) -> bool:
    """Redraw hollow the points of ``series`` (a seed mean against kbar) that
    rest on fewer seeds than the brush ran at any kbar (``runs``:
    `_seed_runs`): a missing seed is said, not drawn as a full mean with a
    narrow bar.  Whether any was."""
    fewer = runs.notnull().sum("seed").values < _seeds_ran(runs)
    if fewer.any():
        ax.plot(kbar_x(series.kbar, x_inf)[fewer], series.values[fewer], "o", ms=4,
                mfc="white", mec=color, zorder=3)
    return bool(fewer.any())


def _fewer_seeds_key(ax, shown: bool) -> None:
    if shown:
        ax.plot([], [], "o", ms=4, mfc="white", mec="k", label=FEWER_SEEDS_LABEL)


def fig6(sweep: xr.Dataset) -> Figure:
    """Fig. 6: adhesive force against kbar (log axis) per N, one panel per layout.

    The rigid limit phi^(-1/4) (eq. 5) is the solid line, drawn for each N
    at the phi its brush realised (`sweep_phi`), as Fig. 8's soft limit is:
    black, or in the N's colour where they stand apart (`RIGID_LINES_APART`);
    the compact punch F_ad = 1 is dotted; a hexagonal panel adds
    each N's lattice at its local filling factor
    (`theory.hexagonal_rigid_limit`, dash-dot).  With
    several seeds the bars span min to max, and a hollow marker is a mean of
    fewer seeds than its brush ran (`_fewer_seeds`).
    Rigid pillars (kbar = inf) are drawn at "rigid" (`rigid_x`), not joined
    to the finite kbar.
    """
    sweep, fig, axes, colors, kbars, x_inf = _kbar_figure(
        sweep, "Adhesive force against pillar stiffness")
    for index, layout, ax, phi, brushes in _panels(sweep, axes, "adhesive_force_normalized"):
        fewer = False
        for n, series in brushes:
            runs = _seed_runs(sweep, "adhesive_force_normalized", layout, n, series)
            low, high = runs.min("seed", skipna=True), runs.max("seed", skipna=True)
            x, y, lo, hi = break_before_rigid(x_inf, kbar_x(series.kbar, x_inf), series,
                                               low, high)
            seeds = _seeds_ran(runs)
            ax.errorbar(x, y, yerr=[y - lo, hi - y], marker="o", ms=4, capsize=2,
                        color=colors[n], label=f"N = {n}" + (
                            f" (mean, min-max of {seeds} seeds)" if seeds > 1 else ""))
            fewer |= _fewer_seeds(ax, runs, series, x_inf, colors[n])
        kbar_axes(ax, panel_title(index, layout), FAD_LABEL, kbars, x_inf)
        if not brushes:
            no_data(ax, f"no flat {layout} runs")
            continue
        if math.isfinite(phi):
            # each brush's own phi as realised, as its data are normalised (`sweep_phi`)
            realised = {n: sweep_phi(sweep, layout, n) for n, _ in brushes}
            limits = [theory.rigid_limit(realised[n]) for n, _ in brushes]
            apart = _rigid_lines_apart(limits)
            for (n, _), limit in zip(brushes, limits):
                ax.axhline(limit, color=colors[n] if apart else "k", lw=1.2)
            ax.plot([], [], "k-", lw=1.2, label=_rigid_label(limits, apart))
            if layout == "hexagonal":  # N that no lattice fills stand denser
                for i, (n, _) in enumerate(brushes):
                    ax.axhline(theory.hexagonal_rigid_limit(realised[n], n), color=colors[n],
                               ls=HEX_LINE, lw=1.0, label=HEX_LABEL if i == 0 else None)
        ax.axhline(1.0, color="k", lw=0.8, ls=":", label="compact punch")
        _fewer_seeds_key(ax, fewer)
        ax.legend(fontsize=7)
    return fig


#: Relative spread of a panel's rigid limits (one per N, at its realised phi)
#: above which Fig. 6 draws each in its N's colour.  Below it they lie about
#: a line's width apart, drawn as one black line: at 512^2 the default sweep's
#: regular brushes realise phi 0.1172-0.1182, limits 1.706-1.709 (0.2 %; 0.6 %
#: above the 1.699 of the phi asked), its random ones 0.1198-0.1201 (0.05 %);
#: at 64^2 regular 4 and 16 realise 0.117 and 0.125, limits 1.6 % apart.
RIGID_LINES_APART = 0.01


def _rigid_lines_apart(limits: Sequence[float]) -> bool:
    """Whether Fig. 6's rigid limits of one panel (``limits``) differ by
    more than `RIGID_LINES_APART`: enough to be told apart, by colour."""
    return max(limits) - min(limits) > RIGID_LINES_APART * min(limits)


def _rigid_label(limits: Sequence[float], apart: bool) -> str:
    """Fig. 6's key of the rigid limit phi^(-1/4) at each brush's realised
    phi (``limits``): its value, or the span of them, drawn ``apart`` in
    their N's colours (`_rigid_lines_apart`) or as one black line."""
    low, high = f"{min(limits):.3f}", f"{max(limits):.3f}"
    if low == high:
        return rf"rigid limit $\varphi^{{-1/4}}$ = {min(limits):.2f}"
    return (rf"rigid limit $\varphi^{{-1/4}}$ = {low}-{high}" + "\n(each N's realised "
            + r"$\varphi$" + (", in its colour)" if apart else ")"))


def fig7(sweep: xr.Dataset) -> Figure:
    """Fig. 7: soft-plateau adhesive force against N, log-log, with N^(1/4).

    The plateau value is F_ad at the softest kbar run for each brush; a
    brush whose two softest kbar differ by more than `PLATEAU_RTOL` has not
    reached it (`brushcore.data.summary.on_plateau`) and is drawn in grey
    with its layout's marker, left out of the fit.  Each layout gets its own
    fit F = c N^(1/4), drawn in its colour, with 1/c (the paper's 1.2-1.3)
    and the free exponent printed on the plot.
    """
    sweep = finest_grid(phi_slice(sweep))
    fig = new_figure(4.6, 3.8)
    ax = fig.add_subplot()
    ax.set_title(_wrapped(fig, "Soft plateau of the adhesive force" + _shape_note(sweep)))
    fitted: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # layout -> plateau (N, F)
    styles = layout_styles(sweep_layouts(sweep))
    off = []  # (N, F) of brushes whose softest kbar is not on the plateau
    for layout in sweep_layouts(sweep):
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
        no_data(ax, "no flat runs")
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
    (`brushcore.model.theory.soft_work`); W = 1 is the rigid compact punch;
    rigid pillars stand apart at "rigid", and means of fewer seeds than the
    brush ran are hollow, as in `fig6`.
    """
    sweep, fig, axes, colors, kbars, x_inf = _kbar_figure(
        sweep, "Work of separation against pillar stiffness")
    for index, layout, ax, phi, brushes in _panels(sweep, axes, "work_of_separation_normalized"):
        fewer = False
        for n, series in brushes:
            ax.plot(*break_before_rigid(x_inf, kbar_x(series.kbar, x_inf), series), "o-",
                    ms=4, color=colors[n], label=f"N = {n}")
            runs = _seed_runs(sweep, "work_of_separation_normalized", layout, n, series)
            fewer |= _fewer_seeds(ax, runs, series, x_inf, colors[n])
            if math.isfinite(phi):
                # Only where the springs' energy matters; it falls as 1/kbar (0 if rigid).
                kbar = series.kbar.values
                soft = np.asarray(theory.soft_work(n, sweep_phi(sweep, layout, n), kbar))
                keep = soft >= SOFT_WORK_FLOOR
                ax.plot(kbar[keep], soft[keep], "--", lw=1, color=colors[n])
        ax.set_yscale("log")
        kbar_axes(ax, panel_title(index, layout), W_LABEL, kbars, x_inf)
        if not brushes:
            no_data(ax, f"no flat {layout} runs")
            continue
        ax.axhline(1.0, color="k", lw=0.8, ls=":", label="compact punch")
        ax.plot([], [], "k--", lw=1,
                label=r"soft limit $2\sqrt{\varphi/\pi}/(\sqrt{N}\bar k)$ (eqs. 25-26)")
        _fewer_seeds_key(ax, fewer)
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
        for layout in sweep_layouts(sweep):
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
    Rigid pillars (kbar = inf) are drawn at "rigid" (`rigid_x`), not joined
    to the finite kbar.  Black lines: the rigid limit phi^(-1/4) (eq. 5, solid,
    at the phi the panel's regular brush realised, as Figs. 6 and 8) and the
    soft limit N^(1/4) of discs (eq. 6, dashed: other shapes let go below
    Kendall's force); grey dash-dot: the hexagonal lattice's rigid limit at its
    local filling factor phi / fill (`theory.hexagonal_rigid_limit`), at the
    phi the hexagonal brush realised.

    Parameters
    ----------
    sweep : flat brushes of a sweep with every shape (`flat_slice(sweep, None)`).
    """
    sweep = finest_grid(phi_slice(sweep)[[name for name in ("adhesive_force_normalized",
                                                            "phi_actual") if name in sweep]])
    series = {int(n): _lattice_series(sweep, int(n)) for n in sweep.n_pillars.values}
    compared = {n: s for n, s in series.items() if len(s) > 1} or \
        {n: s for n, s in series.items() if s}
    fig = new_figure(5.2 * max(len(compared), 1), 4.0)
    axes = fig.subplots(1, max(len(compared), 1), squeeze=False)[0]
    fig.suptitle(_wrapped(fig, "Adhesive force of lattices and pillar shapes of the same N"
                          + title_notes(phi_note(sweep))))
    if not compared:
        no_data(axes[0], "no runs")
        return fig
    phi = sweep_phi(sweep)
    kbars = np.asarray(sweep.kbar.values, dtype=float)
    x_inf = rigid_x(kbars)
    for index, (ax, (n, brushes)) in enumerate(zip(axes, compared.items())):
        for layout, shape, runs in brushes:
            x, mean, low, high = break_before_rigid(
                x_inf, kbar_x(runs.kbar.values, x_inf), *seed_range(runs))
            marker, line = SHAPE_MARKERS.get(parse_shape_label(shape)["shape"], ("^", "-."))
            ax.errorbar(x, mean, yerr=[mean - low, high - mean], marker=marker, ls=line, ms=4,
                        capsize=2, color=LAYOUT_COLORS.get(layout, f"C{3 + index}"),
                        mfc="none" if shape != "disc" else None,
                        label=f"{layout}, {shape_text(shape)}")
        if math.isfinite(phi):
            # solid as in Fig. 6, the soft limit dashed as in Fig. 8: one key for all
            ax.axhline(theory.rigid_limit(sweep_phi(sweep, "regular", n)), color="k",
                       lw=1.2, label=r"rigid limit $\varphi^{-1/4}$")
            if any(b[0] == "hexagonal" for b in brushes) and hexagonal_lattice(n):
                ax.axhline(theory.hexagonal_rigid_limit(sweep_phi(sweep, "hexagonal", n), n),
                           color="0.45", ls=HEX_LINE, lw=1.0, label=HEX_LABEL)
        # Kendall's force per pillar: squares and ellipses let go below it
        ax.axhline(theory.soft_limit(n), color="k", ls="--", lw=1.0,
                   label=r"soft limit $N^{1/4}$ (discs)")
        ax.set_xscale("log")
        rigid_ticks(ax, kbars, x_inf)
        ax.set_title(f"({chr(ord('a') + index)}) N = {n}", loc="left")
        ax.set_xlabel(K_LABEL)
        ax.set_ylabel(FAD_LABEL)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # off the data
    return fig


def rigid_phi(sweep: xr.Dataset) -> Figure:
    """The rigid limit against the filling factor: F_ad of rigid pillars
    (kbar = inf) per N against phi, one panel per layout that ran rigid,
    with the rigid limit phi^(-1/4) (eq. 5, solid) and the compact punch
    F_ad = 1 (dotted).

    Each brush is drawn at the phi it realised (the mean ``phi_actual`` of
    its seeds), as its F_ad is normalised by Kendall's force of the area it
    realised; with several seeds the dot is their mean and the bars span
    min to max.  Each case at its finest grid.  Drawn where the generated
    brushes ran more than one phi (the sweep's ``phi`` dimension); a sweep
    of one phi, or without rigid runs, gets a panel that says so.
    """
    sweep = finest_grid(sweep)
    layouts = sweep_layouts(sweep)
    kbars = np.asarray(sweep.kbar.values, dtype=float)
    rigid = np.flatnonzero(np.isinf(kbars))
    runs = {}
    if PHI_DIM in sweep.dims and rigid.size:
        force = sweep["adhesive_force_normalized"].isel(kbar=int(rigid[0]))
        phi = sweep["phi_actual"].isel(kbar=int(rigid[0]))
        for layout in layouts:
            for n in sweep.n_pillars.values:
                f = force.sel(layout=layout, n_pillars=n)
                ran = f.notnull().any("seed")
                if int(ran.sum()):
                    realised = phi.sel(layout=layout, n_pillars=n).mean("seed", skipna=True)
                    runs.setdefault(layout, []).append(
                        (int(n), *(v.values[ran.values] for v in (realised, *seed_range(f)))))
    fig = new_figure(4.2 * max(len(runs), 1), 3.6)
    axes = fig.subplots(1, max(len(runs), 1), squeeze=False, sharey=True)[0]
    fig.suptitle(_wrapped(fig, "Rigid limit against the filling factor" + _shape_note(sweep)))
    if not runs:
        phis = swept_phis(sweep)
        no_data(axes[0], "no rigid runs (kbar = inf) at several phi" if len(phis) > 1 or
                PHI_DIM in sweep.dims else
                "one filling factor only" + (f" (phi = {phis[0]:g})" if phis else "")
                + ":\nrun a list of phi with rigid pillars (kbar .inf)")
        return fig
    colors = brush_colors([n for brushes in runs.values() for n, *_ in brushes])
    for index, (ax, (layout, brushes)) in enumerate(zip(axes, runs.items())):
        drawn = []
        for n, x, mean, low, high in brushes:
            order = np.argsort(x)
            x, mean, low, high = x[order], mean[order], low[order], high[order]
            ax.errorbar(x, mean, yerr=[mean - low, high - mean], marker="o", ms=4, capsize=2,
                        color=colors[n], label=f"N = {n}")
            drawn += [float(v) for v in x if np.isfinite(v)]
        if drawn:
            span = np.linspace(min(drawn) / 1.1, max(drawn) * 1.1, 60)
            ax.plot(span, theory.rigid_limit(span), "k-", lw=1.2,
                    label=r"rigid limit $\varphi^{-1/4}$ (eq. 5)")
        ax.axhline(1.0, color="k", lw=0.8, ls=":", label="compact punch")
        ax.set_title(panel_title(index, layout) + r", $\bar k$ = rigid", loc="left")
        ax.set_xlabel(r"filling factor $\varphi$ (as realised)")
        ax.set_ylabel(FAD_LABEL)
        ax.legend(fontsize=7)
    return fig
