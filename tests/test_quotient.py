"""Tests for analysis.engine.quotient: standard monomials, dimension, normal forms, action matrices, saturation.

Roots are planted over GF(p) (:func:`analysis.sweeps.benchmarks.planted_root_system`) so that eigenvalues and
eigenvectors of the action matrices can be checked exactly; normal forms are compared with sympy's
``reduced`` remainder mod p.
"""
from __future__ import annotations

from itertools import combinations, product

import flint
import numpy as np

import pytest
import sympy

from analysis.sweeps.benchmarks import (
    dense_random_system,
    monomials_up_to,
    planted_root_system,
    random_small_system,
)
from analysis.engine.f4 import groebner
from analysis.engine.quotient import (
    NotZeroDimensional,
    action_matrix,
    count_standard_monomials,
    degree,
    dimension,
    fglm,
    is_zero_dimensional,
    normal_form,
    saturate,
    standard_monomials,
)
from analysis.engine.ring import Poly, Ring
from analysis.engine.systems import cyclic, katsura


# ----------------------------------------------------------------------------------------------
# helpers
# ----------------------------------------------------------------------------------------------
def monomial_ideal(ring: Ring, exponents) -> list[Poly]:
    return [ring.from_terms({tuple(e): 1}) for e in exponents]


def brute_force_dimension(nvars: int, exponents) -> int:
    """dim of a monomial ideal: largest set S of variables with no generator supported inside S."""
    supports = [frozenset(i for i, e in enumerate(ex) if e) for ex in exponents]
    if any(not s for s in supports):
        return -1
    for size in range(nvars, -1, -1):
        for s in combinations(range(nvars), size):
            if not any(sup <= set(s) for sup in supports):
                return size
    raise AssertionError("unreachable: the empty set has no support inside it")


def nmod(m, p: int) -> flint.nmod_mat:
    m = [[int(v) for v in row] for row in np.asarray(m, dtype=object)]
    return flint.nmod_mat(m, p)


def evaluate_basis(ring: Ring, basis, point) -> list[int]:
    return [Poly(ring, [b], [1]).evaluate(point) for b in basis]


# ----------------------------------------------------------------------------------------------
# standard monomials, degree, dimension
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "name,polys,expected",
    [("katsura-5", katsura(5), 32), ("cyclic-5", cyclic(5), 70), ("dense (2,3,3)", dense_random_system(3, (2, 3, 3)), 18)],
)
def test_standard_monomials_count_is_the_degree(name, polys, expected):
    gb = groebner(polys)
    basis = standard_monomials(gb)
    assert len(basis) == degree(gb) == expected
    assert basis == sorted(set(basis)) and basis[0] == 0
    ring = gb.ring
    for b in basis:
        assert not any(ring.divides(lm, b) for lm in gb.leading_monomials)
    # complete: every monomial of the box of the pure powers that no leading monomial divides is listed
    leads = [ring.exps(lm) for lm in gb.leading_monomials]
    box = [min(e[i] for e in leads if sum(e) == e[i]) for i in range(ring.nvars)]
    outside = [e for e in product(*map(range, box))
               if not any(all(a <= b for a, b in zip(lead, e)) for lead in leads)]
    assert sorted(outside) == sorted(ring.exps(b) for b in basis)
    # closed under division: every divisor of a standard monomial is standard
    keys = set(basis)
    for b in basis:
        e = ring.exps(b)
        for i, x in enumerate(e):
            if x:
                assert ring.key(e[:i] + (x - 1,) + e[i + 1 :]) in keys


def test_standard_monomials_of_a_monomial_ideal():
    ring = Ring(["x", "y"], 32003)
    gb = groebner(monomial_ideal(ring, [(3, 0), (1, 1), (0, 2)]))
    assert sorted(ring.exps(b) for b in standard_monomials(gb)) == [(0, 0), (0, 1), (1, 0), (2, 0)]
    assert degree(gb) == 4


def test_unit_ideal_has_no_standard_monomials():
    ring = Ring(["x", "y"], 32003)
    x, y = ring.gens()
    gb = groebner([x * y - ring.one(), x])
    assert gb.is_unit
    assert standard_monomials(gb) == [] and degree(gb) == 0 and dimension(gb) == -1
    assert is_zero_dimensional(gb)


