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


def test_3d_tables_are_rendered_from_their_csv():
    """tables/calibration3d.md from calibration3d.csv (the same renderer); tables/hypotheses3d.* exist together."""
    bench = _script()
    with open(ROOT / "tables" / "calibration3d.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert {r["cell"] for r in rows} >= {"12r/8s", "16r/10s"}
    assert "sec_med" not in rows[0], "run facts (seconds) belong in the untracked timing file"
    assert (ROOT / "tables" / "calibration3d.md").read_text() == bench.markdown(rows)
    with open(ROOT / "tables" / "hypotheses3d.csv", newline="") as handle:
        hyp = list(csv.DictReader(handle))
    assert {r["solver"] for r in hyp} >= {"12r5s-stratified", "9r5s3d"}
    assert all(r["sigma"] + " |" in (ROOT / "tables" / "hypotheses3d.md").read_text() for r in hyp)
