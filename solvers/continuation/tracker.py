"""Compiled path tracker for parameter homotopies of square polynomial systems (numba).

The system is given by its monomial structure and, per instance, the coefficients of every term as a
polynomial in the path parameter s in [0, 1]:

    H_e(x, s) = sum over terms t of equation e of  c_t(s) x^(a_t),   c_t(s) = sum_k G[t, k] s^k.

For a straight segment q(s) = q0 + s (q1 - q0) in parameter space, c_t(s) is the coefficient function
of the parameters evaluated along the segment, a polynomial of the coefficient's degree in q; the
caller computes G by interpolation (:func:`segment_coefficients`), so one compiled kernel serves every
system and every segment (no code is generated per solver, and nothing is compiled per call).

Tracking (per path, all in compiled code, one thread): the tangent dx/ds = -H_x^-1 H_s; a classical
RK4 predictor whose first stage is the tangent already factored at the end of the previous step;
Newton's method at the new s as corrector. The step h adapts to the size of the first Newton
correction (an estimate of the predictor's local error, O(h^5)) and halves on rejection. A path ends
at s = 1 (status 0), stalls when h < hmin (status 1), or diverges when |x| exceeds ``big`` (status 2).
At s = 1 extra Newton steps run on the target system. Sommese & Wampler (2005), ch. 2 and 7.

Compiled kernels are cached on disk (``cache=True``: compiled on the first use on a machine, then
loaded); :func:`warm_up` compiles them explicitly and returns the seconds it took.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numba import njit

__all__ = ["CORRECTORS", "PREDICTORS", "SystemStructure", "TrackerOptions", "evaluate", "segment_coefficients", "track", "warm_up"]


#: Predictors: classical Runge-Kutta on the tangent field (three extra factorisations per step), or cubic
#: Hermite extrapolation through the last two points and tangents (none; first step by RK4), or (the
#: batched tape tracker only, :mod:`solvers.continuation.tape_kernel`) a Pade approximant of type (2, 1) from
#: the path's Taylor coefficients (no factorisation in the predictor).
PREDICTORS = ("rk4", "hermite", "pade")

#: Correctors: "newton" (every corrector step factors the Jacobian at its point) or, the batched tape tracker
#: only, "chord" (the steps after the first reuse the first one's factorisation and evaluate H alone; the next
#: tangent comes from the Jacobian at the predicted point).
CORRECTORS = ("newton", "chord")


@dataclass(frozen=True)
class TrackerOptions:
    """Step control. ``target``: wanted size of the first Newton correction relative to 1 + |x| (the
    step grows or shrinks to meet it); ``accept``: largest first correction accepted; ``tol``:
    convergence of the corrector; ``newton``: corrector iterations per step; ``final_newton``: Newton
    iterations on the target system at s = 1; ``predictor`` (:data:`PREDICTORS`) and ``corrector``
    (:data:`CORRECTORS`)."""

    h0: float = 0.05
    hmin: float = 1e-9
    hmax: float = 0.5
    target: float = 1e-2
    accept: float = 0.1
    tol: float = 1e-9
    newton: int = 2
    final_newton: int = 3
    max_steps: int = 600
    big: float = 1e8
    contract: float = 0.1
    predictor: str = "rk4"
    corrector: str = "newton"

    def __post_init__(self) -> None:
        if self.predictor not in PREDICTORS:
            raise ValueError(f"unknown predictor {self.predictor!r}; valid: {', '.join(PREDICTORS)}")
        if self.corrector not in CORRECTORS:
            raise ValueError(f"unknown corrector {self.corrector!r}; valid: {', '.join(CORRECTORS)}")

    def as_array(self) -> np.ndarray:
        return np.array([self.h0, self.hmin, self.hmax, self.target, self.accept, self.tol, self.newton,
                         self.final_newton, self.max_steps, self.big, self.contract,
                         PREDICTORS.index(self.predictor)], dtype=np.float64)


#: Step control of a squared system's paths (only its start roots that satisfy the full system are
#: tracked, :func:`solvers.methods.homotopy.full_system_roots`): a path that jumps to a root of another
#: family ends on a root no other tracked path holds, which the duplicate test cannot see, so its steps
#: are smaller and a step is accepted only on a smaller first Newton correction. 5r/5s on the 17 of 1000
#: seeded networks where the default missed the true root (its path is among the tracked ones: tracked
#: back from the true root with TIGHT, it ends on a tracked start root): one plain track with the
#: default misses it on 15 of the 17, with these on 3, for 8 % more steps (tables/NOTES.md).
FAMILY = {"target": 3e-3, "accept": 3e-2, "predictor": "pade"}

#: Step control for retracking a path that stalled or jumped: smaller steps, stricter acceptance. At
#: these targets the Pade predictor of the tape tracker takes far fewer steps than RK4 (6r/3s, 5r/4s:
#: retracking most of the solve time; tables/NOTES.md); the monomial tracker runs RK4 instead.
TIGHT = TrackerOptions(h0=0.01, hmin=1e-13, target=1e-5, accept=1e-3, newton=3, contract=0.05, max_steps=4000,
                       predictor="pade")


@dataclass(frozen=True)
class SystemStructure:
    """Monomial structure of a square system.

    Distinct monomials m have the exponents ``mexp[mptr[m]:mptr[m+1]]`` of the variables
    ``mvar[mptr[m]:mptr[m+1]]`` (nonzero only); term t is monomial ``tmon[t]`` in equation ``teq[t]``.
    Monomials and their derivatives are evaluated once per point and shared by all equations.
    """

    nvars: int
    teq: np.ndarray
    tmon: np.ndarray
    mptr: np.ndarray
    mvar: np.ndarray
    mexp: np.ndarray
    maxexp: np.ndarray

    @classmethod
    def from_exponents(cls, exps: np.ndarray, eq: np.ndarray) -> "SystemStructure":
        exps = np.asarray(exps, dtype=np.int64)
        T, N = exps.shape
        mons, tmon = np.unique(exps, axis=0, return_inverse=True)
        nz = mons != 0
        mptr = np.concatenate([[0], np.cumsum(nz.sum(axis=1))]).astype(np.int64)
        mvar = np.nonzero(nz)[1].astype(np.int64)
        mexp = mons[nz].astype(np.int64)
        maxexp = exps.max(axis=0) if T else np.zeros(N, dtype=np.int64)
        return cls(N, np.asarray(eq, dtype=np.int64), tmon.ravel().astype(np.int64), mptr, mvar, mexp,
                   maxexp.astype(np.int64))

    @property
    def arrays(self) -> tuple:
        return self.teq, self.tmon, self.mptr, self.mvar, self.mexp, self.maxexp


def segment_coefficients(coefficients, q0: np.ndarray, q1: np.ndarray, degree: int) -> np.ndarray:
    """G (B, T, degree + 1): the coefficients c_t(q0 + s (q1 - q0)) as polynomials in s.

    ``coefficients`` maps parameters (K, P) to term coefficients (K, T); q0, q1 (B, P). The values at
    the degree + 1 roots of unity are interpolated by a discrete Fourier transform (unitary, so no
    error growth), exact for coefficient functions of degree <= ``degree`` in q.
    """
    q0 = np.atleast_2d(np.asarray(q0, dtype=complex))
    q1 = np.atleast_2d(np.asarray(q1, dtype=complex))
    B = max(len(q0), len(q1))
    q0, q1 = np.broadcast_to(q0, (B, q0.shape[1])), np.broadcast_to(q1, (B, q1.shape[1]))
    K = degree + 1
    w = np.exp(2j * np.pi * np.arange(K) / K)
    Q = q0[None] + w[:, None, None] * (q1 - q0)[None]  # (K, B, P)
    C = np.asarray(coefficients(Q.reshape(K * B, -1)), dtype=complex).reshape(K, B, -1)
    G = np.fft.fft(C, axis=0) / K  # sum_k C_k w^(-jk)
    return np.ascontiguousarray(np.transpose(G, (1, 2, 0)))


# --------------------------------------------------------------------------------------------------
# compiled kernels
# --------------------------------------------------------------------------------------------------


@njit(cache=True, nogil=True)
def _coefficients_at(s, G, tdeg, C, dC):
    """C[t] = c_t(s), dC[t] = c_t'(s) by Horner's rule up to each term's degree."""
    for t in range(G.shape[0]):
        D = tdeg[t]
        c = G[t, D]
        dc = 0.0 * c
        for k in range(D - 1, -1, -1):
            dc = dc * s + c
            c = c * s + G[t, k]
        C[t] = c
        dC[t] = dc


