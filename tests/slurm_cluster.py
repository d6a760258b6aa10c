"""A throw-away one-node Slurm cluster on 127.0.0.1, for tests.

``one_node_slurm()`` is a context manager that

1. installs Debian's ``slurm-wlm`` and ``munge`` with apt-get unless their
   binaries are already present (services are kept from auto-starting during
   the install by a temporary ``policy-rc.d`` if the system has none);
2. writes a cgroup-free one-node ``/etc/slurm/slurm.conf`` (an existing file
   is moved aside and restored afterwards).  The file must live at that
   path: the Snakemake job-step plugin strips ``SLURM_*`` variables before
   its inner ``srun``, so ``SLURM_CONF`` would be lost inside jobs;
3. makes sure a munge key exists and the socket directory ``/run/munge``
   has mode 0711 (munged refuses 0700), then starts ``munged`` unless one
   already answers on the default socket;
4. starts ``slurmctld`` and ``slurmd`` in the foreground (``-D``) so that the
   PIDs we hold are the daemons' own, and waits until ``sinfo`` reports the
   node idle;
5. on exit cancels the jobs left in the queue, stops exactly the daemons it
   started, by PID (SIGTERM, then SIGKILL after a grace period), restores
   ``/etc/slurm/slurm.conf`` and removes what it created.

No accounting database is configured, so ``sacct`` cannot see jobs; use
``squeue`` for job status (``MinJobAge`` is set to 300 s, which satisfies
the executor plugin's rule ``MinJobAge >= 3 x init-seconds-before-status-checks``
for any init interval up to 100 s).

Requires Linux, root and apt-get.  ``skip_reason()`` says why the cluster
cannot be built here (``None`` when it can).

Run ``python tests/slurm_cluster.py`` to start a cluster, print ``sinfo`` and
tear it down again.
"""

from __future__ import annotations

import contextlib
import os
import platform
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

SLURM_CONF = Path("/etc/slurm/slurm.conf")
MUNGE_KEY = Path("/etc/munge/munge.key")
MUNGE_SOCKET_DIR = Path("/run/munge")
PACKAGES = ("slurm-wlm", "munge")
BINARIES = (
    "munged",
    "munge",
    "unmunge",
    "slurmctld",
    "slurmd",
    "sbatch",
    "srun",
    "squeue",
    "sinfo",
    "scontrol",
    "scancel",
)
SLURMCTLD_PORT = 6817
SLURMD_PORT = 6818
PARTITION = "debug"
MIN_JOB_AGE = 300  # seconds; the Slurm default, kept explicit on purpose
CONF_MARKER = "# one-node test cluster written by brushcore tests/slurm_cluster.py"
BACKUP_PREFIX = "slurm.conf.brushcore-backup-"


def log(msg: str) -> None:
    """Print a harness message (visible with ``pytest -s`` and in CI logs).

    Goes to the process's real stdout, past pytest's ``capsys`` (the fd-level
    capture still shows it on failure), so that it interleaves correctly
    with the test's own progress lines.
    """
    out = sys.__stdout__ or sys.stdout
    print(f"[slurm-cluster] {msg}", file=out, flush=True)


def skip_reason() -> str | None:
    """Why a local Slurm cannot be built on this machine, or ``None``."""
    if platform.system() != "Linux":
        return f"needs Linux (this is {platform.system()})"
    if os.geteuid() != 0:
        return "needs root (to install slurm-wlm/munge and run the daemons)"
    if shutil.which("apt-get") is None and not binaries_present():
        return "needs apt-get (Debian/Ubuntu) to install slurm-wlm and munge"
    return None


def binaries_present() -> bool:
    return all(shutil.which(b) for b in BINARIES)


