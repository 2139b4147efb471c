"""Monte-Carlo experiments of the paper's Section 4: Table 4, Fig. 1 (histograms), Fig. 2 (noise).

This module owns the experiment runner and its artefacts: one seeded trial (`run_trial`), batches
of trials cached on disk and run on worker processes (`run_trials`, `noise_sweep`), their summaries
(`summarise`, `table4`), the writers of ``tables/table4.{csv,md,tex}`` and of the two figures, the
provenance record, and `reproduce`, the one call behind ``tdoa-workbench reproduce``.

Setup (paper Sec. 4): receiver and transmitter coordinates ~ N(0, 10^2), transmitter offsets
~ N(0, 1); measurements f_ij = ||r_i - s_j|| + o_j (+ N(0, sigma^2) noise for Fig. 2). Two ways to
start Levenberg-Marquardt (`solvers.refine.refine`, all m*n measurements):

* ``"solver"`` ("ours" in the paper): the algebraic minimal solver. ``solvers.api.calibrate(F,
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

import contextlib
import dataclasses
import datetime as _dt
import hashlib
import importlib
import json
import math
import os
import platform
import subprocess
import sys
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import pandas as pd

from analysis.complexity import THREAD_VARIABLES, single_threaded_blas_env
from analysis.paths import HEADER_PREFIXES, cache_dir, default_output_dir, same_json_apart_from, write_if_changed
from analysis.progress import Progress
from solvers.metrics import log10_error, offset_error, position_error
from solvers.refine import random_initial, refine
from solvers.synthetic import random_network

__all__ = [
    "CACHE_DIR",
    "CONFIGS",
    "DEFAULT_SEED",
    "FIGURES_DIR",
    "FULL",
    "INITS",
    "PAPER_TABLE4",
    "QUICK",
    "ReproductionPlan",
    "ReproductionSummary",
    "SolverUnavailable",
    "TABLE4_COLUMNS",
    "TABLES_DIR",
    "TRIAL_COLUMNS",
    "TrialError",
    "TrialOptions",
    "WorkerPool",
    "build_figures",
    "build_table4",
    "code_fingerprint",
    "comparison_report",
    "config_label",
    "config_shape",
    "noise_sweep",
    "plot_histograms",
    "plot_noise",
    "provenance",
    "reproduce",
    "run_trial",
    "run_trials",
    "solver_status",
    "summarise",
    "summarise_noise_text",
    "table4",
    "write_table4",
]

ROOT = Path(__file__).resolve().parents[1]
#: Per-batch CSV cache in the user cache directory (analysis.paths), keyed by every parameter that
#: changes the numbers.
CACHE_DIR = cache_dir("experiments")
TABLES_DIR = default_output_dir()
FIGURES_DIR = TABLES_DIR / "figures"
PROVENANCE_PATH = TABLES_DIR / "experiments_provenance.json"

#: Bump when the meaning of a cached trial changes (columns, seeding, failure rule).
CACHE_VERSION = 2

#: The paper's two solvers, in Table 4 order: configuration key -> (m receivers, n transmitters).
CONFIGS: dict[str, tuple[int, int]] = {"9r3s": (9, 3), "6r4s": (6, 4)}

Init = Literal["random", "solver"]
#: Initialisations in Table 4 row order ("rand" before "ours").
INITS: tuple[str, ...] = ("random", "solver")
_INIT_LABEL = {"random": "rand", "solver": "ours"}

#: Base seed of every batch (trial t uses DEFAULT_SEED + t).
DEFAULT_SEED = 0
DEFAULT_JOBS = 2

#: Paper Table 4: median log10 relative (position, offset) error, 1000 noiseless trials.
#: Transcribed in /work/shared/reference/paper_accuracy.csv (checked by the tests).
PAPER_TABLE4: dict[tuple[str, str], tuple[float, float]] = {
    ("9r3s", "random"): (0.31, 1.63),
    ("9r3s", "solver"): (-15.0, -14.0),
    ("6r4s", "random"): (0.55, 1.93),
    ("6r4s", "solver"): (-15.0, -14.0),
}
#: Paper Sec. 4: "our generated Matlab solvers ... run in ~200 ms on an Intel i7-8565U".
PAPER_SOLVER_RUNTIME_MS = 200.0

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

#: Columns of Table 4 (`table4`); "paper_*" are the paper's values beside ours.
TABLE4_COLUMNS: tuple[str, ...] = (
    "solver",
    "init",
    "trials",
    "median_log10_position_error",
    "paper_median_log10_position_error",
    "median_log10_offset_error",
    "paper_median_log10_offset_error",
    "failure_rate",
    "median_runtime_ms",
    "median_solver_ms",
    "median_lm_ms",
    "median_lm_iterations",
    "median_log10_residual",
    "median_real_roots",
    "median_roots",
    "median_real_candidates",
    "median_log10_initial_position_error",
    "median_log10_initial_offset_error",
    "status",
)


class SolverUnavailable(RuntimeError):
    """``solvers.api`` (the algebraic solvers) cannot be imported or lacks ``calibrate``."""


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
    count_roots: bool = True
    failure_threshold: float = 1e-6
    oracle_factor: float = 10.0
    position_sigma: float = 10.0
    offset_sigma: float = 1.0

    def __post_init__(self) -> None:
        if self.refine_candidates < 1:
            raise ValueError(f"refine_candidates must be >= 1, got {self.refine_candidates}")
        if self.max_iter < 1:
            raise ValueError(f"max_iter must be >= 1, got {self.max_iter}")
        if not (self.failure_threshold > 0 and self.oracle_factor > 0):
            raise ValueError("failure_threshold and oracle_factor must be > 0")


# ----------------------------------------------------------------------------------------------
# configurations and the solver API
# ----------------------------------------------------------------------------------------------


def config_shape(config: str) -> tuple[int, int]:
    """Return (m, n) of a configuration written "9r3s" or "9r/3s"; raise ValueError otherwise."""
    key = config.replace("/", "").strip().lower()
    if key not in CONFIGS:
        raise ValueError(f"unknown configuration {config!r}; valid: {', '.join(CONFIGS)}")
    return CONFIGS[key]


def _config_key(config: str) -> str:
    config_shape(config)
    return config.replace("/", "").strip().lower()


def config_label(config: str) -> str:
    """Return the paper's spelling of a configuration, e.g. "9r/3s"."""
    m, n = config_shape(config)
    return f"{m}r/{n}s"


def _check_init(init: str) -> str:
    if init not in INITS:
        raise ValueError(f"unknown initialisation {init!r}; valid: {', '.join(INITS)}")
    return init


def _load_solve_roots() -> Callable[..., np.ndarray] | None:
    """Return ``solvers.api.solve_roots`` if it exists (after `_load_calibrate` succeeded)."""
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


