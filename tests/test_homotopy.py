"""Tests for the general solver generator: parametric systems, the compiled tracker, monodromy, and the
committed homotopy solvers (fresh emission, complete start systems, known roots found)."""
from __future__ import annotations

import importlib
import json
import os

import numpy as np
import pytest
import sympy

from analysis.formulations.parametric import ParametricError, from_formulation, parse
from solvers.continuation import monodromy as md
from solvers.continuation import tracker
from solvers.continuation import tracking as tk
from solvers.generate import GENERATED_DIR, MONODROMY_CHECKPOINTS, SOLVERS
from solvers.methods import homotopy as hm

HOMOTOPY_SPECS = sorted(f for f in os.listdir(GENERATED_DIR) if "_homotopy" in f and f.endswith(".json"))


def _spec(name: str) -> tuple[str, dict]:
    with open(os.path.join(GENERATED_DIR, name), encoding="utf-8") as fh:
        text = fh.read()
    return text, hm.load_spec(text)


def _module(stem: str):
    return importlib.import_module(f"solvers.generated.{stem}")


# --------------------------------------------------------------------------------------------------
# parametric systems
# --------------------------------------------------------------------------------------------------

USER = """
# circle and hyperbola
unknowns: x, y
parameters: a, b, c
equations:
x^2 + y^2 - a
x*y - b*x + c
"""


def test_user_system_counts_like_sympy():
    system = parse(USER, "user")
    report = system.degree()
    # sympy's Groebner basis of one GF(p) instance, same parameter values
    q, _ = system.sample_gf(65521, 0)
    x, y = sympy.symbols("x y")
    a, b, c = q
    gb = sympy.groebner([x**2 + y**2 - a, x * y - b * x + c], x, y, modulus=65521, order="grevlex")
    lead = [sympy.Poly(g, x, y).monoms(order="grevlex")[0] for g in gb.exprs]
    standard = [(i, j) for i in range(10) for j in range(10) if not any(i >= l[0] and j >= l[1] for l in lead)]
    assert report.degree == len(standard) == 4


@pytest.mark.parametrize("text, match", [
    ("unknowns: x\nparameters: a\nequations:\nx^2 - z\n", "line 4, column 7: unknown name 'z'"),
    ("unknowns: x\nparameters: a, b\nequations:\nx^2 - a\n", None),
    ("unknowns: x\nequations:\nx - 1\n", "no parameters: a solver needs data"),  # a plain system: nothing to vary
    ("unknowns: x\nparameters: a\nequations:\nsin(x) - a\n", "unknown name 'sin'.*polynomial"),
    ("unknowns: x\nparameters: a\nequations:\nx^2 - 0.5.1*a\n", "line 4, column 7: malformed number '0.5.1'"),
    ("parameters: a\nequations:\nx - a\n", "unknowns"),
    ("unknowns: x\nparameters: x\nequations:\nx\n", "both"),
])
def test_user_system_errors_are_one_line(text, match):
    if match is None:  # parses, but the generator refuses a parameter that does not occur
        with pytest.raises(ParametricError, match="do not occur"):
            parse(text).check_parameters_occur()
        return
    with pytest.raises(ParametricError, match=match):
        parse(text).check_parameters_occur()


def test_factored_tdoa_system_equals_the_expanded_formulation():
    from analysis.formulations.tdoa import Formulation, symbolic_equations

    system = from_formulation("7r3s:B2,B3,C2-C7")
    ref = symbolic_equations(Formulation.parse("7r3s:B2,B3,C2-C7"))
    aux = {}
    for sym, expr in zip(system.aux_symbols, system.aux_exprs):
        aux[sym] = expr.subs(aux)
    for got, want in zip(system.exprs, ref.values()):
        assert sympy.expand(got.subs(aux) - want) == 0


