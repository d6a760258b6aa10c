"""Parameters: NumPy scalars accepted and normalised, one discretisation rule."""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np
import pytest

from brushcore import BrushParams, ParameterError, SolverOptions
from brushcore.model.layout import build_labels, hinted_params


def test_numpy_scalars_are_accepted_and_normalised():
    p = BrushParams("regular", np.int64(16), np.float32(0.1), np.int64(64),
                    phi=np.float32(0.12), seed=np.uint8(3))
    assert p == BrushParams("regular", 16, float(np.float32(0.1)), 64,
                            phi=float(np.float32(0.12)), seed=3)
    for name in ("n_pillars", "grid", "seed"):
        assert type(getattr(p, name)) is int, name
    for name in ("kbar", "phi", "e_star"):
        assert type(getattr(p, name)) is float, name
    for grid in np.array([64, 128]):  # what users write
        assert BrushParams("regular", 16, 0.1, grid).grid == int(grid)
    assert SolverOptions(rtol=np.float64(1e-5), max_iter=np.int32(10)).max_iter == 10
    # DataArray.values gives 0-d arrays, np.linspace integral floats (the
    # workflow's config takes 64.0 as 64 too)
    q = BrushParams("regular", np.array(16), np.array(0.1), np.linspace(64, 128, 2)[0])
    assert q == BrushParams("regular", 16, 0.1, 64) and type(q.grid) is int


def test_text_from_numpy_is_stored_as_text():
    """A text field taken from a sweep (``sweep.layout[0].values``, a 0-d
    array) was stored as the array: the brush could not be hashed, its
    curve got another parameter_hash, and a waypoint's kind wrote a
    protocol no reader parses ("['force']:-1.0, separation"; a review
    helper's find).  0-d arrays and np.str_ become str; an array of one
    value is refused, not compared element-wise."""
    from brushcore import Waypoint
    from brushcore.model.provenance import parameter_hash

    p = BrushParams(np.array("regular"), 16, 0.1, 64, shape=np.str_("square"))
    plain = BrushParams("regular", 16, 0.1, 64, shape="square")
    assert p == plain and hash(p) == hash(plain) and repr(p) == repr(plain)
    assert type(p.layout) is str and type(p.shape) is str
    assert parameter_hash(p.as_attrs()) == parameter_hash(plain.as_attrs())
    options = SolverOptions(cascade=np.array("global"), precision=np.str_("double"),
                            fft_library=np.array("auto"))
    assert hash(options) == hash(SolverOptions(cascade="global", precision="double"))
    kind = Waypoint(np.array("force"), -1.0).kind
    assert type(kind) is str and kind == "force"
    # a sweep's coordinate elements as they come (0-d DataArrays), numbers too
    import xarray as xr

    sweep = xr.Dataset(coords={"layout": ["regular"], "kbar": [0.1, math.inf], "grid": [64]})
    taken = BrushParams(sweep.layout[0], 16, sweep.kbar[0], sweep.grid[0])
    assert taken == BrushParams("regular", 16, 0.1, 64) and type(taken.kbar) is float
    assert type(taken.grid) is int and type(taken.layout) is str
    assert BrushParams("regular", 16, sweep.kbar[1], 64).kbar == math.inf
    # a str-mixin Enum's member is its text, not "Layout.regular" (str() of it)
    import enum

    class Layout(str, enum.Enum):
        regular = "regular"

    assert BrushParams(Layout.regular, 16, 0.1, 64).layout.__class__ is str
    assert BrushParams(Layout.regular, 16, 0.1, 64) == BrushParams("regular", 16, 0.1, 64)
    for make in (lambda: BrushParams(np.array(["regular"]), 16, 0.1, 64),
                 lambda: SolverOptions(cascade=np.array(["local"])),
                 lambda: Waypoint(np.array(["force"]), -1.0)):
        with pytest.raises(ParameterError, match="is invalid"):
            make()


def _refuse(kbar: float) -> None:
    BrushParams("regular", 16, kbar, 64)


