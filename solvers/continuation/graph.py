"""Monodromy on a complete graph of parameter nodes: the solutions of a parametric system at a generic point.

The loops of :func:`solvers.continuation.monodromy.monodromy_count` (triangles from the base point, every known
solution tracked around each) spend most of their paths re-tracking what is known: on 7r/5s 71 % of the paths
were the loops that found nothing new. Here (Duff, Hill, Jensen, Lee, Leykin, Sommars, "Solving polynomial
systems via homotopy continuation and monodromy", IMA J. Numer. Anal. 39 (2019) 1421-1446, the complete-graph
strategy of HomotopyContinuation.jl's ``monodromy_solve``) the parameter space holds K nodes (the base point
q0 and K - 1 random complex points), each with its own set of known solutions, joined by straight segments
(every pair: K (K - 1) / 2 edges). A solution at node i is tracked along each edge (i, j) at most once; its
endpoint is kept at node j (a new solution there when no known one, or no image of one under ``group``, is
within 1e-6 relative). A segment tracked back is the inverse path, so the endpoint's own track back along
(j, i) is known without tracking it: each edge carries a partial bijection between its two nodes' solutions,
and every solution is tracked once per edge, not once per loop.

The graph is *closed* when every solution at every node has its image along every edge: every node then holds
the same number of solutions, a set closed under the monodromy of all the graph's loops. For an irreducible
solution variety and generic nodes those loops generate the whole monodromy group (loc. cit.), so a closed
graph holds every solution, with probability one; a path that failed (lost, not converged, or landing where
another solution's image already lands: path jumping) leaves its edge open, and it is retracked with tight
step control (:data:`RETRIES` times) before the graph is reported as not closed. A closed graph is numerical
evidence, not a proof: :mod:`.certify` proves each solution (ball arithmetic), and the trace test
(:mod:`.trace`) tells whether the set is complete.

The system is any object with ``track(q0, q1, x0, inst, options)`` and ``newton(x, q, steps, inst)`` in the
form of :class:`solvers.continuation.tracking.HomotopySolver` (the trace test's :class:`.trace.TraceSystem` too).
"""
from __future__ import annotations

import dataclasses
import json
import os
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from . import tracking as _tracking
from . import tracker

__all__ = ["GraphOptions", "GraphCount", "graph_monodromy", "RETRIES"]

#: Local detours (half-width d in the segment's parameter, side) tried in turn for a (solution, edge) whose
#: straight track failed, plain and tight (:func:`_local_detours`); the wider ones for a stall where several
#: solutions meet (3D TOA 4r/6s seed 1: four paths stalling at one s, recovered at d = 0.05).
DETOURS = ((0.005, 1.0), (0.005, -1.0), (0.02, 1.0), (0.02, -1.0), (0.05, 1.0), (0.05, -1.0), (0.1, 1.0),
           (0.1, -1.0))

#: Step control of the straight retracks of a (solution, edge) whose plain track failed, in turn: tight steps,
#: then tight steps with no practical limit on their number (4r/5s: a path crawls through an ill-conditioned
#: stretch in 5,500 RK4 steps, more than TIGHT's 4,000; the Pade predictor took 15,000 there).
STRAIGHT = (tracker.TIGHT, dataclasses.replace(tracker.TIGHT, max_steps=100_000, predictor="rk4"))

#: Retracks of a (solution, edge) whose track failed before the pair is left open: the straight ones, then the
#: local detours.
RETRIES = len(STRAIGHT) + len(DETOURS)

#: Each round tracks the pending (solution, edge) pairs of every edge one way (i < j), then the other way only those
#: still unknown: a track gives its pair's image both ways, and in one batch of both ways a pair pending at both ends
#: was tracked twice (5r/9s seed 0: 221,924 paths on, 259,603 off, for 6 edges x 36,947 solutions = 221,682 images).
#: It was off for a while: it moved the trace test's verdict on 3D TOA 4r/6s (every unknown), which had passed a set
#: of 1,154 of the 1,160 witnesses within a rounding level inflated by unrefined ill-conditioned points, and
#: failed 1,159; the test now refines those points (trace.PRECISE) and passes only the complete set (docs/count.md).
TWO_WAY = True

#: Independent loops the graph keeps when edges with failed tracks leave it (the complete graph on 4 nodes has 3).
MIN_LOOPS = 2

