"""Sounds of every kind in reverberant rooms: `tdoa` and `calibrate RECORDING` per signal kind, strict beside lenient.

Each room (seeded by its kind and condition): a 3D shoebox of random size (6-9 x 5-7 x 2.7-3.5 m) simulated
by pyroomacoustics' image sources to order 20 (`--order`; absorption from the nominal RT60 by Sabine's
formula), 6-16 microphones and `--events` events at random positions at least 0.5 m from the walls (near
and far from the microphones alike), one after the other (the sound, then RT60 + 0.4-0.7 s); every event of a
room is one kind of sound:

  speech     3-5 syllables of 80-200 ms with 30-100 ms pauses: a voiced glottal pulse train (f0 100-250 Hz,
             jittered) and 30 % breath noise, band-passed to 150-3500 Hz (continuous, periodic, with pauses)
  music      a three-note phrase: notes of 200-300 ms, f0 200-800 Hz on a scale, 8 harmonics (1/h), a 10 ms
             attack and an exponential decay (periodic: pair correlations peak at multiples of the period)
  log_sweep  a 0.8 s logarithmic sweep 100 Hz - 0.4 x rate; every event the same sweep
  lin_sweep  a 0.8 s linear sweep over the same band; every event the same sweep
  clap       a 20 ms exponentially decaying noise burst (short, impulsive)

and six conditions per kind (`CONDITIONS`): 16 and 48 kHz x (RT60 0.3 s, 0.55 s, 0.8 s) with the SNR
10, 20 or 30 dB (noise power = the mean power of the noise-free recording while the events sound x
10^(-SNR/10)). The recording is written as a 24-bit WAV file and read back by read_recording, then
`tdoa_and_calibrate(recording, dim=3)` (what `calibrate --dim 3 room.wav` runs); the sweeps also with the
emitted sweep given (`--signal FILE`; rows `log_sweep+signal`, `lin_sweep+signal`).

Columns: the room (`kind`, `rate`, `rt60_s`, `snr_db`, `seed`, `mics`, `events`); `detected` (true events matched
by a detected one within 60 ms of its sound); `kept` (true events with at least one entry); `strict` (the
share of the true events' entries, m - 1 per event, the event's reference left out, within 2 samples of the
true time difference: an event missed or left missing counts 0); `lenient` (the same share over the kept
events only); `first_strict` (the first pass's strict share); `status` (of calibrate); `mics_within_3cm`
(microphones placed within 3 cm of the truth after the best rigid alignment of the microphones, reflections
allowed, / microphones); `max_mic_err_m`; `max_err_over_std` (the largest node error over its reported std,
solvers.metrics.standardised_node_errors). The md ends with per-kind counts: pooled strict and lenient,
rooms at >= 90 % strict, rooms with every microphone within 3 cm, "ok" rooms with a node > 5 std off.
Deterministic: seeded, no runtimes (those go to stderr).

Usage: OPENBLAS_NUM_THREADS=1 python scripts/audio_kinds.py [--kinds speech,music,...] [--conditions 0:6]
       [--events 10] [--order 20] [--name audio3d_kinds]
Needs the optional extra: pip install -e ".[audio]" (pyroomacoustics).
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import zlib  # noqa: E402
from dataclasses import replace  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "scripts"))

import numpy as np  # noqa: E402

from solvers.audio import TdoaOptions  # noqa: E402
from solvers.recording import read_recording  # noqa: E402
from solvers.audio_guided import tdoa_and_calibrate  # noqa: E402
from solvers.metrics import align_rigid, standardised_node_errors  # noqa: E402
from solvers.synthetic import Network  # noqa: E402
from audio_room import render, room_geometry, write_table  # noqa: E402  (scripts/audio_room.py: the one room simulation)

KINDS = ("speech", "music", "log_sweep", "lin_sweep", "clap")
#: (rate, nominal RT60 s, SNR dB)
CONDITIONS = ((16_000, 0.3, 30.0), (16_000, 0.55, 20.0), (16_000, 0.8, 10.0),
              (48_000, 0.3, 10.0), (48_000, 0.55, 30.0), (48_000, 0.8, 20.0))
SWEEP_SECONDS = 0.8


def _band(x: np.ndarray, low: float, high: float, rate: int) -> np.ndarray:
    from scipy.signal import butter, sosfilt

    return sosfilt(butter(2, [low, high], btype="band", fs=rate, output="sos"), x)


def sweep(kind: str, rate: int) -> np.ndarray:
    """The emitted sweep of a room (the same for every event)."""
    from scipy.signal import chirp

    t = np.arange(int(SWEEP_SECONDS * rate)) / rate
    method = "logarithmic" if kind == "log_sweep" else "linear"
    s = chirp(t, f0=100.0, t1=t[-1], f1=0.4 * rate, method=method) * np.hanning(len(t)) ** 0.25
    return s / np.sqrt(np.mean(s**2))


def event_signal(rng: np.random.Generator, kind: str, rate: int) -> np.ndarray:
    """One event's waveform (the module docstring), of unit rms."""
    if kind in ("log_sweep", "lin_sweep"):
        return sweep(kind, rate)
    if kind == "clap":
        t = np.arange(int(0.02 * rate)) / rate
        s = rng.standard_normal(len(t)) * np.exp(-t / 0.005)
    elif kind == "speech":
        parts = []
        for _ in range(int(rng.integers(3, 6))):
            n = int(rng.uniform(0.08, 0.2) * rate)
            f0 = rng.uniform(100.0, 250.0)
            phase = np.cumsum(f0 * (1 + 0.02 * rng.standard_normal(n)) / rate)
            pulses = np.diff(np.floor(phase), prepend=0.0)  # one pulse per period
            voiced = _band(pulses + 0.3 * np.std(pulses) * rng.standard_normal(n), 150.0, 3500.0, rate)
            parts += [voiced * np.hanning(n), np.zeros(int(rng.uniform(0.03, 0.1) * rate))]
        s = np.concatenate(parts[:-1])
    else:  # music
        scale = 220.0 * 2 ** (np.array([0, 2, 4, 5, 7, 9, 11, 12, 14, 16, 17, 19, 21, 23, 24]) / 12)
        notes = []
        for f0 in rng.choice(scale[scale <= 800.0], 3):
            n = int(rng.uniform(0.2, 0.3) * rate)
            t = np.arange(n) / rate
            tone = sum(np.sin(2 * np.pi * h * f0 * t + rng.uniform(0, 2 * np.pi)) / h for h in range(1, 9)
                       if h * f0 < 0.45 * rate)
            notes.append(tone * np.minimum(t / 0.01, 1.0) * np.exp(-t / 0.15))
        s = np.concatenate(notes)
    return s / np.sqrt(np.mean(s**2))