# --------------------------------------------------------------------------------------------------
# tracker
# --------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def system_9r3s():
    system = from_formulation("9r3s:C2-C9")
    exps, eq = tk.structure(system)
    return system, tk.load_coefficients(tk.coefficient_source(system)), tracker.SystemStructure.from_exponents(exps, eq)


def test_tracker_evaluation_matches_sympy_and_finite_differences(system_9r3s):
    system, coefficients, st = system_9r3s
    rng = np.random.default_rng(4)
    q0, q1 = rng.normal(size=(2, 27)) + 1j * rng.normal(size=(2, 27))
    x = rng.normal(size=8) + 1j * rng.normal(size=8)
    G = tracker.segment_coefficients(coefficients, q0, q1, 4)
    s = 0.37
    H, J, Hs = tracker.evaluate(st, G, x[None], np.array([s]))
    # value against sympy at q(s)
    qs = q0 + s * (q1 - q0)
    subs = dict(zip(system.q_symbols, qs)) | dict(zip(system.x_symbols, x))
    for sym, expr in zip(system.aux_symbols, system.aux_exprs):
        subs[sym] = complex(expr.subs(subs))
    ref = np.array([complex(e.subs(subs)) for e in system.exprs])
    assert np.max(np.abs(H[0] - ref)) < 1e-11 * np.max(np.abs(ref))
    eps = 1e-6
    for k in range(8):
        dx = np.zeros(8, complex)
        dx[k] = eps
        fd = (tracker.evaluate(st, G, (x + dx)[None], np.array([s]))[0] - tracker.evaluate(st, G, (x - dx)[None], np.array([s]))[0]) / (2 * eps)
        assert np.max(np.abs(fd[0] - J[0, :, k])) < 1e-6 * np.max(np.abs(J[0]))
    fd = (tracker.evaluate(st, G, x[None], np.array([s + eps]))[0] - tracker.evaluate(st, G, x[None], np.array([s - eps]))[0]) / (2 * eps)
    assert np.max(np.abs(fd[0] - Hs[0])) < 1e-6 * np.max(np.abs(Hs[0]))


def test_tracker_follows_a_known_path():
    # x^2 = 1 + 3 s, x y = 2 - s: the path from (1, 2) ends at (2, 1/2)
    st = tracker.SystemStructure.from_exponents(np.array([[2, 0], [0, 0], [1, 1], [0, 0]]), np.array([0, 0, 1, 1]))
    G = np.zeros((1, 4, 2), complex)
    G[0, :, 0] = [1, -1, 1, -2]
    G[0, :, 1] = [0, -3, 0, 1]
    x, stats = tracker.track(st, G, np.array([[1.0, 2.0]], complex))
    assert stats[0, 0] == 0
    assert np.allclose(x[0], [2.0, 0.5], atol=1e-13)


def test_monodromy_finds_every_root_of_a_user_system():
    system = parse(USER, "user")
    coefficients = tk.load_coefficients(tk.coefficient_source(system))
    spec, _, report = hm.build(system, 4, options=tk.HomotopyOptions(seed=3, verify_trials=0))
    assert len(spec["start_roots"]) == 4
    solver = tk.HomotopySolver(spec, coefficients)
    q = np.array([[2.0, 0.3, 0.1]])
    roots = solver.roots(q)[0]
    assert np.all(np.isfinite(roots)) and not tk._has_duplicates(roots)
    assert solver.residual(roots, q).max() < 1e-12


def test_monodromy_that_cannot_reach_the_count_is_an_error():
    system = parse(USER, "user")
    with pytest.raises(tk.HomotopyError, match="of the certified 5 roots"):
        hm.build(system, 5, options=tk.HomotopyOptions(seed=3, verify_trials=0, stall_loops=3))


