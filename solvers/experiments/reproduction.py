"""The reproduction of the paper's Section 4: Table 4, Figures 1-2 and provenance in one call.

Owns the plans (`QUICK`, `FULL`), `build_table4`, `build_figures` and `reproduce`, the call behind
``tdoa-workbench reproduce``: one worker pool shared by all batches, the solver rows skipped (with
the reason recorded) when ``solvers.api`` cannot solve.
"""
from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from . import batches
from .batches import CACHE_VERSION, WorkerPool, batch_record, code_fingerprint, noise_sweep, run_trials
from .config import CONFIGS, DEFAULT_JOBS, DEFAULT_SEED, INITS, NOISE_SIGMAS, PROVENANCE_PATH, TABLES_DIR
from .figures import plot_histograms, plot_noise
from .provenance import provenance, relative_paths, update_provenance
from .summary import summarise
from .table import comparison_report, table4, write_table4
from .trial import TrialOptions, solver_status

@dataclass(frozen=True)
class ReproductionPlan:
    """Sizes of a reproduction: Table 4 / Fig. 1 trials, Fig. 2 noise levels and trials per level."""

    mode: str
    table_trials: int
    sigmas: tuple[float, ...]
    sweep_trials: int


QUICK = ReproductionPlan("quick", 100, (1e-5, 1e-4, 1e-3, 1e-2, 1e-1), 50)
FULL = ReproductionPlan("full", 1000, NOISE_SIGMAS, 100)



@contextlib.contextmanager
def _shared_pool(pool: WorkerPool | None, jobs: int) -> Iterator[WorkerPool]:
    """Yield `pool`, else a lazily started pool of max(jobs, 1) workers: every trial of a reproduction runs in a
    spawned worker (:func:`batches.reproducible_blas_env`), never in this process, whose BLAS was set up
    before (threads, kernels) and whose history could steer a trial elsewhere."""
    if pool is not None:
        yield pool
    else:
        with WorkerPool(max(jobs, 1)) as own:
            yield own


def _outputs(paths: Sequence[Path | str] | object, tables_dir: Path) -> list[str]:
    """The written files relative to the output directory (the record does not depend on where it is)."""
    return [Path(p).relative_to(Path(tables_dir)).as_posix() for p in paths]  # type: ignore[attr-defined]


def _blas_kernels() -> str:
    """The OpenBLAS kernels the trials ran with (they decide last bits, see :data:`batches.BLAS_CORE`)."""
    return batches.blas_core() or "OpenBLAS's choice for this CPU (no AVX2/FMA: not pinned)"


def _solver_inits(echo: Callable[[str], None] | None) -> tuple[tuple[str, ...], bool, str]:
    available, reason = solver_status()
    if not available and echo is not None:
        echo(f"NOTE: solver-initialised rows ('ours') skipped, {reason}; running the random baseline only.")
    return (INITS if available else ("random",)), available, reason


def build_table4(
    trials: int = 1000,
    *,
    seed: int = DEFAULT_SEED,
    jobs: int = DEFAULT_JOBS,
    options: TrialOptions = TrialOptions(),
    tables_dir: Path = TABLES_DIR,
    progress: bool = True,
    pool: WorkerPool | None = None,
    echo: Callable[[str], None] | None = print,
    mode: str = "custom",
) -> tuple[pd.DataFrame, dict[tuple[str, str], pd.DataFrame | str]]:
    """Run (or read from cache) the four Table 4 rows and write ``table4.{csv,md,tex}``.

    Rows without a working ``solvers.api`` are written with status "solver unavailable (...)"
    and no numbers. Returns (table, {(config, init): per-trial frame or reason}).

    Reference: paper Sec. 4.1, Table 4.
    """
    inits, available, reason = _solver_inits(echo)
    t0 = time.perf_counter()
    frames: dict[tuple[str, str], pd.DataFrame | str] = {}
    with _shared_pool(pool, jobs) as workers:
        for config in CONFIGS:
            for init in INITS:
                if init in inits:
                    frames[(config, init)] = run_trials(
                        config, init, trials, 0.0, seed,  # type: ignore[arg-type]
                        options=options, jobs=jobs, progress=progress, pool=workers,
                    )
                else:
                    frames[(config, init)] = "solver unavailable"
    table = table4(frames)
    meta = provenance(
        mode=mode, seeds=f"{seed}..{seed + trials - 1} (trial t uses seed {seed} + t)", base_seed=seed,
        trials=trials, sigma=0.0, options=dataclasses.asdict(options), jobs=jobs,
        solver_available=available, solver_reason=reason,
        code_fingerprints={init: code_fingerprint(init) for init in INITS}, cache_version=CACHE_VERSION,
        blas_kernels=_blas_kernels(),
        paper_reference="Sec. 4.1 Table 4: median log10 relative errors, 1000 noiseless trials",
        failure_rule="no candidate, or position/offset error > max(failure_threshold, oracle_factor * oracle error)",
    )
    paths = write_table4(table, Path(tables_dir), meta)
    meta["wall_seconds"] = round(time.perf_counter() - t0, 3)
    meta["outputs"] = _outputs(paths.values(), tables_dir)
    meta["rows"] = json.loads(table.to_json(orient="records"))
    meta["trial_batches"] = batch_record(frames.values())
    meta["failed_seeds"] = {
        f"{config}/{init}": " ".join(str(s) for s in frame.loc[frame["failed"], "seed"].head(20))
        for (config, init), frame in frames.items() if not isinstance(frame, str)
    }
    update_provenance({"table4": meta}, Path(tables_dir) / PROVENANCE_PATH.name)
    return table, frames


