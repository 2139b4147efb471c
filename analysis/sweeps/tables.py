"""Tables 2 and 3 of the paper from complexity sweeps: which formulations, comparison with the paper,
and CSV / Markdown / LaTeX output with provenance.

Data flow: :func:`plan_tables` decides which formulations to compute (one canonical representative
per symmetry class, each on the smallest configuration that holds the receivers it uses),
:func:`analysis.sweeps.complexity.sweep` computes them, :func:`build_table2` / :func:`build_table3` turn the
records into pandas tables beside the paper's numbers (read from ``analysis/data/paper_tables.csv``),
and :func:`write_outputs` writes ``tables/table2.*``, ``tables/table3.*``, ``tables/formulations.csv``
and ``tables/provenance.json``. :func:`make_tables` does all of it (the ``tdoa-workbench tables``
command and ``scripts/make_tables.py`` call it).

Which formulations (paper Sections 3.1-3.2, Tables 2-3):

* Table 2: every A/B/C formulation with 8 equations for n = 3 and m = 6..9; after reducing each to
  the receivers it uses these are exactly the paper's six rows (abc = 008, 017, 107, 116, 026, 125).
* Table 3, cell m/n: the *square* formulations, i.e. those whose independent equations
  (n_A + n_B + n_C + rank of the minors' Jacobian at the known root; the paper counts the 10 minors of
  6r/4s as 3) number 5 + n, with a full-rank Jacobian at the known root (otherwise the true root lies
  on a positive-dimensional component). Candidates are (i) A/B/C subsets plus k minors with
  a + b + c + k = 5 + n (k-subsets of the minors enumerated up to symmetry while C(#minors, k) <=
  ``Budget.subset_limit``) and (ii) A/B/C subsets plus all minors (the paper's 6r/4s solver). They are
  ordered by the heuristic "fewer A and B, more C, then more minors" and cut at the cell's budget
  (at most ``Budget.per_base`` per A/B/C subset).
  A cell's value is the smallest degree |B| (as generated) over its own candidates and those of the
  cells m'/n with m' < m (a configuration can ignore receivers). Over-determined formulations (more
  independent equations than unknowns) are not candidates: on exact data they usually keep only the
  true root (|B| = 1), which says nothing about a solver for noisy data.
* Section 3.2: B2 + C2-C6 + every canonical subset of the 10 minors of 6r/4s (the paper's 22 and 66),
  the A/B/C subsets of 5r/4s with 2, 3 or 4 minors (154) and of 5r/5s with all 16 minors (64).
* Cells without any square formulation (fewer independent equations than unknowns, e.g. 4r/5s) get
  the formulation with every equation, to show its dimension.
"""
from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
import json
import math
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import pandas as pd

from .complexity import (
    CSV_COLUMNS,
    DEFAULT_CELLS,
    DEFAULT_PRIMES,
    DEFAULT_SEEDS,
    ENGINE_VERSION,
    FormulationResult,
    root_ranks,
    sweep,
)
from ..engine.f4 import F4Options
from .paths import DATA_DIR, HEADER_PREFIXES, default_output_dir, write_if_changed
from .paths import cache_dir as user_cache_dir
from .provenance import run_facts
from ..formulations.tdoa import Formulation, TDOAConfig, canonical_form, enumerate_formulations

__all__ = [
    "Budget",
    "CellPlan",
    "FULL",
    "PAPER_TABLE1",
    "PAPER_TABLE3",
    "QUICK",
    "TablePlan",
    "TablesSummary",
    "build_table2",
    "build_table3",
    "format_result_row",
    "make_tables",
    "paper_reference",
    "parse_cells",
    "plan_tables",
    "reduce_formulation",
    "write_outputs",
]

TABLES_DIR = default_output_dir()
REFERENCE_CSV = DATA_DIR / "paper_tables.csv"
TABLE3_ROWS = tuple(range(4, 10))   # m
TABLE3_COLS = tuple(range(3, 7))    # n

PAPER_TABLE3: dict[tuple[int, int], str] = {
    (4, 3): "u", (4, 4): "u", (4, 5): "-", (4, 6): "-",
    (5, 3): "u", (5, 4): "154", (5, 5): "64", (5, 6): "X",
    (6, 3): "181", (6, 4): "22", (6, 5): "*", (6, 6): "*",
    (7, 3): "144", (7, 4): "X", (7, 5): "*", (7, 6): "*",
    (8, 3): "116", (8, 4): "*", (8, 5): "*", (8, 6): "*",
    (9, 3): "75", (9, 4): "*", (9, 5): "*", (9, 6): "*",
}
"""Paper Table 3 as printed (m/n -> entry). X: solved in [kuang2013tdoa]; -: unsolved; u: under-
determined; *: reducible to a solvable configuration. The numbers are cross-checked against
``analysis/data/paper_tables.csv`` (the values used for comparisons come from that file)."""

PAPER_TABLE1: dict[tuple[int, int], str] = {
    (4, 3): "u", (4, 4): "u", (4, 5): "M", (4, 6): "-",
    (5, 3): "u", (5, 4): "-", (5, 5): "-", (5, 6): "X",
    (6, 3): "M", (6, 4): "O", (6, 5): "*", (6, 6): "*",
    (7, 3): "-", (7, 4): "X", (7, 5): "*", (7, 6): "*",
    (8, 3): "-", (8, 4): "*", (8, 5): "*", (8, 6): "*",
    (9, 3): "O", (9, 4): "*", (9, 5): "*", (9, 6): "*",
}
"""Paper Table 1 (M: minimal, O: solved in the paper), for the notes column."""

MARK_MEANING = {"u": "underdetermined", "-": "unsolved", "X": "solved in [kuang2013tdoa]",
                "*": "reducible to a solvable configuration", "M": "minimal", "O": "solved in the paper"}


