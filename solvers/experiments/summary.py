"""Summaries of trial batches: the house validation figures per (configuration, initialisation, sigma).

Owns the median/quantile log10 errors with missing estimates counted as +inf (`summarise`) and the
text form of the noise sweep's medians (`summarise_noise_text`); Table 4 and both figures use them.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from solvers.metrics import log10_error

from .config import INIT_LABEL, config_label

def median_log10(errors: pd.Series) -> float:
    """Median of log10(error) with missing estimates (NaN) counted as +inf."""
    values = np.asarray(errors, dtype=float)
    values = np.where(np.isnan(values), np.inf, values)
    with np.errstate(divide="ignore"):
        return float(np.median(log10_error(values))) if values.size else float("nan")


def _quantile_log10(errors: pd.Series, q: float) -> float:
    values = np.asarray(errors, dtype=float)
    values = np.where(np.isnan(values), np.inf, values)
    return float(np.quantile(log10_error(values), q, method="nearest")) if values.size else float("nan")


def summarise(frame: pd.DataFrame) -> pd.DataFrame:
    """Return one row per (config, init, sigma) with the house validation figures (habit 10).

    Columns: trials, median/q25/q75 log10 position and offset errors (no estimate = +inf),
    failure_rate, median_log10_residual, median_real_candidates, median_lm_iterations,
    median_solver_ms, median_lm_ms, median_runtime_ms (solver + LM), the median log10 errors of
    the starting point (solver accuracy before LM) and of the oracle (LM from the ground truth),
    and the first failed seeds.
    """
    rows = []
    for (config, init, sigma), group in frame.groupby(["config", "init", "sigma"], sort=False):
        rows.append({
            "config": config,
            "solver": config_label(config),
            "init": init,
            "sigma": sigma,
            "trials": len(group),
            "median_log10_position_error": median_log10(group["position_error"]),
            "q25_log10_position_error": _quantile_log10(group["position_error"], 0.25),
            "q75_log10_position_error": _quantile_log10(group["position_error"], 0.75),
            "median_log10_offset_error": median_log10(group["offset_error"]),
            "q25_log10_offset_error": _quantile_log10(group["offset_error"], 0.25),
            "q75_log10_offset_error": _quantile_log10(group["offset_error"], 0.75),
            "failure_rate": float(group["failed"].mean()),
            "median_log10_residual": median_log10(group["residual"]),
            "median_real_candidates": float(group["n_real_candidates"].median()),
            "median_real_roots": float(group["n_real_roots"].median()),
            "median_roots": float(group["n_roots"].median()),
            "median_lm_iterations": float(group["lm_iterations"].median()),
            "median_solver_ms": 1e3 * float(group["solver_s"].median()),
            "median_lm_ms": 1e3 * float(group["lm_s"].median()),
            "median_runtime_ms": 1e3 * float(group["total_s"].median()),
            "median_log10_initial_position_error": median_log10(group["initial_position_error"]),
            "median_log10_initial_offset_error": median_log10(group["initial_offset_error"]),
            "median_log10_oracle_position_error": median_log10(group["oracle_position_error"]),
            "median_log10_oracle_offset_error": median_log10(group["oracle_offset_error"]),
            "failed_seeds": " ".join(str(s) for s in group.loc[group["failed"], "seed"].head(10)),
        })
    return pd.DataFrame(rows)


def summarise_noise_text(noise: pd.DataFrame) -> str:
    """Return the Fig. 2 medians as text: one line per (solver, init), "sigma: pos/off" cells."""
    lines = ["Fig. 2 noise sweep, median log10 relative position / offset error (failure rate) per sigma:"]
    for (config, init), part in noise.groupby(["config", "init"], sort=False):
        cells = ", ".join(
            f"{s:.0e}: {p:.1f}/{o:.1f} ({100 * f:.0f}%)"
            for s, p, o, f in zip(part["sigma"], part["median_log10_position_error"],
                                  part["median_log10_offset_error"], part["failure_rate"])
        )
        lines.append(f"  {config_label(config)} {INIT_LABEL[init]}: {cells}")
    return "\n".join(lines)

