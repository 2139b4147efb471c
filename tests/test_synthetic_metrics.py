"""Tests for solvers.synthetic (networks, true roots) and solvers.metrics (aligned errors)."""

import numpy as np
import pytest

from solvers.metrics import (
    align_rigid,
    calibration_errors,
    log10_error,
    offset_error,
    position_error,
)
from solvers.recovery import Calibration, compaction_matrix
from solvers.synthetic import DegenerateNetworkError, Network, random_network, true_root

SHAPES = [(9, 3), (6, 4), (7, 5)]
SEEDS = [0, 1, 2, 3, 4]


def _rotation(theta: float) -> np.ndarray:
    return np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])


def test_random_network_is_reproducible_and_shaped():
    a = random_network(6, 4, np.random.default_rng(7))
    b = random_network(6, 4, np.random.default_rng(7))
    assert a.receivers.shape == (6, 2) and a.transmitters.shape == (4, 2) and a.offsets.shape == (4,)
    assert (a.m, a.n) == (6, 4)
    np.testing.assert_array_equal(a.receivers, b.receivers)
    np.testing.assert_array_equal(a.offsets, b.offsets)
    with pytest.raises(ValueError):
        a.receivers[0, 0] = 1.0  # frozen arrays


def test_measurements_follow_the_tdoa_model():
    net = random_network(5, 3, np.random.default_rng(1))
    F = net.measurements()
    for i in range(net.m):
        for j in range(net.n):
            expected = np.linalg.norm(net.receivers[i] - net.transmitters[j]) + net.offsets[j]
            assert F[i, j] == pytest.approx(expected, rel=1e-14)
    noisy = net.measurements(0.1, np.random.default_rng(2))
    assert 0.0 < np.std(noisy - F) < 0.3
    with pytest.raises(ValueError, match="rng"):
        net.measurements(0.1)


def test_network_validates_shapes():
    with pytest.raises(ValueError):
        Network(np.zeros((3, 2)), np.zeros((3, 2)), np.zeros(2))
    with pytest.raises(ValueError):
        Network(np.zeros((3, 3)), np.zeros((3, 2)), np.zeros(3))


@pytest.mark.parametrize("m,n", SHAPES)
@pytest.mark.parametrize("seed", SEEDS)
def test_true_root_satisfies_the_toa_equations(m, n, seed):
    """Equations (A), (B), (C) of paper Sec. 2.1 hold with R~ = D~[:, :2]^T, S~ = I."""
    net = random_network(m, n, np.random.default_rng(seed))
    F = net.measurements()
    H, b, o = true_root(net)
    np.testing.assert_allclose(H, H.T)
    assert np.all(np.linalg.eigvalsh(H) > 0)
    np.testing.assert_array_equal(o, net.offsets)

    d2 = (F - o) ** 2
    R_tilde = compaction_matrix(F, o)[:, :2].T
    H_inv = np.linalg.inv(H)
    scale = np.max(d2)
    # (A) d_11^2 = b^T H^{-1} b
    assert b @ H_inv @ b == pytest.approx(d2[0, 0], abs=1e-10 * scale)
    # (B) d_1j^2 - d_11^2 = 1/4 e^T H^{-1} e - b^T H^{-1} e, j = 2, 3
    for k in range(2):
        e = np.eye(2)[k]
        lhs = d2[0, k + 1] - d2[0, 0]
        assert 0.25 * e @ H_inv @ e - b @ H_inv @ e == pytest.approx(lhs, abs=1e-10 * scale)
    # (C) d_i1^2 - d_11^2 = R~^T H R~ - 2 b^T R~, i = 2..m
    lhs = d2[1:, 0] - d2[0, 0]
    rhs = np.einsum("ki,kl,li->i", R_tilde, H, R_tilde) - 2 * b @ R_tilde
    np.testing.assert_allclose(rhs, lhs, atol=1e-10 * scale)


