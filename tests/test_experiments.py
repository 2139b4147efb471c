"""Tests for solvers.experiments: trial records, seeding, solver wiring, Table 4 writer, cache.

The solver-initialised accuracy test needs the real algebraic solvers (``solvers.api``) and is
skipped with the reason when they are unavailable; the wiring of that path is checked against a
stub API that only knows the ground truth of the seeded networks (its numbers are never written).
"""

import json
import math
import sys
import types

import numpy as np
import pandas as pd
import pytest

from solvers import experiments as ex
from solvers.experiments import batches
from solvers.recovery import Calibration
from solvers.refine import random_initial
from solvers.synthetic import random_network

@pytest.fixture(autouse=True)
def _private_cache(tmp_path, monkeypatch):
    """Never read or pollute the repository's cache from the tests."""
    monkeypatch.setattr(batches, "CACHE_DIR", tmp_path / "cache")


def _seeded_network(config, seed, sigma=0.0):
    """The documented seeding: one generator draws the network, then the noise."""
    m, n = ex.config_shape(config)
    rng = np.random.default_rng(seed)
    network = random_network(m, n, rng)
    return network, network.measurements(sigma, rng)


def _stub_api(configs, seeds, mode="truth"):
    """A stand-in ``solvers.api`` that returns a perturbed ground truth and a random candidate."""
    lookup = {}
    for config in configs:
        for seed in seeds:
            network, F = _seeded_network(config, seed)
            lookup[F.tobytes()] = network

    def solve_network(F, refine=True):
        assert refine is False, "the experiment must ask for unrefined candidates"
        network = lookup[np.asarray(F, dtype=float).tobytes()]
        if mode == "none":
            return []
        if mode == "linalg":
            raise np.linalg.LinAlgError("singular template")
        if mode == "bug":
            raise RuntimeError("bug in the solver")
        rng = np.random.default_rng(99)
        good = Calibration(
            network.receivers + 1e-4 * rng.standard_normal(network.receivers.shape),
            network.transmitters + 1e-4 * rng.standard_normal(network.transmitters.shape),
            network.offsets + 1e-4 * rng.standard_normal(network.n),
            1e-4,
        )
        bad = Calibration(*random_initial(network.m, network.n, rng), 1.0)
        return [good, bad]

    module = types.ModuleType("solvers.api")
    module.solve_network = solve_network
    return module


def test_run_trials_random_has_documented_columns():
    for config in ("9r3s", "6r/4s"):
        frame = ex.run_trials(config, "random", 5, jobs=1, cache=False, progress=False)
        assert list(frame.columns) == list(ex.TRIAL_COLUMNS)
        assert len(frame) == 5
        assert frame["seed"].tolist() == [ex.DEFAULT_SEED + t for t in range(5)]
        assert set(frame["config"]) == {config.replace("/", "")}
        assert set(frame["init"]) == {"random"}
        assert (frame["n_refined"] == 1).all()
        assert frame["solver_s"].isna().all() and frame["n_real_candidates"].isna().all()
        assert (frame["lm_s"] > 0).all() and np.allclose(frame["total_s"], frame["lm_s"])
        assert set(frame["outcome"]) <= set(ex.OUTCOMES)
        ok = frame[~frame["failed"]]
        assert (ok[["position_error", "offset_error"]] <= 1e-6).all().all()
        # noiseless: LM from the ground truth stays there
        assert (frame["oracle_position_error"] < 1e-12).all()
        np.testing.assert_allclose(frame["log10_position_error"], np.log10(np.maximum(frame["position_error"], 1e-300)))


def test_trial_seeding_is_documented_and_reproducible():
    network, F = _seeded_network("6r4s", 7)
    record = ex.run_trial("6r4s", "random", seed=7)
    # the random start is drawn after the network (and the noise) from the same generator
    rng = np.random.default_rng(7)
    random_network(6, 4, rng)
    start = random_initial(6, 4, rng)
    from solvers.metrics import position_error

    assert record["initial_position_error"] == position_error(types.SimpleNamespace(
        receivers=start[0], transmitters=start[1]), network)
    again = ex.run_trial("6r4s", "random", seed=7)
    assert again["initial_offset_error"] == record["initial_offset_error"]
    assert again["oracle_residual"] == record["oracle_residual"]


def test_noise_is_drawn_after_the_network():
    quiet = ex.run_trial("9r3s", "random", seed=3, sigma=0.0)
    noisy = ex.run_trial("9r3s", "random", seed=3, sigma=1e-3)
    assert quiet["oracle_residual"] < 1e-12 < noisy["oracle_residual"]
    assert noisy["sigma"] == 1e-3


