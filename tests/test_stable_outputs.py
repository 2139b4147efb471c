"""Clean reruns: the sweep's tables do not depend on the order results arrive in, and every committed CSV
the sweeps write is in its documented row order."""
from __future__ import annotations

import csv
import json
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
    """Every file the sweep writes except its untracked run record, as bytes (they hold results only: no
    commit, date or timing, so two runs give the same bytes in full)."""
    return {p.name: p.read_bytes() for p in sorted(out.iterdir()) if not p.name.endswith(".timing.json")}


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


def test_run_facts_go_to_the_timing_record_and_the_tables_hold_results_only(tmp_path, monkeypatch):
    """A rerun that measures other times leaves every committed file as it was (bytes and mtime); the seconds
    it measured, per row, and the run's commit and date are in provenance.timing.json only. A rerun whose
    result changed in one row rewrites that row and nothing else."""
    monkeypatch.setenv("TDOA_WORKBENCH_CACHE", str(tmp_path / "user-cache"))
    monkeypatch.setattr(tables, "sweep", _fake_sweep(None))
    out = tmp_path / "t"
    make_tables(quick=True, jobs=1, cells="6/4,9/3", out_dir=out, progress=False)
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    written = _outputs(out)
    for name, data in written.items():
        text = data.decode()
        assert "seconds" not in text.splitlines()[0].split(","), f"{name} has a timing column"
        assert not any(fact in text for fact in ('"commit"', '"date"', "commit ", "dirty worktree")), name
    monkeypatch.setattr(tables, "sweep", _fake_sweep(None, seconds=2.0))
    make_tables(quick=True, jobs=1, cells="6/4,9/3", out_dir=out, progress=False)
    assert _outputs(out) == written
    assert all(p.stat().st_mtime_ns == before[p.name] for p in out.iterdir() if not p.name.endswith(".timing.json"))
    timing = json.loads((out / "provenance.timing.json").read_text())
    assert timing["commit"] is not None and timing["date"]
    assert {r["seconds"] for r in timing["seconds"]["formulations"]} == {8.0}  # 4 instances x 2.0 s: measured now
    changed = "9r3s:C2-C9"
    monkeypatch.setattr(tables, "sweep", _fake_sweep(None, seconds=2.0, bump=changed))
    make_tables(quick=True, jobs=1, cells="6/4,9/3", out_dir=out, progress=False)
    again = _outputs(out)
    with open(out / "formulations.csv", newline="") as fh:
        rows = {r["label"]: r for r in csv.DictReader(fh)}
    assert rows[changed]["degree"] == str(len(changed) + 1)
    differ = [a.split(",")[0] for a, b in zip(again["formulations.csv"].decode().splitlines(),
                                              written["formulations.csv"].decode().splitlines()) if a != b]
    assert differ == [f'"{changed}"'] or differ == [changed]
