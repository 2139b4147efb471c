"""Calibrate a real network: missing entries, gross errors, RANSAC over the minimal solvers, flags.

This module owns the user's pipeline from a TDOA matrix F (receivers x transmitters, NaN = not
measured) to one honest answer, after Larsson et al., "Upgrade methods for stratified sensor network
self-calibration" / "Fast and robust stratified self-calibration using time-difference-of-arrival
measurements" (EUSIPCO 2021 and ICASSP 2020):

1. **Hypotheses** (`available_solvers`, `_sample_block`): fully measured sub-blocks of F, sampled at
   random (randomised greedy search for a biclique, so that gaps do not defeat the sampling), are
   handed to the project's minimal solvers, cheapest first (the homotopy solvers, 0.1-0.4 s per
   call, a few samples each; the slowest not at all); the real candidates are hypotheses.
   When the blocks run out before the adaptive count is reached in a small network (few fully
   measured blocks, each holding a gross error: gaps and low redundancy), or none exists, hypotheses
   also come from sub-networks (`_sample_subnetwork`: nodes left out at random, or the nodes of the
   best hypothesis's rejected measurements; gaps allowed) solved by least squares from a random start
   or from the best hypothesis (`_hypotheses_from_subnetwork`).
2. **Extension and scoring** (`_extend`, `_score`): every other receiver and transmitter is placed by
   batched robust multilateration (linear initialisation, then iteratively reweighted Gauss-Newton);
   the hypothesis is scored MSAC-style (truncated quadratic at `threshold_sigmas` x sigma) over all
   measured entries, or by the median squared residual (LMedS) when sigma is unknown.
3. **LO-RANSAC** (`_local_optimisation`): each new best hypothesis is refined with a robust loss on
   all measured entries and then by least squares on its inliers; the number of samples adapts to the
   inlier ratio w as log(1 - confidence) / log(1 - w^k), k the sample's number of entries. In a small
   network searched by sub-networks, the best few hypotheses that lost before LO get it afterwards.
4. **Refinement** (`_robust_lm`): iteratively reweighted Levenberg-Marquardt (soft-L1, Huber or
   Cauchy loss, scale from sigma) with a sparse Jacobian, then least squares on the inliers,
   re-classifying until the inlier set is stable.
5. **An honest result** (`CalibrationResult`): inliers, RMS, sigma (given or estimated), a gauge-fixed
   covariance sigma^2 (J^T J)^-1 reduced to per-node standard deviations, and warnings for what the
   data cannot decide (near-collinear nodes, mirror positions that fit as well, an alternative
   hypothesis of similar cost, nodes with too few measurements, no redundancy); a refinement that
   did not converge or diverged is returned with status "unconverged", and a failure says why.

Gauge of the result: receiver 1 at the origin and receiver 2 on the positive x axis (paper Sec. 3),
or, when one of them has fewer than 3 inlier measurements (not determined), the first two receivers
that have them; the remaining reflection is arbitrary. Standard deviations refer to the same gauge.
Minimal numbers of measurements: a receiver (2 unknowns) needs 3 measured transmitters to be unique
(two ranges leave a mirror pair), a transmitter (position and offset, 3 unknowns) needs 4 measured
receivers; one more of each is needed before an outlier among them can be detected.
"""
from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from .recovery import recover, to_gauge

# solvers.api (scipy.optimize, the generated solvers) and scipy.linalg are imported where they are
# used, so that `import solvers` (and every CLI command) stays cheap.

__all__ = [
    "CalibrationOptions",
    "CalibrationResult",
    "MinimalSolver",
    "available_solvers",
    "calibrate",
    "estimate_covariance",
    "robust_refine",
]

Loss = Literal["soft_l1", "huber", "cauchy", "linear"]
_LOSSES = ("soft_l1", "huber", "cauchy", "linear")
Status = Literal["ok", "unconverged", "failed"]

#: Measurements a node needs to be determined (receiver: 2 unknowns; transmitter: 2 + offset).
MIN_RECEIVER_MEASUREMENTS = 3
MIN_TRANSMITTER_MEASUREMENTS = 4

#: MAD -> standard deviation for Gaussian noise.
_MAD_TO_SIGMA = 1.4826


# --------------------------------------------------------------------------------------------------
# Minimal solvers: the one adapter to solvers.api
# --------------------------------------------------------------------------------------------------

Hypothesis = tuple[np.ndarray, np.ndarray, np.ndarray]


@dataclass(frozen=True)
class MinimalSolver:
    """A minimal solver as the pipeline sees it.

    Parameters
    ----------
    label : str, e.g. "6r4s"
    m, n : int
        Size of the fully measured sub-block it needs (receivers x transmitters).
    solve : callable
        F_sub (m, n) -> list of candidate (receivers (m, 2), transmitters (n, 2), offsets (n,)),
        real and geometrically valid, any order.
    cost_ms : float
        Relative cost per call (the pencil 1, a homotopy its number of paths), to try the cheapest first.
    """

    label: str
    m: int
    n: int
    solve: Callable[[np.ndarray], list[Hypothesis]]
    cost_ms: float


def _solver_via_api(m: int, n: int) -> Callable[[np.ndarray], list[Hypothesis]]:
    """F_sub -> candidates through solvers.api.solve_roots (dispatch by shape) and recovery."""

    from . import api

    choice = api.select_solver(m, n)

    def solve(F_sub: np.ndarray) -> list[Hypothesis]:
        out: list[Hypothesis] = []
        with np.errstate(all="ignore"):
            for x in api.solve_roots(F_sub):
                if choice.label in api.POSITIONS:
                    cal = api._from_positions(F_sub, choice, x)
                else:
                    cal = recover(F_sub, x[:3], x[3:5], x[5 : 5 + n])
                if cal is not None:
                    out.append((cal.receivers, cal.transmitters, cal.offsets))
        return out

    return solve


@functools.lru_cache(maxsize=1)
def available_solvers() -> tuple[MinimalSolver, ...]:
    """The minimal solvers hypotheses are drawn from, cheapest first.

    Every generated solver of solvers.api (:data:`solvers.api.SOLVER_ORDER`): the 6r/4s curve pencil
    (~1 ms) and the homotopy solvers, whose cost grows with their number of paths (9r/3s 75 ... 4r/5s
    344; tables/solvers.csv).
    """
    from . import api

    solvers = []
    for label, m, n in api._available():
        module = api._module_for(label)
        if api.select_solver(m, n).label != label:  # the api must dispatch this block shape to it
            raise RuntimeError(f"solvers.api dispatches a {m}x{n} block to {api.select_solver(m, n).label}, not {label}")
        # a homotopy's cost grows with its paths; a squared system (5r/4s, 5r/5s) counts all its start
        # roots: it tracks only the full system's (152, 64), but its paths cost 5-8x the others' (5r/5s
        # 9.4 ms per path, 9r/3s 1.2 ms; tables/solvers.csv), and drawing 5r/5s blocks made 8r/5s
        # 10 % missing / 5 % outliers slower and no better (10 trials: 6/10 at 24 s against 7/10 at 9 s)
        cost = 1.0 if getattr(module, "METHOD", "") != "homotopy" else float(getattr(module, "START_ROOTS", module.PATHS))
        solvers.append(MinimalSolver(label, m, n, _solver_via_api(m, n), cost))
    return tuple(sorted(solvers, key=lambda s: s.cost_ms))


