"""The command line: a curve file for good input, a clear error and no file for bad."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from brushcore.cli import main
from brushcore.io import CurveFileError, read_curve, write_curve


def test_simulate_writes_a_complete_curve(tmp_path, capsys):
    out = tmp_path / "c.nc"
    rc = main(["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "0.01",
               "--grid", "48", "--out", str(out), "--quiet"])
    assert rc == 0
    assert "F_ad/F_K" in capsys.readouterr().out
    ds = read_curve(out)
    assert ds.attrs["n_pillars"] == 4 and ds.attrs["kbar"] == 0.01
    assert ds.attrs["Conventions"] == "CF-1.10" and ds.attrs["git_commit"]
    for name in ("displacement", "force", "contact_area", "attached_pillars"):
        assert ds[name].dims == ("step",) and "units" in ds[name].attrs
    assert [p.name for p in tmp_path.iterdir()] == ["c.nc"]  # no temporary left behind


def test_rigid_kbar_inf(tmp_path):
    out = tmp_path / "rigid.nc"
    assert main(["simulate", "--layout", "random", "--pillars", "5", "--kbar", "inf",
                 "--grid", "48", "--seed", "2", "--out", str(out), "--quiet"]) == 0
    assert np.isinf(read_curve(out).attrs["kbar"])


BAD = [
    (["--kbar", "-1"], "kbar=-1.0"),
    (["--kbar", "nan"], "kbar=nan"),
    (["--kbar", "abc"], "kbar='abc'"),
    (["--kbar", "0"], "kbar=0.0"),
    (["--pillars", "3"], "n_pillars=3 .*perfect square"),
    (["--pillars", "0"], "n_pillars=0 .*N >= 1"),
    (["--phi", "0.6"], r"phi=0.6 .*\(0, 0.5\]"),
    (["--phi", "0"], r"phi=0.0 .*\(0, 0.5\]"),
    (["--grid", "8", "--pillars", "64"], "grid=8 .*pillar"),
    (["--layout", "hex"], "invalid choice: 'hex'"),
    (["--layout", "random", "--pillars", "60", "--phi", "0.5"], "n_pillars=60 .*fewer"),
]


@pytest.mark.parametrize("extra,message", BAD, ids=[b[1][:20] for b in BAD])
def test_bad_input_is_rejected_before_computing(tmp_path, extra, message):
    out = tmp_path / "never.nc"
    args = {"--layout": "regular", "--pillars": "16", "--kbar": "0.1", "--grid": "64"}
    for key, value in zip(extra[::2], extra[1::2]):
        args[key] = value
    cmd = [sys.executable, "-m", "brushcore.cli", "simulate", "--out", str(out)]
    for key, value in args.items():
        cmd += [key, value]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert res.returncode == 2, res.stderr
    import re

    assert re.search(message, res.stderr), res.stderr
    assert not out.exists() and not list(tmp_path.iterdir())


def test_truncated_or_foreign_file_is_refused_by_name(tmp_path):
    good = tmp_path / "good.nc"
    assert main(["simulate", "--layout", "regular", "--pillars", "1", "--kbar", "1",
                 "--grid", "16", "--out", str(good), "--quiet"]) == 0
    bad = tmp_path / "bad.nc"
    bad.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(CurveFileError, match="bad.nc"):
        read_curve(bad)
    foreign = tmp_path / "foreign.nc"
    ds = read_curve(good).drop_vars("force")
    write_curve(ds, foreign)
    with pytest.raises(CurveFileError, match="foreign.nc.*force"):
        read_curve(foreign)
