"""Parameter homotopy: the general solving method, offline build and online solver side by side.

Offline (:func:`build`): from a square :class:`analysis.formulations.parametric.ParametricSystem`
1. certify the number of roots at generic parameters over GF(p) (two primes, two seeds);
2. draw a generic complex start instance q0 with one known root (a complex network, or any system
   whose equations are affine in the parameters: pick x0, solve for q0);
3. find all roots of q0 by monodromy (loops q0 -> qa -> qb -> q0 in parameter space, every known
   root tracked around each loop, new endpoints kept) until their number equals the certified count;
   a run that cannot reach it within its budget is an error naming how many roots it found;
4. check the solver on seeded real instances (the known root must be among the endpoints);
5. write a plain-JSON spec (start parameters and roots rounded to 11 digits, refined at load time).

A squared system's spec may name the start roots that satisfy the full (over-determined) system
(``full_system.tracked``, :func:`full_system_roots`); only those are tracked.

Online (:class:`HomotopySolver`): for target parameters q1, every (tracked) start root is tracked along the
complex segment q0 -> q1 by the compiled tracker (:mod:`solvers.methods.tracker`), or, for systems with
an unexpanded straight-line program (TDOA formulations, with minors squared, and the 4r/5s positions
formulation: :func:`solvers.methods.slp.system_equations`; see :data:`VALIDATED_PROGRAMS`), by the
batched tracker on its instruction tapes (:mod:`solvers.methods.tape_kernel`); paths that stall,
and all paths of an instance where two endpoints coincide (path jumping), are retracked with tight
step control. A spec with further start systems (``starts``, :func:`extra_starts`; 4r/5s) is instead
tracked from each of them and the distinct endpoints pooled, nothing retracked
(:meth:`HomotopySolver._multistart`). Because q0 is a generic complex point, the segment misses the discriminant with
probability one (the gamma trick; Sommese & Wampler 2005, ch. 7).

References: Duff, Hill, Jensen, Lee, Leykin, Sommese, "Solving polynomial systems via homotopy
continuation and monodromy", IMA J. Numer. Anal. 2019; Ferranti et al., EUSIPCO 2021 (TDOA by
homotopy continuation).
"""
from __future__ import annotations

import dataclasses
import os
import json
import re
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from . import tape_kernel, tape_native, tracker
from .common import load_format, verify_found
from .tracker import SystemStructure, TrackerOptions

if TYPE_CHECKING:  # the online solver needs neither sympy nor the exact algebra
    from analysis.formulations.parametric import ParametricSystem

__all__ = ["HomotopyError", "HomotopyOptions", "HomotopySolver", "MonodromyCheckpoint", "accepted", "add_new", "build",
           "checked_roots", "coefficient_source", "expand_orbits", "read_checkpoint",
           "load_coefficients", "structure", "affine_start", "unresolved"]

SPEC_FORMAT = "tdoa-homotopy/1"

#: Largest relative Newton step accepted on a stored start root (ill-conditioned roots of high-degree
#: systems, e.g. the degree-10 4r/5s equations, do not converge further in double precision).
START_TOL = 1e-8

#: Significant digits of stored start data and roots (refined by Newton's method when loaded).
START_DIGITS = 11


#: Size of the detour (relative to |q0|) for paths that stall even with tight step control.
DETOUR = 0.5


def _detour_direction(P: int, k: int = 0) -> np.ndarray:
    """The k-th fixed complex direction in parameter space (seeded: the solver stays deterministic)."""
    rng = np.random.default_rng(12345 + k)
    return (rng.normal(size=P) + 1j * rng.normal(size=P)) / np.sqrt(2.0)


#: Detours (different fixed midpoints) tried in turn for paths that still stall or coincide.
DETOURS = 6

#: Half-width, in the path parameter s, of the local detour of a path that stalls at s*: the path is tracked
#: again to s* - d, then around s* through the complex value s* + i d (or s* - i d) to s* + d, then on to the
#: target, with the plain step control (:meth:`HomotopySolver._local_detours`). A stall is a near-miss of a
#: point where the path's root meets another solution (5r/5s: det H -> 0, the saturated locus, no other
#: tracked path near), not a crossing of two of the tracked roots, so a small loop around it leaves the root
#: where it was; its endpoint is kept only when it is distinct from the instance's other endpoints. Small,
#: because a larger loop encloses more of those points and can swap the root; large enough to leave the
#: stalled stretch (the values tried and their success rates: docs/findings/homotopy-speed.md, "Local detours
#: and pooled midpoints").
LOCAL_DETOUR = 0.005

#: Midpoint routes whose endpoints are pooled for an instance still short of its distinct roots after
#: the detours (no midpoint root set is complete, or none resolved it): a route through a midpoint permutes
#: the endpoints, so pooling the distinct endpoints of both routes recovers roots that either one alone
#: lands twice. One route: each costs a full solve, and the paths still stalling after the detours are few
#: (measurements: docs/findings/homotopy-speed.md, "Local detours and pooled midpoints").
POOLED_MIDPOINTS = 1


#: A path of a multi-start solve that stalls at s >= 1 - NEAR_END keeps its last point for Newton's method on
#: the target (4r/5s networks 679, 820, 899: the true root's path stalled at 1 - 3e-5, 1 - 1e-9, 1 - 5e-4).
NEAR_END = 1e-3

#: Newton steps on the target from such a last point (679 and 820 converge to the truth in 5: their roots are
#: ill-conditioned, which is why the paths stalled).
RESCUE_NEWTON = 8


#: Newton steps on the target system's directly evaluated coefficients after tracking.
FINAL_NEWTON = 2

#: Paths of an instance are retracked with tight step control only when at most this fraction failed.
RETRACK_FRACTION = 0.2


class HomotopyError(RuntimeError):
    """The homotopy solver cannot be built as asked (count not reached, verification failed, ...)."""


@dataclass(frozen=True)
class HomotopyOptions:
    seed: int = 0
    max_loops: int = 200
    stall_loops: int = 30
    radius: float = 1.0
    verify_trials: int = 20
    tracker: TrackerOptions = TrackerOptions()
    #: a loop's endpoint counts when Newton's next step is below this, relative (:func:`accepted`); the trace
    #: test's witness loops take a looser one (trace.WITNESS_TOL)
    accept_tol: float = START_TOL


# --------------------------------------------------------------------------------------------------
# structure and coefficient code
# --------------------------------------------------------------------------------------------------


def structure(system: ParametricSystem) -> tuple[np.ndarray, np.ndarray]:
    """Exponents (T, N) and equation index (T,) of every term, in the system's term order."""
    exps, eq = [], []
    for e, terms in enumerate(system.terms):
        for mon, _ in terms:
            exps.append(mon)
            eq.append(e)
    return np.array(exps, dtype=np.int64), np.array(eq, dtype=np.int64)


_FRACTION = re.compile(r"(?<![\w.])(?<!\*\*)(\d+)/(\d+)")  # not an exponent: u**2/4 is (u**2)/4


def _print(expr) -> str:
    import sympy

    text = sympy.sstr(expr, order="lex")
    return _FRACTION.sub(lambda mm: repr(int(mm.group(1)) / int(mm.group(2))), text)


def coefficient_source(system: ParametricSystem, name: str = "coefficients") -> str:
    """Python source of ``name(q)``: parameters (K, P) -> term coefficients (K, T), numpy only.

    Definitions are computed first (in order), then the coefficients with shared subexpressions
    (``sympy.cse``); byte-stable for a given system.
    """
    import sympy

    coeffs = [c for eq in system.terms for _, c in eq]
    lines = [f"def {name}(q):",
             f'    """Coefficients of the {len(coeffs)} terms from the {len(system.parameters)} parameters q (K, P) -> (K, T)."""',
             "    q = np.asarray(q)",
             f"    out = np.zeros((q.shape[0], {len(coeffs)}), dtype=np.result_type(q.dtype, np.float64))"]
    used = set().union(*(c.free_symbols for c in coeffs)) if coeffs else set()
    aux = dict(zip(system.aux_symbols, system.aux_exprs))
    needed = {s for s in used if s in aux}
    for sym in reversed(system.aux_symbols):  # definitions used by needed definitions
        if sym in needed:
            needed |= aux[sym].free_symbols & set(aux)
    used_q = used | set().union(*(aux[s].free_symbols for s in needed)) if needed else used
    for k, qs in enumerate(system.q_symbols):
        if qs in used_q:
            lines.append(f"    {qs} = q[:, {k}]")
    for sym in system.aux_symbols:
        if sym in needed:
            lines.append(f"    {sym} = {_print(aux[sym])}")
    repl, reduced = sympy.cse(coeffs, symbols=sympy.numbered_symbols("t_"), order="canonical")
    for sym, expr in repl:
        lines.append(f"    {sym} = {_print(expr)}")
    for k, expr in enumerate(reduced):
        lines.append(f"    out[:, {k}] = {_print(expr)}")
    lines.append("    return out")
    return "\n".join(lines) + "\n"