def build_figures(
    trials: int = 1000,
    sigmas: Sequence[float] = FULL.sigmas,
    sweep_trials: int = 100,
    *,
    seed: int = DEFAULT_SEED,
    jobs: int = DEFAULT_JOBS,
    options: TrialOptions = TrialOptions(),
    tables_dir: Path = TABLES_DIR,
    progress: bool = True,
    pool: WorkerPool | None = None,
    echo: Callable[[str], None] | None = print,
    mode: str = "custom",
    frames: dict[tuple[str, str], pd.DataFrame | str] | None = None,
) -> tuple[pd.DataFrame, dict[str, list[str]]]:
    """Fig. 1 (histograms of the `trials` noiseless trials) and Fig. 2 (noise sweep).

    `frames` (from `build_table4`) avoids re-reading the noiseless batches. Writes
    ``<tables_dir>/figures/fig1_histograms.*`` and ``fig2_noise.*`` (PNG, PDF, CSV) and their
    provenance sections. Returns (noise summary, {"fig1"|"fig2": paths}).

    Reference: paper Sec. 4.1 Fig. 1 and Sec. 4.2 Fig. 2.
    """
    inits, available, reason = _solver_inits(echo)
    figures_dir = Path(tables_dir) / "figures"
    kwargs = dict(options=options, jobs=jobs, progress=progress, pool=pool)
    common = dict(
        mode=mode, base_seed=seed, options=dataclasses.asdict(options), jobs=jobs,
        solver_available=available, solver_reason=reason,
        code_fingerprints={init: code_fingerprint(init) for init in INITS}, cache_version=CACHE_VERSION,
        blas_kernels=_blas_kernels(),
    )

    with _shared_pool(pool, jobs) as workers:
        kwargs["pool"] = workers
        t0 = time.perf_counter()
        if frames is None:
            frames = {
                (config, init): run_trials(config, init, trials, 0.0, seed, **kwargs)  # type: ignore[arg-type]
                for config in CONFIGS for init in inits
            }
        hist_frames = {k: v for k, v in frames.items() if not isinstance(v, str)}
        meta1 = provenance(trials=trials, sigma=0.0, seeds=f"{seed}..{seed + trials - 1}",
                           paper_reference="Sec. 4.1 Fig. 1", **common)
        fig1 = plot_histograms(hist_frames, figures_dir / "fig1_histograms", meta1)
        meta1["wall_seconds"] = round(time.perf_counter() - t0, 3)
        meta1["outputs"] = _outputs(fig1, tables_dir)
        meta1["trial_batches"] = batch_record(frames.values())

        t0 = time.perf_counter()
        sweep = noise_sweep(tuple(CONFIGS), inits, tuple(sigmas), sweep_trials, seed, **kwargs)
        noise = summarise(sweep)
    meta2 = provenance(trials_per_sigma=sweep_trials, sigmas=[float(s) for s in sigmas],
                       seeds=f"{seed}..{seed + sweep_trials - 1} at every sigma",
                       paper_reference="Sec. 4.2 Fig. 2", **common)
    fig2 = plot_noise(noise, figures_dir / "fig2_noise", meta2)
    meta2["wall_seconds"] = round(time.perf_counter() - t0, 3)
    meta2["outputs"] = _outputs(fig2, tables_dir)
    meta2["trial_batches"] = sweep.attrs.get("batches")
    update_provenance({"fig1": meta1, "fig2": meta2}, Path(tables_dir) / PROVENANCE_PATH.name)
    return noise, {"fig1": [str(p) for p in fig1], "fig2": [str(p) for p in fig2]}


