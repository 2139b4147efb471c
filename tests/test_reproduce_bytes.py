"""`tdoa-workbench reproduce` reproduces: a rerun writes the same bytes (issue 34 item 1).

A trial does not depend on what the process's freed memory holds: the random starts of Fig. 2 that diverge,
run again after the heap was filled with other bytes, end where they ended (scipy's MINPACK did not:
docs/reproducibility.md, section 4). A slice of the reproduction (Table 4 with a few trials of both initialisations; marked slow: also Figs. 1-2 at
one noise level) runs twice into two directories, each time computing every trial afresh (an empty batch cache of its own)
in the same worker pool, whose workers have run other batches in between (a trial must not depend on
the history of the process that runs it). Every file it writes must be the same byte for byte.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import json

import numpy as np
import pandas as pd
import pytest

from solvers.experiments import batches, reproduction
from solvers.experiments.trial import run_trial

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


def _libc():
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c"))
        libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
        libc.free.argtypes, libc.memset.argtypes = [ctypes.c_void_p], [ctypes.c_void_p, ctypes.c_int, ctypes.c_size_t]
        return libc
    except (OSError, AttributeError, TypeError):
        return None


def _fill_freed_heap(libc, byte: int) -> None:
    """Allocate blocks of every size up to 8 KB, fill them with `byte` and free them: the next allocations of
    the process (a solver's work arrays) get memory that holds these bytes instead of earlier ones."""
    sizes = list(range(16, 8200, 8)) * 2
    blocks = [libc.malloc(size) for size in sizes]
    for block, size in zip(blocks, sizes):
        libc.memset(block, byte, size)
    for block in blocks:
        libc.free(block)


#: 9r/3s random starts at sigma 1e-3 (Fig. 2's sweep) that diverge, with MINPACK and with "trf". With MINPACK each
#: ended elsewhere (other iteration count, end point and residual) in about half of the runs after the heap was
#: filled with other bytes; this test failed at its first seed in 3 of 3 runs on the code before "trf".
DIVERGING_SEEDS = (49, 51, 145, 186, 187)


@pytest.mark.skipif(_libc() is None, reason="needs the C library's malloc/free (ctypes)")
def test_a_diverging_random_start_does_not_depend_on_what_freed_memory_held():
    libc = _libc()
    timing = {"solver_s", "lm_s", "total_s"}
    for seed in DIVERGING_SEEDS:
        first = run_trial("9r3s", "random", seed, sigma=1e-3)
        assert first["position_error"] > 1e4  # the case that moved: LM from this start diverges
        for byte in (0x00, 0x5A, 0xFF):
            _fill_freed_heap(libc, byte)
            again = run_trial("9r3s", "random", seed, sigma=1e-3)
            differ = {k: (first[k], again[k]) for k in first if k not in timing
                      and not (first[k] == again[k] or (first[k] != first[k] and again[k] != again[k]))}
            assert not differ, f"seed {seed}, heap filled with {byte:#04x}: {differ}"
    assert np.isfinite(first["residual"])
