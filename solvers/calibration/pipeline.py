"""`calibrate`: from a TDOA matrix to one honest answer, a short driver of the stages.

diagnose (`diagnose`: what the data say before any fit) -> initialise (`initialise`: the plane-wave
factorization; otherwise the hypothesis search of `search`) -> adjust (`adjust`, `robust`) -> judge
(`judge`: the status from the final fit; `crosscheck`: a search's answer against other fits of the same
data: the given sigma, a second seed, 3D, the orientation). The package docstring describes the steps.
"""
from __future__ import annotations

import logging
import time
from dataclasses import replace

import numpy as np

from . import crosscheck, search
from .adjust import adjust_plane_waves
from .diagnose import WEAK_SPAN_DEGREES, diagnose
from .initialise import plane_wave_start
from .judge import direction_lack_of_fit, judge_kept, plane_wave_result, unexplained
from .result import CalibrationOptions, CalibrationResult
from .state import CalibrationState

#: Channel delays are fitted only when they take little of what the data tell of the positions: the median
#: receiver's std from the noise with them at most this many times that without. Measured: sources on three
#: elevation cones 0.98-1.06 (the Pyramic array's 540, 108 and 32 positions: 2.8-2.9 -> 1.0-1.2 mm from the makers'
#: calibration with the delays; the simulated tetrahedral array, seed 3: 2.7 -> 1.3 x the Cramer-Rao bound); two
#: cones 1.39 (Pyramic: 11 mm off with a median std of 2.3 mm under "ok" with them) and 2.8-2.9 (simulated).
DELAY_INFLATION = 1.2

#: Progress of long calls (stage by stage, each snooping round), at INFO; the CLI shows it on stderr.
log = logging.getLogger("solvers.calibration")


def _check_input(F) -> np.ndarray:
    try:
        arr = np.array(F, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"F must be a 2-D array of real numbers (NaN = missing): {exc}") from None
    if arr.ndim != 2:
        raise ValueError(f"F must be a 2-D (receivers x transmitters) array, got shape {arr.shape}")
    if np.isinf(arr).any():
        i, j = np.argwhere(np.isinf(arr))[0]
        raise ValueError(f"F[{i}, {j}] is infinite; mark a missing measurement with NaN")
    return arr


def calibrate(F, sigma: float | None = None, *, dim: int = 2, seed: int | None = 0,
              options: CalibrationOptions | None = None) -> CalibrationResult:
    """Calibrate a TDOA network in the plane or in space from measurements F[i, j] = |r_i - s_j| + o_j
    (+ noise, gross errors).

    Parameters
    ----------
    F : (m, n) array-like of distances (time differences times the propagation speed, any unit);
        NaN marks a missing measurement.
    sigma : noise standard deviation of the inlier measurements (units of F), > 0; None = estimate it
        from the residuals of the final least-squares fit (SSR / redundancy), never from a fit without
        redundancy: with too little redundancy the status says so and asks for sigma.
    dim : 2 (the plane) or 3 (space); one pipeline for both. 3D gauge: r_1 = 0, r_2 on +x, r_3 in the xy
        half-plane y > 0; the mirror z -> -z cannot be decided by distances (the answer is one of two).
    seed : seed of numpy.random.default_rng for the sampling; the same seed gives the same result.
    options : CalibrationOptions (thresholds, test levels, RANSAC budget, loss).

    Returns
    -------
    CalibrationResult; its `status` says what was checked (see there). Never raises for data that
    merely cannot be calibrated; raises ValueError for malformed input (not 2-D, not numeric, infinite
    values), a sigma that is not a finite positive number, or a dim other than 2 or 3.

    Reference: the paper's pipeline (Sec. 3) inside LO-RANSAC with extension and robust refinement
    (Larsson et al., EUSIPCO 2021); the final adjustment and its tests after Baarda (1968).
    """
    t0 = time.perf_counter()
    opts = options or CalibrationOptions()
    F = _check_input(F)
    if sigma is not None and not (sigma > 0 and np.isfinite(sigma)):
        raise ValueError(f"sigma must be a finite number > 0 (the noise level of real measurements is never 0; "
                         f"None estimates it), got {sigma}")
    if dim not in (2, 3) or isinstance(dim, bool):
        raise ValueError(f"dim must be 2 or 3, got {dim!r}")
    state = CalibrationState(F, np.isfinite(F), dim, sigma, diagnosis=diagnose(F, dim))
    diagnosis = state.diagnosis
    log.info("diagnosis: %d entries, %d unknowns, %d degrees of freedom; wavefronts %s (curvature %.3g)",
             diagnosis.entries, diagnosis.unknowns, diagnosis.dof, diagnosis.wavefront, diagnosis.curvature)
    refuted = None
    if diagnosis.wavefront == "plane":
        # the diagnosis proposes plane waves; the fit from their factorization tests that hypothesis
        result, why = _plane_waves(state, seed, opts, t0)
        if result is not None and why is None:
            # a start from the data's own structure, no sampling: a second seed gives the same answer, and the
            # factorization has already compared the two orientations (diagnosis.orientation_ratio)
            return replace(judge_kept(result), seconds=time.perf_counter() - t0, seed=seed)
        if result is not None:
            log.info("the plane-wave fit does not explain the data (%s): the point-source hypothesis search", why)
            refuted = (result, why)
    result = search._calibrate_once(F, sigma, seed, opts, t0, dim)
    result = crosscheck.recheck(F, sigma, seed, opts, t0, dim, result)
    if refuted is not None:
        result = crosscheck.choose_model(F, sigma, opts, diagnosis, refuted[0], refuted[1], result)
    return replace(judge_kept(result), seconds=time.perf_counter() - t0, seed=seed)