def test_a_refusal_crosses_a_process_pool():
    """ParameterError pickled its message alone, which its constructor cannot
    take: a worker's refusal broke a ProcessPoolExecutor (BrokenProcessPool,
    the message lost) and hung multiprocessing.Pool.map.  It now arrives
    whole; a value that does not pickle arrives as its repr."""
    import pickle
    from concurrent.futures import ProcessPoolExecutor

    error = pickle.loads(pickle.dumps(ParameterError("kbar", -1.0, "a number", "why")))
    assert (error.name, error.value, error.allowed, error.reason) == ("kbar", -1.0, "a number",
                                                                      "why")
    assert str(error) == "kbar=-1.0 is invalid (why): allowed a number"
    odd = pickle.loads(pickle.dumps(ParameterError("protocol", (w for w in ()), "a tuple")))
    assert odd.value.startswith("<generator object")
    with ProcessPoolExecutor(max_workers=1) as pool:
        with pytest.raises(ParameterError, match=r"kbar=-1\.0 is invalid") as info:
            pool.submit(_refuse, -1.0).result(timeout=120)
        assert info.value.name == "kbar"
        assert pool.submit(_refuse, 0.1).result(timeout=120) is None  # the pool lives on


#: Every exception class brushcore defines, with constructor arguments that
#: set its extra fields and flags off their defaults.
_EXCEPTIONS = {
    ("brushcore.validation", "ParameterError"): (("kbar", -1.0, "a number", "why"), {}),
    ("brushcore.model.layout", "LayoutError"): (("pillars leave the square",),
                                                {"grid_helps": False}),
    ("brushcore.data.io", "CurveFileError"): (("c.nc: not a curve",), {"not_a_curve": True}),
    ("brushcore.data.curve_set", "AggregationError"): (("a.nc, b.nc: same case",), {}),
    ("brushcore.numerics.events.pulloff", "SolverError"): (("inconsistent",), {}),
    ("brushcore.numerics.linear.cg", "ConvergenceError"): (("CG stalled",), {}),
    ("brushcore.model.curve", "FirstTouchWarning"): (("3 of 16 pillars",), {}),
    ("brushcore.data.joblog", "Terminated"): ((), {}),
    ("brushcore.cli.simulate", "_Missing"): (("--kbar is required",), {}),
}


def _exception(module: str, name: str) -> BaseException:
    """One of `_EXCEPTIONS`, with a note (``add_note``) and an attribute set after it was made."""
    import importlib

    args, kwargs = _EXCEPTIONS[module, name]
    error = getattr(importlib.import_module(module), name)(*args, **kwargs)
    error.add_note(f"while running case 7 ({name})")
    error.case = 7  # what a caller attaches on the way up
    return error


def _raise(module: str, name: str) -> None:
    raise _exception(module, name)


def test_every_error_crosses_a_process_pool_whole():
    """Message, fields, flags and notes of each brushcore exception arrive as
    raised from a ProcessPoolExecutor's worker: ParameterError pickled by its
    fields alone dropped ``add_note``'s notes.  The table must name every
    exception class the package defines (found in its source)."""
    import ast
    import pathlib
    import pickle
    from concurrent.futures import ProcessPoolExecutor

    import brushcore

    root = pathlib.Path(brushcore.__file__).parent
    defined = set()
    for path in root.rglob("*.py"):
        module = ".".join(path.relative_to(root.parent).with_suffix("").parts)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ClassDef) and any(
                    ast.unparse(base).endswith(("Error", "Exception", "Warning", "Exit",
                                                "Interrupt")) for base in node.bases):
                defined.add((module, node.name))
    assert defined == set(_EXCEPTIONS)
    with ProcessPoolExecutor(max_workers=1) as pool:
        for module, name in _EXCEPTIONS:
            expected = _exception(module, name)
            for got in (pickle.loads(pickle.dumps(expected)), None):
                if got is None:
                    with pytest.raises(type(expected)) as info:
                        pool.submit(_raise, module, name).result(timeout=120)
                    got = info.value
                assert type(got) is type(expected) and str(got) == str(expected), name
                assert got.args == expected.args, name
                assert got.__notes__ == [f"while running case 7 ({name})"], name
                assert vars(got) == vars(expected), name  # fields, flags, the attribute


@pytest.mark.parametrize("field,value", [("grid", True), ("n_pillars", 16.5), ("grid", "64"),
                                         ("kbar", np.bool_(True)), ("grid", np.array([64])),
                                         ("seed", float("inf")), ("seed", 1e20)])
def test_non_numbers_are_still_refused(field, value):
    args = {"layout": "regular", "n_pillars": 16, "kbar": 0.1, "grid": 64, field: value}
    with pytest.raises(ParameterError, match=field):
        BrushParams(**args)


def test_error_speaks_the_callers_vocabulary():
    with pytest.raises(ParameterError) as err:
        BrushParams("regular", 15, 0.1, 64)
    assert str(err.value).startswith("n_pillars=15 is invalid")
    assert err.value.in_terms_of({"n_pillars": "--pillars"}, sep=" ").startswith(
        "--pillars 15 is invalid")


