"""analysis.engine.io: msolve-format parsing (checked against sympy.expand), errors, GF(p) maps and writers."""
from __future__ import annotations

import random
import shutil
import subprocess
from fractions import Fraction

import pytest
import sympy

from analysis.engine.io import (
    InputError,
    System,
    format_polynomial,
    parse_msolve,
    parse_polynomial,
    read_system,
    to_macaulay2,
    to_msolve,
    to_singular,
    write_system,
)
from analysis.engine.f4 import groebner
from analysis.engine.msolve import INSTALL_HINT, find_msolve, parse_msolve_basis
from analysis.engine.ring import BadPrime, Ring
from analysis.engine.systems import katsura

PRIMES = (65521, 32003)


def sympy_system(exprs: list[str], variables: list[str], characteristic: int = 0) -> System:
    """The reference: sympy's parser and expand, converted through System.from_sympy."""
    syms = {v: sympy.Symbol(v) for v in variables}
    parsed = [sympy.expand(sympy.sympify(e.replace("^", "**"), locals=syms)) for e in exprs]
    return System.from_sympy(parsed, variables, characteristic)


# -- parsing --------------------------------------------------------------------------------------

EXAMPLE = """\
# a comment before the header
x, y, z   # variables
0
x^2 + 3/4*y - 1/2,        # first polynomial
(x - 2*y + 1/3)^3
   * (z - x)^2            # continues over lines
   - 3/7*(x*y - z)^2,

x**2*y - -z + +1, # blank line above, '**' and unary signs
2^3^2*x - (x+y)^0 - x/2/3,
"""


def test_parse_example_matches_sympy_expand():
    system = parse_msolve(EXAMPLE, "example.ms")
    expected = sympy_system(
        [
            "x^2 + 3/4*y - 1/2",
            "(x - 2*y + 1/3)^3 * (z - x)^2 - 3/7*(x*y - z)^2",
            "x^2*y + z + 1",
            "512*x - 1 - x/6",
        ],
        ["x", "y", "z"],
    )
    assert system == expected
    assert system.variables == ("x", "y", "z")
    assert system.characteristic == 0
    assert system.lines == (4, 5, 9, 10)
    assert system.source == "example.ms"
    assert system.polynomials[0] == {(2, 0, 0): 1, (0, 1, 0): Fraction(3, 4), (0, 0, 0): Fraction(-1, 2)}


@pytest.mark.parametrize(
    "expr",
    [
        "(x + y)^5 - (x - y)^5",
        "((x - 1/2)*(y + 2/3) - z)^4",
        "-x^2 + (-x)^2 - x^3",
        "(2*x - 3*y + z - 5)^3 * (x*y*z - 1)^2",
        "(x + y + z)^7 / 3 - 5/2*(x - z)**3",
        "x*(y*(z*(x + 1) - 1) + 1)",
        "1/2/3*x - 4/(2*3)*y + (1/2)^3",
        "(x^2)^3^1 - x^6",
    ],
)
def test_expansion_agrees_with_sympy(expr):
    vars_ = ["x", "y", "z"]
    assert parse_msolve(f"x,y,z\n0\n{expr}\n") == sympy_system([expr], vars_)
    assert parse_polynomial(expr, vars_) == sympy_system([expr], vars_).polynomials[0]


def test_precedence_and_associativity():
    v = ["x"]
    assert parse_polynomial("-x^2", v) == {(2,): -1}
    assert parse_polynomial("2^3^2", v) == {(0,): 512}
    assert parse_polynomial("x**2", v) == parse_polynomial("x^2", v)
    assert parse_polynomial("x*-x", v) == {(2,): -1}
    assert parse_polynomial("x/2/3", v) == {(1,): Fraction(1, 6)}
    assert parse_polynomial("x - 1 - 1", v) == {(1,): 1, (0,): -2}


