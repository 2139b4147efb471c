"""Straight-line C code of a solver's tapes and its LU, compiled once per machine, for the batched tracker.

The tape interpreter (:func:`tape_kernel.run_tape`) pays a few ns of dispatch per instruction and
keeps every register in memory; the same tape written out as C (every register write a new local,
four paths per pass in vector registers) runs 2.5-3x faster for a full batch of paths and 5-10x
faster for the few paths of the lock step's tail (``scripts/bench_tracker_floor.py``). The code does
the interpreter's operations in the same order and is compiled without contracting multiply-adds
(``-ffp-contract=off``), so its results are bit-identical to the interpreter's: a solver gives the same
roots with or without it. The same library holds the LU with partial pivoting of the N x N Jacobians
and its solves (:func:`lu_source`: the batched kernel's operations, four paths per pass in vector
registers; 1.3-1.4x the batched kernel for a full batch, 3-5x for a handful of paths).

:func:`addresses` returns the entry points (the three tapes, the LU, its solve) for
:func:`tape_kernel.track`, or zeros while the library is not built (the interpreter runs then). The
library is compiled by the system's C compiler (``$CC``, ``cc`` or ``gcc``) in a background thread the
first time a solver asks, into the cache directory (``analysis.paths.cache_dir("tapes")``) under a name
hashed from the source, the flags and the CPU, so the first solve in a fresh environment does not wait
for it; later calls, and every later process, use it. ``TDOA_WORKBENCH_NATIVE=off`` (as for the F4 kernels) or no compiler:
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

from analysis.native import DISABLE_ENV, disabled
from analysis.paths import cache_dir

from .tape_kernel import OPCODES, WIDTH

__all__ = ["DISABLE_ENV", "ENTRIES", "FLAGS", "WIDTH", "addresses", "describe", "lu_source", "source"]

FLAGS = ("-O2", "-march=native", "-ffp-contract=off", "-shared", "-fPIC", "-std=gnu99")
KINDS = ("full", "newton", "residual")
ENTRIES = ("tape_full", "tape_newton", "tape_residual", "lu_factor", "lu_solve")

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


def lu_source(N: int) -> str:
    """C source of ``lu_factor(P, C, Ar, Ai, base, piv, ok)`` and ``lu_solve(P, C, Ar, Ai, base, piv, br, bi)``
    for N x N matrices at rows base + i N + j of Ar, Ai (point p at column p, row stride C), four points
    per pass: :func:`tape_kernel._lu` and :func:`tape_kernel._solve` with the same operations in the same
    order (the pivot search and the interchanges lane by lane, the elimination in vector registers; four
    points per pass, as :data:`tape_kernel.WIDTH`)."""
    return f"""
