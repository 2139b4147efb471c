"""Mod-p row reduction for F4 matrices behind one interface, with interchangeable backends.

An F4 matrix is given as *pivot rows* (one per pivot column, leading coefficient 1; these are the
reducers found by symbolic preprocessing) and *rows to reduce*. A row is a pair of lists
``(cols, vals)``, columns strictly increasing (column 0 is the largest monomial), values in [1, p).
Every backend implements two operations:

``reduce(pivots, rows, ncols, p)``
    reduce each row fully by the pivot rows (afterwards no row has an entry in a pivot column), then
    bring the results to reduced row echelon form and return its nonzero rows (monic, sorted by leading
    column). This is one F4 reduction step: the returned rows are the new basis elements.
``reduce_each(pivots, rows, ncols, p)``
    reduce each row fully by the pivot rows, without combining rows (used for tail reduction).

Backends: ``"python"`` is the slow, obviously correct reference used in tests; ``"numpy"`` does the
elimination with vectorised dense int64 arithmetic and FLINT's ``nmod_mat.rref`` for the echelon form.
Both must return identical rows.
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


# ----------------------------------------------------------------------------------------------
# numpy + flint backend
# ----------------------------------------------------------------------------------------------
def _dense(rows: Sequence[Row], ncols: int) -> np.ndarray:
    """Scatter sparse rows into a dense int64 matrix with one vectorised assignment."""
    m = np.zeros((len(rows), ncols), dtype=np.int64)
    if not rows:
        return m
    lengths = np.fromiter((len(c) for c, _ in rows), dtype=np.int64, count=len(rows))
    total = int(lengths.sum())
    cols = np.fromiter(chain.from_iterable(c for c, _ in rows), dtype=np.int64, count=total)
    vals = np.fromiter(chain.from_iterable(v for _, v in rows), dtype=np.int64, count=total)
    m[np.repeat(np.arange(len(rows)), lengths), cols] = vals
    return m


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


def _pivot_layers(pivots: dict[int, Row], ncols: int) -> tuple[np.ndarray, np.ndarray]:
    """Sorted pivot columns and their layer: the longest chain of pivot rows leading to each pivot.

    Pivot row i has entries only at columns >= its own; if it has an entry in pivot column j, pivot j
    must be applied after pivot i. Pivots of one layer are independent, so a whole layer is applied at
    once: one matrix product per layer instead of a triangular solve per pivot.
    """
    pcols = np.array(sorted(pivots), dtype=np.int64)
    where = np.full(ncols, -1, dtype=np.int64)
    where[pcols] = np.arange(len(pcols))
    rows = [pivots[int(c)] for c in pcols]
    lengths = np.fromiter((len(r[0]) for r in rows), dtype=np.int64, count=len(rows))
    cols = np.fromiter(chain.from_iterable(r[0] for r in rows), dtype=np.int64, count=int(lengths.sum()))
    src = np.repeat(np.arange(len(rows)), lengths)
    dst = where[cols]
    edge = (dst >= 0) & (dst != src)
    src, dst = src[edge], dst[edge]
    layer = np.zeros(len(pcols), dtype=np.int64)
    while len(src):
        new = layer.copy()
        np.maximum.at(new, dst, layer[src] + 1)
        if np.array_equal(new, layer):
            break
        layer = new
    return pcols, layer


def _eliminate_dense(m: np.ndarray, pivots: dict[int, Row], p: int, block: int = 512) -> np.ndarray:
    """Zero every pivot column of the dense block m by the pivot rows, layer by layer (in place)."""
    if not len(m) or not pivots:
        return m
    pcols, layer = _pivot_layers(pivots, m.shape[1])
    order = np.argsort(layer, kind="stable")
    bounds = np.flatnonzero(np.diff(layer[order])) + 1
    for group in np.split(order, bounds):
        for start in range(0, len(group), block):
            cols = pcols[group[start : start + block]]
            sub = m[:, cols]
            live = np.flatnonzero(np.any(sub != 0, axis=1))
            if not len(live):
                continue
            a = _dense([pivots[int(c)] for c in cols], m.shape[1])
            support = np.flatnonzero(a.any(axis=0))  # F4 matrices are sparse: touch only these columns
            upd = matmul_mod(sub[live], a[:, support], p)
            idx = np.ix_(live, support)
            m[idx] = (m[idx] - upd) % p
    return m


def _rref_flint(m: np.ndarray, p: int) -> np.ndarray:
    """Reduced row echelon form of a dense int64 matrix via FLINT; returns only the nonzero rows."""
    import flint

    r, c = m.shape
    if r == 0 or c == 0:
        return np.zeros((0, c), dtype=np.int64)
    mat = flint.nmod_mat(r, c, m.ravel().tolist(), p)
    red, rank = mat.rref()
    if rank == 0:
        return np.zeros((0, c), dtype=np.int64)
    # read back only the rank nonzero rows, through int conversion of the nmod entries
    vals = [int(x) for x in red.entries()[: rank * c]]
    return np.array(vals, dtype=np.int64).reshape(rank, c)


def _rref_numpy(m: np.ndarray, p: int) -> np.ndarray:
    """Reduced row echelon form of a small dense int64 matrix (nonzero rows only)."""
    m = m.copy()
    r, c = m.shape
    row = 0
    for col in range(c):
        if row == r:
            break
        nz = np.flatnonzero(m[row:, col])
        if not len(nz):
            continue
        piv = row + int(nz[0])
        if piv != row:
            m[[row, piv]] = m[[piv, row]]
        support = col + np.flatnonzero(m[row, col:])
        m[row, support] = m[row, support] * pow(int(m[row, col]), -1, p) % p
        others = np.flatnonzero(m[:, col])
        others = others[others != row]
        if len(others):
            idx = np.ix_(others, support)
            m[idx] = (m[idx] - np.outer(m[others, col], m[row, support]) % p) % p
        row += 1
    return m[:row]


def _rref(m: np.ndarray, p: int) -> np.ndarray:
    """Reduced row echelon form (nonzero rows): numpy's row loop for small blocks, FLINT otherwise.

    The crossover was measured on this project's F4 blocks: FLINT's rref is fast but converting to and
    from nmod_mat costs about 1 microsecond per entry.
    """
    if m.shape[0] <= 40 or m.shape[0] * m.shape[1] <= 25_000:
        return _rref_numpy(m, p)
    return _rref_flint(m, p)


def numpy_reduce(pivots: dict[int, Row], rows: Sequence[Row], ncols: int, p: int) -> list[Row]:
    if not rows:
        return []
    m = _eliminate_dense(_dense(rows, ncols), pivots, p)
    keep = np.ones(ncols, dtype=bool)
    keep[list(pivots)] = False
    free = np.flatnonzero(keep)
    sub = m[:, free]
    sub = sub[np.any(sub != 0, axis=1)]
    red = _rref(sub, p)
    out = []
    for row in red:
        nz = np.flatnonzero(row)
        out.append((free[nz].tolist(), row[nz].tolist()))
    return out


def numpy_reduce_each(pivots: dict[int, Row], rows: Sequence[Row], ncols: int, p: int) -> list[Row]:
    if not rows:
        return []
    m = _eliminate_dense(_dense(rows, ncols), pivots, p)
    return [(np.flatnonzero(r).tolist(), r[np.flatnonzero(r)].tolist()) for r in m]


@dataclass(frozen=True)
class Backend:
    name: str
    reduce: Callable[[dict[int, Row], Sequence[Row], int, int], list[Row]]
    reduce_each: Callable[[dict[int, Row], Sequence[Row], int, int], list[Row]]


_BACKENDS = {
    "python": Backend("python", python_reduce, python_reduce_each),
    "numpy": Backend("numpy", numpy_reduce, numpy_reduce_each),
}


def get_backend(name: str) -> Backend:
    try:
        return _BACKENDS[name]
    except KeyError:
        raise ValueError(f"unknown linear algebra backend {name!r}; valid: {', '.join(BACKENDS)}") from None
