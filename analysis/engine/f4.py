"""Faugère's F4 over GF(p): select -> symbolic preprocessing -> reduce -> update.

The driver :func:`groebner` keeps one :class:`RoundStats` per round and returns the reduced Gröbner
basis. Pairs are selected by the normal strategy (all pairs of minimal lcm degree), pruned with the
Gebauer-Möller criteria; the linear algebra is delegated to a backend of :mod:`analysis.engine.linalg`.

Every step works on arrays: the basis elements live in a term pool of packed monomial codes
(:class:`analysis.engine.ring.MonomialCodes`), so symbolic preprocessing, matrix assembly and the pair update
are numpy operations over all rows, monomials and pairs of a round at once.

Reference: J.-C. Faugère, "A new efficient algorithm for computing Gröbner bases (F4)", JPAA 1999;
R. Gebauer and H. M. Möller, "On an installation of Buchberger's algorithm", JSC 1988.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .linalg import Backend, MatrixTooLarge, SparseRows, get_backend, sparse_pays
from . import native
from .native import index_of
from .ring import CodeOverflow, MonomialCodes, Poly, Ring


_ASSEMBLE_BLOCK = 1 << 18
"""Matrix entries generated at a time by symbolic preprocessing and :func:`_assemble` (:meth:`_Rows.blocks`)."""

CUBE_CELLS = 1 << 21
"""Up to this many divisibility tests (new elements x partners^2) the pair update of a round tests all
pairs of partners at once; above it, degree by degree against the minimal lcms (same pairs)."""

COEFFICIENT_TABLE = 1 << 17
"""Up to this prime the reduced basis shares one int object per field element (see :func:`_reduce_basis`)."""

MEMORY_SHARE = 0.75
"""Share of the machine's available memory (at the start of a run) that the default memory cap allows one
F4 matrix reduction (:func:`default_max_memory`); the rest is left to the basis, the pair set and the
machine's other work."""

FALLBACK_MAX_MEMORY = 8 << 30
"""The default memory cap where the available memory cannot be read (no /proc/meminfo, no sysconf)."""


def available_memory() -> int | None:
    """Bytes of memory the machine can give a process now without swapping (Linux ``MemAvailable``;
    elsewhere free pages by sysconf), or None where neither can be read."""
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        import os

        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None


def default_max_memory() -> int:
    """The default memory cap of one F4 matrix reduction: :data:`MEMORY_SHARE` of the machine's available
    memory now (:data:`FALLBACK_MAX_MEMORY` where that cannot be read)."""
    free = available_memory()
    return FALLBACK_MAX_MEMORY if free is None else int(MEMORY_SHARE * free)


@dataclass(frozen=True)
class F4Options:
    """Options of an F4 run.

    backend: linear algebra backend ("auto": the compiled sparse kernel on large sparse matrices, numpy
        otherwise; "numpy", "sparse", or "python", the reference).
    max_matrix_cells: stop with :class:`MatrixTooLarge` when rows*cols of a matrix exceeds this; None
        (the default): no cap on the shape, the memory cap decides (F4 matrices are sparse: the direct
        6r/3s system's 32299 x 18831 matrix, 608M cells, needs about 200 MiB).
    max_memory: stop with :class:`MatrixTooLarge` before reducing a matrix whose estimated working
        memory (:func:`matrix_memory`) exceeds this many bytes; None (the default): the machine's
        available memory at the start of the run (:func:`default_max_memory`).
    verbose: print one line per round to stderr.
    threads: threads of the row reduction (the C kernel, built with OpenMP; the other backends and a
        build without OpenMP use one). The basis is the same for every count.
    linear_substitution: first solve the linear input polynomials for their leading variables and
        substitute them into the others (:func:`_substitute_linear`): F4 then runs in fewer variables
        (``x^200 + y, x + y + 1``: one univariate polynomial instead of a 20101 x 20301 matrix). Off by
        default, so that the matrix statistics recorded in the tables stay those of F4 on the inputs.
    reduced: True (the default): the reduced Gröbner basis. False: a minimal Gröbner basis, each element
        monic with the tail F4 left it (not reduced by the other elements). Its leading monomials are
        the reduced basis's, and so is its size: this is what a degree or a dimension needs (msolve's
        ``-g 1``, the leading ideal, against ``-g 2``), and it skips the final tail reduction.
    """

    backend: str = "auto"
    max_matrix_cells: int | None = None
    max_memory: int | None = None
    verbose: bool = False
    threads: int = 1
    linear_substitution: bool = False
    reduced: bool = True

    def __post_init__(self):
        if not isinstance(self.threads, int) or self.threads < 1:
            raise ValueError(f"threads must be a positive integer, not {self.threads!r}")


def tighter_cells(*caps: int | None) -> int | None:
    """The smallest of matrix-cell caps, None (no cap) counting as infinite."""
    return min((c for c in caps if c is not None), default=None)


def format_bytes(n: float) -> str:
    """``1.5 GiB``, ``300 MiB``, ``12 KiB``, ``100 B``."""
    for unit, shift in (("GiB", 30), ("MiB", 20), ("KiB", 10)):
        if n >= 1 << shift:
            return f"{n / (1 << shift):.3g} {unit}"
    return f"{int(n)} B"


def matrix_memory(reduce_rows: int, cols: int, nonzeros: int, dense: bool = True) -> int:
    """Estimated peak bytes of reducing one F4 matrix: the rows to reduce as a dense float64 matrix and
    its two reduced copies (see :func:`analysis.engine.linalg._eliminate`; with dense=False, the sparse
    kernel's, one accumulator row), plus the sparse matrix (column and value arrays, int64) and its
    pivot / non-pivot copies."""
    return (24 * reduce_rows * cols if dense else 8 * cols) + 48 * nonzeros


@dataclass(frozen=True)
class RoundStats:
    """Statistics of one F4 round (msolve-style)."""

    degree: int
    pairs: int
    rows: int
    cols: int
    density: float
    new: int
    zero_reductions: int
    seconds: float


