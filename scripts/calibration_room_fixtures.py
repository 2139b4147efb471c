"""The guided TDOA matrices of five rooms of tables/audio3d_kinds, written as text fixtures for the calibration's
regression tests (tests/data/calibration_rooms/, read by tests/test_calibration_rooms.py).

Each room is `scripts/audio_kinds.py`'s `run(kind, condition, 10, 20[, given=True])`; its matrix is
`tdoa_guided(read_recording(wav), TdoaOptions(speed=c[, signal=sweep(kind, rate)]), dim=3, seed=0).matrix.F`, as
`tdoa_and_calibrate` makes it (the guided pass depends on the first calibration, so the matrices are those of the
code that wrote them: the fixtures are data, not a reproduction). Files per room NAME: NAME.F.csv (the matrix,
metres, "nan" missing), NAME.receivers.csv (the true microphones, metres). The docs/audio.md section "The
calibrations that fail with every entry right" describes them.

Usage: OPENBLAS_NUM_THREADS=1 python scripts/calibration_room_fixtures.py   (about 3 minutes)
Needs the optional extra: pip install -e ".[audio]" (pyroomacoustics).
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import sys  # noqa: E402
import tempfile  # noqa: E402
import zlib  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "scripts"))

import numpy as np  # noqa: E402

import audio_kinds  # noqa: E402  (scripts/audio_kinds.py: the rooms)
from solvers.audio import TdoaOptions  # noqa: E402
from solvers.audio_guided import tdoa_guided  # noqa: E402
from solvers.recording import read_recording  # noqa: E402

#: name -> (kind, condition index into audio_kinds.CONDITIONS, the sweep given)
ROOMS = {
    "log_sweep_16k_rt0.3": ("log_sweep", 0, False),
    "log_sweep_signal_16k_rt0.3": ("log_sweep", 0, True),
    "log_sweep_signal_16k_rt0.55": ("log_sweep", 1, True),
    "log_sweep_16k_rt0.55": ("log_sweep", 1, False),
    "clap_48k_rt0.8": ("clap", 5, False),
}
OUT = os.path.join(ROOT, "tests", "data", "calibration_rooms")


def guided_matrix(kind: str, condition: int, given: bool) -> tuple[np.ndarray, np.ndarray]:
    """(the guided matrix F, the true receivers) of one room of audio_kinds."""
    import soundfile

    rate, rt60, snr = audio_kinds.CONDITIONS[condition]
    rng = np.random.default_rng(zlib.crc32(f"{kind}/{condition}".encode()))
    m = int(rng.integers(6, 17))
    rec, net, c = audio_kinds.simulate(rng, kind, rate, m, 10, rt60, snr, 20)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "room.wav")
        soundfile.write(path, (rec / (1.05 * np.max(np.abs(rec)))).T, rate, subtype="PCM_24")
        recording = read_recording(path)
    options = TdoaOptions(speed=c, signal=audio_kinds.sweep(kind, rate) if given else None)
    return tdoa_guided(recording, options, dim=3, seed=0).matrix.F, net.receivers


def main() -> int:
    os.makedirs(OUT, exist_ok=True)
    for name, (kind, condition, given) in ROOMS.items():
        F, receivers = guided_matrix(kind, condition, given)
        np.savetxt(os.path.join(OUT, f"{name}.F.csv"), F, fmt="%.9f", delimiter=",")
        np.savetxt(os.path.join(OUT, f"{name}.receivers.csv"), receivers, fmt="%.9f", delimiter=",")
        print(f"{name}: {F.shape[0]} x {F.shape[1]}, {int(np.isnan(F).sum())} missing", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
