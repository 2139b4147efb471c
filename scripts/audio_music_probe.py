"""Why three-note phrases fail: other ways to their time differences, measured on the six music rooms of audio_kinds.py.

Issue 53 asks >= 90 % of the true events' entries within 2 samples (strict: a missed event counts 0) for every kind
of sound; the phrases (scripts/audio_kinds.py `music`, harmonic tones with a 10 ms attack) reach 42.6 %. This
script measures approaches other than each pair's highest peaks on the same six rooms (the table's seeds), each
printed as the strict share per room and pooled (docs/audio.md, "Why the phrases fail", quotes them):

  first      the first pass (solvers.audio.tdoa_matrix), scored as the table scores it
  consensus  per event analysed whole (the ambiguity switch's segment): the pairs' GCC-PHAT candidates and their
             consensus with every entry kept (no support, agreement or subset rule): what the rules start from
  srp        (A) steered response in delay space: coordinate ascent of sum_{i<k} GCC_ik(t_i - t_k) over integer
             lags, every pair's whole correlation (not its 8 peaks), started from the consensus; and started from
             the truth (whether the truth is a local maximum of that sum)
  mccc       (A) the multichannel cross-correlation coefficient (Chen, Benesty & Huang 2003): the determinant of the
             normalised spatial correlation matrix of the channels (each spectrum prewhitened) minimised by the same
             coordinate ascent, from the consensus and from the truth
  guide      (B) the guided pass (solvers.audio_guided.guided_tdoa_matrix) at the TRUE positions with a position
             std of 1 cm and 5 cm: the ceiling of any first calibration, however found
  onsets     each channel's first-note onset by a hinge fit (noise, then a line) to its band-passed envelope: the
             share within 0.5 and 1 ms of its true arrival (the common offset removed)
  early      (C) the direct sound only: each channel's windows start at its own onset (the hinge), one per note (the
             reference's note onsets), 10 ms after a 1 ms rise, band-passed 150-7000 Hz, the pairs' cross-spectra
             summed with PHAT-beta 0.5, lags searched within 3 ms of the onsets' differences, their consensus, the
             windows moved to the consensus's times 3 times; `early-oracle`: one pass with the windows at the true
             arrivals jittered by up to 0.25, 0.5, 1 ms, each channel against the reference only
  hybrid     each pair's whole-phrase candidates plus its 2 highest peaks within 1 ms of the onsets' difference
  wpe        (C) weighted prediction error dereverberation (nara-wpe, 10 taps, delay 3, 3 iterations) before the
             consensus (skipped when nara_wpe is not installed; not a dependency of the project)
  ranks      why: the share of the pairs whose true lag is the highest / among the 8 highest local maxima of the whole
             phrase's GCC-PHAT, of one note's and of the notes' product, in the room and in the same room rendered
             with the direct sound only (image order 0): 34.0 / 57.1 % reverberant, 97.3 / 99.4 % direct only (the
             whole phrase): the reverberant steady state, not the notes' periodicity, outranks the true lag
  notes      (a) per-note consensus: each note's GCC-PHAT (the event cut at its onsets, solvers.audio.onset_windows'),
             normalised, combined by their product (geometric mean) or minimum, the 8 highest peaks, the consensus
  bound      (c) each pair's lags bounded by its TRUE microphone distance / c + 2 samples (the ceiling of a bound from
             an earlier pass), the 8 highest peaks there, the consensus
  emphasis   (b) the onsets' direct sound (solvers.audio.onset_emphasis, which the front end now runs), the consensus;
             and that or the whole phrase by the pairs agreeing (as the first pass chooses)

`--order 0` renders the rooms with the direct sound only (every approach but `ranks`, which renders both).
Measured (pooled strict, docs/audio.md quotes each room): notes 9.8 % (product) / 9.1 % (minimum), bound 58.7 %,
emphasis 82.6 % (either line), against the consensus's 58.1 %; consensus at order 0: 89.1 %.

Per-event approaches are scored as the table's `strict` with every entry of the event kept (they have no rule that
leaves entries missing); `first` and `guide` as the table (their matrices' rules apply).

Usage: OPENBLAS_NUM_THREADS=1 python scripts/audio_music_probe.py [--approaches first,consensus,...] [--rooms 0:6]
       [--order 20]
Needs the optional extra: pip install -e ".[audio]" (pyroomacoustics). Deterministic (seeded); every approach but
wpe took about 20 minutes in two processes on the shared 2-core machine at load average 10-13 (wpe on the three
16 kHz rooms about 8 minutes, the 48 kHz rooms not finished; ranks, notes + bound, emphasis 2 minutes each, 15-45 s
of CPU, at load 5-9).
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import functools  # noqa: E402
import sys  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "scripts"))

import numpy as np  # noqa: E402

from solvers.audio import (TdoaOptions, _consensus, _event_arrivals, _fast_length, _pair_candidates,  # noqa: E402
                           _parabola, _phat, onset_emphasis, onset_windows, recording_events,
                           tdoa_matrix)
from solvers.audio_guided import guided_tdoa_matrix  # noqa: E402
from audio_kinds import CONDITIONS, index_range, listed, room, scores  # noqa: E402

APPROACHES = ("first", "consensus", "srp", "mccc", "guide", "onsets", "early", "early-oracle", "hybrid", "wpe", "ranks",
              "notes", "bound", "emphasis")
BAND = (150.0, 7000.0)


def events_of(recording, net, c):
    """The detected events matched to true ones (as the table matches): dicts of the segment analysed whole
    (the lag range either side), each channel's true arrival in it (samples) and the reference (loudest)."""
    options = TdoaOptions(speed=c)
    rate = recording.rate
    max_lag = int(np.ceil(options.max_distance / c * rate))
    found = recording_events(recording, options)
    lead = found[:, 0][:, None] / rate - net.offsets[None, :] / c
    near = (lead > -0.02) & (lead < 0.06)
    out, used = [], set()
    for d, (start, end) in enumerate(found):
        if not near[d].any() or int(np.argmax(near[d])) in used:
            continue
        t = int(np.argmax(near[d]))
        used.add(t)
        a = max(0, start - max_lag)
        b = min(recording.frames, start + max(int(options.window * rate), min(end - start, int(options.max_window * rate)))
                + max_lag)
        seg = recording.read(a, b)
        seg = seg - seg.mean(axis=1, keepdims=True)
        arrival = (net.offsets[t] + np.linalg.norm(net.receivers - net.transmitters[t], axis=1)) / c * rate - a
        out.append({"seg": seg, "arrival": arrival, "ref": int(np.argmax(np.sum(seg**2, axis=1)))})
    return out, max_lag, options


