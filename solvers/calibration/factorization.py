"""Low-rank structure of a TDOA matrix: the robust factorization F ~ 1 o^T + A B^T and its metric upgrade.

With sources far from the receivers (plane waves), F[i, j] = |r_i - s_j| + o_j ~ o'_j - u_j . r_i, u_j the
unit direction from the array to source j: after the offsets, F has rank K (the dimension). A factorization
A B^T determines the receivers and directions up to an affine map Q (r = A Q, u = -B Q^-T); the unit norm of
every direction fixes Q Q^T (a linear least-squares problem in the K (K + 1) / 2 entries of M = (Q Q^T)^-1):
the metric upgrade. What remains is a rotation (and reflection): the gauge.

Everything here is computed from the data alone (no fit of the nonlinear model), for `diagnose` (singular
values, spread of directions, orientation) and `initialise` (the far-field start).

Reference: S. Thrun, "Affine structure from sound" (NIPS 2005); Y. Kuang and K. Astrom, "Stratified sensor
network self-calibration from TDOA measurements" (EUSIPCO 2013).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Residuals beyond this many robust scales get no weight in the factorization (gross errors).
CUTOFF_SCALES = 4.0
#: Entries farther than this many robust spreads of the data from their column's median do not enter the start.
START_SPREADS = 10.0
#: 1 / Phi^-1(3/4): the median absolute deviation of a normal sample times this is its std.
MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True, eq=False)
class LowRank:
    """F ~ o[None, :] + A @ B.T on the entries of `inliers` (a robust fit of rank k = A.shape[1]).

    scale : robust std of the residuals on the measured entries (MAD)
    inliers : (m, n) entries within CUTOFF_SCALES x scale
    singular_values : of A B^T after removing its column means (k values, descending)
    """

    o: np.ndarray
    A: np.ndarray
    B: np.ndarray
    scale: float
    inliers: np.ndarray
    singular_values: np.ndarray


def _solve_batched(N: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve each N[t] x = rhs[t] with a small ridge (a node with too few entries gets the least-norm answer)."""
    k = N.shape[-1]
    ridge = 1e-12 * np.maximum(np.trace(N, axis1=1, axis2=2), 1e-300)[:, None, None] * np.eye(k)
    return np.linalg.solve(N + ridge, rhs[..., None])[..., 0]


def robust_low_rank(F: np.ndarray, mask: np.ndarray, k: int, *, iterations: int = 100,
                    transposed: bool = False) -> LowRank:
    """Robust alternating least squares for F ~ 1 o^T + A B^T (rank k plus one offset per column).

    The start: the SVD of F minus its column means, or medians (both are run; the smaller robust scale wins),
    missing entries 0. Each round refits (o_j, b_j) per
    column and a_i per row by weighted least squares, with Cauchy weights at CUTOFF_SCALES / 2 robust
    scales and no weight beyond CUTOFF_SCALES (gross errors). transposed: the offsets belong to the rows
    (the fit of F^T; used to ask which way round the matrix is).
    """
    if transposed:
        low = robust_low_rank(F.T, mask.T, k, iterations=iterations)
        return LowRank(low.o, low.B, low.A, low.scale, low.inliers.T, low.singular_values)
    n = F.shape[1]
    # an entry farther from its column's median than START_SPREADS robust spreads of the whole matrix is no
    # measurement of this geometry (the Pyramic data hold five of -259 m among values within +-0.2 m): the
    # starts leave it out; the weighted rounds then judge every entry by the fit
    dev = np.abs(F - np.array([np.median(F[mask[:, j], j]) if mask[:, j].any() else 0.0 for j in range(n)])[None, :])
    spread = MAD_TO_SIGMA * float(np.median(dev[mask])) if mask.any() else 0.0
    start = mask & (dev <= START_SPREADS * spread) if spread > 0 else mask
    # two starts, the fit with the smaller robust scale kept: the column means (exact plane waves are then
    # exactly rank k) and the column medians (gross errors of the size of the signal, as wrong GCC-PHAT peaks
    # are, can turn the mean start's leading components into a few rows of errors: the Pyramic array's every
    # 5th source fell to rank 1 with a scale of 18 mm, from the medians 1 mm)
    fits = [_alternate(F, mask, start, k,
                       np.array([stat(F[start[:, j], j]) if start[:, j].any() else 0.0 for j in range(n)]), iterations)
            for stat in (np.mean, np.median)]
    return min(fits, key=lambda low: low.scale)