# (N, grid, runs by default): the paper's finest brush runs, meaningless grids do not.
RULE = [(2304, 512, True), (256, 512, True), (256, 256, True), (16, 64, True),
        (256, 64, False),   # radius 0.78 elements, phi realised 0.25 for 0.12
        (256, 128, False),  # radius 1.56, phi realised 0.0625
        (2304, 256, False)]  # radius 1.04


@pytest.mark.parametrize("n_pillars,grid,runs", RULE)
def test_one_discretisation_rule(n_pillars, grid, runs):
    def check(allow_coarse: bool) -> BrushParams:
        p = hinted_params(lambda g: BrushParams("regular", n_pillars, 1.0, g,
                                                allow_coarse=allow_coarse), grid)
        labels = build_labels(p)
        phi = np.count_nonzero(labels >= 0) / labels.size
        assert (p.pillar_radius_elements >= 2 and abs(phi / 0.12 - 1) <= 0.05) == runs
        return p

    if runs:
        check(False)
    else:
        with pytest.raises(ParameterError, match="grid") as err:
            check(False)
        # the suggested grid passes every check, not only the radius rule
        suggested = int(re.search(r"allowed grid (\d+), the next", str(err.value)).group(1))
        build_labels(BrushParams("regular", n_pillars, 1.0, suggested))
        check(True)  # explicitly asked for: runs


# Grids that the radius rule alone would suggest and the filling factor's check
# refuses (realised phi is not monotone in the grid): the suggestion runs.
@pytest.mark.parametrize("args", [
    dict(layout="regular", n_pillars=16, grid=32, phi=0.05),   # radius: 64, refused
    dict(layout="regular", n_pillars=16, grid=64, phi=0.05),   # 65 runs, 68 does not
    dict(layout="random", n_pillars=64, grid=64, shape="square"),  # radius: 82, refused
    dict(layout="hexagonal", n_pillars=64, grid=40, shape="ellipse", aspect=2.0),
])
def test_suggested_grid_runs(args):
    def make(grid: int) -> BrushParams:
        return BrushParams(kbar=1.0, **{**args, "grid": grid})

    with pytest.raises(ParameterError, match="grid") as err:
        build_labels(hinted_params(make, args["grid"]))
    suggested = int(re.search(r"allowed grid (\d+), the next", str(err.value)).group(1))
    build_labels(make(suggested))
    for grid in range(args["grid"] + 1, suggested):  # and no grid between them runs
        with pytest.raises(ParameterError):
            build_labels(make(grid))


def test_suggested_grid_runs_every_brush_of_a_config():
    """The default sweep's brushes on 64^2: one grid that runs them all (492),
    not the first failing brush's own (82, refused for the next one)."""
    from brushcore.model.layout import grid_hint, next_grid

    brushes = [("regular", n) for n in (64, 256, 576, 2304)] + \
        [("random", n) for n in (64, 220, 425, 1620)]
    makes = [lambda g, lay=lay, n=n: BrushParams(lay, n, 1.0, g) for lay, n in brushes]
    with pytest.raises(ParameterError) as err:
        makes[4](64)
    alone = next_grid(makes[4], 65)
    hint = str(grid_hint(err.value, makes[4], 64, makes[:4] + makes[5:]))
    common = int(re.search(r"allowed grid (\d+), the next", hint).group(1))
    assert alone < common
    for make in makes:
        build_labels(make(common))
    for grid in range(65, common):  # no grid between runs them all
        with pytest.raises(ParameterError):
            for make in makes:
                build_labels(make(grid))


def test_a_brush_no_grid_can_pack_names_its_packing_not_a_grid():
    """A random brush too dense to pack fails alike on every grid (its gap
    scales with L): the grid search gives that error at once.  It tried 64
    grids instead, minutes each for 100,000 pillars (the CLI hung)."""
    from brushcore.model.layout import next_grid

    make = lambda g: BrushParams("random", 400, 1e-3, g, phi=0.5, min_gap=4)  # noqa: E731
    with pytest.raises(ParameterError, match=r"^n_pillars=400 is invalid \(random layout: "
                                             r"only \d+ discs"):
        hinted_params(make, 32)
    with pytest.raises(ParameterError, match="n_pillars"):
        next_grid(make, 33)


