"""Tests for analysis.formulations.tdoa: the equations, their degrees, known roots, parsing and symmetry."""
from __future__ import annotations

import dataclasses
import itertools
import math
import sys

import numpy as np
import pytest
import sympy

import analysis.formulations.tdoa as formulations_module
from analysis.formulations.tdoa import (
    BadPrime,
    Formulation,
    InconsistentSample,
    Relabeling,
    SamplingFailed,
    TDOAConfig,
    canonical_form,
    check_root,
    coefficient_expressions,
    data_symbols,
    enumerate_formulations,
    equation_names,
    evaluate_gf,
    evaluate_real,
    gf_equations,
    is_quadratic_residue,
    parse_equations,
    real_equations,
    sample_gf_instance,
    sample_real_instance,
    sqrt_mod,
    symbolic_equations,
    unknown_symbols,
)

P = 2_147_483_647  # 2^31 - 1
CONFIGS = ["9r3s", "6r4s", "5r5s", "4r6s"]


@pytest.fixture(scope="module")
def reference_5r4s():
    """The slow sympy reference for every equation of 5r4s (A, B2, B3, C2-C5 and 4 minors), built once."""
    f = Formulation.from_spec("5r4s", "all")
    return f, symbolic_equations(f)


def _poly_mod_p(expr: sympy.Expr, gens, p: int) -> dict:
    """Exponent dict of an expression with rational coefficients, reduced mod p, zeros dropped."""
    out = {}
    for monom, coeff in sympy.Poly(expr, *gens).terms():
        coeff = sympy.Rational(coeff)
        value = int(coeff.p) * pow(int(coeff.q), -1, p) % p
        if value:
            out[monom] = value
    return out


def _normalise(poly: dict, p: int) -> dict:
    """Scale a GF(p) polynomial so that its largest-exponent term has coefficient 1."""
    lead = poly[max(poly)]
    inv = pow(lead, -1, p)
    return {e: c * inv % p for e, c in poly.items()}


# ---------------------------------------------------------------------------------------------- config


def test_config_parse_label_and_unknowns():
    assert TDOAConfig.parse("6r4s") == TDOAConfig(6, 4)
    assert TDOAConfig.parse(" 6R/4S ") == TDOAConfig(6, 4)
    cfg = TDOAConfig(6, 4)
    assert cfg.label == "6r4s" and str(cfg) == "6r4s"
    assert cfg.unknowns == ("h11", "h12", "h22", "b1", "b2", "o1", "o2", "o3", "o4")
    assert cfg.n_minors == 10
    TDOAConfig(4, 3)  # underdetermined but valid
    for bad in [(3, 4), (6, 2)]:
        with pytest.raises(ValueError, match=">="):
            TDOAConfig(*bad)
    with pytest.raises(ValueError, match="6r4s"):
        TDOAConfig.parse("6x4")


def test_equation_names_order_and_separator():
    names = equation_names("6r4s")
    assert names[:8] == ("A", "B2", "B3", "C2", "C3", "C4", "C5", "C6")
    assert names[8:11] == ("M123_123", "M124_123", "M125_123") and names[-1] == "M345_123"
    assert len(names) == 8 + 10
    assert equation_names("9r3s")[-1] == "C9"
    big = equation_names("11r4s")  # 10 rows: dotted names keep them unambiguous
    minors = [x for x in big if x.startswith("M")]
    assert len(minors) == math.comb(10, 3) and len(set(minors)) == len(minors)
    assert minors[0] == "M1.2.3_1.2.3" and minors[-1] == "M8.9.10_1.2.3"


# --------------------------------------------------------------------------------------------- parsing


def test_parse_equations_ranges_groups_and_globs():
    cfg = TDOAConfig(6, 4)
    assert parse_equations(cfg, "B2,C2-C6,minors") == ("B2", "C2", "C3", "C4", "C5", "C6") + equation_names(cfg)[8:]
    assert parse_equations(cfg, "A,B2,B3,C*") == ("A", "B2", "B3", "C2", "C3", "C4", "C5", "C6")
    assert parse_equations(cfg, "c2-4, b3") == ("B3", "C2", "C3", "C4")
    assert parse_equations(cfg, "M124_123,M123_123,C3,C3") == ("C3", "M123_123", "M124_123")
    assert parse_equations(cfg, "all") == equation_names(cfg)
    assert parse_equations(cfg, "minors(10)") == equation_names(cfg)[8:]
    assert parse_equations(cfg, "M1*") == ("M123_123", "M124_123", "M125_123", "M134_123", "M135_123", "M145_123")
    assert parse_equations("9r3s", "C2-C9") == tuple(f"C{i}" for i in range(2, 10))