def test_zero_constant_and_duplicate_polynomials_are_kept():
    system = parse_msolve("x,y\n0\nx - x, 0, (x+1)^2 - x^2 - 2*x - 1, 5, x*y, x*y,\n")
    assert system.polynomials == ({}, {}, {}, {(0, 0): 5}, {(1, 1): 1}, {(1, 1): 1})
    assert len(system.lines) == 6
    ring, polys = system.to_ring(65521)
    assert [bool(f) for f in polys] == [False, False, False, True, True, True]
    assert polys[3] == ring.one().scale(5)


def test_characteristic_p_coefficients_are_reduced():
    system = parse_msolve("x,y\n7\n3/4*x + 8*y - 14, x/3\n")
    # 3/4 = 3 * 2 = 6 = -1 mod 7; 8 = 1; 14 = 0; 1/3 = 5 = -2 mod 7
    assert system.polynomials == ({(1, 0): -1, (0, 1): 1}, {(1, 0): -2})


def test_read_system_names_the_file(tmp_path):
    path = tmp_path / "sys.ms"
    path.write_text("x,y\n0\nx + y,\nx - q\n")
    with pytest.raises(InputError, match=r"sys\.ms, line 4, column 5: unknown variable 'q'"):
        read_system(path)
    path.write_text("x,y\n0\nx + y,\nx - y\n")
    assert read_system(path).source == str(path)


def test_windows_line_endings_and_polynomials_sharing_a_line():
    system = parse_msolve("x,y\r\n0\r\nx + y, x - y,\r\n  x*y\r\n")
    assert system == parse_msolve("x,y\n0\nx + y,\nx - y,\nx*y\n")
    assert system.lines == (3, 3, 4)


# -- round trips and GF(p) ------------------------------------------------------------------------

@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("characteristic", [0, 32003])
def test_random_systems_round_trip(seed, characteristic):
    rng = random.Random(seed)
    nvars = rng.randint(1, 4)
    polys = []
    for _ in range(rng.randint(1, 4)):
        f = {}
        for _ in range(rng.randint(0, 6)):
            m = tuple(rng.randint(0, 3) for _ in range(nvars))
            f[m] = Fraction(rng.randint(-50, 50), rng.randint(1, 9))
        polys.append(f)
    system = System(tuple(f"v{i}" for i in range(nvars)), characteristic, tuple(polys))
    assert parse_msolve(to_msolve(system)) == system, f"seed={seed}"


@pytest.mark.parametrize("text", [EXAMPLE, "a,b_1,c2\n65521\n(a - b_1)^3 + 1/5*c2, a*b_1*c2 - 7, 0\n"])
def test_msolve_round_trip(text):
    system = parse_msolve(text)
    out = to_msolve(system)
    again = parse_msolve(out)
    assert again == system
    assert to_msolve(again) == out
    assert hash(again) == hash(system)


@pytest.mark.parametrize("prime", PRIMES)
def test_to_ring_matches_sympy_mod_p(prime):
    exprs = ["x^2 + 3/4*y - 1/2", "(x - 2*y + 1/3)^3 * (z - x)^2 - 3/7*(x*y - z)^2", "x^2*y + z + 1"]
    system = parse_msolve("x,y,z\n0\n" + ",\n".join(exprs))
    ring, polys = system.to_ring(prime)
    assert ring == Ring(["x", "y", "z"], prime)
    for f, e in zip(polys, exprs):
        assert f == ring.from_sympy(sympy.sympify(e.replace("^", "**")))


def test_to_ring_denominator_divisible_by_prime():
    system = parse_msolve("x\n0\nx - 1,\nx/65521 - 1\n")
    with pytest.raises(InputError, match=r"polynomial 2 \(line 4\).*denominator divisible by the prime 65521"):
        system.to_ring(65521)
    ring, polys = system.to_ring(32003)  # another prime works
    assert polys[1] == ring.gen("x").scale(pow(65521, -1, 32003)) - ring.one()


def test_to_ring_characteristic_p_needs_that_prime():
    system = parse_msolve("x\n32003\nx - 1\n")
    assert system.to_ring(32003)[1][0].coeffs == [1, 32002]
    with pytest.raises(InputError, match="characteristic 32003"):
        system.to_ring(65521)
    with pytest.raises(BadPrime):
        parse_msolve("x\n0\nx\n").to_ring(65520)


