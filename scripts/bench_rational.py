"""Benchmark the reduced Gröbner basis over Q (``degree --gb``) on large coefficients against Singular (issue 46).

Cases (every file written from a fixed seed into a temporary directory; A, B, ... random integers of the
given number of decimal digits):

* ``linear-2000``: ``B*x - A`` with 2,000-digit A and B (the issue's case: refused after 400 primes);
* ``linear-10000``: the same with 10,000 digits;
* ``linear20-200``: 20 dense linear polynomials in 20 unknowns, 200-digit coefficients (a basis of
  4,000-digit fractions; FLINT's fraction-free row echelon form);
* ``quadratic-5000``: ``A*x^2 + B*y - C, D*x*y - E`` with 5,000-digit coefficients: a basis of three
  elements whose fractions have 10,000 digits;
* ``quadratic-50000``: the same with 50,000 digits (fractions of 100,000 digits: the fixed costs of a
  command no longer count);
* ``ternary-1000``: three quadrics in x, y, z with 1,000-digit coefficients (six basis elements of about
  4,000 digits);
* ``katsura-4`` (``examples/katsura4.ms``): small coefficients, where primes are the fast way.

For each, in a fresh process with the interpreter's start excluded (the same child script, timed inside):
``primes_s``, :func:`analysis.engine.modular.rational_basis` with primes only (``primes_used`` of them);
``exact_s``, :func:`analysis.engine.exact.exact_basis` alone (FLINT's Buchberger over Z, fastest of
three); ``warm_s``, the whole ``tdoa-workbench degree FILE --gb --json`` in-process (majority of primes,
then primes with the exact computation racing them, then the output), fastest of three calls after a
first one that loads the imports and compiled kernels, as Singular has them loaded at its start;
``engine_s``, the library calls of that route on the parsed system (the majority of primes, then
:func:`~analysis.engine.modular.rational_basis` with the race, then the basis as text), without the
command's argument parsing and file reading, as Singular's ``std`` is timed without reading its input
(fastest of three);
``command_s``, the same command in a fresh process by wall clock minus that of a trivial system
(``x - 1``). ``singular_s``: Singular 4 (``std`` with ``option(redSB)``, the basis made a string),
20 times in one run, by wall clock minus the start-up of a trivial Singular run, divided by 20. Ratios
(``ratio``, ``warm_ratio``, ``primes_ratio``, ``exact_ratio``) are against Singular in the same run;
``agree``: the command's basis and Singular's, made monic, are the same set. Without Singular on PATH
its columns are empty and the script says so. Each child runs under ``--cap`` seconds (default 120).

``--fuzz N``: instead, N systems of ``scripts/fuzz_engine.py``'s characteristic-0 category with every
leading coefficient replaced by a random integer of 30 to 2,000 digits (:func:`large_leading_case`),
compared with Singular like the fuzz (``agree``: same dimension, degree and reduced basis), with the
engine's total, median and largest seconds per case (in-process, 30 s each at most) and Singular's total
for all of them (one process); written to tables/bench_rational_fuzz.timing.json.

Writes tables/bench_rational.timing.json (untracked: seconds are facts of the run, not results) and prints
one line per case. Usage: python scripts/bench_rational.py [--cases NAME ...] [--cap 120] [--out DIR] [--fuzz N]
"""
from __future__ import annotations

import json
import random
import shutil
import sys
import tempfile
import time
from fractions import Fraction
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from analysis.engine.io import format_polynomial, parse_msolve, parse_polynomial, read_system  # noqa: E402
from analysis.engine.polytext import _int_to_digits  # noqa: E402
from analysis.engine.modular import order_key  # noqa: E402
import fuzz_engine  # noqa: E402  (scripts/ is on the path of a script)
from bench_parser import _timed, bench_arguments, run_record, write_timing  # noqa: E402

SEED = 46
REPEAT = 3
"""Timed calls of the warm command and of the exact basis alone (the fastest counts)."""
SINGULAR_REPEAT = 20
"""Bases Singular computes in one run (its time per basis: the run minus its start-up, divided by this)."""
COLUMNS = ["case", "digits", "singular_s", "command_s", "ratio", "warm_s", "warm_ratio", "engine_s", "engine_ratio",
           "primes_s", "primes_ratio", "primes_used", "exact_s", "exact_ratio", "agree", "status"]


