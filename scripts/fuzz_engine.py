"""Fuzz the Gröbner engine against a reference CAS: seeded random systems, compared by degree, dimension
and the reduced Gröbner basis (over Q for characteristic 0, over GF(p) otherwise).

Case k (k = 0, 1, 2, ...) is generated from the seed k alone, in the category ``CATEGORIES[k % 8]``, so any
slice of cases is reproducible on its own and slices can run in parallel or in CI jobs::

    python scripts/fuzz_engine.py --cases 0:10000 --reference singular     # the full run
    python scripts/fuzz_engine.py --cases 0:200 --reference sympy          # a quick slice, no CAS needed
    python scripts/fuzz_engine.py --cases 0:10000 --summary                # rewrite tables/fuzz_engine.*

Each case runs through the command line's own code path (``tdoa-workbench degree FILE --json --gb``,
in-process) with the default primes (random 31-bit, seed 0, for characteristic 0). The reference is
Singular 4 (``std`` with ``option(redSB)``; saturation by elimination of a Rabinowitsch variable), or
sympy's ``groebner`` (grevlex, lex and deglex, no saturation: other cases are counted as skipped).

Outcomes per case: ``agree`` (same dimension, degree and reduced basis, made monic), ``disagree`` (a
wrong answer), ``crash`` (a traceback: a bug), ``refused`` (the engine stopped with a one-line error,
e.g. a matrix cap or the exponent limit; not a wrong answer, but counted), ``skipped``
(the reference cannot do the case). Results of a run are appended to ``fuzz_engine.cases.jsonl`` in the
cache directory (one line per case); ``--summary`` counts the latest result of every case there into
``tables/fuzz_engine.csv`` and ``.md`` (no timings; byte-identical for the same results).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import random
import shutil
import signal
import subprocess
import sys
import tempfile
from fractions import Fraction
from math import comb
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from analysis.engine.io import format_polynomial, parse_polynomial  # noqa: E402
from analysis.engine.modular import order_key, random_primes  # noqa: E402
from analysis.sweeps.paths import cache_dir  # noqa: E402

CATEGORIES = ("char0", "char0_unlucky", "orders", "block", "saturation", "small_primes", "large_primes",
              "near_univariate")
"""Case k is of category CATEGORIES[k % len(CATEGORIES)]."""

CASE_SECONDS = 30
"""The engine's time per case before the case counts as refused (a timeout)."""

SMALL_PRIMES = (2, 3, 5, 7, 11, 13, 101, 251, 32003, 65521)


# -- generation -------------------------------------------------------------------------------------

def _monomials(rng: random.Random, n: int, degree: int, count: int) -> list[tuple[int, ...]]:
    out: set[tuple[int, ...]] = set()
    count = min(count, comb(n + degree, n))  # no more than there are monomials of degree <= degree
    while len(out) < count:
        d = rng.randint(0, degree)
        e = [0] * n
        for _ in range(d):
            e[rng.randrange(n)] += 1
        out.add(tuple(e))
    return sorted(out)


def _coefficient(rng: random.Random, characteristic: int) -> Fraction:
    if characteristic:
        return Fraction(rng.randrange(1, characteristic))
    c = Fraction(rng.choice([-1, 1]) * rng.randint(1, 9))
    if rng.random() < 0.25:
        c /= rng.randint(2, 12)
    return c


def _random_poly(rng, n, degree, terms, characteristic):
    mons = _monomials(rng, n, degree, terms)
    top = [0] * n  # one term of full degree keeps the system's degrees what the category asks
    for _ in range(degree):
        top[rng.randrange(n)] += 1
    mons = sorted(set(mons) | {tuple(top)})
    return {m: _coefficient(rng, characteristic) for m in mons}