def load_coefficients(source: str, name: str = "coefficients") -> Callable:
    """Compile the source of :func:`coefficient_source` into a function."""
    namespace: dict = {"np": np}
    exec(compile(source, f"<coefficients {name}>", "exec"), namespace)
    return namespace[name]


# --------------------------------------------------------------------------------------------------
# runtime
# --------------------------------------------------------------------------------------------------


def _complex_array(rows) -> np.ndarray:
    a = np.asarray(rows, dtype=float)
    return a[..., 0] + 1j * a[..., 1]


def _pairs(z: np.ndarray) -> list:
    def r(v: float) -> float:
        return float(f"{v:.{START_DIGITS}g}")

    if z.ndim == 1:
        return [[r(v.real), r(v.imag)] for v in z]
    return [_pairs(row) for row in z]


#: Evaluators of a solver's system: "auto" (the batched tracker on the straight-line program written from
#: the formulation where the system has one and it is validated: TDOA families A, B, C, and the systems
#: of :data:`VALIDATED_PROGRAMS`; else "monomials"), "tape" (that program, or else one traced from the
#: generated coefficient function and the expanded monomials: slower to evaluate, not validated on seeded
#: networks, hence not chosen by "auto"), "monomials" (the expanded system's coefficients, tracker.track).
EVALUATORS = ("auto", "tape", "monomials")

#: Systems with minors (squared) or in a positions formulation whose programs (slp.system_equations)
#: "auto" uses: each was validated on seeded networks (failures and error quantiles no worse than the
#: monomial tracker's on the same networks, docs/findings/homotopy-speed.md).
VALIDATED_PROGRAMS = frozenset({
    "5r4s:A,B2,B3,C2-C5,minors(4) (minors squared, seed 0)",
    "5r5s:B2,B3,C2-C5,M123_123,M124_124,M134_134,M234_234",  # its principal minors (solvers.generate.SQUARE_MINORS)
    "4r5s:positions-receivers-orbits",  # since jumped instances pool their routes (network 518)
})


def _validated(name: str) -> bool:
    """Whether "auto" may track the system ``name`` on its program (see :data:`VALIDATED_PROGRAMS`)."""
    return name in VALIDATED_PROGRAMS or not ("minors" in name or ":positions-" in name)


def _tapes(spec: dict, coefficients: Callable, evaluator: str):
    """The homotopy tapes (slp.HomotopyTapes) of the spec's system for ``evaluator``, or None."""
    if evaluator not in EVALUATORS:
        raise ValueError(f"unknown evaluator {evaluator!r}; valid: {', '.join(EVALUATORS)}")
    if evaluator == "monomials":
        return None
    from . import slp

    tapes = None
    if evaluator == "tape" or _validated(spec["system"]):
        try:
            tapes = slp.system_homotopy_tapes(spec["system"])
        except ValueError:
            pass
    names = list(spec["unknowns"]) + ["s"] + [f"q0:{p}" for p in spec["parameters"]] + [f"dq:{p}" for p in spec["parameters"]]
    if tapes is not None and (list(tapes.full.input_names) != names or not _agrees(tapes, spec, coefficients)):
        tapes = None  # a system named like a formulation but not its equations
    if tapes is None and evaluator == "tape":
        tapes = slp.homotopy_tapes(slp.expanded_equations(coefficients, spec["exponents"], spec["term_equation"]),
                                   spec["unknowns"], spec["parameters"])
    return tapes


def _agrees(tapes, spec: dict, coefficients: Callable) -> bool:
    """Whether the residual tape equals the spec's expanded system at two random complex points."""
    rng = np.random.default_rng(0)
    N, P = len(spec["unknowns"]), len(spec["parameters"])
    x = rng.normal(size=(2, N)) + 1j * rng.normal(size=(2, N))
    q = rng.normal(size=P) + 1j * rng.normal(size=P)
    H, _ = _expanded(coefficients, np.array(spec["exponents"]), np.array(spec["term_equation"]), N, x, q)
    with np.errstate(all="ignore"):
        diff = np.abs(tape_kernel.evaluate(tapes.residual, x, 0.0, q, q) - H)
    return bool(np.all(diff <= 1e-9 * (1.0 + np.abs(H).max())))


