"""Exhaustive search of the Table 3 cells up to relabeling symmetry, within a stated bound.

This module owns the question "which formulation of a cell m/n has the smallest degree |B|?" asked of
*every* symmetry class of equation subsets in a stated family, not of a budgeted, heuristically ordered
subset as :mod:`analysis.sweeps.tables` does. Data flow: :func:`enumerate_cell` lists the classes of one cell
(:func:`analysis.formulations.tdoa.enumerate_formulations`, one canonical representative per class), each
class is computed on the smallest configuration holding the receivers it uses
(:func:`analysis.sweeps.tables.reduce_formulation`: the same polynomials, so the same generic degree), the
sweep (:func:`analysis.sweeps.complexity.sweep`) computes every distinct reduced formulation on two primes,
and :func:`summarise_cell` turns the results into one row of ``tables/search.csv``.

The family of a cell m/n (N = 5 + n unknowns, M minors), stated in every output:

* ``square``: every subset of A, B2, B3, C2..Cm and k minors with exactly N equations, k <= k_max;
* ``over-determined``: the same with N + 1 .. N + ``excess`` equations (the paper's 5r/4s search uses
  A, B2, B3, C2-C5 with 2, 3 or 4 minors: up to N + 2);
* ``all-minors``: any subset of A, B2, B3, C2..Cm together with every minor (the paper's 6r/4s and
  5r/5s formulations).

k_max is the largest k with C(M, j) <= ``SearchBound.subset_limit`` for every j <= k (all k when every
C(M, j) is below the limit). Classes with more minors than k_max (other than all of them), and classes
with k <= k_max minors and more than N + excess equations, are outside the family; the table states
the bound per cell.

Decisions per class (both primes, one consistent instance each; a disagreement is recomputed on two
instances per prime and decided by the majority rule of :func:`analysis.sweeps.complexity.combine`):

``zero-dimensional``  status ok: |B| agreed by both primes;
``singular``          the Jacobian at the known root is rank-deficient on both primes: the known root
                      (a generic point of the incidence variety) lies on a positive-dimensional
                      component, so the system is not zero-dimensional (generic smoothness; see
                      :mod:`analysis.sweeps.complexity`). No Gröbner basis is computed for these;
``positive-dimensional``  full rank at the root, but the Gröbner basis has dimension > 0;
``capped``            a time, matrix-size or memory cap stopped the computation (listed with its cap);
``open``              primes disagree or an error: neither computed nor capped (listed).

A class the own engine's caps stop is computed again by msolve when an executable is given
(:class:`analysis.engine.msolve.MsolveRun`, run as an external program: no matrix cap, a wall-clock limit),
on the same two primes and instances, the known root checked on its basis; msolve's decision is then
the class's, and its row says ``engine msolve``. A cell is complete when every class is decided:
computed (the first three decisions, by either engine) == candidates. The best formulation is the
smallest |B| over the *square* zero-dimensional classes: those whose independent equations (A + B + C
+ rank of the minors' Jacobian at the root, the paper's count) number N with a full-rank Jacobian.
Classes with more independent equations than unknowns are computed and listed, but on exact data they
keep only the true root (|B| = 1), which says nothing about a solver for noisy data.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

from .complexity import ENGINE_VERSION, FormulationResult
from ..engine.degree import PrimeDisagreement
from ..formulations.tdoa import Formulation, TDOAConfig, enumerate_formulations
from ..engine.msolve import MsolveRun
from .paths import cache_dir as user_cache_dir
from .paths import write_if_changed
from .tables import PAPER_TABLE3, _paper_table3_numbers, _same_results, paper_reference, reduce_formulation

__all__ = [
    "CellCandidates",
    "FAMILIES",
    "SearchBound",
    "cached_cell",
    "classify",
    "enumerate_cell",
    "is_square",
    "minor_bound",
    "summarise_cell",
    "two_prime_degree",
]

FAMILIES = ("square", "over-determined", "all-minors")


@dataclass(frozen=True)
class SearchBound:
    """The family searched in each cell (module docstring).

    subset_limit: k-subsets of the minors are enumerated while C(M, k) <= subset_limit.
    excess: over-determined classes have N + 1 .. N + excess equations.
    all_minors: include every A/B/C subset together with all minors.
    """

    subset_limit: int = 1500
    excess: int = 2
    all_minors: bool = True

    def describe(self) -> str:
        return (f"square (N equations) and over-determined (N+1..N+{self.excess}) subsets with k minors, "
                f"k <= k_max (C(M, j) <= {self.subset_limit} for all j <= k)"
                + ("; any A/B/C subset with all M minors" if self.all_minors else ""))


def minor_bound(config: TDOAConfig, bound: SearchBound) -> int:
    """k_max of a configuration: the largest k with C(M, j) <= subset_limit for every j <= k."""
    k = 0
    while k < config.n_minors and math.comb(config.n_minors, k + 1) <= bound.subset_limit:
        k += 1
    return k


@dataclass(frozen=True)
class CellCandidates:
    """The classes of one cell: canonical labels, their family, and the label each is computed as."""

    m: int
    n: int
    k_max: int
    labels: tuple[str, ...]
    families: tuple[str, ...]
    computed_as: tuple[str, ...]

    @property
    def cell(self) -> str:
        return f"{self.m}/{self.n}"


def enumerate_cell(m: int, n: int, bound: SearchBound = SearchBound()) -> CellCandidates:
    """Every symmetry class of the cell's family, sorted by label (a stable order)."""
    config = TDOAConfig(m, n)
    unknowns = config.n_unknowns
    k_max = minor_bound(config, bound)
    found: dict[str, str] = {}
    for k in range(0, k_max + 1):
        for total in range(unknowns, unknowns + bound.excess + 1):
            family = "square" if total == unknowns else "over-determined"
            for f in enumerate_formulations(config, minor_sets=k if k else "none", total=total):
                found.setdefault(f.label, family)
    if bound.all_minors and config.n_minors:
        for f in enumerate_formulations(config, minor_sets="all"):
            found.setdefault(f.label, "all-minors")
    labels = tuple(sorted(found))
    return CellCandidates(m, n, k_max, labels, tuple(found[x] for x in labels),
                          tuple(reduce_formulation(Formulation.parse(x)).label for x in labels))


