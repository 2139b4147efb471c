"""TOA beside TDOA and 3D: configurations, the K-dimensional builder, known roots, degrees (analysis.formulations.kd,
analysis.sweeps.cell_degrees) checked against an independent sympy construction and sympy's groebner over GF(p)."""
from __future__ import annotations

import dataclasses
import math
import multiprocessing

import numpy as np
import pytest
import sympy

import analysis.sweeps.cell_degrees as cell_degrees
from analysis.sweeps.cell_degrees import cell_degree, cell_degree_capped, write_table
from analysis.formulations.tdoa import (Formulation, InconsistentSample, TDOAConfig, canonical_form, check_root,
                                   equation_names, evaluate_gf, gf_equations, parse_equations, real_equations,
                                   sample_gf_instance, sample_real_instance)
from analysis.formulations.kd import build_equations, det_h_terms, solve_mod

P = 65521

NEW_CONFIGS = ["3r3s-toa2d", "4r4s-toa2d", "4r6s-toa3d", "6r4s-toa3d", "5r5s-toa3d", "6r6s-tdoa3d", "10r4s-tdoa3d",
               "7r6s-tdoa3d", "5r3s-tdoa2d-direct", "3r3s-toa2d-direct", "4r6s-toa3d-direct", "6r6s-tdoa3d-direct",
               "3r3s-toa2d-gram", "4r6s-toa3d-gram", "5r5s-toa3d-gram", "6r4s-toa3d-gram"]


# ---------------------------------------------------------------------------------------------- configurations


def test_default_config_is_the_papers_and_keeps_its_label():
    config = TDOAConfig(6, 4)
    assert (config.model, config.dim, config.parametrization) == ("tdoa", 2, "compaction")
    assert config.label == "6r4s" and config.is_planar_tdoa
    assert config.unknowns == ("h11", "h12", "h22", "b1", "b2", "o1", "o2", "o3", "o4")
    assert TDOAConfig.parse("6r4s") == config == TDOAConfig.parse("6r4s-tdoa2d")


@pytest.mark.parametrize("label", NEW_CONFIGS)
def test_label_roundtrip(label):
    config = TDOAConfig.parse(label)
    assert config.label == label
    assert TDOAConfig.parse(config.label) == config
    formulation = Formulation.from_spec(config, "all")
    assert Formulation.parse(formulation.label) == formulation


def test_unknowns_and_degrees_of_freedom():
    toa3 = TDOAConfig(4, 6, model="toa", dim=3)
    assert toa3.unknowns == ("h11", "h12", "h13", "h22", "h23", "h33", "b1", "b2", "b3")
    assert toa3.degrees_of_freedom == 24 and toa3.excess == 0
    tdoa3 = TDOAConfig(6, 6, dim=3)
    assert tdoa3.n_unknowns == 9 + 6 and tdoa3.excess == 0
    assert tdoa3.n_minors == math.comb(5, 4) * math.comb(5, 4)
    direct = TDOAConfig(4, 6, model="toa", dim=3, parametrization="direct")
    # r2x; r3x r3y; r4xyz; six transmitters: 3 m - 6 + 3 n
    assert direct.unknowns[:6] == ("r2x", "r3x", "r3y", "r4x", "r4y", "r4z")
    assert direct.n_unknowns == 3 * 4 - 6 + 3 * 6 and direct.gauge_group_order == 8
    assert TDOAConfig(6, 3, parametrization="direct").n_unknowns == 2 * 6 - 3 + 2 * 3 + 3


@pytest.mark.parametrize("kwargs, fragment", [
    (dict(dim=4), "unsupported dimension 4; valid: 2, 3"),
    (dict(model="foo"), "unknown model 'foo'; valid: tdoa, toa"),
    (dict(parametrization="bar"), "unknown parametrization 'bar'"),
    (dict(dim=3, m=4), "m (receivers) must be >= 5 for tdoa compaction in 3D"),
    (dict(model="toa", dim=3, n=3), "n (transmitters) must be >= 4 for toa compaction in 3D"),
])
def test_config_errors(kwargs, fragment):
    args = dict(m=6, n=6) | kwargs
    with pytest.raises(ValueError) as err:
        TDOAConfig(**args)
    assert fragment in str(err.value)