def _load_calibrate() -> Callable[..., list]:
    """Return ``solvers.api.calibrate`` or raise SolverUnavailable with the reason."""
    try:
        api = importlib.import_module("solvers.api")
    except Exception as exc:  # ImportError, or an error inside a half-written module
        raise SolverUnavailable(f"solvers.api cannot be imported ({type(exc).__name__}: {exc})") from exc
    calibrate = getattr(api, "calibrate", None)
    if not callable(calibrate):
        raise SolverUnavailable("solvers.api has no callable calibrate(F, refine=...)")
    return calibrate


def solver_status(configs: Iterable[str] = tuple(CONFIGS)) -> tuple[bool, str]:
    """Return (available, reason): can ``solvers.api.calibrate`` solve every configuration?

    One noiseless instance per configuration (seed 0) must give at least one candidate; the
    reason is "ok" or a one-line explanation suitable for a skip message.
    """
    try:
        calibrate = _load_calibrate()
    except SolverUnavailable as exc:
        return False, str(exc)
    for config in configs:
        m, n = config_shape(config)
        F = random_network(m, n, np.random.default_rng(0)).measurements()
        try:
            candidates = calibrate(F, refine=False)
        except Exception as exc:
            return False, f"solvers.api.calibrate fails on {config_label(config)}: {type(exc).__name__}: {exc}"
        if not candidates:
            return False, f"solvers.api.calibrate returns no candidate on a noiseless {config_label(config)} instance"
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
      n_real_candidates              calibrations from calibrate(F, refine=False): real roots
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
    key = _config_key(config)
    _check_init(init)
    m, n = CONFIGS[key]
    calibrate = _load_calibrate() if init == "solver" else None
    try:
        # LM from random starts overflows harmlessly on its way to a (wrong) minimum.
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)
            return _run_trial(key, init, m, n, seed, sigma, options, trial, calibrate)
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
    calibrate: Callable[..., list] | None,
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
        assert calibrate is not None
        t0 = time.perf_counter()
        try:
            candidates = list(calibrate(F, refine=False))
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
    results = [refine(start, F, max_iter=options.max_iter) for start in starts]
    lm_s = time.perf_counter() - t0

    oracle = refine((network.receivers, network.transmitters, network.offsets), F, max_iter=options.max_iter)
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


# ----------------------------------------------------------------------------------------------
# batches: cache, workers, progress
# ----------------------------------------------------------------------------------------------


def _file_digest(paths: Iterable[Path]) -> str:
    h = hashlib.sha256()
    for path in sorted(paths):
        h.update(path.name.encode())
        h.update(path.read_bytes() if path.exists() else b"<missing>")
    return h.hexdigest()


def code_fingerprint(init: str) -> str:
    """SHA-256 of the source files the numbers of a batch depend on.

    The numeric pipeline (synthetic, recovery, refine, metrics) always; for init="solver" also
    ``solvers/api.py``, ``solvers/runtime.py`` and ``solvers/generated/*`` (when present), so that
    a new solver invalidates cached results. Edits to this module are covered by CACHE_VERSION.
    """
    here = Path(__file__).resolve().parent
    paths = [here / f"{name}.py" for name in ("synthetic", "recovery", "refine", "metrics")]
    if init == "solver":
        paths += [here / "api.py", here / "runtime.py"]
        generated = here / "generated"
        if generated.is_dir():
            paths += [p for p in generated.iterdir() if p.is_file() and p.suffix in (".py", ".json")]
    return _file_digest(paths)


def _cache_key(config: str, init: str, trials: int, sigma: float, seed: int, options: TrialOptions) -> dict:
    return {
        "cache_version": CACHE_VERSION,
        "config": config,
        "init": init,
        "trials": trials,
        "sigma": repr(float(sigma)),
        "seed": seed,
        "options": dataclasses.asdict(options),
        "code": code_fingerprint(init),
        "numpy": np.__version__,
    }


def _cache_path(key: dict) -> Path:
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]
    name = f"{key['config']}-{key['init']}-sigma{float(key['sigma']):.3g}-n{key['trials']}-seed{key['seed']}-{digest}.csv"
    return CACHE_DIR / name


_DTYPES: dict[str, type] = {
    "config": str, "init": str, "outcome": str, "m": int, "n": int, "trial": int, "seed": int,
    "n_refined": int, "lm_success": bool, "failed": bool,
}
_DTYPES.update({name: float for name in TRIAL_COLUMNS if name not in _DTYPES})


def _read_cache(path: Path) -> pd.DataFrame:
    frame = pd.read_csv(path, dtype=_DTYPES, keep_default_na=False, na_values=["nan", "NaN", ""])
    return frame[list(TRIAL_COLUMNS)]