def test_ellipses_are_resolved_across_their_minor_axis():
    """The radius rule asks 2 elements of the semi-minor axis r / sqrt(aspect):
    16 ellipses of aspect 10 at phi 0.03 have r = 3.15 on 129^2 but b = 1.0."""
    args = dict(layout="regular", n_pillars=16, kbar=1e-3, phi=0.03, shape="ellipse",
                aspect=10.0)
    with pytest.raises(ParameterError, match=r"semi-minor axis spans 0.997 elements.*"
                                             r"allowed grid >= 259"):
        BrushParams(grid=129, **args)
    assert BrushParams(grid=259, **args).narrowest_radius_elements >= 2.0
    assert BrushParams(grid=129, **{**args, "shape": "disc", "aspect": 1.0}) \
        .narrowest_radius_elements == pytest.approx(3.15, abs=0.01)


def test_floor_even_when_coarse_is_allowed():
    """Below sqrt(2)/2 elements a pillar may cover no element centre; the hint is consistent."""
    with pytest.raises(ParameterError, match=r"grid >= \d+") as err:
        BrushParams("regular", 256, 1.0, 41, allow_coarse=True)
    suggested = int(str(err.value).split("grid >= ")[1].split()[0])
    assert suggested == math.ceil(41 * math.sqrt(0.5) / (41 * math.sqrt(0.12 / (math.pi * 256))))
    for grid in range(suggested, suggested + 12):  # every pillar covers an element
        build_labels(BrushParams("regular", 256, 1.0, grid, allow_coarse=True))


# Values that once ran into the solver (singular blocks, a hang, overflow, a
# crash on writing) are refused up front, naming the field and the range.
@pytest.mark.parametrize("field,value,allowed", [
    ("kbar", 1e-12, r"\[1e-09, inf\]"),
    ("seed", 2**64, r"\[0, 2\*\*63 - 1\]"),
    ("e_star", 1e308, r"\[1e-30, 1e\+30\]"),
    ("h", 1e-200, r"\[1e-30, 1e\+30\]"),
    ("dgamma", 1e31, r"\[1e-30, 1e\+30\]"),
    ("roughness", 1e30, r"\[0, 1000\]"),
    ("preload", 1e200, r"\[0, 1000\]"),
    ("kbar_spread", 1e300, r"\[0, 100\]"),
    ("heights", np.array([0.0, 0.0, 0.0, 1e4]), r"each in \[-1000, 1000\]"),
    ("heights", np.array([0.0, 0.0, 0.0, 1j]), "real numbers"),
    ("kbar_values", np.array([0.1, 0.1, 0.1, 1e-30]), r"each in \[1e-09, inf\]"),
    # a uniform gap of 1e16 d_K (a rigid shift) had moved W 0.5 %, 1e300 set it to 0
    ("gap_map", np.full((32, 32), 1e16), r"each in \[-1000, 1000\]"),
])
def test_values_beyond_what_can_run_are_refused(field, value, allowed):
    args = {"layout": "regular", "n_pillars": 4, "kbar": 0.1, "grid": 32, field: value}
    with pytest.raises(ParameterError, match=rf"^{field}=.*allowed .*{allowed}"):
        BrushParams(**args)
    BrushParams("regular", 4, 1.0, 32, seed=2**63 - 1, roughness=1e3, preload=1e3,
                kbar_spread=100.0, e_star=1e30, h=1e-30)  # the ends themselves run
    BrushParams("regular", 4, 1e-9, 32)
    # ... but not a spread whose draws fall under the kbar floor (they left CG
    # unconverged, or W 3.5-6 % off, where a file's values are refused)
    with pytest.raises(ParameterError, match=r"^kbar_spread=100.0 is invalid \(a draw reaches "
                                             r"kbar .* seed \(1\)\): allowed a spread whose"):
        BrushParams("regular", 64, 1e-9, 128, kbar_spread=100.0, seed=1)


def test_numpy_bools_are_switches_too():
    options = SolverOptions(symmetry=np.False_, early_decisions=np.True_)
    assert options.symmetry is False and options.early_decisions is True
    with pytest.raises(ParameterError, match="settle_decisions=1 is invalid"):
        SolverOptions(settle_decisions=1)


def test_rtol_has_a_floor():
    with pytest.raises(ParameterError, match=r"rtol=1e-13 is invalid: allowed a number in "
                                             r"\[1e-12, 1e-3\]"):
        SolverOptions(rtol=1e-13)
    assert SolverOptions(rtol=1e-12, precision="double").rtol == 1e-12


def test_no_grid_suggested_past_the_largest():
    """Where no allowed grid resolves the pillars, the hint says what to change."""
    with pytest.raises(ParameterError, match=r"allowed none up to 8192 resolves these pillars: "
                                             "fewer pillars or a larger filling factor$"):
        BrushParams("regular", 4, 1.0, 32, phi=1e-300)


