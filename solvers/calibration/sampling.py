"""Hypotheses: minimal solvers on fully measured sub-blocks, least squares on sub-networks, and the
LO-RANSAC search over them (scored MSAC-style with sigma, LMedS on held-out entries without)."""
from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..recovery import recover
from .adjustment import n_unknowns, robust_refine
from .placement import _extend
from .result import CalibrationOptions
from .robust import _polish
from .scoring import _classify, _Model, _prune, _residual_matrix, _score, _Search, hypothesis_redundancy

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


def _better(a: _Model, b: _Model, floor: float) -> bool:
    """Whether model a beats b: a lower score, or (a tie within floor^2, as LMedS gives on noiseless
    data when more than half of the entries fit two models exactly) a higher inlier ratio."""
    if abs(a.score - b.score) <= floor * floor:
        return a.inlier_ratio > b.inlier_ratio
    return a.score < b.score


def _needed(w: float, k: int, confidence: float, success: float = 1.0, tolerated: int = 0) -> float:
    """Samples for a sample of k entries with at most `tolerated` gross errors (inlier share w; and a
    `success`ful solve) with this confidence."""
    p = success * sum(math.comb(k, i) * (1.0 - w) ** i * w ** (k - i) for i in range(tolerated + 1))
    if p >= 1.0:
        return 0.0
    return math.log(1.0 - confidence) / math.log1p(-p) if p > 0 else math.inf


