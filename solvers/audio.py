"""From recordings to a measurement matrix: audio files -> sound events -> GCC-PHAT delays -> F.

Owns the way in from audio (issue 45) after the reader (:mod:`solvers.recording`): the
detection of sound events by their energy onsets (:func:`detect_events`), generalized cross-correlation
with the phase transform (:func:`gcc_phat`, sub-sample by parabolic interpolation) and the matrix that
`calibrate` reads (:func:`tdoa_matrix`): one row per microphone (channel), one column per event,

    f_ij = c * (onset_j + tau_ij),

c the speed of sound, onset_j the start of event j's analysis window and tau_ij the delay of channel
i's sound behind the event's reference channel (the loudest), estimated without knowing the emitted
signal. The reference's own entry is its onset (tau = 0). Whatever the true emission time is, it is
a per-event constant and goes into the event's offset o_j (docs/calibrate.md, what F is).

The arrivals come from every pair of channels, not from one reference: between two microphones'
recordings the correlation also peaks where one channel's reflection meets the other's direct sound,
so each channel's arrival is the time most other channels agree with (:func:`tdoa_matrix` says how).
Each entry carries a confidence, its support: the number of other channels whose pair correlation has
a peak at the difference of the two arrivals; an entry with less than `min_support` is left missing
(NaN) rather than guessed.

GCC-PHAT: the cross-spectrum normalised to unit magnitude, so that every frequency votes equally for
the delay (robust to the colouring of reverberation; Knapp & Carter 1976). scipy.signal has no PHAT
weighting; pyroomacoustics' version returns only the lag (no peak strength) and refines by FFT
upsampling, so it is written here (scripts/room_simulation.py uses it against the emitted waveform).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .recording import BLOCK_FRAMES, Recording, RecordingError

__all__ = ["GccPeak", "TdoaMatrix", "TdoaOptions", "agreeing_pairs", "ambiguity", "consistent_subset", "detect_events", "estimate_sweep",
           "onset_emphasis", "onset_windows",
           "frame_power", "gcc_phat", "matched_filter", "recording_events", "tdoa_matrix"]

def _fast_length(n: int) -> int:
    """The smallest 11-smooth number >= n (prime factors 2, 3, 5, 7, 11: FFT lengths pocketfft transforms fast; a
    prime length is several times slower). The value of scipy.fft.next_fast_len(n), without importing scipy at
    start-up (the CLI builds its parser from this module's options)."""
    if n <= 1:
        return 1
    best = 1 << (n - 1).bit_length()  # a power of two >= n
    p11 = 1
    while p11 < best:
        p7 = p11
        while p7 < best:
            p5 = p7
            while p5 < best:
                p3 = p5
                while p3 < best:
                    p2 = p3 << max(0, (-(-n // p3) - 1).bit_length())  # p3 times the power of two reaching n
                    best = min(best, p2)
                    p3 *= 3
                p5 *= 5
            p7 *= 7
        p11 *= 11
    return best


# --------------------------------------------------------------------------------------------------
# GCC-PHAT
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class GccPeak:
    """The peak of a GCC-PHAT correlation.

    lag : delay of y within x in samples, sub-sample (x[t] ~ y[t - lag])
    height : the correlation at the integer peak taken
    top : the highest correlation in the lag range (= height unless search_back took an earlier peak)
    rms : root mean square of the correlation over the lag range
    sidelobe : the highest correlation outside +-guard samples of the peak taken (0 if none)
    edge : the peak taken lies on the first or last lag searched (its true position may lie beyond)
    """

    lag: float
    height: float
    top: float
    rms: float
    sidelobe: float
    edge: bool

    @property
    def psr(self) -> float:
        """Peak-to-sidelobe ratio (inf when nothing lies outside the guard)."""
        return self.height / self.sidelobe if self.sidelobe > 0 else float("inf")


def _phat(cross: np.ndarray, n: int, lo: int, hi: int, beta: float = 1.0) -> np.ndarray:
    """The GCC-PHAT correlation at lags lo..hi (last axis) of cross-spectra of FFT length n: each
    frequency's cross-spectrum divided by its magnitude to the power beta (1: unit magnitude, PHAT; below
    1 the loud frequencies keep some of their weight: PHAT-beta)."""
    cc = np.fft.irfft(cross / np.maximum(np.abs(cross), 1e-12) ** beta, n, axis=-1)
    return cc[..., np.arange(lo, hi + 1) % n]


def _parabola(a, b, c):
    """The offset (in samples, |.| <= 0.5 at a local maximum) of the vertex of the parabola through
    (-1, a), (0, b), (1, c); 0 where they are collinear."""
    curv = np.asarray(a - 2 * b + c)
    return np.where(curv != 0, 0.5 * (a - c) / np.where(curv != 0, curv, 1.0), 0.0)


def gcc_phat(x: np.ndarray, y: np.ndarray, *, max_lag: int, min_lag: int | None = None, search_back: int = 0,
             guard: int = 2) -> GccPeak:
    """The delay of `y` within `x` by GCC-PHAT, searched over lags min_lag..max_lag samples.

    Parameters
    ----------
    x, y : 1-D signals (any lengths)
    max_lag : the largest lag searched (samples)
    min_lag : the smallest (default -max_lag; 0 when y is the emitted signal, which cannot arrive early)
    search_back : > 0: the earliest local maximum of at least half the highest peak within this many
        samples before it is taken instead (a reflection can beat the direct sound, never precede it)
    guard : samples either side of the peak left out of the sidelobe

    The peak is refined by a parabola through it and its neighbours (not at the range's ends).
    Reference: Knapp & Carter, The generalized correlation method for estimation of time delay, 1976.
    """
    lo = -max_lag if min_lag is None else min_lag
    n = _fast_length(len(x) + len(y))  # no wrap-around; a length of small primes (a prime length is slow)
    window = _phat(np.fft.rfft(x, n) * np.conj(np.fft.rfft(y, n)), n, lo, max_lag)
    last = len(window) - 1
    k = top = int(np.argmax(window))
    if search_back > 0 and k > 1:
        before = np.arange(max(1, k - search_back), k)
        earlier = before[(window[before] >= window[before - 1]) & (window[before] >= window[before + 1])
                         & (window[before] >= 0.5 * window[top])]
        k = int(earlier[0]) if len(earlier) else k
    shift = float(_parabola(window[k - 1], window[k], window[k + 1])) if 0 < k < last else 0.0
    outside = np.abs(np.arange(len(window)) - k) > guard
    sidelobe = float(window[outside].max()) if outside.any() else 0.0
    return GccPeak(lo + k + shift, float(window[k]), float(window[top]), float(np.sqrt(np.mean(window**2))),
                   max(sidelobe, 0.0), k in (0, last))


# --------------------------------------------------------------------------------------------------
# Events and the matrix
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TdoaOptions:
    """How a recording becomes a matrix (the defaults are those measured in tables/audio3d.md).

    speed : speed of sound in m/s (the matrix is in metres)
    max_distance : the largest distance between two microphones in metres; the lag range is +- its
        travel time (default 20 m: a room)
    threshold_db : an event starts where the recording's power (all channels) rises this many dB above
        its background (the 10th percentile of 5 ms frames); at 12 dB the simulated rooms at 10 dB SNR
        lost 30-95 % of their events, at 5 dB 0-10 %
    min_gap : seconds of quiet (power below threshold_db - 3 dB) that separate two events
    window : seconds of each event analysed after its onset (plus the lag range either side)
    peaks : the highest peaks of each pair's correlation kept as candidates
    tolerance : samples within which a pair's candidate agrees with two arrivals' difference
    min_support : entries that fewer other channels agree with are left missing
    min_agreement : an event whose channels agree on less than this share of the channel pairs is left
        missing whole (its arrivals may all belong to a reflection; measured: below 0.5, most entries of
        such an event were wrong)
    early : of the arrival times with at least this share of the best support, the earliest is taken
        (reflections arrive after the direct sound)
    taper : seconds of the exponential weight exp(-t / taper) after the onset: the direct sound weighs
        more than the reverberant tail (measured on the simulated rooms: 0.05 s recovers 0.98 of the
        entries where no taper recovers 0.91, RT60 0.4-0.6 s)
    retry_tapers : tapers tried in turn on an event whose channels agree on less than `retry_below` of
        the pairs with `taper`; the taper whose consensus agrees on the most pairs is kept (the first on
        a tie). No taper suits every sound: measured on 30 simulated rooms (20 dB, RT60 0.2-0.6 s), 20 ms
        put the right peak among the candidates of 97 % of the clap pairs and 57 % of the chirp pairs,
        50 ms 94 % and 85 %; agreement chooses without knowing the sound. Empty: `taper` alone
    retry_below : the share of agreeing pairs below which `retry_tapers` are tried (an event that agrees
        well is not analysed again: no cost where the first taper suffices)
    retry_weights : PHAT exponents (PHAT-beta, below 1) tried with every taper after them, while the event
        still agrees on less than `retry_below` of the pairs: PHAT weighs every frequency alike, the empty ones
        between a periodic sound's harmonics too (noise and reverberation); a beta below 1 keeps some weight on
        the loud ones. Empty: PHAT alone
    min_subset, subset_share : an event whose channels agree on less than min_agreement of the pairs is kept
        when a consistent subset of at least min_subset channels agrees: every channel of it agreeing with at
        least subset_share of the others in it (consistent_subset); its other channels' entries are left
        missing. 0: no subset rule (the event left missing whole)
    ambiguous : an event whose pairs' correlations (over `window`, with `taper`) have their second-highest peak
        at more than this share of the highest (the median over the pairs) is analysed whole instead: from its
        onset to its end (at most max_window seconds), without a taper. A periodic sound (a tone, a note: peaks
        at every multiple of its period) or a narrow band (a sweep's first tenth of a second) cannot tell the
        lag in a short window; over its whole length more notes, more of the sweep's band, can. Measured on
        simulated rooms (scripts/audio_kinds.py, RT60 0.55 s, 16 kHz at 20 dB and 48 kHz at 30 dB): the median
        ratio was 0.89-0.95 for three-note phrases, 0.91-0.96 for sweeps, 0.68-0.9 for speech-like sounds,
        0.62-0.81 for claps (at RT60 0.8 s and 10 dB claps and speech reach 0.94); analysed whole, one room's
        phrases (16 kHz, 20 dB) went from 8 to 48 % of the entries within 2 samples, its log sweeps from 0
        to 65 %. Only events lasting whole_after or more (docs/audio.md). 1: never
    max_window : seconds of an event analysed whole (ambiguous)
    whole_after : only an event lasting at least this many seconds from its onset to its end is analysed whole
        when ambiguous: in the mixed rooms of tables/audio3d.md the events judged ambiguous (claps, 0.2 s
        chirps, speech-like sounds) lasted 0.22-0.6 s, and analysed whole, one room's first pass fell from 99.1
        to 95.5 % and two rooms' first calibrations to "partial"; the phrases and sweeps of
        tables/audio3d_kinds.md lasted 0.85-0.97 s
    onset_db : an event's onset is moved back from where its power crosses threshold_db to the last frame at
        most this many dB above the background (a slowly rising sound, a sweep's fade-in, is heard before it
        crosses the threshold: measured at 10 dB SNR, sweeps crossed 5 dB 70 ms after they started)
    starts : the consensus starts from the highest peaks against each of this many channels, the
        loudest first (a start costs about m^3 x peaks^2 operations; on the simulated rooms 2 or 4
        starts gave the matrices all 14-16 gave; 48 channels: 1.1 s per event with 4, 5.8 s with 16)
    frame : seconds per power frame of the event detection
    signal : None, or the emitted sound (1-D samples at the recording's rate; `tdoa --signal FILE`): every
        channel of an event is correlated with it over the whole sound's length, with the phase transform
        (matched_filter: a sweep's or any long sound's arrivals compressed into pulses at their times, the
        channel's room response), and each channel's arrival is its own direct pulse (_signal_arrivals), not
        a pair's correlation: between two channels' responses the correlation peaks wherever one's
        reflection meets the other's direct sound, and under GCC-PHAT the matched filter's |S|^2 cancels
        (measured on the sweep rooms of tables/audio3d_kinds.md: a pair's highest peak at the true lag for
        7-89 % of the pairs of an event, a channel's earliest pulse (signal_share) at its arrival within 2
        samples for 99.2-100 % of the channels of every room)
    signal_share : with a signal, a channel's arrival is the earliest pulse of at least this share of its
        highest, within the lag range before it (its reflections come after the direct sound and can be
        louder): on the same rooms 0.3 put 99.2-100 % of the channels within 2 samples, 0.5 96.7-100 %, the
        highest pulse alone 52-100 %
    signal_psr : with a signal, a channel whose highest pulse is lower than this many times the rms of its
        correlation has no arrival (its entry left missing: nothing of the signal heard above the noise). The
        phase-transformed correlation of noise alone peaks at about sqrt(2 ln N) times its rms (4-5 over an
        event's 10^4-10^5 lags); on the sweep rooms every channel of every event reached 5.5-21 (the lowest in
        the RT60 0.8 s rooms at 10 dB): 5 is a thin margin on both sides
    signal_rate : the signal's sample rate (None: the recording's); a recording at another rate is an error
    sweep_gain : an event analysed whole (`ambiguous`) whose loudest channel's spectrogram ridge follows a sweep (a
        frequency rising or falling linearly or exponentially in time over sweep_span seconds or more and a ratio
        of 4 or more: estimate_sweep) is measured against that estimated sweep as against a given `signal`
        (_sweep_arrivals), when the estimate compresses the sweep_channels loudest channels into a pulse whose
        envelope stands at least sweep_gain x sqrt(ln N) over its rms (N lags; sqrt(ln N) is about the level of
        noise alone, 3.1-3.4 here): on the sweep rooms of tables/audio3d_kinds.md the sweeps' events reached
        a peak 4.3-52 times the rms (median 21), the seven three-note phrases that also fitted a line 3.2-5.7 (the
        staircase test of estimate_sweep, added after, passes none of the 53 phrases analysed whole). 0: never
    sweep_span : seconds the ridge of an estimated sweep must span
    sweep_channels : the loudest channels whose compressed pulses focus the estimated sweep
    onset_rise : an event analysed whole (`ambiguous`) and no sweep is analysed a second way too: its pairs'
        cross-spectra summed over windows that start at each of its onsets (the event's, and every frame whose power
        rises this many dB above its lowest of the 50 ms before, 80 ms or more apart, at most 8: a syllable, a note),
        each weighted by exp(-t / taper) after its onset (onset_arrivals); of the two the analysis agreeing on more
        pairs is kept. Speech in a reverberant room restarts its direct sound at every syllable, which the whole
        event's correlation buries in the tails of the syllables before (measured on the speech rooms of
        tables/audio3d_kinds.md, first pass: 86.8 % of the entries within 2 samples analysed whole, 89.8 % with the
        windows alone, 89.8 % keeping the better; the three-note phrases 43.0 %, 35.9 % and 42.4 %). 0: never
    emphasis : every event (not one measured against a given or estimated sweep) is analysed once more, in both passes:
        on its onsets' direct sound (onset_emphasis: every time-frequency bin weighted by the share of its power that
        is new, to this power), over its segment and, for an event of whole_after or more not analysed whole, over its
        whole length too (emphasised); the analysis agreeing on more pairs is kept. A tone's steady state in a room is the ratio of two room
        responses at its harmonics, not the direct sound's delay: in the three-note phrase rooms of
        tables/audio3d_kinds.md the whole phrase's GCC-PHAT had the true lag highest for 34 % of the pairs, 97 %
        in the same rooms with the direct sound only (scripts/audio_music_probe.py `ranks`); with it the table's
        phrases went from 43.1 to 82.8 % strict, log / linear sweeps from 94.6 / 96.2 to 99.8 / 99.9 %, speech from
        91.2 to 91.9 % (docs/audio.md). 0: never
    emphasis_frame, emphasis_memory : seconds of onset_emphasis's frames (a hop of an eighth) and of the frames
        before whose largest power a bin's power must exceed to count as new
    """

    speed: float = 343.0
    max_distance: float = 20.0
    threshold_db: float = 5.0
    min_gap: float = 0.15
    window: float = 0.1
    peaks: int = 8
    tolerance: float = 1.0
    min_support: int = 2
    min_agreement: float = 0.5
    early: float = 0.5
    taper: float = 0.05
    retry_tapers: tuple[float, ...] = (0.02, 0.1)
    retry_below: float = 0.7
    retry_weights: tuple[float, ...] = (0.5,)
    onset_db: float = 1.0
    min_subset: int = 5
    ambiguous: float = 0.9
    max_window: float = 1.0
    whole_after: float = 0.7
    subset_share: float = 0.8
    starts: int = 4
    frame: float = 0.005
    signal: np.ndarray | None = field(default=None, compare=False, repr=False)
    signal_rate: int | None = None
    signal_share: float = 0.3
    signal_psr: float = 5.0
    sweep_gain: float = 2.0
    sweep_span: float = 0.3
    sweep_channels: int = 5
    onset_rise: float = 6.0
    emphasis: float = 2.0
    emphasis_frame: float = 0.016
    emphasis_memory: float = 0.008

    def __post_init__(self) -> None:
        if self.signal is not None:
            sig = np.asarray(self.signal, dtype=float)
            if sig.ndim != 1 or len(sig) < 2 or not np.all(np.isfinite(sig)) or not np.any(sig):
                raise ValueError("signal must be one channel of finite samples, not all zero")
            object.__setattr__(self, "signal", sig)
        for name in ("speed", "max_distance", "window", "frame", "min_gap", "threshold_db", "taper"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {value}")
        if self.peaks < 1 or self.min_support < 1 or self.starts < 1 or not (np.isfinite(self.tolerance) and self.tolerance > 0):
            raise ValueError("peaks, min_support and starts must be >= 1 and tolerance > 0")
        if not 0.0 <= self.min_agreement <= 1.0:
            raise ValueError(f"min_agreement must be in [0, 1], got {self.min_agreement}")
        if not (np.isfinite(self.whole_after) and self.whole_after >= 0):
            raise ValueError(f"whole_after must be a finite number >= 0, got {self.whole_after}")
        if not 0.0 < self.ambiguous <= 1.0 or not (np.isfinite(self.max_window) and self.max_window > 0):
            raise ValueError(f"ambiguous must be in (0, 1] and max_window > 0, got {self.ambiguous}, {self.max_window}")
        if self.min_subset < 0 or not 0.0 < self.subset_share <= 1.0:
            raise ValueError(f"min_subset must be >= 0 and subset_share in (0, 1], got {self.min_subset}, "
                             f"{self.subset_share}")
        if not all(np.isfinite(b) and 0 < b <= 1 for b in self.retry_weights):
            raise ValueError(f"retry_weights must be numbers in (0, 1], got {self.retry_weights}")
        if not (np.isfinite(self.onset_db) and 0 <= self.onset_db <= self.threshold_db):
            raise ValueError(f"onset_db must be in [0, threshold_db], got {self.onset_db}")
        if not all(np.isfinite(t) and t > 0 for t in self.retry_tapers):
            raise ValueError(f"retry_tapers must be finite numbers > 0, got {self.retry_tapers}")
        if not 0.0 <= self.retry_below <= 1.0:
            raise ValueError(f"retry_below must be in [0, 1], got {self.retry_below}")
        if not 0.0 < self.early <= 1.0:
            raise ValueError(f"early must be in (0, 1], got {self.early}")
        if not (np.isfinite(self.sweep_gain) and self.sweep_gain >= 0 and np.isfinite(self.sweep_span)
                and self.sweep_span > 0 and self.sweep_channels >= 1):
            raise ValueError(f"sweep_gain must be >= 0, sweep_span > 0 and sweep_channels >= 1, got {self.sweep_gain}, "
                             f"{self.sweep_span}, {self.sweep_channels}")
        if not (np.isfinite(self.onset_rise) and self.onset_rise >= 0):
            raise ValueError(f"onset_rise must be a finite number >= 0, got {self.onset_rise}")
        if not (np.isfinite(self.emphasis) and self.emphasis >= 0 and np.isfinite(self.emphasis_frame)
                and self.emphasis_frame > 0 and np.isfinite(self.emphasis_memory) and self.emphasis_memory > 0):
            raise ValueError(f"emphasis must be >= 0, emphasis_frame and emphasis_memory > 0, got {self.emphasis}, "
                             f"{self.emphasis_frame}, {self.emphasis_memory}")
        if not 0.0 < self.signal_share <= 1.0 or not (np.isfinite(self.signal_psr) and self.signal_psr >= 0):
            raise ValueError(f"signal_share must be in (0, 1] and signal_psr >= 0, got {self.signal_share}, "
                             f"{self.signal_psr}")


def detect_events(samples: np.ndarray, rate: int, options: TdoaOptions = TdoaOptions()) -> np.ndarray:
    """(events, 2) sample ranges [start, end) of the sound events of (channels, frames) samples: runs of frames
    whose power (mean over channels) is more than threshold_db above the background, closed by min_gap of quiet
    (threshold_db - 3 dB: hysteresis), in time order (recording_events of the samples)."""
    samples = np.asarray(samples, dtype=float)
    names = tuple(str(k + 1) for k in range(samples.shape[0]))
    return recording_events(Recording(samples, rate, names, "samples"), options)


def frame_power(recording: Recording, hop: int) -> np.ndarray:
    """(frames,) the power of every whole frame of `hop` samples, averaged over the channels, read block by
    block (a streamed recording is never in memory whole)."""
    m = len(recording.channels)
    size = hop * max(1, BLOCK_FRAMES // hop)
    parts = []
    for _, block in recording.blocks(size):
        whole = block.shape[1] // hop
        if whole:
            parts.append(np.mean(block[:, : whole * hop].reshape(m, whole, hop) ** 2, axis=(0, 2)))
    return np.concatenate(parts) if parts else np.zeros(0)


def recording_events(recording: Recording, options: TdoaOptions = TdoaOptions()) -> np.ndarray:
    """(events, 2) sample ranges [start, end) of the recording's sound events (detect_events says how)."""
    hop = max(1, int(round(options.frame * recording.rate)))
    power = frame_power(recording, hop)
    frames = len(power)
    if frames < 2:
        return np.zeros((0, 2), int)
    floor = max(float(np.percentile(power, 10)), 1e-30)
    level = 10 * np.log10(np.maximum(power, 1e-30) / floor)
    loud, quiet = level > options.threshold_db, level < options.threshold_db - 3.0
    gap = max(1, int(round(options.min_gap / options.frame)))
    events, start, quiet_run = [], None, 0
    for f in range(frames):
        if start is None:
            if loud[f]:
                start, quiet_run = f, 0
                back = events[-1][1] // hop if events else 0  # never into the event before
                while start > back and level[start - 1] > options.onset_db:
                    start -= 1  # the sound rose before it crossed the threshold
            continue
        quiet_run = quiet_run + 1 if quiet[f] else 0
        if quiet_run >= gap:
            events.append((start * hop, (f - quiet_run + 1) * hop))
            start = None
    if start is not None:
        events.append((start * hop, frames * hop))
    return np.array(events, dtype=int).reshape(-1, 2)


@dataclass(frozen=True)
class TdoaMatrix:
    """The measurement matrix of a recording (see the module docstring).

    F : (channels, events) metres, NaN where missing (unreliable)
    confidence : (channels, events) each entry's support: how many other channels agree with it
    reference : (events,) the reference channel of each event (0-based)
    onsets : (events,) seconds from the start of the recording
    rate, speed : sample rate (Hz), speed of sound (m/s)
    channels, events : names of the rows and columns
    source : the recording's file name(s)
    notes : what the reader or the analysis did that a user should know
    swept : the events (indices) measured against their own estimated sweep (TdoaOptions.sweep_gain): each channel
        against the sound, not pairs of channels, so the guided pass keeps their columns
    """

    F: np.ndarray
    confidence: np.ndarray
    reference: np.ndarray
    onsets: np.ndarray
    rate: int
    speed: float
    channels: tuple[str, ...]
    events: tuple[str, ...]
    source: str
    notes: tuple[str, ...] = field(default=())
    swept: tuple[int, ...] = field(default=())


def matched_filter(seg: np.ndarray, signal: np.ndarray, beta: float = 0.0) -> np.ndarray:
    """(channels, frames - len(signal) + 1): each channel's correlation with the emitted signal,
    out[t] = sum_s seg[t + s] signal[s]: a sound emitted at t shows as a pulse at t (zeros when the
    segment is shorter than the signal: nothing to compress). beta > 0: each frequency of the
    cross-spectrum divided by its magnitude to that power (1: the phase transform, every frequency of
    the signal voting alike: the pulse sharpened to the channel's room response)."""
    frames, L = seg.shape[1], len(signal)
    if frames < L:
        return np.zeros((seg.shape[0], 1))
    n = _fast_length(frames + L)
    cross = np.fft.rfft(seg, n, axis=1) * np.conj(np.fft.rfft(signal, n))[None, :]
    if beta > 0:
        cross = cross / np.maximum(np.abs(cross), 1e-30) ** beta
    out = np.fft.irfft(cross, n, axis=1)
    return out[:, : frames - L + 1]


def _signal_arrivals(pulses: np.ndarray, max_lag: int, options: TdoaOptions):
    """(reference, arrival times relative to it in samples, support, agreeing pairs) of one event from each
    channel's correlation with the emitted signal (pulses (channels, frames), matched_filter with the phase
    transform): a channel's arrival is the earliest local maximum of at least options.signal_share of its
    highest, within max_lag samples before it (parabolic sub-sample), kept when its height is at least
    options.signal_psr x the rms of the channel's correlation. Every kept channel's arrival is measured
    against the signal itself, so every pair of kept channels is a measured difference: support is the
    number of other kept channels. The reference is the kept channel of the highest pulse."""
    m, frames = pulses.shape
    t = np.zeros(m)
    height = np.zeros(m)
    kept = np.zeros(m, bool)
    rms = np.sqrt(np.mean(pulses**2, axis=1))
    for ch in range(m):
        x = pulses[ch]
        if frames < 3:
            break
        top = int(np.argmax(x[1:-1])) + 1
        lo = max(1, top - max_lag)
        near = np.arange(lo, top + 1)
        local = near[(x[near] >= x[near - 1]) & (x[near] > x[near + 1]) & (x[near] >= options.signal_share * x[top])]
        k = int(local[0]) if len(local) else top
        t[ch] = k + float(_parabola(x[k - 1], x[k], x[k + 1]))
        height[ch] = x[k]
        kept[ch] = x[top] > 0 and x[top] >= options.signal_psr * rms[ch]
    r = int(np.argmax(np.where(kept, height, -np.inf))) if kept.any() else int(np.argmax(height))
    ok = np.outer(kept, kept)
    np.fill_diagonal(ok, False)
    return r, t - t[r], ok.sum(axis=1), ok


def _analytic(x: np.ndarray) -> np.ndarray:
    """The analytic signal of x along its last axis (x + i Hilbert(x)): its magnitude is x's envelope."""
    n = x.shape[-1]
    h = np.zeros(n)
    h[0] = 1.0
    h[1 : (n + 1) // 2] = 2.0
    if n % 2 == 0:
        h[n // 2] = 1.0
    return np.fft.ifft(np.fft.fft(x, axis=-1) * h, axis=-1)


def _ridge(x: np.ndarray, rate: int):
    """(times s, frequencies Hz, bin width Hz) of a spectrogram's strongest frequency in every frame of x (16 ms
    Hann frames, a quarter hop, the peak refined by a parabola through the log powers) whose power is at least
    5 % of the loudest frame's; None when x is shorter than two frames."""
    n = 1 << int(np.ceil(np.log2(0.016 * rate)))
    hop = n // 4
    if len(x) < n + hop:
        return None
    idx = np.arange(n)[None, :] + hop * np.arange((len(x) - n) // hop + 1)[:, None]
    S = np.abs(np.fft.rfft(x[idx] * np.hanning(n), axis=1)) ** 2
    k = np.argmax(S[:, 1:-1], axis=1) + 1
    r = np.arange(len(k))
    lo, mid, hi = (np.log(S[r, k + d] + 1e-300) for d in (-1, 0, 1))
    f = (k + _parabola(lo, mid, hi)) * rate / n
    power = S.sum(axis=1)
    strong = power >= 0.05 * power.max()
    return (idx[strong, 0] + n / 2) / rate, f[strong], rate / n


def _fit_track(t: np.ndarray, f: np.ndarray, width: float, log: bool):
    """(intercept, slope, inliers) of f = a + b t (log: ln f = a + b t) fitted to a ridge, five rounds of least
    squares each keeping the frames within max(3 bins, 8 %) of the last fit; None below 8 frames."""
    y = np.log(np.maximum(f, 1e-9)) if log else f
    use = np.ones(len(t), bool)
    coef = None
    for _ in range(5):
        if use.sum() < 8:
            return None
        coef = np.linalg.lstsq(np.column_stack([np.ones(use.sum()), t[use]]), y[use], rcond=None)[0]
        fit = coef[0] + coef[1] * t
        fit = np.exp(fit) if log else fit
        use = np.abs(f - fit) <= np.maximum(3 * width, 0.08 * fit)
    return coef[0], coef[1], use


def estimate_sweep(x: np.ndarray, rate: int, focus: np.ndarray, options: TdoaOptions = TdoaOptions()):
    """(the estimated emitted sweep, its gain) when the loudest channel x of an event follows a sweep, else None.

    The ridge of x's spectrogram (_ridge) is fitted by a linear and by an exponential frequency track (_fit_track);
    the track of more inliers (at least 60 % of the ridge's frames) spanning options.sweep_span seconds or more and a
    frequency ratio of 4 or more, each third of whose inliers rises (or falls) at 0.5-2 x its slope (notes on a line
    are a staircase), is a sweep, synthesised over the inliers' span with a 0.25-power Hann fade. A
    ridge's slope is biased by the reverberation (by 0.3-3 % measured; a sweep of 0.8 s then smears its compressed
    pulse over milliseconds), so the slope is focused: the one of a grid (+-5 %, then +-0.6, 0.08, 0.01 %, eleven
    each, around the best) whose matched filters (phase transform) of the `focus` channels (rows) have the highest
    envelope peaks over their rms, summed; the track's centre frequency and time stay (an error there only delays
    every channel alike). The gain: that sum's mean over the channels, divided by sqrt(ln N) of the N lags (about
    the level of noise alone); below options.sweep_gain the estimate is None (a three-note phrase whose notes lie
    near a line)."""
    got = _ridge(x, rate)
    if got is None:
        return None
    t, f, width = got
    best = None
    for log in (False, True):
        fitted = _fit_track(t, f, width, log)
        if fitted is None:
            continue
        a, b, use = fitted
        if use.sum() < 0.6 * len(t):
            continue
        t0, t1 = t[use].min(), t[use].max()
        f0, f1 = ((np.exp(a + b * t0), np.exp(a + b * t1)) if log else (a + b * t0, a + b * t1))
        if t1 - t0 < options.sweep_span or min(f0, f1) <= 0 or max(f0, f1) < 4 * min(f0, f1):
            continue
        y = np.log(np.maximum(f[use], 1e-9)) if log else f[use]
        thirds = np.minimum((3 * (t[use] - t0) / (t1 - t0)).astype(int), 2)
        local = [np.polyfit(t[use][thirds == k], y[thirds == k], 1)[0] if np.sum(thirds == k) >= 3 else 0.0
                 for k in range(3)]
        if not all(0.5 <= slope / b <= 2.0 for slope in local):
            continue  # a staircase (notes on a line) is no sweep: every third of the track rises at its slope
        if best is None or use.sum() > best[0]:
            best = (use.sum(), log, a, b, t0, t1)
    if best is None:
        return None
    _, log, a, b, t0, t1 = best
    u = np.arange(int(t0 * rate), int(t1 * rate)) / rate - 0.5 * (t0 + t1)
    centre = a + b * 0.5 * (t0 + t1)
    fade = np.hanning(len(u)) ** 0.25

    def sweep(slope):
        phase = (np.exp(centre) * np.expm1(slope * u) / slope if log else centre * u + slope * u**2 / 2)
        return np.sin(2 * np.pi * phase) * fade

    def gain(slope):
        env = np.abs(_analytic(matched_filter(focus, sweep(slope), beta=1.0)))
        return float(np.mean(env.max(axis=1) / np.maximum(np.sqrt(np.mean(env**2, axis=1)), 1e-300)))

    for span in (0.05, 0.006, 0.0008, 0.0001):
        grid = b * (1 + np.linspace(-span, span, 11))
        b = grid[int(np.argmax([gain(g) for g in grid]))]
    lags = max(2, matched_filter(focus[:1], sweep(b)).shape[1])
    score = gain(b) / np.sqrt(np.log(lags))
    return (sweep(b), score) if score >= options.sweep_gain else None


def _sweep_arrivals(seg: np.ndarray, rate: int, max_lag: int, options: TdoaOptions):
    """_signal_arrivals of an event analysed whole against its estimated sweep (estimate_sweep), or None when the
    loudest channel follows no sweep. The estimate's phase is not the emitted sweep's: each channel's compressed
    pulse is a mix of the pulse and its Hilbert transform, two lobes a few samples apart of which either can be
    the earliest strong one; the pulses are turned by the phase of the highest envelope peak of the channel of the
    sharpest (the one angle for every channel), which makes them one lobe again (measured on the sweep rooms' first
    pass, log / linear: 66.9 / 74.0 % of the entries within 2 samples without the turn, 94.4 / 92.2 % with it)."""
    energy = np.sum(seg**2, axis=1)
    loud = np.argsort(energy)[::-1]
    got = estimate_sweep(seg[loud[0]], rate, seg[loud[: options.sweep_channels]], options)
    if got is None:
        return None
    z = _analytic(matched_filter(seg, got[0], beta=1.0))
    env = np.abs(z)
    r = int(np.argmax(env.max(axis=1) / np.maximum(np.sqrt(np.mean(env**2, axis=1)), 1e-300)))
    turn = np.exp(-1j * np.angle(z[r, int(np.argmax(env[r]))]))
    return _signal_arrivals(np.real(turn * z), max_lag, options)


def onset_windows(seg: np.ndarray, rate: int, max_lag: int, options: TdoaOptions = TdoaOptions()) -> np.ndarray:
    """(windows, samples) weights of an event's segment (its onset at sample max_lag): one per onset (the event's,
    and every 5 ms frame of the channels' mean power that rises options.onset_rise dB or more above the lowest of
    the 50 ms before it, a local maximum of that power, 80 ms or more after the onset before; at most 8), 1 over
    the lag range before the onset, exp(-t / options.taper) after it, 0 earlier."""
    hop = max(1, int(round(0.005 * rate)))
    body = seg[:, max_lag:]
    frames = body.shape[1] // hop
    starts = [0]
    if frames > 2:
        level = 10 * np.log10(np.maximum(np.mean(body[:, : frames * hop].reshape(seg.shape[0], frames, hop) ** 2,
                                                 axis=(0, 2)), 1e-300))
        for f in range(2, frames):
            if len(starts) == 8:
                break
            if (level[f] - level[max(0, f - 10) : f].min() >= options.onset_rise and level[f] >= level[f - 1]
                    and (f + 1 == frames or level[f] >= level[f + 1]) and f - starts[-1] >= 16):
                starts.append(f)
    t = np.arange(seg.shape[1])
    onsets = max_lag + hop * np.array(starts)
    return np.where(t[None, :] < onsets[:, None] - max_lag, 0.0,
                    np.exp(-np.maximum(t[None, :] - onsets[:, None], 0) / (options.taper * rate)))


def onset_emphasis(seg: np.ndarray, rate: int, options: TdoaOptions = TdoaOptions()) -> np.ndarray:
    """(channels, samples) each channel of an event's segment with its onsets' direct sound kept and its steady state
    dropped: its short-time spectrum (Hann frames of options.emphasis_frame s, a hop of an eighth) weighted bin by bin
    by (1 - P_before / P)^options.emphasis, clipped to [0, 1], P the bin's power and P_before the largest power of
    its frequency over the options.emphasis_memory s before, then overlap-added back.

    At a note's onset every harmonic rises first at the direct sound; the reflections that follow add power
    more slowly, and the steady state a tone reaches in a room (the ratio of two room responses at its harmonics,
    not the direct sound's delay) is not new, so it weighs nothing. Each channel is weighted by its own spectrum:
    nothing depends on the lags between channels. A precedence-effect weighting in the spirit of Wilson & Darrell,
    Learning a precedence effect-like weighting function for the generalized cross-correlation framework (IEEE
    TASLP 2006), without their learned weights."""
    m, length = seg.shape
    n = max(4, int(round(options.emphasis_frame * rate)))
    hop = max(1, n // 8)
    frames = max(1, -(-(length + n) // hop))
    padded = np.zeros((m, (frames - 1) * hop + 2 * n))
    padded[:, n : n + length] = seg  # a frame of zeros before: the first samples are new
    window = np.hanning(n + 2)[1:-1]
    idx = np.arange(n)[None, :] + hop * np.arange(frames)[:, None]
    Z = np.fft.rfft(padded[:, idx] * window, axis=2)  # (m, frames, bins)
    P = np.abs(Z) ** 2
    memory = max(1, int(round(options.emphasis_memory * rate / hop)))
    before = np.zeros_like(P)
    for d in range(1, memory + 1):
        before[:, d:] = np.maximum(before[:, d:], P[:, :-d])
    weight = np.clip(1.0 - before / np.maximum(P, 1e-300), 0.0, 1.0) ** options.emphasis
    parts = np.fft.irfft(Z * weight, n, axis=2) * window
    out = np.zeros_like(padded)
    norm = np.zeros(padded.shape[1])
    np.add.at(norm, idx.ravel(), np.tile(window**2, frames))
    for f in range(frames):  # overlap-add (frames of one hop each: a loop over the frames, each a vector op)
        out[:, idx[f]] += parts[:, f]
    return out[:, n : n + length] / np.maximum(norm[n : n + length], 1e-12)


def _pair_candidates(seg: np.ndarray, max_lag: int, peaks: int, beta: float = 1.0, weights=None):
    """GCC-PHAT of every channel pair (i < k) of an event's segments: (i, k, lags (pairs, peaks),
    heights (pairs, peaks)), the `peaks` highest local maxima of each correlation over +-max_lag,
    parabolically refined (lag of channel i's sound behind channel k's, in samples). weights: None, or
    (windows, samples) weights of the segment whose cross-spectra are summed before the phase transform."""
    m, length = seg.shape
    n = _fast_length(2 * length)
    i, k = np.triu_indices(m, 1)
    cross = 0.0
    for w in ([None] if weights is None else weights):
        X = np.fft.rfft(seg if w is None else seg * w, n, axis=1)
        cross = cross + X[i] * np.conj(X[k])
    window = _phat(cross, n, -max_lag, max_lag, beta)
    inner = np.zeros_like(window, dtype=bool)
    inner[:, 1:-1] = (window[:, 1:-1] >= window[:, :-2]) & (window[:, 1:-1] > window[:, 2:])
    masked = np.where(inner, window, -np.inf)
    peaks = min(peaks, masked.shape[1])
    top = np.argpartition(masked, masked.shape[1] - peaks, axis=1)[:, -peaks:]  # the peaks highest, unordered
    ranked = np.take_along_axis(top, np.argsort(-np.take_along_axis(masked, top, axis=1), axis=1, kind="stable"), axis=1)
    rows = np.arange(len(i))[:, None]
    b = window[rows, ranked]
    last = window.shape[1] - 1  # (fewer local maxima than peaks: an end is ranked, its height 0, its shift 0)
    shift = np.where(inner[rows, ranked], _parabola(window[rows, np.maximum(ranked - 1, 0)], b,
                                                    window[rows, np.minimum(ranked + 1, last)]), 0.0)
    heights = np.where(inner[rows, ranked], b, 0.0)
    return i, k, ranked - max_lag + shift, heights


def _candidate_tensor(m: int, i, k, lags, heights):
    """(P (m, m, peaks): channel a's lag behind channel b per candidate, NaN for none; H: their heights)."""
    P = np.full((m, m, lags.shape[1]), np.nan)
    H = np.zeros((m, m, lags.shape[1]))
    P[i, k], P[k, i] = lags, -lags
    H[i, k], H[k, i] = heights, heights
    return P, H


def _consensus(m: int, ref: int, i, k, lags, heights, tol: float, early: float = 0.5, sweeps: int = 4,
               starts=None, init=None):
    """Arrival times t (m,) of an event's channels relative to channel `ref` (t_ref = 0) from the
    candidate pair delays (t_i - t_k ~ one of lags[pair]), and each channel's support: how many other
    channels have a candidate within `tol` samples of the times' difference.

    From each channel's highest peaks against one channel (each of `starts`, default every channel), sweeps
    that move each channel to the time best supported by the others (one vote per other channel, its
    candidates weighted by height; of the times with at least `early` x the best support the earliest,
    since a channel's reflections arrive after its direct sound), and the mean of the supporting votes;
    the start whose end supports the most pairs wins, and a least-squares fit of its supported pairs
    gives the times (the graph Laplacian with t_ref = 0). init : None, or the one start (m,) times (the
    guided pass: the arrivals the geometry predicts; NaN lags are no candidate). A channel whose
    agreeing pairs do not connect it to `ref` has support 0: its time relative to ref is not measured."""
    P, H = _candidate_tensor(m, i, k, lags, heights)
    best = None
    if init is not None:
        firsts = [np.asarray(init, dtype=float).copy()]
    else:
        firsts = (np.where(np.arange(m) == start, 0.0, P[:, start, 0]) for start in (range(m) if starts is None else starts))
    for first in firsts:
        t = _sweep(P, H, first, tol, early, sweeps)
        ok, val = _supported(P, t, tol)
        score = int(ok.sum())  # agreeing pairs; the first start of the most wins
        if best is None or score > best[0]:
            best = (score, t, ok, val)
    _, t, ok, val = best
    ok = ok & np.outer(*(2 * [_component(ok, ref)]))  # pairs connected to the reference
    support = ok.sum(axis=1)
    L = np.diag(support.astype(float)) - ok.astype(float)
    rhs = np.where(ok, val, 0.0).sum(axis=1)
    free = np.flatnonzero(np.arange(m) != ref)
    t = t - t[ref]
    if ok.any():
        t[free] = np.linalg.lstsq(L[np.ix_(free, free)], rhs[free], rcond=None)[0]
    return t, support


def consistent_subset(ok: np.ndarray, min_support: int, share: float) -> np.ndarray:
    """(m,) bool: the largest set of channels found by peeling in which every channel agrees with at least
    `share` of the others in it (ok (m, m): the agreeing pairs of a consensus, each pair's candidate within
    the tolerance of the two arrivals' difference, so that tau_ij + tau_jk = tau_ik holds within twice
    it on every triangle of agreeing pairs). Starts from the channels with min_support agreeing pairs and
    drops the channel agreeing with the fewest others in the set until every one agrees with enough."""
    inside = ok.sum(axis=1) >= min_support
    while inside.any():
        within = (ok & inside[None, :]).sum(axis=1)
        need = share * (inside.sum() - 1)
        worst = int(np.argmin(np.where(inside, within - need, np.inf)))
        if within[worst] >= need:
            break
        inside[worst] = False
    return inside


def _component(ok: np.ndarray, ref: int) -> np.ndarray:
    """(m,) bool: the channels connected to `ref` by agreeing pairs (ok, symmetric)."""
    seen = np.zeros(len(ok), bool)
    seen[ref] = True
    while True:
        grown = seen | ok[seen].any(axis=0)
        if np.array_equal(grown, seen):
            return seen
        seen = grown


def _sweep(P, H, t, tol: float, early: float, sweeps: int) -> np.ndarray:
    """`sweeps` passes of _consensus's channel-by-channel update from times t."""
    m = len(t)
    rows = np.arange(m)
    for _ in range(sweeps):
        before = t.copy()
        for a in range(m):
            votes = P[a] + t[:, None]  # (m, peaks): candidate times of channel a by each other channel
            votes[a] = np.nan
            flat = votes[np.isfinite(votes)]
            if not len(flat):
                continue
            near = np.abs(votes[None, :, :] - flat[:, None, None]) <= tol  # (candidates, m, peaks)
            score = np.max(np.where(near, H[a][None], 0.0), axis=2).sum(axis=1)
            pick = float(np.min(flat[score >= early * score.max()]))
            hit = np.abs(votes - pick) <= tol
            chosen = np.where(hit, np.abs(votes - pick), np.inf).argmin(axis=1)
            sel = hit[rows, chosen]
            t[a] = float(np.mean(votes[rows, chosen][sel]))
        if np.array_equal(t, before):
            break
    return t


def _supported(P, t, tol: float):
    """(ok (m, m): pairs with a candidate within tol of t_i - t_k, that candidate (m, m))."""
    diff = P - (t[:, None] - t[None, :])[:, :, None]
    hit = np.abs(diff) <= tol
    pick = np.where(hit, np.abs(diff), np.inf).argmin(axis=2)
    ok = np.take_along_axis(hit, pick[:, :, None], axis=2)[:, :, 0]
    np.fill_diagonal(ok, False)
    return ok, np.take_along_axis(P, pick[:, :, None], axis=2)[:, :, 0]


def _event_arrivals(seg: np.ndarray, max_lag: int, options: TdoaOptions, beta: float = 1.0, candidates=None):
    """(reference channel, arrival times relative to it in samples, support) of one event's weighted
    segments (channels, samples): the loudest channel is the reference; _consensus of the pairs'
    GCC-PHAT candidates (candidates: None, or those already computed, _pair_candidates(seg, max_lag,
    options.peaks, beta))."""
    energy = np.sum(seg**2, axis=1)
    r = int(np.argmax(energy))
    m = seg.shape[0]
    starts = None if options.starts >= m else np.argsort(energy)[::-1][: options.starts]
    if candidates is None:
        candidates = _pair_candidates(seg, max_lag, options.peaks, beta)
    t, support = _consensus(m, r, *candidates, options.tolerance, options.early, starts=starts)
    return r, t, support, agreeing_pairs(m, candidates, t, options.tolerance)


def ambiguity(seg: np.ndarray, max_lag: int, peaks: int) -> float:
    """The median over the channel pairs of their GCC-PHAT correlation's second-highest peak over its highest
    (near 1: peaks at every multiple of a period, the lag undecided)."""
    if seg.shape[0] < 2 or peaks < 2:
        return 0.0
    heights = _pair_candidates(seg, max_lag, peaks)[3]
    return float(np.median(heights[:, 1] / np.maximum(heights[:, 0], 1e-12)))


def agreeing_pairs(m: int, candidates, t: np.ndarray, tol: float) -> np.ndarray:
    """(m, m) bool: the channel pairs with a candidate (i, k, lags, heights of _pair_candidates) within tol
    samples of the difference of the arrival times t."""
    return _supported(_candidate_tensor(m, *candidates)[0], t, tol)[0]


#: floats (lags and heights) of the first analyses tdoa_matrix keeps for a second pass at most (160 MB)
KEEP_FLOATS = 20_000_000


def tdoa_matrix(recording: Recording, options: TdoaOptions = TdoaOptions(), progress=None,
                keep: dict | None = None) -> TdoaMatrix:
    """Detect the events of a recording and measure every channel's arrival time in each event, relative
    to the event's reference channel (the one with the most energy in the event's window), by GCC-PHAT
    of every channel pair and their consensus.

    The correlation of two microphones' recordings peaks at the difference of their direct sounds,
    but reverberation adds peaks, and a pair of distant microphones can see a reflection's peak above
    the direct one. Every pair's `options.peaks` highest peaks are candidates; each channel's time is
    the one most other channels agree with (within `options.tolerance` samples, weighted by peak
    height), then one least-squares fit over the agreeing pairs. An entry's confidence is the number
    of other channels that agree with it; below `options.min_support` it is left missing.

    progress : None, or a callable taking one line (called every 10 events)
    keep : None, or a dict that receives, event by event (index -> (i, k, lags, heights)), the candidates of each
        event's first analysis (options.taper with PHAT: the guided pass's first analysis too,
        solvers.audio_guided), until they hold KEEP_FLOATS floats
    Raises RecordingError when no event is found.
    """
    if options.signal is not None:  # each channel against the emitted signal (TdoaOptions.signal)
        return _measure(recording, options, lambda j, seg, after, max_lag, whole: _signal_arrivals(seg, max_lag, options),
                        progress)
    kept = [0]
    swept: list[int] = []
    windowed: dict[int, int] = {}
    emphasised_events: list[int] = []

    def arrivals(j, seg, after, max_lag, whole):
        if options.sweep_gain > 0 and not np.any(after):  # analysed whole: a sweep is measured against its estimate
            got = _sweep_arrivals(seg, recording.rate, max_lag, options)
            if got is not None:
                swept.append(j)
                return got

        def analyse(weighted, beta):
            candidates = _pair_candidates(weighted, max_lag, options.peaks, beta)
            if keep is not None and j not in keep and kept[0] + 2 * candidates[2].size <= KEEP_FLOATS:
                keep[j] = candidates  # _over_tapers' first analysis
                kept[0] += 2 * candidates[2].size
            return _event_arrivals(weighted, max_lag, options, beta, candidates)
        best = _over_tapers(seg, after, options, analyse)
        if options.onset_rise > 0 and not np.any(after):  # analysed whole: its onsets' windows too (onset_rise)
            weights = onset_windows(seg, recording.rate, max_lag, options)
            for beta in (1.0, *options.retry_weights):
                got = _event_arrivals(seg, max_lag, options, beta, _pair_candidates(seg, max_lag, options.peaks, beta,
                                                                                     weights))
                if got[2].sum() > best[2].sum():
                    best, windowed[j] = got, len(weights)
        got = emphasised(seg, whole, recording.rate, options, best,
                         lambda z: _event_arrivals(z, max_lag, options))
        if got is not best:
            best = got
            emphasised_events.append(j)
            windowed.pop(j, None)
        return best

    tm = _measure(recording, options, arrivals, progress)
    if windowed:
        tm = replace(tm, notes=tm.notes + (f"{len(windowed)} event(s) measured over windows at their onsets (a syllable, "
                                           "a note), agreeing on more pairs than analysed whole: "
                                           f"{', '.join(tm.events[j] for j in sorted(windowed))}",))
    if emphasised_events:
        tm = replace(tm, notes=tm.notes + (f"{len(emphasised_events)} event(s) measured on their onsets' direct sound (the "
                                           "steady state of each frequency dropped: onset_emphasis), agreeing on more pairs "
                                           f"so: {', '.join(tm.events[j] for j in emphasised_events)}",))
    if swept:
        tm = replace(tm, swept=tuple(swept), notes=tm.notes + (f"{len(swept)} event(s) measured against their own estimated sweep (a "
                                           "frequency track fitted to the loudest channel's spectrogram, its slope "
                                           f"focused): {', '.join(tm.events[j] for j in swept)}",))
    return tm


def emphasised(seg: np.ndarray, whole, rate: int, options: TdoaOptions, best, analyse):
    """`best`, or the analysis of an event's onsets' direct sound (onset_emphasis of its segment `seg`, and of its whole
    segment `whole` when given) that agrees on more pairs than it; analyse(segment) -> (reference, times, support,
    agreeing pairs, ...). options.emphasis 0: `best`. Both passes (tdoa_matrix, solvers.audio_guided) run it. An analysis
    whose every pair agrees cannot be bettered and is not analysed again (the bursts of scripts/bench_audio_stream.py:
    the first pass's CPU time 2.5 times that without the emphasis, were they)."""
    if options.emphasis <= 0:
        return best
    m = seg.shape[0]
    for part in (seg, whole):
        if part is not None and best[2].sum() < m * (m - 1):
            got = analyse(onset_emphasis(part, rate, options))
            if got[2].sum() > best[2].sum():
                best = got
    return best


def _over_tapers(seg: np.ndarray, after: np.ndarray, options: TdoaOptions, analyse):
    """(reference, times, support, agreeing pairs) of the taper and weight (options.taper with PHAT, then options.retry_tapers,
    then every taper with each of options.retry_weights, while fewer than retry_below of the pairs agree)
    whose analysis agrees on the most pairs; analyse(weighted segment, PHAT exponent) -> (reference, times,
    support, agreeing pairs)."""
    m = seg.shape[0]
    best = None
    tapers = (options.taper, *options.retry_tapers) if np.any(after) else (options.taper,)  # no taper: one analysis
    for taper, beta in [(t, 1.0) for t in tapers] + [(t, b) for b in options.retry_weights for t in tapers]:
        got = analyse(seg * np.exp(-after / taper), beta)
        if best is None or got[2].sum() > best[2].sum():
            best = got
        if best[2].sum() >= options.retry_below * m * (m - 1):
            break  # enough pairs agree: no other taper tried
    return best


def _measure(recording: Recording, options: TdoaOptions, arrivals, progress=None, label: str = "tdoa") -> TdoaMatrix:
    """The event loop both passes share (tdoa_matrix, solvers.audio_guided): detect the events, cut each
    event's segment (the lag range either side of `options.window` after its onset; `after`: seconds
    after the onset of each sample, 0 before it), and turn arrivals(j, segment, after, max_lag, whole) ->
    (reference, times in samples relative to it, support, agreeing pairs[, the share of agreeing pairs the event
    needs])
    or None (the event left missing) into the matrix: an entry is kept with support >= min_support; an
    event whose channels agree on fewer than that share of the pairs (default options.min_agreement) is
    left missing whole. `whole`: None, or the segment of an event lasting options.whole_after or more that is not
    analysed whole (not ambiguous) from its onset to its end (at most max_window s; options.emphasis > 0), for
    the direct sound of its later onsets (emphasised)."""
    rate = recording.rate
    events = recording_events(recording, options)
    if len(events) == 0:
        raise RecordingError(f"{recording.source}: no sound event found (nothing {options.threshold_db:g} dB above the "
                             "background; lower the threshold, or check the recording)")
    max_lag = max(1, int(np.ceil(options.max_distance / options.speed * rate)))
    length = int(round(options.window * rate))
    m, n = len(recording.channels), len(events)
    F = np.full((m, n), np.nan)
    conf = np.zeros((m, n))
    ref = np.zeros(n, int)
    onsets = events[:, 0] / rate
    dropped: dict[float, list[int]] = {}
    subsets: list[int] = []
    emitted = 0 if options.signal is None else len(options.signal)
    if emitted and options.signal_rate not in (None, rate):
        raise RecordingError(f"the emitted signal is at {options.signal_rate} Hz, {recording.source} at {rate} Hz: "
                             "resample the signal to the recording's rate")
    whole: list[int] = []
    for j, (start, end) in enumerate(events):
        a, b = max(0, start - max_lag), min(recording.frames, start + length + max_lag + emitted)
        seg = recording.read(a, b)  # one event's frames: a streamed recording reads them from its files
        seg = seg - seg.mean(axis=1, keepdims=True)
        if emitted:
            seg = matched_filter(seg, options.signal, beta=1.0)  # the compressed pulses, sharpened
        after = np.maximum(np.arange(a, a + seg.shape[1]) - start, 0) / rate  # the direct sound weighs more than the tail
        if (not emitted and options.ambiguous < 1.0 and end - start >= options.whole_after * rate
                and ambiguity(seg * np.exp(-after / options.taper), max_lag, options.peaks) > options.ambiguous):
            b = min(recording.frames, start + max(length, min(end - start, int(options.max_window * rate))) + max_lag)
            seg = recording.read(a, b)
            seg = seg - seg.mean(axis=1, keepdims=True)
            after = np.zeros(seg.shape[1])  # no taper: every part of the sound weighs alike
            whole.append(j)
        longer = None  # a long event not analysed whole: its whole segment too, for its onsets' direct sound
        if (not emitted and options.emphasis > 0 and np.any(after) and end - start >= options.whole_after * rate):
            longer = recording.read(a, min(recording.frames, start + max(length, min(end - start, int(options.max_window
                                                                                                      * rate))) + max_lag))
            longer = longer - longer.mean(axis=1, keepdims=True)
        got = arrivals(j, seg, after, max_lag, longer)
        if got is None:
            ref[j] = int(np.argmax(np.sum(seg**2, axis=1)))
        else:
            r, t, support, ok = got[:4]
            needed = got[4] if len(got) > 4 else options.min_agreement
            ref[j] = r
            conf[:, j] = support
            keep = support >= options.min_support  # the reference too: its entry is measured like every other
            if support.sum() < needed * m * (m - 1):
                subset = consistent_subset(ok, options.min_support, options.subset_share)
                if options.min_subset and subset.sum() >= options.min_subset:
                    keep &= subset  # a consistent subset agrees: its channels' entries, the others missing
                    subsets.append(j)
                else:
                    keep[:] = False  # the channels agree on too few pairs: the whole event is unreliable
                    dropped.setdefault(needed, []).append(j)
            if keep.any() and not keep[r]:  # a subset, or pairs, without the reference: its best-supported channel refers
                ref[j] = int(np.argmax(np.where(keep, support, -1)))
            F[keep, j] = options.speed * (onsets[j] + t[keep] / rate)
        if progress is not None and (j + 1) % 10 == 0:
            progress(f"{label}: {j + 1}/{n} events")
    names = tuple(f"e{j + 1}" for j in range(n))
    notes = recording.notes
    if whole:
        notes += (f"{len(whole)} event(s) analysed whole without a taper, their pairs' correlations over "
                  f"{1000 * options.window:g} ms ambiguous (a periodic or narrow-band sound): "
                  f"{', '.join(names[j] for j in whole)}",)
    if subsets:
        notes += (f"{len(subsets)} event(s) kept on a consistent subset of their channels (each agreeing with "
                  f"{100 * options.subset_share:g} % of the others in it, {options.min_subset} or more), the other "
                  f"channels missing: {', '.join(names[j] for j in subsets)}",)
    for needed, events_dropped in sorted(dropped.items(), reverse=True):
        notes += (f"{len(events_dropped)} event(s) left missing, their channels agreeing on fewer than "
                  f"{100 * needed:g} % of the pairs: {', '.join(names[j] for j in events_dropped)}",)
    return TdoaMatrix(F, conf, ref, onsets, rate, options.speed, recording.channels, names, recording.source, notes)
