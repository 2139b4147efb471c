"""One seeded Monte-Carlo trial of the paper's Section 4 (`run_trial`) and the solver it calls.

Owns the per-trial record (`TRIAL_COLUMNS`, `OUTCOMES`), the trial options, access to the algebraic
solvers through ``solvers.api`` (`solver_status`) and the seeding, error and failure rules below.

Setup (paper Sec. 4): receiver and transmitter coordinates ~ N(0, 10^2), transmitter offsets
~ N(0, 1); measurements f_ij = ||r_i - s_j|| + o_j (+ N(0, sigma^2) noise for Fig. 2). Two ways to
start Levenberg-Marquardt (`solvers.refine.refine` with ``TrialOptions.lm_method``, scipy's "trf" by default:
MINPACK's "lm" ends elsewhere from some diverging starts depending on the process's memory; all m*n
measurements):

* ``"solver"`` ("ours" in the paper): the algebraic minimal solver. ``solvers.api.solve_network(F,
  refine=False)`` returns the real, valid candidates best residual first; the best
  ``refine_candidates`` of them are refined and the refined calibration with the smallest RMS
  residual is kept.
* ``"random"`` ("rand"): positions and offsets drawn from the ground-truth distributions
  (`solvers.refine.random_initial`).

Trial t of a batch uses ``seed = base_seed + t`` and one generator ``rng = default_rng(seed)``
which draws, in this order, the network (`random_network`), the measurement noise (only if
sigma > 0) and, for ``"random"``, the starting point. Both initialisations therefore see the same
networks and the same noisy measurements for a given seed (paired comparison).

Errors (computed by `solvers.metrics`, reported as the paper does, as median log10):

* relative position error = ||T(X_est) - X_true||_F / ||X_true - mean(X_true)||_F, where X stacks
  the m receivers and n transmitters (one point per row) and T is the rigid motion (rotation,
  reflection, translation; no scaling) that best aligns X_est to X_true;
* relative offset error = ||o_est - o_true||_2 / ||o_true||_2 (offsets have no gauge).

A trial *fails* if the initialisation yields no candidate (solver: no real valid root) or if the
final position or offset error exceeds its threshold ``max(failure_threshold, oracle_factor *
oracle error)``, where the oracle error is that of LM started at the ground truth on the same
measurements (the local minimum a perfect initialisation reaches; ~1e-15 without noise, so the
noiseless threshold is ``failure_threshold`` = 1e-6). Medians are taken over all trials; a trial
without an estimate counts as an infinite error.

Reference: paper Sec. 4.1 (clean data, Table 4, Fig. 1) and Sec. 4.2 (noisy data, Fig. 2).
"""
from __future__ import annotations

import importlib
import math
import time
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from solvers.metrics import log10_error, offset_error, position_error
from solvers.refine import LM_METHODS, Method, random_initial, refine
from solvers.synthetic import random_network

from .config import CONFIGS, Init, check_init, config_key, config_label, config_shape

#: Columns of the per-trial DataFrame returned by `run_trials` (see `run_trial` for meanings).
TRIAL_COLUMNS: tuple[str, ...] = (
    "config",
    "m",
    "n",
    "init",
    "trial",
    "seed",
    "sigma",
    "position_error",
    "offset_error",
    "log10_position_error",
    "log10_offset_error",
    "residual",
    "lm_iterations",
    "lm_success",
    "failed",
    "outcome",
    "solver_s",
    "lm_s",
    "total_s",
    "n_roots",
    "n_real_roots",
    "n_real_candidates",
    "n_refined",
    "initial_position_error",
    "initial_offset_error",
    "best_candidate_position_error",
    "best_candidate_offset_error",
    "oracle_position_error",
    "oracle_offset_error",
    "oracle_residual",
)

#: Trial outcomes: "ok", or why the trial failed.
OUTCOMES = ("ok", "no_candidate", "solver_error", "error_above_threshold")


class SolverUnavailable(RuntimeError):
    """``solvers.api`` (the algebraic solvers) cannot be imported or lacks ``solve_network``."""