def test_a_pickled_copy_is_validated_and_keeps_its_arrays_read_only():
    """Pickle copies arrays writeable and skips __post_init__: a worker's copy
    (multiprocessing, joblib) could be changed past validation with the old
    hash (heights zeroed: F_ad 1.792 against 0.129, same parameter_hash)."""
    import pickle

    p = BrushParams("regular", 16, 0.01, 64, heights=np.linspace(-0.2, 0.2, 16),
                    kbar_values=np.geomspace(1e-3, 1e-1, 16), gap_map=np.zeros((64, 64)),
                    backend="cpu")
    q = pickle.loads(pickle.dumps(p))
    assert q == p and hash(q) == hash(p) and q.inputs_digest == p.inputs_digest
    assert q.as_attrs() == p.as_attrs()
    for name in ("heights", "kbar_values", "gap_map"):
        assert np.array_equal(getattr(q, name), getattr(p, name)), name
        assert not getattr(q, name).flags.writeable, name
    with pytest.raises(ValueError, match="read-only"):
        q.heights[:] = 0
    flat = BrushParams("random", 9, math.inf, 64, seed=3, allow_coarse=True)
    assert pickle.loads(pickle.dumps(flat)) == flat


def test_top_level_exports_what_a_notebook_needs():
    import brushcore
    from brushcore.data import io

    assert brushcore.read_curve is io.read_curve and brushcore.write_curve is io.write_curve
    assert {"read_curve", "write_curve"} <= set(brushcore.__all__)


def test_file_params_takes_count_grid_and_phi_from_the_file(tmp_path):
    """As --layout file does; BrushParams itself wanted phi=0.1201171875 typed out."""
    from brushcore import file_params
    from brushcore.model.layout_file import save_label_map

    regular = BrushParams("regular", 16, 0.01, 64)
    labels = build_labels(regular)
    path = save_label_map(labels, tmp_path / "lab.npy")
    p = file_params(path, 0.01, seed=2, h=1e-6)
    assert (p.layout, p.n_pillars, p.grid, p.layout_file) == ("file", 16, 64, str(path))
    assert p.phi == np.count_nonzero(labels >= 0) / 64**2 and p.seed == 2 and p.h == 1e-6
    assert np.array_equal(build_labels(p), labels)
    assert file_params(path, kbar=0.01, grid=64) == replace(p, h=1.0, seed=0)
    with pytest.raises(ParameterError, match=r"^n_pillars=9 is invalid: allowed 16, the value"):
        file_params(path, 0.01, n_pillars=9)
    with pytest.raises(ParameterError, match=r"^layout_file="):
        file_params(tmp_path / "missing.npy", 0.01)


def _tilt(grid: int) -> np.ndarray:
    """A gap map rising along x [d_K]."""
    return np.add.outer(np.zeros(grid), 0.00274 * (np.arange(grid) + 0.5))


_GRADED_KBAR = np.geomspace(1e-3, 1e-1, 16)
_GRADED_KBAR[3] = math.inf  # one rigid pillar


@pytest.mark.parametrize("params", [
    BrushParams("regular", 16, math.inf, 32, allow_coarse=True),  # a 0/1 switch in the file
    BrushParams("random", 9, 0.455, 64, seed=3),
    BrushParams("regular", 16, 0.01, 64, roughness=0.2, preload=0.5, seed=2),
    BrushParams("regular", 16, 0.01, 64, preload=0.5,
                heights=np.random.default_rng(1).normal(size=16) * 0.3),
    BrushParams("regular", 16, 0.01, 64, kbar_values=_GRADED_KBAR, gap_map=_tilt(64)),
], ids=["flat_coarse", "random", "rough_preloaded", "heights", "graded_gap_map"])
@pytest.mark.filterwarnings("ignore::brushcore.FirstTouchWarning")  # first touch meant
def test_a_curve_file_gives_its_parameters_back(params, tmp_path):
    """Rebuilt from the file: equal, same arrays bit for bit, same parameter_hash
    (x * d_K / d_K differs from x in 14 % of draws: given arrays are stored as given)."""
    from brushcore import read_curve, simulate, write_curve

    ds = simulate(params)
    write_curve(ds, tmp_path / "c.nc")
    back = BrushParams.from_curve(read_curve(tmp_path / "c.nc"))
    assert back == params and back.as_attrs() == params.as_attrs()
    for name in ("heights", "kbar_values", "gap_map"):
        given, rebuilt = getattr(params, name), getattr(back, name)
        assert (given is None) == (rebuilt is None), name
        assert given is None or np.array_equal(rebuilt, given), name
    assert simulate(back).attrs["parameter_hash"] == ds.attrs["parameter_hash"]
    if not params.inputs_digest:
        assert BrushParams.from_attrs(ds.attrs) == params


