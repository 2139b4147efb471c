"""Benchmark solvers.calibrate on corrupted synthetic networks; writes tables/calibration.csv (+ .meta.json).

Grid: shapes 8r/5s, 12r/20s, 30r/40s x noise sigma {1e-3, 1e-2, 1e-1} x missing {0, 10, 30 %} x outliers
{0, 2, 5, 10 % of the measured entries}. Networks: solvers.synthetic.random_network (positions N(0, 10^2),
offsets N(0, 1)); gaps and outliers: solvers.synthetic.corrupt_measurements (every receiver keeps >= 3 and
every transmitter >= 4 measurements; outliers uniform in the data range). calibrate gets the true sigma.

Per trial: relative position error (after rigid alignment) and offset error, and the same for the
reference: least squares started at the ground truth on the true inliers (the best the data allow).
Success: every node placed and both errors <= 3 x the reference's + 1e-9. Also: outliers flagged
(rejected by `inliers`), inliers falsely rejected, status "unconverged", silent failures (not a success,
status "ok" and no warning), seconds per call, hypotheses per second.
A second table, the noiseless minimal configurations 9r/3s and 6r/4s, compares calibrate with
solvers.api.solve_network (today's path) on the same networks: median / p90 log10 errors and failures (> 1e-6).

Usage: OPENBLAS_NUM_THREADS=1 python scripts/bench_calibration.py [--trials 20] [--quick] [--seed 0]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import datetime  # noqa: E402
import itertools  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402
import scipy  # noqa: E402

from solvers import api  # noqa: E402
from solvers.calibrate import calibrate, robust_refine  # noqa: E402
from solvers.metrics import calibration_errors  # noqa: E402
from solvers.recovery import to_gauge  # noqa: E402
from solvers.synthetic import corrupt_measurements, random_network  # noqa: E402

SHAPES = ((8, 5), (12, 20), (30, 40))
SIGMAS = (1e-3, 1e-2, 1e-1)
MISSING = (0.0, 0.1, 0.3)
OUTLIERS = (0.0, 0.02, 0.05, 0.1)
ABS_TOL = 1e-9


class _Arrays:
    """receivers / transmitters / offsets, as solvers.metrics reads them."""

    def __init__(self, R, S, O):
        self.receivers, self.transmitters, self.offsets = R, S, O


def trial_data(m, n, sigma, missing, outliers, seed):
    """(network, F, outlier mask, reference fit) of one trial; the reference is least squares from the
    ground truth on the true inliers (the best these data allow)."""
    rng = np.random.default_rng(seed)
    net = random_network(m, n, rng)
    F, bad = corrupt_measurements(net.measurements(sigma, rng), rng, missing, outliers)
    good = np.isfinite(F) & ~bad
    ref_fit = robust_refine(F, good, *to_gauge(net.receivers, net.transmitters), net.offsets.copy(), loss="linear")
    return net, F, bad, ref_fit


def judge(res, net, ref_fit):
    """(success, errors of res or None, errors of the reference) by the benchmark's definition."""
    ref = calibration_errors(_Arrays(ref_fit.R, ref_fit.S, ref_fit.O), net)
    placed = np.isfinite(res.receivers).all() and np.isfinite(res.transmitters).all()
    err = calibration_errors(res, net) if placed else None
    success = bool(err is not None and err.position <= 3 * ref.position + ABS_TOL and err.offset <= 3 * ref.offset + ABS_TOL)
    return success, err, ref


def trial(m, n, sigma, missing, outliers, seed):
    net, F, bad, ref_fit = trial_data(m, n, sigma, missing, outliers, seed)
    good = np.isfinite(F) & ~bad
    res = calibrate(F, sigma=sigma, seed=seed)
    success, err, ref = judge(res, net, ref_fit)
    return {
        "success": success,
        "pos": err.position if err else np.inf,
        "off": err.offset if err else np.inf,
        "ref_pos": ref.position,
        "missing": float(np.isnan(F).mean()),
        "n_bad": int(bad.sum()),
        "flagged": int((~res.inliers & bad).sum()),
        "false_rejects": int((~res.inliers & good).sum()),
        "n_good": int(good.sum()),
        "unconverged": res.status != "ok",
        "silent": (not success) and res.status == "ok" and not res.warnings,
        "seconds": res.seconds,
        "hypotheses": res.hypotheses,
        "samples": res.samples,
    }


