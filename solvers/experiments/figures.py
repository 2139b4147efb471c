"""Figures 1 and 2 of the paper: error histograms and error against noise, with their data files.

Owns the plots (`plot_histograms`, `plot_noise`), their PNG/PDF metadata and the rule that skips
rendering when neither the figure's data nor this module changed.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pandas as pd

from solvers.metrics import log10_error

from .config import CONFIGS, CSV_FLOAT_FORMAT, FIGURES_DIR, INIT_LABEL, INITS, config_label, is_timing_column, write_output
from .provenance import package_version
from .summary import median_log10

_COLORS = {"solver": "#1f77b4", "random": "#d62728"}
_LINESTYLES = {"9r3s": "-", "6r4s": "--"}
_MARKERS = {"9r3s": "o", "6r4s": "s"}
#: Histogram x-range (log10 error), fixed: errors outside it are drawn in the end bins. Above 1e4 a run
#: has diverged; where a diverging LM trajectory stops (after its budget) says nothing about the method.
HIST_RANGE = (-17.0, 4.0)


def _figure_metadata(title: str, description: str, meta: dict) -> tuple[dict, dict]:
    """Return (PNG metadata, PDF metadata) for matplotlib's savefig."""
    # no commit or date here (they are in experiments_provenance.json): the same data gives the same bytes
    source = "tdoa-workbench solvers.experiments; provenance in experiments_provenance.json"
    png = {"Title": title, "Description": description, "Source": source, "Software": f"matplotlib {package_version('matplotlib')}"}
    pdf = {"Title": title, "Subject": description, "Keywords": source, "Creator": "tdoa-workbench solvers.experiments",
           "CreationDate": None}
    return png, pdf


def _save(fig: object, stem: Path, title: str, description: str, meta: dict, data_changed: bool = True) -> list[Path]:
    """Write ``<stem>.png`` and ``<stem>.pdf``. Rendering takes seconds, so it is skipped when the
    figure's data file did not change and both images are newer than this module (same data, same
    code: same images)."""
    png_meta, pdf_meta = _figure_metadata(title, description, meta)
    stem.parent.mkdir(parents=True, exist_ok=True)
    png, pdf = stem.with_suffix(".png"), stem.with_suffix(".pdf")
    code = Path(__file__).stat().st_mtime
    if not data_changed and all(p.exists() and p.stat().st_mtime > code for p in (png, pdf)):
        return [png, pdf]
    import io

    for path, kwargs in ((png, dict(dpi=150, metadata=png_meta)), (pdf, dict(metadata=pdf_meta))):
        buffer = io.BytesIO()
        fig.savefig(buffer, format=path.suffix[1:], **kwargs)  # type: ignore[attr-defined]
        if not write_output(path, buffer.getvalue()):
            os.utime(path)  # same bytes from the current code: mark the image as up to date
    return [png, pdf]


