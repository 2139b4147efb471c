"""Calibrate a real network: missing entries, gross errors, RANSAC over the minimal solvers, and an
adjustment whose statistics say what can be trusted.

Stages (docs/calibrate.md "Stages"): `diagnose` reads the data alone (degrees of freedom, the robust
factorization's singular values: plane waves or not, the sources' elevation span); `initialise` starts
plane waves from the metric-upgraded factorization (`factorization`) and everything else from the
hypothesis search below; `adjust` adjusts plane waves with every source a direction and an inverse range;
`judge` gives the status from the final fit, per node kind (a node that keeps fewer than half of its
entries is judged by them, on every route). `state` holds what the stages pass along.

The package follows the pipeline from a TDOA matrix F (receivers x transmitters, NaN = not measured)
to one honest answer, after Larsson et al., "Upgrade methods for stratified sensor network
self-calibration" (EUSIPCO 2021), and geodetic network adjustment (Baarda 1968):

1. **Hypotheses** (`sampling`): fully measured sub-blocks of F handed to the project's minimal
   solvers, cheapest first, and sub-networks solved by least squares from random starts where
   blocks are too few; each extended to the network by batched robust multilateration
   (`placement`) and scored MSAC-style with sigma given, or by the median squared residual of the
   entries the hypothesis was not solved on (a sample's own entries never count: a minimal sample
   fits them exactly). LO-RANSAC (`ransac`): every new best hypothesis is refined (`robust`).
2. **The all-data hypothesis** (`robust._adjust`): least squares on every entry from the best
   hypothesis; if the global test passes (sigma given) and no entry's test statistic exceeds its
   Bonferroni bound, every entry is kept.
3. **Otherwise, robust classification and data snooping**: robust refinement at threshold_sigmas x
   sigma (given, or estimated from a robust fit with positive redundancy: the median of |e| /
   sqrt(r) over testable entries), then Baarda's w-test (or the externally studentised residual
   when sigma is estimated) one entry per node at a time, with readmission of rejected entries that
   the fit predicts within the critical value; entries whose redundancy number is below
   min_redundancy are never rejected (they cannot be tested) and are reported as uncontrolled.
4. **An honest result** (`result.CalibrationResult`, `adjustment.adjustment_statistics`): per entry
   the redundancy number, test statistic and minimal detectable bias; per node the standard
   deviation (gauge-fixed covariance sigma^2 N^-1) and external reliability; the global test; a
   status that names what was not checked ("ok" only when every node is placed, the model test
   passes and every measurement is controlled); a second search with another seed when entries
   were rejected, and "ambiguous" with both answers when it disagrees.
5. **In the user's frame** (`frame`): each node's full covariance (`node_covariances`, in the result
   as receiver_cov / transmitter_cov); `anchor_frame` moves a result into the frame of known positions
   of some nodes (a weighted rigid or similarity fit, tested by chi^2), the covariance carried.

Gauge of the result: receiver 1 at the origin and receiver 2 on the positive x axis (paper Sec. 3),
or, when one of them has fewer than 3 inlier measurements, the first two receivers that have them;
the remaining reflection is arbitrary. Standard deviations refer to the same gauge (or, after
`frame.anchor_frame`, to the anchors' frame).
"""
from .adjustment import AdjustmentStatistics, adjustment_statistics, estimate_covariance, robust_refine
from .frame import Anchors, anchor_frame, node_covariances, read_anchors
from .pipeline import calibrate
from .result import STATUSES, CalibrationOptions, CalibrationResult
from .sampling import MinimalSolver, available_solvers

__all__ = [
    "STATUSES",
    "AdjustmentStatistics",
    "Anchors",
    "CalibrationOptions",
    "CalibrationResult",
    "MinimalSolver",
    "adjustment_statistics",
    "anchor_frame",
    "available_solvers",
    "calibrate",
    "estimate_covariance",
    "node_covariances",
    "read_anchors",
    "robust_refine",
]
