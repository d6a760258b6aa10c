"""The benchmark scripts run (they print figures and assert nothing, so
nothing else would notice one breaking): each one's --help, and the
smallest runs of the two that time curves, at sizes of a few seconds."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _run(*args: str, tmp_path: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "BRUSHCORE_WISDOM_DIR": str(tmp_path / "wisdom"),
           "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, env=env,
                          timeout=300)


@pytest.mark.parametrize("script", sorted(p.name for p in BENCHMARKS.glob("*.py")))
def test_every_benchmark_script_starts(script: str, tmp_path: Path) -> None:
    proc = _run(str(BENCHMARKS / script), "--help", tmp_path=tmp_path)
    assert proc.returncode == 0 and proc.stdout.startswith("usage:"), proc.stderr


def test_fine_times_a_curve_after_its_planning_and_fails_loudly(tmp_path: Path) -> None:
    """`bench_speed.py fine`: a row with its planning apart (a fresh wisdom
    folder plans here), the F_ad of the run; a refused case exits 1."""
    proc = _run(str(BENCHMARKS / "bench_speed.py"), "fine", "--grid", "96",
                "regular:4:0.455", tmp_path=tmp_path)
    assert proc.returncode == 0, proc.stderr
    row = proc.stdout.strip().splitlines()[-1].split()
    assert row[0] == "regular:4:0.455" and float(row[4]) >= 0.0  # plan s
    from brushcore import BrushParams, simulate

    expected = float(simulate(BrushParams("regular", 4, 0.455, 96)).adhesive_force_normalized)
    assert float(row[6]) == pytest.approx(expected, abs=1e-5)  # printed to 5 decimals
    proc = _run(str(BENCHMARKS / "bench_speed.py"), "fine", "--grid", "96", "random:4",
                tmp_path=tmp_path)
    assert proc.returncode == 1 and "random:4 failed" in proc.stdout, proc.stdout