def generate(k: int) -> dict:
    """Case k: {'id', 'category', 'variables', 'characteristic', 'order', 'polys' (Coefficients),
    'saturate' (Coefficients or None)}; deterministic in k."""
    rng = random.Random(k)
    category = CATEGORIES[k % len(CATEGORIES)]
    n = rng.randint(2, 3)
    characteristic, order, saturate = 0, "grevlex", None
    count = n + rng.choice([-1, 0, 0, 0, 1])  # mostly square: zero-dimensional; some positive-dimensional
    degrees = [rng.randint(1, 3) for _ in range(count)]
    if category == "small_primes":
        characteristic = rng.choice(SMALL_PRIMES)
    elif category == "large_primes":
        characteristic = rng.choice((2**31 - 1, 1073741827, 2147483629, 1000000007))
    if category in ("orders", "block"):
        characteristic = rng.choice((0, 32003))
        order = rng.choice(("lex", "deglex")) if category == "orders" else \
            f"block:{rng.randint(1, n - 1)},{n}" if n > 2 else "block:1,1"
        if order.startswith("block"):
            first = int(order.split(":")[1].split(",")[0])
            order = f"block:{first},{n - first}"
        degrees = [rng.randint(1, 3 if n == 2 else 2) for _ in range(count)]
    polys = [_random_poly(rng, n, d, rng.randint(2, 5), characteristic) for d in degrees]
    if category == "near_univariate":  # x^e + (sparse rest), x - y - c: univariate in disguise
        e = rng.randint(8, 60)
        first = {tuple([e] + [0] * (n - 1)): Fraction(1), tuple([0] + [1] + [0] * (n - 2)): _coefficient(rng, 0)}
        polys = [first] + [{tuple(int(i == j) for j in range(n)): Fraction(1), tuple(int(i + 1 == j) for j in range(n)):
                            Fraction(-1), (0,) * n: _coefficient(rng, 0)} for i in range(n - 1)]
    if category == "char0_unlucky":
        polys = _unlucky(rng, n, polys)
    if category == "saturation":
        saturate = _random_poly(rng, n, 1, 2, characteristic)
        # plant the saturating polynomial's zero set into the system: f * g for some generators
        polys = [_mul(saturate, f) if rng.random() < 0.5 else f for f in polys]
    variables = [f"x{i + 1}" for i in range(n)]
    return {"id": k, "category": category, "variables": variables, "characteristic": characteristic,
            "order": order, "polys": polys, "saturate": saturate}


def _mul(f, g):
    out: dict = {}
    for a, c in f.items():
        for b, d in g.items():
            m = tuple(x + y for x, y in zip(a, b))
            out[m] = out.get(m, 0) + c * d
    return {m: c for m, c in out.items() if c}


def _unlucky(rng: random.Random, n: int, polys: list) -> list:
    """Coefficients built to make primes unlucky: products of the default random primes (seed 0) and of
    the former default primes 65521 and 32749, in leading coefficients, denominators and determinants."""
    first = [p for p, _ in zip(random_primes(0), range(4))]
    bad = rng.choice([first[0], first[0] * first[1], first[0] * first[1] * first[2], 65521 * 32749, 65521])
    kind = rng.choice(("leading", "denominator", "determinant", "constant"))
    polys = [dict(f) for f in polys]
    if kind == "leading":
        f = polys[0]
        top = max(f, key=order_key("grevlex", n))
        f[top] = Fraction(bad * rng.randint(1, 3))
    elif kind == "denominator":
        f = polys[rng.randrange(len(polys))]
        m = rng.choice(sorted(f))
        f[m] = Fraction(rng.randint(1, 5), bad)
    elif kind == "determinant":  # two linear forms, dependent exactly modulo the bad primes
        a, b = rng.randint(1, 5), rng.randint(1, 5)
        x = tuple(int(j == 0) for j in range(n))
        y = tuple(int(j == 1) for j in range(n))
        one = (0,) * n
        polys[0] = {x: Fraction(1), y: Fraction(a), one: Fraction(rng.randint(-3, 3))}
        polys[1 % len(polys)] = {x: Fraction(b), y: Fraction(a * b + bad), one: Fraction(rng.randint(-3, 3))}
    else:  # a constant that vanishes mod the bad primes: the unit ideal over Q
        polys.append({(0,) * n: Fraction(bad)})
    return [f for f in polys if f]


# -- the engine -------------------------------------------------------------------------------------

def system_text(case: dict) -> str:
    body = ",\n".join(format_polynomial(f, case["variables"], spaced=False) for f in case["polys"])
    return f"{','.join(case['variables'])}\n{case['characteristic']}\n{body}\n"


class _Timeout(Exception):
    pass


def _alarm(signum, frame):
    raise _Timeout()


