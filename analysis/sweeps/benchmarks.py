"""Seeded polynomial systems for tests and benchmarks, and a registry of named benchmark systems.

Generators (all seeded with ``numpy.random.default_rng(seed)``, exact over GF(p)):

* :func:`dense_random_system` - n dense polynomials in n variables of given degrees: generically
  zero-dimensional with exactly the Bézout number prod(d_i) of solutions (with multiplicity).
* :func:`planted_root_system` - dense polynomials forced to vanish at given random GF(p)-points (the
  coefficient vectors are drawn from the kernel of the evaluation map), so the roots are known.
* :func:`random_small_system` - small sparse systems of several kinds (square, over-/under-determined,
  inconsistent, with zero/duplicate/constant generators) for cross-checks against a reference CAS.

The registry :data:`BENCHMARK_SYSTEMS` maps a name to a builder ``prime -> list[Poly]``; benchmark
scripts read it and other modules (e.g. formulations of the paper's Table 2) extend it with
:func:`register_system`.

msolve's input and output (to compare with it) are :mod:`analysis.engine.msolve`'s.
"""
from __future__ import annotations

import math
from itertools import combinations_with_replacement
from typing import Callable, Literal, Sequence

import numpy as np

from ..engine.ring import Poly, Ring
from ..engine.systems import cyclic, eco, katsura

SystemKind = Literal["square", "overdetermined", "underdetermined", "inconsistent", "junk"]
SYSTEM_KINDS: tuple[str, ...] = ("square", "overdetermined", "underdetermined", "inconsistent", "junk")


def bezout_number(degrees: Sequence[int]) -> int:
    """Product of the degrees: the number of solutions of a generic square dense system."""
    return math.prod(degrees)


def monomials_up_to(nvars: int, degree: int) -> list[tuple[int, ...]]:
    """All exponent vectors in nvars variables of total degree <= degree (degree-major order)."""
    out = []
    for d in range(degree + 1):
        for combo in combinations_with_replacement(range(nvars), d):
            e = [0] * nvars
            for i in combo:
                e[i] += 1
            out.append(tuple(e))
    return out


def _variables(nvars: int) -> list[str]:
    return [f"x{i}" for i in range(nvars)]


def _coefficients(rng: np.random.Generator, prime: int, size: int, nonzero: bool = True) -> list[int]:
    low = 1 if nonzero else 0
    return [int(c) for c in rng.integers(low, prime, size=size, dtype=np.int64)]


def dense_random_system(
    nvars: int, degrees: Sequence[int], prime: int = 65521, seed: int = 0, ring: Ring | None = None
) -> list[Poly]:
    """len(degrees) dense polynomials with random nonzero coefficients on every monomial of degree <= d_i.

    For len(degrees) == nvars the system is zero-dimensional of degree :func:`bezout_number` (degrees)
    with probability close to 1 (the exceptions form a proper Zariski-closed set of coefficients).
    """
    rng = np.random.default_rng(seed)
    ring = ring or Ring(_variables(nvars), prime)
    if ring.nvars != nvars or ring.prime != prime:
        raise ValueError(f"ring {ring} does not match nvars={nvars}, prime={prime}")
    polys = []
    for d in degrees:
        mons = monomials_up_to(nvars, d)
        polys.append(ring.from_terms(zip(mons, _coefficients(rng, prime, len(mons)))))
    return polys


def _kernel_mod_p(rows: list[list[int]], ncols: int, prime: int) -> list[list[int]]:
    """A basis of {c : A c = 0 mod p} for the matrix A given by rows (FLINT nullspace)."""
    import flint

    if not rows:
        return [[int(i == j) for i in range(ncols)] for j in range(ncols)]
    a = flint.nmod_mat(len(rows), ncols, [v % prime for r in rows for v in r], prime)
    x, nullity = a.nullspace()
    return [[int(x[i, j]) for i in range(ncols)] for j in range(nullity)]


