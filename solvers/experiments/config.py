"""The setup shared by every experiment artefact: configurations, initialisations, seeds and paths.

Owns the paper's two configurations (9r/3s, 6r/4s) and their spellings, the two initialisations
("random" = "rand", "solver" = "ours"), the default seed and worker count, the output paths
(``tables/``, ``tables/figures``, the provenance record) and :func:`write_output`, which writes an
artefact only when its bytes change.
"""
from __future__ import annotations

from pathlib import Path
from typing import Literal

from analysis.sweeps.paths import default_output_dir, write_if_changed

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

#: Fig. 2's noise levels, 11 log-spaced in 1e-6..1e-1, each read from its decimal text: the same float on every
#: machine and numpy (np.logspace(-6, -1, 11) gives 1e-05 on some and 9.999999999999999e-06 on others, through
#: pow's last bit), so that the trials, their cache keys and the committed provenance do not depend on the library.
#: The half decades are the values np.logspace gave for the committed Fig. 2.
NOISE_SIGMAS: tuple[float, ...] = tuple(map(float, (
    "1e-06", "3.162277660168379e-06", "1e-05", "3.1622776601683795e-05", "0.0001", "0.00031622776601683794",
    "0.001", "0.0031622776601683794", "0.01", "0.03162277660168379", "0.1")))


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


def write_output(path: Path, content: str | bytes) -> bool:
    """Write an artefact unless it already holds these bytes (a rerun leaves the file and its mtime); True when
    written. Artefacts hold results only (no commit, date or runtime), so a rerun writes the same bytes."""
    return write_if_changed(path, content)


CSV_FLOAT_FORMAT = "%.6g"
"""Float format of the artefacts' CSV files (Table 4, the figures' data)."""


def is_timing_column(name: str) -> bool:
    """Columns that measure this machine's speed (``median_runtime_ms``, ``median_solver_ms`` ...), not results:
    printed and kept in the timing record, never in a committed file."""
    return name.endswith("_ms")
