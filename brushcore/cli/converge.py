"""``brushcore converge``: gather curve files into a sweep and extrapolate
each case run on three or more grids; an interrupted or failed write says
which files it wrote and removed."""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

from brushcore.cli.output import say_error
from brushcore.data.joblog import (EXIT_INTERRUPTED, EXIT_TERMINATED, Terminated, on_sigterm,
                                   terminate)

def run_converge(args: argparse.Namespace) -> int:
    """Run ``brushcore converge``; its exit status (0, 1 a failed write, 2 bad
    input, 130 or 143 interrupted)."""
    from brushcore.data.aggregate import (GRID_DIM, AggregationError, build_sweep,
                                          mixed_runs, write_sweep)
    from brushcore.data.convergence_report import write_study

    out = args.out_dir
    if out.exists() and not out.is_dir():
        say_error(f"--out-dir {out} is a file: allowed a folder (made if missing)")
        return 2
    missing = [f"{p} (a folder)" if p.is_dir() else str(p) for p in args.curves
               if not p.is_file()]
    if missing:  # a path typed wrong: nothing to run again
        say_error(f"no such curve file{'s' if len(missing) > 1 else ''}: {', '.join(missing[:10])}"
               + (f" and {len(missing) - 10} more" if len(missing) > 10 else "")
               + ": allowed the .nc files brushcore simulate wrote")
        return 2
    try:
        # no snapshots: a study reads scalars (small sets kept them all before)
        sweep = build_sweep(args.curves, keep_snapshots=(), all_snapshots_below_mb=0.0)
    except AggregationError as exc:
        say_error(str(exc))
        return 2
    files = [out / name for name in ("convergence.nc", "convergence.csv", "convergence.md",
                                     "convergence.png")]
    # per case, not over the sweep: three cases on three grids make no study
    runs = sweep["adhesive_force_normalized"].notnull().sum(GRID_DIM)
    studied = int(runs.max()) >= 3
    stale = [f for f in files if f.exists()]  # an earlier study: not of the sweep.nc to come
    # Ctrl-C or SIGTERM from here on says what the folder holds (an interrupted
    # run left the new sweep.nc beside the earlier curves' study, and said
    # "nothing written": a crash and resume auditor's find)
    previous = on_sigterm(terminate)
    removed: list[Path] = []
    written = False
    try:
        for f in stale:
            f.unlink()
            removed.append(f)
        out.mkdir(parents=True, exist_ok=True)
        write_sweep(sweep, out / "sweep.nc")
        written = True
        if studied:
            write_study(sweep, *files[:3], files[3:])
    except (OSError, KeyboardInterrupt, Terminated) as exc:
        # what this run wrote: the study files that stand where none stood or
        # an earlier one was removed
        done = ([out / "sweep.nc"] if written else []) + [
            f for f in files if f.exists() and (f not in stale or f in removed)]
        if isinstance(exc, KeyboardInterrupt):
            what, status = "interrupted", EXIT_INTERRUPTED
        elif isinstance(exc, Terminated):
            what, status = "terminated", EXIT_TERMINATED
        else:  # a full disk, a folder gone
            what, status = f"cannot write in {out}: {exc.strerror or exc}", 1
        kept = [f for f in stale if f not in removed]
        say_error(f"{what}; written: {', '.join(f.name for f in done) or 'nothing'}"
               + (f" (the earlier {', '.join(f.name for f in removed)} removed)"
                  if removed else "")
               + (f" (the earlier {', '.join(f.name for f in kept)} not removed: not of "
                  "the curves given)" if kept else "")
               + ": run brushcore converge again for the whole study")
        return status
    finally:
        on_sigterm(previous)
    mixed = mixed_runs(sweep)
    if mixed:  # a study across code versions or settings: said, not hidden in an attribute
        warnings.warn(f"the curves differ in {mixed}: their differences join the mesh's "
                      "in the study; run them again with one brushcore and settings", stacklevel=1)
    grids = [int(g) for g in sweep[GRID_DIM].values]
    if not studied:
        print(f"{len(args.curves)} curves on grids {grids} -> {out / 'sweep.nc'}; no "
              "convergence study: it needs a case run on three or more grids"
              + (f" (removed the earlier curves' {', '.join(f.name for f in stale)})"
                 if stale else ""))
        return 0
    study = ", ".join(map(str, files))
    # the table; its legend (a paragraph on every column and flag) stays in the file
    print((out / "convergence.md").read_text().split("\n\n", 1)[-1], end="")
    print(f"{len(args.curves)} curves on grids {grids} -> {out / 'sweep.nc'}, {study} "
          f"(the columns and flags are explained at the top of convergence.md)")
    return 0