def run_engine(case: dict, workdir: Path) -> dict:
    """{'status': 'ok', 'dimension', 'degree', 'basis' (list of Coefficients)} or {'status': 'refused',
    'error'}: the command line's ``degree --json --gb`` in-process."""
    from solvers.cli import main

    path = workdir / f"case{case['id']}.ms"
    path.write_text(system_text(case))
    argv = ["degree", str(path), "--json", "--gb", "--order", case["order"]]
    if case["saturate"] is not None:
        argv.append("--saturate=" + format_polynomial(case["saturate"], case["variables"], spaced=False))
    out, err = io.StringIO(), io.StringIO()
    signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(CASE_SECONDS)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(argv)
    except _Timeout:
        return {"status": "refused", "error": f"timeout after {CASE_SECONDS} s"}
    except Exception as e:  # a traceback is a bug of the engine: counted, and the run goes on
        return {"status": "crash", "error": f"{type(e).__name__}: {e}"}
    finally:
        signal.alarm(0)
    if code != 0:
        return {"status": "refused", "error": err.getvalue().strip().splitlines()[-1] if err.getvalue() else f"exit {code}"}
    report = json.loads(out.getvalue())
    basis = [parse_polynomial(g, case["variables"], 0) for g in report["groebner_basis"]]
    return {"status": "ok", "dimension": report["dimension"], "degree": report["degree"], "basis": basis}


# -- references -------------------------------------------------------------------------------------

def _singular_order(order: str, n: int) -> str:
    if order == "grevlex":
        return "dp"
    if order == "lex":
        return "lp"
    if order == "deglex":
        return "Dp"
    sizes = [int(s) for s in order.split(":")[1].split(",")]
    return "(" + ",".join(f"dp({s})" for s in sizes) + ")"


def singular_script(cases: list[dict]) -> str:
    lines = ["option(redSB);", "option(redTail);", "int k;"]
    for case in cases:
        v = case["variables"]
        n = len(v)
        ideal = ",".join(format_polynomial(f, v, spaced=False) for f in case["polys"])
        lines.append(f"ring r{case['id']} = {case['characteristic']},({','.join(v)}),{_singular_order(case['order'], n)};")
        if case["saturate"] is None:
            lines.append(f"ideal g = std(ideal({ideal}));")
        else:
            f = format_polynomial(case["saturate"], v, spaced=False)
            inner = _singular_order(case["order"], n)
            inner = inner if inner.startswith("(") else f"({inner}({n}))"
            lines.append(f"ring s{case['id']} = {case['characteristic']},(T_,{','.join(v)}),(dp(1),{inner[1:-1]});")
            lines.append(f"ideal e = eliminate(ideal({ideal}) + ideal(1 - T_*({f})), T_);")
            lines.append(f"setring r{case['id']}; ideal g = std(imap(s{case['id']}, e));")
        lines.append(f'print("CASE {case["id"]}"); print(dim(g)); print(vdim(g));')
        lines.append('for (k = 1; k <= size(g); k++) { print("G " + string(g[k])); }')
        lines.append('print("END");')
    lines.append("quit;")
    return "\n".join(lines) + "\n"


def run_singular(cases: list[dict], exe: str) -> dict[int, dict]:
    """Singular's dimension, degree and reduced basis of each case (one Singular process per batch)."""
    out = subprocess.run([exe, "-q", "--no-warn"], input=singular_script(cases), capture_output=True, text=True,
                         timeout=600).stdout
    results: dict[int, dict] = {}
    by_id = {c["id"]: c for c in cases}
    current = None
    for line in out.splitlines():
        if line.startswith("CASE "):
            current = {"lines": []}
            results[int(line.split()[1])] = current
        elif current is not None and line != "END":
            current["lines"].append(line)
    parsed = {}
    for k, r in results.items():
        case = by_id[k]
        rows = r["lines"]
        dim, vdim = int(rows[0]), int(rows[1])
        basis = [parse_polynomial(x[2:].replace("T_", "0"), case["variables"], 0) for x in rows[2:] if x.startswith("G ")]
        basis = [b for b in basis if b]
        if dim == -1:
            basis = [{(0,) * len(case["variables"]): Fraction(1)}]
        parsed[k] = {"dimension": dim, "degree": vdim if dim == 0 else (0 if dim == -1 else None), "basis": basis}
    return parsed