def simulate(rng: np.random.Generator, kind: str, rate: int, mics: int, events: int, rt60: float, snr_db: float,
             order: int):
    """(recording (mics, frames), Network in metres with each event's offset = c x its emission time, c)."""
    size, absorption, _, c, mic_pos, src_pos = room_geometry(rng, mics, events, rt60)
    signals = [event_signal(rng, kind, rate) for _ in range(events)]
    lengths = np.array([len(s) / rate for s in signals])
    emit = 0.2 + np.concatenate([[0.0], np.cumsum(lengths[:-1] + rt60 + rng.uniform(0.4, 0.7, events - 1))])
    noise_seed = int(rng.integers(2**31))
    rec, net = render(size, rate, absorption, order, mic_pos, src_pos, signals, emit, snr_db, noise_seed, c)
    return rec, net, c


def _matched(tm, net: Network, c: float):
    """(detected events, the true event of each): a detected event whose onset lies within 60 ms after a true
    event's sound starts (20 ms before allowed: 5 ms frames); a split event counts once."""
    lead = tm.onsets[:, None] - net.offsets[None, :] / c
    near = (lead > -0.02) & (lead < 0.06)
    det = [d for d in range(len(tm.events)) if near[d].any()]
    truth = [int(np.argmax(near[d])) for d in det]
    keep = [k for k in range(len(det)) if truth[k] not in truth[:k]]
    return np.array([det[k] for k in keep], int), np.array([truth[k] for k in keep], int)


def scores(tm, net: Network, c: float, rate: int) -> dict:
    """strict, lenient and the counts of the module docstring for one matrix."""
    m, n = net.receivers.shape[0], net.transmitters.shape[0]
    det, truth = _matched(tm, net, c)
    good = 0
    kept = 0
    for d, t in zip(det, truth):
        col, r = tm.F[:, d], tm.reference[d]
        if not np.isfinite(col).any():
            continue
        kept += 1
        D = np.linalg.norm(net.receivers - net.transmitters[t], axis=1)
        err = col - col[r] - (D - D[r])
        other = np.arange(m) != r
        good += int(np.sum(other & (np.abs(err) <= 2 * c / rate)))
    return {"detected": f"{len(det)}/{n}", "kept": f"{kept}/{n}", "strict": round(good / (n * (m - 1)), 4),
            "lenient": round(good / (kept * (m - 1)), 4) if kept else 0.0}


