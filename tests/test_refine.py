"""Tests for solvers.refine: Jacobian against finite differences, convergence from good starts."""

import numpy as np
import pytest

from solvers.metrics import offset_error, position_error
from solvers.recovery import Calibration, recover, to_gauge
from solvers.refine import (
    RefineResult,
    jacobian,
    pack,
    parameter_count,
    random_initial,
    refine,
    residuals,
    unpack,
)
from solvers.synthetic import random_network, true_root

SHAPES = [(9, 3), (6, 4), (7, 5), (4, 5)]


def _gauged_truth(net):
    receivers, transmitters = to_gauge(net.receivers, net.transmitters)
    return pack(receivers, transmitters, net.offsets)


@pytest.mark.parametrize("m,n", SHAPES)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_jacobian_matches_central_differences(m, n, seed):
    rng = np.random.default_rng(seed)
    F = random_network(m, n, rng).measurements(0.5, rng)
    params = 10 * rng.standard_normal(parameter_count(m, n))
    J = jacobian(params, F)
    assert J.shape == (m * n, parameter_count(m, n))
    step = 1e-6
    J_fd = np.empty_like(J)
    for k in range(params.size):
        e = np.zeros_like(params)
        e[k] = step
        J_fd[:, k] = (residuals(params + e, F) - residuals(params - e, F)) / (2 * step)
    np.testing.assert_allclose(J, J_fd, rtol=1e-6, atol=1e-6 * np.max(np.abs(J)),
                               err_msg=f"seed={seed}")


def test_pack_unpack_round_trip_and_zero_residual_at_truth():
    net = random_network(6, 4, np.random.default_rng(3))
    params = _gauged_truth(net)
    assert params.size == 2 * 6 + 3 * 4 - 3
    receivers, transmitters, offsets = unpack(params, 6, 4)
    np.testing.assert_array_equal(pack(receivers, transmitters, offsets), params)
    np.testing.assert_allclose(residuals(params, net.measurements()), 0.0, atol=1e-12)


@pytest.mark.parametrize("m,n", SHAPES)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_refine_from_perturbed_truth_converges(m, n, seed):
    rng = np.random.default_rng(seed)
    net = random_network(m, n, rng)
    F = net.measurements()
    start = (
        net.receivers + 1e-2 * rng.standard_normal(net.receivers.shape),
        net.transmitters + 1e-2 * rng.standard_normal(net.transmitters.shape),
        net.offsets + 1e-2 * rng.standard_normal(net.n),
    )
    result = refine(start, F)
    assert isinstance(result, RefineResult)
    assert result.success, f"seed={seed}: {result.message}"
    cal = result.calibration
    assert position_error(cal, net) < 1e-9, f"seed={seed}"
    assert offset_error(cal, net) < 1e-9, f"seed={seed}"
    assert cal.residual < 1e-9
    assert result.initial_residual > cal.residual
    np.testing.assert_array_equal(cal.receivers[0], [0.0, 0.0])
    assert cal.receivers[1, 1] == 0.0


def test_refine_from_recovered_root_takes_few_iterations():
    net = random_network(9, 3, np.random.default_rng(12))
    F = net.measurements()
    cal = recover(F, *true_root(net))
    result = refine(cal, F)
    assert result.success
    assert result.iterations <= 3
    assert position_error(result.calibration, net) < 1e-12


def test_refine_reduces_residual_on_noisy_data():
    rng = np.random.default_rng(21)
    net = random_network(7, 5, rng)
    F = net.measurements(1e-2, rng)
    cal = recover(F, *true_root(net))
    result = refine(cal, F)
    assert result.calibration.residual <= cal.residual
    assert position_error(result.calibration, net) < 1e-2


@pytest.mark.parametrize("seed", range(6))
def test_refine_from_random_initialisation_descends_and_reports_how_it_stopped(seed):
    """LM from a random start (Table 4's "rand" rows): it lowers the residual, the residual it reports is the
    one of the parameters it returns, a stop by ftol (status 2) is a stationary point (J^T r = 0), and
    "not success" means the evaluation budget ran out."""
    rng = np.random.default_rng(seed)
    net = random_network(6, 4, rng)
    F = net.measurements()
    result = refine(random_initial(6, 4, rng), F, max_iter=200)
    cal = result.calibration
    assert isinstance(cal, Calibration)
    assert cal.receivers.shape == (6, 2) and cal.transmitters.shape == (4, 2)
    assert cal.residual < 0.2 * result.initial_residual, (seed, cal.residual, result.initial_residual)
    x = pack(cal.receivers, cal.transmitters, cal.offsets)
    r = residuals(x, F)
    assert cal.residual == pytest.approx(np.sqrt(np.mean(r**2)), rel=1e-12)
    if result.status == 2:
        assert np.linalg.norm(jacobian(x, F).T @ r) < 1e-5, seed
    assert result.success == (result.status > 0)
    if not result.success:
        assert result.nfev >= 200, (seed, result.nfev)


def test_refine_rejects_bad_input():
    net = random_network(6, 3, np.random.default_rng(0))
    F = net.measurements()
    start = (net.receivers, net.transmitters, net.offsets)
    with pytest.raises(ValueError, match="method"):
        refine(start, F, method="newton")
    with pytest.raises(ValueError):
        refine((net.receivers[:5], net.transmitters, net.offsets), F)
    with pytest.raises(TypeError):
        refine(42, F)
    small = random_network(4, 3, np.random.default_rng(0))  # 12 measurements < 14 parameters
    with pytest.raises(ValueError, match="lm"):
        refine((small.receivers, small.transmitters, small.offsets), small.measurements())
    result = refine((small.receivers, small.transmitters, small.offsets), small.measurements(),
                    method="trf")
    assert result.calibration.residual < 1e-9
