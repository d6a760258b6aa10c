"""Layouts given as a table of disc pillars, drawn on any grid.

A label map or image fits one grid; a lab's array is usually known as a
list of pillars (a mask design, a micrograph's fitted circles).  A pillar
table is a ``.csv`` text file: a header naming the columns ``x``, ``y``
and ``radius`` (any order), then one pillar a line, in label order (the
first pillar is pillar 0), every value in units of the square's side L:
centres inside (0, 1), x along the grid's second axis and y along its
first (a label map's row index is y), discs inside the square and apart.
'#' starts a comment; commas or white space separate values.

The same table runs on every grid, so its brush can be refined like a
generated one (its phi is the discs' own, pi sum r^2, on every grid), and
per-pillar inputs (heights, stiffness) follow its rows.  An element belongs
to a pillar when its centre lies in the disc, as generated layouts are
drawn (`brushcore.model.layout.table_labels`): a table written from a
generated disc layout (`save_pillar_table`) draws the same label map.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from brushcore.model.inputs import header_names, table_rows
from brushcore.validation import ParameterError

SUFFIX = ".csv"
COLUMNS = ("x", "y", "radius")
_NAME = "layout_file"
#: The most pillars a table may hold (a brush of 2304 pillars is the paper's largest).
MAX_PILLARS = 1_000_000


def is_table(path: str | Path) -> bool:
    """Whether a layout file is a pillar table (by its suffix)."""
    return Path(path).suffix.lower() == SUFFIX


@dataclass(frozen=True)
class PillarTable:
    """The disc pillars of a table, in label order.

    Attributes
    ----------
    centres : (N, 2) pillar centres (y, x) [L]
    radii : (N,) pillar radii [L]
    """

    centres: np.ndarray
    radii: np.ndarray

    @property
    def n_pillars(self) -> int:
        """Pillar count N."""
        return int(self.radii.size)

    @property
    def phi(self) -> float:
        """Filling factor pi sum r^2 (of the discs, not of any grid's elements)."""
        return float(math.pi * np.sum(self.radii**2))


def _refuse(path: Path, allowed: str, reason: str) -> ParameterError:
    return ParameterError(_NAME, str(path), allowed, reason)


#: Unknown columns that look like per-pillar values, which have files of their own.
_VALUES = ("height", "kbar", "k", "stiff", "factor")


def _columns(path: Path, names: list[str], number: int) -> list[int]:
    """Positions of x, y and radius in the header line ``names``."""
    lowered = [name.lower() for name in names]
    if "" in lowered:
        raise _refuse(path, "a header line naming the columns x, y and radius [L]",
                      f"line {number}: column {lowered.index('') + 1} has no name (an index "
                      "column? leave it out)")
    unknown = [n for n in lowered if n not in COLUMNS]
    missing = [c for c in COLUMNS if c not in lowered]
    twice = sorted({n for n in lowered if lowered.count(n) > 1})
    if unknown or missing or twice:
        what = (f"unknown column {unknown[0]!r}" if unknown else
                f"column {twice[0]!r} given twice" if twice else f"no column {missing[0]!r}")
        more = (" (heights and stiffness go in their own files, one value per pillar "
                "in the table's order)" if unknown and unknown[0].startswith(_VALUES) else "")
        raise _refuse(path, "a header line naming the columns x, y and radius [L]",
                      f"line {number}: {what}{more}")
    return [lowered.index(c) for c in COLUMNS]


@functools.lru_cache(maxsize=16)
def _read_cached(path: str, mtime_ns: int, size: int) -> PillarTable:
    return _read(Path(path))


def read_pillar_table(path: str | Path) -> PillarTable:
    """The checked pillars of a table (see the module notes).

    Raises
    ------
    ParameterError
        For ``layout_file``, naming the file and the line: no header or
        an unknown, missing or repeated column, a row of another length,
        a value that is not a finite number, a radius <= 0, a disc that
        reaches beyond the square, two discs that overlap or touch, a
        filling factor above 0.5.
    """
    path = Path(path)
    if not path.is_file():
        raise _refuse(path, "an existing, readable file",
                      "a folder" if path.is_dir() else "no such file")
    stat = path.stat()
    return _read_cached(str(path), stat.st_mtime_ns, stat.st_size)


def _commented_header(path: Path) -> tuple[int, list[str]] | None:
    """A header written as a comment before the first row, as
    ``np.savetxt(..., header="x,y,radius")`` writes it, where it names exactly
    the table's columns (any other comment stays a comment)."""
    for number, line in enumerate(path.read_text(encoding="utf-8-sig").splitlines(), 1):
        text, _, comment = line.partition("#")
        if text.strip():
            return None  # the first row: no header before it
        found = header_names(number, comment.strip())
        if sorted(n.lower() for n in found[1]) == sorted(COLUMNS):
            return found
    return None


def _read(path: Path) -> PillarTable:
    # a table's commas separate its columns; an integer table fails the range check
    header, rows, comma_hint = table_rows(path, _NAME, comma_warning=False)
    header = header or (_commented_header(path) if rows else None)
    if header is None:
        raise _refuse(path, "a header line naming the columns x, y and radius [L]",
                      "its first line holds numbers" if rows else "it holds no pillar")
    order = _columns(path, header[1], header[0])
    if not rows:
        raise _refuse(path, "one pillar a line after the header", "it holds no pillar")
    if len(rows) > MAX_PILLARS:
        raise _refuse(path, f"at most {MAX_PILLARS} pillars", f"it holds {len(rows)}")
    for number, row in rows:
        if len(row) != len(COLUMNS):
            raise _refuse(path, "three values a line: x, y and radius [L]",
                          f"line {number} holds {len(row)} values{comma_hint}")
    lines = np.array([number for number, _ in rows])
    data = np.array([[row[i] for i in order] for _, row in rows])
    x, y, r = data.T
    for column, values in zip(COLUMNS, data.T):
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise _refuse(path, "finite numbers",
                          f"line {lines[bad[0]]}: {column} = {float(values[bad[0]])!r}")
    bad = np.flatnonzero(r <= 0)
    if bad.size:
        raise _refuse(path, "radii > 0 [L]",
                      f"line {lines[bad[0]]}: radius = {float(r[bad[0]])!r}")
    outside = np.flatnonzero((x - r < 0) | (y - r < 0) | (x + r > 1) | (y + r > 1))
    if outside.size:
        i = outside[0]
        # every radius beyond L: lengths in another unit (um, elements), likely
        units = ("; every radius exceeds 1: write lengths in units of L (divide by the "
                 "square's side)" if np.all(r > 1) else "")
        raise _refuse(path, "discs inside the square: r <= x <= 1 - r and r <= y <= 1 - r, "
                      "in units of its side L",
                      f"line {lines[i]}: x = {float(x[i])!r}, y = {float(y[i])!r}, "
                      f"radius = {float(r[i])!r}{units}")
    centres = np.column_stack([y, x])
    _check_apart(path, lines, centres, r)
    for array in (centres, r):  # a cached reading: what callers get must not be changed
        array.setflags(write=False)
    table = PillarTable(centres, r)
    if table.phi > 0.5 * (1.0 + 1e-12):  # a generated brush at 0.5 sums to 0.5000000000000001
        raise _refuse(path, "discs covering at most half the square (phi <= 0.5)",
                      f"pi sum r^2 = {table.phi:.4g}")
    return table


def _check_apart(path: Path, lines: np.ndarray, centres: np.ndarray, r: np.ndarray) -> None:
    """Refuse two discs that overlap or touch (no closer than the sum of their
    radii: tangent discs share element edges on every grid)."""
    # Each disc looks for the discs no larger than itself within twice its own
    # radius (d <= r_p + r_q <= 2 r_p): one large disc among many small ones
    # costs its own neighbourhood, not every pair within twice the largest.
    # (a hair wider: the tree's rounding of an exactly tangent pair's distance
    # is not np.hypot's, which judges below)
    near = cKDTree(centres).query_ball_point(centres, 2.0 * r * (1.0 + 1e-9),
                                             return_sorted=False)
    counts = np.fromiter(map(len, near), dtype=np.int64, count=len(near))
    p = np.repeat(np.arange(len(near)), counts)
    q = np.fromiter((j for found in near for j in found), dtype=np.int64, count=int(counts.sum()))
    keep = (p != q) & ((r[q] < r[p]) | ((r[q] == r[p]) & (q > p)))
    p, q = p[keep], q[keep]
    if not p.size:
        return
    distance = np.hypot(*(centres[p] - centres[q]).T)
    overlap = np.flatnonzero(distance <= r[p] + r[q])  # touching: no grid parts them
    if overlap.size:
        i = overlap[np.lexsort((q[overlap], p[overlap]))[0]]
        a, b = sorted((int(p[i]), int(q[i])))
        raise _refuse(path, "discs that neither overlap nor touch (centres farther apart "
                      "than the sum of the radii)",
                      f"the pillars of lines {lines[a]} and {lines[b]} (pillars {a} and {b}) "
                      f"are {distance[i]:.6g} apart, radii {r[a]:.6g} + {r[b]:.6g}")


def save_pillar_table(table: PillarTable, path: str | Path) -> Path:
    """Write a pillar table, readable by `read_pillar_table`.

    Parameters
    ----------
    table : the pillars (`brushcore.model.layout.generated_table` gives a
        generated layout's)
    path : the ``.csv`` file to write (the suffix is added if missing)

    Returns
    -------
    The path written.  Values are written to full precision (repr), so a
    table of a generated layout draws its label map exactly.
    """
    path = Path(path)
    if path.suffix.lower() != SUFFIX:
        path = path.with_name(path.name + SUFFIX)
    lines = ["# pillar table: one disc a line, in label order; x, y, radius in units of L",
             ", ".join(COLUMNS)]
    lines += [f"{float(x)!r}, {float(y)!r}, {float(r)!r}"
              for (y, x), r in zip(table.centres, table.radii)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
