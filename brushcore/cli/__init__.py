"""Command line: ``brushcore simulate`` writes a curve, ``converge`` extrapolates.

``brushcore simulate ...`` writes one curve file; ``brushcore converge ...``
extrapolates the curves of a resolution study.

Conventions: no abbreviated flags, unknown flags named (with the closest
known one), defaults shown in ``--help``, errors worded with the flags the
user typed, every check done before the first solve, Ctrl-C ends with one
line and exit status 130.

Modules: `parser` (flags and their readers), `output` (progress, warnings,
errors), `simulate` and `converge` (the two sub-commands).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

from brushcore.cli.converge import run_converge
from brushcore.cli.output import cli_warning, say_error
from brushcore.cli.parser import DESCRIPTION, FLAGS, ScriptHelp, build_parser
from brushcore.cli.simulate import run_simulate
from brushcore.data.joblog import EXIT_INTERRUPTED, INTERRUPTED

__all__ = ["DESCRIPTION", "FLAGS", "ScriptHelp", "build_parser", "main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``brushcore`` command."""
    # Warnings read as the errors do: one line, no source line of brushcore's.
    previous = warnings.formatwarning
    warnings.formatwarning = cli_warning
    try:
        args = build_parser().parse_args(argv)
        if args.command == "simulate":
            return run_simulate(args)
        if args.command == "converge":
            return run_converge(args)
    except KeyboardInterrupt:  # during start-up (imports, parsing)
        say_error(INTERRUPTED)
        return EXIT_INTERRUPTED
    finally:
        warnings.formatwarning = previous
    return 2  # pragma: no cover - argparse enforces the sub-command
