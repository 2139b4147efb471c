"""Where the homotopy solvers' time per path stands against its floors (issue 20): kernel anchors, the
lock step's tail, step controls.

Per solver (a committed homotopy solver with a straight-line program; default 9r3s and 5r5s):

1. **Evaluation anchor.** The tracker's numba tape interpreter (the full tape: H, J, dH/ds) at P = K, 16,
   4, 1 live paths per call, against the same tape written out as straight-line C code by
   :mod:`solvers.continuation.tape_native` (registers as local variables: one path per pass, and four paths per
   pass in vector registers, the solvers' choice), compiled by the system's C compiler (its compile
   seconds reported; skipped without a compiler).
2. **LU anchor.** LU with partial pivoting and two solves of the N x N Jacobians: the tracker's batched
   kernel (paths in the inner loop), the solver's compiled LU (four paths per pass, what the tracker runs
   where it is built) and a plain per-path C routine.
3. **The lock step's tail.** One plain track of each seeded network against the same track of K copies
   of that network's median path (every column then takes the same number of attempts: the cost of an
   attempt in a full batch), which gives the track's time without any tail; both against numpy's eig
   of size K, timed in this process; with the interpreter and with the compiled tapes.
4. **Step controls** (``--step-control NETWORKS``; slow: a per-path Python prototype). Attempts per path
   of the Pade (2, 1) predictor from Taylor coefficients (exact, by sampling the residual tape on a
   circle and an FFT, or by the tracker's central differences) with the tracker's step rule and with a
   rule after Timme (2021): step from the Newton contraction (omega) and the predictor's local error,
   capped by the Pade pole radius (trust region).

Prints; writes nothing. Timings are minima over repeated runs; compare ratios within one run.

Usage: OPENBLAS_NUM_THREADS=1 python scripts/bench_tracker_floor.py [--solvers 9r3s 5r5s] [--networks 10]
       [--step-control 2]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ["TDOA_WORKBENCH_THREADS"] = "1"  # the trackers on one core, as the eigensolves they are compared with

import argparse  # noqa: E402
import ctypes  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from solvers.continuation import tape_kernel, tape_native  # noqa: E402
from solvers.synthetic import random_network  # noqa: E402

from bench_tape import best  # noqa: E402  (scripts/ is on the path of a script)
from bench_tape_tracker import _kernel_costs, _lu_loop, _module, _solver  # noqa: E402


# --------------------------------------------------------------------------------------------------
# 1, 2: straight-line C code of a tape, a per-path LU in C
# --------------------------------------------------------------------------------------------------

REPEAT = """
void run_reps(long reps, long P, long C, const double *R, const double *I, double *OR, double *OI) {
  for (long r = 0; r < reps; r++) run(P, C, R, I, OR, OI);
}
"""

LU_C = r"""
#include <complex.h>
static void lu(int N, double complex *A, int *piv) {
  for (int k = 0; k < N; k++) {
    int q = k; double best = creal(A[k*N+k])*creal(A[k*N+k]) + cimag(A[k*N+k])*cimag(A[k*N+k]);
    for (int i = k+1; i < N; i++) { double a = creal(A[i*N+k])*creal(A[i*N+k]) + cimag(A[i*N+k])*cimag(A[i*N+k]);
      if (a > best) { best = a; q = i; } }
    piv[k] = q;
    if (q != k) for (int j = 0; j < N; j++) { double complex t = A[k*N+j]; A[k*N+j] = A[q*N+j]; A[q*N+j] = t; }
    double complex r = 1.0 / A[k*N+k]; A[k*N+k] = r;
    for (int i = k+1; i < N; i++) { double complex l = A[i*N+k] * r; A[i*N+k] = l;
      for (int j = k+1; j < N; j++) A[i*N+j] -= l * A[k*N+j]; }
  }
}
static void solve(int N, const double complex *A, const int *piv, double complex *b) {
  for (int k = 0; k < N; k++) { int q = piv[k]; if (q != k) { double complex t = b[k]; b[k] = b[q]; b[q] = t; }
    for (int i = k+1; i < N; i++) b[i] -= A[i*N+k] * b[k]; }
  for (int i = N-1; i >= 0; i--) { for (int j = i+1; j < N; j++) b[i] -= A[i*N+j] * b[j]; b[i] *= A[i*N+i]; }
}
void lu_reps(int reps, int P, int N, int factor, const double complex *A0, double complex *A,
             const double complex *b0, double complex *b, int *piv) {
  for (int r = 0; r < reps; r++) for (int p = 0; p < P; p++) {
    for (int i = 0; i < N*N; i++) A[p*N*N+i] = A0[p*N*N+i];
    if (factor) lu(N, A + p*N*N, piv + p*N);
    for (int t = 0; t < 2; t++) { for (int i = 0; i < N; i++) b[p*N+i] = b0[p*N+i];
      if (factor) solve(N, A + p*N*N, piv + p*N, b + p*N); }
  }
}
"""


def _compile(source: str, folder: str, stem: str, flags: tuple[str, ...]) -> tuple[ctypes.CDLL, float]:
    c_file, so_file = os.path.join(folder, stem + ".c"), os.path.join(folder, stem + ".so")
    with open(c_file, "w", encoding="utf-8") as fh:
        fh.write(source)
    t0 = time.perf_counter()
    subprocess.run([os.environ.get("CC") or "cc", *flags, "-o", so_file, c_file], check=True)
    return ctypes.CDLL(so_file), time.perf_counter() - t0


def _ptr(a: np.ndarray):
    return a.ctypes.data_as(ctypes.c_void_p)


def kernel_anchors(S, folder: str, flags: tuple[str, ...]) -> None:
    native = tape_native.addresses(S.tapes, wait=True)
    tape, K, N = S.tapes.full, S.n_paths, S.nvars
    cap = 4 * ((K + 3) // 4)
    rng = np.random.default_rng(0)
    Rr, Ri, Or, Oi = tape_kernel.workspace(tape, cap)
    Rr[: tape.n_inputs] = rng.normal(size=(tape.n_inputs, cap))
    Ri[: tape.n_inputs] = rng.normal(size=(tape.n_inputs, cap))
    tape_kernel.run_tape(tape.code, tape.imm, Rr, Ri, Or, Oi, cap)
    reference = Or.copy() + 1j * Oi
    libs = {}
    for width in (1, 4):
        lib, seconds = _compile(tape_native.source(tape, "run", width) + REPEAT, folder, f"tape{width}", flags)
        libs[width] = lib.run_reps
        Or[:], Oi[:] = 0.0, 0.0
        libs[width](1, cap, cap, _ptr(Rr), _ptr(Ri), _ptr(Or), _ptr(Oi))
        agree = np.max(np.abs(Or + 1j * Oi - reference)) / np.max(np.abs(reference))
        print(f"  straight-line C, {width} path(s) per pass: {tape.n_instructions} instructions, compiled in "
              f"{seconds:.1f} s, max relative difference to the interpreter {agree:.1e}")
    print("  evaluation, us per path (full tape):")
    for P in (cap, 16, 4, 1):
        reps = max(1, 20000 // P)
        t_numba = best(lambda: [tape_kernel.run_tape(tape.code, tape.imm, Rr, Ri, Or, Oi, P) for _ in range(reps)])
        t_c1 = best(lambda: libs[1](reps, P, cap, _ptr(Rr), _ptr(Ri), _ptr(Or), _ptr(Oi)))
        t_c4 = best(lambda: libs[4](reps, P, cap, _ptr(Rr), _ptr(Ri), _ptr(Or), _ptr(Oi)))  # P = 1 pays for 4
        print(f"    P = {P:3d}: interpreter {1e6 * t_numba / (reps * P):.3f}, C scalar {1e6 * t_c1 / (reps * P):.3f}, "
              f"C 4-wide {1e6 * t_c4 / (reps * P):.3f}")
    lib, _ = _compile(LU_C, folder, "lu", flags)
    print(f"  LU + 2 solves of the {N} x {N} Jacobians, us per path:")
    for P in (K, 16, 4, 1):
        reps = max(1, 20000 // P)
        A0 = rng.normal(size=(P, N, N)) + 1j * rng.normal(size=(P, N, N))
        b0 = rng.normal(size=(P, N)) + 1j * rng.normal(size=(P, N))
        A, b, piv = np.empty_like(A0), np.empty_like(b0), np.zeros((P, N), np.int32)
        c_args = (_ptr(A0), _ptr(A), _ptr(b0), _ptr(b), _ptr(piv))
        t_c = (best(lambda: lib.lu_reps(reps, P, N, 1, *c_args)) - best(lambda: lib.lu_reps(reps, P, N, 0, *c_args)))
        cap = tape_kernel.capacity(P)  # as the tracker lays out its columns
        J0r, J0i = np.zeros((N + N * N, cap)), np.zeros((N + N * N, cap))
        J0r[N:, :P], J0i[N:, :P] = A0.reshape(P, -1).T.real, A0.reshape(P, -1).T.imag
        b0r, b0i = np.zeros((N, cap)), np.zeros((N, cap))
        b0r[:, :P], b0i[:, :P] = b0.T.real, b0.T.imag
        times = []
        for lin in (np.zeros(2, dtype=np.int64), native[3:5]):  # the batched kernel, the solver's compiled LU
            args = (lin, J0r, J0i, J0r.copy(), J0i.copy(), N, np.zeros((N, cap), np.int64), np.zeros(cap, np.bool_),
                    b0r, b0i, b0r.copy(), b0i.copy(), P)
            _lu_loop(*args, 1, True)
            _lu_loop(*args, 1, False)
            times.append(best(lambda: _lu_loop(*args, reps, True)) - best(lambda: _lu_loop(*args, reps, False)))
        print(f"    P = {P:3d}: batched kernel {1e6 * times[0] / (reps * P):.3f}, compiled (4 per pass) "
              f"{1e6 * times[1] / (reps * P):.3f}, C per path {1e6 * t_c / (reps * P):.3f}")


# --------------------------------------------------------------------------------------------------
# 3: the lock step's tail
# --------------------------------------------------------------------------------------------------

def tail(S, module, networks: int, native) -> None:
    m, n = module.CONFIG
    K = S.n_paths
    rng = np.random.default_rng(0)
    nets = [random_network(m, n, rng) for _ in range(networks)]
    A = rng.normal(size=(K, K)) + 1j * rng.normal(size=(K, K))
    rows, acc = [], []
    for net in nets:
        f = net.measurements()
        q = f.reshape(1, -1).astype(complex) / np.sqrt(np.mean(np.abs(f) ** 2))
        out = {}
        t1 = best(lambda: out.update(a=tape_kernel.track(S.tapes, S.q0[None], q, S.x0, None, S.options, native=native)[1]))
        attempts = out["a"][:, 1] + out["a"][:, 2]
        acc.append(float(np.mean(out["a"][:, 1])))
        median = np.argsort(attempts)[K // 2]
        copies = np.repeat(S.x0[median:median + 1], K, axis=0)
        t2 = best(lambda: out.update(b=tape_kernel.track(S.tapes, S.q0[None], q, copies, None, S.options, native=native)[1]))
        a2 = np.mean(out["b"][:, 1] + out["b"][:, 2])
        rows.append((t1, attempts.mean(), attempts.max(), t2 / (K * a2), best(lambda: np.linalg.eig(A))))
    t1, a1, amax, per_attempt, t_eig = np.median(np.array(rows), axis=0)
    free = per_attempt * K * a1
    how = "compiled tapes" if np.any(native) else "interpreter"
    print(f"  {how}: plain track {1e3 * t1:.2f} ms = {1e6 * t1 / K:.0f} us per path ({t1 / t_eig:.2f}x eig{K} = "
          f"{1e3 * t_eig:.2f} ms); attempts per path {a1:.1f} (max {amax:.0f}, the rounds of the lock step)")
    print(f"  an attempt in a full batch {1e6 * per_attempt:.2f} us -> the same track without a tail "
          f"{1e3 * free:.2f} ms = {1e6 * free / K:.0f} us per path ({free / t_eig:.2f}x eig{K})")
    if np.any(native):  # where the compiled track's time goes (the count of kernel runs as bench_tape_tracker's)
        t_full, t_newton, t_res, t_lu = _kernel_costs(S, K, np.random.default_rng(1), native)
        o = S.options
        pade = o.predictor == "pade"
        accepted = float(np.median(acc))
        n_full = (1 if pade else 4) * a1 + 1
        n_newton = (o.newton - 1) * a1 + o.final_newton
        n_res = 4 * (accepted + 1) if pade else 0.0
        ev = n_full * t_full + n_newton * t_newton + n_res * t_res
        lu = (n_full + n_newton) * t_lu
        print(f"  per path: evaluation {1e6 * ev:.0f} us + LU and solves {1e6 * lu:.0f} us + bookkeeping and tail "
              f"{1e6 * (t1 / K - ev - lu):.0f} us ({n_full + n_newton + n_res:.0f} evaluations, {n_full + n_newton:.0f} "
              f"factorisations; full tape {1e6 * t_full:.3f} us, LU with two solves {1e6 * t_lu:.3f} us per path)")


# --------------------------------------------------------------------------------------------------
# 4: step controls (a per-path prototype in Python: attempts, not times)
# --------------------------------------------------------------------------------------------------

def _inputs(S, X, s, q0, dq):
    P = X.shape[1]
    return np.concatenate([X, np.broadcast_to(s, (1, P)), np.tile(q0[:, None], (1, P)), np.tile(dq[:, None], (1, P))])


def _full(S, x, s, q0, dq):
    N = S.nvars
    O = tape_kernel.run(S.tapes.full, _inputs(S, x[:, None], np.array([s]), q0, dq))[:, 0]
    return O[:N], O[N:N + N * N].reshape(N, N), O[N + N * N:N + N * N + N]


def _taylor(S, x, s, J, Hs, q0, dq, h, how):
    """x, x1..x4 of the path at s: x_k = -J^-1 c_k, c_k the t^k coefficient of H along the lower orders."""
    N = S.nvars
    res = lambda Y, t: tape_kernel.run(S.tapes.residual, _inputs(S, Y, s + t, q0, dq))[:N]  # noqa: E731
    X = [x, -np.linalg.solve(J, Hs)]
    if how == "differences":  # the tracker's: H at t = 0 (the full tape's), +-d on the line (c2); +-d3 on the curve (c3)
        d = min(tape_kernel.TAYLOR_DELTA, 0.1 * h)
        H = res(np.stack([x, x + d * X[1], x - d * X[1]], 1), np.array([0.0, d, -d]))
        X.append(-np.linalg.solve(J, (H[:, 1] + H[:, 2] - 2 * H[:, 0]) / (2 * d * d)))
        d = min(tape_kernel.TAYLOR_DELTA3, 0.1 * h)
        t = np.array([d, -d])
        H = res(x[:, None] + t * X[1][:, None] + t ** 2 * X[2][:, None], t)
        X.append(-np.linalg.solve(J, (H[:, 0] - H[:, 1]) / (2 * d ** 3)))
        X.append(np.zeros(N, complex))  # x4 unknown: no local error estimate
        return X
    L, r = 16, max(min(0.25 * h, 0.05), 1e-6)  # exact up to aliasing r^16: samples on a circle, FFT
    t = r * np.exp(2j * np.pi * np.arange(L) / L)
    for k in (2, 3, 4):
        Y = sum(X[j][:, None] * t[None, :] ** j for j in range(k))
        X.append(-np.linalg.solve(J, (np.fft.fft(res(Y, t), axis=1) / L)[:, k] / r ** k))
    return X


def _pade(X, h):
    """The (2, 1) Pade prediction at s + h, its local error coefficient and the nearest pole's radius."""
    x, x1, x2, x3, x4 = X
    out, err, tau = x + h * (x1 + h * (x2 + h * x3)), np.abs(x4), np.inf
    for i in np.flatnonzero((np.abs(x2) > 0) & (np.abs(x3) * h >= 1e-2 * np.abs(x2))):
        b = -x3[i] / x2[i]
        out[i] = (x[i] + (x1[i] + b * x[i]) * h + (x2[i] + b * x1[i]) * h * h) / (1 + b * h)
        tau, err[i] = min(tau, abs(x2[i] / x3[i])), abs(x4[i] + b * x3[i])
    return out, float(np.max(err)), tau