def test_parse_conflicts_and_keywords():
    assert TDOAConfig.parse("4r6s", model="toa", dim=3) == TDOAConfig(4, 6, "toa", 3)
    with pytest.raises(ValueError, match="says dim 3, but 2 was asked for"):
        TDOAConfig.parse("4r6s-toa3d", dim=2)


def test_equation_names_per_model():
    assert equation_names(TDOAConfig(3, 5, model="toa")) == ("A", "B2", "B3", "B4", "B5", "C2", "C3")
    names = equation_names(TDOAConfig(6, 6, dim=3))
    assert names[:11] == ("A", "B2", "B3", "B4", "B5", "B6", "C2", "C3", "C4", "C5", "C6")
    assert names[11] == "M1234_1234" and len(names) == 11 + 25
    assert equation_names(TDOAConfig(6, 6))[:3] == ("A", "B2", "B3")  # the paper's 2D family: no B4..Bn
    assert equation_names(TDOAConfig(2, 2, model="toa", parametrization="direct")) == ("D1_1", "D1_2", "D2_1", "D2_2")
    assert parse_equations(TDOAConfig(6, 6, dim=3), "B*,C2-C3") == ("B2", "B3", "B4", "B5", "B6", "C2", "C3")
    with pytest.raises(ValueError, match="TOA's rank constraints involve only the data"):
        parse_equations(TDOAConfig(5, 5, model="toa", dim=3), "minors")


def test_planar_only_functions_refuse_other_models():
    with pytest.raises(ValueError, match="supports the paper's 2D TDOA formulation only, not 6r6s-tdoa3d"):
        canonical_form(Formulation.from_spec(TDOAConfig(6, 6, dim=3), "C*"))


# ---------------------------------------------------------------------------------------------- equations and roots


@pytest.mark.parametrize("label", NEW_CONFIGS)
@pytest.mark.parametrize("seed", [0, 1])
def test_known_root_vanishes_over_gf_and_reals(label, seed):
    formulation = Formulation.from_spec(label, "all")
    instance = sample_gf_instance(formulation.config, P, seed)
    check_root(formulation, instance)  # raises InconsistentSample otherwise
    assert len(instance.receivers[0]) == formulation.config.dim
    real = sample_real_instance(formulation.config, np.random.default_rng(seed))
    check_root(formulation, real)


def test_check_root_detects_a_wrong_root():
    formulation = Formulation.from_spec("6r6s-tdoa3d", "all")
    instance = sample_gf_instance(formulation.config, P, 3)
    wrong = instance.root[:-1] + ((instance.root[-1] + 1) % P,)
    bad = type(instance)(instance.config, P, instance.F, instance.receivers, instance.transmitters, instance.offsets,
                         wrong)
    with pytest.raises(InconsistentSample):
        check_root(formulation, bad)


def test_gauge_frame_of_instances():
    for config in (TDOAConfig(6, 6, dim=3, parametrization="direct"), TDOAConfig(5, 5, model="toa", dim=3)):
        real = sample_real_instance(config, np.random.default_rng(4))
        rec = np.array(real.receivers)
        assert np.all(rec[0] == 0) and np.all(rec[1, 1:] == 0) and rec[2, 2] == 0
        F = np.linalg.norm(rec[:, None] - np.array(real.transmitters)[None], axis=2) + np.array(real.offsets)
        np.testing.assert_allclose(F, np.array(real.F), rtol=1e-12)


@pytest.mark.parametrize("label", ["6r4s", "5r5s", "9r3s"])
def test_kd_builder_equals_the_planar_builder(label):
    formulation = Formulation.from_spec(label, "all")
    instance = sample_gf_instance(formulation.config, P, 2)
    rows = [list(r) for r in instance.F]
    assert build_equations(formulation, rows, P) == gf_equations(formulation, instance)


