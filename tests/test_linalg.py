"""The mod-p linear algebra backends agree with the pure-Python reference on F4-shaped matrices."""
import numpy as np
import pytest

from analysis.linalg import _rref_flint, _rref_numpy, get_backend, matmul_mod


def _random_f4_matrix(rng, p, ncols, npivots, nrows, density=0.3):
    """Pivot rows (leading 1 at distinct columns) and rows to reduce, as sparse (cols, vals) lists."""
    pcols = np.sort(rng.choice(ncols, size=npivots, replace=False))
    pivots = {}
    for c in pcols:
        tail = np.flatnonzero(rng.random(ncols - c - 1) < density) + c + 1
        vals = rng.integers(1, p, len(tail))
        pivots[int(c)] = ([int(c)] + tail.tolist(), [1] + vals.tolist())
    # rows to reduce: low-rank combinations of random sparse rows, so that zero reductions occur
    base = rng.integers(0, p, (max(1, nrows // 2), ncols)) * (rng.random((max(1, nrows // 2), ncols)) < density)
    mix = rng.integers(0, p, (nrows, len(base)))
    dense = matmul_mod(mix, base.astype(np.int64), p)
    rows = []
    for r in dense:
        nz = np.flatnonzero(r)
        if len(nz):
            rows.append((nz.tolist(), r[nz].tolist()))
    return pivots, rows


@pytest.mark.parametrize("p", [7, 65521, 2147483647])
@pytest.mark.parametrize("seed", range(4))
def test_numpy_backend_matches_reference(p, seed):
    rng = np.random.default_rng(seed)
    ncols = 120
    pivots, rows = _random_f4_matrix(rng, p, ncols, npivots=60, nrows=50)
    ref = get_backend("python")
    fast = get_backend("numpy")
    assert fast.reduce(pivots, rows, ncols, p) == ref.reduce(pivots, rows, ncols, p)
    assert fast.reduce_each(pivots, rows, ncols, p) == ref.reduce_each(pivots, rows, ncols, p)


@pytest.mark.parametrize("p", [7, 65521, 2147483647])
def test_rref_paths_agree(p):
    rng = np.random.default_rng(p % 97)
    for r, c, rank in [(60, 500, 60), (120, 400, 30), (80, 90, 80)]:
        a = rng.integers(0, p, (r, rank))
        b = rng.integers(0, p, (rank, c)) * (rng.random((rank, c)) < 0.5)
        m = matmul_mod(a, b.astype(np.int64), p)
        x, y = _rref_numpy(m, p), _rref_flint(m, p)
        assert x.shape == y.shape and (x == y).all()
