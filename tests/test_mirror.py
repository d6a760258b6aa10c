"""Mirror symmetry: the quadrant problem against the full grid."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from brushcore import BrushParams, SolverOptions, simulate
from brushcore.model.layout import build_labels
from brushcore.numerics.halfspace.convolution import Convolver
from brushcore.numerics.halfspace.kernel import dense_influence_matrix
from brushcore.numerics.halfspace.mirror import MirrorConvolver, mirror_quadrant
from brushcore.numerics.linear.operator import BrushOperator
from brushcore.validation import ParameterError


def _symmetric(quadrant: np.ndarray) -> np.ndarray:
    top = np.concatenate([quadrant[::-1, ::-1], quadrant[::-1]], axis=1)
    return np.concatenate([top, np.concatenate([quadrant[:, ::-1], quadrant], axis=1)])


@pytest.mark.parametrize("n", [4, 10, 16])
@pytest.mark.parametrize("use_pyfftw", [True, False])
def test_mirror_convolution_equals_full_convolution(n, use_pyfftw):
    """DCT-II/III on the quadrant = the DC-FFT on the whole grid, to round-off."""
    rng = np.random.default_rng(n)
    quadrant = rng.standard_normal((n // 2, n // 2))
    full = Convolver(n, 0.7, 2.0, use_pyfftw=use_pyfftw)(_symmetric(quadrant))
    mirror = MirrorConvolver(n, 0.7, 2.0, use_pyfftw=use_pyfftw)
    for _ in range(2):  # plans are reused
        u = mirror(quadrant)
        err = np.abs(u - full[n // 2:, n // 2:]).max() / np.abs(full).max()
        assert err < 1e-13, f"{mirror.backend}: relative error {err:.2e}"


def test_regular_brush_folds_to_its_quadrant():
    params = BrushParams("regular", 64, 1.0, 128)
    labels = build_labels(params)
    quad = mirror_quadrant(labels, np.ones(64))
    assert quad is not None and quad.images.shape == (16, 4)
    # the quadrant's pillars and their images cover every pillar once
    assert np.array_equal(np.sort(quad.images.ravel()), np.arange(64))
    # unfolding the quadrant's map, renamed to full labels, gives the label map back
    back = quad.unfold_field(quad.labels)
    images = np.full(back.shape, -1)
    m = 64
    for k, (rows, cols) in enumerate([(slice(m, None), slice(m, None)),
                                      (slice(None, m), slice(m, None)),
                                      (slice(m, None), slice(None, m)),
                                      (slice(None, m), slice(None, m))]):
        part = back[rows, cols]
        images[rows, cols] = np.where(part >= 0, quad.images[np.maximum(part, 0), k], -1)
    assert np.array_equal(images, labels)


@pytest.mark.parametrize("why, labels_of, compliance", [
    ("random layout", lambda: build_labels(BrushParams("random", 16, 1.0, 64, seed=3)), 16),
    ("odd lattice: the middle pillars cross the mid-lines",
     lambda: build_labels(BrushParams("regular", 9, 1.0, 96)), 9),
    ("odd grid", lambda: build_labels(BrushParams("regular", 16, 1.0, 65)), 16),
])
def test_asymmetric_brushes_are_not_folded(why, labels_of, compliance):
    assert mirror_quadrant(labels_of(), np.ones(compliance)) is None, why


def test_unequal_springs_are_not_folded():
    labels = build_labels(BrushParams("regular", 16, 1.0, 64))
    compliance = np.ones(16)
    assert mirror_quadrant(labels, compliance) is not None
    compliance[0] = 2.0
    assert mirror_quadrant(labels, compliance) is None


def test_folded_operator_and_its_block_inverse_are_exact():
    """A on the quadrant = E^T A_full E / 4 for symmetric vectors (E: unfold), and
    the preconditioner inverts each pillar's folded block exactly."""
    n, m = 24, 12
    labels = build_labels(BrushParams("regular", 16, 0.1, n, allow_coarse=True))
    compliance = np.full(16, 3.0)
    quad = mirror_quadrant(labels, compliance)
    op = BrushOperator(MirrorConvolver(n), quad.labels, compliance[:4], 1.0, 1.0, coarse=False)
    rng = np.random.default_rng(0)
    drop = rng.random(op.size) < 0.3
    drop[0] = False
    op.detach(drop)
    x = rng.standard_normal(op.size)
    q = np.zeros(m * m)
    q[op.elements[op.attached]] = x
    full = _symmetric(q.reshape(m, m)).ravel()
    flat = labels.ravel()
    u = dense_influence_matrix(n, 1.0, 1.0) @ full
    sums = np.bincount(flat[flat >= 0], weights=full[flat >= 0], minlength=16)
    u[flat >= 0] += (compliance * sums)[flat[flat >= 0]]
    expected = u.reshape(n, n)[m:, m:].ravel()[op.elements[op.attached]]
    assert np.allclose(op.apply(x), expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    # the pillar's own block of the folded operator, columns by applying A to unit vectors
    dense = np.column_stack([op.apply(e) for e in np.eye(op.size)])
    same = op.pl[:, None] == op.pl[None, :]
    r = rng.standard_normal(op.size)
    assert np.allclose(op.precondition(r), np.linalg.solve(np.where(same, dense, 0.0), r),
                       rtol=1e-9, atol=1e-9 * np.abs(r).max())


CASES = [(64, 0.455, 128), (256, 1e-4, 128), (64, float("inf"), 168), (16, 1e-2, 96)]


@pytest.mark.parametrize("case", CASES, ids=[f"N{c[0]}-k{c[1]}-n{c[2]}" for c in CASES])
def test_quadrant_pull_off_equals_full_grid(case):
    """Exact settings: the same detachment sequence, F_ad and W to 1e-8, and the
    quadrant needs about a quarter of the unknowns (fewer or equal applications)."""
    params = BrushParams("regular", *case, allow_coarse=True)
    full = simulate(params, replace(SolverOptions.exact(), symmetry=False))
    quad = simulate(params, SolverOptions.exact())
    assert quad.attrs["symmetry_fold"] == 4 and full.attrs["symmetry_fold"] == 1
    for name in ("adhesive_force", "work_of_separation"):
        assert float(quad[name]) == pytest.approx(float(full[name]), rel=1e-8), name
    assert np.array_equal(quad.detachment_step, full.detachment_step)
    assert np.allclose(quad.force, full.force, rtol=1e-7, atol=1e-9 * float(full.force.max()))
    assert np.array_equal(quad.attached_pillars, full.attached_pillars)
    assert quad.attrs["operator_applications"] <= full.attrs["operator_applications"]


def test_symmetry_option_is_validated():
    with pytest.raises(ParameterError, match="symmetry"):
        SolverOptions(symmetry="yes")


def test_cli_solves_the_quadrant_unless_told_not_to(tmp_path):
    from brushcore.cli import main
    from brushcore.data.io import read_curve

    common = ["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "0.01",
              "--grid", "48", "--quiet", "--rtol", "1e-8", "--cascade", "global"]
    assert main([*common, "--out", str(tmp_path / "q.nc")]) == 0
    assert main([*common, "--no-symmetry", "--out", str(tmp_path / "w.nc")]) == 0
    quad, whole = read_curve(tmp_path / "q.nc"), read_curve(tmp_path / "w.nc")
    assert (quad.attrs["symmetry_fold"], quad.attrs["symmetry"]) == (4, 1)
    assert (whole.attrs["symmetry_fold"], whole.attrs["symmetry"]) == (1, 0)
    assert float(quad.adhesive_force) == pytest.approx(float(whole.adhesive_force), rel=1e-8)
