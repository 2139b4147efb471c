"""The over-determined 4r/6s configuration: the 4r/5s solver on five transmitters, the sixth filtering."""
import numpy as np
import pytest

from analysis.positions import _root_from_network, _to_gauge, positions_system
from solvers.subsystem import FILTER_TOL, SubsystemSolver, extra_transmitter_residuals, receivers_from_orbits
from solvers.synthetic import random_network


def _gauge(net):
    return _to_gauge(np.asarray(net.receivers, float), np.asarray(net.transmitters, float))


def test_filter_keeps_true_receivers_and_rejects_others():
    rng = np.random.default_rng(3)
    net = random_network(4, 6, rng)
    rec, tra = _gauge(net)
    F = net.measurements()
    # receivers from the orbit invariants of the true root are the true ones up to reflections
    system = positions_system(4, 6, "receivers-orbits")
    root = np.array(_root_from_network(system, rec, tra, np.asarray(net.offsets, float)), dtype=float)
    R = receivers_from_orbits(root)
    assert np.allclose(np.abs(R.real), np.abs(rec), atol=1e-9) and np.allclose(R.imag, 0)
    assert extra_transmitter_residuals(R, F[:, 5]) < 1e-12
    moved = R.copy()
    moved[3] += 0.5
    assert extra_transmitter_residuals(moved, F[:, 5]) > 1e3 * FILTER_TOL
    # batched, complex candidates and a non-finite one
    batch = np.stack([R, moved, R * (1 + 1e-3j), np.full_like(R, np.nan)])
    res = extra_transmitter_residuals(batch, F[:, 5])
    assert res[0] < 1e-12 and res[1] > FILTER_TOL and res[2] > FILTER_TOL and np.isnan(res[3])


def test_4r6s_keeps_exactly_the_true_network():
    solver = SubsystemSolver("4r6s")
    assert solver.CONFIG == (4, 6) and solver.DEGREE == 1 and solver.PATHS == solver.base.PATHS == 344
    net = random_network(4, 6, np.random.default_rng(0))
    roots = solver.solve(net.measurements())
    kept = roots[np.all(np.isfinite(roots), axis=1)]
    assert len(kept) == 1
    rec, _ = _gauge(net)
    assert np.allclose(np.abs(receivers_from_orbits(kept[0]).real), np.abs(rec), rtol=1e-6, atol=1e-6)
    with pytest.raises(ValueError, match="needs"):
        solver.solve(net.measurements()[:, :5])


def test_unknown_subsystem_is_refused():
    with pytest.raises(ValueError, match="valid: 4r6s"):
        SubsystemSolver("4r7s")
