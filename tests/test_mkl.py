"""The whole-grid transforms on Intel MKL (`brushcore.numerics.platform.mkl`) against
Boussinesq sums and against FFTW, and the choice between them."""

from __future__ import annotations

import numpy as np
import pytest

from brushcore import BrushParams, SolverOptions, simulate
from brushcore.numerics.platform import mkl
from brushcore.numerics.halfspace.convolution import Convolver
from brushcore.numerics.halfspace.kernel import dense_influence_matrix, love_coefficient
from brushcore.numerics.linear.precondition import BlockInverse
from brushcore.validation import ParameterError

needs_mkl = pytest.mark.skipif(not mkl.available(),
                               reason="mkl_fft not installed (pip install 'brushcore[mkl]')")


@needs_mkl
@pytest.mark.parametrize("n", [3, 7, 12])
@pytest.mark.parametrize("single", [False, True])
def test_mkl_convolution_equals_dense_boussinesq(n, single):
    """Small grids against the dense influence matrix: round-off of double
    (< 1e-12) or of float32 transforms (< 1e-6)."""
    rng = np.random.default_rng(n)
    stress = rng.standard_normal((n, n))
    ref = (dense_influence_matrix(n, 0.7, 2.0) @ stress.ravel()).reshape(n, n)
    conv = Convolver(n, 0.7, 2.0, single=single, library="mkl")
    assert conv.backend == "mkl" and conv.real_dtype == ("float32" if single else "float64")
    for _ in range(2):  # buffers are reused: the second call must agree too
        err = np.abs(conv(stress) - ref).max() / np.abs(ref).max()
        assert err < (1e-6 if single else 1e-12), f"relative error {err:.2e}"


@needs_mkl
@pytest.mark.parametrize("single", [False, True])
def test_mkl_convolution_at_256_equals_boussinesq_sums(single):
    """At n = 256 (the passes' shapes of the sweep's grids) the field agrees
    with Boussinesq sums over all n^2 sources at sampled elements, to the
    round-off of the sum of |terms| (the bounds of the FFTW test)."""
    n, h, e_star = 256, 0.7, 2.0
    rng = np.random.default_rng(12)
    stress = rng.standard_normal((n, n))
    u = Convolver(n, h, e_star, single=single, library="mkl")(stress)
    iy, ix = np.divmod(np.arange(n * n), n)
    for t in rng.choice(n * n, size=12, replace=False):
        terms = love_coefficient((iy[t] - iy) * h, (ix[t] - ix) * h, h, e_star) * stress.ravel()
        err = abs(u.ravel()[t] - terms.sum()) / np.abs(terms).sum()
        assert err < (1e-7 if single else 1e-13), f"element {t}: error {err:.2e} of the sum's scale"


@needs_mkl
@pytest.mark.parametrize("n", [5, 12, 64, 101])
@pytest.mark.parametrize("single", [False, True])
def test_mkl_threads_give_the_same_bits(n, single):
    """Cut into slabs of rows and columns, each transformed by its own
    thread, the pair gives the one-thread numbers to the bit, for uneven
    slabs too (n + 1 columns over 2 or 3 threads)."""
    stress = np.random.default_rng(n).standard_normal((n, n))
    one = Convolver(n, 0.7, 2.0, threads=1, single=single, library="mkl")(stress)
    for count in (2, 3):
        conv = Convolver(n, 0.7, 2.0, threads=count, single=single, library="mkl")
        for _ in range(2):
            assert np.array_equal(conv(stress), one), count


@needs_mkl
@pytest.mark.parametrize("tiles", [False, True])
def test_mkl_curve_is_the_same_on_one_and_two_threads(monkeypatch, tiles):
    """A random brush's curve on two threads is the one-thread curve to the
    bit, on the dense blocks and on the tile path (MKL's slabs and the
    stacked inverses' slabs; FFTW's threaded plans round differently)."""
    if tiles:
        monkeypatch.setattr(BlockInverse, "fits", classmethod(lambda cls, *a, **k: False))
    params = BrushParams(layout="random", n_pillars=16, kbar=1e-3, grid=128, seed=1)
    curves = {}
    for threads in ("1", "2"):
        monkeypatch.setenv("BRUSHCORE_THREADS", threads)
        curves[threads] = simulate(params, SolverOptions(fft_library="mkl"))
        assert curves[threads].attrs["fft_library_used"] == "mkl"
    for name in ("force", "displacement", "work_of_separation", "adhesive_force"):
        assert np.array_equal(curves["1"][name].values, curves["2"][name].values), name


@needs_mkl
def test_mkl_and_fftw_curves_agree_to_round_off():
    """A random brush (float32 transforms) and a regular one on the whole
    grid (double) on both libraries: the same F_ad and W to 1e-5, and each
    file says which library ran.  The two round differently, and FFTW's
    plans (timed afresh on each machine) with them: the random brush's F_ad
    differed by 1.07e-6 on one CI run and less on others, a tenth of CG's
    tolerance (1e-4), as over the default sweep (F_ad within 3.8e-6)."""
    cases = [(BrushParams(layout="random", n_pillars=16, kbar=1e-3, grid=128, seed=1), True),
             (BrushParams(layout="regular", n_pillars=16, kbar=0.1, grid=96), False)]
    for params, symmetry in cases:
        got = {lib: simulate(params, SolverOptions(fft_library=lib, symmetry=symmetry))
               for lib in ("mkl", "fftw")}
        assert [got[lib].attrs["fft_library_used"] for lib in ("mkl", "fftw")] == ["mkl", "fftw"]
        for name in ("adhesive_force_normalized", "work_of_separation_normalized"):
            a, b = (float(got[lib][name]) for lib in ("mkl", "fftw"))
            assert a == pytest.approx(b, rel=1e-5), (params.layout, name)


def test_fft_library_is_checked_and_resolved(monkeypatch):
    """Unknown names and "mkl" without mkl_fft fail at the options, naming the
    parameter; "auto" takes MKL where it is installed."""
    with pytest.raises(ParameterError, match="fft_library.*'auto', 'fftw' or 'mkl'"):
        SolverOptions(fft_library="cufft")
    assert SolverOptions(fft_library="fftw").host_fft_library() == "fftw"
    monkeypatch.setattr(mkl, "available", lambda: True)
    assert SolverOptions().host_fft_library() == "mkl"
    monkeypatch.setattr(mkl, "available", lambda: False)
    assert SolverOptions().host_fft_library() == "fftw"
    with pytest.raises(ParameterError, match="fft_library.*needs mkl_fft"):
        SolverOptions(fft_library="mkl")
