"""Online path tracking of a parametric system: the solver that carries a complete root set from start
parameters q0 to target parameters.

:class:`HomotopySolver` tracks the stored start roots of a spec (:data:`SPEC_FORMAT`) along the complex segment
q0 -> q1 by the compiled tracker (:mod:`solvers.continuation.tracker`), or, for systems with an unexpanded
straight-line program (TDOA formulations, with minors squared, and the 4r/5s positions formulation:
:func:`solvers.continuation.slp.system_equations`; see :data:`VALIDATED_PROGRAMS`), by the batched tracker on its
instruction tapes (:mod:`solvers.continuation.tape_kernel`); paths that stall, and all paths of an instance
where two endpoints coincide (path jumping), are retracked with tight step control, taken around their stall
points or through fixed complex midpoints. A spec with further start systems (``starts``) is instead tracked
from each of them and the distinct endpoints pooled, nothing retracked (:meth:`HomotopySolver._multistart`).
Because q0 is a generic complex point, the segment misses the discriminant with probability one (the gamma
trick; Sommese & Wampler 2005, ch. 7).

Also here: the structure and coefficient code of a :class:`analysis.formulations.parametric.ParametricSystem`
(:func:`structure`, :func:`coefficient_source`) and the endpoint bookkeeping shared with
:mod:`solvers.continuation.monodromy` (:func:`unresolved`, :func:`_duplicated`, :func:`_distinct`,
:func:`_pool`, :class:`_Projected`). The parameter-homotopy method built on this solver (offline build,
spec, generated modules) is :mod:`solvers.methods.homotopy`.
"""
from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, Callable

import numpy as np

from .scaling import equation_shift, log2_floor, scaled_float
from . import sparse_lu, tape_kernel, tape_native, tracker
from .tracker import SystemStructure, TrackerOptions

if TYPE_CHECKING:  # the online solver needs neither sympy nor the exact algebra
    from analysis.formulations.parametric import ParametricSystem

__all__ = ["HomotopyError", "HomotopyOptions", "HomotopySolver", "SPEC_FORMAT", "coefficient_source", "equation_shifts",
           "scaling_note",
           "load_coefficients", "structure", "unresolved"]

#: Format of the spec a :class:`HomotopySolver` reads (written by :func:`solvers.methods.homotopy.build`).
SPEC_FORMAT = "tdoa-homotopy/1"

#: Largest relative Newton step accepted on a stored start root (ill-conditioned roots of high-degree
#: systems, e.g. the degree-10 4r/5s equations, do not converge further in double precision).
START_TOL = 1e-8

#: Significant digits of stored start data and roots (refined by Newton's method when loaded).
START_DIGITS = 11


#: How a :class:`HomotopySolver` factors the Jacobian: "dense", in the order of the unknowns and equations (the
#: committed solvers: their outputs were computed so, and they keep their bits), or "sparse", in the order
#: :func:`sparse_lu.plan` picks where the Jacobian is sparse enough (the same roots up to rounding: count's and
#: monodromy's solvers; one thread, 3D 5r/9s tracks 14x faster, 7r/5s 2.7x: scripts/bench_sparse_lu.py).
ELIMINATIONS = ("dense", "sparse")

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
    #: a loop's endpoint counts when Newton's next step is below this, relative
    #: (:func:`solvers.continuation.monodromy.accepted`); the trace test's witness loops take a looser one
    #: (trace.WITNESS_TOL)
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


def equation_shifts(system: ParametricSystem) -> tuple[int, ...]:
    """Per equation the k of its scaling by 2^-k where its coefficients become floats (0: as written):
    :func:`solvers.continuation.scaling.equation_shift` of the numeric constants of its coefficients (polynomials in the
    parameters and definitions)."""
    # the system's own expansion of its coefficients in the parameters (cached; the one its GF(p) counts use)
    return tuple(equation_shift(Fraction(int(v.p), int(v.q)) for _, cterms in row for _, v in cterms)
                 for row in system._gf_coefficients)


