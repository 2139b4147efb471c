"""A room from audio, end to end: simulated recordings -> `tdoa` -> `calibrate --dim 3` -> errors beside the bound.

Each room (seeded): a 3D shoebox of random size (6-9 x 5-7 x 2.7-3.5 m) simulated by pyroomacoustics
(image sources, absorption from a target RT60 by Sabine's formula), `--mics` microphones and `--events`
sound events at random positions at least 0.5 m from the walls, one after the other (RT60 + 0.4-0.7 s
apart); each event a clap (a 20 ms exponentially decaying noise burst), a chirp (0.2 s, 200 Hz - 6 kHz)
or a speech-like sound (0.4 s of noise with a speech-like spectrum and a 4 Hz syllabic envelope), drawn
at random; white noise at the microphones for the given SNR (noise power = the mean power of the
noise-free recording while the events sound x 10^(-SNR/10)). The recording is written as a 24-bit
multichannel WAV file and read back by `solvers.recording.read_recording`, then
`solvers.audio_guided.tdoa_and_calibrate(recording, dim=3)` (what `tdoa-workbench calibrate --dim 3 room.wav`
runs, default options: the emitted signals are not used): the first pass `solvers.audio.tdoa_matrix`,
`calibrate(F, dim=3)` of it (sigma estimated), the guided second pass at that calibration's positions when
its status is "ok" or "uncontrolled" with every receiver placed, and `calibrate(F, dim=3)` of the guided matrix.

Columns: the room (`seed`, `mics`, `events`, `rt60_s`, `snr_db`, `signals`: claps/chirps/speech-like);
`detected` (events detected and matched to a simulated one / simulated, + spurious detections);
`first_pass_within_2` (the first pass's `within_2_samples`, below), `guided` ("yes", or "no (status)": the
first calibration's status that could not guide); what `tdoa` (the guided pass's matrix) measured against the simulator's truth on the detected events, over the entries other than each
event's reference (whose delay is 0 by definition): `within_2_samples` (share within 2 samples of the true time difference,
missing entries counting as misses), `within_2_of_offset` (share of all the entries, the reference's too,
within 2 samples of the true arrival time once the event's offset is taken out, the median of its
measured entries' errors; missing entries counting as misses: `calibrate` estimates every event's offset,
so an event whose reference locked onto a reflection has one wrong entry, not all but one), `missing` (share left missing), `gross`
(measured entries more than 2 samples off), `entry_noise_m` (rms error in metres of the entries within 2 samples); and what
`calibrate` made of the guided matrix: `status` and `reason` (what decided it, from the result's message), `unplaced`
(nodes with measurements it could not place; an event `tdoa` left missing whole has none), `kept`
(inliers / measured), `rms_position_err_m` (after the best rigid alignment, reflections allowed, over
the placed nodes of the detected events), `crb_position_rms_m` (the Cramer-Rao bound of that rms from
the entries the calibration kept at `entry_noise_m`,
solvers.metrics.cramer_rao_position_rms), `rms_over_crb`, `max_err_over_std` (the largest node error over
its reported std, in the result's gauge). The md ends with the counts the issue's targets name.

Usage: OPENBLAS_NUM_THREADS=1 python scripts/audio_room.py [--rooms 10] [--seed 0] [--snr 20] [--rt60 0.2:0.6]
       [--mics 8:16] [--events 10:30] [--name audio3d]
Needs the optional extra: pip install -e ".[audio]" (pyroomacoustics). Writes
tables/NAME.csv and .md; progress on stderr.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from solvers.audio import TdoaOptions  # noqa: E402
from solvers.recording import read_recording  # noqa: E402
from solvers.audio_guided import tdoa_and_calibrate  # noqa: E402
from solvers.metrics import align_rigid, cramer_rao_position_rms, standardised_node_errors  # noqa: E402
from solvers.synthetic import Network  # noqa: E402

FS = 16_000
KINDS = ("clap", "chirp", "speech")


def event_signal(rng: np.random.Generator, kind: str) -> np.ndarray:
    """One event's waveform (see the module docstring), of unit rms (every event equally loud)."""
    if kind == "clap":
        t = np.arange(int(0.02 * FS)) / FS
        s = rng.standard_normal(len(t)) * np.exp(-t / 0.005)
    elif kind == "chirp":
        from scipy.signal import chirp

        t = np.arange(int(0.2 * FS)) / FS
        f0, f1 = (200.0, 6000.0) if rng.random() < 0.5 else (6000.0, 200.0)
        s = chirp(t, f0=f0, t1=t[-1], f1=f1) * np.hanning(len(t)) ** 0.25
    else:
        from scipy.signal import butter, sosfilt

        t = np.arange(int(0.4 * FS)) / FS
        noise = rng.standard_normal(len(t))
        shaped = sosfilt(butter(2, [150.0, 3500.0], btype="band", fs=FS, output="sos"), noise)
        phase = rng.uniform(0, np.pi)
        s = shaped * (0.3 + 0.7 * np.abs(np.sin(2 * np.pi * 4.0 * t + phase))) * np.hanning(len(t)) ** 0.25
    return s / np.sqrt(np.mean(s**2))


