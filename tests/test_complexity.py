"""Tests for analysis.sweeps.complexity and analysis.sweeps.tables: degrees of the paper's formulations, the majority
rule, saturation by det H, caching and limits of the sweep, and staleness of tables/formulations.csv.
"""
from __future__ import annotations

import csv
import dataclasses
import json
from types import SimpleNamespace

import numpy as np
import pytest

from analysis.sweeps import complexity, tables
from analysis.sweeps.complexity import (
    DEFAULT_PRIMES,
    ENGINE_VERSION,
    FormulationResult,
    InstanceOutcome,
    _usable,
    _variable_action_matrices,
    combine,
    compute_formulation,
    jacobian_rank,
    load_cached,
    repo_root,
    root_ranks,
    saturated_degree,
    sweep,
)
from analysis.engine.f4 import F4Options, groebner
from analysis.formulations.tdoa import Formulation, gf_equations, sample_gf_instance
from analysis.engine.quotient import action_matrix, saturate, standard_monomials
from analysis.engine.ring import Ring
from analysis.sweeps.tables import (
    PAPER_TABLE3,
    QUICK,
    TablePlan,
    _csv_text,
    _paper_table2,
    _paper_table3_numbers,
    build_section32,
    format_result_row,
    make_tables,
    paper_reference,
    parse_cells,
    reduce_formulation,
    section32_formulations,
    table2_formulations,
)

SEEDS = (0, 1)
F9 = "9r3s:C2-C9"
F6 = "6r4s:B2,C2-C6,minors(10)"


# --------------------------------------------------------------------------------------------------
# degrees of the paper's formulations, caching
# --------------------------------------------------------------------------------------------------


def _no_worker(*args, **kwargs):
    raise AssertionError("a cached sweep computed something")


def test_sweep_gives_75_and_22_and_second_run_reads_the_cache(tmp_path, monkeypatch):
    flags = []
    results = sweep([F9, F6], primes=DEFAULT_PRIMES, seeds=SEEDS, jobs=1, timeout=None, cache_dir=tmp_path,
                    progress=False, on_result=lambda r, cached: flags.append(cached))
    r9, r6 = results
    assert (r9.status, r9.degree, r9.saturated_degree) == ("ok", 75, 75)
    assert (r6.status, r6.degree, r6.saturated_degree) == ("ok", 22, 22)
    assert r9.instance_degrees == "75,75,75,75" and r9.instances_agree
    assert r6.independent_equations == 9 and r6.n_minors == 10  # 10 minors, 3 independent (Section 3.2)
    assert r9.tangent_dim == 0 and r6.tangent_dim == 0
    assert flags == [False, False]
    assert len(list(tmp_path.glob("*.json"))) == 2

    flags.clear()
    monkeypatch.setattr(complexity, "_run_pool", _no_worker)  # no worker is even started
    monkeypatch.setattr(complexity, "compute_formulation", _no_worker)
    again = sweep([F6, F9], primes=DEFAULT_PRIMES, seeds=SEEDS, jobs=2, cache_dir=tmp_path, progress=False,
                  on_result=lambda r, cached: flags.append(cached))
    assert flags == [True, True]
    assert [r.degree for r in again] == [22, 75]
    assert again[1].to_dict() == r9.to_dict()
    assert load_cached(F9, DEFAULT_PRIMES, SEEDS, tmp_path).degree == 75
    assert load_cached(F9, DEFAULT_PRIMES, (0, 1, 2), tmp_path) is None  # seeds are part of the key


def test_cache_entry_is_plain_json_keyed_by_engine_version(tmp_path):
    sweep([F6], seeds=(0,), jobs=1, timeout=None, cache_dir=tmp_path, progress=False)
    (path,) = tmp_path.glob("*.json")
    data = json.loads(path.read_text())
    assert data["key"] == {"label": F6, "primes": list(DEFAULT_PRIMES), "seeds": [0], "engine": ENGINE_VERSION}
    assert FormulationResult.from_dict(data["result"]).degree == 22


