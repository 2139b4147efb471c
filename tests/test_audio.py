"""solvers.audio and `tdoa-workbench tdoa`: GCC-PHAT recovers a known sub-sample delay, the recording
reader reads what a test writes, events and their time differences come out of a synthetic recording,
and the verb's errors are one line with exit status 2."""
from __future__ import annotations

import numpy as np
import pytest

soundfile = pytest.importorskip("soundfile")

from solvers.audio import GccPeak, TdoaOptions, detect_events, gcc_phat, tdoa_matrix  # noqa: E402
from solvers.calibrate_io import read_input, read_measurements  # noqa: E402
from solvers.recording import RecordingError, is_recording, read_recording  # noqa: E402
from solvers.cli import main  # noqa: E402

RATE = 16_000


def delayed(signal: np.ndarray, delay: float) -> np.ndarray:
    """signal delayed by `delay` samples (fractional: a linear phase in the frequency domain, circular)."""
    n = len(signal)
    f = np.fft.rfftfreq(n)
    return np.fft.irfft(np.fft.rfft(signal) * np.exp(-2j * np.pi * f * delay), n)


def band_noise(rng: np.random.Generator, n: int) -> np.ndarray:
    """White noise low-passed at a third of the rate (a parabola fits the correlation peak well there)."""
    spectrum = np.fft.rfft(rng.standard_normal(n))
    spectrum[len(spectrum) // 3:] = 0.0
    return np.fft.irfft(spectrum, n)


@pytest.mark.parametrize("seed", range(4))
def test_gcc_phat_recovers_a_known_sub_sample_delay(seed):
    rng = np.random.default_rng(seed)
    y = band_noise(rng, 4096)
    delay = float(rng.integers(-40, 40)) + float(rng.uniform(0.35, 0.65))  # a whole sample is 0.35 or more off
    x = delayed(y, delay) + 0.05 * rng.standard_normal(4096)
    peak = gcc_phat(x, y, max_lag=100)
    assert isinstance(peak, GccPeak) and not peak.edge
    # PHAT whitens the spectrum: the peak is a full-band sinc, whose parabola is biased by up to 0.12
    # samples (noise adds a little)
    assert peak.lag == pytest.approx(delay, abs=0.25)
    assert peak.psr > 3


def test_gcc_phat_one_sided_range():
    rng = np.random.default_rng(7)
    y = band_noise(rng, 2048)
    x = delayed(y, -12.0) + 0.05 * rng.standard_normal(2048)
    both = gcc_phat(x, y, max_lag=50)
    assert both.lag == pytest.approx(-12.0, abs=0.1)
    early = gcc_phat(x, y, max_lag=50, min_lag=0)  # a negative delay cannot be found among lags >= 0
    assert early.lag >= 0 and early.height < 0.5 * both.height and early.psr < 0.5 * both.psr


def write_channels(path, samples, rate=RATE, subtype="PCM_24"):
    soundfile.write(str(path), samples.T, rate, subtype=subtype)


def test_reader_reads_a_multichannel_file_and_one_file_per_channel(tmp_path):
    rng = np.random.default_rng(1)
    x = 0.5 * rng.uniform(-1, 1, (3, 1000))
    write_channels(tmp_path / "rec.wav", x, subtype="PCM_16")
    rec = read_recording(str(tmp_path / "rec.wav"))
    assert rec.rate == RATE and rec.channels == ("1", "2", "3") and rec.samples.shape == (3, 1000)
    assert np.max(np.abs(rec.samples - x)) <= 1 / 2**15  # 16-bit quantisation
    assert is_recording(str(tmp_path / "rec.wav"))
    for k in range(3):
        write_channels(tmp_path / f"mic{k}.flac", x[k : k + 1, : 1000 - k], subtype="PCM_24")
    files = [str(tmp_path / f"mic{k}.flac") for k in range(3)]
    rec = read_recording(files)
    assert rec.channels == ("mic0", "mic1", "mic2") and rec.samples.shape == (3, 998)  # trimmed, and said so
    assert rec.notes and "trimmed" in rec.notes[0]
    assert np.max(np.abs(rec.samples - x[:, :998])) <= 1 / 2**23


def test_reader_errors_are_one_line(tmp_path):
    write_channels(tmp_path / "mono.wav", np.zeros((1, 100)))
    write_channels(tmp_path / "fast.wav", np.zeros((1, 100)), rate=48_000)
    (tmp_path / "text.wav").write_text("not audio\n")
    for paths, fragment in (([str(tmp_path / "none.wav")], "no such file"),
                            ([str(tmp_path / "mono.wav")], "one channel"),
                            ([str(tmp_path / "mono.wav"), str(tmp_path / "fast.wav")], "different sample rates"),
                            ([str(tmp_path / "text.wav")], "as audio")):
        with pytest.raises(RecordingError, match=fragment) as info:
            read_recording(paths)
        assert "\n" not in str(info.value)


def synthetic_recording(rng, delays, onsets, length=0.03, noise=1e-3, total=2.0):
    """(channels, frames): at each onset (s) a noise burst of `length` s, channel i hearing it `delays[i, j]`
    samples late (no reverberation), plus white noise."""
    m = delays.shape[0]
    x = noise * rng.standard_normal((m, int(total * RATE)))
    for j, onset in enumerate(onsets):
        burst = band_noise(rng, int(length * RATE))
        start = int(onset * RATE)
        pad = np.zeros(2048)  # the burst in its middle: the circular shift's wrap-around stays negligible
        pad[512 : 512 + len(burst)] = burst
        for i in range(m):
            x[i, start - 512 : start + 1536] += delayed(pad, delays[i, j])
    return x


def test_events_and_time_differences_of_a_synthetic_recording():
    rng = np.random.default_rng(3)
    m, onsets = 5, [0.3, 0.9, 1.5]
    delays = rng.uniform(0.0, 60.0, (m, len(onsets)))
    x = synthetic_recording(rng, delays, onsets)
    events = detect_events(x, RATE)
    assert len(events) == 3 and np.allclose(events[:, 0] / RATE, onsets, atol=0.01)
    from solvers.recording import Recording

    tm = tdoa_matrix(Recording(x, RATE, tuple("abcde"), "synthetic"), TdoaOptions(max_distance=2.0))
    assert tm.F.shape == (m, 3) and np.all(np.isfinite(tm.F))
    assert np.all(tm.confidence >= m - 1)  # every other channel agrees with every arrival
    for j in range(3):
        r = tm.reference[j]
        measured = (tm.F[:, j] - tm.F[r, j]) / tm.speed * RATE
        assert np.max(np.abs(measured - (delays[:, j] - delays[r, j]))) < 0.25  # samples (parabola bias <= 0.12)


def test_an_event_that_agrees_poorly_is_analysed_again_with_the_retry_tapers():
    """Arrivals spread over 19 ms and a taper of 1 ms: the weight leaves the late channels' sound out, the
    channels agree on too few pairs and the events are left missing; with a 50 ms taper to retry, the
    agreement picks it and every time difference comes out within half a sample."""
    from solvers.recording import Recording

    rng = np.random.default_rng(1)
    delays = rng.uniform(0.0, 300.0, (6, 2))
    rec = Recording(synthetic_recording(rng, delays, [0.3, 0.9], noise=3e-2), RATE, tuple("abcdef"), "synthetic")
    # onsets where the power crosses the threshold (onset_db = threshold_db, the detection before onsets were
    # moved back): the taper's knee then lies within the burst. (Moved back before the burst, an exponential
    # weight only scales each channel's delayed burst, exp(-(t - d) / taper) = exp(d / taper) exp(-t / taper),
    # and even 1 ms finds the delays)
    # (emphasis 0: the onsets' direct sound, analysed without a taper, finds these delays by itself)
    late = dict(max_distance=8.0, taper=0.001, retry_weights=(), onset_db=5.0, ambiguous=1.0, emphasis=0.0)
    alone = tdoa_matrix(rec, TdoaOptions(retry_tapers=(), **late))
    assert np.isnan(alone.F).any()
    tm = tdoa_matrix(rec, TdoaOptions(retry_tapers=(0.05,), **late))
    assert np.all(np.isfinite(tm.F)) and np.all(tm.confidence >= 5)
    for j in range(2):
        r = tm.reference[j]
        measured = (tm.F[:, j] - tm.F[r, j]) / tm.speed * RATE
        assert np.max(np.abs(measured - (delays[:, j] - delays[r, j]))) < 0.5


def test_tdoa_verb_writes_the_matrix_calibrate_reads(tmp_path, capsys):
    rng = np.random.default_rng(5)
    delays = rng.uniform(0.0, 40.0, (4, 2))
    write_channels(tmp_path / "rec.wav", 0.3 * synthetic_recording(rng, delays, [0.4, 1.2]))
    out = tmp_path / "m.csv"
    assert main(["tdoa", str(tmp_path / "rec.wav"), "--out", str(out), "--max-distance", "2"]) == 0
    assert "2 events" in capsys.readouterr().err  # progress and summary on stderr
    meas = read_measurements(str(out))
    assert meas.F.shape == (4, 2) and meas.receivers == ("1", "2", "3", "4") and meas.transmitters == ("e1", "e2")
    again = read_input([str(tmp_path / "rec.wav")], tdoa_options=TdoaOptions(max_distance=2.0))
    assert np.allclose(again.F, meas.F, rtol=1e-8)  # calibrate's reader gives the same matrix


@pytest.mark.parametrize("argv, fragment", [
    (["tdoa", "{tmp}/none.wav"], "none.wav: no such file"),
    (["calibrate", "{tmp}/none.wav", "{tmp}/rec.wav"], "is not a recording"),
    (["tdoa", "{tmp}/rec.wav", "--out", "{tmp}/no/such/dir/m.csv"], "no directory"),
    (["tdoa", "{tmp}/rec.wav", "--speed", "0"], "must be a finite number > 0"),
    (["tdoa", "{tmp}/silence.wav"], "no sound event found"),
])
def test_verb_errors_are_one_line_with_exit_status_2(tmp_path, capsys, argv, fragment):
    write_channels(tmp_path / "rec.wav", 0.01 * np.random.default_rng(0).standard_normal((3, 4000)))
    write_channels(tmp_path / "silence.wav", np.zeros((3, 4000)))
    try:
        code = main([a.replace("{tmp}", str(tmp_path)) for a in argv])
    except SystemExit as e:  # argparse's own errors
        code = e.code
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    last = err.strip().splitlines()[-1]  # (argparse's own errors print the usage first)
    assert last.startswith("tdoa-workbench ") and ": error: " in last and fragment in last


def test_consensus_prefers_the_direct_sound_over_a_stronger_reflection():
    """Pair candidates of 6 channels: every pair peaks at the difference of the direct sounds, and the
    pairs of channel 3 peak higher where its reflection (40 samples later) meets the others' direct
    sound; a random extra peak per pair. The consensus takes channel 3's direct sound, all channels
    agree with every arrival, and the times are relative to the reference."""
    from solvers.audio import _consensus

    rng = np.random.default_rng(2)
    m, ref = 6, 1
    t = rng.uniform(-50, 50, m)
    i, k = np.triu_indices(m, 1)
    direct = t[i] - t[k]
    reflected = np.where(i == 3, t[i] + 40 - t[k], np.where(k == 3, t[i] - t[k] - 40, rng.uniform(-90, 90, len(i))))
    lags = np.column_stack([reflected, direct, rng.uniform(-90, 90, len(i))])
    heights = np.column_stack([np.where((i == 3) | (k == 3), 0.5, 0.2), np.full(len(i), 0.3), np.full(len(i), 0.1)])
    times, support = _consensus(m, ref, i, k, lags, heights, tol=1.0)
    assert np.allclose(times, t - t[ref], atol=1e-9) and np.all(support == m - 1)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [3, 8])
