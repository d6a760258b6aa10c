"""Provenance: which code and which parameters produced a result."""

from __future__ import annotations

import hashlib
import json
import subprocess
import tomllib
from functools import lru_cache
from importlib import metadata
from pathlib import Path


def _brushcore_project(pyproject: Path) -> dict | None:
    """The ``[project]`` table of ``pyproject`` where it is brushcore's own (a
    source tree, not another project brushcore is installed in), else None."""
    try:
        project = tomllib.loads(pyproject.read_text())["project"]
    except (OSError, KeyError, TypeError, tomllib.TOMLDecodeError):
        return None
    return project if project.get("name") == "brushcore" and "version" in project else None


@lru_cache(maxsize=1)
def version() -> str:
    """Version of the brushcore that runs: its source tree's ``pyproject.toml``
    where it runs from one (a clone on PYTHONPATH beside another installed
    copy reported that copy's), else the installed distribution's."""
    project = _brushcore_project(Path(__file__).resolve().parents[2] / "pyproject.toml")
    if project is not None:
        return str(project["version"])
    try:
        return metadata.version("brushcore")
    except metadata.PackageNotFoundError:
        return "0+unknown"


@lru_cache(maxsize=1)
def git_commit() -> str:
    """Commit of the source tree brushcore runs from ("+dirty" if anything in
    the package is modified), or "unknown"."""
    here = Path(__file__).resolve().parents[1]  # the package, not this module's folder
    if _brushcore_project(here.parent / "pyproject.toml") is None:
        return "unknown"  # installed (in site-packages, maybe inside another repository)
    try:
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True,
                             text=True, timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", str(here)], cwd=here,
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return sha + ("+dirty" if dirty else "")


@lru_cache(maxsize=1)
def code_digest() -> str:
    """SHA-256 over the package's Python files (their paths and bytes): the
    code that ran, named where git cannot (an installed wheel reports "git
    unknown" and version 0.1.0 whatever commit it was built from)."""
    return package_digest(Path(__file__).resolve().parents[1])


def package_digest(root: Path) -> str:
    """`code_digest` of the package folder ``root`` (a checkout's brushcore/)."""
    h = hashlib.sha256()
    for path in sorted(Path(root).rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def other_code(checkout: Path) -> str:
    """Where the brushcore that runs is not ``checkout``'s brushcore/ and its
    code differs, what to say ("" otherwise): a clone's workflow ran an older
    installed wheel through all its jobs without a word (an installation
    helper's find)."""
    mine = Path(checkout) / "brushcore"
    running = Path(__file__).resolve().parents[1]
    if not mine.is_dir() or running == mine.resolve() or package_digest(mine) == code_digest():
        return ""
    return (f"the jobs run brushcore from {running} (code sha256 {code_digest()[:16]}), whose "
            f"code differs from this checkout's {mine} ({package_digest(mine)[:16]}): "
            "install the checkout (pip install -e .) or put it on PYTHONPATH to run its code")


def source() -> str:
    """CF's ``source`` attribute: the software, commit and code digest that made a file."""
    return f"brushcore {version()} (git {git_commit()}, code sha256 {code_digest()[:16]})"


#: The libraries a curve's numbers pass through (MKL's FFT and spmv where
#: installed; CuPy under the name of the wheel the gpu extra installs).
SOFTWARE = ("numpy", "scipy", "pyfftw", "mkl_fft", "mkl", "xarray", "netCDF4", "cupy",
            "cupy-cuda12x", "cupy-cuda11x", "cupy-cuda13x")


@lru_cache(maxsize=1)
def software_versions() -> str:
    """Python's and the installed `SOFTWARE` packages' versions, as
    "python 3.11.7, numpy 2.4.6, ..." (packages not installed are left out),
    for a methods section."""
    import platform

    found = [f"python {platform.python_version()}"]
    for name in SOFTWARE:
        try:
            found.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            continue
    return ", ".join(found)


def parameter_hash(*parts: dict) -> str:
    """Short stable hash of parameter dictionaries (sorted JSON, SHA-256)."""
    text = json.dumps(parts, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:16]
