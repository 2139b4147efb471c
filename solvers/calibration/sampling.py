"""Hypotheses: minimal solvers on fully measured sub-blocks and least squares on sub-networks, each
locally optimised; the LO-RANSAC search over them is `ransac`."""
from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..recovery import recover
from .adjustment import n_unknowns, robust_refine
from .placement import _extend
from .result import CalibrationOptions
from .robust import _polish
from .scoring import _Model, _prune, _residual_matrix, _score, _Search, hypothesis_redundancy

Hypothesis = tuple[np.ndarray, np.ndarray, np.ndarray]

# --------------------------------------------------------------------------------------------------
# Minimal solvers: the one adapter to solvers.api
# --------------------------------------------------------------------------------------------------



@dataclass(frozen=True)
class MinimalSolver:
    """A minimal solver as the pipeline sees it.

    Parameters
    ----------
    label : str, e.g. "6r4s"
    m, n : int
        Size of the fully measured sub-block it needs (receivers x transmitters).
    solve : callable
        (F_sub (m, n), sigma or None) -> list of candidate (receivers (m, dim), transmitters (n, dim),
        offsets (n,)), real and geometrically valid, any order; sigma, the noise level when it is
        known, lets a solver tell a degenerate sample from noise (it may ignore it).
    cost_ms : float
        Relative cost per call (the pencil 1, a homotopy its number of paths), to try the cheapest first.
    dim : 2 or 3
    tolerates : gross errors a sample may hold and still give its hypothesis (the RANSAC count
        needs a sample with at most this many)
    """

    label: str
    m: int
    n: int
    solve: Callable[[np.ndarray], list[Hypothesis]]
    cost_ms: float
    dim: int = 2
    tolerates: int = 0


def _solver_via_api(m: int, n: int) -> Callable[[np.ndarray], list[Hypothesis]]:
    """F_sub -> candidates through solvers.api.solve_roots (dispatch by shape) and recovery."""

    from .. import api

    choice = api.select_solver(m, n)

    def solve(F_sub: np.ndarray, sigma: float | None = None) -> list[Hypothesis]:
        out: list[Hypothesis] = []
        with np.errstate(all="ignore"):
            for x in api.solve_roots(F_sub):
                if choice.label in api.POSITIONS:
                    cal = api._from_positions(F_sub, choice, x)
                else:
                    cal = recover(F_sub, x[:3], x[3:5], x[5 : 5 + n])
                if cal is not None:
                    out.append((cal.receivers, cal.transmitters, cal.offsets))
        return out

    return solve


@functools.lru_cache(maxsize=2)
def available_solvers(dim: int = 2) -> tuple[MinimalSolver, ...]:
    """The block solvers hypotheses are drawn from, cheapest first.

    2D: every generated solver of solvers.api (:data:`solvers.api.SOLVER_ORDER`): the 6r/4s curve
    pencil (~1 ms) and the homotopy solvers, whose cost grows with their number of paths (9r/3s 75 ...
    4r/5s 344; tables/solvers.csv). 3D: the stratified block solvers of :mod:`.stratified`
    (over-determined, noise-robust) and the generated 9r/5s offset kernel (exactly determined).
    """
    from .. import api

    if dim == 3:
        return _solvers_3d()
    if dim != 2:
        raise ValueError(f"dim must be 2 or 3, got {dim!r}")

    solvers = []
    for label, m, n in api._available():
        module = api._module_for(label)
        if api.select_solver(m, n).label != label:  # the api must dispatch this block shape to it
            raise RuntimeError(f"solvers.api dispatches a {m}x{n} block to {api.select_solver(m, n).label}, not {label}")
        # a homotopy's cost grows with its paths; a squared system (5r/4s, 5r/5s) counts all its start
        # roots: it tracks only the full system's (152, 64), but its paths cost 5-8x the others' (5r/5s
        # 9.4 ms per path, 9r/3s 1.2 ms; tables/solvers.csv), and drawing 5r/5s blocks made 8r/5s
        # 10 % missing / 5 % outliers slower and no better (10 trials: 6/10 at 24 s against 7/10 at 9 s)
        cost = 1.0 if getattr(module, "METHOD", "") != "homotopy" else float(getattr(module, "START_ROOTS", module.PATHS))
        solvers.append(MinimalSolver(label, m, n, _solver_via_api(m, n), cost))
    return tuple(sorted(solvers, key=lambda s: s.cost_ms))