def _reference_equations(formulation: Formulation, F, p: int) -> list[dict]:
    """The compaction equations written with sympy matrices (adjugate, det, inverse) from the paper's formulas
    (Section 2.1 in K dimensions), at numeric data, reduced mod p: independent of the sparse builder."""
    config = formulation.config
    k, m, n = config.dim, config.m, config.n
    syms = sympy.symbols(config.unknowns)
    by_name = dict(zip(config.unknowns, syms))
    H = sympy.Matrix(k, k, lambda a, c: by_name[f"h{min(a, c) + 1}{max(a, c) + 1}"])
    b = sympy.Matrix([by_name[f"b{a + 1}"] for a in range(k)])
    o = [by_name.get(f"o{j}", 0) for j in range(1, n + 1)]
    d2 = sympy.Matrix(m, n, lambda i, j: (sympy.Integer(F[i][j]) - o[j]) ** 2)
    D = sympy.Matrix(m - 1, n - 1, lambda i, j: d2[i + 1, j + 1] - d2[0, j + 1] - d2[i + 1, 0] + d2[0, 0])
    Dhat = D[:, :k]
    adj, det = H.adjugate(), H.det()
    out = []
    for name in formulation.equations:
        if name == "A":
            expr = d2[0, 0] * det - (b.T * adj * b)[0, 0]
        elif name[0] == "B":
            j = int(name[1:])
            # S~ = D~[:K, :K]^{-1} D~[:K, :]: the identity for j <= K + 1, rational in the offsets beyond (TDOA)
            s = sympy.eye(k)[:, j - 2] if j <= k + 1 else Dhat[:k, :].inv() * D[:k, j - 2]
            expr = (d2[0, int(name[1:]) - 1] - d2[0, 0]) * det - (s.T * adj * s)[0, 0] / 4 + (b.T * adj * s)[0, 0]
            if config.model == "tdoa" and int(name[1:]) > k + 1:  # cleared of its denominator det(D~[:K, :K])^2
                expr = sympy.cancel(sympy.together(expr) * Dhat[:k, :].det() ** 2)
        elif name[0] == "C":
            i = int(name[1:])
            r = Dhat[i - 2, :].T
            expr = d2[i - 1, 0] - d2[0, 0] - ((r.T * H * r)[0, 0] - 2 * (b.T * r)[0, 0])
        else:
            rows, cols = name[1:].split("_")
            expr = D.extract([int(x) - 1 for x in rows], [int(x) - 1 for x in cols]).det(method="berkowitz")
        poly = sympy.Poly(sympy.expand(expr), *syms)
        terms = {}
        for monom, coeff in poly.terms():
            coeff = sympy.Rational(coeff)
            value = int(coeff.p) * pow(int(coeff.q), -1, p) % p
            if value:
                terms[monom] = value
        out.append(terms)
    return out


@pytest.mark.parametrize("label, spec", [("4r5s-toa3d", "all"), ("3r4s-toa2d", "all"),
                                         ("6r5s-tdoa3d", "A,B2-B4,C2,C6,M1234_1234,M2345_1234"),
                                         pytest.param("6r5s-tdoa3d", "B5", marks=pytest.mark.slow)])
def test_builder_matches_a_sympy_reference(label, spec):
    formulation = Formulation.from_spec(label, spec)
    instance = sample_gf_instance(formulation.config, P, 5)
    assert gf_equations(formulation, instance) == _reference_equations(formulation, instance.F, P)


def test_real_equations_match_gf_shape():
    formulation = Formulation.from_spec("5r5s-toa3d", "all")
    instance = sample_real_instance(formulation.config, np.random.default_rng(0))
    polys = real_equations(formulation, instance)
    assert len(polys) == formulation.n_equations and all(polys)


def test_solve_mod_and_det_h():
    a = [[2, 1, 0], [0, 3, 1], [1, 0, 1]]
    x = solve_mod(a, [[1], [2], [3]], P)
    assert [sum(a[i][q] * x[q][0] for q in range(3)) % P for i in range(3)] == [1, 2, 3]
    assert solve_mod([[1, 2], [2, 4]], [[1], [1]], P) is None
    det = det_h_terms(TDOAConfig(4, 6, model="toa", dim=3))
    h = sympy.symbols("h11 h12 h13 h22 h23 h33 b1 b2 b3")
    H = sympy.Matrix([[h[0], h[1], h[2]], [h[1], h[3], h[4]], [h[2], h[4], h[5]]])
    assert det == {tuple(mon): int(c) for mon, c in sympy.Poly(H.det(), *h).terms()}


# ---------------------------------------------------------------------------------------------- degrees