@dataclass(frozen=True)
class GroebnerResult:
    """A Gröbner basis with its per-round statistics: the reduced one, or a minimal one where
    ``F4Options(reduced=False)`` asked for it (``reduced`` says which)."""

    ring: Ring
    basis: tuple[Poly, ...]
    rounds: tuple[RoundStats, ...] = field(repr=False)
    seconds: float = 0.0
    reduced: bool = True

    @property
    def leading_monomials(self) -> list[int]:
        return [g.lm for g in self.basis]

    @property
    def is_unit(self) -> bool:
        """Whether the ideal is the whole ring (inconsistent system)."""
        return len(self.basis) == 1 and self.basis[0].is_constant()

    @property
    def max_matrix(self) -> tuple[int, int]:
        return max(((r.rows, r.cols) for r in self.rounds), key=lambda rc: rc[0] * rc[1], default=(0, 0))


def _exponent_field(top: int) -> np.dtype:
    """The narrowest unsigned field (uint8, uint16 or uint32) holding exponents up to top with its top bit
    free (exponents from 32768 on need uint32; the parser allows total degrees below 2^31)."""
    if top < 128:
        return np.dtype(np.uint8)
    if top < 32768:
        return np.dtype(np.uint16)
    if top < 1 << 31:
        return np.dtype(np.uint32)
    raise OverflowError("exponent too large for packed divisibility tests")


