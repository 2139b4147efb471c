"""The setup shared by every experiment artefact: configurations, initialisations, seeds and paths.

Owns the paper's two configurations (9r/3s, 6r/4s) and their spellings, the two initialisations
("random" = "rand", "solver" = "ours"), the default seed and worker count, the output paths
(``tables/``, ``tables/figures``, the provenance record) and :func:`write_output`, which writes an
artefact only when more than its provenance header changed.
"""
from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from analysis.paths import HEADER_PREFIXES, default_output_dir, keep_row_timings, write_if_changed

if TYPE_CHECKING:
    import pandas as pd

#: Repository root (paths in provenance records are relative to it).
ROOT = Path(__file__).resolve().parents[2]
TABLES_DIR = default_output_dir()
FIGURES_DIR = TABLES_DIR / "figures"
PROVENANCE_PATH = TABLES_DIR / "experiments_provenance.json"

#: The paper's two solvers, in Table 4 order: configuration key -> (m receivers, n transmitters).
CONFIGS: dict[str, tuple[int, int]] = {"9r3s": (9, 3), "6r4s": (6, 4)}

Init = Literal["random", "solver"]
#: Initialisations in Table 4 row order ("rand" before "ours").
INITS: tuple[str, ...] = ("random", "solver")
INIT_LABEL = {"random": "rand", "solver": "ours"}

#: Base seed of every batch (trial t uses DEFAULT_SEED + t).
DEFAULT_SEED = 0
DEFAULT_JOBS = 2


def config_shape(config: str) -> tuple[int, int]:
    """Return (m, n) of a configuration written "9r3s" or "9r/3s"; raise ValueError otherwise."""
    key = config.replace("/", "").strip().lower()
    if key not in CONFIGS:
        raise ValueError(f"unknown configuration {config!r}; valid: {', '.join(CONFIGS)}")
    return CONFIGS[key]


def config_key(config: str) -> str:
    config_shape(config)
    return config.replace("/", "").strip().lower()


def config_label(config: str) -> str:
    """Return the paper's spelling of a configuration, e.g. "9r/3s"."""
    m, n = config_shape(config)
    return f"{m}r/{n}s"


def check_init(init: str) -> str:
    if init not in INITS:
        raise ValueError(f"unknown initialisation {init!r}; valid: {', '.join(INITS)}")
    return init


def _same_apart_from_header(old: str, new: str) -> bool:
    """Equal once the provenance header lines (commit, date) are dropped."""
    def body(text: str) -> list[str]:
        return [line for line in text.splitlines() if not line.startswith(HEADER_PREFIXES)]

    return body(old) == body(new)


def write_output(path: Path, content: str | bytes) -> bool:
    """Write an artefact unless only its provenance header would change (a rerun keeps a checkout
    clean); True when written."""
    return write_if_changed(path, content, _same_apart_from_header)


CSV_FLOAT_FORMAT = "%.6g"
"""Float format of the artefacts' CSV files (Table 4, the figures' data)."""


def is_timing_column(name: str) -> bool:
    """Columns that measure this machine's speed (``median_runtime_ms``, ``median_solver_ms`` ...), not results."""
    return name.endswith("_ms")


def keep_timings(frame: "pd.DataFrame", path: Path) -> "pd.DataFrame":
    """``frame`` with the timing columns of the CSV at ``path`` in every row whose other cells are unchanged.

    A rerun that computes again (fresh caches, a clean checkout) measures other runtimes but the same
    results; with the committed timings kept, it writes the same bytes, so ``git status`` stays clean.
    The run's own timings are in the untracked ``experiments_provenance.timing.json``. Rows are matched
    by position (same header and number of rows); a row whose results changed keeps its own timings,
    so a change in one row does not rewrite the runtimes of the others (all rows keep their own when
    the file is missing, unreadable or of another shape). Either way the timings are returned at the
    precision the CSV holds, so that the provenance record, which lists them, does not change between
    a first run and a rerun.
    """
    text = frame.to_csv(index=False, float_format=CSV_FLOAT_FORMAT)
    new = list(csv.reader(io.StringIO(text)))
    try:
        old = list(csv.reader(io.StringIO(Path(path).read_text(encoding="utf-8"))))
    except (OSError, UnicodeDecodeError):
        old = []
    timing = [k for k, name in enumerate(new[0]) if is_timing_column(name)]
    new = keep_row_timings(new, old, is_timing_column)
    out = frame.copy()
    for k in timing:
        out[new[0][k]] = [float(row[k]) if row[k] else float("nan") for row in new[1:]]
    return out