def _number(rng: random.Random, digits: int) -> str:
    return str(rng.randint(1, 9)) + "".join(rng.choice("0123456789") for _ in range(digits - 1))


def linear_text(digits: int, seed: int = SEED) -> str:
    rng = random.Random(seed)
    a, b = _number(rng, digits), _number(rng, digits)
    return f"x\n0\n{b}*x-{a}\n"


def square_linear_text(n: int, digits: int, seed: int = SEED) -> str:
    """n dense linear polynomials in n unknowns with ``digits``-digit coefficients."""
    rng = random.Random(seed)
    names = [f"x{i}" for i in range(n)]
    rows = ["+".join(f"{_number(rng, digits)}*{v}" for v in names) + f"-{_number(rng, digits)}" for _ in range(n)]
    return ",".join(names) + "\n0\n" + ",\n".join(rows) + "\n"


def quadratic_text(digits: int, seed: int = SEED) -> str:
    rng = random.Random(seed)
    a, b, c, d, e = (_number(rng, digits) for _ in range(5))
    return f"x,y\n0\n{a}*x^2+{b}*y-{c},\n{d}*x*y-{e}\n"


def ternary_text(digits: int, seed: int = SEED) -> str:
    rng = random.Random(seed)
    n = [_number(rng, digits) for _ in range(9)]
    return (f"x,y,z\n0\n{n[0]}*x^2+{n[1]}*y*z-{n[2]},\n{n[3]}*y^2+{n[4]}*x*z-{n[5]},\n"
            f"{n[6]}*z^2+{n[7]}*x*y-{n[8]}\n")


CASES = {
    "linear-2000": lambda: linear_text(2000),
    "linear-10000": lambda: linear_text(10_000),
    "linear20-200": lambda: square_linear_text(20, 200),
    "quadratic-5000": lambda: quadratic_text(5000),
    "quadratic-50000": lambda: quadratic_text(50_000),
    "ternary-1000": lambda: ternary_text(1000),
    "katsura-4": lambda: (ROOT / "examples" / "katsura4.ms").read_text(),
}

CHILD = """
import sys, time
from analysis.engine.degree import analyse_prime
from analysis.engine.io import format_polynomial, read_system
from analysis.engine.modular import analyse_rational, input_seed, rational_basis
from analysis.engine.exact import exact_basis
import flint  # imported before the clock starts, as the command has it by then
system = read_system(sys.argv[1])
mode, REPEAT = sys.argv[2], int(sys.argv[3])
t = time.perf_counter()
if mode == "warm":  # the whole command in-process, timed on its second call (imports and kernels loaded)
    import contextlib, io
    from solvers.cli import main
    times = []
    for _ in range(REPEAT + 1):
        t = time.perf_counter()
        with contextlib.redirect_stdout(io.StringIO()):
            main(["degree", sys.argv[1], "--gb", "--json"])
        times.append(time.perf_counter() - t)
    print(min(times[1:]), 0, 1)
elif mode == "engine":  # the library calls of the default route on the parsed system, as Singular's std
    from analysis.engine.f4 import F4Options
    options = F4Options(linear_substitution=True)
    compute = lambda p: analyse_prime(system.to_ring(p)[1], options)
    seed = input_seed(system.variables, system.polynomials)
    times = []
    for _ in range(REPEAT + 1):
        t = time.perf_counter()
        rational = analyse_rational(system.polynomials, "grevlex", system.nvars, compute, None, seed)
        basis, status = rational_basis(rational, system.polynomials, "grevlex", system.nvars, compute, seed,
                                       generators=system.polynomials)
        text = [format_polynomial(f, system.variables) for f in basis]  # Singular's loop makes its text too
        times.append(time.perf_counter() - t)
    print(min(times[1:]), 0, len(basis))
elif mode == "exact":
    times = []
    for _ in range(REPEAT):
        t = time.perf_counter()
        result = exact_basis(system.polynomials, "grevlex", system.nvars)
        times.append(time.perf_counter() - t)
    print(min(times), 0, len(result.basis))
else:
    compute = lambda p: analyse_prime(system.to_ring(p)[1])
    seed = input_seed(system.variables, system.polynomials)
    rational = analyse_rational(system.polynomials, "grevlex", system.nvars, compute, None, seed)
    basis, status = rational_basis(rational, system.polynomials, "grevlex", system.nvars, compute, seed)
    print(time.perf_counter() - t, status.split("Chinese remaindering of ")[1].split()[0], 1)
"""


