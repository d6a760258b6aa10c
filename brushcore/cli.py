"""Command line: ``brushcore simulate`` writes a curve, ``converge`` extrapolates.

``brushcore simulate ...`` writes one curve file; ``brushcore converge ...``
extrapolates the curves of a resolution study.

Conventions: no abbreviated flags, unknown flags named (with the closest
known one), defaults shown in ``--help``, errors worded with the flags the
user typed, every check done before the first solve, Ctrl-C ends with one
line and exit status 130.
"""

from __future__ import annotations

import argparse
import dataclasses
import difflib
import math
import re
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NoReturn

from brushcore.numerics.linear.cg import ConvergenceError
from brushcore.data.joblog import (EXIT_INTERRUPTED, EXIT_TERMINATED, INTERRUPTED, Terminated,
                                   on_sigterm, terminate)
from brushcore.model.inputs import PROTOCOL_SYNTAX
from brushcore.model.labelmap import count_touching_pairs, touching_note
from brushcore.model.params import (LAYOUTS, MAX_ASPECT, MAX_GRID, MAX_KBAR_SPREAD,
                                    MAX_ORIENTATION, MAX_PHI, MAX_PHI_ERROR, MAX_ROUGH,
                                    MAX_SEED, MIN_GRID, MIN_KBAR, RANDOM_GAP_GRID, UNIT_RANGE,
                                    BrushParams)
from brushcore.numerics.platform.backend import USER_BACKENDS, resolve_backend
from brushcore.numerics.options import SolverOptions
from brushcore.numerics.platform.threads import MAX_THREADS
from brushcore.validation import ParameterError, overflows
from brushcore.model.provenance import version
from brushcore.numerics.events.pulloff import SolverError
from brushcore.model.shapes import SHAPES

#: API parameter -> the flag that sets it, for error messages.
FLAGS = {"n_pillars": "--pillars", "kbar": "--kbar", "grid": "--grid", "phi": "--phi",
         "seed": "--seed", "min_gap": "--min-gap", "e_star": "--e-star",
         "dgamma": "--dgamma", "h": "--h", "layout": "--layout", "rtol": "--rtol",
         "lookahead": "--lookahead", "cascade": "--cascade", "symmetry": "--no-symmetry", "threads": "--threads",
         "precision": "--precision", "early_decisions": "--no-early-decisions",
         "settle_decisions": "--no-settle-decisions", "fft_library": "--fft-library",
         "out": "--out", "allow_coarse": "--allow-coarse", "shape": "--shape",
         "aspect": "--aspect", "orientation": "--orientation", "layout_file": "--layout-file",
         "roughness": "--roughness", "preload": "--preload", "kbar_spread": "--kbar-spread",
         "heights": "--heights", "kbar_values": "--kbar-file", "gap_map": "--gap-map",
         "kbar_factors": "--kbar-factors", "kbar_file": "--kbar-file",
         "backend": "--backend", "protocol": "--protocol"}
_NUMBER = re.compile(r"^-\d|^-\.\d|^-inf$", re.IGNORECASE)


def _default(name: str) -> object:
    """`BrushParams`' default of field ``name``: the flags show the API's."""
    return BrushParams.__dataclass_fields__[name].default


def _path(text: str) -> Path:
    """A file path as typed; an empty one is refused (Path("") would be ".")."""
    if not text:
        raise argparse.ArgumentTypeError("an empty path; allowed a path")
    return Path(text)


def _integer(allowed: str) -> Callable[[str], int]:
    """An integer flag's reader: "64" and "64.0" give 64, as the config and
    the Python API take 64.0; "4.5", "four" and "inf" are refused naming
    ``allowed`` (the flag's range), which argparse's ``int`` does not."""
    def read(text: str) -> int:
        try:
            return int(text)
        except ValueError:
            pass
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not value.is_integer():
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer; allowed {allowed}")
        return int(value)
    read.__name__ = "integer"
    return read


def _output(text: str) -> str:
    """The output path as typed (a trailing separator kept for the check)."""
    _path(text)
    return text