def room_geometry(rng: np.random.Generator, mics: int, events: int, rt60: float):
    """A seeded shoebox room 6-9 x 5-7 x 2.7-3.5 m: (size, wall absorption and image order for ``rt60`` by Sabine,
    the speed of sound, microphone positions, source positions), every node 0.5 m from the walls."""
    import pyroomacoustics as pra

    size = [rng.uniform(6.0, 9.0), rng.uniform(5.0, 7.0), rng.uniform(2.7, 3.5)]
    absorption, max_order = pra.inverse_sabine(rt60, size)
    margin = 0.5
    mic_pos = np.column_stack([rng.uniform(margin, side - margin, mics) for side in size])
    src_pos = np.column_stack([rng.uniform(margin, side - margin, events) for side in size])
    return size, absorption, max_order, pra.constants.get("c"), mic_pos, src_pos


def simulate(rng: np.random.Generator, mics: int, events: int, rt60: float, snr_db: float):
    """(recording (mics, frames), Network in metres with each event's offset = c x its emission time, kinds)."""
    size, absorption, max_order, c, mic_pos, src_pos = room_geometry(rng, mics, events, rt60)
    kinds = [KINDS[int(k)] for k in rng.integers(len(KINDS), size=events)]
    signals = [event_signal(rng, k) for k in kinds]
    emit = 0.2 + np.concatenate([[0.0], np.cumsum(rt60 + rng.uniform(0.4, 0.7, events - 1))])
    noise_seed = int(rng.integers(2**31))
    rec, net = render(size, FS, absorption, min(max_order, 25), mic_pos, src_pos, signals, emit, snr_db, noise_seed, c)
    return rec, net, kinds, c


