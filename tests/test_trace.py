"""The trace test (solvers.continuation.trace) on certified cells: it passes on the complete root set and fails
when one root (or one witness) is missing."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from analysis.formulations.parametric import from_formulation
from analysis.formulations.tdoa import Formulation
from solvers.continuation import monodromy as md
from solvers.continuation import graph, slp, trace
from solvers.continuation import tracking as tk
from solvers.generate import SOLVERS
from solvers.instances import complex_instance


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
    """A witness graph cut by its time cap gives no verdict, and points that are not roots are refused."""
    system, q0, roots, other = _roots("3r3stoa", 8)
    cut = trace.trace_test_system(system, q0, roots, other, trace.TraceOptions(seed=1, seconds=0.0))
    assert cut.status == "inconclusive" and cut.witness_loops == 0
    with pytest.raises(tk.HomotopyError, match="not roots"):
        trace.trace_test_system(system, q0, roots + 0.1, other)


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


def test_a_slice_whose_paths_fail_on_every_route_is_redrawn(monkeypatch):
    """Two paths to the first t1 made to fail on every route (the detours and the continuation fallback off): the
    slice is drawn again at another t of the same circle and the test passes on the whole fibre (2D TOA 3r/3s);
    with no redraw allowed the same run is inconclusive."""
    system, q0, roots, other = _roots("3r3stoa", 8)
    straight = trace.TraceSystem.track
    first: list[complex] = []

    def lossy(self, q0_, q1_, x0, inst=None, options=None):
        x, stats = straight(self, q0_, q1_, x0, inst, options)
        q0_, q1_ = np.atleast_2d(q0_), np.atleast_2d(q1_)
        if np.all(q0_[:, -1] == 0) and np.all(q1_[:, -1] != 0):  # the slices' tracks from t = 0
            t = q1_[np.zeros(len(x), dtype=np.int64) if inst is None else np.asarray(inst), -1]
            first.append(first[0] if first else t[0])  # the first slice's t1, as first drawn
            x[np.flatnonzero(t == first[0])[:2]] = np.nan
        return x, stats

    monkeypatch.setattr(trace.TraceSystem, "track", lossy)
    monkeypatch.setattr(trace, "_detours", lambda *args, **kw: 0)
    monkeypatch.setattr(trace, "_continuation", lambda *args, **kw: 0)
    messages = []
    test = trace.trace_test_system(system, q0, roots, other, trace.TraceOptions(seed=1), progress=messages.append)
    assert test.status == "passed" and test.redrawn == 1 and test.residual < trace.PASS_TOL, test
    assert any("slice 1 failed on every route; the slice redrawn" in m for m in messages), messages
    monkeypatch.setattr(trace, "REDRAWS", 0)
    first.clear()
    assert trace.trace_test_system(system, q0, roots, other, trace.TraceOptions(seed=1)).status == "inconclusive"


def test_witness_points_on_the_roots_component_are_set_apart(monkeypatch):
    """Q_0 = {a . x = 1} u {lam = 0}: the witness graph can reach the roots themselves (lam = 0; the 10r/4s loops
    reached all 6148). Mixed into the witnesses, they are summed once with the roots and the test passes
    (2D TOA 3r/3s); with one root left out of R but reached by the loops, it fails and says so."""
    system, q0, roots, other = _roots("3r3stoa", 8)
    count = graph.graph_monodromy

    def with_roots(*args, **kwargs):
        found = count(*args, **kwargs)
        return dataclasses.replace(found, roots=np.vstack([found.roots, np.column_stack([roots, np.zeros(len(roots))])]))

    monkeypatch.setattr(graph, "graph_monodromy", with_roots)
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
    monkeypatch.setattr(trace, "_failed", lambda s, t, e, o, others=None, group=None: ~np.all(np.isfinite(e), axis=1))
    # counted as points they never pass; their own Newton steps (6.9e-3) put the residual (2.4e-2) within the
    # rounding level, too inaccurate for a verdict: inconclusive, not "failed" (a verdict the points cannot carry)
    unchecked = trace.trace_test_system(system, q0, roots, other, options)
    assert unchecked.status == "inconclusive" and "rounding level" in unchecked.why, unchecked

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


def _short_graphs(monkeypatch, drops: list[int]):
    """Make the witness graph close short: its k-th run keeps all but the last drops[k] witnesses it found."""
    real = trace.graph.graph_monodromy
    calls = []

    def short(*args, **kwargs):
        result = real(*args, **kwargs)
        d = drops[min(len(calls), len(drops) - 1)]
        calls.append(len(result.roots))
        return dataclasses.replace(result, roots=result.roots[:len(result.roots) - d]) if d else result

    monkeypatch.setattr(trace.graph, "graph_monodromy", short)
    return calls


def test_a_witness_graph_that_closes_short_is_regrown_not_failed(monkeypatch):
    """2D TOA 3r/3s, the complete set of 8 roots: a witness graph that closes one short makes the trace nonzero;
    the regrowth (another graph from the witnesses found) finds the missing one and the test passes."""
    system, q0, roots, other = _roots("3r3stoa", 8)
    options = trace.TraceOptions(seed=1)
    calls = _short_graphs(monkeypatch, [1, 0])
    test = trace.trace_test_system(system, q0, roots, other, options)
    assert test.status == "passed" and len(calls) == 2 and "witnesses regrown" in test.why, test
    full = calls[-1]
    assert test.witnesses == full and test.why == f"witnesses regrown: {full - 1} -> {full}"


def test_the_witness_count_changing_at_every_regrowth_is_inconclusive(monkeypatch):
    """Each growth one witness fuller than the last, never whole: the trace stays nonzero, but the witness set never
    repeats, so the verdict is "inconclusive" (not enough witnesses), never "failed"."""
    system, q0, roots, other = _roots("3r3stoa", 8)
    calls = _short_graphs(monkeypatch, [3, 2, 1])
    test = trace.trace_test_system(system, q0, roots, other, trace.TraceOptions(seed=1))
    assert len(calls) == 1 + trace.REGROW
    assert test.status == "inconclusive" and "witness count differs between regrowths" in test.why, test


def test_a_missing_root_fails_on_a_confirmed_witness_set():
    """One root of 8 left out: the regrowth finds the same witnesses, so "failed" stands and says why."""
    system, q0, roots, other = _roots("3r3stoa", 8)
    test = trace.trace_test_system(system, q0, roots[1:], other, trace.TraceOptions(seed=1))
    assert test.status == "failed" and test.why.startswith("witness set confirmed by a second graph"), test


def test_a_witness_found_twice_counts_once(monkeypatch):
    """2D TOA 3r/3s: the witness graph returns one witness twice, as two points 4e-6 apart (relative; farther than
    graph.SAME, as an ill-conditioned witness's double-precision points are: 3D TOA 4r/6s, 1.5e-6). Both step above
    PRECISE, are refined at 160 bits onto the same point and count once: the test passes on the right witness count.
    Counted twice, the trace would be off by a whole point."""
    system, q0, roots, other = _roots("3r3stoa", 8)
    options = trace.TraceOptions(seed=1)
    clean = trace.trace_test_system(system, q0, roots, other, options)
    assert clean.status == "passed", clean
    real = trace.graph.graph_monodromy

    def twice(*args, **kwargs):
        result = real(*args, **kwargs)
        w = result.roots[0]
        size = 1.0 + np.linalg.norm(w)
        again = np.vstack([w + 2e-6 * size / np.sqrt(len(w)), w - 2e-6 * size / np.sqrt(len(w)), result.roots[1:]])
        return dataclasses.replace(result, roots=again)

    monkeypatch.setattr(trace.graph, "graph_monodromy", twice)
    test = trace.trace_test_system(system, q0, roots, other, options)
    assert test.status == "passed" and test.witnesses == clean.witnesses and test.residual < trace.PASS_TOL, test


def test_ball_newton_on_the_trace_tape_reaches_a_witness_at_high_precision():
    """certify.TapeBalls runs the trace system's Newton tape in arb: its values agree with the double-precision
    tape, and a witness moved by 1e-5 (relative) comes back to the witness to double rounding, flagged converged;
    a point far from the curve is not."""
    from solvers.continuation import certify, tape_kernel

    system, q0, roots, other = _roots("3r3stoa", 8)
    names = list(system.unknowns), list(system.parameters)
    equations = trace.system_equations(system)[0]
    pencil = trace.Pencil.build(equations, *names, q0, other, trace.TraceOptions(seed=1), None)
    y = pencil.start[0]
    balls = certify.TapeBalls(pencil.system.tapes, pencil.Q0)
    from flint import acb
    out = balls.run([np.array([acb(v.real, v.imag)], dtype=object) for v in y])
    ref = tape_kernel.run(pencil.system.tapes.newton,
                          np.concatenate([y, [0.0], pencil.Q0, np.zeros_like(pencil.Q0)])[:, None])[:, 0]
    got = np.array([complex(float(v[0].real.mid()), float(v[0].imag.mid())) for v in out])
    assert np.allclose(got, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    moved = y * (1.0 + 1e-5)
    far = y + 0.5 * (1.0 + np.abs(y))
    z, ok = balls.refine(np.vstack([moved, far]), steps=8)
    assert ok[0] and np.abs(z[0] - y).max() <= 1e-14 * (1.0 + np.abs(y).max()), np.abs(z[0] - y).max()
    assert not ok[1] and np.array_equal(z[1], far)


def test_graphs_agreeing_on_a_set_with_untrackable_witnesses_do_not_confirm_a_failure(monkeypatch):
    """A nonzero trace on a witness set that a second graph finds again is "failed" only where the graphs could reach
    every witness: with points among them that the tracker cannot start from or end on (their Newton step above its
    corrector tolerance: 3D TOA 4r/6s, two graphs agreed on 1,157 of 1,160 witnesses), it is "inconclusive". The
    same agreement on well-conditioned witnesses stays "failed"."""
    W = np.ones((5, 3), dtype=complex)

    def once(stalled):
        def run(*args, **kwargs):
            return trace.TraceTest("failed", 1e-6, 4, 5, 3, 100, 1.0, 0, 1e-12, stalled=stalled), W
        return run

    monkeypatch.setattr(trace, "_trace_once", once(2))
    test = trace.trace_test(None, ["x", "y"], ["a"], np.zeros(1), np.zeros((4, 2)), (np.zeros(1), np.zeros(2)))
    assert test.status == "inconclusive" and "too ill-conditioned for the double-precision tracker" in test.why, test
    monkeypatch.setattr(trace, "_trace_once", once(0))
    test = trace.trace_test(None, ["x", "y"], ["a"], np.zeros(1), np.zeros((4, 2)), (np.zeros(1), np.zeros(2)))
    assert test.status == "failed" and test.why == "witness set confirmed by a second graph (5)", test


def test_a_pass_far_above_the_rounding_level_regrows_its_witnesses(monkeypatch):
    """PASS_TOL admits a set short of a witness whose path in t is nearly affine (examples/fivepoint20.sys, seed 1: 425
    of 426 witnesses, residual 4.6e-11 against a rounding level of 1.7e-13). A pass more than SUSPECT times above the
    level regrows the witnesses, up to REGROW graphs: the regrown set is tested when it is larger; a pass whose set every
    regrowth finds again stands and says so; a pass near the level is not regrown."""
    def runs(*tests):
        calls = []

        def run(*args, **kwargs):
            calls.append(kwargs.get("regrow", 0))
            return tests[len(calls) - 1], np.ones((tests[len(calls) - 1].witnesses, 3), dtype=complex)
        monkeypatch.setattr(trace, "_trace_once", run)
        return calls

    def test_once():
        return trace.trace_test(None, ["x", "y"], ["a"], np.zeros(1), np.zeros((4, 2)), (np.zeros(1), np.zeros(2)))

    short = trace.TraceTest("passed", 5e-11, 4, 5, 3, 100, 1.0, 0, 2e-13)
    whole = trace.TraceTest("passed", 1e-13, 4, 6, 3, 100, 1.0, 0, 2e-13)
    calls = runs(short, whole)
    test = test_once()
    assert calls == [0, 1] and test.witnesses == 6 and test.why == "witnesses regrown: 5 -> 6", test
    calls = runs(short, short, whole)  # the first regrowth finds the same set, the second (more nodes) the whole
    test = test_once()
    assert calls == [0, 1, 2] and test.witnesses == 6 and test.why == "witnesses regrown: 5 -> 5 -> 6", test
    calls = runs(*[short] * (1 + trace.REGROW))
    test = test_once()
    assert calls == list(range(1 + trace.REGROW)) and test.status == "passed" and test.witnesses == 5, test
    assert test.why == (f"residual 250x the points' rounding level; witness set confirmed by {trace.REGROW} more graphs "
                        "(5)"), test
    calls = runs(trace.TraceTest("passed", 1e-12, 4, 5, 3, 100, 1.0, 0, 2e-13))
    assert test_once().why == "" and calls == [0]
