"""Tests for solvers.template: the staged elimination template over GF(p) and its plain-text spec."""
from __future__ import annotations

import os

import pytest

from solvers.codegen import GENERATED_DIR, SOLVERS, module_name
from solvers.template import (
    SPEC_FORMAT,
    TemplateError,
    TemplateOptions,
    build_template,
    dump_spec,
    load_spec,
    macaulay_reducible_rank,
)


@pytest.fixture(scope="module")
def built_6r4s():
    # the committed spec was selected among all unknowns; o4 wins, so building only o4 reproduces it
    return build_template(SOLVERS["6r4s"], TemplateOptions(actions=("o4",)))


def test_6r4s_template_shape_and_basis(built_6r4s):
    spec = built_6r4s.spec
    assert spec["format"] == SPEC_FORMAT
    assert len(spec["basis"]) == 22  # paper Section 3.2
    assert spec["action"] == "o4"
    rows, cols = spec["final"]["shape"]
    assert cols == rows + len(spec["final"]["columns"]) - spec["final"]["n_lead"]
    # every reducible monomial x_a * b (b in B, not in B) is a target of the final template
    assert set(spec["reducible"]) <= set(spec["final"]["target_monomials"])


def test_spec_text_is_stable_and_matches_committed(built_6r4s):
    text = dump_spec(built_6r4s.spec)
    assert dump_spec(load_spec(text)) == text
    path = os.path.join(GENERATED_DIR, module_name(built_6r4s.spec) + ".json")
    with open(path, encoding="utf-8") as fh:
        assert fh.read() == text, "committed 6r4s spec differs from a fresh build (seed 1, p = 65521)"


def test_load_spec_rejects_other_formats():
    with pytest.raises(TemplateError, match="format"):
        load_spec('{"format": "something-else"}')


def test_single_macaulay_template_is_not_enough_at_low_degree():
    # why the template is staged: at degree 5 the Macaulay matrix reduces only part of R
    rows, rank, need = macaulay_reducible_rank(SOLVERS["6r4s"], 5, "o4")
    assert rows == 835 and need == 15 and rank < need