def test_excluded_locus_is_relative_to_the_condition_not_to_the_point():
    # det H = h11 h22 - h12^2: zero when it cancels, not merely when H is small next to the offsets
    system = parse("unknowns: h11, h12, h22, o\nparameters: a\nnonzero: h11*h22 - h12**2\nequations:\n"
                   "h11 - a\nh12 - a\nh22 - a\no - a\n", "deth")
    mask = md._excluded(system, np.array([1.0]))
    x = np.array([[1e-4, 5e-4, -2.6e-3, 130.0],   # genuine root of the 5r/5s start system's kind
                  [1e-4, 2e-4, 4e-4, 130.0],      # det H = 0 exactly (h12^2 = h11 h22)
                  [1e-12, -2e-12, 3e-12, 130.0],  # H = 0 to rounding (a spurious root of 5r/4s's squared system)
                  [3.0, 1.0, 2.0, 0.0]])
    assert mask(x).tolist() == [False, True, True, False]


@pytest.mark.parametrize("index", [52, 65])
def test_every_path_of_a_failing_instance_takes_the_same_detour(index):
    # seeded networks 52 and 65 of bench_solvers (seed 0): the direct segment passes so close to a
    # singular point that one path stalls even with tight steps while another takes its root; routes
    # through a midpoint permute the endpoints, so all paths of the instance must take the same one
    from solvers.synthetic import random_network, true_root

    module = importlib.import_module("solvers.generated.tdoa_6r3s_homotopy180")
    rng = np.random.default_rng(0)
    net = [random_network(6, 3, rng) for _ in range(index + 1)][index]
    H, b, o = true_root(net)
    x = np.concatenate([[H[0, 0], H[0, 1], H[1, 1]], b, o])
    roots = module.solve(net.measurements())
    assert np.all(np.isfinite(roots)) and not tk._has_duplicates(roots)
    assert np.min(np.linalg.norm(roots - x, axis=1)) / np.linalg.norm(x) < 1e-9


@pytest.mark.parametrize("index, predictor", [(164, None), (679, "rk4")])
def test_further_start_systems_find_a_root_the_direct_segment_loses(index, predictor, monkeypatch):
    # seeded networks of bench_solvers (4r/5s, seed 0). 164: the true root's path heads towards infinity on
    # the direct segment (backtracked from the truth, |x| grows from 2 to 126 before s = 0.53, where it
    # stalls); the segments from the spec's further start systems reach it. 679, with RK4 plain tracks (the
    # spec's Pade predictor reaches it on the direct segment): its path stalls at s = 1 - 3e-5 on the direct
    # segment (an ill-conditioned root) and is kept for Newton's method on the target.
    import dataclasses

    from analysis.formulations.positions import _to_gauge
    from solvers.subsystem import orbits_from_receivers
    from solvers.synthetic import random_network

    module = importlib.import_module("solvers.generated.tdoa_4r5s_homotopy344")
    solver = module.solver()
    if predictor is not None:
        monkeypatch.setattr(solver, "options", dataclasses.replace(solver.options, predictor=predictor))
    assert len(solver.starts) == 3 and all(len(x) == module.PATHS for _, x in solver.starts)
    rng = np.random.default_rng(0)
    net = [random_network(4, 5, rng) for _ in range(index + 1)][index]
    truth = orbits_from_receivers(_to_gauge(np.asarray(net.receivers, float), np.asarray(net.transmitters, float))[0])
    direct = hm.solve_scaled(solver, net.measurements(), module.CONFIG, module.SCALE_POWERS, plain=True)
    assert not np.nanmin(np.linalg.norm(direct - truth, axis=1)) / np.linalg.norm(truth) < 1e-6
    roots = module.solve(net.measurements())
    assert not tk._has_duplicates(roots)  # a few roots near infinity stay lost (NaN rows)
    assert np.nanmin(np.linalg.norm(roots - truth, axis=1)) / np.linalg.norm(truth) < 1e-9


