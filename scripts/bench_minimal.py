"""Validate and benchmark the generated minimal TOA solvers; writes tables/solvers_minimal.{csv,md} (results)
and tables/solvers_minimal.timing.json (times: untracked, they depend on the machine and its load).

Per solver (solvers.api.KD_SOLVERS: TOA 2D 3r/3s, TOA 3D 4r/6s, 6r/4s, 5r/5s) on N seeded room networks
(seeds 0..N-1; solvers.synthetic.room_network with offsets 0: receivers and transmitters uniform in an
8 x 6 x 3 m room, in 2D on its 8 x 6 m floor): log10 relative error of the root (H, b) nearest to the true
one (median, 99th percentile, maximum; the solver alone on F, without solve_network's transposed retry),
failures (the true network is not among the calibrations of ``solve_network(F, dim=K, model="toa")``
within a position error of 1e-6 after rigid alignment, which allows the undecidable mirror image), the
number of real roots and of calibrations per network. Times, interleaved in the same run: one ``solve``
call (median of single calls, best of three rounds, one thread) against numpy.linalg.eig of an N x N
complex matrix, N = the solver's root count; their ratio and the microseconds per tracked path.

A configuration with two committed methods (3r3stoa: homotopy and action matrix) gets one row per method;
the "true network found" of an action-matrix row runs solve_network with that solver
(solvers.api.PREFERRED_METHOD is set to it for the row).

Usage: OPENBLAS_NUM_THREADS=1 python scripts/bench_minimal.py [--trials 1000] [--single-calls 200] [--only LABEL ...]
  --only: rerun these configurations; their rows replace the old ones in the CSV and the table, the
  other rows are kept as committed.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ["TDOA_WORKBENCH_THREADS"] = "1"  # the trackers on one core, as the eigensolves they are compared with
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import datetime  # noqa: E402
import importlib  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from analysis.formulations.kd import gram_root  # noqa: E402
from solvers import api  # noqa: E402
from solvers.api import KD_SOLVERS, _module_for, solve_network  # noqa: E402
from solvers.metrics import position_error  # noqa: E402
from solvers.synthetic import ROOM, room_network, true_root  # noqa: E402

TABLES = os.path.join(ROOT, "tables")
FOUND_TOL = 1e-6
REAL_TOL = 1e-6
SINGLE_ROUNDS = 3
COLUMNS = ["solver", "method", "formulation", "dim", "model", "roots", "paths", "trials", "root_median_log10_err",
           "root_p99_log10_err", "root_max_log10_err", "found", "failures", "failure_share",
           "position_median_log10_err", "mean_real", "mean_calibrations", "spec_sha256"]


def minimal_solvers() -> list[tuple[str, int, str, str]]:
    """(label, dim, model, method) of the committed TOA solvers (every committed method of a label)."""
    out = []
    for (dim, model), labels in sorted(KD_SOLVERS.items()):
        if model != "toa":
            continue
        for label in labels:
            for method, tag in (("homotopy", "_homotopy"), ("action-matrix", "_action")):
                if any(f.startswith(f"tdoa_{label}{tag}") and f.endswith(".py") for f in os.listdir(api._GENERATED)):
                    out.append((label, dim, model, method))
    return out


def _log(values) -> np.ndarray:
    """log10, clipped to [-17, 300] (a network without any finite candidate has error inf: 300)."""
    return np.log10(np.clip(np.nan_to_num(np.asarray(values, dtype=float), nan=1e300, posinf=1e300), 1e-17, 1e300))


def _q(values, q: float) -> float:
    return round(float(np.percentile(_log(values), q)), 2) if len(values) else float("nan")


def networks(m: int, n: int, dim: int, trials: int) -> list:
    """Seeded TOA room networks (offsets 0)."""
    return [room_network(m, n, np.random.default_rng(seed), room=ROOM[:dim], offset_sigma=0.0) for seed in range(trials)]


def bench(label: str, dim: int, model: str, trials: int, method: str = "homotopy") -> tuple[dict, list[int]]:
    """One row of solvers_minimal.csv and the seeds of the failed networks."""
    module = _module_for(label, method)
    m, n = module.CONFIG
    nets = networks(m, n, dim, trials)
    F = np.stack([net.measurements() for net in nets])
    iu = np.triu_indices(dim)
    if "-gram" in module.SYSTEM:  # the receivers' Gram matrix (and further receivers' coordinates in its basis)
        truths = np.stack([gram_root(net.receivers, dim) for net in nets])
    else:
        truths = np.stack([np.concatenate([true_root(net)[0][iu], true_root(net)[1]]) for net in nets])
    roots = module.solve_batch(F)
    dist = np.linalg.norm(roots - truths[:, None, :], axis=2)  # NaN for a lost path: not the nearest root
    err = np.min(np.where(np.isfinite(dist), dist, np.inf), axis=1) / np.linalg.norm(truths, axis=1)
    found, failed, n_cals = [], [], []
    preferred = dict(api.PREFERRED_METHOD)
    api.PREFERRED_METHOD[label] = method  # solve_network runs the solver of this row
    try:
        for seed, net in enumerate(nets):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # minimal data: several exact solutions, by design
                cals = solve_network(F[seed], dim=dim, model=model)
            n_cals.append(len(cals))
            best = min((position_error(c, net) for c in cals), default=np.inf)
            found.append(best)
            if not best <= FOUND_TOL:
                failed.append(seed)
    finally:
        api.PREFERRED_METHOD.clear()
        api.PREFERRED_METHOD.update(preferred)
    finite = np.all(np.isfinite(roots), axis=2)
    scale = np.max(np.abs(np.where(np.isfinite(roots), roots, 0)), axis=2)
    real = finite & (np.max(np.abs(np.where(np.isfinite(roots), roots, 0).imag), axis=2) <= REAL_TOL * np.maximum(scale, 1e-300))
    with open(os.path.join(os.path.dirname(module.__file__), module.SPEC_FILE), encoding="utf-8") as fh:
        spec = json.load(fh)
    ok = [v for v in found if np.isfinite(v)]
    row = {
        "solver": label, "method": method, "formulation": module.SYSTEM, "dim": dim, "model": model, "roots": module.DEGREE,
        "paths": spec.get("paths", module.DEGREE), "trials": trials,
        "root_median_log10_err": _q(err, 50), "root_p99_log10_err": _q(err, 99), "root_max_log10_err": _q(err, 100),
        "found": trials - len(failed), "failures": len(failed), "failure_share": round(len(failed) / trials, 4),
        "position_median_log10_err": _q(ok, 50), "mean_real": round(float(np.mean(real.sum(axis=1))), 3),
        "mean_calibrations": round(float(np.mean(n_cals)), 3), "spec_sha256": module.SPEC_SHA256,
    }
    return row, failed


def timing(label: str, dim: int, calls: int, method: str = "homotopy") -> dict:
    """Median single ``solve`` and eig(N x N) times, interleaved (best of SINGLE_ROUNDS rounds)."""
    module = _module_for(label, method)
    m, n = module.CONFIG
    F = np.stack([net.measurements() for net in networks(m, n, dim, calls)])
    N = module.DEGREE
    rng = np.random.default_rng(0)
    A = rng.normal(size=(N, N)) + 1j * rng.normal(size=(N, N))
    module.solve(F[0])  # warm-up (compilation of the tracker, spec load)
    best_solve, best_eig = np.inf, np.inf
    for _ in range(SINGLE_ROUNDS):
        ts, te = [], []
        for k in range(calls):
            t0 = time.perf_counter()
            module.solve(F[k])
            t1 = time.perf_counter()
            np.linalg.eig(A)
            t2 = time.perf_counter()
            ts.append(t1 - t0)
            te.append(t2 - t1)
        best_solve, best_eig = min(best_solve, float(np.median(ts))), min(best_eig, float(np.median(te)))
    return {"solve_ms": round(1e3 * best_solve, 3), "eig_ms": round(1e3 * best_eig, 3),
            "ratio_to_eig": round(best_solve / best_eig, 2), "us_per_path": round(1e6 * best_solve / N, 1), "eig_n": N}


def markdown(rows: list[dict]) -> str:
    """tables/solvers_minimal.md from the rows of the CSV (as read back: strings)."""
    lines = ["<!-- Regenerate: OPENBLAS_NUM_THREADS=1 python scripts/bench_minimal.py; times in "
             "solvers_minimal.timing.json (not committed) -->", "",
             "**Generated minimal TOA solvers: noise-free validation on room networks** (log10 relative error of "
             "the solver's root nearest the true one, the solver alone on F, median / p99 / max, 300 where every "
             "path was lost; a failure: the true network is not among the calibrations of "
             "solve_network(F, dim=K, model=\"toa\") within 1e-6 position error after rigid alignment)", "",
             "| solver | method | formulation | roots (paths) | trials | root error | true network found | failures | "
             "real roots (mean) | calibrations (mean) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['dim']}D {r['model'].upper()} {r['solver'].split('s')[0]}s | {r['method']} | {r['formulation']} | "
                     f"{r['roots']} ({r['paths']}) | {r['trials']} | {r['root_median_log10_err']} / "
                     f"{r['root_p99_log10_err']} / {r['root_max_log10_err']} | {r['found']} | "
                     f"{r['failures']} ({100 * float(r['failure_share']):.1f} %) | {r['mean_real']} | "
                     f"{r['mean_calibrations']} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=1000, help="noise-free networks per solver (default 1000)")
    parser.add_argument("--single-calls", type=int, default=200, help="timed single calls per round (default 200)")
    parser.add_argument("--only", nargs="*", help="a subset of the solver labels (their rows replace the old ones)")
    args = parser.parse_args(argv)
    if min(args.trials, args.single_calls) < 1:
        parser.error("--trials and --single-calls must be positive")
    rows, failed, times = {}, {}, {}
    for label, dim, model, method in minimal_solvers():
        if args.only and label not in args.only:
            continue
        key = f"{label}:{method}"
        row, bad = bench(label, dim, model, args.trials, method)
        rows[key] = row
        failed[key] = bad
        times[key] = timing(label, dim, args.single_calls, method)
        print(f"{key}: root median {row['root_median_log10_err']}, max {row['root_max_log10_err']}; found "
              f"{row['found']}/{args.trials}; {times[key]}", flush=True)
    csv_path = os.path.join(TABLES, "solvers_minimal.csv")
    if args.only:  # the other rows as committed (a row written before the method column: a homotopy)
        with open(csv_path, newline="", encoding="utf-8") as fh:
            old = {f"{r['solver']}:{r.get('method') or 'homotopy'}": {**r, "method": r.get("method") or "homotopy"}
                   for r in csv.DictReader(fh)}
        order = [f"{lb}:{mt}" for lb, _, _, mt in minimal_solvers()]
        rows = {k: rows.get(k, old.get(k)) for k in order if k in rows or k in old}
    with open(csv_path, "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows.values())
    with open(os.path.join(TABLES, "solvers_minimal.csv"), newline="", encoding="utf-8") as fh:
        table = markdown(list(csv.DictReader(fh)))
    with open(os.path.join(TABLES, "solvers_minimal.md"), "w", encoding="utf-8", newline="\n") as fh:
        fh.write(table)
    timing_path = os.path.join(TABLES, "solvers_minimal.timing.json")
    if args.only and os.path.exists(timing_path):  # keep the other solvers' times
        with open(timing_path, encoding="utf-8") as fh:
            previous = json.load(fh)
        times = {**previous.get("times", {}), **times}
        failed = {**previous.get("failed_networks", {}), **failed}
    record = {"date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
              "trials": args.trials, "single_calls": args.single_calls, "threads": os.environ.get("OPENBLAS_NUM_THREADS"),
              "load_average_at_end": list(os.getloadavg()), "times": times, "failed_networks": failed}
    with open(os.path.join(TABLES, "solvers_minimal.timing.json"), "w", encoding="utf-8", newline="\n") as fh:
        json.dump(record, fh, indent=2)
        fh.write("\n")
    print("wrote tables/solvers_minimal.csv, solvers_minimal.md (results), solvers_minimal.timing.json (times)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
