"""Batches of trials: the on-disk cache, the worker pool and the noise sweep.

Owns `run_trials` (trials seed, seed + 1, ... of one (configuration, initialisation, sigma), read
from or written to a per-batch CSV cache keyed by every parameter and a fingerprint of the numeric
code), the spawned `WorkerPool` shared by several batches, and `noise_sweep` (Fig. 2's batches).
"""
from __future__ import annotations

import contextlib
import dataclasses
import datetime as _dt
import hashlib
import json
import os
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.sweeps.complexity import single_threaded_blas_env
from analysis.sweeps.paths import cache_dir
from analysis.sweeps.progress import Progress

from .config import (CONFIGS, DEFAULT_JOBS, DEFAULT_SEED, INIT_LABEL, INITS, NOISE_SIGMAS, Init, check_init, config_key,
                     config_label)
from .trial import TRIAL_COLUMNS, TrialOptions, load_solve_network, run_trial

#: Per-batch CSV cache in the user cache directory (analysis.sweeps.paths), keyed by every parameter that
#: changes the numbers.
CACHE_DIR = cache_dir("experiments")

#: Bump when the meaning of a cached trial changes (columns, seeding, failure rule).
CACHE_VERSION = 2


def _file_digest(paths: Iterable[Path]) -> str:
    h = hashlib.sha256()
    for path in sorted(paths):
        h.update(path.name.encode())
        h.update(path.read_bytes() if path.exists() else b"<missing>")
    return h.hexdigest()


def _solver_sources(package: Path) -> list[Path]:
    """The files the experiments' solvers are made of: the generated modules and specs of :data:`CONFIGS`
    (``solvers/generated/tdoa_<config>_*``) and the modules of the ``solvers`` package they import, directly or
    through each other (read from the source, imports inside functions included; a module moved to another
    subpackage stays covered). Other solvers (a 3D one, another cell's) are not among them: changing them
    leaves the batches' cache and the experiments' provenance alone."""
    import ast

    generated = package / "generated"
    modules = sorted(p for p in generated.glob("tdoa_*") if p.is_file() and p.suffix in (".py", ".json")
                     and p.name.split("_")[1] in CONFIGS) if generated.is_dir() else []
    kernels = {p for p in package.rglob("*.py") if not p.is_relative_to(generated) and p.name != "__init__.py"}
    found: set[Path] = set()
    todo = [p for p in modules if p.suffix == ".py"]
    while todo:
        path = todo.pop()
        here = path.relative_to(package.parent).with_suffix("").parts[:-1]  # the module's package
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                base = list(here[: len(here) - node.level + 1]) if node.level else []
                base += node.module.split(".") if node.module else []
                names = [base + [a.name] for a in node.names] + [base]  # a submodule, or the module itself
            elif isinstance(node, ast.Import):
                names = [a.name.split(".") for a in node.names]
            else:
                continue
            for parts in names:
                target = package.parent.joinpath(*parts).with_suffix(".py")
                if target in kernels and target not in found:
                    found.add(target)
                    todo.append(target)
    return modules + sorted(found)


def code_fingerprint(init: str) -> str:
    """SHA-256 of the source files the numbers of a batch depend on.

    The numeric pipeline (synthetic, recovery, refine, metrics) always; for init="solver" also
    ``solvers/api.py`` and the experiments' solvers (:func:`_solver_sources`: their generated modules
    and specs, the method kernels and runtime they import), so that a changed solver invalidates
    cached results and an unrelated one does not. Edits to the trial itself
    (:mod:`solvers.experiments.trial`) are covered by CACHE_VERSION.
    """
    here = Path(__file__).resolve().parents[1]
    paths = [here / f"{name}.py" for name in ("synthetic", "recovery", "refine", "metrics")]
    if init == "solver":
        paths += [here / "api.py", *_solver_sources(here)]
    return _file_digest(set(paths))


def _cache_key(config: str, init: str, trials: int, sigma: float, seed: int, options: TrialOptions) -> dict:
    return {
        "cache_version": CACHE_VERSION,
        "config": config,
        "init": init,
        "trials": trials,
        "sigma": repr(float(sigma)),
        "seed": seed,
        "options": dataclasses.asdict(options),
        "code": code_fingerprint(init),
        "numpy": np.__version__,
        "blas_kernels": blas_core(),  # the workers' OpenBLAS kernels decide last bits
    }


def _cache_path(key: dict) -> Path:
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]
    name = f"{key['config']}-{key['init']}-sigma{float(key['sigma']):.3g}-n{key['trials']}-seed{key['seed']}-{digest}.csv"
    return CACHE_DIR / name


_DTYPES: dict[str, type] = {
    "config": str, "init": str, "outcome": str, "m": int, "n": int, "trial": int, "seed": int,
    "n_refined": int, "lm_success": bool, "failed": bool,
}
_DTYPES.update({name: float for name in TRIAL_COLUMNS if name not in _DTYPES})