@pytest.mark.parametrize("spec, fragment", [
    ("C2,C7", "'C7'"),
    ("C2-C9", "C9 does not exist"),
    ("C5-C3", "empty"),
    ("B2-C4", "mixes"),
    ("minors(9)", "has 10 minors"),
    ("Q*", "matches no equation"),
    ("C2,,C3", "empty token"),
    ("M123_124", "'M123_124'"),
])
def test_parse_equations_errors(spec, fragment):
    with pytest.raises(ValueError, match=fragment.replace("(", r"\(")) as info:
        parse_equations("6r4s", spec)
    if "does not exist" in fragment or "'" in fragment:
        assert "valid names for 6r4s" in str(info.value)


def test_parse_minors_without_minors_is_an_error():
    with pytest.raises(ValueError, match="no minors"):
        parse_equations("9r3s", "C2,minors")


def test_formulation_label_roundtrip_and_counts():
    f = Formulation.from_spec("6r4s", "C2-C6,B2,minors")
    assert f.label == "6r4s:B2,C2-C6,minors(10)"
    assert tuple(f.counts) == (0, 1, 5, 10) and f.n_equations == 16
    assert Formulation.parse(f.label) == f
    g = Formulation(TDOAConfig(6, 4), ("C4", "A", "C2", "M135_123"))
    assert g.equations == ("A", "C2", "C4", "M135_123") and g.label == "6r4s:A,C2,C4,M135_123"
    assert Formulation.parse(g.label) == g
    with pytest.raises(ValueError, match="duplicate"):
        Formulation(TDOAConfig(6, 4), ("C2", "C2"))
    with pytest.raises(ValueError, match="unknown equation"):
        Formulation(TDOAConfig(6, 4), ("C7",))


# --------------------------------------------------------------------------------------------- degrees


def test_degrees_of_each_family(reference_5r4s):
    f, reference = reference_5r4s
    cfg = f.config
    syms = unknown_symbols(cfg)
    gens = syms + tuple(itertools.chain.from_iterable(data_symbols(cfg)))
    expected = {"A": (3, 4), "B": (2, 4), "C": (1, 3)}
    for name, expr in reference.items():
        fam = "minors" if name.startswith("M") else name[0]
        monoms = sympy.Poly(expr, *gens).monoms()
        deg_hb = max(sum(mon[:5]) for mon in monoms)
        deg_total = max(sum(mon[:len(syms)]) for mon in monoms)
        if fam == "minors":
            assert deg_hb == 0 and deg_total == 3, name  # degree 3 in the offsets only
        else:
            assert (deg_hb, deg_total) == expected[fam], name
    # the fast path has the same degrees (on 9r6s, where sympy would be slow)
    cfg = TDOAConfig(9, 6)
    f = Formulation.from_spec(cfg, "all")
    inst = sample_gf_instance(cfg, P, np.random.default_rng(3))
    for name, poly in zip(f.equations, gf_equations(f, inst)):
        fam = "minors" if name.startswith("M") else name[0]
        deg_hb = max(sum(e[:5]) for e in poly)
        deg_total = max(sum(e) for e in poly)
        if fam == "minors":
            assert deg_hb == 0 and deg_total == 3, name
        else:
            assert (deg_hb, deg_total) == expected[fam], name


# ------------------------------------------------------------------------------------------ known roots


def test_symbolic_equations_vanish_at_real_root(reference_5r4s):
    f, reference = reference_5r4s
    cfg = f.config
    inst = sample_real_instance(cfg, np.random.default_rng(11))
    gens = unknown_symbols(cfg) + tuple(itertools.chain.from_iterable(data_symbols(cfg)))
    point = np.array(inst.root + tuple(itertools.chain.from_iterable(inst.F)))
    for name, expr in reference.items():
        poly = sympy.Poly(expr, *gens)
        terms = [float(c) * float(np.prod(point ** np.array(mon))) for mon, c in poly.terms()]
        assert abs(sum(terms)) <= 1e-9 * sum(map(abs, terms)), name


