"""Statuses where real data push them (issue 45): how often `calibrate --dim 3` ends "ok", and whether an
"ok" is ever wrong, on simulated rooms with gross errors.

Cases (solvers.synthetic.room_network in an 8 x 6 x 3 m room, noise sigma 1 cm, gross errors by
corrupt_measurements, the networks of scripts/bench_calibrate.py's `network` for seeds 0, 1, ...):
  est5   20r/12s, 5 % gross errors, sigma estimated   (target: "ok" in >= 80 %)
  given10 16r/10s, 10 % gross errors, sigma given     (target: no "unconverged", no "ok" node > 5 std off)

Prints one line per network (status, gross errors rejected, good entries rejected, the largest
|error| / reported std, the first clause of the message) and a summary per case.

Usage: python scripts/bench_statuses.py [--case est5|given10] [--networks 10] [--seed0 0]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "scripts"))

import numpy as np  # noqa: E402

CASES = {"est5": ((20, 12), 0.05, False), "given10": ((16, 10), 0.10, True)}
SIGMA = 1e-2


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", choices=sorted(CASES), default="est5")
    ap.add_argument("--networks", type=int, default=10)
    ap.add_argument("--seed0", type=int, default=0)
    args = ap.parse_args()

    from bench_calibrate import network

    from solvers.calibration import calibrate
    from solvers.metrics import standardised_node_errors

    (m, n), gross, given = CASES[args.case]
    counts: dict[str, int] = {}
    ok_wrong = 0
    for seed in range(args.seed0, args.seed0 + args.networks):
        net, F, bad = network(m, n, SIGMA, 0.0, gross, seed, 3)
        res = calibrate(F, sigma=SIGMA if given else None, dim=3, seed=seed)
        z = standardised_node_errors(res, net)
        zmax = float(z.max()) if z.size else float("nan")
        counts[res.status] = counts.get(res.status, 0) + 1
        ok_wrong += res.status == "ok" and zmax > 5
        measured = np.isfinite(F)
        print(f"{args.case} seed {seed}: {res.status:12s} gross rejected {int((bad & ~res.inliers).sum())}/{int(bad.sum())}, "
              f"good rejected {int((measured & ~bad & ~res.inliers).sum())}, max |err|/std {zmax:.2f}, "
              f"{res.seconds:.1f} s - {res.message.split(' - ', 1)[-1][:150]}", flush=True)
    total = sum(counts.values())
    print(f"{args.case}: {', '.join(f'{k} {v}' for k, v in sorted(counts.items()))} of {total}; ok share "
          f"{counts.get('ok', 0) / max(total, 1):.2f}; ok with a node > 5 std off: {ok_wrong}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
