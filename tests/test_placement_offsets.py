"""Placement of transmitters whose offsets are hundreds of metres (arrival times from audio: seconds x c)."""
import numpy as np
import pytest

from solvers.calibration.placement import _multilaterate


@pytest.mark.parametrize("dim", [2, 3])
def test_transmitters_with_large_offsets_are_placed(dim):
    rng = np.random.default_rng(11)
    size = np.array([8.0, 6.0, 3.0])[:dim]
    R = rng.uniform(0.5, size - 0.5, (12, dim))
    S = rng.uniform(0.5, size - 0.5, (40, dim))
    O = rng.uniform(0.0, 1000.0, 40)  # up to 3 s of unknown emission time
    G = (np.linalg.norm(S[:, None] - R[None], axis=2) + O[:, None]) + 0.002 * rng.standard_normal((40, 12))
    G[rng.random(G.shape) < 0.2] = np.nan  # missing entries
    X = _multilaterate(G, R, True, np.full((40, dim + 1), np.nan), 0.006, rng)
    # before the offset was referred to a measured entry, 3D lost most of these (singular minimal subsets)
    assert np.isfinite(X).all()
    np.testing.assert_allclose(X[:, :dim], S, atol=0.05)
    np.testing.assert_allclose(X[:, dim], O, atol=0.05)
