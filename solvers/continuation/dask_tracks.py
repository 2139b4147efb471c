"""Monodromy loops on a Dask cluster: each leg's batch of paths split among the workers.

A monodromy loop (:func:`solvers.continuation.monodromy.monodromy_count`) tracks every known root along three
segments; at 10^4-10^5 roots in 35-45 unknowns a leg takes minutes to an hour on one core. :class:`DaskTracks`
is a drop-in for the loop's ``track(a, b, xs)``: it cuts xs into chunks of ``chunk`` paths, tracks each on a
worker of a ``dask.distributed`` cluster (``address``: a scheduler, or ``"local"`` for a LocalCluster of
``workers`` processes on this machine, default one per core) and returns the endpoints in xs's order. Every path is tracked on its
own (the tracker's step control is per path), so the endpoints, and the count, are the same numbers as on
one process; the client keeps the loop's bookkeeping (new-root test, checkpoints).

The workers need the system: it travels as its formulation label (``from_formulation(label,
saturate_det_h=saturate)``) and start pair (q0, x0); each worker builds its start solver once (compiling the
tapes into its own cache directory) and keeps it for the loop's other legs. dask is imported only here,
when a cluster is asked for (an optional dependency: ``pip install -e ".[dask]"``).
"""
from __future__ import annotations

import os

import numpy as np

from analysis.formulations.parametric import from_formulation

from .monodromy import start_solver

__all__ = ["DaskTracks", "track_chunk"]

#: Start solvers built on this worker, by (label, saturate, q0, x0) bytes.
_SOLVERS: dict = {}


def _solver(label: str, saturate: bool, q0: np.ndarray, x0: np.ndarray):
    key = (label, saturate, q0.tobytes(), x0.tobytes())
    if key not in _SOLVERS:
        _SOLVERS.clear()  # one system per loop: keep the memory of one solver
        _SOLVERS[key] = start_solver(from_formulation(label, saturate_det_h=saturate), q0, x0)[0]
    return _SOLVERS[key]


def track_chunk(label: str, saturate: bool, q0: np.ndarray, x0: np.ndarray, a: np.ndarray, b: np.ndarray,
                xs: np.ndarray) -> np.ndarray:
    """Endpoints of the paths xs (K, N) along a -> b (a worker's task): NaN rows for lost paths."""
    return _solver(label, saturate, q0, x0).track(a[None], b[None], xs)[0]


class DaskTracks:
    """``track(a, b, xs) -> endpoints`` on a Dask cluster (module docstring). ``address``: a scheduler address,
    ``"local"``, or a ``dask.distributed.Client`` already connected (then not closed here). Use as a context
    manager, or call :meth:`close`; a bad address raises ValueError in one line."""

    def __init__(self, address, label: str, saturate: bool, q0: np.ndarray, x0: np.ndarray,
                 chunk: int = 2000, workers: int | None = None):
        workers = workers or os.cpu_count() or 1
        if chunk < 1 or workers < 1:
            raise ValueError(f"chunk and workers must be at least 1, got {chunk} and {workers}")
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError as e:
            raise ValueError("--dask needs dask.distributed: pip install -e \".[dask]\" "
                             f"(or pip install 'dask[distributed]'); import failed: {e}") from None
        self.label, self.saturate, self.chunk = label, saturate, chunk
        self.q0, self.x0 = np.asarray(q0, dtype=complex), np.atleast_2d(np.asarray(x0, dtype=complex))
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

    def __call__(self, a: np.ndarray, b: np.ndarray, xs: np.ndarray) -> np.ndarray:
        if not len(xs):
            return xs
        pieces = [xs[i:i + self.chunk] for i in range(0, len(xs), self.chunk)]
        futures = [self.client.submit(track_chunk, self.label, self.saturate, self.q0, self.x0, a, b, piece,
                                      pure=False) for piece in pieces]
        return np.concatenate(self.client.gather(futures))

    def close(self) -> None:
        if self.owned:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()

    def __enter__(self) -> "DaskTracks":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
