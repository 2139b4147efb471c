"""Sweep executors: the local pool and Dask give the same results; caps are reported, never dropped."""
from __future__ import annotations

import pytest

from analysis.sweeps import executors
from analysis.sweeps.complexity import FormulationResult, sweep
from analysis.sweeps.executors import DaskExecutor, ExecutorError, LocalPool, SweepTask, make_executor

pytest.importorskip("dask.distributed", reason="pip install -e '.[dev]' installs dask[distributed]")

F9 = "9r3s:C2-C9"
F6 = "6r4s:B2,C2-C6,minors(10)"


def _comparable(r: FormulationResult) -> dict:
    d = r.to_dict()
    d.pop("seconds")
    for o in d["instances"]:
        o.pop("seconds")
    return d


def test_dask_local_cluster_gives_the_local_pools_results_and_resumes_from_the_cache(tmp_path):
    local = sweep([F9, F6], seeds=(0,), jobs=1, timeout=120, cache_dir=tmp_path / "local", progress=False)
    dask = DaskExecutor("local", chunk_size=1)
    first = sweep([F9], seeds=(0,), timeout=120, cache_dir=tmp_path / "dask", progress=False, executor=dask)
    flags = []
    both = sweep([F9, F6], seeds=(0,), timeout=120, cache_dir=tmp_path / "dask", progress=False, executor=dask,
                 on_result=lambda r, cached: flags.append((r.label, cached)))
    assert [r.degree for r in both] == [75, 22]
    assert [_comparable(r) for r in both] == [_comparable(r) for r in local]
    assert _comparable(first[0]) == _comparable(local[0])
    # the second sweep took F9 from the cache written by the first (an interrupted sweep resumes)
    assert flags == [(F9, True), (F6, False)]


def test_a_task_over_its_time_cap_is_reported_with_its_formulation(tmp_path):
    (r,) = sweep(["7r3s:A,B2,C2-C7"], seeds=(0,), timeout=0.01, cache_dir=tmp_path, progress=False,
                 executor=DaskExecutor("local"))
    assert r.label == "7r3s:A,B2,C2-C7" and r.status == "timeout" and r.degree is None
    assert "wall-clock limit of 0.01 s" in r.message


def test_a_failed_dask_task_reports_every_formulation_of_its_chunk(tmp_path, monkeypatch):
    def broken(labels, task):
        raise MemoryError("worker ran out of memory")

    monkeypatch.setattr(executors, "run_chunk", broken)
    results = sweep([F9, F6], seeds=(0,), timeout=60, cache_dir=tmp_path, progress=False,
                    executor=DaskExecutor("local", chunk_size=2))
    assert [r.label for r in results] == [F9, F6]
    assert all(r.status == "error" and "MemoryError" in r.message for r in results)


def test_chunk_keys_are_content_keys():
    task = SweepTask((65521,), (0,), {"max_matrix_cells": 10}, False, 0, 5.0)
    assert task.key([F9, F6]) == SweepTask((65521,), (0,), {"max_matrix_cells": 10}, False, 0, 5.0).key([F9, F6])
    assert task.key([F9, F6]) != task.key([F6, F9])
    assert task.key([F9]) != SweepTask((65521,), (0,), {"max_matrix_cells": 10}, False, 0, 6.0).key([F9])


@pytest.mark.parametrize("address", ["", "tcp://", "host", "tcp://host", "local cluster", "tcp://host:99999",
                                     "http://host:8786", "host:port"])
def test_bad_dask_addresses_are_refused_before_connecting(address):
    with pytest.raises(ExecutorError, match="--dask"):
        DaskExecutor(address)


def test_make_executor_defaults_to_the_local_pool():
    assert make_executor(None, 3) == LocalPool(3)
    assert isinstance(make_executor("tcp://127.0.0.1:8786", 1), DaskExecutor)
    with pytest.raises(ExecutorError):
        make_executor("local", 1, chunk_size=0)


def test_an_unreachable_scheduler_is_a_clear_error(tmp_path):
    executor = DaskExecutor("tcp://127.0.0.1:9", connect_timeout=2)
    with pytest.raises(ExecutorError, match="cannot reach a Dask scheduler"):
        sweep([F9], seeds=(0,), timeout=60, cache_dir=tmp_path, progress=False, executor=executor)


def test_the_cli_refuses_a_bad_dask_address_in_one_line(capsys):
    from solvers.cli import main

    assert main(["tables", "--dask", "tcp://nohost"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--dask 'tcp://nohost' is not a scheduler address" in err[0]
