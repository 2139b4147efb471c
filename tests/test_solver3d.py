"""The generated 3D solver (9r/5s, offset kernel): certified count, known root, recovery of seeded room
networks, 3D gauge and recovery, and clear errors for bad input."""
from __future__ import annotations

import importlib
import os

import numpy as np
import pytest

from analysis.sweeps.cell_degrees import cell_degree
from analysis.engine.degree import DEFAULT_PRIMES
from analysis.formulations.tdoa import Formulation, real_equations, sample_real_instance
from solvers.api import calibrations
from solvers.generate import GENERATED_DIR, SOLVERS, GenerationError, generate
from solvers.methods import offset_kernel
from solvers.methods.spec import TemplateError
from solvers.metrics import offset_error, position_error
from solvers.recovery import recover, to_gauge
from solvers.synthetic import ROOM, random_network, room_network, true_root

LABEL = "9r5s3d"
IU = np.triu_indices(3)


def _module():
    stem = next(f[:-3] for f in sorted(os.listdir(GENERATED_DIR)) if f.startswith(f"tdoa_{LABEL}_") and f.endswith(".py"))
    return importlib.import_module(f"solvers.generated.{stem}")


def _truth(net) -> np.ndarray:
    H, b, o = true_root(net)
    return np.concatenate([H[IU], b, o])


@pytest.mark.parametrize("seed", [0, 1])
def test_count_is_one_on_two_primes(seed):
    record = cell_degree(SOLVERS[LABEL], primes=DEFAULT_PRIMES, seed=seed)
    assert len(DEFAULT_PRIMES) == 2 and record.primes == " ".join(map(str, DEFAULT_PRIMES))
    assert record.status == "ok" and record.degree == 1 and record.up_to_gauge == 1, record


def test_committed_module_states_its_certificate():
    module = _module()
    spec = module.solver()
    assert module.SYSTEM == SOLVERS[LABEL] == offset_kernel.offset_kernel_formulation(9)
    assert module.METHOD == "offset-kernel" and module.DEGREE == 1 and module.CONFIG == (9, 5) and module.DIM == 3
    assert spec.m == 9 and spec.n == 5


def test_known_root_satisfies_the_system_and_the_solver_finds_it():
    # the real instance of the formulation (gauge frame) and its root: every equation vanishes there
    form = Formulation.parse(SOLVERS[LABEL])
    inst = sample_real_instance(form.config, 3)
    F = np.array(inst.F)
    root = dict(zip(form.unknowns, inst.root))
    for name, eq in zip(form.equations, real_equations(form, F)):
        scale = sum(abs(c) * np.prod([abs(root[v]) ** e for v, e in zip(form.unknowns, exp)]) for exp, c in eq.items())
        value = sum(c * np.prod([root[v] ** e for v, e in zip(form.unknowns, exp)]) for exp, c in eq.items())
        assert abs(value) <= 1e-9 * scale, name
    x = _module().solve(F)[0]
    assert np.max(np.abs(x.imag)) == 0.0
    assert np.linalg.norm(x.real - np.array(inst.root)) <= 1e-8 * np.linalg.norm(inst.root)


def test_noise_free_room_networks_are_recovered():
    module = _module()
    for seed in range(20):
        net = room_network(9, 5, np.random.default_rng(seed))
        F = net.measurements()
        x = module.solve(F)[0]
        assert np.linalg.norm(x - _truth(net)) <= 1e-8 * np.linalg.norm(_truth(net)), seed
        cals = calibrations(module, F)
        assert len(cals) == 1, seed
        cal = cals[0]
        assert position_error(cal, net) < 1e-8 and offset_error(cal, net) < 1e-8, seed
        assert cal.residual < 1e-8 and cal.receivers.shape == (9, 3) and cal.transmitters.shape == (5, 3)
        # the 3D gauge: r_1 = 0, r_2 on the positive x axis, r_3 in the xy plane with y > 0
        assert np.all(cal.receivers[0] == 0) and np.all(cal.receivers[1, 1:] == 0) and cal.receivers[2, 2] == 0
        assert cal.receivers[1, 0] > 0 and cal.receivers[2, 1] > 0


def test_batch_agrees_with_single_and_the_paper_networks_are_solved():
    module = _module()
    nets = [random_network(9, 5, np.random.default_rng(s), dim=3) for s in range(5)]
    batch = module.solve_batch(np.stack([net.measurements() for net in nets]))
    assert batch.shape == (5, 1, 14)
    for net, roots in zip(nets, batch):
        np.testing.assert_allclose(roots, module.solve(net.measurements()), rtol=1e-12, atol=0)
        assert np.linalg.norm(roots[0] - _truth(net)) <= 1e-8 * np.linalg.norm(_truth(net))


def test_room_network_is_seeded_and_inside_the_room():
    a = room_network(9, 5, np.random.default_rng(4))
    b = room_network(9, 5, np.random.default_rng(4))
    assert np.array_equal(a.receivers, b.receivers) and np.array_equal(a.offsets, b.offsets) and a.dim == 3
    for points in (a.receivers, a.transmitters):
        assert np.all(points >= 0) and np.all(points <= np.array(ROOM))
    floor = room_network(9, 5, np.random.default_rng(4), room=ROOM[:2])  # two extents: a 2D network
    assert floor.dim == 2 and np.all(floor.receivers <= np.array(ROOM[:2]))
    for bad in ((8.0,), (8.0, -6.0, 3.0)):
        with pytest.raises(ValueError, match="room"):
            room_network(9, 5, np.random.default_rng(0), room=bad)


