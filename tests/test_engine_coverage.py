"""Inputs Singular answers in milliseconds (issue 35, item 2): linear substitution before F4,
characteristic 2 and small primes against sympy, through the engine and the command line."""
import json
import random

import pytest
import sympy

from analysis.engine.f4 import F4Options, groebner
from analysis.engine.ring import Ring
from solvers.cli import main

SUBSTITUTE = F4Options(linear_substitution=True)


def random_system(seed: int, prime: int, order: str):
    """2-4 variables: one or two random linear polynomials and random ones of degree 2-3."""
    rng = random.Random(seed)
    n = rng.randint(2, 4)
    ring = Ring([f"x{i}" for i in range(n)], prime, order)
    polys = []
    for k in range(n):
        degree = 1 if k < rng.randint(1, 2) else rng.randint(2, 3)
        terms = {}
        for _ in range(rng.randint(2, 5)):
            e = [0] * n
            for _ in range(rng.randint(0, degree)):
                e[rng.randrange(n)] += 1
            terms[tuple(e)] = rng.randrange(1, prime)
        top = [0] * n
        top[rng.randrange(n)] = degree
        terms[tuple(top)] = 1
        polys.append(ring.from_terms(terms))
    rng.shuffle(polys)
    return ring, polys


@pytest.mark.parametrize("order", ["grevlex", "lex", "deglex", "block:1,1"])
@pytest.mark.parametrize("prime", [2, 3, 32003, 2147483647])
def test_linear_substitution_gives_the_same_reduced_basis(order, prime):
    for seed in range(8):
        ring, polys = random_system(seed, prime, order if not order.startswith("block") else
                                    f"block:1,{random.Random(seed).randint(2, 4) - 1}")
        if order == "lex" and ring.nvars > 3:
            continue  # F4 directly in lex swells; the order itself is what is tested
        assert groebner(polys, SUBSTITUTE).basis == groebner(polys).basis, (order, prime, seed)


@pytest.mark.parametrize("prime", [2, 3, 5])
def test_small_characteristic_matches_sympy(prime):
    for seed in range(10):
        ring, polys = random_system(seed, prime, "grevlex")
        syms = sympy.symbols(ring.variables)
        expected = {ring.from_sympy(e).monic() for e in
                    sympy.groebner([ring.to_sympy(f) for f in polys], *syms, modulus=prime, order="grevlex").exprs}
        assert set(groebner(polys).basis) == expected, (prime, seed)


def degree_json(capsys, tmp_path, text, *argv):
    path = tmp_path / "system.ms"
    path.write_text(text)
    code = main(["degree", str(path), "--json", *argv])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


def test_issue_x200_plus_y(capsys, tmp_path):
    """Refused before by the 400M-cell cap (a 20101 x 20301 matrix at degree 200)."""
    report = degree_json(capsys, tmp_path, "x,y\n0\nx^200+y, x+y+1\n", "--gb")
    assert report["degree"] == 200 and report["groebner_basis"][0] == "x + y + 1"
    assert report["groebner_basis"][1].startswith("y^200 + 200*y^199 + 19900*y^198")
    assert report["max_matrix"][0] * report["max_matrix"][1] < 10_000


def test_issue_characteristic_2(capsys, tmp_path):
    """Refused before (characteristic 2 out of range)."""
    report = degree_json(capsys, tmp_path, "x,y\n2\nx^3+x*y+1, y^3+x*y^2+x+y\n", "--gb")
    x, y = sympy.symbols("x y")
    gb = sympy.groebner([x**3 + x*y + 1, y**3 + x*y**2 + x + y], x, y, modulus=2, order="grevlex")
    ring = Ring(["x", "y"], 2)
    assert report["primes"] == [2] and report["dimension"] == 0
    assert {str(ring.from_sympy(e)) for e in gb.exprs} == set(report["groebner_basis"])
    leads = [sympy.Poly(e, x, y).monoms(order="grevlex")[0] for e in gb.exprs]
    standard = [(a, b) for a in range(8) for b in range(8) if not any(a >= u and b >= v for u, v in leads)]
    assert report["degree"] == len(standard) > 1


@pytest.mark.parametrize("prime", [3, 32003, 2147483647])
def test_shape_lemma_path_gives_the_classical_fglm_basis(prime, monkeypatch):
    """Zero-dimensional systems to lex: the Berlekamp-Massey shape path (when the shape exists) and the
    classical FGLM walk give the same reduced basis; ideals without a shape fall back."""
    import analysis.engine.quotient as quotient

    shaped = 0
    systems = [random_system(seed, prime, "grevlex") for seed in range(12)]
    systems.append((lambda r: (r, [r.gen(0) ** 2, r.gen(1) ** 2]))(Ring(["x", "y"], prime)))  # no shape
    for ring, polys in systems:
        gb = groebner(polys)
        if not quotient.is_zero_dimensional(gb) or gb.is_unit:
            continue
        target = ring.with_order("lex")
        basis = quotient.standard_monomials(gb)
        shape = quotient._shape_basis(gb, target, basis, quotient.variable_action_matrices(gb, basis))
        with monkeypatch.context() as m:
            m.setattr(quotient, "_shape_basis", lambda *args, **kw: None)
            classical = quotient.fglm(gb, target).basis
        assert quotient.fglm(gb, target).basis == classical
        if shape is not None:
            assert shape == classical
            shaped += 1
    assert shaped >= 3


def test_issue_x1024_lex(capsys, tmp_path):
    """21 s at p = 32003 and > 70 s at 2^31 - 1 before (classical FGLM on a 1024-dimensional quotient);
    x = y^683 / 4 since y^683 = x^2049 = 4 x."""
    report = degree_json(capsys, tmp_path, "x,y\n0\nx^1024-2, y-x^3\n", "--order", "lex", "--gb")
    assert report["degree"] == 1024 and report["groebner_basis"] == ["y^1024 - 8", "x - 1/4*y^683"]


@pytest.mark.parametrize("text, degree", [("x\n0\nx^65536-1\n", 65536), ("x,y\n0\nx^100000-2, y^2-x\n", 200000),
                                          ("x,y\n7\nx^70000*y-1, y^2-x\n", 140001)])  # y^140001 = 1
def test_issue_exponents_past_65535(capsys, tmp_path, text, degree):
    """Refused before (16-bit monomial fields); the count of a univariate-like quotient is by the split,
    not degree by degree (65,537 waves took 3.8 s)."""
    assert degree_json(capsys, tmp_path, text)["degree"] == degree