def test_from_polys_round_trip():
    polys = katsura(3)
    ring = polys[0].ring
    system = System.from_polys(ring, polys)
    assert system.characteristic == ring.prime
    assert system.to_ring(ring.prime) == (ring, polys)
    assert parse_msolve(to_msolve(system)).to_ring(ring.prime)[1] == polys


def test_system_equality_ignores_provenance():
    a = parse_msolve("x\n0\nx\n", "a.ms")
    b = System(("x",), 0, ({(1,): Fraction(1)},))
    assert a == b and hash(a) == hash(b)
    assert b.lines == (0,) and b.degrees() == (1,)


# -- errors ---------------------------------------------------------------------------------------

ERRORS = [
    # unknown variable: named, with the line and the valid variables
    ("x,y\n0\nx + y,\nx + z\n", ["line 4", "unknown variable 'z'", "variables are x, y"]),
    # malformed polynomials: line, column and token
    ("x,y\n0\nx + * y\n", ["line 3, column 5", "unexpected '*'"]),
    ("x,y\n0\nx y\n", ["line 3, column 3", "unexpected 'y'", "missing '*'"]),
    ("x,y\n0\n2x\n", ["column 2", "unexpected 'x'"]),
    ("x,y\n0\nx + y\nx - y\n", ["line 4, column 1", "missing ',' at the end of line 3"]),
    ("x,y\n0\n(x + y\n", ["expected ')'", "line 3, column 1"]),
    ("x,y\n0\nx + y)\n", ["column 6", "unmatched ')'"]),
    ("x,y\n0\n(x, y)\n", ["',' inside parentheses"]),
    ("x,y\n0\nx +\n", ["unexpected end of polynomial"]),
    ("x,y\n0\n1.5.2*x\n", ["column 1", "malformed number '1.5.2'"]),
    ("x,y\n0\n1e*x\n", ["column 1", "malformed number '1e'", "scientific notation"]),
    ("x,y\n0\n1e9999999*x\n", ["'1e9999999'", "power of ten beyond"]),
    ("x,y\n0\nx $ y\n", ["column 3", "unknown variable '$'"]),
    ("x,y\n0\nx y\n", ["column 3", "unexpected 'y' after 'x' (missing '*'?)"]),
    ("x,y\n0\n2.5.*x\n", ["column 4", "malformed number '2.5.'"]),
    ("x,y\n0\nx,,y\n", ["empty polynomial"]),
    # characteristic
    ("x\n65520\nx\n", ["line 2", "not prime"]),
    ("x\n2147483659\nx\n", ["line 2", "out of range", "2^31"]),
    ("x\n2147483648\nx\n", ["out of range"]),
    ("x\n1\nx\n", ["out of range"]),
    ("x\n-7\nx\n", ["out of range"]),
    ("x\nabc\nx\n", ["line 2", "must be an integer", "'abc'"]),
    ("x\n7.0\nx\n", ["must be an integer"]),
    # empty system and missing lines
    ("x,y\n0\n", ["empty system"]),
    ("x,y\n0\n# only a comment\n\n", ["empty system"]),
    ("", ["missing variable line"]),
    ("# nothing but a comment\n", ["missing variable line"]),
    ("x,y\n", ["missing characteristic line"]),
    # variable names
    ("x,y,x\n0\nx\n", ["line 1", "duplicate variable name 'x'"]),
    ("x,2y\n0\nx\n", ["invalid variable name '2y'"]),
    ("x,y z\n0\nx\n", ["invalid variable name 'y z'"]),
    ("x,.y\n0\nx\n", ["invalid variable name '.y'"]),
    ("x,y^2\n0\nx\n", ["invalid variable name 'y^2'"]),
    ("x,\n0\nx\n", ["empty variable name"]),
    ("x,1\n0\nx\n", ["variable name '1' collides with a number"]),
    # division
    ("x\n0\nx/0\n", ["division by zero"]),
    ("x,y\n0\nx/(y - y)\n", ["division by zero"]),
    ("x\n7\nx/14\n", ["division by 14, which is zero in characteristic 7"]),
    ("x\n0\n1/x\n", ["division by a non-constant polynomial"]),
    # exponents
    ("x\n0\nx^-1\n", ["negative exponent -1"]),
    ("x\n0\nx^(1/2)\n", ["non-integer exponent 1/2"]),
    ("x,y\n0\nx^y\n", ["exponent must be a nonnegative integer"]),
    ("x\n0\nx^\n", ["missing exponent"]),
    ("x\n0\nx^9999999999\n", ["exponent 9999999999 too large"]),
    ("x\n0\n(x+1)^70000\n", ["exponent 70000 too large for expanding a sum"]),
    ("x\n0\n9^9^9\n", ["too large"]),
]


