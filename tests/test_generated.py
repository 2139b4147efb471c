"""Tests for the generated solvers: files up to date, coefficients exact, seeded noiseless instances solved."""
from __future__ import annotations

import importlib
import json
import os

import numpy as np
import pytest

from analysis.formulations.tdoa import Formulation, real_equations
from solvers.generate import committed_spec_text, committed_specs, emit_committed
from solvers.synthetic import random_network, true_root

SPECS = committed_specs()


def _module(label: str):
    stem = next(os.path.basename(p)[:-5] for p in SPECS if os.path.basename(p).startswith(f"tdoa_{label}_"))
    return importlib.import_module(f"solvers.generated.{stem}")


def _truth(net) -> np.ndarray:
    H, b, o = true_root(net)
    return np.concatenate([[H[0, 0], H[0, 1], H[1, 1]], b, o])


def test_pencil_solver_is_generated():
    names = [os.path.basename(p) for p in SPECS]
    assert any(n.startswith("tdoa_6r4s_") for n in names)


@pytest.mark.parametrize("json_path", SPECS, ids=[os.path.basename(p) for p in SPECS])
def test_generated_module_is_fresh_emission(json_path):
    # every committed module (pencil and homotopy), re-emitted from its committed spec by the one template
    py_path, text = emit_committed(json_path)
    with open(py_path, encoding="utf-8") as fh:
        committed = fh.read()
    assert committed == text, "generated module is stale: run python scripts/generate_solvers.py --emit-only"


@pytest.mark.parametrize("json_path", SPECS, ids=[os.path.basename(p) for p in SPECS])
def test_committed_spec_has_its_configurations_step_control(json_path):
    # the "tracker" and "retrack" fields of every committed homotopy spec are those its configuration's
    # step control (solvers.generate.STEP_CONTROL, tracker.FAMILY for squared systems) writes now
    with open(json_path, encoding="utf-8") as fh:
        committed = fh.read()
    assert committed == committed_spec_text(json_path), "run python scripts/generate_solvers.py --emit-only"


def test_committed_spec_text_writes_a_changed_step_control_only(monkeypatch):
    # a configuration's new step control goes into its spec's "tracker"/"retrack" fields; every other field and
    # the key order stay (the further start systems last, as a generation writes them)
    from solvers import generate

    path = next(p for p in SPECS if os.path.basename(p).startswith("tdoa_4r5s_homotopy"))
    with open(path, encoding="utf-8") as fh:
        before = json.load(fh)
    monkeypatch.setitem(generate.STEP_CONTROL, "4r5s", {"tracker": {"corrector": "chord"}, "retrack": {"target": 1e-4},
                                                      "starts": 3})
    after = json.loads(committed_spec_text(path))
    assert after["tracker"] == {"corrector": "chord"} and after["retrack"] == {"target": 1e-4}
    assert list(after)[-2:] == ["retrack", "starts"]
    assert {k: v for k, v in after.items() if k not in ("tracker", "retrack")} == {k: v for k, v in before.items() if k != "tracker"}


@pytest.mark.parametrize("label", ["6r4s"])
def test_factored_coefficients_equal_the_formulation(label):
    # the emitted (factored) coefficients against analysis.formulations.tdoa.real_equations, seeds 0-2
    module = _module(label)
    with open(os.path.join(os.path.dirname(module.__file__), module.SPEC_FILE), encoding="utf-8") as fh:
        spec = json.load(fh)
    form = Formulation.parse(module.SYSTEM)
    mons = [tuple(m) for m in spec["monomials"]]
    for seed in range(3):
        F = random_network(*module.CONFIG, np.random.default_rng(seed)).measurements()
        F = F / np.sqrt(np.mean(F * F))
        got = iter(module.coefficients(tuple(F.ravel().tolist())))
        for eq, terms in zip(real_equations(form, F), spec["inputs"]):
            scale = max(abs(v) for v in eq.values())
            for t in terms:
                assert abs(next(got) - eq.get(mons[t], 0.0)) <= 1e-12 * scale, (label, seed)


def _errors(module, seeds, polish=None):
    m, n = module.CONFIG
    out = []
    for seed in seeds:
        net = random_network(m, n, np.random.default_rng(seed))
        x = _truth(net)
        roots = module.solve(net.measurements()) if polish is None else module.solve(net.measurements(), polish=polish)
        assert roots.shape == (module.DEGREE, len(module.UNKNOWNS))
        out.append(np.nanmin(np.linalg.norm(roots - x, axis=1)) / np.linalg.norm(x))
    return np.array(out)


@pytest.mark.parametrize("label", ["6r4s"])
def test_known_root_among_candidates(label):
    module = _module(label)
    err = _errors(module, range(10))
    ok = int(np.sum(err < 1e-9))
    assert ok == 10, f"{label}: only {ok}/10 seeded instances (seeds 0-9) solved to 1e-9: {err}"


@pytest.mark.parametrize("label", ["6r4s"])
def test_raw_solution_is_accurate(label):
    # without Gauss-Newton polishing: pencil eigen-solution / homotopy endpoints
    module = _module(label)
    err = _errors(module, range(10), polish=0)
    assert np.median(np.log10(err)) < -11, err
    assert int(np.sum(err < 1e-6)) >= 9, err


