"""The quotient ring GF(p)[x]/I from a Gröbner basis: standard monomials, degree, dimension, normal
forms, action (multiplication) matrices and saturation.

Reference: Cox, Little, O'Shea, *Ideals, Varieties, and Algorithms*, ch. 5 and 9; *Using Algebraic
Geometry*, ch. 2 (action matrices).
"""
from __future__ import annotations

import heapq
from typing import Sequence

import numpy as np

from .f4 import F4Options, GroebnerResult, groebner
from .ring import Poly, Ring


class NotZeroDimensional(ValueError):
    """The ideal has positive dimension, so it has no finite standard monomial basis."""

    def __init__(self, dimension: int):
        super().__init__(f"the ideal is not zero-dimensional (Krull dimension {dimension})")
        self.dimension = dimension


def _supports(ring: Ring, lms: Sequence[int]) -> list[int]:
    out = []
    for k in lms:
        mask = 0
        for i, e in enumerate(ring.exps(k)):
            if e:
                mask |= 1 << i
        out.append(mask)
    return out


def dimension(gb: GroebnerResult) -> int:
    """Krull dimension of GF(p)[x]/I, read off the leading-monomial ideal (-1 for the unit ideal).

    dim R/LM(I) is the largest size of a variable set S such that no leading monomial is supported in S.
    """
    ring = gb.ring
    if gb.is_unit:
        return -1
    supports = sorted(set(_supports(ring, gb.leading_monomials)), key=lambda s: bin(s).count("1"))
    full = (1 << ring.nvars) - 1
    memo: dict[int, int] = {}

    def best(s: int) -> int:
        if s in memo:
            return memo[s]
        for sup in supports:
            if sup & ~s == 0:  # a leading monomial lives inside s: drop one of its variables
                out = 0
                v = sup
                while v:
                    low = v & -v
                    out = max(out, best(s & ~low))
                    v ^= low
                break
        else:
            out = bin(s).count("1")
        memo[s] = out
        return out

    return best(full)


def is_zero_dimensional(gb: GroebnerResult) -> bool:
    """Whether I is zero-dimensional (each variable has a pure power among the leading monomials)."""
    if gb.is_unit:
        return True
    ring = gb.ring
    pure = set()
    for k in gb.leading_monomials:
        e = ring.exps(k)
        nz = [i for i, x in enumerate(e) if x]
        if len(nz) == 1:
            pure.add(nz[0])
    return len(pure) == ring.nvars


def standard_monomials(gb: GroebnerResult) -> list[int]:
    """The standard monomial basis B (monomial keys, increasing order); raises NotZeroDimensional."""
    if gb.is_unit:
        return []
    if not is_zero_dimensional(gb):
        raise NotZeroDimensional(dimension(gb))
    ring = gb.ring
    lm_exps = [ring.exps(k) for k in gb.leading_monomials]
    n = ring.nvars
    seen = {0}
    frontier = [(0,) * n]
    out = [0]
    while frontier:
        nxt = []
        for e in frontier:
            for i in range(n):
                f = e[:i] + (e[i] + 1,) + e[i + 1 :]
                k = ring.key(f)
                if k in seen:
                    continue
                seen.add(k)
                if any(all(a <= b for a, b in zip(lm, f)) for lm in lm_exps):
                    continue
                out.append(k)
                nxt.append(f)
        frontier = nxt
    out.sort()
    return out


def degree(gb: GroebnerResult) -> int:
    """Number of standard monomials = number of solutions with multiplicity (0 if inconsistent)."""
    return len(standard_monomials(gb))


def normal_form(f: Poly, gb: GroebnerResult) -> Poly:
    """Remainder of f on division by the Gröbner basis (unique: independent of the division order)."""
    ring = f.ring
    p = ring.prime
    basis = list(gb.basis)
    lm_exps = [ring.exps(g.lm) for g in basis]
    acc = f.to_dict()
    heap = [-k for k in acc]
    heapq.heapify(heap)
    rem: dict[int, int] = {}
    while heap:
        k = -heapq.heappop(heap)
        c = acc.pop(k, 0)
        if not c:
            continue
        e = ring.exps(k)
        for g, le in zip(basis, lm_exps):
            if all(a <= b for a, b in zip(le, e)):
                t = k - g.lm
                ring._exps.setdefault(t, tuple(b - a for a, b in zip(le, e)))
                for kk, cc in zip(g.mons[1:], g.coeffs[1:]):
                    m = kk + t
                    if m not in acc:
                        heapq.heappush(heap, -m)
                        ring._exps.setdefault(m, tuple(x + y for x, y in zip(ring.exps(kk), ring.exps(t))))
                    acc[m] = (acc.get(m, 0) - c * cc) % p
                break
        else:
            rem[k] = c
    return Poly.from_dict(ring, rem)


def action_matrix(gb: GroebnerResult, f: "Poly | int | str", basis: Sequence[int] | None = None) -> np.ndarray:
    """Matrix M of multiplication by f on the standard monomial basis B (int64 entries mod p).

    Row convention: NF(f * b_j) = sum_k M[j, k] b_k, so M v = f(x) v for v = (b_k(x))_k at every root x:
    the eigenvalues of M are the values of f at the roots and the eigenvectors are evaluations of B.
    f may be a polynomial, a variable index or a variable name.
    """
    ring = gb.ring
    if not isinstance(f, Poly):
        f = ring.gen(f)
    if basis is None:
        basis = standard_monomials(gb)
    pos = {k: i for i, k in enumerate(basis)}
    M = np.zeros((len(basis), len(basis)), dtype=np.int64)
    for j, b in enumerate(basis):
        nf = normal_form(f.mul_term(b), gb)
        for k, c in zip(nf.mons, nf.coeffs):
            M[j, pos[k]] = c
    return M


def saturate(polys: Sequence[Poly], f: Poly, options: F4Options = F4Options()) -> GroebnerResult:
    """Gröbner basis of the saturation I : f^infinity (in the ring's own order), by the Rabinowitsch trick.

    Adds a variable t, computes a Gröbner basis of I + (1 - t f) in an order eliminating t, and keeps the
    elements free of t (Cox-Little-O'Shea, ch. 4 sec. 4).
    """
    ring = polys[0].ring
    tname = "_t"
    while tname in ring.variables:
        tname += "_"
    ext = Ring((tname,) + ring.variables, ring.prime, f"block:1,{ring.nvars}")

    def lift(g: Poly) -> Poly:
        return ext.from_terms(((0,) + e, c) for e, c in g.terms())

    t = ext.gen(0)
    gens = [lift(g) for g in polys if g] + [ext.one() - t * lift(f)]
    elim = groebner(gens, options)
    kept = []
    for g in elim.basis:
        if all(e[0] == 0 for e, _ in g.terms()):
            kept.append(ring.from_terms((e[1:], c) for e, c in g.terms()))
    if not kept:
        return GroebnerResult(ring, (), (), elim.seconds)
    return groebner(kept, options)