def _write_atomic(path: Path, text: str | bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(text if isinstance(text, bytes) else text.encode())
    os.replace(tmp, path)


def _same_apart_from_header(old: str, new: str) -> bool:
    """Equal once the provenance header lines (commit, date) are dropped."""
    def body(text: str) -> list[str]:
        return [line for line in text.splitlines() if not line.startswith(HEADER_PREFIXES)]

    return body(old) == body(new)


def _write_output(path: Path, content: str | bytes) -> bool:
    """Write an artefact unless only its provenance header would change (a rerun keeps a checkout
    clean); True when written."""
    return write_if_changed(path, content, _same_apart_from_header)


VOLATILE_PROVENANCE = ("updated", "date", "commit", "worktree_dirty", "versions", "machine", "threads", "wall_seconds",
                       "load_average_at_end", "seconds", "jobs", "computed_now", "cache_hits",
                       "compute_seconds_when_computed")
"""Keys of experiments_provenance.json that change without the results changing (a rerun from the
caches differs from the computing run only in these)."""


def _frame(records: list[dict]) -> pd.DataFrame:
    frame = pd.DataFrame.from_records(records, columns=list(TRIAL_COLUMNS))
    return frame.astype({k: v for k, v in _DTYPES.items() if k in frame})


_THREAD_VARIABLES = THREAD_VARIABLES
_single_threaded_blas_env = single_threaded_blas_env


def _run_chunk(task: tuple[str, str, list[tuple[int, int]], float, TrialOptions]) -> list[dict]:
    config, init, trial_seeds, sigma, options = task
    return [run_trial(config, init, seed, sigma, options, trial) for trial, seed in trial_seeds]


class WorkerPool:
    """Spawned worker processes shared by several batches, started on first use.

    Workers are spawned (not forked) with OPENBLAS/OMP/MKL_NUM_THREADS=1 in their environment, so
    numpy and scipy in each worker use one BLAS thread; starting them costs a few seconds (imports),
    which is why `reproduce` shares one pool over all its batches. Use as a context manager.
    """

    def __init__(self, jobs: int = DEFAULT_JOBS) -> None:
        if jobs < 1:
            raise ValueError(f"jobs must be >= 1, got {jobs}")
        self.jobs = jobs
        self._pool = None

    def imap(self, function: Callable, tasks: list) -> Iterator:
        if self._pool is None:
            import multiprocessing

            with _single_threaded_blas_env():
                self._pool = multiprocessing.get_context("spawn").Pool(self.jobs)
        return self._pool.imap(function, tasks)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool.join()
            self._pool = None

    def __enter__(self) -> "WorkerPool":
        return self

    def __exit__(self, *exc: object) -> None:
        if exc[0] is not None and self._pool is not None:
            self._pool.terminate()
        self.close()


class _Progress(Progress):
    """One batch of trials: on a terminal it rewrites the phase's single progress line, otherwise it
    prints one line when the batch is done."""

    def __init__(self, total: int, description: str, enabled: bool) -> None:
        super().__init__(description, total, enabled, "trials", checkpoints=0)


def run_trials(
    config: str,
    init: Init,
    trials: int = 1000,
    sigma: float = 0.0,
    seed: int = DEFAULT_SEED,
    *,
    options: TrialOptions = TrialOptions(),
    jobs: int = DEFAULT_JOBS,
    cache: bool = True,
    progress: bool = True,
    chunk_size: int = 10,
    pool: WorkerPool | None = None,
) -> pd.DataFrame:
    """Run `trials` seeded trials (seeds seed, seed+1, ...) and return one row per trial.

    Parameters
    ----------
    config : "9r3s" | "6r4s"
    init : "solver" | "random"
    trials : int
    sigma : float
        Measurement noise standard deviation.
    seed : int
        Base seed; trial t uses seed + t.
    options : TrialOptions
    jobs : int
        Worker processes (spawned with one BLAS thread each); 1, or fewer than 5 chunks of
        trials, runs in this process.
    cache : bool
        Read/write ``<cache>/experiments/<config>-<init>-...-<hash>.csv`` (``analysis.paths.cache_dir``),
        keyed by all parameters, CACHE_VERSION and a fingerprint of the numeric code.
    progress : bool
        Progress bar on stderr.
    chunk_size : int
        Trials per task sent to a worker.
    pool : WorkerPool, optional
        Workers shared with other batches (else a pool of `jobs` workers is started if needed).

    Returns
    -------
    pandas.DataFrame with columns `TRIAL_COLUMNS` (see `run_trial`), ordered by trial.

    Raises
    ------
    SolverUnavailable
        For init="solver" without a working ``solvers.api`` (checked before any work).
    TrialError
        If a trial raises (the message names its seed).
    """
    key_config = _config_key(config)
    _check_init(init)
    if trials < 1:
        raise ValueError(f"trials must be >= 1, got {trials}")
    if not sigma >= 0:
        raise ValueError(f"sigma must be >= 0, got {sigma}")
    if init == "solver":
        _load_calibrate()
    path = None
    if cache:
        key = _cache_key(key_config, init, trials, sigma, seed, options)
        path = _cache_path(key)
        if path.exists():
            frame = _read_cache(path)
            frame.attrs["batch"] = _batch_info(path, "cache hit")
            return frame

    started = time.perf_counter()
    pairs = [(t, seed + t) for t in range(trials)]
    tasks = [
        (key_config, init, pairs[i : i + chunk_size], float(sigma), options)
        for i in range(0, trials, chunk_size)
    ]
    bar = _Progress(trials, f"{config_label(key_config)} {_INIT_LABEL[init]} sigma={sigma:g}", progress)
    records: list[dict] = []
    try:
        if pool is None and (jobs <= 1 or len(tasks) < 5):
            for task in tasks:
                records += _run_chunk(task)
                bar.update(len(task[2]))
        else:
            with contextlib.ExitStack() as stack:
                workers = pool if pool is not None else stack.enter_context(WorkerPool(jobs))
                for chunk in workers.imap(_run_chunk, tasks):
                    records += chunk
                    bar.update(len(chunk))
    finally:
        bar.close()

    frame = _frame(records)
    seconds = round(time.perf_counter() - started, 3)
    if path is not None:
        _write_atomic(path, frame.to_csv(index=False, float_format="%.17g"))
        sidecar = dict(key, compute_seconds=seconds, jobs=jobs if pool is None else pool.jobs,
                       computed=_dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat())
        _write_atomic(path.with_suffix(".json"), json.dumps(sidecar, indent=2, sort_keys=True) + "\n")
        frame.attrs["batch"] = _batch_info(path, "computed")
    else:
        frame.attrs["batch"] = {"file": None, "status": "not cached", "compute_seconds": seconds}
    return frame


def _batch_info(path: Path, status: str) -> dict:
    """Cache file, whether it was computed now, and the wall time it took when it was computed."""
    try:
        sidecar = json.loads(path.with_suffix(".json").read_text())
    except (OSError, json.JSONDecodeError):
        sidecar = {}
    return {"file": path.name, "status": status, "compute_seconds": sidecar.get("compute_seconds"),
            "computed": sidecar.get("computed")}


def _batches(frames: Iterable[pd.DataFrame | str]) -> dict:
    """Summarise the `batch` attributes of run_trials frames for the provenance record."""
    infos = [f.attrs["batch"] for f in frames if not isinstance(f, str) and "batch" in f.attrs]
    return {
        "batches": len(infos),
        "computed_now": sum(i["status"] != "cache hit" for i in infos),
        "cache_hits": sum(i["status"] == "cache hit" for i in infos),
        "compute_seconds_when_computed": round(sum(i["compute_seconds"] or 0.0 for i in infos), 1),
        "files": [i["file"] for i in infos],
    }


def noise_sweep(
    configs: Sequence[str] = tuple(CONFIGS),
    inits: Sequence[str] = INITS,
    sigmas: Sequence[float] = tuple(np.logspace(-6, -1, 11)),
    trials: int = 100,
    seed: int = DEFAULT_SEED,
    **kwargs: object,
) -> pd.DataFrame:
    """Run `run_trials` for every (config, init, sigma) and concatenate the rows.

    The same seeds are used at every sigma, so the networks are shared across noise levels.
    Keyword arguments (options, jobs, cache, progress) are passed on.

    Reference: paper Sec. 4.2, Fig. 2.
    """
    frames = [
        run_trials(config, init, trials, float(sigma), seed, **kwargs)  # type: ignore[arg-type]
        for config in configs
        for init in inits
        for sigma in sigmas
    ]
    batches = _batches(frames)
    sweep = pd.concat(frames, ignore_index=True)
    sweep.attrs = {"batches": batches}
    return sweep


# ----------------------------------------------------------------------------------------------
# summaries and Table 4
# ----------------------------------------------------------------------------------------------


def _median_log10(errors: pd.Series) -> float:
    """Median of log10(error) with missing estimates (NaN) counted as +inf."""
    values = np.asarray(errors, dtype=float)
    values = np.where(np.isnan(values), np.inf, values)
    with np.errstate(divide="ignore"):
        return float(np.median(log10_error(values))) if values.size else float("nan")


def _quantile_log10(errors: pd.Series, q: float) -> float:
    values = np.asarray(errors, dtype=float)
    values = np.where(np.isnan(values), np.inf, values)
    return float(np.quantile(log10_error(values), q, method="nearest")) if values.size else float("nan")


def summarise(frame: pd.DataFrame) -> pd.DataFrame:
    """Return one row per (config, init, sigma) with the house validation figures (habit 10).

    Columns: trials, median/q25/q75 log10 position and offset errors (no estimate = +inf),
    failure_rate, median_log10_residual, median_real_candidates, median_lm_iterations,
    median_solver_ms, median_lm_ms, median_runtime_ms (solver + LM), the median log10 errors of
    the starting point (solver accuracy before LM) and of the oracle (LM from the ground truth),
    and the first failed seeds.
    """
    rows = []
    for (config, init, sigma), group in frame.groupby(["config", "init", "sigma"], sort=False):
        rows.append({
            "config": config,
            "solver": config_label(config),
            "init": init,
            "sigma": sigma,
            "trials": len(group),
            "median_log10_position_error": _median_log10(group["position_error"]),
            "q25_log10_position_error": _quantile_log10(group["position_error"], 0.25),
            "q75_log10_position_error": _quantile_log10(group["position_error"], 0.75),
            "median_log10_offset_error": _median_log10(group["offset_error"]),
            "q25_log10_offset_error": _quantile_log10(group["offset_error"], 0.25),
            "q75_log10_offset_error": _quantile_log10(group["offset_error"], 0.75),
            "failure_rate": float(group["failed"].mean()),
            "median_log10_residual": _median_log10(group["residual"]),
            "median_real_candidates": float(group["n_real_candidates"].median()),
            "median_real_roots": float(group["n_real_roots"].median()),
            "median_roots": float(group["n_roots"].median()),
            "median_lm_iterations": float(group["lm_iterations"].median()),
            "median_solver_ms": 1e3 * float(group["solver_s"].median()),
            "median_lm_ms": 1e3 * float(group["lm_s"].median()),
            "median_runtime_ms": 1e3 * float(group["total_s"].median()),
            "median_log10_initial_position_error": _median_log10(group["initial_position_error"]),
            "median_log10_initial_offset_error": _median_log10(group["initial_offset_error"]),
            "median_log10_oracle_position_error": _median_log10(group["oracle_position_error"]),
            "median_log10_oracle_offset_error": _median_log10(group["oracle_offset_error"]),
            "failed_seeds": " ".join(str(s) for s in group.loc[group["failed"], "seed"].head(10)),
        })
    return pd.DataFrame(rows)


def table4(frames: dict[tuple[str, str], pd.DataFrame | str]) -> pd.DataFrame:
    """Build Table 4 (rows 9r/3s rand, 9r/3s ours, 6r/4s rand, 6r/4s ours) with the paper beside.

    Parameters
    ----------
    frames : {(config, init): per-trial DataFrame of noiseless trials, or a string saying why the
        row is missing (e.g. the solver is unavailable); missing rows get NaN numbers and that
        string as status}

    Returns
    -------
    DataFrame with columns `TABLE4_COLUMNS`; init is "rand" or "ours" as in the paper.

    Reference: paper Sec. 4.1, Table 4.
    """
    rows = []
    for config in CONFIGS:
        for init in INITS:
            paper_position, paper_offset = PAPER_TABLE4[(config, init)]
            row = dict.fromkeys(TABLE4_COLUMNS, float("nan"))
            row.update(
                solver=config_label(config), init=_INIT_LABEL[init], trials=0,
                paper_median_log10_position_error=paper_position,
                paper_median_log10_offset_error=paper_offset,
            )
            value = frames.get((config, init), "not run")
            if isinstance(value, str):
                row["status"] = value
            else:
                summary = summarise(value)
                if len(summary) != 1:
                    raise ValueError(f"Table 4 needs one noise level per row, got {len(summary)} for {config} {init}")
                s = summary.iloc[0]
                row.update({k: s[k] for k in TABLE4_COLUMNS if k in s.index and k not in ("solver", "init")})
                row["trials"] = int(s["trials"])
                row["status"] = "ok"
            rows.append(row)
    return pd.DataFrame(rows, columns=list(TABLE4_COLUMNS))


def _fmt(value: object, digits: int = 2) -> str:
    if isinstance(value, str):
        return value
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, float) and math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return f"{float(value):.{digits}f}"


