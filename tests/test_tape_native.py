"""The tapes' compiled straight-line code, the compiled LU and the compiled tracker (solvers.continuation.tape_native)
give the same bits as the interpreter, the batched LU and numba's tracker: a solver's roots do not depend on
which ran."""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from solvers.continuation import tape_jit, tape_kernel, tape_native

from analysis.engine.native import disabled

# the compiled code is built where a compiler is found, unless TDOA_WORKBENCH_NATIVE=off (as the F4 kernels)
COMPILED = (shutil.which("cc") is not None or shutil.which("gcc") is not None) and not disabled()


def _solver(name: str = "tdoa_9r3s_homotopy75"):
    import importlib

    module = importlib.import_module(f"solvers.generated.{name}")
    return module, module.solver()


#: Every kind of homotopy solver: monomials (9r/3s), squared by principal minors with a Pade predictor
#: (5r/5s), squared by random combinations of minors (5r/4s), the degree-10 positions program (4r/5s).
TAPE_SOLVERS = ["tdoa_9r3s_homotopy75", "tdoa_5r5s_homotopy64", "tdoa_5r4s_homotopy152",
                pytest.param("tdoa_4r5s_homotopy344", marks=pytest.mark.slow)]


@pytest.mark.skipif(not COMPILED, reason="no C compiler, or TDOA_WORKBENCH_NATIVE=off")
@pytest.mark.parametrize("name", TAPE_SOLVERS)
def test_compiled_tapes_equal_the_interpreter_bit_for_bit(name):
    """Every output of a solver's three tapes at random complex inputs, and whole plain tracks (statuses,
    steps, endpoints) on two seeded networks, with and without the compiled code."""
    from solvers.synthetic import random_network

    module, solver = _solver(name)
    native = tape_native.addresses(solver.tapes, wait=True)
    assert native.shape == (6,) and np.all(native != 0), tape_native.describe(solver.tapes)
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
        tape_jit._eval(tape.code, tape.imm, fn, Rr, Ri, Or, Oi, N, x_r, x_i, s, P)
        np.testing.assert_array_equal(Or[:, :P], expected[0])
        np.testing.assert_array_equal(Oi[:, :P], expected[1])
    for seed in (0, 1):
        F = random_network(*module.CONFIG, np.random.default_rng(seed)).measurements().reshape(1, -1)
        q = F / np.sqrt(np.mean(F ** 2)) if module.SCALE_POWERS is not None else F
        x_a, s_a = tape_kernel.track(solver.tapes, solver.q0, q, solver.x0, None, solver.options)
        x_b, s_b = tape_kernel.track(solver.tapes, solver.q0, q, solver.x0, None, solver.options,
                                     native=np.r_[native[:5], 0])  # the compiled tapes in numba's tracker
        np.testing.assert_array_equal(s_a, s_b)
        np.testing.assert_array_equal(x_a, x_b)
        # the comparison covers tracked paths, not failures
        assert np.sum(s_a[:, 0] == 0) >= 0.8 * module.PATHS, (name, seed, np.sum(s_a[:, 0] == 0))


def test_native_switch_and_bad_addresses(monkeypatch):
    """TDOA_WORKBENCH_NATIVE=off: no compiled code (the interpreter, same results); a malformed address
    array is refused before it reaches the kernel."""
    _, solver = _solver()
    monkeypatch.setenv(tape_native.DISABLE_ENV, "off")
    assert not tape_native.addresses(solver.tapes).any()
    with pytest.raises(ValueError, match="six entry points"):
        tape_kernel.track(solver.tapes, solver.q0, solver.q0, solver.x0[:2], None, solver.options, native=np.zeros(3))


