"""Tests for analysis.engine.f4: reduced Gröbner bases against sympy, known degrees, backends, statistics.

The reference is ``sympy.groebner(..., modulus=p)``; sympy prints GF(p) coefficients in the symmetric
range (-p/2, p/2], so both sides are compared as sets of monic polynomials of our ring (coefficients
in [0, p)). Every randomised case is named by (prime, kind, seed) so a failure can be reproduced with
:func:`analysis.sweeps.benchmarks.random_small_system`.
"""
from __future__ import annotations

import pytest
import sympy
from sympy.polys.orderings import ProductOrder, grevlex

from analysis.sweeps.benchmarks import (
    SYSTEM_KINDS,
    bezout_number,
    dense_random_system,
    planted_root_system,
    random_small_system,
)
from analysis.engine.f4 import F4Options, GroebnerResult, RoundStats, groebner
from analysis.engine.linalg import BACKENDS, MatrixTooLarge
from analysis.engine.msolve import INSTALL_HINT, find_msolve, groebner_msolve
from analysis.engine.quotient import degree, dimension, is_zero_dimensional, standard_monomials
from analysis.engine.ring import Poly, Ring
from analysis.engine.systems import cyclic, katsura

PRIMES = (32003, 65521, 2147483647)
SEEDS = range(6)
CASES = [(p, kind, seed) for p in PRIMES for kind in SYSTEM_KINDS for seed in SEEDS]  # 90 systems


def case_nvars(seed: int) -> int:
    """2, 3 or 4 variables, cycling with the seed."""
    return 2 + seed % 3


# ----------------------------------------------------------------------------------------------
# helpers
# ----------------------------------------------------------------------------------------------
def sympy_basis(ring: Ring, polys, order="grevlex") -> set[Poly]:
    """sympy's reduced Gröbner basis over GF(p), as monic polynomials of ring."""
    syms = sympy.symbols(ring.variables)
    gb = sympy.groebner([ring.to_sympy(f) for f in polys], *syms, modulus=ring.prime, order=order)
    return {ring.from_sympy(e).monic() for e in gb.exprs}


def show(polys) -> list[str]:
    return [str(f) for f in polys]


def assert_reduced(result: GroebnerResult) -> None:
    """Reduced Gröbner basis shape: monic, no leading monomial divides another's term."""
    ring = result.ring
    lms = result.leading_monomials
    for g in result.basis:
        assert g.lc == 1, f"not monic: {g}"
        for h in result.basis:
            if h is g:
                continue
            for k in g.mons:
                assert not ring.divides(h.lm, k), (
                    f"lm {ring.monomial_str(h.lm)} of {h} divides the term {ring.monomial_str(k)} of {g}"
                )
    assert len(set(lms)) == len(lms)


def run_both(polys) -> dict[str, GroebnerResult]:
    return {be: groebner(polys, F4Options(backend=be)) for be in BACKENDS}


# ----------------------------------------------------------------------------------------------
# agreement with sympy (grevlex), both backends
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("prime,kind,seed", CASES)
def test_random_system_matches_sympy_grevlex(prime, kind, seed):
    nvars = case_nvars(seed)
    ring, polys = random_small_system(seed, prime, kind, nvars=nvars)
    where = f"random_small_system(seed={seed}, prime={prime}, kind={kind!r}, nvars={nvars}): {show(polys)}"
    expected = sympy_basis(ring, polys)
    results = run_both(polys)
    assert results["python"].basis == results["numpy"].basis, f"backends disagree on {where}"
    ours = results["numpy"]
    assert set(ours.basis) == expected, f"{where}\n ours  {show(ours.basis)}\n sympy {show(expected)}"
    assert_reduced(ours)
    if kind == "inconsistent":
        assert ours.is_unit and [str(g) for g in ours.basis] == ["1"]
    if kind == "underdetermined":
        assert dimension(ours) >= 1


def test_random_cases_cover_unit_and_positive_dimensional_ideals():
    """The kinds really produce unit ideals and positive-dimensional ideals besides finite ones."""
    seen = set()
    for prime, kind, seed in CASES:
        if prime != 32003:
            continue
        ring, polys = random_small_system(seed, prime, kind, nvars=case_nvars(seed))
        gb = groebner(polys)
        d = dimension(gb)
        seen.add("unit" if d < 0 else "finite" if d == 0 else "positive")
    assert seen == {"unit", "finite", "positive"}