def planted_root_system(
    nvars: int, degrees: Sequence[int], npoints: int, prime: int = 65521, seed: int = 0
) -> tuple[list[Poly], list[tuple[int, ...]]]:
    """Dense random polynomials of the given degrees vanishing at npoints random points of GF(p)^n.

    Each polynomial is a random combination of a kernel basis of the evaluation map at the points, so
    it is generic among polynomials of degree <= d_i through the points. Returns (polys, points).
    Needs npoints < number of monomials of degree <= min(degrees).
    """
    rng = np.random.default_rng(seed)
    ring = Ring(_variables(nvars), prime)
    points = [tuple(int(v) for v in rng.integers(0, prime, size=nvars, dtype=np.int64)) for _ in range(npoints)]
    polys = []
    for d in degrees:
        mons = monomials_up_to(nvars, d)
        if npoints >= len(mons):
            raise ValueError(f"{npoints} points over-determine polynomials of degree {d} in {nvars} variables")
        evaluation = [[math.prod(pow(x, e, prime) for x, e in zip(pt, m)) % prime for m in mons] for pt in points]
        kernel = _kernel_mod_p(evaluation, len(mons), prime)
        weights = _coefficients(rng, prime, len(kernel))
        coeffs = [sum(w * v[i] for w, v in zip(weights, kernel)) % prime for i in range(len(mons))]
        polys.append(ring.from_terms(zip(mons, coeffs)))
    for f in polys:
        for pt in points:
            if f.evaluate(pt):
                raise AssertionError(f"planted point {pt} is not a root (seed {seed})")
    return polys, points


def _random_sparse_poly(ring: Ring, rng: np.random.Generator, max_degree: int, max_terms: int) -> Poly:
    mons = monomials_up_to(ring.nvars, max_degree)
    nterms = int(rng.integers(1, max_terms + 1))
    picks = rng.choice(len(mons), size=min(nterms, len(mons)), replace=False)
    # keep at least one non-constant term so that the polynomial is not accidentally a unit
    chosen = [mons[int(i)] for i in picks]
    if not any(any(m) for m in chosen):
        chosen.append(mons[int(rng.integers(1, len(mons)))])
    return ring.from_terms(zip(chosen, _coefficients(rng, ring.prime, len(chosen))))


def random_small_system(
    seed: int,
    prime: int = 32003,
    kind: SystemKind = "square",
    nvars: int | None = None,
    max_degree: int = 3,
    max_terms: int = 4,
    order: str = "grevlex",
) -> tuple[Ring, list[Poly]]:
    """A small sparse system for cross-checks against a reference CAS. Returns (ring, polys).

    kind
        "square": nvars polynomials; "overdetermined": nvars+1 or nvars+2 (often inconsistent);
        "underdetermined": nvars-1 (positive-dimensional); "inconsistent": contains f and f + c for a
        nonzero constant c (the unit ideal); "junk": a square system plus a zero polynomial, a scaled
        duplicate, an exact duplicate and a combination of two generators.
    nvars
        2..4 variables (drawn from the seed when None); degree <= max_degree, <= max_terms terms each.
    """
    if kind not in SYSTEM_KINDS:
        raise ValueError(f"unknown system kind {kind!r}; valid: {', '.join(SYSTEM_KINDS)}")
    rng = np.random.default_rng(seed)
    if nvars is None:
        nvars = int(rng.integers(2, 5))
    ring = Ring(_variables(nvars), prime, order)
    count = {
        "square": nvars,
        "overdetermined": nvars + int(rng.integers(1, 3)),
        "underdetermined": max(1, nvars - 1),
        "inconsistent": max(1, nvars - 1),
        "junk": nvars,
    }[kind]
    polys = [_random_sparse_poly(ring, rng, max_degree, max_terms) for _ in range(count)]
    if kind == "inconsistent":
        c = int(rng.integers(1, prime))
        polys.append(polys[0] + ring.one().scale(c))
    elif kind == "junk":
        a, b = (int(v) for v in rng.integers(1, prime, size=2))
        polys += [ring.zero(), polys[0].scale(a), polys[-1], polys[0].scale(a) + polys[1 % count].scale(b)]
        perm = rng.permutation(len(polys))
        polys = [polys[int(i)] for i in perm]
    return ring, polys


# ----------------------------------------------------------------------------------------------
# registry of named benchmark systems
# ----------------------------------------------------------------------------------------------
SystemBuilder = Callable[[int], list[Poly]]

BENCHMARK_SYSTEMS: dict[str, SystemBuilder] = {
    "katsura-5": lambda p: katsura(5, p),
    "katsura-6": lambda p: katsura(6, p),
    "katsura-7": lambda p: katsura(7, p),
    "katsura-8": lambda p: katsura(8, p),
    "cyclic-5": lambda p: cyclic(5, p),
    "cyclic-6": lambda p: cyclic(6, p),
    "cyclic-7": lambda p: cyclic(7, p),
    "dense-3x(2,3,3)": lambda p: dense_random_system(3, (2, 3, 3), p, seed=0),
    "dense-4x(2,2,3,3)": lambda p: dense_random_system(4, (2, 2, 3, 3), p, seed=0),
    "katsura-9": lambda p: katsura(9, p),
    "katsura-10": lambda p: katsura(10, p),
    "eco-10": lambda p: eco(10, p),
    "eco-11": lambda p: eco(11, p),
    **{f"quadrics-{n}": (lambda n: lambda p: dense_random_system(n, (2,) * n, p, seed=0))(n) for n in range(8, 12)},
}
"""Name -> builder(prime). Extend with :func:`register_system`."""


