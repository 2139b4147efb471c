"""Residuals, classification and hypothesis scores of the calibration pipeline."""
from __future__ import annotations

import math

from dataclasses import dataclass, field

import numpy as np

from .adjustment import min_measurements, n_unknowns

#: MAD -> standard deviation for Gaussian noise.
MAD_TO_SIGMA = 1.4826

def _residual_matrix(F: np.ndarray, R: np.ndarray, S: np.ndarray, O: np.ndarray) -> np.ndarray:
    """e_ij = F_ij - o_j - |r_i - s_j|; NaN where F is missing or a node is unplaced (NaN)."""
    diff = R[:, None, :] - S[None, :, :]
    return F - O[None, :] - np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))


def _classify(E, mask, t):
    return mask & (np.abs(E) <= t)  # NaN (missing, unplaced) compares False


def hypothesis_redundancy(mask: np.ndarray, rows, cols, R: np.ndarray, S: np.ndarray) -> np.ndarray:
    """(m, n) approximate redundancy number of every entry of a hypothesis solved on the block
    rows x cols and extended to the other nodes by multilateration (0 where unmeasured or unplaced).

    Block entries share the block's redundancy (entries - unknowns) / entries (0 for a minimal
    solver: they fit it exactly); an entry of a receiver placed from k transmitters gets (k - dim) / k,
    of a transmitter placed from k receivers (k - dim - 1) / k (the smaller where both apply). With
    sigma unknown e^2 / r estimates sigma^2 whatever the entry's share of the fit, so that hypotheses
    are compared on one scale and a minimal fit's zero residuals never look like zero noise.
    """
    m, n = mask.shape
    dim = R.shape[1]
    use = mask & np.isfinite(R[:, 0])[:, None] & np.isfinite(S[:, 0])[None, :]
    in_r, in_c = np.zeros(m, bool), np.zeros(n, bool)
    in_r[rows], in_c[cols] = True, True
    k_r, k_t = use.sum(axis=1), use.sum(axis=0)
    r_rec = np.maximum(k_r - dim, 0) / np.maximum(k_r, 1)
    r_tra = np.maximum(k_t - dim - 1, 0) / np.maximum(k_t, 1)
    block = use & in_r[:, None] & in_c[None, :]
    n_block = int(block.sum())
    u_block = n_unknowns(int(in_r.sum()), int(in_c.sum()), dim)
    rr = np.full((m, n), np.inf)
    rr[block] = max(n_block - u_block, 0) / max(n_block, 1)
    rr = np.where(use & ~in_r[:, None], np.minimum(rr, r_rec[:, None]), rr)
    rr = np.where(use & ~in_c[None, :], np.minimum(rr, r_tra[None, :]), rr)
    rr[~use | np.isinf(rr)] = 0.0
    return rr


def uniform_redundancy(mask: np.ndarray, placed_r: np.ndarray, placed_t: np.ndarray, dim: int) -> np.ndarray:
    """(m, n) the average redundancy (entries - unknowns) / entries of a fit on every entry between
    placed nodes, for each of them (0 elsewhere)."""
    use = mask & placed_r[:, None] & placed_t[None, :]
    k = int(use.sum())
    u = n_unknowns(int(placed_r.sum()), int(placed_t.sum()), dim)
    return np.where(use, max(k - u, 0) / max(k, 1), 0.0)


#: Entries whose (approximate) redundancy number is below this do not enter a scale estimate.
MIN_SCALE_REDUNDANCY = 0.02


def _score(E: np.ndarray, mask: np.ndarray, thr: float | None, floor: float,
           redundancy: np.ndarray | None = None, dim: int | None = None) -> tuple[float, float, float]:
    """(score, inlier ratio, threshold) of a residual matrix; lower score is better.

    Known sigma (thr given): MSAC, sum over measured entries of min(e^2, thr^2), unplaced entries
    counting thr^2. Unknown: the median of e^2 / r over the measured entries (r: the entry's
    redundancy in the hypothesis, `hypothesis_redundancy`, default `uniform_redundancy` in `dim`
    dimensions, which must then be given; entries with
    r below MIN_SCALE_REDUNDANCY left out, unplaced entries counting inf), an estimate of
    (0.6745 sigma)^2 that a minimal fit cannot drive to zero; thr = 3 x 1.4826 x its root, floored.
    """
    e2_all = np.where(np.isfinite(E), E * E, np.inf)
    e2 = e2_all[mask]
    if e2.size == 0:
        return np.inf, 0.0, thr or floor
    if thr is None:
        rr = redundancy
        if rr is None:  # a node is placed when any of its residuals is finite
            if dim is None:
                raise ValueError("_score with sigma unknown needs the hypothesis's redundancy numbers or dim")
            rr = uniform_redundancy(mask, np.isfinite(E).any(axis=1), np.isfinite(E).any(axis=0), dim)
        sel = mask & ((rr > MIN_SCALE_REDUNDANCY) | ~np.isfinite(e2_all))
        if not sel.any():
            sel = mask
        z = e2_all[sel] / np.where(rr[sel] > MIN_SCALE_REDUNDANCY, rr[sel], 1.0)
        med = float(np.median(z))
        t = max(3.0 * MAD_TO_SIGMA * math.sqrt(med), floor) if np.isfinite(med) else floor
        return med, float(np.mean(e2 <= t * t)), t
    return float(np.sum(np.minimum(e2, thr * thr))), float(np.mean(e2 <= thr * thr)), thr


def _prune(mask: np.ndarray, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Receivers / transmitters that keep enough measurements among each other (iterated)."""
    rows = np.ones(mask.shape[0], bool)
    cols = np.ones(mask.shape[1], bool)
    need_r, need_t = min_measurements(dim)
    while True:
        sub = mask & rows[:, None] & cols[None, :]
        new_rows = rows & (sub.sum(axis=1) >= need_r)
        new_cols = cols & (sub.sum(axis=0) >= need_t)
        if (new_rows == rows).all() and (new_cols == cols).all():
            return rows, cols
        rows, cols = new_rows, new_cols



@dataclass
class _Model:
    R: np.ndarray
    S: np.ndarray
    O: np.ndarray
    score: float
    inlier_ratio: float
    refined: bool = False
    converged: bool = False
    redundancy: np.ndarray | None = None  # (m, n) approximate redundancy numbers (hypothesis_redundancy)


@dataclass
class _Search:
    """Running state of the hypothesis search (counts for the result and the benchmark)."""

    samples: int = 0
    hypotheses: int = 0
    productive: int = 0  # samples that gave at least one hypothesis (the ones that can confirm a model)
    local_optimisations: int = 0
    solvers: set = field(default_factory=set)
    others: list = field(default_factory=list)  # distinct refined models (alternatives)
    runners_up: list = field(default_factory=list)  # unrefined models that did not beat the best
    accepted: bool = False  # the search ended because the best model passed the all-data test
    short_of: int = 0  # samples the confidence still needed when the budget (max_samples) stopped the search
    needed: float = 0.0  # samples the confidence needed then (inf: no sample count reaches it)
    share: float = 1.0  # the inlier share that count was computed at
    unconfirmed: int = 0  # confirming samples still needed when the distinct blocks ran out (sigma unknown)
    block: tuple = ()  # (entries, gross errors tolerated) of the sample that set the count needed
