"""Tests for analysis.formulations.positions (positions formulations) and analysis.sweeps.minimal (their root counts).

They check mathematics: known roots vanish (GF(p) and real), every variant's equations are the stated
multiples of the original range residuals at arbitrary points (so the eliminations are right), the
sympy expressions agree with the fast GF(p) path, the sign group maps roots to roots, and a small
degree computation agrees across two primes.
"""
from __future__ import annotations

import os

import numpy as np
import pytest
import sympy

from analysis.engine.degree import DEFAULT_PRIMES
from analysis.formulations.tdoa import data_symbols, TDOAConfig
from analysis.sweeps.minimal import Subsystem, count, count_instance
from analysis.formulations.positions import (
    ORBIT_VARIANTS,
    VARIANTS,
    apply_sign,
    evaluate_gf,
    evaluate_real,
    gf_system,
    network_from_root,
    positions_system,
    sample_gf_positions,
    sample_real_positions,
)

P = 65521
CONFIGS = [(4, 5), (4, 6), (6, 3), (5, 4)]
CASES = [(m, n, v) for m, n in CONFIGS for v in VARIANTS]


@pytest.mark.parametrize("m,n,variant", CASES)
def test_known_root_vanishes_gf(m, n, variant):
    system = positions_system(m, n, variant)
    F, root = sample_gf_positions(m, n, P, 3, variant)
    values, sat = evaluate_gf(system, F, root, P)
    assert values == [0] * system.n_equations
    assert all(sat), "saturating polynomials must be nonzero at the known root"
    eqs, _ = gf_system(system, F, P)
    assert all(e.evaluate(root) == 0 for e in eqs)


@pytest.mark.parametrize("m,n,variant", CASES)
def test_known_root_vanishes_real_and_network_recovered(m, n, variant):
    system = positions_system(m, n, variant)
    F, root = sample_real_positions(m, n, 5, variant)
    _, rel = evaluate_real(system, F, root)
    assert rel.max() < 1e-12
    rec, tra, offs = network_from_root(system, root, F)
    assert rec[0].tolist() == [0.0, 0.0] and rec[1, 1] == 0.0 and rec[1, 0] > 0
    D = np.linalg.norm(rec[:, None, :] - tra[None, :, :], axis=2)
    assert np.abs(D + offs[None, :] - F).max() < 1e-9


def test_data_names_match_paper_formulation():
    system = positions_system(4, 5, "receivers")
    expected = [str(s) for row in data_symbols(TDOAConfig(4, 5)) for s in row]
    assert list(system.parameters) == expected


def _residuals(F, rec, tra, offs):
    """Original range residuals: R_j (receiver 1) and L_ij = rho_ij - rho_1j, rho_ij = (f_ij - o_j)^2 - |r_i - s_j|^2."""
    diff = rec[:, None, :] - tra[None, :, :]
    rho = (F - offs[None, :]) ** 2 - (diff[..., 0] ** 2 + diff[..., 1] ** 2)
    return rho[0], rho - rho[0][None, :]


def _multipliers(system, value, F, rec, tra):
    """Expected value of each equation as (factor, residual) from the derivation in the module docstring."""
    m, n, var = system.m, system.n, system.variant
    R, L = value["R"], value["L"]
    delta = F - F[0][None, :]
    out = {}
    for j in range(n):
        A = np.column_stack([rec[1:4, 0], rec[1:4, 1], -delta[1:4, j]]) if m >= 4 else None
        if var == "full":
            out[f"R{j + 1}"] = R[j]
            for i in range(1, m):
                out[f"L{i + 1}_{j + 1}"] = L[i, j]
        elif var == "transmitters":
            out[f"T{j + 1}"] = 4 * delta[1, j] ** 2 * R[j]
            for i in range(2, m):
                out[f"E{i + 1}_{j + 1}"] = delta[1, j] * L[i, j]
        elif var == "offsets":
            x2y3 = rec[1, 0] * rec[2, 1]
            out[f"P{j + 1}"] = 4 * x2y3**2 * R[j]
            for i in range(3, m):
                out[f"K{i + 1}_{j + 1}"] = x2y3 * L[i, j]
        elif var in ("receivers", "receivers-orbits"):
            D = np.linalg.det(A)
            if var == "receivers":
                out[f"Q{j + 1}"] = 4 * D**2 * R[j]
                for i in range(4, m):
                    out[f"G{i + 1}_{j + 1}"] = D * L[i, j]
            else:
                x2, y3 = rec[1, 0], rec[2, 1]
                Dt = D / (x2 * y3)
                out[f"W{j + 1}"] = 4 * Dt**2 * x2**2 * y3**2 * R[j]
                for i in range(4, m):
                    out[f"V{i + 1}_{j + 1}"] = Dt * L[i, j]
    if var in ("dual", "dual-orbits"):
        # positions in the dual gauge (s_1 on the x axis): rotate s_1 back onto the x axis
        w = tra[0]
        Q = np.array([[w[0], w[1]], [-w[1], w[0]]]) / np.hypot(*w)
        t = tra @ Q.T
        Pdet = np.linalg.det(np.column_stack([t[1] - t[0], t[2] - t[0]]))
        Ph = Pdet / (t[0, 0] * t[1, 1]) if var == "dual-orbits" else Pdet  # H is divided by u1 v2, J is not
        for j in range(n):
            out[f"R{j + 1}"] = R[j]
        for i in range(1, m):
            out[f"J{i + 1}"] = 4 * Pdet**2 * L[i, 0]
            for j in range(3, n):
                out[f"H{i + 1}_{j + 1}"] = Ph * (L[i, j] - L[i, 0])
    return out


