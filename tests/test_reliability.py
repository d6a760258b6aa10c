"""Reliability (issue 5): kills, corrupt files, determinism and loud failures.

* A sweep of ``config/test.yaml`` (narrowed to 5 curves) killed with SIGKILL (Snakemake and its jobs)
  after its first curve file resumes to the same ``sweep.nc`` as a clean run.
* Aggregation refuses truncated, bit-flipped, foreign and non-finite curve
  files with an error naming the file, also through the Snakemake rule.
* Identical inputs give bit-identical curves, in one process, in another, and
  with an identical job running beside it.
* Solver failures raise with the problem in the message; the CLI then exits
  non-zero and leaves no curve file.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

xr = pytest.importorskip("xarray")

from brushcore import BrushParams, SolverOptions, simulate  # noqa: E402
from brushcore.data.aggregate import AggregationError, build_sweep  # noqa: E402
from brushcore.numerics.linear.cg import ConvergenceError  # noqa: E402
from brushcore.data.io import CurveFileError, read_curve, write_curve  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SNAKEMAKE = [sys.executable, "-m", "snakemake"]
CLI = [sys.executable, "-m", "brushcore.cli"]
#: The kill-and-resume sweep: config/test.yaml narrowed to both layouts at two kbar
#: and its Fig. 5 brush (5 curves instead of 11), written into each copy of the
#: repository by `copy_repo`, run up to sweep.nc (what the tests compare): the
#: figures and summary, most of the test sweep's job time, are left out.
NARROW_CONFIG = "config/narrow.yaml"
NARROW = ("kbar: [1.0e-2, 1.0]\nregular: [4]\nrandom: [4]\n"
          "fig5: {n_pillars: 4, kbar: [0.455]}\n")
TEST_SWEEP = ["results/sweep.nc", "--cores", "2", "--configfile", "config/test.yaml",
              NARROW_CONFIG]
# Things a run leaves behind that must not leak into a copy of the repository.
IGNORE = shutil.ignore_patterns(
    ".git", ".snakemake", "results", "logs", "__pycache__", "*.egg-info", ".pytest_cache",
    ".hypothesis", "report.html",
)
# Sweep variables that legitimately differ between runs.
VOLATILE = ("wall_time_s",)
# Counts stored as float (NaN = case not run); compared exactly.
COUNTS = ("events", "operator_applications", "cg_iterations", "n_steps", "attached_pillars")
# Attributes of a curve file that legitimately differ between runs.
VOLATILE_ATTRS = ("wall_time_s", "history", "date_created", "content_sha256")
# A small problem with a few detachment events and cascades (< 1 s).
SMALL = dict(layout="random", n_pillars=16, kbar=0.1, grid=48, phi=0.12, seed=3)
SMALL_ARGS = ["--layout", "random", "--pillars", "16", "--kbar", "0.1", "--grid", "48",
              "--seed", "3", "--quiet"]


def copy_repo(dest: Path) -> Path:
    """The repository without results, Snakemake state or git (and with the
    narrowed test sweep's config, `NARROW_CONFIG`)."""
    shutil.copytree(REPO, dest, ignore=IGNORE)
    (dest / NARROW_CONFIG).write_text(NARROW)
    return dest


def snakemake(workdir: Path, *args: str, timeout: float = 300,
              env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([*SNAKEMAKE, *args], cwd=workdir, capture_output=True, text=True,
                          timeout=timeout, env=env)


def output(proc: subprocess.CompletedProcess) -> str:
    return proc.stdout + proc.stderr


def curve_files(workdir: Path) -> list[Path]:
    return sorted((workdir / "results/curves").rglob("*.nc"))


def live_group_members(pgid: int) -> list[int]:
    """Processes of a process group that are still running (zombies excluded)."""
    alive = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # exited meanwhile
        state, group = fields[0], int(fields[2])
        if group == pgid and state != "Z":
            alive.append(int(stat.parent.name))
    return alive


def assert_same_sweep(got: xr.Dataset, ref: xr.Dataset) -> None:
    """Same variables and coordinates; counts exact, floats to 1e-12, NaN where ref has NaN."""
    assert set(got.variables) == set(ref.variables), (
        f"variables differ: {sorted(set(got.variables) ^ set(ref.variables))}")
    assert dict(got.sizes) == dict(ref.sizes), f"sizes {dict(got.sizes)} != {dict(ref.sizes)}"
    for name in ref.variables:
        if name in VOLATILE:
            continue
        a, b = got[name].values, ref[name].values
        if b.dtype.kind in "OUS":
            assert a.tolist() == b.tolist(), f"{name}: {a} != {b}"
        elif b.dtype.kind in "iub" or name in COUNTS:
            assert np.array_equal(a, b, equal_nan=b.dtype.kind == "f"), f"{name} differs"
        else:
            assert np.array_equal(np.isnan(a), np.isnan(b)), f"{name}: NaN positions differ"
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=0.0, equal_nan=True,
                                       err_msg=f"sweep variable {name}")


def assert_identical_curves(got: xr.Dataset, ref: xr.Dataset, what: str) -> None:
    """Bit-identical variables and identical non-volatile attributes."""
    assert set(got.variables) == set(ref.variables), what
    for name in ref.variables:
        a, b = got[name].values, ref[name].values
        if b.dtype.kind in "OUS":
            assert a.tolist() == b.tolist(), f"{what}: {name} differs"
        else:
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), f"{what}: {name} differs"
    for key in set(ref.attrs) | set(got.attrs):
        if key not in VOLATILE_ATTRS:
            assert str(got.attrs.get(key)) == str(ref.attrs.get(key)), f"{what}: attr {key}"


# -- kill and resume -----------------------------------------------------------------------


