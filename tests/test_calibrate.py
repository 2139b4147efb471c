"""Tests for solvers.api (solve_network, the paper's pipeline): input validation, noiseless calibration, degenerate networks, refinement."""
from __future__ import annotations

import numpy as np
import pytest

from solvers.api import select_solver, solve_network, solve_roots
from solvers.metrics import calibration_errors
from solvers.recovery import recover
from solvers.refine import refine
from solvers.synthetic import random_network, true_root


@pytest.mark.parametrize("bad,match", [
    (np.ones(12), "2-D"),
    (np.ones((6, 4, 1)), "2-D"),
    (np.ones((4, 4)), "too few"),
    (np.ones((5, 3)), "too few"),
    (np.ones((3, 6)), "too few"),
    (np.ones((12, 2)), "too few"),
    (np.full((6, 4), np.nan), "NaN"),
    (np.full((6, 4), np.inf), "NaN or infinite"),
    ([["a"] * 4] * 6, "real numbers"),
])
def test_bad_inputs_raise_clear_errors(bad, match):
    with pytest.raises(ValueError, match=match):
        solve_network(bad)


def test_dispatch():
    assert select_solver(6, 4).label == "6r4s"
    assert select_solver(12, 7).label == "6r4s"
    assert select_solver(9, 3).label == "9r3s"
    assert select_solver(15, 3).label == "9r3s"
    assert select_solver(8, 3).label == "8r3s"
    assert select_solver(7, 3).label == "7r3s"
    assert select_solver(6, 3).label == "6r3s"
    assert select_solver(5, 4).label == "5r4s"
    assert select_solver(5, 5).label == "5r5s"
    assert select_solver(5, 7).label == "5r5s"
    assert select_solver(4, 5).label == "4r5s"
    assert select_solver(4, 6).label == "4r5s"


@pytest.mark.parametrize("m,n,seed", [(8, 3, 21), (7, 3, 22), (5, 4, 23), (5, 6, 24), (4, 6, 25)])
def test_noiseless_calibration_of_the_new_cells(m, n, seed):
    net = random_network(m, n, np.random.default_rng(seed))
    best = solve_network(net.measurements())[0]
    err = calibration_errors(best, net)
    assert err.position < 1e-8 and err.offset < 1e-8, (m, n, seed, err)


@pytest.mark.parametrize("m,n", [(6, 3), (4, 5)])
def test_minimal_data_returns_every_exact_solution(m, n):
    import warnings

    net = random_network(m, n, np.random.default_rng(5))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cals = solve_network(net.measurements())
    assert cals and all(c.residual < 1e-8 * np.abs(net.measurements()).max() for c in cals)
    assert min(calibration_errors(c, net).position for c in cals) < 1e-8
    # several exact solutions come with a warning that the data cannot tell them apart
    assert (len(cals) > 1) == any("cannot tell them apart" in str(w.message) for w in caught)


@pytest.mark.parametrize("m,n,seed", [(6, 4, 11), (9, 3, 12), (8, 6, 13), (11, 3, 14)])
def test_noiseless_calibration(m, n, seed):
    net = random_network(m, n, np.random.default_rng(seed))
    cals = solve_network(net.measurements())
    assert cals, f"no calibration for {m}r{n}s seed {seed}"
    best = cals[0]
    assert best.m == m and best.n == n
    err = calibration_errors(best, net)
    assert err.position < 1e-8 and err.offset < 1e-8, (seed, err)
    assert [c.residual for c in cals] == sorted(c.residual for c in cals)


def test_collinear_receivers_give_no_false_exact_fit():
    """Receivers on a line are outside the solvers' generic family: whatever comes back must report
    its true residual (sorted, recomputed from the returned geometry), and a candidate claiming an
    exact fit must be the true network (up to the gauge)."""
    from solvers.recovery import rms_residual
    from solvers.synthetic import Network

    net = random_network(6, 4, np.random.default_rng(3))
    line = np.linspace(-10, 10, 6)
    receivers = np.column_stack([line, 2.0 * line + 1.0])
    truth = Network(receivers, net.transmitters, net.offsets)
    F = truth.measurements()
    out = solve_network(F)
    assert [c.residual for c in out] == sorted(c.residual for c in out)
    for c in out:
        assert c.residual == pytest.approx(rms_residual(F, c.receivers, c.transmitters, c.offsets), rel=1e-9, abs=1e-12)
        if c.residual < 1e-8:
            err = calibration_errors(c, truth)
            assert err.position < 1e-6 and err.offset < 1e-6, err


