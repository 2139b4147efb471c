"""Levenberg-Marquardt refinement of a TDOA calibration on all measurements.

This module owns the non-linear least-squares step of the paper's pipeline: the parameter vector in
the gauge r_1 = 0, r_2 = (r_2x, 0), the residuals e_ij = F_ij - o_j - ||r_i - s_j||, their analytic
Jacobian (kept apart from the loop and tested against finite differences), the driver around
scipy.optimize.least_squares, and the random initialisation used as the paper's baseline.

Parameter layout (size 2m + 3n - 3, the number of degrees of freedom of 2D TDOA):
    [r_2x, r_3x, r_3y, ..., r_mx, r_my, s_1x, s_1y, ..., s_nx, s_ny, o_1, ..., o_n].
In 3D (gauge r_1 = 0, r_2 = (r_2x, 0, 0), r_3 = (r_3x, r_3y, 0); size 3m + 4n - 6):
    [r_2x, r_3x, r_3y, r_4x, r_4y, r_4z, ..., s_1x, s_1y, s_1z, ..., o_1, ..., o_n].
Residuals are flattened row-major: index i * n + j.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.optimize import least_squares

from solvers.recovery import Calibration, rms_residual, to_gauge

__all__ = [
    "LM_METHODS",
    "RefineResult",
    "jacobian",
    "pack",
    "random_initial",
    "refine",
    "residuals",
    "unpack",
]

Method = Literal["lm", "trf", "dogbox"]
LM_METHODS = ("lm", "trf", "dogbox")


@dataclass(frozen=True, eq=False)
class RefineResult:
    """Outcome of `refine`.

    Parameters
    ----------
    calibration : Calibration
        Refined network in the gauge r_1 = 0, r_2 = (r_2x, 0); r_2x > 0 unless LM moved r_2
        through r_1.
    success : bool
        scipy's convergence flag (a tolerance was met, not the evaluation budget).
    iterations : int
        Number of Jacobian evaluations (one per accepted iteration: MINPACK's lmder, scipy's "trf").
    nfev : int
        Number of residual evaluations.
    status : int
        scipy.optimize.least_squares status code.
    message : str
        scipy's termination message.
    initial_residual : float
        RMS residual of the initial calibration (for convergence reports).
    """

    calibration: Calibration
    success: bool
    iterations: int
    nfev: int
    status: int
    message: str
    initial_residual: float


def parameter_count(m: int, n: int, dim: int = 2) -> int:
    """Return 2m + 3n - 3 (3D: 3m + 4n - 6), the length of the parameter vector (paper Sec. 1, DoF of TDOA)."""
    return 2 * m + 3 * n - 3 if dim == 2 else 3 * m + 4 * n - 6


def _free_receiver_coordinates(m: int, dim: int) -> list[int]:
    """Indices into receivers.ravel() of the coordinates the gauge leaves free (r_2x; 3D also r_3x, r_3y)."""
    return [i * dim + a for i in range(1, m) for a in range(min(i, dim))]


def pack(receivers: np.ndarray, transmitters: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Return the parameter vector of a calibration already in the gauge (r_1 = 0, r_2y = 0; 3D also
    r_2z = r_3z = 0).

    The gauge-fixed coordinates (r_1x, r_1y, r_2y in 2D) are dropped; they are not checked here.
    """
    m, dim = receivers.shape
    free = receivers.ravel()[_free_receiver_coordinates(m, dim)]
    return np.concatenate([free, transmitters.ravel(), offsets]).astype(float)


