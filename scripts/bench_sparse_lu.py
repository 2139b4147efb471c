"""The tracker's Jacobians factored in the sparse elimination order against the dense order (issue 54, item 5).

Per cell (count's solver of a formulation, seed 0's start pair): the Jacobian's non-zeros, the LU's entry updates in
each order (:mod:`solvers.continuation.sparse_lu`), and ``--paths`` tracks of the start root to as many seeded random
parameter points (RK4, count's step control) in either order, one thread, best of ``--rounds`` interleaved rounds: CPU
ms a path each and their ratio, whether statuses and step counts agree, the largest relative difference of the
endpoints, and the largest residual of the sparse order's endpoints.

Usage: python scripts/bench_sparse_lu.py [--cells 7r5s 6r6s 5r9s] [--paths 256] [--rounds 3]
       [--out tables/bench_sparse_lu.csv]

Timings are of this run on this machine: the CSV is a run record (the ratios are what compare), not a committed result.
"""
from __future__ import annotations

import os

os.environ["TDOA_WORKBENCH_THREADS"] = "1"  # CPU a path, one core
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from solvers import count  # noqa: E402
from solvers.continuation import monodromy, sparse_lu  # noqa: E402

#: label -> (configuration, dimension): the 3D direct cells, and a 2D one whose Jacobian is just sparse enough.
CELLS = {"7r5s": ("7r5s", 3), "6r6s": ("6r6s", 3), "5r9s": ("5r9s", 3), "5r5s-2d": ("5r5s", 2)}


def bench(label: str, paths: int, rounds: int) -> dict:
    config, dim = CELLS[label]
    system, q0, x0, _ = count._start(count.tdoa_target(config, dim=dim), 0)
    solver, x0 = monodromy.start_solver(system, q0, x0, 0)
    N = solver.nvars
    nz = sparse_lu.pattern(solver.tapes.full, N)
    rows, cols = sparse_lu.elimination_order(nz)
    ordered = sparse_lu.cost(sparse_lu.schedule(nz[np.ix_(rows, cols)]))
    plan = solver.sparse
    rng = np.random.default_rng(1)
    scale = 0.3 * np.abs(q0).mean()
    q = q0 + scale * (rng.normal(size=(paths, len(q0))) + 1j * rng.normal(size=(paths, len(q0))))
    X, inst = np.tile(x0[0], (paths, 1)), np.arange(paths)
    best, out = {"sparse": np.inf, "dense": np.inf}, {}
    for name in ("dense", "sparse"):  # each order's compiled code built and loaded before timing
        solver.sparse = plan if name == "sparse" else None
        solver.track(q0[None], q[:8], X[:8], inst[:8])
    for _ in range(rounds):
        for name in ("dense", "sparse"):
            solver.sparse = plan if name == "sparse" else None
            t = time.process_time()
            out[name] = solver.track(q0[None], q, X, inst)
            best[name] = min(best[name], time.process_time() - t)
    solver.sparse = plan
    (xs, ss), (xd, sd) = out["sparse"], out["dense"]
    done = (ss[:, 0] == 0) & (sd[:, 0] == 0)
    diff = np.abs(xs[done] - xd[done]).max(axis=1) / np.maximum(np.abs(xd[done]).max(axis=1), 1e-300)
    row = {"cell": label, "unknowns": N, "nonzeros": int(nz.sum()), "updates_sparse": ordered,
           "updates_dense": sparse_lu.dense_cost(N), "sparse_used": plan is not None, "paths": paths,
           "ended": int(done.sum()), "same_status_and_steps": bool(np.array_equal(ss[:, :2], sd[:, :2])),
           "max_rel_endpoint_difference": f"{diff.max():.1e}" if len(diff) else "",
           "max_residual_sparse": f"{solver.residual(xs[done], q, inst[done]).max():.1e}" if done.any() else "",
           "cpu_ms_per_path_dense": round(1e3 * best["dense"] / paths, 3),
           "cpu_ms_per_path_sparse": round(1e3 * best["sparse"] / paths, 3),
           "ratio_dense_to_sparse": round(best["dense"] / best["sparse"], 2)}
    print(", ".join(f"{k}={v}" for k, v in row.items()), flush=True)
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", nargs="+", default=list(CELLS), choices=list(CELLS), metavar="CELL")
    ap.add_argument("--paths", type=int, default=256)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", default=os.path.join(ROOT, "tables", "bench_sparse_lu.csv"))
    args = ap.parse_args(argv)
    if args.paths < 8 or args.rounds < 1:
        ap.error("--paths must be at least 8 and --rounds at least 1")
    rows = []
    for label in args.cells:
        rows.append(bench(label, args.paths, args.rounds))
        pd.DataFrame(rows).to_csv(args.out, index=False, lineterminator="\n")  # after each cell: a partial run keeps its rows
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
