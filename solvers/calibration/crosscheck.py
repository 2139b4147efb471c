"""Judge by comparison: a search's answer checked against other fits of the same data (stage 4).

A hypothesis search (`search._calibrate_once`) depends on its seed and on the sigma it was given; what
its own statistics cannot see, another fit of the same data can. In the order `recheck` runs them:
- the given sigma (`_check_sigma`): tested against the calibration with sigma estimated; where that one
  fits the given sigma and explains the data better, the search restarts from it (`_restart_from`);
- a second seed (`_second_seed`): two answers that fit about as well make the result "ambiguous";
- 2D data the model does not explain: fitted in 3D too (`_suggest_3d`, advice only);
- sigma estimated: the transposed matrix (`_check_orientation`).
A factorization-started answer (plane waves) needs none of these: its start comes from the data's own
structure (no sampling), and the diagnosis has compared the two orientations (`_judge_route`). That start
is a hypothesis of the diagnosis, which its fit tests (`judge.unexplained`); a fit that does not explain
the data sends them to the search, and `choose_model` keeps the answer that explains them better.

Where a stage could choose from the data instead (not done in this step, behaviour unchanged): the
orientation is a property of the data alone (the diagnosis compares the two for plane waves; a near-field
analogue would replace the transposed search), and the 3D suggestion could come from the diagnosis's
singular values rather than from a second search.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from . import search
from .adjustment import enough_data, n_unknowns
from .diagnose import ORIENTATION_DECIDED
from .flags import _beyond_std
from .judge import message, worst
from .result import CalibrationOptions, CalibrationResult
from .search import UNUSABLE, _floor, log
from .state import Diagnosis


def _judge_route(F, diagnosis: Diagnosis, result: CalibrationResult, opts: CalibrationOptions) -> CalibrationResult:
    """The orientation of a factorization-started answer: decided when the row-offset fit is
    ORIENTATION_DECIDED times worse than the column-offset one, else said (the columns were taken as the
    transmitters); with the orientation given (CalibrationOptions.orientation_given) nothing is said."""
    if (not opts.orientation_given and not diagnosis.orientation_ratio >= ORIENTATION_DECIDED
            and result.status in ("ok", "uncontrolled")):
        note = (f"the factorization fits the transposed matrix about as well (scale ratio "
                f"{diagnosis.orientation_ratio:.2g}): the data do not decide whether rows are receivers")
        return replace(result, warnings=result.warnings + (note,))
    return result


def choose_model(F, sigma, opts: CalibrationOptions, diagnosis: Diagnosis, tried: CalibrationResult, why: str,
                 searched: CalibrationResult) -> CalibrationResult:
    """The answer when the plane-wave hypothesis of the diagnosis was refuted by its own fit (`tried`, which
    does not explain the data: `why`) and the point-source search ran (`searched`, after `recheck`): the
    one that explains the data better, as `_second_seed` orders two answers (usable first, then the
    truncated cost at one scale, then more inliers); a warning says which model was tried, why it was
    left and what the other gave. (The plane-wave adjustment is the exact point-source model through an
    inverse range: its fit fails from a start in the wrong basin, which is what the search is for.)"""
    cost_t, cost_s, scale = _truncated_costs(tried, searched, sigma, opts, _floor(F))
    left = (f"the diagnosis proposed plane waves (curvature {diagnosis.curvature:.2g} of the linear term), but the "
            f"fit from the plane-wave factorization does not explain the data ({why}; {tried.status})")
    if _rank(searched, cost_s) <= _rank(tried, cost_t):
        note = (f"{left}: the point-source hypothesis search was run, and its answer explains the data better "
                f"(truncated cost {cost_s / scale**2:.4g} against {cost_t / scale**2:.4g} sigma^2)")
        return replace(searched, warnings=searched.warnings + (note,))
    note = (f"{left}; the point-source hypothesis search explains them no better ({searched.status}, truncated cost "
            f"{cost_s / scale**2:.4g} against {cost_t / scale**2:.4g} sigma^2): the plane-wave fit is kept")
    return replace(tried, warnings=tried.warnings + (note,))


def _fits_given_sigma(res: CalibrationResult) -> bool:
    """A usable answer whose global test passes at the given sigma."""
    return res.status not in UNUSABLE and res.global_test is not None and res.global_test[2]


def _check_sigma(F, sigma, seed, opts: CalibrationOptions, t0, dim: int, result: CalibrationResult,
                 second_search=None) -> CalibrationResult:
    """A given sigma that rejected measurements or failed the global test, or whose search found no
    hypothesis at all, is checked against the data: the calibration with sigma estimated (which rejects
    only what its own scale calls gross) is tested with the given sigma, SSR / sigma^2 = dof
    (sigma_hat / sigma)^2 against chi^2(dof). If it passes, `_restart_from`. If it fails, the given
    sigma may be too small (the measurements it rejected are not gross errors), or the sigma-estimated
    answer kept a gross error that inflated its scale (10r/6s at 1 cm with 5 % gross errors: sigma
    0.0375 estimated, one gross error kept, while least squares from the truth passes the test at the
    given 0.01). So before the given sigma is blamed, the sigma-given answer, then the search with the
    second seed (`second_search`, None: not run), is taken when it is usable, passes its global test
    (`_fits_given_sigma`) and its rejections look like gross errors, not like the cut tail of a noise
    larger than the given sigma (`_rejections_look_gross`). Only when none does, the answer is the
    sigma-estimated one, with status "inconsistent" and the sigma the data support in the message."""
    from scipy import stats

    failed_test = result.global_test is not None and not result.global_test[2]
    rejected = int((np.isfinite(F) & ~result.inliers).sum()) if result.status != "failed" else 0
    # a failed search at a small sigma: every hypothesis from a noisy block scored outside 3 sigma
    # (16r/10s, sigma 0.1 mm, 30 % missing: 4 of 10 networks), while the data calibrate without sigma
    searched = result.status == "failed" and enough_data(*F.shape, int(np.isfinite(F).sum()), dim)
    if not (searched or (result.status != "failed" and (rejected or failed_test))):
        return result
    log.info("check of the given sigma: the calibration with sigma estimated")
    est = search._calibrate_once(F, None, seed, replace(opts, stability_check=False), t0, dim)
    if est.status in UNUSABLE or min(est.dof, _redundancy(est, dim)) < opts.min_dof_for_sigma:
        return result
    statistic = est.dof * (est.sigma / sigma) ** 2
    critical = float(stats.chi2.isf(opts.alpha_global, est.dof))
    if statistic <= critical:
        return _restart_from(F, sigma, seed, opts, t0, dim, result, est)
    candidates = [lambda: result] + ([second_search] if second_search is not None else [])
    for candidate in candidates:
        answer = candidate()
        if not _fits_given_sigma(answer):
            continue
        gross, beyond, marginal = _rejections_look_gross(answer)
        if not gross:
            continue
        ssr, crit, _ = answer.global_test
        note = (f"the calibration with sigma estimated ({est.sigma:.3g}, keeping "
                f"{int(est.inliers.sum()) - int(answer.inliers.sum())} more measurement(s)) does not fit the given "
                f"sigma {sigma:.3g} (SSR / sigma^2 = {statistic:.4g} > {critical:.4g}), but this answer (seed "
                f"{answer.seed}) does (SSR / sigma^2 = {ssr:.4g} <= {crit:.4g}) and its rejections look like gross "
                f"errors ({beyond} beyond {GROSS_BEYOND_DOUBT:g} x the critical value, {marginal} between 1 and "
                f"{GROSS_BEYOND_DOUBT:g} x): the given sigma is kept")
        return replace(answer, warnings=answer.warnings + (note,))
    kept = int(est.inliers.sum()) - int(result.inliers.sum())
    note = (f"the given sigma {sigma:.3g} is too small for these data: they support sigma {est.sigma:.3g} ({est.dof} "
            f"degrees of freedom; with the given sigma SSR / sigma^2 = {statistic:.4g} > {critical:.4g}); the answer "
            f"is the one with sigma estimated, which keeps {kept} more measurement(s) the given sigma would reject: "
            f"give --sigma {est.sigma:.2g} or omit it")
    return replace(est, status="inconsistent", message=message("inconsistent", est, note),
                   warnings=(note,) + est.warnings)


def _redundancy(res: CalibrationResult, dim: int) -> int:
    """Kept entries minus the unknowns of the placed nodes: the most degrees of freedom a fit can have. A fit
    whose normal matrix is found singular throughout reports more (8r/5s, 30 % missing, 28 entries for 28
    unknowns, network 64 of bench_calibrate: a wrong basin counted with 28), which no estimate of sigma has."""
    placed = (int(np.isfinite(res.receivers[:, 0]).sum()), int(np.isfinite(res.transmitters[:, 0]).sum()))
    return int(res.inliers.sum()) - n_unknowns(*placed, dim)


#: Rejections with |w| beyond this many critical values would stand with a sigma that many times the given one
#: (gross errors beyond doubt); those between 1 and this many are marginal (`_rejections_look_gross`).
GROSS_BEYOND_DOUBT = 3.0


def _rejections_look_gross(res: CalibrationResult) -> tuple[bool, int, int]:
    """(whether the rejections of a sigma-given answer look like gross errors, how many are beyond doubt,
    how many are marginal). A sigma k times too small cuts the tail of the noise: its rejections lie
    just above the critical value c (|w| = k |z|: at k = 3, 27 % of the good entries in (c, 3c], 0.1 %
    beyond; k = 5: 46 % and 5 %; 12r/10s in the plane, 3x too small: 17 rejections at 3.5-9, none
    beyond). A right sigma rejects gross errors, mostly far beyond (10r/6s at 1 cm: 47 and 114) and
    marginal ones only where a gross error distorts the fit. The rejections look gross when those beyond
    doubt (|w| > GROSS_BEYOND_DOUBT c) are at least as many as the marginal ones, and at least one."""
    c = res.critical_value
    if res.w_test is None or res.measured is None or not np.isfinite(c):  # (a failed search: no tests)
        return False, 0, 0
    w = np.abs(np.nan_to_num(res.w_test, nan=0.0))[res.measured & ~res.inliers]
    beyond = int((w > GROSS_BEYOND_DOUBT * c).sum())
    marginal = int(((w > c) & (w <= GROSS_BEYOND_DOUBT * c)).sum())
    return beyond >= max(1, marginal), beyond, marginal


def _restart_from(F, sigma, seed, opts: CalibrationOptions, t0, dim: int, result: CalibrationResult,
                  est: CalibrationResult) -> CalibrationResult:
    """The given sigma fits the sigma-estimated calibration `est`. Where `est` explains the data better
    than the sigma-given search's answer (truncated cost at 3 sigma lower by more than
    `ambiguity_chi2` sigma^2), that search missed the basin: its hypotheses are scored at 3 given
    sigmas, and a hypothesis extended from a noisy block lies outside that band on most entries even in
    the right basin (16r/10s at sigma 1 cm with 5 % gross errors: 6 of 193 hypotheses in the basin,
    every one scored as explaining < 1 % of the entries). The sigma-given search then runs again with
    `est` offered first; its answer is kept if it explains the data better than the first one."""
    floor = _floor(F)
    cost_r, cost_e, scale = _truncated_costs(result, est, sigma, opts, floor)
    if not cost_e < cost_r - opts.ambiguity_chi2 * scale**2:
        return result
    again = search._calibrate_once(F, sigma, seed, opts, t0, dim, hint=(est.receivers, est.transmitters, est.offsets))
    cost_a, _, _ = _truncated_costs(again, result, sigma, opts, floor)
    if again.status == "failed" or not cost_a < cost_r:
        return result
    note = ("the search with the given sigma was restarted from the calibration with sigma estimated, which the "
            "given sigma fits and which explains the data better")
    return replace(again, warnings=again.warnings + (note,))


#: The transposed matrix's sigma estimate below this fraction of the answer's: the file is transposed.
TRANSPOSED_SIGMA_RATIO = 1.0 / 3.0
#: With the orientation given, a transposed matrix with more rows than this and than the given one is not fitted.
ORIENTATION_CHECK_ROWS = 100
#: A matrix with more rows or columns than this has its orientation compared on a seeded sub-network of at most
#: this many rows and columns, both orientations fitted there: the orientation is a property of every part of
#: the data, and the transposed search of the whole (100r/60s in 3D: 60 receivers x 100 transmitters) cost
#: 9/10 of the call.
ORIENTATION_BLOCK = 30


def _check_orientation(F, seed, opts: CalibrationOptions, t0, dim: int, result: CalibrationResult) -> CalibrationResult:
    """With sigma estimated, a transposed matrix (transmitters as rows) can be fitted too, on its own
    inflated noise scale. Where the transposed matrix is a calibratable shape, it is fitted with a small
    budget (a matrix in the right orientation is found quickly: clean data fit at once); when its sigma
    estimate is below TRANSPOSED_SIGMA_RATIO x this one's and it passes its checks, the data are
    transposed: status "inconsistent", and the message says so. A fit of the transposed matrix that is
    merely as good makes the orientation undecided: status "ambiguous", unless the caller gave the
    orientation (CalibrationOptions.orientation_given): then it is a note among the warnings.
    With the orientation given and more transmitters than max(receivers, ORIENTATION_CHECK_ROWS), the
    transposed matrix is not fitted (its receivers' reduced system would be the large one: 540
    receivers x 48 in 3D, 1,614 unknowns, minutes) and a note says so."""
    m, n = F.shape
    if not enough_data(n, m, int(np.isfinite(F).sum()), dim):
        return result
    if opts.orientation_given and n > max(m, ORIENTATION_CHECK_ROWS):
        note = (f"the orientation was given: the transposed matrix ({n} receivers x {m} transmitters) was not fitted "
                "to compare")
        return replace(result, warnings=result.warnings + (note,))
    # blocks only (no sub-networks, no basin probing): a clean transposed file fits at once
    quick = replace(opts, stability_check=False, max_samples=min(opts.max_samples, 20), subnetwork_samples=0,
                    max_confirm_samples=5, probe_nodes=0)
    block, where = _orientation_block(F, seed, dim)
    if block is None:
        log.info("orientation check: the transposed matrix")
        mine = result.sigma
    else:
        log.info("orientation check: both orientations of a %d x %d sub-network", *block.shape)
        own = search._calibrate_once(block, None, seed, quick, t0, dim)
        if own.status not in ("ok", "uncontrolled", "ambiguous") or not np.isfinite(own.sigma):
            return result
        mine, F = own.sigma, block
    other = search._calibrate_once(np.ascontiguousarray(F.T), None, seed, quick, t0, dim)
    if other.status not in ("ok", "uncontrolled", "ambiguous") or not np.isfinite(other.sigma):
        return result
    versus = f"sigma {other.sigma:.3g} against {mine:.3g}{where}"
    if other.sigma < TRANSPOSED_SIGMA_RATIO * mine:
        note = (f"the transposed matrix fits far better ({versus}): the rows "
                "look like transmitters; give --transpose (calibrate(F.T))")
        return replace(result, status=worst(result.status, "inconsistent"), warnings=(note,) + result.warnings,
                       message=message(worst(result.status, "inconsistent"), result, note))
    if mine < TRANSPOSED_SIGMA_RATIO * other.sigma:
        return result
    if opts.orientation_given:
        note = (f"the transposed matrix fits about as well ({versus}): the "
                "data alone do not decide whether rows are receivers or transmitters; the given orientation is used")
        return replace(result, warnings=result.warnings + (note,))
    note = (f"the transposed matrix fits about as well ({versus}): the data do "
            "not decide whether rows are receivers or transmitters (give the orientation: --oriented)")
    return replace(result, status=worst(result.status, "ambiguous"), warnings=(note,) + result.warnings,
                   message=message(worst(result.status, "ambiguous"), result, note))


def _orientation_block(F, seed, dim: int):
    """The seeded sub-network on which a large matrix's two orientations are compared (at most
    ORIENTATION_BLOCK rows and columns, each kept row and column with enough entries for the block to be
    calibratable both ways), with the words that say so; (None, "") for a matrix small enough to compare whole."""
    m, n = F.shape
    if max(m, n) <= ORIENTATION_BLOCK:
        return None, ""
    rng = np.random.default_rng([seed, 0x0B1])
    rows = np.sort(rng.choice(m, min(m, ORIENTATION_BLOCK), replace=False))
    cols = np.sort(rng.choice(n, min(n, ORIENTATION_BLOCK), replace=False))
    block = np.ascontiguousarray(F[np.ix_(rows, cols)])
    a, b = block.shape
    if not (enough_data(a, b, int(np.isfinite(block).sum()), dim) and enough_data(b, a, int(np.isfinite(block).sum()), dim)):
        return None, ""
    return block, f" on a seeded {a} x {b} sub-network"


def _suggest_3d(F, sigma, seed, opts: CalibrationOptions, t0, result: CalibrationResult) -> CalibrationResult:
    """A 2D calibration the model does not explain: fit in 3D too, and where that passes its checks
    (status ok: the global test with the given sigma, or an estimated sigma the spread of the data
    supports), say so in the message (the 2D answer and its status are kept)."""
    m, n = F.shape
    if not enough_data(m, n, int(np.isfinite(F).sum()), 3):
        return result
    other = search._calibrate_once(F, sigma, seed, replace(opts, stability_check=False), t0, 3)
    if other.status != "ok":
        return result
    note = (f"the data fit a 3D network (dim=3: status ok, rms {other.rms:.3g}, sigma {other.sigma:.3g}): calibrate "
            "with dim=3 (--dim 3)")
    return replace(result, message=f"{result.message} - {note}", warnings=result.warnings + (note,))


def _truncated_costs(a: CalibrationResult, b: CalibrationResult, sigma, opts: CalibrationOptions, floor: float):
    """(cost of a, cost of b, scale s): sum over every measured entry of min(e^2, (k s)^2) (an entry
    of an unplaced node counts (k s)^2) at one scale s, the given sigma or the larger estimate (the
    smaller could be that of a fit that explains a subset exactly and call everything else an outlier)."""
    s = sigma if sigma is not None else float(np.nanmax([a.sigma, b.sigma]))
    if not (np.isfinite(s) and s > floor):
        s = floor  # neither fit has a noise estimate (no redundancy left): the search's floor
    cap = (opts.threshold_sigmas * s) ** 2

    def cost(r):
        e = r.residuals[r.measured]
        return float(np.sum(np.minimum(np.nan_to_num(e, nan=np.inf) ** 2, cap)))

    return cost(a), cost(b), s


def _differs(a: CalibrationResult, b: CalibrationResult) -> bool:
    """True when two results differ: another inlier set, nodes placed in one only, or positions that
    differ (after a rigid alignment, reflections allowed) by more than 3 reported standard deviations."""
    if not np.array_equal(a.inliers, b.inliers):
        return True
    pa = np.concatenate([np.isfinite(a.receivers[:, 0]), np.isfinite(a.transmitters[:, 0])])
    pb = np.concatenate([np.isfinite(b.receivers[:, 0]), np.isfinite(b.transmitters[:, 0])])
    if not np.array_equal(pa, pb) or pa.sum() < 3:
        return bool(not np.array_equal(pa, pb))
    X = np.vstack([a.receivers, a.transmitters])[pa]
    return _beyond_std(b.receivers, b.transmitters, a.receivers, a.transmitters, a.receiver_std, a.transmitter_std,
                       1e-9 * max(float(np.abs(X).max()), 1.0))


def recheck(F, sigma, seed, opts: CalibrationOptions, t0, dim: int, result: CalibrationResult) -> CalibrationResult:
    """The checks of a search's answer against other fits of the same data, in the order of the module
    docstring; the search with the second seed runs once, whichever check asks first."""
    seed2 = int(np.random.SeedSequence(seed if seed is not None else None).generate_state(1)[0])
    second: list[CalibrationResult] = []

    def second_search() -> CalibrationResult:
        """The search with the second seed (run once, whichever check asks first)."""
        if not second:
            log.info("a second search with seed %d", seed2)
            second.append(search._calibrate_once(F, sigma, seed2, opts, t0, dim))
        return second[0]

    if sigma is not None:
        result = _check_sigma(F, sigma, seed, opts, t0, dim, result, second_search if opts.stability_check else None)
    rejected = int((np.isfinite(F) & ~result.inliers).sum()) if result.status != "failed" else 0
    # (an unconverged answer gets the second search too: a search that found no basin with one seed can
    # find it with another; 16r/10s, 1 cm, 5 % gross, sigma estimated: 1 of 20 networks)
    if opts.stability_check and rejected and result.status != "failed":
        log.info("stability check")
        result = _second_seed(F, sigma, opts, result, second_search())
    if dim == 2 and result.status in ("inconsistent", "unconverged", "failed"):
        result = _suggest_3d(F, sigma, seed, opts, t0, result)
    if sigma is None and result.status in ("ok", "uncontrolled", "ambiguous"):
        result = _check_orientation(F, seed, opts, t0, dim, result)
    return result


def _rank(res: CalibrationResult, cost: float) -> tuple:
    """Order of two answers to the same data: usable first, then the truncated cost, then more inliers."""
    return res.status in UNUSABLE, cost, -int(res.inliers.sum())


def _second_seed(F, sigma, opts: CalibrationOptions, result: CalibrationResult, other: CalibrationResult
                 ) -> CalibrationResult:
    """The answer of the search with the second seed against this one: where they differ, the better
    (usable first, then the truncated cost, then more inliers) is kept; "ambiguous" when the other fits
    within opts.ambiguity_chi2 sigma^2 (both reported), else a note says what the other found."""
    if other is result or other.status == "failed" or not _differs(result, other):
        return result
    cost_r, cost_o, scale = _truncated_costs(result, other, sigma, opts, _floor(F))
    first, second = (result, other) if _rank(result, cost_r) <= _rank(other, cost_o) else (other, result)
    gap = abs(cost_r - cost_o) / scale**2 if np.isfinite(cost_r - cost_o) else np.inf
    n_diff = int((first.inliers != second.inliers).sum())
    if gap < opts.ambiguity_chi2:
        note = (f"seed-dependent: a second search (seed {second.seed}) gives another answer that fits about as "
                f"well (cost +{gap:.2g} sigma^2; {n_diff} measurements classified differently or nodes moved "
                f"beyond 3 std); both are reported")
        status = worst(first.status, "ambiguous")
        return replace(first, status=status, warnings=(note,) + first.warnings, alternative=second.to_dict(),
                       message=message(status, first, note))
    if first is other:
        note = (f"the search with seed {result.seed} ended {result.status} (cost +{gap:.3g} sigma^2); a second "
                f"search (seed {other.seed}) found this answer")
        return replace(first, warnings=first.warnings + (note,))
    note = (f"a second search (seed {second.seed}) found a worse answer (cost +{gap:.3g} sigma^2, {n_diff} "
            f"measurements classified differently); this one is kept")
    return replace(first, warnings=first.warnings + (note,))