def test_from_attrs_needs_the_curve_for_arrays_and_switches_of_0_or_1():
    attrs = {**BrushParams("regular", 16, 0.01, 64).as_attrs(), "backend": "gpu",
             "rtol": 1e-6}  # a run's other attributes are ignored
    assert BrushParams.from_attrs({**attrs, "allow_coarse": np.int64(1)}).allow_coarse is True
    assert BrushParams.from_attrs(attrs).backend == "cpu"
    with pytest.raises(ParameterError, match=r"^allow_coarse=np.int64\(2\) is invalid"):
        BrushParams.from_attrs({**attrs, "allow_coarse": np.int64(2)})
    with pytest.raises(ParameterError, match=r"^inputs_digest='0123' is invalid .*from_curve"):
        BrushParams.from_attrs({**attrs, "inputs_digest": "0123"})


@pytest.mark.filterwarnings("ignore::brushcore.FirstTouchWarning")  # first touch meant
def test_from_curve_refuses_arrays_it_cannot_rebuild():
    from brushcore import simulate

    ds = simulate(BrushParams("regular", 4, 0.01, 32, heights=[0.1, 0.0, -0.1, 0.2]))
    with pytest.raises(ParameterError, match=r"^inputs_digest=.*lacks pillar_height_normalized"):
        BrushParams.from_curve(ds.drop_vars("pillar_height_normalized"))
    shifted = ds.assign(pillar_height_normalized=ds.pillar_height_normalized * (1 + 1e-15))
    with pytest.raises(ParameterError, match=r"^inputs_digest=.*do not reproduce it"):
        BrushParams.from_curve(shifted)
    with pytest.raises(ParameterError, match=r"^ds='dict' is invalid.*from_attrs"):
        BrushParams.from_curve(dict(ds.attrs))  # was an AttributeError


_RERUN_VARIABLES = ("displacement", "force", "contact_area", "attached_pillars",
                    "adhesive_force", "work_of_separation")


@pytest.mark.parametrize("params,options,protocol", [
    (BrushParams("random", 9, 0.455, 48, seed=3),
     SolverOptions(rtol=1e-6, cascade="global", precision="double", tie_rtol=1e-8,
                   early_decisions=False, symmetry=False), None),
    (BrushParams("regular", 9, 0.05, 48), SolverOptions(precision="mixed", lookahead=0.01,
                                                        settle_decisions=False), None),
    # force 30 F_K: run at rtol 1e-7 x (10 / 30)^2, recorded so; a rerun given
    # that would tighten it to 1.2e-9 (another parameter_hash, other numbers)
    (BrushParams("regular", 9, 0.05, 48, heights=np.linspace(-0.3, 0.3, 9)),
     replace(SolverOptions.exact(), rtol=1e-7), "force:-30, separation"),
], ids=["random_global_double", "mixed_lookahead", "protocol_tightened"])
def test_a_curve_file_reruns_from_its_parameters_and_options(params, options, protocol,
                                                             tmp_path):
    """SolverOptions.from_curve gives the options as given (a protocol's rtol
    as asked, ``rtol_requested``, not the tightened one that ran), so that a
    rerun from the file repeats the curve bit for bit, parameter_hash too."""
    from brushcore import read_curve, simulate, write_curve
    from brushcore.model.inputs import parse_protocol

    waypoints = None if protocol is None else parse_protocol(protocol)
    ds = simulate(params, options, protocol=waypoints)
    write_curve(ds, tmp_path / "c.nc")
    back = read_curve(tmp_path / "c.nc")
    rebuilt = SolverOptions.from_curve(back)
    assert rebuilt == options and type(rebuilt.rtol) is float and type(rebuilt.symmetry) is bool
    if protocol is not None:
        assert back.attrs["rtol"] < options.rtol == back.attrs["rtol_requested"]
        waypoints = parse_protocol(back.attrs["protocol_normalized"])
    again = simulate(BrushParams.from_curve(back), rebuilt, protocol=waypoints)
    assert again.attrs["parameter_hash"] == ds.attrs["parameter_hash"]
    assert again.attrs["rtol"] == ds.attrs["rtol"]
    for name in _RERUN_VARIABLES:
        np.testing.assert_array_equal(again[name].values, ds[name].values, err_msg=name)
    assert SolverOptions.from_attrs(back.attrs) == options


