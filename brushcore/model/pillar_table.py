"""Layouts given as a table of disc or elliptic pillars, drawn on any grid.

A label map or image fits one grid; a lab's array is usually known as a
list of pillars (a mask design, a micrograph's fitted circles or
ellipses).  A pillar table is a ``.csv`` text file: a header naming the
columns ``x``, ``y`` and ``radius`` (any order), then one pillar a line, in
label order (the first pillar is pillar 0), every length in units of the
square's side L: centres inside (0, 1), x along the grid's second axis and
y along its first (a label map's row index is y), pillars inside the
square and apart.  Optional columns ``aspect`` (semi-major / semi-minor
axis, >= 1) and ``orientation`` (degrees from the x axis to the major
axis) make a pillar an ellipse of the disc's area: ``radius`` is then its
equal-area radius, its semi-axes radius sqrt(aspect) and radius /
sqrt(aspect), as the generated ellipses' (`brushcore.model.shapes`).
'#' starts a comment; commas or white space separate values.

The same table runs on every grid, so its brush can be refined like a
generated one (its phi is the pillars' own, pi sum r^2, on every grid), and
per-pillar inputs (heights, stiffness) follow its rows.  An element belongs
to a pillar when its centre lies in the disc, as generated layouts are
drawn (`brushcore.model.layout.table_labels`): a table written from a
generated disc layout (`save_pillar_table`) draws the same label map.
"""

from __future__ import annotations

import functools
import math
import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import optimize
from scipy.spatial import cKDTree

from brushcore.model.inputs import header_names, table_rows
from brushcore.model.params import MAX_ORIENTATION, MAX_PHI
from brushcore.model.shapes import PillarShape, along_axes, ellipse_half_extents
from brushcore.validation import ParameterError

SUFFIX = ".csv"
COLUMNS = ("x", "y", "radius")
#: Columns a table may add: an elliptic pillar's aspect and orientation.
SHAPE_COLUMNS = ("aspect", "orientation")
#: What the header must name, in the refusals' words.
HEADER = "a header line naming the columns x, y and radius [L] (and aspect, orientation)"
#: Points on each ellipse's boundary that the overlap check tries.
BOUNDARY_POINTS = 720
_NAME = "layout_file"
#: The most pillars a table may hold (a brush of 2304 pillars is the paper's largest).
MAX_PILLARS = 1_000_000


def is_table(path: str | Path) -> bool:
    """Whether a layout file is a pillar table (by its suffix)."""
    return Path(path).suffix.lower() == SUFFIX


# eq=False: its fields are arrays, so == and hash() on them could only raise
@dataclass(frozen=True, eq=False)
class PillarTable:
    """The pillars of a table, in label order.

    Attributes
    ----------
    centres : (N, 2) pillar centres (y, x) [L]
    radii : (N,) pillar radii, an ellipse's equal-area one [L]
    aspects : (N,) semi-major / semi-minor axis (1: a disc), or None for
        discs alone
    orientations : (N,) angle of the major axis from the x axis [degrees],
        or None
    """

    centres: np.ndarray
    radii: np.ndarray
    aspects: np.ndarray | None = None
    orientations: np.ndarray | None = None

    @property
    def n_pillars(self) -> int:
        """Pillar count N."""
        return int(self.radii.size)

    @property
    def phi(self) -> float:
        """Filling factor pi sum r^2 (of the pillars, not of any grid's elements)."""
        return float(math.pi * np.sum(self.radii**2))

    @property
    def has_ellipses(self) -> bool:
        """Whether some pillar is not a disc."""
        return self.aspects is not None and bool(np.any(self.aspects != 1.0))

    @functools.cached_property
    def semi_axes(self) -> tuple[np.ndarray, np.ndarray]:
        """(N,) semi-major and semi-minor axes [L]: r sqrt(aspect) and r /
        sqrt(aspect), a disc's radius twice (once per table: the overlap
        test reads them for every boundary point it tries)."""
        if self.aspects is None:
            return self.radii, self.radii
        root = np.sqrt(self.aspects)
        return self.radii * root, self.radii / root

    @property
    def narrowest(self) -> np.ndarray:
        """Each pillar's half-width across its narrowest direction [L]: a
        disc's radius, an ellipse's semi-minor axis (the radius rule's)."""
        return self.semi_axes[1]

    def shape(self, p: int) -> PillarShape:
        """Pillar p's cross-section (its area is pi radii[p]^2)."""
        if self.aspects is None or self.aspects[p] == 1.0:
            return PillarShape()
        return PillarShape("ellipse", float(self.aspects[p]), float(self.orientations[p]))

    def half_extents(self) -> np.ndarray:
        """(N, 2) half widths of each pillar's bounding box along y and x [L]."""
        a, b = self.semi_axes
        if self.aspects is None:
            return np.column_stack([a, b])
        return np.column_stack(ellipse_half_extents(a, b, self.orientations))


