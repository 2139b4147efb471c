"""Ground-truth error metrics for calibrations, after removing the gauge by rigid alignment.

This module owns the figures the paper reports (Sec. 4, Table 4 and Fig. 1-2): the relative
position error after the best rigid alignment (rotation, reflection and translation; no scaling,
since distances fix the scale) and the relative offset error (offsets carry no gauge: the receiver
clock frame is common), plus log10 helpers for histograms and medians. Only numpy is used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "CalibrationErrors",
    "RigidTransform",
    "align_rigid",
    "calibration_errors",
    "cramer_rao_position_rms",
    "log10_error",
    "offset_error",
    "position_error",
    "receiver_cramer_rao_rms",
    "tdoa_jacobian",
]

#: Floor applied by `log10_error` so that exact results map to a finite value.
LOG10_FLOOR = 1e-300


@dataclass(frozen=True, eq=False)
class RigidTransform:
    """Rigid map x -> A x + t on column vectors (rows: X @ A.T + t), A orthogonal (det +-1).

    Parameters
    ----------
    matrix : (k, k) orthogonal array A (rotation if det = +1, rotation-reflection if -1)
    translation : (k,) array t
    """

    matrix: np.ndarray
    translation: np.ndarray

    def apply(self, X: np.ndarray) -> np.ndarray:
        """Return the transformed points; X holds one point per row."""
        return np.asarray(X, dtype=float) @ self.matrix.T + self.translation


def align_rigid(X_est: np.ndarray, X_true: np.ndarray) -> RigidTransform:
    """Return the rigid transform T minimising ||T(X_est) - X_true||_F (reflections allowed).

    Orthogonal Procrustes / Kabsch without the determinant correction and without scaling:
    centre both point sets, take the SVD U S V^T of X_est_c^T X_true_c, then A = V U^T and
    t = mean(X_true) - A mean(X_est).

    Parameters
    ----------
    X_est, X_true : (N, k) arrays, corresponding points in rows

    Returns
    -------
    RigidTransform

    Reference: paper Sec. 4 (errors are reported up to the Euclidean gauge of Sec. 1).
    """
    X_est = np.asarray(X_est, dtype=float)
    X_true = np.asarray(X_true, dtype=float)
    if X_est.shape != X_true.shape or X_est.ndim != 2:
        raise ValueError(f"point sets must have equal (N, k) shapes, got {X_est.shape}, {X_true.shape}")
    mean_est = X_est.mean(axis=0)
    mean_true = X_true.mean(axis=0)
    U, _, Vt = np.linalg.svd((X_est - mean_est).T @ (X_true - mean_true))
    A = Vt.T @ U.T
    return RigidTransform(A, mean_true - A @ mean_est)


def _stacked_positions(obj: object) -> np.ndarray:
    return np.vstack([np.asarray(obj.receivers, dtype=float), np.asarray(obj.transmitters, dtype=float)])  # type: ignore[attr-defined]


def position_error(calibration: object, network: object) -> float:
    """Return the relative position error after the best rigid alignment.

    error = ||T(X_est) - X_true||_F / ||X_true - centroid(X_true)||_F, where X stacks the m
    receivers and n transmitters (one point per row) and T = align_rigid(X_est, X_true).

    Parameters
    ----------
    calibration : Calibration (or any object with receivers/transmitters arrays)
    network : synthetic.Network (or any object with receivers/transmitters arrays)

    Returns
    -------
    float (0 for an exact recovery up to a rigid motion).

    Reference: paper Sec. 4.1, Table 4 "Position error".
    """
    X_est = _stacked_positions(calibration)
    X_true = _stacked_positions(network)
    aligned = align_rigid(X_est, X_true).apply(X_est)
    spread = np.linalg.norm(X_true - X_true.mean(axis=0))
    return float(np.linalg.norm(aligned - X_true) / spread)


def offset_error(calibration: object, network: object) -> float:
    """Return the relative offset error ||o_est - o_true|| / ||o_true|| (Euclidean norms).

    Reference: paper Sec. 4.1, Table 4 "Offset error".
    """
    o_est = np.asarray(calibration.offsets, dtype=float)  # type: ignore[attr-defined]
    o_true = np.asarray(network.offsets, dtype=float)  # type: ignore[attr-defined]
    return float(np.linalg.norm(o_est - o_true) / np.linalg.norm(o_true))


def log10_error(error: float | np.ndarray, floor: float = LOG10_FLOOR) -> float | np.ndarray:
    """Return log10(max(error, floor)), elementwise; the scale of the paper's histograms.

    Parameters
    ----------
    error : float or array of non-negative relative errors
    floor : float
        Lower clamp so that exact (zero) errors give a finite value.

    Reference: paper Sec. 4.1, Fig. 1 and Table 4 (log10 relative errors).
    """
    result = np.log10(np.maximum(np.asarray(error, dtype=float), floor))
    return float(result) if np.ndim(result) == 0 else result


@dataclass(frozen=True)
class CalibrationErrors:
    """Relative position and offset errors of one calibration against ground truth."""

    position: float
    offset: float


def calibration_errors(calibration: object, network: object) -> CalibrationErrors:
    """Return both relative errors (see `position_error`, `offset_error`)."""
    return CalibrationErrors(position_error(calibration, network), offset_error(calibration, network))


def standardised_node_errors(result: object, network: object) -> np.ndarray:
    """|position error| / reported std of every placed node of a calibration result, in its gauge.

    The truth is moved into the result's gauge (`result.gauge`: the receiver at the origin, the one
    on the positive x axis, in 3D the one in the xy half-plane y > 0; the reflection the gauge leaves
    free is the one that fits better), so that the error and the reported std (the root of the sum
    of the coordinates' variances, `receiver_std`, `transmitter_std`) refer to the same coordinates. The gauge receiver at the origin (std 0) is left out. For a 2-D
    normal error, the share above 3 is between 1e-4 (isotropic) and 2.7e-3 (one-dimensional).
    """
    from .recovery import to_gauge

    gauge = getattr(result, "gauge", None)
    if gauge is None:
        return np.array([])
    m, dim = network.receivers.shape  # type: ignore[attr-defined]
    fixed = [int(g) for g in gauge]
    order = fixed + [i for i in range(m) if i not in fixed]
    moved = to_gauge(network.receivers[order], network.transmitters)  # type: ignore[attr-defined]
    if moved is None:
        return np.array([])
    truth_r = np.empty((m, dim))
    truth_r[order] = moved[0]
    truth = np.vstack([truth_r, moved[1]])
    est = np.vstack([result.receivers, result.transmitters])  # type: ignore[attr-defined]
    std = np.concatenate([result.receiver_std, result.transmitter_std])  # type: ignore[attr-defined]
    # the reflection the gauge leaves free: y -> -y in the plane, z -> -z in space
    errors = [np.linalg.norm(est - truth * np.r_[np.ones(dim - 1), flip], axis=1) for flip in (1.0, -1.0)]
    err = min(errors, key=lambda e: float(np.nansum(e)))
    keep = np.isfinite(err) & np.isfinite(std) & (std > 0)
    return err[keep] / std[keep]


def tdoa_jacobian(receivers: np.ndarray, transmitters: np.ndarray, measured_mask: np.ndarray) -> np.ndarray:
    """(k, K (m + n) + n) Jacobian of the measured f_ij = |r_i - s_j| + o_j (row-major over the
    mask's True entries) by (r_1, ..., r_m, s_1, ..., s_n, o_1, ..., o_n), without a gauge.

    d f_ij / d r_i = u_ij, d f_ij / d s_j = -u_ij, d f_ij / d o_j = 1, u_ij = (r_i - s_j) / |r_i - s_j|.
    """
    R = np.asarray(receivers, dtype=float)
    S = np.asarray(transmitters, dtype=float)
    (m, K), n = R.shape, S.shape[0]
    ii, jj = np.nonzero(np.asarray(measured_mask, dtype=bool))
    diff = R[ii] - S[jj]
    u = diff / np.linalg.norm(diff, axis=1)[:, None]
    rows = np.arange(len(ii))
    J = np.zeros((len(ii), K * (m + n) + n))
    for a in range(K):
        J[rows, K * ii + a] = u[:, a]
        J[rows, K * (m + jj) + a] = -u[:, a]
    J[rows, K * (m + n) + jj] = 1.0
    return J


def cramer_rao_position_rms(receivers: np.ndarray, transmitters: np.ndarray, measured_mask: np.ndarray,
                            sigma: float, *, rtol: float = 1e-9) -> float:
    """Cramer-Rao bound of the rms node position error after the best rigid alignment.

    The model is f_ij = |r_i - s_j| + o_j + e_ij on the entries where `measured_mask` is True, with
    independent e_ij ~ N(0, sigma^2); every position and offset is unknown. The Fisher information
    J^T J / sigma^2 (J: `tdoa_jacobian` at the given, true, positions) is singular exactly along the
    K (K + 1) / 2 rigid motions (K = 3: 3 translations, 3 rotations; they leave every |r_i - s_j| unchanged).
    Its pseudo-inverse is the covariance of an efficient estimator's error projected off those
    directions, which to first order is the error left after the best rigid alignment of the
    estimate onto the truth (solvers.metrics.align_rigid); the offsets are not moved by a rigid
    motion, so the position block of sigma^2 (J^T J)^+ is that covariance. Returns

        sqrt(trace(position block) / (m + n)),

    the bound on the expected rms position error over all m + n nodes (the figure a calibration's
    `rms_position_err_m` is compared with; a mean-square bound, so a single network's rms error may
    fall below it).

    Parameters
    ----------
    receivers : (m, K) true receiver positions, K = 2 or 3
    transmitters : (n, K) true transmitter positions
    measured_mask : (m, n) bool, True where f_ij is measured (and used: the inliers)
    sigma : standard deviation of the measurement noise (units of the positions), > 0
    rtol : singular values of J below rtol * the largest count as zero

    Returns
    -------
    float; inf when the measured entries leave more than the rigid motions undetermined (a node
    with too few entries, a degenerate configuration): no estimator can place every node.

    Reference: Cramer-Rao bound with a singular Fisher information (the constrained / gauge-free
    bound is the pseudo-inverse, Xavier & Barroso; Stoica & Ng, IEEE SPL 1998); TDOA model of the
    paper, Sec. 1 eq. (2).
    """
    R = np.asarray(receivers, dtype=float)
    S = np.asarray(transmitters, dtype=float)
    mask = np.asarray(measured_mask, dtype=bool)
    (m, K), n = R.shape, S.shape[0]
    if S.shape != (n, K) or mask.shape != (m, n):
        raise ValueError(f"shapes do not match: receivers {R.shape}, transmitters {S.shape}, mask {mask.shape}")
    if not (sigma > 0 and np.isfinite(sigma)):
        raise ValueError(f"sigma must be a finite number > 0, got {sigma}")
    J = tdoa_jacobian(R, S, mask)
    n_rigid = K * (K + 1) // 2
    if J.shape[0] < J.shape[1] - n_rigid:
        return float("inf")
    _, s, Vt = np.linalg.svd(J, full_matrices=False)
    rank = int(np.sum(s > rtol * s[0])) if len(s) else 0
    if rank < J.shape[1] - n_rigid:
        return float("inf")
    V = Vt[:rank].T[: K * (m + n)]  # the position rows of the range directions
    return float(sigma * np.sqrt(np.sum((V / s[:rank]) ** 2) / (m + n)))


def receiver_cramer_rao_rms(receivers: np.ndarray, transmitters: np.ndarray, measured_mask: np.ndarray,
                            sigma: float) -> float:
    """Cramer-Rao bound of the receivers' rms position error after a rigid alignment of the receivers.

    The sources are nuisance parameters: each source block (position, offset) is eliminated by its Schur
    complement, leaving the receivers' Fisher information (K m)^2, singular along the rigid motions;
    its pseudo-inverse's trace / m, square-rooted (`cramer_rao_position_rms` restricted to the receivers,
    without forming the whole Jacobian: 48 x 540 in 3D would be 25,920 x 2,304).
    """
    R = np.asarray(receivers, dtype=float)
    S = np.asarray(transmitters, dtype=float)
    mask = np.asarray(measured_mask, dtype=bool)
    m, dim = R.shape
    info = np.zeros((m * dim, m * dim))
    for j in range(S.shape[0]):
        rows = np.flatnonzero(mask[:, j])
        d = R[rows] - S[j]
        u = d / np.linalg.norm(d, axis=1)[:, None]
        Jr = np.zeros((len(rows), m * dim))
        for a in range(dim):
            Jr[np.arange(len(rows)), dim * rows + a] = u[:, a]
        Js = np.column_stack([-u, np.ones(len(rows))])
        C = Js.T @ Js
        B = Jr.T @ Js
        info += Jr.T @ Jr - B @ np.linalg.solve(C, B.T)
    cov = np.linalg.pinv(info / sigma**2, rcond=1e-9, hermitian=True)
    return float(np.sqrt(np.trace(cov) / m))
