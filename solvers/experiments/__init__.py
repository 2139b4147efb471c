"""Monte-Carlo experiments of the paper's Section 4: Table 4, Fig. 1 (histograms), Fig. 2 (noise).

One module per part, data flowing one way (trial -> batches -> summary -> table / figures ->
reproduction):

* :mod:`.config`: configurations, initialisations, seeds, output paths, artefact writing;
* :mod:`.trial`: one seeded trial (`run_trial`), its record, options and the solver it calls;
* :mod:`.batches`: batches of trials cached on disk and run on a shared worker pool (`run_trials`,
  `WorkerPool`, `noise_sweep`);
* :mod:`.summary`: the validation figures of a batch (`summarise`);
* :mod:`.table`: Table 4 and its CSV/Markdown/LaTeX files (`table4`, `write_table4`);
* :mod:`.figures`: Figures 1 and 2 (`plot_histograms`, `plot_noise`);
* :mod:`.provenance`: the provenance record of every artefact;
* :mod:`.reproduction`: `build_table4`, `build_figures` and `reproduce`, the one call behind
  ``tdoa-workbench reproduce``.

This package re-exports the names the CLI, the scripts and the tests use.
"""
from __future__ import annotations

from .batches import WorkerPool, noise_sweep, run_trials
from .config import DEFAULT_JOBS, DEFAULT_SEED, config_shape
from .figures import plot_histograms, plot_noise
from .reproduction import FULL, QUICK, build_figures, build_table4, reproduce
from .summary import summarise, summarise_noise_text
from .table import PAPER_TABLE4, TABLE4_COLUMNS, comparison_report, table4, write_table4
from .trial import OUTCOMES, TRIAL_COLUMNS, SolverUnavailable, TrialError, TrialOptions, run_trial, solver_status

__all__ = [
    "DEFAULT_JOBS",
    "DEFAULT_SEED",
    "FULL",
    "OUTCOMES",
    "PAPER_TABLE4",
    "QUICK",
    "SolverUnavailable",
    "TABLE4_COLUMNS",
    "TRIAL_COLUMNS",
    "TrialError",
    "TrialOptions",
    "WorkerPool",
    "build_figures",
    "build_table4",
    "comparison_report",
    "config_shape",
    "noise_sweep",
    "plot_histograms",
    "plot_noise",
    "reproduce",
    "run_trial",
    "run_trials",
    "solver_status",
    "summarise",
    "summarise_noise_text",
    "table4",
    "write_table4",
]
