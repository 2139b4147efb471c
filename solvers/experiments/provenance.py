"""Provenance of the experiment artefacts: commit, date, versions, machine, threads.

Owns the record of one run (`provenance`) and ``tables/experiments_provenance.json``, merged per
artefact so that regenerating one leaves the others' sections intact (`update_provenance`).
"""
from __future__ import annotations

import datetime as _dt
import importlib
import json
import os
import platform
import subprocess
from collections.abc import Iterable
from pathlib import Path

from analysis.complexity import THREAD_VARIABLES
from analysis.paths import same_json_apart_from, write_if_changed

from .config import PROVENANCE_PATH, ROOT

VOLATILE_PROVENANCE = ("updated", "date", "commit", "worktree_dirty", "versions", "machine", "threads", "wall_seconds",
                       "load_average_at_end", "seconds", "jobs", "computed_now", "cache_hits",
                       "compute_seconds_when_computed")
"""Keys of experiments_provenance.json that change without the results changing (a rerun from the
caches differs from the computing run only in these)."""



def package_version(module: str) -> str:
    try:
        from importlib.metadata import version

        return version(module)
    except Exception:
        try:
            return str(importlib.import_module(module).__version__)
        except Exception:
            return "unavailable"


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True, timeout=10).stdout.strip()
    except Exception:
        return ""


def provenance(**extra: object) -> dict:
    """Return the provenance record of an experiment run: commit, date, versions, machine, threads.

    Keyword arguments are merged in (seeds, trials, sigmas, options, wall times...).
    """
    status = _git("status", "--porcelain")
    record = {
        "date": _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat(),
        "commit": _git("rev-parse", "HEAD") or "unknown",
        "worktree_dirty": bool(status),
        "versions": {
            "python": platform.python_version(),
            **{name: package_version(name) for name in ("numpy", "scipy", "pandas", "matplotlib")},
        },
        "machine": {"platform": platform.platform(), "processor": platform.machine(), "cpus": os.cpu_count()},
        "threads": {name: os.environ.get(name, "") for name in THREAD_VARIABLES},
    }
    record.update(extra)
    return record


def update_provenance(sections: dict[str, dict], path: Path = PROVENANCE_PATH) -> None:
    """Merge per-artefact provenance records into ``experiments_provenance.json``.

    One section per artefact ("table4", "fig1", "fig2", "reproduce"), so that a script
    regenerating one artefact leaves the record of the others intact.
    """
    record: dict = {}
    timing = path.with_name(path.stem + ".timing.json")  # the full record of the last run (untracked)
    # the timing file holds the last run's full record, unless the tracked file is newer (a checkout or merge
    # brought another run's record): merging into a stale one would rewrite the tracked file for nothing
    source = timing if timing.exists() and (not path.exists() or timing.stat().st_mtime >= path.stat().st_mtime) else path
    if source.exists():
        try:
            record = json.loads(source.read_text())
        except json.JSONDecodeError:
            record = {}
    record.setdefault("artefacts", {}).update(sections)
    record["updated"] = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    record["description"] = (
        "Provenance of tables/table4.{csv,md,tex} and tables/figures/fig1_*, fig2_* "
        "(solvers.experiments); one section per artefact."
    )
    text = json.dumps(record, indent=2, default=str) + "\n"
    write_if_changed(path, text, same_json_apart_from(VOLATILE_PROVENANCE))
    write_if_changed(path.with_name(path.stem + ".timing.json"), text)


def relative_paths(paths: Iterable[Path | str]) -> list[str]:
    out = []
    for p in paths:
        p = Path(p)
        out.append(str(p.relative_to(ROOT)) if p.is_relative_to(ROOT) else str(p))
    return out

