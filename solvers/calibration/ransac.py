"""The LO-RANSAC search over the hypotheses of `sampling` (minimal solvers on fully measured sub-blocks,
then sub-networks solved by least squares), scored MSAC-style with sigma, LMedS on held-out entries
without; its stopping count (`_needed`) and the comparison of two models (`_better`)."""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from .adjustment import n_unknowns
from .result import CalibrationOptions
from .sampling import (_hypotheses_from_block, _hypotheses_from_subnetwork, _local_optimisation, _sample_block,
                       _sample_subnetwork)
from .scoring import _classify, _Model, _residual_matrix, _score, _Search


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

    if confirmed():
        return best, search  # the accepted model stayed the best for the count (or sigma given: at once)
    if pending[0] is None:
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
    # fully measured blocks, low redundancy), or there were too few blocks at all; or, sigma unknown, before
    # an accepted model was confirmed: the sub-networks (gaps allowed) draw the challengers the blocks could
    # not (10r/8s with 30 % missing: one distinct 6r4s block, the accepted model "unconfirmed" after 1 sample
    # in 9 of the 12 networks whose sigma-given call is "ok", each within 3.2 std of the truth).
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
        if not confirmed():
            # the blocks and the sub-networks ran out before as many samples as confirm_outliers asks for gave
            # a hypothesis: the accepted model was never challenged enough to call it unique
            search.unconfirmed = pending[1] - (search.productive - pending[0])
        search.accepted = True  # the samples ran out (or the count was met) with the accepted model still best
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