def placement(result, net: Network, det: np.ndarray, truth: np.ndarray) -> dict:
    """Microphones within 3 cm after the best rigid alignment of the microphones, the largest error, and
    the largest node error over its reported std (the detected events det matched to the true events truth)."""
    m = net.receivers.shape[0]
    R = result.receivers
    placed = np.isfinite(R[:, 0])
    if result.status == "failed" or placed.sum() < 4:
        return {"mics_within_3cm": f"0/{m}", "max_mic_err_m": "", "max_err_over_std": ""}
    aligned = align_rigid(R[placed], net.receivers[placed]).apply(R[placed])
    sub = replace(result, transmitters=result.transmitters[det], transmitter_std=result.transmitter_std[det],
                  offsets=result.offsets[det], inliers=result.inliers[:, det])
    truth_net = Network(net.receivers, net.transmitters[truth], net.offsets[truth])
    err = np.linalg.norm(aligned - net.receivers[placed], axis=1)
    return {"mics_within_3cm": f"{int(np.sum(err <= 0.03))}/{m}",
            "max_mic_err_m": float(f"{err.max():.3g}") if placed.all() else "",
            "max_err_over_std": float(f"{np.max(standardised_node_errors(sub, truth_net), initial=0.0):.3g}")}


def room(kind: str, condition: int, events: int, order: int):
    """(Recording read back from the room's 24-bit WAV file, Network, speed of sound, seed) of one room of the
    table (seeded by its kind and condition; scripts/audio_music_probe.py measures the same rooms)."""
    import soundfile

    rate, rt60, snr = CONDITIONS[condition]
    seed = zlib.crc32(f"{kind}/{condition}".encode())  # the same room with and without the signal given
    rng = np.random.default_rng(seed)
    m = int(rng.integers(6, 17))
    rec, net, c = simulate(rng, kind, rate, m, events, rt60, snr, order)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "room.wav")
        soundfile.write(path, (rec / (1.05 * np.max(np.abs(rec)))).T, rate, subtype="PCM_24")
        recording = read_recording(path)
    return recording, net, c, seed


def run(kind: str, condition: int, events: int, order: int, given: bool = False) -> dict:
    """One room, one row (the module docstring); `given`: the sweep's signal given to tdoa (--signal)."""
    rate, rt60, snr = CONDITIONS[condition]
    recording, net, c, seed = room(kind, condition, events, order)
    m = net.receivers.shape[0]
    options = TdoaOptions(speed=c, signal=sweep(kind, rate) if given else None)
    run_ = tdoa_and_calibrate(recording, options, dim=3, seed=0)
    row = {"kind": kind + ("+signal" if given else ""), "rate": rate, "rt60_s": rt60, "snr_db": snr, "seed": seed,
           "mics": m, "events": events}
    row.update(scores(run_.matrix, net, c, rate))
    row["first_strict"] = scores(run_.first, net, c, rate)["strict"]
    row["status"] = run_.calibration.status
    row.update(placement(run_.calibration, net, *_matched(run_.matrix, net, c)))
    return row


def summary(rows: list[dict]) -> str:
    """Per kind: rooms, pooled strict and lenient, rooms at >= 90 % strict, rooms with every microphone within
    3 cm, and "ok" rooms with a node > 5 std off."""
    lines = ["| kind | rooms | strict (pooled) | lenient (pooled) | rooms >= 90 % strict | every mic within 3 cm | "
             "ok with a node > 5 std off |", "|---|---|---|---|---|---|---|"]
    for kind in dict.fromkeys(r["kind"] for r in rows):
        sub = [r for r in rows if r["kind"] == kind]
        entries = [(r["mics"] - 1) * r["events"] for r in sub]
        strict = sum(r["strict"] * e for r, e in zip(sub, entries)) / sum(entries)
        kept = [(r["mics"] - 1) * int(r["kept"].split("/")[0]) for r in sub]
        lenient = sum(r["lenient"] * e for r, e in zip(sub, kept)) / max(sum(kept), 1)
        within = sum(r["mics_within_3cm"].split("/")[0] == r["mics_within_3cm"].split("/")[1] for r in sub)
        off = sum(r["status"] == "ok" and r["max_err_over_std"] != "" and r["max_err_over_std"] > 5 for r in sub)
        lines.append(f"| {kind} | {len(sub)} | {strict:.3f} | {lenient:.3f} | {sum(r['strict'] >= 0.9 for r in sub)} | "
                     f"{within} | {off} |")
    return "\n".join(lines)


