"""Reproduce Figs. 1 and 2 of the paper: error histograms (clean data) and median error vs noise.

Fig. 1 (``tables/figures/fig1_histograms.{png,pdf,csv}``): histograms of the log10 relative
position and offset errors after Levenberg-Marquardt, initialised by the solver ("ours") and at
random ("rand"), for 9r/3s and 6r/4s, on the same noiseless trials as Table 4 (shared cache).
Fig. 2 (``tables/figures/fig2_noise.{png,pdf,csv}``): median relative errors against the noise
standard deviation sigma, with the interquartile range and LM-from-ground-truth as reference.
Provenance goes to the "fig1"/"fig2" sections of ``tables/experiments_provenance.json``. Without
a working ``solvers.api`` only the random baseline is drawn and the script says so.

Usage: python scripts/make_figures.py [--quick] [--trials N] [--sweep-trials N] [--sigmas 1e-6,1e-5,...]
       [--jobs 2] [--seed 0] [--no-progress]
"""
from __future__ import annotations

import os

for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from solvers import experiments as ex  # noqa: E402  (after the thread settings)


def _sigmas(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"--sigmas must be comma-separated numbers, got {text!r}") from None
    if not values or any(v <= 0 for v in values):
        raise argparse.ArgumentTypeError("--sigmas must be positive (the x-axis is logarithmic)")
    return values


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the quick plan (100 trials; 5 noise levels x 50)")
    parser.add_argument("--trials", type=int, help="noiseless trials per histogram (default 1000)")
    parser.add_argument("--sweep-trials", type=int, help="trials per noise level (default 100)")
    parser.add_argument("--sigmas", type=_sigmas, help="noise levels (default 11 log-spaced in 1e-6..1e-1)")
    parser.add_argument("--jobs", type=int, default=ex.DEFAULT_JOBS, help="worker processes (default 2)")
    parser.add_argument("--seed", type=int, default=ex.DEFAULT_SEED, help="base seed; trial t uses seed + t")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars on stderr")
    args = parser.parse_args(argv)
    plan = ex.QUICK if args.quick else ex.FULL

    available, reason = ex.solver_status()
    start = time.perf_counter()
    noise, paths = ex.build_figures(
        args.trials or plan.table_trials, args.sigmas or plan.sigmas, args.sweep_trials or plan.sweep_trials,
        seed=args.seed, jobs=args.jobs, progress=not args.no_progress, mode=plan.mode,
    )
    print(ex.summarise_noise_text(noise))
    print(f"Wall time: {time.perf_counter() - start:.1f} s; wrote " + ", ".join(
        str(Path(p).relative_to(ROOT)) for v in paths.values() for p in v))
    if not available:
        print(f"MISSING: solver-initialised histograms and curves ('ours'), {reason}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
