"""Straight-line C code of a solver's tapes, compiled once per machine, for the batched tracker.

The tape interpreter (:func:`tape_kernel.run_tape`) pays a few ns of dispatch per instruction and
keeps every register in memory; the same tape written out as C (every register write a new local,
four paths per pass in vector registers) runs 2.5-3x faster for a full batch of paths and 5-10x
faster for the few paths of the lock step's tail (``scripts/bench_tracker_floor.py``). The code does
the interpreter's operations in the same order and is compiled without contracting multiply-adds
(``-ffp-contract=off``), so its results are bit-identical to the interpreter's: a solver gives the same
roots with or without it.

:func:`addresses` returns the three tapes' (full, Newton, residual) entry points for
:func:`tape_kernel.track`, or zeros while the library is not built (the interpreter runs then). The
library is compiled by the system's C compiler (``$CC``, ``cc`` or ``gcc``) in a background thread the
first time a solver asks, into the user's cache directory under a name hashed from the source, the
flags and the CPU, so the first solve in a fresh environment does not wait for it; later calls, and
every later process, use it. ``TDOA_WORKBENCH_NATIVE=off`` (as for the F4 kernels) or no compiler:
the interpreter only.
"""
from __future__ import annotations

import ctypes
import os
import platform
import threading
import zlib
from pathlib import Path

import numpy as np

from .tape_kernel import OPCODES

__all__ = ["FLAGS", "WIDTH", "addresses", "describe", "source"]

#: Paths per pass (one vector of doubles); the tracker's capacity is a multiple of it.
WIDTH = 4
FLAGS = ("-O2", "-march=native", "-ffp-contract=off", "-shared", "-fPIC", "-std=gnu99")
DISABLE_ENV = "TDOA_WORKBENCH_NATIVE"
KINDS = ("full", "newton", "residual")

_OPS = {  # opcode -> (real, imaginary) of d from a, b, c and the immediate w, in the interpreter's order
    "MULADD": ("{cr} + {w} * ({ar} * {br} - {ai} * {bi})", "{ci} + {w} * ({ar} * {bi} + {ai} * {br})"),
    "AXPY": ("{ar} + {w} * {br}", "{ai} + {w} * {bi}"),
    "MUL": ("{ar} * {br} - {ai} * {bi}", "{ar} * {bi} + {ai} * {br}"),
    "ADD": ("{ar} + {br}", "{ai} + {bi}"),
    "SUB": ("{ar} - {br}", "{ai} - {bi}"),
    "CMUL": ("{w} * {ar}", "{w} * {ai}"),
    "SQR": ("{ar} * {ar} - {ai} * {ai}", "2.0 * {ar} * {ai}"),
    "CADD": ("{ar} + {w}", "{ai}"),
    "NEG": ("-{ar}", "-{ai}"),
    "CONST": ("{z} + {w}", "{z}"),
}


def source(tape, name: str, width: int = WIDTH) -> str:
    """C source of ``void name(long P, long C, const double *R, const double *I, double *OR, double *OI)``:
    the tape on points 0..P-1 of the interpreter's layout (register or output row r, point p at r C + p;
    inputs read from R, I, outputs written to OR, OI), ``width`` points per pass (P is rounded up to a
    multiple of it: the arrays must have the room)."""
    T = "double" if width == 1 else f"v{width}d"
    lines = [] if width == 1 else [f"typedef double {T} __attribute__((vector_size({8 * width})));"]
    lines.append(f"static void {name}_pass(long p, long C, const double *restrict R, const double *restrict I, "
                 "double *restrict OR, double *restrict OI) {")
    local, count = {}, 0

    def load(dst: str, src: str) -> str:
        if width == 1:
            return f"{T} {dst} = {src};"
        return f"{T} {dst}; __builtin_memcpy(&{dst}, &{src}, sizeof({T}));"

    def store(dst: str, src: str) -> str:
        return f"{dst} = {src};" if width == 1 else f"__builtin_memcpy(&{dst}, &{src}, sizeof({T}));"

    for r in range(tape.n_inputs):
        local[r] = f"{r}_0"
        lines.append(f"  {load(f'r{r}_0', f'R[{r} * C + p]')} {load(f'i{r}_0', f'I[{r} * C + p]')}")
    zero = "0.0" if width == 1 else f"(({T}){{0}})"
    for k, (op, d, a, b, c) in enumerate(tape.code):
        op = OPCODES[op]
        if op == "OUT":
            lines.append(f"  {store(f'OR[{d} * C + p]', f'r{local[a]}')} {store(f'OI[{d} * C + p]', f'i{local[a]}')}")
            continue
        f = {"w": repr(float(tape.imm[k])), "z": zero}
        for key, reg in (("a", a), ("b", b), ("c", c)):
            if reg in local:
                f[key + "r"], f[key + "i"] = f"r{local[reg]}", f"i{local[reg]}"
        count += 1
        local[d] = f"{d}_{count}"
        re, im = _OPS[op]
        lines.append(f"  {T} r{local[d]} = {re.format(**f)}, i{local[d]} = {im.format(**f)};")
    lines.append("}")
    lines.append(f"void {name}(long P, long C, const double *R, const double *I, double *OR, double *OI) {{\n"
                 f"  for (long p = 0; p < P; p += {width}) {name}_pass(p, C, R, I, OR, OI);\n}}")
    return "\n".join(lines)


