"""Files around `solvers.calibrate`: the measurement CSV, the JSON report and the map plot.

What F holds: one row per receiver, one column per transmitter, f_ij = |r_i - s_j| + o_j, distances
(arrival times or time differences multiplied by the propagation speed, e.g. the speed of sound), in
any one unit; o_j is transmitter j's unknown offset (its emission time times the speed).

The CSV reader (:func:`read_measurements`, ``-`` reads standard input):

* Text: UTF-8 (a byte-order mark is dropped) or UTF-16 with a byte-order mark (a spreadsheet's
  "Unicode text"). Line ends \n, \r\n or \r.
* Comments: from a ``#`` outside double quotes to the end of its line is a comment; a line that holds
  nothing else is skipped, as are blank lines. Exception: a cell ``#N/A`` (a spreadsheet's missing value).
* Delimiter: TAB, ``;``, ``,`` or runs of spaces. Unless given, it is the first of TAB, ``;``, ``,``
  that splits every line into the same number (>= 2) of cells; if none does, the one on the most
  lines (the ragged line is then reported); if none occurs, runs of spaces. With ``;``, TAB or
  spaces as delimiter, a decimal comma (``1,5``) is read as a decimal point.
* Cells: a number (``12``, ``-0.5``, ``1.2e3``), or a missing measurement: an empty cell, ``NaN``,
  ``NA``, ``N/A`` or ``#N/A``. Anything else is refused, as is an infinite or overflowing value
  (``inf``, ``1e400``).
* Names (``header="auto"``): the first row holds the transmitter names when one of its cells after
  the first is text, or when its first cell is text or empty and its other cells are distinct integers
  (``rx,1,2,3``: transmitters named 1, 2, 3); in that second case its first cell labels the receiver
  names, so the first column holds them. If then every measurement is an integer too, the first row
  could as well be a receiver's measurements and the file is refused (give ``header``). The first
  column holds the receiver names when the header row's first cell is empty (``,s1,s2``), when below
  a header row it reads 0, 1, 2, ... or 1, 2, 3, ... (a row index), or when one of its cells below the
  header row is text. ``header="row"``, ``"column"``, ``"both"`` or ``"none"``
  says it instead. Nodes without names are numbered 1, 2, ...
* A last column that is empty on every line (a delimiter at the end of every line) is dropped.

Every defect is one `MeasurementFileError` line naming the file, the line and the column (1-based:
line as an editor counts it, column as the cell's position in its line).
"""
from __future__ import annotations

import csv
import itertools
import json
import math
import os
import re
import sys
import tempfile
from dataclasses import dataclass

import numpy as np

from analysis.engine.io import InputError, read_input_bytes

__all__ = ["DELIMITERS", "HEADERS", "MeasurementFileError", "Measurements", "check_output_path", "format_matrix",
           "parse_measurements", "plot_calibration", "plot_formats", "read_input", "read_measurements", "report_dict",
           "write_json", "write_nodes_csv"]

#: Delimiters by name (``--delimiter``); the characters themselves are accepted too.
DELIMITERS = {"comma": ",", "semicolon": ";", "tab": "\t", "space": " "}

#: Which of the first row / first column hold names (``--header``).
HEADERS = ("auto", "row", "column", "both", "none")

_MISSING = {"", "nan", "na", "n/a", "#n/a"}
_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")
_DECIMAL_COMMA = re.compile(r"[+-]?\d+,\d+(?:[eE][+-]?\d+)?")
_INTEGER = re.compile(r"[+-]?\d+")
_INFINITE = {"inf", "+inf", "-inf", "infinity", "+infinity", "-infinity"}
_SNIFFED = ("\t", ";", ",")
_STDIN = "-"


class MeasurementFileError(ValueError):
    """A measurement file that cannot be read as a matrix; the message is one line."""


