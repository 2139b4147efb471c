"""One system format (issue 46): msolve's `.ms` and the parametric `.sys` are read by one reader
(analysis.formulations.systemfile.read_system_text), whichever verb is given the file."""
import json
from pathlib import Path

import pytest

from analysis.engine.io import System, parse_msolve
from analysis.formulations.parametric import ParametricSystem
from analysis.formulations.systemfile import ParametricError, read_system_text
from solvers.cli import main

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
KATSURA4_SYS = """# katsura-4 in the parametric format, without parameters: a plain system
unknowns: x0, x1, x2, x3, x4
equations:
x0+2*x1+2*x2+2*x3+2*x4-1
x0^2+2*x1^2+2*x2^2+2*x3^2+2*x4^2-x0
2*x0*x1+2*x1*x2+2*x2*x3+2*x3*x4-x1
x1^2+2*x0*x2+2*x1*x3+2*x2*x4-x2
2*x1*x2+2*x0*x3+2*x1*x4-x3
"""


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_the_two_formats_give_one_plain_system():
    msolve = (EXAMPLES / "katsura4.ms").read_text()
    assert read_system_text(KATSURA4_SYS, "k.sys") == read_system_text(msolve, "k.ms") == parse_msolve(msolve)
    assert isinstance(read_system_text((EXAMPLES / "circle.sys").read_text()), ParametricSystem)


def test_nonzero_without_parameters_is_the_rabinowitsch_saturation():
    system = read_system_text("unknowns: x, y\nnonzero: x, y - 2\nequations:\nx^2 + y^2 - 1\nx*(x - y)\n")
    assert isinstance(system, System) and system.variables == ("x", "y", "t")
    assert system == parse_msolve("x,y,t\n0\nx^2+y^2-1, x^2-x*y, t*x*y-2*t*x-1\n")


def test_errors_name_the_format_they_were_read_in():
    with pytest.raises(ParametricError, match="line 3"):
        read_system_text("unknowns: x\nequations:\nx^2 +* 1\n", "bad.sys")
    with pytest.raises(ValueError, match="characteristic"):
        read_system_text("x\nz\nx^2-1\n", "bad.ms")


@pytest.mark.parametrize("name", ["system.sys", "system.ms", "system.txt"])
def test_degree_reads_either_format_under_any_name(capsys, tmp_path, name):
    """The format is told by the content, not by the extension."""
    for text in ((EXAMPLES / "katsura4.ms").read_text(), KATSURA4_SYS):
        path = tmp_path / name
        path.write_text(text)
        code, out, _ = run(capsys, "degree", path, "--json")
        assert code == 0 and json.loads(out)["degree"] == 16


def test_degree_of_a_parametric_system_is_its_generic_count(capsys):
    code, out, _ = run(capsys, "degree", EXAMPLES / "circle.sys", "--json", "--basis")
    report = json.loads(out)
    # x^2 + y^2 = a, x*y - b*x + c = 0, x != 0: y = b - c/x, a quartic in x
    assert code == 0 and report["degree"] == 4 and report["saturated_by"] == "x"
    assert report["parameters"] == ["a", "b", "c"] and len(report["standard_basis"]) == 4
    assert "random parameter values" in report["status"]


@pytest.mark.parametrize("flag", [("--prime", "65521"), ("--gb",), ("--order", "lex"), ("--saturate", "x")])
def test_degree_refuses_plain_system_flags_on_a_parametric_one(capsys, flag):
    code, out, err = run(capsys, "degree", EXAMPLES / "circle.sys", *flag)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert f"{flag[0]} applies to plain systems" in err


def test_degree_of_a_plain_sys_with_nonzero(capsys, tmp_path):
    path = tmp_path / "plain.sys"
    path.write_text("unknowns: x, y\nnonzero: x\nequations:\nx^2 + y^2 - 1\nx*(x - y)\n")
    code, out, _ = run(capsys, "degree", path, "--json")
    assert code == 0 and json.loads(out)["degree"] == 2  # x = y on the circle; x = 0 saturated away


def test_generate_reads_msolve_format_and_says_a_plain_system_has_no_data(capsys):
    code, out, err = run(capsys, "generate", EXAMPLES / "katsura4.ms", "--out", "unused")
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert "plain system (no parameters)" in err and "tdoa-workbench degree" in err


def test_template_check_reads_a_plain_sys(capsys, tmp_path):
    path = tmp_path / "k.sys"
    path.write_text(KATSURA4_SYS)
    code, out, _ = run(capsys, "template-check", path, "--degrees", "1")
    assert code == 0 and out.startswith(f"{path}: |B| = 16")
    code, _, err = run(capsys, "template-check", EXAMPLES / "circle.sys")
    assert code == 2 and "has parameters (a, b, c)" in err


def test_template_check_checks_its_prime_against_random_primes(capsys, tmp_path):
    """Issue 46: the prime of template-check (65521 by default) is checked like degree's --prime; a system that
    is inconsistent over Q but not mod 65521 is an error (exit 3), not a basis of 2 monomials."""
    path = tmp_path / "unlucky.ms"
    path.write_text("x\n0\nx^2-1, x^2+65520\n")
    code, out, err = run(capsys, "template-check", path)
    assert code == 3 and out == "" and "--prime 65521 is unlucky" in err and "degree 0, dimension -1" in err
    code, out, _ = run(capsys, "template-check", EXAMPLES / "katsura4.ms", "--degrees", "1")
    assert code == 0 and "agreeing with 3 random 31-bit primes" in out