def test_pool_keeps_one_copy_of_each_root_and_pads_with_nan():
    nan = np.nan
    a = np.array([[1.0, 0.0], [1.0, 0.0], [nan, nan], [3.0, 0.0]], complex)   # a jumped pair, a lost path
    b = np.array([[2.0, 0.0], [3.0, 1e-9], [1.0, 0.0], [nan, nan]], complex)  # the missing root 2
    pooled = tk._pool([a, b])
    assert pooled[:3].real.tolist() == [[1, 0], [3, 0], [2, 0]] and np.all(np.isnan(pooled[3]))
    assert tk._distinct(np.full((2, 2), nan)).shape == (0, 2)
    # ordered by the next Newton step: a surplus drops the unconverged copy (4r/5s network 85's case)
    a = np.array([[1.0, 0.0], [5.0, 0.0], [nan, nan]], complex)
    b = np.array([[2.0, 0.0], [1.0 + 1e-3, 0.0], [nan, nan]], complex)  # 1.001: an unconverged copy of 1
    step = np.array([1e-16, 1e-15, np.inf, 1e-16, 1e-3, np.inf])
    assert tk._pool([a, b], step)[:3].real.tolist() == [[1, 0], [2, 0], [5, 0]]


@pytest.mark.parametrize("name", [n for n in HOMOTOPY_SPECS if _spec(n)[1].get("full_system")])
def test_tracked_roots_are_exactly_the_full_systems(name):
    from analysis.formulations.parametric import from_formulation
    from solvers.generate import SOLVERS

    _, spec = _spec(name)
    label = spec["name"].split("_")[1]
    full = from_formulation(SOLVERS[label], saturate_det_h=True)
    assert full.name == spec["full_system"]["system"] and len(full.equations) == spec["full_system"]["equations"]
    module = _module(name[:-5])
    all_roots = tk.HomotopySolver({k: v for k, v in spec.items() if k != "full_system"}, module.coefficients)
    res = md.system_residuals(full, all_roots.x0, all_roots.q0)
    tracked = np.zeros(len(res), dtype=bool)
    tracked[spec["full_system"]["tracked"]] = True
    assert res[tracked].max() < hm.FULL_TOL and res[~tracked].min() > hm.FULL_GAP


def test_squared_system_tracks_only_the_full_systems_roots(tmp_path):
    # x^2 = a, (y - x)(y + x - b) = 0 has 4 roots in two families (y = x, y = b - x); the full system
    # (x = y too) has the 2 of the first: paths from them stay in it, so only they are tracked. The
    # start holds a root of each family (monodromy cannot cross from one to the other)
    import importlib.util

    from solvers.generate import generate

    square_ = parse("unknowns: x, y\nparameters: a, b\nequations:\nx^2 - a\ny^2 - a + b*x - b*y\n", "square")
    full = parse("unknowns: x, y\nparameters: a, b\nequations:\nx^2 - a\ny^2 - a + b*x - b*y\nx - y\n", "full")
    def start(rng):
        a, b = 2.0 + 1.0j, -0.5 + 0.3j
        return np.array([a, b]), np.array([[np.sqrt(a), np.sqrt(a)], [np.sqrt(a), b - np.sqrt(a)]])

    result = generate(square_, out=str(tmp_path), name="toy", start=start, full=full)
    assert result.degree == 4 and result.candidates == 2 and result.report["tracked"] == "2 of 4"
    spec = json.loads((tmp_path / (result.name + ".json")).read_text())
    assert spec["full_system"]["degree"] == 2 and len(spec["start_roots"]) == 4
    mod_spec = importlib.util.spec_from_file_location("toy_solver", tmp_path / (result.name + ".py"))
    module = importlib.util.module_from_spec(mod_spec)
    mod_spec.loader.exec_module(module)
    roots = module.solve(np.array([4.0, 1.0]))
    assert module.PATHS == 2 and roots.shape == (2, 2)
    assert np.allclose(sorted(roots[:, 0].real), [-2, 2]) and np.allclose(roots[:, 0], roots[:, 1])
    with pytest.raises(tk.HomotopyError, match="differ"):
        generate(square_, out=str(tmp_path), name="t", start=start, full=parse("unknowns: x, z\nparameters: a, b\nequations:\nx - a\nz - b\n", "other"))


