"""Robust classification and the adjustment of point sources: iteratively reweighted refinement on all
measured entries, re-placement of badly placed nodes, and least squares on the inliers (the local
optimisation of LO-RANSAC and the robust route of the final adjustment); the all-data fit, data snooping
with readmission and the exact leave-one-out test (`_adjust`, the stage the search's best hypothesis goes
through; plane waves go through `adjust` instead)."""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from .adjustment import (
    AdjustmentStatistics,
    adjustment_statistics,
    critical_value,
    make_problem,
    min_measurements,
    n_unknowns,
    robust_refine,
)
from .flags import _repair_flips
from .placement import _fill, _place
from .result import CalibrationOptions
from .scoring import MAD_TO_SIGMA, _classify, _Model, _residual_matrix, _score

log = logging.getLogger("solvers.calibration")


def _replace_weak(F, mask, R, S, O, t, rng):
    """Re-place afresh the nodes that explain fewer than 3/4 of their measurements (at least the
    minimum); keep a new position only where it explains more measurements. Returns (R, S, O, changed)."""
    changed = False
    for receivers in (True, False):
        inl = _classify(_residual_matrix(F, R, S, O), mask, t)
        axis, minimum = (1, min_measurements(R.shape[1])[0]) if receivers else (0, min_measurements(R.shape[1])[1])
        placed = np.isfinite(R[:, 0]) if receivers else np.isfinite(S[:, 0])
        weak = placed & (inl.sum(axis=axis) < np.maximum(minimum, 0.75 * mask.sum(axis=axis)))
        if not weak.any():
            continue
        R2, S2, O2 = _place(F, mask, R, S, O, t, rng, receivers, fresh=weak, refine_all=False)
        better = weak & (_classify(_residual_matrix(F, R2, S2, O2), mask, t).sum(axis=axis) > inl.sum(axis=axis))
        if better.any():
            changed = True
            if receivers:
                R = np.where(better[:, None], R2, R)
            else:
                S, O = np.where(better[:, None], S2, S), np.where(better, O2, O)
    return R, S, O, changed


@dataclass(frozen=True)
class _Polished:
    R: np.ndarray
    S: np.ndarray
    O: np.ndarray
    inliers: np.ndarray
    sigma: float
    threshold: float
    converged: bool


def _n_params(R, S) -> int:
    """Unknowns of the placed nodes (2m + 3n - 3; 3D: 3m + 4n - 6)."""
    return n_unknowns(int(np.isfinite(R[:, 0]).sum()), int(np.isfinite(S[:, 0]).sum()), R.shape[1])


def _estimate_sigma(E, mask, inliers, n_params: int, k: float, floor: float) -> float:
    """Noise level from residuals of a fit with n_params parameters.

    Without an inlier set: 1.4826 x the median |e| over the measured entries. With one (a least
    squares fit on it): sqrt(SSR / N) over the inliers, divided by the standard deviation of a unit
    Gaussian truncated at +-k (the threshold cut the tails). Both are scaled by sqrt(N / (N - p)):
    residuals of a fit keep N - p degrees of freedom. Without these corrections the estimate
    shrinks round after round (classify at k sigma, refit, re-estimate) and rejects good data.
    """
    use = mask & np.isfinite(E) if inliers is None else inliers
    N = int(use.sum())
    if N == 0:
        return floor / k
    dof_factor = N / (N - n_params) if N > n_params else 1.0
    if inliers is None:
        sig = MAD_TO_SIGMA * float(np.median(np.abs(E[use]))) * math.sqrt(dof_factor)
    else:
        truncated = 1.0 - 2.0 * k * math.exp(-0.5 * k * k) / math.sqrt(2.0 * math.pi) / math.erf(k / math.sqrt(2.0))
        sig = math.sqrt(float(np.sum(E[use] ** 2)) / N * dof_factor / truncated)
    return max(sig, floor / k)


