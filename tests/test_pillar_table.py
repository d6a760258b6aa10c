"""Pillar tables: a layout as a list of discs in units of L, drawn on any grid.

A table written from a generated layout must draw that layout's label map
and pull off as it does; discs of unequal radius (which no generated layout
has) must let go as independent pillars where they stand far apart; what
does not fit is refused, naming the file and the line.
"""

from __future__ import annotations

import warnings
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from brushcore import (BrushParams, ParameterError, file_params, generated_table,
                       read_pillar_table, save_pillar_table, simulate, theory)
from brushcore.model.layout import build_labels
from brushcore.model.pillar_table import PillarTable

F_AD, W = "adhesive_force_normalized", "work_of_separation_normalized"


def _table(tmp_path: Path, text: str, name: str = "t.csv") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("layout, n, grid", [("regular", 256, 256), ("random", 64, 256),
                                             ("hexagonal", 64, 256), ("random", 220, 1024)])
def test_a_table_of_a_generated_layout_draws_its_label_map(tmp_path: Path, layout: str,
                                                           n: int, grid: int) -> None:
    params = BrushParams(layout, n, 0.01, grid)
    path = save_pillar_table(generated_table(params), tmp_path / layout)
    assert path.suffix == ".csv"
    table = read_pillar_table(path)
    assert table.n_pillars == n and table.phi == pytest.approx(params.phi, rel=1e-12)
    assert np.array_equal(build_labels(file_params(path, 0.01, grid=grid)),
                          build_labels(params))


@pytest.mark.parametrize("kbar", [0.01, math.inf])
def test_a_table_of_a_lattice_pulls_off_as_the_lattice(tmp_path: Path, kbar: float) -> None:
    """The same elements, the same mirror symmetry and precision: the same numbers."""
    params = BrushParams("regular", 16, kbar, 64)
    path = save_pillar_table(generated_table(params), tmp_path / "lattice")
    own, generated = simulate(file_params(path, kbar, grid=64)), simulate(params)
    assert own.attrs["symmetry_fold"] == generated.attrs["symmetry_fold"] == 4
    for name in (F_AD, W):
        assert float(own[name]) == pytest.approx(float(generated[name]), rel=1e-12)
    # every pillar's area, its elements' (h = 1): the curve's contact area in all
    labels = build_labels(params)
    assert own.pillar_area.values.tolist() == np.bincount(labels[labels >= 0]).tolist()
    assert float(own.pillar_area.sum()) == own.attrs["real_contact_area"]


def test_one_table_runs_on_every_grid_with_the_discs_phi(tmp_path: Path) -> None:
    path = _table(tmp_path, "# two discs\ny, radius, x\n0.3, 0.1, 0.25\n0.7, 0.05, 0.75\n")
    table = read_pillar_table(path)  # columns in any order
    assert table.centres.tolist() == [[0.3, 0.25], [0.7, 0.75]]
    assert table.phi == pytest.approx(math.pi * (0.01 + 0.0025), rel=1e-12)
    # a phi given within 1e-9 (a plan's, summed on another machine) is kept as given
    nudged = table.phi * (1 + 1e-12)
    assert file_params(path, 0.01, grid=64, phi=nudged).phi == nudged
    for grid in (64, 100, 256):
        params = file_params(path, 0.01, grid=grid)
        assert (params.n_pillars, params.grid, params.phi) == (2, grid, table.phi)
        labels = build_labels(params)
        counts = np.bincount(labels[labels >= 0])
        # each disc's elements: pi r^2 n^2 to within its perimeter's elements
        assert counts == pytest.approx(math.pi * (table.radii * grid) ** 2,
                                       abs=2 * math.pi * 0.1 * grid)
        # the larger disc is pillar 0, centred at (y, x) = (0.3, 0.25) L: its
        # elements' centroid within half an element (the staircase's offset)
        iy, ix = np.nonzero(labels == 0)
        assert (iy.mean() + 0.5) / grid == pytest.approx(0.3, abs=0.5 / grid)
        assert (ix.mean() + 0.5) / grid == pytest.approx(0.25, abs=0.5 / grid)