# --------------------------------------------------------------------------------------------------
# Options and result
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CalibrationOptions:
    """Tuning of `calibrate`; the defaults are what the benchmark (scripts/bench_calibration.py) uses.

    threshold_sigmas : inlier threshold in units of sigma (MSAC truncation and final classification)
    confidence : RANSAC stops when an all-inlier sample was drawn with this probability
    min_samples, max_samples : bounds on the number of sub-blocks handed to the solvers
    candidates_per_sample : hypotheses extended per sample (those with the smallest block residual); a
        minimal solver's roots all fit their block exactly, so up to `minimal_candidates` of them are
        extended instead
    minimal_candidates : roots of a minimal solver (6r/3s, 4r/5s) extended per sample
    expensive_samples : samples per solver costlier than `expensive_cost` (a homotopy costs 0.1-4 s per
        call; tables/solvers.csv), so that they supplement the cheap ones without dominating the time
    expensive_cost : MinimalSolver.cost_ms above which a solver counts as expensive
    max_solver_cost : solvers costlier than this are not used (4r/5s, 344 paths, ~4 s per call; the
        squared 5r/4s and 5r/5s, see `available_solvers`: sub-networks find what they would)
    max_local_optimisations : LO runs (each new best hypothesis gets one, up to this many)
    lo_iterations : LM iterations per LO run
    loss : robust loss of the refinement ("cauchy", "soft_l1", "huber"; "linear" = plain LS). Cauchy is
        redescending: a gross error stops pulling. With soft-L1 or Huber its pull stays constant and
        drags a weakly constrained transmitter along its range/offset valley (seen in the benchmark).
    max_iterations : LM iterations of the final refinement
    subnetwork_samples : most hypotheses from sub-networks (random subsets of the nodes, gaps allowed)
        solved by least squares from a random start; drawn for networks with at most
        `subnetwork_max_params` unknowns, or when too few fully measured blocks exist. The number
        adapts like the block samples, assuming a clean sub-network converges from one start in
        `subnetwork_convergence` of the cases
    subnetwork_max_params, subnetwork_convergence : see subnetwork_samples
    runners_up : in a small network searched by sub-networks, this many of the best hypotheses that
        did not beat the best one before local optimisation get it afterwards
    collinear_ratio : warn when the smaller/larger principal spread of receivers or transmitters is below
    ambiguity_chi2 : an alternative (mirror) position or hypothesis whose cost exceeds the best one by
        less than this many sigma^2 is reported as ambiguous
    """

    threshold_sigmas: float = 3.0
    confidence: float = 0.99
    min_samples: int = 5
    max_samples: int = 200
    candidates_per_sample: int = 2
    minimal_candidates: int = 12
    expensive_samples: int = 3
    expensive_cost: float = 100.0
    max_solver_cost: float = 200.0
    max_local_optimisations: int = 6
    lo_iterations: int = 15
    loss: Loss = "cauchy"
    max_iterations: int = 100
    subnetwork_samples: int = 120
    subnetwork_max_params: int = 40
    subnetwork_convergence: float = 0.3
    runners_up: int = 4
    collinear_ratio: float = 0.05
    ambiguity_chi2: float = 9.0

    def __post_init__(self) -> None:
        if self.loss not in _LOSSES:
            raise ValueError(f"loss must be one of {_LOSSES}, got {self.loss!r}")
        if not 0.0 < self.confidence < 1.0:
            raise ValueError(f"confidence must be in (0, 1), got {self.confidence}")
        if self.threshold_sigmas <= 0 or self.max_samples < 1 or self.min_samples < 0:
            raise ValueError("threshold_sigmas must be > 0, max_samples >= 1, min_samples >= 0")


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """The answer of `calibrate`: a calibration, what supports it, and what it cannot decide.

    status : "ok" (converged; read the warnings), "unconverged" (returned with a flag: the refinement
        hit its budget, diverged, or explains fewer than half of the measurements), "failed" (no
        calibration; arrays are NaN; `message` says why)
    message : one line summarising the outcome
    receivers (m, 2), transmitters (n, 2), offsets (n,) : NaN for a node that could not be placed;
        gauge: receiver 1 at 0, receiver 2 on the positive x axis (or the first two determined receivers)
    inliers : (m, n) bool, False for missing or rejected measurements
    residuals : (m, n) F - o_j - |r_i - s_j| (NaN where missing or a node is unplaced)
    rms : RMS residual over the inliers
    sigma : noise level used (given, or estimated from the inlier residuals)
    sigma_estimated : True when sigma was estimated
    receiver_std, transmitter_std, offset_std : per-node standard deviations from the gauge-fixed
        covariance sigma^2 (J^T J)^-1 (position std = sqrt(var_x + var_y); inf if not determined)
    warnings : what the data cannot decide, one sentence each
    solver : labels of the minimal solvers that produced hypotheses ("subnetworks": least squares on
        sub-networks from random starts)
    samples, hypotheses : sub-blocks solved and hypotheses scored
    seconds : wall time
    seed : the seed of the sampling
    """

    status: Status
    message: str
    receivers: np.ndarray
    transmitters: np.ndarray
    offsets: np.ndarray
    inliers: np.ndarray
    residuals: np.ndarray
    rms: float
    sigma: float
    sigma_estimated: bool
    receiver_std: np.ndarray
    transmitter_std: np.ndarray
    offset_std: np.ndarray
    warnings: tuple[str, ...] = ()
    solver: str = ""
    samples: int = 0
    hypotheses: int = 0
    seconds: float = 0.0
    seed: int | None = None

    @property
    def ok(self) -> bool:
        """True when a converged calibration was found (warnings may still apply)."""
        return self.status == "ok"

    @property
    def m(self) -> int:
        return self.receivers.shape[0]

    @property
    def n(self) -> int:
        return self.transmitters.shape[0]

    def to_dict(self) -> dict:
        """JSON-ready dictionary (NaN and inf become null)."""

        def clean(a):
            a = np.asarray(a)
            if a.dtype == bool:
                return a.tolist()
            return [clean(x) for x in a] if a.ndim else (float(a) if np.isfinite(a) else None)

        return {
            "status": self.status,
            "message": self.message,
            "receivers": clean(self.receivers),
            "transmitters": clean(self.transmitters),
            "offsets": clean(self.offsets),
            "inliers": clean(self.inliers),
            "rms": clean(self.rms),
            "sigma": clean(self.sigma),
            "sigma_estimated": self.sigma_estimated,
            "receiver_std": clean(self.receiver_std),
            "transmitter_std": clean(self.transmitter_std),
            "offset_std": clean(self.offset_std),
            "warnings": list(self.warnings),
            "solver": self.solver,
            "samples": self.samples,
            "hypotheses": self.hypotheses,
            "seconds": round(self.seconds, 4),
            "seed": self.seed,
        }


# --------------------------------------------------------------------------------------------------
# Residuals and batched placement of single nodes
# --------------------------------------------------------------------------------------------------


def _residual_matrix(F: np.ndarray, R: np.ndarray, S: np.ndarray, O: np.ndarray) -> np.ndarray:
    """e_ij = F_ij - o_j - |r_i - s_j|; NaN where F is missing or a node is unplaced (NaN)."""
    diff = R[:, None, :] - S[None, :, :]
    return F - O[None, :] - np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))


def _loss_weights(z: np.ndarray, loss: Loss) -> np.ndarray:
    """IRLS weights rho'(z) for z = (e / c)^2 (scipy's loss conventions)."""
    if loss == "soft_l1":
        return 1.0 / np.sqrt(1.0 + z)
    if loss == "huber":
        return np.where(z <= 1.0, 1.0, 1.0 / np.sqrt(np.maximum(z, 1.0)))
    if loss == "cauchy":
        return 1.0 / (1.0 + z)
    return np.ones_like(z)


def _loss_rho(z: np.ndarray, loss: Loss) -> np.ndarray:
    """rho(z) with rho(z) ~ z near 0 (scipy's conventions); cost = c^2 / 2 * sum rho."""
    if loss == "soft_l1":
        return 2.0 * (np.sqrt(1.0 + z) - 1.0)
    if loss == "huber":
        return np.where(z <= 1.0, z, 2.0 * np.sqrt(np.maximum(z, 1.0)) - 1.0)
    if loss == "cauchy":
        return np.log1p(z)
    return z


