"""Provenance facts recorded beside generated tables: the commit, whether the checkout was dirty, the
date, library versions and the machine (the volatile part of a ``*.meta.json`` / ``provenance.json``)."""
from __future__ import annotations

import datetime as _dt
import os
import platform
import subprocess
from pathlib import Path
from typing import Sequence

__all__ = ["run_facts"]


def _git(root: Path, *args: str) -> str:
    try:
        return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def run_facts(modules: Sequence[str] = ("numpy", "flint")) -> dict:
    """``date``, ``commit``, ``worktree_dirty``, ``versions`` (Python and the given modules; None when one is
    not installed) and ``machine`` of this run, read from the source checkout holding ``analysis/``."""
    root = Path(__file__).resolve().parents[2]
    versions = {"python": platform.python_version()}
    for module in modules:
        try:
            versions[module] = getattr(__import__(module), "__version__", "?")
        except ImportError:
            versions[module] = None
    return {
        "date": _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat(),
        "commit": _git(root, "rev-parse", "HEAD"),
        "worktree_dirty": bool(_git(root, "status", "--porcelain")),
        "versions": versions,
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
    }