def test_non_square_system_is_refused():
    system = parse("unknowns: x, y\nparameters: a\nequations:\nx - a\n", "thin")
    with pytest.raises(tk.HomotopyError, match="square"):
        hm.build(system, 1)


# --------------------------------------------------------------------------------------------------
# committed solvers
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("label", sorted(SOLVERS))
def test_every_registered_solver_is_committed_with_its_own_spec(label):
    """One spec and one module per registered configuration; the module was emitted from that very spec
    (its SPEC_SHA256 is the file's hash), solves the registered system, and its name carries its degree."""
    import hashlib

    from solvers.generate import POSITIONS, solver_system

    specs = [f for f in os.listdir(GENERATED_DIR) if f.startswith(f"tdoa_{label}_") and f.endswith(".json")
             and "_action" not in f]  # an action-matrix solver sits beside (tests/test_action_matrix.py)
    assert len(specs) == 1, specs
    name = specs[0][:-5]
    module = _module(name)
    with open(os.path.join(GENERATED_DIR, specs[0]), "rb") as fh:
        raw = fh.read()
    assert module.SPEC_FILE == specs[0] and module.SPEC_SHA256 == hashlib.sha256(raw).hexdigest()
    spec = json.loads(raw)
    assert module.SYSTEM == spec.get("system", spec.get("formulation"))
    assert module.DEGREE == spec["degree"]
    if "_pencil" in name:  # a pencil's name carries its size, the others' their root count
        assert name.endswith(f"pencil{module.SIZE[0]}") and module.SYSTEM == SOLVERS[label]
    elif label in POSITIONS:  # building the positions system takes 10 s: its name is the label's
        assert name.endswith(f"homotopy{module.DEGREE}") and module.SYSTEM == f"{label}:positions-{POSITIONS[label]}"
    elif "_homotopy" in name:  # its paths: the roots, or one per orbit of a group (7r5s3d: 2321 of 18568)
        assert name.endswith(f"homotopy{module.PATHS}") and module.SYSTEM == solver_system(label).name
        assert module.DEGREE == module.PATHS * getattr(module, "GROUP_ORDER", 1)
    else:
        assert name.endswith(f"kernel{module.DEGREE}") and module.SYSTEM == SOLVERS[label]


@pytest.mark.parametrize("name", HOMOTOPY_SPECS)
def test_start_system_is_complete(name):
    _, spec = _spec(name)
    module = _module(name[:-5])
    solver = module.solver()
    # as many distinct roots as certified over GF(p), each a root of the start instance to rounding
    if "evidence" in spec:  # built on monodromy alone (not certified): one root per orbit of its group
        evidence = spec["evidence"]
        assert evidence["method"] == "monodromy" and "certified" not in spec
        assert len(spec["start_roots"]) == spec["paths"] == evidence["orbits"]
        assert spec["degree"] == evidence["degree"] == spec["paths"] * spec["group"]["order"]
    else:
        assert len(spec["start_roots"]) == spec["certified"]["degree"]
        assert len(spec["certified"]["primes"]) == 2
    full = spec.get("full_system")
    if "evidence" in spec:
        pass
    elif full:  # a squared system: the tracked roots are the full system's, certified on two primes x two seeds
        assert spec["paths"] == spec["degree"] == full["degree"] == len(full["tracked"]) < spec["certified"]["degree"]
        assert len(full["primes"]) == 2 and len(full["seeds"]) == 2
    else:
        assert spec["paths"] == spec["degree"] == spec["certified"]["degree"]
    assert solver.x0.shape == (spec["paths"], len(spec["unknowns"]))
    # a Newton step no longer moves them (to the build's tolerance)
    step = solver.newton(solver.x0, solver.q0[None]) - solver.x0
    # Newton noise ~ eps x condition: degree-10 positions equations are ill-conditioned, and so are the 3D
    # TOA B_j, j >= 5, whose coefficients carry det(M)^2 (degree 14 in the data; 4r/6s: 4e-9 measured); a
    # monodromy checkpoint's roots are checked to its 1e-8 (solvers.generate): 6r/6s 3D start root 1473 (norm 726)
    # has cond(J) = 1.1e10 at q0 and its Newton steps hover at 2e-9 to 8e-9 (the others' below 1e-10)
    tol = (1e-7 if "positions" in spec["system"] else 1e-8 if spec["coefficient_degree"] > 10 or "evidence" in spec
           else 1e-9)
    assert np.max(np.linalg.norm(step, axis=1) / (1 + np.linalg.norm(solver.x0, axis=1))) < tol
    assert not tk._has_duplicates(solver.x0)


