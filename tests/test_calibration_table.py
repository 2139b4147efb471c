"""The committed calibration benchmark is consistent: tables/calibration.md is what the script renders from
tables/calibration.csv, and the summary in docs/calibrate.md is the script's summary of that CSV (no hand edits)."""
from __future__ import annotations

import csv
import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _script():
    path = ROOT / "scripts" / "bench_calibrate.py"
    spec = importlib.util.spec_from_file_location("bench_calibrate", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _rows():
    with open(ROOT / "tables" / "calibration.csv", newline="") as handle:
        return list(csv.DictReader(handle))


def test_markdown_is_rendered_from_the_csv():
    bench = _script()
    assert (ROOT / "tables" / "calibration.md").read_text() == bench.markdown(_rows())


def test_docs_summary_is_the_scripts_summary_of_the_csv():
    bench = _script()
    table = bench.summary(_rows())
    assert table.count("\n") >= 10  # 8 cells, 2 scale rows, header
    assert table in (ROOT / "docs" / "calibrate.md").read_text()
