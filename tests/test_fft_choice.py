"""``fft_library: auto``: the faster library for a case, timed once per machine
and remembered (`brushcore.numerics.halfspace.fft_choice`)."""

from __future__ import annotations

import json

import pytest

from brushcore import BrushParams, SolverOptions, simulate
from brushcore.numerics.halfspace import fft_choice
from brushcore.numerics.platform import mkl
from brushcore.numerics.platform.threads import fft_threads

needs_mkl = pytest.mark.skipif(not mkl.available(),
                               reason="mkl_fft not installed (pip install 'brushcore[mkl]')")


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A fresh machine cache, and no answer remembered in this process."""
    monkeypatch.setenv("BRUSHCORE_WISDOM_DIR", str(tmp_path))
    fft_choice.faster_library.cache_clear()
    yield tmp_path / "fft-library.json"
    fft_choice.faster_library.cache_clear()


def test_the_faster_library_is_timed_once_and_remembered(cache, monkeypatch):
    """The first call times both and picks the faster; later calls (another
    process: the in-process answer cleared) read the file and time nothing;
    each case has its own answer, and so has each pair of library versions;
    an unreadable file is timed again."""
    timed = []

    def fake(n, h, e_star, threads, single):
        timed.append((n, threads, single))
        return {"fftw": 2.0, "mkl": 1.5} if threads == 1 else {"fftw": 1.0, "mkl": 1.5}

    monkeypatch.setattr(fft_choice, "time_pairs", fake)
    assert fft_choice.faster_library(64, 1.0, 1.0, 1, True) == "mkl"
    assert fft_choice.faster_library(64, 1.0, 1.0, 2, True) == "fftw"
    entries = json.loads(cache.read_text())
    assert entries[fft_choice._key(64, 1, True)] == {"library": "mkl", "fftw_ms": 2.0,
                                                     "mkl_ms": 1.5}
    assert fft_choice.processor() in fft_choice._key(64, 1, True)
    assert fft_choice.versions() in fft_choice._key(64, 1, True)
    assert timed == [(64, 1, True), (64, 2, True)]

    fft_choice.faster_library.cache_clear()
    monkeypatch.setattr(fft_choice, "time_pairs", lambda *a: pytest.fail("timed again"))
    assert fft_choice.faster_library(64, 1.0, 1.0, 1, True) == "mkl"
    assert fft_choice.faster_library(64, 1.0, 1.0, 2, True) == "fftw"

    # An upgrade of either library is a new case (its answer may turn).
    fft_choice.faster_library.cache_clear()
    monkeypatch.setattr(fft_choice, "versions", lambda: "pyfftw 9.9, mkl_fft 9.9")
    monkeypatch.setattr(fft_choice, "time_pairs", fake)
    assert fft_choice.faster_library(64, 1.0, 1.0, 1, True) == "mkl"
    assert timed[-1] == (64, 1, True) and len(json.loads(cache.read_text())) == 3

    fft_choice.faster_library.cache_clear()
    cache.write_text("{ half a file")
    monkeypatch.setattr(fft_choice, "time_pairs", fake)
    assert fft_choice.faster_library(64, 1.0, 1.0, 2, True) == "fftw"
    assert timed[-1] == (64, 2, True)


@needs_mkl
def test_timing_both_libraries_gives_positive_times(cache):
    """The real timing on a small grid: both pairs measured, the faster kept."""
    ms = fft_choice.time_pairs(24, 0.5, 2.0, 1, True)
    assert set(ms) == {"fftw", "mkl"} and min(ms.values()) > 0.0
    library = fft_choice.faster_library(24, 0.5, 2.0, 1, False)
    entry = json.loads(cache.read_text())[fft_choice._key(24, 1, False)]
    assert library == entry["library"] == min(("fftw", "mkl"), key=lambda k: entry[f"{k}_ms"])


@needs_mkl
@pytest.mark.parametrize("remembered", ["fftw", "mkl"])
def test_a_curve_runs_on_the_remembered_library(cache, remembered):
    """`simulate` under "auto" runs a random brush (whole grid, float32) on
    the library remembered for its case, and its file says so; an explicit
    choice overrides it."""
    params = BrushParams(layout="random", n_pillars=16, kbar=1e-3, grid=64, seed=1)
    key = fft_choice._key(64, fft_threads(), single=True)
    cache.write_text(json.dumps({key: {"library": remembered}}))
    ds = simulate(params, SolverOptions())
    assert ds.attrs["fft_library_used"] == remembered
    other = {"fftw": "mkl", "mkl": "fftw"}[remembered]
    assert simulate(params, SolverOptions(fft_library=other)).attrs["fft_library_used"] == other
