"""Provenance: which code and which parameters produced a result."""

from __future__ import annotations

import hashlib
import json
import subprocess
from functools import lru_cache
from importlib import metadata
from pathlib import Path


@lru_cache(maxsize=1)
def version() -> str:
    """Installed brushcore version."""
    try:
        return metadata.version("brushcore")
    except metadata.PackageNotFoundError:  # running from a source tree
        return "0+unknown"


@lru_cache(maxsize=1)
def git_commit() -> str:
    """Commit of the source tree brushcore runs from ("+dirty" if anything in
    the package is modified), or "unknown"."""
    here = Path(__file__).resolve().parents[1]  # the package, not this module's folder
    try:
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=here, capture_output=True,
                             text=True, timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", str(here)], cwd=here,
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return sha + ("+dirty" if dirty else "")


def parameter_hash(*parts: dict) -> str:
    """Short stable hash of parameter dictionaries (sorted JSON, SHA-256)."""
    text = json.dumps(parts, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:16]