def right(ev, t, r) -> int:
    """Entries other than the reference r within 2 samples of the truth (t relative times, every entry kept)."""
    err = (t - t[r]) - (ev["arrival"] - ev["arrival"][r])
    return int(np.sum((np.arange(len(t)) != r) & (np.abs(err) <= 2)))


def correlations(seg, max_lag, beta=1.0):
    """(m, m, 2 max_lag + 1) GCC-PHAT of every ordered pair: [a, b, max_lag + x] at a's lag x behind b."""
    m, length = seg.shape
    n = _fast_length(2 * length)
    i, k = np.triu_indices(m, 1)
    X = np.fft.rfft(seg, n, axis=1)
    G = _phat(X[i] * np.conj(X[k]), n, -max_lag, max_lag, beta)
    M = np.zeros((m, m, G.shape[1]))
    M[i, k], M[k, i] = G, G[:, ::-1]
    return M


def coefficients(seg, max_lag):
    """(m, m, 2 max_lag + 1) correlation coefficients of every ordered pair of the channels, each spectrum
    prewhitened (divided by its magnitude): [a, b, max_lag + x] at a's lag x behind b."""
    m, length = seg.shape
    n = _fast_length(2 * length)
    i, k = np.triu_indices(m, 1)
    X = np.fft.rfft(seg, n, axis=1)
    X = X / np.maximum(np.abs(X), 1e-12)
    cc = np.fft.irfft(X[i] * np.conj(X[k]), n, axis=1)[:, np.arange(-max_lag, max_lag + 1) % n]
    energy = np.sqrt(np.sum(np.abs(X) ** 2, axis=1) / n * 2)
    M = np.zeros((m, m, 2 * max_lag + 1))
    M[i, k] = cc / (energy[i] * energy[k])[:, None]
    M[k, i] = M[i, k][:, ::-1]
    return M


