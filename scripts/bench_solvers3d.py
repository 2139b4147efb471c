"""Validate and benchmark the generated 3D solvers; writes tables/solvers3d.{csv,md}, solvers3d_noise.csv
and solvers3d.meta.json.

Per 3D solver (solvers/generated/tdoa_*3d_*) and network family, on N seeded networks (seeds 0..N-1):
``room`` (solvers.synthetic.room_network: receivers and transmitters uniform in an 8 x 6 x 3 m room,
offsets N(0, 1 m^2)) and ``paper`` (solvers.synthetic.random_network with dim=3: coordinates N(0, 10^2),
offsets N(0, 1), the paper's 2D distribution one dimension up). Noise-free figures: log10 relative error
of the root (H, b, o) against the true root (median, 90th and 99th percentile, maximum), failures (root
error above 1e-6, or no calibration recovered), the positions and offsets from solvers.api.calibrations
(relative position error after rigid alignment, relative offset error; no refinement), the RMS
measurement residual, the number of real candidates, the median time of one ``solve`` (best of three
rounds of single calls, one thread) and of ``solve_batch`` per network. The noise curve
(solvers3d_noise.csv): room networks with i.i.d. Gaussian noise of sigma on every f_ij, median and 90th
percentile of the position and offset errors of the calibration, before and after Levenberg-Marquardt on
all measurements (solvers.refine, as the 2D Table 4 rows), and the number of networks without one.

Usage: OPENBLAS_NUM_THREADS=1 python scripts/bench_solvers3d.py [--trials 1000] [--noise-trials 200]

The table (solvers3d.md) is written from the two CSVs alone (tests/test_solver3d.py checks it is current,
and that every committed 3D solver has rows with its spec's sha256); the date, commit and the indices of
the failed networks go to the meta file.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import datetime  # noqa: E402
import importlib  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from solvers import generate as gen  # noqa: E402
from solvers.api import calibrations  # noqa: E402
from solvers.metrics import offset_error, position_error  # noqa: E402
from solvers.refine import refine  # noqa: E402
from solvers.synthetic import random_network, room_network, true_root  # noqa: E402

TABLES = os.path.join(ROOT, "tables")
FAIL_TOL = 1e-6
REAL_TOL = 1e-6
SINGLE_ROUNDS = 3
#: Network families: name -> (description, sampler m, n, rng -> Network).
FAMILIES = {
    "room": ("uniform in an 8 x 6 x 3 m room, offsets N(0, 1)", lambda m, n, rng: room_network(m, n, rng)),
    "paper": ("coordinates N(0, 10^2), offsets N(0, 1)", lambda m, n, rng: random_network(m, n, rng, dim=3)),
}
NOISE_SIGMAS = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2)
COLUMNS = ["solver", "formulation", "method", "roots", "certified_primes", "size", "network", "trials",
           "root_median_log10_err", "root_p90_log10_err", "root_p99_log10_err", "root_max_log10_err", "failures",
           "recovered", "position_median_log10_err", "position_p99_log10_err", "position_max_log10_err",
           "offset_median_log10_err", "offset_max_log10_err", "residual_median_log10", "mean_real",
           "single_ms", "batch_us_per_network", "spec_sha256"]
NOISE_COLUMNS = ["solver", "network", "sigma_m", "trials", "position_median_log10_err", "position_p90_log10_err",
                 "offset_median_log10_err", "offset_p90_log10_err", "refined_position_median_log10_err",
                 "refined_position_p90_log10_err", "refined_offset_median_log10_err", "no_calibration"]


def solvers3d() -> list[str]:
    """Committed 3D solver labels (their module names carry the dimension: ``9r5s3d``)."""
    return [label for label in gen.SOLVERS if label.endswith("3d")]


def module_for(label: str):
    stem = next(f[:-3] for f in sorted(os.listdir(gen.GENERATED_DIR)) if f.startswith(f"tdoa_{label}_") and f.endswith(".py"))
    return importlib.import_module(f"solvers.generated.{stem}")


def _truth(net) -> np.ndarray:
    H, b, o = true_root(net)
    return np.concatenate([H[np.triu_indices(net.dim)], b, o])


def _log(values) -> np.ndarray:
    return np.log10(np.maximum(np.asarray(values, dtype=float), 1e-17))


def _q(values, q: float) -> float:
    return round(float(np.percentile(_log(values), q)), 2)


def _single_ms(module, F: np.ndarray, calls: int) -> float:
    best = np.inf
    for _ in range(SINGLE_ROUNDS):
        times = []
        for k in range(calls):
            t0 = time.perf_counter()
            module.solve(F[k % len(F)])
            times.append(time.perf_counter() - t0)
        best = min(best, float(np.median(times)))
    return 1e3 * best


def bench(label: str, family: str, trials: int, calls: int) -> tuple[dict, list[int]]:
    """One row of solvers3d.csv and the seeds of the failed networks."""
    module = module_for(label)
    m, n = module.CONFIG
    nets = [FAMILIES[family][1](m, n, np.random.default_rng(seed)) for seed in range(trials)]
    F = np.stack([net.measurements() for net in nets])
    truths = np.stack([_truth(net) for net in nets])
    t0 = time.perf_counter()
    roots = module.solve_batch(F)
    batch_s = time.perf_counter() - t0
    err = np.min(np.linalg.norm(roots - truths[:, None, :], axis=2), axis=1) / np.linalg.norm(truths, axis=1)
    err = np.where(np.isfinite(err), err, np.inf)
    pos, off, res, failed = [], [], [], []
    for seed, (net, x) in enumerate(zip(nets, roots)):
        cals = calibrations(module, F[seed], x)
        if not cals or err[seed] > FAIL_TOL:
            failed.append(seed)
        if cals:
            pos.append(position_error(cals[0], net))
            off.append(offset_error(cals[0], net))
            res.append(cals[0].residual)
    scale = np.max(np.abs(roots), axis=2)
    real = np.max(np.abs(roots.imag), axis=2) <= REAL_TOL * np.maximum(scale, 1e-300)
    with open(os.path.join(gen.GENERATED_DIR, module.SPEC_FILE), encoding="utf-8") as fh:
        spec = json.load(fh)
    row = {
        "solver": label, "formulation": module.SYSTEM, "method": module.METHOD, "roots": module.DEGREE,
        "certified_primes": " ".join(map(str, spec["certified"]["primes"])), "size": "x".join(map(str, module.SIZE)),
        "network": family, "trials": trials,
        "root_median_log10_err": _q(err, 50), "root_p90_log10_err": _q(err, 90), "root_p99_log10_err": _q(err, 99),
        "root_max_log10_err": _q(err, 100), "failures": len(failed), "recovered": len(pos),
        "position_median_log10_err": _q(pos, 50), "position_p99_log10_err": _q(pos, 99),
        "position_max_log10_err": _q(pos, 100), "offset_median_log10_err": _q(off, 50),
        "offset_max_log10_err": _q(off, 100), "residual_median_log10": _q(res, 50),
        "mean_real": round(float(np.mean(real.sum(axis=1))), 3),
        "single_ms": round(_single_ms(module, F, calls), 3), "batch_us_per_network": round(1e6 * batch_s / trials, 1),
        "spec_sha256": module.SPEC_SHA256,
    }
    return row, failed


def noise_curve(label: str, trials: int) -> list[dict]:
    """Rows of solvers3d_noise.csv: room networks, noise sigma on every measurement (seeds 0..trials-1)."""
    module = module_for(label)
    m, n = module.CONFIG
    rows = []
    for sigma in NOISE_SIGMAS:
        pos, off, rpos, roff, missing = [], [], [], [], 0
        for seed in range(trials):
            rng = np.random.default_rng(seed)
            net = room_network(m, n, rng)
            F = net.measurements(sigma, rng)
            cals = calibrations(module, F)
            if not cals:
                missing += 1
                continue
            pos.append(position_error(cals[0], net))
            off.append(offset_error(cals[0], net))
            refined = refine(cals[0], F).calibration
            rpos.append(position_error(refined, net))
            roff.append(offset_error(refined, net))
        rows.append({"solver": label, "network": "room", "sigma_m": f"{sigma:g}", "trials": trials,
                     "position_median_log10_err": _q(pos, 50), "position_p90_log10_err": _q(pos, 90),
                     "offset_median_log10_err": _q(off, 50), "offset_p90_log10_err": _q(off, 90),
                     "refined_position_median_log10_err": _q(rpos, 50), "refined_position_p90_log10_err": _q(rpos, 90),
                     "refined_offset_median_log10_err": _q(roff, 50), "no_calibration": missing})
    return rows


def markdown(rows: list[dict], noise: list[dict]) -> str:
    """tables/solvers3d.md from the rows of the two CSVs (as read back: strings)."""
    lines = ["<!-- Regenerate: OPENBLAS_NUM_THREADS=1 python scripts/bench_solvers3d.py; provenance in "
             "solvers3d.meta.json -->", "",
             "**Generated 3D solvers: noise-free validation** (log10 relative errors: median / p99 / max; failures: "
             "root error > 1e-6 or no calibration; positions and offsets from solvers.api.calibrations, not refined)", "",
             "| solver | method | roots (certified on) | networks | trials | root error | position error | "
             "offset error (median / max) | failures | ms per call | us per network (batch) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        m, n = r["solver"][:-2].split("r")
        lines.append(
            f"| {m}r/{n} 3D | {r['method']} {r['size']} | {r['roots']} ({r['certified_primes']}) | "
            f"{FAMILIES[r['network']][0]} | {r['trials']} | {r['root_median_log10_err']} / {r['root_p99_log10_err']} / "
            f"{r['root_max_log10_err']} | {r['position_median_log10_err']} / {r['position_p99_log10_err']} / "
            f"{r['position_max_log10_err']} | {r['offset_median_log10_err']} / {r['offset_max_log10_err']} | "
            f"{r['failures']} | {r['single_ms']} | {r['batch_us_per_network']} |")
    lines += ["", "**Noise** (room networks, Gaussian noise of sigma on every measurement; log10 relative errors "
              "median / p90 of the solver's calibration, then after Levenberg-Marquardt on all 45 measurements)", "",
              "| solver | sigma [m] | trials | position error | offset error | refined: position error | "
              "refined: offset error (median) | no calibration |", "|---|---|---|---|---|---|---|---|"]
    for r in noise:
        lines.append(f"| {r['solver']} | {r['sigma_m']} | {r['trials']} | {r['position_median_log10_err']} / "
                     f"{r['position_p90_log10_err']} | {r['offset_median_log10_err']} / {r['offset_p90_log10_err']} | "
                     f"{r['refined_position_median_log10_err']} / {r['refined_position_p90_log10_err']} | "
                     f"{r['refined_offset_median_log10_err']} | {r['no_calibration']} |")
    return "\n".join(lines) + "\n"


def read_csv(name: str) -> list[dict]:
    with open(os.path.join(TABLES, name), newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _write_csv(name: str, columns: list[str], rows: list[dict]) -> None:
    with open(os.path.join(TABLES, name), "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)


def _git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=False).stdout.strip()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=1000, help="noise-free networks per family (default 1000)")
    parser.add_argument("--noise-trials", type=int, default=200, help="networks per noise level (default 200)")
    parser.add_argument("--single-calls", type=int, default=200, help="timed single calls per round (default 200)")
    args = parser.parse_args(argv)
    if min(args.trials, args.noise_trials, args.single_calls) < 1:
        parser.error("--trials, --noise-trials and --single-calls must be positive")
    rows, noise, failed = [], [], {}
    for label in solvers3d():
        for family in FAMILIES:
            row, bad = bench(label, family, args.trials, args.single_calls)
            rows.append(row)
            failed[f"{label} {family}"] = bad
            print(f"{label} {family}: root median {row['root_median_log10_err']}, max {row['root_max_log10_err']}; "
                  f"failures {row['failures']}/{args.trials}; {row['single_ms']} ms per call", flush=True)
        noise += noise_curve(label, args.noise_trials)
    _write_csv("solvers3d.csv", COLUMNS, rows)
    _write_csv("solvers3d_noise.csv", NOISE_COLUMNS, noise)
    with open(os.path.join(TABLES, "solvers3d.md"), "w", encoding="utf-8", newline="\n") as fh:
        fh.write(markdown(read_csv("solvers3d.csv"), read_csv("solvers3d_noise.csv")))
    meta = {"date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "commit": _git("rev-parse", "--short", "HEAD"), "dirty": bool(_git("status", "--porcelain", "--", "solvers")),
            "trials": args.trials, "noise_trials": args.noise_trials, "single_calls": args.single_calls,
            "seeds": f"0..{args.trials - 1}", "threads": os.environ.get("OPENBLAS_NUM_THREADS"),
            "load_average_at_end": list(os.getloadavg()), "failed_networks": failed}
    with open(os.path.join(TABLES, "solvers3d.meta.json"), "w", encoding="utf-8", newline="\n") as fh:
        json.dump(meta, fh, indent=2)
        fh.write("\n")
    print(f"wrote tables/solvers3d.csv, solvers3d_noise.csv, solvers3d.md, solvers3d.meta.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
