"""solvers.calibration.adjustment: the statistics of a least-squares fit against their dense definitions."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from solvers.calibration.adjustment import (
    adjustment_statistics,
    critical_value,
    dense_jacobian,
    entry_residuals,
    robust_refine,
)
from solvers.recovery import to_gauge
from solvers.refine import jacobian, pack
from solvers.synthetic import random_network


def _fit(m, n, seed, sigma=1e-2, missing=0.0):
    rng = np.random.default_rng(seed)
    net = random_network(m, n, rng)
    F = net.measurements(sigma, rng)
    F[rng.random(F.shape) < missing] = np.nan
    mask = np.isfinite(F)
    R, S = to_gauge(net.receivers, net.transmitters)
    ls = robust_refine(F, mask, R, S, net.offsets.copy(), loss="linear")
    return net, F, mask, ls


@pytest.mark.parametrize("sigma_prior", [None, 1e-2])
def test_redundancy_numbers_and_w_tests_match_their_dense_definitions(sigma_prior):
    _, F, mask, ls = _fit(8, 6, seed=1)
    st = adjustment_statistics(F, mask, ls.R, ls.S, ls.O, sigma_prior)
    e, diff, dist = entry_residuals(st.x, st.problem)
    J = dense_jacobian(st.problem, diff, dist)
    H = J @ np.linalg.solve(J.T @ J, J.T)
    r = 1.0 - np.diag(H)
    assert np.allclose(st.redundancy, r, atol=1e-10)
    assert np.isclose(st.redundancy.sum(), st.dof) and st.dof == mask.sum() - (2 * 8 + 3 * 6 - 3)
    # residuals of the least-squares fit are orthogonal to the columns of J
    assert np.abs(J.T @ e).max() < 1e-9 * np.abs(J).sum()
    if sigma_prior is None:
        s_out = np.sqrt((st.ssr - e**2 / r) / (st.dof - 1))  # sigma without entry k
        assert np.allclose(st.w, e / (s_out * np.sqrt(r)))
        assert st.global_passed is None and np.isclose(st.sigma, np.sqrt(st.ssr / st.dof))
    else:
        assert np.allclose(st.w, e / (sigma_prior * np.sqrt(r)))
        assert np.isclose(st.global_statistic, st.ssr / sigma_prior**2)
        assert np.isclose(st.global_critical, stats.chi2.isf(0.01, st.dof))
    delta0 = stats.norm.isf(0.0005) + stats.norm.ppf(0.8)
    assert np.allclose(st.mdb, st.sigma * delta0 / np.sqrt(r))


def test_node_std_is_the_refine_jacobians_covariance():
    net, F, mask, ls = _fit(7, 5, seed=12, sigma=0.0)
    st = adjustment_statistics(F, mask, ls.R, ls.S, ls.O, 0.1)
    rstd, tstd, ostd = st.node_std(7, 5)
    R, S = to_gauge(net.receivers, net.transmitters)
    J = jacobian(pack(R, S, net.offsets), F)  # solvers.refine: same gauge and parameter order
    var = np.diag(0.01 * np.linalg.inv(J.T @ J))
    k0 = 1 + 2 * (7 - 2)
    assert rstd[0] == 0.0 and np.isclose(rstd[1], np.sqrt(var[0]))
    assert np.allclose(rstd[2:], np.sqrt(var[1:k0].reshape(-1, 2).sum(axis=1)))
    assert np.allclose(tstd, np.sqrt(var[k0 : k0 + 10].reshape(-1, 2).sum(axis=1)))
    assert np.allclose(ostd, np.sqrt(var[k0 + 10 :]))


def test_external_reliability_is_the_largest_node_shift_of_an_mdb_sized_error():
    _, F, mask, ls = _fit(6, 5, seed=3, missing=0.1)
    st = adjustment_statistics(F, mask, ls.R, ls.S, ls.O, 1e-2)
    rel_r, rel_t = st.external_reliability(6, 5)
    e, diff, dist = entry_residuals(st.x, st.problem)
    J = dense_jacobian(st.problem, diff, dist)
    N_inv = np.linalg.inv(J.T @ J)
    shifts = N_inv @ J.T * st.mdb  # column k: parameter shift of a bias mdb_k in entry k
    shifts = np.vstack([shifts, np.zeros(shifts.shape[1])])  # the fixed gauge coordinates
    rs, ts = st.problem.slots_of(True), st.problem.slots_of(False)
    expect_r = np.hypot(shifts[rs[:, 0]], shifts[rs[:, 1]]).max(axis=1)
    expect_t = np.hypot(shifts[ts[:, 0]], shifts[ts[:, 1]]).max(axis=1)
    assert np.allclose(rel_r[st.problem.rows], expect_r) and np.allclose(rel_t[st.problem.cols], expect_t)
    assert rel_r[0] == 0.0  # the gauge receiver does not move


def test_prediction_test_of_a_left_out_entry_equals_its_in_fit_w_test():
    # Baarda: testing entry k inside the fit and predicting it from the fit without it are one test.
    _, F, mask, ls = _fit(8, 5, seed=4)
    st = adjustment_statistics(F, mask, ls.R, ls.S, ls.O, 1e-2)
    k = int(np.argmax(st.redundancy))
    i, j = st.entries[k]
    without = mask.copy()
    without[i, j] = False
    ls2 = robust_refine(F, mask, ls.R, ls.S, ls.O, loss="linear", use=without)
    st2 = adjustment_statistics(F, without, ls2.R, ls2.S, ls2.O, 1e-2)
    from solvers.calibration.adjustment import make_problem

    only = np.zeros_like(mask)
    only[i, j] = True
    e, h = st2.hat(make_problem(F, only, st2.problem.rows, st2.problem.cols, dim=2))
    w_pred = e[0] / (1e-2 * np.sqrt(1.0 + h[0]))
    assert np.isclose(w_pred, st.w[k], rtol=1e-3)


def test_critical_values():
    assert np.isclose(critical_value(0.001), 3.2905, atol=1e-4)
    assert critical_value(0.001, 5) > critical_value(0.001, 50) > critical_value(0.001)


def test_a_rank_deficient_fit_reports_its_undetermined_coordinates():
    # transmitter 4 measured by 2 receivers only: its position and offset (3 unknowns) are not determined
    net, F, mask, ls = _fit(6, 4, seed=5, sigma=0.0)
    use = mask.copy()
    use[2:, 3] = False
    st = adjustment_statistics(F, use, ls.R, ls.S, ls.O, 1e-3)
    rstd, tstd, ostd = st.node_std(6, 4)
    assert st.deficient and np.isinf(tstd[3]) and np.isfinite(tstd[:3]).all()


def _dense_reference(st, weights=None):
    """Redundancy numbers and the covariance diagonal from the dense pseudo-inverse of J^T W J."""
    from solvers.calibration.adjustment import _pseudo_inverse

    e, diff, dist = entry_residuals(st.x, st.problem)
    J = dense_jacobian(st.problem, diff, dist)
    w = np.ones(len(e)) if weights is None else weights
    Ninv, null = _pseudo_inverse(J.T @ (w[:, None] * J))
    return 1.0 - w * np.einsum("ka,ab,kb->k", J, Ninv, J), np.diag(Ninv), null, J, Ninv


@pytest.mark.parametrize("dim, m, n, missing", [(2, 9, 7, 0.1), (3, 10, 8, 0.15)])
def test_block_schur_statistics_equal_the_dense_pseudo_inverse(dim, m, n, missing):
    # the normal matrix kept by blocks (transmitters eliminated by their Schur complement) gives the
    # redundancy numbers, w-tests, node stds and external reliability of the dense pseudo-inverse
    from solvers.calibration.adjustment import normal_equations
    from solvers.synthetic import room_network

    rng = np.random.default_rng(20 + dim)
    net = random_network(m, n, rng) if dim == 2 else room_network(m, n, rng)
    F = net.measurements(1e-2, rng)
    F[rng.random(F.shape) < missing] = np.nan
    mask = np.isfinite(F)
    R, S = to_gauge(net.receivers, net.transmitters)
    ls = robust_refine(F, mask, R, S, net.offsets.copy(), loss="linear")
    weights = rng.uniform(0.2, 1.0, F.shape)
    for wmat in (None, weights):
        st = adjustment_statistics(F, mask, ls.R, ls.S, ls.O, 1e-2, weights=wmat)
        wk = None if wmat is None else wmat[st.entries[:, 0], st.entries[:, 1]]
        r, diag, null, J, Ninv = _dense_reference(st, wk)
        assert not null.any() and not st.deficient
        assert np.abs(st.redundancy - r).max() < 1e-8
        assert np.allclose(st.inverse.diagonal(), diag, rtol=1e-8, atol=1e-12)
    # the block normal matrix and its solve are J^T J and its inverse
    e, diff, dist = entry_residuals(st.x, st.problem)
    N = normal_equations(st.problem, diff, dist, np.ones(len(e)), e)
    assert np.allclose(N.dense(), J.T @ J, atol=1e-12) and np.allclose(N.g, J.T @ e, atol=1e-14)
    b = rng.standard_normal(J.shape[1])
    assert np.allclose(N.solve(b), np.linalg.solve(J.T @ J, b), rtol=1e-8, atol=1e-10)
    assert np.allclose(N.matvec(b), J.T @ (J @ b))
    # external reliability: the largest node shift of an MDB-sized error, N^-1 j_k mdb_k
    rel_r, rel_t = st.external_reliability(m, n)
    shifts = np.vstack([Ninv @ J.T * st.mdb, np.zeros(len(e))])
    rs, ts = st.problem.slots_of(True), st.problem.slots_of(False)
    expect_r = np.sqrt(sum(shifts[rs[:, a]] ** 2 for a in range(dim))).max(axis=1)
    expect_t = np.sqrt(sum(shifts[ts[:, a]] ** 2 for a in range(dim))).max(axis=1)
    assert np.allclose(rel_r[st.problem.rows], expect_r, rtol=1e-7, atol=1e-12)
    assert np.allclose(rel_t[st.problem.cols], expect_t, rtol=1e-7, atol=1e-12)


def test_block_inverse_of_a_rank_deficient_fit_marks_the_dense_null_space():
    # transmitter 4 measured by 2 receivers: its block is singular; the redundancy numbers (estimable)
    # and the undetermined coordinates are those of the dense pseudo-inverse
    net, F, mask, ls = _fit(6, 4, seed=5, sigma=1e-3)
    use = mask.copy()
    use[2:, 3] = False
    st = adjustment_statistics(F, use, ls.R, ls.S, ls.O, 1e-3)
    r, diag, null, _, _ = _dense_reference(st)
    assert np.array_equal(st.null, null) and null.any()
    assert np.abs(st.redundancy - r).max() < 1e-8
    assert np.allclose(st.inverse.diagonal()[~null], diag[~null], rtol=1e-8)