def summarise(rows: list[dict]) -> dict:
    pos = np.array([r["pos"] for r in rows])
    off = np.array([r["off"] for r in rows])
    n_bad = sum(r["n_bad"] for r in rows)
    seconds = np.array([r["seconds"] for r in rows])
    return {
        "trials": len(rows),
        "missing_actual": round(float(np.mean([r["missing"] for r in rows])), 3),
        "success": round(float(np.mean([r["success"] for r in rows])), 3),
        "median_pos_err": float(f"{np.median(pos):.3g}"),
        "p90_pos_err": float(f"{np.percentile(pos, 90):.3g}"),
        "median_off_err": float(f"{np.median(off):.3g}"),
        "p90_off_err": float(f"{np.percentile(off, 90):.3g}"),
        "median_ref_pos_err": float(f"{np.median([r['ref_pos'] for r in rows]):.3g}"),
        "outliers_flagged": round(sum(r["flagged"] for r in rows) / n_bad, 3) if n_bad else "",
        "false_reject_rate": round(sum(r["false_rejects"] for r in rows) / sum(r["n_good"] for r in rows), 4),
        "unconverged": round(float(np.mean([r["unconverged"] for r in rows])), 3),
        "silent_failures": round(float(np.mean([r["silent"] for r in rows])), 3),
        "median_seconds": round(float(np.median(seconds)), 3),
        "p90_seconds": round(float(np.percentile(seconds, 90)), 3),
        "hypotheses_per_s": round(sum(r["hypotheses"] for r in rows) / seconds.sum(), 1),
        "median_samples": float(np.median([r["samples"] for r in rows])),
    }


def minimal_rows(trials: int, seed: int) -> list[dict]:
    """Noiseless 9r/3s and 6r/4s: solvers.calibrate vs solvers.api.solve_network on the same networks."""
    out = []
    for m, n in ((9, 3), (6, 4)):
        errs = {"calibrate": [], "api.solve_network": []}
        secs = {"calibrate": [], "api.solve_network": []}
        for t in range(trials):
            net = random_network(m, n, np.random.default_rng(seed + 100_000 + t))
            F = net.measurements()
            t0 = time.perf_counter()
            res = calibrate(F, seed=t)
            secs["calibrate"].append(time.perf_counter() - t0)
            e = calibration_errors(res, net) if np.isfinite(res.receivers).all() else None
            errs["calibrate"].append(max(e.position, e.offset) if e else np.inf)
            t0 = time.perf_counter()
            cands = api.solve_network(F)
            secs["api.solve_network"].append(time.perf_counter() - t0)
            e = calibration_errors(cands[0], net) if cands else None
            errs["api.solve_network"].append(max(e.position, e.offset) if e else np.inf)
        for name in errs:
            log = np.log10(np.maximum(np.array(errs[name]), 1e-17))
            out.append({"shape": f"{m}r/{n}s", "method": name, "trials": trials,
                        "median_log10_err": round(float(np.median(log)), 2),
                        "p90_log10_err": round(float(np.percentile(log, 90)), 2),
                        "failures": round(float(np.mean(np.array(errs[name]) > 1e-6)), 3),
                        "median_seconds": round(float(np.median(secs[name])), 4)})
    return out


def markdown(rows: list[dict], minimal: list[dict]) -> str:
    """tables/calibration.md: per sigma, success % (median seconds) per shape x (missing, outliers),
    then outliers flagged and the noiseless minimal rows."""
    out = []
    cols = [(mi, ou) for mi in MISSING for ou in OUTLIERS]
    key = {(r["shape"], float(r["sigma"]), float(r["missing"]), float(r["outliers"])): r for r in rows}
    shapes = list(dict.fromkeys(r["shape"] for r in rows))
    head = "| shape | " + " | ".join(f"{100 * mi:.0f} % / {100 * ou:.0f} %" for mi, ou in cols) + " |"
    for sigma in SIGMAS:
        out.append(f"\nsigma = {sigma:g}: success % (median s per call), columns missing / outliers\n")
        out += [head, "|---|" + "---|" * len(cols)]
        for shape in shapes:
            cells = []
            for mi, ou in cols:
                r = key.get((shape, sigma, mi, ou))
                cells.append(f"{100 * float(r['success']):.0f} ({float(r['median_seconds']):.2f})" if r else "")
            out.append(f"| {shape} | " + " | ".join(cells) + " |")
    flagged = [float(r["outliers_flagged"]) for r in rows if r["outliers_flagged"] not in ("", None)]
    out.append(f"\nOutliers flagged over all cells with outliers: min {100 * min(flagged):.0f} %, median "
               f"{100 * float(np.median(flagged)):.0f} %.\n")
    out += ["| shape | method | trials | median log10 err | p90 log10 err | failures | median s |", "|---|---|---|---|---|---|---|"]
    for r in minimal:
        out.append(f"| {r['shape']} | {r['method']} | {r['trials']} | {r['median_log10_err']} | {r['p90_log10_err']} | "
                   f"{r['failures']} | {r['median_seconds']} |")
    return "\n".join(out) + "\n"