def test_soft_discs_of_unequal_radius_let_go_as_independent_pillars(tmp_path: Path) -> None:
    """Two soft pillars (radii 0.08 and 0.06 L, 0.6 L apart): the elastic
    foundation lets the small one go at its own force f_b, when both springs
    hold k lambda_b, so F_ad = 2 f_b > f_a (`theory.foundation_pull_off`, with
    each pillar's f_c from a run of that disc alone on the same grid).  What
    the model adds is the neighbour's field: its gradient f / (pi E* r^2)
    across the face of the pillar, whose tip cannot tilt, shifts the edge
    stress by 4 E* a^2 theta / f of itself (a flat punch's tilt, Johnson
    §5.2), i.e. by (4 / pi) (a / r)^2 = 1.3 %: the tolerance."""
    kbar, grid = 1e-6, 128
    discs = {"a": (0.2, 0.5, 0.08), "b": (0.8, 0.5, 0.06)}

    def force(name: str, *rows: tuple[float, float, float]) -> tuple[float, float]:
        table = PillarTable(np.array([[y, x] for x, y, _ in rows]),
                            np.array([r for *_, r in rows]))
        curve = simulate(file_params(save_pillar_table(table, tmp_path / name), kbar,
                                     grid=grid))
        return float(curve.adhesive_force), float(curve.attrs["side_length"])

    f_a, side = force("a", discs["a"])
    f_b, _ = force("b", discs["b"])
    pair, _ = force("pair", discs["a"], discs["b"])
    k = theory.stiffness_from_kbar(kbar, 1.0, side)
    target = theory.foundation_pull_off(np.zeros(2), np.full(2, k), np.array([f_a, f_b]))
    assert target == pytest.approx(2 * f_b, rel=1e-12) and target > f_a
    assert abs(pair / target - 1) < 4 / math.pi * (0.06 / 0.6) ** 2, (pair, target)


@pytest.mark.parametrize("text, message", [
    ("0.3, 0.3, 0.1\n", r"first line holds numbers\): allowed a header line"),
    ("x, y, r\n0.3, 0.3, 0.1\n", r"line 1: unknown column 'r'\): allowed a header"),
    ("x, y, radius, height\n0.3, 0.3, 0.1, 2\n",
     r"unknown column 'height' \(heights and stiffness go in their own files"),
    ("x, y, radius, x\n", r"column 'x' given twice"),
    ("x, radius\n", r"no column 'y'"),
    ("x, y, radius\n", r"holds no pillar"),
    ("x, y, radius\n0.3, 0.3\n", r"line 2 holds 2 values"),
    ("x y radius\n0,3 0,3 0,1\n", r"line 2 holds 6 values; commas separate values"),
    ("x, y, radius\n0.3, nan, 0.1\n", r"line 2: y = nan\): allowed finite numbers"),
    ("x, y, radius\n0.3, 0.3, 0\n", r"line 2: radius = 0.0\): allowed radii > 0"),
    ("x, y, radius\n# a comment\n0.3, 0.3, 0.1\n0.95, 0.5, 0.1\n",
     r"line 4: x = 0.95, y = 0.5, radius = 0.1\): allowed discs inside the square"),
    ("x, y, radius\n0.3, 0.3, 0.1\n0.7, 0.7, 0.1\n0.45, 0.3, 0.1\n",
     r"lines 2 and 4 \(pillars 0 and 2\) are 0.15 apart, radii 0.1 \+ 0.1\): allowed "
     r"discs that neither overlap nor touch"),
    ("x, y, radius\n0.25, 0.25, 0.24\n0.75, 0.75, 0.24\n0.25, 0.75, 0.24\n",
     r"pi sum r\^2 = 0.5429\): allowed discs covering at most half"),
    ("x, y, radius\n0.25, 0.5, 0.125\n0.5, 0.5, 0.125\n",  # tangent: on no grid apart
     r"lines 2 and 3 .* are 0.25 apart, radii 0.125 \+ 0.125\): allowed discs that neither"),
    (" ,X,Y,Radius\n1,0.3,0.3,0.1\n",  # an image tool's export with its index column
     r"line 1: column 1 has no name \(an index column\? leave it out\)"),
    ("x,y,radius\n0.3,0.3,0.1,0.2\n", r"line 2 holds 4 values\): allowed three"),
    ("x,y,radius\n0.5,0.5,0.3\n0.85,0.5,0.06\n",  # a small disc in a large one's reach
     r"lines 2 and 3 \(pillars 0 and 1\) are 0.35 apart, radii 0.3 \+ 0.06"),
], ids=["no header", "unknown column", "heights column", "twice", "missing", "empty",
        "short row", "decimal commas", "nan", "zero radius", "outside", "overlap", "phi",
        "tangent", "index column", "extra value with decimal points", "unequal overlap"])
def test_a_table_that_does_not_fit_is_refused_naming_the_line(
        tmp_path: Path, text: str, message: str) -> None:
    path = _table(tmp_path, text)
    with warnings.catch_warnings():  # the refusal says it all (decimal commas too)
        warnings.simplefilter("error")
        with pytest.raises(ParameterError, match=message) as err:
            file_params(path, 0.01, grid=128)
    assert err.value.name == "layout_file" and str(path) in str(err.value)


