"""Least-squares adjustment of a TDOA network and the statistics that say whether to trust it.

This module owns the one least-squares engine of the calibration pipeline and what geodetic network
adjustment reports for every fit (Baarda, "A testing procedure for use in geodetic networks", 1968;
Teunissen, "Testing theory", 2006; open-source adjustment software such as JAG3D):

* the fit itself (`robust_refine`): (iteratively reweighted) Levenberg-Marquardt on the measured
  entries e_ij = F_ij - o_j - |r_i - s_j| in the gauge r_1 = 0, r_2 on the x axis (3D: r_3 in the xy
  plane), in 2D or 3D (the arrays' second axis), with the normal matrix accumulated from the
  2 dim + 1 non-zeros of each Jacobian row;
* `adjustment_statistics`: the normal matrix N = J^T J and its (pseudo-)inverse, the a-posteriori
  variance factor from the residuals of a fit with positive redundancy (SSR / (entries - unknowns)),
  the global test of the model (SSR / sigma^2 against chi^2 with that many degrees of freedom, when
  sigma is given), every entry's redundancy number r_k = 1 - j_k^T N^-1 j_k (its share of the total
  redundancy: near 0, an error there cannot be seen), Baarda's w-test (sigma given) or the externally
  studentised residual (sigma estimated without the tested entry: a t-test), the minimal detectable
  bias (internal reliability), its largest effect on a node (external reliability), and the
  gauge-fixed covariance sigma^2 N^-1 reduced to per-node standard deviations.

The normal matrix is (2m + 3n - 3)^2 (3D: (3m + 4n - 6)^2); it is kept by blocks and solved and
inverted by the Schur complement on the transmitters (solvers.calibration.normal), so that the cost
grows linearly in the transmitters (48 receivers x 540 sources in 3D: 2,298 unknowns, a 138^2 reduced
system); nothing here forms the dense Jacobian of all entries or a dense inverse.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import numpy as np

from ..recovery import to_gauge
from ..refine import _free_receiver_coordinates, pack, parameter_count
from ..refine import unpack as _unpack
from .normal import BlockInverse, BlockLayout, BlockNormal, pseudo_inverse

__all__ = [
    "AdjustmentStatistics",
    "Refined",
    "adjustment_statistics",
    "critical_value",
    "estimate_covariance",
    "robust_refine",
]

Loss = Literal["soft_l1", "huber", "cauchy", "linear"]

def min_measurements(dim: int) -> tuple[int, int]:
    """Measurements a (receiver, transmitter) needs to be determined in `dim` dimensions: a receiver
    has dim unknowns, a transmitter dim + 1 (its offset); one more each, so that a node is not fixed
    exactly by its own measurements (2D: 3, 4; 3D: 4, 5)."""
    return dim + 1, dim + 2


def n_unknowns(n_receivers: int, n_transmitters: int, dim: int) -> int:
    """Unknowns of a network after the gauge: 2m + 3n - 3 in 2D, 3m + 4n - 6 in 3D (solvers.refine)."""
    return parameter_count(n_receivers, n_transmitters, dim)


def enough_data(m: int, n: int, entries: int, dim: int) -> bool:
    """Whether m receivers and n transmitters with this many measured entries can be calibrated in `dim`
    dimensions at all: enough receivers for a transmitter, transmitters for a receiver, entries for the
    unknowns."""
    need_r, need_t = min_measurements(dim)
    return m >= need_t and n >= need_r and entries >= n_unknowns(m, n, dim)


#: Measurements a node needs in the plane (receiver: 2 unknowns; transmitter: 2 + offset); see min_measurements.
MIN_RECEIVER_MEASUREMENTS, MIN_TRANSMITTER_MEASUREMENTS = min_measurements(2)


# --------------------------------------------------------------------------------------------------
# The problem: measured entries between placed nodes, gauge-fixed parameters
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Problem:
    """The measured entries between placed nodes, in a gauge-fixed parameterisation.

    rows, cols: placed receivers / transmitters (global indices); local receiver 0 is fixed at the
    origin, local receiver 1 on the x axis (3D: local receiver 2 in the xy plane); parameters as in
    solvers.refine.pack: [free receiver coordinates, s_0 (dim), s_1 (dim), ..., o_0, ...] (local indices).
    slots[k] holds the parameter columns of entry k's derivatives by (r (dim), s (dim), o);
    n_params marks a fixed coordinate.
    """

    F: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    ii: np.ndarray  # local receiver index per entry
    jj: np.ndarray  # local transmitter index per entry
    slots: np.ndarray  # (k, 2 dim + 1)
    dim: int = 2

    @cached_property
    def n_params(self) -> int:
        return n_unknowns(len(self.rows), len(self.cols), self.dim)

    @cached_property
    def gather(self) -> np.ndarray:
        """Indices into [x, 0] giving [receivers (ma dim), transmitters (na dim), offsets (na)]: unpack
        by one take (the fixed gauge coordinates read the appended 0)."""
        ma, na, dim = len(self.rows), len(self.cols), self.dim
        u = self.n_params
        rec = np.full(ma * dim, u)
        free = _free_receiver_coordinates(ma, dim)
        rec[free] = np.arange(len(free))
        return np.concatenate([rec, np.arange(len(free), u)])

    @cached_property
    def layout(self) -> BlockLayout:
        """The entries' places in the blocks of the normal matrix (receivers, one block per transmitter)."""
        k0 = len(_free_receiver_coordinates(len(self.rows), self.dim))
        return BlockLayout(self.slots, self.jj, k0, len(self.cols), self.dim)

    @cached_property
    def measured(self) -> np.ndarray:
        """F at the problem's entries."""
        return self.F[self.ii, self.jj]

    def slots_of(self, receivers: bool) -> np.ndarray:
        """Parameter columns of each local receiver's coordinates (ma, dim), or each transmitter's
        (coordinates, offset) (na, dim + 1); n_params marks a fixed gauge coordinate."""
        return _slot_tables(len(self.rows), len(self.cols), self.dim)[0 if receivers else 1]