def _kbar(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a number; allowed a number in [{MIN_KBAR:g}, inf], 'inf' means rigid"
        ) from None
    if overflows(text):
        raise argparse.ArgumentTypeError(
            f"{text!r} overflows a float; allowed a finite number >= {MIN_KBAR:g} or 'inf' "
            "for rigid pillars")
    return value


#: A whole negative number, as a value rather than a flag: argparse's own
#: pattern takes -5 and -0.5 but not -1e1 or -inf.
_NEGATIVE_VALUE = re.compile(r"^-(?:\d+\.?\d*|\.\d+)(?:e[-+]?\d+)?$|^-inf$", re.IGNORECASE)


class _Parser(argparse.ArgumentParser):
    """argparse that names unknown flags before complaining about missing
    ones, reads -1e1 and -inf as values, and says what is wrong in one line
    (as the checks after parsing do), not under the whole usage text."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_VALUE

    def error(self, message: str) -> NoReturn:  # noqa: D102 - argparse API
        self.exit(2, f"brushcore: error: {message} (see '{self.prog} --help')\n")

    def parse_known_args(self, args=None, namespace=None):  # noqa: D102 - argparse API
        args = list(sys.argv[1:] if args is None else args)
        if self._subparsers is None:  # a sub-command's parser judges its own flags
            known = set(self._option_string_actions)
            seen: dict[str, list[str]] = {}
            for token in args:
                if token == "--":
                    break
                flag = token.split("=", 1)[0]
                if flag.startswith("-") and not _NUMBER.match(flag) and flag not in known:
                    # a flag cut short is a prefix of what was meant (--pil: --pillars)
                    close = ([k for k in sorted(known) if k.startswith(flag) and len(flag) > 2]
                             or difflib.get_close_matches(flag, sorted(known), n=1))
                    hint = f" (did you mean {' or '.join(close[:3])}?)" if close else ""
                    self.error(f"unknown argument {flag}{hint}")
                if flag in known:
                    seen.setdefault(self._option_string_actions[flag].dest, []).append(flag)
            for flags in seen.values():
                if len(flags) > 1:  # argparse keeps the last: say so, a typo may hide there
                    warnings.warn(f"{flags[0]} is given {len(flags)} times: the last one counts")
        return super().parse_known_args(args, namespace)

    def parse_args(self, args=None, namespace=None):  # noqa: D102 - argparse API
        args = list(sys.argv[1:] if args is None else args)
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:
            # the sub-command's help, where the stray words followed one
            command = next((a for a in args if not a.startswith("-")), None)
            sub = (self._subparsers._group_actions[0].choices.get(command)
                   if self._subparsers is not None else None)
            shown = f"{self.prog} {command}" if sub is not None else self.prog
            takes = sub._option_string_actions if sub is not None else {}
            self.exit(2, f"brushcore: error: {_unrecognized(args, extras, takes)} "
                         f"(see '{shown} --help')\n")
        return parsed


def _unrecognized(args: list[str], extras: list[str],
                  actions: dict[str, argparse.Action]) -> str:
    """argparse's "unrecognized arguments", with the likeliest cause: a list
    value with spaces left unquoted (--protocol force:-1, separation, or
    --protocol=force:-1, separation), which the shell split after its comma.
    ``actions``: the sub-command's flags, to tell a flag that takes a value."""
    message = f"unrecognized arguments: {' '.join(extras)}"
    # the stray words' place: the last run of them at the end of what was typed
    at = len(args) - len(extras) if args[len(args) - len(extras):] == extras else -1
    for i in range(len(args) - 1, -1, -1):  # or where the first stray word stands alone
        if at < 0 and args[i] == extras[0]:
            at = i
    before = args[at - 1] if at >= 1 else ""
    flag, value = (before.split("=", 1) if before.startswith("--") and "=" in before
                   else (args[at - 2] if at >= 2 else "", before))
    action = actions.get(flag)
    if value.endswith(",") and action is not None and action.nargs != 0:
        rest = [word for word in args[at:] if word in extras][:len(extras)]
        message += (f"; after {flag} {value}: quote a value with spaces, "
                    f"{flag} '{' '.join([value, *rest])}'")
    return message