@dataclass(frozen=True)
class Measurements:
    """A measurement matrix with the receiver and transmitter names of the file (or 1, 2, ...).

    F : (m, n) float array, NaN where a measurement is missing
    receivers, transmitters : names, one per row / column of F
    source : the file name ("stdin" for standard input)
    delimiter : the delimiter the file was read with
    """

    F: np.ndarray
    receivers: tuple[str, ...]
    transmitters: tuple[str, ...]
    source: str = ""
    delimiter: str = ","

    def transposed(self) -> Measurements:
        """The same file read with receivers as columns (F transposed, names swapped)."""
        return Measurements(self.F.T.copy(), self.transmitters, self.receivers, self.source, self.delimiter)


def _delimiter_name(d: str) -> str:
    return {v: k for k, v in DELIMITERS.items()}.get(d, repr(d))


def _delimiter(name: str) -> str:
    """The delimiter character of a ``--delimiter`` value (a name of DELIMITERS or the character)."""
    key = name.lower() if len(name) > 1 else name
    if key in DELIMITERS:
        return DELIMITERS[key]
    if name in DELIMITERS.values() or name == "\\t":
        return "\t" if name == "\\t" else name
    raise MeasurementFileError(f"unknown delimiter {name!r}; give one of {', '.join(DELIMITERS)} (or , ; and a TAB character)")


def _decode(data: bytes, source: str) -> str:
    """Text of the file's bytes: UTF-8 (BOM dropped) or UTF-16 with a BOM; a one-line error otherwise."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        try:
            return data.decode("utf-16")
        except UnicodeDecodeError as e:
            raise MeasurementFileError(f"{source}: broken UTF-16 text at byte {e.start}") from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data[: e.start].count(b"\n") + 1
        raise MeasurementFileError(f"{source}: line {line}: not UTF-8 text (byte 0x{data[e.start]:02x}); "
                                   "save the file as UTF-8 (CSV UTF-8 in a spreadsheet)") from None
    if "\x00" in text:
        line = text[: text.index("\x00")].count("\n") + 1
        raise MeasurementFileError(f"{source}: line {line}: a NUL byte: a binary file, not a CSV text")
    return text


def _strip_comment(line: str) -> str:
    """The line without its comment: from the first # outside double quotes, except a cell #N/A."""
    quoted = False
    k = 0
    while k < len(line):
        c = line[k]
        if c == '"':
            quoted = not quoted
        elif c == "#" and not quoted:
            if line[k : k + 4].upper() == "#N/A" and not line[k + 4 : k + 5].strip(" \t,;"):
                k += 4
                continue
            return line[:k]
        k += 1
    return line


def _count_outside_quotes(line: str, d: str) -> int:
    quoted, count = False, 0
    for c in line:
        if c == '"':
            quoted = not quoted
        elif c == d and not quoted:
            count += 1
    return count


def _sniff(lines: list[tuple[int, str]]) -> str:
    """The delimiter of the content lines (see the module docstring)."""
    counts = {d: [_count_outside_quotes(text, d) for _, text in lines] for d in _SNIFFED}
    for d in _SNIFFED:
        if counts[d][0] > 0 and all(c == counts[d][0] for c in counts[d]):
            return d
    used = {d: sum(c > 0 for c in counts[d]) for d in _SNIFFED}
    best = max(_SNIFFED, key=lambda d: used[d])  # max keeps the first of equals: TAB, ;, ,
    if used[best]:
        return best
    return " "


def _split(text: str, d: str, source: str, line: int) -> list[str]:
    """Cells of one line (double quotes as in CSV); a one-line error for a broken quote."""
    if d == " ":
        return text.split()
    try:
        rows = list(csv.reader([text], delimiter=d, skipinitialspace=True, strict=True))
    except csv.Error as e:
        raise MeasurementFileError(f"{source}: line {line}: {e} (a double quote opens a quoted cell that must close "
                                   "on the same line)") from None
    return [cell.strip() for cell in rows[0]] if rows else [""]