def _polish(F, mask, R, S, O, thr, floor, opts: CalibrationOptions, rng, max_iter: int, rounds: int,
            redundancy: np.ndarray | None = None) -> _Polished:
    """Robust LM on all measured entries, placement of unplaced and badly placed nodes, then
    least squares on the inliers, re-classifying (and re-estimating sigma when unknown) for up to
    `rounds` rounds or until the inlier set is stable. The local optimisation of LO-RANSAC with
    rounds=1; the final refinement with more. `redundancy`: the hypothesis's approximate redundancy
    numbers (`hypothesis_redundancy`), for the first scale estimate when sigma is unknown."""
    _, _, t = _score(_residual_matrix(F, R, S, O), mask, thr, floor, redundancy, dim=R.shape[1])
    ref = robust_refine(F, mask, R, S, O, loss=opts.loss, scale=t / opts.threshold_sigmas, max_iter=max_iter)
    R, S, O = _fill(F, mask, ref.R, ref.S, ref.O, t, rng)
    converged = ref.converged
    _, _, t = _score(_residual_matrix(F, R, S, O), mask, thr, floor, dim=R.shape[1])
    R, S, O, changed = _replace_weak(F, mask, R, S, O, t, rng)
    if changed:
        ref = robust_refine(F, mask, R, S, O, loss=opts.loss, scale=t / opts.threshold_sigmas, max_iter=max_iter)
        R, S, O, converged = ref.R, ref.S, ref.O, ref.converged
    E = _residual_matrix(F, R, S, O)
    if thr is None:
        sig = _estimate_sigma(E, mask, None, _n_params(R, S), opts.threshold_sigmas, floor)
    else:
        sig = thr / opts.threshold_sigmas
    inl = None
    for round_ in range(rounds):
        # Unknown sigma: the first cut is twice as wide, because the median residual of a robust fit
        # with many parameters per measurement under-estimates sigma; least squares on those inliers
        # then gives sigma from the sum of squares, and the later rounds cut at threshold_sigmas.
        k = opts.threshold_sigmas * (2.0 if thr is None and round_ == 0 else 1.0)
        t = max(k * sig, floor)
        new = _classify(E, mask, t)
        if inl is not None and (new == inl).all():
            break
        inl = new
        fin = robust_refine(F, mask, R, S, O, loss="linear", scale=1.0, max_iter=max_iter, use=inl)
        R, S, O, converged = fin.R, fin.S, fin.O, converged and fin.converged
        E = _residual_matrix(F, R, S, O)
        if thr is None:
            sig = _estimate_sigma(E, mask, inl, _n_params(R, S), k, floor)
    t = max(opts.threshold_sigmas * sig, floor)
    return _Polished(R, S, O, _classify(E, mask, t), sig, t, converged)


def _drop_undetermined(F, work, R, S, O, inl, max_iter):
    """Unplace nodes with fewer inlier measurements than they need (min_measurements), repeatedly, and refit the
    rest by least squares on the inliers. A node the data do not fix would otherwise be reported at an
    arbitrary place and keep the refinement from converging. Returns (R, S, O, inl, warnings, fit)."""
    R, S, O, inl = R.copy(), S.copy(), O.copy(), inl.copy()
    out = []
    need_r, need_t = min_measurements(R.shape[1])
    while True:
        weak_r = np.isfinite(R[:, 0]) & (inl.sum(axis=1) < need_r)
        weak_t = np.isfinite(S[:, 0]) & (inl.sum(axis=0) < need_t)
        if not (weak_r.any() or weak_t.any()):
            break
        for i in np.flatnonzero(weak_r):
            out.append(f"receiver {i + 1}: only {int(inl[i].sum())} of its {int(work[i].sum())} measurements are "
                       f"inliers (needs {need_r}); not placed")
        for j in np.flatnonzero(weak_t):
            out.append(f"transmitter {j + 1}: only {int(inl[:, j].sum())} of its {int(work[:, j].sum())} measurements "
                       f"are inliers (needs {need_t}); not placed")
        R[weak_r], S[weak_t], O[weak_t] = np.nan, np.nan, np.nan
        inl[weak_r], inl[:, weak_t] = False, False
    if not out:
        return R, S, O, inl, out, None
    ls = robust_refine(F, work, R, S, O, loss="linear", max_iter=max_iter, use=inl)
    return ls.R, ls.S, ls.O, inl, out, ls


def _no_outlier(st: AdjustmentStatistics, sigma, opts: CalibrationOptions) -> bool:
    """True when the fit on all entries shows no outlier: the global test passes (sigma given) and the
    largest test statistic among testable entries stays below its Bonferroni bound (level alpha_global
    over all of them), or nothing can be tested."""
    testable = st.redundancy >= opts.min_redundancy
    if not testable.any():
        return True
    if sigma is not None:
        c = critical_value(opts.alpha_global / testable.sum())
        return st.global_passed is not False and float(np.abs(st.w[testable]).max()) <= c
    if st.dof < 2:
        return True
    c = critical_value(opts.alpha_global / testable.sum(), st.dof - 1)
    return float(np.abs(st.w[testable]).max()) <= c


