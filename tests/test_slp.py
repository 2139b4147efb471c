"""Straight-line programs and the tape interpreter: common subexpressions, constant folding, and the
TDOA homotopy tapes against the tracker's monomial kernel and finite differences."""
from __future__ import annotations

import dataclasses
import importlib
import os

import numpy as np
import pytest

from solvers.continuation import slp, tape_jit, tape_kernel, tracker
from solvers.generate import GENERATED_DIR, SOLVERS


def test_program_shares_and_folds():
    prog = slp.Program()
    x, y = prog.inputs(["x", "y"])
    a = x * y + 2.0 * x
    b = y * x + x * 2.0
    assert a.id == b.id  # hash-consed, commutative operands sorted
    assert (x * 1.0).id == x.id and (x + 0.0).id == x.id and prog.is_zero(x * 0.0)
    assert (-(-x)).id == x.id and (x - x).id == prog.constant(0.0).id
    dx, dy = slp.derivative([x * x * y], x)[0], slp.derivative([x * x * y], y)[0]
    tape = prog.compile([x * x * y, dx, dy])
    out = tape_kernel.run(tape, np.array([[1.5 + 0.5j, -2.0], [0.25j, 3.0 - 1j]]))
    X, Y = np.array([1.5 + 0.5j, -2.0]), np.array([0.25j, 3.0 - 1j])
    np.testing.assert_allclose(out, [X * X * Y, 2 * X * Y, X * X], rtol=1e-14)


def test_power_by_squaring():
    prog = slp.Program()
    (x,) = prog.inputs(["x"])
    tape = prog.compile([x ** 5, x ** 0])
    z = np.array([[0.3 - 1.1j]])
    np.testing.assert_allclose(tape_kernel.run(tape, z)[:, 0], [z[0, 0] ** 5, 1.0], rtol=1e-14)
    assert tape.n_instructions == 4  # x^2, x^4, x^5 and the constant 1


MODULES = {"9r3s": "tdoa_9r3s_homotopy75", "6r3s": "tdoa_6r3s_homotopy180", "5r4s": "tdoa_5r4s_homotopy152",
           "5r5s": "tdoa_5r5s_homotopy64", "4r5s": "tdoa_4r5s_homotopy344"}


@pytest.mark.parametrize("label", ["9r3s", "6r3s", "5r4s", "5r5s", "4r5s"])
def test_tdoa_tape_matches_tracker_kernel(label):
    """H, J, dH/ds of the unexpanded tape (TDOA A/B/C; minors squared: 5r/4s, 5r/5s; positions: 4r/5s)
    equal the generated solver's expanded system at random complex points on a random segment; J and
    dH/ds agree with central finite differences."""
    module = importlib.import_module(f"solvers.generated.{MODULES[label]}")
    solver = module.solver()
    tapes = slp.system_homotopy_tapes(module.SYSTEM)
    if label in ("9r3s", "6r3s"):  # the formulation's label gives the same program
        assert slp.tdoa_homotopy_tapes(SOLVERS[label]).full.n_instructions == tapes.full.n_instructions
    rng = np.random.default_rng(7)
    P, N = 12, solver.nvars
    x = solver.x0[:P] + 0.3 * (rng.normal(size=(P, N)) + 1j * rng.normal(size=(P, N)))
    q0 = solver.q0
    q1 = rng.normal(size=len(q0)) + 0.1j * rng.normal(size=len(q0))
    s = rng.uniform(size=P)
    H, J, Hs = tracker.evaluate(solver.structure, solver.segment(q0[None], q1[None]), x, s)
    out = tape_kernel.evaluate(tapes.full, x, s, q0, q1)
    scale = np.abs(H).max() + np.abs(J).max()
    np.testing.assert_allclose(out[:, :N], H, atol=1e-12 * scale)
    np.testing.assert_allclose(out[:, N:N + N * N].reshape(P, N, N), J, atol=1e-12 * scale)
    np.testing.assert_allclose(out[:, N + N * N:], Hs, atol=1e-12 * (np.abs(Hs).max()))
    np.testing.assert_allclose(tape_kernel.evaluate(tapes.residual, x, s, q0, q1), H, atol=1e-12 * scale)
    np.testing.assert_allclose(tape_kernel.evaluate(tapes.newton, x, s, q0, q1), out[:, :N + N * N], atol=1e-12 * scale)
    # finite differences (complex-analytic: a real step suffices)
    eps = 1e-6
    Jfd = np.empty((P, N, N), dtype=complex)
    for k in range(N):
        dxk = np.zeros(N)
        dxk[k] = eps * (1.0 + np.abs(x[:, k]).max())
        hp = tape_kernel.evaluate(tapes.residual, x + dxk, s, q0, q1)
        hm = tape_kernel.evaluate(tapes.residual, x - dxk, s, q0, q1)
        Jfd[:, :, k] = (hp - hm) / (2 * dxk[k])
    np.testing.assert_allclose(out[:, N:N + N * N].reshape(P, N, N), Jfd, atol=1e-6 * scale)
    hp = tape_kernel.evaluate(tapes.residual, x, s + eps, q0, q1)
    hm = tape_kernel.evaluate(tapes.residual, x, s - eps, q0, q1)
    np.testing.assert_allclose(out[:, N + N * N:], (hp - hm) / (2 * eps), atol=1e-6 * np.abs(Hs).max())