@pytest.mark.parametrize("label", CONFIGS)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gf_equations_vanish_at_known_root(label, seed):
    cfg = TDOAConfig.parse(label)
    f = Formulation.from_spec(cfg, "all")
    for p in (P, 10007):
        inst = sample_gf_instance(cfg, p, np.random.default_rng(seed))
        polys = gf_equations(f, inst)
        assert len(polys) == f.n_equations
        for name, poly in zip(f.equations, polys):
            assert poly, f"{name} vanished identically (seed {seed}, p {p})"
            assert all(0 < c < p and len(e) == cfg.n_unknowns for e, c in poly.items())
            assert evaluate_gf(poly, inst.root, p) == 0, f"{name} seed {seed} p {p}"
        check_root(f, inst)


@pytest.mark.parametrize("label", CONFIGS)
def test_real_equations_vanish_at_known_root(label):
    cfg = TDOAConfig.parse(label)
    f = Formulation.from_spec(cfg, "all")
    for seed in range(3):
        inst = sample_real_instance(cfg, np.random.default_rng(seed))
        check_root(f, inst)
        for poly in real_equations(f, inst):
            value, scale = evaluate_real(poly, inst.root)
            assert abs(value) <= 1e-9 * scale


def test_check_root_detects_a_wrong_root():
    cfg = TDOAConfig(6, 4)
    f = Formulation.from_spec(cfg, "B2,C2-C6,minors")
    inst = sample_gf_instance(cfg, P, np.random.default_rng(5))
    bad = dataclasses.replace(inst, root=inst.root[:5] + ((inst.root[5] + 1) % P,) + inst.root[6:])
    with pytest.raises(InconsistentSample, match="C2"):
        check_root(f, bad)
    rinst = sample_real_instance(cfg, np.random.default_rng(5))
    rbad = dataclasses.replace(rinst, root=(rinst.root[0] * 1.001,) + rinst.root[1:])
    with pytest.raises(InconsistentSample):
        check_root(f, rbad)


# ------------------------------------------------------------------------------- fast path vs reference


def test_gf_equations_match_symbolic_reference_mod_p(reference_5r4s):
    f, reference = reference_5r4s
    cfg = f.config
    p = 1_000_003
    inst = sample_gf_instance(cfg, p, np.random.default_rng(7))
    fsyms = data_symbols(cfg)
    subs = {fsyms[i][j]: inst.F[i][j] for i in range(cfg.m) for j in range(cfg.n)}
    gens = unknown_symbols(cfg)
    for (name, expr), poly in zip(reference.items(), gf_equations(f, inst)):
        assert _poly_mod_p(expr.xreplace(subs), gens, p) == poly, name


def test_real_equations_match_symbolic_reference(reference_5r4s):
    f, reference = reference_5r4s
    cfg = f.config
    inst = sample_real_instance(cfg, np.random.default_rng(8))
    fsyms = data_symbols(cfg)
    subs = {fsyms[i][j]: sympy.Float(inst.F[i][j], 30) for i in range(cfg.m) for j in range(cfg.n)}
    gens = unknown_symbols(cfg)
    for (name, expr), poly in zip(reference.items(), real_equations(f, inst)):
        ref = {m: float(c) for m, c in sympy.Poly(sympy.expand(expr.xreplace(subs)), *gens).terms()}
        scale = max(map(abs, ref.values()))
        for mon in set(ref) | set(poly):
            assert abs(ref.get(mon, 0.0) - poly.get(mon, 0.0)) <= 1e-9 * scale, (name, mon)


def test_coefficient_expressions_match_symbolic_reference(reference_5r4s):
    f, reference = reference_5r4s
    cfg = f.config
    unknowns = unknown_symbols(cfg)
    data = tuple(itertools.chain.from_iterable(data_symbols(cfg)))
    for (name, expr), coeffs in zip(reference.items(), coefficient_expressions(f, form="ring")):
        ref = {mon: sympy.Rational(c) for mon, c in sympy.Poly(expr, *unknowns, *data).terms()}
        ours = {exp + dmon: sympy.Rational(c.numerator, c.denominator)
                for exp, coeff in coeffs.items() for dmon, c in coeff.items()}
        assert ours == ref, name
    small = Formulation.from_spec(cfg, "A,B2,C3")
    for ring_coeffs, expr_coeffs in zip(coefficient_expressions(small, form="ring"), coefficient_expressions(small)):
        assert set(ring_coeffs) == set(expr_coeffs)
        assert all(ring_coeffs[m].as_expr() == expr_coeffs[m] for m in ring_coeffs)
        assert all(c.free_symbols <= set(data) for c in expr_coeffs.values())
    with pytest.raises(ValueError, match="form"):
        coefficient_expressions(f, form="lambda")


