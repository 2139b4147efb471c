"""Benchmark the instruction-tape evaluator against the tracker's monomial kernel (issue 20, item 1).

Per system: instructions and registers of the H+J+dH/ds tape (and of the H+J and H tapes), microseconds per path
per evaluation of the tape at P paths per call, of the tracker's kernel (``tracker._eval``: term
coefficients by Horner in s, then monomials; once with s changing at every call, once with s fixed,
its cached case), and numpy's complex eig of the root count's size, all timed in this process (best
of ``--repeat`` rounds). Writes nothing; prints a table and ratios.

Usage: OPENBLAS_NUM_THREADS=1 python scripts/bench_tape.py [--systems 9r3s 6r3s] [--paths 75]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ["TDOA_WORKBENCH_THREADS"] = "1"  # the trackers on one core, as the eigensolves they are compared with

import argparse  # noqa: E402
import functools  # noqa: E402
import importlib  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

from solvers.continuation import slp, tape_jit, tape_kernel, tape_native, tracker  # noqa: E402


@njit(cache=False)  # calls kernels of another file: a disk cache would go stale with them
def _old_kernel_loop(x, s, G, inst, tdeg, teq, tmon, mptr, mvar, mexp, maxexp, H, J, Hs, reps):
    """Evaluate H, J, dH/ds at every path reps times with the tracker's kernel."""
    for r in range(reps):
        tracker._evaluate_many(x, s, G, inst, tdeg, teq, tmon, mptr, mvar, mexp, maxexp, H, J, Hs)


@njit(cache=False)  # calls kernels of another file: a disk cache would go stale with them
def _tape_loop(code, imm, Rr, Ri, Or, Oi, P, reps):
    for r in range(reps):
        tape_kernel.run_tape(code, imm, Rr, Ri, Or, Oi, P)


@njit(cache=False)
def _native_loop(fn, Rr, Ri, Or, Oi, P, reps):
    """reps runs of a tape's compiled code (solvers.continuation.tape_native) at address fn, as the tracker calls it."""
    for r in range(reps):
        tape_jit._call_native(fn, P, Rr.shape[1], Rr.ctypes.data, Ri.ctypes.data, Or.ctypes.data, Oi.ctypes.data)


def best(f, repeat: int = 5) -> float:
    out = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        f()
        out = min(out, time.perf_counter() - t0)
    return out