def test_solver_path_wiring_with_stub_api(monkeypatch):
    monkeypatch.setitem(sys.modules, "solvers.api", _stub_api(["9r3s", "6r4s"], range(4)))
    for config in ("9r3s", "6r4s"):
        frame = ex.run_trials(config, "solver", 4, jobs=1, cache=False, progress=False)
        assert list(frame.columns) == list(ex.TRIAL_COLUMNS)
        assert (frame["n_real_candidates"] == 2).all()
        assert (frame["n_refined"] == 2).all()  # refine_candidates=3 but only 2 candidates
        assert (frame["solver_s"] > 0).all()
        assert (frame["log10_position_error"] < -8).all() and (frame["log10_offset_error"] < -8).all()
        assert not frame["failed"].any() and set(frame["outcome"]) == {"ok"}


def test_solver_path_failures_are_recorded(monkeypatch):
    monkeypatch.setitem(sys.modules, "solvers.api", _stub_api(["6r4s"], [5], mode="none"))
    record = ex.run_trial("6r4s", "solver", seed=5)
    assert record["failed"] and record["outcome"] == "no_candidate"
    assert math.isnan(record["position_error"]) and record["n_real_candidates"] == 0
    monkeypatch.setitem(sys.modules, "solvers.api", _stub_api(["6r4s"], [5], mode="linalg"))
    assert ex.run_trial("6r4s", "solver", seed=5)["outcome"] == "solver_error"
    monkeypatch.setitem(sys.modules, "solvers.api", _stub_api(["6r4s"], [5], mode="bug"))
    with pytest.raises(ex.TrialError, match="seed=5"):
        ex.run_trial("6r4s", "solver", seed=5)


def test_missing_api_raises_named_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "solvers.api", None)  # makes the import fail
    with pytest.raises(ex.SolverUnavailable):
        ex.run_trials("9r3s", "solver", 2, jobs=1, cache=False, progress=False)
    available, reason = ex.solver_status()
    assert not available and "solvers.api" in reason


def test_solver_initialised_noiseless_trials_are_accurate():
    available, reason = ex.solver_status()
    if not available:
        pytest.skip(f"algebraic solvers unavailable: {reason}")
    # worker processes run with one BLAS thread, as the scripts and the CLI do (the solvers'
    # results depend on the BLAS summation order on hard instances)
    with ex.WorkerPool(2) as pool:
        frames = {
            config: ex.run_trials(config, "solver", 5, cache=False, progress=False, pool=pool, chunk_size=1)
            for config in ("9r3s", "6r4s")
        }
    for config, frame in frames.items():
        bad = frame[~(frame["log10_position_error"] < -8) | ~(frame["log10_offset_error"] < -8)]
        assert bad.empty, f"{config}: seeds {bad['seed'].tolist()} not accurate"
        assert (frame["n_real_candidates"] >= 1).all()
        assert (frame["n_real_candidates"] <= frame["n_real_roots"]).all()
        assert (frame["n_real_roots"] <= frame["n_roots"]).all()
        assert (frame["solver_s"] > 0).all()
        assert not frame["failed"].any()


def test_cache_hit_on_rerun(monkeypatch, tmp_path):
    first = ex.run_trials("6r4s", "random", 3, sigma=1e-3, seed=11, jobs=1, progress=False)
    files = sorted((tmp_path / "cache").glob("*.csv"))
    assert len(files) == 1 and files[0].with_suffix(".json").exists()

    def no_work(self, function, tasks):  # cached batches are computed in workers
        raise AssertionError("cache miss: trials were recomputed")

    monkeypatch.setattr(batches.WorkerPool, "imap", no_work)
    second = ex.run_trials("6r4s", "random", 3, sigma=1e-3, seed=11, jobs=1, progress=False)
    pd.testing.assert_frame_equal(first, second)
    assert first.attrs["batch"]["status"] == "computed" and second.attrs["batch"]["status"] == "cache hit"
    assert second.attrs["batch"]["compute_seconds"] > 0
    # any parameter change is a different key
    with pytest.raises(AssertionError, match="cache miss"):
        ex.run_trials("6r4s", "random", 3, sigma=1e-3, seed=12, jobs=1, progress=False)
    with pytest.raises(AssertionError, match="cache miss"):
        ex.run_trials("6r4s", "random", 3, sigma=1e-3, seed=11, jobs=1, progress=False,
                      options=ex.TrialOptions(max_iter=50))


