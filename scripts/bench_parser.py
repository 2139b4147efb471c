"""Benchmark the system-file reader and `degree` on large inputs against Singular (issue 46's cases).

Cases (every file written from a fixed seed into a temporary directory):

* ``linear-10mb``: 41,000 random linear polynomials in 50 unknowns (about 10 MB; each uses 35 of the
  unknowns with coefficients up to 999);
* ``linear-1mb``: the first 4,100 of them (about 1 MB);
* ``digits-1e6``: ``x^2 - N*y, y^2 - x + 1`` with N of 10^6 decimal digits.

For each: ``parse_s``, reading the file in a fresh process (``analysis.engine.io.read_system``, the
interpreter's start and imports excluded); ``degree_s``, the whole ``tdoa-workbench degree FILE``
command in a fresh process by wall clock; ``singular_s``, Singular (``Singular -q``, when on PATH)
on the same system (``std`` and ``vdim``, written by ``analysis.engine.io.to_singular``), by wall
clock minus the start-up of a trivial Singular run; ``ratio`` = degree_s / singular_s. Both sides
answer the same question (the degree, or that the system is inconsistent) and their answers are compared
(``agree``). Each child runs under ``--cap`` seconds (default 300).

Writes tables/bench_parser.timing.json (untracked: seconds are facts of the run, not results): the rows
and the run record (date, machine, versions), and prints one line per case. Usage:
python scripts/bench_parser.py [--cases NAME ...] [--cap 300] [--out DIR]
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import platform
import random
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from analysis.engine.io import read_system, to_singular  # noqa: E402

SEED = 46
COLUMNS = ["case", "megabytes", "polynomials", "terms", "parse_s", "degree_s", "singular_s", "ratio", "own_answer",
           "singular_answer", "agree"]


def linear_text(npolys: int, nvars: int = 50, used: int = 35, seed: int = SEED) -> str:
    """Random linear polynomials in msolve's format (characteristic 0)."""
    rng = random.Random(seed)
    names = [f"x{i}" for i in range(nvars)]
    lines = []
    for _ in range(npolys):
        idx = sorted(rng.sample(range(nvars), used))
        terms = "".join(f"{rng.choice('+-')}{rng.randint(1, 999)}*{names[i]}" for i in idx)
        lines.append(terms.lstrip("+") + f"+{rng.randint(1, 999)}")
    return ",".join(names) + "\n0\n" + ",\n".join(lines) + "\n"


def digits_text(ndigits: int = 10**6, seed: int = SEED) -> str:
    rng = random.Random(seed)
    n = str(rng.randint(1, 9)) + "".join(rng.choice("0123456789") for _ in range(ndigits - 1))
    return f"x,y\n0\nx^2-{n}*y,\ny^2-x+1\n"


CASES = {
    "linear-1mb": lambda: linear_text(4_100),
    "linear-10mb": lambda: linear_text(41_000),
    "digits-1e6": digits_text,
}

PARSE_CHILD = """
import sys, time
t = time.perf_counter()
from analysis.engine.io import read_system
t0 = time.perf_counter()
s = read_system(sys.argv[1])
print(time.perf_counter() - t0, len(s.polynomials), sum(len(f) for f in s.polynomials))
"""


def _timed(argv: list[str], cap: float, stdin: str | None = None) -> tuple[float | None, str]:
    """(wall seconds, stdout) of a child run under ``cap`` seconds, or (None, why it gave no answer)."""
    t0 = time.perf_counter()
    try:
        done = subprocess.run(argv, capture_output=True, text=True, timeout=cap, cwd=ROOT, input=stdin)
    except subprocess.TimeoutExpired:
        return None, f"over the {cap:g} s cap"
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        return None, (done.stderr.strip().splitlines() or ["exit %d" % done.returncode])[-1]
    return seconds, done.stdout


def _own_answer(out: str) -> str:
    m = re.search(r"degree (\d+)", out)
    return f"degree {m.group(1)}" if m else out.strip().splitlines()[0] if out.strip() else "?"


