"""Long recordings streamed: peak memory and time of `tdoa` on a 10-minute 16-channel 48 kHz file.

Synthesises (in a temporary directory, deleted afterwards, never committed) a 24-bit WAV file of
`--minutes` minutes, `--channels` channels at `--rate` Hz, written block by block: white noise at
-60 dB full scale and, every `--spacing` seconds, a 30 ms noise burst from a random point in a
9 x 7 x 3 m room heard by every microphone at its free-field delay (fractional, no reverberation: this
measures the reading and the analysis' cost, not their accuracy; tables/audio3d does that). Then runs,
each in its own process (its peak resident memory from os.wait4, the wall time around it):

  reference   the same analysis of a `--ref-minutes` file read whole into memory (read_recording with
              stream=False), `tdoa --no-guide` as a library call: the way before streaming
  streamed    the same short file streamed (stream=True): same matrix, less memory
  long        `tdoa-workbench tdoa FILE --no-guide` on the long file (streamed, as the reader chooses)
  long_guided `tdoa-workbench tdoa FILE` (the first pass, its calibration and the guided pass) unless
              --no-guided

and prints each run's peak RSS (MB), wall time and CPU time (user + system, s: what the run cost whatever
else the machine ran), events and entries, and the ratios of the streamed
runs against the reference (memory per minute of audio). The figures go to the untracked
tables/audio_stream.timing.json (runtimes are run facts, never committed). The machine is shared:
`uptime`'s load average is recorded beside the times.

Usage: python scripts/bench_audio_stream.py [--minutes 10] [--channels 16] [--rate 48000] [--spacing 2]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

SPEED = 343.0
BURST = 0.03  # seconds


def synthesise(path: str, minutes: float, channels: int, rate: int, spacing: float, seed: int = 0) -> int:
    """Write the recording block by block (bounded memory); returns the number of bursts."""
    import soundfile

    rng = np.random.default_rng(seed)
    frames = int(minutes * 60 * rate)
    mics = rng.uniform((0.5, 0.5, 0.5), (8.5, 6.5, 2.5), (channels, 3))
    onsets = np.arange(1.0, minutes * 60 - 1.0, spacing)
    pad = 1 << int(np.ceil(np.log2(BURST * rate + 12 / SPEED * rate + 64)))  # the burst and the room's largest delay
    f = np.fft.rfftfreq(pad)
    bursts = []  # (start frame, (channels, pad) waveform)
    for onset in onsets:
        source = rng.uniform((0.5, 0.5, 0.5), (8.5, 6.5, 2.5))
        delays = np.linalg.norm(mics - source, axis=1) / SPEED * rate  # samples
        burst = np.zeros(pad)
        burst[: int(BURST * rate)] = rng.standard_normal(int(BURST * rate)) * np.hanning(int(BURST * rate))
        spectrum = np.fft.rfft(burst)
        wave = np.fft.irfft(spectrum[None, :] * np.exp(-2j * np.pi * f[None, :] * delays[:, None]), pad, axis=1)
        bursts.append((int(onset * rate), 0.3 * wave / np.max(np.abs(wave))))
    block = 1 << 16
    with soundfile.SoundFile(path, "w", rate, channels, subtype="PCM_24") as out:
        k = 0
        for a in range(0, frames, block):
            b = min(frames, a + block)
            x = 1e-3 * rng.standard_normal((channels, b - a))
            while k < len(bursts) and bursts[k][0] + pad <= a:
                k += 1
            for start, wave in bursts[k:]:
                if start >= b:
                    break
                lo, hi = max(a, start), min(b, start + pad)
                x[:, lo - a: hi - a] += wave[:, lo - start: hi - start]
            out.write(x.T)
    return len(bursts)


LIBRARY = """
import sys, json
import numpy as np
from solvers.audio import tdoa_matrix
from solvers.recording import read_recording
rec = read_recording(sys.argv[1], stream=sys.argv[2] == "stream")
tm = tdoa_matrix(rec)
print(json.dumps({"events": len(tm.events), "entries": int(np.isfinite(tm.F).sum()), "size": int(tm.F.size),
                  "streamed": rec.samples is None}))
