"""Why the calibration has its own Levenberg-Marquardt: against scipy.optimize.least_squares on the same fits.

Writes tables/least_squares.csv and tables/least_squares.md. For each network (positions uniform in
[-5, 5]^2, offsets in [-2, 2], sigma 1e-2, 20 % missing; start: the truth moved by 0.05 per coordinate)
the least-squares fit on every measured entry is solved by
  own     solvers.calibration.adjustment.levenberg_marquardt (normal matrix accumulated from the 5
          non-zeros of each Jacobian row, dense Cholesky of (2m + 3n - 3)^2),
  lsmr    scipy least_squares(method="trf", jac=sparse CSR, tr_solver="lsmr"),
  exact   scipy least_squares(method="trf", jac=dense, tr_solver="exact") (small networks only),
and reports seconds (best of 3) and the final cost, ratios against `own` in the same run.
scipy's solver is the one solvers/refine.py uses for the paper's experiments (MINPACK LM on complete,
small networks); the calibration pipeline keeps its own for the sizes below.

Usage: python scripts/bench_least_squares.py
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ["TDOA_WORKBENCH_THREADS"] = "1"  # the trackers on one core, as the eigensolves they are compared with

import csv  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402
import scipy.sparse  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

from solvers.calibration.adjustment import (  # noqa: E402
    entry_residuals,
    jacobian_values,
    levenberg_marquardt,
    make_problem,
    pack,
)
from solvers.recovery import to_gauge  # noqa: E402
from solvers.synthetic import Network, corrupt_measurements  # noqa: E402

SIZES = ((10, 8), (30, 30), (100, 100), (200, 150))


def problem(m, n, seed=0):
    rng = np.random.default_rng(seed)
    net = Network(rng.uniform(-5, 5, (m, 2)), rng.uniform(-5, 5, (n, 2)), rng.uniform(-2, 2, n))
    F, _ = corrupt_measurements(net.measurements(1e-2, rng), rng, 0.2, 0.0)
    R, S = to_gauge(net.receivers, net.transmitters)
    p = make_problem(F, np.isfinite(F), np.arange(m), np.arange(n), dim=2)
    x0 = pack(R, S, net.offsets) + 0.05 * rng.standard_normal(2 * m + 3 * n - 3)
    return p, x0


def sparse_jacobian(p):
    rows = np.repeat(np.arange(len(p.ii)), 5)
    cols = p.slots.ravel()
    keep = cols < p.n_params

    def jac(x):
        _, diff, dist = entry_residuals(x, p)
        v = jacobian_values(diff, dist).ravel()
        return scipy.sparse.csr_matrix((v[keep], (rows[keep], cols[keep])), shape=(len(p.ii), p.n_params))

    return jac


def best_of(fn, repeats=3):
    best, out = np.inf, None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def main() -> int:
    rows = []
    for m, n in SIZES:
        p, x0 = problem(m, n)

        def fun(x):
            return entry_residuals(x, p)[0]

        t_own, (x_own, _, _) = best_of(lambda: levenberg_marquardt(x0.copy(), p, "linear", 1.0, 100))
        cost_own = 0.5 * float(np.sum(fun(x_own) ** 2))
        jac = sparse_jacobian(p)
        t_lsmr, r_lsmr = best_of(lambda: least_squares(fun, x0, jac=jac, method="trf", tr_solver="lsmr",
                                                        xtol=1e-12, ftol=1e-12))
        row = {"network": f"{m}r/{n}s", "entries": len(p.ii), "unknowns": p.n_params,
               "own_s": round(t_own, 4), "lsmr_s": round(t_lsmr, 4), "lsmr_over_own": round(t_lsmr / t_own, 2),
               "own_cost": f"{cost_own:.6g}", "lsmr_cost": f"{r_lsmr.cost:.6g}"}
        if p.n_params <= 200:
            t_ex, r_ex = best_of(lambda: least_squares(fun, x0, jac=lambda x: jac(x).toarray(), method="trf",
                                                        tr_solver="exact", xtol=1e-12, ftol=1e-12))
            row.update({"exact_s": round(t_ex, 4), "exact_over_own": round(t_ex / t_own, 2), "exact_cost": f"{r_ex.cost:.6g}"})
        else:
            row.update({"exact_s": "", "exact_over_own": "", "exact_cost": ""})
        rows.append(row)
        print(row, file=sys.stderr, flush=True)
    out = os.path.join(ROOT, "tables")
    with open(os.path.join(out, "least_squares.csv"), "w", newline="") as handle:
        w = csv.DictWriter(handle, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    cols = list(rows[0])
    with open(os.path.join(out, "least_squares.md"), "w") as handle:
        handle.write("# Least squares on all entries: own LM against scipy (scripts/bench_least_squares.py)\n\n")
        handle.write("| " + " | ".join(cols) + " |\n|" + "---|" * len(cols) + "\n")
        for r in rows:
            handle.write("| " + " | ".join(str(r[c]) for c in cols) + " |\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
