"""Calibrate a simulated room from audio: pyroomacoustics -> GCC-PHAT -> F -> solvers.calibrate.

A shoebox room with reverberation (image sources, absorption from a target RT60) and microphone noise:
`--dim 2` (default) a 10 x 8 m room with the positions in a plane, `--dim 3` an 8 x 6 x 3 m room with
microphones and sources anywhere in it at least 0.5 m from the walls (not coplanar). `--sources`
sources emit distinct white-noise bursts or linear chirps (`--signal`) at unknown times (2D: 0.1 s
within 0.5 s, overlapping; 3D: 0.3 s within 3 s, see RoomSetup); the `--mics` microphones record them
all together. SNR: in 3D that of the recordings at the microphones; in 2D nominal (the noise power is
the source power / 20 x 10^(-SNR/10); one room measured 31 dB at the microphones for a stated 20 dB;
kept so that the committed 2D tables reproduce). For every (microphone, source) pair the arrival time
of the direct sound is the peak of the GCC-PHAT cross-correlation of the recording with the source's
emitted waveform (the reference; in 3D the earliest peak of at least half the highest within 20 ms
before it, since floor and ceiling reflections can beat the direct sound), refined by parabolic
interpolation:
    f_ij = c * arrival_ij = |r_i - s_j| + c * (emission time_j + filter delay),
i.e. TDOA data with one unknown offset per source. A peak weaker than `--min-peak` times the
correlation's RMS is a missed detection (NaN); reflections and overlapping sources that beat the direct
path give gross errors. Nothing is planted: gaps and outliers come from the signal chain.
The matrix is calibrated with sigma estimated (`calibrate(F, dim=3)` in 3D), and compared with the
simulator's ground truth after the best rigid alignment (solvers.metrics; reflections allowed), over the
nodes it placed (`unplaced` counts those it reports as not determined), and each node's error in units
of its reported standard deviation (`max_err_over_std`).
In 3D the table also gives the Cramer-Rao bound of each network (`crb_position_rms_m`,
solvers.metrics.cramer_rao_position_rms): the least rms position error after alignment that any
unbiased estimator can reach for the placed nodes from the entries the calibration kept (its inliers),
at the noise level of the signal chain measured against the simulator's truth (`inlier_noise_m`, the
rms of F - F_true over the measured entries that are not gross errors, |F - F_true| <= 10 cm; not the
calibration's own estimate `sigma_estimated_m`, so that an estimator cannot lower its own bar);
`rms_over_crb` is the calibration's error over it. `crb_clean_entries_m` is the bound of all nodes
from every measured entry without a gross error: what the signal chain allows (inf: some node is heard
correctly too rarely for any estimator to place it). The md ends with the count of rooms that place
every node within 2 x their bound.
Writes tables/NAME.csv and .md (one row per room; NAME defaults to room_simulation, room_simulation3d).

GCC-PHAT is the library's (solvers.audio.gcc_phat; why not scipy's or pyroomacoustics': its docstring),
here against the emitted waveform; `tdoa-workbench tdoa` measures without it (scripts/audio_room.py).

Needs the optional extra: pip install -e ".[audio]"  (pyroomacoustics).
Usage: OPENBLAS_NUM_THREADS=1 python scripts/room_simulation.py [--dim 2|3] [--rooms 5] [--seed 0]
       [--rt60 0.3 | --rt60 0.3:0.6] [--snr 20] [--signal noise|chirp] [--name room_simulation]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import sys  # noqa: E402
from dataclasses import dataclass  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from solvers.audio import gcc_phat  # noqa: E402
from solvers.calibration import calibrate  # noqa: E402
from solvers.metrics import align_rigid, cramer_rao_position_rms, standardised_node_errors  # noqa: E402
from solvers.synthetic import Network  # noqa: E402

FS = 16_000
SIGNALS = ("noise", "chirp")


@dataclass(frozen=True)
class RoomSetup:
    """What differs between the 2D and the 3D room (measured choices, see docs/room-simulation-3d.md).

    size : room dimensions in metres
    burst : seconds of sound per source
    emission_window : emission times are uniform in [0, emission_window) seconds
    max_delay : the GCC-PHAT lag search covers [0, max_delay] seconds
    search_back : seconds before the highest GCC-PHAT peak searched for an earlier peak of at least
        half its height (the direct sound; 0 = take the highest peak)
    snr_at_microphones : True: the SNR is that of the noise-free recordings at the microphones (mean
        power over the emission window); False: nominal, noise power = source power / 20 x 10^(-SNR/10)
    """

    size: tuple[float, ...]
    burst: float
    emission_window: float
    max_delay: float
    search_back: float
    snr_at_microphones: bool


# 2D: the setup of tables/room_simulation*.md (kept byte-identical). 3D: with 0.1 s bursts overlapping in
# 0.5 s, 30-60 % of the pairs fell below the detection threshold and 4-16 % of the rest were wrong peaks
# (two rooms, RT60 0.45 s, SNR 20 dB), and floor and ceiling reflections beat the direct sound in 18 % of
# the pairs; 0.3 s bursts within 3 s and a 20 ms search back for the direct sound: every pair detected,
# 1.7 % wrong peaks.
SETUPS = {2: RoomSetup((10.0, 8.0), 0.1, 0.5, 1.0, 0.0, False),
          3: RoomSetup((8.0, 6.0, 3.0), 0.3, 3.0, 3.5, 0.02, True)}


def emitted_signal(rng: np.random.Generator, kind: str, seconds: float) -> np.ndarray:
    """One source's waveform: white noise, or a linear chirp between a random low (100-500 Hz) and high
    (5-7.5 kHz) frequency, up or down at random (distinct sources, distinct sweeps)."""
    samples = int(seconds * FS)
    if kind == "noise":
        return rng.standard_normal(samples)
    from scipy.signal import chirp

    low, high = rng.uniform(100.0, 500.0), rng.uniform(5000.0, 7500.0)
    f0, f1 = (low, high) if rng.random() < 0.5 else (high, low)
    t = np.arange(samples) / FS
    return chirp(t, f0=f0, t1=seconds, f1=f1) * np.hanning(samples) ** 0.25  # soft edges, no clicks


def gcc_phat_delay(recording: np.ndarray, reference: np.ndarray, fs: int, max_delay: float,
                   search_back: float = 0.0) -> tuple[float, float]:
    """(delay in seconds of `reference` within `recording`, peak / RMS of the correlation).

    solvers.audio.gcc_phat over the lags 0..max_delay (the emitted burst cannot arrive early);
    search_back > 0: the earliest local maximum of at least half the highest peak's height within
    search_back seconds before it is taken instead (a reflection can beat the direct sound, never
    precede it); the peak / RMS is that of the highest peak.
    """
    peak = gcc_phat(recording, reference, max_lag=int(max_delay * fs), min_lag=0, search_back=int(search_back * fs))
    return peak.lag / fs, peak.top / peak.rms


def simulate_room(rng: np.random.Generator, mics: int, sources: int, rt60: float, snr_db: float,
                  setup: RoomSetup = SETUPS[2], signal: str = "noise"):
    """One room (2D or 3D after `setup.size`): returns (F with NaN for missed detections, GCC-PHAT
    peak / RMS of every pair, true Network in metres)."""
    import pyroomacoustics as pra

    size = setup.size
    noise_seed = int(rng.integers(2**31))
    # Sabine's formula needs a volume: a 2D room gets a 3 m height
    absorption, max_order = pra.inverse_sabine(rt60, list(size) + [3.0] if len(size) == 2 else list(size))
    c = pra.constants.get("c")
    margin = 0.5
    mic_pos = np.column_stack([rng.uniform(margin, side - margin, mics) for side in size])
    src_pos = np.column_stack([rng.uniform(margin, side - margin, sources) for side in size])
    emit = rng.uniform(0.0, setup.emission_window, sources)
    signals = [emitted_signal(rng, signal, setup.burst) for _ in range(sources)]
    power = float(np.mean([np.mean(s**2) for s in signals]))
    nominal = None if setup.snr_at_microphones else power * 10 ** (-snr_db / 10) / 20.0
    room = pra.ShoeBox(list(size), fs=FS, materials=pra.Material(absorption), max_order=min(max_order, 30),
                       sigma2_awgn=nominal)
    for j in range(sources):
        room.add_source(src_pos[j], signal=signals[j], delay=emit[j])
    room.add_microphone_array(pra.MicrophoneArray(mic_pos.T, FS))
    pra.random.seed(noise_seed)  # the microphone noise comes from pyroomacoustics' own generator
    room.simulate()
    rec = room.mic_array.signals
    if setup.snr_at_microphones:
        active = int((setup.emission_window + setup.burst) * FS)
        noise_power = np.mean(rec[:, :active] ** 2) * 10 ** (-snr_db / 10)
        rec = rec + np.sqrt(noise_power) * np.random.default_rng(noise_seed).standard_normal(rec.shape)
    # The simulator starts a source at floor(delay * fs) samples, and its fractional-delay filter
    # delays every arrival by the same number of samples.
    emit = np.floor(emit * FS) / FS
    filter_delay = (pra.constants.get("frac_delay_length") // 2) / FS
    F = np.full((mics, sources), np.nan)
    peaks = np.zeros((mics, sources))
    for i in range(mics):
        for j in range(sources):
            delay, peak = gcc_phat_delay(rec[i], signals[j], FS, setup.max_delay, setup.search_back)
            peaks[i, j] = peak
            F[i, j] = c * delay
    net = Network(mic_pos, src_pos, c * (emit + filter_delay))
    return F, peaks, net


def run(seed: int, mics: int, sources: int, rt60: tuple[float, float], snr_db: float, min_peak: float,
        dim: int = 2, signal: str = "noise") -> dict:
    """One room, one table row. rt60 = (low, high): drawn uniformly per room when high > low."""
    rng = np.random.default_rng(seed)
    rt60_s = rt60[0] if rt60[1] <= rt60[0] else round(float(rng.uniform(*rt60)), 2)
    F_raw, peaks, net = simulate_room(rng, mics, sources, rt60_s, snr_db, SETUPS[dim], signal)
    F = np.where(peaks >= min_peak, F_raw, np.nan)
    F_true = net.measurements()
    measured = np.isfinite(F)
    gross = measured & (np.abs(F - F_true) > 0.1)  # > 10 cm: not noise but a wrong peak
    noise = float(np.sqrt(np.mean((F - F_true)[measured & ~gross] ** 2)))
    res = calibrate(F, seed=seed) if dim == 2 else calibrate(F, dim=3, seed=seed)
    row = {"seed": seed, "mics": mics, "sources": sources}
    if dim == 3 or signal != "noise":
        row["signal"] = signal
    row.update({"rt60_s": rt60_s, "snr_db": snr_db,
                "missing": round(float(1 - measured.mean()), 3), "gross_errors": int(gross.sum()),
                "inlier_noise_m": float(f"{noise:.3g}"), "status": res.status, "warnings": len(res.warnings)})
    X = np.vstack([res.receivers, res.transmitters])
    Y = np.vstack([net.receivers, net.transmitters])
    placed = np.isfinite(X[:, 0])
    row["unplaced"] = int((~placed).sum())
    if dim == 3:
        row["kept"] = f"{int(res.inliers.sum())}/{int(measured.sum())}"  # a failed result has no inliers
    if res.status == "failed" or placed.sum() < 3:
        row.update({"flagged": "", "false_rejects": "", "rms_position_err_m": "", "relative_position_err": "",
                    "offset_rms_err_m": "", "sigma_estimated_m": "", "max_err_over_std": ""})
        if dim == 3:
            row.update({"crb_position_rms_m": "", "rms_over_crb": "", "crb_clean_entries_m": ""})
        return row
    # Errors over the placed nodes (a node the data do not fix is reported as not placed).
    aligned = align_rigid(X[placed], Y[placed]).apply(X[placed])
    spread = np.linalg.norm(Y[placed] - Y[placed].mean(axis=0))
    off = np.isfinite(res.offsets)
    rms = float(np.sqrt(np.mean(np.sum((aligned - Y[placed]) ** 2, axis=1))))
    row.update({
        "flagged": f"{int((gross & ~res.inliers).sum())}/{int(gross.sum())}",
        "false_rejects": int((measured & ~gross & ~res.inliers).sum()),
        "rms_position_err_m": float(f"{rms:.3g}"),
        "relative_position_err": float(f"{np.linalg.norm(aligned - Y[placed]) / spread:.3g}"),
        "offset_rms_err_m": float(f"{np.sqrt(np.mean((res.offsets[off] - net.offsets[off]) ** 2)):.3g}"),
        "sigma_estimated_m": float(f"{res.sigma:.3g}"),
        # the largest node error in units of its reported std (in the result's gauge): honest if small
        "max_err_over_std": float(f"{np.max(standardised_node_errors(res, net), initial=0.0):.3g}"),
    })
    if dim == 3:
        # The bound of the placed nodes from the entries the calibration kept, at the noise level they
        # really have; and of every node from every entry without a gross error (what the signal chain
        # allows: inf when a node has too few, no estimator could place it).
        pr, pt = placed[:mics], placed[mics:]
        crb = cramer_rao_position_rms(net.receivers[pr], net.transmitters[pt], res.inliers[np.ix_(pr, pt)], noise)
        clean = cramer_rao_position_rms(net.receivers, net.transmitters, measured & ~gross, noise)
        row.update({"crb_position_rms_m": float(f"{crb:.3g}"),
                    "rms_over_crb": float(f"{rms / crb:.3g}") if np.isfinite(crb) else "",
                    "crb_clean_entries_m": float(f"{clean:.3g}")})
    return row


def meets_target(row: dict) -> bool:
    """The issue's target for a 3D room: every node placed, rms position error <= 2 x its Cramer-Rao bound."""
    return row["unplaced"] == 0 and row["rms_over_crb"] != "" and row["rms_over_crb"] <= 2.0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dim", type=int, choices=(2, 3), default=2,
                    help="2: a 10 x 8 m room, positions in a plane (default); 3: an 8 x 6 x 3 m room")
    ap.add_argument("--rooms", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--mics", type=int, default=12)
    ap.add_argument("--sources", type=int, default=10)
    ap.add_argument("--rt60", default=None,
                    help="reverberation time in seconds, or LOW:HIGH drawn per room (default 0.3; --dim 3: 0.3:0.6)")
    ap.add_argument("--snr", type=float, default=20.0, help="signal-to-noise ratio in dB at the microphones (default 20)")
    ap.add_argument("--min-peak", type=float, default=8.0, help="GCC-PHAT peak / RMS below which a pair is missing")
    ap.add_argument("--signal", choices=SIGNALS, default="noise", help="what the sources emit (default noise)")
    ap.add_argument("--name", default=None,
                    help="output tables/NAME.csv and .md (default room_simulation; --dim 3: room_simulation3d)")
    args = ap.parse_args(argv)
    rt60_text = args.rt60 or ("0.3" if args.dim == 2 else "0.3:0.6")
    try:
        low, _, high = rt60_text.partition(":")
        rt60 = (float(low), float(high or low))
    except ValueError:
        ap.error(f"--rt60 must be a number or LOW:HIGH, got {rt60_text!r}")
    name = args.name or ("room_simulation" if args.dim == 2 else "room_simulation3d")
    try:
        import pyroomacoustics  # noqa: F401
    except ImportError:
        print("room_simulation needs the audio extra: pip install -e \".[audio]\"", file=sys.stderr)
        return 2
    rows = []
    for k in range(args.rooms):
        row = run(args.seed + k, args.mics, args.sources, rt60, args.snr, args.min_peak, args.dim, args.signal)
        rows.append(row)
        print(row, flush=True)
    out = os.path.join(ROOT, "tables", name)
    with open(out + ".csv", "w", newline="") as handle:
        w = csv.DictWriter(handle, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    keys = list(rows[0])
    with open(out + ".md", "w") as handle:
        handle.write("| " + " | ".join(keys) + " |\n|" + "---|" * len(keys) + "\n")
        for r in rows:
            handle.write("| " + " | ".join(str(r[k]) for k in keys) + " |\n")
        if args.dim == 3:
            met = sum(meets_target(r) for r in rows)
            handle.write(f"\nRooms with every node placed and rms position error <= 2 x its Cramer-Rao bound: "
                         f"{met} of {len(rows)}.\n")
    print(f"wrote {out}.csv and {out}.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