ENUMERATION_VERSION = "search-enumeration/1"
"""Part of the key of a cached enumeration: bump it when :func:`enumerate_cell` changes what it lists."""


def _cell_key(m: int, n: int, bound: SearchBound) -> str:
    """The key of a cached enumeration: the bound, :data:`ENUMERATION_VERSION` and the source of the
    modules that canonicalise and reduce (a changed canonical form gives a new key)."""
    here = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for name in ("formulations/tdoa.py", "sweeps/tables.py"):
        digest.update((here / name).read_bytes())
    digest.update(json.dumps([m, n, dataclasses.asdict(bound), ENGINE_VERSION, ENUMERATION_VERSION]).encode())
    return digest.hexdigest()[:20]


def cached_cell(m: int, n: int, bound: SearchBound = SearchBound(), use_cache: bool = True) -> CellCandidates:
    """:func:`enumerate_cell`, stored as JSON in the user cache (``search-cells/``), keyed by the bound and
    the source of the modules that decide the enumeration (the large cells take a minute)."""
    path = user_cache_dir("search-cells") / f"{m}r{n}s-{_cell_key(m, n, bound)}.json"
    if use_cache:
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            return CellCandidates(data["m"], data["n"], data["k_max"], tuple(data["labels"]),
                                  tuple(data["families"]), tuple(data["computed_as"]))
        except (OSError, ValueError, KeyError, TypeError):
            pass
    cell = enumerate_cell(m, n, bound)
    write_if_changed(path, json.dumps(dataclasses.asdict(cell), indent=0))
    return cell


# --------------------------------------------------------------------------------------------------
# Decisions
# --------------------------------------------------------------------------------------------------


def classify(result: FormulationResult) -> str:
    """``zero-dimensional``, ``singular``, ``positive-dimensional``, ``capped`` or ``open``."""
    if result.status == "ok":
        return "zero-dimensional"
    if result.status == "positive-dimensional":
        return "positive-dimensional" if result.dimension is not None else "singular"
    if result.status in ("too-large", "timeout"):
        return "capped"
    return "open"