def test_junk_generators_are_ignored():
    """Zero polynomials, exact and scaled duplicates do not change the basis."""
    ring = Ring(["x", "y", "z"], 65521)
    x, y, z = ring.gens()
    one = ring.one()
    clean = [x * y - z, y**2 + 3 * x - one, z**2 - x]
    junk = [ring.zero(), clean[1], clean[0].scale(7), ring.zero(), clean[2] + clean[0].scale(5)] + clean
    for be in BACKENDS:
        a = groebner(clean, F4Options(backend=be))
        b = groebner(junk, F4Options(backend=be))
        assert a.basis == b.basis
        assert set(a.basis) == sympy_basis(ring, clean)


def test_degenerate_inputs():
    ring = Ring(["x", "y"], 32003)
    x, y = ring.gens()
    for be in BACKENDS:
        opts = F4Options(backend=be)
        assert groebner([ring.zero()], opts).basis == ()
        assert groebner([ring.zero(), ring.zero()], opts).basis == ()
        unit = groebner([x**2 - y, ring.one().scale(5)], opts)
        assert unit.is_unit and unit.basis == (ring.one(),)
        assert groebner([x * y + ring.one(), x * y + ring.one().scale(2)], opts).basis == (ring.one(),)
        assert groebner([x.scale(3)], opts).basis == (x,)
    with pytest.raises(ValueError):
        groebner([])
    with pytest.raises(ValueError):
        groebner([x], F4Options(backend="no-such-backend"))
    with pytest.raises(ValueError):
        groebner([x, Ring(["x", "y"], 65521).gen(0)])


def test_univariate_ideal_is_generated_by_the_gcd():
    p = 65521
    ring = Ring(["x"], p)
    x = ring.gen(0)
    one = ring.one()
    common = (x - one.scale(3)) * (x**2 + one.scale(5))
    f, g = common * (x**3 - one.scale(7)), common * (x + one.scale(11)) ** 2
    t = sympy.Symbol("x")
    expected = ring.from_sympy(sympy.Poly(sympy.gcd(ring.to_sympy(f), ring.to_sympy(g), modulus=p), t).as_expr()).monic()
    for be in BACKENDS:
        assert groebner([f, g], F4Options(backend=be)).basis == (common.monic(),) == (expected,)


def test_degrees_beyond_the_narrow_monomial_codes():
    # 16 variables leave 4 bits per field of the packed monomial codes (degrees up to 15); the pair
    # (x0^8, x0 x1^8) has degree 16, so the run is repeated with wide codes
    ring = Ring([f"x{i}" for i in range(16)], 32003)
    x = ring.gens()
    polys = [x[0] ** 8 + x[1] + 1, x[0] * x[1] ** 8 + x[2]]
    results = run_both(polys)
    assert results["python"].basis == results["numpy"].basis
    assert max(r.degree for r in results["numpy"].rounds) > 15
    assert set(results["numpy"].basis) == sympy_basis(ring, polys)


def test_reduced_basis_is_minimal_when_one_input_lm_divides_another():
    """x^2 | lm(x^2*y + y^3): the reduced basis is {x^2, y^3}, not {x^2, x^2*y, y^3}."""
    ring = Ring(["x", "y"], 32003)
    x, y = ring.gens()
    polys = [x**2, x**2 * y + y**3]
    assert sympy_basis(ring, polys) == {x**2, y**3}
    for be in BACKENDS:
        gb = groebner(polys, F4Options(backend=be))
        assert set(gb.basis) == {x**2, y**3}, f"backend {be}: {show(gb.basis)}"


@pytest.mark.parametrize("name,polys", [("katsura-5", katsura(5)), ("cyclic-5", cyclic(5))])
def test_classic_bases_are_minimal(name, polys):
    """Reduced bases of classic systems: monic, no leading monomial divides a term of another element."""
    gb = groebner(polys)
    assert_reduced(gb)


# ----------------------------------------------------------------------------------------------
# lex and block orders
# ----------------------------------------------------------------------------------------------
ORDER_CASES = [(p, kind, seed) for p in (32003, 65521) for kind in SYSTEM_KINDS for seed in range(2)]


