"""Run a block with stdout and stderr going to a log file, tracebacks included."""

from __future__ import annotations

import contextlib
import os
import traceback
from collections.abc import Iterator
from contextlib import redirect_stderr, redirect_stdout


@contextlib.contextmanager
def logged(path: str | os.PathLike) -> Iterator[None]:
    """Redirect output to ``path``; an exception is logged with its traceback, then re-raised.

    Workflow scripts wrap their work in it so that every job leaves a
    readable log, and a failure still fails the job.
    """
    with open(path, "w") as log, redirect_stdout(log), redirect_stderr(log):
        try:
            yield
        except BaseException:
            traceback.print_exc()
            raise
