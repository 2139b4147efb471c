"""Stage 3 for plane waves: robust adjustment with every source as a direction and an inverse range.

A source far from a compact array is parametrised by its unit direction u_j (seen from the origin, the
array's centre), its inverse range rho_j = 1 / |s_j| and the arrival time at the origin o_j:

    F_ij = o_j + h(r_i; u_j, rho_j),   h = (|r_i - s_j| - |s_j|) = (rho |r|^2 - 2 u . r) / (1 + g),
    g = sqrt(1 - 2 rho u . r + rho^2 |r|^2) = rho |r_i - s_j|,

smooth through rho = 0, where h = -u . r (a plane wave): a source whose range the data cannot fix stays a
direction (rho near 0, its interval in rho reported) instead of drifting outward and leaving the
least-squares problem unconverged. The normal equations are reduced to the receivers by the Schur
complement of each source's (K + 1) block (K - 1 direction angles, rho, o); the gauge (a rigid motion) is
left to the damping while iterating and to the pseudo-inverse in the statistics.

Channel delays (`adjust_plane_waves(..., delays=True)`; the pipeline's choice when the residuals depend on the
direction of arrival, `judge.direction_lack_of_fit`): every receiver also carries a delay d_i, F_ij += d_i (a
channel's latency, an acoustic centre behind the capsule; the paper's model with offsets on both sides), their
common part held by the sources' arrival times (a gauge freedom left to the pseudo-inverse like the rigid motions).
The receivers' blocks of the reduced normal matrix then hold (position, delay); the covariances reported are the
positions' (marginal over the delays). A delay is what a microphone's model error mostly is when the sources lie
near one elevation (the mean over azimuth of a directivity u^T A u is -A_zz / 2), and least squares without it moves
the heights (the simulated tetrahedral array's seed 3: 2.7 x the Cramer-Rao bound, 1.3 x with the delays); a
directivity of the direction's quadratic forms is not fitted: at sources 3.5-4.2 m from a 0.15 m array it is the
wavefronts' curvature (rho_j (u_j . r_i)^2 / 2 is a quadratic form of u_j for each receiver), so their ranges become
undetermined and the positions worse (seed 0: 4.1 x the bound with it, 0.94 x with the delays alone).

Robust route: Cauchy-weighted iterations at 3 robust scales from the factorization's start, then data
snooping with readmission (one rejection per source and per receiver each round, Baarda's w-test or the
externally studentised residual), as in `robust._snoop` for the point-source model.

Reference: inverse-depth parametrisation (Civera, Davison and Montiel, IEEE T-RO 2008); Baarda (1968).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .adjustment import critical_value

#: Cauchy scale in robust scales, and the first classification's cut (robust scales).
ROBUST_SCALES = 3.0


@dataclass(frozen=True, eq=False)
class PlaneWaveFit:
    """The adjusted far-field network and its statistics.

    R (m, K), U (n, K) unit directions, rho (n,) inverse ranges, o (n,) arrival times at the origin; D (m,) the
    receivers' delays (None: not modelled);
    inliers (m, n); residuals (m, n) F - prediction (NaN where missing); sigma (given or SSR / dof);
    dof; converged; redundancy, w (m, n) (w: the test statistic of every entry, a rejected one's
    from its prediction); receiver_cov (m, K, K) in the inner (minimum-norm) gauge, whose trace is the
    rigid-aligned error variance; cov_rr (mK, mK) the same, whole; source_cov (n, K + 1, K + 1) over
    (direction angles, rho, o); tangents (n, K, K - 1) the direction angles' axes; critical value.
    """

    R: np.ndarray
    U: np.ndarray
    rho: np.ndarray
    o: np.ndarray
    inliers: np.ndarray
    residuals: np.ndarray
    sigma: float
    dof: int
    converged: bool
    redundancy: np.ndarray
    w: np.ndarray
    receiver_cov: np.ndarray
    cov_rr: np.ndarray
    source_cov: np.ndarray
    tangents: np.ndarray
    critical: float
    rounds: int
    D: np.ndarray | None = None


def direction_features(U: np.ndarray) -> np.ndarray:
    """(n, p): a constant and the quadratic forms of each unit direction of arrival (the last square dropped:
    1 minus the others); p = 6 in space, 3 in the plane: the shape of a model error in `judge.direction_lack_of_fit`.
    A part linear in the direction is a shift of the microphone (its position holds it)."""
    K = U.shape[1]
    return np.column_stack([np.ones(len(U))] + [U[:, a] * U[:, b] for a in range(K) for b in range(a, K)][:-1])


def _delays(theta):
    """The receivers' delays of a parameter tuple (R, U, rho, o[, D]), or None when it has none."""
    return theta[4] if len(theta) > 4 else None


