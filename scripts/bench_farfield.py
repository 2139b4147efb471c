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
       python scripts/bench_farfield.py --table   (tables/farfield_tetra.*: the tetrahedral array, seeds 0-4)
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


#: The committed per-seed table of the tetrahedral array (`--table`): (case, cones, sources per cone).
TETRA_CASES = (("three cones", (-12.0, 2.0, 14.0), 180), ("three cones, every 6th", (-12.0, 2.0, 14.0), 30),
               ("two cones", (-12.0, 14.0), 60))
TETRA_SEEDS = (0, 1, 2, 3, 4)
TABLE_FIELDS = ("case", "sources", "seed", "status", "rx_rms_mm", "crb_mm", "ratio", "oracle_ratio",
                "gross_rejected", "good_rejected", "max_err_over_std", "rx_z_rms")


def oracle_receivers(net, F, use, delays: bool = False) -> np.ndarray:
    """The receivers of the plane-wave least-squares fit on the entries `use` (the true inliers) started at the
    truth: what the calibration would give had it found every gross error and no good entry, in the same model
    (the reference that separates what the data allow from what the pipeline loses); delays: the model with a
    delay per receiver (as the calibration chose it)."""
    from solvers.calibration.adjust import levenberg_marquardt

    c = net.receivers.mean(axis=0)
    S = net.transmitters - c
    ranges = np.linalg.norm(S, axis=1)
    theta = (net.receivers - c, S / ranges[:, None], 1.0 / ranges, net.offsets + ranges)
    theta = theta + (np.zeros(len(net.receivers)),) if delays else theta
    return levenberg_marquardt(F, use, theta, max_iter=50)[0][0]


def _rms_after_alignment(est: np.ndarray, truth: np.ndarray) -> float:
    from solvers.metrics import align_rigid

    if not np.isfinite(est).all():
        return float("nan")
    T = align_rigid(est, truth)
    return float(np.sqrt(np.mean(np.sum((T.apply(est) - truth) ** 2, axis=1))))


def evaluate(net, F, bad, rounding: float, seed: int, given_sigma: bool = False, oriented: bool = False):
    """(row, result, CPU seconds) of one call on the network `net` measured as F (gross entries `bad`),
    against the Cramer-Rao bound at the noise `rounding` and the oracle (`oracle_receivers`)."""
    from dataclasses import replace

    from solvers.calibration import CalibrationOptions, calibrate
    from solvers.metrics import receiver_cramer_rao_rms, standardised_node_errors

    cpu = time.process_time()
    res = calibrate(F, rounding if given_sigma else None, dim=3, seed=seed,
                    options=CalibrationOptions(orientation_given=oriented))
    cpu = time.process_time() - cpu
    crb = receiver_cramer_rao_rms(net.receivers, net.transmitters, ~bad, rounding)
    err = _rms_after_alignment(res.receivers, net.receivers)
    oracle = _rms_after_alignment(oracle_receivers(net, F, np.isfinite(F) & ~bad, res.receiver_delays is not None),
                                  net.receivers)
    z = standardised_node_errors(res, net)
    z_r = standardised_node_errors(replace(res, transmitter_std=np.full(F.shape[1], np.nan)), net)
    measured = np.isfinite(F)
    row = dict(sources=F.shape[1], seed=seed, status=res.status, rx_rms_mm=round(1e3 * err, 3),
               crb_mm=round(1e3 * crb, 3), ratio=round(err / crb, 2), oracle_ratio=round(oracle / crb, 2),
               gross_rejected=f"{int((bad & ~res.inliers).sum())}/{int(bad.sum())}",
               good_rejected=int((measured & ~bad & ~res.inliers).sum()),
               max_err_over_std=round(float(z.max()), 2) if z.size else float("nan"),
               rx_z_rms=round(float(np.sqrt(np.mean(z_r**2))), 2) if z_r.size else float("nan"))
    return row, res, cpu


