"""Brushes of one's own (`layout_files`): their maps and, for a brush as
made, its heights, stiffness factors and gap map: read and refused at
plan time, the cases they run, and what their simulate jobs take.

Included by the Snakefile after the helpers it uses (ConfigError of
config_checks.smk, `_rough_tags` and `parse_rough_tag` of cases.smk).
"""

import functools
import hashlib
import math
import re
from pathlib import Path
from typing import NamedTuple

from brushcore.model.inputs import INPUT_FILES, with_input_files
from brushcore.model.layout_file import file_layout, file_params
from brushcore.model.params import ParameterError
from brushcore.model.pillar_table import is_table, read_pillar_table

#: What a layout file's name (without suffix) may hold: it names curve files.
_FILE_NAME = re.compile(r"[A-Za-z0-9._-]+")


class FileBrush(NamedTuple):
    """A `layout_files` entry: its map, what the map holds, the brush as made."""

    path: str  # the label map or image, or a pillar table
    n_pillars: int
    grid: int | None  # the map's; None for a table, drawn on the sweep's grids
    phi: float  # realised by the map; a table's pi sum r^2
    # per-pillar and per-element files by key (heights, kbar_factors, gap_map)
    inputs: dict


def _entry_files(entry):
    """(map path, {input key: path}) of a `layout_files` entry (text or mapping)."""
    if isinstance(entry, str):
        return entry, {}
    return entry["layout"], {k: v for k, v in entry.items() if k != "layout"}


def _refused_file(key, path, exc):
    """A ConfigError naming the key for a file's own problem, told as the file's."""
    reason = f" ({exc.reason})" if exc.reason else ""
    return ConfigError(f"{key}: {path!r} is invalid{reason}: allowed {exc.allowed}")


def file_brushes(config):
    """{layout: `FileBrush`} of the config's `layout_files`, the layout
    `file_layout` of the map's path ("file_" + its name); refused at plan
    time, naming the key, where a map cannot be read as a layout, its name
    does not fit a file name, two maps share one, or a per-pillar or
    per-element file does not fit the map (count, shape, range: checked at
    the sweep's smallest kbar, where factors matter most)."""
    brushes = {}
    finite = [float(k) for k in config["kbar"] if math.isfinite(float(k))]
    kbar = min(finite) if finite else math.inf
    for i, entry in enumerate(config.get("layout_files", [])):
        path, inputs = _entry_files(entry)
        key = f"config key 'layout_files.{i}" + (
            "'" if isinstance(entry, str) else ".layout'"
        )
        stem = Path(path).stem
        if not _FILE_NAME.fullmatch(stem):
            raise ConfigError(
                f"{key}: {path!r} is invalid: allowed a file whose name (without its "
                "suffix) holds letters, digits, '.', '-' and '_' only"
            )
        layout = file_layout(path)
        if layout in brushes:
            raise ConfigError(
                f"{key}: {path!r} is invalid: its name {stem!r} is that of "
                f"{brushes[layout].path!r}; allowed one file per name (it names the brush: "
                "copy a map under another name to run it twice)"
            )
        try:
            geometry = _file_geometry(path)
        except ParameterError as exc:
            raise _refused_file(key, path, exc) from None
        grids = case_grids(config, geometry[0]) if geometry[1] is None else [None]
        if "gap_map" in inputs and len(grids) > 1:
            raise ConfigError(
                f"config key 'layout_files.{i}.gap_map': {inputs['gap_map']!r} is "
                f"invalid (the table {path!r} runs on grids {grids}, and a gap map "
                "fits one): allowed a sweep of one grid for a table with a gap map"
            )
        for grid in grids if inputs else []:
            try:
                _check_inputs(path, tuple(sorted(inputs.items())), kbar, grid)
            except ParameterError as exc:
                name = next(
                    (k for k in inputs if exc.name in (k, INPUT_FILES[k])), None
                )
                if name is None:  # a table too coarse for a grid: check_cases says so
                    continue
                raise _refused_file(
                    f"config key 'layout_files.{i}.{name}'", inputs[name], exc
                ) from None
        for name, drawn in _REPLACES.items():
            if name in inputs and 0.0 not in [float(v) for v in config[drawn]]:
                raise ConfigError(
                    f"config key '{drawn}': {config[drawn]} has no 0.0, which the "
                    f"brush of 'layout_files.{i}.{name}' needs (its {name} are given, "
                    f"so it draws no {drawn}); allowed a list holding 0.0"
                )
        brushes[layout] = FileBrush(path, *geometry, inputs)
    return brushes


