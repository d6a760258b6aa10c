"""Reading per-pillar values and gap maps that users hand in, as data only.

Text files hold numbers separated by white space or commas, '#' starts a
comment; ``.npy`` files are read with ``allow_pickle=False``.  Whatever does
not fit (wrong count or shape, NaN or inf, a non-positive stiffness, text
that is no number) is refused with a `ParameterError` naming the file and
the line (or the entry of a ``.npy`` array), before any computation.
"""

from __future__ import annotations

import dataclasses
import math
import re
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from brushcore.model.params import MAX_ROUGH, MIN_KBAR, BrushParams
from brushcore.numerics.events.waypoints import KINDS, Waypoint
from brushcore.validation import ParameterError


#: A number as a text file writes it: ASCII digits, optional sign, point and
#: exponent, or inf/nan (refused later by value).  Python's float() also takes
#: "1_0" (10) and other scripts' digits, which a data file must not mean.
_NUMBER = re.compile(r"[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|inf(?:inity)?|nan)",
                     re.IGNORECASE | re.ASCII)


def _is_npy(path: Path) -> bool:
    return path.suffix.lower() == ".npy"


#: Said where a count is off and a comma stands between digits: "0,5" is
#: read as two values (commas separate values), not as 0.5.
_COMMA_HINT = "; commas separate values: write decimals with a point"


def _rows(path: Path, name: str) -> tuple[list[tuple[int, list[float]]], str]:
    """(line number, values) of every non-empty line of a text file, and
    `_COMMA_HINT` where a comma stands between digits ("" otherwise)."""
    _, rows, hint = table_rows(path, name, header=False)
    return rows, hint


def header_names(number: int, line: str) -> tuple[int, list[str]]:
    """(line number, column names) of a header line: commas separate names,
    an empty one too (an index column's; a trailing comma adds none), else
    white space; quotes around a name are a spreadsheet's, not the name's."""
    pieces = line.split(",")
    while len(pieces) > 1 and not pieces[-1].strip():
        pieces.pop()
    # white space inside a comma's piece separates names too ("x y,radius")
    names = [name for piece in pieces for name in (piece.split() or [""])]
    return number, [name.strip("'\"") for name in names]


def table_rows(path: Path, name: str, header: bool = True, comma_warning: bool = True
               ) -> tuple[tuple[int, list[str]] | None, list[tuple[int, list[float]]], str]:
    """A text file's lines as `_rows` reads them, after a header line.

    ``comma_warning`` False: no warning for "0,5" without a decimal point
    anywhere (a CSV table of integers separates its values with commas).

    Returns
    -------
    ((line number, column names) of the first non-empty line, or None where
    it holds numbers only or ``header`` is False; the rows of numbers after
    it; `_COMMA_HINT` or "").
    """
    try:
        text = path.read_text(encoding="utf-8-sig")  # a BOM is no character of line 1
    except (OSError, UnicodeDecodeError) as exc:
        raise ParameterError(name, str(path), "a readable text or .npy file",
                             unreadable(exc)) from None
    names, rows, hint, points = None, [], "", False
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.split("#", 1)[0]
        tokens = line.replace(",", " ").split()
        if header and tokens and not rows and names is None \
                and not all(_NUMBER.fullmatch(token) for token in tokens):
            names = header_names(number, line)
            continue
        # a number's exponent is no decimal comma's sign: "25e-2,5e-1" is plain
        points = points or "." in line or bool(re.search(r"\d[eE][+-]?\d", line)
                                               and not re.search(r"\d,\d+[eE]", line))
        if re.search(r"\d,\d", line) and not hint:
            hint, first = _COMMA_HINT, (number, line.strip())
        if not tokens:
            continue
        values = []
        for token in tokens:
            if not _NUMBER.fullmatch(token):
                semicolons = "" if ";" not in token else (
                    "; semicolons between values and decimal commas, as a spreadsheet in "
                    "some locales writes: save with decimal points and commas" if "," in line
                    else "; semicolons between values: separate them with commas or spaces")
                raise ParameterError(name, str(path), "numbers only",
                                     f"line {number}: {token!r} is not a number{semicolons}")
            values.append(float(token))
        rows.append((number, values))
    if hint and points:  # decimal points and commas between values: a plain CSV
        hint = ""
    elif hint and comma_warning:  # "0,5" and not one decimal point: decimal commas, likely
        warnings.warn(f"{name} {path}: line {first[0]} {first[1]!r} is read as values "
                      "that commas separate, and the file has no decimal point; if those "
                      "are decimal commas, write decimals with a point")
    return names, rows, hint