def _run(cmd, check=True, timeout=120, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(
        cmd, check=check, timeout=timeout, text=True, capture_output=True, **kw
    )


# --------------------------------------------------------------------------
# installation
# --------------------------------------------------------------------------
def install_packages(timeout: float = 900) -> bool:
    """Install slurm-wlm and munge with apt-get unless already present.

    Returns True when something was installed.  Idempotent.
    """
    if binaries_present():
        log("slurm-wlm and munge already installed; skipping apt-get")
        return False
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    policy = Path("/usr/sbin/policy-rc.d")
    made_policy = False
    if not policy.exists():
        # keep the packages' postinst scripts from starting daemons that we
        # would then not own
        policy.write_text("#!/bin/sh\nexit 101\n")
        policy.chmod(0o755)
        made_policy = True
    try:
        t0 = time.monotonic()
        cmd = ["apt-get", "install", "-y", "-q", "--no-install-recommends", *PACKAGES]
        r = subprocess.run(
            cmd, env=env, text=True, capture_output=True, timeout=timeout
        )
        if r.returncode != 0:
            log("apt-get install failed; running apt-get update and retrying")
            subprocess.run(
                ["apt-get", "update", "-q"],
                env=env,
                check=True,
                timeout=timeout,
                capture_output=True,
            )
            r = subprocess.run(
                cmd, env=env, text=True, capture_output=True, timeout=timeout
            )
        if r.returncode != 0:
            raise RuntimeError(
                f"apt-get install {' '.join(PACKAGES)} failed:\n{r.stdout}\n{r.stderr}"
            )
        log(f"installed {' '.join(PACKAGES)} in {time.monotonic() - t0:.1f} s")
    finally:
        if made_policy:
            policy.unlink(missing_ok=True)
    if not binaries_present():
        missing = [b for b in BINARIES if not shutil.which(b)]
        raise RuntimeError(f"still missing after install: {missing}")
    return True


# --------------------------------------------------------------------------
# configuration
# --------------------------------------------------------------------------
def detect_node() -> dict[str, int]:
    """CPU layout and memory as slurmd sees them (``slurmd -C``)."""
    out = _run(["slurmd", "-C"]).stdout
    fields = dict(re.findall(r"(\w+)=(\S+)", out.splitlines()[0]))
    node = {
        k: int(fields[k])
        for k in (
            "CPUs",
            "SocketsPerBoard",
            "CoresPerSocket",
            "ThreadsPerCore",
            "RealMemory",
        )
        if k in fields
    }
    return node


def slurm_conf_text(nodename: str, statedir: Path, node: dict[str, int]) -> str:
    """A cgroup-free one-node configuration (fits a container)."""
    mem = node["RealMemory"]
    # leave a margin, else slurmd reports less than configured and the node
    # is drained ("Low RealMemory")
    real_memory = max(256, mem - max(512, mem // 10))
    cpu = (
        f"CPUs={node['CPUs']} Sockets={node.get('SocketsPerBoard', 1)} "
        f"CoresPerSocket={node.get('CoresPerSocket', node['CPUs'])} "
        f"ThreadsPerCore={node.get('ThreadsPerCore', 1)}"
    )
    return f"""\
{CONF_MARKER}
# (temporary: the original file, if any, is restored on teardown)
ClusterName=brushcore-test
SlurmctldHost={nodename}(127.0.0.1)
SlurmctldPort={SLURMCTLD_PORT}
SlurmdPort={SLURMD_PORT}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
StateSaveLocation={statedir}/ctld
SlurmdSpoolDir={statedir}/spool
SlurmctldPidFile={statedir}/slurmctld.pid
SlurmdPidFile={statedir}/slurmd.pid
SlurmctldLogFile={statedir}/slurmctld.log
SlurmdLogFile={statedir}/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
# no cgroups in a container
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
# no slurmdbd: sacct cannot see jobs, use squeue for status
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
MpiDefault=none
ReturnToService=2
# finished jobs stay visible to squeue this long
MinJobAge={MIN_JOB_AGE}
# jobs submitted without --mem must not take the whole node
DefMemPerCPU=1000
SchedulerParameters=sched_interval=2
SlurmctldTimeout=30
SlurmdTimeout=60
InactiveLimit=0
KillWait=5
Waittime=0
NodeName={nodename} NodeAddr=127.0.0.1 {cpu} RealMemory={real_memory} State=UNKNOWN
PartitionName={PARTITION} Nodes={nodename} Default=YES MaxTime=INFINITE State=UP
"""


def _is_ours(path: Path) -> bool:
    try:
        return path.read_text(errors="replace").startswith(CONF_MARKER)
    except OSError:
        return False


# --------------------------------------------------------------------------
# processes
# --------------------------------------------------------------------------
def _port_in_use(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("0.0.0.0", port))
        except OSError:
            return True
    return False


def munge_works() -> bool:
    try:
        cred = subprocess.run(
            ["munge", "-n"], capture_output=True, timeout=10, check=True
        ).stdout
        subprocess.run(
            ["unmunge"], input=cred, capture_output=True, timeout=10, check=True
        )
        return True
    except (subprocess.SubprocessError, OSError):
        return False


def stop_pid(proc: subprocess.Popen, name: str, grace: float = 10.0) -> None:
    """SIGTERM the process we started, SIGKILL it after ``grace`` seconds."""
    if proc.poll() is not None:
        log(f"{name} (pid {proc.pid}) had already exited with {proc.returncode}")
        return
    log(f"stopping {name} (pid {proc.pid})")
    with contextlib.suppress(ProcessLookupError):
        os.kill(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=grace)
    except subprocess.TimeoutExpired:
        log(f"{name} (pid {proc.pid}) ignored SIGTERM; sending SIGKILL")
        with contextlib.suppress(ProcessLookupError):
            os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)


@dataclass
class SlurmCluster:
    """Handle on the running cluster."""

    nodename: str
    partition: str
    statedir: Path
    pids: dict[str, int] = field(default_factory=dict)

    def sinfo(self) -> str:
        return _run(["sinfo", "-N", "-l"], check=False).stdout

    def squeue(self) -> str:
        fmt = "%.8i %.9P %.10j %.6C %.10l %.8m %.10T %.10M %R"
        return _run(["squeue", "--states=all", "-o", fmt], check=False).stdout

    def logs(self, tail: int = 40) -> str:
        parts = []
        for name in ("slurmctld.log", "slurmd.log", "munged.out"):
            p = self.statedir / name
            if p.exists():
                lines = p.read_text(errors="replace").splitlines()[-tail:]
                parts.append(f"--- {p} (last {tail} lines)\n" + "\n".join(lines))
        return "\n".join(parts)


@contextlib.contextmanager
def one_node_slurm(
    workdir: Path | None = None, start_timeout: float = 60.0, keep_state: bool = False
) -> Iterator[SlurmCluster]:
    """Install, configure and run a one-node Slurm; tear it all down on exit.

    Parameters
    ----------
    workdir
        Where state, spool and daemon logs go (a fresh temporary directory
        when ``None``; that one is removed on exit unless ``keep_state``).
    start_timeout
        Seconds to wait for the node to become idle.
    """
    reason = skip_reason()
    if reason:
        raise RuntimeError(f"cannot run a local Slurm: {reason}")
    install_packages()

    for port in (SLURMCTLD_PORT, SLURMD_PORT):
        if _port_in_use(port):
            raise RuntimeError(
                f"port {port} is in use: another slurmctld/slurmd is running; "
                "refusing to interfere with it"
            )

    own_tmp = workdir is None
    statedir = (
        Path(tempfile.mkdtemp(prefix="brushcore-slurm-")) if own_tmp else Path(workdir)
    )
    statedir.mkdir(parents=True, exist_ok=True)
    for sub in ("ctld", "spool"):
        (statedir / sub).mkdir(exist_ok=True)
    nodename = socket.gethostname().split(".")[0]

    started: list[tuple[str, subprocess.Popen]] = []
    open_files = []
    backup: Path | None = None
    wrote_conf = False
    created_key = False
    created_sockdir = False
    cluster = SlurmCluster(nodename=nodename, partition=PARTITION, statedir=statedir)

    def start(name: str, cmd: list[str], **kw) -> subprocess.Popen:
        out = open(statedir / f"{name}.out", "wb")
        open_files.append(out)
        proc = subprocess.Popen(
            cmd,
            stdout=out,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
            **kw,
        )
        started.append((name, proc))
        cluster.pids[name] = proc.pid
        log(f"started {name} (pid {proc.pid}): {' '.join(cmd)}")
        return proc

    try:
        # --- slurm.conf ------------------------------------------------------
        SLURM_CONF.parent.mkdir(parents=True, exist_ok=True)
        orphans = sorted(SLURM_CONF.parent.glob(BACKUP_PREFIX + "*"))
        if _is_ours(SLURM_CONF) and len(orphans) == 1:
            # a previous run died before restoring: its backup is the original
            backup = orphans[0]
            log(f"found {SLURM_CONF} of a crashed run; will restore {backup}")
        elif SLURM_CONF.exists() or SLURM_CONF.is_symlink():
            if _is_ours(SLURM_CONF):
                log(f"found {SLURM_CONF} of a crashed run; will remove it")
            else:
                backup = SLURM_CONF.with_name(f"{BACKUP_PREFIX}{os.getpid()}")
                os.replace(SLURM_CONF, backup)
                log(f"moved existing {SLURM_CONF} to {backup}")
        SLURM_CONF.write_text(slurm_conf_text(nodename, statedir, detect_node()))
        wrote_conf = True
        log(f"wrote {SLURM_CONF} (node {nodename}, partition {PARTITION})")

        # --- munge -----------------------------------------------------------
        if munge_works():
            log("a munged already answers on the default socket; reusing it")
        else:
            import grp
            import pwd

            uid = pwd.getpwnam("munge").pw_uid
            gid = grp.getgrnam("munge").gr_gid
            if not MUNGE_KEY.exists():
                MUNGE_KEY.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
                os.chown(MUNGE_KEY.parent, uid, gid)
                MUNGE_KEY.write_bytes(os.urandom(1024))
                created_key = True
                log(f"created munge key {MUNGE_KEY}")
            os.chown(MUNGE_KEY, uid, gid)
            MUNGE_KEY.chmod(0o400)
            if not MUNGE_SOCKET_DIR.exists():
                MUNGE_SOCKET_DIR.mkdir(parents=True)
                created_sockdir = True
            os.chown(MUNGE_SOCKET_DIR, uid, gid)
            MUNGE_SOCKET_DIR.chmod(0o711)  # 0700 is refused by munged
            for d in (Path("/var/lib/munge"), Path("/var/log/munge")):
                d.mkdir(parents=True, exist_ok=True)
                os.chown(d, uid, gid)
            start("munged", ["munged", "--foreground", "--force"], user=uid, group=gid)
            deadline = time.monotonic() + 20
            while not munge_works():
                if started[-1][1].poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError("munged did not come up:\n" + cluster.logs())
                time.sleep(0.2)
            log("munge works")

        # --- slurm daemons -----------------------------------------------------
        start("slurmctld", ["slurmctld", "-D", "-i"])
        time.sleep(0.5)
        start("slurmd", ["slurmd", "-D", "-N", nodename])
        deadline = time.monotonic() + start_timeout
        state = ""
        while True:
            for name, proc in started:
                if proc.poll() is not None:
                    raise RuntimeError(
                        f"{name} exited with {proc.returncode} during start-up\n"
                        + cluster.logs()
                    )
            r = _run(["sinfo", "-h", "-N", "-o", "%N %T"], check=False, timeout=15)
            state = r.stdout.strip()
            if r.returncode == 0 and re.search(
                rf"^{re.escape(nodename)} idle\b", state, re.M
            ):
                break
            if time.monotonic() > deadline:
                raise RuntimeError(
                    f"node not idle after {start_timeout} s (sinfo: {state!r} "
                    f"{r.stderr.strip()!r})\n"
                    + _run(["sinfo", "-R"], check=False).stdout
                    + cluster.logs()
                )
            time.sleep(0.5)
        log(f"node idle: {state}")
        yield cluster
    finally:
        # cancel whatever is still queued/running so no slurmstepd outlives us
        if any(n == "slurmctld" and p.poll() is None for n, p in started):
            ids = _run(
                ["squeue", "-h", "-o", "%i"], check=False, timeout=15
            ).stdout.split()
            if ids:
                log(f"cancelling leftover jobs {ids}")
                _run(["scancel", *ids], check=False, timeout=30)
                deadline = time.monotonic() + 20
                while time.monotonic() < deadline:
                    left = _run(
                        ["squeue", "-h", "-t", "PD,R,CG,CF,S", "-o", "%i"],
                        check=False,
                        timeout=15,
                    ).stdout.split()
                    if not left:
                        break
                    time.sleep(0.5)
        for name, proc in reversed(started):
            try:
                stop_pid(proc, name)
            except Exception as e:  # keep tearing down the rest
                log(f"could not stop {name} (pid {proc.pid}): {e}")
        for f in open_files:
            f.close()
        if wrote_conf:
            SLURM_CONF.unlink(missing_ok=True)
        if backup is not None:
            os.replace(backup, SLURM_CONF)
            log(f"restored {SLURM_CONF}")
        elif wrote_conf:
            log(f"removed {SLURM_CONF}")
        if created_key:
            MUNGE_KEY.unlink(missing_ok=True)
        if created_sockdir:
            shutil.rmtree(MUNGE_SOCKET_DIR, ignore_errors=True)
        if own_tmp and not keep_state:
            shutil.rmtree(statedir, ignore_errors=True)


if __name__ == "__main__":  # manual smoke test
    why = skip_reason()
    if why:
        sys.exit(f"skipped: {why}")
    t0 = time.monotonic()
    with one_node_slurm() as c:
        print(c.sinfo())
        r = _run(["srun", "-N1", "-n1", "hostname"], check=False, timeout=60)
        print("srun:", r.returncode, r.stdout.strip(), r.stderr.strip())
    print(f"total {time.monotonic() - t0:.1f} s")