def coordinate_search(M, t, r, objective, sweeps):
    """Integer times t (t_r fixed) improved channel by channel: each moved to the lag x maximising
    objective(t, a, row), row (lags, m) = M[a, b, x - t_b] for every x (0 beyond the lag range, and for b = a)."""
    m, lags = M.shape[0], M.shape[2]
    max_lag = lags // 2
    xs = np.arange(-max_lag, max_lag + 1)
    t = np.round(t).astype(int)
    for _ in range(sweeps):
        before = t.copy()
        for a in (a for a in range(m) if a != r):
            e = xs[:, None] - t[None, :] + max_lag
            row = np.where((e >= 0) & (e < lags), M[a, np.arange(m)[None, :], np.clip(e, 0, lags - 1)], 0.0)
            row[:, a] = 0.0
            t[a] = xs[int(np.argmax(objective(t, a, row)))]
        if np.array_equal(t, before):
            break
    return t


def ascend(M, t, r, sweeps=10):
    """Coordinate ascent of sum_{a<b} M[a, b, t_a - t_b] (the steered response in delay space)."""
    return coordinate_search(M, t, r, lambda t, a, row: row.sum(axis=1), sweeps)


def ascend_mccc(M, t, r, sweeps=6):
    """Coordinate descent of log det R(t), R[a, b] = M[a, b, t_a - t_b] (1 on the diagonal; MCCC)."""
    m, lags = M.shape[0], M.shape[2]
    max_lag = lags // 2

    def objective(t, a, row):
        inside = np.abs(t[:, None] - t[None, :]) <= max_lag
        d = np.clip(t[:, None] - t[None, :] + max_lag, 0, lags - 1)
        R = np.where(inside, M[np.arange(m)[:, None], np.arange(m)[None, :], d], 0.0)
        np.fill_diagonal(R, 1.0)
        Rs = np.repeat(R[None], len(row), axis=0)
        others = np.arange(m) != a
        Rs[:, a, others] = Rs[:, others, a] = row[:, others]
        sign, logdet = np.linalg.slogdet(Rs)
        return -np.where(sign > 0, logdet, np.inf)

    return coordinate_search(M, t, r, objective, sweeps)


def band(seg, rate):
    from scipy.signal import butter, sosfiltfilt

    return sosfiltfilt(butter(4, [BAND[0], min(BAND[1], 0.45 * rate)], btype="band", fs=rate, output="sos"), seg, axis=1)