def test_table4_writer_has_paper_columns(tmp_path):
    frames = {
        ("9r3s", "random"): ex.run_trials("9r3s", "random", 3, jobs=1, cache=False, progress=False),
        ("6r4s", "random"): ex.run_trials("6r4s", "random", 3, jobs=1, cache=False, progress=False),
        ("9r3s", "solver"): "solver unavailable",
    }
    table = ex.table4(frames)
    assert list(table.columns) == list(ex.TABLE4_COLUMNS)
    assert table[["solver", "init"]].values.tolist() == [
        ["9r/3s", "rand"], ["9r/3s", "ours"], ["6r/4s", "rand"], ["6r/4s", "ours"]
    ]
    assert table["paper_median_log10_position_error"].tolist() == [0.31, -15, 0.55, -15]
    assert table["paper_median_log10_offset_error"].tolist() == [1.63, -14, 1.93, -14]
    assert table["status"].tolist() == ["ok", "solver unavailable", "ok", "not run"]
    assert table.loc[1, ["median_log10_position_error", "failure_rate"]].isna().all()  # no made-up numbers

    paths = ex.write_table4(table, tmp_path, {"commit": "abc", "date": "monday", "mode": "test", "seeds": "0..2"})
    written = pd.read_csv(paths["csv"])
    assert list(written.columns) == [c for c in ex.TABLE4_COLUMNS if not c.endswith("_ms")]  # results only
    md = paths["md"].read_text()
    assert "Position log10 (paper)" in md and "Offset log10 (ours)" in md and "Failure rate" in md
    assert "| 9r/3s | ours | n/a | -15.00 |" in md and "test run, seeds 0..2" in md
    assert "abc" not in md and "monday" not in md and "(ms)" not in md
    tex = paths["tex"].read_text()
    assert r"\begin{tabular}" in tex and "9r/3s rand" in tex and tex.count(r"\\") >= 6


def test_a_rerun_with_the_same_results_rewrites_no_table(tmp_path):
    """Table 4 from a rerun that measured other runtimes, on another commit and date, but the same results:
    no file changes (the files hold no runtime, commit or date); other results do change them."""
    frames = {(config, "random"): ex.run_trials(config, "random", 3, jobs=1, cache=False, progress=False)
              for config in ("9r3s", "6r4s")}
    paths = ex.write_table4(ex.table4(frames), tmp_path, {"commit": "abc", "date": "monday", "mode": "test"})
    before = {p: p.read_bytes() for p in paths.values()}
    slower = ex.table4({key: frame.assign(total_s=frame["total_s"] * 3, lm_s=frame["lm_s"] * 3)
                        for key, frame in frames.items()})
    assert not slower["median_runtime_ms"].equals(ex.table4(frames)["median_runtime_ms"])
    ex.write_table4(slower, tmp_path, {"commit": "def", "date": "tuesday", "mode": "test"})
    assert {p: p.read_bytes() for p in paths.values()} == before
    ex.write_table4(slower.assign(failure_rate=slower["failure_rate"] + 0.5), tmp_path, {"mode": "test"})
    assert all(p.read_bytes() != before[p] for p in paths.values())


def test_committed_provenance_holds_results_only(tmp_path):
    """experiments_provenance.json gets the record without run facts (dates, commit, machine, wall times,
    runtimes in ms, at any depth); the untracked timing record beside it keeps them all."""
    from solvers.experiments.provenance import provenance, update_provenance

    path = tmp_path / "experiments_provenance.json"
    meta = provenance(mode="test", seeds="0..2", rows=[{"failure_rate": 0.5, "median_runtime_ms": 7.5}],
                      wall_seconds=1.5)
    update_provenance({"table4": meta}, path)
    tracked, timing = json.loads(path.read_text()), json.loads(path.with_name(path.stem + ".timing.json").read_text())
    section = tracked["artefacts"]["table4"]
    assert section["rows"] == [{"failure_rate": 0.5}] and section["mode"] == "test"
    assert not {"date", "commit", "machine", "versions", "wall_seconds"} & set(section) and "updated" not in tracked
    assert timing["artefacts"]["table4"]["rows"][0]["median_runtime_ms"] == 7.5 and "date" in timing["artefacts"]["table4"]
    before = path.read_bytes()
    update_provenance({"table4": provenance(mode="test", seeds="0..2", rows=[{"failure_rate": 0.5, "median_runtime_ms": 9.0}],
                                            wall_seconds=3.0)}, path)
    assert path.read_bytes() == before  # another run's facts, the same results: the same bytes


