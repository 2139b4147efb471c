"""Calibrate a simulated room from audio: pyroomacoustics -> GCC-PHAT -> F -> solvers.calibrate.

A 2D shoebox room with reverberation (image sources, absorption from a target RT60) and microphone
noise; `--sources` sources emit distinct white-noise bursts at unknown times (overlapping in time); the
`--mics` microphones record them all together. For every (microphone, source) pair the arrival time of
the direct sound is the peak of the GCC-PHAT cross-correlation of the recording with the source's
emitted waveform (the reference), refined by parabolic interpolation:
    f_ij = c * arrival_ij = |r_i - s_j| + c * (emission time_j + filter delay),
i.e. TDOA data with one unknown offset per source. A peak weaker than `--min-peak` times the
correlation's RMS is a missed detection (NaN); reflections and overlapping sources that beat the direct
path give gross errors. Nothing is planted: gaps and outliers come from the signal chain.
The matrix is calibrated with sigma estimated, and compared with the simulator's ground truth after the
best rigid alignment (solvers.metrics), over the nodes it placed (`unplaced` counts those it reports as
not determined), and each node's error in units of its reported standard deviation (`max_err_over_std`).
Writes tables/room_simulation.csv and .md (one row per room).

Needs the optional extra: pip install -e ".[audio]"  (pyroomacoustics).
Usage: OPENBLAS_NUM_THREADS=1 python scripts/room_simulation.py [--rooms 5] [--seed 0] [--rt60 0.3] [--snr 20]
       [--name room_simulation]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import sys  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from solvers.calibration import calibrate  # noqa: E402
from solvers.metrics import align_rigid, standardised_node_errors  # noqa: E402
from solvers.synthetic import Network  # noqa: E402

FS = 16_000
BURST = 0.1  # seconds of white noise per source


def gcc_phat_delay(recording: np.ndarray, reference: np.ndarray, fs: int, max_delay: float) -> tuple[float, float]:
    """(delay in seconds of `reference` within `recording`, peak / RMS of the correlation).

    GCC-PHAT: the cross-spectrum normalised to unit magnitude, so that every frequency votes equally
    for the delay (robust to the colouring of reverberation); parabolic interpolation of the peak.
    """
    n = len(recording) + len(reference)
    X = np.fft.rfft(recording, n)
    Y = np.fft.rfft(reference, n)
    cross = X * np.conj(Y)
    cc = np.fft.irfft(cross / np.maximum(np.abs(cross), 1e-12), n)
    lags = int(max_delay * fs)
    window = cc[: lags + 1]
    k = int(np.argmax(window))
    if 0 < k < lags:
        a, b, c = window[k - 1], window[k], window[k + 1]
        shift = 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) != 0 else 0.0
    else:
        shift = 0.0
    return (k + shift) / fs, float(window[k] / np.sqrt(np.mean(window**2)))


def simulate_room(rng: np.random.Generator, mics: int, sources: int, rt60: float, snr_db: float, size=(10.0, 8.0)):
    """One room: returns (F with NaN for missed detections, true Network in metres, emission times)."""
    import pyroomacoustics as pra

    noise_seed = int(rng.integers(2**31))
    absorption, max_order = pra.inverse_sabine(rt60, list(size) + [3.0])  # a 3 m height for Sabine's formula
    c = pra.constants.get("c")
    margin = 0.5
    mic_pos = np.column_stack([rng.uniform(margin, size[0] - margin, mics), rng.uniform(margin, size[1] - margin, mics)])
    src_pos = np.column_stack([rng.uniform(margin, size[0] - margin, sources), rng.uniform(margin, size[1] - margin, sources)])
    emit = rng.uniform(0.0, 0.5, sources)
    signals = [rng.standard_normal(int(BURST * FS)) for _ in range(sources)]
    power = float(np.mean([np.mean(s**2) for s in signals]))
    room = pra.ShoeBox(list(size), fs=FS, materials=pra.Material(absorption), max_order=min(max_order, 30),
                       sigma2_awgn=power * 10 ** (-snr_db / 10) / 20.0)
    for j in range(sources):
        room.add_source(src_pos[j], signal=signals[j], delay=emit[j])
    room.add_microphone_array(pra.MicrophoneArray(mic_pos.T, FS))
    pra.random.seed(noise_seed)  # the microphone noise comes from pyroomacoustics' own generator
    room.simulate()
    rec = room.mic_array.signals
    # The simulator starts a source at floor(delay * fs) samples, and its fractional-delay filter
    # delays every arrival by the same number of samples.
    emit = np.floor(emit * FS) / FS
    filter_delay = (pra.constants.get("frac_delay_length") // 2) / FS
    F = np.full((mics, sources), np.nan)
    peaks = np.zeros((mics, sources))
    for i in range(mics):
        for j in range(sources):
            delay, peak = gcc_phat_delay(rec[i], signals[j], FS, max_delay=1.0)
            peaks[i, j] = peak
            F[i, j] = c * delay
    net = Network(mic_pos, src_pos, c * (emit + filter_delay))
    return F, peaks, net


def run(seed: int, mics: int, sources: int, rt60: float, snr_db: float, min_peak: float) -> dict:
    rng = np.random.default_rng(seed)
    F_raw, peaks, net = simulate_room(rng, mics, sources, rt60, snr_db)
    F = np.where(peaks >= min_peak, F_raw, np.nan)
    F_true = net.measurements()
    measured = np.isfinite(F)
    gross = measured & (np.abs(F - F_true) > 0.1)  # > 10 cm: not noise but a wrong peak
    res = calibrate(F, seed=seed)
    row = {"seed": seed, "mics": mics, "sources": sources, "rt60_s": rt60, "snr_db": snr_db,
           "missing": round(float(1 - measured.mean()), 3), "gross_errors": int(gross.sum()),
           "inlier_noise_m": float(f"{np.sqrt(np.mean((F - F_true)[measured & ~gross] ** 2)):.3g}"),
           "status": res.status, "warnings": len(res.warnings)}
    X = np.vstack([res.receivers, res.transmitters])
    Y = np.vstack([net.receivers, net.transmitters])
    placed = np.isfinite(X[:, 0])
    row["unplaced"] = int((~placed).sum())
    if res.status == "failed" or placed.sum() < 3:
        row.update({"flagged": "", "false_rejects": "", "rms_position_err_m": "", "relative_position_err": "",
                    "offset_rms_err_m": "", "sigma_estimated_m": "", "max_err_over_std": ""})
        return row
    # Errors over the placed nodes (a node the data do not fix is reported as not placed).
    aligned = align_rigid(X[placed], Y[placed]).apply(X[placed])
    spread = np.linalg.norm(Y[placed] - Y[placed].mean(axis=0))
    off = np.isfinite(res.offsets)
    row.update({
        "flagged": f"{int((gross & ~res.inliers).sum())}/{int(gross.sum())}",
        "false_rejects": int((measured & ~gross & ~res.inliers).sum()),
        "rms_position_err_m": float(f"{np.sqrt(np.mean(np.sum((aligned - Y[placed]) ** 2, axis=1))):.3g}"),
        "relative_position_err": float(f"{np.linalg.norm(aligned - Y[placed]) / spread:.3g}"),
        "offset_rms_err_m": float(f"{np.sqrt(np.mean((res.offsets[off] - net.offsets[off]) ** 2)):.3g}"),
        "sigma_estimated_m": float(f"{res.sigma:.3g}"),
        # the largest node error in units of its reported std (in the result's gauge): honest if small
        "max_err_over_std": float(f"{np.max(standardised_node_errors(res, net), initial=0.0):.3g}"),
    })
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rooms", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--mics", type=int, default=12)
    ap.add_argument("--sources", type=int, default=10)
    ap.add_argument("--rt60", type=float, default=0.3, help="reverberation time in seconds (default 0.3)")
    ap.add_argument("--snr", type=float, default=20.0, help="signal-to-noise ratio in dB at the microphones (default 20)")
    ap.add_argument("--min-peak", type=float, default=8.0, help="GCC-PHAT peak / RMS below which a pair is missing")
    ap.add_argument("--name", default="room_simulation", help="output tables/NAME.csv and .md (default room_simulation)")
    args = ap.parse_args(argv)
    try:
        import pyroomacoustics  # noqa: F401
    except ImportError:
        print("room_simulation needs the audio extra: pip install -e \".[audio]\"", file=sys.stderr)
        return 2
    rows = []
    for k in range(args.rooms):
        row = run(args.seed + k, args.mics, args.sources, args.rt60, args.snr, args.min_peak)
        rows.append(row)
        print(row, flush=True)
    out = os.path.join(ROOT, "tables", args.name)
    with open(out + ".csv", "w", newline="") as handle:
        w = csv.DictWriter(handle, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    keys = list(rows[0])
    with open(out + ".md", "w") as handle:
        handle.write("| " + " | ".join(keys) + " |\n|" + "---|" * len(keys) + "\n")
        for r in rows:
            handle.write("| " + " | ".join(str(r[k]) for k in keys) + " |\n")
    print(f"wrote {out}.csv and {out}.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