def _plane_waves(state: CalibrationState, seed, opts: CalibrationOptions, t0
                 ) -> tuple[CalibrationResult | None, str | None]:
    """The route the diagnosis proposed for plane waves: initialise from the factorization
    (`initialise.plane_wave_start`, recorded in the state), adjust every source as a direction and an
    inverse range (`adjust.adjust_plane_waves`), judge (`judge.plane_wave_result`, then the orientation,
    `crosscheck._judge_route`).

    Returns (the answer, None) when its fit explains the data, (the answer, why not) when it does not
    (`judge.unexplained`: the hypothesis is refuted, the driver runs the point-source search), (None, None)
    when too few entries are usable (the search route then says so)."""
    F, dim, sigma, diagnosis = state.F, state.dim, state.sigma, state.diagnosis
    work, warnings, failure = search._usable(F, dim)
    if failure is not None:
        return None, None
    m, n = F.shape
    log.info("calibrate %dD, %d x %d, %d measured, sigma %s: plane-wave factorization", dim, m, n,
             int(state.mask.sum()), "estimated" if sigma is None else f"{sigma:g} given")
    state = replace(state, start=plane_wave_start(F, work, diagnosis))
    notes = warnings + list(diagnosis.notes) + list(state.start.notes)
    # With the sources on one elevation cone (3D) the data leave part of the network free: a singular or an
    # unconverged plane-wave fit is then the data's, not the start's, and the point-source search is no way out
    # (20 sources on one cone: 516 s, "unconverged"): no calibration rather than a guessed one. Otherwise the
    # data do not explain it, the start does (near-field 12r/20s in the plane taken for plane waves): refuted.
    weak = dim == 3 and diagnosis.elevation_span < WEAK_SPAN_DEGREES

    def undetermined(what: str) -> CalibrationResult:
        span = f"the sources span {diagnosis.elevation_span:.0f} deg of elevation; " if weak else ""
        return search._failed(F, f"the plane-wave adjustment {what}: the data leave part of the network "
                              f"undetermined ({span}sources at more elevations, or more sources, determine it)",
                              t0, seed, warnings=tuple(notes), dim=dim)

    try:
        fit = adjust_plane_waves(F, work, state.start, sigma, diagnosis.low_rank.scale, alpha=opts.alpha,
                                 max_iter=opts.max_iterations)
        log.info("  plane-wave adjustment: %d of %d measurements kept, %d snooping rounds (%.1f s)",
                 int(fit.inliers.sum()), int(work.sum()), fit.rounds, time.perf_counter() - t0)
        lack = direction_lack_of_fit(fit, opts.alpha)
        if lack is not None and not weak:
            # the data choose the model: residuals that depend on the direction of arrival; their part a channel
            # delay holds is fitted (adjust's docstring: without it the heights move); the rest is judged as before.
            # (Sources on one elevation leave a delay and the height one unknown: the weak-span finding says so.)
            delayed = adjust_plane_waves(F, work, state.start, sigma, diagnosis.low_rank.scale, alpha=opts.alpha,
                                         max_iter=opts.max_iterations, delays=True)
            log.info("  with the channel delays: %d of %d measurements kept, %d snooping rounds, %s (%.1f s)",
                     int(delayed.inliers.sum()), int(work.sum()), delayed.rounds,
                     "converged" if delayed.converged else "not converged", time.perf_counter() - t0)
            head = lack[0].split(": a model error")[0]
            inflation = _std_inflation(fit, delayed)
            log.info("  the delays inflate the receivers' std from the noise %.3g x", inflation)
            if not delayed.converged:
                notes.append(f"{head}: the fit with a delay per receiver did not converge; the positions are fitted "
                             "without delays")
            elif inflation > DELAY_INFLATION:
                notes.append(f"{head}: a delay per receiver would explain part of it, but the sources' elevations do "
                             f"not separate the delays from the positions (with them the receivers' std from the noise "
                             f"is {inflation:.2g} x larger); the positions are fitted without delays")
            else:
                fit = delayed
                notes.append(f"{head}: each receiver's delay is fitted with its position (their spread "
                             f"{float(np.std(fit.D)):.2g}, in the units of the data; the receivers' std from the noise "
                             f"{inflation:.2g} x that without)")
        res = plane_wave_result(F, work, diagnosis, fit, sigma, opts, notes, seed)
    except np.linalg.LinAlgError:
        # a source block of the normal matrix is singular
        return undetermined("is singular"), (None if weak else "its adjustment is singular although the source "
                                             "directions spread")
    if weak and res.status == "unconverged":
        # nearly singular (which side of exactly singular depends on the machine's rounding)
        return undetermined("did not converge"), None
    res = crosscheck._judge_route(F, diagnosis, replace(res, seconds=time.perf_counter() - t0), opts)
    return res, unexplained(res)


def _std_inflation(plain, delayed) -> float:
    """The median over the receivers of their position std from the noise with the delays over that without
    (each at its own sigma): how much of what the data tell of the positions the delays take."""
    def std(fit):
        return np.sqrt(np.maximum(np.einsum("iaa->i", fit.receiver_cov), 0.0)) / max(fit.sigma, 1e-300)
    a, b = std(plain), std(delayed)
    keep = (a > 0) & np.isfinite(a) & np.isfinite(b)
    return float(np.median(b[keep] / a[keep])) if keep.any() else float("inf")
