"""Straight-line C code of a solver's tapes, its LU and the batched tracker, compiled once per machine.

The tape interpreter (:func:`tape_jit.run_tape`) pays a few ns of dispatch per instruction and
keeps every register in memory; the same tape written out as C (every register write a new local,
four paths per pass in vector registers) runs 2.5-3x faster for a full batch of paths and 5-10x
faster for the few paths of the lock step's tail (``scripts/bench_tracker_floor.py``). The code does
the interpreter's operations in the same order and is compiled without contracting multiply-adds
(``-ffp-contract=off``), so its results are bit-identical to the interpreter's: a solver gives the same
roots with or without it. The same library holds the LU with partial pivoting of the N x N Jacobians
and its solves (:func:`lu_source`: the batched kernel's operations, four paths per pass in vector
registers; 1.3-1.4x the batched kernel for a full batch, 3-5x for a handful of paths; for tapes renamed to a sparse
elimination order, :func:`sparse_lu_source`, which skips the exact zeros of :mod:`.sparse_lu`'s schedule), and the batched
tracker itself (:func:`tracker_source`: :func:`tape_jit._track_batch` line for line, the same bits),
so that a fresh environment compiles one C file (about a second) where numba took 13-90 s to compile
the tracker.

:func:`addresses` returns the entry points (the three tapes, the LU, its solve, the tracker) for
:func:`tape_kernel.track`, or zeros (the interpreter and numba's tracker run then). The library is
compiled by the system's C compiler (``$CC``, ``cc`` or ``gcc``) the first time a solver asks, into the
cache directory (``analysis.sweeps.paths.cache_dir("tapes")``) under a name hashed from the source, the flags
and the CPU; later calls, and every later process, load it. The object of the LU-and-tracker unit, which depends on
the number of unknowns alone, is kept beside it (``unit-<hash>.o``) and linked into every later library of that
size, so that a new system compiles only its tapes. ``TDOA_WORKBENCH_NATIVE=off`` (as for the F4
kernels) or no compiler: the interpreter and numba's tracker only.
"""
from __future__ import annotations

import ctypes
import os
import platform
import threading
import zlib
from pathlib import Path

import numpy as np

from analysis.engine.native import DISABLE_ENV, disabled
from analysis.sweeps.paths import cache_dir

from .tape_jit import OPCODES, WIDTH

__all__ = ["DISABLE_ENV", "ENTRIES", "FLAGS", "WIDTH", "addresses", "describe", "lu_source", "source"]

FLAGS = ("-O2", "-march=native", "-ffp-contract=off", "-shared", "-fPIC", "-std=gnu99")

#: Tried first for the tapes' units where the compiler takes them (GCC): RTL's instruction combiner spent two
#: thirds of the compile time of a tape's straight-line code (gcc 12 -ftime-report, 9r/3s full tape) for no
#: measurable speed (9r/3s plain tracks 1.008x the time, the same bits), so a first call waits half as long.
FAST_COMPILE = ("-fdisable-rtl-combine",)

#: Prototype of a tape's entry point, for the unit that calls the tapes of another unit.
_TAPE_PROTOTYPE = "void {name}(long P, long C, const double *R, const double *I, double *OR, double *OI);"
KINDS = ("full", "newton", "residual")
ENTRIES = ("tape_full", "tape_newton", "tape_residual", "lu_factor", "lu_solve", "track_batch")

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


