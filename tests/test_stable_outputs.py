"""Clean reruns: the sweep's tables do not depend on the order results arrive in, and every committed CSV
the sweeps write is in its documented row order."""
from __future__ import annotations

import csv
import random

import pytest

from analysis.sweeps import tables
from analysis.sweeps.complexity import InstanceOutcome, combine, repo_root
from analysis.engine.f4 import F4Options
from analysis.formulations.tdoa import Formulation
from analysis.sweeps.tables import make_tables, paper_reference

SEED = 7


def _fake_sweep(order_seed, seconds=0.5, bump=None):
    """A stand-in for analysis.sweeps.complexity.sweep: a deterministic made-up result per label (degree = label
    length, one more for the label ``bump``), each instance taking ``seconds``, handed back in input order
    (order_seed None) or shuffled by the given seed."""

    def sweep(labels, *, primes, seeds, on_result=None, **kwargs):
        out = []
        for label in dict.fromkeys(labels):
            f = Formulation.parse(label)
            n = f.config.n_unknowns
            degree = len(label) + (label == bump)
            marks = [InstanceOutcome(p, s, "ok", degree=degree, dimension=0, jacobian_rank=n,
                                     minor_rank=n - f.counts.A - f.counts.B - f.counts.C, seconds=seconds)
                     for p in primes for s in seeds]
            out.append(combine(f, marks, primes, seeds, F4Options()))
        if order_seed is not None:
            random.Random(order_seed).shuffle(out)
        for r in out:
            if on_result is not None:
                on_result(r, False)
        return out

    return sweep


def _outputs(out):
    """Every table file's bytes, without the provenance header line (it holds the run's date, to the second:
    two runs straddling a second differed there alone)."""
    from analysis.sweeps.paths import HEADER_PREFIXES

    return {p.name: b"\n".join(line for line in p.read_bytes().split(b"\n")
                               if not line.startswith(tuple(x.encode() for x in HEADER_PREFIXES)))
            for p in sorted(out.iterdir()) if not p.name.startswith("provenance")}


def test_tables_do_not_depend_on_the_order_results_arrive_in(tmp_path, monkeypatch):
    """Two cells given in either order, results handed back shuffled (as worker processes or Dask chunks
    deliver them): every table file is byte-identical."""
    monkeypatch.setenv("TDOA_WORKBENCH_CACHE", str(tmp_path / "user-cache"))
    monkeypatch.setattr(tables, "sweep", _fake_sweep(None))
    make_tables(quick=True, jobs=1, cells="6/4,9/3", out_dir=tmp_path / "a", progress=False)
    monkeypatch.setattr(tables, "sweep", _fake_sweep(SEED))
    make_tables(quick=True, jobs=1, cells="9/3,6/4", out_dir=tmp_path / "b", progress=False)
    a, b = _outputs(tmp_path / "a"), _outputs(tmp_path / "b")
    assert set(a) >= {"table2.csv", "table3.csv", "formulations.csv", "table3.md"}
    assert a == b
    with open(tmp_path / "a" / "table3.csv", newline="") as fh:
        assert [(r["m"], r["n"]) for r in csv.DictReader(fh)] == [("6", "4"), ("9", "3")]


