"""Lex bases of positive-dimensional ideals through homogenization (analysis.engine.homogenize), and the deglex
order it runs F4 in, against sympy's Buchberger over GF(p)."""
from __future__ import annotations

import pytest
import sympy

from analysis.sweeps.benchmarks import dense_random_system
from analysis.engine.degree import analyse_prime
from analysis.engine.f4 import F4Options, groebner
from analysis.engine.homogenize import lex_by_homogenization
from analysis.engine.quotient import dimension
from analysis.engine.ring import Ring


def _sympy_basis(ring: Ring, polys, order: str) -> list:
    syms = sympy.symbols(ring.variables)
    gb = sympy.groebner([ring.to_sympy(f) for f in polys], *syms, modulus=ring.prime, order=order)
    return sorted((ring.from_sympy(e).monic() for e in gb.exprs), key=lambda g: g.lm)


def test_deglex_keys_decode_and_order_monomials_by_degree_then_lex():
    ring = Ring(("x", "y", "z"), 65521, "deglex")
    monomials = [(0, 0, 3), (1, 0, 0), (0, 2, 0), (1, 1, 1), (2, 0, 0), (0, 1, 1)]
    for e in monomials:
        assert ring.exps(ring.key(e)) == e
        assert tuple(ring.decode_many([ring.key(e)])[0]) == e
    ordered = sorted(monomials, key=ring.key, reverse=True)
    assert ordered == [(1, 1, 1), (0, 0, 3), (2, 0, 0), (0, 2, 0), (0, 1, 1), (1, 0, 0)]


@pytest.mark.parametrize("seed", range(3))
def test_deglex_basis_is_sympys_grlex(seed):
    polys = dense_random_system(3, (2, 2, 2), 32003, seed, Ring(("x", "y", "z"), 32003, "deglex"))
    gb = groebner(polys)
    assert list(gb.basis) == _sympy_basis(gb.ring, polys, "grlex")


@pytest.mark.parametrize("nvars, degrees, seed", [(3, (2, 2), 0), (3, (2, 3), 1), (4, (2, 2, 2), 2),
                                                  (3, (3, 3), 3)])
def test_positive_dimensional_lex_basis_is_sympys(nvars, degrees, seed):
    """Curves and surfaces cut by dense equations: the reduced lex basis equals sympy's, and F4 stays
    small (F4 directly in lex stopped at a 400M-cell cap on the two cubics)."""
    ring = Ring(tuple("xyzw"[:nvars]), 65521, "lex")
    polys = dense_random_system(nvars, degrees, 65521, seed, ring)
    gb = lex_by_homogenization(polys)
    assert dimension(gb) == nvars - len(degrees)
    assert list(gb.basis) == _sympy_basis(ring, polys, "lex")
    rows, cols = gb.max_matrix
    assert rows * cols < 1_000_000


def test_degree_takes_the_homogenized_route_for_positive_dimensional_lex():
    """A point and a curve (x (x - 1) = 0 and x (y^2 - z) = 0 with z y = 1 on the point's side): the own
    engine's lex answer is the reduced basis sympy gives, under a cap F4 in lex would exceed."""
    ring = Ring(("x", "y", "z"), 65521, "lex")
    x, y, z = ring.gens()
    polys = [x * x - x, x * (y * y - z), (x - 1) * (y * z - 1) + x * (z * z * z - y - 3)]
    result = analyse_prime(polys, F4Options(max_matrix_cells=2_000))
    assert result.dimension == 1 and result.degree is None
    assert list(result.gb.basis) == _sympy_basis(ring, polys, "lex")


def test_lex_by_homogenization_needs_a_lex_ring():
    ring = Ring(("x", "y"), 65521, "grevlex")
    with pytest.raises(ValueError, match="lex ring"):
        lex_by_homogenization([ring.gen(0)])


@pytest.mark.parametrize("seed", range(3))
def test_tail_reduction_by_f4_equals_the_division_fallback(seed, monkeypatch):
    """The reduced basis from F4's tail reduction (interreduce) equals the one from dividing each tail by
    the others (the fallback where the narrow monomial codes overflow)."""
    import analysis.engine.homogenize as homogenize
    from analysis.engine.ring import CodeOverflow

    ring = Ring(("x", "y", "z"), 32003, "lex")
    polys = dense_random_system(3, (3, 3), 32003, seed, ring)
    by_f4 = lex_by_homogenization(polys)

    def overflow(*args, **kwargs):
        raise CodeOverflow("forced for the test")

    monkeypatch.setattr(homogenize, "interreduce", overflow)
    by_division = lex_by_homogenization(polys)
    assert by_f4.basis == by_division.basis and len(by_f4.basis) >= 2


@pytest.mark.parametrize("blocks, seed", [((1, 2), 0), ((2, 1), 1), ((1, 1, 1), 2)])
def test_positive_dimensional_block_basis_is_sympys(blocks, seed):
    """Block orders take the homogenized route too (issue 35: two dense cubics in block:1,1,1 were refused
    by a 40668 x 157247 matrix); the graded order of the homogenizing ring breaks degree ties by the
    block order."""
    from sympy.polys.orderings import ProductOrder, grevlex

    from analysis.engine.degree import groebner_in_order
    from analysis.engine.homogenize import by_homogenization

    nvars = sum(blocks)
    ring = Ring(tuple("xyzw"[:nvars]), 32003, "block:" + ",".join(map(str, blocks)))
    polys = dense_random_system(nvars, (3, 2), 32003, seed, ring)
    cuts = [sum(blocks[:k]) for k in range(len(blocks) + 1)]
    order = ProductOrder(*[(grevlex, (lambda a, b: lambda m: m[a:b])(a, b)) for a, b in zip(cuts, cuts[1:])])
    gb = by_homogenization(polys)
    assert list(gb.basis) == _sympy_basis(ring, polys, order)
    assert groebner_in_order(polys, F4Options(max_matrix_cells=1_000_000)).basis == gb.basis