def test_gf_equations_for_9r6s_needs_no_sympy(monkeypatch):
    """All 571 equations of 9r/6s come from the sparse builder alone (no sympy: that is what makes them
    cheap, about 6 ms; the timing is a benchmark's business), and the known root satisfies them."""
    cfg = TDOAConfig(9, 6)
    f = Formulation.from_spec(cfg, "all")
    inst = sample_gf_instance(cfg, P, np.random.default_rng(0))
    for module in ("sympy", "sympy.polys.rings"):
        monkeypatch.setitem(sys.modules, module, None)  # any import of sympy now fails
    polys = gf_equations(f, inst)
    assert len(polys) == len(f.equations) == 571
    assert all(polys) and all(0 < c < P for poly in polys for c in poly.values())
    assert all(evaluate_gf(poly, inst.root, P) == 0 for poly in polys)
    assert gf_equations(f, inst) == polys


def test_gf_equations_argument_errors():
    cfg = TDOAConfig(6, 4)
    f = Formulation.from_spec(cfg, "C*")
    inst = sample_gf_instance(cfg, 10007, np.random.default_rng(0))
    with pytest.raises(BadPrime):
        gf_equations(f, inst, 10009)
    with pytest.raises(BadPrime):
        gf_equations(f, inst.F, 15)
    with pytest.raises(ValueError, match="6 x 4"):
        gf_equations(f, inst.F[:5], 10007)
    with pytest.raises(ValueError, match="real"):
        gf_equations(f, sample_real_instance(cfg, 0))


# -------------------------------------------------------------------------------------------- samplers


def test_sqrt_mod_and_residues():
    for p in (7, 11, 17, 41, 97, 65537):
        squares = {x * x % p for x in range(1, p)}
        for a in range(1, min(p, 3000)):
            assert is_quadratic_residue(a, p) == (a in squares)
            if a in squares:
                r = sqrt_mod(a, p)
                assert r * r % p == a and r <= p - r
            else:
                with pytest.raises(ValueError):
                    sqrt_mod(a, p)


@pytest.mark.parametrize("label", CONFIGS + ["9r6s"])
def test_gf_sampler_residues_and_determinism(label):
    cfg = TDOAConfig.parse(label)
    p = 10007
    inst = sample_gf_instance(cfg, p, np.random.default_rng(42))
    assert inst.receivers[0] == (0, 0) and inst.prime == p
    for i, (rx, ry) in enumerate(inst.receivers):
        for j, (sx, sy) in enumerate(inst.transmitters):
            d2 = ((rx - sx) ** 2 + (ry - sy) ** 2) % p
            assert is_quadratic_residue(d2, p)
            assert (inst.F[i][j] - inst.offsets[j]) ** 2 % p == d2
    assert inst == sample_gf_instance(cfg, p, np.random.default_rng(42))
    assert inst == sample_gf_instance(cfg, p, 42)
    assert inst != sample_gf_instance(cfg, p, np.random.default_rng(43))
    assert inst.data_array().shape == (cfg.m, cfg.n)


@pytest.mark.parametrize("label", ["50r3s", "20r5s", pytest.param("17r16s", marks=pytest.mark.slow)])
def test_gf_sampler_many_receivers(label, monkeypatch):
    """More than 16 receivers: transmitters first, receivers by rejection (seconds, not minutes); the
    distances are residues, r_1 = 0 and the known root satisfies every C equation."""
    cfg = TDOAConfig.parse(label)
    batches = []
    real_mask = formulations_module._residue_mask
    monkeypatch.setattr(formulations_module, "_residue_mask",
                        lambda points, anchors, p: batches.append(len(anchors)) or real_mask(points, anchors, p))
    inst = sample_gf_instance(cfg, 65521, 0)
    # transmitters first: every batch tests candidates against the n transmitters (acceptance about
    # 2^-n), and a few dozen batches suffice (against the receivers, 2^-m, it would take ~2^m)
    assert set(batches) == {cfg.n} and len(batches) <= 4 * cfg.m
    assert inst.receivers[0] == (0, 0) and len(inst.receivers) == cfg.m
    for i, (rx, ry) in enumerate(inst.receivers):
        for j, (sx, sy) in enumerate(inst.transmitters):
            d2 = ((rx - sx) ** 2 + (ry - sy) ** 2) % 65521
            assert is_quadratic_residue(d2, 65521)
            assert (inst.F[i][j] - inst.offsets[j]) ** 2 % 65521 == d2
    assert inst == sample_gf_instance(cfg, 65521, 0)
    check_root(Formulation.from_spec(cfg, "A,B2,B3,C2-C9"), inst)