_DISPLAY = (
    ("solver", "Solver", 0),
    ("init", "Init", 0),
    ("median_log10_position_error", "Position log10 (ours)", 2),
    ("paper_median_log10_position_error", "Position log10 (paper)", 2),
    ("median_log10_offset_error", "Offset log10 (ours)", 2),
    ("paper_median_log10_offset_error", "Offset log10 (paper)", 2),
    ("failure_rate", "Failure rate", 3),
    ("median_runtime_ms", "Median runtime (ms)", 1),
    ("median_solver_ms", "Solver (ms)", 2),
    ("median_lm_ms", "LM (ms)", 1),
    ("median_lm_iterations", "LM iterations", 0),
    ("median_log10_residual", "Residual log10", 1),
    ("median_real_roots", "Real roots", 0),
    ("median_real_candidates", "Valid candidates", 0),
    ("trials", "Trials", 0),
)


def _num(value: object) -> str:
    """Counts and medians of counts: 3, 3.5, or n/a."""
    return f"{value:g}" if isinstance(value, (int, float)) and not math.isnan(value) else "n/a"


def _display_rows(table: pd.DataFrame) -> list[list[str]]:
    out = []
    for _, row in table.iterrows():
        cells = []
        for column, _, digits in _DISPLAY:
            value = row[column]
            if column in ("median_lm_iterations", "median_real_roots", "median_real_candidates") and isinstance(value, float) and not math.isnan(value):
                cells.append(f"{value:g}")
            else:
                cells.append(_fmt(value, digits))
        out.append(cells)
    return out


def _provenance_line(meta: dict) -> str:
    dirty = " (dirty worktree)" if meta.get("worktree_dirty") else ""
    return (
        f"commit {str(meta.get('commit', 'unknown'))[:12]}{dirty}, {meta.get('date', '')}, "
        f"{meta.get('mode', '')} run, seeds {meta.get('seeds', '')}, numpy {meta.get('versions', {}).get('numpy', '')}, "
        f"scipy {meta.get('versions', {}).get('scipy', '')}"
    )