def _read(path):
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def _write(path, rows):
    with open(path, "w", newline="") as handle:
        w = csv.DictWriter(handle, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=20, help="trials per cell (default 20)")
    ap.add_argument("--minimal-trials", type=int, default=100, help="trials of the noiseless 9r/3s and 6r/4s rows")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="5 trials per cell, 20 minimal trials, into tables/quick/")
    ap.add_argument("--markdown-only", action="store_true", help="only rewrite calibration.md from the CSVs")
    args = ap.parse_args(argv)
    trials = 5 if args.quick else args.trials
    minimal_trials = 20 if args.quick else args.minimal_trials
    out_dir = os.path.join(ROOT, "tables", "quick") if args.quick else os.path.join(ROOT, "tables")
    os.makedirs(out_dir, exist_ok=True)
    if args.markdown_only:
        with open(os.path.join(out_dir, "calibration.md"), "w") as handle:
            handle.write(markdown(_read(os.path.join(out_dir, "calibration.csv")),
                                  _read(os.path.join(out_dir, "calibration_minimal.csv"))))
        return 0

    t_start = time.perf_counter()
    rows = []
    for (m, n), sigma, missing, outliers in itertools.product(SHAPES, SIGMAS, MISSING, OUTLIERS):
        cell = [trial(m, n, sigma, missing, outliers, args.seed + 1000 * t) for t in range(trials)]
        row = {"shape": f"{m}r/{n}s", "sigma": sigma, "missing": missing, "outliers": outliers, **summarise(cell)}
        rows.append(row)
        print(f"{row['shape']:>7} sigma {sigma:<6g} missing {missing:<4g} outliers {outliers:<5g} success {row['success']:.2f} "
              f"pos {row['median_pos_err']:.2g}/{row['p90_pos_err']:.2g} (ref {row['median_ref_pos_err']:.2g}) flagged "
              f"{row['outliers_flagged']} {row['median_seconds']:.2f} s", flush=True)
    _write(os.path.join(out_dir, "calibration.csv"), rows)
    minimal = minimal_rows(minimal_trials, args.seed)
    _write(os.path.join(out_dir, "calibration_minimal.csv"), minimal)
    for r in minimal:
        print(r)

    commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    dirty = bool(subprocess.run(["git", "status", "--porcelain"], cwd=ROOT, capture_output=True, text=True).stdout.strip())
    meta = {
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "commit": commit, "worktree_dirty": dirty, "trials_per_cell": trials, "minimal_trials": minimal_trials,
        "seed": args.seed, "seconds": round(time.perf_counter() - t_start, 1),
        "networks": "solvers.synthetic.random_network: positions N(0, 10^2), offsets N(0, 1); Gaussian noise sigma",
        "corruption": "solvers.synthetic.corrupt_measurements: random NaN keeping >= 3 per receiver and >= 4 per "
                      "transmitter; outliers = fraction of measured entries, uniform in [min F, max F]",
        "success": "all nodes placed and position and offset errors <= 3 x those of least squares from the ground "
                   "truth on the true inliers, + 1e-9",
        "calibrate": "solvers.calibrate.calibrate(F, sigma=true sigma, seed=trial seed), default options",
        "versions": {"python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__},
        "threads": {k: os.environ.get(k) for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")},
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
    }
    with open(os.path.join(out_dir, "calibration.md"), "w") as handle:
        handle.write(markdown(_read(os.path.join(out_dir, "calibration.csv")), _read(os.path.join(out_dir, "calibration_minimal.csv"))))
    with open(os.path.join(out_dir, "calibration.meta.json"), "w") as handle:
        json.dump(meta, handle, indent=2)
        handle.write("\n")
    print(f"wrote {out_dir}/calibration.csv, calibration_minimal.csv, calibration.md, calibration.meta.json "
          f"in {meta['seconds']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
