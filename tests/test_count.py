"""`count`: graph monodromy, Krawczyk proofs, seeds compared as sets, the trace test (solvers.count,
solvers.continuation.graph / certify / trace). Each test can fail: a missing solution, a fake one, a dropped
ill-conditioned one."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from analysis.formulations.parametric import parse
from solvers import count as counting
from solvers import count_evidence as evidence
from solvers.continuation import certify, graph, monodromy, trace

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CIRCLE = os.path.join(ROOT, "examples", "circle.sys")


@pytest.fixture(scope="module")
def toa3():
    """3r/3s TOA in 2D (8 solutions): its start, solver and the graph's closed set."""
    system, q0, x0, group = counting._start("3r3stoa", 0)
    solver, x0 = monodromy.start_solver(system, q0, x0, 0)
    excluded = monodromy._excluded(system, q0)
    result = graph.graph_monodromy(solver, q0, x0, graph.GraphOptions(), excluded=excluded)
    return system, q0, solver, excluded, result


def test_graph_closes_on_the_8_solutions_of_toa_3r3s(toa3):
    system, q0, solver, _, result = toa3
    assert result.closed and result.counts == (8, 8, 8, 8)
    assert len(result.roots) == 8
    # each is a solution: the system's residual at q0 vanishes
    assert np.max(monodromy.system_residuals(system, result.roots, q0)) < 1e-10
    # the graph tracked each solution about once per edge, not once per loop
    assert result.paths <= 8 * 6 * 2


def test_count_proves_8_and_the_seeds_agree_as_sets():
    result = counting.count("3r3stoa", counting.CountOptions(seeds=(0, 1)))
    assert result.count == 8 and result.proven == 8
    assert result.evidence.startswith("at least 8, proven")
    assert [s.closed for s in result.seeds] == [True, True]
    assert result.seeds[1].carried == "equal as sets"


def test_a_set_with_one_solution_removed_is_found_incomplete(toa3):
    system, q0, solver, excluded, result = toa3
    short = result.roots[1:]
    # another seed's complete set, carried to q0, lands outside the short set
    system1, q1, x1, _ = counting._start("3r3stoa", 1)
    solver1, x1 = monodromy.start_solver(system1, q1, x1, 1)
    other = graph.graph_monodromy(solver1, q1, x1, graph.GraphOptions(seed=1), excluded=monodromy._excluded(system1, q1))
    ends, ok = counting._carry(solver, q1, other.roots, q0, excluded, solver.options)
    words, outside = counting._compare(short, ends, ok, None)
    assert outside == 1 and words.startswith("not equal")
    # a graph started from the short set closes again on all 8 (the missing one is an image of the others)
    regrown = graph.graph_monodromy(solver, q0, short, graph.GraphOptions(seed=3), excluded=excluded)
    assert len(regrown.roots) == 8
    # and the trace test fails on it, passes on the whole set
    _, qs, xs, _ = counting._start("3r3stoa", 1000)
    full = trace.trace_test_system(system, q0, result.roots, (qs, xs), trace.TraceOptions())
    cut = trace.trace_test_system(system, q0, short, (qs, xs), trace.TraceOptions())
    assert full.status == "passed", full
    assert cut.status == "failed" and cut.residual > 1e3 * max(full.residual, 1e-15)


def test_a_further_seed_s_graph_carries_its_set_to_the_first_seed_s_q0_along_its_own_edges(toa3):
    """count's further seeds hold the first seed's q0 as node 1 (count.ANCHORED): the closed graph's set there is
    the set the separate carrying reached, equal to the first seed's; a set one short is still caught."""
    system, q0, solver, excluded, result = toa3
    system1, q1, x1, _ = counting._start("3r3stoa", 1)
    solver1, x1 = monodromy.start_solver(system1, q1, x1, 1)
    other = graph.graph_monodromy(solver1, q1, x1, graph.GraphOptions(seed=1), excluded=monodromy._excluded(system1, q1),
                                  anchors=q0[None])
    assert other.closed and np.array_equal(other.nodes[1], q0) and other.counts == (8, 8, 8, 8)
    at_q0 = other.node_roots[1]
    assert counting._compare(result.roots, at_q0, np.ones(8, dtype=bool), None) == ("equal as sets", 0)
    ends, ok = counting._carry(solver, q1, other.roots, q0, excluded, solver.options)
    assert ok.all() and counting._compare(at_q0, ends, ok, None) == ("equal as sets", 0)
    words, outside = counting._compare(result.roots[1:], at_q0, np.ones(8, dtype=bool), None)
    assert outside == 1 and words.startswith("not equal")
    with pytest.raises(ValueError, match="anchors"):
        graph.graph_monodromy(solver1, q1, x1, graph.GraphOptions(nodes=2), anchors=np.vstack([q0, q0]))