def two_prime_degree(result: FormulationResult) -> int:
    """The degree of an ok result, checked to be given by an instance over every prime.

    Raises :class:`analysis.engine.degree.PrimeDisagreement` otherwise (STYLE.md habit 6: a degree counts
    only when two primes agree)."""
    if result.status != "ok" or result.degree is None:
        raise ValueError(f"{result.label} has no degree (status {result.status})")
    primes = {o.prime for o in result.instances if o.status == "ok" and o.degree == result.degree}
    if len(set(result.primes)) < 2 or primes != set(result.primes):
        raise PrimeDisagreement(f"{result.label}: degree {result.degree} is not given by every prime "
                                f"({result.instance_degrees} over primes {result.primes})")
    return result.degree


def is_square(result: FormulationResult) -> bool:
    """Independent equations (the paper's count) equal the unknowns and the root is simple."""
    return result.independent_equations == result.n_unknowns and result.tangent_dim == 0


SEARCH_COLUMNS = ("cell", "config", "paper", "k_max", "candidates", "computed", "by_msolve", "capped", "open", "complete",
                  "zero_dimensional", "square_zero_dimensional", "singular", "positive_dimensional",
                  "best_formulation", "best_degree", "best_saturated_degree", "best_computed_as", "seconds")


def summarise_cell(cell: CellCandidates, results: Mapping[str, FormulationResult], paper: str = "") -> dict:
    """One row of ``tables/search.csv`` (columns :data:`SEARCH_COLUMNS`)."""
    counts = {k: 0 for k in ("zero-dimensional", "singular", "positive-dimensional", "capped", "open")}
    square = 0
    best: tuple | None = None
    seconds = 0.0
    for label, target in zip(cell.labels, cell.computed_as):
        r = results[target]
        kind = classify(r)
        counts[kind] += 1
        if kind == "zero-dimensional" and is_square(r):
            square += 1
            degree = two_prime_degree(r)
            key = (degree, r.n_equations, label)  # at equal |B| the smallest system, then the label
            if best is None or key < best[0]:
                best = (key, label, r)
    for target in dict.fromkeys(cell.computed_as):
        seconds += results[target].seconds
    computed = counts["zero-dimensional"] + counts["singular"] + counts["positive-dimensional"]
    by_msolve = sum(1 for target in cell.computed_as if results[target].engine == "msolve"
                    and classify(results[target]) not in ("capped", "open"))
    return {
        "cell": cell.cell, "config": f"{cell.m}r{cell.n}s", "paper": paper, "k_max": cell.k_max, "candidates": len(cell.labels),
        "computed": computed, "by_msolve": by_msolve, "capped": counts["capped"], "open": counts["open"],
        "complete": "yes" if computed == len(cell.labels) else "no",
        "zero_dimensional": counts["zero-dimensional"], "square_zero_dimensional": square,
        "singular": counts["singular"], "positive_dimensional": counts["positive-dimensional"],
        "best_formulation": best[1] if best else "", "best_degree": best[0][0] if best else "",
        "best_saturated_degree": "" if best is None or best[2].saturated_degree is None else best[2].saturated_degree,
        "best_computed_as": best[2].label if best else "", "seconds": round(seconds, 1),
    }


def candidate_rows(cell: CellCandidates, results: Mapping[str, FormulationResult]) -> list[dict]:
    """One row per class of the cell (``tables/search_candidates.csv``), in label order."""
    rows = []
    for label, family, target in zip(cell.labels, cell.families, cell.computed_as):
        r = results[target]
        rows.append({"cell": cell.cell, "formulation": label, "family": family, "computed_as": target,
                     "decision": classify(r), "status": r.status, "degree": r.degree,
                     "saturated_degree": r.saturated_degree, "independent_equations": r.independent_equations,
                     "tangent_dim": r.tangent_dim, "instance_degrees": r.instance_degrees,
                     "cap": r.message if classify(r) in ("capped", "open") or r.engine != "own" else "",
                     "engine": r.engine})
    return rows



