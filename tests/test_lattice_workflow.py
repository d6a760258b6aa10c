"""Issue 13 in the workflow: hexagonal brushes and pillar shapes.

Dry runs (no job starts) for the plans and the plan-time checks; a few
tiny curves (N = 4 on 32^2, well under a second each) for the sweep's
``shape`` dimension and the lattice figure.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from test_workflow import (assert_refused_at_plan_time, expected_cases, output,  # noqa: F401
                           repo_copy, snakemake)  # repo_copy: fixture

xr = pytest.importorskip("xarray")
pytest.importorskip("snakemake")


def planned_curves(workdir: Path, tmp_path: Path, extra: dict,
                   base: str = "config/test.yaml") -> set[str]:
    """Curve files a dry run plans with `extra` on top of `base` (all of them: --forceall)."""
    config = tmp_path / "extra.yaml"
    config.write_text(yaml.safe_dump(extra))
    proc = snakemake(workdir, "-n", "--cores", "2", "--forceall", "--configfile", base,
                     str(config))
    assert proc.returncode == 0, output(proc)
    return set(re.findall(r"results/curves/[^\s,]+\.nc", output(proc)))


def paper_names(config: dict, grid: int, phi: float) -> set[str]:
    """The curve names of a disc config as they were before issue 13."""
    return {f"results/curves/{layout}/N{n}_kbar{kbar!r}_seed{seed}_grid{grid}_phi{phi!r}.nc"
            for layout, n, kbar, seed in expected_cases(config)}


@pytest.mark.parametrize("name", ["config.yaml", "test.yaml"])
def test_disc_configs_plan_the_same_file_names(repo_copy: Path, tmp_path: Path,  # noqa: F811
                                               name: str) -> None:
    config = yaml.safe_load((repo_copy / "config" / name).read_text())
    names = planned_curves(repo_copy, tmp_path, {}, base=f"config/{name}")
    assert names == paper_names(config, config["grid"], config["phi"])


def test_hexagonal_and_shapes_plan_suffixed_names(repo_copy: Path,  # noqa: F811
                                                  tmp_path: Path) -> None:
    """Every brush runs every shape; discs keep their names; hexagonal runs seed 0."""
    names = planned_curves(repo_copy, tmp_path, {
        "regular": [], "hexagonal": [16], "random": [4], "kbar": [0.01], "seeds": [0, 1],
        "shape": ["disc", "square", "ellipse"], "aspect": 2.0, "orientation": 30.0,
        "fig5": {"n_pillars": 16, "layout": "hexagonal", "shape": "square", "kbar": [1.0]},
    })
    suffixes = ("", "_square_30.0", "_ellipse2.0_30.0")
    expected = {f"results/curves/hexagonal/N16_kbar0.01_seed0_grid64_phi0.12{s}.nc"
                for s in suffixes}
    expected |= {f"results/curves/random/N4_kbar0.01_seed{seed}_grid64_phi0.12{s}.nc"
                 for seed in (0, 1) for s in suffixes}
    expected.add("results/curves/hexagonal/N16_kbar1.0_seed0_grid64_phi0.12_square_30.0.nc")
    assert names == expected, names ^ expected


def test_rough_hexagonal_brushes_run_every_seed(repo_copy: Path,  # noqa: F811
                                                tmp_path: Path) -> None:
    names = planned_curves(repo_copy, tmp_path, {
        "regular": [], "hexagonal": [16], "random": [], "kbar": [0.01], "seeds": [0, 1],
        "roughness": [0.0, 0.2], "shape": ["square"],
        "fig5": {"n_pillars": 16, "layout": "hexagonal", "shape": "square", "kbar": [0.01]},
    })
    stem = "results/curves/hexagonal/N16_kbar0.01_seed{}_grid64_phi0.12_square{}.nc"
    assert names == {stem.format(0, ""), *(stem.format(s, "_S0.2_P0.0_C0.0") for s in (0, 1))}


def test_lists_of_aspects_and_orientations_run_every_shape(repo_copy: Path,  # noqa: F811
                                                           tmp_path: Path) -> None:
    """aspect and orientation take lists: every ellipse at each aspect, every
    square and ellipse at each orientation, one shape label (and curve) each;
    discs keep their names.  (One value each was all a sweep could vary.)"""
    names = planned_curves(repo_copy, tmp_path, {
        "regular": [4], "random": [], "kbar": [0.1], "shape": ["disc", "square", "ellipse"],
        "aspect": [2.0, 3.0], "orientation": [0.0, 30.0], "allow_coarse": True,
        "fig5": {"kbar": []},
    })
    stem = "results/curves/regular/N4_kbar0.1_seed0_grid64_phi0.12{}.nc"
    assert names == {stem.format(s) for s in (
        "", "_square", "_square_30.0", "_ellipse2.0_0.0", "_ellipse2.0_30.0",
        "_ellipse3.0_0.0", "_ellipse3.0_30.0")}, names


def test_lattice_config_plans_the_study(repo_copy: Path) -> None:  # noqa: F811
    config = yaml.safe_load((repo_copy / "config/lattices.yaml").read_text())
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--forceall", "--configfile",
                     "config/lattices.yaml")
    text = output(proc)
    assert proc.returncode == 0, text
    runs = len(config["kbar"]) * len(config["shape"]) * (2 + len(config["seeds"]))
    assert re.search(rf"^simulate\s+{runs}\s*$", text, flags=re.MULTILINE), text
    assert re.search(r"^lattices\s+1\s*$", text, flags=re.MULTILINE), text
    assert "results/figures/lattices.png" in text


def test_disc_config_makes_no_lattice_figure(repo_copy: Path) -> None:  # noqa: F811
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--forceall", "--configfile",
                     "config/test.yaml")
    assert proc.returncode == 0, output(proc)
    assert "lattices" not in output(proc)


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        ({"hexagonal": [10]}, r"config: hexagonal = 10 is invalid .*allowed a count that fills "
                              r"a hexagonal lattice, e\.g\. 9 or 12"),
        ({"hexagonal": [7]}, r"config: hexagonal = 7 is invalid"),
        ({"shape": ["disc", "hexagon"]}, r"config key 'shape\.1': 'hexagon' is not one of"),
        ({"aspect": 20.0}, r"config key 'aspect': 20\.0 is greater than the maximum"),
        ({"aspect": [2.0, 20.0], "shape": ["ellipse"]},
         r"config key 'aspect\.1': 20\.0 is greater than the maximum of 10"),
        ({"fig5": {"n_pillars": 16, "shape": "star", "kbar": [0.01]}},
         r"config key 'fig5\.shape': 'star' is not one of"),
        ({"fig5": {"n_pillars": 16, "layout": "random", "kbar": [0.01]}},
         r"config key 'fig5\.layout': 'random' is not one of"),
        # squares of a regular 4 x 4 brush quantise badly on 64^2: the shape is named
        ({"shape": ["square"], "orientation": 30.0, "regular": [16], "random": []},
         r"phi is realised as .*shape = square_30\.0"),
    ],
)
def test_bad_lattice_config_stops_before_any_job(repo_copy: Path,  # noqa: F811
                                                 tmp_path: Path, bad: dict,
                                                 message: str) -> None:
    assert_refused_at_plan_time(repo_copy, tmp_path, bad, message)


# -- brushes of one's own: layout_files ---------------------------------------------------

def _own_array(workdir: Path, name: str = "my_array.npy") -> Path:
    """A label map of one's own in `workdir`/arrays: random 16 of seed 3 on 64^2."""
    from brushcore import BrushParams
    from brushcore.model.layout import build_labels
    from brushcore.model.layout_file import save_label_map

    (workdir / "arrays").mkdir(exist_ok=True)
    return save_label_map(build_labels(BrushParams("random", 16, 0.01, 64, seed=3)),
                          workdir / "arrays" / name)


