"""Robust classification: iteratively reweighted refinement on all measured entries, re-placement of
badly placed nodes, and least squares on the inliers (the local optimisation of LO-RANSAC and the
robust route of the final adjustment)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .adjustment import min_measurements, n_unknowns, robust_refine
from .placement import _fill, _place
from .result import CalibrationOptions
from .scoring import MAD_TO_SIGMA, _classify, _residual_matrix, _score


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