def _h(a):
    return 2 * a * (np.sqrt(4 * a * a + 1) - 2 * a)


def _track_prototype(S, x, q0, dq, rule, how, a=0.125, beta_tau=0.4, max_attempts=2000):
    """One path, two Newton steps per attempt and the tracker's acceptance test; returns (reached, attempts)."""
    o = S.options
    s, h, steps, rejected, last_failed = 0.0, o.h0, 0, 0, False
    _, J, Hs = _full(S, x, s, q0, dq)
    X = _taylor(S, x, s, J, Hs, q0, dq, h, how)
    while s < 1 and steps + rejected < max_attempts:
        h = min(h, 1 - s)
        xp, err, tau = _pade(X, h)
        scale, s1 = 1 + np.linalg.norm(xp), (s + h if 1 - (s + h) > 1e-14 else 1.0)
        H1, J1, _ = _full(S, xp, s1, q0, dq)
        d0 = np.linalg.solve(J1, H1)
        e0, e1, xq = np.linalg.norm(d0) / scale, np.inf, xp - d0
        if e0 < o.accept:
            H2, J2, Hs2 = _full(S, xq, s1, q0, dq)
            d1 = np.linalg.solve(J2, H2)
            e1, xq = np.linalg.norm(d1) / scale, xq - d1
        if e0 < o.accept and (e1 < o.tol or e1 < o.contract * e0):
            steps, s, x = steps + 1, s1, xq
            if s >= 1:
                break
            if rule == "tracker":
                h_next = min(h * min(max(0.8 * (o.target / e0) ** 0.25, 0.5), 2.0) if e0 > 0 else 2 * h, o.hmax)
            else:  # Timme: omega from the two Newton steps, error e h^4 within Kantorovich's bound; pole cap
                omega = max(2 * e1 / max(e0, 1e-300) ** 2, 1e-8)
                bound = (np.sqrt(1 + 2 * _h(a)) - 1) / (omega * max(err / scale, 1e-300))
                h_next = min(bound ** 0.25, beta_tau * tau, 4 * h, o.hmax)
                if last_failed:
                    h_next = min(h_next, h)
            last_failed = False
            X, h = _taylor(S, x, s, J2, Hs2, q0, dq, h_next, how), h_next
        else:
            rejected, last_failed = rejected + 1, True
            theta = e1 / e0 if e0 < o.accept and np.isfinite(e1) else 1.0
            if rule == "tracker" or theta >= 1:
                h *= 0.5
            else:
                h *= min(max((0.5 * (np.sqrt(1 + 2 * _h(a)) - 1) / max(_h(theta), 1e-12)) ** 0.25, 0.2), 0.9)
            if h < o.hmin:
                break
    return s >= 1, steps + rejected


