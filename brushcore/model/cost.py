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

import numpy as np

from brushcore.model.labelmap import pillar_element_counts
from brushcore.model.params import BrushParams
from brushcore.numerics.options import SolverOptions
from brushcore.numerics.events.protocol import standard_preload
from brushcore.numerics.linear.precondition import MEMORY_BUDGET, BlockInverse

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


# --- Memory: a curve's peak from its brush's geometry ---------------------------
#: Python with NumPy, SciPy, xarray and brushcore imported [MB] (150-180 measured).
PROCESS_MB = 200.0
#: A workflow job's own Snakemake, resident beside its curve [MB] (the job
#: step's: 192 MiB measured, 2026-12-07).
JOB_STEP_MB = 200.0
#: Bytes per element of the n x n grid: the padded transforms' buffers and
#: the per-element arrays, on a mirror quadrant and on the whole grid.
GRID_BYTES = {"mirror": 125.0, "whole": 250.0}
#: Per pillar on the whole grid [MB] (random 1620 holds 200-250 MB more than
#: random 64 at 256^2 and 512^2).
PILLAR_MB = 0.2
#: Per pillar on the tile path [MB] (its coarse blocks; 16 at most by design).
TILE_MB = 8.0
#: A generated pillar's largest discretisation over its area phi n^2 / N
#: (3 %: the stack sizes of `BlockInverse.stack_size` within 2 % of it).
RASTER_EXCESS = 1.03
#: What a job asks for over its estimate: `peak_mb` lies 1.06-1.32x above
#: the 20 peak RSS measured (256^2-2048^2, rigid to soft, regular and random,
#: phi 0.12-0.5, N 16-2304; helpers' runs of 2026-12-07 and docs/SPEED.md;
#: `tests/test_workflow.py` holds the table), the request 1.38-1.68x above
#: them with the job step's 192 MiB.
MEMORY_SAFETY = 1.3
#: Extra memory a retry asks for, per attempt after the first (Snakemake says
#: the attempt, not whether a time or a memory limit ended the last one).
RETRY_MEMORY = 0.5


def largest_pillar(n_pillars: int, phi: float, grid: int) -> float:
    """Elements of a generated brush's largest pillar: its area phi n^2 / N,
    times `RASTER_EXCESS`."""
    return RASTER_EXCESS * phi * grid * grid / n_pillars


def peak_mb(*, n_pillars: int, grid: int, largest: float, mirrored: bool,
            protocol_engine: bool, counted: bool = False) -> float:
    """A curve's peak memory [MB]: the process, the grid's buffers, and the
    preconditioner the run takes (`BlockInverse.fits`).

    Parameters
    ----------
    n_pillars : N
    grid : elements per side n
    largest : elements of the largest pillar (`largest_pillar`, or a label
        map's counted)
    mirrored : solved on a mirror quadrant (a quarter of the pillars' blocks)
    protocol_engine : solved by the protocol engine (rough or given heights,
        a protocol other than a flat brush's preload): blocks up to
        `BlockInverse.MAX_BLOCK_PROTOCOL`, bordered (2.5 stacks, not 1.5)
    counted : ``largest`` counted on the labels; else `largest_pillar`'s
        bound, and the run may take the blocks wherever a pillar
        `RASTER_EXCESS` under its area fits them (random 64 at 888^2: 1,483
        elements against 1,523 estimated, past MAX_BLOCK: blocks of 1.8 GB
        where the tiles' 0.5 were asked for; a review helper's find)

    Returns
    -------
    float
        The estimate [MB = 1e6 bytes].
    """
    pillars = math.ceil(math.sqrt(n_pillars) / 2) ** 2 if mirrored else n_pillars
    smallest = largest if counted else largest / RASTER_EXCESS**2  # what the run may count
    limit = BlockInverse.MAX_BLOCK_PROTOCOL if protocol_engine else BlockInverse.MAX_BLOCK

    def fits(m: float) -> bool:  # `BlockInverse.fits`
        return m <= limit and 1.5 * 8.0 * pillars * m * m <= MEMORY_BUDGET

    # the dense inverses (float64) and their packed copy, or bordered in the
    # protocol engine; `BlockInverse.fits` keeps either within the budget
    blocks = min((2.5 if protocol_engine else 1.5) * 8.0 * pillars * largest**2,
                 MEMORY_BUDGET) / 1e6
    tiles = TILE_MB * pillars
    preconditioner = (blocks if fits(largest) else tiles if not fits(smallest)
                      else max(blocks, tiles))  # either, by a few elements
    kind = "mirror" if mirrored else "whole"
    return (PROCESS_MB + GRID_BYTES[kind] * grid * grid / 1e6
            + (0.0 if mirrored else PILLAR_MB * n_pillars) + preconditioner)


def job_memory_mb(*, n_pillars: int, grid: int, largest: float, mirrored: bool,
                  protocol_engine: bool, counted: bool = False, attempt: int = 1,
                  floor_mb: float = 0.0) -> int:
    """What a workflow job asks for [MB, rounded up to 100]: `peak_mb` and
    its Snakemake (`JOB_STEP_MB`), times `MEMORY_SAFETY`, at least
    ``floor_mb``, and `RETRY_MEMORY` more of either for each retry."""
    need = MEMORY_SAFETY * (peak_mb(n_pillars=n_pillars, grid=grid, largest=largest,
                                    mirrored=mirrored, protocol_engine=protocol_engine,
                                    counted=counted) + JOB_STEP_MB)
    need = max(need, floor_mb) * (1.0 + RETRY_MEMORY * (attempt - 1))
    return int(math.ceil(need / 100.0) * 100)


def expected_peak_bytes(params: BrushParams, options: SolverOptions,
                        protocol: Sequence[object] | None = None,
                        labels: np.ndarray | None = None) -> float:
    """`peak_mb` of a run [bytes]; its largest pillar counted on ``labels``
    where given (a label map's or a table's), else `largest_pillar`."""
    largest = (float(pillar_element_counts(labels).max()) if labels is not None
               else largest_pillar(params.n_pillars, params.phi, params.grid))
    kind = curve_kind(params, options, protocol)
    return 1e6 * peak_mb(n_pillars=params.n_pillars, grid=params.grid, largest=largest,
                         mirrored=kind == "mirror", protocol_engine=kind == "rough",
                         counted=labels is not None)


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
                available: float | None = None, labels: np.ndarray | None = None) -> str:
    """A warning where the run may need more memory than ``available``
    (default: this machine's, `available_bytes`) [bytes]; "" otherwise and
    on a GPU, whose memory the solver budgets itself."""
    need = expected_peak_bytes(params, options, protocol, labels)
    free = available_bytes() if available is None else available
    if need <= free or params.backend != "cpu":
        return ""
    return (f"this run may need about {need / 1e9:.2g} GB of memory (its grid's buffers "
            f"and preconditioner, estimated), more than the {free / 1e9:.2g} GB "
            "available: a smaller grid, or a machine with more memory")


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
    contact at first touch, so they do not make it rough, nor does a
    preload's protocol (the pull-off takes it: `protocol.dispatches`)."""
    uneven = (params.roughness > 0 or params.heights is not None
              or params.gap_map is not None
              or protocol is not None and standard_preload(tuple(protocol)) is None)
    regular = params.layout == "regular" and params.shape == "disc" and params.is_flat
    # a protocol, a preload's too, runs on the whole grid (symmetry_fold 1)
    return kind_of(uneven=uneven, mirrored=regular and options.symmetry and protocol is None)


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