def test_a_fake_solution_is_never_certified(toa3):
    system, q0, _, _, result = toa3
    rng = np.random.default_rng(5)
    fakes = np.vstack([result.roots[:4] + 1e-3 * (1 + np.abs(result.roots[:4])),  # near a solution, not one
                       rng.normal(size=(4, result.roots.shape[1])) + 1j * rng.normal(size=(4, result.roots.shape[1]))])
    cert = certify.certify(system, q0, fakes)
    assert not cert.proven.any()
    good = certify.certify(system, q0, result.roots)
    assert good.proven.all()
    # the same solution twice: its two boxes meet, so it is not counted twice
    twice = certify.certify(system, q0, np.vstack([result.roots, result.roots[:1]]))
    meets = certify.disjoint(twice.centres, twice.radii)
    assert meets[0] and meets[-1] and not meets[1:-1].any()


def test_boxes_and_their_images_are_checked_disjoint():
    centres = np.array([[1.0 + 0j, 2.0], [-1.0, 2.0], [3.0, 4.0]])
    radii = np.full(3, 1e-9)
    signs = np.array([[1.0, 1.0], [-1.0, 1.0]])
    assert not certify.disjoint(centres[[0, 2]], radii[:2], signs).any()
    meets = certify.disjoint(centres, radii, signs)  # row 1 is row 0's image: one orbit, counted once
    assert meets[0] and meets[1] and not meets[2]


def test_an_ill_conditioned_solution_is_kept_and_proven():
    """2D 6r/3s, seed 0: three of its 180 solutions fail Krawczyk's test in double precision and are proven at
    HIGH_PRECISION bits; none is dropped."""
    result = counting.count("6r3s", counting.CountOptions(seeds=(0,)))
    assert result.count == 180 and result.proven == 180
    system, q0, x0, _ = counting._start("6r3s", 0)
    solver, x0 = monodromy.start_solver(system, q0, x0, 0)
    roots = graph.graph_monodromy(solver, q0, x0, graph.GraphOptions(), excluded=monodromy._excluded(system, q0)).roots
    cert = certify.certify(system, q0, roots)
    assert cert.proven.all() and (cert.bits == certify.HIGH_PRECISION).sum() >= 1


class _Stalling:
    """A stand-in system whose Newton steps stall at a relative size of 1e-7 (an ill-conditioned solution in
    double precision): the graph's acceptance keeps such an endpoint, a solver's 1e-8 would not."""

    def newton(self, x, q, steps=1, inst=None):
        return x * (1.0 + 1e-7)


def test_the_graph_keeps_an_endpoint_whose_newton_step_stalls_at_1e_7():
    x = np.array([[3000.0 + 1j, 2.0]])
    _, ok = graph._accept(_Stalling(), x, np.zeros((1, 1)), np.zeros(1, dtype=np.int64), graph.GraphOptions().accept_tol, None)
    assert ok.all()
    _, strict = graph._accept(_Stalling(), x, np.zeros((1, 1)), np.zeros(1, dtype=np.int64), 1e-8, None)
    assert not strict.any()


def test_count_a_user_system_finds_all_4_even_where_one_graph_closes_on_1():
    """examples/circle.sys, seed 1: the closed 4-node graph holds 1 of the 4 solutions (its triangles wind around
    no branch point); seed 0's set carried there has more, and the graphs run again from the union."""
    system = parse(open(CIRCLE, encoding="utf-8").read(), "circle")
    result = counting.count(system, counting.CountOptions(seeds=(1, 0)))
    assert result.count == 4 and result.proven == 4, result.summary()
    assert any("ran again" in n for n in result.notes)