def _solve_batched(A: np.ndarray, b: np.ndarray, rcond: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """Solve the small systems A[k] x = b[k]; returns (x, solved) with NaN rows where A[k] is not
    finite or nearly singular (|det A| below rcond times the product of its row norms)."""
    k = A.shape[-1]
    x = np.full(b.shape, np.nan)
    finite = np.isfinite(A).all(axis=(1, 2)) & np.isfinite(b).all(axis=1)
    A_ok = np.where(finite[:, None, None], A, np.eye(k))
    hadamard = np.prod(np.linalg.norm(A_ok, axis=2), axis=1)
    good = finite & (np.abs(np.linalg.det(A_ok)) > rcond * hadamard)
    if good.any():
        x[good] = np.linalg.solve(A_ok[good], b[good][..., None])[:, :, 0]
    return x, good


def _linear_system(g: np.ndarray, P: np.ndarray, with_offset: bool) -> tuple[np.ndarray, np.ndarray]:
    """Rows of the linearised multilateration |p - P_k|^2 = (g_k - q)^2 in (p, [q,] |p|^2 - q^2).

    -2 P_k.p [+ 2 g_k q] + t = g_k^2 - |P_k|^2; g (..., K), P (..., K, 2) -> A (..., K, 3|4), rhs (..., K).
    """
    cols = [-2.0 * P] + ([2.0 * g[..., None]] if with_offset else []) + [np.ones(g.shape + (1,))]
    return np.concatenate(cols, axis=-1), g * g - np.einsum("...k,...k->...", P, P)


def _node_residuals(X: np.ndarray, G: np.ndarray, P: np.ndarray, with_offset: bool):
    """e_k = g_k - q - |p - P_k| for nodes X (..., 2|3) against partners P (K, 2); also p - P and |p - P|."""
    diff = X[..., None, :2] - P
    dist = np.sqrt(np.einsum("...k,...k->...", diff, diff))
    q = X[..., 2:3] if with_offset else 0.0
    return G - q - dist, diff, dist


def _multilaterate(G, P, with_offset, X, c, rng, trials=24, steps=3):
    """Robust batched multilateration of nodes (rows of G) against placed partners P.

    Each node solves g_k - q = |p - P_k| over its measured partners k (G finite): position p (2)
    and, for a transmitter, its offset q. Nodes without an estimate (NaN rows of X) start from the
    best of the all-partner linear solution and `trials` linear solutions of random minimal subsets
    (3 partners for a receiver, 4 for a transmitter), scored by the median e^2 (LMedS); then `steps`
    Cauchy-IRLS Gauss-Newton steps. Nodes with too few partners keep their value.
    """
    N, K = G.shape
    need = 4 if with_offset else 3
    use = np.isfinite(G)
    able = use.sum(axis=1) >= need
    X = X.copy()
    start = np.flatnonzero(able & ~np.isfinite(X[:, 0]))
    if start.size:
        Gs, us = G[start], use[start]
        A, rhs = _linear_system(np.where(us, Gs, 0.0), np.broadcast_to(P, (len(start), K, 2)), with_offset)
        w = us.astype(float)
        full, _ = _solve_batched(np.einsum("nk,nki,nkj->nij", w, A, A), np.einsum("nk,nki,nk->ni", w, A, rhs))
        keys = rng.random((trials, len(start), K))
        keys[:, ~us] = np.inf
        idx = np.argsort(keys, axis=2)[:, :, :need]  # (T, n, need)
        rows = np.arange(len(start))[None, :, None]
        sub, _ = _solve_batched(A[rows, idx].reshape(-1, need, need), rhs[rows, idx].reshape(-1, need))
        cand = np.concatenate([full[None], sub.reshape(trials, len(start), need)])[..., : need - 1]
        e, _, _ = _node_residuals(cand, Gs, P, with_offset)
        # LMedS over the node's partners: needs no noise level and tolerates up to half outliers.
        e2 = np.sort(np.where(us, np.nan_to_num(e, nan=np.inf) ** 2, np.inf), axis=2)
        cost = e2[:, np.arange(len(start)), (us.sum(axis=1) - 1) // 2]
        cost[~np.isfinite(cand).all(axis=2)] = np.inf
        pick = np.argmin(cost, axis=0)
        X[start] = cand[pick, np.arange(len(start))]
    active = np.flatnonzero(able & np.isfinite(X[:, 0]))
    ua = use[active]
    G0 = np.where(ua, G[active], 0.0)
    rows = np.arange(len(active))
    median_index = (ua.sum(axis=1) - 1) // 2
    for _ in range(steps):
        e, diff, dist = _node_residuals(X[active], G0, P, with_offset)
        e = np.where(ua, e, 0.0)
        # Per-node scale max(c, 3 x 1.4826 x median |e|): a badly started node is not frozen by c.
        med = np.sort(np.where(ua, np.abs(e), np.inf), axis=1)[rows, median_index]
        scale = np.maximum(c, 3.0 * _MAD_TO_SIGMA * np.where(np.isfinite(med), med, 0.0))
        w = ua / (1.0 + (e / scale[:, None]) ** 2)  # Cauchy weights, 0 for unmeasured partners
        u = diff / np.maximum(dist, 1e-300)[..., None]
        J = np.concatenate([-u, -np.ones(dist.shape + (1,))], axis=2) if with_offset else -u
        step, good = _solve_batched(np.einsum("nk,nki,nkj->nij", w, J, J), -np.einsum("nk,nki,nk->ni", w, J, e))
        X[active[good]] += step[good]
    return X


def _place(F, mask, R, S, O, c, rng, receivers: bool, fresh=None, refine_all=True, trials=24):
    """Place receivers (receivers=True) or transmitters from their measured placed partners.

    fresh: bool mask of nodes placed from scratch (their current value is dropped); unplaced nodes
    are always placed from scratch. refine_all: IRLS steps on every node, not only the new ones.
    """
    if receivers:
        placed = np.isfinite(S[:, 0])
        G = np.where(mask & placed[None, :], F - O[None, :], np.nan)[:, placed]
        X = R.copy()
        P = S[placed]
    else:
        placed = np.isfinite(R[:, 0])
        G = np.where(mask & placed[:, None], F, np.nan)[placed].T
        X = np.column_stack([S, O])
        P = R[placed]
    if fresh is not None:
        X[fresh] = np.nan
    new = ~np.isfinite(X[:, 0])
    if refine_all:
        X = _multilaterate(G, P, not receivers, X, c, rng, trials)
    elif new.any():
        X[new] = _multilaterate(G[new], P, not receivers, X[new], c, rng, trials)
    if receivers:
        return X, S, O
    return R, X[:, :2].copy(), X[:, 2].copy()


def _extend(F, mask, R, S, O, c, rng, sample_r, best_ratio=None, trials=10):
    """Extend a hypothesis on a sample block (sample_r placed with its transmitters) to the network.

    Receivers from the sample transmitters, transmitters from all receivers, receivers afresh from
    all transmitters (the sample's only refined), then IRLS on all transmitters. Early exit (the
    T(d,d) idea of randomised RANSAC): after the first two passes, a hypothesis explaining fewer than
    half as many measurements as the best one so far is returned partially placed (and scores badly).
    `trials` minimal subsets per node: 10 leave a node with 10 % bad partners misplaced with
    probability ~3e-5 (4-subsets; LMedS picks the clean one).
    """
    R = _place(F, mask, R, S, O, c, rng, True, refine_all=False, trials=trials)[0]
    S, O = _place(F, mask, R, S, O, c, rng, False, refine_all=False, trials=trials)[1:]
    if best_ratio is not None and np.mean(_classify(_residual_matrix(F, R, S, O), mask, c)[mask]) < 0.5 * best_ratio:
        return R, S, O
    R = _place(F, mask, R, S, O, c, rng, True, fresh=~sample_r, trials=trials)[0]
    S, O = _place(F, mask, R, S, O, c, rng, False, trials=trials)[1:]
    return R, S, O


def _fill(F, mask, R, S, O, c, rng):
    """Place the nodes that are still unplaced (NaN), receivers first; placed nodes are kept."""
    R = _place(F, mask, R, S, O, c, rng, True, refine_all=False)[0]
    return (R,) + _place(F, mask, R, S, O, c, rng, False, refine_all=False)[1:]


# --------------------------------------------------------------------------------------------------
# Robust Levenberg-Marquardt on the measured entries (sparse Jacobian)
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Problem:
    """The measured entries between placed nodes, in a gauge-fixed parameterisation.

    rows, cols: placed receivers / transmitters (global indices); local receiver 0 is fixed at the
    origin and local receiver 1 on the x axis; parameters as in solvers.refine.pack:
    [r_1x, r_2x, r_2y, ..., s_0x, s_0y, ..., o_0, ...] (local indices). slots[k] holds the parameter
    columns of entry k's derivatives by (r_x, r_y, s_x, s_y, o); n_params marks a fixed coordinate.
    """

    F: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    ii: np.ndarray  # local receiver index per entry
    jj: np.ndarray  # local transmitter index per entry
    slots: np.ndarray  # (k, 5)

    @property
    def n_params(self) -> int:
        return 2 * len(self.rows) + 3 * len(self.cols) - 3


def _problem(F: np.ndarray, use: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> _Problem:
    ma, na = len(rows), len(cols)
    n_params = 2 * ma + 3 * na - 3
    ii, jj = np.nonzero(use[np.ix_(rows, cols)])
    k0 = 1 + 2 * (ma - 2)
    rx = np.where(ii == 0, n_params, np.where(ii == 1, 0, 1 + 2 * (ii - 2)))
    ry = np.where(ii >= 2, 2 + 2 * (ii - 2), n_params)
    slots = np.stack([rx, ry, k0 + 2 * jj, k0 + 2 * jj + 1, k0 + 2 * na + jj], axis=1)
    return _Problem(F[np.ix_(rows, cols)], rows, cols, ii, jj, slots)


def _unpack(x: np.ndarray, p: _Problem):
    from .refine import unpack  # the same parameter layout as solvers.refine

    return unpack(x, len(p.rows), len(p.cols))


def _pack(R, S, O) -> np.ndarray:
    from .refine import pack

    return pack(R, S, O)


def _entry_residuals(x: np.ndarray, p: _Problem):
    R, S, O = _unpack(x, p)
    diff = R[p.ii] - S[p.jj]
    dist = np.sqrt(np.einsum("ij,ij->i", diff, diff))
    return p.F[p.ii, p.jj] - O[p.jj] - dist, diff, dist


def _jacobian_values(diff: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """(k, 5) derivatives of e_k by (r_x, r_y, s_x, s_y, o) of its receiver and transmitter."""
    u = diff / np.maximum(dist, 1e-300)[:, None]
    return np.column_stack([-u, u, -np.ones(len(dist))])


def _dense_jacobian(p: _Problem, diff: np.ndarray, dist: np.ndarray) -> np.ndarray:
    J = np.zeros((len(dist), p.n_params + 1))
    np.add.at(J, (np.arange(len(dist))[:, None], p.slots), _jacobian_values(diff, dist))
    return J[:, :-1]


def _normal_equations(p: _Problem, diff, dist, w, e) -> tuple[np.ndarray, np.ndarray]:
    """J^T W J and J^T W e, accumulated from the 5 non-zeros per row (no sparse matrices)."""
    v = _jacobian_values(diff, dist)
    size = p.n_params + 1
    idx = (p.slots[:, :, None] * size + p.slots[:, None, :]).ravel()
    A = np.bincount(idx, (w[:, None, None] * v[:, :, None] * v[:, None, :]).ravel(), minlength=size * size)
    g = np.bincount(p.slots.ravel(), ((w * e)[:, None] * v).ravel(), minlength=size)
    return A.reshape(size, size)[:-1, :-1], g[:-1]


def _lm(x: np.ndarray, p: _Problem, loss: Loss, scale: float, max_iter: int):
    """Iteratively reweighted Levenberg-Marquardt for sum rho((e/scale)^2); returns (x, converged, its).

    The gradient J^T W e is exact for the robust cost (W = rho'); the Hessian is the IRLS one, so a
    robust loss converges linearly and gets looser tolerances (it only warm-starts least squares).
    """
    import scipy.linalg

    tol = 1e-12 if loss == "linear" else 1e-8
    xtol = 1e-15 if loss == "linear" else 1e-8  # least squares: iterate to rounding (noiseless data)
    e, diff, dist = _entry_residuals(x, p)

    def cost_of(e):
        return float(np.sum(_loss_rho((e / scale) ** 2, loss)))

    cost = cost_of(e)
    lam = 1e-3
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        A, g = _normal_equations(p, diff, dist, _loss_weights((e / scale) ** 2, loss), e)
        diag = np.diag(A).copy()
        floor = 1e-12 * max(diag.max(initial=0.0), 1e-300)
        improved = False
        while lam < 1e12:
            M = A + lam * np.diag(np.maximum(diag, floor))
            try:
                step = scipy.linalg.cho_solve(scipy.linalg.cho_factor(M, check_finite=False), -g, check_finite=False)
            except (np.linalg.LinAlgError, ValueError):
                lam *= 10.0
                continue
            x_new = x + step
            e_new, diff_new, dist_new = _entry_residuals(x_new, p)
            cost_new = cost_of(e_new) if np.all(np.isfinite(e_new)) else np.inf
            if cost_new <= cost:
                converged = bool(np.linalg.norm(step) <= xtol * (np.linalg.norm(x) + xtol) or cost - cost_new <= tol * cost)
                x, e, diff, dist, cost = x_new, e_new, diff_new, dist_new, cost_new
                lam = max(lam / 5.0, 1e-12)
                improved = True
                break
            lam *= 4.0
        if not improved:
            converged = True  # no descent left at this precision: a (local) minimum
        if converged:
            break
    return x, converged, it


@dataclass(frozen=True)
class _Refined:
    R: np.ndarray
    S: np.ndarray
    O: np.ndarray
    converged: bool
    iterations: int


def _gauge_order(R: np.ndarray, use: np.ndarray) -> np.ndarray:
    """Placed receivers, the two gauge receivers first: the first two (by index) with at least
    MIN_RECEIVER_MEASUREMENTS entries in `use` (else the first two placed), then the rest by index.

    A gauge receiver whose own position the data do not fix would leave the whole network free to
    rotate about it (a rank-deficient fit that wanders off).
    """
    placed = np.flatnonzero(np.isfinite(R[:, 0]))
    good = placed[use[placed].sum(axis=1) >= MIN_RECEIVER_MEASUREMENTS]
    first = list(good[:2]) if len(good) >= 2 else list(placed[:2])
    return np.array(first + [i for i in placed if i not in first], dtype=int)


def robust_refine(F, mask, R, S, O, *, loss: Loss = "soft_l1", scale: float = 1.0, max_iter: int = 100,
                  use: np.ndarray | None = None) -> _Refined:
    """Refine placed nodes on the measured entries `use` (default: all of `mask`) with a robust loss.

    Unplaced nodes (NaN) stay NaN. Returns the refined arrays in the gauge (first placed receiver at
    the origin, second on the x axis), the convergence flag and the iteration count.
    """
    use = mask if use is None else use
    placed_r = _gauge_order(R, use)
    placed_t = np.flatnonzero(np.isfinite(S[:, 0]))
    if len(placed_r) < 2 or len(placed_t) < 1:
        return _Refined(R, S, O, False, 0)
    gauged = to_gauge(R[placed_r], S[placed_t])
    if gauged is None:
        return _Refined(R, S, O, False, 0)
    p = _problem(F, use, placed_r, placed_t)
    if len(p.ii) == 0:
        return _Refined(R, S, O, False, 0)
    x0 = _pack(gauged[0], gauged[1], O[placed_t])
    x, converged, its = _lm(x0, p, loss, scale, max_iter)
    Rl, Sl, Ol = _unpack(x, p)
    R2, S2, O2 = np.full_like(R, np.nan), np.full_like(S, np.nan), np.full_like(O, np.nan)
    R2[placed_r], S2[placed_t], O2[placed_t] = Rl, Sl, Ol
    return _Refined(R2, S2, O2, converged, its)


def _gauge_covariance(F, use, R, S, O, sigma: float):
    """(problem, x, covariance sigma^2 (J^T J)^+, null-space mask) on the entries `use` between placed
    nodes, in the gauge-fixed parameterisation of `_problem`; None if the gauge cannot be fixed."""
    placed_r = _gauge_order(R, use)
    placed_t = np.flatnonzero(np.isfinite(S[:, 0]))
    if len(placed_r) < 2 or len(placed_t) < 1:
        return None
    gauged = to_gauge(R[placed_r], S[placed_t])
    if gauged is None:
        return None
    p = _problem(F, use, placed_r, placed_t)
    x = _pack(gauged[0], gauged[1], O[placed_t])
    _, diff, dist = _entry_residuals(x, p)
    J = _dense_jacobian(p, diff, dist)
    _, s, Vt = np.linalg.svd(J, full_matrices=True)
    s_full = np.zeros(p.n_params)
    s_full[: len(s)] = s
    null = s_full <= 1e-10 * max(s_full[0] if s_full.size else 0.0, 1e-300)
    inv = np.where(null, 0.0, 1.0 / np.where(null, 1.0, s_full) ** 2)
    return p, x, sigma**2 * (Vt.T * inv) @ Vt, null, Vt


def _readmit(F, work, inl, R, S, O, sigma: float, k: float) -> np.ndarray:
    """Rejected entries that the fit predicts within k standard deviations of prediction.

    For an entry left out of the fit the prediction error e has variance sigma^2 + j^T C j (C the
    covariance of the parameters, j the entry's Jacobian row): a weakly determined node predicts
    its own measurements poorly, and a plain |e| <= k sigma test rejects good data there.
    """
    out = np.zeros_like(inl)
    cand = work & ~inl & np.isfinite(R[:, 0])[:, None] & np.isfinite(S[:, 0])[None, :]
    if not cand.any() or not inl.any():
        return out
    cov = _gauge_covariance(F, inl, R, S, O, sigma)
    if cov is None:
        return out
    p, x, C, null, _ = cov
    if null.any():
        return out
    q = _problem(F, cand, p.rows, p.cols)
    e, diff, dist = _entry_residuals(x, q)
    v = _jacobian_values(diff, dist)
    Cp = np.zeros((p.n_params + 1, p.n_params + 1))
    Cp[:-1, :-1] = C
    var = sigma**2 + np.einsum("ka,kab,kb->k", v, Cp[q.slots[:, :, None], q.slots[:, None, :]], v)
    # Only with a full-rank fit (checked above: else the prediction variance is meaningless) and
    # within 3k sigma (a node can be weak, but not arbitrarily wrong).
    ok = (np.abs(e) <= k * np.sqrt(var)) & (np.abs(e) <= 3.0 * k * sigma)
    out[q.rows[q.ii[ok]], q.cols[q.jj[ok]]] = True
    return out


def estimate_covariance(F, use, R, S, O, sigma: float):
    """Gauge-fixed covariance sigma^2 (J^T J)^-1 on the entries `use`, reduced to per-node stds.

    Returns (receiver_std (m,), transmitter_std (n,), offset_std (n,), rank_deficient). Position std
    = sqrt(var_x + var_y); parameters in the null space of J (not determined) get inf; nodes not
    placed get NaN. Gauge: first placed receiver fixed, second placed receiver's y fixed.
    """
    m, n = F.shape
    rstd, tstd, ostd = np.full(m, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    cov = _gauge_covariance(F, use, R, S, O, sigma) if use.any() else None
    if cov is None:
        return rstd, tstd, ostd, True
    p, _, C, null, Vt = cov
    var = np.diag(C).copy()
    deficient = bool(null.any())
    if deficient:
        var[np.linalg.norm(Vt[null], axis=0) > 1e-6] = np.inf
    ma, na = len(p.rows), len(p.cols)
    k0 = 1 + 2 * (ma - 2)
    vr = np.zeros((ma, 2))
    vr[1, 0] = var[0]
    vr[2:] = var[1:k0].reshape(ma - 2, 2)
    rstd[p.rows] = np.sqrt(vr.sum(axis=1))
    tstd[p.cols] = np.sqrt(var[k0 : k0 + 2 * na].reshape(na, 2).sum(axis=1))
    ostd[p.cols] = np.sqrt(var[k0 + 2 * na :])
    return rstd, tstd, ostd, deficient


# --------------------------------------------------------------------------------------------------
# Sampling fully measured sub-blocks
# --------------------------------------------------------------------------------------------------


def _sample_block(mask: np.ndarray, ms: int, ns: int, rng: np.random.Generator, tried: set, attempts: int = 25):
    """A fully measured ms x ns block not tried before, by randomised greedy biclique search.

    Columns are added one at a time, uniformly among those that keep at least ms common measured
    rows, then ms of the common rows are drawn uniformly. (Weighting columns by their overlap
    concentrates the samples on a few dense columns, and on any outlier they hold.)
    Returns (rows, cols) sorted, or None when `attempts` draws found nothing new.
    """
    m, n = mask.shape
    if m < ms or n < ns:
        return None
    for _ in range(attempts):
        rows = np.ones(m, bool)
        cand = np.flatnonzero(mask.sum(axis=0) >= ms)
        chosen = []
        for _ in range(ns):
            overlap = mask[rows][:, cand].sum(axis=0)
            keep = overlap >= ms
            if not keep.any():
                break
            cand = cand[keep]
            k = rng.integers(len(cand))
            chosen.append(int(cand[k]))
            rows &= mask[:, cand[k]]
            cand = np.delete(cand, k)
        if len(chosen) < ns:
            continue
        r = np.sort(rng.choice(np.flatnonzero(rows), ms, replace=False))
        key = (tuple(r.tolist()), tuple(sorted(chosen)))
        if key in tried:
            continue
        tried.add(key)
        return r, np.array(sorted(chosen))
    return None


# --------------------------------------------------------------------------------------------------
# Scoring and LO-RANSAC
# --------------------------------------------------------------------------------------------------


@dataclass
class _Model:
    R: np.ndarray
    S: np.ndarray
    O: np.ndarray
    score: float
    inlier_ratio: float
    refined: bool = False
    converged: bool = False


def _score(E: np.ndarray, mask: np.ndarray, thr: float | None, floor: float) -> tuple[float, float, float]:
    """(score, inlier ratio, threshold) of a residual matrix; lower score is better.

    Known sigma (thr given): MSAC, sum over measured entries of min(e^2, thr^2), unplaced entries
    counting thr^2. Unknown: LMedS, the median of e^2 (unplaced = inf), and thr = 3 x 1.4826 x the
    median |e|, floored.
    """
    e2 = np.where(np.isfinite(E), E * E, np.inf)[mask]
    if e2.size == 0:
        return np.inf, 0.0, thr or floor
    if thr is None:
        med = float(np.median(e2))
        t = max(3.0 * _MAD_TO_SIGMA * math.sqrt(med), floor) if np.isfinite(med) else floor
        return med, float(np.mean(e2 <= t * t)), t
    return float(np.sum(np.minimum(e2, thr * thr))), float(np.mean(e2 <= thr * thr)), thr


def _prune(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Receivers / transmitters that keep enough measurements among each other (iterated)."""
    rows = np.ones(mask.shape[0], bool)
    cols = np.ones(mask.shape[1], bool)
    while True:
        sub = mask & rows[:, None] & cols[None, :]
        new_rows = rows & (sub.sum(axis=1) >= MIN_RECEIVER_MEASUREMENTS)
        new_cols = cols & (sub.sum(axis=0) >= MIN_TRANSMITTER_MEASUREMENTS)
        if (new_rows == rows).all() and (new_cols == cols).all():
            return rows, cols
        rows, cols = new_rows, new_cols


@dataclass
class _Search:
    """Running state of the hypothesis search (counts for the result and the benchmark)."""

    samples: int = 0
    hypotheses: int = 0
    local_optimisations: int = 0
    solvers: set = field(default_factory=set)
    others: list = field(default_factory=list)  # distinct refined models (alternatives)
    runners_up: list = field(default_factory=list)  # unrefined models that did not beat the best


def _replace_weak(F, mask, R, S, O, t, rng):
    """Re-place afresh the nodes that explain fewer than 3/4 of their measurements (at least the
    minimum); keep a new position only where it explains more measurements. Returns (R, S, O, changed)."""
    changed = False
    for receivers in (True, False):
        inl = _classify(_residual_matrix(F, R, S, O), mask, t)
        axis, minimum = (1, MIN_RECEIVER_MEASUREMENTS) if receivers else (0, MIN_TRANSMITTER_MEASUREMENTS)
        placed = np.isfinite(R[:, 0]) if receivers else np.isfinite(S[:, 0])
        weak = placed & (inl.sum(axis=axis) < np.maximum(minimum, 0.75 * mask.sum(axis=axis)))
        if not weak.any():
            continue
        R2, S2, O2 = _place(F, mask, R, S, O, t, rng, receivers, fresh=weak, refine_all=False)
        better = weak & (_classify(_residual_matrix(F, R2, S2, O2), mask, t).sum(axis=axis) > inl.sum(axis=axis))
        if better.any():
            changed = True
            if receivers:
                R = np.where(better[:, None], R2, R)
            else:
                S, O = np.where(better[:, None], S2, S), np.where(better, O2, O)
    return R, S, O, changed


@dataclass(frozen=True)
class _Polished:
    R: np.ndarray
    S: np.ndarray
    O: np.ndarray
    inliers: np.ndarray
    sigma: float
    threshold: float
    converged: bool


def _n_params(R, S) -> int:
    """2m + 3n - 3 over the placed nodes."""
    return 2 * int(np.isfinite(R[:, 0]).sum()) + 3 * int(np.isfinite(S[:, 0]).sum()) - 3


def _estimate_sigma(E, mask, inliers, n_params: int, k: float, floor: float) -> float:
    """Noise level from residuals of a fit with n_params parameters.

    Without an inlier set: 1.4826 x the median |e| over the measured entries. With one (a least
    squares fit on it): sqrt(SSR / N) over the inliers, divided by the standard deviation of a unit
    Gaussian truncated at +-k (the threshold cut the tails). Both are scaled by sqrt(N / (N - p)):
    residuals of a fit keep N - p degrees of freedom. Without these corrections the estimate
    shrinks round after round (classify at k sigma, refit, re-estimate) and rejects good data.
    """
    use = mask & np.isfinite(E) if inliers is None else inliers
    N = int(use.sum())
    if N == 0:
        return floor / k
    dof_factor = N / (N - n_params) if N > n_params else 1.0
    if inliers is None:
        sig = _MAD_TO_SIGMA * float(np.median(np.abs(E[use]))) * math.sqrt(dof_factor)
    else:
        truncated = 1.0 - 2.0 * k * math.exp(-0.5 * k * k) / math.sqrt(2.0 * math.pi) / math.erf(k / math.sqrt(2.0))
        sig = math.sqrt(float(np.sum(E[use] ** 2)) / N * dof_factor / truncated)
    return max(sig, floor / k)


def _polish(F, mask, R, S, O, thr, floor, opts: CalibrationOptions, rng, max_iter: int, rounds: int) -> _Polished:
    """Robust LM on all measured entries, placement of unplaced and badly placed nodes, then
    least squares on the inliers, re-classifying (and re-estimating sigma when unknown) for up to
    `rounds` rounds or until the inlier set is stable. The local optimisation of LO-RANSAC with
    rounds=1; the final refinement with more."""
    _, _, t = _score(_residual_matrix(F, R, S, O), mask, thr, floor)
    ref = robust_refine(F, mask, R, S, O, loss=opts.loss, scale=t / opts.threshold_sigmas, max_iter=max_iter)
    R, S, O = _fill(F, mask, ref.R, ref.S, ref.O, t, rng)
    converged = ref.converged
    _, _, t = _score(_residual_matrix(F, R, S, O), mask, thr, floor)
    R, S, O, changed = _replace_weak(F, mask, R, S, O, t, rng)
    if changed:
        ref = robust_refine(F, mask, R, S, O, loss=opts.loss, scale=t / opts.threshold_sigmas, max_iter=max_iter)
        R, S, O, converged = ref.R, ref.S, ref.O, ref.converged
    E = _residual_matrix(F, R, S, O)
    if thr is None:
        sig = _estimate_sigma(E, mask, None, _n_params(R, S), opts.threshold_sigmas, floor)
    else:
        sig = thr / opts.threshold_sigmas
    inl = None
    for round_ in range(rounds):
        # Unknown sigma: the first cut is twice as wide, because the median residual of a robust fit
        # with many parameters per measurement under-estimates sigma; least squares on those inliers
        # then gives sigma from the sum of squares, and the later rounds cut at threshold_sigmas.
        k = opts.threshold_sigmas * (2.0 if thr is None and round_ == 0 else 1.0)
        t = max(k * sig, floor)
        new = _classify(E, mask, t)
        if inl is not None and (new == inl).all():
            break
        inl = new
        fin = robust_refine(F, mask, R, S, O, loss="linear", scale=1.0, max_iter=max_iter, use=inl)
        R, S, O, converged = fin.R, fin.S, fin.O, converged and fin.converged
        E = _residual_matrix(F, R, S, O)
        if thr is None:
            sig = _estimate_sigma(E, mask, inl, _n_params(R, S), k, floor)
    t = max(opts.threshold_sigmas * sig, floor)
    return _Polished(R, S, O, _classify(E, mask, t), sig, t, converged)


def _local_optimisation(F, mask, model: _Model, thr, floor, opts: CalibrationOptions, rng) -> _Model:
    """LO step of LO-RANSAC: `_polish` with a small budget, rescored."""
    out = _polish(F, mask, model.R, model.S, model.O, thr, floor, opts, rng, opts.lo_iterations, rounds=1)
    score, ratio, _ = _score(_residual_matrix(F, out.R, out.S, out.O), mask, thr, floor)
    return _Model(out.R, out.S, out.O, score, ratio, True, out.converged)


def _hypotheses_from_block(F, mask, solver: MinimalSolver, rows, cols, thr, floor, opts, rng, search: _Search,
                           best_ratio: float | None = None):
    """Candidates of one sub-block, extended to the network and scored.

    Only candidates whose block RMS is within 10x of the best one (or below the threshold) are
    extended, at most `candidates_per_sample` of them; a minimal solver's roots all fit the block
    exactly (RMS cannot rank them), so up to `minimal_candidates` of those.
    """
    block = F[np.ix_(rows, cols)]
    cands = solver.solve(block)
    search.samples += 1
    if not cands:
        return []
    rms = np.array([float(np.sqrt(np.mean(_residual_matrix(block, *c) ** 2))) for c in cands])
    rms[~np.isfinite(rms)] = np.inf
    best_rms = float(rms.min())
    if not np.isfinite(best_rms):
        return []
    # Unknown sigma: a clean block's RMS is about 0.35 sigma (3 redundant entries of 24 or 27).
    c = thr if thr is not None else max(floor, 8.0 * best_rms)
    minimal = solver.m * solver.n == 2 * solver.m + 3 * solver.n - 3
    per_sample = opts.minimal_candidates if minimal else opts.candidates_per_sample
    keep = [k for k in np.argsort(rms)[:per_sample] if rms[k] <= max(10.0 * best_rms, c)]
    return _extended_hypotheses(F, mask, [cands[k] for k in keep], rows, cols, c, thr, floor, rng, search, best_ratio)


def _extended_hypotheses(F, mask, cands, rows, cols, c, thr, floor, rng, search: _Search, best_ratio):
    """Block solutions (R_b, S_b, O_b on rows x cols) polished on the block's measured entries,
    deduplicated, extended to the network (`_extend`) and scored."""
    m, n = F.shape
    block = F[np.ix_(rows, cols)]
    sample_r = np.zeros(m, bool)
    sample_r[rows] = True
    out = []
    block_mask = np.isfinite(block)
    seen: list[np.ndarray] = []
    for cand in cands:
        R, S, O = np.full((m, 2), np.nan), np.full((n, 2), np.nan), np.full(n, np.nan)
        # A few least-squares steps on the block: on noisy data the solver's root satisfies a subset
        # of the equations exactly, and its error grows when extended; the block optimum is better.
        pol = robust_refine(block, block_mask, *cand, loss="linear", max_iter=4)
        R[rows], S[cols], O[cols] = (pol.R, pol.S, pol.O) if np.all(np.isfinite(pol.R)) else cand
        if any(np.allclose(O[cols], o, rtol=1e-9, atol=1e-9 * (1.0 + np.abs(o).max())) for o in seen):
            continue  # two roots polished into the same block solution
        seen.append(O[cols].copy())
        R, S, O = _extend(F, mask, R, S, O, c, rng, sample_r, best_ratio)
        score, ratio, _ = _score(_residual_matrix(F, R, S, O), mask, thr, floor)
        search.hypotheses += 1
        out.append(_Model(R, S, O, score, ratio))
    return out


def _sample_subnetwork(mask: np.ndarray, rng: np.random.Generator, tried: set | None, suspicious: np.ndarray | None = None,
                       redundancy: int = 2, attempts: int = 20):
    """A random sub-network (gaps allowed) that determines its nodes with little redundancy.

    Unguided (suspicious None or empty): nodes are left out one at a time in random order as long
    as the rest keeps at least `redundancy` (or, drawn at random, one more) measured entries more
    than unknowns, so that the sub-network holds as few measurements (and gross errors) as can
    still expose one. Guided: for up to 3 of the `suspicious` entries (an (k, 2) array of
    (receiver, transmitter), e.g. the current best's rejected measurements) the receiver or the
    transmitter is left out, at random. Nodes left with too few measurements among the rest are
    pruned (`_prune`) in both cases. Returns (rows, cols) as index arrays when the sub-network is
    valid and not in `tried` (None: repeats allowed), else None.
    Leaving nodes out, not entries, is what lets a sub-network avoid a node's gross error when no
    fully measured block does (low-redundancy networks with gaps).
    """
    m, n = mask.shape

    def pruned(rows, cols):
        keep_r, keep_c = _prune(mask & rows[:, None] & cols[None, :])
        keep_r &= rows
        keep_c &= cols
        sub = mask & keep_r[:, None] & keep_c[None, :]
        ok = keep_r.sum() >= 3 and keep_c.sum() >= 3
        return keep_r, keep_c, int(sub.sum()) - (2 * int(keep_r.sum()) + 3 * int(keep_c.sum()) - 3) if ok else -1

    for _ in range(attempts):
        rows, cols = np.ones(m, bool), np.ones(n, bool)
        if suspicious is not None and len(suspicious):
            pick = suspicious[rng.permutation(len(suspicious))[: int(rng.integers(1, min(3, len(suspicious)) + 1))]]
            by_row = rng.random(len(pick)) < 0.5
            rows[pick[by_row, 0]] = False
            cols[pick[~by_row, 1]] = False
            rows, cols, spare = pruned(rows, cols)
        else:
            target = redundancy + int(rng.integers(0, 2))
            rows, cols, spare = pruned(rows, cols)
            for node in rng.permutation(m + n):
                r2, c2 = rows.copy(), cols.copy()
                if node < m:
                    r2[node] = False
                else:
                    c2[node - m] = False
                r2, c2, spare2 = pruned(r2, c2)
                if spare2 >= target:
                    rows, cols, spare = r2, c2, spare2
        if spare < redundancy:
            continue
        key = ("subnetwork", tuple(np.flatnonzero(rows).tolist()), tuple(np.flatnonzero(cols).tolist()))
        if tried is not None and key in tried:
            continue
        if tried is not None:
            tried.add(key)
        return np.flatnonzero(rows), np.flatnonzero(cols)
    return None


def _random_start(F, mask, rows, cols, rng):
    """Receivers, transmitters and offsets of rows x cols drawn at the scale of the data."""
    spread = float(np.percentile(F[mask], 90) - np.percentile(F[mask], 10)) or 1.0
    sub = F[np.ix_(rows, cols)]
    centre = np.array([np.median(v[np.isfinite(v)]) for v in sub.T])
    return (0.5 * spread * rng.standard_normal((len(rows), 2)), 0.5 * spread * rng.standard_normal((len(cols), 2)),
            centre - 0.5 * spread + 0.1 * spread * rng.standard_normal(len(cols)))


def _hypotheses_from_subnetwork(F, mask, rows, cols, thr, floor, opts, rng, search: _Search, best_ratio,
                                start: _Model | None = None):
    """Least squares on a sub-network's measured entries, extended and scored.

    The multi-start local optimisation of a non-minimal sample: it needs no fully measured block
    and costs milliseconds for a small network. It starts from `start` (the current best, whose
    gross errors the sub-network may leave out) where that places every node of the sub-network,
    else from a random start. A fit whose RMS on its own entries exceeds the threshold (a gross
    error inside, or a local minimum) is not extended.
    """
    block = F[np.ix_(rows, cols)]
    sub_mask = np.isfinite(block)
    search.samples += 1
    x0 = None
    if start is not None:
        x0 = start.R[rows], start.S[cols], start.O[cols]
        if not all(np.isfinite(a).all() for a in x0):
            x0 = None
    # Least squares first: a redescending loss far from any solution gives every entry the same tiny
    # weight and stalls; near a basin, the LO step's robust loss then sheds the outliers.
    ls = robust_refine(block, sub_mask, *(x0 or _random_start(F, mask, rows, cols, rng)), loss="linear",
                       max_iter=3 * opts.lo_iterations)
    if not np.all(np.isfinite(ls.R)):
        return []
    rms = float(np.sqrt(np.mean(_residual_matrix(block, ls.R, ls.S, ls.O)[sub_mask] ** 2)))
    if thr is not None and not rms <= thr:
        return []
    c = thr if thr is not None else max(floor, 8.0 * rms)
    return _extended_hypotheses(F, mask, [(ls.R, ls.S, ls.O)], rows, cols, c, thr, floor, rng, search, best_ratio)


def _better(a: _Model, b: _Model, floor: float) -> bool:
    """Whether model a beats b: a lower score, or (a tie within floor^2, as LMedS gives on noiseless
    data when more than half of the entries fit two models exactly) a higher inlier ratio."""
    if abs(a.score - b.score) <= floor * floor:
        return a.inlier_ratio > b.inlier_ratio
    return a.score < b.score


def _needed(w: float, k: int, confidence: float, success: float = 1.0) -> float:
    """Samples for an all-inlier sample of k entries (and a `success`ful solve) with this confidence."""
    p = success * w**k
    if p >= 1.0:
        return 0.0
    return math.log(1.0 - confidence) / math.log1p(-p) if p > 0 else math.inf


def _ransac(F, mask, thr, floor, opts: CalibrationOptions, rng, solvers) -> tuple[_Model | None, _Search]:
    """LO-RANSAC over the minimal solvers on fully measured sub-blocks, then over sub-networks solved
    by least squares from random starts (see module docstring)."""
    search = _Search()
    best: _Model | None = None

    def offer(models) -> bool:
        """Keep the best model (LO on each new best, up to the budget); True when the best changed."""
        nonlocal best
        changed = False
        for model in models:
            if best is not None and not _better(model, best, floor):
                if not model.refined and np.isfinite(model.score):
                    search.runners_up = sorted(search.runners_up + [model], key=lambda x: x.score)[: opts.runners_up]
                continue
            if search.local_optimisations < opts.max_local_optimisations:
                search.local_optimisations += 1
                lo = _local_optimisation(F, mask, model, thr, floor, opts, rng)
                if lo.score <= model.score:
                    model = lo
            if best is not None and best.refined:
                search.others.append(best)
            best, changed = model, True
        return changed

    needed = math.inf
    tried: set = set()
    exhausted: set = set()
    drawn_by: dict[str, int] = {}
    # min_samples guards against trusting one lucky sample, unless a hypothesis explains every entry.
    while search.samples < (max(needed, opts.min_samples) if needed > 0 else 0) and search.samples < opts.max_samples:
        drawn = None
        for solver in solvers:
            if solver.label in exhausted or solver.cost_ms > opts.max_solver_cost:
                continue
            if solver.cost_ms > opts.expensive_cost and drawn_by.get(solver.label, 0) >= opts.expensive_samples:
                continue
            block = _sample_block(mask, solver.m, solver.n, rng, tried)
            if block is None:
                exhausted.add(solver.label)
                continue
            drawn = (solver, block)
            break
        if drawn is None:
            break
        solver, (rows, cols) = drawn
        search.solvers.add(solver.label)
        drawn_by[solver.label] = drawn_by.get(solver.label, 0) + 1
        if offer(_hypotheses_from_block(F, mask, solver, rows, cols, thr, floor, opts, rng, search,
                                        best.inlier_ratio if best is not None else None)):
            needed = _needed(best.inlier_ratio, solver.m * solver.n, opts.confidence)

    confident = best is not None and (needed == 0 or search.samples >= max(needed, opts.min_samples))
    small = _n_params_mask(mask) <= opts.subnetwork_max_params
    if confident or (best is not None and not small and search.samples >= opts.min_samples):
        return best, search
    # Sub-networks: the blocks ran out before the adaptive count was reached in a small network (few
    # fully measured blocks, low redundancy), or there were too few blocks at all.
    search.solvers.add("subnetworks")
    search.local_optimisations = min(search.local_optimisations, opts.max_local_optimisations // 2)
    k = max(int(mask.sum() * 0.75), 1)  # entries of a typical sub-network
    needed_sub = _needed(best.inlier_ratio, k, opts.confidence, opts.subnetwork_convergence) if best else math.inf
    drawn_sub = 0
    while drawn_sub < min(needed_sub, opts.subnetwork_samples):
        # Every other draw is guided by the best model so far: it leaves out the node of one of its
        # rejected measurements and starts from it (a best model with a gross error inside is often
        # in the right basin but pulled off it).
        guided = best is not None and drawn_sub % 2 == 1
        suspicious = None
        if guided:
            _, _, t = _score(_residual_matrix(F, best.R, best.S, best.O), mask, thr, floor)
            suspicious = np.argwhere(mask & ~_classify(_residual_matrix(F, best.R, best.S, best.O), mask, t))
        # Unguided draws may repeat a sub-network: each gets a new random start.
        block = _sample_subnetwork(mask, rng, tried if guided else None, suspicious)
        if block is None:
            if guided:
                drawn_sub += 1
                continue
            # No redundant sub-network (e.g. as many measurements as unknowns): random starts on all.
            block = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        drawn_sub += 1
        if offer(_hypotheses_from_subnetwork(F, mask, *block, thr, floor, opts, rng, search,
                                             best.inlier_ratio if best is not None else None,
                                             best if guided else None)):
            needed_sub = _needed(best.inlier_ratio, k, opts.confidence, opts.subnetwork_convergence)
    # The runners-up get their local optimisation too: with low redundancy a hypothesis in the right
    # basin, pulled off by a gross error, can score worse than a wrong one before LO and better after.
    for model in search.runners_up:
        lo = _local_optimisation(F, mask, model, thr, floor, opts, rng)
        search.local_optimisations += 1
        if best is None or _better(lo, best, floor):
            if best is not None and best.refined:
                search.others.append(best)
            best = lo
    return best, search


def _n_params_mask(mask: np.ndarray) -> int:
    """Unknowns 2m + 3n - 3 of the nodes that have measurements."""
    return 2 * int(mask.any(axis=1).sum()) + 3 * int(mask.any(axis=0).sum()) - 3


# --------------------------------------------------------------------------------------------------
# Final refinement, classification, flags
# --------------------------------------------------------------------------------------------------


def _classify(E, mask, t):
    return mask & (np.abs(E) <= t)  # NaN (missing, unplaced) compares False


def _principal_ratio(P: np.ndarray) -> float:
    """Smaller / larger principal spread of a point set (0 = collinear)."""
    P = P[np.isfinite(P[:, 0])]
    if len(P) < 3:
        return 0.0
    s = np.linalg.svd(P - P.mean(axis=0), compute_uv=False)
    return float(s[1] / s[0]) if s[0] > 0 else 0.0


def _reflect_across_line(x: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Reflection of point x across the principal line of the points P."""
    c = P.mean(axis=0)
    _, _, Vt = np.linalg.svd(P - c)
    d = Vt[0]
    v = x - c
    return c + 2.0 * (v @ d) * d - v


def _mirror_alternatives(F, inl, R, S, O) -> list[tuple[str, int, np.ndarray, float, float]]:
    """For every placed node: its mirror image across the principal line of its inlier partners,
    re-fitted to those measurements by Gauss-Newton (partners fixed).

    Returns (kind "receiver"/"transmitter", index, alternative (x, y[, offset]), SSR of the
    alternative, SSR of the current position) per node with enough partners (flip ambiguity).
    """
    out = []
    for kind, X, partners in (("receiver", R, S), ("transmitter", np.column_stack([S, O]), R)):
        with_offset = kind == "transmitter"
        for k in np.flatnonzero(np.isfinite(X[:, 0])):
            idx = np.flatnonzero(inl[:, k] if with_offset else inl[k])
            if len(idx) < (3 if with_offset else 2):
                continue
            G = F[idx, k] if with_offset else F[k, idx] - O[idx]
            P = partners[idx]
            alt = X[k].copy()
            alt[:2] = _reflect_across_line(X[k, :2], P)
            for _ in range(8):
                e, diff, dist = _node_residuals(alt, G, P, with_offset)
                u = diff / np.maximum(dist, 1e-300)[:, None]
                J = np.column_stack([-u, -np.ones(len(idx))]) if with_offset else -u
                alt = alt + np.linalg.lstsq(J, -e, rcond=None)[0]
            e_alt = _node_residuals(alt, G, P, with_offset)[0]
            e_now = _node_residuals(X[k], G, P, with_offset)[0]
            out.append((kind, int(k), alt, float(np.sum(e_alt**2)), float(np.sum(e_now**2))))
    return out


def _mirror_warnings(F, inl, R, S, O, sigma, rstd, tstd, opts, floor) -> list[str]:
    """Nodes whose mirror image across the line of their partners fits nearly as well."""
    out = []
    var = max(sigma, floor) ** 2
    for kind, k, alt, ssr_alt, ssr_now in _mirror_alternatives(F, inl, R, S, O):
        X, std = (R, rstd) if kind == "receiver" else (S, tstd)
        delta = (ssr_alt - ssr_now) / var
        apart = np.linalg.norm(alt[:2] - X[k]) > max(3.0 * np.nan_to_num(std[k], nan=0.0, posinf=0.0), 1e3 * floor)
        if apart and delta < opts.ambiguity_chi2:
            partners = "transmitters" if kind == "receiver" else "receivers"
            out.append(f"{kind} {k + 1}: its mirror position ({alt[0]:.4g}, {alt[1]:.4g}) across the line of its "
                       f"{partners} fits its measurements as well (cost {delta:+.2g} sigma^2)")
    return out


def _repair_flips(F, inl, R, S, O, sigma, floor):
    """Move every node whose re-fitted mirror position explains its inliers better by > 1 sigma^2.

    Returns (R, S, O, changed). A flipped node is a local minimum of the joint cost that the
    refinement cannot leave (the other side is beyond a ridge); the mirror test finds the other side.
    """
    var = max(sigma, floor) ** 2
    R, S, O = R.copy(), S.copy(), O.copy()
    changed = False
    for kind, k, alt, ssr_alt, ssr_now in _mirror_alternatives(F, inl, R, S, O):
        if ssr_alt < ssr_now - var and np.all(np.isfinite(alt)):
            changed = True
            if kind == "receiver":
                R[k] = alt
            else:
                S[k], O[k] = alt[:2], alt[2]
    return R, S, O, changed


def _distinct(a: _Model, b: _Model, tol: float) -> bool:
    """True when two models differ beyond a rigid motion (reflections allowed)."""
    from .metrics import align_rigid

    ok = np.isfinite(a.R[:, 0]) & np.isfinite(b.R[:, 0])
    okt = np.isfinite(a.S[:, 0]) & np.isfinite(b.S[:, 0])
    X = np.vstack([a.R[ok], a.S[okt]])
    Y = np.vstack([b.R[ok], b.S[okt]])
    if len(X) < 3:
        return False
    aligned = align_rigid(X, Y).apply(X)
    return float(np.linalg.norm(aligned - Y) / max(np.linalg.norm(Y - Y.mean(axis=0)), 1e-300)) > tol


def _failed(F, message, t0, seed, search: _Search | None = None, warnings=()) -> CalibrationResult:
    m, n = F.shape
    nan = np.full
    return CalibrationResult(
        status="failed", message=message, receivers=nan((m, 2), np.nan), transmitters=nan((n, 2), np.nan),
        offsets=nan(n, np.nan), inliers=np.zeros((m, n), bool), residuals=nan((m, n), np.nan), rms=float("nan"),
        sigma=float("nan"), sigma_estimated=True, receiver_std=nan(m, np.nan), transmitter_std=nan(n, np.nan),
        offset_std=nan(n, np.nan), warnings=tuple(warnings),
        solver="+".join(sorted(search.solvers)) if search else "", samples=search.samples if search else 0,
        hypotheses=search.hypotheses if search else 0, seconds=time.perf_counter() - t0, seed=seed,
    )


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


def calibrate(F, sigma: float | None = None, *, seed: int | None = 0,
              options: CalibrationOptions | None = None) -> CalibrationResult:
    """Calibrate a 2D TDOA network from measurements F[i, j] = |r_i - s_j| + o_j (+ noise, gross errors).

    Parameters
    ----------
    F : (m, n) array-like; NaN marks a missing measurement.
    sigma : noise standard deviation of the inlier measurements (units of F); None = estimate it
        robustly (median absolute residual of the best hypothesis, then the inlier RMS).
    seed : seed of numpy.random.default_rng for the sampling; the same seed gives the same result.
    options : CalibrationOptions (thresholds, RANSAC budget, loss).

    Returns
    -------
    CalibrationResult (status "ok", "unconverged" or "failed"; see there). Never raises for data
    that merely cannot be calibrated; raises ValueError for malformed input (not 2-D, not numeric,
    infinite values) or a negative sigma.

    Reference: the paper's pipeline (Sec. 3) inside LO-RANSAC with extension and robust refinement
    (Larsson et al., EUSIPCO 2021); see the module docstring.
    """
    t0 = time.perf_counter()
    opts = options or CalibrationOptions()
    F = _check_input(F)
    if sigma is not None and not (sigma >= 0 and np.isfinite(sigma)):
        raise ValueError(f"sigma must be a finite number >= 0, got {sigma}")
    m, n = F.shape
    mask = np.isfinite(F)
    rng = np.random.default_rng(seed)
    warnings: list[str] = []

    rows_ok, cols_ok = _prune(mask)
    for i in np.flatnonzero(~rows_ok):
        warnings.append(f"receiver {i + 1}: only {int(mask[i].sum())} measured transmitters usable "
                        f"(needs {MIN_RECEIVER_MEASUREMENTS}); not placed")
    for j in np.flatnonzero(~cols_ok):
        warnings.append(f"transmitter {j + 1}: only {int(mask[:, j].sum())} measured receivers usable "
                        f"(needs {MIN_TRANSMITTER_MEASUREMENTS}); not placed")
    work = mask & rows_ok[:, None] & cols_ok[None, :]
    n_params = 2 * int(rows_ok.sum()) + 3 * int(cols_ok.sum()) - 3
    if rows_ok.sum() < 3 or cols_ok.sum() < 3 or work.sum() < n_params:
        return _failed(F, f"too few measurements: {int(work.sum())} usable entries between {int(rows_ok.sum())} "
                       f"receivers and {int(cols_ok.sum())} transmitters for {max(n_params, 0)} unknowns",
                       t0, seed, warnings=warnings)
    if work.sum() == n_params:
        warnings.append(f"no redundancy: {n_params} measurements for {n_params} unknowns; the solution may not "
                        "be unique and outliers cannot be detected")

    data_scale = float(np.max(np.abs(F[work]))) or 1.0
    floor = 1e-9 * data_scale
    thr = None if sigma is None else max(opts.threshold_sigmas * sigma, floor)

    best, search = _ransac(F, work, thr, floor, opts, rng, available_solvers())
    if best is None:
        return _failed(F, "no hypothesis: every minimal-solver sample and sub-network fit failed (degenerate geometry?)",
                       t0, seed, search, warnings)

    # Final refinement: robust LM, badly placed nodes afresh, least squares on the inliers until stable.
    fin = _polish(F, work, best.R, best.S, best.O, thr, floor, opts, rng, opts.max_iterations, rounds=4)
    R, S, O, flipped = _repair_flips(F, fin.inliers, fin.R, fin.S, fin.O, fin.sigma, floor)
    if flipped:
        fin = _polish(F, work, R, S, O, thr, floor, opts, rng, opts.max_iterations, rounds=4)
    R, S, O, inl, sig, converged = fin.R, fin.S, fin.O, fin.inliers, fin.sigma, fin.converged
    for _ in range(3):  # rejected measurements that a weakly determined node predicts that badly anyway
        readmit = _readmit(F, work, inl, R, S, O, max(sig, floor / opts.threshold_sigmas), opts.threshold_sigmas)
        if not readmit.any():
            break
        inl = inl | readmit
        ls = robust_refine(F, work, R, S, O, loss="linear", max_iter=opts.max_iterations, use=inl)
        R, S, O, converged = ls.R, ls.S, ls.O, ls.converged
    R, S, O, inl, converged = _refit_with_moderate_rejects(F, work, R, S, O, inl, sig, floor, opts, converged)
    R, S, O, inl, dropped, ls = _drop_undetermined(F, work, R, S, O, inl, opts.max_iterations)
    warnings += dropped
    if ls is not None:
        converged = ls.converged
    E = _residual_matrix(F, R, S, O)
    rms = float(np.sqrt(np.mean(E[inl] ** 2))) if inl.any() else float("nan")

    # Gauge of the report: receiver 1 at 0 and receiver 2 on +x, or the first two receivers with
    # enough inliers (see _gauge_order); the covariance uses the same gauge.
    placed_r, placed_t = np.isfinite(R[:, 0]), np.isfinite(S[:, 0])
    order = _gauge_order(R, inl)
    gauged = to_gauge(R[order], S[placed_t]) if len(order) >= 2 else None
    if gauged is not None:
        R[order], S[placed_t] = gauged

    sig_cov = max(sig, floor / opts.threshold_sigmas)
    rstd, tstd, ostd, deficient = estimate_covariance(F, inl, R, S, O, sig_cov)
    warnings += _flags(F, work, inl, R, S, O, sig_cov, rstd, tstd, opts, floor, deficient, search, best,
                       sigma, rms, already=tuple(warnings))

    status: Status = "ok"
    reasons = []
    if not converged:
        reasons.append("the refinement did not converge within its iteration budget")
    spread = float(np.nanmax(np.abs(np.vstack([R[placed_r], S[placed_t]])))) if placed_r.any() else np.inf
    if not np.isfinite(spread) or spread > 1e3 * data_scale:
        reasons.append(f"the solution diverged (coordinates up to {spread:.3g}, data scale {data_scale:.3g})")
    inlier_fraction = float(inl.sum() / max(work.sum(), 1))
    if inlier_fraction < 0.5:
        reasons.append(f"only {100 * inlier_fraction:.0f} % of the measurements are inliers")
    if reasons:
        status = "unconverged"
        warnings.insert(0, "; ".join(reasons))
    n_out = int(work.sum() - inl.sum())
    message = (f"{status}: {int(placed_r.sum())}/{m} receivers, {int(placed_t.sum())}/{n} transmitters placed; "
               f"{int(inl.sum())} inliers, {n_out} rejected, {int((~mask).sum())} missing; rms {rms:.3g}; "
               f"{len(warnings)} warning(s)")
    return CalibrationResult(
        status=status, message=message, receivers=R, transmitters=S, offsets=O, inliers=inl, residuals=E,
        rms=rms, sigma=float(sig), sigma_estimated=sigma is None,
        receiver_std=rstd, transmitter_std=tstd, offset_std=ostd, warnings=tuple(warnings),
        solver="+".join(sorted(search.solvers)), samples=search.samples, hypotheses=search.hypotheses,
        seconds=time.perf_counter() - t0, seed=seed,
    )


def _refit_with_moderate_rejects(F, work, R, S, O, inl, sigma, floor, opts, converged):
    """Refit with the rejected entries within 3k sigma added back; keep the refit if it keeps every
    inlier and gains some (at the threshold k sigma).

    The robust stage can settle a weakly determined node where a few good measurements look like
    outliers, and least squares without them never comes back (a self-consistent split).
    """
    t = max(opts.threshold_sigmas * sigma, floor)
    E = _residual_matrix(F, R, S, O)
    cand = work & ~inl & (np.abs(E) <= 3.0 * t)
    if not cand.any():
        return R, S, O, inl, converged
    fit = robust_refine(F, work, R, S, O, loss="linear", max_iter=opts.max_iterations, use=inl | cand)
    new = _classify(_residual_matrix(F, fit.R, fit.S, fit.O), work, t)
    if (new | ~inl).all() and new.sum() > inl.sum():
        fit = robust_refine(F, work, fit.R, fit.S, fit.O, loss="linear", max_iter=opts.max_iterations, use=new)
        return fit.R, fit.S, fit.O, new, fit.converged
    return R, S, O, inl, converged


def _drop_undetermined(F, work, R, S, O, inl, max_iter):
    """Unplace nodes with fewer inlier measurements than they need (3 / 4), repeatedly, and refit the
    rest by least squares on the inliers. A node the data do not fix would otherwise be reported at an
    arbitrary place and keep the refinement from converging. Returns (R, S, O, inl, warnings, fit)."""
    R, S, O, inl = R.copy(), S.copy(), O.copy(), inl.copy()
    out = []
    while True:
        weak_r = np.isfinite(R[:, 0]) & (inl.sum(axis=1) < MIN_RECEIVER_MEASUREMENTS)
        weak_t = np.isfinite(S[:, 0]) & (inl.sum(axis=0) < MIN_TRANSMITTER_MEASUREMENTS)
        if not (weak_r.any() or weak_t.any()):
            break
        for i in np.flatnonzero(weak_r):
            out.append(f"receiver {i + 1}: only {int(inl[i].sum())} of its {int(work[i].sum())} measurements are "
                       f"inliers (needs {MIN_RECEIVER_MEASUREMENTS}); not placed")
        for j in np.flatnonzero(weak_t):
            out.append(f"transmitter {j + 1}: only {int(inl[:, j].sum())} of its {int(work[:, j].sum())} measurements "
                       f"are inliers (needs {MIN_TRANSMITTER_MEASUREMENTS}); not placed")
        R[weak_r], S[weak_t], O[weak_t] = np.nan, np.nan, np.nan
        inl[weak_r], inl[:, weak_t] = False, False
    if not out:
        return R, S, O, inl, out, None
    ls = robust_refine(F, work, R, S, O, loss="linear", max_iter=max_iter, use=inl)
    return ls.R, ls.S, ls.O, inl, out, ls


def _flags(F, work, inl, R, S, O, sigma, rstd, tstd, opts, floor, deficient, search, best, sigma_given, rms,
           already=()):
    """Warnings for what the data cannot decide (see CalibrationResult.warnings)."""
    out = []
    placed_r, placed_t = np.isfinite(R[:, 0]), np.isfinite(S[:, 0])
    for i in np.flatnonzero(~placed_r & work.any(axis=1)):
        if not any(w.startswith(f"receiver {i + 1}: ") for w in already):
            out.append(f"receiver {i + 1}: could not be placed from its measurements")
    for j in np.flatnonzero(~placed_t & work.any(axis=0)):
        if not any(w.startswith(f"transmitter {j + 1}: ") for w in already):
            out.append(f"transmitter {j + 1}: could not be placed from its measurements")
    ratio = _principal_ratio(R)
    if ratio < opts.collinear_ratio:
        out.append(f"receivers are nearly collinear (spread ratio {ratio:.2g}): transmitters have mirror "
                   "positions across their line that fit about as well")
    ratio = _principal_ratio(S)
    if ratio < opts.collinear_ratio:
        out.append(f"transmitters are nearly collinear (spread ratio {ratio:.2g}): receivers have mirror "
                   "positions across their line that fit about as well")
    n_in, rejected = int(inl.sum()), int((work & ~inl & placed_r[:, None] & placed_t[None, :]).sum())
    redundancy = n_in - (2 * int(placed_r.sum()) + 3 * int(placed_t.sum()) - 3)
    if rejected and redundancy <= 3 * rejected:
        out.append(f"low redundancy: {n_in} inliers for {n_in - redundancy} unknowns with {rejected} measurements "
                   "rejected; another choice of rejected measurements may fit as well")
    if deficient:
        out.append("the Jacobian on the inliers is rank-deficient: some coordinates are not determined by the data "
                   "(their std is inf)")
    out += _mirror_warnings(F, inl, R, S, O, sigma, rstd, tstd, opts, floor)
    # An alternative hypothesis (after local optimisation) of similar cost that is a different network.
    var = max(sigma, floor) ** 2
    best_cost = float(np.sum(np.minimum(_residual_matrix(F, R, S, O)[work] ** 2, (opts.threshold_sigmas ** 2) * var)))
    for other in search.others:
        E = _residual_matrix(F, other.R, other.S, other.O)[work]
        cost = float(np.sum(np.minimum(np.nan_to_num(E, nan=np.inf) ** 2, (opts.threshold_sigmas ** 2) * var)))
        if (cost - best_cost) / var < opts.ambiguity_chi2 and _distinct(other, best, 1e-3):
            out.append(f"an alternative calibration fits nearly as well (cost +{(cost - best_cost) / var:.2g} sigma^2); "
                       "the data may not decide between them")
            break
    if sigma_given is not None and sigma_given > 0 and rms > 3.0 * sigma_given:
        out.append(f"the inlier RMS {rms:.3g} is {rms / sigma_given:.1f} x the given sigma; is sigma right?")
    return out
