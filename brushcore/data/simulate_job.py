"""The workflow's simulate job: one (layout, N, kbar, seed, shape, ...) -> one curve file.

`workflow/scripts/simulate.py` only calls `run_job`: Snakemake reruns every
finished curve when a rule's script changes (its "code" trigger), and not
when a module it imports does, so the job's logic lives here.
"""

from __future__ import annotations

import sys
import time
import warnings
from collections.abc import Mapping
from typing import TYPE_CHECKING

from brushcore.data.joblog import CurveClock, logged, stops_on_sigterm

if TYPE_CHECKING:
    import xarray as xr

    from brushcore.model.params import BrushParams


def run_job(smk) -> None:
    """Run the job Snakemake describes (``snakemake`` of a script rule):
    its log, its SIGTERM line (Slurm's time limit, scancel: status 143, no
    curve) and the curve file."""
    clock = CurveClock()
    with logged(smk.log[0]), stops_on_sigterm(clock.where):
        _simulate(smk, clock)


def _simulate(smk, clock: CurveClock) -> None:
    """Build the brush from the job's wildcards and params, pull it off, write the curve."""
    from brushcore.model.curve import FirstTouchWarning, simulate
    from brushcore.numerics.options import SolverOptions
    from brushcore.numerics.linear.cg import ConvergenceError, ran_out_of_iterations
    from brushcore.data.io import check_output_path, remove_stale_temporaries, write_curve
    from brushcore.data.joblog import parent_watch
    from brushcore.model.inputs import parse_protocol
    from brushcore.numerics.platform.threads import pin_threads

    orphaned = parent_watch()  # Snakemake killed: stop, and write nothing later

    def progress(events: int, attached: int, total: int) -> None:
        clock(events, attached, total)  # for the line a SIGTERM leaves
        orphaned()

    check_output_path(smk.output[0])  # an unwritable folder fails now, not after the solve
    # left by a job killed while writing (not by one started since: --nolock runs)
    remove_stale_temporaries(smk.output[0], older_than=time.time())
    pin_threads(smk.threads)
    w = smk.wildcards
    params = case_params(w.layout, int(w.n_pillars), float(w.kbar), int(w.seed), int(w.grid),
                         float(w.phi), files=smk.params.layout_file, rough=smk.params.rough,
                         shape=smk.params.shape, allow_coarse=bool(smk.config["allow_coarse"]),
                         backend=smk.config["backend"])
    # the digest tells which given heights, stiffnesses or gap map ran
    given = f" (inputs {params.inputs_digest})" if params.inputs_digest else ""
    print(f"{params}{given} on {smk.threads} thread(s)", flush=True)
    text = smk.config.get("protocol")  # checked at plan time; named in the file by its digest
    protocol = None if text is None else parse_protocol(text)
    try:
        with warnings.catch_warnings():  # said below, in the config's words
            warnings.filterwarnings("ignore", category=FirstTouchWarning)
            curve = simulate(params, SolverOptions(**smk.params.solver), progress=progress,
                             protocol=protocol)
    except ConvergenceError as exc:
        if ran_out_of_iterations(exc):  # the one limit a config may raise for it
            exc.add_note("the config's solver.max_iter raises the limit")
        raise
    orphaned()
    try:
        write_curve(curve, smk.output[0])
    except OSError as exc:  # a full disk or quota: one line, as the CLI says it
        line = f"cannot write {smk.output[0]}: {exc.strerror or exc}"
        print(line, flush=True)  # the log
        print(f"{smk.log[0]}: {line}", file=sys.__stderr__, flush=True)  # the terminal
        raise SystemExit(1) from None
    for line in log_lines(curve):
        print(line)


def case_params(layout: str, n_pillars: int, kbar: float, seed: int, grid: int, phi: float,
                *, files: str | Mapping[str, str] = "", rough: Mapping[str, float] | None = None,
                shape: Mapping[str, object] | None = None, allow_coarse: bool = False,
                backend: str = "cpu") -> BrushParams:
    """The parameters of one case of a sweep: what its job runs and what the
    plan checks before any job starts (`workflow/rules/config_checks.smk`), one
    construction so that the two cannot drift apart.

    Parameters
    ----------
    layout, n_pillars, kbar, seed, grid, phi : the case (a file brush's
        layout is ``file_<name>``, and it takes "file" from ``files``; its
        N, grid and phi are checked against the file's)
    files : "" for a generated layout, a map's or table's path, or
        {"layout": path, "heights": ..., ...} (`with_input_files` keys; a
        "sha256" key, the workflow's digest of the files, is left out)
    rough : roughness, preload, kbar_spread; None or {} for a flat brush
    shape : shape, aspect, orientation; None or {} for discs
    allow_coarse, backend : as `BrushParams`

    Raises
    ------
    ParameterError
        As `BrushParams`, `file_params` and `with_input_files`.
    """
    from brushcore.model.inputs import with_input_files
    from brushcore.model.layout_file import file_params
    from brushcore.model.params import BrushParams

    fields = dict(n_pillars=n_pillars, grid=grid, phi=phi, seed=seed,
                  allow_coarse=allow_coarse, backend=backend, **(rough or {}),
                  **(shape or {}))
    if files:  # a brush of one's own: the file's N, grid and phi checked
        inputs = dict(files) if isinstance(files, Mapping) else {"layout": files}
        inputs.pop("sha256", None)  # the workflow's digest of the files: reruns, not inputs
        params = file_params(inputs.pop("layout"), kbar, **fields)
        return with_input_files(params, inputs)  # heights, stiffness factors, gap map
    return BrushParams(layout=layout, kbar=kbar, **fields)


def log_lines(curve: xr.Dataset) -> list[str]:
    """What a job's log says of its curve: F_ad, W, events and time, the
    resolution, touching pillars (as the command says them) and how far an
    approach pressed, in the config's words."""
    from brushcore.model.curve import preload_contact
    from brushcore.model.labelmap import touching_note
    from brushcore.model.layout import pillars_differ

    mean, narrowest = (float(curve.attrs[f"{which}_radius_elements"])
                       for which in ("pillar", "smallest"))
    lines = [
        f"F_ad = {float(curve['adhesive_force_normalized']):.6g}, "
        f"W = {float(curve['work_of_separation_normalized']):.6g} (normalised), "
        f"{curve.attrs.get('events')} events, "
        f"{curve.attrs.get('wall_time_s', float('nan')):.3g} s; "
        f"pillar radius {mean:.3g} elements"
        + (f" (the narrowest {narrowest:.3g})" if pillars_differ(narrowest, mean) else "")
        + f", phi realised {curve.attrs['phi_actual']:.4g}"
    ]
    touching = touching_note(int(curve.attrs.get("touching_pillar_pairs", 0)))
    if touching:  # random discs on grids coarser than 512
        lines.append(touching)
    pressed = preload_contact(curve, "preload", "add a load to the config's 'preload' list "
                                                "to press the brush on")
    if pressed:
        lines.append(pressed)
    return lines
