"""3D TDOA complexity: tables/table3d.csv, tables/table3d.md, tables/table3d.meta.json.

Cells: every m/n with 5 <= m <= 11, 4 <= n <= 10 (the 3D compaction parametrization needs m >= 5,
n >= 4) whose excess mn - (3m + 4n - 6) lies in EXCESS: the minimal cells (excess 0: 10r/4s, 7r/5s,
6r/6s, 5r/9s) and their neighbours, which include the cells of the published stratified 3D solvers
(9r/5s, 7r/6s, 6r/8s). Per cell, in this order (analysis.cell_degrees.cell_degree, primes 65521 and
32749, seed 0; unknowns H (6), b (3), o1..on; saturated by det H):

* ``all``: A, B2-B4, C2-Cm and every 4 x 4 minor of the compaction matrix (the whole cell);
* ``C*,minors``: without A and B (when the cell has minors): the analogue of the paper's 2D formulations.

Budget: each formulation runs in a child process with a wall-time cap (--seconds, default 90) and an F4
matrix cap (--max-cells, default 30 000 000 rows x cols); a formulation that hits one is listed with it.
msolve (when installed) recomputes each degree found on the first prime. Usage:
OPENBLAS_NUM_THREADS=1 python scripts/table3d.py [--seconds S] [--max-cells N] [--out-dir DIR]
(about 15 minutes with the defaults on one core).
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import datetime  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from analysis.cell_degrees import cell_degree_capped, provenance, write_table  # noqa: E402
from analysis.degree import DEFAULT_PRIMES  # noqa: E402
from analysis.formulations import Formulation, TDOAConfig  # noqa: E402
from analysis.msolve import find_msolve, msolve_version  # noqa: E402

EXCESS = (-2, 6)
M_RANGE = range(5, 12)
N_RANGE = range(4, 11)
SEED = 0
SPECS = ("all", "C*,minors")

NOTES = """Unknowns H (symmetric 3 x 3), b in R^3 and the offsets; gauge r_1 = 0 (the compaction unknowns are
invariant under rotations and reflections, so each solution is one network up to the Euclidean group).
The grid shows the first formulation computed for the cell (``all``: the whole cell); cap/timeout: the
budget in the meta file was not enough. Comparison with the published 3D solvers and the open cells:
tables/NOTES.md, section "3D TDOA".
"""


def cells() -> list[TDOAConfig]:
    """The 3D TDOA configurations of the table, in (m, n) order."""
    return [TDOAConfig(m, n, dim=3) for m in M_RANGE for n in N_RANGE
            if EXCESS[0] <= TDOAConfig(m, n, dim=3).excess <= EXCESS[1]]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=90.0, help="wall-time cap per formulation")
    parser.add_argument("--max-cells", type=int, default=30_000_000, help="F4 matrix cap (rows x cols)")
    parser.add_argument("--out-dir", default=os.path.join(ROOT, "tables"))
    args = parser.parse_args(argv)
    exe = find_msolve()
    info = provenance(ROOT)
    t_start = time.perf_counter()
    records = []
    for config in cells():
        for spec in SPECS:
            if spec != "all" and not config.n_minors:
                continue
            r = cell_degree_capped(Formulation.from_spec(config, spec), args.seconds, DEFAULT_PRIMES, SEED,
                                   args.max_cells, exe)
            records.append(r)
            print(f"{r.formulation:<40} {r.status:<22} degree {r.degree!s:<5} {r.seconds:.1f} s",
                  file=sys.stderr, flush=True)
    command = "python scripts/table3d.py" + "".join(
        f" {flag} {value:g}" for flag, value, default in (("--seconds", args.seconds, 90.0),
                                                          ("--max-cells", args.max_cells, 30_000_000))
        if value != default)
    meta = {
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        **info,
        "command": command,
        "primes": list(DEFAULT_PRIMES), "seed": SEED,
        "cells": f"3D TDOA, m in [{M_RANGE.start}, {M_RANGE.stop - 1}], n in [{N_RANGE.start}, {N_RANGE.stop - 1}], "
                 f"excess in [{EXCESS[0]}, {EXCESS[1]}]",
        "formulations": list(SPECS),
        "caps": {"seconds_per_formulation": args.seconds, "max_matrix_cells": args.max_cells},
        "instances": "analysis.formulations.sample_gf_instance(config, prime, seed 0): gauge-frame positions over GF(p)",
        "degree": "degree of I + (t det H - 1) in grevlex (solutions with det H != 0)",
        "msolve": msolve_version(exe) or "not installed",
        "seconds_total": round(time.perf_counter() - t_start, 1),
    }
    paths = write_table(records, args.out_dir, "table3d", "3D TDOA self-calibration: complexity per m/n cell",
                        command, meta, NOTES)
    print("wrote " + ", ".join(paths), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
