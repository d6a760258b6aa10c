"""What the sweep's figures share: labels, colours and markers, a figure on
the Agg canvas, the kbar axis with its rigid column, and `save`.

Figures are built on matplotlib's object API with the Agg canvas, so no
global pyplot state or GUI backend is involved.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import xarray as xr
import matplotlib
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from matplotlib.ticker import NullFormatter

from brushcore.model.layout_file import FILE_LAYOUT_PREFIX
from brushcore.model.shapes import parse_shape_label
from brushcore.data.io import write_atomic


K_LABEL = r"$\bar k = k / (E^* L)$"


FAD_LABEL = r"$\bar F_{ad} = F_{ad} / F_K$"


W_LABEL = r"$\bar W = W / (2\pi a_0^2 \Delta\gamma)$"


#: Colours of the layouts and markers of the pillar shapes in the lattice figure.
LAYOUT_COLORS = {"regular": "C0", "hexagonal": "C1", "random": "C2"}


SHAPE_MARKERS = {"disc": ("o", "-"), "square": ("s", "--"), "ellipse": ("D", ":")}


#: The hexagonal lattice's rigid limit at its local filling factor (dash-dot).
HEX_LINE = (0, (6, 2, 1, 2))


HEX_LABEL = r"hexagonal rigid limit $(\varphi/\mathrm{fill})^{-1/4}$ (approx.)"


#: Fig. 7's marker of each generated layout; others (files) take OTHER_MARKERS in turn.
LAYOUT_MARKERS = {"regular": "s", "random": "o", "hexagonal": "h"}


OTHER_MARKERS = ("^", "v", "D", "P", "X", "<", ">", "p", "*")


# detached / attached pillar element on a white background (no pillar)
SNAPSHOT_CMAP = ListedColormap(["white", "0.8", "tab:red"])


def snapshot_key(fig: Figure, not_in_contact: str = "detached", **where) -> None:
    """The contact maps' colour key (`SNAPSHOT_CMAP`) as a figure legend.

    ``not_in_contact`` names the grey elements: "detached" where every
    pillar starts in contact (Fig. 5), wider where some may never have
    touched (a rough brush at its preload).  ``where``: `Figure.legend`'s
    placement keywords.
    """
    fig.legend(handles=[Patch(color=SNAPSHOT_CMAP(2), label="attached"),
                        Patch(color=SNAPSHOT_CMAP(1), label=not_in_contact)],
               **{"ncols": 2, "fontsize": 7, "frameon": False, **where})


def layout_styles(layouts: Sequence[str]) -> dict[str, tuple[str, str]]:
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


def new_figure(width: float, height: float) -> Figure:
    """A constrained-layout figure of ``width`` x ``height`` [inches], drawn
    off screen (Agg), so that figures need no display."""
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def sweep_layouts(sweep: xr.Dataset) -> list[str]:
    """The sweep's layouts, in its order: one panel each."""
    return [str(v) for v in sweep.layout.values]


def shape_text(label: str) -> str:
    """A `shape_label` for people: "disc", "square at 30°", "ellipse 2:1 at 30°"."""
    shape = parse_shape_label(label)
    text = shape["shape"] + (f" {shape['aspect']:g}:1" if shape["shape"] == "ellipse" else "")
    return text + (f" at {shape['orientation']:g}°" if shape["orientation"] else "")


def panel_title(index: int, layout: str) -> str:
    """"(a) regular", "(b) hexagonal", ...: one panel per layout that ran."""
    return f"({chr(ord('a') + index)}) {layout}"


def brush_colors(n_pillars: Sequence[int]) -> dict[int, str]:
    """One colour per N, stable across figures and panels."""
    return {int(n): f"C{i}" for i, n in enumerate(sorted(n_pillars))}


def seed_range(runs: xr.DataArray) -> tuple[xr.DataArray, xr.DataArray, xr.DataArray]:
    """Mean, min and max over ``seed`` of the seeds that ran (NaN skipped):
    a marker and its bar."""
    return (runs.mean("seed", skipna=True), runs.min("seed", skipna=True),
            runs.max("seed", skipna=True))


def title_notes(*notes: str) -> str:
    """A title's parenthesised notes, the empty ones left out: " (disc
    pillars, phi = 0.12 of 0.08, 0.12)", or "" where every one is empty."""
    shown = [note for note in notes if note]
    return f" ({', '.join(shown)})" if shown else ""