def test_layout_files_plan_their_own_n_grid_and_phi(repo_copy: Path,  # noqa: F811
                                                    tmp_path: Path) -> None:
    """Each file runs every kbar on its own grid, N and phi, seed 0 (nothing drawn)."""
    _own_array(repo_copy)
    names = planned_curves(repo_copy, tmp_path, {
        "regular": [], "random": [], "kbar": [0.01, math.inf],
        "layout_files": ["arrays/my_array.npy"], "fig5": {"n_pillars": 16, "kbar": [0.01]}})
    files = {n for n in names if "/file_" in n}
    assert files == {f"results/curves/file_my_array/N16_kbar{k}_seed0_grid64_phi0.1201171875.nc"
                     for k in ("0.01", "inf")}, names


@pytest.mark.parametrize(
    ("files", "message"),
    [
        (["arrays/missing.npy"], r"config key 'layout_files\.0': 'arrays/missing\.npy' is "
                                 r"invalid \(no such file\): allowed an existing"),
        (["arrays/my array.npy"], r"config key 'layout_files\.0': 'arrays/my array\.npy' is "
                                  r"invalid: allowed a file whose name"),
        (["arrays/my_array.npy", "my_array.png"], r"config key 'layout_files\.1': "
                                                  r"'my_array\.png' is invalid: its name"),
    ],
)
def test_bad_layout_files_stop_before_any_job(repo_copy: Path, tmp_path: Path,  # noqa: F811
                                              files: list, message: str) -> None:
    _own_array(repo_copy)
    assert_refused_at_plan_time(repo_copy, tmp_path, {"layout_files": files}, message)


@pytest.mark.slow
def test_a_brush_of_ones_own_runs_through_the_workflow(tmp_path: Path) -> None:
    """End to end: the file brush enters sweep.nc as layout file_my_array with the
    file's N and phi, and its numbers are those of `simulate(file_params(...))`
    (to round-off) and of the random brush the map was drawn from (within the
    3e-7 that single- against double-precision transforms leave)."""
    import shutil

    from brushcore import BrushParams, file_params, simulate
    from test_workflow import IGNORE, REPO

    work = tmp_path / "repo"
    shutil.copytree(REPO, work, ignore=IGNORE)
    path = _own_array(work)
    config = tmp_path / "own.yaml"
    config.write_text(yaml.safe_dump({
        "regular": [], "random": [], "kbar": [0.01, math.inf], "layout_files": [
            "arrays/my_array.npy"], "fig5": {"n_pillars": 4, "kbar": [0.01]}}))
    proc = snakemake(work, "--cores", "2", "--configfile", "config/test.yaml", str(config))
    assert proc.returncode == 0, output(proc)[-4000:]
    with xr.open_dataset(work / "results/sweep.nc") as sweep:
        own = sweep.sel(layout="file_my_array", n_pillars=16).squeeze()
        assert float(own.phi_actual.sel(kbar=0.01)) == 0.1201171875
        for kbar in (0.01, math.inf):
            f_ad = float(own.adhesive_force_normalized.sel(kbar=kbar))
            direct = simulate(file_params(path, kbar))
            assert f_ad == pytest.approx(float(direct.adhesive_force_normalized), rel=1e-12)
            drawn = simulate(BrushParams("random", 16, kbar, 64, seed=3))
            assert f_ad == pytest.approx(float(drawn.adhesive_force_normalized), rel=1e-5)
    assert (work / "results/figures/fig6.png").exists()


# -- brushes as made: a layout file's heights, stiffness factors and gap map ------------