def _seconds(t: float) -> float:
    """Three significant digits (a basis may take a tenth of a millisecond)."""
    return float(f"{t:.3g}")


def monic_set(basis: list[dict], nvars: int) -> frozenset:
    key = order_key("grevlex", nvars)
    out = set()
    for f in basis:
        if f:
            lc = f[max(f, key=key)]
            out.add(frozenset((m, Fraction(c) / lc) for m, c in f.items()))
    return frozenset(out)


def singular_script(text: str, repeat: int) -> str:
    """Singular computes the reduced basis ``repeat`` times (each time with its text, as the command writes
    it), then prints it once."""
    system = parse_msolve(text)
    ideal = ",\n".join(format_polynomial(f, system.variables, spaced=False) for f in system.polynomials)
    return (f"option(redSB); option(redTail);\nring r = 0,({','.join(system.variables)}),dp; short = 0;\n"
            f"ideal i = {ideal};\nideal g; string s; int j; int k;\n"
            f"for (j = 1; j <= {repeat}; j++) {{ g = std(i); s = string(g); }}\n"
            'for (k = 1; k <= size(g); k++) { print("G " + string(g[k])); }\nquit;\n')


def _min_time(argv: list[str], runs: int = 3) -> float:
    return min(_timed(argv, 60)[0] or 0.0 for _ in range(runs))


def bench(name: str, tmp: Path, cap: float, singular: str | None, startup: dict) -> dict:
    text = CASES[name]()
    path = tmp / f"{name}.ms"
    path.write_text(text)
    system = read_system(path)
    row: dict = {"case": name}
    seconds, out = _timed([sys.executable, "-m", "solvers.cli", "degree", str(path), "--gb", "--json"], cap)
    mine = None
    if seconds is None:
        row["status"] = out
    else:
        row["command_s"] = _seconds(max(seconds - startup["own"], 1e-4))
        report = json.loads(out)
        row["status"] = report.get("groebner_basis_status", "")
        mine = [parse_polynomial(g, system.variables, 0) for g in report["groebner_basis"]]
        row["digits"] = max(len(_int_to_digits(max(abs(c.numerator), c.denominator))) for f in mine
                            for c in f.values())
    print(f"{name}: command {row.get('command_s', out)}", file=sys.stderr, flush=True)
    for mode in ("warm", "engine", "primes", "exact"):
        seconds, out = _timed([sys.executable, "-c", CHILD, str(path), mode, str(REPEAT)], cap)
        if seconds is None:
            row[f"{mode}_s"] = out
        else:
            t, used, _ = out.split()
            row[f"{mode}_s"] = _seconds(float(t))
            if mode == "primes":
                row["primes_used"] = int(used)
        print(f"{name}: {mode} {row[f'{mode}_s']}", file=sys.stderr, flush=True)
    if singular:
        seconds, out = _timed([singular, "-q", "--no-warn"], cap, stdin=singular_script(text, SINGULAR_REPEAT))
        if seconds is None:
            row["singular_s"] = out
        else:
            row["singular_s"] = _seconds(max(seconds - startup["singular"], 1e-4) / SINGULAR_REPEAT)
            theirs = [parse_polynomial(x[2:], system.variables, 0) for x in out.splitlines() if x.startswith("G ")]
            if mine is not None:
                row["agree"] = monic_set(mine, system.nvars) == monic_set(theirs, system.nvars)
            for mode, column in (("command", "ratio"), ("warm", "warm_ratio"), ("engine", "engine_ratio"),
                                 ("primes", "primes_ratio"), ("exact", "exact_ratio")):
                if isinstance(row.get(f"{mode}_s"), float):
                    row[column] = round(row[f"{mode}_s"] / row["singular_s"], 2)
        print(f"{name}: Singular {row['singular_s']}", file=sys.stderr, flush=True)
    return row


