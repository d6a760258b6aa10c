"""Fast options against the reference: local cascades, lookahead, tolerance."""

from __future__ import annotations

import pytest

from brushcore import BrushParams, SolverOptions, simulate

CASES = [("regular", 256, 0.455, 128), ("regular", 64, 1e-3, 128), ("regular", 64, 1e-4, 256),
         ("regular", 16, float("inf"), 128), ("random", 30, 0.01, 96),
         ("random", 220, 1e-3, 256)]
# Some cases resolve the pillars coarsely (256 pillars on 128^2: radius 1.6 elements); they
# compare solver modes on one discretisation, which needs no converged physics.


@pytest.fixture(scope="module")
def reference():
    return {c: simulate(BrushParams(*c, seed=1, allow_coarse=True), SolverOptions.exact())
            for c in CASES}


@pytest.mark.parametrize("case", CASES, ids=[f"{c[0]}-{c[1]}-{c[2]}" for c in CASES])
def test_default_tolerance_is_harmless(reference, case):
    """Defaults (CG to 1e-4, local cascades) against the exact settings: 0.2 % allowed."""
    ref = reference[case]
    ds = simulate(BrushParams(*case, seed=1, allow_coarse=True))
    for name in ("adhesive_force", "work_of_separation"):
        assert float(ds[name]) == pytest.approx(float(ref[name]), rel=2e-3), name
    assert ds.attrs["operator_applications"] < ref.attrs["operator_applications"]


@pytest.mark.parametrize("case", CASES, ids=[f"{c[0]}-{c[1]}-{c[2]}" for c in CASES])
def test_local_cascade_agrees_with_global(reference, case):
    """Certified local cascades reach the global cascade's contact sets."""
    ref = reference[case]
    fast = simulate(BrushParams(*case, seed=1, allow_coarse=True),
                    SolverOptions(rtol=1e-8, cascade="local", early_decisions=False))
    df = float(fast.adhesive_force) / float(ref.adhesive_force) - 1
    dw = float(fast.work_of_separation) / float(ref.work_of_separation) - 1
    # Measured (grids 96-512): both within 2e-4.
    assert abs(df) < 1e-3 and abs(dw) < 1e-3, f"dF = {df:.2e}, dW = {dw:.2e}"
    assert fast.attrs["operator_applications"] <= ref.attrs["operator_applications"]


@pytest.mark.parametrize("option", [dict(lookahead=1e-3), dict(lookahead=1e-2)])
def test_lookahead_changes_little(reference, option):
    """Detaching within a window of the next event: its effect on F_ad and W is bounded."""
    case = CASES[0]
    ref = reference[case]
    ds = simulate(BrushParams(*case[:4], allow_coarse=True), SolverOptions(**option))
    for name in ("adhesive_force", "work_of_separation"):
        assert float(ds[name]) == pytest.approx(float(ref[name]), rel=2e-3), (option, name)
