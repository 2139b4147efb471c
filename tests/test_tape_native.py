"""The tapes' compiled straight-line code (solvers.methods.tape_native) and the tail's one-by-one LU give
the same bits as the interpreter and the batched LU: a solver's roots do not depend on which ran."""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from solvers.methods import tape_kernel, tape_native

HAS_CC = shutil.which("cc") is not None or shutil.which("gcc") is not None


def _solver():
    from solvers.generated import tdoa_9r3s_homotopy75 as module

    return module, module.solver()


@pytest.mark.skipif(not HAS_CC, reason="no C compiler")
def test_compiled_tapes_equal_the_interpreter_bit_for_bit():
    """Every output of the three 9r/3s tapes at random complex inputs, and whole plain tracks (statuses,
    steps, endpoints) on two seeded networks, with and without the compiled code."""
    from solvers.synthetic import random_network

    module, solver = _solver()
    native = tape_native.addresses(solver.tapes, wait=True)
    assert native.shape == (5,) and np.all(native != 0), tape_native.describe(solver.tapes)
    rng = np.random.default_rng(5)
    for kind, fn in zip(tape_native.KINDS, native):
        tape = getattr(solver.tapes, kind)
        P = 9  # not a multiple of the width: the last pass runs into the spare columns
        cap = -(-P // tape_kernel.WIDTH) * tape_kernel.WIDTH
        Rr, Ri, Or, Oi = tape_kernel.workspace(tape, cap)
        Rr[: tape.n_inputs] = rng.normal(size=(tape.n_inputs, cap))
        Ri[: tape.n_inputs] = rng.normal(size=(tape.n_inputs, cap))
        N = solver.nvars
        Ri[N] = 0.0  # the path parameter s is real
        tape_kernel.run_tape(tape.code, tape.imm, Rr, Ri, Or, Oi, P)
        expected = (Or[:, :P].copy(), Oi[:, :P].copy())
        Or[:], Oi[:] = np.nan, np.nan
        x_r, x_i, s = Rr[:N].copy(), Ri[:N].copy(), Rr[N].copy()
        tape_kernel._eval(tape.code, tape.imm, fn, Rr, Ri, Or, Oi, N, x_r, x_i, s, P)
        np.testing.assert_array_equal(Or[:, :P], expected[0])
        np.testing.assert_array_equal(Oi[:, :P], expected[1])
    for seed in (0, 1):
        F = random_network(9, 3, np.random.default_rng(seed)).measurements().reshape(1, -1)
        q = F / np.sqrt(np.mean(F ** 2))
        x_a, s_a = tape_kernel.track(solver.tapes, solver.q0, q, solver.x0, None, solver.options)
        x_b, s_b = tape_kernel.track(solver.tapes, solver.q0, q, solver.x0, None, solver.options, native=native)
        np.testing.assert_array_equal(s_a, s_b)
        np.testing.assert_array_equal(x_a, x_b)
        assert np.sum(s_a[:, 0] == 0) >= 70  # the comparison covers tracked paths, not failures


def test_native_switch_and_bad_addresses(monkeypatch):
    """TDOA_WORKBENCH_NATIVE=off: no compiled code (the interpreter, same results); a malformed address
    array is refused before it reaches the kernel."""
    _, solver = _solver()
    monkeypatch.setenv(tape_native.DISABLE_ENV, "off")
    assert not tape_native.addresses(solver.tapes).any()
    with pytest.raises(ValueError, match="five entry points"):
        tape_kernel.track(solver.tapes, solver.q0, solver.q0, solver.x0[:2], None, solver.options, native=np.zeros(3))


def test_lu_one_by_one_equals_batched():
    """Below SCALAR_BELOW columns the LU and its solves run matrix by matrix: the same bits as the batched
    loops (the same matrices factored in a batch of 12 and in batches of 1 and 3), singular flags too."""
    rng = np.random.default_rng(11)
    N, P = 7, 12
    A = rng.normal(size=(N + N * N, P)) + 1j * rng.normal(size=(N + N * N, P))
    A[N:, 4] = 0.0  # a singular matrix
    b = rng.normal(size=(N, P)) + 1j * rng.normal(size=(N, P))

    def factor_solve(cols):
        Ar, Ai = np.ascontiguousarray(A[:, cols].real), np.ascontiguousarray(A[:, cols].imag)
        br, bi = np.ascontiguousarray(b[:, cols].real), np.ascontiguousarray(b[:, cols].imag)
        k = len(cols)
        piv, ok = np.zeros((N, k), dtype=np.int64), np.zeros(k, dtype=np.bool_)
        tape_kernel._lu(Ar, Ai, N, N, piv, ok, k)
        tape_kernel._solve(Ar, Ai, N, N, piv, br, bi, k)
        return Ar + 1j * Ai, br + 1j * bi, piv, ok

    assert 3 < tape_kernel.SCALAR_BELOW <= P
    whole = factor_solve(list(range(P)))
    for cols in ([0], [3, 4, 5], [11]):
        part = factor_solve(cols)
        for got, ref in zip(part, whole):
            np.testing.assert_array_equal(got, ref[..., cols])
    assert not whole[3][4] and whole[3][[0, 1, 2, 3, 5]].all()
    # and the solves are solves: A x = b on a regular column
    M = A[N:, 0].reshape(N, N)
    np.testing.assert_allclose(M @ whole[1][:, 0], b[:, 0], rtol=1e-10, atol=1e-10)
