"""How many solutions? The number of isolated solutions of a parametric system at a generic complex parameter,
where F4's GF(p) count does not reach: monodromy on a complete graph, every solution proven, sets compared.

For a square parametric system F(x; q) = 0 (a system file, a TDOA/TOA formulation, 2D or 3D) and a seed:
1. a generic complex start pair (q0, x0): a complex network and its root for a formulation; for a user's
   system a random x0 and parameters q0 that make it a root (a point of the affine space of such q when the
   parameters enter linearly, else Gauss-Newton on q);
2. monodromy on a complete graph of parameter nodes (:func:`solvers.continuation.graph.graph_monodromy`): every
   solution tracked once per edge, until the graph closes;
3. the solutions at q0 proven one by one (:func:`solvers.continuation.certify.certify`, Krawczyk's test in ball
   arithmetic) and their boxes checked pairwise disjoint (one solution per orbit of the system's group: boxes
   disjoint from every image of every other box);
4. a check that can fail: random known solutions carried around fresh loops must land in the set;
5. for every further seed the same from its own start pair, and its set carried to the first seed's q0: the
   sets must be equal (every endpoint one of the first set's, one-to-one);
6. optionally the trace test (:mod:`solvers.continuation.trace`) on the first seed's set, with its witnesses
   found by the same graph strategy.

The evidence is said in words, the strongest that holds (STYLE.md, habit 16): "at least N, proven" (every
solution proven and distinct: a lower bound that is a theorem); "complete: ..." only where it holds for the whole
solution set (F4's degree over GF(p) or Bezout's bound equals N, or the trace test passed on an incidence variety
shown irreducible: :func:`solvers.count_evidence.scope_of`); "complete for the component reached (N found) by trace test ...; another
component may exist" where the trace test passed and nothing more is known; else the number found numerically,
"lower bound (numerical)", beside the proven one. The count shown is the proven number; singular points (multiple
roots, positive-dimensional components) are named and never counted. A count is never called complete on a rule
that only stops looking.
"""
from __future__ import annotations

import dataclasses
import json
import os
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from analysis.formulations.parametric import ParametricSystem
from analysis.formulations.tdoa import Formulation

from .continuation import certify as certify_mod
from .continuation import graph, monodromy, tape_kernel, tracker
from .continuation import trace as trace_mod
from .continuation.tracking import (HomotopyError, _duplicated, _expanded, coefficient_source, evaluator_for,
                                    load_coefficients, scaling_note, structure)
from . import count_evidence
from .generate import GenerationError, SOLVERS, _job

__all__ = ["CountOptions", "CountResult", "SeedCount", "count", "tdoa_target", "CELLS"]

#: The 3D TDOA minimal cells without a committed solver, by configuration key (the others: solvers.generate.SOLVERS).
#: 10r/4s: the compaction formulation with every measurement (13 unknowns, det H saturated); 5r/9s: the direct
#: parametrization (receivers in the gauge frame, transmitters, offsets; one solution per orbit of the frame's
#: 8 reflections).
CELLS = {"10r4s3d": "10r4s-tdoa3d:A,B2,B3,B4,C2-C10", "5r9s3d": "5r9s-tdoa3d-direct:all"}

#: The tracking options of count's graphs: RK4 with Newton's corrector. The Pade predictor took 0.7-0.8 of its time
#: with the same counts, closed graphs and equal seed sets on 6r/3s, 3D TOA 6r/4s, 4r/5s and 7r/5s
#: (scripts/bench_tracker_variants.py), but it is not as safe on 3D 10r/4s: seed 0's graph left 11 tracks open
#: and 2 of seed 1's solutions were lost carrying them to seed 0 (twice, 2026-11-29), where RK4 closed seed 0's
#: graph and carried every solution.
COUNT_TRACKER = tracker.TrackerOptions()

#: Every further seed's graph holds the first seed's q0 as its node 1 (in place of a random node), so that the
#: closed graph carries its set there along its own edges: no separate carrying of the whole set (5r/9s: 248 s of
#: 3,601, 2026-12-01). The graphs stay independent (their own start pairs, random nodes and edges; one node
#: shared). A graph that does not close is carried as before (:func:`_carry`).
ANCHORED = True

#: Routes through a random midpoint tried, in turn, for a carried path that failed on the straight segment and
#: around its stall point (5r/9s, 2026-11-29: one of 36,947 paths carried from seed 1 to seed 0 failed every
#: straight retrack and every local detour).
CARRY_ROUTES = 3

#: |t1| = |t2| of count's trace test: at 0.5 a path was lost on every route on 3D 10r/4s (pencil on b) and on 7r/5s
#: (offsets: a witness of norm 723), at 0.2 none was (docs/minimal-3d.md).
TRACE_STEP = 0.2

#: Seeded random known solutions carried around each fresh verification loop.
VERIFY_SAMPLE = 64

#: Rounds in which the graphs run again, from the union of what every seed and the fresh loops found, when
#: they found solutions the first seed's closed graph lacked (a family whose branch points few of the graph's
#: triangles wind around: examples/circle.sys, seed 1, 1 of 4 on 4 and on 6 nodes), each with more nodes.
AUGMENT = 3
NODES_PER_AUGMENT = 2


