"""What the command prints on stderr: progress, warnings and errors."""

from __future__ import annotations

import re
import sys
import time

from brushcore.cli.parser import FLAGS

class Progress:
    """Progress on stderr: a live line on a terminal, plain lines in a log.

    On a terminal the line is rewritten in place every 2 s; when stderr is a
    file (a batch job's log) a full line is printed every 30 s, so that the
    log never holds carriage returns.
    """

    def __init__(self, stream=None) -> None:
        self.stream = sys.stderr if stream is None else stream
        self.live = bool(getattr(self.stream, "isatty", lambda: False)())
        self.every = 2.0 if self.live else 30.0
        self.t0 = self.last = time.monotonic()
        self.shown = False

    def __call__(self, events: int, attached: int, total: int) -> None:
        now = time.monotonic()
        if now - self.last < self.every:
            return
        self.last = now
        # in contact now, not a share let go: an approach or a cycle attaches elements
        text = (f"  {100 * attached / total:5.1f}% of the pillar area in contact, "
                f"{events} events, {now - self.t0:6.1f} s")
        if self.live:
            print("\r" + text, end="", file=self.stream, flush=True)
            self.shown = True
        else:
            print(text, file=self.stream, flush=True)

    def end_line(self) -> None:
        """Finish a live line so that the next message starts on its own."""
        if self.shown:
            print("", file=self.stream, flush=True)
            self.shown = False


def cli_warning(message: Warning | str, *args: object, **kwargs: object) -> str:
    """A warning as the command prints it: one that opens with a parameter's
    name and a file ("heights FILE: ...", the input readers' form) names its
    flag; any other text is left as it is."""
    text = str(message)
    found = re.match(r"(\w+)( \S+:)", text)
    if found and found[1] in FLAGS:
        text = FLAGS[found[1]] + text[len(found[1]):]
    return f"brushcore: warning: {text}\n"


def say_error(message: str, progress: Progress | None = None) -> None:
    """An error as one line on stderr, after a live progress line is ended."""
    if progress is not None:
        progress.end_line()
    print(f"brushcore: error: {message}", file=sys.stderr)