@dataclass(frozen=True)
class Budget:
    """How many formulations to compute per Table 3 cell.

    focus: cells with a paper number or '-' (9/3, 8/3, 7/3, 6/3, 6/4, 5/4, 5/5, 4/5, 4/6).
    other: cells marked X or * (0 skips them). per_base: at most this many candidates share one A/B/C
    subset (so that the budget covers many A/B/C choices rather than many minor subsets of one).
    subset_limit: enumerate k-subsets of the minors only while C(#minors, k) <= subset_limit.
    section32: compute the Section 3.2 searches. other_timeout: wall-clock limit (seconds) per
    formulation of the X/* cells (they are swept after everything else, with this shorter limit).
    """

    focus: int
    other: int
    per_base: int = 4
    subset_limit: int = 3000
    section32: bool = True
    other_timeout: float = 90.0


FULL = Budget(focus=40, other=6)
QUICK = Budget(focus=2, other=0, subset_limit=0, section32=False)


# --------------------------------------------------------------------------------------------------
# Paper reference
# --------------------------------------------------------------------------------------------------


def paper_reference(path: Path | str | None = None) -> pd.DataFrame:
    """The transcribed paper numbers (``analysis/data/paper_tables.csv``) as a DataFrame of strings."""
    return pd.read_csv(path or REFERENCE_CSV, dtype=str, keep_default_na=False)


def _paper_table2(ref: pd.DataFrame) -> dict[tuple[int, int, int], int]:
    rows = ref[ref["table"] == "2"]
    return {(int(r.A), int(r.B), int(r.C)): int(r.basis_size) for r in rows.itertuples()}


def _paper_table3_numbers(ref: pd.DataFrame) -> dict[tuple[int, int], int]:
    out = {}
    for r in ref.itertuples():
        match = re.search(r"Table 3 cell (\d)/(\d)", r.note)
        if match and r.basis_size:
            out[(int(match.group(1)), int(match.group(2)))] = int(r.basis_size)
    return out


# --------------------------------------------------------------------------------------------------
# Which formulations
# --------------------------------------------------------------------------------------------------


def _minor_rows_cols(name: str) -> tuple[tuple[int, ...], tuple[int, ...]]:
    rows, cols = name[1:].split("_")
    split = (lambda s: tuple(map(int, s.split(".")))) if "." in name else (lambda s: tuple(map(int, s)))
    return split(rows), split(cols)


def _minor_name(rows: Sequence[int], cols: Sequence[int], dotted: bool) -> str:
    sep = "." if dotted else ""
    return f"M{sep.join(map(str, rows))}_{sep.join(map(str, cols))}"


def reduce_formulation(formulation: Formulation) -> Formulation:
    """The same system on the smallest configuration holding the receivers it uses (at least 4).

    Receiver 1 is always used; C_i uses receiver i and a minor with compaction rows r uses receivers
    r + 1. The used receivers are renumbered 1..k in order, which maps the equations of the formulation
    to equations with the same polynomials (for the same measurements) on the k-receiver configuration;
    the result is put in canonical form. Transmitters are never dropped: each one owns an unknown.
    """
    config = formulation.config
    used = {1}
    for name in formulation.equations:
        if name[0] == "C":
            used.add(int(name[1:]))
        elif name[0] == "M":
            used.update(r + 1 for r in _minor_rows_cols(name)[0])
    if len(used) == config.m:
        return canonical_form(formulation)
    new_m = max(4, len(used))
    index = {old: new for new, old in enumerate(sorted(used), start=1)}
    reduced = TDOAConfig(new_m, config.n)
    dotted = max(new_m - 1, config.n - 1) > 9
    names = []
    for name in formulation.equations:
        if name[0] == "C":
            names.append(f"C{index[int(name[1:])]}")
        elif name[0] == "M":
            rows, cols = _minor_rows_cols(name)
            names.append(_minor_name(sorted(index[r + 1] - 1 for r in rows), cols, dotted))
        else:
            names.append(name)
    return canonical_form(Formulation(reduced, tuple(names)))


def _heuristic_key(f: Formulation) -> tuple:
    """Fewer A and B, more C, then more minors (paper Table 2: C is cheapest, A dearest; Section 3.2:
    all 10 minors beat 3)."""
    c = f.counts
    return (c.A + c.B, c.A, -c.C, -c.minors, f.label)


@dataclass(frozen=True)
class CellPlan:
    """The formulations computed for one Table 3 cell m/n.

    candidates: square formulations native to this configuration (after reduction), in heuristic
    order, cut at the budget; n_square / n_generated: how many square / generated candidates existed
    before the cut; fallback: the all-equations formulation when no square formulation exists;
    max_independent: the largest number of independent equations any formulation of the cell has.
    """

    m: int
    n: int
    candidates: tuple[str, ...]
    n_generated: int
    n_square: int
    fallback: str | None
    max_independent: int
    budget: int
    skipped_subset_sizes: tuple[int, ...] = ()

    @property
    def label(self) -> str:
        return f"{self.m}/{self.n}"

    @property
    def focus(self) -> bool:
        return PAPER_TABLE3[(self.m, self.n)] not in ("X", "*", "u")


def _square_filter(formulations: Iterable[Formulation], unknowns: int) -> list[Formulation]:
    out = []
    for f in formulations:
        jac, minor_rank = root_ranks(f)
        if jac == unknowns and f.counts.A + f.counts.B + f.counts.C + minor_rank == unknowns:
            out.append(f)
    return out