def _sympy_degree(polys_terms: list[dict], nvars: int, p: int) -> int:
    """Number of standard monomials of sympy's grevlex Gröbner basis over GF(p) (zero-dimensional only)."""
    xs = sympy.symbols(f"x0:{nvars}")
    exprs = [sum(c * sympy.prod([x ** e for x, e in zip(xs, exp)]) for exp, c in t.items()) for t in polys_terms]
    gb = sympy.groebner(exprs, *xs, modulus=p, order="grevlex")
    assert gb.is_zero_dimensional
    leads = [sympy.Poly(g, *xs).monoms(order="grevlex")[0] for g in gb.exprs]

    def standard(mon) -> bool:
        return not any(all(a >= b for a, b in zip(mon, lm)) for lm in leads)

    # the standard monomials form an order ideal: grow each one from 1 by raising variables k >= the last raised
    count, stack = 0, [((0,) * nvars, 0)]
    while stack:
        mon, first = stack.pop()
        count += 1
        for k in range(first, nvars):
            up = mon[:k] + (mon[k] + 1,) + mon[k + 1:]
            if standard(up):
                stack.append((up, k))
    return count


@pytest.mark.parametrize("label, expected_vars", [("3r3s-toa2d:all", 6), ("3r3s-toa2d-direct:all", 9)])
def test_degree_agrees_with_sympy_groebner(label, expected_vars):
    formulation = Formulation.parse(label)
    record = cell_degree(formulation)
    system, _ = cell_degrees.formulation_system(formulation)
    polys = system(P)
    assert polys[0].ring.nvars == expected_vars
    assert record.status == "ok"
    assert _sympy_degree([dict(f.terms()) for f in polys], expected_vars, P) == record.degree


def test_direct_degree_is_the_gauge_group_times_the_compaction_count():
    compaction = cell_degree("3r3s-toa2d:all")
    direct = cell_degree("3r3s-toa2d-direct:all")
    assert direct.degree == 4 * compaction.degree and direct.up_to_gauge == compaction.up_to_gauge


@pytest.mark.parametrize("compaction, gram", [
    ("3r3s-toa2d:all", "3r3s-toa2d-gram:all"),
    ("4r6s-toa3d:all", "4r6s-toa3d-gram:all"),
    ("5r5s-toa3d:A,B2,B3,B4,B5,C2-C5", "5r5s-toa3d-gram:S1-S5,E5_1,E5_2,E5_3,E5_4"),
    ("6r4s-toa3d:all", "6r4s-toa3d-gram:all")])
def test_gram_degree_is_the_compaction_count(compaction, gram):
    """The Gram parametrization (TOA: G = R R^T of r_2..r_{K+1}, coordinates of the further receivers in that
    basis; invariant under the Euclidean group) counts the same networks as the compaction one, 8 / 38 / 42 /
    38, each with its known root checked; 5r/5s leaves out f5_5 in both."""
    a, b = cell_degree(compaction), cell_degree(gram)
    assert a.status == b.status == "ok" and a.tangent_dim == b.tangent_dim == 0  # the known root is isolated
    assert b.degree == a.degree and b.up_to_gauge == a.up_to_gauge


def test_gram_parametrization_is_for_toa_with_k_plus_1_receivers():
    config = TDOAConfig.parse("5r5s-toa3d-gram")
    assert config.unknowns == ("g11", "g12", "g13", "g22", "g23", "g33", "a5_1", "a5_2", "a5_3")
    assert config.gauge_group_order == 1
    assert equation_names(config)[:5] == ("S1", "S2", "S3", "S4", "S5") and equation_names(config)[5] == "E5_1"
    with pytest.raises(ValueError, match="gram parametrization is for TOA"):
        TDOAConfig(6, 6, dim=3, parametrization="gram")
    with pytest.raises(ValueError, match="m \\(receivers\\) must be >= 4"):
        TDOAConfig(3, 6, model="toa", dim=3, parametrization="gram")
    with pytest.raises(ValueError, match=r"valid names for 4r6s-toa3d-gram: S1..S6 .*groups: all, S\*; "):
        Formulation.parse("4r6s-toa3d-gram:E5_1")


