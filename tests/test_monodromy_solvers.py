"""Solvers built from a monodromy checkpoint (numerical evidence, no GF(p) certificate): the checkpoint loader's
checks, generate(..., from_monodromy=PATH) on the direct parametrization with one root per orbit of the gauge
reflections, and the committed 3D TDOA minimal-cell solvers (7r/5s, 6r/6s) behind solve_network(F, dim=3)."""
from __future__ import annotations

import importlib
import json
import os
import sys
import warnings

import numpy as np
import pytest

from analysis.formulations.parametric import from_formulation
from solvers import api
from solvers.continuation import monodromy as md
from solvers.continuation import tracking as tk
from solvers.generate import GENERATED_DIR, MONODROMY_CHECKPOINTS, SETTLED_LOOPS, SOLVERS, GenerationError, generate
from solvers.instances import complex_instance, gauge_reflections
from solvers.metrics import position_error
from solvers.synthetic import ROOM, room_network

LABEL = "3r3s-toa2d-direct:all"  # 9 unknowns, 8 orbits of the 4 reflections of the 2D gauge (Kuang et al. 2013)


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    """A settled monodromy checkpoint of 2D TOA 3r/3s direct (the file scripts/monodromy_counts.py writes)."""
    system = from_formulation(LABEL)
    F, x0 = complex_instance(3, 3, np.random.default_rng(5), 2, "toa", "direct")
    solver, x0 = md.start_solver(system, F.ravel(), x0)
    path = str(tmp_path_factory.mktemp("monodromy") / "3r3s-seed5.json")
    grown = md.monodromy_count(solver, F.ravel(), x0, tk.HomotopyOptions(seed=3, stall_loops=SETTLED_LOOPS), 1e9,
                               path, group=gauge_reflections(system.unknowns))
    assert len(grown.roots) == 8 and grown.stall == SETTLED_LOOPS
    return path


def _rewritten(path: str, tmp_path, change) -> str:
    with open(path, encoding="utf-8") as fh:
        saved = json.load(fh)
    change(saved)
    out = str(tmp_path / "changed.json")
    with open(out, "w", encoding="utf-8") as fh:
        json.dump(saved, fh)
    return out


def test_checkpoint_loader_accepts_its_roots_and_rejects_others(checkpoint, tmp_path):
    """checked_roots: the stored roots (11 digits) satisfy the system at q0 and are refined; a root moved in its 6th
    digit, a root of other data, and a root that is a reflection of another are each rejected with a named error."""
    system = from_formulation(LABEL)
    group = gauge_reflections(system.unknowns)
    ck = md.read_checkpoint(checkpoint)
    roots = md.checked_roots(system, ck.q0, ck.roots, group)
    assert roots.shape == (8, 9) and md.system_residuals(system, roots, ck.q0).max() < 1e-12

    moved = ck.roots.copy()
    moved[3, 2] *= 1 + 1e-6
    with pytest.raises(tk.HomotopyError, match="1 of 8 checkpoint roots do not satisfy"):
        md.checked_roots(system, ck.q0, moved, group)
    other, _ = complex_instance(3, 3, np.random.default_rng(6), 2, "toa", "direct")
    with pytest.raises(tk.HomotopyError, match="8 of 8 checkpoint roots do not satisfy"):
        md.checked_roots(system, other.ravel(), ck.roots, group)
    imaged = np.vstack([ck.roots, ck.roots[:1] * group[1]])  # a root and its mirror image: one orbit twice
    with pytest.raises(tk.HomotopyError, match="image of another under the group"):
        md.checked_roots(system, ck.q0, imaged, group)
    with pytest.raises(tk.HomotopyError, match="not a monodromy checkpoint"):
        md.read_checkpoint(_rewritten(checkpoint, tmp_path, lambda d: d.pop("roots")))


def test_generate_from_a_checkpoint(checkpoint, tmp_path):
    """generate(..., from_monodromy=PATH): no regrowing; the spec carries evidence "monodromy" with the
    checkpoint's loops and paths, the group, 8 paths for 32 roots; the module's header says not certified; the
    solver finds a real network's root (up to the reflections), and calibrations() its positions. A perturbed
    checkpoint and an unsettled one are refused."""
    out = str(tmp_path / "gen")
    result = generate(LABEL, out=out, from_monodromy=checkpoint)
    assert result.evidence == "monodromy" and result.degree == 32 and result.candidates == 8
    stem = os.path.splitext(os.path.basename(result.module))[0]
    assert stem.endswith("_homotopy8")
    with open(os.path.join(out, stem + ".json"), encoding="utf-8") as fh:
        spec = json.load(fh)
    ck = md.read_checkpoint(checkpoint)
    evidence = spec["evidence"]
    assert "certified" not in spec and evidence["method"] == "monodromy" and evidence["orbits"] == 8
    assert (evidence["loops"], evidence["paths_tracked"], evidence["loops_without_new"]) == (ck.loops, ck.paths, ck.stall)
    assert spec["group"]["order"] == 4 and spec["degree"] == 32 and spec["paths"] == 8
    with open(result.module, encoding="utf-8") as fh:
        text = fh.read()
    assert "NOT certified over GF(p)" in text and "GROUP_ORDER = 4" in text

    sys.path.insert(0, out)
    try:
        module = importlib.import_module(stem)
    finally:
        sys.path.remove(out)
    net = room_network(3, 3, np.random.default_rng(2), room=ROOM[:2], offset_sigma=0.0)
    F = net.measurements()
    roots = module.solve(F)
    assert roots.shape == (8, 9)
    cals = api.calibrations(module, F, roots)
    assert cals and min(position_error(c, net) for c in cals) < 1e-9

    moved = _rewritten(checkpoint, tmp_path, lambda d: d["roots"][0][0].__setitem__(0, d["roots"][0][0][0] + 1e-3))
    with pytest.raises(tk.HomotopyError, match="do not satisfy"):
        generate(LABEL, out=str(tmp_path / "bad"), from_monodromy=moved)
    unsettled = _rewritten(checkpoint, tmp_path, lambda d: d.__setitem__("stall", SETTLED_LOOPS - 1))
    with pytest.raises(tk.HomotopyError, match="not settled"):
        generate(LABEL, out=str(tmp_path / "bad"), from_monodromy=unsettled)
    with pytest.raises(GenerationError, match="no such monodromy checkpoint"):
        generate(LABEL, out=str(tmp_path / "bad"), from_monodromy=str(tmp_path / "missing.json"))


