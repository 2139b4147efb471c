"""Regenerate the solvers in solvers/generated/: root counts certified over GF(p), spec JSON and module.

Usage: python scripts/generate_solvers.py [6r4s 9r3s 8r3s 7r3s 6r3s 5r4s 5r5s 4r5s ...] [--emit-only]
  CONFIG         build the configuration's solver again (solvers.generate.generate; the 6r4s eigenvalue
                 pencil, the others parameter homotopies whose start roots monodromy recomputes).
  --emit-only    re-emit the modules of the given (default: all) committed solvers from their committed
                 JSON specs (no construction, numerics unchanged); a homotopy spec first takes its
                 configuration's current step control (solvers.generate.STEP_CONTROL: its "tracker" and
                 "retrack" fields; solvers.generate.committed_spec_text).
  --method M     build with method M instead (3r3stoa --method action-matrix: the elimination-template
                 solver, written beside the homotopy one).
  --from-monodromy PATH
                 start from this monodromy checkpoint (scripts/monodromy_counts.py; one configuration). The
                 configurations of solvers.generate.MONODROMY_CHECKPOINTS (7r5s3d, 6r6s3d: 3D TDOA minimal
                 cells, numerical evidence) take their file there by default, in $TDOA_WORKBENCH_CACHE/monodromy/
                 (7r5s-seed0.json; 6r6s-seed1.json, the seed with the 3920th root).
Same as `tdoa-workbench generate CONFIG --out solvers/generated` for each configuration.
"""
from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from analysis.sweeps.paths import cache_dir  # noqa: E402
from solvers import generate as gen  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    every = list(gen.SOLVERS)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("configs", nargs="*", default=every, help=f"subset of {', '.join(every)}")
    parser.add_argument("--emit-only", action="store_true", help="re-emit the modules from their committed specs")
    parser.add_argument("--method", choices=list(gen.METHODS), help="build with this method (default: the "
                        "configuration's own); action-matrix solvers are written beside the homotopy ones")
    parser.add_argument("--from-monodromy", metavar="PATH", help="a monodromy checkpoint to start from (one "
                        "configuration; default for 7r5s3d, 6r6s3d: the cache's file of solvers.generate.MONODROMY_CHECKPOINTS)")
    args = parser.parse_args(argv)
    if args.from_monodromy and len(args.configs) != 1:
        parser.error("--from-monodromy is for one configuration")
    unknown = [c for c in args.configs if c not in gen.SOLVERS]
    if unknown:
        parser.error(f"unknown configuration(s) {', '.join(unknown)}; valid: {', '.join(every)}")
    if args.emit_only:
        for json_path in gen.committed_specs():
            if os.path.basename(json_path).split("_")[1] in args.configs:
                spec_text = gen.committed_spec_text(json_path)
                with open(json_path, encoding="utf-8") as fh:
                    stale = fh.read() != spec_text
                if stale:
                    with open(json_path, "w", encoding="utf-8", newline="\n") as fh:
                        fh.write(spec_text)
                    print(f"step control written into {json_path}")
                py_path, text = gen.emit_committed(json_path)
                with open(py_path, "w", encoding="utf-8", newline="\n") as fh:
                    fh.write(text)
                print(f"emitted {py_path}")
        return 0
    for label in args.configs:
        checkpoint = args.from_monodromy
        if checkpoint is None and label in gen.MONODROMY_CHECKPOINTS:
            checkpoint = str(cache_dir("monodromy") / gen.MONODROMY_CHECKPOINTS[label])
        result = gen.generate(label, args.method, out=gen.GENERATED_DIR, from_monodromy=checkpoint,
                              progress=lambda msg: print("  " + msg, file=sys.stderr, flush=True))
        print(result.summary(), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