def _robust_scale(F, work, best: _Model, floor, opts: CalibrationOptions):
    """Noise level from a robust fit on all entries: 1.4826 x the median of |e_k| / sqrt(r_k) over the
    entries whose redundancy number r_k is at least min_redundancy (e_k / sqrt(r_k) has the noise's
    variance in a least-squares fit, whatever the redundancy of the entry). The first scale comes from
    the hypothesis's residuals normalised by its approximate redundancy numbers (a minimal sample's
    own entries, which fit it exactly, never set it).
    Returns (scale, statistics of the last robust fit or None)."""
    R, S, O = best.R, best.S, best.O
    med, _, _ = _score(_residual_matrix(F, R, S, O), work, None, floor, best.redundancy, dim=R.shape[1])
    s = max(MAD_TO_SIGMA * math.sqrt(med), floor) if np.isfinite(med) else floor
    st = None
    for _ in range(3):
        c = opts.threshold_sigmas * s
        ref = robust_refine(F, work, R, S, O, loss="cauchy", scale=c, max_iter=opts.lo_iterations)
        R, S, O = ref.R, ref.S, ref.O
        # redundancy numbers of the weighted fit: a subset the Cauchy fit explains exactly has r ~ 0
        # and cannot shrink the scale (the collapse a minimal fit's zero residuals caused)
        E = _residual_matrix(F, R, S, O)
        w = 1.0 / (1.0 + (np.nan_to_num(E, nan=0.0) / c) ** 2)
        st = adjustment_statistics(F, work & np.isfinite(R[:, 0])[:, None] & np.isfinite(S[:, 0])[None, :], R, S, O, None,
                                   weights=w)
        if st is None:
            break
        ok = st.redundancy >= max(opts.min_redundancy, 1e-3)
        if not ok.any():
            break
        s = max(MAD_TO_SIGMA * float(np.median(np.abs(st.residuals[ok]) / np.sqrt(st.redundancy[ok]))), floor)
    return s, st


def _snoop(F, work, R, S, O, inl, sigma, opts: CalibrationOptions):
    """Data snooping with readmission: least squares on the inliers; rejected entries whose prediction
    by that fit passes the test come back; then the inlier with the largest test statistic above the
    critical value (one per receiver and per transmitter per round, the entries' redundancy numbers
    at least min_redundancy) is rejected; until nothing changes. Returns (R, S, O, inl, converged)."""
    inl = inl.copy()
    converged = True
    seen = set()
    t0 = time.perf_counter()
    for round_ in range(opts.max_snooping_rounds):
        if round_:
            log.info("  data snooping round %d: %d measurements kept (%.1f s)", round_, int(inl.sum()),
                     time.perf_counter() - t0)
        ls = robust_refine(F, work, R, S, O, loss="linear", max_iter=opts.max_iterations, use=inl)
        R, S, O, converged = ls.R, ls.S, ls.O, ls.converged
        st = adjustment_statistics(F, inl, R, S, O, sigma, alpha=opts.alpha, power=opts.power,
                                   alpha_global=opts.alpha_global)
        if st is None or st.dof < (1 if sigma is not None else 2):
            break
        key = inl.tobytes()
        if key in seen:
            break
        seen.add(key)
        dof_t = None if sigma is not None else st.dof - 1
        c = critical_value(opts.alpha, dof_t)
        placed = np.isfinite(R[:, 0])[:, None] & np.isfinite(S[:, 0])[None, :]
        cand = work & ~inl & placed
        if cand.any():
            q = make_problem(F, cand, st.problem.rows, st.problem.cols, dim=st.problem.dim)
            if len(q.ii):
                e, h = st.hat(q)
                wq = e / (st.sigma * np.sqrt(1.0 + h))
                back = np.abs(wq) <= c
                if back.any():
                    inl[q.rows[q.ii[back]], q.cols[q.jj[back]]] = True
                    continue
        testable = st.redundancy >= opts.min_redundancy
        aw = np.where(testable, np.abs(st.w), 0.0)
        big = aw > c
        if not big.any():
            break
        i, j = st.entries[:, 0], st.entries[:, 1]
        m, n = F.shape
        best_r = np.zeros(m)
        best_t = np.zeros(n)
        np.maximum.at(best_r, i, aw)
        np.maximum.at(best_t, j, aw)
        pick = big & (aw >= best_r[i]) & (aw >= best_t[j])
        inl[i[pick], j[pick]] = False
    return R, S, O, inl, converged


