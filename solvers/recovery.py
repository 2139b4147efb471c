"""From candidate roots (H, b, o) of the algebraic formulation to positions and offsets.

This module owns the "upgrade" step of the paper: given a (possibly complex) root of the polynomial
system, it rejects non-real and non positive-definite candidates, builds the compaction matrix
with the candidate offsets, recovers all receivers and the first three transmitters from the
parametrisation, trilaterates the remaining transmitters, fixes the paper's gauge and scores the
result by its RMS measurement residual. It also owns `Calibration`, the numeric result shared with
`solvers.refine` and `solvers.metrics`, and the gauge/residual helpers they use.

Conventions (paper Sec. 2-3): F[i, j] = ||r_i - s_j|| + o_j; gauge r_1 = 0, r_2 = (r_2x, 0) with
r_2x > 0; the remaining reflection ambiguity is left as recovered (metrics align it away). The same
steps recover a 3D network (K = 3: H 3 x 3, b in R^3, gauge r_1 = 0, r_2 = (r_2x > 0, 0, 0),
r_3 = (r_3x, r_3y > 0, 0)).
Only numpy is used; degenerate inputs give None, never numpy.linalg.LinAlgError.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Calibration",
    "compaction_matrix",
    "measurement_residuals",
    "rank_candidates",
    "recover",
    "rms_residual",
    "to_gauge",
]

#: Relative singular-value threshold below which a geometric matrix is treated as singular.
RANK_TOL = 1e-10


@dataclass(frozen=True, eq=False)
class Calibration:
    """Recovered network: positions, offsets and the RMS measurement residual.

    Parameters
    ----------
    receivers : (m, K) array, K = 2 or 3
    transmitters : (n, K) array
    offsets : (n,) array
    residual : float
        RMS over all m*n measurements of F_ij - o_j - ||r_i - s_j||.

    Reference: paper Sec. 3 (recovered r_i, s_j, o_j).
    """

    receivers: np.ndarray
    transmitters: np.ndarray
    offsets: np.ndarray
    residual: float

    @property
    def m(self) -> int:
        """Number of receivers."""
        return self.receivers.shape[0]

    @property
    def n(self) -> int:
        """Number of transmitters."""
        return self.transmitters.shape[0]


def measurement_residuals(
    F: np.ndarray, receivers: np.ndarray, transmitters: np.ndarray, offsets: np.ndarray
) -> np.ndarray:
    """Return the (m, n) residuals e_ij = F_ij - o_j - ||r_i - s_j||.

    Reference: paper Sec. 1 eq. (2); the cost minimised in Sec. 3.1 step 4.
    """
    diff = receivers[:, None, :] - transmitters[None, :, :]
    return F - offsets[None, :] - np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))


def rms_residual(
    F: np.ndarray, receivers: np.ndarray, transmitters: np.ndarray, offsets: np.ndarray
) -> float:
    """Return the RMS of `measurement_residuals` over all m*n measurements."""
    e = measurement_residuals(F, receivers, transmitters, offsets)
    return float(np.sqrt(np.mean(e * e)))


def to_gauge(
    receivers: np.ndarray, transmitters: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Move positions into the paper's gauge r_1 = 0, r_2 = (r_2x, 0) with r_2x > 0 (3D: r_1 = 0,
    r_2 = (r_2x > 0, 0, 0), r_3 = (r_3x, r_3y > 0, 0)).

    A translation by -r_1 and a rotation (never a reflection) are applied to all nodes.

    Parameters
    ----------
    receivers : (m, K) array, m >= K
    transmitters : (n, K) array

    Returns
    -------
    (receivers, transmitters) in the gauge, or None if r_2 coincides with r_1 (3D: or r_1, r_2, r_3 are
    collinear; the rotation is then undefined).

    Reference: paper Sec. 3 (gauge freedom).
    """
    if receivers.shape[1] == 3:
        return _to_gauge_3d(receivers, transmitters)
    r1 = receivers[0]
    rec = receivers - r1
    tra = transmitters - r1
    r2 = rec[1]
    norm = float(np.hypot(r2[0], r2[1]))
    scale = max(float(np.max(np.abs(rec))), float(np.max(np.abs(tra), initial=0.0)), 1e-300)
    if not norm > RANK_TOL * scale:
        return None
    c, s = r2 / norm
    rotation = np.array([[c, s], [-s, c]])  # rotation * r2 = (norm, 0)
    rec = rec @ rotation.T
    tra = tra @ rotation.T
    rec[0] = 0.0
    rec[1, 1] = 0.0
    return rec, tra


