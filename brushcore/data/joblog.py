"""Run a block with stdout and stderr going to a log file, tracebacks included."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import time
import traceback
from collections.abc import Callable, Iterator
from contextlib import redirect_stderr, redirect_stdout
from typing import NoReturn

#: Exit status after Ctrl-C (128 + SIGINT), as shells report it.
EXIT_INTERRUPTED = 130
INTERRUPTED = "interrupted; nothing written"
#: Exit status of a job whose Snakemake is gone (EX_TEMPFAIL: run it again).
EXIT_ORPHANED = 75
#: Exit status after SIGTERM (128 + 15), as shells report it.
EXIT_TERMINATED = 143


class Terminated(BaseException):
    """SIGTERM (kill, Slurm's scancel or time limit) arrived; like
    KeyboardInterrupt, no ``except Exception`` may swallow it."""


def terminate(signum: int, frame: object) -> NoReturn:
    """SIGTERM handler: raise `Terminated` where the program is."""
    raise Terminated


def on_sigterm(handler: Callable[..., object] | int | None) -> object:
    """Install a SIGTERM handler, returning the previous one; a no-op (None)
    off the main thread, where Python allows none (`main` called from a thread)."""
    if handler is None:
        return None
    try:
        return signal.signal(signal.SIGTERM, handler)
    except ValueError:
        return None


class CurveClock:
    """Where a job's curve stands, for the line a killed job leaves.

    A progress callback (``progress(events, attached, total)``, called after
    each event) that records the last event and the pillar elements in
    contact; the clock starts when it is made.  Counts, not a share
    detached: a rough brush's approach attaches elements.
    """

    def __init__(self) -> None:
        self.started = time.monotonic()
        self.events: int | None = None
        self.attached = 0
        self.total = 0

    def __call__(self, events: int, attached: int, total: int) -> None:
        self.events, self.attached, self.total = events, attached, total

    def where(self) -> str:
        """'at event E, A of T pillar elements in contact, after S s' (or
        'before the first event, after S s')."""
        at = ("before the first event" if self.events is None else
              f"at event {self.events}, {self.attached} of {self.total} pillar elements in "
              "contact")
        return f"{at}, after {time.monotonic() - self.started:.0f} s"


@contextlib.contextmanager
def stops_on_sigterm(where: Callable[[], str]) -> Iterator[None]:
    """SIGTERM inside the block stops it with one line and status 143.

    Slurm sends SIGTERM at a job's time limit (and on ``scancel``), then
    SIGKILL; without a handler the job's log ended wherever the work was.
    The line, printed to stdout (the job's log under `logged`), says
    ``terminated (SIGTERM: scancel or the time limit) <where()>; nothing
    written``, true of a block that publishes its output only at its end,
    as `write_curve` does (atomically, its temporary removed on any exit).
    """
    previous = on_sigterm(terminate)
    try:
        yield
    except Terminated:
        print(f"terminated (SIGTERM: scancel or the time limit) {where()}; nothing written",
              flush=True)
        raise SystemExit(EXIT_TERMINATED) from None
    finally:
        on_sigterm(previous)


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