@pytest.mark.parametrize("prime,kind,seed", ORDER_CASES)
def test_lex_matches_sympy(prime, kind, seed):
    ring, polys = random_small_system(seed, prime, kind, nvars=3, max_degree=2, order="lex")
    expected = sympy_basis(ring, polys, order="lex")
    results = run_both(polys)
    assert results["python"].basis == results["numpy"].basis
    assert set(results["numpy"].basis) == expected, f"lex seed={seed} prime={prime} kind={kind}: {show(polys)}"


@pytest.mark.parametrize("prime,kind,seed", ORDER_CASES)
def test_block_order_matches_sympy_product_order(prime, kind, seed):
    ring, polys = random_small_system(seed, prime, kind, nvars=3, max_degree=2, order="block:1,2")
    order = ProductOrder((grevlex, lambda m: m[:1]), (grevlex, lambda m: m[1:]))
    expected = sympy_basis(ring, polys, order=order)
    results = run_both(polys)
    assert results["python"].basis == results["numpy"].basis
    assert set(results["numpy"].basis) == expected, f"block seed={seed} prime={prime} kind={kind}: {show(polys)}"


def test_block_order_eliminates_the_parameter():
    """(x - t^2, y - t^3) with t eliminated: the basis meets GF(p)[x, y] in the cusp (x^3 - y^2)."""
    ring = Ring(["t", "x", "y"], 32003, "block:1,2")
    t, x, y = ring.gens()
    gb = groebner([x - t**2, y - t**3])
    free = [g for g in gb.basis if all(e[0] == 0 for e, _ in g.terms())]
    assert free == [x**3 - y**2]


@pytest.mark.parametrize("seed", range(3))
def test_block_order_elimination_ideal_matches_sympy_lex(seed):
    """Elements free of the first block generate I ∩ GF(p)[rest] (Cox-Little-O'Shea, elimination thm)."""
    prime = 65521
    ring, polys = random_small_system(seed, prime, "underdetermined", nvars=3, max_degree=2, order="block:1,2")
    # positive-dimensional in 3 variables with 2 equations: the elimination ideal is principal or unit
    gb = groebner(polys)
    ours = {ring.from_terms(g.terms()) for g in gb.basis if all(e[0] == 0 for e, _ in g.terms())}
    # reference: lex basis elements free of x0 generate the same elimination ideal; reduce in grevlex
    lex_ring = ring.with_order("lex")
    lex = sympy_basis(lex_ring, [lex_ring.from_terms(f.terms()) for f in polys], order="lex")
    free = [f for f in lex if all(e[0] == 0 for e, _ in f.terms())]
    sub = Ring(ring.variables[1:], prime)
    if free:
        expected = sympy_basis(sub, [sub.from_terms((e[1:], c) for e, c in f.terms()) for f in free])
    else:
        expected = set()
    assert {sub.from_terms((e[1:], c) for e, c in f.terms()) for f in ours} == expected, f"seed {seed}"