@njit(cache=True, nogil=True)
def _evaluate(x, C, dC, teq, tmon, mptr, mvar, mexp, maxexp, pw, mon, dmon, H, J, Hs):
    """H (N,), J = dH/dx (N, N), Hs = dH/ds (N,) at x with term coefficients C, dC at some s.

    pw (N, max exponent + 1), mon (M,), dmon (nnz,) are scratch."""
    N = x.shape[0]
    for v in range(N):
        pw[v, 0] = 1.0
        for k in range(1, maxexp[v] + 1):
            pw[v, k] = pw[v, k - 1] * x[v]
    for m in range(mptr.shape[0] - 1):
        a = mptr[m]
        b = mptr[m + 1]
        val = 1.0 + 0.0j
        for r in range(a, b):
            val *= pw[mvar[r], mexp[r]]
        mon[m] = val
        for r in range(a, b):
            ex = mexp[r]
            d = ex * pw[mvar[r], ex - 1]
            for u in range(a, b):
                if u != r:
                    d *= pw[mvar[u], mexp[u]]
            dmon[r] = d
    for e in range(N):
        H[e] = 0.0
        Hs[e] = 0.0
        for v in range(N):
            J[e, v] = 0.0
    for t in range(teq.shape[0]):
        m = tmon[t]
        e = teq[t]
        c = C[t]
        H[e] += c * mon[m]
        Hs[e] += dC[t] * mon[m]
        for r in range(mptr[m], mptr[m + 1]):
            J[e, mvar[r]] += c * dmon[r]