def no_data(ax: Axes, message: str) -> None:
    """Write ``message`` in the middle of an empty panel (a case not run)."""
    ax.text(0.5, 0.5, message, ha="center", va="center", transform=ax.transAxes)


def sweep_phi(sweep: xr.Dataset, layout: str | None = None, n_pillars: int | None = None
         ) -> float:
    """The filling factor a layout's theory lines take: the sweep's, or for a
    brush read from a file (layout "file_..."), the file's own; with
    ``n_pillars``, the one brush's as realised (its curves' mean
    ``phi_actual``), as its data are normalised (regular 256 and 2304
    realise 0.117 of 0.12 at 512^2, which put its soft-work line 1.2 %
    low).  A brush the sweep does not hold takes the sweep's."""
    held = layout in sweep.layout.values and (
        n_pillars in sweep.n_pillars.values if n_pillars is not None
        else layout.startswith(FILE_LAYOUT_PREFIX))
    if "phi_actual" in sweep and held:
        realised = sweep["phi_actual"].sel(layout=layout)
        if n_pillars is not None:
            realised = realised.sel(n_pillars=n_pillars)
        if bool(realised.notnull().any()):
            return float(realised.mean(skipna=True))
    return float(sweep.attrs.get("phi", math.nan))


def rigid_x(kbars: np.ndarray) -> float:
    """Where rigid pillars (kbar = inf) are drawn on a log kbar axis: one
    decade right of the decade tick at or above the stiffest finite kbar, so
    that its "rigid" label never meets that tick's (at 1 when none is finite)."""
    finite = kbars[np.isfinite(kbars)]
    return 10.0 ** (np.ceil(np.log10(finite.max())) + 1) if finite.size else 1.0


def break_before_rigid(x_inf: float, x: np.ndarray, *values: np.ndarray
                        ) -> tuple[np.ndarray, ...]:
    """x and values with a NaN between the finite kbar and the rigid point at
    ``x_inf``, so that no line joins them: the axis between holds no
    measurement."""
    arrays = tuple(np.asarray(a, dtype=float) for a in (x, *values))
    if arrays[0].size < 2 or arrays[0][-1] != x_inf:
        return arrays
    return tuple(np.insert(a, a.size - 1, np.nan) for a in arrays)


def kbar_x(kbar, x_inf: float) -> np.ndarray:
    """kbar values as x positions: rigid ones at ``x_inf``."""
    k = np.asarray(kbar, dtype=float)
    return np.where(np.isinf(k), x_inf, k)


def rigid_ticks(ax: Axes, kbars: np.ndarray, x_inf: float) -> None:
    """Decade ticks over the finite kbar, and "rigid" at ``x_inf`` where rigid ran."""
    if not np.isinf(kbars).any():
        return
    finite = kbars[np.isfinite(kbars)]
    ticks = ([10.0**e for e in range(int(np.floor(np.log10(finite.min()))),
                                     int(np.ceil(np.log10(finite.max()))) + 1)]
             if finite.size else [])
    ax.set_xticks([*ticks, x_inf], [f"$10^{{{round(np.log10(t))}}}$" for t in ticks] + ["rigid"])
    ax.xaxis.set_minor_formatter(NullFormatter())


def kbar_axes(ax: Axes, title: str, ylabel: str, kbars: np.ndarray, x_inf: float) -> None:
    """Log kbar axis (rigid pillars at ``x_inf``), panel title and labels
    shared by Figs. 6 and 8."""
    ax.set_xscale("log")
    rigid_ticks(ax, kbars, x_inf)
    ax.set_title(title, loc="left")
    ax.set_xlabel(K_LABEL)
    ax.set_ylabel(ylabel)


def kbar_text(kbar: float) -> str:
    """kbar for a legend: "rigid" for inf, else three significant digits."""
    return "rigid" if math.isinf(kbar) else f"{kbar:.3g}"


def save(fig: Figure, path: str | Path, dpi: int = 150) -> None:
    """Write a figure (format from the suffix; none: matplotlib's default format,
    its suffix added, as savefig does) atomically, creating the directory."""
    path = Path(path)
    if not path.suffix:
        path = path.with_name(f"{path.name}.{matplotlib.rcParams['savefig.format']}")
    write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format=path.suffix[1:].lower()))