"""


def with_rss(argv: list[str]) -> dict:
    """Run argv in its own process: its wall time, peak resident memory (MB, os.wait4's rusage of that child
    alone), exit status and the last lines of its output."""
    start = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    out_chunks, err_chunks = [], []

    def drain(stream, into):
        for chunk in iter(lambda: stream.read(65536), b""):
            into.append(chunk)

    threads = [threading.Thread(target=drain, args=(proc.stdout, out_chunks)),
               threading.Thread(target=drain, args=(proc.stderr, err_chunks))]
    for t in threads:
        t.start()
    _, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - start
    for t in threads:
        t.join()
    proc.returncode = os.waitstatus_to_exitcode(status)
    out, err = b"".join(out_chunks).decode(), b"".join(err_chunks).decode()
    return {"seconds": round(seconds, 1), "cpu_seconds": round(usage.ru_utime + usage.ru_stime, 1),
            "peak_rss_mb": round(usage.ru_maxrss / 1024, 1), "code": proc.returncode,
            "out": out.strip().splitlines()[-1] if out.strip() else "",
            "err": err.strip().splitlines()[-1] if err.strip() else ""}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--ref-minutes", type=float, default=1.0)
    ap.add_argument("--channels", type=int, default=16)
    ap.add_argument("--rate", type=int, default=48_000)
    ap.add_argument("--spacing", type=float, default=2.0, help="seconds between bursts")
    ap.add_argument("--no-guided", action="store_true", help="skip the full tdoa (first pass, calibration, guided)")
    ap.add_argument("--out", default=os.path.join(ROOT, "tables", "audio_stream.timing.json"))
    args = ap.parse_args()
    python = sys.executable
    cli = [python, "-m", "solvers.cli"]
    record: dict = {"minutes": args.minutes, "channels": args.channels, "rate": args.rate, "spacing_s": args.spacing,
                    "uptime_before": subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()}
    with tempfile.TemporaryDirectory() as tmp:
        short, long = os.path.join(tmp, "short.wav"), os.path.join(tmp, "long.wav")
        t0 = time.perf_counter()
        record["short_bursts"] = synthesise(short, args.ref_minutes, args.channels, args.rate, args.spacing)
        record["long_bursts"] = synthesise(long, args.minutes, args.channels, args.rate, args.spacing, seed=1)
        record["synthesis_s"] = round(time.perf_counter() - t0, 1)
        record["long_file_mb"] = round(os.path.getsize(long) / 2**20, 1)
        print(f"synthesised {args.ref_minutes:g} and {args.minutes:g} min ({record['long_file_mb']} MB) in "
              f"{record['synthesis_s']} s", file=sys.stderr, flush=True)
        runs = {"reference": [python, "-c", LIBRARY, short, "whole"],
                "streamed": [python, "-c", LIBRARY, short, "stream"],
                "long": cli + ["tdoa", long, "--no-guide", "--out", os.path.join(tmp, "long.csv")]}
        if not args.no_guided:
            runs["long_guided"] = cli + ["tdoa", long, "--out", os.path.join(tmp, "guided.csv")]
        for name, argv in runs.items():
            record[name] = with_rss(argv)
            print(f"{name}: {record[name]}", file=sys.stderr, flush=True)
    record["uptime_after"] = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    ref, streamed = record["reference"], record["streamed"]
    record["ratios"] = {"streamed_over_reference_rss": round(streamed["peak_rss_mb"] / ref["peak_rss_mb"], 3),
                        "long_over_reference_rss": round(record["long"]["peak_rss_mb"] / ref["peak_rss_mb"], 3),
                        "long_over_reference_seconds_per_minute": round(
                            record["long"]["seconds"] / args.minutes / (ref["seconds"] / args.ref_minutes), 3)}
    with open(args.out, "w", encoding="utf-8") as handle:
        json.dump(record, handle, indent=1)
        handle.write("\n")
    print(json.dumps(record["ratios"]), file=sys.stderr)
    print(f"wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
