"""Faugère's F4 over GF(p): select -> symbolic preprocessing -> reduce -> update.

The driver :func:`groebner` keeps one :class:`RoundStats` per round and returns the reduced Gröbner
basis. Pairs are selected by the normal strategy (all pairs of minimal lcm degree), pruned with the
Gebauer-Möller criteria; the linear algebra is delegated to a backend of :mod:`analysis.linalg`.

Reference: J.-C. Faugère, "A new efficient algorithm for computing Gröbner bases (F4)", JPAA 1999;
R. Gebauer and H. M. Möller, "On an installation of Buchberger's algorithm", JSC 1988.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .linalg import MatrixTooLarge, Row, get_backend
from .ring import Poly, Ring


@dataclass(frozen=True)
class F4Options:
    """Options of an F4 run.

    backend: linear algebra backend ("numpy" fast, "python" reference).
    max_matrix_cells: stop with :class:`MatrixTooLarge` when rows*cols of a matrix exceeds this.
    verbose: print one line per round to stderr.
    """

    backend: str = "numpy"
    max_matrix_cells: int = 400_000_000
    verbose: bool = False


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
    """A reduced Gröbner basis with its per-round statistics."""

    ring: Ring
    basis: tuple[Poly, ...]
    rounds: tuple[RoundStats, ...] = field(repr=False)
    seconds: float = 0.0

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


def _pack_words(E: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pack exponent rows into uint64 words with guard bits: (words, guard mask per word).

    8-bit fields (exponents < 128) when possible, else 16-bit fields; a | b for packed rows is then
    ((b | guard) - a) & guard == guard in every word, with no borrow between fields.
    """
    top = int(E.max(initial=0))
    bits = 8 if top < 128 else 16 if top < 32768 else 0
    if not bits:
        raise OverflowError("exponent too large for packed divisibility tests")
    per_word = 64 // bits
    n = E.shape[1]
    nwords = -(-n // per_word)
    words = np.zeros((len(E), nwords), dtype=np.uint64)
    guard = np.zeros(nwords, dtype=np.uint64)
    for v in range(n):
        w, f = divmod(v, per_word)
        words[:, w] |= E[:, v].astype(np.uint64) << np.uint64(bits * f)
        guard[w] |= np.uint64(1 << (bits * f + bits - 1))
    return words, guard


def _divides(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Row-wise (broadcast) test that exponent rows A divide exponent rows B."""
    A, B = np.broadcast_arrays(A, B)
    words, guard = _pack_words(np.concatenate([A, B]))
    a, b = words[: len(A)], words[len(A) :]
    return np.all(((b | guard) - a) & guard == guard, axis=1)


def _divides_matrix(L: np.ndarray) -> np.ndarray:
    """le[i, j] = (row j of L divides row i of L), by packed words with guard bits."""
    words, guard = _pack_words(L)
    le = np.ones((len(L), len(L)), dtype=bool)
    for w in range(words.shape[1]):
        col = words[:, w]
        le &= (((col | guard[w])[:, None] - col[None, :]) & guard[w]) == guard[w]
    return le


class _State:
    """The growing basis G and the pair set, with a vectorised Gebauer-Möller update.

    Exponent vectors of the leading monomials and of the pair lcms live in numpy arrays, so each
    insertion costs a few array operations instead of Python loops over all pairs.
    """

    def __init__(self, ring: Ring):
        self.ring = ring
        n = ring.nvars
        self.polys: list[Poly] = []
        self.lms: list[int] = []
        self.active_list: list[bool] = []
        self.E = np.zeros((16, n), dtype=np.int32)
        self.active = np.zeros(16, dtype=bool)
        # pairs: parallel arrays (i, j, lcm exponents, lcm degree)
        self.pi = np.zeros(0, dtype=np.int64)
        self.pj = np.zeros(0, dtype=np.int64)
        self.pL = np.zeros((0, n), dtype=np.int32)
        self.pdeg = np.zeros(0, dtype=np.int64)

    @property
    def npairs(self) -> int:
        return len(self.pi)

    def pop_pairs(self) -> tuple[int, list[tuple[int, int, tuple[int, ...]]]]:
        """Remove and return the pairs of minimal lcm degree (normal strategy): (degree, [(i, j, lcm)])."""
        d = int(self.pdeg.min())
        sel = self.pdeg == d
        out = [(int(i), int(j), tuple(int(x) for x in L)) for i, j, L in zip(self.pi[sel], self.pj[sel], self.pL[sel])]
        keep = ~sel
        self.pi, self.pj, self.pL, self.pdeg = self.pi[keep], self.pj[keep], self.pL[keep], self.pdeg[keep]
        return d, out

    def add(self, h: Poly) -> None:
        """Insert h (monic, lm not divisible by any lm of G) and update the pairs.

        Gebauer-Möller as in Becker-Weispfenning's UPDATE: among the new pairs (g, h) drop those whose
        lcm is a proper multiple of another new pair's lcm (criterion M), keep one per equal lcm unless
        one of them is coprime (criterion F, then all go by Buchberger's first criterion); drop old pairs
        whose lcm is divisible by lm(h) with both lcms against h different (criterion B).
        """
        ring = self.ring
        k = len(self.polys)
        eh = np.array(ring.exps(h.lm), dtype=np.int32)
        if k == len(self.E):
            self.E = np.vstack([self.E, np.zeros_like(self.E)])
            self.active = np.concatenate([self.active, np.zeros_like(self.active)])
        self.polys.append(h)
        self.lms.append(h.lm)
        self.E[k] = eh
        # criterion B on old pairs
        if len(self.pi):
            divisible = np.flatnonzero(_divides(eh[None, :], self.pL))
            if len(divisible):
                sub = self.pL[divisible]
                eq_i = np.all(np.maximum(self.E[self.pi[divisible]], eh) == sub, axis=1)
                eq_j = np.all(np.maximum(self.E[self.pj[divisible]], eh) == sub, axis=1)
                drop = divisible[~(eq_i | eq_j)]
                if len(drop):
                    keep = np.ones(len(self.pi), dtype=bool)
                    keep[drop] = False
                    self.pi, self.pj, self.pL, self.pdeg = self.pi[keep], self.pj[keep], self.pL[keep], self.pdeg[keep]
        act = np.flatnonzero(self.active[:k])
        if len(act):
            Ea = self.E[act]
            L = np.maximum(Ea, eh)
            coprime = ~np.any((Ea > 0) & (eh > 0), axis=1)
            # criteria M and F: le[i, j] says lcm_j divides lcm_i
            le = _divides_matrix(L)
            eq = le & le.T
            dominated = np.any(le & ~eq, axis=1)
            has_coprime = np.any(eq & coprime[None, :], axis=1)
            first = ~np.any(np.tril(eq, -1), axis=1)
            keep_new = ~dominated & ~has_coprime & first
            if keep_new.any():
                Lk = L[keep_new]
                self.pi = np.concatenate([self.pi, act[keep_new]])
                self.pj = np.concatenate([self.pj, np.full(int(keep_new.sum()), k, dtype=np.int64)])
                self.pL = np.vstack([self.pL, Lk])
                self.pdeg = np.concatenate([self.pdeg, Lk.sum(axis=1, dtype=np.int64)])
            redundant = np.all(Ea >= eh, axis=1)
            self.active[act[redundant]] = False
        self.active[k] = True

    def find_reducer(self, m: int) -> int:
        """Index of the sparsest active basis element whose leading monomial divides m, or -1."""
        act = np.flatnonzero(self.active[: len(self.polys)])
        if not len(act):
            return -1
        hits = act[np.all(self.E[act] <= np.array(self.ring.exps(m)), axis=1)]
        if not len(hits):
            return -1
        return int(min(hits, key=lambda i: len(self.polys[i])))


def _symbolic_preprocessing(
    state: _State, rows: list[tuple[int, int]], leads_done: bool = True
) -> tuple[list[tuple[int, int]], list[int]]:
    """Add reducer rows for every matrix monomial divisible by a leading monomial.

    Works in waves: the monomials first seen in one wave are decoded in bulk and tested for divisibility
    against all active leading monomials with one array comparison; the reducer of a monomial is the
    sparsest basis element whose leading monomial divides it. rows: list of (multiplier key, basis index).
    With leads_done=False the leading monomials of the given rows get reducers too (tail reduction).
    Returns all rows and the column monomials in decreasing order.
    """
    polys = state.polys
    ring = state.ring
    seen: set[int] = set()
    done: set[int] = set()
    frontier: list[int] = []
    for t, i in rows:
        g = polys[i]
        if leads_done:
            done.add(t + g.lm)
        for k in g.mons:
            m = t + k
            if m not in seen:
                seen.add(m)
                frontier.append(m)
    out_rows = list(rows)
    act = np.flatnonzero(state.active[: len(polys)])
    e_act = state.E[act]
    lengths = np.array([len(polys[i]) for i in act], dtype=np.int64)
    big = np.iinfo(np.int64).max
    while frontier:
        cand = [m for m in frontier if m not in done]
        frontier = []
        if not cand or not len(act):
            break
        X = ring.decode_many(cand)
        chunk = max(1, 2_000_000 // max(1, e_act.size))
        for s in range(0, len(cand), chunk):
            divides = np.all(e_act[None, :, :] <= X[s : s + chunk, None, :], axis=2)
            cost = np.where(divides, lengths[None, :], big)
            best = cost.argmin(axis=1)
            has = cost[np.arange(len(best)), best] != big
            for r in np.flatnonzero(has):
                m = cand[s + r]
                idx = int(act[best[r]])
                g = polys[idx]
                t = m - g.lm
                done.add(m)
                out_rows.append((t, idx))
                for k in g.mons:
                    mm = t + k
                    if mm not in seen:
                        seen.add(mm)
                        frontier.append(mm)
    return out_rows, sorted(seen, reverse=True)


def select_pairs(state: _State) -> tuple[int, list, list[tuple[int, int]]]:
    """Pop the pairs of minimal lcm degree; return (degree, pairs, sorted rows (multiplier key, index))."""
    ring = state.ring
    d, sel = state.pop_pairs()
    row_set: set[tuple[int, int]] = set()
    for i, j, le in sel:
        for k in (i, j):
            t_exps = tuple(a - b for a, b in zip(le, ring.exps(state.lms[k])))
            row_set.add((ring.key(t_exps), k))
    return d, sel, sorted(row_set)


def split_pivots(matrix: Sequence[Row]) -> tuple[dict[int, int], list[int]]:
    """One pivot row per leading column (the sparsest), the others to reduce: (column -> row, rows)."""
    pivots: dict[int, int] = {}
    to_reduce: list[int] = []
    for r in sorted(range(len(matrix)), key=lambda r: len(matrix[r][0])):
        lead = matrix[r][0][0]
        if lead not in pivots:
            pivots[lead] = r
        else:
            to_reduce.append(r)
    return pivots, to_reduce


def _build_matrix(state: _State, rows: list[tuple[int, int]], columns: list[int]):
    col_of = {m: c for c, m in enumerate(columns)}
    polys = state.polys
    built: list[Row] = []
    for t, i in rows:
        g = polys[i]
        built.append(([col_of[t + k] for k in g.mons], g.coeffs))
    return built


def groebner(polys: Sequence[Poly], options: F4Options = F4Options()) -> GroebnerResult:
    """Reduced Gröbner basis of the ideal generated by polys (all in one ring) by F4.

    Zero polynomials are ignored; a nonzero constant gives the basis [1].
    """
    t_start = time.perf_counter()
    if not polys:
        raise ValueError("empty system: no polynomials given")
    ring = polys[0].ring
    for f in polys:
        if f.ring != ring:
            raise ValueError("all polynomials must belong to the same ring")
    backend = get_backend(options.backend)
    p = ring.prime
    state = _State(ring)
    rounds: list[RoundStats] = []

    inputs = [f.monic() for f in polys if f]
    if not inputs:  # only zero polynomials: the zero ideal
        return GroebnerResult(ring, (), (), time.perf_counter() - t_start)
    if any(f.is_constant() for f in inputs):
        return GroebnerResult(ring, (ring.one(),), (), time.perf_counter() - t_start)
    # initial inter-reduction of the input as one matrix: echelon form, then insert by increasing lm
    if inputs:
        # treat inputs as rows to reduce with no pivots: this removes duplicates and dependencies
        cols = sorted({k for f in inputs for k in f.mons}, reverse=True)
        col_of = {m: c for c, m in enumerate(cols)}
        rows = [([col_of[k] for k in f.mons], f.coeffs) for f in inputs]
        ech = backend.reduce({}, rows, len(cols), p)
        for c, v in sorted(ech, key=lambda r: r[0][0]):  # decreasing lm: no new lm divides an earlier one
            h = Poly(ring, [cols[j] for j in c], list(v))
            _insert(state, h)
    while state.npairs:
        t0 = time.perf_counter()
        d, sel, rows = select_pairs(state)
        rows, columns = _symbolic_preprocessing(state, rows)
        ncols = len(columns)
        if len(rows) * ncols > options.max_matrix_cells:
            raise MatrixTooLarge(
                f"F4 matrix {len(rows)} x {ncols} at degree {d} exceeds the cap of {options.max_matrix_cells} cells"
            )
        matrix = _build_matrix(state, rows, columns)
        pivot_index, reduce_index = split_pivots(matrix)
        pivots = {c: matrix[r] for c, r in pivot_index.items()}
        to_reduce = [matrix[r] for r in reduce_index]
        nnz = sum(len(r[0]) for r in matrix)
        new_rows = backend.reduce(pivots, to_reduce, ncols, p)
        for c, v in sorted(new_rows, key=lambda r: r[0][0]):  # decreasing lm: no new lm divides an earlier one
            h = Poly(ring, [columns[j] for j in c], list(v))
            if h.is_constant():
                return GroebnerResult(ring, (ring.one(),), tuple(rounds), time.perf_counter() - t_start)
            _insert(state, h)
        stats = RoundStats(
            degree=d,
            pairs=len(sel),
            rows=len(matrix),
            cols=ncols,
            density=nnz / max(1, len(matrix) * ncols),
            new=len(new_rows),
            zero_reductions=len(to_reduce) - len(new_rows),
            seconds=time.perf_counter() - t0,
        )
        rounds.append(stats)
        if options.verbose:
            print(
                f"[f4] deg {d:3d}  pairs {len(sel):5d}  matrix {len(matrix):6d} x {ncols:6d}  "
                f"density {stats.density:6.2%}  new {stats.new:4d}  zero {stats.zero_reductions:5d}  "
                f"{stats.seconds:7.3f}s",
                file=sys.stderr,
            )
    basis = _reduce_basis(state, backend)
    return GroebnerResult(ring, tuple(basis), tuple(rounds), time.perf_counter() - t_start)


def _insert(state: _State, h: Poly) -> None:
    for k in h.mons:
        state.ring.exps(k)
    state.add(h)


def _reduce_basis(state: _State, backend) -> list[Poly]:
    """Minimal basis (active elements) with tails fully reduced: the reduced Gröbner basis.

    Symbolic preprocessing of the active elements supplies a reducer for every tail monomial that is
    divisible by a leading monomial; the tails are then reduced by these pivot rows, each on its own.
    """
    ring = state.ring
    idx = [int(i) for i in np.flatnonzero(state.active[: len(state.polys)])]
    rows, columns = _symbolic_preprocessing(state, [(0, i) for i in idx], leads_done=False)
    col_of = {m: c for c, m in enumerate(columns)}
    pivots: dict[int, Row] = {}
    for t, j in rows[len(idx) :]:
        g = state.polys[j]
        r = ([col_of[t + k] for k in g.mons], g.coeffs)
        pivots[r[0][0]] = r
    tails = [([col_of[k] for k in state.polys[i].mons[1:]], state.polys[i].coeffs[1:]) for i in idx]
    reduced = backend.reduce_each(pivots, tails, len(columns), ring.prime)
    basis = []
    for i, (c, v) in zip(idx, reduced):
        g = state.polys[i]
        basis.append(Poly(ring, [g.lm] + [columns[j] for j in c], [1] + list(v)))
    basis.sort(key=lambda g: g.lm)
    return basis