#: What each kind of per-pillar value may be (`read_pillar_values`'s ``kind``).
VALUE_RANGES = {"finite": "finite numbers",
                "stiffness": f"stiffness values in [{MIN_KBAR:g}, inf]",
                "factor": "finite factors > 0"}


def _check_values(path: Path, name: str, where: str, values, kind: str) -> None:
    """Refuse NaN and inf (stiffness: inf is rigid), stiffness below
    `MIN_KBAR` and factors <= 0."""
    allowed = VALUE_RANGES[kind]
    for value in values:
        rigid = kind == "stiffness" and value == math.inf
        if math.isnan(value) or (math.isinf(value) and not rigid) \
                or (kind == "stiffness" and value < MIN_KBAR) \
                or (kind == "factor" and value <= 0):
            raise ParameterError(name, str(path), allowed, f"{where} holds {value!r}")


def read_pillar_values(path: str | Path, n_pillars: int, name: str,
                       kind: str = "finite") -> np.ndarray:
    """One value per pillar (label order) from a text or .npy file.

    Parameters
    ----------
    path : the file
    n_pillars : the count expected
    name : the parameter it sets (for messages: "heights", "kbar_values")
    kind : what the values may be (`VALUE_RANGES`): "finite", "stiffness"
        ([MIN_KBAR, inf]) or "factor" (finite, > 0)
    """
    path = Path(path)
    if _is_npy(path):
        arr = _load_npy(path, name)
        if arr.ndim == 2 and 1 in arr.shape:  # a column or a row: one value a pillar all the same
            arr = arr.ravel()
        if arr.ndim != 1 or arr.size != n_pillars:
            raise ParameterError(name, str(path), f"{n_pillars} values, one per pillar",
                                 f"it holds an array of shape {arr.shape}")
        for i, value in enumerate(arr):
            _check_values(path, name, f"entry {i}", [float(value)], kind)
        return arr.astype(float)
    rows, comma_hint = _rows(path, name)
    wide = [(number, row) for number, row in rows if len(row) > 1]
    if len(rows) > 1 and wide:  # a table (label and value?) would pass for a list of values
        number, row = wide[0]
        raise ParameterError(name, str(path), f"{n_pillars} values, one per line (or all on "
                             "one line)", f"line {number} holds {len(row)} values"
                             + (comma_hint or ": a file of columns, e.g. labels beside the "
                                "values, gives the values alone"))
    values, lines = [], []
    for number, row in rows:
        _check_values(path, name, f"line {number}", row, kind)
        values.extend(row)
        lines.extend([number] * len(row))
    if len(values) != n_pillars:
        extra = f"; the first too many, value {n_pillars + 1}, is on line {lines[n_pillars]}" \
            if len(values) > n_pillars else ""
        raise ParameterError(name, str(path), f"{n_pillars} values, one per pillar",
                             f"it holds {len(values)} values{extra}{comma_hint}")
    return np.array(values)


