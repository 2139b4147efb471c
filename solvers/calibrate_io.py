"""Files around `solvers.calibrate`: the measurement CSV, the JSON report and the map plot.

CSV: one row per receiver, one column per transmitter, F[i, j] = |r_i - s_j| + o_j in any distance
unit. An empty cell, NaN, NA or N/A is a missing measurement. An optional header row (transmitter
names) and header column (receiver names) are detected: the first row / column is a header when it
holds a cell that is neither a number nor a missing marker. Every defect is reported as one
`MeasurementFileError` naming the file, the line and the column (1-based, as an editor shows them).
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["MeasurementFileError", "Measurements", "plot_calibration", "read_measurements", "write_json"]

_MISSING = {"", "nan", "na", "n/a"}


class MeasurementFileError(ValueError):
    """A measurement file that cannot be read as a matrix; the message is one line."""


@dataclass(frozen=True)
class Measurements:
    """A measurement matrix with the receiver and transmitter names of the file (or 1, 2, ...)."""

    F: np.ndarray
    receivers: tuple[str, ...]
    transmitters: tuple[str, ...]


def _number(cell: str) -> float | None:
    """float of a cell, NaN for a missing marker, None if it is not a number."""
    text = cell.strip()
    if text.lower() in _MISSING:
        return math.nan
    try:
        value = float(text)
    except ValueError:
        return None
    return value


def read_measurements(path: str) -> Measurements:
    """Read a TDOA measurement matrix from a CSV file (see the module docstring).

    Raises MeasurementFileError for an unreadable, empty, ragged or non-numeric file (one line,
    naming the line and column), or infinite values.
    """
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:
            rows = [(k + 1, row) for k, row in enumerate(csv.reader(handle)) if any(c.strip() for c in row)]
    except OSError as exc:
        raise MeasurementFileError(f"cannot read {path}: {exc.strerror}") from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise MeasurementFileError(f"{path}: not a text CSV file ({exc})") from None
    if not rows:
        raise MeasurementFileError(f"{path}: no data (empty file)")
    width = len(rows[0][1])
    for line, row in rows:
        if len(row) != width:
            raise MeasurementFileError(f"{path}: line {line} has {len(row)} cells, expected {width} as on line {rows[0][0]}")
    # Row 1 is a header if it has text after its first cell, or text in its first cell while the
    # other rows' first cells are numbers (no header column to explain that text).
    header_row = any(_number(c) is None for c in rows[0][1][1:]) or (
        _number(rows[0][1][0]) is None and all(_number(r[0]) is not None for _, r in rows[1:]))
    body = rows[1:] if header_row else rows
    header_col = bool(body) and any(_number(r[0]) is None for _, r in body)
    first = 1 if header_col else 0
    if not body or width - first == 0:
        raise MeasurementFileError(f"{path}: no measurements (only a header)")
    F = np.empty((len(body), width - first))
    for i, (line, row) in enumerate(body):
        for j, cell in enumerate(row[first:]):
            value = _number(cell)
            if value is None:
                raise MeasurementFileError(f"{path}: line {line}, column {j + first + 1}: {cell.strip()!r} is not a number "
                                           "(leave the cell empty or write NaN for a missing measurement)")
            if math.isinf(value):
                raise MeasurementFileError(f"{path}: line {line}, column {j + first + 1}: infinite value")
            F[i, j] = value
    names_r = tuple(r[0].strip() for _, r in body) if header_col else tuple(str(i + 1) for i in range(len(body)))
    names_t = tuple(c.strip() for c in rows[0][1][first:]) if header_row else tuple(str(j + 1) for j in range(F.shape[1]))
    return Measurements(F, names_r, names_t)


def report_dict(result, measurements: Measurements | None = None) -> dict:
    """The JSON report: `CalibrationResult.to_dict()` plus the node names of the file."""
    out = result.to_dict()
    if measurements is not None:
        out["receiver_names"] = list(measurements.receivers)
        out["transmitter_names"] = list(measurements.transmitters)
    return out


def write_json(report: dict, path: str) -> None:
    """Write the report; OSError propagates (the CLI turns it into a one-line error)."""
    with open(path, "w", encoding="utf-8") as handle:
        json.dump(report, handle, indent=1)
        handle.write("\n")


def plot_calibration(result, path: str, measurements: Measurements | None = None) -> None:
    """Map of the calibration: receivers (triangles), transmitters (circles), 1-sigma circles, and
    every rejected measurement as a dashed red line between its receiver and transmitter."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names_r = measurements.receivers if measurements else [str(i + 1) for i in range(result.m)]
    names_t = measurements.transmitters if measurements else [str(j + 1) for j in range(result.n)]
    fig, ax = plt.subplots(figsize=(7, 7))
    R, S = result.receivers, result.transmitters
    rejected = ~result.inliers & np.isfinite(result.residuals)
    first = True
    for i, j in zip(*np.nonzero(rejected)):
        ax.plot([R[i, 0], S[j, 0]], [R[i, 1], S[j, 1]], "--", color="tab:red", lw=0.8,
                label="rejected measurement" if first else None)
        first = False
    ax.plot(R[:, 0], R[:, 1], "^", color="tab:blue", ms=8, label="receivers")
    ax.plot(S[:, 0], S[:, 1], "o", color="tab:orange", ms=7, label="transmitters")
    for P, std, names in ((R, result.receiver_std, names_r), (S, result.transmitter_std, names_t)):
        for k, name in enumerate(names):
            if not np.all(np.isfinite(P[k])):
                continue
            ax.annotate(name, P[k], textcoords="offset points", xytext=(4, 4), fontsize=8)
            if np.isfinite(std[k]) and std[k] > 0:
                ax.add_patch(plt.Circle(P[k], std[k], fill=False, color="gray", lw=0.5))
    ax.set_aspect("equal")
    ax.set_title(f"{result.status}: rms {result.rms:.3g}, {int((~result.inliers & np.isfinite(result.residuals)).sum())} "
                 f"rejected, {len(result.warnings)} warning(s)")
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
