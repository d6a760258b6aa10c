"""What curve files and sweep.nc say about their values beyond the numbers: units."""

from __future__ import annotations

import pytest


def test_dimensional_values_in_element_units_say_so(tmp_path) -> None:
    """With e_star = dgamma = h = 1 (the workflow's) a variable in N, m or J
    holds element units: its comment says so, once, in the curve and in a
    sweep of it; a run in a material's units has no such comment."""
    from brushcore import BrushParams, simulate
    from brushcore.data.aggregate import build_sweep
    from brushcore.data.io import write_curve
    from brushcore.model.curve_format import ELEMENT_UNITS_COMMENT

    curve = simulate(BrushParams("regular", 4, 0.01, 48))
    marked = {n for n in curve.variables if ELEMENT_UNITS_COMMENT in
              curve[n].attrs.get("comment", "")}
    assert {"adhesive_force", "work_of_separation", "force", "displacement"} <= marked
    assert all(curve[n].attrs["units"] in ("m", "m2", "N", "J") for n in marked)
    write_curve(curve, tmp_path / "c.nc")
    sweep = build_sweep([tmp_path / "c.nc"], keep_snapshots=())
    assert sweep.adhesive_force.attrs["comment"] == ELEMENT_UNITS_COMMENT
    assert "comment" not in sweep.adhesive_force_normalized.attrs
    material = simulate(BrushParams("regular", 4, 0.01, 48, e_star=2e6, dgamma=0.05, h=1e-7))
    assert not any(ELEMENT_UNITS_COMMENT in material[n].attrs.get("comment", "")
                   for n in material.variables)


def test_an_atomic_write_removes_what_a_killed_one_left(tmp_path):
    """A writer killed mid-write (an aggregation, a table, a figure) leaves a
    `.NAME.*.tmp` beside its output; a later write of that output removes
    it once untouched for STALE_AFTER_S, not one touched since (a writer
    that started earlier may still be at work on it)."""
    import os
    import time

    from brushcore.data.io import STALE_AFTER_S, write_text_atomic

    out = tmp_path / "summary.csv"
    stale, live = tmp_path / ".summary.csv.killed.tmp", tmp_path / ".summary.csv.live.tmp"
    stale.write_text("half")
    live.write_text("half")
    old = time.time() - STALE_AFTER_S - 60
    os.utime(stale, (old, old))
    os.utime(live, (time.time() - 60, time.time() - 60))  # an earlier writer, still going
    write_text_atomic(out, "a,b\n")
    assert out.read_text() == "a,b\n"
    assert not stale.exists() and live.exists()


def test_none_is_a_declared_fill_that_xarray_skips(tmp_path) -> None:
    """"None" in an integer variable (a step map outside the pillars, the
    branch before the first waypoint, a stage never reached) is its netCDF
    _FillValue: `xr.open_dataset` reads NaN there, so the mean detachment
    step is the pillars' (0.89 for 14.1 with the -1s counted, a 16-pillar
    brush at 64^2), while `read_curve` keeps the numbers as `simulate` made
    them, its digest checks and the curve writes again as it was."""
    import warnings

    import numpy as np
    import xarray as xr

    from brushcore import BrushParams, Waypoint, simulate
    from brushcore.data.io import read_curve, write_curve
    from brushcore.model.curve_format import FILL_VALUES

    flat = simulate(BrushParams("regular", 16, 0.455, 64))
    with warnings.catch_warnings():  # it never pulls: said, and wanted here
        warnings.simplefilter("ignore")
        pressed = simulate(BrushParams("regular", 16, 0.1, 64),
                           protocol=[Waypoint("force", -1.0), Waypoint("force", -2.0)])
    for name, curve in (("flat", flat), ("pressed", pressed)):
        path = tmp_path / f"{name}.nc"
        write_curve(curve, path)
        with xr.open_dataset(path) as ds:
            for var in set(FILL_VALUES) & set(curve.data_vars):
                raw = curve[var].values
                none = raw == FILL_VALUES[var]
                assert np.array_equal(np.isnan(ds[var].values), none), (name, var)
                assert np.array_equal(ds[var].values[~none], raw[~none]), (name, var)
            step = flat.detachment_step.values if name == "flat" else None
            if step is not None:
                assert float(ds.detachment_step.mean()) == step[step >= 0].mean()
                assert float(ds.detachment_step.mean()) > 5 * step.mean()
        back = read_curve(path)
        for var in set(FILL_VALUES) & set(curve.data_vars):
            assert back[var].dtype == curve[var].dtype, (name, var)
            assert np.array_equal(back[var].values, curve[var].values), (name, var)
            assert "_FillValue" not in back[var].attrs
        write_curve(back, tmp_path / f"{name}_again.nc")
        assert read_curve(tmp_path / f"{name}_again.nc").identical(back)
    # a protocol that never pulls has no maximum force: its map is all fill,
    # not a map of a detached brush (the brush stays in full contact)
    assert int(pressed.snapshot_step.values[-1]) == -1
    assert (pressed.contact_snapshot.values[-1] == FILL_VALUES["contact_snapshot"]).all()
    assert int(pressed.attached_pillars.values[-1]) == 16