def write_table4(table: pd.DataFrame, directory: Path = TABLES_DIR, meta: dict | None = None) -> dict[str, Path]:
    """Write Table 4 as CSV (all columns), Markdown and LaTeX (paper columns beside ours).

    The Markdown and LaTeX files start with a provenance line (commit, date, seeds, versions); the
    full record is ``experiments_provenance.json``. Returns {"csv"|"md"|"tex": path}.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    meta = meta or {}
    paths = {ext: directory / f"table4.{ext}" for ext in ("csv", "md", "tex")}
    _write_output(paths["csv"], table.to_csv(index=False, float_format="%.6g"))

    headers = [label for _, label, _ in _DISPLAY]
    rows = _display_rows(table)
    notes = [
        "Median log10 relative errors over noiseless trials (paper Sec. 4.1, Table 4); paper values beside ours.",
        "Position error: after the best rigid alignment, ||X_est - X_true||_F / ||X_true - centroid||_F over all "
        "receivers and transmitters. Offset error: ||o_est - o_true|| / ||o_true||.",
        "A trial fails when there is no candidate or an error exceeds 1e-6; runtimes are per trial "
        "(solver + LM over the refined candidates, this machine, Python).",
    ]
    md = [f"<!-- generated by solvers.experiments.write_table4; {_provenance_line(meta)} -->", ""]
    md += ["**Table 4 (reproduction).** " + " ".join(notes), ""]
    md.append("| " + " | ".join(headers) + " |")
    md.append("|" + "|".join("---" if i < 2 else "---:" for i in range(len(headers))) + "|")
    md += ["| " + " | ".join(r) + " |" for r in rows]
    status = [f"{r['solver']} {r['init']}: {r['status']}" for _, r in table.iterrows() if r["status"] != "ok"]
    if status:
        md += ["", "Missing rows: " + "; ".join(status)]
    _write_output(paths["md"], "\n".join(md) + "\n")

    def tex_escape(text: str) -> str:
        return text.replace("_", r"\_").replace("%", r"\%").replace("&", r"\&")

    tex_columns = _DISPLAY[:8]
    tex = [f"% generated by solvers.experiments.write_table4; {tex_escape(_provenance_line(meta))}"]
    tex += [
        r"\begin{table}[tbh]",
        r"  \centering",
        r"  \caption{Median relative errors ($\log_{10}$), ours (reproduction) beside the paper, failure rate "
        r"and median runtime; noiseless data.}",
        r"  \label{tab:medianErrReproduction}",
        r"  \begin{tabular}{l|rr|rr|rr}",
        r"    Solver & \multicolumn{2}{c|}{Position error ($\log_{10}$)} & \multicolumn{2}{c|}{Offset error ($\log_{10}$)}"
        r" & Failure & Runtime \\",
        r"    & ours & paper & ours & paper & rate & (ms) \\\hline\hline",
    ]
    for row in rows:
        cells = [f"{row[0]} {row[1]}"] + row[2 : len(tex_columns)]
        tex.append("    " + " & ".join(tex_escape(c) for c in cells) + r" \\")
    tex += [r"  \end{tabular}", r"\end{table}"]
    _write_output(paths["tex"], "\n".join(tex) + "\n")
    return paths


# ----------------------------------------------------------------------------------------------
# figures
# ----------------------------------------------------------------------------------------------

_COLORS = {"solver": "#1f77b4", "random": "#d62728"}
_LINESTYLES = {"9r3s": "-", "6r4s": "--"}
_MARKERS = {"9r3s": "o", "6r4s": "s"}
#: Histogram x-range (log10 error); the upper end grows with the data up to HIST_MAX.
HIST_RANGE = (-17.0, 4.0)
HIST_MAX = 10


def _figure_metadata(title: str, description: str, meta: dict) -> tuple[dict, dict]:
    """Return (PNG metadata, PDF metadata) for matplotlib's savefig."""
    # no commit or date here (they are in experiments_provenance.json): the same data gives the same bytes
    source = "tdoa-workbench solvers.experiments; provenance in experiments_provenance.json"
    png = {"Title": title, "Description": description, "Source": source, "Software": f"matplotlib {_version('matplotlib')}"}
    pdf = {"Title": title, "Subject": description, "Keywords": source, "Creator": "tdoa-workbench solvers.experiments",
           "CreationDate": None}
    return png, pdf


def _save(fig: object, stem: Path, title: str, description: str, meta: dict, data_changed: bool = True) -> list[Path]:
    """Write ``<stem>.png`` and ``<stem>.pdf``. Rendering takes seconds, so it is skipped when the
    figure's data file did not change and both images are newer than this module (same data, same
    code: same images)."""
    png_meta, pdf_meta = _figure_metadata(title, description, meta)
    stem.parent.mkdir(parents=True, exist_ok=True)
    png, pdf = stem.with_suffix(".png"), stem.with_suffix(".pdf")
    code = Path(__file__).stat().st_mtime
    if not data_changed and all(p.exists() and p.stat().st_mtime > code for p in (png, pdf)):
        return [png, pdf]
    import io

    for path, kwargs in ((png, dict(dpi=150, metadata=png_meta)), (pdf, dict(metadata=pdf_meta))):
        buffer = io.BytesIO()
        fig.savefig(buffer, format=path.suffix[1:], **kwargs)  # type: ignore[attr-defined]
        if not _write_output(path, buffer.getvalue()):
            os.utime(path)  # same bytes from the current code: mark the image as up to date
    return [png, pdf]


