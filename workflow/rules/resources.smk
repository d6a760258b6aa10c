"""What a simulate job asks for: memory, GPUs and its time limit, from the
slowest curves measured per kind and grid (`brushcore.model.cost`)."""

import math

from brushcore.model.cost import is_exact, kind_of, slowdown, slowest_curve_s
from brushcore.model.layout_file import FILE_LAYOUT_PREFIX
from brushcore.model.params import ParameterError
from brushcore.numerics.options import SolverOptions
from brushcore.numerics.platform.backend import resolve_backend


def simulate_mem_mb(wildcards):
    """Memory of one simulation [MB], the same on every attempt.

    Measured peak RSS (README, "Speed and memory"): at most 0.6 GB at grid
    512, 1.05 GiB for a flat curve and 3.4 GB for the rough 8 x 8 brush at
    1024, 2.7 GiB at 2048 (random 1620).  Granted: 1 GB, the FFT buffers at
    150 MB x (n/512)^2, and above 512 the 4 GB that per-pillar block inverses
    may take (`BlockInverse.fits`): 1.15 GB at 512, 5.6 GB at 1024, 7.4 GB
    at 2048.  Snakemake tells a resource function the attempt, not why the
    last one failed, and a time limit is the likelier cause with these
    margins: a retry asks for more time (`simulate_runtime`), not memory.
    """
    grid = int(wildcards.grid)
    blocks = 4000 if grid > 512 else 0
    return int(1000 + 150 * (grid / 512) ** 2 + blocks)


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


def curve_kind(layout, shape, rough, solver=None, offsets=False):
    """The `SLOWEST_CURVE_S` kind of a curve (`brushcore.model.cost.kind_of`,
    as the command's note asks it) from its wildcards (shape and rough
    suffixes), whether its brush is given heights or a gap map
    (``offsets``, `_given_offsets`) and the config's solver settings
    (``symmetry: false`` solves a regular brush on the whole grid)."""
    uneven = (
        parse_rough_tag(rough).get("roughness", 0.0) > 0 or "_Q" in rough or offsets
    )
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


def curve_minutes(layout, shape, rough, grid, solver=None, offsets=False):
    """Time limit of a curve's first attempt [min]: `RUNTIME_SAFETY` x the
    slowest measured curve of its kind and grid, times `solver_slowdown` of
    the config's ``solver`` settings, plus `RUNTIME_OVERHEAD_MIN`.

    With the default solver: 1024^2 12 min regular, 39 min random, 18 h
    rough; 2048^2 66 min regular, 13.1 h random.  The time does not shrink
    with `threads`: the measurements are on one thread, and a second gains
    at most 2x.
    """
    kind = curve_kind(layout, shape, rough, solver, offsets)
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