@functools.lru_cache(maxsize=None)
def _check_inputs(path, inputs, kbar, grid):
    """Read a file brush's per-pillar and per-element files ((key, path)
    pairs) at ``kbar`` once, on ``grid`` (a table's; None: the map's); a
    `ParameterError` where one does not fit."""
    drawn_on = {} if grid is None else {"grid": grid}
    with_input_files(
        file_params(path, kbar, allow_coarse=True, **drawn_on), dict(inputs)
    )


@functools.lru_cache(maxsize=None)
def _file_geometry(path):
    """(N, grid, phi) a layout file holds, read once (its checks come with each
    case); grid None for a pillar table, which runs on the sweep's grids."""
    if is_table(path):
        table = read_pillar_table(path)
        return table.n_pillars, None, table.phi
    params = file_params(path, 1.0, allow_coarse=True)
    return params.n_pillars, params.grid, params.phi


#: The drawn quantity that a given per-pillar file replaces (exclusive with it).
_REPLACES = {"heights": "roughness", "kbar_factors": "kbar_spread"}


def _file_rough_tags(config, kbar, brush):
    """`_rough_tags` of a file brush: where its heights or stiffness factors
    are given, only the cases that draw none of them (roughness 0,
    kbar_spread 0; `file_brushes` made sure the config lists them)."""
    drawn = [d for name, d in _REPLACES.items() if name in brush.inputs]
    return [
        t
        for t in _rough_tags(config, kbar)
        if all(parse_rough_tag(t).get(d, 0.0) == 0.0 for d in drawn)
    ]


def brush_files(config, layout):
    """The rule's `layout_file` param: "" for generated layouts, else
    {"layout": map, key: file, ..., "sha256": the files' contents}, so that
    swapping which file gives which input reruns its curves (the inputs
    alone see the same set of unchanged files), and so does any edit of a
    file's content: a bare map is no input (`simulate_inputs`), and a file
    put back with its old time (cp -p, rsync -a, tar) is older than the
    curves; both left stale curves (a lab helper's finds, 2026-12-07)."""
    brush = file_brushes(config).get(layout)
    if not brush:
        return ""
    files = {"layout": brush.path, **dict(sorted(brush.inputs.items()))}
    return {**files, "sha256": contents_digest(tuple(files.items()))}


def contents_digest(files):
    """SHA-256 over ((key, path), ...) and each file's bytes, read once a file
    version (by its time and size) however many jobs ask."""
    digest = hashlib.sha256()
    for key, path in files:
        stat = Path(path).stat()
        digest.update(f"{key}={path}:".encode())
        digest.update(_file_sha256(path, stat.st_mtime_ns, stat.st_size).encode())
    return digest.hexdigest()


@functools.lru_cache(maxsize=None)
def _file_sha256(path, mtime_ns, size):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def simulate_inputs(config):
    """The rule's input function: a pillar table, and a brush as made's map and
    its per-pillar and per-element files, so that editing one reruns its
    curves; nothing for generated layouts and bare maps (whose curves, made
    before brushes as made, would otherwise all rerun: Snakemake sees a new
    set of inputs)."""

    def inputs(wildcards):
        brush = file_brushes(config).get(wildcards.layout)
        if brush and (
            brush.inputs or brush.grid is None
        ):  # a table is new: no old curves
            return [brush.path, *brush.inputs.values()]
        return []

    return inputs


def made_brush(config):
    """True when some `layout_files` brush is given heights, stiffness or a gap map."""
    return any(brush.inputs for brush in file_brushes(config).values())
