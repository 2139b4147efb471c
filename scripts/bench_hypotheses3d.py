"""3D hypotheses under noise: how often does a block solver start the block's least squares in the right basin?

For each 3D block solver of the calibration pipeline (solvers.calibration.sampling: the stratified solver
on 12r/5s and 10r/5s blocks, the generated 9r/5s offset kernel) and noise sigma 1e-4, 1e-3, 1e-2 m, on
seeded room networks (solvers.synthetic.room_network, 8 x 6 x 3 m, offsets N(0, 1 m)):

  hypothesis   share of samples for which the solver returns a hypothesis
  in_basin     share of samples whose hypothesis, refined by least squares on the block's own entries
               (those of the receivers it places: a 12r/5s block leaves one out), ends within 3x the
               position error of the same least squares started from the truth
               (the block's best estimate; "3 sigma-scaled errors"): the hypothesis is in the right basin
  raw_err_med  median RMS position error of the raw hypothesis after rigid alignment, in metres
  coplanar     share of samples with every receiver in one plane (z = 1.5 m) that return a hypothesis
               (should be 0: such samples are detected, not returned)
Every call is given the true sigma, as the pipeline does when sigma is given (with sigma unknown only
exactly coplanar samples are detected; see solvers.methods.stratified.solve_block).

Writes tables/hypotheses3d.{csv,md} (results only); the microseconds per sample go to the untracked
tables/hypotheses3d.timing.json.

Usage: OPENBLAS_NUM_THREADS=1 python scripts/bench_hypotheses3d.py [--samples 200]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ["TDOA_WORKBENCH_THREADS"] = "1"  # the trackers on one core, as the eigensolves they are compared with

import argparse  # noqa: E402
import csv  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from solvers.calibration.adjustment import robust_refine  # noqa: E402
from solvers.calibration.sampling import available_solvers  # noqa: E402
from solvers.metrics import align_rigid  # noqa: E402
from solvers.synthetic import Network, room_network  # noqa: E402

SIGMAS = (1e-4, 1e-3, 1e-2)


def _rms_error(R, S, net) -> float:
    """RMS position error after rigid alignment over the nodes placed (a trimmed block leaves one out)."""
    X, Y = np.vstack([R, S]), np.vstack([net.receivers, net.transmitters])
    ok = np.all(np.isfinite(X), axis=1)
    if ok.sum() < 4:
        return float("inf")
    return float(np.sqrt(np.mean(np.sum((align_rigid(X[ok], Y[ok]).apply(X[ok]) - Y[ok]) ** 2, axis=1))))


def measure(solver, sigma: float, samples: int) -> tuple[dict, float]:
    got, basin, raw, flat, seconds = 0, 0, [], 0, 0.0
    for seed in range(samples):
        rng = np.random.default_rng(seed)
        net = room_network(solver.m, solver.n, rng)
        F = net.measurements(sigma, rng)
        mask = np.ones(F.shape, bool)
        t0 = time.perf_counter()
        cands = solver.solve(F, sigma)
        seconds += time.perf_counter() - t0
        if cands:
            got += 1
            best = min(cands, key=lambda c: _rms_error(*c[:2], net))
            raw.append(_rms_error(best[0], best[1], net))
            # on the receivers the hypothesis places (a trimmed block leaves one out)
            keep = np.isfinite(best[0][:, 0])
            sub = Network(net.receivers[keep], net.transmitters, net.offsets)
            ref = robust_refine(F[keep], mask[keep], sub.receivers, sub.transmitters, sub.offsets, loss="linear",
                                max_iter=50)
            pol = robust_refine(F[keep], mask[keep], best[0][keep], best[1], best[2], loss="linear", max_iter=50)
            if np.all(np.isfinite(pol.R)) and _rms_error(pol.R, pol.S, sub) <= 3.0 * _rms_error(ref.R, ref.S, sub):
                basin += 1
        R = net.receivers.copy()
        R[:, 2] = 1.5
        flat += bool(solver.solve(Network(R, net.transmitters, net.offsets).measurements(sigma, rng), sigma))
    row = {"solver": solver.label, "block": f"{solver.m}r/{solver.n}s", "sigma": f"{sigma:g}", "samples": samples,
           "hypothesis": round(got / samples, 3), "in_basin": round(basin / samples, 3),
           "raw_err_med": f"{np.median(raw):.3g}" if raw else "", "coplanar": round(flat / samples, 3)}
    return row, 1e6 * seconds / samples


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--samples", type=int, default=200)
    ap.add_argument("--out", default=os.path.join(ROOT, "tables"))
    args = ap.parse_args(argv)
    rows, timing = [], {}
    for solver in available_solvers(3):
        for sigma in SIGMAS:
            row, us = measure(solver, sigma, args.samples)
            rows.append(row)
            timing[f"{solver.label} {sigma:g}"] = round(us, 1)
            print(row, f"{us:.0f} us/sample", file=sys.stderr, flush=True)
    with open(os.path.join(args.out, "hypotheses3d.csv"), "w", newline="") as handle:
        w = csv.DictWriter(handle, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    cols = list(rows[0])
    lines = ["# 3D hypotheses under noise (scripts/bench_hypotheses3d.py)", "",
             "in_basin: share of samples whose hypothesis, refined on its block, ends within 3x the error of the "
             "block's least squares started from the truth; coplanar: hypotheses returned from samples with "
             "coplanar receivers (0 = detected). Columns: see the script's docstring.", "",
             "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(str(r[c]) for c in cols) + " |" for r in rows]
    with open(os.path.join(args.out, "hypotheses3d.md"), "w") as handle:
        handle.write("\n".join(lines) + "\n")
    with open(os.path.join(args.out, "hypotheses3d.timing.json"), "w") as handle:
        json.dump({"us_per_sample": timing, "samples": args.samples}, handle, indent=1)
        handle.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
