"""A set of curve files as one sweep's cases: read, keyed and checked.

Each curve file is one case (`CaseKey`: layout, N, kbar, seed, grid, and
the rough parameters and pillar shape where they are not the default);
`load_curves` reads a set of them and refuses, naming the files, what
cannot form one sweep: unreadable files, two files of one case, a file
whose name stands for another case, brushes of one name drawn from other
files, per-pillar arrays that differ between the grids of a case.
`brushcore.data.aggregate` lays the checked set out as the sweep.
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import xarray as xr

from brushcore.model.params import RANDOM_GAP_GRID, BrushParams
from brushcore.model.layout_file import curve_layout
from brushcore.model.pillar_table import is_table
from brushcore.model.shapes import shape_label
from brushcore.data.io import (CurveFileError, as_simulated, check_curve, content_digest,
                               read_curve)
from brushcore.validation import ParameterError, brief

#: The case coordinates of every sweep.
CASE_DIMS = ("layout", "n_pillars", "kbar", "seed")
#: Pillar cross-section: a dimension only when a non-disc case ran,
#: with `brushcore.model.shapes.shape_label` values ("disc", "square",
#: "ellipse2.0_30.0"), so a sweep of discs keeps the flat sweep's dimensions.
SHAPE_DIM = "shape"
#: Extra case dimensions of rough, preloaded or graded brushes.  A
#: sweep of flat brushes only keeps the four base dimensions.
ROUGH_DIMS = ("roughness", "preload", "kbar_spread")
#: The filling factor asked for: a dimension only when the generated brushes'
#: curves differ in phi (a file brush keeps its file's), so a sweep of one phi
#: keeps its dimensions and the attribute ``phi``.
PHI_DIM = "phi"
#: The resolution dimension (elements per side n of the L x L square).
GRID_DIM = "grid"
SWEEP_DIMS = (*CASE_DIMS, GRID_DIM)


class AggregationError(ValueError):
    """The curve files cannot form one sweep; the message names the file(s)."""


@dataclass(frozen=True, order=True)
class CaseKey:
    """Coordinates of one simulation in the sweep.

    Parameters
    ----------
    layout : "regular", "hexagonal", "random" or "file".
    n_pillars : number of pillars N.
    kbar : normalised spring stiffness k / (E* L) [1].
    seed : seed of the random layout, heights and stiffnesses (0 where
        nothing is drawn).
    grid : elements per side n of the L x L square.
    roughness, preload, kbar_spread : rough-brush parameters (0 when flat).
    shape : `shape_label` of the pillar cross-section ("disc" by default).
    phi : the filling factor asked for (a file brush's: its file's), as its
        curve's attribute ``phi``; None where unknown (a case the workflow
        names, whose phi it gives beside it).
    """

    layout: str
    n_pillars: int
    kbar: float
    seed: int
    grid: int
    roughness: float = 0.0
    preload: float = 0.0
    kbar_spread: float = 0.0
    shape: str = "disc"
    phi: float | None = None

    @property
    def is_flat(self) -> bool:
        """Today's brush: no roughness, preload or stiffness spread."""
        return self.roughness == 0 and self.preload == 0 and self.kbar_spread == 0

    def __str__(self) -> str:
        """The case as a message names it: "random N=64 kbar=0.01 seed 1 on 256^2"
        and the rough parameters and shape where they are not the default."""
        rough = "".join(f" {name}={getattr(self, name):g}" for name in ROUGH_DIMS
                        if getattr(self, name))
        return (f"{self.layout} N={self.n_pillars} kbar={self.kbar:g} seed {self.seed}"
                f"{rough}{'' if self.shape == 'disc' else ' ' + self.shape}"
                f" on {self.grid}^2")


