"""Exhaustive search of the Table 3 cells: every relabeling-symmetry class within a stated bound.

Enumerates the classes of each cell (:func:`analysis.sweeps.search.enumerate_cell`), computes every class on
two primes (cached in the user cache's ``search/``, so an interrupted run resumes), and writes
``tables/search.{csv,md}``, ``tables/search_candidates.csv`` (every class and its decision),
``tables/search_capped.csv`` (classes stopped by a cap or left open, with the cap) and
``tables/search.meta.json`` (provenance). Progress goes to stderr.

Usage: python scripts/search_formulations.py [--cells 6/4,5/5] [--count-only] [--jobs 1]
       [--dask ADDRESS|local] [--chunk-size 4] [--timeout 60] [--max-cells 20000000] [--max-memory 2G]
       [--subset-limit 3000] [--excess 2] [--msolve auto|none|PATH] [--msolve-timeout 1800] [--no-cache]
       [--out-dir DIR] [--no-progress]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

# Every class is computed in a spawned worker that sets one BLAS thread itself (analysis.sweeps.complexity), so
# this process needs no thread settings before numpy is imported.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from analysis.sweeps.executors import ExecutorError, make_executor  # noqa: E402
from analysis.sweeps.search import SearchBound, SearchLimits, cached_cell, run_search  # noqa: E402
from analysis.sweeps.tables import parse_cells  # noqa: E402
from solvers.cli.common import _memory_size  # noqa: E402  (the CLI's --max-memory parser)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", help="only these Table 3 cells, e.g. 6/4,5/5 (default: all 24)")
    parser.add_argument("--count-only", action="store_true",
                        help="enumerate the classes of each cell and print their numbers; compute nothing")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    parser.add_argument("--dask", metavar="ADDRESS",
                        help="run the tasks on a Dask scheduler at ADDRESS, or 'local' for a LocalCluster")
    parser.add_argument("--chunk-size", type=int, default=4, help="classes per Dask task (default 4)")
    parser.add_argument("--timeout", type=float, default=SearchLimits.timeout,
                        help=f"wall-clock seconds per class (default {SearchLimits.timeout:g})")
    parser.add_argument("--max-cells", type=int, default=SearchLimits.max_matrix_cells,
                        help=f"cap on rows*cols of an F4 matrix (default {SearchLimits.max_matrix_cells})")
    parser.add_argument("--max-memory", type=_memory_size, default="2G", help="cap on one F4 matrix's working memory (default 2G)")
    parser.add_argument("--subset-limit", type=int, default=SearchBound.subset_limit,
                        help="enumerate k-subsets of the minors while C(M, k) <= this (default "
                        f"{SearchBound.subset_limit})")
    parser.add_argument("--excess", type=int, default=SearchBound.excess,
                        help=f"over-determined classes: up to N + this many equations (default {SearchBound.excess})")
    parser.add_argument("--msolve", default="auto", metavar="auto|none|PATH",
                        help="decide the classes the own engine's caps stop with msolve, run as an external program "
                             "(auto: when an executable is found; default auto)")
    parser.add_argument("--msolve-timeout", type=float, default=1800.0,
                        help="wall-clock seconds per msolve run (default 1800)")
    parser.add_argument("--no-cache", action="store_true", help="recompute (the cache is still written)")
    parser.add_argument("--out-dir", type=Path,
                        help="output directory (default tables/ for all cells, else the user cache's search-partial/)")
    parser.add_argument("--no-progress", action="store_true", help="no progress on stderr")
    return parser


def _msolve_run(choice: str, timeout: float):
    """The msolve run of ``--msolve`` (None for none, or auto without an executable)."""
    from analysis.engine.msolve import INSTALL_HINT, MsolveRun, find_msolve

    if timeout <= 0:
        raise ValueError("--msolve-timeout must be positive")
    if choice == "none":
        return None
    exe = find_msolve() if choice == "auto" else choice
    if exe is None:
        print(f"search: no msolve executable found; capped classes stay capped ({INSTALL_HINT})", file=sys.stderr)
        return None
    if not Path(exe).is_file():
        raise ValueError(f"--msolve {choice}: no such file")
    return MsolveRun(exe, timeout=timeout)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        cells = parse_cells(args.cells)
        if args.jobs < 1 or args.timeout <= 0 or args.max_cells < 1 or args.subset_limit < 1 or args.excess < 0:
            raise ValueError("--jobs, --timeout, --max-cells and --subset-limit must be positive, --excess >= 0")
        limits = SearchLimits(args.timeout, args.max_cells, args.max_memory)
        bound = SearchBound(args.subset_limit, args.excess)
        executor = make_executor(args.dask, args.jobs, args.chunk_size)
        msolve = _msolve_run(args.msolve, args.msolve_timeout)
    except (ValueError, ExecutorError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.count_only:
        total = 0
        for m, n in cells:
            t0 = time.perf_counter()
            plan = cached_cell(m, n, bound, not args.no_cache)
            total += len(plan.labels)
            print(f"{m}/{n}: k_max {plan.k_max}, {len(plan.labels)} classes, {len(set(plan.computed_as))} distinct "
                  f"reduced ({time.perf_counter() - t0:.1f} s)")
        print(f"total {total} classes")
        return 0
    from analysis.sweeps.paths import cache_dir, default_output_dir

    out_dir = args.out_dir or (default_output_dir() if args.cells is None else cache_dir("search-partial"))
    try:
        summary = run_search(cells, bound, limits, jobs=args.jobs, executor=executor, use_cache=not args.no_cache,
                             progress=not args.no_progress, out_dir=out_dir, msolve=msolve)
    except ExecutorError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    for row in summary.cells:
        print(f"{row['cell']:>4}  paper {row['paper']:>4}  candidates {row['candidates']:>5}  computed "
              f"{row['computed']:>5} (msolve {row['by_msolve']:>3})  capped {row['capped']:>4}  open {row['open']:>3}  complete {row['complete']:>3}  "
              f"best {row['best_degree'] or '-':>4}  {row['best_formulation']}")
    print(f"{summary.computed} classes computed, {summary.cached} from cache; {summary.seconds:.0f} s; wrote "
          + ", ".join(str(p) for p in summary.paths))
    return 0


if __name__ == "__main__":
    sys.exit(main())
