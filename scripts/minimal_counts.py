"""Generic solution counts of the minimal 2D TDOA problems in positions formulations: tables/minimal_counts.csv.

Rows (each a degree agreed by every (prime, seed) instance; analysis.sweeps.minimal.count):

* 4r/5s (minimal): ``receivers`` (5 receiver coordinates; degree in the unknowns, orbits of the sign
  group) and ``receivers-orbits`` (invariants: one root per geometric solution), saturated by the listed
  nonzero conditions; the same without saturation (dimension of the spurious part) and with x2 alone.
  Simple roots are checked on the orbit variants only (charpoly of a random linear form's action
  matrix); in the gauge unknowns they follow (the group acts freely, checked, and the quotient map is
  4:1 and unramified where x2 y3 != 0), and the check would dominate the run time.
* 4r/6s (over-determined by one): all 6 equations; square subsystems (drop W6 = transmitter 6, or 5
  random combinations of W1..W6) with the number of their roots that satisfy all 6 (``satisfy_full``).
* 6r/3s (cross-check): ``dual-orbits`` (receivers eliminated, invariants of the transmitters) against the
  paper's formulation A,B2,B3,C2-C6 computed in the same run (181 as generated, 180 saturated by det H).
* with ``--all-variants``: one instance of every other variant, recording where F4 exceeds the cap.

Writes tables/minimal_counts.csv and tables/minimal_counts.meta.json (commit, primes, seeds, versions,
machine, seconds). Usage: OPENBLAS_NUM_THREADS=1 python scripts/minimal_counts.py [--quick]
[--all-variants] [--out-dir DIR]  (about 5 minutes; --quick: one seed, about 2 minutes).
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import datetime  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from analysis.sweeps.complexity import compute_formulation  # noqa: E402
from analysis.engine.degree import DEFAULT_PRIMES  # noqa: E402
from analysis.engine.f4 import F4Options  # noqa: E402
from analysis.sweeps.minimal import Subsystem, count  # noqa: E402

FIELDS = ["label", "variant", "config", "subsystem", "saturate_by", "unknowns", "equations", "equation_degrees",
          "group_order", "status", "degree", "dimension", "orbits", "free_action", "simple_roots", "satisfy_full",
          "primes", "seeds", "instance_degrees", "max_matrix", "seconds", "note"]
CAP = 60_000_000


def plan(seeds: tuple[int, ...], all_variants: bool) -> list[dict]:
    """The rows to compute: (system, subsystem, saturation, seeds, note)."""
    one = seeds[:1]
    w = tuple(f"W{j}" for j in range(1, 7))
    rows = [
        dict(system=(4, 5, "receivers-orbits"), seeds=seeds + (max(seeds) + 1,),
             note="4r/5s geometric solutions (one root per orbit)"),
        dict(system=(4, 5, "receivers"), seeds=seeds, check_simple=False,
             note="4r/5s in the gauge unknowns; orbits = degree / 4 (free action checked)"),
        dict(system=(4, 5, "receivers"), saturate=("x2",), seeds=one, check_simple=False,
             note="x2 != 0 alone removes every spurious root"),
        dict(system=(4, 5, "receivers"), saturate="none", seeds=one, note="unsaturated: spurious components"),
        dict(system=(4, 5, "receivers-orbits"), saturate="none", seeds=one, note="unsaturated: spurious components"),
        dict(system=(4, 6, "receivers"), seeds=seeds, note="4r/6s over-determined: only the true network"),
        dict(system=(4, 6, "receivers-orbits"), seeds=seeds, note="4r/6s over-determined: only the true network"),
        dict(system=(4, 6, "receivers-orbits"), subsystem=Subsystem("drop", ("W6",)), seeds=seeds,
             note="square subsystem = 4r/5s on transmitters 1-5"),
        dict(system=(4, 6, "receivers-orbits"), subsystem=Subsystem("random", w, 5), seeds=seeds,
             note="square subsystem: 5 random GF(p) combinations of the 6 equations"),
        dict(system=(4, 6, "receivers"), subsystem=Subsystem("drop", ("Q6",)), seeds=one, check_simple=False,
             note="square subsystem in the gauge unknowns"),
        dict(system=(6, 3, "dual-orbits"), seeds=seeds, note="6r/3s cross-check: paper 181 as generated, 180 saturated"),
        dict(system=(6, 3, "dual-orbits"), saturate="none", seeds=one, note="unsaturated: spurious components"),
    ]
    if all_variants:
        for system in [(4, 5, v) for v in ("full", "transmitters", "offsets", "dual", "dual-orbits")] + \
                      [(6, 3, v) for v in ("full", "transmitters", "offsets", "receivers", "receivers-orbits", "dual")]:
            rows.append(dict(system=system, seeds=one, primes=DEFAULT_PRIMES[:1], check=False,
                             note="variant attempt (first instance only, checks off)"))
    return rows


def compute_row(item: dict) -> dict:
    """One row of the table: the count of one planned item (:func:`plan`), with its note."""
    rec = count(item["system"], primes=item.get("primes", DEFAULT_PRIMES), seeds=item["seeds"],
                subsystem=item.get("subsystem", Subsystem()), saturate=item.get("saturate", "all"),
                options=F4Options(max_matrix_cells=CAP), check_group=item.get("check", True),
                check_simple=item.get("check_simple", item.get("check", True)))
    return dict(rec.row(), note=item["note"])


def paper_rows(seeds: tuple[int, ...]) -> list[dict]:
    """The paper's 6r/3s formulation on the project's own instances (analysis.sweeps.complexity)."""
    t0 = time.perf_counter()
    res = compute_formulation("6r3s:A,B2,B3,C2-C6", DEFAULT_PRIMES, seeds)
    seconds = time.perf_counter() - t0
    base = dict(label=res.label, variant="paper (H, b, o)", config="6r3s", subsystem="all", unknowns=res.n_unknowns,
                equations=res.n_equations, equation_degrees="4 4 4 3 3 3 3 3", group_order=1, status=res.status,
                dimension=res.dimension, primes=" ".join(map(str, res.primes)), seeds=" ".join(map(str, res.seeds)),
                max_matrix=f"{res.max_rows}x{res.max_cols}", seconds=round(seconds, 2))
    return [dict(base, saturate_by="none", degree=res.degree, orbits="",
                 instance_degrees=res.instance_degrees.replace(",", " "), note="paper Table 2 (as generated)"),
            dict(base, saturate_by="det H", degree=res.saturated_degree, orbits=res.saturated_degree,
                 instance_degrees=res.instance_saturated_degrees.replace(",", " "),
                 note="saturated by det H (rank of the det H action matrix power)")]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one seed per row instead of two")
    ap.add_argument("--all-variants", action="store_true", help="also try every other variant once (cap 60M cells)")
    ap.add_argument("--out-dir", default=os.path.join(ROOT, "tables"))
    args = ap.parse_args(argv)
    seeds = (0,) if args.quick else (0, 1)
    t_start = time.perf_counter()
    out_rows = []
    for item in plan(seeds, args.all_variants):
        row = compute_row(item)
        out_rows.append(row)
        print(f"{row['label']:34s} {row['subsystem'][:28]:28s} sat={row['saturate_by'][:22]:22s} "
              f"{row['status']:9s} degree={row['degree']} dim={row['dimension']} orbits={row['orbits']} "
              f"full={row['satisfy_full']} [{row['instance_degrees']}] {row['seconds']} s", flush=True)
    for row in paper_rows(seeds):
        out_rows.append(row)
        print(f"{row['label']:34s} {'all':28s} sat={row['saturate_by']:22s} {row['status']:9s} degree={row['degree']} "
              f"[{row['instance_degrees']}] {row['seconds']} s", flush=True)
    total = time.perf_counter() - t_start
    os.makedirs(args.out_dir, exist_ok=True)
    csv_path = os.path.join(args.out_dir, "minimal_counts.csv")
    with open(csv_path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=FIELDS)
        writer.writeheader()
        for row in out_rows:
            writer.writerow({k: row.get(k, "") for k in FIELDS})
    meta = provenance(seeds, args, total)
    with open(os.path.join(args.out_dir, "minimal_counts.meta.json"), "w") as fh:
        json.dump(meta, fh, indent=2)
        fh.write("\n")
    print(f"wrote {csv_path} ({len(out_rows)} rows, {total:.0f} s)")
    return 0


def provenance(seeds, args, total: float) -> dict:
    import flint
    import numpy
    import sympy

    def git(*cmd: str) -> str:
        try:
            return subprocess.run(["git", *cmd], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            return ""

    return {
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "commit": git("rev-parse", "HEAD"),
        "worktree_dirty": bool(git("status", "--porcelain", "--untracked-files=no")),
        "command": "python scripts/minimal_counts.py" + (" --quick" if args.quick else "")
                   + (" --all-variants" if args.all_variants else ""),
        "primes": list(DEFAULT_PRIMES),
        "seeds": list(seeds),
        "seeds_note": "receivers-orbits 4r/5s uses one extra seed; rows marked with one seed use the first; "
                      "--all-variants rows use the first prime and seed only",
        "instances": "analysis.formulations.positions.sample_gf_positions(m, n, p, seed, variant); paper rows: "
                     "analysis.formulations.tdoa.sample_gf_instance (analysis.sweeps.complexity.compute_formulation)",
        "saturation": "Rabinowitsch variable t_ (t_ * f - 1, f the product of the saturating polynomials) in "
                      "grevlex; degree of I + (t_ f - 1) = degree of I : f^inf",
        "max_matrix_cells": CAP,
        "order": "grevlex",
        "seconds_total": round(total, 1),
        "versions": {"python": platform.python_version(), "numpy": numpy.__version__, "sympy": sympy.__version__,
                     "python-flint": flint.__version__},
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
        "threads": {"OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS")},
    }


if __name__ == "__main__":
    sys.exit(main())