# ----------------------------------------------------------------------------------------------
# known degrees
# ----------------------------------------------------------------------------------------------
def _root_of_unity(order: int, p: int) -> int:
    """A primitive order-th root of unity in GF(p) (requires order | p - 1)."""
    assert (p - 1) % order == 0
    for g in range(2, p):
        w = pow(g, (p - 1) // order, p)
        if all(pow(w, order // q, p) != 1 for q in sympy.primefactors(order)):
            return w
    raise AssertionError("no primitive root found")


def cyclic_root(n: int, p: int) -> tuple[int, ...]:
    """The root x_i = c w^i of cyclic-n (w a primitive n-th root of unity, c^n w^(n(n-1)/2) = 1)."""
    w = _root_of_unity(n, p)
    target = pow(pow(w, n * (n - 1) // 2, p), -1, p)
    # c ranges over the 2n-th roots of unity, which contain every solution of c^n = +-1
    z = _root_of_unity(2 * n, p)
    for k in range(2 * n):
        c = pow(z, k, p)
        if pow(c, n, p) == target:
            return tuple(c * pow(w, i, p) % p for i in range(n))
    raise AssertionError("no scaling found")


def assert_root(gb: GroebnerResult, point) -> None:
    for g in gb.basis:
        assert g.evaluate(point) == 0, f"{g} does not vanish at the known root {point}"


@pytest.mark.parametrize(
    "name,builder,expected,root",
    [
        ("katsura-5", lambda p: katsura(5, p), 32, lambda p: (1,) + (0,) * 5),
        ("katsura-6", lambda p: katsura(6, p), 64, lambda p: (1,) + (0,) * 6),
        ("cyclic-5", lambda p: cyclic(5, p), 70, lambda p: cyclic_root(5, p)),
        ("cyclic-6", lambda p: cyclic(6, p), 156, lambda p: cyclic_root(6, p)),
    ],
)
def test_classic_degrees(name, builder, expected, root):
    p = 65521  # p - 1 = 2^4 3^2 5 7 13: the roots of unity of the cyclic roots exist
    gb = groebner(builder(p))
    assert is_zero_dimensional(gb)
    assert degree(gb) == expected
    assert_root(gb, root(p))


@pytest.mark.parametrize("name,builder", [("katsura-5", lambda p: katsura(5, p)), ("cyclic-5", lambda p: cyclic(5, p))])
def test_degree_agrees_across_primes(name, builder):
    a, b = groebner(builder(32003)), groebner(builder(65521))
    assert degree(a) == degree(b)
    assert [a.ring.exps(k) for k in a.leading_monomials] == [b.ring.exps(k) for k in b.leading_monomials]


@pytest.mark.parametrize(
    "nvars,degrees,seed", [(2, (3, 4), 0), (3, (2, 3, 3), 1), (3, (2, 2, 2), 2), (4, (2, 2, 2, 2), 3)]
)
def test_dense_generic_system_has_bezout_degree(nvars, degrees, seed):
    degs = []
    for p in (32003, 65521):
        gb = groebner(dense_random_system(nvars, degrees, p, seed=seed))
        degs.append(degree(gb))
    assert degs == [bezout_number(degrees)] * 2, f"seed {seed}"


def test_planted_roots_vanish_on_the_basis():
    polys, points = planted_root_system(3, (2, 3, 3), 3, 65521, seed=4)
    gb = groebner(polys)
    assert degree(gb) == 18
    for pt in points:
        assert_root(gb, pt)


@pytest.mark.parametrize(
    "label,make,expected",
    [
        # affine twisted cubic (y - x^2, z - x^3): a curve
        ("twisted cubic", lambda r: [r.gen(1) - r.gen(0) ** 2, r.gen(2) - r.gen(0) ** 3], 1),
        # plane x = 0 union the line y = z = 0: dimension of the largest component
        ("plane and line", lambda r: [r.gen(0) * r.gen(1), r.gen(0) * r.gen(2)], 2),
        ("one dense surface", lambda r: dense_random_system(3, (3,), r.prime, seed=5, ring=r), 2),
        ("two dense surfaces", lambda r: dense_random_system(3, (2, 2), r.prime, seed=6, ring=r), 1),
    ],
)
def test_positive_dimensional_examples(label, make, expected):
    for p in (32003, 65521):
        ring = Ring(["x0", "x1", "x2"], p)
        gb = groebner(make(ring))
        assert not is_zero_dimensional(gb), label
        assert dimension(gb) == expected, label


def test_dense_underdetermined_in_four_variables_has_dimension_two():
    for p in (32003, 65521):
        gb = groebner(dense_random_system(4, (2, 2), p, seed=7))
        assert dimension(gb) == 2


# ----------------------------------------------------------------------------------------------
# statistics and limits
# ----------------------------------------------------------------------------------------------
def test_round_statistics_agree_across_backends_and_with_the_basis():
    """Every backend (the pure-Python reference, numpy, the sparse kernel) reduces the same matrices to the
    same ranks: identical round statistics; the new elements of the rounds cover the basis."""
    runs = {b: groebner(katsura(5), F4Options(backend=b)) for b in ("python", "numpy", "sparse")}
    strip = {b: [(r.degree, r.pairs, r.rows, r.cols, r.density, r.new, r.zero_reductions) for r in gb.rounds]
             for b, gb in runs.items()}
    assert strip["python"] == strip["numpy"] == strip["sparse"]
    gb = runs["python"]
    assert len(standard_monomials(gb)) == 32  # katsura-5: 2^5 solutions
    # every element of the reduced basis that is not an input polynomial was new in some round
    assert sum(r.new for r in gb.rounds) >= len(gb.basis) - len(katsura(5))
    assert gb.rounds, "no rounds recorded"
    for r in gb.rounds:
        assert isinstance(r, RoundStats)
        assert r.degree >= 1 and r.pairs >= 1
        assert r.rows >= 1 and r.cols >= 1
        assert 0.0 < r.density <= 1.0
        assert r.new >= 0 and r.zero_reductions >= 0
        assert r.new + r.zero_reductions <= r.rows
        assert r.seconds >= 0.0
    assert sum(r.seconds for r in gb.rounds) <= gb.seconds + 1e-9
    assert gb.max_matrix in {(r.rows, r.cols) for r in gb.rounds}
    degrees = [r.degree for r in gb.rounds]
    assert min(degrees) >= 2  # katsura's pairs start in degree 2


def test_matrix_cap_raises():
    with pytest.raises(MatrixTooLarge):
        groebner(katsura(5), F4Options(max_matrix_cells=50))


def test_verbose_prints_one_line_per_round(capsys):
    gb = groebner(cyclic(5), F4Options(verbose=True))
    err = capsys.readouterr().err
    assert len([line for line in err.splitlines() if line.startswith("[f4]")]) == len(gb.rounds)


# ----------------------------------------------------------------------------------------------
# cross-check with msolve (optional binary)
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name,polys", [("katsura-6", katsura(6)), ("cyclic-6", cyclic(6))])
def test_matches_msolve(name, polys):
    exe = find_msolve()
    if exe is None:
        pytest.skip(f"msolve not installed ({INSTALL_HINT})")
    expected = groebner_msolve(polys, exe).basis
    ours = groebner(polys)
    assert len(ours.basis) == len(expected), f"{name}: {len(ours.basis)} elements, msolve {len(expected)}"
    assert ours.basis == expected


def test_exponents_up_to_the_parser_limit():
    """The parser documents total degree 65535; exponents from 2^15 on need 32-bit divisibility fields."""
    R = Ring(["x", "y"], 65521)
    x, y = R.gens()
    gb = groebner([x**32768 - 1, y - 1, x * y**2 - x])
    assert degree(gb) == 32768
    gb = groebner([x**65535 - 1, y - 1])
    assert degree(gb) == 65535


def test_memory_cap_stops_before_allocating():
    """F4 directly in lex on katsura-4 swells (it once outgrew 24 GB); the memory estimate stops it."""
    from analysis.engine.systems import katsura

    lex = katsura(4)[0].ring.with_order("lex")
    with pytest.raises(MatrixTooLarge, match="MiB, above the memory cap of 100 MiB"):
        groebner([lex.from_terms(f.terms()) for f in katsura(4)], F4Options(max_memory=100 << 20))


def test_default_caps_count_memory_not_cells():
    """``x^300 + y, x + y + 1``: one 45151 x 45451 matrix (2.05e9 cells, five times the old dense-shape
    cap) with 135k nonzeros; by default only its memory estimate counts, so it is answered."""
    from analysis.engine.f4 import matrix_memory

    R = Ring(["x", "y"], 65521)
    x, y = R.gens()
    assert F4Options().max_matrix_cells is None and F4Options().max_memory is None
    gb = groebner([x**300 + y, x + y + 1])
    assert degree(gb) == 300 and gb.max_matrix[0] * gb.max_matrix[1] > 2_000_000_000
    assert matrix_memory(45151, 45451, 3 * 45151, dense=False) < 10 << 20  # the sparse estimate: a few MiB
    assert matrix_memory(45151, 45451, 3 * 45151, dense=True) > 40 << 30  # dense, it would not fit


def test_default_memory_cap_is_a_share_of_available_memory(monkeypatch):
    """The default cap is MEMORY_SHARE of the available memory read at the start of the run."""
    from analysis.engine import f4

    monkeypatch.setattr(f4, "available_memory", lambda: 1 << 20)
    assert f4.default_max_memory() == int(f4.MEMORY_SHARE * (1 << 20))
    with pytest.raises(MatrixTooLarge, match="above the memory cap of 768 KiB .75% of the machine's available memory"):
        groebner(katsura(7))  # its largest matrix needs about 873 KiB
    monkeypatch.setattr(f4, "available_memory", lambda: None)
    assert f4.default_max_memory() == f4.FALLBACK_MAX_MEMORY


@pytest.mark.parametrize("name", ["katsura-6", "cyclic-6", "tdoa-9r3s-C8", "dense-4x(2,2,3,3)"])
def test_pair_update_by_degree_matches_cube(name, monkeypatch):
    """The two ways of choosing the new pairs of a round (all partner pairs at once, or degree by degree
    against the minimal lcms) give the same pairs: same rounds, same basis."""
    import analysis.engine.f4 as f4
    from analysis.sweeps.benchmarks import benchmark_system

    polys = benchmark_system(name)
    monkeypatch.setattr(f4, "CUBE_CELLS", 1 << 62)
    cube = groebner(polys)
    monkeypatch.setattr(f4, "CUBE_CELLS", 0)
    by_degree = groebner(polys)
    assert by_degree.basis == cube.basis
    shape = [(r.degree, r.pairs, r.rows, r.cols, r.new, r.zero_reductions) for r in cube.rounds]
    assert [(r.degree, r.pairs, r.rows, r.cols, r.new, r.zero_reductions) for r in by_degree.rounds] == shape


def test_matrices_assembled_in_blocks_give_the_same_basis(monkeypatch):
    """F4 matrices converted a few entries at a time (block edges inside rows) give the same rounds."""
    import analysis.engine.f4 as f4
    from analysis.sweeps.benchmarks import benchmark_system

    polys = benchmark_system("katsura-5")
    whole = groebner(polys)
    monkeypatch.setattr(f4, "_ASSEMBLE_BLOCK", 7)
    blocks = groebner(polys)
    assert blocks.basis == whole.basis
    assert [(r.rows, r.cols, r.new) for r in blocks.rounds] == [(r.rows, r.cols, r.new) for r in whole.rounds]


@pytest.mark.parametrize("prime,kind,seed", [(p, kind, seed) for p in PRIMES[:2] for kind in SYSTEM_KINDS for seed in range(3)]
                         + [(65521, "katsura", 6), (65521, "cyclic", 5)])
def test_c_kernels_give_the_same_rounds_as_numpy(prime, kind, seed, monkeypatch):
    """The C kernels (pair update, lookup, reduction: analysis/engine/f4_kernels.c) and the numpy code they replace
    give the same pairs round by round (degree, pairs, matrix shape, new elements) and the same basis."""
    from analysis.engine import native

    if native.kernel() is None:
        pytest.skip("no C compiler here: the C kernels cannot be built")
    if kind == "katsura":
        polys = katsura(seed, prime)
    elif kind == "cyclic":
        polys = cyclic(seed, prime)
    else:
        polys = random_small_system(seed, prime, kind, nvars=case_nvars(seed))[1]

    def rounds(gb):
        return [(r.degree, r.pairs, r.rows, r.cols, r.new, r.zero_reductions) for r in gb.rounds]

    with_c = groebner(polys)
    monkeypatch.setattr(native, "_LOADED", [None])
    without = groebner(polys)
    assert rounds(with_c) == rounds(without), f"{kind} seed {seed} p {prime}"
    assert with_c.basis == without.basis


@pytest.mark.parametrize("prime", [65521, 1073741827, 2147483647])
def test_threads_give_the_same_basis_at_every_prime(prime):
    """F4 with the C kernel on two threads, on one, and with the numpy backend (dense products, no C)
    gives the same rounds and basis, at a 16-bit prime and at 30- and 31-bit ones (bounded accumulators)."""
    from analysis.engine import native

    if native.kernel() is None:
        pytest.skip("no C compiler here: the C kernels cannot be built")
    polys = katsura(6, prime)

    def rounds(gb):
        return [(r.degree, r.pairs, r.rows, r.cols, r.new, r.zero_reductions) for r in gb.rounds]

    one, two = groebner(polys, F4Options(threads=1)), groebner(polys, F4Options(threads=2))
    dense = groebner(polys, F4Options(backend="numpy"))
    assert one.basis == two.basis == dense.basis
    assert rounds(one) == rounds(two) == rounds(dense)
    assert degree(one) == 64


def test_threads_must_be_positive():
    with pytest.raises(ValueError, match="threads must be a positive integer"):
        F4Options(threads=0)


@pytest.mark.parametrize("name", ["cyclic-7", "tdoa-6r3s-A1B2C5"])
@pytest.mark.parametrize("prime", [65521, 2147483647])
def test_threads_give_the_same_basis_on_racing_systems(name, prime):
    """Systems whose F4 matrices make the threads race for new pivots in part of a block (a row that won
    its pivot and one that lost it, side by side; before the fix the winner was taken again and the rows
    after it lost: cyclic-7 and tdoa-6r3s-A1B2C5 differed in 3 of 3 runs): two threads, three runs, the
    one-thread basis every time."""
    from analysis.engine import native
    from analysis.sweeps.benchmarks import benchmark_system

    if native.kernel() is None:
        pytest.skip("no C compiler here: the C kernels cannot be built")
    polys = benchmark_system(name, prime)
    one = groebner(polys, F4Options(threads=1))
    for _ in range(3):
        assert groebner(polys, F4Options(threads=2)).basis == one.basis


@pytest.mark.parametrize("name", ["cyclic-7", "katsura-8", "tdoa-6r3s-A1B2C5"])
@pytest.mark.parametrize("prime", [65521, 2147483647])
def test_threaded_preprocessing_and_pair_update_give_the_same_rounds(name, prime):
    """The symbolic preprocessing (the codes seen shared among the threads, reducer search shared out) and
    the pair update (activity spans, the new pairs of each element, criterion B: each pass shared out) on
    2 and 3 threads, forced onto the threaded paths however small the work (native.share_small_work), give
    the rounds and basis of one thread, minimal and reduced."""
    from analysis.engine import native
    from analysis.sweeps.benchmarks import benchmark_system

    if native.kernel() is None:
        pytest.skip("no C compiler here: the C kernels cannot be built")
    polys = benchmark_system(name, prime)

    def rounds(gb):
        return [(r.degree, r.pairs, r.rows, r.cols, r.new, r.zero_reductions) for r in gb.rounds]

    for reduced in (False, True):
        one = groebner(polys, F4Options(threads=1, reduced=reduced))
        with native.share_small_work():
            for threads in (1, 2, 3):
                many = groebner(polys, F4Options(threads=threads, reduced=reduced))
                assert rounds(many) == rounds(one), f"{name} p {prime} threads {threads}"
                assert many.basis == one.basis


@pytest.mark.parametrize("prime,kind,seed", [(p, kind, seed) for p in (32003, 2147483647) for kind in SYSTEM_KINDS
                                             for seed in range(3)])
def test_minimal_basis_has_the_leading_ideal_of_the_reduced_one(prime, kind, seed):
    """F4Options(reduced=False): a minimal Gröbner basis of the same ideal (monic, no leading monomial dividing
    another's), with the reduced basis's leading monomials, whose tail reduction (interreduce) is the reduced
    basis; with and without the linear substitution, on the C kernels and the numpy path."""
    from analysis.engine.f4 import interreduce

    _, polys = random_small_system(seed, prime, kind, nvars=case_nvars(seed))
    for substitute in (False, True):
        for backend in ("auto", "numpy"):
            reduced = groebner(polys, F4Options(backend=backend, linear_substitution=substitute))
            minimal = groebner(polys, F4Options(backend=backend, linear_substitution=substitute, reduced=False))
            assert reduced.reduced and not minimal.reduced
            assert minimal.leading_monomials == reduced.leading_monomials
            assert all(g.coeffs[0] == 1 for g in minimal.basis)
            ring = minimal.ring
            assert not any(ring.divides(a, b) for a in minimal.leading_monomials for b in minimal.leading_monomials
                           if a != b)
            assert set(interreduce(list(minimal.basis))) == set(reduced.basis)
            assert dimension(minimal) == dimension(reduced)
            if is_zero_dimensional(reduced):
                assert degree(minimal) == degree(reduced)


def test_minimal_basis_keeps_unreduced_tails():
    """katsura-6's minimal basis is not its reduced basis (the tails F4 left are not fully reduced): the option
    skips a real step."""
    from analysis.engine.f4 import interreduce

    minimal = groebner(katsura(6), F4Options(reduced=False))
    assert set(minimal.basis) != set(groebner(katsura(6)).basis)
    assert set(interreduce(list(minimal.basis))) == set(groebner(katsura(6)).basis)