def render(size, rate: int, absorption: float, order: int, mic_pos: np.ndarray, src_pos: np.ndarray, signals, emit,
           snr_db: float, noise_seed: int, c: float):
    """The image-source recording of ``signals`` emitted at times ``emit`` (s) from ``src_pos`` in a shoebox room,
    with white noise ``snr_db`` below the sounding stretches' power, and the Network in metres (each event's offset
    = c x its emission time, as the simulator starts it, plus its fractional-delay filter's half length)."""
    import pyroomacoustics as pra

    room = pra.ShoeBox(size, fs=rate, materials=pra.Material(absorption), max_order=order)
    for j in range(len(signals)):
        room.add_source(src_pos[j], signal=signals[j], delay=emit[j])
    room.add_microphone_array(pra.MicrophoneArray(mic_pos.T, rate))
    room.simulate()
    rec = room.mic_array.signals
    sounding = np.zeros(rec.shape[1], bool)
    for j in range(len(signals)):
        a = int(emit[j] * rate)
        sounding[a : a + len(signals[j]) + int(0.03 * rate)] = True
    noise_power = np.mean(rec[:, sounding[: rec.shape[1]]] ** 2) * 10 ** (-snr_db / 10)
    rec = rec + np.sqrt(noise_power) * np.random.default_rng(noise_seed).standard_normal(rec.shape)
    emit = np.floor(emit * rate) / rate  # the simulator starts a source at floor(delay * fs)
    filter_delay = (pra.constants.get("frac_delay_length") // 2) / rate
    return rec, Network(mic_pos, src_pos, c * (emit + filter_delay))


def record(seed: int, mics: tuple[int, int], events: tuple[int, int], rt60: tuple[float, float], snr_db: float):
    """One room simulated and recorded: (the row's room columns, Recording read back from the WAV file, Network,
    speed of sound)."""
    import soundfile

    rng = np.random.default_rng(seed)
    m = int(rng.integers(mics[0], mics[1] + 1))
    n = int(rng.integers(events[0], events[1] + 1))
    rt60_s = round(float(rng.uniform(*rt60)), 2) if rt60[1] > rt60[0] else rt60[0]
    rec, net, kinds, c = simulate(rng, m, n, rt60_s, snr_db)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "room.wav")
        soundfile.write(path, (rec / (1.05 * np.max(np.abs(rec)))).T, FS, subtype="PCM_24")
        recording = read_recording(path)
    row = {"seed": seed, "mics": m, "events": n, "rt60_s": rt60_s, "snr_db": snr_db,
           "signals": "/".join(str(kinds.count(k)) for k in KINDS)}
    return row, recording, net, c


def run(seed: int, mics: tuple[int, int], events: tuple[int, int], rt60: tuple[float, float], snr_db: float) -> dict:
    """One room, one table row: recorded, then `tdoa` (first pass, calibration, guided pass) and `calibrate`
    of the guided matrix (solvers.audio_guided.tdoa_and_calibrate, what `calibrate --dim 3 room.wav` runs)."""
    row, recording, net, c = record(seed, mics, events, rt60, snr_db)
    return assess(row, tdoa_and_calibrate(recording, TdoaOptions(speed=c), dim=3, seed=seed), net, c)


def _matched(tm, net: Network, c: float):
    """(detected events, the true event of each): each detected event is the true event whose direct sound
    starts within 60 ms after its onset (the first microphone hears it within 30 ms; the 5 ms frames start up
    to 20 ms early); a split event counts once."""
    lead = tm.onsets[:, None] - net.offsets[None, :] / c
    near = (lead > -0.02) & (lead < 0.06)
    det = [d for d in range(len(tm.events)) if near[d].any()]
    truth = [int(np.argmax(near[d])) for d in det]
    keep = [k for k in range(len(det)) if truth[k] not in truth[:k]]
    return np.array([det[k] for k in keep], int), np.array([truth[k] for k in keep], int)


def entry_errors(tm, net: Network, c: float, det: np.ndarray, truth: np.ndarray) -> dict:
    """tdoa's entries against the truth on the detected events (the module docstring's columns
    within_2_samples .. entry_noise_m; the reference's own entry is exact)."""
    D = np.linalg.norm(net.receivers[:, None, :] - net.transmitters[None, truth, :], axis=2)
    Fd, ref = tm.F[:, det], tm.reference[det]
    cols = np.arange(len(det))
    err = Fd - (c * tm.onsets[det][None, :] + D - D[ref, cols][None, :])
    other = np.ones(Fd.shape, bool)
    other[ref, cols] = False
    good = other & (np.abs(err) <= 2 * c / FS)
    measured = np.isfinite(Fd)
    arrival = Fd - net.offsets[truth][None, :] - D  # each entry's arrival-time error, up to the event's offset
    offset = np.array([np.median(col[np.isfinite(col)]) if np.isfinite(col).any() else np.nan for col in arrival.T])
    noise = float(np.sqrt(np.mean(err[good] ** 2)))
    return {"within_2_samples": round(float(good.sum() / other.sum()), 4),
            "within_2_of_offset": round(float(np.mean(np.abs(arrival - offset[None, :]) <= 2 * c / FS)), 4),
            "missing": round(float((other & ~measured).sum() / other.sum()), 4),
            "gross": int((other & measured & ~good).sum()), "entry_noise_m": float(f"{noise:.3g}")}