def position_index(m: int, per: int, K: int) -> np.ndarray:
    """The positions' rows among m receivers' parameters of `per` each (position first, then any delay)."""
    return (np.arange(m)[:, None] * per + np.arange(K)[None, :]).reshape(-1)


def tangent_basis(U: np.ndarray) -> np.ndarray:
    """(n, K, K - 1) orthonormal axes perpendicular to each unit row of U."""
    n, K = U.shape
    if K == 2:
        return np.stack([-U[:, 1], U[:, 0]], axis=1)[:, :, None]
    helper = np.where((np.abs(U[:, 0]) < 0.9)[:, None], np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    a = np.cross(U, helper)
    a /= np.linalg.norm(a, axis=1)[:, None]
    b = np.cross(U, a)
    return np.stack([a, b], axis=2)


def predict(R, U, rho, o, T, D=None):
    """(prediction (m, n), dP/d(receiver) (m, n, K [+ 1]), dP/d(angles, rho, o) (m, n, K + 1)); with the delays
    D (m,) a receiver's parameters are (r_i, d_i)."""
    a = R @ U.T                                      # u . r
    b = np.sum(R**2, axis=1)[:, None]                # |r|^2
    p = rho[None, :]
    g = np.sqrt(np.maximum(1.0 - 2.0 * p * a + p * p * b, 1e-300))
    num = p * b - 2.0 * a
    h = num / (1.0 + g)
    dr = (p[..., None] * R[:, None, :] - U[None, :, :]) / g[..., None]
    du = -R[:, None, :] / g[..., None]               # dh/du, projected on the tangent axes below
    dg = (p * b - a) / g
    drho = b / (1.0 + g) - num * dg / (1.0 + g) ** 2
    ds = np.concatenate([np.einsum("ijk,jkl->ijl", du, T), drho[..., None], np.ones(h.shape)[..., None]], axis=2)
    if D is None:
        return o[None, :] + h, dr, ds
    dr = np.concatenate([dr, np.ones(h.shape)[..., None]], axis=2)
    return o[None, :] + h + D[:, None], dr, ds


def _reduced(Wt, dr, ds, damping):
    """Schur complement of the source blocks: (reduced matrix (mK, mK), T (mK, n, K+1), Y (n, K+1, K+1))."""
    m, n, K = dr.shape
    q = ds.shape[2]
    Nrr = np.einsum("ij,ija,ijb->iab", Wt, dr, dr)
    Nss = np.einsum("ij,ijp,ijq->jpq", Wt, ds, ds)
    Nss = Nss + damping * (np.einsum("jpp->jp", Nss)[:, :, None] * np.eye(q) + 1e-12 * np.eye(q))
    Y = np.linalg.inv(Nss)
    T = np.einsum("ij,ija,ijq->iajq", Wt, dr, ds).reshape(m * K, n, q)
    TY = np.einsum("anp,npq->anq", T, Y)
    red = -TY.reshape(m * K, n * q) @ T.reshape(m * K, n * q).T
    for i in range(m):
        blk = Nrr[i] + damping * (np.diag(np.diag(Nrr[i])) + 1e-12 * np.eye(K))
        red[i * K:(i + 1) * K, i * K:(i + 1) * K] += blk
    return red, T, Y, TY


def _step(F, use, W, theta, damping):
    R, U, rho, o = theta[:4]
    D = _delays(theta)
    T_ax = tangent_basis(U)
    P, dr, ds = predict(R, U, rho, o, T_ax, D)
    E = np.where(use, F - P, 0.0)
    Wt = np.where(use, W, 0.0)
    red, T, Y, TY = _reduced(Wt, dr, ds, damping)
    m, n, Kp = dr.shape
    K = R.shape[1]
    gr = np.einsum("ij,ija,ij->ia", Wt, dr, E).reshape(-1)
    gs = np.einsum("ij,ijq,ij->jq", Wt, ds, E)
    rhs = gr - np.einsum("anq,nq->a", TY, gs)
    dR = np.linalg.lstsq(red, rhs, rcond=1e-12)[0]
    dS = np.einsum("npq,nq->np", Y, gs - np.einsum("anq,a->nq", T, dR))
    Un = U + np.einsum("jkl,jl->jk", T_ax, dS[:, :K - 1])
    Un /= np.linalg.norm(Un, axis=1)[:, None]
    dR = dR.reshape(m, Kp)
    out = (R + dR[:, :K], Un, rho + dS[:, K - 1], o + dS[:, K])
    return out if D is None else out + (D + dR[:, K],)


def _cost(F, use, theta, c):
    R, U, rho, o = theta[:4]
    P, _, _ = predict(R, U, rho, o, tangent_basis(U), _delays(theta))
    e = np.where(use, F - P, 0.0)
    if c is None:
        return float(np.sum(e**2)), e
    return float(np.sum(c * c * np.log1p((e / c) ** 2))), e


def levenberg_marquardt(F, use, theta, c=None, max_iter=50, tol=1e-10):
    """Minimise the (Cauchy at scale c, or plain) cost over the entries of `use`; (theta, converged)."""
    cost, e = _cost(F, use, theta, c)
    lam = 1e-4
    for _ in range(max_iter):
        W = np.ones_like(e) if c is None else 1.0 / (1.0 + (e / c) ** 2)
        trial = _step(F, use, W, theta, lam)
        new, e_new = _cost(F, use, trial, c)
        if np.isfinite(new) and new <= cost:
            done = cost - new <= tol * max(cost, 1e-300)
            theta, cost, e = trial, new, e_new
            lam = max(lam / 3.0, 1e-9)
            if done:
                return theta, True
        else:
            lam *= 5.0
            if lam > 1e8:
                return theta, True  # no descent left at any damping: a minimum to the precision of the cost
    return theta, False


def statistics(F, mask, use, theta, sigma):
    """Leverages, redundancy numbers, sigma, the receivers' and sources' covariances of the LS fit on `use` (the
    receivers' over all their parameters: positions first, then any delay)."""
    R, U, rho, o = theta[:4]
    T_ax = tangent_basis(U)
    P, dr, ds = predict(R, U, rho, o, T_ax, _delays(theta))
    m, n, K = dr.shape
    red, T, Y, TY = _reduced(use.astype(float), dr, ds, 0.0)
    Pinv = np.linalg.pinv(red, rcond=1e-10, hermitian=True)
    PTY = (Pinv @ TY.reshape(m * K, -1)).reshape(m * K, n, -1)
    Q = Y + np.einsum("anp,anq->npq", TY, PTY)
    X = -PTY.reshape(m, K, n, -1)
    Pb = np.stack([Pinv[i * K:(i + 1) * K, i * K:(i + 1) * K] for i in range(m)])
    h = (np.einsum("ija,iab,ijb->ij", dr, Pb, dr) + 2.0 * np.einsum("ija,iajq,ijq->ij", dr, X, ds)
         + np.einsum("ijp,jpq,ijq->ij", ds, Q, ds))
    E = np.where(mask, F - P, np.nan)
    rank = int(np.linalg.matrix_rank(red, tol=1e-10 * max(np.abs(red).max(), 1e-300), hermitian=True)) + n * (K + 1)
    dof = int(use.sum()) - rank
    r = np.where(use, np.clip(1.0 - h, 0.0, 1.0), np.nan)
    ssr = float(np.sum(np.where(use, E, 0.0) ** 2))
    s = sigma if sigma is not None else (np.sqrt(ssr / dof) if dof > 0 else float("nan"))
    return dict(E=E, h=h, r=r, dof=dof, sigma=float(s), ssr=ssr, Pinv=Pinv, Pb=Pb, Q=Q, T_ax=T_ax)


def adjust_plane_waves(F, work, start, sigma, scale0, alpha=0.001, max_rounds=30, max_iter=50,
                       delays: bool = False) -> PlaneWaveFit:
    """The robust adjustment of a plane-wave start (initialise.Start with its sources at c + D u): Cauchy
    iterations at ROBUST_SCALES x (sigma or the factorization's robust scale `scale0`), the classification at
    that cut, then data snooping with readmission on least squares; delays=True also fits each receiver's delay
    (module docstring), from 0."""
    R = start.R - start.R.mean(axis=0)[None, :]
    S = start.S - start.R.mean(axis=0)[None, :]
    rng_ = np.linalg.norm(S, axis=1)
    U = S / rng_[:, None]
    rho = 1.0 / rng_
    o = np.nanmedian(np.where(work, F, np.nan) - (np.linalg.norm(R[:, None] - S[None], axis=2) - rng_[None, :]), axis=0)
    theta = (R, U, rho, o)
    if delays:
        theta = theta + (np.zeros(len(R)),)
    s0 = sigma if sigma is not None else scale0
    c = ROBUST_SCALES * s0
    theta, _ = levenberg_marquardt(F, work, theta, c=c, max_iter=max_iter)
    _, e = _cost(F, work, theta, None)
    if sigma is None:  # the robust scale of the robust fit
        s0 = 1.4826 * float(np.median(np.abs(e[work])))
    inl = work & (np.abs(e) <= ROBUST_SCALES * s0)
    seen = set()
    converged, rounds = False, 0
    for rounds in range(1, max_rounds + 1):
        theta, converged = levenberg_marquardt(F, inl, theta, max_iter=max_iter)
        st = statistics(F, work, inl, theta, sigma)
        if st["dof"] < 2:
            break
        key = inl.tobytes()
        if key in seen:
            break
        seen.add(key)
        crit = critical_value(alpha, None if sigma is not None else st["dof"] - 1)
        E, h, r = st["E"], st["h"], st["r"]
        w = np.where(inl, E / (st["sigma"] * np.sqrt(np.maximum(r, 1e-12))),
                     E / (st["sigma"] * np.sqrt(1.0 + np.maximum(h, 0.0))))
        back = work & ~inl & (np.abs(w) <= crit)
        if back.any():
            inl = inl | back
            continue
        aw = np.where(inl & (r >= 0.01), np.abs(w), 0.0)
        big = aw > crit
        if not big.any():
            break
        pick = big & (aw >= aw.max(axis=1, keepdims=True)) & (aw >= aw.max(axis=0, keepdims=True))
        inl = inl & ~pick
    st = statistics(F, work, inl, theta, sigma)
    crit = critical_value(alpha, None if sigma is not None else max(st["dof"] - 1, 1))
    E, h, r = st["E"], st["h"], st["r"]
    w = np.where(inl, E / (st["sigma"] * np.sqrt(np.maximum(r, 1e-12))), E / (st["sigma"] * np.sqrt(1.0 + np.maximum(h, 0))))
    m, K = theta[0].shape
    pos = position_index(m, st["Pb"].shape[1], K)
    cov_rr = st["sigma"] ** 2 * st["Pinv"][np.ix_(pos, pos)]
    return PlaneWaveFit(*theta[:4], inliers=inl, residuals=E, sigma=st["sigma"], dof=st["dof"], converged=converged,
                        redundancy=r, w=np.where(work, w, np.nan), receiver_cov=st["sigma"] ** 2 * st["Pb"][:, :K, :K],
                        cov_rr=cov_rr, source_cov=st["sigma"] ** 2 * st["Q"], tangents=st["T_ax"], critical=crit,
                        rounds=rounds, D=_delays(theta))


def parameter_shifts(F, fit: PlaneWaveFit, bias: np.ndarray, readout: np.ndarray, chunk: int = 1024):
    """The parameters' shifts that a bias in one entry causes, entry by entry, for the inlier entries whose
    `bias` (m, n) is finite (an MDB: the external reliability): yields (entries (k, 2), dR (k, m, K) in the
    fit's minimum-norm gauge, dX (k, n, c)), by chunks of entries; dX_j = readout_j dS_j reads each source's
    shift dS_j over (direction angles, rho, o) through `readout` (n, c, K + 1) (the identity: dS itself).

    The shift is N^+ j_k b_k, with N the normal matrix of the least-squares fit on the inliers, solved by the
    Schur complement of `statistics`: dR = P^+ (j_r - T Y j_s), then every source dS_j = Y_j (g_j - T_j^T dR)
    (g_j = j_s for the entry's own source, 0 for the others); readout_j Y_j T_j^T is formed once, so that
    every entry's effect on every source is one matrix product."""
    R, U, rho, o = fit.R, fit.U, fit.rho, fit.o
    T_ax = tangent_basis(U)
    _, dr, ds = predict(R, U, rho, o, T_ax, fit.D)
    m, n, K = dr.shape          # K: the receiver's parameters (position, then any delay)
    red, T, Y, TY = _reduced(fit.inliers.astype(float), dr, ds, 0.0)
    Pinv = np.linalg.pinv(red, rcond=1e-10, hermitian=True)
    AY = np.einsum("jcq,jqp->jcp", readout, Y)                                      # (n, c, q)
    c = AY.shape[1]
    B = np.einsum("jcq,ajq->jca", AY, T).reshape(n * c, m * K)                      # readout_j Y_j T_j^T
    entries = np.argwhere(fit.inliers & np.isfinite(bias))
    for start in range(0, len(entries), chunk):
        ii, jj = entries[start:start + chunk].T
        k = len(ii)
        gs = ds[ii, jj] * bias[ii, jj][:, None]                                      # (k, q)
        rhs = -np.einsum("akq,kq->ak", TY[:, jj, :], gs)                             # (mK, k)
        rows = ii[:, None] * K + np.arange(K)[None, :]
        rhs[rows, np.arange(k)[:, None]] += dr[ii, jj] * bias[ii, jj][:, None]
        dR = Pinv @ rhs                                                               # (mK, k)
        dX = -(dR.T @ B.T).reshape(k, n, c)
        dX[np.arange(k), jj] += np.einsum("kcq,kq->kc", AY[jj], gs)
        yield np.column_stack([ii, jj]), dR.T.reshape(k, m, K)[:, :, :R.shape[1]], dX