def _refuse(path: Path, allowed: str, reason: str) -> ParameterError:
    return ParameterError(_NAME, str(path), allowed, reason)


#: Unknown columns that look like per-pillar values, which have files of their own.
_VALUES = ("height", "kbar", "k", "stiff", "factor")


def _columns(path: Path, names: list[str], number: int) -> dict[str, int]:
    """Positions of x, y, radius and the shape columns given, in the header
    line ``names``."""
    lowered = [name.lower() for name in names]
    if "" in lowered:
        raise _refuse(path, HEADER, f"line {number}: column {lowered.index('') + 1} has no "
                      "name (an index column? leave it out)")
    unknown = [n for n in lowered if n not in COLUMNS + SHAPE_COLUMNS]
    missing = [c for c in COLUMNS if c not in lowered]
    twice = sorted({n for n in lowered if lowered.count(n) > 1})
    if "orientation" in lowered and "aspect" not in lowered:
        missing = ["aspect"]  # an orientation turns nothing without it
    if unknown or missing or twice:
        what = (f"unknown column {unknown[0]!r}" if unknown else
                f"column {twice[0]!r} given twice" if twice else f"no column {missing[0]!r}")
        more = (" (heights and stiffness go in their own files, one value per pillar "
                "in the table's order)" if unknown and unknown[0].startswith(_VALUES) else "")
        raise _refuse(path, HEADER, f"line {number}: {what}{more}")
    return {name: lowered.index(name) for name in COLUMNS + SHAPE_COLUMNS if name in lowered}


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
        a value that is not a finite number, a radius <= 0, an aspect < 1,
        a pillar that reaches beyond the square, two pillars that overlap
        or touch, a filling factor above 0.5.
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
        names = {n.lower() for n in found[1]}
        if set(COLUMNS) <= names <= set(COLUMNS + SHAPE_COLUMNS):
            return found
    return None


def _read(path: Path) -> PillarTable:
    # a table's commas separate its columns; an integer table fails the range check
    header, rows, comma_hint = table_rows(path, _NAME, comma_warning=False)
    header = header or (_commented_header(path) if rows else None)
    if header is None:
        raise _refuse(path, HEADER, "its first line holds numbers" if rows else
                      "it holds no pillar")
    order = _columns(path, header[1], header[0])
    if not rows:
        raise _refuse(path, "one pillar a line after the header", "it holds no pillar")
    if len(rows) > MAX_PILLARS:
        raise _refuse(path, f"at most {MAX_PILLARS} pillars", f"it holds {len(rows)}")
    for number, row in rows:
        if len(row) != len(order):
            values = ("three values a line: x, y and radius [L]" if len(order) == 3 else
                      f"{len(order)} values a line: {', '.join(order)}")
            raise _refuse(path, values, f"line {number} holds {len(row)} values{comma_hint}")
    lines = np.array([number for number, _ in rows])
    data = {name: np.array([row[i] for _, row in rows]) for name, i in order.items()}
    for column, values in data.items():
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            name = column if column in COLUMNS else repr(column)  # as for 'aspect' below
            raise _refuse(path, "finite numbers",
                          f"line {lines[bad[0]]}: {name} = {float(values[bad[0]])!r}")
    x, y, r = (data[name] for name in COLUMNS)
    bad = np.flatnonzero(r <= 0)
    if bad.size:
        raise _refuse(path, "radii > 0 [L]",
                      f"line {lines[bad[0]]}: radius = {float(r[bad[0]])!r}")
    aspects = data.get("aspect")
    if aspects is not None:
        bad = np.flatnonzero(aspects < 1.0)
        if bad.size:
            # column names quoted: the command would read aspect as its --aspect
            raise _refuse(path, "'aspect' >= 1 (semi-major over semi-minor axis; 1 for a "
                          "disc)", f"line {lines[bad[0]]}: 'aspect' = {float(aspects[bad[0]])!r}")
    orientations = data.get("orientation", None if aspects is None else np.zeros_like(r))
    if "orientation" in data:
        _check_degrees(path, lines, orientations)
    table = PillarTable(np.column_stack([y, x]), r, aspects, orientations)
    half = table.half_extents()  # (y, x)
    outside = np.flatnonzero((x - half[:, 1] < 0) | (y - half[:, 0] < 0)
                             | (x + half[:, 1] > 1) | (y + half[:, 0] > 1))
    if outside.size:
        i = outside[0]
        # every radius beyond L: lengths in another unit (um, elements), likely
        units = ("; every radius exceeds 1: write lengths in units of L (divide by the "
                 "square's side)" if np.all(r > 1) else "")
        shape = "" if aspects is None else (f", 'aspect' = {float(aspects[i])!r}, "
                                            f"'orientation' = {float(orientations[i])!r}")
        raise _refuse(path, "discs inside the square: r <= x <= 1 - r and r <= y <= 1 - r, "
                      "in units of its side L" + ("" if aspects is None else
                                                  " (an ellipse's half extents in place of r)"),
                      f"line {lines[i]}: x = {float(x[i])!r}, y = {float(y[i])!r}, "
                      f"radius = {float(r[i])!r}{shape}{units}")
    _check_apart(path, lines, table)
    for array in (table.centres, r, aspects, orientations):  # a cached reading: callers
        if array is not None:  # must not change what the next one gets
            array.setflags(write=False)
    if table.phi > MAX_PHI * (1.0 + 1e-12):  # a generated brush at 0.5 sums to 0.5000000000000001
        raise _refuse(path, f"discs covering at most half the square (phi <= {MAX_PHI:g})",
                      f"pi sum r^2 = {table.phi:.4g}")
    return table