def test_worker_pool_and_wall_clock_timeout(tmp_path):
    # two cheap formulations through spawned workers
    fast = sweep([F6, "5r5s:B2,B3,C2-C5,minors(16)"], seeds=(0,), jobs=2, timeout=120, cache_dir=tmp_path,
                 progress=False)
    assert [r.degree for r in fast] == [22, 64]
    # a limit no computation can meet (a spawned worker needs longer than 0.01 s just to import numpy,
    # and this formulation takes seconds): the worker is killed and the status recorded
    (slow,) = sweep(["7r3s:A,B2,C2-C7"], seeds=(0,), jobs=1, timeout=0.01, cache_dir=tmp_path, progress=False)
    assert slow.status == "timeout" and slow.degree is None and slow.timeout == 0.01
    assert "timeout" in slow.instance_degrees and "wall-clock limit of 0.01 s" in slow.message
    # a timeout is not reused under a longer limit
    assert not _usable(slow, F4Options(), 10.0, False)
    assert _usable(slow, F4Options(), 0.01, False)


def test_positive_dimensional_formulation_reports_its_dimension():
    r = compute_formulation("9r3s:C2-C8", seeds=(0,))  # 7 equations, 8 unknowns
    assert r.status == "positive-dimensional"
    assert r.degree is None and r.dimension == 1
    assert r.tangent_dim == 1 and r.instance_degrees == "dim1,dim1"


def test_matrix_cap_gives_too_large_and_skips_the_other_instances():
    r = compute_formulation("8r3s:B2,C2-C8", seeds=SEEDS, options=F4Options(max_matrix_cells=2000))
    assert r.status == "too-large" and r.degree is None
    assert r.instance_degrees == "too-large,too-large,too-large,too-large"
    assert "skipped" in r.instances[1].message
    assert not _usable(r, F4Options(max_matrix_cells=10**8), None, False)  # a larger cap recomputes


def test_errors_are_recorded_with_prime_and_seed():
    r = compute_formulation(F6, primes=(7,), seeds=(0,))  # far too small for a consistent instance
    assert r.status == "error"
    assert "prime 7" in r.message and "seed 0" in r.message


# --------------------------------------------------------------------------------------------------
# majority rule
# --------------------------------------------------------------------------------------------------


def _outcomes(tokens, primes, seeds):
    out = []
    for (p, s), t in zip([(p, s) for p in primes for s in seeds], tokens):
        if isinstance(t, int):
            out.append(InstanceOutcome(p, s, "ok", degree=t, dimension=0, jacobian_rank=8, minor_rank=0, gb_size=1))
        else:
            out.append(InstanceOutcome(p, s, "positive-dimensional", dimension=int(t[3:]), jacobian_rank=7,
                                       minor_rank=0, gb_size=1))
    return out


@pytest.mark.parametrize("tokens,status,degree,agree", [
    ((75, 75, 75, 75), "ok", 75, True),
    ((75, 74, 75, 75), "ok", 75, False),          # one non-generic instance: recorded, not hidden
    ((75, 75, 74, 74), "disagree", None, False),  # the primes disagree
    ((75, 74, 74, 75), "disagree", None, False),  # no unique majority
    (("dim1", "dim1", "dim1", 75), "positive-dimensional", None, False),
])
def test_majority_rule(tokens, status, degree, agree):
    primes, seeds = (65521, 32749), (0, 1)
    f = Formulation.parse(F9)
    r = combine(f, _outcomes(tokens, primes, seeds), primes, seeds, F4Options())
    assert (r.status, r.degree, r.instances_agree) == (status, degree, agree)
    assert r.instance_degrees == ",".join(str(t) for t in tokens)


def test_a_prime_that_never_gives_the_majority_is_a_disagreement():
    primes, seeds = (65521, 32749, 40009), (0, 1)
    f = Formulation.parse(F9)
    r = combine(f, _outcomes((75, 75, 75, 75, 74, 74), primes, seeds), primes, seeds, F4Options())
    assert r.status == "disagree" and "40009" in r.message


# --------------------------------------------------------------------------------------------------
# exact tools
# --------------------------------------------------------------------------------------------------


def test_action_matrices_match_the_reference_normal_forms():
    f = Formulation.parse(F6)
    for p in (65521, 2_147_483_647):  # the second exercises the Python-integer path
        inst = sample_gf_instance(f.config, p, 3)
        ring = Ring(f.unknowns, p)
        gb = groebner([ring.from_terms(t) for t in gf_equations(f, inst)])
        basis = standard_monomials(gb)
        M = _variable_action_matrices(gb, basis)
        for i in range(ring.nvars):
            assert np.array_equal(M[i], action_matrix(gb, i, basis))


