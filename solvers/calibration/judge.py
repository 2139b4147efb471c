"""Stage 4, judge: the status of a calibration from the final fit's statistics, per node kind, in words.

One rule, read off the final fit (never off an intermediate one):
- a node is judged by what it kept: a receiver or transmitter whose kept measurements are fewer than
  KEPT_SHARE of its measured ones rests on the few it kept, whatever their tests say (a shuffled column
  fits 6 of its 24 entries as well as the truth fits 24): never "ok", the node named; one that keeps most but
  rejects more than the rest of the network's rejection rate explains (a binomial test at CONTAMINATED_LEVEL
  over the nodes: its entries go wrong together, not as scattered gross errors) has a noise of its own: its
  std is widened by the robust scale of its entries' w-tests (`widen_contaminated`), said in a note;
- receivers: every coordinate determined; a coordinate whose std is WEAK_ANISOTROPY times that of the
  best-determined one, or the height when the sources span less than diagnose.WEAK_SPAN_DEGREES of
  elevation, is weakly determined (plane waves from one elevation: the height rests on the
  wavefronts' curvature alone, which the model error of a real array swamps): the axis named;
- transmitters far away (plane waves): their directions must be determined; a range that is not (its
  interval in 1 / range reaches 0) is reported as a lower bound, never as a failure;
- the model: sigma given, the global test; sigma estimated, enough redundancy to estimate it; the
  refinement converged; at least 2/3 of the measurements kept.
The status is the most severe finding (result.STATUSES); each finding is a warning, the first in the message.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import stats

from ..recovery import to_gauge
from .adjust import (PlaneWaveFit, _reduced, direction_features, parameter_shifts, position_index, predict,
                     tangent_basis)
from .adjustment import gauge_order
from .diagnose import WEAK_SPAN_DEGREES
from .result import STATUSES, CalibrationOptions, CalibrationResult
from .scoring import _Search
from .state import Diagnosis

#: A node that keeps fewer than this share of its measured entries is judged by what it kept.
KEPT_SHARE = 0.5
#: A node whose rejections the rest of the network's rejection rate explains with a probability below this (binomial,
#: divided by the number of placed nodes) has entries that go wrong together: a room recording's event heard through
#: reflections, 6 of its 16 entries rejected against 1.7 % elsewhere (p 1.6e-7), its kept entries spread 3.3 x the
#: network's sigma (two errors of 12 and 15 mm kept at redundancy numbers 0.16 and 0.26), its source 62 mm off,
#: 6.1 x the std from the network's sigma, under "ok" (tables/audio3d seed 7; 1.8 x the widened std).
CONTAMINATED_LEVEL = 0.001
#: The robust scale of a normal variable: its median absolute value over this is its standard deviation.
MAD_NORMAL = 0.6745
#: A fit that keeps fewer than this share of all the measured entries does not explain the data: "inconsistent".
EXPLAINED_SHARE = 2.0 / 3.0
#: A model error in the residuals (direction_lack_of_fit) whose rms reaches this share of the receivers' median
#: std makes their std no uncertainty: simulated 48 x 540 with 2 mm of directivity, 0.92 mm rms against a median
#: std of 0.93 mm, a receiver 5.9 std off under "ok" at share 1; the Pyramic array, 540 sources, 0.78 mm against
#: 0.72 mm (2.8 mm from the makers' calibration); the simulated array's 0.3 mm (0.15 mm rms against 0.43 mm,
#: nodes within 4.4 std) stays a note.
MODEL_ERROR_SHARE = 0.5
#: A receiver coordinate whose std exceeds this many times the best-determined one's is weakly determined.
WEAK_ANISOTROPY = 10.0


def worst(*statuses: str) -> str:
    """The most severe of the statuses (result.STATUSES order)."""
    return min(statuses, key=STATUSES.index)


def message(status, res: CalibrationResult, why: str = "") -> str:
    """The one-line summary of a result: counts, rms, sigma, and the first finding."""
    m, n = res.inliers.shape
    placed_r, placed_t = np.isfinite(res.receivers[:, 0]), np.isfinite(res.transmitters[:, 0])
    measured = res.measured
    n_missing = m * n - int(measured.sum())
    sig = (f"sigma {res.sigma:.3g} {'estimated' if res.sigma_estimated else 'given'}" if np.isfinite(res.sigma) else
           "sigma not estimated (no redundancy)")
    rms = f"rms {res.rms:.3g}" if np.isfinite(res.rms) else "no rms (no inlier)"
    head = (f"{status}: {int(placed_r.sum())}/{m} receivers, {int(placed_t.sum())}/{n} transmitters placed; "
            f"{int(res.inliers.sum())} inliers, {int(measured.sum() - res.inliers.sum())} rejected, {n_missing} "
            f"missing; {rms}; {sig}")
    return head + (f" - {why}" if why else "")


def _names(kind: str, idx) -> str:
    idx = list(idx)
    return ", ".join(f"{kind}{k + 1}" for k in idx[:8]) + (", ..." if len(idx) > 8 else "")


def kept_findings(measured: np.ndarray, inliers: np.ndarray, placed_r, placed_t) -> list[tuple[str, str]]:
    """Nodes that keep fewer than KEPT_SHARE of their measured entries: ("uncontrolled", words)."""
    found = []
    for kind, axis, placed, word in (("r", 1, placed_r, "receiver"), ("s", 0, placed_t, "transmitter")):
        had, kept = measured.sum(axis=axis), inliers.sum(axis=axis)
        few = np.flatnonzero(placed & (had > 0) & (kept < KEPT_SHARE * had))
        if few.size:
            k = few[0]
            found.append(("uncontrolled", f"{few.size} {word}(s) keep fewer than {100 * KEPT_SHARE:g} % of their "
                          f"measurements ({_names(kind, few)}; {kind}{k + 1} keeps {int(kept[k])} of {int(had[k])}): "
                          "each is placed from the few it kept, which the rest contradict (a wrong column or row, "
                          "a swapped label?); their positions are not checked"))
    return found


def unexplained(result: CalibrationResult) -> str | None:
    """Why a fit does not explain its data, or None when it does: it did not converge, it keeps fewer than
    EXPLAINED_SHARE of the measured entries, or a node keeps fewer than KEPT_SHARE of its own (the data
    contradict the fit there). A fit from a start that was a hypothesis (the plane-wave factorization) is
    its test: such a fit refutes the start, not the data (findings about what the data leave undetermined,
    the noise level or a model error are not in it)."""
    if result.status == "failed" or result.measured is None:
        return None
    if result.status == "unconverged":
        return "its adjustment did not converge"
    measured = int(result.measured.sum())
    kept = int((result.inliers & result.measured).sum())
    if kept < EXPLAINED_SHARE * measured:
        return f"it explains {kept} of the {measured} measurements"
    found = kept_findings(result.measured, result.inliers, np.isfinite(result.receivers[:, 0]),
                          np.isfinite(result.transmitters[:, 0]))
    return found[0][1].split(":")[0] if found else None


def contaminated(measured: np.ndarray, inliers: np.ndarray, placed_r, placed_t
                 ) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Per node kind ("r", "s"): (kind, nodes, their rejected and measured counts, the rate of the rest) of the
    placed nodes that keep at least KEPT_SHARE of their entries and reject more than the rest of the network's
    rejection rate explains: the binomial probability of as many rejections among its measured entries, at the
    rate of the other entries (one rejection and one kept entry added to them: a clean rest is no certainty),
    below CONTAMINATED_LEVEL divided by the number of placed nodes. Gross errors scattered at random pass it."""
    rejected = measured & ~inliers
    total_had, total_rej = int(measured.sum()), int(rejected.sum())
    nodes = int(np.sum(placed_r)) + int(np.sum(placed_t))
    out = []
    for kind, axis, placed in (("r", 1, placed_r), ("s", 0, placed_t)):
        had, rej = measured.sum(axis=axis), rejected.sum(axis=axis)
        rate = (total_rej - rej + 1.0) / (total_had - had + 2.0)
        p = stats.binom.sf(rej - 1, had, rate)
        bad = np.flatnonzero(placed & (rej > 0) & (had - rej >= KEPT_SHARE * had) & (p < CONTAMINATED_LEVEL / max(nodes, 1)))
        if bad.size:
            out.append((kind, bad, rej[bad], had[bad], rate[bad]))
    return out