def test_underdetermined_cell_is_positive_dimensional_without_a_groebner_basis():
    record = cell_degree("4r5s-toa3d:all")
    assert record.status == "positive-dimensional" and record.tangent_dim == 1 and record.degree is None


@pytest.mark.slow
def test_toa_3d_minimal_counts_and_direct_cross_check():
    """The minimal 3D TOA cells: 38 networks for 4r/6s and 6r/4s, 42 for 5r/5s (Kuang, Burgess, Torstensson,
    Åström, ICASSP 2013); the direct parametrization counts each network 2^3 times."""
    counts = {label: cell_degree(f"{label}:all").up_to_gauge for label in ("4r6s-toa3d", "6r4s-toa3d", "5r5s-toa3d")}
    assert counts["4r6s-toa3d"] == counts["6r4s-toa3d"] == 38  # TOA is symmetric in receivers and transmitters
    assert counts["5r5s-toa3d"] == 42
    direct = cell_degree("4r6s-toa3d-direct:all", max_cells=100_000_000)
    assert direct.degree == 8 * counts["4r6s-toa3d"]


def _never_finishes(*args, **kwargs):
    multiprocessing.Event().wait()


def test_capped_run_lists_a_formulation_that_runs_out_of_time(monkeypatch):
    monkeypatch.setattr(cell_degrees, "cell_degree", _never_finishes)  # inherited by the forked child
    record = cell_degree_capped("3r3s-toa2d:all", 0.5)
    assert record.status == "timeout" and "0.5 s wall-time cap" in record.note and record.degree is None


def test_capped_run_returns_the_childs_record():
    record = cell_degree_capped("3r4s-toa2d:all", 600)
    assert record.status == "ok" and record.degree == cell_degree("3r4s-toa2d:all").degree


def test_write_table_is_plain_text_with_regenerate_line(tmp_path):
    records = [cell_degree("3r3s-toa2d:all"), cell_degree("4r5s-toa3d:all")]
    paths = write_table(records, str(tmp_path), "t", "title", "python scripts/x.py", {"commit": "abc"})
    csv_text = open(paths[0]).read().splitlines()
    assert csv_text[0].startswith("formulation,config,model,dim")
    assert csv_text[1].startswith('"3r3s-toa2d:A,B2,B3,C2-C3",3r3s-toa2d,toa,2,compaction,3,3,0,5,5,ok,8,8,1,0,')
    md = open(paths[1]).read()
    assert md.startswith("<!-- # Regenerate: python scripts/x.py") and "| 3 | 8 |" in md
    assert '"commit": "abc"' in open(paths[2]).read()


def test_committed_table3d_records_round_trip_and_take_evidence(tmp_path):
    """scripts/table3d.py --reuse: the committed CSV read back and written again is byte-identical; a cell
    without a certified count shows the evidence given for it, a certified one keeps its count."""
    import os

    source = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tables", "table3d.csv")
    records = cell_degrees.read_records(source)
    evidence = {("tdoa", 3, 10, 4): "6148 (monodromy, 2 seeds, not certified)", ("tdoa", 3, 7, 6): "99 (wrong)"}
    paths = write_table(records, str(tmp_path), "table3d", "title", "python scripts/table3d.py", {"commit": "abc"},
                        evidence=evidence)
    assert open(paths[0]).read() == open(source).read()
    md = open(paths[1]).read()
    assert "| 10 | 6148 (monodromy, 2 seeds, not certified) | 1 |" in md
    assert "| 7 |  | cap | 1 | 1 |" in md and "99 (wrong)" not in md  # 7r/6s has its GF(p) count 1


def test_gf_evaluation_of_saturated_system_at_root():
    system, root = cell_degrees.formulation_system(Formulation.from_spec("6r6s-tdoa3d", "all"))
    polys = system(P)
    assert polys[-1].ring.variables[-1] == cell_degrees.SATURATION_VARIABLE
    assert all(evaluate_gf(dict(f.terms()), root(P), P) == 0 for f in polys)


# ---------------------------------------------------------------------------------------------- command line and networks


