"""What curve files and sweep.nc say about their values beyond the numbers: units."""

from __future__ import annotations


def test_dimensional_values_in_element_units_say_so(tmp_path) -> None:
    """With e_star = dgamma = h = 1 (the workflow's) a variable in N, m or J
    holds element units: its comment says so, once, in the curve and in a
    sweep of it; a run in a material's units has no such comment."""
    from brushcore import BrushParams, simulate
    from brushcore.data.aggregate import build_sweep
    from brushcore.data.io import write_curve
    from brushcore.model.curve import ELEMENT_UNITS_COMMENT

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