def _pack(E: np.ndarray, field: np.dtype) -> np.ndarray:
    """Exponent rows as rows of fields, zero padded to whole 64-bit words: ``.view(np.uint64)`` of the
    result gives the packed words of :func:`_divides_words`."""
    per_word = 8 // field.itemsize
    out = np.zeros((len(E), -(-E.shape[1] // per_word) * per_word), dtype=field)
    out[:, : E.shape[1]] = E
    return out


_GUARDS: dict[tuple[int, int], np.ndarray] = {}
_GUARD_BITS = {1: 0x8080808080808080, 2: 0x8000800080008000, 4: 0x8000000080000000}


def _guard(field: np.dtype, nwords: int) -> np.ndarray:
    """The top bit of every field of a packed word (cached; do not modify)."""
    key = (field.itemsize, nwords)
    guard = _GUARDS.get(key)
    if guard is None:
        guard = np.full(nwords, _GUARD_BITS[field.itemsize], dtype=np.uint64)
        _GUARDS[key] = guard
    return guard


_DIVIDES_CELLS = 1 << 20


def _divides_words(a: np.ndarray, b: np.ndarray, guard: np.ndarray) -> np.ndarray:
    """out[i, j] = (packed row a[j] divides packed row b[i]): ((b | guard) - a) & guard == guard in every
    word, as the guard bits stop borrows between fields."""
    step = max(1, _DIVIDES_CELLS // max(1, len(a)))
    if len(b) > step:  # a block of rows at a time: its temporaries stay in cache (5x faster at 26M cells)
        return np.concatenate([_divides_words(a, b[s : s + step], guard) for s in range(0, len(b), step)])
    out = ((b[:, None, 0] | guard[0]) - a[None, :, 0]) & guard[0] == guard[0]
    for w in range(1, a.shape[1]):
        out &= ((b[:, None, w] | guard[w]) - a[None, :, w]) & guard[w] == guard[w]
    return out


class _Elements:
    """The basis elements as polynomials, each built from the term pool of its state when first needed
    (F4 itself works on the pool; only callers that look at elements pay for the polynomials)."""

    def __init__(self, state: "_State"):
        self._state = state
        self._polys: list[Poly | None] = []

    def __len__(self) -> int:
        return len(self._polys)

    def __getitem__(self, k: int) -> Poly:
        poly = self._polys[k]
        if poly is None:
            state = self._state
            terms = slice(state.starts[k], state.starts[k] + state.lengths[k])
            poly = Poly(state.ring, state.codes.to_keys(state.pool_codes[terms]), state.pool_coeffs[terms].tolist())
            self._polys[k] = poly
        return poly

    def extend(self, polys: Sequence[Poly | None]) -> None:
        self._polys.extend(polys)


class _State:
    """The growing basis G and the pair set, with a vectorised Gebauer-Möller update.

    Exponent vectors of the leading monomials and of the pair lcms live in numpy arrays of narrow
    fields that view as packed 64-bit words (see :func:`_divides_words`), so that inserting the new
    elements of a round costs a few array operations instead of Python loops over all pairs. The terms
    of every element are kept as monomial codes (see :class:`analysis.engine.ring.MonomialCodes`) and
    coefficients in one concatenated term pool, so that the rows of an F4 matrix are gathered with
    array operations; ``polys`` gives the elements as polynomials.
    """

    def __init__(self, ring: Ring, codes: MonomialCodes | None = None, threads: int = 1):
        self.ring = ring
        self.threads = threads  # of the C pair update
        self.codes = codes or MonomialCodes(ring)
        self.polys = _Elements(self)
        self.field = _exponent_field(0)
        # per element: packed exponents and degree of the leading monomial, its code, whether it is
        # active, its terms pool[starts : starts + lengths] and their top degree
        # room for a typical run, so that the arrays rarely grow
        self.E = _pack(np.zeros((256, ring.nvars), dtype=np.int64), self.field)
        self.lm_degrees = np.zeros(256, dtype=np.int64)
        self.lm_codes = np.zeros(256, dtype=self.codes.dtype)
        self.active = np.zeros(256, dtype=bool)
        self.starts = np.zeros(256, dtype=np.int64)
        self.lengths = np.zeros(256, dtype=np.int64)
        self.max_degrees = np.zeros(256, dtype=np.int64)
        self.pool_codes = np.zeros(16384, dtype=self.codes.dtype)
        self.pool_coeffs = np.zeros(16384, dtype=np.int32)  # p < 2**31; the C kernel reads it as it is
        self.pool_size = 0
        # pairs: rows (i, j, lcm degree) and the packed lcm exponents
        self.pairs = np.zeros((0, 3), dtype=np.int64)
        self.pL = self.E[:0]

    @property
    def npairs(self) -> int:
        return len(self.pairs)

    def lead_exponents(self, index: np.ndarray) -> np.ndarray:
        """Exponent vectors (int64) of the leading monomials of the elements at index."""
        return self.E[index, : self.ring.nvars].astype(np.int64)

    def pop_pairs(self) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
        """Remove and return the pairs of minimal lcm degree (normal strategy): (degree, i, j, lcm exponents)."""
        d = int(self.pairs[:, 2].min())
        sel = self.pairs[:, 2] == d
        chosen = self.pairs[sel]
        out = (d, chosen[:, 0], chosen[:, 1], self.pL[sel, : self.ring.nvars].astype(np.int64))
        self.pairs, self.pL = self.pairs[~sel], self.pL[~sel]
        return out

    def store_minimal(self, polys: Sequence[Poly]) -> None:
        """Store the elements of a minimal basis (monic, leading monomials decreasing, none dividing
        another's), all active, without pairs: the state :func:`_reduce_basis` needs, in one pass (one
        decoding of all terms) instead of an :meth:`add` and a pair update per element."""
        lengths = np.array([len(g.mons) for g in polys], dtype=np.int64)
        indptr = np.concatenate([[0], np.cumsum(lengths)])
        codes = self.codes.from_keys([k for g in polys for k in g.mons])
        coeffs = np.array([c for g in polys for c in g.coeffs], dtype=np.int64)
        self._store(codes, coeffs, indptr, self.codes.decode(codes[indptr[:-1]]))
        self.polys.extend(polys)
        self.active[: len(self.polys)] = True

    def _store(self, codes: np.ndarray, coeffs: np.ndarray, indptr: np.ndarray, leads: np.ndarray) -> None:
        """Append new elements (terms codes/coeffs[indptr[i] : indptr[i + 1]], leading exponents) to the
        per-element arrays and the term pool."""
        k, m = len(self.polys), len(indptr) - 1
        field = _exponent_field(int(leads.max(initial=0)))
        if field.itemsize > self.field.itemsize:
            n = self.ring.nvars
            self.field = field
            self.E, self.pL = _pack(self.E[:, :n], field), _pack(self.pL[:, :n], field)
        while k + m > len(self.starts):
            self.E = np.vstack([self.E, np.zeros_like(self.E)])
            self.lm_degrees, self.lm_codes, self.active, self.starts, self.lengths, self.max_degrees = (
                np.concatenate([a, np.zeros_like(a)])
                for a in (self.lm_degrees, self.lm_codes, self.active, self.starts, self.lengths, self.max_degrees)
            )
        end = self.pool_size + len(codes)
        if end > len(self.pool_codes):
            grow = max(end, 2 * len(self.pool_codes)) - len(self.pool_codes)
            self.pool_codes = np.concatenate([self.pool_codes, np.zeros(grow, dtype=self.pool_codes.dtype)])
            self.pool_coeffs = np.concatenate([self.pool_coeffs, np.zeros(grow, dtype=np.int32)])
        self.pool_codes[self.pool_size : end] = codes
        self.pool_coeffs[self.pool_size : end] = coeffs
        degrees = self.codes.degrees(codes)
        new = slice(k, k + m)
        self.E[new, : leads.shape[1]] = leads
        self.lm_degrees[new] = leads.sum(axis=1)
        self.lm_codes[new] = codes[indptr[:-1]]
        self.starts[new] = self.pool_size + indptr[:-1]
        self.lengths[new] = indptr[1:] - indptr[:-1]
        self.max_degrees[new] = np.maximum.reduceat(degrees, indptr[:-1])
        self.pool_size = end

    def insert(self, codes: np.ndarray, coeffs: np.ndarray, indptr: np.ndarray, polys: Sequence[Poly | None]) -> None:
        """Insert new monic elements h_0, ..., h_{m-1} (terms codes/coeffs[indptr[t] : indptr[t + 1]],
        leading monomials decreasing, none divisible by the lm of an active element) one after the other,
        updating the pairs; polys[t] is h_t or None (built from the pool when asked for).

        Gebauer-Möller as in Becker-Weispfenning's UPDATE, for each h_t in turn: among the new pairs
        (g, h_t) drop those whose lcm is a proper multiple of another new pair's lcm (criterion M), keep
        one per equal lcm unless one of them is coprime (criterion F, then all go by Buchberger's first
        criterion); drop existing pairs whose lcm is divisible by lm(h_t) with both lcms against h_t
        different (criterion B); h_t makes the active elements whose lm it divides inactive.

        All m insertions are done at once with the same outcome: an element is a partner of h_t when it
        is active at time t (inserted before t, made inactive at t or later), so the new pairs of all t
        follow from these activity spans, and criterion B drops a pair as soon as any later h_t
        qualifies. Degrees decide the equalities: for monomials a | c and b | c, lcm(a, b) = c iff their
        degrees agree. Where the C kernels are built (:mod:`analysis.engine.native`) the same update runs there
        in the same three passes (activity spans; the new pairs of each h_t; criterion B pair by pair), each
        shared among ``threads`` threads, without numpy's per-call overhead (cyclic-7: 93 -> 16 ms); the
        arrays below are the fallback and the reference it is tested against.
        """
        m = len(polys)
        k = len(self.polys)
        leads = self.codes.decode(codes[indptr[:-1]])
        self._store(codes, coeffs, indptr, leads)
        self.polys.extend(polys)
        if native.kernel() is not None:  # the same update in C (the same passes, on up to self.threads threads)
            n = self.ring.nvars
            keep, new, new_lcms, active = native.pair_update(
                self.E[: k + m, :n], self.lm_degrees[: k + m], self.active[:k], k, m, self.pairs, self.pL[:, :n],
                self.threads)
            self.pairs = np.vstack([self.pairs[keep], new])
            self.pL = np.vstack([self.pL[keep], _pack(new_lcms, self.field)])
            self.active[: k + m] = active
            return
        # activity spans of the partners: born (inserted) before t, made inactive by the first later h_u
        # whose lm divides theirs (a new lm cannot divide an earlier, larger one)
        partners = np.concatenate([self.active[:k].nonzero()[0], np.arange(k, k + m)])
        born = np.concatenate([np.full(len(partners) - m, -1), np.arange(m)])
        words = self.E.view(np.uint64)
        guard = _guard(self.field, words.shape[1])
        new_words = words[k : k + m]
        covered = _divides_words(new_words, words[partners], guard) & (np.arange(m)[None, :] > born[:, None])
        dies = np.where(covered.any(axis=1), covered.argmax(axis=1), m)
        # new pairs (g, h_t): all t at once through cubes of divisibility tests while they are small,
        # else t by t through the minimal lcms (see _new_pairs_by_degree)
        if m * len(partners) ** 2 <= CUBE_CELLS:
            new_pairs, new_lcms, new_born = self._new_pairs_cube(k, m, partners, born, dies, guard)
        else:
            new_pairs, new_lcms, new_born = self._new_pairs_by_degree(k, m, partners, born, dies, guard)
        # criterion B over the existing and the new pairs, by every h_u inserted after the pair
        pairs = np.vstack([self.pairs, *new_pairs])
        lcms = np.vstack([self.pL, *new_lcms])
        pair_born = np.concatenate([np.full(len(self.pairs), -1), *new_born])
        hit = _divides_words(new_words, lcms.view(np.uint64), guard) & (np.arange(m)[None, :] > pair_born[:, None])
        pp, uu = np.nonzero(hit)
        if len(pp):
            lead_u = self.E[k + uu]
            same_i = np.maximum(self.E[pairs[pp, 0]], lead_u).sum(axis=1, dtype=np.int64) == pairs[pp, 2]
            same_j = np.maximum(self.E[pairs[pp, 1]], lead_u).sum(axis=1, dtype=np.int64) == pairs[pp, 2]
            keep = np.ones(len(pairs), dtype=bool)
            keep[pp[~(same_i | same_j)]] = False
            pairs, lcms = pairs[keep], lcms[keep]
        self.pairs, self.pL = pairs, lcms
        self.active[partners] = dies == m

    def _new_pairs_cube(self, k: int, m: int, partners: np.ndarray, born: np.ndarray, dies: np.ndarray,
                        guard: np.ndarray) -> tuple[list, list, list]:
        """The new pairs (g, h_t) of :meth:`insert` for all t, a few t at a time: span[t, c] says partner c
        is active at time t; every partner's lcm with h_t is tested against every other's (m x P^2 tests).
        Returns lists of (pairs, lcms, insertion times t) arrays."""
        words = self.E.view(np.uint64)
        new_pairs, new_lcms, new_born = [], [], []
        step = max(1, (1 << 18) // len(partners) ** 2)
        for t0 in range(0, m, step):
            t = np.arange(t0, min(t0 + step, m))
            span = (born[None, :] < t[:, None]) & (dies[None, :] >= t[:, None])
            live = span.any(axis=0).nonzero()[0]
            if not len(live):
                continue
            span, cand = span[:, live], partners[live]
            L = np.maximum(self.E[cand][None, :, :], self.E[k + t][:, None, :])
            degrees = L.sum(axis=2, dtype=np.int64)
            coprime = degrees == self.lm_degrees[cand][None, :] + self.lm_degrees[k + t][:, None]
            # divides[t, c, c'] = lm(c') | lcm(c, h_t), i.e. lcm(c', h_t) | lcm(c, h_t), for partners c';
            # then the two lcms are equal iff their degrees are
            L_words = L.view(np.uint64)
            divides = _divides_words(words[cand], L_words.reshape(-1, L_words.shape[2]), guard)
            divides = divides.reshape(len(t), len(cand), len(cand)) & span[:, None, :]
            same = degrees[:, :, None] == degrees[:, None, :]
            equal = divides & same
            dominated = (divides > same).any(axis=2)
            has_coprime = (equal & coprime[:, None, :]).any(axis=2)
            first = equal.argmax(axis=2) == np.arange(len(cand))  # no earlier partner with this lcm
            tt, cc = np.nonzero(span & first & ~dominated & ~has_coprime)
            new_pairs.append(np.column_stack([cand[cc], k + t[tt], degrees[tt, cc]]))
            new_lcms.append(L[tt, cc])
            new_born.append(t[tt])
        return new_pairs, new_lcms, new_born

    def _new_pairs_by_degree(self, k: int, m: int, partners: np.ndarray, born: np.ndarray, dies: np.ndarray,
                             guard: np.ndarray) -> tuple[list, list, list]:
        """The same new pairs as :meth:`_new_pairs_cube`, t by t: the lcms of h_t with its partners by
        increasing degree, each degree's tested only against the minimal lcms of lower degrees (a proper
        divisor of an lcm has lower degree and is a multiple of a minimal one), so a round costs about
        m x P x (minimal lcms) tests instead of m x P^2."""
        new_pairs, new_lcms, new_born = [], [], []
        nbytes = 8 * self.E.view(np.uint64).shape[1]
        for t in range(m):
            cand = partners[(born < t) & (dies >= t)]
            if not len(cand):
                continue
            L = np.maximum(self.E[cand], self.E[k + t])
            degrees = L.sum(axis=1, dtype=np.int64)
            coprime = degrees == self.lm_degrees[cand] + self.lm_degrees[k + t]
            L_words = L.view(np.uint64)
            minimal = L_words[:0]
            kept = []
            for d in np.unique(degrees):
                sel = np.flatnonzero(degrees == d)
                if len(minimal):
                    sel = sel[~_divides_words(minimal, L_words[sel], guard).any(axis=1)]
                    if not len(sel):
                        continue
                # equal lcms (criterion F): the first partner's pair, none if one of them is coprime
                keys = np.ascontiguousarray(L_words[sel]).view(np.dtype((np.void, nbytes))).ravel()
                _, first, group = np.unique(keys, return_index=True, return_inverse=True)
                has_coprime = np.bincount(group.ravel(), weights=coprime[sel], minlength=len(first)) > 0
                kept.append(sel[first[~has_coprime]])
                minimal = np.vstack([minimal, L_words[sel[first]]])
            if not kept:
                continue
            keep = np.sort(np.concatenate(kept))
            new_pairs.append(np.column_stack([cand[keep], np.full(len(keep), k + t), degrees[keep]]))
            new_lcms.append(L[keep])
            new_born.append(np.full(len(keep), t))
        return new_pairs, new_lcms, new_born

    def find_reducer(self, m: int) -> int:
        """Index of the sparsest active basis element whose leading monomial divides m, or -1."""
        act = np.flatnonzero(self.active[: len(self.polys)])
        hits = act[np.all(self.lead_exponents(act) <= np.array(self.ring.exps(m)), axis=1)]
        if not len(hits):
            return -1
        return int(hits[np.argmin(self.lengths[hits])])


@dataclass(frozen=True)
class _Rows:
    """Rows mult[r] * g[index[r]] of an F4 matrix: multiplier codes, element indices and row lengths. Their
    terms are generated when needed (:meth:`entries`), a block at a time, and never kept for a whole
    matrix: 16 bytes per matrix entry that the assembled int32 blocks do not need."""

    mult: np.ndarray
    index: np.ndarray
    lengths: np.ndarray

    @staticmethod
    def of(state: "_State", mult: np.ndarray, index: np.ndarray, checked: bool = False) -> "_Rows":
        """The rows mult[r] * g[index[r]]; raises :class:`CodeOverflow` when a product could exceed the
        degrees the codes can hold (unless checked says that no term can exceed a degree already seen)."""
        codes = state.codes
        if len(index) and not codes.wide and not checked:
            top = int((codes.degrees(mult) + state.max_degrees[index]).max())
            if top > codes.max_degree:
                raise CodeOverflow(f"degree {top} exceeds the narrow monomial codes")
        return _Rows(mult, index, state.lengths[index])

    @staticmethod
    def concat(parts: Sequence["_Rows"]) -> "_Rows":
        return _Rows(*(np.concatenate([getattr(rows, f) for rows in parts]) for f in ("mult", "index", "lengths")))

    def entries(self, state: "_State", rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """The terms (monomial codes) of the given rows, concatenated."""
        mult, index, lengths = self.mult[rows], self.index[rows], self.lengths[rows]
        ends = np.cumsum(lengths)
        total = int(ends[-1]) if len(ends) else 0
        positions = np.repeat(state.starts[index] - (ends - lengths), lengths) + np.arange(total)
        return state.pool_codes[positions] + np.repeat(mult, lengths)

    def blocks(self, state: "_State", index: np.ndarray):
        """The terms of the rows at index a block of rows at a time (about _ASSEMBLE_BLOCK terms each, so
        that the int64 temporaries stay small): (first entry, end entry, codes) per block; entry numbers
        count the terms of the rows at index in order."""
        indptr = np.zeros(len(index) + 1, dtype=np.int64)
        np.cumsum(self.lengths[index], out=indptr[1:])
        if indptr[-1] <= _ASSEMBLE_BLOCK:
            yield 0, indptr[-1], self.entries(state, index)
            return
        bounds = _distinct(np.searchsorted(indptr, np.arange(0, int(indptr[-1]), _ASSEMBLE_BLOCK), side="right") - 1)
        for a, b in zip(bounds, [*bounds[1:], len(index)]):
            yield indptr[a], indptr[b], self.entries(state, index[a:b])


def _reducers(state: _State, act: np.ndarray, monomials: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each monomial code, the first element of act (the active elements by increasing length, in
    index order on ties: see :func:`_by_length`) whose leading monomial divides it: (mask of monomials
    that have one, their reducers)."""
    X = state.codes.decode(monomials)
    if native.kernel() is not None:
        best = native.first_divisors(state.lead_exponents(act), X)
        has = best >= 0
        return has, act[best[has]]
    field = _exponent_field(int(X.max(initial=0)))
    if field.itemsize < state.field.itemsize:
        field = state.field
    leads = state.E[act] if field == state.field else _pack(state.lead_exponents(act), field)
    lead_words, mono_words = leads.view(np.uint64), _pack(X, field).view(np.uint64)
    guard = _guard(field, lead_words.shape[1])
    chunk = max(1, 1_000_000 // len(act))
    if len(monomials) <= chunk:
        divides = _divides_words(lead_words, mono_words, guard)
        best = divides.argmax(axis=1)
        has = divides[np.arange(len(best)), best]
        return has, act[best[has]]
    best = np.zeros(len(monomials), dtype=np.int64)
    has = np.zeros(len(monomials), dtype=bool)
    for s in range(0, len(monomials), chunk):
        divides = _divides_words(lead_words, mono_words[s : s + chunk], guard)
        best[s : s + chunk] = divides.argmax(axis=1)
        has[s : s + chunk] = divides.any(axis=1)
    return has, act[best[has]]


def _by_length(state: _State) -> np.ndarray:
    """The active elements by increasing number of terms, in index order on ties (the preferred reducers
    first)."""
    act = state.active[: len(state.polys)].nonzero()[0]
    return act[state.lengths[act].argsort(kind="stable")]


def _distinct(values: np.ndarray) -> np.ndarray:
    """The distinct values, ascending (np.unique without its overhead, for short arrays)."""
    values = np.sort(values)
    if len(values) > 1:
        keep = np.empty(len(values), dtype=bool)
        keep[0] = True
        np.not_equal(values[1:], values[:-1], out=keep[1:])
        values = values[keep]
    return values


def _first_seen(terms: np.ndarray, known: np.ndarray) -> np.ndarray:
    """The distinct terms that are not in known (sorted), ascending."""
    if len(known):
        terms = terms[index_of(known, terms) < 0]
    return _distinct(terms)


def _new_terms(state: _State, rows: _Rows, known: np.ndarray) -> np.ndarray:
    """The distinct terms of the rows that are not in known (sorted), ascending: by the C kernel where it
    is built (no temporaries of the rows' size), else by :func:`_first_seen` a block of rows at a time."""
    if native.kernel() is not None and state.pool_codes.dtype == np.uint64:
        found = native.new_terms(state.pool_codes, state.starts[rows.index], rows.lengths, rows.mult, known)
        found.sort()
        return found
    found = [_first_seen(terms, known) for _, _, terms in rows.blocks(state, np.arange(len(rows.index)))]
    if len(found) == 1:
        return found[0]
    return _distinct(np.concatenate(found)) if found else known[:0]


def _graded(codes: MonomialCodes) -> bool:
    """Whether the order compares total degrees first: the most significant field of a code is the
    total degree."""
    top = codes.ring._nrows - 1
    return not codes.wide and list(codes._degree_fields) == [top] and int(codes._degree_weights[0]) == 1


def _preprocess(state: _State, rows: _Rows, leads_done: bool = True, threads: int = 1) -> tuple[_Rows, np.ndarray]:
    """Symbolic preprocessing on arrays: add a reducer row for every matrix monomial divisible by a lead.

    Works in waves: the monomials first seen in one wave are tested for divisibility against all active
    leading monomials at once; the reducer of a monomial is the sparsest basis element whose leading
    monomial divides it. With leads_done=False the leading monomials of the given rows get reducers too
    (tail reduction). Returns all rows, the given ones first and then the reducers wave by wave (within
    a wave by increasing monomial: the matrix and its reduction do not depend on that order), and the
    column codes ascending. The C kernel (narrow codes, graded order) shares the work among up to threads
    threads; the result is the same on any count.
    """
    codes = state.codes
    if native.kernel() is not None and _graded(codes):  # the same waves in C, one call
        act = _by_length(state)
        mult, index, columns = native.preprocess(
            state.pool_codes, state.starts, state.lengths, state.lm_codes, act, state.lead_exponents(act),
            codes._code_shifts, codes.max_degree, codes.ring._winv_t, rows.mult, rows.index, leads_done, threads)
        return _Rows.concat([rows, _Rows(mult, index, state.lengths[index])]), columns
    done = _distinct(state.lm_codes[rows.index] + rows.mult) if leads_done else state.pool_codes[:0]
    frontier = _new_terms(state, rows, done)
    seen = _distinct(np.concatenate([frontier, done]))
    parts = [rows]
    act = _by_length(state)
    # a reducer's leading monomial is a matrix monomial; in a degree order no other term is of higher
    # degree, so the reducers need no overflow check
    graded = _graded(state.codes)
    while len(frontier) and len(act):
        has, red_index = _reducers(state, act, frontier)
        if not len(red_index):
            break
        parts.append(_Rows.of(state, frontier[has] - state.lm_codes[red_index], red_index, graded))
        frontier = _new_terms(state, parts[-1], seen)
        seen = np.concatenate([seen, frontier])
        seen.sort(kind="stable")  # two sorted runs: a merge
    return _Rows.concat(parts), seen


def _assemble(state: _State, rows: _Rows, columns: np.ndarray, index: np.ndarray | None = None,
              threads: int = 1) -> SparseRows:
    """The rows (those at index, in that order, if given) as sparse rows over the column codes (ascending;
    column 0 is the largest monomial): int32 columns, the values read from the term pool through offsets
    (a row repeats its element's coefficients), so 4 bytes per matrix entry. The column indices are
    computed a block of rows at a time (:meth:`_Rows.blocks`), so that the int64 temporaries stay small (by
    the C kernel: all at once, on up to threads threads)."""
    if index is None:
        index = np.arange(len(rows.lengths))
    indptr = np.zeros(len(index) + 1, dtype=np.int64)
    np.cumsum(rows.lengths[index], out=indptr[1:])
    if native.kernel() is not None and columns.dtype == np.uint64:
        cols = native.column_indices(state.pool_codes, state.starts[rows.index[index]], rows.lengths[index],
                                     rows.mult[index], columns, threads)
    else:
        cols = np.empty(int(indptr[-1]), dtype=np.int32)
        last = len(columns) - 1
        for lo, hi, terms in rows.blocks(state, index):
            cols[lo:hi] = last - index_of(columns, terms)
    return SparseRows(indptr, cols, state.pool_coeffs, state.starts[rows.index[index]])


def _lead_columns(state: _State, rows: _Rows, columns: np.ndarray) -> np.ndarray:
    """The column of every row's leading term."""
    return len(columns) - 1 - np.searchsorted(columns, state.lm_codes[rows.index] + rows.mult)


def _split_pivots(leads: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One pivot row per leading column (the sparsest, the first on ties), the others to reduce:
    (pivot rows, rows to reduce), each in order of increasing length."""
    order = lengths.argsort(kind="stable")
    by_lead = leads[order].argsort(kind="stable")
    sorted_leads = leads[order[by_lead]]
    is_pivot = np.zeros(len(order), dtype=bool)
    if len(order):
        is_pivot[by_lead[0]] = True
        is_pivot[by_lead[1:][sorted_leads[1:] != sorted_leads[:-1]]] = True
    return order[is_pivot], order[~is_pivot]


def _pair_rows(
    state: _State, d: int, pi: np.ndarray, pj: np.ndarray, lcms: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The rows lcm/lm(g) * g of both sides of the pairs (i, j) of lcm degree d, without repeats, sorted
    by (multiplier, index): (multiplier codes, element indices)."""
    codes = state.codes
    if d > codes.max_degree:
        raise CodeOverflow(f"degree {d} exceeds the narrow monomial codes")
    index = np.concatenate([pi, pj])
    mult = codes.encode(np.vstack([lcms, lcms]) - state.lead_exponents(index))
    by_index = np.argsort(index, kind="stable")
    order = by_index[np.argsort(mult[by_index], kind="stable")]
    mult, index = mult[order], index[order]
    fresh = np.ones(len(index), dtype=bool)
    fresh[1:] = (mult[1:] != mult[:-1]) | (index[1:] != index[:-1])
    return mult[fresh], index[fresh]


# ----------------------------------------------------------------------------------------------
# the driver
# ----------------------------------------------------------------------------------------------
def groebner(polys: Sequence[Poly], options: F4Options = F4Options()) -> GroebnerResult:
    """Reduced Gröbner basis of the ideal generated by polys (all in one ring) by F4.

    Zero polynomials are ignored; a nonzero constant gives the basis [1]. The run uses narrow 64-bit
    monomial codes and is repeated with wide ones if a degree outgrows them.
    """
    t_start = time.perf_counter()
    if not polys:
        raise ValueError("empty system: no polynomials given")
    ring = polys[0].ring
    for f in polys:
        if f.ring != ring:
            raise ValueError("all polynomials must belong to the same ring")
    backend = get_backend(options.backend)
    if options.linear_substitution:
        result = _substitute_linear(polys, options)
        if result is not None:
            return GroebnerResult(ring, result.basis, result.rounds, time.perf_counter() - t_start, result.reduced)
    try:
        basis, rounds = _f4(ring, polys, backend, options, MonomialCodes(ring))
    except CodeOverflow as overflow:
        if options.verbose:
            print(f"[f4] {overflow}: restarting with wide codes", file=sys.stderr)
        basis, rounds = _f4(ring, polys, backend, options, MonomialCodes(ring, wide=True))
    return GroebnerResult(ring, basis, rounds, time.perf_counter() - t_start, options.reduced)


def _substitute_linear(polys: Sequence[Poly], options: F4Options) -> GroebnerResult | None:
    """The reduced basis through the linear inputs, or None when there are none (or no gain).

    The linear inputs in reduced echelon form are x_i - l_i with leading variables x_i and tails l_i in
    the other, smaller variables. Substituting x_i = l_i into the other inputs gives polynomials J free
    of every x_i, and {x_i - l_i} together with a Gröbner basis of J is a Gröbner basis of the ideal in
    every monomial order: reducing f of the ideal by the x_i - l_i replaces monomials by smaller ones, so
    an x_i-free leading monomial survives into the result, which lies in (J). Tails are then reduced
    (with ``options.reduced`` False they are not: the union is already minimal, as no x_i divides an
    x_i-free leading monomial and the x_i are distinct).
    """
    ring = polys[0].ring
    linear = [f for f in polys if f and f.total_degree() == 1]
    if not linear:
        return None
    # reduced whatever options.reduced says: the tails l_i must be free of every leading variable
    solved = groebner(linear, F4Options(options.backend, options.max_matrix_cells, options.max_memory))
    if solved.is_unit:
        return solved
    tails = {g.lm: Poly(ring, g.mons[1:], [ring.prime - c for c in g.coeffs[1:]]) for g in solved.basis}
    rest = [h for h in (_substitute(f, tails) for f in polys if f and f.total_degree() != 1) if h]
    if not rest:
        return GroebnerResult(ring, solved.basis, solved.rounds)
    others = groebner(rest, options)
    if others.is_unit:
        return others
    if not options.reduced:
        return GroebnerResult(ring, tuple(sorted(solved.basis + others.basis, key=lambda g: g.lm)),
                              solved.rounds + others.rounds, reduced=False)
    try:
        basis = interreduce(list(solved.basis) + list(others.basis), options)
    except CodeOverflow:
        return None
    return GroebnerResult(ring, tuple(basis), solved.rounds + others.rounds)


def _substitute(f: Poly, tails: dict[int, Poly]) -> Poly:
    """f with every variable x (a key of ``tails``) replaced by tails[x] (powers computed once each)."""
    ring = f.ring
    variables = [(i, ring.variable_key(i)) for i in range(ring.nvars) if ring.variable_key(i) in tails]
    powers: dict[tuple[int, int], Poly] = {}
    acc: dict[int, int] = {}
    p = ring.prime
    for key, c in zip(f.mons, f.coeffs):
        e = ring.exps(key)
        term = Poly(ring, [key - sum(e[i] * k for i, k in variables)], [c])
        for i, k in variables:
            if e[i]:
                power = powers.get((i, e[i]))
                if power is None:
                    power = powers[(i, e[i])] = tails[k] ** e[i]
                term = term * power
        for m, v in zip(term.mons, term.coeffs):
            acc[m] = (acc.get(m, 0) + v) % p
    return Poly.from_dict(ring, acc)


def _f4(
    ring: Ring, polys: Sequence[Poly], backend: Backend, options: F4Options, codes: MonomialCodes
) -> tuple[tuple[Poly, ...], tuple[RoundStats, ...]]:
    """The F4 loop of :func:`groebner`: (reduced basis, round statistics)."""
    p = ring.prime
    max_memory = default_max_memory() if options.max_memory is None else options.max_memory
    state = _State(ring, codes, options.threads)
    rounds: list[RoundStats] = []

    # in a degree order the terms of the pair rows are of degree at most the pairs' (checked by
    # _pair_rows), so the rows need no overflow check of their own
    graded = _graded(codes)
    inputs = [f.monic() for f in polys if f]
    if not inputs:  # only zero polynomials: the zero ideal
        return (), ()
    if any(f.is_constant() for f in inputs):
        return (ring.one(),), ()
    # initial inter-reduction of the input as one matrix: rows to reduce with no pivots remove
    # duplicates and dependencies; then insert by decreasing lm
    cols = sorted({k for f in inputs for k in f.mons}, reverse=True)
    col_of = {m: c for c, m in enumerate(cols)}
    rows = SparseRows.from_rows([([col_of[k] for k in f.mons], f.coeffs) for f in inputs])
    if _insert_rows(state, backend.reduce_sparse(rows.take([]), rows, len(cols), p, options.threads),
                    codes.from_keys(cols)):
        return (ring.one(),), ()
    while state.npairs:
        t0 = time.perf_counter()
        d, pi, pj, lcms = state.pop_pairs()
        npairs = len(pi)
        rows, columns = _preprocess(state, _Rows.of(state, *_pair_rows(state, d, pi, pj, lcms), graded),
                                    threads=options.threads)
        nrows, ncols = len(rows.index), len(columns)
        if options.max_matrix_cells is not None and nrows * ncols > options.max_matrix_cells:
            raise MatrixTooLarge(
                f"F4 matrix {nrows} x {ncols} at degree {d} exceeds the cap of {options.max_matrix_cells} cells"
            )
        nonzeros = int(rows.lengths.sum())
        leads = _lead_columns(state, rows, columns)
        pivot_rows, reduce_rows = _split_pivots(leads, rows.lengths)
        dense = backend.name == "numpy" or (backend.name == "auto" and not sparse_pays(
            len(pivot_rows), int(rows.lengths[pivot_rows].sum()), len(reduce_rows), ncols))
        need = matrix_memory(len(reduce_rows), ncols, nonzeros, dense)
        if need > max_memory:
            raise MatrixTooLarge(
                f"F4 matrix {nrows} x {ncols} at degree {d} needs about {format_bytes(need)}, above the memory cap "
                f"of {format_bytes(max_memory)}" + ("" if options.max_memory is not None else
                                                    f" ({MEMORY_SHARE:.0%} of the machine's available memory)")
            )
        pivot_rows = pivot_rows[leads[pivot_rows].argsort()]  # by lead: the backend need not sort
        # the two blocks straight from the rows' terms (no whole matrix and copies of it)
        pivots = _assemble(state, rows, columns, pivot_rows, options.threads)
        to_reduce = _assemble(state, rows, columns, reduce_rows, options.threads)
        del rows
        new_rows = backend.reduce_sparse(pivots, to_reduce, ncols, p, options.threads)
        del pivots, to_reduce
        if _insert_rows(state, new_rows, columns[::-1]):
            return (ring.one(),), tuple(rounds)
        stats = RoundStats(
            degree=d,
            pairs=npairs,
            rows=nrows,
            cols=ncols,
            density=nonzeros / max(1, nrows * ncols),
            new=len(new_rows),
            zero_reductions=len(reduce_rows) - len(new_rows),
            seconds=time.perf_counter() - t0,
        )
        rounds.append(stats)
        if options.verbose:
            print(
                f"[f4] deg {d:3d}  pairs {npairs:5d}  matrix {nrows:6d} x {ncols:6d}  "
                f"density {stats.density:6.2%}  new {stats.new:4d}  zero {stats.zero_reductions:5d}  "
                f"{stats.seconds:7.3f}s  memory estimate {format_bytes(need)}{_peak_rss()}",
                file=sys.stderr,
            )
    if not options.reduced:
        return tuple(_minimal_basis(state)), tuple(rounds)
    return tuple(_reduce_basis(state, backend, options.threads)), tuple(rounds)


def _peak_rss() -> str:
    """``, peak RSS 4.1 GiB``: the process's peak resident memory so far (Linux /proc), for the verbose
    lines beside :func:`matrix_memory`'s estimate; empty where /proc is not there."""
    try:
        with open("/proc/self/status") as handle:
            for line in handle:
                if line.startswith("VmHWM:"):
                    return f", peak RSS {format_bytes(int(line.split()[1]) * 1024)}"
    except OSError:
        pass
    return ""


def _insert_rows(state: _State, rows: SparseRows, columns: np.ndarray) -> bool:
    """Insert the rows of a reduced row echelon form (over columns: codes, decreasing) into the basis;
    True when one of them is a nonzero constant (the unit ideal)."""
    terms = columns[rows.cols]
    if not len(rows):
        return False
    if (terms[rows.indptr[:-1]] == 0).any():
        return True
    # increasing leading column is decreasing lm: no new lm divides an earlier one
    state.insert(terms, rows.vals, rows.indptr, [None] * len(rows))
    return False


def interreduce(basis: Sequence[Poly], options: F4Options = F4Options()) -> list[Poly]:
    """The reduced Gröbner basis from a minimal one (monic elements of one ring, no leading monomial
    dividing another's), by the tail reduction that ends :func:`groebner` (:func:`_reduce_basis`).

    Raises :class:`analysis.engine.ring.CodeOverflow` when a reducer's degree outgrows the narrow monomial codes
    (possible in a non-graded order); callers then reduce another way.
    """
    if not basis:
        return []
    state = _State(basis[0].ring)
    state.store_minimal(sorted(basis, key=lambda g: g.lm, reverse=True))
    return _reduce_basis(state, get_backend(options.backend), options.threads)


def _minimal_basis(state: _State) -> list[Poly]:
    """The active elements as they are (monic, tails as F4 left them): a minimal Gröbner basis, sorted by
    leading monomial. Each distinct monomial is decoded once and its key shared by the terms that have
    it (katsura-10 at 2^31 - 1: peak memory 150 -> 75 MB; the reduced basis 68 MB), then split element by
    element. The keys are spread over the terms by one take from an object array (katsura-10, 383k terms:
    2 ms against 15 ms for a Python lookup per term): this step runs on one thread whatever ``threads``."""
    ring = state.ring
    idx = np.flatnonzero(state.active[: len(state.polys)])
    starts, lengths = state.starts[idx], state.lengths[idx]
    terms = np.repeat(starts - np.cumsum(lengths) + lengths, lengths) + np.arange(int(lengths.sum()))
    distinct, inverse = np.unique(state.pool_codes[terms], return_inverse=True)
    distinct_keys = np.empty(len(distinct), dtype=object)
    distinct_keys[:] = state.codes.to_keys(distinct)
    keys = distinct_keys[inverse.ravel()]
    coeffs = state.pool_coeffs[terms].tolist()
    bounds = np.concatenate([[0], np.cumsum(lengths)]).tolist()
    basis = [Poly(ring, keys[a:b].tolist(), coeffs[a:b]) for a, b in zip(bounds, bounds[1:])]
    basis.sort(key=lambda g: g.lm)
    return basis


def _reduce_basis(state: _State, backend: Backend, threads: int = 1) -> list[Poly]:
    """Minimal basis (active elements) with tails fully reduced: the reduced Gröbner basis.

    Symbolic preprocessing of the active elements supplies a reducer for every tail monomial that is
    divisible by a leading monomial; the tails are then reduced by these pivot rows, each on its own.
    """
    ring = state.ring
    idx = np.flatnonzero(state.active[: len(state.polys)])
    elements = _Rows.of(state, np.zeros(len(idx), dtype=state.codes.dtype), idx, checked=True)  # the elements
    rows, columns = _preprocess(state, elements, leads_done=False, threads=threads)
    pivots = _assemble(state, rows, columns, np.arange(len(idx), len(rows.index)), threads)
    heads = _assemble(state, rows, columns, np.arange(len(idx))).compact()
    del rows
    tail = np.ones(len(heads.cols), dtype=bool)
    tail[heads.indptr[:-1]] = False
    tails = SparseRows(heads.indptr - np.arange(len(idx) + 1), heads.cols[tail], heads.vals[tail])
    reduced = backend.reduce_each_sparse(pivots, tails, len(columns), ring.prime, threads)
    column_keys = state.codes.to_keys(columns[::-1])  # fewer than the terms: decode each column once
    # a small field's coefficients as shared int objects when there are more terms than field elements:
    # 8 bytes per coefficient instead of 36 (quadrics-11: 1.5M terms, 42 MB less at the peak)
    values = list(range(ring.prime)) if ring.prime <= COEFFICIENT_TABLE and len(reduced.vals) > ring.prime else None
    bounds = reduced.indptr.tolist()
    basis = []
    # element by element: no list of all terms beside the polynomials' own
    for lm, a, b in zip(state.codes.to_keys(state.lm_codes[idx]), bounds, bounds[1:]):
        keys = map(column_keys.__getitem__, reduced.cols[a:b].tolist())
        coeffs = reduced.vals[a:b].tolist()
        basis.append(Poly(ring, [lm, *keys], [1, *(coeffs if values is None else map(values.__getitem__, coeffs))]))
    basis.sort(key=lambda g: g.lm)
    return basis
