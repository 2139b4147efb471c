"""The tdoa-workbench command line: results, JSON shape and one-line errors with exit codes."""
import json
from pathlib import Path

import pytest

from solvers.cli import main

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "katsura4.ms"


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def write(tmp_path, text):
    path = tmp_path / "system.ms"
    path.write_text(text)
    return str(path)


def test_degree_json_of_katsura4(capsys):
    code, out, _ = run(capsys, "degree", str(EXAMPLE), "--json")
    report = json.loads(out)
    assert code == 0
    assert report["degree"] == 16 and report["dimension"] == 0 and report["zero_dimensional"]
    assert len(report["primes"]) >= 3 and all(p > 2**30 for p in report["primes"]) and report["gb_size"] > 0 and report["seconds"] >= 0


def test_standard_basis_is_printed(capsys, tmp_path):
    code, out, _ = run(capsys, "degree", write(tmp_path, "x,y\n0\nx^2-1,y^2-x\n"), "--json", "--basis")
    assert code == 0 and sorted(json.loads(out)["standard_basis"]) == sorted(["1", "y", "x", "x*y"])


def test_positive_dimensional_and_inconsistent(capsys, tmp_path):
    _, out, _ = run(capsys, "degree", write(tmp_path, "x,y,z\n0\nx*y-z\n"), "--json")
    report = json.loads(out)
    assert report["degree"] is None and report["dimension"] == 2 and not report["zero_dimensional"]
    _, out, _ = run(capsys, "degree", write(tmp_path, "x,y\n7\nx*y+1,x*y+2\n"), "--json")
    report = json.loads(out)
    assert report["degree"] == 0 and report["dimension"] == -1 and report["primes"] == [7]


def test_zero_polynomials_leave_the_ideal_unchanged(capsys, tmp_path):
    _, out, _ = run(capsys, "degree", write(tmp_path, "x,y\n0\nx^2-1,0,x-x,y^3-2\n"), "--json")
    assert json.loads(out)["degree"] == 6


def test_saturation_removes_a_planted_point(capsys, tmp_path):
    path = write(tmp_path, "x,y\n0\nx*(x-1),x*(y-2),y*(y-2)\n")  # points (0,0) and (1,2), plus (0,2)
    _, out, _ = run(capsys, "degree", path, "--json")
    assert json.loads(out)["degree"] == 3
    _, out, _ = run(capsys, "degree", path, "--json", "--saturate", "x")
    assert json.loads(out)["degree"] == 1


@pytest.mark.parametrize(
    "text, args, fragment",
    [
        ("x,y\n0\nx+q\n", (), "unknown variable 'q'"),
        ("x,y\n8\nx+y\n", (), "not prime"),
        ("x,y\n0\n", (), "empty"),
        ("x,y\n0\nx+*y\n", (), "line 3"),
        ("x,y\n7\nx+y\n", ("--prime", "11"), "conflicts"),
        ("x,y\n0\nx+y\n", ("--prime", "9"), "not prime"),
        ("x,y\n0\nx^2+y^2-1,x*y-2\n", ("--max-cells", "1"), "exceeds the cap of 1 cells; raise --max-cells"),
        ("x,y\n0\nx^2+y^2-1,x*y-2\n", ("--max-memory", "1"), "memory cap of 1 B; raise --max-memory"),
    ],
)
def test_bad_input_is_one_line_with_status_2(capsys, tmp_path, text, args, fragment):
    code, out, err = run(capsys, "degree", write(tmp_path, text), *args)
    assert code == 2 and out == ""
    assert fragment in err and len(err.strip().splitlines()) == 1


def test_memory_share_in_help_is_the_engines():
    """--help names the default memory share as a literal (no numpy at parse time); it is F4's."""
    from analysis.engine.f4 import MEMORY_SHARE
    from solvers.cli import build_parser

    helps = [a.help for a in build_parser()._subparsers._group_actions[0].choices["degree"]._actions
             if "--max-memory" in a.option_strings]
    assert f"{MEMORY_SHARE:.0%}%" in helps[0]


@pytest.mark.slow
def test_direct_6r3s_degree_with_default_caps(capsys):
    """The direct 6r/3s system (18 unknowns): its 32299 x 18831 F4 matrix (608M cells, once refused by a
    400M-cell cap) needs about 200 MiB by the estimate; with default options the degree is 720 (~6 s)."""
    code, out, _ = run(capsys, "degree", "--tdoa", "6r3s", "--parametrization", "direct", "--equations", "all",
                       "--json")
    report = json.loads(out)
    assert code == 0 and report["degree"] == 720 and report["max_matrix"] == [32299, 18831]


def test_missing_file_is_reported(capsys, tmp_path):
    code, _, err = run(capsys, "degree", str(tmp_path / "nope.ms"))
    assert code == 2 and "cannot read" in err


def test_tdoa_formulation_6r4s_has_degree_22(capsys):
    code, out, _ = run(capsys, "degree", "--tdoa", "6r4s", "--equations", "B2,C2-C6,minors", "--json")
    report = json.loads(out)
    assert code == 0 and report["degree"] == 22 and report["formulation"] == "6r4s:B2,C2-C6,minors(10)"