#: 3D block shapes of the stratified solver, largest first: 12 receivers average more noise away
#: (share of 12r/5s blocks in the right basin at sigma 1 mm / 1 cm: 0.92 / 0.63, 10r/5s 0.66 / 0.30;
#: docs/calibration-3d.md), 10 is the fewest it can use.
STRATIFIED_BLOCKS = ((12, 5), (10, 5))
#: Blocks of at least this many receivers leave out the one that fits worst (solve_block's trim): one
#: gross error in a 12r/5s block then spoils 38 % of its hypotheses instead of 96 % (sigma 1 mm, 100
#: seeded samples; clean blocks 74 % within 5 cm against 82 % untrimmed).
STRATIFIED_TRIM_FROM = 11


def _stratified_solve(F_sub: np.ndarray, sigma: float | None = None) -> list[Hypothesis]:
    from ..methods.stratified import solve_block

    out = solve_block(F_sub, sigma, trim=len(F_sub) > STRATIFIED_TRIM_FROM - 1)
    return [(out.receivers, out.transmitters, out.offsets)] if out.solved else []


def _kernel_solve_3d(F_sub: np.ndarray, sigma: float | None = None) -> list[Hypothesis]:
    """The generated 9r/5s offset kernel (exactly determined: exact without noise, rough with it)."""
    from .. import api

    with np.errstate(all="ignore"):
        cals = api.calibrations(api._module_for("9r5s3d"), F_sub)
    return [(c.receivers, c.transmitters, c.offsets) for c in cals]


def _solvers_3d() -> tuple[MinimalSolver, ...]:
    """3D block solvers: the stratified solver on 12r/5s and 10r/5s blocks, then the 9r/5s offset kernel
    (for networks of nine receivers); all cost about the same (sub-millisecond), larger blocks first."""
    solvers = [MinimalSolver(f"{m}r{n}s-stratified", m, n, _stratified_solve, 1.0 + k, 3,
                             tolerates=int(m >= STRATIFIED_TRIM_FROM))
               for k, (m, n) in enumerate(STRATIFIED_BLOCKS)]
    solvers.append(MinimalSolver("9r5s3d", 9, 5, _kernel_solve_3d, 1.0 + len(STRATIFIED_BLOCKS), 3))
    return tuple(solvers)


# --------------------------------------------------------------------------------------------------
# Sampling fully measured sub-blocks
# --------------------------------------------------------------------------------------------------


def _sample_block(mask: np.ndarray, ms: int, ns: int, rng: np.random.Generator, tried: set, attempts: int = 25):
    """A fully measured ms x ns block not tried before, by randomised greedy biclique search.

    Columns are added one at a time, uniformly among those that keep at least ms common measured
    rows, then ms of the common rows are drawn uniformly. (Weighting columns by their overlap
    concentrates the samples on a few dense columns, and on any outlier they hold.)
    Returns (rows, cols) sorted, or None when `attempts` draws found nothing new.
    """
    m, n = mask.shape
    if m < ms or n < ns:
        return None
    for _ in range(attempts):
        rows = np.ones(m, bool)
        cand = np.flatnonzero(mask.sum(axis=0) >= ms)
        chosen = []
        for _ in range(ns):
            overlap = mask[rows][:, cand].sum(axis=0)
            keep = overlap >= ms
            if not keep.any():
                break
            cand = cand[keep]
            k = rng.integers(len(cand))
            chosen.append(int(cand[k]))
            rows &= mask[:, cand[k]]
            cand = np.delete(cand, k)
        if len(chosen) < ns:
            continue
        r = np.sort(rng.choice(np.flatnonzero(rows), ms, replace=False))
        key = (tuple(r.tolist()), tuple(sorted(chosen)))
        if key in tried:
            continue
        tried.add(key)
        return r, np.array(sorted(chosen))
    return None



def _local_optimisation(F, mask, model: _Model, thr, floor, opts: CalibrationOptions, rng) -> _Model:
    """LO step of LO-RANSAC: `_polish` with a small budget, rescored."""
    out = _polish(F, mask, model.R, model.S, model.O, thr, floor, opts, rng, opts.lo_iterations, rounds=1,
                  redundancy=model.redundancy)
    score, ratio, _ = _score(_residual_matrix(F, out.R, out.S, out.O), mask, thr, floor, dim=out.R.shape[1])
    return _Model(out.R, out.S, out.O, score, ratio, True, out.converged)



def _block_rms(E: np.ndarray) -> float:
    """RMS of the finite residuals of a block (inf when there are none)."""
    e = E[np.isfinite(E)]
    return float(np.sqrt(np.mean(e * e))) if e.size else np.inf