def _all_data_fit(F, work, model: _Model, sigma, floor, opts: CalibrationOptions, rng, memo: dict | None = None):
    """(R, S, O, use, converged, robust scale, passed): least squares on every entry between the nodes
    placed by the model (unplaced ones placed first), and whether it shows no outlier.

    Sigma given: the global test and the largest w-test statistic (`_no_outlier`). Sigma estimated:
    the largest externally studentised residual, and - because two gross errors mask each other in
    that statistic (each inflates the other's leave-one-out sigma) - the largest residual of a
    robust fit standardised by the robust scale (`_robust_scale`), each against its Bonferroni bound
    (the latter widened by 1.5 for the scale's own sampling error). Below min_dof_for_sigma the exact
    leave-one-out test decides (`_leave_one_out`); `memo` keeps its verdict per minimum (the same
    entries and SSR to 1e-9), which the search's successive hypotheses often share.
    """
    c = opts.threshold_sigmas * sigma if sigma is not None else floor
    R, S, O = _fill(F, work, model.R, model.S, model.O, max(c, floor), rng)
    placed = np.isfinite(R[:, 0])[:, None] & np.isfinite(S[:, 0])[None, :]
    ls = robust_refine(F, work, R, S, O, loss="linear", max_iter=opts.max_iterations, use=work & placed)
    st = adjustment_statistics(F, work & placed, ls.R, ls.S, ls.O, sigma, alpha=opts.alpha, power=opts.power,
                               alpha_global=opts.alpha_global)
    passed = st is not None and ls.converged and _no_outlier(st, sigma, opts)
    if passed and sigma is None and st.dof < opts.min_dof_for_sigma:
        # little redundancy: the linearised statistic of a fit pulled by a gross error understates it
        key = ((work & placed).tobytes(), float(f"{st.ssr:.9e}"))
        verdict = memo.get(key) if memo is not None else None
        if verdict is None:
            found = _leave_one_out(F, work, [(ls.R, ls.S, ls.O), (R, S, O)], work & placed, st, opts)
            verdict = found is None or found[0] <= found[1]
            if memo is not None:
                memo[key] = verdict
        passed = verdict
    scale = sigma
    if sigma is None and st is not None and st.dof >= opts.min_dof_for_sigma:
        # (below that redundancy a robust scale means nothing, and only classic snooping is done)
        scale, robust = _robust_scale(F, work, _Model(R, S, O, 0.0, 0.0, redundancy=model.redundancy), floor, opts)
        if passed and robust is not None:
            testable = robust.redundancy >= max(opts.min_redundancy, 1e-3)
            if testable.any():
                z = np.abs(robust.residuals[testable]) / (scale * np.sqrt(robust.redundancy[testable]))
                passed = float(z.max()) <= 1.5 * critical_value(opts.alpha_global / testable.sum())
    return ls.R, ls.S, ls.O, work & placed, ls.converged, scale, passed


