"""Helpers shared by the rules: config checks, the job list and resource estimates."""

import difflib
import functools
import hashlib
import math
import re
import time
from pathlib import Path

import jsonschema
import yaml
from snakemake.logging import logger

from brushcore.data.simulate_job import case_params
from brushcore.model.cost import is_exact, kind_of, slowdown, slowest_curve_s
from brushcore.model.layout_file import FILE_LAYOUT_PREFIX
from brushcore.model.inputs import (
    parse_protocol,
    protocol_text,
)
from brushcore.model.params import ParameterError
from brushcore.model.layout import build_labels, grid_hint, smallest_radius_elements
from brushcore.data.convergence import UNDER_RESOLVED_RADIUS
from brushcore.numerics.options import SolverOptions
from brushcore.numerics.platform.backend import resolve_backend
from brushcore.model.shapes import parse_shape_label, shape_label
from brushcore.validation import overflows


def check_config(config, schema_path):
    """Validate the config against its schema with one short message naming the key.

    Snakemake's `validate` prints the whole schema around the error; this
    reports the first error only, as "config key 'x': ...", with the closest
    known key for a typo.  Defaults are filled in afterwards by `validate`.
    """
    schema = _schema(schema_path)
    overflow = _typed_text(config)
    if overflow:
        raise ConfigError(overflow)
    error = jsonschema.exceptions.best_match(
        jsonschema.Draft202012Validator(schema).iter_errors(config)
    )
    if error is None:
        where = _first_nan(config)
        if where is not None:
            raise ConfigError(
                f"config key '{where}': nan is not a number; allowed a number "
                "in the range the schema gives"
            )
        _integral_counts(config)
        _shape_settings_used(config, schema)
        return
    where = ".".join(str(p) for p in error.absolute_path)
    if error.validator == "additionalProperties":
        known = sorted(error.schema.get("properties", {}))
        extra = sorted(set(error.instance) - set(known))
        close = difflib.get_close_matches(extra[0], known, n=1)
        hint = f"; did you mean '{close[0]}'?" if close else f"; known keys: {known}"
        prefix = f"{where}." if where else ""
        raise ConfigError(f"config key '{prefix}{extra[0]}' is unknown{hint}")
    message = error.message
    if error.validator == "oneOf" and error.context:  # say what each form wanted
        forms = {}
        for sub in error.context:
            forms.setdefault(sub.schema_path[0], sub.message)
        message = f"{error.instance!r} fits none of its forms: " + "; ".join(
            forms.values()
        )
    if (
        error.validator == "type"
        and error.validator_value == "array"
        and not isinstance(error.instance, (list, dict))
    ):
        # kbar: 0.01 for kbar: [0.01]
        message += f"; write a list, even of one value: [{error.instance!r}]"
    raise ConfigError(f"config key '{where}': {message}")


#: A number in exponent form without a point ("1e-8"): YAML 1.2 reads it as a
#: number, but PyYAML (YAML 1.1, which Snakemake uses) as a string.
_EXPONENT_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)[eE][-+]?\d+")


@functools.lru_cache(maxsize=None)
def _schema(path):
    """The config schema, read once for the checks that need it."""
    with open(path) as fh:
        return yaml.safe_load(fh)


def _children(value):
    """(key, item) of a config mapping or list; nothing for a plain value."""
    if isinstance(value, dict):
        return list(value.items())
    if isinstance(value, (list, tuple)):
        return list(enumerate(value))
    return []


#: What `_typed_text` leaves as text.
_TEXT = object()


#: Infinity as the CLI's --kbar and Python spell it; YAML wants .inf.
_INF = re.compile(r"[-+]?inf(?:inity)?", re.IGNORECASE)


def _typed(text):
    """The number, bool or null a config file would read `text` as (and inf
    as the CLI reads it), else `_TEXT`; blank text stays text (YAML reads
    it as null: `protocol: ""` had run no protocol without a word)."""
    if not text.strip():
        return _TEXT
    if _EXPONENT_NUMBER.fullmatch(text.strip()) or _INF.fullmatch(text.strip()):
        return float(text)
    try:
        typed = yaml.safe_load(text)
    except yaml.YAMLError:
        return _TEXT
    return typed if typed is None or isinstance(typed, (bool, int, float)) else _TEXT


def _typed_text(value, where=""):
    """Read text as a config file would, wherever the config holds it (in place):
    "1e-8" (text to PyYAML, which reads YAML 1.1) becomes 1e-8, so that
    `kbar: [1e-6, 1e-3]` means what it says, and `--config kbar=[0.001]`,
    `regular=[64]` or `allow_coarse=true`, which Snakemake reads as text
    (its --config lists go through YAML's BaseLoader), become the numbers and
    switches a config file gives.  Returns the message for the first numeral
    that overflows a float, or None."""
    refused = None
    for key, item in _children(value):
        path = f"{where}.{key}" if where else str(key)
        typed = _typed(item) if isinstance(item, str) else _TEXT
        if typed is not _TEXT:
            value[key] = typed
            if overflows(item) and refused is None:
                refused = f"config key '{path}': {item.strip()} {_OVERFLOW}"
        else:
            refused = refused or _typed_text(item, path)
    return refused


_OVERFLOW = "is beyond the largest float (about 1.8e308); for rigid pillars write .inf"
_MERGE_TAG = "tag:yaml.org,2002:merge"


