"""What a simulate job asks for: memory, GPUs and its time limit, from the
slowest curves measured per kind and grid (`brushcore.model.cost`)."""

import functools
import math


from brushcore.model.cost import (
    is_exact,
    job_memory_mb,
    kind_of,
    largest_pillar,
    slowdown,
    slowest_curve_s,
)
from brushcore.numerics.events.protocol import standard_preload
from brushcore.model.labelmap import pillar_element_counts
from brushcore.model.layout import build_labels
from brushcore.model.layout_file import FILE_LAYOUT_PREFIX, file_params
from brushcore.model.pillar_table import is_table
from brushcore.model.params import ParameterError
from brushcore.numerics.options import SolverOptions
from brushcore.numerics.platform.backend import resolve_backend


def unmeasured_mem_mb(grid):
    """The floor of a request where `brushcore.model.cost.peak_mb` has not
    been measured to the end [MB]: the rule before 2026-12-07, 1 GB, 150 MB
    x (n/512)^2 and above 512 the 4 GB block budget.  Rough curves: their one
    peak measured at 1024 (3.4 GB, the estimate 3.6) was 20 minutes into an
    estimated 6 hours, its growth to the end unknown.  GPU jobs: the host
    memory of CuPy's and CUDA's libraries beside the curve, never measured
    (no card was lent to the sessions that wrote this)."""
    return 1000 + 150 * (grid / 512) ** 2 + (4000 if grid > 512 else 0)


def simulate_mem_mb(config):
    """The simulate rule's `mem_mb` [MB]: `brushcore.model.cost.job_memory_mb`
    of the job's brush (N, phi, grid, and whether it runs on a mirror
    quadrant or through the protocol engine, from its wildcards; a file
    brush's largest pillar counted on its labels), at least
    `unmeasured_mem_mb` for rough curves and GPU jobs (whose device runs
    solve the whole grid); a retry asks for half as much again (Snakemake
    says the attempt, not whether time or memory ended the last one).

    The rule before 2026-12-07 (1 GB + 150 MB (n/512)^2, + 4 GB above 512)
    left out the blocks at 512 and below: a random brush of 60 pillars at
    phi 0.3 peaked at 1.24 GiB, 100 at phi 0.5 at 2.2 GiB, against 1.15 GB
    asked; above 512 it asked 4-12x the peaks measured.
    """

    def mem_mb(wildcards, attempt):
        grid = int(wildcards.grid)
        kind = curve_kind(
            wildcards.layout,
            wildcards.shape,
            wildcards.rough,
            config.get("solver"),
            _offsets(config, wildcards.layout),
            config_protocol(config),
        )
        n_pillars = int(wildcards.n_pillars)
        counted = _file_largest_pillar(config, wildcards.layout, grid)
        gpu = config.get("backend", "cpu") == "gpu"
        return job_memory_mb(
            n_pillars=n_pillars,
            grid=grid,
            largest=(
                largest_pillar(n_pillars, float(wildcards.phi), grid)
                if counted is None
                else counted
            ),
            mirrored=kind == "mirror" and not gpu,
            protocol_engine=kind == "rough",
            counted=counted is not None,
            attempt=attempt,
            floor_mb=unmeasured_mem_mb(grid) if kind == "rough" or gpu else 0.0,
        )

    return mem_mb


@functools.cache
def _largest_on(layout_file, grid):
    """Elements of the largest pillar of a file brush drawn on ``grid``."""
    grid = {} if grid is None else {"grid": grid}  # a table is drawn on the job's grid
    labels = build_labels(file_params(layout_file, math.inf, **grid))
    return float(pillar_element_counts(labels).max())


def _file_largest_pillar(config, layout, grid):
    """A `layout_files` brush's largest pillar on ``grid`` [elements], None
    for a generated layout (`largest_pillar` then)."""
    if not layout.startswith(FILE_LAYOUT_PREFIX):
        return None
    brush = file_brushes(config).get(layout)
    if not brush:
        return None
    table = is_table(brush.path)
    return _largest_on(brush.path, grid if table else None)


def check_local_backend(config, local):
    """Refuse `backend: gpu` before the first job where the jobs run on this
    machine (``local``: Snakemake's local executor) and it has no CuPy or no
    card; jobs sent to a cluster check on their own node, as each job does
    before any work.  Called from `onstart`, once the executor is known."""
    if not local or config.get("backend", "cpu") != "gpu":
        return
    try:
        resolve_backend("gpu")
    except ParameterError as exc:
        raise ConfigError(
            f"config key 'backend': 'gpu' is invalid on this machine ({exc.reason}): "
            "allowed 'cpu' here, or 'gpu' where CuPy and a CUDA device are (a cluster "
            "executor's jobs check on their node)"
        ) from None


def simulate_gpus(config):
    """Cards one simulate job holds: 1 with backend gpu (Snakemake resource
    `gpu`, limited locally by `--resources gpu=N`), else 0."""
    return 1 if config.get("backend", "cpu") == "gpu" else 0


def simulate_gres(config):
    """Slurm generic resource of one simulate job: "gpu:1" with backend gpu.

    The Slurm profile zeroes the `gpu` resource for simulate (the plugin
    would add --gpus, which Slurm treats as a second GPU request), so that
    Slurm sees this --gres=gpu:1 alone.
    """
    return "gpu:1" if simulate_gpus(config) else ""


#: The slowest curve measured per kind and grid (`SLOWEST_CURVE_S`,
#: `RUNTIME_EXPONENT`, the settings' `slowdown`) is `brushcore.model.cost`'s,
#: which the command's note before a long run reads too.
#: Margin over the slowest measured curve: nodes 2-3x slower than the
#: development machine, and 1.3x between days on one machine.
RUNTIME_SAFETY = 3
#: Minutes for what is not the curve: Python's and the nested Snakemake's
#: start, FFTW planning on a fresh node, the shared file system's latency.
RUNTIME_OVERHEAD_MIN = 5