def test_discs_closer_than_an_element_share_its_edges_and_are_counted(tmp_path: Path) -> None:
    """Discs 0.005 L apart share element edges on 64^2, as random discs do on
    grids coarser than 512: the grid runs, the pair is counted (the curve's
    touching_pillar_pairs, the convergence study's flag), a finer grid parts
    them.  A table needs a grid, and its N is its lines'."""
    from brushcore.model.labelmap import count_touching_pairs

    path = _table(tmp_path, "x, y, radius\n0.3, 0.3, 0.1\n0.505, 0.3, 0.1\n")
    assert count_touching_pairs(build_labels(file_params(path, 0.01, grid=64))) == 1
    assert count_touching_pairs(build_labels(file_params(path, 0.01, grid=512))) == 0
    with pytest.raises(ParameterError, match=r"grid=None is invalid .* pillar table"):
        file_params(path, 0.01)
    with pytest.raises(ParameterError, match=r"n_pillars=3 is invalid.*allowed 2"):
        file_params(path, 0.01, grid=128, n_pillars=3)


def test_square_pillars_have_no_table() -> None:
    with pytest.raises(ParameterError, match="shape='square' is invalid"):
        generated_table(BrushParams("regular", 16, 0.01, 64, shape="square"))


@pytest.mark.parametrize("layout,grid", [("regular", 96), ("hexagonal", 96)])
def test_a_table_of_ellipses_is_the_generated_brush(tmp_path: Path, layout: str,
                                                    grid: int) -> None:
    """Columns aspect and orientation make a table's pillars ellipses of the
    radius's area, drawn as generated ellipses are: the table of a generated
    ellipse brush draws its label map element for element, and pulls off
    with the same F_ad and W to the last bit."""
    params = BrushParams(layout, 16, 0.01, grid, shape="ellipse", aspect=2.0,
                         orientation=30.0)
    path = save_pillar_table(generated_table(params), tmp_path / "ellipses")
    assert path.read_text().splitlines()[1] == "x, y, radius, aspect, orientation"
    table = file_params(path, 0.01, grid=grid)
    assert np.array_equal(build_labels(table), build_labels(params))
    made, read = simulate(params), simulate(table)
    for name in ("adhesive_force_normalized", "work_of_separation_normalized"):
        assert float(read[name]) == float(made[name]), name
    # the file brush's shape parameter stays "disc": its curve says what the file holds
    assert (read.attrs["shape"], read.attrs["pillar_shapes"]) == ("disc", "ellipses")
    from brushcore.model.layout_file import pillar_shapes

    mixed = _table(tmp_path, "x, y, radius, aspect, orientation\n0.3, 0.3, 0.1, 2, 0\n"
                             "0.7, 0.7, 0.1, 1, 0\n")
    assert pillar_shapes(mixed) == "discs and ellipses"
    discs = save_pillar_table(generated_table(BrushParams(layout, 16, 0.01, grid)),
                              tmp_path / "discs")
    assert pillar_shapes(discs) == "discs" and pillar_shapes(tmp_path / "m.npy") == "as drawn"
    # the radius rule reads the semi-minor axis: r / sqrt(2)
    from brushcore.model.layout import smallest_pillar

    assert smallest_pillar(table) == pytest.approx(params.narrowest_radius_elements, rel=1e-12)


@pytest.mark.parametrize("text, message", [
    ("x, y, radius, aspect\n0.3, 0.3, 0.1, 0.5\n",
     r"line 2: 'aspect' = 0.5\): allowed 'aspect' >= 1"),
    ("x, y, radius, orientation\n0.3, 0.3, 0.1, 30\n", r"line 1: no column 'aspect'"),
    # inside the square as a disc, not as an ellipse of aspect 4 along x
    ("x, y, radius, aspect, orientation\n0.15, 0.5, 0.1, 4, 0\n",
     r"line 2: x = 0.15, y = 0.5, radius = 0.1, 'aspect' = 4.0, 'orientation' = 0.0\): "
     r"allowed discs inside the square.* \(an ellipse's half extents in place of r\)"),
    # side by side along x: apart as upright ellipses, overlapping when turned to x
    ("x, y, radius, aspect, orientation\n0.37, 0.5, 0.07, 4, 0\n0.63, 0.5, 0.07, 4, 0\n",
     r"pillars of lines 2 and 3 \(pillars 0 and 1\) overlap or touch \(an ellipse"),
    # a disc on an ellipse's flank, 1e-7 L into it, between two boundary samples
    ("x, y, radius, aspect, orientation\n0.5, 0.5, 0.06, 8.0, 0\n"
     "0.5071454877102651, 0.5411945646687565, 0.02, 1, 0\n",
     r"pillars of lines 2 and 3 \(pillars 0 and 1\) overlap or touch"),
], ids=["aspect below 1", "orientation alone", "ellipse outside", "ellipses overlap",
        "a sliver of overlap"])