@pytest.mark.parametrize(
    "label,make,expected",
    [
        ("affine twisted cubic", lambda r: [r.gen(1) - r.gen(0) ** 2, r.gen(2) - r.gen(0) ** 3], 1),
        ("plane and line", lambda r: [r.gen(0) * r.gen(1), r.gen(0) * r.gen(2)], 2),
        ("dense surface", lambda r: dense_random_system(3, (2,), r.prime, seed=1, ring=r), 2),
        ("zero ideal", lambda r: [r.zero()], 3),
    ],
)
def test_not_zero_dimensional_carries_the_dimension(label, make, expected):
    ring = Ring(["x0", "x1", "x2"], 65521)
    gb = groebner(make(ring))
    assert not is_zero_dimensional(gb)
    assert dimension(gb) == expected
    with pytest.raises(NotZeroDimensional) as info:
        standard_monomials(gb)
    assert info.value.dimension == expected, label
    with pytest.raises(NotZeroDimensional):
        degree(gb)


@pytest.mark.parametrize(
    "nvars,exponents,expected",
    [
        (3, [(1, 1, 0), (0, 1, 1)], 2),  # y = 0 or x = z = 0
        (3, [(2, 0, 0), (0, 3, 0)], 1),  # the z-axis, with multiplicity
        (3, [(1, 1, 1)], 2),  # union of the coordinate planes
        (3, [(1, 0, 0), (0, 1, 0), (0, 0, 1)], 0),  # the origin
        (4, [(1, 1, 0, 0), (0, 0, 1, 1)], 2),  # union of four planes
        (4, [(1, 0, 0, 0)], 3),
        (4, [(1, 1, 1, 1), (2, 0, 0, 0), (0, 0, 0, 5)], 2),
        (2, [(0, 0)], -1),  # the unit ideal
    ],
)
def test_dimension_of_monomial_ideals(nvars, exponents, expected):
    ring = Ring([f"x{i}" for i in range(nvars)], 32003)
    gb = groebner(monomial_ideal(ring, exponents))
    assert dimension(gb) == expected == brute_force_dimension(nvars, exponents)
    assert is_zero_dimensional(gb) == (expected <= 0)


@pytest.mark.parametrize("seed", range(12))
def test_dimension_of_random_monomial_ideals_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    nvars = int(rng.integers(2, 6))
    mons = [m for m in monomials_up_to(nvars, 3) if any(m)]
    picks = rng.choice(len(mons), size=int(rng.integers(1, 5)), replace=False)
    exponents = [mons[int(i)] for i in picks]
    ring = Ring([f"x{i}" for i in range(nvars)], 65521)
    gb = groebner(monomial_ideal(ring, exponents))
    assert dimension(gb) == brute_force_dimension(nvars, exponents), f"seed {seed}: {exponents}"


# ----------------------------------------------------------------------------------------------
# normal forms
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("prime,seed", [(p, s) for p in (32003, 2147483647) for s in range(5)])
def test_normal_form_matches_sympy_reduced(prime, seed):
    ring, polys = random_small_system(seed, prime, "square", nvars=3, max_degree=2)
    gb = groebner(polys)
    syms = sympy.symbols(ring.variables)
    basis = [ring.to_sympy(g) for g in gb.basis]
    rng = np.random.default_rng(1000 + seed)
    for _ in range(3):
        mons = monomials_up_to(3, 4)
        picks = rng.choice(len(mons), size=6, replace=False)
        f = ring.from_terms((mons[int(i)], int(c)) for i, c in zip(picks, rng.integers(1, prime, size=6)))
        _, rem = sympy.reduced(ring.to_sympy(f), basis, *syms, modulus=prime, order="grevlex")
        assert normal_form(f, gb) == ring.from_sympy(rem), f"seed {seed}, f = {f}"


def test_normal_form_is_linear_and_kills_the_ideal():
    ring = Ring(["x", "y", "z"], 65521)
    polys = dense_random_system(3, (2, 2, 2), 65521, seed=3)
    gb = groebner(polys)
    x, y, z = ring.gens()
    f, g = x**3 * y + z, y**4 - x * z.scale(5)
    assert normal_form(f + g.scale(7), gb) == normal_form(f, gb) + normal_form(g, gb).scale(7)
    for h in polys + list(gb.basis):
        assert not normal_form(h * (x * y + z), gb)
    for b in standard_monomials(gb):
        m = Poly(ring, [b], [1])
        assert normal_form(m, gb) == m


# ----------------------------------------------------------------------------------------------
# action matrices
# ----------------------------------------------------------------------------------------------
PLANTED = [
    (2, (2, 3), 3, 32003, 0),
    (3, (2, 2, 2), 4, 65521, 1),
    (3, (2, 2, 3), 5, 2147483647, 2),
]