def _made_inputs(workdir: Path) -> dict:
    """Heights [d_K] and stiffness factors of the 16 pillars of `_own_array`."""
    heights = np.linspace(0.1, 0.9, 16)[np.random.default_rng(7).permutation(16)]
    np.savetxt(workdir / "arrays" / "heights.txt", heights)
    np.save(workdir / "arrays" / "factors.npy", np.geomspace(0.5, 2.0, 16))
    return {"heights": heights, "factors": np.geomspace(0.5, 2.0, 16)}


def test_a_brush_as_made_runs_the_cases_that_draw_nothing_it_was_given(
        repo_copy: Path, tmp_path: Path) -> None:  # noqa: F811
    """Given heights and factors, the file brush runs roughness 0 and kbar_spread
    0 only (they are exclusive), at every preload; the plain map runs them all."""
    _own_array(repo_copy)
    _own_array(repo_copy, "plain.npy")
    _made_inputs(repo_copy)
    names = planned_curves(repo_copy, tmp_path, {
        "regular": [], "random": [], "kbar": [0.01], "roughness": [0.0, 0.3],
        "preload": [0.0, 1.0], "kbar_spread": [0.0, 0.2],
        "layout_files": [{"layout": "arrays/my_array.npy", "heights": "arrays/heights.txt",
                          "kbar_factors": "arrays/factors.npy"}, "arrays/plain.npy"],
        "fig5": {"n_pillars": 16, "kbar": [0.01]}})
    stem = "N16_kbar0.01_seed0_grid64_phi0.1201171875"
    made = {n for n in names if "/file_my_array/" in n}
    assert made == {f"results/curves/file_my_array/{stem}{tag}.nc"
                    for tag in ("", "_S0.0_P1.0_C0.0")}, made
    plain = {n for n in names if "/file_plain/" in n}
    assert len(plain) == 2 * 2 * 2 - 1 + 1, plain  # S x P x C, seed 0 flat; seed 0 drawn
    # preload 0 pulls a brush of uneven heights off from first touch: planning says so
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", "config/test.yaml",
                     str(tmp_path / "extra.yaml"))
    assert re.search(r"the brush of layout_files\.0 is given heights or a gap map, and "
                     r"'preload' holds 0\.0: that approach stops at first touch", output(proc))


@pytest.mark.parametrize(
    ("entry", "extra", "message"),
    [
        ({"heights": "arrays/h15.txt"}, {},
         r"config key 'layout_files\.0\.heights': 'arrays/h15\.txt' is invalid \(it holds 15 values\): "
         r"allowed 16 values, one per pillar"),
        ({"kbar_factors": "arrays/zero.txt"}, {},
         r"config key 'layout_files\.0\.kbar_factors': 'arrays/zero\.txt' is invalid "
         r"\(line 16 holds 0\.0\): allowed finite factors > 0"),
        ({"kbar_factors": "arrays/tiny.txt"}, {"kbar": [1.0e-6, 1.0]},
         r"'layout_files\.0\.kbar_factors': 'arrays/tiny\.txt' is invalid \(pillar 15: "
         r"factor 0\.0001 makes it 1e-10\): allowed factors whose products with kbar = 1e-06 "
         r"lie in \[1e-09, inf\]"),
        ({"gap_map": "arrays/h15.txt"}, {},
         r"'layout_files\.0\.gap_map': 'arrays/h15\.txt' is invalid \(line 1 holds 1 numbers\): "
         r"allowed 64 lines of 64 numbers"),
        ({"heights": "arrays/h16.txt"}, {"roughness": [0.3]},
         r"config key 'roughness': \[0\.3\] has no 0\.0, which the brush of "
         r"'layout_files\.0\.heights' needs"),
        ({"height": "arrays/h16.txt"}, {},
         r"config key 'layout_files\.0\.height' is unknown; did you mean 'heights'\?"),
    ],
)
def test_bad_inputs_of_a_brush_as_made_stop_before_any_job(
        repo_copy: Path, tmp_path: Path, entry: dict, extra: dict,  # noqa: F811
        message: str) -> None:
    _own_array(repo_copy)
    arrays = repo_copy / "arrays"
    np.savetxt(arrays / "h15.txt", np.zeros(15))
    np.savetxt(arrays / "h16.txt", np.zeros(16))
    np.savetxt(arrays / "zero.txt", np.r_[np.ones(15), 0.0])
    np.savetxt(arrays / "tiny.txt", np.r_[np.ones(15), 1e-4])
    assert_refused_at_plan_time(repo_copy, tmp_path, {
        "layout_files": [{"layout": "arrays/my_array.npy", **entry}], **extra}, message)


