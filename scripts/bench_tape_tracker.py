"""Benchmark the batched tape tracker against the per-path monomial tracker (issue 20, items 2 and 7).

Per solver (a committed homotopy solver whose system has an unexpanded straight-line program,
solvers.continuation.slp.system_equations; positions solvers compared in their own unknowns): on N
seeded noiseless networks (solvers.synthetic.random_network, as scripts/bench_solvers.py), each
evaluator ("monomials": tracker.track; "tape": tape_kernel.track) solves every network through the
generated module's solve path (solve_scaled: scaling, tracking, retracking, detours, Newton on the
target); reported: median ms of one solve (best of three rounds over the first ``--single`` networks),
its ratio to numpy's complex eig of the root count's size (one BLAS thread) timed in this process,
microseconds per path (wall, and CPU time of the same solves: the steadier figure on a loaded machine),
failures (no candidate within 1e-6 of the true root) and log10 error quantiles
of the raw endpoints, and where the tape solver's time goes (tape evaluations, LU + solves, the rest;
the kernels as the solver runs them: its compiled code where solvers.continuation.tape_native builds it)
from the steps the tracker took and the kernels' per-path costs measured here.

Usage: OPENBLAS_NUM_THREADS=1 python scripts/bench_tape_tracker.py [--trials 200] [--solvers 9r3s 6r3s]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ["TDOA_WORKBENCH_THREADS"] = "1"  # the trackers on one core, as the eigensolves they are compared with

import argparse  # noqa: E402
import importlib  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

from solvers.continuation import tape_jit, tape_kernel, tape_native  # noqa: E402
from solvers.continuation.tracking import HomotopySolver  # noqa: E402
from solvers.generate import GENERATED_DIR  # noqa: E402
from solvers.methods import homotopy  # noqa: E402
from solvers.synthetic import random_network  # noqa: E402

from bench_solvers import _truth  # noqa: E402  (scripts/ is on the path of a script)
from bench_tape import _native_loop, _tape_loop, best as _best  # noqa: E402

FAIL_TOL = 1e-6
ROUNDS = 5


def _module(label: str):
    name = [f for f in os.listdir(GENERATED_DIR) if f.startswith(f"tdoa_{label}_homotopy") and f.endswith(".py")][0]
    return importlib.import_module(f"solvers.generated.{name[:-3]}")


def _solver(module, evaluator: str) -> HomotopySolver:
    with open(os.path.join(GENERATED_DIR, module.SPEC_FILE), encoding="utf-8") as fh:
        return HomotopySolver(homotopy.load_spec(fh.read()), module.coefficients, evaluator)


@njit(cache=False)  # calls kernels of another file: a disk cache would go stale with them
def _lu_loop(lin, J0r, J0i, Or, Oi, N, piv, ok, b0r, b0i, br, bi, P, reps, factor):
    """reps x (copy the Jacobians and right-hand sides in; with ``factor``, one LU and two solves, the
    tracker's work per evaluation; without, the copies alone, to be subtracted). lin: the solver's
    compiled LU and solve (tape_native), zeros for the batched numba kernels."""
    for r in range(reps):
        Or[:, :] = J0r
        Oi[:, :] = J0i
        for k in range(2):
            br[:, :] = b0r  # fresh right-hand sides: repeated solves would reach denormals
            bi[:, :] = b0i
            if factor:
                if k == 0:
                    tape_jit._factor(lin, Or, Oi, N, N, piv, ok, P)
                tape_jit._back(lin, Or, Oi, N, N, piv, br, bi, P)


def _kernel_costs(solver, P: int, rng, native=None) -> tuple[float, float, float, float]:
    """Seconds per path of one evaluation of the full, the Newton and the residual tape and of one LU
    with two solves, at P paths per call: by the interpreter and the batched LU, or with ``native``
    (tape_native.addresses) by the solver's compiled code."""
    N = solver.nvars
    tapes = solver.tapes
    cap = tape_kernel.capacity(P)  # as the tracker lays out its columns
    x = np.resize(solver.x0, (cap, N))
    q1 = rng.normal(size=len(solver.q0)) + 0j
    inputs = np.concatenate([x.T, np.full((1, cap), 0.5), np.tile(solver.q0[:, None], (1, cap)),
                             np.tile((q1 - solver.q0)[:, None], (1, cap))])
    native = np.zeros(5, dtype=np.int64) if native is None else native
    reps = max(1, 20000 // P)
    costs = []
    for fn, tape in zip(native[:3], (tapes.full, tapes.newton, tapes.residual)):
        Rr, Ri, Or, Oi = tape_kernel.workspace(tape, cap)
        Rr[: tape.n_inputs], Ri[: tape.n_inputs] = inputs.real, inputs.imag
        if fn:
            run = lambda: _native_loop(fn, Rr, Ri, Or, Oi, P, reps)  # noqa: E731
        else:
            run = lambda: _tape_loop(tape.code, tape.imm, Rr, Ri, Or, Oi, P, reps)  # noqa: E731
        run()
        costs.append(_best(run) / (reps * P))
    Rr, Ri, Or, Oi = tape_kernel.workspace(tapes.full, cap)  # the full tape's outputs: J after H
    Rr[: tapes.full.n_inputs], Ri[: tapes.full.n_inputs] = inputs.real, inputs.imag
    tape_kernel.run_tape(tapes.full.code, tapes.full.imm, Rr, Ri, Or, Oi, cap)
    J0r, J0i = np.ascontiguousarray(Or), np.ascontiguousarray(Oi)
    piv, ok = np.zeros((N, cap), dtype=np.int64), np.zeros(cap, dtype=bool)
    b0r, b0i = np.ascontiguousarray(J0r[:N]), np.ascontiguousarray(J0i[:N])
    br, bi = np.empty_like(b0r), np.empty_like(b0i)
    args = (np.ascontiguousarray(native[3:5]), J0r, J0i, Or, Oi, N, piv, ok, b0r, b0i, br, bi, P)
    _lu_loop(*args, 1, True)
    _lu_loop(*args, 1, False)
    t_lu = _best(lambda: _lu_loop(*args, reps, True)) / (reps * P)
    t_copy = _best(lambda: _lu_loop(*args, reps, False)) / (reps * P)
    return costs[0], costs[1], costs[2], t_lu - t_copy


def bench(label: str, trials: int, seed: int, single: int, evaluators=("monomials", "tape")) -> list[dict]:
    module = _module(label)
    m, n = module.CONFIG
    rng = np.random.default_rng(seed)
    nets = [random_network(m, n, rng) for _ in range(trials)]
    F = np.stack([net.measurements() for net in nets])
    truths = np.array([_truth(module, net) for net in nets])
    K = module.PATHS
    A = rng.normal(size=(K, K)) + 1j * rng.normal(size=(K, K))
    solvers, first = {}, {}
    for evaluator in evaluators:
        t0 = time.perf_counter()
        solvers[evaluator] = _solver(module, evaluator)
        homotopy.solve_scaled(solvers[evaluator], F[:1], module.CONFIG, module.SCALE_POWERS)
        first[evaluator] = time.perf_counter() - t0
    # rounds interleave the evaluators and eig (this shared machine's speed drifts by 2x in minutes)
    medians = {ev: [] for ev in solvers}
    cpu = {ev: [] for ev in solvers}  # CPU time of the same solves: steadier than wall time under load
    eig, eig_cpu = [], []
    for _ in range(ROUNDS):
        for evaluator, solver in solvers.items():
            times, cpus = [], []
            for k in range(min(single, trials)):
                t, c = time.perf_counter(), time.process_time()
                homotopy.solve_scaled(solver, F[k:k + 1], module.CONFIG, module.SCALE_POWERS)
                times.append(time.perf_counter() - t)
                cpus.append(time.process_time() - c)
            medians[evaluator].append(float(np.median(times)))
            cpu[evaluator].append(float(np.median(cpus)))
        eig.append(_best(lambda: np.linalg.eig(A), 5))
        c = time.process_time()
        for _ in range(5):
            np.linalg.eig(A)
        eig_cpu.append((time.process_time() - c) / 5)
    eig_ms = 1e3 * min(eig)
    rows = []
    for evaluator, solver in solvers.items():
        ms = 1e3 * min(medians[evaluator])
        roots = np.stack([homotopy.solve_scaled(solver, f[None], module.CONFIG, module.SCALE_POWERS)[0] for f in F])
        with np.errstate(all="ignore"):
            err = np.nanmin(np.linalg.norm(roots - truths[:, None, :], axis=2), axis=1) / np.linalg.norm(truths, axis=1)
        err = np.where(np.isfinite(err), err, np.inf)
        log = np.log10(np.maximum(err, 1e-17))
        row = {"solver": label, "evaluator": evaluator, "paths": K, "ms_single": ms, "eig_ms": eig_ms,
               "ratio_eig": ms / eig_ms, "us_per_path": 1e3 * ms / K,
               "us_per_path_cpu": 1e6 * min(cpu[evaluator]) / K, "ratio_eig_cpu": min(cpu[evaluator]) / min(eig_cpu), "first_s": first[evaluator],
               "failures": int(np.sum(err > FAIL_TOL)), "trials": trials, "failed": np.flatnonzero(err > FAIL_TOL).tolist(),
               "median_log10_err": float(np.median(log)), "p90_log10_err": float(np.percentile(log, 90)),
               "p99_log10_err": float(np.percentile(log, 99))}
        if evaluator == "tape":
            # evaluations per path of one plain track (lock step: per attempt three predictor stages and
            # the last Newton step on the full tape, the other Newton steps on the Newton tape)
            opts = solver.options
            sc = np.sqrt(np.mean(np.abs(F[:single].reshape(len(F[:single]), -1)) ** 2, axis=1))
            # rounds interleave the plain tracks and the kernels' timings (minimum of each over rounds)
            attempts, accepted, t_track, costs = [], [], [], []
            native = tape_native.addresses(solver.tapes, wait=True)  # what the solver runs (zeros: the interpreter)
            for _ in range(ROUNDS):
                round_track = []
                for f, s in zip(F[:single], sc):
                    q = f.reshape(1, -1).astype(complex) / s
                    t = time.perf_counter()
                    _, stats = tape_kernel.track(solver.tapes, solver.q0[None], q, solver.x0, None, opts, native=native)
                    round_track.append(time.perf_counter() - t)
                    attempts.append(float(np.mean(stats[:, 1] + stats[:, 2])))
                    accepted.append(float(np.mean(stats[:, 1])))
                t_track.append(float(np.median(round_track)))
                costs.append(_kernel_costs(solver, K, rng, native))
            t_full, t_newton, t_res, t_lu = np.min(costs, axis=0)
            a, acc = float(np.median(attempts)), float(np.median(accepted))
            # per attempt: RK4 three full-tape stages, the corrector's Newton-tape steps and its last step on
            # the full tape; Pade: no stage, and per accepted point (and the start) four residual-tape runs
            # for the Taylor coefficients (their two solves reuse a factorisation: not counted)
            pade = opts.predictor == "pade"
            n_full = (1 if pade else 4) * a + 1
            n_newton = (opts.newton - 1) * a + opts.final_newton
            n_res = 4 * (acc + 1) if pade else 0.0
            row.update({"predictor": opts.predictor, "attempts_per_path": a, "accepted_per_path": acc,
                        "evals_per_path": n_full + n_newton + n_res, "us_eval": 1e6 * t_full,
                        "us_eval_newton": 1e6 * t_newton, "us_eval_residual": 1e6 * t_res, "us_lu": 1e6 * t_lu,
                        "us_path_track": 1e6 * min(t_track) / K,
                        "us_path_eval": 1e6 * (n_full * t_full + n_newton * t_newton + n_res * t_res),
                        "us_path_lu": 1e6 * (n_full + n_newton) * t_lu})
        rows.append(row)
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--solvers", nargs="+", default=["9r3s", "6r3s"])
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--single", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--evaluators", nargs="+", default=["monomials", "tape"], choices=["monomials", "tape"])
    args = ap.parse_args(argv)
    for label in args.solvers:
        rows = bench(label, args.trials, args.seed, args.single, args.evaluators)
        for r in rows:
            print(f"{r['solver']} {r['evaluator']:9s}: {r['ms_single']:.2f} ms single = {r['ratio_eig']:.2f}x eig{r['paths']} "
                  f"({r['eig_ms']:.2f} ms), {r['us_per_path']:.0f} us/path ({r['us_per_path_cpu']:.1f} CPU, {r['ratio_eig_cpu']:.2f}x eig's CPU), first call {r['first_s']:.1f} s; "
                  f"failures {r['failures']}/{r['trials']} {r['failed']}, log10 err median {r['median_log10_err']:.2f} "
                  f"p90 {r['p90_log10_err']:.2f} p99 {r['p99_log10_err']:.2f}")
        t = rows[-1]
        if t["evaluator"] != "tape":
            continue
        print(f"  tape tracker ({t['predictor']}), one plain track: {t['us_path_track']:.0f} us/path; "
              f"{t['evals_per_path']:.0f} evaluations per path ({t['attempts_per_path']:.0f} step attempts, "
              f"{t['accepted_per_path']:.0f} accepted); evaluation {t['us_eval']:.2f} us (full tape), "
              f"{t['us_eval_newton']:.2f} us (Newton tape), {t['us_eval_residual']:.2f} us (residual tape): "
              f"{t['us_path_eval']:.0f} us, LU + 2 solves {t['us_lu']:.2f} us x evals = {t['us_path_lu']:.0f} us, "
              f"rest (bookkeeping) {t['us_path_track'] - t['us_path_eval'] - t['us_path_lu']:.0f} us; "
              f"solve beyond tracking {t['us_per_path'] - t['us_path_track']:.0f} us/path")
        if len(rows) == 2:
            print(f"  speed-up tape vs monomials: {rows[0]['ms_single'] / t['ms_single']:.2f}x")


if __name__ == "__main__":
    main()