def _boundary(table: PillarTable, p: int, t: np.ndarray) -> np.ndarray:
    """Points (y, x) [L] on pillar p's boundary at parameters t [rad]."""
    a, b = (float(axis[p]) for axis in table.semi_axes)
    u, v = a * np.cos(t), b * np.sin(t)
    o = math.radians(table.orientations[p])
    return table.centres[p] + np.column_stack([u * math.sin(o) + v * math.cos(o),
                                               u * math.cos(o) - v * math.sin(o)])


def _level(table: PillarTable, q: int, points: np.ndarray) -> np.ndarray:
    """Pillar q's implicit function at ``points`` (y, x): (u/a)^2 + (v/b)^2,
    <= 1 inside or on its boundary."""
    a, b = (float(axis[q]) for axis in table.semi_axes)
    dy, dx = (points - table.centres[q]).T
    u, v = along_axes(dy, dx, float(table.orientations[q]))
    return (u / a) ** 2 + (v / b) ** 2


def _ellipses_meet(table: PillarTable, p: int, q: int) -> bool:
    """Whether pillars p and q (one an ellipse at least) overlap or touch:
    the lowest of the other's implicit function f over either's boundary is
    <= 1.  Found on `BOUNDARY_POINTS` samples, then, where the samples'
    lowest lies within what f can dip between two samples, refined around
    it by a bounded scalar search (an overlap of 1e-7 L between two samples
    passed the samples alone).

    f(t) = q(x(t)) with x on an ellipse of semi-major a1 and q the other's
    (u/a2)^2 + (v/b2)^2: |f''| <= |x'|^2 |H| + |grad q| |x''| <= 2 c^2 +
    2 sqrt(q) c, c = a1 / b2.  A minimum f(t*) <= 1 has a sample s within
    step / 2 of it, so f(s) <= 1 + |f''| step^2 / 8 there: with y = sqrt(f(s)),
    y^2 - k y - (1 + c k) <= 0, k = c step^2 / 4.  Samples all above its
    root squared leave no such minimum.
    """
    step = 2.0 * math.pi / BOUNDARY_POINTS
    t = np.arange(BOUNDARY_POINTS) * step
    major, minor = table.semi_axes
    for one, other in ((p, q), (q, p)):
        values = _level(table, other, _boundary(table, one, t))
        lowest = float(values.min())
        if lowest <= 1.0 + TANGENT_RTOL:
            return True
        c = float(major[one] / minor[other])
        k = c * step**2 / 4.0
        if lowest > (0.5 * (k + math.sqrt(k * k + 4.0 * (1.0 + TANGENT_RTOL + c * k)))) ** 2:
            continue  # no dip between samples reaches the other pillar
        best = float(t[int(np.argmin(values))])
        found = optimize.minimize_scalar(
            lambda s: float(_level(table, other, _boundary(table, one, np.array([s])))[0]),
            bounds=(best - step, best + step), method="bounded",
            options={"xatol": 1e-12})
        if float(found.fun) <= 1.0 + TANGENT_RTOL:
            return True
    return False