def test_programs_need_a_square_system_or_a_known_variant():
    """An over-determined formulation (5r/4s with all its minors, not squared) has a program but no
    homotopy; a positions variant without a program and a name of no known form are refused."""
    with pytest.raises(ValueError, match="square system"):
        slp.system_homotopy_tapes("5r4s:A,B2,B3,C2-C5,minors")
    with pytest.raises(ValueError, match="no unexpanded program"):
        slp.system_equations("4r5s:positions-receivers")
    with pytest.raises(ValueError):
        slp.system_equations("not a system")


def test_squared_program_uses_the_generators_combinations():
    """The squared system's combinations are analysis.formulations.parametric.square's (same seed, same draws)."""
    from analysis.formulations.parametric import parse_squared_name, square_combinations, squared_name

    assert parse_squared_name(squared_name("5r5s:B2,B3,C2-C5,minors(16)", 3)) == ("5r5s:B2,B3,C2-C5,minors(16)", 3)
    assert parse_squared_name("9r3s:C2-C9") is None
    c = square_combinations(16, 4, 0)
    assert c.shape == (4, 16) and np.all(c != 0) and np.all(np.abs(c) <= 9)
    np.testing.assert_array_equal(c, square_combinations(16, 4, 0))


def test_batched_tracker_matches_tracker():
    """The lock-step tape tracker and the per-path monomial tracker take the same steps to the same
    endpoints (9r/3s, one seeded network; the tape tracker's last Newton step factors at the point of
    the tangent, so a path whose corrector converged in one step may differ by a step)."""
    from solvers.generated import tdoa_9r3s_homotopy75 as module
    from solvers.synthetic import random_network

    solver = module.solver()
    assert solver.tapes is not None
    F = random_network(9, 3, np.random.default_rng(3)).measurements().reshape(1, -1)
    q = F / np.sqrt(np.mean(F ** 2))
    rk4 = tracker.TrackerOptions()  # RK4 (the monomial tracker's predictor), the default step control
    x_old, s_old = tracker.track(solver.structure, solver.segment(solver.q0[None], q), solver.x0, None, rk4)
    x_new, s_new = tape_kernel.track(solver.tapes, solver.q0, q, solver.x0, None, rk4)
    np.testing.assert_array_equal(s_new[:, 0], s_old[:, 0])
    assert np.mean(s_new[:, 1] == s_old[:, 1]) > 0.9
    ok = s_old[:, 0] == 0
    np.testing.assert_allclose(x_new[ok], x_old[ok], rtol=1e-7, atol=1e-7 * np.abs(x_old[ok]).max())
    x_chord, s_chord = tape_kernel.track(solver.tapes, solver.q0, q, solver.x0, None,
                                           dataclasses.replace(rk4, corrector="chord"))
    # the chord corrector loses a path here and there (why it is no solver's default): one of 75 on this network
    assert np.sum(s_chord[:, 0] != s_old[:, 0]) <= 1
    both = ok & (s_chord[:, 0] == 0)
    np.testing.assert_allclose(x_chord[both], x_old[both], rtol=1e-7, atol=1e-7 * np.abs(x_old[ok]).max())
    # Newton on the tape (batched LU) = Newton on the monomials (numpy solve)
    x = x_old[ok] * (1 + 1e-4)
    G = solver.segment(q, q)
    H, J, _ = tracker.evaluate(solver.structure, G, x, np.zeros(len(x)))
    expected = x - np.linalg.solve(J, H[..., None])[..., 0]
    np.testing.assert_allclose(tape_kernel.newton(solver.tapes, q, x), expected, rtol=1e-9, atol=1e-12)


