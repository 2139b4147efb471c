"""The sparse elimination order of the tracker's Jacobians (solvers.continuation.sparse_lu): the zero pattern read off
the tapes is the Jacobian's, the compiled LU that skips what the schedule says is zero gives the dense LU's bits on the
renamed matrix, and a solver in that order tracks to the dense order's roots."""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from analysis.engine.native import disabled
from solvers import count
from solvers.continuation import monodromy, sparse_lu, tape_jit, tape_kernel, tape_native
from test_tape_native import factor_solve

COMPILED = (shutil.which("cc") is not None or shutil.which("gcc") is not None) and not disabled()


@pytest.fixture(scope="module")
def sparse_solver():
    """count's solver of the 3D TDOA 7r/5s cell (35 unknowns, 215 of 1,225 Jacobian entries not zero) and its
    start pair."""
    system, q0, x0, _ = count._start(count.tdoa_target("7r5s", dim=3), 0)
    solver, x0 = monodromy.start_solver(system, q0, x0, 0)
    return solver, q0, x0[0]


def _segments(q0, k, seed):
    rng = np.random.default_rng(seed)
    scale = 0.3 * np.abs(q0).mean()
    return np.array([q0 + scale * (rng.normal(size=q0.shape) + 1j * rng.normal(size=q0.shape)) for _ in range(k)])


def test_pattern_is_the_jacobians_zero_pattern(sparse_solver):
    """Every entry the tape says is zero is exactly zero at random complex points, and every other one is not."""
    solver, q0, x0 = sparse_solver
    tapes, N = solver.tapes, solver.nvars
    nz = sparse_lu.pattern(tapes.full, N)
    assert 0 < nz.sum() < 0.25 * N * N
    rng = np.random.default_rng(3)
    x = rng.normal(size=(5, N)) + 1j * rng.normal(size=(5, N))
    q1 = _segments(q0, 1, 4)[0]
    out = tape_kernel.evaluate(tapes.full, x, np.full(5, 0.4), q0, q1)  # (5, outputs)
    J = out[:, N:N + N * N].reshape(5, N, N)
    assert np.all(J[:, ~nz] == 0)
    assert np.all(np.abs(J[:, nz]) > 0)


def test_order_and_schedule_bound_the_work(sparse_solver):
    """The greedy order's schedule holds every position the LU can fill (a dense LU of a random matrix with the
    renamed pattern writes nothing outside it) and costs at most WORTH of the dense LU's updates."""
    solver, _, _ = sparse_solver
    N = solver.nvars
    nz = sparse_lu.pattern(solver.tapes.full, N)
    rows, cols = sparse_lu.elimination_order(nz)
    assert sorted(rows) == list(range(N)) and sorted(cols) == list(range(N))
    M = nz[np.ix_(rows, cols)]
    steps = sparse_lu.schedule(M)
    assert sparse_lu.cost(steps) <= sparse_lu.WORTH * sparse_lu.dense_cost(N)
    allowed = M.copy()
    for k, (T, U) in enumerate(steps):
        for i in (k, *T):
            allowed[i, k] = True
            allowed[i, list(U)] = True
    rng = np.random.default_rng(8)
    A = ((rng.normal(size=(N, N)) + 1j * rng.normal(size=(N, N))) * M).reshape(-1, 1)
    Ar, Ai = np.ascontiguousarray(A.real), np.ascontiguousarray(A.imag)
    piv, ok = np.zeros((N, 1), dtype=np.int64), np.zeros(1, dtype=np.bool_)
    tape_jit._lu(Ar, Ai, 0, N, piv, ok, 1)
    F = (Ar + 1j * Ai)[:, 0].reshape(N, N)
    assert ok[0] and np.all(F[~allowed] == 0)


