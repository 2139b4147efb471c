"""`tdoa-workbench reproduce` reproduces: a rerun writes the same bytes (issue 34 item 1).

A slice of the reproduction (Table 4 with a few trials of both initialisations; marked slow: also Figs. 1-2 at
one noise level) runs twice into two directories, each time computing every trial afresh (an empty batch cache of its own)
in the same worker pool, whose workers have run other batches in between (a trial must not depend on
the history of the process that runs it). Every file it writes must be the same byte for byte.
"""
from __future__ import annotations

import json

import pandas as pd
import pytest

from solvers.experiments import batches, reproduction

TABLE4 = {"table4.csv", "table4.md", "table4.tex", "experiments_provenance.json"}
FIGURES = {f"figures/{fig}.{ext}" for fig in ("fig1_histograms", "fig2_noise") for ext in ("csv", "png", "pdf")}


def _twice(tmp_path, monkeypatch, trials: int, figures: bool, jobs: int):
    """The slice run twice into tmp_path/tables0, tables1; returns the two directories."""
    outs, computed = [], []
    with batches.WorkerPool(jobs) as pool:
        for k in range(2):
            monkeypatch.setattr(batches, "CACHE_DIR", tmp_path / f"cache{k}")  # every trial computed again
            out = tmp_path / f"tables{k}"
            common = dict(jobs=jobs, tables_dir=out, progress=False, pool=pool, echo=None, mode="test")
            _, frames = reproduction.build_table4(trials, **common)
            if figures:
                reproduction.build_figures(trials, (1e-3,), trials, frames=frames, **common)
            outs.append(out)
            computed.append(sorted(p.name for p in (tmp_path / f"cache{k}").glob("*.csv")))
    assert computed[0] == computed[1] and len(computed[0]) == (8 if figures else 4)  # every batch computed
    return outs


@pytest.mark.parametrize("trials, figures, jobs", [
    (3, False, 1),
    pytest.param(6, True, 2, marks=pytest.mark.slow),  # the figures' rendering and sweep: ~60 s at load 8
])
def test_a_reproduce_slice_rerun_writes_the_same_bytes(tmp_path, monkeypatch, trials, figures, jobs):
    outs = _twice(tmp_path, monkeypatch, trials, figures, jobs)
    files = sorted(p.relative_to(outs[0]).as_posix() for p in outs[0].rglob("*") if p.is_file())
    tracked = [f for f in files if not f.endswith(".timing.json")]
    assert set(tracked) == (TABLE4 | FIGURES if figures else TABLE4)
    for name in tracked:
        assert (outs[0] / name).read_bytes() == (outs[1] / name).read_bytes(), f"{name} differs between two runs"
    # the slice is a real one: both initialisations ran, the solver rows are accurate, the random ones are not
    written = pd.read_csv(outs[0] / "table4.csv")
    assert (written["status"] == "ok").all() and (written["trials"] == trials).all()
    ours, rand = written[written["init"] == "ours"], written[written["init"] == "rand"]
    assert (ours["median_log10_position_error"] < -10).all() and (ours["failure_rate"] == 0).all()
    assert (rand["failure_rate"] > 0).any()
    # and what differs between the runs (runtimes, dates) is in the untracked timing record only
    timing = [json.loads((out / "experiments_provenance.timing.json").read_text()) for out in outs]
    assert all("median_runtime_ms" in t["artefacts"]["table4"]["rows"][1] for t in timing)
    assert not any(c.endswith("_ms") for c in written.columns)