def case_key(curve: xr.Dataset) -> CaseKey:
    """Read the case coordinates from a curve file's attributes.

    Raises
    ------
    CurveFileError
        Where one is missing or no number (an array, inf for an integer):
        the file's fault, which aggregation reports as such.
    """
    a = curve.attrs

    def number(name: str, default: float | None = None, integer: bool = False) -> float:
        value = a.get(name, default)
        if value is None:
            raise CurveFileError(f"its attribute {name!r} is missing")
        try:
            x = float(value)
        except (TypeError, ValueError):
            x = math.nan
        # kbar may be inf (rigid); an integer must be one (32.7 was cut to 32)
        if math.isnan(x) or integer and not (math.isfinite(x) and x.is_integer()):
            raise CurveFileError(f"its attribute {name} is {value!r}, not "
                                 + ("an integer" if integer else "a number"))
        return int(x) if integer else x

    layout = curve_layout(a)  # a brush of one's own by its file, as the workflow names it
    shape = shape_label(str(a.get("shape", "disc")), number("aspect", 1.0),
                        number("orientation", 0.0))  # files without a shape: discs
    return CaseKey(layout, number("n_pillars", integer=True), number("kbar"),
                   number("seed", integer=True), number("grid", integer=True),
                   *(number(name, 0.0) for name in ROUGH_DIMS), shape=shape,
                   phi=number("phi"))


