"""Monodromy on a Dask cluster: each round's batch of paths split among the workers.

A round of :func:`solvers.continuation.graph.graph_monodromy` tracks every pending (solution, edge) pair in two
batches (the edges one way, then the other); at 10^4-10^5 solutions in 35-45 unknowns a round takes minutes on one core. :class:`DaskSystem` stands in
for the graph's system (``track(q0, q1, x0, inst, options)``; ``newton`` and ``options`` stay with the local
solver): it cuts the batch into chunks of ``chunk`` paths, tracks each on a worker of a ``dask.distributed``
cluster (``address``: a scheduler, or ``"local"`` for a LocalCluster of ``workers`` processes on this machine,
default one per core) and returns the endpoints and statistics in the batch's order. Every path is tracked on its
own (the tracker's step control is per path), so the endpoints, and the count, are the same numbers as in one
process; the client keeps the graph's bookkeeping (matching, checkpoints).

The workers need the system: it travels as text (a formulation label, or a user's system file in the
generator's format, read by the project's parser) with its start pair (q0, x0); each worker builds its start
solver once (compiling the tapes into its own cache directory) and keeps it for the other rounds. dask is
imported only here, when a cluster is asked for (an optional dependency: ``pip install -e ".[dask]"``).
"""
from __future__ import annotations

import dataclasses
import os

import numpy as np

from analysis.formulations.parametric import from_formulation, parse

from .monodromy import start_solver
from .tracker import TrackerOptions
from .tracking import evaluator_for

__all__ = ["DaskSystem", "track_chunk", "track_trace_chunk", "trace_stand_in"]

#: Start solvers built on this worker, by (source, saturate, q0, x0) bytes.
_SOLVERS: dict = {}


def _system(source: str, saturate: bool):
    """A formulation label's system, or a system text's (the generator's format, the project's parser)."""
    if "\n" in source:
        return parse(source, "<dask>")
    return from_formulation(source, saturate_det_h=saturate)


def _solver(source: str, saturate: bool, q0: np.ndarray, x0: np.ndarray):
    key = (source, saturate, q0.tobytes(), x0.tobytes())
    if key not in _SOLVERS:
        _SOLVERS.clear()  # one system per count: keep the memory of one solver
        system = _system(source, saturate)
        _SOLVERS[key] = start_solver(system, q0, x0, evaluator=evaluator_for(system.name))[0]
    return _SOLVERS[key]


def track_chunk(source: str, saturate: bool, q0: np.ndarray, x0: np.ndarray, qa: np.ndarray, qb: np.ndarray,
                xs: np.ndarray, inst: np.ndarray, options: dict) -> tuple[np.ndarray, np.ndarray]:
    """Endpoints and statistics of the paths xs (K, N), path k along qa[inst[k]] -> qb[inst[k]] (a worker's task)."""
    return _solver(source, saturate, q0, x0).track(qa, qb, xs, inst, TrackerOptions(**options))


def _trace_system(source: str, saturate: bool, square: tuple[bool, ...]):
    key = ("trace", source, saturate, square)
    if key not in _SOLVERS:
        _SOLVERS.clear()
        from . import trace  # here: trace imports the graph, the graph nothing of this module

        _SOLVERS[key] = trace.TraceSystem(*trace.system_equations(_system(source, saturate)), square)
    return _SOLVERS[key]


def track_trace_chunk(source: str, saturate: bool, square: tuple[bool, ...], qa: np.ndarray, qb: np.ndarray,
                      xs: np.ndarray, inst: np.ndarray, options: dict) -> tuple[np.ndarray, np.ndarray]:
    """:func:`track_chunk` for the trace test's system of ``source`` (:class:`.trace.TraceSystem`, its pencil
    squaring the coordinates ``square`` flags)."""
    return _trace_system(source, saturate, square).track(qa, qb, xs, inst, TrackerOptions(**options))


def trace_stand_in(address, source: str, saturate: bool, chunk: int = 2000):
    """For :func:`.trace.trace_test`'s ``dask``: a function of the local TraceSystem that returns its DaskSystem
    (the workers build the same trace system from ``source``)."""

    def make(system) -> "DaskSystem":
        return DaskSystem(address, system, source, saturate, None, None, chunk, square=tuple(system.square.tolist()))

    return make


class DaskSystem:
    """The graph's system with its tracking on a Dask cluster (module docstring). ``solver``: the local start
    solver (Newton steps, options); ``source``: the system as text (a formulation label or a system file's text);
    ``square``: given, the workers track the trace test's system of ``source`` with this pencil (q0, x0 unused);
    ``address``: a scheduler address, ``"local"``, or a ``dask.distributed.Client`` already connected (then not
    closed here). Use as a context manager, or call :meth:`close`; a bad address raises ValueError in one line."""

    def __init__(self, address, solver, source: str, saturate: bool, q0: np.ndarray | None, x0: np.ndarray | None,
                 chunk: int = 2000, workers: int | None = None, square: tuple[bool, ...] | None = None):
        workers = workers or os.cpu_count() or 1
        if chunk < 1 or workers < 1:
            raise ValueError(f"chunk and workers must be at least 1, got {chunk} and {workers}")
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError as e:
            raise ValueError("--dask needs dask.distributed: pip install -e \".[dask]\" "
                             f"(or pip install 'dask[distributed]'); import failed: {e}") from None
        self.solver, self.source, self.saturate, self.chunk = solver, source, saturate, chunk
        self.options = solver.options
        self.square = square  # the trace test's system (track_trace_chunk), else the start solver's
        self.q0 = None if q0 is None else np.asarray(q0, dtype=complex)
        self.x0 = None if x0 is None else np.atleast_2d(np.asarray(x0, dtype=complex))
        self.cluster, self.owned = None, True
        if not isinstance(address, str):
            self.client, self.owned = address, False
        elif address == "local":
            self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                        dashboard_address=None)
            self.client = Client(self.cluster)
        else:
            try:
                self.client = Client(address, timeout="20s")
            except (OSError, TimeoutError, ValueError) as e:
                raise ValueError(f"--dask {address}: cannot reach a Dask scheduler there ({e})") from None

    def newton(self, x: np.ndarray, q: np.ndarray, steps: int = 1, inst: np.ndarray | None = None) -> np.ndarray:
        return self.solver.newton(x, q, steps, inst)

    def track(self, q0: np.ndarray, q1: np.ndarray, x0: np.ndarray, inst: np.ndarray | None = None,
              options: TrackerOptions | None = None) -> tuple[np.ndarray, np.ndarray]:
        if not len(x0):
            return x0, np.zeros((0, 4))
        qa, qb = np.atleast_2d(q0), np.atleast_2d(q1)
        inst = np.zeros(len(x0), dtype=np.int64) if inst is None else np.asarray(inst, dtype=np.int64)
        if len(qa) == 1 and len(qb) > 1:
            qa = np.repeat(qa, len(qb), axis=0)
        if len(qb) == 1 and len(qa) > 1:
            qb = np.repeat(qb, len(qa), axis=0)
        opts = dataclasses.asdict(options or self.options)
        task, args = ((track_chunk, (self.source, self.saturate, self.q0, self.x0)) if self.square is None else
                      (track_trace_chunk, (self.source, self.saturate, self.square)))
        futures = [self.client.submit(task, *args, qa, qb, x0[i:i + self.chunk], inst[i:i + self.chunk], opts,
                                      pure=False)
                   for i in range(0, len(x0), self.chunk)]
        parts = self.client.gather(futures)
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])

    def close(self) -> None:
        if self.owned:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()

    def __enter__(self) -> "DaskSystem":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