def test_a_formulation_stopped_by_the_wall_clock_limit_is_computed_again_without_it(tmp_path, monkeypatch):
    """A timeout depends on the machine's load, so it never reaches a table: make_tables computes what the
    limit stopped again with timeout=None, and the tables equal those of a run without timeouts."""
    monkeypatch.setenv("TDOA_WORKBENCH_CACHE", str(tmp_path / "user-cache"))
    monkeypatch.setattr(tables, "sweep", _fake_sweep(None))
    make_tables(quick=True, jobs=1, cells="6/4,9/3", out_dir=tmp_path / "a", progress=False)
    calm = _fake_sweep(None)
    calls = []

    def loaded(labels, *, primes, seeds, timeout=None, **kwargs):
        labels = list(labels)
        calls.append((labels, timeout))
        out = calm(labels, primes=primes, seeds=seeds, **kwargs)
        if timeout is None:
            return out
        slow = [r for r in out if r.m == 6]  # every 6-receiver formulation "takes too long" under load
        for r in slow:
            f = Formulation.parse(r.label)
            marks = [InstanceOutcome(p, s, "timeout", message="wall-clock limit of 300 s exceeded") for p in primes
                     for s in seeds]
            out[out.index(r)] = combine(f, marks, primes, seeds, F4Options(), timeout)
        return out

    monkeypatch.setattr(tables, "sweep", loaded)
    summary = make_tables(quick=True, jobs=1, cells="6/4,9/3", out_dir=tmp_path / "b", progress=False)
    retried, limit = calls[-1]
    assert limit is None and retried and all(Formulation.parse(x).config.m == 6 for x in retried)
    assert "timeout" not in summary.statuses
    assert _outputs(tmp_path / "a") == _outputs(tmp_path / "b")


def test_a_changed_row_rewrites_its_own_seconds_only(tmp_path, monkeypatch):
    """A rerun that measures other times keeps every table file; one whose result changed in one row
    rewrites that row, its seconds included, and the other rows keep the seconds they were written with."""
    monkeypatch.setenv("TDOA_WORKBENCH_CACHE", str(tmp_path / "user-cache"))
    monkeypatch.setattr(tables, "sweep", _fake_sweep(None))
    out = tmp_path / "t"
    make_tables(quick=True, jobs=1, cells="6/4,9/3", out_dir=out, progress=False)
    before = _outputs(out)
    slow = _fake_sweep(None, seconds=2.0)
    monkeypatch.setattr(tables, "sweep", slow)
    make_tables(quick=True, jobs=1, cells="6/4,9/3", out_dir=out, progress=False)
    assert _outputs(out) == before
    changed = "9r3s:C2-C9"
    monkeypatch.setattr(tables, "sweep", _fake_sweep(None, seconds=2.0, bump=changed))
    make_tables(quick=True, jobs=1, cells="6/4,9/3", out_dir=out, progress=False)
    with open(out / "formulations.csv", newline="") as fh:
        rows = {r["label"]: r for r in csv.DictReader(fh)}
    assert rows[changed]["seconds"] == "8.0"  # 4 instances x 2.0 s: measured now
    assert {r["seconds"] for label, r in rows.items() if label != changed} == {"2.0"}  # 4 x 0.5 s: as written


def _rows(name):
    path = repo_root() / "tables" / name
    if not path.exists():
        pytest.skip(f"tables/{name} not generated yet")
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def _cell_key(text):
    m, n = text.split("/")
    return int(m), int(n)


def test_committed_sweep_csvs_are_in_their_documented_row_order():
    formulations = _rows("formulations.csv")
    assert formulations == sorted(formulations, key=lambda r: (int(r["n"]), int(r["m"]), r["label"]))
    table3 = _rows("table3.csv")
    assert table3 == sorted(table3, key=lambda r: (int(r["m"]), int(r["n"])))
    ref = paper_reference()
    paper_order = [(r.A, r.B, r.C) for r in ref[ref["table"] == "2"].itertuples()]
    assert [(r["A"], r["B"], r["C"]) for r in _rows("table2.csv")] == paper_order
    searches = [r["search"] for r in _rows("section32.csv")]
    order = list(tables.SECTION32_TARGETS)
    assert searches == sorted(searches, key=order.index)
    search = _rows("search.csv")
    assert search == sorted(search, key=lambda r: _cell_key(r["cell"]))
    for name in ("search_candidates.csv", "search_capped.csv"):
        rows = _rows(name)
        assert rows == sorted(rows, key=lambda r: (_cell_key(r["cell"]), r["formulation"])), name