@dataclass(frozen=True)
class CountOptions:
    """seeds: one start pair each (the first is the reference; every other seed's set is carried to it);
    nodes: the monodromy graph's nodes; verify_loops: fresh loops the sampled solutions are carried around;
    certify: prove every solution (Krawczyk); trace: run the trace test on the first seed's set (TDOA/TOA
    formulations and systems with a program; slow for large sets); seconds: wall-time cap of each graph;
    checkpoints: a directory for the graphs' resumable files (None: none); tracker: the tracking options (None:
    :data:`COUNT_TRACKER`); dask: a Dask scheduler address (or "local") whose workers track the graphs' batches, in chunks
    of dask_chunk paths (solvers.continuation.dask_tracks; the same numbers); degree: compare with F4's count over
    GF(p) where it reaches (:data:`solvers.count_evidence.DEGREE_CELLS`)."""

    seeds: tuple[int, ...] = (0, 1)
    nodes: int = 4
    verify_loops: int = 1
    certify: bool = True
    trace: bool = False
    trace_step: float = TRACE_STEP
    seconds: float = float("inf")
    checkpoints: str | None = None
    tracker: tracker.TrackerOptions | None = None
    dask: str | None = None
    dask_chunk: int = 2000
    degree: bool = True

    def __post_init__(self) -> None:
        if self.tracker is None:
            object.__setattr__(self, "tracker", COUNT_TRACKER)


@dataclass(frozen=True)
class SeedCount:
    """One seed's graph: its solutions at its own q0, the graph's numbers, and (the first seed) the proof."""

    seed: int
    solutions: int
    closed: bool
    open_tracks: int
    paths: int
    rounds: int
    seconds: float
    carried: str = ""  # how this seed's set compares with the first seed's ("equal as sets", ...)

    @property
    def graph(self) -> str:
        """The graph's state in words: "closed", or "not closed (N tracks open)"."""
        return "closed" if self.closed else f"not closed ({self.open_tracks} tracks open)"


@dataclass(frozen=True)
class CountResult:
    """The count and its evidence. ``count``: the number shown, the proven solutions (one per orbit of the group
    when ``group_order`` > 1) at the first seed's q0, or without proofs the number found; ``found``: the solutions
    found numerically; ``evidence``: in words (module docstring); ``proven``: solutions proven (Krawczyk) with
    pairwise disjoint boxes; ``scope``: what the completeness shown covers, "whole solution set", "component reached"
    or "lower bound" (:func:`solvers.count_evidence.scope_of`); ``gf_degree``: F4's degree and dimension over GF(p), where it reached."""

    system: str
    unknowns: int
    parameters: int
    group_order: int
    count: int
    evidence: str
    proven: int
    seeds: tuple[SeedCount, ...]
    loops_checked: str
    trace: dict | None
    seconds: float
    certify_seconds: float = 0.0
    notes: tuple[str, ...] = field(default=())
    # the first seed's parameters, its solutions there and the group (sign vectors) they are orbits of: what a
    # solver is built from (solvers.generate, evidence "monodromy"); not part of the record
    q0: np.ndarray | None = field(default=None, repr=False, compare=False)
    roots: np.ndarray | None = field(default=None, repr=False, compare=False)
    group: np.ndarray | None = field(default=None, repr=False, compare=False)
    found: int = 0
    certified: bool = True
    scope: str = "lower bound"
    gf_degree: dict | None = None

    @property
    def complete(self) -> bool:
        """Whether the count is shown complete for the whole solution set."""
        return self.scope == "whole solution set"

    def record(self) -> dict:
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in ("q0", "roots", "group")}
        out["seeds"] = [dataclasses.asdict(s) for s in self.seeds]
        return out

    def summary(self) -> str:
        what = "orbits" if self.group_order > 1 else "solutions"
        head = (f"{self.count} {what} proven" if self.certified else f"{self.found} {what} found numerically (not proven)")
        if self.certified and self.found != self.count:
            head += f"; {self.found} found numerically"
        lines = [f"{self.system}: {head}" + (f" (orbits of a group of order {self.group_order})" if self.group_order > 1 else "")
                 + f" ({self.unknowns} unknowns, {self.parameters} parameters)",
                 f"evidence: {self.evidence}",
                 f"scope: {self.scope}"]
        for s in self.seeds:
            lines.append(f"seed {s.seed}: {s.solutions} {what}, graph {s.graph}, "
                         f"{s.paths} paths, {s.rounds} rounds, {s.seconds:.1f} s" + (f"; {s.carried}" if s.carried else ""))
        lines.append(f"loops: {self.loops_checked}")
        if self.trace is not None:
            t = self.trace
            lines.append(f"trace test: {t['status']}, residual {t['residual']:.1e}, {t['witnesses']} witnesses, {t['paths']} paths"
                         + (f" ({t['why']})" if t.get("why") else ""))
        lines += [f"note: {n}" for n in self.notes]
        lines.append(f"{self.seconds:.1f} s in all ({self.certify_seconds:.1f} s proving)")
        return "\n".join(lines)


