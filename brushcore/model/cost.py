"""What a curve costs: the slowest curve measured per kind and grid.

One table serves the workflow's Slurm time limits (`workflow/rules/resources.smk`
asks for `RUNTIME_SAFETY` x it) and the command's word before a long run
(`cost_note`).  Measured on one thread of the 2-core AMD EPYC development
machine (README, "Speed and memory"; docs/SPEED.md); other machines run
2-3x apart, so these are orders of magnitude, not promises.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from brushcore.model.params import BrushParams
from brushcore.numerics.options import SolverOptions

#: The slowest curve measured [s, one thread] by kind and grid.  Where only a
#: two-thread time exists (2048^2) the one-thread bound is twice it.
#: "mirror": flat regular brushes of discs, solved on one quadrant; 1024:
#: 8 x 8 rigid 123 s; 2048: 531 s on one thread (48 x 48), 8 x 8 rigid 609 s
#: on two on a slow afternoon.  "whole": every other flat brush (random,
#: hexagonal, other shapes, a flat preload or a stiffness spread) on the whole
#: grid; 512: the paper sweep's slowest, 1.6 min; 1024: random 64 at k 1e-6
#: 666 s (hexagonal 8 x 8 622 s); 2048: random 1620 at k 1e-5, about 130 min
#: on two threads (a straight line through its 11.6 % detached in 15 min;
#: its applications alone about 95 min).  "rough": roughness > 0, given
#: heights or a gap map, or a protocol: contact made element by
#: element on an approach; 256: 116.5 s (config/rough.yaml); 512: the rough
#: 8 x 8 brush 416.5 s; 1024: about 6 h (estimated from the rate of its
#: first 12 min, not run).
SLOWEST_CURVE_S = {
    "mirror": {512: 30, 1024: 125, 2048: 1218},
    "whole": {512: 100, 1024: 670, 2048: 15600},
    "rough": {256: 120, 512: 420, 1024: 21600},
}
#: Beyond the measured grids a curve's time grows as n^3 (solves ~ n, each
#: ~ n^2 log n), a rough one's as n^5 (also ~ n^2 more contact events).
RUNTIME_EXPONENT = {"mirror": 3, "whole": 3, "rough": 5}
#: How much slower than the defaults other solver settings run: the paper's
#: global cascades or a reference tolerance (exact mode: the rigid 8 x 8
#: brush at 2048^2 took 40 min against 379 s, 6.3x; a regular brush at
#: 256^2 3.9x), and double-precision transforms where random brushes would
#: run single (45 % more job time over the sweep's random curves).
EXACT_SLOWDOWN = 6.0
DOUBLE_SLOWDOWN = 1.5
#: An rtol under this runs at exact mode's cost.
EXACT_RTOL = 1e-6
#: The command says what a run may cost from this bound on [s]: a bound,
#: not a forecast (a 4-pillar protocol at 256^2 bounded by 2 min took 1.6 s).
NOTE_FROM_S = 300.0


#: The largest peak memory measured per kind [bytes] on one grid (README,
#: "Speed and memory"): "mirror" the soft 48 x 48 brush at 2048^2 (0.81
#: GiB), "whole" random 1620 at k 1e-5 at 2048^2 (2.69 GiB, its per-pillar
#: blocks), "rough" the rough 8 x 8 brush at 1024^2 (3.4 GB).  Other grids
#: scale it as n^2 (the transforms' buffers; the blocks grow slower, so
#: beyond the grid it errs high).
LARGEST_PEAK_BYTES = {"mirror": (2048, 0.81 * 2**30), "whole": (2048, 2.69 * 2**30),
                      "rough": (1024, 3.4e9)}


def expected_peak_bytes(params: BrushParams, options: SolverOptions,
                        protocol: Sequence[object] | None = None) -> float:
    """The largest peak memory measured for the run's kind, scaled to its
    grid as n^2 [bytes]: an order of magnitude, for `memory_note`."""
    return _peak(params, options, protocol)[1]


def _peak(params: BrushParams, options: SolverOptions,
          protocol: Sequence[object] | None) -> tuple[int, float]:
    """The grid the run's kind was measured on, and its peak scaled to the run's grid."""
    grid, peak = LARGEST_PEAK_BYTES[curve_kind(params, options, protocol)]
    return grid, peak * (params.grid / grid) ** 2


def available_bytes() -> float:
    """Memory available to a new process [bytes] (Linux's MemAvailable);
    inf where the system does not say."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return math.inf


def memory_note(params: BrushParams, options: SolverOptions,
                protocol: Sequence[object] | None = None,
                available: float | None = None) -> str:
    """A warning where the run may need more memory than ``available``
    (default: this machine's, `available_bytes`) [bytes]; "" otherwise and
    on a GPU, whose memory the solver budgets itself."""
    grid, need = _peak(params, options, protocol)
    free = available_bytes() if available is None else available
    if need <= free or params.backend != "cpu":
        return ""
    return (f"this run may need up to about {need / 1e9:.2g} GB of memory (the largest "
            f"peak of its kind measured at {grid}^2, scaled as grid^2), more than the "
            f"{free / 1e9:.2g} GB available: a smaller grid, or a machine with more memory")


def slowest_curve_s(kind: str, grid: int) -> float:
    """The slowest curve of ``kind`` on ``grid`` [s, one thread]: measured,
    interpolated on a log-log scale between measured grids, or scaled by
    `RUNTIME_EXPONENT` beyond them."""
    measured = SLOWEST_CURVE_S[kind]
    grids = sorted(measured)
    if grid in measured:
        return float(measured[grid])
    if grid < grids[0] or grid > grids[-1]:
        edge = grids[0] if grid < grids[0] else grids[-1]
        return measured[edge] * (grid / edge) ** RUNTIME_EXPONENT[kind]
    upper = next(g for g in grids if g > grid)
    lower = grids[grids.index(upper) - 1]
    slope = math.log(measured[upper] / measured[lower]) / math.log(upper / lower)
    return measured[lower] * (grid / lower) ** slope


def slowdown(kind: str, *, exact: bool, double: bool) -> float:
    """Factor on a curve's time for solver settings: ``exact`` (`is_exact`)
    and ``double`` (double-precision transforms asked for)."""
    return ((EXACT_SLOWDOWN if exact else 1.0)
            * (DOUBLE_SLOWDOWN if double and kind == "whole" else 1.0))


def is_exact(options: SolverOptions) -> bool:
    """Whether settings run at exact mode's cost: global cascades, or an rtol
    under `EXACT_RTOL`."""
    return options.cascade == "global" or options.rtol < EXACT_RTOL


def kind_of(*, uneven: bool, mirrored: bool) -> str:
    """The `SLOWEST_CURVE_S` kind: "rough" where contact is made element by
    element on an approach (``uneven``: roughness, given heights or a gap
    map, a protocol), else "mirror" for a flat regular brush of discs
    solved on a quadrant (``mirrored``), else "whole".  The command
    (`curve_kind`) and the workflow (from a job's wildcards) both ask it."""
    return "rough" if uneven else "mirror" if mirrored else "whole"


def curve_kind(params: BrushParams, options: SolverOptions,
               protocol: Sequence[object] | None = None) -> str:
    """`kind_of` a run: given stiffnesses alone leave a flat brush in full
    contact at first touch, so they do not make it rough."""
    uneven = (params.roughness > 0 or params.heights is not None
              or params.gap_map is not None or protocol is not None)
    regular = params.layout == "regular" and params.shape == "disc" and params.is_flat
    return kind_of(uneven=uneven, mirrored=regular and options.symmetry)


def _priced(params: BrushParams, options: SolverOptions,
            protocol: Sequence[object] | None) -> tuple[str, float, float]:
    """The run's kind, its slowest measured curve on the grid [s] and the
    settings' `slowdown`."""
    kind = curve_kind(params, options, protocol)
    return kind, slowest_curve_s(kind, params.grid), slowdown(
        kind, exact=is_exact(options), double=options.precision == "double")


def expected_seconds(params: BrushParams, options: SolverOptions,
                     protocol: Sequence[object] | None = None) -> float:
    """The slowest measured curve of the run's kind on its grid, times the
    settings' `slowdown` [s, one thread]: what the run may take at most on
    the development machine."""
    _, slowest, factor = _priced(params, options, protocol)
    return slowest * factor


#: A kind in the words of the command's note.
KIND_WORDS = {"mirror": "flat regular", "whole": "flat", "rough": "uneven or protocol"}


def cost_note(params: BrushParams, options: SolverOptions,
              protocol: Sequence[object] | None = None) -> str:
    """What a run on the host may take, said where it may exceed `NOTE_FROM_S`;
    "" below, and on a GPU, whose times the table does not hold."""
    kind, slowest, factor = _priced(params, options, protocol)
    seconds = slowest * factor
    if seconds < NOTE_FROM_S or params.backend != "cpu":
        return ""
    hours = seconds / 3600
    span = (f"{seconds / 60:.0f} min" if seconds < 5400 else
            f"{hours:.1f} h" if hours < 10 else f"{hours:.0f} h")
    grids = sorted(SLOWEST_CURVE_S[kind])
    basis = (f"the slowest {KIND_WORDS[kind]} curve measured at {params.grid}^2"
             if params.grid in grids else
             f"scaled from the slowest {KIND_WORDS[kind]} curves measured at "
             f"{', '.join(f'{g}^2' for g in grids)}")
    settings = f", x{factor:g} for these solver settings" if factor != 1 else ""
    return (f"this run may take up to about {span} on one thread ({basis}{settings}; "
            "machines differ 2-3x)")