def assess(row: dict, run, net: Network, c: float) -> dict:
    """The row of one measured room (run: a solvers.audio_guided.GuidedTdoa with its calibration): the first
    pass's and the guided pass's entries against the truth, then what `calibrate` made of the guided matrix."""
    tm, m, n = run.matrix, row["mics"], row["events"]
    det, truth = _matched(tm, net, c)
    row["detected"] = f"{len(det)}/{n}" + (f" +{len(tm.events) - len(det)}" if len(tm.events) > len(det) else "")
    empty = ("first_pass_within_2", "guided", "within_2_samples", "within_2_of_offset", "missing", "gross",
             "entry_noise_m", "status", "reason", "unplaced", "kept", "rms_position_err_m", "crb_position_rms_m",
             "rms_over_crb", "max_err_over_std")
    if len(det) < 4:
        row.update(dict.fromkeys(empty, ""))
        return row
    first = run.first_calibration
    row["first_pass_within_2"] = entry_errors(run.first, net, c, det, truth)["within_2_samples"]
    row["guided"] = "yes" if run.guided else f"no ({first.status})"
    row.update(entry_errors(tm, net, c, det, truth))
    noise = row["entry_noise_m"]
    # the whole matrix (spurious events too, as a user has it) calibrated; errors on the detected events
    res = run.calibration
    row.update({"status": res.status, "reason": res.message.split(" - ", 1)[-1].replace("|", "/")[:120],
                "unplaced": int((~np.isfinite(res.receivers[:, 0]) & np.isfinite(tm.F).any(axis=1)).sum() +
                                (~np.isfinite(res.transmitters[:, 0]) & np.isfinite(tm.F).any(axis=0)).sum()),
                "kept": f"{int(res.inliers.sum())}/{int(np.isfinite(tm.F).sum())}"})
    sub = replace(res, transmitters=res.transmitters[det], transmitter_std=res.transmitter_std[det],
                  offsets=res.offsets[det], inliers=res.inliers[:, det])
    truth_net = Network(net.receivers, net.transmitters[truth], net.offsets[truth])
    X = np.vstack([sub.receivers, sub.transmitters])
    Y = np.vstack([truth_net.receivers, truth_net.transmitters])
    placed = np.isfinite(X[:, 0])
    if res.status == "failed" or placed.sum() < 4:
        row.update(dict.fromkeys(empty[-4:], ""))
        return row
    aligned = align_rigid(X[placed], Y[placed]).apply(X[placed])
    rms = float(np.sqrt(np.mean(np.sum((aligned - Y[placed]) ** 2, axis=1))))
    pr, pt = placed[:m], placed[m:]
    crb = cramer_rao_position_rms(truth_net.receivers[pr], truth_net.transmitters[pt], sub.inliers[np.ix_(pr, pt)], noise)
    row.update({"rms_position_err_m": float(f"{rms:.3g}"), "crb_position_rms_m": float(f"{crb:.3g}"),
                "rms_over_crb": float(f"{rms / crb:.3g}") if np.isfinite(crb) else "",
                "max_err_over_std": float(f"{np.max(standardised_node_errors(sub, truth_net), initial=0.0):.3g}")})
    return row