@pytest.mark.filterwarnings("ignore::brushcore.FirstTouchWarning")  # first touch meant
def test_sweep_and_figures_tell_a_brush_as_made_from_a_flat_one(tmp_path: Path) -> None:
    """sweep.nc gives a brush as made the rough dimensions and `given_inputs`
    even at preload 0; `flat_slice` (the paper's figures and summary) leaves
    it out and keeps the plain map; the rough figures title it "as made"; two
    files get two styles in Fig. 7."""
    from brushcore import SolverOptions, file_params, read_curve, simulate
    from brushcore.data import figures
    from brushcore.data.figures.common import layout_styles
    from brushcore.data.aggregate import build_sweep, given_inputs
    from brushcore.data.io import write_curve
    from brushcore.data.summary import headline_rows
    from brushcore.data.views import flat_slice

    made = _made_inputs(_own_array(tmp_path).parent.parent)
    plain = _own_array(tmp_path, "plain.npy")
    paths = []
    for kbar in (0.01, math.inf):
        for name, params in (("made", file_params(tmp_path / "arrays" / "my_array.npy", kbar,
                                                  heights=made["heights"])),
                             ("plain", file_params(plain, kbar))):
            # another rtol for one curve: sweep.nc then says where (run_rtol) too
            options = SolverOptions(rtol=1e-6 if name == "plain" and kbar == math.inf else 1e-4)
            paths.append(write_curve(simulate(params, options), tmp_path / f"{name}_{kbar}.nc"))
    sweep = build_sweep(paths)
    assert {"roughness", "preload", "kbar_spread"} <= set(sweep.dims) and "run_rtol" in sweep
    # a curve written before the attribute: its variables say what it was given
    older = read_curve(paths[0]).copy()
    del older.attrs["given_inputs"]
    assert given_inputs(older) == "heights" and given_inputs(read_curve(paths[1])) == ""
    made_cases = (sweep.given_inputs != "").any([d for d in sweep.given_inputs.dims
                                                 if d != "layout"])
    assert sweep.layout.values[made_cases.values].tolist() == ["file_my_array"]
    assert set(sweep.given_inputs.sel(layout="file_plain").values.ravel()) == {""}
    flat = flat_slice(sweep)
    assert flat.layout.values.tolist() == ["file_plain"] and "given_inputs" not in flat
    assert float(flat.adhesive_force_normalized.sel(kbar=0.01).squeeze()) == pytest.approx(
        float(simulate(file_params(plain, 0.01)).adhesive_force_normalized), rel=1e-12)
    fig = figures.rough_preload(sweep, "file_my_array", 16)
    assert "as made (heights given)" in fig.get_suptitle().replace("\n", " ")
    styles = layout_styles(["regular", "file_a", "file_b"])
    assert len(set(styles.values())) == 3
    # a rigid Fig. 5 brush keeps its row; NaN (fig5.kbar []) leaves it out
    rows = headline_rows(sweep, fig5_layout="file_plain", fig5_n_pillars=16,
                         fig5_kbar=math.inf)
    assert rows[0].quantity.startswith("F_ad (normalised), Fig. 5a"), rows[0]
    rows = headline_rows(sweep, fig5_layout="file_plain", fig5_n_pillars=16,
                         fig5_kbar=math.nan)
    assert not any("Fig. 5a" in row.quantity for row in rows)
    # tables request no phi: the theory row takes the realised one; no 2304 row
    phi = float(np.nanmean(flat.phi_actual.values))
    theory_row = rows[0]
    assert theory_row.quantity.startswith("rigid limit") and theory_row.value == \
        f"{phi ** -0.25:.3g}" and f"phi = {phi:.3g} realised" in theory_row.note, theory_row
    assert not any("2304" in row.quantity for row in rows)


@pytest.mark.slow
def test_a_brush_as_made_runs_through_the_workflow(tmp_path: Path) -> None:
    """End to end, a sweep of one's own brush alone (no generated brush, no
    Fig. 5): heights, stiffness factors and a preload reach sweep.nc (layout
    file_my_array with the rough dimensions and `given_inputs`) with the
    numbers of `simulate` given the same arrays (to round-off); the rough
    figures show it, the paper's figures and summary leave it out; editing
    the heights, or swapping which file gives which input, reruns it."""
    import shutil

    from brushcore import file_params, simulate
    from test_workflow import IGNORE, REPO

    work = tmp_path / "repo"
    shutil.copytree(REPO, work, ignore=IGNORE)
    path = _own_array(work)
    made = _made_inputs(work)
    entry = {"layout": "arrays/my_array.npy", "heights": "arrays/heights.txt",
             "kbar_factors": "arrays/factors.npy"}
    config = tmp_path / "made.yaml"
    config.write_text(yaml.safe_dump({
        "regular": [], "random": [], "kbar": [0.01, math.inf], "preload": [1.0],
        "layout_files": [entry], "fig5": {"kbar": []}}))
    proc = snakemake(work, "--cores", "2", "--configfile", "config/test.yaml", str(config))
    assert proc.returncode == 0, output(proc)[-4000:]
    with xr.open_dataset(work / "results/sweep.nc") as sweep:
        assert sweep.layout.values.tolist() == ["file_my_array"]
        own = sweep.sel(layout="file_my_array", n_pillars=16, preload=1.0).squeeze()
        for kbar in (0.01, math.inf):
            case = own.sel(kbar=kbar)
            assert str(case.given_inputs.values) == "heights kbar_values"
            kbar_values = kbar * made["factors"]  # inf at kbar inf: rigid
            direct = simulate(file_params(path, kbar, heights=made["heights"],
                                          kbar_values=kbar_values, preload=1.0))
            for name in ("adhesive_force_normalized", "work_of_separation_normalized",
                         "pillars_in_contact_at_preload"):
                assert float(case[name]) == pytest.approx(float(direct[name]), rel=1e-12)
        # the stiffness factors matter: the brush differs from its uniform one
        uniform = simulate(file_params(path, 0.01, heights=made["heights"], preload=1.0))
        assert abs(float(own.adhesive_force_normalized.sel(kbar=0.01))
                   / float(uniform.adhesive_force_normalized) - 1) > 1e-3
    figures = work / "results/figures"
    for name in ("rough_preload", "rough_roughness", "rough_loop", "load_sharing", "fig6"):
        assert (figures / f"{name}.png").exists(), name
    assert not (figures / "fig5.png").exists()
    summary = (work / "results/summary.md").read_text()
    assert "Fig. 5a" not in summary and "file_my_array" not in summary, summary

    def rerun(change) -> int:
        change()
        dry = snakemake(work, "-n", "--cores", "2", "--configfile", "config/test.yaml",
                        str(config))
        assert dry.returncode == 0, output(dry)
        return len(re.findall(r"results/curves/file_my_array/[^\s,]+\.nc", output(dry)))

    swapped = {**entry, "heights": "arrays/factors.npy", "kbar_factors": "arrays/heights.txt"}
    assert rerun(lambda: config.write_text(config.read_text().replace(
        yaml.safe_dump([entry]).strip(), yaml.safe_dump([swapped]).strip()))) >= 2
    config.write_text(config.read_text().replace(yaml.safe_dump([swapped]).strip(),
                                                 yaml.safe_dump([entry]).strip()))
    assert rerun(lambda: None) == 0
    assert rerun(lambda: np.savetxt(work / "arrays" / "heights.txt",
                                    made["heights"] * 0.5)) >= 2

    def put_back_old() -> None:  # cp -p, rsync -a, tar: new content, a time before the curves
        np.savetxt(work / "arrays" / "heights.txt", made["heights"] * 0.25)
        os.utime(work / "arrays" / "heights.txt", (1e9, 1e9))

    assert rerun(put_back_old) >= 2  # the content, not the time (a lab helper's find)