def _committed(label: str):
    names = [f[:-3] for f in os.listdir(GENERATED_DIR) if f.startswith(f"tdoa_{label}_homotopy") and f.endswith(".py")]
    if not names or label not in SOLVERS:
        pytest.skip(f"no committed {label} solver")
    return importlib.import_module(f"solvers.generated.{names[0]}")


@pytest.mark.parametrize("label, paths", [("7r5s3d", 2321), ("6r6s3d", 3920)])
def test_committed_minimal_3d_solver_carries_its_evidence(label, paths):
    """The committed 3D TDOA minimal-cell solvers (7r/5s, 6r/6s): evidence "monodromy" from their checkpoint (not
    certified, said in the header), one path per orbit of the 8 gauge reflections, picked by solve_network(F, dim=3)
    for their shape."""
    module = _committed(label)
    with open(os.path.join(GENERATED_DIR, module.SPEC_FILE), encoding="utf-8") as fh:
        spec = json.load(fh)
    assert spec["evidence"]["method"] == "monodromy" and "certified" not in spec
    assert spec["evidence"]["checkpoint"] == MONODROMY_CHECKPOINTS[label]
    assert spec["evidence"]["loops_without_new"] >= SETTLED_LOOPS
    assert module.PATHS == paths == len(spec["start_roots"]) and module.GROUP_ORDER == 8 and module.DEGREE == 8 * paths
    with open(module.__file__, encoding="utf-8") as fh:
        assert "NOT certified over GF(p)" in fh.read()
    m, n = module.CONFIG
    assert api.select_solver_kd(m, n, 3, "tdoa").label == label


@pytest.mark.parametrize("label, shape", [("7r5s3d", (2321, 35)), ("6r6s3d", (3920, 36))])
def test_committed_minimal_3d_start_roots_satisfy_their_system(label, shape):
    """Every 20th stored start root of a 3D minimal-cell solver is a root of the direct system at the stored q0, in
    an orbit of its own (checked as a checkpoint is; generation checked all of them)."""
    module = _committed(label)
    with open(os.path.join(GENERATED_DIR, module.SPEC_FILE), encoding="utf-8") as fh:
        spec = json.load(fh)
    system = from_formulation(module.SYSTEM)
    q0 = tk._complex_array(spec["start_parameters"])
    roots = tk._complex_array(spec["start_roots"])
    assert roots.shape == shape
    sample = roots[::20]
    assert md.checked_roots(system, q0, sample, np.array(spec["group"]["signs"])).shape == sample.shape


@pytest.mark.slow
def test_solve_network_finds_a_7r5s_room_network():
    """solve_network(F, dim=3) on a noiseless 7r/5s room network (about 20-40 s: 2321 paths) returns the true
    network among its exact fits."""
    _committed("7r5s3d")
    net = room_network(7, 5, np.random.default_rng(0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cals = api.solve_network(net.measurements(), dim=3)
    assert cals and min(position_error(c, net) for c in cals) < 1e-8


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("TDOA_LONG_TESTS"), reason="a 3920-path solve, 2-5 min: set TDOA_LONG_TESTS=1 "
                    "to run it")
def test_solve_network_finds_a_6r6s_room_network():
    """solve_network(F, dim=3) on a noiseless 6 x 6 room network runs the 6r/6s solver and returns the true network
    among its exact fits (3920 paths: the solve took 67 s at load 3, the whole test 278 s at load 7.6)."""
    _committed("6r6s3d")
    assert api.select_solver_kd(6, 6, 3, "tdoa").label == "6r6s3d"
    net = room_network(6, 6, np.random.default_rng(0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cals = api.solve_network(net.measurements(), dim=3)
    assert cals and min(position_error(c, net) for c in cals) < 1e-8


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("TDOA_LONG_TESTS"), reason="two 7r/5s solves and a retry, 3-7 min: "
                    "set TDOA_LONG_TESTS=1 to run it")
def test_solve_network_retries_a_suspect_7r5s_solve_with_its_receivers_reordered():
    """Room network 12: 2142 of the 2321 endpoints land on images of others and the true network is missed;
    solve_network sees the suspect root set (api.SUSPECT_FRACTION) and solves the network with its receivers
    reordered too, which finds it (several minutes: the first solve's stalled paths go through the detours)."""
    _committed("7r5s3d")
    net = room_network(7, 5, np.random.default_rng(12))
    F = net.measurements()
    cands, _, suspect = api._kd_candidates(F, 3, "tdoa")
    assert suspect and min([position_error(c, net) for c in cands], default=np.inf) > 1e-3
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cals = api.solve_network(F, dim=3)
    assert cals and min(position_error(c, net) for c in cals) < 1e-8
