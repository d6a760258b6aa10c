"""Figures of rough, graded and preloaded brushes: F_ad against roughness
and preload from a sweep, and one protocol curve's loops and load sharing.
"""

from __future__ import annotations

import math
import textwrap

import numpy as np
import xarray as xr
from matplotlib.figure import Figure

from brushcore.model import theory
from brushcore.model.inputs import parse_protocol
from brushcore.model.layout_file import curve_layout
from brushcore.data.aggregate import HEIGHT_SD
from brushcore.data.views import finest_grid, phi_note, phi_slice
from brushcore.data.figures.paper import FEWER_SEEDS_LABEL
from brushcore.data.figures.common import (FAD_LABEL, SNAPSHOT_CMAP, kbar_text, new_figure,
                                           no_data, seed_range, snapshot_key, sweep_phi,
                                           title_notes)


#: Where the elastic foundation's soft limit is drawn (`theory`'s, shared with the summary).
MIN_FOUNDATION_STRETCH = theory.MIN_FOUNDATION_STRETCH


def _rough_series(sweep: xr.Dataset, name: str, layout: str, n: int, kbar: float,
                  **at: float) -> tuple[xr.DataArray, xr.DataArray, xr.DataArray]:
    """Seed mean, min and max of a rough-sweep variable for one brush and kbar,
    at the figure's stiffness spread (`_spread_shown`) unless ``at`` names one."""
    at = {"kbar_spread": _spread_shown(sweep), **at}
    runs = sweep[name].sel(layout=layout, n_pillars=n, kbar=kbar, **at)
    return seed_range(runs)


def _spread_shown(sweep: xr.Dataset) -> float:
    """The stiffness spread C the roughness and preload figures show: 0 (equal
    stiffness) where it ran, else the smallest C of the sweep (a sweep of
    ``kbar_spread: [0.5]`` alone drew "no rough runs" before)."""
    if "kbar_spread" not in sweep.dims:
        return 0.0
    spreads = np.asarray(sweep.kbar_spread.values, dtype=float)
    return 0.0 if 0.0 in spreads else float(spreads.min())


def _spread_note(sweep: xr.Dataset) -> str:
    """A title's note of the stiffness spread shown where it is not 0: every
    pillar then has its own kbar, the legend's being their mean."""
    spread = _spread_shown(sweep)
    return "" if spread == 0 else (
        f"; stiffness spread C = {spread:g} (the smallest run), " + r"$\bar{k}$ its mean")


def _notes(sweep: xr.Dataset, spread: bool = True) -> str:
    """A rough figure's title notes: the stiffness spread shown where it is
    not 0 (`_spread_note`, unless ``spread`` is False: a figure over C), and
    the phi shown of several (`phi_note`)."""
    return (_spread_note(sweep) if spread else "") + title_notes(phi_note(sweep))