def factor_solve(A: np.ndarray, b: np.ndarray, N: int, P: int, addresses: np.ndarray) -> tuple:
    """(factors, solutions, pivots, flags) of the matrices in rows N.. of A's first P columns and right-hand sides b, by
    the LU and solve at ``addresses`` (zeros: the batched kernels)."""
    cap = A.shape[1]
    Ar, Ai = np.ascontiguousarray(A.real), np.ascontiguousarray(A.imag)
    br, bi = np.ascontiguousarray(b.real), np.ascontiguousarray(b.imag)
    piv, ok = np.zeros((N, cap), dtype=np.int64), np.zeros(cap, dtype=np.bool_)
    tape_jit._factor(addresses, Ar, Ai, N, N, piv, ok, P)
    tape_jit._back(addresses, Ar, Ai, N, N, piv, br, bi, P)
    return (Ar + 1j * Ai)[:, :P], (br + 1j * bi)[:, :P], piv[:, :P], ok[:P]


@pytest.mark.skipif(not COMPILED, reason="no C compiler, or TDOA_WORKBENCH_NATIVE=off")
def test_compiled_lu_equals_batched():
    """The solver's compiled LU and solves (four columns per pass) give the batched kernels' bits: factors,
    pivots, singular flags and solutions, on 9 columns (a last pass into spare columns) with a singular one and
    one with a NaN entry."""
    _, solver = _solver()
    lin = tape_native.addresses(solver.tapes, wait=True)[3:5]
    assert np.all(lin != 0), tape_native.describe(solver.tapes)
    N = solver.nvars
    rng = np.random.default_rng(11)
    P, cap = 9, 12
    A = rng.normal(size=(N + N * N, cap)) + 1j * rng.normal(size=(N + N * N, cap))
    A[N:, 4] = 0.0  # a singular matrix
    A[N + N * N - 1, 7] = np.nan  # a NaN in the last pivot (the interchanges are vector selects: NaN lanes too)
    b = rng.normal(size=(N, cap)) + 1j * rng.normal(size=(N, cap))
    compiled, batched = factor_solve(A, b, N, P, lin), factor_solve(A, b, N, P, np.zeros(2, dtype=np.int64))
    for got, ref in zip(compiled, batched):
        np.testing.assert_array_equal(got, ref)
    assert not batched[3][4] and not batched[3][7] and batched[3][[0, 1, 2, 3, 5, 6, 8]].all()
    M = A[N:, 0].reshape(N, N)  # and the solves are solves
    np.testing.assert_allclose(M @ batched[1][:, 0], b[:, 0], rtol=1e-10, atol=1e-10)


def test_reference_interpreter_equals_the_compiled_interpreter():
    """run_tape_numpy (plain numpy, what tape_kernel.run uses) gives run_tape's bits on every 9r/3s tape."""
    _, solver = _solver()
    for kind in tape_native.KINDS:
        tape = getattr(solver.tapes, kind)
        outputs = []
        for run in (tape_kernel.run_tape, tape_kernel.run_tape_numpy):
            Rr, Ri, Or, Oi = tape_kernel.workspace(tape, 7)
            Rr[: tape.n_inputs] = np.random.default_rng(3).normal(size=(tape.n_inputs, 7))
            Ri[: tape.n_inputs] = np.random.default_rng(4).normal(size=(tape.n_inputs, 7))
            run(tape.code, tape.imm, Rr, Ri, Or, Oi, 5)
            outputs.append((Or[:, :5], Oi[:, :5]))
        np.testing.assert_array_equal(outputs[0][0], outputs[1][0])
        np.testing.assert_array_equal(outputs[0][1], outputs[1][1])
        assert np.isfinite(outputs[0][0]).all() and np.abs(outputs[0][0]).max() > 0


