"""Parameter homotopy: the general solving method, offline build and online solver side by side.

Offline (:func:`build`): from a square :class:`analysis.formulations.parametric.ParametricSystem`
1. certify the number of roots at generic parameters over GF(p) (two primes, two seeds);
2. draw a generic complex start instance q0 with one known root (a complex network, or any system
   whose equations are affine in the parameters: pick x0, solve for q0);
3. find all roots of q0 by monodromy until their number equals the certified count: on complete graphs
   of parameter nodes when :mod:`solvers.generate` builds (``grow``: :func:`solvers.generate.graph_growth`),
   else by loops q0 -> qa -> qb -> q0 (:mod:`solvers.continuation.monodromy`, every known root tracked
   around each loop, new endpoints kept); a run that cannot reach it within its budget is an error naming
   how many roots it found;
4. check the solver on seeded real instances (the known root must be among the endpoints);
5. write a plain-JSON spec (start parameters and roots rounded to 11 digits, refined at load time).

A squared system's spec may name the start roots that satisfy the full (over-determined) system
(``full_system.tracked``, :func:`full_system_roots`); only those are tracked.

Online (:class:`HomotopySolver`, from :mod:`solvers.continuation.tracking`): for target parameters q1, every
(tracked) start root is tracked along the complex segment q0 -> q1 by the compiled tracker
(:mod:`solvers.continuation.tracker`), or, for systems with an unexpanded straight-line program (TDOA
formulations, with minors squared, and the 4r/5s positions formulation:
:func:`solvers.continuation.slp.system_equations`; see
:data:`solvers.continuation.tracking.VALIDATED_PROGRAMS`), by the batched tracker on its instruction tapes
(:mod:`solvers.continuation.tape_kernel`); paths that stall, and all paths of an instance where two
endpoints coincide (path jumping), are retracked with tight step control. A spec with further start
systems (``starts``, :func:`extra_starts`; 4r/5s) is instead tracked from each of them and the distinct
endpoints pooled, nothing retracked (:meth:`HomotopySolver._multistart`). Because q0 is a generic complex
point, the segment misses the discriminant with probability one (the gamma trick; Sommese & Wampler
2005, ch. 7).

References: Duff, Hill, Jensen, Lee, Leykin, Sommese, "Solving polynomial systems via homotopy
continuation and monodromy", IMA J. Numer. Anal. 2019; Ferranti et al., EUSIPCO 2021 (TDOA by
homotopy continuation).
"""
from __future__ import annotations

import time
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..continuation.monodromy import (MonodromyCheckpoint, _excluded, checked_roots, monodromy, monodromy_count,
                                      system_residuals)
from ..continuation.tracking import (SPEC_FORMAT, START_TOL, HomotopyError, HomotopyOptions, HomotopySolver,
                                     _detour_direction, _distinct, _expanded, _has_duplicates, _pairs, coefficient_source,
                                     evaluator_for, load_coefficients, structure)
from .common import load_format, verify_found

if TYPE_CHECKING:  # the online solver needs neither sympy nor the exact algebra
    from analysis.formulations.parametric import ParametricSystem

__all__ = ["HomotopySolver", "SPEC_FORMAT", "affine_start", "build", "expand_orbits", "extra_starts",
           "full_system_roots", "load_spec", "solve_scaled", "verify"]


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
    x0 = rng.normal(size=N) + 1j * rng.normal(size=N)

    def f(q):  # numpy (tracking._expanded): a user's build compiles no monomial kernel
        return _expanded(coefficients, exps, eq, N, x0[None], q)[0][0]

    b = f(np.zeros(P, dtype=complex))
    A = np.column_stack([f(np.eye(P, dtype=complex)[k]) - b for k in range(P)])
    if np.linalg.matrix_rank(A) < N:
        raise HomotopyError(f"{system.name}: the parameters do not move every equation (rank {np.linalg.matrix_rank(A)} < {N})")
    q_part = np.linalg.lstsq(A, -b, rcond=None)[0]
    _, _, Vh = np.linalg.svd(A)
    null = Vh[np.linalg.matrix_rank(A):].conj().T
    q0 = q_part + null @ (rng.normal(size=null.shape[1]) + 1j * rng.normal(size=null.shape[1]))
    return q0, x0


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


def build(system: ParametricSystem, count: int | None, start: Callable[[np.random.Generator], tuple[np.ndarray, np.ndarray]] | None = None,
          trials: Callable[[int], tuple[np.ndarray, np.ndarray]] | None = None,
          options: HomotopyOptions = HomotopyOptions(), progress: Callable[[str], None] | None = None,
          checkpoint: MonodromyCheckpoint | None = None, group: np.ndarray | None = None,
          grow: Callable[..., tuple[np.ndarray, dict]] | None = None) -> tuple[dict, str, dict]:
    """Spec, coefficient source and build report of the homotopy solver of a square system.

    count: the certified number of roots (GF(p), two primes), or None: numerical evidence alone, monodromy
    until ``options.stall_loops`` loops find no new root (the count is then what it found). start: rng -> (q0, x0) generic complex
    parameters with one known root (default :func:`affine_start`). trials: seed -> (q real, known
    root) for the verification on seeded real instances (skipped when None). checkpoint (with count None): the
    q0 and roots of a settled :func:`monodromy_count` instead of growing them again (checked by
    :func:`checked_roots`); group: sign vectors (G, N) whose orbits the roots come in, one root per orbit
    stored and tracked (the spec's "group"; its "degree" counts every root, G per orbit, and its "paths"
    the orbits). grow: how the roots at q0 are found instead of the loops of :func:`monodromy`:
    ``grow(solver, q0, x0, count, progress, excluded) -> (roots, record)`` (count None: the roots it returns are
    the count), the record's fields written into the spec's "monodromy" and the report
    (:func:`solvers.generate.graph_growth`: graph monodromy).
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
    solver = HomotopySolver(spec, coefficients, evaluator_for(system.name))
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
    elif grow is not None:  # found elsewhere (graph monodromy), checked below like the loops' roots
        roots, growth = grow(solver, solver.q0, x0, count, progress, _excluded(system, solver.q0))
        if count is None:
            count = len(roots) * (1 if group is None else len(group))
            spec["degree"] = count
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
    if grow is None or checkpoint is not None:
        growth = {"loops": loops}
    spec["monodromy"].update(growth)
    if group is not None:
        spec["group"] = {"name": "gauge reflections", "order": len(group), "signs": np.asarray(group).astype(int).tolist()}
    report = {"method": "homotopy", "degree": int(count), **growth, "paths": len(roots)}
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