def plot_histograms(
    frames: dict[tuple[str, str], pd.DataFrame], stem: Path = FIGURES_DIR / "fig1_histograms", meta: dict | None = None
) -> list[Path]:
    """Fig. 1: histograms of log10 relative error, ours vs random initialisation.

    A 2x2 grid: rows are the solvers (9r/3s, 6r/4s), columns position and offset errors; medians
    are dashed lines. Errors below 1e-17 are drawn in the first bin, trials without an estimate are
    counted in the legend. Writes ``<stem>.png``, ``<stem>.pdf`` and the bin counts ``<stem>.csv``.

    Reference: paper Sec. 4.1, Fig. 1.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    meta = meta or {}
    finite_logs = [
        log10_error(v[np.isfinite(v) & (v > 0)])
        for f in frames.values() if not isinstance(f, str)
        for v in (np.asarray(f["position_error"], float), np.asarray(f["offset_error"], float))
    ]
    top = max([HIST_RANGE[1]] + [float(np.max(x)) for x in finite_logs if np.size(x)])
    hi = min(math.ceil(top), HIST_MAX)
    edges = np.arange(HIST_RANGE[0], hi + 1e-9, 0.25)
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), sharex=True, constrained_layout=True)
    count_rows = []
    trials_seen = set()
    for r, config in enumerate(CONFIGS):
        for c, (column, what) in enumerate((("position_error", "position"), ("offset_error", "offset"))):
            ax = axes[r, c]
            for init in INITS:
                frame = frames.get((config, init))
                if frame is None or isinstance(frame, str):
                    continue
                trials_seen.add(len(frame))
                errors = np.asarray(frame[column], dtype=float)
                missing = int(np.isnan(errors).sum())
                logs = np.clip(log10_error(errors[~np.isnan(errors)]), edges[0], edges[-1])
                counts, _ = np.histogram(logs, bins=edges)
                median = _median_log10(frame[column])
                label = (f"{_INIT_LABEL[init]} ({'LM from solver' if init == 'solver' else 'LM from random start'})\n"
                         f"median {median:.2f}\n{int(frame['failed'].sum())}/{len(frame)} failed")
                if missing:
                    label += f" ({missing} no estimate)"
                ax.hist(edges[:-1], bins=edges, weights=counts, histtype="stepfilled", alpha=0.45,
                        color=_COLORS[init], edgecolor=_COLORS[init], linewidth=1.2, label=label)
                if math.isfinite(median):
                    ax.axvline(median, color=_COLORS[init], linestyle="--", linewidth=1.2)
                for lo, hi, k in zip(edges[:-1], edges[1:], counts):
                    count_rows.append({"config": config, "init": init, "quantity": what,
                                       "bin_lo": lo, "bin_hi": hi, "count": int(k)})
            ax.set_title(f"{config_label(config)}: {what} error")
            ax.set_ylabel("trials per bin (width 0.25)")
            ax.set_xlabel(f"log10 relative {what} error (dimensionless)")
            ax.grid(alpha=0.3)
            if ax.get_legend_handles_labels()[0]:
                # centred on log10 error -6, in the gap between converged (~-15) and failed (>= -2) runs
                x_gap = (-6.0 - edges[0]) / (edges[-1] - edges[0])
                ax.legend(loc="upper center", bbox_to_anchor=(x_gap, 1.0), fontsize=8, framealpha=0.9)
            ax.set_xlim(edges[0], edges[-1])
            ax.tick_params(labelbottom=True)
    trials = "/".join(str(t) for t in sorted(trials_seen)) or "0"
    fig.suptitle(f"Relative error after Levenberg-Marquardt, noiseless data, {trials} trials per histogram\n"
                 f"(dashed: medians; errors outside 1e{edges[0]:.0f}..1e{edges[-1]:.0f} are drawn in the end bins)")
    title = "Fig. 1: log10 relative error histograms, ours vs random initialisation"
    csv_path = Path(stem).with_suffix(".csv")
    fresh = _write_output(csv_path, pd.DataFrame(count_rows).to_csv(index=False, float_format="%.6g"))
    paths = _save(fig, Path(stem), title, "Paper Sec. 4.1 Fig. 1 reproduction", meta, fresh)
    plt.close(fig)
    return paths + [csv_path]


def plot_noise(summary: pd.DataFrame, stem: Path = FIGURES_DIR / "fig2_noise", meta: dict | None = None) -> list[Path]:
    """Fig. 2: median relative error against the noise level sigma, positions and offsets.

    One line per (solver, initialisation), the interquartile range of "ours" shaded, plus the oracle
    (LM started at the ground truth) as a dotted grey reference. Both axes logarithmic. Writes
    ``<stem>.png``, ``<stem>.pdf`` and the plotted summary ``<stem>.csv``.

    Parameters
    ----------
    summary : output of `summarise` on a `noise_sweep` frame (sigma > 0 rows are plotted)

    Reference: paper Sec. 4.2, Fig. 2.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    meta = meta or {}
    data = summary[summary["sigma"] > 0].sort_values(["config", "init", "sigma"])
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.6), constrained_layout=True)
    for ax, what in zip(axes, ("position", "offset")):
        for config in CONFIGS:
            for init in INITS:
                part = data[(data["config"] == config) & (data["init"] == init)]
                if part.empty:
                    continue
                sig = part["sigma"].to_numpy()
                med = 10.0 ** part[f"median_log10_{what}_error"].to_numpy()
                q25 = 10.0 ** part[f"q25_log10_{what}_error"].to_numpy()
                q75 = 10.0 ** part[f"q75_log10_{what}_error"].to_numpy()
                ax.plot(sig, med, color=_COLORS[init], linestyle=_LINESTYLES[config], marker=_MARKERS[config],
                        label=f"{config_label(config)} {_INIT_LABEL[init]}")
                if init == "solver":  # the random baseline's spread covers decades: not drawn
                    ax.fill_between(sig, q25, q75, color=_COLORS[init], alpha=0.10, linewidth=0)
            part = data[(data["config"] == config) & (data["init"] == INITS[0])]
            if not part.empty:
                ax.plot(part["sigma"], 10.0 ** part[f"median_log10_oracle_{what}_error"], color="0.45",
                        linestyle=":", marker=_MARKERS[config], markersize=3,
                        label=f"{config_label(config)} LM from ground truth (reference)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("noise standard deviation sigma (distance units; positions ~ N(0, 10^2))")
        ax.set_ylabel(f"median relative {what} error (dimensionless)")
        ax.set_title(f"{what.capitalize()} error vs noise")
        ax.grid(True, which="major", alpha=0.35)
        ax.grid(True, which="minor", alpha=0.1)
    handles, labels = axes[0].get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="outside lower center", ncol=2, fontsize=9)
    trials = "/".join(str(int(t)) for t in sorted(set(data["trials"]))) if not data.empty else "0"
    fig.suptitle(f"Median relative error after Levenberg-Marquardt vs measurement noise\n"
                 f"({trials} trials per point; shaded: interquartile range of 'ours')")
    title = "Fig. 2: median relative error vs noise sigma"
    csv_path = Path(stem).with_suffix(".csv")
    fresh = _write_output(csv_path, data.to_csv(index=False, float_format="%.6g"))
    paths = _save(fig, Path(stem), title, "Paper Sec. 4.2 Fig. 2 reproduction", meta, fresh)
    plt.close(fig)
    return paths + [csv_path]


# ----------------------------------------------------------------------------------------------
# provenance and the reproduction
# ----------------------------------------------------------------------------------------------


def _version(module: str) -> str:
    try:
        from importlib.metadata import version

        return version(module)
    except Exception:
        try:
            return str(importlib.import_module(module).__version__)
        except Exception:
            return "unavailable"


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True, timeout=10).stdout.strip()
    except Exception:
        return ""


def provenance(**extra: object) -> dict:
    """Return the provenance record of an experiment run: commit, date, versions, machine, threads.

    Keyword arguments are merged in (seeds, trials, sigmas, options, wall times...).
    """
    status = _git("status", "--porcelain")
    record = {
        "date": _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat(),
        "commit": _git("rev-parse", "HEAD") or "unknown",
        "worktree_dirty": bool(status),
        "versions": {
            "python": platform.python_version(),
            **{name: _version(name) for name in ("numpy", "scipy", "pandas", "matplotlib")},
        },
        "machine": {"platform": platform.platform(), "processor": platform.machine(), "cpus": os.cpu_count()},
        "threads": {name: os.environ.get(name, "") for name in _THREAD_VARIABLES},
    }
    record.update(extra)
    return record


def _update_provenance(sections: dict[str, dict], path: Path = PROVENANCE_PATH) -> None:
    """Merge per-artefact provenance records into ``experiments_provenance.json``.

    One section per artefact ("table4", "fig1", "fig2", "reproduce"), so that a script
    regenerating one artefact leaves the record of the others intact.
    """
    record: dict = {}
    timing = path.with_name(path.stem + ".timing.json")  # the full record of the last run (untracked)
    source = timing if timing.exists() else path
    if source.exists():
        try:
            record = json.loads(source.read_text())
        except json.JSONDecodeError:
            record = {}
    record.setdefault("artefacts", {}).update(sections)
    record["updated"] = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    record["description"] = (
        "Provenance of tables/table4.{csv,md,tex} and tables/figures/fig1_*, fig2_* "
        "(solvers.experiments); one section per artefact."
    )
    text = json.dumps(record, indent=2, default=str) + "\n"
    write_if_changed(path, text, same_json_apart_from(VOLATILE_PROVENANCE))
    write_if_changed(path.with_name(path.stem + ".timing.json"), text)