def test_true_root_is_translation_invariant_and_rejects_collinear_transmitters():
    net = random_network(6, 4, np.random.default_rng(3))
    shifted = Network(net.receivers + [5.0, -2.0], net.transmitters + [5.0, -2.0], net.offsets)
    for x, y in zip(true_root(net), true_root(shifted)):
        np.testing.assert_allclose(x, y, rtol=1e-10, atol=1e-14)
    collinear = Network(net.receivers, np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3, 1]]), net.offsets)
    with pytest.raises(DegenerateNetworkError):
        true_root(collinear)


@pytest.mark.parametrize("reflect", [False, True])
def test_align_rigid_recovers_known_transform(reflect):
    rng = np.random.default_rng(11)
    X_true = 10 * rng.standard_normal((12, 2))
    A = _rotation(0.7) @ (np.diag([1.0, -1.0]) if reflect else np.eye(2))
    t = np.array([3.0, -4.5])
    X_est = (X_true - t) @ A  # X_true = A X_est + t, rows
    transform = align_rigid(X_est, X_true)
    np.testing.assert_allclose(transform.matrix, A, atol=1e-12)
    np.testing.assert_allclose(transform.translation, t, atol=1e-12)
    np.testing.assert_allclose(transform.apply(X_est), X_true, atol=1e-12)
    assert np.linalg.det(transform.matrix) == pytest.approx(-1.0 if reflect else 1.0)


def test_position_and_offset_errors():
    net = random_network(6, 4, np.random.default_rng(5))
    A = _rotation(-1.3) @ np.diag([1.0, -1.0])
    moved = Calibration(net.receivers @ A.T + 7.0, net.transmitters @ A.T + 7.0, net.offsets.copy(), 0.0)
    assert position_error(moved, net) < 1e-14
    assert offset_error(moved, net) == 0.0

    X_true = np.vstack([net.receivers, net.transmitters])
    spread = np.linalg.norm(X_true - X_true.mean(axis=0))
    delta = np.zeros_like(net.receivers)
    delta[0, 0] = 1e-3 * spread  # a single small displacement barely changes the alignment
    perturbed = Calibration(net.receivers + delta, net.transmitters, 2 * net.offsets, 0.0)
    assert position_error(perturbed, net) == pytest.approx(1e-3, rel=0.2)
    assert offset_error(perturbed, net) == pytest.approx(1.0)
    errors = calibration_errors(perturbed, net)
    assert errors.offset == pytest.approx(1.0)


def test_log10_error():
    assert log10_error(1e-3) == pytest.approx(-3.0)
    assert np.isfinite(log10_error(0.0))
    np.testing.assert_allclose(log10_error(np.array([1.0, 100.0])), [0.0, 2.0])


def test_standardised_node_errors_in_3d_take_the_gauge_and_the_mirror_of_the_result():
    """A 3D result in the gauge of receivers (2, 0, 4), mirrored z -> -z, with known errors."""
    from types import SimpleNamespace

    from solvers.metrics import standardised_node_errors
    from solvers.recovery import to_gauge

    rng = np.random.default_rng(5)
    net = Network(rng.uniform(0, 5, (7, 3)), rng.uniform(0, 5, (4, 3)), rng.uniform(0, 1, 4))
    order = [2, 0, 4, 1, 3, 5, 6]
    R, S = to_gauge(net.receivers[order], net.transmitters)
    R_back = np.empty_like(R)
    R_back[order] = R
    shift = 0.01 * rng.standard_normal((11, 3))
    shift[[2, 0, 4]] = 0.0  # the gauge receivers are where the gauge puts them
    est = np.vstack([R_back, S]) * np.array([1.0, 1.0, -1.0]) + shift
    std = np.full(11, 0.02)
    std[[2, 0, 4]] = 0.0
    result = SimpleNamespace(gauge=(2, 0, 4), receivers=est[:7], transmitters=est[7:],
                             receiver_std=std[:7], transmitter_std=std[7:])
    z = standardised_node_errors(result, net)
    np.testing.assert_allclose(z, np.linalg.norm(np.delete(shift, [0, 2, 4], axis=0), axis=1) / 0.02, rtol=1e-9)