def test_a_committed_room_of_tables_audio3d_is_recomputed(seed):
    """Rooms 3 (the shortest, about 5 s) and 8 (rejections 1-3 critical values out at a node keeping an
    entry of small redundancy number: "ok" after the absorbed-error probe refutes an absorbed error) of
    tables/audio3d.csv from the script's own run(): every column equal as the CSV writes it."""
    pytest.importorskip("pyroomacoustics")
    import csv
    import importlib.util
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location("audio_room", root / "scripts" / "audio_room.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    with open(root / "tables" / "audio3d.csv", newline="") as handle:
        committed = next(r for r in csv.DictReader(handle) if r["seed"] == str(seed))
    row = script.run(seed, (8, 16), (10, 30), (0.2, 0.6), 20.0)
    assert {k: str(v) for k, v in row.items()} == committed


# --------------------------------------------------------------------------------------------------
# One reader per input kind: clipped, 8-bit, mono, empty, NaN; streamed as read whole
# --------------------------------------------------------------------------------------------------


def test_clipping_is_a_warning_with_the_share_of_clipped_samples_per_channel(tmp_path):
    rng = np.random.default_rng(4)
    x = 0.3 * rng.uniform(-1, 1, (3, 10_000))
    x[1, 1000:1100] = 1.0  # 100 samples at positive full scale
    x[1, 5000:5050] = -1.0  # and 50 at negative
    x[2, 7000:7010] = 1.0
    write_channels(tmp_path / "clip.wav", x, subtype="PCM_16")
    rec = read_recording(str(tmp_path / "clip.wav"))
    [note] = [n for n in rec.notes if "clipping" in n]
    assert note.startswith("warning: clipping") and "\n" not in note
    listed = note.split("the share per channel: ")[1].split(";")[0]
    assert listed == "2 1.5 %, 3 0.1 %" and "the other channels none" in note  # 150 / 10000, 10 / 10000
    for subtype in ("PCM_24", "FLOAT"):  # every format's full scale
        write_channels(tmp_path / f"clip_{subtype}.wav", x, subtype=subtype)
        again = read_recording(str(tmp_path / f"clip_{subtype}.wav"))
        assert any("2 1.5 %" in n for n in again.notes), subtype
    write_channels(tmp_path / "clean.wav", x * 0.5, subtype="PCM_16")
    assert not any("clipping" in n for n in read_recording(str(tmp_path / "clean.wav")).notes)


def test_8_bit_samples_are_a_note(tmp_path):
    x = 0.5 * np.random.default_rng(5).uniform(-1, 1, (2, 4000))
    write_channels(tmp_path / "u8.wav", x, subtype="PCM_U8")
    rec = read_recording(str(tmp_path / "u8.wav"))
    assert any(n.startswith("8-bit samples") and "48 dB" in n for n in rec.notes)
    write_channels(tmp_path / "s16.wav", x, subtype="PCM_16")
    assert not any("8-bit" in n for n in read_recording(str(tmp_path / "s16.wav")).notes)


def test_nan_and_empty_inputs_are_one_line_errors(tmp_path):
    x = 0.1 * np.random.default_rng(6).standard_normal((3, 4000))
    x[2, 1600] = np.nan
    x[2, 1700] = np.inf
    write_channels(tmp_path / "nan.wav", x, subtype="FLOAT")
    with pytest.raises(RecordingError, match=r"nan\.wav: 2 samples are NaN or infinite \(channel\(s\) 3; the first at "
                       r"0\.100 s\)") as info:
        read_recording(str(tmp_path / "nan.wav"))
    assert "\n" not in str(info.value)
    (tmp_path / "empty.wav").write_bytes(b"")
    with pytest.raises(RecordingError, match=r"empty\.wav: no data \(empty file\)$"):
        read_recording(str(tmp_path / "empty.wav"))
    write_channels(tmp_path / "header_only.wav", np.zeros((2, 0)))
    with pytest.raises(RecordingError, match=r"header_only\.wav: no data \(no samples\)$"):
        read_recording(str(tmp_path / "header_only.wav"))


def _last_error(capsys, argv) -> tuple[int, str]:
    try:
        code = main(argv)
    except SystemExit as e:
        code = e.code
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err.strip().splitlines()[-1]


def test_the_verbs_say_the_same_words_for_empty_mono_and_nan_input(tmp_path, capsys):
    (tmp_path / "empty.wav").write_bytes(b"")
    write_channels(tmp_path / "mono.wav", 0.1 * np.ones((1, 4000)))
    x = 0.1 * np.random.default_rng(7).standard_normal((3, 4000))
    x[0, 10] = np.nan
    write_channels(tmp_path / "nan.wav", x, subtype="FLOAT")
    for name, fragment in (("empty.wav", "empty.wav: no data (empty file)"), ("mono.wav", "one channel"),
                           ("nan.wav", "samples are NaN or infinite")):
        said = []
        for verb in ("tdoa", "calibrate"):
            code, last = _last_error(capsys, [verb, str(tmp_path / name)])
            assert code == 2 and last.startswith("tdoa-workbench ") and ": error: " in last
            assert fragment in last, (verb, last)
            said.append(last.split(": error: ")[1])
        assert said[0] == said[1], said  # one reader, the same words


def test_verbs_warn_of_clipping_on_stderr(tmp_path, capsys):
    rng = np.random.default_rng(8)
    delays = rng.uniform(0.0, 40.0, (4, 2))
    x = 0.3 * synthetic_recording(rng, delays, [0.4, 1.2])
    x[0] = np.clip(8 * x[0], -1, 1)  # channel 1 driven into clipping
    write_channels(tmp_path / "rec.wav", x, subtype="PCM_16")
    assert main(["tdoa", str(tmp_path / "rec.wav"), "--out", str(tmp_path / "m.csv"), "--max-distance", "2",
                 "--no-guide"]) == 0
    err = capsys.readouterr().err
    said = [line for line in err.splitlines() if "warning: clipping" in line]
    assert len(said) == 1, err
    line = said[0]
    assert line.startswith("tdoa: warning: clipping: samples at full scale, the share per channel: 1 ")
    assert "the other channels none" in line


def test_a_streamed_recording_gives_the_matrix_of_one_read_whole(tmp_path):
    rng = np.random.default_rng(9)
    delays = rng.uniform(0.0, 40.0, (4, 3))
    x = 0.3 * synthetic_recording(rng, delays, [0.3, 0.9, 1.5])
    write_channels(tmp_path / "rec.wav", x)
    for k in range(4):
        write_channels(tmp_path / f"mic{k}.flac", x[k : k + 1])
    options = TdoaOptions(max_distance=2.0)
    for paths in (str(tmp_path / "rec.wav"), [str(tmp_path / f"mic{k}.flac") for k in range(4)]):
        whole = read_recording(paths, stream=False)
        assert whole.samples is not None
        streamed = read_recording(paths, stream=True)
        assert streamed.samples is None and streamed.frames == x.shape[1]
        assert np.array_equal(streamed.read(100, 5000), whole.read(100, 5000))
        a, b = tdoa_matrix(whole, options), tdoa_matrix(streamed, options)
        assert np.array_equal(a.F, b.F, equal_nan=True) and np.array_equal(a.confidence, b.confidence)


def _sweep(seconds: float, rate: int = RATE) -> np.ndarray:
    from scipy.signal import chirp

    t = np.arange(int(seconds * rate)) / rate
    return chirp(t, f0=100.0, t1=t[-1], f1=0.4 * rate, method="logarithmic") * np.hanning(len(t)) ** 0.25


def test_a_sweep_with_its_signal_given_is_compressed_into_its_arrivals(tmp_path, capsys):
    """Half-second log sweeps with an echo of 0.8 x their level 2-6 ms later at every channel: with the emitted
    sweep given (a matched filter) every time difference is within half a sample; the CLI reads --signal and
    refuses a signal at another rate or with two channels in one line."""
    rng = np.random.default_rng(11)
    m, onsets, sweep = 6, [0.3, 1.3], _sweep(0.5)
    delays = rng.uniform(0.0, 60.0, (m, 2))
    x = 1e-3 * rng.standard_normal((m, int(2.2 * RATE)))
    for j, onset in enumerate(onsets):
        pad = np.zeros(len(sweep) + 2048)
        pad[512 : 512 + len(sweep)] = sweep
        start = int(onset * RATE) - 512
        for i in range(m):
            echo = delays[i, j] + rng.uniform(32, 96)
            x[i, start : start + len(pad)] += delayed(pad, delays[i, j]) + 0.8 * delayed(pad, echo)
    from solvers.recording import Recording

    options = TdoaOptions(max_distance=2.0, signal=sweep)
    tm = tdoa_matrix(Recording(0.2 * x, RATE, tuple("abcdef"), "synthetic"), options)
    assert tm.F.shape == (m, 2) and np.all(np.isfinite(tm.F))
    for j in range(2):
        r = tm.reference[j]
        measured = (tm.F[:, j] - tm.F[r, j]) / tm.speed * RATE
        assert np.max(np.abs(measured - (delays[:, j] - delays[r, j]))) < 0.5
    write_channels(tmp_path / "rec.wav", 0.2 * x)
    soundfile.write(str(tmp_path / "sweep.wav"), sweep, RATE, subtype="FLOAT")
    soundfile.write(str(tmp_path / "sweep48.wav"), sweep, 48_000, subtype="FLOAT")
    soundfile.write(str(tmp_path / "stereo.wav"), np.column_stack([sweep, sweep]), RATE, subtype="FLOAT")
    assert main(["tdoa", str(tmp_path / "rec.wav"), "--signal", str(tmp_path / "sweep.wav"), "--max-distance", "2",
                 "--no-guide", "--out", str(tmp_path / "m.csv")]) == 0
    assert np.allclose(read_measurements(str(tmp_path / "m.csv")).F, tm.F, atol=1e-3)  # 24-bit file, CSV digits
    capsys.readouterr()
    for signal, fragment in (("sweep48.wav", "the emitted signal is at 48000 Hz"), ("stereo.wav", "2 channels"),
                             ("none.wav", "no such file")):
        for verb in ("tdoa", "calibrate"):
            code, last = _last_error(capsys, [verb, str(tmp_path / "rec.wav"), "--signal", str(tmp_path / signal),
                                              "--max-distance", "2"])
            assert code == 2 and fragment in last, (verb, last)


def test_with_the_signal_each_channel_is_its_own_direct_pulse_even_under_a_louder_echo():
    """Half-second log sweeps whose echo, 2-6 ms after the direct sound, is 1.5 x its level at every channel and
    a 24 ms one at 1.2 x: with the emitted sweep given, every channel's arrival is its direct pulse (the earliest
    of at least signal_share of its highest), within half a sample; a channel of noise alone is left missing; the
    guided pass is not run (a note says why)."""
    from solvers.audio_guided import tdoa_guided
    from solvers.recording import Recording

    rng = np.random.default_rng(5)
    m, onsets, sweep = 6, [0.3, 1.3], _sweep(0.5)
    delays = rng.uniform(0.0, 60.0, (m, 2))
    x = 1e-3 * rng.standard_normal((m, int(2.2 * RATE)))
    for j, onset in enumerate(onsets):
        pad = np.zeros(len(sweep) + 2048)
        pad[512 : 512 + len(sweep)] = sweep
        start = int(onset * RATE) - 512
        for i in range(m - 1):  # the last channel hears nothing but its noise
            x[i, start : start + len(pad)] += (delayed(pad, delays[i, j]) + 1.5 * delayed(pad, delays[i, j] + rng.uniform(32, 96))
                                               + 1.2 * delayed(pad, delays[i, j] + 384))
    options = TdoaOptions(max_distance=2.0, signal=sweep)
    recording = Recording(0.2 * x, RATE, tuple("abcdef"), "synthetic")
    tm = tdoa_matrix(recording, options)
    assert np.all(np.isfinite(tm.F[: m - 1])) and not np.isfinite(tm.F[m - 1]).any()
    for j in range(2):
        r = tm.reference[j]
        measured = (tm.F[: m - 1, j] - tm.F[r, j]) / tm.speed * RATE
        assert np.max(np.abs(measured - (delays[: m - 1, j] - delays[r, j]))) < 0.5
        assert np.all(tm.confidence[: m - 1, j] == m - 2) and tm.confidence[m - 1, j] == 0
    run = tdoa_guided(recording, options)
    assert not run.guided and run.first_calibration is None and np.array_equal(run.matrix.F, tm.F, equal_nan=True)
    assert "measured against the emitted signal" in run.matrix.notes[-1]


def _echoed(rng, sound, delays, onsets, total, echo=0.8):
    """(channels, frames): `sound` at each onset, channel i hearing it delays[i, j] samples late plus an echo of
    `echo` x its level 2-6 ms after that and one of 0.6 x 24 ms after, over white noise 1e-3."""
    m = delays.shape[0]
    x = 1e-3 * rng.standard_normal((m, int(total * RATE)))
    for j, onset in enumerate(onsets):
        pad = np.zeros(len(sound) + 2048)
        pad[512 : 512 + len(sound)] = sound
        start = int(onset * RATE) - 512
        for i in range(m):
            x[i, start : start + len(pad)] += (delayed(pad, delays[i, j]) + echo * delayed(pad, delays[i, j] + rng.uniform(32, 96))
                                               + 0.6 * delayed(pad, delays[i, j] + 384))
    return 0.2 * x


@pytest.mark.parametrize("method", ["linear", "logarithmic"])
def test_a_sweep_analysed_whole_is_measured_against_its_own_estimate(method):
    """0.8 s sweeps (linear and logarithmic, 100 Hz - 6.4 kHz) under two echoes, the signal not given: the event
    analysed whole is measured against the sweep estimated from its loudest channel (a note names the events), every
    time difference within half a sample; with sweep_gain 0 (no estimate) the same events go to the pairs'
    correlations and the note is absent."""
    from scipy.signal import chirp

    from solvers.recording import Recording

    rng = np.random.default_rng(21)
    t = np.arange(int(0.8 * RATE)) / RATE
    sweep = chirp(t, f0=100.0, t1=t[-1], f1=0.4 * RATE, method=method) * np.hanning(len(t)) ** 0.25
    m, onsets = 7, [0.3, 1.6]
    delays = rng.uniform(0.0, 60.0, (m, 2))
    recording = Recording(_echoed(rng, sweep, delays, onsets, 2.9), RATE, tuple("abcdefg"), "synthetic")
    options = TdoaOptions(max_distance=2.0, ambiguous=0.01, whole_after=0.0)
    tm = tdoa_matrix(recording, options)
    assert any(n.startswith("2 event(s) measured against their own estimated sweep") for n in tm.notes)
    assert np.all(np.isfinite(tm.F))
    for j in range(2):
        r = tm.reference[j]
        measured = (tm.F[:, j] - tm.F[r, j]) / tm.speed * RATE
        assert np.max(np.abs(measured - (delays[:, j] - delays[r, j]))) < 0.5
    plain = tdoa_matrix(recording, TdoaOptions(max_distance=2.0, ambiguous=0.01, whole_after=0.0, sweep_gain=0.0))
    assert not any("estimated sweep" in n for n in plain.notes)


def test_notes_and_noise_are_no_sweep():
    """estimate_sweep finds no sweep in a three-note phrase (each note a harmonic tone, the notes on a rising line),
    nor in noise; it finds the linear sweep, its gain far above sweep_gain."""
    from solvers.audio import estimate_sweep
    from scipy.signal import chirp

    rng = np.random.default_rng(2)
    notes = []
    for f0 in (262.0, 440.0, 784.0):
        t = np.arange(int(0.27 * RATE)) / RATE
        notes.append(sum(np.sin(2 * np.pi * h * f0 * t) / h for h in range(1, 9) if h * f0 < 0.45 * RATE)
                     * np.minimum(t / 0.01, 1.0) * np.exp(-t / 0.15))
    phrase = np.concatenate([np.zeros(800), *notes, np.zeros(800)]) + 1e-3 * rng.standard_normal(1)
    assert estimate_sweep(phrase, RATE, phrase[None, :]) is None
    noise = rng.standard_normal(RATE)
    assert estimate_sweep(noise, RATE, noise[None, :]) is None
    t = np.arange(int(0.8 * RATE)) / RATE
    sweep = np.concatenate([np.zeros(800), chirp(t, f0=100.0, t1=t[-1], f1=6400.0), np.zeros(800)])
    got = estimate_sweep(sweep, RATE, sweep[None, :])
    assert got is not None and got[1] > 4 * TdoaOptions().sweep_gain


def test_a_subset_without_the_reference_refers_to_one_of_its_channels():
    """An event kept on a consistent subset that leaves out the channel the analysis referred to: the event's
    reference is a channel of the subset (its kept entries' differences are measured against it)."""
    from solvers.audio import _measure
    from solvers.recording import Recording

    rng = np.random.default_rng(4)
    m = 8
    recording = Recording(synthetic_recording(rng, np.zeros((m, 1)), [0.5]), RATE, tuple("abcdefgh"), "synthetic")
    ok = np.zeros((m, m), bool)
    ok[1:6, 1:6] = True  # channels 1-5 agree; the reference 0 with none
    np.fill_diagonal(ok, False)
    t = np.arange(m, dtype=float)
    tm = _measure(recording, TdoaOptions(max_distance=2.0), lambda j, seg, after, lag, whole: (0, t, ok.sum(axis=1), ok))
    assert np.isfinite(tm.F[1:6, 0]).all() and not np.isfinite(tm.F[[0, 6, 7], 0]).any()
    assert tm.reference[0] in range(1, 6)
    assert any("consistent subset" in n for n in tm.notes)



def test_a_reference_with_fewer_than_min_support_agreeing_pairs_is_left_missing():
    """The reference's entry is measured like every other: with one agreeing pair (the 48 kHz 0.8 s speech room of
    tables/audio3d_kinds, whose guided pass kept a reference 10 samples off that way) it is left missing, and the
    best-supported kept channel refers; the other entries, agreeing with each other, are kept."""
    from solvers.audio import _measure
    from solvers.recording import Recording

    rng = np.random.default_rng(4)
    m = 8
    recording = Recording(synthetic_recording(rng, np.zeros((m, 1)), [0.5]), RATE, tuple("abcdefgh"), "synthetic")
    ok = np.zeros((m, m), bool)
    ok[1:, 1:] = True  # channels 1-7 agree with each other
    ok[0, 1] = ok[1, 0] = True  # the reference 0 with one channel only
    np.fill_diagonal(ok, False)
    t = np.arange(m, dtype=float)
    options = TdoaOptions(max_distance=2.0)
    assert options.min_support == 2
    tm = _measure(recording, options, lambda j, seg, after, lag, whole: (0, t, ok.sum(axis=1), ok))
    assert not np.isfinite(tm.F[0, 0]) and np.isfinite(tm.F[1:, 0]).all()
    assert tm.reference[0] == 1  # the most agreeing pairs (7), the first on a tie
    assert np.allclose(np.diff(tm.F[1:, 0]), options.speed / RATE)  # the kept entries' differences unchanged

def test_consistent_subset_peels_the_channels_that_disagree():
    from solvers.audio import consistent_subset

    ok = np.zeros((8, 8), bool)
    ok[:5, :5] = True  # channels 0-4 agree with each other
    ok[5, 0] = ok[0, 5] = ok[6, 1] = ok[1, 6] = ok[5, 7] = ok[7, 5] = True  # the others agree by chance, with one or two
    np.fill_diagonal(ok, False)
    assert consistent_subset(ok, 2, 0.8).tolist() == [True] * 5 + [False] * 3
    assert not consistent_subset(np.zeros((4, 4), bool), 2, 0.8).any()
    noisy = ok.copy()
    noisy[0, 3] = noisy[3, 0] = False  # one pair of the five disagrees: each still agrees with 3 of 4 >= 0.75
    assert consistent_subset(noisy, 2, 0.75).tolist() == [True] * 5 + [False] * 3




def test_an_ambiguous_event_is_analysed_whole():
    """Noise heard 7 samples apart has one correlation peak (ambiguity small; the rooms' periodic sounds measure
    0.89-0.96, scripts/audio_kinds.py). An event judged ambiguous (here every event: ambiguous = 0.01) is
    analysed whole, untapered, and says so; its delays hold."""
    from solvers.audio import ambiguity
    from solvers.recording import Recording

    rng = np.random.default_rng(14)
    noise = band_noise(rng, 4000)
    heard = np.vstack([noise, delayed(noise, 7.0)]) + 0.05 * rng.standard_normal((2, 4000))  # every band: some noise
    assert ambiguity(heard, 60, 8) < 0.6
    delays = rng.uniform(0.0, 40.0, (5, 2))
    rec = Recording(synthetic_recording(rng, delays, [0.4, 1.2]), RATE, tuple("abcde"), "synthetic")
    assert not any("analysed whole" in n for n in tdoa_matrix(rec, TdoaOptions(max_distance=2.0, ambiguous=1.0)).notes)
    tm = tdoa_matrix(rec, TdoaOptions(max_distance=2.0, ambiguous=0.01, whole_after=0.0))  # (the bursts are short)
    assert any(n.startswith("2 event(s) analysed whole") for n in tm.notes) and np.all(np.isfinite(tm.F))
    for j in range(2):
        r = tm.reference[j]
        measured = (tm.F[:, j] - tm.F[r, j]) / tm.speed * RATE
        assert np.max(np.abs(measured - (delays[:, j] - delays[r, j]))) < 0.5


@pytest.mark.slow
def test_a_committed_room_of_tables_audio3d_kinds_is_recomputed():
    """The linear sweeps with their signal given, 16 kHz, RT60 0.3 s, 30 dB (a short room) of
    tables/audio3d_kinds.csv from the script's own run(): every column equal as the CSV writes it."""
    pytest.importorskip("pyroomacoustics")
    import csv
    import importlib.util
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location("audio_kinds", root / "scripts" / "audio_kinds.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    with open(root / "tables" / "audio3d_kinds.csv", newline="") as handle:
        committed = next(r for r in csv.DictReader(handle) if r["kind"] == "lin_sweep+signal" and r["rate"] == "16000"
                         and r["rt60_s"] == "0.3")
    row = script.run("lin_sweep", 0, 10, 20, given=True)
    assert {k: str(v) for k, v in row.items()} == committed


def test_the_fft_length_is_scipys_next_fast_len():
    """solvers.audio picks FFT lengths without importing scipy (the CLI's start-up): the same lengths."""
    from scipy.fft import next_fast_len

    from solvers.audio import _fast_length

    rng = np.random.default_rng(0)
    sizes = list(range(1, 3000)) + [int(v) for v in rng.integers(3000, 10**7, 500)]
    assert [_fast_length(n) for n in sizes] == [next_fast_len(n) for n in sizes]


def test_onset_windows_start_at_each_syllable():
    """Three 150 ms noise bursts 100 ms apart, over a tail 20 dB down: one window per burst, each 1 over the lag range
    before its onset and exp(-t / taper) after it; onset_rise 0 is refused below 0 and turns the stage off."""
    from solvers.audio import onset_windows

    rng = np.random.default_rng(8)
    lag, n = 40, int(0.8 * RATE)
    x = 0.1 * rng.standard_normal((3, n + lag))
    starts = [0, int(0.25 * RATE), int(0.5 * RATE)]
    for s in starts:
        x[:, lag + s : lag + s + int(0.15 * RATE)] += rng.standard_normal((3, int(0.15 * RATE)))
    w = onset_windows(x, RATE, lag, TdoaOptions())
    assert w.shape == (3, n + lag)
    first = np.array([int(np.argmax(row > 0)) for row in w])  # each window's first sample: its onset - lag
    assert np.allclose(first, starts, atol=0.01 * RATE)
    for row, f in zip(w, first):
        assert np.all(row[f : f + lag] == 1.0) and np.all(np.diff(row[f + lag + 2 :]) <= 0)
    with pytest.raises(ValueError, match="onset_rise"):
        TdoaOptions(onset_rise=-1.0)


def _phrase_in_a_reverberant_room(seed: int, m: int = 6, tail_db: float = 8.0, rt60: float = 0.5):
    """(recording (m, 2 s at RATE), delays in samples): three harmonic notes (8 harmonics, 1/h, a 10 ms attack, as
    scripts/audio_kinds.py's phrases) through room responses of a direct sound at each channel's delay (a windowed
    sinc) and an exponentially decaying diffuse tail from 2 ms after it, `tail_db` above the direct sound (beyond the
    critical distance); white noise 30 dB below."""
    rng = np.random.default_rng(seed)
    notes = []
    for f0 in (262.0, 330.0, 392.0):
        t = np.arange(int(0.25 * RATE)) / RATE
        tone = sum(np.sin(2 * np.pi * h * f0 * t + rng.uniform(0, 2 * np.pi)) / h for h in range(1, 9))
        notes.append(tone * np.minimum(t / 0.01, 1.0) * np.exp(-t / 0.15))
    phrase = np.concatenate(notes)
    delays = rng.uniform(0.0, 120.0, m)
    n, start = RATE, int(0.3 * RATE)
    t = np.arange(n) / RATE
    out = np.zeros((m, 2 * RATE))
    k = np.arange(-20, 21)
    for i, d in enumerate(delays):
        h = np.zeros(n)
        h[int(np.floor(d)) + k + 40] += np.sinc(k - (d - np.floor(d))) * np.hanning(43)[1:-1]
        tail = rng.standard_normal(n) * np.exp(-6.9 * t / rt60) * (t > (d + 40) / RATE + 0.002)
        h += tail * 10 ** (tail_db / 20) / np.sqrt(np.sum(tail**2))
        size = len(phrase) + n
        y = np.fft.irfft(np.fft.rfft(phrase, size) * np.fft.rfft(h, size), size)[: out.shape[1] - start]
        out[i, start : start + len(y)] = y
    return out + 0.03 * np.std(out) * rng.standard_normal(out.shape), delays


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_phrase_beyond_the_critical_distance_is_measured_on_its_onsets_direct_sound(seed):
    """A tone's steady state in a room carries the ratio of two room responses at its harmonics, not the direct
    sound's delay: with a diffuse tail 8 dB above the direct sound the pairs' correlations agree on lags whole periods
    off (emphasis 0); weighted by onset_emphasis (only the new power of each frequency: the direct sound of each note's
    attack) every difference is within half a sample."""
    from solvers.recording import Recording

    x, delays = _phrase_in_a_reverberant_room(seed)
    rec = Recording(x, RATE, tuple("abcdef"), "synthetic")
    errors = {}
    for emphasis in (0.0, 2.0):
        tm = tdoa_matrix(rec, TdoaOptions(max_distance=5.0, emphasis=emphasis))
        assert len(tm.events) == 1
        r = tm.reference[0]
        errors[emphasis] = (tm.F[:, 0] - tm.F[r, 0]) / tm.speed * RATE - (delays - delays[r])
    assert np.nanmax(np.abs(errors[0.0])) > 20  # whole periods off (or missing) without the emphasis
    assert np.all(np.abs(errors[2.0]) < 0.5)
    assert any("onsets' direct sound" in note for note in tm.notes)


def test_onset_emphasis_keeps_what_is_new_and_drops_a_steady_state():
    """A tone that has sounded for 0.1 s weighs nothing once its frames hold only it (its power is not new: 1e-8 of
    it measured); the tone's start and a burst that starts later come through (a rising frame's power is partly new:
    about a sixth of their amplitude); emphasis < 0 is refused."""
    from solvers.audio import onset_emphasis

    t = np.arange(int(0.5 * RATE)) / RATE
    tone = np.sin(2 * np.pi * 440.0 * t)
    burst = np.where((t >= 0.3) & (t < 0.32), np.random.default_rng(0).standard_normal(len(t)), 0.0)
    z = onset_emphasis(np.vstack([tone, tone + burst]), RATE)
    steady = (t > 0.1) & (t < 0.28)
    assert np.sqrt(np.mean(z[0, steady] ** 2)) < 1e-4 * np.sqrt(np.mean(tone**2))
    assert np.sqrt(np.mean(z[0, t < 0.01] ** 2)) > 0.1 * np.sqrt(np.mean(tone[t < 0.01] ** 2))  # measured 0.16
    around = (t >= 0.3) & (t < 0.32)
    assert np.sqrt(np.mean(z[1, around] ** 2)) > 0.1 * np.sqrt(np.mean(burst[around] ** 2))  # measured 0.13
    with pytest.raises(ValueError, match="emphasis"):
        TdoaOptions(emphasis=-1.0)
