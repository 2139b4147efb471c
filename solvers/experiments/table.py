"""Table 4 of the paper: its rows from trial batches, the paper's values beside, and its writers.

Owns the table (`table4`, `TABLE4_COLUMNS`, `PAPER_TABLE4` read from the package data), its CSV/Markdown/LaTeX files
(`write_table4`) and the text comparing every number with the paper (`comparison_report`).
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.sweeps.paths import DATA_DIR

from .config import CONFIGS, CSV_FLOAT_FORMAT, INIT_LABEL, INITS, TABLES_DIR, config_label, is_timing_column, write_output
from .summary import summarise, summarise_noise_text

PAPER_ACCURACY_CSV = DATA_DIR / "paper_accuracy.csv"
"""The paper's accuracy numbers (Table 4), transcribed; package data beside ``paper_tables.csv``."""


def paper_table4(path: Path | str = PAPER_ACCURACY_CSV) -> dict[tuple[str, str], tuple[float, float]]:
    """Paper Table 4 from ``analysis/data/paper_accuracy.csv``: (config, init) -> median log10 relative
    (position, offset) error over 1000 noiseless trials (config "9r3s", init "random" or "solver")."""
    with open(path, newline="", encoding="utf-8") as handle:
        rows = [r for r in csv.DictReader(handle) if r["table"] == "4"]
    return {(r["solver"].replace("/", ""), r["init"]):
            (float(r["median_log10_position_error"]), float(r["median_log10_offset_error"])) for r in rows}


#: Paper Table 4 (:func:`paper_table4`), read once.
PAPER_TABLE4: dict[tuple[str, str], tuple[float, float]] = paper_table4()

#: Columns of Table 4 (`table4`); "paper_*" are the paper's values beside ours.
TABLE4_COLUMNS: tuple[str, ...] = (
    "solver",
    "init",
    "trials",
    "median_log10_position_error",
    "paper_median_log10_position_error",
    "median_log10_offset_error",
    "paper_median_log10_offset_error",
    "failure_rate",
    "median_runtime_ms",
    "median_solver_ms",
    "median_lm_ms",
    "median_lm_iterations",
    "median_log10_residual",
    "median_real_roots",
    "median_roots",
    "median_real_candidates",
    "median_log10_initial_position_error",
    "median_log10_initial_offset_error",
    "status",
)


def table4(frames: dict[tuple[str, str], pd.DataFrame | str]) -> pd.DataFrame:
    """Build Table 4 (rows 9r/3s rand, 9r/3s ours, 6r/4s rand, 6r/4s ours) with the paper beside.

    Parameters
    ----------
    frames : {(config, init): per-trial DataFrame of noiseless trials, or a string saying why the
        row is missing (e.g. the solver is unavailable); missing rows get NaN numbers and that
        string as status}

    Returns
    -------
    DataFrame with columns `TABLE4_COLUMNS`; init is "rand" or "ours" as in the paper.

    Reference: paper Sec. 4.1, Table 4.
    """
    rows = []
    for config in CONFIGS:
        for init in INITS:
            paper_position, paper_offset = PAPER_TABLE4[(config, init)]
            row = dict.fromkeys(TABLE4_COLUMNS, float("nan"))
            row.update(
                solver=config_label(config), init=INIT_LABEL[init], trials=0,
                paper_median_log10_position_error=paper_position,
                paper_median_log10_offset_error=paper_offset,
            )
            value = frames.get((config, init), "not run")
            if isinstance(value, str):
                row["status"] = value
            else:
                summary = summarise(value)
                if len(summary) != 1:
                    raise ValueError(f"Table 4 needs one noise level per row, got {len(summary)} for {config} {init}")
                s = summary.iloc[0]
                row.update({k: s[k] for k in TABLE4_COLUMNS if k in s.index and k not in ("solver", "init")})
                row["trials"] = int(s["trials"])
                row["status"] = "ok"
            rows.append(row)
    return pd.DataFrame(rows, columns=list(TABLE4_COLUMNS))


def _fmt(value: object, digits: int = 2) -> str:
    if isinstance(value, str):
        return value
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, float) and math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return f"{float(value):.{digits}f}"


_DISPLAY = (
    ("solver", "Solver", 0),
    ("init", "Init", 0),
    ("median_log10_position_error", "Position log10 (ours)", 2),
    ("paper_median_log10_position_error", "Position log10 (paper)", 2),
    ("median_log10_offset_error", "Offset log10 (ours)", 2),
    ("paper_median_log10_offset_error", "Offset log10 (paper)", 2),
    ("failure_rate", "Failure rate", 3),
    ("median_lm_iterations", "LM iterations", 0),
    ("median_log10_residual", "Residual log10", 1),
    ("median_real_roots", "Real roots", 0),
    ("median_real_candidates", "Valid candidates", 0),
    ("trials", "Trials", 0),
)


def _num(value: object) -> str:
    """Counts and medians of counts: 3, 3.5, or n/a."""
    return f"{value:g}" if isinstance(value, (int, float)) and not math.isnan(value) else "n/a"


def _display_rows(table: pd.DataFrame) -> list[list[str]]:
    out = []
    for _, row in table.iterrows():
        cells = []
        for column, _, digits in _DISPLAY:
            value = row[column]
            if column in ("median_lm_iterations", "median_real_roots", "median_real_candidates") and isinstance(value, float) and not math.isnan(value):
                cells.append(f"{value:g}")
            else:
                cells.append(_fmt(value, digits))
        out.append(cells)
    return out


def _provenance_line(meta: dict) -> str:
    """What the numbers depend on (mode, seeds); the run's commit, date and versions are in the timing record."""
    return f"{meta.get('mode', '')} run, seeds {meta.get('seeds', '')}"