def listed(ap: argparse.ArgumentParser, text: str, valid, flag: str) -> list[str]:
    """The comma-separated names of a flag, each one of `valid` (else the parser's error naming them)."""
    names = [k for k in text.split(",") if k]
    if any(k not in valid for k in names):
        ap.error(f"{flag} takes {', '.join(valid)}")
    return names


def index_range(text: str) -> range:
    """LOW:HIGH (or LOW alone: that one index) as a range of indices into CONDITIONS."""
    low, _, high = text.partition(":")
    return range(int(low), int(high or int(low) + 1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kinds", default=",".join(KINDS), help=f"comma-separated, of {', '.join(KINDS)}")
    ap.add_argument("--conditions", default="0:6", help="LOW:HIGH indices into CONDITIONS (default 0:6)")
    ap.add_argument("--events", type=int, default=10)
    ap.add_argument("--order", type=int, default=20, help="image-source order (default 20)")
    ap.add_argument("--no-signal", action="store_true", help="skip the sweeps' rows with the signal given")
    ap.add_argument("--name", default="audio3d_kinds", help="output tables/NAME.csv and .md")
    ap.add_argument("--resume", action="store_true", help="append each row to tables/NAME.csv as it is measured and "
                    "skip the rows already there (several processes can share the runs); the table is rewritten "
                    "whole, in order, at the end")
    ap.add_argument("--signal-only", action="store_true", help="only the sweeps' rows with the signal given")
    args = ap.parse_args(argv)
    kinds = listed(ap, args.kinds, KINDS, "--kinds")
    conditions = index_range(args.conditions)
    jobs = [] if args.signal_only else [(k, cond, False) for k in kinds for cond in conditions]
    if not args.no_signal:
        jobs += [(k, cond, True) for k in kinds if k.endswith("sweep") for cond in conditions]
    out = os.path.join(ROOT, "tables", args.name)
    done = _rows_written(out) if args.resume else {}
    for n, (kind, cond, given) in enumerate(jobs):
        key = (kind + ("+signal" if given else ""), *CONDITIONS[cond])
        if key in done:
            continue
        t0 = time.perf_counter()
        row = run(kind, cond, args.events, args.order, given)
        print(f"room {n + 1}/{len(jobs)} ({time.perf_counter() - t0:.0f} s): {row}", file=sys.stderr, flush=True)
        if args.resume:  # each row as it comes: several processes may share the file, one row a line
            fresh = not os.path.exists(out + ".csv")
            with open(out + ".csv", "a", newline="") as handle:
                w = csv.DictWriter(handle, fieldnames=list(row))
                if fresh:
                    w.writeheader()
                w.writerow(row)
        done[key] = row
    if args.resume:
        done.update(_rows_written(out))  # another process's rows too
    write(out, _ordered(list(done.values())))
    return 0


def _rows_written(out: str) -> dict:
    """The rows in tables/NAME.csv (a stopped or parallel run's: the same seeds give the same rows), by
    (kind, rate, RT60, SNR)."""
    if not os.path.exists(out + ".csv"):
        return {}
    with open(out + ".csv", newline="") as handle:
        return {(r["kind"], int(r["rate"]), float(r["rt60_s"]), float(r["snr_db"])): r for r in csv.DictReader(handle)
                if r["kind"] != "kind"}


def _ordered(rows: list[dict]) -> list[dict]:
    """The rows typed as run() returns them, in the order of KINDS (the signal rows last) and CONDITIONS."""
    typed = []
    for r in rows:
        t = dict(r)
        for k in ("rate", "seed", "mics", "events"):
            t[k] = int(t[k])
        for k in ("rt60_s", "snr_db", "strict", "lenient", "first_strict"):
            t[k] = float(t[k])
        for k in ("max_mic_err_m", "max_err_over_std"):
            t[k] = float(t[k]) if t[k] != "" else ""
        typed.append(t)
    order = {k: n for n, k in enumerate([*KINDS, *(f"{k}+signal" for k in KINDS)])}
    return sorted(typed, key=lambda r: (order[r["kind"]], CONDITIONS.index((r["rate"], r["rt60_s"], r["snr_db"]))))


def write(out: str, rows: list[dict]) -> None:
    """tables/NAME.csv and .md of the rows."""
    write_table(out, rows, summary(rows))


if __name__ == "__main__":
    sys.exit(main())