class TrialError(RuntimeError):
    """An unexpected error inside one trial; the message names config, init, seed and sigma."""


@dataclass(frozen=True)
class TrialOptions:
    """Options of one trial (all part of the cache key).

    Parameters
    ----------
    refine_candidates : int
        Solver initialisation: number of best-residual candidates refined by LM.
    max_iter : int
        LM budget of residual evaluations (`solvers.refine.refine` ``max_iter``).
    lm_method : "trf" | "lm" | "dogbox"
        `solvers.refine.refine` ``method``. "trf" (scipy's trust-region method; without bounds the
        Levenberg-Marquardt iteration of MINPACK with the LM step from an SVD) gives the same bits from
        the same start in any process; MINPACK's "lm" does not on starts that diverge
        (docs/reproducibility.md, section 4), so the committed experiments use "trf".
    count_roots : bool
        Solver initialisation: also call ``solvers.api.solve_roots`` (outside the timed part) to
        count all finite and all real roots of the polynomial system.
    failure_threshold : float
        Relative error above which a noiseless trial has failed (see module docstring).
    oracle_factor : float
        With noise, the threshold is max(failure_threshold, oracle_factor * oracle error).
    position_sigma, offset_sigma : float
        Ground-truth (and random-initialisation) standard deviations (paper: 10 and 1).
    """

    refine_candidates: int = 3
    max_iter: int = 200
    lm_method: Method = "trf"
    count_roots: bool = True
    failure_threshold: float = 1e-6
    oracle_factor: float = 10.0
    position_sigma: float = 10.0
    offset_sigma: float = 1.0

    def __post_init__(self) -> None:
        if self.refine_candidates < 1:
            raise ValueError(f"refine_candidates must be >= 1, got {self.refine_candidates}")
        if self.lm_method not in LM_METHODS:
            raise ValueError(f"lm_method must be one of {LM_METHODS}, got {self.lm_method!r}")
        if self.max_iter < 1:
            raise ValueError(f"max_iter must be >= 1, got {self.max_iter}")
        if not (self.failure_threshold > 0 and self.oracle_factor > 0):
            raise ValueError("failure_threshold and oracle_factor must be > 0")



def _load_solve_roots() -> Callable[..., np.ndarray] | None:
    """Return ``solvers.api.solve_roots`` if it exists (after `load_solve_network` succeeded)."""
    solve_roots = getattr(importlib.import_module("solvers.api"), "solve_roots", None)
    return solve_roots if callable(solve_roots) else None


#: A root counts as real when max |Im x| <= REAL_TOL * max |x| (as `solvers.recovery.recover`).
REAL_TOL = 1e-6


def _count_roots(roots: np.ndarray) -> tuple[int, int]:
    """Return (number of roots, number of real roots) of a (k, N) array of candidate roots."""
    roots = np.asarray(roots)
    if roots.ndim != 2 or roots.shape[0] == 0:
        return 0, 0
    scale = np.max(np.abs(roots), axis=1)
    imag = np.max(np.abs(np.imag(roots)), axis=1)
    return int(roots.shape[0]), int(np.sum(imag <= REAL_TOL * scale))


def load_solve_network() -> Callable[..., list]:
    """Return ``solvers.api.solve_network`` or raise SolverUnavailable with the reason."""
    try:
        api = importlib.import_module("solvers.api")
    except Exception as exc:  # ImportError, or an error inside a half-written module
        raise SolverUnavailable(f"solvers.api cannot be imported ({type(exc).__name__}: {exc})") from exc
    solve_network = getattr(api, "solve_network", None)
    if not callable(solve_network):
        raise SolverUnavailable("solvers.api has no callable solve_network(F, refine=...)")
    return solve_network


