"""solvers.system_solve and the ``solve`` verb: every solution, checked against known roots and counts."""
import csv
import io
import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from analysis.engine.io import parse_msolve
from analysis.formulations.parametric import parse
from solvers.cli import main
from solvers.system_solve import SolveError, instance_system, parameter_values, solve_system

ROOT = Path(__file__).resolve().parents[1]


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def katsura_text(n: int) -> str:
    """katsura-n over Q in msolve's format (n + 1 unknowns, 2^n solutions)."""
    v = [f"u{i}" for i in range(n + 1)]

    def u(i):
        return v[abs(i)] if abs(i) <= n else None

    polys = ["+".join(f"{u(l)}*{u(m - l)}" for l in range(-n, n + 1) if u(l) and u(m - l)) + f"-{v[m]}"
             for m in range(n)]
    polys.append("+".join([v[0]] + [f"2*{x}" for x in v[1:]]) + "-1")
    return ",".join(v) + "\n0\n" + ",\n".join(polys) + "\n"


def test_known_roots_are_found_and_real_ones_marked():
    """(x^2 - 2)(x - 3) = 0, y = x + 1/2: three real points; x^2 + 1 = 0, y = x: two complex ones."""
    result = solve_system(parse_msolve("x,y\n0\n(x^2-2)*(x-3),y-x-1/2\n"))
    assert result.degree == 3 and result.complete and result.n_real == 3
    xs = sorted(s.values[0].real for s in result.solutions)
    assert np.allclose(xs, [-np.sqrt(2), np.sqrt(2), 3], atol=1e-12)
    assert all(abs(s.values[1] - s.values[0] - 0.5) < 1e-12 for s in result.solutions)
    result = solve_system(parse_msolve("x,y\n0\nx^2+1,y-x\n"))
    assert result.n_real == 0 and sorted(round(s.values[0].imag) for s in result.solutions) == [-1, 1]


def test_katsura6_all_64_solutions():
    """katsura-6: degree 64 (the classic count); every solution found, distinct and simple, residuals tiny."""
    result = solve_system(parse_msolve(katsura_text(6)))
    assert result.degree == 64 and len(result.solutions) == 64 and result.complete
    assert result.max_residual < 1e-8
    assert 0 < result.n_real < 64 and result.n_real % 2 == 0  # u -> -u on odd indices keeps real roots paired


def test_parametric_instance_with_nonzero_condition():
    """circle.sys: x^2 + y^2 = a, x y - b x + c = 0, x != 0: 4 solutions at a=5, b=1, c=3/2; t is hidden."""
    system = parse((ROOT / "examples" / "circle.sys").read_text(), "circle.sys")
    instance = instance_system(system, {"a": Fraction(5), "b": Fraction(1), "c": Fraction(3, 2)})
    assert instance.variables[:2] == ("x", "y") and instance.nvars == 3
    result = solve_system(instance, hidden=2)
    assert result.degree == 4 and result.complete and result.unknowns == ("x", "y")
    for s in result.solutions:
        x, y = s.values
        assert abs(x * x + y * y - 5) < 1e-10 and abs(x * y - x + 1.5) < 1e-10 and abs(x) > 1e-6


def test_parameter_values_are_read_exactly_and_checked():
    assert parameter_values(["a=3/4", "b=-1.25e-3", "c = 7"]) == {"a": Fraction(3, 4), "b": Fraction(-1, 800), "c": 7}
    for bad in (["a"], ["a=nan"], ["a=1", "a=2"], ["a=__import__('os')"]):
        with pytest.raises(SolveError):
            parameter_values(bad)


def test_characteristic_p_and_positive_dimension_are_refused():
    with pytest.raises(SolveError, match="characteristic 7"):
        solve_system(parse_msolve("x\n7\nx^2-1\n"))
    with pytest.raises(SolveError, match="not zero-dimensional"):
        solve_system(parse_msolve("x,y\n0\nx*y-1\n"))
    result = solve_system(parse_msolve("x,y\n0\nx*y-1,x*y-2\n"))
    assert result.degree == 0 and result.solutions == () and result.dimension == -1


def test_cli_text_json_csv(capsys, tmp_path):
    path = tmp_path / "k4.ms"
    path.write_text(katsura_text(4))
    code, out, err = run(capsys, "solve", str(path), "--json")
    report = json.loads(out)
    assert code == 0 and report["degree"] == 16 and report["n_solutions"] == 16 and report["complete"]
    assert report["method"] == "action matrix over Q" and "[solve]" in err
    assert all(isinstance(v, float) for s in report["solutions"] if s["real"] for v in s["values"].values())
    code, out, _ = run(capsys, "solve", str(path), "--csv")
    rows = list(csv.DictReader(io.StringIO(out)))
    assert code == 0 and len(rows) == 16 and set(rows[0]) >= {"index", "real", "residual", "u0_re", "u4_im"}
    code, out, _ = run(capsys, "solve", str(ROOT / "examples" / "circle.sys"), "--param", "a=5", "--param", "b=1",
                       "--param", "c=3/2")
    assert code == 0 and "degree 4" in out and "4 solutions, 2 real" in out


