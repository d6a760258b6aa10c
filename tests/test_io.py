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