def _leave_one_out(F, work, starts, inl, st: AdjustmentStatistics, opts: CalibrationOptions,
                   only: np.ndarray | None = None):
    """The entry whose removal explains the misfit best, by refitting without it (nonlinear), and the
    entries that explain it as well (their removal fits no significantly worse: an error there cannot be
    told apart, e.g. the three measurements of a receiver with three transmitters).

    The test statistic is the exact (nonlinear) externally studentised residual
    t_k^2 = (SSR - SSR_k) / (SSR_k / (dof - 1)), t(dof - 1) under the null. With little redundancy and a
    gross error the all-data fit is far from the truth, and the linearised statistic of that fit
    (`st.w`) understates it by orders of magnitude (9r/3s, one 0.15 error at sigma 1e-3: 7.8 against
    the exact 680). Candidates: every entry, largest |w| first, at most loo_candidates.
    Each refit starts from every (R, S, O) of `starts` (the current fit, and the search's best
    hypothesis: a fit pulled off by a gross error is often in another basin than the truth) and keeps
    the smallest SSR. `only` (bool per entry of `st`): test these entries alone (the critical value
    stays that of all entries). Returns (t, critical value, group (list of (i, j)), refit of the best) or
    None."""
    if st.dof < 3 or len(st.entries) == 0 or (only is not None and not only.any()):
        return None
    # every entry is a candidate: the redundancy numbers of a fit pulled off by a gross error can put
    # the erroneous entry itself below min_redundancy (refitting without an entry of redundancy 0
    # changes nothing and cannot be selected)
    aw = np.abs(np.nan_to_num(st.w, nan=0.0))
    order = [k for k in np.argsort(-aw, kind="stable") if only is None or only[k]][: opts.loo_candidates]
    # a start that predicts every entry like the first one (within 3 a-posteriori sigmas) is in its basin
    E0 = _residual_matrix(F, *starts[0])
    s_post = math.sqrt(st.ssr / st.dof)
    starts = starts[:1] + [x for x in starts[1:]
                           if not np.nanmax(np.abs(_residual_matrix(F, *x) - E0)[inl], initial=0.0) <= 3.0 * s_post]
    ssr_k, fits = [], []
    for k in order:
        use = inl.copy()
        use[st.entries[k, 0], st.entries[k, 1]] = False
        best_k = (math.inf, None)
        for R, S, O in starts:
            ls = robust_refine(F, work, R, S, O, loss="linear", max_iter=opts.max_iterations, use=use)
            E = _residual_matrix(F, ls.R, ls.S, ls.O)
            ssr = float(np.sum(E[use] ** 2))
            if np.isfinite(ssr) and ssr < best_k[0]:
                best_k = (ssr, ls)
        ssr_k.append(best_k[0])
        fits.append(best_k[1])
    ssr_k = np.asarray(ssr_k)
    best = int(np.argmin(ssr_k))
    if not np.isfinite(ssr_k[best]):
        return None
    s2 = max(ssr_k[best], 1e-300) / (st.dof - 1)
    t = math.sqrt(max(st.ssr - ssr_k[best], 0.0) / s2)
    c = critical_value(opts.alpha / len(st.entries), st.dof - 1)
    # told apart from the best when removing it instead leaves a significantly larger misfit
    c1 = critical_value(opts.alpha, st.dof - 1)
    group = [tuple(int(v) for v in st.entries[order[g]]) for g in range(len(order))
             if (ssr_k[g] - ssr_k[best]) / s2 <= c1 ** 2]
    return t, c, group, fits[best]


def _snoop_low_redundancy(F, work, R, S, O, inl, opts: CalibrationOptions, notes: list | None = None,
                          hypothesis: tuple | None = None, weak_only: bool = False,
                          unresolved: list | None = None):
    """Sigma unknown, little redundancy: reject the entry whose removal explains the misfit best while its
    exact externally studentised residual (`_leave_one_out`) exceeds the Bonferroni bound (alpha over
    the entries) and the fit keeps at least 2 degrees of freedom; when other entries explain it
    as well and all belong to one node, the error cannot be located among them and all of them are
    rejected (said in `notes`); equally good entries of different nodes stop the snooping (the finding,
    (t, critical value, group), is appended to `unresolved`). weak_only: only the entries whose
    redundancy number is below opts.weak_redundancy are tested (after the robust route, whose w-test
    cannot see an error there). Returns (R, S, O, inl, converged)."""
    inl = inl.copy()
    converged = True
    while True:
        st = adjustment_statistics(F, inl, R, S, O, None, alpha=opts.alpha, power=opts.power,
                                   alpha_global=opts.alpha_global)
        if st is None or st.dof < 3:
            break
        only = st.redundancy < opts.weak_redundancy if weak_only else None
        found = _leave_one_out(F, work, [(R, S, O)] + ([hypothesis] if hypothesis is not None else []), inl, st, opts,
                               only)
        # family-wise level alpha (0.001): with 2-9 degrees of freedom one false rejection costs a node
        # (a receiver with 3 measurements keeps 2 and cannot be placed), a gross error is far beyond it
        if found is None or found[0] <= found[1]:
            break
        t, c, group, ls = found
        if len({i for i, _ in group}) > 1 and len({j for _, j in group}) > 1:
            # entries of different nodes that explain the misfit equally: nothing local to reject
            # (a degenerate geometry or a fit in a wrong basin); the status reports the misfit
            if unresolved is not None:
                unresolved.append((t, c, group))
            break
        for i, j in group:
            inl[i, j] = False
        if len(group) > 1 and notes is not None:
            names = ", ".join(f"r{i + 1}-s{j + 1}" for i, j in group)
            notes.append(f"a gross error among {names} (t = {t:.3g} > {c:.3g}) cannot be located: all {len(group)} rejected")
        if len(group) == 1:
            R, S, O, converged = ls.R, ls.S, ls.O, ls.converged
        else:
            ls = robust_refine(F, work, R, S, O, loss="linear", max_iter=opts.max_iterations, use=inl)
            R, S, O, converged = ls.R, ls.S, ls.O, ls.converged
    return R, S, O, inl, converged


