"""The test sweep runs through a real one-node Slurm and matches a local run.

Marker ``slurm``; needs Linux, root and apt-get (Debian's slurm-wlm and munge
are installed on first use), skipped with the reason printed otherwise.
Run it alone with::

    pytest -m slurm -s tests/test_slurm.py

Steps: copy the repository twice into ``tmp_path`` (without results/ and
.snakemake/); run ``snakemake --cores 2 --configfile config/test.yaml`` in
one copy; start munged, slurmctld and slurmd (tests/slurm_cluster.py); run
``snakemake --profile workflow/profiles/slurm --configfile config/test.yaml``
in the other; check that every simulation ran inside a Slurm job whose id
Slurm knows; compare the two ``results/sweep.nc``; stop the daemons by PID.

``BRUSHCORE_SLURM_WORKFLOW`` may name another workflow directory to copy
instead of the repository (used to develop the harness on a toy workflow).
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from slurm_cluster import log, one_node_slurm, skip_reason  # noqa: E402

pytestmark = pytest.mark.slurm

REPO = Path(__file__).resolve().parents[1]
WORKFLOW = Path(os.environ.get("BRUSHCORE_SLURM_WORKFLOW", REPO))
CONFIG = "config/test.yaml"
PROFILE = "workflow/profiles/slurm"
SWEEP = Path("results/sweep.nc")
SIM_RULE = "simulate"
# "rule simulate:" / "localrule simulate:" followed by its first output file
SIM_OUTPUT = rf"^\s*(?:local)?rule {SIM_RULE}:\n\s+output: ([^\n,]+)"
TIMEOUT_LOCAL = 900  # s
TIMEOUT_SLURM = 1200  # s
COPY_IGNORE = shutil.ignore_patterns(
    "results",
    ".snakemake",
    "logs",
    "__pycache__",
    ".pytest_cache",
    ".hypothesis",
    "*.egg-info",
    "build",
    "out",
    "report.html",
)
# provenance / timing: differ between two runs by design
IGNORED_VARIABLES = re.compile(r"wall|time_s$|history|git_commit|hostname|date")
# integer-valued even where NaN padding made them float: must agree exactly
EXACT_VARIABLES = {
    "events",
    "n_steps",
    "attached_pillars",
    "detachment_step",
    "snapshot_step",
    "contact_snapshot",
}


def _say(capsys, msg: str) -> None:
    """Print to the real stdout, also when pytest captures output."""
    with capsys.disabled():
        print(f"\n[test_slurm] {msg}", flush=True)


def _copy_workflow(dest: Path) -> Path:
    shutil.copytree(WORKFLOW, dest, ignore=COPY_IGNORE, symlinks=True)
    if WORKFLOW != REPO:  # always test this repository's profile
        shutil.copytree(REPO / PROFILE, dest / PROFILE, dirs_exist_ok=True)
    return dest


def _run_snakemake(args: list[str], cwd: Path, logfile: Path, timeout: float):
    """Run snakemake in its own process group; SIGKILL the group on timeout.

    A hung Snakemake ignores SIGTERM, hence SIGKILL.  Returns (returncode,
    wall seconds, combined output).
    """
    env = {k: v for k, v in os.environ.items() if not k.startswith("SLURM_")}
    cmd = [sys.executable, "-m", "snakemake", *args]
    log(f"running in {cwd}: {' '.join(cmd)}")
    t0 = time.monotonic()
    with open(logfile, "wb") as out:
        proc = subprocess.Popen(
            cmd,
            cwd=cwd,
            stdout=out,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            env=env,
            start_new_session=True,
        )
        try:
            rc = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            rc = None
        finally:
            # nothing of this run may outlive it (e.g. a stuck sbatch/squeue)
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    wall = time.monotonic() - t0
    return rc, wall, logfile.read_text(errors="replace")


def _tail(text: str, n: int = 80) -> str:
    return "\n".join(text.splitlines()[-n:])


def _assert_same_sweep(slurm_nc: Path, local_nc: Path) -> None:
    """Same variables and coordinates, same numbers; attributes ignored."""
    import xarray as xr

    with xr.open_dataset(slurm_nc) as a, xr.open_dataset(local_nc) as b:
        a, b = a.load(), b.load()
    assert set(a.data_vars) == set(b.data_vars), "different variables"
    assert set(a.coords) == set(b.coords), "different coordinates"
    assert dict(a.sizes) == dict(b.sizes), "different dimensions"
    for name in a.coords:
        xr.testing.assert_equal(
            a[name].reset_coords(drop=True), b[name].reset_coords(drop=True)
        )
    compared, bitwise = [], []
    for name in sorted(a.data_vars):
        if IGNORED_VARIABLES.search(name):
            continue
        va, vb = a[name].copy(), b[name].copy()
        va.attrs, vb.attrs = {}, {}
        compared.append(name)
        if va.equals(vb):
            bitwise.append(name)
            continue
        if va.dtype.kind in "fc" and name not in EXACT_VARIABLES:
            # the same code on the same machine; FFTW may pick different
            # plans in the two runs, hence a tolerance of a few ulps
            xr.testing.assert_allclose(va, vb, rtol=1e-9, atol=1e-12)
        else:
            # integers, strings, counts, the detachment sequence: exactly equal
            xr.testing.assert_equal(va, vb)
    assert compared, "no variables compared"
    log(
        f"sweep.nc: {len(compared)} variables agree ({len(bitwise)} bit for bit): "
        + ", ".join(compared)
    )


def _simulate_outputs_in_slurm_logs(slurm_logs: Path) -> dict[str, set[str]]:
    """Map Slurm job id -> outputs of simulate jobs run inside that job."""
    found: dict[str, set[str]] = {}
    for lf in slurm_logs.rglob("*.log"):
        text = lf.read_text(errors="replace")
        outs = set(re.findall(SIM_OUTPUT, text, re.M))
        found.setdefault(lf.stem.split("_")[0], set()).update(outs)
    return found


@pytest.fixture(scope="module")
def skip_unless_possible():
    reason = skip_reason()
    if reason is None:
        try:
            import snakemake_executor_plugin_slurm  # noqa: F401
        except ImportError:
            reason = "snakemake-executor-plugin-slurm is not installed"
    if reason is None and not (WORKFLOW / "Snakefile").exists():
        reason = f"no Snakefile in {WORKFLOW}"
    if reason:
        print(f"\n[test_slurm] SKIPPED: {reason}", file=sys.__stdout__, flush=True)
        pytest.skip(reason)


def test_sweep_through_slurm_matches_local(
    tmp_path, capsys, record_property, skip_unless_possible
):
    t_test = time.monotonic()

    # --- the reference: a local run -----------------------------------------
    local = _copy_workflow(tmp_path / "local")
    rc, wall_local, out_local = _run_snakemake(
        ["--cores", "2", "--configfile", CONFIG],
        local,
        tmp_path / "local.log",
        TIMEOUT_LOCAL,
    )
    _say(capsys, f"local run (--cores 2): {wall_local:.1f} s wall")
    assert rc == 0, f"local run failed (rc={rc}):\n{_tail(out_local)}"
    assert (local / SWEEP).exists()

    # --- the same through Slurm ---------------------------------------------
    remote = _copy_workflow(tmp_path / "slurm")
    with one_node_slurm(workdir=tmp_path / "slurm-state") as cluster:
        rc, wall_slurm, out = _run_snakemake(
            ["--profile", PROFILE, "--configfile", CONFIG],
            remote,
            tmp_path / "slurm.log",
            TIMEOUT_SLURM,
        )
        _say(capsys, f"slurm run (--profile {PROFILE}): {wall_slurm:.1f} s wall")
        if rc != 0:
            pytest.fail(
                f"slurm run failed (rc={rc}, None = killed after "
                f"{TIMEOUT_SLURM} s):\n{_tail(out)}\n--- squeue\n{cluster.squeue()}"
                f"\n{cluster.logs()}"
            )

        # job ids snakemake says it got from sbatch
        submitted = sorted(
            set(re.findall(r"submitted with SLURM jobid (\d+)", out)), key=int
        )
        assert submitted, f"no Slurm submission in the log:\n{_tail(out)}"
        # ... are jobs that Slurm itself ran to completion
        squeue = subprocess.run(
            ["squeue", "--states=all", "-h", "-o", "%i|%j|%T"],
            capture_output=True,
            text=True,
            timeout=30,
            check=True,
        ).stdout
        states = {
            line.split("|")[0]: line.split("|")[2] for line in squeue.splitlines()
        }
        for jid in submitted:
            assert (
                states.get(jid) == "COMPLETED"
            ), f"Slurm job {jid}: state {states.get(jid)!r}\n{squeue}"
        _say(capsys, f"Slurm job ids of the simulate bundles: {', '.join(submitted)}")
        _say(capsys, "squeue --states=all:\n" + cluster.squeue())

    # every simulation ran inside one of those Slurm jobs, none locally
    assert not re.search(
        rf"^\s*localrule {SIM_RULE}:", out, re.M
    ), "a simulate job ran on the submit host"
    in_slurm = _simulate_outputs_in_slurm_logs(remote / ".snakemake" / "slurm_logs")
    assert set(in_slurm) <= set(submitted) | {""}, (in_slurm.keys(), submitted)
    ran_in_slurm = set().union(*in_slurm.values()) if in_slurm else set()
    expected = set(re.findall(SIM_OUTPUT, out_local, re.M))
    assert expected, "the local run had no simulate jobs?"
    assert (
        ran_in_slurm == expected
    ), f"simulations not seen in Slurm job logs: {sorted(expected - ran_in_slurm)}"
    _say(
        capsys, f"{len(ran_in_slurm)} simulate jobs ran in {len(submitted)} Slurm jobs"
    )

    # --- same numbers ---------------------------------------------------------
    _assert_same_sweep(remote / SWEEP, local / SWEEP)

    total = time.monotonic() - t_test
    record_property("wall_local_s", round(wall_local, 1))
    record_property("wall_slurm_s", round(wall_slurm, 1))
    record_property("slurm_job_ids", " ".join(submitted))
    _say(
        capsys,
        f"WALL TIMES: slurm run {wall_slurm:.1f} s, local run {wall_local:.1f} s, "
        f"whole test incl. Slurm start/stop {total:.1f} s",
    )