def _relative(paths: Iterable[Path | str]) -> list[str]:
    out = []
    for p in paths:
        p = Path(p)
        out.append(str(p.relative_to(ROOT)) if p.is_relative_to(ROOT) else str(p))
    return out


@dataclass(frozen=True)
class ReproductionPlan:
    """Sizes of a reproduction: Table 4 / Fig. 1 trials, Fig. 2 noise levels and trials per level."""

    mode: str
    table_trials: int
    sigmas: tuple[float, ...]
    sweep_trials: int


QUICK = ReproductionPlan("quick", 100, (1e-5, 1e-4, 1e-3, 1e-2, 1e-1), 50)
FULL = ReproductionPlan("full", 1000, tuple(float(s) for s in np.logspace(-6, -1, 11)), 100)


@contextlib.contextmanager
def _shared_pool(pool: WorkerPool | None, jobs: int) -> Iterator[WorkerPool | None]:
    """Yield `pool`, else a lazily started pool of `jobs` workers (None for jobs <= 1)."""
    if pool is not None or jobs <= 1:
        yield pool
    else:
        with WorkerPool(jobs) as own:
            yield own


def _solver_inits(echo: Callable[[str], None] | None) -> tuple[tuple[str, ...], bool, str]:
    available, reason = solver_status()
    if not available and echo is not None:
        echo(f"NOTE: solver-initialised rows ('ours') skipped, {reason}; running the random baseline only.")
    return (INITS if available else ("random",)), available, reason


def build_table4(
    trials: int = 1000,
    *,
    seed: int = DEFAULT_SEED,
    jobs: int = DEFAULT_JOBS,
    options: TrialOptions = TrialOptions(),
    tables_dir: Path = TABLES_DIR,
    progress: bool = True,
    pool: WorkerPool | None = None,
    echo: Callable[[str], None] | None = print,
    mode: str = "custom",
) -> tuple[pd.DataFrame, dict[tuple[str, str], pd.DataFrame | str]]:
    """Run (or read from cache) the four Table 4 rows and write ``table4.{csv,md,tex}``.

    Rows without a working ``solvers.api`` are written with status "solver unavailable (...)"
    and no numbers. Returns (table, {(config, init): per-trial frame or reason}).

    Reference: paper Sec. 4.1, Table 4.
    """
    inits, available, reason = _solver_inits(echo)
    t0 = time.perf_counter()
    frames: dict[tuple[str, str], pd.DataFrame | str] = {}
    with _shared_pool(pool, jobs) as workers:
        for config in CONFIGS:
            for init in INITS:
                if init in inits:
                    frames[(config, init)] = run_trials(
                        config, init, trials, 0.0, seed,  # type: ignore[arg-type]
                        options=options, jobs=jobs, progress=progress, pool=workers,
                    )
                else:
                    frames[(config, init)] = "solver unavailable"
    table = table4(frames)
    meta = provenance(
        mode=mode, seeds=f"{seed}..{seed + trials - 1} (trial t uses seed {seed} + t)", base_seed=seed,
        trials=trials, sigma=0.0, options=dataclasses.asdict(options), jobs=jobs,
        solver_available=available, solver_reason=reason,
        code_fingerprints={init: code_fingerprint(init) for init in INITS}, cache_version=CACHE_VERSION,
        paper_reference="Sec. 4.1 Table 4: median log10 relative errors, 1000 noiseless trials",
        failure_rule="no candidate, or position/offset error > max(failure_threshold, oracle_factor * oracle error)",
    )
    paths = write_table4(table, Path(tables_dir), meta)
    meta["wall_seconds"] = round(time.perf_counter() - t0, 3)
    meta["outputs"] = _relative(paths.values())
    meta["rows"] = json.loads(table.to_json(orient="records"))
    meta["trial_batches"] = _batches(frames.values())
    meta["failed_seeds"] = {
        f"{config}/{init}": " ".join(str(s) for s in frame.loc[frame["failed"], "seed"].head(20))
        for (config, init), frame in frames.items() if not isinstance(frame, str)
    }
    _update_provenance({"table4": meta}, Path(tables_dir) / PROVENANCE_PATH.name)
    return table, frames


def build_figures(
    trials: int = 1000,
    sigmas: Sequence[float] = FULL.sigmas,
    sweep_trials: int = 100,
    *,
    seed: int = DEFAULT_SEED,
    jobs: int = DEFAULT_JOBS,
    options: TrialOptions = TrialOptions(),
    tables_dir: Path = TABLES_DIR,
    progress: bool = True,
    pool: WorkerPool | None = None,
    echo: Callable[[str], None] | None = print,
    mode: str = "custom",
    frames: dict[tuple[str, str], pd.DataFrame | str] | None = None,
) -> tuple[pd.DataFrame, dict[str, list[str]]]:
    """Fig. 1 (histograms of the `trials` noiseless trials) and Fig. 2 (noise sweep).

    `frames` (from `build_table4`) avoids re-reading the noiseless batches. Writes
    ``<tables_dir>/figures/fig1_histograms.*`` and ``fig2_noise.*`` (PNG, PDF, CSV) and their
    provenance sections. Returns (noise summary, {"fig1"|"fig2": paths}).

    Reference: paper Sec. 4.1 Fig. 1 and Sec. 4.2 Fig. 2.
    """
    inits, available, reason = _solver_inits(echo)
    figures_dir = Path(tables_dir) / "figures"
    kwargs = dict(options=options, jobs=jobs, progress=progress, pool=pool)
    common = dict(
        mode=mode, base_seed=seed, options=dataclasses.asdict(options), jobs=jobs,
        solver_available=available, solver_reason=reason,
        code_fingerprints={init: code_fingerprint(init) for init in INITS}, cache_version=CACHE_VERSION,
    )

    with _shared_pool(pool, jobs) as workers:
        kwargs["pool"] = workers
        t0 = time.perf_counter()
        if frames is None:
            frames = {
                (config, init): run_trials(config, init, trials, 0.0, seed, **kwargs)  # type: ignore[arg-type]
                for config in CONFIGS for init in inits
            }
        hist_frames = {k: v for k, v in frames.items() if not isinstance(v, str)}
        meta1 = provenance(trials=trials, sigma=0.0, seeds=f"{seed}..{seed + trials - 1}",
                           paper_reference="Sec. 4.1 Fig. 1", **common)
        fig1 = plot_histograms(hist_frames, figures_dir / "fig1_histograms", meta1)
        meta1["wall_seconds"] = round(time.perf_counter() - t0, 3)
        meta1["outputs"] = _relative(fig1)
        meta1["trial_batches"] = _batches(frames.values())

        t0 = time.perf_counter()
        sweep = noise_sweep(tuple(CONFIGS), inits, tuple(sigmas), sweep_trials, seed, **kwargs)
        noise = summarise(sweep)
    meta2 = provenance(trials_per_sigma=sweep_trials, sigmas=[float(s) for s in sigmas],
                       seeds=f"{seed}..{seed + sweep_trials - 1} at every sigma",
                       paper_reference="Sec. 4.2 Fig. 2", **common)
    fig2 = plot_noise(noise, figures_dir / "fig2_noise", meta2)
    meta2["wall_seconds"] = round(time.perf_counter() - t0, 3)
    meta2["outputs"] = _relative(fig2)
    meta2["trial_batches"] = sweep.attrs.get("batches")
    _update_provenance({"fig1": meta1, "fig2": meta2}, Path(tables_dir) / PROVENANCE_PATH.name)
    return noise, {"fig1": [str(p) for p in fig1], "fig2": [str(p) for p in fig2]}