def test_3d_gauge_is_a_rotation_and_recover_takes_the_true_root():
    net = random_network(6, 5, np.random.default_rng(2), dim=3)
    rec, tra = to_gauge(net.receivers, net.transmitters)
    assert np.allclose(np.linalg.norm(rec[:, None] - tra[None], axis=2), net.distances(), atol=1e-12)
    H, b, o = true_root(net)
    cal = recover(net.measurements(), H, b, o)
    assert cal is not None and cal.residual < 1e-10 and position_error(cal, net) < 1e-10
    assert recover(net.measurements(), H[IU], b, o) is not None  # the upper triangle is accepted too
    assert recover(net.measurements(), -H, b, o) is None  # not positive definite
    with pytest.raises(ValueError, match="b must have shape"):
        recover(net.measurements(), H, b[:2], o)


def test_bad_input_gives_clear_errors(tmp_path):
    module = _module()
    F = room_network(9, 5, np.random.default_rng(0)).measurements()
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 9, 5\)"):
        module.solve(F[:8])
    with pytest.raises(ValueError, match="one \\(9, 5\\) matrix"):
        module.solve(np.stack([F, F]))
    bad = F.copy()
    bad[2, 3] = np.nan
    with pytest.raises(ValueError, match="NaN or infinite"):
        module.solve(bad)
    with pytest.raises(ValueError, match="all zero"):
        module.solve(np.zeros((9, 5)))
    with pytest.raises(ValueError, match="the solver needs \\(9, 5\\)"):
        calibrations(module, F[:, :4])
    with pytest.raises(TemplateError, match="offset kernel needs"):
        offset_kernel.build("9r5s-tdoa3d:A,B2,B3,B4,B5,C2-C9,minors(70)")
    with pytest.raises(TemplateError, match="offset kernel needs a 3D TDOA cell"):
        generate("6r4s:B2,C2-C6,minors(10)", method="offset-kernel", out=str(tmp_path))
    with pytest.raises(GenerationError, match="not 'offset-kernel'"):
        from analysis.formulations.parametric import parse

        generate(parse("unknowns: x\nparameters: a\nequations:\nx - a\n", "line"), method="offset-kernel",
                 out=str(tmp_path))
    assert not any(tmp_path.iterdir())


def test_3d_refinement_jacobian_matches_finite_differences_and_recovers_a_noisy_network():
    from solvers.refine import jacobian, pack, parameter_count, refine, residuals

    net = room_network(9, 5, np.random.default_rng(8))
    rec, tra = to_gauge(net.receivers, net.transmitters)
    x = pack(rec, tra, net.offsets)
    assert x.shape == (parameter_count(9, 5, 3),) == (3 * 9 + 4 * 5 - 6,)
    F = net.measurements()
    assert np.max(np.abs(residuals(x, F, 3))) < 1e-12
    J = jacobian(x, F, 3)
    for v in range(len(x)):
        dx = np.zeros_like(x)
        dx[v] = 1e-6
        np.testing.assert_allclose(J[:, v], (residuals(x + dx, F, 3) - residuals(x - dx, F, 3)) / 2e-6, atol=1e-7)
    net = room_network(9, 5, np.random.default_rng(1))  # its noisy data keep a positive-definite H (seed 0 not)
    noisy = net.measurements(1e-4, np.random.default_rng(1))
    cal = calibrations(_module(), noisy)[0]
    result = refine(cal, noisy)
    assert result.success and result.calibration.receivers.shape == (9, 3)
    assert result.calibration.residual <= cal.residual
    assert position_error(result.calibration, net) < position_error(cal, net)


def test_benchmark_table_is_current():
    """tables/solvers3d.* (scripts/bench_solvers3d.py): rows for every committed 3D solver and family, made
    with the committed spec, and the Markdown table written from the two CSVs."""
    import importlib.util

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    spec = importlib.util.spec_from_file_location("bench_solvers3d", os.path.join(root, "scripts", "bench_solvers3d.py"))
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    rows, noise = bench.read_csv("solvers3d.csv"), bench.read_csv("solvers3d_noise.csv")
    labels = bench.solvers3d()
    assert labels[0] == LABEL
    # the minimal cells built on numerical evidence (7r/5s, 6r/6s) run on room networks only, fewer of them
    expected = [(label, f) for label in labels for f in (bench.FAMILIES if label == LABEL else ("room",))]
    assert [(r["solver"], r["network"]) for r in rows] == expected, "stale: run scripts/bench_solvers3d.py"
    for row in rows:
        module = bench.module_for(row["solver"])
        assert row["spec_sha256"] == module.SPEC_SHA256, "the solver changed: run scripts/bench_solvers3d.py"
        assert row["method"] == module.METHOD and int(row["roots"]) == module.DEGREE
        assert int(row["trials"]) >= (1000 if row["solver"] == LABEL else 20)
    assert [r["sigma_m"] for r in noise] == [f"{s:g}" for s in bench.NOISE_SIGMAS]
    with open(os.path.join(root, "tables", "solvers3d.md"), encoding="utf-8") as fh:
        assert fh.read() == bench.markdown(rows, noise), "stale: run scripts/bench_solvers3d.py"