def test_tdoa_export_and_unknown_equation(capsys, tmp_path):
    target = tmp_path / "x.m2"
    code, _, _ = run(capsys, "degree", "--tdoa", "6r4s", "--equations", "B2,C2-C6,minors", "--export", "m2", str(target))
    assert code == 0 and "ideal(" in target.read_text()
    code, _, err = run(capsys, "degree", "--tdoa", "6r4s", "--equations", "B2,Q7")
    assert code == 2 and "unknown equation 'Q7'" in err


def test_template_check_counts_relations(capsys):
    assert main(["template-check", "9r3s:C2-C9", "--family", "linear-offsets", "--degrees", "2-3", "--stop"]) == 0
    out = capsys.readouterr().out
    assert "|B| = 75 (grevlex basis), action o1" in out
    assert "degree 2: 480 x 597, 38/63 relations, incomplete" in out  # as in tables/template_evidence_9r3s.csv
    assert "degree 3: 960 x 1001, 46/63 relations, incomplete" in out


@pytest.mark.parametrize("args, fragment", [
    (["--degrees", "3-1"], "--degrees must be N or N-M"),
    (["--action", "q"], "unknown action 'q'"),
    (["--family", "bogus"], "unknown multiplier family"),
    (["--basis", "lex"], "unknown basis"),
])
def test_template_check_bad_input(capsys, args, fragment):
    assert main(["template-check", "9r3s:C2-C9", "--degrees", "1", *args]) == 2
    err = capsys.readouterr().err
    assert fragment in err and len(err.strip().splitlines()) == 1


def test_template_check_on_a_system_file(capsys, tmp_path):
    # two generic quadrics: 4 roots, complete in degree d1 + d2 - 1 = 3 (multipliers of degree 1)
    f = tmp_path / "q.ms"
    f.write_text("x, y\n0\n3*x^2 + 5*x*y - 7*y^2 + 2*x - 11*y + 13,\n-4*x^2 + 9*x*y + 6*y^2 - 8*x + 3*y - 5\n")
    assert main(["template-check", str(f), "--degrees", "0-3", "--stop"]) == 0
    out = capsys.readouterr().out
    assert "|B| = 4 (grevlex basis), action x, GF(65521), agreeing with 3 random 31-bit primes" in out
    assert "degree 0: 2 x 6, 2/3 relations, incomplete" in out
    assert "degree 1: 6 x 10, 3/3 relations, complete" in out and "degree 2" not in out
    g = tmp_path / "line.ms"
    g.write_text("x, y\n0\nx + y - 1\n")
    assert main(["template-check", str(g)]) == 2
    assert "not zero-dimensional" in capsys.readouterr().err


def test_lex_order_goes_through_fglm(capsys):
    """katsura-4 in lex: a shape basis (x4 of degree 16, every other variable linear), in milliseconds
    (F4 directly in lex once outgrew 24 GB)."""
    code, out, _ = run(capsys, "degree", str(EXAMPLE), "--order", "lex", "--gb", "--json")
    report = json.loads(out)
    assert code == 0 and report["degree"] == 16 and len(report["groebner_basis"]) == 5
    assert report["groebner_basis"][0].startswith("x4^16 - 8/7*x4^15 + ")  # over Q


def test_saturate_det_h_by_action_matrix_rank(capsys):
    """Table 2's 6r/3s (A+2B+5C): 181 as generated, 180 after saturating by det H."""
    args = ("degree", "--tdoa", "6r3s", "--equations", "A,B2,B3,C2-C6", "--prime", "65521", "--json")
    assert json.loads(run(capsys, *args, "--saturate-det-h")[1])["degree"] == 180


@pytest.mark.parametrize("config, equations, rank, dimension", [
    ("4r3s", "all", 6, 2), ("4r5s", "all", 8, None), ("6r4s", "C2-C6", 5, 4)])
def test_underdetermined_formulation_is_reported_from_the_jacobian(capsys, config, equations, rank, dimension):
    code, out, _ = run(capsys, "degree", "--tdoa", config, "--equations", equations, "--json")
    report = json.loads(out)
    assert code == 0 and report["jacobian_rank"] == rank and report["dimension"] == dimension
    assert not report["zero_dimensional"] and "add equations" in report["hint"]


def test_version(capsys):
    with pytest.raises(SystemExit):
        main(["--version"])
    assert capsys.readouterr().out.startswith("tdoa-workbench ")


HEAVY = ("sympy", "pandas", "matplotlib", "scipy", "numba")


@pytest.mark.parametrize("argv", [["degree", str(EXAMPLE.parent / "katsura7.ms")],
                                  ["degree", "--tdoa", "6r4s", "--equations", "B2,C2-C6,minors"]],
                         ids=["file", "tdoa"])
