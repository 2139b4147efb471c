"""Regenerate the solvers in solvers/generated/: construction over GF(p) and checks, spec JSON and module.

Usage: python scripts/generate_solvers.py [6r4s] [9r3s] [--method curve-pencil|homotopy|staged] [--emit-only]
  --method     force a construction method (default: the formulation's, solvers.template.solver_method).
  --emit-only  re-emit the .py modules from the committed JSON specs (no construction).
"""
from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from solvers.codegen import SOLVERS, emit_all, generate  # noqa: E402
from solvers.template import METHODS  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("configs", nargs="*", default=list(SOLVERS), help=f"subset of {', '.join(SOLVERS)}")
    parser.add_argument("--method", choices=METHODS, default=None, help="force a construction method")
    parser.add_argument("--emit-only", action="store_true", help="re-emit modules from the committed specs")
    args = parser.parse_args(argv)
    if args.emit_only:
        for path in emit_all():
            print(f"emitted {path}")
        return 0
    for label in args.configs:
        stats = generate(label, method=args.method)
        print(f"{label}: {stats.formulation}  {stats.method}  |B| {stats.degree}  size {stats.size[0]} x {stats.size[1]}  "
              f"{stats.seconds:.1f} s  checks {stats.checks}  -> {stats.module}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