@pytest.mark.parametrize("m,n,variant", CASES)
def test_equations_are_multiples_of_range_residuals(m, n, variant):
    """At an arbitrary point (not a root, inconsistent data), each equation equals the derivation's
    factor times the original residual of the network recovered by the linear eliminations."""
    system = positions_system(m, n, variant)
    rng = np.random.default_rng(11)
    F = rng.normal(5, 2, size=(m, n))
    point = rng.normal(0, 1, size=system.n_unknowns)
    for name in ("X", "Y", "U", "V"):  # squares: positive for a real representative
        if name in system.unknowns:
            point[system.unknown_index(name)] = abs(point[system.unknown_index(name)]) + 0.5
    rec, tra, offs = network_from_root(system, point, F)
    R, L = _residuals(F, rec, tra, offs)
    expected = _multipliers(system, {"R": R, "L": L}, F, rec, tra)
    values, _ = evaluate_real(system, F, point)
    got = dict(zip(system.equation_names, values))
    assert set(expected) == set(got)
    for name, val in got.items():
        assert val == pytest.approx(expected[name], rel=1e-8, abs=1e-8), name


@pytest.mark.parametrize("variant", ["full", "offsets", "dual-orbits"])
def test_sympy_expressions_agree_with_gf_path(variant):
    system = positions_system(4, 5, variant)
    rng = np.random.default_rng(2)
    F = rng.integers(0, P, size=(4, 5))
    point = rng.integers(0, P, size=system.n_unknowns)
    fast, fast_sat = evaluate_gf(system, F, point, P)
    subs = {sympy.Symbol(u): int(x) for u, x in zip(system.unknowns, point)}
    subs.update({sympy.Symbol(f): int(x) for f, x in zip(system.parameters, F.ravel())})
    slow = [int(e.xreplace(subs)) % P for e in system.equations]
    slow_sat = [int(e.xreplace(subs)) % P for e in system.saturate_by]
    assert slow == fast and slow_sat == fast_sat


@pytest.mark.parametrize("m,n,variant", [(m, n, v) for m, n in CONFIGS for v in VARIANTS if v not in ORBIT_VARIANTS])
def test_sign_group_maps_roots_to_roots(m, n, variant):
    system = positions_system(m, n, variant)
    assert len(system.sign_group) == 4 and system.sign_group[0] == (1,) * system.n_unknowns
    F, root = sample_gf_positions(m, n, P, 4, variant)
    for sign in system.sign_group:
        values, _ = evaluate_gf(system, F, apply_sign(root, sign, P), P)
        assert values == [0] * system.n_equations
    Fr, rr = sample_real_positions(m, n, 4, variant)
    for sign in system.sign_group[1:]:
        _, rel = evaluate_real(system, Fr, apply_sign(rr, sign))
        assert rel.max() < 1e-12


def test_bad_arguments():
    with pytest.raises(ValueError, match="valid"):
        positions_system(4, 5, "nope")
    with pytest.raises(ValueError, match="m >= 4"):
        positions_system(3, 6, "receivers")
    with pytest.raises(ValueError, match="n >= 3"):
        positions_system(9, 2, "dual")


def test_4r6s_full_system_keeps_only_the_true_network_two_primes():
    rec = count((4, 6, "receivers-orbits"), primes=DEFAULT_PRIMES, seeds=(0,), check_simple=False)
    assert (rec.status, rec.degree, rec.dimension, rec.instance_degrees) == ("ok", 1, 0, (1, 1))
    inst = count_instance(positions_system(4, 6, "receivers"), DEFAULT_PRIMES[0], 1, check_simple=False)
    assert (inst.degree, inst.free_action, inst.root_ok) == (4, True, True)  # one orbit of the sign group


def test_4r5s_orbit_count_two_primes():
    """The minimal 4r/5s: 344 geometric solutions (tables/minimal_problems.md), on two primes."""
    rec = count((4, 5, "receivers-orbits"), primes=DEFAULT_PRIMES, seeds=(0,), check_simple=False)
    assert (rec.degree, rec.orbits, rec.instance_degrees) == (344, 344, (344, 344))


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("TDOA_SLOW_TESTS"), reason="~10-40 s; set TDOA_SLOW_TESTS=1 (the number is in "
                    "tables/minimal_counts.csv)")
def test_6r3s_dual_orbits_matches_paper_two_primes():
    """Positions (receivers eliminated, orbit chart) against the paper's 181 - 1 spurious = 180."""
    rec = count((6, 3, "dual-orbits"), primes=DEFAULT_PRIMES, seeds=(0,), check_simple=False)
    assert (rec.degree, rec.orbits, rec.instance_degrees) == (180, 180, (180, 180))


def test_random_subsystem_is_a_combination():
    from analysis.sweeps.minimal import _select

    system = positions_system(4, 6, "receivers-orbits")
    F, _ = sample_gf_positions(4, 6, P, 0, system.variant)
    eqs, _ = gf_system(system, F, P)
    sub, names = _select(system, eqs, Subsystem("random", tuple(f"W{j}" for j in range(1, 7)), 5), 0)
    assert names == [f"comb{k}" for k in range(1, 6)] and all(s not in eqs for s in sub)
