"""The command line: a curve file for good input, a clear error and no file for bad."""

from __future__ import annotations

import errno
import math
import os
import re
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from brushcore import BrushParams, SolverOptions
from brushcore.cli import main
from brushcore.model.labelmap import count_touching_pairs
from brushcore.model.layout import build_labels
from brushcore.data.io import CurveFileError, read_curve, write_curve


def test_simulate_writes_a_complete_curve(tmp_path, capsys):
    out = tmp_path / "c.nc"
    rc = main(["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "0.01",
               "--grid", "48", "--out", str(out), "--quiet"])
    assert rc == 0
    assert "F_ad/F_K" in capsys.readouterr().out
    ds = read_curve(out)
    assert ds.attrs["n_pillars"] == 4 and ds.attrs["kbar"] == 0.01
    assert ds.attrs["Conventions"] == "CF-1.10" and ds.attrs["git_commit"]
    assert re.match(r"python \S+, numpy \S+, scipy \S+, pyfftw ", ds.attrs["software_versions"])
    for name in ("displacement", "force", "contact_area", "attached_pillars"):
        assert ds[name].dims == ("step",) and "units" in ds[name].attrs
    assert [p.name for p in tmp_path.iterdir()] == ["c.nc"]  # no temporary left behind


def test_a_killed_runs_temporary_is_removed_by_the_next(tmp_path):
    """kill -9 while writing leaves a ``.c.nc.*.tmp``; the next run of the same
    --out removes it, but not one written after it started (another writer's)."""
    out = tmp_path / "c.nc"
    killed = tmp_path / ".c.nc.killed.tmp"
    killed.write_bytes(b"")
    os.utime(killed, (time.time() - 60, time.time() - 60))
    other = tmp_path / ".c.nc.other.tmp"
    other.write_bytes(b"")
    os.utime(other, (time.time() + 3600, time.time() + 3600))
    assert main(["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "0.01",
                 "--grid", "48", "--out", str(out), "--quiet"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [".c.nc.other.tmp", "c.nc"]


def test_rigid_kbar_inf(tmp_path):
    out = tmp_path / "rigid.nc"
    assert main(["simulate", "--layout", "random", "--pillars", "5", "--kbar", "inf",
                 "--grid", "48", "--seed", "2", "--out", str(out), "--quiet"]) == 0
    attrs = read_curve(out).attrs
    assert np.isinf(attrs["kbar"])
    assert attrs["random_gap"] == 48 / 512  # min_gap 1 of L / 512 (h = 1): the 512^2 brush
    assert attrs["touching_pillar_pairs"] == count_touching_pairs(
        build_labels(BrushParams("random", 5, np.inf, 48, seed=2)))


BAD = [
    (["--kbar", "-1"], r"--kbar -1.0 is invalid"),
    (["--kbar", "nan"], "--kbar nan is invalid"),
    (["--kbar", "abc"], "--kbar: 'abc' is not a number"),
    (["--kbar", "1e400"], "--kbar: '1e400' overflows a float"),  # ran silently as rigid
    (["--kbar", "0"], "--kbar 0.0 is invalid"),
    (["--pillars", "3"], "--pillars 3 .*perfect square"),
    (["--pillars", "0"], "--pillars 0 .*N >= 1"),
    (["--phi", "0.6"], r"--phi 0.6 .*\(0, 0.5\]"),
    (["--phi", "0"], r"--phi 0.0 .*\(0, 0.5\]"),
    (["--grid", "8", "--pillars", "64"], "--grid 8 .*pillar radius"),
    (["--grid", "0"], r"--grid 0 is invalid: allowed an integer in \[4, 8192\]"),  # not "41"
    (["--grid", "41", "--pillars", "256"], "--grid 41 .*--grid 164, the next .*--allow-coarse"),
    (["--grid", "128", "--pillars", "256"], "--grid 128 .*--grid 164, the next"),
    (["--layout", "hex"], "invalid choice: 'hex'"),
    (["--layout", "random", "--pillars", "60", "--phi", "0.5"], "--pillars 60 .*fewer"),
    (["--threads", "0"], r"--threads 0 .*\[1, 256\]"),
    (["--threads", "100000"], r"--threads 100000 .*\[1, 256\]"),  # crashed FFTW's planner
    (["--kbar", "1e-18"], r"--kbar 1e-18 is invalid: allowed a number in \[1e-09, inf\]"),
    (["--seed", str(2**64)], r"--seed 18446744073709551616 .*\[0, 2\*\*63 - 1\]"),
    (["--roughness", "1e30"], r"--roughness 1e\+30 .*\[0, 1000\]"),  # hung the approach
    (["--h", "1e-200"], r"--h 1e-200 .*\[1e-30, 1e\+30\]"),
    (["--n-pillars", "16"], "unknown argument --n-pillars .*did you mean --pillars"),
    (["--pillars", "abc"], r"argument --pillars: 'abc' is not an integer; allowed a whole "
                           r"number of pillars >= 1 \(see 'brushcore simulate --help'\)"),
    (["--grid", "64.5"], r"argument --grid: '64.5' is not an integer; allowed an integer in "
                         r"\[4, 8192\]"),
    (["--pil", "16"], r"unknown argument --pil \(did you mean --pillars\?\)"),  # not --phi
    (["--heights", "no-such-heights.txt"], r"--heights no-such-heights.txt is invalid "
                                           r"\(no such file\): allowed a readable"),
    # no grid draws them inside the square: "a finer grid" is not said
    (["--shape", "ellipse", "--aspect", "10", "--phi", "0.4", "--grid", "256"],
     r"reaches beyond the 256 x 256 square\): allowed a smaller phi, fewer pillars, a more "
     r"compact shape$"),
    (["--kbar", "-inf"], r"--kbar -inf is invalid"),  # a value, not an unknown flag
    (["--heights", ""], r"argument --heights: an empty path"),  # not the folder "."

    (["--k", "0.1"], "unknown argument --k "),
    (["--ou", "x.nc"], "unknown argument --ou "),
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
    assert re.search(message, res.stderr), res.stderr
    assert "Traceback" not in res.stderr and "n_pillars" not in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1, res.stderr  # no usage text around it
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


def _cli(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "brushcore.cli", *args], capture_output=True,
                          text=True, timeout=120, **kw)


SMALL = ["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "0.01", "--grid", "48"]


@pytest.mark.parametrize("out,reason", [
    ("a.nc/fig5a.nc", "a.nc is a file, not a folder"),
    (".", "it is a folder"),
    ("newdir/sub/", "it names a folder (ends with a separator)"),
    ("pipe", "it exists and is not a regular file"),  # the rename would replace it
    ("/proc/x.nc", "cannot create a file in /proc"),
])
def test_bad_output_path_is_refused_before_computing(tmp_path, out, reason):
    (tmp_path / "a.nc").write_text("not a folder")
    os.mkfifo(tmp_path / "pipe")
    big = ["simulate", "--layout", "regular", "--pillars", "256", "--kbar", "0.455", "--grid",
           "256"]  # long enough that a late refusal would show
    res = _cli(*big, "--out", out, cwd=tmp_path)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    assert res.stderr.startswith("brushcore: error: --out ") and reason in res.stderr, res.stderr
    # one line: the discretisation line, printed just before the pull-off, never came
    assert len(res.stderr.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.nc", "pipe"]  # nothing made
    assert not (tmp_path / "pipe").is_file()


def test_a_flag_given_twice_warns_that_the_last_counts(tmp_path):
    """argparse keeps a repeated flag's last value: said, since a typo may hide there."""
    res = _cli(*SMALL, "--kbar", "inf", "--quiet", "--out", str(tmp_path / "c.nc"))
    assert res.returncode == 0, res.stderr
    assert "brushcore: warning: --kbar is given 2 times: the last one counts" in res.stderr
    assert read_curve(tmp_path / "c.nc").attrs["kbar"] == math.inf


def test_files_respect_the_umask(tmp_path):
    out = tmp_path / "sub" / "c.nc"
    old = os.umask(0o022)
    try:
        assert main([*SMALL, "--out", str(out), "--quiet"]) == 0
    finally:
        os.umask(old)
    assert out.stat().st_mode & 0o777 == 0o644


def test_negative_numbers_in_any_notation_are_values(tmp_path):
    """argparse alone takes -5 and -0.5 as values but -1e1 as a flag."""
    out = tmp_path / "c.nc"
    assert main(["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "1", "--grid",
                 "32", "--shape", "square", "--orientation", "-1e1", "--allow-coarse",
                 "--out", str(out), "--quiet"]) == 0
    assert read_curve(out).attrs["orientation"] == -10.0


def test_version_and_defaults_in_help():
    res = _cli("--version")
    import brushcore
    from brushcore.model.provenance import code_digest, git_commit

    # the version, the commit, the code and the libraries, as a curve file records them
    assert res.returncode == 0 and re.fullmatch(
        rf"brushcore {re.escape(brushcore.__version__)} \(commit {re.escape(git_commit())}, "
        rf"code sha256 {code_digest()}\)\n"
        r"python \S+, numpy \S+, scipy \S+, pyfftw \S+.*xarray \S+, netCDF4 \S+\n",
        res.stdout), res
    package = subprocess.run([sys.executable, "-m", "brushcore", "--version"],
                             capture_output=True, text=True, timeout=120)
    assert package.returncode == 0 and package.stdout == res.stdout, package
    text = _cli("simulate", "--help").stdout
    assert "(default: 0.12)" in text and "(default: local)" in text
    # zero defaults are defaults too (0 == False once hid them) ...
    assert re.search(r"--seed SEED\s+seed of the random layout .*\(--kbar-spread\), in\s+"
                     r"\[0,\s+9223372036854775807\]\s+\(default: 0\)", text, flags=re.DOTALL), text
    assert re.search(r"--preload PRELOAD\s+[^-]*\(default: 0\.0\)", text), text
    # every numeric flag says its range, as the checks have it
    for flag, interval in (("--kbar KBAR", "[1e-09, inf]"), ("--grid GRID", "[4, 8192]"),
                           ("--roughness ROUGHNESS", "[0, 1000]"),
                           ("--threads THREADS", "[1, 256]"), ("--rtol RTOL", "[1e-12, 1e-3]")):
        entry = re.search(rf"^  {flag}\s+(.*?)(?=\n  -|\Z)", text,
                          flags=re.DOTALL | re.MULTILINE).group(1)
        assert interval in " ".join(entry.split()), (flag, entry)
    # ... while an on/off switch has no value to show
    assert "(default: True)" not in text and "(default: False)" not in text


def test_every_missing_flag_is_named_at_once(tmp_path, capsys):
    """The layout's flags and --kbar in one error: a second try should not
    meet the next missing flag."""
    out = tmp_path / "never.nc"
    assert main(["simulate", "--layout", "regular", "--out", str(out), "--quiet"]) == 2
    assert ("--pillars and --grid are required for --layout regular; --kbar is required "
            "(or --kbar-file, one kbar per pillar)") in capsys.readouterr().err
    assert main(["simulate", "--layout", "file", "--out", str(out), "--quiet"]) == 2
    assert ("--layout-file is required for --layout file; --kbar is required"
            in capsys.readouterr().err)
    assert not out.exists()


def test_an_unquoted_protocol_is_told_to_be_quoted(tmp_path, capsys):
    """The shell splits --protocol force:-1, separation after its comma; the
    stray word was "unrecognized" with the top-level help, naming neither the
    flag nor the fix."""
    out = tmp_path / "never.nc"
    with pytest.raises(SystemExit, match="2"):
        main(["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "1", "--grid",
              "32", "--protocol", "force:-1,", "separation", "--out", str(out)])
    assert ("unrecognized arguments: separation; after --protocol force:-1,: quote a value "
            "with spaces, --protocol 'force:-1, separation' (see 'brushcore simulate --help')"
            in capsys.readouterr().err)
    with pytest.raises(SystemExit, match="2"):
        main(["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "1", "--grid",
              "32", "stray", "--out", str(out)])
    assert ("unrecognized arguments: stray (see 'brushcore simulate --help')"
            in capsys.readouterr().err)
    # the --flag=value form; a switch before it is not the flag (review helper's finds)
    with pytest.raises(SystemExit, match="2"):
        main(["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "1", "--grid",
              "32", "--quiet", "--protocol=force:-1,", "separation", "--out", str(out)])
    assert "quote a value with spaces, --protocol 'force:-1, separation'" in \
        capsys.readouterr().err
    with pytest.raises(SystemExit, match="2"):
        main(["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "1", "--grid",
              "32", "--quiet", "separation", "--out", str(out)])
    assert "unrecognized arguments: separation (see" in capsys.readouterr().err
    assert not out.exists()


def test_lookahead_says_at_run_time_that_it_is_approximate(tmp_path):
    """--lookahead trades accuracy for solves: said when the run starts, not
    only in the help; the exact default says nothing."""
    res = _cli(*SMALL, "--lookahead", "0.02", "--quiet", "--out", str(tmp_path / "c.nc"))
    assert res.returncode == 0, res.stderr
    assert ("brushcore: warning: --lookahead 0.02 batches the events within 2 % of the next "
            "one: approximate") in res.stderr
    res = _cli(*SMALL, "--quiet", "--out", str(tmp_path / "d.nc"))
    assert "lookahead" not in res.stderr


def test_every_run_reports_its_discretisation(tmp_path):
    res = _cli(*SMALL, "--out", str(tmp_path / "c.nc"), "--quiet")
    assert res.returncode == 0, res.stderr
    assert re.search(r"pillar radius 4\.69 elements, phi realised 0\.1\d+ \(requested 0\.12\)",
                     res.stderr), res.stderr
    assert abs(read_curve(tmp_path / "c.nc").attrs["pillar_radius_elements"] - 4.69) < 0.01


def test_rough_run_says_how_many_pillars_it_pressed_on(tmp_path):
    """A rough brush without --preload is pulled off after first touch, one
    pillar in contact (DESIGN.md's convention): the run says so, and how to press on."""
    args = ["simulate", "--layout", "regular", "--pillars", "16", "--kbar", "0.01", "--grid",
            "64", "--roughness", "0.3", "--quiet"]
    alone = _cli(*args, "--out", str(tmp_path / "a.nc"))
    assert alone.returncode == 0, alone.stderr
    touching = int(read_curve(tmp_path / "a.nc").pillars_in_contact_at_preload)
    assert touching == 1
    assert ("1 of 16 pillars in contact at the first touch (--preload 0 stops the approach "
            "there; give --preload") in alone.stdout, alone.stdout
    assert "pillars in contact" not in alone.stderr  # said once, in the flag's words
    pressed = _cli(*args, "--preload", "1", "--out", str(tmp_path / "b.nc"))
    assert "16 of 16 pillars in contact at the preload\n" in pressed.stdout, pressed.stdout


def test_the_python_api_warns_where_preload_0_left_pillars_out():
    """simulate() says what the command prints: a rough brush at preload 0
    pulls off the one pillar that touched; pressed on, or flat, no warning."""
    from brushcore import BrushParams, FirstTouchWarning, simulate

    rough = BrushParams("regular", 16, 0.01, 64, roughness=0.3)
    with pytest.warns(FirstTouchWarning, match=r"^1 of 16 pillars in contact at the first "
                                                r"touch: preload 0 stops the approach there"):
        simulate(rough)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        simulate(BrushParams("regular", 16, 0.01, 64, roughness=0.3, preload=1.0))
        simulate(BrushParams("regular", 16, 0.01, 64))


def test_run_reports_random_discs_that_touch(tmp_path):
    """On grids coarser than 512 random discs may share an element edge (their
    gap is L / 512): the run says how many pairs, and the file records it."""
    args = ["simulate", "--layout", "random", "--pillars", "10", "--kbar", "1.0", "--grid",
            "48", "--seed", "1", "--quiet"]
    res = _cli(*args, "--out", str(tmp_path / "c.nc"))
    assert res.returncode == 0, res.stderr
    expected = count_touching_pairs(build_labels(BrushParams("random", 10, 1.0, 48, seed=1)))
    assert expected > 0
    told = "1 pillar pair shares" if expected == 1 else f"{expected} pillar pairs share"
    assert f"; {told} an element edge" in res.stderr, res.stderr
    assert read_curve(tmp_path / "c.nc").attrs["touching_pillar_pairs"] == expected
    quiet = _cli(*SMALL, "--out", str(tmp_path / "d.nc"), "--quiet")
    assert "share an element edge" not in quiet.stderr


def test_allow_coarse_runs_what_is_refused_by_default(tmp_path):
    args = ["simulate", "--layout", "regular", "--pillars", "256", "--kbar", "0.455",
            "--grid", "64", "--out", str(tmp_path / "c.nc"), "--quiet"]
    assert _cli(*args).returncode == 2
    res = _cli(*args, "--allow-coarse")
    assert res.returncode == 0, res.stderr
    assert "pillar radius 0.782 elements, phi realised 0.25" in res.stderr
    assert read_curve(tmp_path / "c.nc").attrs["allow_coarse"] == 1


def test_progress_in_a_log_has_no_carriage_returns(tmp_path):
    """stderr to a file (a batch log) gets whole lines, never a rewritten one."""
    from brushcore.cli.output import Progress

    log = open(tmp_path / "log", "w+")
    progress = Progress(log)
    progress.last -= 60  # as if the last line was a minute ago
    progress(3, 50, 100)
    progress.end_line()
    log.seek(0)
    text = log.read()
    assert "\r" not in text and re.fullmatch(r" +50\.0% of the pillar area in contact, 3 events, "
                                          r"+\S+ s\n", text)


def _default_sigint() -> None:
    """A child's default Ctrl-C, even where pytest runs as a background job
    of a shell, whose children inherit SIGINT ignored (Python then keeps it
    ignored and the job never sees the interrupt)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_sigterm_prints_one_line_and_exits_143(tmp_path):
    """kill, Slurm's scancel or its time limit: like Ctrl-C, one line and no file."""
    out = tmp_path / "c.nc"
    proc = subprocess.Popen([sys.executable, "-m", "brushcore.cli", "simulate", "--layout",
                             "random", "--pillars", "1620", "--kbar", "1e-5", "--grid", "512",
                             "--out", str(out)], stderr=subprocess.PIPE, text=True)
    first = proc.stderr.readline()
    assert first.startswith("grid 512: pillar radius"), first
    time.sleep(1.0)
    proc.terminate()
    rest = proc.stderr.read()
    assert proc.wait(timeout=60) == 143, rest
    assert rest.strip().splitlines()[-1] == "brushcore: error: terminated; nothing written"
    assert "Traceback" not in rest
    assert not list(tmp_path.iterdir())


def test_full_disk_is_said_in_words(tmp_path, monkeypatch):
    """netCDF reports a full disk as "HDF error": the writer says what it is,
    and leaves no temporary file."""
    import shutil
    from collections import namedtuple

    import xarray as xr

    from brushcore.data import io

    def full(*args, **kwargs):
        raise RuntimeError("NetCDF: HDF error")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", full)
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(10**9, 10**9 - 512, 512))
    ds = xr.Dataset({"x": ("n", np.zeros(1000))})
    with pytest.raises(OSError, match=r"512 bytes free on its disk") as err:
        io.write_dataset_atomic(ds, tmp_path / "a.nc", {})
    assert err.value.errno == errno.ENOSPC
    assert not list(tmp_path.iterdir())

    # Ctrl-C while writing stays Ctrl-C, even where the free space cannot be read
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    def gone(path):
        raise FileNotFoundError(path)

    monkeypatch.setattr(xr.Dataset, "to_netcdf", interrupted)
    monkeypatch.setattr(shutil, "disk_usage", gone)
    with pytest.raises(KeyboardInterrupt):
        io.write_dataset_atomic(ds, tmp_path / "a.nc", {})


def test_ctrl_c_prints_one_line_and_exits_130(tmp_path):
    out = tmp_path / "c.nc"
    # A curve of about a minute (random 1620 at kbar 1e-5 on 512^2, 60-80 s on
    # 2 cores): still running 1 s after its first line on any machine.
    proc = subprocess.Popen([sys.executable, "-m", "brushcore.cli", "simulate", "--layout",
                             "random", "--pillars", "1620", "--kbar", "1e-5", "--grid", "512",
                             "--out", str(out)], stderr=subprocess.PIPE, text=True,
                            preexec_fn=_default_sigint)
    first = proc.stderr.readline()  # printed after every check, before the pull-off
    assert first.startswith("grid 512: pillar radius"), first
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    rest = proc.stderr.read()
    assert proc.wait(timeout=60) == 130, rest
    assert rest.strip().splitlines()[-1] == "brushcore: error: interrupted; nothing written"
    assert "Traceback" not in rest
    assert not list(tmp_path.iterdir())


def test_converge_says_where_its_curves_differ_in_code_or_settings(tmp_path, capsys):
    """A study over curves run with other settings (or commits) is warned of
    on the terminal, as the workflow's aggregation warns: their difference
    joins the mesh's in the extrapolation."""
    from brushcore import BrushParams, SolverOptions, simulate, write_curve
    from brushcore.cli import main

    paths = []
    for grid, cascade in ((32, "global"), (48, "local"), (64, "local")):
        curve = simulate(BrushParams("regular", 4, 0.01, grid), SolverOptions(cascade=cascade))
        paths.append(str(tmp_path / f"c{grid}.nc"))
        write_curve(curve, paths[-1])
    with pytest.warns(UserWarning, match=r"the curves differ in cascade \(global; local\)"):
        assert main(["converge", *paths, "--out-dir", str(tmp_path / "study")]) == 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert main(["converge", *paths[1:], "--out-dir", str(tmp_path / "two")]) == 0


def test_a_coarse_grid_is_suggested_with_the_phi_it_realises(tmp_path, capsys):
    """Under --allow-coarse the filling factor is not checked, so the grid the
    hint names need not realise phi within 5 %: the hint and the run say
    what it comes out as (4 pillars of 4 elements on 8^2: 0.25, not 0.12)."""
    from brushcore.cli import main

    out = tmp_path / "coarse.nc"
    base = ["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "0.1",
            "--allow-coarse", "--quiet", "--out", str(out)]
    assert main([*base, "--grid", "4"]) == 2
    err = capsys.readouterr().err
    assert ("--grid 8, the next that resolves the pillars and realises phi as 0.25 "
            "(--allow-coarse: not checked; 0.12 asked for)") in err, err
    assert main([*base, "--grid", "8"]) == 0
    assert "phi realised 0.25 (requested 0.12, +108 %: --allow-coarse ran it)" in \
        capsys.readouterr().err


def test_converge_extrapolates_curves_run_by_hand_on_three_grids(tmp_path, capsys) -> None:
    """`brushcore converge` gathers simulate's curves into sweep.nc and the
    convergence study, whose extrapolated F_ad is Richardson's on the three
    values (checked with `extrapolate` on the curves' own numbers)."""
    import xarray as xr

    from brushcore.data.extrapolation import extrapolate

    paths, values = [], []
    for grid in (48, 64, 96):
        path = tmp_path / f"c{grid}.nc"
        assert main(["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "0.01",
                     "--grid", str(grid), "--quiet", "--out", str(path)]) == 0
        paths.append(str(path))
        values.append(float(read_curve(path).adhesive_force_normalized))
    out = tmp_path / "study"
    assert main(["converge", *paths, "--out-dir", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "3 curves on grids [48, 64, 96]" in printed and "| F_ad |" in printed
    assert "Results extrapolated" not in printed  # the legend stays in the file
    assert (out / "convergence.md").read_text().startswith("Results extrapolated")
    for name in ("sweep.nc", "convergence.nc", "convergence.csv", "convergence.md",
                 "convergence.png"):
        assert (out / name).is_file(), name
    with xr.open_dataset(out / "sweep.nc") as sweep:  # a study's sweep: scalars, no maps
        assert "contact_snapshot" not in sweep
    expected = extrapolate([1 / 48, 1 / 64, 1 / 96], values)
    assert math.isfinite(expected.value)
    with xr.open_dataset(out / "convergence.nc") as study:
        got = study.adhesive_force_normalized_extrapolated.squeeze()
        assert float(got) == pytest.approx(expected.value, rel=1e-12)
    # two grids: the sweep, and no study, said; one case twice, or a file as the folder: refused
    assert main(["converge", *paths[:2], "--out-dir", str(tmp_path / "two")]) == 0
    assert "no convergence study: it needs a case run on three" in capsys.readouterr().out
    assert not (tmp_path / "two" / "convergence.nc").exists()
    # ... in a folder that holds an earlier study: it goes, as it no longer fits sweep.nc
    assert main(["converge", *paths[:2], "--out-dir", str(out)]) == 0
    assert "(removed the earlier curves' convergence.nc, convergence.csv" in \
        capsys.readouterr().out
    assert not list(out.glob("convergence.*")) and (out / "sweep.nc").is_file()
    assert main(["converge", paths[0], paths[0], "--out-dir", str(tmp_path / "x")]) == 2
    assert "hold the same case (regular N=4 kbar=0.01 seed 0 on 48^2): a sweep takes one " \
        "file per case and grid" in capsys.readouterr().err
    assert main(["converge", *paths, "--out-dir", paths[0]]) == 2
    assert "is a file: allowed a folder" in capsys.readouterr().err
    # L held fixed through --h = L / n: one sweep holds one unit system, said
    other = tmp_path / "h.nc"
    assert main(["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "0.01",
                 "--grid", "128", "--h", "0.5", "--quiet", "--out", str(other)]) == 0
    assert main(["converge", *paths, str(other), "--out-dir", str(tmp_path / "h")]) == 2
    assert re.search(r"disagree on h: 1\.0 in .*, 0\.5 in .*run every grid with the same "
                     r"--e-star, --dgamma and --h", capsys.readouterr().err)
    # Ctrl-C while the study is written, over an earlier study: said what the
    # folder holds (it said "nothing written" beside the earlier curves' study)
    from brushcore.data import convergence_report

    assert main(["converge", *paths, "--out-dir", str(out)]) == 0
    capsys.readouterr()

    def cut_short(sweep, nc_path, *rest):
        Path(nc_path).write_bytes(b"")
        raise KeyboardInterrupt

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(convergence_report, "write_study", cut_short)
        assert main(["converge", *paths, "--out-dir", str(out)]) == 130
    assert ("interrupted; written: sweep.nc, convergence.nc (the earlier convergence.nc, "
            "convergence.csv, convergence.md, convergence.png removed): run brushcore "
            "converge again") in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["convergence.nc", "sweep.nc"]
    # an earlier study that cannot be removed is not called written nor removed
    assert main(["converge", *paths, "--out-dir", str(out)]) == 0
    capsys.readouterr()

    def refused(self, missing_ok=False):
        raise PermissionError(errno.EACCES, "Permission denied", str(self))

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(Path, "unlink", refused)
        assert main(["converge", *paths, "--out-dir", str(out)]) == 1
    err = capsys.readouterr().err
    assert "Permission denied; written: nothing (the earlier convergence.nc, convergence.csv, " \
        "convergence.md, convergence.png not removed" in err, err


def test_a_kbar_file_says_that_kbar_is_only_recorded(tmp_path) -> None:
    """--kbar beside --kbar-file is only recorded: said."""
    values = tmp_path / "k.txt"
    values.write_text("0.01\n0.02\n0.03\n0.04\n")
    with pytest.warns(UserWarning, match=r"--kbar-file gives every pillar's stiffness: "
                      r"--kbar 5 is recorded as the curve's kbar but no pillar runs it"):
        assert main(["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "5",
                     "--grid", "48", "--kbar-file", str(values), "--quiet",
                     "--out", str(tmp_path / "k.nc")]) == 0
    assert read_curve(tmp_path / "k.nc").pillar_kbar.values.tolist() == [0.01, 0.02, 0.03, 0.04]


def test_a_kbar_file_alone_records_its_mean(tmp_path, capsys) -> None:
    """Without --kbar, --kbar-file's mean is the curve's kbar (a lognormal
    draw's mean is its --kbar alike), with no warning; without either, the
    error names both flags before any work."""
    values = tmp_path / "k.txt"
    values.write_text("0.01\n0.02\n0.03\n0.04\n")
    argv = ["simulate", "--layout", "regular", "--pillars", "4", "--grid", "48", "--quiet"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert main([*argv, "--kbar-file", str(values), "--out", str(tmp_path / "k.nc")]) == 0
    curve = read_curve(tmp_path / "k.nc")
    assert curve.attrs["kbar"] == pytest.approx(0.025, rel=1e-15)
    assert curve.pillar_kbar.values.tolist() == [0.01, 0.02, 0.03, 0.04]
    capsys.readouterr()
    assert main([*argv, "--out", str(tmp_path / "none.nc")]) == 2
    assert "--kbar is required (or --kbar-file" in capsys.readouterr().err
    assert not (tmp_path / "none.nc").exists()
    # rigid beside finite pillars: no mean names the brush (inf would file it as rigid)
    values.write_text("0.01\n0.02\ninf\n0.04\n")
    assert main([*argv, "--kbar-file", str(values), "--out", str(tmp_path / "m.nc")]) == 2
    assert ("--kbar is required beside a --kbar-file of rigid and finite pillars (1 of 4 "
            "rigid)") in capsys.readouterr().err
    values.write_text("inf\ninf\ninf\ninf\n")
    assert main([*argv, "--kbar-file", str(values), "--out", str(tmp_path / "r.nc")]) == 0
    assert read_curve(tmp_path / "r.nc").attrs["kbar"] == math.inf


def test_min_gap_on_a_lattice_is_said_to_be_ignored(tmp_path) -> None:
    """--min-gap sets only a random layout's draw: given on a lattice, that is
    said, and it is not recorded: the curve is the lattice's, parameter hash
    included (`converge` refused the two as disagreeing on min_gap)."""
    argv = ["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "0.01",
            "--grid", "48", "--quiet"]
    with pytest.warns(UserWarning, match=r"--min-gap applies to random layouts only: the "
                      r"regular layout ignores --min-gap 3"):
        assert main([*argv, "--min-gap", "3", "--out", str(tmp_path / "g.nc")]) == 0
    assert main([*argv, "--out", str(tmp_path / "plain.nc")]) == 0
    gap, plain = read_curve(tmp_path / "g.nc"), read_curve(tmp_path / "plain.nc")
    assert gap.attrs["min_gap"] == 1.0
    assert gap.attrs["parameter_hash"] == plain.attrs["parameter_hash"]


def test_a_seed_that_draws_nothing_is_said_to(tmp_path, recwarn) -> None:
    """--seed picks a random layout, drawn heights or a stiffness draw; on a
    lattice with given heights it drew nothing without a word."""
    heights = tmp_path / "h.txt"
    heights.write_text("0.1 0 -0.1 0\n")
    argv = ["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "0.01",
            "--grid", "48", "--quiet", "--preload", "1", "--heights", str(heights)]
    with pytest.warns(UserWarning, match=r"--seed 3 draws nothing here \(it picks a random "
                      r"layout, --roughness heights or a --kbar-spread draw\)"):
        assert main([*argv, "--seed", "3", "--out", str(tmp_path / "s.nc")]) == 0
    recwarn.clear()
    assert main(["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "0.01",
                 "--grid", "48", "--quiet", "--roughness", "0.2", "--preload", "1",
                 "--seed", "3", "--out", str(tmp_path / "r.nc")]) == 0
    assert not [w for w in recwarn if "--seed" in str(w.message)]


def test_converge_keeps_two_files_of_one_name_apart(tmp_path, capsys) -> None:
    """Two folders' brush.csv (different discs) are two brushes: refused, not
    extrapolated as one; and three brushes on three different grids make no
    study (grids are counted per case)."""
    paths = []
    for folder, radius, grid in (("a", 0.1, 32), ("a", 0.1, 48), ("b", 0.14, 64)):
        (tmp_path / folder).mkdir(exist_ok=True)
        table = tmp_path / folder / "brush.csv"
        table.write_text(f"x, y, radius\n0.3, 0.3, {radius}\n0.7, 0.7, {radius}\n")
        paths.append(str(tmp_path / f"{folder}{grid}.nc"))
        assert main(["simulate", "--layout", "file", "--layout-file", str(table), "--kbar",
                     "0.01", "--grid", str(grid), "--quiet", "--out", paths[-1]]) == 0
    assert main(["converge", *paths, "--out-dir", str(tmp_path / "mix")]) == 2
    assert re.search(r"a32\.nc and .*b64\.nc are both brush file_brush but were drawn from "
                     r"files of different content", capsys.readouterr().err)
    spread = []
    for n, grid in ((1, 32), (4, 48), (9, 64)):
        spread.append(str(tmp_path / f"r{n}.nc"))
        assert main(["simulate", "--layout", "regular", "--pillars", str(n), "--kbar", "1",
                     "--grid", str(grid), "--quiet", "--out", spread[-1]]) == 0
    capsys.readouterr()
    assert main(["converge", *spread, "--out-dir", str(tmp_path / "three")]) == 0
    assert "no convergence study: it needs a case run on three" in capsys.readouterr().out


def test_converge_names_a_curve_file_that_is_not_there(tmp_path, capsys) -> None:
    """A mistyped path is said as one, before any file is read, and not
    answered with advice to run the curve again."""
    (tmp_path / "here.nc").write_bytes(b"")
    assert main(["converge", str(tmp_path / "nope.nc"), str(tmp_path / "here.nc"),
                 "--out-dir", str(tmp_path / "study")]) == 2
    err = capsys.readouterr().err
    assert re.search(r"no such curve file: \S*nope\.nc: allowed the \.nc files", err)
    assert "here.nc" not in err and "again" not in err
    assert not (tmp_path / "study").exists()


def test_converge_refines_a_map_drawn_once_a_grid(tmp_path, capsys) -> None:
    """A map fits one grid, so its refinement has one file a grid (g32/brush.npy,
    ...): their contents differ by nature, and they are one brush."""
    from brushcore import BrushParams, generated_table
    from brushcore.model.layout import table_labels
    from brushcore.model.layout_file import save_label_map

    table = generated_table(BrushParams("regular", 4, 0.01, 64))
    paths = []
    for grid in (32, 48, 64):
        (tmp_path / f"g{grid}").mkdir()
        brush = save_label_map(table_labels(table, grid), tmp_path / f"g{grid}" / "brush")
        paths.append(str(tmp_path / f"c{grid}.nc"))
        assert main(["simulate", "--layout", "file", "--layout-file", str(brush), "--kbar",
                     "0.01", "--quiet", "--out", paths[-1]]) == 0
    assert main(["converge", *paths, "--out-dir", str(tmp_path / "s")]) == 0
    assert "3 curves on grids [32, 48, 64]" in capsys.readouterr().out
    assert (tmp_path / "s" / "convergence.nc").is_file()


def test_a_warning_that_names_a_parameter_names_its_flag() -> None:
    """The input readers' warnings open with the parameter ("heights FILE:");
    the command prints the flag a user typed, and leaves other text alone."""
    from brushcore.cli.output import cli_warning

    assert cli_warning(UserWarning("heights h.txt: line 1 '0,1' is read as values")) == \
        "brushcore: warning: --heights h.txt: line 1 '0,1' is read as values\n"
    assert cli_warning("the protocol never retracts") == \
        "brushcore: warning: the protocol never retracts\n"
    assert cli_warning("protocol ends early") == "brushcore: warning: protocol ends early\n"


def test_input_files_of_an_unknown_key_are_refused_as_bad_input(tmp_path) -> None:
    """with_input_files names its keys (ParameterError, as other bad input),
    and points from the field kbar_values to the key kbar_file."""
    from brushcore import BrushParams, ParameterError, with_input_files

    with pytest.raises(ParameterError, match=r"files=\['kbar_values'\] is invalid \(unknown "
                                             r"key; kbar_file gives kbar_values\): allowed keys "
                                             r"among \['gap_map', 'heights'"):
        with_input_files(BrushParams("regular", 4, 0.01, 48), {"kbar_values": "k.txt"})


def test_a_run_that_may_take_long_says_so_before_it_starts(tmp_path, capsys, monkeypatch):
    """After the discretisation line and before any solve, a run whose bound
    exceeds five minutes says what it may take (random 64 at 1024^2: the
    slowest flat curve measured there, 670 s); a small run says nothing."""
    import brushcore.model.curve as curve
    from brushcore.cli import main

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt  # the line is said: no need to solve

    monkeypatch.setattr(curve, "simulate", interrupted)
    out = tmp_path / "c.nc"
    base = ["simulate", "--layout", "random", "--pillars", "64", "--kbar", "1e-4",
            "--quiet", "--out", str(out)]
    assert main([*base, "--grid", "1024"]) == 130
    err = capsys.readouterr().err
    assert ("this run may take up to about 11 min on one thread (the slowest flat curve "
            "measured at 1024^2; machines differ 2-3x)") in err, err
    assert err.index("grid 1024:") < err.index("this run may take") and not out.exists()
    assert main([*base, "--grid", "256"]) == 130
    assert "this run may take" not in capsys.readouterr().err


def test_threads_default_to_the_environments(tmp_path) -> None:
    """Without --threads the command takes BRUSHCORE_THREADS, as the Python
    API does (it pinned 1 whatever the variable said, a reproducibility
    helper's find); a bad value is refused naming the variable."""
    env = {**os.environ, "BRUSHCORE_THREADS": "two"}
    cmd = [sys.executable, "-m", "brushcore.cli", "simulate", "--layout", "regular",
           "--pillars", "4", "--kbar", "0.1", "--grid", "32", "--quiet",
           "--out", str(tmp_path / "t.nc")]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env)
    assert res.returncode == 2 and "BRUSHCORE_THREADS" in res.stderr, res.stderr
    assert not (tmp_path / "t.nc").exists()
    res = subprocess.run([*cmd, "--threads", "1"], capture_output=True, text=True,
                         timeout=120, env=env)
    assert res.returncode == 0, res.stderr


def test_integer_flags_take_whole_numbers_in_any_notation(tmp_path):
    """--grid 64.0 runs as the config's grid: 64.0 and BrushParams(grid=64.0) do."""
    out = tmp_path / "a.nc"
    assert main(["simulate", "--layout", "random", "--pillars", "4.0", "--kbar", "1",
                 "--grid", "64.0", "--seed", "1e1", "--out", str(out), "--quiet"]) == 0
    ds = read_curve(out)
    assert (ds.attrs["n_pillars"], ds.attrs["grid"], ds.attrs["seed"]) == (4, 64, 10)
    from brushcore.numerics.platform.threads import fft_threads

    assert ds.attrs["threads"] == fft_threads()  # what its bits hang on: recorded


def test_a_pillar_table_in_metres_is_told_its_unit(tmp_path, capsys):
    """A table of 5-um discs written in metres spans no element on any grid:
    the error says a table's lengths are in units of L, not "fewer pillars"."""
    table = tmp_path / "metres.csv"
    table.write_text("x,y,radius\n2e-5,2e-5,5e-6\n6e-5,6e-5,5e-6\n")
    assert main(["simulate", "--layout", "file", "--layout-file", str(table), "--kbar", "1",
                 "--grid", "64", "--out", str(tmp_path / "a.nc"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "none up to 8192 resolves these pillars: a table's x, y and radius are in units " \
           "of L" in err, err
    assert "fewer pillars" not in err and not (tmp_path / "a.nc").exists()


def test_threads_beyond_the_cpus_are_warned_of(monkeypatch):
    from brushcore.numerics.platform import threads

    for var in threads._VARS:  # restored after the test, as the limits below
        monkeypatch.setenv(var, os.environ.get(var, "1"))
    before = threads.fft_threads()
    cpus = threads.usable_cpus()
    if cpus + 1 > threads.MAX_THREADS:  # pin_threads refuses more than MAX_THREADS
        monkeypatch.setattr(threads, "usable_cpus", lambda: threads.MAX_THREADS - 1)
        cpus = threads.MAX_THREADS - 1
    try:
        with pytest.warns(UserWarning, match=f"{cpus + 1} threads on {cpus} usable CPU"):
            assert threads.pin_threads(cpus + 1) == cpus + 1
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            threads.pin_threads(cpus)
    finally:
        threads.pin_threads(before)


def test_a_run_that_may_not_fit_in_memory_is_warned_of():
    """The peak estimated from the brush (`cost.peak_mb`, which
    test_workflow holds against the peaks measured): random 1620 at 8192^2
    on the tiles, 0.2 GB of process, 16.8 GB of grid buffers (250 bytes an
    element), 0.3 GB for its pillars and 13 GB of tiles (8 MB a pillar);
    said only beyond what is available, and not on a GPU."""
    from brushcore import SolverOptions
    from brushcore.model import cost

    params = BrushParams(layout="random", n_pillars=1620, kbar=1e-3, grid=8192)
    need = cost.expected_peak_bytes(params, SolverOptions())
    assert need == pytest.approx(1e6 * (200 + 250 * 8192**2 / 1e6 + 0.2 * 1620 + 8 * 1620))
    note = cost.memory_note(params, SolverOptions(), available=24e9)
    assert note.startswith("this run may need about 30 GB of memory") and "24 GB" in note
    assert cost.memory_note(params, SolverOptions(), available=need * 1.01) == ""
    gpu = BrushParams(layout="random", n_pillars=1620, kbar=1e-3, grid=8192, backend="gpu")
    assert cost.memory_note(gpu, SolverOptions(), available=1e9) == ""


def test_a_curve_under_another_suffix_is_warned_of_and_a_folder_named(tmp_path, capsys):
    out = tmp_path / "curve.txt"
    with pytest.warns(UserWarning, match=r"--out .*curve.txt: the curve is written as netCDF"):
        assert main(["simulate", "--layout", "regular", "--pillars", "1", "--kbar", "1",
                     "--grid", "16", "--out", str(out), "--quiet"]) == 0
    assert read_curve(out).attrs["n_pillars"] == 1
    (tmp_path / "conv").mkdir()
    assert main(["converge", str(tmp_path / "conv"), "--out-dir", str(tmp_path / "o")]) == 2
    assert f"no such curve file: {tmp_path / 'conv'} (a folder)" in capsys.readouterr().err


def test_every_solver_flag_reaches_the_curve(tmp_path) -> None:
    """Each solver flag sets its option (the parser's mapping onto
    SolverOptions is written out by hand, so a dropped one would pass
    unseen): the curve records every field as given, non-defaults all."""
    out = tmp_path / "c.nc"
    given = dict(rtol=1e-5, max_iter=4000, tie_rtol=5e-7, lookahead=0.01, cascade="global",
                 symmetry=False, precision="double", early_decisions=False,
                 settle_decisions=False, fft_library="fftw")
    assert all(getattr(SolverOptions(), k) != v for k, v in given.items())  # each one moves
    with pytest.warns(UserWarning, match="--lookahead 0.01"):
        assert main(["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "0.01",
                     "--grid", "48", "--rtol", "1e-5", "--max-iter", "4000",
                     "--tie-rtol", "5e-7", "--lookahead", "0.01", "--cascade", "global",
                     "--no-symmetry", "--precision", "double", "--no-early-decisions",
                     "--no-settle-decisions", "--fft-library", "fftw", "--out", str(out),
                     "--quiet"]) == 0
    assert SolverOptions.from_curve(read_curve(out)) == SolverOptions(**given)


@pytest.mark.parametrize("argv, message", [
    (["--max-iter", "0"], "--max-iter 0 is invalid: allowed an integer >= 1"),
    (["--max-iter", "2.5"], "--max-iter: '2.5' is not an integer; allowed an integer >= 1"),
    (["--tie-rtol", "1e-3"], r"--tie-rtol 0.001 is invalid: allowed a number in \[0, 1e-6\]"),
])
def test_bad_solver_limits_are_refused_by_flag(tmp_path, capsys, argv, message) -> None:
    try:  # argparse's own readers exit, the options' checks return
        rc = main(["simulate", "--layout", "regular", "--pillars", "4", "--kbar", "0.01",
                   "--grid", "48", *argv, "--out", str(tmp_path / "c.nc")])
    except SystemExit as exc:
        rc = exc.code
    assert rc == 2 and re.search(message, capsys.readouterr().err)
    assert not list(tmp_path.iterdir())


def test_cg_that_runs_out_of_iterations_names_the_flag_that_allows_more(tmp_path,
                                                                        capsys) -> None:
    rc = main(["simulate", "--layout", "random", "--pillars", "16", "--kbar", "0.1",
               "--grid", "48", "--seed", "3", "--max-iter", "1", "--quiet",
               "--out", str(tmp_path / "c.nc")])
    err = capsys.readouterr().err
    assert rc == 1 and "did not converge in 1 iterations" in err, err
    assert "(--max-iter raises the limit)" in err
    assert not list(tmp_path.iterdir())