#: Endpoints whose Newton step stalls between the acceptance tolerance and this get a refinement in higher
#: precision (``refine`` of :func:`graph_monodromy`) before they are rejected.
BORDER = 1e-2

#: Relative distance under which two endpoints are one solution (as :func:`monodromy.add_new`).
SAME = 1e-6


@dataclass(frozen=True)
class GraphOptions:
    """nodes: K, the parameter points (the base point and K - 1 random ones); seed: their rng; radius: the
    random nodes are q0 + radius |q0|_rms (N(0, 1) + i N(0, 1)) (``free``: only those parameters move);
    accept_tol: an endpoint is a solution when Newton's next step after three is below this, relative (looser
    than a solver's 1e-8: ill-conditioned solutions of norm 10^3-10^6 stall at 1e-7-1e-5 in double precision,
    and dropping one leaves a count short; :mod:`.certify` proves or refutes each kept one afterwards);
    target: stop as soon as node 0 holds this many (a count known otherwise); seconds: wall-time cap (the
    graph is then not closed); tracker: the tracking options (None: the system's); retries: at most this many of
    the :data:`RETRIES` retracks of a failed track (None: all; the trace test's witnesses take the tight one only,
    the test itself telling whether a point is missing)."""

    nodes: int = 4
    seed: int = 0
    radius: float = 1.0
    accept_tol: float = 1e-6
    target: int | None = None
    seconds: float = float("inf")
    tracker: tracker.TrackerOptions | None = None
    retries: int | None = None

    def __post_init__(self) -> None:
        if self.nodes < 2:
            raise ValueError(f"a monodromy graph needs at least 2 nodes, not {self.nodes}")


@dataclass(frozen=True)
class GraphCount:
    """The outcome: the solutions at the base point (one per orbit with a group), every node's count, the
    nodes, the paths tracked, the rounds, the (solution, edge) pairs left open, whether the graph closed, the
    seconds (this run and the checkpoint it resumed), the jumps seen, every node's solutions, the edges left and
    whether the run ended for want of work (not cut by ``seconds`` or stopped at ``target``)."""

    roots: np.ndarray
    counts: tuple[int, ...]
    nodes: np.ndarray
    paths: int
    rounds: int
    open_edges: int
    closed: bool
    seconds: float
    jumps: int = 0
    node_roots: tuple = field(default=(), repr=False, compare=False)
    edges: int = 0
    finished: bool = True


class _Node:
    """One node's solutions and, per other node, the image index of each (-1: not known yet) and the failed
    tracks of each."""

    def __init__(self, q: np.ndarray, K: int, k: int, N: int):
        self.q = q
        self.roots = np.zeros((0, N), dtype=complex)
        self.image = {j: np.zeros(0, dtype=np.int64) for j in range(K) if j != k}
        self.tries = {j: np.zeros(0, dtype=np.int64) for j in range(K) if j != k}

    def add(self, xs: np.ndarray) -> np.ndarray:
        """Append solutions; their indices."""
        start = len(self.roots)
        self.roots = np.vstack([self.roots, xs])
        for j in self.image:
            self.image[j] = np.concatenate([self.image[j], np.full(len(xs), -1, dtype=np.int64)])
            self.tries[j] = np.concatenate([self.tries[j], np.zeros(len(xs), dtype=np.int64)])
        return np.arange(start, len(self.roots))


def _match(known: np.ndarray, xs: np.ndarray, group: np.ndarray | None) -> np.ndarray:
    """For each x of xs (M, N): the index of the known solution (K, N) it is (or an image of it under
    ``group``) within SAME relative, else -1 (sorted projections, :class:`tracking._Projected`)."""
    out = np.full(len(xs), -1, dtype=np.int64)
    if not len(known) or not len(xs):
        return out
    images = np.ones((1, known.shape[1])) if group is None else np.asarray(group, dtype=float)
    tol = SAME * (1.0 + np.linalg.norm(xs, axis=1))
    index = _tracking._Projected(known)
    for g in images:
        lo, hi = index.windows(index.project(xs, g), tol)
        for i in np.flatnonzero((hi > lo) & (out < 0)):
            cand = index.order[lo[i]:hi[i]]
            d = np.linalg.norm(known[cand] - g * xs[i], axis=1)
            if d.min() <= tol[i]:
                out[i] = cand[int(np.argmin(d))]
    return out


