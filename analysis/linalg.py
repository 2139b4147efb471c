"""Mod-p row reduction for F4 matrices behind one interface, with interchangeable backends.

An F4 matrix is given as *pivot rows* (one per pivot column, leading coefficient 1; these are the
reducers found by symbolic preprocessing) and *rows to reduce*. A row is a pair of lists
``(cols, vals)``, columns strictly increasing (column 0 is the largest monomial), values in [1, p);
a block of rows is also held in compressed form as :class:`SparseRows`. Every backend implements two
operations, each on row lists (pivots as a dict leading column -> row) and on :class:`SparseRows`
(pivot rows in any order):

``reduce(pivots, rows, ncols, p)`` / ``reduce_sparse``
    reduce each row fully by the pivot rows (afterwards no row has an entry in a pivot column), then
    bring the results to reduced row echelon form and return its nonzero rows (monic, sorted by leading
    column). This is one F4 reduction step: the returned rows are the new basis elements.
``reduce_each(pivots, rows, ncols, p)`` / ``reduce_each_sparse``
    reduce each row fully by the pivot rows, without combining rows (used for tail reduction).

Backends: ``"python"`` is the slow, obviously correct reference used in tests; ``"numpy"`` does the
elimination with dense float64 BLAS products (a blocked triangular solve against the pivot rows) and
the echelon form with a blocked row-by-row elimination. Both must return identical rows.
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import chain
from typing import Callable, Literal, Sequence

import numpy as np

Row = tuple[list[int], list[int]]
BackendName = Literal["python", "numpy"]
BACKENDS = ("python", "numpy")


class MatrixTooLarge(RuntimeError):
    """An F4 matrix exceeded the configured size cap."""


@dataclass(frozen=True)
class SparseRows:
    """Sparse rows in compressed form: row i has columns ``cols[indptr[i]:indptr[i + 1]]`` (strictly
    increasing) with values ``vals[indptr[i]:indptr[i + 1]]`` in [1, p). All arrays are int64."""

    indptr: np.ndarray
    cols: np.ndarray
    vals: np.ndarray

    @staticmethod
    def from_rows(rows: Sequence[Row]) -> "SparseRows":
        lengths = np.fromiter((len(c) for c, _ in rows), dtype=np.int64, count=len(rows))
        indptr = np.zeros(len(rows) + 1, dtype=np.int64)
        np.cumsum(lengths, out=indptr[1:])
        total = int(indptr[-1])
        cols = np.fromiter(chain.from_iterable(c for c, _ in rows), dtype=np.int64, count=total)
        vals = np.fromiter(chain.from_iterable(v for _, v in rows), dtype=np.int64, count=total)
        return SparseRows(indptr, cols, vals)

    @staticmethod
    def from_dense(m: np.ndarray, columns: np.ndarray | None = None) -> "SparseRows":
        """The nonzero entries of a dense matrix, row by row; columns relabels the matrix columns."""
        r, c = np.nonzero(m)
        indptr = np.zeros(len(m) + 1, dtype=np.int64)
        np.cumsum(np.bincount(r, minlength=len(m)), out=indptr[1:])
        return SparseRows(indptr, (c if columns is None else columns[c]).astype(np.int64), m[r, c].astype(np.int64))

    def __len__(self) -> int:
        return len(self.indptr) - 1

    @property
    def lengths(self) -> np.ndarray:
        return np.diff(self.indptr)

    @property
    def leads(self) -> np.ndarray:
        """Leading column of every row (rows must be nonzero)."""
        return self.cols[self.indptr[:-1]]

    def take(self, index: np.ndarray) -> "SparseRows":
        """The rows at the given positions, in that order."""
        index = np.asarray(index, dtype=np.int64)
        lengths = self.lengths[index]
        indptr = np.zeros(len(index) + 1, dtype=np.int64)
        np.cumsum(lengths, out=indptr[1:])
        gather = np.repeat(self.indptr[index] - indptr[:-1], lengths) + np.arange(int(indptr[-1]))
        return SparseRows(indptr, self.cols[gather], self.vals[gather])

    def to_rows(self) -> list[Row]:
        bounds = self.indptr.tolist()
        cols, vals = self.cols.tolist(), self.vals.tolist()
        return [(cols[a:b], vals[a:b]) for a, b in zip(bounds, bounds[1:])]

    def to_dense(self, ncols: int, dtype=np.int64) -> np.ndarray:
        m = np.zeros((len(self), ncols), dtype=dtype)
        m[np.repeat(np.arange(len(self)), self.lengths), self.cols] = self.vals
        return m


def _pivot_rows(pivots: dict[int, Row]) -> SparseRows:
    return SparseRows.from_rows([pivots[c] for c in sorted(pivots)])


# ----------------------------------------------------------------------------------------------
# reference backend
# ----------------------------------------------------------------------------------------------
def _reduce_dict(row: dict[int, int], pivots: dict[int, Row], p: int) -> dict[int, int]:
    """Fully reduce a dict row by the pivot rows, eliminating pivot columns left to right."""
    import heapq

    heap = [c for c in row if c in pivots]
    heapq.heapify(heap)
    while heap:
        c = heapq.heappop(heap)
        a = row.get(c)
        if not a:
            continue
        pc, pv = pivots[c]
        for cc, v in zip(pc, pv):
            nv = (row.get(cc, 0) - a * v) % p
            if nv:
                if cc not in row and cc in pivots:
                    heapq.heappush(heap, cc)
                row[cc] = nv
            else:
                row.pop(cc, None)
    return row


def _rref_dicts(rows: list[dict[int, int]], p: int) -> list[dict[int, int]]:
    """Reduced row echelon form of dict rows."""
    echelon: dict[int, dict[int, int]] = {}
    for row in rows:
        row = _reduce_dict(dict(row), {c: (sorted(r), [r[k] for k in sorted(r)]) for c, r in echelon.items()}, p)
        if not row:
            continue
        lead = min(row)
        inv = pow(row[lead], -1, p)
        row = {c: v * inv % p for c, v in row.items()}
        # back-substitute into the existing echelon rows
        for r in echelon.values():
            a = r.get(lead)
            if a:
                for c, v in row.items():
                    nv = (r.get(c, 0) - a * v) % p
                    if nv:
                        r[c] = nv
                    else:
                        r.pop(c, None)
        echelon[lead] = row
    return [echelon[c] for c in sorted(echelon)]


def _to_row(d: dict[int, int]) -> Row:
    cols = sorted(d)
    return cols, [d[c] for c in cols]


def python_reduce(pivots: dict[int, Row], rows: Sequence[Row], ncols: int, p: int) -> list[Row]:
    reduced = [_reduce_dict(dict(zip(c, v)), pivots, p) for c, v in rows]
    return [_to_row(d) for d in _rref_dicts([d for d in reduced if d], p)]


def python_reduce_each(pivots: dict[int, Row], rows: Sequence[Row], ncols: int, p: int) -> list[Row]:
    return [_to_row(_reduce_dict(dict(zip(c, v)), pivots, p)) for c, v in rows]


def _pivot_dict(pivots: SparseRows) -> dict[int, Row]:
    return {r[0][0]: r for r in pivots.to_rows()}


def python_reduce_sparse(pivots: SparseRows, rows: SparseRows, ncols: int, p: int) -> SparseRows:
    return SparseRows.from_rows(python_reduce(_pivot_dict(pivots), rows.to_rows(), ncols, p))


def python_reduce_each_sparse(pivots: SparseRows, rows: SparseRows, ncols: int, p: int) -> SparseRows:
    return SparseRows.from_rows(python_reduce_each(_pivot_dict(pivots), rows.to_rows(), ncols, p))


# ----------------------------------------------------------------------------------------------
# numpy backend
# ----------------------------------------------------------------------------------------------
def matmul_mod(x: np.ndarray, y: np.ndarray, p: int) -> np.ndarray:
    """x @ y mod p for int64 matrices with entries in [0, p), exactly, through float64 BLAS.

    When every dot product stays below 2**53 one product suffices. Otherwise both factors are split into
    16-bit limbs (p < 2**31 so limbs are < 2**16 and limb dot products stay exact for k < 2**21), and
    the four limb products are recombined mod p in int64.
    """
    k = x.shape[1]
    if k == 0:
        return np.zeros((x.shape[0], y.shape[1]), dtype=np.int64)
    if k * (p - 1) ** 2 < 2**53:
        return (x.astype(np.float64) @ y.astype(np.float64)).astype(np.int64) % p
    if k >= 2**21:
        raise ValueError("inner dimension too large for exact limb products")
    x0, x1 = (x & 0xFFFF).astype(np.float64), (x >> 16).astype(np.float64)
    y0, y1 = (y & 0xFFFF).astype(np.float64), (y >> 16).astype(np.float64)
    r00 = (x0 @ y0).astype(np.int64) % p
    r01 = ((x0 @ y1).astype(np.int64) + (x1 @ y0).astype(np.int64)) % p
    r11 = (x1 @ y1).astype(np.int64) % p
    s16 = (1 << 16) % p
    s32 = (1 << 32) % p
    return (r00 + r01 * s16 % p + r11 * s32 % p) % p


def _solve_unit_upper(x: np.ndarray, t: np.ndarray, p: int) -> np.ndarray:
    """y with y @ t = x mod p, for t unit upper triangular (k x k) and x (r x k), entries in [0, p).

    Forward substitution by layers: a column's layer is the longest chain of nonzero entries of t above
    the diagonal leading to it, so the columns of one layer are final together and are eliminated from
    all later columns with one product.
    """
    dep = np.triu(t, 1)
    # longest chains by one pass over the entries in column order (t is a small, sparse block; a
    # vectorised fixpoint would need one pass per layer)
    dst, src = np.nonzero(dep.T)
    longest = [0] * len(t)
    for j, i in zip(dst.tolist(), src.tolist()):
        if longest[i] >= longest[j]:
            longest[j] = longest[i] + 1
    layer = np.array(longest, dtype=np.int64)
    top = int(layer.max(initial=0))
    if top == 0:
        return x
    order = np.argsort(layer, kind="stable")
    bounds = np.searchsorted(layer[order], np.arange(1, top + 1)).tolist()
    dep = dep[np.ix_(order, order)]
    out = np.empty_like(x)
    if len(t) * (p - 1) ** 2 + p < 2**53:
        # a column accumulates one product per predecessor: exact in float64, reduced once when final
        y = x[:, order].astype(np.float64)
        dep = dep.astype(np.float64)
        for start, stop in zip([0] + bounds, bounds):
            y[:, start:stop] %= p
            y[:, stop:] -= y[:, start:stop] @ dep[start:stop, stop:]
        y[:, bounds[-1] :] %= p
        out[:, order] = y.astype(np.int64)
        return out
    y = x[:, order]
    for start, stop in zip([0] + bounds, bounds):
        y[:, stop:] = (y[:, stop:] - matmul_mod(y[:, start:stop], dep[start:stop, stop:], p)) % p
    out[:, order] = y
    return out


def _eliminate(rows: SparseRows, ncols: int, pivots: SparseRows, p: int, block: int = 64) -> np.ndarray:
    """The rows as a dense int64 matrix mod p, every pivot column zeroed by the pivot rows (sorted by
    leading column).

    A blocked triangular solve: for each block of consecutive pivots, the multipliers of the rows come
    from a small unit triangular solve on the block's columns, then one product subtracts the block's
    pivot rows (dense from their first column on) from all rows.

    With p small enough that the sum of all products stays below 2**53, the matrix is kept in float64
    and reduced mod p only on the few columns a block reads; otherwise every product is reduced mod p
    in int64 and the (then bounded) differences accumulate in int64.
    """
    npiv = len(pivots)
    in_float = npiv * (p - 1) ** 2 + p < 2**53
    dtype = np.float64 if in_float else np.int64
    work = rows.to_dense(ncols, dtype)
    if not len(work) or not npiv:
        return work.astype(np.int64)
    pcols, lengths = pivots.leads, pivots.lengths
    for start in range(0, npiv, block):
        stop = min(start + block, npiv)
        cols = pcols[start:stop]
        x = work[:, cols].astype(np.int64) % p
        live = np.flatnonzero(x.any(axis=1))
        if not len(live):
            continue
        first = int(cols[0])
        a, b = pivots.indptr[start], pivots.indptr[stop]
        dense = np.zeros((stop - start, ncols - first), dtype=dtype)
        dense[np.repeat(np.arange(stop - start), lengths[start:stop]), pivots.cols[a:b] - first] = pivots.vals[a:b]
        y = _solve_unit_upper(x[live], dense[:, cols - first].astype(np.int64), p)
        update = y.astype(np.float64) @ dense if in_float else matmul_mod(y, dense, p)
        if len(live) == len(work):
            work[:, first:] -= update
        else:
            work[live, first:] -= update
    out = work.astype(np.int64) if in_float else work
    out %= p
    return out


def _rref_chunk(m: np.ndarray, p: int) -> tuple[np.ndarray, np.ndarray]:
    """Reduced row echelon form of a few rows: (nonzero rows, their pivot columns), row by row.

    Each row, reduced by the pivots before it, is zero or gives a new pivot at its leading column,
    which is then cleared from all other rows (Gauss-Jordan).
    """
    m = m.copy()
    pivcols = []
    for row in range(len(m)):
        nonzero = np.flatnonzero(m[row])
        if not len(nonzero):
            continue
        col = int(nonzero[0])
        lead = m[row] * pow(int(m[row, col]), -1, p) % p
        factors = m[:, col].copy()
        factors[row] = 0
        m -= np.outer(factors, lead)
        m %= p
        m[row] = lead
        pivcols.append(col)
    return m[m.any(axis=1)], np.array(pivcols, dtype=np.int64)


def _rref(m: np.ndarray, p: int, chunk: int = 16) -> np.ndarray:
    """Reduced row echelon form of a dense int64 matrix (nonzero rows only), chunk by chunk of rows.

    The echelon rows found so far are kept fully reduced; each new chunk is reduced by them with one
    product, brought to echelon form on its own, and then used to clear its pivot columns from the
    earlier echelon rows with one more product. F4 matrices have many zero reductions, which then cost
    one product each.
    """
    echelon = np.zeros((0, m.shape[1]), dtype=np.int64)
    pivcols = np.zeros(0, dtype=np.int64)
    for start in range(0, len(m), chunk):
        rows = m[start : start + chunk]
        if len(pivcols):
            rows = (rows - matmul_mod(rows[:, pivcols], echelon, p)) % p
        rows = rows[rows.any(axis=1)]
        if not len(rows):
            continue
        new, new_cols = _rref_chunk(rows, p)
        if len(pivcols):
            echelon = (echelon - matmul_mod(echelon[:, new_cols], new, p)) % p
        echelon = np.vstack([echelon, new])
        pivcols = np.concatenate([pivcols, new_cols])
    return echelon[np.argsort(pivcols)]


def numpy_reduce_sparse(pivots: SparseRows, rows: SparseRows, ncols: int, p: int) -> SparseRows:
    pivots = pivots.take(np.argsort(pivots.leads))
    keep = np.ones(ncols, dtype=bool)
    keep[pivots.leads] = False
    free = np.flatnonzero(keep)
    sub = _eliminate(rows, ncols, pivots, p)[:, free]
    return SparseRows.from_dense(_rref(sub[sub.any(axis=1)], p), free)


def numpy_reduce_each_sparse(pivots: SparseRows, rows: SparseRows, ncols: int, p: int) -> SparseRows:
    pivots = pivots.take(np.argsort(pivots.leads))
    return SparseRows.from_dense(_eliminate(rows, ncols, pivots, p))


def numpy_reduce(pivots: dict[int, Row], rows: Sequence[Row], ncols: int, p: int) -> list[Row]:
    return numpy_reduce_sparse(_pivot_rows(pivots), SparseRows.from_rows(rows), ncols, p).to_rows()


def numpy_reduce_each(pivots: dict[int, Row], rows: Sequence[Row], ncols: int, p: int) -> list[Row]:
    return numpy_reduce_each_sparse(_pivot_rows(pivots), SparseRows.from_rows(rows), ncols, p).to_rows()


@dataclass(frozen=True)
class Backend:
    name: str
    reduce: Callable[[dict[int, Row], Sequence[Row], int, int], list[Row]]
    reduce_each: Callable[[dict[int, Row], Sequence[Row], int, int], list[Row]]
    reduce_sparse: Callable[[SparseRows, SparseRows, int, int], SparseRows]
    reduce_each_sparse: Callable[[SparseRows, SparseRows, int, int], SparseRows]


_BACKENDS = {
    "python": Backend("python", python_reduce, python_reduce_each, python_reduce_sparse, python_reduce_each_sparse),
    "numpy": Backend("numpy", numpy_reduce, numpy_reduce_each, numpy_reduce_sparse, numpy_reduce_each_sparse),
}


def get_backend(name: str) -> Backend:
    try:
        return _BACKENDS[name]
    except KeyError:
        raise ValueError(f"unknown linear algebra backend {name!r}; valid: {', '.join(BACKENDS)}") from None