def test_a_bare_maps_edit_reruns_its_curves(tmp_path: Path) -> None:
    """A map without heights is no input of its jobs (its curves predate
    brushes as made), so an edit that keeps N and phi (a pillar moved 3
    elements) planned nothing and the sweep kept the old F_ad (a lab
    helper's find): the files' digest is a param of the job."""
    from brushcore import BrushParams
    from brushcore.model.layout import build_labels
    from brushcore.model.layout_file import save_label_map
    from test_workflow import _common_rules

    labels = build_labels(BrushParams("random", 16, 1.0, 128, seed=1))
    path = tmp_path / "bare.npy"
    save_label_map(labels, path)
    rules = _common_rules()
    config = {"layout_files": [str(path)], "kbar": [1.0]}
    before = rules["brush_files"](config, "file_bare")
    assert before["layout"] == str(path) and len(before["sha256"]) == 64
    moved = labels.copy()
    moved[labels == 5] = -1
    moved[np.roll(labels == 5, 3, axis=1)] = 5
    assert (moved >= 0).sum() == (labels >= 0).sum()
    save_label_map(moved, path)
    os.utime(path, (1e9, 1e9))  # older than any curve
    rules = _common_rules()
    after = rules["brush_files"](config, "file_bare")
    assert after["sha256"] != before["sha256"]
    assert rules["brush_files"](config, "regular") == ""


# -- sweep.nc with a shape dimension, and the figures ------------------------------------

#: (layout, kbar, shape) of the tiny sweep; hexagonal squares at kbar 1 are left out.
CASES = [("regular", 1.0, "disc"), ("regular", 1.0, "square"), ("regular", 1e-3, "disc"),
         ("hexagonal", 1.0, "disc"), ("hexagonal", 1e-3, "disc"), ("hexagonal", 1e-3, "square"),
         ("random", 1.0, "square")]


def _own_table(workdir: Path, name: str = "my_table") -> Path:
    """A pillar table of one's own in `workdir`/arrays: the 2 x 2 lattice at phi 0.12."""
    from brushcore import BrushParams, generated_table, save_pillar_table

    (workdir / "arrays").mkdir(exist_ok=True)
    return save_pillar_table(generated_table(BrushParams("regular", 4, 0.01, 64)),
                             workdir / "arrays" / name)


@pytest.mark.slow
def test_a_pillar_table_runs_on_every_grid_into_the_convergence_study(tmp_path: Path) -> None:
    """A table runs on the sweep's grids (its N's grid_by_n or grid) at the
    discs' phi: sweep.nc holds it at each grid with the numbers of `simulate`
    (to round-off), the convergence study extrapolates it, and editing the
    table reruns its curves."""
    import shutil

    from brushcore import file_params, simulate
    from test_workflow import IGNORE, REPO

    work = tmp_path / "repo"
    shutil.copytree(REPO, work, ignore=IGNORE)
    path = _own_table(work)
    config = tmp_path / "table.yaml"
    config.write_text(yaml.safe_dump({
        "regular": [], "random": [], "kbar": [0.01, math.inf], "grid": [48, 64],
        "grid_by_n": [{"n_pillars": 4, "grid": [48, 64, 96]}],
        "layout_files": ["arrays/my_table.csv"], "fig5": {"kbar": []}}))
    proc = snakemake(work, "--cores", "2", "--configfile", "config/test.yaml", str(config))
    assert proc.returncode == 0, output(proc)[-4000:]
    with xr.open_dataset(work / "results/sweep.nc") as sweep:
        assert sweep.layout.values.tolist() == ["file_my_table"]
        assert sweep.grid.values.tolist() == [48, 64, 96]
        for kbar in (0.01, math.inf):
            for grid in (48, 64, 96):
                case = sweep.sel(layout="file_my_table", n_pillars=4, kbar=kbar,
                                 grid=grid).squeeze()
                direct = simulate(file_params(path, kbar, grid=grid))
                for name in ("adhesive_force_normalized", "work_of_separation_normalized"):
                    assert float(case[name]) == pytest.approx(float(direct[name]),
                                                              rel=1e-12)
    with xr.open_dataset(work / "results/convergence.nc") as study:
        fits = study.sel(layout="file_my_table", n_pillars=4).squeeze()
        assert np.isfinite(fits.adhesive_force_normalized.values).all()
        assert fits.sizes["grid"] == 3
    assert "file_my_table" in (work / "results/convergence.md").read_text()

    def planned() -> int:
        dry = snakemake(work, "-n", "--cores", "2", "--configfile", "config/test.yaml",
                        str(config))
        assert dry.returncode == 0, output(dry)
        return len(set(re.findall(r"results/curves/file_my_table/[^\s,]+\.nc",
                                  output(dry))))

    assert planned() == 0
    path.write_text(path.read_text().replace("0.25, 0.25,", "0.26, 0.25,"))
    assert planned() == 6