def test_saturated_degree_agrees_with_rabinowitsch():
    p = 65521
    ring = Ring(["x", "y"], p)
    x, y = ring.gens()
    one = ring.one()
    # roots x = 0 (double), 1, 2 on the parabola y = x^2; saturating by x(x - 1) leaves the root x = 2
    polys = [x * x * (x - one) * (x - one * 2), y - x * x]
    gb = groebner(polys)
    assert len(standard_monomials(gb)) == 4
    f = x * (x - one)
    assert saturated_degree(gb, f) == 1 == len(standard_monomials(saturate(polys, f)))
    assert saturated_degree(gb, y + one) == 4  # y + 1 vanishes at no root


def test_saturation_by_det_h_drops_spurious_roots_of_the_minimal_problem():
    # 6r/3s (abc = 125): one of the 181 solutions has det H = 0 (NOTES.md: A and B are multiplied by det H)
    r = compute_formulation("6r3s:A,B2,B3,C2-C6", primes=(65521,), seeds=(0,))
    assert (r.degree, r.saturated_degree) == (181, 180)


def test_jacobian_rank_and_independent_minors():
    assert root_ranks(F6) == (9, 3)  # 10 minors of 6r/4s, 3 independent (Theorem 1)
    assert root_ranks("5r5s:minors") == (4, 4)
    p = 101
    # x^2 + y^2 - 2 and x - y at (1, 1): Jacobian [[2, 2], [1, -1]] has rank 2; x - y twice: rank 1
    polys = [{(2, 0): 1, (0, 2): 1, (0, 0): p - 2}, {(1, 0): 1, (0, 1): p - 1}]
    assert jacobian_rank(polys, (1, 1), p) == 2
    assert jacobian_rank([polys[1], polys[1]], (1, 1), p) == 1


# --------------------------------------------------------------------------------------------------
# tables: which formulations, paper reference, staleness of the committed CSV
# --------------------------------------------------------------------------------------------------


def test_table2_formulations_are_the_papers_six_rows():
    labels = [f.label for f in table2_formulations()]
    abc = {(f.counts.A, f.counts.B, f.counts.C) for f in table2_formulations()}
    assert abc == set(_paper_table2(paper_reference()))
    assert "9r3s:C2-C9" in labels and "6r3s:A,B2,B3,C2-C6" in labels and len(labels) == 6


def test_reduce_formulation_drops_unused_receivers():
    assert reduce_formulation(Formulation.parse("9r3s:B2,C2-C8")).label == "8r3s:B2,C2-C8"
    assert reduce_formulation(Formulation.parse("9r3s:C3-C9")).label == "8r3s:C2-C8"
    # C on receivers 2-6 and every minor of D~ rows 1-5: the 6r/4s solver inside 8r/4s
    minors = ",".join(f"M{a}{b}{c}_123" for a in range(1, 6) for b in range(a + 1, 6) for c in range(b + 1, 6))
    assert reduce_formulation(Formulation.parse(f"8r4s:B2,C2-C6,{minors}")).label == F6
    assert reduce_formulation(Formulation.parse(F6)).label == F6


def test_paper_table3_grid_agrees_with_the_reference_csv():
    numbers = _paper_table3_numbers(paper_reference())
    assert numbers == {k: int(v) for k, v in PAPER_TABLE3.items() if v.isdigit()}
    assert parse_cells("6/4, 5r5s") == [(6, 4), (5, 5)]
    with pytest.raises(ValueError, match="not in Table 3"):
        parse_cells("3/3")


def test_committed_formulations_csv_is_not_stale():
    """Recompute the cheap 9r/3s and 6r/4s rows of tables/formulations.csv and compare every column
    except the timings (and where the row is used)."""
    path = repo_root() / "tables" / "formulations.csv"
    prov = repo_root() / "tables" / "provenance.json"
    if not path.exists() or not prov.exists():
        pytest.skip("tables/formulations.csv not generated yet (python scripts/make_tables.py)")
    provenance = json.loads(prov.read_text())
    options = F4Options(max_matrix_cells=provenance["max_matrix_cells"])
    with path.open(newline="") as fh:
        rows = {r["label"]: r for r in csv.DictReader(fh)}
    checked = 0
    for label in (F9, F6):
        if label not in rows:
            continue
        committed = rows[label]
        primes = tuple(int(x) for x in committed["primes"].split())
        seeds = tuple(int(x) for x in committed["seeds"].split())
        fresh = format_result_row(compute_formulation(label, primes, seeds, options))
        for column in fresh:
            if column in ("seconds", "used_in"):
                continue
            assert fresh[column] == committed[column], f"{label}: column {column} is stale"
        checked += 1
    assert checked == 2


