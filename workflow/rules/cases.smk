"""The sweep's cases: wildcard tags, the cases a config expands to, their
grids and the curve files they name."""

import hashlib

from brushcore.model.inputs import (
    parse_protocol,
    protocol_text,
)
from brushcore.model.params import ParameterError
from brushcore.model.shapes import parse_shape_label, shape_label

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


def config_values(config, key):
    """A config key that takes a number or a list (phi, aspect, orientation),
    as a list of floats in its order."""
    value = config[key]
    return [float(v) for v in (value if isinstance(value, list) else [value])]


def shape_tags(config, shape):
    """File-name suffixes of a pillar shape, one per aspect (ellipses) and
    orientation the config lists: [""] for discs (names unchanged), else
    "_" + `shape_label` of each."""
    if shape == "disc":
        return [""]
    aspects = config_values(config, "aspect") if shape == "ellipse" else [1.0]
    return [
        "_" + shape_label(shape, aspect, orientation)
        for aspect in aspects
        for orientation in config_values(config, "orientation")
    ]


def shape_tag(config, shape):
    """The first of `shape_tags`: the Fig. 5 brush's, which draws one."""
    return shape_tags(config, shape)[0]


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
    seed) run every seed.  Every brush runs every pillar shape of `shape`,
    ellipses at every `aspect` and squares and ellipses at every `orientation`.
    The Fig. 5 brush adds its own kbar values to the sweep of its layout and
    shape.  Every generated brush runs at each `phi` (`config_values`); a file
    brush at its file's.
    """
    phis = config_values(config, "phi")
    cases = set()
    shapes = [tag for s in config["shape"] for tag in shape_tags(config, s)]

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
        for phi in phis
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


def _given_offsets(brush):
    """Whether a `layout_files` brush is given heights or a gap map: it
    touches with its highest pillars first, and roughness draws it none."""
    return bool({"heights", "gap_map"} & set(brush.inputs))


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