@pytest.mark.skipif(not COMPILED, reason="no C compiler, or TDOA_WORKBENCH_NATIVE=off")
@pytest.mark.parametrize("predictor, corrector", [("rk4", "newton"), ("pade", "newton"), ("pade", "chord")])
def test_compiled_tracker_equals_numba_tracker(predictor, corrector):
    """The compiled tracker (tape_native.tracker_source) and numba's (tape_jit._track_batch), both on the
    compiled tapes, give the same statuses, step counts and endpoints bit for bit: plain tracks with either
    predictor and corrector and tight retracks on three seeded 9r/3s networks at once (paths compacted as they
    end), and Newton steps alone."""
    import dataclasses

    from solvers.continuation import tracker
    from solvers.synthetic import random_network

    _, solver = _solver()
    native = tape_native.addresses(solver.tapes, wait=True)
    assert native[5] != 0, tape_native.describe(solver.tapes)
    numba_tracker = np.r_[native[:5], 0]
    q = np.vstack([random_network(9, 3, np.random.default_rng(seed)).measurements().reshape(1, -1) for seed in (0, 1, 2)])
    q /= np.sqrt(np.mean(q ** 2, axis=1, keepdims=True))
    K = len(solver.x0)
    x0, inst = np.tile(solver.x0, (3, 1)), np.repeat(np.arange(3), K)
    for options in (dataclasses.replace(solver.options, predictor=predictor, corrector=corrector),
                    dataclasses.replace(tracker.TIGHT, predictor=predictor, corrector=corrector)):
        ends = [tape_kernel.track(solver.tapes, solver.q0, q, x0, inst, options, native=n)
                for n in (numba_tracker, native)]
        np.testing.assert_array_equal(ends[0][1], ends[1][1])
        np.testing.assert_array_equal(ends[0][0], ends[1][0])
        assert np.sum(ends[0][1][:, 0] == 0) >= 200 and np.sum(ends[0][1][:, 1]) > 3 * K * 5  # real tracks
    steps = [tape_kernel.newton(solver.tapes, q, x0, inst, 3, native=n) for n in (numba_tracker, native)]
    np.testing.assert_array_equal(steps[0], steps[1])


@pytest.mark.parametrize("compiled", [True, False])
def test_threads_give_the_same_bits(compiled, monkeypatch):
    """Batches tracked side by side on threads (tape_kernel.set_threads, $TDOA_WORKBENCH_THREADS) give the
    statuses, step counts, endpoints and Newton steps of one thread, with the compiled tracker and with
    numba's: 9r/3s, 8 seeded networks at once (8 x 75 paths, 2 batches); bad thread counts are refused."""
    from solvers.synthetic import random_network

    if compiled and not COMPILED:
        pytest.skip("no C compiler, or TDOA_WORKBENCH_NATIVE=off")
    _, solver = _solver()
    native = tape_native.addresses(solver.tapes, wait=True) if compiled else None
    q = np.vstack([random_network(9, 3, np.random.default_rng(seed)).measurements().reshape(1, -1) for seed in range(8)])
    q /= np.sqrt(np.mean(q ** 2, axis=1, keepdims=True))
    K = len(solver.x0)
    x0, inst = np.tile(solver.x0, (8, 1)), np.repeat(np.arange(8), K)
    assert len(tape_kernel._chunks(len(x0))) >= 2
    runs = []
    try:
        for n in (1, 2, 3):
            tape_kernel.set_threads(n)
            assert tape_kernel.threads() == n
            x, stats = tape_kernel.track(solver.tapes, solver.q0, q, x0, inst, solver.options, native=native)
            runs.append((x, stats, tape_kernel.newton(solver.tapes, q, x0, inst, 2, native=native)))
    finally:
        tape_kernel.set_threads(None)
    for run in runs[1:]:
        for a, b in zip(runs[0], run):
            np.testing.assert_array_equal(a, b)
    assert np.sum(runs[0][1][:, 0] == 0) >= 0.8 * len(x0)  # real tracks
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="positive integer"):
            tape_kernel.set_threads(bad)
    monkeypatch.setenv(tape_kernel.THREADS_ENV, "auto")
    assert tape_kernel.threads() >= 1
    monkeypatch.setenv(tape_kernel.THREADS_ENV, "two")
    with pytest.raises(ValueError, match="TDOA_WORKBENCH_THREADS"):
        tape_kernel.threads()
    monkeypatch.delenv(tape_kernel.THREADS_ENV)
    assert tape_kernel.threads() == 1