@pytest.mark.parametrize("text, fragments", ERRORS)
def test_input_errors(text, fragments):
    with pytest.raises(InputError) as info:
        parse_msolve(text, "in.ms")
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith("in.ms")
    for fragment in fragments:
        assert fragment in message, (fragment, message)
    assert isinstance(info.value, ValueError)


@pytest.mark.parametrize(
    "build, fragment",
    [
        (lambda: System(("x",), 0, ()), "empty system"),
        (lambda: System(("x", "x"), 0, ({},)), "duplicate variable name"),
        (lambda: System((), 0, ({},)), "no variables"),
        (lambda: System(("x",), 9, ({},)), "not prime"),
        (lambda: System(("x",), 0, ({(1, 2): 1},)), "exponent vector"),
        (lambda: System(("x",), 0, ({(1,): 0.5},)), "not an integer or Fraction"),
        (lambda: System(("x",), 7, ({(1,): Fraction(1, 7)},)), "undefined in characteristic 7"),
        (lambda: System.from_sympy([sympy.Symbol("x") * 0.5], ["x"]), "floating-point"),
        (lambda: System.from_sympy([sympy.Symbol("z")], ["x"]), "unknown variable(s) z"),
        (lambda: System.from_sympy([1 / sympy.Symbol("x")], ["x"]), "not a polynomial"),
        (lambda: System.from_sympy([sympy.sqrt(2) * sympy.Symbol("x")], ["x"]), "not a polynomial"),
        (lambda: parse_polynomial("x, y", ["x", "y"]), "expected one polynomial"),
    ],
)
def test_object_errors(build, fragment):
    with pytest.raises(InputError) as info:
        build()
    assert fragment in str(info.value) and "\n" not in str(info.value)


def test_from_sympy_matches_symbols_by_name_and_accepts_equations():
    x, y = sympy.symbols("x y", real=True)
    system = System.from_sympy([sympy.Eq(x**2, y / 3), 2 * x * y], ["x", "y"], characteristic=65521)
    assert system == parse_msolve("x,y\n65521\nx^2 - y/3, 2*x*y\n")
    # strings are sympified with the variables bound to symbols, so 'I' is a variable, not sqrt(-1)
    assert System.from_sympy(["x^2 - 1/3", "I*x"], ["x", "I"]) == parse_msolve("x,I\n0\nx^2 - 1/3, I*x\n")


# -- writers --------------------------------------------------------------------------------------

def test_format_polynomial_grevlex_and_rationals():
    f = parse_polynomial("1 - 3/4*x + y^2*x - x^2", ["x", "y"])
    assert format_polynomial(f, ["x", "y"]) == "x*y^2 - x^2 - 3/4*x + 1"
    assert format_polynomial({}, ["x"]) == "0"
    assert format_polynomial({(0, 0): Fraction(-2, 3)}, ["x", "y"]) == "-2/3"


