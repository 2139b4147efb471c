"""Everything numba compiles for straight-line programs: the tape interpreter, the batched LU and the lock-step
path tracker's kernels (their Python entry points, threads and batches: :mod:`solvers.continuation.tape_kernel`).

One file on purpose: numba's on-disk cache is invalidated by changes to the file that defines a function, not by
changes to the functions it calls from other files, so a compiled function that calls another compiled one must
live beside it (else an edit to the callee leaves a stale caller in the cache). The Python side that calls these
kernels (no numba code) lives in :mod:`~solvers.continuation.tape_kernel`.

Interpreter (:func:`run_tape`). Registers hold complex numbers as two real arrays (real and
imaginary parts) of shape (registers, points); every instruction runs over all points (live paths)
in its inner loop, so the cost of dispatching an instruction (a few ns) is spread over the points and
the loop over points is plain vectorisable arithmetic. One kernel for every system, compiled once and
cached on disk: no system needs its own compile. Where the machine has a C compiler, each solver's tapes
are also written out as straight-line C (:mod:`solvers.continuation.tape_native`, built in the background on
first use); the tracker then calls that code through its address (:func:`_call_native`: one compiled
tracker for every solver), with bit-identical results, 1.5-3x faster, most in the lock step's tail.

Batched tracker (:func:`_track_batch`). The predictor-corrector of :mod:`solvers.continuation.tracker` (classical
RK4 on the tangent field, Newton corrector, step size from the first Newton correction; tight
retracking by the caller), the step logic of ``tracker._track_one`` kept path by path but run in lock
step. A second predictor, Pade (:func:`_pade`, :func:`_taylor`): at each accepted point the path's
Taylor coefficients x1 (the tangent), x2, x3 (central differences of the residual tape along the
path's expansion, solved with the factorisation already at hand: four runs of the short H tape, no
factorisation) give a type (2, 1) Pade approximant per coordinate, which follows a nearby pole of the
path (Timme 2021); a rejected step costs only its corrector. Each round every live path makes one
step attempt; each evaluation of H, dH/dx (and dH/ds) is one run of a tape over all live paths,
followed by one batched LU with partial pivoting of the N x N Jacobians (paths in the inner loop). The Newton
steps before the last use the tape without dH/ds (:class:`slp.HomotopyTapes`); the last one's factorisation
gives the next tangent. Paths that end leave the batch at the end of the round (their columns are compacted
away). Statuses as in the tracker: 0 reached s = 1, 1 stalled (or out of steps, or singular Jacobian), 2 diverged.

References: Sommese & Wampler (2005), ch. 2 and 7; Timme, "Mixed precision path tracking for polynomial
homotopy continuation" (2021), for tracking many paths of one compiled program.
"""
from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

__all__ = ["NEWTON_ONLY", "OPCODES", "PADE", "TAYLOR_DELTA", "TAYLOR_DELTA3", "WIDTH", "capacity", "run_tape"]

#: Instruction set of the tape: d = a + b, a - b, a b, -a, imm a, a + imm, a a, imm; fused: c + imm a b
#: (imm = +-1), a + imm b; OUT copies register a to output row d. a, b, c are registers, imm the
#: instruction's real immediate; the inputs' registers are written by the caller before a run.
OPCODES = ("ADD", "SUB", "MUL", "NEG", "CMUL", "CADD", "SQR", "CONST", "OUT", "MULADD", "AXPY")
ADD, SUB, MUL, NEG, CMUL, CADD, SQR, CONST, OUT, MULADD, AXPY = range(len(OPCODES))


