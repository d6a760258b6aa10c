"""Curve files and sweep.nc pass the IOOS compliance checker's CF-1.10 suite with no error."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from brushcore import BrushParams, simulate
from brushcore.data.aggregate import build_sweep, write_sweep
from brushcore.data.io import write_curve

pytest.importorskip("compliance_checker")


def cf_errors(path: Path, tmp_path: Path) -> list[str]:
    """Messages of every failed CF-1.10 check of the checker's highest priority."""
    from compliance_checker.runner import CheckSuite, ComplianceChecker

    CheckSuite.load_all_available_checkers()
    report = tmp_path / f"{path.stem}.json"
    ComplianceChecker.run_checker(str(path), ["cf:1.10"], verbose=0, criteria="normal",
                                  output_filename=str(report), output_format="json")
    results = json.loads(report.read_text())["cf:1.10"]
    errors = []
    for item in results.get("high_priorities", []):
        if item["value"][0] < item["value"][1]:
            errors += [f"{item['name']}: {m}" for m in item["msgs"]]
    return errors


@pytest.fixture(scope="module")
def curve_files(tmp_path_factory) -> list[Path]:
    root = tmp_path_factory.mktemp("cf")
    files = []
    for layout, n, kbar in (("regular", 4, 0.01), ("regular", 16, float("inf")),
                            ("random", 4, 1.0)):
        path = root / f"{layout}_{n}_{kbar}.nc"
        write_curve(simulate(BrushParams(layout, n, kbar, 64)), path)
        files.append(path)
    return files


@pytest.mark.parametrize("which", [0, 1, 2], ids=["soft regular", "rigid regular",
                                                  "random single precision"])
def test_curve_file_is_cf_clean(curve_files, tmp_path, which):
    assert cf_errors(curve_files[which], tmp_path) == []


def test_sweep_is_cf_clean(curve_files, tmp_path):
    sweep_nc = tmp_path / "sweep.nc"
    sweep = build_sweep(curve_files, keep_snapshots=[("regular", 4)])
    assert "case_kbar" in sweep.coords  # the snapshot cases are in the file checked
    # regular brushes run double, random ones float32: which case ran which
    assert sweep.attrs["fft_precision"] == "double; single"
    precision = sweep["run_fft_precision"].sel(seed=0, grid=64)
    assert precision.sel(layout="regular", n_pillars=16, kbar=float("inf")) == "double"
    assert precision.sel(layout="random", n_pillars=4, kbar=1.0) == "single"
    assert precision.sel(layout="random", n_pillars=16, kbar=1.0) == ""  # not run
    assert "run_rtol" not in sweep  # the same for every curve: an attribute only
    write_sweep(sweep, sweep_nc)
    assert cf_errors(sweep_nc, tmp_path) == []


def test_sweep_keeps_every_parameter(curve_files):
    sweep = build_sweep(curve_files)
    for name in ("e_star", "dgamma", "h", "min_gap", "rtol", "cascade", "tie_rtol",
                 "units_convention", "symbols", "grid", "phi"):
        assert name in sweep.attrs, name
    assert "a0 = sqrt(A / pi)" in sweep.attrs["symbols"]


def test_convergence_is_cf_clean(curve_files, tmp_path):
    from brushcore.data.convergence import extrapolate_sweep, write_dataset

    import warnings

    import xarray as xr

    path = tmp_path / "convergence.nc"
    with warnings.catch_warnings():
        warnings.simplefilter("error", xr.SerializationWarning)  # no NaN cast silently
        write_dataset(extrapolate_sweep(build_sweep(curve_files)), path)
    assert cf_errors(path, tmp_path) == []
    with xr.open_dataset(path) as conv:  # a count, as documented: integers, no fill
        for q in ("adhesive_force_normalized", "work_of_separation_normalized"):
            assert conv[f"{q}_n_grids"].dtype.kind == "i"
            assert "_FillValue" not in conv[f"{q}_n_grids"].encoding


def test_sweep_with_shapes_and_hexagonal_is_cf_clean(curve_files, tmp_path):
    """Issue 13: the layout "hexagonal" and the label coordinate `shape` keep sweep.nc CF-clean."""
    extra = []
    for layout, shape in (("hexagonal", "disc"), ("regular", "ellipse")):
        path = tmp_path / f"{layout}_{shape}.nc"
        params = BrushParams(layout, 4, 0.01, 64, shape=shape,
                             aspect=1.5 if shape == "ellipse" else 1.0)
        write_curve(simulate(params), path)
        extra.append(path)
    sweep_nc = tmp_path / "sweep_shapes.nc"
    sweep = build_sweep([*curve_files, *extra], keep_snapshots=[("regular", 4)])
    assert "shape" in sweep.dims and "case_shape" in sweep.coords
    write_sweep(sweep, sweep_nc)
    assert cf_errors(sweep_nc, tmp_path) == []


def test_sweep_from_curve_files_with_and_without_pillar_variables(curve_files, tmp_path):
    """Flat curve files have per-pillar variables since 2026-12-05; a sweep of
    older files (without them) and newer ones is the sweep of newer ones."""
    import xarray as xr

    from brushcore.data.io import read_curve

    older = tmp_path / "older.nc"
    ds = read_curve(curve_files[0])
    assert "pillar_force_at_adhesive_force" in ds and ds.sizes["pillar"] == 4
    ds = ds.drop_dims("pillar")
    del ds.attrs["pillar_order"], ds.attrs["content_sha256"]
    write_curve(ds, older)
    mixed = build_sweep([older, *curve_files[1:]], keep_snapshots=[("regular", 4)])
    new = build_sweep(curve_files, keep_snapshots=[("regular", 4)])
    xr.testing.assert_identical(mixed.drop_attrs(), new.drop_attrs())
    sweep_nc = tmp_path / "sweep_mixed.nc"
    write_sweep(mixed, sweep_nc)
    assert cf_errors(sweep_nc, tmp_path) == []