def lu_source(N: int, steps=None) -> str:
    """C source of ``lu_factor(P, C, Ar, Ai, base, piv, ok)`` and ``lu_solve(P, C, Ar, Ai, base, piv, br, bi)``
    for N x N matrices at rows base + i N + j of Ar, Ai (point p at column p, row stride C), four points
    per pass: :func:`tape_jit._lu` and :func:`tape_jit._solve` with the same operations in the same
    order. The row interchanges, which differ from lane to lane, are vector selects (lanes whose pivot row is i
    exchange rows k and i), and the solve holds its right-hand side in registers: interchanges written lane by
    lane and then read back as vectors stalled on store forwarding (a whole 9r/3s solve took 0.88x the time with selects,
    the same bits).

    ``steps``: a :func:`solvers.continuation.sparse_lu.schedule` (the tapes' ``lu``): the same operations on only the
    positions and columns it says can be non-zero (:func:`sparse_lu_source`)."""
    if steps is not None:
        return sparse_lu_source(N, steps)
    return f"""
#include <math.h>
typedef double v4d __attribute__((vector_size(32)));
typedef long v4l __attribute__((vector_size(32)));
#define N {N}
#define LD(a, r) ({{ v4d _v; __builtin_memcpy(&_v, &(a)[(r) * C + p], 32); _v; }})
#define LDL(a, r) ({{ v4l _v; __builtin_memcpy(&_v, &(a)[(r) * C + p], 32); _v; }})
#define ST(a, r, v) do {{ v4d _v = (v); __builtin_memcpy(&(a)[(r) * C + p], &_v, 32); }} while (0)
#define SEL(m, a, b) ((v4d)(((m) & (v4l)(a)) | (~(m) & (v4l)(b))))
void lu_factor(long P, long C, double *restrict Ar, double *restrict Ai, long base, long *restrict piv,
                   unsigned char *restrict ok) {{
  for (long p = 0; p < P; p += 4) {{
    v4l bad = {{0, 0, 0, 0}};
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
        best = SEL(m, a, best);
        q = (m & (v4l){{i, i, i, i}}) | (~m & q);
      }}
      __builtin_memcpy(&piv[k * C + p], &q, 32);
      /* the interchanges, lanes whose pivot row is i, in vector registers (the same values as lane by lane) */
      for (int i = k + 1; i < N; i++) {{
        v4l m = q == (v4l){{i, i, i, i}};
        if (!(m[0] | m[1] | m[2] | m[3])) continue;
        for (int j = k; j < N; j++) {{
          long u = base + k * N + j, w = base + i * N + j;
          v4d ur = LD(Ar, u), wr = LD(Ar, w), ui = LD(Ai, u), wi = LD(Ai, w);
          ST(Ar, u, SEL(m, wr, ur)); ST(Ar, w, SEL(m, ur, wr));
          ST(Ai, u, SEL(m, wi, ui)); ST(Ai, w, SEL(m, ui, wi));
        }}
      }}
      /* !(best > 0) || !isfinite(best): a singular column (best is a sum of squares, never negative) */
      v4l sing = ~(best > 0.0) | ~(best < (v4d){{INFINITY, INFINITY, INFINITY, INFINITY}});
      bad |= sing;
      v4d b = SEL(sing, ((v4d){{1e-300, 1e-300, 1e-300, 1e-300}}), best);
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
    for (int l = 0; l < 4; l++) ok[p + l] = !bad[l];
  }}
}}
void lu_solve(long P, long C, const double *restrict Ar, const double *restrict Ai, long base,
                  const long *restrict piv, double *restrict br, double *restrict bi) {{
  for (long p = 0; p < P; p += 4) {{
    v4d xr[N], xi[N];
#pragma GCC unroll 16
    for (int k = 0; k < N; k++) {{ xr[k] = LD(br, k); xi[k] = LD(bi, k); }}
#pragma GCC unroll 16
    for (int k = 0; k < N; k++) {{
      v4l q = LDL(piv, k);
#pragma GCC unroll 16
      for (int i = k + 1; i < N; i++) {{
        v4l m = q == (v4l){{i, i, i, i}};
        v4d tr = xr[k], ti = xi[k];
        xr[k] = SEL(m, xr[i], tr); xr[i] = SEL(m, tr, xr[i]);
        xi[k] = SEL(m, xi[i], ti); xi[i] = SEL(m, ti, xi[i]);
      }}
      v4d kr = xr[k], ki = xi[k];
#pragma GCC unroll 16
      for (int i = k + 1; i < N; i++) {{
        long f = base + i * N + k;
        v4d a = LD(Ar, f), b = LD(Ai, f);
        xr[i] = xr[i] - (a * kr - b * ki); xi[i] = xi[i] - (a * ki + b * kr);
      }}
    }}
#pragma GCC unroll 16
    for (int i = N - 1; i >= 0; i--) {{
      v4d yr = xr[i], yi = xi[i];
#pragma GCC unroll 16
      for (int j = i + 1; j < N; j++) {{
        long f = base + i * N + j;
        v4d a = LD(Ar, f), b = LD(Ai, f);
        yr = yr - (a * xr[j] - b * xi[j]); yi = yi - (a * xi[j] + b * xr[j]);
      }}
      long f = base + i * N + i;
      v4d dr = LD(Ar, f), di = LD(Ai, f);
      xr[i] = yr * dr - yi * di; xi[i] = yr * di + yi * dr;
    }}
#pragma GCC unroll 16
    for (int k = 0; k < N; k++) {{ ST(br, k, xr[k]); ST(bi, k, xi[k]); }}
  }}
}}
"""


def _table(name: str, lists) -> str:
    """C tables of index lists: ``name_o`` (offsets, len(lists) + 1) and ``name`` (the lists one after another)."""
    offsets = np.cumsum([0] + [len(x) for x in lists])
    flat = [v for x in lists for v in x] or [0]
    return (f"static const int {name}_o[{len(offsets)}] = {{{', '.join(map(str, offsets))}}};\n"
            f"static const int {name}[{len(flat)}] = {{{', '.join(map(str, flat))}}};\n")