def test_a_table_of_ellipses_that_does_not_fit_is_refused(tmp_path: Path, text: str,
                                                          message: str) -> None:
    with pytest.raises(ParameterError, match=message):
        file_params(_table(tmp_path, text), 0.01, grid=128)


def test_upright_ellipses_whose_circles_meet_stand_apart(tmp_path: Path) -> None:
    """Two ellipses whose circumscribed discs overlap but whose faces do not
    are accepted, and drawn apart; turned towards each other, refused."""
    apart = _table(tmp_path, "x, y, radius, aspect, orientation\n"
                   "0.37, 0.5, 0.07, 4, 90\n0.63, 0.5, 0.07, 4, 90\n")
    labels = build_labels(file_params(apart, 0.01, grid=128))
    assert set(np.unique(labels)) == {-1, 0, 1}
    counts = np.bincount(labels[labels >= 0])
    assert np.allclose(counts / (math.pi * (0.07 * 128) ** 2), 1.0, atol=0.05), counts
    # an ellipse that touches the square's edge (x = its half extent) is drawn
    edge = _table(tmp_path, "x, y, radius, aspect, orientation\n"
                  f"{0.05 * math.sqrt(1.5)!r}, 0.5, 0.05, 1.5, 0\n", "edge.csv")
    assert (build_labels(file_params(edge, 0.01, grid=128)) == 0).any()
    # their bounding boxes: 4.5 elements across x (the minor axis), 18 along y
    rows, cols = np.nonzero(labels == 0)
    assert np.ptp(cols) < np.ptp(rows) / 3


