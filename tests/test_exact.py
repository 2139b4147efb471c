"""The exact basis over Q (analysis.engine.exact) and its race with the primes (analysis.engine.modular):
bases checked against sympy's groebner and against answers known in closed form (B*x - A: x - A/B)."""
import random
from fractions import Fraction

import pytest
import sympy

from analysis.engine import exact as exact_module
from analysis.engine.degree import analyse_prime
from analysis.engine.exact import ExactRace, exact_basis
from analysis.engine.io import parse_msolve
from analysis.engine.modular import analyse_rational, rational_basis

SYSTEMS = [
    "x,y\n0\n3*x^2+2*y-1, 2*x*y-5/7\n",
    "x,y,z\n0\nx^2+y*z-1/3, x*y-z^2+7, z^3-x/11+y\n",
    "x,y,z\n0\nx*y-z, y^2-2*x+1/5\n",  # positive-dimensional
    "x,y\n0\nx^2+1, x^2+2\n",  # the unit ideal
]
SYMPY_ORDERS = {"grevlex": "grevlex", "lex": "lex", "deglex": "grlex"}


def sympy_basis(system, order):
    gens = sympy.symbols(system.variables)
    exprs = [sum(sympy.Rational(c.numerator, c.denominator) * sympy.prod(g**e for g, e in zip(gens, m))
                 for m, c in f.items()) for f in system.polynomials if f]
    gb = sympy.groebner(exprs, *gens, order=SYMPY_ORDERS[order], domain="QQ")
    return {frozenset((m, Fraction(int(c.p), int(c.q))) for m, c in sympy.Poly(g, *gens).terms()) for g in gb.exprs}


def as_set(basis):
    return {frozenset(f.items()) for f in basis}


def numbers(seed, digits, count):
    rng = random.Random(seed)
    return [rng.randint(10 ** (digits - 1), 10**digits - 1) for _ in range(count)]


@pytest.mark.parametrize("order", sorted(SYMPY_ORDERS))
@pytest.mark.parametrize("text", SYSTEMS)
def test_exact_basis_is_sympys(text, order):
    system = parse_msolve(text)
    result = exact_basis(system.polynomials, order, system.nvars, certify=True)
    assert result.groebner
    assert as_set(result.basis) == sympy_basis(system, order)
    assert all(next(iter(f.values())) == 1 for f in result.basis)  # monic, leading term first


def test_exact_basis_refuses_block_orders():
    with pytest.raises(ValueError, match="exact orders: grevlex, lex, deglex"):
        exact_basis([{(1, 0): Fraction(1)}], "block:1,1", 2)


def test_the_race_returns_the_childs_basis():
    a, b = numbers(1, 300, 2)
    system = parse_msolve(f"x\n0\n{b}*x-{a}\n")
    with ExactRace(system.polynomials, "grevlex", 1) as race:
        while (found := race.poll()) is None:
            assert not race.failed
    assert found.method.startswith("row echelon form") and found.basis == ({(1,): Fraction(1), (0,): Fraction(-a, b)},)


def rational(text):
    system = parse_msolve(text)

    def compute(p):
        return analyse_prime(system.to_ring(p)[1])

    return analyse_rational(system.polynomials, "grevlex", system.nvars, compute), compute, system


def test_300_digit_coefficients_over_q_by_primes_and_by_the_race():
    """Fractions of 600 digits need about 130 primes; the race's exact basis is the same, and both are sympy's."""
    a, b, c, d, e = numbers(2, 300, 5)
    text = f"x,y\n0\n{a}*x^2+{b}*y-{c}, {d}*x*y-{e}\n"
    report, compute, system = rational(text)
    expected = sympy_basis(system, "grevlex")
    primes_only, status = rational_basis(report, system.polynomials, "grevlex", system.nvars, compute)
    assert as_set(primes_only) == expected and "Chinese remaindering of" in status
    raced, status = rational_basis(report, system.polynomials, "grevlex", system.nvars, compute,
                                   generators=system.polynomials)
    assert as_set(raced) == expected and "checked modulo the" in status


