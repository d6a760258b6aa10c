"""The filling factor phi as a sweep dimension: the config's list, sweep.nc's
``phi`` dimension (one phi: the sweep as before), the figures that show one
phi of several and say which, the rigid limit against phi, and
``brushcore converge`` across phi.

Tiny curves (regular N = 4 on 32^2, well under a second each) and dry runs.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from test_workflow import (SWEEP_DIMS, assert_refused_at_plan_time, output,  # noqa: F401
                           planned_simulations, repo_copy, snakemake)  # repo_copy: fixture

xr = pytest.importorskip("xarray")

PHIS = (0.12, 0.2)
KBARS = (math.inf, 1e-2)


@pytest.fixture(scope="module")
def phi_curves(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[float, float], Path]:
    """(phi, kbar) -> curve file of regular N = 4 on 32^2."""
    from brushcore import BrushParams, simulate
    from brushcore.data.io import write_curve

    root = tmp_path_factory.mktemp("phi")
    files = {}
    for phi in PHIS:
        for kbar in KBARS:
            path = root / f"N4_kbar{kbar!r}_phi{phi!r}.nc"
            write_curve(simulate(BrushParams("regular", 4, kbar, 32, phi=phi)), path)
            files[phi, kbar] = path
    return files


@pytest.fixture(scope="module")
def two_phi(phi_curves):
    from brushcore.data.aggregate import build_sweep

    return build_sweep(list(phi_curves.values()))


@pytest.fixture(scope="module")
def one_phi(phi_curves):
    from brushcore.data.aggregate import build_sweep

    return build_sweep([p for (phi, _), p in phi_curves.items() if phi == 0.12])


def test_curves_of_two_phi_give_the_sweep_a_phi_dimension(two_phi, phi_curves) -> None:
    """Curves of two phi were refused ("curve files disagree on phi", or as
    one case twice); they now lie along ``phi``, the phi asked for, with the
    realised phi kept per case."""
    from brushcore.data.io import read_curve

    f = two_phi["adhesive_force_normalized"]
    assert f.dims == (*SWEEP_DIMS, "phi")
    assert two_phi["phi"].values.tolist() == list(PHIS)
    assert two_phi["phi"].attrs["units"] == "1" and "asked for" in two_phi["phi"].attrs[
        "long_name"]
    assert math.isnan(two_phi.attrs["phi"])  # the coordinate says each case's
    for (phi, kbar), path in phi_curves.items():
        curve = read_curve(path)
        case = dict(layout="regular", n_pillars=4, kbar=kbar, seed=0, grid=32, phi=phi)
        assert float(f.sel(case)) == float(curve["adhesive_force_normalized"])
        assert float(two_phi["phi_actual"].sel(case)) == float(curve.attrs["phi_actual"])
    # the snapshots say which phi they are
    assert sorted(set(two_phi["case_phi"].values.tolist())) == list(PHIS)


def test_one_phi_keeps_the_sweep_as_it_was(one_phi, two_phi) -> None:
    """One phi: no phi dimension, no case_phi, the attribute phi; and the
    slice of the two-phi sweep at that phi is the one-phi sweep, variable
    for variable (its attributes aside: its sources and the phi shown)."""
    from brushcore.data.views import SHOWN_PHI, phi_slice

    assert "phi" not in one_phi.dims and "phi" not in one_phi.variables
    assert "case_phi" not in one_phi.variables
    assert one_phi["adhesive_force_normalized"].dims == SWEEP_DIMS
    assert one_phi.attrs["phi"] == 0.12 and SHOWN_PHI not in one_phi.attrs
    assert phi_slice(one_phi) is one_phi
    sliced = phi_slice(two_phi)  # the paper's 0.12 of the two
    assert sliced.attrs["phi"] == 0.12 and sliced.attrs[SHOWN_PHI] == 0.12
    a, b = sliced.copy(), one_phi.copy()
    a.attrs, b.attrs = {}, {}
    assert a.identical(b)
    other = phi_slice(two_phi, 0.2)
    assert other.attrs["phi"] == 0.2 and other.sizes["case"] == 2
    assert np.isnan(phi_slice(two_phi, 0.3)["adhesive_force_normalized"]).all()  # not run


def test_the_workflows_named_phi_is_checked_per_file(phi_curves) -> None:
    """The workflow names each file's case and phi; a phi list's files pass,
    and a file of another phi than its name says is refused."""
    from brushcore.data.aggregate import AggregationError, CaseKey, build_sweep

    paths = list(phi_curves)
    expected = [(CaseKey("regular", 4, kbar, 0, 32), phi) for phi, kbar in paths]
    sweep = build_sweep([phi_curves[k] for k in paths], expected=expected)
    assert sweep.sizes["phi"] == 2
    with pytest.raises(AggregationError, match=r"phi=0.2, not the case its name stands for"):
        build_sweep([phi_curves[0.2, math.inf]], expected=[(CaseKey("regular", 4, math.inf,
                                                                    0, 32), 0.12)])


def test_rigid_phi_draws_the_sweep_and_the_quarter_power(two_phi, one_phi, tmp_path) -> None:
    """The new figure: the rigid runs' F_ad at each phi as realised, the
    rigid limit phi^(-1/4) and the compact punch; one phi: a placeholder."""
    from brushcore import theory
    from brushcore.data import figures

    fig = figures.rigid_phi(two_phi)
    ax = fig.axes[0]
    rigid = two_phi.sel(kbar=math.inf).squeeze()
    want_x = rigid["phi_actual"].values
    want_y = rigid["adhesive_force_normalized"].values
    data = [line for line in ax.lines if line.get_marker() == "o"]
    assert len(data) == 1 and "N = 4" in [t.get_text() for t in ax.get_legend().get_texts()]
    np.testing.assert_allclose(data[0].get_xdata(), want_x)
    np.testing.assert_allclose(data[0].get_ydata(), want_y)
    quarter = [line for line in ax.lines if "varphi^{-1/4}" in line.get_label()]
    assert len(quarter) == 1
    x, y = (np.asarray(v, dtype=float) for v in quarter[0].get_data())
    np.testing.assert_allclose(y, theory.rigid_limit(x))
    assert x.min() < want_x.min() and x.max() > want_x.max()
    assert any(set(np.ravel(line.get_ydata())) == {1.0} for line in ax.lines)  # the punch
    figures.save(fig, tmp_path / "rigid_phi.png")
    assert (tmp_path / "rigid_phi.png").stat().st_size > 10_000
    alone = figures.rigid_phi(one_phi)
    assert not [line for line in alone.axes[0].lines if line.get_marker() == "o"]
    assert "one filling factor only (phi = 0.12)" in alone.axes[0].texts[0].get_text()


def test_figures_and_summary_of_several_phi_say_which_they_show(two_phi, one_phi) -> None:
    from brushcore.data import figures
    from brushcore.data.summary import headline_rows

    said = "phi = 0.12 of 0.12, 0.2"

    def title(fig) -> str:
        return " ".join(fig.get_suptitle().split())  # wrapped to the figure's width

    fig6 = figures.fig6(two_phi)
    assert said in title(fig6)
    # and it draws the phi it names: F_ad of the 0.12 curves, not of 0.2
    drawn = np.concatenate([line.get_ydata() for line in fig6.axes[0].lines
                            if line.get_marker() == "o"])
    f = two_phi["adhesive_force_normalized"]
    assert np.isclose(drawn, float(f.sel(kbar=math.inf, phi=0.12).squeeze())).any()
    assert not np.isclose(drawn, float(f.sel(kbar=math.inf, phi=0.2).squeeze())).any()
    assert said in title(figures.fig8(two_phi))
    assert said in title(figures.fig5(two_phi, n_pillars=4, kbar=[math.inf]))
    assert said in title(figures.lattices(two_phi))
    assert said in " ".join(figures.fig7(two_phi).axes[0].get_title().split())
    for draw in (figures.fig6, figures.fig8):  # one phi: nothing said
        assert "phi" not in title(draw(one_phi))
    rows = headline_rows(two_phi, fig5_n_pillars=4, fig5_kbar=math.inf)
    limit = next(r for r in rows if r.quantity.startswith("rigid limit"))
    assert said in limit.note and limit.value == "1.7"
    assert said not in next(r for r in headline_rows(one_phi, fig5_n_pillars=4,
                                                     fig5_kbar=math.inf)
                            if r.quantity.startswith("rigid limit")).note


def test_converge_gathers_curves_of_two_phi(phi_curves, tmp_path, capsys) -> None:
    """`brushcore converge a.nc b.nc` of two phi refused them as one case twice."""
    from brushcore.cli import main

    out = tmp_path / "out"
    paths = [str(phi_curves[phi, math.inf]) for phi in PHIS]
    assert main(["converge", *paths, "--out-dir", str(out)]) == 0
    assert "2 curves on grids [32]" in capsys.readouterr().out
    with xr.open_dataset(out / "sweep.nc") as sweep:
        assert sweep["phi"].values.tolist() == list(PHIS)


def test_a_phi_list_plans_one_curve_a_phi(repo_copy: Path, tmp_path: Path) -> None:  # noqa: F811
    """`phi: [0.12, 0.2]` plans every case at each phi (named _phi{phi} as one
    phi is) and the rigid-limit figure; `phi: 0.12` neither changes."""
    runs = {}
    for phi in (0.12, [0.12], [0.12, 0.2]):
        config = tmp_path / "phi.yaml"
        config.write_text(yaml.safe_dump({"phi": phi, "kbar": [1.0e-2, float("inf")]}))
        proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", "config/test.yaml",
                         str(config), "--forceall")
        text = output(proc)
        assert proc.returncode == 0, text
        runs[str(phi)] = (planned_simulations(text),
                          set(re.findall(r"results/curves/\S+\.nc", text)),
                          "rigid_phi.png" in text)
    single, names, figure = runs["0.12"]
    assert runs["[0.12]"] == runs["0.12"] and not figure
    assert all("_phi0.12" in n for n in names)
    count, both, figure = runs["[0.12, 0.2]"]
    assert count == 2 * single and figure
    assert names < both and {n.replace("_phi0.2", "_phi0.12") for n in both} == names


@pytest.mark.parametrize(("bad", "message"), [
    ({"phi": [0.08, 0.7]},
     r"config key 'phi.1': 0.7 is out of range; allowed a number in \(0, 0.5\]\n"),
    ({"phi": 0.0}, r"config key 'phi': 0.0 is out of range; allowed a number in \(0, 0.5\] "
                   r"or a list of such numbers"),
    ({"phi": [0.1, "dense"]}, r"config key 'phi.1': 'dense' is not a number; allowed a "
                              r"number in \(0, 0.5\]"),
    ({"phi": [0.1, float("nan")]},
     r"config key 'phi.1': nan is not a number; allowed a number in \(0, 0.5\]"),
    ({"phi": []}, r"config key 'phi': \[\] should be non-empty"),
    # each phi's brushes are built at plan time: a phi the grid cannot realise is named
    ({"phi": [0.12, 0.05], "regular": [16], "random": []},
     r"phi is realised as 0.04688 instead of 0.05 .*\(case regular N = 16, grid = 64, "
     r"phi = 0.05\)"),
], ids=["out of range in a list", "zero", "text", "nan in a list", "empty", "unrealised"])
def test_a_bad_phi_is_refused_by_name_before_any_job(repo_copy: Path, tmp_path: Path,  # noqa: F811
                                                     bad: dict, message: str) -> None:
    assert_refused_at_plan_time(repo_copy, tmp_path, bad, message)


def test_the_convergence_figure_names_each_rows_phi() -> None:
    """A study over two phi draws one row per phi: each title names its phi
    (two rows read "regular N=4, kbar=rigid" alike, with other results)."""
    from brushcore import BrushParams, simulate
    from brushcore.data.aggregate import build_sweep
    from brushcore.data.convergence import extrapolate_sweep
    from brushcore.data.figures import convergence

    curves = [simulate(BrushParams("regular", 4, math.inf, grid, phi=phi))
              for phi in PHIS for grid in (32, 41, 48)]
    fig = convergence(extrapolate_sweep(build_sweep(curves)))
    titles = sorted({ax.get_title() for ax in fig.axes if ax.get_title()})
    assert len(titles) == 2 and all(", phi " in t for t in titles), titles
    assert {t.rsplit(", phi ", 1)[1] for t in titles} == {f"{p:g}" for p in PHIS}, titles
