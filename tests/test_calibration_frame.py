"""solvers.calibration.frame and the calibrate flags --anchors, --anchor-fit, --csv: node covariances
agree with the reported standard deviations, a known similarity is recovered from anchors, the
uncertainty is carried into the anchors' frame, a wrong anchor is caught, and the exports hold the
documented keys and columns."""
from __future__ import annotations

import csv
import dataclasses
import importlib
import json

import numpy as np
import pytest

from solvers.calibrate_io import ellipse_magnification
from solvers.calibration import calibrate
from solvers.calibration.frame import AnchorError, Anchors, anchor_frame, parse_anchors, widen_far_ranges
from solvers.cli import main
from solvers.synthetic import random_network, room_network


@pytest.fixture(scope="module")
def fitted():
    """(network, F, result) of an 8r/6s plane network calibrated with sigma given."""
    net = random_network(8, 6, np.random.default_rng(4))
    F = net.measurements(0.01, np.random.default_rng(5))
    return net, F, calibrate(F, sigma=0.01, seed=0)


def rotation(dim: int, rng) -> np.ndarray:
    Q, _ = np.linalg.qr(rng.standard_normal((dim, dim)))
    return Q  # orthogonal; a reflection when det = -1


def test_node_covariances_agree_with_the_reported_stds(fitted):
    _, _, res = fitted
    assert res.receiver_cov.shape == (8, 2, 2) and res.transmitter_cov.shape == (6, 3, 3)
    assert np.allclose(np.sqrt(np.trace(res.receiver_cov, axis1=1, axis2=2)), res.receiver_std)
    assert np.allclose(np.sqrt(np.trace(res.transmitter_cov[:, :2, :2], axis1=1, axis2=2)), res.transmitter_std)
    assert np.allclose(np.sqrt(res.transmitter_cov[:, 2, 2]), res.offset_std)
    for C in np.concatenate([res.receiver_cov[1:], res.transmitter_cov[:, :2, :2]]):
        assert np.allclose(C, C.T) and np.linalg.eigvalsh(C).min() > -1e-15  # symmetric, semi-definite
    assert np.all(res.receiver_cov[0] == 0)  # the gauge's origin is fixed


def synthetic_result(dim: int, rng, m=6, n=5):
    """A result with known positions and a small isotropic covariance (no calibration run)."""
    from solvers.calibration.result import CalibrationResult

    R, S = rng.uniform(-5, 5, (m, dim)), rng.uniform(-5, 5, (n, dim))
    rc = np.tile(np.eye(dim) * 1e-6, (m, 1, 1))
    tc = np.tile(np.eye(dim + 1) * 1e-6, (n, 1, 1))
    std = np.sqrt(dim * 1e-6)
    return CalibrationResult(
        status="ok", message="ok: synthetic", receivers=R, transmitters=S, offsets=rng.uniform(-1, 1, n),
        inliers=np.ones((m, n), bool), residuals=np.zeros((m, n)), rms=0.0, sigma=1e-3, sigma_estimated=False,
        receiver_std=np.full(m, std), transmitter_std=np.full(n, std), offset_std=np.full(n, 1e-3),
        receiver_cov=rc, transmitter_cov=tc, gauge=tuple(range(dim)))


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("fit", ["rigid", "similarity"])
def test_anchors_recover_a_known_similarity(dim, fit):
    rng = np.random.default_rng(dim)
    res = synthetic_result(dim, rng)
    A, t = rotation(dim, rng), rng.uniform(-20, 20, dim)
    s = 1.7 if fit == "similarity" else 1.0
    idx = np.array([0, 2, 3, 5])
    anchors = Anchors(tuple(str(i + 1) for i in idx), np.ones(4, bool), idx, s * res.receivers[idx] @ A.T + t,
                      np.full(4, 1e-3))
    out = anchor_frame(res, anchors, fit)
    assert np.allclose(out.frame["rotation"], A, atol=1e-9) and np.allclose(out.frame["translation"], t, atol=1e-8)
    assert out.frame["scale"] == pytest.approx(s, rel=1e-12)
    assert np.allclose(out.receivers, s * res.receivers @ A.T + t, atol=1e-8)
    assert np.allclose(out.transmitters, s * res.transmitters @ A.T + t, atol=1e-8)
    assert np.allclose(out.offsets, s * res.offsets)
    assert out.status == "ok" and out.frame["passed"] and out.gauge is None
    # the uncertainty carried: the node's covariance scaled, rotated, plus the frame's own (never less)
    for k in range(res.m):
        moved = s**2 * A @ res.receiver_cov[k] @ A.T
        assert np.linalg.eigvalsh(out.receiver_cov[k] - moved).min() > -1e-15
    assert np.allclose(out.receiver_std, np.sqrt(np.trace(out.receiver_cov, axis1=1, axis2=2)))
    assert np.all(out.receiver_std >= s * res.receiver_std * (1 - 1e-12))