def _value(cell: str, decimal_comma: bool) -> float | None:
    """float of a cell, NaN for a missing marker, +-inf for an infinite or overflowing value, None
    for text."""
    low = cell.lower()
    if low in _MISSING:
        return math.nan
    if low in _INFINITE:
        return math.inf
    if _NUMBER.fullmatch(cell):
        return float(cell)
    if decimal_comma and _DECIMAL_COMMA.fullmatch(cell):
        return float(cell.replace(",", "."))
    return None


def _is_text(cell: str, decimal_comma: bool) -> bool:
    return _value(cell, decimal_comma) is None


def parse_measurements(text: str, source: str = "<text>", *, delimiter: str | None = None,
                       header: str = "auto", network: bool = True) -> Measurements:
    """A measurement matrix from CSV text (rules in the module docstring).

    Parameters
    ----------
    text : the file's text
    source : the name that error messages give (the file name)
    delimiter : None to sniff it, else a name of DELIMITERS or the character
    header : "auto", "row" (first row: transmitter names), "column" (first column: receiver names),
        "both" or "none"
    network : the table is a measurement matrix (rows receivers, columns transmitters), whose values absurd
        next to their column are refused (:data:`ABSURD_SPREAD`); False for another table read by the same
        rules (the anchors' coordinates, solvers.calibration.frame), which keeps only the overflow bound

    Raises MeasurementFileError (one line naming source, line and column) for anything that is not
    a matrix of measurements.
    """
    if header not in HEADERS:
        raise MeasurementFileError(f"unknown header choice {header!r}; give one of {', '.join(HEADERS)}")
    lines = []
    for k, raw in enumerate(re.split(r"\r\n|\r|\n", text)):
        content = _strip_comment(raw)
        if content.strip():
            lines.append((k + 1, content))
    if not lines:  # the same words as the recording reader's (solvers.audio) for an empty file
        raise MeasurementFileError(f"{source}: no data ({'empty file' if not text.strip() else 'only comments'})")
    d = _sniff(lines) if delimiter is None else _delimiter(delimiter)
    decimal_comma = d != ","
    rows = [(line, _split(content, d, source, line)) for line, content in lines]
    width = len(rows[0][1])
    for line, row in rows:
        if len(row) != width:
            raise MeasurementFileError(f"{source}: line {line} has {len(row)} cells, expected {width} as on line "
                                       f"{rows[0][0]} (cells separated by {_delimiter_name(d)})")
    if width == 1:
        raise MeasurementFileError(f"{source}: one cell per line (read with {_delimiter_name(d)} as delimiter): a "
                                   "network needs a column per transmitter; the delimiter is TAB, ';', ',' or spaces "
                                   "(--delimiter)")
    if all(row[-1] == "" for _, row in rows):  # a delimiter at the end of every line
        rows = [(line, row[:-1]) for line, row in rows]
        width -= 1
    header_row, header_col = _names_layout(rows, header, decimal_comma, source)
    body = rows[1:] if header_row else rows
    first = 1 if header_col else 0
    if not body or width - first == 0:
        raise MeasurementFileError(f"{source}: no measurements (only names)")
    F = np.empty((len(body), width - first))
    for i, (line, row) in enumerate(body):
        for j, cell in enumerate(row[first:]):
            value = _value(cell, decimal_comma)
            where = f"{source}: line {line}, column {j + first + 1}"
            if value is None:
                hint = " (a decimal comma needs ; or TAB as delimiter)" if _DECIMAL_COMMA.fullmatch(cell) else ""
                raise MeasurementFileError(f"{where}: {cell!r} is not a number{hint} (leave the cell empty or write "
                                           "NaN for a missing measurement)")
            if math.isinf(value):
                if cell.lower() in _INFINITE:
                    raise MeasurementFileError(f"{where}: infinite value")
                raise MeasurementFileError(f"{where}: {cell!r} overflows (beyond {sys.float_info.max:.3g}); "
                                           "check the units")
            F[i, j] = value
    _check_magnitudes(F, [line for line, _ in body], first, [row[first:] for _, row in body], source, network)
    names_r = tuple(row[0] or str(i + 1) for i, (_, row) in enumerate(body)) if header_col else \
        tuple(str(i + 1) for i in range(len(body)))
    names_t = tuple(c or str(j + 1) for j, c in enumerate(rows[0][1][first:])) if header_row else \
        tuple(str(j + 1) for j in range(F.shape[1]))
    return Measurements(F, names_r, names_t, source, d)