def test_gf_sampler_many_receivers_is_generic():
    """50r3s:C2-C9 on the receivers-last path has the degree of 9r3s:C2-C9 (Table 2: 75)."""
    from analysis.engine.degree import analyse
    from analysis.engine.ring import Ring

    f = Formulation.from_spec("50r3s", "C2-C9")

    def polys(p):
        ring = Ring(f.unknowns, p)
        return [ring.from_terms(t) for t in gf_equations(f, sample_gf_instance(f.config, p, 0))]

    assert analyse(polys).degree == 75


def test_gf_sampler_refuses_both_sides_large():
    with pytest.raises(SamplingFailed, match="fewer receivers or transmitters"):
        sample_gf_instance("17r17s", 65521, 0)


def test_gf_root_matches_network():
    """H = (4 S^T S)^{-1} and b = -1/2 S^{-1} s_1 over GF(p), checked with sympy matrices mod p."""
    cfg = TDOAConfig(6, 4)
    p = 10007
    inst = sample_gf_instance(cfg, p, np.random.default_rng(9))
    s = [sympy.Matrix(t) for t in inst.transmitters]
    S = sympy.Matrix.hstack(s[1] - s[0], s[2] - s[0])
    H = (4 * S.T * S).inv_mod(p)
    b = (-sympy.Rational(1, 2) * S.inv_mod(p) * s[0]).applyfunc(lambda x: int(x.p * pow(int(x.q), -1, p)) % p)
    assert inst.root[:5] == (H[0, 0] % p, H[0, 1] % p, H[1, 1] % p, b[0] % p, b[1] % p)
    assert inst.root[5:] == inst.offsets


def test_real_sampler_consistency():
    cfg = TDOAConfig(6, 4)
    inst = sample_real_instance(cfg, np.random.default_rng(1))
    r, s = np.array(inst.receivers), np.array(inst.transmitters)
    assert np.all(r[0] == 0)
    d = np.linalg.norm(r[:, None] - s[None], axis=2)
    assert np.allclose(np.array(inst.F) - np.array(inst.offsets), d)
    assert inst == sample_real_instance(cfg, np.random.default_rng(1))
    H = np.array([[inst.root[0], inst.root[1]], [inst.root[1], inst.root[2]]])
    L = -2 * np.column_stack([s[1] - s[0], s[2] - s[0]])
    assert np.allclose(np.linalg.inv(H), L.T @ L)
    assert np.allclose(L @ np.array(inst.root[3:5]), s[0])  # s_1 = L b


def test_sampler_rejects_bad_primes():
    for p in (2, 9, 2**31 + 11):
        with pytest.raises(BadPrime):
            sample_gf_instance("6r4s", p, 0)


# -------------------------------------------------------------------------------------------- symmetry


def _random_relabeling(cfg: TDOAConfig, rng: np.random.Generator) -> Relabeling:
    receivers = (1,) + tuple(int(x) for x in rng.permutation(np.arange(2, cfg.m + 1)))
    head = (2, 3) if rng.integers(2) else (3, 2)
    tail = tuple(int(x) for x in rng.permutation(np.arange(4, cfg.n + 1)))
    return Relabeling(cfg, receivers, (1,) + head + tail)


@pytest.mark.parametrize("label", ["6r4s", "5r5s", "4r6s"])
def test_relabeling_is_a_symmetry_of_the_equations(label):
    """Relabeled equations on relabeled data = original equations with permuted unknowns (up to sign)."""
    cfg = TDOAConfig.parse(label)
    f = Formulation.from_spec(cfg, "all")
    inst = sample_gf_instance(cfg, P, np.random.default_rng(21))
    rng = np.random.default_rng(22)
    original = dict(zip(f.equations, gf_equations(f, inst)))
    for _ in range(4):
        g = _random_relabeling(cfg, rng)
        image = g.apply(f)
        assert image == f  # "all" is invariant
        moved = dict(zip(image.equations, gf_equations(image, g.permute_data(inst.F), P)))
        perm = g.unknown_permutation()
        for name, poly in original.items():
            mapped = {}
            for e, c in poly.items():
                new = [0] * len(e)
                for k, x in enumerate(e):
                    new[perm[k]] = x
                mapped[tuple(new)] = c
            target = moved[g.equation_name(name)]
            assert _normalise(mapped, P) == _normalise(target, P), (name, g)
            if not name.startswith("M"):
                assert mapped == target, (name, g)  # A, B, C are mapped exactly, not just up to sign