#include <math.h>
typedef double v4d __attribute__((vector_size(32)));
typedef long v4l __attribute__((vector_size(32)));
#define N {N}
#define LD(a, r) ({{ v4d _v; __builtin_memcpy(&_v, &(a)[(r) * C + p], 32); _v; }})
#define ST(a, r, v) do {{ v4d _v = (v); __builtin_memcpy(&(a)[(r) * C + p], &_v, 32); }} while (0)
void lu_factor(long P, long C, double *restrict Ar, double *restrict Ai, long base, long *restrict piv,
                   unsigned char *restrict ok) {{
  for (long p = 0; p < P; p += 4) {{
    for (int l = 0; l < 4; l++) ok[p + l] = 1;
    for (int k = 0; k < N; k++) {{
      long kk = base + k * N + k;
      v4d ar = LD(Ar, kk), ai = LD(Ai, kk);
      v4d best = ar * ar + ai * ai;
      v4l q = {{k, k, k, k}};
      for (int i = k + 1; i < N; i++) {{
        long ik = base + i * N + k;
        v4d xr = LD(Ar, ik), xi = LD(Ai, ik);
        v4d a = xr * xr + xi * xi;
        v4l m = a > best;
        best = (v4d)((m & (v4l)a) | (~m & (v4l)best));
        q = (m & (v4l){{i, i, i, i}}) | (~m & q);
      }}
      double bestv[4];
      for (int l = 0; l < 4; l++) {{
        long c = p + l, qq = q[l];
        piv[k * C + c] = qq;
        if (qq != k) for (int j = k; j < N; j++) {{
          long u = (base + k * N + j) * C + c, w = (base + qq * N + j) * C + c;
          double t = Ar[u]; Ar[u] = Ar[w]; Ar[w] = t; t = Ai[u]; Ai[u] = Ai[w]; Ai[w] = t;
        }}
        double bb = best[l];
        if (!(bb > 0.0) || !isfinite(bb)) {{ ok[c] = 0; bb = 1e-300; }}
        bestv[l] = bb;
      }}
      v4d b; __builtin_memcpy(&b, bestv, 32);
      v4d fr = LD(Ar, kk) / b, fi = -LD(Ai, kk) / b;
      ST(Ar, kk, fr); ST(Ai, kk, fi);
      for (int i = k + 1; i < N; i++) {{
        long ik = base + i * N + k;
        v4d xr = LD(Ar, ik), xi = LD(Ai, ik);
        v4d yr = xr * fr - xi * fi, yi = xr * fi + xi * fr;
        ST(Ar, ik, yr); ST(Ai, ik, yi);
        for (int j = k + 1; j < N; j++) {{
          long ij = base + i * N + j, kj = base + k * N + j;
          v4d ar = LD(Ar, ij), ai = LD(Ai, ij), br = LD(Ar, kj), bi = LD(Ai, kj);
          ST(Ar, ij, ar - (yr * br - yi * bi)); ST(Ai, ij, ai - (yr * bi + yi * br));
        }}
      }}
    }}
  }}
}}
void lu_solve(long P, long C, const double *restrict Ar, const double *restrict Ai, long base,
                  const long *restrict piv, double *restrict br, double *restrict bi) {{
  for (long p = 0; p < P; p += 4) {{
    for (int k = 0; k < N; k++) {{
      for (int l = 0; l < 4; l++) {{
        long c = p + l, q = piv[k * C + c];
        double t = br[k * C + c]; br[k * C + c] = br[q * C + c]; br[q * C + c] = t;
        t = bi[k * C + c]; bi[k * C + c] = bi[q * C + c]; bi[q * C + c] = t;
      }}
      v4d kr = LD(br, k), ki = LD(bi, k);
      for (int i = k + 1; i < N; i++) {{
        long f = base + i * N + k;
        v4d a = LD(Ar, f), b = LD(Ai, f);
        ST(br, i, LD(br, i) - (a * kr - b * ki)); ST(bi, i, LD(bi, i) - (a * ki + b * kr));
      }}
    }}
    for (int i = N - 1; i >= 0; i--) {{
      v4d xr = LD(br, i), xi = LD(bi, i);
      for (int j = i + 1; j < N; j++) {{
        long f = base + i * N + j;
        v4d a = LD(Ar, f), b = LD(Ai, f), jr = LD(br, j), ji = LD(bi, j);
        xr = xr - (a * jr - b * ji); xi = xi - (a * ji + b * jr);
      }}
      long f = base + i * N + i;
      v4d dr = LD(Ar, f), di = LD(Ai, f);
      ST(br, i, xr * dr - xi * di); ST(bi, i, xr * di + xi * dr);
    }}
  }}
}}
"""


_LOCK = threading.Lock()
_BUILT: dict[int, tuple] = {}  # source hash -> (library, addresses) once loaded
_PENDING: dict[int, threading.Thread] = {}
_WHY: list[str] = []
_KEYS: dict[int, tuple] = {}  # id(tapes) -> (tapes, source hash, source): the source is written once per tapes


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
    import time

    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        _WHY.append("no C compiler found (cc, gcc or $CC)")
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    for stale in path.parent.glob("build-*"):  # left by a process that exited during its build (daemon thread)
        try:
            if time.time() - stale.stat().st_mtime > 3600:
                shutil.rmtree(stale, ignore_errors=True)
        except OSError:
            pass
    with tempfile.TemporaryDirectory(prefix="build-", dir=path.parent) as tmp:
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
    _BUILT[key] = (lib, np.array([ctypes.cast(getattr(lib, name), ctypes.c_void_p).value for name in ENTRIES],
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
    """Entry points (full, Newton, residual tape, LU, solve) of the tapes' compiled code, or zeros (the interpreter) while
    it is being built (in the background: ``wait`` blocks until it is), without a compiler or with
    ``TDOA_WORKBENCH_NATIVE=off``."""
    none = np.zeros(len(ENTRIES), dtype=np.int64)
    if disabled():
        return none
    known = _KEYS.get(id(tapes))
    if known is None or known[0] is not tapes:  # (an id can be reused after its object is gone)
        n_out = tapes.full.n_outputs  # H, J, dH/ds: N + N^2 + N rows
        N = int(round(np.sqrt(1 + n_out))) - 1
        text = "\n".join([source(getattr(tapes, kind), f"tape_{kind}") for kind in KINDS] + [lu_source(N)])
        known = _KEYS[id(tapes)] = (tapes, zlib.crc32((text + " ".join(FLAGS) + _cpu()).encode()), text)
    key = known[1]
    if key in _BUILT:
        return _BUILT[key][1]
    with _LOCK:
        if key in _BUILT:
            return _BUILT[key][1]
        path = cache_dir("tapes") / f"tapes-{key:08x}.so"
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