def _slot_tables(ma: int, na: int, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """(receiver slots (ma, dim), transmitter slots (na, dim + 1)) of the solvers.refine.pack layout."""
    u = n_unknowns(ma, na, dim)
    free = _free_receiver_coordinates(ma, dim)
    rs = np.full(ma * dim, u)
    rs[free] = np.arange(len(free))
    k0 = len(free)
    j = np.arange(na)
    ts = np.column_stack([k0 + dim * j + a for a in range(dim)] + [k0 + dim * na + j]) if na else \
        np.zeros((0, dim + 1), int)
    return rs.reshape(ma, dim), ts.reshape(na, dim + 1)


def make_problem(F: np.ndarray, use: np.ndarray, rows: np.ndarray, cols: np.ndarray, *, dim: int) -> Problem:
    """The entries `use` between receivers `rows` and transmitters `cols` (the first dim rows fix the gauge)."""
    ii, jj = np.nonzero(use[np.ix_(rows, cols)])
    rs, ts = _slot_tables(len(rows), len(cols), dim)
    slots = np.concatenate([rs[ii], ts[jj]], axis=1)
    return Problem(F[np.ix_(rows, cols)], rows, cols, ii, jj, slots, dim)


def unpack(x: np.ndarray, p: Problem):
    """(R, S, O) of the problem's placed nodes (local order) from x: the parameter layout of solvers.refine."""
    if np.shape(x) != (p.n_params,):
        return _unpack(x, len(p.rows), len(p.cols), p.dim)  # (raises with the layout's message)
    ma, na, dim = len(p.rows), len(p.cols), p.dim
    full = np.append(np.asarray(x, dtype=float), 0.0)[p.gather]
    return full[: ma * dim].reshape(ma, dim), full[ma * dim: (ma + na) * dim].reshape(na, dim), full[(ma + na) * dim:]


def entry_residuals(x: np.ndarray, p: Problem):
    """(e, r_i - s_j, |r_i - s_j|) of the problem's entries at parameters x."""
    R, S, O = unpack(x, p)
    diff = R[p.ii] - S[p.jj]
    dist = np.sqrt(np.einsum("ij,ij->i", diff, diff))
    return p.measured - O[p.jj] - dist, diff, dist


def jacobian_values(diff: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """(k, 2 dim + 1) derivatives of e_k by (r, s, o) of its receiver and transmitter."""
    u = diff / np.maximum(dist, 1e-300)[:, None]
    dim = diff.shape[1]
    v = np.empty((len(dist), 2 * dim + 1))
    np.negative(u, out=v[:, :dim])
    v[:, dim: 2 * dim] = u
    v[:, 2 * dim] = -1.0
    return v


def dense_jacobian(p: Problem, diff: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """The (k, n_params) Jacobian (tests and small problems only)."""
    J = np.zeros((len(dist), p.n_params + 1))
    np.add.at(J, (np.arange(len(dist))[:, None], p.slots), jacobian_values(diff, dist))
    return J[:, :-1]


def normal_equations(p: Problem, diff, dist, w, e) -> BlockNormal:
    """J^T W J (by blocks: receivers, one block per transmitter) and J^T W e, accumulated from the
    2 dim + 1 non-zeros per row (no dense or sparse Jacobian)."""
    return BlockNormal.accumulate(p.layout, jacobian_values(diff, dist), w, e)


# --------------------------------------------------------------------------------------------------
# Robust losses and the Levenberg-Marquardt loop
# --------------------------------------------------------------------------------------------------


def loss_weights(z: np.ndarray, loss: Loss) -> np.ndarray:
    """IRLS weights rho'(z) for z = (e / c)^2 (scipy's loss conventions)."""
    if loss == "soft_l1":
        return 1.0 / np.sqrt(1.0 + z)
    if loss == "huber":
        return np.where(z <= 1.0, 1.0, 1.0 / np.sqrt(np.maximum(z, 1.0)))
    if loss == "cauchy":
        return 1.0 / (1.0 + z)
    return np.ones_like(z)


def loss_rho(z: np.ndarray, loss: Loss) -> np.ndarray:
    """rho(z) with rho(z) ~ z near 0 (scipy's conventions); cost = c^2 / 2 * sum rho."""
    if loss == "soft_l1":
        return 2.0 * (np.sqrt(1.0 + z) - 1.0)
    if loss == "huber":
        return np.where(z <= 1.0, z, 2.0 * np.sqrt(np.maximum(z, 1.0)) - 1.0)
    if loss == "cauchy":
        return np.log1p(z)
    return z


def levenberg_marquardt(x: np.ndarray, p: Problem, loss: Loss, scale: float, max_iter: int):
    """Iteratively reweighted Levenberg-Marquardt for sum rho((e/scale)^2); returns (x, converged, its).

    The gradient J^T W e is exact for the robust cost (W = rho'); the Hessian is the IRLS one, so a
    robust loss converges linearly and gets looser tolerances (it only warm-starts least squares).
    Why not scipy.optimize.least_squares: its sparse trust-region path forms J (24,000 x 847 for a
    200 x 150 network) and factors it by LSMR each iteration; the normal matrix here is accumulated
    from 5 non-zeros per row by blocks and solved by the Schur complement on the transmitters
    (solvers.calibration.normal: a 297^2 reduced system for 200 x 150 in 2D, 138^2 for 48 receivers in
    3D whatever the number of sources), which is what these problems need.
    """

    tol = 1e-12 if loss == "linear" else 1e-8
    xtol = 1e-15 if loss == "linear" else 1e-8  # least squares: iterate to rounding (noiseless data)
    e, diff, dist = entry_residuals(x, p)

    def cost_of(e):
        return float(np.sum(loss_rho((e / scale) ** 2, loss)))

    cost = cost_of(e)
    lam, nu = 1e-3, 2.0
    converged = False
    it = 0
    for it in range(1, max_iter + 1):
        N = normal_equations(p, diff, dist, loss_weights((e / scale) ** 2, loss), e)
        g = N.g
        diag = N.diagonal()
        floor = 1e-12 * max(diag.max(initial=0.0), 1e-300)
        damping = np.maximum(diag, floor)
        improved = False
        while lam < 1e12:
            step = N.solve(-g, lam * damping)
            if step is None:
                lam *= 10.0
                continue
            x_new = x + step
            e_new, diff_new, dist_new = entry_residuals(x_new, p)
            cost_new = cost_of(e_new) if np.all(np.isfinite(e_new)) else np.inf
            if cost_new <= cost:
                converged = bool(np.linalg.norm(step) <= xtol * (np.linalg.norm(x) + xtol) or cost - cost_new <= tol * cost)
                # Nielsen's damping update from the gain ratio (actual over predicted decrease of the
                # quadratic model): a step the model predicted well lets lambda fall by up to 3x, a poor
                # one keeps it; a long curved valley no longer costs a rejected step every iteration
                predicted = -(2.0 * float(g @ step) + float(step @ N.matvec(step))) / (scale * scale)
                rho = (cost - cost_new) / predicted if predicted > 0 else 0.0
                x, e, diff, dist, cost = x_new, e_new, diff_new, dist_new, cost_new
                lam = max(lam * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), 1e-12)
                nu = 2.0
                improved = True
                break
            lam *= nu
            nu *= 2.0
        if not improved:
            converged = True  # no descent left at this precision: a (local) minimum
        if converged:
            break
    return x, converged, it


@dataclass(frozen=True)
class Refined:
    R: np.ndarray
    S: np.ndarray
    O: np.ndarray
    converged: bool
    iterations: int


def gauge_order(R: np.ndarray, use: np.ndarray) -> np.ndarray:
    """Placed receivers, the dim gauge receivers first, then the rest by index.

    The gauge receivers are the first (by index) with at least min_measurements(dim) entries in `use`
    (else the first placed); in 3D the third is the first such receiver off the line of the first two
    (by more than 1e-6 of the network's extent), else the next one.
    A gauge receiver whose own position the data do not fix would leave the whole network free to
    rotate about it (a rank-deficient fit that wanders off).
    """
    dim = R.shape[1]
    placed = np.flatnonzero(np.isfinite(R[:, 0]))
    good = placed[use[placed].sum(axis=1) >= min_measurements(dim)[0]]
    pool = list(good) if len(good) >= dim else list(placed)
    first = pool[:2]
    if dim == 3 and len(first) == 2:
        a, b = R[first[0]], R[first[1]]
        axis = (b - a) / max(float(np.linalg.norm(b - a)), 1e-300)
        extent = max(float(np.nanmax(np.abs(R[placed] - a))), 1e-300)
        rest = pool[2:]
        off = [i for i in rest if np.linalg.norm(np.cross(R[i] - a, axis)) > 1e-6 * extent]
        first += (off or rest)[:1]
    first = np.array(first, dtype=int)
    return np.concatenate([first, placed[~np.isin(placed, first)]]).astype(int)


def _gauged_problem(F, use, R, S, O):
    """(problem, x) on the entries `use` between placed nodes, or None if the gauge cannot be fixed."""
    dim = R.shape[1]
    placed_r = gauge_order(R, use)
    placed_t = np.flatnonzero(np.isfinite(S[:, 0]))
    if len(placed_r) < dim or len(placed_t) < 1:
        return None
    gauged = to_gauge(R[placed_r], S[placed_t])
    if gauged is None:
        return None
    p = make_problem(F, use, placed_r, placed_t, dim=dim)
    return p, pack(gauged[0], gauged[1], O[placed_t])


def _scatter(p: Problem, x: np.ndarray, shape_r, shape_t):
    Rl, Sl, Ol = unpack(x, p)
    R2, S2, O2 = np.full(shape_r, np.nan), np.full(shape_t, np.nan), np.full(shape_t[0], np.nan)
    R2[p.rows], S2[p.cols], O2[p.cols] = Rl, Sl, Ol
    return R2, S2, O2


def robust_refine(F, mask, R, S, O, *, loss: Loss = "soft_l1", scale: float = 1.0, max_iter: int = 100,
                  use: np.ndarray | None = None) -> Refined:
    """Refine placed nodes on the measured entries `use` (default: all of `mask`) with a robust loss.

    Unplaced nodes (NaN) stay NaN. Returns the refined arrays in the gauge (first placed receiver at
    the origin, second on the x axis), the convergence flag and the iteration count.
    """
    use = mask if use is None else use
    gp = _gauged_problem(F, use, R, S, O)
    if gp is None or len(gp[0].ii) == 0:
        return Refined(R, S, O, False, 0)
    p, x0 = gp
    x, converged, its = levenberg_marquardt(x0, p, loss, scale, max_iter)
    return Refined(*_scatter(p, x, R.shape, S.shape), converged, its)


# --------------------------------------------------------------------------------------------------
# Statistics of a least-squares fit
# --------------------------------------------------------------------------------------------------


def critical_value(alpha: float, dof: float | None = None) -> float:
    """Two-sided critical value of a standard normal (dof None) or Student t test at level alpha."""
    from scipy import stats

    if dof is None or not np.isfinite(dof):
        return float(stats.norm.isf(alpha / 2.0))
    return float(stats.t.isf(alpha / 2.0, max(dof, 1e-9)))


#: The dense reference of the block inverse (tests compare the two).
_pseudo_inverse = pseudo_inverse


@dataclass(frozen=True, eq=False)
class AdjustmentStatistics:
    """What a least-squares fit on `use` supports (see the module docstring).

    entries : (k, 2) global (receiver, transmitter) of every entry of the fit
    residuals : (k,) e = F - o - |r - s| at the fit
    redundancy : (k,) redundancy numbers r_k in [0, 1]; their sum is the degrees of freedom
    dof : entries - unknowns (redundancy of the fit); 0 or less: nothing can be tested
    ssr : sum of squared residuals
    sigma_prior : the given noise level, or None
    sigma_post : a-posteriori noise level sqrt(ssr / dof) (NaN when dof <= 0)
    sigma : the level the tests and covariance use (sigma_prior if given, else sigma_post)
    global_statistic, global_critical, global_passed : ssr / sigma_prior^2 against the chi^2(dof)
        quantile at the global level (None when sigma is estimated: the test needs a prior)
    w : (k,) test statistic of each entry: Baarda's w = e / (sigma sqrt(r)) when sigma is given,
        else the externally studentised residual (sigma from the fit without that entry, t(dof - 1))
    mdb : (k,) minimal detectable bias sigma delta0 / sqrt(r) (inf where r ~ 0)
    null : (n_params,) parameters not determined (rank-deficient fit)
    inverse : a generalised inverse of N kept by blocks (solvers.calibration.normal.BlockInverse)
    problem, x : the fit's problem and parameters
    """

    entries: np.ndarray
    residuals: np.ndarray
    redundancy: np.ndarray
    dof: int
    ssr: float
    sigma_prior: float | None
    sigma_post: float
    sigma: float
    global_statistic: float | None
    global_critical: float | None
    global_passed: bool | None
    w: np.ndarray
    mdb: np.ndarray
    null: np.ndarray
    inverse: BlockInverse
    problem: Problem
    x: np.ndarray

    @property
    def deficient(self) -> bool:
        return bool(self.null.any())

    def hat(self, p: Problem, x: np.ndarray | None = None):
        """(e, j^T N^-1 j) of the entries of another problem `p` on the same nodes (prediction)."""
        e, diff, dist = entry_residuals(self.x if x is None else x, p)
        v = jacobian_values(diff, dist)
        return e, self.inverse.quadratic(p.slots, v)

    def node_std(self, m: int, n: int):
        """(receiver_std (m,), transmitter_std (n,), offset_std (n,)): the square root of the sum of the
        coordinates' variances, the offset's std; inf for a coordinate in the null space, NaN for a node
        not in the fit."""
        var = self.sigma**2 * self.inverse.diagonal()
        var[self.null] = np.inf
        var = np.append(var, 0.0)  # fixed gauge coordinates
        p = self.problem
        rstd, tstd, ostd = np.full(m, np.nan), np.full(n, np.nan), np.full(n, np.nan)
        rs, ts = p.slots_of(True), p.slots_of(False)
        rstd[p.rows] = np.sqrt(var[rs].sum(axis=1))
        tstd[p.cols] = np.sqrt(var[ts[:, : p.dim]].sum(axis=1))
        ostd[p.cols] = np.sqrt(var[ts[:, p.dim]])
        return rstd, tstd, ostd

    def external_reliability(self, m: int, n: int, chunk: int = 2048):
        """(receiver (m,), transmitter (n,)): the largest shift of a node's position that an
        undetected error of one entry's minimal detectable bias causes (N^-1 j_k mdb_k; NaN off the fit).
        Entries with infinite MDB (no redundancy) are left out: they are reported as uncontrolled."""
        p = self.problem
        _, diff, dist = entry_residuals(self.x, p)
        v = jacobian_values(diff, dist)
        rs, ts = p.slots_of(True), p.slots_of(False)[:, : p.dim]
        node_slots = np.vstack([rs, ts])  # (nodes, dim)
        best = np.zeros(len(node_slots))
        finite = np.flatnonzero(np.isfinite(self.mdb))
        for start in range(0, len(finite), chunk):
            k = finite[start : start + chunk]
            # shift of every parameter: N^-1 j_k mdb_k  -> (n_params + 1, len(k)), the fixed row 0
            rhs = np.zeros((p.n_params + 1, len(k)))
            rhs[p.slots[k].T, np.arange(len(k))[None, :]] = (v[k] * self.mdb[k, None]).T
            shift = np.zeros_like(rhs)
            shift[:-1] = self.inverse.solve(rhs[:-1])
            disp = np.sqrt(np.sum(shift[node_slots] ** 2, axis=1))  # (nodes, len(k))
            best = np.maximum(best, disp.max(axis=1))
        rel_r, rel_t = np.full(m, np.nan), np.full(n, np.nan)
        rel_r[p.rows] = best[: len(rs)]
        rel_t[p.cols] = best[len(rs) :]
        return rel_r, rel_t


def adjustment_statistics(F, use, R, S, O, sigma_prior: float | None, *, alpha: float = 0.001,
                          power: float = 0.8, alpha_global: float = 0.01,
                          weights: np.ndarray | None = None) -> AdjustmentStatistics | None:
    """Statistics of the least-squares fit (R, S, O) on the entries `use` (see AdjustmentStatistics).

    alpha: level of each entry's test (Baarda's alpha_0); power: the probability of detecting a bias
    of the MDB; alpha_global: level of the global test of the model. None if the gauge cannot be fixed.
    weights: (m, n) weights of an iteratively reweighted (robust) fit; the redundancy numbers are then
    those of the weighted fit, r_k = 1 - w_k j_k^T (J^T W J)^-1 j_k: an entry the robust loss ignores
    gets r ~ 1, and the entries of a subset the fit explains exactly get r ~ 0 (their residuals say
    nothing about the noise). The tests below assume an unweighted fit.
    """
    from scipy import stats

    gp = _gauged_problem(F, use, R, S, O)
    if gp is None or len(gp[0].ii) == 0:
        return None
    p, x = gp
    e, diff, dist = entry_residuals(x, p)
    wk = np.ones(len(e)) if weights is None else weights[p.rows[p.ii], p.cols[p.jj]]
    inverse = normal_equations(p, diff, dist, wk, e).inverse()
    null = inverse.null
    v = jacobian_values(diff, dist)
    h = wk * inverse.quadratic(p.slots, v)
    r = np.clip(1.0 - h, 0.0, 1.0)
    k = len(e)
    rank = p.n_params - int(null.sum())
    dof = k - rank
    ssr = float(np.sum(e * e))
    sigma_post = math.sqrt(ssr / dof) if dof > 0 else math.nan
    sigma = sigma_prior if sigma_prior is not None else sigma_post
    tiny = 1e-12
    with np.errstate(divide="ignore", invalid="ignore"):
        if sigma_prior is not None:
            w = np.where(r > tiny, e / (sigma_prior * np.sqrt(r)), 0.0)
            g_stat = ssr / sigma_prior**2
            g_crit = float(stats.chi2.isf(alpha_global, dof)) if dof > 0 else math.inf
            g_pass = bool(g_stat <= g_crit) if dof > 0 else None
        else:
            # externally studentised: sigma from the fit without entry k (its own share removed)
            s2 = (ssr - np.where(r > tiny, e * e / np.maximum(r, tiny), 0.0)) / max(dof - 1, 1)
            w = np.where((r > tiny) & (s2 > 0) & (dof > 1), e / np.sqrt(np.maximum(s2, 1e-300) * r), 0.0)
            g_stat = g_crit = g_pass = None
        delta0 = float(stats.norm.isf(alpha / 2.0) + stats.norm.ppf(power))
        mdb = np.where(r > tiny, sigma * delta0 / np.sqrt(r), np.inf) if np.isfinite(sigma) else np.full(k, np.inf)
    entries = np.column_stack([p.rows[p.ii], p.cols[p.jj]])
    return AdjustmentStatistics(entries, e, r, int(dof), ssr, sigma_prior, sigma_post, float(sigma), g_stat, g_crit,
                                g_pass, w, mdb, null, inverse, p, x)


def estimate_covariance(F, use, R, S, O, sigma: float):
    """Gauge-fixed covariance sigma^2 (J^T J)^-1 on the entries `use`, reduced to per-node stds.

    Returns (receiver_std (m,), transmitter_std (n,), offset_std (n,), rank_deficient). Position std
    = sqrt of the sum of the coordinates' variances; parameters in the null space of J (not
    determined) get inf; nodes not placed get NaN. Gauge: that of gauge_order and to_gauge.
    """
    m, n = F.shape
    st = adjustment_statistics(F, use, R, S, O, sigma) if use.any() else None
    if st is None:
        return np.full(m, np.nan), np.full(n, np.nan), np.full(n, np.nan), True
    return (*st.node_std(m, n), st.deficient)