def test_degree_imports_only_what_it_needs(argv):
    """Start-up: ``degree`` imports none of the heavy libraries the other commands use (sympy alone
    took 0.4 s, the calibration package's scipy.sparse 0.25 s); flint only where a rank is needed."""
    import subprocess
    import sys

    code = ("import sys; from solvers.cli import main; status = main(sys.argv[1:]); "
            f"print(sorted({{m.split('.')[0] for m in sys.modules}} & set({HEAVY!r}))); sys.exit(status)")
    out = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout



SATURATED_2D = ("degree", "--tdoa", "6r3s", "--equations", "A,B2,B3,C2-C6", "--prime", "65521", "--json")
"""Table 2's 6r/3s: 181 as generated, 180 after saturating by det H (fast; the 3D case below is slow)."""
SATURATED_3D = ("degree", "--tdoa", "6r9s", "--dim", "3", "--equations", "A,B2,B3,B4,C2-C6,minors", "--json")
"""A 3D cell whose system has a spurious det H = 0 component of dimension 1; saturated, degree 38."""


def _msolve_dimension_degree(exe: str, path: Path, out: Path) -> tuple[int, int | None]:
    """msolve's own verdict on a file: (dimension, degree) from its rational parametrization, whose first
    entries are the dimension and, for dimension 0, [characteristic, variables, degree, ...]."""
    import re
    import subprocess

    done = subprocess.run([exe, "-t", "1", "-f", str(path), "-o", str(out)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    text = out.read_text()
    match = re.match(r"\s*\[\s*(-?\d+)\s*,\s*\[\s*(\d+)\s*,\s*(\d+)\s*,\s*(-?\d+)", text)
    if match:
        return int(match.group(1)), int(match.group(4))
    match = re.match(r"\s*\[\s*(-?\d+)\s*,", text)
    assert match, text[:200]
    return int(match.group(1)), None


@pytest.mark.parametrize("fmt", ["msolve", "m2", "singular"])
def test_export_carries_the_saturation(capsys, tmp_path, fmt):
    """--saturate-det-h --export writes t * det H - 1 after the equations, in every format; the msolve
    file read back has the printed degree (own engine; without t it would be 181)."""
    target = tmp_path / f"sat.{fmt}"
    code, out, _ = run(capsys, *SATURATED_2D, "--saturate-det-h", "--export", fmt, str(target))
    assert code == 0 and json.loads(out)["degree"] == 180
    text = target.read_text()
    assert "o3, t" in text or "o3,t" in text  # t appended after the unknowns
    assert text.count("*t") == 2  # t * det H, det H = h11*h22 - h12^2: one t per term
    if fmt == "msolve":
        code, out, _ = run(capsys, "degree", str(target), "--json")
        assert code == 0 and json.loads(out)["degree"] == 180


def test_export_of_a_file_carries_its_saturation(capsys, tmp_path):
    path = write(tmp_path, "x,y\n0\nx*(x-1),x*(y-2),y*(y-2)\n")
    target = tmp_path / "sat.ms"
    _, out, _ = run(capsys, "degree", path, "--json", "--saturate", "x", "--export", "msolve", str(target))
    assert json.loads(out)["degree"] == 1
    assert target.read_text().splitlines()[0] == "x,y,t"
    _, out, _ = run(capsys, "degree", str(target), "--json")
    assert json.loads(out)["degree"] == 1


def _need_msolve() -> str:
    from analysis.engine.msolve import INSTALL_HINT, find_msolve

    exe = find_msolve()
    if exe is None:
        pytest.skip(f"msolve not installed ({INSTALL_HINT})")
    return exe


def test_msolve_counts_the_exported_saturation(capsys, tmp_path):
    """msolve itself, on the exported file: 180, the degree printed, not the unsaturated 181."""
    exe = _need_msolve()
    saturated = tmp_path / "sat.ms"
    run(capsys, *SATURATED_2D, "--saturate-det-h", "--export", "msolve", str(saturated))
    assert _msolve_dimension_degree(exe, saturated, tmp_path / "sat.out") == (0, 180)


@pytest.mark.slow
def test_msolve_counts_the_exported_saturation_3d(capsys, tmp_path):
    """3D 6r/9s: msolve finds degree 38 in the saturated export, dimension > 0 in the plain one (the
    det H = 0 component); the own engine agrees on both files (about 10 s per formulation build)."""
    exe = _need_msolve()
    saturated, plain = tmp_path / "sat.ms", tmp_path / "plain.ms"
    code, out, _ = run(capsys, *SATURATED_3D, "--saturate-det-h", "--export", "msolve", str(saturated))
    assert code == 0 and json.loads(out)["degree"] == 38
    run(capsys, *SATURATED_3D, "--export", "msolve", str(plain))
    assert _msolve_dimension_degree(exe, saturated, tmp_path / "sat.out") == (0, 38)
    assert _msolve_dimension_degree(exe, plain, tmp_path / "plain.out")[0] > 0
    assert json.loads(run(capsys, "degree", str(saturated), "--json")[1])["degree"] == 38
    assert json.loads(run(capsys, "degree", str(plain), "--json")[1])["dimension"] == 1