def _hypotheses_from_block(F, mask, solver: MinimalSolver, rows, cols, thr, floor, opts, rng, search: _Search,
                           best_ratio: float | None = None):
    """Candidates of one sub-block, extended to the network and scored.

    Only candidates whose block RMS is within 10x of the best one (or below the threshold) are
    extended, at most `candidates_per_sample` of them; a minimal solver's roots all fit the block
    exactly (RMS cannot rank them), so up to `minimal_candidates` of those.
    """
    block = F[np.ix_(rows, cols)]
    cands = solver.solve(block, thr / opts.threshold_sigmas if thr is not None else None)
    search.samples += 1
    if not cands:
        return []
    # over the entries a candidate places (a trimmed block leaves a receiver out: NaN)
    rms = np.array([_block_rms(_residual_matrix(block, *c)) for c in cands])
    rms[~np.isfinite(rms)] = np.inf
    best_rms = float(rms.min())
    if not np.isfinite(best_rms):
        return []
    # Unknown sigma: a clean block's RMS is about 0.35 sigma (3 redundant entries of 24 or 27).
    c = thr if thr is not None else max(floor, 8.0 * best_rms)
    minimal = solver.m * solver.n == n_unknowns(solver.m, solver.n, solver.dim)
    per_sample = opts.minimal_candidates if minimal else opts.candidates_per_sample
    keep = [k for k in np.argsort(rms)[:per_sample] if rms[k] <= max(10.0 * best_rms, c)]
    return _extended_hypotheses(F, mask, [cands[k] for k in keep], rows, cols, c, thr, floor, rng, search, best_ratio)


#: Blocks with more redundant entries than this are polished with a robust loss (_extended_hypotheses).
ROBUST_BLOCK_REDUNDANCY = 5


def _extended_hypotheses(F, mask, cands, rows, cols, c, thr, floor, rng, search: _Search, best_ratio):
    """Block solutions (R_b, S_b, O_b on rows x cols) polished on the block's measured entries,
    deduplicated, extended to the network (`_extend`) and scored."""
    m, n = F.shape
    block = F[np.ix_(rows, cols)]
    sample_r = np.zeros(m, bool)
    sample_r[rows] = True
    out = []
    block_mask = np.isfinite(block)
    seen: list[np.ndarray] = []
    for cand in cands:
        dim = cand[0].shape[1]
        R, S, O = np.full((m, dim), np.nan), np.full((n, dim), np.nan), np.full(n, np.nan)
        # A few least-squares steps on the block: on noisy data the solver's root satisfies a subset
        # of the equations exactly, and its error grows when extended; the block optimum is better.
        # A block with many more entries than unknowns (3D: 12 x 5, 10 redundant) holds a gross error
        # more often than it is clean; a redescending loss at the inlier threshold lets it out.
        if int(block_mask.sum()) - n_unknowns(len(rows), len(cols), dim) > ROBUST_BLOCK_REDUNDANCY:
            pol = robust_refine(block, block_mask, *cand, loss="cauchy", scale=c, max_iter=8)
        else:
            pol = robust_refine(block, block_mask, *cand, loss="linear", max_iter=4)
        R[rows], S[cols], O[cols] = (pol.R, pol.S, pol.O) if np.all(np.isfinite(pol.R)) else cand
        if any(np.allclose(O[cols], o, rtol=1e-9, atol=1e-9 * (1.0 + np.abs(o).max())) for o in seen):
            continue  # two roots polished into the same block solution
        seen.append(O[cols].copy())
        R, S, O = _extend(F, mask, R, S, O, c, rng, sample_r, best_ratio)
        rr = hypothesis_redundancy(mask, rows, cols, R, S)
        score, ratio, _ = _score(_residual_matrix(F, R, S, O), mask, thr, floor, rr, dim=R.shape[1])
        search.hypotheses += 1
        out.append(_Model(R, S, O, score, ratio, redundancy=rr))
    return out


