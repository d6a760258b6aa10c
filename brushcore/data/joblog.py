"""Run a block with stdout and stderr going to a log file, tracebacks included."""

from __future__ import annotations

import contextlib
import os
import sys
import traceback
from collections.abc import Callable, Iterator
from contextlib import redirect_stderr, redirect_stdout

#: Exit status after Ctrl-C (128 + SIGINT), as shells report it.
EXIT_INTERRUPTED = 130
INTERRUPTED = "interrupted; nothing written"
#: Exit status of a job whose Snakemake is gone (EX_TEMPFAIL: run it again).
EXIT_ORPHANED = 75


def parent_watch() -> Callable[..., None]:
    """A check that stops a job once the process that started it is gone.

    Snakemake starts a script job as its direct child; killed with
    SIGKILL it leaves the job running, reparented, and the job would write
    its curve whenever it finished: after a resumed run had rebuilt
    ``sweep.nc``, perhaps with other solver settings, and unseen by it.
    Call the check (it takes and ignores a progress callback's arguments)
    during the work and just before writing; from an orphaned job it
    prints one line and exits with `EXIT_ORPHANED`, writing nothing.
    """
    parent = os.getppid()

    def check(*_: object) -> None:
        if os.getppid() != parent:
            print(f"the process that started this job ({parent}) is gone; stopping, "
                  "nothing written (a rerun of the workflow makes this output)", flush=True)
            raise SystemExit(EXIT_ORPHANED)

    return check


@contextlib.contextmanager
def logged(path: str | os.PathLike) -> Iterator[None]:
    """Redirect output to ``path``; an exception is logged with its traceback, then re-raised.

    Workflow scripts wrap their work in it so that every job leaves a
    readable log, and a failure still fails the job.  Ctrl-C is not a
    failure of the job: it logs one line, prints it once on the terminal
    and exits with status 130, without a traceback.
    """
    with open(path, "w") as log:
        try:
            with redirect_stdout(log), redirect_stderr(log):
                try:
                    yield
                except KeyboardInterrupt:
                    print(INTERRUPTED, flush=True)
                    raise
                except SystemExit:  # a deliberate stop, already explained
                    raise
                except BaseException:
                    traceback.print_exc()
                    raise
        except KeyboardInterrupt:
            print(f"{path}: {INTERRUPTED}", file=sys.__stderr__, flush=True)
            raise SystemExit(EXIT_INTERRUPTED) from None