def read_gap_map(path: str | Path, grid: int, name: str = "gap_map") -> np.ndarray:
    """An n x n map (row y, column x) from a text file of n lines or a .npy array."""
    path = Path(path)
    if _is_npy(path):
        arr = _load_npy(path, name)
        if arr.shape != (grid, grid):
            raise ParameterError(name, str(path), f"an array of shape ({grid}, {grid})",
                                 f"it has shape {arr.shape}")
        bad = np.argwhere(~np.isfinite(arr))
        if bad.size:
            raise ParameterError(name, str(path), "finite numbers",
                                 f"element (y, x) = {tuple(int(i) for i in bad[0])} holds "
                                 f"{float(arr[tuple(bad[0])])!r}")
        return arr.astype(float)
    rows, comma_hint = _rows(path, name)
    for number, row in rows:
        if len(row) != grid:
            raise ParameterError(name, str(path), f"{grid} lines of {grid} numbers",
                                 f"line {number} holds {len(row)} numbers{comma_hint}")
        for column, value in enumerate(row, start=1):
            _check_values(path, name, f"line {number}, column {column},", [value],
                          "finite")
    if len(rows) != grid:
        raise ParameterError(name, str(path), f"{grid} lines of {grid} numbers",
                             f"it holds {len(rows)} lines of numbers")
    return np.array([row for _, row in rows])


def recorded_kbar(kbar_values: np.ndarray) -> float | None:
    """The kbar a brush given every pillar's kbar records: their mean [-],
    as a lognormal draw's mean is its kbar (inf where every pillar is
    rigid); None where rigid and finite pillars mix, whose mean (inf) would
    file the brush as rigid: its kbar must then be given."""
    values = np.asarray(kbar_values, dtype=float)
    rigid = np.isinf(values)
    return None if rigid.any() and not rigid.all() else float(values.mean())


#: Per-pillar and per-element input files, by the name a caller gives them
#: (the CLI's flags, the workflow's `layout_files` keys), and the
#: `BrushParams` field each sets; a refusal is named by that field, but for
#: factors, which are not the field's values.
INPUT_FILES = {"heights": "heights", "kbar_file": "kbar_values",
               "kbar_factors": "kbar_values", "gap_map": "gap_map"}


def with_input_files(base: BrushParams,
                     files: Mapping[str, str | Path | None]) -> BrushParams:
    """``base`` with the arrays that per-pillar and per-element files hold.

    Parameters
    ----------
    base : the brush without them; its N and grid are what the files must fit
    files : path by name (`INPUT_FILES`; None or absent: not given):

        heights : pillar heights [d_K], one per pillar (label order)
        kbar_file : each pillar's kbar, in [MIN_KBAR, inf]
        kbar_factors : each pillar's stiffness relative to ``base.kbar``
            (finite, > 0): pillar p runs kbar * f_p, so that a sweep over kbar
            keeps the brush's proportions; rigid brushes (kbar = inf) stay rigid
            (every pillar's kbar inf: still a brush given stiffnesses)
        gap_map : extra gap of every element [d_K], grid x grid (rows y)

    Raises
    ------
    ParameterError
        Named as `INPUT_FILES` names the file, with its path as the value,
        where a file does not fit or a value it gives falls out of range.
    """
    if not isinstance(files, Mapping):  # a bare path: which file is it?
        raise ParameterError("files", str(files), f"a mapping of {sorted(INPUT_FILES)} to paths",
                             f"a {type(files).__name__}, not a mapping")
    given = {name: path for name, path in files.items() if path is not None}
    unknown = sorted(set(given) - set(INPUT_FILES))
    if unknown:  # kbar_values is the field a kbar_file sets: the likely slip
        hint = "; kbar_file gives kbar_values" if "kbar_values" in unknown else ""
        raise ParameterError("files", unknown, f"keys among {sorted(INPUT_FILES)}",
                             f"unknown key{'s' * (len(unknown) > 1)}{hint}")
    if "kbar_file" in given and "kbar_factors" in given:
        raise ParameterError("kbar_factors", str(given["kbar_factors"]),
                             "no kbar_file beside it (the two are exclusive)")
    n = base.n_pillars
    arrays = {}
    if "heights" in given:
        arrays["heights"] = read_pillar_values(given["heights"], n, "heights")
    if "kbar_file" in given:
        arrays["kbar_values"] = read_pillar_values(given["kbar_file"], n, "kbar_values",
                                                   "stiffness")
    if "kbar_factors" in given:
        factors = read_pillar_values(given["kbar_factors"], n, "kbar_factors", "factor")
        arrays["kbar_values"] = base.kbar * factors  # rigid (kbar inf) stays rigid: inf
        if math.isfinite(base.kbar):
            low = np.flatnonzero(arrays["kbar_values"] < MIN_KBAR)
            if low.size:
                i = int(low[0])
                raise ParameterError(
                    "kbar_factors", str(given["kbar_factors"]),
                    f"factors whose products with kbar = {base.kbar:g} lie in "
                    f"[{MIN_KBAR:g}, inf]",
                    f"pillar {i}: factor {factors[i]:g} makes it {arrays['kbar_values'][i]:.3g}")
    if "gap_map" in given:
        arrays["gap_map"] = read_gap_map(given["gap_map"], base.grid)
    for name in ("heights", "gap_map"):
        if name in arrays:
            _unit_hint(name, given[name], arrays[name])
    source = {INPUT_FILES[name]: (name, path) for name, path in given.items()}
    try:
        return dataclasses.replace(base, **arrays) if arrays else base
    except ParameterError as exc:  # a value out of range: name the file it came from
        if exc.name == "kbar_spread" and "kbar_factors" in given:
            raise ParameterError(exc.name, exc.value, "0 beside kbar_factors (the two "
                                 "are exclusive)") from None
        if exc.name not in source:
            raise
        name, path = source[exc.name]
        raise ParameterError(exc.name if name != "kbar_factors" else name, str(path),
                             exc.allowed, exc.reason) from None


