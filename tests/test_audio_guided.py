"""solvers.audio_guided: the geometry-guided second pass of `tdoa`. On a small synthetic recording (noise
bursts, one channel hearing a stronger 'reflection' after a weak direct sound) the first pass takes the
reflection; the guided pass, given the positions, measures the direct sound; its entries are measured
peaks, not the prediction, and a wrong guide is caught against the first pass; a source the positions do not give is located from the event's candidates;
and the verbs say what they did."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

soundfile = pytest.importorskip("soundfile")

from solvers.audio import TdoaOptions, tdoa_matrix  # noqa: E402
from solvers.recording import Recording  # noqa: E402
from solvers.audio_guided import (GuideOptions, guided_tdoa_matrix, locate_source, reconcile,  # noqa: E402
                                  tdoa_guided)
from solvers.cli import main  # noqa: E402

RATE, SPEED = 16_000, 343.0
OPTIONS = TdoaOptions(speed=SPEED, max_distance=6.0)


def delayed(signal: np.ndarray, delay: float) -> np.ndarray:
    """signal delayed by `delay` samples (fractional: a linear phase in the frequency domain, circular)."""
    f = np.fft.rfftfreq(len(signal))
    return np.fft.irfft(np.fft.rfft(signal) * np.exp(-2j * np.pi * f * delay), len(signal))


def room(seed: int = 4, m: int = 7, onsets=(0.3, 0.9), echo: int = 3):
    """(Recording, receivers (m, 3), sources (events, 3), true arrival delays (m, events) in samples): band-limited
    noise bursts from sources in a 4 m box, each channel hearing its direct sound; channel `echo` hears its
    direct sound at 0.1 and a 'reflection' 25 samples later at 0.8."""
    rng = np.random.default_rng(seed)
    receivers = rng.uniform(0.0, 4.0, (m, 3))
    sources = rng.uniform(0.5, 3.5, (len(onsets), 3))
    delays = np.linalg.norm(receivers[:, None] - sources[None], axis=2) / SPEED * RATE
    x = 1e-3 * rng.standard_normal((m, int(2.0 * RATE)))
    for j, onset in enumerate(onsets):
        spectrum = np.fft.rfft(rng.standard_normal(480))
        spectrum[len(spectrum) // 3:] = 0.0
        pad = np.zeros(4096)
        pad[1024:1504] = np.fft.irfft(spectrum, 480)
        start = int(onset * RATE)
        for i in range(m):
            heard = delayed(pad, delays[i, j]) * (0.1 if i == echo else 1.0)
            if i == echo:
                heard += 0.8 * delayed(pad, delays[i, j] + 25.0)
            x[i, start - 1024 : start + 3072] += heard
    return Recording(0.2 * x, RATE, tuple(f"m{i}" for i in range(m)), "synthetic"), receivers, sources, delays


def differences(tm, j: int) -> np.ndarray:
    """Event j's measured delays in samples relative to its reference channel."""
    return (tm.F[:, j] - tm.F[tm.reference[j], j]) / SPEED * RATE


def test_the_guided_pass_measures_the_direct_sound_the_first_pass_missed():
    rec, receivers, sources, delays = room()
    first = tdoa_matrix(rec, OPTIONS)
    guided = guided_tdoa_matrix(rec, receivers, sources, OPTIONS, sigma=1e-3)
    for j in range(2):
        r = first.reference[j]
        truth = delays[:, j] - delays[r, j]
        err_first = differences(first, j) - truth
        assert not abs(err_first[3]) <= 2.0  # the first pass took the reflection (or left it missing)
        assert guided.reference[j] == r
        assert np.max(np.abs(differences(guided, j) - truth)) < 0.3  # every entry, channel 3's direct sound too
    assert "guided pass (3D positions): 2 event(s) at their given source" in guided.notes[-1]
    known: dict = {}  # the first pass's first analyses, kept: the guided pass the same without computing them again
    assert np.array_equal(tdoa_matrix(rec, OPTIONS, keep=known).F, first.F, equal_nan=True) and sorted(known) == [0, 1]
    again = guided_tdoa_matrix(rec, receivers, sources, OPTIONS, sigma=1e-3, known=known)
    assert np.array_equal(again.F, guided.F, equal_nan=True)