def tdoa_target(config: str, dim: int = 2, model: str = "tdoa") -> str:
    """The formulation label counted for a configuration ("7r5s", or a formulation label "7r5s-tdoa3d-direct:all"
    as it is): the committed solver's formulation (solvers.generate.SOLVERS) or :data:`CELLS`."""
    if ":" in config:
        return config
    key = config.replace("/", "") + ("3d" if dim == 3 else "") + ("toa" if model == "toa" else "")
    if key in SOLVERS and isinstance(SOLVERS[key], str):
        return key
    if key in CELLS:
        return CELLS[key]
    known = sorted(set(SOLVERS) | set(CELLS))
    raise GenerationError(f"no formulation registered for {config} (dim {dim}, {model}); give a formulation label "
                          f"such as 7r5s-tdoa3d-direct:all, or one of {', '.join(known)}")


def _gauss_newton_start(system: ParametricSystem, coefficients: Callable, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A random complex x0 and parameters q0 that make it a root, for parameters that enter non-linearly: Newton's
    method on F(x0; q) = 0 in q (least-norm steps, P >= N), from random complex q."""
    exps, eq = structure(system)
    N, P = len(system.unknowns), len(system.parameters)
    x0 = rng.normal(size=N) + 1j * rng.normal(size=N)

    def f(q: np.ndarray) -> np.ndarray:
        return _expanded(coefficients, exps, eq, N, x0[None], q)[0][0]

    for attempt in range(10):
        q = rng.normal(size=P) + 1j * rng.normal(size=P)
        for _ in range(60):
            r = f(q)
            h = 1e-7 * (1.0 + np.abs(q))
            J = np.column_stack([(f(q + h[k] * np.eye(P)[k]) - r) / h[k] for k in range(P)])
            q = q - np.linalg.lstsq(J, r, rcond=None)[0]
            if np.linalg.norm(f(q)) < 1e-13 * (1.0 + np.linalg.norm(q)):
                return q, x0
    raise HomotopyError(f"{system.name}: no parameters found that make a random point a root (Newton's method on "
                        "the parameters did not converge); give a start pair")


def _start(target, seed: int, start: tuple[np.ndarray, np.ndarray] | None = None
           ) -> tuple[ParametricSystem, np.ndarray, np.ndarray, np.ndarray | None]:
    """(system, q0, x0, group) for a target (a ParametricSystem or a formulation/configuration label) and seed;
    ``start``: the user's start pair (q0, x0) instead of a drawn one."""
    job, _, _ = _job(target, None, None, "homotopy")
    system = job.system
    q0, x0 = start if start is not None else _draw(job, np.random.default_rng(seed))
    group = job.group
    if group is None and system.symmetry:
        group = np.array([[1] * len(system.unknowns)] + [list(g) for g in system.symmetry], dtype=float)
    return system, np.asarray(q0, dtype=complex), np.asarray(x0, dtype=complex), group


def _draw(job, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A random start pair (q0, x0) of a job: its sampler's (a complex network for a formulation), else a random x0
    and parameters that make it a root (the affine space of such q when the parameters enter linearly, else Newton's
    method on q). Raises :class:`HomotopyError`, naming the equations that hold no parameter where that is why."""
    if job.start is not None:
        return job.start(rng)
    system = job.system
    coefficients = load_coefficients(coefficient_source(system))
    try:
        from .methods.homotopy import affine_start
        return affine_start(system, coefficients, rng)
    except HomotopyError:
        pass
    try:
        return _gauss_newton_start(system, coefficients, rng)
    except HomotopyError as exc:
        fixed = _parameter_free(system)
        if not fixed:
            raise
        which = "; ".join(f"equation {k + 1} ({system.equations[k].strip()})" for k in fixed)
        raise HomotopyError(f"{system.name}: {which} holds no parameter, so a random point is a root for no parameters "
                            "and no start pair can be drawn; give one (--start: parameters and a root there), from "
                            "which every seed's start pair is drawn on the same incidence variety") from exc


def _parameter_free(system: ParametricSystem) -> list[int]:
    """Indices of the equations none of whose coefficients holds a parameter (c^2 + s^2 = 1, det X = 0)."""
    return [k for k, terms in enumerate(system.terms) if not any(c.free_symbols for _, c in terms)]


def _moved_start(system: ParametricSystem, solver, q0: np.ndarray, x0: np.ndarray, rng: np.random.Generator, options
                 ) -> tuple[np.ndarray, np.ndarray] | None:
    """A further start pair on the incidence variety of a given one (q0, x0): x0 tracked by the parameter homotopy
    to a random complex parameter point of q0's size (:func:`_carry`, every retry); None when the path fails."""
    scale = np.sqrt(np.mean(np.abs(q0) ** 2)) or 1.0
    for _ in range(3):
        q = scale * (rng.normal(size=len(q0)) + 1j * rng.normal(size=len(q0))) / np.sqrt(2.0)
        ends, ok = _carry(solver, q0, np.atleast_2d(x0), q, monodromy._excluded(system, q), options)
        if ok.all():
            return q, ends[0]
    return None


class _Refiner:
    """``refine(points, q_rows)`` for :func:`graph.graph_monodromy`: Newton's method in ball arithmetic at
    certify.HIGH_PRECISION bits, one :class:`certify.BallSystem` per parameter point (the graph's nodes)."""

    def __init__(self, system: ParametricSystem):
        self.system = system
        self.balls: dict[bytes, certify_mod.BallSystem] = {}

    def __call__(self, points: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        out, ok = points.copy(), np.zeros(len(points), dtype=bool)
        for k, (x, qk) in enumerate(zip(points, q)):
            key = np.asarray(qk, dtype=complex).tobytes()
            if key not in self.balls:
                self.balls[key] = certify_mod.BallSystem(self.system, qk)
            out[k], ok[k] = certify_mod.refine(self.balls[key], x)
        return out, ok


def _carry(solver, qa: np.ndarray, xs: np.ndarray, qb: np.ndarray, excluded, options,
           group: np.ndarray | None = None, refine=None) -> tuple[np.ndarray, np.ndarray]:
    """Track xs (K, N) from qa to qb: endpoints and the mask of those accepted as solutions at qb. A path that
    fails, or lands where another lands (with ``group``: on an image of another's endpoint; path jumping), is
    retracked with tight steps (:data:`graph.STRAIGHT`), then around its stall point (:data:`graph.DETOURS`),
    then along two legs through a random midpoint (:data:`CARRY_ROUTES` of them in turn); a retracked endpoint
    is kept only where it lands on no other endpoint.

    The routes differ, so the carried points are not the image of one path: what the comparison concludes
    stands anyway. Each route carries the whole fibre at qa one-to-one onto the whole fibre at qb, so if xs
    were the whole fibre and the endpoints are distinct solutions at qb that all lie in a known set of as many
    points, that set is the whole fibre too; a missing solution still shows as an endpoint outside it, or as
    two endpoints on one point (rejected here, the path counted lost)."""
    inst = np.zeros(len(xs), dtype=np.int64)
    ends, _ = solver.track(qa[None], qb[None], xs, inst, options)
    ends, ok = graph._accept(solver, ends, qb[None], inst, 1e-6, excluded, refine)
    ok &= ~_clashes(ends, ok, group)
    rng = np.random.default_rng([len(xs), 11])
    scale = np.sqrt(np.mean(np.abs(qa) ** 2 + np.abs(qb) ** 2) / 2.0)
    mids = [0.5 * (qa + qb) + 0.5 * scale * (rng.normal(size=len(qa)) + 1j * rng.normal(size=len(qa)))
            for _ in range(CARRY_ROUTES)]
    natural = [("natural", [qa, qb])] + [("natural", [qa, m, qb]) for m in mids] if NATURAL_STEPS else []
    for detour in list(graph.STRAIGHT) + list(graph.DETOURS) + mids + natural:
        bad = np.flatnonzero(~ok)
        if not len(bad):
            break
        if isinstance(detour, tracker.TrackerOptions):
            e, _ = solver.track(qa[None], qb[None], xs[bad], inst[bad], detour)
        elif isinstance(detour, np.ndarray):
            e, _ = graph._track_routes(solver, [[qa, detour, qb]], xs[bad], inst[bad], tracker.TIGHT)
        elif detour[0] == "natural":
            e = _natural(solver, detour[1], xs[bad])
        else:
            e, _ = graph._local_detours(solver, [(qa, qb)], xs[bad], inst[bad], *detour)
        e, good = graph._accept(solver, e, qb[None], inst[bad], 1e-6, excluded, refine)
        for k, y, g in zip(bad, e, good):  # kept only where it lands on no endpoint kept so far
            if g and graph._match(ends[ok], y[None], group)[0] < 0:
                ends[k] = y
                ok[k] = True
    return ends, ok


#: Steps of the natural-parameter continuation a carried path gets when every tracked route failed: the parameters
#: moved along the route in this many equal steps, four Newton steps at each, no predictor and no step control (it
#: needs no tangent). 5r/9s, 2026-11-29: the one path of 36,947 carried from seed 1 to seed 0 that failed every route
#: (a point of norm 5.7) landed this way on the one seed-0 solution no other path reached. 0: none.
NATURAL_STEPS = 2000


def _natural(solver, route: list[np.ndarray], xs: np.ndarray) -> np.ndarray:
    """xs carried along the polygon ``route`` of parameter points by natural-parameter continuation
    (:data:`NATURAL_STEPS` equal steps a leg, four Newton steps at each)."""
    y = xs.copy()
    inst = np.zeros(len(xs), dtype=np.int64)
    with np.errstate(all="ignore"):
        for a, b in zip(route[:-1], route[1:]):
            for j in range(1, NATURAL_STEPS + 1):
                y = solver.newton(y, (a + (b - a) * (j / NATURAL_STEPS))[None], steps=4, inst=inst)
    return y


def _reverse(solver, q0: np.ndarray, known: np.ndarray, qk: np.ndarray, xs: np.ndarray, ends: np.ndarray,
             ok: np.ndarray, excluded_k, options, group, refine=None) -> np.ndarray:
    """The paths of xs (at qk) carried to q0 that were lost on every route, tried from the other end: the known
    solutions at q0 that no carried endpoint landed on are tracked back to qk (:func:`_carry`, every retry), and a
    lost path whose start point one of them reaches is joined to it (the segment tracked back is the inverse path;
    a path that ends on an ill-conditioned solution can fail where the track leaving it does not). Fills ``ends``
    in place; returns the new mask. At most :data:`REVERSE_MAX` lost paths are tried."""
    lost = np.flatnonzero(~ok)
    if not len(lost) or len(lost) > REVERSE_MAX or not len(known):
        return ok
    hit = graph._match(known, ends[ok], group)
    free = np.setdiff1d(np.arange(len(known)), hit[hit >= 0])
    if not len(free) or len(free) > REVERSE_MAX:
        return ok
    back, good = _carry(solver, q0, known[free], qk, excluded_k, options, group, refine)
    where = graph._match(xs[lost], back[good], group)
    ok = ok.copy()
    for j, i in zip(free[good], where):
        if i >= 0 and not ok[lost[i]]:
            ends[lost[i]] = known[j]
            ok[lost[i]] = True
    return ok


#: Lost carried paths :func:`_reverse` tries from the other end (a handful in practice: 5r/9s lost 1 of 36,947).
REVERSE_MAX = 64


def _clashes(ends: np.ndarray, ok: np.ndarray, group) -> np.ndarray:
    """Mask of the accepted endpoints that coincide with another accepted one (or an image of one)."""
    out = np.zeros(len(ends), dtype=bool)
    idx = np.flatnonzero(ok)
    if len(idx) > 1:
        out[idx] = _duplicated(ends[idx], group=group)
    return out


def _compare(known: np.ndarray, carried: np.ndarray, ok: np.ndarray, group) -> tuple[str, int]:
    """How a carried set compares with the known set: (words, number of solutions the known set lacks)."""
    m = graph._match(known, carried[ok], group)
    outside = int((m < 0).sum())
    hits = m[m >= 0]
    twice = len(hits) - len(np.unique(hits))
    lost = int((~ok).sum())
    if outside == 0 and twice == 0 and lost == 0 and len(hits) == len(known):
        return "equal as sets", 0
    parts = []
    if lost:
        parts.append(f"{lost} paths lost")
    if outside:
        parts.append(f"{outside} land outside the set")
    if twice:
        parts.append(f"{twice} land on a solution twice")
    if len(np.unique(hits)) < len(known):
        parts.append(f"{len(known) - len(np.unique(hits))} of the set's {len(known)} reached by none (the carried set "
                     f"has {int(ok.sum())})")
    return "not equal: " + ", ".join(parts), outside


def _loop_check(solver, q0: np.ndarray, roots: np.ndarray, rng: np.random.Generator, loops: int, group, excluded,
                options, refine=None) -> tuple[str, int, np.ndarray]:
    """Carry VERIFY_SAMPLE random known solutions around ``loops`` fresh random triangles: (words, the number that
    landed outside the set, those endpoints)."""
    if loops <= 0 or not len(roots):
        return "not checked", 0, np.zeros((0, roots.shape[1]), dtype=complex)
    scale = np.sqrt(np.mean(np.abs(q0) ** 2))
    landed = outside = lost = 0
    new = []
    for _ in range(loops):
        pick = rng.choice(len(roots), size=min(VERIFY_SAMPLE, len(roots)), replace=False)
        xs, q = roots[pick], q0
        ok = np.ones(len(xs), dtype=bool)
        for _leg in range(2):
            qn = q0 + scale * (rng.normal(size=len(q0)) + 1j * rng.normal(size=len(q0)))
            xs, good = _carry(solver, q, xs, qn, excluded, options, group, refine)
            ok &= good
            q = qn
        xs, good = _carry(solver, q, np.where(ok[:, None], xs, 0.0), q0, excluded, options, group, refine)
        ok &= good
        m = graph._match(roots, xs[ok], group)
        landed += int((m >= 0).sum())
        outside += int((m < 0).sum())
        lost += int((~ok).sum())
        new.append(xs[ok][m < 0])
    words = f"{landed} of {landed + outside + lost} sampled solutions carried around {loops} fresh loop(s) landed in the set"
    if outside:
        words += f", {outside} outside it (the set is incomplete)"
    if lost:
        words += f", {lost} paths lost"
    return words, outside, np.vstack(new)


def count(target, options: CountOptions = CountOptions(), progress: Callable[[str], None] | None = None,
          start: tuple[np.ndarray, np.ndarray] | None = None) -> CountResult:
    """The number of solutions of ``target`` (a :class:`ParametricSystem`, a formulation label or a committed
    configuration such as "7r5s3d") at a generic complex parameter, with its evidence (module docstring).
    ``start``: a start pair (q0, x0) for the first seed (a system whose parameters enter non-linearly and that
    Newton's method on the parameters does not solve, or with an equation that holds no parameter); every other seed's
    start pair is then that root tracked to random parameters (the same incidence variety)."""
    t0 = time.perf_counter()
    say = progress or (lambda msg: None)
    if not options.seeds:
        raise ValueError("count needs at least one seed")
    notes: list[str] = []
    job, _, _ = _job(target, None, None, "homotopy")
    gf = count_evidence.gf_degree(job.system, say) if options.degree else None
    runs = []  # per seed: (system, q0, group, solver, excluded)
    known = []  # per seed: the solutions its next graph starts from
    for k, seed in enumerate(options.seeds):
        drawn = None
        if k == 0:
            drawn = _start(target, seed, start)
        elif start is None:
            try:
                drawn = _start(target, seed)
            except HomotopyError:
                drawn = None
        if drawn is None:  # the first seed's root tracked to random parameters
            system0, q00, group0, solver0, _ = runs[0]
            moved = _moved_start(system0, solver0, q00, known[0][0], np.random.default_rng([seed, 3]),
                                 options.tracker or solver0.options)
            if moved is None:
                raise HomotopyError(f"{system0.name}: seed {seed}: the first seed's root could not be tracked to random "
                                    "parameters for this seed's start pair; give other --seeds")
            drawn = (system0, moved[0], moved[1], group0)
            notes.append(f"seed {seed}: start pair drawn from seed {options.seeds[0]}'s, its root tracked to random "
                         "parameters (the same incidence variety)")
        system, q0, x0, group = drawn
        try:
            solver, x0 = monodromy.start_solver(system, q0, x0, seed, evaluator=evaluator_for(system.name))
        except HomotopyError as exc:
            if gf is not None and gf.dimension > 0:
                raise HomotopyError(f"{system.name} is positive-dimensional (dimension {gf.dimension}, F4 over GF(p)): "
                                    f"the start point is no isolated solution ({exc}); count counts isolated solutions, "
                                    "add equations") from None
            raise
        runs.append((system, q0, group, solver, monodromy._excluded(system, q0)))
        known.append(x0)
    if scaling_note(runs[0][0]):
        notes.append(scaling_note(runs[0][0]))
    clusters = [_cluster(options, *run) for run in runs]
    try:
        return _count(target, job, options, say, notes, runs, known, clusters, t0, gf, probe=start is None)
    finally:
        for c in clusters:
            if c is not None:
                c.close()


def _cluster(options: CountOptions, system: ParametricSystem, q0: np.ndarray, group, solver, excluded):
    """A Dask stand-in for one seed's solver (options.dask), or None."""
    if not options.dask:
        return None
    from .continuation.dask_tracks import DaskSystem

    source, saturate = _source(system)
    return DaskSystem(options.dask, solver, source, saturate, q0, solver.x0, chunk=options.dask_chunk)


def _source(system: ParametricSystem) -> tuple[str, bool]:
    """How a system travels to Dask workers: (a formulation label or the system's text, det H saturated)."""
    try:
        config = Formulation.parse(system.name).config
        return system.name, config.parametrization != "direct"
    except Exception:  # a user's system travels as its text
        if system.definitions:
            raise ValueError(f"{system.name}: a system with definitions cannot be sent to Dask workers as text; "
                             "count it without --dask") from None
        return system.text(), False


def _count(target, job, options: CountOptions, say, notes: list[str], runs: list, known: list, clusters: list,
           t0: float, gf, probe: bool = True) -> CountResult:
    """:func:`count` once its start pairs and solvers are drawn."""
    system, q0, group, solver0, excluded0 = runs[0]
    track0 = options.tracker or solver0.options
    refiners = [_Refiner(run[0]) for run in runs]
    rng = np.random.default_rng([options.seeds[0], 7])
    for attempt in range(AUGMENT + 1):
        seeds: list[SeedCount] = []
        results = []
        carried_sets = []  # every other seed's set carried to the first seed's q0: (endpoints, accepted)
        nodes = options.nodes + NODES_PER_AUGMENT * attempt
        for k, seed in enumerate(options.seeds):
            system_k, q0_k, _, solver_k, excluded_k = runs[k]
            if clusters[k] is not None:
                solver_k = clusters[k]
            result = graph.graph_monodromy(
                solver_k, q0_k, known[k], graph.GraphOptions(nodes=nodes, seed=seed + 1000 * attempt,
                                                             seconds=options.seconds, tracker=options.tracker),
                group=group, excluded=excluded_k, checkpoint=_checkpoint(options, system_k, seed, f"graph{attempt}"),
                progress=lambda msg, seed=seed: say(f"seed {seed}: {msg}"), refine=refiners[k],
                anchors=q0[None] if k and ANCHORED and nodes > 2 else None)
            results.append(result)
            carried = ""
            if k and ANCHORED and nodes > 2 and result.closed:
                # the first seed's q0 is this graph's node 1: a closed graph's set there is this seed's set carried
                # to it (every node's set is the image of the base point's along the graph's edges, one-to-one)
                ends = result.node_roots[1]
                carried_sets.append((ends, np.ones(len(ends), dtype=bool)))
                carried, _ = _compare(results[0].roots, *carried_sets[-1], group)
            elif k:
                ends, ok = _carry(solver0, q0_k, result.roots, q0, excluded0, track0, group, refiners[0])
                ok = _reverse(solver0, q0, results[0].roots, q0_k, result.roots, ends, ok, excluded_k, track0, group,
                              refiners[k])
                carried_sets.append((ends, ok))
                carried, _ = _compare(results[0].roots, *carried_sets[-1], group)
            seeds.append(SeedCount(seed, len(result.roots), result.closed, result.open_edges, result.paths,
                                   result.rounds, round(result.seconds, 1), carried))
            say(f"seed {seed}: {len(result.roots)} solutions, graph {'closed' if result.closed else 'not closed'}"
                + (f", {carried}" if carried else "") + f" ({result.seconds:.0f} s)")
        roots = results[0].roots
        loops_checked, outside, landed = _loop_check(solver0, q0, roots, rng, options.verify_loops, group, excluded0,
                                                     track0, refiners[0])
        say(f"loops: {loops_checked}")
        probed = np.zeros((0, roots.shape[1]), dtype=complex)
        if probe and attempt == 0:
            probes, probed = _probe(job, solver0, q0, roots, options, group, excluded0, track0, refiners[0])
            say(f"start pairs: {probes}")
        # the union at the first seed's q0: every other seed's set carried there, the loops' and the probes' endpoints
        union = np.vstack([roots, landed, probed] + [ends[ok] for ends, ok in carried_sets])
        fresh = graph._match(roots, union[len(roots):], group) < 0
        # another seed's graph that closed on fewer (its set carried here reaches only part of the first's) runs
        # again too, from the first seed's set carried to it (line and circle from a given start: seed 1 closed on 1
        # of 2)
        short = [s.seed for s in seeds[1:] if "reached by none" in s.carried]
        if (not fresh.any() and not short) or attempt == AUGMENT:
            break
        extra = union[len(roots):][fresh]
        extra = extra[graph._distinct_new(extra, group) == np.arange(len(extra))]
        why = (f"the seeds' sets or the loops held {len(extra)} solution(s) the first graph lacked" if len(extra) else
               f"the graph of seed(s) {', '.join(map(str, short))} closed on fewer solutions than the first's")
        notes.append(f"round {attempt + 1}: {why}; every graph ran again from the union, with "
                     f"{nodes + NODES_PER_AUGMENT} nodes")
        say(notes[-1])
        known[0] = np.vstack([roots, extra])
        for k in range(1, len(runs)):  # the union carried to every other seed's q0
            ends, ok = _carry(runs[k][3], q0, known[0], runs[k][1], runs[k][4], track0, group, refiners[k])
            known[k] = np.vstack([results[k].roots, ends[ok]])
    proven, cert_seconds, cert = 0, 0.0, None
    if options.certify:
        cert = certify_mod.certify(system, q0, roots, progress=say, processes=tape_kernel.threads())
        meets = certify_mod.disjoint(cert.centres, np.where(cert.proven, cert.radii, 0.0), group)
        proven = int((cert.proven & ~meets).sum())
        cert_seconds = cert.seconds
        if meets.any():
            notes.append(f"{int(meets.sum())} proven boxes meet another box or an image of one")
        if not cert.proven.all():
            notes.append(f"{int((~cert.proven).sum())} solution(s) not proven by Krawczyk's test: "
                         + count_evidence.unproven_words(system, solver0, q0, roots[~cert.proven], gf))
        say(f"certify: {proven} of {len(roots)} proven, boxes disjoint ({cert.seconds:.0f} s)")
    trace_record = None
    if options.trace and options.certify and proven < len(roots):
        notes.append("trace test not run: not every solution is proven (it tests a set of solutions for completeness)")
    elif options.trace:
        trace_record = _trace(target, system, q0, roots, group, options, say, solver0, track0, refiners[0])
    consistent = all(s.closed for s in seeds) and all(s.carried in ("", "equal as sets") for s in seeds) and not outside
    found = len(roots)
    if options.certify and proven == found and found:
        evidence = f"at least {found}, proven (Krawczyk's test, disjoint boxes)"
    elif options.certify and proven:
        evidence = (f"at least {proven}, proven (Krawczyk's test, disjoint boxes); {found} found numerically, "
                    f"{found - proven} not proven")
    else:
        evidence = f"lower bound (numerical): {found} found, " + ("none proven" if options.certify else "not proven")
    scope, why = count_evidence.scope_of(system, roots, cert, proven, group, gf, trace_record)
    if why:
        evidence += f"; {why}"
    if gf is not None:
        notes.append(count_evidence.gf_words(gf, proven, count_evidence.orbit_total(roots, cert, group) if proven == found else None))
    if not consistent:
        notes.append("the graphs did not all close or the seeds' sets differ: a solution may be missing")
    elif len(options.seeds) > 1:
        notes.append(f"graphs closed on {len(options.seeds)} seeds, their sets equal")
    shown = proven if options.certify else found
    return CountResult(system.name, len(system.unknowns), len(system.parameters), 1 if group is None else len(group),
                       shown, evidence, proven, tuple(seeds), loops_checked, trace_record,
                       round(time.perf_counter() - t0, 1), round(cert_seconds, 1), tuple(notes), q0, roots, group,
                       found=found, certified=options.certify, scope=scope,
                       gf_degree=None if gf is None else {"degree": gf.degree, "dimension": gf.dimension})


#: Further start pairs drawn at random (each its own root, carried to the first seed's parameters): one that lands
#: outside the set is a solution the graphs lack, maybe on another component of the incidence variety (x^2 = a^2,
#: x y = b: each drawn start lands on x = a or on x = -a).
PROBES = 8


def _probe(job, solver0, q0: np.ndarray, roots: np.ndarray, options: CountOptions, group, excluded0, track0, refine
           ) -> tuple[str, np.ndarray]:
    """:data:`PROBES` start pairs drawn with seeds of their own, their roots carried to q0: (words, the endpoints
    outside the set)."""
    xs = []
    for j in range(PROBES):
        try:
            q, x = _draw(job, np.random.default_rng([options.seeds[0], 2000 + j]))
        except HomotopyError:
            continue
        ends, ok = _carry(solver0, np.asarray(q, dtype=complex), np.atleast_2d(np.asarray(x, dtype=complex)), q0,
                          excluded0, track0, group, refine)
        if ok.all():
            xs.append(ends[0])
    if not xs:
        return "no further start pair drawn", np.zeros((0, roots.shape[1]), dtype=complex)
    xs = np.array(xs)
    outside = graph._match(roots, xs, group) < 0
    return (f"{len(xs)} further drawn start pair(s) carried to the first seed's parameters, {int(outside.sum())} "
            "outside the set"), xs[outside]


def _checkpoint(options: CountOptions, system: ParametricSystem, seed: int, what: str) -> str | None:
    """The resumable file of one seed's graph (or the trace test's witnesses) in options.checkpoints, or None."""
    if not options.checkpoints:
        return None
    os.makedirs(options.checkpoints, exist_ok=True)
    stem = "".join(ch if ch.isalnum() else "_" for ch in system.name)[:80]
    return os.path.join(options.checkpoints, f"{stem}-seed{seed}-{what}.json")


#: The first seed's roots carried to the trace test's second instance to start its witnesses from (a sample of this
#: many): witnesses on the components the roots lie on, whichever start pair the count was given.
TRACE_STARTS = 8


def _trace(target, system: ParametricSystem, q0: np.ndarray, roots: np.ndarray, group, options: CountOptions,
           say: Callable[[str], None], solver0=None, track0=None, refine=None) -> dict:
    """The trace test's record on the first seed's solutions (with a group, on the orbits: invariant coordinates).
    Its second instance: a drawn start pair's parameters (random ones of q0's size where none can be drawn), with
    up to :data:`TRACE_STARTS` of the roots carried there (their witnesses lie on the roots' components)."""
    try:
        _, q_star, x_star, _ = _start(target, options.seeds[0] + 1000)
    except HomotopyError:
        rng = np.random.default_rng([options.seeds[0], 1000])
        scale = np.sqrt(np.mean(np.abs(q0) ** 2)) or 1.0
        q_star = scale * (rng.normal(size=len(q0)) + 1j * rng.normal(size=len(q0))) / np.sqrt(2.0)
        x_star = None
    starts = x_star[None] if x_star is not None else np.zeros((0, roots.shape[1]), dtype=complex)
    if solver0 is not None and len(roots):
        pick = np.random.default_rng([options.seeds[0], 1001]).permutation(len(roots))[:TRACE_STARTS]
        ends, ok = _carry(solver0, q0, roots[pick], q_star, monodromy._excluded(system, q_star), track0, group, None)
        starts = np.vstack([ends[ok], starts])
    if not len(starts):
        raise HomotopyError(f"{system.name}: no root of the trace test's second instance (none of the roots carried "
                            "there); run without --trace")
    stand_in = None
    if options.dask:
        from .continuation.dask_tracks import trace_stand_in

        stand_in = trace_stand_in(options.dask, *_source(system), chunk=options.dask_chunk)
    coordinates, pencil = count_evidence.pencil_coordinates(system, group, say)

    def run(coordinates):
        # the witnesses belong to one pencil: its coordinates name the file (another pencil's run does not overwrite it)
        witnesses = "witnesses-" + ("all" if coordinates is None else "-".join(system.unknowns[k] for k in coordinates))
        return trace_mod.trace_test_system(system, q0, roots, (q_star, starts),
                                           trace_mod.TraceOptions(seed=options.seeds[0], step=options.trace_step,
                                                                  coordinates=coordinates),
                                           checkpoint=_checkpoint(options, system, options.seeds[0], witnesses),
                                           progress=say, group=group, dask=stand_in)

    test = run(coordinates)
    if test.status == "inconclusive" and test.failed_paths and coordinates is not None:
        # paths lost on every route on a pencil of a few coordinates: the fibre's points escape with those coordinates
        # finite (base points of the pencil on the curve; 3D TOA 4r/6s on b: 71 of 1,866 slice paths diverged, 24 of
        # the 38 roots among them); the pencil on every unknown has none (1,160 witnesses, passed at 1.6e-13, rounding level
        # 1.7e-12, 2026-12-02)
        say(f"trace test: {test.failed_paths} paths lost on the pencil on {pencil}; again on every unknown")
        pencil = f"every unknown (on {pencil}: {test.failed_paths} slice paths lost on every route, base points)"
        test = run(None)
    return {**test.record(), "pencil": pencil}


def write_record(result: CountResult, path: str) -> None:
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(result.record(), fh, indent=1, default=float)
        fh.write("\n")