@dataclass(frozen=True)
class ReproductionSummary:
    """Result of `reproduce`: Table 4, the noise summary, written files and the report text."""

    plan: ReproductionPlan
    table: pd.DataFrame
    noise: pd.DataFrame
    paths: dict[str, list[str]]
    solver_available: bool
    solver_reason: str
    wall_seconds: float
    report: str


def reproduce(
    quick: bool = True,
    jobs: int = DEFAULT_JOBS,
    *,
    seed: int = DEFAULT_SEED,
    options: TrialOptions = TrialOptions(),
    tables_dir: Path = TABLES_DIR,
    progress: bool = True,
    echo: Callable[[str], None] | None = print,
) -> ReproductionSummary:
    """Reproduce Table 4 and Figs. 1-2 of the paper; write tables, figures and provenance.

    Parameters
    ----------
    quick : bool
        `QUICK` (100 trials per Table 4 row; 5 noise levels 1e-5..1e-1 x 50 trials) or `FULL`
        (1000 trials as the paper; 11 noise levels 1e-6..1e-1 x 100 trials).
    jobs : int
        Worker processes (one pool shared by all batches; 1 = in this process).
    seed : int
        Base seed of every batch.
    options : TrialOptions
    tables_dir : Path
        Output directory (``tables/``; figures go to ``<tables_dir>/figures``).
    progress : bool
        Progress bars on stderr.
    echo : callable or None
        Where notes and the final comparison with the paper are printed (None: silent).

    Returns
    -------
    ReproductionSummary. Without a working ``solvers.api`` the solver rows are left empty (their
    status says why) and only the random baseline is run: no number is made up.

    Reference: paper Sec. 4 (Table 4, Fig. 1, Fig. 2).
    """
    plan = QUICK if quick else FULL
    start = time.perf_counter()
    available, reason = solver_status()
    with _shared_pool(None, jobs) as pool:
        common = dict(seed=seed, jobs=jobs, options=options, tables_dir=tables_dir, progress=progress,
                      pool=pool, mode=plan.mode)
        t0 = time.perf_counter()
        table, frames = build_table4(plan.table_trials, echo=echo, **common)  # type: ignore[arg-type]
        table_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        noise, figure_paths = build_figures(
            plan.table_trials, plan.sigmas, plan.sweep_trials, frames=frames, echo=None, **common  # type: ignore[arg-type]
        )
        figures_s = time.perf_counter() - t0
    wall = time.perf_counter() - start
    paths = {"table4": [str(Path(tables_dir) / f"table4.{e}") for e in ("csv", "md", "tex")], **figure_paths,
             "provenance": [str(Path(tables_dir) / PROVENANCE_PATH.name)]}
    update_provenance(
        {"reproduce": {"mode": plan.mode, "plan": dataclasses.asdict(plan), "jobs": jobs,
                       "wall_seconds": {"table4": round(table_s, 3), "figures": round(figures_s, 3), "total": round(wall, 3)},
                       "load_average_at_end": list(os.getloadavg()) if hasattr(os, "getloadavg") else None}},
        Path(tables_dir) / PROVENANCE_PATH.name,
    )
    report = comparison_report(table, noise, plan.table_trials)
    report += (f"\nWall time ({plan.mode}, {jobs} jobs): {wall:.1f} s (Table 4 + Fig. 1: {table_s:.1f} s, "
               f"Fig. 2 noise sweep: {figures_s:.1f} s); cached batches in {relative_paths([batches.CACHE_DIR])[0]}/")
    if not available:
        report += f"\nMISSING: the solver-initialised rows ('ours') and curves, {reason}"
    report += "\nWrote: " + ", ".join(p for v in paths.values() for p in relative_paths(v))
    if echo is not None:
        echo(report)
    return ReproductionSummary(plan, table, noise, paths, available, reason, wall, report)