def _known_root_errors(module, seeds: int) -> np.ndarray:
    from analysis.formulations.tdoa import sample_real_instance

    from analysis.formulations.positions import sample_real_positions

    m, n = module.CONFIG
    errs = []
    for seed in range(seeds):
        if "positions" in module.SYSTEM:
            F, x = sample_real_positions(m, n, seed, module.SYSTEM.split("positions-")[1])
        else:
            inst = sample_real_instance(module.SYSTEM.split(":")[0], seed)  # the model and dimension of the label
            F, x = np.array(inst.F), np.array(inst.root)
        roots = module.solve(F)
        assert roots.shape == (module.PATHS, len(module.UNKNOWNS))
        if getattr(module, "GROUP_ORDER", 1) > 1:  # one root per orbit of a group: compare with every image
            roots = hm.expand_orbits(roots, _spec(module.SPEC_FILE)[1])
        errs.append(np.nanmin(np.linalg.norm(roots - x, axis=1)) / np.linalg.norm(x))
    return np.array(errs)


#: Solvers with more paths than this take seconds per instance: 3 seeded instances here (the failure
#: rate on 100+ networks is measured by scripts/bench_solvers.py, tables/solvers.csv).
FAST_PATHS = 200


#: Solvers whose one-instance known-root test takes minutes (6r/6s: 266 s at load 7): run with TDOA_LONG_TESTS=1.
LONG_SPECS = ("6r6s3d",)
_LONG = pytest.mark.skipif(not os.environ.get("TDOA_LONG_TESTS"), reason="minutes: set TDOA_LONG_TESTS=1 to run it")


@pytest.mark.parametrize("name", [pytest.param(n, marks=[pytest.mark.slow] + ([_LONG] if n.split("_")[1] in LONG_SPECS else []))
                                  if n.split("_")[1] in MONODROMY_CHECKPOINTS else n
                                  for n in HOMOTOPY_SPECS])  # (the 3D minimal cells: 7r/5s 20-60 s a solve, 6r/6s 60 s)
def test_known_root_among_candidates(name):
    module = _module(name[:-5])
    positions = "positions" in module.SYSTEM
    errs = _known_root_errors(module, 10 if module.PATHS <= FAST_PATHS else 3 if module.PATHS <= 1000 else 1)
    # raw endpoints (no polishing); the degree-10 positions equations are ill-conditioned near
    # nearly collinear receivers (calibrate's refinement polishes on the range equations)
    if positions:
        assert errs.max() < 1e-7, errs
    else:  # as the earlier 9r3s tests: every seed to 1e-9, median below 1e-11
        assert errs.max() < 1e-9 and np.median(np.log10(errs)) < -11, errs