def solver_status(configs: Iterable[str] = tuple(CONFIGS)) -> tuple[bool, str]:
    """Return (available, reason): can ``solvers.api.solve_network`` solve every configuration?

    One noiseless instance per configuration (seed 0) must give at least one candidate; the
    reason is "ok" or a one-line explanation suitable for a skip message.
    """
    try:
        solve_network = load_solve_network()
    except SolverUnavailable as exc:
        return False, str(exc)
    for config in configs:
        m, n = config_shape(config)
        F = random_network(m, n, np.random.default_rng(0)).measurements()
        try:
            candidates = solve_network(F, refine=False)
        except Exception as exc:
            return False, f"solvers.api.solve_network fails on {config_label(config)}: {type(exc).__name__}: {exc}"
        if not candidates:
            return False, f"solvers.api.solve_network returns no candidate on a noiseless {config_label(config)} instance"
    return True, "ok"



# ----------------------------------------------------------------------------------------------
# one trial
# ----------------------------------------------------------------------------------------------


def _errors(calibration: object, network: object) -> tuple[float, float]:
    return position_error(calibration, network), offset_error(calibration, network)


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


def run_trial(
    config: str,
    init: Init,
    seed: int,
    sigma: float = 0.0,
    options: TrialOptions = TrialOptions(),
    trial: int = 0,
) -> dict[str, object]:
    """Run one seeded trial and return its record (one row of `run_trials`).

    Parameters
    ----------
    config : "9r3s" | "6r4s" (or "9r/3s", "6r/4s")
    init : "solver" | "random"
    seed : int
        Seed of the trial's generator (network, then noise, then random start).
    sigma : float
        Standard deviation of the Gaussian noise on every f_ij (0 = noiseless).
    options : TrialOptions
    trial : int
        Index of the trial in its batch (recorded only).

    Returns
    -------
    dict with the keys `TRIAL_COLUMNS`:
      position_error, offset_error   relative errors of the final (refined) calibration, NaN if none
      log10_*                        log10 of those errors (`solvers.metrics.log10_error`)
      residual                       RMS measurement residual of the final calibration
      lm_iterations, lm_success      LM Jacobian evaluations and scipy's convergence flag (kept run)
      failed, outcome                see `OUTCOMES` and the module docstring
      solver_s, lm_s, total_s        seconds in the algebraic solver (NaN for "random"), in LM (all
                                     refined candidates), and their sum
      n_roots, n_real_roots          finite / real roots of the polynomial system (solve_roots;
                                     NaN for "random" or when not counted)
      n_real_candidates              calibrations from solve_network(F, refine=False): real roots
                                     with positive-definite H and a valid geometry, deduplicated
                                     (NaN for "random")
      n_refined                      starting points refined by LM
      initial_*_error                errors of the solver's best-residual candidate before LM (the
                                     solver alone), or of the random start
      best_candidate_*_error         smallest errors over all candidates before LM (is the true
                                     root among them?; NaN for "random")
      oracle_*                       LM started at the ground truth on the same F

    Raises
    ------
    SolverUnavailable
        For init="solver" without a working ``solvers.api``.
    TrialError
        For any unexpected error; the message gives config, init, seed and sigma.

    Reference: paper Sec. 4.1-4.2.
    """
    key = config_key(config)
    check_init(init)
    m, n = CONFIGS[key]
    solve_network = load_solve_network() if init == "solver" else None
    try:
        # LM from random starts overflows harmlessly on its way to a (wrong) minimum.
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)
            return _run_trial(key, init, m, n, seed, sigma, options, trial, solve_network)
    except SolverUnavailable:
        raise
    except Exception as exc:
        raise TrialError(
            f"trial failed: config={key} init={init} seed={seed} sigma={sigma!r}: "
            f"{type(exc).__name__}: {exc}"
        ) from exc


