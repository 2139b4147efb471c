"""Tests for the action-matrix method (solvers/methods/action_matrix.py): the composition of the
equations with the kernel of the linear ones (floats against GF(p), against direct evaluation), the
template built over GF(p) for 2D TOA 3r/3s, and the committed solver on seeded room networks."""
from __future__ import annotations

import importlib
import os

import numpy as np
import pytest

from solvers import api
from solvers.continuation import tracking
from solvers.generate import GENERATED_DIR, solver_system
from solvers.methods import action_matrix as am
from solvers.synthetic import ROOM, room_network, true_root


def _random_system(rng, n=4, k=2, terms=12, degree=3):
    exps = np.array([rng.multinomial(int(rng.integers(0, degree + 1)), [1 / n] * n) for _ in range(terms)])
    term_eq = rng.integers(0, 2, size=terms)
    term_eq[:2] = [0, 1]
    return exps, term_eq


def test_composition_equals_evaluation_at_points():
    rng = np.random.default_rng(3)
    exps, term_eq = _random_system(rng)
    composer = am.Composer(exps, term_eq, 2, 2)
    c = rng.normal(size=len(exps))
    M = np.zeros((5, 3))
    M[0, 0] = 1.0
    M[1:, :] = rng.normal(size=(4, 3))
    G = composer.compose(c, M)
    for _ in range(5):
        y = rng.normal(size=2)
        x = M[1:, 0] + M[1:, 1:] @ y
        direct = [sum(ci * np.prod(x ** e) for ci, e, q in zip(c, exps, term_eq) if q == eq) for eq in (0, 1)]
        via = G @ np.array([np.prod(y ** np.array(m)) for m in composer.monomials])
        assert np.allclose(direct, via, rtol=1e-12, atol=1e-12)


def test_composition_mod_p_agrees_with_exact_integers():
    rng = np.random.default_rng(4)
    exps, term_eq = _random_system(rng)
    composer = am.Composer(exps, term_eq, 2, 2)
    p = 65521
    c = rng.integers(-5, 6, size=len(exps))
    M = rng.integers(-3, 4, size=(5, 3))
    M[0] = [1, 0, 0]
    exact = composer.compose(c.astype(float), M.astype(float))  # small integers: exact in float64
    assert np.array_equal(composer.compose(c % p, M % p, p), np.round(exact).astype(np.int64) % p)


def test_template_of_2d_toa_3r3s():
    system = solver_system("3r3stoa")
    spec = am.build(system, 8)
    tpl = spec["template"]
    # 8 roots plus one on det H = 0 (H = 0, b fixed by the linear equations) in the standard basis
    assert len(tpl["basis"]) == 9 and spec["saturation"] == "dropped"
    rows, cols = tpl["size"]
    assert cols == len(tpl["excess"]) + len(tpl["reducible"]) + len(tpl["basis"])
    # only independent excess columns are kept, and the pruned rows make [E R] square: one LU solve online
    assert tpl["rank_excess"] == len(tpl["excess"]) and rows == len(tpl["excess"]) + len(tpl["reducible"])
    with pytest.raises(am.ActionMatrixError, match="saturated count 8"):
        am.build(system, 7)


def test_3d_toa_is_refused_with_its_reason():
    # the 38 roots are counted in the eliminated coordinates, but the unsaturated ideal has a
    # positive-dimensional part (rank H <= 1): no template of this kind (docs/action-matrix.md)
    with pytest.raises(am.ActionMatrixError, match="not zero-dimensional"):
        am.build(solver_system("6r4s3dtoa"), 38)


def _module(method_tag):
    stem = next(f[:-3] for f in sorted(os.listdir(GENERATED_DIR)) if f.startswith(f"tdoa_3r3stoa_{method_tag}")
                and f.endswith(".py"))
    return importlib.import_module(f"solvers.generated.{stem}")


def test_committed_solver_finds_the_true_root():
    module = _module("action")
    assert module.METHOD == "action-matrix" and module.DEGREE == 8
    found = 0
    for seed in range(40):
        net = room_network(3, 3, np.random.default_rng(seed), room=ROOM[:2], offset_sigma=0.0)
        H, b = true_root(net)[:2]
        truth = np.concatenate([H[np.triu_indices(2)], b])
        roots = module.solve(net.measurements())
        assert roots.shape == (8, 5)
        found += np.nanmin(np.linalg.norm(roots - truth, axis=1)) <= 1e-6 * np.linalg.norm(truth)
    assert found >= 39, found


def test_solver_agrees_with_the_homotopy():
    # the same real roots as the committed homotopy on one network (distinct roots, compared as sets)
    net = room_network(3, 3, np.random.default_rng(7), room=ROOM[:2], offset_sigma=0.0)
    F = net.measurements()
    a, h = _module("action").solve(F), _module("homotopy").solve(F)
    for x in h[np.all(np.isfinite(h), axis=1)]:
        assert np.min(np.linalg.norm(a - x, axis=1)) <= 1e-7 * np.linalg.norm(x)


def test_api_runs_the_preferred_method():
    assert api._module_for("3r3stoa").METHOD == "homotopy"  # faster and as reliable (PREFERRED_METHOD)
    assert api._module_for("3r3stoa", "action-matrix").METHOD == "action-matrix"
    with pytest.raises(ValueError, match="unknown method"):
        api._module_for("3r3stoa", "qr")


def test_spec_format_is_checked():
    with pytest.raises(am.ActionMatrixError, match="format"):
        am.load_spec('{"format": "tdoa-homotopy/1"}')
    assert tracking.coefficient_source(am.extended_system(solver_system("3r3stoa"))).startswith("def coefficients")
