"""The trace test (solvers.continuation.trace) on certified cells: it passes on the complete root set and fails
when one root (or one witness) is missing."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from analysis.formulations.parametric import from_formulation
from analysis.formulations.tdoa import Formulation
from solvers.continuation import monodromy as md
from solvers.continuation import slp, trace
from solvers.continuation import tracking as tk
from solvers.generate import SOLVERS, complex_instance


def _roots(key: str, count: int):
    """The system of a committed cell, a seeded complex start network and all its roots by monodromy (the
    count certified over GF(p): tables/toa.*), and a second seeded network with its known root."""
    label = SOLVERS[key]
    config = Formulation.parse(label).config
    system = from_formulation(label, saturate_det_h=True)
    F, x0 = complex_instance(config.m, config.n, np.random.default_rng(5), config.dim, config.model)
    solver, x0 = md.start_solver(system, F.ravel(), x0)
    found = md.monodromy_count(solver, F.ravel(), x0, tk.HomotopyOptions(seed=3, stall_loops=8), 1e9,
                               excluded=md._excluded(system, F.ravel()))
    assert len(found.roots) == count
    F2, x2 = complex_instance(config.m, config.n, np.random.default_rng(6), config.dim, config.model)
    return system, F.ravel(), found.roots, (F2.ravel(), x2)


@pytest.mark.parametrize("key, count, coordinates", [("3r3stoa", 8, None),
                                                     pytest.param("6r4s3dtoa", 38, (6, 7, 8), marks=pytest.mark.slow)])
def test_trace_test_passes_on_all_roots_and_fails_without_one(key, count, coordinates):
    """2D TOA 3r/3s (8 roots) with the pencil on every unknown, 3D TOA 6r/4s (38, 35 s: slow) on b: the
    complete set's trace is affine to rounding, the set without a root (any of three) is off by orders of
    magnitude."""
    system, q0, roots, other = _roots(key, count)
    options = trace.TraceOptions(seed=1, coordinates=coordinates)
    full = trace.trace_test_system(system, q0, roots, other, options)
    assert full.status == "passed" and full.residual < trace.PASS_TOL and full.failed_paths == 0, full
    assert full.roots == count and full.witnesses > 0
    for k in (0, count // 2, count - 1):
        short = trace.trace_test_system(system, q0, np.delete(roots, k, axis=0), other, options)
        assert short.status == "failed" and short.residual > 1e4 * trace.PASS_TOL, (k, short)


def test_trace_test_is_inconclusive_on_a_cut_witness_set_and_checks_its_inputs():
    """A witness monodromy cut short (one loop, not settled) gives no verdict, and points that are not roots
    are refused."""
    system, q0, roots, other = _roots("3r3stoa", 8)
    cut = trace.trace_test_system(system, q0, roots, other, trace.TraceOptions(seed=1, max_loops=1))
    assert cut.status == "inconclusive" and cut.witness_loops == 1
    with pytest.raises(tk.HomotopyError, match="not roots"):
        trace.trace_test_system(system, q0, roots + 0.1, other)


def test_union_of_two_seeds_finds_a_root_one_checkpoint_lacks(tmp_path, monkeypatch):
    """scripts/monodromy_counts.union: the second seed's roots carried to the first seed's instance pool to
    the full count (2D TOA 3r/3s, 8 roots); with a root deleted from the first checkpoint, the pool still has
    8 and counts the one only the second seed had (6r/6s 3D: 3919 and 3920 settled, pool 3920)."""
    import importlib.util
    import json
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("monodromy_counts",
                                                  Path(__file__).resolve().parents[1] / "scripts" / "monodromy_counts.py")
    counts = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(counts)
    monkeypatch.setenv("TDOA_WORKBENCH_CACHE", str(tmp_path))
    monkeypatch.setattr(counts, "CELLS", {"t": SOLVERS["3r3stoa"]})
    for seed in (0, 1):
        row, _ = counts.count("t", seed, loops=30, stall=6, seconds=1e9, trace_seconds=0)
        assert row["roots"] == 8 and row["status"] == "settled"
    pooled = counts.union("t", [0, 1])
    assert (pooled["union"], pooled["new"], pooled["lost"]) == (8, 0, 0)
    first = tmp_path / "monodromy" / "t-seed0.json"
    saved = json.loads(first.read_text())
    saved["roots"] = saved["roots"][1:]
    first.write_text(json.dumps(saved))
    pooled = counts.union("t", [0, 1])
    assert (pooled["union"], pooled["new"]) == (8, 1)


def test_paths_lost_on_the_straight_route_are_retracked_around_it(monkeypatch):
    """The pencil's tracks from t = 0 to t1, t2: two paths made to fail on the straight route (plain and tight)
    are retracked around it through a midpoint pushed sideways (trace._detours), and the test still passes on
    the whole, distinct fibre (2D TOA 3r/3s); without the detours, natural-parameter continuation
    (trace._continuation) recovers them; without both the same run is inconclusive."""
    system, q0, roots, other = _roots("3r3stoa", 8)
    straight = trace.TraceSystem.track

    def lossy(self, q0_, q1_, x0, inst=None, options=None):
        x, stats = straight(self, q0_, q1_, x0, inst, options)
        q0_, q1_ = np.atleast_2d(q0_), np.atleast_2d(q1_)
        if np.all(q0_[:, -1] == 0) and np.allclose(np.abs(q1_[:, -1]), 0.5):  # 0 -> t1, t2 straight: lose two paths
            x[:2] = np.nan
        return x, stats

    monkeypatch.setattr(trace.TraceSystem, "track", lossy)
    options = trace.TraceOptions(seed=1)
    test = trace.trace_test_system(system, q0, roots, other, options)
    assert test.status == "passed" and test.failed_paths == 0 and test.residual < trace.PASS_TOL, test
    monkeypatch.setattr(trace, "_detours", lambda *args, **kw: 0)  # the continuation fallback alone recovers them
    test = trace.trace_test_system(system, q0, roots, other, options)
    assert test.status == "passed" and test.failed_paths == 0 and test.residual < trace.PASS_TOL, test
    monkeypatch.setattr(trace, "_continuation", lambda *args, **kw: 0)
    assert trace.trace_test_system(system, q0, roots, other, options).status == "inconclusive"


def test_witness_points_on_the_roots_component_are_set_apart(monkeypatch):
    """Q_0 = {a . x = 1} u {lam = 0}: witness loops can reach the roots themselves (lam = 0; the 10r/4s loops
    reached all 6148). Mixed into the witnesses, they are summed once with the roots and the test passes
    (2D TOA 3r/3s); with one root left out of R but reached by the loops, it fails and says so."""
    system, q0, roots, other = _roots("3r3stoa", 8)
    count = md.monodromy_count

    def with_roots(*args, **kwargs):
        found = count(*args, **kwargs)
        return dataclasses.replace(found, roots=np.vstack([found.roots, np.column_stack([roots, np.zeros(len(roots))])]))

    monkeypatch.setattr(md, "monodromy_count", with_roots)
    options = trace.TraceOptions(seed=1)
    test = trace.trace_test_system(system, q0, roots, other, options)
    assert test.status == "passed" and test.failed_paths == 0 and test.residual < trace.PASS_TOL, test
    messages = []
    short = trace.trace_test_system(system, q0, roots[1:], other, options, progress=messages.append)
    assert short.status == "failed", short
    assert any("reached 1 root(s)" in m for m in messages), messages


def test_endpoints_off_the_fibre_count_as_failed_paths(monkeypatch):
    """trace._failed: an endpoint counts only where it is finite, converged (Newton's next step below
    WITNESS_TOL after two), off the excluded locus and on no other endpoint. Two tracks made to end off the fibre are
    retracked and the test passes (2D TOA 3r/3s); counted as points, as before this check, they make it fail
    (10r/4s: 3 of 284,128 tracks had slid onto the det H = 0 locus, residual 1.1e-5 instead of 2.3e-8)."""
    system, q0, roots, other = _roots("3r3stoa", 8)
    straight, criterion = trace.TraceSystem.track, trace._failed

    def drifting(self, q0_, q1_, x0, inst=None, options=None):
        x, stats = straight(self, q0_, q1_, x0, inst, options)
        q0_, q1_ = np.atleast_2d(q0_), np.atleast_2d(q1_)
        if options is None and np.all(q0_[:, -1] == 0) and np.allclose(np.abs(q1_[:, -1]), 0.5):
            x[:2] = x[:2] + 0.3 * (1.0 + np.abs(x[:2]))  # far from the fibre: not converged after two steps
        return x, stats

    monkeypatch.setattr(trace.TraceSystem, "track", drifting)
    options = trace.TraceOptions(seed=1)
    test = trace.trace_test_system(system, q0, roots, other, options)
    assert test.status == "passed" and test.failed_paths == 0 and test.residual < trace.PASS_TOL, test
    monkeypatch.setattr(trace, "_failed", lambda s, t, e, o, others=None: ~np.all(np.isfinite(e), axis=1))
    assert trace.trace_test_system(system, q0, roots, other, options).status == "failed"

    # the criterion on endpoints at t = 0: roots 0-2, root 0 again, not finite, root 3 moved off, root 4 masked
    ts = trace.TraceSystem(*slp.system_equations(system.name))
    N = len(system.unknowns)
    Q0 = np.concatenate([q0, np.zeros(len(q0)), np.ones(N) / N, [0.0]])
    good = ts.newton(np.column_stack([roots, np.zeros(len(roots))]), Q0[None], steps=2)
    ends = np.vstack([good[:3], good[:1], np.full((1, N + 1), np.nan), good[3:4] + 0.3, good[4:5]])
    bad = criterion(ts, Q0, ends, lambda y: np.all(np.isclose(y, good[4]), axis=1))
    assert bad.tolist() == [True, False, False, True, True, True, True]


def test_a_checkpoint_resumed_under_another_acceptance_counts_its_stall_again(tmp_path):
    """monodromy.monodromy_count: a checkpoint settled under START_TOL, resumed with the trace test's looser
    acceptance (WITNESS_TOL), keeps its roots and runs stall_loops more loops (the loops that found nothing under
    the old rule say nothing under the new one); resumed under the same rule it runs none."""
    label = SOLVERS["3r3stoa"]
    config = Formulation.parse(label).config
    system = from_formulation(label, saturate_det_h=True)
    F, x0 = complex_instance(config.m, config.n, np.random.default_rng(5), config.dim, config.model)
    solver, x0 = md.start_solver(system, F.ravel(), x0)
    path = str(tmp_path / "count.json")
    strict = tk.HomotopyOptions(seed=3, stall_loops=4)
    first = md.monodromy_count(solver, F.ravel(), x0, strict, 1e9, path, excluded=md._excluded(system, F.ravel()))
    assert len(first.roots) == 8 and first.stall == 4
    again = md.monodromy_count(solver, F.ravel(), x0, strict, 1e9, path)
    assert again.loops == first.loops
    messages = []
    loose = md.monodromy_count(solver, F.ravel(), x0, dataclasses.replace(strict, accept_tol=trace.WITNESS_TOL), 1e9,
                               path, progress=messages.append, excluded=md._excluded(system, F.ravel()))
    assert loose.loops == first.loops + 4 and len(loose.roots) == 8 and loose.stall == 4
    assert "start again" in messages[0]