class HomotopySolver:
    """Tracks the stored start roots from q0 to target parameters (the online half of the method).

    ``evaluator`` (:data:`EVALUATORS`): how the tracker evaluates the system. The spec's "tracker" fields
    set the plain track's options, its "retrack" fields replace those of :data:`tracker.TIGHT` for the
    retracks and detours (:data:`solvers.generate.STEP_CONTROL`).
    """

    def __init__(self, spec: dict, coefficients: Callable, evaluator: str = "auto"):
        self.coefficients = coefficients
        self.tapes = _tapes(spec, coefficients, evaluator)
        self.structure = SystemStructure.from_exponents(np.array(spec["exponents"]), np.array(spec["term_equation"]))
        self.degree = int(spec["coefficient_degree"])
        self.q0 = _complex_array(spec["start_parameters"])
        roots = spec["start_roots"]
        self.x0 = _complex_array(roots) if roots else np.zeros((0, self.structure.nvars), complex)
        self.options = TrackerOptions(**spec.get("tracker", {}))
        self.retrack = dataclasses.replace(tracker.TIGHT, **spec.get("retrack", {}))
        self.nvars = self.structure.nvars
        # one root per orbit of a group (sign vectors; the direct parametrization's gauge reflections). An endpoint
        # on an image of another path's endpoint is path jumping too (unresolved(x, solver.group) tells), but it is
        # not retracked: 7r/5s room networks have about 3 such pairs of 2321 endpoints, complex ones; retracking
        # them with tight steps took 2.5x the solve (seed 0: 34.5 s against 13.9 s), and where that left a pair the
        # midpoint routes took up to 525 s (docs/minimal-3d.md, section 5)
        self.group = np.asarray(spec["group"]["signs"], dtype=float) if spec.get("group") else None
        tracked = (spec.get("full_system") or {}).get("tracked")
        if tracked is not None:  # a squared system: only the roots of the full system are tracked
            self.x0 = self.x0[np.asarray(tracked, dtype=np.int64)]
        self.n_paths = len(self.x0)
        if self.n_paths:
            self.x0 = self.newton(self.x0, np.broadcast_to(self.q0, (1, len(self.q0))), steps=2)
        # further complete start systems (:func:`extra_starts`): every path is tracked from each, the
        # distinct endpoints pooled, nothing retracked (:meth:`_multistart`)
        self.starts = [(self.q0, self.x0)]
        for item in spec.get("starts", []):
            qk = _complex_array(item["parameters"])
            self.starts.append((qk, self.newton(_complex_array(item["roots"]), qk[None], steps=2)))

    def segment(self, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
        return tracker.segment_coefficients(self.coefficients, q0, q1, self.degree)

    def newton(self, x: np.ndarray, q: np.ndarray, steps: int = 1, inst: np.ndarray | None = None) -> np.ndarray:
        """Newton steps on the system at parameters q (B, P); x (P', N), path p on instance inst[p]."""
        if self.tapes is not None:
            return tape_kernel.newton(self.tapes, q, x, inst, steps, native=tape_native.addresses(self.tapes))
        G = self.segment(q, q)
        for _ in range(steps):
            H, J, _ = tracker.evaluate(self.structure, G, x, np.zeros(len(x)), inst)
            with np.errstate(all="ignore"):
                try:
                    x = x - np.linalg.solve(J, H[..., None])[..., 0]
                except np.linalg.LinAlgError:
                    x = x - np.stack([np.linalg.lstsq(a, b, rcond=None)[0] for a, b in zip(J, H)])
        return x

    def residual(self, x: np.ndarray, q: np.ndarray, inst: np.ndarray | None = None) -> np.ndarray:
        G = self.segment(q, q)
        H, _, _ = tracker.evaluate(self.structure, G, x, np.zeros(len(x)), inst)
        return np.abs(H).max(axis=1)

    def track(self, q0: np.ndarray, q1: np.ndarray, x0: np.ndarray, inst: np.ndarray | None = None,
              options: TrackerOptions | None = None, near_end: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Track x0 (P, N) along q0 -> q1 (B, P) (path p on segment inst[p]); endpoints and stats
        (``near_end``: :func:`tape_kernel.track`'s, for the tape tracker)."""
        options = options or self.options
        if self.tapes is not None and options.predictor in tape_kernel.PREDICTORS:
            return tape_kernel.track(self.tapes, q0, q1, x0, inst, options, near_end=near_end,
                                     native=tape_native.addresses(self.tapes))
        if options.predictor == "pade":  # Taylor coefficients of the path come from the tapes only
            options = dataclasses.replace(options, predictor="rk4")
        G = self.segment(q0, q1)
        return tracker.track(self.structure, G, x0, inst, options)

    def _route(self, qa: np.ndarray, xa: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Track the complete root set xa (K, N) of qa to every target q (B, P) along straight segments.

        Paths that stall are first taken around their stall points (:meth:`_local_detours`); those still
        unresolved and paths that end on the same root as another path (path jumping) are retracked with
        tight step control on the same segments (when few of an instance's paths failed: many
        failures mean degenerate data, e.g. coincident nodes). Returns endpoints (B, K, N) and the
        mask of instances whose endpoints are complete (all finite and distinct).
        """
        B, K = len(q), len(xa)
        inst = np.repeat(np.arange(B), K)
        x, stats = self.track(qa[None], q, np.tile(xa, (B, 1)), inst)
        x = x.reshape(B, K, -1)
        stalled = stats[:, 0].reshape(B, K) == 1
        self._local_detours(qa, xa, q, x, stalled, stats[:, 3].reshape(B, K)[stalled])
        redo = stalled & ~np.all(np.isfinite(x), axis=2)
        for b in range(B):
            redo[b] |= _duplicated(x[b])
            if _degenerate(redo[b]):
                redo[b] = False
        bi, ki = np.nonzero(redo)
        if len(bi):
            xr, _ = self.track(qa[None], q, xa[ki], bi, self.retrack)
            x[bi, ki] = xr
        complete = np.array([not unresolved(x[b]).any() for b in range(B)])
        return x, complete

    def _local_detours(self, qa: np.ndarray, xa: np.ndarray, q: np.ndarray, x: np.ndarray, stalled: np.ndarray,
                       at: np.ndarray) -> None:
        """Track the stalled paths (mask (B, K); they stalled at s = at) from their start roots xa around their
        stall points (:data:`LOCAL_DETOUR`) into x (B, K, N), in place, where the endpoint is finite and
        distinct from the instance's other endpoints; one side of s*, then the other. Instances with many
        failed paths (degenerate data) are left to the caller."""
        bi, ki = np.nonzero(stalled)
        keep = np.array([not _degenerate(stalled[b]) for b in bi], dtype=bool)
        bi, ki, at = bi[keep], ki[keep], at[keep]
        d = np.minimum(LOCAL_DETOUR, np.minimum(at, 0.5 * (1.0 - at)))
        keep = d > 0
        bi, ki, at, d = bi[keep], ki[keep], at[keep], d[keep]
        for side in (1.0, -1.0):
            if not len(bi):
                return
            dq = q[bi] - qa[None, :]
            corners = [qa[None, :] + (at + c * d)[:, None] * dq for c in (-1.0, 1j * side, 1.0)]
            rows = np.arange(len(bi))
            y, _ = self.track(qa[None], corners[0], xa[ki], rows)
            for a, b in ((0, 1), (1, 2)):
                ok = np.all(np.isfinite(y), axis=1)
                y, _ = self.track(corners[a], corners[b], np.where(ok[:, None], y, 0.0), rows)
                y[~ok] = np.nan
            ok = np.all(np.isfinite(y), axis=1)
            y, _ = self.track(corners[2], q[bi], np.where(ok[:, None], y, 0.0), rows)
            y[~ok] = np.nan
            done = np.zeros(len(bi), dtype=bool)
            for j, (b, k) in enumerate(zip(bi, ki)):
                if np.all(np.isfinite(y[j])):
                    trial = x[b].copy()
                    trial[k] = y[j]
                    if not _duplicated(trial)[k]:
                        x[b, k] = y[j]
                        done[j] = True
            bi, ki, at, d = bi[~done], ki[~done], at[~done], d[~done]

    def _detour_point(self, k: int) -> np.ndarray:
        """The k-th fixed complex detour point in parameter space."""
        return self.q0 + DETOUR * np.sqrt(np.mean(np.abs(self.q0) ** 2)) * _detour_direction(len(self.q0), k)

    def _midpoint(self, k: int) -> tuple[np.ndarray, np.ndarray, bool]:
        """The k-th detour point, the distinct roots the paths from q0 reach there and whether they are
        all of them (computed on first need, then cached; 4r/5s loses a few paths on every such segment)."""
        cache = self.__dict__.setdefault("_midpoints", {})
        if k not in cache:
            qm = self._detour_point(k)
            xm, complete = self._route(self.q0, self.x0, qm[None])
            cache[k] = (qm, _distinct(xm[0]), bool(complete[0]))
        return cache[k]

    def roots(self, q: np.ndarray) -> np.ndarray:
        """Candidate roots (B, K, N) for target parameters q (B, P); NaN rows for lost paths."""
        q = np.atleast_2d(np.asarray(q, dtype=complex))
        if len(self.starts) > 1:
            return self._multistart(q)
        B, K = len(q), self.n_paths
        x, complete = self._route(self.q0, self.x0, q)
        bad = [b for b in np.flatnonzero(~complete) if not _degenerate(unresolved(x[b]))]
        # paths that still stall even with tight steps: the segment passes too close to a singular
        # point. Each such path alone goes around it through a fixed complex midpoint (two segments);
        # K distinct finite endpoints are all K roots whatever route each path took.
        jumped = {b for b in bad if _duplicated(x[b]).any()}
        for k in range(DETOURS):
            rows = np.zeros((B, K), dtype=bool)
            for b in bad:
                if b not in jumped:
                    rows[b] = ~np.all(np.isfinite(x[b]), axis=1)
            if not rows.any():
                break
            bj, kj = np.nonzero(rows)
            qm = self._detour_point(k)
            xm, _ = self.track(self.q0[None], qm[None], self.x0[kj], None, self.retrack)
            good = np.flatnonzero(np.all(np.isfinite(xm), axis=1))
            if not len(good):
                continue
            xe, _ = self.track(qm[None], q, xm[good], bj[good], self.retrack)
            for b, i, xi in zip(bj[good], kj[good], xe):
                if np.all(np.isfinite(xi)):
                    if _duplicated(np.vstack([x[b], xi[None]]))[-1]:
                        jumped.add(b)
                    else:
                        x[b, i] = xi
        # A route through a midpoint permutes the endpoints (monodromy): an endpoint that lands on a root
        # another path already holds means that path jumped (or took this one's root); then every path
        # of the instance takes the same midpoint route, whose endpoints are consistent, where the
        # midpoint's root set is complete; where that route is not complete either, the instance keeps
        # the distinct endpoints of both routes (:meth:`_pooled`; replacing the direct endpoints by a route
        # with fewer unresolved ones lost 4r/5s network 518's true root, which a direct path held).
        jumped = np.array(sorted(jumped), dtype=np.int64)
        for k in range(DETOURS):
            if not len(jumped):
                break
            qm, xm, complete_m = self._midpoint(k)
            if not complete_m:
                continue
            xk, ok = self._route(qm, xm, q[jumped])
            for j, b in enumerate(jumped):
                x[b] = xk[j] if ok[j] else self._pooled(x[b], xk[j], q[b])
            jumped = jumped[~ok]
        # Where no midpoint's root set is complete (4r/5s: 5-40 of its 344 paths stall near roots that go
        # to infinity, on every segment), an instance still short of K distinct roots sends every path
        # through a midpoint anyway and pools the distinct endpoints of both routes, compared after
        # Newton steps on the target (two unconverged endpoints of one ill-conditioned root, |x| ~ 5e4
        # in 4r/5s's scaled unknowns, can differ by more than the duplicate test's tolerance before
        # them and coincide after).
        left = np.array([b for b in bad if unresolved(x[b]).any()], dtype=np.int64)
        for k in range(POOLED_MIDPOINTS):
            if not len(left):
                break
            qm, xm, _ = self._midpoint(k)
            if not len(xm):
                continue
            L, M = len(left), len(xm)
            xk, _ = self.track(qm[None], q[left], np.tile(xm, (L, 1)), np.repeat(np.arange(L), M))
            xk = xk.reshape(L, M, -1)
            for j, b in enumerate(left):
                x[b] = self._pooled(x[b], xk[j], q[b])
            left = left[[bool(unresolved(x[b]).any()) for b in left]]
        return self._polish(x, q)

    def _multistart(self, q: np.ndarray) -> np.ndarray:
        """Candidate roots (B, K, N): the plain track from every start system, each instance's distinct
        endpoints pooled (polished on the target, in order of their next Newton step, at most K kept).

        For systems where a few paths of every segment stall in ill-conditioned stretches (4r/5s: about
        20 of 344, some of them the true root's on 4.4 % of seeded networks), a root one start's segment
        loses, another's usually reaches, at the cost of one plain track per start: cheaper than
        retracking the stalled paths with tight steps (1,000-4,000 steps each; tables/NOTES.md)."""
        B = len(q)
        parts = [self._plain(qa, xa, q, near_end=NEAR_END) for qa, xa in self.starts]  # (B, K, N) each
        return np.stack([_pool([x[b] for x in parts], self._next_step(np.concatenate([x[b] for x in parts]), q[b]))
                         for b in range(B)])

    def plain_roots(self, q: np.ndarray) -> np.ndarray:
        """Candidate roots (B, K, N) from the plain track alone, polished on the targets: no retracks, detours
        or pooled routes, so a stalled path's row stays NaN. The cheap first pass of a caller that can tell
        a right answer when it sees one (4r/6s: its extra transmitter; :mod:`solvers.subsystem`)."""
        return self._plain(self.q0, self.x0, np.atleast_2d(np.asarray(q, dtype=complex)))

    def _plain(self, qa: np.ndarray, xa: np.ndarray, q: np.ndarray, near_end: float = 0.0) -> np.ndarray:
        """The roots xa (K, N) of qa tracked to every target q (B, P) with the plain options, polished on the
        targets: (B, K, N), NaN rows for lost paths. ``near_end``: a path that stalls at s >= 1 - near_end
        gets :data:`RESCUE_NEWTON` Newton steps on its target from its last point."""
        B, K = len(q), len(xa)
        x, stats = self.track(qa[None], q, np.tile(xa, (B, 1)), np.repeat(np.arange(B), K), near_end=near_end)
        x = x.reshape(B, K, -1)
        bi, ki = np.nonzero((stats[:, 0] != 0).reshape(B, K) & np.all(np.isfinite(x), axis=2))
        if len(bi):  # stalled near the end (kept by near_end only)
            x[bi, ki] = self.newton(x[bi, ki], q, steps=RESCUE_NEWTON, inst=bi)
        return self._polish(x, q)

    def _pooled(self, a: np.ndarray, b: np.ndarray, q: np.ndarray) -> np.ndarray:
        """:func:`_pool` of two endpoint sets (K, n) of one instance with target parameters q (P,), both
        polished by Newton's method on the target first and ordered by their next Newton step."""
        rows = self._polish(np.vstack([a, b])[None], q[None])[0]
        return _pool([rows[: len(a)], rows[len(a):]], self._next_step(rows, q))

    def _next_step(self, rows: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Size of each row's (K, n) next Newton step on the target q (P,), relative to 1 + |row|; inf where
        the row is not finite."""
        step = np.full(len(rows), np.inf)
        ok = np.all(np.isfinite(rows), axis=1)
        if ok.any():
            step[ok] = np.linalg.norm(self.newton(rows[ok], q[None]) - rows[ok], axis=1) / (1.0 + np.linalg.norm(rows[ok], axis=1))
        return step

    def _polish(self, x: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Newton steps on the targets' own coefficients (x (B, K, N), q (B, P)): the tracker's are
        interpolated along the segment, with rounding errors relative to their size on |s| = 1."""
        B, K = x.shape[:2]
        flat = x.reshape(B * K, -1).copy()
        inst = np.repeat(np.arange(B), K)
        ok = np.all(np.isfinite(flat), axis=1)
        if ok.any():
            flat[ok] = self.newton(flat[ok], q, steps=FINAL_NEWTON, inst=inst[ok])
        return flat.reshape(B, K, -1)


def _degenerate(failed: np.ndarray) -> bool:
    """Whether too many of an instance's K paths failed (mask (K,)) for retracking to be worth it:
    degenerate data (e.g. coincident nodes), not path jumping."""
    return int(failed.sum()) > max(8, RETRACK_FRACTION * len(failed))


def unresolved(x: np.ndarray, group: np.ndarray | None = None) -> np.ndarray:
    """Mask of the endpoints (K, n) of one instance that were lost (NaN) or coincide with another (``group``: or
    with an image of another, one root per orbit tracked): where it is not all False, the root set is
    incomplete (solvers.api retries TOA networks transposed then)."""
    return ~np.all(np.isfinite(x), axis=1) | _duplicated(x, group=group)


def _near(f: np.ndarray, tol: float, sign: np.ndarray | None = None) -> np.ndarray:
    """near[i, j]: row j of f (finite rows; with ``sign``, its image sign * f_j) lies within tol (1 + |f_i|) of
    row i. Squared distances from the Gram matrix (rounding ~1e-16 |x|^2, far below tol^2 (1 + |x|)^2; the
    K x K x n differences took a tenth of a 9r/3s solve)."""
    size = np.linalg.norm(f, axis=1)
    g = f if sign is None else f * sign
    d2 = size[:, None] ** 2 + size[None, :] ** 2 - 2.0 * (f @ g.conj().T).real
    return d2 < (tol * (1.0 + size))[:, None] ** 2


def _duplicated(x: np.ndarray, tol: float = 1e-6, group: np.ndarray | None = None) -> np.ndarray:
    """Mask of the rows of x (K, n) that coincide with another finite row (path jumping); with ``group`` (sign
    vectors (G, n), one root per orbit tracked), also with an image of another row: one G-th of the distances
    at a time, never the G K x G K Gram matrix (7r/5s direct: 3 such pairs of 2321 endpoints on a room
    network, complex roots, two paths on one orbit)."""
    out = np.zeros(len(x), dtype=bool)
    ok = np.flatnonzero(np.all(np.isfinite(x), axis=1))
    if len(ok) < 2:
        return out
    if len(ok) > GRAM_ROWS:  # the K x K Gram matrix would not fit (a 10^5-point trace test): sorted projections
        out[ok] = _duplicated_by_projection(x[ok], tol, group)
        return out
    hit = np.zeros(len(ok), dtype=bool)
    for sign in (None,) if group is None else [None if np.all(g == 1.0) else g for g in np.asarray(group)]:
        near = _near(x[ok], tol, sign)
        np.fill_diagonal(near, False)
        hit |= near.any(axis=1)
    out[ok] = hit
    return out


#: Above this many finite rows :func:`_duplicated` compares by sorted projections instead of a Gram matrix.
GRAM_ROWS = 10_000

#: Seed of the fixed direction u of the sorted-projection searches (any direction gives the same decisions).
PROJECTION_SEED = 20261127


class _Projected:
    """Rows (K, n) sorted by their projection Re u^H x on a fixed direction u: the rows within distance d of a
    point y are among those whose projection lies within |u| d of y's (|Re u^H (x - y)| <= |u| |x - y|), found
    by binary search. The shared search of :func:`add_new` and :func:`_duplicated_by_projection`."""

    def __init__(self, rows: np.ndarray):
        rng = np.random.default_rng(PROJECTION_SEED)
        self.u = rng.normal(size=rows.shape[1]) + 1j * rng.normal(size=rows.shape[1])
        self.reach = np.linalg.norm(self.u) * (1.0 + 1e-9)
        proj = self.project(rows)
        self.order = np.argsort(proj, kind="stable")
        self.sorted = proj[self.order]

    def project(self, points: np.ndarray, sign: np.ndarray | None = None) -> np.ndarray:
        """Re u^H (sign * p) of every point p (sign real: Re (sign u)^H p)."""
        u = self.u if sign is None else sign * self.u
        return (points @ u.conj()).real

    def windows(self, proj: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """[lo, hi) into :attr:`order` of the rows that may lie within radius of points projecting to proj."""
        return (np.searchsorted(self.sorted, proj - self.reach * radius),
                np.searchsorted(self.sorted, proj + self.reach * radius, side="right"))


def _duplicated_by_projection(f: np.ndarray, tol: float, group: np.ndarray | None) -> np.ndarray:
    """:func:`_duplicated` of finite rows f (K, n) without the K x K matrix: row i is compared only with the
    rows in reach of its images' projections (:class:`_Projected`)."""
    index = _Projected(f)
    limit = tol * (1.0 + np.linalg.norm(f, axis=1))
    signs = np.ones((1, f.shape[1])) if group is None else np.asarray(group, dtype=float)
    rows = np.arange(len(f))
    hit = np.zeros(len(f), dtype=bool)
    for g in signs:  # |f_i - g f_j| = |g f_i - f_j|: the image of row i against the rows themselves
        lo, hi = index.windows(index.project(f, g), limit)
        alone = (hi - lo == 1) & (index.order[np.minimum(lo, len(f) - 1)] == rows)  # only itself in reach
        for i in np.flatnonzero((hi > lo) & ~alone & ~hit):
            cand = index.order[lo[i]:hi[i]]
            cand = cand[cand != i]
            if len(cand) and np.min(np.linalg.norm(f[cand] - g * f[i], axis=1)) < limit[i]:
                hit[i] = True
    return hit


def _distinct(x: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """The finite rows of x (K, n), one per group of coinciding rows (same test as :func:`_duplicated`):
    in order, a row is kept unless it lies within tol (1 + |row|) of a row kept before it."""
    f = x[np.all(np.isfinite(x), axis=1)]
    if len(f) < 2:
        return f.reshape(-1, x.shape[1])
    close = np.tril(_near(f, tol), k=-1)  # row i within reach of an earlier row j
    kept = ~close.any(axis=1)  # no earlier row near: kept whatever the others
    dropped = (close & kept[None, :]).any(axis=1)  # near a row that is kept
    for i in np.flatnonzero(~kept & ~dropped):
        kept[i] = not np.any(close[i, :i] & kept[:i])
    return f[kept]


def _pool(sets: list[np.ndarray], step: np.ndarray | None = None) -> np.ndarray:
    """The distinct roots of endpoint sets (K, n) of one instance as K rows (NaN-padded), in the sets' order;
    with ``step`` (each row's next Newton step on the target, the sets' rows in turn) in order of it
    instead, so that of two copies of one root the converged one is kept and a surplus over K (an
    unconverged copy counted as distinct: 4r/5s network 85) drops the least converged rows."""
    rows = np.vstack(sets)
    if step is not None:
        rows = rows[np.argsort(step, kind="stable")]
    rows = _distinct(rows)[: len(sets[0])]
    out = np.full_like(sets[0], np.nan)
    out[: len(rows)] = rows
    return out


def extra_starts(spec: dict, coefficients: Callable, count: int) -> list[dict]:
    """``count`` further start systems for :meth:`HomotopySolver._multistart`, as spec entries: seeded complex
    parameters (the k-th detour direction, :func:`_detour_direction`, scaled to the RMS of q0) and all their K roots, found by the spec's solver (retracks, detours,
    pooled routes) and checked: K distinct finite roots, each converged under Newton's method."""
    solver = HomotopySolver({**spec, "starts": []}, coefficients)
    q0, K = solver.q0, solver.n_paths
    out = []
    for k in range(count):
        qk = np.sqrt(np.mean(np.abs(q0) ** 2)) * _detour_direction(len(q0), k)
        qk = np.array([complex(*v) for v in _pairs(qk)])  # as stored
        x = solver.roots(qk[None])[0]
        x = solver.newton(_distinct(x), qk[None], steps=3)
        step = np.linalg.norm(solver.newton(x, qk[None]) - x, axis=1) / (1.0 + np.linalg.norm(x, axis=1)) if len(x) else np.inf
        if len(x) != K or np.max(step) > START_TOL or _has_duplicates(x):
            raise HomotopyError(f"{spec['system']}: extra start {k + 1}: {len(x)} distinct roots of {K} "
                                f"(largest Newton step {np.max(step):.1e})")
        order = np.lexsort((np.round(x.imag[:, 0], 8), np.round(x.real[:, 0], 8)))
        out.append({"parameters": _pairs(qk), "roots": _pairs(x[order])})
    return out


def _has_duplicates(x: np.ndarray, tol: float = 1e-6) -> bool:
    return bool(_duplicated(x, tol).any())


# --------------------------------------------------------------------------------------------------
# offline build
# --------------------------------------------------------------------------------------------------


def affine_start(system: ParametricSystem, coefficients: Callable, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A random complex root x0 and parameters q0 that make it a root, for systems affine in q.

    The residual is affine in q: f(x0; q) = A q + b; q0 is a random point of that affine space.
    Raises :class:`HomotopyError` if the system is not affine in its parameters or A lacks rank.
    """
    if system.definitions or any(c > 1 for c in system.coefficient_degrees):
        raise HomotopyError(f"{system.name}: parameters enter non-linearly; give a start sampler "
                            "(a point q0 with a known root) to build a homotopy")
    N, P = len(system.unknowns), len(system.parameters)
    exps, eq = structure(system)
    st = SystemStructure.from_exponents(exps, eq)
    x0 = rng.normal(size=N) + 1j * rng.normal(size=N)

    def f(q):
        G = tracker.segment_coefficients(coefficients, q[None], q[None], 1)
        H, _, _ = tracker.evaluate(st, G, x0[None], np.zeros(1))
        return H[0]

    b = f(np.zeros(P, dtype=complex))
    A = np.column_stack([f(np.eye(P, dtype=complex)[k]) - b for k in range(P)])
    if np.linalg.matrix_rank(A) < N:
        raise HomotopyError(f"{system.name}: the parameters do not move every equation (rank {np.linalg.matrix_rank(A)} < {N})")
    q_part = np.linalg.lstsq(A, -b, rcond=None)[0]
    _, _, Vh = np.linalg.svd(A)
    null = Vh[np.linalg.matrix_rank(A):].conj().T
    q0 = q_part + null @ (rng.normal(size=null.shape[1]) + 1j * rng.normal(size=null.shape[1]))
    return q0, x0


def _monodromy_loop(solver: HomotopySolver, q0: np.ndarray, roots: np.ndarray, rng: np.random.Generator,
                    options: HomotopyOptions, excluded: Callable[[np.ndarray], np.ndarray] | None,
                    free: np.ndarray | None = None, group: np.ndarray | None = None,
                    track: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None) -> tuple[np.ndarray, int]:
    """One monodromy loop (a triangle q0 -> qa -> qb -> q0 through random complex parameters) from all known
    roots: (the known roots with the new ones appended, the number of paths tracked). ``free``: mask of the
    parameters the loop moves (default all; the trace test's witness loops keep its pencil parameter at 0).
    ``group``: sign vectors (G, N) of a group acting on the unknowns that fixes the parameters (the direct
    parametrization's reflections of the gauge frame); the roots are then one per orbit, and an endpoint is
    new only when no image of it is known (the loop commutes with the group, so the orbits' other members
    need not be tracked). ``track(a, b, xs)``: the endpoints of xs along a -> b (default: the solver's tracker
    in this process; :class:`solvers.methods.dask_tracks.DaskTracks`: on a Dask cluster).

    New endpoints count only when Newton's method has converged on them and, with ``excluded`` (a mask of
    points on the locus of the non-vanishing conditions), when they lie off that locus; a new root is one
    farther than 1e-6 (relative) from every known root.
    """
    scale = np.sqrt(np.mean(np.abs(q0) ** 2))
    qa = q0 + options.radius * scale * (rng.normal(size=q0.shape) + 1j * rng.normal(size=q0.shape))
    qb = q0 + options.radius * scale * (rng.normal(size=q0.shape) + 1j * rng.normal(size=q0.shape))
    if free is not None:
        qa, qb = np.where(free, qa, q0), np.where(free, qb, q0)
    track = track or (lambda a, b, xs: solver.track(a[None], b[None], xs)[0])
    xs, paths = roots, 0
    for a, b in ((q0, qa), (qa, qb), (qb, q0)):
        paths += len(xs)
        xs = track(a, b, xs)
        xs = xs[np.all(np.isfinite(xs), axis=1)]
    return add_new(roots, accepted(solver, xs, q0, excluded, options.accept_tol), group), paths


def accepted(solver, xs: np.ndarray, q0: np.ndarray, excluded: Callable[..., np.ndarray] | None = None,
             tol: float = START_TOL) -> np.ndarray:
    """The endpoints xs (K, N) that are roots at q0: finite, polished by three Newton steps after which the next
    step is below ``tol`` (relative), and (``excluded``: a mask of points on the locus of the non-vanishing
    conditions) off that locus."""
    xs = xs[np.all(np.isfinite(xs), axis=1)]
    if not len(xs):
        return xs
    xs = solver.newton(xs, q0[None], steps=3)
    step = np.linalg.norm(solver.newton(xs, q0[None]) - xs, axis=1) / (1.0 + np.linalg.norm(xs, axis=1))
    keep = step < tol
    if excluded is not None:
        keep &= ~excluded(xs)
    return xs[keep & np.all(np.isfinite(xs), axis=1)]


def add_new(roots: np.ndarray, xs: np.ndarray, group: np.ndarray | None = None) -> np.ndarray:
    """roots (R, N) with every x of xs appended, in order, that lies farther than 1e-6 (1 + |x|) from each root
    known by then (``group``: sign vectors (G, N), and from each root's images: one root per orbit).

    Each x is compared only with the roots in reach of its images' projections (:class:`_Projected`, binary
    search; the endpoints with exactly one root in reach, most of a loop's, in one vectorised step): the same
    decisions as comparing with every root, in O((R + K) log R) instead of O(R K) (25,000 endpoints against
    20,000 roots x 8 images in 35 unknowns: 0.6 s instead of about 2,400 s)."""
    roots = np.asarray(roots, dtype=complex)
    xs = np.asarray(xs, dtype=complex).reshape(-1, roots.shape[1])
    if not len(xs):
        return roots
    images = np.ones((1, roots.shape[1])) if group is None else np.asarray(group, dtype=float)
    tol = 1e-6 * (1.0 + np.linalg.norm(xs, axis=1))
    known = _Projected(roots)
    near = np.zeros(len(xs), dtype=bool)
    for g in images:
        lo, hi = known.windows(known.project(xs, g), tol)
        one = np.flatnonzero((hi - lo == 1) & ~near)
        if len(one):
            near[one] |= np.linalg.norm(roots[known.order[lo[one]]] - g * xs[one], axis=1) <= tol[one]
        for i in np.flatnonzero((hi - lo > 1) & ~near):
            near[i] = np.min(np.linalg.norm(roots[known.order[lo[i]:hi[i]]] - g * xs[i], axis=1)) <= tol[i]
    fresh = np.flatnonzero(~near)
    # among the new ones, in order: kept when far from every one kept before it
    new = _Projected(xs[fresh])
    keep = np.zeros(len(fresh), dtype=bool)
    for a, i in enumerate(fresh):
        keep[a] = True
        for g in images:
            lo, hi = new.windows(new.project(xs[i:i + 1], g), tol[i:i + 1])
            cand = new.order[lo[0]:hi[0]]
            cand = cand[(cand < a) & keep[cand]]
            if len(cand) and np.min(np.linalg.norm(xs[fresh[cand]] - g * xs[i], axis=1)) <= tol[i]:
                keep[a] = False
                break
    kept = fresh[keep]
    return np.vstack([roots, xs[kept]]) if len(kept) else roots


def monodromy(solver: HomotopySolver, q0: np.ndarray, x0: np.ndarray, count: int, rng: np.random.Generator,
              options: HomotopyOptions, progress: Callable[[str], None] | None = None,
              excluded: Callable[[np.ndarray], np.ndarray] | None = None) -> tuple[np.ndarray, int]:
    """All ``count`` roots of the system at q0 from the roots x0, by monodromy loops (:func:`_monodromy_loop`).

    Stops when ``count`` distinct roots are known; raises :class:`HomotopyError` after
    ``max_loops`` loops or ``stall_loops`` loops without a new root.
    """
    roots = np.array(x0, dtype=complex).reshape(-1, solver.nvars)
    stall = 0
    for loop in range(1, options.max_loops + 1):
        before = len(roots)
        roots, _ = _monodromy_loop(solver, q0, roots, rng, options, excluded)
        stall = 0 if len(roots) > before else stall + 1
        if progress:
            progress(f"monodromy loop {loop}: {len(roots)}/{count} roots")
        if len(roots) >= count:
            if len(roots) > count:
                raise HomotopyError(f"monodromy found {len(roots)} roots, more than the certified {count}: "
                                    "numerical duplicates or a wrong count")
            return roots, loop
        if stall >= options.stall_loops:
            break
    raise HomotopyError(f"monodromy found {len(roots)} of the certified {count} roots in {loop} loops "
                        f"(seed {options.seed}); the solver would miss roots")


@dataclass(frozen=True)
class MonodromyCount:
    """A root count by monodromy alone (no certificate): the roots at q0, the loops run, the paths tracked,
    the loops since the last new root and the seconds (this run and the checkpoints it resumed)."""

    roots: np.ndarray
    loops: int
    paths: int
    stall: int
    seconds: float


def start_solver(system: ParametricSystem, q0: np.ndarray, x0: np.ndarray,
                 seed: int = 0) -> tuple[HomotopySolver, np.ndarray]:
    """A solver of ``system`` with the one start pair (q0, x0) and no certified count, for counting roots by
    monodromy (:func:`monodromy_count`): (solver, x0 refined by Newton's method). Raises
    :class:`HomotopyError` when x0 is not a root at q0."""
    coefficients = load_coefficients(coefficient_source(system))
    exps, eq = structure(system)
    q0 = np.asarray(q0, dtype=complex)
    spec = {"format": SPEC_FORMAT, "kind": "homotopy", "system": system.name, "unknowns": list(system.unknowns),
            "parameters": list(system.parameters), "degree": 0, "coefficient_degree": int(max(system.coefficient_degrees)),
            "monodromy": {"seed": seed}, "tracker": {}, "term_equation": eq.tolist(), "exponents": exps.tolist(),
            "start_parameters": _pairs(q0), "start_roots": _pairs(np.atleast_2d(x0))}
    solver = HomotopySolver(spec, coefficients)
    x0 = solver.newton(np.atleast_2d(x0), q0[None], steps=3)
    if solver.residual(x0, q0[None]).max() > 1e-8:
        raise HomotopyError(f"{system.name}: the start point is not a root (residual {solver.residual(x0, q0[None]).max():.1e})")
    return solver, x0


def monodromy_count(solver: HomotopySolver, q0: np.ndarray, x0: np.ndarray, options: HomotopyOptions,
                    seconds: float, checkpoint: str | None = None,
                    progress: Callable[[str], None] | None = None,
                    excluded: Callable[[np.ndarray], np.ndarray] | None = None,
                    free: np.ndarray | None = None, group: np.ndarray | None = None,
                    track: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None) -> MonodromyCount:
    """Grow the roots at q0 by monodromy loops until ``options.stall_loops`` loops bring nothing new, or
    ``options.max_loops`` loops, or ``seconds`` have passed (then the count is a lower bound).

    checkpoint: a JSON file (plain text: q0, roots, loops, paths, stall, seconds, the rng state, the acceptance
    tolerance) written after every loop and resumed from when it exists for the same q0, so that a long count
    survives an interruption; under another ``options.accept_tol`` its roots are kept and its loops without a
    new root count again from 0. Numerical evidence only: a root count without the GF(p) certificate of :func:`build`.
    ``free``: the parameters the loops move, ``group``: roots kept one per orbit, ``track``: where the paths are
    tracked (:func:`_monodromy_loop`).
    Completeness: :mod:`.trace`.
    """
    roots = np.array(x0, dtype=complex).reshape(-1, solver.nvars)
    loops = paths = stall = 0
    spent = 0.0
    rng = np.random.default_rng(options.seed)
    if checkpoint and os.path.exists(checkpoint):
        with open(checkpoint, encoding="utf-8") as fh:
            saved = json.load(fh)
        # the same start instance (the file keeps START_DIGITS significant digits of q0 and the roots)
        if np.allclose(_complex_array(saved["q0"]), q0, rtol=10.0 ** (1 - START_DIGITS), atol=0):
            roots = _complex_array(saved["roots"])
            loops, paths, stall, spent = saved["loops"], saved["paths"], saved["stall"], saved["seconds"]
            rng.bit_generator.state = saved["rng"]
            if saved.get("accept_tol", START_TOL) != options.accept_tol:  # loops without a new root under
                stall = 0  # another acceptance rule do not count towards this one's
                if progress:
                    progress(f"checkpoint of {loops} loops kept ({len(roots)} roots); its loops without a new one "
                             f"start again: endpoints now accepted at {options.accept_tol:.0e}, "
                             f"not {saved.get('accept_tol', START_TOL):.0e}")
    t0 = time.perf_counter()
    while loops < options.max_loops and stall < options.stall_loops and time.perf_counter() - t0 < seconds:
        before = len(roots)
        roots, tracked = _monodromy_loop(solver, q0, roots, rng, options, excluded, free, group, track)
        loops, paths = loops + 1, paths + tracked
        stall = 0 if len(roots) > before else stall + 1
        if checkpoint:
            record = {"q0": _pairs(q0), "roots": _pairs(roots), "loops": loops, "paths": paths, "stall": stall,
                      "seconds": round(spent + time.perf_counter() - t0, 1), "rng": rng.bit_generator.state,
                      "accept_tol": options.accept_tol}
            tmp = checkpoint + ".tmp"
            with open(tmp, "w", encoding="utf-8") as fh:
                json.dump(record, fh)
            os.replace(tmp, checkpoint)
        if progress:
            progress(f"monodromy loop {loops}: {len(roots)} roots ({paths} paths, {stall} loop(s) without a new one, "
                     f"{spent + time.perf_counter() - t0:.0f} s)")
    return MonodromyCount(roots, loops, paths, stall, spent + time.perf_counter() - t0)


def _excluded(system: ParametricSystem, q0: np.ndarray, rel: float = 1e-8) -> Callable[..., np.ndarray] | None:
    """Mask of points where a non-vanishing condition is (numerically) zero at parameters q0, or None.
    The mask is ``mask(x)``, or ``mask(x, q)`` with parameters q (K, P) per point (the trace test's witnesses
    lie over different parameters).

    A condition of degree d counts as zero when it cancels to rounding level (its value below ``rel``
    times the sum of its terms' moduli) or when all its terms are at noise level for the point's size
    (their sum below (1e-8 (1 + |x|))^d, e.g. H = 0 computed as 1e-12). A single threshold relative to
    |x| would also exclude genuine roots whose condition is small only because its variables are
    (5r/5s: det H ~ 1e-8 with H ~ 1e-4 and offsets ~ 100, a root the GF(p) saturation keeps).
    """
    if not system.nonzero:
        return None
    import sympy

    args = system.x_symbols + system.q_symbols
    conditions = []
    for g in system.nonzero_exprs:
        poly = sympy.Poly(g, *system.x_symbols)  # terms: one per monomial in x, coefficients in q
        terms = [c * sympy.Mul(*(v**e for v, e in zip(system.x_symbols, mon))) for mon, c in poly.terms()]
        conditions.append((sympy.lambdify(args, terms, "numpy"), poly.total_degree()))

    def mask(x: np.ndarray, q: np.ndarray | None = None) -> np.ndarray:
        noise = 1e-8 * (1.0 + np.linalg.norm(x, axis=1))
        out = np.zeros(len(x), dtype=bool)
        qs = q0 if q is None else np.asarray(q).T
        for terms, degree in conditions:
            values = np.array([np.broadcast_to(v, (len(x),)) for v in terms(*x.T, *qs)])
            size = np.abs(values).sum(axis=0)
            out |= (np.abs(values.sum(axis=0)) <= rel * size) | (size <= noise ** degree)
        return out

    return mask


def system_residuals(system: ParametricSystem, x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Largest relative residual over the equations of ``system`` (any shape, e.g. over-determined) at
    points x (K, N) and parameters q (P,): |f_e(x)| / sum of the moduli of f_e's terms."""
    exps, eq = structure(system)
    H, size = _expanded(load_coefficients(coefficient_source(system)), exps, eq, len(system.equations), x, q)
    return np.max(np.abs(H) / np.maximum(size, np.finfo(float).tiny), axis=1)


def _expanded(coefficients: Callable, exps: np.ndarray, eq: np.ndarray, n_eq: int, x: np.ndarray,
              q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values (K, n_eq) of an expanded system (term coefficients from ``coefficients``, exponents (T, N),
    equation of each term (T,)) at points x (K, N) and parameters q (P,), and the sums of its terms'
    moduli; numpy alone (a solver's first call compiles no monomial kernel to check its program)."""
    c = coefficients(np.asarray(q, dtype=complex)[None])[0]
    x = np.asarray(x, dtype=complex)
    terms = c[None, :] * np.prod(x[:, None, :] ** exps[None, :, :], axis=2)  # (K, T)
    H = np.zeros((len(x), n_eq), dtype=complex)
    size = np.zeros(H.shape)
    np.add.at(H.T, eq, terms.T)
    np.add.at(size.T, eq, np.abs(terms).T)
    return H, size


#: A start root of a squared system is a root of the full system when its relative residual there is
#: below FULL_TOL; every other root must be above FULL_GAP (5r/4s, 5r/5s: 3e-14 against 7.7e-4).
FULL_TOL = 1e-8
FULL_GAP = 1e-5


def full_system_roots(full: ParametricSystem, spec: dict, coefficients: Callable, degree: int) -> list[int]:
    """Indices of the start roots of a squared system's spec that are roots of the full system.

    Only they need tracking when the squared system's roots split into families (components of its
    incidence variety over the whole parameter space) one of which meets consistent data exactly in
    the full system's roots: continuation stays in a family, so paths from the full system's start
    roots end at the target's full-system roots, and the other paths end at spurious roots. That holds
    for the TDOA squared systems (5r/4s, 5r/5s: every endpoint of those paths satisfies the full
    system, along straight and bent routes; tables/NOTES.md) and is checked on seeded instances by the
    build's verification and by tests; the bench measures the failure rate. Raises
    :class:`HomotopyError` unless exactly ``degree`` (the full system's certified count) start roots
    are, with a clear gap to the others.
    """
    solver = HomotopySolver(spec, coefficients)  # start roots refined by Newton's method
    res = system_residuals(full, solver.x0, solver.q0)
    tracked = np.flatnonzero(res < FULL_TOL)
    others = np.delete(res, tracked)
    if len(tracked) != degree or (len(others) and others.min() < FULL_GAP):
        raise HomotopyError(f"{full.name}: {len(tracked)} start roots satisfy the full system, certified {degree}; "
                            f"smallest residual of the others {others.min() if len(others) else float('nan'):.1e}")
    return tracked.tolist()


@dataclass(frozen=True)
class MonodromyCheckpoint:
    """What :func:`monodromy_count` wrote to its checkpoint: the start parameters q0, the roots there (one per
    orbit when it ran with a group), the loops run, the paths tracked, the loops since the last new root and
    the seconds spent."""

    q0: np.ndarray
    roots: np.ndarray
    loops: int
    paths: int
    stall: int
    seconds: float


def read_checkpoint(path: str) -> MonodromyCheckpoint:
    """A checkpoint of :func:`monodromy_count` (plain JSON); raises :class:`HomotopyError` for a file without
    its fields. Nothing is checked against a system here (:func:`checked_roots` does)."""
    with open(path, encoding="utf-8") as fh:
        saved = json.load(fh)
    missing = [k for k in ("q0", "roots", "loops", "paths", "stall") if k not in saved]
    if missing:
        raise HomotopyError(f"{path}: not a monodromy checkpoint (no {', '.join(missing)})")
    return MonodromyCheckpoint(_complex_array(saved["q0"]), _complex_array(saved["roots"]), int(saved["loops"]),
                               int(saved["paths"]), int(saved["stall"]), float(saved.get("seconds", 0.0)))


#: Largest relative residual (:func:`system_residuals`: |f_e| over the sum of f_e's terms' moduli) a stored
#: root may have at its parameters before Newton's method: the checkpoints keep START_DIGITS digits, which
#: leaves about 1e-11 (7r/5s direct: 2e-11 at most); a root of another instance or system has 1e-3 or more.
CHECKPOINT_TOL = 1e-8


def checked_roots(system: ParametricSystem, q0: np.ndarray, roots: np.ndarray,
                  group: np.ndarray | None = None) -> np.ndarray:
    """The roots (K, N) of ``system`` at q0 read from a checkpoint, refined by Newton's method, after checking
    that each satisfies the system (relative residual <= :data:`CHECKPOINT_TOL` as stored, next Newton step
    <= :data:`START_TOL` after refinement) and that no two coincide, nor (with ``group``, sign vectors (G, N))
    lie in one orbit. Raises :class:`HomotopyError` naming how many roots fail and the worst value."""
    roots = np.atleast_2d(np.asarray(roots, dtype=complex))
    q0 = np.asarray(q0, dtype=complex)
    if roots.shape[1] != len(system.unknowns) or len(q0) != len(system.parameters):
        raise HomotopyError(f"{system.name}: the checkpoint has {roots.shape[1]} unknowns and {len(q0)} parameters, "
                            f"the system {len(system.unknowns)} and {len(system.parameters)}")
    res = system_residuals(system, roots, q0)
    bad = ~(res <= CHECKPOINT_TOL)
    if bad.any():
        raise HomotopyError(f"{system.name}: {int(bad.sum())} of {len(roots)} checkpoint roots do not satisfy the system "
                            f"at its q0 (relative residual up to {np.nanmax(np.where(np.isfinite(res), res, np.inf)):.1e}, "
                            f"tolerance {CHECKPOINT_TOL:.0e})")
    solver, _ = start_solver(system, q0, roots[:1])
    roots = solver.newton(roots, q0[None], steps=3)
    step = np.linalg.norm(solver.newton(roots, q0[None]) - roots, axis=1) / (1.0 + np.linalg.norm(roots, axis=1))
    if not np.all(step <= START_TOL):
        raise HomotopyError(f"{system.name}: {int(np.sum(~(step <= START_TOL)))} checkpoint roots do not converge under "
                            f"Newton's method (next step up to {np.nanmax(step):.1e})")
    same = int(_duplicated(roots, group=group).sum())
    if same:
        raise HomotopyError(f"{system.name}: {same} checkpoint roots coincide with another"
                            + (" or with an image of another under the group" if group is not None else ""))
    return roots


def build(system: ParametricSystem, count: int | None, start: Callable[[np.random.Generator], tuple[np.ndarray, np.ndarray]] | None = None,
          trials: Callable[[int], tuple[np.ndarray, np.ndarray]] | None = None,
          options: HomotopyOptions = HomotopyOptions(), progress: Callable[[str], None] | None = None,
          checkpoint: MonodromyCheckpoint | None = None, group: np.ndarray | None = None) -> tuple[dict, str, dict]:
    """Spec, coefficient source and build report of the homotopy solver of a square system.

    count: the certified number of roots (GF(p), two primes), or None: numerical evidence alone, monodromy
    until ``options.stall_loops`` loops find no new root (the count is then what it found). start: rng -> (q0, x0) generic complex
    parameters with one known root (default :func:`affine_start`). trials: seed -> (q real, known
    root) for the verification on seeded real instances (skipped when None). checkpoint (with count None): the
    q0 and roots of a settled :func:`monodromy_count` instead of growing them again (checked by
    :func:`checked_roots`); group: sign vectors (G, N) whose orbits the roots come in, one root per orbit
    stored and tracked (the spec's "group"; its "degree" counts every root, G per orbit, and its "paths"
    the orbits).
    """
    t0 = time.perf_counter()
    if not system.is_square:
        raise HomotopyError(f"{system.name}: {len(system.equations)} equations in {len(system.unknowns)} unknowns; "
                            "a homotopy needs a square system (square it first)")
    system.check_parameters_occur()
    source = coefficient_source(system)
    coefficients = load_coefficients(source)
    rng = np.random.default_rng(options.seed)
    if checkpoint is not None:
        q0, x0 = checkpoint.q0, None
    else:
        q0, x0 = start(rng) if start is not None else affine_start(system, coefficients, rng)
    exps, eq = structure(system)
    spec = {
        "format": SPEC_FORMAT,
        "kind": "homotopy",
        "system": system.name,
        "unknowns": list(system.unknowns),
        "parameters": list(system.parameters),
        "degree": int(count or 0),  # set by the monodromy count when None
        "coefficient_degree": int(max(system.coefficient_degrees)),
        "monodromy": {"seed": options.seed},
        "tracker": {},
        "term_equation": eq.tolist(),
        "exponents": exps.tolist(),
        "start_parameters": _pairs(np.asarray(q0, dtype=complex)),
        "start_roots": [],
    }
    solver = HomotopySolver(spec, coefficients)
    solver.q0 = np.asarray(q0, dtype=complex)
    if checkpoint is None:
        x0 = solver.newton(np.atleast_2d(x0), q0[None], steps=3)
        if solver.residual(x0, q0[None]).max() > 1e-8:
            raise HomotopyError(f"{system.name}: the start point is not a root (residual {solver.residual(x0, q0[None]).max():.1e})")
    if checkpoint is not None:  # a settled count grown earlier (scripts/monodromy_counts.py): checked, not regrown
        if count is not None:
            raise HomotopyError(f"{system.name}: a checkpoint's roots are numerical evidence; no certified count with it")
        if checkpoint.stall < options.stall_loops:
            raise HomotopyError(f"{system.name}: the checkpoint's count is not settled ({checkpoint.stall} loops without a "
                                f"new root, {options.stall_loops} asked); no solver from an unsettled count")
        roots, loops = checked_roots(system, solver.q0, checkpoint.roots, group), checkpoint.loops
        count = len(roots) * (1 if group is None else len(group))
        spec["degree"] = count
        spec["monodromy"] = {"checkpoint": True, "paths": checkpoint.paths, "loops_without_new": checkpoint.stall}
    elif count is None:  # numerical evidence alone: loops until options.stall_loops of them bring nothing new
        grown = monodromy_count(solver, solver.q0, x0, options, float("inf"), progress=progress,
                                excluded=_excluded(system, solver.q0))
        if grown.stall < options.stall_loops:
            raise HomotopyError(f"{system.name}: monodromy still found new roots after {grown.loops} loops "
                                f"({len(grown.roots)} so far); no solver from an unsettled count")
        roots, loops, count = grown.roots, grown.loops, len(grown.roots)
        spec["degree"] = count
    else:
        roots, loops = monodromy(solver, solver.q0, x0, count, rng, options, progress, _excluded(system, solver.q0))
    roots = solver.newton(roots, solver.q0[None], steps=3)
    step = np.max(np.linalg.norm(solver.newton(roots, solver.q0[None]) - roots, axis=1) / (1.0 + np.linalg.norm(roots, axis=1)))
    if step > START_TOL or _has_duplicates(roots):
        raise HomotopyError(f"{system.name}: start roots not converged (Newton step {step:.1e}) or duplicated "
                            f"({_has_duplicates(roots)})")
    order = np.lexsort((np.round(roots.imag[:, 0], 8), np.round(roots.real[:, 0], 8)))
    spec["start_parameters"] = _pairs(solver.q0)
    spec["start_roots"] = _pairs(roots[order])
    spec["monodromy"]["loops"] = loops
    if group is not None:
        spec["group"] = {"name": "gauge reflections", "order": len(group), "signs": np.asarray(group).astype(int).tolist()}
    report = {"method": "homotopy", "degree": int(count), "loops": loops, "paths": len(roots)}
    if trials is not None and options.verify_trials:
        report["verified"] = verify(system.name, spec, coefficients, trials, options.verify_trials)
    report["seconds"] = round(time.perf_counter() - t0, 2)
    return spec, source, report


def verify(name: str, spec: dict, coefficients: Callable, trials: Callable[[int], tuple[np.ndarray, np.ndarray]],
           count: int) -> str:
    """Solve ``count`` seeded real instances (seed -> (q, known root)) with the spec's solver; "found/count",
    or :class:`HomotopyError` when the known root is missed in more than 10 % of them."""
    solver = HomotopySolver(spec, coefficients)
    return verify_found(name, lambda q: expand_orbits(solver.roots(q[None])[0], spec), trials, count, HomotopyError)


def expand_orbits(x: np.ndarray, spec: dict) -> np.ndarray:
    """Every root from one root per orbit: x (..., K, N) -> (..., G K, N), the images under the spec's group
    (sign vectors (G, N), its "group"; the identity first) one after the other; x itself without a group."""
    group = spec.get("group")
    if not group:
        return x
    signs = np.asarray(group["signs"], dtype=float)
    return np.concatenate([x * g for g in signs], axis=-2)


def load_spec(text: str) -> dict:
    """A spec from its JSON text; raises :class:`HomotopyError` for another format."""
    return load_format(text, SPEC_FORMAT, HomotopyError, "homotopy")


def solve_scaled(solver: HomotopySolver, F, shape: tuple[int, ...], powers: tuple[float, ...] | None,
                 plain: bool = False) -> np.ndarray:
    """Roots for data F (..., *shape): parameters normalised by their RMS when ``powers`` (the scaling
    weights of the unknowns) are known, roots mapped back to the data's scale. ``plain``: the plain track
    alone (:meth:`HomotopySolver.plain_roots`)."""
    F = np.asarray(F)
    if F.shape[F.ndim - len(shape):] != tuple(shape):
        raise ValueError(f"data of shape {F.shape} given; the solver needs (..., {', '.join(map(str, shape))})")
    batch = F.shape[: F.ndim - len(shape)]
    Q = F.reshape(-1, int(np.prod(shape))).astype(complex)
    roots = solver.plain_roots if plain else solver.roots
    if powers is not None:
        s = np.sqrt(np.mean(np.abs(Q) ** 2, axis=1))
        s = np.where(s > 0, s, 1.0)
        x = roots(Q / s[:, None]) * s[:, None, None] ** np.asarray(powers)[None, None, :]
    else:
        x = roots(Q)
    return x.reshape(batch + x.shape[1:])