def test_expanded_tape_matches_tracker_kernel():
    """A system without a program from its formulas (a user's) gets one traced from its generated
    coefficient function and monomials (evaluator "tape"); on 5r/4s it equals the monomial kernel."""
    from solvers.generated import tdoa_5r4s_homotopy152 as module
    from solvers.continuation import tracking as tk
    from solvers.methods import homotopy

    with open(os.path.join(GENERATED_DIR, module.SPEC_FILE), encoding="utf-8") as fh:
        spec = homotopy.load_spec(fh.read())
    solver = tk.HomotopySolver(spec, module.coefficients, "monomials")
    tapes = slp.homotopy_tapes(slp.expanded_equations(module.coefficients, spec["exponents"], spec["term_equation"]),
                               spec["unknowns"], spec["parameters"])
    rng = np.random.default_rng(11)
    P, N = 6, solver.nvars
    x = solver.x0[:P] * (1 + 0.1 * rng.normal(size=(P, N)))
    q1 = rng.normal(size=len(solver.q0)) + 0j
    s = rng.uniform(size=P)
    H, J, Hs = tracker.evaluate(solver.structure, solver.segment(solver.q0[None], q1[None]), x, s)
    out = tape_kernel.evaluate(tapes.full, x, s, solver.q0, q1)
    np.testing.assert_allclose(out[:, :N], H, atol=1e-12 * np.abs(H).max())
    np.testing.assert_allclose(out[:, N:N + N * N].reshape(P, N, N), J, atol=1e-12 * np.abs(J).max())
    np.testing.assert_allclose(out[:, N + N * N:], Hs, atol=1e-12 * np.abs(Hs).max())


def test_solver_takes_a_program_only_for_its_own_equations():
    """A spec whose system is labelled like a formulation but whose equations differ (here one term's
    coefficient doubled) gets no program: the tapes are checked against the generated system."""
    from solvers.generated import tdoa_9r3s_homotopy75 as module
    from solvers.continuation import tracking as tk
    from solvers.methods import homotopy

    with open(os.path.join(GENERATED_DIR, module.SPEC_FILE), encoding="utf-8") as fh:
        spec = homotopy.load_spec(fh.read())
    assert tk._tapes(spec, module.coefficients, "auto") is not None

    def other(q):
        c = module.coefficients(q)
        c[:, 0] *= 2.0
        return c

    assert tk._tapes(spec, other, "auto") is None


@pytest.mark.parametrize("label", ["5r4s", "5r5s", "4r5s"])
def test_auto_tracks_the_validated_programs(label):
    """"auto" tracks the committed minors-squared and positions solvers on their programs (validated on
    seeded networks, tables/NOTES.md); a system with minors that is not validated keeps the monomials;
    "tape" takes any program."""
    from solvers.continuation import tracking as tk
    from solvers.methods import homotopy

    module = importlib.import_module(f"solvers.generated.{MODULES[label]}")
    with open(os.path.join(GENERATED_DIR, module.SPEC_FILE), encoding="utf-8") as fh:
        spec = homotopy.load_spec(fh.read())
    assert module.SYSTEM in tk.VALIDATED_PROGRAMS
    assert module.solver().tapes is not None
    assert tk._tapes(spec, module.coefficients, "tape").full.n_instructions < 2000  # from the formulas
    if "seed 0" in spec["system"]:
        spec["system"] = spec["system"].replace("seed 0", "seed 1")  # another squaring: not validated
        assert tk._tapes(spec, module.coefficients, "auto") is None


