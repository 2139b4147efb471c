"""TOA minimal and near-minimal cells in 2D and 3D: tables/toa.csv, tables/toa.md, tables/toa.meta.json.

Cells: every m/n with m, n >= K + 1 (the compaction parametrization's bound), m, n <= MAX_SIDE and
excess mn - (K(m + n) - K(K+1)/2) between EXCESS[0] and EXCESS[1] (minimal: 0). Per cell two
formulations (analysis.cell_degrees.cell_degree, primes 65521 and 32749, seed 0):

* compaction ``all`` (A, B2..Bn, C2..Cm in the unknowns H, b; paper Section 2.1): solutions with
  det H != 0, each one network up to rotation, reflection and translation; msolve (when installed)
  recomputes the first prime and must agree;
* direct ``all`` (|r_i - s_j|^2 = d_ij^2 in the gauge r_1 = 0, r_2 on the x axis, r_3 in the xy plane):
  its degree divided by 2^K must equal the compaction count (the script raises otherwise).

Each formulation runs in a child process under a wall-time cap (--seconds, default 120) and an F4 matrix
cap (--max-cells); a formulation that hits one is listed with it. Usage:
OPENBLAS_NUM_THREADS=1 python scripts/toa_table.py [--seconds S] [--out-dir DIR]  (about 2 minutes).
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

EXCESS = (-1, 3)
MAX_SIDE = {2: 6, 3: 9}
SEED = 0

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


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=120.0, help="wall-time cap per formulation")
    parser.add_argument("--max-cells", type=int, default=30_000_000, help="F4 matrix cap (rows x cols)")
    parser.add_argument("--out-dir", default=os.path.join(ROOT, "tables"))
    args = parser.parse_args(argv)
    exe = find_msolve()
    info = provenance(ROOT)
    t_start = time.perf_counter()
    records = []
    for config in cells():
        compaction = cell_degree_capped(Formulation.from_spec(config, "all"), args.seconds, DEFAULT_PRIMES, SEED,
                                        args.max_cells, exe)
        direct_config = TDOAConfig(config.m, config.n, model="toa", dim=config.dim, parametrization="direct")
        direct = cell_degree_capped(Formulation.from_spec(direct_config, "all"), args.seconds, DEFAULT_PRIMES, SEED,
                                    args.max_cells, exe if config.dim == 2 else None)
        if compaction.status == direct.status == "ok" and compaction.up_to_gauge != direct.up_to_gauge:
            raise ArithmeticError(f"{config.label}: compaction gives {compaction.up_to_gauge} networks, direct "
                                  f"{direct.degree} / {direct.group_order} = {direct.up_to_gauge}")
        records += [compaction, direct]
        for r in (compaction, direct):
            print(f"{r.formulation:<45} {r.status:<22} degree {r.degree!s:<5} up to gauge {r.up_to_gauge!s:<5} "
                  f"{r.seconds:.1f} s", file=sys.stderr, flush=True)
    meta = {
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        **info,
        "command": "python scripts/toa_table.py" + (f" --seconds {args.seconds:g}" if args.seconds != 120 else ""),
        "primes": list(DEFAULT_PRIMES), "seed": SEED,
        "cells": f"TOA, m, n >= K + 1, m, n <= {MAX_SIDE}, excess in [{EXCESS[0]}, {EXCESS[1]}]",
        "caps": {"seconds_per_formulation": args.seconds, "max_matrix_cells": args.max_cells},
        "instances": "analysis.formulations.sample_gf_instance(config, prime, seed 0): gauge-frame positions over GF(p)",
        "degree": "compaction: degree of I + (t det H - 1) in grevlex; direct: degree of I, divided by 2^K",
        "msolve": msolve_version(exe) or "not installed",
        "seconds_total": round(time.perf_counter() - t_start, 1),
    }
    paths = write_table(records, args.out_dir, "toa", "TOA self-calibration: minimal and near-minimal cells",
                        meta["command"], meta, NOTES)
    print("wrote " + ", ".join(paths), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