def positions_direct_system(m: int, n: int, prime: int = 65521, seed: int = 0) -> list[Poly]:
    """The direct formulation of the m r / n s problem (unknowns: gauge-fixed receiver and transmitter
    positions and offsets; :func:`analysis.formulations.positions.positions_system` ``"full"``) on its seed's
    consistent random instance, unsaturated (6r/3s: 18 unknowns, degree 720 = 4 x 180)."""
    from ..formulations.positions import gf_system, positions_system, sample_gf_positions

    system = positions_system(m, n, "full")
    data, _root = sample_gf_positions(m, n, prime, seed, "full")
    return gf_system(system, data, prime)[0]


def in_order(polys: Sequence[Poly], order: str) -> list[Poly]:
    """The polynomials in the same variables under another monomial order."""
    ring = polys[0].ring.with_order(order)
    return [ring.from_terms(f.terms()) for f in polys]


LEX_SYSTEMS = {
    "lex-katsura-6": lambda p: in_order(katsura(6, p), "lex"),
    "lex-cyclic-5": lambda p: in_order(cyclic(5, p), "lex"),
    "lex-curve-3x(3,3)": lambda p: in_order(dense_random_system(3, (3, 3), p, seed=0), "lex"),
}
"""Lex bases: two zero-dimensional ideals (grevlex then FGLM) and a curve (two dense cubics in three
unknowns: positive-dimensional, F4 in lex)."""
BENCHMARK_SYSTEMS.update(LEX_SYSTEMS)
BENCHMARK_SYSTEMS["positions-6r3s"] = lambda p: positions_direct_system(6, 3, p)


def tdoa_system(label: str, prime: int = 65521, seed: int = 0) -> list[Poly]:
    """A TDOA formulation ("9r3s:C2-C9") on a consistent random instance (known root checked)."""
    from ..formulations import tdoa as tf
    from ..engine.ring import Ring

    formulation = tf.Formulation.parse(label)
    instance = tf.sample_gf_instance(formulation.config, prime, seed)
    tf.check_root(formulation, instance)
    ring = Ring(formulation.config.unknowns, prime)
    return [ring.from_terms(eq) for eq in tf.gf_equations(formulation, instance, prime)]


TDOA_TABLE_SYSTEMS = {
    "tdoa-9r3s-C8": "9r3s:C2-C9",
    "tdoa-8r3s-B1C7": "8r3s:B2,C2-C8",
    "tdoa-8r3s-A1C7": "8r3s:A,C2-C8",
    "tdoa-7r3s-A1B1C6": "7r3s:A,B2,C2-C7",
    "tdoa-7r3s-B2C6": "7r3s:B2,B3,C2-C7",
    "tdoa-6r3s-A1B2C5": "6r3s:A,B2,B3,C2-C6",
    "tdoa-6r4s-B1C5M10": "6r4s:B2,C2-C6,minors",
}
"""The systems of the paper's Table 2 and the 6r/4s cell of Table 3 (seed-0 instances)."""

for _name, _label in TDOA_TABLE_SYSTEMS.items():
    BENCHMARK_SYSTEMS[_name] = (lambda label: lambda p: tdoa_system(label, p))(_label)


def register_system(name: str, builder: SystemBuilder, replace: bool = False) -> None:
    """Add a named benchmark system builder ``prime -> list[Poly]``."""
    if name in BENCHMARK_SYSTEMS and not replace:
        raise ValueError(f"benchmark system {name!r} already registered")
    BENCHMARK_SYSTEMS[name] = builder


def basis_digest(basis: Sequence[Poly]) -> str:
    """SHA-256 of a basis's terms (exponents and coefficients), elements in the given order: two reduced
    bases sorted by leading monomial are equal iff their digests are. Hashed element by element, so that
    no text of the whole basis is held (katsura-10's was most of the benchmark child's peak memory)."""
    import hashlib

    digest = hashlib.sha256()
    for f in basis:
        digest.update(repr(f.terms()).encode())
        digest.update(b";")
    return digest.hexdigest()


def benchmark_system(name: str, prime: int = 65521) -> list[Poly]:
    """The registered system called name, over GF(prime)."""
    try:
        builder = BENCHMARK_SYSTEMS[name]
    except KeyError:
        raise ValueError(f"unknown benchmark system {name!r}; registered: {', '.join(BENCHMARK_SYSTEMS)}") from None
    return builder(prime)