def hinge_onsets(seg, rate, max_lag, k=5.0, before=0.008, after=0.006):
    """Each channel's onset (samples): its band-passed envelope (1 ms rms) first crosses the noise's median + k std
    (noise: the segment before the event), and the hinge y = a + b max(0, t - t0) fitted by least squares over
    [crossing - before, crossing + after] with t0 <= the crossing gives t0 (NaN: no crossing)."""
    x = band(seg, rate)
    n = max(1, int(0.001 * rate))
    env = np.sqrt(np.array([np.convolve(e, np.ones(n) / n, mode="same") for e in x**2]))
    pre = env[:, : max(10, max_lag - int(0.01 * rate))]
    floor = np.median(pre, axis=1) + k * pre.std(axis=1)
    out = np.full(seg.shape[0], np.nan)
    for ch in range(seg.shape[0]):
        above = np.flatnonzero(env[ch, max_lag // 2:] > floor[ch])
        if not len(above):
            continue
        c0 = max_lag // 2 + int(above[0])
        lo, hi = max(0, c0 - int(before * rate)), min(env.shape[1], c0 + int(after * rate))
        y, t = env[ch, lo:hi], np.arange(lo, hi)
        grid = np.arange(lo, c0 + 1)
        H = np.maximum(t[None, :] - grid[:, None], 0).astype(float)
        sh, shh, sy, shy = H.sum(1), (H**2).sum(1), y.sum(), H @ y
        det = len(t) * shh - sh**2
        slope = (len(t) * shy - sh * sy) / np.where(det > 0, det, 1.0)
        level = (sy - slope * sh) / len(t)
        res = ((y[None, :] - level[:, None] - slope[:, None] * H) ** 2).sum(1)
        res[(det <= 0) | (slope <= 0)] = np.inf
        out[ch] = grid[int(np.argmin(res))]
    return out


def note_onsets(x, rate, first, rise=6.0):
    """The first onset and every later 5 ms frame of channel x whose power rises `rise` dB over the lowest of the
    50 ms before (80 ms apart, at most 8; as solvers.audio.onset_windows), a frame early."""
    hop = int(0.005 * rate)
    body = x[int(first):]
    frames = len(body) // hop
    level = 10 * np.log10(np.maximum(np.mean(body[: frames * hop].reshape(frames, hop) ** 2, axis=1), 1e-300))
    starts = [0]
    for f in range(2, frames):
        if len(starts) == 8:
            break
        if (level[f] - level[max(0, f - 10):f].min() >= rise and level[f] >= level[f - 1]
                and (f + 1 == frames or level[f] >= level[f + 1]) and f - starts[-1] >= 16):
            starts.append(f)
    return [float(first)] + [float(first) + hop * (s - 1) for s in starts[1:]]


def early_correlations(x, d, notes, rate, search, beta=0.5, window=0.010, rise=0.001):
    """(i, k, G (pairs, 2 search + 1)): per pair the PHAT-beta correlation of windows starting at each channel's
    time d (+ each note's start relative to the reference's, `notes`), a raised-cosine rise then `window` s flat,
    the notes' cross-spectra summed; lag x of G: i's residual lag behind k (the total lag d_i - d_k + x)."""
    m = x.shape[0]
    pre, W = int(rise * rate), int(window * rate)
    u = np.arange(-pre, W)
    w = np.where(u < 0, 0.5 - 0.5 * np.cos(np.pi * (u + pre) / max(pre, 1)), 1.0)
    n = _fast_length(2 * len(u))
    i, k = np.triu_indices(m, 1)
    cross = 0.0
    for N in notes:
        idx = np.clip(np.round(N + d[:, None] + u[None, :]).astype(int), 0, x.shape[1] - 1)
        X = np.fft.rfft(x[np.arange(m)[:, None], idx] * w, n, axis=1)
        cross = cross + X[i] * np.conj(X[k])
    return i, k, _phat(cross, n, -search, search, beta)


def peaks_of(G, offset, count):
    """(lags (pairs, count), heights): the `count` highest local maxima of each row of G, parabolically refined,
    as lags offset[pair] + index - (G.shape[1] // 2)."""
    inner = np.zeros_like(G, bool)
    inner[:, 1:-1] = (G[:, 1:-1] >= G[:, :-2]) & (G[:, 1:-1] > G[:, 2:])
    ranked = np.argsort(-np.where(inner, G, -np.inf), axis=1)[:, :count]
    rows = np.arange(len(G))[:, None]
    b, last = G[rows, ranked], G.shape[1] - 1
    shift = np.where(inner[rows, ranked], _parabola(G[rows, np.maximum(ranked - 1, 0)], b,
                                                    G[rows, np.minimum(ranked + 1, last)]), 0.0)
    return offset[:, None] + ranked - G.shape[1] // 2 + shift, np.where(inner[rows, ranked], b, 0.0)


def early(ev, rate, max_lag, options, iterations=3, search=0.003):
    """Approach `early` of the module docstring: times relative to the reference (samples)."""
    seg, r = ev["seg"], ev["ref"]
    m = seg.shape[0]
    d = hinge_onsets(seg, rate, max_lag)
    d = np.where(np.isfinite(d), d, np.nanmedian(d))
    x = band(seg, rate)
    s = int(search * rate)
    for _ in range(iterations):
        notes = [N - d[r] for N in note_onsets(x[r], rate, d[r])[:3]]
        i, k, G = early_correlations(x, d, notes, rate, s)
        lags, heights = peaks_of(G, d[i] - d[k], 4)
        t = _consensus(m, r, i, k, lags, heights, options.tolerance, options.early)[0]
        d = t + d[r]
    return t


def early_oracle(ev, rate, jitter, seed=0):
    """Each channel against the reference, one pass of early_correlations with windows at the true arrivals
    jittered uniformly by up to `jitter` s."""
    seg, r = ev["seg"], ev["ref"]
    d = ev["arrival"] + np.random.default_rng(seed).uniform(-1, 1, seg.shape[0]) * jitter * rate
    x = band(seg, rate)
    s = int(0.003 * rate)
    notes = [N - d[r] for N in note_onsets(x[r], rate, d[r])[:3]]
    i, k, G = early_correlations(x, d, notes, rate, s)
    best = G.argmax(axis=1) - s
    t = np.zeros(seg.shape[0])
    for p in range(len(i)):
        if k[p] == r:
            t[i[p]] = d[i[p]] - d[r] + best[p]
        elif i[p] == r:
            t[k[p]] = d[k[p]] - d[r] - best[p]
    return t


def hybrid(ev, rate, max_lag, options, within=0.001, count=2):
    """Approach `hybrid`: each pair's 8 whole-phrase candidates plus its `count` highest GCC-PHAT local maxima
    within `within` s of the hinge onsets' difference; their consensus."""
    seg, r = ev["seg"], ev["ref"]
    m = seg.shape[0]
    d = hinge_onsets(seg, rate, max_lag)
    d = np.where(np.isfinite(d), d, np.nanmedian(d))
    i, k, lags, heights = _pair_candidates(seg, max_lag, options.peaks)
    M = correlations(seg, max_lag)
    w = int(within * rate)
    near = np.full((len(i), count), np.nan)
    near_h = np.zeros((len(i), count))
    for p in range(len(i)):
        c = int(round(d[i[p]] - d[k[p]])) + max_lag
        G = M[i[p], k[p]]
        idx = np.arange(max(1, c - w), min(len(G) - 1, c + w + 1))
        idx = idx[(G[idx] >= G[idx - 1]) & (G[idx] > G[idx + 1])]
        idx = idx[np.argsort(-G[idx])][:count]
        near[p, :len(idx)] = idx - max_lag + _parabola(G[idx - 1], G[idx], G[idx + 1])
        near_h[p, :len(idx)] = G[idx]
    return _consensus(m, r, i, k, np.concatenate([lags, near], axis=1), np.concatenate([heights, near_h], axis=1),
                      options.tolerance, options.early)[0]


def truth_ranks(G, lags, max_lag):
    """(pairs,) the rank (0: the highest) of the true lag among each correlation's local maxima (rows of G over
    -max_lag..max_lag; the highest local maximum within 1.5 samples of the true lag `lags` stands for it), -1 when
    no local maximum lies that near."""
    inner = np.zeros_like(G, bool)
    inner[:, 1:-1] = (G[:, 1:-1] >= G[:, :-2]) & (G[:, 1:-1] > G[:, 2:])
    out = np.full(len(G), -1)
    for p in range(len(G)):
        idx = np.flatnonzero(inner[p])
        near = idx[np.abs(idx - max_lag - lags[p]) <= 1.5]
        if len(near):
            out[p] = int(np.sum(G[p, idx] > G[p, near].max()))
    return out


def note_correlations(seg, rate, max_lag, options):
    """(i, k, (notes, pairs, 2 max_lag + 1)): each note's GCC-PHAT of every pair, normalised to its highest
    value: the notes are the stretches between the event's onsets (solvers.audio.onset_windows: the channels'
    mean power rising onset_rise dB), the first from the segment's start, the last to its end, every channel cut
    at the same times."""
    w = onset_windows(seg, rate, max_lag, options)
    onsets = [int(np.argmax(row > 0)) + max_lag for row in w]
    bounds = [0] + onsets[1:] + [seg.shape[1]]
    m, length = seg.shape
    n = _fast_length(2 * length)
    i, k = np.triu_indices(m, 1)
    out = []
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        X = np.fft.rfft(np.where((np.arange(length) >= lo) & (np.arange(length) < hi), seg, 0.0), n, axis=1)
        G = _phat(X[i] * np.conj(X[k]), n, -max_lag, max_lag)
        out.append(G / np.maximum(G.max(axis=1, keepdims=True), 1e-12))
    return i, k, np.array(out)


def per_note(ev, rate, max_lag, options, how):
    """Approach `notes`: the notes' normalised correlations combined (`how`: "product" of each clipped at 1e-3,
    its geometric mean as the height; "min"), the 8 highest local maxima of the combination per pair, their
    consensus (every entry kept). Each note's comb of periodic peaks has its own period; only lags common to every
    note survive the product or the minimum."""
    i, k, Gs = note_correlations(ev["seg"], rate, max_lag, options)
    C = (np.exp(np.mean(np.log(np.maximum(Gs, 1e-3)), axis=0)) if how == "product" else Gs.min(axis=0))
    lags, heights = peaks_of(C, np.zeros(len(i)), options.peaks)
    return _consensus(ev["seg"].shape[0], ev["ref"], i, k, lags, heights, options.tolerance, options.early)[0]


def bounded(ev, receivers, rate, max_lag, options, c):
    """Approach `bound`: each pair's whole-phrase GCC-PHAT searched only within +-(its TRUE microphone distance / c
    + 2 samples) (the ceiling of a bound on |lag| from an earlier pass's microphone spread), its 8 highest local
    maxima there, their consensus (every entry kept)."""
    i, k = np.triu_indices(ev["seg"].shape[0], 1)
    G = correlations(ev["seg"], max_lag)[i, k]
    bound = np.linalg.norm(receivers[i] - receivers[k], axis=1) / c * rate + 2
    G = np.where(np.abs(np.arange(-max_lag, max_lag + 1))[None, :] <= bound[:, None], G, G.min() - 1.0)
    lags, heights = peaks_of(G, np.zeros(len(i)), options.peaks)
    return _consensus(ev["seg"].shape[0], ev["ref"], i, k, lags, heights, options.tolerance, options.early)[0]


def dereverberated(seg, rate):
    from nara_wpe.utils import istft, stft
    from nara_wpe.wpe import wpe

    size = 512 if rate <= 16_000 else 1536
    Y = stft(seg, size=size, shift=size // 4).transpose(2, 0, 1)
    z = istft(wpe(Y, taps=10, delay=3, iterations=3).transpose(1, 2, 0), size=size, shift=size // 4)[:, : seg.shape[1]]
    return np.pad(z, ((0, 0), (0, seg.shape[1] - z.shape[1])))


@functools.lru_cache(maxsize=None)
def music_room(condition: int, order: int = 20):
    """audio_kinds.room of the music room of that condition (simulated once per run); order 0: the same room, sounds,
    noise and SNR with the direct sound only (no reflection)."""
    return room("music", condition, 10, order)


def measure(approach: str, condition: int, order: int = 20) -> dict:
    """{label: (entries right, entries of the true events)} of one approach in one room (rendered to that image
    order; `ranks`: {label: (pairs, pairs of the true events)} at orders 20 and 0 both)."""
    if approach == "ranks":
        return ranks(condition)
    recording, net, c, _ = music_room(condition, order)
    rate = recording.rate
    m, n = net.receivers.shape[0], net.transmitters.shape[0]
    total = n * (m - 1)
    if approach == "first":
        return {"first pass": (round(scores(tdoa_matrix(recording, TdoaOptions(speed=c)), net, c, rate)["strict"] * total),
                               total)}
    if approach == "guide":
        options = TdoaOptions(speed=c)
        found = recording_events(recording, options)
        lead = found[:, 0][:, None] / rate - net.offsets[None, :] / c
        near = (lead > -0.02) & (lead < 0.06)
        S = np.array([net.transmitters[int(np.argmax(row))] if row.any() else np.full(3, np.nan) for row in near])
        out = {}
        for std in (0.01, 0.05):
            tm = guided_tdoa_matrix(recording, net.receivers, S, options, receiver_std=np.full(m, std),
                                    transmitter_std=np.full(len(S), std), sigma=0.002)
            out[f"true positions, std {100 * std:g} cm"] = (round(scores(tm, net, c, rate)["strict"] * total), total)
        return out
    events, max_lag, options = events_of(recording, net, c)
    got: dict[str, int] = {}

    def add(label, value):
        got[label] = got.get(label, 0) + value

    for ev in events:
        r = ev["ref"]
        if approach in ("consensus", "srp"):
            t = _event_arrivals(ev["seg"], max_lag, options)[1]
            add("consensus, every entry kept", right(ev, t, r))
            if approach == "srp":
                M = correlations(ev["seg"], max_lag)
                add("ascent from the consensus", right(ev, ascend(M, t, r), r))
                add("ascent from the truth", right(ev, ascend(M, ev["arrival"] - ev["arrival"][r], r), r))
        elif approach == "mccc":
            t = _event_arrivals(ev["seg"], max_lag, options)[1]
            M = coefficients(ev["seg"], max_lag)
            add("descent from the consensus", right(ev, ascend_mccc(M, t, r), r))
            add("descent from the truth", right(ev, ascend_mccc(M, ev["arrival"] - ev["arrival"][r], r), r))
        elif approach == "onsets":
            e = hinge_onsets(ev["seg"], rate, max_lag) - ev["arrival"]
            e = np.abs(e - np.nanmedian(e)) / rate
            add("onsets within 0.5 ms", int(np.sum(e <= 0.0005)))
            add("onsets within 1 ms", int(np.sum(e <= 0.001)))
        elif approach == "early":
            add("early windows at the onsets", right(ev, early(ev, rate, max_lag, options), r))
        elif approach == "early-oracle":
            for jitter in (0.0, 0.00025, 0.0005, 0.001):
                add(f"windows at the truth +- {1000 * jitter:g} ms", right(ev, early_oracle(ev, rate, jitter), r))
        elif approach == "hybrid":
            add("whole-phrase and near-onset candidates", right(ev, hybrid(ev, rate, max_lag, options), r))
        elif approach == "notes":
            for how in ("product", "min"):
                add(f"per-note consensus, the {how}", right(ev, per_note(ev, rate, max_lag, options, how), r))
        elif approach == "emphasis":
            whole = _event_arrivals(ev["seg"], max_lag, options)
            new = _event_arrivals(onset_emphasis(ev["seg"], rate, options), max_lag, options)
            add("the onsets' direct sound (onset_emphasis), then the consensus", right(ev, new[1], r))
            add("that or the whole phrase, whichever agrees on more pairs", right(ev, (new if new[2].sum() > whole[2].sum()
                                                                                       else whole)[1], r))
        elif approach == "bound":
            add("whole phrase within the true microphone distances", right(ev, bounded(ev, net.receivers, rate, max_lag,
                                                                                       options, c), r))
        elif approach == "wpe":
            z = dereverberated(ev["seg"], rate)
            add("WPE, then the consensus", right(ev, _event_arrivals(z, max_lag, options)[1], r))
    denominator = n * m if approach == "onsets" else total
    return {label: (value, denominator) for label, value in got.items()}


def ranks(condition: int) -> dict:
    """Approach `ranks`: {label: (pairs, pairs of the true events)} whose true lag is the highest / among the 8
    highest local maxima (truth_ranks) of the whole phrase's GCC-PHAT, of each note's and of the notes' product
    (note_correlations), in the room (image order 20) and in the same room with the direct sound only (order 0)."""
    out = {}
    for order, room_name in ((20, "reverberant"), (0, "direct sound only")):
        recording, net, c, _ = music_room(condition, order)
        events, max_lag, options = events_of(recording, net, c)
        got: dict[str, list] = {}
        for ev in events:
            i, k = np.triu_indices(ev["seg"].shape[0], 1)
            true = ev["arrival"][i] - ev["arrival"][k]
            _, _, Gs = note_correlations(ev["seg"], recording.rate, max_lag, options)
            product = np.exp(np.mean(np.log(np.maximum(Gs, 1e-3)), axis=0))
            for label, G in (("whole phrase", correlations(ev["seg"], max_lag)[i, k]), ("the notes' product", product),
                             *(("one note", g) for g in Gs)):
                got.setdefault(label, []).append(truth_ranks(G, true, max_lag))
        for label, rk in got.items():
            rk = np.concatenate(rk)
            out[f"{room_name}, {label}: the truth highest"] = (int(np.sum(rk == 0)), len(rk))
            out[f"{room_name}, {label}: among the 8 highest"] = (int(np.sum((rk >= 0) & (rk < 8))), len(rk))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--approaches", default=",".join(a for a in APPROACHES if a not in ("wpe", "ranks", "notes", "bound")),
                    help=f"comma-separated, of {', '.join(APPROACHES)}")
    ap.add_argument("--rooms", default="0:6", help="LOW:HIGH indices into audio_kinds.CONDITIONS (default 0:6)")
    ap.add_argument("--order", type=int, default=20, help="image-source order of the rooms (default 20, the table's; 0: "
                    "the direct sound only)")
    args = ap.parse_args(argv)
    approaches = listed(ap, args.approaches, APPROACHES, "--approaches")
    rooms = index_range(args.rooms)
    names = [f"{CONDITIONS[r][0] // 1000} kHz {CONDITIONS[r][1]} s {CONDITIONS[r][2]:g} dB" for r in rooms]
    print("| approach | " + " | ".join(names) + " | pooled |")
    print("|---|" + "---|" * (len(names) + 1))
    for approach in approaches:
        rows: dict[str, list] = {}
        for r in rooms:
            for label, value in measure(approach, r, args.order).items():
                rows.setdefault(label, []).append(value)
        for label, values in rows.items():
            pooled = sum(v[0] for v in values) / sum(v[1] for v in values)
            print(f"| {approach}: {label} | " + " | ".join(f"{100 * a / b:.1f}" for a, b in values)
                  + f" | {100 * pooled:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