#: The head of widen_contaminated's note (a result that carries it is not widened again).
WIDENED = "node(s) with a noise of their own"


def widen_contaminated(result: CalibrationResult) -> CalibrationResult:
    """A node whose entries go wrong together (`contaminated`) has a noise of its own, which the network's sigma
    understates: its std, covariance and reliability are widened by the robust scale of its measured entries'
    w-tests (median |w| / MAD_NORMAL, kept and rejected: the node's error distribution, half of it allowed to be
    gross), when above 1; a note names the nodes and the factors."""
    if result.w_test is None or result.measured is None or any(w.startswith(WIDENED) for w in result.warnings):
        return result
    measured, w = result.measured, np.abs(np.asarray(result.w_test, dtype=float))
    placed_r, placed_t = np.isfinite(result.receivers[:, 0]), np.isfinite(result.transmitters[:, 0])
    found = contaminated(measured, result.inliers & measured, placed_r, placed_t)
    if not found:
        return result
    fields = {"r": ["receiver_std", "receiver_cov", "receiver_reliability"],
              "s": ["transmitter_std", "offset_std", "transmitter_cov", "transmitter_reliability"]}
    changes, said = {}, []
    for kind, nodes, rej, had, rate in found:
        arrays = {name: None if getattr(result, name) is None else np.array(getattr(result, name), dtype=float)
                  for name in fields[kind]}
        for k, r, h, q in zip(nodes, rej, had, rate):
            entries = w[:, k] if kind == "s" else w[k]
            use = (measured[:, k] if kind == "s" else measured[k]) & np.isfinite(entries)
            factor = max(1.0, float(np.median(entries[use])) / MAD_NORMAL) if use.any() else 1.0
            for name, arr in arrays.items():
                if arr is not None:
                    arr[k] = arr[k] * (factor**2 if name.endswith("cov") else factor)
            said.append(f"{kind}{k + 1} ({int(r)} of {int(h)} rejected, {100 * q:.2g} % elsewhere; x {factor:.2g})")
        changes.update({name: arr for name, arr in arrays.items() if arr is not None})
    note = (f"{WIDENED} ({len(said)}): they reject more of their measurements than the rest of the network's "
            f"rejection rate explains (binomial, level {CONTAMINATED_LEVEL:g} over the nodes), their entries go wrong "
            "together (an event heard through reflections, a noisy channel); their std is widened by the "
            "robust scale of their entries' w-tests: " + ", ".join(said[:8]) + (", ..." if len(said) > 8 else ""))
    return replace(result, warnings=result.warnings + (note,), **changes)