def test_the_cli_runs_a_table_on_the_grid_it_is_given(tmp_path: Path) -> None:
    path = save_pillar_table(generated_table(BrushParams("regular", 4, 0.01, 64)),
                             tmp_path / "four")
    cli = [sys.executable, "-m", "brushcore", "simulate", "--layout", "file",
           "--layout-file", str(path), "--kbar", "0.01", "--quiet"]
    missing = subprocess.run(cli + ["--out", str(tmp_path / "a.nc")], capture_output=True,
                             text=True)
    assert missing.returncode == 2
    assert "--grid is required for a pillar table" in missing.stderr
    # a table that is not there: that first, not a --grid it could not use
    absent = [a if a != str(path) else str(tmp_path / "none.csv") for a in cli]
    gone = subprocess.run(absent + ["--out", str(tmp_path / "c.nc")], capture_output=True,
                          text=True)
    assert gone.returncode == 2 and "none.csv is invalid (no such file)" in gone.stderr
    done = subprocess.run(cli + ["--grid", "48", "--out", str(tmp_path / "b.nc")],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    import xarray as xr

    with xr.open_dataset(tmp_path / "b.nc") as curve:
        assert (int(curve.attrs["grid"]), int(curve.attrs["n_pillars"])) == (48, 4)
        direct = simulate(file_params(path, 0.01, grid=48))
        assert float(curve[F_AD]) == pytest.approx(float(direct[F_AD]), rel=1e-12)


def test_the_cli_names_a_grid_that_runs_a_table_of_unequal_pillars(tmp_path: Path) -> None:
    """A table too coarse for its mean radius is told the first grid that
    passes every check in one step: the mean radius's grid (35 for this
    brush of 15 discs of 0.06 L and one of 0.02 L) realises phi 5 % off up
    to 51 and would be refused a second time."""
    rows = [f"{0.125 + 0.25 * i}, {0.125 + 0.25 * j}, {0.02 if i == j == 0 else 0.06}"
            for i in range(4) for j in range(4)]
    path = _table(tmp_path, "x, y, radius\n" + "\n".join(rows) + "\n")
    cli = [sys.executable, "-m", "brushcore", "simulate", "--layout", "file",
           "--layout-file", str(path), "--kbar", "1", "--quiet"]
    coarse = subprocess.run(cli + ["--grid", "16", "--out", str(tmp_path / "a.nc")],
                            capture_output=True, text=True)
    assert coarse.returncode == 2
    assert "allowed --grid 52, the next that resolves the pillars" in coarse.stderr, \
        coarse.stderr
    for grid in (35, 51):
        with pytest.raises(ParameterError, match="phi"):
            build_labels(file_params(path, 1.0, grid=grid))
    assert build_labels(file_params(path, 1.0, grid=52)).max() == 15


def test_a_stub_among_pillars_is_judged_by_its_own_radius(tmp_path: Path) -> None:
    """A broken stub (radius 0.004 L beside two of 0.1 L) sets the grid: the
    refusal names the smallest disc.  The grid suggested is the next that
    passes where the search finds one (263 from 256; 129 from 128 with
    allow_coarse, where the stub need only cover an element centre), else
    one from where a disc that small is three elements across wherever it
    sits (radius 1 + sqrt(1/2) elements: 427), said as such."""
    path = _table(tmp_path, "x, y, radius\n0.25, 0.5, 0.1\n0.75, 0.5, 0.1\n0.5, 0.85, 0.004\n")
    with pytest.raises(ParameterError, match=r"1 of 3 pillars cover no element centre; the "
                       r"smallest disc's radius is 0.512 elements\): allowed grid 427, on "
                       r"which the smallest disc is three elements across wherever it sits"):
        build_labels(file_params(path, 0.01, grid=128))
    with pytest.raises(ParameterError, match=r"allowed grid 263, the next that"):
        build_labels(file_params(path, 0.01, grid=256))
    with pytest.raises(ParameterError, match=r"allowed grid 129, the next that"):
        build_labels(file_params(path, 0.01, grid=128, allow_coarse=True))
    for grid in (263, 427):
        assert np.bincount(build_labels(file_params(path, 0.01, grid=grid)).ravel() + 1)[3] > 4


@pytest.mark.parametrize("text", [
    "# x,y,radius\n0.25,0.25,0.1\n0.75,0.75,0.1\n",  # np.savetxt(header="x,y,radius")
    'x,y,radius,\n0.25,0.25,0.1,\n0.75,0.75,0.1,\n',  # trailing commas
    '"x","y","radius"\n0.25,0.25,0.1\n0.75,0.75,0.1\n',  # a spreadsheet's quotes
    "x y radius\n25e-2 25e-2 1e-1\n75e-2,75e-2,1e-1\n",  # exponents, no point: no warning
    "x y,radius\n0.25 0.25 0.1\n0.75 0.75 0.1\n",  # white space and a comma
], ids=["commented header", "trailing commas", "quoted names", "exponents", "mixed header"])
def test_tables_as_tools_write_them_are_read(tmp_path: Path, text: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no decimal-comma warning either
        table = read_pillar_table(_table(tmp_path, text))
    assert table.centres.tolist() == [[0.25, 0.25], [0.75, 0.75]]
    assert table.radii.tolist() == [0.1, 0.1]


@pytest.mark.parametrize("text, message", [
    ("x;y;radius\n0.25;0.25;0.1\n", r"semicolons between values: separate them with commas"),
    ("x;y;radius\n0,25;0,25;0,1\n", r"semicolons between values and decimal commas"),
], ids=["semicolons", "semicolons and decimal commas"])
def test_semicolon_tables_are_told_what_to_change(tmp_path: Path, text: str,
                                                  message: str) -> None:
    with pytest.raises(ParameterError, match=message):
        read_pillar_table(_table(tmp_path, text))


def test_generated_tables_run_where_their_brushes_run(tmp_path: Path) -> None:
    """phi = 0.5 sums to 0.5000000000000001 from 256 discs (accepted), and a
    random brush's discs that share element edges on 256^2 (its gap is L/512)
    run there too, counted as the generated brush counts them."""
    from brushcore.model.labelmap import count_touching_pairs

    dense = BrushParams("regular", 256, 0.01, 256, phi=0.5)
    table = read_pillar_table(save_pillar_table(generated_table(dense), tmp_path / "dense"))
    assert table.phi == pytest.approx(0.5, rel=1e-12)
    random = BrushParams("random", 220, 0.01, 256)
    path = save_pillar_table(generated_table(random), tmp_path / "random")
    labels = build_labels(file_params(path, 0.01, grid=256))
    assert np.array_equal(labels, build_labels(random))
    assert count_touching_pairs(labels) == count_touching_pairs(build_labels(random)) > 0


def test_a_decimal_comma_before_an_exponent_is_still_warned_about(tmp_path: Path) -> None:
    """"2,5e-1" is a decimal-comma locale's 0.25 (read as 2 and 0.5): on one
    line warned, on several refused (two values a line), the commas named."""
    from brushcore.model.inputs import read_pillar_values

    path = _table(tmp_path, "2,5e-1 3,0e-1\n", "h.txt")
    with pytest.warns(UserWarning, match="no decimal point"):
        assert read_pillar_values(path, 4, "heights").tolist() == [2.0, 0.5, 3.0, 0.0]
    path = _table(tmp_path, "2,5e-1\n3,0e-1\n", "h2.txt")
    with pytest.warns(UserWarning, match="no decimal point"), \
            pytest.raises(ParameterError, match=r"line 1 holds 2 values; commas separate "
                                                 r"values: write decimals with a point"):
        read_pillar_values(path, 4, "heights")


def test_a_table_in_other_units_is_named_as_such_without_a_comma_warning(tmp_path: Path
                                                                         ) -> None:
    """A table of integers (micrometres) separates its values with commas:
    no decimal-comma warning, and the refusal says the unit is L."""
    path = _table(tmp_path, "x,y,radius\n25,25,5\n75,75,5\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ParameterError, match=r"every radius exceeds 1: write lengths "
                                                 r"in units of L"):
            file_params(path, 0.01, grid=64)


def test_a_label_map_names_the_grid_and_the_kinds_of_layout_file(tmp_path: Path) -> None:
    """A grid other than a map's is the grid's error (as N's and phi's are),
    and an unknown suffix lists the table's .csv beside the maps'."""
    path = tmp_path / "m.npy"
    np.save(path, build_labels(BrushParams("regular", 16, 0.01, 64)))
    with pytest.raises(ParameterError, match=r"grid=128 is invalid: allowed 64, the value of"):
        file_params(path, 0.01, grid=128)
    with pytest.raises(ParameterError, match=r"allowed a label map \(\.npy or \.png\) or a "
                                             r"pillar table \(\.csv\)"):
        file_params(tmp_path / "m.txt", 0.01)


def test_exactly_tangent_discs_are_refused_whatever_their_angle(tmp_path: Path) -> None:
    """Equal discs whose centres lie exactly 2 r apart (np.hypot) at random
    angles: a k-d tree rounds the distance otherwise, so the search is a hair
    wider than 2 r (it missed 26 % of such pairs)."""
    from brushcore.model.pillar_table import _check_apart

    rng = np.random.default_rng(3)
    found = 0
    for _ in range(2000):
        r = 0.05
        angle = rng.uniform(0, 2 * np.pi)
        centres = np.array([[0.5, 0.5], [0.5 + 2 * r * np.sin(angle),
                                         0.5 + 2 * r * np.cos(angle)]])
        if np.hypot(*(centres[1] - centres[0])) != 2 * r:
            continue  # not tangent to the last bit
        found += 1
        with pytest.raises(ParameterError, match="neither overlap nor touch"):
            _check_apart(tmp_path / "t.csv", np.array([2, 3]),
                         PillarTable(centres, np.full(2, r)))
    assert found > 100


@pytest.mark.parametrize("rows", [
    "0.1, 0.5, 0.05\n0.4, 0.5, 0.25",  # 0.4 - 0.1 = 0.30000000000000004 > 0.05 + 0.25
    "0.5, 0.15, 0.15\n0.5, 0.45, 0.15",
    "0.5, 0.5, 0.06, 4, 0\n0.5, 0.56, 0.06, 4, 0",  # ellipses along their minor axes
    "0.5, 0.5, 0.06, 4, 90\n0.56, 0.5, 0.06, 4, 90",
    "0.3, 0.5, 0.06, 4, 0\n0.52, 0.5, 0.1, 1, 0",  # an ellipse's tip on a disc
], ids=["discs x", "discs y", "ellipses y", "ellipses x", "ellipse and disc"])
def test_pillars_written_tangent_are_refused_where_decimals_round_apart(
        tmp_path: Path, rows: str) -> None:
    """Tangent in decimals, 1 ulp apart in floats: these five ran (a geometry
    auditor's finds, touching on some grids and not on others), where the
    same pairs at 45 degrees were refused."""
    header = "x, y, radius" + (", aspect, orientation" if rows.count(",") > 4 else "")
    with pytest.raises(ParameterError, match="overlap|touch"):
        read_pillar_table(_table(tmp_path, f"{header}\n{rows}\n"))
    apart = rows.replace("0.4, 0.5, 0.25", "0.4, 0.5, 0.2499999").replace(
        "0.45, 0.15", "0.4500001, 0.15").replace("0.56, 0.06", "0.5600001, 0.06").replace(
        "0.56, 0.5, 0.06", "0.5600001, 0.5, 0.06").replace("0.52, 0.5", "0.5200001, 0.5")
    assert apart != rows
    read_pillar_table(_table(tmp_path, f"{header}\n{apart}\n"))  # 1e-7 apart: accepted


def test_the_narrowest_pillar_is_recorded_for_the_resolution_flags(tmp_path: Path) -> None:
    """`smallest_radius_elements`, which the under-resolved flags read: a
    generated brush's radius rule (an ellipse's semi-minor axis r/sqrt(4)),
    a table's smallest disc (0.04 L on 96^2: 3.84 elements, against a mean
    equal-area radius of 6.07), a label map's smallest pillar as the
    equal-area radius of its element count, written into the curve file."""
    from brushcore.model.layout import smallest_radius_elements
    from brushcore.model.layout_file import save_label_map

    disc = BrushParams("regular", 16, 0.01, 128)
    assert smallest_radius_elements(disc, build_labels(disc)) == disc.pillar_radius_elements
    ellipse = BrushParams("regular", 16, 0.01, 256, shape="ellipse", aspect=4.0)
    assert smallest_radius_elements(ellipse, build_labels(ellipse)) == pytest.approx(
        ellipse.pillar_radius_elements / 2.0, rel=1e-12)
    table = _table(tmp_path, "x,y,radius\n0.3,0.3,0.08\n0.7,0.7,0.04\n")
    params = file_params(table, 1e-3, grid=96)
    assert params.pillar_radius_elements == pytest.approx(96 * math.sqrt(0.08**2 / 2 + 0.04**2 / 2))
    assert smallest_radius_elements(params, build_labels(params)) == pytest.approx(3.84)
    labels = np.full((40, 40), -1)
    labels[4:14, 4:14] = 0   # 100 elements
    labels[20:26, 20:26] = 1  # 36 elements: equal-area radius sqrt(36/pi) = 3.385
    mapped = file_params(save_label_map(labels, tmp_path / "m.npy"), 1e-3)
    assert smallest_radius_elements(mapped, labels) == pytest.approx(math.sqrt(36 / math.pi))
    curve = simulate(params)
    assert curve.attrs["smallest_radius_elements"] == pytest.approx(3.84)


def test_sweeps_carry_the_narrowest_pillar_and_read_it_from_older_files(tmp_path: Path) -> None:
    """sweep.nc's `smallest_radius_elements` is each curve's; a curve written
    before it was recorded gives it from its shape (an ellipse's semi-minor
    axis r / sqrt(aspect), whose mean radius would hide a coarse study)."""
    import xarray as xr

    from brushcore.data.aggregate import build_sweep
    from brushcore.data.io import read_curve, write_curve

    ellipse = BrushParams("regular", 4, 0.01, 64, shape="ellipse", aspect=4.0)
    new = write_curve(simulate(ellipse), tmp_path / "new" / "e.nc")
    old = read_curve(new)
    del old.attrs["smallest_radius_elements"]
    old = write_curve(old, tmp_path / "old" / "e.nc")
    semi_minor = ellipse.pillar_radius_elements / 2.0
    for path in (new, old):
        sweep = build_sweep([path])
        got = sweep["smallest_radius_elements"].values[np.isfinite(
            sweep["smallest_radius_elements"].values)]
        assert got.tolist() == pytest.approx([semi_minor], rel=1e-12), path
    table = _table(tmp_path, "x,y,radius\n0.3,0.3,0.08\n0.7,0.7,0.04\n")
    curve = write_curve(simulate(file_params(table, 1e-3, grid=96)), tmp_path / "t.nc")
    with xr.open_dataset(curve) as c:
        assert c.attrs["smallest_radius_elements"] == pytest.approx(3.84)
    assert float(np.nanmax(build_sweep([curve])["smallest_radius_elements"])) == \
        pytest.approx(3.84)


def test_a_label_map_read_back_would_refuse_is_not_written(tmp_path: Path) -> None:
    """random 220 on 160^2 has 11 pairs of discs that share an element edge:
    save_label_map refuses it (read_label_map would), naming a pair."""
    from brushcore.model.labelmap import count_touching_pairs
    from brushcore.model.layout_file import save_label_map

    labels = build_labels(BrushParams("random", 220, 0.01, 160, seed=0))
    assert count_touching_pairs(labels) == 11
    with pytest.raises(ParameterError, match=r"pillars 1 and 137 at element \(row 10, column "
                                             r"4\).*draw it on a finer grid"):
        save_label_map(labels, tmp_path / "r220.npy")
    assert not (tmp_path / "r220.npy").exists()


def test_a_table_the_reader_would_refuse_is_not_saved(tmp_path) -> None:
    """`save_pillar_table` checks a table as `read_pillar_table` will: a
    negative radius is refused naming the file and the line, before the file
    exists (it was written, and refused only when read back); a .npy name is
    refused (it was written as x.npy.csv); missing folders are made."""
    from dataclasses import replace

    import pytest

    from brushcore import BrushParams, ParameterError, generated_table

    table = generated_table(BrushParams("regular", 4, 0.01, 64))
    with pytest.raises(ParameterError, match=r"neg\.csv' is invalid \(line 3: radius = -0\.0977"):
        save_pillar_table(replace(table, radii=-table.radii), tmp_path / "neg.csv")
    with pytest.raises(ParameterError, match=r"it ends in \.npy\): allowed a \.csv file"):
        save_pillar_table(table, tmp_path / "x.npy")
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing, no temporary
    saved = save_pillar_table(table, tmp_path / "new" / "folder" / "brush")
    assert saved == tmp_path / "new" / "folder" / "brush.csv"
    assert read_pillar_table(saved).n_pillars == 4


def test_orientations_beyond_a_turn_are_refused_and_radians_are_said(tmp_path: Path) -> None:
    """An angle past +-360 degrees says nothing more (1e308 passed, and the
    grid rule then blamed the grid); a column of 0.5236 and 1.0472 is
    30 and 60 degrees written in radians: read as degrees, with a warning."""
    header = "x, y, radius, aspect, orientation\n"
    with pytest.raises(ParameterError, match=r"line 3: 'orientation' = 400.0.*\[-360, 360\]"):
        read_pillar_table(_table(tmp_path, header + "0.3,0.3,0.08,2,30\n0.7,0.7,0.08,2,400\n"))
    with pytest.raises(ParameterError, match=r"orientation=1e\+308 is invalid: allowed an angle "
                                             r"in degrees in \[-360, 360\]"):
        BrushParams("regular", 4, 1.0, 64, shape="square", orientation=1e308)
    radians = _table(tmp_path, header + "0.3,0.3,0.08,2,0.5236\n0.7,0.7,0.08,2,1.0472\n",
                     "radians.csv")
    with pytest.warns(UserWarning, match="every 'orientation' lies within 2 pi and not all "
                                         "are whole .*read as degrees"):
        table = read_pillar_table(radians)
    assert table.orientations.tolist() == [0.5236, 1.0472]
    with warnings.catch_warnings():  # whole degrees within 2 pi: no word
        warnings.simplefilter("error")
        read_pillar_table(_table(tmp_path, header + "0.3,0.3,0.08,2,0\n0.7,0.7,0.08,2,5\n",
                                 "degrees.csv"))


def test_a_label_covering_separate_pieces_is_said_once(tmp_path: Path) -> None:
    """One label on two footprints runs as one pillar (one spring on both):
    said once per file, however often a run reads the map."""
    from brushcore.model.layout_file import read_label_map, split_pillars

    labels = build_labels(BrushParams("random", 16, 1.0, 128, seed=2))
    assert split_pillars(labels).size == 0
    joined = labels.copy()
    joined[joined == 5] = 3
    joined[joined == 15] = 5  # labels stay 0 ... N-1
    assert split_pillars(joined).tolist() == [3]
    path = tmp_path / "joined.npy"
    np.save(path, joined)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(3):
            read_label_map(path)
    said = [str(w.message) for w in caught if "pieces" in str(w.message)]
    assert said == [f"{path}: label 3 covers pieces that share no element edge; such a label "
                    "runs as one pillar, one spring on all its pieces: give each piece its "
                    "own label otherwise"], said


def test_a_table_named_with_decimals_is_saved_under_csv(tmp_path: Path) -> None:
    """phi0.12 ends a name in a number's decimals, not a file kind (a diff
    reviewer's find: refused as "it ends in .12"); .npy stays refused."""
    from brushcore.model.pillar_table import save_pillar_table

    table = generated_table(BrushParams("regular", 4, 1.0, 64))
    assert save_pillar_table(table, tmp_path / "brush_phi0.12") == tmp_path / "brush_phi0.12.csv"
    assert save_pillar_table(table, tmp_path / "b.CSV") == tmp_path / "b.CSV"
    with pytest.raises(ParameterError, match=r"it ends in \.npy"):
        save_pillar_table(table, tmp_path / "x.npy")
    assert read_pillar_table(tmp_path / "brush_phi0.12.csv").n_pillars == 4
