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
the echelon form with a blocked row-by-row elimination; ``"sparse"`` reduces with a compiled kernel that
keeps the pivot rows sparse: the C one of :mod:`analysis.engine.native` (compiled on first use), or the numba one
of :mod:`analysis.engine.sparse_kernels` where no C compiler is found; ``"auto"`` (the F4 default) takes the C
kernel for every matrix, and without it the numba kernel for large matrices with sparse pivot rows and
numpy otherwise (:func:`sparse_pays`). All must return identical rows.

The ``*_sparse`` operations take ``threads`` (default 1): the C kernel shares its blocks of rows among
that many OpenMP threads (same rows: the reduced row echelon form is unique); the other backends run on
one thread whatever it says.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass
from itertools import chain
from typing import Callable, Literal, Sequence

import numpy as np

Row = tuple[list[int], list[int]]
BackendName = Literal["python", "numpy", "sparse", "auto"]
BACKENDS = ("python", "numpy", "sparse", "auto")


class MatrixTooLarge(RuntimeError):
    """An F4 matrix exceeded the configured size cap."""


@dataclass(frozen=True)
class SparseRows:
    """Sparse rows in compressed form: row i has columns ``cols[indptr[i]:indptr[i + 1]]`` (strictly
    increasing) with values ``vals[indptr[i]:indptr[i + 1]]`` in [1, p). ``indptr`` is int64, the columns
    and values int64 or int32 (F4's matrices: half the memory)."""

    indptr: np.ndarray
    cols: np.ndarray
    vals: np.ndarray
    offsets: np.ndarray | None = None
    """If given, vals is a pool of values shared by the rows and row i's values are
    ``vals[offsets[i] : offsets[i] + length]``: an F4 row repeats the coefficients of the basis element it
    is a multiple of, so F4's matrices keep only their columns (half the memory). :meth:`compact` gives
    the plain layout, which every method but the C kernel expects."""

    def compact(self) -> "SparseRows":
        """The same rows with their own values (vals aligned with cols)."""
        if self.offsets is None:
            return self
        gather = np.repeat(self.offsets - self.indptr[:-1], self.lengths) + np.arange(len(self.cols))
        return SparseRows(self.indptr, self.cols, self.vals[gather])

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
        return self.indptr[1:] - self.indptr[:-1]

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


def python_reduce_sparse(pivots: SparseRows, rows: SparseRows, ncols: int, p: int, threads: int = 1) -> SparseRows:
    return SparseRows.from_rows(python_reduce(_pivot_dict(pivots.compact()), rows.compact().to_rows(), ncols, p))


def python_reduce_each_sparse(pivots: SparseRows, rows: SparseRows, ncols: int, p: int, threads: int = 1) -> SparseRows:
    return SparseRows.from_rows(python_reduce_each(_pivot_dict(pivots.compact()), rows.compact().to_rows(), ncols, p))


# ----------------------------------------------------------------------------------------------
# numpy backend
# ----------------------------------------------------------------------------------------------
def matmul_mod(x: np.ndarray, y: np.ndarray, p: int) -> np.ndarray:
    """x @ y mod p for int64 matrices (or stacks of matrices) with entries in [0, p), exactly, through
    float64 BLAS.

    When every dot product stays below 2**53 one product suffices. Otherwise both factors are split into
    16-bit limbs (p < 2**31 so limbs are < 2**16 and limb dot products stay exact for k < 2**21), and
    the four limb products are recombined mod p in int64.
    """
    k = x.shape[-1]
    if k == 0:
        return np.zeros(np.broadcast_shapes(x.shape[:-2], y.shape[:-2]) + (x.shape[-2], y.shape[-1]), dtype=np.int64)
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


def _balanced(x: np.ndarray, p: int) -> np.ndarray:
    """A representative of x mod p of absolute value below p (at most p/2 + 2), for a float64 array of
    integers below 2**53 in magnitude (a new array).

    x - rint(x / p) * p is exact, and the rounded quotient is off by less than 2/p, so the result is
    zero exactly when x is divisible by p. It costs a few multiplies, against about ten for np.remainder
    on floats; the float path keeps these representatives and makes them canonical once at the end.
    """
    q = x * (1.0 / p)
    np.rint(q, out=q)
    q *= p
    return np.subtract(x, q, out=q)


