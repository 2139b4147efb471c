"""Batched path tracker on instruction tapes: every live path advances together (numba).

The same predictor-corrector as :mod:`solvers.methods.tracker` (classical RK4 on the tangent field,
Newton corrector, step size from the first Newton correction, tight retracking by the caller), with
the step logic of ``tracker._track_one`` kept path by path, but run in lock step: each round, every
live path makes one step attempt, and each evaluation of H, dH/dx, dH/ds is one run of the system's
tape (:mod:`solvers.methods.slp`) over all live paths (:func:`solvers.methods.tape_kernel.run_tape`),
followed by one batched LU with partial pivoting of the N x N Jacobians (paths in the inner loop).
Paths that end leave the batch at the end of the round (their columns are compacted away).

Statuses as in the tracker: 0 reached s = 1, 1 stalled (or out of steps, or singular Jacobian),
2 diverged. Reference: Sommese & Wampler (2005), ch. 2 and 7; Timme (2021) for tracking many paths of
one compiled program.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .slp import Tape
from .tape_kernel import run_tape
from .tracker import TrackerOptions

__all__ = ["track"]


@njit(cache=True, nogil=True, boundscheck=False, inline="always")
def _swap(Xr, Xi, u, v, p):
    """Swap rows u and v of column p (complex numbers as two arrays)."""
    t = Xr[u, p]
    Xr[u, p] = Xr[v, p]
    Xr[v, p] = t
    t = Xi[u, p]
    Xi[u, p] = Xi[v, p]
    Xi[v, p] = t


@njit(cache=True, nogil=True, boundscheck=False)
def _lu(Ar, Ai, base, N, piv, ok, P):
    """In-place LU with partial pivoting of the matrices in rows base + i N + j of Ar, Ai (one per
    column p < P), the diagonal replaced by its reciprocal; piv (N, capacity) receives the pivots,
    ok[p] is False where a matrix is singular (its column then holds inf or nan, the others not)."""
    for p in range(P):
        ok[p] = True
    for k in range(N):
        kk = base + k * N + k
        for p in range(P):
            best = Ar[kk, p] * Ar[kk, p] + Ai[kk, p] * Ai[kk, p]
            r = k
            for i in range(k + 1, N):
                ik = base + i * N + k
                a = Ar[ik, p] * Ar[ik, p] + Ai[ik, p] * Ai[ik, p]
                if a > best:
                    best = a
                    r = i
            piv[k, p] = r
            if not (best > 0.0) or not np.isfinite(best):
                ok[p] = False
                best = 1e-300
            if r != k:
                for j in range(N):
                    _swap(Ar, Ai, base + k * N + j, base + r * N + j, p)
            Ar[kk, p] = Ar[kk, p] / best
            Ai[kk, p] = -Ai[kk, p] / best
        for i in range(k + 1, N):
            ik = base + i * N + k
            _mul_row(Ar, Ai, ik, Ar, Ai, kk, P)
            for j in range(k + 1, N):
                _sub_product(Ar, Ai, base + i * N + j, base + k * N + j, Ar, Ai, ik, P)


@njit(cache=True, nogil=True, boundscheck=False, inline="always")
def _mul_row(Br, Bi, i, Fr, Fi, f, P):
    """Row i of B *= row f of F, over the points."""
    for p in range(P):
        yr = Br[i, p] * Fr[f, p] - Bi[i, p] * Fi[f, p]
        yi = Br[i, p] * Fi[f, p] + Bi[i, p] * Fr[f, p]
        Br[i, p] = yr
        Bi[i, p] = yi


@njit(cache=True, nogil=True, boundscheck=False, inline="always")
def _sub_product(Br, Bi, i, j, Fr, Fi, f, P):
    """Row i of B -= row f of F times row j of B, over the points (complex numbers as two arrays)."""
    for p in range(P):
        a = Fr[f, p]
        b = Fi[f, p]
        Br[i, p] -= a * Br[j, p] - b * Bi[j, p]
        Bi[i, p] -= a * Bi[j, p] + b * Br[j, p]


@njit(cache=True, nogil=True, boundscheck=False)
def _solve(Ar, Ai, base, N, piv, br, bi, P):
    """Solve A y = b in place in br, bi (N, capacity) with the factors of :func:`_lu`."""
    for k in range(N):
        for p in range(P):
            if piv[k, p] != k:
                _swap(br, bi, k, piv[k, p], p)
    for i in range(N):
        for j in range(i):
            _sub_product(br, bi, i, j, Ar, Ai, base + i * N + j, P)
    for i in range(N - 1, -1, -1):
        for j in range(i + 1, N):
            _sub_product(br, bi, i, j, Ar, Ai, base + i * N + j, P)
        _mul_row(br, bi, i, Ar, Ai, base + i * N + i, P)


@njit(cache=True, nogil=True, boundscheck=False)
def _eval(code, imm, Rr, Ri, Or, Oi, N, xr, xi, s, P):
    """Outputs of the H+J+Hs tape at the points x (N, capacity) and path parameters s (capacity,)."""
    for v in range(N):
        for p in range(P):
            Rr[v, p] = xr[v, p]
            Ri[v, p] = xi[v, p]
    for p in range(P):
        Rr[N, p] = s[p]
        Ri[N, p] = 0.0
    run_tape(code, imm, Rr, Ri, Or, Oi, P)


@njit(cache=True, nogil=True, boundscheck=False)
def _tangent(Or, Oi, N, piv, kr, ki, P):
    """k = -J^-1 dH/ds with the factored Jacobian in the outputs."""
    hs = N + N * N
    for v in range(N):
        for p in range(P):
            kr[v, p] = -Or[hs + v, p]
            ki[v, p] = -Oi[hs + v, p]
    _solve(Or, Oi, N, N, piv, kr, ki, P)


@njit(cache=True, nogil=True, boundscheck=False)
def _newton_step(code, imm, Rr, Ri, Or, Oi, N, xr, xi, s, piv, ok, dxr, dxi, P):
    """Newton correction dx = J^-1 H at (x, s) (not applied); the factored Jacobian stays in the outputs."""
    _eval(code, imm, Rr, Ri, Or, Oi, N, xr, xi, s, P)
    _lu(Or, Oi, N, N, piv, ok, P)
    for v in range(N):
        for p in range(P):
            dxr[v, p] = Or[v, p]
            dxi[v, p] = Oi[v, p]
    _solve(Or, Oi, N, N, piv, dxr, dxi, P)


@njit(cache=True, nogil=True, boundscheck=False)
def _load_segment(Rr, Ri, N, q0, dq, b, col):
    """Segment b's start parameters and direction into the tape's input rows of column col."""
    Q = q0.shape[1]
    for k in range(Q):
        Rr[N + 1 + k, col] = q0[b, k].real
        Ri[N + 1 + k, col] = q0[b, k].imag
        Rr[N + 1 + Q + k, col] = dq[b, k].real
        Ri[N + 1 + Q + k, col] = dq[b, k].imag


@njit(cache=True, nogil=True)
def _track_batch(code, imm, n_reg, n_out, x0, q0, dq, inst, opts, x_out, stats):
    """Track paths x0 (M, N) along the segments q0 + s dq (B, Q) (path m on inst[m]); endpoints to
    x_out (M, N) and stats (M, 4): status, steps, rejected, last s (as tracker._track_one)."""
    h0, hmin, hmax, target, accept, tol = opts[0], opts[1], opts[2], opts[3], opts[4], opts[5]
    newton, final_newton, max_steps, big = int(opts[6]), int(opts[7]), int(opts[8]), opts[9]
    contract = opts[10]
    M, N = x0.shape
    Q = q0.shape[1]
    cap = max(M, 1)
    Rr = np.zeros((n_reg, cap))
    Ri = np.zeros((n_reg, cap))
    Or = np.zeros((n_out, cap))
    Oi = np.zeros((n_out, cap))
    piv = np.zeros((N, cap), dtype=np.int64)
    ok = np.zeros(cap, dtype=np.bool_)
    # state per column (live path), compacted as paths end
    ids = np.arange(M)
    xr = np.empty((N, cap))
    xi = np.empty((N, cap))
    for m in range(M):
        for v in range(N):
            xr[v, m] = x0[m, v].real
            xi[v, m] = x0[m, v].imag
    s = np.zeros(cap)
    h = np.full(cap, h0)
    steps = np.zeros(cap, dtype=np.int64)
    rejected = np.zeros(cap, dtype=np.int64)
    status = np.full(cap, -1, dtype=np.int64)  # -1 running
    k1r = np.empty((N, cap))
    k1i = np.empty((N, cap))
    k2r = np.empty((N, cap))
    k2i = np.empty((N, cap))
    k3r = np.empty((N, cap))
    k3i = np.empty((N, cap))
    k4r = np.empty((N, cap))
    k4i = np.empty((N, cap))
    ktr = np.empty((N, cap))
    kti = np.empty((N, cap))
    xtr = np.empty((N, cap))
    xti = np.empty((N, cap))
    xpr = np.empty((N, cap))
    xpi = np.empty((N, cap))
    dxr = np.empty((N, cap))
    dxi = np.empty((N, cap))
    st = np.empty(cap)
    s1 = np.empty(cap)
    scale = np.ones(cap)
    e0 = np.empty(cap)
    e = np.empty(cap)
    good = np.empty(cap, dtype=np.bool_)  # predictor succeeded
    done = np.empty(cap, dtype=np.bool_)  # corrector finished
    # segment data in the tape's input rows (written again when columns move)
    for m in range(M):
        _load_segment(Rr, Ri, N, q0, dq, inst[m], m)
    P = M
    # tangent at the start
    _eval(code, imm, Rr, Ri, Or, Oi, N, xr, xi, s, P)
    _lu(Or, Oi, N, N, piv, ok, P)
    _tangent(Or, Oi, N, piv, k1r, k1i, P)
    for p in range(P):
        if not ok[p]:
            status[p] = 1
    while True:
        # -- retire the paths that ended (write results, compact the live columns) -------------
        w = 0
        for p in range(P):
            if status[p] == -1 and steps[p] + rejected[p] >= max_steps:
                status[p] = 1
            if status[p] != -1:
                m = ids[p]
                for v in range(N):
                    x_out[m, v] = xr[v, p] + 1j * xi[v, p]
                stats[m, 0] = status[p]
                stats[m, 1] = steps[p]
                stats[m, 2] = rejected[p]
                stats[m, 3] = s[p]
                continue
            if w != p:
                ids[w] = ids[p]
                for v in range(N):
                    xr[v, w] = xr[v, p]
                    xi[v, w] = xi[v, p]
                    k1r[v, w] = k1r[v, p]
                    k1i[v, w] = k1i[v, p]
                for k in range(N + 1, N + 1 + 2 * Q):
                    Rr[k, w] = Rr[k, p]
                    Ri[k, w] = Ri[k, p]
                s[w] = s[p]
                h[w] = h[p]
                steps[w] = steps[p]
                rejected[w] = rejected[p]
                status[w] = -1
            w += 1
        P = w
        if P == 0:
            break
        # -- RK4 predictor: three more tangents ----------------------------------------------------
        for p in range(P):
            if h[p] > 1.0 - s[p]:
                h[p] = 1.0 - s[p]
            good[p] = True
        for stage in range(3):
            if stage == 0:
                kr, ki = k1r, k1i
            elif stage == 1:
                kr, ki = k2r, k2i
            else:
                kr, ki = k3r, k3i
            for p in range(P):
                c = 0.5 * h[p] if stage < 2 else h[p]
                st[p] = s[p] + c
                for v in range(N):
                    xtr[v, p] = xr[v, p] + c * kr[v, p]
                    xti[v, p] = xi[v, p] + c * ki[v, p]
            _eval(code, imm, Rr, Ri, Or, Oi, N, xtr, xti, st, P)
            _lu(Or, Oi, N, N, piv, ok, P)
            if stage == 0:
                _tangent(Or, Oi, N, piv, k2r, k2i, P)
            elif stage == 1:
                _tangent(Or, Oi, N, piv, k3r, k3i, P)
            else:
                _tangent(Or, Oi, N, piv, k4r, k4i, P)
            for p in range(P):
                if not ok[p]:
                    good[p] = False
        for p in range(P):
            s1[p] = s[p] + h[p]
            if 1.0 - s1[p] < 1e-14:
                s1[p] = 1.0
            hh = h[p] / 6.0
            acc = 0.0
            for v in range(N):
                a = xr[v, p] + hh * (k1r[v, p] + 2.0 * k2r[v, p] + 2.0 * k3r[v, p] + k4r[v, p])
                b = xi[v, p] + hh * (k1i[v, p] + 2.0 * k2i[v, p] + 2.0 * k3i[v, p] + k4i[v, p])
                xpr[v, p] = a
                xpi[v, p] = b
                acc += a * a + b * b
            scale[p] = 1.0 + np.sqrt(acc)
            e0[p] = np.inf
            e[p] = np.inf
            done[p] = not good[p]
        # -- Newton corrector; each iteration's factorisation gives the tangent at the new point --
        for it in range(newton):
            _newton_step(code, imm, Rr, Ri, Or, Oi, N, xpr, xpi, s1, piv, ok, dxr, dxi, P)
            _tangent(Or, Oi, N, piv, k2r, k2i, P)  # k2 is free after the predictor
            for p in range(P):
                if done[p]:
                    continue
                if not ok[p]:
                    e[p] = np.inf
                    done[p] = True
                    continue
                acc = 0.0
                for v in range(N):
                    xpr[v, p] -= dxr[v, p]
                    xpi[v, p] -= dxi[v, p]
                    acc += dxr[v, p] * dxr[v, p] + dxi[v, p] * dxi[v, p]
                    ktr[v, p] = k2r[v, p]
                    kti[v, p] = k2i[v, p]
                e[p] = np.sqrt(acc) / scale[p]
                if it == 0:
                    e0[p] = e[p]
                    if not (e0[p] < accept):
                        done[p] = True
                        continue
                if e[p] < tol or (it > 0 and e[p] < contract * e0[p] and e[p] < 1e-5):
                    done[p] = True
        # -- accept or reject, step size -------------------------------------------------------------
        for p in range(P):
            if good[p] and np.isfinite(e[p]) and e0[p] < accept and (e[p] < tol or e[p] < contract * e0[p]):
                for v in range(N):
                    xr[v, p] = xpr[v, p]
                    xi[v, p] = xpi[v, p]
                    k1r[v, p] = ktr[v, p]
                    k1i[v, p] = kti[v, p]
                s[p] = s1[p]
                steps[p] += 1
                if s[p] >= 1.0:
                    status[p] = 0
                    continue
                if scale[p] > big:
                    status[p] = 2
                    continue
                f = 2.0
                if e0[p] > 0:
                    f = 0.8 * (target / e0[p]) ** 0.2
                f = min(max(f, 0.5), 2.0)
                h[p] = min(h[p] * f, hmax)
            else:
                rejected[p] += 1
                h[p] *= 0.5
                if h[p] < hmin:
                    status[p] = 2 if scale[p] > big else 1
    # -- Newton steps on the target system for the paths that reached s = 1 ---------------------------
    P = 0
    for m in range(M):
        if stats[m, 0] == 0:
            ids[P] = m
            for v in range(N):
                xr[v, P] = x_out[m, v].real
                xi[v, P] = x_out[m, v].imag
            _load_segment(Rr, Ri, N, q0, dq, inst[m], P)
            s[P] = 1.0
            done[P] = False
            P += 1
    for it in range(final_newton):
        _newton_step(code, imm, Rr, Ri, Or, Oi, N, xr, xi, s, piv, ok, dxr, dxi, P)
        for p in range(P):
            if done[p] or not ok[p]:
                done[p] = True
                continue
            a = 0.0
            b = 0.0
            for v in range(N):
                xr[v, p] -= dxr[v, p]
                xi[v, p] -= dxi[v, p]
                a += dxr[v, p] * dxr[v, p] + dxi[v, p] * dxi[v, p]
                b += xr[v, p] * xr[v, p] + xi[v, p] * xi[v, p]
            if np.sqrt(a) < 1e-15 * (1.0 + np.sqrt(b)):
                done[p] = True
    for p in range(P):
        for v in range(N):
            x_out[ids[p], v] = xr[v, p] + 1j * xi[v, p]


def track(tape: Tape, q0: np.ndarray, q1: np.ndarray, x0: np.ndarray, inst: np.ndarray | None = None,
          options: TrackerOptions = TrackerOptions()) -> tuple[np.ndarray, np.ndarray]:
    """Track x0 (P, N) along q0 -> q1 ((B, Q) or (Q,), broadcast); path p on segment inst[p].

    ``tape``: the H+J+dH/ds tape of :func:`solvers.methods.slp.homotopy_program`. Returns endpoints
    (P, N) (NaN unless the path reached s = 1) and stats (P, 4), as :func:`tracker.track`.
    """
    if options.predictor != "rk4":
        raise ValueError(f"the batched tracker predicts by rk4 only, not {options.predictor!r}")
    x0 = np.ascontiguousarray(np.atleast_2d(x0), dtype=np.complex128)
    M, N = x0.shape
    q0 = np.atleast_2d(np.asarray(q0, dtype=np.complex128))
    q1 = np.atleast_2d(np.asarray(q1, dtype=np.complex128))
    B = max(len(q0), len(q1))
    q0 = np.ascontiguousarray(np.broadcast_to(q0, (B, q0.shape[1])))
    dq = np.ascontiguousarray(np.broadcast_to(q1, q0.shape) - q0)
    if tape.n_inputs != N + 1 + 2 * q0.shape[1]:
        raise ValueError(f"the tape has {tape.n_inputs} inputs; {N} unknowns and {q0.shape[1]} parameters need "
                         f"{N + 1 + 2 * q0.shape[1]}")
    inst = np.zeros(M, dtype=np.int64) if inst is None else np.ascontiguousarray(inst, dtype=np.int64)
    x = np.empty_like(x0)
    stats = np.zeros((M, 4))
    if M:
        _track_batch(tape.code, tape.imm, tape.n_registers, tape.n_outputs, x0, q0, dq, inst,
                     options.as_array(), x, stats)
    x[stats[:, 0] != 0] = np.nan
    return x, stats
