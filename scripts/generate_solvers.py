"""Regenerate the solvers in solvers/generated/: template search over GF(p), spec JSON and module.

Usage: python scripts/generate_solvers.py [6r4s] [9r3s] [--emit-only]
  --emit-only  re-emit the .py modules from the committed JSON specs (no template search).
"""
from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from solvers.codegen import SOLVERS, emit_all, generate  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("configs", nargs="*", default=list(SOLVERS), help=f"subset of {', '.join(SOLVERS)}")
    parser.add_argument("--emit-only", action="store_true", help="re-emit modules from the committed specs")
    args = parser.parse_args(argv)
    if args.emit_only:
        for path in emit_all():
            print(f"emitted {path}")
        return 0
    for label in args.configs:
        stats = generate(label)
        print(f"{label}: {stats.formulation}  action {stats.action}  |B| {stats.basis_size}  "
              f"final template {stats.rows} x {stats.cols}  steps {stats.steps} ({stats.total_rows} rows)  "
              f"{stats.seconds:.1f} s  -> {stats.module}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