def plan_cell(m: int, n: int, budget: Budget) -> CellPlan:
    """Candidates of one Table 3 cell (see the module docstring)."""
    config = TDOAConfig(m, n)
    unknowns = config.n_unknowns
    focus = PAPER_TABLE3[(m, n)] not in ("X", "*", "u")
    limit = budget.focus if focus else budget.other
    all_minors = Formulation.from_spec(config, "minors") if config.n_minors else None
    rank_minors = root_ranks(all_minors)[1] if all_minors else 0
    max_independent = min(m + 2, 8) + rank_minors
    generated: list[Formulation] = []
    skipped: list[int] = []
    if max_independent >= unknowns and limit > 0:
        for k in range(0, rank_minors + 1):
            if k and math.comb(config.n_minors, k) > budget.subset_limit:
                skipped.append(k)
                continue
            generated += enumerate_formulations(config, minor_sets=k if k else "none", total=unknowns)
        if config.n_minors:
            generated += [f for f in enumerate_formulations(config, minor_sets="all")
                          if f.counts.A + f.counts.B + f.counts.C + rank_minors == unknowns]
    native = {}
    for f in generated:
        r = reduce_formulation(f)
        if r.config == config:
            native[r.label] = r
    square = sorted(_square_filter(native.values(), unknowns), key=_heuristic_key)
    chosen: list[Formulation] = []
    per_base: dict[tuple[str, ...], int] = {}
    for f in square:
        base = tuple(x for x in f.equations if not x.startswith("M"))
        if len(chosen) < limit and per_base.get(base, 0) < budget.per_base:
            chosen.append(f)
            per_base[base] = per_base.get(base, 0) + 1
    fallback = None
    if max_independent < unknowns:
        fallback = Formulation.from_spec(config, "all").label
    return CellPlan(m, n, tuple(f.label for f in chosen), len(native), len(square), fallback,
                    max_independent, limit, tuple(skipped))


def table2_formulations() -> list[Formulation]:
    """The Table 2 formulations: 8 A/B/C equations for n = 3, m = 6..9, reduced and deduplicated."""
    out: dict[str, Formulation] = {}
    for m in range(6, 10):
        for f in enumerate_formulations(TDOAConfig(m, 3), total=8):
            r = reduce_formulation(f)
            out.setdefault(r.label, r)
    return sorted(out.values(), key=lambda f: (-f.counts.C, f.counts.A, f.label))


def section32_formulations() -> dict[str, list[str]]:
    """The Section 3.2 searches: paper number -> labels. B2 + C2-C6 + every 3-subset of the minors of
    6r/4s, and otherwise only formulations with a full-rank Jacobian at the known root (whose true root
    is isolated)."""
    c64, c54, c55 = TDOAConfig(6, 4), TDOAConfig(5, 4), TDOAConfig(5, 5)
    six = [f for k in range(1, c64.n_minors + 1)
           for f in enumerate_formulations(c64, nA=0, nB=1, nC=5, minor_sets=k)]
    five_four = [f for k in (2, 3, 4) for f in enumerate_formulations(c54, nA=1, nB=2, nC=4, minor_sets=k)]
    five_five = list(enumerate_formulations(c55, minor_sets="all"))

    def isolated(fs: list[Formulation]) -> list[str]:
        return [f.label for f in fs if root_ranks(f)[0] == f.config.n_unknowns]

    # the paper's "only 3 minors": every 3-subset, even those whose true root is not isolated
    three = [f.label for f in six if f.counts.minors == 3]
    return {"22/66": three + [x for x in isolated(six) if x not in three], "154": isolated(five_four),
            "64": isolated(five_five)}


@dataclass(frozen=True)
class TablePlan:
    """Everything to compute: Table 2, Table 3 cells, Section 3.2 searches."""

    table2: tuple[str, ...]
    cells: tuple[CellPlan, ...]
    section32: Mapping[str, tuple[str, ...]]
    budget: Budget

    def labels(self, part: str = "all") -> list[str]:
        """Formulations, deduplicated, in sweep order: Table 2, focus cells, Section 3.2 (part
        "primary"), then the X/* cells (part "secondary", minus those already in the primary part)."""
        primary = list(self.table2)
        for cell in self.cells:
            if cell.focus:
                primary += list(cell.candidates) + ([cell.fallback] if cell.fallback else [])
        for labels in self.section32.values():
            primary += list(labels)
        primary = list(dict.fromkeys(primary))
        seen = set(primary)
        secondary = []
        for cell in self.cells:
            if not cell.focus:
                secondary += [x for x in cell.candidates + ((cell.fallback,) if cell.fallback else ()) if x not in seen]
        secondary = list(dict.fromkeys(secondary))
        return {"primary": primary, "secondary": secondary, "all": primary + secondary}[part]

    def memberships(self) -> dict[str, list[str]]:
        """label -> where it is used: "T2", "T3:6/4", "S3.2:66"."""
        out: dict[str, list[str]] = {}
        for label in self.table2:
            out.setdefault(label, []).append("T2")
        for cell in self.cells:
            for label in cell.candidates + ((cell.fallback,) if cell.fallback else ()):
                out.setdefault(label, []).append(f"T3:{cell.label}")
        for key, labels in self.section32.items():
            for label in labels:
                out.setdefault(label, []).append(f"S3.2:{key}")
        return out


def parse_cells(text: str | Sequence[str] | None) -> list[tuple[int, int]]:
    """``"6/4,5/5"`` or ``["6r4s", "9/3"]`` -> [(6, 4), (5, 5)]; None -> every cell of Table 3."""
    if text is None:
        return [(m, n) for m in TABLE3_ROWS for n in TABLE3_COLS]
    items = text.split(",") if isinstance(text, str) else list(text)
    out = []
    for item in items:
        item = item.strip()
        match = re.fullmatch(r"(\d+)\s*(?:/|r/?)\s*(\d+)s?", item)
        if not match:
            raise ValueError(f"cannot parse cell {item!r}; use m/n like 6/4 or 6r4s")
        cell = (int(match.group(1)), int(match.group(2)))
        if cell not in PAPER_TABLE3:
            raise ValueError(f"cell {item!r} is not in Table 3 (m = 4..9, n = 3..6)")
        out.append(cell)
    return out