def test_cli_degree_toa_3d_and_errors(capsys):
    from solvers.cli import main

    assert main(["degree", "--tdoa", "4r6s", "--model", "toa", "--dim", "3", "--saturate-det-h", "--json"]) == 0
    import json

    out = json.loads(capsys.readouterr().out)
    assert out["formulation"] == "4r6s-toa3d:A,B2,B3,B4,B5,B6,C2-C4" and out["degree"] == cell_degree("4r6s-toa3d:all").degree
    for argv, fragment in ((["--tdoa", "4r6s", "--dim", "4"], "unsupported dimension 4; valid: 2, 3"),
                           (["--tdoa", "4r6s", "--model", "foo"], "unknown model 'foo'; valid: tdoa, toa"),
                           (["examples/katsura4.ms", "--model", "toa"], "need --tdoa CONFIG"),
                           (["--tdoa", "3r3s", "--model", "toa", "--parametrization", "direct", "--saturate-det-h"],
                            "--saturate-det-h needs the compaction or gram parametrization")):
        assert main(["degree", *argv]) == 2
        assert fragment in capsys.readouterr().err


def test_default_degree_command_is_unchanged(capsys):
    from solvers.cli import main

    assert main(["degree", "--tdoa", "6r4s", "--equations", "B2,C2-C6,minors"]) == 0
    assert "degree 22  (zero-dimensional)" in capsys.readouterr().out


def test_synthetic_3d_network_and_true_root():
    from solvers.synthetic import DegenerateNetworkError, Network, random_network, true_root

    net = random_network(6, 6, np.random.default_rng(11), dim=3)
    assert net.dim == 3 and net.receivers.shape == (6, 3)
    H, b, o = true_root(net)
    # the root of the 3D compaction formulation: the real sampler's, for the same network in its gauge frame
    config = TDOAConfig(6, 6, dim=3)
    S = (net.transmitters[1:4] - net.transmitters[0]).T
    np.testing.assert_allclose(np.linalg.inv(H), 4 * S.T @ S, rtol=1e-10)
    root = tuple(H[a, c] for a in range(3) for c in range(a, 3)) + tuple(b) + tuple(o)
    moved = type(sample_real_instance(config, 0))(config, None, tuple(map(tuple, net.measurements())),
                                                  tuple(map(tuple, net.receivers - net.receivers[0])),
                                                  tuple(map(tuple, net.transmitters - net.receivers[0])),
                                                  tuple(o), root)
    check_root(Formulation.from_spec(config, "all"), moved)
    flat = Network(net.receivers, np.c_[net.transmitters[:, :2], np.zeros(6)], net.offsets)
    with pytest.raises(DegenerateNetworkError, match="coplanar"):
        true_root(flat)
    assert random_network(4, 3, np.random.default_rng(1)).dim == 2  # the 2D default is unchanged


def _script(name: str):
    import importlib.util
    import os

    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts", f"{name}.py")
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_table3d_count_evidence_rules():
    """scripts/table3d.py's text for a cell's `count` row (tables/monodromy3d.csv): every solution proven with a
    passed trace test; proven with closed graphs and equal seed sets; proven but not closed or differing; not
    every solution proven."""
    text = _script("table3d").count_text

    def row(n, proven=None, graphs="closed; closed", sets="equal as sets", trace="not run", residual=""):
        return {"solutions": str(n), "proven": str(n if proven is None else proven), "seeds": "0 1", "graphs": graphs,
                "seed_sets": sets, "trace_test": trace, "trace_residual": residual}

    assert text(row(6148, trace="passed", residual="3e-12")) == "6148 (proven; 2 seeds equal as sets; complete by trace test, residual 3e-12)"
    assert text(row(6148, sets="not equal: 1 paths lost", trace="passed", residual="3e-12")) == \
        "6148 (proven; complete by trace test, residual 3e-12)"
    assert text(row(2321)) == "2321 (proven; 2 seeds equal as sets)"
    assert text(row(3920, graphs="closed; not closed (2 tracks open)")) == ">=3920 (proven lower bound; graphs not all closed)"
    assert text(row(3920, sets="not equal: 1 land outside the set")) == ">=3920 (proven lower bound; seed sets: 1 land outside the set)"
    assert text(row(36947, sets="not equal: 1 paths lost")) == ">=36947 (proven lower bound; seed sets: 1 paths lost)"
    assert text(row(12965, proven=12960, trace="passed")) == ">=12965 (lower bound, numerical)"
    assert text({**row(20000, sets=""), "seeds": "0"}) == ">=20000 (proven lower bound; one seed)"
    gf = _script("table3d").with_gf_counts
    counted = {("tdoa", 3, 10, 4): "6148 (proven; 2 seeds equal as sets)",
               ("tdoa", 3, 7, 5): "2321 (proven; 2 seeds equal as sets)"}
    assert gf(counted, {("tdoa", 3, 10, 4): (6148, 2), ("tdoa", 3, 7, 5): (2320, 2), ("tdoa", 3, 5, 9): (9, 2)}) == {
        ("tdoa", 3, 10, 4): "6148 (GF(p), 2 primes, F4 with a larger budget; monodromy agrees)",
        ("tdoa", 3, 7, 5): "2320 (GF(p), 2 primes, F4 with a larger budget; monodromy: 2321)",
        ("tdoa", 3, 5, 9): "9 (GF(p), 2 primes, F4 with a larger budget)"}
    assert gf(counted, {}) == counted


