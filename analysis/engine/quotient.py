"""The quotient ring GF(p)[x]/I from a Gröbner basis: standard monomials, degree, dimension, normal
forms, action (multiplication) matrices and saturation.

Reference: Cox, Little, O'Shea, *Ideals, Varieties, and Algorithms*, ch. 5 and 9; *Using Algebraic
Geometry*, ch. 2 (action matrices).
"""
from __future__ import annotations

import heapq
import math
import time
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
    waves = _standard_waves(_lead_exponents(gb))
    return sorted(ring.key(tuple(e)) for e in np.concatenate(list(waves)).tolist())


def _lead_exponents(gb: GroebnerResult) -> np.ndarray:
    n = gb.ring.nvars
    return np.array([gb.ring.exps(k) for k in gb.leading_monomials], dtype=np.int64).reshape(-1, n)


class _TooMany(Exception):
    """More standard monomials than a wave enumeration was allowed to list."""


def _standard_waves(lm_exps: np.ndarray, limit: int | None = None):
    """The standard monomials of a zero-dimensional leading ideal degree by degree (exponent arrays, one
    per degree): the multiples x_i s of the standard monomials s of degree d are all of degree d + 1, so
    each wave is deduplicated on its own; those no leading monomial divides are the next wave. Raises
    :class:`_TooMany` once the count passes ``limit`` (or a wave's candidates would).

    A candidate m = x_i s is standard iff it is not itself a leading monomial and every m / x_j (x_j | m)
    is standard: a leading monomial properly dividing m divides one of the m / x_j. Where the exponents
    fit one int64 code (mixed radix, each variable up to its largest leading exponent, which bounds the
    candidates' exponents) that is a few sorted lookups per candidate; otherwise every leading monomial
    is tested against every candidate."""
    n = lm_exps.shape[1]
    radix = lm_exps.max(axis=0, initial=0) + 1
    coded = math.prod(int(r) for r in radix) < 1 << 62
    strides = np.cumprod(np.concatenate([[1], radix[:-1]])).astype(np.int64) if coded else None
    lm_codes = np.sort(lm_exps @ strides) if coded else None
    frontier = np.zeros((1, n), dtype=np.int64)
    codes = np.zeros(1, dtype=np.int64)
    total = 1
    yield frontier
    step = np.eye(n, dtype=np.int64)
    chunk = max(1, (1 << 20) // max(1, len(lm_exps) * n))
    while len(frontier):
        if limit is not None and len(frontier) * n > limit:  # the candidates alone: memory bound
            raise _TooMany
        candidates = (frontier[:, None, :] + step[None, :, :]).reshape(-1, n)
        if coded:
            cand_codes = (codes[:, None] + strides[None, :]).ravel()
            cand_codes, first = np.unique(cand_codes, return_index=True)
            candidates = candidates[first]
            keep = ~_member(cand_codes, lm_codes)
            for j in range(n):
                has = candidates[:, j] > 0
                keep[has] &= _member(cand_codes[has] - strides[j], codes)
            frontier, codes = candidates[keep], cand_codes[keep]
        else:
            candidates = candidates[np.lexsort(candidates.T)]  # np.unique(axis=0) would import numpy.ma (12 ms)
            fresh = np.ones(len(candidates), dtype=bool)
            fresh[1:] = (candidates[1:] != candidates[:-1]).any(axis=1)
            candidates = candidates[fresh]
            divisible = np.concatenate([
                (lm_exps[None, :, :] <= candidates[s : s + chunk, None, :]).all(axis=2).any(axis=1)
                for s in range(0, len(candidates), chunk)
            ])
            frontier = candidates[~divisible]
        total += len(frontier)
        if limit is not None and total > limit:
            raise _TooMany
        yield frontier


def _member(values: np.ndarray, sorted_set: np.ndarray) -> np.ndarray:
    """values[k] in sorted_set, element by element."""
    at = np.searchsorted(sorted_set, values)
    return sorted_set[np.minimum(at, len(sorted_set) - 1)] == values


WAVE_COUNT_LIMIT = 200_000
"""count_standard_monomials enumerates B wave by wave (arrays) when the box of the pure powers bounds |B| by
this and there are at most WAVE_DEGREE_LIMIT waves; otherwise it counts by the memoised split, which never
lists B."""

WAVE_DEGREE_LIMIT = 2_000
"""Most waves (degrees) of the wave count: one wave per degree costs ~50 us of numpy calls, so x^65536 - 1
(65,537 waves of one monomial, 3.8 s) is counted by the split instead (one slice)."""


def degree(gb: GroebnerResult) -> int:
    """Number of standard monomials = number of solutions with multiplicity (0 if inconsistent)."""
    return count_standard_monomials(gb)


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


def variable_action_matrices(gb: GroebnerResult, basis: Sequence[int]) -> np.ndarray:
    """Action matrices of all variables on the standard monomials (row convention of
    :func:`analysis.engine.quotient.action_matrix`: row j is NF(x_i b_j)), shape (nvars, |B|, |B|).

    FGLM border recursion: border monomials u = x_i b are visited in increasing order; u is either a
    leading monomial of the reduced basis (NF(u) = -tail) or u = x_k u' with u' a smaller border
    monomial, and then NF(u) = NF(u') M_k, whose needed rows NF(x_k b_j), b_j < u', are already known.
    M_k is a shift (x_k b_j another standard monomial) on most rows: the product is a gather over those
    and a dense product over the border rows known so far only (:func:`_vecmat_mod`), O(|B| (1 + border
    rows)) instead of O(|B|^2) per border monomial (x^1024 - 2, y - x^3: 0.2 s instead of 5 s).
    """
    ring = gb.ring
    p = ring.prime
    nb, nvars = len(basis), ring.nvars
    pos = {k: i for i, k in enumerate(basis)}
    lead = {g.lm: g for g in gb.basis}
    vkeys = [ring.variable_key(i) for i in range(nvars)]
    M = np.zeros((nvars, nb, nb), dtype=np.int64)
    border: dict[int, list[tuple[int, int]]] = {}
    shifts: list[tuple[list[int], list[int]]] = [([], []) for _ in range(nvars)]
    for j, b in enumerate(basis):
        for i in range(nvars):
            u = b + vkeys[i]
            if u in pos:
                M[i, j, pos[u]] = 1
                shifts[i][0].append(j)
                shifts[i][1].append(pos[u])
            else:
                border.setdefault(u, []).append((i, j))
    src = [np.array(a, dtype=np.int64) for a, _ in shifts]
    dst = [np.array(b, dtype=np.int64) for _, b in shifts]
    known_rows: list[list[int]] = [[] for _ in range(nvars)]  # border rows of M_k filled so far
    nf: dict[int, np.ndarray] = {}
    for u in sorted(border):
        g = lead.get(u)
        if g is not None:
            v = np.zeros(nb, dtype=np.int64)
            for k, c in zip(g.mons[1:], g.coeffs[1:]):
                v[pos[k]] = (-c) % p
        else:
            e = ring.exps(u)
            for k in range(nvars):
                if e[k] and (u - vkeys[k]) in nf:
                    prev = nf[u - vkeys[k]]
                    v = np.zeros(nb, dtype=np.int64)
                    v[dst[k]] = prev[src[k]]
                    rows = known_rows[k]
                    if rows:
                        v = (v + _vecmat_mod(prev[rows], M[k, rows], p)) % p
                    break
            else:  # pragma: no cover - impossible for a reduced Gröbner basis of a zero-dimensional ideal
                raise RuntimeError(f"border monomial {ring.monomial_str(u)} has no smaller border divisor")
        nf[u] = v
        for i, j in border[u]:
            M[i, j] = v
            known_rows[i].append(j)
    return M


def _vecmat_mod(a: np.ndarray, N: np.ndarray, p: int) -> np.ndarray:
    """a @ N mod p for int64 entries in [0, p), p < 2^31, exactly in int64: directly when len(a) (p-1)^2
    < 2^63, else with a split into 16-bit halves (each partial product below 2^47; len(a) < 2^16)."""
    if len(a) * (p - 1) ** 2 < 1 << 63:
        return a @ N % p
    if len(a) >= 1 << 16:
        return np.array((a.astype(object) @ N.astype(object)) % p, dtype=np.int64)
    high = (a >> 16) @ N % p
    return (high * 65536 + (a & 0xFFFF) @ N) % p


def _flint(M: np.ndarray, p: int) -> "flint.nmod_mat":  # noqa: F821
    import flint  # only here and in saturated_degree: python-flint costs 70 ms to import

    return flint.nmod_mat(M.shape[0], M.shape[1], [int(x) for x in M.ravel()], p)


def saturated_degree(gb: GroebnerResult, f: Poly, basis: Sequence[int] | None = None) -> int:
    """deg(I : f^inf) for a zero-dimensional I given by its reduced Gröbner basis: rank of M_f^N, N >= |B|.

    Raises :class:`analysis.engine.quotient.NotZeroDimensional` for positive-dimensional ideals.
    """
    if basis is None:
        basis = standard_monomials(gb)
    nb = len(basis)
    if nb == 0:
        return 0
    import flint

    p = gb.ring.prime
    var_mats = [_flint(X, p) for X in variable_action_matrices(gb, basis)]
    Mf = flint.nmod_mat(nb, nb, p)
    for exps, c in f.terms():
        term = flint.nmod_mat(nb, nb, [c if i == j else 0 for i in range(nb) for j in range(nb)], p)
        for i, e in enumerate(exps):
            for _ in range(e):
                term = term * var_mats[i]
        Mf = Mf + term
    power = 1
    while power < nb:
        Mf = Mf * Mf
        power *= 2
    return Mf.rank()


def count_standard_monomials(gb: GroebnerResult) -> int:
    """|B| without listing B: the number of monomials outside the leading-monomial ideal.

    Splits on the last variable x: with a the smallest pure power of x among the leading monomials,
    B = union over k < a of x^k B_k, where B_k are the standard monomials in the other variables of the
    leading monomials whose x-exponent is at most k. B_k only changes at those exponents, so each
    distinct slice is counted once (memoised), which makes products of univariate ideals (2^40
    solutions in 40 variables) instant. Raises NotZeroDimensional like :func:`standard_monomials`.
    """
    if gb.is_unit:
        return 0
    if not is_zero_dimensional(gb):
        raise NotZeroDimensional(dimension(gb))
    ring = gb.ring
    lm_exps = _lead_exponents(gb)
    single = (lm_exps > 0).sum(axis=1) == 1  # pure powers x_i^a (each variable has one: zero-dimensional)
    pure = np.where(lm_exps[single] > 0, lm_exps[single], np.iinfo(np.int64).max).min(axis=0)
    if int(pure.sum()) <= WAVE_DEGREE_LIMIT:  # B listed wave by wave while it stays small
        in_box = math.prod(int(a) for a in pure) <= WAVE_COUNT_LIMIT
        try:
            return sum(len(wave) for wave in _standard_waves(lm_exps, None if in_box else WAVE_COUNT_LIMIT))
        except _TooMany:
            pass
    memo: dict[tuple, int] = {}

    def minimal(gens: list[tuple[int, ...]]) -> tuple[tuple[int, ...], ...]:
        gens = sorted(set(gens), key=sum)
        keep: list[tuple[int, ...]] = []
        for g in gens:
            if not any(all(a <= b for a, b in zip(h, g)) for h in keep):
                keep.append(g)
        return tuple(sorted(keep))

    def count(gens: tuple[tuple[int, ...], ...], nvars: int) -> int:
        if any(not any(g) for g in gens):
            return 0
        if nvars == 0:
            return 1
        key = (gens, nvars)
        if key not in memo:
            v = nvars - 1
            a = min(g[v] for g in gens if not any(g[:v]))
            cuts = sorted({g[v] for g in gens if g[v] < a} | {0}) + [a]
            total = 0
            for lo, hi in zip(cuts, cuts[1:]):
                sliced = minimal([g[:v] for g in gens if g[v] <= lo])
                total += (hi - lo) * count(sliced, v)
            memo[key] = total
        return memo[key]

    return count(minimal([ring.exps(k) for k in gb.leading_monomials]), ring.nvars)


def fglm(gb: GroebnerResult, target: Ring) -> GroebnerResult:
    """Reduced Gröbner basis of the same zero-dimensional ideal in the order of ``target`` (FGLM).

    Walks the monomials of the target order upwards from 1 (candidates x_i s for the standard
    monomials s found so far, skipping multiples of leading monomials found so far); the normal form
    of each, as a vector on the standard monomials of ``gb``, comes from the action matrices
    (NF(x_i s) = NF(s) M_i). A candidate whose vector depends on those of the standard monomials found
    so far is a new leading monomial, and the dependency is its Gröbner basis element; otherwise it is
    a new standard monomial. Costs |B|^2 per candidate, n |B| candidates: the standard way to a lex
    basis, where F4 in lex itself can swell far beyond the ideal's degree.
    Faugère, Gianni, Lazard, Mora, "Efficient computation of zero-dimensional Gröbner bases by change
    of ordering", JSC 1993.
    """
    ring = gb.ring
    if target.variables != ring.variables or target.prime != ring.prime:
        raise ValueError("fglm: the target ring must have the same variables and prime")
    t0 = time.perf_counter()
    if gb.is_unit:
        return GroebnerResult(target, (target.one(),), gb.rounds, time.perf_counter() - t0)
    basis = standard_monomials(gb)
    nb, n, p = len(basis), ring.nvars, ring.prime
    M = variable_action_matrices(gb, basis)
    if target.order.name == "lex":
        shape = _shape_basis(gb, target, basis, M)
        if shape is not None:
            return GroebnerResult(target, shape, gb.rounds, gb.seconds + time.perf_counter() - t0)
    dtype = object if nb * (p - 1) ** 2 >= 1 << 63 else np.int64
    M = M.astype(dtype)
    E = np.zeros((nb, nb), dtype=dtype)  # reduced echelon rows (pivot entries 1, pivot columns cleared)
    T = np.zeros((nb, nb), dtype=dtype)  # E = T V, V the vectors of the new standard monomials
    pivots: list[int] = []
    std: list[int] = []  # keys of the standard monomials found so far
    leads = np.zeros((n * nb + 1, n), dtype=np.int64)  # the leading monomials found so far
    nleads = 0
    polys: list[Poly] = []
    zero = (0,) * n
    one = np.zeros(nb, dtype=dtype)
    one[basis.index(ring.key(zero))] = 1
    steps = [target.key(tuple(int(i == j) for j in range(n))) for i in range(n)]  # key(e + x_i) = key(e) + steps[i]
    heap = [(target.key(zero), zero)]
    # the vector of a candidate x_i s is NF(s) M_i, computed when the candidate is reached and is not a
    # multiple of a leading monomial found by then (most are)
    vectors: dict[tuple[int, ...], tuple[np.ndarray, int]] = {zero: (one, -1)}
    while heap:
        key, e = heapq.heappop(heap)
        source = vectors.pop(e, None)
        if source is None or (nleads and (leads[:nleads] <= e).all(axis=1).any()):
            continue
        v = source[0] if source[1] < 0 else source[0] @ M[source[1]] % p
        k = len(pivots)
        coefs = v[pivots] % p if k else np.zeros(0, dtype=dtype)
        r = (v - coefs @ E[:k]) % p if k else v % p
        combo = (coefs @ T[:k, :k]) % p if k else np.zeros(0, dtype=dtype)
        nonzero = np.flatnonzero(r)
        if not len(nonzero):
            leads[nleads] = e
            nleads += 1
            terms = {s: (-int(c)) % p for s, c in zip(std, combo.tolist()) if c}
            terms[key] = 1
            polys.append(Poly.from_dict(target, terms))
            continue
        c = int(nonzero[0])
        inv = pow(int(r[c]), -1, p)
        E[k] = r * inv % p
        T[k, :k] = (-combo) * inv % p
        T[k, k] = inv
        if k:
            factor = E[:k, c].copy()
            E[:k] = (E[:k] - np.outer(factor, E[k])) % p
            T[:k, : k + 1] = (T[:k, : k + 1] - np.outer(factor, T[k, : k + 1])) % p
        pivots.append(c)
        std.append(key)
        for i in range(n):
            f = e[:i] + (e[i] + 1,) + e[i + 1:]
            if f not in vectors:
                vectors[f] = (v, i)
                heapq.heappush(heap, (key + steps[i], f))
    polys.sort(key=lambda g: g.lm)
    return GroebnerResult(target, tuple(polys), gb.rounds, gb.seconds + time.perf_counter() - t0)


def _shape_basis(gb: GroebnerResult, target: Ring, basis: Sequence[int], M: np.ndarray,
                 seed: int = 0) -> tuple[Poly, ...] | None:
    """The reduced lex basis {x_1 - g_1(x_n), ..., x_{n-1} - g_{n-1}(x_n), m(x_n)} when the ideal is in shape
    position (the minimal polynomial m of x_n has degree |B|), else None (then classical FGLM runs).

    Wiedemann's way, in O(|B|^2) instead of FGLM's O(n |B|^3): for a random linear form l on the quotient,
    the sequence l(x_n^k), k < 2|B|, has minimal polynomial m (Berlekamp-Massey, flint), and for every
    other variable x_i = g_i(x_n) with g_i = Phi_{x_i} / Phi_1 mod m, where Phi_h is the numerator of the
    generating series sum_k l(h x_n^k) / T^(k+1) = Phi_h(T) / m(T) (Bostan, Salvy, Schost 2003; Faugère,
    Mou 2011). The sequences come from the transposed action of x_n on l, sparse as in
    :func:`variable_action_matrices`. The answer is then checked exactly: m(x_n) and x_i - g_i(x_n) reduce to
    zero (their normal forms from the Krylov rows NF(x_n^k)), and |B| = deg m, so they are the basis.
    An unlucky random form (probability <= 2|B|/p) or a missing shape gives None.
    """
    import flint  # imported here only: python-flint costs 70 ms to import

    ring = gb.ring
    nb, n, p = len(basis), ring.nvars, ring.prime
    pos = {k: i for i, k in enumerate(basis)}
    if 0 not in pos or nb < 2:
        return None
    last = n - 1
    Mn = M[last]
    ones = (Mn != 0).sum(axis=1) == 1
    unit = np.flatnonzero(ones & (Mn.max(axis=1) == 1))  # rows NF(x_n b_j) = b_j': a shift
    dst = Mn[unit].argmax(axis=1)
    dense = np.setdiff1d(np.arange(nb), unit)
    dense_t = np.ascontiguousarray(Mn[dense].T)

    def act(w: np.ndarray) -> np.ndarray:  # M_n w: row j of M_n against w
        out = np.zeros(nb, dtype=np.int64)
        out[unit] = w[dst]
        if len(dense):
            out[dense] = _vecmat_mod(w, dense_t, p)
        return out

    def times_m(v: np.ndarray) -> np.ndarray:  # v M_n: the row NF(x_n b) from the row NF(b)
        out = np.zeros(nb, dtype=np.int64)
        out[dst] = v[unit]
        if len(dense):
            out = (out + _vecmat_mod(v[dense], Mn[dense], p)) % p
        return out

    targets = np.zeros((nb, last), dtype=np.int64)  # column i: NF(x_i)
    for i in range(last):
        key = ring.variable_key(i)
        if key in pos:
            targets[pos[key], i] = 1
            continue
        g = next((g for g in gb.basis if g.lm == key), None)
        if g is None:
            return None
        for k, c in zip(g.mons[1:], g.coeffs[1:]):
            targets[pos[k], i] = (-c) % p
    w = np.random.default_rng(seed).integers(0, p, nb, dtype=np.int64)
    s, v = [], []
    for k in range(2 * nb):
        s.append(int(w[pos[0]]))
        if k < nb and last:
            v.append(_vecmat_mod(w, targets, p).tolist())
        w = act(w)
    ctx = flint.fmpz_mod_poly_ctx(p)
    m = flint.nmod_poly([int(c) for c in ctx.minpoly(s).coeffs()], p)
    if m.degree() != nb:
        return None
    m_rev = m.reverse()

    def phi(seq: list[int]) -> "flint.nmod_poly":  # numerator of sum_k seq_k / T^(k+1) times m
        series = flint.nmod_poly(seq[:nb], p)
        return (m_rev * series).truncate(nb).reverse(nb - 1)

    phi_1 = phi(s)
    g, inverse, _ = phi_1.xgcd(m)
    if g.degree() != 0:
        return None
    inverse = inverse * pow(int(g.coeffs()[0]), -1, p)
    params = [(phi([row[i] for row in v]) * inverse) % m for i in range(last)]
    m_coeffs = [int(c) for c in m.coeffs()]
    p_coeffs = [[int(c) for c in q.coeffs()] + [0] * (nb - len(q.coeffs())) for q in params]
    # exact check: sum_k c_k NF(x_n^k) over the Krylov rows
    row = np.zeros(nb, dtype=np.int64)
    row[pos[0]] = 1
    acc_m = np.zeros(nb, dtype=np.int64)
    acc = np.zeros((last, nb), dtype=np.int64)
    coef = np.array(p_coeffs, dtype=np.int64).reshape(last, nb)
    for k in range(nb + 1):
        acc_m = (acc_m + m_coeffs[k] * row) % p
        if k < nb and last:
            acc = (acc + (coef[:, k:k + 1] * row[None, :]) % p) % p
        row = times_m(row)
    if acc_m.any() or not np.array_equal(acc, targets.T % p):
        return None
    power = target.variable_key(last)
    polys = [Poly.from_dict(target, {power * k: c for k, c in enumerate(m_coeffs) if c})]
    for i, c in enumerate(p_coeffs):
        terms = {power * k: (-x) % p for k, x in enumerate(c) if x}
        terms[target.variable_key(i)] = 1
        polys.append(Poly.from_dict(target, terms))
    for g in polys:
        for k in g.mons:
            target.exps(k)
    return tuple(sorted(polys, key=lambda g: g.lm))