def _to_gauge_3d(receivers: np.ndarray, transmitters: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`to_gauge` in 3D: the rotation is Q^T of the QR factorisation of [r_2 - r_1, r_3 - r_1], with
    the signs of Q's columns chosen so that r_2x, r_3y > 0 and det Q = +1."""
    rec = receivers - receivers[0]
    tra = transmitters - receivers[0]
    scale = max(float(np.max(np.abs(rec))), float(np.max(np.abs(tra), initial=0.0)), 1e-300)
    q, r = np.linalg.qr(rec[1:3].T, mode="complete")
    if not (abs(r[0, 0]) > RANK_TOL * scale and abs(r[1, 1]) > RANK_TOL * scale):
        return None
    signs = np.sign(np.array([r[0, 0], r[1, 1], 1.0]))
    q = q * signs[None, :]
    if np.linalg.det(q) < 0:
        q[:, 2] = -q[:, 2]
    rec, tra = rec @ q, tra @ q
    rec[0] = 0.0
    rec[1, 1:] = 0.0
    rec[2, 2] = 0.0
    return rec, tra


def compaction_matrix(F: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Return the (m-1, n-1) compaction matrix D~ built with d_ij^2 = (F_ij - o_j)^2.

    D~[i-1, j-1] = d^2_{i,j} - d^2_{0,j} - d^2_{i,0} + d^2_{0,0} (0-based rows/cols of F), which
    equals -2 (r_i - r_0)^T (s_j - s_0) for the true offsets.

    Reference: paper Sec. 2.1 eq. (3)-(4) (with the typo d_{i+1,j} read as d_{i+1,1}).
    """
    d2 = (F - offsets[None, :]) ** 2
    return d2[1:, 1:] - d2[:1, 1:] - d2[1:, :1] + d2[0, 0]


def _real_part(value: np.ndarray, tol: float) -> np.ndarray | None:
    """Return Re(value) if max|Im(value)| <= tol * max|value|, else None (also for non-finite)."""
    value = np.asarray(value)
    if not np.all(np.isfinite(value)):
        return None
    if np.iscomplexobj(value):
        if np.max(np.abs(value.imag)) > tol * np.max(np.abs(value)):
            return None
        value = value.real
    return np.asarray(value, dtype=float)


def _as_symmetric(H: np.ndarray) -> np.ndarray:
    """Accept H as a (2, 2) or (3, 3) matrix or as its upper triangle, (h11, h12, h22) or
    (h11, h12, h13, h22, h23, h33); return the square form."""
    if H.shape == (3,):
        return np.array([[H[0], H[1]], [H[1], H[2]]])
    if H.shape == (6,):
        return np.array([[H[0], H[1], H[2]], [H[1], H[3], H[4]], [H[2], H[4], H[5]]])
    if H.shape not in ((2, 2), (3, 3)):
        raise ValueError(f"H must have shape (2, 2), (3, 3) or be its upper triangle (3,) or (6,), got {H.shape}")
    return 0.5 * (H + H.T)


def _trilaterate(
    receivers: np.ndarray, ranges: np.ndarray, gauss_newton_steps: int
) -> np.ndarray | None:
    """Least-squares position s with ||r_i - s|| ~ ranges[i], receivers[0] = 0.

    Subtracting receiver 1's squared equation gives the linear system
    2 r_i^T s = ||r_i||^2 - d_i^2 + d_1^2 (i = 2..m), solved by least squares; a few guarded
    Gauss-Newton steps on sum_i (||r_i - s|| - d_i)^2 then make the estimate consistent with the
    residual that ranks candidates (this only matters with noise).

    Parameters
    ----------
    receivers : (m, K) array with receivers[0] = 0 and rank-K receivers[1:] (checked by caller)
    ranges : (m,) array of d_i = F_ij - o_j

    Returns
    -------
    (K,) array, or None if the linear system is singular.

    Reference: paper Sec. 3.2 (last transmitter by trilateration).
    """
    A = 2.0 * receivers[1:]
    rhs = np.einsum("ij,ij->i", receivers[1:], receivers[1:]) - ranges[1:] ** 2 + ranges[0] ** 2
    k = receivers.shape[1]
    s, _, rank, _ = np.linalg.lstsq(A, rhs, rcond=RANK_TOL)
    if rank < k or not np.all(np.isfinite(s)):
        return None

    def cost(point: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        diff = point[None, :] - receivers
        dist = np.sqrt(np.einsum("ij,ij->i", diff, diff))
        return float(np.sum((dist - ranges) ** 2)), diff, dist

    current, diff, dist = cost(s)
    for _ in range(gauss_newton_steps):
        if np.any(dist == 0.0):
            break
        J = diff / dist[:, None]
        step, _, rank, _ = np.linalg.lstsq(J, ranges - dist, rcond=RANK_TOL)
        if rank < k:
            break
        candidate = s + step
        new, new_diff, new_dist = cost(candidate)
        if not new < current:
            break
        s, current, diff, dist = candidate, new, new_diff, new_dist
    return s


def recover(
    F: np.ndarray,
    H: np.ndarray,
    b: np.ndarray,
    o: np.ndarray,
    *,
    tol: float = 1e-6,
    gauss_newton_steps: int = 3,
) -> Calibration | None:
    """Turn one candidate root (H, b, o) into receivers, transmitters and offsets.

    Steps: reject non-real candidates and non positive-definite H; L = Cholesky factor with
    L^T L = H^{-1} (L upper triangular, one representative of the rotation/reflection gauge);
    compaction matrix D~ with the candidate offsets, R~ = D~[:, :K]^T, S~ = I;
    r_1 = 0, r_i = L^{-T} R~[:, i-2] (i = 2..m), s_1 = L b, s_j = L(b - e_{j-1}/2) (j = 2..K+1);
    transmitters j >= K + 2 by trilateration; finally rotate into the gauge r_2 = (r_2x > 0, 0)
    (3D: also r_3 = (r_3x, r_3y > 0, 0)). K = 2 or 3 is H's size.

    Parameters
    ----------
    F : (m, n) array
        All measurements f_ij = ||r_i - s_j|| + o_j, m >= K + 1, n >= K + 1.
    H : (K, K) array or its upper triangle, (h11, h12, h22) or (h11, h12, h13, h22, h23, h33);
        possibly complex
    b : (K,) array, possibly complex
    o : (n,) array, possibly complex, candidate offsets of all transmitters
    tol : float
        A group (H, b or o) is non-real if its largest imaginary magnitude exceeds tol times its
        largest entry magnitude.
    gauss_newton_steps : int
        Gauss-Newton iterations after the linear trilateration (0 disables them).

    Returns
    -------
    Calibration, or None for a non-real / non positive-definite candidate or a degenerate
    configuration (collinear receivers (3D: coplanar), r_2 = r_1, singular matrices, non-finite values).

    Raises
    ------
    ValueError
        Only for inconsistent shapes (a usage error, not a degenerate candidate).

    Reference: paper Sec. 2.1 eq. (5), Sec. 3.1 eq. (6), Sec. 3.2 (trilateration).
    """
    F = np.asarray(F, dtype=float)
    H_arr, b_arr, o_arr = np.asarray(H), np.asarray(b), np.asarray(o)
    H_arr = _as_symmetric(H_arr)
    k = H_arr.shape[0]
    if F.ndim != 2 or F.shape[0] < k + 1 or F.shape[1] < k + 1:
        raise ValueError(f"F must be an (m, n) array with m >= {k + 1}, n >= {k + 1} for a {k}D root, got shape {F.shape}")
    m, n = F.shape
    if b_arr.shape != (k,) or o_arr.shape != (n,):
        raise ValueError(f"b must have shape ({k},) and o shape ({n},), got {b_arr.shape}, {o_arr.shape}")
    if not np.all(np.isfinite(F)):
        return None
    # Spurious solver roots may be huge; overflow just makes them fail the finiteness checks.
    with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
        return _recover_candidate(F, H_arr, b_arr, o_arr, tol, gauss_newton_steps)


def _recover_candidate(
    F: np.ndarray, H: np.ndarray, b: np.ndarray, o: np.ndarray, tol: float, gauss_newton_steps: int
) -> Calibration | None:
    """`recover` after shape checks: reality test, then the real recovery."""
    H_real, b_real, o_real = (_real_part(v, tol) for v in (H, b, o))
    if H_real is None or b_real is None or o_real is None:
        return None
    try:
        return _recover_real(F, H_real, b_real, o_real, gauss_newton_steps)
    except np.linalg.LinAlgError:  # belt and braces: the checks below should pre-empt it
        return None


def _recover_real(
    F: np.ndarray, H: np.ndarray, b: np.ndarray, o: np.ndarray, gauss_newton_steps: int
) -> Calibration | None:
    """`recover` for a real candidate; see there. May return None for degenerate input."""
    m, n = F.shape
    k = H.shape[0]
    eigenvalues = np.linalg.eigvalsh(H)
    if not (eigenvalues[0] > 0.0 and eigenvalues[0] > RANK_TOL * eigenvalues[-1]):
        return None
    if k == 2:
        # (2x2) inverse in closed form: cannot raise, and is exact enough for a PD matrix.
        det = H[0, 0] * H[1, 1] - H[0, 1] ** 2
        H_inv = np.array([[H[1, 1], -H[0, 1]], [-H[0, 1], H[0, 0]]]) / det
    else:
        H_inv = np.linalg.inv(H)  # well conditioned: eigenvalues checked above
        H_inv = 0.5 * (H_inv + H_inv.T)
    try:
        L = np.linalg.cholesky(H_inv).T  # upper triangular, L^T L = H^{-1}
    except np.linalg.LinAlgError:
        return None

    D = compaction_matrix(F, o)
    R_tilde = D[:, :k].T  # (K, m-1)
    receivers = np.zeros((m, k))
    receivers[1:] = np.linalg.solve(L.T, R_tilde).T

    singular_values = np.linalg.svd(receivers[1:], compute_uv=False)
    if not (np.all(np.isfinite(singular_values)) and singular_values[k - 1] > RANK_TOL * singular_values[0]):
        return None  # collinear (3D: coplanar) receivers: transmitters not identifiable (reflections)

    transmitters = np.empty((n, k))
    S_tilde = np.hstack([np.zeros((k, 1)), np.eye(k)])  # columns 0, e_1, ..., e_K
    transmitters[: k + 1] = (L @ (b[:, None] - 0.5 * S_tilde)).T
    for j in range(k + 1, n):
        s = _trilaterate(receivers, F[:, j] - o[j], gauss_newton_steps)
        if s is None:
            return None
        transmitters[j] = s

    gauged = to_gauge(receivers, transmitters)
    if gauged is None:
        return None
    receivers, transmitters = gauged
    if not (np.all(np.isfinite(receivers)) and np.all(np.isfinite(transmitters))):
        return None
    residual = rms_residual(F, receivers, transmitters, o)
    if not np.isfinite(residual):
        return None
    return Calibration(receivers, transmitters, o.copy(), residual)


def rank_candidates(
    F: np.ndarray,
    roots: Iterable[tuple[np.ndarray, np.ndarray, np.ndarray]],
    *,
    tol: float = 1e-6,
    gauss_newton_steps: int = 3,
) -> list[Calibration]:
    """Recover every candidate root and sort the valid calibrations by RMS residual.

    Parameters
    ----------
    F : (m, n) array of measurements
    roots : iterable of (H, b, o) candidate roots (possibly complex), e.g. a solver's output
    tol, gauss_newton_steps : passed to `recover`

    Returns
    -------
    list of Calibration, best (smallest residual) first; empty if no candidate is valid.

    Reference: paper Sec. 3.1 (select the solution before refinement).
    """
    calibrations = []
    for H, b, o in roots:
        calibration = recover(F, H, b, o, tol=tol, gauss_newton_steps=gauss_newton_steps)
        if calibration is not None:
            calibrations.append(calibration)
    calibrations.sort(key=lambda c: c.residual)
    return calibrations