def _read_cache(path: Path) -> pd.DataFrame:
    frame = pd.read_csv(path, dtype=_DTYPES, keep_default_na=False, na_values=["nan", "NaN", ""])
    return frame[list(TRIAL_COLUMNS)]


def _write_atomic(path: Path, text: str | bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(text if isinstance(text, bytes) else text.encode())
    os.replace(tmp, path)



def _frame(records: list[dict]) -> pd.DataFrame:
    frame = pd.DataFrame.from_records(records, columns=list(TRIAL_COLUMNS))
    return frame.astype({k: v for k, v in _DTYPES.items() if k in frame})


#: OpenBLAS kernel set of the workers that run trials, where the CPU has it (x86-64 with AVX2 and FMA): numpy's
#: and scipy's OpenBLAS otherwise pick kernels for the CPU (SkylakeX on an AVX-512 machine, Haswell on most
#: others), which give other last bits in the metrics' SVD, the recovery's least squares and the pencil's
#: eigenvalues; LM from a random start amplifies them into another end point (Fig. 1's bins moved between
#: machines). Pinned, every such machine computes the same bits.
BLAS_CORE = "Haswell"


def blas_core() -> str:
    """:data:`BLAS_CORE` where the CPU runs it (AVX2 and FMA3, as numpy detects them), else "" (OpenBLAS's choice)."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # numpy < 2
        try:
            from numpy.core._multiarray_umath import __cpu_features__ as features
        except ImportError:
            return ""
    return BLAS_CORE if features.get("AVX2") and features.get("FMA3") else ""


@contextlib.contextmanager
def reproducible_blas_env() -> Iterator[None]:
    """One BLAS thread and the kernels of :func:`blas_core` in the environment, for workers spawned in it (they
    read it before importing numpy): a trial's bits do not depend on threads, the CPU's kernels or the worker."""
    core = blas_core()
    saved = os.environ.get("OPENBLAS_CORETYPE")
    with single_threaded_blas_env():
        if core:
            os.environ["OPENBLAS_CORETYPE"] = core
        try:
            yield
        finally:
            if saved is None:
                os.environ.pop("OPENBLAS_CORETYPE", None)
            else:
                os.environ["OPENBLAS_CORETYPE"] = saved


def _run_chunk(task: tuple[str, str, list[tuple[int, int]], float, TrialOptions]) -> list[dict]:
    config, init, trial_seeds, sigma, options = task
    return [run_trial(config, init, seed, sigma, options, trial) for trial, seed in trial_seeds]


class WorkerPool:
    """Spawned worker processes shared by several batches, started on first use.

    Workers are spawned (not forked) in :func:`reproducible_blas_env`: numpy and scipy in each worker use
    one BLAS thread and the same OpenBLAS kernels on every x86-64 machine with AVX2; starting them costs a
    few seconds (imports), which is why `reproduce` shares one pool over all its batches (and runs every
    batch in it, also with one job). Use as a context manager.
    """

    def __init__(self, jobs: int = DEFAULT_JOBS) -> None:
        if jobs < 1:
            raise ValueError(f"jobs must be >= 1, got {jobs}")
        self.jobs = jobs
        self._pool = None

    def imap(self, function: Callable, tasks: list) -> Iterator:
        if self._pool is None:
            import multiprocessing

            with reproducible_blas_env():
                self._pool = multiprocessing.get_context("spawn").Pool(self.jobs)
        return self._pool.imap(function, tasks)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool.join()
            self._pool = None

    def __enter__(self) -> "WorkerPool":
        return self

    def __exit__(self, *exc: object) -> None:
        if exc[0] is not None and self._pool is not None:
            self._pool.terminate()
        self.close()


class _Progress(Progress):
    """One batch of trials: on a terminal it rewrites the phase's single progress line, otherwise it
    prints one line when the batch is done."""

    def __init__(self, total: int, description: str, enabled: bool) -> None:
        super().__init__(description, total, enabled, "trials", checkpoints=0)


def run_trials(
    config: str,
    init: Init,
    trials: int = 1000,
    sigma: float = 0.0,
    seed: int = DEFAULT_SEED,
    *,
    options: TrialOptions = TrialOptions(),
    jobs: int = DEFAULT_JOBS,
    cache: bool = True,
    progress: bool = True,
    chunk_size: int = 10,
    pool: WorkerPool | None = None,
) -> pd.DataFrame:
    """Run `trials` seeded trials (seeds seed, seed+1, ...) and return one row per trial.

    Parameters
    ----------
    config : "9r3s" | "6r4s"
    init : "solver" | "random"
    trials : int
    sigma : float
        Measurement noise standard deviation.
    seed : int
        Base seed; trial t uses seed + t.
    options : TrialOptions
    jobs : int
        Worker processes (spawned in :func:`reproducible_blas_env`). Uncached batches of jobs 1, or of fewer
        than 5 chunks of trials, run in this process; cached ones always in workers (the same bits
        whichever process asked).
    cache : bool
        Read/write ``<cache>/experiments/<config>-<init>-...-<hash>.csv`` (``analysis.sweeps.paths.cache_dir``),
        keyed by all parameters, CACHE_VERSION and a fingerprint of the numeric code.
    progress : bool
        Progress bar on stderr.
    chunk_size : int
        Trials per task sent to a worker.
    pool : WorkerPool, optional
        Workers shared with other batches (else a pool of `jobs` workers is started if needed).

    Returns
    -------
    pandas.DataFrame with columns `TRIAL_COLUMNS` (see `run_trial`), ordered by trial.

    Raises
    ------
    SolverUnavailable
        For init="solver" without a working ``solvers.api`` (checked before any work).
    TrialError
        If a trial raises (the message names its seed).
    """
    key_config = config_key(config)
    check_init(init)
    if trials < 1:
        raise ValueError(f"trials must be >= 1, got {trials}")
    if not sigma >= 0:
        raise ValueError(f"sigma must be >= 0, got {sigma}")
    if init == "solver":
        load_solve_network()
    path = None
    if cache:
        key = _cache_key(key_config, init, trials, sigma, seed, options)
        path = _cache_path(key)
        if path.exists():
            frame = _read_cache(path)
            frame.attrs["batch"] = _batch_info(path, "cache hit")
            return frame

    started = time.perf_counter()
    pairs = [(t, seed + t) for t in range(trials)]
    tasks = [
        (key_config, init, pairs[i : i + chunk_size], float(sigma), options)
        for i in range(0, trials, chunk_size)
    ]
    bar = _Progress(trials, f"{config_label(key_config)} {INIT_LABEL[init]} sigma={sigma:g}", progress)
    records: list[dict] = []
    try:
        # a batch that goes to the cache is computed in spawned workers (reproducible_blas_env), whose bits do
        # not depend on this process's BLAS set-up; an uncached one may run here when it is small
        if pool is None and not cache and (jobs <= 1 or len(tasks) < 5):
            for task in tasks:
                records += _run_chunk(task)
                bar.update(len(task[2]))
        else:
            with contextlib.ExitStack() as stack:
                workers = pool if pool is not None else stack.enter_context(WorkerPool(max(1, min(jobs, len(tasks)))))
                for chunk in workers.imap(_run_chunk, tasks):
                    records += chunk
                    bar.update(len(chunk))
    finally:
        bar.close()

    frame = _frame(records)
    seconds = round(time.perf_counter() - started, 3)
    if path is not None:
        _write_atomic(path, frame.to_csv(index=False, float_format="%.17g"))
        sidecar = dict(key, compute_seconds=seconds, jobs=jobs if pool is None else pool.jobs,
                       computed=_dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat())
        _write_atomic(path.with_suffix(".json"), json.dumps(sidecar, indent=2, sort_keys=True) + "\n")
        frame.attrs["batch"] = _batch_info(path, "computed")
    else:
        frame.attrs["batch"] = {"file": None, "status": "not cached", "compute_seconds": seconds}
    return frame


def _batch_info(path: Path, status: str) -> dict:
    """Cache file, whether it was computed now, and the wall time it took when it was computed."""
    try:
        sidecar = json.loads(path.with_suffix(".json").read_text())
    except (OSError, json.JSONDecodeError):
        sidecar = {}
    return {"file": path.name, "status": status, "compute_seconds": sidecar.get("compute_seconds"),
            "computed": sidecar.get("computed")}


def batch_record(frames: Iterable[pd.DataFrame | str]) -> dict:
    """Summarise the `batch` attributes of run_trials frames for the provenance record."""
    infos = [f.attrs["batch"] for f in frames if not isinstance(f, str) and "batch" in f.attrs]
    return {
        "batches": len(infos),
        "computed_now": sum(i["status"] != "cache hit" for i in infos),
        "cache_hits": sum(i["status"] == "cache hit" for i in infos),
        "compute_seconds_when_computed": round(sum(i["compute_seconds"] or 0.0 for i in infos), 1),
        "files": [i["file"] for i in infos],
    }


def noise_sweep(
    configs: Sequence[str] = tuple(CONFIGS),
    inits: Sequence[str] = INITS,
    sigmas: Sequence[float] = NOISE_SIGMAS,
    trials: int = 100,
    seed: int = DEFAULT_SEED,
    **kwargs: object,
) -> pd.DataFrame:
    """Run `run_trials` for every (config, init, sigma) and concatenate the rows.

    The same seeds are used at every sigma, so the networks are shared across noise levels.
    Keyword arguments (options, jobs, cache, progress) are passed on.

    Reference: paper Sec. 4.2, Fig. 2.
    """
    frames = [
        run_trials(config, init, trials, float(sigma), seed, **kwargs)  # type: ignore[arg-type]
        for config in configs
        for init in inits
        for sigma in sigmas
    ]
    batches = batch_record(frames)
    sweep = pd.concat(frames, ignore_index=True)
    sweep.attrs = {"batches": batches}
    return sweep

