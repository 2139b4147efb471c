/* Sparse row reduction mod p for F4 matrices: the C twin of analysis/sparse_kernels.py.
 *
 * Loaded through ctypes by analysis/native.py (compiled there on first use with the system's C compiler
 * and cached); no Python API. Same algorithm and same results as the numba kernel sparse_echelon: the
 * rows are reduced one at a time in a dense 64-bit accumulator by the sparse, unreduced pivot rows, with
 * delayed modular reduction; in echelon mode the rows that do not vanish become pivots, and at the end
 * every new pivot is swept once more (reduced row echelon form).
 *
 * Reference: J. Berthomieu, C. Eder, M. Safey El Din, "msolve: a library for solving polynomial systems",
 * ISSAC 2021 (known pivots kept sparse, delayed reduction in 64-bit accumulators).
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    int32_t *cols;
    int32_t *vals;
    int64_t size, cap;
} store_t;

static int room(store_t *s, int64_t more)
{
    if (s->size + more <= s->cap)
        return 0;
    int64_t grow = 2 * s->cap > s->size + more ? 2 * s->cap : s->size + more;
    int32_t *c = realloc(s->cols, grow * sizeof(int32_t));
    if (!c)
        return -1;
    s->cols = c;
    int32_t *v = realloc(s->vals, grow * sizeof(int32_t));
    if (!v)
        return -1;
    s->vals = v;
    s->cap = grow;
    return 0;
}

static int64_t inverse(int64_t a, int64_t p)
{
    int64_t t = 0, nt = 1, r = p, nr = a;
    while (nr) {
        int64_t q = r / nr, x;
        x = t - q * nt; t = nt; nt = x;
        x = r - q * nr; r = nr; nr = x;
    }
    t %= p;
    return t < 0 ? t + p : t;
}

/* Reduce acc[first:] by every pivot except the one at column skip; entries left in [0, p). Returns the
 * number of nonzero entries. */
static int64_t sweep(uint64_t *acc, int64_t first, int64_t ncols, const int64_t *pivot_of, const int64_t *starts,
                     const int64_t *ends, const int32_t *piv_cols, const int32_t *piv_vals, int64_t npiv,
                     const int32_t *scols, const int32_t *svals, uint64_t p, int delayed, int64_t skip)
{
    int64_t nnz = 0;
    for (int64_t c = first; c < ncols; c++) {
        uint64_t a = acc[c];
        if (!a)
            continue;
        if (delayed)
            a %= p;
        if (!a) {
            acc[c] = 0;
            continue;
        }
        int64_t k = pivot_of[c];
        if (k < 0 || c == skip) {
            acc[c] = a;
            nnz++;
            continue;
        }
        acc[c] = 0;
        uint64_t m = p - a; /* pivot rows are monic: add (p - a) times the row's tail */
        /* the known pivots are read where the caller keeps them, the new ones from the store */
        const int32_t *pc = (k < npiv ? piv_cols : scols) + starts[k] + 1;
        const int32_t *pv = (k < npiv ? piv_vals : svals) + starts[k] + 1;
        int64_t n = ends[k] - starts[k] - 1;
        if (delayed) {
            for (int64_t t = 0; t < n; t++)
                acc[pc[t]] += m * (uint64_t)pv[t];
        } else {
            for (int64_t t = 0; t < n; t++)
                acc[pc[t]] = (acc[pc[t]] + m * (uint64_t)pv[t]) % p;
        }
    }
    return nnz;
}

/* Move the nonzero entries of acc[first:] to cols/vals from position w on (acc left zero). */
static int64_t gather(uint64_t *acc, int64_t first, int64_t ncols, int32_t *cols, int32_t *vals, int64_t w)
{
    for (int64_t c = first; c < ncols; c++) {
        if (acc[c]) {
            cols[w] = (int32_t)c;
            vals[w] = (int32_t)acc[c];
            w++;
            acc[c] = 0;
        }
    }
    return w;
}

static int ascending(const void *x, const void *y)
{
    int64_t a = *(const int64_t *)x, b = *(const int64_t *)y;
    return (a > b) - (a < b);
}

void f4_free(void *ptr) { free(ptr); }

/* Reduce the rows by the monic pivot rows (any order, distinct leading columns). echelon != 0: the reduced
 * row echelon form of the reduced rows, nonzero rows only, monic, by increasing leading column; else every
 * row reduced on its own (zero rows kept). The result is returned in malloc'ed arrays, their addresses and
 * the row count in result[0..3] (indptr with rows + 1 entries, cols, vals, rows; free each array with
 * f4_free). Returns 0, or -1 when memory ran out. */
