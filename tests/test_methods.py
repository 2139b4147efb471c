"""Tests for the GF(p)-built methods (solvers.methods.spec, pencil): root counts, specs, plain text."""
from __future__ import annotations

import os

import pytest

from analysis.formulations.tdoa import Formulation, gf_equations, sample_gf_instance
from solvers.codegen import module_name
from solvers.generate import GENERATED_DIR, SOLVERS
from solvers.methods import pencil
from solvers.methods.spec import (
    SPEC_FORMAT,
    TemplateError,
    dump_spec,
    gf_degree,
    load_spec,
    solver_method,
    term_structure,
)


@pytest.fixture(scope="module")
def built_6r4s():
    return pencil.build(SOLVERS["6r4s"])


def test_methods_of_the_paper_solvers():
    assert solver_method(SOLVERS["6r4s"]) == "curve-pencil"
    assert solver_method("9r3s:C2-C9") == "homotopy"
    assert solver_method("6r4s:B2,C2-C6,M123_123,M124_123,M125_123") == "homotopy"  # not square: refused there


def test_gf_degree_of_6r4s_is_22():
    assert gf_degree(SOLVERS["6r4s"]) == 22  # paper Section 3.2


def test_pencil_spec_is_stable_and_matches_committed(built_6r4s):
    spec = built_6r4s.spec
    assert spec["format"] == SPEC_FORMAT and spec["kind"] == "curve-pencil"
    assert spec["degree"] == 22
    # det K has degree 22 + 8 (sigma^8); the column-degree pencil has 1 + 3*4 + 2*2 + 5*4 = 37 eigenvalues
    assert spec["size"] == [37, 37]
    assert spec["pencil"]["drop_infinite"] == 37 - 30 and spec["pencil"]["drop_sigma"] == 8
    assert built_6r4s.candidates[0]["verified"] == built_6r4s.candidates[0]["trials"]
    text = dump_spec(spec)
    assert dump_spec(load_spec(text)) == text
    path = os.path.join(GENERATED_DIR, module_name("tdoa_6r4s", spec) + ".json")
    with open(path, encoding="utf-8") as fh:
        assert fh.read() == text, "committed 6r4s spec differs from a fresh build (seed 1, p = 65521)"


def test_term_structure_matches_gf_supports():
    form = Formulation.parse(SOLVERS["6r4s"])
    monomials, inputs = term_structure(form)
    instance = sample_gf_instance(form.config, 65521, 3)
    for eq, terms in zip(gf_equations(form, instance), inputs):
        assert set(eq) == {tuple(monomials[t]) for t in terms}


def test_load_spec_rejects_other_formats():
    with pytest.raises(TemplateError, match="format"):
        load_spec('{"format": "something-else"}')


def test_pencil_rejects_other_formulations():
    with pytest.raises(TemplateError, match="curve pencil"):
        pencil.build("6r4s:B2,C2-C6,M123_123,M124_123,M125_123")