def test_summary_counts_missing_estimates_as_infinite():
    frame = ex.run_trials("6r4s", "random", 3, jobs=1, cache=False, progress=False)
    frame.loc[:, "position_error"] = [1e-3, np.nan, np.nan]
    summary = ex.summarise(frame)
    assert summary.loc[0, "median_log10_position_error"] == np.inf
    assert summary.loc[0, "q25_log10_position_error"] == pytest.approx(-3)


def test_figures_plot_the_trials_and_say_what_they_are(tmp_path):
    """Fig. 1's data file holds the trials' log10 errors binned (recounted here with numpy, errors outside
    the range in the end bins); Fig. 2's holds the summary's medians; the images carry their title."""
    frame = ex.run_trials("6r4s", "random", 3, jobs=1, cache=False, progress=False)
    paths = ex.plot_histograms({("6r4s", "random"): frame}, tmp_path / "fig1", {"commit": "abc"})
    assert {p.suffix for p in paths} == {".png", ".pdf", ".csv"}
    assert b"Fig. 1" in (tmp_path / "fig1.png").read_bytes()  # PNG tEXt metadata
    bins = pd.read_csv(tmp_path / "fig1.csv")
    edges = np.arange(-17.0, 4.0 + 1e-9, 0.25)
    for quantity in ("position", "offset"):
        rows = bins[(bins["config"] == "6r4s") & (bins["init"] == "random") & (bins["quantity"] == quantity)]
        errors = frame[f"{quantity}_error"].dropna().to_numpy(dtype=float)
        expected, _ = np.histogram(np.clip(np.log10(errors), edges[0], edges[-1]), bins=edges)
        assert rows["bin_lo"].tolist() == pytest.approx(edges[:-1].tolist())
        assert rows["count"].tolist() == expected.tolist() and rows["count"].sum() == len(errors) == 3
    assert set(bins["config"] + bins["init"]) == {"6r4srandom"}  # no rows for configurations not run
    sweep = ex.noise_sweep(["6r4s"], ["random"], [1e-4, 1e-2], 2, jobs=1, cache=False, progress=False)
    summary = ex.summarise(sweep)
    paths = ex.plot_noise(summary, tmp_path / "fig2", {"commit": "abc"})
    assert b"Fig. 2" in (tmp_path / "fig2.png").read_bytes()
    plotted = pd.read_csv(tmp_path / "fig2.csv")
    want = summary[summary["sigma"] > 0].sort_values(["config", "init", "sigma"])
    assert plotted["sigma"].tolist() == want["sigma"].tolist() == [1e-4, 1e-2]
    for column in ("median_log10_position_error", "median_log10_offset_error"):
        assert plotted[column].to_numpy() == pytest.approx(want[column].to_numpy(), rel=1e-5)  # the CSV keeps 6 digits


def test_invalid_names_list_the_valid_ones():
    with pytest.raises(ValueError, match="9r3s, 6r4s"):
        ex.config_shape("7r4s")
    with pytest.raises(ValueError, match="random, solver"):
        ex.run_trials("9r3s", "best", 1)


def test_paper_values_are_package_data():
    """Table 4's paper numbers ship with the package (``analysis/data/paper_accuracy.csv``, declared as
    package data like ``paper_tables.csv``) and are the paper's."""
    from analysis.sweeps.paths import DATA_DIR
    from solvers.experiments.table import PAPER_ACCURACY_CSV, paper_table4

    assert PAPER_ACCURACY_CSV == DATA_DIR / "paper_accuracy.csv" and PAPER_ACCURACY_CSV.is_file()
    assert ex.PAPER_TABLE4 == paper_table4() == {
        ("9r3s", "random"): (0.31, 1.63), ("9r3s", "solver"): (-15.0, -14.0),
        ("6r4s", "random"): (0.55, 1.93), ("6r4s", "solver"): (-15.0, -14.0),
    }

def test_the_solver_fingerprint_covers_the_experiments_solvers_and_nothing_else():
    """The cache key of solver batches (and the provenance) changes with the 9r/3s and 6r/4s solvers and the
    kernels they import, not with another committed solver (the 3D offset kernel, the homotopies of other cells)."""
    from pathlib import Path

    import solvers
    from solvers.experiments.batches import _solver_sources

    names = {p.name for p in _solver_sources(Path(solvers.__file__).resolve().parent)}
    assert {"tdoa_9r3s_homotopy75.py", "tdoa_9r3s_homotopy75.json", "tdoa_6r4s_pencil37.py", "homotopy.py",
            "tracking.py", "tracker.py", "tape_kernel.py", "slp.py", "pencil.py", "runtime.py"} <= names
    assert not {n for n in names if "9r5s3d" in n or n.startswith(("tdoa_5r5s", "tdoa_4r5s")) or n == "offset_kernel.py"}