def judge_kept(result: CalibrationResult) -> CalibrationResult:
    """Apply the kept-share rule to a finished result (any route): an "ok" (or milder) status with a node
    that rests on few of its entries becomes "uncontrolled", the finding first in the warnings; a node whose
    entries go wrong together gets its own noise (`widen_contaminated`)."""
    if result.status == "failed" or result.measured is None:
        return result
    result = widen_contaminated(result)
    found = [f for f in kept_findings(result.measured, result.inliers, np.isfinite(result.receivers[:, 0]),
                                      np.isfinite(result.transmitters[:, 0])) if f[1] not in result.warnings]
    if not found:
        return result
    status = worst(result.status, *(s for s, _ in found))
    words = tuple(w for _, w in found)
    return replace(result, status=status, warnings=words + result.warnings,
                   message=message(status, result, words[0]) if status != result.status else result.message)


def _rigid_motions(P: np.ndarray) -> np.ndarray:
    """(len(P) K, K (K + 1) / 2): the first-order rigid motions (translations, rotations about the axes) at
    the points P (len(P), K), as columns over the flattened coordinates."""
    m, K = P.shape
    cols = [np.tile(np.eye(K)[a], m) for a in range(K)]
    if K == 3:
        for axis in np.eye(3):
            cols.append(np.cross(axis[None, :], P).reshape(-1))
    else:
        cols.append(np.column_stack([-P[:, 1], P[:, 0]]).reshape(-1))
    return np.column_stack(cols)


def _gauge_fix(R: np.ndarray, gauge: np.ndarray) -> np.ndarray:
    """((C^T G)^-1 C^T): the rigid motion (coefficients over `_rigid_motions`) that a shift of the receivers R
    (in the gauge frame: gauge[0] at 0, gauge[1] on +x, gauge[2] in xy) must lose for the gauge's fixed
    coordinates to stay fixed (an S-transformation; Baarda 1973)."""
    m, K = R.shape
    fixed = [gauge[0] * K + a for a in range(K)] + [gauge[1] * K + a for a in range(1, K)]
    if K == 3:
        fixed.append(gauge[2] * K + 2)
    C = np.zeros((m * K, len(fixed)))
    C[fixed, np.arange(len(fixed))] = 1.0
    return np.linalg.solve(C.T @ _rigid_motions(R), C.T)