@pytest.mark.parametrize("name", HOMOTOPY_SPECS)
def test_committed_spec_carries_its_configurations_step_control(name):
    # the generator's per-configuration step control (solvers.generate.STEP_CONTROL) is in the committed
    # spec, and the solver tracks with it: the plain track's options and TIGHT with the retrack fields replaced
    import dataclasses

    from solvers.generate import STEP_CONTROL

    _, spec = _spec(name)
    label = spec["name"].split("_")[1]
    control = dict(STEP_CONTROL.get(label, {}))
    starts = control.pop("starts", 1)  # a count: the spec holds the further start systems
    for key, fields in control.items():
        assert {k: spec[key][k] for k in fields} == fields
    solver = tk.HomotopySolver(spec, _module(name[:-5]).coefficients)
    assert len(spec.get("starts", [])) == starts - 1 and len(solver.starts) == starts
    assert solver.retrack == dataclasses.replace(tracker.TIGHT, **spec.get("retrack", {}))
    assert solver.options == tracker.TrackerOptions(**spec.get("tracker", {}))
    assert set(spec.get("retrack", {})) <= {f.name for f in dataclasses.fields(tracker.TrackerOptions)}


def test_add_new_by_sorted_projections_decides_as_the_full_comparison():
    """monodromy.add_new compares each endpoint only with the roots whose projection on a fixed direction is
    within reach; its result is the same as comparing with every root and image, in order (random roots,
    endpoints near roots or their images at 1e-9..1e-5, new points, repeats among the new ones)."""
    from solvers.instances import gauge_reflections

    def reference(roots, xs, group=None):
        images = np.ones((1, roots.shape[1])) if group is None else np.asarray(group)
        for x in xs:
            d = min(np.min(np.linalg.norm(roots - g * x, axis=1)) for g in images)
            if d > 1e-6 * (1.0 + np.linalg.norm(x)):
                roots = np.vstack([roots, x])
        return roots

    rng = np.random.default_rng(1)
    group = gauge_reflections(["r2x", "r3x", "r3y", "s1x", "s1y", "s2x", "s2y", "o1", "o2"])
    for trial in range(40):
        R, K = int(rng.integers(1, 40)), int(rng.integers(0, 60))
        roots = rng.normal(size=(R, 9)) + 1j * rng.normal(size=(R, 9))
        base = np.vstack([roots, rng.normal(size=(6, 9)) + 1j * rng.normal(size=(6, 9))])
        signs = group[rng.integers(0, len(group), size=K)] if trial % 2 else np.ones((K, 9))
        xs = base[rng.integers(0, len(base), size=K)] * signs + 10.0 ** rng.uniform(-9, -5, size=(K, 1)) * rng.normal(size=(K, 9))
        g = group if trial % 2 else None
        assert np.array_equal(md.add_new(roots, xs, g), reference(roots, xs, g)), trial


def test_duplicated_by_projection_decides_as_the_gram_matrix():
    """Above GRAM_ROWS finite rows tracking._duplicated compares by sorted projections (a 10^5-point trace test
    would need a 10^10-entry Gram matrix); on random sets with near copies and images of rows, and NaN rows,
    it marks the same rows as the Gram-matrix test."""
    from solvers.instances import gauge_reflections

    rng = np.random.default_rng(3)
    group = gauge_reflections(["r2x", "r3x", "r3y", "s1x", "s1y", "s2x", "s2y", "o1", "o2"])
    for trial in range(30):
        K = int(rng.integers(2, 200))
        x = rng.normal(size=(K, 9)) + 1j * rng.normal(size=(K, 9))
        m = int(rng.integers(0, K // 2 + 1))
        src, dst = rng.integers(0, K, m), rng.integers(0, K, m)
        g = group if trial % 2 else None
        signs = group[rng.integers(0, len(group), m)] if g is not None else np.ones((m, 9))
        x[dst] = x[src] * signs + 10.0 ** rng.uniform(-9, -5, (m, 1)) * rng.normal(size=(m, 9))
        x[rng.integers(0, K, 2)] = np.nan
        ok = np.all(np.isfinite(x), axis=1)
        by_projection = np.zeros(K, dtype=bool)
        by_projection[ok] = tk._duplicated_by_projection(x[ok], 1e-6, g)
        assert np.array_equal(by_projection, tk._duplicated(x, 1e-6, g)), trial
