"""Regenerate the solvers in solvers/generated/: root counts certified over GF(p), spec JSON and module.

Usage: python scripts/generate_solvers.py [6r4s 9r3s 8r3s 7r3s 6r3s 5r4s 5r5s ...] [--emit-only]
  6r4s           the eigenvalue pencil (solvers.codegen); the others: parameter homotopies (solvers.generate).
  --emit-only    re-emit the pencil module from its committed JSON spec (no construction).
Same as `tdoa-workbench generate CONFIG` for each configuration.
"""
from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from solvers import generate as gen  # noqa: E402
from solvers.codegen import SOLVERS as PENCILS  # noqa: E402
from solvers.codegen import emit_all  # noqa: E402
from solvers.codegen import generate as generate_pencil  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    every = list(PENCILS) + list(gen.SOLVERS)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("configs", nargs="*", default=every, help=f"subset of {', '.join(every)}")
    parser.add_argument("--emit-only", action="store_true", help="re-emit the pencil module from its committed spec")
    args = parser.parse_args(argv)
    if args.emit_only:
        for path in emit_all():
            print(f"emitted {path}")
        return 0
    for label in args.configs:
        if label in PENCILS:
            stats = generate_pencil(label)
            print(f"{label}: {stats.formulation}  {stats.method}  |B| {stats.degree}  size {stats.size[0]} x "
                  f"{stats.size[1]}  {stats.seconds:.1f} s  -> {stats.module}", flush=True)
        elif label in gen.SOLVERS:
            print(gen.generate(label, progress=lambda msg: print("  " + msg, file=sys.stderr, flush=True)).summary(), flush=True)
        else:
            parser.error(f"unknown configuration {label!r}; valid: {', '.join(every)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