int f4_sparse_echelon(const int64_t *piv_indptr, const int32_t *piv_cols, const int32_t *piv_vals, int64_t npiv,
                      const int64_t *row_indptr, const int32_t *row_cols, const int32_t *row_vals, int64_t nrows,
                      int64_t ncols, int64_t prime, int echelon, int64_t *result)
{
    uint64_t p = (uint64_t)prime;
    int delayed = ((double)npiv + nrows + 1.0) * (prime - 1.0) * (prime - 1.0) + prime < 4611686018427387904.0;
    int64_t nrow_entries = row_indptr[nrows];
    int64_t *pivot_of = malloc(ncols * sizeof(int64_t));
    int64_t *starts = malloc((npiv + nrows + 1) * sizeof(int64_t));
    int64_t *ends = malloc((npiv + nrows + 1) * sizeof(int64_t));
    uint64_t *acc = calloc(ncols + 1, sizeof(uint64_t));
    int64_t *indptr = calloc(nrows + 1, sizeof(int64_t));
    store_t st = {0}, out = {0};
    int status = -1;
    if (!pivot_of || !starts || !ends || !acc || !indptr)
        goto done;
    for (int64_t c = 0; c < ncols; c++)
        pivot_of[c] = -1;
    if (room(&st, ncols > 1024 ? ncols : 1024)) /* the store holds the new pivots only */
        goto done;
    for (int64_t k = 0; k < npiv; k++) {
        starts[k] = piv_indptr[k];
        ends[k] = piv_indptr[k + 1];
        pivot_of[piv_cols[piv_indptr[k]]] = k;
    }
    int64_t count = npiv;
    if (!echelon && room(&out, nrow_entries > 16 ? nrow_entries : 16))
        goto done;
    for (int64_t r = 0; r < nrows; r++) {
        int64_t a = row_indptr[r], b = row_indptr[r + 1];
        if (a == b) {
            indptr[r + 1] = out.size;
            continue;
        }
        for (int64_t t = a; t < b; t++)
            acc[row_cols[t]] = (uint64_t)row_vals[t];
        int64_t first = row_cols[a];
        int64_t nnz = sweep(acc, first, ncols, pivot_of, starts, ends, piv_cols, piv_vals, npiv, st.cols, st.vals, p, delayed,
                            -1);
        if (!echelon) {
            if (room(&out, nnz))
                goto done;
            out.size = gather(acc, first, ncols, out.cols, out.vals, out.size);
            indptr[r + 1] = out.size;
            continue;
        }
        if (!nnz)
            continue;
        if (room(&st, nnz))
            goto done;
        int64_t lead = -1;
        uint64_t inv = 1;
        starts[count] = st.size;
        for (int64_t c = first; c < ncols; c++) {
            uint64_t v = acc[c];
            if (v) {
                if (lead < 0) {
                    lead = c;
                    inv = (uint64_t)inverse((int64_t)v, prime);
                }
                st.cols[st.size] = (int32_t)c;
                st.vals[st.size] = (int32_t)(v * inv % p);
                st.size++;
                acc[c] = 0;
            }
        }
        ends[count] = st.size;
        pivot_of[lead] = count;
        count++;
    }
    int64_t out_rows = nrows;
    if (!echelon)
        goto hand_over;
    /* the new pivots by decreasing leading column, each swept against all the others (those to its right
     * are final by then) and written back in place, or at the end of the store if it grew */
    int64_t nnew = count - npiv;
    int64_t *order = malloc((nnew + 1) * sizeof(int64_t));
    if (!order)
        goto done;
    /* (leading column, index) packed in one key: columns and counts are below 2**31 */
    for (int64_t i = 0; i < nnew; i++)
        order[i] = ((int64_t)st.cols[starts[npiv + i]] << 32) | i;
    qsort(order, nnew, sizeof(int64_t), ascending);
    for (int64_t i = 0; i < nnew; i++)
        order[i] &= 0xFFFFFFFF;
    int64_t total = 0;
    for (int64_t i = nnew - 1; i >= 0; i--) {
        int64_t k = npiv + order[i];
        int64_t s = starts[k], e = ends[k];
        int64_t lead = st.cols[s];
        for (int64_t t = s; t < e; t++)
            acc[st.cols[t]] = (uint64_t)st.vals[t];
        int64_t nnz = sweep(acc, lead, ncols, pivot_of, starts, ends, piv_cols, piv_vals, npiv, st.cols, st.vals, p,
                            delayed, lead);
        if (nnz > e - s) {
            if (room(&st, nnz)) {
                free(order);
                goto done;
            }
            s = st.size;
            st.size += nnz;
            starts[k] = s;
        }
        ends[k] = gather(acc, lead, ncols, st.cols, st.vals, s);
        total += ends[k] - s;
    }
    if (room(&out, total > 0 ? total : 1)) {
        free(order);
        goto done;
    }
    indptr[0] = 0;
    for (int64_t i = 0; i < nnew; i++) {
        int64_t k = npiv + order[i], n = ends[k] - starts[k];
        memcpy(out.cols + out.size, st.cols + starts[k], n * sizeof(int32_t));
        memcpy(out.vals + out.size, st.vals + starts[k], n * sizeof(int32_t));
        out.size += n;
        indptr[i + 1] = out.size;
    }
    free(order);
    out_rows = nnew;
hand_over: /* the caller owns indptr, out.cols and out.vals from here */
    result[0] = (int64_t)(intptr_t)indptr;
    result[1] = (int64_t)(intptr_t)out.cols;
    result[2] = (int64_t)(intptr_t)out.vals;
    result[3] = out_rows;
    indptr = NULL;
    out.cols = out.vals = NULL;
    status = 0;
done:
    free(pivot_of);
    free(starts);
    free(ends);
    free(acc);
    free(indptr);
    free(st.cols);
    free(st.vals);
    free(out.cols);
    free(out.vals);
    return status;
}