def _scaled_coefficient(c, k: int, system: ParametricSystem):
    """A coefficient (polynomial in the parameters) times 2^-k, each constant rounded once to a float written
    with 17 digits (which reads back as the same float): a constant of thousands of digits never meets
    numpy as an integer."""
    import sympy

    gens = system.q_symbols + system.aux_symbols or (sympy.Symbol("_dummy"),)
    out = []
    for e, v in sympy.Poly(c, *gens).terms():
        r = sympy.Rational(v)
        value = scaled_float(Fraction(int(r.p), int(r.q)), k)
        if not value:
            lg = log2_floor(Fraction(int(r.p), int(r.q)))
            raise HomotopyError(f"{system.name}: an equation's constants span 2^{lg} to 2^{k}, more than float64's "
                                "range: the floating-point system would not be the exact one; rescale the unknowns "
                                "(x = 10^k y) so that each equation's terms are of comparable size")
        if value:
            out.append(sympy.Float(repr(value), 17) * sympy.Mul(*[g**x for g, x in zip(gens, e) if x]))
    return sympy.Add(*out)


def scaling_note(system: ParametricSystem) -> str:
    """One sentence saying which equations :func:`coefficient_source` scaled ('' when none)."""
    scaled = [f"{k + 1} by 2^{-s}" for k, s in enumerate(equation_shifts(system)) if s]
    return ("equations scaled for float64 (largest constant in [1, 2); the solutions are unchanged): "
            + ", ".join(scaled)) if scaled else ""


def coefficient_source(system: ParametricSystem, name: str = "coefficients") -> str:
    """Python source of ``name(q)``: parameters (K, P) -> term coefficients (K, T), numpy only.

    Definitions are computed first (in order), then the coefficients with shared subexpressions
    (``sympy.cse``); byte-stable for a given system. An equation with a constant beyond 2^+-SCALE_BITS is
    scaled exactly by a power of two first (:func:`equation_shifts`, :data:`solvers.continuation.scaling.SCALE_BITS`).
    """
    import sympy

    shifts = equation_shifts(system)
    coeffs = [_scaled_coefficient(c, k, system) if k else c for eq, k in zip(system.terms, shifts) for _, c in eq]
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


