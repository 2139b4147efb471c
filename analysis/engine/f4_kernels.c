/* Sparse row reduction mod p for F4 matrices: the C twin of analysis/engine/sparse_kernels.py.
 *
 * Loaded through ctypes by analysis/engine/native.py (compiled there on first use with the system's C compiler
 * and cached); no Python API. Same results as the numba kernel sparse_echelon, and the same design: the
 * rows are reduced in dense 64-bit accumulators by the sparse, unreduced pivot rows, with delayed modular
 * reduction where the sums cannot overflow (small primes) and accumulators bounded by p**2 by one compare
 * and subtract per product elsewhere (31-bit primes; modulus_t), never a division per product; in echelon
 * mode the rows that do not vanish become pivots, and at the end every new pivot is swept once more
 * (reduced row echelon form). Unlike the numba kernel the rows go BLOCK at a time, in interleaved
 * accumulators: a pivot row is read once per block and applied to all its rows with vector multiplies, and
 * the rows of a block that find no pivot at a column eliminate it among themselves. With OpenMP the blocks
 * and the final sweeps are shared among threads (reduce_blocks, back_substitute); the reduced row echelon
 * form being unique, the result does not depend on the threads.
 *
 * Reference: J. Berthomieu, C. Eder, M. Safey El Din, "msolve: a library for solving polynomial systems",
 * ISSAC 2021 (known pivots kept sparse, delayed reduction in 64-bit accumulators).
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#if defined(__x86_64__)
#include <immintrin.h>
#endif
#if defined(_OPENMP)
#include <omp.h>
#endif

/* Built with -fopenmp where the compiler has it (analysis/engine/native.py): the row reduction, the symbolic
 * preprocessing, the column lookup and the pair update then share their independent work among the threads
 * asked for; without it every pragma is ignored. */
int f4_openmp(void)
{
#if defined(_OPENMP)
    return 1;
#else
    return 0;
#endif
}

/* Nonzero: every step that can share its work among threads does so, however small (the steps below
 * stay on one thread under a size where waking a second costs more than it saves). Set by the tests
 * (analysis/engine/native.py: share_small_work), so that small systems run the threaded code paths. */
int f4_share_small = 0;

/* The pivot rows, known and new, by index k: columns cols[k][0 .. len[k]) and values vals[k][...], the
 * leading entry 1 at cols[k][0]; at[c] is the pivot whose leading column is c, or -1. A new pivot is
 * published by a compare-and-swap on at[lead] after its row is written (release; readers load at[c] with
 * acquire), so a thread that finds a pivot reads all of its row. A slot whose row is not published has
 * len[k] = -1. */
typedef struct {
    const int32_t **cols, **vals;
    int64_t *len, *at;
    int64_t count; /* slots handed out: the known pivots, then one per new row that tried to publish */
    int32_t **fin; /* during the back substitution: the final row of pivot k (columns, then values) once
                      published, else NULL; its length fin_len[k] */
    int64_t *fin_len;
} pivots_t;

/* the columns, values and length of pivot k: its final row where one is published, else its row */
static inline const int32_t *pivot_row(const pivots_t *pv, int64_t k, const int32_t **vals, int64_t *len)
{
    const int32_t *f = pv->fin ? __atomic_load_n(&pv->fin[k], __ATOMIC_ACQUIRE) : NULL;
    if (f) {
        *len = pv->fin_len[k];
        *vals = f + *len;
        return f;
    }
    *len = pv->len[k];
    *vals = pv->vals[k];
    return pv->cols[k];
}

static inline int64_t pivot_at(const pivots_t *pv, int64_t c) { return __atomic_load_n(&pv->at[c], __ATOMIC_ACQUIRE); }

/* A malloc'ed copy of n columns and values (one array: the columns, then the values), or NULL when n is 0
 * or memory ran out (*oom set). */
static int32_t *new_row(const int32_t *cols, const int32_t *vals, int64_t n, int *oom)
{
    if (!n)
        return NULL;
    int32_t *row = malloc(2 * n * sizeof(int32_t));
    if (!row) {
        __atomic_store_n(oom, 1, __ATOMIC_RELAXED);
        return NULL;
    }
    memcpy(row, cols, n * sizeof(int32_t));
    memcpy(row + n, vals, n * sizeof(int32_t));
    return row;
}

/* The prime and its arithmetic. Products of two entries (< p < 2**31) are below p2 = p * p < 2**62. An
 * accumulator is either delayed (no reduction until it is read; chosen when the largest possible sum of
 * products, one per pivot and row, stays below 2**62) or bounded: kept below p2 by subtracting p2 after
 * every addition (the sum of an accumulator and a product is below 2 * p2 < 2**63), as msolve's 31-bit
 * kernels do; a single compare and subtract, no division. Entries are brought to [0, p) by Barrett
 * reduction (a multiply by a precomputed floor(2**64 / p), no division). */
typedef struct {
    uint64_t p, p2, barrett;
    int delayed;
} modulus_t;

static modulus_t modulus(uint64_t p, double additions)
{
    modulus_t m = {p, p * p, UINT64_MAX / p, additions * (p - 1.0) * (p - 1.0) + p < 4611686018427387904.0};
    return m;
}

/* x mod p for any 64-bit x: the quotient estimate (x * floor(2**64 / p)) >> 64 is short by at most 2 */
static inline uint64_t reduce(const modulus_t *m, uint64_t x)
{
#if defined(__SIZEOF_INT128__)
    uint64_t r = x - (uint64_t)(((unsigned __int128)x * m->barrett) >> 64) * m->p;
    r = r >= m->p ? r - m->p : r;
    return r >= m->p ? r - m->p : r;
#else
    return x % m->p;
#endif
}

/* a bounded accumulator after one addition (x < 2 * p2): below p2 again */
static inline uint64_t bound(uint64_t x, uint64_t p2) { return x >= p2 ? x - p2 : x; }

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
static int64_t sweep(uint64_t *acc, int64_t first, int64_t ncols, const pivots_t *pv, const modulus_t *mod,
                     int64_t skip)
{
    int64_t nnz = 0;
    uint64_t p = mod->p, p2 = mod->p2;
    for (int64_t c = first; c < ncols; c++) {
        uint64_t a = acc[c];
        if (!a)
            continue;
        a = reduce(mod, a);
        if (!a) {
            acc[c] = 0;
            continue;
        }
        int64_t k = pivot_at(pv, c);
        if (k < 0 || c == skip) {
            acc[c] = a;
            nnz++;
            continue;
        }
        acc[c] = 0;
        uint64_t m = p - a; /* pivot rows are monic: add (p - a) times the row's tail */
        const int32_t *pvv;
        int64_t n;
        const int32_t *pc = pivot_row(pv, k, &pvv, &n) + 1;
        pvv++;
        n--;
        if (mod->delayed) {
            for (int64_t t = 0; t < n; t++)
                acc[pc[t]] += m * (uint64_t)pvv[t];
        } else {
            for (int64_t t = 0; t < n; t++)
                acc[pc[t]] = bound(acc[pc[t]] + m * (uint64_t)pvv[t], p2);
        }
    }
    return nnz;
}

