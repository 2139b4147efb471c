"""Numbers as numbers: a coefficient of thousands of digits, or 1e300 written in a file or given by --param,
is read exactly and goes through solve, count and generate (scaled by powers of two where the numerics start,
and said so), or is refused with a message naming it. The solutions are compared with sympy's."""
from fractions import Fraction

import numpy as np
import pytest
import sympy

from analysis.engine.io import parse_msolve
from analysis.engine.polytext import read_number
from analysis.formulations.parametric import parse
from solvers.cli import main
from solvers.system_solve import SolveError, instance_system, parameter_values, solve_system

BIG = 10**1999 + 7  # 2000 digits
x, y = sympy.symbols("x y")


def run(capsys, *argv):
    try:
        code = main(list(argv))
    except SystemExit as e:
        code = e.code
    out, err = capsys.readouterr()
    return code, out, err


def _close(found, expected, rel=1e-12):
    """Two lists of complex tuples equal as sets up to rel."""
    assert len(found) == len(expected)
    left = list(expected)
    for z in found:
        k = min(range(len(left)), key=lambda i: max(abs(a - b) / max(abs(b), 1e-300) for a, b in zip(z, left[i])))
        assert max(abs(a - b) / max(abs(b), 1e-300) for a, b in zip(z, left[k])) < rel, (z, left[k])
        left.pop(k)


def test_scientific_notation_is_read_exactly_everywhere():
    system = parse_msolve("x\n0\n1e300*x^2 - 1.5e-3\n")
    assert system.polynomials[0] == {(2,): Fraction(10**300), (0,): Fraction(-3, 2000)}
    assert parse_msolve("x\n0\n1e300*x^2-1\n") == parse_msolve(f"x\n0\n{10**300}*x^2-1\n")  # fast path, same value
    assert read_number("1e300", "here") == 10**300 and read_number("-.5E-2", "here") == Fraction(-1, 200)
    assert parameter_values(["a=1e300", "b=1.5e-3", "c=2e3/3"]) == {"a": 10**300, "b": Fraction(3, 2000),
                                                                   "c": Fraction(2000, 3)}
    with pytest.raises(SolveError, match="'1e9999999': a power of ten beyond"):
        parameter_values(["a=1e9999999"])


def test_a_2000_digit_cubic_against_sympy():
    """BIG (x-1)(x-2)(x-3) + x^2 - 5: roots within 1e-1999 of 1, 2, 3, by sympy's nroots at 50 digits."""
    p = sympy.expand(BIG * (x - 1) * (x - 2) * (x - 3) + x**2 - 5)
    system = parse_msolve(f"x\n0\n{sympy.sstr(p).replace('**', '^')}\n")
    result = solve_system(system)
    assert result.degree == 3 and result.complete, result.status
    assert "equations scaled for float64" in result.status and "1 by 2^-66" in result.status
    expected = [(complex(r),) for r in sympy.Poly(p, x).nroots(n=50, maxsteps=200)]
    _close([s.values for s in result.solutions], expected)


def test_a_system_with_huge_and_tiny_roots_against_sympy():
    """x^2 = 1e400, x y = 3e200: x = +-1e200 (its action matrix has 1e400: the unknowns are scaled by 2^s),
    y = +-3; and 1e300 x^2 = 1, roots +-1e-150, distinct at their own scale."""
    system = parse_msolve("x,y\n0\nx^2 - 1e400, x*y - 3e200\n")
    result = solve_system(system)
    assert result.complete and "unknowns scaled for float64" in result.status, result.status
    exact = sympy.solve_poly_system([x**2 - 10**400, x * y - 3 * 10**200], x, y)
    _close([s.values for s in result.solutions], [tuple(complex(v) for v in r) for r in exact])
    result = solve_system(parse_msolve("x\n0\n1e300*x^2 - 1\n"))
    assert result.complete, result.status
    _close([s.values for s in result.solutions], [(complex(r),) for r in sympy.Poly(10**300 * x**2 - 1).all_roots()])


def test_a_5000_digit_coefficient_next_to_a_small_one():
    """B x^2 + x - 4 B, B of 5000 digits: the monic basis holds 1/B (about 2^-16600) beside 4; the unknowns keep
    their scale (geometric mean of the roots, 2) instead of being balanced towards the negligible entry."""
    import flint

    B = int(flint.fmpz(10) ** 4999 + 7)
    system = parse_msolve(f"x\n0\n{flint.fmpz(B)}*x^2 + x - {flint.fmpz(4 * B)}\n")
    result = solve_system(system)
    assert result.complete and "s = 1 for unknown 1" in result.status, result.status
    expected = [(complex(r),) for r in sympy.Poly(B * x**2 + x - 4 * B, x).nroots(n=30, maxsteps=200)]
    _close([s.values for s in result.solutions], expected)


def test_coordinates_beyond_float64_are_a_named_refusal():
    with pytest.raises(SolveError, match=r"coordinates of about 2\^-1659 \(1e-500\): outside float64's range"):
        solve_system(parse_msolve("x,y\n0\nx^2 - 1e400, x*y - 3e-300\n"))