ABSURD_SPREAD = 1e6
"""A measurement farther from its column's median than this many times the network's spread (the median,
over the columns, of each column's median absolute deviation) is refused as a typo or a unit error. A
column holds one transmitter's measurements at every receiver, f_ij = |r_i - s_j| + o_j: they share the
offset o_j and differ by at most the receivers' distances (|f_ij - f_kj| <= |r_i - r_k|), so every column
has the spread of the receiver array whatever the offsets are; a gross error (an echo, a wrong event) is
a few times that spread and left to the robust calibration, a millionfold one is not a measurement."""


def _check_magnitudes(F: np.ndarray, lines: list[int], first: int, cells: list[list[str]], source: str,
                      network: bool = True) -> None:
    """Refuse, at reading, a value the calibration cannot compute with: (1) one whose square, summed over
    the matrix, overflows float64 (|f| above sqrt(1.8e308 / (m n)): the calibration normalises by the root
    mean square of the entries and squares them in its equations), and (2) one absurd relative to the
    others (:data:`ABSURD_SPREAD`; ``network`` tables only). One MeasurementFileError naming the file, line and
    column."""
    def refuse(i: int, j: int, why: str) -> MeasurementFileError:
        return MeasurementFileError(f"{source}: line {lines[i]}, column {j + first + 1}: {cells[i][j]!r} {why}")

    finite = np.isfinite(F)
    if not finite.any():
        return
    limit = math.sqrt(sys.float_info.max / F.size)
    big = np.argwhere(finite & (np.abs(np.where(finite, F, 0.0)) > limit))
    if len(big):
        i, j = big[0]
        raise refuse(i, j, f"is out of range: a measurement's square summed over the {F.shape[0]} x {F.shape[1]} "
                           f"matrix must stay within float64 (|value| <= {limit:.3g}); check the units")
    if not network:
        return
    counts = finite.sum(axis=0)
    usable = counts >= 3
    if not usable.any():
        return
    with np.errstate(all="ignore"):
        med = np.nanmedian(np.where(finite, F, np.nan)[:, usable], axis=0)
        mad = np.nanmedian(np.abs(np.where(finite, F, np.nan)[:, usable] - med), axis=0)
    spread = float(np.median(mad))
    if not spread > 0:
        return
    deviation = np.abs(np.where(finite, F, np.nan)[:, usable] - med)
    absurd = np.argwhere(np.nan_to_num(deviation, nan=0.0) > ABSURD_SPREAD * spread)
    if len(absurd):
        i, k = absurd[0]
        j = int(np.flatnonzero(usable)[k])
        raise refuse(i, j, f"is absurd next to the other measurements: {deviation[i, k]:.3g} from its column's median "
                           f"{med[k]:.6g}, more than {ABSURD_SPREAD:g} times the network's spread {spread:.3g} (the "
                           "median over the columns of their median absolute deviations); check the value and the units")


def _names_layout(rows, header: str, decimal_comma: bool, source: str) -> tuple[bool, bool]:
    """(first row holds names, first column holds names) by the rules of the module docstring."""
    if header != "auto":
        return header in ("row", "both"), header in ("column", "both")
    line1, top = rows[0]
    rest = top[1:]
    text_after_first = any(_is_text(c, decimal_comma) for c in rest)
    corner = top[0]
    integer_names = (bool(rest) and (corner == "" or _is_text(corner, decimal_comma))
                     and all(_INTEGER.fullmatch(c) for c in rest) and len({int(c) for c in rest}) == len(rest))
    header_row = text_after_first or integer_names
    body = rows[1:] if header_row else rows
    header_col = (header_row and (corner == "" or integer_names or _is_row_index([r[0] for _, r in body]))) or \
        any(_is_text(r[0], decimal_comma) for _, r in body)
    if integer_names and not text_after_first and body:
        first = 1 if header_col else 0
        if all(_INTEGER.fullmatch(c) or c.lower() in _MISSING for _, r in body for c in r[first:]):
            raise MeasurementFileError(
                f"{source}: line {line1} ({corner!r}, then integers) could be transmitter names or the measurements "
                f"of a receiver {corner!r}, as every measurement is an integer; say which with --header both "
                "(names) or --header column (measurements)")
    return header_row, header_col