def unpack(params: np.ndarray, m: int, n: int, dim: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (receivers (m, dim), transmitters (n, dim), offsets (n,)) from a parameter vector."""
    params = np.asarray(params, dtype=float)
    if params.shape != (parameter_count(m, n, dim),):
        raise ValueError(
            f"params must have length {'2m + 3n - 3' if dim == 2 else '3m + 4n - 6'} = "
            f"{parameter_count(m, n, dim)}, got {params.shape}"
        )
    free = _free_receiver_coordinates(m, dim)
    receivers = np.zeros(m * dim)
    receivers[free] = params[: len(free)]
    receivers = receivers.reshape(m, dim)
    k = len(free)
    transmitters = params[k : k + dim * n].reshape(n, dim)
    offsets = params[k + dim * n :]
    return receivers, transmitters, offsets


def _shape(F: np.ndarray) -> tuple[int, int]:
    if F.ndim != 2 or F.shape[0] < 2 or F.shape[1] < 1:
        raise ValueError(f"F must be an (m, n) array with m >= 2, got shape {F.shape}")
    return F.shape


def residuals(params: np.ndarray, F: np.ndarray, dim: int = 2) -> np.ndarray:
    """Return the m*n residuals e_ij = F_ij - o_j - ||r_i - s_j|| (row-major, index i*n + j).

    Parameters
    ----------
    params : (2m + 3n - 3,) parameter vector (3D: 3m + 4n - 6; see module docstring)
    F : (m, n) measurements
    dim : 2 or 3

    Reference: paper Sec. 1 eq. (2), Sec. 3.1 step 4.
    """
    F = np.asarray(F, dtype=float)
    m, n = _shape(F)
    receivers, transmitters, offsets = unpack(params, m, n, dim)
    diff = receivers[:, None, :] - transmitters[None, :, :]
    dist = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
    return (F - offsets[None, :] - dist).ravel()


def jacobian(params: np.ndarray, F: np.ndarray, dim: int = 2) -> np.ndarray:
    """Return the analytic (m*n, 2m + 3n - 3) Jacobian of `residuals` (3D: (m*n, 3m + 4n - 6)).

    With u_ij = (r_i - s_j) / ||r_i - s_j||: de_ij/dr_i = -u_ij, de_ij/ds_j = +u_ij,
    de_ij/do_j = -1; columns of the gauge-fixed coordinates (r_1x, r_1y, r_2y in 2D) are dropped.
    Where r_i = s_j the distance is not differentiable and u_ij is set to 0. Dense; each row has at
    most 2 dim + 1 non-zeros.

    Parameters
    ----------
    params : parameter vector
    F : (m, n) measurements (only its shape is used)
    dim : 2 or 3

    Reference: paper Sec. 3.1 step 4 (Levenberg-Marquardt).
    """
    F = np.asarray(F)
    m, n = _shape(F)
    receivers, transmitters, _ = unpack(params, m, n, dim)
    diff = receivers[:, None, :] - transmitters[None, :, :]
    dist = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
    safe = np.where(dist > 0.0, dist, 1.0)
    u = np.where((dist > 0.0)[:, :, None], diff / safe[:, :, None], 0.0)  # (m, n, dim)

    rows_m, rows_n = np.arange(m), np.arange(n)
    J_r = np.zeros((m, n, m, dim))
    J_r[rows_m, :, rows_m, :] = -u
    J_s = np.zeros((m, n, n, dim))
    J_s[:, rows_n, rows_n, :] = u
    J_o = np.zeros((m, n, n))
    J_o[:, rows_n, rows_n] = -1.0

    J_r = J_r.reshape(m * n, dim * m)[:, _free_receiver_coordinates(m, dim)]  # drop the gauge-fixed ones
    return np.hstack([J_r, J_s.reshape(m * n, dim * n), J_o.reshape(m * n, n)])


def _initial_arrays(initial: object) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Accept a Calibration-like object (receivers/transmitters/offsets) or a 3-tuple."""
    if all(hasattr(initial, name) for name in ("receivers", "transmitters", "offsets")):
        arrays = (initial.receivers, initial.transmitters, initial.offsets)  # type: ignore[attr-defined]
    else:
        try:
            arrays = tuple(initial)  # type: ignore[arg-type]
        except TypeError:
            arrays = ()
        if len(arrays) != 3:
            raise TypeError(
                "initial must be a Calibration or a tuple (receivers, transmitters, offsets)"
            )
    receivers, transmitters, offsets = (np.array(a, dtype=float) for a in arrays)
    return receivers, transmitters, offsets


def refine(
    initial: Calibration | tuple[np.ndarray, np.ndarray, np.ndarray],
    F: np.ndarray,
    *,
    max_iter: int = 200,
    method: Method = "lm",
    tol: float = 1e-12,
) -> RefineResult:
    """Minimise sum_ij (F_ij - o_j - ||r_i - s_j||)^2 starting from `initial`.

    The initial positions are first moved into the gauge r_1 = 0, r_2 = (r_2x, 0) (3D: also
    r_3 = (r_3x, r_3y, 0); translation and rotation; if the rotation is undefined only the
    translation is applied). Offsets are unaffected by the gauge. The dimension (2 or 3) is that
    of the initial positions.

    Parameters
    ----------
    initial : Calibration or (receivers (m, K), transmitters (n, K), offsets (n,)), K = 2 or 3
    F : (m, n) measurements
    max_iter : int
        Budget of residual evaluations (scipy's max_nfev); it bounds the number of iterations.
    method : "lm" | "trf" | "dogbox"
        scipy.optimize.least_squares method; "lm" (MINPACK Levenberg-Marquardt, the paper's
        choice) needs m*n >= 2m + 3n - 3 (3D: 3m + 4n - 6), i.e. not an underdetermined configuration.
        "trf" without bounds is the same Levenberg-Marquardt trust-region iteration (Moré's LM
        parameter, here from an SVD of J instead of MINPACK's pivoted QR) in numpy and LAPACK. From a
        start that diverges, MINPACK's end point can depend on what the process's freed memory held;
        "trf"'s cannot (docs/reproducibility.md, section 4), so the experiments use it.
    tol : float
        ftol = xtol = gtol passed to scipy.

    Returns
    -------
    RefineResult

    Raises
    ------
    ValueError
        For inconsistent shapes, non-finite initial values, an unknown method, or "lm" on an
        underdetermined configuration.

    Reference: paper Sec. 3.1 step 4 and Sec. 4 (LM from the solver vs from random values).
    """
    if method not in LM_METHODS:
        raise ValueError(f"method must be one of {LM_METHODS}, got {method!r}")
    F = np.asarray(F, dtype=float)
    m, n = _shape(F)
    receivers, transmitters, offsets = _initial_arrays(initial)
    dim = receivers.shape[1] if receivers.ndim == 2 and receivers.shape[1] in (2, 3) else 2
    if receivers.shape != (m, dim) or transmitters.shape != (n, dim) or offsets.shape != (n,):
        raise ValueError(
            f"initial shapes {receivers.shape}, {transmitters.shape}, {offsets.shape} do not "
            f"match F of shape {F.shape}"
        )
    if not all(np.all(np.isfinite(a)) for a in (receivers, transmitters, offsets, F)):
        raise ValueError("initial calibration and F must be finite")
    if method == "lm" and m * n < parameter_count(m, n, dim):
        raise ValueError(
            f"method 'lm' needs at least as many measurements ({m * n}) as parameters "
            f"({parameter_count(m, n, dim)}); use 'trf' for underdetermined configurations"
        )

    gauged = to_gauge(receivers, transmitters)
    if gauged is None:
        receivers, transmitters = receivers - receivers[0], transmitters - receivers[0]
    else:
        receivers, transmitters = gauged
    x0 = pack(receivers, transmitters, offsets)
    initial_residual = rms_residual(F, receivers, transmitters, offsets)

    solution = least_squares(
        residuals,
        x0,
        jac=jacobian,
        args=(F, dim),
        method=method,
        max_nfev=max_iter,
        ftol=tol,
        xtol=tol,
        gtol=tol,
    )
    receivers, transmitters, offsets = unpack(solution.x, m, n, dim)
    calibration = Calibration(
        receivers, transmitters, offsets, rms_residual(F, receivers, transmitters, offsets)
    )
    return RefineResult(
        calibration=calibration,
        success=bool(solution.success),
        iterations=int(solution.njev) if solution.njev is not None else int(solution.nfev),
        nfev=int(solution.nfev),
        status=int(solution.status),
        message=str(solution.message),
        initial_residual=initial_residual,
    )


def random_initial(
    m: int,
    n: int,
    rng: np.random.Generator,
    position_sigma: float = 10.0,
    offset_sigma: float = 1.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Draw a random starting point from the ground-truth distributions (the paper's baseline).

    Parameters
    ----------
    m, n : int
    rng : numpy.random.Generator (explicitly seeded); draws receivers, transmitters, offsets
    position_sigma, offset_sigma : float
        Standard deviations of the zero-mean normal coordinates and offsets (paper: 10 and 1).

    Returns
    -------
    (receivers (m, 2), transmitters (n, 2), offsets (n,)), accepted by `refine`.

    Reference: paper Sec. 4.1 ("rand" rows of Table 4).
    """
    receivers = position_sigma * rng.standard_normal((m, 2))
    transmitters = position_sigma * rng.standard_normal((n, 2))
    offsets = offset_sigma * rng.standard_normal(n)
    return receivers, transmitters, offsets
