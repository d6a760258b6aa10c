"""The pillars' collective mode over the tile preconditioner (`brushcore.numerics.collective`)."""

from __future__ import annotations

import numpy as np
import pytest

from brushcore import BrushParams, SolverOptions, simulate
from brushcore.model.curve import spring_compliance
from brushcore.model.layout import build_labels
from brushcore.numerics.cg import pcg
from brushcore.numerics.collective import CollectiveMode, centroid_influence
from brushcore.numerics.convolution import Convolver
from brushcore.numerics.kernel import folded_coefficient, love_coefficient
from brushcore.numerics.operator import BrushOperator
from brushcore.numerics.precondition import BlockInverse


@pytest.fixture
def tiles_only(monkeypatch):
    """Pillars take the tiles, as when dense blocks exceed the memory budget."""
    monkeypatch.setattr(BlockInverse, "fits", classmethod(lambda cls, *a, **k: False))


def _operator(layout: str, n_pillars: int, kbar: float, grid: int) -> BrushOperator:
    params = BrushParams(layout=layout, n_pillars=n_pillars, kbar=kbar, grid=grid)
    return BrushOperator(Convolver(grid), build_labels(params),
                         spring_compliance(params, n_pillars), 1.0, 1.0)


def _dense(op: BrushOperator) -> np.ndarray:
    return np.column_stack([op.precondition(e) for e in np.eye(op.size)])


def test_centroid_influence_is_the_monopole_kernel_with_images_on_a_quadrant():
    """R between centroids from Love's coefficient; on a quadrant the three
    images add in, a pillar's own images on the diagonal."""
    n, h, e_star = 8, 0.5, 2.0
    labels = -np.ones((n, n), dtype=int)
    labels[0:2, 0:2] = 0  # centroid (0.25, 0.25)
    labels[5:7, 4:6] = 1  # centroid (2.75, 2.25)
    flat = labels.ravel()
    elements = np.flatnonzero(flat >= 0)
    plain = centroid_influence(elements, flat[elements], n, h, e_star, False)
    assert plain[0, 0] == plain[1, 1] == 0.0
    assert plain[0, 1] == plain[1, 0] == pytest.approx(love_coefficient(2.5, 2.0, h, e_star))
    folded = centroid_influence(elements, flat[elements], n, h, e_star, True)
    assert folded[0, 1] == pytest.approx(
        folded_coefficient(0.25, 0.25, 2.75, 2.25, h, e_star), rel=1e-12)
    assert folded[0, 0] == pytest.approx(folded_coefficient(0.25, 0.25, 0.25, 0.25, h, e_star)
                                         - love_coefficient(0.0, 0.0, h, e_star), rel=1e-12)


def test_preconditioner_stays_spd_with_a_stale_factor(tiles_only):
    """P = Z E^-1 Z^T + Q^T M^-1 Q is symmetric positive definite, also after
    detachments that leave E as it was (c moved less than DRIFT) and after
    ones that refactorise it."""
    op = _operator("random", 16, np.inf, 64)
    mode = op.collective
    assert mode is not None and mode.valid and mode.factorisations == 1
    rng = np.random.default_rng(5)
    for fraction, factorisations in ((0.02, 1), (0.6, 2)):
        m = _dense(op)
        assert np.allclose(m, m.T, rtol=0, atol=1e-12 * np.abs(m).max())
        assert np.linalg.eigvalsh(m).min() > 0.0
        op.detach(rng.random(op.size) < fraction)
        assert mode.factorisations == factorisations
    m = _dense(op)
    assert np.allclose(m, m.T, rtol=0, atol=1e-12 * np.abs(m).max())
    assert np.linalg.eigvalsh(m).min() > 0.0


def test_coarse_vectors_follow_the_attached_set(tiles_only):
    """z_p = M_p^-1 1 over each pillar's attached elements, zero at detached ones."""
    op = _operator("random", 16, 1.0, 64)
    op.detach(np.random.default_rng(2).random(op.size) < 0.3)
    mode = op.collective
    assert not mode.z[~op.attached].any()
    for p in range(op.n_pillars):
        members = op.tiles.members[p]
        rest = members[op.attached[members]]
        expected = op.tiles.apply_pillar(p, np.ones(rest.size), rest, op.diag)
        np.testing.assert_allclose(mode.z[rest], expected, rtol=1e-12)


@pytest.mark.parametrize("kbar", [np.inf, 1.0])
def test_collective_mode_cuts_iterations(tiles_only, monkeypatch, kbar):
    """First solve (from zero to 1e-6) of random 64 at 256^2 on the tiles: 13
    iterations without the mode, 11 with it (measured, rigid and kbar 1)."""
    its = {}
    for on in (False, True):
        monkeypatch.setattr(BrushOperator, "COLLECTIVE", on)
        op = _operator("random", 64, kbar, 256)
        assert (op.collective is not None) == on
        its[on] = pcg(op.apply, op.precondition, np.ones(op.size), np.zeros(op.size),
                      1e-6, 5000)[1]
    assert its[True] < its[False]


def test_weakly_coupled_soft_pillars_go_without_it(tiles_only):
    """Soft springs decouple the pillars: below the dense blocks' coupling
    threshold (COUPLING_PER_PILLAR x N) the mode costs more than it saves."""
    assert _operator("random", 64, 1e-3, 256).collective is None


def test_pull_off_with_the_mode_matches_exact(tiles_only, monkeypatch):
    """Random 16 rigid at 128^2 on the tiles with the mode: F_ad and W within
    2e-4 of the exact settings."""
    params = BrushParams(layout="random", n_pillars=16, kbar=np.inf, grid=128)
    applied = []
    apply = CollectiveMode.apply
    monkeypatch.setattr(CollectiveMode, "apply",
                        lambda self, *a: applied.append(1) or apply(self, *a))
    tiled = simulate(params)
    assert applied, "the mode should precondition this brush"
    exact = simulate(params, SolverOptions.exact())
    for name in ("adhesive_force_normalized", "work_of_separation_normalized"):
        assert float(tiled[name]) == pytest.approx(float(exact[name]), rel=2e-4), name


def test_mode_without_a_positive_definite_factor_is_left_out():
    """Monopoles too strong for their self terms (E indefinite): not valid,
    so the operator applies the tiles alone."""
    r = np.array([[0.0, 10.0], [10.0, 0.0]])
    mode = CollectiveMode(r, np.ones(4), np.array([0, 0, 1, 1]))
    mode.refactorise()
    assert not mode.valid