@njit(cache=True, nogil=True, boundscheck=False)
def run_tape(code, imm, Rr, Ri, Or, Oi, P):
    """Run the tape on points 0..P-1: registers Rr, Ri (n_registers, capacity) with the inputs in
    their first rows; output rows of Or, Oi (n_outputs, capacity) written."""
    for k in range(code.shape[0]):
        op = code[k, 0]
        d = code[k, 1]
        a = code[k, 2]
        b = code[k, 3]
        if op == MULADD:
            c = code[k, 4]
            w = imm[k]
            for p in range(P):
                ar = Rr[a, p]
                ai = Ri[a, p]
                br = Rr[b, p]
                bi = Ri[b, p]
                xr = Rr[c, p] + w * (ar * br - ai * bi)
                xi = Ri[c, p] + w * (ar * bi + ai * br)
                Rr[d, p] = xr
                Ri[d, p] = xi
        elif op == AXPY:
            w = imm[k]
            for p in range(P):
                xr = Rr[a, p] + w * Rr[b, p]
                xi = Ri[a, p] + w * Ri[b, p]
                Rr[d, p] = xr
                Ri[d, p] = xi
        elif op == MUL:
            for p in range(P):
                ar = Rr[a, p]
                ai = Ri[a, p]
                br = Rr[b, p]
                bi = Ri[b, p]
                Rr[d, p] = ar * br - ai * bi
                Ri[d, p] = ar * bi + ai * br
        elif op == ADD:
            for p in range(P):
                xr = Rr[a, p] + Rr[b, p]
                xi = Ri[a, p] + Ri[b, p]
                Rr[d, p] = xr
                Ri[d, p] = xi
        elif op == SUB:
            for p in range(P):
                xr = Rr[a, p] - Rr[b, p]
                xi = Ri[a, p] - Ri[b, p]
                Rr[d, p] = xr
                Ri[d, p] = xi
        elif op == CMUL:
            c = imm[k]
            for p in range(P):
                xr = c * Rr[a, p]
                xi = c * Ri[a, p]
                Rr[d, p] = xr
                Ri[d, p] = xi
        elif op == SQR:
            for p in range(P):
                ar = Rr[a, p]
                ai = Ri[a, p]
                Rr[d, p] = ar * ar - ai * ai
                Ri[d, p] = 2.0 * ar * ai
        elif op == CADD:
            c = imm[k]
            for p in range(P):
                xr = Rr[a, p] + c
                xi = Ri[a, p]
                Rr[d, p] = xr
                Ri[d, p] = xi
        elif op == NEG:
            for p in range(P):
                xr = -Rr[a, p]
                xi = -Ri[a, p]
                Rr[d, p] = xr
                Ri[d, p] = xi
        elif op == CONST:
            c = imm[k]
            for p in range(P):
                Rr[d, p] = c
                Ri[d, p] = 0.0
        elif op == OUT:
            for p in range(P):
                Or[d, p] = Rr[a, p]
                Oi[d, p] = Ri[a, p]


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
    ok[p] is False where a matrix is singular (its column then holds inf or nan, the others not).

    Interchanges as in LINPACK's zgefa: step k swaps rows k and piv[k] in columns k.. only (the
    multipliers stay where they were computed; :func:`_solve` interleaves the swaps), and every loop
    runs over the points, so it vectorises (the solver's compiled LU, :func:`_factor`, does the same
    operations four points per pass)."""
    best = np.empty(P)
    for p in range(P):
        ok[p] = True
    for k in range(N):
        kk = base + k * N + k
        for p in range(P):
            best[p] = Ar[kk, p] * Ar[kk, p] + Ai[kk, p] * Ai[kk, p]
            piv[k, p] = k
        for i in range(k + 1, N):
            ik = base + i * N + k
            for p in range(P):
                a = Ar[ik, p] * Ar[ik, p] + Ai[ik, p] * Ai[ik, p]
                if a > best[p]:
                    best[p] = a
                    piv[k, p] = i
        for j in range(k, N):
            for p in range(P):  # (a swap of row k with itself where piv[k, p] = k)
                _swap(Ar, Ai, base + k * N + j, base + piv[k, p] * N + j, p)
        for p in range(P):
            b = best[p]
            if not (b > 0.0) or not np.isfinite(b):
                ok[p] = False
                b = 1e-300
            Ar[kk, p] = Ar[kk, p] / b
            Ai[kk, p] = -Ai[kk, p] / b
        for i in range(k + 1, N):
            ik = base + i * N + k
            _mul_row(Ar, Ai, ik, Ar, Ai, kk, P)
            for j in range(k + 1, N):
                _sub_product(Ar, Ai, base + i * N + j, base + k * N + j, Ar, Ai, ik, P)


@njit(cache=True, nogil=True, boundscheck=False)
def _mul_row(Br, Bi, i, Fr, Fi, f, P):
    """Row i of B *= row f of F, over the points."""
    for p in range(P):
        yr = Br[i, p] * Fr[f, p] - Bi[i, p] * Fi[f, p]
        yi = Br[i, p] * Fi[f, p] + Bi[i, p] * Fr[f, p]
        Br[i, p] = yr
        Bi[i, p] = yi


@njit(cache=True, nogil=True, boundscheck=False)
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
            _swap(br, bi, k, piv[k, p], p)
        for i in range(k + 1, N):
            _sub_product(br, bi, i, k, Ar, Ai, base + i * N + k, P)
    for i in range(N - 1, -1, -1):
        for j in range(i + 1, N):
            _sub_product(br, bi, i, j, Ar, Ai, base + i * N + j, P)
        _mul_row(br, bi, i, Ar, Ai, base + i * N + i, P)


#: Points per pass of a tape's compiled code (:mod:`solvers.continuation.tape_native`): the tracker's arrays have
#: room for a multiple of it.
WIDTH = 4


@intrinsic
def _call_native(typingctx, fn, P, C, R, I, OR, OI):
    """Call the compiled tape at address fn (``void f(long P, long C, double *R, *I, *OR, *OI)``); all
    arguments are int64 (the arrays' data addresses), so one compiled kernel serves every solver."""
    sig = types.void(types.int64, types.int64, types.int64, types.int64, types.int64, types.int64, types.int64)

    def codegen(context, builder, signature, args):
        i64, dptr = ir.IntType(64), ir.DoubleType().as_pointer()
        fnty = ir.FunctionType(ir.VoidType(), [i64, i64, dptr, dptr, dptr, dptr])
        f = builder.inttoptr(args[0], fnty.as_pointer())
        builder.call(f, [args[1], args[2]] + [builder.inttoptr(a, dptr) for a in args[3:]])
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def _call_lu(typingctx, fn, P, C, Ar, Ai, base, piv, ok):
    """Call a compiled LU (``void f(long P, long C, double *Ar, *Ai, long base, long *piv, unsigned char *ok)``)
    at address fn; the arrays as their data addresses (int64)."""
    sig = types.void(*([types.int64] * 8))

    def codegen(context, builder, signature, args):
        i64, dptr, i8ptr = ir.IntType(64), ir.DoubleType().as_pointer(), ir.IntType(8).as_pointer()
        fnty = ir.FunctionType(ir.VoidType(), [i64, i64, dptr, dptr, i64, i64.as_pointer(), i8ptr])
        f = builder.inttoptr(args[0], fnty.as_pointer())
        builder.call(f, [args[1], args[2], builder.inttoptr(args[3], dptr), builder.inttoptr(args[4], dptr), args[5],
                         builder.inttoptr(args[6], i64.as_pointer()), builder.inttoptr(args[7], i8ptr)])
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def _call_solve(typingctx, fn, P, C, Ar, Ai, base, piv, br, bi):
    """Call a compiled solve (``void f(long P, long C, double *Ar, *Ai, long base, long *piv, double *br, *bi)``)."""
    sig = types.void(*([types.int64] * 9))

    def codegen(context, builder, signature, args):
        i64, dptr = ir.IntType(64), ir.DoubleType().as_pointer()
        fnty = ir.FunctionType(ir.VoidType(), [i64, i64, dptr, dptr, i64, i64.as_pointer(), dptr, dptr])
        f = builder.inttoptr(args[0], fnty.as_pointer())
        builder.call(f, [args[1], args[2], builder.inttoptr(args[3], dptr), builder.inttoptr(args[4], dptr), args[5],
                         builder.inttoptr(args[6], i64.as_pointer()), builder.inttoptr(args[7], dptr),
                         builder.inttoptr(args[8], dptr)])
        return context.get_dummy_value()

    return sig, codegen


@njit(cache=True, nogil=True, boundscheck=False)
def _factor(lin, Ar, Ai, base, N, piv, ok, P):
    """:func:`_lu`, by the solver's compiled LU at address lin[0] where there is one (the same bits)."""
    if lin[0] != 0:
        _call_lu(lin[0], P, Ar.shape[1], Ar.ctypes.data, Ai.ctypes.data, base, piv.ctypes.data, ok.ctypes.data)
    else:
        _lu(Ar, Ai, base, N, piv, ok, P)


@njit(cache=True, nogil=True, boundscheck=False)
def _back(lin, Ar, Ai, base, N, piv, br, bi, P):
    """:func:`_solve`, by the solver's compiled solve at address lin[1] where there is one (the same bits)."""
    if lin[1] != 0:
        _call_solve(lin[1], P, Ar.shape[1], Ar.ctypes.data, Ai.ctypes.data, base, piv.ctypes.data, br.ctypes.data,
                    bi.ctypes.data)
    else:
        _solve(Ar, Ai, base, N, piv, br, bi, P)


@njit(cache=True, nogil=True, boundscheck=False)
def _eval(code, imm, fn, Rr, Ri, Or, Oi, N, xr, xi, s, P):
    """Outputs of a homotopy tape at the points x (N, capacity) and path parameters s (capacity,): by its
    compiled code at address fn (0: the interpreter; both give the same bits)."""
    for v in range(N):
        for p in range(P):
            Rr[v, p] = xr[v, p]
            Ri[v, p] = xi[v, p]
    for p in range(P):
        Rr[N, p] = s[p]
        Ri[N, p] = 0.0
    if fn != 0:
        _call_native(fn, P, Rr.shape[1], Rr.ctypes.data, Ri.ctypes.data, Or.ctypes.data, Oi.ctypes.data)
    else:
        run_tape(code, imm, Rr, Ri, Or, Oi, P)


@njit(cache=True, nogil=True, boundscheck=False)
def _tangent(lin, Or, Oi, N, piv, kr, ki, P):
    """k = -J^-1 dH/ds with the factored Jacobian in the outputs."""
    hs = N + N * N
    for v in range(N):
        for p in range(P):
            kr[v, p] = -Or[hs + v, p]
            ki[v, p] = -Oi[hs + v, p]
    _back(lin, Or, Oi, N, N, piv, kr, ki, P)


@njit(cache=True, nogil=True, boundscheck=False)
def _newton_step(code, imm, fn, lin, Rr, Ri, Or, Oi, N, xr, xi, s, piv, ok, dxr, dxi, P):
    """Newton correction dx = J^-1 H at (x, s) (not applied); the factored Jacobian stays in the outputs."""
    _eval(code, imm, fn, Rr, Ri, Or, Oi, N, xr, xi, s, P)
    _factor(lin, Or, Oi, N, N, piv, ok, P)
    _correction(lin, Or, Oi, N, piv, dxr, dxi, P)


@njit(cache=True, nogil=True, boundscheck=False)
def _correction(lin, Or, Oi, N, piv, dxr, dxi, P):
    """dx = J^-1 H with H and the factored J in the outputs."""
    for v in range(N):
        for p in range(P):
            dxr[v, p] = Or[v, p]
            dxi[v, p] = Oi[v, p]
    _back(lin, Or, Oi, N, N, piv, dxr, dxi, P)


@njit(cache=True, nogil=True, boundscheck=False)
def _load_segment(Rr, Ri, N, q0, dq, b, col):
    """Segment b's start parameters and direction into the tape's input rows of column col."""
    Q = q0.shape[1]
    for k in range(Q):
        Rr[N + 1 + k, col] = q0[b, k].real
        Ri[N + 1 + k, col] = q0[b, k].imag
        Rr[N + 1 + Q + k, col] = dq[b, k].real
        Ri[N + 1 + Q + k, col] = dq[b, k].imag


#: Largest step in s of the finite differences that give the Taylor coefficients of the path (and at most
#: a tenth of the next step: the rounding error of x3 h^3 then stays ~ 1e3 eps times the terms' size).
TAYLOR_DELTA = 1e-4

#: The same for x3 (a third difference: its rounding error, ~ eps / d^3, balances the truncation error, ~ d^2,
#: near eps^(1/5); at 1e-4 x3 was good to 2e-4 on the test path, at 5e-4 to 2e-5, in as many steps).
TAYLOR_DELTA3 = 5e-4

#: Index of the Pade predictor in :data:`tracker.PREDICTORS`.
PADE = 2

#: Index of the options array's flag for Newton steps only (:func:`newton` runs through the tracker's kernel,
#: the final Newton steps alone: one compiled entry point, where a kernel of its own took 12.8 of the 33 s
#: of a first call in a fresh environment). :meth:`TrackerOptions.as_array` has no such entry.
NEWTON_ONLY = 12


@njit(cache=True, nogil=True, boundscheck=False)
def _taylor(rcode, rimm, rfn, lin, Rr, Ri, Or, Oi, N, xr, xi, H0r, H0i, s, h, k1r, k1i, piv, fresh, x2r, x2i, x3r, x3i,
            xtr, xti, st, dl, tv, work, P):
    """Taylor coefficients x2, x3 of the path x(s + t) = x + t x1 + t^2 x2 + t^3 x3 + ... through the points x
    where the full tape ran last (H0 = H there, x1 = k1 the tangent solved there with the factorisation in the
    outputs), at the columns with ``fresh``: x_k = -J^-1 c_k, c_k the t^k coefficient of H along the path's
    lower-order expansion, by central differences of the residual tape: c2 from H at t = +-d on x + t x1
    (and H0), c3 from the odd part at t = +-d3 on x + t x1 + t^2 x2, which has no t term (J x1 + dH/ds = 0 at
    x) and no t^2 term. Four runs. The outputs' H rows are overwritten, the factorisation (rows N..) is
    kept. Every loop runs over the columns (vectorised); dl, tv, st: scratch (P,)."""
    for p in range(P):
        dl[p] = min(TAYLOR_DELTA, 0.1 * h[p])
    Cr, Ci, Tr, Ti = work[0], work[1], work[2], work[3]
    for v in range(N):
        for p in range(P):
            Cr[v, p] = -2.0 * H0r[v, p]
            Ci[v, p] = -2.0 * H0i[v, p]
            Tr[v, p] = 0.0
            Ti[v, p] = 0.0
    # t = d, -d on x + t x1 (c2 -> x2, into T), then t = d, -d on x + t x1 + t^2 x2 (c3 -> x3, in C): one
    # evaluation site (T is zero for the first two points)
    for k in range(4):
        m = 1.0 if k % 2 == 0 else -1.0
        w = 1.0 if k < 2 else m
        if k == 2:
            for p in range(P):
                dl[p] = min(TAYLOR_DELTA3, 0.1 * h[p])
        for p in range(P):
            t = m * dl[p]
            tv[p] = t
            st[p] = s[p] + t
        for v in range(N):
            for p in range(P):
                t = tv[p]
                xtr[v, p] = xr[v, p] + t * (k1r[v, p] + t * Tr[v, p])
                xti[v, p] = xi[v, p] + t * (k1i[v, p] + t * Ti[v, p])
        _eval(rcode, rimm, rfn, Rr, Ri, Or, Oi, N, xtr, xti, st, P)
        for v in range(N):
            for p in range(P):
                Cr[v, p] += w * Or[v, p]
                Ci[v, p] += w * Oi[v, p]
        if k == 1:  # x2 = -J^-1 c2, c2 = (H(d) + H(-d) - 2 H0) / (2 d^2)
            for p in range(P):
                tv[p] = -0.5 / (dl[p] * dl[p])
            for v in range(N):
                for p in range(P):
                    c = tv[p]
                    Tr[v, p] = c * Cr[v, p]
                    Ti[v, p] = c * Ci[v, p]
                    Cr[v, p] = 0.0
                    Ci[v, p] = 0.0
            _back(lin, Or, Oi, N, N, piv, Tr, Ti, P)
    for p in range(P):  # x3 = -J^-1 c3, c3 = (H(d) - H(-d)) / (2 d^3)
        tv[p] = -0.5 / (dl[p] * dl[p] * dl[p])
    for v in range(N):
        for p in range(P):
            c = tv[p]
            Cr[v, p] *= c
            Ci[v, p] *= c
    _back(lin, Or, Oi, N, N, piv, Cr, Ci, P)
    for v in range(N):
        for p in range(P):
            if fresh[p]:
                x2r[v, p] = Tr[v, p]
                x2i[v, p] = Ti[v, p]
                x3r[v, p] = Cr[v, p]
                x3i[v, p] = Ci[v, p]


@njit(cache=True, nogil=True, boundscheck=False)
def _pade(xr, xi, k1r, k1i, x2r, x2i, x3r, x3i, h, N, xpr, xpi, P):
    """Columns p < P of xp = the path at s + h[p] by the Pade approximant of type (2, 1) of each
    coordinate's Taylor polynomial x + h x1 + h^2 x2 + h^3 x3: (x + (x1 + b x) h + (x2 + b x1) h^2) / (1 + b h),
    b = -x3 / x2, where the pole's term matters (|x3| h >= 1e-2 |x2|); else the Taylor polynomial."""
    for v in range(N):
        for p in range(P):
            hp = h[p]
            ar, ai = x2r[v, p], x2i[v, p]
            cr, ci = x3r[v, p], x3i[v, p]
            a2 = ar * ar + ai * ai
            c2 = cr * cr + ci * ci
            if a2 > 0.0 and c2 * hp * hp >= 1e-4 * a2:
                br = -(cr * ar + ci * ai) / a2  # b = -x3 / x2
                bi = -(ci * ar - cr * ai) / a2
                nr = xr[v, p] + hp * (k1r[v, p] + br * xr[v, p] - bi * xi[v, p]) + hp * hp * (ar + br * k1r[v, p] - bi * k1i[v, p])
                ni = xi[v, p] + hp * (k1i[v, p] + br * xi[v, p] + bi * xr[v, p]) + hp * hp * (ai + br * k1i[v, p] + bi * k1r[v, p])
                dr = 1.0 + hp * br
                di = hp * bi
                d = dr * dr + di * di
                xpr[v, p] = (nr * dr + ni * di) / d
                xpi[v, p] = (ni * dr - nr * di) / d
            else:
                xpr[v, p] = xr[v, p] + hp * (k1r[v, p] + hp * (ar + hp * cr))
                xpi[v, p] = xi[v, p] + hp * (k1i[v, p] + hp * (ai + hp * ci))


@njit(cache=True, nogil=True, boundscheck=False)
def _copy_rows(Ar, Ai, N, Br, Bi, P):
    """B = the first N rows of A (columns p < P)."""
    for v in range(N):
        for p in range(P):
            Br[v, p] = Ar[v, p]
            Bi[v, p] = Ai[v, p]


@njit(cache=True, nogil=True, boundscheck=False)
def capacity(M):
    """Columns of the tracker's arrays for M paths: room for the compiled code's last pass of four, and an odd
    number of 64-byte cache lines per row (a multiple of 16 columns put 5r/5s's 64 paths on rows 512 bytes
    apart, which share a few of the L1 cache's sets: the Jacobians' LU ran 2.3x slower, a plain track 1.15x)."""
    cap = (max(M, 1) + 7) // 8 * 8
    if cap % 16 == 0:
        cap += 8
    return cap


@njit(cache=True, nogil=True)
def _track_batch(code, imm, ncode, nimm, rcode, rimm, fns, chord, n_reg, n_out, x0, q0, dq, inst, opts, x_out, stats):
    """Track paths x0 (M, N) along the segments q0 + s dq (B, Q) (path m on inst[m]); endpoints to
    x_out (M, N) and stats (M, 4): status, steps, rejected, last s (as tracker._track_one).

    code, imm: the full tape (H, J, dH/ds); ncode, nimm: the Newton tape (H, J); rcode, rimm: the
    residual tape (H). chord: the corrector's steps after the first reuse its Jacobian (see :func:`track`)."""
    h0, hmin, hmax, target, accept, tol = opts[0], opts[1], opts[2], opts[3], opts[4], opts[5]
    newton, final_newton, max_steps, big = int(opts[6]), int(opts[7]), int(opts[8]), opts[9]
    contract = opts[10]
    pade = int(opts[11]) == PADE
    M, N = x0.shape
    Q = q0.shape[1]
    cap = capacity(M)
    fn, nfn, rfn = fns[0], fns[1], fns[2]
    lin = fns[3:5]  # compiled LU and solve (zeros: the batched kernels)
    Rr = np.zeros((n_reg, cap))
    Ri = np.zeros((n_reg, cap))
    Or = np.zeros((n_out, cap))
    Oi = np.zeros((n_out, cap))
    piv = np.zeros((N, cap), dtype=np.int64)
    ok = np.zeros(cap, dtype=np.bool_)
    # state per column (live path), compacted as paths end; zeros, not np.empty: the compiled kernels' last
    # pass of four columns reads the spare ones, and garbage there (denormals) slowed a whole solve 1.5x
    ids = np.arange(M)
    xr = np.zeros((N, cap))
    xi = np.zeros((N, cap))
    for m in range(M):
        for v in range(N):
            xr[v, m] = x0[m, v].real
            xi[v, m] = x0[m, v].imag
    s = np.zeros(cap)
    h = np.full(cap, h0)
    steps = np.zeros(cap, dtype=np.int64)
    rejected = np.zeros(cap, dtype=np.int64)
    status = np.full(cap, -1, dtype=np.int64)  # -1 running
    k1r = np.zeros((N, cap))
    k1i = np.zeros((N, cap))
    k2r = np.zeros((N, cap))
    k2i = np.zeros((N, cap))
    k3r = np.zeros((N, cap))
    k3i = np.zeros((N, cap))
    k4r = np.zeros((N, cap))
    k4i = np.zeros((N, cap))
    ktr = np.zeros((N, cap))
    kti = np.zeros((N, cap))
    xtr = np.zeros((N, cap))
    xti = np.zeros((N, cap))
    xpr = np.zeros((N, cap))
    xpi = np.zeros((N, cap))
    dxr = np.zeros((N, cap))
    dxi = np.zeros((N, cap))
    st = np.zeros(cap)
    tv = np.zeros(cap)
    s1 = np.zeros(cap)
    scale = np.ones(cap)
    e0 = np.zeros(cap)
    e = np.zeros(cap)
    good = np.zeros(cap, dtype=np.bool_)  # predictor succeeded
    done = np.zeros(cap, dtype=np.bool_)  # corrector finished
    live = np.zeros(cap, dtype=np.bool_)  # corrector running, Jacobian regular
    accepted = np.zeros(cap, dtype=np.bool_)  # step accepted
    # Pade predictor: the path's Taylor coefficients x2, x3 at the last accepted point (x1 = k1)
    x2r = np.zeros((N, cap))
    x2i = np.zeros((N, cap))
    x3r = np.zeros((N, cap))
    x3i = np.zeros((N, cap))
    work = np.zeros((4, N, cap))
    fresh = np.zeros(cap, dtype=np.bool_)
    # where the full tape ran last in a round (the Taylor coefficients' expansion point) and H there
    xqr = np.zeros((N, cap))
    xqi = np.zeros((N, cap))
    H0r = np.zeros((N, cap))
    H0i = np.zeros((N, cap))
    # segment data in the tape's input rows (written again when columns move)
    for m in range(M):
        _load_segment(Rr, Ri, N, q0, dq, inst[m], m)
    P = M
    newton_only = opts.shape[0] > NEWTON_ONLY and opts[NEWTON_ONLY] > 0.0
    if newton_only:  # every path "at s = 1": only the final Newton steps run (:func:`newton`)
        for p in range(P):
            status[p] = 0
            s[p] = 1.0
    else:  # tangent at the start
        _eval(code, imm, fn, Rr, Ri, Or, Oi, N, xr, xi, s, P)
        _factor(lin, Or, Oi, N, N, piv, ok, P)
        _tangent(lin, Or, Oi, N, piv, k1r, k1i, P)
        for p in range(P):
            if not ok[p]:
                status[p] = 1
            fresh[p] = ok[p]
        if pade:
            _copy_rows(Or, Oi, N, H0r, H0i, P)  # H where the full tape ran
            _taylor(rcode, rimm, rfn, lin, Rr, Ri, Or, Oi, N, xr, xi, H0r, H0i, s, h, k1r, k1i, piv, fresh, x2r, x2i, x3r,
                    x3i, xtr, xti, st, e, tv, work, P)
    while True:
        # -- retire the paths that ended (write results, compact the live columns) -------------
        w = np.int64(0)  # not a literal 0: see the final Newton steps below
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
                    x2r[v, w] = x2r[v, p]
                    x2i[v, w] = x2i[v, p]
                    x3r[v, w] = x3r[v, p]
                    x3i[v, w] = x3i[v, p]
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
        for stage in range(0 if pade else 3):
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
            _eval(code, imm, fn, Rr, Ri, Or, Oi, N, xtr, xti, st, P)
            _factor(lin, Or, Oi, N, N, piv, ok, P)
            if stage == 0:
                _tangent(lin, Or, Oi, N, piv, k2r, k2i, P)
            elif stage == 1:
                _tangent(lin, Or, Oi, N, piv, k3r, k3i, P)
            else:
                _tangent(lin, Or, Oi, N, piv, k4r, k4i, P)
            for p in range(P):
                if not ok[p]:
                    good[p] = False
        for p in range(P):
            s1[p] = s[p] + h[p]
            if 1.0 - s1[p] < 1e-14:
                s1[p] = 1.0
            e0[p] = np.inf
            e[p] = np.inf
            done[p] = not good[p]
            scale[p] = 0.0
        if pade:
            _pade(xr, xi, k1r, k1i, x2r, x2i, x3r, x3i, h, N, xpr, xpi, P)
        else:
            for v in range(N):
                for p in range(P):
                    hh = h[p] / 6.0
                    xpr[v, p] = xr[v, p] + hh * (k1r[v, p] + 2.0 * k2r[v, p] + 2.0 * k3r[v, p] + k4r[v, p])
                    xpi[v, p] = xi[v, p] + hh * (k1i[v, p] + 2.0 * k2i[v, p] + 2.0 * k3i[v, p] + k4i[v, p])
        for v in range(N):
            for p in range(P):
                scale[p] += xpr[v, p] * xpr[v, p] + xpi[v, p] * xpi[v, p]
        for p in range(P):
            scale[p] = 1.0 + np.sqrt(scale[p])
        # -- corrector. Newton: the last iteration's factorisation gives the tangent at the new point (at
        # the point before its correction; a path whose corrector finished earlier is evaluated there
        # too, at its final point). Chord: the first iteration's factorisation (at the predicted point)
        # serves every iteration and gives the tangent.
        for it in range(newton):
            if chord and it > 0:
                _eval(rcode, rimm, rfn, Rr, Ri, Or, Oi, N, xpr, xpi, s1, P)
                _correction(lin, Or, Oi, N, piv, dxr, dxi, P)
            elif it == newton - 1 or chord:
                _newton_step(code, imm, fn, lin, Rr, Ri, Or, Oi, N, xpr, xpi, s1, piv, ok, dxr, dxi, P)
                _tangent(lin, Or, Oi, N, piv, ktr, kti, P)
                if pade:  # the Taylor coefficients' expansion point: here J, dH/ds, H and the tangent agree
                    _copy_rows(Or, Oi, N, H0r, H0i, P)
                    _copy_rows(xpr, xpi, N, xqr, xqi, P)
            else:
                _newton_step(ncode, nimm, nfn, lin, Rr, Ri, Or, Oi, N, xpr, xpi, s1, piv, ok, dxr, dxi, P)
            for p in range(P):
                live[p] = not done[p] and ok[p]
                if not done[p] and not ok[p]:
                    e[p] = np.inf
                    done[p] = True
                tv[p] = 0.0
            for v in range(N):  # (x - 0.0 is x: the columns that are not live keep their bits)
                for p in range(P):
                    ar = dxr[v, p] if live[p] else 0.0
                    ai = dxi[v, p] if live[p] else 0.0
                    xpr[v, p] -= ar
                    xpi[v, p] -= ai
                    tv[p] += ar * ar + ai * ai
            for p in range(P):
                if not live[p]:
                    continue
                e[p] = np.sqrt(tv[p]) / scale[p]
                if it == 0:
                    e0[p] = e[p]
                    if not (e0[p] < accept):
                        done[p] = True
                        continue
                if e[p] < tol or (it > 0 and e[p] < contract * e0[p] and e[p] < 1e-5):
                    done[p] = True
        # -- accept or reject, step size -------------------------------------------------------------
        for p in range(P):
            accepted[p] = good[p] and np.isfinite(e[p]) and e0[p] < accept and (e[p] < tol or e[p] < contract * e0[p])
        for v in range(N):
            for p in range(P):
                if accepted[p]:
                    xr[v, p] = xpr[v, p]
                    xi[v, p] = xpi[v, p]
                    k1r[v, p] = ktr[v, p]
                    k1i[v, p] = kti[v, p]
        for p in range(P):
            fresh[p] = False
            if accepted[p]:
                s[p] = s1[p]
                steps[p] += 1
                if s[p] >= 1.0:
                    status[p] = 0
                    continue
                if scale[p] > big:
                    status[p] = 2
                    continue
                # local error ~ h^(order + 1) (RK4: 4, Pade (2, 1): 3): aim the next first correction at target
                f = 2.0
                if e0[p] > 0:
                    f = 0.8 * (target / e0[p]) ** (0.25 if pade else 0.2)
                f = min(max(f, 0.5), 2.0)
                h[p] = min(h[p] * f, hmax)
                fresh[p] = True
            else:
                rejected[p] += 1
                h[p] *= 0.5
                if h[p] < hmin:
                    status[p] = 2 if scale[p] > big else 1
        if pade:  # Taylor coefficients at the new points (expanded where the last full tape ran, see above)
            _taylor(rcode, rimm, rfn, lin, Rr, Ri, Or, Oi, N, xqr, xqi, H0r, H0i, s, h, k1r, k1i, piv, fresh, x2r, x2i, x3r,
                    x3i, xtr, xti, st, e, tv, work, P)
    # -- Newton steps on the target system for the paths that reached s = 1 ---------------------------
    # (not "P = 0": numba's type inference would first type the calls below with the literal 0 and compile
    # everything they call a second time for it: several seconds of a first call in a fresh environment)
    P = np.int64(0)
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
    _newton_steps(ncode, nimm, nfn, lin, Rr, Ri, Or, Oi, N, xr, xi, s, piv, ok, dxr, dxi, done, final_newton,
                  0.0 if newton_only else 1e-15, P)
    for p in range(P):
        for v in range(N):
            x_out[ids[p], v] = xr[v, p] + 1j * xi[v, p]


@njit(cache=True, nogil=True, boundscheck=False)
def _newton_steps(code, imm, fn, lin, Rr, Ri, Or, Oi, N, xr, xi, s, piv, ok, dxr, dxi, done, steps, stop, P):
    """Up to ``steps`` Newton steps at the points x (columns with done False): a column stops after a
    step smaller than stop (1 + |x|) or at a singular Jacobian (then unchanged)."""
    for it in range(steps):
        _newton_step(code, imm, fn, lin, Rr, Ri, Or, Oi, N, xr, xi, s, piv, ok, dxr, dxi, P)
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
            if np.sqrt(a) < stop * (1.0 + np.sqrt(b)):
                done[p] = True