def run_sympy(case: dict) -> dict | None:
    """sympy's answer, or None when sympy cannot do the case (block orders, saturation)."""
    import sympy

    orders = {"grevlex": "grevlex", "lex": "lex", "deglex": "grlex"}
    if case["order"] not in orders or case["saturate"] is not None:
        return None
    gens = sympy.symbols(case["variables"])
    exprs = [sum(sympy.Rational(c.numerator, c.denominator) * sympy.prod(g**e for g, e in zip(gens, m))
                 for m, c in f.items()) for f in case["polys"]]
    kw = {"modulus": case["characteristic"]} if case["characteristic"] else {"domain": "QQ"}
    gb = sympy.groebner(exprs, *gens, order=orders[case["order"]], **kw)
    basis = [{m: Fraction(int(c.p), int(c.q)) if hasattr(c, "p") else Fraction(int(c))
              for m, c in sympy.Poly(g, *gens).terms()} for g in gb.exprs]
    # dimension and degree from the leading monomials, by the engine's own counting would not be independent:
    # sympy's is_zero_dimensional and the standard monomials of its basis are used instead
    if basis == [{(0,) * len(gens): Fraction(1)}]:
        return {"dimension": -1, "degree": 0, "basis": basis}
    if not gb.is_zero_dimensional:
        return {"dimension": None, "degree": None, "basis": basis}
    return {"dimension": 0, "degree": _count_standard(gb, gens, orders[case["order"]]), "basis": basis}


def _count_standard(gb, gens, order: str) -> int:
    """Number of monomials not divisible by a leading monomial of sympy's basis (zero-dimensional)."""
    import sympy

    leads = [sympy.Poly(g, *gens).monoms(order=order)[0] for g in gb.exprs]
    n = len(gens)
    bound = [min(m[i] for m in leads if all(m[j] == 0 for j in range(n) if j != i)) for i in range(n)]
    count = 0
    stack = [(0,) * n]
    seen = set(stack)
    while stack:
        e = stack.pop()
        if any(all(a >= b for a, b in zip(e, m)) for m in leads):
            continue
        count += 1
        for i in range(n):
            f = e[:i] + (e[i] + 1,) + e[i + 1:]
            if f[i] < bound[i] and f not in seen:
                seen.add(f)
                stack.append(f)
    return count


# -- comparison -------------------------------------------------------------------------------------

def monic_set(basis: list[dict], case: dict) -> frozenset:
    """The basis as a set of monic polynomials (coefficients mod p in characteristic p)."""
    key = order_key(case["order"], len(case["variables"]))
    p = case["characteristic"]
    out = set()
    for f in basis:
        if p:
            f = {m: Fraction(c.numerator * pow(c.denominator, -1, p) % p) for m, c in f.items()}
            f = {m: c for m, c in f.items() if c}
        if not f:
            continue
        lc = f[max(f, key=key)]
        if p:
            inv = pow(int(lc), -1, p)
            out.add(frozenset((m, Fraction(int(c) * inv % p)) for m, c in f.items()))
        else:
            out.add(frozenset((m, c / lc) for m, c in f.items()))
    return frozenset(out)


def compare(case: dict, mine: dict, ref: dict | None) -> tuple[str, str]:
    """(outcome, detail) of one case."""
    if mine["status"] != "ok":
        return mine["status"], mine["error"]
    if ref is None:
        return "skipped", "the reference cannot do this case"
    if ref["dimension"] is not None and mine["dimension"] != ref["dimension"]:
        return "disagree", f"dimension {mine['dimension']} vs {ref['dimension']}"
    if ref["dimension"] is None and mine["dimension"] in (-1, 0):
        return "disagree", f"dimension {mine['dimension']} vs positive"
    if ref["degree"] is not None and mine["degree"] != ref["degree"]:
        return "disagree", f"degree {mine['degree']} vs {ref['degree']}"
    if monic_set(mine["basis"], case) != monic_set(ref["basis"], case):
        return "disagree", "reduced bases differ"
    return "agree", ""


# -- driver -----------------------------------------------------------------------------------------

def results_path() -> Path:
    path = cache_dir("fuzz") / "fuzz_engine.cases.jsonl"
    path.parent.mkdir(parents=True, exist_ok=True)
    return path