/* Move the nonzero entries of acc[first:] to cols/vals (acc left zero); returns their number. */
static int64_t gather(uint64_t *acc, int64_t first, int64_t ncols, int32_t *cols, int32_t *vals)
{
    int64_t w = 0;
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

#define BLOCK 8 /* rows reduced together: each pivot row is read once per block, not once per row */

/* y[c * BLOCK + r] += m[r] * v[t] at the columns c = col[t] of a pivot's tail, all BLOCK rows at once.
 * m[r] and v[t] are below 2**31, so every product is one 32 x 32 -> 64-bit vector multiply. Delayed
 * accumulators take the sum as it is; bounded ones (see modulus_t) are brought below p2 again by one
 * compare and subtract (AVX-512: min(y, y - p2) in unsigned lanes, y - p2 wrapping around when y < p2).
 * AVX-512 or AVX2 where the processor has it (checked at run time), else SSE2 (every x86-64; bounded:
 * plain C), else plain C. */
static void axpy_plain(uint64_t *bacc, const int32_t *col, const int32_t *val, int64_t n, const uint32_t *m,
                       uint64_t p2)
{
    (void)p2;
    for (int64_t t = 0; t < n; t++) {
        uint64_t v = (uint32_t)val[t], *y = bacc + (int64_t)col[t] * BLOCK;
        for (int r = 0; r < BLOCK; r++)
            y[r] += (uint64_t)m[r] * v;
    }
}

static void axpy_plain_bounded(uint64_t *bacc, const int32_t *col, const int32_t *val, int64_t n,
                               const uint32_t *m, uint64_t p2)
{
    for (int64_t t = 0; t < n; t++) {
        uint64_t v = (uint32_t)val[t], *y = bacc + (int64_t)col[t] * BLOCK;
        for (int r = 0; r < BLOCK; r++)
            y[r] = bound(y[r] + (uint64_t)m[r] * v, p2);
    }
}

#if defined(__x86_64__)
static void axpy_sse2(uint64_t *bacc, const int32_t *col, const int32_t *val, int64_t n, const uint32_t *m,
                      uint64_t p2)
{
    (void)p2;
    __m128i m01 = _mm_set_epi64x(m[1], m[0]), m23 = _mm_set_epi64x(m[3], m[2]);
    __m128i m45 = _mm_set_epi64x(m[5], m[4]), m67 = _mm_set_epi64x(m[7], m[6]);
    for (int64_t t = 0; t < n; t++) {
        __m128i v = _mm_set1_epi64x((uint32_t)val[t]);
        __m128i *y = (__m128i *)(bacc + (int64_t)col[t] * BLOCK);
        _mm_storeu_si128(y, _mm_add_epi64(_mm_loadu_si128(y), _mm_mul_epu32(m01, v)));
        _mm_storeu_si128(y + 1, _mm_add_epi64(_mm_loadu_si128(y + 1), _mm_mul_epu32(m23, v)));
        _mm_storeu_si128(y + 2, _mm_add_epi64(_mm_loadu_si128(y + 2), _mm_mul_epu32(m45, v)));
        _mm_storeu_si128(y + 3, _mm_add_epi64(_mm_loadu_si128(y + 3), _mm_mul_epu32(m67, v)));
    }
}

__attribute__((target("avx2"))) static void axpy_avx2(uint64_t *bacc, const int32_t *col, const int32_t *val,
                                                      int64_t n, const uint32_t *m, uint64_t p2)
{
    (void)p2;
    __m256i lo = _mm256_set_epi64x(m[3], m[2], m[1], m[0]), hi = _mm256_set_epi64x(m[7], m[6], m[5], m[4]);
    for (int64_t t = 0; t < n; t++) {
        __m256i v = _mm256_set1_epi64x((uint32_t)val[t]);
        __m256i *y = (__m256i *)(bacc + (int64_t)col[t] * BLOCK);
        _mm256_storeu_si256(y, _mm256_add_epi64(_mm256_loadu_si256(y), _mm256_mul_epu32(lo, v)));
        _mm256_storeu_si256(y + 1, _mm256_add_epi64(_mm256_loadu_si256(y + 1), _mm256_mul_epu32(hi, v)));
    }
}

/* the sums are below 2**63, so the signed compare y > p2 - 1 is the unsigned one */
__attribute__((target("avx2"))) static void axpy_avx2_bounded(uint64_t *bacc, const int32_t *col,
                                                              const int32_t *val, int64_t n, const uint32_t *m,
                                                              uint64_t p2)
{
    __m256i lo = _mm256_set_epi64x(m[3], m[2], m[1], m[0]), hi = _mm256_set_epi64x(m[7], m[6], m[5], m[4]);
    __m256i q = _mm256_set1_epi64x((int64_t)p2), q1 = _mm256_set1_epi64x((int64_t)p2 - 1);
    for (int64_t t = 0; t < n; t++) {
        __m256i v = _mm256_set1_epi64x((uint32_t)val[t]);
        __m256i *y = (__m256i *)(bacc + (int64_t)col[t] * BLOCK);
        __m256i a = _mm256_add_epi64(_mm256_loadu_si256(y), _mm256_mul_epu32(lo, v));
        __m256i b = _mm256_add_epi64(_mm256_loadu_si256(y + 1), _mm256_mul_epu32(hi, v));
        a = _mm256_sub_epi64(a, _mm256_and_si256(_mm256_cmpgt_epi64(a, q1), q));
        b = _mm256_sub_epi64(b, _mm256_and_si256(_mm256_cmpgt_epi64(b, q1), q));
        _mm256_storeu_si256(y, a);
        _mm256_storeu_si256(y + 1, b);
    }
}

__attribute__((target("avx512f"))) static void axpy_avx512(uint64_t *bacc, const int32_t *col, const int32_t *val,
                                                           int64_t n, const uint32_t *m, uint64_t p2)
{
    (void)p2;
    __m512i mm = _mm512_set_epi64(m[7], m[6], m[5], m[4], m[3], m[2], m[1], m[0]);
    for (int64_t t = 0; t < n; t++) {
        uint64_t *y = bacc + (int64_t)col[t] * BLOCK;
        __m512i v = _mm512_set1_epi64((uint32_t)val[t]);
        _mm512_storeu_si512(y, _mm512_add_epi64(_mm512_loadu_si512(y), _mm512_mul_epu32(mm, v)));
    }
}

__attribute__((target("avx512f"))) static void axpy_avx512_bounded(uint64_t *bacc, const int32_t *col,
                                                                   const int32_t *val, int64_t n, const uint32_t *m,
                                                                   uint64_t p2)
{
    __m512i mm = _mm512_set_epi64(m[7], m[6], m[5], m[4], m[3], m[2], m[1], m[0]), q = _mm512_set1_epi64((int64_t)p2);
    for (int64_t t = 0; t < n; t++) {
        uint64_t *y = bacc + (int64_t)col[t] * BLOCK;
        __m512i v = _mm512_set1_epi64((uint32_t)val[t]);
        __m512i a = _mm512_add_epi64(_mm512_loadu_si512(y), _mm512_mul_epu32(mm, v));
        _mm512_storeu_si512(y, _mm512_min_epu64(a, _mm512_sub_epi64(a, q)));
    }
}
#endif

typedef void (*axpy_t)(uint64_t *, const int32_t *, const int32_t *, int64_t, const uint32_t *, uint64_t);

/* The widest vector version this processor runs, for delayed or bounded accumulators. F4_KERNEL_ISA
 * (avx512, avx2, sse2 or plain) caps it: a comparison of the versions on one machine. */
static axpy_t pick_axpy(int delayed)
{
    const char *cap = getenv("F4_KERNEL_ISA");
    int level = 3; /* 3 avx512, 2 avx2, 1 sse2, 0 plain */
    if (cap)
        level = !strcmp(cap, "avx2") ? 2 : !strcmp(cap, "sse2") ? 1 : !strcmp(cap, "plain") ? 0 : 3;
#if defined(__x86_64__)
    __builtin_cpu_init();
    if (level >= 3 && __builtin_cpu_supports("avx512f"))
        return delayed ? axpy_avx512 : axpy_avx512_bounded;
    if (level >= 2 && __builtin_cpu_supports("avx2"))
        return delayed ? axpy_avx2 : axpy_avx2_bounded;
    if (level >= 1 && delayed)
        return axpy_sse2;
#endif
    (void)level;
    return delayed ? axpy_plain : axpy_plain_bounded;
}

/* Reduce a block of rows, held interleaved in bacc[c * BLOCK + r], from column first on by every pivot.
 * In echelon mode, at a column without a pivot the first nonzero row of the block that has no lead yet
 * takes it as its lead (lead[r] = c) and the column is eliminated from the other rows without a lead (the
 * block's own Gaussian elimination). Leaves every entry in [0, p). Undesignated rows end zero. */
static void block_sweep(uint64_t *bacc, int nb, int64_t first, int64_t ncols, const pivots_t *pv,
                        const modulus_t *mod, int echelon, int64_t *lead, axpy_t axpy)
{
    uint32_t m[BLOCK]; /* 32 x 32 -> 64-bit products: one vector multiply for several rows */
    const uint64_t p = mod->p, p2 = mod->p2;
    const int delayed = mod->delayed;
    for (int64_t c = first; c < ncols; c++) {
        uint64_t *a = bacc + c * BLOCK;
        uint64_t any = 0;
        for (int r = 0; r < BLOCK; r++)
            any |= a[r];
        if (!any)
            continue;
        int hits = 0, last = 0;
        for (int r = 0; r < BLOCK; r++) {
            a[r] = reduce(mod, a[r]);
            if (a[r]) {
                hits++;
                last = r;
            }
        }
        if (!hits)
            continue;
        int64_t k = pivot_at(pv, c);
        if (k >= 0) {
            const int32_t *pc = pv->cols[k] + 1, *pvv = pv->vals[k] + 1;
            int64_t n = pv->len[k] - 1;
            if (hits == 1) {
                uint64_t mm = p - a[last], *x = bacc + last;
                a[last] = 0;
                if (delayed) {
                    for (int64_t t = 0; t < n; t++)
                        x[(int64_t)pc[t] * BLOCK] += mm * (uint64_t)pvv[t];
                } else {
                    for (int64_t t = 0; t < n; t++) {
                        uint64_t *y = x + (int64_t)pc[t] * BLOCK;
                        *y = bound(*y + mm * (uint64_t)pvv[t], p2);
                    }
                }
                continue;
            }
            for (int r = 0; r < BLOCK; r++) {
                m[r] = (uint32_t)(a[r] ? p - a[r] : 0); /* pivot rows are monic: add (p - a) times the tail */
                a[r] = 0;
            }
            axpy(bacc, pc, pvv, n, m, p2);
            continue;
        }
        if (!echelon)
            continue;
        int r0 = -1;
        for (int r = 0; r < nb && r0 < 0; r++)
            if (a[r] && lead[r] < 0)
                r0 = r;
        if (r0 < 0)
            continue;
        lead[r0] = c;
        uint64_t inv = (uint64_t)inverse((int64_t)a[r0], (int64_t)p);
        for (int r = 0; r < nb; r++) {
            if (r == r0 || !a[r] || lead[r] >= 0)
                continue;
            uint64_t mm = reduce(mod, (p - a[r]) * inv);
            a[r] = 0;
            for (int64_t j = c + 1; j < ncols; j++) {
                uint64_t x = bacc[j * BLOCK + r0];
                if (!x)
                    continue;
                uint64_t *y = bacc + j * BLOCK + r;
                if (delayed)
                    *y += mm * reduce(mod, x);
                else
                    *y = bound(*y + mm * reduce(mod, x), p2);
            }
        }
    }
}


/* Copy the nonzero entries of row r of the block from column first on, times scale mod p, to cols and vals
 * (the block is left zero there); returns their number. */
static int64_t gather_row(uint64_t *bacc, int r, int64_t first, int64_t ncols, int32_t *cols, int32_t *vals,
                          uint64_t scale, const modulus_t *mod)
{
    int64_t w = 0;
    for (int64_t c = first; c < ncols; c++) {
        uint64_t v = bacc[c * BLOCK + r];
        if (v) {
            cols[w] = (int32_t)c;
            vals[w] = (int32_t)(scale == 1 ? v : reduce(mod, v * scale));
            w++;
            bacc[c * BLOCK + r] = 0;
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

/* Reduce blocks of rows (rows[b * BLOCK ...], by their numbers in order) by the pivots, one block at a time
 * per thread, blocks handed out in order. In echelon mode a row left with a lead becomes a new pivot (monic)
 * when it wins the compare-and-swap at its lead; when another thread published a pivot there first, the
 * row is put back and goes on reducing. Else row i's reduced entries go to each[i] (length each_len[i]). */
static void reduce_blocks(const int64_t *row_indptr, const int32_t *row_cols, const int32_t *row_vals,
                          const int64_t *row_voff, const int64_t *order, int64_t nrows, int64_t ncols, pivots_t *pv,
                          const modulus_t *mod, int echelon, int threads, int32_t **each, int64_t *each_len, int *oom)
{
    int64_t nblocks = (nrows + BLOCK - 1) / BLOCK, next = 0;
    (void)nblocks; /* read by OpenMP only */
    axpy_t axpy = pick_axpy(mod->delayed);
#pragma omp parallel num_threads(threads) if (threads > 1 && nblocks > 1)
    {
        uint64_t *bacc = calloc((size_t)ncols * BLOCK + 1, sizeof(uint64_t));
        int32_t *scratch = malloc((2 * ncols + 2) * sizeof(int32_t)); /* a row's columns, then its values */
        if (!bacc || !scratch)
            __atomic_store_n(oom, 1, __ATOMIC_RELAXED);
        while (!__atomic_load_n(oom, __ATOMIC_RELAXED)) {
            int64_t b0 = __atomic_fetch_add(&next, 1, __ATOMIC_RELAXED) * BLOCK;
            if (b0 >= nrows)
                break;
            int nb = nrows - b0 < BLOCK ? (int)(nrows - b0) : BLOCK;
            int64_t first = ncols, lead[BLOCK], slot[BLOCK];
            int published[BLOCK]; /* the row is a pivot now (and zero in the block) */
            for (int r = 0; r < nb; r++) {
                int64_t row = order[b0 + r];
                lead[r] = slot[r] = -1;
                published[r] = 0;
                const int32_t *rv = row_vals + row_voff[row] - row_indptr[row];
                for (int64_t t = row_indptr[row]; t < row_indptr[row + 1]; t++)
                    bacc[(int64_t)row_cols[t] * BLOCK + r] = (uint64_t)rv[t];
                if (row_indptr[row] < row_indptr[row + 1] && row_cols[row_indptr[row]] < first)
                    first = row_cols[row_indptr[row]];
            }
            while (first < ncols) { /* until every row of the block is published or zero */
                block_sweep(bacc, nb, first, ncols, pv, mod, echelon, lead, axpy);
                first = ncols;
                for (int r = 0; r < nb; r++) {
                    if (!echelon) {
                        int64_t row = order[b0 + r];
                        int64_t n = gather_row(bacc, r, 0, ncols, scratch, scratch + ncols, 1, mod);
                        each[row] = new_row(scratch, scratch + ncols, n, oom);
                        each_len[row] = n;
                        continue;
                    }
                    if (lead[r] < 0 || published[r])
                        continue;
                    uint64_t inv = (uint64_t)inverse((int64_t)bacc[lead[r] * BLOCK + r], (int64_t)mod->p);
                    int64_t n = gather_row(bacc, r, lead[r], ncols, scratch, scratch + ncols, inv, mod);
                    int32_t *row = new_row(scratch, scratch + ncols, n, oom);
                    if (!row)
                        break;
                    if (slot[r] < 0) /* kept through retries: at most one slot per row */
                        slot[r] = __atomic_fetch_add(&pv->count, 1, __ATOMIC_RELAXED);
                    int64_t k = slot[r], free_slot = -1;
                    pv->cols[k] = row;
                    pv->vals[k] = row + n;
                    pv->len[k] = n;
                    if (__atomic_compare_exchange_n(&pv->at[lead[r]], &free_slot, k, 0, __ATOMIC_RELEASE,
                                                    __ATOMIC_RELAXED)) {
                        published[r] = 1;
                        continue;
                    }
                    /* another thread published a pivot at this lead first: the row reduces on from there */
                    pv->len[k] = -1;
                    for (int64_t t = 0; t < n; t++)
                        bacc[(int64_t)row[t] * BLOCK + r] = (uint64_t)row[n + t];
                    first = lead[r] < first ? lead[r] : first;
                    lead[r] = -1;
                    free(row);
                }
            }
        }
        free(bacc);
        free(scratch);
    }
}

/* Sweep every new pivot (slots order[0 .. nnew), by increasing leading column) against all the other pivots,
 * from the right: then each is reduced (zero at every other pivot's column). The threads take the pivots
 * in that order and publish each final row (fin); a sweep reads the final rows where they are published
 * (all of those to its right on one thread: they are sparser) and the others as they were (a row swept by
 * a pivot that is not final is still fully reduced: the sweep goes on to the columns that pivot brings in).
 * At the end the final rows replace the rows. */
static void back_substitute(pivots_t *pv, const int64_t *order, int64_t nnew, int64_t ncols, const modulus_t *mod,
                            int threads, int *oom)
{
    int64_t next = nnew - 1;
    pv->fin = calloc(pv->count + 1, sizeof(int32_t *));
    pv->fin_len = calloc(pv->count + 1, sizeof(int64_t));
    if (!pv->fin || !pv->fin_len)
        *oom = 1;
#pragma omp parallel num_threads(threads) if (threads > 1 && nnew > 1)
    {
        uint64_t *acc = calloc(ncols + 1, sizeof(uint64_t));
        int32_t *cols = malloc((2 * ncols + 2) * sizeof(int32_t)), *vals = cols + ncols;
        if (!acc || !cols)
            __atomic_store_n(oom, 1, __ATOMIC_RELAXED);
        while (!__atomic_load_n(oom, __ATOMIC_RELAXED)) {
            int64_t i = __atomic_fetch_sub(&next, 1, __ATOMIC_RELAXED);
            if (i < 0)
                break;
            int64_t k = order[i], lead = pv->cols[k][0];
            for (int64_t t = 0; t < pv->len[k]; t++)
                acc[pv->cols[k][t]] = (uint64_t)pv->vals[k][t];
            sweep(acc, lead, ncols, pv, mod, lead);
            int64_t n = gather(acc, lead, ncols, cols, vals);
            int32_t *row = new_row(cols, vals, n, oom);
            pv->fin_len[k] = n;
            __atomic_store_n(&pv->fin[k], row, __ATOMIC_RELEASE);
        }
        free(acc);
        free(cols);
    }
    for (int64_t i = 0; i < nnew && !*oom; i++) {
        int64_t k = order[i];
        free((void *)pv->cols[k]);
        pv->cols[k] = pv->fin[k];
        pv->vals[k] = pv->fin[k] + pv->fin_len[k];
        pv->len[k] = pv->fin_len[k];
        pv->fin[k] = NULL;
    }
    if (pv->fin)
        for (int64_t i = 0; i < nnew; i++)
            free(pv->fin[order[i]]);
    free(pv->fin);
    free(pv->fin_len);
    pv->fin = NULL;
}

/* Reduce the rows by the monic pivot rows (any order, distinct leading columns). The values of row i of a
 * block are vals[voff[i] :] (one pool may serve many rows: an F4 row repeats the coefficients of the basis
 * element it is a multiple of). echelon != 0: the reduced row echelon form of the reduced rows, nonzero
 * rows only, monic, by increasing leading column; else every row reduced on its own (zero rows kept). The
 * work is shared among up to threads threads (OpenMP; one without it): the result is the same, the reduced
 * row echelon form being unique. The result is returned in malloc'ed arrays, their addresses and the row
 * count in result[0..3] (indptr with rows + 1 entries, cols, vals, rows; free each array with f4_free).
 * Returns 0, or -1 when memory ran out. */
int f4_sparse_echelon(const int64_t *piv_indptr, const int32_t *piv_cols, const int32_t *piv_vals,
                      const int64_t *piv_voff, int64_t npiv, const int64_t *row_indptr, const int32_t *row_cols,
                      const int32_t *row_vals, const int64_t *row_voff, int64_t nrows,
                      int64_t ncols, int64_t prime, int echelon, int threads, int64_t *result)
{
    const modulus_t mod = modulus((uint64_t)prime, (double)npiv + nrows + 1.0);
    int64_t total = npiv + nrows, out_rows = 0, nnz = 0;
    pivots_t pv = {malloc((total + 1) * sizeof(int32_t *)), malloc((total + 1) * sizeof(int32_t *)),
                   malloc((total + 1) * sizeof(int64_t)), malloc((ncols + 1) * sizeof(int64_t)), npiv, NULL, NULL};
    int64_t *order = malloc((nrows + 1) * sizeof(int64_t)), *indptr = calloc(nrows + 1, sizeof(int64_t));
    int32_t **each = echelon ? NULL : calloc(nrows + 1, sizeof(int32_t *));
    int64_t *each_len = echelon ? NULL : calloc(nrows + 1, sizeof(int64_t));
    int32_t *cols = NULL, *vals = NULL;
    int oom = !pv.cols || !pv.vals || !pv.len || !pv.at || !order || !indptr || (!echelon && (!each || !each_len));
    threads = threads < 1 ? 1 : threads;
    if (oom)
        goto done;
    for (int64_t c = 0; c < ncols; c++)
        pv.at[c] = -1;
    for (int64_t k = 0; k < npiv; k++) {
        pv.cols[k] = piv_cols + piv_indptr[k];
        pv.vals[k] = piv_vals + piv_voff[k];
        pv.len[k] = piv_indptr[k + 1] - piv_indptr[k];
        pv.at[piv_cols[piv_indptr[k]]] = k;
    }
    /* in echelon mode the rows go by leading column, so that a block's rows fill in alike */
    for (int64_t r = 0; r < nrows; r++) {
        int64_t first = row_indptr[r] < row_indptr[r + 1] ? row_cols[row_indptr[r]] : ncols;
        order[r] = echelon ? (first << 32) | r : r;
    }
    if (echelon) {
        qsort(order, nrows, sizeof(int64_t), ascending);
        for (int64_t r = 0; r < nrows; r++)
            order[r] &= 0xFFFFFFFF;
    }
    reduce_blocks(row_indptr, row_cols, row_vals, row_voff, order, nrows, ncols, &pv, &mod, echelon, threads, each,
                  each_len, &oom);
    if (oom)
        goto done;
    if (echelon) { /* the new pivots (published slots) by leading column */
        for (int64_t k = npiv; k < pv.count; k++)
            if (pv.len[k] > 0)
                order[out_rows++] = ((int64_t)pv.cols[k][0] << 32) | k;
        qsort(order, out_rows, sizeof(int64_t), ascending);
        for (int64_t i = 0; i < out_rows; i++)
            order[i] &= 0xFFFFFFFF;
        back_substitute(&pv, order, out_rows, ncols, &mod, threads, &oom);
        if (oom)
            goto done;
    } else {
        out_rows = nrows;
    }
    for (int64_t i = 0; i < out_rows; i++)
        nnz += echelon ? pv.len[order[i]] : each_len[i];
    cols = malloc((nnz + 1) * sizeof(int32_t));
    vals = malloc((nnz + 1) * sizeof(int32_t));
    if (!cols || !vals) {
        oom = 1;
        goto done;
    }
    for (int64_t i = 0, w = 0; i < out_rows; i++) {
        const int32_t *c = echelon ? pv.cols[order[i]] : each[i];
        int64_t n = echelon ? pv.len[order[i]] : each_len[i];
        if (n) {
            memcpy(cols + w, c, n * sizeof(int32_t));
            memcpy(vals + w, c + n, n * sizeof(int32_t));
        }
        w += n;
        indptr[i + 1] = w;
    }
    result[0] = (int64_t)(intptr_t)indptr; /* the caller owns indptr, cols and vals from here */
    result[1] = (int64_t)(intptr_t)cols;
    result[2] = (int64_t)(intptr_t)vals;
    result[3] = out_rows;
    indptr = NULL;
    cols = vals = NULL;
done:
    if (pv.cols && pv.len)
        for (int64_t k = npiv; k < pv.count; k++)
            if (pv.len[k] >= 0)
                free((void *)pv.cols[k]);
    if (each)
        for (int64_t i = 0; i < nrows; i++)
            free(each[i]);
    free(pv.cols);
    free(pv.vals);
    free(pv.len);
    free(pv.at);
    free(order);
    free(indptr);
    free(each);
    free(each_len);
    free(cols);
    free(vals);
    return oom ? -1 : 0;
}

static int divides(const int32_t *a, const int32_t *b, int64_t n)
{
    for (int64_t v = 0; v < n; v++)
        if (a[v] > b[v])
            return 0;
    return 1;
}

/* bit v % 64 for every variable v with a positive exponent: a lead can divide only monomials whose mask
 * holds its own */
static uint64_t support_mask(const int32_t *e, int64_t n)
{
    uint64_t mask = 0;
    for (int64_t v = 0; v < n; v++)
        if (e[v])
            mask |= (uint64_t)1 << (v & 63);
    return mask;
}

/* Divisibility masks (as msolve's divmasks): bit j of variable v (bit (v * bits + j) mod 64) is set when
 * the exponent reaches thr[v * bits + j]; a divides b only if mask(a) is contained in mask(b), so one AND
 * rejects most candidates before the exponents are compared. The thresholds spread over 1 .. the largest
 * exponent of each variable among the rows given (any thresholds keep the test exact). */
typedef struct {
    int32_t *thr;
    int bits;
} divmask_t;

static int divmask_init(divmask_t *dm, const int32_t *E, int64_t rows, int64_t n)
{
    dm->bits = n >= 64 ? 1 : (int)(64 / n);
    if (dm->bits > 8)
        dm->bits = 8;
    dm->thr = malloc((n * dm->bits + 1) * sizeof(int32_t));
    if (!dm->thr)
        return -1;
    for (int64_t v = 0; v < n; v++) {
        int32_t top = 1;
        for (int64_t i = 0; i < rows; i++)
            top = E[i * n + v] > top ? E[i * n + v] : top;
        for (int j = 0; j < dm->bits; j++)
            dm->thr[v * dm->bits + j] = 1 + (int32_t)((int64_t)j * (top - 1) / dm->bits);
    }
    return 0;
}

static uint64_t divmask(const divmask_t *dm, const int32_t *e, int64_t n)
{
    uint64_t mask = 0;
    for (int64_t v = 0; v < n; v++)
        for (int j = 0; j < dm->bits && e[v] >= dm->thr[v * dm->bits + j]; j++)
            mask |= (uint64_t)1 << ((v * dm->bits + j) & 63);
    return mask;
}

static int64_t lcm_degree(const int32_t *a, const int32_t *b, int64_t n)
{
    int64_t d = 0;
    for (int64_t v = 0; v < n; v++)
        d += a[v] > b[v] ? a[v] : b[v];
    return d;
}

/* Gebauer-Moeller pair update of analysis/engine/f4.py (_State.insert), for new elements h_t = k + t, t < m, inserted
 * one after the other. E: exponents (k + m rows of nvars), deg: their degrees, active: flags of the k old
 * elements (updated in place, k + m entries). Existing pairs: npairs rows (i, j, lcm degree) with lcm
 * exponents lcm; keep[q] is cleared for those criterion B drops. The new pairs (g, h_t, lcm degree), in
 * order of t and then g, and their lcm exponents, go to malloc'ed arrays whose addresses and count are
 * result[0..2] (free with f4_free); born[q] of each new pair is t, or -1 where a later h_u dropped it by
 * criterion B. Returns 0, or -1 when memory ran out.
 *
 * The m insertions are done as three passes with the outcome of inserting h_0, h_1, ... in turn, each pass
 * shared among up to threads threads: (1) the activity spans: g is a partner of h_t when it was active
 * before t (born) and no h_u with born < u < t divides lm(g) (dies: the first such u); (2) the new pairs of
 * every h_t from its partners (criteria M and F), each t on its own into its own list, the lists then
 * joined in order of t; (3) criterion B on every pair, old (born -1) and new, by the h_u inserted after
 * it. No step depends on a pair another step drops, so the pairs are those of the one-by-one update. */
/* Below this many partner tests (m x (k + m), a few nanoseconds each) the update stays on one thread: waking
 * a sleeping one costs tens of microseconds. */
#define UPDATE_PARALLEL_TESTS 200000

typedef struct { /* one thread's scratch for the new pairs of one h_t */
    int64_t *partners, *pdeg, *by_degree, *minimal, *bucket, bucket_cap;
    int32_t *L;
    uint8_t *coprime, *dropped;
    uint64_t *lmask;
} update_scratch_t;

/* The new pairs of h = k + t among its partners (the elements g < h with born[g] < t <= dies[g]): rows
 * (g, h, lcm degree, t) to *out and lcm exponents to *out_lcm (malloc'ed), their number to *count.
 * Returns 0, or -1 when memory ran out. */
static int new_pairs_of(int64_t t, int64_t k, int64_t n, const int32_t *E, const int64_t *deg, const int64_t *born,
                        const int64_t *dies, const uint64_t *emask, update_scratch_t *w, int64_t **out,
                        int32_t **out_lcm, int64_t *count)
{
    int64_t h = k + t, np = 0;
    const int32_t *eh = E + h * n;
    const uint64_t hmask = emask[h];
    for (int64_t g = 0; g < h; g++) {
        if (born[g] >= t || dies[g] < t)
            continue;
        w->partners[np] = g;
        int32_t *l = w->L + np * n;
        const int32_t *eg = E + g * n;
        int64_t d = 0;
        for (int64_t v = 0; v < n; v++) {
            l[v] = eg[v] > eh[v] ? eg[v] : eh[v];
            d += l[v];
        }
        w->pdeg[np] = d;
        w->coprime[np] = d == deg[g] + deg[h];
        w->lmask[np] = emask[g] | hmask; /* the mask of a max is the union of the masks */
        np++;
    }
    *out = NULL;
    *out_lcm = NULL;
    *count = 0;
    if (!np)
        return 0;
    /* criterion M (a partner's lcm properly divides this one's: dropped) and F (of the partners with
     * equal lcms the first is kept, none if one of them is coprime). The partners go by increasing lcm
     * degree; M is tested against one partner per distinct lcm that M kept (minimal[0 .. nmin), all of
     * lower degree): a proper divisor that M dropped has a kept one dividing it in turn. So the test is
     * against the few minimal lcms, not all the partners. */
    int64_t low = INT64_MAX, high = 0; /* counting sort: the lcm degrees span a short range */
    for (int64_t c = 0; c < np; c++) {
        low = w->pdeg[c] < low ? w->pdeg[c] : low;
        high = w->pdeg[c] > high ? w->pdeg[c] : high;
    }
    if (high - low + 2 > w->bucket_cap) {
        int64_t cap = 2 * (high - low + 2), *bucket = realloc(w->bucket, cap * sizeof(int64_t));
        if (!bucket)
            return -1;
        w->bucket = bucket;
        w->bucket_cap = cap;
    }
    int64_t *bucket = w->bucket, *by_degree = w->by_degree, *minimal = w->minimal;
    uint8_t *dropped = w->dropped;
    memset(bucket, 0, (high - low + 2) * sizeof(int64_t));
    for (int64_t c = 0; c < np; c++)
        bucket[w->pdeg[c] - low + 1]++;
    for (int64_t d = 1; d <= high - low + 1; d++)
        bucket[d] += bucket[d - 1];
    for (int64_t c = 0; c < np; c++) /* stable: by degree, then by partner */
        by_degree[bucket[w->pdeg[c] - low]++] = (w->pdeg[c] << 32) | c;
    int64_t nmin = 0, kept = 0;
    for (int64_t s = 0; s < np;) {
        int64_t e = s; /* by_degree[s .. e): one lcm degree */
        while (e < np && by_degree[e] >> 32 == by_degree[s] >> 32)
            e++;
        for (int64_t i = s; i < e; i++) {
            int64_t c = by_degree[i] & 0xFFFFFFFF;
            dropped[c] = 0;
            for (int64_t j = 0; j < nmin && !dropped[c]; j++)
                dropped[c] = !(w->lmask[minimal[j]] & ~w->lmask[c]) && divides(w->L + minimal[j] * n, w->L + c * n, n);
        }
        for (int64_t i = s; i < e; i++) { /* F among the partners of this degree that M kept */
            int64_t c = by_degree[i] & 0xFFFFFFFF;
            if (dropped[c] == 1 || dropped[c] == 2)
                continue;
            int64_t has_coprime = w->coprime[c];
            for (int64_t i2 = i + 1; i2 < e; i2++) {
                int64_t c2 = by_degree[i2] & 0xFFFFFFFF;
                if (dropped[c2] || w->lmask[c2] != w->lmask[c] ||
                    memcmp(w->L + c2 * n, w->L + c * n, n * sizeof(int32_t)))
                    continue;
                dropped[c2] = 2; /* same lcm: c (the first, by index) speaks for it */
                has_coprime |= w->coprime[c2];
            }
            minimal[nmin++] = c;
            dropped[c] = has_coprime ? 3 : 0;
        }
        s = e;
    }
    for (int64_t c = 0; c < np; c++)
        kept += !dropped[c];
    if (!kept)
        return 0;
    *out = malloc(kept * 4 * sizeof(int64_t));
    *out_lcm = malloc(kept * n * sizeof(int32_t) + 4);
    if (!*out || !*out_lcm)
        return -1;
    for (int64_t c = 0, q = 0; c < np; c++) {
        if (dropped[c])
            continue;
        (*out)[4 * q] = w->partners[c];
        (*out)[4 * q + 1] = h;
        (*out)[4 * q + 2] = w->pdeg[c];
        (*out)[4 * q + 3] = t;
        memcpy(*out_lcm + q * n, w->L + c * n, n * sizeof(int32_t));
        q++;
    }
    *count = kept;
    return 0;
}

/* Whether a later h_u (born < u < m) drops the pair (i, j) of lcm degree d and lcm exponents l (mask lm) by
 * criterion B: lm(h_u) divides the lcm and lcm(g, h_u) differs from it for both g = i and g = j. */
static int dropped_by_b(int64_t born, int64_t k, int64_t m, int64_t n, const int32_t *E, const uint64_t *emask,
                        int64_t i, int64_t j, int64_t d, const int32_t *l, uint64_t lm)
{
    for (int64_t u = born + 1; u < m; u++) {
        const int32_t *eh = E + (k + u) * n;
        if ((emask[k + u] & ~lm) || !divides(eh, l, n))
            continue;
        if (lcm_degree(E + i * n, eh, n) != d && lcm_degree(E + j * n, eh, n) != d)
            return 1;
    }
    return 0;
}

int f4_update(int64_t nvars, const int32_t *E, const int64_t *deg, uint8_t *active, int64_t k, int64_t m,
              int64_t npairs, const int64_t *pairs, const int32_t *lcm, uint8_t *keep, int64_t *result, int threads)
{
    int64_t n = nvars, total = k + m, count = 0;
    int64_t *born = malloc((total + 1) * sizeof(int64_t)), *dies = malloc((total + 1) * sizeof(int64_t));
    uint64_t *emask = malloc((total + 1) * sizeof(uint64_t));
    int64_t **lists = calloc(m + 1, sizeof(int64_t *)), *counts = calloc(m + 1, sizeof(int64_t));
    int32_t **list_lcms = calloc(m + 1, sizeof(int32_t *));
    int64_t *out = NULL;
    int32_t *out_lcm = NULL;
    divmask_t dm = {0};
    int status = -1, oom = 0;
    if (threads < 1 || ((double)m * total < UPDATE_PARALLEL_TESTS && !f4_share_small))
        threads = 1;
    if (!born || !dies || !emask || !lists || !counts || !list_lcms || divmask_init(&dm, E, total, n))
        goto done;
    for (int64_t g = 0; g < total; g++) {
        emask[g] = divmask(&dm, E + g * n, n);
        born[g] = g < k ? (active[g] ? -1 : m) : g - k; /* an inactive old element is never a partner */
    }
    /* (1) activity spans; (2) the new pairs of each h_t; both shared out (t by t: dynamic, their costs grow) */
#pragma omp parallel num_threads(threads) if (threads > 1)
    {
        update_scratch_t w = {malloc((total + 1) * sizeof(int64_t)), malloc((total + 1) * sizeof(int64_t)),
                              malloc((total + 1) * sizeof(int64_t)), malloc((total + 1) * sizeof(int64_t)), NULL, 0,
                              malloc((total + 1) * n * sizeof(int32_t)), malloc(total + 1), malloc(total + 1),
                              malloc((total + 1) * sizeof(uint64_t))};
        if (!w.partners || !w.pdeg || !w.by_degree || !w.minimal || !w.L || !w.coprime || !w.dropped || !w.lmask)
            __atomic_store_n(&oom, 1, __ATOMIC_RELAXED);
#pragma omp for schedule(static)
        for (int64_t g = 0; g < total; g++) {
            dies[g] = m;
            for (int64_t u = born[g] + 1; u < m; u++) /* a new lead cannot divide an earlier, larger one */
                if (!(emask[k + u] & ~emask[g]) && divides(E + (k + u) * n, E + g * n, n)) {
                    dies[g] = u;
                    break;
                }
        }
#pragma omp for schedule(dynamic, 1)
        for (int64_t t = 0; t < m; t++)
            if (!__atomic_load_n(&oom, __ATOMIC_RELAXED) &&
                new_pairs_of(t, k, n, E, deg, born, dies, emask, &w, &lists[t], &list_lcms[t], &counts[t]))
                __atomic_store_n(&oom, 1, __ATOMIC_RELAXED);
        free(w.partners);
        free(w.pdeg);
        free(w.by_degree);
        free(w.minimal);
        free(w.bucket);
        free(w.L);
        free(w.coprime);
        free(w.dropped);
        free(w.lmask);
    }
    if (oom)
        goto done;
    for (int64_t t = 0; t < m; t++)
        count += counts[t];
    out = malloc((count + 1) * 4 * sizeof(int64_t));
    out_lcm = malloc((count + 1) * n * sizeof(int32_t));
    if (!out || !out_lcm)
        goto done;
    for (int64_t t = 0, q = 0; t < m; q += counts[t], t++) {
        if (!counts[t])
            continue;
        memcpy(out + 4 * q, lists[t], counts[t] * 4 * sizeof(int64_t));
        memcpy(out_lcm + q * n, list_lcms[t], counts[t] * n * sizeof(int32_t));
    }
    /* (3) criterion B, pair by pair */
#pragma omp parallel for num_threads(threads) schedule(dynamic, 256) if (threads > 1)
    for (int64_t q = 0; q < npairs + count; q++) {
        if (q < npairs) {
            const int64_t *pq = pairs + 3 * q;
            keep[q] = !dropped_by_b(-1, k, m, n, E, emask, pq[0], pq[1], pq[2], lcm + q * n,
                                    divmask(&dm, lcm + q * n, n));
        } else {
            int64_t *pq = out + 4 * (q - npairs);
            const int32_t *l = out_lcm + (q - npairs) * n;
            if (dropped_by_b(pq[3], k, m, n, E, emask, pq[0], pq[1], pq[2], l, divmask(&dm, l, n)))
                pq[3] = -1;
        }
    }
    for (int64_t g = 0; g < total; g++)
        active[g] = born[g] < m && dies[g] == m;
    result[0] = (int64_t)(intptr_t)out;
    result[1] = (int64_t)(intptr_t)out_lcm;
    result[2] = count;
    out = NULL;
    out_lcm = NULL;
    status = 0;
done:
    if (lists)
        for (int64_t t = 0; t < m; t++) {
            free(lists[t]);
            free(list_lcms[t]);
        }
    free(lists);
    free(list_lcms);
    free(counts);
    free(born);
    free(dies);
    free(emask);
    free(dm.thr);
    free(out);
    free(out_lcm);
    return status;
}

/* For each of nmono monomials (exponent rows of nvars), the first of nlead leading monomials (in the order
 * given: the preferred reducers first) that divides it, or -1: best[i]. A support mask per monomial (bit
 * v % 64 for every variable v with a positive exponent) rejects most candidates with one test before the
 * exponents are compared. Returns 0, or -1 when memory ran out. */
int f4_reducers(int64_t nvars, const int32_t *lead, int64_t nlead, const int32_t *mono, int64_t nmono, int64_t *best)
{
    uint64_t *masks = malloc((nlead + 1) * sizeof(uint64_t));
    if (!masks)
        return -1;
    for (int64_t a = 0; a < nlead; a++)
        masks[a] = support_mask(lead + a * nvars, nvars);
    for (int64_t i = 0; i < nmono; i++) {
        const int32_t *x = mono + i * nvars;
        uint64_t mask = support_mask(x, nvars);
        best[i] = -1;
        for (int64_t a = 0; a < nlead; a++) {
            if (masks[a] & ~mask)
                continue;
            if (divides(lead + a * nvars, x, nvars)) {
                best[i] = a;
                break;
            }
        }
    }
    free(masks);
    return 0;
}

/* A hash table of distinct 64-bit codes (open addressing, linear probing): slot -> position in keys, -1. */
typedef struct {
    int64_t *slot;
    uint64_t mask;
    int bits;
} table_t;

static int table_init(table_t *t, int64_t capacity)
{
    t->bits = 4;
    while (((int64_t)1 << t->bits) < 2 * capacity)
        t->bits++;
    t->mask = ((uint64_t)1 << t->bits) - 1;
    t->slot = malloc(((size_t)1 << t->bits) * sizeof(int64_t));
    if (!t->slot)
        return -1;
    for (uint64_t h = 0; h <= t->mask; h++)
        t->slot[h] = -1;
    return 0;
}

static inline uint64_t table_home(const table_t *t, uint64_t key)
{
    return (key * 0x9E3779B97F4A7C15ULL) >> (64 - t->bits);
}

/* the slot of key in the table over keys: its position there, or the empty slot where it would go */
static inline uint64_t table_find(const table_t *t, const uint64_t *keys, uint64_t key)
{
    uint64_t h = table_home(t, key);
    while (t->slot[h] >= 0 && keys[t->slot[h]] != key)
        h = (h + 1) & t->mask;
    return h;
}

/* The codes of the terms of F4 rows that are not in known (distinct codes), each once: row r is
 * mult[r] times the basis element whose term codes are pool[starts[r] : starts[r] + lengths[r]], so its
 * codes are those plus mult[r]. The new codes, in order of first occurrence, go to a malloc'ed array
 * (address and count in result[0..1]; free with f4_free). Returns 0, or -1 when memory ran out. */
int f4_new_terms(const uint64_t *pool, const int64_t *starts, const int64_t *lengths, const uint64_t *mult,
                 int64_t nrows, const uint64_t *known, int64_t nknown, int64_t *result)
{
    table_t old = {0}, fresh = {0};
    int64_t cap = 1024, count = 0;
    uint64_t *out = malloc(cap * sizeof(uint64_t));
    int status = -1;
    if (!out || table_init(&old, nknown) || table_init(&fresh, cap))
        goto done;
    for (int64_t i = 0; i < nknown; i++)
        old.slot[table_find(&old, known, known[i])] = i;
    for (int64_t r = 0; r < nrows; r++) {
        const uint64_t *terms = pool + starts[r];
        for (int64_t t = 0; t < lengths[r]; t++) {
            uint64_t code = terms[t] + mult[r];
            if (nknown && old.slot[table_find(&old, known, code)] >= 0)
                continue;
            uint64_t h = table_find(&fresh, out, code);
            if (fresh.slot[h] >= 0)
                continue;
            if (2 * (count + 1) > (int64_t)fresh.mask + 1) { /* grow: rehash the codes found so far */
                table_t bigger;
                if (table_init(&bigger, 2 * (count + 1)))
                    goto done;
                for (int64_t i = 0; i < count; i++)
                    bigger.slot[table_find(&bigger, out, out[i])] = i;
                free(fresh.slot);
                fresh = bigger;
                h = table_find(&fresh, out, code);
            }
            if (count == cap) {
                cap *= 2;
                uint64_t *o = realloc(out, cap * sizeof(uint64_t));
                if (!o)
                    goto done;
                out = o;
            }
            out[count] = code;
            fresh.slot[h] = count++;
        }
    }
    result[0] = (int64_t)(intptr_t)out;
    result[1] = count;
    out = NULL;
    status = 0;
done:
    free(old.slot);
    free(fresh.slot);
    free(out);
    return status;
}

/* The column of every term of F4 rows (as in f4_new_terms) over the matrix columns (codes ascending; column
 * 0 is the largest code): out[e] = ncols - 1 - position of the code, entry by entry, the rows shared among
 * up to threads threads (row r's entries start at offset[r]). Every code must be a column. Returns 0, or
 * -1 when memory ran out. */
int f4_columns(const uint64_t *pool, const int64_t *starts, const int64_t *lengths, const uint64_t *mult,
               int64_t nrows, const uint64_t *columns, int64_t ncols, int32_t *out, int threads)
{
    table_t t;
    int64_t *offset = malloc((nrows + 1) * sizeof(int64_t));
    if (!offset || table_init(&t, ncols)) {
        free(offset);
        return -1;
    }
    for (int64_t i = 0; i < ncols; i++)
        t.slot[table_find(&t, columns, columns[i])] = i;
    offset[0] = 0;
    for (int64_t r = 0; r < nrows; r++)
        offset[r + 1] = offset[r] + lengths[r];
#pragma omp parallel for num_threads(threads) schedule(static) if (threads > 1 && (offset[nrows] > 100000 || f4_share_small))
    for (int64_t r = 0; r < nrows; r++) {
        const uint64_t *terms = pool + starts[r];
        for (int64_t k = 0; k < lengths[r]; k++)
            out[offset[r] + k] = (int32_t)(ncols - 1 - t.slot[table_find(&t, columns, terms[k] + mult[r])]);
    }
    free(offset);
    free(t.slot);
    return 0;
}

/* out[i] = the position of queries[i] in keys (distinct), or -1 when it is not there: a hash table of the
 * keys, one probe sequence per query (a binary search costs log2(nkeys) cache misses per query). Returns
 * 0, or -1 when memory ran out. */
int f4_index_of(const uint64_t *keys, int64_t nkeys, const uint64_t *queries, int64_t nq, int64_t *out)
{
    table_t t;
    if (table_init(&t, nkeys))
        return -1;
    for (int64_t i = 0; i < nkeys; i++)
        t.slot[table_find(&t, keys, keys[i])] = i;
    for (int64_t i = 0; i < nq; i++)
        out[i] = t.slot[table_find(&t, keys, queries[i])];
    free(t.slot);
    return 0;
}

/* A growing set of distinct codes: keys[0 .. n) and a hash table over them. */
typedef struct {
    table_t t;
    uint64_t *keys;
    int64_t n, cap;
} codeset_t;

static int set_init(codeset_t *s, int64_t cap)
{
    s->n = 0;
    s->cap = cap > 16 ? cap : 16;
    s->keys = malloc(s->cap * sizeof(uint64_t));
    if (!s->keys || table_init(&s->t, s->cap)) {
        free(s->keys);
        s->keys = NULL;
        return -1;
    }
    return 0;
}

static void set_free(codeset_t *s)
{
    free(s->keys);
    free(s->t.slot);
}

/* 1 if key was added, 0 if it was there, -1 when memory ran out */
static int set_add(codeset_t *s, uint64_t key)
{
    uint64_t h = table_find(&s->t, s->keys, key);
    if (s->t.slot[h] >= 0)
        return 0;
    if (s->n == s->cap) {
        s->cap *= 2;
        uint64_t *k = realloc(s->keys, s->cap * sizeof(uint64_t));
        if (!k)
            return -1;
        s->keys = k;
        table_t bigger;
        if (table_init(&bigger, s->cap))
            return -1;
        for (int64_t i = 0; i < s->n; i++)
            bigger.slot[table_find(&bigger, s->keys, s->keys[i])] = i;
        free(s->t.slot);
        s->t = bigger;
        h = table_find(&s->t, s->keys, key);
    }
    s->keys[s->n] = key;
    s->t.slot[h] = s->n++;
    return 1;
}

static int ascending_u64(const void *x, const void *y)
{
    uint64_t a = *(const uint64_t *)x, b = *(const uint64_t *)y;
    return (a > b) - (a < b);
}

static void set_clear(codeset_t *s)
{
    s->n = 0;
    memset(s->t.slot, 0xFF, ((size_t)s->t.mask + 1) * sizeof(int64_t)); /* every slot -1 */
}

/* Below this many terms in a wave's rows one thread walks them: a wave of 50,000 terms is about 0.15 ms of
 * work, against the tens of microseconds it takes to wake a sleeping thread (OMP_WAIT_POLICY=PASSIVE). */
#define PREPROCESS_PARALLEL_TERMS 50000

/* Symbolic preprocessing of analysis/engine/f4.py (_preprocess) for narrow codes of a graded order: the terms of
 * the rows mult[r] * g[index[r]] (element g's term codes pool[el_start[g] : el_start[g] + el_len[g]],
 * leading code lm[g]) are walked wave by wave; every code first seen (not a leading term of a given row when
 * leads_done) whose exponents some active leading monomial divides gets a reducer row, from the first of
 * the active elements act[0 .. nact) (exponents act_exps) that divides it; a wave's codes are taken in
 * ascending order. A code's exponents: its fields (code >> shift[f]) & field_mask times winv_t (nfields x
 * nvars). Results (free each array with f4_free): result[0..2] the reducers' multipliers, elements and
 * count, result[3..4] all codes seen (the matrix columns), ascending, and their count. Returns 0, or -1
 * when memory ran out.
 *
 * The work of a wave is shared among up to threads threads: each walks some of the rows and keeps, in a
 * set of its own, the codes that are not among those seen before the wave (read only while the threads
 * walk); one thread then adds these few codes to the codes seen, each once, and the reducer search over
 * the wave's new codes is shared out again. A wave's new codes are sorted, so the waves and reducers are
 * the same on any number of threads. */
int f4_preprocess(const uint64_t *pool, const int64_t *el_start, const int64_t *el_len, const uint64_t *lm,
                  const int64_t *act, int64_t nact, const int32_t *act_exps, int64_t nvars, int64_t nfields,
                  const uint64_t *shift, uint64_t field_mask, const int64_t *winv_t, const uint64_t *mult,
                  const int64_t *index, int64_t nrows, int leads_done, int threads, int64_t *result)
{
    enum { MAX_THREADS = 64 };
    int nlocal = threads < 1 ? 1 : threads > MAX_THREADS ? MAX_THREADS : threads, ready = 0;
    codeset_t seen = {0}, local[MAX_THREADS];
    int64_t fcap = 1024, nfront = 0, rcap = 1024, nred = 0;
    uint64_t *front = malloc(fcap * sizeof(uint64_t)), *red_mult = malloc(rcap * sizeof(uint64_t));
    int64_t *red_index = malloc(rcap * sizeof(int64_t)), *best = malloc(fcap * sizeof(int64_t));
    uint64_t *masks = malloc((nact + 1) * sizeof(uint64_t));
    int status = -1, oom = 0;
    for (; ready < nlocal && !set_init(&local[ready], 4096); ready++)
        ;
    if (ready < nlocal || !front || !red_mult || !red_index || !best || !masks || set_init(&seen, 4096))
        goto done;
    for (int64_t a = 0; a < nact; a++)
        masks[a] = support_mask(act_exps + a * nvars, nvars);
    if (leads_done)
        for (int64_t r = 0; r < nrows; r++)
            if (set_add(&seen, lm[index[r]] + mult[r]) < 0)
                goto done;
    int64_t from = 0; /* the rows whose terms are walked next: the given ones, then each wave's reducers */
    for (int wave = 0;; wave++) {
        const int64_t upto = wave ? nred : nrows;
        const int64_t *rows_index = wave ? red_index : index;
        const uint64_t *rows_mult = wave ? red_mult : mult;
        int64_t terms_walked = 0;
        for (int64_t r = from; r < upto; r++)
            terms_walked += el_len[rows_index[r]];
        int walkers = terms_walked < PREPROCESS_PARALLEL_TERMS && !f4_share_small ? 1 : nlocal;
#pragma omp parallel num_threads(walkers) if (walkers > 1)
        {
#if defined(_OPENMP)
            codeset_t *mine = &local[omp_get_thread_num()];
#else
            codeset_t *mine = &local[0];
#endif
            set_clear(mine);
#pragma omp for schedule(dynamic, 64)
            for (int64_t r = from; r < upto; r++) {
                int64_t g = rows_index[r];
                uint64_t m = rows_mult[r];
                const uint64_t *terms = pool + el_start[g];
                for (int64_t t = 0; t < el_len[g] && !__atomic_load_n(&oom, __ATOMIC_RELAXED); t++) {
                    uint64_t code = terms[t] + m;
                    if (seen.t.slot[table_find(&seen.t, seen.keys, code)] >= 0) /* seen before the wave */
                        continue;
                    if (set_add(mine, code) < 0)
                        __atomic_store_n(&oom, 1, __ATOMIC_RELAXED);
                }
            }
        }
        if (oom)
            goto done;
        nfront = 0;
        for (int j = 0; j < walkers; j++) /* the wave's new codes into the codes seen, each once */
            for (int64_t i = 0; i < local[j].n; i++) {
                int added = set_add(&seen, local[j].keys[i]);
                if (added < 0)
                    goto done;
                if (!added)
                    continue;
                if (nfront == fcap) {
                    fcap *= 2;
                    uint64_t *f = realloc(front, fcap * sizeof(uint64_t));
                    if (f)
                        front = f;
                    int64_t *b = f ? realloc(best, fcap * sizeof(int64_t)) : NULL;
                    if (!b)
                        goto done;
                    best = b;
                }
                front[nfront++] = local[j].keys[i];
            }
        if (!nfront || !nact)
            break;
        qsort(front, nfront, sizeof(uint64_t), ascending_u64);
        /* the first active element dividing each new code, shared out among the threads */
#pragma omp parallel num_threads(nlocal) if (nlocal > 1 && (nfront * nact > 1000000 || f4_share_small))
        {
            int32_t *x = malloc((nvars + 1) * sizeof(int32_t));
            if (!x)
                __atomic_store_n(&oom, 1, __ATOMIC_RELAXED);
#pragma omp for schedule(dynamic, 64)
            for (int64_t i = 0; i < nfront; i++) {
                if (!x)
                    continue;
                uint64_t code = front[i];
                for (int64_t v = 0; v < nvars; v++)
                    x[v] = 0;
                for (int64_t f = 0; f < nfields; f++) {
                    int64_t value = (int64_t)((code >> shift[f]) & field_mask);
                    if (value)
                        for (int64_t v = 0; v < nvars; v++)
                            x[v] += (int32_t)(value * winv_t[f * nvars + v]);
                }
                uint64_t mask = support_mask(x, nvars);
                best[i] = -1;
                for (int64_t a = 0; a < nact; a++)
                    if (!(masks[a] & ~mask) && divides(act_exps + a * nvars, x, nvars)) {
                        best[i] = a;
                        break;
                    }
            }
            free(x);
        }
        if (oom)
            goto done;
        int64_t wave_start = nred;
        for (int64_t i = 0; i < nfront; i++) {
            if (best[i] < 0)
                continue;
            if (nred == rcap) {
                rcap *= 2;
                uint64_t *rm = realloc(red_mult, rcap * sizeof(uint64_t));
                if (!rm)
                    goto done;
                red_mult = rm;
                int64_t *ri = realloc(red_index, rcap * sizeof(int64_t));
                if (!ri)
                    goto done;
                red_index = ri;
            }
            red_mult[nred] = front[i] - lm[act[best[i]]];
            red_index[nred++] = act[best[i]];
        }
        if (nred == wave_start)
            break;
        from = wave_start;
    }
    qsort(seen.keys, seen.n, sizeof(uint64_t), ascending_u64);
    result[0] = (int64_t)(intptr_t)red_mult;
    result[1] = (int64_t)(intptr_t)red_index;
    result[2] = nred;
    result[3] = (int64_t)(intptr_t)seen.keys;
    result[4] = seen.n;
    red_mult = NULL;
    red_index = NULL;
    seen.keys = NULL;
    status = 0;
done:
    for (int j = 0; j < ready; j++)
        set_free(&local[j]);
    set_free(&seen);
    free(front);
    free(best);
    free(red_mult);
    free(red_index);
    free(masks);
    return status;
}