def results_columns(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` without its runtime columns (:func:`config.is_timing_column`): what a committed file holds."""
    return frame[[c for c in frame.columns if not is_timing_column(c)]]


def write_table4(table: pd.DataFrame, directory: Path = TABLES_DIR, meta: dict | None = None) -> dict[str, Path]:
    """Write Table 4 as CSV (every result column), Markdown and LaTeX (paper columns beside ours).

    Results only: the runtime columns (this machine's speed) are left out, and the Markdown and LaTeX files'
    first line names the mode and seeds, not the commit or date (both in the untracked
    ``experiments_provenance.timing.json``, the runtimes also in the printed comparison), so a rerun on any
    machine writes the same bytes. Returns {"csv"|"md"|"tex": path}.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    meta = meta or {}
    paths = {ext: directory / f"table4.{ext}" for ext in ("csv", "md", "tex")}
    write_output(paths["csv"], results_columns(table).to_csv(index=False, float_format=CSV_FLOAT_FORMAT))

    headers = [label for _, label, _ in _DISPLAY]
    rows = _display_rows(table)  # (no runtime in _DISPLAY)
    notes = [
        "Median log10 relative errors over noiseless trials (paper Sec. 4.1, Table 4); paper values beside ours.",
        "Position error: after the best rigid alignment, ||X_est - X_true||_F / ||X_true - centroid||_F over all "
        "receivers and transmitters. Offset error: ||o_est - o_true|| / ||o_true||.",
        "Levenberg-Marquardt (LM): scipy's least_squares method 'trf' without bounds, i.e. MINPACK's LM iteration "
        "with the LM step from an SVD; its end point from a start that diverges does not depend on the process "
        "(MINPACK's can).",
        "A trial fails when there is no candidate or an error exceeds 1e-6. Runtimes are facts of a run, not "
        "results: `tdoa-workbench reproduce` prints them and keeps them in experiments_provenance.timing.json.",
    ]
    md = [f"<!-- generated by solvers.experiments.write_table4; {_provenance_line(meta)} -->", ""]
    md += ["**Table 4 (reproduction).** " + " ".join(notes), ""]
    md.append("| " + " | ".join(headers) + " |")
    md.append("|" + "|".join("---" if i < 2 else "---:" for i in range(len(headers))) + "|")
    md += ["| " + " | ".join(r) + " |" for r in rows]
    status = [f"{r['solver']} {r['init']}: {r['status']}" for _, r in table.iterrows() if r["status"] != "ok"]
    if status:
        md += ["", "Missing rows: " + "; ".join(status)]
    write_output(paths["md"], "\n".join(md) + "\n")

    def tex_escape(text: str) -> str:
        return text.replace("_", r"\_").replace("%", r"\%").replace("&", r"\&")

    tex_columns = _DISPLAY[:7]
    tex = [f"% generated by solvers.experiments.write_table4; {tex_escape(_provenance_line(meta))}"]
    tex += [
        r"\begin{table}[tbh]",
        r"  \centering",
        r"  \caption{Median relative errors ($\log_{10}$), ours (reproduction) beside the paper, and failure rate; "
        r"noiseless data.}",
        r"  \label{tab:medianErrReproduction}",
        r"  \begin{tabular}{l|rr|rr|r}",
        r"    Solver & \multicolumn{2}{c|}{Position error ($\log_{10}$)} & \multicolumn{2}{c|}{Offset error ($\log_{10}$)}"
        r" & Failure \\",
        r"    & ours & paper & ours & paper & rate \\\hline\hline",
    ]
    for row in rows:
        cells = [f"{row[0]} {row[1]}"] + row[2 : len(tex_columns)]
        tex.append("    " + " & ".join(tex_escape(c) for c in cells) + r" \\")
    tex += [r"  \end{tabular}", r"\end{table}"]
    write_output(paths["tex"], "\n".join(tex) + "\n")
    return paths


def comparison_report(table: pd.DataFrame, noise: pd.DataFrame | None = None, trials: int | None = None) -> str:
    """Return the text comparing every Table 4 number with the paper (and the noise medians)."""
    trials_text = f"{trials} noiseless trials per row" if trials else "noiseless trials"
    lines = [f"Table 4 reproduction ({trials_text}) vs paper, median log10 relative error:"]
    lines.append(
        f"  {'row':<12} {'position ours':>13} {'paper':>6} {'diff':>6}   {'offset ours':>11} {'paper':>6} "
        f"{'diff':>6}   {'failures':>8} {'runtime ms':>10} {'real roots':>10} {'valid cands':>11}"
    )
    for _, r in table.iterrows():
        name = f"{r['solver']} {r['init']}"
        if r["status"] != "ok":
            lines.append(f"  {name:<12} no numbers: {r['status']}")
            continue
        dp = r["median_log10_position_error"] - r["paper_median_log10_position_error"]
        do = r["median_log10_offset_error"] - r["paper_median_log10_offset_error"]
        lines.append(
            f"  {name:<12} {r['median_log10_position_error']:>13.2f} {r['paper_median_log10_position_error']:>6.2f} "
            f"{dp:>+6.2f}   {r['median_log10_offset_error']:>11.2f} {r['paper_median_log10_offset_error']:>6.2f} "
            f"{do:>+6.2f}   {100 * r['failure_rate']:>7.1f}% {r['median_runtime_ms']:>10.1f} "
            f"{_num(r['median_real_roots']):>10} {_num(r['median_real_candidates']):>11}"
        )
    if noise is not None and not noise.empty:
        lines.append(summarise_noise_text(noise))
    return "\n".join(lines)

