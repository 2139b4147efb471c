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
    "log10_error",
    "offset_error",
    "position_error",
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