def _s_transform(cov: np.ndarray, R: np.ndarray, gauge: np.ndarray) -> np.ndarray:
    """The covariance (mK, mK) of receivers R moved from the minimum-norm gauge to the gauge that fixes the
    coordinates of `_gauge_fix` (P = I - G (C^T G)^-1 C^T, G the rigid motions at R)."""
    P = np.eye(R.size) - _rigid_motions(R) @ _gauge_fix(R, gauge)
    return P @ cov @ P.T


def _plane_wave_reliability(F, fit: PlaneWaveFit, R, S, Q, gauge, determined, opts: CalibrationOptions):
    """(receiver (m,), transmitter (n,)) external reliability of a plane-wave fit: the largest shift of a
    node's position, in the reported gauge, that an undetected error of one inlier's minimal detectable bias
    (sigma delta0 / sqrt(r)) causes. A source whose range is not determined gets inf: a bias moves it along
    an unbounded range (its direction's shift is bounded, but it is an angle, not a position)."""
    m, K = R.shape
    n = len(S)
    delta0 = float(stats.norm.isf(opts.alpha / 2.0) + stats.norm.ppf(opts.power))
    r = np.nan_to_num(fit.redundancy, nan=0.0)
    with np.errstate(divide="ignore"):
        mdb = np.where(fit.inliers & (r > 1e-12), fit.sigma * delta0 / np.sqrt(np.maximum(r, 1e-300)), np.inf)
    fix = _gauge_fix(R, gauge)
    G_r, G_s = _rigid_motions(R), _rigid_motions(S)
    rng = np.where(determined, 1.0 / np.where(determined, fit.rho, 1.0), 0.0)
    # source positions s = u / rho: ds = (tangent axes . d angles) / rho - u d rho / rho^2, rotated by Q
    readout = np.zeros((n, K, K + 1))
    readout[:, :, :K - 1] = fit.tangents * rng[:, None, None]
    readout[:, :, K - 1] = -fit.U * (rng**2)[:, None]
    readout = np.einsum("ab,jbq->jaq", Q, readout)
    rel_r, rel_t = np.zeros(m), np.zeros(n)
    for _, dR, dSg in parameter_shifts(F, fit, mdb, readout):
        k = len(dR)
        dRg = dR @ Q.T
        c = dRg.reshape(k, -1) @ fix.T                      # the rigid motion the gauge removes
        dRg = dRg - (c @ G_r.T).reshape(k, m, K)
        dSg = dSg - (c @ G_s.T).reshape(k, n, K)
        rel_r = np.maximum(rel_r, np.sqrt((dRg * dRg).sum(axis=2).max(axis=0)))
        rel_t = np.maximum(rel_t, np.sqrt((dSg * dSg).sum(axis=2).max(axis=0)))
    return rel_r, np.where(determined, rel_t, np.inf)


def _spread_gauge(R: np.ndarray, use: np.ndarray) -> np.ndarray:
    """Receivers in the order of `adjustment.gauge_order`, its gauge receivers chosen spread out: the first
    with enough entries, the one farthest from it, then (3D) the one farthest from their line. A compact
    array's first receivers often sit on one edge (a tetrahedral frame: 0.4 mm off one line), and a gauge
    on nearly collinear receivers turns the data's precision into a rotation about that line."""
    order = gauge_order(R, use)
    K = R.shape[1]
    first = int(order[0])
    cand = np.asarray(order)
    d = np.linalg.norm(R[cand] - R[first], axis=1)
    second = int(cand[np.argmax(d)])
    chosen = [first, second]
    if K == 3:
        axis = (R[second] - R[first]) / max(float(np.linalg.norm(R[second] - R[first])), 1e-300)
        off = np.linalg.norm(np.cross(R[cand] - R[first], axis), axis=1)
        chosen.append(int(cand[np.argmax(off)]))
    return np.array(chosen + [int(i) for i in order if int(i) not in chosen], dtype=int)