def curve_kind(layout, shape, rough, solver=None, offsets=False, protocol=None):
    """The `SLOWEST_CURVE_S` kind of a curve (`brushcore.model.cost.kind_of`,
    as the command's note asks it) from its wildcards (shape and rough
    suffixes), whether its brush is given heights or a gap map
    (``offsets``, `_given_offsets`), the config's solver settings
    (``symmetry: false`` solves a regular brush on the whole grid) and its
    protocol (`config_protocol`): a flat brush's preload and separation is
    a pull-off (`protocol.dispatches`), not a rough curve (it asked for 26
    min at 512^2 and 18 h at 1024^2 where its plain pull-off takes 10 and 39)."""
    tagged = parse_rough_tag(rough)
    protocol_run = "_Q" in rough and (
        protocol is None or standard_preload(protocol) is None
    )
    uneven = tagged.get("roughness", 0.0) > 0 or protocol_run or offsets
    folded = (solver or {}).get("symmetry", True)
    return kind_of(
        uneven=uneven,
        mirrored=layout == "regular" and not shape and not rough and folded,
    )


def solver_slowdown(solver, kind):
    """Factor on a curve's time for the config's solver settings
    (`brushcore.model.cost.slowdown`, `is_exact`); 1 for the defaults."""
    options = SolverOptions(**(solver or {}))
    return slowdown(kind, exact=is_exact(options), double=options.precision == "double")


def curve_minutes(
    layout, shape, rough, grid, solver=None, offsets=False, protocol=None
):
    """Time limit of a curve's first attempt [min]: `RUNTIME_SAFETY` x the
    slowest measured curve of its kind and grid, times `solver_slowdown` of
    the config's ``solver`` settings, plus `RUNTIME_OVERHEAD_MIN`.

    With the default solver: 1024^2 12 min regular, 39 min random, 18 h
    rough; 2048^2 66 min regular, 13.1 h random.  The time does not shrink
    with `threads`: the measurements are on one thread, and a second gains
    at most 2x.
    """
    kind = curve_kind(layout, shape, rough, solver, offsets, protocol)
    seconds = (
        RUNTIME_SAFETY * slowest_curve_s(kind, grid) * solver_slowdown(solver, kind)
    )
    return math.ceil(RUNTIME_OVERHEAD_MIN + seconds / 60)


def _offsets(config, layout):
    """Whether ``layout`` is a `layout_files` brush given heights or a gap map."""
    if not layout.startswith(FILE_LAYOUT_PREFIX):
        return False  # a generated layout: no files to read
    brush = file_brushes(config).get(layout)
    return bool(brush) and _given_offsets(brush)


def simulate_runtime(config):
    """The simulate rule's `runtime` [min]: `curve_minutes`, doubled on a retry
    (a time limit is the likelier cause of a failure), clipped to the config's
    `slurm_max_runtime_min` (`clipped_runtimes` warns at plan time)."""
    cap = config.get("slurm_max_runtime_min")

    def runtime(wildcards, attempt):
        minutes = attempt * curve_minutes(
            wildcards.layout,
            wildcards.shape,
            wildcards.rough,
            int(wildcards.grid),
            config.get("solver"),
            _offsets(config, wildcards.layout),
            config_protocol(config),
        )
        return minutes if cap is None else min(minutes, int(cap))

    return runtime


def clipped_runtimes(config):
    """The plan-time warning for curves whose first attempt asks for more than
    `slurm_max_runtime_min`, or None: how many, and the largest request."""
    cap = config.get("slurm_max_runtime_min")
    if cap is None:
        return None
    asked = [
        (
            curve_minutes(
                layout,
                shape,
                rough,
                grid,
                config.get("solver"),
                _offsets(config, layout),
                config_protocol(config),
            ),
            curve_file(layout, n, kbar, seed, grid, phi, rough, shape),
        )
        for layout, n, kbar, seed, grid, phi, rough, shape in sweep_cases(config)
    ]
    over = sorted((a for a in asked if a[0] > int(cap)), reverse=True)
    if not over:
        return None
    minutes, name = over[0]
    return (
        f"slurm_max_runtime_min = {cap} clips the time limit of {len(over)} of "
        f"{len(asked)} simulations (the largest: {minutes} min for {name}); a curve "
        f"that needs longer is killed at {cap} min (its retry too) and writes nothing"
    )


#: Finest grid whose curves may share a Slurm job (README, "How jobs are bundled").
BUNDLE_MAX_GRID = 512


def bundled_fine_grids(config, components):
    """The plan-time warning where `--group-components sims=N` (N > 1) bundles
    curves finer than BUNDLE_MAX_GRID, or None: a bundle fails as a whole, and
    Snakemake then removes the curves that had finished inside it."""
    size = int(components.get("sims", 1))
    if size <= 1:
        return None
    fine = sorted(
        {int(grid) for *_, grid, _, _, _ in sweep_cases(config)}
        - set(range(BUNDLE_MAX_GRID + 1))
    )
    if not fine:
        return None
    return (
        f"--group-components sims={size} bundles curves on grids {fine}: when one member of "
        "a bundle fails (a time or memory limit), Snakemake removes every curve the bundle "
        "finished and its retry runs them all again, hours each at these grids; bundle "
        f"only grids up to {BUNDLE_MAX_GRID} (run the finer ones in a sweep of their own "
        "with sims=1)"
    )