@pytest.mark.parametrize("nvars,degrees,npoints,prime,seed", PLANTED)
def test_action_matrices_commute_and_have_the_planted_roots_as_eigenvalues(nvars, degrees, npoints, prime, seed):
    polys, points = planted_root_system(nvars, degrees, npoints, prime, seed)
    gb = groebner(polys)
    ring = gb.ring
    basis = standard_monomials(gb)
    assert len(basis) == int(np.prod(degrees)), f"seed {seed}: not generic"
    mats = [nmod(action_matrix(gb, i, basis), prime) for i in range(nvars)]
    for a in range(nvars):
        for b in range(a + 1, nvars):
            assert mats[a] * mats[b] == mats[b] * mats[a], f"M_{a} and M_{b} do not commute (seed {seed})"
    identity = nmod(np.eye(len(basis), dtype=np.int64), prime)
    for pt in points:
        v = nmod([[c] for c in evaluate_basis(ring, basis, pt)], prime)
        for i, m in enumerate(mats):
            # M v = x_i(pt) v: the evaluated standard monomials are an eigenvector
            assert m * v == v * flint.nmod(pt[i], prime), f"seed {seed}: point {pt}, variable {i}"
            assert (m - identity * flint.nmod(pt[i], prime)).det() == 0


def test_action_matrix_of_a_product_is_the_product_of_action_matrices():
    prime = 65521
    polys, _ = planted_root_system(3, (2, 2, 2), 2, prime, seed=5)
    gb = groebner(polys)
    ring = gb.ring
    x, y, z = ring.gens()
    f = x * y + z.scale(3) + ring.one()
    mx, my, mz = (nmod(action_matrix(gb, v), prime) for v in "x0 x1 x2".split())
    identity = nmod(np.eye(mx.nrows(), dtype=np.int64), prime)
    assert nmod(action_matrix(gb, f), prime) == mx * my + mz * flint.nmod(3, prime) + identity
    assert (action_matrix(gb, "x1") == action_matrix(gb, 1)).all()


def test_action_matrix_on_a_grid_has_the_expected_characteristic_polynomial():
    """I = (prod (x - a), prod (y - b)): the roots are the grid A x B, each simple."""
    prime = 32003
    ring = Ring(["x", "y"], prime)
    x, y = ring.gens()
    xs, ys = [2, 5, 11], [7, 13]
    fx, fy = ring.one(), ring.one()
    for a in xs:
        fx = fx * (x - ring.one().scale(a))
    for b in ys:
        fy = fy * (y - ring.one().scale(b))
    # a generic linear change of the generators, so the basis is not the input
    gb = groebner([fx + fy.scale(3), fx.scale(2) - fy])
    assert degree(gb) == 6
    t = sympy.Symbol("t")
    for var, values, mult in (("x", xs, len(ys)), ("y", ys, len(xs))):
        char = nmod(action_matrix(gb, var), prime).charpoly()
        expected = sympy.Poly(sympy.prod([(t - v) ** mult for v in values]), t, modulus=prime)
        assert [int(c) for c in char.coeffs()] == [int(c) % prime for c in reversed(expected.all_coeffs())]


# ----------------------------------------------------------------------------------------------
# saturation
# ----------------------------------------------------------------------------------------------
def test_saturation_removes_the_line_x_equals_zero():
    """(x y, x (x - 1)) = (x) ∩ (x - 1, y): saturating by x leaves the point (1, 0)."""
    ring = Ring(["x", "y"], 32003)
    x, y = ring.gens()
    gb = groebner([x * y, x * (x - ring.one())])
    assert dimension(gb) == 1
    sat = saturate([x * y, x * (x - ring.one())], x)
    assert set(sat.basis) == {x - ring.one(), y}
    assert degree(sat) == 1


@pytest.mark.parametrize("prime,seed", [(32003, 0), (65521, 1)])
def test_saturation_removes_a_planted_spurious_component(prime, seed):
    """J zero-dimensional with x != 0 at its roots. x*J has the extra component {x = 0}; J*(x, y) the
    extra point (0, 0). Saturating either by x gives back J."""
    ring = Ring(["x0", "x1"], prime)
    x, y = ring.gens()
    clean = dense_random_system(2, (2, 3), prime, seed=seed, ring=ring)
    j = groebner(clean)
    assert degree(j) == 6

    times_x = [x * f for f in clean]
    gb = groebner(times_x)
    assert dimension(gb) == 1
    sat = saturate(times_x, x)
    assert sat.basis == j.basis and degree(sat) == 6

    with_origin = [v * f for f in clean for v in (x, y)]
    gb = groebner(with_origin)
    assert degree(gb) == 7  # J*(x, y) = J ∩ (x, y) since the origin is not a root of J
    sat = saturate(with_origin, x)
    assert sat.basis == j.basis