#: Heights and gaps all under this [d_K] change nothing a run can resolve:
#: most likely lengths in metres (a micron is 1e-6) where d_K was meant.
NEGLIGIBLE_OFFSET = 1e-4


def _unit_hint(name: str, path: str | Path, values: np.ndarray) -> None:
    """Warn where every height or gap in a file is nonzero but under
    `NEGLIGIBLE_OFFSET` d_K: the file was likely written in metres (a
    measured brush's 2e-6 m read as 2e-6 d_K: a brush a millionth of its
    critical displacement from flat, run without a word)."""
    largest = float(np.max(np.abs(values))) if values.size else 0.0
    if 0.0 < largest < NEGLIGIBLE_OFFSET:
        warnings.warn(f"{name} {path}: every value is under {NEGLIGIBLE_OFFSET:g} d_K (the "
                      f"largest {largest:.3g}); they are read in units of d_K = sqrt(2 pi "
                      "dgamma a0 / E*), the brush's critical displacement: lengths in metres "
                      "must be divided by d_K (the curve file's displacement_unit_d_K, in "
                      "the run's units)", stacklevel=2)


def unreadable(exc: Exception) -> str:
    """Why a file could not be read, in words (not "FileNotFoundError: [Errno 2]")."""
    if isinstance(exc, FileNotFoundError):
        return "no such file"
    if isinstance(exc, IsADirectoryError):
        return "a folder"
    if isinstance(exc, PermissionError):
        return "permission denied"
    if isinstance(exc, UnicodeDecodeError):
        return f"not UTF-8 text (byte {exc.start})"
    return str(getattr(exc, "strerror", None) or exc) or type(exc).__name__


def npy_problem(exc: Exception) -> str:
    """What `np.load(..., allow_pickle=False)` found wrong, without NumPy's
    advice to load pickles unsafely (never right for an input file)."""
    if isinstance(exc, OSError):
        return unreadable(exc)
    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    if "allow_pickle" in text or "pickled" in text:
        return "it holds Python objects or is not a .npy file"
    return text if len(text) <= 120 else text[:117].rsplit(" ", 1)[0] + " ..."