def test_macaulay2_script():
    m2 = to_macaulay2(parse_msolve("x,y\n0\nx^2 - 3/4*y, y^2 - 1, 0\n"))
    assert "R = QQ[x, y, MonomialOrder => GRevLex];" in m2
    assert "I = ideal(\n    x^2 - 3/4*y,\n    y^2 - 1,\n    promote(0, R)\n);" in m2
    assert m2.rstrip().endswith("print degree I; print dim I")
    assert "R = ZZ/65521[x, y" in to_macaulay2(parse_msolve("x,y\n65521\nx - y\n"))


def test_singular_script():
    text = to_singular(parse_msolve("x,y\n0\nx^2 - 3/4*y, y^2 - 1\n"))
    assert "ring r = 0,(x,y),dp;" in text
    assert "ideal i =\n  x^2 - 3/4*y,\n  y^2 - 1;" in text
    assert "ideal g = std(i);\nprint(vdim(g));\nprint(dim(g));" in text
    assert "ring r = 32003,(x,y),dp;" in to_singular(parse_msolve("x,y\n32003\nx - y\n"))


def test_writers_rename_reserved_names():
    system = parse_msolve("dim, x_1, r, R, I, g\n0\ndim - x_1, r - R, I - g\n")
    m2 = to_macaulay2(system)
    assert "variables renamed for Macaulay2: dim -> dim0, x_1 -> x1" in m2
    assert "R0 = QQ[dim0, x1, r, R, I, g, MonomialOrder => GRevLex];" in m2
    assert "print degree I0; print dim I0" in m2
    sing = to_singular(system)
    assert "variables renamed for Singular: dim -> dim0" in sing
    assert "ring r0 = 0,(dim0,x_1,r,R,I,g),dp;" in sing
    assert "ideal g0 = std(i);" in sing


def test_msolve_names_are_read_and_renamed_for_the_other_systems():
    system = parse_msolve(MSOLVE_NAMES)
    assert system.variables == ("x[1]", "x'", "a.b", "_t", "\u03b1")
    assert parse_msolve(to_msolve(system)) == system
    m2 = to_macaulay2(system)
    assert "R = QQ[x1, x, ab, t, v, MonomialOrder => GRevLex];" in m2
    assert "ring r = 0,(x1,x,ab,t,v),dp;" in to_singular(system)


def test_write_system(tmp_path):
    system = parse_msolve("x,y\n0\nx^2 - 1/2, y - x\n")
    assert read_system(write_system(system, tmp_path / "s.ms", "msolve")) == system
    assert "ideal(" in write_system(system, tmp_path / "s.m2", "m2").read_text()
    assert "std(" in write_system(system, tmp_path / "s.sing", "singular").read_text()
    with pytest.raises(ValueError, match="valid formats: msolve, m2, singular"):
        write_system(system, tmp_path / "s.x", "maple")


# -- optional cross-checks (skipped when the CAS is not installed) -------------------------------

KATSURA3_Q = to_msolve(System.from_polys(katsura(3)[0].ring, katsura(3))).replace("65521", "0", 1)
# reserved names in both systems, char p with rationals: 6 * 2 * 2 = 24 points, dimension 0
RENAMED_P = "dim, x_1, r, R, I, g, ord\n32003\ndim^2 - x_1, x_1^3 - 1/2, r - R^2, R^2 - 3, I*g - 1, g^2 - 5, ord - dim\n"
# (text, Singular's vdim and dim, Macaulay2's degree and dim); vdim is -1 off dimension 0
# names as msolve reads them (brackets, primes, dots, a leading '_', non-ASCII letters): 2 * 2 = 4 points
MSOLVE_NAMES = "x[1], x', a.b, _t, \u03b1\n0\nx[1]^2 - 2, x' - x[1], a.b*_t - 1, _t^2 - 3, \u03b1 - a.b\n"
CROSS_CHECKS = [
    (KATSURA3_Q, ["8", "0"], ["8", "0"]),
    (RENAMED_P, ["24", "0"], ["24", "0"]),
    ("x,y\n0\nx*y - 1/3, 0\n", ["-1", "1"], ["2", "1"]),
    (MSOLVE_NAMES, ["4", "0"], ["4", "0"]),
]
CROSS_IDS = ["katsura3", "reserved-names-char-p", "positive-dimensional", "msolve-names"]


