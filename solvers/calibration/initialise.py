"""Stage 2, initialise: where the adjustment starts, by the route the diagnosis chose.

Plane waves (`Diagnosis.wavefront == "plane"`): the metric-upgraded factorization gives the receivers and
the source directions; each source's range comes from the wavefront's curvature left in its column (the
second-order term of |r - s| in 1 / range), a source whose curvature is not measurable is put at
FAR_RANGES x the array's extent along its direction (the adjustment then finds its range, or reports it
as weakly determined); the offsets follow. Otherwise the hypothesis search over the minimal solvers
(`ransac` over `sampling`), run by the driver.

Reference: Thrun (2005), Kuang and Astrom (2013), see `factorization`.
"""
from __future__ import annotations

import numpy as np

from .diagnose import WEAK_SPAN_DEGREES
from .factorization import LowRank, metric_upgrade
from .state import Diagnosis, Start

#: A source whose range the curvature does not give starts this many array extents away.
FAR_RANGES = 50.0


def _level_upgrade(low: LowRank):
    """The upgrade when the directions hardly leave one plane (one elevation cone): their elevation, and with
    it the receivers' height, is not in the plane waves (the unit norm no longer fixes the metric: a cone
    at any elevation fits), so the start is level: the directions' varying part (the top two principal
    axes of the factorization's product) upgraded as unit directions in that plane, the receivers in it, height 0.
    The adjustment then finds what the curvature says of the height; the judge reports how weakly."""
    # the varying part A (B - mean B)^T (the mean is the per-receiver height term), its top two singular
    # directions: those of the data, not of B alone (the factorization leaves A and B unbalanced)
    Bc = low.B - low.B.mean(axis=0)[None, :]
    U2, s2, Vt2 = np.linalg.svd(low.A @ Bc.T, full_matrices=False)
    flat = LowRank(low.o, U2[:, :2] * s2[:2], Vt2[:2].T, low.scale, low.inliers, s2[:2])
    up = metric_upgrade(flat)
    pad = np.zeros((len(up.receivers), 1))
    return type(up)(np.hstack([up.receivers, pad]), np.hstack([up.directions, np.zeros((len(up.directions), 1))]),
                    up.offsets, up.conditioning, up.misfit)


def plane_wave_start(F: np.ndarray, work: np.ndarray, diagnosis: Diagnosis) -> Start:
    """The start of the adjustment from the plane-wave factorization (diagnosis.upgrade; level, see
    `_level_upgrade`, when the sources span under WEAK_SPAN_DEGREES of elevation).

    Positions are those of the factorization (receivers centred at 0); sources at c + D_j u_j with
    1 / D_j the least-squares slope of F_ij - o'_j + u_j . r_i against (|r_i|^2 - (u_j . r_i)^2) / 2
    over the factorization's inliers of column j, where that slope is positive and at least twice its
    standard error; offsets the median of F_ij - |r_i - s_j| over those inliers.
    """
    up, low = diagnosis.upgrade, diagnosis.low_rank
    if low.A.shape[1] == 3 and diagnosis.elevation_span < WEAK_SPAN_DEGREES:
        up = _level_upgrade(low)
    R, U = up.receivers, up.directions
    inl = work & low.inliers
    extent = float(np.sqrt(np.mean(np.sum(R**2, axis=1))))
    proj = R @ U.T                                   # (m, n) u_j . r_i
    q = 0.5 * (np.sum(R**2, axis=1)[:, None] - proj**2)  # curvature term per unit 1 / range
    y = np.where(inl, F + proj, 0.0)                 # F_ij + u_j . r_i = o'_j + q_ij / D_j
    w = inl.astype(float)
    cnt = w.sum(axis=0)
    qm = (w * q).sum(axis=0) / np.maximum(cnt, 1)
    ym = (w * y).sum(axis=0) / np.maximum(cnt, 1)
    qc = np.where(inl, q - qm[None, :], 0.0)
    sxx = (qc**2).sum(axis=0)
    slope = np.where(sxx > 0, (qc * np.where(inl, y - ym[None, :], 0.0)).sum(axis=0) / np.where(sxx > 0, sxx, 1.0), 0.0)
    resid = np.where(inl, y - ym[None, :] - slope[None, :] * qc, 0.0)
    s2 = (resid**2).sum(axis=0) / np.maximum(cnt - 2, 1)
    se = np.sqrt(s2 / np.where(sxx > 0, sxx, np.inf))
    measurable = (slope > 2.0 * se) & (slope > 0)
    far = FAR_RANGES * max(extent, 1e-12)
    D = np.where(measurable, 1.0 / np.where(measurable, slope, 1.0), far)
    D = np.minimum(D, far)
    S = U * D[:, None]
    dist = np.linalg.norm(R[:, None, :] - S[None, :, :], axis=2)
    O = np.array([np.median((F - dist)[inl[:, j], j]) if inl[:, j].any() else np.nan for j in range(F.shape[1])])
    note = (f"started from the plane-wave factorization (no hypothesis search): the receivers and the source "
            f"directions from its metric upgrade, {int(measurable.sum())} of {F.shape[1]} source ranges from the "
            f"wavefront's curvature, the others {FAR_RANGES:g} array extents away")
    return Start(R.copy(), S, O, "factorization", (note,))