LEADING_DIGITS = (30, 100, 300, 1000, 2000)
"""Sizes of the large leading coefficients of the fuzz (:func:`large_leading_case`)."""


def large_leading_case(k: int) -> dict:
    """Fuzz case k: scripts/fuzz_engine.py's characteristic-0 case 8k, each polynomial's leading coefficient
    (grevlex) replaced by a random integer of 30 to 2,000 digits and either sign (seed 10^6 + k)."""
    case = fuzz_engine.generate(8 * k)
    rng = random.Random(10**6 + k)
    key = order_key(case["order"], len(case["variables"]))
    polys = []
    for f in case["polys"]:
        f = dict(f)
        if f:
            d = rng.choice(LEADING_DIGITS)
            f[max(f, key=key)] = Fraction(rng.randint(10 ** (d - 1), 10**d - 1) * rng.choice((1, -1)))
        polys.append(f)
    return {**case, "id": k, "polys": polys}


def fuzz(count: int, singular: str) -> dict:
    """``count`` large-leading-coefficient cases through ``degree --gb`` in-process (fuzz_engine's runner:
    30 s each) and through Singular (one process): outcomes, and the engine's seconds per case."""
    cases = [large_leading_case(k) for k in range(count)]
    t0 = time.perf_counter()
    refs = fuzz_engine.run_singular(cases, singular)
    singular_s = time.perf_counter() - t0
    outcomes: dict[str, int] = {}
    seconds, slowest = [], (0.0, None)
    with tempfile.TemporaryDirectory() as tmp:
        for case in cases:
            t = time.perf_counter()
            mine = fuzz_engine.run_engine(case, Path(tmp))
            seconds.append(time.perf_counter() - t)
            slowest = max(slowest, (seconds[-1], case["id"]))
            outcome, detail = fuzz_engine.compare(case, mine, refs.get(case["id"]))
            outcomes[outcome] = outcomes.get(outcome, 0) + 1
            if outcome != "agree":
                print(f"fuzz case {case['id']}: {outcome} {detail}", file=sys.stderr, flush=True)
    seconds.sort()
    return {"cases": count, "outcomes": outcomes, "engine_total_s": _seconds(sum(seconds)),
            "engine_median_s": _seconds(seconds[len(seconds) // 2]), "engine_max_s": _seconds(slowest[0]),
            "slowest_case": slowest[1], "over_1_s": sum(t > 1 for t in seconds),
            "singular_total_s": _seconds(singular_s)}


def main() -> int:
    args = bench_arguments(__doc__, list(CASES), 120.0, fuzz=True)
    if args.fuzz:
        singular = shutil.which("Singular")
        if not singular:
            print("Singular is not on PATH: the fuzz needs it (apt-get install singular)", file=sys.stderr)
            return 2
        result = fuzz(args.fuzz, singular)
        path = args.out / "bench_rational_fuzz.timing.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({**run_record(singular), **result}, indent=1) + "\n")
        print(", ".join(f"{k}={v}" for k, v in result.items()))
        return 0
    singular = shutil.which("Singular")
    if not singular:
        print("Singular is not on PATH: its columns and the ratios stay empty (apt-get install singular)",
              file=sys.stderr)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "trivial.ms").write_text("x\n0\nx-1\n")
        startup = {"own": _min_time([sys.executable, "-m", "solvers.cli", "degree", str(tmp / "trivial.ms"), "--gb",
                                     "--json"]),
                   "singular": _min_time([singular, "-q", "--no-warn", "-c", "quit;"]) if singular else 0.0}
        rows = [bench(name, tmp, args.cap, singular, startup) for name in args.cases]
    write_timing(args.out / "bench_rational.timing.json",
                 {**run_record(singular), "startup_s": {k: round(v, 3) for k, v in startup.items()}, "seed": SEED,
                  "repeat": REPEAT, "singular_repeat": SINGULAR_REPEAT}, COLUMNS, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
