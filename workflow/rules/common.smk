"""Helpers shared by the rules: config checks, the job list and resource estimates."""

import difflib

import jsonschema
import yaml

from brushcore.params import BrushParams, ParameterError
from brushcore.layout import build_labels


def check_config(config, schema_path):
    """Validate the config against its schema with one short message naming the key.

    Snakemake's `validate` prints the whole schema around the error; this
    reports the first error only, as "config key 'x': ...", with the closest
    known key for a typo.  Defaults are filled in afterwards by `validate`.
    """
    with open(schema_path) as fh:
        schema = yaml.safe_load(fh)
    error = jsonschema.exceptions.best_match(
        jsonschema.Draft202012Validator(schema).iter_errors(config)
    )
    if error is None:
        return
    where = ".".join(str(p) for p in error.absolute_path)
    if error.validator == "additionalProperties":
        known = sorted(error.schema.get("properties", {}))
        extra = sorted(set(error.instance) - set(known))
        close = difflib.get_close_matches(extra[0], known, n=1)
        hint = f"; did you mean '{close[0]}'?" if close else f"; known keys: {known}"
        prefix = f"{where}." if where else ""
        raise ConfigError(f"config key '{prefix}{extra[0]}' is unknown{hint}")
    raise ConfigError(f"config key '{where}': {error.message}")


class ConfigError(ValueError):
    """The config asks for something that cannot run; the message names the key."""


def check_cases(config):
    """Run every check that needs no solve, for every case, before any job starts.

    Builds the parameters of each case (ranges, the grid rule: pillar radius
    >= 2 elements) and the label map of each regular brush (realised phi within
    5 %), so that a config that cannot run stops `snakemake -n` already.
    Random layouts are packed in their jobs (seconds each); a packing failure
    fails that job.  The geometry does not depend on kbar: checked once.
    """
    named = [int(e["n_pillars"]) for e in config.get("grid_by_n", [])]
    twice = sorted({n for n in named if named.count(n) > 1})
    if twice:
        raise ConfigError(f"config key 'grid_by_n': N = {twice} listed more than once")
    seen = set()
    for layout, n, kbar, seed, grid, phi in sweep_cases(config):
        if (layout, n, seed, grid, phi) in seen:
            continue
        seen.add((layout, n, seed, grid, phi))
        try:
            params = BrushParams(
                layout, n, float(kbar), grid, phi=phi, seed=seed,
                allow_coarse=config["allow_coarse"],
            )
            if layout == "regular":
                build_labels(params)
        except ParameterError as exc:
            keys = {"n_pillars": layout, "allow_coarse": "allow_coarse: true"}
            raise ConfigError(
                f"config: {exc.in_terms_of(keys, sep=' = ')} "
                f"(case {layout} N = {n}, grid = {grid}, phi = {phi})"
            ) from None


def kbar_tag(kbar):
    """File-name form of a stiffness: the shortest exact repr (1e-06, 0.455)."""
    return repr(float(kbar))


def sweep_cases(config):
    """Every (layout, n_pillars, kbar, seed, grid, phi) the config asks for, once.

    Regular layouts ignore the seed, so they run with seed 0 only; the Fig. 5
    brush adds its own kbar values to the regular sweep.
    """
    phi = config["phi"]
    cases = set()
    for n in config["regular"]:
        for kbar in config["kbar"]:
            cases.add(("regular", n, kbar_tag(kbar), 0))
    fig5 = config["fig5"]
    for kbar in fig5["kbar"]:
        cases.add(("regular", fig5["n_pillars"], kbar_tag(kbar), 0))
    for n in config["random"]:
        for kbar in config["kbar"]:
            for seed in config["seeds"]:
                cases.add(("random", n, kbar_tag(kbar), seed))
    ordered = sorted(cases, key=lambda c: (c[0], c[1], float(c[2]), c[3]))
    return [(*case, grid, phi) for case in ordered for grid in case_grids(config, case[1])]


def grid_list(value):
    """A config grid (an integer or a list of integers) as a sorted list."""
    return sorted({int(value)} if isinstance(value, int) else {int(g) for g in value})


def case_grids(config, n_pillars):
    """The grids a brush of `n_pillars` runs on: `grid_by_n` if it names N, else `grid`."""
    for entry in config.get("grid_by_n", []):
        if int(entry["n_pillars"]) == int(n_pillars):
            return grid_list(entry["grid"])
    return grid_list(config["grid"])


def wants_convergence(config):
    """True when some brush runs on three or more grids: the refinement study is made."""
    return any(len(case_grids(config, n)) >= 3 for n in sweep_brushes(config))


def sweep_brushes(config):
    """Every pillar number N of the sweep (both layouts and the Fig. 5 brush)."""
    return {*config["regular"], *config["random"], config["fig5"]["n_pillars"]}


#: One curve file per case; every parameter that changes the curve is in its name,
#: so that a sweep on another grid or filling factor never overwrites it.
CURVE_NAME = "{layout}/N{n_pillars}_kbar{kbar}_seed{seed}_grid{grid}_phi{phi}"


def curve_files(config):
    """The curve file of every case of the sweep."""
    return [
        "results/curves/"
        + CURVE_NAME.format(
            layout=layout, n_pillars=n, kbar=kbar, seed=seed, grid=grid, phi=repr(float(phi))
        )
        + ".nc"
        for layout, n, kbar, seed, grid, phi in sweep_cases(config)
    ]


def simulate_mem_mb(wildcards, attempt):
    """Memory of one simulation [MB], doubled on a retry.

    Measured peak RSS at grid 512: 0.18-0.31 GB, 0.56 GB for 48 x 48 pillars
    (pillar-interaction matrices); FFT buffers and blocks scale with n^2.
    """
    grid = int(wildcards.grid)
    return int(400 + 800 * (grid / 512) ** 2) * attempt


def simulate_runtime(wildcards, attempt):
    """Wall-time limit of one simulation [min], doubled on a retry.

    Measured at grid 512 on one core: 2-150 s per curve; the cost grows
    about as n^3 (solves ~ n, each ~ n^2 log n).
    """
    grid = int(wildcards.grid)
    return int(5 + 15 * (grid / 512) ** 3) * attempt