def run_tetra(cones, per_cone: int, seed: int, given_sigma: bool = False, oriented: bool = False):
    """(row, result, CPU seconds) of one tetrahedral-array call (see the module docstring)."""
    from solvers.synthetic import array_network

    net, F, bad = array_network(np.random.default_rng(seed), cones=tuple(cones), per_cone=per_cone)
    return evaluate(net, F, bad, 0.25 * ROUNDING_SIGMA, seed, given_sigma, oriented)


def write_table(out_dir: str) -> None:
    """tables/farfield_tetra.{csv,md} (TETRA_CASES x TETRA_SEEDS; byte-stable) and .meta.json (CPU seconds,
    load, date: the run's facts)."""
    import csv
    import datetime
    import json
    import platform

    rows, meta = [], {}
    for case, cones, per_cone in TETRA_CASES:
        for seed in TETRA_SEEDS:
            row, _, cpu = run_tetra(cones, per_cone, seed)
            rows.append(dict(case=case, **row))
            meta[f"{case}, seed {seed}"] = round(cpu, 2)
            print(" ".join(f"{k}={v}" for k, v in rows[-1].items()), f"cpu={cpu:.1f}s", flush=True)
    with open(os.path.join(out_dir, "farfield_tetra.csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=TABLE_FIELDS, lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
    md = ["**The simulated tetrahedral array** (`scripts/bench_farfield.py --table`; `synthetic.array_network`: 48 "
          "microphones on a tetrahedron's edges, radius 0.15 m, sources 3.5-4.2 m away on elevation cones, quarter "
          "samples at 48 kHz, 0.3 mm model error, 1.5 % gross errors; sigma estimated). rx_rms_mm: the receivers' rms "
          "error after a rigid alignment; crb_mm: its Cramer-Rao bound at the rounding noise; ratio = rx_rms / crb; "
          "oracle_ratio: the same for least squares on the true inliers started at the truth (what the data allow "
          "in this model: with a delay per receiver where the calibration fitted them, which it does when the residuals "
          "depend on the direction of arrival); max_err_over_std: the largest node error over its reported std (result's gauge); "
          "rx_z_rms: the receivers' rms of error / reported std (1 when the std is right).", "",
          "| " + " | ".join(TABLE_FIELDS) + " |", "|" + "---|" * len(TABLE_FIELDS)]
    md += ["| " + " | ".join(str(r[k]) for k in TABLE_FIELDS) + " |" for r in rows]
    with open(os.path.join(out_dir, "farfield_tetra.md"), "w") as fh:
        fh.write("\n".join(md) + "\n")
    info = dict(date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
                load_average=[round(x, 2) for x in os.getloadavg()], cpu_seconds_per_call=meta,
                versions=dict(python=platform.python_version(), numpy=np.__version__),
                threads={k: os.environ.get(k) for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")})
    with open(os.path.join(out_dir, "farfield_tetra.meta.json"), "w") as fh:
        json.dump(info, fh, indent=2)
        fh.write("\n")


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
    ap.add_argument("--table", action="store_true", help="write tables/farfield_tetra.{csv,md,meta.json} (seeds 0-4)")
    args = ap.parse_args()
    if args.table:
        write_table(os.path.join(ROOT, "tables"))
        return 0
    import logging

    logging.basicConfig(level=logging.INFO, format="%(relativeCreated)8.0f ms %(message)s", stream=sys.stderr)

    t = time.perf_counter()
    if args.array == "tetra":
        row, res, cpu = run_tetra([float(c) for c in args.cones.split(",")], args.per_cone, args.seed, args.sigma,
                                  args.oriented)
    else:
        net, F, bad = farfield_network(args.receivers, args.sources, args.gross, args.seed, every=args.every)
        row, res, cpu = evaluate(net, F, bad, ROUNDING_SIGMA, args.seed, args.sigma, args.oriented)
    row = dict(array=args.array, sigma="given" if args.sigma else "estimated", oriented=args.oriented, **row,
               cpu_seconds=round(cpu, 1), wall_seconds=round(time.perf_counter() - t, 1))
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