@pytest.mark.parametrize("entry, message", [
    ({"layout": "arrays/my_table.csv", "gap_map": "arrays/gap.npy"},
     r"layout_files.0.gap_map': 'arrays/gap.npy' is invalid \(the table "
     r"'arrays/my_table.csv' runs on grids \[32, 64\], and a gap map fits one\)"),
    ("arrays/stub.csv", r"grid = 32 is invalid \(1 of 2 pillars are at most two elements "
     r"across, pillar 1 of 1 elements among them.*\): allowed grid \d+, "),
    ({"layout": "arrays/my_table.csv", "heights": "arrays/five.txt"},
     r"layout_files.0.heights': 'arrays/five.txt' is invalid \(it holds 5 values; .*\): "
     r"allowed 4 values, one per pillar"),
], ids=["gap map on two grids", "a stub too small for a grid", "heights miscounted"])
def test_a_pillar_table_that_a_grid_cannot_run_is_refused_at_plan_time(
        repo_copy: Path, tmp_path: Path, entry, message: str) -> None:  # noqa: F811
    _own_table(repo_copy)
    np.save(repo_copy / "arrays" / "gap.npy", np.zeros((32, 32)))
    np.savetxt(repo_copy / "arrays" / "five.txt", np.zeros(5))
    (repo_copy / "arrays" / "stub.csv").write_text(  # 0.01 L: 0.32 elements on 32^2
        "x, y, radius\n0.3, 0.3, 0.1\n0.7, 0.7, 0.01\n")
    assert_refused_at_plan_time(repo_copy, tmp_path, {
        "regular": [], "random": [], "grid": [32, 64], "layout_files": [entry],
        "fig5": {"kbar": []}}, message)