def test_relabeling_validation():
    cfg = TDOAConfig(6, 4)
    with pytest.raises(ValueError, match="fixing 1"):
        Relabeling(cfg, (2, 1, 3, 4, 5, 6), (1, 2, 3, 4))
    with pytest.raises(ValueError, match="onto themselves"):
        Relabeling(cfg, (1, 2, 3, 4, 5, 6), (1, 4, 3, 2))


@pytest.mark.parametrize("label", ["6r4s", "5r5s", "9r3s"])
def test_canonical_form_is_invariant(label):
    cfg = TDOAConfig.parse(label)
    names = equation_names(cfg)
    rng = np.random.default_rng(5)
    for _ in range(12):
        chosen = tuple(x for x in names if rng.random() < 0.4) or ("C3",)
        f = Formulation(cfg, chosen)
        canon = canonical_form(f)
        assert canon.counts == f.counts
        assert canonical_form(canon) == canon
        for _ in range(5):
            assert canonical_form(_random_relabeling(cfg, rng).apply(f)) == canon


def test_canonical_form_is_an_image_and_separates_orbits():
    """On 5r5s (group of order 4! * 2 * 2 = 96) compare with brute-force orbits."""
    cfg = TDOAConfig(5, 5)
    group = [Relabeling(cfg, (1,) + rec, (1,) + head + tail)
             for rec in itertools.permutations((2, 3, 4, 5))
             for head in ((2, 3), (3, 2)) for tail in ((4, 5), (5, 4))]
    names = equation_names(cfg)
    rng = np.random.default_rng(6)
    for _ in range(6):
        f = Formulation(cfg, tuple(x for x in names if rng.random() < 0.3) or ("M123_123",))
        orbit = {g.apply(f) for g in group}
        canon = canonical_form(f)
        assert canon in orbit
        assert {canonical_form(x) for x in orbit} == {canon}


def test_orbit_count_of_minor_subsets_6r4s():
    """Subsets of the 10 minors of a 5 x 3 compaction matrix ~ 3-uniform hypergraphs on 5 rows
    ~ (by complement) graphs on 5 vertices: 34 classes, 33 of them non-empty."""
    cfg = TDOAConfig(6, 4)
    minors = [x for x in equation_names(cfg) if x.startswith("M")]
    forms = {canonical_form(Formulation(cfg, s)).equations
             for k in range(1, 11) for s in itertools.combinations(minors, k)}
    assert len(forms) == 33


def test_enumerate_formulations_counts():
    found = list(enumerate_formulations("9r3s", total=8))
    assert sorted(tuple(f.counts)[:3] for f in found) == sorted(
        [(0, 0, 8), (0, 1, 7), (1, 0, 7), (1, 1, 6), (0, 2, 6), (1, 2, 5)])  # the rows of Table 2
    assert Formulation.from_spec("9r3s", "C*") in found
    assert all(canonical_form(f) == f for f in found)
    assert [f.label for f in enumerate_formulations("6r4s", 0, 1, 5, minor_sets="all")] == ["6r4s:B2,C2-C6,minors(10)"]
    # 3 of the 10 minors with all C rows used ~ graphs with 3 edges on 5 vertices: 4 classes
    assert len(list(enumerate_formulations("6r4s", 0, 1, 5, minor_sets=3))) == 4
    assert len(list(enumerate_formulations("6r4s", 0, 0, 0, minor_sets=range(1, 11)))) == 33
    explicit = list(enumerate_formulations("6r4s", 0, 0, 2, minor_sets=[("M123_123",), ("M345_123",), ("M145_123",)]))
    assert len(explicit) == 3  # the minors meet 2, 0 and 1 of the C rows: three classes
    with pytest.raises(ValueError, match="out of range"):
        list(enumerate_formulations("6r4s", nB=3))
    with pytest.raises(ValueError, match="no minors"):
        list(enumerate_formulations("9r3s", minor_sets="all"))