def sparse_lu_source(N: int, steps) -> str:
    """:func:`lu_source`'s ``lu_factor`` and ``lu_solve`` restricted to a schedule: at step k the pivot search,
    the interchanges and the elimination run over the positions of ``steps[k][0]`` and the columns of
    ``steps[k][1]`` only, in the dense code's order; the back substitution of row i over the columns of
    ``steps[i][1]``. What is skipped is an exact zero (:mod:`.sparse_lu`): the same bits as the dense code."""
    head = lu_source(N).split("void lu_factor", 1)[0]
    return head + _table("lu_t", [T for T, _ in steps]) + _table("lu_u", [U for _, U in steps]) + r"""
void lu_factor(long P, long C, double *restrict Ar, double *restrict Ai, long base, long *restrict piv,
                   unsigned char *restrict ok) {
  for (long p = 0; p < P; p += 4) {
    v4l bad = {0, 0, 0, 0};
    for (int k = 0; k < N; k++) {
      long kk = base + k * N + k;
      int t0 = lu_t_o[k], t1 = lu_t_o[k + 1], u0 = lu_u_o[k], u1 = lu_u_o[k + 1];
      v4d ar = LD(Ar, kk), ai = LD(Ai, kk);
      v4d best = ar * ar + ai * ai;
      v4l q = {k, k, k, k};
      for (int t = t0; t < t1; t++) {
        long i = lu_t[t], ik = base + i * N + k;
        v4d xr = LD(Ar, ik), xi = LD(Ai, ik);
        v4d a = xr * xr + xi * xi;
        v4l m = a > best;
        best = SEL(m, a, best);
        q = (m & (v4l){i, i, i, i}) | (~m & q);
      }
      __builtin_memcpy(&piv[k * C + p], &q, 32);
      for (int t = t0; t < t1; t++) {
        long i = lu_t[t];
        v4l m = q == (v4l){i, i, i, i};
        if (!(m[0] | m[1] | m[2] | m[3])) continue;
        for (int s = u0 - 1; s < u1; s++) {
          long j = s < u0 ? k : lu_u[s];
          long u = base + k * N + j, w = base + i * N + j;
          v4d ur = LD(Ar, u), wr = LD(Ar, w), ui = LD(Ai, u), wi = LD(Ai, w);
          ST(Ar, u, SEL(m, wr, ur)); ST(Ar, w, SEL(m, ur, wr));
          ST(Ai, u, SEL(m, wi, ui)); ST(Ai, w, SEL(m, ui, wi));
        }
      }
      v4l sing = ~(best > 0.0) | ~(best < (v4d){INFINITY, INFINITY, INFINITY, INFINITY});
      bad |= sing;
      v4d b = SEL(sing, ((v4d){1e-300, 1e-300, 1e-300, 1e-300}), best);
      v4d fr = LD(Ar, kk) / b, fi = -LD(Ai, kk) / b;
      ST(Ar, kk, fr); ST(Ai, kk, fi);
      for (int t = t0; t < t1; t++) {
        long i = lu_t[t], ik = base + i * N + k;
        v4d xr = LD(Ar, ik), xi = LD(Ai, ik);
        v4d yr = xr * fr - xi * fi, yi = xr * fi + xi * fr;
        ST(Ar, ik, yr); ST(Ai, ik, yi);
        for (int s = u0; s < u1; s++) {
          long j = lu_u[s], ij = base + i * N + j, kj = base + k * N + j;
          v4d ar = LD(Ar, ij), ai = LD(Ai, ij), br = LD(Ar, kj), bi = LD(Ai, kj);
          ST(Ar, ij, ar - (yr * br - yi * bi)); ST(Ai, ij, ai - (yr * bi + yi * br));
        }
      }
    }
    for (int l = 0; l < 4; l++) ok[p + l] = !bad[l];
  }
}
void lu_solve(long P, long C, const double *restrict Ar, const double *restrict Ai, long base,
                  const long *restrict piv, double *restrict br, double *restrict bi) {
  for (long p = 0; p < P; p += 4) {
    v4d xr[N], xi[N];
    for (int k = 0; k < N; k++) { xr[k] = LD(br, k); xi[k] = LD(bi, k); }
    for (int k = 0; k < N; k++) {
      v4l q = LDL(piv, k);
      for (int t = lu_t_o[k]; t < lu_t_o[k + 1]; t++) {
        int i = lu_t[t];
        v4l m = q == (v4l){i, i, i, i};
        v4d tr = xr[k], ti = xi[k];
        xr[k] = SEL(m, xr[i], tr); xr[i] = SEL(m, tr, xr[i]);
        xi[k] = SEL(m, xi[i], ti); xi[i] = SEL(m, ti, xi[i]);
      }
      v4d kr = xr[k], ki = xi[k];
      for (int t = lu_t_o[k]; t < lu_t_o[k + 1]; t++) {
        int i = lu_t[t];
        long f = base + i * N + k;
        v4d a = LD(Ar, f), b = LD(Ai, f);
        xr[i] = xr[i] - (a * kr - b * ki); xi[i] = xi[i] - (a * ki + b * kr);
      }
    }
    for (int i = N - 1; i >= 0; i--) {
      v4d yr = xr[i], yi = xi[i];
      for (int s = lu_u_o[i]; s < lu_u_o[i + 1]; s++) {
        int j = lu_u[s];
        long f = base + i * N + j;
        v4d a = LD(Ar, f), b = LD(Ai, f);
        yr = yr - (a * xr[j] - b * xi[j]); yi = yi - (a * xi[j] + b * xr[j]);
      }
      long f = base + i * N + i;
      v4d dr = LD(Ar, f), di = LD(Ai, f);
      xr[i] = yr * dr - yi * di; xi[i] = yr * di + yi * dr;
    }
    for (int k = 0; k < N; k++) { ST(br, k, xr[k]); ST(bi, k, xi[k]); }
  }
}
"""