def test_solver_options_from_a_curve_refuse_what_is_none_and_warn_for_old_protocols():
    from brushcore.numerics.options import REQUESTED_RTOL

    attrs = {"rtol": np.float64(1e-6), "max_iter": np.int64(5000), "tie_rtol": 1e-7,
             "lookahead": 0.0, "cascade": "global", "symmetry": np.int64(0),
             "precision": "double", "early_decisions": 1, "settle_decisions": 0,
             "fft_library": "auto", "layout": "regular"}  # a run's other attributes ignored
    assert SolverOptions.from_attrs(attrs) == SolverOptions(
        rtol=1e-6, cascade="global", symmetry=False, precision="double",
        settle_decisions=False)
    with pytest.raises(ParameterError, match=r"^symmetry=np.int64\(2\) is invalid"):
        SolverOptions.from_attrs({**attrs, "symmetry": np.int64(2)})
    with pytest.raises(ParameterError, match=r"^attrs=.*fft_library missing"):
        SolverOptions.from_attrs({k: v for k, v in attrs.items() if k != "fft_library"})
    with pytest.raises(ParameterError, match=r"^ds='dict' is invalid.*SolverOptions\.from_attrs"):
        SolverOptions.from_curve(attrs)
    with pytest.raises(ParameterError, match=r"^attrs='list' is invalid"):
        SolverOptions.from_attrs([("rtol", 1e-4)])
    protocol = {**attrs, "protocol": "force -1; separation"}
    assert SolverOptions.from_attrs({**protocol, REQUESTED_RTOL: 1e-4}).rtol == 1e-4
    with pytest.warns(UserWarning, match="rtol its protocol ran at .* tightens it again"):
        assert SolverOptions.from_attrs(protocol).rtol == 1e-6


def test_a_parameter_set_reads_as_the_call_that_makes_it():
    """repr gives the constructor call with the fields set (it once listed all
    23, an init=False digest among them, so it could not be pasted back)."""
    for params in (BrushParams("regular", 16, 0.1, 128),
                   BrushParams("random", 64, math.inf, 256, seed=3, phi=0.2),
                   BrushParams("hexagonal", 16, 1e-3, 128, shape="ellipse", aspect=2.0,
                               orientation=30.0, roughness=0.5)):
        assert eval(repr(params)) == params, repr(params)
    assert repr(BrushParams("random", 64, math.inf, 256, seed=3)) == \
        "BrushParams('random', 64, math.inf, 256, seed=3)"
    given = BrushParams("regular", 4, 0.1, 32, heights=np.array([0.1, 0.0, -0.1, 0.0]))
    assert repr(given) == "BrushParams('regular', 4, 0.1, 32, heights=<4 values>)"


def test_a_brush_of_finite_pillars_is_not_filed_as_rigid() -> None:
    """kbar names a brush given every pillar's kbar (a sweep files it there):
    inf over finite pillars filed a soft brush (F_ad 1.03497, W 18.5 W_K)
    in the rigid column, through the API where the CLI refuses it; mixed
    pillars are named by a finite number, rigid ones alone may be inf."""
    import math

    import numpy as np
    import pytest

    from brushcore import BrushParams, ParameterError

    soft = [0.01, 0.02, 0.01, 0.01]
    with pytest.raises(ParameterError, match=r"kbar=inf is invalid \(0 of 4 pillars are rigid\)"):
        BrushParams("regular", 4, math.inf, 32, kbar_values=soft)
    with pytest.raises(ParameterError, match=r"kbar=inf is invalid \(1 of 4"):
        BrushParams("regular", 4, math.inf, 32, kbar_values=[math.inf, 1.0, 1.0, 1.0])
    assert BrushParams("regular", 4, 0.0125, 32, kbar_values=soft).kbar == 0.0125
    assert BrushParams("regular", 4, 1.0, 32, kbar_values=[math.inf, 1.0, 1.0, 1.0]).kbar == 1.0
    assert np.isinf(BrushParams("regular", 4, math.inf, 32, kbar_values=[math.inf] * 4).kbar)


