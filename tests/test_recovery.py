"""Tests for solvers.recovery: true roots give the network back; bad candidates give None."""

import numpy as np
import pytest

from solvers.metrics import offset_error, position_error
from solvers.recovery import rank_candidates, recover, to_gauge
from solvers.synthetic import Network, random_network, true_root

SHAPES = [(9, 3), (6, 4), (7, 5)]
SEEDS = [0, 1, 2, 3, 4]


def _instance(m, n, seed):
    net = random_network(m, n, np.random.default_rng(seed))
    return net, net.measurements()


@pytest.mark.parametrize("m,n", SHAPES)
@pytest.mark.parametrize("seed", SEEDS)
def test_true_root_reproduces_network(m, n, seed):
    net, F = _instance(m, n, seed)
    cal = recover(F, *true_root(net))
    assert cal is not None, f"seed={seed}"
    assert position_error(cal, net) < 1e-10, f"seed={seed}"
    assert offset_error(cal, net) < 1e-14, f"seed={seed}"
    assert cal.residual < 1e-9, f"seed={seed}"
    # paper gauge: r_1 = 0, r_2 on the positive x-axis
    np.testing.assert_array_equal(cal.receivers[0], [0.0, 0.0])
    assert cal.receivers[1, 1] == 0.0 and cal.receivers[1, 0] > 0.0
    assert cal.receivers.shape == (m, 2) and cal.transmitters.shape == (n, 2)


def test_h_as_vector_and_tiny_imaginary_parts_are_accepted():
    net, F = _instance(6, 4, 8)
    H, b, o = true_root(net)
    h = np.array([H[0, 0], H[0, 1], H[1, 1]])
    cal = recover(F, h + 1e-14j * np.abs(h), b + 1e-15j, o.astype(complex))
    assert cal is not None
    assert position_error(cal, net) < 1e-10


def test_complex_candidate_is_rejected():
    net, F = _instance(9, 3, 0)
    H, b, o = true_root(net)
    assert recover(F, H, b + 0.3j, o) is None
    assert recover(F, H * (1 + 0.1j), b, o) is None
    o_complex = o.astype(complex)
    o_complex[1] += 0.5j
    assert recover(F, H, b, o_complex) is None


def test_non_positive_definite_candidate_is_rejected():
    net, F = _instance(6, 4, 1)
    H, b, o = true_root(net)
    assert recover(F, -H, b, o) is None
    indefinite = H.copy()
    indefinite[0, 1] = indefinite[1, 0] = 2 * np.sqrt(H[0, 0] * H[1, 1])
    assert recover(F, indefinite, b, o) is None
    assert recover(F, np.zeros((2, 2)), b, o) is None
    assert recover(F, np.full((2, 2), np.nan), b, o) is None


def test_degenerate_networks_give_none():
    rng = np.random.default_rng(4)
    transmitters = 10 * rng.standard_normal((4, 2))
    offsets = rng.standard_normal(4)
    collinear = Network(np.column_stack([np.linspace(-10, 10, 6), 0.5 * np.linspace(-10, 10, 6) + 1]),
                        transmitters, offsets)
    assert recover(collinear.measurements(), *true_root(collinear)) is None
    collinear3 = Network(collinear.receivers, transmitters[:3], offsets[:3])
    assert recover(collinear3.measurements(), *true_root(collinear3)) is None

    receivers = 10 * rng.standard_normal((6, 2))
    receivers[1] = receivers[0]  # r_2 = r_1: gauge rotation undefined
    coincident = Network(receivers, transmitters, offsets)
    assert recover(coincident.measurements(), *true_root(coincident)) is None

    net, F = _instance(6, 4, 2)
    F_bad = F.copy()
    F_bad[2, 1] = np.nan
    assert recover(F_bad, *true_root(net)) is None


def test_shape_errors_raise_value_error():
    net, F = _instance(6, 4, 0)
    H, b, o = true_root(net)
    with pytest.raises(ValueError):
        recover(F, H, b, o[:3])
    with pytest.raises(ValueError):
        recover(F[:, :2], H, b, o[:2])


def test_noisy_data_gives_residual_of_noise_level():
    net = random_network(9, 3, np.random.default_rng(6))
    F = net.measurements(1e-3, np.random.default_rng(60))
    cal = recover(F, *true_root(net))
    assert cal is not None
    assert cal.residual < 1e-2
    assert position_error(cal, net) < 1e-2


def test_rank_candidates_sorts_and_filters():
    net, F = _instance(7, 5, 3)
    H, b, o = true_root(net)
    rng = np.random.default_rng(30)
    roots = [
        (H * (1 + 0.05 * rng.standard_normal((2, 2))), b, o),
        (H, b + 0.2j, o),  # complex
        (-H, b, o),  # not positive-definite
        (H, b, o),
        (H, b, o + 0.1),
    ]
    ranked = rank_candidates(F, roots)
    assert len(ranked) == 3
    residuals = [c.residual for c in ranked]
    assert residuals == sorted(residuals)
    assert position_error(ranked[0], net) < 1e-10
    assert rank_candidates(F, [(H, b + 0.2j, o), (-H, b, o)]) == []
    assert rank_candidates(F, []) == []


def test_to_gauge():
    rng = np.random.default_rng(9)
    receivers, transmitters = rng.standard_normal((4, 2)), rng.standard_normal((3, 2))
    rec, tra = to_gauge(receivers, transmitters)
    np.testing.assert_array_equal(rec[0], [0.0, 0.0])
    assert rec[1, 1] == 0.0 and rec[1, 0] == pytest.approx(np.linalg.norm(receivers[1] - receivers[0]))
    # distances preserved, no reflection (orientation of a triangle kept)
    d = np.linalg.norm(receivers[:, None] - transmitters[None], axis=2)
    np.testing.assert_allclose(np.linalg.norm(rec[:, None] - tra[None], axis=2), d, rtol=1e-12)
    def orientation(p):
        u, v = p[1] - p[0], p[2] - p[0]
        return np.sign(u[0] * v[1] - u[1] * v[0])

    assert orientation(rec) == orientation(receivers)
    receivers[1] = receivers[0]
    assert to_gauge(receivers, transmitters) is None