@pytest.mark.skipif(not COMPILED, reason="no C compiler, or TDOA_WORKBENCH_NATIVE=off")
def test_compiled_sparse_lu_equals_the_dense_lu_bit_for_bit(sparse_solver):
    """On 9 matrices with the renamed pattern (one singular), the compiled LU that follows the schedule gives the dense batched LU's factors, pivots, flags and solves."""
    solver, _, _ = sparse_solver
    T, N = solver.sparse.tapes, solver.nvars
    lin = tape_native.addresses(T, wait=True)[3:5]
    nz = sparse_lu.pattern(solver.tapes.full, N)
    nz = nz[np.ix_(*sparse_lu.elimination_order(nz))]  # the renamed Jacobian's pattern
    rng = np.random.default_rng(11)
    P, cap = 9, 12
    A = np.zeros((N + N * N, cap), dtype=complex)
    for p in range(cap):
        A[N:, p] = ((rng.normal(size=(N, N)) + 1j * rng.normal(size=(N, N))) * nz).ravel()
    A[N:, 4] = 0.0
    b = rng.normal(size=(N, cap)) + 1j * rng.normal(size=(N, cap))
    compiled, dense = factor_solve(A, b, N, P, lin), factor_solve(A, b, N, P, np.zeros(2, dtype=np.int64))
    for got, ref in zip(compiled, dense):
        np.testing.assert_array_equal(got, ref)
    assert not dense[3][4] and dense[3][[0, 1, 2, 3, 5, 6, 7, 8]].all()
    M = A[N:, 0].reshape(N, N)
    np.testing.assert_allclose(M @ dense[1][:, 0], b[:, 0], rtol=1e-9, atol=1e-9)


def test_sparse_order_tracks_to_the_dense_orders_roots(sparse_solver):
    """count's solver (sparse order) and the same solver in the dense order track 24 paths to 24 random parameter
    points with the same statuses and step counts, to the same roots up to rounding; on the renamed tapes the
    compiled tracker and numba's give the same bits, and the same as numba's on renamed tapes that still write every
    zero the factorisation never reaches."""
    solver, q0, x0 = sparse_solver
    assert solver.sparse is not None
    ordered, dense = solver.sparse.work
    assert ordered < 0.3 * dense
    q = _segments(q0, 24, 5)
    X = np.tile(x0, (24, 1))
    inst = np.arange(24)
    xs, ss = solver.track(q0[None], q, X, inst)
    plan, solver.sparse = solver.sparse, None
    try:
        xd, sd = solver.track(q0[None], q, X, inst)
    finally:
        solver.sparse = plan
    np.testing.assert_array_equal(ss[:, :2], sd[:, :2])
    done = ss[:, 0] == 0
    assert done.sum() >= 20
    np.testing.assert_allclose(xs[done], xd[done], rtol=1e-9, atol=1e-9)
    assert solver.residual(xs[done], q, inst[done]).max() < 1e-8
    T = plan.tapes
    N = solver.nvars
    rows, cols = sparse_lu.elimination_order(sparse_lu.pattern(solver.tapes.full, N))
    written = sparse_lu.permuted(solver.tapes, rows, cols, unwritten=False)  # every zero written, every evaluation
    assert np.array_equal(plan.cols, cols) and len(T.full.code) < len(written.full.code)
    runs = [tape_kernel.track(T, q0[None], q, X[:, plan.cols], inst, solver.options, native=tape_native.addresses(T)),
            tape_kernel.track(T, q0[None], q, X[:, plan.cols], inst, solver.options, native=None),
            tape_kernel.track(written, q0[None], q, X[:, plan.cols], inst, solver.options, native=None)]
    for other in runs[1:]:
        np.testing.assert_array_equal(runs[0][1], other[1])
        np.testing.assert_array_equal(runs[0][0], other[0])


def test_dense_systems_and_committed_solvers_keep_the_dense_order():
    """No plan where the order would not save half the work (the 9r/3s solver's 8 unknowns), and a committed
    solver is built in the dense order (its committed outputs were computed so)."""
    import importlib

    module = importlib.import_module("solvers.generated.tdoa_9r3s_homotopy75")
    solver = module.solver()
    assert solver.sparse is None and sparse_lu.plan(solver.tapes) is None
    seven = importlib.import_module("solvers.generated.tdoa_7r5s3d_homotopy2321").solver()
    assert seven.sparse is None and sparse_lu.plan(seven.tapes) is not None


def test_fortran_ordered_start_points_are_tracked(sparse_solver):
    """Start points in Fortran order (a column selection x[:, idx] can be one) reach the compiled tracker's output:
    the same endpoints as the C-ordered copy (the compiled tracker wrote into a contiguous copy of an F-ordered
    output and left the output unset)."""
    solver, q0, x0 = sparse_solver
    q = _segments(q0, 6, 7)
    X = np.tile(x0, (6, 1))
    a = tape_kernel.track(solver.tapes, q0[None], q, np.ascontiguousarray(X), np.arange(6), solver.options,
                          native=tape_native.addresses(solver.tapes))
    b = tape_kernel.track(solver.tapes, q0[None], q, np.asfortranarray(X), np.arange(6), solver.options,
                          native=tape_native.addresses(solver.tapes))
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
