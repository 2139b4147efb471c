"""The state passed along the calibration stages (diagnose -> initialise -> adjust -> judge).

`Diagnosis` is what the data say before any fit of the model (stage `diagnose`); `Start` is where the
adjustment begins and how it was found (stage `initialise`); `CalibrationState` carries both with the
data, so that each stage reads what the one before decided instead of deciding again.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from .factorization import LowRank, MetricUpgrade

Wavefront = Literal["plane", "spherical", "unknown"]
Route = Literal["factorization", "search"]


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """What the data alone say (`diagnose.diagnose`).

    entries, unknowns, dof : measured entries, unknowns of the model after the gauge (K m + (K + 1) n -
        K (K + 1) / 2 over the nodes with enough entries), and their difference (the redundancy)
    singular_values : the K of the robust rank-K factorization of F after its column offsets, then the
        largest of what it leaves on its inliers (the (K + 1)-th), divided by the first (None when the data are too few to factorize with redundancy)
    curvature : singular_values[K] (the (K + 1)-th): the share of the wavefronts' curvature; small for
        plane waves (sources far from a compact array), order 0.1-1 when the nodes are mixed
    wavefront : "plane" when curvature < FAR_FIELD_CURVATURE, "spherical" above, "unknown" when not
        computed
    low_rank, upgrade : the rank-K factorization and its metric upgrade (plane waves only)
    elevation_span : degrees the source directions span out of the plane of their largest spread (plane
        waves only; small: the receivers' coordinate along `span_axis` is weakly determined)
    orientation_ratio : robust scale of the rank-K fit with row offsets over that with column offsets
        (plane waves only): well above 1, the columns are the transmitters
    notes : sentences for the result's warnings
    """

    dim: int
    entries: int
    unknowns: int
    dof: int
    singular_values: np.ndarray | None = None
    curvature: float = float("nan")
    wavefront: Wavefront = "unknown"
    low_rank: LowRank | None = None
    upgrade: MetricUpgrade | None = None
    elevation_span: float = float("nan")
    span_axis: np.ndarray | None = None
    orientation_ratio: float = float("nan")
    notes: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False)
class Start:
    """Receivers, transmitters and offsets where the adjustment begins, and the route that found them."""

    R: np.ndarray
    S: np.ndarray
    O: np.ndarray
    route: Route
    notes: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False)
class CalibrationState:
    """The data and what the stages decided so far."""

    F: np.ndarray
    mask: np.ndarray
    dim: int
    sigma: float | None
    diagnosis: Diagnosis | None = None
    start: Start | None = None
    notes: tuple[str, ...] = field(default_factory=tuple)
