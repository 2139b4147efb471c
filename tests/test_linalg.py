"""The mod-p linear algebra backends agree with the pure-Python reference on F4-shaped matrices."""
import os

import numpy as np
import pytest

from analysis.engine.linalg import SparseRows, _rref, _rref_dicts, get_backend, matmul_mod


def _random_f4_matrix(rng, p, ncols, npivots, nrows, density=0.3, rank=None):
    """Pivot rows (leading 1 at distinct columns) and rows to reduce, as sparse (cols, vals) lists: random
    combinations of rank (default nrows // 2) random sparse rows."""
    pcols = np.sort(rng.choice(ncols, size=npivots, replace=False))
    pivots = {}
    for c in pcols:
        tail = np.flatnonzero(rng.random(ncols - c - 1) < density) + c + 1
        vals = rng.integers(1, p, len(tail))
        pivots[int(c)] = ([int(c)] + tail.tolist(), [1] + vals.tolist())
    # rows to reduce: low-rank combinations of random sparse rows, so that zero reductions occur
    rank = max(1, nrows // 2) if rank is None else rank
    base = rng.integers(0, p, (rank, ncols)) * (rng.random((rank, ncols)) < density)
    mix = rng.integers(0, p, (nrows, len(base)))
    dense = matmul_mod(mix, base.astype(np.int64), p)
    rows = []
    for r in dense:
        nz = np.flatnonzero(r)
        if len(nz):
            rows.append((nz.tolist(), r[nz].tolist()))
    return pivots, rows


def use_kernel(monkeypatch, kernel: str) -> None:
    """Make the sparse backend run the C kernel (analysis.engine.native) or the numba one ("none": as it is)."""
    from analysis.engine import native

    if kernel == "none":
        return
    if kernel == "numba":
        monkeypatch.setattr(native, "_LOADED", [None])
    elif native.kernel() is None:
        pytest.skip("no C compiler here: the C kernel cannot be built")


@pytest.fixture(params=["C", "numba"])
def sparse_kernel(request, monkeypatch):
    use_kernel(monkeypatch, request.param)
    return request.param


def _pooled(block: SparseRows, rng) -> SparseRows:
    """The same rows with their values read through offsets from a pool (rows in shuffled order, gaps
    between them), as F4 hands them to the kernels."""
    order = rng.permutation(len(block))
    pool, offsets, at = [], np.zeros(len(block), dtype=np.int64), 0
    for i in order:
        gap = int(rng.integers(0, 3))
        pool.append(np.zeros(gap, dtype=np.int64))
        offsets[i] = at + gap
        pool.append(block.vals[block.indptr[i] : block.indptr[i + 1]])
        at += gap + block.lengths[i]
    pool = np.concatenate(pool) if pool else np.zeros(0, dtype=np.int64)
    pooled = SparseRows(block.indptr, block.cols, pool.astype(np.int32), offsets)
    assert pooled.compact().to_rows() == block.to_rows()
    return pooled


@pytest.mark.parametrize("name, kernel", [("numpy", "none"), ("sparse", "C"), ("sparse", "numba")])
@pytest.mark.parametrize("p", [7, 65521, 2147483647])
@pytest.mark.parametrize("seed", range(4))
def test_fast_backends_match_reference(name, kernel, p, seed, monkeypatch):
    use_kernel(monkeypatch, kernel)
    rng = np.random.default_rng(seed)
    ncols = 120
    pivots, rows = _random_f4_matrix(rng, p, ncols, npivots=60, nrows=50)
    ref = get_backend("python")
    fast = get_backend(name)
    assert fast.reduce(pivots, rows, ncols, p) == ref.reduce(pivots, rows, ncols, p)
    assert fast.reduce_each(pivots, rows, ncols, p) == ref.reduce_each(pivots, rows, ncols, p)


@pytest.mark.parametrize("p", [7, 65521, 2147483647])
@pytest.mark.parametrize("seed", range(3))
def test_sparse_interface_matches_row_lists(p, seed, sparse_kernel):
    rng = np.random.default_rng(seed)
    ncols = 400
    pivots, rows = _random_f4_matrix(rng, p, ncols, npivots=300, nrows=120, density=0.1)
    pivot_rows = SparseRows.from_rows([pivots[c] for c in rng.permutation(sorted(pivots))])  # any order
    sparse_rows = SparseRows.from_rows(rows)
    assert sparse_rows.to_rows() == rows
    assert SparseRows.from_dense(sparse_rows.to_dense(ncols)).to_rows() == rows
    assert sparse_rows.take([2, 0]).to_rows() == [rows[2], rows[0]]
    for name in ("python", "numpy", "sparse"):
        backend = get_backend(name)
        reduced = backend.reduce_sparse(pivot_rows, sparse_rows, ncols, p).to_rows()
        assert reduced == backend.reduce(pivots, rows, ncols, p)
        each = backend.reduce_each_sparse(pivot_rows, sparse_rows, ncols, p).to_rows()
        assert each == backend.reduce_each(pivots, rows, ncols, p)
        pooled_pivots, pooled_rows = _pooled(pivot_rows, rng), _pooled(sparse_rows, rng)
        assert backend.reduce_sparse(pooled_pivots, pooled_rows, ncols, p).to_rows() == reduced
        assert backend.reduce_each_sparse(pooled_pivots, pooled_rows, ncols, p).to_rows() == each


@pytest.mark.parametrize("p", [7, 65521, 2147483647])
@pytest.mark.parametrize("seed", range(3))
def test_c_kernel_matches_numba_kernel(p, seed):
    """The C twin of the numba kernel returns the same arrays, in echelon and in "each" mode, also with
    empty blocks (no pivots, no rows)."""
    from analysis.engine import native
    from analysis.engine.sparse_kernels import sparse_echelon

    if native.kernel() is None:
        pytest.skip("no C compiler here: the C kernel cannot be built")
    rng = np.random.default_rng(seed)
    ncols = 300
    pivots, rows = _random_f4_matrix(rng, p, ncols, npivots=150, nrows=100, density=0.05)
    pivot_rows = SparseRows.from_rows([pivots[c] for c in rng.permutation(sorted(pivots))])
    blocks = [pivot_rows, SparseRows.from_rows(rows), SparseRows.from_rows([])]

    def arrays(block):
        return block.indptr.astype(np.int64), block.cols.astype(np.int32), block.vals.astype(np.int32)

    def pooled_arrays(block):  # the C kernel reads the values through offsets into a shared pool
        pooled = _pooled(block, rng)
        return (*arrays(pooled), pooled.offsets)

    for piv, red in ((0, 1), (2, 1), (0, 2), (2, 2)):
        for echelon in (True, False):
            theirs = sparse_echelon(*arrays(blocks[piv]), *arrays(blocks[red]), ncols, p, echelon)
            ours = native.sparse_echelon(*pooled_arrays(blocks[piv]), *pooled_arrays(blocks[red]), ncols, p, echelon)
            assert len(ours[0]) == len(theirs[0]) and (echelon or len(ours[0]) == len(blocks[red]) + 1)
            for a, b in zip(ours, theirs):
                assert np.array_equal(a, b)


@pytest.mark.parametrize("p", [7, 65521, 2147483647])
def test_blocked_rref_matches_reference(p):
    rng = np.random.default_rng(p % 97)
    for r, c, rank in [(60, 500, 60), (120, 400, 30), (80, 90, 80), (0, 10, 0)]:
        a = rng.integers(0, p, (r, rank))
        b = rng.integers(0, p, (rank, c)) * (rng.random((rank, c)) < 0.5)
        m = matmul_mod(a, b.astype(np.int64), p)
        ref = np.zeros((0, c), dtype=np.int64)
        rows = _rref_dicts([{j: int(v) for j, v in enumerate(row) if v} for row in m], p)
        if rows:
            ref = np.array([[row.get(j, 0) for j in range(c)] for row in rows], dtype=np.int64)
        for chunk in (1, 7, 16, 200):
            x = _rref(m, p, chunk)
            assert x.shape == ref.shape and (x == ref).all(), f"p={p} shape={m.shape} chunk={chunk}"


@pytest.mark.parametrize("p", [65521, 2147483647])
def test_numpy_backend_in_row_chunks_matches_reference(p, monkeypatch):
    """Many rows are reduced a chunk at a time against shared block inverses: same rows."""
    import analysis.engine.linalg as linalg

    rng = np.random.default_rng(5)
    ncols = 200
    pivots, rows = _random_f4_matrix(rng, p, ncols, npivots=130, nrows=90, density=0.1)
    expected = get_backend("python").reduce(pivots, rows, ncols, p), get_backend("python").reduce_each(pivots, rows, ncols, p)
    monkeypatch.setattr(linalg, "_ROW_CHUNK_CELLS", 7 * ncols)  # chunks of 7 rows
    fast = get_backend("numpy")
    assert (fast.reduce(pivots, rows, ncols, p), fast.reduce_each(pivots, rows, ncols, p)) == expected


@pytest.mark.parametrize("seed", range(3))
def test_index_of_matches_searchsorted(seed, monkeypatch):
    """The hashed lookup of monomial codes gives the positions np.searchsorted finds, -1 for absent codes,
    by the C table and by the numpy fallback alike."""
    from analysis.engine import native

    rng = np.random.default_rng(seed)
    keys = np.unique(rng.integers(0, 2**63, 5000, dtype=np.uint64))
    queries = np.concatenate([rng.choice(keys, 3000), rng.integers(0, 2**63, 500, dtype=np.uint64)])
    expected = np.searchsorted(keys, queries)
    expected[(expected == len(keys)) | (keys[np.minimum(expected, len(keys) - 1)] != queries)] = -1
    assert (expected >= 0).sum() >= 3000
    for kernel in ("C", "numba"):
        use_kernel(monkeypatch, kernel)
        assert np.array_equal(native.index_of(keys, queries), expected)
        assert np.array_equal(native.index_of(keys[:0], queries), np.full(len(queries), -1))


def test_c_kernels_build_where_a_compiler_is_found():
    """Where a C compiler is on PATH, the C kernels must build and load (else every C test above would skip
    and F4 would silently fall back to numba and numpy)."""
    import shutil

    from analysis.engine import native

    if not (shutil.which("cc") or shutil.which("gcc")):
        pytest.skip("no C compiler on PATH")
    if os.environ.get(native.DISABLE_ENV):
        pytest.skip(f"{native.DISABLE_ENV} is set")
    lib = native.kernel()
    assert lib is not None, "a C compiler is on PATH but analysis/engine/f4_kernels.c did not build"
    assert all(hasattr(lib, f) for f in ("f4_sparse_echelon", "f4_update", "f4_reducers", "f4_new_terms",
                                         "f4_columns", "f4_index_of", "f4_free"))


def test_native_describe_names_why_the_c_kernels_are_not_used(monkeypatch, tmp_path):
    """A source that does not compile: the engine falls back, and -v's line says which kernels run and why."""
    from analysis.engine import native

    broken = tmp_path / "broken.c"
    broken.write_text("int f( {\n")
    monkeypatch.setattr(native, "SOURCE", broken)
    monkeypatch.setattr(native, "_LOADED", [])
    monkeypatch.setattr(native, "_WHY", [])
    monkeypatch.setattr(native, "_cache_dirs", lambda: [tmp_path / "cache"])
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    monkeypatch.delenv(native.DISABLE_ENV, raising=False)
    assert native.kernel() is None
    line = native.describe()
    assert line.startswith("numba/numpy kernels (") and "no-such-compiler" in line and "broken.c" in line


@pytest.mark.parametrize("p", [7, 65521, 1073741827, 2147483647])
@pytest.mark.parametrize("threads", [1, 2, 3])
@pytest.mark.parametrize("rank", [80, 140])
def test_c_kernel_on_threads_matches_reference(p, threads, rank):
    """The C kernel on 1-3 threads returns the reference backend's rows, in echelon and in "each" mode, at
    small primes (delayed accumulators) and 30/31-bit ones (accumulators bounded by p**2): many blocks of
    rows with the same leads make the threads race for the same new pivots (run five times, for several
    interleavings); of rank 140, nearly every row is a new pivot, so a row lost in a race shows."""
    from analysis.engine import native

    if native.kernel() is None:
        pytest.skip("no C compiler here: the C kernel cannot be built")
    rng = np.random.default_rng(p % 1000 + threads)
    ncols = 240
    pivots, rows = _random_f4_matrix(rng, p, ncols, npivots=90, nrows=160, density=0.08, rank=rank)
    pivot_rows = SparseRows.from_rows([pivots[c] for c in rng.permutation(sorted(pivots))])
    sparse_rows = SparseRows.from_rows(rows)
    reference = get_backend("python")
    reduced = reference.reduce_sparse(pivot_rows, sparse_rows, ncols, p).to_rows()
    each = reference.reduce_each_sparse(pivot_rows, sparse_rows, ncols, p).to_rows()
    assert len(reduced) > 8 and any(c for c, _ in each)  # new pivots and nonzero remainders to race for
    sparse = get_backend("sparse")
    for _ in range(5):
        assert sparse.reduce_sparse(pivot_rows, sparse_rows, ncols, p, threads).to_rows() == reduced
        assert sparse.reduce_each_sparse(pivot_rows, sparse_rows, ncols, p, threads).to_rows() == each


def test_column_lookup_on_threads_matches_one_thread():
    """The C column lookup of F4 rows (term codes plus a multiplier) gives the same columns on 2 threads
    as on one, and as numpy's search, on a matrix large enough (> 100,000 entries) to be shared."""
    from analysis.engine import native

    if native.kernel() is None:
        pytest.skip("no C compiler here: the C kernel cannot be built")
    rng = np.random.default_rng(35)
    pool = np.sort(rng.choice(1 << 40, size=5000, replace=False)).astype(np.uint64)
    nrows = 3000
    starts = rng.integers(0, 4900, nrows)
    lengths = rng.integers(20, 100, nrows)
    mult = rng.choice([0, 1 << 41, 1 << 42], size=nrows).astype(np.uint64)
    codes = np.concatenate([pool[s : s + n] + m for s, n, m in zip(starts, lengths, mult)])
    assert len(codes) > 100_000
    columns = np.unique(codes)
    expected = (len(columns) - 1 - np.searchsorted(columns, codes)).astype(np.int32)
    for threads in (1, 2):
        assert np.array_equal(native.column_indices(pool, starts, lengths, mult, columns, threads), expected)