def _adjust(F, work, best: _Model, sigma, floor, opts: CalibrationOptions, rng, all_data=None,
            notes: list | None = None, unresolved: list | None = None, exact: list | None = None):
    """The final adjustment from the best hypothesis: (R, S, O, inliers, converged, route).

    1. The all-data hypothesis: least squares on every entry between placed nodes; if the fit shows
       no outlier (`_no_outlier`), every entry is kept (route "all data").
    2. Otherwise the robust route: robust refinement and classification at threshold_sigmas x sigma
       (sigma given, or `_robust_scale`), flipped nodes repaired, then data snooping with
       readmission (`_snoop`); with sigma unknown, then the exact leave-one-out test of the kept
       entries of small redundancy number (`_snoop_low_redundancy`, weak_only; an error it finds but
       cannot locate goes to `unresolved`, the mask of the entries it rejected to `exact`).
    """
    R, S, O, use, converged, scale, passed = all_data or _all_data_fit(F, work, best, sigma, floor, opts, rng)
    if passed:
        return R, S, O, use, converged, "all data"
    n_fit = int(use.sum())
    dof_all = n_fit - n_unknowns(int(np.isfinite(R[:, 0]).sum()), int(np.isfinite(S[:, 0]).sum()), R.shape[1])
    if sigma is None and dof_all < opts.min_dof_for_sigma:
        # Too little redundancy to estimate sigma robustly: a robust fit would explain a subset exactly
        # and call the rest outliers. Only classic data snooping from the all-data fit remains: the
        # largest externally studentised residual, above its Bonferroni bound, one at a time.
        R, S, O, inl, converged = _snoop_low_redundancy(F, work, R, S, O, use, opts, notes, (best.R, best.S, best.O))
        return R, S, O, inl, converged, "snooping"
    if scale is None:
        scale, _ = _robust_scale(F, work, best, floor, opts)
    thr = max(opts.threshold_sigmas * scale, floor)
    fin = _polish(F, work, best.R, best.S, best.O, thr, floor, opts, rng, opts.max_iterations, rounds=4)
    R, S, O, flipped = _repair_flips(F, fin.inliers, fin.R, fin.S, fin.O, fin.sigma, floor)
    if flipped:
        fin = _polish(F, work, R, S, O, thr, floor, opts, rng, opts.max_iterations, rounds=4)
    # converged: that of the final least squares (the robust stage only warm-starts it)
    R2, S2, O2, inl, converged = _snoop(F, work, fin.R, fin.S, fin.O, fin.inliers, sigma, opts)
    kept_dof = int(inl.sum()) - n_unknowns(int(np.isfinite(R2[:, 0]).sum()), int(np.isfinite(S2[:, 0]).sum()), R2.shape[1])
    if sigma is None and kept_dof < opts.min_dof_for_sigma:
        # The robust route kept too little redundancy to say what the noise is: its rejections rest on a
        # scale it cannot estimate. Only classic snooping from the all-data fit is justified.
        R, S, O, inl, converged = _snoop_low_redundancy(F, work, R, S, O, use, opts, notes, (best.R, best.S, best.O))
        return R, S, O, inl, converged, "snooping"
    if sigma is None:
        # the w-test of an entry with a small redundancy number shows almost nothing of an error in it, and an
        # estimated sigma that absorbed the error hides it further: such entries are tested exactly
        before = inl
        R2, S2, O2, inl, weak_converged = _snoop_low_redundancy(F, work, R2, S2, O2, inl, opts, notes, weak_only=True,
                                                                unresolved=unresolved)
        converged = converged and weak_converged
        if exact is not None:
            exact.append(before & ~inl)
    return R2, S2, O2, inl, converged, "robust"