def test_saturation_removes_a_planted_root_on_the_hyperplane():
    """A planted root with x0 = 0 is removed by saturating by x0; the other planted roots stay."""
    prime = 65521
    polys, points = planted_root_system(2, (2, 2), 2, prime, seed=8)
    ring = polys[0].ring
    x, y = ring.gens()
    # move the first planted root onto x0 = 0 by the substitution x0 -> x0 + a
    a = points[0][0]
    moved = []
    for f in polys:
        g = ring.zero()
        for e, c in f.terms():
            g = g + ((x + ring.one().scale(a)) ** e[0]) * (y ** e[1]) * c
        moved.append(g)
    shift = [((pt[0] - a) % prime, pt[1]) for pt in points]
    assert all(g.evaluate(shift[0]) == 0 for g in moved) and shift[0][0] == 0
    before = groebner(moved)
    assert degree(before) == 4
    sat = saturate(moved, x)
    assert degree(sat) == 3
    for g in sat.basis:
        assert g.evaluate(shift[1]) == 0
    assert any(g.evaluate(shift[0]) != 0 for g in sat.basis)


def test_saturation_of_the_unit_ideal_and_by_a_unit():
    ring = Ring(["x", "y"], 32003)
    x, y = ring.gens()
    # every root has x = 0: the saturation is the unit ideal
    assert saturate([x, y**2 - ring.one()], x).is_unit
    # saturating by a constant changes nothing
    polys = [x**2 - y, y**2 - x - ring.one()]
    assert saturate(polys, ring.one().scale(5)).basis == groebner(polys).basis


@pytest.mark.parametrize("system, order", [(katsura(2), "lex"), (katsura(3), "lex"), (katsura(3), "block:2,2")])
def test_fglm_equals_f4_in_the_target_order(system, order):
    """FGLM from grevlex gives exactly the reduced basis F4 computes directly in the target order."""
    gb = groebner(system)
    target = gb.ring.with_order(order)
    direct = groebner([target.from_terms(f.terms()) for f in system])
    converted = fglm(gb, target)
    assert [str(g) for g in converted.basis] == [str(g) for g in direct.basis]
    assert degree(converted) == degree(gb)


def test_fglm_lex_katsura4_shape_and_sympy():
    """katsura-4 in lex (16 solutions): a shape basis, equal to sympy's lex basis mod p."""
    system = katsura(4)
    ring = system[0].ring
    lex = fglm(groebner(system), ring.with_order("lex"))
    assert len(lex.basis) == 5 and degree(lex) == 16
    gens = sympy.symbols(ring.variables)
    p = ring.prime

    def expr(f: Poly):
        return sum(c * sympy.prod(x**e for x, e in zip(gens, exps)) for exps, c in f.terms())

    def normalised(poly: sympy.Poly) -> dict:
        return {m: int(c) % p for m, c in poly.monic().as_dict().items()}

    ref = sympy.groebner([expr(f) for f in system], *gens, order="lex", modulus=p)
    ours = [normalised(sympy.Poly(expr(g), *gens, modulus=p)) for g in lex.basis]
    theirs = [normalised(sympy.Poly(g, *gens, modulus=p)) for g in ref.exprs]
    assert sorted(map(sorted, map(dict.items, ours))) == sorted(map(sorted, map(dict.items, theirs)))


def test_count_standard_monomials_without_listing():
    """The count agrees with the listing, and 2^40 solutions in 40 variables are counted at once."""
    from analysis.engine import quotient

    for system in (katsura(4), cyclic(5), katsura(6)):
        gb = groebner(system)
        listed = len(standard_monomials(gb))
        assert count_standard_monomials(gb) == listed  # by waves: the box of the pure powers is small
        with pytest.MonkeyPatch.context() as mp:  # by the memoised split
            mp.setattr(quotient, "WAVE_COUNT_LIMIT", 0)
            assert count_standard_monomials(gb) == listed
        # a box larger than the limit: waves while the count stays within it, else the memoised split
        for limit in (listed, listed - 1):
            with pytest.MonkeyPatch.context() as mp:
                mp.setattr(quotient, "WAVE_COUNT_LIMIT", limit)
                assert count_standard_monomials(gb) == listed
    ring = Ring([f"x{i}" for i in range(40)], 65521)
    gb = groebner([x**2 - 1 for x in ring.gens()])
    assert count_standard_monomials(gb) == 2**40
    with pytest.raises(NotZeroDimensional):
        count_standard_monomials(groebner([ring.gen(0) * ring.gen(1)]))
