"""The workflow's outputs: the figures and studies a config asks for, and
the stale ones another config left in results/."""

import math
import time
from pathlib import Path

ROUGH_FIGURES = ("rough_roughness", "rough_preload")

#: F_ad against the stiffness spread C: drawn where `kbar_spread` asks for a C > 0.
SPREAD_FIGURES = ("rough_spread",)


def rough_brush(config, axes=True):
    """(layout, N) the rough figures show: the first brush as made (a
    `layout_files` entry given heights, stiffness or a gap map: the paper's
    figures leave it out, so these show it), else the first regular brush,
    else the first hexagonal, else the first random, else the first file.
    For the figures with a roughness axis (`axes`) the brushes whose heights
    `roughness` draws come first where it draws any: generated ones, then
    tables and maps given no heights or gap map (a brush given heights has
    no roughness axis)."""
    files = file_brushes(config)
    made = [(layout, b.n_pillars) for layout, b in files.items() if b.inputs]
    generated = [
        (layout, int(config[layout][0]))
        for layout in (*LATTICES, "random")
        if config[layout]
    ]
    drawn = axes and any(float(s) > 0 for s in config["roughness"])
    roughened = [
        (layout, b.n_pillars) for layout, b in files.items() if not _given_offsets(b)
    ]
    for brush in (generated + roughened + made) if drawn else (made + generated):
        return brush
    for layout, brush in files.items():
        return layout, brush.n_pillars
    return config["fig5"]["layout"], int(config["fig5"]["n_pillars"])


CURVE_FIGURES = ("rough_loop", "load_sharing")


def rough_example_curve(config):
    """The curve file the one-curve rough figures show, or None for a flat sweep.

    The brush of `rough_brush`, seed 0, the largest roughness and preload
    asked for (a brush as made: any, preload 0 too), and the finite kbar
    closest to 0.01 on a log scale (soft enough that pillars share load,
    stiff enough that they interact).
    """
    brush = rough_brush(config, axes=False)  # one curve: the brush as made first
    entry = file_brushes(config).get(brush[0])
    made = bool(entry and entry.inputs)
    rough = [
        c
        for c in sweep_cases(config)
        if (c[6] or made)
        and not c[7]
        and (c[0], c[1]) == brush
        and c[3] == 0
        and float(c[2]) < float("inf")
    ]
    if not rough:
        return None

    def rank(case):
        tag = parse_rough_tag(case[6])  # {} for a brush as made at preload 0
        return (
            -tag.get("roughness", 0.0),
            -tag.get("preload", 0.0),
            tag.get("kbar_spread", 0.0),
            abs(math.log10(float(case[2])) + 2.0),
            # of several phi, the paper's (as Figs. 5-8 show)
            abs(float(case[5]) - 0.12),
        )

    return curve_file(*min(rough, key=rank))


def rough_figure_files(config):
    """The rough-brush figures, for configs that ask for rough cases only."""
    flat = all(
        float(v) == 0.0
        for key in ("roughness", "preload", "kbar_spread")
        for v in config[key]
    )
    if flat and config.get("protocol") is None and not made_brush(config):
        return []
    spread = any(float(c) > 0 for c in config["kbar_spread"])
    names = (
        ROUGH_FIGURES
        + (SPREAD_FIGURES if spread else ())
        + (CURVE_FIGURES if rough_example_curve(config) else ())
    )
    return [f"results/figures/{name}.{ext}" for name in names for ext in ("png", "pdf")]


def wants_lattice_figure(config):
    """True when the sweep compares lattices or shapes: hexagonal brushes or non-disc pillars."""
    return bool(config["hexagonal"]) or any(s != "disc" for s in config["shape"])


def lattice_figure_files(config):
    """The lattice comparison figure, for configs that ask for one."""
    if not wants_lattice_figure(config):
        return []
    return [f"results/figures/lattices.{ext}" for ext in ("png", "pdf")]


def phi_figure_files(config):
    """The rigid limit against phi, for configs that list more than one phi."""
    if "phi" not in config or len(config_values(config, "phi")) < 2:
        return []
    return [f"results/figures/rigid_phi.{ext}" for ext in ("png", "pdf")]


CONVERGENCE_FILES = (
    "results/convergence.nc",
    "results/convergence.csv",
    "results/convergence.md",
    "results/figures/convergence.png",
    "results/figures/convergence.pdf",
)


def sweep_targets(config):
    """What the default target makes of a config: sweep.nc, the summary, the figures
    it asks for, and the refinement study where some brush runs on three or
    more grids."""
    return [
        "results/sweep.nc",
        "results/summary.csv",
        "results/summary.md",
        *paper_figure_files(config),
        *rough_figure_files(config),
        *lattice_figure_files(config),
        *phi_figure_files(config),
        *(CONVERGENCE_FILES if wants_convergence(config) else ()),
    ]


#: When this Snakemake read its Snakefile [s since the epoch]: what it writes is newer.
PLANNED_AT = time.time()


def stale_outputs(config, root=".", since=None):
    """A warning naming the figures and tables in results/ that some other
    config made and this one does not (None where there are none): Snakemake
    leaves them, beside this sweep's sweep.nc, as if they were its own.
    Files written since ``since`` (default `PLANNED_AT`) are this run's own
    (a target named on the command line), not stale."""
    since = PLANNED_AT if since is None else since
    names = (
        *ROUGH_FIGURES,
        *SPREAD_FIGURES,
        *CURVE_FIGURES,
        "lattices",
        "rigid_phi",
        *(f"fig{n}" for n in (5, 6, 7, 8)),
    )
    made = {f"results/figures/{n}.{ext}" for n in names for ext in ("png", "pdf")}
    wanted = set(sweep_targets(config))
    stale = sorted(
        p
        for p in made | set(CONVERGENCE_FILES)
        if p not in wanted
        and Path(root, p).exists()
        and Path(root, p).stat().st_mtime < since
    )
    if not stale:
        return None
    return (
        f"{len(stale)} file{'s' * (len(stale) != 1)} in results/ "
        f"{'are' if len(stale) != 1 else 'is'} from an earlier sweep, which this config "
        f"does not make: {', '.join(stale)}. Remove {'them' if len(stale) != 1 else 'it'} "
        "(curve files in results/curves/ are kept and reused), or give each config its "
        "own working copy"
    )


def paper_figure_files(config):
    """Figs. 5-8 (PNG and PDF); Fig. 5 only where `fig5.kbar` lists a stiffness."""
    numbers = ([5] if config["fig5"]["kbar"] else []) + [6, 7, 8]
    return [f"results/figures/fig{n}.{ext}" for n in numbers for ext in ("png", "pdf")]


def fig5_shape(config):
    """`shape_label` of the Fig. 5 brush's pillars (the sweep slice it is drawn from)."""
    tag = shape_tag(config, config["fig5"]["shape"])
    return tag[1:] if tag else "disc"


def fig5_options(config):
    """Keyword arguments of `figures.fig5`: the Fig. 5 config with its shape label."""
    return {**config["fig5"], "shape": fig5_shape(config)}