def test_a_wrong_anchor_makes_the_result_inconsistent():
    rng = np.random.default_rng(9)
    res = synthetic_result(2, rng)
    idx = np.arange(4)
    a = res.receivers[idx].copy()
    a[2] += [0.5, 0.0]  # 500 std off
    out = anchor_frame(res, Anchors(("1", "2", "3", "4"), np.ones(4, bool), idx, a, np.full(4, 1e-3)))
    assert out.status == "inconsistent" and out.frame["passed"] is False
    assert "anchors do not fit" in out.message and "the worst is 3" in out.message


def test_anchored_std_is_honest_on_a_calibrated_network(fitted):
    """The errors of the anchored positions against the truth, in units of their std, are of order 1 (a
    2D normal error has |e| / std below 3 with probability 0.99)."""
    net, _, res = fitted
    rng = np.random.default_rng(11)
    idx = np.array([0, 2, 4, 6])
    known = net.receivers[idx] + 0.005 * rng.standard_normal((4, 2))
    out = anchor_frame(res, Anchors(tuple(map(str, idx)), np.ones(4, bool), idx, known, np.full(4, 0.005)))
    ratio = np.concatenate([np.linalg.norm(out.receivers - net.receivers, axis=1) / out.receiver_std,
                            np.linalg.norm(out.transmitters - net.transmitters, axis=1) / out.transmitter_std])
    assert out.status == res.status and ratio.max() < 3.5 and 0.2 < np.sqrt(np.mean(ratio**2)) < 2


@pytest.mark.parametrize("text, fragment", [
    ("node,x,y,std\nr9,0,0,0.01\n", "no node 'r9'"),
    ("node,x,y,std\n1,0,0,0.01\n", "names a receiver and a transmitter"),
    ("node,x,y\nr1,0,0\n", "give x, y, std"),
    ("node,x,y,std\nr1,0,0,0\n", "std must be > 0"),
    ("node,x,y,std\nr1,0,,0.1\n", "missing value"),
    ("node,x,y,std\nr1,0,0,0.1\nr1,1,1,0.1\n", "given twice"),
])
def test_anchor_file_errors_are_one_line(text, fragment):
    with pytest.raises(AnchorError, match=fragment) as info:
        parse_anchors(text, ["r1", "r2", "1"], ["s1", "1"], 2, "a.csv")
    assert "\n" not in str(info.value)


def test_anchor_names_columns_and_prefixes():
    a = parse_anchors("# known\nname;STD;y;x\ns:1;0,5;2;1\nr2;0,1;4;3\n", ["r1", "r2", "1"], ["s1", "1"], 2)
    assert a.names == ("s:1", "r2") and a.receivers.tolist() == [False, True] and a.index.tolist() == [1, 1]
    assert np.allclose(a.positions, [[1, 2], [3, 4]]) and np.allclose(a.std, [0.5, 0.1])
    with pytest.raises(AnchorError, match="give x, y, z, std"):
        parse_anchors("n,x,y,std\nr1,0,0,1\n", ["r1"], ["s1"], 3)


def test_anchors_on_a_line_leave_the_3d_mirror_open_and_two_do_not_fix_3d():
    rng = np.random.default_rng(3)
    res = synthetic_result(3, rng)
    idx = np.array([0, 1, 2])
    out = anchor_frame(res, Anchors(("1", "2", "3"), np.ones(3, bool), idx, res.receivers[idx], np.full(3, 1e-3)))
    assert any("mirror image" in w for w in out.warnings)
    with pytest.raises(AnchorError, match="at least 3"):
        anchor_frame(res, Anchors(("1", "2"), np.ones(2, bool), idx[:2], res.receivers[:2], np.full(2, 1e-3)))


def test_ellipse_magnification_is_a_round_factor_of_at_least_one():
    assert ellipse_magnification(10.0, [0.001, 0.002]) == 100  # 3 % of 10 over 0.002 = 150 -> 100
    assert ellipse_magnification(10.0, [0.01]) == 20
    assert ellipse_magnification(10.0, [1.0]) == 1  # never drawn smaller than it is
    assert ellipse_magnification(10.0, [np.inf]) == 1


