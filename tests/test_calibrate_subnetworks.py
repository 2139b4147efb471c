"""solvers.calibrate on small networks with gaps: sub-network hypotheses, their sampler, tie-breaking."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from solvers.calibration import calibrate, robust_refine
from solvers.calibration.adjustment import MIN_RECEIVER_MEASUREMENTS, MIN_TRANSMITTER_MEASUREMENTS
from solvers.calibration.ransac import _better
from solvers.calibration.sampling import _sample_subnetwork
from solvers.calibration.scoring import _Model
from solvers.metrics import calibration_errors
from solvers.recovery import to_gauge
from solvers.synthetic import corrupt_measurements, random_network


def _spare(mask, rows, cols):
    """Measured entries minus unknowns (2m + 3n - 3) of the sub-network rows x cols."""
    return int(mask[np.ix_(rows, cols)].sum()) - (2 * len(rows) + 3 * len(cols) - 3)


def test_unguided_subnetworks_determine_their_nodes_with_the_asked_redundancy():
    rng = np.random.default_rng(0)
    mask = rng.random((8, 5)) > 0.1
    for _ in range(30):
        rows, cols = _sample_subnetwork(mask, rng, None, dim=2)
        sub = mask[np.ix_(rows, cols)]
        assert (sub.sum(axis=1) >= MIN_RECEIVER_MEASUREMENTS).all()
        assert (sub.sum(axis=0) >= MIN_TRANSMITTER_MEASUREMENTS).all()
        assert _spare(mask, rows, cols) >= 2  # a gross error inside shows in the fit's residuals
        assert len(rows) < 8 or len(cols) < 5


def test_guided_subnetworks_leave_out_a_node_of_the_suspicious_entry_and_never_repeat():
    rng = np.random.default_rng(1)
    mask = np.ones((8, 5), bool)
    suspicious = np.array([[2, 3]])
    tried: set = set()
    drawn = []
    while (block := _sample_subnetwork(mask, rng, tried, suspicious, dim=2)) is not None:
        rows, cols = block
        assert 2 not in rows or 3 not in cols
        drawn.append((tuple(rows), tuple(cols)))
    assert len(drawn) == len(set(drawn)) == 2  # receiver 3 left out, or transmitter 4


def test_lmeds_ties_go_to_the_model_explaining_more_entries():
    nan = np.full((1, 2), np.nan)
    exact_on_most = _Model(nan, nan, np.zeros(1), score=1e-30, inlier_ratio=0.75)
    exact_on_all = _Model(nan, nan, np.zeros(1), score=2e-30, inlier_ratio=1.0)
    assert _better(exact_on_all, exact_on_most, floor=1e-9)
    assert not _better(exact_on_most, exact_on_all, floor=1e-9)
    assert _better(_Model(nan, nan, np.zeros(1), 1.0, 0.5), exact_on_all, floor=1e-9) is False


def _clean_blocks(F, bad, shapes=((6, 4), (8, 3), (7, 3), (6, 3), (5, 4), (4, 5))) -> int:
    """Fully measured blocks of the solvers' shapes that hold no gross error."""
    mask = np.isfinite(F)
    count = 0
    for ms, ns in shapes:
        for cols in itertools.combinations(range(F.shape[1]), ns):
            rows = np.flatnonzero(mask[:, cols].all(axis=1))
            count += sum(not bad[np.ix_(r, cols)].any() for r in itertools.combinations(rows, ms))
    return count


@pytest.mark.parametrize("seed", [2000])
def test_a_small_gapped_network_without_a_clean_block_is_calibrated(seed):
    # The benchmark's 8r/5s, sigma 1e-3, 10 % missing, 2 % outliers, trial seed 2000: every fully
    # measured block of every solver's shape holds the gross error, so only sub-networks can help.
    sigma = 1e-3
    rng = np.random.default_rng(seed)
    net = random_network(8, 5, rng)
    F, bad = corrupt_measurements(net.measurements(sigma, rng), rng, 0.1, 0.02)
    assert bad.sum() == 1 and _clean_blocks(F, bad) == 0
    res = calibrate(F, sigma=sigma, seed=seed)
    good = np.isfinite(F) & ~bad
    ref = robust_refine(F, good, *to_gauge(net.receivers, net.transmitters), net.offsets.copy(), loss="linear")

    class Ref:
        receivers, transmitters, offsets = ref.R, ref.S, ref.O

    best_possible = calibration_errors(Ref, net)
    err = calibration_errors(res, net)
    # 35 inliers for 28 unknowns: the geometry leaves two entries without redundancy (uncontrolled)
    assert res.status in ("ok", "uncontrolled") and "subnetworks" in res.solver
    assert (res.uncontrolled == (res.redundancy < 0.01)).all()
    assert err.position <= 3 * best_possible.position and err.offset <= 3 * best_possible.offset, (err, best_possible)
    assert not res.inliers[bad].any()