def _drawn_spread(sweep: xr.Dataset, layout: str, n: int, kbar: float, **at: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(height SD as drawn [d_K], F_ad / F_K) of every seed and roughness of
    one brush and kbar that ran; empty where the sweep does not record the
    SD (`HEIGHT_SD`: a flat sweep, or one built before 2026-12-06).

    The ``roughness`` coordinate is the S asked for, only the expectation of
    what a seed draws: 16 pillars at S = 0.3 drew 0.370 and 0.157.
    """
    if HEIGHT_SD not in sweep:
        return np.empty(0), np.empty(0)
    where = dict(layout=layout, n_pillars=n, kbar=kbar, kbar_spread=_spread_shown(sweep), **at)
    spread = sweep[HEIGHT_SD].sel(where)
    force = sweep["adhesive_force_normalized"].sel(where).transpose(*spread.dims)
    spread, force = np.ravel(spread.values), np.ravel(force.values)
    ran = np.isfinite(spread) & np.isfinite(force)
    return spread[ran], force[ran]


#: Legend entry of `rough_roughness`'s open markers (`_drawn_spread`).
DRAWN_SPREAD_LABEL = "open: a seed at its heights' SD"


def _rough_ready(sweep: xr.Dataset, fig: Figure) -> bool:
    """Whether the sweep has rough cases (its ROUGH_DIMS), else a placeholder.
    Any stiffness spread will do: the figures draw `_spread_shown`."""
    if "roughness" in sweep.dims:
        return True
    no_data(fig.add_subplot(), "no rough runs in this sweep")
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
                       width: float, note: str = "", kind: str = "rough") -> str:
    """A rough figure's title, wrapped to its ``width`` [in]: a ``kind``
    ("rough", "graded") brush, or a brush as made with what it was given;
    ``note`` ends it."""
    words = ", ".join(GIVEN_WORDS.get(name, name) for name in given.split())
    brush = (f"the {layout} brush as made ({words} given)" if given
             else f"a {kind} {layout} brush")
    return textwrap.fill(f"{what} {brush}, N = {n_pillars}{note}", max(30, int(11 * width)))


def _heights_text(roughness: float, given: str) -> str:
    """A panel's heights: "roughness S d_K", or "heights given"."""
    return "heights given" if "heights" in given.split() else (
        f"roughness {roughness:g} " + r"$d_K$")


def _curve_case(attrs: dict) -> str:
    """A curve's case for a title: its heights, stiffness spread C (where not
    0) and preload, or the protocol's first load (the figures named kbar and
    roughness alone: a spread or preloaded curve read as the flat one)."""
    text = _heights_text(float(attrs.get("roughness", 0.0)), str(attrs.get("given_inputs", "")))
    spread = float(attrs.get("kbar_spread", 0.0))
    if spread:
        text += f", stiffness spread C = {spread:g}"
    protocol = attrs.get("protocol_normalized")
    first = _first_load(str(protocol)) if protocol else None
    return text + (f", preload {float(attrs.get('preload', 0.0)):g} " + r"$F_K$"
                   if not protocol else
                   f", first load {first:g} " + r"$F_K$" if first is not None
                   else ", protocol " + str(protocol))


def rough_roughness(sweep: xr.Dataset, layout: str = "regular", n_pillars: int = 256
                    ) -> Figure:
    """Adhesive force against roughness per kbar, one panel per preload.

    Filled markers are the seed mean at the roughness S asked for, its bars
    span the seeds; open markers are each seed at the standard deviation of
    the heights it drew (`_drawn_spread`), which a brush of few pillars
    draws far from S.  Dashed lines are the soft limit (elastic foundation,
    every pillar attached, large N): N^(1/4) G(S d_K / lambda) with G
    `theory.gaussian_spread_pull_off` and lambda `theory.foundation_stretch`,
    drawn where it applies: where lambda is at least `MIN_FOUNDATION_STRETCH`,
    on pillars of equal stiffness (not at a spread C > 0, `_spread_shown`).
    """
    sweep = finest_grid(phi_slice(sweep))  # one value per case: the best-resolved one
    # 1.6 in more than a panel each: the side legend took a one-panel figure's axes
    fig = new_figure(4.2 * max(1, sweep.sizes.get("preload", 1)) + 1.6, 3.6)
    if not _rough_ready(sweep, fig):
        return fig
    preloads = [float(p) for p in sweep.preload.values]
    axes = fig.subplots(1, len(preloads), squeeze=False)[0]
    phi = sweep_phi(sweep, layout, n_pillars)
    kbars = [float(k) for k in sweep.kbar.values]
    colors = {k: f"C{i}" for i, k in enumerate(kbars)}
    s_axis = np.asarray(sweep.roughness.values, dtype=float)
    given = _given(sweep, layout)  # heights given, not drawn: no Gaussian soft limit
    soft_drawn = spread_drawn = False
    protocol = sweep.attrs.get("protocol_normalized")  # its loads stand for the preload
    equal = _spread_shown(sweep) == 0
    for ax, preload in zip(axes, preloads):
        for kbar in kbars:
            mean, low, high = _rough_series(sweep, "adhesive_force_normalized", layout,
                                            n_pillars, kbar, preload=preload)
            if not np.isfinite(mean.values).any():
                continue
            ax.errorbar(s_axis, mean, yerr=[mean - low, high - mean], marker="o", ms=4,
                        capsize=2, color=colors[kbar], label=rf"$\bar k$ = {kbar_text(kbar)}")
            spread, force = _drawn_spread(sweep, layout, n_pillars, kbar, preload=preload)
            if spread.size:  # part of a seed bar is the scatter of what the seeds drew
                ax.plot(spread, force, "o", ms=5, mfc="none", mec=colors[kbar], mew=0.8)
                spread_drawn = True
            lam = float(theory.foundation_stretch(n_pillars, phi, kbar))  # 0 if rigid
            reach = max(s_axis.max(), spread.max(initial=0.0))  # to the widest drawn too
            # equal stiffness only: at C > 0 (`_spread_shown`) pillars let go at other stretches
            if lam >= MIN_FOUNDATION_STRETCH and s_axis.max() > 0 and not given and equal:
                span = np.linspace(0.0, reach, 60)
                soft = [theory.gaussian_spread_pull_off(s / lam) for s in span]
                ax.plot(span, theory.soft_limit(n_pillars) * np.asarray(soft), "--", lw=1,
                        color=colors[kbar])
                soft_drawn = True
        ax.set_title(f"preload {preload:g} " + r"$F_K$" if protocol is None else
                     "last retraction of\n" + textwrap.fill(protocol, 36), fontsize=8)
        ax.set_ylabel(FAD_LABEL)
        _no_false_zoom(ax)  # one roughness: its axis read "1e-12+1.354190643"
    for ax in axes:
        ax.set_xlabel("height spread [$d_K$]: roughness $S$ asked for (filled),\n"
                      "SD of the heights as drawn (open)" if spread_drawn else
                      r"roughness $S$ [$d_K$]")
    if spread_drawn:
        axes[0].plot([], [], "o", ms=5, mfc="none", mec="k", mew=0.8, label=DRAWN_SPREAD_LABEL)
    if soft_drawn:
        axes[0].plot([], [], "k--", lw=1, label="soft limit (elastic foundation)")
    _side_legend(fig, axes)
    fig.suptitle(_rough_brush_title("Adhesive force of", layout, n_pillars, given,
                                    fig.get_figwidth(), _notes(sweep)))
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
    """Adhesive force against preload per kbar, one panel per roughness, on
    one y range."""
    sweep = finest_grid(phi_slice(sweep))  # one value per case: the best-resolved one
    fig = new_figure(4.2 * max(1, sweep.sizes.get("roughness", 1)), 3.6)
    if not _rough_ready(sweep, fig):
        return fig
    given = _given(sweep, layout)
    # a panel per roughness this brush ran (a brush given heights: S = 0 alone)
    ran = sweep["adhesive_force_normalized"].sel(layout=layout, n_pillars=n_pillars,
                                                 kbar_spread=_spread_shown(sweep))
    roughs = [float(r) for r in sweep.roughness.values
              if np.isfinite(ran.sel(roughness=r).values).any()] or [0.0]
    # one y range: the roughness panels are read against each other
    axes = fig.subplots(1, len(roughs), squeeze=False, sharey=True)[0]
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
                        capsize=2, color=f"C{i}", label=rf"$\bar k$ = {kbar_text(kbar)}")
        ax.set_title(_heights_text(rough, given) if protocol is None else
                     _heights_text(rough, given) + ", last retraction of\n"
                     + textwrap.fill(protocol, 36), fontsize=8 if protocol else 9)
        ax.set_xlabel(r"preload [$F_K$]" if protocol is None else
                      r"load of the protocol's first waypoint [$F_K$]" if first is not None
                      else r"preload [$F_K$] (0: the protocol starts with a displacement)")
        ax.set_ylabel(FAD_LABEL)
    for ax in axes:  # after every panel's data: on the first alone it fixed the shared
        _no_false_zoom(ax)  # range before the others', cutting off their points
    _side_legend(fig, axes)
    fig.suptitle(_rough_brush_title("Adhesive force against preload of", layout, n_pillars,
                                    given, fig.get_figwidth(), _notes(sweep)))
    return fig


