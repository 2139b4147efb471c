"""The second, geometry-guided pass of `tdoa` (issue 45): a first calibration's positions narrow each
channel pair's search for its direct sound.

The first pass (:func:`solvers.audio.tdoa_matrix`) knows nothing of the geometry: in a reverberant room
a pair's eight highest GCC-PHAT peaks may miss the direct sound, and an event whose channels agree on
too few pairs is left missing whole. Once `calibrate` has placed every receiver from that matrix, each
event has a source position (the calibration's transmitter, or, for an event it did not place, one
located from the event's own pair candidates, :func:`locate_source`), and the geometry predicts every
pair's arrival difference. The second pass (:func:`guided_tdoa_matrix`) keeps only the correlation's
local maxima within a window of a few samples around that prediction (its half-width from the
calibration's standard deviations, `GuideOptions.window_sigmas`) and runs the first pass's consensus
on them: the entries are measured peaks (parabolic sub-sample lags), never the prediction, and an
entry or an event that the peaks do not support is left missing as in the first pass.
:func:`tdoa_and_calibrate` is the whole chain a user gets: first pass, calibration, guided pass,
calibration of the guided matrix.

The prediction is trusted only from a calibration whose status is in `GuideOptions.trusted` ("ok", or
"uncontrolled": a fit that passed its model test but has measurements of too little redundancy to be
tested, whose nodes are still placed to their std) with every receiver placed and finite std; any
other first calibration leaves the first pass's matrix as the answer, and its notes say why.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .audio import (TdoaMatrix, TdoaOptions, _candidate_tensor, _consensus, _measure, _over_tapers, emphasised,
                    _pair_candidates, agreeing_pairs, tdoa_matrix)
from .recording import Recording

__all__ = ["GuideOptions", "GuidedTdoa", "guided_tdoa_matrix", "locate_from_entries", "locate_source", "reconcile",
           "tdoa_and_calibrate", "tdoa_guided"]


@dataclass(frozen=True)
class GuideOptions:
    """How the first calibration guides the second pass.

    trusted : statuses of the first calibration whose positions guide ("ok", "uncontrolled"; every
        receiver must be placed with a finite std besides)
    window_sigmas : each pair's window reaches the consensus tolerance plus this many standard
        deviations of the predicted difference beyond the prediction; the std combines the two
        receivers' and the source's position std (conservatively: the whole position std along the
        pair's direction) and the noise of a measured difference (sqrt(2) x the calibration's sigma)
    peaks : each pair's highest local maxima (the first pass's candidates: 8) of which those within its
        window are kept (any local maximum within the window would do worse: a correlation's sidelobes and
        noise put one within a sample or two of any prediction, right or wrong)
    min_agreement : an event of the guided pass is left missing whole when its channels agree on less
        than this share of the pairs. The first pass's rule (TdoaOptions.min_agreement, 0.5) guards
        against an event whose arrivals all belong to a reflection; within windows around the direct
        sound's predicted differences that cannot happen, and fewer agreeing pairs suffice
    locate_samples : RANSAC hypotheses for an event the calibration did not place (each from dim + 1
        candidate differences against one of the three loudest channels)
    locate_tolerance : samples within which a pair's candidate agrees with a located source
    locate_share : a located source needs this share of the pairs agreeing with it (locate_source): a
        position that fits only a few pairs' candidates can be a reflection's or chance's (on the
        simulated rooms, located sources 4-27 m off had 19-26 % of the pairs agree, right ones 49-67 %)
    seed : of the localisation's sampling (each event its own stream)
    calibrate_events : the first calibration (tdoa_guided) uses at most this many of the first pass's events,
        those with the most entries (the earliest on a tie): its receivers guide every event, and an event
        outside them is located from its own first-pass entries (locate_from_entries), or, when those do not
        fit, from its candidates (locate_source). A calibration's cost grows faster than its events (on the
        10-minute file of scripts/bench_audio_stream.py, 300 events, `tdoa` stopped at 483 s, the first pass
        taking 45 s); a guide needs the receivers, which 40 events of 16 channels place
    retry_least_supported : when the first calibration cannot guide (`_trust`), it is run once more without the
        entries that only TdoaOptions.min_support other channels agree with (the least sure the first pass keeps:
        in the 16 kHz / 0.8 s / 10 dB speech room of tables/audio3d_kinds, 4 of its 8 wrong entries and none of
        its 63 right ones), and guides when that one can
    """

    trusted: tuple[str, ...] = ("ok", "uncontrolled")
    window_sigmas: float = 3.0
    peaks: int = 8
    min_agreement: float = 0.3
    locate_samples: int = 3000
    locate_tolerance: float = 1.5
    locate_share: float = 0.4
    seed: int = 0
    calibrate_events: int = 40
    retry_least_supported: bool = True

    def __post_init__(self) -> None:
        if not (np.isfinite(self.window_sigmas) and self.window_sigmas >= 0):
            raise ValueError(f"window_sigmas must be a finite number >= 0, got {self.window_sigmas}")
        if not 0.0 <= self.min_agreement <= 1.0:
            raise ValueError(f"min_agreement must be in [0, 1], got {self.min_agreement}")
        if self.calibrate_events < 1:
            raise ValueError(f"calibrate_events must be >= 1, got {self.calibrate_events}")
        if self.peaks < 1 or self.locate_samples < 1 or not (np.isfinite(self.locate_tolerance) and self.locate_tolerance > 0):
            raise ValueError("peaks and locate_samples must be >= 1 and locate_tolerance > 0")


@dataclass(frozen=True, eq=False)
class GuidedTdoa:
    """What `tdoa` made of a recording, pass by pass.

    first : the first pass's matrix (solvers.audio.tdoa_matrix)
    first_calibration : `calibrate` of the first pass (sigma estimated), None without a guide
    matrix : the guided pass's matrix, or the first pass's when nothing guided it (its notes say why)
    guided : whether `matrix` is the guided pass's
    calibration : `calibrate` of `matrix` (tdoa_and_calibrate), else None
    """

    first: TdoaMatrix
    first_calibration: object
    matrix: TdoaMatrix
    guided: bool
    calibration: object = None


def _differences(receivers: np.ndarray, sources: np.ndarray) -> np.ndarray:
    """(S, m) distances of S sources to the receivers."""
    return np.linalg.norm(sources[:, None, :] - receivers[None, :, :], axis=2)


def _agreeing_pairs(P: np.ndarray, dist: np.ndarray, tol: float) -> np.ndarray:
    """(S, m, m) bool: pairs with a candidate within tol of the distances' difference (dist (S, m))."""
    pred = dist[:, :, None] - dist[:, None, :]
    with np.errstate(invalid="ignore"):
        return np.any(np.abs(P[None] - pred[..., None]) <= tol, axis=3)