def _is_row_index(cells: list[str]) -> bool:
    """Whether a column reads 0, 1, 2, ... or 1, 2, 3, ... (a row index, as pandas writes it)."""
    if len(cells) < 2 or not all(_INTEGER.fullmatch(c) for c in cells):
        return False
    values = [int(c) for c in cells]
    return values in (list(range(len(cells))), list(range(1, len(cells) + 1)))


def read_measurements(path: str, *, delimiter: str | None = None, header: str = "auto") -> Measurements:
    """Read a TDOA measurement matrix from a CSV file, or from standard input when path is ``-``
    (rules in the module docstring; options as :func:`parse_measurements`).

    Raises MeasurementFileError (one line naming the file, line and column) for an unreadable,
    empty, ragged or non-numeric file, or an infinite or overflowing value.
    """
    source = "stdin" if path == _STDIN else path
    try:
        data = read_input_bytes(path)
    except InputError as exc:
        raise MeasurementFileError(str(exc)) from None
    return parse_measurements(_decode(data, source), source, delimiter=delimiter, header=header)


def read_input(paths, *, delimiter: str | None = None, header: str = "auto", tdoa_options=None, analyse=None,
               progress=None) -> Measurements:
    """The one reader of every verb that takes measurements: a measurement CSV (one path, ``-`` for
    standard input), or a recording (one multichannel audio file, or one file per channel: recognised
    by their first bytes, solvers.recording.is_recording), turned into the matrix by
    solvers.audio.tdoa_matrix with `tdoa_options` (a solvers.audio.TdoaOptions; None: the defaults), or by
    `analyse` (a callable taking the solvers.recording.Recording and returning its solvers.audio.TdoaMatrix: the CLI
    passes the guided pass, solvers.audio_guided.tdoa_guided; this module imports nothing of the calibration,
    which reads its anchor files through it).
    progress: None, or a callable taking one line (the analysis's progress and notes).

    Raises MeasurementFileError or solvers.recording.RecordingError (one line) for what cannot be read.
    """
    paths = [paths] if isinstance(paths, str) else list(paths)
    audio = [p for p in paths if p != _STDIN and _is_audio(p)]
    if audio:
        if len(audio) < len(paths):
            other = next(p for p in paths if p not in audio)
            raise MeasurementFileError(f"{other} is not a recording, but {audio[0]} is: give recordings only (one "
                                       "multichannel file or one file per channel), or one measurement CSV")
        from .audio import TdoaOptions, tdoa_matrix
        from .recording import read_recording

        recording = read_recording(paths)
        tm = (analyse(recording) if analyse is not None else
              tdoa_matrix(recording, tdoa_options or TdoaOptions(), progress=progress))
        for note in tm.notes if progress is not None else ():
            progress(f"tdoa: {note}")
        return recording_measurements(tm)
    if len(paths) != 1:
        raise MeasurementFileError(f"{len(paths)} files given: a measurement CSV is one file (several files are read "
                                   "only as recordings, one per channel)")
    return read_measurements(paths[0], delimiter=delimiter, header=header)


def recording_measurements(tm) -> "Measurements":
    """The matrix of a solvers.audio.TdoaMatrix as Measurements (what every verb reads; the audio module does not
    import this one, which reads recordings through it)."""
    return Measurements(tm.F.copy(), tm.channels, tm.events, tm.source, ",")