def direction_lack_of_fit(fit: PlaneWaveFit, alpha: float) -> tuple[str, float, np.ndarray] | None:
    """(words, rms size, coefficients' second moment (p, p)) of a model error the residuals show, or None: per
    receiver, the residuals of its inliers regressed on a constant and the quadratic forms of the direction of
    arrival (`direction_features`: a per-channel delay, directivity, the frame's shadow: what a point
    microphone does not hold; a part linear in the direction is a shift of the microphone and cannot be seen),
    pooled in one F test at level alpha. The second moment is the mean over the receivers of their
    coefficients' outer products less the noise's part sigma^2 (X^T X)^-1 (clipped to >= 0): the spread of
    the model error from receiver to receiver, which `model_error_covariance` propagates to the positions."""
    m, K = fit.R.shape
    X = direction_features(fit.U)
    p = X.shape[1]
    E = np.where(fit.inliers, np.nan_to_num(fit.residuals), 0.0)
    explained = 0.0
    moment, fitted = np.zeros((p, p)), 0
    for i in range(m):
        use = fit.inliers[i]
        if use.sum() <= 2 * p:
            continue
        coef, *_ = np.linalg.lstsq(X[use], E[i, use], rcond=None)
        explained += float(np.sum((X[use] @ coef) ** 2))
        moment += np.outer(coef, coef) - fit.sigma**2 * np.linalg.pinv(X[use].T @ X[use])
        fitted += 1
    ssr = float(np.sum(E**2))
    d1, d2 = p * m, fit.dof - p * m
    if d2 <= 0 or ssr <= explained:
        return None
    F_stat = (explained / d1) / ((ssr - explained) / d2)
    critical = float(stats.f.isf(alpha, d1, d2))
    if F_stat <= critical:
        return None
    size = math.sqrt(explained / max(int(fit.inliers.sum()), 1))
    lam, vec = np.linalg.eigh(moment / max(fitted, 1))
    moment = (vec * np.maximum(lam, 0.0)) @ vec.T
    return (f"the residuals depend on the direction of arrival at the receivers (F = {F_stat:.3g} > {critical:.3g}): "
            f"a model error of rms {size:.2g} that point microphones do not hold (a per-channel delay, directivity, "
            "the frame's shadow); its part linear in the direction moves each position (an acoustic centre): the "
            "receivers' std holds that shift for a model error spread from microphone to microphone as the "
            "residuals show it"), size, moment


def model_error_covariance(fit: PlaneWaveFit, moment: np.ndarray) -> np.ndarray:
    """(mK, mK) covariance of the receivers' shifts (in the fit's minimum-norm gauge) that a model error of
    `direction_features` with coefficients drawn per receiver with second moment `moment` causes in the
    least-squares fit on the inliers: D_i = N^+ J^T (receiver i's entries times the features), summed as
    D_i moment D_i^T (a random-effects model of the directivity). The fit absorbs the error's part that
    looks like the parameters (a shift of the microphone, a source's offset or direction); the residuals
    show the rest, from which `moment` is estimated. Schur complement of the source blocks as in
    `adjust.statistics`."""
    R, U, rho, o = fit.R, fit.U, fit.rho, fit.o
    _, dr, ds = predict(R, U, rho, o, tangent_basis(U), fit.D)
    m, n, K = dr.shape          # K: a receiver's parameters (its position, then any delay: which absorbs the constant)
    W = fit.inliers.astype(float)
    red, T, Y, TY = _reduced(W, dr, ds, 0.0)
    Pinv = np.linalg.pinv(red, rcond=1e-10, hermitian=True)
    X = direction_features(U)                                                  # (n, p)
    p = X.shape[1]
    M = (W[..., None] * ds)[..., None] * X[None, :, None, :]                     # (m, n, K + 1, p)
    rhs = -(TY.reshape(m * K, -1) @ M.transpose(1, 2, 0, 3).reshape(-1, m * p)).reshape(m * K, m, p)
    own = np.einsum("in,ina,np->iap", W, dr, X)                                 # receiver i's own rows
    for i in range(m):
        rhs[i * K:(i + 1) * K, i, :] += own[i]
    D = (Pinv @ rhs.reshape(m * K, m * p)).reshape(m * K, m, p)
    lam, vec = np.linalg.eigh(moment)
    L = vec * np.sqrt(np.maximum(lam, 0.0))                                     # moment = L L^T (semi-definite)
    G = np.einsum("aip,pq->aiq", D, L).reshape(m * K, m * p)
    pos = position_index(m, K, R.shape[1])
    return G[pos] @ G[pos].T


