"""The command line's parser: its flags, their readers, help and one-line errors.

Conventions: no abbreviated flags, unknown flags named (with the closest
known one), defaults shown in ``--help``, a value's error naming its
flag and allowed range.
"""

from __future__ import annotations

import argparse
import difflib
import math
import re
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

from brushcore.model.inputs import PROTOCOL_SYNTAX
from brushcore.model.params import (LAYOUTS, MAX_ASPECT, MAX_GRID, MAX_KBAR_SPREAD,
                                    MAX_ORIENTATION, MAX_PHI, MAX_ROUGH, MAX_SEED, MIN_GRID,
                                    MIN_KBAR, RANDOM_GAP_GRID, UNIT_RANGE, BrushParams)
from brushcore.model.provenance import version
from brushcore.model.shapes import SHAPES
from brushcore.numerics.options import (CASCADES, FFT_LIBRARIES, PRECISIONS, SolverOptions,
                                        short_float)
from brushcore.numerics.platform.backend import USER_BACKENDS
from brushcore.numerics.platform.threads import MAX_THREADS
from brushcore.validation import overflows

#: The command's one-line description (``brushcore --help``).
DESCRIPTION = "Command line: ``brushcore simulate`` writes a curve, ``converge`` extrapolates."

#: API parameter -> the flag that sets it, for error messages.
FLAGS = {"n_pillars": "--pillars", "kbar": "--kbar", "grid": "--grid", "phi": "--phi",
         "seed": "--seed", "min_gap": "--min-gap", "e_star": "--e-star",
         "dgamma": "--dgamma", "h": "--h", "layout": "--layout", "rtol": "--rtol",
         "max_iter": "--max-iter", "tie_rtol": "--tie-rtol",
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


#: The solver's options that choose among words (`build_parser`): flag,
#: choices and help; the default is `SolverOptions`' field of the flag's name.
_CHOICE_OPTIONS = (
    ("--cascade", CASCADES,
     "local: per-pillar cascades where a rigorous bound shows they do not change the result; "
     "global: re-solve after every round (reference)"),
    ("--precision", PRECISIONS,
     "FFT precision on the CPU: mixed = single-precision transforms, the rest double (needs "
     "--rtol >= 1e-6; it moves a solution by up to ~1.5e-5 of its peak stress, enough to "
     "reorder soft random pillars); auto = mixed for random layouts at --rtol >= 1e-6, else "
     "double; both run double in units float32 cannot hold (stress, displacement scale or "
     "--h beyond 1e+-15)"),
    ("--fft-library", FFT_LIBRARIES,
     "whose FFTs the whole grid runs on: mkl needs pip install 'brushcore[mkl]' (faster on "
     "Intel CPUs); auto = the faster of the two on this machine, timed once per grid, thread "
     "count and precision; a mirror-symmetric brush's quadrant runs FFTW's DCTs whatever "
     "this says (the curve records fft_library_used)"),
)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (exposed for documentation and tests)."""
    parser = _Parser(prog="brushcore", description=DESCRIPTION,
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
    sim.add_argument("--max-iter", type=_integer("an integer >= 1"),
                     default=SolverOptions.max_iter,
                     help="CG iterations a solve may take before the run stops, an integer >= 1")
    sim.add_argument("--tie-rtol", type=float, default=SolverOptions.tie_rtol,
                     help="elements whose stress lies within this relative distance of the "
                          "critical stress detach together, as ties (mirror images stay "
                          f"symmetric), in [0, {short_float(SolverOptions.MAX_TIE_RTOL)}]")
    sim.add_argument("--lookahead", type=float, default=SolverOptions.lookahead,
                     help="approximate: detach (rough brushes: also attach) within this relative "
                          "window of the next event, in [0, 0.1] (0 = exact)")
    # the solver's options that choose among words: flag, choices, help
    for flag, choices, text in _CHOICE_OPTIONS:
        sim.add_argument(flag, choices=choices,
                         default=getattr(SolverOptions, flag[2:].replace("-", "_")), help=text)
    sim.add_argument("--no-symmetry", dest="symmetry", action="store_false",
                     help="solve mirror-symmetric brushes on the whole grid, not one quadrant")
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
