"""Exhaustive search of the Table 3 cells up to relabeling symmetry, within a stated bound.

This module owns the question "which formulation of a cell m/n has the smallest degree |B|?" asked of
*every* symmetry class of equation subsets in a stated family, not of a budgeted, heuristically ordered
subset as :mod:`analysis.tables` does. Data flow: :func:`enumerate_cell` lists the classes of one cell
(:func:`analysis.formulations.enumerate_formulations`, one canonical representative per class), each
class is computed on the smallest configuration holding the receivers it uses
(:func:`analysis.tables.reduce_formulation`: the same polynomials, so the same generic degree), the
sweep (:func:`analysis.complexity.sweep`) computes every distinct reduced formulation on two primes,
and :func:`summarise_cell` turns the results into one row of ``tables/search.csv``.

The family of a cell m/n (N = 5 + n unknowns, M minors), stated in every output:

* ``square``: every subset of A, B2, B3, C2..Cm and k minors with exactly N equations, k <= k_max;
* ``over-determined``: the same with N + 1 .. N + ``excess`` equations (the paper's 5r/4s search uses
  A, B2, B3, C2-C5 with 2, 3 or 4 minors: up to N + 2);
* ``all-minors``: any subset of A, B2, B3, C2..Cm together with every minor (the paper's 6r/4s and
  5r/5s formulations).

k_max is the largest k with C(M, j) <= ``SearchBound.subset_limit`` for every j <= k (all k when every
C(M, j) is below the limit). Classes with more minors than k_max (other than all of them) are outside
the family; the table says so per cell.

Decisions per class (both primes, one consistent instance each; a disagreement is recomputed on two
instances per prime and decided by the majority rule of :func:`analysis.complexity.combine`):

``zero-dimensional``  status ok: |B| agreed by both primes;
``singular``          the Jacobian at the known root is rank-deficient on both primes: the known root
                      (a generic point of the incidence variety) lies on a positive-dimensional
                      component, so the system is not zero-dimensional (generic smoothness; see
                      :mod:`analysis.complexity`). No Gröbner basis is computed for these;
``positive-dimensional``  full rank at the root, but the Gröbner basis has dimension > 0;
``capped``            a time, matrix-size or memory cap stopped the computation (listed with its cap);
``open``              primes disagree or an error: neither computed nor capped (listed).

A cell is complete when computed (the first three) + capped == candidates. The best formulation is the
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
from .degree import PrimeDisagreement
from .formulations import Formulation, TDOAConfig, enumerate_formulations
from .paths import cache_dir as user_cache_dir
from .paths import write_if_changed

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

    subset_limit: int = 3000
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
    from .tables import reduce_formulation  # tables imports this module's users, not the other way round

    config = TDOAConfig(m, n)
    unknowns = config.n_unknowns
    k_max = minor_bound(config, bound)
    found: dict[str, str] = {}
    for k in range(0, k_max + 1):
        for total in range(unknowns, unknowns + bound.excess + 1):
            family = "square" if total == unknowns else "over-determined"
            for f in enumerate_formulations(config, minor_sets=k if k else "none", total=total):
                found.setdefault(f.label, family)
    if bound.all_minors and config.n_minors > k_max:
        for f in enumerate_formulations(config, minor_sets="all"):
            found.setdefault(f.label, "all-minors")
    labels = tuple(sorted(found))
    return CellCandidates(m, n, k_max, labels, tuple(found[x] for x in labels),
                          tuple(reduce_formulation(Formulation.parse(x)).label for x in labels))


def _cell_key(m: int, n: int, bound: SearchBound) -> str:
    here = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for name in ("search.py", "formulations.py", "tables.py"):
        digest.update((here / name).read_bytes())
    digest.update(json.dumps([m, n, dataclasses.asdict(bound), ENGINE_VERSION]).encode())
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

    Raises :class:`analysis.degree.PrimeDisagreement` otherwise (STYLE.md habit 6: a degree counts
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


SEARCH_COLUMNS = ("cell", "paper", "k_max", "candidates", "computed", "capped", "open", "complete",
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
            key = (degree, label)
            if best is None or key < best[0]:
                best = (key, label, r)
    for target in dict.fromkeys(cell.computed_as):
        seconds += results[target].seconds
    computed = counts["zero-dimensional"] + counts["singular"] + counts["positive-dimensional"]
    return {
        "cell": cell.cell, "paper": paper, "k_max": cell.k_max, "candidates": len(cell.labels),
        "computed": computed, "capped": counts["capped"], "open": counts["open"],
        "complete": "yes" if computed + counts["capped"] == len(cell.labels) else "no",
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
                     "cap": r.message if classify(r) in ("capped", "open") else ""})
    return rows

