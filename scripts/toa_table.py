"""TOA minimal and near-minimal cells in 2D and 3D: tables/toa.csv, tables/toa.md, tables/toa.meta.json.

Cells: every m/n with m, n >= K + 1 (the compaction parametrization's bound), m, n <= MAX_SIDE and
excess mn - (K(m + n) - K(K+1)/2) between EXCESS[0] and EXCESS[1] (minimal: 0). Per cell two
formulations (analysis.sweeps.cell_degrees.cell_degree, primes 65521 and 32749, seed 0):

* compaction ``all`` (A, B2..Bn, C2..Cm in the unknowns H, b; paper Section 2.1): solutions with
  det H != 0, each one network up to rotation, reflection and translation; msolve (when installed)
  recomputes the first prime and must agree;
* direct ``all`` (|r_i - s_j|^2 = d_ij^2 in the gauge r_1 = 0, r_2 on the x axis, r_3 in the xy plane):
  its degree divided by 2^K must equal the compaction count (the script raises otherwise).

Each formulation runs in a child process under a wall-time cap (--seconds, default 300) and an F4 matrix
cap (--max-cells, default 150 000 000); a formulation that hits one is listed with it. Usage:
OPENBLAS_NUM_THREADS=1 python scripts/toa_table.py [--seconds S] [--out-dir DIR]  (about 2 minutes).
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import sys  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from analysis.sweeps.cell_degrees import run_table_script  # noqa: E402
from analysis.formulations.tdoa import Formulation, TDOAConfig  # noqa: E402

EXCESS = (-1, 3)
MAX_SIDE = {2: 6, 3: 9}

NOTES = """Degrees are computed by this script (own F4 engine, two primes that must agree); the compaction
count is the number of solutions (H, b) with det H != 0, one per network up to rotation, reflection and
translation; the direct degree counts gauge-fixed positions and is 2^K times larger (sign changes of the
axes keep the gauge). Comparison with the literature: tables/NOTES.md, section "TOA beside TDOA".
"""


def cells() -> list[TDOAConfig]:
    """The TOA configurations of the table, in (dimension, m, n) order."""
    out = []
    for dim in (2, 3):
        for m in range(dim + 1, MAX_SIDE[dim] + 1):
            for n in range(dim + 1, MAX_SIDE[dim] + 1):
                config = TDOAConfig(m, n, model="toa", dim=dim)
                if EXCESS[0] <= config.excess <= EXCESS[1]:
                    out.append(config)
    return out


def jobs() -> list[tuple[Formulation, bool]]:
    """Per cell: the compaction formulation (msolve confirms) and the direct one (msolve in 2D only)."""
    out = []
    for config in cells():
        direct = TDOAConfig(config.m, config.n, model="toa", dim=config.dim, parametrization="direct")
        out += [(Formulation.from_spec(config, "all"), True), (Formulation.from_spec(direct, "all"), config.dim == 2)]
    return out


def check(records: list) -> None:
    """Compaction and direct counts of one cell must agree wherever both were computed."""
    for compaction, direct in zip(records[::2], records[1::2]):
        if compaction.status == direct.status == "ok" and compaction.up_to_gauge != direct.up_to_gauge:
            raise ArithmeticError(f"{compaction.config}: compaction gives {compaction.up_to_gauge} networks, direct "
                                  f"{direct.degree} / {direct.group_order} = {direct.up_to_gauge}")


def main(argv=None) -> int:
    return run_table_script(argv, __doc__, ROOT, "scripts/toa_table.py", "toa",
                            "TOA self-calibration: minimal and near-minimal cells", NOTES, jobs,
                            {"cells": f"TOA, m, n >= K + 1, m, n <= {MAX_SIDE}, excess in [{EXCESS[0]}, {EXCESS[1]}]",
                             "degree": "compaction: degree of I + (t det H - 1) in grevlex; direct: degree of I, "
                                       "divided by 2^K"},
                            seconds=300.0, max_cells=150_000_000, check=check)


if __name__ == "__main__":
    sys.exit(main())