def tracker_source() -> str:
    """C source of ``track_batch``: :func:`tape_jit._track_batch` (the batched tracker: RK4 or Pade
    predictor, Newton or chord corrector, step control, compaction of the ended paths, the final Newton
    steps) with the same operations in the same order, calling the library's tapes and LU directly. It is
    appended to the tapes' and LU's source (:func:`lu_source` defines N), so a first solve in a fresh
    environment compiles one C file in about a second instead of numba compiling the tracker (13-90 s).
    Returns 0, or -1 when its work arrays cannot be allocated (the caller then runs the numba kernel)."""
    return r"""
#include <stdlib.h>
#define TK_PADE 2
#define TK_NEWTON_ONLY 12
/* numba's min(a, b) and max(a, b): b where b < a (b > a), else a (the same pick with NaN) */
static inline double tk_min(double a, double b) { return b < a ? b : a; }
static inline double tk_max(double a, double b) { return b > a ? b : a; }
typedef void (*tk_tape)(long, long, const double *, const double *, double *, double *);

static void tk_eval(tk_tape fn, double *Rr, double *Ri, double *Or, double *Oi, long C, const double *xr,
                    const double *xi, const double *s, long P) {
  for (long v = 0; v < N; v++)
    for (long p = 0; p < P; p++) { Rr[v * C + p] = xr[v * C + p]; Ri[v * C + p] = xi[v * C + p]; }
  for (long p = 0; p < P; p++) { Rr[N * C + p] = s[p]; Ri[N * C + p] = 0.0; }
  fn(P, C, Rr, Ri, Or, Oi);
}

static void tk_tangent(double *Or, double *Oi, long C, long *piv, double *kr, double *ki, long P) {
  long hs = N + N * N;
  for (long v = 0; v < N; v++)
    for (long p = 0; p < P; p++) { kr[v * C + p] = -Or[(hs + v) * C + p]; ki[v * C + p] = -Oi[(hs + v) * C + p]; }
  lu_solve(P, C, Or, Oi, N, piv, kr, ki);
}

static void tk_correction(double *Or, double *Oi, long C, long *piv, double *dxr, double *dxi, long P) {
  for (long v = 0; v < N; v++)
    for (long p = 0; p < P; p++) { dxr[v * C + p] = Or[v * C + p]; dxi[v * C + p] = Oi[v * C + p]; }
  lu_solve(P, C, Or, Oi, N, piv, dxr, dxi);
}

static void tk_newton_step(tk_tape fn, double *Rr, double *Ri, double *Or, double *Oi, long C, const double *xr,
                           const double *xi, const double *s, long *piv, unsigned char *ok, double *dxr, double *dxi,
                           long P) {
  tk_eval(fn, Rr, Ri, Or, Oi, C, xr, xi, s, P);
  lu_factor(P, C, Or, Oi, N, piv, ok);
  tk_correction(Or, Oi, C, piv, dxr, dxi, P);
}

static void tk_load_segment(double *Rr, double *Ri, long C, long Q, const double *q0, const double *dq, long b,
                            long col) {
  for (long k = 0; k < Q; k++) {
    Rr[(N + 1 + k) * C + col] = q0[2 * (b * Q + k)];
    Ri[(N + 1 + k) * C + col] = q0[2 * (b * Q + k) + 1];
    Rr[(N + 1 + Q + k) * C + col] = dq[2 * (b * Q + k)];
    Ri[(N + 1 + Q + k) * C + col] = dq[2 * (b * Q + k) + 1];
  }
}

static void tk_copy_rows(const double *Ar, const double *Ai, long C, double *Br, double *Bi, long P) {
  for (long v = 0; v < N; v++)
    for (long p = 0; p < P; p++) { Br[v * C + p] = Ar[v * C + p]; Bi[v * C + p] = Ai[v * C + p]; }
}

static void tk_taylor(double *Rr, double *Ri, double *Or, double *Oi, long C, const double *xr, const double *xi,
                      const double *H0r, const double *H0i, const double *s, const double *h, const double *k1r,
                      const double *k1i, long *piv, const unsigned char *fresh, double *x2r, double *x2i,
                      double *x3r, double *x3i, double *xtr, double *xti, double *st, double *dl, double *tv,
                      double *work, long P) {
  for (long p = 0; p < P; p++) dl[p] = tk_min(1e-4, 0.1 * h[p]);
  double *Cr = work, *Ci = work + N * C, *Tr = work + 2 * N * C, *Ti = work + 3 * N * C;
  for (long v = 0; v < N; v++)
    for (long p = 0; p < P; p++) {
      Cr[v * C + p] = -2.0 * H0r[v * C + p]; Ci[v * C + p] = -2.0 * H0i[v * C + p];
      Tr[v * C + p] = 0.0; Ti[v * C + p] = 0.0;
    }
  for (int k = 0; k < 4; k++) {
    double m = k % 2 == 0 ? 1.0 : -1.0;
    double w = k < 2 ? 1.0 : m;
    if (k == 2)
      for (long p = 0; p < P; p++) dl[p] = tk_min(5e-4, 0.1 * h[p]);
    for (long p = 0; p < P; p++) { double t = m * dl[p]; tv[p] = t; st[p] = s[p] + t; }
    for (long v = 0; v < N; v++)
      for (long p = 0; p < P; p++) {
        long i = v * C + p; double t = tv[p];
        xtr[i] = xr[i] + t * (k1r[i] + t * Tr[i]);
        xti[i] = xi[i] + t * (k1i[i] + t * Ti[i]);
      }
    tk_eval(tape_residual, Rr, Ri, Or, Oi, C, xtr, xti, st, P);
    for (long v = 0; v < N; v++)
      for (long p = 0; p < P; p++) { long i = v * C + p; Cr[i] += w * Or[i]; Ci[i] += w * Oi[i]; }
    if (k == 1) {
      for (long p = 0; p < P; p++) tv[p] = -0.5 / (dl[p] * dl[p]);
      for (long v = 0; v < N; v++)
        for (long p = 0; p < P; p++) {
          long i = v * C + p; double c = tv[p];
          Tr[i] = c * Cr[i]; Ti[i] = c * Ci[i]; Cr[i] = 0.0; Ci[i] = 0.0;
        }
      lu_solve(P, C, Or, Oi, N, piv, Tr, Ti);
    }
  }
  for (long p = 0; p < P; p++) tv[p] = -0.5 / (dl[p] * dl[p] * dl[p]);
  for (long v = 0; v < N; v++)
    for (long p = 0; p < P; p++) { long i = v * C + p; double c = tv[p]; Cr[i] *= c; Ci[i] *= c; }
  lu_solve(P, C, Or, Oi, N, piv, Cr, Ci);
  for (long v = 0; v < N; v++)
    for (long p = 0; p < P; p++)
      if (fresh[p]) {
        long i = v * C + p;
        x2r[i] = Tr[i]; x2i[i] = Ti[i]; x3r[i] = Cr[i]; x3i[i] = Ci[i];
      }
}

static void tk_pade(const double *xr, const double *xi, const double *k1r, const double *k1i, const double *x2r,
                    const double *x2i, const double *x3r, const double *x3i, const double *h, long C, double *xpr,
                    double *xpi, long P) {
  for (long v = 0; v < N; v++)
    for (long p = 0; p < P; p++) {
      long i = v * C + p;
      double hp = h[p], ar = x2r[i], ai = x2i[i], cr = x3r[i], ci = x3i[i];
      double a2 = ar * ar + ai * ai, c2 = cr * cr + ci * ci;
      if (a2 > 0.0 && c2 * hp * hp >= 1e-4 * a2) {
        double br = -(cr * ar + ci * ai) / a2, bi = -(ci * ar - cr * ai) / a2;
        double nr = xr[i] + hp * (k1r[i] + br * xr[i] - bi * xi[i]) + hp * hp * (ar + br * k1r[i] - bi * k1i[i]);
        double ni = xi[i] + hp * (k1i[i] + br * xi[i] + bi * xr[i]) + hp * hp * (ai + br * k1i[i] + bi * k1r[i]);
        double dr = 1.0 + hp * br, di = hp * bi, d = dr * dr + di * di;
        xpr[i] = (nr * dr + ni * di) / d;
        xpi[i] = (ni * dr - nr * di) / d;
      } else {
        xpr[i] = xr[i] + hp * (k1r[i] + hp * (ar + hp * cr));
        xpi[i] = xi[i] + hp * (k1i[i] + hp * (ai + hp * ci));
      }
    }
}

static void tk_newton_steps(tk_tape fn, double *Rr, double *Ri, double *Or, double *Oi, long C, double *xr,
                            double *xi, const double *s, long *piv, unsigned char *ok, double *dxr, double *dxi,
                            unsigned char *done, long steps, double stop, long P) {
  for (long it = 0; it < steps; it++) {
    tk_newton_step(fn, Rr, Ri, Or, Oi, C, xr, xi, s, piv, ok, dxr, dxi, P);
    for (long p = 0; p < P; p++) {
      if (done[p] || !ok[p]) { done[p] = 1; continue; }
      double a = 0.0, b = 0.0;
      for (long v = 0; v < N; v++) {
        long i = v * C + p;
        xr[i] -= dxr[i]; xi[i] -= dxi[i];
        a += dxr[i] * dxr[i] + dxi[i] * dxi[i];
        b += xr[i] * xr[i] + xi[i] * xi[i];
      }
      if (sqrt(a) < stop * (1.0 + sqrt(b))) done[p] = 1;
    }
  }
}

/* x_out[m, v] = xr + 1j * xi as numba computes it: 1j * xi = (0 xi - 1 0) + (0 0 + 1 xi) i, then + (xr + 0 i) */
static inline void tk_store(double *x_out, long k, double xr, double xi) {
  x_out[2 * k] = xr + (0.0 * xi - 0.0);
  x_out[2 * k + 1] = 0.0 + (0.0 + xi);
}

long tk_capacity(long M) {
  long cap = ((M > 1 ? M : 1) + 7) / 8 * 8;
  if (cap % 16 == 0) cap += 8;
  return cap;
}

int track_batch(long chord, long n_reg, long n_out, long M, long Q, const double *x0, const double *q0,
                const double *dq, const long *inst, const double *opts, long n_opts, double *x_out, double *stats) {
  double h0 = opts[0], hmin = opts[1], hmax = opts[2], target = opts[3], accept = opts[4], tol = opts[5];
  long newton = (long)opts[6], final_newton = (long)opts[7], max_steps = (long)opts[8];
  double big = opts[9], contract = opts[10];
  int pade = (long)opts[11] == TK_PADE;
  long cap = tk_capacity(M), C = cap;
  /* one zeroed block for every work array (np.zeros in the numba kernel): reals, then integers, then flags */
  long nd = 2 * n_reg * cap + 2 * n_out * cap + 30 * N * cap + 4 * N * cap + 10 * cap;
  long nl = N * cap + 5 * cap;
  long nb = 7 * cap;
  double *D = calloc((size_t)nd, sizeof(double));
  long *L = calloc((size_t)nl, sizeof(long));
  unsigned char *B = calloc((size_t)nb, 1);
  if (!D || !L || !B) { free(D); free(L); free(B); return -1; }
  double *d = D;
#define TK_TAKE(n) (d += (n), d - (n))
  double *Rr = TK_TAKE(n_reg * cap), *Ri = TK_TAKE(n_reg * cap), *Or = TK_TAKE(n_out * cap), *Oi = TK_TAKE(n_out * cap);
  double *xr = TK_TAKE(N * cap), *xi = TK_TAKE(N * cap);
  double *k1r = TK_TAKE(N * cap), *k1i = TK_TAKE(N * cap), *k2r = TK_TAKE(N * cap), *k2i = TK_TAKE(N * cap);
  double *k3r = TK_TAKE(N * cap), *k3i = TK_TAKE(N * cap), *k4r = TK_TAKE(N * cap), *k4i = TK_TAKE(N * cap);
  double *ktr = TK_TAKE(N * cap), *kti = TK_TAKE(N * cap), *xtr = TK_TAKE(N * cap), *xti = TK_TAKE(N * cap);
  double *xpr = TK_TAKE(N * cap), *xpi = TK_TAKE(N * cap), *dxr = TK_TAKE(N * cap), *dxi = TK_TAKE(N * cap);
  double *x2r = TK_TAKE(N * cap), *x2i = TK_TAKE(N * cap), *x3r = TK_TAKE(N * cap), *x3i = TK_TAKE(N * cap);
  double *xqr = TK_TAKE(N * cap), *xqi = TK_TAKE(N * cap), *H0r = TK_TAKE(N * cap), *H0i = TK_TAKE(N * cap);
  double *work = TK_TAKE(4 * N * cap);
  double *s = TK_TAKE(cap), *h = TK_TAKE(cap), *st = TK_TAKE(cap), *tv = TK_TAKE(cap), *s1 = TK_TAKE(cap);
  double *scale = TK_TAKE(cap), *e0 = TK_TAKE(cap), *e = TK_TAKE(cap);
  d += 2 * cap;  /* (spare) */
#undef TK_TAKE
  long *piv = L, *ids = L + N * cap, *steps = L + N * cap + cap, *rejected = L + N * cap + 2 * cap;
  long *status = L + N * cap + 3 * cap;
  unsigned char *ok = B, *good = B + cap, *done = B + 2 * cap, *live = B + 3 * cap, *accepted = B + 4 * cap;
  unsigned char *fresh = B + 5 * cap;
  for (long m = 0; m < M; m++) ids[m] = m;
  for (long m = 0; m < M; m++)
    for (long v = 0; v < N; v++) { xr[v * C + m] = x0[2 * (m * N + v)]; xi[v * C + m] = x0[2 * (m * N + v) + 1]; }
  for (long p = 0; p < cap; p++) { h[p] = h0; scale[p] = 1.0; status[p] = -1; }
  for (long m = 0; m < M; m++) tk_load_segment(Rr, Ri, C, Q, q0, dq, inst[m], m);
  long P = M;
  int newton_only = n_opts > TK_NEWTON_ONLY && opts[TK_NEWTON_ONLY] > 0.0;
  if (newton_only) {
    for (long p = 0; p < P; p++) { status[p] = 0; s[p] = 1.0; }
  } else {
    tk_eval(tape_full, Rr, Ri, Or, Oi, C, xr, xi, s, P);
    lu_factor(P, C, Or, Oi, N, piv, ok);
    tk_tangent(Or, Oi, C, piv, k1r, k1i, P);
    for (long p = 0; p < P; p++) { if (!ok[p]) status[p] = 1; fresh[p] = ok[p]; }
    if (pade) {
      tk_copy_rows(Or, Oi, C, H0r, H0i, P);
      tk_taylor(Rr, Ri, Or, Oi, C, xr, xi, H0r, H0i, s, h, k1r, k1i, piv, fresh, x2r, x2i, x3r, x3i, xtr, xti, st,
                e, tv, work, P);
    }
  }
  for (;;) {
    long w = 0;
    for (long p = 0; p < P; p++) {
      if (status[p] == -1 && steps[p] + rejected[p] >= max_steps) status[p] = 1;
      if (status[p] != -1) {
        long m = ids[p];
        for (long v = 0; v < N; v++) tk_store(x_out, m * N + v, xr[v * C + p], xi[v * C + p]);
        stats[4 * m] = (double)status[p]; stats[4 * m + 1] = (double)steps[p];
        stats[4 * m + 2] = (double)rejected[p]; stats[4 * m + 3] = s[p];
        continue;
      }
      if (w != p) {
        ids[w] = ids[p];
        for (long v = 0; v < N; v++) {
          xr[v * C + w] = xr[v * C + p]; xi[v * C + w] = xi[v * C + p];
          k1r[v * C + w] = k1r[v * C + p]; k1i[v * C + w] = k1i[v * C + p];
          x2r[v * C + w] = x2r[v * C + p]; x2i[v * C + w] = x2i[v * C + p];
          x3r[v * C + w] = x3r[v * C + p]; x3i[v * C + w] = x3i[v * C + p];
        }
        for (long k = N + 1; k < N + 1 + 2 * Q; k++) { Rr[k * C + w] = Rr[k * C + p]; Ri[k * C + w] = Ri[k * C + p]; }
        s[w] = s[p]; h[w] = h[p]; steps[w] = steps[p]; rejected[w] = rejected[p]; status[w] = -1;
      }
      w++;
    }
    P = w;
    if (P == 0) break;
    for (long p = 0; p < P; p++) { if (h[p] > 1.0 - s[p]) h[p] = 1.0 - s[p]; good[p] = 1; }
    for (int stage = 0; stage < (pade ? 0 : 3); stage++) {
      double *kr = stage == 0 ? k1r : stage == 1 ? k2r : k3r, *ki = stage == 0 ? k1i : stage == 1 ? k2i : k3i;
      for (long p = 0; p < P; p++) {
        double c = stage < 2 ? 0.5 * h[p] : h[p];
        st[p] = s[p] + c;
        for (long v = 0; v < N; v++) {
          xtr[v * C + p] = xr[v * C + p] + c * kr[v * C + p];
          xti[v * C + p] = xi[v * C + p] + c * ki[v * C + p];
        }
      }
      tk_eval(tape_full, Rr, Ri, Or, Oi, C, xtr, xti, st, P);
      lu_factor(P, C, Or, Oi, N, piv, ok);
      if (stage == 0) tk_tangent(Or, Oi, C, piv, k2r, k2i, P);
      else if (stage == 1) tk_tangent(Or, Oi, C, piv, k3r, k3i, P);
      else tk_tangent(Or, Oi, C, piv, k4r, k4i, P);
      for (long p = 0; p < P; p++) if (!ok[p]) good[p] = 0;
    }
    for (long p = 0; p < P; p++) {
      s1[p] = s[p] + h[p];
      if (1.0 - s1[p] < 1e-14) s1[p] = 1.0;
      e0[p] = INFINITY; e[p] = INFINITY;
      done[p] = !good[p];
      scale[p] = 0.0;
    }
    if (pade) tk_pade(xr, xi, k1r, k1i, x2r, x2i, x3r, x3i, h, C, xpr, xpi, P);
    else
      for (long v = 0; v < N; v++)
        for (long p = 0; p < P; p++) {
          long i = v * C + p; double hh = h[p] / 6.0;
          xpr[i] = xr[i] + hh * (k1r[i] + 2.0 * k2r[i] + 2.0 * k3r[i] + k4r[i]);
          xpi[i] = xi[i] + hh * (k1i[i] + 2.0 * k2i[i] + 2.0 * k3i[i] + k4i[i]);
        }
    for (long v = 0; v < N; v++)
      for (long p = 0; p < P; p++) { long i = v * C + p; scale[p] += xpr[i] * xpr[i] + xpi[i] * xpi[i]; }
    for (long p = 0; p < P; p++) scale[p] = 1.0 + sqrt(scale[p]);
    for (long it = 0; it < newton; it++) {
      if (chord && it > 0) {
        tk_eval(tape_residual, Rr, Ri, Or, Oi, C, xpr, xpi, s1, P);
        tk_correction(Or, Oi, C, piv, dxr, dxi, P);
      } else if (it == newton - 1 || chord) {
        tk_newton_step(tape_full, Rr, Ri, Or, Oi, C, xpr, xpi, s1, piv, ok, dxr, dxi, P);
        tk_tangent(Or, Oi, C, piv, ktr, kti, P);
        if (pade) { tk_copy_rows(Or, Oi, C, H0r, H0i, P); tk_copy_rows(xpr, xpi, C, xqr, xqi, P); }
      } else {
        tk_newton_step(tape_newton, Rr, Ri, Or, Oi, C, xpr, xpi, s1, piv, ok, dxr, dxi, P);
      }
      for (long p = 0; p < P; p++) {
        live[p] = !done[p] && ok[p];
        if (!done[p] && !ok[p]) { e[p] = INFINITY; done[p] = 1; }
        tv[p] = 0.0;
      }
      for (long v = 0; v < N; v++)
        for (long p = 0; p < P; p++) {
          long i = v * C + p;
          double ar = live[p] ? dxr[i] : 0.0, ai = live[p] ? dxi[i] : 0.0;
          xpr[i] -= ar; xpi[i] -= ai;
          tv[p] += ar * ar + ai * ai;
        }
      for (long p = 0; p < P; p++) {
        if (!live[p]) continue;
        e[p] = sqrt(tv[p]) / scale[p];
        if (it == 0) {
          e0[p] = e[p];
          if (!(e0[p] < accept)) { done[p] = 1; continue; }
        }
        if (e[p] < tol || (it > 0 && e[p] < contract * e0[p] && e[p] < 1e-5)) done[p] = 1;
      }
    }
    for (long p = 0; p < P; p++)
      accepted[p] = good[p] && isfinite(e[p]) && e0[p] < accept && (e[p] < tol || e[p] < contract * e0[p]);
    for (long v = 0; v < N; v++)
      for (long p = 0; p < P; p++)
        if (accepted[p]) {
          long i = v * C + p;
          xr[i] = xpr[i]; xi[i] = xpi[i]; k1r[i] = ktr[i]; k1i[i] = kti[i];
        }
    for (long p = 0; p < P; p++) {
      fresh[p] = 0;
      if (accepted[p]) {
        s[p] = s1[p];
        steps[p] += 1;
        if (s[p] >= 1.0) { status[p] = 0; continue; }
        if (scale[p] > big) { status[p] = 2; continue; }
        double f = 2.0;
        if (e0[p] > 0) f = 0.8 * pow(target / e0[p], pade ? 0.25 : 0.2);
        f = tk_min(tk_max(f, 0.5), 2.0);
        h[p] = tk_min(h[p] * f, hmax);
        fresh[p] = 1;
      } else {
        rejected[p] += 1;
        h[p] *= 0.5;
        if (h[p] < hmin) status[p] = scale[p] > big ? 2 : 1;
      }
    }
    if (pade)
      tk_taylor(Rr, Ri, Or, Oi, C, xqr, xqi, H0r, H0i, s, h, k1r, k1i, piv, fresh, x2r, x2i, x3r, x3i, xtr, xti, st,
                e, tv, work, P);
  }
  P = 0;
  for (long m = 0; m < M; m++)
    if (stats[4 * m] == 0) {
      ids[P] = m;
      for (long v = 0; v < N; v++) { xr[v * C + P] = x_out[2 * (m * N + v)]; xi[v * C + P] = x_out[2 * (m * N + v) + 1]; }
      tk_load_segment(Rr, Ri, C, Q, q0, dq, inst[m], P);
      s[P] = 1.0;
      done[P] = 0;
      P++;
    }
  tk_newton_steps(tape_newton, Rr, Ri, Or, Oi, C, xr, xi, s, piv, ok, dxr, dxi, done, final_newton,
                  newton_only ? 0.0 : 1e-15, P);
  for (long p = 0; p < P; p++)
    for (long v = 0; v < N; v++) tk_store(x_out, ids[p] * N + v, xr[v * C + p], xi[v * C + p]);
  free(D); free(L); free(B);
  return 0;
}
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


def _units(tapes, N: int) -> list[str]:
    """The library's C source in three translation units compiled side by side (:func:`_compile`): the full
    tape; the Newton and residual tapes; the LU and the tracker (:data:`TAPE_UNITS` of them are tapes)."""
    prototypes = [_TAPE_PROTOTYPE.format(name=f"tape_{kind}") for kind in KINDS]
    return [source(tapes.full, "tape_full"), "\n".join(source(getattr(tapes, kind), f"tape_{kind}") for kind in KINDS[1:]),
            "\n".join(prototypes + [lu_source(N, getattr(tapes, "lu", None)), tracker_source()])]


#: The first units of :func:`_units` are straight-line tapes, compiled with :data:`FAST_COMPILE`; the LU's and
#: the tracker's loops keep the combiner (without it 5r/5s plain tracks took up to 1.5x as long).
TAPE_UNITS = 2


def _run_all(commands: list[list[str]]) -> tuple[int, str]:
    """Run the commands side by side; (first non-zero return code or 0, its first line of stderr)."""
    import subprocess

    running = [subprocess.Popen(c, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE) for c in commands]
    failed = (0, "")
    for proc in running:
        _, err = proc.communicate(timeout=600)
        if proc.returncode and not failed[0]:
            lines = err.decode(errors="replace").strip().splitlines()
            failed = (proc.returncode, lines[0] if lines else "")
    return failed


def _compile(units: list[str], path: Path) -> None:
    """Build ``path`` from the C translation units (compiled in parallel, then linked; atomically: a whole file
    or none)."""
    import shutil
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
    flags = [f for f in FLAGS if f != "-shared"]
    with tempfile.TemporaryDirectory(prefix="build-", dir=path.parent) as tmp:
        objects, todo = [], []
        for k, text in enumerate(units):
            (Path(tmp) / f"unit{k}.c").write_text(text, encoding="utf-8")
            objects.append(str(Path(tmp) / f"unit{k}.o"))
            # the LU and tracker unit depends on N alone: its object is kept, so that another system of N unknowns
            # compiles its tapes only (0.34 of 0.45 s of CPU for a user's system of 3 unknowns)
            kept = path.parent / f"unit-{zlib.crc32((text + ' '.join(flags) + _cpu()).encode()):08x}.o"
            if k >= TAPE_UNITS and kept.exists():
                objects[k] = str(kept)
            else:
                todo.append((k, kept))
        for extra in (FAST_COMPILE, ()):  # a compiler that refuses the extra flags compiles without them
            code, why = _run_all([[compiler, *flags, *(extra if k < TAPE_UNITS else ()), "-c", "-o", objects[k],
                                   objects[k][:-2] + ".c"] for k, _ in todo])
            if not code:
                break
        if not code:
            so_file = Path(tmp) / "tapes.so"
            code, why = _run_all([[compiler, "-shared", "-o", str(so_file), *objects]])
        if code:
            _WHY.append(f"{compiler} failed on a tape: {why or code}")
            return
        for k, kept in todo:
            if k >= TAPE_UNITS:  # atomically: a whole object or none
                shutil.copyfile(objects[k], Path(tmp) / "kept.o")
                os.replace(Path(tmp) / "kept.o", kept)
        os.replace(so_file, path)


def _load(key: int, path: Path) -> None:
    lib = ctypes.CDLL(str(path))
    _BUILT[key] = (lib, np.array([ctypes.cast(getattr(lib, name), ctypes.c_void_p).value for name in ENTRIES],
                                 dtype=np.int64))


def _build(key: int, units: list[str], path: Path) -> None:
    try:
        if not path.exists():
            _compile(units, path)
        if path.exists():
            with _LOCK:
                _load(key, path)
    except (OSError, ValueError) as exc:  # subprocess errors are OSErrors; a broken library too
        _WHY.append(f"the tapes' C code could not be built or loaded: {exc}")
    finally:
        with _LOCK:
            _PENDING.pop(key, None)


def addresses(tapes, wait: bool = True) -> np.ndarray:
    """Entry points (full, Newton, residual tape, LU, solve, tracker) of the tapes' compiled code, or zeros (the
    interpreter and numba's tracker) without a compiler, with ``TDOA_WORKBENCH_NATIVE=off``, or while it is
    being built by another thread when ``wait`` is False (the first call builds it, about a second, and waits:
    numba compiling its own tracker instead would take 13-90 s)."""
    none = np.zeros(len(ENTRIES), dtype=np.int64)
    if disabled():
        return none
    known = _KEYS.get(id(tapes))
    if known is None or known[0] is not tapes:  # (an id can be reused after its object is gone)
        n_out = tapes.full.n_outputs  # H, J, dH/ds: N + N^2 + N rows
        N = int(round(np.sqrt(1 + n_out))) - 1
        units = _units(tapes, N)
        key = zlib.crc32(("\n".join(units) + " ".join(FLAGS + FAST_COMPILE) + _cpu()).encode())
        known = _KEYS[id(tapes)] = (tapes, key, units)
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