def test_cli_count_prints_the_evidence_and_refuses_a_plain_system():
    run = subprocess.run([sys.executable, "-m", "solvers.cli", "count", "--tdoa", "3r3s", "--model", "toa"],
                         capture_output=True, text=True, cwd=ROOT)
    assert run.returncode == 0, run.stderr
    assert "evidence: at least 8, proven" in run.stdout
    bad = subprocess.run([sys.executable, "-m", "solvers.cli", "count", os.path.join(ROOT, "examples", "katsura4.ms")],
                         capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr and "degree" in bad.stderr
    # an unwritable --json is refused before the count runs, not after it
    nowhere = subprocess.run([sys.executable, "-m", "solvers.cli", "count", "--tdoa", "5r9s", "--dim", "3", "--json",
                              os.path.join(ROOT, "no-such-folder", "out.json")], capture_output=True, text=True,
                             cwd=ROOT, timeout=60)
    assert nowhere.returncode == 2 and "cannot write" in nowhere.stderr and "(--json)" in nowhere.stderr
    assert "Traceback" not in nowhere.stderr and len(nowhere.stderr.strip().splitlines()) == 1


class _SegmentBlocked:
    """A stand-in system with the solutions 1, 2, 3 (one unknown) at every parameter, whose tracks of the first
    point fail on every leg that ends at qb coming along the straight segment qa -> qb (a branch point sitting on
    the segment, close enough that tight steps and local detours all fail): only a route leaving the segment
    gets it there."""

    def __init__(self, qa, qb):
        self.qa, self.qb = qa, qb

    def newton(self, x, q, steps=1, inst=None):
        return np.round(x.real) + 0j

    def track(self, q0, q1, x0, inst=None, options=None):
        q0 = np.broadcast_to(q0, (len(x0), len(self.qa))) if np.ndim(q0) == 2 and len(q0) == 1 else q0
        inst = np.zeros(len(x0), dtype=np.int64) if inst is None else inst
        out = x0.copy()
        d = self.qb - self.qa
        for k in range(len(x0)):
            a, b = np.atleast_2d(q0)[min(inst[k], len(np.atleast_2d(q0)) - 1)], np.atleast_2d(q1)[min(inst[k], len(np.atleast_2d(q1)) - 1)]
            if x0[k, 0].real == 1.0 and np.allclose(b, self.qb) and self.blocked(a):
                out[k] = np.nan
        return out, np.full((len(x0), 4), 0.5)

    def blocked(self, a) -> bool:
        """Whether a leg into qb from a fails: here when a lies on the segment qa -> qb."""
        d = self.qb - self.qa
        t = np.vdot(d, a - self.qa) / np.vdot(d, d)
        return abs(t.imag) < 1e-12 and np.linalg.norm(a - self.qa - t.real * d) < 1e-12


def test_a_carried_path_blocked_on_its_segment_goes_round_through_a_midpoint():
    qa, qb = np.array([0.0 + 0j, 1.0]), np.array([1.0 + 0j, 0.0])
    solver = _SegmentBlocked(qa, qb)
    xs = np.array([[1.0 + 0j], [2.0], [3.0]])
    ends, ok = counting._carry(solver, qa, xs, qb, None, None)
    assert ok.all() and np.allclose(ends, xs)
    words, outside = counting._compare(xs, ends, ok, None)
    assert words == "equal as sets" and outside == 0
    # without the midpoint routes the path is lost, unless natural-parameter continuation (no tracker) carries it
    old, counting.CARRY_ROUTES = counting.CARRY_ROUTES, 0
    steps, counting.NATURAL_STEPS = counting.NATURAL_STEPS, 0
    try:
        ends, ok = counting._carry(solver, qa, xs, qb, None, None)
        assert ok.tolist() == [False, True, True]
        counting.NATURAL_STEPS = 5
        ends, ok = counting._carry(solver, qa, xs, qb, None, None)
        assert ok.all() and np.allclose(ends, xs)
    finally:
        counting.CARRY_ROUTES, counting.NATURAL_STEPS = old, steps


def test_the_trace_test_runs_on_orbits_without_expanding_them():
    """2D TOA 3r/3s in the direct parametrization: one solution per orbit of the gauge frame's 4 reflections, no
    coordinate invariant. The test runs on the orbits (the pencil and the traces on the squares of the flipped
    coordinates): the 8 orbits pass at rounding level, and with any one left out it fails by 8 orders of magnitude
    or more."""
    label = "3r3s-toa2d-direct:all"
    system, q0, x0, group = counting._start(label, 0)
    assert group is not None and len(group) == 4 and not (group == 1).all(axis=0).any()
    solver, x0 = monodromy.start_solver(system, q0, x0, 0)
    roots = graph.graph_monodromy(solver, q0, x0, graph.GraphOptions(), group=group,
                                  excluded=monodromy._excluded(system, q0)).roots
    assert len(roots) == 8
    _, qs, xs, _ = counting._start(label, 1000)
    whole = trace.trace_test_system(system, q0, roots, (qs, xs), trace.TraceOptions(), group=group)
    assert whole.status == "passed" and whole.residual < 1e-12, whole
    assert whole.witnesses > 0
    for cut in (0, 5):
        short = trace.trace_test_system(system, q0, np.delete(roots, cut, axis=0), (qs, xs), trace.TraceOptions(),
                                        group=group)
        assert short.status == "failed" and short.residual > 1e6 * whole.residual, short
    # a point fixed by a reflection counts once per distinct image
    signs = np.array([[1.0, 1.0], [1.0, -1.0]])
    assert trace._orbit_sizes(np.array([[1.0 + 0j, 2.0], [1.0, 0.0]]), signs).tolist() == [2.0, 1.0]


class _EndBlocked(_SegmentBlocked):
    """As :class:`_SegmentBlocked`, but the first point's tracks fail on every route into qb (an ill-conditioned
    solution there that no track arriving reaches), while the track leaving it for qa does not fail."""

    def blocked(self, a) -> bool:
        return True


def test_a_carried_path_lost_on_every_route_is_joined_from_the_other_end():
    qa, qb = np.array([0.0 + 0j, 1.0]), np.array([1.0 + 0j, 0.0])
    solver = _EndBlocked(qa, qb)
    xs = np.array([[1.0 + 0j], [2.0], [3.0]])
    steps, counting.NATURAL_STEPS = counting.NATURAL_STEPS, 0  # the stand-in's Newton steps are not blocked
    try:
        ends, ok = counting._carry(solver, qa, xs, qb, None, None)
    finally:
        counting.NATURAL_STEPS = steps
    assert ok.tolist() == [False, True, True]
    known = np.array([[3.0 + 0j], [1.0], [2.0]])
    joined = counting._reverse(solver, qb, known, qa, xs, ends, ok, None, None, None)
    assert joined.all() and np.allclose(ends, xs)
    assert counting._compare(known, ends, joined, None) == ("equal as sets", 0)
    # a known set without the first point's solution: nothing to join it to, and the comparison says so
    steps, counting.NATURAL_STEPS = counting.NATURAL_STEPS, 0
    try:
        ends, ok = counting._carry(solver, qa, xs, qb, None, None)
    finally:
        counting.NATURAL_STEPS = steps
    short = np.array([[3.0 + 0j], [2.0]])
    assert not counting._reverse(solver, qb, short, qa, xs, ends, ok, None, None, None)[0]


def test_the_trace_witness_checkpoint_is_named_by_its_pencil(tmp_path):
    """A resumable witness file belongs to one pencil: another pencil's run must not overwrite it."""
    result = counting.count("3r3stoa", counting.CountOptions(seeds=(0,), certify=False, trace=True,
                                                             checkpoints=str(tmp_path)))
    assert result.trace["status"] == "passed", result.trace
    names = sorted(p.name for p in tmp_path.iterdir() if "witnesses" in p.name)
    # the compaction formulation's pencil is b (count_evidence.pencil_coordinates)
    assert names == ["3r3s_toa2d_A_B2_B3_C2_C3-seed0-witnesses-b1-b2.json"], names


@pytest.mark.slow
def test_the_direct_tdoa_pencil_is_on_the_offsets_where_they_determine_each_orbit():
    """2D TDOA 6r/3s, direct parametrization (180 orbits of the 4 reflections): given the offsets the data are
    TOA data, and F4 finds the system with the offsets fixed, down to o1 alone, with 4 solutions (the group's
    order) over GF(p): o1 determines each orbit and carries the trace test. Its pencil has a tenth of the witnesses
    of every unknown's (734 against 7,384), passes on the whole set and fails with one orbit removed."""
    label = "6r3s-tdoa2d-direct:all"
    system, q0, x0, group = counting._start(label, 0)
    coordinates, words = evidence.pencil_coordinates(system, group, lambda msg: None)
    assert [system.unknowns[k] for k in coordinates] == ["o1"] and "4 solutions" in words
    solver, x0 = monodromy.start_solver(system, q0, x0, 0)
    roots = graph.graph_monodromy(solver, q0, x0, graph.GraphOptions(), group=group,
                                  excluded=monodromy._excluded(system, q0)).roots
    assert len(roots) == 180
    _, qs, xs, _ = counting._start(label, 1000)
    options = trace.TraceOptions(coordinates=coordinates)
    whole = trace.trace_test_system(system, q0, roots, (qs, xs), options, group=group)
    assert whole.status == "passed" and whole.residual < 1e-11 and whole.witnesses < 7384 / 5, whole
    short = trace.trace_test_system(system, q0, roots[1:], (qs, xs), options, group=group)
    assert short.status == "failed" and short.residual > 1e5 * whole.residual, short