# --------------------------------------------------------------------------------------------------
# Driver and outputs
# --------------------------------------------------------------------------------------------------

SEARCH_PRIMES = (65521, 32749)
SEARCH_SEEDS = (0,)
"""One consistent instance per prime; a class whose two primes disagree is recomputed on
:data:`ESCALATION_SEEDS` (reference/NOTES.md: a single instance can be non-generic)."""
ESCALATION_SEEDS = (0, 1)

CANDIDATE_COLUMNS = ("cell", "formulation", "family", "computed_as", "decision", "status", "degree",
                     "saturated_degree", "independent_equations", "tangent_dim", "instance_degrees", "cap", "engine")
CAPPED_COLUMNS = ("cell", "formulation", "computed_as", "decision", "status", "cap")


@dataclass(frozen=True)
class SearchLimits:
    """Per-class caps: wall-clock seconds, F4 matrix cells (rows x cols), F4 working memory (bytes)."""

    timeout: float = 60.0
    max_matrix_cells: int = 20_000_000
    max_memory: int = 2 << 30


@dataclass
class SearchSummary:
    """What :func:`run_search` found: one row per cell, one per class, and the capped / open classes."""

    cells: list[dict]
    candidates: list[dict]
    capped: list[dict]
    paths: list[Path]
    seconds: float
    computed: int
    cached: int


def _paper_entries() -> dict[tuple[int, int], str]:
    numbers = _paper_table3_numbers(paper_reference())
    return {key: str(numbers.get(key, mark)) for key, mark in PAPER_TABLE3.items()}


def run_search(cells: Sequence[tuple[int, int]], bound: SearchBound = SearchBound(),
               limits: SearchLimits = SearchLimits(), *, jobs: int = 1, executor=None, use_cache: bool = True,
               cache_dir: Path | str | None = None, progress: bool = True,
               out_dir: Path | str | None = None, msolve: MsolveRun | None = None) -> SearchSummary:
    """Enumerate, compute and tabulate the given cells (module docstring); writes the outputs when
    ``out_dir`` is given (``tables/search.{csv,md}``, ``search_candidates.csv``, ``search_capped.csv``,
    ``search.meta.json``). With ``msolve``, the classes the own engine's caps stop are computed again
    by msolve (``jobs`` runs at a time)."""
    import sys
    import time

    from .complexity import sweep
    from ..engine.f4 import F4Options

    t0 = time.perf_counter()
    cells = sorted(set(cells))  # the tables' rows in Table 3 order whatever order the cells were given in
    cache = Path(cache_dir) if cache_dir is not None else user_cache_dir("search")
    plans = []
    for m, n in cells:
        plan = cached_cell(m, n, bound, use_cache)
        if progress:
            print(f"search: cell {m}/{n}: {len(plan.labels)} classes (k_max {plan.k_max})", file=sys.stderr, flush=True)
        plans.append(plan)
    labels = list(dict.fromkeys(x for plan in plans for x in plan.computed_as))
    options = F4Options(max_matrix_cells=limits.max_matrix_cells, max_memory=limits.max_memory)
    cached: set[str] = set()
    common = dict(options=options, jobs=jobs, cache_dir=cache, use_cache=use_cache, progress=progress,
                  timeout=limits.timeout, positive_dimensional_cells=0, executor=executor,
                  on_result=lambda r, from_cache: cached.add(r.label) if from_cache else None)
    results = {r.label: r for r in sweep(labels, primes=SEARCH_PRIMES, seeds=SEARCH_SEEDS,
                                          phase="search: two primes", **common)}
    disagree = [x for x, r in results.items() if r.status == "disagree"]
    if disagree:
        for r in sweep(disagree, primes=SEARCH_PRIMES, seeds=ESCALATION_SEEDS,
                       phase="search: disagreements on two seeds per prime", **common):
            results[r.label] = r
    if msolve is not None:
        _decide_capped_by_msolve(results, msolve, jobs, cache, use_cache, progress)
    paper = _paper_entries()
    rows = [summarise_cell(plan, results, paper.get((plan.m, plan.n), "")) for plan in plans]
    candidates = [row for plan in plans for row in candidate_rows(plan, results)]
    capped = [{k: row[k] for k in CAPPED_COLUMNS} for row in candidates if row["decision"] in ("capped", "open")]
    seconds = time.perf_counter() - t0
    summary = SearchSummary(rows, candidates, capped, [], seconds, len(results) - len(cached), len(cached))
    if out_dir is not None:
        meta = _meta(bound, limits, cells, plans, summary, jobs, executor, msolve)
        summary.paths = write_search_outputs(Path(out_dir), summary, bound, limits, meta)
    return summary