def plan_tables(budget: Budget = FULL, cells: Sequence[tuple[int, int]] | None = None) -> TablePlan:
    """What to compute for the given budget and Table 3 cells (default: all)."""
    cells = parse_cells(None) if cells is None else list(cells)
    plans = tuple(plan_cell(m, n, budget) for m, n in cells)
    section32 = {k: tuple(v) for k, v in section32_formulations().items()} if budget.section32 else {}
    return TablePlan(tuple(f.label for f in table2_formulations()), plans, section32, budget)


def _plan_fingerprint(budget: Budget, cells: Sequence[tuple[int, int]]) -> str:
    """Key of a cached plan: the budget, the cells, the engine version and the source of the modules
    that decide the plan (a changed enumeration or filter gives a new key)."""
    here = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for name in ("sweeps/tables.py", "formulations/tdoa.py", "sweeps/complexity.py"):
        digest.update((here / name).read_bytes())
    digest.update(json.dumps([dataclasses.asdict(budget), [list(c) for c in cells], ENGINE_VERSION]).encode())
    return digest.hexdigest()[:20]


def cached_plan(budget: Budget = FULL, cells: Sequence[tuple[int, int]] | None = None,
                use_cache: bool = True) -> TablePlan:
    """:func:`plan_tables`, stored as JSON in the user cache (``plans/``): enumerating and filtering the
    formulations takes about a minute for the full budget, reading the plan milliseconds."""
    cells = parse_cells(None) if cells is None else list(cells)
    path = user_cache_dir("plans") / f"plan-{_plan_fingerprint(budget, cells)}.json"
    if use_cache:
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            return TablePlan(
                tuple(data["table2"]),
                tuple(CellPlan(**{**c, "candidates": tuple(c["candidates"]),
                                  "skipped_subset_sizes": tuple(c["skipped_subset_sizes"])}) for c in data["cells"]),
                {k: tuple(v) for k, v in data["section32"].items()}, Budget(**data["budget"]))
        except (OSError, ValueError, KeyError, TypeError):
            pass
    plan = plan_tables(budget, cells)
    write_if_changed(path, json.dumps(dataclasses.asdict(plan), indent=1, sort_keys=True))
    return plan


# --------------------------------------------------------------------------------------------------
# Tables
# --------------------------------------------------------------------------------------------------