def plane_wave_result(F, work, diagnosis: Diagnosis, fit: PlaneWaveFit, sigma, opts: CalibrationOptions,
                      warnings: list[str], seed) -> CalibrationResult:
    """The CalibrationResult of a plane-wave adjustment, judged by the rule of the module docstring."""
    m, n = F.shape
    K = fit.R.shape[1]
    mask = np.isfinite(F)
    inl = fit.inliers
    # the sources' ranges: determined where the 2-sigma interval in 1 / range stays above 0
    srho = np.sqrt(np.maximum(fit.source_cov[:, K - 1, K - 1], 0.0))
    determined = fit.rho > 2.0 * srho
    lower = 1.0 / (np.maximum(fit.rho, 0.0) + 2.0 * srho)
    ranges = np.where(determined, 1.0 / np.where(determined, fit.rho, 1.0), lower)
    S = fit.U * ranges[:, None]
    common = float(np.mean(fit.D)) if fit.D is not None else 0.0   # the delays' mean, held by the offsets
    O = fit.o + common - ranges
    # report in the gauge of the other route (receiver g1 at 0, g2 on +x, g3 in xy)
    order = _spread_gauge(fit.R, inl)
    moved = to_gauge(fit.R[order], np.vstack([S, fit.U, np.zeros((1, K))]))
    R = fit.R.copy()
    R[order], rest = moved
    S, Ug = rest[:n], rest[n:2 * n] - rest[2 * n]
    Q = np.linalg.lstsq(fit.U, Ug, rcond=None)[0].T        # the rotation applied (u -> Q u)
    QQ = np.kron(np.eye(m), Q)
    # a model error that the residuals show moves the positions by its part the fit absorbed: in the std
    lack = direction_lack_of_fit(fit, opts.alpha)
    noise_cov = _s_transform(QQ @ fit.cov_rr @ QQ.T, R, order[:K])
    cov = noise_cov if lack is None else _s_transform(QQ @ (fit.cov_rr + model_error_covariance(fit, lack[2])) @ QQ.T,
                                                      R, order[:K])
    rcov = np.stack([cov[i * K:(i + 1) * K, i * K:(i + 1) * K] for i in range(m)])
    rstd = np.sqrt(np.maximum(np.einsum("iaa->i", rcov), 0.0))
    noise_std = np.sqrt(np.maximum(np.einsum("ii->i", noise_cov).reshape(m, K).sum(axis=1), 0.0))
    # transmitters: (angles, rho, o) -> (s, o - 1 / rho), rotated into the gauge frame
    # (the range's error is skewed: 1 / rho; along the range the std is that of the far side of the 1-sigma
    # interval in rho, 1 / (rho - s) - 1 / rho = s / (rho (rho - s)), as frame.widen_far_ranges does)
    along = np.where(determined, 1.0 / np.where(determined, fit.rho * (fit.rho - srho), 1.0), 0.0)
    J = np.zeros((n, K + 1, K + 1))
    J[:, :K, :K - 1] = fit.tangents * ranges[:, None, None]
    J[:, :K, K - 1] = -fit.U * along[:, None]
    J[:, K, K - 1] = along
    J[:, K, K] = 1.0
    Rot = np.eye(K + 1)
    Rot[:K, :K] = Q
    tcov = np.einsum("ab,jbc,jcd,jed,fe->jaf", Rot, J, fit.source_cov, J, Rot)
    tcov[~determined] = np.inf
    tstd = np.where(determined, np.sqrt(np.maximum(np.einsum("jaa->j", tcov[:, :K, :K]), 0.0)), np.inf)
    ostd = np.where(determined, np.sqrt(np.maximum(tcov[:, K, K], 0.0)), np.inf)
    rel_r, rel_t = _plane_wave_reliability(F, fit, R, S, Q, order[:K], determined, opts)
    dir_std = np.degrees(np.sqrt(np.maximum(np.einsum("jaa->j", fit.source_cov[:, :K - 1, :K - 1]), 0.0)))

    found: list[tuple[str, str]] = []
    kept = float(inl.sum()) / max(int(work.sum()), 1)
    if kept < EXPLAINED_SHARE:
        found.append(("inconsistent", f"the model explains only {100 * kept:.0f} % of the measurements"))
    if not fit.converged:
        found.append(("unconverged", "the plane-wave adjustment did not converge within its iteration budget"))
    if sigma is not None:
        statistic = float(np.nansum(np.where(inl, fit.residuals, 0.0) ** 2)) / sigma**2
        critical = float(stats.chi2.isf(opts.alpha_global, max(fit.dof, 1)))
        if statistic > critical:
            found.append(("inconsistent", f"the global test of the model fails: SSR / sigma^2 = {statistic:.4g} > "
                          f"{critical:.4g} (chi^2, {fit.dof} degrees of freedom): the residuals are "
                          f"{math.sqrt(statistic / max(fit.dof, 1)):.2g} x the given sigma; is sigma right, or the model?"))
        global_test = (statistic, critical, statistic <= critical)
    else:
        global_test = None
        if fit.dof < opts.min_dof_for_sigma:
            found.append(("uncontrolled", f"too little redundancy to estimate sigma ({fit.dof} degrees of freedom)"))
    found += kept_findings(mask, inl, np.ones(m, bool), np.ones(n, bool))
    # receivers, per coordinate: the pooled covariance of their positions after a rigid alignment
    pooled = np.einsum("iab->ab", fit.receiver_cov) / m
    lam, vec = np.linalg.eigh(pooled)
    if not (np.all(np.isfinite(rstd)) and lam[0] > 0):
        found.append(("uncontrolled", "some receiver coordinates are not determined (std inf)"))
    elif math.sqrt(lam[-1] / lam[0]) > WEAK_ANISOTROPY or (K == 3 and diagnosis.elevation_span < WEAK_SPAN_DEGREES):
        # (the geometry decides too: with the sources on one elevation the height rests on the curvature
        # alone, whatever its std from the noise says; the Pyramic array's middle loudspeaker: 4 x, 9 mm off)
        axis = Q @ vec[:, -1]
        axis = axis * np.sign(axis[np.argmax(np.abs(axis))])
        span = (f"the sources span {diagnosis.elevation_span:.0f} deg of elevation: " if K == 3 and
                np.isfinite(diagnosis.elevation_span) else "")
        found.append(("uncontrolled", f"{span}the receivers' coordinate along ({', '.join(f'{a:.2f}' for a in axis)}) "
                      f"(their height, across the plane of the source directions) is weakly determined: its std "
                      f"{1e3 * math.sqrt(lam[-1]):.3g}e-3 against {1e3 * math.sqrt(lam[0]):.3g}e-3 across "
                      f"({math.sqrt(lam[-1] / lam[0]):.0f} x); " + (
                          "the receivers' delays, fitted because the residuals depend on the direction of arrival, "
                          "take what the sources' few elevations tell of it" if fit.D is not None else
                          "it rests on the wavefronts' curvature alone, which a model error swamps")
                      + "; sources at more elevations determine it"))
    if not np.all(np.isfinite(dir_std)):
        found.append(("uncontrolled", "some source directions are not determined (std inf)"))
    notes = []
    if lack is not None and lack[1] >= MODEL_ERROR_SHARE * float(np.median(noise_std[noise_std > 0])):
        # an unmodelled error of the size of the receivers' std from the noise: its propagation above rests on
        # a model of the model error (quadratic forms of the direction), which is then no longer checked
        found.append(("uncontrolled", lack[0] + f"; it reaches {MODEL_ERROR_SHARE:g} x the receivers' median std from "
                      f"the noise ({float(np.median(noise_std[noise_std > 0])):.2g}): their positions are not checked "
                      "to their std"))
    elif lack is not None:
        notes.append(lack[0])
    if (~determined).any():
        notes.append(f"{int((~determined).sum())} of {n} source ranges are not determined (plane waves: the 2-sigma "
                     "interval in 1 / range reaches 0): each such source is placed at the lower bound of its range "
                     f"(std inf; {_names('s', np.flatnonzero(~determined))}); their directions are determined "
                     f"(median std {np.median(dir_std[~determined]):.2g} deg)")
    status = worst("ok", *(s for s, _ in found))
    warnings = [w for _, w in found] + notes + list(warnings)
    E = fit.residuals
    rms = float(np.sqrt(np.mean(E[inl] ** 2))) if inl.any() else float("nan")
    redundancy = np.where(inl, fit.redundancy, np.nan)
    res = CalibrationResult(
        status=status, message="", receivers=R, transmitters=S, offsets=O, inliers=inl, residuals=E, rms=rms,
        sigma=float(fit.sigma), sigma_estimated=sigma is None, receiver_std=rstd, transmitter_std=tstd,
        offset_std=ostd, warnings=tuple(warnings), solver="factorization", seed=seed, dof=fit.dof,
        global_test=global_test, redundancy=redundancy, w_test=fit.w, critical_value=float(fit.critical),
        uncontrolled=inl & (np.nan_to_num(redundancy, nan=1.0) < opts.min_redundancy), measured=mask,
        gauge=tuple(int(g) for g in order[:K]), receiver_cov=rcov, transmitter_cov=tcov,
        receiver_reliability=rel_r, transmitter_reliability=rel_t,
        receiver_delays=None if fit.D is None else fit.D - common,
    )
    why = found[0][1] if found else (notes[0] if notes else "plane waves: every receiver and direction determined")
    return replace(res, message=message(status, res, why))