_LOCK = threading.Lock()
_BUILT: dict[int, tuple] = {}  # source hash -> (library, addresses) once loaded
_PENDING: dict[int, threading.Thread] = {}
_WHY: list[str] = []
_KEYS: dict[int, tuple] = {}  # id(tapes) -> (tapes, source hash, source): the source is written once per tapes


def _cache_dir() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "tdoa-workbench" / "tapes"


def _cpu() -> str:
    """What -march=native compiles for: the CPU's model and flags (a cache shared between machines must
    not hand one machine's instructions to another)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            text = fh.read()
        keep = [ln for ln in text.splitlines() if ln.startswith(("model name", "flags", "Features", "CPU part"))]
        return "\n".join(sorted(set(keep)))
    except OSError:
        return platform.processor() + platform.machine()


def _compile(text: str, path: Path) -> None:
    """Build ``path`` from the C source ``text`` (atomically: a whole file or none)."""
    import shutil
    import subprocess
    import tempfile

    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        _WHY.append("no C compiler found (cc, gcc or $CC)")
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=path.parent) as tmp:
        c_file, so_file = Path(tmp) / "tapes.c", Path(tmp) / "tapes.so"
        c_file.write_text(text, encoding="utf-8")
        done = subprocess.run([compiler, *FLAGS, "-o", str(so_file), str(c_file)], capture_output=True, timeout=600)
        if done.returncode:
            lines = done.stderr.decode(errors="replace").strip().splitlines()
            _WHY.append(f"{compiler} failed on a tape: {lines[0] if lines else done.returncode}")
            return
        os.replace(so_file, path)


def _load(key: int, path: Path) -> None:
    lib = ctypes.CDLL(str(path))
    _BUILT[key] = (lib, np.array([ctypes.cast(getattr(lib, f"tape_{kind}"), ctypes.c_void_p).value for kind in KINDS],
                                 dtype=np.int64))


def _build(key: int, text: str, path: Path) -> None:
    try:
        if not path.exists():
            _compile(text, path)
        if path.exists():
            with _LOCK:
                _load(key, path)
    except (OSError, ValueError) as exc:  # subprocess errors are OSErrors; a broken library too
        _WHY.append(f"the tapes' C code could not be built or loaded: {exc}")
    finally:
        with _LOCK:
            _PENDING.pop(key, None)


def addresses(tapes, wait: bool = False) -> np.ndarray:
    """Entry points (full, Newton, residual) of the tapes' compiled code, or zeros (the interpreter) while
    it is being built (in the background: ``wait`` blocks until it is), without a compiler or with
    ``TDOA_WORKBENCH_NATIVE=off``."""
    none = np.zeros(len(KINDS), dtype=np.int64)
    if os.environ.get(DISABLE_ENV, "").lower() in ("off", "0", "no"):
        return none
    known = _KEYS.get(id(tapes))
    if known is None or known[0] is not tapes:  # (an id can be reused after its object is gone)
        text = "\n".join(source(getattr(tapes, kind), f"tape_{kind}") for kind in KINDS)
        known = _KEYS[id(tapes)] = (tapes, zlib.crc32((text + " ".join(FLAGS) + _cpu()).encode()), text)
    key = known[1]
    if key in _BUILT:
        return _BUILT[key][1]
    with _LOCK:
        if key in _BUILT:
            return _BUILT[key][1]
        path = _cache_dir() / f"tapes-{key:08x}.so"
        thread = _PENDING.get(key)
        if thread is None:
            if path.exists():  # built by an earlier process: load now
                try:
                    _load(key, path)
                    return _BUILT[key][1]
                except OSError as exc:
                    _WHY.append(f"{path} did not load: {exc}")
                    return none
            thread = threading.Thread(target=_build, args=(key, known[2], path), daemon=True)
            _PENDING[key] = thread
            thread.start()
    if wait:
        thread.join()
        return _BUILT[key][1] if key in _BUILT else none
    return none


def describe(tapes) -> str:
    """One line: whether this process evaluates the tapes by compiled code or by the interpreter, and why."""
    if addresses(tapes, wait=True).any():
        return "compiled straight-line code"
    return f"the tape interpreter ({_WHY[-1] if _WHY else 'compiled code unavailable'})"
