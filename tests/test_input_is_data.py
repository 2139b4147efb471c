"""Input is data (STYLE habit 11): a system file cannot run code, and no module evaluates text.

Every text a user hands in is read by the project's own tokenizer/parser (analysis.engine.io); nothing under
analysis/ or solvers/ passes text to ``eval``, ``exec``, ``sympify`` or ``parse_expr``.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

from analysis.formulations.parametric import ParametricError, parse
from solvers.cli import main

ROOT = Path(__file__).resolve().parents[1]

PAYLOAD = "__import__('os').system('touch PWNED')*0"

EVIL = f"""# a parametric system whose second equation holds Python
unknowns: x, y
parameters: a, b
equations:
x^2 + y^2 - a
x*y - b + {PAYLOAD}
"""


def test_parse_refuses_code_and_names_the_line(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ParametricError, match=r"evil\.sys, line 6, column 22: unexpected character"):
        parse(EVIL, "evil.sys")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("section, line", [("equations", 6), ("nonzero", 4)])
def test_generate_refuses_a_system_file_holding_code(tmp_path, monkeypatch, capsys, section, line):
    monkeypatch.chdir(tmp_path)
    if section == "equations":
        text = EVIL
    else:
        text = f"unknowns: x, y\nparameters: a, b\n\nnonzero: {PAYLOAD}\nequations:\nx^2 - a\ny^2 - b\n"
    (tmp_path / "evil.sys").write_text(text)
    code = main(["generate", "evil.sys", "--out", "gen"])
    err = capsys.readouterr().err
    assert code != 0 and f"evil.sys, line {line}" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["evil.sys"], "the payload ran or output was written"


@pytest.mark.parametrize("text, match", [
    ("unknowns: x\nparameters: a\nequations:\nx - a; eval(a)\n", r"line 4, column 8: unknown name 'eval'"),
    ("unknowns: x\nparameters: a\nequations:\nx**a\n", r"line 4, column 4: exponent must be .* constant"),
    ("unknowns: x\nparameters: a\nequations:\nx/a\n", r"line 4, column 3: division by a non-constant"),
    ("unknowns: x\nparameters: a\nequations:\nx.real - a\n", r"line 4, column 2: unexpected character '\.'"),
    ("unknowns: lambda\nparameters: a\nequations:\nlambda - a\n", "not a Python keyword"),
])
def test_text_is_read_as_polynomials_only(text, match):
    with pytest.raises(ParametricError, match=match):
        parse(text, "user.sys")


def test_parsed_system_keeps_rationals_and_division_by_constants():
    system = parse("unknowns: x, y\nparameters: a\nequations:\n(x - y)^2/3 - 3/4*a; x*y - a**2\n", "q")
    x, y = system.x_symbols
    (a,) = system.q_symbols
    assert system.exprs[0] == ((x - y) ** 2 / 3 - a * 3 / 4).expand()
    assert system.exprs[1] == x * y - a**2


# --------------------------------------------------------------------------------------------------
# no module evaluates text
# --------------------------------------------------------------------------------------------------

#: Calls that turn text into Python objects by evaluating it.
FORBIDDEN = {"eval", "exec", "sympify", "parse_expr", "S", "lambdify"}

#: (module, call) pairs that run code the project generated itself, not text it read. Each needs a reason.
ALLOWED = {
    # compiles the coefficient function printed by coefficient_source from sympy expressions built by
    # the project's parser (names checked to be identifiers, numbers printed by sympy)
    ("solvers/continuation/tracking.py", "exec"),
    # the non-vanishing conditions as numpy functions, from the same parsed expressions
    ("solvers/continuation/monodromy.py", "lambdify"),
}


def _calls(path: Path):
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            func = node.func
            name = func.id if isinstance(func, ast.Name) else func.attr if isinstance(func, ast.Attribute) else None
            if name in FORBIDDEN:
                strict = any(k.arg == "strict" and isinstance(k.value, ast.Constant) and k.value.value is True
                             for k in node.keywords)
                yield name, node.lineno, strict


def test_no_module_evaluates_text():
    found = []
    for package in ("analysis", "solvers"):
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            for name, lineno, strict in _calls(path):
                if name == "sympify" and strict:  # strict sympify converts objects and refuses strings
                    continue
                if (rel, name) not in ALLOWED:
                    found.append(f"{rel}:{lineno}: {name}(...)")
    assert not found, "text must be read by analysis.engine.io's parser, not evaluated: " + "; ".join(found)
