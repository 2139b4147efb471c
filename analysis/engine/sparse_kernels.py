"""Compiled sparse row reduction mod p for F4 matrices (numba, cached on disk).

One kernel, :func:`sparse_echelon`, reduces the rows of an F4 matrix one at a time in a dense 64-bit
accumulator of the matrix's width, left to right: at every column that has a pivot row (the known
pivots from symbolic preprocessing, and the rows found new so far) the row's entry times that pivot row
is subtracted. The pivot rows stay sparse and unreduced (each is triangular against the others through
its leading column), so the accumulator only ever reads the entries that exist. With
``npiv * (p - 1)**2 + p < 2**63`` the products are accumulated without reduction and each entry is
reduced mod p once, when the sweep reaches its column (delayed modular reduction); otherwise (31-bit
primes) every entry is kept below p**2 by one compare and subtract per update, and reduced mod p when
the sweep reaches it.

In echelon mode a row that does not reduce to zero is made monic and becomes a pivot for the rows
after it; at the end every new pivot row is swept once more against all pivots, which gives the reduced
row echelon form. In "each" mode (tail reduction) the rows are only reduced.

Reference: J. Berthomieu, C. Eder, M. Safey El Din, "msolve: a library for solving polynomial systems",
ISSAC 2021 (the design: known pivots kept sparse, delayed reduction in 64-bit accumulators); the code
here is written from that description.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _inverse(a, p):
    """a^-1 mod p for 0 < a < p (extended Euclid)."""
    t, new_t, r, new_r = 0, 1, p, a
    while new_r:
        q = r // new_r
        t, new_t = new_t, t - q * new_t
        r, new_r = new_r, r - q * new_r
    return t % p


@njit(cache=True)
def _room(cols, vals, size, more):
    """The arrays, or copies of their first size entries with room for at least more after them."""
    if size + more <= len(cols):
        return cols, vals
    grow = max(2 * len(cols), size + more)
    c2 = np.empty(grow, dtype=cols.dtype)
    v2 = np.empty(grow, dtype=vals.dtype)
    c2[:size] = cols[:size]
    v2[:size] = vals[:size]
    return c2, v2


@njit(cache=True)
def _gather(acc, first, ncols, cols, vals, w):
    """Move the nonzero entries of acc[first:] to cols/vals from position w on (acc is left zero);
    returns the position after them."""
    for c in range(first, ncols):
        if acc[c]:
            cols[w] = c
            vals[w] = acc[c]
            w += 1
            acc[c] = 0
    return w


@njit(cache=True)
def _sweep(acc, first, ncols, pivot_of, starts, ends, store_cols, store_vals, p, delayed, skip):
    """Reduce the accumulator from column first on by every pivot (except the one at column skip);
    leaves reduced entries in [0, p) and returns the number of nonzero entries."""
    nnz = 0
    for c in range(first, ncols):
        a = acc[c]
        if a == 0:
            continue
        a %= p
        if a == 0:
            acc[c] = 0
            continue
        k = pivot_of[c]
        if k < 0 or c == skip:
            acc[c] = a
            nnz += 1
            continue
        acc[c] = 0
        m = p - a  # pivot rows are monic: add (p - a) times the row's tail
        s, e = starts[k] + 1, ends[k]
        if delayed:
            for t in range(s, e):
                acc[store_cols[t]] += m * store_vals[t]
        else:  # bounded: kept below p**2 by one compare and subtract, no division (sums < 2**63)
            p2 = p * p
            for t in range(s, e):
                j = store_cols[t]
                x = acc[j] + m * store_vals[t]
                acc[j] = x - p2 if x >= p2 else x
    return nnz


@njit(cache=True)
def sparse_echelon(piv_indptr, piv_cols, piv_vals, row_indptr, row_cols, row_vals, ncols, p, echelon):
    """Reduce the rows by the monic pivot rows (any order, distinct leading columns).

    echelon=True: the reduced row echelon form of the reduced rows (new pivots found one after the
    other, then swept again), nonzero rows only, monic, by increasing leading column. echelon=False:
    every row reduced on its own (zero rows kept). Returns (indptr, cols, vals) of the result.
    """
    npiv = len(piv_indptr) - 1
    nrows = len(row_indptr) - 1
    delayed = (npiv + nrows + 1.0) * (p - 1.0) * (p - 1.0) + p < 2.0**62  # in float: no overflow
    pivot_of = np.full(ncols, -1, dtype=np.int64)
    # the store of all pivot rows: the known ones, then each new one as it is found
    cap = len(piv_cols) + max(16, ncols)
    store_cols = np.empty(cap, dtype=np.int32)
    store_vals = np.empty(cap, dtype=np.int32)
    store_cols[: len(piv_cols)] = piv_cols
    store_vals[: len(piv_vals)] = piv_vals
    size = len(piv_cols)
    starts = np.empty(npiv + nrows, dtype=np.int64)
    ends = np.empty(npiv + nrows, dtype=np.int64)
    for k in range(npiv):
        starts[k] = piv_indptr[k]
        ends[k] = piv_indptr[k + 1]
        pivot_of[piv_cols[piv_indptr[k]]] = k
    count = npiv
    acc = np.zeros(ncols, dtype=np.int64)
    # "each" mode output
    out_indptr = np.zeros(nrows + 1, dtype=np.int64)
    out_cols = np.empty(len(row_cols) if not echelon else 0, dtype=np.int64)
    out_vals = np.empty(len(row_cols) if not echelon else 0, dtype=np.int64)
    out_size = 0
    for r in range(nrows):
        a, b = row_indptr[r], row_indptr[r + 1]
        if a == b:
            out_indptr[r + 1] = out_size
            continue
        for t in range(a, b):
            acc[row_cols[t]] = row_vals[t]
        first = row_cols[a]
        nnz = _sweep(acc, first, ncols, pivot_of, starts, ends, store_cols, store_vals, p, delayed, -1)
        if not echelon:
            out_cols, out_vals = _room(out_cols, out_vals, out_size, nnz)
            out_size = _gather(acc, first, ncols, out_cols, out_vals, out_size)
            out_indptr[r + 1] = out_size
            continue
        if nnz == 0:
            continue
        store_cols, store_vals = _room(store_cols, store_vals, size, nnz)
        lead = -1
        inv = 1
        starts[count] = size
        for c in range(first, ncols):
            v = acc[c]
            if v:
                if lead < 0:
                    lead = c
                    inv = _inverse(v, p)
                store_cols[size] = c
                store_vals[size] = v * inv % p
                size += 1
                acc[c] = 0
        ends[count] = size
        pivot_of[lead] = count
        count += 1
    if not echelon:
        return out_indptr, out_cols[:out_size], out_vals[:out_size]
    # the new pivots by decreasing leading column, each swept against all the others (those to its
    # right are final by then) and written back in place (it can only get shorter)
    new = np.arange(npiv, count)
    leads = np.empty(count - npiv, dtype=np.int64)
    for i in range(count - npiv):
        leads[i] = store_cols[starts[npiv + i]]
    order = np.argsort(leads)
    total = 0
    for i in range(len(order) - 1, -1, -1):
        k = new[order[i]]
        s, e = starts[k], ends[k]
        lead = store_cols[s]
        for t in range(s, e):
            acc[store_cols[t]] = store_vals[t]
        nnz = _sweep(acc, lead, ncols, pivot_of, starts, ends, store_cols, store_vals, p, delayed, lead)
        # nnz <= e - s is not guaranteed (fill-in from the known pivots): keep the row where it fits
        if nnz > e - s:
            store_cols, store_vals = _room(store_cols, store_vals, size, nnz)
            s = size
            size += nnz
            starts[k] = s
        w = _gather(acc, lead, ncols, store_cols, store_vals, s)
        ends[k] = w
        total += w - s
    out_indptr = np.zeros(len(order) + 1, dtype=np.int64)
    out_cols = np.empty(total, dtype=np.int64)
    out_vals = np.empty(total, dtype=np.int64)
    w = 0
    for i in range(len(order)):
        k = new[order[i]]
        for t in range(starts[k], ends[k]):
            out_cols[w] = store_cols[t]
            out_vals[w] = store_vals[t]
            w += 1
        out_indptr[i + 1] = w
    return out_indptr, out_cols, out_vals