def step_controls(S, module, networks: int) -> None:
    m, n = module.CONFIG
    rng = np.random.default_rng(0)
    nets = [random_network(m, n, rng) for _ in range(networks)]
    variants = [("tracker", "differences", {}), ("tracker", "exact", {}), ("timme", "exact", {}),
                ("timme", "exact", {"a": 0.3, "beta_tau": 0.8}), ("timme", "exact", {"a": 0.3, "beta_tau": 2.0})]
    for rule, how, kw in variants:
        attempts, lost = [], 0
        for net in nets:
            f = net.measurements()
            dq = f.reshape(-1).astype(complex) / np.sqrt(np.mean(np.abs(f) ** 2)) - S.q0
            for x0 in S.x0:
                reached, k = _track_prototype(S, x0.astype(complex), S.q0, dq, rule, how, **kw)
                attempts.append(k)
                lost += not reached
        print(f"  Pade (2, 1), Taylor coefficients {how:11s}, {rule} step rule {kw or ''}: "
              f"{np.mean(attempts):.1f} attempts per path, {lost} paths short of s = 1")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--solvers", nargs="+", default=["9r3s", "5r5s"])
    ap.add_argument("--networks", type=int, default=10, help="seeded networks for the tail")
    ap.add_argument("--step-control", type=int, default=0, metavar="NETWORKS",
                    help="also count the prototype step controls' attempts on this many networks (slow)")
    ap.add_argument("--flags", default=" ".join(tape_native.FLAGS), help="C compiler flags of the anchors")
    args = ap.parse_args(argv)
    compiler = os.environ.get("CC") or shutil.which("cc")
    for label in args.solvers:
        module = _module(label)
        S = _solver(module, "tape")
        print(f"{label}: {S.n_paths} paths, {S.nvars} unknowns, full tape {S.tapes.full.n_instructions} instructions")
        if compiler and tape_native.addresses(S.tapes, wait=True).any():
            with tempfile.TemporaryDirectory() as folder:
                kernel_anchors(S, folder, tuple(args.flags.split()))
        else:
            print("  no C compiler (cc or $CC) or TDOA_WORKBENCH_NATIVE=off: kernel anchors skipped")
        tail(S, module, args.networks, None)
        native = tape_native.addresses(S.tapes, wait=True)
        if native.any():
            tail(S, module, args.networks, native)
        if args.step_control:
            step_controls(S, module, args.step_control)


if __name__ == "__main__":
    main()