def summary(rows: list[dict]) -> str:
    """The counts the issue's targets name, as one paragraph."""
    done = [r for r in rows if r["within_2_samples"] != ""]
    share = [r["within_2_samples"] for r in done]
    entries = [(r["mics"] - 1) * int(r["detected"].split("/")[0]) for r in done]  # a reference is not measured
    pooled = sum(r["within_2_samples"] * e for r, e in zip(done, entries)) / max(sum(entries), 1)
    within = sum(r["rms_over_crb"] != "" and r["rms_over_crb"] <= 2.0 and r["unplaced"] == 0 for r in done)
    missed = sum(r["events"] - int(r["detected"].split("/")[0]) for r in rows)
    met = sum(r["status"] == "ok" and r["rms_over_crb"] != "" and r["rms_over_crb"] <= 2.0 for r in done)
    statuses = ", ".join(f"{k} {sum(r['status'] == k for r in rows)}" for k in sorted({r["status"] for r in rows}))
    given = sum(r["within_2_of_offset"] >= 0.95 for r in done)
    pooled_offset = sum(r["within_2_of_offset"] * r["mics"] * int(r["detected"].split("/")[0]) for r in done) / max(
        sum(r["mics"] * int(r["detected"].split("/")[0]) for r in done), 1)
    worst = max((r["max_err_over_std"] for r in done if r["status"] == "ok" and r["max_err_over_std"] != ""), default=None)
    first = [r["first_pass_within_2"] for r in done]
    pooled_first = sum(v * e for v, e in zip(first, entries)) / max(sum(entries), 1)
    guided = sum(r["guided"] == "yes" for r in done)
    return (f"Rooms whose entries are >= 95 % within 2 samples: {sum(v >= 0.95 for v in share)} of {len(rows)} "
            f"(median share {np.median(share) if share else float('nan'):.4f}, pooled {pooled:.4f}; the first pass "
            f"{sum(v >= 0.95 for v in first)} of {len(rows)}, pooled {pooled_first:.4f}; guided: {guided} of {len(rows)} "
            f"rooms); every entry, up to "
            f"its event's offset: {given} of {len(rows)} (pooled {pooled_offset:.4f}). Rooms with every "
            f"node that has measurements placed and rms position error <= 2 x the Cramer-Rao bound: {within} of {len(rows)}; of those "
            f"\"ok\": {met}. Largest node error over its reported std in an \"ok\" room: "
            f"{'none ok' if worst is None else worst}. Statuses: {statuses or 'none'}. Events not detected: {missed} of "
            f"{sum(r['events'] for r in rows)}.")


def _range(text: str, kind=float) -> tuple:
    low, _, high = text.partition(":")
    return kind(low), kind(high or low)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rooms", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--mics", default="8:16", help="microphones, N or LOW:HIGH drawn per room (default 8:16)")
    ap.add_argument("--events", default="10:30", help="events, N or LOW:HIGH drawn per room (default 10:30)")
    ap.add_argument("--rt60", default="0.2:0.6", help="reverberation time in s, or LOW:HIGH (default 0.2:0.6)")
    ap.add_argument("--snr", type=float, default=20.0, help="SNR in dB at the microphones (default 20)")
    ap.add_argument("--name", default="audio3d", help="output tables/NAME.csv and .md (default audio3d)")
    args = ap.parse_args(argv)
    try:
        mics, events, rt60 = _range(args.mics, int), _range(args.events, int), _range(args.rt60)
    except ValueError:
        ap.error("--mics, --events and --rt60 take N or LOW:HIGH")
    try:
        import pyroomacoustics  # noqa: F401
        import soundfile  # noqa: F401
    except ImportError:
        print("audio_room needs the audio extra: pip install -e \".[audio]\"", file=sys.stderr)
        return 2
    rows = []
    for k in range(args.rooms):
        t0 = time.perf_counter()
        rows.append(run(args.seed + k, mics, events, rt60, args.snr))
        print(f"room {k + 1}/{args.rooms} ({time.perf_counter() - t0:.0f} s): {rows[-1]}", file=sys.stderr, flush=True)
    write_table(os.path.join(ROOT, "tables", args.name), rows, summary(rows))
    return 0


def write_table(out: str, rows: list[dict], summary_text: str) -> None:
    """OUT.csv and OUT.md of the rows (one column per key of the first row), the summary under the table."""
    keys = list(rows[0])
    with open(out + ".csv", "w", newline="") as handle:
        w = csv.DictWriter(handle, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    with open(out + ".md", "w") as handle:
        handle.write("| " + " | ".join(keys) + " |\n|" + "---|" * len(keys) + "\n")
        for r in rows:
            handle.write("| " + " | ".join(str(r[k]) for k in keys) + " |\n")
        handle.write("\n" + summary_text + "\n")
    print(f"wrote {out}.csv and {out}.md", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
