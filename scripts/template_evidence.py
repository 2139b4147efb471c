"""Why the 9r/3s solver is a homotopy: single-template feasibility of the paper's 9r3s:C2-C9.

Writes tables/template_evidence_9r3s.csv (and prints it), three kinds of rows:

* ``relations``: for multiplier families of growing degree (solvers.feasibility), the number of the
  action-matrix relations (action o1) that a single template reaches over GF(65521), seeded instance 1,
  on the grevlex basis (75 monomials of (H, b)-degree <= 2) or on the offsets basis (75 monomials in
  o of degree <= 6, standard for the elimination ideal);
* ``numerics-<elimination>``: the smallest complete template found (offset multipliers of degree 11
  on the offsets basis) filled with real data of seeded networks (positions N(0, 10^2), offsets
  N(0, 1)), its excess columns eliminated orthogonally (svd), or by LU on a square part chosen over
  GF(p) (lu: dense; splu-natural / splu-colamd: SuperLU in template order or COLAMD order): the
  singular value of the excess block at its exact rank relative to the largest, the condition number
  of the matrix solved, the error of the roots it gives, and the elimination's seconds (indicative);
* ``basis-condition``: on the same networks, the condition number of the 75 roots' monomial matrix
  for each basis (roots from the generated homotopy solver): a bound on any action matrix on it.

Usage: OPENBLAS_NUM_THREADS=1 python scripts/template_evidence.py [--networks 3] [--max-total 4]
(about five minutes; tests/test_feasibility.py re-checks the cheapest rows against the CSV).
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from solvers.feasibility import ELIMINATIONS, basis_condition, gf_basis, relation_count, template_numerics  # noqa: E402
from solvers.synthetic import random_network, true_root  # noqa: E402

FORMULATION = "9r3s:C2-C9"
OUT = os.path.join(ROOT, "tables", "template_evidence_9r3s.csv")
FIELDS = ["kind", "family", "degree", "basis", "action", "rows", "columns", "relations", "needed", "complete",
          "network_seed", "sv_at_rank", "solved_condition", "log10_root_error", "seconds", "basis_condition"]
#: (family, degrees, basis) of the relation counts; the total-degree family is capped by --max-total.
PLAN = (("total", (2, 3, 4), "grevlex"), ("linear-offsets", (2, 3, 4, 5), "grevlex"),
        ("offsets", (7, 8, 9, 10, 11), "offsets"))


def relation_rows(max_total: int) -> list[dict]:
    rows = []
    for family, degrees, basis in PLAN:
        for d in degrees:
            if family == "total" and d > max_total:
                continue
            t0 = time.perf_counter()
            rc = relation_count(FORMULATION, family, d, "o1", basis)
            print(f"{family:>15s} d={d:2d} {basis:>8s}: {rc.rows} x {rc.columns}, {rc.relations}/{rc.needed} relations "
                  f"({time.perf_counter() - t0:.1f} s)", flush=True)
            rows.append({"kind": "relations", "family": family, "degree": d, "basis": basis, "action": "o1",
                         "rows": rc.rows, "columns": rc.columns, "relations": rc.relations, "needed": rc.needed,
                         "complete": int(rc.complete)})
    return rows


def _truth(net) -> np.ndarray:
    H, b, o = true_root(net)
    return np.concatenate([[H[0, 0], H[0, 1], H[1, 1]], b, o])


def numeric_rows(networks: int) -> list[dict]:
    from solvers.generated import tdoa_9r3s_homotopy75 as solver

    rows = []
    bases = {name: gf_basis(FORMULATION, name)[1] for name in ("grevlex", "offsets")}
    powers = np.array(solver.SCALE_POWERS)
    for seed in range(networks):
        net = random_network(9, 3, np.random.default_rng(seed))
        F = net.measurements()
        for method in ELIMINATIONS:
            t0 = time.perf_counter()
            out = template_numerics(FORMULATION, "offsets", 11, "o1", F, _truth(net), method=method)
            print(f"network {seed}, {method}: sv at exact rank {out['sv_at_rank']:.1e}, condition "
                  f"{out['solved_condition']:.1e}, root error {out['root_error']:.1e} ({time.perf_counter() - t0:.1f} s)",
                  flush=True)
            rows.append({"kind": f"numerics-{method}", "seconds": f"{out['seconds']:.2f}", "family": "offsets", "degree": 11, "basis": "offsets",
                         "action": "o1", "rows": out["rows"], "columns": out["columns"], "network_seed": seed,
                         "sv_at_rank": f"{out['sv_at_rank']:.1e}", "solved_condition": f"{out['solved_condition']:.1e}",
                         "log10_root_error": f"{np.log10(out['root_error']):.1f}"})
        roots = solver.solve(F)
        roots = roots[np.all(np.isfinite(roots), axis=1)]
        scale = float(np.sqrt(np.mean(F * F)))  # the solver's normalisation (solvers.runtime.data_scale)
        for name, B in bases.items():
            cond = basis_condition(roots / scale**powers, B)
            rows.append({"kind": "basis-condition", "basis": name, "network_seed": seed, "rows": len(roots),
                         "basis_condition": f"{cond:.2e}"})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--networks", type=int, default=3, help="seeded networks for the numeric rows (default 3)")
    parser.add_argument("--max-total", type=int, default=4, help="highest total-degree multiplier set (default 4)")
    parser.add_argument("--out", default=OUT)
    args = parser.parse_args(argv)
    rows = relation_rows(args.max_total) + numeric_rows(args.networks)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=FIELDS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