def test_batch_agrees_with_single():
    module = _module("6r4s")
    nets = [random_network(6, 4, np.random.default_rng(s)) for s in (0, 2, 4)]
    batch = module.solve_batch(np.stack([net.measurements() for net in nets]))
    assert batch.shape == (3, module.DEGREE, len(module.UNKNOWNS))
    for net, roots in zip(nets, batch):
        x = _truth(net)
        single = module.solve(net.measurements())
        # candidate order may differ; the best candidate must agree
        e_batch = np.nanmin(np.linalg.norm(roots - x, axis=1)) / np.linalg.norm(x)
        e_single = np.nanmin(np.linalg.norm(single - x, axis=1)) / np.linalg.norm(x)
        assert e_batch < 1e-9 and e_single < 1e-9, (e_batch, e_single)


def test_wrong_shape_is_rejected():
    module = _module("6r4s")
    with pytest.raises(ValueError, match="shape"):
        module.solve(np.ones((5, 4)))


def test_polynomial_system_jacobian_matches_finite_differences():
    from solvers.runtime import PolySystem

    module = _module("6r4s")
    solver = module.solver()
    system = solver.system
    F = random_network(6, 4, np.random.default_rng(5)).measurements()
    coeffs = np.array(module.coefficients(tuple((F / np.sqrt(np.mean(F * F))).ravel().tolist())))[None]
    C = system.coefficient_matrix(coeffs).astype(complex)
    x = np.random.default_rng(1).normal(size=(1, 3, 9)) + 0.1j
    f, J = system.residual_jacobian(x, C)
    eps = 1e-6
    for v in range(9):
        dx = np.zeros(9)
        dx[v] = eps
        fp, _ = system.residual_jacobian(x + dx, C, jacobian=False)
        fm, _ = system.residual_jacobian(x - dx, C, jacobian=False)
        np.testing.assert_allclose(J[..., v], (fp - fm) / (2 * eps), rtol=1e-6, atol=1e-8)
    assert isinstance(system, PolySystem)


def test_solver_table_covers_every_committed_solver():
    """tables/solvers.csv (scripts/bench_solvers.py) has one row per committed solver, consistent with
    the modules (roots, size, method), and solvers.meta.json the provenance of every row."""
    import csv

    from solvers.api import SOLVER_ORDER
    from solvers.subsystem import SUBSYSTEMS, module_for

    tables = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tables")
    with open(os.path.join(tables, "solvers.csv"), newline="", encoding="utf-8") as fh:
        rows = {r["solver"]: r for r in csv.DictReader(fh)}
    with open(os.path.join(tables, "solvers.meta.json"), encoding="utf-8") as fh:
        provenance = json.load(fh)["rows"]
    labels = list(SOLVER_ORDER) + list(SUBSYSTEMS)
    assert list(rows) == labels, "stale: run scripts/bench_solvers.py"
    for label in labels:
        module, row = module_for(label), rows[label]
        assert int(row["basis_size"]) == module.DEGREE and row["method"] == module.METHOD, label
        paths = getattr(module, "PATHS", None) if module.METHOD == "homotopy" else None
        expected = f"{paths}x{len(module.UNKNOWNS)}" if paths else f"{module.SIZE[0]}x{module.SIZE[1]}"
        assert row["size"] == expected, label
        assert int(row["trials"]) >= 100 and row["eig_n"], label
        assert provenance[label]["commit"] and int(provenance[label]["trials"]) == int(row["trials"]), label
    # the table of docs/solvers.md is tables/solvers.md, written from the same rows
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_solvers", os.path.join(os.path.dirname(tables), "scripts", "bench_solvers.py"))
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    with open(os.path.join(tables, "solvers.md"), encoding="utf-8") as fh:
        table = fh.read()
    assert table == bench.markdown(list(rows.values())), "stale: run scripts/bench_solvers.py"
    with open(os.path.join(os.path.dirname(tables), bench.DOCS_PAGE), encoding="utf-8") as fh:
        assert "".join(bench.README_MARKERS[:1]) + table + bench.README_MARKERS[1] in fh.read(), "docs table is stale"


def test_a_user_systems_module_speaks_of_its_own_system():
    """Issue 46: a solver for a parametric system without a TDOA configuration documents solve(q) with its
    parameters, and neither solve(F) nor the TDOA helpers (the committed 3r/3s TOA spec, its configuration
    taken away, stands for a user's system)."""
    from solvers.codegen import emit_module

    path = next(p for p in SPECS if os.path.basename(p) == "tdoa_3r3stoa_homotopy8.json")
    with open(path, encoding="utf-8") as fh:
        spec = json.load(fh)
    spec.pop("config")
    text = emit_module(json.dumps(spec), "mine.json", "def coefficients(q):\n    return q\n", "tdoa-workbench generate")
    doc = text.split('"""')[1]
    assert f"solve(q) -> (8, {len(spec['unknowns'])})" in doc and ", ".join(spec["parameters"]) in doc
    assert "solve(F)" not in doc and "TDOA" not in doc and "calibrations" not in text
    assert "def solve(q):" in text and "def solve_batch(q):" in text