def _alternate(F: np.ndarray, mask: np.ndarray, start: np.ndarray, k: int, o: np.ndarray, iterations: int) -> LowRank:
    """The alternating weighted least squares of `robust_low_rank` from the column offsets o and the SVD of
    the entries of `start`."""
    m, n = F.shape
    X = np.where(mask, F, 0.0)
    C = np.where(start, F - o[None, :], 0.0)
    U, s, Vt = np.linalg.svd(C, full_matrices=False)
    A = U[:, :k] * s[:k]
    B = Vt[:k].T
    W = mask.astype(float)
    scale = np.inf
    for _ in range(iterations):
        E = np.where(mask, X - o[None, :] - A @ B.T, 0.0)
        scale = max(MAD_TO_SIGMA * float(np.median(np.abs(E[mask]))), 1e-12 * float(np.abs(X[mask]).max() or 1.0))
        c = 0.5 * CUTOFF_SCALES * scale
        W = np.where(mask & (np.abs(E) <= CUTOFF_SCALES * scale), 1.0 / (1.0 + (E / c) ** 2), 0.0)
        D = np.column_stack([np.ones(m), A])
        N = np.einsum("ij,ia,ib->jab", W, D, D)
        ob = _solve_batched(N, np.einsum("ij,ia,ij->ja", W, D, X))
        o_new, B_new = ob[:, 0], ob[:, 1:]
        N = np.einsum("ij,ja,jb->iab", W, B_new, B_new)
        A_new = _solve_batched(N, np.einsum("ij,ja,ij->ia", W, B_new, X - o_new[None, :]))
        change = np.abs(A_new @ B_new.T + o_new[None, :] - A @ B.T - o[None, :])[mask].max()
        A, B, o = A_new, B_new, o_new
        if change < 1e-3 * scale:
            break
    E = np.where(mask, X - o[None, :] - A @ B.T, np.nan)
    scale = max(MAD_TO_SIGMA * float(np.median(np.abs(E[mask]))), 1e-300)
    inliers = mask & (np.abs(np.nan_to_num(E, nan=np.inf)) <= CUTOFF_SCALES * scale)
    P = A @ B.T
    sv = np.linalg.svd(P - P.mean(axis=0)[None, :], compute_uv=False)[:k]
    return LowRank(o, A, B, scale, inliers, sv)


@dataclass(frozen=True, eq=False)
class MetricUpgrade:
    """Receivers and unit directions from a rank-K factorization (far field: F ~ o'_j - u_j . r_i).

    receivers : (m, K), centred; directions : (n, K), unit rows; offsets : (n,) o'_j
    conditioning : smallest / largest singular value of the upgrade's least-squares system (near 0: the
        directions do not determine the metric, e.g. every source on one elevation cone)
    misfit : rms of |u_j|^2 - 1 before normalising (0 for exact plane waves)
    """

    receivers: np.ndarray
    directions: np.ndarray
    offsets: np.ndarray
    conditioning: float
    misfit: float


def _sym_design(B: np.ndarray) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Rows b^T M b as linear forms in the upper-triangular entries of a symmetric M."""
    k = B.shape[1]
    pairs = [(a, b) for a in range(k) for b in range(a, k)]
    cols = [B[:, a] * B[:, b] * (1.0 if a == b else 2.0) for a, b in pairs]
    return np.column_stack(cols), pairs


def metric_upgrade(low: LowRank, use: np.ndarray | None = None) -> MetricUpgrade:
    """The metric upgrade of a rank-K factorization: M symmetric with b_j^T M b_j = 1 (least squares over
    the sources in `use`, default all), M = L L^T, directions u_j = -L^T b_j, receivers r_i = L^-1 a_i
    (so that -u_j . r_i = a_i . b_j). An indefinite M (noise, a degenerate spread) is replaced by the
    nearest positive semi-definite one with a floor of 1e-9 of its largest eigenvalue."""
    B = low.B if use is None else low.B[use]
    k = B.shape[1]
    D, pairs = _sym_design(B)
    sv = np.linalg.svd(D, compute_uv=False)
    conditioning = float(sv[-1] / sv[0]) if sv[0] > 0 else 0.0
    x, *_ = np.linalg.lstsq(D, np.ones(len(B)), rcond=None)
    M = np.zeros((k, k))
    for v, (a, b) in zip(x, pairs):
        M[a, b] = M[b, a] = v
    w, V = np.linalg.eigh(M)
    w = np.maximum(w, 1e-9 * max(float(w.max()), 1e-300))
    L = V * np.sqrt(w)[None, :]  # M = L L^T
    directions = -low.B @ L
    norms = np.linalg.norm(directions, axis=1)
    misfit = float(np.sqrt(np.mean((norms**2 - 1.0) ** 2)))
    directions = directions / np.where(norms > 0, norms, 1.0)[:, None]
    receivers = np.linalg.solve(L, low.A.T).T
    receivers = receivers - receivers.mean(axis=0)[None, :]
    # o'_j: the offsets of the centred receivers (a_i . b_j = -u_j . r_i before the shift)
    centre = np.linalg.solve(L, low.A.T).T.mean(axis=0)
    offsets = low.o - directions @ centre * norms
    return MetricUpgrade(receivers, directions, offsets, conditioning, misfit)


def elevation_span(directions: np.ndarray) -> tuple[float, np.ndarray]:
    """(span in degrees, axis): the directions' spread out of the plane of their largest spread, the
    2nd-98th percentile range of arcsin(u . axis) with axis the eigenvector of the smallest centred second
    moment (sources on elevation cones around a vertical axis: the vertical; on one cone: a span near 0)."""
    U = np.asarray(directions, dtype=float)
    C = np.cov(U.T)
    w, V = np.linalg.eigh(C)
    axis = V[:, 0]
    el = np.degrees(np.arcsin(np.clip(U @ axis, -1.0, 1.0)))
    lo, hi = np.percentile(el, [2, 98])
    return float(hi - lo), axis