@njit(cache=True, nogil=True)
def _lu(A, piv):
    """In-place LU with partial pivoting; returns False when singular."""
    N = A.shape[0]
    for k in range(N):
        p = k
        best = abs(A[k, k])
        for i in range(k + 1, N):
            a = abs(A[i, k])
            if a > best:
                best = a
                p = i
        if best == 0.0 or not np.isfinite(best):
            return False
        piv[k] = p
        if p != k:
            for j in range(N):
                tmp = A[k, j]
                A[k, j] = A[p, j]
                A[p, j] = tmp
        inv = 1.0 / A[k, k]
        for i in range(k + 1, N):
            f = A[i, k] * inv
            A[i, k] = f
            if f != 0:
                for j in range(k + 1, N):
                    A[i, j] -= f * A[k, j]
    return True


@njit(cache=True, nogil=True)
def _lu_solve(A, piv, b):
    """Solve in place with the factors of :func:`_lu`."""
    N = A.shape[0]
    for k in range(N):
        p = piv[k]
        if p != k:
            tmp = b[k]
            b[k] = b[p]
            b[p] = tmp
    for i in range(N):
        acc = b[i]
        for j in range(i):
            acc -= A[i, j] * b[j]
        b[i] = acc
    for i in range(N - 1, -1, -1):
        acc = b[i]
        for j in range(i + 1, N):
            acc -= A[i, j] * b[j]
        b[i] = acc / A[i, i]


@njit(cache=True, nogil=True)
def _norm(v):
    acc = 0.0
    for i in range(v.shape[0]):
        acc += v[i].real * v[i].real + v[i].imag * v[i].imag
    return np.sqrt(acc)


