"""The config's checks: its YAML, its schema and the cases it asks for,
refused by key before any job starts."""

import difflib
import functools
import math
import re
from pathlib import Path

import jsonschema
import yaml
from snakemake.logging import logger

from brushcore.data.convergence import UNDER_RESOLVED_RADIUS
from brushcore.data.simulate_job import case_params
from brushcore.model.params import ParameterError
from brushcore.model.layout import build_labels, grid_hint, smallest_radius_elements
from brushcore.numerics.options import SolverOptions
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
    bad_phi = _bad_phi(config, schema)
    if bad_phi:
        raise ConfigError(bad_phi)
    error = jsonschema.exceptions.best_match(
        jsonschema.Draft202012Validator(schema).iter_errors(config)
    )
    if error is None:
        where = _first_nan(config)
        if where is not None:
            raise ConfigError(
                f"config key '{where}': nan is not a number; allowed "
                f"{_schema_range(schema, where)}"
            )
        _integral_counts(config)
        _shape_settings_used(config, schema)
        _warn_near_duplicates(config)
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
    if error.validator == "type" and error.instance is None:
        # `kbar:` with nothing after it
        message += "; the key is empty (YAML reads that as null): give it a value, or leave it out for its default"
    elif error.validator == "type" and isinstance(error.instance, bool):
        # backend: off, kbar: [no]
        message += (
            "; YAML reads yes/no/on/off/true/false as true or false: quote a word "
            "meant as text ('off'), or give what the key takes"
        )
    elif (
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


def _resolved(schema, node):
    """A schema node with its `$ref` to `$defs` followed."""
    while "$ref" in node:
        node = schema["$defs"][node["$ref"].rsplit("/", 1)[-1]]
    return node


def _forms(schema, node):
    """A schema node and the forms of its `oneOf` (a number or a list: phi, grid)."""
    node = _resolved(schema, node)
    return [node, *(_resolved(schema, form) for form in node.get("oneOf", []))]


_BOUNDS = {"minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"}


def _schema_range(schema, where):
    """The range the schema allows at a dotted config key ("phi", "phi.1",
    "kbar.0", "fig5.kbar.1"), in a message's words: "a number in (0, 0.5]"."""
    node = schema
    for part in where.split("."):
        if part.isdigit():  # the list form's items
            node = next((f["items"] for f in _forms(schema, node) if "items" in f), {})
        else:
            node = _resolved(schema, node).get("properties", {}).get(part, {})
    node = next((f for f in _forms(schema, node) if _BOUNDS & set(f)), {})
    low = node.get("exclusiveMinimum", node.get("minimum"))
    high = node.get("exclusiveMaximum", node.get("maximum"))
    if high is None:
        sign = ">" if "exclusiveMinimum" in node else ">="
        return "a number" if low is None else f"a number {sign} {low:g}"
    if low is None:
        return f"a number {'<' if 'exclusiveMaximum' in node else '<='} {high:g}"
    left = "(" if "exclusiveMinimum" in node else "["
    right = ")" if "exclusiveMaximum" in node else "]"
    return f"a number in {left}{low:g}, {high:g}{right}"


def _bad_phi(config, schema):
    """The first value of `phi` (a number, or each of a list) that is no
    number or out of the schema's range, named by its key with that range
    (the schema's two forms would say "fits none of its forms"); None where
    all are (a NaN is `_first_nan`'s, an empty or repeated list the schema's)."""
    value = config.get("phi")
    if value is None:
        return None
    items = (
        [(f"phi.{i}", v) for i, v in enumerate(value)]
        if isinstance(value, list)
        else [("phi", value)]
    )
    low, high = (
        schema["$defs"]["phi"]["exclusiveMinimum"],
        schema["$defs"]["phi"]["maximum"],
    )
    for where, v in items:
        number = isinstance(v, (int, float)) and not isinstance(v, bool)
        if number and (math.isnan(v) or low < v <= high):
            continue
        said = "is not a number" if not number else "is out of range"
        return (
            f"config key '{where}': {v!r} {said}; allowed "
            f"{_schema_range(schema, where)}"
            + (" or a list of such numbers" if where == "phi" else "")
        )
    return None


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


#: Numbers of one list closer than this (relative) are one value written two
#: ways: 0.1 * 3 and np.arange give 0.30000000000000004 beside 0.3.
NEAR_DUPLICATE_RTOL = 1e-9


def _near_duplicates(values):
    """The first pair of distinct finite numbers in ``values`` within
    `NEAR_DUPLICATE_RTOL` of each other, or None."""
    # floats only: integers (seeds, counts) a unit apart are distinct at any size
    numbers = sorted(v for v in values if isinstance(v, float) and math.isfinite(v))
    for a, b in zip(numbers, numbers[1:]):
        if a != b and abs(b - a) <= NEAR_DUPLICATE_RTOL * max(abs(a), abs(b)):
            return a, b
    return None


def _warn_near_duplicates(value, where=""):
    """Warn where a list holds one number written two ways: each runs as its
    own case, twice the work, and the sweep gets two coordinates an ulp apart."""
    if isinstance(value, (list, tuple)):
        pair = _near_duplicates(value)
        if pair is not None:
            a, b = pair
            logger.warning(
                f"config key '{where}': {a!r} and {b!r} differ by {abs(b - a) / abs(b):.1g} "
                "(relative): they run as two cases with two files; write them as one value"
            )
    for key, item in _children(value):
        _warn_near_duplicates(item, f"{where}.{key}" if where else str(key))


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
        which = brush[:2]  # (layout, N): two brushes of one N are told apart
        if (
            radius[low] < UNDER_RESOLVED_RADIUS
            and radius[low] < coarse.get(which, (math.inf,))[0]
        ):
            flag = (
                "under_resolved"
                if radius[high] < UNDER_RESOLVED_RADIUS
                else "coarsest_under_resolved"
            )
            need = math.ceil(low * UNDER_RESOLVED_RADIUS / radius[low])
            coarse[which] = (radius[low], low, need, flag)
    if coarse:
        text = "; ".join(
            f"{layout} N = {n} on {g}: {r:.2g} elements ({flag}; n = {need} gives "
            f"{UNDER_RESOLVED_RADIUS:g})"
            for (layout, n), (r, g, need, flag) in sorted(
                coarse.items(), key=lambda item: (item[0][1], item[0][0])
            )
        )
        logger.warning(
            f"config: the convergence study's coarsest grid gives pillars a radius under "
            f"{UNDER_RESOLVED_RADIUS:g} elements, so their fits will be flagged as it "
            f"says ({text}): they rest on a grid whose own mesh error is a few per cent"
        )