def _decide_capped_by_msolve(results: dict[str, FormulationResult], msolve: MsolveRun, jobs: int, cache: Path,
                             use_cache: bool, progress: bool) -> None:
    """Compute every capped class again with msolve (same primes and instances; escalation seeds when
    the primes disagree) and take msolve's result where it decides the class. Cached like the sweep's
    results, under a key that names the engine."""
    from concurrent.futures import ThreadPoolExecutor

    from .complexity import _store, _usable, compute_formulation, load_cached
    from ..engine.f4 import F4Options
    from .progress import Progress

    todo = sorted(label for label, r in results.items() if classify(r) == "capped")
    if not todo:
        return
    options = F4Options()  # only saturation would use it; msolve has no matrix cap

    def decide(label: str) -> FormulationResult:
        for seeds in (SEARCH_SEEDS, ESCALATION_SEEDS):
            r = load_cached(label, SEARCH_PRIMES, seeds, cache, "msolve") if use_cache else None
            if r is None or not _usable(r, options, msolve.timeout, False):
                r = compute_formulation(label, SEARCH_PRIMES, seeds, options, msolve=msolve)
                _store(cache, r)
            if r.status != "disagree":
                break
        return r

    bar = Progress("search: capped classes by msolve", len(todo), progress, "classes")
    try:
        # msolve runs as a separate process, so threads suffice to keep `jobs` of them busy
        with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
            for label, r in zip(todo, pool.map(decide, todo)):
                own = results[label]
                if classify(r) in ("capped", "open"):
                    results[label] = dataclasses.replace(own, message=f"{own.message}; msolve: {r.message}")
                else:
                    results[label] = dataclasses.replace(r, message=f"own engine: {own.message}")
                bar.update(1, f"{label[:50]} {classify(r)} {r.degree if r.degree is not None else ''}")
    finally:
        bar.close()


VOLATILE_META = ("date", "commit", "worktree_dirty", "versions", "machine", "timings", "executor")


def _meta(bound: SearchBound, limits: SearchLimits, cells, plans, summary: SearchSummary, jobs, executor,
          msolve: MsolveRun | None = None) -> dict:
    from ..engine.msolve import msolve_version
    from .provenance import run_facts

    facts = run_facts()
    return {
        "generated_by": "scripts/search_formulations.py (analysis.sweeps.search.run_search)",
        "date": facts["date"],
        "commit": facts["commit"],
        "worktree_dirty": facts["worktree_dirty"],
        "engine_version": ENGINE_VERSION,
        "cells": [f"{m}/{n}" for m, n in cells],
        "bound": {**dataclasses.asdict(bound), "text": bound.describe(),
                  "k_max": {plan.cell: plan.k_max for plan in plans}},
        "limits": dataclasses.asdict(limits),
        "primes": list(SEARCH_PRIMES), "seeds": list(SEARCH_SEEDS), "escalation_seeds": list(ESCALATION_SEEDS),
        "instances": "one consistent instance per (prime, seed): sample_gf_instance(config, prime, seed); a class "
                     "whose primes disagree is recomputed on the escalation seeds (majority rule, every prime "
                     "must give the majority)",
        "decisions": "singular: Jacobian rank-deficient at the known root on both primes (no Groebner basis); "
                     "square: independent equations (A + B + C + minors' Jacobian rank) = unknowns, full rank",
        "capped_by_msolve": None if msolve is None else {
            "version": msolve_version(msolve.exe), "threads": msolve.threads, "timeout": msolve.timeout,
            "what": "classes stopped by the own engine's caps, computed again by msolve (external program) on the "
                    "same primes and instances, the known root checked on its basis"},
        "executor": repr(executor) if executor is not None else f"LocalPool(jobs={jobs})",
        "versions": facts["versions"],
        "machine": facts["machine"],
        "timings": {"wall_seconds": round(summary.seconds, 1), "classes_computed": summary.computed,
                    "classes_from_cache": summary.cached,
                    "worker_seconds": round(sum(r["seconds"] for r in summary.cells), 1)},
    }