class _Given(argparse.Action):
    """Stores the value and remembers that the flag was typed (not its default)."""

    def __call__(self, parser, namespace, values, option_string=None):  # noqa: D102
        setattr(namespace, self.dest, values)
        namespace.given = getattr(namespace, "given", set()) | {self.dest}


class _DefaultsShown(argparse.ArgumentDefaultsHelpFormatter):
    """Shows defaults, except for required flags, flags without one (None) and
    on/off switches (whose default is a bool: a zero default, ``0 == False``,
    is still shown); the benchmark scripts' help too (`ScriptHelp`)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.required or action.default is None or isinstance(action.default, bool):
            return action.help
        return super()._get_help_string(action)


class ScriptHelp(argparse.RawDescriptionHelpFormatter, _DefaultsShown):
    """A benchmark script's help: its module docstring as written (the
    examples) and each option's default, as `_DefaultsShown` shows them."""


class _Version(argparse.Action):
    """``--version``: the version, the commit (a git call, so only when asked)
    and the libraries the numbers pass through, as a curve file records them."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: object, option_string: str | None = None) -> None:
        from brushcore.model.provenance import code_digest, git_commit, software_versions

        print(f"brushcore {version()} (commit {git_commit()}, code sha256 {code_digest()})\n"
              f"{software_versions()}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (exposed for documentation and tests)."""
    parser = _Parser(prog="brushcore", description=__doc__.splitlines()[0],
                     allow_abbrev=False)
    parser.add_argument("--version", action=_Version, nargs=0,
                        help="show the version, commit and libraries, and exit")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    sim = sub.add_parser("simulate", help="pull one brush off and write its curve (netCDF)",
                         description="Pull one brush off and write its curve (netCDF). "
                                     "Units: E*, dgamma and h in one consistent system "
                                     "(the file states SI).",
                         allow_abbrev=False,
                         formatter_class=_DefaultsShown)
    conv = sub.add_parser(
        "converge", help="gather curve files into a sweep and extrapolate each case run on "
                         "three or more grids to h -> 0",
        description="Gather curve files (brushcore simulate's, on several --grid) into "
                    "DIR/sweep.nc and, for every case run on three or more grids, extrapolate "
                    "F_ad and W to h -> 0 with the observed order: DIR/convergence.nc, .csv, "
                    ".md and .png, as the workflow writes them.",
        allow_abbrev=False, formatter_class=_DefaultsShown)
    conv.add_argument("curves", nargs="+", type=_path, metavar="CURVE",
                      help="curve files (.nc), one per (case, grid)")
    conv.add_argument("--out-dir", type=_path, required=True, metavar="DIR",
                      help="folder for sweep.nc and convergence.* (made if missing)")
    sim.add_argument("--layout", choices=LAYOUTS, required=True, help="pillar layout")
    sim.add_argument("--pillars", type=_integer("a whole number of pillars >= 1"), action=_Given,
                     help="number of pillars N (required, except for --layout file: the "
                          "file's)")
    sim.add_argument("--kbar", type=_kbar, default=None,
                     help=f"spring stiffness k/(E* L), in [{MIN_KBAR:g}, inf]; 'inf' for rigid "
                          "pillars (required, except with --kbar-file: then the file's mean)")
    sim.add_argument("--grid", type=_integer(f"an integer in [{MIN_GRID}, {MAX_GRID}]"),
                     action=_Given,
                     help=f"elements per side n, in [{MIN_GRID}, {MAX_GRID}] (required, except "
                          "for a label map or image: the file's; a pillar table needs it)")
    sim.add_argument("--phi", type=float, default=_default("phi"), action=_Given,
                     help=f"filling factor (0, {MAX_PHI:g}] (--layout file: the file's)")
    sim.add_argument("--seed", type=_integer(f"an integer in [0, {MAX_SEED}]"), default=0,
                     help=f"seed of the random layout and of drawn heights (--roughness) and "
                          f"stiffnesses (--kbar-spread), in [0, {MAX_SEED}]")
    sim.add_argument("--min-gap", type=float, default=_default("min_gap"),
                     help=f"minimum gap between random pillars [elements of the "
                          f"{RANDOM_GAP_GRID} x {RANDOM_GAP_GRID} grid, L/{RANDOM_GAP_GRID}, on "
                          f"every grid], in [1, {RANDOM_GAP_GRID})")
    units = f", in [{UNIT_RANGE[0]:g}, {UNIT_RANGE[1]:g}]"
    sim.add_argument("--e-star", type=float, default=_default("e_star"),
                     help="effective modulus E* [Pa]" + units)
    sim.add_argument("--dgamma", type=float, default=_default("dgamma"),
                     help="work of adhesion [J/m^2]" + units)
    sim.add_argument("--h", type=float, default=_default("h"),
                     help="element size [m]" + units)
    sim.add_argument("--allow-coarse", action="store_true",
                     help="run even if the pillars are under 2 elements in radius or phi "
                          "is realised more than 5 %% off")
    sim.add_argument("--shape", choices=SHAPES, default=_default("shape"),
                     help="pillar cross-section (area phi L^2 / N for every shape)")
    sim.add_argument("--aspect", type=float, default=_default("aspect"),
                     help=f"major / minor axis of --shape ellipse, [1, {MAX_ASPECT:g}]")
    sim.add_argument("--orientation", type=float, default=_default("orientation"),
                     help="angle of the ellipse's major axis or a square's side from the "
                          f"x axis [degrees], in [-{MAX_ORIENTATION:g}, {MAX_ORIENTATION:g}]")
    sim.add_argument("--layout-file", type=_path,
                     help="label map (.npy: -1 no pillar, 0..N-1 pillar) or image (.png: "
                          "dark pillars on white), of the grid's size, or a pillar table "
                          "(.csv: columns x, y, radius in units of L, one pillar a line, "
                          "optionally aspect and orientation for ellipses; "
                          "with --grid) for --layout file")
    rough = sim.add_argument_group(
        "rough, graded and preloaded brushes",
        "Heights in units of d_K = sqrt(2 pi dgamma a0 / E*), forces in F_K = sqrt(8 pi E* "
        "dgamma a0^3), a0 = sqrt(A / pi) of the discretised pillar area A. Any of these runs "
        "an approach from first touch to the preload, then the pull-off. Per-pillar files: "
        "one value per pillar in label order (regular: row-major, first axis slowest; the "
        "curve file lists every pillar's centre), text ('#' comments; one value a line, or "
        "all on one line) or .npy.")
    rough.add_argument("--roughness", type=float, default=_default("roughness"),
                       help=f"standard deviation of Gaussian pillar heights [d_K], in "
                            f"[0, {MAX_ROUGH:g}], drawn from --seed")
    rough.add_argument("--preload", type=float, default=_default("preload"),
                       help=f"compressive force the approach stops at [F_K], in "
                            f"[0, {MAX_ROUGH:g}]")
    rough.add_argument("--kbar-spread", type=float, default=_default("kbar_spread"),
                       help=f"coefficient of variation of a lognormal per-pillar kbar "
                            f"(mean --kbar), in [0, {MAX_KBAR_SPREAD:g}], drawn from --seed")
    rough.add_argument("--heights", type=_path, default=None, metavar="FILE",
                       help=f"pillar heights [d_K] in [-{MAX_ROUGH:g}, {MAX_ROUGH:g}], one per "
                            "pillar")
    rough.add_argument("--kbar-file", type=_path, default=None, metavar="FILE",
                       help=f"pillar kbar in [{MIN_KBAR:g}, inf], one per pillar, in place of "
                            "--kbar; the curve records their mean as its kbar (or --kbar, if "
                            "given); --kbar-factors scales --kbar instead")
    rough.add_argument("--kbar-factors", type=_path, default=None, metavar="FILE",
                       help="pillar stiffness relative to --kbar (finite, > 0), one per "
                            "pillar: pillar p runs kbar * f_p")
    rough.add_argument("--gap-map", type=_path, default=None, metavar="FILE",
                       help="extra gap of every element [d_K], grid x grid (rows y)")
    rough.add_argument("--protocol", default=None, metavar="WAYPOINTS",
                       help="loading-unloading cycles in place of --preload: "
                            + PROTOCOL_SYNTAX + "; the file then holds every retraction's "
                            "F_ad and W (pull_*), and F_ad and W of the last one as its "
                            "adhesive_force and work_of_separation")
    sim.add_argument("--rtol", type=float, default=SolverOptions.rtol,
                     help=f"CG tolerance, in [{SolverOptions.MIN_RTOL:g}, 1e-3]")
    sim.add_argument("--lookahead", type=float, default=SolverOptions.lookahead,
                     help="approximate: detach (rough brushes: also attach) within this relative "
                          "window of the next event, in [0, 0.1] (0 = exact)")
    sim.add_argument("--cascade", choices=("global", "local"), default=SolverOptions.cascade,
                     help="local: per-pillar cascades where a rigorous bound shows they "
                          "do not change the result; global: re-solve after every round "
                          "(reference)")
    sim.add_argument("--no-symmetry", dest="symmetry", action="store_false",
                     help="solve mirror-symmetric brushes on the whole grid, not one quadrant")
    sim.add_argument("--precision", choices=("auto", "mixed", "double"),
                     default=SolverOptions.precision,
                     help="FFT precision on the CPU: mixed = single-precision transforms, "
                          "the rest double (needs --rtol >= 1e-6; it moves a solution by up "
                          "to ~1.5e-5 of its peak stress, enough to reorder soft random "
                          "pillars); auto = mixed for random layouts at --rtol >= 1e-6, "
                          "else double; both run double in units float32 cannot hold "
                          "(stress, displacement scale or --h beyond 1e+-15)")
    sim.add_argument("--fft-library", choices=("auto", "fftw", "mkl"),
                     default=SolverOptions.fft_library,
                     help="whose FFTs the whole grid runs on: mkl needs "
                          "pip install 'brushcore[mkl]' (faster on Intel CPUs); "
                          "auto = the faster of the two on this machine, timed "
                          "once per grid, thread count and precision; a mirror-symmetric "
                          "brush's quadrant runs FFTW's DCTs whatever this says (the "
                          "curve records fft_library_used)")
    sim.add_argument("--no-early-decisions", dest="early_decisions", action="store_false",
                     help="run every cascade round's CG to the tolerance")
    sim.add_argument("--no-settle-decisions", dest="settle_decisions", action="store_false",
                     help="stop CG at the tolerance even where an element lies within its "
                          "error of sigma_c or of the next event's cut")
    sim.add_argument("--threads", type=_integer(f"an integer in [1, {MAX_THREADS}]"), default=None,
                     help="threads of the FFTs, BLAS and the preconditioners' stacked "
                          f"inverses, in [1, {MAX_THREADS}] (default: the environment's "
                          "BRUSHCORE_THREADS, else 1)")
    sim.add_argument("--backend", choices=USER_BACKENDS, default="cpu",
                     help="where to solve: cpu (NumPy) or gpu (CuPy, needs "
                          "pip install 'brushcore[gpu]' and a CUDA card (12.x wheels; see "
                          "the README); whole grid, no symmetry fold)")
    sim.add_argument("--out", type=_output, required=True, help="output netCDF file")
    sim.add_argument("--quiet", action="store_true", help="no progress on stderr")
    return parser