@pytest.fixture(scope="module")
def clean_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The test sweep run once without interruption."""
    work = copy_repo(tmp_path_factory.mktemp("clean") / "repo")
    proc = snakemake(work, *TEST_SWEEP)
    assert proc.returncode == 0, f"clean test sweep failed:\n{output(proc)[-6000:]}"
    return work


@pytest.mark.slow
def test_killed_sweep_resumes_to_the_same_sweep(clean_run: Path, tmp_path: Path) -> None:
    work = copy_repo(tmp_path / "repo")
    with open(tmp_path / "killed.log", "w") as log:
        proc = subprocess.Popen([*SNAKEMAKE, *TEST_SWEEP], cwd=work, stdout=log,
                                stderr=subprocess.STDOUT, start_new_session=True)
        deadline = time.monotonic() + 180
        try:
            while not curve_files(work):
                assert proc.poll() is None, (
                    "Snakemake ended before writing a curve:\n"
                    + (tmp_path / "killed.log").read_text()[-4000:])
                assert time.monotonic() < deadline, "no curve file within 180 s"
                time.sleep(0.05)
        finally:
            os.killpg(proc.pid, signal.SIGKILL)  # Snakemake and every job it started
            proc.wait(timeout=60)
    if Path("/proc/self/stat").exists():  # no job may survive and keep writing
        deadline = time.monotonic() + 30
        while live_group_members(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not live_group_members(proc.pid), "processes survived SIGKILL of the group"

    expected = {p.relative_to(clean_run) for p in curve_files(clean_run)}
    done = {p.relative_to(work) for p in curve_files(work)}
    assert done and done < expected, (
        f"the kill should have hit a running sweep: {len(done)} of {len(expected)} curves")
    assert not (work / "results/sweep.nc").exists(), "sweep.nc written before all curves"
    for path in curve_files(work):  # whatever exists is complete
        read_curve(path)
    leftovers = [p for p in (work / "results/curves").rglob("*")
                 if p.is_file() and p.suffix != ".nc"]
    assert all(p.name.startswith(".") and p.name.endswith(".tmp") for p in leftovers), (
        f"unexpected files after the kill: {leftovers}")
    # A job killed inside write_curve leaves such a hidden temporary file; plant one for
    # a curve that is still missing to check the rerun ignores and removes it.
    missing = work / sorted(expected - done)[0]
    stale = missing.parent / f".{missing.name}.killed.tmp"
    stale.parent.mkdir(parents=True, exist_ok=True)
    stale.write_bytes(b"\x89HDF\r\n\x1a\n half a file")

    # SIGKILL leaves Snakemake's lock on the directory: it must be released by hand.
    unlock = snakemake(work, "--configfile", "config/test.yaml", "--unlock")
    assert unlock.returncode == 0, output(unlock)
    proc2 = snakemake(work, *TEST_SWEEP, "--rerun-incomplete")
    assert proc2.returncode == 0, f"resumed sweep failed:\n{output(proc2)[-6000:]}"
    assert {p.relative_to(work) for p in curve_files(work)} == expected
    leftovers = [p for p in (work / "results").rglob("*.tmp")]
    assert not leftovers, f"temporary files left after the resumed sweep: {leftovers}"
    with xr.open_dataset(work / "results/sweep.nc") as got, \
            xr.open_dataset(clean_run / "results/sweep.nc") as ref:
        assert_same_sweep(got.load(), ref.load())


# -- corrupt, truncated and foreign curve files --------------------------------------------


@pytest.fixture(scope="module")
def cli_curves(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Three curve files of one small sweep written by the CLI (grid 32)."""
    root = tmp_path_factory.mktemp("cli_curves")
    cases = [("regular", "4", "0.01", "0"), ("regular", "4", "1.0", "0"),
             ("random", "4", "1.0", "1")]
    paths = []
    for layout, n, kbar, seed in cases:
        out = root / f"{layout}_N{n}_kbar{kbar}_seed{seed}.nc"
        proc = subprocess.run([*CLI, "simulate", "--layout", layout, "--pillars", n,
                               "--kbar", kbar, "--grid", "32", "--seed", seed, "--quiet",
                               "--out", str(out)], capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, output(proc)
        paths.append(out)
    return paths


def _truncated(src: Path, dest: Path, keep: float) -> None:
    data = src.read_bytes()
    dest.write_bytes(data[: int(len(data) * keep)])


def _flipped(src: Path, dest: Path) -> None:
    """One byte changed inside the force values: a valid HDF5 file with a wrong number."""
    ds = read_curve(src)
    data = bytearray(src.read_bytes())
    needle = np.asarray(ds["force"].values[1:], dtype="<f8").tobytes()
    at = data.find(needle)
    assert at > 0, "force values not found stored contiguously"
    data[at + 3] ^= 0x5A
    dest.write_bytes(bytes(data))


def _foreign(src: Path, dest: Path) -> None:
    xr.Dataset({"temperature": ("time", np.arange(5.0))},
               attrs={"title": "not a curve"}).to_netcdf(dest)


def _non_finite(src: Path, dest: Path) -> None:
    ds = read_curve(src)
    ds["force"].values[1] = np.nan  # written without the digest: an older or foreign writer
    ds.attrs.pop("content_sha256", None)
    ds.to_netcdf(dest)


def _missing_attr(src: Path, dest: Path) -> None:
    ds = read_curve(src)
    del ds.attrs["kbar"]
    write_curve(ds, dest)


CORRUPTIONS = {
    "empty": lambda src, dest: dest.write_bytes(b""),
    "truncated_header": lambda src, dest: _truncated(src, dest, 0.01),
    "truncated_half": lambda src, dest: _truncated(src, dest, 0.5),
    "truncated_last_byte": lambda src, dest: dest.write_bytes(src.read_bytes()[:-1]),
    "byte_flipped": _flipped,
    "foreign_netcdf": _foreign,
    "non_finite_force": _non_finite,
    "missing_kbar_attribute": _missing_attr,
    "text_file": lambda src, dest: dest.write_text("force,displacement\n1,2\n"),
}


@pytest.mark.parametrize("kind", sorted(CORRUPTIONS))
def test_aggregation_refuses_a_bad_curve_file(cli_curves: list[Path], tmp_path: Path,
                                              kind: str) -> None:
    good = build_sweep(cli_curves)  # the good files alone aggregate
    assert int(np.isfinite(good["adhesive_force_normalized"].values).sum()) == len(cli_curves)
    bad = tmp_path / f"bad_{kind}.nc"
    CORRUPTIONS[kind](cli_curves[-1], bad)
    with pytest.raises(CurveFileError, match=bad.name):
        read_curve(bad)
    with pytest.raises(AggregationError) as info:
        build_sweep([*cli_curves[:-1], bad])
    assert bad.name in str(info.value), f"error does not name the file: {info.value}"


def test_aggregation_refuses_a_random_brush_of_the_old_gap_rule(cli_curves: list[Path],
                                                               tmp_path: Path) -> None:
    """A random curve off 512^2 without ``random_gap`` was drawn with a gap of
    min_gap elements of its own grid (before 2026-12-04): another brush than
    its seed names now, so it must not join today's curves along ``grid``."""
    random_curve = cli_curves[-1]
    ds = read_curve(random_curve)
    assert ds.attrs["layout"] == "random" and ds.attrs["grid"] == 32
    del ds.attrs["random_gap"]
    old = tmp_path / "random_before_the_rule.nc"
    write_curve(ds, old)
    read_curve(old)  # a valid file on its own
    with pytest.raises(AggregationError, match=r"random_before_the_rule\.nc.*grid 32.*"
                                               r"seed 1 names another brush"):
        build_sweep([*cli_curves[:-1], old])
    ds.attrs["grid"] = 512  # where both rules draw the same brush: accepted
    at_512 = tmp_path / "random_512.nc"
    write_curve(ds, at_512)
    assert "random" in build_sweep([*cli_curves[:-1], at_512])["layout"].values


def test_aggregate_rule_fails_on_a_truncated_curve(clean_run: Path, tmp_path: Path) -> None:
    work = tmp_path / "repo"
    shutil.copytree(clean_run, work, symlinks=True)  # results and .snakemake included
    victim = curve_files(work)[0]
    victim.write_bytes(victim.read_bytes()[:1000])
    os.utime(victim)  # newer than sweep.nc
    proc = snakemake(work, "--cores", "1", "--configfile", "config/test.yaml", NARROW_CONFIG,
                     "--forcerun", "aggregate")
    log = (work / "logs/aggregate.log").read_text() if (work / "logs/aggregate.log").exists() \
        else ""
    assert proc.returncode != 0, f"aggregation accepted a truncated curve:\n{output(proc)}"
    assert victim.name in output(proc) + log, (
        f"neither Snakemake nor the log names {victim.name}:\n{output(proc)[-4000:]}\n{log}")
    assert not (work / "results/sweep.nc").exists(), "a failed aggregation left sweep.nc"
    assert "rule simulate" not in output(proc), "a truncated curve must not trigger a rerun"
    # an explained refusal: its message on the terminal and in the log, no traceback
    assert f"aggregate: cannot aggregate 1 curve file(s): {victim.relative_to(work)}" in \
        output(proc), output(proc)[-4000:]
    assert "Traceback" not in log and "Delete them and run snakemake again" in log, log


# -- determinism ---------------------------------------------------------------------------

SUBPROCESS_SIMULATE = textwrap.dedent("""
    import sys
    from brushcore import BrushParams, SolverOptions, simulate
    from brushcore.data.io import write_curve
    write_curve(simulate(BrushParams(**{params!r}), SolverOptions()), sys.argv[1])
""")


def test_same_params_give_bit_identical_curves(tmp_path: Path) -> None:
    params = BrushParams(**SMALL)
    first = simulate(params, SolverOptions())
    second = simulate(params, SolverOptions())
    out = tmp_path / "subprocess.nc"
    proc = subprocess.run([sys.executable, "-c", SUBPROCESS_SIMULATE.format(params=SMALL),
                           str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, output(proc)
    other = read_curve(out)
    assert first.attrs["events"] > 1, "the determinism case should have several events"
    for label, ds in (("second run in the process", second), ("another process", other)):
        assert first["force"].values.tobytes() == ds["force"].values.tobytes(), (
            f"force differs in the {label}")
        for name in ("adhesive_force", "work_of_separation", "displacement_at_adhesive_force",
                     "adhesive_force_normalized", "work_of_separation_normalized"):
            assert float(first[name]) == float(ds[name]), f"{name} differs in the {label}"
        assert_identical_curves(ds, first, label)


def test_concurrent_identical_jobs_match_a_lone_one(tmp_path: Path) -> None:
    # A fresh FFTW wisdom cache: the two concurrent jobs both have to plan.
    env = {**os.environ, "BRUSHCORE_WISDOM_DIR": str(tmp_path / "wisdom")}
    outs = [tmp_path / f"concurrent{i}.nc" for i in (1, 2)]
    procs = [subprocess.Popen([*CLI, "simulate", *SMALL_ARGS, "--out", str(out)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
             for out in outs]
    texts = [p.communicate(timeout=120)[0] for p in procs]
    assert all(p.returncode == 0 for p in procs), texts
    alone = tmp_path / "alone.nc"
    proc = subprocess.run([*CLI, "simulate", *SMALL_ARGS, "--out", str(alone)], env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, output(proc)
    ref = read_curve(alone)
    for out in outs:
        assert_identical_curves(read_curve(out), ref, f"{out.name} vs a job run alone")


# -- loud failures -------------------------------------------------------------------------


def test_damaged_fftw_wisdom_is_planned_afresh_not_fatal(tmp_path: Path) -> None:
    """FFTW's importer does not refuse damaged wisdom: it aborts the process
    in an assertion (exit 134, no message), and every later run on the
    machine with it.  Three bytes changed in the cached text (the damage an
    audit found fatal) are caught by the stored checksum: the run warns,
    plans afresh and finishes, and its save replaces the damaged file."""
    import pickle

    env = {**os.environ, "BRUSHCORE_WISDOM_DIR": str(tmp_path / "wisdom")}
    run = [*CLI, "simulate", *SMALL_ARGS, "--out"]
    first = subprocess.run([*run, str(tmp_path / "a.nc")], env=env, capture_output=True,
                           text=True, timeout=120)
    assert first.returncode == 0, output(first)
    cache = tmp_path / "wisdom" / "fftw-wisdom-v2.pickle"
    stored = pickle.loads(cache.read_bytes())
    text = stored["wisdom"][0]
    damaged = re.sub(rb"(#x[0-9a-f]+) (#x0)\b", rb"\1s\2", text, count=1)
    assert damaged != text
    stored["wisdom"] = (damaged, *stored["wisdom"][1:])  # its old checksum kept
    cache.write_bytes(pickle.dumps(stored))
    again = subprocess.run([*run, str(tmp_path / "b.nc")], env=env, capture_output=True,
                           text=True, timeout=120)
    assert again.returncode == 0, output(again)
    assert "is damaged" in again.stderr, output(again)
    assert read_curve(tmp_path / "b.nc").attrs["events"] == read_curve(tmp_path / "a.nc").attrs["events"]
    mended = pickle.loads(cache.read_bytes())
    assert mended["wisdom"][0] != damaged
    # the file before the checksum (a bare tuple), which older versions read and
    # this one reads where its own is missing, stays as it was
    old = tmp_path / "wisdom" / "fftw-wisdom.pickle"
    old.write_bytes(pickle.dumps(mended["wisdom"]))
    cache.unlink()
    third = subprocess.run([*run, str(tmp_path / "c.nc")], env=env, capture_output=True,
                           text=True, timeout=120)
    assert third.returncode == 0 and "is damaged" not in third.stderr, output(third)
    assert pickle.loads(old.read_bytes()) == mended["wisdom"] and cache.exists()


def test_a_wisdom_file_damaged_in_its_pickle_is_planned_afresh(tmp_path: Path, monkeypatch,
                                                                capsys) -> None:
    """A crash and resume auditor changed single bytes of the wisdom file's
    pickle: 38 of 3,600 escaped the checksum and raised MemoryError (a length
    byte: the command said "out of memory at --grid 64"), OverflowError or
    ModuleNotFoundError (pickle imports what a file names) on every later run
    on the machine.  Any such file is now warned of and planned afresh, and
    a file that names a class is refused without importing it; a cache write
    that fails leaves no temporary behind."""
    import pickle

    from brushcore.numerics.halfspace import convolution

    monkeypatch.setenv("BRUSHCORE_WISDOM_DIR", str(tmp_path))
    good = pickle.dumps({"wisdom": (b"x" * 64,), "sha256": "0"}, protocol=4)
    assert good[2:3] == b"\x95"  # FRAME and its 8-byte length
    huge_frame = good[:3] + (2**62).to_bytes(8, "little") + good[11:]  # MemoryError before
    names_a_module = b"cnot_a_module\nf\n."  # GLOBAL: ModuleNotFoundError before
    for damaged in (huge_frame, names_a_module, b"", b"\x00" * 40):
        (tmp_path / convolution.WISDOM_FILE).write_bytes(damaged)
        convolution._load_wisdom()  # no exception
        assert "is damaged" in capsys.readouterr().err
    (tmp_path / "blocked.bin").mkdir()  # the target a folder: the rename fails
    convolution.save_to_cache("blocked.bin", b"data")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blocked.bin", convolution.WISDOM_FILE]


def test_an_unusable_cache_is_said_once(tmp_path: Path, monkeypatch, capsys) -> None:
    """A cache that cannot be written (here a file where its folder should
    be) was silent: every run then plans FFTW afresh and jobs plan without
    the machine's lock.  It is said once per process, naming the folder and
    the variable that moves it, and the save still fails quietly."""
    from brushcore.numerics.halfspace import convolution

    blocked = tmp_path / "not-a-folder"
    blocked.write_text("")
    monkeypatch.setenv("BRUSHCORE_WISDOM_DIR", str(blocked))
    monkeypatch.setattr(convolution, "_UNUSABLE_SAID", set())
    convolution.save_to_cache("a.bin", b"data")
    convolution.save_to_cache("b.bin", b"data")
    err = capsys.readouterr().err
    assert err.count(f"cannot write the cache {blocked}") == 1, err
    assert "BRUSHCORE_WISDOM_DIR" in err
    monkeypatch.setenv("BRUSHCORE_WISDOM_DIR", str(tmp_path))  # a writable one: silent
    convolution.save_to_cache("c.bin", b"data")
    assert capsys.readouterr().err == "" and (tmp_path / "c.bin").read_bytes() == b"data"


@pytest.mark.skipif(not __import__("brushcore.numerics.halfspace.convolution",
                                   fromlist=["HAVE_PYFFTW"]).HAVE_PYFFTW, reason="no pyfftw")
def test_a_read_only_cache_that_holds_the_plans_is_not_written_to(tmp_path: Path, monkeypatch,
                                                                  capsys) -> None:
    """Wisdom was saved after every planning, new plans or not, so a cache
    that holds every plan but cannot be written (a site-wide wisdom folder)
    printed the unusable-cache note, falsely saying plans were made afresh
    (a diff reviewer's find).  Wisdom is saved only when it changed (FFTW
    exports imported entries in another order: compared as sorted lines)."""
    from brushcore.numerics.halfspace import convolution

    monkeypatch.setenv("BRUSHCORE_WISDOM_DIR", str(tmp_path))
    monkeypatch.setattr(convolution, "_UNUSABLE_SAID", set())
    convolution.Convolver(24)  # plans and saves: the cache now holds them
    saved = (tmp_path / convolution.WISDOM_FILE).stat().st_mtime_ns

    def refused(src, dst):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(convolution.os, "replace", refused)  # root ignores chmod
    convolution.Convolver(24)  # nothing new to plan: no write, no note
    assert capsys.readouterr().err == ""
    assert (tmp_path / convolution.WISDOM_FILE).stat().st_mtime_ns == saved
    convolution.Convolver(40)  # new plans that cannot be kept: said
    assert "cannot write the cache" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.tmp"))


def test_cg_non_convergence_raises_with_the_problem_in_the_message() -> None:
    params = BrushParams(**SMALL)
    with pytest.raises(ConvergenceError) as info:
        simulate(params, SolverOptions(max_iter=1))
    message = str(info.value)
    for part in ("did not converge in 1 iterations", "size ", "at event 0", "elements attached"):
        assert part in message, f"{part!r} missing from: {message}"
    # the problem as the fields that differ from their defaults, not all twenty
    assert message.endswith("; problem: layout='random', n_pillars=16, kbar=0.1, grid=48, "
                            "seed=3; options: max_iter=1"), message  # phi 0.12: the default


def test_non_finite_operator_raises(monkeypatch: pytest.MonkeyPatch) -> None:
    import brushcore.numerics.events.pulloff as pulloff

    real_pcg = pulloff.pcg
    calls = []

    def poisoned(apply, precondition, b, x0, rtol, max_iter, *args):
        calls.append(1)
        if len(calls) < 3:
            return real_pcg(apply, precondition, b, x0, rtol, max_iter, *args)
        return real_pcg(lambda x: apply(x) * np.nan, precondition, b, x0, rtol, max_iter,
                        *args)

    monkeypatch.setattr(pulloff, "pcg", poisoned)
    with pytest.raises(ConvergenceError, match="non-finite") as info:
        simulate(BrushParams(**SMALL), SolverOptions())
    assert "at event" in str(info.value), str(info.value)


CLI_FAILING = textwrap.dedent("""
    import sys
    import brushcore.numerics.linear.cg, brushcore.numerics.events.pulloff, brushcore.cli

    def fail(*args, **kwargs):
        raise brushcore.numerics.linear.cg.ConvergenceError("injected CG failure")

    brushcore.numerics.linear.cg.pcg = brushcore.numerics.events.pulloff.pcg = fail
    sys.exit(brushcore.cli.main(sys.argv[1:]))
""")


def test_cli_failure_exits_non_zero_without_output(tmp_path: Path) -> None:
    out = tmp_path / "curves" / "failed.nc"
    proc = subprocess.run([sys.executable, "-c", CLI_FAILING, "simulate", *SMALL_ARGS,
                           "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0, f"CLI exited 0 after a solver failure:\n{output(proc)}"
    assert "injected CG failure" in proc.stderr, output(proc)
    left = list(out.parent.iterdir()) if out.parent.exists() else []
    assert not left, f"a failed solve left files: {left}"


KILL_IN_WRITE = textwrap.dedent("""
    import os, signal, sys
    import numpy as np, xarray as xr
    from brushcore.data.io import write_curve

    real = xr.Dataset.to_netcdf

    def dying(self, path, *args, **kwargs):
        real(self, path, *args, **kwargs)
        with open(path, "r+b") as fh:  # the file is half flushed when the kill comes
            fh.truncate(os.path.getsize(path) // 2)
        os.kill(os.getpid(), signal.SIGKILL)

    xr.Dataset.to_netcdf = dying
    write_curve(xr.Dataset({"force": ("step", np.arange(3.0))}), sys.argv[1])
""")


def test_kill_inside_write_curve_keeps_the_old_file(cli_curves: list[Path], tmp_path: Path
                                                    ) -> None:
    target = tmp_path / "curve.nc"
    shutil.copy(cli_curves[0], target)
    before = target.read_bytes()
    proc = subprocess.run([sys.executable, "-c", KILL_IN_WRITE, str(target)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == -signal.SIGKILL, output(proc)
    assert target.read_bytes() == before, "a killed write changed the existing curve"
    read_curve(target)
    others = [p.name for p in tmp_path.iterdir() if p != target]
    assert others and all(n.startswith(".curve.nc.") and n.endswith(".tmp") for n in others), (
        f"a killed write should leave only its hidden temporary file, found {others}")
    assert not [n for n in others if n.endswith(".nc")], others


def _fill_disk_on_write(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make every netCDF write fail with ENOSPC after writing its bytes."""
    import errno

    real = xr.Dataset.to_netcdf

    def disk_full(self, path, *args, **kwargs):
        real(self, path, *args, **kwargs)
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(xr.Dataset, "to_netcdf", disk_full)


def test_failed_write_leaves_neither_file_nor_temporary(cli_curves: list[Path], tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """A full disk (ENOSPC half way through the write) raises and cleans up."""
    target = tmp_path / "curve.nc"
    shutil.copy(cli_curves[0], target)
    before = target.read_bytes()
    _fill_disk_on_write(monkeypatch)
    with pytest.raises(OSError, match="No space left"):
        write_curve(read_curve(cli_curves[1]), target)
    with pytest.raises(OSError, match="No space left"):
        write_curve(read_curve(cli_curves[1]), tmp_path / "new.nc")
    assert target.read_bytes() == before, "a failed write changed the existing curve"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["curve.nc"], (
        f"a failed write left files: {sorted(p.name for p in tmp_path.iterdir())}")


def test_writing_to_a_folder_says_so_before_writing(cli_curves: list[Path],
                                                     tmp_path: Path) -> None:
    """A folder as the file name: one clear error naming it, nothing left behind
    (it was a rename error naming the temporary, after the whole write)."""
    with pytest.raises(IsADirectoryError, match=r"a folder, not a file name: give a file in "
                                                r"it, .*/NAME"):
        write_curve(read_curve(cli_curves[0]), tmp_path)
    assert list(tmp_path.iterdir()) == []
    # a folder no file can be made in (a read-only one): the path asked for, not the temporary
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    if os.access(locked, os.W_OK):  # root writes anywhere: /proc's files are made by the kernel
        locked = Path("/proc")
    with pytest.raises(OSError, match=rf"no file can be written in {locked}: '{locked}/c\.nc'"):
        write_curve(read_curve(cli_curves[0]), locked / "c.nc")


#: Makes every random brush's solve fail in the jobs (a `sitecustomize` on
#: PYTHONPATH): whatever can be checked is checked at plan time, so a job
#: that fails is one whose solve fails.
FAILING_RANDOM_SOLVES = textwrap.dedent("""
    import brushcore.model.curve as curve
    from brushcore.numerics.events.pulloff import SolverError

    solve = curve.run

    def fail_random(params, *args, **kwargs):
        if params.layout == "random":
            raise SolverError("injected failure of a random brush's solve")
        return solve(params, *args, **kwargs)

    curve.run = fail_random
""")


def test_failing_job_fails_the_sweep_loudly(tmp_path: Path) -> None:
    """A job whose solve fails: Snakemake fails, names it, writes no curve for it."""
    work = copy_repo(tmp_path / "repo")
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(FAILING_RANDOM_SOLVES)
    config = work / "config/unfit.yaml"
    config.write_text("grid: 64\nkbar: [1.0]\nregular: [4]\nrandom: [4]\n"
                      "seeds: [0]\nfig5: {n_pillars: 4, kbar: [1.0]}\nthreads: 1\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(hook), *filter(None, [os.environ.get("PYTHONPATH")])])}
    proc = snakemake(work, "--cores", "2", "--configfile", "config/unfit.yaml", env=env)
    text = output(proc)
    assert proc.returncode != 0, f"the sweep succeeded with a failing solve:\n{text[-4000:]}"
    assert "Error in rule simulate" in text and "N4_kbar1.0_seed0" in text, text[-4000:]
    log = (work / "logs/simulate/random/N4_kbar1.0_seed0_grid64_phi0.12.log").read_text()
    assert "SolverError" in log and "injected failure" in log, log
    assert not (work / "results/curves/random").exists() or not list(
        (work / "results/curves/random").iterdir()), "the failed job left files"
    assert not (work / "results/sweep.nc").exists(), "sweep.nc written despite a failed job"


def test_failed_sweep_write_keeps_the_old_sweep(cli_curves: list[Path], tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    from brushcore.data.aggregate import write_sweep

    target = tmp_path / "sweep.nc"
    write_sweep(build_sweep(cli_curves[:2]), target)
    before = target.read_bytes()
    _fill_disk_on_write(monkeypatch)
    with pytest.raises(OSError, match="No space left"):
        write_sweep(build_sweep(cli_curves), target)
    assert target.read_bytes() == before, "a failed write changed the existing sweep"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sweep.nc"], (
        f"a failed sweep write left files: {sorted(p.name for p in tmp_path.iterdir())}")


def test_interrupted_job_logs_one_line_and_exits_130(tmp_path: Path, capfd) -> None:
    """Ctrl-C inside a workflow script: no traceback, one line, status 130."""
    from brushcore.data.joblog import EXIT_INTERRUPTED, logged

    log = tmp_path / "job.log"
    with pytest.raises(SystemExit) as stop:
        with logged(log):
            print("working")
            raise KeyboardInterrupt
    assert stop.value.code == EXIT_INTERRUPTED == 130
    assert log.read_text() == "working\ninterrupted; nothing written\n"
    err = capfd.readouterr().err
    assert err.strip() == f"{log}: interrupted; nothing written" and "Traceback" not in err


def test_terminated_job_logs_where_it_stood_and_exits_143(tmp_path: Path, capfd) -> None:
    """SIGTERM (Slurm's time limit, scancel) inside a workflow script: one
    line saying where the curve stood, status 143, no traceback."""
    from brushcore.data.joblog import CurveClock, logged, stops_on_sigterm

    log = tmp_path / "job.log"
    clock = CurveClock()
    clock(12, 750, 1000)  # the curve's last event so far
    with pytest.raises(SystemExit) as stop:
        with logged(log), stops_on_sigterm(clock.where):
            print("working")
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(30)  # the handler interrupts this
    assert stop.value.code == 143
    assert log.read_text() == (
        "working\nterminated (SIGTERM: scancel or the time limit) at event 12, 750 of 1000 "
        "pillar elements in contact, after 0 s; nothing written\n")
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # the handler is gone again
    assert "Traceback" not in capfd.readouterr().err


def test_simulate_script_killed_by_sigterm_writes_no_curve(tmp_path: Path) -> None:
    """The workflow's simulate script, killed as at a Slurm time limit: its
    log ends with the one line, it exits 143 and leaves no curve file."""
    out, log = tmp_path / "curve.nc", tmp_path / "job.log"
    job = textwrap.dedent(f"""
        import runpy
        from types import SimpleNamespace
        smk = SimpleNamespace(
            threads=1, log=[{str(log)!r}], output=[{str(out)!r}],
            wildcards=SimpleNamespace(layout="random", n_pillars="1620", kbar="1e-05",
                                      grid="512", phi="0.12", seed="0"),
            config={{"allow_coarse": False, "backend": "cpu"}},
            params=SimpleNamespace(solver={{}}, rough={{}}, shape={{}}, layout_file=""))
        runpy.run_path({str(REPO / "workflow/scripts/simulate.py")!r},
                       init_globals={{"snakemake": smk}})
    """)
    proc = subprocess.Popen([sys.executable, "-c", job])
    for _ in range(600):  # the job has built its brush and started the curve
        if log.exists() and " thread(s)" in log.read_text():
            break
        time.sleep(0.05)
    time.sleep(3.0)
    proc.terminate()
    assert proc.wait(timeout=60) == 143
    lines = log.read_text().splitlines()
    assert len(lines) == 2 and "Traceback" not in log.read_text(), lines
    assert re.fullmatch(r"terminated \(SIGTERM: scancel or the time limit\) (at event \d+, "
                        r"\d+ of \d+ pillar elements in contact|before the first event), "
                        r"after \d+ s; nothing written", lines[1]), lines
    assert sorted(p.name for p in tmp_path.iterdir()) == ["job.log"]


def test_orphaned_job_stops_without_writing(tmp_path: Path) -> None:
    """A job whose Snakemake was killed (its parent gone) stops at its next
    check with status 75 instead of writing a curve much later, unseen."""
    ready, result = tmp_path / "ready", tmp_path / "result"
    job = textwrap.dedent(f"""
        import time
        from brushcore.data.joblog import parent_watch
        check = parent_watch()
        check(1, 2, 3)  # while the parent lives: nothing happens
        open({str(ready)!r}, "w").close()
        try:
            for _ in range(500):
                time.sleep(0.02)
                check()
            open({str(result)!r}, "w").write("still running")
        except SystemExit as exc:
            open({str(result)!r}, "w").write(str(exc.code))
    """)
    # The stand-in for Snakemake starts the job and dies once it is running.
    parent = textwrap.dedent(f"""
        import os, subprocess, sys, time
        subprocess.Popen([sys.executable, "-c", {job!r}], stdout=subprocess.DEVNULL)
        while not os.path.exists({str(ready)!r}):
            time.sleep(0.01)
        os._exit(0)
    """)
    subprocess.run([sys.executable, "-c", parent], check=True, timeout=60)
    for _ in range(600):
        if result.exists() and result.read_text():
            break
        time.sleep(0.05)
    assert result.read_text() == "75"


def test_git_commit_says_dirty_for_an_edit_anywhere_in_the_package(monkeypatch) -> None:
    """The "+dirty" check looked at brushcore/model only (where provenance.py
    moved): an edit in numerics/ went unrecorded.  It asks git about the
    whole package."""
    import brushcore
    from brushcore.model import provenance

    asked = []

    def fake_run(args, **kwargs):
        asked.append(args)
        out = "abc123\n" if args[1] == "rev-parse" else " M brushcore/numerics/linear/cg.py\n"
        return subprocess.CompletedProcess(args, 0, stdout=out, stderr="")

    monkeypatch.setattr(provenance.subprocess, "run", fake_run)
    assert provenance.git_commit.__wrapped__() == "abc123+dirty"
    assert asked[-1][-1] == str(Path(brushcore.__file__).resolve().parent)


def test_a_brushcore_inside_another_projects_repository_records_no_commit(tmp_path,
                                                                           monkeypatch):
    """Installed in a virtual environment inside another project's git
    repository, brushcore recorded that project's commit as its own (a
    review's finding): only a package beside brushcore's own pyproject asks
    git (a source tree, also one inside a larger repository)."""
    from brushcore.model import provenance

    (tmp_path / "pyproject.toml").write_text('[project]\nname = "myproject"\nversion = "1"\n')
    site = tmp_path / ".venv/lib/python3.11/site-packages/brushcore/model"

    def fake_run(args, **kwargs):
        return subprocess.CompletedProcess(args, 0, stdout="857ce5c\n", stderr="")

    monkeypatch.setattr(provenance.subprocess, "run", fake_run)
    monkeypatch.setattr(provenance, "__file__", str(site / "provenance.py"))
    assert provenance.git_commit.__wrapped__() == "unknown"
    tree = tmp_path / "monorepo/brushcore"  # a checkout below another repository's top
    tree.mkdir(parents=True)
    (tree / "pyproject.toml").write_text('[project]\nname = "brushcore"\nversion = "1"\n')
    monkeypatch.setattr(provenance, "__file__", str(tree / "brushcore/model/provenance.py"))
    assert provenance.git_commit.__wrapped__().startswith("857ce5c")


def test_the_version_recorded_is_that_of_the_tree_that_runs(tmp_path, monkeypatch) -> None:
    """A source tree's version is its pyproject's (a clone on PYTHONPATH beside
    another installed copy recorded that copy's); outside a tree, the
    installed distribution's.  Curves, sweeps and studies name it in CF's
    ``source``, with the commit."""
    import tomllib

    from brushcore.model import provenance

    tree = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())
    assert provenance.version.__wrapped__() == tree["project"]["version"]
    assert provenance.source() == (f"brushcore {provenance.version()} "
                                   f"(git {provenance.git_commit()}, "
                                   f"code sha256 {provenance.code_digest()[:16]})")
    fake = tmp_path / "a" / "b" / "provenance.py"  # no pyproject two folders up
    monkeypatch.setattr(provenance, "__file__", str(fake))
    from importlib import metadata

    try:
        installed = metadata.version("brushcore")
    except metadata.PackageNotFoundError:
        installed = "0+unknown"
    assert provenance.version.__wrapped__() == installed


@pytest.mark.parametrize("name,value,said", [
    ("n_pillars", np.array([4, 4]), r"its attribute n_pillars is array\(\[4, 4\]\), not an "
                                    r"integer"),
    ("seed", np.inf, "its attribute seed is inf, not an integer"),
    ("grid", 32.7, "its attribute grid is 32.7, not an integer"),
    ("grid", None, "not a brushcore curve file, missing attribute grid"),
])
def test_a_curve_with_bad_case_attributes_is_refused_as_the_files_fault(name, value, said):
    """An array or a non-finite number where a case's integer stands, or an
    attribute missing: aggregation says which curve and what, and what brings
    it back, where an array or inf escaped as a traceback."""
    from brushcore.data.aggregate import AggregationError, build_sweep

    curve = simulate(BrushParams("regular", 4, 0.1, 32))
    if value is None:
        del curve.attrs[name]
    else:
        curve.attrs[name] = value
    with pytest.raises(AggregationError, match=rf"cannot aggregate 1 curve file\(s\): <curve "
                                               rf"sha256:[0-9a-f]{{64}} in memory> \({said}.*"
                                               rf"Run their brushcore"):
        build_sweep([curve])


def test_files_that_never_were_curves_are_told_apart_from_damaged_ones(tmp_path):
    """A sweep, a table or another netCDF file given among curves (a glob
    that took them) is named as not a curve, with the advice to leave it
    out; "run their simulate again" was said of them, which cannot help.
    A damaged curve keeps that advice; a missing file or a folder says so."""
    from brushcore.data.aggregate import AggregationError, build_sweep, write_sweep
    from brushcore.data.io import CurveFileError, read_curve, write_curve

    curve = simulate(BrushParams("regular", 4, 0.1, 32))
    good = write_curve(curve, tmp_path / "c.nc")
    sweep = tmp_path / "sweep.nc"
    write_sweep(build_sweep([good]), sweep)
    table = tmp_path / "t.csv"
    table.write_text("x,y,radius\n0.5,0.5,0.1\n")
    other = tmp_path / "other.nc"
    import xarray as xr
    xr.Dataset({"a": ("x", [1.0])}).to_netcdf(other)
    cut = tmp_path / "cut.nc"
    cut.write_bytes(good.read_bytes()[:3000])
    for path, said in [(sweep, "a brushcore sweep file, not a curve file"),
                       (table, "cannot be read as a netCDF curve file"),
                       (other, "not a brushcore curve file")]:
        with pytest.raises(CurveFileError, match=said) as caught:
            read_curve(path)
        assert caught.value.not_a_curve
    with pytest.raises(CurveFileError, match="no such file") as caught:
        read_curve(tmp_path / "nope.nc")
    assert not caught.value.not_a_curve
    with pytest.raises(CurveFileError, match="a folder, not a curve file"):
        read_curve(tmp_path)
    with pytest.raises(CurveFileError) as caught:
        read_curve(cut)
    assert not caught.value.not_a_curve  # a .nc cut short may be a curve: run it again
    with pytest.raises(AggregationError) as caught:
        build_sweep([good, cut, sweep, table])
    said = str(caught.value)
    assert said.startswith("cannot aggregate 1 curve file(s): ")
    assert "Run their brushcore simulate again" in said
    assert ("Cannot aggregate 2 file(s) that are not curves: " in said
            and "Give only curve files" in said and str(table) in said and str(sweep) in said)
    with pytest.raises(AggregationError, match=r"^cannot aggregate 1 file\(s\) that are not "
                                               r"curves: .*sweep.nc"):
        build_sweep([good, sweep])


def test_a_job_that_cannot_write_its_curve_says_so_in_one_line(tmp_path, monkeypatch, capfd):
    """A full disk at the curve's writing: the job's log and the terminal get
    one line naming the file and the cause, the job fails (status 1) and
    leaves no curve; no traceback."""
    import errno
    from types import SimpleNamespace

    from brushcore.data import simulate_job

    def full(curve, path):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
    monkeypatch.setattr("brushcore.data.io.write_curve", full)
    out, log = tmp_path / "curve.nc", tmp_path / "curve.log"
    smk = SimpleNamespace(
        output=[str(out)], log=[str(log)], threads=1,
        wildcards=SimpleNamespace(layout="regular", n_pillars="4", kbar="0.455", seed="0",
                                  grid="32", phi="0.12"),
        params=SimpleNamespace(layout_file="", rough={}, shape={}, solver={}),
        config={"allow_coarse": False, "backend": "cpu"})
    with pytest.raises(SystemExit) as stop:
        simulate_job.run_job(smk)
    assert stop.value.code == 1
    line = f"cannot write {out}: {os.strerror(errno.ENOSPC)}"
    assert line in log.read_text() and "Traceback" not in log.read_text()
    assert line in capfd.readouterr().err
    assert not out.exists()


def test_a_job_whose_cg_runs_out_of_iterations_names_the_config_key(tmp_path) -> None:
    """CG's "did not converge in N iterations" in a workflow job's log names
    the config key that allows more (the CLI's says --max-iter)."""
    from types import SimpleNamespace

    from brushcore.data import simulate_job

    out, log = tmp_path / "curve.nc", tmp_path / "curve.log"
    smk = SimpleNamespace(
        output=[str(out)], log=[str(log)], threads=1,
        wildcards=SimpleNamespace(layout="random", n_pillars="16", kbar="0.1", seed="3",
                                  grid="48", phi="0.12"),
        params=SimpleNamespace(layout_file="", rough={}, shape={}, solver={"max_iter": 1}),
        config={"allow_coarse": False, "backend": "cpu"})
    with pytest.raises(ConvergenceError):
        simulate_job.run_job(smk)
    said = log.read_text()
    assert "did not converge in 1 iterations" in said
    assert "the config's solver.max_iter raises the limit" in said
    assert not out.exists()


def test_the_code_that_ran_is_named_where_git_cannot(tmp_path, monkeypatch) -> None:
    """An installed wheel says "git unknown" and version 0.1.0 whatever it was
    built from (an installation helper's find: curves of two commits went
    through converge without a word): each curve records the SHA-256 of the
    package's Python files, which an edit anywhere changes, and a sweep of
    curves from two codes says so as it does for two commits."""
    import shutil

    import brushcore
    from brushcore import BrushParams, simulate
    from brushcore.data.aggregate import build_sweep, mixed_runs
    from brushcore.model import provenance

    digest = provenance.code_digest()
    curve = simulate(BrushParams("regular", 1, 1.0, 16))
    assert curve.attrs["code_sha256"] == digest and len(digest) == 64
    copy = tmp_path / "brushcore"
    shutil.copytree(Path(brushcore.__file__).parent, copy,
                    ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(provenance, "__file__", str(copy / "model/provenance.py"))
    assert provenance.code_digest.__wrapped__() == digest  # the same files, anywhere
    with open(copy / "numerics/linear/cg.py", "a") as fh:
        fh.write("\n# an edit\n")
    assert provenance.code_digest.__wrapped__() != digest
    other = curve.copy()
    other.attrs = {**curve.attrs, "code_sha256": "0" * 64, "kbar": 0.5, "parameter_hash": "x"}
    sweep = build_sweep([curve, other])
    assert "simulation_code_sha256" in mixed_runs(sweep)
    assert sweep.attrs["simulation_code_sha256"] == ", ".join(sorted([digest, "0" * 64]))


def test_a_workflow_running_another_brushcore_is_said_to(tmp_path) -> None:
    """A clone's workflow ran an older installed wheel through all its jobs
    without a word (an installation helper's find): planning says so where
    the brushcore that runs is not the checkout's and its code differs."""
    import shutil

    import brushcore
    from brushcore.model import provenance

    package = Path(brushcore.__file__).resolve().parent
    assert provenance.other_code(package.parent) == ""  # this checkout's own
    checkout = tmp_path / "clone"
    shutil.copytree(package, checkout / "brushcore", ignore=shutil.ignore_patterns("__pycache__"))
    assert provenance.other_code(checkout) == ""  # another copy of the same code
    with open(checkout / "brushcore/model/curve.py", "a") as fh:
        fh.write("\n# a later commit\n")
    said = provenance.other_code(checkout)
    assert said.startswith(f"the jobs run brushcore from {package} (code sha256 "
                           f"{provenance.code_digest()[:16]}), whose code differs from this "
                           f"checkout's {checkout / 'brushcore'}"), said
    assert provenance.other_code(tmp_path / "no checkout") == ""
