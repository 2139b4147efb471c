"""Initialise by the hypothesis search (stage 2, the near-field route) and adjust from its best hypothesis.

The route of data that are not plane waves (`diagnose.Diagnosis.wavefront`): LO-RANSAC over the minimal
solvers (`ransac` over `sampling`) with local optimisation and extension, the robust adjustment (`robust`), the
probing of other least-squares basins (`flags`) and the statistics of the final fit (`adjustment`),
handed to the judge as one `judge_search.SearchFit`. `_calibrate_once` is one such search; `crosscheck`
compares its answer with other searches of the same data.

The absorbed-error probe (`_absorbed_error_probe`) lives here because it is a second search: with sigma
unknown the first fit's own tests are blind at a node of small redundancy number; the judge
(`judge_search`) decides when to call it. A robust initialisation that sees the node's entries (the
factorization's inliers, where it applies) could choose without it.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import replace

import numpy as np

from ..recovery import to_gauge
from .adjustment import adjustment_statistics, critical_value, gauge_order, make_problem, min_measurements, n_unknowns
from .flags import _flags, _probe_basins, _standardised_shift
from .frame import node_covariances
from .judge_search import SearchFit, judge_search
from .result import CalibrationOptions, CalibrationResult
from .robust import _adjust, _all_data_fit, _drop_undetermined
from .ransac import _ransac
from .sampling import available_solvers
from .scoring import _Model, _prune, _residual_matrix, _Search

#: Progress of long calls (stage by stage, each snooping round), at INFO; the CLI shows it on stderr.
log = logging.getLogger("solvers.calibration")

#: Statuses of an answer that is no usable calibration (a second answer is preferred to it).
UNUSABLE = ("failed", "unconverged", "inconsistent")


def _failed(F, message, t0, seed, search: _Search | None = None, warnings=(), dim: int = 2) -> CalibrationResult:
    m, n = F.shape
    nan = np.full
    return CalibrationResult(
        status="failed", message=message, receivers=nan((m, dim), np.nan), transmitters=nan((n, dim), np.nan),
        offsets=nan(n, np.nan), inliers=np.zeros((m, n), bool), residuals=nan((m, n), np.nan), rms=float("nan"),
        sigma=float("nan"), sigma_estimated=True, receiver_std=nan(m, np.nan), transmitter_std=nan(n, np.nan),
        offset_std=nan(n, np.nan), warnings=tuple(warnings),
        solver="+".join(sorted(search.solvers)) if search else "", samples=search.samples if search else 0,
        hypotheses=search.hypotheses if search else 0, seconds=time.perf_counter() - t0, seed=seed,
        measured=np.isfinite(F),
    )


def _data_scale(F, mask) -> float:
    """Largest |F| over the entries of mask (1 when there are none or all are 0): the unit of the floors."""
    values = np.abs(F[mask])
    return float(values.max()) if values.size and values.max() > 0 else 1.0


def _floor(F) -> float:
    """The floor of the noise scales when comparing whole results: 1e-9 of the largest measured |F|."""
    return 1e-9 * _data_scale(F, np.isfinite(F))


def _usable(F, dim: int) -> tuple[np.ndarray, list[str], str | None]:
    """(the usable entries, a warning per node not placed, the failure message when too few are usable or
    None): a node is usable with enough measurements to usable nodes (`scoring._prune`, iterated)."""
    m, n = F.shape
    mask = np.isfinite(F)
    warnings: list[str] = []
    need_r, need_t = min_measurements(dim)

    rows_ok, cols_ok = _prune(mask, dim)
    for i in np.flatnonzero(~rows_ok):  # usable: measured to a node that is itself kept (pruning is iterated)
        warnings.append(f"receiver {i + 1}: only {int((mask[i] & cols_ok).sum())} measured transmitters usable "
                        f"(needs {need_r}); not placed")
    for j in np.flatnonzero(~cols_ok):
        warnings.append(f"transmitter {j + 1}: only {int((mask[:, j] & rows_ok).sum())} measured receivers usable "
                        f"(needs {need_t}); not placed")
    work = mask & rows_ok[:, None] & cols_ok[None, :]
    n_params = n_unknowns(int(rows_ok.sum()), int(cols_ok.sum()), dim)
    if rows_ok.sum() < need_r or cols_ok.sum() < need_r or work.sum() < n_params:
        hint = ""
        if m < need_t <= n or n < need_t <= m:
            hint = (f" ({m} receivers x {n} transmitters: a {dim}D network needs >= {need_r} receivers with >= "
                    f"{need_r} transmitters each and transmitters with >= {need_t} receivers each; is the matrix "
                    "transposed?)")
        return work, warnings, (f"too few measurements: {int(work.sum())} usable entries between "
                                f"{int(rows_ok.sum())} receivers and {int(cols_ok.sum())} transmitters for "
                                f"{max(n_params, 0)} unknowns{hint}")
    return work, warnings, None


#: The columns' common parts are taken out before a search where they exceed the spread of the columns
#: (their distances' differences and gross errors) this many times (`_column_reference`).
COMMON_PART_RATIO = 10.0


def _column_reference(F) -> np.ndarray | None:
    """The part common to each column that the search takes out first (F_ij - c_j: o_j absorbs c_j, an
    exact change of the offsets), or None when the columns need none.

    A recording's offsets are the events' emission times times the speed of sound: up to 5,000 m in a
    90 s room recording, where the distances differ by a few metres. The hypotheses of such a matrix
    come out wrong (every source of the 8 x 10 log-sweep room at 300-4,000 m, a valley the final
    least squares crawls along for 1,000 iterations); the same matrix less its column medians
    calibrates at once, 0.6 mm rms (tests/data/calibration/rooms). The reference is each column's
    median, taken out only where the largest |median| exceeds COMMON_PART_RATIO x the largest column
    spread (max - min), so that networks whose offsets are of the distances' size keep their results
    bit for bit (the committed grids)."""
    measured = np.isfinite(F)
    cols = measured.any(axis=0)
    if not cols.any():
        return None
    with np.errstate(all="ignore"):
        sub = F[:, cols]
        median = np.nanmedian(sub, axis=0)
        spread = float(np.max(np.nanmax(sub, axis=0) - np.nanmin(sub, axis=0)))
    if not np.max(np.abs(median)) > COMMON_PART_RATIO * spread:
        return None
    ref = np.zeros(F.shape[1])
    ref[cols] = median
    return ref


def _calibrate_once(F, sigma, seed, opts: CalibrationOptions, t0, dim: int,
                    hint: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                    probe: bool = True) -> CalibrationResult:
    """One search and adjustment; `hint` (receivers, transmitters, offsets) is offered to the search
    before any sample. probe: with sigma unknown, marginal rejections at a node that keeps entries of
    small redundancy number are tested by a search without those entries (`_absorbed_error_probe`);
    False in the probe's own searches. The columns' common parts (`_column_reference`) are taken out
    before and given back to the offsets after."""
    ref = _column_reference(F)
    if ref is None:
        return _search_and_adjust(F, sigma, seed, opts, t0, dim, hint, probe)
    moved = None if hint is None else (hint[0], hint[1], np.asarray(hint[2], dtype=float) - ref)
    res = _search_and_adjust(F - ref, sigma, seed, opts, t0, dim, moved, probe)
    return replace(res, offsets=res.offsets + ref)


def _search_and_adjust(F, sigma, seed, opts: CalibrationOptions, t0, dim: int,
                       hint: tuple[np.ndarray, np.ndarray, np.ndarray] | None, probe: bool) -> CalibrationResult:
    """`_calibrate_once` on a matrix whose columns need no reference taken out."""
    m, n = F.shape
    mask = np.isfinite(F)
    rng = np.random.default_rng(seed)
    work, warnings, failure = _usable(F, dim)
    if failure is not None:
        return _failed(F, failure, t0, seed, warnings=warnings, dim=dim)

    data_scale = _data_scale(F, work)
    floor = 1e-9 * data_scale
    thr = None if sigma is None else max(opts.threshold_sigmas * sigma, floor)

    fits = {}
    memo: dict = {}

    def accept(model: _Model) -> bool:
        fits[id(model)] = _all_data_fit(F, work, model, sigma, floor, opts, rng, memo)
        return fits[id(model)][-1]

    log.info("calibrate %dD, %d x %d, %d measured, seed %s, sigma %s: hypothesis search", dim, m, n,
             int(mask.sum()), seed, "estimated" if sigma is None else f"{sigma:g} given")
    best, search = _ransac(F, work, thr, floor, opts, rng, available_solvers(dim), accept,
                           0.0 if sigma is not None else opts.confirm_outliers, dim=dim, hint=hint)
    log.info("  search: %d samples, %d hypotheses (%.1f s)", search.samples, search.hypotheses,
             time.perf_counter() - t0)
    if best is None:
        return _failed(F, "no hypothesis: every minimal-solver sample and sub-network fit failed (degenerate geometry?)",
                       t0, seed, search, warnings, dim=dim)

    notes: list[str] = []
    unresolved: list = []
    exact: list = []  # entries rejected by the exact leave-one-out test (their w-test says little)
    R, S, O, inl, converged, route = _adjust(F, work, best, sigma, floor, opts, rng, fits.get(id(best)), notes,
                                             unresolved, exact)
    log.info("  adjustment (%s): %d of %d measurements kept (%.1f s)", route, int(inl.sum()), int(work.sum()),
             time.perf_counter() - t0)
    warnings += notes
    R, S, O, inl, dropped, ls = _drop_undetermined(F, work, R, S, O, inl, opts.max_iterations)
    warnings += dropped
    if ls is not None:
        converged = ls.converged
    R, S, O, moved, other_minimum = _probe_basins(F, work, inl, R, S, O, sigma, opts)
    log.info("  basins probed (%.1f s)", time.perf_counter() - t0)
    if moved:
        warnings.append("a better least-squares minimum was found by moving a node with rejected measurements")
    E = _residual_matrix(F, R, S, O)
    rms = float(np.sqrt(np.mean(E[inl] ** 2))) if inl.any() else float("nan")

    # Gauge of the report: receiver 1 at 0 and receiver 2 on +x (3D: receiver 3 in the xy half-plane
    # y > 0), or the first receivers with enough inliers (see gauge_order); the statistics use it too.
    # 2D: of the two mirror images (equally good), the one with the first further receiver off the
    # x axis at y > 0 (else the search's path would decide which one is printed).
    placed_r, placed_t = np.isfinite(R[:, 0]), np.isfinite(S[:, 0])
    order = gauge_order(R, inl)
    gauged = to_gauge(R[order], S[placed_t]) if len(order) >= dim else None
    if gauged is not None:
        R[order], S[placed_t] = gauged
        if dim == 2:
            extent = float(np.nanmax(np.abs(R[order])))
            off = [i for i in order[2:] if abs(R[i, 1]) > 1e-9 * extent]
            if off and R[off[0], 1] < 0:
                R[:, 1], S[:, 1] = 0.0 - R[:, 1], 0.0 - S[:, 1]  # (0.0 - x: no negative zeros)
    st = adjustment_statistics(F, inl, R, S, O, sigma, alpha=opts.alpha, power=opts.power,
                               alpha_global=opts.alpha_global) if inl.any() else None
    nan_mn = np.full((m, n), np.nan)
    if st is not None and st.dof > 0:
        sig = st.sigma
        sig_cov = max(sig, floor / opts.threshold_sigmas)
        st_cov = st if sig == sig_cov else replace(st, sigma=sig_cov)
        rstd, tstd, ostd = st_cov.node_std(m, n)
        rcov, tcov = node_covariances(st_cov, m, n, dim)
        rrel, trel = st_cov.external_reliability(m, n)
        dof_t = None if sigma is not None else st.dof - 1
        crit = critical_value(opts.alpha, dof_t) if dof_t is None or dof_t >= 1 else math.inf
        redundancy, w_test, mdb = nan_mn.copy(), nan_mn.copy(), nan_mn.copy()
        i, j = st.entries[:, 0], st.entries[:, 1]
        redundancy[i, j], w_test[i, j], mdb[i, j] = st.redundancy, st.w, st.mdb
        cand = work & ~inl & placed_r[:, None] & placed_t[None, :]
        if cand.any():
            q = make_problem(F, cand, st.problem.rows, st.problem.cols, dim=dim)
            e, h = st.hat(q)
            w_test[q.rows[q.ii], q.cols[q.jj]] = e / (st.sigma * np.sqrt(1.0 + h))
        uncontrolled = np.zeros((m, n), bool)
        uncontrolled[i, j] = st.redundancy < opts.min_redundancy
        deficient = st.deficient
    else:
        sig = float("nan") if sigma is None else sigma
        sig_cov = sig if np.isfinite(sig) else floor
        rstd, tstd, ostd = (st.node_std(m, n) if st is not None and np.isfinite(sig) else
                            (np.full(m, np.inf), np.full(n, np.inf), np.full(n, np.inf)))
        rcov, tcov = node_covariances(st if np.isfinite(sig) else None, m, n, dim)
        rrel, trel = np.full(m, np.nan), np.full(n, np.nan)
        crit = math.inf
        redundancy, w_test, mdb = nan_mn.copy(), nan_mn.copy(), nan_mn.copy()
        uncontrolled = inl.copy()
        deficient = True if st is None else st.deficient
        rstd = np.where(placed_r, rstd, np.nan)
        tstd, ostd = np.where(placed_t, tstd, np.nan), np.where(placed_t, ostd, np.nan)
    flagged, undecided = _flags(F, work, inl, R, S, O, sig_cov, rstd, tstd, opts, floor, deficient, search, best,
                                sigma, rms, already=tuple(warnings))
    warnings += flagged

    fit = SearchFit(F=F, work=work, mask=mask, dim=dim, R=R, S=S, O=O, E=E, inl=inl, rms=rms, converged=converged,
                    route=route, search=search, data_scale=data_scale, order=order, gauged=gauged,
                    placed_r=placed_r, placed_t=placed_t, st=st, sig=sig, rstd=rstd, tstd=tstd, ostd=ostd,
                    rcov=rcov, tcov=tcov, rrel=rrel, trel=trel, crit=crit, redundancy=redundancy, w_test=w_test,
                    mdb=mdb, uncontrolled=uncontrolled, deficient=deficient, undecided=undecided,
                    other_minimum=other_minimum, unresolved=unresolved, exact=exact, warnings=tuple(warnings))
    at = (lambda suspects, s, dof, fitted: _absorbed_error_probe(F, seed, opts, t0, dim, suspects, s, dof, fitted)
          ) if probe else None
    return judge_search(fit, sigma, seed, opts, t0, at)


#: Two fits whose nodes lie farther apart than this many combined std (after a rigid alignment) are two
#: calibrations, not one: the probe's search then missed the first fit's basin and decides nothing.
SAME_CALIBRATION_STD = 5.0


def _absorbed_error_probe(F, seed, opts: CalibrationOptions, t0, dim: int, suspects: list, sig: float, dof: int,
                          fit: tuple):
    """Sigma unknown: do the marginal rejections hide an error absorbed by a kept entry of small redundancy
    number? The hypothesis search and adjustment run again on the data without the suspects (`_weak_at`).
    An error absorbed there had pulled the whole fit: without it the search finds a fit whose sigma is
    significantly smaller (F test of the two variance estimates at level opts.alpha; they share most
    entries, so the test is conservative). 12r/8s, 1 mm, 5 % gross errors (network 7007): sigma
    0.0179 with one gross error kept at r 0.047 and two good entries rejected; without the kept entries
    of small redundancy number at those nodes, 0.00125 with every gross error out. Audio rooms whose
    rejections are the tail of the noise: the sigma does not move.

    A fit without the suspects that is not significantly better refutes the suspicion only when it is the
    same calibration: every node within SAME_CALIBRATION_STD combined std of the first fit's (fit: its
    receivers, transmitters and their stds, in its gauge). A search that lands elsewhere with no better
    sigma missed the first fit's basin (7007 searched with seed 0: sigma 0.0212, a node 12 combined std
    away) and says nothing; audio rooms: 0.5-2.9.

    Returns None (no suspect), ("absorbed", the calibration restarted from the better fit, note),
    ("undecided", None, note: the search without the suspects gave no usable fit, or another calibration)
    or ("refuted", None, note)."""
    from scipy import stats

    if not suspects or not (np.isfinite(sig) and sig > 0):
        return None
    G = F.copy()
    for i, j in suspects:
        G[i, j] = np.nan
    names = ", ".join(f"r{i + 1}-s{j + 1}" for i, j in suspects[:6]) + (", ..." if len(suspects) > 6 else "")
    log.info("absorbed-error probe: the search without %d entries of small redundancy number", len(suspects))
    other = _calibrate_once(G, None, seed, opts, t0, dim, probe=False)
    if (other.status in UNUSABLE + ("partial",) or other.dof < opts.min_dof_for_sigma
            or not (np.isfinite(other.sigma) and other.sigma > 0)):
        return "undecided", None, (f"the search without the kept entries of small redundancy number there ({names}) "
                                   f"gave no usable fit to compare ({other.status})")
    ratio = (sig / other.sigma) ** 2
    critical = float(stats.f.isf(opts.alpha, dof, other.dof))
    said = (f"the search without the kept entries of small redundancy number there ({names}) fits with sigma "
            f"{other.sigma:.3g} against {sig:.3g} (variance ratio {ratio:.3g}")
    if ratio <= critical:
        R, S, rstd, tstd = fit
        moved = _standardised_shift(other.receivers, other.transmitters, other.receiver_std, other.transmitter_std,
                                    R, S, rstd, tstd)
        if moved > SAME_CALIBRATION_STD:
            return "undecided", None, (f"{said} <= {critical:.3g}, F test), but it is another calibration (a node "
                                       f"{moved:.3g} combined std away): that search missed this fit's basin")
        return "refuted", None, (f"{said} <= {critical:.3g}, F test) and the same calibration (nodes within "
                                 f"{moved:.2g} combined std): no error absorbed there; the rejections are kept")
    again = _calibrate_once(F, None, seed, opts, t0, dim, hint=(other.receivers, other.transmitters, other.offsets),
                            probe=False)
    if again.status in UNUSABLE or not (np.isfinite(again.sigma) and again.sigma < sig):
        return "undecided", None, f"{said} > {critical:.3g}, F test), but the search restarted from it did not keep it"
    return "absorbed", again, (f"{said} > {critical:.3g}, F test): the first fit had absorbed an error; this answer is "
                               "the search restarted from that fit")
