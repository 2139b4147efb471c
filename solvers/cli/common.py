"""What the verb groups share: option types, reading a system file, output checks before any work, progress
lines."""
from __future__ import annotations

import argparse
import os
import sys


class UserError(Exception):
    """An error caused by the input; printed as one line."""


MAX_MEMORY_ENV = "TDOA_WORKBENCH_MAX_MEMORY"
"""Environment variable with the default of ``--max-memory`` (e.g. ``4G``)."""


def _nonnegative(option: str):
    """An argparse type: an integer >= 0, with an error naming the option."""
    return _integer_at_least(option, 0)


def _integer_at_least(option: str, minimum: int):
    """An argparse type: an integer >= minimum, with an error naming the option."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be an integer >= {minimum}, got {value}")
        return value

    parse.__name__ = option
    return parse


def _memory_size(text: str) -> int:
    """Bytes from ``8G``, ``512M``, ``1.5GB`` or a plain number of bytes (binary units)."""
    units = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}
    t = text.strip().upper().removesuffix("IB").removesuffix("B")
    unit = t[-1:] if t[-1:] in units else ""
    try:
        value = float(t[: len(t) - len(unit)]) * units[unit]
    except ValueError:
        raise argparse.ArgumentTypeError(f"memory size must look like 8G, 512M or 1000000, got {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"memory size must be positive, got {text!r}")
    return int(value)


def _default_max_memory() -> str | None:
    """$TDOA_WORKBENCH_MAX_MEMORY, or None: F4's default (a share of the machine's available memory)."""
    return os.environ.get(MAX_MEMORY_ENV) or None


def _f4_options(args: argparse.Namespace, linear_substitution: bool = False, reduced: bool = True):
    """F4 options of the command line; ``linear_substitution`` for system files (analysis.engine.f4.F4Options: the
    TDOA formulations keep F4 on their inputs, whose matrix statistics the tables record); ``reduced`` False
    where only leading monomials are read (a degree without --gb: a minimal basis, no final tail reduction)."""
    from analysis.engine.f4 import F4Options

    if args.verbose and args.backend in ("auto", "sparse"):
        from analysis.engine import native

        print(f"[f4] {native.describe()}", file=sys.stderr)
    return F4Options(backend=args.backend, max_matrix_cells=args.max_cells, max_memory=args.max_memory,
                     verbose=args.verbose, threads=args.threads, linear_substitution=linear_substitution,
                     reduced=reduced)


def _add_f4_caps(p: argparse.ArgumentParser) -> None:
    """--max-cells and --max-memory, the F4 caps of every verb that runs the engine on a system file (the
    75% is analysis.engine.f4.MEMORY_SHARE, not imported here: --help stays free of numpy; a test compares)."""
    p.add_argument("--max-cells", type=_nonnegative("--max-cells"), default=None, metavar="N",
                   help="cap on F4 matrix rows*cols (default none: the memory cap decides)")
    p.add_argument("--max-memory", type=_memory_size, default=_default_max_memory(), metavar="SIZE",
                   help=f"stop before an F4 matrix needs more memory than this (its sparse rows and their reduction), "
                   f"e.g. 4G (default ${MAX_MEMORY_ENV}, else 75%% of the machine's available memory)")


def read_system_arg(path: str, name: str | None = None):
    """The system in FILE ('-': stdin), in either format (analysis.formulations.systemfile.read_system_text): an
    analysis.engine.io.System (a plain system) or a ParametricSystem named ``name`` (default: the path); a
    one-line UserError for anything wrong. Every verb that takes a system FILE reads it here."""
    from analysis.engine.io import InputError, decode_text, read_input_bytes
    from analysis.formulations.systemfile import ParametricError, read_system_text

    source = "<stdin>" if path == "-" else path
    try:
        return read_system_text(decode_text(read_input_bytes(path), source), name or source)
    except (InputError, ParametricError) as e:
        raise UserError(str(e)) from None


def _delayed_progress(after: float | None = None):
    """A progress callback that prints to stderr, with the elapsed time, once the call has run ``after`` seconds
    (default: 2 s on a terminal, 30 s into a pipe, as calibrate's): a quick call prints nothing."""
    import time

    start = time.time()
    after = (2.0 if sys.stderr.isatty() else 30.0) if after is None else after

    def say(line: str) -> None:
        elapsed = time.time() - start
        if elapsed >= after:
            print(f"[{elapsed:6.1f} s] {line}", file=sys.stderr, flush=True)

    return say


def _check_outputs(outputs: dict, readings=(), directories: dict | None = None) -> None:
    """Refuse, before any computing, output paths that cannot be written (check_output_path: writing is tried,
    against every input file) or that name the same file: the one check of every verb that writes. outputs:
    {option: (file path or None, formats or None)}; directories: {option: directory path or None}."""
    from solvers.calibrate_io import MeasurementFileError, check_output_path

    given = [(option, path, formats) for option, (path, formats) in outputs.items() if path]
    try:
        for option, path in (directories or {}).items():
            if path:
                check_output_path(path, option, directory=True)
        for option, path, formats in given:
            for reading in list(readings) or [None]:
                check_output_path(path, option, reading=reading, formats=formats)
        for a, (option, path, _) in enumerate(given):
            for other, path2, _ in given[a + 1:]:
                if os.path.abspath(path) == os.path.abspath(path2):
                    raise MeasurementFileError(f"{option} and {other} name the same file {path}")
    except MeasurementFileError as e:
        raise UserError(str(e)) from None
