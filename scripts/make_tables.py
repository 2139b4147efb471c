"""Reproduce Tables 2 and 3 of the paper (complexity |B| of TDOA formulations) and search beyond them.

Computes (or reads from the user cache, ``analysis.sweeps.paths.cache_dir('complexity')``) every formulation chosen by
:func:`analysis.sweeps.tables.plan_tables`, writes ``tables/table2.{csv,md,tex}``, ``tables/table3.{csv,md,tex}``,
``tables/section32.csv``, ``tables/formulations.csv`` and ``tables/provenance.json``, and prints every
number beside the paper's. A quick run or a run over some cells writes to the user cache's ``tables-partial/``
unless --out-dir is given, so the full tables are never overwritten by a partial run.

Usage: python scripts/make_tables.py [--quick] [--jobs 2] [--no-cache] [--cells 6/4,5/5]
       [--timeout 300] [--max-cells 60000000] [--out-dir DIR] [--dask ADDRESS|local] [--no-progress]
"""
from __future__ import annotations

import os

# one BLAS thread: F4 matrices are small, and worker processes must not oversubscribe the CPUs
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from analysis.sweeps.complexity import DEFAULT_CELLS  # noqa: E402  (after the thread settings)
from analysis.sweeps.executors import make_executor  # noqa: E402
from analysis.sweeps.tables import make_tables  # noqa: E402


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="small budget: Table 2 and two formulations per focus cell of Table 3 (a few minutes)")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    parser.add_argument("--no-cache", action="store_true", help="recompute everything (the cache is still written)")
    parser.add_argument("--cells", help="only these Table 3 cells, e.g. 6/4,5/5 (default: all)")
    parser.add_argument("--timeout", type=float, default=300.0, help="wall-clock seconds per formulation (default 300)")
    parser.add_argument("--max-cells", type=int, default=DEFAULT_CELLS,
                        help=f"cap on rows*cols of an F4 matrix (default {DEFAULT_CELLS})")
    parser.add_argument("--out-dir", type=Path, help="output directory (default tables/ for a full run)")
    parser.add_argument("--dask", metavar="ADDRESS",
                        help="compute on a Dask scheduler at ADDRESS, or 'local' for a LocalCluster (--jobs threads)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        summary = make_tables(quick=args.quick, jobs=args.jobs, use_cache=not args.no_cache, cells=args.cells,
                              out_dir=args.out_dir, progress=not args.no_progress, timeout=args.timeout,
                              max_matrix_cells=args.max_cells, executor=make_executor(args.dask, args.jobs))
    except ValueError as e:  # ExecutorError (a bad --dask address) is a ValueError
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(summary.report())
    return 0


if __name__ == "__main__":
    sys.exit(main())