def _sample_subnetwork(mask: np.ndarray, rng: np.random.Generator, tried: set | None, suspicious: np.ndarray | None = None,
                       redundancy: int = 2, attempts: int = 20, *, dim: int):
    """A random sub-network (gaps allowed) that determines its nodes with little redundancy.

    Unguided (suspicious None or empty): nodes are left out one at a time in random order as long
    as the rest keeps at least `redundancy` (or, drawn at random, one more) measured entries more
    than unknowns, so that the sub-network holds as few measurements (and gross errors) as can
    still expose one. Guided: for up to 3 of the `suspicious` entries (an (k, 2) array of
    (receiver, transmitter), e.g. the current best's rejected measurements) the receiver or the
    transmitter is left out, at random. Nodes left with too few measurements among the rest are
    pruned (`_prune`) in both cases. Returns (rows, cols) as index arrays when the sub-network is
    valid and not in `tried` (None: repeats allowed), else None.
    Leaving nodes out, not entries, is what lets a sub-network avoid a node's gross error when no
    fully measured block does (low-redundancy networks with gaps).
    """
    m, n = mask.shape

    def pruned(rows, cols):
        keep_r, keep_c = _prune(mask & rows[:, None] & cols[None, :], dim)
        keep_r &= rows
        keep_c &= cols
        sub = mask & keep_r[:, None] & keep_c[None, :]
        ok = keep_r.sum() >= dim + 1 and keep_c.sum() >= dim + 1
        return keep_r, keep_c, int(sub.sum()) - n_unknowns(int(keep_r.sum()), int(keep_c.sum()), dim) if ok else -1

    for _ in range(attempts):
        rows, cols = np.ones(m, bool), np.ones(n, bool)
        if suspicious is not None and len(suspicious):
            pick = suspicious[rng.permutation(len(suspicious))[: int(rng.integers(1, min(3, len(suspicious)) + 1))]]
            by_row = rng.random(len(pick)) < 0.5
            rows[pick[by_row, 0]] = False
            cols[pick[~by_row, 1]] = False
            rows, cols, spare = pruned(rows, cols)
            need = redundancy
        else:
            rows, cols, spare = pruned(rows, cols)
            # a network with little redundancy (5r/5s: 3) has no sub-network with `redundancy` spare
            # entries; one with a single spare entry still exposes a misfit and leaves a gross error out
            target = min(redundancy + int(rng.integers(0, 2)), max(1, spare - 2))
            need = min(redundancy, target)
            for node in rng.permutation(m + n):
                r2, c2 = rows.copy(), cols.copy()
                if node < m:
                    r2[node] = False
                else:
                    c2[node - m] = False
                r2, c2, spare2 = pruned(r2, c2)
                if spare2 >= target:
                    rows, cols, spare = r2, c2, spare2
        if spare < need:
            continue
        key = ("subnetwork", tuple(np.flatnonzero(rows).tolist()), tuple(np.flatnonzero(cols).tolist()))
        if tried is not None and key in tried:
            continue
        if tried is not None:
            tried.add(key)
        return np.flatnonzero(rows), np.flatnonzero(cols)
    return None


def _random_start(F, mask, rows, cols, rng, dim: int):
    """Receivers, transmitters and offsets of rows x cols drawn at the scale of the data."""
    spread = float(np.percentile(F[mask], 90) - np.percentile(F[mask], 10)) or 1.0
    sub = F[np.ix_(rows, cols)]
    centre = np.array([np.median(v[np.isfinite(v)]) for v in sub.T])
    return (0.5 * spread * rng.standard_normal((len(rows), dim)), 0.5 * spread * rng.standard_normal((len(cols), dim)),
            centre - 0.5 * spread + 0.1 * spread * rng.standard_normal(len(cols)))


def _hypotheses_from_subnetwork(F, mask, rows, cols, thr, floor, opts, rng, search: _Search, best_ratio,
                                start: _Model | None = None, *, dim: int):
    """Least squares on a sub-network's measured entries, extended and scored.

    The multi-start local optimisation of a non-minimal sample: it needs no fully measured block
    and costs milliseconds for a small network. It starts from `start` (the current best, whose
    gross errors the sub-network may leave out) where that places every node of the sub-network,
    else from a random start. A fit whose RMS on its own entries exceeds the threshold (a gross
    error inside, or a local minimum) is not extended.
    """
    block = F[np.ix_(rows, cols)]
    sub_mask = np.isfinite(block)
    search.samples += 1
    x0 = None
    if start is not None:
        x0 = start.R[rows], start.S[cols], start.O[cols]
        if not all(np.isfinite(a).all() for a in x0):
            x0 = None
    # Least squares first: a redescending loss far from any solution gives every entry the same tiny
    # weight and stalls; near a basin, the LO step's robust loss then sheds the outliers.
    ls = robust_refine(block, sub_mask, *(x0 or _random_start(F, mask, rows, cols, rng, dim)), loss="linear",
                       max_iter=3 * opts.lo_iterations)
    if not np.all(np.isfinite(ls.R)):
        return []
    rms = float(np.sqrt(np.mean(_residual_matrix(block, ls.R, ls.S, ls.O)[sub_mask] ** 2)))
    if thr is not None and not rms <= thr:
        return []
    c = thr if thr is not None else max(floor, 8.0 * rms)
    return _extended_hypotheses(F, mask, [(ls.R, ls.S, ls.O)], rows, cols, c, thr, floor, rng, search, best_ratio)
