"""Options and result of `calibrate`."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

Loss = Literal["soft_l1", "huber", "cauchy", "linear"]
_LOSSES = ("soft_l1", "huber", "cauchy", "linear")
Status = Literal["ok", "partial", "uncontrolled", "inconsistent", "ambiguous", "unconverged", "failed"]
#: Statuses from the most to the least severe; a result takes the first that applies.
STATUSES = ("failed", "unconverged", "inconsistent", "partial", "ambiguous", "uncontrolled", "ok")

# --------------------------------------------------------------------------------------------------
# Options and result
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CalibrationOptions:
    """Tuning of `calibrate`; the defaults are what the benchmark (scripts/bench_calibrate.py) uses.

    threshold_sigmas : inlier threshold in units of sigma (MSAC truncation and final classification)
    confidence : RANSAC stops when an all-inlier sample was drawn with this probability
    min_samples, max_samples : bounds on the number of sub-blocks handed to the solvers
    candidates_per_sample : hypotheses extended per sample (those with the smallest block residual); a
        minimal solver's roots all fit their block exactly, so up to `minimal_candidates` of them are
        extended instead
    minimal_candidates : roots of a minimal solver (6r/3s, 4r/5s) extended per sample
    expensive_samples : samples per solver costlier than `expensive_cost` (a homotopy costs 0.1-4 s per
        call; tables/solvers.csv), so that they supplement the cheap ones without dominating the time
    expensive_cost : MinimalSolver.cost_ms above which a solver counts as expensive
    max_solver_cost : solvers costlier than this are not used (4r/5s, 344 paths, ~4 s per call; the
        squared 5r/4s and 5r/5s, see `available_solvers`: sub-networks find what they would)
    max_local_optimisations : LO runs (each new best hypothesis gets one, up to this many)
    lo_iterations : LM iterations per LO run
    loss : robust loss of the refinement ("cauchy", "soft_l1", "huber"; "linear" = plain LS). Cauchy is
        redescending: a gross error stops pulling. With soft-L1 or Huber its pull stays constant and
        drags a weakly constrained transmitter along its range/offset valley (seen in the benchmark).
    max_iterations : LM iterations of the final refinement
    subnetwork_samples : most hypotheses from sub-networks (random subsets of the nodes, gaps allowed)
        solved by least squares from a random start; drawn for networks with at most
        `subnetwork_max_params` unknowns, or when too few fully measured blocks exist. The number
        adapts like the block samples, assuming a clean sub-network converges from one start in
        `subnetwork_convergence` of the cases
    subnetwork_max_params, subnetwork_convergence : see subnetwork_samples
    runners_up : in a small network searched by sub-networks, this many of the best hypotheses that
        did not beat the best one before local optimisation get it afterwards
    collinear_ratio : warn when the smallest/largest principal spread of receivers or transmitters is below
        (2D: collinear, 3D: coplanar)
    ambiguity_chi2 : an alternative (mirror) position or hypothesis whose cost exceeds the best one by
        less than this many sigma^2 is reported as ambiguous
    alpha : level of each entry's outlier test (Baarda's alpha_0; critical value 3.29 for 0.001)
    power : probability that a bias of the minimal detectable size is detected (Baarda's beta_0 = 0.8)
    alpha_global : level of the global test of the model (sigma given) and, divided by the number of
        entries (Bonferroni), of the largest test statistic that decides whether any entry is an outlier
    min_redundancy : entries whose redundancy number is below this are not tested (an error there
        cannot be seen) and are reported as uncontrolled
    min_dof_for_sigma : redundancy (entries - unknowns) below which an estimated sigma is not trusted
        (chi^2 with 10 degrees of freedom puts the estimate within a factor 2 of the truth 99 % of the
        time); the result then asks for sigma
    max_snooping_rounds : refits of the data snooping (rejection / readmission) loop
    probe_nodes, probe_radii : after the adjustment, up to probe_nodes nodes with rejected measurements
        jump by each radius (x the network's spread) in 8 directions (3D: 14) and least squares follows: a better
        minimum is taken, a distinct one about as good makes the answer ambiguous
    loo_candidates : with sigma unknown and little redundancy (below min_dof_for_sigma), the entries
        (largest linearised test statistic first) refitted without themselves to test them exactly
    weak_redundancy : with sigma unknown, the kept entries whose redundancy number is below this are
        tested exactly after the robust route too (refitted without themselves, at most loo_candidates):
        the linearised w-test of an entry with r ~ 0.05 shows almost nothing of an error in it (12r/8s,
        5 % gross errors, 1 cm: one kept at r 0.034, |w| 2.95, exact t 6.9); an entry that test rejects
        makes the status "uncontrolled"; a rejection only 1-3 critical values out at a node that keeps
        such an entry (an error the fit absorbed there pushes the node's good entries out instead) is
        tested by a search without those entries (search._absorbed_error_probe)
    unknown_sigma_outliers : with sigma unknown, the RANSAC sample count assumes at least this share of
        gross errors (the inlier ratio on a hypothesis's own scale cannot be trusted), unless the
        network has trusted_ratio_redundancy measured entries per unknown or more and the hypothesis
        was refined robustly (its median-based scale is then trusted, and the search goes on until it
        stayed the best for max_confirm_samples samples)
    confirm_outliers : with sigma unknown, a model that passes the all-data test ends the search only
        after as many more samples as an all-inlier sample needs at this share of gross errors (14
        for a 6 x 4 block) without a better one: a fit distorted by gross errors can pass the test
        on its own inflated scale
    max_confirm_samples : at most this many confirming samples (confirm_outliers): a 3D block of 60
        entries would need 98 (2D 6 x 4 blocks: 14); beyond 30 the samples cost seconds and found
        nothing better in the 3D benchmark (tables/calibration3d.md)
    stability_check : when entries were rejected, repeat the search with a second seed and report the
        result as "ambiguous" (with the other answer) if it differs
    orientation_given : the caller says the rows are receivers (the CLI: --oriented or --transpose); a
        transposed matrix that fits about as well is then a note, not "ambiguous" (one that fits far
        better still makes the answer "inconsistent": the data contradict the given orientation)
    """

    threshold_sigmas: float = 3.0
    confidence: float = 0.99
    min_samples: int = 5
    max_samples: int = 200
    candidates_per_sample: int = 2
    minimal_candidates: int = 12
    expensive_samples: int = 3
    expensive_cost: float = 100.0
    max_solver_cost: float = 200.0
    max_local_optimisations: int = 6
    lo_iterations: int = 15
    loss: Loss = "cauchy"
    max_iterations: int = 100
    subnetwork_samples: int = 120
    subnetwork_max_params: int = 40
    subnetwork_convergence: float = 0.3
    runners_up: int = 4
    collinear_ratio: float = 0.05
    ambiguity_chi2: float = 9.0
    alpha: float = 0.001
    power: float = 0.8
    alpha_global: float = 0.01
    min_redundancy: float = 0.01
    min_dof_for_sigma: int = 10
    max_snooping_rounds: int = 60
    loo_candidates: int = 30
    weak_redundancy: float = 0.1
    probe_nodes: int = 4
    probe_radii: tuple = (0.02, 0.05)
    stability_check: bool = True
    unknown_sigma_outliers: float = 0.1
    trusted_ratio_redundancy: float = 6.0
    confirm_outliers: float = 0.05
    max_confirm_samples: int = 30
    orientation_given: bool = False

    def __post_init__(self) -> None:
        if self.loss not in _LOSSES:
            raise ValueError(f"loss must be one of {_LOSSES}, got {self.loss!r}")
        if not 0.0 < self.confidence < 1.0:
            raise ValueError(f"confidence must be in (0, 1), got {self.confidence}")
        if self.threshold_sigmas <= 0 or self.max_samples < 1 or self.min_samples < 0:
            raise ValueError("threshold_sigmas must be > 0, max_samples >= 1, min_samples >= 0")
        for name in ("alpha", "power", "alpha_global"):
            if not 0.0 < getattr(self, name) < 1.0:
                raise ValueError(f"{name} must be in (0, 1), got {getattr(self, name)}")
        if not 0.0 <= self.min_redundancy < 1.0:
            raise ValueError(f"min_redundancy must be in [0, 1), got {self.min_redundancy}")
        if not 0.0 <= self.weak_redundancy < 1.0:
            raise ValueError(f"weak_redundancy must be in [0, 1), got {self.weak_redundancy}")


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """The answer of `calibrate`: a calibration, what supports it, and what it cannot decide.

    status : what was checked, the most severe of (see STATUSES):
        "ok": every node placed, the refinement converged, the model test passed (sigma given: the
            global chi^2 test; estimated: enough redundancy to estimate it) and every measurement
            controlled (redundancy number >= CalibrationOptions.min_redundancy);
        "uncontrolled": a calibration, but some measurements (and the nodes they fix) have too little
            redundancy for an error in them to be detected, or too little redundancy to estimate sigma;
        "ambiguous": a second search with another seed gives a different inlier set or positions
            beyond the reported standard deviations (`alternative` holds it);
        "partial": some nodes could not be placed (NaN);
        "inconsistent": the model does not explain the data (the global test fails with the given
            sigma, or most measurements are rejected): a transposed matrix, wrong units, not TDOA data;
        "unconverged": the refinement hit its budget or diverged (from a fit that explains at least 2/3
            of the measurements; below that, the fit is "inconsistent" and the divergence a warning);
        "failed": no calibration; arrays are NaN; `message` says why
    message : one line summarising the outcome
    receivers (m, dim), transmitters (n, dim), offsets (n,) : NaN for a node that could not be placed;
        gauge: receiver 1 at 0, receiver 2 on the positive x axis (or the first two determined
        receivers); 3D: also receiver 3 in the xy plane with y > 0. The reflection the gauge leaves
        free (2D: y -> -y, 3D: z -> -z) cannot be decided by distances: the answer is one of the two
    inliers : (m, n) bool, False for missing or rejected measurements
    residuals : (m, n) F - o_j - |r_i - s_j| (NaN where missing or a node is unplaced)
    rms : RMS residual over the inliers
    sigma : noise level used (given, or estimated from the inlier residuals)
    sigma_estimated : True when sigma was estimated
    receiver_std, transmitter_std, offset_std : per-node standard deviations from the gauge-fixed
        covariance sigma^2 (J^T J)^-1 (position std = sqrt of the sum of the coordinates' variances;
        inf if not determined)
    warnings : what the data cannot decide, one sentence each
    solver : labels of the minimal solvers that produced hypotheses ("subnetworks": least squares on
        sub-networks from random starts)
    samples, hypotheses : sub-blocks solved and hypotheses scored
    seconds : wall time
    seed : the seed of the sampling
    dof : redundancy of the final fit (inlier entries - unknowns)
    global_test : (statistic SSR / sigma^2, critical value, passed) of the global model test with the
        given sigma, or None when sigma was estimated
    redundancy : (m, n) redundancy number of every inlier entry (NaN elsewhere); their sum is dof
    w_test : (m, n) outlier test statistic of every entry between placed nodes: for an inlier Baarda's
        w (sigma given) or the externally studentised residual (sigma estimated); for a rejected entry
        the same statistic of its prediction by the fit without it. |w| > `critical_value` is an outlier
    critical_value : the critical value of w_test (normal, or Student t with dof - 1)
    mdb : (m, n) minimal detectable bias of every inlier entry (inf where its redundancy is ~0)
    receiver_reliability, transmitter_reliability : (m,), (n,) external reliability, the largest
        position shift an undetected error of one entry's MDB causes in the node
    uncontrolled : (m, n) inlier entries with redundancy number below the bound (not testable)
    alternative : when status is "ambiguous", the other answer (a dict as `to_dict` gives), else None
    gauge : (i, k) (3D: (i, k, l)), the receivers (0-based) fixed at the origin, on the positive x
        axis (and in the xy half-plane y > 0); None in an anchors' frame (`frame`)
    receiver_cov, transmitter_cov : (m, dim, dim), (n, dim + 1, dim + 1) covariance of each node's
        coordinates (a transmitter's offset last), sigma^2 N^-1 in the result's gauge or frame; inf where
        not determined, NaN for a node not placed (solvers.calibration.frame.node_covariances)
    frame : None in the solver's gauge; after solvers.calibration.frame.anchor_frame, the transform into
        the anchors' frame (fit, rotation, translation, scale), its test and each anchor's residual
    dim : 2 or 3, the dimension of the positions
    measured : (m, n) bool, the entries of F that hold a measurement
    receiver_delays : (m,) each receiver's delay (units of F; their mean is in the offsets) when the fit
        modelled them, F_ij = |r_i - s_j| + o_j + d_i (the plane-wave route fits them when the residuals
        depend on the direction of arrival: a channel's latency, an acoustic centre), else None
    """

    status: Status
    message: str
    receivers: np.ndarray
    transmitters: np.ndarray
    offsets: np.ndarray
    inliers: np.ndarray
    residuals: np.ndarray
    rms: float
    sigma: float
    sigma_estimated: bool
    receiver_std: np.ndarray
    transmitter_std: np.ndarray
    offset_std: np.ndarray
    warnings: tuple[str, ...] = ()
    solver: str = ""
    samples: int = 0
    hypotheses: int = 0
    seconds: float = 0.0
    seed: int | None = None
    dof: int = 0
    global_test: tuple[float, float, bool] | None = None
    redundancy: np.ndarray | None = None
    w_test: np.ndarray | None = None
    critical_value: float = float("nan")
    mdb: np.ndarray | None = None
    receiver_reliability: np.ndarray | None = None
    transmitter_reliability: np.ndarray | None = None
    uncontrolled: np.ndarray | None = None
    alternative: dict | None = None
    gauge: tuple[int, ...] | None = None
    measured: np.ndarray | None = None
    receiver_cov: np.ndarray | None = None
    transmitter_cov: np.ndarray | None = None
    frame: dict | None = None
    receiver_delays: np.ndarray | None = None

    @property
    def dim(self) -> int:
        return int(self.receivers.shape[1])

    @property
    def ok(self) -> bool:
        """True only when the status is "ok" (see `status` for what that checks)."""
        return self.status == "ok"

    @property
    def m(self) -> int:
        return self.receivers.shape[0]

    @property
    def n(self) -> int:
        return self.transmitters.shape[0]

    def to_dict(self) -> dict:
        """JSON-ready dictionary (NaN and inf become null)."""

        def clean(a):
            if a is None:
                return None
            a = np.asarray(a)
            if a.dtype == bool:
                return a.tolist()
            return [clean(x) for x in a] if a.ndim else (float(a) if np.isfinite(a) else None)

        return {
            "status": self.status,
            "message": self.message,
            "receivers": clean(self.receivers),
            "transmitters": clean(self.transmitters),
            "offsets": clean(self.offsets),
            "inliers": clean(self.inliers),
            "rms": clean(self.rms),
            "sigma": clean(self.sigma),
            "sigma_estimated": self.sigma_estimated,
            "receiver_std": clean(self.receiver_std),
            "transmitter_std": clean(self.transmitter_std),
            "offset_std": clean(self.offset_std),
            "warnings": list(self.warnings),
            "solver": self.solver,
            "samples": self.samples,
            "hypotheses": self.hypotheses,
            "seconds": round(self.seconds, 4),
            "seed": self.seed,
            "dof": self.dof,
            "global_test": None if self.global_test is None else {
                "statistic": clean(self.global_test[0]), "critical": clean(self.global_test[1]),
                "passed": bool(self.global_test[2])},
            "redundancy": clean(self.redundancy),
            "w_test": clean(self.w_test),
            "critical_value": clean(self.critical_value),
            "mdb": clean(self.mdb),
            "receiver_reliability": clean(self.receiver_reliability),
            "transmitter_reliability": clean(self.transmitter_reliability),
            "uncontrolled": clean(self.uncontrolled),
            "alternative": self.alternative,
            "gauge": None if self.gauge is None else [int(g) for g in self.gauge],
            "dim": self.dim,
            "receiver_cov": clean(self.receiver_cov),
            "transmitter_cov": clean(self.transmitter_cov),
            "frame": self.frame,
            "receiver_delays": clean(self.receiver_delays),
        }