@pytest.fixture(scope="module")
def shape_curves(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    from brushcore import BrushParams, simulate
    from brushcore.data.io import write_curve

    root = tmp_path_factory.mktemp("shapes")
    files = []
    for layout, kbar, shape in CASES:
        path = root / f"{layout}_{kbar}_{shape}.nc"
        # allow_coarse: 4 x 4-element squares miss phi by 17 %; this checks the bookkeeping
        write_curve(simulate(BrushParams(layout, 4, kbar, 32, shape=shape, allow_coarse=True)),
                    path)
        files.append(path)
    return files


@pytest.fixture(scope="module")
def shape_sweep(shape_curves: list[Path]):
    from brushcore.data.aggregate import build_sweep

    return build_sweep(shape_curves)


def test_sweep_has_a_shape_dimension_with_missing_cases_nan(shape_sweep) -> None:
    f = shape_sweep["adhesive_force_normalized"]
    assert f.dims == ("layout", "n_pillars", "kbar", "seed", "grid", "shape")
    assert shape_sweep.layout.values.tolist() == ["regular", "hexagonal", "random"]
    assert shape_sweep.shape.values.tolist() == ["disc", "square"]
    assert shape_sweep.shape.attrs["long_name"].startswith("pillar cross-section")
    # the label's numbers as coordinates along shape (a square: aspect 1, 0 degrees)
    assert shape_sweep.shape_aspect.values.tolist() == [1.0, 1.0]
    assert shape_sweep.shape_orientation.values.tolist() == [0.0, 0.0]
    assert shape_sweep.shape_orientation.attrs["units"] == "degree"
    one = f.isel(n_pillars=0, seed=0, grid=0)
    ran = {(lay, k, s) for lay, k, s in CASES}
    for layout in one.layout.values:
        for kbar in one.kbar.values:
            for shape in one["shape"].values:  # DataArray.shape is the numpy shape
                value = float(one.sel(layout=layout, kbar=kbar, shape=shape))
                assert math.isfinite(value) == ((layout, kbar, shape) in ran), \
                    (layout, kbar, shape, value)
    # the snapshots say which shape they are
    assert sorted(set(shape_sweep["case_shape"].values)) == ["disc", "square"]


def test_flat_slice_is_the_disc_sweep(shape_sweep, shape_curves) -> None:
    from brushcore.data.aggregate import build_sweep
    from brushcore.data.views import flat_slice, shape_slice

    discs = [p for p, c in zip(shape_curves, CASES) if c[2] == "disc"]
    alone = build_sweep(discs)
    assert "shape" not in alone.dims  # a disc sweep keeps today's dimensions
    from brushcore.data import figures
    assert "pillars)" not in figures.fig6(flat_slice(alone))._suptitle.get_text()
    sliced = flat_slice(shape_sweep)
    assert "shape" not in sliced.dims and "case_shape" not in sliced.coords
    assert "shape_aspect" not in sliced.coords and "shape_orientation" not in sliced.coords
    a = alone["adhesive_force_normalized"]
    b = sliced["adhesive_force_normalized"].sel(layout=a.layout, kbar=a.kbar)
    np.testing.assert_array_equal(a.values, b.values)
    assert sliced.sizes["case"] == alone.sizes["case"]
    square = shape_slice(shape_sweep, "square")["adhesive_force_normalized"]
    assert np.isfinite(square.sel(layout="random", kbar=1.0)).all()
    assert np.isnan(square.sel(layout="hexagonal", kbar=1.0)).all()


def test_figures_draw_a_hexagonal_panel_and_the_lattice_comparison(shape_sweep,
                                                                   tmp_path: Path) -> None:
    from brushcore.data import figures
    from brushcore.data.views import flat_slice

    discs = flat_slice(shape_sweep)
    fig6 = figures.fig6(discs)
    # one shape of several: the title says which (a disc-only sweep's does not)
    assert fig6._suptitle.get_text().endswith("(disc pillars)")
    titles = [ax.get_title(loc="left") for ax in fig6.axes]
    assert titles == ["(a) regular", "(b) hexagonal", "(c) random"], titles
    # the hexagonal panel adds its lattice's rigid limit at phi / fill, per N,
    # both lines at the phi each brush realised
    from brushcore import theory

    all_n = [int(n) for n in shape_sweep.n_pillars.values]

    def realised(layout: str, n: int) -> float:
        return float(discs["phi_actual"].sel(layout=layout, n_pillars=n).mean(skipna=True))

    def levels(ax, layout: str) -> set[float]:  # horizontal lines but eq. 5's and the punch's
        flat = {round(float(line.get_ydata()[0]), 9) for line in ax.get_lines()
                if len(set(np.ravel(line.get_ydata()))) == 1}
        return flat - {round(theory.rigid_limit(realised(layout, n)), 9) for n in all_n} - {1.0}

    assert levels(fig6.axes[1], "hexagonal") == {
        round(theory.hexagonal_rigid_limit(realised("hexagonal", n), n), 9) for n in all_n}
    assert not levels(fig6.axes[0], "regular")
    fig = figures.lattices(flat_slice(shape_sweep, None))
    # its rigid limits too at the phi the lattices realised (they took the one asked)
    every = flat_slice(shape_sweep, None)
    for ax in fig.axes:
        n = int(ax.get_title(loc="left").split("N = ")[1])
        lines = {round(float(line.get_ydata()[0]), 9) for line in ax.get_lines()
                 if len(set(np.ravel(line.get_ydata()))) == 1}
        for layout, limit in (("regular", theory.rigid_limit),
                              ("hexagonal", lambda phi: theory.hexagonal_rigid_limit(phi, n))):
            phi = float(every["phi_actual"].sel(layout=layout, n_pillars=n).mean(skipna=True))
            assert round(limit(phi), 9) in lines, (layout, n, lines)
    labels = fig.axes[0].get_legend_handles_labels()[1]
    for label in ("regular, disc", "regular, square", "hexagonal, square", "random, square"):
        assert label in labels, labels
    path = tmp_path / "lattices.png"
    figures.save(fig, path)
    assert path.stat().st_size > 10_000
    fig5 = figures.fig5(flat_slice(shape_sweep, "square"), n_pillars=4, kbar=[1e-3],
                        layout="hexagonal", shape="square")
    figures.save(fig5, tmp_path / "fig5.png")
    assert "square" in fig5.get_suptitle()


def test_fig5_of_the_whole_sweep_draws_the_shape_asked_for(shape_sweep, shape_curves) -> None:
    """Given the sweep as it is on disk (several shapes), Fig. 5 draws the
    named shape's curve and snapshots (it once drew both shapes' points as
    one curve beside the discs' snapshots, whatever the title said)."""
    from brushcore.data import figures
    from brushcore.data.io import read_curve

    for shape in ("square", "disc"):
        curve = read_curve(shape_curves[CASES.index(("regular", 1.0, shape))])
        fig = figures.fig5(shape_sweep, n_pillars=4, kbar=[1.0], shape=shape)
        d, f = fig.axes[0].lines[0].get_data()
        np.testing.assert_array_equal(f, curve["force_normalized"].values)
        image = fig.axes[1].get_images()[0].get_array()
        np.testing.assert_array_equal(image, curve["contact_snapshot"].values[0] + 1)


def test_figs_6_and_8_draw_rigid_pillars(tmp_path: Path) -> None:
    """kbar = inf is drawn one decade right of the stiffest finite kbar, under
    a "rigid" tick (it fell off the log axis, and Fig. 8 of rigid runs alone
    crashed)."""
    from brushcore import BrushParams, simulate
    from brushcore.data import figures
    from brushcore.data.aggregate import build_sweep
    from brushcore.data.io import write_curve

    paths = []
    for kbar in (math.inf, 1e-2):
        paths.append(tmp_path / f"k{kbar}.nc")
        write_curve(simulate(BrushParams("regular", 4, kbar, 32)), paths[-1])
    for files, x_rigid in ((paths, 0.1), (paths[:1], 1.0)):
        sweep = build_sweep(files)
        for draw, name in ((figures.fig6, "adhesive_force_normalized"),
                           (figures.fig8, "work_of_separation_normalized")):
            fig = draw(sweep)
            ax = fig.axes[0]
            xs = np.concatenate([line.get_xdata() for line in ax.lines if len(line.get_xdata())])
            ys = np.concatenate([line.get_ydata() for line in ax.lines if len(line.get_xdata())])
            rigid = float(sweep[name].sel(kbar=math.inf).squeeze())
            assert np.any((xs == x_rigid) & np.isclose(ys, rigid, rtol=1e-12)), (draw, xs, ys)
            assert "rigid" in [t.get_text() for t in ax.get_xticklabels()]
            # no line joins the rigid point to the finite ones: a NaN breaks it
            joined = [np.asarray(line.get_xdata(), dtype=float) for line in ax.lines
                      if line.get_marker() not in ("None", "", None)  # data, not axhlines
                      and len(line.get_xdata()) > 1]
            assert all(np.isnan(x[-2]) for x in joined if x[-1] == x_rigid), joined
            assert len(files) == 1 or joined, "the finite and rigid runs make one series"
            figures.save(fig, tmp_path / f"{draw.__name__}.png")


def test_rigid_tick_keeps_clear_of_the_decade_ticks() -> None:
    """"rigid" stands one decade right of the decade tick at or above the
    stiffest finite kbar: with kbar up to 2 that tick is 10 and rigid is at
    100 (at 20 its label ran into "10")."""
    from brushcore.data.figures.common import rigid_x

    assert rigid_x(np.array([1e-4, 2.0, math.inf])) == pytest.approx(100.0)
    assert rigid_x(np.array([1e-4, 1e-2, math.inf])) == pytest.approx(0.1)
    assert rigid_x(np.array([math.inf])) == 1.0


def test_summary_quotes_the_configs_fig5_brush(shape_sweep, shape_curves) -> None:
    """The summary's Fig. 5a row is the brush the config's `fig5` names (layout
    and shape), as the Fig. 5 figure draws it; the paper's value is quoted
    only beside the paper's brush."""
    from brushcore.data.io import read_curve
    from brushcore.data.summary import headline_rows

    def force(layout: str, kbar: float, shape: str) -> str:
        curve = read_curve(shape_curves[CASES.index((layout, kbar, shape))])
        return f"{float(curve['adhesive_force_normalized']):.3g}"

    for layout, kbar, shape in [("hexagonal", 1e-3, "square"), ("regular", 1.0, "disc")]:
        row = headline_rows(shape_sweep, fig5_layout=layout, fig5_n_pillars=4, fig5_kbar=kbar,
                            fig5_shape=shape)[0]
        assert (row.layout, row.value) == (layout, force(layout, kbar, shape)), row
        assert row.paper == "" and "16 x 16 discs at kbar 0.455" in row.note, row
    # the paper's ~1.8 stands beside its own brush only: 16 x 16 regular discs at 0.455
    row = headline_rows(shape_sweep, fig5_n_pillars=256, fig5_kbar=0.455)[0]
    assert (row.value, row.paper) == ("n/a", "~1.8"), row


def test_snapshots_pick_the_shape_asked_for(shape_sweep) -> None:
    """Disc and square snapshots of one (layout, N, kbar, seed) are told apart:
    discs unless a shape is named."""
    from brushcore.data.views import snapshots

    disc = snapshots(shape_sweep, "regular", 4, 1.0)
    square = snapshots(shape_sweep, "regular", 4, 1.0, shape="square")
    assert disc is not None and square is not None
    pillars = [int((s["contact_snapshot"].isel(snapshot=0) >= 0).sum()) for s in (disc, square)]
    assert pillars[0] != pillars[1], pillars  # 4 x 4-element squares against discs
    assert snapshots(shape_sweep, "hexagonal", 4, 1.0, shape="square") is None  # never ran
    with pytest.raises(TypeError, match="unknown case keys"):
        snapshots(shape_sweep, "regular", 4, 1.0, rougness=0.3)


def test_fig5_numbers_snapshots_in_the_order_of_the_curve(tmp_path: Path) -> None:
    """A preloaded brush's file keeps "maximum force" after "separated"
    (its steps [preload, separated, maximum]); Fig. 5 numbered them in that
    order, so "3: maximum force" came before "2: separated" on the curve."""
    from brushcore import BrushParams, simulate
    from brushcore.data import figures
    from brushcore.data.aggregate import build_sweep
    from brushcore.data.io import write_curve

    ds = simulate(BrushParams("regular", 4, 0.01, 32, preload=1.0))
    steps = [int(s) for s in ds.snapshot_step.values]
    assert steps[2] < steps[1], steps  # the file's order is not the curve's
    write_curve(ds, tmp_path / "c.nc")
    fig = figures.fig5(build_sweep([tmp_path / "c.nc"], keep_snapshots=[("regular", 4)]),
                       n_pillars=4, kbar=(0.01,))
    titles = [ax.get_title() for ax in fig.axes[1:] if ax.get_title()]
    assert titles == ["1: preload", "2: maximum force", "3: separated"], titles


def test_paper_figures_of_a_rough_only_sweep_say_no_flat_runs() -> None:
    """Figs. 6-8 draw flat brushes (`flat_slice`): where only rough ones ran,
    the empty panel says no *flat* runs, not that the layout did not run."""
    from brushcore.data import figures

    dims = ("layout", "n_pillars", "kbar", "seed")
    nan = np.full((1, 1, 1, 1), np.nan)
    sweep = xr.Dataset({"adhesive_force_normalized": (dims, nan),
                        "work_of_separation_normalized": (dims, nan)},
                       coords={"layout": ["regular"], "n_pillars": [16], "kbar": [0.01],
                               "seed": [0]})
    for draw, said in ((figures.fig6, "no flat regular runs"),
                       (figures.fig8, "no flat regular runs"), (figures.fig7, "no flat runs")):
        texts = [t.get_text() for ax in draw(sweep).axes for t in ax.texts]
        assert said in texts, (draw.__name__, texts)
    # brushes as made alone leave no layout at all: said, not a blank panel (a lab's find)
    none = sweep.isel(layout=slice(0, 0))
    for draw in (figures.fig6, figures.fig8):
        texts = [t.get_text() for ax in draw(none).axes for t in ax.texts]
        assert any(t.startswith("no flat runs (brushes given heights") for t in texts), texts


def test_a_coarse_study_is_said_by_the_narrowest_disc_and_only_where_refined(
        repo_copy: Path, tmp_path: Path) -> None:  # noqa: F811
    """Planning warns by the pillar the study's flags read: a table's smallest
    disc (radius 0.05 L: 2.4 elements on 48^2, where the mean radius has 4.4),
    and never for a label map, which runs on its own grid only."""
    from brushcore.model.pillar_table import PillarTable, save_pillar_table

    (repo_copy / "arrays").mkdir(exist_ok=True)
    save_pillar_table(PillarTable(np.array([[0.25, 0.25], [0.25, 0.75], [0.75, 0.25],
                                            [0.75, 0.75]]),
                                  np.array([0.1, 0.1, 0.1, 0.05])),
                      repo_copy / "arrays" / "small_disc")
    _own_array(repo_copy)
    config = tmp_path / "coarse.yaml"
    config.write_text(yaml.safe_dump({
        "regular": [], "random": [], "kbar": [0.01], "grid": [48, 64, 96],
        "layout_files": ["arrays/small_disc.csv", "arrays/my_array.npy"],
        "fig5": {"kbar": []}}))
    proc = snakemake(repo_copy, "-n", "--cores", "2", "--configfile", "config/test.yaml",
                     str(config))
    text = output(proc)
    assert proc.returncode == 0, text
    assert re.search(r"radius under 4 elements, .*\(file_small_disc N = 4 on 48: 2\.4 elements "
                     r"\(coarsest_under_resolved; n = 80 gives 4\)\)", text), text
    assert "N = 16" not in text, text  # the map: one grid, no study of it
