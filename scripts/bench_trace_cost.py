"""The cost of a trace test's witness path on the 3D TDOA minimal cells, to plan the tests that do not fit here.

Per cell (default 7r5s, 6r6s, 5r9s: the direct parametrization, 35-45 unknowns, on orbits of 8 reflections): the
trace test's system (solvers.continuation.trace.Pencil, seed 0, the count's start pair and its second instance, the
pencil on count's coordinates: the fewest offsets that determine each orbit),
and ``--paths`` tracks of its start point from the base node to as many random nodes of the witness graph (the
graph's own node distribution and tracking options), on one thread. Prints and writes, per cell, the seconds per
path and the share that failed, and, given the witnesses per orbit measured on a cell whose test ran
(``--witness-ratio``, e.g. 7r/5s's), the estimated witnesses, paths (6 per witness on the graph's 4 nodes, the
graph's own 1.1 for retracks, and 2 per point for the test's two slices) and core-hours of the whole test; the seconds
per path in the dense elimination order beside them (the sparse one is what the test runs where its plan exists).

Writes tables/bench_trace_cost.timing.json (untracked: seconds are facts of the run). Compare cells by their ratio
in one run: the machine's load moves all of them alike.

Usage: python scripts/bench_trace_cost.py [CELL ...] [--paths 40] [--witness-ratio R]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from solvers import count as counting  # noqa: E402
from solvers import count_evidence as evidence  # noqa: E402
from solvers.continuation import graph, tape_kernel, trace  # noqa: E402

#: Solutions (orbits) of each cell, as `count` proved them (tables/monodromy3d.csv), for the estimate.
ORBITS = {"7r5s": 2321, "6r6s": 3920, "5r9s": 36947}

#: Paths per witness: 6 edges of the complete graph on 4 nodes, retracks (the 2D/3D runs: about 1.1x), and
#: the test's own two slices.
PATHS_PER_WITNESS = 6 * 1.1 + 2


def measure(cell: str, paths: int) -> dict:
    target = counting.tdoa_target(cell, 3)
    system, q0, _, group = counting._start(target, 0)
    _, q_star, x_star, _ = counting._start(target, 1000)
    equations, unknowns, parameters = trace.system_equations(system)
    coordinates, words = evidence.pencil_coordinates(system, group, lambda msg: print(f"  {cell}: {msg}", file=sys.stderr))
    pencil = trace.Pencil.build(equations, unknowns, parameters, q0, (q_star, x_star),
                                trace.TraceOptions(coordinates=coordinates), group)
    rng = np.random.default_rng(7)
    Q0 = pencil.Q0
    scale = np.sqrt(np.mean(np.abs(Q0) ** 2))
    nodes = np.array([np.where(pencil.free, Q0 + scale * (rng.normal(size=len(Q0)) + 1j * rng.normal(size=len(Q0))), Q0)
                      for _ in range(paths)])
    xs = np.repeat(pencil.start, paths, axis=0)
    inst = np.arange(paths)
    plan, seconds = pencil.system.sparse, {}
    for order in ("dense", "sparse"):  # the trace system's Jacobian in either elimination order (solvers.continuation.sparse_lu)
        pencil.system.sparse = plan if order == "sparse" else None
        pencil.system.track(Q0[None], nodes[:1], xs[:1], inst[:1])  # the tapes' first call
        t0 = time.perf_counter()
        ends, _ = pencil.system.track(Q0[None], nodes, xs, inst)
        seconds[order] = time.perf_counter() - t0
    _, ok = graph._accept(pencil.system, ends, nodes, inst, graph.GraphOptions().accept_tol, None)
    return {"cell": cell, "unknowns": len(unknowns), "pencil": words, "paths": paths,
            "sparse_order": plan is not None, "seconds_per_path": seconds["sparse"] / paths,
            "seconds_per_path_dense": seconds["dense"] / paths, "failed": float(1.0 - ok.mean())}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cells", nargs="*", default=["7r5s", "6r6s", "5r9s"], help="cells (default 7r5s 6r6s 5r9s)")
    parser.add_argument("--paths", type=int, default=40, help="tracks timed per cell (default 40)")
    parser.add_argument("--witness-ratio", type=float, metavar="R",
                        help="witness orbits per solution orbit, measured on a cell whose test ran (for the estimate)")
    args = parser.parse_args(argv)
    unknown = [c for c in args.cells if c not in ORBITS]
    if unknown:
        parser.error(f"unknown cell {unknown[0]!r}; valid: {', '.join(ORBITS)}")
    if args.paths < 1:
        parser.error("--paths must be at least 1")
    tape_kernel.set_threads(1)
    rows = []
    for cell in args.cells:
        row = measure(cell, args.paths)
        if args.witness_ratio:
            witnesses = args.witness_ratio * ORBITS[cell]
            row.update(witnesses_estimated=round(witnesses), paths_estimated=round(witnesses * PATHS_PER_WITNESS),
                       core_hours_estimated=round(witnesses * PATHS_PER_WITNESS * row["seconds_per_path"] / 3600, 1))
        rows.append(row)
        print(json.dumps(row), flush=True)
    with open(os.path.join(ROOT, "tables", "bench_trace_cost.timing.json"), "w", encoding="utf-8") as fh:
        json.dump({"script": "scripts/bench_trace_cost.py", "date": time.strftime("%Y-%m-%d"),
                   "load_average": os.getloadavg()[0], "rows": rows}, fh, indent=1)
        fh.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
