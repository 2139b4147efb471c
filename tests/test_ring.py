"""Rings, monomial keys and polynomial arithmetic over GF(p)."""
import numpy as np
import pytest

from analysis.engine.linalg import matmul_mod
from analysis.engine.ring import BadPrime, CodeOverflow, MonomialCodes, Ring, check_prime


@pytest.mark.parametrize("order", ["grevlex", "lex", "block:2,3"])
def test_keys_are_additive_order_preserving_and_decode(order):
    ring = Ring(["a", "b", "c", "d", "e"], 65521, order)
    rng = np.random.default_rng(0)
    exps = [tuple(int(v) for v in rng.integers(0, 9, 5)) for _ in range(200)]
    keys = [ring.key(e) for e in exps]
    fresh = Ring(ring.variables, ring.prime, order)  # empty cache: forces decoding
    assert [fresh.exps(k) for k in keys] == exps
    assert [tuple(r) for r in ring.decode_many(keys).tolist()] == exps
    for (e1, k1), (e2, k2) in zip(zip(exps, keys), zip(exps[1:], keys[1:])):
        assert ring.key(tuple(x + y for x, y in zip(e1, e2))) == k1 + k2


@pytest.mark.parametrize(
    "nvars,order", [(5, "grevlex"), (5, "lex"), (9, "block:4,5"), (12, "grevlex"), (70, "grevlex")]
)
def test_monomial_codes_round_trip_order_and_add_like_keys(nvars, order):
    ring = Ring([f"x{i}" for i in range(nvars)], 65521, order)
    rng = np.random.default_rng(nvars)
    exps = rng.integers(0, 3, (300, nvars)) * (rng.random((300, nvars)) < 4 / nvars)
    keys = [ring.key(tuple(int(v) for v in e)) for e in exps]
    for wide in (False, True):
        codes = MonomialCodes(ring, wide)
        assert codes.wide == (wide or nvars > 64)
        c = codes.from_keys(keys)
        assert codes.to_keys(c) == keys
        assert (codes.decode(c) == exps).all() and (codes.encode(exps) == c).all()
        assert (codes.degrees(c) == exps.sum(axis=1)).all()
        assert [keys[i] for i in np.argsort(c, kind="stable")] == sorted(keys)
        assert codes.to_keys(c[:-1] + c[1:]) == [a + b for a, b in zip(keys[:-1], keys[1:])]


def test_narrow_codes_refuse_degrees_they_cannot_hold():
    ring = Ring([f"x{i}" for i in range(16)], 65521)  # 4-bit fields: degrees up to 15
    codes = MonomialCodes(ring)
    assert codes.max_degree == 15
    codes.from_keys([ring.key((15,) + (0,) * 15)])
    with pytest.raises(CodeOverflow):
        codes.from_keys([ring.key((16,) + (0,) * 15)])
    assert MonomialCodes(ring, wide=True).from_keys([ring.key((16,) + (0,) * 15)]).dtype == object


def test_grevlex_and_lex_compare_like_sympy():
    import sympy
    from sympy.polys.orderings import grevlex, lex

    rng = np.random.default_rng(1)
    exps = [tuple(int(v) for v in rng.integers(0, 4, 4)) for _ in range(60)]
    for name, ref in (("grevlex", grevlex), ("lex", lex)):
        ring = Ring(["w", "x", "y", "z"], 101, name)
        assert sorted(exps, key=ring.key) == sorted(exps, key=ref)


def test_arithmetic_with_integers_and_evaluation():
    ring = Ring(["x", "y"], 7)
    x, y = ring.gens()
    f = (x + 1) * (y - 2) + 3
    assert f.evaluate((2, 5)) == ((2 + 1) * (5 - 2) + 3) % 7
    assert (1 - x).evaluate((3, 0)) == (1 - 3) % 7
    assert str(ring.from_sympy("x**2 - 1/2")) == "x^2 + 3"


@pytest.mark.parametrize("p", [4, 2**31 + 11, 2**31, 1, 0, -7])
def test_bad_primes_are_rejected(p):
    with pytest.raises(BadPrime):
        check_prime(p)


@pytest.mark.parametrize("p", [2, 3, 2**31 - 1])
def test_every_prime_below_2_31_is_a_characteristic(p):
    assert check_prime(p) == p


def test_unknown_variable_is_named():
    ring = Ring(["x", "y"], 7)
    with pytest.raises(ValueError, match="unknown variable"):
        ring.from_sympy("x + q")


@pytest.mark.parametrize("p", [3, 65521, 1073741789, 2147483647])
def test_matmul_mod_is_exact(p):
    rng = np.random.default_rng(p % 1000)
    x = rng.integers(0, p, (12, 300))
    y = rng.integers(0, p, (300, 9))
    ref = [[sum(int(a) * int(b) for a, b in zip(x[i], y[:, j])) % p for j in range(9)] for i in range(12)]
    assert matmul_mod(x, y, p).tolist() == ref