def test_coincident_nodes_give_no_calibration():
    """F of all ones (every receiver at the same distance of every transmitter) has no valid
    geometry: an empty list, not an exception and not a made-up network."""
    assert solve_network(np.ones((6, 4))) == []


def test_refinement_from_solver_output_converges():
    net = random_network(6, 4, np.random.default_rng(21))
    F = net.measurements()
    H, b, o = true_root(net)
    x = np.concatenate([[H[0, 0], H[0, 1], H[1, 1]], b, o])
    roots = solve_roots(F)
    best = roots[np.argmin(np.linalg.norm(roots - x, axis=1))]
    # perturb the solver's root (as noise would) and check LM brings it back
    start = recover(F, best[:3].real * 1.001, best[3:5].real, best[5:].real + 1e-3)
    assert start is not None
    result = refine(start, F)
    assert result.calibration.residual < 1e-9 < result.initial_residual
    assert calibration_errors(result.calibration, net).position < 1e-8


@pytest.mark.parametrize("label", ["6r4s", "9r3s", "4r5s"])
def test_calibrations_from_a_generated_solvers_roots(label):
    # generate -> solve -> positions: pencil and homotopy (H, b, o) roots, and a positions formulation
    from solvers.api import _module_for, calibrations

    module = _module_for(label)
    net = random_network(*module.CONFIG, np.random.default_rng(3))
    roots = None
    if label == "4r5s":  # its 344 paths take seconds: the true root (orbit invariants) and a complex one
        from analysis.formulations.positions import _to_gauge
        from solvers.subsystem import orbits_from_receivers

        truth = orbits_from_receivers(_to_gauge(np.asarray(net.receivers, float), np.asarray(net.transmitters, float))[0])
        roots = np.array([truth + 1j, truth, np.full_like(truth, np.nan)], dtype=complex)
    cals = calibrations(module, net.measurements(), roots)
    assert cals and all(a.residual <= b.residual for a, b in zip(cals, cals[1:]))
    best = cals[0]
    assert best.receivers.shape == (module.CONFIG[0], 2) and best.offsets.shape == (module.CONFIG[1],)
    assert best.receivers[0].tolist() == [0.0, 0.0] and abs(best.receivers[1, 1]) < 1e-12 < best.receivers[1, 0]
    errors = calibration_errors(best, net)
    assert best.residual < 1e-8 and max(errors.position, errors.offset) < 1e-8, (label, best.residual, errors)


def test_a_generated_module_gives_its_own_calibrations(tmp_path):
    """generate -> solve -> positions from the module alone, also when it is loaded from a file outside
    any package (not in sys.modules): the same calibrations as solvers.api.calibrations."""
    import importlib.util

    from solvers.api import _module_for, calibrations

    committed = _module_for("6r4s")
    spec = importlib.util.spec_from_file_location("loose_solver", committed.__file__)
    loose = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(loose)
    net = random_network(6, 4, np.random.default_rng(5))
    F = net.measurements()
    own, via_api = loose.calibrations(F), calibrations(committed, F)
    assert own and [c.residual for c in own] == [c.residual for c in via_api]
    errors = calibration_errors(own[0], net)
    assert max(errors.position, errors.offset) < 1e-8


def test_calibrations_refuse_other_data_and_systems():
    from types import SimpleNamespace

    from solvers.api import _module_for, calibrations

    with pytest.raises(ValueError, match=r"needs \(6, 4\)"):
        calibrations(_module_for("6r4s"), np.ones((5, 4)))
    other = SimpleNamespace(__name__="circle", SYSTEM="circle", CONFIG=(6, 4), UNKNOWNS=("x", "y"))
    with pytest.raises(ValueError, match="neither"):
        calibrations(other, np.ones((6, 4)), roots=np.zeros((1, 2)))