def file_sha256(path: str | Path) -> str:
    """SHA-256 hex digest of a file's bytes (provenance of the inputs)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


#: How a curve handed in as a Dataset is named in messages and provenance: by
#: its content digest (`io.content_digest`), whatever its place in the list.
IN_MEMORY = "<curve sha256:{} in memory>"
IN_MEMORY_PATTERN = re.compile(r"<curve sha256:([0-9a-f]{64}) in memory>")


def load_curves(paths: Iterable[str | Path | xr.Dataset],
                expected: Sequence[tuple[CaseKey, float]] | None = None
                ) -> dict[CaseKey, tuple[Path, xr.Dataset]]:
    """Read every curve file and index it by its case.

    Parameters
    ----------
    paths : curve files, or curves as `brushcore.simulate` returns them
        (named `IN_MEMORY` by their content digest, which provenance takes
        as their hash, a file's being that of its bytes; checked as a file is)
    expected : per path, the case and phi it must hold (the workflow's,
        from the file's name), or None to take each file's own

    Raises
    ------
    AggregationError
        If a file cannot be read (the message names it), holds another case
        than ``expected`` says, two files hold the same case (the message
        names both), or a random layout off the 512^2 grid was drawn under
        the rule before 2026-12-04 (`check_brush`).
    """
    curves: dict[CaseKey, tuple[Path, xr.Dataset]] = {}
    paths = list(paths)
    if expected is not None and len(expected) != len(paths):
        raise ValueError(f"{len(expected)} expected cases for {len(paths)} curve files")
    unreadable, not_curves = [], []
    for i, raw in enumerate(paths):
        in_memory = isinstance(raw, xr.Dataset)
        if in_memory:  # one opened by xarray: its "none" as numbers, as simulate gave
            raw = as_simulated(raw.copy(deep=False))
        path = Path(IN_MEMORY.format(content_digest(raw)) if in_memory else raw)
        try:
            if in_memory:
                check_curve(raw, str(path), digest=False)
            curve = raw if in_memory else read_curve(path)
            key = case_key(curve)
        # the file's fault (unreadable, an attribute missing or not a number), not a
        # bug here, which would otherwise send the user to delete good curves
        except CurveFileError as exc:
            (not_curves if exc.not_a_curve else unreadable).append(
                f"{path} ({str(exc).removeprefix(f'{path}: ')})")
            continue
        if expected is not None:
            check_named_case(path, key, float(curve.attrs["phi"]), *expected[i])
        check_brush(path, curve, key)
        if key in curves:
            other = curves[key][1].attrs.get("inputs_digest", "")
            if other != curve.attrs.get("inputs_digest", ""):
                raise AggregationError(
                    f"curve files {curves[key][0]} and {path} hold two brushes under one "
                    f"case ({key}): they were given other per-pillar heights, stiffnesses "
                    "or gap maps (inputs_digest); aggregate each brush on its own")
            raise AggregationError(
                f"curve files {curves[key][0]} and {path} hold the same case ({key}): "
                "a sweep takes one file per case and grid"
            )
        curves[key] = (path, curve)
    if unreadable or not_curves:  # every one of them at once, and what brings them back
        def shown(files: list[str]) -> str:
            return "; ".join(files[:10]) + (f"; and {len(files) - 10} more"
                                            if len(files) > 10 else "")
        parts = []
        if unreadable:
            # The workflow names what each file must hold; elsewhere the user ran them.
            again = ("Delete them and run snakemake again: it recomputes the missing curves"
                     if expected is not None else "Run their brushcore simulate again")
            parts.append(f"cannot aggregate {len(unreadable)} curve file(s): "
                         f"{shown(unreadable)}. {again}")
        if not_curves:  # given by mistake (a glob that took a table or the sweep)
            parts.append(f"cannot aggregate {len(not_curves)} file(s) that are not curves: "
                         f"{shown(not_curves)}. Give only curve files (the .nc files "
                         "brushcore simulate writes)")
        raise AggregationError(". ".join([parts[0], *(p[0].upper() + p[1:] for p in parts[1:])]))
    if not curves:
        raise AggregationError("no curve files to aggregate")
    return curves


def check_named_case(path: Path, key: CaseKey, phi: float, case: CaseKey,
                     case_phi: float) -> None:
    """Refuse a file that holds another case than the one its name stands for
    (a curve copied or moved by hand would otherwise enter the sweep as its
    own case, and the case asked for would be NaN)."""
    if (replace(key, phi=None), phi) != (replace(case, phi=None), case_phi):
        raise AggregationError(
            f"curve file {path} holds {brief(replace(key, phi=None))}, phi={phi!r}, not the "
            f"case its name stands for ({brief(replace(case, phi=None))}, phi={case_phi!r}): "
            "delete it and rerun")


def check_brush(path: Path, curve: xr.Dataset, key: CaseKey) -> None:
    """Refuse a random layout whose seed names another brush than the current rule's.

    Before 2026-12-04 a random layout kept a gap of ``min_gap`` elements of
    its own grid, so off the `RANDOM_GAP_GRID` grid it drew other pillars
    than the same seed draws now (`brushcore.model.layout.random_gap`), and
    beside current curves it would pass for the same brush along ``grid``.
    Such files lack the ``random_gap`` attribute that every random curve
    records since; on the 512^2 grid both rules draw the same brush.
    """
    if (key.layout == "random" and key.grid != RANDOM_GAP_GRID
            and "random_gap" not in curve.attrs):
        raise AggregationError(
            f"curve file {path} is a random layout at grid {key.grid} written before "
            f"2026-12-04, when a random brush kept a gap of min_gap elements of its own "
            f"grid: seed {key.seed} names another brush there today. Delete the file "
            f"and rerun its job to get the brush that seed {key.seed} draws on every grid")


def check_one_file_per_layout(curves: dict[CaseKey, tuple[Path, xr.Dataset]]) -> None:
    """A file brush is named by its file's name (`curve_layout`): curves of one
    name drawn from files of different content (two folders' brush.csv, a
    table edited between runs; for a map, on one grid) are two brushes, not
    one refined."""
    digests: dict[tuple[str, int | None], dict[str, Path]] = {}
    for key, (path, curve) in curves.items():
        digest = curve.attrs.get("layout_file_sha256")  # absent before it was recorded
        if curve.attrs.get("layout") == "file" and digest:
            # a table fits every grid; a map or image one (a refinement has one a grid)
            table = is_table(str(curve.attrs.get("layout_file", "")))
            brush = (key.layout, None if table else key.grid)
            digests.setdefault(brush, {}).setdefault(str(digest), path)
    for (layout, _), files in digests.items():
        if len(files) > 1:
            first, second = list(files.values())[:2]
            raise AggregationError(
                f"curve files {first} and {second} are both brush {layout} but were drawn "
                "from files of different content (layout_file_sha256): rename one file, "
                "or delete the curves of the older content and make them again (the "
                "workflow remakes missing curves: snakemake, or brushcore simulate)")


def check_one_brush_per_case(curves: dict[CaseKey, tuple[Path, xr.Dataset]]) -> None:
    """Per-pillar heights and stiffnesses given by hand (``--heights``,
    ``--kbar-factors``, ``--kbar-file``; not a case coordinate) must be the
    same on every grid of a case: curves of other arrays are other brushes,
    and a study across them would extrapolate from one brush to another.
    (A gap map is a map per grid, so only its presence is compared.)"""
    seen: dict[CaseKey, tuple[Path, int, tuple, str]] = {}
    for key, (path, curve) in curves.items():
        given = given_inputs(curve)
        arrays: tuple = (given,)
        if given:
            try:
                params = BrushParams.from_curve(curve)
            except ParameterError:  # written before its arrays were kept: not comparable
                continue
            arrays += tuple(getattr(params, name) for name in ("heights", "kbar_values"))
        words = f"{given} ({curve.attrs.get('inputs_digest', '')})" if given else "none"
        case = replace(key, grid=0)
        if case not in seen:
            seen[case] = (path, key.grid, arrays, words)
            continue
        first, grid, before, before_words = seen[case]
        # the names given, then heights and stiffnesses (None where not given)
        if len(before) != len(arrays) or not all(map(np.array_equal, before, arrays)):
            raise AggregationError(
                f"curve files {first} (grid {grid}) and {path} (grid {key.grid}) are "
                f"{str(case).removesuffix(' on 0^2')} but not one brush: they were given "
                f"other per-pillar arrays ({before_words}; {words}), so a study across "
                "their grids would mix two brushes; make every grid with the same "
                "per-pillar files (the workflow's layout_files entry: heights, kbar_factors, "
                "gap_map; the command's --heights, --kbar-factors, --kbar-file, --gap-map; "
                "a gap map on each grid or none), deleting the curves made from others")


def common_attr(curves: dict[CaseKey, tuple[Path, xr.Dataset]], name: str) -> object:
    """An attribute every curve must share (e.g. grid); raise naming a mismatch."""
    values = {}
    for path, curve in curves.values():
        values.setdefault(curve.attrs.get(name), path)
    if len(values) > 1:
        found = ", ".join(f"{_plain(v)!r} in {p}" for v, p in values.items())
        units = (" (one sweep holds one unit system: run every grid with the same --e-star, "
                 "--dgamma and --h; the normalised results do not depend on them, nor on L)"
                 if name in ("e_star", "dgamma", "h") else "")
        raise AggregationError(f"curve files disagree on {name}: {found}{units}")
    return next(iter(values))


def _plain(value: object) -> object:
    """A NumPy scalar as the Python number it holds (for messages)."""
    return value.item() if isinstance(value, np.generic) else value


def given_inputs(curve: xr.Dataset) -> str:
    """The arrays a curve's brush was given (`BrushParams.given_inputs`), from
    its attribute; a file written before the attribute, whose ``inputs_digest``
    says arrays were given, from its variables: a gap map, heights where none
    were drawn, stiffnesses that differ from kbar where none were drawn."""
    a = curve.attrs
    if "given_inputs" in a or not a.get("inputs_digest"):
        return str(a.get("given_inputs", ""))
    names = []
    if "pillar_height_normalized" in curve and not float(a.get("roughness", 0.0)):
        if np.any(curve["pillar_height_normalized"].values != 0):
            names.append("heights")
    if "pillar_kbar" in curve and not float(a.get("kbar_spread", 0.0)):
        if np.any(curve["pillar_kbar"].values != float(a["kbar"])):
            names.append("kbar_values")
    if "gap_map_normalized" in curve:
        names.append("gap_map")
    return " ".join(names)