def test_table3d_minimal_script_runs_under_its_caps(tmp_path, capsys):
    """scripts/table3d_minimal.py: a formulation stopped by its wall-time cap is a 'timeout' row (never dropped)
    in a table of its own; unknown cells and bad budgets are refused."""
    script = _script("table3d_minimal")
    assert script.formulation("10r4s").label == "10r4s-tdoa3d:A,B2,B3,B4,C2-C10"
    assert script.main(["10r4s", "--seconds", "0.5", "--out-dir", str(tmp_path)]) == 0
    records = cell_degrees.read_records(str(tmp_path / "table3d_minimal.csv"))
    (record,) = [r for r in records if r.config == "10r4s-tdoa3d"]
    assert record.status == "timeout" and record.degree is None and "0.5 s wall-time cap" in record.note
    assert "| 10 | timeout |" in (tmp_path / "table3d_minimal.md").read_text()
    assert [r.config for r in records] == [f"{c}-tdoa3d" for c in script.CELLS
                                           if c == "10r4s" or script.formulation(c).label in script.committed()]
    for argv, fragment in ((["11r4s"], "unknown cell(s) 11r4s"), (["--seconds", "0"], "must be positive")):
        with pytest.raises(SystemExit):
            script.main([*argv, "--out-dir", str(tmp_path)])
        assert fragment in capsys.readouterr().err


def test_committed_table3d_minimal_is_what_its_script_writes(tmp_path):
    """scripts/table3d_minimal.py --reuse writes the committed CSV and Markdown again, byte for byte."""
    import os

    script = _script("table3d_minimal")
    if not script.committed():
        pytest.skip("tables/table3d_minimal.csv not committed")
    assert script.main(["--reuse", "--out-dir", str(tmp_path)]) == 0
    for ext in ("csv", "md"):
        committed = os.path.join(script.ROOT, "tables", f"table3d_minimal.{ext}")
        assert (tmp_path / f"table3d_minimal.{ext}").read_text() == open(committed).read(), ext


def test_table_scripts_cover_the_minimal_cells_and_check_the_cross_check():
    toa = _script("toa_table")
    labels = {c.label for c in toa.cells()}
    assert {"3r3s-toa2d", "4r6s-toa3d", "6r4s-toa3d", "5r5s-toa3d"} <= labels
    assert all(-1 <= c.excess <= 3 for c in toa.cells())
    table3d = _script("table3d")
    minimal = {c.label for c in table3d.cells() if c.excess == 0}
    assert minimal == {"10r4s-tdoa3d", "7r5s-tdoa3d", "6r6s-tdoa3d", "5r9s-tdoa3d"}
    assert {"9r5s-tdoa3d", "7r6s-tdoa3d", "6r8s-tdoa3d"} <= {c.label for c in table3d.cells()}
    good = [cell_degree("3r3s-toa2d:all"), cell_degree("3r3s-toa2d-direct:all")]
    toa.check(good)  # 8 networks both ways
    wrong = [good[0], dataclasses.replace(good[1], degree=36, up_to_gauge=9)]
    with pytest.raises(ArithmeticError, match="compaction gives 8 networks, direct 36 / 4 = 9"):
        toa.check(wrong)