def _ransac(F, mask, thr, floor, opts: CalibrationOptions, rng, solvers,
            accept: Callable[[_Model], bool] | None = None, confirm: float = 0.0, *,
            dim: int, hint: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> tuple[_Model | None, _Search]:
    """LO-RANSAC over the minimal solvers on fully measured sub-blocks, then over sub-networks solved
    by least squares from random starts (see module docstring).

    accept: called on every new best model; True ends the search (the pipeline passes the all-data
    test: a least-squares fit on every entry that shows no outlier leaves nothing to find), at once
    when confirm is 0, else when the model stays the best for as many more samples as an all-inlier
    sample needs when a share `confirm` of the entries were gross errors (with sigma
    unknown, a fit distorted by gross errors can look clean on its own scale; a better hypothesis
    from another sample then beats it).
    hint: (R, S, O) of a calibration found otherwise, offered (with its local optimisation) first; while
    it stays the best, the samples it needs are counted at its inlier share as for a sampled best (every
    sample was drawn after it), so that a restart from a right calibration can end confident.
    """
    search = _Search()
    best: _Model | None = None

    def offer(models, sample: bool = True) -> bool:
        """Keep the best model (LO on each new best, up to the budget); True when the best changed.
        sample: the models come from a sample (one that gave any counts towards confirming the best)."""
        nonlocal best
        changed = False
        search.productive += bool(models) and sample
        for model in models:
            if best is not None and not _better(model, best, floor):
                if not model.refined and np.isfinite(model.score):
                    search.runners_up = sorted(search.runners_up + [model], key=lambda x: x.score)[: opts.runners_up]
                continue
            if search.local_optimisations < opts.max_local_optimisations:
                search.local_optimisations += 1
                lo = _local_optimisation(F, mask, model, thr, floor, opts, rng)
                if lo.score <= model.score:
                    model = lo
            if best is not None and best.refined:
                search.others.append(best)
            best, changed = model, True
            pending[0] = None
            if accept is not None and accept(best):
                if confirm == 0:
                    search.accepted = True
                    return True
                pending[0] = search.productive
                pending[1] = min(_needed(1.0 - confirm, k_now[0], opts.confidence, tolerated=k_now[1]), opts.max_samples,
                                 opts.max_confirm_samples)
        return changed

    # [samples drawn when the current best passed `accept`, samples needed to confirm it]
    pending: list = [None, 0]
    k_now = [1, 0]  # entries of the sample being offered, gross errors it tolerates

    # entries per unknown: with many, a locally optimised (robust) model's own scale is a trusted one
    redundant = mask.sum() >= opts.trusted_ratio_redundancy * max(_n_params_mask(mask, dim), 1)

    def ratio_of(model: _Model) -> float:
        # With sigma unknown the inlier ratio is measured on the model's own scale, which gross errors
        # inflate: a distorted model "explains" almost everything. Until the all-data test accepts a
        # model, the sample count assumes at least `unknown_sigma_outliers` of gross errors - unless the
        # model was refined robustly (redescending loss: a gross error stops pulling) in a network with
        # many entries per unknown, where its median-based scale cannot be inflated by the few gross
        # errors a count of samples guards against (48 x 540 far field: 200 samples, the budget, for
        # 8 gross errors among 25,920 entries); it must then stay the best for max_confirm_samples
        if thr is not None or (redundant and model.refined):
            return model.inlier_ratio
        return min(model.inlier_ratio, 1.0 - opts.unknown_sigma_outliers)

    def confirmed() -> bool:
        # counted in samples that gave a hypothesis: a block refused as coplanar or failed says nothing
        # about whether a better model exists (10r/6s at 1 cm: 23 of 32 samples gave none, and a wrong
        # basin was confirmed by the 9 that did)
        if pending[0] is not None and search.productive - pending[0] >= pending[1]:
            search.accepted = True
        return search.accepted

    needed = math.inf
    needed_own = math.inf  # from the best model's own inlier ratio (not capped when sigma is unknown)
    tried: set = set()
    exhausted: set = set()
    drawn_by: dict[str, int] = {}
    # min_samples guards against trusting one lucky sample, unless a hypothesis explains every entry.
    # min_samples also holds with sigma unknown: a hypothesis distorted by gross errors explains all
    # entries on its own inflated scale (inlier ratio 1, needed 0).
    floor_samples = opts.min_samples if thr is None else 0
    # The hint's count of samples: every sample is drawn after it, so while it stays the best the samples
    # needed at its inlier share are counted as for a best model from a sample (from the first drawn block's
    # size; until then, the first solver's). Without this the count stayed unset (infinite) whenever the
    # hint was never beaten, and a right restarted calibration could never end confident (12r/8s, 1 mm,
    # 5 % gross errors, network 7007: the absorbed-error probe's restart).
    hinted = hint is not None
    if hint is not None:
        first = next((s for s in solvers if s.cost_ms <= opts.max_solver_cost), None)
        if first is not None:
            k_now[:] = [first.m * first.n, first.tolerates]
        R0, S0, O0 = (np.array(a, dtype=float) for a in hint)
        score, ratio, _ = _score(_residual_matrix(F, R0, S0, O0), mask, thr, floor, dim=dim)
        offer([_Model(R0, S0, O0, score, ratio)], sample=False)
    while (not confirmed() and search.samples < (max(needed, opts.min_samples) if needed > 0 else floor_samples)
           and search.samples < opts.max_samples):
        drawn = None
        for solver in solvers:
            if solver.label in exhausted or solver.cost_ms > opts.max_solver_cost:
                continue
            if solver.cost_ms > opts.expensive_cost and drawn_by.get(solver.label, 0) >= opts.expensive_samples:
                continue
            if pending[0] is not None and solver.cost_ms > opts.expensive_cost:
                break  # the accepted model is confirmed by what the cheap solvers could draw
            if solver.cost_ms > opts.expensive_cost and search.samples >= max(needed_own, opts.min_samples):
                continue  # the sigma-unknown pessimism draws more cheap samples, never costly ones
            block = _sample_block(mask, solver.m, solver.n, rng, tried)
            if block is None:
                exhausted.add(solver.label)
                continue
            drawn = (solver, block)
            break
        if drawn is None:
            break
        solver, (rows, cols) = drawn
        k_now[:] = [solver.m * solver.n, solver.tolerates]
        search.solvers.add(solver.label)
        drawn_by[solver.label] = drawn_by.get(solver.label, 0) + 1
        changed = offer(_hypotheses_from_block(F, mask, solver, rows, cols, thr, floor, opts, rng, search,
                                               best.inlier_ratio if best is not None else None))
        hinted = hinted and not changed and best is not None
        if changed or (hinted and search.block != (solver.m * solver.n, solver.tolerates)):
            needed = _needed(ratio_of(best), solver.m * solver.n, opts.confidence, tolerated=solver.tolerates)
            search.block = (solver.m * solver.n, solver.tolerates)
            if thr is None and redundant and best.refined:
                # its own ratio trusted (ratio_of), the model still has to stay the best for as many
                # samples as confirm an accepted one (far field: block hypotheses are rough, and the
                # first refined one can sit in another basin at 20 x the noise); the hint since sample 0
                needed = max(needed, (search.samples if changed else 0) + opts.max_confirm_samples)
            needed_own = _needed(best.inlier_ratio, solver.m * solver.n, opts.confidence, tolerated=solver.tolerates)
            if hinted and pending[0] is not None:
                # the hint passed the all-data test before any sample: its confirming count at this block
                pending[1] = min(_needed(1.0 - confirm, k_now[0], opts.confidence, tolerated=k_now[1]),
                                 opts.max_samples, opts.max_confirm_samples)

    if search.accepted or pending[0] is not None:
        if not confirmed():
            # the distinct blocks ran out before as many samples as confirm_outliers asks for gave a
            # hypothesis: the accepted model was never challenged enough to call it unique
            search.unconfirmed = pending[1] - (search.productive - pending[0])
        search.accepted = True  # the blocks ran out (or the count was met) with the accepted model still best
        return best, search
    confident = best is not None and ((needed == 0 and search.samples >= floor_samples)
                                      or search.samples >= max(needed, opts.min_samples))
    small = _n_params_mask(mask, dim) <= opts.subnetwork_max_params
    if not confident and search.samples >= opts.max_samples:
        # stopped by the budget, not by the confidence (nor by running out of blocks)
        search.short_of = int(min(needed, 1e9)) - search.samples
        search.needed, search.share = needed, ratio_of(best) if best is not None else 0.0
    if confident or (best is not None and not small and search.samples >= opts.min_samples):
        return best, search
    # Sub-networks: the blocks ran out before the adaptive count was reached in a small network (few
    # fully measured blocks, low redundancy), or there were too few blocks at all.
    search.solvers.add("subnetworks")
    search.local_optimisations = min(search.local_optimisations, opts.max_local_optimisations // 2)
    k = max(int(mask.sum() * 0.75), 1)  # entries of a typical sub-network
    k_now[:] = [k, 0]
    needed_sub = _needed(ratio_of(best), k, opts.confidence, opts.subnetwork_convergence) if best else math.inf
    drawn_sub = 0
    while drawn_sub < min(needed_sub, opts.subnetwork_samples) and not confirmed():
        # Every other draw is guided by the best model so far: it leaves out the node of one of its
        # rejected measurements and starts from it (a best model with a gross error inside is often
        # in the right basin but pulled off it).
        guided = best is not None and drawn_sub % 2 == 1
        suspicious = None
        if guided:
            _, _, t = _score(_residual_matrix(F, best.R, best.S, best.O), mask, thr, floor, best.redundancy,
                                 dim=best.R.shape[1])
            suspicious = np.argwhere(mask & ~_classify(_residual_matrix(F, best.R, best.S, best.O), mask, t))
        # Unguided draws may repeat a sub-network: each gets a new random start.
        block = _sample_subnetwork(mask, rng, tried if guided else None, suspicious, dim=dim)
        if block is None:
            if guided:
                drawn_sub += 1
                continue
            # No redundant sub-network (e.g. as many measurements as unknowns): random starts on all.
            block = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        drawn_sub += 1
        if offer(_hypotheses_from_subnetwork(F, mask, *block, thr, floor, opts, rng, search,
                                             best.inlier_ratio if best is not None else None,
                                             best if guided else None, dim=dim)):
            needed_sub = _needed(ratio_of(best), k, opts.confidence, opts.subnetwork_convergence)
    # The runners-up get their local optimisation too: with low redundancy a hypothesis in the right
    # basin, pulled off by a gross error, can score worse than a wrong one before LO and better after.
    if pending[0] is not None:
        search.accepted = True
    for model in search.runners_up if not search.accepted else ():
        lo = _local_optimisation(F, mask, model, thr, floor, opts, rng)
        search.local_optimisations += 1
        if best is None or _better(lo, best, floor):
            if best is not None and best.refined:
                search.others.append(best)
            best = lo
    return best, search


def _n_params_mask(mask: np.ndarray, dim: int) -> int:
    """Unknowns (2m + 3n - 3; 3D: 3m + 4n - 6) of the nodes that have measurements."""
    return n_unknowns(int(mask.any(axis=1).sum()), int(mask.any(axis=0).sum()), dim)