def test_a_sweeps_snapshot_padding_is_fill_and_left_out(tmp_path) -> None:
    """A case with fewer snapshots (a protocol's 3 beside a pull-off's 5) is
    padded with maps of the fill, not of the flag "no pillar";
    `views.snapshots` returns the case's own snapshots only."""
    import numpy as np
    import xarray as xr

    from brushcore import BrushParams, simulate
    from brushcore.data.aggregate import build_sweep, write_sweep
    from brushcore.data.views import snapshots

    flat = simulate(BrushParams("regular", 4, 0.01, 48))
    rough = simulate(BrushParams("regular", 4, 0.01, 48, roughness=0.3, preload=1.0, seed=1))
    sweep = build_sweep([flat, rough], keep_snapshots=[("regular", 4)])
    write_sweep(sweep, tmp_path / "sweep.nc")
    with xr.open_dataset(tmp_path / "sweep.nc") as ds:
        mine = snapshots(ds, "regular", 4, 0.01, seed=1, roughness=0.3, preload=1.0)
        assert mine.snapshot_label.values.tolist() == \
            rough.snapshot_label.values.tolist()
        assert np.array_equal(mine.contact_snapshot.values, rough.contact_snapshot.values)
        assert np.array_equal(mine.snapshot_step.values, rough.snapshot_step.values)
        # a rough case of a sweep without one is no case (the flat brush's maps came back)
        flat_only = build_sweep([flat], keep_snapshots=[("regular", 4)])
        assert snapshots(flat_only, "regular", 4, 0.01, roughness=0.3) is None
        assert snapshots(flat_only, "regular", 4, 0.01, shape="square") is None
        assert snapshots(flat_only, "regular", 4, 0.01) is not None
        full = snapshots(ds, "regular", 4, 0.01)
        assert full.sizes["snapshot"] == 5 == ds.sizes["snapshot"]
        padded = ds.contact_snapshot.isel(case=int(np.flatnonzero(
            ds.case_roughness.values == 0.3)[0]), snapshot=slice(3, None))
        assert bool(np.isnan(padded.values).all())  # the fill, not -1 (no pillar)
        # the maps are placed: the curves' element centres, in the curves' units
        for axis in ("y", "x"):
            assert np.array_equal(ds[axis].values, flat[axis].values)
            assert ds[axis].attrs["units"] == flat[axis].attrs["units"] == "m"
        assert np.array_equal(mine.x.values, (np.arange(48) + 0.5) * 1.0)


def test_a_curve_opened_with_xarray_writes_again_as_it_was(tmp_path) -> None:
    """`xr.open_dataset` reads the fills as NaN (floats); `write_curve` of
    such a Dataset (attributes edited, say) writes the numbers back, so
    that `read_curve` finds its digest and the values `simulate` made."""
    import numpy as np
    import xarray as xr

    from brushcore import BrushParams, simulate
    from brushcore.data.io import read_curve, write_curve

    curve = simulate(BrushParams("regular", 4, 0.01, 48, roughness=0.2, preload=1.0, seed=1))
    write_curve(curve, tmp_path / "a.nc")
    with xr.open_dataset(tmp_path / "a.nc") as opened:
        edited = opened.load()
    assert edited.detachment_step.dtype.kind == "f"
    edited.attrs["comment"] = "edited"
    write_curve(edited, tmp_path / "b.nc")
    back = read_curve(tmp_path / "b.nc")
    for name in ("detachment_step", "attachment_step", "branch", "snapshot_step",
                 "contact_snapshot"):
        assert back[name].dtype == curve[name].dtype, name
        assert np.array_equal(back[name].values, curve[name].values), name


def test_a_curve_however_opened_writes_and_aggregates_as_simulated(tmp_path) -> None:
    """A diff reviewer's finds: a curve opened with mask_and_scale=False
    (_FillValue among the attributes) or decode_cf=False failed to write;
    one whose contact maps lost their encoding was written int32; and
    build_sweep cast xarray's NaN fills to INT_MIN (steps) and 0 ("detached"
    maps).  Each now writes the digest `simulate`'s curve has, and
    aggregates to the same sweep."""
    import numpy as np
    import xarray as xr

    from brushcore import BrushParams, Waypoint, simulate
    from brushcore.data.aggregate import build_sweep
    from brushcore.data.io import read_curve, write_curve

    curve = simulate(BrushParams("regular", 4, 0.01, 32))
    write_curve(curve, tmp_path / "a.nc")
    digest = read_curve(tmp_path / "a.nc").attrs["content_sha256"]
    opened = {}
    for name, kwargs in (("raw", {"mask_and_scale": False}), ("undecoded", {"decode_cf": False}),
                         ("masked", {})):
        with xr.open_dataset(tmp_path / "a.nc", **kwargs) as ds:
            opened[name] = ds.load()
    opened["masked"]["contact_snapshot"] = opened["masked"].contact_snapshot * 1  # no encoding
    for name, ds in opened.items():
        write_curve(ds, tmp_path / f"{name}.nc")
        back = read_curve(tmp_path / f"{name}.nc")
        assert back.contact_snapshot.dtype == np.int8, name
        assert back.attrs["content_sha256"] == digest, name
    with pytest.warns(UserWarning, match="the protocol never retracts"):
        never = simulate(BrushParams("regular", 4, 0.01, 32, roughness=0.2, seed=1),
                         protocol=[Waypoint("force", -1.0), Waypoint("force", -2.0)])
    write_curve(never, tmp_path / "never.nc")
    with xr.open_dataset(tmp_path / "never.nc") as ds:
        never_opened = ds.load()
    keep = [("regular", 4)]
    for given in (never, never_opened):
        sweep = build_sweep([given], keep_snapshots=keep)
        steps = sweep.snapshot_step.values
        assert steps.min() >= -1 and (steps == -1).sum() == 1  # the never-reached stage
        maps = sweep.contact_snapshot.values
        assert (maps[steps == -1] == -2).all()  # the fill, not 0 ("detached")
    ref, got = (build_sweep([c], keep_snapshots=keep) for c in (curve, opened["masked"]))
    for name in ("detachment_step", "snapshot_step", "contact_snapshot"):
        assert np.array_equal(got[name].values, ref[name].values), name
    assert ref.detachment_step.values.min() == -1
