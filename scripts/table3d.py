"""3D TDOA complexity: tables/table3d.csv, tables/table3d.md, tables/table3d.meta.json.

Cells: every m/n with 5 <= m <= 11, 4 <= n <= 10 (the 3D compaction parametrization needs m >= 5,
n >= 4) whose excess mn - (3m + 4n - 6) lies in EXCESS: the minimal cells (excess 0: 10r/4s, 7r/5s,
6r/6s, 5r/9s) and their neighbours, which include the cells of the published stratified 3D solvers
(9r/5s, 7r/6s, 6r/8s). Unknowns H (6), b (3), o1..on, saturated by det H (and det D~[:3, :3] with the
B_j, j >= 5). Per cell, in this order (analysis.sweeps.cell_degrees.cell_degree, primes 65521 and 32749, seed 0;
a formulation equal to an earlier one is not repeated):

* ``A,B2-B4,C*,minors``: the paper's family carried to 3D (B only for the transmitters of S~ = I);
* ``all``: also B5..Bn (the whole cell: every measurement enters);
* ``C*,minors``: without A and B (when the cell has minors).

Budget: each formulation runs in a child process with a wall-time cap (--seconds, default 180) and an F4
matrix cap (--max-cells, default 150 000 000 rows x cols; F4's own 8 GiB memory cap also applies); a
formulation that hits one is listed with it.
msolve (when installed) recomputes each degree found on the first prime. Usage:
OPENBLAS_NUM_THREADS=1 python scripts/table3d.py [--seconds S] [--max-cells N] [--out-dir DIR] [--reuse]
(about 15 minutes with the defaults on one core; --reuse: the committed table3d.csv's records, no F4).

The minimal cells that F4 leaves open under these caps show their counts from tables/table3d_minimal.csv
(scripts/table3d_minimal.py: the same formulation, F4 with a larger budget; a GF(p) count) and by monodromy
from tables/monodromy3d.csv (scripts/monodromy_counts.py: `count`, every solution proven, the evidence named in
the cell).
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import csv  # noqa: E402
import sys  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from analysis.sweeps.cell_degrees import read_records, run_table_script  # noqa: E402
from analysis.formulations.tdoa import Formulation, TDOAConfig  # noqa: E402

EXCESS = (-2, 6)
M_RANGE = range(5, 12)
N_RANGE = range(4, 11)

NOTES = """Unknowns H (symmetric 3 x 3), b in R^3 and the offsets; gauge r_1 = 0 (the compaction unknowns are
invariant under rotations and reflections, so each solution is one network up to the Euclidean group).
A degree 1 from any formulation means the cell has one solution; a larger degree from a subset of the
cell's equations bounds the count from above and is the size of that formulation's solver.
cap/timeout: the budget in the meta file was not enough. Comparison with the published 3D solvers and the
open cells: tables/NOTES.md, section "3D TDOA".
"""


def evidence() -> tuple[dict[tuple[str, int, int, int], str], str]:
    """The minimal cells' counts by other means than this sweep: GF(p) counts with a larger budget
    (tables/table3d_minimal.csv) and monodromy counts (:func:`monodromy_evidence`), as grid cells and a note."""
    monodromy, note = monodromy_evidence()
    path = os.path.join(ROOT, "tables", "table3d_minimal.csv")
    gf = {}
    if os.path.exists(path):
        gf = {(r.model, r.dim, r.m, r.n): (r.up_to_gauge, len(r.primes.split())) for r in read_records(path)
              if r.status == "ok"}
    if gf:
        note += ("Cells marked (GF(p), F4 with a larger budget ...): the whole-cell formulation's degree on two primes "
                 "from tables/table3d_minimal.* (scripts/table3d_minimal.py; no cell cap), compared with the "
                 "monodromy count.\n")
    return with_gf_counts(monodromy, gf), note


def with_gf_counts(monodromy: dict, gf: dict) -> dict:
    """Grid texts: a GF(p) count (gf: (count, primes) per cell) where there is one, saying whether the
    monodromy count agrees; else the monodromy text."""
    out = dict(monodromy)
    for key, (count, primes) in gf.items():
        other = monodromy.get(key, "").split(" ")[0]
        agreement = ("" if not other else "; monodromy agrees" if other == str(count) else f"; monodromy: {other}")
        out[key] = f"{count} (GF(p), {primes} primes, F4 with a larger budget{agreement})"
    return out


def monodromy_evidence() -> tuple[dict[tuple[str, int, int, int], str], str]:
    """The counts of tables/monodromy3d.csv (scripts/monodromy_counts.py: `count` on two seeds) as grid cells and
    the note naming them (:func:`count_text`)."""
    path = os.path.join(ROOT, "tables", "monodromy3d.csv")
    if not os.path.exists(path):
        return {}, ""
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    out = {}
    for row in rows:
        if "evidence" not in row:  # a file of another layout: no cell texts from it
            continue
        config = Formulation.parse(row["formulation"]).config
        out[(config.model, config.dim, config.m, config.n)] = count_text(row)
    note = ("Cells marked (proven ...) or (lower bound ...): no GF(p) count (F4's memory); the count is from "
            "tables/monodromy3d.* (scripts/monodromy_counts.py: `count`, monodromy on a complete graph for two seeds, "
            "every solution proven by Krawczyk's test, the seeds' sets compared, the trace test where it ran).\n"
            if out else "")
    return out, note


def count_text(row: dict) -> str:
    """One cell's text from its row of monodromy3d.csv, the evidence in words (STYLE.md, habit 16):
    "N (proven; [k seeds equal as sets; ]complete by trace test, residual r)": every solution proven, the trace
    test passed (and the seeds' graphs closed on equal sets);
    "N (proven; k seeds equal as sets)": every solution proven, every seed's graph closed and their sets equal,
    no trace test passed (N is then a proven lower bound that two seeds reach);
    ">=N (proven lower bound; ...)": every solution proven, but a graph did not close, one seed ran, or a carried
    set was not equal (what it said: solutions outside the first set, or paths lost carrying it);
    ">=N (lower bound, numerical)": not every solution proven."""
    n, proven = int(row["solutions"]), int(row["proven"])
    seeds = len(row["seeds"].split())
    closed = all(g == "closed" for g in row["graphs"].split("; "))
    equal = all(c == "equal as sets" for c in row["seed_sets"].split("; ")) if seeds > 1 else False
    if proven < n:
        return f">={n} (lower bound, numerical)"
    if row["trace_test"] == "passed":
        both = f"{seeds} seeds equal as sets; " if closed and equal else ""
        return f"{n} (proven; {both}complete by trace test, residual {row['trace_residual']})"
    if closed and equal:
        return f"{n} (proven; {seeds} seeds equal as sets)"
    if not closed:
        why = "graphs not all closed"
    elif seeds == 1:
        why = "one seed"
    else:  # what the carried sets said: solutions outside the first set, or only paths lost carrying them
        why = "seed sets: " + "; ".join(c.removeprefix("not equal: ") for c in row["seed_sets"].split("; ")
                                        if c != "equal as sets")
    return f">={n} (proven lower bound; {why})"


def cells() -> list[TDOAConfig]:
    """The 3D TDOA configurations of the table, in (m, n) order."""
    return [TDOAConfig(m, n, dim=3) for m in M_RANGE for n in N_RANGE
            if EXCESS[0] <= TDOAConfig(m, n, dim=3).excess <= EXCESS[1]]


def jobs() -> list[tuple[Formulation, bool]]:
    """The formulations of every cell, in table order, each confirmed by msolve where installed."""
    out = []
    for config in cells():
        minors = ",minors" if config.n_minors else ""
        seen = set()
        for spec in (f"A,B2-B4,C*{minors}", "all", f"C*{minors}" if minors else ""):
            if spec:
                formulation = Formulation.from_spec(config, spec)
                if formulation.equations not in seen:
                    seen.add(formulation.equations)
                    out.append((formulation, True))
    return out


def main(argv=None) -> int:
    return run_table_script(argv, __doc__, ROOT, "scripts/table3d.py", "table3d",
                            "3D TDOA self-calibration: complexity per m/n cell", NOTES, jobs,
                            {"cells": f"3D TDOA, m in [{M_RANGE.start}, {M_RANGE.stop - 1}], n in "
                                      f"[{N_RANGE.start}, {N_RANGE.stop - 1}], excess in [{EXCESS[0]}, {EXCESS[1]}]",
                             "formulations": "A,B2-B4,C*,minors; all; C*,minors (each once per cell)",
                             "degree": "degree of I + (t g - 1) in grevlex, g = det H (times det D~[:3, :3] with "
                                       "B5..Bn): solutions with g != 0"},
                            seconds=180.0, max_cells=150_000_000, evidence=evidence)


if __name__ == "__main__":
    sys.exit(main())
