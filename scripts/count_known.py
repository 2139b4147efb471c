"""`count` on the systems whose counts F4 certifies: tables/count_known.{csv,md} (results) and
tables/count_known.meta.json (wall times). Each row is `count` from scratch, two seeds, every solution proven;
the certified count is recomputed beside it by F4 over GF(p) (`degree`'s engine, two primes) for the user system
and read from the committed solver's spec (its certificate) for the formulations.

Usage: python scripts/count_known.py [--threads 2]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from analysis.formulations.parametric import parse  # noqa: E402
from solvers import count as counting  # noqa: E402
from solvers.continuation import tape_kernel  # noqa: E402
from solvers.generate import GENERATED_DIR, SOLVERS  # noqa: E402

TABLES = os.path.join(ROOT, "tables")

#: (row name, count target: a configuration key of solvers.generate.SOLVERS or a system file under examples/)
TARGETS = [("2D TDOA 6r/3s", "6r3s"), ("2D TDOA 4r/5s", "4r5s"), ("2D TOA 3r/3s", "3r3stoa"),
           ("3D TOA 4r/6s", "4r6s3dtoa"), ("3D TOA 5r/5s", "5r5s3dtoa"), ("3D TOA 6r/4s", "6r4s3dtoa"),
           ("examples/circle.sys", "examples/circle.sys")]

COLUMNS = ["system", "formulation", "certified", "certificate", "solutions", "proven", "graphs", "seed_sets", "evidence"]


def certified(key: str, system) -> tuple[int, str]:
    """The count certified over GF(p): the committed solver's spec for a configuration, F4 for a system file."""
    if key in SOLVERS:
        for name in sorted(os.listdir(GENERATED_DIR)):
            if name.startswith(f"tdoa_{key}_homotopy") and name.endswith(".json"):
                with open(os.path.join(GENERATED_DIR, name), encoding="utf-8") as fh:
                    return int(json.load(fh)["degree"]), f"solvers/generated/{name}"
    report = system.degree()
    return int(report.degree), "F4 over GF(p), 2 primes x 2 seeds"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=2, metavar="N")
    args = parser.parse_args(argv)
    tape_kernel.set_threads(args.threads)
    rows, times = [], {}
    for name, key in TARGETS:
        target = parse(open(os.path.join(ROOT, key), encoding="utf-8").read(), os.path.basename(key)) \
            if key.startswith("examples/") else key
        t0 = time.perf_counter()
        result = counting.count(target, counting.CountOptions(seeds=(0, 1)))
        times[name] = round(time.perf_counter() - t0, 1)
        system, *_ = counting._start(target, 0)
        n, how = certified(key, system)
        rows.append({"system": name, "formulation": result.system, "certified": n, "certificate": how,
                     "solutions": result.count, "proven": result.proven,
                     "graphs": "; ".join(s.graph for s in result.seeds),
                     "seed_sets": "; ".join(s.carried for s in result.seeds[1:]), "evidence": result.evidence})
        print(f"{name}: {result.count} ({result.evidence}); certified {n}; {times[name]} s", flush=True)
    with open(os.path.join(TABLES, "count_known.csv"), "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    lines = ["<!-- Regenerate: python scripts/count_known.py; wall times in count_known.meta.json -->", "",
             "**`count` on systems with a certified count** (two seeds from scratch, every solution proven by "
             "Krawczyk's test; certified: the GF(p) count of the committed solver's spec, or F4 for a system file)", "",
             "| system | formulation | certified | solutions | proven | graphs | seed sets | evidence |",
             "|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r['system']} | {r['formulation']} | {r['certified']} | {r['solutions']} | {r['proven']} | {r['graphs']} "
              f"| {r['seed_sets']} | {r['evidence']} |" for r in rows]
    with open(os.path.join(TABLES, "count_known.md"), "w", encoding="utf-8", newline="\n") as fh:
        fh.write("\n".join(lines) + "\n")
    with open(os.path.join(TABLES, "count_known.meta.json"), "w", encoding="utf-8", newline="\n") as fh:
        json.dump({"script": "scripts/count_known.py", "threads": args.threads, "wall_seconds": times}, fh, indent=1)
        fh.write("\n")
    ok = all(r["solutions"] == r["certified"] == r["proven"] for r in rows)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