@pytest.mark.skipif(shutil.which("Singular") is None, reason="Singular not installed")
@pytest.mark.parametrize("text, expected, _", CROSS_CHECKS, ids=CROSS_IDS)
def test_singular_cross_check(tmp_path, text, expected, _):
    path = write_system(parse_msolve(text), tmp_path / "s.sing", "singular")
    out = subprocess.run(["Singular", "-q", str(path)], capture_output=True, text=True, timeout=60)
    assert out.stdout.split() == expected, out.stdout + out.stderr


@pytest.mark.skipif(shutil.which("M2") is None, reason="Macaulay2 not installed")
@pytest.mark.parametrize("text, _, expected", CROSS_CHECKS, ids=CROSS_IDS)
def test_macaulay2_cross_check(tmp_path, text, _, expected):
    path = write_system(parse_msolve(text), tmp_path / "s.m2", "m2")
    out = subprocess.run(["M2", "--script", str(path)], capture_output=True, text=True, timeout=120)
    assert out.stdout.split() == expected, out.stdout + out.stderr


BIG_Q = "x,y,z\n0\n123456789012345678901*x^2 - 3/7*y*z, y^2 - x + 5, z^3 - x*y - 1\n"


@pytest.mark.skipif(find_msolve() is None, reason=f"msolve not installed ({INSTALL_HINT})")
@pytest.mark.parametrize("text", [t for t, _, _ in CROSS_CHECKS] + [BIG_Q], ids=CROSS_IDS + ["big-rationals"])
def test_msolve_cross_check(tmp_path, text):
    """The exporter's file, run by msolve itself: its reduced basis (over Q: reduced mod 65521) is the own
    engine's. Reserved names, rationals and 21-digit integers go through as msolve reads them."""
    system = parse_msolve(text)
    path = write_system(system, tmp_path / "s.ms", "msolve")
    out = subprocess.run([find_msolve(), "-g", "2", "-t", "1", "-f", str(path), "-o", str(tmp_path / "gb")],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    ring, polys = system.to_ring(system.characteristic or 65521)
    expected = groebner([f for f in polys if f]).basis
    answer = parse_msolve_basis((tmp_path / "gb").read_text(), ring, system.variables)
    assert {g.monic() for g in answer} == set(expected)


def test_integers_of_any_length(tmp_path):
    """Coefficients beyond Python's 4300-digit limit for int <-> str are read and written (in chunks,
    without lifting the process-wide limit); a characteristic or an exponent that long is a clear error."""
    big, den = 7 * (10**5000 - 1) // 9, (10**4400 - 1) // 3 + 2  # 77...7 and 33...35
    system = parse_msolve("x,y\n0\n" + "7" * 5000 + "*x - y/" + "3" * 4399 + "5, y^2 - 1\n")
    assert system.polynomials[0] == {(1, 0): Fraction(big), (0, 1): Fraction(-1, den)}
    assert parse_msolve(to_msolve(system)) == system
    assert read_system(write_system(system, tmp_path / "big.ms", "msolve")) == system
    with pytest.raises(InputError, match="characteristic of 5000 digits"):
        parse_msolve("x\n" + "1" * 5000 + "\nx\n")
    with pytest.raises(InputError, match="exponent of 5000 digits too large"):
        parse_msolve("x\n0\nx^" + "9" * 5000 + "\n")


@pytest.mark.parametrize("text", ["x + 0", "x+0*x^2", "0 + x", "x - 0*x", "(x + 0)^2 - x^2 + x", "x+00"])
def test_a_zero_term_is_no_term(text):
    """'x+0' once raised KeyError (a zero constant kept as a term with coefficient 0; found by the fuzz)."""
    assert parse_msolve(f"x\n0\n{text}\n").polynomials == ({(1,): Fraction(1)},)


# -- the fast path of sums of terms (analysis.engine.polytext.parse_sums) ---------------------------

SUMS = [
    "x,y\n0\nx + y, x - y,\n  x*y\n",
    "x,y\n0\n-2/4*x^3*y**2 + 3 - y*x*x, 0, x - x\n",
    "x,y\n7\n10*x + 14/3*y - 1,\n y^2\n- x,\n",
    "x',y[1]\n0\n 12345678901234567890*x'^2*y[1] + 1/3\n",
    "x,y,z\n0\nx^65535*y - 5/10, z ** 4 *x* y -7*x\n",
    "x,y\n0\n2 - 2, x\t+\ty\n",
]
"""Texts inside the fast path (zero coefficients, repeated variables, continuation lines, tabs, p)."""


def _slow(text, monkeypatch):
    """The recursive-descent parser's reading (the fast path switched off)."""
    import analysis.engine.io as io

    monkeypatch.setattr(io, "parse_sums", lambda *args: None)
    try:
        return io.parse_msolve(text)
    finally:
        monkeypatch.undo()


@pytest.mark.parametrize("text", SUMS)
def test_sums_fast_path_reads_like_the_parser(text, monkeypatch):
    from analysis.engine.polytext import parse_sums

    body = text.split("\n", 2)[2]
    assert parse_sums(body, text.split("\n")[0].split(","), int(text.split("\n")[1])) is not None  # fast path taken
    fast, slow = parse_msolve(text), _slow(text, monkeypatch)
    assert fast == slow and fast.lines == slow.lines


@pytest.mark.parametrize("seed", range(4))
def test_sums_fast_path_random_systems(seed, monkeypatch):
    """Random sums with signs, fractions, powers written ^ or ** and spacing: fast == slow."""
    rng = random.Random(seed)
    names = [f"v{i}" for i in range(rng.randint(1, 5))]
    polys = []
    for _ in range(rng.randint(1, 6)):
        terms = []
        for k in range(rng.randint(1, 7)):
            sign = rng.choice(["+", "-"]) if k else rng.choice(["", "-", "+"])
            coef = rng.choice(["", f"{rng.randint(0, 10**25)}", f"{rng.randint(0, 99)}/{rng.randint(1, 99)}"])
            factors = [rng.choice(names) + rng.choice(["", f"^{rng.randint(0, 5)}", f"**{rng.randint(1, 5)}"])
                       for _ in range(rng.randint(0 if coef else 1, 3))]
            mono = rng.choice(["*", " * "]).join(factors)
            terms.append(f"{sign} {coef}{'*' if coef and mono else ''}{mono}")
        polys.append(rng.choice([" ", "", "\n"]).join(terms))
    text = ",".join(names) + "\n0\n" + ",\n".join(polys) + "\n"
    assert parse_msolve(text) == _slow(text, monkeypatch), text


def test_outside_the_fast_path_errors_are_the_parsers():
    """Every error text of the table above is read by the full parser (the fast path declines)."""
    from analysis.engine.polytext import parse_sums

    for text, _ in ERRORS:
        parts = text.split("\n", 2)
        names = parts[0].split(",")
        header_ok = all(n.isalpha() for n in names) and len(set(names)) == len(names)
        if len(parts) == 3 and header_ok and parts[1].strip() in ("0", "7"):  # the polynomials' errors
            assert parse_sums(parts[2], parts[0].split(","), 0) is None, text


def test_ten_thousand_digit_coefficients_round_trip():
    """Integers above Python's 4300-digit str limit are converted by FLINT, both ways."""
    rng = random.Random(5)
    digits = str(rng.randint(1, 9)) + "".join(rng.choice("0123456789") for _ in range(12_000))
    system = parse_msolve(f"x\n0\nx - {digits}/7\n")
    value = 0
    for k in range(0, len(digits), 4000):  # Python's own reading, in chunks below its limit
        value = value * 10 ** len(digits[k:k + 4000]) + int(digits[k:k + 4000])
    assert system.polynomials[0][(0,)] == -Fraction(value, 7)
    assert parse_msolve(to_msolve(system)) == system  # written back by FLINT, read again
