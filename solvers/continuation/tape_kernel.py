"""The batched path tracker and the tape interpreter as Python calls: inputs and workspaces laid out, paths cut
into lock-step batches, the batches run on threads, by the tapes' compiled code (:mod:`solvers.continuation.tape_native`)
or by numba's kernels (:mod:`solvers.continuation.tape_jit`, which owns the instruction set and everything numba
compiles, in one file for numba's cache).

:func:`track` tracks paths of a parameter homotopy (RK4 or Pade predictor, Newton or chord corrector; statuses as
in :mod:`solvers.continuation.tracker`: 0 reached s = 1, 1 stalled, 2 diverged); :func:`newton` runs Newton steps
through the same kernel; :func:`evaluate`, :func:`run` and :func:`taylor` evaluate tapes at points (checks and
tests, by the numpy reference interpreter :func:`run_tape_numpy` where they can).
"""
from __future__ import annotations

import ctypes
import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .tape_jit import (ADD, AXPY, CADD, CMUL, CONST, MUL, MULADD, NEG, NEWTON_ONLY, OPCODES, OUT, PADE, SQR, SUB,  # noqa: F401
                       TAYLOR_DELTA, TAYLOR_DELTA3, WIDTH, _eval, _lu, _tangent, _taylor, _track_batch, capacity, run_tape)
from .tracker import TrackerOptions

# The tapes' types (solvers.continuation.slp.Tape, HomotopyTapes) are named in annotations only as strings:
# slp imports this module's opcodes, and this module never imports slp (one direction of dependency).

__all__ = ["OPCODES", "PREDICTORS", "THREADS_ENV", "capacity", "evaluate", "newton", "run", "run_tape", "run_tape_numpy",
           "set_threads", "taylor", "threads", "track", "workspace"]


def run_tape_numpy(code, imm, Rr, Ri, Or, Oi, P):
    """:func:`run_tape` in plain numpy, one instruction at a time over all points (the same operations in the
    same order, so the same bits): the reference interpreter, and the one :func:`run` uses, so that checking a
    tape at a few points (:func:`solvers.continuation.tracking._agrees`, at every solver's construction) does not
    make numba compile the interpreter (6 s of a first call in a fresh environment)."""
    for k in range(code.shape[0]):
        op, d, a, b, c = (int(v) for v in code[k])
        ar, ai = Rr[a, :P], Ri[a, :P]
        if op == MULADD:
            br, bi = Rr[b, :P], Ri[b, :P]
            xr = Rr[c, :P] + imm[k] * (ar * br - ai * bi)
            xi = Ri[c, :P] + imm[k] * (ar * bi + ai * br)
        elif op == AXPY:
            xr, xi = ar + imm[k] * Rr[b, :P], ai + imm[k] * Ri[b, :P]
        elif op == MUL:
            br, bi = Rr[b, :P], Ri[b, :P]
            xr, xi = ar * br - ai * bi, ar * bi + ai * br
        elif op == ADD:
            xr, xi = ar + Rr[b, :P], ai + Ri[b, :P]
        elif op == SUB:
            xr, xi = ar - Rr[b, :P], ai - Ri[b, :P]
        elif op == CMUL:
            xr, xi = imm[k] * ar, imm[k] * ai
        elif op == SQR:
            xr, xi = ar * ar - ai * ai, 2.0 * ar * ai
        elif op == CADD:
            xr, xi = ar + imm[k], ai.copy()
        elif op == NEG:
            xr, xi = -ar, -ai
        elif op == CONST:
            xr, xi = np.full(P, imm[k]), np.zeros(P)
        elif op == OUT:
            Or[d, :P], Oi[d, :P] = ar, ai
            continue
        else:
            raise ValueError(f"unknown opcode {op} at instruction {k}")
        Rr[d, :P], Ri[d, :P] = xr, xi