#: A search that would need more samples than this for its confidence cannot reach it (at ~3 ms a 3D sample,
#: hours): its message says so instead of a count of samples short.
SEARCH_REACH = 1e6


def _marginal_rejections(rejected, inl, w_test, redundancy, crit: float, opts: CalibrationOptions) -> list:
    """Rejected entries (i, j) whose test statistic lies between 1 and 3 critical values, at a receiver or
    transmitter that keeps an entry of redundancy number below opts.weak_redundancy.

    A gross error is far beyond the critical value; a rejection just beyond it is either a small error
    or the symptom of an error the fit absorbed at the same node: an entry of small redundancy number
    pulls its node without showing in its own test, the node's good entries then look wrong (12r/8s,
    1 mm, 5 % gross errors, sigma estimated 18 x too large: one kept at r 0.047, two good ones rejected
    at 1.5 and 4 critical values, a receiver 12 std off under status "ok"). With sigma unknown nothing
    tells the two apart."""
    if not np.isfinite(crit) or not rejected.any():
        return []
    weak = inl & (np.nan_to_num(redundancy, nan=1.0) < opts.weak_redundancy)
    aw = np.abs(np.nan_to_num(w_test, nan=np.inf))
    marginal = rejected & (aw > crit) & (aw <= 3.0 * crit) & (weak.any(axis=1)[:, None] | weak.any(axis=0)[None, :])
    return [(int(i), int(j)) for i, j in np.argwhere(marginal)]