def test_guided_entries_are_measured_peaks_and_a_wrong_guide_is_caught():
    """Sources 2 cm off (about 1 sample in the predicted differences, within the window): the entries stay at
    the true delays, not at the prediction. Sources 30 cm off: the right peaks lie outside the windows and
    the correlations' sidelobes inside them are measured instead (peaks, but wrong ones); reconcile sees
    that the guided pass contradicts the entries a calibration accepted (here: the first pass's entries
    within 2 samples of the truth) and every event keeps its first-pass column."""
    rec, receivers, sources, delays = room()
    first = tdoa_matrix(rec, OPTIONS)
    near_sources = sources + [0.02, -0.015, 0.01]
    near = guided_tdoa_matrix(rec, receivers, near_sources, OPTIONS, sigma=1e-3)
    predicted = np.linalg.norm(receivers[:, None] - near_sources[None], axis=2) / SPEED * RATE
    accepted = np.zeros(first.F.shape, bool)
    for j in range(2):
        r = near.reference[j]
        truth = delays[:, j] - delays[r, j]
        assert np.max(np.abs(differences(near, j) - truth)) < 0.3
        shifted = np.abs(predicted[:, j] - predicted[r, j] - truth) > 0.5  # the prediction half a sample or more off
        assert shifted.sum() >= 2 and np.all(np.abs(differences(near, j) - truth)[shifted] < 0.3)  # measured, not predicted
        accepted[:, j] = np.abs(differences(first, j) - (delays[:, j] - delays[first.reference[j], j])) <= 2.0
    assert reconcile(first, near, accepted, OPTIONS.tolerance) is near  # it agrees with every accepted entry
    far = guided_tdoa_matrix(rec, receivers, sources + [0.3, -0.3, 0.2], OPTIONS, sigma=1e-3)
    assert np.nanmax(np.abs(differences(far, 0) - (delays[:, 0] - delays[far.reference[0], 0]))) > 5.0
    kept = reconcile(first, far, accepted, OPTIONS.tolerance)
    assert np.array_equal(kept.F, first.F, equal_nan=True) and np.array_equal(kept.reference, first.reference)
    assert "2 event(s) keep the first pass's entries" in kept.notes[-1]


def test_an_event_without_a_position_is_located_from_its_candidates():
    rec, receivers, sources, delays = room()
    given = guided_tdoa_matrix(rec, receivers, sources, OPTIONS, sigma=1e-3)
    located = guided_tdoa_matrix(rec, receivers, np.vstack([sources[0], [np.nan] * 3]), OPTIONS, sigma=1e-3,
                                 guide=GuideOptions(locate_samples=500))
    assert np.allclose(located.F, given.F, equal_nan=True, atol=1e-9)
    assert "1 event(s) at their given source, 1 located" in located.notes[-1]
    # locate_source directly: the position to a few mm from exact candidates of every pair, none with 4 agreeing channels
    scale = RATE / SPEED
    i, k = np.triu_indices(7, 1)
    lags = (delays[i, 1] - delays[k, 1])[:, None] + np.array([0.0, 17.0, -31.0])[None, :]  # the truth and two others
    heights = np.tile([0.5, 0.6, 0.4], (len(i), 1))
    s, pairs, rms = locate_source(receivers * scale, i, k, lags, heights, references=[0, 1, 2], samples=500, seed=1)
    assert np.linalg.norm(s / scale - sources[1]) < 1e-6 and pairs.sum() == 7 * 6 and rms < 1e-6
    junk = (i >= 4) | (k >= 4)  # channels 4-6 agree with nothing: 4 channels cannot fix a position and a time
    lags[junk] = np.random.default_rng(0).uniform(-90, 90, (junk.sum(), 3))
    assert locate_source(receivers * scale, i, k, lags, heights, references=[0, 1, 2], samples=500, seed=1) is None


def test_an_event_outside_the_guiding_calibration_is_located_from_its_entries():
    """An event without a position but with first-pass entries is located from them (the linearised range
    differences, refined on its candidates): the same matrix as at its true source, no RANSAC; entries that fit
    no source (shuffled) fall back to the candidates' search. guide_events keeps the events with the most entries."""
    from solvers.audio_guided import guide_events, locate_from_entries
    from solvers.audio import _pair_candidates

    rec, receivers, sources, delays = room()
    first = tdoa_matrix(rec, OPTIONS)
    given = guided_tdoa_matrix(rec, receivers, sources, OPTIONS, sigma=1e-3)
    one = np.vstack([sources[0], [np.nan] * 3])
    entries = first.F.copy()
    entries[:, 0] = np.nan
    located = guided_tdoa_matrix(rec, receivers, one, OPTIONS, sigma=1e-3, entries=entries)
    assert np.allclose(located.F, given.F, equal_nan=True, atol=1e-9)
    assert "1 located (1 from their first-pass entries" in located.notes[-1]
    scale = RATE / SPEED
    seg = rec.samples[:, int(0.9 * RATE) - 400: int(0.9 * RATE) + 2000]
    i, k, lags, heights = _pair_candidates(seg, 120, 8)
    exact = delays[:, 1] + 17.0  # any constant
    s, pairs, rms = locate_from_entries(receivers * scale, exact, i, k, lags, heights, min_share=0.4)
    assert np.linalg.norm(s / scale - sources[1]) < 0.02 and pairs.sum() >= 0.6 * 7 * 6
    shuffled = exact[np.random.default_rng(2).permutation(7)]
    assert locate_from_entries(receivers * scale, shuffled, i, k, lags, heights, min_share=0.4) is None
    F = np.array([[1.0, np.nan, 1.0, 1.0], [1.0, 1.0, np.nan, 1.0], [np.nan, 1.0, np.nan, 1.0]])
    assert list(guide_events(replace(first, F=F), 2)) == [0, 3] and list(guide_events(replace(first, F=F), 9)) == [0, 1, 2, 3]