def test_committed_section32_csv_is_what_the_code_writes():
    """tables/section32.csv is exactly what build_section32 writes from the committed results
    (tables/formulations.csv) and a freshly enumerated plan, rows in the same order; the plan's
    searches are handed over in sorted-key order, as a cached plan returns them."""
    section32 = repo_root() / "tables" / "section32.csv"
    with (repo_root() / "tables" / "formulations.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    as_int = lambda text: int(text) if text else None  # noqa: E731
    results = {r["label"]: SimpleNamespace(
        label=r["label"], config=r["config"], status=r["status"], instance_degrees=r["instance_degrees"],
        **{k: as_int(r[k]) for k in ("degree", "saturated_degree", "dimension", "tangent_dim",
                                      "independent_equations", "n_minors")}) for r in rows}
    searches = section32_formulations()
    plan = TablePlan((), (), {k: tuple(searches[k]) for k in sorted(searches)}, QUICK)
    assert _csv_text(build_section32(plan, results)) == section32.read_text(encoding="utf-8")


@pytest.mark.slow
def test_table2_in_full():
    """All six rows of Table 2 on 2 primes x 2 seeds (about 25 s on an idle machine, 4 instances each)."""
    paper = _paper_table2(paper_reference())
    for f in table2_formulations():
        r = compute_formulation(f, seeds=SEEDS)
        c = f.counts
        assert r.status == "ok" and r.instances_agree
        assert r.degree == paper[(c.A, c.B, c.C)], f.label


def test_make_tables_from_an_empty_cache_writes_its_outputs(tmp_path, monkeypatch):
    """A first run (nothing cached) must write the tables and provenance (regression: KeyError); a rerun
    reads the cached plan and results and rewrites nothing but the untracked timing record.

    Section 3.2 searches (stand-ins among the formulations computed anyway, listed out of order): the
    cached plan comes back with its searches in sorted-key order, and section32.csv must not follow
    that (regression: its rows swapped between a first run and a rerun)."""
    searches = {"64": ["6r4s:A,C2-C6,minors(10)"], "22/66": [F6], "154": [F9]}
    monkeypatch.setattr(tables, "section32_formulations", lambda: searches)
    budget = dataclasses.replace(QUICK, section32=True)
    monkeypatch.setenv("TDOA_WORKBENCH_CACHE", str(tmp_path / "user-cache"))
    summary = make_tables(quick=True, jobs=1, cells="6/4", out_dir=tmp_path / "out",
                          cache_dir=tmp_path / "cache", progress=False, budget=budget)
    with open(tmp_path / "out" / "section32.csv", newline="") as handle:
        rows = [(r["search"], r["formulation"]) for r in csv.DictReader(handle)]
    assert rows == [("22/66", F6), ("154", F9), ("64", "6r4s:A,C2-C6,minors(10)")]
    assert summary.computed > 0
    timing = json.loads((tmp_path / "out" / "provenance.timing.json").read_text())
    assert timing["last_uncached_run"]["formulations"] == summary.computed
    assert "last_uncached_run" not in json.loads((tmp_path / "out" / "provenance.json").read_text())
    assert (tmp_path / "out" / "table3.csv").exists()
    assert len(list((tmp_path / "user-cache" / "plans").glob("plan-*.json"))) == 1
    files = sorted((tmp_path / "out").iterdir())
    before = {f.name: (f.stat().st_mtime_ns, f.read_bytes()) for f in files}
    again = make_tables(quick=True, jobs=1, cells="6/4", out_dir=tmp_path / "out",
                        cache_dir=tmp_path / "cache", progress=False, budget=budget)
    assert again.computed == 0
    after = {f.name: (f.stat().st_mtime_ns, f.read_bytes()) for f in sorted((tmp_path / "out").iterdir())}
    changed = sorted(name for name in after if after[name] != before.get(name))
    assert changed == ["provenance.timing.json"]