def test_taylor_coefficients_of_a_known_path():
    """The Pade predictor's Taylor coefficients (central differences of the residual tape along the
    path's expansion) on x^2 = q0 + s dq, whose path x(s) = sqrt(q(s)) has x1 = dq / (2x),
    x2 = -dq^2 / (8x^3), x3 = dq^3 / (16x^5)."""
    tapes = slp.homotopy_tapes(lambda x, q: [x[0] * x[0] - q[0]], ["x"], ["q"])
    q0, q1 = np.array([2.0 + 1.0j]), np.array([-1.0 + 0.5j])
    dq = q1[0] - q0[0]
    s = np.array([0.0, 0.3, 0.7])
    x = np.sqrt(q0[0] + s * dq)
    x1, x2, x3 = tape_kernel.taylor(tapes, x[:, None], s, q0, q1, h=0.05)
    np.testing.assert_allclose(x1[:, 0], dq / (2 * x), rtol=1e-12)
    np.testing.assert_allclose(x2[:, 0], -dq ** 2 / (8 * x ** 3), rtol=1e-6)
    np.testing.assert_allclose(x3[:, 0], dq ** 3 / (16 * x ** 5), rtol=1e-4)


def test_pade_is_exact_on_a_pole():
    """The (2, 1) Pade approximant reproduces x(t) = c / (1 - t / a) (a pole at a), where the cubic
    Taylor polynomial does not."""
    c, a, h = 1.5 - 0.5j, 0.2 + 0.1j, 0.1
    coeff = [c / a ** k for k in range(4)]
    arr = [np.array([[z.real]]) for z in coeff] + [np.array([[z.imag]]) for z in coeff]
    xr, k1r, x2r, x3r, xi, k1i, x2i, x3i = arr
    out_r, out_i = np.zeros((1, 1)), np.zeros((1, 1))
    tape_jit._pade(xr, xi, k1r, k1i, x2r, x2i, x3r, x3i, np.array([h]), 1, out_r, out_i, 1)
    np.testing.assert_allclose(out_r[0, 0] + 1j * out_i[0, 0], c / (1 - h / a), rtol=1e-13)


def test_pade_tracker_reaches_the_same_roots():
    """The tape tracker with the Pade predictor (plain and with the retracking's tight step control)
    ends every path where RK4 does (9r/3s, one seeded network)."""
    from solvers.generated import tdoa_9r3s_homotopy75 as module
    from solvers.synthetic import random_network

    solver = module.solver()
    F = random_network(9, 3, np.random.default_rng(3)).measurements().reshape(1, -1)
    q = F / np.sqrt(np.mean(F ** 2))
    x_rk4, s_rk4 = tape_kernel.track(solver.tapes, solver.q0, q, solver.x0, None,
                                     dataclasses.replace(solver.options, predictor="rk4"))
    ok = s_rk4[:, 0] == 0
    for options in (dataclasses.replace(solver.options, predictor="pade"), tracker.TIGHT):
        x, st = tape_kernel.track(solver.tapes, solver.q0, q, solver.x0, None, options)
        assert np.all(st[ok, 0] == 0)
        np.testing.assert_allclose(x[ok], x_rk4[ok], rtol=1e-7, atol=1e-7 * np.abs(x_rk4[ok]).max())


def test_tracker_capacity_avoids_power_of_two_rows():
    """The tracker's arrays have room for every path and the compiled code's last pass of four, and an odd
    number of 64-byte cache lines per row (rows a multiple of 128 bytes apart share few of the L1 cache's sets)."""
    for M in [1, 3, 4, 63, 64, 65, 75, 152, 180, 344, 512]:
        cap = tape_kernel.capacity(M)
        assert cap >= M and cap % tape_kernel.WIDTH == 0
        assert (8 * cap) % 64 == 0 and (8 * cap // 64) % 2 == 1, (M, cap)