def plot_histograms(
    frames: dict[tuple[str, str], pd.DataFrame], stem: Path = FIGURES_DIR / "fig1_histograms", meta: dict | None = None
) -> list[Path]:
    """Fig. 1: histograms of log10 relative error, ours vs random initialisation.

    A 2x2 grid: rows are the solvers (9r/3s, 6r/4s), columns position and offset errors; medians
    are dashed lines. Errors below 1e-17 are drawn in the first bin, trials without an estimate are
    counted in the legend. Writes ``<stem>.png``, ``<stem>.pdf`` and the bin counts ``<stem>.csv``.

    Reference: paper Sec. 4.1, Fig. 1.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    meta = meta or {}
    edges = np.arange(HIST_RANGE[0], HIST_RANGE[1] + 1e-9, 0.25)
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), sharex=True, constrained_layout=True)
    count_rows = []
    trials_seen = set()
    for r, config in enumerate(CONFIGS):
        for c, (column, what) in enumerate((("position_error", "position"), ("offset_error", "offset"))):
            ax = axes[r, c]
            for init in INITS:
                frame = frames.get((config, init))
                if frame is None or isinstance(frame, str):
                    continue
                trials_seen.add(len(frame))
                errors = np.asarray(frame[column], dtype=float)
                missing = int(np.isnan(errors).sum())
                logs = np.clip(log10_error(errors[~np.isnan(errors)]), edges[0], edges[-1])
                counts, _ = np.histogram(logs, bins=edges)
                median = median_log10(frame[column])
                label = (f"{INIT_LABEL[init]} ({'LM from solver' if init == 'solver' else 'LM from random start'})\n"
                         f"median {median:.2f}\n{int(frame['failed'].sum())}/{len(frame)} failed")
                if missing:
                    label += f" ({missing} no estimate)"
                ax.hist(edges[:-1], bins=edges, weights=counts, histtype="stepfilled", alpha=0.45,
                        color=_COLORS[init], edgecolor=_COLORS[init], linewidth=1.2, label=label)
                if math.isfinite(median):
                    ax.axvline(median, color=_COLORS[init], linestyle="--", linewidth=1.2)
                for lo, hi, k in zip(edges[:-1], edges[1:], counts):
                    count_rows.append({"config": config, "init": init, "quantity": what,
                                       "bin_lo": lo, "bin_hi": hi, "count": int(k)})
            ax.set_title(f"{config_label(config)}: {what} error")
            ax.set_ylabel("trials per bin (width 0.25)")
            ax.set_xlabel(f"log10 relative {what} error (dimensionless)")
            ax.grid(alpha=0.3)
            if ax.get_legend_handles_labels()[0]:
                # centred on log10 error -6, in the gap between converged (~-15) and failed (>= -2) runs
                x_gap = (-6.0 - edges[0]) / (edges[-1] - edges[0])
                ax.legend(loc="upper center", bbox_to_anchor=(x_gap, 1.0), fontsize=8, framealpha=0.9)
            ax.set_xlim(edges[0], edges[-1])
            ax.tick_params(labelbottom=True)
    trials = "/".join(str(t) for t in sorted(trials_seen)) or "0"
    fig.suptitle(f"Relative error after Levenberg-Marquardt, noiseless data, {trials} trials per histogram\n"
                 f"(dashed: medians; errors outside 1e{edges[0]:.0f}..1e{edges[-1]:.0f} are drawn in the end bins)")
    title = "Fig. 1: log10 relative error histograms, ours vs random initialisation"
    csv_path = Path(stem).with_suffix(".csv")
    fresh = write_output(csv_path, pd.DataFrame(count_rows).to_csv(index=False, float_format=CSV_FLOAT_FORMAT))
    paths = _save(fig, Path(stem), title, "Paper Sec. 4.1 Fig. 1 reproduction", meta, fresh)
    plt.close(fig)
    return paths + [csv_path]


def plot_noise(summary: pd.DataFrame, stem: Path = FIGURES_DIR / "fig2_noise", meta: dict | None = None) -> list[Path]:
    """Fig. 2: median relative error against the noise level sigma, positions and offsets.

    One line per (solver, initialisation), the interquartile range of "ours" shaded, plus the oracle
    (LM started at the ground truth) as a dotted grey reference. Both axes logarithmic. Writes
    ``<stem>.png``, ``<stem>.pdf`` and the plotted summary ``<stem>.csv``.

    Parameters
    ----------
    summary : output of `summarise` on a `noise_sweep` frame (sigma > 0 rows are plotted)

    Reference: paper Sec. 4.2, Fig. 2.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    meta = meta or {}
    data = summary[summary["sigma"] > 0].sort_values(["config", "init", "sigma"])
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.6), constrained_layout=True)
    for ax, what in zip(axes, ("position", "offset")):
        for config in CONFIGS:
            for init in INITS:
                part = data[(data["config"] == config) & (data["init"] == init)]
                if part.empty:
                    continue
                sig = part["sigma"].to_numpy()
                med = 10.0 ** part[f"median_log10_{what}_error"].to_numpy()
                q25 = 10.0 ** part[f"q25_log10_{what}_error"].to_numpy()
                q75 = 10.0 ** part[f"q75_log10_{what}_error"].to_numpy()
                ax.plot(sig, med, color=_COLORS[init], linestyle=_LINESTYLES[config], marker=_MARKERS[config],
                        label=f"{config_label(config)} {INIT_LABEL[init]}")
                if init == "solver":  # the random baseline's spread covers decades: not drawn
                    ax.fill_between(sig, q25, q75, color=_COLORS[init], alpha=0.10, linewidth=0)
            part = data[(data["config"] == config) & (data["init"] == INITS[0])]
            if not part.empty:
                ax.plot(part["sigma"], 10.0 ** part[f"median_log10_oracle_{what}_error"], color="0.45",
                        linestyle=":", marker=_MARKERS[config], markersize=3,
                        label=f"{config_label(config)} LM from ground truth (reference)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("noise standard deviation sigma (distance units; positions ~ N(0, 10^2))")
        ax.set_ylabel(f"median relative {what} error (dimensionless)")
        ax.set_title(f"{what.capitalize()} error vs noise")
        ax.grid(True, which="major", alpha=0.35)
        ax.grid(True, which="minor", alpha=0.1)
    handles, labels = axes[0].get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="outside lower center", ncol=2, fontsize=9)
    trials = "/".join(str(int(t)) for t in sorted(set(data["trials"]))) if not data.empty else "0"
    fig.suptitle(f"Median relative error after Levenberg-Marquardt vs measurement noise\n"
                 f"({trials} trials per point; shaded: interquartile range of 'ours')")
    title = "Fig. 2: median relative error vs noise sigma"
    csv_path = Path(stem).with_suffix(".csv")
    data = data[[c for c in data.columns if not is_timing_column(c)]]  # runtimes: facts of the run, not results
    fresh = write_output(csv_path, data.to_csv(index=False, float_format=CSV_FLOAT_FORMAT))
    paths = _save(fig, Path(stem), title, "Paper Sec. 4.2 Fig. 2 reproduction", meta, fresh)
    plt.close(fig)
    return paths + [csv_path]