@njit(cache=True, nogil=True)
def _eval(x, s, G, tdeg, teq, tmon, mptr, mvar, mexp, maxexp, sc, C, dC, pw, mon, dmon, H, J, Hs):
    """Evaluate at (x, s), recomputing the term coefficients only when s changed (sc[0] caches s)."""
    if s != sc[0]:
        _coefficients_at(s, G, tdeg, C, dC)
        sc[0] = s
    _evaluate(x, C, dC, teq, tmon, mptr, mvar, mexp, maxexp, pw, mon, dmon, H, J, Hs)


@njit(cache=True, nogil=True)
def _track_one(x0, G, tdeg, teq, tmon, mptr, mvar, mexp, maxexp, opts, x, stats):
    """Track one path from s = 0 to 1; x receives the endpoint. stats: [status, steps, rejected, s]."""
    h0, hmin, hmax, target, accept, tol = opts[0], opts[1], opts[2], opts[3], opts[4], opts[5]
    newton, final_newton, max_steps, big = int(opts[6]), int(opts[7]), int(opts[8]), opts[9]
    contract = opts[10]
    predictor = int(opts[11])
    N = x0.shape[0]
    T = teq.shape[0]
    sc = np.full(1, np.nan)
    C = np.empty(T, dtype=np.complex128)
    dC = np.empty(T, dtype=np.complex128)
    pw = np.empty((N, maxexp.max() + 1), dtype=np.complex128)
    mon = np.empty(mptr.shape[0] - 1, dtype=np.complex128)
    dmon = np.empty(max(mvar.shape[0], 1), dtype=np.complex128)
    H = np.empty(N, dtype=np.complex128)
    Hs = np.empty(N, dtype=np.complex128)
    J = np.empty((N, N), dtype=np.complex128)
    piv = np.empty(N, dtype=np.int64)
    k1 = np.empty(N, dtype=np.complex128)
    k2 = np.empty(N, dtype=np.complex128)
    k3 = np.empty(N, dtype=np.complex128)
    k4 = np.empty(N, dtype=np.complex128)
    xt = np.empty(N, dtype=np.complex128)
    xp = np.empty(N, dtype=np.complex128)
    dx = np.empty(N, dtype=np.complex128)
    xq = np.empty(N, dtype=np.complex128)
    kq = np.empty(N, dtype=np.complex128)
    hq = 1.0
    have_prev = False
    for i in range(N):
        x[i] = x0[i]
    s = 0.0
    h = h0
    steps = 0
    rejected = 0
    status = 1
    _eval(x, s, G, tdeg, teq, tmon, mptr, mvar, mexp, maxexp, sc, C, dC, pw, mon, dmon, H, J, Hs)
    have_tangent = _lu(J, piv)
    if have_tangent:
        for i in range(N):
            k1[i] = -Hs[i]
        _lu_solve(J, piv, k1)
    scale = 1.0
    while steps + rejected < max_steps:
        if not have_tangent:
            status = 1
            break
        if h > 1.0 - s:
            h = 1.0 - s
        ok = True
        hermite = predictor == 1 and have_prev
        if hermite:
            # cubic Hermite extrapolation through the last two points and tangents: no linear solve
            tau = 1.0 + h / hq
            t2 = tau * tau
            t3 = t2 * tau
            a0 = 2.0 * t3 - 3.0 * t2 + 1.0
            b0 = (t3 - 2.0 * t2 + tau) * hq
            a1 = -2.0 * t3 + 3.0 * t2
            b1 = (t3 - t2) * hq
            for i in range(N):
                xp[i] = a0 * xq[i] + b0 * kq[i] + a1 * x[i] + b1 * k1[i]
        # RK4 predictor: three more tangents (the first is carried over from the last step)
        for stage in range(0 if hermite else 3):
            if stage == 0:
                c = 0.5 * h
                for i in range(N):
                    xt[i] = x[i] + c * k1[i]
            elif stage == 1:
                for i in range(N):
                    xt[i] = x[i] + c * k2[i]
            else:
                c = h
                for i in range(N):
                    xt[i] = x[i] + c * k3[i]
            _eval(xt, s + c, G, tdeg, teq, tmon, mptr, mvar, mexp, maxexp, sc, C, dC, pw, mon, dmon, H, J, Hs)
            if not _lu(J, piv):
                ok = False
                break
            kk = k2 if stage == 0 else (k3 if stage == 1 else k4)
            for i in range(N):
                kk[i] = -Hs[i]
            _lu_solve(J, piv, kk)
        s1 = s + h
        if 1.0 - s1 < 1e-14:
            s1 = 1.0
        e0 = np.inf
        e = np.inf
        if ok:
            if not hermite:
                for i in range(N):
                    xp[i] = x[i] + (h / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            scale = 1.0 + _norm(xp)
            # Newton corrector; the last factorisation also gives the tangent at the new point
            for it in range(newton):
                _eval(xp, s1, G, tdeg, teq, tmon, mptr, mvar, mexp, maxexp, sc, C, dC, pw, mon, dmon, H, J, Hs)
                if not _lu(J, piv):
                    e = np.inf
                    break
                for i in range(N):
                    dx[i] = H[i]
                _lu_solve(J, piv, dx)
                for i in range(N):
                    xp[i] -= dx[i]
                e = _norm(dx) / scale
                if it == 0:
                    e0 = e
                    if not (e0 < accept):
                        break
                if e < tol or (it > 0 and e < contract * e0 and e < 1e-5):
                    break
        if ok and np.isfinite(e) and e0 < accept and (e < tol or e < contract * e0):
            for i in range(N):
                xq[i] = x[i]
                kq[i] = k1[i]
            hq = s1 - s
            have_prev = True
            for i in range(N):
                x[i] = xp[i]
                k1[i] = -Hs[i]
            _lu_solve(J, piv, k1)
            s = s1
            steps += 1
            if s >= 1.0:
                status = 0
                break
            if scale > big:
                status = 2
                break
            # local error ~ h^5: aim the next first correction at `target`
            f = 2.0
            if e0 > 0:
                f = 0.8 * (target / e0) ** (0.25 if hermite else 0.2)
            if f > 2.0:
                f = 2.0
            if f < 0.5:
                f = 0.5
            h = min(h * f, hmax)
        else:
            rejected += 1
            h *= 0.5
            if h < hmin:
                status = 1
                if scale > big:
                    status = 2
                break
    if status == 0:
        for it in range(final_newton):
            _eval(x, 1.0, G, tdeg, teq, tmon, mptr, mvar, mexp, maxexp, sc, C, dC, pw, mon, dmon, H, J, Hs)
            if not _lu(J, piv):
                break
            for i in range(N):
                dx[i] = H[i]
            _lu_solve(J, piv, dx)
            for i in range(N):
                x[i] -= dx[i]
            if _norm(dx) < 1e-15 * (1.0 + _norm(x)):
                break
    stats[0] = status
    stats[1] = steps
    stats[2] = rejected
    stats[3] = s


@njit(cache=True, nogil=True)
def _track_many(x0, G, inst, tdeg, teq, tmon, mptr, mvar, mexp, maxexp, opts, x, stats):
    for p in range(x0.shape[0]):
        _track_one(x0[p], G[inst[p]], tdeg, teq, tmon, mptr, mvar, mexp, maxexp, opts, x[p], stats[p])


@njit(cache=True, nogil=True)
def _evaluate_many(x, s, G, inst, tdeg, teq, tmon, mptr, mvar, mexp, maxexp, H, J, Hs):
    N = x.shape[1]
    T = teq.shape[0]
    C = np.empty(T, dtype=np.complex128)
    dC = np.empty(T, dtype=np.complex128)
    pw = np.empty((N, maxexp.max() + 1), dtype=np.complex128)
    mon = np.empty(mptr.shape[0] - 1, dtype=np.complex128)
    dmon = np.empty(max(mvar.shape[0], 1), dtype=np.complex128)
    for p in range(x.shape[0]):
        _coefficients_at(s[p], G[inst[p]], tdeg, C, dC)
        _evaluate(x[p], C, dC, teq, tmon, mptr, mvar, mexp, maxexp, pw, mon, dmon, H[p], J[p], Hs[p])


# --------------------------------------------------------------------------------------------------
# Python entry points
# --------------------------------------------------------------------------------------------------


def _degrees(G: np.ndarray) -> np.ndarray:
    """Per term, the highest power of s with a nonzero coefficient in any instance (Horner's length)."""
    nz = np.any(np.abs(G) > 0, axis=0)  # (T, D + 1)
    D = G.shape[2] - 1
    return np.where(nz.any(axis=1), D - np.argmax(nz[:, ::-1], axis=1), 0).astype(np.int64)


def track(structure: SystemStructure, G: np.ndarray, x0: np.ndarray, inst: np.ndarray | None = None,
          options: TrackerOptions = TrackerOptions()) -> tuple[np.ndarray, np.ndarray]:
    """Track paths x0 (P, N) along the segments G (B, T, D + 1); path p uses instance ``inst[p]``.

    Returns endpoints (P, N) (NaN unless the path reached s = 1) and stats (P, 4): status (0 reached
    s = 1, 1 stalled, 2 diverged), accepted steps, rejected steps, last s.
    """
    if options.predictor == "pade":
        raise ValueError("the monomial tracker predicts by rk4 or hermite; pade is the tape tracker's")
    if options.corrector != "newton":
        raise ValueError(f"the monomial tracker corrects by newton; {options.corrector} is the tape tracker's")
    x0 = np.ascontiguousarray(x0, dtype=np.complex128)
    P, N = x0.shape
    if N != structure.nvars:
        raise ValueError(f"start points have {N} coordinates, the system {structure.nvars} unknowns")
    G = np.ascontiguousarray(G, dtype=np.complex128)
    inst = np.zeros(P, dtype=np.int64) if inst is None else np.ascontiguousarray(inst, dtype=np.int64)
    x = np.empty_like(x0)
    stats = np.zeros((P, 4))
    _track_many(x0, G, inst, _degrees(G), *structure.arrays, options.as_array(), x, stats)
    x[stats[:, 0] != 0] = np.nan
    return x, stats


def evaluate(structure: SystemStructure, G: np.ndarray, x: np.ndarray, s: np.ndarray,
             inst: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H (P, N), dH/dx (P, N, N), dH/ds (P, N) at points x (P, N) and path parameters s (P,)."""
    x = np.ascontiguousarray(x, dtype=np.complex128)
    G = np.ascontiguousarray(G, dtype=np.complex128)
    P, N = x.shape
    inst = np.zeros(P, dtype=np.int64) if inst is None else np.ascontiguousarray(inst, dtype=np.int64)
    H = np.empty((P, N), dtype=np.complex128)
    J = np.empty((P, N, N), dtype=np.complex128)
    Hs = np.empty((P, N), dtype=np.complex128)
    _evaluate_many(x, np.ascontiguousarray(np.broadcast_to(s, (P,)), dtype=np.float64),
                   G, inst, _degrees(G), *structure.arrays, H, J, Hs)
    return H, J, Hs


def warm_up() -> float:
    """Compile (or load from the on-disk cache) every kernel; returns the seconds it took."""
    t0 = time.perf_counter()
    st = SystemStructure.from_exponents(np.array([[2, 0], [0, 0], [1, 1], [0, 0]]), np.array([0, 0, 1, 1]))
    G = np.zeros((1, 4, 2), dtype=complex)
    G[0, :, 0] = [1, -1, 1, -1]
    G[0, :, 1] = [0, -1, 0, -1]  # x^2 = 1 + s, x y = 1 + s
    x0 = np.array([[1.0, 1.0]], dtype=complex)
    track(st, G, x0)
    evaluate(st, G, x0, np.zeros(1))
    return time.perf_counter() - t0