@dataclass(frozen=True)
class ReproductionSummary:
    """Result of `reproduce`: Table 4, the noise summary, written files and the report text."""

    plan: ReproductionPlan
    table: pd.DataFrame
    noise: pd.DataFrame
    paths: dict[str, list[str]]
    solver_available: bool
    solver_reason: str
    wall_seconds: float
    report: str


def comparison_report(table: pd.DataFrame, noise: pd.DataFrame | None = None, trials: int | None = None) -> str:
    """Return the text comparing every Table 4 number with the paper (and the noise medians)."""
    trials_text = f"{trials} noiseless trials per row" if trials else "noiseless trials"
    lines = [f"Table 4 reproduction ({trials_text}) vs paper, median log10 relative error:"]
    lines.append(
        f"  {'row':<12} {'position ours':>13} {'paper':>6} {'diff':>6}   {'offset ours':>11} {'paper':>6} "
        f"{'diff':>6}   {'failures':>8} {'runtime ms':>10} {'real roots':>10} {'valid cands':>11}"
    )
    for _, r in table.iterrows():
        name = f"{r['solver']} {r['init']}"
        if r["status"] != "ok":
            lines.append(f"  {name:<12} no numbers: {r['status']}")
            continue
        dp = r["median_log10_position_error"] - r["paper_median_log10_position_error"]
        do = r["median_log10_offset_error"] - r["paper_median_log10_offset_error"]
        lines.append(
            f"  {name:<12} {r['median_log10_position_error']:>13.2f} {r['paper_median_log10_position_error']:>6.2f} "
            f"{dp:>+6.2f}   {r['median_log10_offset_error']:>11.2f} {r['paper_median_log10_offset_error']:>6.2f} "
            f"{do:>+6.2f}   {100 * r['failure_rate']:>7.1f}% {r['median_runtime_ms']:>10.1f} "
            f"{_num(r['median_real_roots']):>10} {_num(r['median_real_candidates']):>11}"
        )
    if noise is not None and not noise.empty:
        lines.append(summarise_noise_text(noise))
    return "\n".join(lines)


def summarise_noise_text(noise: pd.DataFrame) -> str:
    """Return the Fig. 2 medians as text: one line per (solver, init), "sigma: pos/off" cells."""
    lines = ["Fig. 2 noise sweep, median log10 relative position / offset error (failure rate) per sigma:"]
    for (config, init), part in noise.groupby(["config", "init"], sort=False):
        cells = ", ".join(
            f"{s:.0e}: {p:.1f}/{o:.1f} ({100 * f:.0f}%)"
            for s, p, o, f in zip(part["sigma"], part["median_log10_position_error"],
                                  part["median_log10_offset_error"], part["failure_rate"])
        )
        lines.append(f"  {config_label(config)} {_INIT_LABEL[init]}: {cells}")
    return "\n".join(lines)


def reproduce(
    quick: bool = True,
    jobs: int = DEFAULT_JOBS,
    *,
    seed: int = DEFAULT_SEED,
    options: TrialOptions = TrialOptions(),
    tables_dir: Path = TABLES_DIR,
    progress: bool = True,
    echo: Callable[[str], None] | None = print,
) -> ReproductionSummary:
    """Reproduce Table 4 and Figs. 1-2 of the paper; write tables, figures and provenance.

    Parameters
    ----------
    quick : bool
        `QUICK` (100 trials per Table 4 row; 5 noise levels 1e-5..1e-1 x 50 trials) or `FULL`
        (1000 trials as the paper; 11 noise levels 1e-6..1e-1 x 100 trials).
    jobs : int
        Worker processes (one pool shared by all batches; 1 = in this process).
    seed : int
        Base seed of every batch.
    options : TrialOptions
    tables_dir : Path
        Output directory (``tables/``; figures go to ``<tables_dir>/figures``).
    progress : bool
        Progress bars on stderr.
    echo : callable or None
        Where notes and the final comparison with the paper are printed (None: silent).

    Returns
    -------
    ReproductionSummary. Without a working ``solvers.api`` the solver rows are left empty (their
    status says why) and only the random baseline is run: no number is made up.

    Reference: paper Sec. 4 (Table 4, Fig. 1, Fig. 2).
    """
    plan = QUICK if quick else FULL
    start = time.perf_counter()
    available, reason = solver_status()
    with _shared_pool(None, jobs) as pool:
        common = dict(seed=seed, jobs=jobs, options=options, tables_dir=tables_dir, progress=progress,
                      pool=pool, mode=plan.mode)
        t0 = time.perf_counter()
        table, frames = build_table4(plan.table_trials, echo=echo, **common)  # type: ignore[arg-type]
        table_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        noise, figure_paths = build_figures(
            plan.table_trials, plan.sigmas, plan.sweep_trials, frames=frames, echo=None, **common  # type: ignore[arg-type]
        )
        figures_s = time.perf_counter() - t0
    wall = time.perf_counter() - start
    paths = {"table4": [str(Path(tables_dir) / f"table4.{e}") for e in ("csv", "md", "tex")], **figure_paths,
             "provenance": [str(Path(tables_dir) / PROVENANCE_PATH.name)]}
    _update_provenance(
        {"reproduce": {"mode": plan.mode, "plan": dataclasses.asdict(plan), "jobs": jobs,
                       "wall_seconds": {"table4": round(table_s, 3), "figures": round(figures_s, 3), "total": round(wall, 3)},
                       "load_average_at_end": list(os.getloadavg()) if hasattr(os, "getloadavg") else None}},
        Path(tables_dir) / PROVENANCE_PATH.name,
    )
    report = comparison_report(table, noise, plan.table_trials)
    report += (f"\nWall time ({plan.mode}, {jobs} jobs): {wall:.1f} s (Table 4 + Fig. 1: {table_s:.1f} s, "
               f"Fig. 2 noise sweep: {figures_s:.1f} s); cached batches in {_relative([CACHE_DIR])[0]}/")
    if not available:
        report += f"\nMISSING: the solver-initialised rows ('ours') and curves, {reason}"
    report += "\nWrote: " + ", ".join(p for v in paths.values() for p in _relative(v))
    if echo is not None:
        echo(report)
    return ReproductionSummary(plan, table, noise, paths, available, reason, wall, report)
