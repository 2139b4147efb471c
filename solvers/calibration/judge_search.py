"""Stage 4 for the search route: the status of a searched fit from its final statistics, in words.

`search._calibrate_once` ends with the fit of its best hypothesis and that fit's statistics (`SearchFit`);
this module reads them off it and makes the findings, the most severe the status (result.STATUSES),
each a warning, the first in the message: a fit that explains under 2/3 of the measurements, degenerate
geometry (collinear or coplanar nodes), convergence and divergence, the global test (sigma given) or the
estimated noise against the data's spread (sigma estimated), undecided mirror images and second minima,
unplaced nodes, a search short of its confidence, too little redundancy, uncontrolled entries,
rank deficiency, errors the exact leave-one-out test finds, and (sigma estimated) marginal rejections at
a node of small redundancy number, which the absorbed-error probe (`search._absorbed_error_probe`,
passed in as `probe`) tests by another search. The plane-wave route is judged by `judge.plane_wave_result`;
both end in `judge.judge_kept` (a node is judged by what it kept).

Where a stage could choose from the data instead (behaviour unchanged here): the findings are the rule of
`judge` applied to a searched fit; the probe is a second search because, with sigma unknown, the fit's
own tests are blind where the redundancy numbers are small.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, fields, replace

import numpy as np

from .flags import _principal_ratio
from .frame import RANGE_SHARE, widen_far_ranges
from .judge import EXPLAINED_SHARE, _marginal_rejections, _short_search, _weak_at, message, route_note, worst
from .result import CalibrationOptions, CalibrationResult
from .ransac import _needed


@dataclass(frozen=True, eq=False)
class SearchFit:
    """The final fit of a hypothesis search (`search._calibrate_once`) and its statistics: the data (F, the
    usable entries `work`, the measured `mask`, dim), the fit (R, S, O, residuals E, inliers `inl`, rms,
    converged, the adjustment's `route`), the search's record (`search`: scoring._Search), the gauge
    (`order`, `gauged`), which nodes are placed, the statistics `st` (adjustment.AdjustmentStatistics or
    None) with sigma `sig`, the node stds and covariances, external reliabilities, the critical value, the
    per-entry redundancy numbers, w-tests, MDBs and uncontrolled entries, rank deficiency, the flags'
    undecided mirrors and second minimum, the robust route's unresolved and exact rejections, and the
    warnings so far."""

    F: object
    work: object
    mask: object
    dim: object
    R: object
    S: object
    O: object
    E: object
    inl: object
    rms: object
    converged: object
    route: object
    search: object
    data_scale: object
    order: object
    gauged: object
    placed_r: object
    placed_t: object
    st: object
    sig: object
    rstd: object
    tstd: object
    ostd: object
    rcov: object
    tcov: object
    rrel: object
    trel: object
    crit: object
    redundancy: object
    w_test: object
    mdb: object
    uncontrolled: object
    deficient: object
    undecided: object
    other_minimum: object
    unresolved: object
    exact: object
    warnings: tuple[str, ...] = ()


def judge_search(fit: SearchFit, sigma, seed, opts: CalibrationOptions, t0,
                 probe: Callable | None = None) -> CalibrationResult:
    """The CalibrationResult of a searched fit, judged by the findings of the module docstring. probe(suspects,
    sigma, dof, (R, S, rstd, tstd)): the absorbed-error probe (None: not run); its verdict "absorbed" returns
    the answer of the search restarted from the better fit."""
    # every field but the warnings, in the order of SearchFit
    (F, work, mask, dim, R, S, O, E, inl, rms, converged, route, search, data_scale, order, gauged, placed_r,
     placed_t, st, sig, rstd, tstd, ostd, rcov, tcov, rrel, trel, crit, redundancy, w_test, mdb, uncontrolled,
     deficient, undecided, other_minimum, unresolved, exact) = (getattr(fit, f.name) for f in fields(fit)[:-1])
    m, n = F.shape
    warnings = list(fit.warnings)
    # Status: the most severe finding; each one also becomes the first warnings, in order.
    found: list[tuple[str, str]] = []
    n_work = int(work.sum())
    kept = float(inl.sum() / max(n_work, 1))
    # A fit that explains less than 2/3 of the measurements is no calibration of these data: said first,
    # because it explains what follows. A refinement from such a hypothesis that does not converge, or
    # collapses onto a plane, is its symptom, not the finding (16r/10s rooms, 10 % gross errors, sigma
    # given: 5 of 8 reported "unconverged", each from a search that drew no block in the basin).
    lost = kept < EXPLAINED_SHARE
    if lost:
        found.append(("inconsistent", f"the model explains only {100 * kept:.0f} % of the measurements (transposed "
                      "matrix, wrong units, not TDOA data, or mostly gross errors?)"
                      + ("; the hypothesis search ended short of its confidence (see below): a calibration that "
                         "explains more may exist" if search.short_of > 0 else "")))
    symptoms: list[str] = []  # findings that a lost fit explains: warnings, not statuses
    # Degenerate geometry first: it explains the findings that follow (an unconverged or rank-deficient fit).
    enough = placed_r.sum() > dim and placed_t.sum() > dim  # the shapes below mean something
    flat_all = _principal_ratio(np.vstack([R[placed_r], S[placed_t]])) if dim == 3 and enough else 1.0
    shape, across = ("collinear", "line") if dim == 2 else ("coplanar", "plane")
    if flat_all < opts.collinear_ratio and st is not None and st.global_passed:
        # the planar fit explains the data within the given sigma: a fact about the data
        found.append(("ambiguous", f"every node lies nearly in one plane (spread ratio {flat_all:.2g}) and the fit passes "
                      "the global test: the data are planar, each node's mirror image across that plane fits as well; "
                      "calibrate in 2D (dim=2, --dim 2)"))
    elif flat_all < opts.collinear_ratio:
        # a fit not shown to explain the data says nothing about them (issue 52): the search can end in a planar
        # local minimum (a 6 x 10 room recording: rms 38 mm planar, its true 3D positions 0.35 mm)
        found.append(("ambiguous", f"every node of this fit lies nearly in one plane (spread ratio {flat_all:.2g}): either "
                      "the network is planar (each node's mirror image across that plane fits as well: calibrate in 2D, "
                      "dim=2, --dim 2) or the search ended in a planar local minimum (another seed, or sigma given, may "
                      "find a better 3D fit); " + ("the global test fails at the given sigma" if sigma is not None else
                                                   "with sigma estimated this fit cannot tell which")))
    else:
        for kind, other, P in (("receivers", "transmitter", R[placed_r]), ("transmitters", "receiver", S[placed_t])):
            ratio = _principal_ratio(P)
            if enough and ratio < opts.collinear_ratio:
                found.append(("ambiguous", f"the {kind} are nearly {shape} (spread ratio {ratio:.2g}): every {other}'s "
                              f"mirror image across their {across} fits its measurements as well; the data cannot "
                              "decide the side"))
    unconverged = []
    if not converged:
        unconverged.append("the refinement did not converge within its iteration budget")
    spread = float(np.nanmax(np.abs(np.vstack([R[placed_r], S[placed_t]])))) if placed_r.any() else np.inf
    if not np.isfinite(spread) or spread > 1e3 * data_scale:
        unconverged.append(f"the solution diverged (coordinates up to {spread:.3g}, data scale {data_scale:.3g})")
    if lost:
        symptoms += unconverged
    else:
        found += [("unconverged", why) for why in unconverged]
    if st is not None and st.global_passed is False:
        found.append(("inconsistent", f"the global test of the model fails: SSR / sigma^2 = {st.global_statistic:.4g} > "
                      f"{st.global_critical:.4g} (chi^2, {st.dof} degrees of freedom, level {opts.alpha_global:g}): the "
                      f"residuals are {st.sigma_post / sigma:.2g} x the given sigma; is sigma right, or the model?"))
    spread_f = float(np.percentile(F[work], 90) - np.percentile(F[work], 10)) if n_work else 0.0
    if sigma is None and st is not None and np.isfinite(st.sigma_post) and st.sigma_post > 0.02 * max(spread_f, 1e-300):
        found.append(("inconsistent", f"the estimated noise {st.sigma_post:.3g} is {100 * st.sigma_post / spread_f:.0f} % "
                      "of the spread of the data: the model does not fit (transposed matrix, wrong units, not TDOA data?)"))
    for note in undecided:
        found.append(("ambiguous", note))
    if other_minimum is not None:
        found.append(("ambiguous", f"a second least-squares minimum on the same inliers (reached by moving "
                      f"{other_minimum[1]}) fits within {other_minimum[0]:.2g} sigma^2: the data do not decide"))
    unplaced = int((~placed_r & mask.any(axis=1)).sum() + (~placed_t & mask.any(axis=0)).sum())
    if unplaced:
        found.append(("partial", f"{unplaced} node(s) with measurements could not be placed"))
    short_of = search.short_of
    if short_of > 0 and sigma is None and st is not None and st.dof >= opts.min_dof_for_sigma and search.block:
        # The count assumed unknown_sigma_outliers of gross errors (a hypothesis's own scale is not to be
        # trusted); the adjustment's inlier share, at a sigma estimated from its inliers with enough
        # redundancy and every rejection tested, is: the count it needs may have been met.
        share = float(inl.sum()) / max(int(work.sum()), 1)
        need = _needed(share, search.block[0], opts.confidence, tolerated=search.block[1])
        if search.samples >= need:
            short_of = 0
            warnings.append(f"the hypothesis search drew {search.samples} samples: enough for a sample without gross "
                            f"errors at the adjustment's inlier share ({100 * share:.1f} %, {math.ceil(need)} needed), "
                            f"not at the {100 * opts.unknown_sigma_outliers:g} % of gross errors assumed while searching")
    if short_of > 0:
        found.append(("uncontrolled", _short_search(search, short_of, opts, sigma is None)))
    if sigma is None and (st is None or st.dof < opts.min_dof_for_sigma):
        dof = st.dof if st is not None else 0
        found.append(("uncontrolled", f"too little redundancy to estimate sigma ({dof} degrees of freedom, needs "
                      f"{opts.min_dof_for_sigma}): give sigma (--sigma) to test the measurements"))
    if search.unconfirmed > 0:
        found.append(("uncontrolled", f"the data hold too few distinct blocks to confirm the calibration: "
                      f"{math.ceil(search.unconfirmed)} more sample(s) with a hypothesis were needed, with sigma "
                      "unknown, to rule out a better one (give sigma to test it)"))
    n_unc = int(uncontrolled.sum())
    if n_unc:
        nodes = sorted({f"r{i + 1}" for i in np.flatnonzero(uncontrolled.any(axis=1))} |
                       {f"s{j + 1}" for j in np.flatnonzero(uncontrolled.any(axis=0))},
                       key=lambda s: (s[0], int(s[1:])))
        listed = ", ".join(nodes[:8]) + (", ..." if len(nodes) > 8 else "")
        found.append(("uncontrolled", f"{n_unc} measurement(s) have redundancy numbers below {opts.min_redundancy:g}: an "
                      f"error in them cannot be detected (nodes {listed})"))
    if deficient:
        found.append(("uncontrolled", "the fit is rank-deficient: some coordinates are not determined (std inf)"))
    for t, c, group in unresolved:
        names = ", ".join(f"r{i + 1}-s{j + 1}" for i, j in group[:6]) + (", ..." if len(group) > 6 else "")
        found.append(("uncontrolled", f"the exact leave-one-out test finds an error (t = {t:.3g} > {c:.3g}) that "
                      f"cannot be located: removing any of {names} (different nodes) explains it as well"))
    for done in exact:
        if done.any():
            # the robust route kept an error its tests could not see: what else they missed is not known
            # (12r/8s, 1 cm, 5 % gross errors: the right entry, and the answer right; another network's fit,
            # three gross errors absorbed and sigma 10 x too large, lost a good entry to the same test)
            names = ", ".join(f"r{i + 1}-s{j + 1}" for i, j in np.argwhere(done)[:6])
            found.append(("uncontrolled", f"the exact leave-one-out test rejected {names} (redundancy number below "
                          f"{opts.weak_redundancy:g}), which the robust classification kept: its tests, at the estimated "
                          "sigma, see little there and may have missed more; give sigma to test the measurements"))
    if sigma is None:
        tested = work & ~inl & placed_r[:, None] & placed_t[None, :]
        for done in exact:
            tested &= ~done
        marginal = _marginal_rejections(tested, inl, w_test, redundancy, crit, opts)
        if marginal:
            names = ", ".join(f"r{i + 1}-s{j + 1}" for i, j in marginal[:6]) + (", ..." if len(marginal) > 6 else "")
            head = (f"{len(marginal)} rejected measurement(s) ({names}) lie only 1-3 critical values out at a node "
                    f"that keeps measurements of redundancy number below {opts.weak_redundancy:g}")
            suspects = _weak_at(marginal, inl, redundancy, opts)
            verdict = (probe(suspects, float(sig), st.dof, (R, S, rstd, tstd))
                       if probe is not None and st is not None else None)
            if verdict is None:
                found.append(("uncontrolled", f"{head}: an error absorbed there (sigma estimated, its tests blind) "
                              "can push good measurements out instead; give sigma to test them"))
            elif verdict[0] == "absorbed":
                _, again, note = verdict
                return replace(again, warnings=(f"{head}; {note}",) + again.warnings)
            elif verdict[0] == "undecided":
                found.append(("uncontrolled", f"{head}; {verdict[2]}: an error absorbed there (sigma estimated, its "
                              "tests blind) can push good measurements out instead; give sigma to test them"))
            else:
                warnings.append(f"{head}; {verdict[2]}")
    status = worst("ok", *(s for s, _ in found))
    warnings = [why for _, why in found] + symptoms + [w for w in warnings if w not in {why for _, why in found}]
    # reported only (every test above used the linear std): a far node's skewed range error (frame.widen_far_ranges)
    rcov, tcov, widened = widen_far_ranges(R, S, rcov, tcov)
    if widened:
        rstd, tstd = rstd.copy(), tstd.copy()
        for kind, k in widened:
            std, cov = (rstd, rcov) if kind == "r" else (tstd, tcov)
            std[k] = math.sqrt(float(np.trace(cov[k, :dim, :dim])))
        listed = ", ".join(f"{kind}{k + 1}" for kind, k in widened[:8]) + (", ..." if len(widened) > 8 else "")
        warnings.append(f"{len(widened)} node(s) far from the other nodes have their range weakly determined (its std "
                        f"over {100 * RANGE_SHARE:g} % of the range): their std and covariance are widened along the range to "
                        f"the far side of the 1-sigma interval in 1 / range, where the error is symmetric ({listed})")
    res = CalibrationResult(
        status=status, message="", receivers=R, transmitters=S, offsets=O, inliers=inl, residuals=E,
        rms=rms, sigma=float(sig), sigma_estimated=sigma is None,
        receiver_std=rstd, transmitter_std=tstd, offset_std=ostd, warnings=tuple(warnings),
        solver="+".join(sorted(search.solvers)), samples=search.samples, hypotheses=search.hypotheses,
        seconds=time.perf_counter() - t0, seed=seed, dof=st.dof if st is not None else 0,
        # no test without redundancy (dof 0: global_passed None), not a failed one (bool(None) was False)
        global_test=None if st is None or st.global_statistic is None or st.global_passed is None else
        (float(st.global_statistic), float(st.global_critical), bool(st.global_passed)),
        redundancy=redundancy, w_test=w_test, critical_value=float(crit), mdb=mdb,
        receiver_reliability=rrel, transmitter_reliability=trel, uncontrolled=uncontrolled, measured=mask,
        gauge=tuple(int(g) for g in order[:dim]) if gauged is not None else None,
        receiver_cov=np.where(placed_r[:, None, None], rcov, np.nan),
        transmitter_cov=np.where(placed_t[:, None, None], tcov, np.nan),
    )
    return replace(res, message=message(status, res, found[0][1] if found else route_note(route)))