@pytest.mark.parametrize("text, args, fragment", [
    ("x,y\n0\nx^2-1,y-1\n", ("--param", "a=1"), "no parameters"),
    ("x\n7\nx^2-1\n", (), "characteristic 7"),
    ("x,y\n0\nx*y-1\n", (), "not zero-dimensional"),
    ("unknowns: x\nparameters: a\nequations:\nx^2 - a\n", (), "missing a"),
    ("unknowns: x\nparameters: a\nequations:\nx^2 - a\n", ("--param", "a=1", "--param", "q=2"), "q not a parameter"),
])
def test_cli_errors_are_one_line(capsys, tmp_path, text, args, fragment):
    path = tmp_path / "s.txt"
    path.write_text(text)
    code, out, err = run(capsys, "solve", str(path), *args)
    assert code == 2 and out == "" and fragment in err and len(err.strip().splitlines()) == 1


def _network_values(seed: int = 1):
    from solvers.synthetic import random_network

    net = random_network(6, 3, rng=np.random.default_rng(seed))
    F = net.measurements()
    return net, {f"f{i + 1}_{j + 1}": Fraction(float(F[i, j])) for i in range(6) for j in range(3)}


def test_homotopy_route_with_the_committed_6r3s_solver(monkeypatch):
    """The homotopy route (track, polish on the exact instance, check) on the committed 6r/3s solver (its
    system has definitions and a nonzero condition): 180 points, the network's own root (H, b, o) among
    the real ones."""
    import solvers.system_solve as ss
    from solvers.generate import solver_system
    from solvers.generated import tdoa_6r3s_homotopy180 as module
    from solvers.synthetic import true_root

    spec = json.loads((ROOT / "solvers" / "generated" / "tdoa_6r3s_homotopy180.json").read_text())
    monkeypatch.setattr(ss, "generated_solver", lambda *args, **kw: (module, spec))
    net, values = _network_values()
    result = ss.solve_by_homotopy(solver_system("6r3s"), values)
    assert result.method == ss.HOMOTOPY and result.degree == 180 and len(result.solutions) == 180
    assert result.max_residual < 1e-6 and "certified over GF(p)" in result.certificate
    assert result.complete == ("NOT" not in result.status)
    H, b, o = true_root(net)
    truth = np.array([H[0, 0], H[0, 1], H[1, 1], *b, *o])
    assert min(np.abs(np.array(s.values) - truth).max() for s in result.solutions if s.real) < 1e-8


@pytest.mark.slow
def test_direct_6r3s_all_720_solutions(capsys, tmp_path, monkeypatch):
    """`solve 6r3s-tdoa2d-direct:all` with a seeded network's measurements: the generated homotopy solver
    (about 60 s the first time, into a fresh cache) gives all 720 solutions, residuals below 1e-8."""
    monkeypatch.setenv("TDOA_WORKBENCH_CACHE", str(tmp_path / "cache"))
    _, values = _network_values()
    params = tmp_path / "f.txt"
    params.write_text("".join(f"{k} = {float(v)!r}\n" for k, v in values.items()))
    code, out, _ = run(capsys, "solve", "6r3s-tdoa2d-direct:all", "--params", str(params), "--json")
    report = json.loads(out)
    assert code == 0 and report["degree"] == 720 and report["n_solutions"] == 720 and report["complete"]
    assert report["max_residual"] < 1e-8 and report["method"] == "parameter homotopy" and report["n_real"] > 0


@pytest.mark.slow
def test_circle_by_both_methods(capsys, tmp_path, monkeypatch):
    """examples/circle.sys: the homotopy route (generated into a fresh cache) and the action matrix agree."""
    monkeypatch.setenv("TDOA_WORKBENCH_CACHE", str(tmp_path / "cache"))
    args = ("solve", str(ROOT / "examples" / "circle.sys"), "--param", "a=5", "--param", "b=1", "--param", "c=3/2",
            "--json")
    points = []
    for method in ("action-matrix", "homotopy"):
        code, out, _ = run(capsys, *args, "--method", method)
        report = json.loads(out)
        assert code == 0 and report["complete"] and report["n_solutions"] == 4
        points.append(sorted((complex(*v) if isinstance(v, list) else complex(v) for v in
                              (s["values"]["x"] for s in report["solutions"])), key=lambda z: (z.real, z.imag)))
    assert np.allclose(points[0], points[1], atol=1e-10)
