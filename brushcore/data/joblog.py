"""Run a block with stdout and stderr going to a log file, tracebacks included."""

from __future__ import annotations

import contextlib
import os
import sys
import traceback
from collections.abc import Iterator
from contextlib import redirect_stderr, redirect_stdout

#: Exit status after Ctrl-C (128 + SIGINT), as shells report it.
EXIT_INTERRUPTED = 130
INTERRUPTED = "interrupted; nothing written"


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
                except BaseException:
                    traceback.print_exc()
                    raise
        except KeyboardInterrupt:
            print(f"{path}: {INTERRUPTED}", file=sys.__stderr__, flush=True)
            raise SystemExit(EXIT_INTERRUPTED) from None