def _weak_at(marginal: list, inl, redundancy, opts: CalibrationOptions) -> list:
    """The kept entries of redundancy number below opts.weak_redundancy at the receivers and transmitters
    of the marginal rejections (i, j): where an absorbed error would sit."""
    weak = inl & (np.nan_to_num(redundancy, nan=1.0) < opts.weak_redundancy)
    rows = np.zeros(weak.shape[0], bool)
    cols = np.zeros(weak.shape[1], bool)
    for i, j in marginal:
        rows[i] = cols[j] = True
    return [(int(i), int(j)) for i, j in np.argwhere(weak & (rows[:, None] | cols[None, :]))]


def _short_search(search: _Search, short_of: int, opts: CalibrationOptions, sigma_unknown: bool) -> str:
    """The finding of a hypothesis search stopped by its budget before its confidence."""
    advice = "give sigma, or raise max_samples" if sigma_unknown else "raise max_samples"
    head = f"the hypothesis search stopped at its budget of {opts.max_samples} samples"
    if search.needed > SEARCH_REACH:
        needed = f"about {search.needed:.2g}" if math.isfinite(search.needed) else "no finite number of"
        return (f"{head} and cannot reach the {opts.confidence:g} confidence of a sample without gross errors at "
                f"this gross-error rate (its best hypothesis explains {100 * search.share:.0f} % of the measurements: "
                f"{needed} samples would be needed): a better calibration may exist ({advice})")
    return (f"{head}, {short_of} short of the {opts.confidence:g} confidence of a sample without gross errors: a "
            f"better calibration may exist ({advice})")


def route_note(route: str) -> str:
    return "no outlier: every measurement kept" if route == "all data" else "outliers rejected by data snooping"