class _Progress:
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


def _cli_warning(message: Warning | str, *args: object, **kwargs: object) -> str:
    """A warning as the command prints it: one that opens with a parameter's
    name and a file ("heights FILE: ...", the input readers' form) names its
    flag; any other text is left as it is."""
    text = str(message)
    found = re.match(r"(\w+)( \S+:)", text)
    if found and found[1] in FLAGS:
        text = FLAGS[found[1]] + text[len(found[1]):]
    return f"brushcore: warning: {text}\n"


def _error(message: str, progress: _Progress | None = None) -> None:
    if progress is not None:
        progress.end_line()
    print(f"brushcore: error: {message}", file=sys.stderr)


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


def _simulate(args: argparse.Namespace) -> int:
    from brushcore.model.cost import cost_note, memory_note
    from brushcore.model.curve import (FirstTouchWarning, check_protocol_preload,
                                       preload_contact, simulate)
    from brushcore.data.io import check_output_path, remove_stale_temporaries, write_curve
    from brushcore.model.layout import build_labels, pillars_differ, smallest_radius_elements
    from brushcore.model.inputs import (INPUT_FILES, parse_protocol, recorded_kbar,
                                        with_input_files)
    from brushcore.model.pillar_table import is_table
    from brushcore.numerics.platform.threads import fft_threads, pin_threads

    progress = None if args.quiet else _Progress()
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
        options = SolverOptions(rtol=args.rtol, lookahead=args.lookahead, cascade=args.cascade,
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
                _error(f"cannot write {args.out}: {exc.strerror or exc}; nothing written",
                       progress)
                return 1
            # what a run killed (kill -9, a node's crash) while writing --out left
            remove_stale_temporaries(args.out, older_than=started)
        finally:
            on_sigterm(previous)
    except ParameterError as exc:
        _error(exc.in_terms_of(FLAGS, sep=" "), progress)
        return 2
    except _Missing as exc:
        _error(str(exc), progress)
        return 2
    except (ConvergenceError, SolverError) as exc:
        _error(f"solver failed: {exc}", progress)
        return 1
    except MemoryError:  # what memory_note could only warn of
        where = f" at --grid {args.grid}" if args.grid else ""  # else a label map's own
        _error(f"out of memory{where}: a smaller grid, or a machine with more memory; "
               "nothing written", progress)
        return 1
    except KeyboardInterrupt:
        _error(INTERRUPTED, progress)
        return EXIT_INTERRUPTED
    except Terminated:
        _error(TERMINATED, progress)
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


def _converge(args: argparse.Namespace) -> int:
    from brushcore.data.aggregate import (GRID_DIM, AggregationError, build_sweep,
                                          mixed_runs, write_sweep)
    from brushcore.data.convergence_report import write_study

    out = args.out_dir
    if out.exists() and not out.is_dir():
        _error(f"--out-dir {out} is a file: allowed a folder (made if missing)")
        return 2
    missing = [f"{p} (a folder)" if p.is_dir() else str(p) for p in args.curves
               if not p.is_file()]
    if missing:  # a path typed wrong: nothing to run again
        _error(f"no such curve file{'s' if len(missing) > 1 else ''}: {', '.join(missing[:10])}"
               + (f" and {len(missing) - 10} more" if len(missing) > 10 else "")
               + ": allowed the .nc files brushcore simulate wrote")
        return 2
    try:
        # no snapshots: a study reads scalars (small sets kept them all before)
        sweep = build_sweep(args.curves, keep_snapshots=(), all_snapshots_below_mb=0.0)
    except AggregationError as exc:
        _error(str(exc))
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
        _error(f"{what}; written: {', '.join(f.name for f in done) or 'nothing'}"
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


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``brushcore`` command."""
    # Warnings read as the errors do: one line, no source line of brushcore's.
    previous = warnings.formatwarning
    warnings.formatwarning = _cli_warning
    try:
        args = build_parser().parse_args(argv)
        if args.command == "simulate":
            return _simulate(args)
        if args.command == "converge":
            return _converge(args)
    except KeyboardInterrupt:  # during start-up (imports, parsing)
        _error(INTERRUPTED)
        return EXIT_INTERRUPTED
    finally:
        warnings.formatwarning = previous
    return 2  # pragma: no cover - argparse enforces the sub-command


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