def _is_audio(path: str) -> bool:
    from .recording import is_recording

    return is_recording(path)


def format_matrix_cell(name: str) -> str:
    """A name as a CSV cell: double-quoted (quotes doubled) when it holds a delimiter, a quote or a #."""
    quote = any(c in name for c in ',;"#\t') or name != name.strip()
    return '"' + name.replace('"', '""') + '"' if quote else name


def format_matrix(meas: Measurements, comments: tuple[str, ...] = ()) -> str:
    """The CSV text of a measurement matrix, as `read_measurements` reads it back: `comments` as # lines,
    a header row (an empty corner, then the transmitter names), one row per receiver (its name, then
    its values to 10 significant digits: 0.1 mm at an hour of sound travel; an empty cell where missing)."""
    cell = format_matrix_cell
    lines = [f"# {c}" for c in comments]
    lines.append(",".join([""] + [cell(t) for t in meas.transmitters]))
    for name, row in zip(meas.receivers, meas.F):
        lines.append(",".join([cell(name)] + [f"{v:.10g}" if math.isfinite(v) else "" for v in row]))
    return "\n".join(lines) + "\n"


def plot_formats() -> tuple[str, ...]:
    """File extensions matplotlib can write (png, pdf, svg, ...)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    return tuple(sorted(Figure().canvas.get_supported_filetypes()))


def check_output_path(path: str, option: str, reading: str | None = None, formats: tuple[str, ...] | None = None,
                      directory: bool = False) -> None:
    """Refuse, before any computing, an output path that cannot be written: a directory (a file for
    ``directory``), a missing or unwritable directory, the measurement file itself (`reading`), or
    (`formats` given) an extension not among them. Writing is tried, not guessed from permissions (which
    say yes to root on a read-only file system or in /proc): the file is opened for appending (an existing
    one keeps its bytes; one created for the test is removed), a directory gets a temporary file (a
    missing one is tried in its nearest existing parent, and not created). One-line MeasurementFileError
    naming the path and the option, in the same words for every verb: ``cannot write PATH (OPTION): why``."""
    def refuse(why: str) -> MeasurementFileError:
        return MeasurementFileError(f"cannot write {path} ({option}): {why}")

    if path == _STDIN:
        raise MeasurementFileError(f"{option} -: give a file name ({'--json prints the JSON' if option == '--out' else 'a plot is a file'})")
    if directory:
        if os.path.exists(path) and not os.path.isdir(path):
            raise refuse("it is a file; give a directory")
        parent = os.path.abspath(path)
        while not os.path.exists(parent):
            parent = os.path.dirname(parent)
        if not os.path.isdir(parent):
            raise refuse(f"{parent} is a file")
        _try_writing(parent, refuse)
        return
    if os.path.isdir(path):
        raise refuse("it is a directory")
    folder = os.path.dirname(path) or "."
    if not os.path.isdir(folder):
        raise refuse(f"no directory {folder}")
    if not os.access(folder, os.W_OK | os.X_OK) or (os.path.exists(path) and not os.access(path, os.W_OK)):
        raise refuse("permission denied")
    if reading not in (None, _STDIN) and os.path.exists(path) and os.path.exists(reading) and os.path.samefile(path, reading):
        raise MeasurementFileError(f"{option} {path} is the measurement file; give another name")
    if formats is not None:
        ext = os.path.splitext(path)[1].lstrip(".").lower()
        if ext not in formats:
            got = f"extension .{ext}" if ext else "no extension"
            raise MeasurementFileError(f"{option} {path}: {got}; give one of {', '.join('.' + f for f in formats)}")
    existed = os.path.exists(path)
    try:
        with open(path, "a", encoding="utf-8"):
            pass
    except OSError as exc:
        raise refuse(exc.strerror or str(exc)) from None
    finally:
        if not existed and os.path.isfile(path):
            os.remove(path)


def _try_writing(folder: str, refuse) -> None:
    """Create and remove a temporary file in folder, or raise refuse(why)."""
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise refuse(exc.strerror or str(exc)) from None


def report_dict(result, measurements: Measurements | None = None, units: str | None = None) -> dict:
    """The JSON report: `CalibrationResult.to_dict()` plus the node names of the file and the name
    of its distance unit (None when not given)."""
    out = result.to_dict()
    if measurements is not None:
        out["receiver_names"] = list(measurements.receivers)
        out["transmitter_names"] = list(measurements.transmitters)
    out["units"] = units
    return out


def write_json(report: dict, path: str) -> None:
    """Write the report; OSError propagates (the CLI turns it into a one-line error)."""
    with open(path, "w", encoding="utf-8") as handle:
        json.dump(report, handle, indent=1)
        handle.write("\n")


def write_nodes_csv(result, path: str, measurements: Measurements | None = None, units: str | None = None) -> None:
    """The nodes as CSV (``--csv``): one row per receiver, then per transmitter, with the columns kind
    (receiver / transmitter), name, the coordinates x, y (z), offset (transmitters; a receiver's delay where the
    fit modelled them, `CalibrationResult.receiver_delays`), the standard
    deviation of each coordinate and of the offset, and std (the root of the sum of the coordinates'
    variances, as printed); an empty cell for what is not placed or not determined. Comment lines first:
    the status line and the frame (the solver's gauge, or the anchors'). OSError propagates."""
    dim = result.dim
    axes = "xyz"[:dim]
    names_r = measurements.receivers if measurements else [str(i + 1) for i in range(result.m)]
    names_t = measurements.transmitters if measurements else [str(j + 1) for j in range(result.n)]

    def number(v) -> str:
        return f"{float(v):.9g}" if np.isfinite(v) else ""

    def axis_std(cov, k) -> list:
        if cov is None:
            return [math.nan] * dim
        with np.errstate(invalid="ignore"):
            return list(np.sqrt(np.diagonal(cov[k])[:dim]))

    unit = f" [{units}]" if units else ""
    if result.frame is not None:
        where = f"the frame of the anchors in {result.frame['source']} ({result.frame['fit']} fit)"
    elif result.gauge is not None:
        where = "the solver's gauge: receiver " + ", ".join(
            f"{names_r[g]} {role}" for g, role in zip(result.gauge, ("at the origin", "on +x", "in the xy half-plane y > 0")))
    else:
        where = "no frame (not placed)"
    lines = [f"# {result.message}", f"# coordinates{unit} in {where}",
             ",".join(["kind", "name", *axes, "offset", *(f"std_{a}" for a in axes), "std_offset", "std"])]
    for k, name in enumerate(names_r):
        delay = "" if getattr(result, "receiver_delays", None) is None else number(result.receiver_delays[k])
        lines.append(",".join(["receiver", format_matrix_cell(name), *map(number, result.receivers[k]), delay,
                               *map(number, axis_std(result.receiver_cov, k)), "", number(result.receiver_std[k])]))
    for k, name in enumerate(names_t):
        lines.append(",".join(["transmitter", format_matrix_cell(name), *map(number, result.transmitters[k]),
                               number(result.offsets[k]), *map(number, axis_std(result.transmitter_cov, k)),
                               number(result.offset_std[k]), number(result.transmitter_std[k])]))
    with open(path, "w", encoding="utf-8") as handle:
        handle.write("\n".join(lines) + "\n")


ELLIPSE_SHARE = 0.03
"""The largest 1-sigma error ellipse of a map is magnified to about this share of the map's extent (a
centimetre standard deviation on a map of metres is otherwise thinner than the line that draws it)."""


def ellipse_magnification(extent: float, stds) -> int:
    """The factor (1, 2, 5, 10, 20, 50, ...) by which a map's 1-sigma error ellipses are magnified: the
    largest one that keeps the largest node std (the root of the summed variances, at least the largest
    semi-axis) within :data:`ELLIPSE_SHARE` of the extent, at least 1."""
    stds = np.asarray(stds, dtype=float)
    stds = stds[np.isfinite(stds) & (stds > 0)]
    if not stds.size or not np.isfinite(extent) or extent <= 0:
        return 1
    limit = ELLIPSE_SHARE * extent / stds.max()
    factor = 1
    for step in itertools.cycle((2, 2.5, 2)):  # 1, 2, 5, 10, 20, 50, ...
        if factor * step > limit:
            return factor
        factor = round(factor * step)


def plot_calibration(result, path: str, measurements: Measurements | None = None, units: str | None = None) -> None:
    """Map of the calibration: receivers (triangles), transmitters (circles), each node's 1-sigma error
    ellipse (its covariance projected on the view), enlarged by one factor so that they can be seen on
    the map (:func:`ellipse_magnification`; the legend says the factor), and every rejected measurement as a dashed red
    line between its receiver and transmitter; `units` labels the axes. A 3D calibration is drawn as its
    three projections (xy, xz, yz)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Ellipse

    names_r = measurements.receivers if measurements else [str(i + 1) for i in range(result.m)]
    names_t = measurements.transmitters if measurements else [str(j + 1) for j in range(result.n)]
    views = [(0, 1)] if result.dim == 2 else [(0, 1), (0, 2), (1, 2)]
    fig, axs = plt.subplots(1, len(views), figsize=(7 * len(views), 7), squeeze=False)
    R, S = result.receivers, result.transmitters
    rejected = ~result.inliers & np.isfinite(result.residuals)
    placed = np.vstack([R, S])
    placed = placed[np.all(np.isfinite(placed), axis=1)]
    extent = float(np.ptp(placed, axis=0).max()) if len(placed) else 0.0
    magnify = ellipse_magnification(extent, np.concatenate([result.receiver_std, result.transmitter_std]))
    for ax, (a, b) in zip(axs[0], views):
        first = True
        for i, j in zip(*np.nonzero(rejected)):
            ax.plot([R[i, a], S[j, a]], [R[i, b], S[j, b]], "--", color="tab:red", lw=0.8,
                    label="rejected measurement" if first else None)
            first = False
        ax.plot(R[:, a], R[:, b], "^", color="tab:blue", ms=8, label="receivers")
        ax.plot(S[:, a], S[:, b], "o", color="tab:orange", ms=7, label="transmitters")
        ellipses = []
        for P, std, cov, names in ((R, result.receiver_std, result.receiver_cov, names_r),
                                   (S, result.transmitter_std, result.transmitter_cov, names_t)):
            for k, name in enumerate(names):
                if not np.all(np.isfinite(P[k])):
                    continue
                ax.annotate(name, P[k, [a, b]], textcoords="offset points", xytext=(4, 4), fontsize=8)
                block = cov[k][np.ix_([a, b], [a, b])] if cov is not None else np.eye(2) * std[k] ** 2 / result.dim
                if np.all(np.isfinite(block)) and np.trace(block) > 0:
                    lam, vec = np.linalg.eigh(block)
                    ellipses.append((P[k, [a, b]], np.sqrt(np.maximum(lam, 0.0)), vec))
        for k, (centre, semi, vec) in enumerate(ellipses):
            angle = math.degrees(math.atan2(vec[1, 1], vec[0, 1]))
            ax.add_patch(Ellipse(centre, 2 * magnify * semi[1], 2 * magnify * semi[0], angle=angle, fill=False,
                                 color="gray", lw=0.7, label=None if k else
                                 "1-sigma ellipses" + (f" x {magnify}" if magnify > 1 else "")))
        ax.set_aspect("equal")
        unit = f" [{units}]" if units else ""
        ax.set_xlabel("xyz"[a] + unit)
        ax.set_ylabel("xyz"[b] + unit)
        ax.legend(loc="best", fontsize=8)
        ax.grid(alpha=0.3)
    fig.suptitle(f"{result.status}: rms {result.rms:.3g}, {int((~result.inliers & np.isfinite(result.residuals)).sum())} "
                 f"rejected, {len(result.warnings)} warning(s)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