#: Legend entries of `rough_spread`'s soft limits (equal heights, soft springs).
SPREAD_LIMIT_LABEL = r"soft limit, many pillars: $N^{1/4} G(C)$"
SEED_LIMIT_LABEL = "soft limit of these seeds' stiffnesses"


def _spread_ready(sweep: xr.Dataset, fig: Figure) -> bool:
    """Whether the sweep ran a stiffness spread C > 0, else a placeholder."""
    spreads = (np.asarray(sweep.kbar_spread.values, dtype=float)
               if "kbar_spread" in sweep.dims else np.zeros(1))
    if (spreads > 0).any():
        return True
    no_data(fig.add_subplot(), "no stiffness spread in this sweep\n"
            f"(kbar_spread: {', '.join(f'{c:g}' for c in spreads)})")
    return False


def rough_spread(sweep: xr.Dataset, layout: str = "regular", n_pillars: int = 256
                 ) -> Figure:
    """Adhesive force against the stiffness spread C per kbar, one panel per
    roughness (columns) and preload (rows) that ran.

    C is the coefficient of variation of the lognormal per-pillar kbar of
    mean kbar (``kbar_spread``; rigid pillars run at C = 0 alone).  Markers
    are the seed mean, bars span the seeds, a hollow marker is a mean of
    fewer seeds than the brush ran (as in Fig. 6; a lattice of equal heights
    at C = 0 runs seed 0 alone, as the workflow runs it).  On a panel of equal
    heights (roughness 0) where a kbar's let-go stretch lambda is at least
    `MIN_FOUNDATION_STRETCH` the soft limit is drawn: pillars let go at
    their own stretch f_c / k_i, the stiffest first, so F_ad / F_K =
    N^(1/4) G(C) for many pillars (`theory.lognormal_stiffness_pull_off`,
    dashed; it does not depend on kbar) and, dotted, the same elastic
    foundation for the stiffnesses the sweep's seeds drew
    (`theory.drawn_stiffness_pull_off`), which a brush of few pillars needs:
    it lies above G (16 pillars at C = 0.5: 0.61-0.65 against 0.49).  The
    half space's interaction keeps soft data up to ~10 % under the lines
    (regular 16, kbar 1e-4, 64^2: 0.91 of N^(1/4) at C = 0, 0.94-1.01 of
    the seeds' line at C = 0.25 and 0.5, seeds 0 and 1).
    """
    sweep = finest_grid(phi_slice(sweep))  # one value per case: the best-resolved one
    roughs, preloads = [0.0], [0.0]
    if "roughness" in sweep.dims and layout in sweep.layout and n_pillars in sweep.n_pillars:
        runs = sweep["adhesive_force_normalized"].sel(layout=layout, n_pillars=n_pillars)
        ran = runs.notnull().any([d for d in runs.dims if d not in ("roughness", "preload")])
        roughs = [float(r) for r in sweep.roughness.values
                  if bool(ran.sel(roughness=r).any())] or roughs
        preloads = [float(p) for p in sweep.preload.values
                    if bool(ran.sel(preload=p).any())] or preloads
    fig = new_figure(3.8 * len(roughs) + 1.8, 3.2 * len(preloads) + 0.6)
    if not _spread_ready(sweep, fig):
        return fig
    axes = fig.subplots(len(preloads), len(roughs), squeeze=False, sharey=True)
    phi = sweep_phi(sweep, layout, n_pillars)
    kbars = [float(k) for k in sweep.kbar.values]
    c_axis = np.asarray(sweep.kbar_spread.values, dtype=float)
    given = _given(sweep, layout)
    protocol = sweep.attrs.get("protocol_normalized")
    brush = sweep["adhesive_force_normalized"].sel(layout=layout, n_pillars=n_pillars)
    seeds = int(brush.notnull().any([d for d in brush.dims if d != "seed"]).sum())
    soft_drawn = fewer_drawn = False
    for row, preload in zip(axes, preloads):
        for ax, rough in zip(row, roughs):
            at = dict(roughness=rough, preload=preload)
            soft = False
            for i, kbar in enumerate(kbars):
                runs = sweep["adhesive_force_normalized"].sel(
                    layout=layout, n_pillars=n_pillars, kbar=kbar, **at)
                mean, low, high = seed_range(runs)
                ok = np.isfinite(mean.values)
                if not ok.any():
                    continue
                x, y = c_axis[ok], mean.values[ok]
                ax.errorbar(x, y, yerr=[y - low.values[ok], high.values[ok] - y], marker="o",
                            ms=4, capsize=2, color=f"C{i}",
                            label=rf"$\bar k$ = {kbar_text(kbar)}")
                # a flat lattice (equal heights and stiffness) runs seed 0 alone
                fixed = (c_axis[ok] == 0) & (rough == 0) & (layout != "random")
                fewer = runs.notnull().sum("seed").values[ok] < np.where(fixed, 1, seeds)
                if fewer.any():
                    ax.plot(x[fewer], y[fewer], "o", ms=4, mfc="white", mec=f"C{i}", zorder=3)
                    fewer_drawn = True
                lam = float(theory.foundation_stretch(n_pillars, phi, kbar))  # 0 if rigid
                soft |= lam >= MIN_FOUNDATION_STRETCH
            if soft and rough == 0 and not given:  # equal heights: the closed form's case
                span = np.linspace(0.0, c_axis.max(), 60)
                ax.plot(span, theory.soft_limit(n_pillars)
                        * theory.lognormal_stiffness_pull_off(span), "k--", lw=1)
                ran_seeds = [int(s) for s in sweep.seed.values
                             if bool(brush.sel(seed=s).notnull().any())]
                drawn = [theory.drawn_stiffness_pull_off(n_pillars, c, ran_seeds)
                         for c in c_axis]
                ax.plot(c_axis, float(theory.soft_limit(n_pillars)) * np.asarray(drawn),
                        "k:", marker="x", ms=4, lw=1)
                soft_drawn = True
            heights = _heights_text(rough, given)
            ax.set_title(f"{heights}, preload {preload:g} " + r"$F_K$" if protocol is None
                         else f"{heights}, last retraction of\n" + textwrap.fill(protocol, 36),
                         fontsize=8)
            ax.set_xlabel(r"stiffness spread $C$ (CV of the pillars' $\bar k$)")
            ax.set_ylabel(FAD_LABEL)
    for ax in axes.ravel():  # once every panel's data are in: their y range is shared
        _no_false_zoom(ax)
    first = axes[0][0]
    if fewer_drawn:
        first.plot([], [], "o", ms=4, mfc="white", mec="k", label=FEWER_SEEDS_LABEL)
    if soft_drawn:
        first.plot([], [], "k--", lw=1, label=SPREAD_LIMIT_LABEL)
        first.plot([], [], "k:", marker="x", ms=4, lw=1, label=SEED_LIMIT_LABEL)
    _side_legend(fig, axes.ravel())
    fig.suptitle(_rough_brush_title("Adhesive force against stiffness spread of", layout,
                                    n_pillars, given, fig.get_figwidth(), _notes(sweep, spread=False),
                                    kind="graded"))
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
    stages (red attached, grey not in contact: detached, or a pillar that
    never touched), with their colour key below.
    """
    fig = new_figure(10.5, 3.6)
    ax, *maps = fig.subplots(1, 3, width_ratios=[1.6, 1, 1])
    d = curve["displacement_normalized"].values
    f = curve["force_normalized"].values
    pulls = _pull_ranges(curve) or [(0, d.size - 1)]
    # Approaches run from the end of one pull (first touch) to the start of the next.
    starts = [0] + [last for _, last in pulls]
    ends = [first for first, _ in pulls] + [d.size - 1]
    # colour is the branch, not the cycle: the key says so where there are several
    # cycles, which their F_ad markers' labels tell apart
    every = " (every cycle)" if len(pulls) > 1 else ""
    for k, (a, b) in enumerate(zip(starts, ends)):
        if b > a:
            ax.plot(d[a:b + 1], f[a:b + 1], color="C0", lw=1,
                    label=("approaches" if every else "approach") + every if k == 0 else None)
    for k, (a, b) in enumerate(pulls):
        ax.plot(d[a:b + 1], f[a:b + 1], color="C3", lw=1,
                label=("retractions" if every else "retraction") + every if k == 0 else None)
        i = a + int(np.argmax(f[a:b + 1]))
        if f[i] > 0:
            name = rf"$\bar F_{{ad}}$ = {f[i]:.3g}" if len(pulls) == 1 else \
                rf"retraction {k}: $\bar F_{{ad}}$ = {f[i]:.3g}"
            ax.plot(d[i], f[i], "^", color="k" if k == len(pulls) - 1 else "0.5", label=name)
    i_pre = int(np.nanargmin(f))
    load = 0.0 - f[i_pre]  # + 0: a curve at preload 0 read "preload -0"
    ax.plot(d[i_pre], f[i_pre], "kv", label=rf"largest load {load:.3g} $F_K$"
            if len(pulls) > 1 else rf"preload {load:.3g} $F_K$")
    ax.axhline(0.0, color="0.6", lw=0.5)
    ax.set_xlabel(r"$\bar d = d / d_K$")
    ax.set_ylabel(r"$\bar F = F / F_K$ (tensile > 0)")
    ax.legend(fontsize=7)
    labels = [str(s) for s in curve["snapshot_label"].values] if "snapshot_label" in curve else []
    first = labels[0] if labels and labels[0] != "maximum force" else "preload"
    for axm, stage in zip(maps, (first, "maximum force")):
        axm.set_axis_off()
        if stage not in labels:
            no_data(axm, f"no map at {stage}")
            continue
        state = curve["contact_snapshot"].isel(snapshot=labels.index(stage)).values
        axm.imshow(state + 1, cmap=SNAPSHOT_CMAP, vmin=0, vmax=2, origin="lower",
                   interpolation="nearest")
        title = {"preload": "the preload", "maximum force": r"$F_{ad}$"}.get(stage, stage)
        axm.set_title("contact at " + title, fontsize=9)
    # grey is not "detached" alone here: a rough brush's short pillars may never touch
    snapshot_key(fig, "not in contact (detached or never touched)", loc="outside lower right")
    a = curve.attrs
    fig.suptitle(f"{curve_layout(a)} brush, N = {a.get('n_pillars')}, "
                 rf"$\bar k$ = {float(a.get('kbar', math.nan)):g}, " + _curve_case(a)
                 + f", seed {a.get('seed')}")
    return fig


def load_sharing(curve: xr.Dataset) -> Figure:
    """Force of every pillar at F_ad against its height.

    Forces are in units of the mean pillar force at F_ad (F_ad / N), heights
    in d_K; colour is the pillar's kbar.  Equal load sharing is the line at 1.
    In tension at F_ad the shorter of the attached pillars carry more (their
    springs are stretched further, by d - z), the more so the stiffer they
    are; a pillar that never touched (at a small preload, a stiff brush's
    short ones) carries none.
    A flat pull-off's file holds the forces alone: its pillars stand at
    height 0 on the brush's kbar.
    """
    fig = new_figure(5.0, 3.8)
    ax = fig.subplots()
    if "pillar_force_at_adhesive_force" not in curve:
        no_data(ax, "no per-pillar forces in this curve")
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
                 + f"seed {a.get('seed')},\n" + _curve_case(a), fontsize=9)
    return fig