def evaluator_for(name: str) -> str:
    """The evaluator a system's solvers and counts use: "auto" for a system with a program written from its
    formulation (slp.system_equations: TDOA/TOA formulations, positions), "tape" for any other (a user's system:
    the program traced from its expanded equations, compiled to C like the formulations')."""
    from . import slp

    try:
        slp.system_equations(name)
        return "auto"
    except ValueError:
        return "tape"


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

    def __init__(self, spec: dict, coefficients: Callable, evaluator: str = "auto", elimination: str = "dense"):
        if elimination not in ELIMINATIONS:
            raise ValueError(f"unknown elimination {elimination!r}; valid: {', '.join(ELIMINATIONS)}")
        self.coefficients = coefficients
        self.tapes = _tapes(spec, coefficients, evaluator)
        # "sparse": the tapes renamed to a sparse elimination order where the Jacobian is sparse enough (every track
        # and Newton step factors it; 3D 5r/9s: 1,779 entry updates for the dense order's 32,430), else None
        self.sparse = sparse_lu.plan(self.tapes) if self.tapes is not None and elimination == "sparse" else None
        self.terms = (np.array(spec["exponents"], dtype=np.int64), np.array(spec["term_equation"], dtype=np.int64))
        self.structure = SystemStructure.from_exponents(*self.terms)
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
        # further complete start systems (:func:`solvers.methods.homotopy.extra_starts`): every path is tracked
        # from each, the distinct endpoints pooled, nothing retracked (:meth:`_multistart`)
        self.starts = [(self.q0, self.x0)]
        for item in spec.get("starts", []):
            qk = _complex_array(item["parameters"])
            self.starts.append((qk, self.newton(_complex_array(item["roots"]), qk[None], steps=2)))

    def segment(self, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
        return tracker.segment_coefficients(self.coefficients, q0, q1, self.degree)

    def newton(self, x: np.ndarray, q: np.ndarray, steps: int = 1, inst: np.ndarray | None = None) -> np.ndarray:
        """Newton steps on the system at parameters q (B, P); x (P', N), path p on instance inst[p]."""
        if self.sparse is not None:
            return self.sparse.newton(q, x, inst, steps)
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
        """Largest |f_e(x)| of each point x (P', N) at parameters q (B, P) (point p at q[inst[p]]), by numpy
        (:func:`_expanded`): a build's check of its start point compiles no monomial kernel."""
        x, q = np.atleast_2d(np.asarray(x, dtype=complex)), np.atleast_2d(np.asarray(q, dtype=complex))
        inst = np.zeros(len(x), dtype=np.int64) if inst is None else np.asarray(inst)
        out = np.zeros(len(x))
        for b in np.unique(inst):
            at = inst == b
            H, _ = _expanded(self.coefficients, *self.terms, self.nvars, x[at], q[b])
            out[at] = np.abs(H).max(axis=1)
        return out

    def track(self, q0: np.ndarray, q1: np.ndarray, x0: np.ndarray, inst: np.ndarray | None = None,
              options: TrackerOptions | None = None, near_end: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Track x0 (P, N) along q0 -> q1 (B, P) (path p on segment inst[p]); endpoints and stats
        (``near_end``: :func:`tape_kernel.track`'s, for the tape tracker)."""
        options = options or self.options
        if self.sparse is not None and options.predictor in tape_kernel.PREDICTORS:
            return self.sparse.track(q0, q1, x0, inst, options, near_end=near_end)
        if self.tapes is not None and options.predictor in tape_kernel.PREDICTORS:
            return tape_kernel.track(self.tapes, q0, q1, x0, inst, options, near_end=near_end,
                                     native=tape_native.addresses(self.tapes))
        if options.predictor == "pade" or options.corrector == "chord":  # the tape tracker's only
            options = dataclasses.replace(options, predictor="rk4", corrector="newton")
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
        if stalled.any():
            self._local_detours(qa, xa, q, x, stalled, stats[:, 3].reshape(B, K)[stalled])
        lost = ~np.all(np.isfinite(x), axis=2)  # :func:`unresolved` of each instance, kept where nothing is retracked
        redo = stalled & lost
        for b in range(B):
            dup = _duplicated(x[b])
            lost[b] |= dup
            redo[b] |= dup
            if _degenerate(redo[b]):
                redo[b] = False
        bi, ki = np.nonzero(redo)
        if len(bi):
            xr, _ = self.track(qa[None], q, xa[ki], bi, self.retrack)
            x[bi, ki] = xr
            for b in np.unique(bi):
                lost[b] = unresolved(x[b])
        return x, ~lost.any(axis=1)

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
        if complete.all():  # (nothing stalled or coincides: what follows would change nothing)
            return self._polish(x, q)
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
    if len(ok) > GRAM_ROWS:  # the K x K Gram matrix would be large (a count's sets, a trace test): projections
        out[ok] = _duplicated_by_projection(x[ok], tol, group)
        return out
    hit = np.zeros(len(ok), dtype=bool)
    for sign in (None,) if group is None else [None if np.all(g == 1.0) else g for g in np.asarray(group)]:
        near = _near(x[ok], tol, sign)
        np.fill_diagonal(near, False)
        hit |= near.any(axis=1)
    out[ok] = hit
    return out


#: Above this many finite rows :func:`_duplicated` compares by sorted projections instead of a Gram matrix (the same
#: decisions, tests/test_homotopy.py). The Gram matrix and its temporaries take about 40 K^2 bytes: at 10,000 rows
#: (the bound before) 4 GB; Alt's problem's 8,652 solutions compared once as sets took 2.3 GB and 7.5 s of CPU that
#: way, 4 MB and 0.02 s by projections (count's peak 2.55 GB on 2 seeds, 0.53 GB on one, 2026-12-02). The
#: solvers' instances (75-344 roots) keep the Gram matrix.
GRAM_ROWS = 1_000

#: Seed of the fixed direction u of the sorted-projection searches (any direction gives the same decisions).
PROJECTION_SEED = 20261127


class _Projected:
    """Rows (K, n) sorted by their projection Re u^H x on a fixed direction u: the rows within distance d of a
    point y are among those whose projection lies within |u| d of y's (|Re u^H (x - y)| <= |u| |x - y|), found
    by binary search. The shared search of :func:`solvers.continuation.monodromy.add_new` and
    :func:`_duplicated_by_projection`."""

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


def _has_duplicates(x: np.ndarray, tol: float = 1e-6) -> bool:
    return bool(_duplicated(x, tol).any())


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