def run(cases: range, reference: str, batch: int = 50, categories: tuple[str, ...] = CATEGORIES) -> dict[str, int]:
    exe = shutil.which("Singular") if reference == "singular" else None
    if reference == "singular" and exe is None:
        raise SystemExit("Singular not found (Debian: apt-get install singular); use --reference sympy")
    counts: dict[str, int] = {}
    path = results_path()
    with tempfile.TemporaryDirectory() as tmp, path.open("a") as log:
        for start in range(cases.start, cases.stop, batch):
            block = [generate(k) for k in range(start, min(start + batch, cases.stop))
                     if CATEGORIES[k % len(CATEGORIES)] in categories]
            if not block:
                continue
            refs = run_singular(block, exe) if exe else {c["id"]: run_sympy(c) for c in block}
            for case in block:
                mine = run_engine(case, Path(tmp))
                ref = refs.get(case["id"]) if exe else refs[case["id"]]
                if exe and ref is None:
                    ref = {"dimension": None, "degree": None, "basis": None}
                    outcome, detail = (mine["status"], mine["error"]) if mine["status"] != "ok" else \
                        ("skipped", "Singular gave no answer")
                else:
                    outcome, detail = compare(case, mine, ref)
                counts[outcome] = counts.get(outcome, 0) + 1
                log.write(json.dumps({"id": case["id"], "category": case["category"], "reference": reference,
                                      "outcome": outcome, "detail": detail}) + "\n")
                if outcome in ("disagree", "crash"):
                    print(f"case {case['id']} ({case['category']}, seed {case['id']}): {detail}\n{system_text(case)}",
                          file=sys.stderr)
            log.flush()
            print(f"cases {block[0]['id']}..{block[-1]['id']}: {counts}", file=sys.stderr)
    return counts


def summary(out_dir: Path) -> None:
    """Count the latest outcome of every case in the results log into tables/fuzz_engine.csv and .md."""
    latest: dict[int, dict] = {}
    for line in results_path().read_text().splitlines():
        row = json.loads(line)
        latest[row["id"]] = row
    outcomes = ("agree", "disagree", "crash", "refused", "skipped")
    table: dict[tuple[str, str], dict[str, int]] = {}
    for row in latest.values():
        cell = table.setdefault((row["category"], row["reference"]), dict.fromkeys(outcomes, 0))
        cell[row["outcome"]] += 1
    refused: dict[str, int] = {}
    for row in latest.values():
        if row["outcome"] == "refused":
            reason = row["detail"].split(":")[-1].strip()[:80]
            refused[reason] = refused.get(reason, 0) + 1
    rows = sorted(table.items(), key=lambda kv: (CATEGORIES.index(kv[0][0]), kv[0][1]))
    csv = ["category,reference,cases," + ",".join(outcomes)]
    md = ["# Engine fuzz (scripts/fuzz_engine.py)", "",
          f"{len(latest)} seeded systems (case ids {min(latest)}..{max(latest)}), each compared by dimension, "
          "degree and reduced Groebner basis (made monic; over Q in characteristic 0).", "",
          "| category | reference | cases | " + " | ".join(outcomes) + " |",
          "|---|---|---:|" + "---:|" * len(outcomes)]
    for (category, reference), cell in rows:
        total = sum(cell.values())
        csv.append(f"{category},{reference},{total}," + ",".join(str(cell[o]) for o in outcomes))
        md.append(f"| {category} | {reference} | {total} | " + " | ".join(str(cell[o]) for o in outcomes) + " |")
    totals = {o: sum(c[o] for c in table.values()) for o in outcomes}
    md.append(f"| all | | {len(latest)} | " + " | ".join(str(totals[o]) for o in outcomes) + " |")
    if refused:
        md += ["", "Refusals (one-line errors of the engine, not wrong answers):", ""]
        md += [f"* {n} x {reason}" for reason, n in sorted(refused.items(), key=lambda kv: (-kv[1], kv[0]))]
    (out_dir / "fuzz_engine.csv").write_text("\n".join(csv) + "\n")
    (out_dir / "fuzz_engine.md").write_text("\n".join(md) + "\n")


def _range(text: str) -> range:
    start, _, stop = text.partition(":")
    return range(int(start), int(stop))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", type=_range, default=range(0, 200), metavar="START:STOP",
                        help="case ids to run (default 0:200)")
    parser.add_argument("--reference", choices=("singular", "sympy"), default="singular")
    parser.add_argument("--categories", default=",".join(CATEGORIES),
                        help=f"comma-separated categories to run (default all: {','.join(CATEGORIES)})")
    parser.add_argument("--summary", action="store_true",
                        help="only write tables/fuzz_engine.csv and .md from the results log")
    parser.add_argument("--out", type=Path, default=ROOT / "tables")
    args = parser.parse_args(argv)
    if args.summary:
        summary(args.out)
        return 0
    categories = tuple(c.strip() for c in args.categories.split(",") if c.strip())
    unknown = sorted(set(categories) - set(CATEGORIES))
    if unknown:
        parser.error(f"unknown categories {', '.join(unknown)}; valid: {', '.join(CATEGORIES)}")
    counts = run(args.cases, args.reference, categories=categories)
    print(json.dumps(counts))
    return 1 if counts.get("disagree") or counts.get("crash") else 0


if __name__ == "__main__":
    sys.exit(main())