def _load_npy(path: Path, name: str) -> np.ndarray:
    try:
        arr = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:  # EOFError: an empty file
        raise ParameterError(name, str(path), "a readable .npy file of numbers "
                             "(no pickles)", npy_problem(exc)) from None
    if not isinstance(arr, np.ndarray):  # np.load opens a .npz whatever its name
        raise ParameterError(name, str(path), "a .npy file of numbers",
                             f"it is a {type(arr).__name__} archive, not one array")
    if not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise ParameterError(name, str(path), "real numbers", f"its dtype is {arr.dtype}")
    return np.asarray(arr, dtype=float)


#: How a protocol is written on a command line or in a config file.
PROTOCOL_SYNTAX = ("waypoints separated by commas, each 'force:F' (total force F in F_K, "
                   "tensile positive, so a preload P is force:-P), 'displacement:D' (d in d_K, "
                   "absolute: 0 where a pillar of height 0 touches, larger pulls away) "
                   "or 'separation', e.g. 'force:-1, displacement:0.5, force:-1, separation'")


#: The loads a protocol may ask for: the preload's range (its CG tolerance shrinks with the load).
PROTOCOL_LOADS = f"force waypoints in [-{MAX_ROUGH:g}, {MAX_ROUGH:g}] F_K (the preload's range)"


def load_beyond_range(protocol: Sequence[Waypoint]) -> str:
    """Why a normalised protocol asks for too large a load ("" if it does not)."""
    for k, leg in enumerate(protocol):
        if leg.kind == "force" and not abs(leg.value) <= MAX_ROUGH:
            return f"waypoint {k} is a force of {leg.value:g} F_K"
    return ""


def protocol_text(protocol: Sequence[Waypoint]) -> str:
    """The text form `parse_protocol` reads, of normalised waypoints (exact reprs)."""
    return ", ".join(w.kind if w.kind == "separation" else f"{w.kind}:{w.value!r}"
                     for w in protocol)


def parse_protocol(text: str, name: str = "protocol") -> tuple[Waypoint, ...]:
    """Waypoints from their text form, normalised values (F_K, d_K) as given.

    ``"force:-1, displacement:0.5, force:-1, separation"`` presses to 1 F_K,
    retracts to d = 0.5 d_K, presses again and pulls off: two loading cycles.
    Refused with a `ParameterError` naming ``name`` and the waypoint: an
    empty list, an unknown kind, a missing or extra value, text that is no
    finite number, a load beyond `PROTOCOL_LOADS`.
    """
    items = [item.strip() for item in str(text).split(",")]
    if not any(items):
        raise ParameterError(name, text, PROTOCOL_SYNTAX, "it holds no waypoint")
    waypoints = []
    for k, item in enumerate(items):
        kind, colon, value = (part.strip() for part in item.partition(":"))
        kind = kind.lower()  # "Force:-1" means force:-1
        where = f"waypoint {k} ({item!r})"
        hint = ("; a colon joins a kind and its value (force:-1)" if "=" in item else
                "; commas separate waypoints" if ";" in item else "")
        if kind not in KINDS:
            raise ParameterError(name, text, PROTOCOL_SYNTAX,
                                 f"{where} is of no kind in {KINDS}{hint}")
        if kind == "separation":
            if colon:
                raise ParameterError(name, text, PROTOCOL_SYNTAX, f"{where} takes no value")
            waypoints.append(Waypoint(kind))
            continue
        if not _NUMBER.fullmatch(value) or not math.isfinite(float(value)):
            raise ParameterError(name, text, PROTOCOL_SYNTAX,
                                 f"{where} needs a finite number after '{kind}:'{hint}")
        waypoints.append(Waypoint(kind, float(value)))
    beyond = load_beyond_range(waypoints)
    if beyond:
        raise ParameterError(name, text, PROTOCOL_LOADS, beyond)
    return tuple(waypoints)
