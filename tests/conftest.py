"""Shared helpers for the physics tests, and the opt-in for tests that change the system."""

from __future__ import annotations

import math
import os
import shutil
import tempfile

import pytest
from hypothesis import settings

from brushcore import BrushParams

# Property tests draw new seeds on every run, which is how they found brushes
# and round-off that broke two assertions.  Under CI (the CI variable, which
# .ci/run sets) they draw the same ones every time: a seed that breaks a test
# should be found by a developer's run and fixed, not fail someone's merge at
# random.
settings.register_profile("ci", derandomize=True)
if os.environ.get("CI", "").lower() not in ("", "0", "false"):
    settings.load_profile("ci")


#: The cache folder this run made (the controller's), removed at its end.
_OWN_CACHE: list[str] = []


def pytest_configure(config):
    """Keep the tests off the user's cache: FFTW wisdom and the FFT library
    answers go to a folder of this run (xdist workers inherit it through the
    environment), unless BRUSHCORE_WISDOM_DIR names one already."""
    if os.environ.get("BRUSHCORE_WISDOM_DIR") or hasattr(config, "workerinput"):
        return
    _OWN_CACHE.append(tempfile.mkdtemp(prefix="brushcore-tests-"))
    os.environ["BRUSHCORE_WISDOM_DIR"] = _OWN_CACHE[0]


def pytest_unconfigure(config):
    for path in _OWN_CACHE:
        shutil.rmtree(path, ignore_errors=True)


def full_contact_stiffness(ds) -> float:
    """Full-contact stiffness F/d from the first (linear) segment of a curve [E* h]."""
    return float(ds.force[1] / ds.displacement[1])


def punch_params(radius: float, kbar: float = math.inf, **kw) -> BrushParams:
    """One centred circular punch of the given radius [elements] on a snug grid."""
    n = int(math.ceil(2.6 * radius))
    n += n % 2  # even grid: the punch centre sits on an element corner, symmetric footprint
    return BrushParams("regular", 1, kbar, n, phi=math.pi * radius**2 / n**2, **kw)


@pytest.fixture
def punch():
    return punch_params


#: Most pytest-xdist workers `-n auto` starts: loadscope gives each a test
#: module, and a few modules take most of the time, so more workers only add
#: memory (each holds its modules' curves and sweeps).
MAX_WORKERS = 8


def pytest_xdist_auto_num_workers(config):
    """Workers for `-n auto`: the CPUs this process may use, within a
    container's CPU quota (cgroup v2 ``cpu.max``, which os.cpu_count() does
    not see), at most MAX_WORKERS."""
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    try:
        with open("/sys/fs/cgroup/cpu.max") as fh:
            quota, period = fh.read().split()[:2]
        if quota != "max":
            cpus = min(cpus or 1, max(1, math.ceil(int(quota) / int(period))))
    except (OSError, ValueError):
        pass
    return max(1, min(cpus or 1, MAX_WORKERS))


#: The Slurm test installs Debian packages (slurm-wlm, munge) and starts daemons:
#: it runs only when asked for (CI asks, see .ci/run).
SLURM_OPT_IN = "BRUSHCORE_SLURM_TESTS"


def pytest_collection_modifyitems(config, items):
    if os.environ.get(SLURM_OPT_IN) == "1":
        return
    skip = pytest.mark.skip(reason=f"opt-in: set {SLURM_OPT_IN}=1 to install slurm-wlm and "
                                   "munge with apt and run the sweep through a one-node Slurm")
    for item in items:
        if "slurm" in item.keywords:
            item.add_marker(skip)