def test_public_calls_refuse_wrong_arguments_by_name(tmp_path) -> None:
    """Wrong arguments to public calls are refused naming the argument, not
    by an AttributeError or TypeError from inside (an input helper's six
    probes)."""
    import numpy as np
    import pytest
    from brushcore import (BrushParams, ParameterError, file_params, positive_work,
                           unit_scales, write_curve)
    from brushcore.model.inputs import with_input_files

    params = BrushParams("regular", 4, 0.01, 32)
    refused = [
        (lambda: unit_scales({"a": 1}), ParameterError, r"params='dict' is invalid"),
        (lambda: with_input_files(params, "h4.txt"), ParameterError,
         r"files='h4.txt' is invalid \(a str, not a mapping\)"),
        (lambda: file_params("m.npy", kbar=1.0, layout="regular"), ParameterError,
         r"layout='regular' is invalid"),
        (lambda: write_curve({"a": 1}, tmp_path / "a.nc"), ParameterError,
         r"ds='dict' is invalid"),
        (lambda: BrushParams.from_attrs({}), ParameterError,
         r"\(layout, n_pillars, kbar, grid missing\)"),
        (lambda: positive_work(np.zeros(3), np.zeros(4)), ValueError,
         r"shapes \(3,\) and \(4,\)"),
    ]
    for call, kind, message in refused:
        with pytest.raises(kind, match=message):
            call()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("text,hint", [("inf", ": float('inf')"), ("0.455", ": float('0.455')"),
                                       ("abc", "")])
def test_kbar_as_a_string_is_told_to_be_a_number(text, hint):
    """kbar="inf" read "allowed a number in [1e-09, inf]; inf means rigid
    pillars": the user had typed inf.  The message says a string is not a
    number, and how to make one of a string that reads as one."""
    with pytest.raises(ParameterError, match=re.escape(
            f"kbar='{text}' is invalid: allowed a number in [1e-09, inf]; inf means rigid "
            f"pillars (a number, not a string{hint})") + "$"):
        BrushParams("regular", 16, text, 64)


def test_a_mistyped_keyword_names_the_closest_one():
    """Python's TypeError named no alternative where the command line names
    the closest flag (the Python API helper's find): the parameter classes
    and simulate now do, and say where threads are set."""
    from brushcore import Waypoint, simulate

    brush = BrushParams("regular", 4, 1.0, 32)
    for call, message in (
            (lambda: BrushParams("regular", 16, 0.1, 64, kbr=0.1), "'kbr'; did you mean 'kbar'?"),
            (lambda: Waypoint("force", vlaue=1.0), "'vlaue'; did you mean 'value'?"),
            (lambda: simulate(brush, option=None), "'option'; did you mean 'options'?"),
            (lambda: SolverOptions(threads=2), "'threads'; threads are set for the process: "
                                               "brushcore.numerics.platform.threads.pin_threads"),
            (lambda: BrushParams("regular", 16, 0.1, 64, zzzz=1), "'zzzz'")):
        with pytest.raises(TypeError) as info:
            call()
        assert message in str(info.value), str(info.value)
    assert BrushParams("regular", 16, 0.1, 64, seed=2).seed == 2  # the known ones pass


@pytest.mark.parametrize("layout, n", [("regular", 4), ("hexagonal", 6)])
def test_min_gap_on_a_lattice_is_recorded_as_1_as_the_cli_does(layout, n) -> None:
    """A lattice ignores min_gap (only a random draw keeps gaps): given one,
    the Python API says so and records 1, as the CLI's --min-gap, so the
    brush keeps one identity (it had two parameter hashes, and its curves
    did not aggregate with the workflow's: "disagree on min_gap")."""
    with pytest.warns(UserWarning, match=f"the {layout} layout ignores min_gap 5, recorded as 1"):
        given = BrushParams(layout, n, 0.1, 48, min_gap=5)
    assert given == BrushParams(layout, n, 0.1, 48) and given.min_gap == 1.0
    assert BrushParams("random", 16, 0.1, 48, min_gap=5).min_gap == 5.0  # its draw's gap


def test_a_lattice_curve_that_recorded_another_min_gap_still_aggregates() -> None:
    """Before 2026-12-07 the Python API recorded a lattice's min_gap as given;
    such a curve beside today's (min_gap 1) stopped the sweep ("curve files
    disagree on min_gap"), though only a random draw reads it: the sweep's
    min_gap is its random brushes' (1 where none ran)."""
    from brushcore import simulate
    from brushcore.data.aggregate import AggregationError, build_sweep

    old = simulate(BrushParams("regular", 4, 0.01, 32))
    old.attrs["min_gap"] = 3.0  # as that API wrote it
    lattices = [old, simulate(BrushParams("regular", 4, 1.0, 32))]
    assert build_sweep(lattices).attrs["min_gap"] == 1.0
    drawn = simulate(BrushParams("random", 4, 1.0, 32, min_gap=2.0, seed=1))
    assert build_sweep([*lattices, drawn]).attrs["min_gap"] == 2.0
    other = simulate(BrushParams("random", 4, 0.01, 32, seed=1))  # min_gap 1
    with pytest.raises(AggregationError, match="disagree on min_gap"):
        build_sweep([drawn, other])  # two random draws of other gaps: two rules