def rates(S, P: int, rng: np.random.Generator, repeat: int = 7) -> dict[str, float]:
    """Seconds per path per evaluation at P paths per call of the homotopy solver S's system: its tapes
    ("full", "newton", "residual"; absent for a solver without a program), the full tape's compiled code
    ("full_native", where tape_native builds it here: what the tracker runs) and the tracker's kernel with
    s changing at every call ("changing") and fixed ("fixed"); "eig": seconds of numpy's eig of the
    root count's size. Interleaved rounds (this machine's load drifts), minimum over ``repeat``."""
    x = np.resize(S.x0, (P, S.nvars)) + 0.01 * (rng.normal(size=(P, S.nvars)) + 1j * rng.normal(size=(P, S.nvars)))
    q1 = rng.normal(size=len(S.q0)) + 0j
    s = rng.uniform(size=P)
    N = S.nvars
    G = S.segment(S.q0[None], q1[None])
    G_fixed = np.ascontiguousarray(G[:, :, :1])  # constant coefficients: no Horner
    G_fixed[0, :, 0] = np.sum(G[0], axis=1)  # c_t(1), any fixed s will do
    inst = np.zeros(P, dtype=np.int64)
    out = (np.empty((P, N), complex), np.empty((P, N, N), complex), np.empty((P, N), complex))
    reps = max(1, 20000 // P)
    runs = {}  # name -> (function of a repetition count, evaluations per repetition)
    for key, g in (("changing", G), ("fixed", G_fixed)):
        tdeg = tracker._degrees(g)
        _old_kernel_loop(x, s, g, inst, tdeg, *S.structure.arrays, *out, 1)
        runs[key] = (functools.partial(_old_kernel_loop, x, s, g, inst, tdeg, *S.structure.arrays, *out), P)
    inputs = np.concatenate([x.T, s[None, :], np.tile(S.q0[:, None], (1, P)), np.tile((q1 - S.q0)[:, None], (1, P))])
    tapes = getattr(S, "tapes", None)
    for kind in ("full", "newton", "residual") if tapes is not None else ():
        tape = getattr(tapes, kind)
        Rr, Ri, Or, Oi = tape_kernel.workspace(tape, P)
        Rr[: tape.n_inputs] = inputs.real
        Ri[: tape.n_inputs] = inputs.imag
        _tape_loop(tape.code, tape.imm, Rr, Ri, Or, Oi, P, 1)
        runs[kind] = (functools.partial(_tape_loop, tape.code, tape.imm, Rr, Ri, Or, Oi, P), P)
    native = tape_native.addresses(tapes, wait=True) if tapes is not None else np.zeros(1)
    if native[0]:
        cap = tape_kernel.capacity(P)  # as the tracker lays out its columns
        Rr, Ri, Or, Oi = tape_kernel.workspace(tapes.full, cap)
        Rr[: tapes.full.n_inputs, :P] = inputs.real
        Ri[: tapes.full.n_inputs, :P] = inputs.imag
        _native_loop(native[0], Rr, Ri, Or, Oi, P, 1)
        runs["full_native"] = (functools.partial(_native_loop, native[0], Rr, Ri, Or, Oi, P), P)
    A = rng.normal(size=(S.n_paths, S.n_paths)) + 1j * rng.normal(size=(S.n_paths, S.n_paths))
    runs["eig"] = (lambda k: [np.linalg.eig(A) for _ in range(k)], 1)
    row = {key: np.inf for key in runs}
    for _ in range(repeat):
        for key, (f, per) in runs.items():
            k = 1 if key == "eig" else reps
            row[key] = min(row[key], best(lambda: f(k), 1) / (k * per))
    return row


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--systems", nargs="+", default=["9r3s", "6r3s"], help="configuration labels of committed homotopy solvers")
    ap.add_argument("--paths", type=int, default=0, help="paths per call (default: the root count)")
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    for label in args.systems:
        name = [m for m in os.listdir(os.path.join(os.path.dirname(tracker.__file__), "..", "generated"))
                if m.startswith(f"tdoa_{label}_homotopy") and m.endswith(".py")][0][:-3]
        module = importlib.import_module(f"solvers.generated.{name}")
        t0 = time.perf_counter()
        tapes = slp.system_homotopy_tapes(module.SYSTEM)
        build = time.perf_counter() - t0
        S = module.solver()
        P = args.paths or S.n_paths
        row = rates(S, P, rng, args.repeat)
        t_old, t_old_fixed, t_eig = row["changing"], row["fixed"], row["eig"]
        hj = tapes.full
        print(f"{label}: tape H+J+Hs {hj.n_instructions} instructions, {hj.n_registers} registers "
              f"(H+J {tapes.newton.n_instructions}, H {tapes.residual.n_instructions}); built in {build:.2f} s; {P} paths per call")
        print(f"  tape H+J+Hs {1e6 * row['full']:.3f} us/path/eval ({1e9 * row['full'] * P / hj.n_instructions:.2f} ns per "
              f"instruction per call), {1 / row['full'] / 1e6:.2f} M evals/s")
        print(f"  tape H+J    {1e6 * row['newton']:.3f} us/path/eval; H {1e6 * row['residual']:.3f}")
        print(f"  tracker kernel: {1e6 * t_old:.3f} us/path/eval (s changing), {1e6 * t_old_fixed:.3f} (s fixed)")
        print(f"  ratio tracker/tape: {t_old / row['full']:.2f} (s changing), {t_old_fixed / row['full']:.2f} (s fixed)")
        print(f"  eig{S.n_paths}: {1e3 * t_eig:.2f} ms = {t_eig / row['full'] / S.n_paths:.0f} tape evaluations per path")


if __name__ == "__main__":
    main()