def _run_trial(
    key: str,
    init: str,
    m: int,
    n: int,
    seed: int,
    sigma: float,
    options: TrialOptions,
    trial: int,
    solve_network: Callable[..., list] | None,
) -> dict[str, object]:
    rng = np.random.default_rng(seed)
    network = random_network(m, n, rng, options.position_sigma, options.offset_sigma)
    F = network.measurements(sigma, rng)

    nan = float("nan")
    solver_s, n_real, n_roots, n_real_roots, outcome = nan, nan, nan, nan, "ok"
    best_candidate_pe, best_candidate_oe = nan, nan
    starts: list[object] = []
    if init == "random":
        starts = [random_initial(m, n, rng, options.position_sigma, options.offset_sigma)]
    else:
        assert solve_network is not None
        t0 = time.perf_counter()
        try:
            candidates = list(solve_network(F, refine=False))
        except (np.linalg.LinAlgError, FloatingPointError, ZeroDivisionError):
            candidates, outcome = [], "solver_error"
        solver_s = time.perf_counter() - t0
        n_real = float(len(candidates))
        starts = candidates[: options.refine_candidates]
        if not starts and outcome == "ok":
            outcome = "no_candidate"
        if candidates:
            errors = np.array([_errors(c, network) for c in candidates])
            best_candidate_pe, best_candidate_oe = (float(v) for v in np.min(errors, axis=0))
        solve_roots = _load_solve_roots() if options.count_roots else None
        if solve_roots is not None:
            try:
                n_roots, n_real_roots = (float(k) for k in _count_roots(solve_roots(F)))
            except (np.linalg.LinAlgError, FloatingPointError, ZeroDivisionError):
                pass

    t0 = time.perf_counter()
    results = [refine(start, F, max_iter=options.max_iter, method=options.lm_method) for start in starts]
    lm_s = time.perf_counter() - t0

    oracle = refine((network.receivers, network.transmitters, network.offsets), F, max_iter=options.max_iter,
                    method=options.lm_method)
    oracle_pe, oracle_oe = _errors(oracle.calibration, network)

    record: dict[str, object] = dict(
        config=key, m=m, n=n, init=init, trial=trial, seed=seed, sigma=float(sigma),
        position_error=nan, offset_error=nan, log10_position_error=nan, log10_offset_error=nan,
        residual=nan, lm_iterations=nan, lm_success=False, failed=True, outcome=outcome,
        solver_s=solver_s, lm_s=lm_s if results else 0.0,
        total_s=(0.0 if math.isnan(solver_s) else solver_s) + lm_s,
        n_roots=n_roots, n_real_roots=n_real_roots, n_real_candidates=n_real, n_refined=len(results),
        initial_position_error=nan, initial_offset_error=nan,
        best_candidate_position_error=best_candidate_pe, best_candidate_offset_error=best_candidate_oe,
        oracle_position_error=oracle_pe, oracle_offset_error=oracle_oe,
        oracle_residual=oracle.calibration.residual,
    )
    if not results:
        return record

    def score(result: object) -> float:
        residual = result.calibration.residual  # type: ignore[attr-defined]
        return residual if math.isfinite(residual) else math.inf

    best = min(results, key=score)
    calibration = best.calibration
    pe, oe = _errors(calibration, network)
    start_pe, start_oe = _errors(_as_calibration_like(starts[0]), network)
    position_limit = max(options.failure_threshold, options.oracle_factor * oracle_pe)
    offset_limit = max(options.failure_threshold, options.oracle_factor * oracle_oe)
    ok = _finite(pe, oe) and pe <= position_limit and oe <= offset_limit
    record.update(
        position_error=pe, offset_error=oe,
        log10_position_error=log10_error(pe) if math.isfinite(pe) else nan,
        log10_offset_error=log10_error(oe) if math.isfinite(oe) else nan,
        residual=calibration.residual, lm_iterations=float(best.iterations),
        lm_success=bool(best.success), failed=not ok,
        outcome="ok" if ok else "error_above_threshold",
        initial_position_error=start_pe, initial_offset_error=start_oe,
    )
    return record


@dataclass(frozen=True)
class _Points:
    receivers: np.ndarray
    transmitters: np.ndarray
    offsets: np.ndarray


def _as_calibration_like(start: object) -> object:
    """A Calibration passes through; a (receivers, transmitters, offsets) tuple is wrapped."""
    if all(hasattr(start, name) for name in ("receivers", "transmitters", "offsets")):
        return start
    receivers, transmitters, offsets = start  # type: ignore[misc]
    return _Points(np.asarray(receivers), np.asarray(transmitters), np.asarray(offsets))

