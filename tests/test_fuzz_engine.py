"""A fixed slice of scripts/fuzz_engine.py in the default tests: every category against sympy (and
against Singular where it is installed); the comparison itself is checked to see a wrong basis."""
import importlib.util
import shutil
from fractions import Fraction
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "fuzz_engine.py"
spec = importlib.util.spec_from_file_location("fuzz_engine", SCRIPT)
fuzz = importlib.util.module_from_spec(spec)
spec.loader.exec_module(fuzz)

SLICE = range(0, 2 * len(fuzz.CATEGORIES))
"""Two cases of every category."""


def test_cases_are_seeded_and_cover_every_category():
    assert [fuzz.generate(k) for k in SLICE] == [fuzz.generate(k) for k in SLICE]
    assert {fuzz.generate(k)["category"] for k in SLICE} == set(fuzz.CATEGORIES)
    assert fuzz.generate(1) != fuzz.generate(1 + len(fuzz.CATEGORIES))


@pytest.mark.parametrize("k", SLICE)
def test_engine_agrees_with_sympy(k, tmp_path):
    case = fuzz.generate(k)
    outcome, detail = fuzz.compare(case, fuzz.run_engine(case, tmp_path), fuzz.run_sympy(case))
    assert outcome in ("agree", "skipped"), (k, detail, fuzz.system_text(case))
    if case["category"] not in ("block", "saturation"):
        assert outcome == "agree"


def test_a_wrong_answer_is_seen(tmp_path):
    case = fuzz.generate(0)
    mine = fuzz.run_engine(case, tmp_path)
    ref = fuzz.run_sympy(case)
    assert fuzz.compare(case, mine, ref)[0] == "agree"
    first = {**mine["basis"][0], (0,) * len(case["variables"]): Fraction(1, 3)}  # another constant term
    wrong = dict(mine, basis=[first] + mine["basis"][1:])
    assert fuzz.compare(case, wrong, ref) == ("disagree", "reduced bases differ")
    assert fuzz.compare(case, dict(mine, degree=(mine["degree"] or 0) + 1), ref)[0] == "disagree"


@pytest.mark.skipif(shutil.which("Singular") is None, reason="Singular is not installed")
def test_engine_agrees_with_singular(tmp_path):
    cases = [fuzz.generate(k) for k in SLICE]
    refs = fuzz.run_singular(cases, shutil.which("Singular"))
    for case in cases:
        outcome, detail = fuzz.compare(case, fuzz.run_engine(case, tmp_path), refs[case["id"]])
        assert outcome == "agree", (case["id"], detail, fuzz.system_text(case))
