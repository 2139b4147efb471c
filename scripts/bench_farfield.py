"""Benchmark `calibrate --dim 3` on a far-field microphone array: the case that did not scale (issue 45).

The network (seeded, `farfield_network`): 48 receivers uniform in a 25 cm cube centred at the origin,
540 sources at 3.5-4 m from the centre in directions uniform on the sphere, emission offsets uniform
in [0, 1] m; F[i, j] = |r_i - s_j| + o_j quantized to whole samples at 48 kHz (speed of sound 343 m/s:
a step of 7.15 mm, rounding noise of std 2.06 mm), then a few gross errors (a wrong GCC-PHAT peak: an
entry moved by a whole number of samples, uniform in +-(10..60) samples, i.e. 7-43 cm).

`--array tetra`: the simulated analogue of a real array instead (issue 52, `solvers.synthetic.array_network`):
48 microphones on the six edges of a tetrahedron (radius 0.15 m), sources on elevation cones within +-16 deg
(`--cones`, `--per-cone`) at 3.5-4.2 m, TDOAs in quarter samples at 48 kHz (rounding std 0.52 mm), 0.3 mm of
model error, 1.5 % gross errors; the Cramer-Rao bound at the quarter-sample rounding noise.

Per run it prints (one line, and a CSV row with --csv): sources, seconds, status, the receivers' rms
error after rigid alignment, the Cramer-Rao bound of that rms (at the rounding noise, on the entries
without gross error), their ratio, gross errors rejected / good entries rejected, and the largest
standardised node error (|error| / reported std). Run facts go to stdout only.

Usage: python scripts/bench_farfield.py [--sources 540] [--every 1] [--gross 8] [--seed 0] [--sigma] [--oriented]
       python scripts/bench_farfield.py --array tetra [--per-cone 180] [--cones=-12,2,14] [--seed 0] [--sigma]
       --every 17 takes every 17th source (the 32-source subset of the issue); --sigma gives the
       rounding noise's std as sigma (default: sigma estimated); --oriented says the rows are receivers
       (CalibrationOptions.orientation_given, the CLI's --oriented).
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from solvers.synthetic import Network  # noqa: E402

SPEED_OF_SOUND = 343.0
SAMPLE_RATE = 48_000.0
#: one sample in metres, and the std of rounding to it (uniform on one step)
STEP = SPEED_OF_SOUND / SAMPLE_RATE
ROUNDING_SIGMA = STEP / np.sqrt(12.0)


def farfield_network(m: int = 48, n: int = 540, gross: int = 8, seed: int = 0, *, every: int = 1,
                     cube: float = 0.25, distance: tuple[float, float] = (3.5, 4.0)):
    """(network, F, gross mask) of the far-field benchmark: see the module docstring.

    Draws, in order: receivers, source directions, source distances, offsets (stream `seed`); then,
    after keeping every `every`-th source, the gross entries, their shifts in samples, their signs
    (stream (seed, 1)): the subset of a network is the same network's sources.
    """
    rng = np.random.default_rng(seed)
    receivers = rng.uniform(-cube / 2, cube / 2, (m, 3))
    u = rng.standard_normal((n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    transmitters = u * rng.uniform(*distance, n)[:, None]
    offsets = rng.uniform(0.0, 1.0, n)
    keep = np.arange(0, n, every)
    net = Network(receivers, transmitters[keep], offsets[keep])
    F = np.round(net.measurements() / STEP) * STEP
    m, n = F.shape
    rng = np.random.default_rng([seed, 1])
    bad = np.zeros((m, n), bool)
    k = rng.choice(m * n, gross, replace=False)
    shift = rng.integers(10, 61, gross) * rng.choice([-1.0, 1.0], gross) * STEP
    F.flat[k] += shift
    bad.flat[k] = True
    return net, F, bad


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--receivers", type=int, default=48)
    ap.add_argument("--sources", type=int, default=540)
    ap.add_argument("--every", type=int, default=1, help="keep every k-th source (after generating all)")
    ap.add_argument("--gross", type=int, default=8, help="gross errors among the entries (after --every)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sigma", action="store_true", help="give the rounding noise's std as sigma")
    ap.add_argument("--oriented", action="store_true", help="say the rows are receivers (orientation_given)")
    ap.add_argument("--array", choices=("cube", "tetra"), default="cube", help="the receivers and sources (see above)")
    ap.add_argument("--per-cone", type=int, default=180, help="--array tetra: sources per elevation cone")
    ap.add_argument("--cones", default="-12,2,14", help="--array tetra: cone elevations in degrees (--cones=-12,14)")
    ap.add_argument("--csv", help="append a row to this CSV")
    args = ap.parse_args()
    import logging

    logging.basicConfig(level=logging.INFO, format="%(relativeCreated)8.0f ms %(message)s", stream=sys.stderr)

    from solvers.calibration import CalibrationOptions, calibrate
    from solvers.metrics import align_rigid, receiver_cramer_rao_rms, standardised_node_errors

    from solvers.synthetic import array_network

    rounding = ROUNDING_SIGMA
    if args.array == "tetra":
        cones = tuple(float(c) for c in args.cones.split(","))
        net, F, bad = array_network(np.random.default_rng(args.seed), cones=cones, per_cone=args.per_cone)
        rounding = 0.25 * ROUNDING_SIGMA
    else:
        net, F, bad = farfield_network(args.receivers, args.sources, args.gross, args.seed, every=args.every)
    sigma = rounding if args.sigma else None
    t = time.perf_counter()
    res = calibrate(F, sigma, dim=3, seed=args.seed, options=CalibrationOptions(orientation_given=args.oriented))
    sec = time.perf_counter() - t
    crb = receiver_cramer_rao_rms(net.receivers, net.transmitters, ~bad, rounding)
    placed = np.isfinite(res.receivers[:, 0])
    if placed.all():
        T = align_rigid(res.receivers, net.receivers)
        err = float(np.sqrt(np.mean(np.sum((T.apply(res.receivers) - net.receivers) ** 2, axis=1))))
    else:
        err = float("nan")
    z = standardised_node_errors(res, net)
    z_max = float(z.max()) if z.size else float("nan")
    measured = np.isfinite(F)
    gross_rej = int((bad & ~res.inliers).sum())
    good_rej = int((measured & ~bad & ~res.inliers).sum())
    row = dict(array=args.array, receivers=F.shape[0], sources=F.shape[1], gross=int(bad.sum()), sigma="given" if args.sigma else
               "estimated", oriented=args.oriented, seed=args.seed, seconds=round(sec, 1), status=res.status, rx_rms_mm=round(1e3 * err, 3),
               crb_mm=round(1e3 * crb, 3), ratio=round(err / crb, 2), gross_rejected=gross_rej,
               good_rejected=good_rej, max_std_err=round(z_max, 2))
    print(" ".join(f"{k}={v}" for k, v in row.items()))
    print(res.message)
    for w in res.warnings:
        print("  -", w)
    if args.csv:
        import csv

        new = not os.path.exists(args.csv)
        with open(args.csv, "a", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(row))
            if new:
                w.writeheader()
            w.writerow(row)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