@pytest.mark.parametrize("compiled", [False, True])
def test_narrower_batches_give_the_same_bits(compiled, monkeypatch):
    """A system whose batch of CHUNK paths would take more than BATCH_BYTES is tracked in narrower batches
    (5r/9s in 3D: 64 paths a batch): 9r/3s's 75 paths of one network in batches of 8 give the bits of one batch."""
    if compiled and not COMPILED:
        pytest.skip("no C compiler, or TDOA_WORKBENCH_NATIVE=off")
    from solvers.synthetic import random_network

    _, solver = _solver()
    native = tape_native.addresses(solver.tapes, wait=True) if compiled else None
    q = random_network(9, 3, np.random.default_rng(3)).measurements().reshape(1, -1)
    q = q / np.sqrt(np.mean(q ** 2))
    assert tape_kernel.batch_width(solver.tapes) == tape_kernel.CHUNK  # 4.8 KB a path
    one = tape_kernel.track(solver.tapes, solver.q0, q, solver.x0, None, solver.options, native=native)
    polished = tape_kernel.newton(solver.tapes, q, one[0][np.all(np.isfinite(one[0]), axis=1)], None, 2, native=native)
    monkeypatch.setattr(tape_kernel, "BATCH_BYTES", 1)
    assert tape_kernel.batch_width(solver.tapes) == 8
    assert len(tape_kernel._chunks(len(solver.x0), 8)) >= 9
    narrow = tape_kernel.track(solver.tapes, solver.q0, q, solver.x0, None, solver.options, native=native)
    for a, b in zip(one, narrow):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(polished, tape_kernel.newton(solver.tapes, q, one[0][np.all(np.isfinite(one[0]), axis=1)],
                                                               None, 2, native=native))
    assert np.sum(one[1][:, 0] == 0) >= 0.8 * len(solver.x0)  # real tracks


@pytest.mark.skipif(not COMPILED, reason="no C compiler, or TDOA_WORKBENCH_NATIVE=off")
def test_systems_of_one_size_share_the_lu_and_tracker_object(tmp_path, monkeypatch):
    """The LU-and-tracker translation unit depends on the number of unknowns alone: a second user's system of 2
    unknowns compiles only its tapes and links the kept object, and its library's Newton steps (tapes, LU,
    tracker of that object) converge on a known root."""
    from analysis.formulations.parametric import parse
    from solvers.continuation import tracking

    monkeypatch.setenv("TDOA_WORKBENCH_CACHE", str(tmp_path))
    compiled: list[list[str]] = []
    run_all = tape_native._run_all
    monkeypatch.setattr(tape_native, "_run_all", lambda commands: compiled.append(commands) or run_all(commands))

    def tapes(text: str):
        system = parse(text, "user")
        exps, eq = tracking.structure(system)
        spec = {"system": system.name, "unknowns": list(system.unknowns), "parameters": list(system.parameters),
                "exponents": exps.tolist(), "term_equation": eq.tolist()}
        return tracking._tapes(spec, tracking.load_coefficients(tracking.coefficient_source(system)), "tape")

    first = tapes("unknowns: x, y\nparameters: a, b\nequations:\nx^2 + y^2 - a\nx*y - b\n")
    second = tapes("unknowns: x, y\nparameters: a, b, c\nequations:\nx^3 - y - a\nx*y^2 - b*x - c\n")
    assert tape_native.addresses(first).all()
    assert len([c for c in compiled[0] if "-c" in c]) == 3 and len(list((tmp_path / "tapes").glob("unit-*.o"))) == 1
    native = tape_native.addresses(second)
    assert native.all() and len([c for c in compiled[-2] if "-c" in c]) == tape_native.TAPE_UNITS
    x, y = 1.3 - 0.2j, -0.7 + 0.4j  # a root of the second system at q
    q = np.array([[x ** 3 - y, 0.5, x * y * y - 0.5 * x]])
    start = np.array([[x + 1e-3, y - 2e-3]])
    np.testing.assert_allclose(tape_kernel.newton(second, q, start, steps=6, native=native)[0], [x, y], atol=1e-13)