def test_a_failing_child_leaves_the_answer_to_the_primes(monkeypatch):
    def fail(*args):
        raise MemoryError("as a capped child would")

    monkeypatch.setattr(exact_module, "exact_basis", fail)
    a, b = numbers(3, 120, 2)
    report, compute, system = rational(f"x\n0\n{b}*x-{a}\n")
    basis, status = rational_basis(report, system.polynomials, "grevlex", system.nvars, compute,
                                   generators=system.polynomials)
    assert basis == [{(1,): Fraction(1), (0,): Fraction(-a, b)}] and "Chinese remaindering" in status


@pytest.mark.slow
def test_10000_digit_bases_over_q_through_the_command_line(tmp_path, capsys):
    """Issue 46: B*x - A with 10,000-digit A and B (known answer x - A/B), and a quadratic system whose basis
    has 10,000-digit fractions (sympy's basis), answered and checked."""
    import json

    from analysis.engine.io import parse_polynomial
    from solvers.cli import main

    from analysis.engine.polytext import _int_to_digits as digits  # past Python's 4300-digit str limit

    a, b = numbers(4, 10_000, 2)
    q = [digits(n) for n in numbers(5, 5000, 5)]
    for text, expected in ((f"x\n0\n{digits(b)}*x-{digits(a)}\n",
                            {frozenset({((1,), Fraction(1)), ((0,), Fraction(-a, b))})}),
                           (f"x,y\n0\n{q[0]}*x^2+{q[1]}*y-{q[2]}, {q[3]}*x*y-{q[4]}\n", None)):
        path = tmp_path / "big.ms"
        path.write_text(text)
        system = parse_msolve(text)
        assert main(["degree", str(path), "--gb", "--json"]) == 0
        report = json.loads(capsys.readouterr().out)
        basis = as_set(parse_polynomial(g, system.variables, 0) for g in report["groebner_basis"])
        assert basis == (expected or sympy_basis(system, "grevlex"))
        assert "checked modulo the" in report["groebner_basis_status"]
        assert "largest numerator or denominator 10000 digits" in report["groebner_basis_status"]


def test_an_unlucky_majority_is_caught_when_the_exact_basis_comes_first():
    """Fuzz case 713's lines, dependent modulo each of the first three primes of seed 0 (which all see an
    inconsistent system): the exact basis (degree 2) or the fresh primes refuse the majority."""
    import itertools

    from analysis.engine.degree import PrimeDisagreement
    from analysis.engine.modular import random_primes

    p1, p2, p3 = itertools.islice(random_primes(0), 3)
    report, compute, system = rational(f"x,y,z\n0\nx+5*y, 2*x+{10 + p1 * p2 * p3}*y+1, z^2-2\n")
    assert report.report.dimension == -1  # fooled, as the residual risk allows
    with pytest.raises(PrimeDisagreement, match="the majority's primes were unlucky"):
        rational_basis(report, system.polynomials, "grevlex", system.nvars, compute, generators=system.polynomials)


@pytest.mark.parametrize("order", sorted(SYMPY_ORDERS))
@pytest.mark.parametrize("text", [
    "x,y,z,w\n0\n3*x+2*y-z+1/2, x-y+7*w-2, 2*x+3*y-z-7*w+5/2\n",  # the third: the first minus the second
    "x,y,z\n0\n3*y+2*z-1, y-z/7, 2*z+4\n",  # no x: pivots from the second column
    "x,y\n0\nx+y-1, x+y-2\n",  # inconsistent: the unit ideal
])
def test_linear_systems_by_row_echelon_form_are_sympys(text, order):
    system = parse_msolve(text)
    result = exact_basis(system.polynomials, order, system.nvars)
    assert result.groebner and as_set(result.basis) == sympy_basis(system, order)
    assert all(next(iter(f.values())) == 1 for f in result.basis)
