"""Where a sweep's formulations are computed: a local process pool (the default) or a Dask cluster.

:func:`analysis.sweeps.complexity.sweep` decides *what* to compute (cache look-up, progress, storing each
result as it arrives); an executor decides *where*. Both executors run the same task,
:func:`analysis.sweeps.complexity.compute_formulation` on every (prime, seed) instance of one formulation, in
a child process that is killed when it exceeds the wall-clock cap (status ``timeout``); the F4 matrix
caps (rows x cols and estimated working memory, :class:`analysis.engine.f4.F4Options`) stop a formulation
with status ``too-large``. Either way the result names its formulation and goes into the table and
the cache: a capped task is reported, never dropped.

* :class:`LocalPool`: ``jobs`` spawned worker processes on this machine. It and :class:`SweepTask` are
  defined in :mod:`analysis.sweeps.complexity` beside the pool they drive (the default of
  :func:`~analysis.sweeps.complexity.sweep`) and re-exported here, so this module builds on that one and not
  the other way round.
* :class:`DaskExecutor`: chunks of formulations are submitted to a ``dask.distributed`` scheduler
  (``--dask ADDRESS``) or to a LocalCluster started here (``--dask local``). Each chunk is a Dask task
  whose key is a hash of its content (formulations, primes, seeds, caps, engine version), so a chunk
  submitted twice is computed once; results come back to the client, which stores each one in the
  sweep's cache as its chunk completes, so an interrupted sweep resumes with the chunks not yet done.
  On the worker a chunk runs through a local pool of one child process (the time cap needs a process
  to kill), so Dask workers must be allowed to start processes: ``--dask local`` arranges it, a remote
  worker needs ``DASK_DISTRIBUTED__WORKER__DAEMON=False`` in its environment.

dask is imported only by :class:`DaskExecutor` (an optional dependency: ``pip install -e ".[dask]"``).
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Callable, Protocol, Sequence

from .complexity import FormulationResult, InstanceOutcome, LocalPool, SweepTask, combine
from ..engine.f4 import F4Options
from ..formulations.tdoa import Formulation

__all__ = ["DaskExecutor", "Executor", "ExecutorError", "LocalPool", "SweepTask", "make_executor", "run_chunk"]


class ExecutorError(ValueError):
    """A bad executor specification (e.g. a malformed or unreachable ``--dask`` address)."""


class Executor(Protocol):
    """Computes formulations and hands each result to ``finish`` as soon as it is known."""

    def run(self, labels: list[str], task: SweepTask, finish: Callable[[FormulationResult], None]) -> None: ...


def run_chunk(labels: Sequence[str], task: SweepTask) -> list[dict]:
    """Compute one chunk on a Dask worker (a local pool of one process): the results as plain dicts."""
    import multiprocessing

    if task.timeout is not None and multiprocessing.current_process().daemon:
        raise RuntimeError("this Dask worker is a daemonic process and cannot start the child process that "
                           "enforces the time cap: start the workers with DASK_DISTRIBUTED__WORKER__DAEMON=False")
    out: list[dict] = []
    LocalPool(jobs=1).run(list(labels), task, lambda r: out.append(r.to_dict()))
    return out


_ADDRESS_RE = re.compile(r"^(?:(tcp|tls|ws|wss|inproc|ucx)://)?([A-Za-z0-9_.\-\[\]:]+?)(?::(\d{1,5}))?/?$")


def _check_address(address: str) -> str:
    """``local`` or a scheduler address ``[tcp://]host:port``; anything else raises ExecutorError."""
    if address == "local":
        return address
    match = _ADDRESS_RE.match(address.strip())
    if match is None or not match.group(2) or (match.group(1) in (None, "tcp", "tls", "ws", "wss")
                                                 and match.group(3) is None):
        raise ExecutorError(f"--dask {address!r} is not a scheduler address; give 'local' or host:port "
                            "(e.g. tcp://10.0.0.5:8786)")
    if match.group(3) is not None and not 0 < int(match.group(3)) < 65536:
        raise ExecutorError(f"--dask {address!r}: port {match.group(3)} is out of range")
    return address.strip()


@dataclass
class DaskExecutor:
    """Chunks of formulations as Dask tasks (module docstring).

    address: ``"local"`` (a LocalCluster in this process: ``workers`` threads, each running its chunk in
    a child process) or a scheduler address. chunk_size: formulations per task. connect_timeout:
    seconds to reach the scheduler before giving up with :class:`ExecutorError`.
    """

    address: str
    chunk_size: int = 4
    workers: int = 1
    connect_timeout: float = 20.0

    def __post_init__(self) -> None:
        self.address = _check_address(self.address)
        if self.chunk_size < 1:
            raise ExecutorError(f"chunk size must be at least 1, got {self.chunk_size}")
        if self.workers < 1:
            raise ExecutorError(f"workers must be at least 1, got {self.workers}")

    def _client(self):
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError as e:  # an optional dependency
            raise ExecutorError("--dask needs dask.distributed: pip install -e \".[dask]\" "
                                f"(or pip install 'dask[distributed]'); import failed: {e}") from None
        if self.address == "local":
            cluster = LocalCluster(n_workers=1, threads_per_worker=self.workers, processes=False,
                                   dashboard_address=None)
            return Client(cluster), cluster
        try:
            return Client(self.address, timeout=f"{self.connect_timeout}s"), None
        except (OSError, TimeoutError) as e:
            raise ExecutorError(f"--dask {self.address}: cannot reach a Dask scheduler there ({e})") from None

    def run(self, labels: list[str], task: SweepTask, finish: Callable[[FormulationResult], None]) -> None:
        from dask.distributed import as_completed

        client, cluster = self._client()
        try:
            chunks = [labels[i:i + self.chunk_size] for i in range(0, len(labels), self.chunk_size)]
            futures, chunk_of = [], {}
            for chunk in chunks:
                future = client.submit(run_chunk, chunk, task, key=task.key(chunk), pure=True)
                futures.append(future)
                chunk_of[future.key] = chunk
            for future in as_completed(futures):
                chunk = chunk_of[future.key]
                try:
                    dicts = future.result()
                except Exception as e:  # a worker died or the task raised: every formulation is reported
                    message = f"Dask task failed: {type(e).__name__}: {e}".splitlines()[0]
                    for label in chunk:
                        finish(_failed(label, task, message))
                    continue
                for d in dicts:
                    finish(FormulationResult.from_dict(d))
        finally:
            client.close()
            if cluster is not None:
                cluster.close()


def _failed(label: str, task: SweepTask, message: str) -> FormulationResult:
    """An ``error`` result for a formulation whose Dask task failed."""
    formulation = Formulation.parse(label)
    marks = [InstanceOutcome(p, s, "error", message=message) for p in task.primes for s in task.seeds]
    return combine(formulation, marks, task.primes, task.seeds, F4Options(**task.options), task.timeout,
                   task.saturate)


def make_executor(dask: str | None, jobs: int, chunk_size: int = 4) -> Executor:
    """``--dask`` / ``--jobs`` -> an executor: Dask when an address (or ``local``) is given, else a local
    pool of ``jobs`` processes."""
    if dask is None:
        return LocalPool(jobs)
    return DaskExecutor(dask, chunk_size=chunk_size, workers=max(1, jobs))
