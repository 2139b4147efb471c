"""Why does solvers.calibrate fail on a benchmark cell? Classifies every failed trial.

Same trials as scripts/bench_calibration.py (same seeds, networks, corruption, reference). A failed
trial (not a success by the benchmark's definition) is put in the first class that applies:

  d  unidentifiable: a node has fewer true inliers than it needs (a receiver < 3, a transmitter < 4: its
     position has several exact solutions and only the reference, started at the truth, picks the right
     one), or the network has fewer true inliers than unknowns, or the returned calibration has a
     robust (MSAC, 3 sigma) cost on all measured entries at most that of the reference (least squares
     from the ground truth on the true inliers) + 1 sigma^2: the data prefer (or cannot tell apart) a
     wrong answer, so no method can be expected to succeed
  a  no hypothesis at all
  b  hypotheses, but none within 5 % relative position error of the truth
  c  the right basin was found (a hypothesis within 5 %), but the wrong inlier set / local minimum won

Usage: python scripts/diagnose_calibration.py 8 5 0.01 0.3 0.05 [--trials 20] [--seed 0]
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

import bench_calibration as bench  # noqa: E402
import importlib  # noqa: E402

cal = importlib.import_module("solvers.calibrate")  # the module (solvers.calibrate is also the function)
from solvers.metrics import align_rigid  # noqa: E402

NEAR = 0.05


def _partial_error(R, S, net) -> float:
    """Relative position error over the placed nodes (inf with fewer than 3 placed)."""
    X = np.vstack([R, S])
    Y = np.vstack([net.receivers, net.transmitters])
    ok = np.isfinite(X[:, 0])
    if ok.sum() < 3:
        return np.inf
    aligned = align_rigid(X[ok], Y[ok]).apply(X[ok])
    return float(np.linalg.norm(aligned - Y[ok]) / np.linalg.norm(Y - Y.mean(axis=0)))


def _msac(F, R, S, O, t) -> float:
    E = cal._residual_matrix(F, R, S, O)[np.isfinite(F)]
    return float(np.sum(np.minimum(np.nan_to_num(E, nan=np.inf) ** 2, t * t)))


def classify(m, n, sigma, missing, outliers, seed, options=None) -> tuple[str, dict]:
    """(class, details) of one benchmark trial; class "ok" for a success."""
    recorded: list = []
    # (_hypotheses_from_random_starts: the generator before sub-networks, to classify older commits)
    originals = {name: getattr(cal, name) for name in
                 ("_hypotheses_from_block", "_hypotheses_from_subnetwork", "_hypotheses_from_random_starts")
                 if hasattr(cal, name)}

    def recording(fn):
        def wrapper(*args, **kwargs):
            out = fn(*args, **kwargs)
            recorded.extend(out)
            return out

        return wrapper

    for name, fn in originals.items():
        setattr(cal, name, recording(fn))
    try:
        net, F, bad, ref = bench.trial_data(m, n, sigma, missing, outliers, seed)
        res = cal.calibrate(F, sigma=sigma, seed=seed, options=options)
    finally:
        for name, fn in originals.items():
            setattr(cal, name, fn)
    success, err, ref_err = bench.judge(res, net, ref)
    t = 3.0 * sigma
    cost_ref = _msac(F, ref.R, ref.S, ref.O, t)
    cost_res = _msac(F, res.receivers, res.transmitters, res.offsets, t) if np.isfinite(res.receivers).any() else np.inf
    hyp_err = min((_partial_error(h.R, h.S, net) for h in recorded), default=np.inf)
    details = {"seed": seed, "pos": err.position if err else np.inf, "ref_pos": ref_err.position, "cost_res/s2": cost_res / sigma**2,
               "cost_ref/s2": cost_ref / sigma**2, "hypotheses": len(recorded), "best_hyp_err": hyp_err,
               "samples": res.samples, "solver": res.solver, "seconds": round(res.seconds, 2),
               "n_bad": int(bad.sum()), "measured": int(np.isfinite(F).sum()), "unknowns": 2 * m + 3 * n - 3}
    if success:
        return "ok", details
    good = np.isfinite(F) & ~bad
    details["underdetermined"] = int((good.sum(axis=1) < cal.MIN_RECEIVER_MEASUREMENTS).sum()
                                     + (good.sum(axis=0) < cal.MIN_TRANSMITTER_MEASUREMENTS).sum()
                                     + (good.sum() < 2 * m + 3 * n - 3))
    if details["underdetermined"] or cost_res <= cost_ref + sigma**2:
        return "d", details
    if not recorded:
        return "a", details
    if hyp_err > NEAR:
        return "b", details
    return "c", details


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("m", type=int)
    ap.add_argument("n", type=int)
    ap.add_argument("sigma", type=float)
    ap.add_argument("missing", type=float)
    ap.add_argument("outliers", type=float)
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--verbose", action="store_true")
    ap.add_argument("--option", action="append", default=[], metavar="NAME=VALUE",
                    help="a CalibrationOptions field (numbers only), e.g. expensive_samples=0")
    args = ap.parse_args(argv)
    fields = {k: float(v) if "." in v or "e" in v else int(v) for k, v in (o.split("=", 1) for o in args.option)}
    options = cal.CalibrationOptions(**fields)
    counts: dict[str, int] = {}
    seconds = []
    for k in range(args.trials):
        label, d = classify(args.m, args.n, args.sigma, args.missing, args.outliers, args.seed + 1000 * k, options)
        counts[label] = counts.get(label, 0) + 1
        seconds.append(d["seconds"])
        if args.verbose or label != "ok":
            print(label, {k: (float(f"{v:.3g}") if isinstance(v, float) else v) for k, v in d.items()}, flush=True)
    print(f"{args.m}r/{args.n}s sigma {args.sigma:g} missing {args.missing:g} outliers {args.outliers:g}: "
          f"{counts} median {np.median(seconds):.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