def _unit_upper_inverses(t: np.ndarray, p: int, in_float: bool, levels: int = -1) -> np.ndarray:
    """Inverses mod p of a stack of unit upper triangular (k x k, k a power of two) matrices, in place.

    In float64 when in_float (entries and results as :func:`_balanced` representatives, k * p**2 < 2**53),
    else in int64 (entries and results in [0, p)).

    By doubling, all matrices at once: the inverse of [[A, B], [0, C]] is [[A^-1, -A^-1 B C^-1], [0, C^-1]],
    so log2(k) steps of two batched products turn the diagonal blocks of size s, already inverted, into
    inverted diagonal blocks of size 2s. This replaces a forward substitution per matrix, whose cost is
    one step per dependency layer. Only the steps s with s & levels are done: the others must have B = 0
    (true when no entry (i, j), i < j, has s as the top bit of i ^ j).
    """
    nb, k = t.shape[0], t.shape[1]
    item = t.itemsize
    s = 1
    while s < k:
        if not s & levels:
            s *= 2
            continue
        # the diagonal 2s-blocks of every matrix, as a (nb, k / 2s, 2s, 2s) view
        strides = (k * k * item, 2 * s * (k + 1) * item, k * item, item)
        diag = np.ndarray((nb, k // (2 * s), 2 * s, 2 * s), t.dtype, t, 0, strides)
        b = diag[:, :, :s, s:]
        if s == 1:  # A = C = 1
            if in_float:
                np.negative(b, out=b)
            else:
                b[...] = (p - b) % p
        elif in_float:
            half = (p + 4) / 2  # bound of the representatives
            ab = diag[:, :, :s, :s] @ b
            if s * s * half**3 >= 2**53:
                ab = _balanced(ab, p)
            np.negative(_balanced(ab @ diag[:, :, s:, s:], p), out=b)
        else:
            b[...] = (p - matmul_mod(matmul_mod(diag[:, :, :s, :s], b, p), diag[:, :, s:, s:], p)) % p
        s *= 2
    return t


_SPARSE_WORK = 2_000_000  # rows x block x width above which sparse pivot blocks may pay ...
_SPARSE_DENSITY = 8  # ... when at most 1/8 of their entries are nonzero
_ROW_CHUNK_CELLS = 1 << 20  # rows x columns of the dense working matrix (8 MiB of float64) ...
# ... above which the rows to reduce are reduced a chunk at a time (the block inverses are shared)
_SCRATCH = threading.local()
_SCRATCH_MAX = 1 << 20  # elements (8 MiB of float64)


def _scratch(slot: str, shape: tuple[int, ...], dtype) -> np.ndarray:
    """A C-contiguous array of the given shape, uninitialised, from a per-thread buffer kept between
    calls (one per slot and dtype; a later request for the same slot reuses it). Arrays above
    _SCRATCH_MAX elements are fresh, so that no large buffer outlives a big computation.

    Fresh arrays of a few hundred kilobytes are served by new memory mappings, so every call would pay
    a page fault per 4 KiB touched; the temporaries of the elimination come from here instead.
    """
    size = 1
    for n in shape:
        size *= n
    if size > _SCRATCH_MAX:
        return np.empty(shape, dtype=dtype)
    key = (slot, dtype)
    buffers = _SCRATCH.__dict__
    buffer = buffers.get(key)
    if buffer is None or len(buffer) < size:
        buffer = np.empty(min(max(size, 2 * len(buffer) if buffer is not None else 0), _SCRATCH_MAX), dtype=dtype)
        buffers[key] = buffer
    return buffer[:size].reshape(shape)


def _eliminate(
    rows: SparseRows, ncols: int, pivots: SparseRows, p: int, block: int = 64, columns: np.ndarray | None = None
) -> np.ndarray:
    """The rows as a dense int64 matrix mod p, every pivot column zeroed by the pivot rows (sorted by
    leading column); only the given columns if columns is not None.

    A blocked triangular solve: for each block of consecutive pivots, the multipliers of the rows are
    their entries in the block's columns times the inverse of the block's (unit upper triangular)
    restriction to those columns, and one product subtracts the block's pivot rows (dense from their
    first column on) from all rows. The inverses of all blocks are computed together beforehand
    (:func:`_unit_upper_inverses`).

    With p small enough that the sum of all products stays below 2**53, the matrix is kept in float64
    and reduced mod p (to :func:`_balanced` representatives) only on the few columns a block reads;
    otherwise every product is reduced mod p in int64 and the (then bounded) differences accumulate in
    int64. Temporaries come from :func:`_scratch`. Many rows are reduced a chunk of rows at a time
    (at most _ROW_CHUNK_CELLS dense entries), against the same block inverses.
    """
    npiv = len(pivots)
    in_float = npiv * (p - 1) ** 2 + p < 2**53
    dtype = np.float64 if in_float else np.int64
    if not len(rows) or not npiv:
        dense = rows.to_dense(ncols)
        return dense if columns is None else dense[:, columns]
    pcols, lengths, indptr = pivots.leads, pivots.lengths, pivots.indptr
    block = min(block, 1 << (npiv - 1).bit_length())  # a power of two, for the doubling
    # the entries of every pivot row in the later pivot columns of its own block
    owner = np.repeat(np.arange(npiv), lengths)
    position = np.full(ncols, -1, dtype=np.int64)
    position[pcols] = np.arange(npiv)
    at = position[pivots.cols]
    inside = (at > owner) & (at // block == owner // block)
    at, row = at[inside], owner[inside]
    nblocks = -(-npiv // block)
    diagonal = np.zeros((nblocks, block, block), dtype=dtype)
    diagonal.reshape(nblocks, block * block)[:, :: block + 1] = 1
    diagonal[row // block, row % block, at % block] = pivots.vals[inside]
    # the doubling steps that see an entry: those of the bits of (i ^ j) for the entries (i, j)
    levels = int(np.bitwise_or.reduce((row % block) ^ (at % block))) if len(row) else 0
    inverses = _unit_upper_inverses(diagonal, p, in_float, levels) if levels else None

    def reduce_chunk(rows: SparseRows) -> np.ndarray:
        # transposed, one row per matrix column: the columns a block reads and writes are then
        # contiguous rows (gathering and scattering strided matrix columns cost more than the products)
        # the rows come by increasing leading column: a block can only touch those that start at or
        # before its last column, a prefix of them
        n = len(rows)
        work = _scratch("work", (ncols, n), dtype)
        work.fill(0)
        work[rows.cols, np.repeat(np.arange(n), rows.lengths)] = rows.vals
        leads = _row_leads(rows, ncols)
        for b, start in enumerate(range(0, npiv, block)):
            stop = min(start + block, npiv)
            k = stop - start
            cols = pcols[start:stop]
            reach = int(np.searchsorted(leads, cols[-1], side="right"))
            if not reach:
                continue
            x = _balanced(work[cols, :reach], p) if in_float else work[cols, :reach] % p
            live = x.any(axis=0).nonzero()[0]
            if not len(live):
                continue
            few = 4 * len(live) < reach  # then only the live rows are multiplied and written back
            if few:
                x = x[:, live]
            if inverses is not None:  # else every block is the identity
                inverse = inverses[b, :k, :k].T
                x = _balanced(inverse @ x, p) if in_float else matmul_mod(np.ascontiguousarray(inverse), x.astype(np.int64), p)
            first = int(cols[0])
            lo, hi = indptr[start], indptr[stop]
            width = ncols - first
            if in_float and x.shape[1] * k * width > _SPARSE_WORK and (hi - lo) * _SPARSE_DENSITY < k * width:
                # wide, sparse pivot rows and many rows to reduce: the product with the block restricted to
                # the columns its rows use costs rows x block x used instead of rows x block x width (a
                # scipy.sparse product was as fast, but importing scipy.sparse cost every process 0.1 s)
                used, local = np.unique(pivots.cols[lo:hi], return_inverse=True)
                compact = _scratch("compact", (len(used), k), dtype)
                compact.fill(0)
                compact[local, owner[lo:hi] - start] = pivots.vals[lo:hi]
                update = compact @ x
                if few:
                    work[np.ix_(used, live)] -= update
                else:
                    work[used, :reach] -= update
                continue
            dense = _scratch("dense", (width, k), dtype)
            dense.fill(0)
            dense[pivots.cols[lo:hi] - first, owner[lo:hi] - start] = pivots.vals[lo:hi]
            update = _scratch("product", (width, x.shape[1]), dtype)
            if in_float:
                np.matmul(dense, x, out=update)
            else:
                update[...] = matmul_mod(dense, x.astype(np.int64), p)
            if few:
                work[first:, live] -= update
            else:
                work[first:, :reach] -= update
        if columns is not None:
            work = work[columns]
        if not in_float:
            return np.ascontiguousarray((work % p).T)
        out = _balanced(work, p)
        np.add(out, p, out=out, where=out < 0)
        return np.ascontiguousarray(out.T, dtype=np.int64)

    order = np.argsort(_row_leads(rows, ncols), kind="stable")
    rows = rows.take(order)
    chunk = max(1, _ROW_CHUNK_CELLS // ncols)
    if len(rows) <= chunk:
        reduced = reduce_chunk(rows)
    else:
        reduced = np.vstack([reduce_chunk(rows.take(np.arange(start, min(start + chunk, len(rows)))))
                             for start in range(0, len(rows), chunk)])
    out = np.empty_like(reduced)
    out[order] = reduced
    return out


def _row_leads(rows: SparseRows, ncols: int) -> np.ndarray:
    """The leading column of every row, ncols for an empty one."""
    lengths = rows.lengths
    leads = np.full(len(rows), ncols, dtype=np.int64)
    nonempty = lengths > 0
    leads[nonempty] = rows.cols[rows.indptr[:-1][nonempty]]
    return leads


def _rref_chunk(m: np.ndarray, p: int) -> tuple[np.ndarray, np.ndarray]:
    """Reduced row echelon form of a few rows: (nonzero rows, their pivot columns), row by row.

    Each row, reduced by the pivots before it, is zero or gives a new pivot at its leading column,
    which is then cleared from all other rows (Gauss-Jordan). int64 entries in [0, p), or float64
    :func:`_balanced` representatives (chosen by the caller, :func:`_rref`, through the dtype).
    """
    in_float = m.dtype == np.float64
    m = m.copy()
    pivcols = []
    for row in range(len(m)):
        nonzero = m[row].nonzero()[0]
        if not len(nonzero):
            continue
        col = int(nonzero[0])
        factors = m[:, col].copy()
        factors[row] = 0
        if in_float:
            lead = _balanced(m[row] * pow(int(m[row, col]) % p, -1, p), p)
            m -= factors[:, None] * lead
            m[...] = _balanced(m, p)
        else:
            lead = m[row] * pow(int(m[row, col]), -1, p) % p
            m -= factors[:, None] * lead
            m %= p
        m[row] = lead
        pivcols.append(col)
    return m[m.any(axis=1)], np.array(pivcols, dtype=np.int64)


def _rref(m: np.ndarray, p: int, chunk: int = 16) -> np.ndarray:
    """Reduced row echelon form of a dense int64 matrix with entries in [0, p) (nonzero rows only),
    chunk by chunk of rows.

    The echelon rows found so far are kept fully reduced; each new chunk is reduced by them with one
    product, brought to echelon form on its own, and then used to clear its pivot columns from the
    earlier echelon rows with one more product. F4 matrices have many zero reductions, which then cost
    one product each. When the products stay below 2**53 the work is done in float64 (:func:`_balanced`
    representatives, cheaper than int64 remainders).
    """
    in_float = m.shape[1] * (p - 1) ** 2 + p < 2**53

    def product(x, y):
        return _balanced(x @ y, p) if in_float else matmul_mod(x, y, p)

    def reduce(x):
        return _balanced(x, p) if in_float else x % p

    if in_float:
        m = m.astype(np.float64)
    echelon = np.zeros((0, m.shape[1]), dtype=m.dtype)
    pivcols = np.zeros(0, dtype=np.int64)
    for start in range(0, len(m), chunk):
        rows = m[start : start + chunk]
        if len(pivcols):
            rows = reduce(rows - product(rows[:, pivcols], echelon))
        rows = rows[rows.any(axis=1)]
        if not len(rows):
            continue
        new, new_cols = _rref_chunk(rows, p)
        if len(pivcols):
            echelon = reduce(echelon - product(echelon[:, new_cols], new))
        echelon = np.vstack([echelon, new])
        pivcols = np.concatenate([pivcols, new_cols])
    echelon = echelon[pivcols.argsort()]
    if in_float:
        echelon = echelon.astype(np.int64)
        echelon %= p
    return echelon


def pivot_columns(m: np.ndarray, p: int) -> np.ndarray:
    """Pivot columns (increasing) of the row echelon form of a dense matrix over GF(p).

    They index a maximal set of linearly independent columns, the leftmost one; applied to the
    transpose, the same call picks independent rows. Entries may be any integers (reduced mod p here).
    """
    m = np.asarray(m, dtype=np.int64) % p
    if m.size == 0:
        return np.zeros(0, dtype=np.int64)
    echelon = _rref(m, p)
    return np.sort(np.argmax(echelon != 0, axis=1))


def numpy_reduce_sparse(pivots: SparseRows, rows: SparseRows, ncols: int, p: int, threads: int = 1) -> SparseRows:
    pivots, rows = pivots.compact(), rows.compact()
    leads = pivots.leads
    if (leads[1:] < leads[:-1]).any():
        pivots = pivots.take(leads.argsort())
    keep = np.ones(ncols, dtype=bool)
    keep[leads] = False
    free = keep.nonzero()[0]
    sub = _eliminate(rows, ncols, pivots, p, columns=free)
    return SparseRows.from_dense(_rref(sub[sub.any(axis=1)], p), free)


def numpy_reduce_each_sparse(pivots: SparseRows, rows: SparseRows, ncols: int, p: int, threads: int = 1) -> SparseRows:
    pivots, rows = pivots.compact(), rows.compact()
    leads = pivots.leads
    if (leads[1:] < leads[:-1]).any():
        pivots = pivots.take(leads.argsort())
    return SparseRows.from_dense(_eliminate(rows, ncols, pivots, p))


def numpy_reduce(pivots: dict[int, Row], rows: Sequence[Row], ncols: int, p: int) -> list[Row]:
    return numpy_reduce_sparse(_pivot_rows(pivots), SparseRows.from_rows(rows), ncols, p).to_rows()


def numpy_reduce_each(pivots: dict[int, Row], rows: Sequence[Row], ncols: int, p: int) -> list[Row]:
    return numpy_reduce_each_sparse(_pivot_rows(pivots), SparseRows.from_rows(rows), ncols, p).to_rows()


# ----------------------------------------------------------------------------------------------
# sparse backend (compiled)
# ----------------------------------------------------------------------------------------------
def _sparse_kernel(pivots: SparseRows, rows: SparseRows, ncols: int, p: int, echelon: bool,
                   threads: int = 1) -> SparseRows:
    from . import native

    def arrays(block: SparseRows) -> tuple[np.ndarray, ...]:  # one compiled signature
        return (np.ascontiguousarray(block.indptr, dtype=np.int64), np.ascontiguousarray(block.cols, dtype=np.int32),
                np.ascontiguousarray(block.vals, dtype=np.int32))

    if native.kernel() is None:
        from .sparse_kernels import sparse_echelon

        return SparseRows(*sparse_echelon(*arrays(pivots.compact()), *arrays(rows.compact()), ncols, p, echelon))

    def offsets(block: SparseRows) -> np.ndarray:
        return np.ascontiguousarray(block.indptr[:-1] if block.offsets is None else block.offsets, dtype=np.int64)

    return SparseRows(*native.sparse_echelon(*arrays(pivots), offsets(pivots), *arrays(rows), offsets(rows), ncols, p,
                                             echelon, threads))


def sparse_reduce_sparse(pivots: SparseRows, rows: SparseRows, ncols: int, p: int, threads: int = 1) -> SparseRows:
    return _sparse_kernel(pivots, rows, ncols, p, True, threads)


def sparse_reduce_each_sparse(pivots: SparseRows, rows: SparseRows, ncols: int, p: int, threads: int = 1) -> SparseRows:
    return _sparse_kernel(pivots, rows, ncols, p, False, threads)


def sparse_reduce(pivots: dict[int, Row], rows: Sequence[Row], ncols: int, p: int) -> list[Row]:
    return sparse_reduce_sparse(_pivot_rows(pivots), SparseRows.from_rows(rows), ncols, p).to_rows()


def sparse_reduce_each(pivots: dict[int, Row], rows: Sequence[Row], ncols: int, p: int) -> list[Row]:
    return sparse_reduce_each_sparse(_pivot_rows(pivots), SparseRows.from_rows(rows), ncols, p).to_rows()


SPARSE_MAX_DENSITY = 0.05
"""Without the C kernel, pivot rows that fill more than this share of their columns are *dense*, and the
numba kernel is not taken for them: the dense BLAS products of the numpy backend were faster there
(random quadrics, pivot density 8 %: 1.1-1.6x). The C kernel (rows a block at a time, vector multiplies)
is faster than numpy on every benchmark matrix, dense ones included (quadrics-10: 0.94 s and 83 MB
against 1.44 s and 131 MB), so with it ``auto`` always takes the sparse kernel."""
SPARSE_MIN_WORK = 20_000_000_000
"""Without the C kernel (no compiler), the numba kernel is taken, until it is loaded, only when the dense
elimination would cost more than this many multiply-adds (about 1 s of dense products): loading numba and
the cached kernel costs about 0.45 s and 110 MB of a process, which small systems never pay."""
SPARSE_MIN_WORK_LOADED = 20_000_000
"""Once the numba kernel is loaded, the dense path is kept only for matrices below this much work, where
numpy's products are as fast."""


def sparse_pays(npiv: int, pivot_entries: int, nrows: int, ncols: int) -> bool:
    """Whether ``auto`` reduces this matrix with the sparse kernel (see :data:`SPARSE_MAX_DENSITY`)."""
    import sys

    from . import native

    if not nrows:
        return False
    if native.kernel() is not None:
        return True
    if not npiv or pivot_entries > SPARSE_MAX_DENSITY * npiv * ncols:
        return False
    loaded = "analysis.engine.sparse_kernels" in sys.modules
    return nrows * npiv * ncols > (SPARSE_MIN_WORK_LOADED if loaded else SPARSE_MIN_WORK)


def auto_reduce_sparse(pivots: SparseRows, rows: SparseRows, ncols: int, p: int, threads: int = 1) -> SparseRows:
    if sparse_pays(len(pivots), len(pivots.cols), len(rows), ncols):
        return sparse_reduce_sparse(pivots, rows, ncols, p, threads)
    return numpy_reduce_sparse(pivots, rows, ncols, p)


def auto_reduce_each_sparse(pivots: SparseRows, rows: SparseRows, ncols: int, p: int, threads: int = 1) -> SparseRows:
    if sparse_pays(len(pivots), len(pivots.cols), len(rows), ncols):
        return sparse_reduce_each_sparse(pivots, rows, ncols, p, threads)
    return numpy_reduce_each_sparse(pivots, rows, ncols, p)


def auto_reduce(pivots: dict[int, Row], rows: Sequence[Row], ncols: int, p: int) -> list[Row]:
    return auto_reduce_sparse(_pivot_rows(pivots), SparseRows.from_rows(rows), ncols, p).to_rows()


def auto_reduce_each(pivots: dict[int, Row], rows: Sequence[Row], ncols: int, p: int) -> list[Row]:
    return auto_reduce_each_sparse(_pivot_rows(pivots), SparseRows.from_rows(rows), ncols, p).to_rows()


@dataclass(frozen=True)
class Backend:
    name: str
    reduce: Callable[[dict[int, Row], Sequence[Row], int, int], list[Row]]
    reduce_each: Callable[[dict[int, Row], Sequence[Row], int, int], list[Row]]
    reduce_sparse: Callable[..., SparseRows]  # (pivots, rows, ncols, p, threads=1)
    reduce_each_sparse: Callable[..., SparseRows]


_BACKENDS = {
    "python": Backend("python", python_reduce, python_reduce_each, python_reduce_sparse, python_reduce_each_sparse),
    "numpy": Backend("numpy", numpy_reduce, numpy_reduce_each, numpy_reduce_sparse, numpy_reduce_each_sparse),
    "sparse": Backend("sparse", sparse_reduce, sparse_reduce_each, sparse_reduce_sparse, sparse_reduce_each_sparse),
    "auto": Backend("auto", auto_reduce, auto_reduce_each, auto_reduce_sparse, auto_reduce_each_sparse),
}


def get_backend(name: str) -> Backend:
    try:
        return _BACKENDS[name]
    except KeyError:
        raise ValueError(f"unknown linear algebra backend {name!r}; valid: {', '.join(BACKENDS)}") from None