def test_tdoa_guided_says_why_it_did_not_guide(tmp_path, capsys):
    """Two events of seven microphones cannot be calibrated in 3D: the first pass's matrix is the answer,
    a note says why (tdoa and calibrate of a recording), and --no-guide skips the calibration."""
    rec, _, _, _ = room()
    run = tdoa_guided(rec, OPTIONS)
    assert not run.guided and run.first_calibration.status == "failed"
    assert np.array_equal(run.matrix.F, run.first.F, equal_nan=True)
    assert "no guided pass: the first pass's calibration cannot guide it, its status is 'failed'" in run.matrix.notes[-1]
    soundfile.write(str(tmp_path / "rec.wav"), rec.samples.T, RATE, subtype="PCM_24")
    assert main(["tdoa", str(tmp_path / "rec.wav"), "--max-distance", "6", "--out", str(tmp_path / "m.csv")]) == 0
    assert "no guided pass" in capsys.readouterr().err
    assert main(["tdoa", str(tmp_path / "rec.wav"), "--max-distance", "6", "--no-guide"]) == 0
    err = capsys.readouterr().err
    assert "guided" not in err and "2 events" in err
    assert main(["calibrate", str(tmp_path / "rec.wav"), "--dim", "3", "--max-distance", "6"]) == 1  # too few events
    assert "no guided pass" in capsys.readouterr().err  # calibrate reads a recording as tdoa does


def test_guide_options_are_checked():
    with pytest.raises(ValueError, match="window_sigmas"):
        GuideOptions(window_sigmas=-1.0)
    with pytest.raises(ValueError, match="peaks"):
        GuideOptions(peaks=0)


def test_the_guided_pass_keeps_the_columns_measured_against_an_estimated_sweep():
    """An event the first pass measured against its own estimated sweep (TdoaMatrix.swept) keeps its first-pass
    column in the guided matrix (a note names it); an event of it left missing whole takes the guided column."""
    from solvers.audio import TdoaMatrix
    from solvers.audio_guided import _keep_swept

    F1 = np.array([[1.0, np.nan, 3.0], [1.5, np.nan, 3.5], [2.0, np.nan, 4.0]])
    first = TdoaMatrix(F1, np.full((3, 3), 2.0), np.zeros(3, int), np.zeros(3), 16_000, 343.0, ("a", "b", "c"),
                       ("e1", "e2", "e3"), "synthetic", swept=(0, 1))
    guided = replace(first, F=np.nan_to_num(F1, nan=9.0) + 0.01, swept=())
    out = _keep_swept(first, guided)
    assert np.array_equal(out.F[:, 0], F1[:, 0])  # measured against the sweep: the first pass's
    assert np.allclose(out.F[:, 1], 9.01) and np.allclose(out.F[:, 2], F1[:, 2] + 0.01)  # missing / not swept: guided
    assert out.notes[-1].startswith("1 event(s) keep the first pass's entries, measured against their own estimated")
    assert _keep_swept(replace(first, swept=()), guided) is guided


def test_a_guide_that_fails_is_calibrated_again_without_the_least_supported_entries(monkeypatch):
    """When the first pass's calibration cannot guide, it runs once more without the entries only min_support other
    channels agree with (GuideOptions.retry_least_supported); the note says both statuses. Off: one calibration."""
    import solvers.audio_guided as guided_module
    import solvers.calibration as calibration

    rec, _, _, _ = room()
    first = tdoa_matrix(rec, OPTIONS)
    conf = first.confidence.copy()
    conf[[1, 4], 0] = OPTIONS.min_support  # two entries with the least support the first pass keeps
    crafted = replace(first, confidence=conf)
    monkeypatch.setattr(guided_module, "tdoa_matrix", lambda *a, **k: crafted)
    given = []
    real = calibration.calibrate
    monkeypatch.setattr(calibration, "calibrate", lambda F, *a, **k: given.append(np.array(F)) or real(F, *a, **k))
    run = tdoa_guided(rec, OPTIONS)
    assert not run.guided and len(given) == 2 and run.first_calibration.status == "failed"
    weak = np.isfinite(first.F) & (conf <= OPTIONS.min_support)
    assert weak.sum() == 2 and np.isnan(given[1][weak]).all()
    assert np.array_equal(given[1][~weak], first.F[~weak], equal_nan=True)
    assert "its status is 'failed'" in run.matrix.notes[-1]
    assert "; 'failed' without the 2 entries only 2 other channels agree with" in run.matrix.notes[-1]
    given.clear()
    tdoa_guided(rec, OPTIONS, guide=GuideOptions(retry_least_supported=False))
    assert len(given) == 1