def workspace(tape: "Tape", capacity: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Register and output arrays (real, imaginary) for up to ``capacity`` points."""
    return (np.zeros((tape.n_registers, capacity)), np.zeros((tape.n_registers, capacity)),
            np.zeros((tape.n_outputs, capacity)), np.zeros((tape.n_outputs, capacity)))


def run(tape: "Tape", inputs: np.ndarray) -> np.ndarray:
    """Outputs (n_outputs, P) complex of the tape at inputs (n_inputs, P) complex, by the reference interpreter
    :func:`run_tape_numpy` (checks and tests; trackers keep their workspace and call :func:`run_tape` or the
    tapes' compiled code)."""
    inputs = np.asarray(inputs, dtype=complex)
    if inputs.shape[0] != tape.n_inputs:
        raise ValueError(f"{inputs.shape[0]} input rows given; the tape has {tape.n_inputs}")
    P = inputs.shape[1]
    Rr, Ri, Or, Oi = workspace(tape, P)
    Rr[: tape.n_inputs] = inputs.real
    Ri[: tape.n_inputs] = inputs.imag
    run_tape_numpy(tape.code, tape.imm, Rr, Ri, Or, Oi, P)
    return Or + 1j * Oi


def evaluate(tape: "Tape", x: np.ndarray, s: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Outputs (P, n_outputs) of a homotopy tape (:func:`slp.homotopy_program`) at points x (P, N),
    path parameters s (P,) on the segments q0 -> q1 (P, Q) or (Q,)."""
    x = np.atleast_2d(np.asarray(x, dtype=complex))
    P = len(x)
    s = np.broadcast_to(np.asarray(s, dtype=float), (P,))
    q0 = np.broadcast_to(np.asarray(q0, dtype=complex), (P, np.shape(q0)[-1]))
    q1 = np.broadcast_to(np.asarray(q1, dtype=complex), (P, np.shape(q1)[-1]))
    inputs = np.concatenate([x.T, s[None, :], q0.T, (q1 - q0).T], axis=0)
    return run(tape, inputs).T


def taylor(tapes: "HomotopyTapes", x: np.ndarray, s: np.ndarray, q0: np.ndarray, q1: np.ndarray,
           h: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Taylor coefficients x1, x2, x3 (each (P, N)) of the paths through the points x (P, N) at s (P,) on
    the segments q0 -> q1 (P, Q) or (Q,), as the Pade predictor computes them for a next step h (a
    reference entry point for tests)."""
    x = np.atleast_2d(np.asarray(x, dtype=complex))
    P, N = x.shape
    s = np.ascontiguousarray(np.broadcast_to(np.asarray(s, dtype=float), (P,)))
    q0 = np.broadcast_to(np.asarray(q0, dtype=complex), (P, np.shape(q0)[-1]))
    dq = np.broadcast_to(np.asarray(q1, dtype=complex), q0.shape) - q0
    _check(tapes, N, q0.shape[1])
    _, _, Or, Oi = workspace(tapes.full, P)
    Rr = np.zeros((tapes.n_registers, P))
    Ri = np.zeros((tapes.n_registers, P))
    Q = q0.shape[1]
    Rr[N + 1:N + 1 + Q], Ri[N + 1:N + 1 + Q] = q0.T.real, q0.T.imag
    Rr[N + 1 + Q:N + 1 + 2 * Q], Ri[N + 1 + Q:N + 1 + 2 * Q] = dq.T.real, dq.T.imag
    xr, xi = np.ascontiguousarray(x.T.real), np.ascontiguousarray(x.T.imag)
    piv, ok = np.zeros((N, P), dtype=np.int64), np.zeros(P, dtype=np.bool_)
    _eval(tapes.full.code, tapes.full.imm, 0, Rr, Ri, Or, Oi, N, xr, xi, s, P)
    _lu(Or, Oi, N, N, piv, ok, P)
    k = [np.zeros((N, P)) for _ in range(6)]
    lin = np.zeros(2, dtype=np.int64)  # the batched kernels (these arrays have no room for compiled passes)
    _tangent(lin, Or, Oi, N, piv, k[0], k[1], P)
    H0r, H0i = np.ascontiguousarray(Or[:N]), np.ascontiguousarray(Oi[:N])
    _taylor(tapes.residual.code, tapes.residual.imm, 0, lin, Rr, Ri, Or, Oi, N, xr, xi, H0r, H0i, s, np.full(P, float(h)),
            k[0], k[1], piv, np.ones(P, dtype=np.bool_), k[2], k[3], k[4], k[5], np.empty((N, P)), np.empty((N, P)),
            np.empty(P), np.empty(P), np.empty(P), np.empty((4, N, P)), P)
    return tuple((k[2 * j] + 1j * k[2 * j + 1]).T for j in range(3))


def _segments(q0: np.ndarray, q1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start points and directions (B, Q) of the segments q0 -> q1 (either broadcast)."""
    q0 = np.atleast_2d(np.asarray(q0, dtype=np.complex128))
    q1 = np.atleast_2d(np.asarray(q1, dtype=np.complex128))
    B = max(len(q0), len(q1))
    q0 = np.array(np.broadcast_to(q0, (B, q0.shape[1])))  # a writable copy: numba compiles readonly arrays apart
    return q0, np.ascontiguousarray(np.broadcast_to(q1, q0.shape) - q0)


def _native(native: np.ndarray | None) -> np.ndarray:
    """The compiled entry points as the kernel takes them: the full, Newton and residual tapes, the LU, its
    solve and the compiled tracker (zeros: the interpreter, the batched kernels and this module's tracker)."""
    if native is None:
        return np.zeros(6, dtype=np.int64)
    native = np.ascontiguousarray(native, dtype=np.int64)
    if native.shape != (6,):
        raise ValueError(f"native: six entry points (full, Newton, residual tape, LU, solve, tracker) expected, "
                         f"not {native.shape}")
    return native


#: ctypes prototype of the compiled tracker (:func:`tape_native.tracker_source`), made once per address.
_TRACK_PROTOTYPE = ctypes.CFUNCTYPE(ctypes.c_int, *([ctypes.c_long] * 5), *([ctypes.c_void_p] * 5), ctypes.c_long,
                                    ctypes.c_void_p, ctypes.c_void_p)
_TRACKERS: dict[int, object] = {}


def _batch(tapes: "HomotopyTapes", native: np.ndarray, chord: bool, x0: np.ndarray, q0: np.ndarray, dq: np.ndarray,
           inst: np.ndarray, opts: np.ndarray, x_out: np.ndarray, stats: np.ndarray) -> None:
    """One lock-step batch: by the compiled tracker at native[5] where there is one (the same bits as
    :func:`_track_batch`, which runs otherwise and where the compiled one cannot allocate its arrays)."""
    if native[5] != 0:
        call = _TRACKERS.get(int(native[5]))
        if call is None:
            call = _TRACKERS[int(native[5])] = _TRACK_PROTOTYPE(int(native[5]))
        # the compiled tracker writes C-ordered arrays: an output that is not (an F-ordered x0's empty_like, say) is
        # written through a copy and copied back, never left as it was
        out, st = np.ascontiguousarray(x_out), np.ascontiguousarray(stats)
        x0, q0, dq = np.ascontiguousarray(x0), np.ascontiguousarray(q0), np.ascontiguousarray(dq)
        opts = np.ascontiguousarray(opts, dtype=np.float64)
        if call(int(chord), tapes.n_registers, tapes.full.n_outputs, len(x0), q0.shape[1], x0.ctypes.data, q0.ctypes.data,
                dq.ctypes.data, inst.ctypes.data, opts.ctypes.data, len(opts), out.ctypes.data, st.ctypes.data) == 0:
            if out is not x_out:
                x_out[...] = out
            if st is not stats:
                stats[...] = st
            return
    _track_batch(tapes.full.code, tapes.full.imm, tapes.newton.code, tapes.newton.imm, tapes.residual.code,
                 tapes.residual.imm, native, chord, tapes.n_registers, tapes.full.n_outputs, x0, q0, dq, inst, opts,
                 x_out, stats)


def _check(tapes: "HomotopyTapes", N: int, Q: int) -> None:
    if tapes.full.n_inputs != N + 1 + 2 * Q:
        raise ValueError(f"the tapes have {tapes.full.n_inputs} inputs; {N} unknowns and {Q} parameters need {N + 1 + 2 * Q}")


#: Paths per lock-step batch: the registers of a 9r/3s tape for 256 paths take 1 MB (L2-sized); a
#: batch of 600 was slower per path than one of 300 (many instances solved at once are split, into
#: batches of about this size: :func:`_chunks`).
CHUNK = 256

#: Bytes of one batch's work arrays (registers, outputs, the tracker's state) beyond which a system's batches hold
#: fewer than CHUNK paths (:func:`batch_width`). A batch's factorisations sweep its N + N^2 + N output rows once per
#: evaluation: 5r/9s in 3D (45 unknowns, 48.7 KB a path) tracked 256 distinct paths in 5.5 ms of CPU a path in
#: one batch of 256 (12.5 MB), 4.9 in batches of 128, 4.4-4.5 in batches of 48-64 (2.3-3.1 MB), the same bits;
#: 9r/3s (4.8 KB a path, 1.2 MB for 256) keeps 256.
BATCH_BYTES = 3 << 20


def batch_width(tapes: "HomotopyTapes") -> int:
    """Paths per lock-step batch of ``tapes``' system: CHUNK, or fewer (at least 8) where that many would take
    more than :data:`BATCH_BYTES` of work arrays (the compiled tracker's: 2 n_reg + 2 n_out + 34 N + 10 doubles
    a path)."""
    n_out = tapes.full.n_outputs  # H, J, dH/ds: N + N^2 + N rows
    N = int(round(np.sqrt(1 + n_out))) - 1
    per_path = 8 * (2 * tapes.n_registers + 2 * n_out + 34 * N + 10)
    return int(max(8, min(CHUNK, BATCH_BYTES // per_path)))


def _chunks(M: int, width: int = CHUNK) -> list[tuple[int, int]]:
    """Row ranges of M paths in round(M / width) batches of equal size: one 4r/5s instance (344 paths) is one
    batch (a second of 88 paths ran a lock-step tail of its own: 186 against 137 ms per plain track)."""
    n = max(1, int(round(M / width)))
    size = -(-M // n)
    return [(a, min(a + size, M)) for a in range(0, M, size)]


#: Threads that track a call's batches side by side (:func:`threads`): a positive integer, or "auto" for
#: every core. The batches are independent (each writes its own rows; the compiled tracker and numba's
#: release the GIL and keep no state between calls), so the results are the same bits with any number.
THREADS_ENV = "TDOA_WORKBENCH_THREADS"

_THREADS: int | None = None
_POOL: tuple[int, ThreadPoolExecutor] | None = None
_POOL_LOCK = threading.Lock()


def threads() -> int:
    """Threads per :func:`track` / :func:`newton` call: :func:`set_threads`'s, else ``$TDOA_WORKBENCH_THREADS``
    (a positive integer or "auto": every core), else 1. ValueError for any other value."""
    if _THREADS is not None:
        return _THREADS
    value = os.environ.get(THREADS_ENV, "").strip()
    if not value:
        return 1
    if value.lower() == "auto":
        return os.cpu_count() or 1
    if not value.isdigit() or int(value) < 1:
        raise ValueError(f"${THREADS_ENV} must be a positive integer or 'auto', not {value!r}")
    return int(value)


def set_threads(n: int | None) -> None:
    """Track every later call's batches on ``n`` threads (None: back to ``$TDOA_WORKBENCH_THREADS``)."""
    global _THREADS
    if n is not None and (not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 1):
        raise ValueError(f"threads: a positive integer or None, not {n!r}")
    _THREADS = None if n is None else int(n)


def _pool(n: int) -> ThreadPoolExecutor:
    global _POOL
    with _POOL_LOCK:
        if _POOL is None or _POOL[0] != n:
            if _POOL is not None:
                _POOL[1].shutdown(wait=False)
            _POOL = (n, ThreadPoolExecutor(max_workers=n, thread_name_prefix="tdoa-track"))
        return _POOL[1]


def _each_chunk(M: int, native: np.ndarray, run, width: int = CHUNK) -> None:
    """run(a, b) for the row ranges of :func:`_chunks` (batches of about ``width`` paths), on :func:`threads`
    threads when there are several."""
    chunks = _chunks(M, width)
    n = min(threads(), len(chunks))
    if n <= 1:
        for a, b in chunks:
            run(a, b)
        return
    if native[5] != 0 and int(native[5]) not in _TRACKERS:  # made once, before the threads share it
        _TRACKERS[int(native[5])] = _TRACK_PROTOTYPE(int(native[5]))
    for future in [_pool(n).submit(run, a, b) for a, b in chunks]:
        future.result()


#: Predictors of :func:`track` (:data:`tracker.PREDICTORS` it implements).
PREDICTORS = ("rk4", "pade")

def track(tapes: "HomotopyTapes", q0: np.ndarray, q1: np.ndarray, x0: np.ndarray, inst: np.ndarray | None = None,
          options: TrackerOptions = TrackerOptions(), near_end: float = 0.0, native: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Track x0 (P, N) along q0 -> q1 ((B, Q) or (Q,), broadcast); path p on segment inst[p].

    Returns endpoints (P, N) (NaN unless the path reached s = 1, or, with ``near_end`` > 0, stalled at
    s >= 1 - near_end: then its last point, for Newton's method on the target) and stats (P, 4), as
    :func:`tracker.track`. ``options``: step control, predictor (rk4 or pade) and corrector (newton or chord,
    :data:`tracker.CORRECTORS`). ``native``: the tapes' compiled code (:func:`tape_native.addresses`; None or
    zeros: the interpreter, with the same results).
    """
    if options.predictor not in PREDICTORS:
        raise ValueError(f"the batched tracker predicts by {' or '.join(PREDICTORS)}, not {options.predictor!r}")
    x0 = np.array(np.atleast_2d(x0), dtype=np.complex128)  # a writable copy (see _segments)
    M, N = x0.shape
    q0, dq = _segments(q0, q1)
    _check(tapes, N, q0.shape[1])
    inst = np.zeros(M, dtype=np.int64) if inst is None else np.ascontiguousarray(inst, dtype=np.int64)
    x = np.empty_like(x0)
    stats = np.zeros((M, 4))
    native = _native(native)
    opts = options.as_array()
    _each_chunk(M, native, lambda a, b: _batch(tapes, native, options.corrector == "chord", x0[a:b], q0, dq, inst[a:b], opts,
                                               x[a:b], stats[a:b]), batch_width(tapes))
    x[(stats[:, 0] != 0) & ~((stats[:, 0] == 1) & (stats[:, 3] >= 1.0 - near_end))] = np.nan
    return x, stats


def newton(tapes: "HomotopyTapes", q: np.ndarray, x: np.ndarray, inst: np.ndarray | None = None, steps: int = 1,
           native: np.ndarray | None = None) -> np.ndarray:
    """``steps`` Newton steps on the systems at parameters q (B, Q) from x (P, N), row p on inst[p]; a row
    whose Jacobian is singular keeps its last point. ``native`` as for :func:`track`."""
    x = np.array(np.atleast_2d(x), dtype=np.complex128)
    M, N = x.shape
    q = np.array(q, dtype=np.complex128, ndmin=2)  # a writable copy (a broadcast view would compile apart)
    _check(tapes, N, q.shape[1])
    inst = np.zeros(M, dtype=np.int64) if inst is None else np.ascontiguousarray(inst, dtype=np.int64)
    out = np.empty_like(x)
    stats = np.zeros((M, 4))
    opts = np.zeros(NEWTON_ONLY + 1)
    opts[7], opts[NEWTON_ONLY] = int(steps), 1.0  # final_newton = steps; Newton steps only
    native = _native(native)
    dq = np.zeros_like(q)
    _each_chunk(M, native, lambda a, b: _batch(tapes, native, False, x[a:b], q, dq, inst[a:b], opts, out[a:b], stats[a:b]),
                batch_width(tapes))
    return out
