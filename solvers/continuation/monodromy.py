"""Root sets by monodromy: loops in parameter space that carry every known root of a parametric system
around a triangle q0 -> qa -> qb -> q0, new endpoints kept (Duff, Hill, Jensen, Lee, Leykin, Sommese,
"Solving polynomial systems via homotopy continuation and monodromy", IMA J. Numer. Anal. 2019).

:func:`monodromy` grows the roots up to a certified count (the build of :mod:`solvers.methods.homotopy`);
:func:`monodromy_count` grows them without one, with a checkpoint to resume from (numerical evidence only;
completeness: :mod:`solvers.continuation.trace`); :func:`checked_roots` checks a checkpoint's roots against
a system. The paths are tracked by :class:`solvers.continuation.tracking.HomotopySolver`.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from .tracking import (SPEC_FORMAT, START_DIGITS, START_TOL, HomotopyError, HomotopyOptions, HomotopySolver,
                       _complex_array, _duplicated, _expanded, _pairs, _Projected, coefficient_source,
                       load_coefficients, structure)

if TYPE_CHECKING:
    from analysis.formulations.parametric import ParametricSystem

__all__ = ["CHECKPOINT_TOL", "MonodromyCheckpoint", "MonodromyCount", "accepted", "add_new", "checked_roots",
           "monodromy", "monodromy_count", "read_checkpoint", "start_solver", "system_residuals"]


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
    in this process; :class:`solvers.continuation.dask_tracks.DaskTracks`: on a Dask cluster).

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
                 seed: int = 0, evaluator: str = "auto") -> tuple[HomotopySolver, np.ndarray]:
    """A solver of ``system`` with the one start pair (q0, x0) and no certified count, for counting roots by
    monodromy (:func:`monodromy_count`, :func:`.graph.graph_monodromy`): (solver, x0 refined by Newton's method).
    ``evaluator``: :data:`.tracking.EVALUATORS`. Raises :class:`HomotopyError` when x0 is not a root at q0."""
    coefficients = load_coefficients(coefficient_source(system))
    exps, eq = structure(system)
    q0 = np.asarray(q0, dtype=complex)
    spec = {"format": SPEC_FORMAT, "kind": "homotopy", "system": system.name, "unknowns": list(system.unknowns),
            "parameters": list(system.parameters), "degree": 0, "coefficient_degree": int(max(system.coefficient_degrees)),
            "monodromy": {"seed": seed}, "tracker": {}, "term_equation": eq.tolist(), "exponents": exps.tolist(),
            "start_parameters": _pairs(q0), "start_roots": _pairs(np.atleast_2d(x0))}
    solver = HomotopySolver(spec, coefficients, evaluator, elimination="sparse")
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
    new root count again from 0. Numerical evidence only: a root count without the GF(p) certificate of
    :func:`solvers.methods.homotopy.build`.
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