def test_solve_param_1e300_and_a_2000_digit_param(capsys, tmp_path):
    path = tmp_path / "p.txt"
    path.write_text(f"unknowns: x, y\nparameters: a\nequations:\nx^2 - a*y\n{BIG}*y - {4 * BIG}\n")
    code, out, err = run(capsys, "solve", str(path), "--param", "a=1e300")
    assert code == 0 and "all 2 solutions" in out and "2 by 2^-6642" in out, out + err
    values = sorted(float(line.split()[3]) for line in out.splitlines()[5:])
    assert values == pytest.approx([-2e150, 2e150], rel=1e-14)
    path.write_text("unknowns: x, y\nparameters: a\nequations:\na*x^2 - a*y - 5\ny - 4\n")
    code, out, err = run(capsys, "solve", str(path), "--param", f"a={BIG}")
    expected = sorted(float(r) for r in sympy.Poly(BIG * x**2 - 4 * BIG - 5, x).nroots(n=30))
    values = sorted(float(line.split()[3]) for line in out.splitlines()[5:])
    assert code == 0 and values == pytest.approx(expected, rel=1e-14) and "1 by 2^-6640" in out and "1 coefficient(s) below float64's range" in out, out + err


def test_count_and_generate_scale_a_2000_digit_equation(capsys, tmp_path):
    path = tmp_path / "c.txt"
    path.write_text(f"unknowns: x, y\nparameters: a, b\nequations:\n{BIG}*x^2 + {BIG}*y^2 - {BIG}*a\nx*y - b\n")
    code, out, err = run(capsys, "count", str(path))
    assert code == 0 and ": 4 solutions" in out and "equations scaled for float64" in out, out + err
    code, out, err = run(capsys, "generate", str(path), "--out", str(tmp_path / "gen"))
    assert code == 0 and "4 roots certified" in out and "scaling equations scaled" in out, out + err
    import importlib.util

    module = next((tmp_path / "gen").glob("*.py"))
    spec = importlib.util.spec_from_file_location("gen_huge", module)
    solver = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(solver)
    roots = [tuple(r) for r in np.asarray(solver.solve(np.array([5.0, 2.0])))]
    exact = sympy.solve_poly_system([x**2 + y**2 - 5, x * y - 2], x, y)  # BIG divides out exactly
    _close(roots, [tuple(complex(v) for v in r) for r in exact], rel=1e-9)


def test_an_equation_spanning_beyond_float64_is_refused(capsys, tmp_path):
    path = tmp_path / "s.txt"
    path.write_text(f"unknowns: x, y\nparameters: a, b\nequations:\n{BIG}*x^2 + y^2 - a\nx*y - b\n")
    code, out, err = run(capsys, "count", str(path))
    assert code == 2 and "constants span 2^0 to 2^6640, more than float64's range" in err, err


@pytest.mark.parametrize("start", ['{"parameters": [1e400, 2], "root": [1, 2]}',
                                   '{"parameters": [1, 2], "root": [' + "1" + "0" * 400 + ', 2]}'])
def test_a_start_pair_beyond_float64_is_refused_by_name(capsys, tmp_path, start):
    path = tmp_path / "c.txt"
    path.write_text("unknowns: x, y\nparameters: a, b\nequations:\nx^2 + y^2 - a\nx*y - b\n")
    (tmp_path / "s.json").write_text(start)
    code, out, err = run(capsys, "count", str(path), "--start", str(tmp_path / "s.json"))
    assert code == 2 and "s.json: '" in err and "is not a finite float64" in err, err


def test_the_homotopy_refuses_a_parameter_beyond_its_floats_and_the_action_matrix_says_what_it_lost(capsys, tmp_path):
    """x^2 + y^2 = a, x y = 2: with a = 1e400 the homotopy (tracking in float64) refuses by name; with a = 1e300 the
    action matrix finds the two solutions near (1e150, 2e-150) and says it lost the other two (x spans 1e300
    over the solutions, more than float64's precision): not complete, exit 3, never an 'all' status."""
    path = tmp_path / "c.txt"
    path.write_text("unknowns: x, y\nparameters: a, b\nequations:\nx^2 + y^2 - a\nx*y - b\n")
    with pytest.raises(SolveError, match=r"a = 2\^1328 \(about\): beyond 2\^500.*--method action-matrix"):
        from solvers.system_solve import solve_by_homotopy

        solve_by_homotopy(parse(path.read_text()), {"a": Fraction(10**400), "b": Fraction(2)})
    code, out, err = run(capsys, "solve", str(path), "--param", "a=1e300", "--param", "b=2")
    assert code == 3 and "NOT checked complete: 2 eigenvector(s) lost in float64" in out, out + err
    A = sympy.Integer(10) ** 300  # x^4 - A x^2 + 4 = 0 (y = 2 / x): the large root of x^2 has no cancellation
    xb = sympy.sqrt((A + sympy.sqrt(A**2 - 16)) / 2)
    assert sympy.simplify(xb**4 - A * xb**2 + 4) == 0
    big = [(s * complex(xb.evalf(40)), s * complex((2 / xb).evalf(40))) for s in (-1, 1)]
    found = [tuple(complex(v) for v in line.split()[3:5]) for line in out.splitlines()[5:]]
    _close(found, big, rel=1e-12)
