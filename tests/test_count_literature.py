"""The literature problems of scripts/count_literature.py: the committed system files and start pairs are the
script's builders' output and solve their systems, the committed table is what the script computes now (one cheap
row here, a few end to end in the slow suite), and a row agrees only when the count is the published one."""
from __future__ import annotations

import csv
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from analysis.formulations.parametric import parse

ROOT = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("count_literature", ROOT / "scripts" / "count_literature.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


LIT = _script()


def _committed() -> dict[str, dict]:
    with open(ROOT / "tables" / "count_literature.csv", newline="", encoding="utf-8") as fh:
        return {r["file"]: r for r in csv.DictReader(fh)}


def _as_text(row: dict) -> dict:
    return {k: "" if v is None else str(v) for k, v in row.items()}


@pytest.mark.parametrize("stem", [p[0] for p in LIT.PROBLEMS])
def test_the_committed_system_files_and_start_pairs_are_the_scripts(stem):
    problem = next(p for p in LIT.PROBLEMS if p[0] == stem)
    sys_path, start_path = LIT.paths(stem)
    text = Path(sys_path).read_text(encoding="utf-8")
    if problem[4] is not None:
        assert text == problem[4](), f"{sys_path} is stale: python scripts/count_literature.py --write-examples"
    system = parse(text, stem)
    draw = problem[5]
    if callable(draw):
        q, x = draw(np.random.default_rng(problem[6]))
        assert Path(start_path).read_text(encoding="utf-8") == LIT.start_json(q, x)
    if draw is not None:  # every committed start pair solves its system, and a moved root does not
        pair = json.loads(Path(start_path).read_text(encoding="utf-8"))
        q = np.array([complex(*v) for v in pair["parameters"]])
        x = np.array([complex(*v) for v in pair["root"]])
        assert LIT.residual(system, q, x) < 1e-10
        assert LIT.residual(system, q, x + 1e-3) > 1e-6
        # an equation without a parameter is why the pair is given
        assert any(not (f.free_symbols & set(system.q_symbols)) for f in system.exprs)


def test_the_published_ed_degrees_follow_the_formula():
    assert [LIT.ed_degree(n, d) for n, d in ((2, 3), (2, 4), (3, 3), (3, 4), (4, 3))] == [9, 16, 21, 52, 45]


def test_the_committed_table_is_current_for_a_cheap_row():
    """dense3_2 (8 solutions, a few seconds) recomputed: every column of the committed row, the residual included."""
    row, _ = LIT.run_row("dense3_2")
    assert _as_text(row) == _committed()["examples/dense3_2.sys"]


def test_the_committed_rows_agree_only_when_they_should():
    rows = _committed()
    assert len(rows) == len(LIT.PROBLEMS) and all(r["source"] for r in rows.values())
    for r in rows.values():
        agrees = (r["solutions"] == r["proven"] == r["published"] and r["scope"] == "whole solution set"
                  and r["trace_test"] == "passed")
        assert (r["agrees"] == "yes") == agrees, r


@pytest.mark.slow
@pytest.mark.parametrize("stem", ["rpr3", "stewart40", "sixr16", "fivepoint20", "ed3_3"])
def test_literature_rows_end_to_end(stem):
    """The kinematics and pose rows (start pairs given, parameter-free equations) and one ED degree, each `count`
    with two seeds and the trace test, as committed; 10-60 s a row."""
    row, _ = LIT.run_row(stem)
    assert row["solutions"] == row["published"] == row["proven"] and row["agrees"] == "yes", row
    assert _as_text(row) == _committed()[f"examples/{stem}.sys"]


def test_docs_quote_the_committed_table():
    """docs/count.md's table of the literature problems is tables/count_literature.md's, row for row."""
    table = (ROOT / "tables" / "count_literature.md").read_text(encoding="utf-8")
    rows = [line for line in table.splitlines() if line.startswith("| ")]
    page = (ROOT / "docs" / "count.md").read_text(encoding="utf-8")
    section = page[page.index("## Problems from the literature"):]
    section = section[:section.index("\n## ")]
    assert [line for line in section.splitlines() if line.startswith("| ")] == rows
