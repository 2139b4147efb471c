"""A large linear system by `degree` against Singular's `std`: CPU seconds of each whole process, taking turns.

The system is seeded and written here (no file is committed): ``--unknowns`` n dense linear equations in n
unknowns over GF(``--prime``), random nonzero coefficients (numpy ``default_rng(--seed)``), one solution; at
n = 250 and p = 2^31 - 1 the file has about 0.94 MB. The own side is ``python -m solvers.cli degree FILE
--json`` in a fresh process (parsing, the linear substitution and F4 included); Singular 4.x reads the same
polynomials (``option(redSB); std``) when it is installed (``apt-get install singular``). Each side runs
``--repeat`` times, alternating; the user CPU seconds (``os.wait4``) are compared, as on a loaded machine
the wall clock is several times the CPU time. Both must find one solution.

Writes tables/bench_linear.md and .meta.json (date, commit, load average at the start and the end).

Usage: python scripts/bench_linear.py [--unknowns 250] [--prime 2147483647] [--seed 0] [--repeat 3]
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "tables" / "bench_linear"


def write_system(n: int, prime: int, seed: int, folder: Path) -> tuple[Path, Path]:
    """The msolve-format file and the Singular script of the seeded system."""
    import numpy as np

    rng = np.random.default_rng(seed)
    names = [f"x{i + 1}" for i in range(n)]
    rows = []
    for _ in range(n):
        values = rng.integers(1, prime, n + 1)
        rows.append("+".join(f"{int(v)}*{x}" for v, x in zip(values, names)) + f"+{int(values[-1])}")
    system = folder / "linear.ms"
    system.write_text(",".join(names) + "\n" + str(prime) + "\n" + ",\n".join(rows) + "\n", encoding="ascii")
    script = folder / "linear.sing"
    script.write_text(f"ring r = {prime}, ({','.join(names)}), dp;\noption(redSB);\nideal i = " + ",\n".join(rows)
                      + ";\nideal g = std(i);\nprint(vdim(g));\nquit;\n", encoding="ascii")
    return system, script


def run_timed(argv: list[str], cwd: Path) -> tuple[float, float, str]:
    """(user CPU seconds, wall seconds, stdout) of one process, by os.wait4 on the child itself."""
    t0 = time.perf_counter()
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(argv, cwd=cwd, stdout=out, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        code = os.waitstatus_to_exitcode(status)
        proc.returncode = code
        out.seek(0)
        err.seek(0)
        if code:
            raise RuntimeError(f"{' '.join(argv[:4])} failed ({code}): {err.read().decode()[-500:]}")
        return usage.ru_utime, wall, out.read().decode()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--unknowns", type=int, default=250)
    parser.add_argument("--prime", type=int, default=2147483647)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    singular = shutil.which("Singular")
    load_start = os.getloadavg()
    own, theirs = [], []
    with tempfile.TemporaryDirectory(prefix="bench-linear-") as name:
        folder = Path(name)
        system, script = write_system(args.unknowns, args.prime, args.seed, folder)
        size = system.stat().st_size
        print(f"{system.name}: {args.unknowns} unknowns, {size / 1e6:.2f} MB", file=sys.stderr)
        for k in range(args.repeat):
            user, wall, out = run_timed([sys.executable, "-m", "solvers.cli", "degree", str(system), "--json"], ROOT)
            report = json.loads(out)
            if report["degree"] != 1:
                raise RuntimeError(f"degree found {report['degree']} solutions, not 1")
            own.append((user, wall, report["seconds"]))
            print(f"round {k + 1}: degree {user:.2f} s user ({wall:.2f} s wall)", file=sys.stderr)
            if singular:
                user, wall, out = run_timed([singular, "-q", str(script)], folder)
                if out.split()[-1] != "1":
                    raise RuntimeError(f"Singular found {out.split()[-1]} solutions, not 1")
                theirs.append((user, wall))
                print(f"round {k + 1}: Singular {user:.2f} s user ({wall:.2f} s wall)", file=sys.stderr)
    best_own = min(u for u, _, _ in own)
    best_theirs = min(u for u, _ in theirs) if theirs else None
    ratios = [a[0] / b[0] for a, b in zip(own, theirs)]
    meta = {
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "commit": subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip(),
        "load_average_at_start": load_start, "load_average_at_end": os.getloadavg(), "cpus": os.cpu_count(),
        "unknowns": args.unknowns, "prime": args.prime, "seed": args.seed, "file_bytes": size,
        "repeat": args.repeat, "singular": singular,
        "timing": "user CPU seconds of each whole process (os.wait4), alternating; best of each",
        "own_user_s": [round(u, 3) for u, _, _ in own], "own_wall_s": [round(w, 3) for _, w, _ in own],
        "own_engine_s": [round(s, 3) for _, _, s in own],
        "singular_user_s": [round(u, 3) for u, _ in theirs], "singular_wall_s": [round(w, 3) for _, w in theirs],
    }
    OUT.with_suffix(".meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    lines = [
        f"`degree` on a linear system against Singular's `std`: {args.unknowns} dense linear equations in "
        f"{args.unknowns} unknowns over GF({args.prime}) (seed {args.seed}, {size / 1e6:.2f} MB), one solution; user "
        f"CPU seconds of each whole process, {args.repeat} alternating runs, best of each; load average "
        f"{load_start[0]:.1f} at the start ({os.cpu_count()} cores).",
        "",
        "| own degree s | Singular std s | ratio | rounds |",
        "|---|---|---|---|",
        f"| {best_own:.2f} | {'' if best_theirs is None else f'{best_theirs:.2f}'} | "
        f"{'' if best_theirs is None else f'{best_own / best_theirs:.2f}'} | "
        f"{'' if not ratios else f'{min(ratios):.2f}-{max(ratios):.2f}'} |",
    ]
    OUT.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
