"""Root counts of the 3D TDOA minimal cells by `count` (solvers.count), from scratch: tables/monodromy3d.{csv,md}
(results) and tables/monodromy3d.meta.json (the run record: wall times, threads, date, commit).

Per cell (CELLS: 10r/4s in the compaction formulation, every measurement, det H saturated, 13 unknowns; 7r/5s,
6r/6s, 5r/9s in the direct parametrization, one solution per orbit of the gauge frame's 8 reflections): monodromy
on a complete graph of parameter nodes for seeds 0 and 1 (solvers.continuation.graph), the second seed's set
carried to the first seed's network and compared as sets, random solutions carried around a fresh loop, every
solution of seed 0 proven by Krawczyk's test in ball arithmetic with pairwise disjoint boxes (and images), and
(--trace CELL, by default 10r4s) the trace test with its witnesses found by the same graph strategy. The
compaction unknowns are invariant under the Euclidean group and the direct counts are orbits, so every count is
networks up to rotation, reflection and translation.

Usage: python scripts/monodromy_counts.py [10r4s 7r5s 6r6s 5r9s] [--threads 2] [--trace CELL ...] [--no-trace]
       [--checkpoint DIR] [--out DIR]
       python scripts/monodromy_counts.py --reuse [--merge OTHER/monodromy3d.csv]   (the tables again, no run)
Cells not named keep their committed rows. Rows hold what code and seeds determine; times go to the meta file.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from solvers import count as counting  # noqa: E402
from solvers.continuation import tape_kernel, trace  # noqa: E402

TABLES = os.path.join(ROOT, "tables")

#: The minimal 3D TDOA cells: configuration keys of solvers.count.tdoa_target (dimension 3).
CELLS = {"10r4s": "10r4s", "7r5s": "7r5s", "6r6s": "6r6s", "5r9s": "5r9s"}

#: Cells whose trace test runs by default (the direct cells' on their orbits, the pencil on the offsets: docs/count.md).
#: Not 5r/9s: its witnesses would be 20-33 x its 36,947 orbits in 45 unknowns, days of this machine
#: (docs/minimal-3d.md: the cost, and the plan to run it on a cluster with --dask).
TRACE = ("10r4s", "7r5s", "6r6s")

#: |t1| = |t2| of the trace test's pencil per cell (count's TRACE_STEP otherwise, 0.2).
TRACE_STEP: dict[str, float] = {}

SEEDS = (0, 1)

COLUMNS = ["cell", "formulation", "unknowns", "group_order", "seeds", "solutions", "proven", "graphs", "seed_sets",
           "loop_check", "paths", "trace_test", "trace_residual", "witnesses", "trace_paths", "evidence"]


def row(cell: str, result: counting.CountResult) -> dict:
    """One CSV row of a count (no times: those go to the meta file)."""
    t = result.trace or {}
    residual = t.get("residual")
    return {"cell": cell, "formulation": result.system, "unknowns": result.unknowns, "group_order": result.group_order,
            "seeds": " ".join(str(s.seed) for s in result.seeds), "solutions": result.count, "proven": result.proven,
            "graphs": "; ".join(s.graph for s in result.seeds),
            "seed_sets": "; ".join(s.carried for s in result.seeds[1:]),
            "loop_check": result.loops_checked, "paths": sum(s.paths for s in result.seeds),
            "trace_test": t.get("status", "not run"),
            "trace_residual": "" if residual is None or residual != residual else f"{residual:.0e}",
            "witnesses": t.get("witnesses", ""), "trace_paths": t.get("paths", ""), "evidence": result.evidence}


def markdown(rows: list[dict]) -> str:
    lines = ["<!-- Regenerate: python scripts/monodromy_counts.py; run record (wall times) in monodromy3d.meta.json -->", "",
             "**3D TDOA minimal cells: solutions by `count`** (networks up to rotation, reflection and translation; "
             "group order 8: direct parametrization, one solution per orbit of the gauge frame's reflections; graphs: "
             "monodromy on a complete graph of 4 parameter nodes per seed, closed when every solution has its image "
             "along every edge; seed sets: the second seed's solutions carried to the first seed's network; proven: "
             "Krawczyk's test in ball arithmetic, boxes (and their images) pairwise disjoint; trace test: "
             f"solvers.continuation.trace, passed when the affine fit's residual is <= {trace.PASS_TOL:.0e} or within "
             f"{trace.FLOOR_FACTOR:.0f}x of the points' rounding level)", "",
             "| cell | formulation | unknowns | group order | seeds | solutions | proven | graphs | seed sets "
             "| paths | trace test | residual | witnesses | trace paths | evidence |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['cell']} | {r['formulation']} | {r['unknowns']} | {r['group_order']} | {r['seeds']} | "
                     f"{r['solutions']} | {r['proven']} | {r['graphs']} | {r['seed_sets']} | {r['paths']} | "
                     f"{r['trace_test']} | {r['trace_residual']} | {r['witnesses']} | {r['trace_paths']} | {r['evidence']} |")
    return "\n".join(lines) + "\n"


def _read(path: str) -> list[dict]:
    if not os.path.exists(path):
        return []
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    return rows if rows and list(rows[0]) == COLUMNS else []


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cells", nargs="*", help=f"any of {', '.join(CELLS)} (default: all)")
    parser.add_argument("--threads", type=int, default=2, metavar="N", help="tracking threads (default 2)")
    parser.add_argument("--trace", nargs="+", default=list(TRACE), metavar="CELL",
                        help=f"cells whose trace test runs (default: {', '.join(TRACE)})")
    parser.add_argument("--no-trace", action="store_true", help="no trace test")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(SEEDS), metavar="K",
                        help="seeds of every cell (default 0 1; one seed gives a proven lower bound at most)")
    parser.add_argument("--checkpoint", metavar="DIR", help="resumable graph files (default: none, from scratch)")
    parser.add_argument("--out", metavar="DIR", default=TABLES, help="where the tables are read and written (default tables/)")
    parser.add_argument("--reuse", action="store_true", help="run nothing: write the tables again from the CSV's rows "
                        "(and --merge's)")
    parser.add_argument("--merge", metavar="CSV", help="with --reuse: take the rows of this monodromy3d.csv for its cells")
    args = parser.parse_args(argv)
    unknown = [c for c in args.cells + ([] if args.no_trace else args.trace) if c not in CELLS]
    if unknown:
        parser.error(f"unknown cell {unknown[0]!r}; valid: {', '.join(CELLS)}")
    try:
        tape_kernel.set_threads(args.threads)
    except ValueError:
        parser.error(f"--threads must be a positive integer, not {args.threads}")
    kept = {r["cell"]: r for r in _read(os.path.join(args.out, "monodromy3d.csv"))}
    runs = _runs(os.path.join(args.out, "monodromy3d.meta.json"))
    if args.merge:
        merged = {r["cell"]: r for r in _read(args.merge)}
        kept.update(merged)
        other = _runs(os.path.join(os.path.dirname(os.path.abspath(args.merge)), "monodromy3d.meta.json"))
        runs.update({c: v for c, v in other.items() if c in merged})
    for cell in [] if args.reuse else (args.cells or list(CELLS)):
        traced = not args.no_trace and cell in args.trace
        options = counting.CountOptions(seeds=tuple(args.seeds), trace=traced,
                                        trace_step=TRACE_STEP.get(cell, counting.TRACE_STEP),
                                        checkpoints=args.checkpoint)
        t0 = time.perf_counter()
        result = counting.count(counting.tdoa_target(CELLS[cell], 3), options,
                                progress=lambda msg, cell=cell: print(f"  {cell}: {msg}", file=sys.stderr, flush=True))
        wall = time.perf_counter() - t0
        print(result.summary(), flush=True)
        kept[cell] = row(cell, result)
        runs[cell] = {"wall_seconds": round(wall, 1), "proving_seconds": result.certify_seconds,
                      "seed_seconds": [s.seconds for s in result.seeds],
                      "trace_seconds": (result.trace or {}).get("seconds"), "threads": args.threads,
                      "date": time.strftime("%Y-%m-%d"), "commit": _commit(), "cores": os.cpu_count(),
                      "machine": platform.machine()}
        write(args.out, kept, runs)  # after every cell: a long run keeps what it finished
    write(args.out, kept, runs)
    return 0


def _runs(path: str) -> dict:
    meta = json.load(open(path, encoding="utf-8")) if os.path.exists(path) else {}
    return meta.get("runs", {}) if isinstance(meta.get("runs"), dict) else {}


def write(out: str, kept: dict, runs: dict) -> None:
    """monodromy3d.{csv,md} in ``out`` from the rows, in CELLS' order, and the run record."""
    os.makedirs(out, exist_ok=True)
    csv_path = os.path.join(out, "monodromy3d.csv")
    meta_path = os.path.join(out, "monodromy3d.meta.json")
    rows = [kept[c] for c in CELLS if c in kept]
    with open(csv_path, "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    with open(os.path.join(out, "monodromy3d.md"), "w", encoding="utf-8", newline="\n") as fh:
        fh.write(markdown(rows))
    with open(meta_path, "w", encoding="utf-8", newline="\n") as fh:
        json.dump({"script": "scripts/monodromy_counts.py", "runs": {c: runs[c] for c in CELLS if c in runs}}, fh,
                  indent=1)
        fh.write("\n")


if __name__ == "__main__":
    sys.exit(main())
