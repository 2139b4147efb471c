"""Single-template feasibility (solvers.feasibility): relation counts over GF(p), multiplier families,
the committed evidence for 9r/3s, and pivot selection (analysis.engine.linalg.pivot_columns)."""
from __future__ import annotations

import csv
import os

import flint
import numpy as np
import pytest

from analysis.engine.linalg import pivot_columns
from solvers.feasibility import (
    basis_condition,
    count_relations,
    multipliers,
    relation_count,
)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
P = 32003


def _two_quadrics(rng):
    """Two dense random quadrics in x, y over GF(P): 4 roots, none at infinity."""
    mons = [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)]
    return [{m: int(rng.integers(1, P)) for m in mons} for _ in range(2)]


def test_macaulay_bound_on_a_regular_sequence():
    # two generic quadrics: their Macaulay matrix is complete in degree d1 + d2 - 1 = 3, i.e. with
    # multipliers of degree <= 1, and not with the equations alone
    from analysis.engine.f4 import groebner
    from analysis.engine.quotient import standard_monomials
    from analysis.engine.ring import Ring

    eqs = _two_quadrics(np.random.default_rng(0))
    ring = Ring(("x", "y"), P, "grevlex")
    gb = groebner([ring.from_terms(e) for e in eqs])
    basis = [ring.exps(m) for m in standard_monomials(gb)]
    assert len(basis) == 4
    for action in (0, 1):
        rows, cols, rel, need = count_relations(eqs, multipliers(("x", "y"), "total", 1), basis, action, P)
        assert (rows, rel) == (6, need) and need > 0
        _, _, rel0, need0 = count_relations(eqs, multipliers(("x", "y"), "total", 0), basis, action, P)
        assert rel0 < need0


def test_multiplier_families():
    u = ("h11", "b1", "o1", "o2")
    assert len(multipliers(u, "total", 2)) == 15
    assert len(multipliers(u, "offsets", 2)) == 6
    lin = multipliers(u, "linear-offsets", 1)
    assert len(lin) == 3 * 3 and all(sum(e[:2]) <= 1 and sum(e[2:]) <= 1 for e in lin)
    with pytest.raises(ValueError, match="unknown multiplier family"):
        multipliers(u, "bogus", 1)
    with pytest.raises(ValueError, match="needs offset unknowns"):
        multipliers(("x", "y"), "offsets", 1)
    with pytest.raises(ValueError, match="degree"):
        multipliers(u, "total", -1)


def test_pivot_columns_pick_independent_columns():
    rng = np.random.default_rng(3)
    m = rng.integers(0, P, size=(6, 3)) @ rng.integers(0, P, size=(3, 9)) % P  # rank 3
    piv = pivot_columns(m, P)
    assert len(piv) == flint.nmod_mat(m.tolist(), P).rank() == 3
    assert flint.nmod_mat(m[:, piv].tolist(), P).rank() == 3
    rows = pivot_columns(m.T, P)
    assert flint.nmod_mat(m[rows].tolist(), P).rank() == 3


def test_basis_condition_is_one_for_orthogonal_monomial_rows():
    # roots 1 and -1 of x^2 - 1 on the basis {1, x}: V = [[1, 1], [1, -1]] / sqrt(2), orthogonal
    assert basis_condition(np.array([[1.0], [-1.0]]), [(0,), (1,)]) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="must agree"):
        basis_condition(np.ones((2, 2)), [(0,), (1,)])


def test_committed_evidence_is_not_stale():
    """Recompute the cheapest GF(p) rows of tables/template_evidence_9r3s.csv (scripts/template_evidence.py)."""
    path = os.path.join(ROOT, "tables", "template_evidence_9r3s.csv")
    with open(path, encoding="utf-8") as fh:
        rows = [r for r in csv.DictReader(fh) if r["kind"] == "relations"]
    assert any(r["complete"] == "1" for r in rows), "the evidence must contain a complete template"
    checked = 0
    for r in rows:
        if (r["family"], r["degree"]) not in (("total", "2"), ("linear-offsets", "2"), ("linear-offsets", "3")):
            continue
        rc = relation_count("9r3s:C2-C9", r["family"], int(r["degree"]), r["action"], r["basis"])
        assert (rc.rows, rc.columns, rc.relations, rc.needed) == tuple(
            int(r[k]) for k in ("rows", "columns", "relations", "needed")), f"stale row {r}"
        checked += 1
    assert checked == 3