def _distinct_new(xs: np.ndarray, group: np.ndarray | None) -> np.ndarray:
    """For the points xs (M, N), none of them known: the index among xs of the first point each one is (itself
    when first), in order. One sorted-projection index over xs (:class:`tracking._Projected`), each point compared
    only with the earlier first points in its window (a round brings thousands of new solutions: 5r/9s)."""
    rep = np.arange(len(xs))
    if len(xs) < 2:
        return rep
    images = np.ones((1, xs.shape[1])) if group is None else np.asarray(group, dtype=float)
    tol = SAME * (1.0 + np.linalg.norm(xs, axis=1))
    index = _tracking._Projected(xs)
    windows = [index.windows(index.project(xs, g), tol) for g in images]
    for i in range(len(xs)):
        for g, (lo, hi) in zip(images, windows):
            cand = index.order[lo[i]:hi[i]]
            cand = cand[(cand < i) & (rep[cand] == cand)]
            if len(cand):
                d = np.linalg.norm(xs[cand] - g * xs[i], axis=1)
                if d.min() <= tol[i]:
                    rep[i] = cand[int(np.argmin(d))]
                    break
    return rep


def _accept(system, xs: np.ndarray, q: np.ndarray, inst: np.ndarray, tol: float,
            excluded: Callable | None, refine: Callable | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The endpoints xs (M, N) at parameters q[inst] polished by three Newton steps, and the mask of those that
    are solutions: finite, the next Newton step below ``tol`` relative to 1 + |x|, off the excluded locus.
    ``refine(points, q_rows) -> (points, mask)``: a second chance for endpoints whose step stalls between tol
    and :data:`BORDER` (Newton's method in higher precision, :func:`.certify.refine`)."""
    ok = np.all(np.isfinite(xs), axis=1)
    out = xs.copy()
    if ok.any():
        with np.errstate(all="ignore"):
            y = system.newton(xs[ok], q, steps=3, inst=inst[ok])
            step = np.linalg.norm(system.newton(y, q, steps=1, inst=inst[ok]) - y, axis=1) / (1.0 + np.linalg.norm(y, axis=1))
        good = np.isfinite(step) & (step < tol) & np.all(np.isfinite(y), axis=1)
        border = np.flatnonzero(np.isfinite(step) & (step >= tol) & (step < BORDER) & np.all(np.isfinite(y), axis=1))
        if refine is not None and len(border):
            y[border], good[border] = refine(y[border], q[inst[ok][border]])
        if excluded is not None and good.any():
            sub = np.flatnonzero(good)
            good[sub] &= ~excluded(y[sub], q[inst[ok][sub]])
        out[ok] = y
        ok[ok] = good
    return out, ok


def _local_detours(system, edges: list[tuple[np.ndarray, np.ndarray]], xs: np.ndarray, inst: np.ndarray,
                   d: float, side: float) -> tuple[np.ndarray, int]:
    """Track xs (M, N), path p along edge edges[inst[p]] = (qa, qb), around the point where its straight track
    stalls: tight steps to s* - d, through s* + i side d, to s* + d, on to qb (q(s) = qa + s (qb - qa)). A
    straight segment that passes near a branch point (two solutions meeting) loses its path on both ends, tight
    steps or not; a small loop on the side away from the branch point is homotopic to the segment and ends where
    the segment was heading, on the other side it swaps the two (:func:`_record` keeps only an endpoint that
    leaves the edge's correspondence one-to-one). Returns the endpoints and the segments tracked."""
    qa = np.array([e[0] for e in edges])[inst]
    qb = np.array([e[1] for e in edges])[inst]
    rows = np.arange(len(xs))
    _, stats = system.track(qa, qb, xs, rows, tracker.TIGHT)
    at = np.clip(stats[:, 3], d, 1.0 - d)
    dq = qb - qa
    ways = [[qa[p], qa[p] + (at[p] - d) * dq[p], qa[p] + (at[p] + 1j * side * d) * dq[p], qa[p] + (at[p] + d) * dq[p],
             qb[p]] for p in rows]
    ends, tracked = _track_routes(system, ways, xs, rows, tracker.TIGHT)
    return ends, tracked + len(xs)


def _track_routes(system, ways: list[list[np.ndarray]], xs: np.ndarray, inst: np.ndarray,
                  options) -> tuple[np.ndarray, int]:
    """Track xs (M, N), path p along the route ways[inst[p]] (a list of parameter points), leg by leg in one
    batch per leg; NaN rows where a leg failed. Returns the endpoints and the segments tracked."""
    ends = xs.copy()
    tracked = 0
    legs = np.array([len(w) - 1 for w in ways])
    for leg in range(int(legs.max())):
        rows = np.flatnonzero((legs[inst] > leg) & np.all(np.isfinite(ends), axis=1))
        if not len(rows):
            continue
        edges = np.unique(inst[rows])
        local = np.searchsorted(edges, inst[rows])
        qa = np.array([ways[e][leg] for e in edges])
        qb = np.array([ways[e][leg + 1] for e in edges])
        out, _ = system.track(qa, qb, ends[rows], local, options)
        ends[rows] = out
        tracked += len(rows)
    return ends, tracked


def _save(path: str, record: dict) -> None:
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as fh:
        json.dump(record, fh)
    os.replace(tmp, path)


def _pairs(z: np.ndarray) -> list:
    return np.stack([z.real, z.imag], axis=-1).tolist()


def _complex(rows) -> np.ndarray:
    a = np.asarray(rows, dtype=float)
    return a[..., 0] + 1j * a[..., 1]


def graph_monodromy(system, q0: np.ndarray, x0: np.ndarray, options: GraphOptions = GraphOptions(), *,
                    group: np.ndarray | None = None, excluded: Callable | None = None,
                    free: np.ndarray | None = None, checkpoint: str | None = None,
                    progress: Callable[[str], None] | None = None, refine: Callable | None = None,
                    anchors: np.ndarray | None = None) -> GraphCount:
    """Solutions of ``system`` at q0 (P,) from the one solution x0 (N,) (or several, (R, N)) by monodromy on a
    complete graph of ``options.nodes`` parameter nodes (module docstring).

    group: sign vectors (G, N) of a group acting on the solutions for every parameter (the direct
    parametrization's gauge reflections): one solution per orbit is kept and tracked. excluded: mask(x, q)
    of points on the locus of the non-vanishing conditions (never kept). free: mask of the parameters the
    random nodes move (the trace test's witnesses keep its pencil parameter at 0). checkpoint: a JSON file
    written every minute and at the end, resumed from when it exists for the same q0, options and group.
    refine: a second chance for endpoints whose Newton step stalls (:func:`_accept`). anchors: parameter points
    (A, P), A < K, taken as nodes 1..A in place of random ones (count's further seeds take the first seed's q0: a
    closed graph then holds its set carried there, :attr:`GraphCount.node_roots`).
    Each round tracks every (solution, edge) whose image is not known yet, in two batches (:data:`TWO_WAY`): the
    edges i -> j with i < j, then the other way what the first batch left unknown.
    """
    t0 = time.perf_counter()
    q0 = np.asarray(q0, dtype=complex)
    x0 = np.atleast_2d(np.asarray(x0, dtype=complex))
    N, P, K = x0.shape[1], len(q0), options.nodes
    rng = np.random.default_rng(options.seed)
    scale = np.sqrt(np.mean(np.abs(q0) ** 2))
    qs = [q0]
    for _ in range(K - 1):
        q = q0 + options.radius * scale * (rng.normal(size=P) + 1j * rng.normal(size=P))
        qs.append(np.where(free, q, q0) if free is not None else q)
    anchors = np.zeros((0, P), dtype=complex) if anchors is None else np.atleast_2d(np.asarray(anchors, dtype=complex))
    if len(anchors) >= K or anchors.shape[1] != P:
        raise ValueError(f"anchors: fewer than {K} parameter points of {P} parameters, not {anchors.shape}")
    qs[1:1 + len(anchors)] = list(anchors)  # (the random draws of the other nodes as without anchors)
    nodes = [_Node(q, K, k, N) for k, q in enumerate(qs)]
    first = _distinct_new(x0, group)
    nodes[0].add(x0[first == np.arange(len(x0))])
    paths = rounds = jumps = 0
    spent = 0.0
    key = {"q0": _pairs(q0), "nodes": K, "seed": options.seed, "radius": options.radius,
           "accept_tol": options.accept_tol, "group": 0 if group is None else len(group), "N": N}
    if len(anchors):
        key["anchors"] = _pairs(anchors)
    if checkpoint and os.path.exists(checkpoint):
        with open(checkpoint, encoding="utf-8") as fh:
            saved = json.load(fh)
        if saved.get("key") == key:
            for node, s in zip(nodes, saved["nodes"]):
                node.roots = _complex(s["roots"]).reshape(-1, N)
                node.image = {int(j): np.array(v, dtype=np.int64) for j, v in s["image"].items()}
                node.tries = {int(j): np.array(v, dtype=np.int64) for j, v in s["tries"].items()}
            paths, rounds, jumps, spent = saved["paths"], saved["rounds"], saved["jumps"], saved["seconds"]
            if progress:
                progress(f"resumed from {checkpoint}: {len(nodes[0].roots)} solutions at the base point, "
                         f"{paths} paths, {rounds} rounds")
    plain = options.tracker or system.options
    retries = RETRIES if options.retries is None else min(options.retries, RETRIES)
    last_save = time.perf_counter()

    def record() -> dict:
        return {"key": key, "paths": paths, "rounds": rounds, "jumps": jumps,
                "seconds": round(spent + time.perf_counter() - t0, 1),
                "nodes": [{"roots": _pairs(n.roots), "image": {str(j): v.tolist() for j, v in n.image.items()},
                           "tries": {str(j): v.tolist() for j, v in n.tries.items()}} for n in nodes]}

    while True:
        if options.target is not None and len(nodes[0].roots) >= options.target:
            break
        if time.perf_counter() - t0 >= options.seconds:
            break
        # every (solution, edge) whose image is unknown and whose retracks are not used up
        work = [(i, j, np.flatnonzero((n.image[j] < 0) & (n.tries[j] <= retries)))
                for i, n in enumerate(nodes) for j in n.image]
        if not any(len(idx) for _, _, idx in work):
            break
        rounds += 1
        tally = []  # per retry level tracked this round: (level, paths, failed, seconds)
        for phase, attempt in [(p, a) for p in range(2 if TWO_WAY else 1) for a in range(retries + 1)]:
            if TWO_WAY and attempt == 0:
                # the edges one way (i < j), then the other way, on what the first way left unknown: a track
                # i -> j gives the pair's image both ways, so the solutions it reaches at j are not tracked back
                work = [(i, j, np.flatnonzero((n.image[j] < 0) & (n.tries[j] <= retries)))
                        for i, n in enumerate(nodes) for j in n.image if (i < j) == (phase == 0)]
            work = [(i, j, idx) for i, j, idx in work if len(idx)]
            part = [(i, j, idx[nodes[i].tries[j][idx] == attempt]) for i, j, idx in work]
            part = [(i, j, idx) for i, j, idx in part if len(idx)]
            if not part:
                continue
            t_level = time.perf_counter()
            qb = np.array([nodes[j].q for _, j, _ in part])
            inst = np.concatenate([np.full(len(idx), e) for e, (_, _, idx) in enumerate(part)])
            xs = np.vstack([nodes[i].roots[idx] for i, _, idx in part])
            if attempt < len(STRAIGHT) + 1:
                ways = [[nodes[i].q, nodes[j].q] for i, j, _ in part]
                ends, tracked = _track_routes(system, ways, xs, inst, STRAIGHT[attempt - 1] if attempt else plain)
            else:
                ends, tracked = _local_detours(system, [(nodes[i].q, nodes[j].q) for i, j, _ in part], xs, inst,
                                               *DETOURS[attempt - 1 - len(STRAIGHT)])
            paths += tracked
            ends, ok = _accept(system, ends, qb, inst, options.accept_tol, excluded, refine)
            tally.append((attempt, len(xs), int((~ok).sum()), time.perf_counter() - t_level))
            start = 0
            for e, (i, j, idx) in enumerate(part):
                sl = slice(start, start + len(idx))
                start += len(idx)
                jumps += _record(nodes, i, j, idx, ends[sl], ok[sl], group, detour=attempt > len(STRAIGHT))
        if progress:
            progress(f"round {rounds}: {' / '.join(str(len(n.roots)) for n in nodes)} solutions at the "
                     f"{K} nodes, {paths} paths, {sum(int((n.image[j] < 0).sum()) for n in nodes for j in n.image)} "
                     f"tracks pending, {spent + time.perf_counter() - t0:.0f} s; tracked (retry level: paths, "
                     f"failed, s) " + ", ".join(f"{a}: {n}, {f}, {s:.0f}" for a, n, f, s in tally))
        if checkpoint and time.perf_counter() - last_save > 60.0:
            _save(checkpoint, record())
            last_save = time.perf_counter()
    # edges whose open tracks failed every retry (a segment passing close to a point where several solutions
    # meet: 3D TOA 4r/6s seed 1, four paths stalling at one s from both ends) leave the graph, when the other
    # edges still join every node in at least MIN_LOOPS independent loops
    finished = time.perf_counter() - t0 < options.seconds and (options.target is None or len(nodes[0].roots) < options.target)
    dropped = [(i, j) for i, n in enumerate(nodes) for j in n.image if i < j and (
        (n.image[j] < 0).any() or (nodes[j].image[i] < 0).any())]
    if finished and dropped and _loops(nodes, dropped) >= MIN_LOOPS:
        for i, j in dropped:
            del nodes[i].image[j], nodes[i].tries[j], nodes[j].image[i], nodes[j].tries[i]
            if progress:
                progress(f"edge {i}-{j} dropped: tracks along it failed every retry")
    if checkpoint:
        _save(checkpoint, record())
    open_edges = sum(int((n.image[j] < 0).sum()) for n in nodes for j in n.image)
    counts = tuple(len(n.roots) for n in nodes)
    edges = sum(len(n.image) for n in nodes) // 2
    closed = open_edges == 0 and len(set(counts)) == 1 and _loops(nodes, []) >= MIN_LOOPS
    return GraphCount(nodes[0].roots, counts, np.array(qs), paths, rounds, open_edges, closed,
                      spent + time.perf_counter() - t0, jumps, tuple(n.roots for n in nodes), edges, finished)


def _loops(nodes: list[_Node], without: list[tuple[int, int]]) -> int:
    """Independent loops of the graph's edges less ``without`` (edges - nodes + 1), 0 when they do not join every
    node."""
    cut = {frozenset(e) for e in without}
    seen, todo = {0}, [0]
    while todo:
        i = todo.pop()
        for j in nodes[i].image:
            if j not in seen and frozenset((i, j)) not in cut:
                seen.add(j)
                todo.append(j)
    if len(seen) < len(nodes):
        return 0
    return sum(len(n.image) for n in nodes) // 2 - len(cut) - len(nodes) + 1


def _record(nodes: list[_Node], i: int, j: int, idx: np.ndarray, ends: np.ndarray, ok: np.ndarray,
            group: np.ndarray | None, detour: bool = False) -> int:
    """Enter the tracks of node i's solutions idx along (i, j): accepted endpoints become (or match) node j's
    solutions, and each pair is entered both ways (the segment tracked back is the inverse path). A track
    whose endpoint is already the image of another of node i's solutions (path jumping, one of the two) sends
    both to a tight retrack; a ``detour`` track (through a midpoint, not homotopic to the segment) that lands
    on a solution already matched is only rejected itself. Failed tracks count a try. Returns the jumps seen."""
    src, dst = nodes[i], nodes[j]
    src.tries[j][idx[~ok]] += 1
    idx, ends = idx[ok], ends[ok]
    if not len(idx):
        return 0
    found = _match(dst.roots, ends, group)
    fresh = np.flatnonzero(found < 0)
    if len(fresh):
        rep = _distinct_new(ends[fresh], group)
        firsts = np.flatnonzero(rep == np.arange(len(fresh)))
        new_index = dst.add(ends[fresh[firsts]])
        where = np.full(len(fresh), -1, dtype=np.int64)
        where[firsts] = new_index
        found[fresh] = where[rep]
    jumps = 0
    for a, b in zip(idx, found):
        back = dst.image[i][b]
        if back < 0 or back == a:
            src.image[j][a] = b
            dst.image[i][b] = a
        elif detour:
            src.tries[j][a] += 1
        else:  # b is already the image of another solution of node i: one of the two tracks jumped
            jumps += 1
            src.tries[j][a] += 1
            src.image[j][back] = -1
            src.tries[j][back] += 1
            dst.image[i][b] = -1
            dst.tries[i][b] += 1
    return jumps