def test_cli_anchors_csv_json_and_plot(capsys, tmp_path, monkeypatch, fitted):
    net, F, res = fitted
    path = tmp_path / "meas.csv"
    path.write_text("rx," + ",".join(f"s{j + 1}" for j in range(6)) + "\n" +
                    "".join(f"r{i + 1}," + ",".join(repr(float(v)) for v in row) + "\n" for i, row in enumerate(F)))
    monkeypatch.setattr(importlib.import_module("solvers.calibration"), "calibrate", lambda *a, **k: res)
    A, t = rotation(2, np.random.default_rng(1)), np.array([100.0, -50.0])
    anchors = tmp_path / "anchors.csv"
    anchors.write_text("node,x,y,std\n" + "".join(
        f"r{i + 1},{float(p[0])!r},{float(p[1])!r},0.001\n" for i, p in zip([0, 3, 6], res.receivers[[0, 3, 6]] @ A.T + t)))
    out_json, out_csv, plot = tmp_path / "r.json", tmp_path / "nodes.csv", tmp_path / "map.png"
    code = main(["calibrate", str(path), "--sigma", "0.01", "--anchors", str(anchors), "--csv", str(out_csv),
                 "--out", str(out_json), "--plot", str(plot)])
    text, err = capsys.readouterr()
    assert code == (0 if res.status == "ok" else 1), err
    assert text.splitlines()[1].startswith("frame: 3 anchors of ")
    report = json.loads(out_json.read_text())
    assert {"receiver_cov", "transmitter_cov", "frame"} <= set(report)
    assert np.array(report["receiver_cov"]).shape == (8, 2, 2) and np.array(report["transmitter_cov"]).shape == (6, 3, 3)
    assert set(report["frame"]) >= {"fit", "rotation", "translation", "scale", "statistic", "critical", "dof", "passed",
                                    "anchors"}
    assert np.allclose(report["receivers"], res.receivers @ A.T + t, atol=1e-6)
    rows = list(csv.reader(line for line in out_csv.read_text().splitlines() if not line.startswith("#")))
    assert rows[0] == ["kind", "name", "x", "y", "offset", "std_x", "std_y", "std_offset", "std"]
    assert [r[1] for r in rows[1:]] == [f"r{i + 1}" for i in range(8)] + [f"s{j + 1}" for j in range(6)]
    assert np.allclose([float(r[-1]) for r in rows[2:]], np.r_[report["receiver_std"][1:], report["transmitter_std"]],
                       rtol=1e-8)
    assert plot.stat().st_size > 10_000
    # errors: an unknown node, the anchors file named as an output
    bad = tmp_path / "bad.csv"
    bad.write_text("node,x,y,std\nr99,0,0,1\n")
    assert main(["calibrate", str(path), "--anchors", str(bad)]) == 2
    assert "no node 'r99'" in capsys.readouterr().err
    assert main(["calibrate", str(path), "--anchors", str(anchors), "--csv", str(anchors)]) == 2
    assert "is the measurement file" in capsys.readouterr().err


def test_room_covariance_is_3d(monkeypatch):
    net = room_network(10, 6, np.random.default_rng(3))
    res = calibrate(net.measurements(1e-3, np.random.default_rng(4)), sigma=1e-3, dim=3, seed=0)
    assert res.receiver_cov.shape == (10, 3, 3) and res.transmitter_cov.shape == (6, 4, 4)
    assert np.allclose(np.sqrt(np.trace(res.receiver_cov, axis1=1, axis2=2)), res.receiver_std)
    assert dataclasses.replace(res).to_dict()["transmitter_cov"] is not None


def test_a_far_node_with_a_weak_range_is_widened_to_the_far_side_in_inverse_range():
    """frame.widen_far_ranges: 8 receivers in a 25 cm cube, sources 4 m away. A source whose linear range std is
    0.6 m (15 % of its range) gets 0.6 / (1 - 0.15) along the range, its bearing's variance kept; one at 2.5 %
    keeps its covariance exactly; one whose range std exceeds its range is not bounded (inf). The receivers,
    inside the sources' spread, and any room-like network, whose nodes lie among each other, are untouched."""
    rng = np.random.default_rng(0)
    R = rng.uniform(-0.125, 0.125, (8, 3))
    c = R.mean(axis=0)
    dirs = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [-1.0, 0, 0]])
    S = c + 4.0 * dirs
    rcov = np.tile(np.eye(3) * 1e-8, (8, 1, 1))
    tcov = np.zeros((4, 4, 4))
    for k, sr in enumerate((0.6, 0.1, 5.0, 0.6)):
        d = dirs[k]
        tcov[k, :3, :3] = sr**2 * np.outer(d, d) + 0.01**2 * (np.eye(3) - np.outer(d, d))
        tcov[k, 3, 3] = 1e-4
    r2, t2, widened = widen_far_ranges(R, S, rcov, tcov)
    assert widened == [("s", 0), ("s", 2), ("s", 3)]
    np.testing.assert_array_equal(r2, rcov)
    np.testing.assert_array_equal(t2[1], tcov[1])
    d = dirs[0]
    eps = 0.6 / float(np.linalg.norm(S[0] - c))
    assert d @ t2[0, :3, :3] @ d == pytest.approx((0.6 / (1 - eps)) ** 2, rel=1e-12)
    side = np.array([0.0, 1.0, 0.0])
    assert side @ t2[0, :3, :3] @ side == pytest.approx(0.01**2, rel=1e-12)
    assert t2[0, 3, 3] == tcov[0, 3, 3]
    assert np.all(np.isinf(t2[2, :3, :3]))
    # a room: receivers and sources among each other, large stds and all, nothing widened
    Rr, Sr = rng.uniform(0, 6, (10, 3)), rng.uniform(0, 6, (6, 3))
    big_r, big_t = np.tile(np.eye(3), (10, 1, 1)), np.tile(np.eye(4), (6, 1, 1))
    assert widen_far_ranges(Rr, Sr, big_r, big_t)[2] == []
