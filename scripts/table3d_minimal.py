"""The four 3D TDOA minimal cells over GF(p), F4 with a larger budget: tables/table3d_minimal.{csv,md,meta.json}.

scripts/table3d.py runs every formulation under a 150 000 000-cell matrix cap and 180 s, which the whole-cell
formulations of the minimal cells (10r/4s, 7r/5s, 6r/6s, 5r/9s: ``all``, every measurement, saturated by
det H * det D~[:3, :3]) exceed. This script runs those formulations again with the same code
(analysis.sweeps.cell_degrees.cell_degree_capped: primes 65521 and 32749 must agree, seed 0, the known root
checked on every Groebner basis), with no cell cap and a cap on F4's memory (--max-memory-gib) and wall time
(--seconds per formulation) instead. A count found here is a GF(p) count; scripts/table3d.py --reuse then
shows it in the minimal cell of tables/table3d.md beside the monodromy count of tables/monodromy3d.*.

Usage: OPENBLAS_NUM_THREADS=1 python scripts/table3d_minimal.py [CELL ...] [--seconds S] [--max-memory-gib G]
[--threads N] [--out-dir DIR] [--reuse]. CELL: any of 10r4s 7r5s 6r6s 5r9s (default all); the cells not
named keep their committed rows (tables/table3d_minimal.csv); --reuse computes nothing and writes the
committed rows again (the same bytes). Long: up to hours a cell; F4 prints one line per round on stderr.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import datetime  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from analysis.engine.degree import DEFAULT_PRIMES  # noqa: E402
from analysis.formulations.tdoa import Formulation, TDOAConfig  # noqa: E402
from analysis.sweeps.cell_degrees import cell_degree_capped, provenance, read_records, write_table  # noqa: E402

CELLS = {"10r4s": (10, 4), "7r5s": (7, 5), "6r6s": (6, 6), "5r9s": (5, 9)}
STEM = "table3d_minimal"
#: No cap on rows x cols: F4's memory cap is the one that binds.
NO_CELL_CAP = 10 ** 15

NOTES = """The whole-cell formulation of each 3D TDOA minimal cell (unknowns H, b, o and t; saturated by
det H * det D~[:3, :3]), computed modulo 65521 and 32749 on the instance of seed 0 with no cap on the matrix
size, F4's memory and wall-time caps in the meta file. status ok: the two primes agree on the degree, the
known root vanishes on both bases; each solution is one network up to rotation, reflection and translation.
cap/timeout: the budget was not enough (the note names the matrix). scripts/table3d.py --reuse shows these
counts in tables/table3d.md beside the monodromy counts (tables/monodromy3d.*).
"""


def formulation(cell: str) -> Formulation:
    m, n = CELLS[cell]
    return Formulation.from_spec(TDOAConfig(m, n, dim=3), "all")


def committed() -> dict:
    """The committed records (tables/table3d_minimal.csv) by formulation label (none when the table does not
    exist yet)."""
    path = os.path.join(ROOT, "tables", f"{STEM}.csv")
    return {r.formulation: r for r in read_records(path)} if os.path.exists(path) else {}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cells", nargs="*", default=list(CELLS), help=f"any of {', '.join(CELLS)} (default: all)")
    parser.add_argument("--seconds", type=float, default=4 * 3600.0, help="wall-time cap per formulation (default 4 h)")
    parser.add_argument("--max-memory-gib", type=float, default=16.0, help="F4 memory cap in GiB (default 16)")
    parser.add_argument("--threads", type=int, default=1, help="row-reduction threads of the C kernel (default 1)")
    parser.add_argument("--out-dir", default=os.path.join(ROOT, "tables"))
    parser.add_argument("--reuse", action="store_true", help="rewrite the committed records, compute nothing")
    args = parser.parse_args(argv)
    unknown = [c for c in args.cells if c not in CELLS]
    if unknown:
        parser.error(f"unknown cell(s) {', '.join(unknown)}; valid: {', '.join(CELLS)}")
    if args.seconds <= 0 or args.max_memory_gib <= 0 or args.threads < 1:
        parser.error("--seconds and --max-memory-gib must be positive, --threads at least 1")
    info = provenance(ROOT)
    old = committed()
    meta_path = os.path.join(ROOT, "tables", f"{STEM}.meta.json")
    runs = {}
    if os.path.exists(meta_path):
        with open(meta_path) as handle:
            runs = json.load(handle)["runs"]
    records = []
    for cell in CELLS:
        label = formulation(cell).label
        if args.reuse or cell not in args.cells:
            if label in old:
                records.append(old[label])
            continue
        print(f"{label}: F4 modulo {' and '.join(map(str, DEFAULT_PRIMES))}, memory cap {args.max_memory_gib:g} GiB, "
              f"{args.seconds:g} s", file=sys.stderr, flush=True)
        r = cell_degree_capped(label, args.seconds, DEFAULT_PRIMES, 0, NO_CELL_CAP, None,
                               max_memory=int(args.max_memory_gib * (1 << 30)), threads=args.threads, verbose=True)
        print(f"{r.formulation}: {r.status}, degree {r.degree}, {r.seconds:.0f} s {r.note}", file=sys.stderr, flush=True)
        records.append(r)
        runs[cell] = {"date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"), **info,
                      "seconds_cap": args.seconds, "max_memory_gib": args.max_memory_gib, "threads": args.threads}
    written = {r.config.split("-")[0] for r in records}  # each row's run record, in the rows' (CELLS) order
    meta = {"primes": list(DEFAULT_PRIMES), "seed": 0, "max_matrix_cells": "none (memory and wall-time caps)",
            "runs": {cell: runs[cell] for cell in CELLS if cell in written and cell in runs}}
    paths = write_table(records, args.out_dir, STEM, "3D TDOA minimal cells over GF(p): F4 with a larger budget",
                        "python scripts/table3d_minimal.py", meta, NOTES)
    print("wrote " + ", ".join(paths), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