def _fmt(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def format_result_row(result: FormulationResult, used_in: Sequence[str] = ()) -> dict[str, str]:
    """One row of ``formulations.csv`` as strings (the exact text written; used by the staleness test)."""
    row = {k: _fmt(v) for k, v in result.row().items()}
    row["used_in"] = " ".join(used_in)
    return row


FORMULATION_COLUMNS = CSV_COLUMNS[:-1] + ("used_in", "seconds")


def _is_square(r: FormulationResult) -> bool:
    return r.independent_equations == r.n_unknowns and r.tangent_dim == 0


def build_table2(results: Mapping[str, FormulationResult], ref: pd.DataFrame | None = None) -> pd.DataFrame:
    """Table 2: A, B, C, |B| of the paper and ours (as generated and after saturating by det H)."""
    ref = paper_reference() if ref is None else ref
    paper = _paper_table2(ref)
    rows = []
    for (a, b, c), value in paper.items():  # the paper's row order
        match = [r for r in results.values() if r.n == 3 and (r.n_A, r.n_B, r.n_C, r.n_minors) == (a, b, c, 0)
                 and r.n_equations == 8]
        r = min(match, key=lambda x: x.m) if match else None
        rows.append({
            "A": a, "B": b, "C": c, "config": f"{r.m}r/{r.n}s" if r else None,
            "paper": value, "ours": r.degree if r else None,
            "match": None if r is None or r.degree is None else ("yes" if r.degree == value else "no"),
            "ours_saturated": r.saturated_degree if r else None,
            "status": r.status if r else "not computed", "formulation": r.label if r else None,
            "instance_degrees": r.instance_degrees if r else None, "gb_size": r.gb_size if r else None,
            "max_matrix": f"{r.max_rows}x{r.max_cols}" if r and r.max_rows else None,
            "seconds": round(r.seconds, 2) if r else None,
        })
    return pd.DataFrame(rows, dtype=object)


def _cell_best(cell: CellPlan, plans: Mapping[tuple[int, int], CellPlan],
               results: Mapping[str, FormulationResult]) -> tuple[FormulationResult | None, list[FormulationResult]]:
    """Best square ok result over this cell and the cells m'/n, m' < m (computed ones), and the cell's own."""
    pool = []
    for (m, n), plan in plans.items():
        if n == cell.n and m <= cell.m:
            pool += [results[x] for x in plan.candidates if x in results]
    own = [results[x] for x in cell.candidates if x in results]
    ok = [r for r in pool if r.status == "ok" and _is_square(r)]
    best = min(ok, key=lambda r: (r.degree, r.m, _heuristic_key(r.formulation))) if ok else None
    return best, own


def build_table3(plan: TablePlan, results: Mapping[str, FormulationResult],
                 ref: pd.DataFrame | None = None) -> pd.DataFrame:
    """Table 3, one row per cell: the paper's entry beside our best square formulation."""
    ref = paper_reference() if ref is None else ref
    numbers = _paper_table3_numbers(ref)
    plans = {(c.m, c.n): c for c in plan.cells}
    rows = []
    for cell in sorted(plan.cells, key=lambda c: (c.m, c.n)):  # Table 3 order, whatever order --cells gave
        key = (cell.m, cell.n)
        paper_entry = str(numbers.get(key, PAPER_TABLE3[key]))
        best, own = _cell_best(cell, plans, results)
        statuses = {}
        for r in own:
            statuses[r.status] = statuses.get(r.status, 0) + 1
        fallback = results.get(cell.fallback) if cell.fallback else None
        unknowns = 5 + cell.n
        if best is not None:
            ours, status = best.degree, "ok"
        elif cell.fallback is not None:
            ours, status = None, "underdetermined"
        elif not cell.candidates:
            ours, status = None, "not computed"
        else:
            ours, status = None, "no finite formulation found"
        if key in numbers:
            match = "n/a" if ours is None else ("yes" if ours == numbers[key] else "no")
        elif paper_entry == "u":
            match = "yes" if status == "underdetermined" else "n/a"
        else:
            match = "n/a"
        notes = []
        if status == "underdetermined":
            notes.append(f"at most {cell.max_independent} independent equations for {unknowns} unknowns in this "
                         "formulation family")
            if fallback is not None:
                if fallback.dimension is not None:
                    notes.append(f"all {fallback.n_equations} equations: dimension {fallback.dimension}")
                else:
                    notes.append(f"all {fallback.n_equations} equations: tangent space of dimension "
                                 f"{fallback.tangent_dim} at the known root; {fallback.message}")
        if best is not None and best.m < cell.m:
            notes.append(f"best uses {best.m} receivers")
        if best is not None and best.n >= 4 and best.n_minors == TDOAConfig(best.m, best.n).n_minors:
            expected = (best.m - 3) * (best.n - 3)
            if expected >= best.n:
                notes.append(f"the rank constraints alone fix the offsets ((m-3)(n-3) = {expected} for {best.n} "
                             f"offsets, rank {best.minor_rank} at the root), then C is linear in (H, b)")
        comment = "; ".join(notes)
        rows.append({
            "m": cell.m, "n": cell.n, "paper": paper_entry, "paper_table1": PAPER_TABLE1[key], "ours": ours,
            "match": match, "ours_saturated": best.saturated_degree if best else None,
            "formulation": best.label if best else (cell.fallback or None),
            "instance_degrees": best.instance_degrees if best else (fallback.instance_degrees if fallback else None),
            "status": status,
            "candidates_computed": len(own), "candidates_square": cell.n_square,
            "candidates_generated": cell.n_generated, "budget": cell.budget,
            "statuses": " ".join(f"{k}:{v}" for k, v in sorted(statuses.items())),
            "comment": comment,
            "seconds": round(sum(r.seconds for r in own) + (fallback.seconds if fallback else 0.0), 2),
        })
    return pd.DataFrame(rows, dtype=object)


SECTION32_TARGETS: dict[str, tuple[str, tuple[int, ...]]] = {
    "22/66": ("6r4s", (22, 66)), "154": ("5r4s", (154,)), "64": ("5r5s", (64,)),
}
"""Section 3.2 / Table 3 numbers whose equation subsets the paper does not (fully) state: search key ->
(configuration, numbers)."""


def build_section32(plan: TablePlan, results: Mapping[str, FormulationResult]) -> pd.DataFrame:
    """The Section 3.2 searches: every searched formulation, plus every other computed formulation of
    the same configuration whose degree (as generated or saturated) is one of the paper's numbers.

    Rows come in the order of :data:`SECTION32_TARGETS`, then of each search's labels: a plan read back
    from the cache (JSON with sorted keys) lists the searches in another order than a fresh one, and the
    CSV must not follow it."""
    rows = []
    unknown = sorted(set(plan.section32) - set(SECTION32_TARGETS))
    if unknown:
        raise ValueError(f"unknown Section 3.2 search(es) {', '.join(unknown)}; valid: {', '.join(SECTION32_TARGETS)}")
    for key, (config, targets) in SECTION32_TARGETS.items():
        if key not in plan.section32:
            continue
        labels = plan.section32[key]
        hits = [r.label for r in sorted(results.values(), key=lambda r: r.label)
                if r.config == config and ({r.degree, r.saturated_degree} & set(targets))]
        for label in dict.fromkeys(list(labels) + hits):
            r = results.get(label)
            if r is None:
                continue
            hit = [t for t in targets if t in (r.degree, r.saturated_degree)]
            rows.append({"search": key, "formulation": label, "searched": label in labels,
                         "independent_equations": r.independent_equations, "n_minors": r.n_minors,
                         "status": r.status, "degree": r.degree, "saturated_degree": r.saturated_degree,
                         "dimension": r.dimension, "tangent_dim": r.tangent_dim,
                         "instance_degrees": r.instance_degrees, "paper_hit": " ".join(map(str, hit))})
    return pd.DataFrame(rows, dtype=object)


# --------------------------------------------------------------------------------------------------
# Writers
# --------------------------------------------------------------------------------------------------


def _csv_text(df: pd.DataFrame) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(df.columns)
    for row in df.itertuples(index=False):
        writer.writerow([_fmt(v) for v in row])
    return buf.getvalue()


def _md_table(df: pd.DataFrame) -> str:
    cols = list(df.columns)
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for row in df.itertuples(index=False):
        lines.append("| " + " | ".join(_fmt(v).replace("|", "\\|") for v in row) + " |")
    return "\n".join(lines) + "\n"


def _tex_escape(text: str) -> str:
    return (text.replace("\\", r"\textbackslash{}").replace("_", r"\_").replace("%", r"\%")
            .replace("&", r"\&").replace("#", r"\#").replace("*", r"$\ast$").replace("<=", r"$\le$")
            .replace("|B|", r"$|\mathcal{B}|$"))


def _tex_table(df: pd.DataFrame, caption: str, label: str) -> str:
    cols = list(df.columns)
    lines = [r"\begin{table}[t]", r"\centering", rf"\caption{{{_tex_escape(caption)}}}", rf"\label{{{label}}}",
             r"\begin{tabular}{" + "l" * len(cols) + "}", r"\hline",
             " & ".join(_tex_escape(c) for c in cols) + r" \\", r"\hline"]
    for row in df.itertuples(index=False):
        lines.append(" & ".join(_tex_escape(_fmt(v)) for v in row) + r" \\")
    lines += [r"\hline", r"\end{tabular}", r"\end{table}"]
    return "\n".join(lines) + "\n"


def _grid(table3: pd.DataFrame, tex: bool) -> str:
    """The paper's m x n layout, each cell "ours (paper)"."""
    cells = {(int(r.m), int(r.n)): r for r in table3.itertuples()}
    cols = sorted({n for _, n in cells})
    rows = sorted({m for m, _ in cells})

    def text(m: int, n: int) -> tuple[str, str]:
        r = cells.get((m, n))
        if r is None:
            return "", ""
        if r.ours not in (None, ""):
            ours = str(r.ours)
        else:
            ours = {"underdetermined": "u", "not computed": "."}.get(r.status, "?")
        marks = {"yes": r" \checkmark", "no": r" $\times$"} if tex else {"yes": " ✓", "no": " ✗"}
        return f"{ours} ({r.paper})", marks.get(r.match, "")

    if tex:
        lines = [r"\begin{tabular}{c|" + "c" * len(cols) + "}", r"\hline\hline",
                 "$m/n$ & " + " & ".join(map(str, cols)) + r" \\\hline"]
        for m in rows:
            lines.append(f"{m} & " + " & ".join(_tex_escape(text(m, n)[0]).replace(r"$\ast$", "*") + text(m, n)[1]
                                                for n in cols) + r" \\")
        lines.append(r"\end{tabular}")
        return "\n".join(lines) + "\n"
    lines = ["| m/n | " + " | ".join(map(str, cols)) + " |", "|---|" + "---|" * len(cols)]
    for m in rows:
        lines.append(f"| {m} | " + " | ".join("".join(text(m, n)) for n in cols) + " |")
    return "\n".join(lines) + "\n"


def _provenance(primes, seeds, options: F4Options, timeout, budget: Budget, mode: str,
                seconds: float, computed: int, cached: int, jobs: int) -> dict:
    facts = run_facts(("numpy", "flint", "sympy", "pandas", "tqdm"))
    return {
        "date": facts["date"],
        "commit": facts["commit"],
        "worktree_dirty": facts["worktree_dirty"],
        "engine_version": ENGINE_VERSION,
        "mode": mode,
        "primes": list(primes),
        "seeds": list(seeds),
        "instances": "one consistent instance per (prime, seed): sample_gf_instance(config, prime, seed)",
        "degree_rule": "majority over instances; per-instance values in instance_degrees",
        "max_matrix_cells": options.max_matrix_cells,
        "timeout_seconds": timeout,
        "budget": dataclasses.asdict(budget),
        "jobs": jobs,
        "versions": facts["versions"],
        "machine": facts["machine"],
        "timings": {"wall_seconds": round(seconds, 1), "formulations_computed": computed,
                    "formulations_from_cache": cached},
    }


def _last_uncached_run(previous: Path, provenance: dict, cached: int) -> dict | None:
    """Timings of the last run that computed everything, carried over from the previous timing record
    while the engine version and mode are unchanged (a cached rerun otherwise hides the real cost)."""
    if cached == 0:
        return {"date": provenance["date"], "commit": provenance["commit"],
                "wall_seconds": provenance["timings"]["wall_seconds"],
                "worker_seconds": provenance["sweep_seconds_sum"],
                "formulations": provenance["timings"]["formulations_computed"], "jobs": provenance["jobs"]}
    try:
        old = json.loads(previous.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if old.get("engine_version") != provenance["engine_version"] or old.get("mode") != provenance["mode"]:
        return None
    return old.get("last_uncached_run")


VOLATILE_PROVENANCE = ("date", "commit", "worktree_dirty", "versions", "machine", "timings", "jobs",
                       "sweep_seconds_sum", "last_uncached_run", "seconds")
"""Keys of the provenance record that are facts of the run (dates, commit, machine, timings), not results: they go
to the untracked provenance.timing.json only; provenance.json holds the rest."""

TIMING_COLUMNS = ("seconds",)
"""Columns of the sweep's frames that measure this run's speed: written to provenance.timing.json, never to a
committed table."""


def _strip_volatile(text: str, csv_file: bool) -> str:
    """A table file without its provenance header (commit, date) and timing columns (the search tables,
    `analysis.sweeps.search`, still carry both)."""
    if csv_file:
        rows = list(csv.reader(io.StringIO(text)))
        if not rows:
            return ""
        keep = [k for k, name in enumerate(rows[0]) if name not in TIMING_COLUMNS]
        return "\n".join(",".join(r[k] for k in keep if k < len(r)) for r in rows)
    out, drop = [], []
    for line in text.splitlines():
        if line.startswith(HEADER_PREFIXES):
            continue
        if line.startswith("|"):
            cells = line.strip().strip("|").split("|")
            if any(c.strip() in TIMING_COLUMNS for c in cells):
                drop = [k for k, c in enumerate(cells) if c.strip() in TIMING_COLUMNS]
            line = "|".join(c for k, c in enumerate(cells) if k not in drop)
        else:
            drop = []
        out.append(line)
    return "\n".join(out)


def _same_results(name: str):
    csv_file = name.endswith(".csv")
    return lambda old, new: _strip_volatile(old, csv_file) == _strip_volatile(new, csv_file)


def _row_seconds(frame: pd.DataFrame, key: Sequence[str]) -> list[dict]:
    """The ``seconds`` of each row of a table, with the columns that name the row (for the timing record)."""
    def seconds(value: object) -> float | None:
        return None if value is None or value == "" or pd.isna(value) else float(value)

    return [{**{k: _fmt(row[k]) for k in key}, "seconds": seconds(row["seconds"])} for _, row in frame.iterrows()]


def _results_only(frame: pd.DataFrame) -> pd.DataFrame:
    return frame[[c for c in frame.columns if c not in TIMING_COLUMNS]]


def write_outputs(out_dir: Path, table2: pd.DataFrame, table3: pd.DataFrame, section32: pd.DataFrame,
                  formulations: pd.DataFrame, provenance: dict) -> list[Path]:
    """Write the tables (CSV, Markdown and LaTeX) and provenance.json: results only, so that the same results
    give the same bytes on every run and machine; the run facts (commit, date, versions, machine, wall time and
    every row's ``seconds``) go to the untracked provenance.timing.json. A file whose bytes are unchanged is not
    touched (its mtime stays).
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    header = (f"generated by analysis.sweeps.tables.make_tables ({provenance['mode']} run); primes "
              f"{' '.join(map(str, provenance['primes']))}, seeds {' '.join(map(str, provenance['seeds']))}, "
              f"engine {provenance['engine_version']}; see provenance.json (commit, date and timings: "
              "provenance.timing.json, not tracked)")
    written = []

    def put(name: str, text: str) -> None:
        path = out_dir / name
        write_if_changed(path, text)
        written.append(path)

    timing = {**provenance, "seconds": {
        "table2": _row_seconds(table2, ("A", "B", "C", "formulation")),
        "table3": _row_seconds(table3, ("m", "n", "formulation")),
        "formulations": _row_seconds(formulations, ("label",)),
    }}
    table2, table3, formulations = (_results_only(t) for t in (table2, table3, formulations))
    put("table2.csv", _csv_text(table2))
    put("table3.csv", _csv_text(table3))
    put("formulations.csv", _csv_text(formulations))
    if len(section32):
        put("section32.csv", _csv_text(_results_only(section32)))
    t2_caption = ("Table 2 (reproduction): size of the standard monomial basis |B| for the 3-transmitter "
                  "formulations with a A, b B and c C equations. 'ours' is |B| as generated (A and B multiplied "
                  "by det H); 'ours_saturated' after saturating by det H.")
    put("table2.md", f"<!-- {header} -->\n\n**{t2_caption}**\n\n" + _md_table(table2))
    put("table2.tex", f"% {header}\n" + _tex_table(table2[["A", "B", "C", "paper", "ours", "match", "ours_saturated",
                                                          "formulation"]], t2_caption, "tab:3rec-repro"))
    t3_caption = ("Table 3 (reproduction): complexity |B| of TDOA configurations m/n, ours (paper). Ours is the "
                  "smallest |B| (as generated) over the square formulations computed for the cell and for the "
                  "cells with fewer receivers; u: no square formulation exists in this formulation family.")
    grid_md = _grid(table3, tex=False)
    detail_cols = ["m", "n", "paper", "ours", "match", "ours_saturated", "formulation", "instance_degrees",
                   "status", "candidates_computed", "candidates_square", "comment"]
    put("table3.md", f"<!-- {header} -->\n\n**{t3_caption}**\n\n" + grid_md + "\nPer cell:\n\n"
        + _md_table(table3[detail_cols]))
    put("table3.tex", f"% {header}\n" + r"\begin{table}[t]" + "\n" + r"\centering" + "\n"
        + rf"\caption{{{_tex_escape(t3_caption)}}}" + "\n" + r"\label{tab:degree-repro}" + "\n"
        + _grid(table3, tex=True) + r"\end{table}" + "\n\n"
        + _tex_table(table3[["m", "n", "paper", "ours", "match", "ours_saturated", "formulation"]],
                     "Table 3 (reproduction), per cell: the formulation behind each number.", "tab:degree-cells"))
    put("provenance.json", json.dumps({k: v for k, v in provenance.items() if k not in VOLATILE_PROVENANCE},
                                      indent=2) + "\n")
    write_if_changed(out_dir / "provenance.timing.json", json.dumps(timing, indent=2, default=str) + "\n")
    return written


# --------------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------------


@dataclass
class TablesSummary:
    """What :func:`make_tables` did: the tables, where they went and how long it took."""

    table2: pd.DataFrame
    table3: pd.DataFrame
    section32: pd.DataFrame
    formulations: pd.DataFrame
    paths: list[Path]
    seconds: float
    computed: int
    cached: int
    mode: str
    statuses: dict = field(default_factory=dict)

    def __str__(self) -> str:
        return self.report()

    def report(self) -> str:
        """Plain-text comparison with the paper."""
        out = [f"Table 2 ({self.mode} run)"]
        for r in self.table2.itertuples():
            out.append(f"  {r.A}{r.B}{r.C}  paper {r.paper:>4}  ours {_fmt(r.ours):>4}  sat {_fmt(r.ours_saturated):>4}"
                       f"  {_fmt(r.match):4}  {r.formulation}  [{r.instance_degrees}]")
        out.append("Table 3")
        for r in self.table3.itertuples():
            out.append(f"  {r.m}/{r.n}  paper {r.paper:>4}  ours {_fmt(r.ours):>4}  sat {_fmt(r.ours_saturated):>4}"
                       f"  {_fmt(r.match):4}  {_fmt(r.formulation)}  {r.status}; {r.candidates_computed} computed"
                       f"{'; ' + r.comment if r.comment else ''}")
        if len(self.section32):
            out.append("Section 3.2 hits")
            hits = self.section32[self.section32["paper_hit"] != ""]
            for r in hits.itertuples():
                out.append(f"  {r.search}: {r.formulation} -> {r.degree} (saturated {_fmt(r.saturated_degree)})")
        out.append(f"{self.computed} formulations computed, {self.cached} from cache; statuses "
                   + ", ".join(f"{k} {v}" for k, v in sorted(self.statuses.items()))
                   + f"; {self.seconds:.1f} s")
        out.append("wrote " + ", ".join(str(p) for p in self.paths))
        return "\n".join(out)


def make_tables(quick: bool = False, jobs: int = 2, *, use_cache: bool = True,
                cells: str | Sequence[str] | None = None, out_dir: Path | str | None = None,
                progress: bool = True, timeout: float | None = 300.0,
                max_matrix_cells: int = DEFAULT_CELLS, primes: Sequence[int] = DEFAULT_PRIMES,
                seeds: Sequence[int] = DEFAULT_SEEDS, budget: Budget | None = None,
                cache_dir: Path | str | None = None, executor=None) -> TablesSummary:
    """Compute and write Tables 2 and 3 (and the full list of formulations) with provenance.

    Parameters
    ----------
    quick : small budget (:data:`QUICK`): Table 2 and two formulations per focus cell, no X/* cells,
        no Section 3.2 searches.
    jobs : worker processes for the sweep.
    use_cache : read the caches of results and plans (results are always written there).
    cells : restrict Table 3 to these cells (``"6/4,5/5"``).
    out_dir : where to write. Default: ``tables/`` for a full run over all cells; a partial run (quick
        or a subset of cells) writes to the user cache's ``tables-partial/`` so it never overwrites the full tables.
    timeout, max_matrix_cells : per-formulation limits (wall-clock seconds, F4 matrix rows*cols). A
        formulation stopped by the wall-clock limit is computed again without it after the sweeps, so
        that no table entry depends on the machine's speed or load (only the matrix cap bounds it).
    primes, seeds : instances per formulation.
    budget : override the budget.
    executor : where the sweep computes (:mod:`analysis.sweeps.executors`; default a local pool of ``jobs``).

    Returns a :class:`TablesSummary` (``.report()`` prints the comparison with the paper).
    """
    t0 = time.perf_counter()
    budget = budget or (QUICK if quick else FULL)
    cell_list = parse_cells(cells)
    partial = quick or cells is not None or budget != FULL
    mode = "quick" if quick else ("partial" if partial else "full")
    if out_dir is None:
        out_dir = user_cache_dir("tables-partial") if partial else TABLES_DIR
    out_dir = Path(out_dir)
    plan = cached_plan(budget, cell_list, use_cache)
    options = F4Options(max_matrix_cells=max_matrix_cells)
    from_cache: set[str] = set()
    results: dict[str, FormulationResult] = {}
    other_timeout = budget.other_timeout if timeout is None else min(timeout, budget.other_timeout)
    phases = {"primary": "sweep 1/2: Table 2, numbered Table 3 cells, Section 3.2",
              "secondary": "sweep 2/2: Table 3 cells marked X or *"}
    def record(result: FormulationResult, cached: bool) -> None:
        if cached:
            from_cache.add(result.label)

    for part, limit in (("primary", timeout), ("secondary", other_timeout)):
        for r in sweep(plan.labels(part), primes=primes, seeds=seeds, options=options, jobs=jobs,
                       cache_dir=cache_dir, use_cache=use_cache, progress=progress, timeout=limit, executor=executor,
                       on_result=record, phase=phases[part]):
            results[r.label] = r
    # The wall-clock limit keeps the parallel sweeps moving; it must not decide a result, or the tables
    # would depend on the machine's load (a formulation that finishes in 200 s on an idle machine times out
    # at 300 s on a loaded one). What it stopped is computed again without it, the F4 matrix cap (a
    # deterministic limit) still in force.
    timed_out = [label for label, r in results.items() if r.status == "timeout"]
    from_cache.difference_update(timed_out)  # computed now, whether or not their timeout came from the cache
    if timed_out:
        for r in sweep(timed_out, primes=primes, seeds=seeds, options=options, jobs=jobs, cache_dir=cache_dir,
                       use_cache=use_cache, progress=progress, timeout=None, executor=executor, on_result=record,
                       phase=f"sweep: {len(timed_out)} formulation(s) past the wall-clock limit, without it"):
            results[r.label] = r
    ref = paper_reference()
    table2 = build_table2({k: results[k] for k in plan.table2}, ref)
    table3 = build_table3(plan, results, ref)
    section32 = build_section32(plan, results)
    members = plan.memberships()
    ordered = sorted(results.values(), key=lambda r: (r.n, r.m, r.label))
    formulations = pd.DataFrame([format_result_row(r, members.get(r.label, ())) for r in ordered],
                                columns=list(FORMULATION_COLUMNS), dtype=object)
    seconds = time.perf_counter() - t0
    cached = len(from_cache)
    statuses: dict[str, int] = {}
    for r in results.values():
        statuses[r.status] = statuses.get(r.status, 0) + 1
    provenance = _provenance(primes, seeds, options, timeout, budget, mode, seconds, len(results) - cached, cached,
                             jobs)
    provenance["timeout_seconds_x_star_cells"] = other_timeout
    provenance["table3_cells"] = [f"{m}/{n}" for m, n in sorted(cell_list)]  # Table 3 order, as --cells gave it or not
    provenance["sweep_seconds_sum"] = round(sum(r.seconds for r in results.values()), 1)
    provenance["last_uncached_run"] = _last_uncached_run(out_dir / "provenance.timing.json", provenance, cached)
    paths = write_outputs(out_dir, table2, table3, section32, formulations, provenance)
    return TablesSummary(table2, table3, section32, formulations, paths, seconds, len(results) - cached, cached,
                         mode, statuses)