def locate_source(receivers: np.ndarray, i, k, lags, heights, *, references, tol: float = 1.5, samples: int = 3000,
                  min_support: int = 2, min_share: float = 0.0, refined: int = 20, seed: int = 0):
    """A source position from an event's pair candidates with the receivers known, or None.

    Parameters
    ----------
    receivers : (m, dim) positions in samples of sound travel (metres x rate / speed)
    i, k, lags, heights : the event's pair candidates (solvers.audio._pair_candidates: lag of channel i's
        sound behind channel k's, in samples)
    references : channels the hypotheses measure against (the loudest: their direct sound is clearest)
    tol : samples within which a candidate agrees with a position's predicted difference
    samples : RANSAC hypotheses; each takes one reference and, channel by channel in random order, one
        candidate of its pair with the reference that agrees (within tol) with a candidate of its pair
        with every channel taken before (a direct sound's differences close every triangle; a random
        mix of peaks rarely does), until dim + 1 channels are taken, and solves the linearised range
        differences (2 (r_o - r_ref) . s + 2 d_o d_ref = |r_o|^2 - |r_ref|^2 - d_o^2, unknowns s and the
        reference's range d_ref) exactly
    min_support : a channel agrees when at least this many of its pairs agree
    min_share : the share of all channel pairs that must agree with the position
    seed : of the sampling

    The `refined` hypotheses with the most agreeing pairs are refined by Gauss-Newton on them (the
    nearest candidate of each; three rounds, re-collecting the agreeing pairs), and the refined position
    with the most agreeing pairs is taken. Returns (position (dim,), the
    agreeing pairs (m, m) bool, rms residual of the agreeing pairs in samples) when at least dim + 2
    channels agree (a position in dim unknowns plus the event's emission time, and one channel to spare),
    else None.
    """
    receivers = np.asarray(receivers, dtype=float)
    m, dim = receivers.shape
    if m < dim + 2:
        return None
    P, H = _candidate_tensor(m, i, k, lags, heights)
    rng = np.random.default_rng(seed)
    refs = rng.choice(np.asarray(references), samples)
    rows, rhs = np.zeros((samples, dim + 1, dim + 1)), np.zeros((samples, dim + 1))
    usable = np.ones(samples, bool)
    sq = np.sum(receivers**2, axis=1)
    for h, r in enumerate(refs):
        chosen: dict[int, float] = {}  # channel -> its lag behind the reference
        for o in rng.permutation(np.flatnonzero(np.arange(m) != r)):
            options = P[o, r][np.isfinite(P[o, r])]
            for c, t in chosen.items():  # consistent with every channel chosen: a candidate of pair (o, c) agrees
                options = options[np.any(np.abs(P[o, c][None, :] - (options[:, None] - t)) <= tol, axis=1)]
            if len(options):
                chosen[int(o)] = float(rng.choice(options))
            if len(chosen) == dim + 1:
                break
        if len(chosen) < dim + 1:
            usable[h] = False
            continue
        for row, (o, d) in enumerate(chosen.items()):
            rows[h, row, :dim] = 2.0 * (receivers[o] - receivers[r])
            rows[h, row, dim] = 2.0 * d
            rhs[h, row] = sq[o] - sq[r] - d * d
    ok = usable & (np.abs(np.linalg.det(rows)) > 1e-9 * np.max(np.abs(rows)) ** (dim + 1))
    if not ok.any():
        return None
    sol = np.linalg.solve(rows[ok], rhs[ok][..., None])[..., 0]
    sol = sol[sol[:, dim] >= 0]  # the reference's range
    if not len(sol):
        return None
    score = np.concatenate([_agreeing_pairs(P, _differences(receivers, part[:, :dim]), tol).sum(axis=(1, 2))
                            for part in np.array_split(sol, -(-len(sol) // 100))])  # 100 at a time: bounded memory
    best = None
    for h in np.argsort(-score, kind="stable")[:refined]:  # a hypothesis from noisy lags fits better once refined
        s, pairs = sol[h, :dim], None
        for _ in range(3):
            s, pairs, rms = _refine(receivers, P, s, tol)
            if pairs is None:
                break
        if pairs is not None and (best is None or pairs.sum() > best[1].sum()):
            best = (s, pairs, rms)
    if best is None:
        return None
    s, pairs, rms = best
    support = pairs.sum(axis=1)
    if np.sum(support >= min_support) < dim + 2 or pairs.sum() < min_share * m * (m - 1):
        return None
    return s, pairs, rms


def locate_from_entries(receivers: np.ndarray, arrivals: np.ndarray, i, k, lags, heights, *, tol: float = 1.5,
                        min_support: int = 2, min_share: float = 0.0):
    """A source position from an event's measured arrivals with the receivers known, checked against the event's
    pair candidates, or None (then locate_source searches the candidates).

    receivers : (m, dim) positions in samples of sound travel; arrivals : (m,) the first pass's arrival times
    in samples (any constant; NaN: not measured). The linearised range differences of every measured channel
    against the earliest (locate_source's equations, least squares; twice the fit without one channel that puts
    the most channels within tol of their entries, refitted on those: a wrong entry pulls a fit of all) give a
    start (None unless dim + 2 channels' entries fit it within tol), refined by
    Gauss-Newton on the pairs whose candidates agree with it (_refine, three rounds). Returns (position,
    agreeing pairs, rms residual) as locate_source does when at least dim + 2 channels have min_support
    agreeing pairs and min_share of all pairs agree, else None."""
    receivers = np.asarray(receivers, dtype=float)
    m, dim = receivers.shape
    seen = np.flatnonzero(np.isfinite(arrivals))
    if len(seen) < dim + 2:
        return None
    r = int(seen[np.argmin(arrivals[seen])])
    sq = np.sum(receivers**2, axis=1)

    def fit(used):
        d = arrivals[used] - arrivals[r]
        A = np.hstack([2.0 * (receivers[used] - receivers[r]), 2.0 * d[:, None]])
        sol = np.linalg.lstsq(A, sq[used] - sq[r] - d * d, rcond=None)[0]
        dist = np.linalg.norm(sol[:dim] - receivers, axis=1)
        with np.errstate(invalid="ignore"):
            inside = np.abs(dist - dist[r] - (arrivals - arrivals[r])) <= tol  # NaN arrivals: outside
        return sol, np.flatnonzero(inside & (np.arange(m) != r))

    used = seen[seen != r]
    sol, inside = fit(used)
    for _ in range(2):  # a wrong entry pulls the fit: the fit without one channel that agrees with the most
        trials = [(sol, inside)] + [fit(np.delete(used, o)) for o in range(len(used))] if len(used) > dim + 1 else []
        best = max(trials, key=lambda t: len(t[1]), default=(sol, inside))
        if len(best[1]) < dim + 1:
            break
        used = best[1]
        sol, inside = fit(used)
    if not np.all(np.isfinite(sol)) or len(inside) < dim + 1:
        return None  # fewer than dim + 2 channels' entries fit one source
    P, _ = _candidate_tensor(m, i, k, lags, heights)
    s, pairs, rms = sol[:dim], None, np.inf
    for _ in range(3):
        s, pairs, rms = _refine(receivers, P, s, tol)
        if pairs is None:
            return None
    if np.sum(pairs.sum(axis=1) >= min_support) < dim + 2 or pairs.sum() < min_share * m * (m - 1):
        return None
    return s, pairs, rms


def _refine(receivers: np.ndarray, P: np.ndarray, s: np.ndarray, tol: float):
    """Gauss-Newton steps of the position s on the pairs agreeing with it (each its nearest candidate):
    (s, agreeing pairs after the steps, rms residual in samples); pairs None when fewer than dim + 1 agree."""
    m, dim = receivers.shape
    iu = np.triu_indices(m, 1)
    for _ in range(5):
        dist = np.linalg.norm(s - receivers, axis=1)
        pred = dist[:, None] - dist[None, :]
        with np.errstate(invalid="ignore"):
            gap = np.abs(P - pred[..., None])
        near = np.where(np.isfinite(gap), gap, np.inf).argmin(axis=2)
        val = np.take_along_axis(P, near[..., None], axis=2)[..., 0]
        pairs = np.abs(val - pred) <= tol
        sel = pairs[iu]
        if sel.sum() < dim + 1:
            return s, None, np.inf
        a, b = iu[0][sel], iu[1][sel]
        unit = (s - receivers) / np.maximum(dist, 1e-12)[:, None]
        J = unit[a] - unit[b]
        res = val[a, b] - pred[a, b]
        step = np.linalg.lstsq(J, res, rcond=None)[0]
        s = s + step
        if np.linalg.norm(step) < 1e-6:
            break
    dist = np.linalg.norm(s - receivers, axis=1)
    pred = dist[:, None] - dist[None, :]
    with np.errstate(invalid="ignore"):
        gap = np.abs(P - pred[..., None])
    best = np.where(np.isfinite(gap), gap, np.inf).min(axis=2)
    pairs = best <= tol
    np.fill_diagonal(pairs, False)
    return s, pairs, float(np.sqrt(np.mean(best[pairs] ** 2))) if pairs.any() else np.inf


def _source_std(receivers: np.ndarray, s: np.ndarray, pairs: np.ndarray, noise: float) -> float:
    """Position std (root of the trace of the covariance) of a located source: Gauss-Newton's
    noise^2 (J^T J)^-1 over its agreeing pairs (noise: of one measured difference)."""
    a, b = np.nonzero(np.triu(pairs, 1))
    unit = (s - receivers) / np.maximum(np.linalg.norm(s - receivers, axis=1), 1e-12)[:, None]
    J = unit[a] - unit[b]
    try:
        return float(noise * np.sqrt(np.trace(np.linalg.inv(J.T @ J))))
    except np.linalg.LinAlgError:
        return float("inf")


def _windows(receivers: np.ndarray, s: np.ndarray, receiver_std: np.ndarray, source_std: float, noise: float,
             options: TdoaOptions, guide: GuideOptions):
    """(predicted arrival distance of every channel (m,), half-width of every pair's window (m, m)), in samples."""
    dist = np.linalg.norm(s - receivers, axis=1)
    unit = (s - receivers) / np.maximum(dist, 1e-12)[:, None]
    lever = np.sum((unit[:, None, :] - unit[None, :, :]) ** 2, axis=2)  # |u_i - u_k|^2
    var = receiver_std[:, None] ** 2 + receiver_std[None, :] ** 2 + lever * source_std**2 + noise**2
    return dist, options.tolerance + guide.window_sigmas * np.sqrt(var)


def _guided_arrivals(seg: np.ndarray, max_lag: int, options: TdoaOptions, guide: GuideOptions, pred: np.ndarray,
                     half: np.ndarray, beta: float = 1.0, known=None):
    """(reference, times relative to it in samples, support) of one event's weighted segments: the first
    pass's consensus, started from the predicted arrivals, on the candidates within each pair's window.
    known : None, or the segments' candidates already computed (_pair_candidates(seg, max_lag, guide.peaks, beta))."""
    energy = np.sum(seg**2, axis=1)
    r = int(np.argmax(energy))
    m = seg.shape[0]
    i, k, lags, heights = _pair_candidates(seg, max_lag, guide.peaks, beta) if known is None else known
    inside = np.abs(lags - (pred[i] - pred[k])[:, None]) <= half[i, k][:, None]
    candidates = (i, k, np.where(inside, lags, np.nan), np.where(inside, heights, 0.0))
    t, support = _consensus(m, r, *candidates, options.tolerance, options.early, init=pred - pred[r])
    return r, t, support, agreeing_pairs(m, candidates, t, options.tolerance)


def guided_tdoa_matrix(recording: Recording, receivers, transmitters=None, options: TdoaOptions = TdoaOptions(), *,
                       receiver_std=None, transmitter_std=None, sigma: float = 0.0, guide: GuideOptions = GuideOptions(),
                       entries=None, known: dict | None = None, progress=None) -> TdoaMatrix:
    """The second pass: every channel's arrival per event, searched within a window around the arrival
    differences that known positions predict (module docstring).

    Parameters
    ----------
    recording : the recording of the first pass
    receivers : (channels, dim) positions in metres, any frame (a calibration's gauge)
    transmitters : None, or (events, dim) one source position per event the first pass detects with the
        same options (same frame), NaN rows for events without one; an event without a position is
        located from its pair candidates (locate_source), or left missing when no position has dim + 2
        channels and GuideOptions.locate_share of the pairs agreeing
    options : the first pass's options (events, lag range, tapers, consensus, min_support, min_agreement)
    receiver_std, transmitter_std : (channels,), (events,) position std in metres (None: 0)
    sigma : noise std of one entry in metres (the calibration's)
    guide : GuideOptions
    entries : None, or (channels, events) entries in metres of the first pass (same options, F; NaN columns for
        none): an event without a position is first located from its entries (locate_from_entries, checked on
        the candidates of options.taper), and only when they do not fit from its candidates (locate_source, those
        of every taper). tdoa_guided gives those of the events its
        calibration was not given (an event given and not placed has entries the calibration did not accept)
    known : None, or the first pass's candidates of its events' first analyses (tdoa_matrix's `keep`, same
        recording and options): used instead of computing them again
    progress : None, or a callable taking one line

    Returns a TdoaMatrix whose notes say what guided it. Raises ValueError for positions of the wrong
    shape, RecordingError (one line) for a recording without an event.
    """
    rate, speed = recording.rate, options.speed
    scale = rate / speed  # metres -> samples of sound travel
    R = np.asarray(receivers, dtype=float)
    m = len(recording.channels)
    if R.ndim != 2 or R.shape[0] != m or not np.all(np.isfinite(R)):
        raise ValueError(f"receivers must be ({m}, dim) finite positions, one per channel; got shape {R.shape}")
    dim = R.shape[1]
    R = R * scale
    rstd = np.zeros(m) if receiver_std is None else np.asarray(receiver_std, dtype=float) * scale
    noise = np.sqrt(2.0) * sigma * scale
    S = None if transmitters is None else np.asarray(transmitters, dtype=float)
    sstd = None if transmitter_std is None else np.asarray(transmitter_std, dtype=float)
    placed, located, missing, from_entries = [], [], [], []

    def arrivals(j, seg, after, max_lag, whole):
        taper_candidates = None if known is None else known.get(j)  # of options.taper with PHAT
        if S is not None and j >= len(S):
            raise ValueError(f"transmitters has {len(S)} rows, but the recording has more events")
        if S is not None and np.all(np.isfinite(S[j])):
            s = S[j] * scale
            s_std = 0.0 if sstd is None else float(sstd[j]) * scale
            placed.append(j)
        else:
            energy = np.sum(seg**2, axis=1)
            found = None
            if entries is not None and j < entries.shape[1] and np.sum(np.isfinite(entries[:, j])) >= dim + 2:
                if taper_candidates is None:
                    taper_candidates = _pair_candidates(seg * np.exp(-after / options.taper), max_lag, options.peaks)
                i, k, lags, heights = taper_candidates
                found = locate_from_entries(R, entries[:, j] * scale, i, k, lags, heights, tol=guide.locate_tolerance,
                                            min_support=options.min_support, min_share=guide.locate_share)
                if found is not None:
                    from_entries.append(j)
            if found is None:  # the candidates of every taper searched
                pooled = [taper_candidates if taper == options.taper and taper_candidates is not None
                          else _pair_candidates(seg * np.exp(-after / taper), max_lag, options.peaks)
                          for taper in (options.taper, *options.retry_tapers)]
                i, k = pooled[0][:2]
                lags, heights = np.hstack([p[2] for p in pooled]), np.hstack([p[3] for p in pooled])
                taper_candidates = pooled[0]
                found = locate_source(R, i, k, lags, heights, references=np.argsort(energy)[::-1][:3],
                                      tol=guide.locate_tolerance, samples=guide.locate_samples,
                                      min_support=options.min_support, min_share=guide.locate_share,
                                      seed=int(np.random.SeedSequence([guide.seed, j]).generate_state(1)[0]))
            if found is None:
                missing.append(j)
                return None
            s, pairs, rms = found
            s_std = _source_std(R, s, pairs, max(noise, rms))
            located.append(j)
        pred, half = _windows(R, s, rstd, s_std, noise, options, guide)
        # _over_tapers analyses options.taper with PHAT first: the candidates of the first pass or of the localisation
        memo = {"first": taper_candidates} if taper_candidates is not None and guide.peaks == options.peaks else {}

        def analyse(w, beta):
            known = memo.pop("first", None) if beta == 1.0 else None
            return _guided_arrivals(w, max_lag, options, guide, pred, half, beta, known)

        best = _over_tapers(seg, after, options, analyse)
        best = emphasised(seg, whole, rate, options, best,  # the onsets' direct sound, as the first pass
                          lambda z: _guided_arrivals(z, max_lag, options, guide, pred, half))
        return (*best, guide.min_agreement)

    tm = _measure(recording, options, arrivals, progress, label="tdoa (guided)")
    if S is not None and len(S) != len(tm.events):
        raise ValueError(f"transmitters has {len(S)} rows for the recording's {len(tm.events)} events")
    note = (f"guided pass ({dim}D positions): {len(placed)} event(s) at their given source, {len(located)} located "
            + (f"({len(from_entries)} from their first-pass entries, the others from their pair candidates)"
               if from_entries else "from their pair candidates"))
    if missing:
        note += (f", {len(missing)} left missing (no position with {dim + 2} channels and {100 * guide.locate_share:g} % "
                 f"of the pairs agreeing: {', '.join(tm.events[j] for j in missing)})")
    return replace(tm, notes=tm.notes + (note + "; each pair's peaks searched within a window around the predicted "
                                         "difference, the entries measured peaks",))


def reconcile(first: TdoaMatrix, guided: TdoaMatrix, inliers: np.ndarray, tolerance: float,
              max_contradicted: float = 0.2) -> TdoaMatrix:
    """The guided matrix, except that an event whose guided entries contradict more than `max_contradicted`
    of the first pass's entries that the first calibration accepted (inliers (channels, events)) keeps its
    first-pass column: its guide is not trusted (a note names it).

    An accepted entry is contradicted when the guided pass left it missing or measured it more than
    `tolerance` samples away (up to a constant per event: the passes may take different reference channels).
    On the simulated rooms (tables/audio3d) the guided pass contradicts none; a guide 30 cm off does (the
    right peaks outside its windows, a correlation's sidelobes inside: tests/test_audio_guided.py).
    """
    F, conf, ref = guided.F.copy(), guided.confidence.copy(), guided.reference.copy()
    tol = tolerance * guided.speed / guided.rate
    kept = []
    for j in range(F.shape[1]):
        accepted = np.asarray(inliers[:, j], bool) & np.isfinite(first.F[:, j])
        if not accepted.any():
            continue
        d = guided.F[accepted, j] - first.F[accepted, j]
        measured = np.isfinite(d)
        shift = np.median(d[measured]) if measured.any() else 0.0
        if np.sum(~measured | (np.abs(d - shift) > tol)) > max_contradicted * accepted.sum():
            F[:, j], conf[:, j], ref[j] = first.F[:, j], first.confidence[:, j], first.reference[j]
            kept.append(j)
    if not kept:
        return guided
    note = (f"{len(kept)} event(s) keep the first pass's entries, the guided pass contradicting more than "
            f"{100 * max_contradicted:g} % of those the calibration accepted: {', '.join(guided.events[j] for j in kept)}")
    return replace(guided, F=F, confidence=conf, reference=ref, notes=guided.notes + (note,))


def _keep_swept(first: TdoaMatrix, guided: TdoaMatrix) -> TdoaMatrix:
    """The guided matrix with the first pass's column of every event measured against its own estimated sweep
    (TdoaMatrix.swept) that has entries: each of its channels was measured against the sound, as with a given
    signal, which the pairs' windows would not improve (on the sweep rooms of tables/audio3d_kinds.md the guided
    pass moved two rooms from 100 and 98.9 % of their entries within 2 samples to 99.1 and 96.7 %)."""
    kept = [j for j in first.swept if np.isfinite(first.F[:, j]).any()]
    if not kept:
        return guided
    F, conf, ref = guided.F.copy(), guided.confidence.copy(), guided.reference.copy()
    F[:, kept], conf[:, kept], ref[kept] = first.F[:, kept], first.confidence[:, kept], first.reference[kept]
    note = (f"{len(kept)} event(s) keep the first pass's entries, measured against their own estimated sweep: "
            f"{', '.join(guided.events[j] for j in kept)}")
    return replace(guided, F=F, confidence=conf, reference=ref, swept=first.swept, notes=guided.notes + (note,))


def _trust(result, guide: GuideOptions) -> str:
    """Why a first calibration cannot guide ('' when it can)."""
    if result.status not in guide.trusted:
        return f"its status is {result.status!r} (a guide needs {' or '.join(map(repr, guide.trusted))})"
    unplaced = int(np.sum(~np.isfinite(result.receivers[:, 0])))
    if unplaced:
        return f"{unplaced} receiver(s) not placed"
    if not np.all(np.isfinite(result.receiver_std)):
        return "some receiver's position std is not finite"
    return ""


def guide_events(first: TdoaMatrix, limit: int) -> np.ndarray:
    """(events,) indices, in time order, of at most `limit` events of the first pass for the guiding calibration:
    those with the most entries, the earliest first on a tie (GuideOptions.calibrate_events)."""
    n = first.F.shape[1]
    if n <= limit:
        return np.arange(n)
    entries = np.isfinite(first.F).sum(axis=0)
    return np.sort(np.argsort(-entries, kind="stable")[:limit])


def tdoa_guided(recording: Recording, options: TdoaOptions = TdoaOptions(), *, dim: int = 3, seed: int | None = 0,
                guide: GuideOptions | None = GuideOptions(), progress=None) -> GuidedTdoa:
    """`tdoa` as the verb runs it: the first pass; with a guide, `calibrate(F, dim=dim, seed=seed)` of it
    (sigma estimated; when it cannot guide, once more without the least supported entries,
    GuideOptions.retry_least_supported) and, when that calibration is trusted (GuideOptions.trusted, every
    receiver placed), the guided pass at its positions, each event checked against the first pass's entries that calibration
    accepted (reconcile); notes say what was done. guide None, or the emitted signal given (options.signal:
    each channel's arrival its own pulse, no pair correlation to narrow): the first pass only."""
    from .calibration import calibrate

    known: dict = {}
    first = tdoa_matrix(recording, options, progress=progress, keep=None if guide is None else known)
    if guide is None:
        return GuidedTdoa(first, None, first, False)
    if options.signal is not None:  # every channel measured against the emitted signal: no pair to search again
        note = ("no guided pass: every channel's arrival measured against the emitted signal, its own direct pulse "
                "(the guide narrows pairs' correlations); the matrix is the first pass's")
        return GuidedTdoa(first, None, replace(first, notes=first.notes + (note,)), False)
    n = first.F.shape[1]
    chosen = guide_events(first, guide.calibrate_events)
    if progress is not None:
        progress(f"tdoa: calibrating the first pass ({dim}D, sigma estimated"
                 + (f", {len(chosen)} of its {n} events" if len(chosen) < n else "") + ") to guide a second pass")
    cal = calibrate(first.F[:, chosen], dim=dim, seed=seed)
    why = _trust(cal, guide)
    retried = ""
    if why and guide.retry_least_supported:
        # the entries only min_support channels agree with are the first pass's least sure: the guide is
        # calibrated once more without them (the final calibration is still of the whole guided matrix)
        sure = first.F[:, chosen].copy()
        weak = np.isfinite(sure) & (first.confidence[:, chosen] <= options.min_support)
        if weak.any():
            sure[weak] = np.nan
            again = calibrate(sure, dim=dim, seed=seed)
            without = f"without the {int(weak.sum())} entries only {options.min_support} other channels agree with"
            if not _trust(again, guide):
                retried = f"; {cal.status!r} with every entry, {again.status!r} {without}"
                cal, why = again, ""
            else:
                why += f"; {again.status!r} {without}"
    if why:
        note = f"no guided pass: the first pass's calibration cannot guide it, {why}; the matrix is the first pass's"
        return GuidedTdoa(first, cal, replace(first, notes=first.notes + (note,)), False)
    transmitters = np.full((n, cal.transmitters.shape[1]), np.nan)
    transmitter_std = np.full(n, np.nan)
    inliers = np.zeros(first.F.shape, bool)
    transmitters[chosen], transmitter_std[chosen] = cal.transmitters, cal.transmitter_std
    inliers[:, chosen] = cal.inliers
    untested = first.F.copy()
    untested[:, chosen] = np.nan  # the events the calibration was given: placed, or their entries not accepted
    matrix = guided_tdoa_matrix(recording, cal.receivers, transmitters, options, receiver_std=cal.receiver_std,
                                transmitter_std=transmitter_std, sigma=float(cal.sigma), guide=guide,
                                entries=untested, known=known, progress=progress)
    matrix = reconcile(first, matrix, inliers, options.tolerance)
    matrix = _keep_swept(first, matrix)
    before, after = int(np.isfinite(first.F).sum()), int(np.isfinite(matrix.F).sum())
    own = tuple(f"first pass: {n}" for n in first.notes[len(recording.notes):])  # the recording's notes are in both
    note = (f"first pass: {before}/{first.F.size} entries, calibrated {cal.status!r} (sigma {cal.sigma:.3g} m"
            + (f", {len(chosen)} of its {n} events, those with the most entries" if len(chosen) < n else "")
            + f"{retried}); guided pass: {after}/{matrix.F.size}")
    return GuidedTdoa(first, cal, replace(matrix, notes=matrix.notes + own + (note,)), True)


def tdoa_and_calibrate(recording: Recording, options: TdoaOptions = TdoaOptions(), *, dim: int = 3,
                       sigma: float | None = None, seed: int | None = 0, guide: GuideOptions | None = GuideOptions(),
                       calibration_options=None, progress=None) -> GuidedTdoa:
    """From a recording to a calibration in one call: tdoa_guided, then `calibrate` of its matrix (sigma,
    seed and calibration_options as calibrate takes them): the result a user of `calibrate RECORDING` gets."""
    from .calibration import calibrate

    run = tdoa_guided(recording, options, dim=dim, seed=seed, guide=guide, progress=progress)
    return replace(run, calibration=calibrate(run.matrix.F, sigma, dim=dim, seed=seed, options=calibration_options))