def _rows_csv(rows: Sequence[Mapping], columns: Sequence[str]) -> str:
    import csv
    import io

    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow(["" if row[c] is None else row[c] for c in columns])
    return buf.getvalue()


def search_markdown(summary: SearchSummary, bound: SearchBound, limits: SearchLimits, header: str) -> str:
    """``tables/search.md``: the bound, the per-cell table and what is open."""
    cols = ("cell", "paper", "k_max", "candidates", "computed", "by_msolve", "capped", "open", "complete",
            "best_formulation", "best_degree", "best_saturated_degree", "seconds")
    lines = [f"<!-- {header} -->", "", "**Exhaustive search of the Table 3 cells up to relabeling symmetry** "
             f"(within the bound: {bound.describe()}; caps per class: {limits.timeout:g} s, "
             f"{limits.max_matrix_cells} F4 matrix cells, {limits.max_memory >> 20} MiB F4 working memory; "
             f"each class on primes {' and '.join(map(str, SEARCH_PRIMES))}). "
             "best: smallest |B| (as generated; saturated by det H beside it) over the square zero-dimensional "
             "classes; by_msolve: classes the own engine's caps stopped, decided by msolve on the same primes "
             "and instances (search_candidates.csv names the engine of every class); complete: every class "
             "decided (computed = candidates).", "",
             "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for row in summary.cells:
        lines.append("| " + " | ".join(str(row[c]) for c in cols) + " |")
    lines.append("")
    notes = []
    for row in summary.cells:
        left = row["candidates"] - row["computed"]
        if left:
            notes.append(f"* {row['cell']}: {left} of {row['candidates']} classes without a decision "
                         f"({row['capped']} capped, {row['open']} open): listed in search_capped.csv.")
        if row["candidates"] and row["best_degree"] == "" and not left:
            notes.append(f"* {row['cell']}: none of its {row['candidates']} classes is a square zero-dimensional "
                         f"system ({row['singular']} singular at the known root, {row['positive_dimensional']} "
                         f"positive-dimensional, {row['zero_dimensional']} zero-dimensional but over-determined).")
        if row["candidates"] == 0:
            notes.append(f"* {row['cell']}: no subset of its equations has {5 + int(row['cell'].split('/')[1])} "
                         "equations (underdetermined in this formulation family).")
    if notes:
        lines += ["Per cell:", ""] + notes + [""]
    return "\n".join(lines)


def write_search_outputs(out_dir: Path, summary: SearchSummary, bound: SearchBound, limits: SearchLimits,
                         meta: dict) -> list[Path]:
    """Write the search tables; a file whose results did not change is left alone (only timings or the
    header would differ), so a rerun from the cache keeps a checkout clean."""
    from .paths import same_json_apart_from

    out_dir.mkdir(parents=True, exist_ok=True)
    # run facts (commit, date) live in search.meta.json only: two runs a second apart write the same bytes
    header = "generated by scripts/search_formulations.py; run facts (commit, date) in search.meta.json"
    files = {
        "search.csv": _rows_csv(summary.cells, SEARCH_COLUMNS),
        "search_candidates.csv": _rows_csv(summary.candidates, CANDIDATE_COLUMNS),
        "search_capped.csv": _rows_csv(summary.capped, CAPPED_COLUMNS),
        "search.md": search_markdown(summary, bound, limits, header),
    }
    paths = []
    for name, text in files.items():
        write_if_changed(out_dir / name, text, _same_results(name))
        paths.append(out_dir / name)
    text = json.dumps(meta, indent=2) + "\n"
    write_if_changed(out_dir / "search.meta.json", text, same_json_apart_from(VOLATILE_META))
    paths.append(out_dir / "search.meta.json")
    return paths
