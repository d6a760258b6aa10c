"""``brushcore simulate``: check every flag, run one curve, write its file.

Every check runs before the first solve; Ctrl-C and SIGTERM end with one
line, exit status 130 or 143, and no file written.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
import warnings
from pathlib import Path

from brushcore.cli.output import Progress, say_error
from brushcore.cli.parser import FLAGS
from brushcore.data.joblog import (EXIT_INTERRUPTED, EXIT_TERMINATED, INTERRUPTED, Terminated,
                                   on_sigterm, terminate)
from brushcore.model.labelmap import count_touching_pairs, touching_note
from brushcore.model.params import MAX_PHI_ERROR, BrushParams
from brushcore.numerics.events.pulloff import SolverError
from brushcore.numerics.linear.cg import ConvergenceError, ran_out_of_iterations
from brushcore.numerics.options import SolverOptions
from brushcore.numerics.platform.backend import resolve_backend
from brushcore.numerics.platform.threads import MAX_THREADS
from brushcore.validation import ParameterError

def _brush_params(args: argparse.Namespace) -> BrushParams:
    """BrushParams from the flags (`_missing_flags` found none missing); for --layout
    file N, grid and phi come from the file."""
    given = getattr(args, "given", set())
    # a lattice or a file ignores the gap: not recorded, so its curve is the lattice's
    gap = args.min_gap if args.layout == "random" else 1.0
    # without --kbar, --kbar-file's mean replaces this stand-in once the file is read
    kbar = args.kbar if args.kbar is not None else 1.0
    common = dict(seed=args.seed, min_gap=gap, e_star=args.e_star,
                  dgamma=args.dgamma, h=args.h, allow_coarse=args.allow_coarse,
                  shape=args.shape, aspect=args.aspect, orientation=args.orientation)
    from brushcore.model.layout import hinted_params

    if args.layout == "file":
        from brushcore.model.layout_file import file_params
        from brushcore.model.pillar_table import is_table

        fixed = {"n_pillars": args.pillars, "grid": args.grid, "phi": args.phi}
        fixed = {k: v for k, v in fixed.items() if {"n_pillars": "pillars"}.get(k, k) in given}
        if fixed.get("grid") is None or not is_table(args.layout_file):
            return file_params(args.layout_file, kbar, **common, **fixed)
        # a table fits every grid: one too coarse is told the next that runs,
        # not the mean radius's grid that the filling factor may refuse again
        return hinted_params(lambda grid: file_params(args.layout_file, kbar, **common,
                                                      **{**fixed, "grid": grid}), args.grid)

    return hinted_params(
        lambda grid: BrushParams(layout=args.layout, n_pillars=args.pillars, kbar=kbar,
                                 grid=grid, phi=args.phi, layout_file="" if args.layout_file
                                 is None else str(args.layout_file), **common), args.grid)


def _missing_flags(args: argparse.Namespace) -> str:
    """Every flag the chosen layout needs and ``args`` lacks, in one sentence
    ("" where none): a second try should not meet the next one."""
    from brushcore.model.pillar_table import is_table

    parts = []
    if args.layout == "file":
        if args.layout_file is None:
            parts.append("--layout-file is required for --layout file")
        elif (is_table(args.layout_file) and "grid" not in getattr(args, "given", set())
              and Path(args.layout_file).is_file()):  # a missing file: its own error first
            parts.append("--grid is required for a pillar table (.csv): it is drawn on any "
                         "grid")
    else:
        missing = [flag for flag, value in (("--pillars", args.pillars), ("--grid", args.grid))
                   if value is None]
        if missing:
            parts.append(f"{' and '.join(missing)} {'are' if len(missing) > 1 else 'is'} "
                         f"required for --layout {args.layout}")
    if args.kbar is None and args.kbar_file is None:
        parts.append("--kbar is required (or --kbar-file, one kbar per pillar)")
    return "; ".join(parts)


class _Missing(Exception):
    """A flag that the chosen layout needs was not given."""


#: What SIGTERM makes the command say (it exits with `EXIT_TERMINATED`).
TERMINATED = "terminated; nothing written"


def run_simulate(args: argparse.Namespace) -> int:
    """Run ``brushcore simulate``; its exit status (0, 1 a failure, 2 bad input,
    130 or 143 interrupted)."""
    from brushcore.model.cost import cost_note, memory_note
    from brushcore.model.curve import (FirstTouchWarning, check_protocol_preload,
                                       preload_contact, simulate)
    from brushcore.data.io import check_output_path, remove_stale_temporaries, write_curve
    from brushcore.model.layout import build_labels, pillars_differ, smallest_radius_elements
    from brushcore.model.inputs import (INPUT_FILES, parse_protocol, recorded_kbar,
                                        with_input_files)
    from brushcore.model.pillar_table import is_table
    from brushcore.numerics.platform.threads import fft_threads, pin_threads

    progress = None if args.quiet else Progress()
    started = time.time()
    try:
        missing = _missing_flags(args)
        if missing:
            raise _Missing(missing)
        # Files are checked against the counts the plain parameters imply.
        base = dataclasses.replace(_brush_params(args), roughness=args.roughness,
                                   preload=args.preload, kbar_spread=args.kbar_spread,
                                   backend=args.backend)
        backend = resolve_backend(base.backend)  # CuPy and a card, before any work
        params = with_input_files(base, {name: getattr(args, name) for name in INPUT_FILES})
        if args.min_gap != 1.0 and args.layout != "random":  # it would seem to count
            warnings.warn(f"--min-gap applies to random layouts only: the {params.layout} "
                          f"layout ignores --min-gap {args.min_gap:g}")
        if args.seed != 0 and not params.draws_from_seed:  # it would seem to count
            warnings.warn(f"--seed {args.seed} draws nothing here (it picks a random layout, "
                          "--roughness heights or a --kbar-spread draw): the brush is the "
                          "same for every seed")
        if args.kbar is None:  # as a --kbar-spread draw's mean is its --kbar
            kbar = recorded_kbar(params.kbar_values)
            if kbar is None:
                raise _Missing(f"--kbar is required beside a --kbar-file of rigid and finite "
                               f"pillars ({sum(map(math.isinf, params.kbar_values))} of "
                               f"{params.n_pillars} rigid): their mean, inf, would file the "
                               "brush as rigid")
            params = dataclasses.replace(params, kbar=kbar)
        elif args.kbar_file is not None:  # it would seem to count
            warnings.warn(f"--kbar-file gives every pillar's stiffness: --kbar {args.kbar:g} "
                          "is recorded as the curve's kbar but no pillar runs it")
        options = SolverOptions(rtol=args.rtol, max_iter=args.max_iter, tie_rtol=args.tie_rtol,
                                lookahead=args.lookahead, cascade=args.cascade,
                                symmetry=args.symmetry, precision=args.precision,
                                early_decisions=args.early_decisions,
                                settle_decisions=args.settle_decisions,
                                fft_library=args.fft_library)
        protocol = None if args.protocol is None else parse_protocol(args.protocol)
        check_protocol_preload(args.preload, protocol)  # before the layout's line
        if args.threads is None:  # as the Python API: the environment's, else 1
            args.threads = fft_threads()
        if not 1 <= args.threads <= MAX_THREADS:
            raise ParameterError("threads", args.threads, f"an integer in [1, {MAX_THREADS}]")
        check_output_path(args.out)
        if Path(args.out).suffix.lower() not in (".nc", ".nc4"):  # runs, but hides its kind
            warnings.warn(f"--out {args.out}: the curve is written as netCDF, which tools "
                          "(and brushcore converge) find by the suffix .nc")
        labels = build_labels(params)  # layout and discretisation checked before any solve
        area = int((labels >= 0).sum())
        touching = count_touching_pairs(labels)  # random discs on grids coarser than 512
        asked = ("requested" if not params.layout_file else
                 "the table's" if is_table(params.layout_file) else "the file's")
        n_built = int(labels.max()) + 1
        narrowest = smallest_radius_elements(params, labels)  # what the flags read
        print(f"grid {params.grid}: pillar radius {params.pillar_radius_elements:.3g} elements"
              f"{' (equal-area mean)' if params.layout_file else ''}"
              + (f", the narrowest {narrowest:.3g}"
                 if pillars_differ(narrowest, params.pillar_radius_elements) else "") + ","
              f" phi realised {area / labels.size:.4g} ({asked} {params.phi:g}"
              + (f", {100 * (area / labels.size / params.phi - 1):+.0f} %: --allow-coarse ran it"
                 if abs(area / labels.size / params.phi - 1) > MAX_PHI_ERROR else "") + "), "
              f"{n_built} pillar{'s' * (n_built != 1)}"
              + ("" if backend.on_host else f", on {backend.device_name}")
              + (f"; {touching_note(touching)}" if touching else ""),
              file=sys.stderr)
        cost = cost_note(params, options, protocol)
        if cost:  # a long run said before it starts, not discovered
            print(cost, file=sys.stderr)
        memory = memory_note(params, options, protocol, labels=labels)
        if memory:  # a warning, not a refusal: the peak is scaled, not known
            warnings.warn(memory)
        if options.lookahead:  # opt-in and documented, but a number could be quoted unread
            warnings.warn(f"--lookahead {options.lookahead:g} batches the events within "
                          f"{100 * options.lookahead:g} % of the next one: approximate (W and "
                          "F_ad of soft or rough brushes can move by per cent); 0 is the "
                          "exact event-driven result")
        pin_threads(args.threads)
        # SIGTERM goes the way of Ctrl-C: one line, and the temporary file removed.
        previous = on_sigterm(terminate)
        try:
            with warnings.catch_warnings():  # said after the run, in the flag's words
                warnings.filterwarnings("ignore", category=FirstTouchWarning)
                ds = simulate(params, options, progress=progress, labels=labels,
                              protocol=protocol)
            try:
                write_curve(ds, args.out)
            except OSError as exc:  # the disk filled up or the folder went away
                say_error(f"cannot write {args.out}: {exc.strerror or exc}; nothing written",
                       progress)
                return 1
            # what a run killed (kill -9, a node's crash) while writing --out left
            remove_stale_temporaries(args.out, older_than=started)
        finally:
            on_sigterm(previous)
    except ParameterError as exc:
        say_error(exc.in_terms_of(FLAGS, sep=" "), progress)
        return 2
    except _Missing as exc:
        say_error(str(exc), progress)
        return 2
    except (ConvergenceError, SolverError) as exc:
        # the one limit a user may raise for it (the config's solver.max_iter)
        hint = " (--max-iter raises the limit)" if ran_out_of_iterations(exc) else ""
        say_error(f"solver failed: {exc}{hint}", progress)
        return 1
    except MemoryError:  # what memory_note could only warn of
        where = f" at --grid {args.grid}" if args.grid else ""  # else a label map's own
        say_error(f"out of memory{where}: a smaller grid, or a machine with more memory; "
               "nothing written", progress)
        return 1
    except KeyboardInterrupt:
        say_error(INTERRUPTED, progress)
        return EXIT_INTERRUPTED
    except Terminated:
        say_error(TERMINATED, progress)
        return EXIT_TERMINATED
    if progress is not None:
        progress.end_line()
    print(f"F_ad/F_K = {float(ds.adhesive_force_normalized):.4f}  "
          f"W/W_K = {float(ds.work_of_separation_normalized):.4f}  "
          f"events = {ds.attrs['events']}  operator applications = "
          f"{ds.attrs['operator_applications']}  time = {ds.attrs['wall_time_s']:.1f} s  "
          f"-> {args.out}")
    pressed = preload_contact(ds, "--preload", "give --preload P to press the brush on")
    if pressed:  # an approach ran: say how far it pressed
        print(pressed)
    if ds.sizes.get("pull", 0) > 1:  # cycles: every retraction's own pull-off
        area = float(ds.attrs["real_contact_area"])
        for k in range(ds.sizes["pull"]):
            pull = ds.isel(pull=k)
            left = float(pull.pull_contact_area_at_end) / area
            print(f"retraction {k}: F_ad/F_K = {float(pull.pull_adhesive_force_normalized):.4f}"
                  f"  W/W_K = {float(pull.pull_work_of_separation_normalized):.4f}"
                  f"  cycle energy/W_K = {float(pull.pull_cycle_energy_normalized):.4f}"
                  f"  in contact at its end: {left:.1%} of the pillar area"
                  + ("  (a partial retraction: F_ad is the largest force it reached, "
                     "not a pull-off)" if left > 0 and math.isfinite(
                         float(pull.pull_adhesive_force_normalized)) else ""))
    if "dissipated_energy_normalized" in ds and pressed:  # a protocol's energy, in its words
        ends = float(ds.contact_area[-1]) > 0  # in contact: stored energy besides the losses
        print(f"integral of F dd over the protocol/W_K = "
              f"{float(ds.dissipated_energy_normalized):.4f}"
              + (" (the energy lost plus the elastic energy stored at its end, in contact)"
                 if ends else " (the energy dissipated)"))
    return 0