def _singular_answer(out: str) -> str:
    numbers = [int(v) for v in re.findall(r"^-?\d+$", out, re.MULTILINE)]
    if len(numbers) < 2:
        return "?"
    vdim, dim = numbers[-2], numbers[-1]
    return "degree 0" if dim == -1 else f"degree {vdim}" if dim == 0 else f"dimension {dim}"


def bench(name: str, tmp: Path, cap: float, singular: str | None, startup: float) -> dict:
    path = tmp / f"{name}.ms"
    path.write_text(CASES[name]())
    row = {"case": name, "megabytes": round(path.stat().st_size / 1e6, 2)}
    seconds, out = _timed([sys.executable, "-c", PARSE_CHILD, str(path)], cap)
    if seconds is not None:
        parse_s, npolys, nterms = out.split()
        row.update(parse_s=round(float(parse_s), 3), polynomials=int(npolys), terms=int(nterms))
    print(f"{name}: parse {row.get('parse_s', out)}", file=sys.stderr, flush=True)
    seconds, out = _timed([sys.executable, "-m", "solvers.cli", "degree", str(path)], cap)
    row["degree_s"] = round(seconds, 3) if seconds is not None else ""
    row["own_answer"] = _own_answer(out) if seconds is not None else out
    print(f"{name}: degree {row['degree_s']} s, {row['own_answer']}", file=sys.stderr, flush=True)
    if singular:
        script = tmp / f"{name}.sing"
        script.write_text(to_singular(read_system(path)))
        seconds, out = _timed([singular, "-q", str(script)], cap)
        if seconds is not None:
            row["singular_s"] = round(max(seconds - startup, 1e-3), 3)
            row["singular_answer"] = _singular_answer(out)
            if row["degree_s"] != "":
                row["ratio"] = round(row["degree_s"] / row["singular_s"], 2)
            row["agree"] = row["singular_answer"] == row["own_answer"]
        else:
            row["singular_answer"] = out
        print(f"{name}: Singular {row.get('singular_s', out)} s", file=sys.stderr, flush=True)
    return row


def run_record(singular: str | None) -> dict:
    """The facts of a timed run: date, machine, processor, Python, and Singular's path and version."""
    version = subprocess.run([singular, "-v", "-q", "-c", "quit;"], capture_output=True, text=True).stdout.strip() \
        if singular else None
    return {"date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"), "machine": platform.node(),
            "processor": platform.processor() or platform.machine(), "python": platform.python_version(),
            "singular": singular, "singular_version": (version or "").splitlines()[:1]}


def write_timing(path: Path, record: dict, columns: list[str], rows: list[dict]) -> None:
    """Write the run record with its rows (an untracked ``*.timing.json``) and print one line per row."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({**record, "columns": columns, "rows": rows}, indent=1) + "\n")
    for row in rows:
        print(", ".join(f"{k}={row.get(k, '')}" for k in columns))


def bench_arguments(doc: str, cases: list[str], cap: float, fuzz: bool = False) -> argparse.Namespace:
    """--cases (default all), --cap (seconds per child), --out (directory of the run record) and, with
    ``fuzz``, --fuzz N (a number of fuzz cases instead of the cases)."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--cases", nargs="+", choices=sorted(cases), default=list(cases))
    parser.add_argument("--cap", type=float, default=cap)
    parser.add_argument("--out", type=Path, default=ROOT / "tables")
    if fuzz:
        parser.add_argument("--fuzz", type=int, default=0, metavar="N")
    return parser.parse_args()


def main() -> int:
    args = bench_arguments(__doc__, list(CASES), 300.0)
    singular = shutil.which("Singular")
    startup = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if singular:
            (tmp / "empty.sing").write_text("quit;\n")
            runs = [_timed([singular, "-q", str(tmp / "empty.sing")], 60)[0] or 0.0 for _ in range(3)]
            startup = min(runs)
        rows = [bench(name, tmp, args.cap, singular, startup) for name in args.cases]
    write_timing(args.out / "bench_parser.timing.json",
                 {**run_record(singular), "singular_startup_s": round(startup, 3), "seed": SEED}, COLUMNS, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
