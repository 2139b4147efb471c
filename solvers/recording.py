"""The one reader of recordings: audio files (soundfile: WAV, FLAC, OGG, AIFF, ... at any bit depth) -> a
:class:`Recording` of channels, read whole or streamed in blocks with bounded memory, and the words for what is
wrong with a file (no data, a mono file, NaN samples) or worth a warning (clipping, 8 bits), the same for
`tdoa` and `calibrate`. :mod:`solvers.audio` turns a recording into a measurement matrix.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, replace

import numpy as np

__all__ = ["AUDIO_MAGIC", "BLOCK_FRAMES", "STREAM_ABOVE", "Recording", "RecordingError", "is_recording", "no_data",
           "read_recording", "read_signal"]

#: The first bytes of the audio containers soundfile reads that `calibrate` recognises as a recording.
AUDIO_MAGIC = (b"RIFF", b"RIFX", b"RF64", b"fLaC", b"FORM", b"OggS", b"caff", b"\x2enb")


class RecordingError(ValueError):
    """A recording that cannot be read or analysed; the message is one line naming the file."""


#: Frames per block when a file is scanned or streamed (16 channels: 8 MB of float64).
BLOCK_FRAMES = 1 << 16

#: A recording larger than this (bytes of float64 samples) is streamed from its files: only the blocks an
#: analysis needs are in memory (the frame power, then each event's segment).
STREAM_ABOVE = 256 << 20

#: Bits of the integer sample formats whose full scale is known (libsndfile's subtype names).
_PCM_BITS = {"PCM_S8": 8, "PCM_U8": 8, "PCM_16": 16, "PCM_24": 24, "PCM_32": 32}


@dataclass(frozen=True)
class Recording:
    """Samples of every channel on one clock.

    samples : (channels, frames) float64, or None for a recording streamed from its files (`files`)
    rate : sample rate in Hz
    channels : one name per channel (the file's stem per file, or 1, 2, ... within one file)
    source : the file name(s), for messages
    notes : what the reader found that a user should know (channels trimmed to the shortest file, clipping,
        8-bit samples)
    files : a streamed recording's files, (path, channels) each, read block by block (:meth:`read`)
    length : a streamed recording's frames (every file trimmed to it)

    Every analysis reads through :meth:`read` and :meth:`blocks`, in memory or streamed alike.
    """

    samples: np.ndarray | None
    rate: int
    channels: tuple[str, ...]
    source: str
    notes: tuple[str, ...] = ()
    files: tuple[tuple[str, int], ...] = ()
    length: int = 0

    @property
    def frames(self) -> int:
        return self.samples.shape[1] if self.samples is not None else self.length

    @property
    def seconds(self) -> float:
        return self.frames / self.rate

    def read(self, start: int, stop: int) -> np.ndarray:
        """(channels, stop - start) float64: the frames start..stop (clipped to the recording)."""
        start, stop = max(0, int(start)), min(self.frames, int(stop))
        if self.samples is not None:
            return self.samples[:, start:stop]
        import soundfile

        parts = [soundfile.read(path, start=start, stop=stop, dtype="float64", always_2d=True)[0].T
                 for path, _ in self.files]
        return np.vstack(parts) if len(parts) > 1 else parts[0]

    def blocks(self, size: int = BLOCK_FRAMES):
        """(start frame, (channels, <= size) block) over the whole recording, in order (bounded memory)."""
        if self.samples is not None:
            for a in range(0, self.frames, size):
                yield a, self.samples[:, a:a + size]
            return
        import soundfile

        handles = [soundfile.SoundFile(path) for path, _ in self.files]
        try:
            for a in range(0, self.frames, size):
                n = min(size, self.frames - a)
                parts = [h.read(n, dtype="float64", always_2d=True).T for h in handles]
                yield a, (np.vstack(parts) if len(parts) > 1 else parts[0])
        finally:
            for h in handles:
                h.close()


def is_recording(path: str) -> bool:
    """Whether `path` is an audio file (by its first bytes, not its name); False for '-' and unreadable paths."""
    if path == "-":
        return False
    try:
        with open(path, "rb") as handle:
            head = handle.read(4)
    except OSError:
        return False
    return head in AUDIO_MAGIC


def no_data(source: str, why: str = "empty file") -> str:
    """The one words for input without data, the same for a recording and a measurement CSV or system file
    (:func:`analysis.engine.io.read_input_bytes` says the same of a 0-byte file)."""
    return f"{source}: no data ({why})"


@dataclass
class _Scan:
    """What one pass over a file's blocks found, per channel: samples at full scale, non-finite samples and
    the first frame of one (-1: none)."""

    clipped: np.ndarray
    bad: np.ndarray
    first_bad: int = -1


def _open_one(path: str):
    """(soundfile info) of one file, or RecordingError with the words every verb uses."""
    try:
        import soundfile
    except ImportError:
        raise RecordingError("reading audio needs soundfile: pip install soundfile (a dependency of tdoa-workbench)") from None
    if not os.path.exists(path):
        raise RecordingError(f"cannot read {path}: no such file")
    if os.path.isdir(path):
        raise RecordingError(f"cannot read {path}: it is a directory")
    try:
        if os.path.getsize(path) == 0:
            raise RecordingError(no_data(path))
        info = soundfile.info(path)
    except OSError as exc:
        raise RecordingError(f"cannot read {path}: {exc.strerror or exc}") from None
    except (RuntimeError, soundfile.SoundFileError) as exc:  # libsndfile: not an audio file it knows
        raise RecordingError(f"cannot read {path} as audio: {' '.join(str(exc).split())}") from None
    if info.frames == 0:
        raise RecordingError(no_data(path, "no samples"))
    return info


def _full_scale(subtype: str) -> float:
    """The magnitude at and above which a sample of this format is at full scale: one step below 1 for
    integer formats (their positive maximum), 1 for float formats and the rest."""
    bits = _PCM_BITS.get(subtype)
    return 1.0 - 2.0 ** (1 - bits) if bits else 1.0


def _scan(recording: "Recording", full: np.ndarray) -> _Scan:
    """One pass over the recording's blocks: per channel, the samples at full scale (|x| >= full) and the
    non-finite ones."""
    m = len(recording.channels)
    scan = _Scan(np.zeros(m, np.int64), np.zeros(m, np.int64))
    for a, block in recording.blocks():
        finite = np.isfinite(block)
        if not finite.all():
            bad = (~finite).sum(axis=1)
            if scan.first_bad < 0:
                scan.first_bad = a + int(np.flatnonzero((~finite).any(axis=0))[0])
            scan.bad += bad
        with np.errstate(invalid="ignore"):
            scan.clipped += (np.abs(block) >= full[:, None]).sum(axis=1)
    return scan


def _percent(share: float) -> str:
    """A share as a percentage that never rounds a non-zero share to 0."""
    if share == 0:
        return "0 %"
    value = 100 * share
    return f"{value:.2g} %" if value >= 0.01 else "< 0.01 %"


def read_signal(path: str) -> tuple[np.ndarray, int]:
    """(samples, rate) of an emitted sound (`--signal FILE`): one channel, finite, not silent; the same
    words as read_recording for a missing, unreadable or empty file. Raises RecordingError (one line)."""
    import soundfile

    info = _open_one(path)
    if info.channels != 1:
        raise RecordingError(f"{path}: {info.channels} channels; the emitted signal is one channel")
    data, rate = soundfile.read(path, dtype="float64")
    if not np.all(np.isfinite(data)):
        raise RecordingError(f"{path}: {int(np.sum(~np.isfinite(data)))} samples are NaN or infinite: a signal needs "
                             "finite samples")
    if not np.any(data):
        raise RecordingError(f"{path}: every sample is zero: no signal to match")
    return data, int(rate)


def read_recording(paths, *, stream: bool | None = None) -> Recording:
    """Read one multichannel file, or one file per channel (every channel of each file, in order).

    Parameters
    ----------
    paths : a path or a sequence of paths (WAV, FLAC, or anything libsndfile reads)
    stream : True: leave the samples in the files, read block by block when analysed (bounded memory);
        False: read them into memory; None (default): stream when the samples take more than STREAM_ABOVE
        bytes as float64

    The files must share a sample rate; files of different lengths are trimmed to the shortest (a note
    says so). Every sample is scanned once, block by block: samples at full scale (clipping) and 8-bit
    formats are notes (a warning with the share of clipped samples per channel); a missing, unreadable or
    empty file, a rate mismatch, non-finite samples (NaN) or fewer than two channels in all raise
    RecordingError (one line).
    """
    paths = [paths] if isinstance(paths, str) else list(paths)
    if not paths:
        raise RecordingError("no recording given")
    infos = [_open_one(p) for p in paths]
    rates = {int(info.samplerate) for info in infos}
    if len(rates) > 1:
        listed = ", ".join(f"{p}: {int(info.samplerate)} Hz" for p, info in zip(paths, infos))
        raise RecordingError(f"the files have different sample rates ({listed}); resample them to one")
    rate = rates.pop()
    source = paths[0] if len(paths) == 1 else f"{paths[0]} (+{len(paths) - 1} files)"
    widths = [int(info.channels) for info in infos]
    if sum(widths) < 2:
        raise RecordingError(f"{source}: one channel; a time difference needs two or more (a multichannel file, "
                             "or one file per microphone)")
    lengths = [int(info.frames) for info in infos]
    frames = min(lengths)
    notes = ()
    if len(set(lengths)) > 1:
        notes = (f"files of {min(lengths)} to {max(lengths)} frames: trimmed to the shortest",)
    if len(paths) == 1:
        names = tuple(str(k + 1) for k in range(widths[0]))
    else:
        stems = [os.path.splitext(os.path.basename(p))[0] for p in paths]
        names = tuple(f"{stem}.{c + 1}" if w > 1 else stem for stem, w in zip(stems, widths) for c in range(w))
        if len(set(names)) < len(names):
            names = tuple(str(k + 1) for k in range(len(names)))
    streamed = Recording(None, rate, names, source, notes, tuple(zip(paths, widths)), frames)
    full = np.concatenate([np.full(w, _full_scale(info.subtype)) for w, info in zip(widths, infos)])
    scan = _scan(streamed, full)
    if scan.bad.any():
        which = ", ".join(names[c] for c in np.flatnonzero(scan.bad))
        raise RecordingError(f"{source}: {int(scan.bad.sum())} samples are NaN or infinite (channel(s) {which}; the "
                             f"first at {scan.first_bad / rate:.3f} s): a recording needs finite samples")
    eight = [p for p, info in zip(paths, infos) if _PCM_BITS.get(info.subtype) == 8]
    if eight:
        notes += (f"8-bit samples ({', '.join(eight)}): quantisation noise about 48 dB below full scale; quiet "
                  "sounds' time differences are the noisier",)
    if scan.clipped.any():
        shares = ", ".join(f"{names[c]} {_percent(scan.clipped[c] / frames)}" for c in np.flatnonzero(scan.clipped))
        rest = "" if scan.clipped.all() else "; the other channels none"
        notes += (f"warning: clipping: samples at full scale, the share per channel: {shares}{rest}; a clipped "
                  "sound's waveform and timing are distorted (record at a lower gain)",)
    if stream is None:
        stream = frames * len(names) * 8 > STREAM_ABOVE
    if stream:
        return replace(streamed, notes=notes)
    samples = np.empty((len(names), frames))
    for a, block in streamed.blocks():
        samples[:, a:a + block.shape[1]] = block
    return Recording(samples, rate, names, source, notes)
