"""Provenance of the experiment artefacts: what determines the results, and the facts of the run apart.

Owns the record of one run (`provenance`) and its two files, merged per artefact so that regenerating
one leaves the others' sections intact (`update_provenance`): the tracked
``tables/experiments_provenance.json`` holds only what code, seeds and options determine (the same bytes
on every rerun and machine), the untracked ``experiments_provenance.timing.json`` the whole record with
the run's facts (commit, date, versions, machine, threads, wall times, runtimes in ms, cache hits).
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

from analysis.sweeps.complexity import THREAD_VARIABLES
from analysis.sweeps.paths import write_if_changed

from .config import PROVENANCE_PATH, ROOT

VOLATILE_PROVENANCE = ("updated", "date", "commit", "worktree_dirty", "versions", "machine", "threads", "wall_seconds",
                       "load_average_at_end", "seconds", "jobs", "computed_now", "cache_hits",
                       "compute_seconds_when_computed", "blas_core")
"""Keys of the provenance record that are facts of the run, not results (at any depth; also every key
ending in ``_ms``, a runtime): kept in the untracked timing record only."""


def results_only(value):
    """The record without its run facts (:data:`VOLATILE_PROVENANCE`, ``*_ms`` runtimes), at any depth."""
    if isinstance(value, dict):
        return {k: results_only(v) for k, v in value.items() if k not in VOLATILE_PROVENANCE and not k.endswith("_ms")}
    if isinstance(value, list):
        return [results_only(v) for v in value]
    return value



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
    """Merge per-artefact provenance records into ``experiments_provenance.json`` and its timing record.

    One section per artefact ("table4", "fig1", "fig2", "reproduce"), so that a script regenerating one
    artefact leaves the record of the others intact. The tracked file gets :func:`results_only` of the
    merged record (written only when its bytes change), the untracked ``.timing.json`` beside it all of it.
    """
    record: dict = {}
    timing = path.with_name(path.stem + ".timing.json")  # the full record of the last run (untracked)
    for source in (timing, path):  # the last run's full record, else the tracked one (a fresh checkout)
        try:
            record = json.loads(source.read_text())
            break
        except (OSError, json.JSONDecodeError):
            continue
    record.setdefault("artefacts", {}).update(sections)
    record["updated"] = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    record["description"] = (
        "Provenance of tables/table4.{csv,md,tex} and tables/figures/fig1_*, fig2_* "
        "(solvers.experiments); one section per artefact. Run facts (commit, date, versions, machine, "
        "runtimes) are in the untracked experiments_provenance.timing.json."
    )
    write_if_changed(path, json.dumps(results_only(record), indent=2, default=str) + "\n")
    write_if_changed(timing, json.dumps(record, indent=2, default=str) + "\n")


def relative_paths(paths: Iterable[Path | str]) -> list[str]:
    out = []
    for p in paths:
        p = Path(p)
        out.append(str(p.relative_to(ROOT)) if p.is_relative_to(ROOT) else str(p))
    return out

