"""The parser of every verb, the one place where a user's error becomes one line on stderr, and ``main``."""
from __future__ import annotations

import argparse
import os
import sys

from solvers.cli.common import UserError
from solvers.cli.complexity import _add_degree, _add_reproduce, _add_tables, _add_template_check
from solvers.cli.systems import _add_count, _add_generate, _add_solve
from solvers.cli.networks import _add_calibrate, _add_tdoa


class _VersionAction(argparse.Action):
    """``--version``: the installed version, looked up only when asked (importlib.metadata costs 50 ms)."""

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"{parser.prog} {_version()}")
        parser.exit()


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("tdoa-workbench")
    except PackageNotFoundError:  # pragma: no cover - running from a checkout without installing
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tdoa-workbench",
        description="Polynomial-system complexity analysis (Groebner bases over GF(p), root counts of your own "
        "systems), minimal-solver generation and self-calibration of TDOA/TOA sensor networks in 2D and 3D.",
    )
    parser.add_argument("--version", action=_VersionAction, nargs=0, help="show the program's version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    _add_degree(sub)
    _add_tables(sub)
    _add_solve(sub)
    _add_generate(sub)
    _add_count(sub)
    _add_template_check(sub)
    _add_reproduce(sub)
    _add_calibrate(sub)
    _add_tdoa(sub)
    return parser


def _user_error(e: Exception) -> tuple[str, int] | None:
    """(one-line message, exit status) for an exception a user's input can cause, else None. Looks the
    exception classes up only in modules already imported (none can be raised from the others), so
    that a command does not import sympy just to report errors."""
    def cls(module: str, name: str) -> type:
        return getattr(sys.modules.get(module), name, ())

    if isinstance(e, (cls("analysis.engine.degree", "PrimeDisagreement"), cls("analysis.engine.modular", "ReconstructionFailed"))):
        return str(e), 3
    if isinstance(e, cls("analysis.engine.msolve", "MsolveError")):
        return f"{e}; --engine own computes without it", 2
    if isinstance(e, cls("analysis.engine.linalg", "MatrixTooLarge")):
        flag = "--max-memory" if "memory cap" in str(e) else "--max-cells"  # the cap that stopped it
        return f"{e}; raise {flag} if the machine allows, or give a smaller system", 2
    if isinstance(e, cls("analysis.formulations.tdoa", "InconsistentSample")):
        return f"{e}; try another --seed", 2
    if isinstance(e, (UserError, ValueError, OverflowError, cls("analysis.formulations.tdoa", "SamplingFailed"))):
        return str(e), 2  # ValueError covers InputError, BadPrime and NotZeroDimensional
    if isinstance(e, MemoryError):
        return "out of memory; lower --max-memory so that the computation stops before the machine's limit", 2
    if isinstance(e, OSError):
        return (f"{e.filename}: " if e.filename else "") + str(e.strerror or e), 2
    return None


def _run(args: argparse.Namespace) -> int:
    """Run a subcommand; every error a user can cause becomes one line on stderr (exit 2, 3 when primes
    disagree), never a traceback. Anything else is a bug and keeps its traceback."""
    try:
        status = args.func(args)
        sys.stdout.flush()  # a closed pipe shows here, not at interpreter exit
        return status
    except BrokenPipeError:
        # the reader went away (e.g. | head): stop quietly, as a command killed by SIGPIPE would
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Exception as e:
        known = _user_error(e)
        if known is None:
            raise
        message, status = known
        print(f"tdoa-workbench {args.command}: error: {' '.join(message.split())}", file=sys.stderr)
        return status


VALUE_OPTIONS = ("--saturate",)
"""Options whose value may start with '-' (a polynomial such as -x-1): the word after the option is always
its value, as it is with ``--saturate=-x-1`` (argparse would take ``-x-1`` for an option)."""


def _join_values(argv: list[str]) -> list[str]:
    """argv with ``--saturate VALUE`` written as ``--saturate=VALUE`` (see :data:`VALUE_OPTIONS`)."""
    out, k = [], 0
    while k < len(argv):
        if argv[k] in VALUE_OPTIONS and k + 1 < len(argv) and argv[k + 1].startswith("-"):
            out.append(f"{argv[k]}={argv[k + 1]}")
            k += 2
        else:
            out.append(argv[k])
            k += 1
    return out


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(_join_values(sys.argv[1:] if argv is None else list(argv)))
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    return _run(args)