def _check_degrees(path: Path, lines: np.ndarray, orientations: np.ndarray) -> None:
    """Refuse an orientation beyond a turn; warn where the column reads as
    radians (every angle within 2 pi, not all whole degrees)."""
    bad = np.flatnonzero(np.abs(orientations) > MAX_ORIENTATION)
    if bad.size:
        raise _refuse(path, f"'orientation' in degrees, in [-{MAX_ORIENTATION:g}, "
                      f"{MAX_ORIENTATION:g}]",
                      f"line {lines[bad[0]]}: 'orientation' = {float(orientations[bad[0]])!r}")
    turned = orientations[orientations != 0.0]
    if turned.size and np.all(np.abs(turned) <= 2.0 * math.pi) \
            and not np.all(turned == np.round(turned)):
        warnings.warn(f"{path}: every 'orientation' lies within 2 pi and not all are whole "
                      f"(e.g. {float(turned[0]):g}): they are read as degrees; multiply "
                      "radians by 180/pi", stacklevel=4)


#: A file kind's suffix (a letter first): ".npy" names another kind of
#: file, where ".12" ends a number in the name.
_FILE_KIND = re.compile(r"\.[a-z][a-z0-9]*")


#: Pillars this close (relative) to tangent touch: a table's decimals
#: written as tangent land 1 ulp either side (0.4 - 0.1 = 0.30000000000000004).
TANGENT_RTOL = 1e-12


def _check_apart(path: Path, lines: np.ndarray, table: PillarTable) -> None:
    """Refuse two pillars that overlap or touch (discs no closer than the sum
    of their radii: tangent discs share element edges on every grid;
    ellipses by `_ellipses_meet`)."""
    centres = table.centres
    # an ellipse's circumscribed disc for the search, a disc's own radius
    r = table.semi_axes[0]
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
    overlap = distance <= (r[p] + r[q]) * (1.0 + TANGENT_RTOL)  # touching: no grid parts them
    if table.has_ellipses:  # circumscribed discs that meet: ask the ellipses
        round_pair = (table.aspects[p] == 1.0) & (table.aspects[q] == 1.0)
        for i in np.flatnonzero(overlap & ~round_pair):
            overlap[i] = _ellipses_meet(table, int(p[i]), int(q[i]))
    overlap = np.flatnonzero(overlap)
    if overlap.size:
        i = overlap[np.lexsort((q[overlap], p[overlap]))[0]]
        a, b = sorted((int(p[i]), int(q[i])))
        if table.has_ellipses and not (table.aspects[a] == table.aspects[b] == 1.0):
            raise _refuse(path, "pillars that neither overlap nor touch",
                          f"the pillars of lines {lines[a]} and {lines[b]} (pillars {a} and "
                          f"{b}) overlap or touch (an ellipse among them)")
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
    path : the ``.csv`` file to write (the suffix is added where there is
        none or the name ends in a number's decimals, "phi0.12"; another
        kind of file's suffix, ".npy", is refused; missing folders are made)

    Returns
    -------
    The path written.  Values are written to full precision (repr), so a
    table of a generated layout draws its label map exactly.

    Raises
    ------
    ParameterError
        Named ``path``, before anything is written where ``path``
        has another suffix, and with nothing left behind where the table
        breaks a rule that `read_pillar_table` reads it by (a radius <= 0,
        a pillar outside the square, two that overlap, ...).
    """
    path = Path(path)
    kind = path.suffix.lower()
    if _FILE_KIND.fullmatch(kind) and kind != SUFFIX:  # x.npy: a label map's name
        raise ParameterError("path", str(path), f"a {SUFFIX} file (a pillar table)",
                             f"it ends in {path.suffix}")
    if kind != SUFFIX:  # none, or a number's decimals: brush_phi0.12 -> brush_phi0.12.csv
        path = path.with_name(path.name + SUFFIX)
    shaped = table.aspects is not None
    columns = [table.centres[:, 1], table.centres[:, 0], table.radii]
    lines = ["# pillar table: one disc a line, in label order; x, y, radius in units of L"
             if not shaped else
             "# pillar table: one pillar a line, in label order; x, y, radius in units "
             "of L (an ellipse's equal-area radius), orientation in degrees",
             ", ".join(COLUMNS + (SHAPE_COLUMNS if shaped else ()))]
    if shaped:
        columns += [table.aspects, table.orientations]
    lines += [", ".join(repr(float(value)) for value in row) for row in zip(*columns)]
    path.parent.mkdir(parents=True, exist_ok=True)
    # Checked as it will be read, before it takes the name: a table the
    # reader refuses is no table to hand on (the refusal names ``path``).
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{SUFFIX}")  # the umask's mode
    try:
        tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
        try:
            with warnings.catch_warnings():  # said where the table is read, by its name
                warnings.simplefilter("ignore")
                _read(tmp)
        except ParameterError as exc:  # named as this function's argument
            raise ParameterError("path", str(path), exc.allowed, exc.reason) from None
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path