class _StrictLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing what it would otherwise take silently:
    a key twice in one mapping (the second wins) and a number too large for
    a float (1.0e+400 reads as inf: rigid pillars for a kbar; 1e400, text to
    PyYAML, would become inf in `_typed_text` or in a JSON config)."""

    path = ""

    def construct_mapping(self, node, deep=False):
        seen = {}
        for key_node, _ in node.value:
            if key_node.tag == _MERGE_TAG:  # '<<': keys may override what it merges
                continue
            key = self.construct_object(key_node, deep=deep)
            line = key_node.start_mark.line + 1
            try:
                first = seen.get(key)
                seen[key] = line
            except TypeError:  # an unhashable key: YAML's own error follows
                continue
            if first is not None:
                where = (
                    f"lines {first} and {line}"
                    if first != line
                    else f"both on line {line}"
                )
                raise _Refused(
                    f"config file {self.path}: key '{key}' is given twice in one "
                    f"mapping ({where}), and YAML would keep the second silently; "
                    "allowed once"
                )
        return super().construct_mapping(node, deep)

    def _overflow(self, node, text):
        return _Refused(
            f"config file {self.path}, line {node.start_mark.line + 1}: {text} {_OVERFLOW}"
        )

    def construct_yaml_float(self, node):
        if overflows(node.value):
            raise self._overflow(node, node.value)
        return super().construct_yaml_float(node)

    def construct_yaml_str(self, node):
        value = super().construct_yaml_str(node)
        # plain, not quoted: a number to JSON and to the checks
        if node.style is None and overflows(value):
            raise self._overflow(node, value)
        return value


_StrictLoader.add_constructor(
    "tag:yaml.org,2002:float", _StrictLoader.construct_yaml_float
)
_StrictLoader.add_constructor("tag:yaml.org,2002:str", _StrictLoader.construct_yaml_str)


def check_config_files(paths):
    """Read each config file again with `_StrictLoader`, before the checks of
    the merged config (which cannot see a key that YAML already dropped)."""
    for path in paths:
        loader = type("Loader", (_StrictLoader,), {"path": str(path)})
        refused = None
        try:
            with open(path, encoding="utf-8") as fh:
                yaml.load(fh, Loader=loader)
        except _Refused as exc:
            refused = str(exc)
        except (OSError, UnicodeDecodeError, yaml.YAMLError):
            continue  # what Snakemake could not read, it has reported already
        if refused:  # raised here, not inside PyYAML: a short traceback
            raise ConfigError(refused)


class _Refused(Exception):
    """What `_StrictLoader` refuses (turned into a ConfigError by its caller)."""


#: Keys whose values are counts: JSON Schema calls 64.0 an integer, Python does not.
_COUNT_KEYS = ("grid", "regular", "random", "hexagonal", "seeds", "threads")


def _integral_counts(config):
    """Counts written as 64.0 become 64 (in place), as the schema accepted them."""

    def fix(value):
        if isinstance(value, list):
            return [fix(v) for v in value]
        return int(value) if isinstance(value, float) and value.is_integer() else value

    for key in _COUNT_KEYS:
        if key in config:
            config[key] = fix(config[key])
    if "n_pillars" in config.get("fig5", {}):
        config["fig5"]["n_pillars"] = fix(config["fig5"]["n_pillars"])
    for entry in config.get("grid_by_n", []):
        for key in ("n_pillars", "grid"):
            if key in entry:
                entry[key] = fix(entry[key])


#: Shape settings and the pillar shapes that read them (the CLI refuses
#: --aspect without --shape ellipse alike).
_SHAPE_SETTINGS = {"aspect": ("ellipse",), "orientation": ("square", "ellipse")}


def _shape_settings_used(config, schema):
    """Refuse `aspect` or `orientation` other than its default where no brush
    of the config has a shape that reads it: it would seem to count (as the
    CLI and BrushParams rule; a config that layers shape: [disc] over the
    shipped lattices config, which sets orientation: 0.0, runs).  Read
    before `validate` fills in the defaults."""
    fig5 = config.get("fig5", {})
    shapes = set(config.get("shape", ["disc"]))
    if fig5.get("kbar", [None]):  # fig5: {kbar: []} runs no Fig. 5 brush
        shapes.add(fig5.get("shape", "disc"))
    for key, readers in _SHAPE_SETTINGS.items():
        default = schema["properties"][key]["default"]
        if config.get(key, default) != default and not shapes.intersection(readers):
            raise ConfigError(
                f"config key '{key}': applies to {' and '.join(readers)} pillars only, "
                f"and no brush of this config has them (shape: {sorted(shapes)}); add "
                f"{' or '.join(readers)} to 'shape' (or fig5.shape), or remove '{key}'"
            )


def _first_nan(value, where=""):
    """The key of the first NaN in the config, or None: JSON Schema's ranges
    let NaN through (every comparison with it is false), and a NaN kbar
    would only fail as missing files at the end of planning."""
    if isinstance(value, float) and math.isnan(value):
        return where
    for key, item in _children(value):
        found = _first_nan(item, f"{where}.{key}" if where else str(key))
        if found is not None:
            return found
    return None


class ConfigError(ValueError):
    """The config asks for something that cannot run; the message names the key."""


def canonical_solver(config, schema_path):
    """Put the solver options in the schema's order (in place, after `validate`
    filled the defaults).  They reach every simulate job as a param, which
    Snakemake compares as written: `solver: {cascade: local, rtol: 1.0e-4}`,
    the defaults in another order, reran every finished curve.  The default
    config's order is the schema's, so its curves keep their records."""
    order = list(_schema(schema_path)["properties"]["solver"]["properties"])
    solver = config["solver"]
    config["solver"] = {k: solver[k] for k in order if k in solver} | {
        k: v for k, v in solver.items() if k not in order
    }


def _case_params(config, key, kbar, grid):
    """The parameters of a case (layout, n, seed, grid, phi, rough, shape) on
    ``grid``, as its job will build them (`case_params`)."""
    layout, n, seed, _, phi, rough, shape = key
    return case_params(
        layout,
        n,
        kbar,
        seed,
        grid,
        phi,
        files=brush_files(config, layout),
        rough=parse_rough_tag(rough),
        shape=parse_shape_tag(shape),
        allow_coarse=config["allow_coarse"],
        backend=config["backend"],
    )


def check_cases(config, main=True):
    """Run every check that needs no solve, for every case, before any job starts.

    Builds the parameters of each case (ranges, the grid rule: pillar radius
    >= 2 elements, hexagonal N) and the label map of each lattice brush
    (regular, hexagonal: realised phi within 5 %, for every pillar shape) and
    random layout (packed as its job will pack it: milliseconds for N = 1620
    at phi 0.12, under a second where packing fails), so that a config that
    cannot run stops `snakemake -n` already.  The geometry does not depend
    on kbar: checked once.
    """
    try:  # the solver options every job will build
        SolverOptions(**config["solver"])
    except ParameterError as exc:
        keys = {k: f"solver.{k}" for k in config["solver"]}
        raise ConfigError(f"config: {exc.in_terms_of(keys, sep=' = ')}") from None
    config_protocol(config)
    brushes = file_brushes(config)  # every layout file read once, and refused here
    cases = sweep_cases(config)
    if not cases:
        raise ConfigError(
            "config: the sweep has no brush; allowed a config that lists one under "
            "'regular', 'hexagonal', 'random', 'layout_files' or 'fig5.kbar'"
        )
    if main:
        _warn_first_touch(config, brushes)
        _warn_first_waypoint(config, brushes)
        _warn_unused(config, cases)
    named = [int(e["n_pillars"]) for e in config.get("grid_by_n", [])]
    twice = sorted({n for n in named if named.count(n) > 1})
    if twice:
        raise ConfigError(f"config key 'grid_by_n': N = {twice} listed more than once")
    by_n = set(named)
    # One brush per geometry, at its smallest kbar: the layout does not
    # depend on kbar, and a stiffness spread's draws are smallest there.
    softest = {}
    for layout, n, kbar, seed, grid, phi, rough, shape in cases:
        key = (layout, n, seed, grid, phi, rough, shape)
        softest[key] = min(float(kbar), softest.get(key, math.inf))
    # A mistyped N would leave its brush on `grid` without a word; an entry
    # kept for a brush taken out of the lists for now is fine: warn.
    stray = sorted(by_n - {key[1] for key in softest})
    if stray and main:  # once, not in every job's log
        ran = sorted({key[1] for key in softest})
        logger.warning(
            f"config: grid_by_n names N = {stray}, which no brush of the sweep has "
            f"(the sweep runs N = {ran}): ignored"
        )
    makes = {
        key: functools.partial(_case_params, config, key, kbar)
        for key, kbar in softest.items()
    }
    # the narrowest pillar's radius of each case on each grid, as the study's flags read it
    radii = {}
    for at, make in makes.items():
        layout, n, seed, grid, phi, rough, shape = at
        try:
            # hinted below, with the brushes sharing the grid
            params = make(grid)
            radii[at] = smallest_radius_elements(params, build_labels(params))
        except ParameterError as exc:
            # A grid to suggest must run every brush the same grid key sets.
            key = n if n in by_n else None
            others = [
                m
                for (_, n2, _, g2, *_), m in makes.items()
                if m is not make and g2 == grid and (n2 if n2 in by_n else None) == key
            ]
            exc = grid_hint(exc, make, grid, others)
            fig5 = config["fig5"]
            only_fig5 = (
                layout == fig5["layout"]
                and n == int(fig5["n_pillars"])
                and n not in config.get(layout, [])
            )
            keys = {
                "n_pillars": "fig5.n_pillars" if only_fig5 else layout,
                "seed": "seeds",
                "grid": "grid_by_n.grid" if n in by_n else "grid",
                "allow_coarse": "allow_coarse: true",
                "min_gap": "min_gap (CLI only: --min-gap)",
            }
            rough_keys = [
                f"{k} = {v!r}" for k, v in parse_rough_tag(rough).items() if v
            ]
            case = ", ".join(
                [f"{layout} N = {n}", f"grid = {grid}", f"phi = {phi}"]
                + ([f"shape = {shape[1:]}"] if shape else [])
                + rough_keys
            )
            raise ConfigError(
                f"config: {exc.in_terms_of(keys, sep=' = ')} (case {case})"
                + _also_refused(makes, at, keys["grid"])
                + _inherited_note(config, layout, only_fig5)
            ) from None
    if main:  # a plan that stands: what it leaves out
        _warn_two_grids(config)
        _warn_coarse_study(radii)


def _brush_grids(cases):
    """{brush: {grid: value}} of a {(layout, n, seed, grid, phi, rough, shape):
    value} mapping: each brush (its case but the grid) with the grids it runs on."""
    out = {}
    for case, value in cases.items():
        out.setdefault(case[:3] + case[4:], {})[case[3]] = value
    return out


def _also_refused(makes, refused, key):
    """The other grids of a refused brush that refuse it too, as a clause of
    its error in the config's words (``key``: grid or grid_by_n.grid), so
    that one edit of its grid list deals with them all, not one per run."""
    grids = _brush_grids(makes)[refused[:3] + refused[4:]]
    more = []
    for g2, make in grids.items():
        if g2 == refused[3]:
            continue
        try:
            build_labels(make(g2))
        except ParameterError:
            more.append(g2)
    if not more:
        return ""
    return f"; {key} = {sorted(more)} refuse{'s' * (len(more) == 1)} it too"


def _given_offsets(brush):
    """Whether a `layout_files` brush is given heights or a gap map: it
    touches with its highest pillars first, and roughness draws it none."""
    return bool({"heights", "gap_map"} & set(brush.inputs))


def _uneven_files(brushes):
    """The `layout_files` keys of the brushes given heights or a gap map."""
    return [
        f"layout_files.{i}"
        for i, brush in enumerate(brushes.values())
        if _given_offsets(brush)
    ]


def _warn_first_waypoint(config, brushes):
    """Warn where a protocol starts with a tensile force and a brush touches
    with its highest pillars only at first (drawn heights, a table's heights
    or gap map): it pulls on those, as a preload of the wrong sign does
    (`first_waypoint_note` says it in a job, and of a displacement above the
    first touch, which needs the drawn heights)."""
    protocol = config_protocol(config)
    if protocol is None or protocol[0].kind != "force" or protocol[0].value <= 0:
        return
    uneven = _uneven_files(brushes) + [
        f"roughness = {float(s)!r}" for s in config["roughness"] if float(s) > 0
    ]
    if uneven:
        logger.warning(
            f"config: 'protocol' starts with a tensile force of {protocol[0].value:g} F_K: "
            f"the brushes of {', '.join(uneven)} touch with their highest pillars only "
            "at first, and it pulls on those, not on the brush pressed on (a preload P "
            "is force:-P)"
        )


def _warn_first_touch(config, brushes):
    """Warn where a brush as made, given heights or a gap map, runs preload 0:
    its approach stops at first touch, so only the pillars that touched pull
    off (the CLI says so after the run; a sweep should before it)."""
    if config.get("protocol") is not None or 0.0 not in map(float, config["preload"]):
        return
    uneven = _uneven_files(brushes)
    if uneven:
        logger.warning(
            f"config: the brush of {', '.join(uneven)} is given heights or a gap map, "
            "and 'preload' holds 0.0: that approach stops at first touch, so its "
            "pull-off is that of the pillars that touched; add a load to 'preload' "
            "to press it on"
        )
    drawn = sorted(float(s) for s in config["roughness"] if float(s) > 0)
    if drawn:
        logger.warning(
            f"config: 'roughness' holds {drawn} and 'preload' holds 0.0: a rough "
            "brush's approach at preload 0 stops at first touch, so its pull-off is "
            "that of the pillar that touched first; add a load to 'preload' to press "
            "it on"
        )


def _warn_unused(config, cases):
    """Warn where a listed seed or stiffness spread reaches no case: flat
    lattice brushes run seed 0 only and rigid ones no spread, so the value
    would seem to count ('grid_by_n' warns alike)."""
    seeds = sorted({int(s) for s in config["seeds"]} - {int(c[3]) for c in cases})
    used = {parse_rough_tag(c[6]).get("kbar_spread", 0.0) for c in cases}
    spreads = sorted({float(c) for c in config["kbar_spread"]} - used)
    if seeds:
        logger.warning(
            f"config: 'seeds' holds {seeds}, which no brush of the sweep draws from "
            "(flat lattices and layout files run seed 0 only; random layouts, "
            "roughness and kbar_spread draw from the seed): ignored"
        )
    if spreads:
        logger.warning(
            f"config: 'kbar_spread' holds {spreads}, which no brush of the sweep runs "
            "(rigid pillars, kbar .inf, and brushes given their stiffness in "
            "kbar_factors run no spread): ignored"
        )


def check_cluster_threads(config, cores, jobs, main):
    """Stop a run with `--jobs` whose `cores` would cut the config's `threads`.

    With `jobs` given (`--jobs`, the Slurm profile's `jobs`) Snakemake caps
    every rule's threads at `cores`, and on a cluster the job asks Slurm for
    that many CPUs: `threads: 2` under the profile's `cores: 1` ran one
    thread without a word.  (The Snakefile cannot see the executor while it
    is read, so a local run with `--jobs` and too few `--cores` stops too;
    its threads would be cut all the same.)  A larger `cores` is harmless:
    a job asks for `threads` CPUs.  `main`: only the Snakemake that plans
    the run checks (the ones inside a Slurm job run with the node's cores).
    """
    threads = int(config["threads"])
    if jobs is None or not main or cores is None or int(cores) >= threads:
        return
    raise ConfigError(
        f"config key 'threads': {threads}, but Snakemake's cores is {cores}, which caps "
        f"every job at {cores} thread(s) (and on a cluster {cores} CPU(s)): set "
        f"`cores: {threads}` in the profile or pass --cores {threads}"
    )


#: Deterministic layouts: their label maps are built at plan time, and a flat
#: brush runs seed 0 only.
LATTICES = ("regular", "hexagonal")


def kbar_tag(kbar):
    """File-name form of a stiffness: the shortest exact repr (1e-06, 0.455)."""
    return repr(float(kbar))


def config_protocol(config):
    """The config's `protocol` as waypoints (None when not given), refused at
    plan time, naming the key, when it does not parse or comes with a preload."""
    text = config.get("protocol")
    if text is None:
        return None
    try:
        protocol = parse_protocol(text)
    except ParameterError as exc:
        raise ConfigError(f"config: {exc.in_terms_of({}, sep=' = ')}") from None
    if protocol[-1].kind != "separation":
        raise ConfigError(
            f"config key 'protocol': {text!r} does not end with 'separation'; allowed a "
            "protocol that does (the sweep's F_ad, W, summary and figures read its last "
            "retraction as a pull-off; `brushcore simulate --protocol` runs a partial cycle)"
        )
    if [float(p) for p in config["preload"]] != [0.0]:
        raise ConfigError(
            f"config key 'preload': {config['preload']} must be [0.0] when 'protocol' is "
            "given (its force waypoints are the loads)"
        )
    return protocol


def protocol_digest(config):
    """Eight hex digits naming the config's protocol in file names ("" for none)."""
    protocol = config_protocol(config)
    if protocol is None:
        return ""
    return hashlib.sha256(protocol_text(protocol).encode()).hexdigest()[:8]


def rough_tag(roughness, preload, kbar_spread, protocol=""):
    """File-name suffix of a rough brush or a protocol (`protocol_digest`); ""
    for the flat brush pulled off from full contact (names unchanged)."""
    values = (float(roughness), float(preload), float(kbar_spread))
    if values == (0.0, 0.0, 0.0) and not protocol:
        return ""
    return "_S{!r}_P{!r}_C{!r}".format(*values) + (f"_Q{protocol}" if protocol else "")


def parse_rough_tag(tag):
    """BrushParams fields of a `rough_tag` suffix (the protocol comes from the config)."""
    if not tag:
        return {}
    s, rest = tag[2:].split("_P")
    p, c = rest.split("_C")
    return {
        "roughness": float(s),
        "preload": float(p),
        "kbar_spread": float(c.split("_Q")[0]),
    }


def _rough_tags(config, kbar):
    """Suffixes of every (roughness, preload, kbar_spread) asked for, with the
    config's protocol; rigid pillars have no stiffness spread."""
    spreads = [0.0] if float(kbar) == float("inf") else config["kbar_spread"]
    digest = protocol_digest(config)
    return sorted(
        {
            rough_tag(s, p, c, digest)
            for s in config["roughness"]
            for p in config["preload"]
            for c in spreads
        }
    )


def shape_tag(config, shape):
    """File-name suffix of a pillar shape: "" for discs (names unchanged), else
    "_" + `shape_label` with the config's aspect (ellipses) and orientation."""
    if shape == "disc":
        return ""
    aspect = config["aspect"] if shape == "ellipse" else 1.0
    return "_" + shape_label(shape, aspect, config["orientation"])


def parse_shape_tag(tag):
    """BrushParams fields of a `shape_tag` suffix ({} for discs)."""
    return parse_shape_label(tag[1:]) if tag else {}


def _deterministic_seeds(config, rough):
    """The seeds a brush of a fixed layout (lattice, file) runs: every seed where
    heights or stiffnesses are drawn from it (`rough`), else seed 0 only."""
    fields = parse_rough_tag(rough)
    drawn = fields.get("roughness", 0.0) + fields.get("kbar_spread", 0.0) > 0
    return config["seeds"] if drawn else [0]


def sweep_cases(config):
    """Every (layout, n_pillars, kbar, seed, grid, phi, rough, shape) the config asks for, once.

    Flat lattice brushes (regular, hexagonal) ignore the seed, so they run with
    seed 0 only; rough or graded ones (heights and stiffness drawn from the
    seed) run every seed.  Every brush runs every pillar shape of `shape`.
    The Fig. 5 brush adds its own kbar values to the sweep of its layout and
    shape.
    """
    phi = config["phi"]
    cases = set()
    shapes = [shape_tag(config, s) for s in config["shape"]]

    def lattice(layout, n, kbar, shape):
        for rough in _rough_tags(config, kbar):
            for seed in _deterministic_seeds(config, rough):
                cases.add((layout, n, kbar_tag(kbar), seed, rough, shape))

    for layout in LATTICES:
        for n in config[layout]:
            for kbar in config["kbar"]:
                for shape in shapes:
                    lattice(layout, n, kbar, shape)
    fig5 = config["fig5"]
    for kbar in fig5["kbar"]:
        lattice(
            fig5["layout"], fig5["n_pillars"], kbar, shape_tag(config, fig5["shape"])
        )
    for n in config["random"]:
        for kbar in config["kbar"]:
            for seed in config["seeds"]:
                for rough in _rough_tags(config, kbar):
                    for shape in shapes:
                        cases.add(("random", n, kbar_tag(kbar), seed, rough, shape))
    ordered = sorted(cases, key=lambda c: (c[0], c[1], float(c[2]), c[3], c[5], c[4]))
    # A map on its own grid, a table on the sweep's, with the file's N and
    # phi; discs of any shape.
    files = set()
    for layout, brush in file_brushes(config).items():
        grids = [brush.grid] if brush.grid else case_grids(config, brush.n_pillars)
        for kbar in config["kbar"]:
            for rough in _file_rough_tags(config, kbar, brush):
                for seed in _deterministic_seeds(config, rough):
                    for grid in grids:
                        files.add(
                            (
                                layout,
                                brush.n_pillars,
                                kbar_tag(kbar),
                                seed,
                                grid,
                                brush.phi,
                                rough,
                                "",
                            )
                        )
    return [
        (*case[:4], grid, phi, case[4], case[5])
        for case in ordered
        for grid in case_grids(config, case[1])
    ] + sorted(files, key=lambda c: (c[0], float(c[2]), c[3], c[6], c[4]))


def grid_list(value):
    """A config grid (an integer or a list of integers) as a sorted list."""
    return sorted({int(value)} if isinstance(value, int) else {int(g) for g in value})


def case_grids(config, n_pillars):
    """The grids a brush of `n_pillars` runs on: `grid_by_n` if it names N, else `grid`."""
    for entry in config.get("grid_by_n", []):
        if int(entry["n_pillars"]) == int(n_pillars):
            return grid_list(entry["grid"])
    return grid_list(config["grid"])


#: The config every run starts from (the Snakefile's `configfile:`), which a
#: user's --configfile extends key by key.
DEFAULT_CONFIG = "config/config.yaml"


def _inherited_note(config, layout, only_fig5):
    """Where a refused brush's list is the default config's and other config
    files were given, say where it comes from: a config of one's own that
    leaves out `random` still runs the paper's random brushes."""
    if len(workflow.configfiles) < 2:
        return ""
    try:
        with open(Path(workflow.basedir) / DEFAULT_CONFIG, encoding="utf-8") as fh:
            default = yaml.safe_load(fh)
    except (OSError, yaml.YAMLError):
        return ""
    key = "fig5" if only_fig5 else layout
    if key not in default:
        return ""
    mine = config.get(key)
    if only_fig5:  # the schema adds fig5's defaults (layout, shape) to both
        mine = {k: v for k, v in mine.items() if k in default[key]}
    if mine != default[key]:
        return ""
    unset = "fig5: {kbar: []}" if only_fig5 else f"{layout}: []"
    return (
        f"; this brush's '{key}' is {DEFAULT_CONFIG}'s, which your config files extend: "
        f"set '{unset}' to run none"
    )


def _warn_two_grids(config):
    """Say so where brushes run on two grids and none on three: a refinement
    with no convergence study (it needs three grids to observe an order)."""
    two = sorted(n for n in sweep_brushes(config) if len(case_grids(config, n)) == 2)
    if two and not wants_convergence(config):
        logger.warning(
            f"config: N = {two} run on two grids each; the convergence study "
            "(results/convergence.*) needs three or more, so none is made"
        )


def _warn_coarse_study(radii):
    """Warn where a brush of the refinement study runs on a grid that gives its
    narrowest pillar under `UNDER_RESOLVED_RADIUS` elements a radius: the study
    flags its fits coarsest_under_resolved (or under_resolved, where the finest
    grid is too), known before any job.  ``radii``: the narrowest pillar's
    radius [elements] of each case on each grid it runs on (a label map keeps
    its own), as `check_cases` found it."""
    coarse = {}
    for brush, radius in _brush_grids(radii).items():
        if len(radius) < 3:  # no study of this brush
            continue
        low, high = min(radius), max(radius)
        if (
            radius[low] < UNDER_RESOLVED_RADIUS
            and radius[low] < coarse.get(brush[1], (math.inf,))[0]
        ):
            flag = (
                "under_resolved"
                if radius[high] < UNDER_RESOLVED_RADIUS
                else "coarsest_under_resolved"
            )
            need = math.ceil(low * UNDER_RESOLVED_RADIUS / radius[low])
            coarse[brush[1]] = (radius[low], low, need, flag)
    if coarse:
        text = "; ".join(
            f"N = {n} on {g}: {r:.2g} elements ({flag}; n = {need} gives "
            f"{UNDER_RESOLVED_RADIUS:g})"
            for n, (r, g, need, flag) in sorted(coarse.items())
        )
        logger.warning(
            f"config: the convergence study's coarsest grid gives pillars a radius under "
            f"{UNDER_RESOLVED_RADIUS:g} elements, so their fits will be flagged as it "
            f"says ({text}): they rest on a grid whose own mesh error is a few per cent"
        )


def wants_convergence(config):
    """True when some brush runs on three or more grids: the refinement study is made."""
    return any(len(case_grids(config, n)) >= 3 for n in sweep_brushes(config))


def snapshot_brushes(config):
    """(layout, N) whose contact snapshots sweep.nc keeps for Fig. 5: its
    brush where `fig5.kbar` lists a stiffness, none where Fig. 5 is off."""
    fig5 = config["fig5"]
    return [(fig5["layout"], fig5["n_pillars"])] if fig5["kbar"] else []


def sweep_brushes(config):
    """Every pillar number N run on the sweep's grids (every layout, the Fig. 5
    brush and pillar tables)."""
    fig5 = config["fig5"]
    tables = [b.n_pillars for b in file_brushes(config).values() if b.grid is None]
    return {
        *config["regular"],
        *config["hexagonal"],
        *config["random"],
        *([fig5["n_pillars"]] if fig5["kbar"] else []),
        *tables,
    }


#: One curve file per case; every parameter that changes the curve is in its name,
#: so that a sweep on another grid or filling factor never overwrites it.  The
#: shape and rough suffixes are empty for the flat brush of discs.
CURVE_NAME = (
    "{layout}/N{n_pillars}_kbar{kbar}_seed{seed}_grid{grid}_phi{phi}{shape}{rough}"
)


def curve_file(layout, n_pillars, kbar, seed, grid, phi, rough, shape=""):
    """The curve file of one case (a tuple of `sweep_cases`)."""
    name = CURVE_NAME.format(
        layout=layout,
        n_pillars=n_pillars,
        kbar=kbar,
        seed=seed,
        grid=grid,
        phi=repr(float(phi)),
        shape=shape,
        rough=rough,
    )
    return f"results/curves/{name}.nc"


def curve_files(config):
    """The curve file of every case of the sweep."""
    return [curve_file(*case) for case in sweep_cases(config)]


def named_case(case):
    """What the curve file of a case must record: the fields of
    `brushcore.data.aggregate.CaseKey`, then phi (plain values, for the script)."""
    layout, n_pillars, kbar, seed, grid, phi, rough, shape = case
    rough = parse_rough_tag(rough)
    return [
        layout,
        int(n_pillars),
        float(kbar),
        int(seed),
        int(grid),
        *(rough.get(name, 0.0) for name in ("roughness", "preload", "kbar_spread")),
        shape[1:] if shape else "disc",
        float(phi),
    ]


def simulate_mem_mb(wildcards):
    """Memory of one simulation [MB], the same on every attempt.

    Measured peak RSS (README, "Speed and memory"): at most 0.6 GB at grid
    512, 1.05 GiB for a flat curve and 3.4 GB for the rough 8 x 8 brush at
    1024, 2.7 GiB at 2048 (random 1620).  Granted: 1 GB, the FFT buffers at
    150 MB x (n/512)^2, and above 512 the 4 GB that per-pillar block inverses
    may take (`BlockInverse.fits`): 1.15 GB at 512, 5.6 GB at 1024, 7.4 GB
    at 2048.  Snakemake tells a resource function the attempt, not why the
    last one failed, and a time limit is the likelier cause with these
    margins: a retry asks for more time (`simulate_runtime`), not memory.
    """
    grid = int(wildcards.grid)
    blocks = 4000 if grid > 512 else 0
    return int(1000 + 150 * (grid / 512) ** 2 + blocks)


def check_local_backend(config, local):
    """Refuse `backend: gpu` before the first job where the jobs run on this
    machine (``local``: Snakemake's local executor) and it has no CuPy or no
    card; jobs sent to a cluster check on their own node, as each job does
    before any work.  Called from `onstart`, once the executor is known."""
    if not local or config.get("backend", "cpu") != "gpu":
        return
    try:
        resolve_backend("gpu")
    except ParameterError as exc:
        raise ConfigError(
            f"config key 'backend': 'gpu' is invalid on this machine ({exc.reason}): "
            "allowed 'cpu' here, or 'gpu' where CuPy and a CUDA device are (a cluster "
            "executor's jobs check on their node)"
        ) from None


def simulate_gpus(config):
    """Cards one simulate job holds: 1 with backend gpu (Snakemake resource
    `gpu`, limited locally by `--resources gpu=N`), else 0."""
    return 1 if config.get("backend", "cpu") == "gpu" else 0


def simulate_gres(config):
    """Slurm generic resource of one simulate job: "gpu:1" with backend gpu.

    The Slurm profile zeroes the `gpu` resource for simulate (the plugin
    would add --gpus, which Slurm treats as a second GPU request), so that
    Slurm sees this --gres=gpu:1 alone.
    """
    return "gpu:1" if simulate_gpus(config) else ""


#: The slowest curve measured per kind and grid (`SLOWEST_CURVE_S`,
#: `RUNTIME_EXPONENT`, the settings' `slowdown`) is `brushcore.model.cost`'s,
#: which the command's note before a long run reads too.
#: Margin over the slowest measured curve: nodes 2-3x slower than the
#: development machine, and 1.3x between days on one machine.
RUNTIME_SAFETY = 3
#: Minutes for what is not the curve: Python's and the nested Snakemake's
#: start, FFTW planning on a fresh node, the shared file system's latency.
RUNTIME_OVERHEAD_MIN = 5


def curve_kind(layout, shape, rough, solver=None, offsets=False):
    """The `SLOWEST_CURVE_S` kind of a curve (`brushcore.model.cost.kind_of`,
    as the command's note asks it) from its wildcards (shape and rough
    suffixes), whether its brush is given heights or a gap map
    (``offsets``, `_given_offsets`) and the config's solver settings
    (``symmetry: false`` solves a regular brush on the whole grid)."""
    uneven = (
        parse_rough_tag(rough).get("roughness", 0.0) > 0 or "_Q" in rough or offsets
    )
    folded = (solver or {}).get("symmetry", True)
    return kind_of(
        uneven=uneven,
        mirrored=layout == "regular" and not shape and not rough and folded,
    )


def solver_slowdown(solver, kind):
    """Factor on a curve's time for the config's solver settings
    (`brushcore.model.cost.slowdown`, `is_exact`); 1 for the defaults."""
    options = SolverOptions(**(solver or {}))
    return slowdown(kind, exact=is_exact(options), double=options.precision == "double")


def curve_minutes(layout, shape, rough, grid, solver=None, offsets=False):
    """Time limit of a curve's first attempt [min]: `RUNTIME_SAFETY` x the
    slowest measured curve of its kind and grid, times `solver_slowdown` of
    the config's ``solver`` settings, plus `RUNTIME_OVERHEAD_MIN`.

    With the default solver: 1024^2 12 min regular, 39 min random, 18 h
    rough; 2048^2 66 min regular, 13.1 h random.  The time does not shrink
    with `threads`: the measurements are on one thread, and a second gains
    at most 2x.
    """
    kind = curve_kind(layout, shape, rough, solver, offsets)
    seconds = (
        RUNTIME_SAFETY * slowest_curve_s(kind, grid) * solver_slowdown(solver, kind)
    )
    return math.ceil(RUNTIME_OVERHEAD_MIN + seconds / 60)


def _offsets(config, layout):
    """Whether ``layout`` is a `layout_files` brush given heights or a gap map."""
    if not layout.startswith(FILE_LAYOUT_PREFIX):
        return False  # a generated layout: no files to read
    brush = file_brushes(config).get(layout)
    return bool(brush) and _given_offsets(brush)


def simulate_runtime(config):
    """The simulate rule's `runtime` [min]: `curve_minutes`, doubled on a retry
    (a time limit is the likelier cause of a failure), clipped to the config's
    `slurm_max_runtime_min` (`clipped_runtimes` warns at plan time)."""
    cap = config.get("slurm_max_runtime_min")

    def runtime(wildcards, attempt):
        minutes = attempt * curve_minutes(
            wildcards.layout,
            wildcards.shape,
            wildcards.rough,
            int(wildcards.grid),
            config.get("solver"),
            _offsets(config, wildcards.layout),
        )
        return minutes if cap is None else min(minutes, int(cap))

    return runtime


def clipped_runtimes(config):
    """The plan-time warning for curves whose first attempt asks for more than
    `slurm_max_runtime_min`, or None: how many, and the largest request."""
    cap = config.get("slurm_max_runtime_min")
    if cap is None:
        return None
    asked = [
        (
            curve_minutes(
                layout,
                shape,
                rough,
                grid,
                config.get("solver"),
                _offsets(config, layout),
            ),
            curve_file(layout, n, kbar, seed, grid, phi, rough, shape),
        )
        for layout, n, kbar, seed, grid, phi, rough, shape in sweep_cases(config)
    ]
    over = sorted((a for a in asked if a[0] > int(cap)), reverse=True)
    if not over:
        return None
    minutes, name = over[0]
    return (
        f"slurm_max_runtime_min = {cap} clips the time limit of {len(over)} of "
        f"{len(asked)} simulations (the largest: {minutes} min for {name}); a curve "
        f"that needs longer is killed at {cap} min (its retry too) and writes nothing"
    )


ROUGH_FIGURES = ("rough_roughness", "rough_preload")


def rough_brush(config, axes=True):
    """(layout, N) the rough figures show: the first brush as made (a
    `layout_files` entry given heights, stiffness or a gap map: the paper's
    figures leave it out, so these show it), else the first regular brush,
    else the first hexagonal, else the first random, else the first file.
    For the figures with a roughness axis (`axes`) the brushes whose heights
    `roughness` draws come first where it draws any: generated ones, then
    tables and maps given no heights or gap map (a brush given heights has
    no roughness axis)."""
    files = file_brushes(config)
    made = [(layout, b.n_pillars) for layout, b in files.items() if b.inputs]
    generated = [
        (layout, int(config[layout][0]))
        for layout in (*LATTICES, "random")
        if config[layout]
    ]
    drawn = axes and any(float(s) > 0 for s in config["roughness"])
    roughened = [
        (layout, b.n_pillars) for layout, b in files.items() if not _given_offsets(b)
    ]
    for brush in (generated + roughened + made) if drawn else (made + generated):
        return brush
    for layout, brush in files.items():
        return layout, brush.n_pillars
    return config["fig5"]["layout"], int(config["fig5"]["n_pillars"])


CURVE_FIGURES = ("rough_loop", "load_sharing")


def rough_example_curve(config):
    """The curve file the one-curve rough figures show, or None for a flat sweep.

    The brush of `rough_brush`, seed 0, the largest roughness and preload
    asked for (a brush as made: any, preload 0 too), and the finite kbar
    closest to 0.01 on a log scale (soft enough that pillars share load,
    stiff enough that they interact).
    """
    brush = rough_brush(config, axes=False)  # one curve: the brush as made first
    entry = file_brushes(config).get(brush[0])
    made = bool(entry and entry.inputs)
    rough = [
        c
        for c in sweep_cases(config)
        if (c[6] or made)
        and not c[7]
        and (c[0], c[1]) == brush
        and c[3] == 0
        and float(c[2]) < float("inf")
    ]
    if not rough:
        return None

    def rank(case):
        tag = parse_rough_tag(case[6])  # {} for a brush as made at preload 0
        return (
            -tag.get("roughness", 0.0),
            -tag.get("preload", 0.0),
            tag.get("kbar_spread", 0.0),
            abs(math.log10(float(case[2])) + 2.0),
        )

    return curve_file(*min(rough, key=rank))


def rough_figure_files(config):
    """The rough-brush figures, for configs that ask for rough cases only."""
    flat = all(
        float(v) == 0.0
        for key in ("roughness", "preload", "kbar_spread")
        for v in config[key]
    )
    if flat and config.get("protocol") is None and not made_brush(config):
        return []
    names = ROUGH_FIGURES + (CURVE_FIGURES if rough_example_curve(config) else ())
    return [f"results/figures/{name}.{ext}" for name in names for ext in ("png", "pdf")]


def wants_lattice_figure(config):
    """True when the sweep compares lattices or shapes: hexagonal brushes or non-disc pillars."""
    return bool(config["hexagonal"]) or any(s != "disc" for s in config["shape"])


def lattice_figure_files(config):
    """The lattice comparison figure, for configs that ask for one."""
    if not wants_lattice_figure(config):
        return []
    return [f"results/figures/lattices.{ext}" for ext in ("png", "pdf")]


CONVERGENCE_FILES = (
    "results/convergence.nc",
    "results/convergence.csv",
    "results/convergence.md",
    "results/figures/convergence.png",
    "results/figures/convergence.pdf",
)


def sweep_targets(config):
    """What the default target makes of a config: sweep.nc, the summary, the figures
    it asks for, and the refinement study where some brush runs on three or
    more grids."""
    return [
        "results/sweep.nc",
        "results/summary.csv",
        "results/summary.md",
        *paper_figure_files(config),
        *rough_figure_files(config),
        *lattice_figure_files(config),
        *(CONVERGENCE_FILES if wants_convergence(config) else ()),
    ]


#: When this Snakemake read its Snakefile [s since the epoch]: what it writes is newer.
PLANNED_AT = time.time()


def stale_outputs(config, root=".", since=None):
    """A warning naming the figures and tables in results/ that some other
    config made and this one does not (None where there are none): Snakemake
    leaves them, beside this sweep's sweep.nc, as if they were its own.
    Files written since ``since`` (default `PLANNED_AT`) are this run's own
    (a target named on the command line), not stale."""
    since = PLANNED_AT if since is None else since
    names = (
        *ROUGH_FIGURES,
        *CURVE_FIGURES,
        "lattices",
        *(f"fig{n}" for n in (5, 6, 7, 8)),
    )
    made = {f"results/figures/{n}.{ext}" for n in names for ext in ("png", "pdf")}
    wanted = set(sweep_targets(config))
    stale = sorted(
        p
        for p in made | set(CONVERGENCE_FILES)
        if p not in wanted
        and Path(root, p).exists()
        and Path(root, p).stat().st_mtime < since
    )
    if not stale:
        return None
    return (
        f"{len(stale)} file{'s' * (len(stale) != 1)} in results/ "
        f"{'are' if len(stale) != 1 else 'is'} from an earlier sweep, which this config "
        f"does not make: {', '.join(stale)}. Remove {'them' if len(stale) != 1 else 'it'} "
        "(curve files in results/curves/ are kept and reused), or give each config its "
        "own working copy"
    )


def paper_figure_files(config):
    """Figs. 5-8 (PNG and PDF); Fig. 5 only where `fig5.kbar` lists a stiffness."""
    numbers = ([5] if config["fig5"]["kbar"] else []) + [6, 7, 8]
    return [f"results/figures/fig{n}.{ext}" for n in numbers for ext in ("png", "pdf")]


def fig5_shape(config):
    """`shape_label` of the Fig. 5 brush's pillars (the sweep slice it is drawn from)."""
    tag = shape_tag(config, config["fig5"]["shape"])
    return tag[1:] if tag else "disc"


def fig5_options(config):
    """Keyword arguments of `figures.fig5`: the Fig. 5 config with its shape label."""
    return {**config["fig5"], "shape": fig5_shape(config)}
