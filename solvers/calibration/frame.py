"""The calibration in a user's frame: node covariances, anchors, and the transform into their frame.

A calibration is determined up to a rigid motion (and a reflection): the pipeline reports it in the
solver's gauge (receiver 1 at the origin, receiver 2 on +x, ...; `CalibrationResult.gauge`). This
module owns what takes it elsewhere:

* `node_covariances`: the full covariance of every node from the adjustment, sigma^2 N^-1 restricted
  to the node's coordinates (receivers dim x dim; transmitters (dim + 1) x (dim + 1), the offset last);
* `widen_far_ranges`: that covariance widened along the range of a far node whose range is weakly
  determined (a far-field source: its error is skewed, symmetric in 1 / range);
* `read_anchors` / `parse_anchors`: known positions of some nodes with their standard deviations (a
  CSV read by the project's own tokenizer, solvers.calibrate_io.parse_measurements);
* `anchor_frame`: the rigid (or similarity) transform that takes the calibrated anchors onto their
  known positions by weighted least squares (weighted Procrustes / Umeyama, reflections allowed: the
  data cannot tell a network from its mirror image), the test of that fit, and the result in that
  frame with the uncertainty carried: each node's covariance rotated (and scaled) into the frame plus
  the transform's own covariance propagated to it (first order; the correlation between a node and
  the anchors' calibrated positions is neglected, see `anchor_frame`).

Reference: Umeyama, Least-squares estimation of transformation parameters between two point patterns,
IEEE PAMI 1991 (weighted form); the S-transformation of geodetic networks (Baarda 1973) for why a
datum change moves the covariance.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

__all__ = ["ANCHOR_FITS", "AnchorError", "Anchors", "anchor_frame", "node_covariances", "parse_anchors", "read_anchors",
           "widen_far_ranges"]

#: A node farther than this many times the other kind's spread (rms distance from its centroid) from that
#: centroid is "far" for `widen_far_ranges` (a room's nodes are among each other: none is).
FAR_SPREADS = 2.0
#: ... and its range is "weakly determined" where its linear std along the range exceeds this share of the range.
RANGE_SHARE = 0.05

AnchorFit = Literal["rigid", "similarity"]
#: The transforms `anchor_frame` fits (``--anchor-fit``).
ANCHOR_FITS = ("rigid", "similarity")


class AnchorError(ValueError):
    """An anchor file or set that cannot be used; the message is one line."""


def node_covariances(st, m: int, n: int, dim: int):
    """(receiver_cov (m, dim, dim), transmitter_cov (n, dim + 1, dim + 1)) of an adjustment
    (solvers.calibration.adjustment.AdjustmentStatistics, or None): sigma^2 N^-1 restricted to each
    node's coordinates (a transmitter's offset last), in the fit's gauge (its fixed coordinates have
    variance 0); inf on a coordinate the fit does not determine, NaN for a node not in the fit, and
    inf everywhere when st is None or its sigma is not finite."""
    rcov, tcov = np.full((m, dim, dim), np.nan), np.full((n, dim + 1, dim + 1), np.nan)
    if st is None or not np.isfinite(st.sigma):
        rcov[:], tcov[:] = np.inf, np.inf
        return rcov, tcov
    p = st.problem
    bad = np.append(st.null, False)
    rs, ts = p.slots_of(True), p.slots_of(False)
    for slots, out, nodes in ((rs, rcov, p.rows), (ts, tcov, p.cols)):
        # the blocks of N^-1 (kept by blocks: adjustment.AdjustmentStatistics.inverse); a fixed
        # coordinate (slot n_params) reads 0
        block = st.sigma**2 * st.inverse.entries(slots[:, :, None], slots[:, None, :])
        undetermined = bad[slots]
        block[undetermined[:, :, None] | undetermined[:, None, :]] = np.inf
        out[nodes] = block
    return rcov, tcov


def widen_far_ranges(R: np.ndarray, S: np.ndarray, rcov: np.ndarray, tcov: np.ndarray, *, far: float = FAR_SPREADS,
                     share: float = RANGE_SHARE):
    """(rcov, tcov, widened ((kind "r" or "s", index) of each node widened)): the node covariances with each far node's range variance widened to the far
    side of its 1-sigma interval in inverse range.

    A node far from the other kind's nodes (a source 4 m from a 25 cm array) is located in bearing well and in
    range poorly, and its range error is skewed: the data determine u = 1 / range (with the bearing) about
    linearly, so the error is symmetric in u and the range runs out far more than it runs in (the 48 x 540
    far-field array: a source fitted at 2.05 m with a linear std of 0.31 m lies at 3.72 m, 5.45 std out, and
    2.97 std out in u). Where the node lies more than `far` spreads of the other kind from its centroid c and
    its linear range std sigma_r (along d = (x - c) / r, r = |x - c|) exceeds `share` r, the range std becomes
    1 / (u - sigma_u) - r = sigma_r / (1 - eps), eps = sigma_r / r, sigma_u = sigma_r / r^2 (the far side of the
    1-sigma interval in u; as for a distance from a parallax), and inf where eps >= 1 (the range is not
    bounded): the position block gets (sigma_r'^2 - sigma_r^2) d d^T more. Nodes that are not far, or whose
    range is well determined, keep their covariance exactly. R, S: positions (NaN: not placed); rcov
    (m, dim, dim), tcov (n, dim + 1, dim + 1) as `node_covariances` gives them."""
    rcov, tcov = rcov.copy(), tcov.copy()
    dim = R.shape[1]
    widened: list[tuple[str, int]] = []
    for X, cov, others, tag in ((R, rcov, S, "r"), (S, tcov, R, "s")):
        placed = others[np.all(np.isfinite(others), axis=1)]
        if len(placed) < 2:
            continue
        c = placed.mean(axis=0)
        spread = float(np.sqrt(np.mean(np.sum((placed - c) ** 2, axis=1))))
        for k in range(len(X)):
            C = cov[k, :dim, :dim]
            if not (np.all(np.isfinite(X[k])) and np.all(np.isfinite(C))):
                continue
            v = X[k] - c
            r = float(np.linalg.norm(v))
            if r <= far * spread:
                continue
            d = v / r
            var_r = float(d @ C @ d)
            eps = math.sqrt(max(var_r, 0.0)) / r
            if eps <= share:
                continue
            if eps >= 1.0:
                cov[k, :dim, :dim] = np.inf
            else:
                cov[k, :dim, :dim] = C + (var_r / (1.0 - eps) ** 2 - var_r) * np.outer(d, d)
            widened.append((tag, k))
    return rcov, tcov, widened


@dataclass(frozen=True)
class Anchors:
    """Known positions of some nodes.

    names : the names as the file gives them
    receivers : (k,) bool, True where the anchor is a receiver (else a transmitter)
    index : (k,) the node's row (receiver) or column (transmitter) in the measurement matrix
    positions : (k, dim) known coordinates
    std : (k,) standard deviation of each known coordinate (the same on every axis), > 0
    source : the file name
    """

    names: tuple[str, ...]
    receivers: np.ndarray
    index: np.ndarray
    positions: np.ndarray
    std: np.ndarray
    source: str = ""

    @property
    def dim(self) -> int:
        return int(self.positions.shape[1])


def _node(name: str, receivers, transmitters, source: str) -> tuple[bool, int]:
    """(is receiver, index) of an anchor's name: a receiver or transmitter name, or r:NAME / s:NAME."""
    in_r, in_t = name in receivers, name in transmitters
    if in_r != in_t:
        return in_r, (receivers.index(name) if in_r else transmitters.index(name))
    if not in_r and name[:2] in ("r:", "s:"):
        names = receivers if name[0] == "r" else transmitters
        if name[2:] in names:
            return name[0] == "r", names.index(name[2:])
    if in_r:
        raise AnchorError(f"{source}: {name!r} names a receiver and a transmitter; write r:{name} or s:{name}")
    raise AnchorError(f"{source}: no node {name!r} (receivers {', '.join(receivers[:4])}{', ...' if len(receivers) > 4 else ''}; "
                      f"transmitters {', '.join(transmitters[:4])}{', ...' if len(transmitters) > 4 else ''})")


def parse_anchors(text: str, receivers, transmitters, dim: int, source: str = "<anchors>") -> Anchors:
    """Anchors from CSV text: a header row naming the columns x, y (z in 3D) and std in any order (case
    ignored), then one row per anchor: the node's name (a receiver or transmitter name of the
    measurements, or r:NAME / s:NAME when both have it) and its numbers. Delimiters, comments and
    encodings as the measurement CSV (solvers.calibrate_io). Raises AnchorError (one line)."""
    from ..calibrate_io import MeasurementFileError, parse_measurements

    try:
        table = parse_measurements(text, source, header="both", network=False)  # coordinates: no column-spread test
    except MeasurementFileError as e:
        raise AnchorError(str(e)) from None
    columns = [c.strip().lower() for c in table.transmitters]
    need = ["x", "y", "z"][:dim] + ["std"]
    if sorted(columns) != sorted(need):
        raise AnchorError(f"{source}: the header names the columns {', '.join(table.transmitters)}; give {', '.join(need)} "
                          f"({dim}D), e.g. 'node,{','.join(need)}'")
    values = table.F[:, [columns.index(c) for c in need]]
    for k, name in enumerate(table.receivers):
        if not np.all(np.isfinite(values[k])):
            raise AnchorError(f"{source}: anchor {name!r} has a missing value; every anchor needs {', '.join(need)}")
        if values[k, -1] <= 0:
            raise AnchorError(f"{source}: anchor {name!r}: std must be > 0 (a known position is never exact), got "
                              f"{values[k, -1]:g}")
    nodes = [_node(name, list(receivers), list(transmitters), source) for name in table.receivers]
    if len(set(nodes)) < len(nodes):
        raise AnchorError(f"{source}: a node is given twice")
    return Anchors(tuple(table.receivers), np.array([r for r, _ in nodes], bool), np.array([i for _, i in nodes], int),
                   values[:, :dim].copy(), values[:, dim].copy(), source)


def read_anchors(path: str, receivers, transmitters, dim: int) -> Anchors:
    """`parse_anchors` of a file (UTF-8 or UTF-16 with a byte-order mark, as the measurement CSV)."""
    from ..calibrate_io import MeasurementFileError, _decode

    try:
        with open(path, "rb") as handle:
            data = handle.read()
        text = _decode(data, path)
    except OSError as exc:
        raise AnchorError(f"cannot read {path}: {exc.strerror or exc}") from None
    except MeasurementFileError as e:
        raise AnchorError(str(e)) from None
    return parse_anchors(text, receivers, transmitters, dim, path)


def _rotation_generators(u: np.ndarray) -> np.ndarray:
    """(k, dim, n_rot): the derivative of R(omega) u at omega = 0 for each row u (2D: one angle; 3D: the
    rotation vector, d(omega x u) = -[u]x)."""
    if u.shape[1] == 2:
        return np.stack([-u[:, 1], u[:, 0]], axis=1)[:, :, None]
    x, y, z = u[:, 0], u[:, 1], u[:, 2]
    zero = np.zeros_like(x)
    return np.stack([np.stack([zero, z, -y], 1), np.stack([-z, zero, x], 1), np.stack([y, -x, zero], 1)], axis=1)


def _frame_jacobian(u: np.ndarray, similarity: bool) -> np.ndarray:
    """(k, dim, n_params) derivative of q = s A p + t by (rotation, translation[, log scale]) at u = s A p."""
    k, dim = u.shape
    parts = [_rotation_generators(u), np.broadcast_to(np.eye(dim), (k, dim, dim))]
    if similarity:
        parts.append(u[:, :, None])
    return np.concatenate(parts, axis=2)


def anchor_frame(result, anchors: Anchors, fit: AnchorFit = "rigid", alpha: float = 0.01):
    """The calibration `result` (a CalibrationResult with receiver_cov / transmitter_cov) in the anchors'
    frame.

    The transform q = s A p + t (A orthogonal, reflections allowed; s = 1 for "rigid") minimises
    sum_k w_k |q_k - a_k|^2 over the anchors, w_k = 1 / (std_k^2 + var_k), var_k the calibrated node's
    variance per coordinate (trace of its covariance / dim) in the solver's gauge. Its fit is tested:
    T = sum_k w_k |q_k - a_k|^2 against chi^2 with dim k - (number of transform parameters) degrees of
    freedom at level alpha; a failed test makes the status "inconsistent" (the anchors, their names or
    their unit disagree with the calibration), a frame the anchors cannot fix (too few, or all on a
    line) is refused, and anchors that leave the mirror image open (2D: two; 3D: three, or all in a
    plane) give a warning.

    Uncertainty: each node's covariance C becomes M C M^T + G Cov(theta) G^T, M = s A (and s on a
    transmitter's offset), G the derivative of its position by the transform's parameters theta
    (rotation, translation, log scale) and Cov(theta) = (sum G_k^T w_k G_k)^-1 that of the weighted fit.
    The correlation between a node and the calibrated anchors is neglected: C is the covariance in the
    solver's gauge, which holds the uncertainty of that gauge (large far from receiver 1); the anchored
    std is therefore on the safe side (larger) rather than the least a datum through the anchors could give.

    With "similarity", positions, offsets and their covariances are multiplied by s (a wrong speed of
    sound or unit); sigma, residuals and the tests stay in the measurement's unit.
    Returns a new CalibrationResult with `frame` describing the transform and the anchors' residuals;
    the reliabilities (shift lengths, scaled by s) and an ambiguous result's `alternative` stay in the
    solver's gauge.
    """
    from .result import STATUSES

    if fit not in ANCHOR_FITS:
        raise AnchorError(f"unknown anchor fit {fit!r}; give one of {', '.join(ANCHOR_FITS)}")
    dim = result.dim
    if anchors.dim != dim:
        raise AnchorError(f"{anchors.source}: {anchors.dim}D anchors for a {dim}D calibration")
    if result.receiver_cov is None or result.transmitter_cov is None:
        raise AnchorError("the result carries no covariance (a failed calibration?)")
    P = np.array([result.receivers[i] if r else result.transmitters[i]
                  for r, i in zip(anchors.receivers, anchors.index)]).reshape(-1, dim)
    C = np.array([result.receiver_cov[i] if r else result.transmitter_cov[i][:dim, :dim]
                  for r, i in zip(anchors.receivers, anchors.index)]).reshape(-1, dim, dim)
    usable = np.all(np.isfinite(P), axis=1) & np.all(np.isfinite(C), axis=(1, 2))
    need = dim if fit == "rigid" else dim + 1  # points that fix the transform (up to the mirror)
    if usable.sum() < max(2, dim):
        raise AnchorError(f"{int(usable.sum())} of the {len(P)} anchors are placed with a finite covariance; a {dim}D "
                          f"frame needs at least {max(2, dim)}")
    P, C, a = P[usable], C[usable], anchors.positions[usable]
    names = [n for n, u in zip(anchors.names, usable) if u]
    var = np.trace(C, axis1=1, axis2=2) / dim
    w = 1.0 / (anchors.std[usable] ** 2 + var)
    p_bar, a_bar = w @ P / w.sum(), w @ a / w.sum()
    Pc, Ac = P - p_bar, a - a_bar
    spread_a = np.linalg.svd(Ac, compute_uv=False)
    extent = max(float(spread_a[0]), 1e-300)
    if spread_a[0] <= 1e-9 * max(1.0, float(np.abs(a).max())):
        raise AnchorError("the anchors coincide: a frame needs anchors at distinct positions")
    U, _, Vt = np.linalg.svd((Pc * w[:, None]).T @ Ac)
    A = Vt.T @ U.T
    s = 1.0
    if fit == "similarity":
        s = float(np.sum(w[:, None] * Ac * (Pc @ A.T)) / np.sum(w[:, None] * Pc * Pc))
    t = a_bar - s * A @ p_bar
    u = s * P @ A.T
    resid = u + t - a
    stat = float(np.sum(w * np.sum(resid**2, axis=1)))
    n_params = (1 if dim == 2 else 3) + dim + (1 if fit == "similarity" else 0)
    dof = dim * len(P) - n_params
    warnings = list(result.warnings)
    flat = int(np.sum(spread_a > 1e-6 * extent))  # the dimension the anchors span
    if flat < dim - 1 or (flat < dim and len(P) < need):
        raise AnchorError(f"the {len(P)} anchors lie on a line: they cannot fix a {dim}D frame's rotation")
    if flat < dim:
        warnings.append(f"the anchors lie in a {'line' if dim == 2 else 'plane'}: the mirror image across it fits them "
                        "as well; the side is not decided by the anchors")
    G = _frame_jacobian(u, fit == "similarity")
    info = np.einsum("kdi,k,kdj->ij", G, w, G)
    cov_theta = np.linalg.pinv(info)
    critical = None
    status, message = result.status, result.message
    if dof > 0:
        from scipy import stats

        critical = float(stats.chi2.isf(alpha, dof))
        if stat > critical:
            worst = int(np.argmax(w * np.sum(resid**2, axis=1)))
            why = (f"the anchors do not fit the calibration: sum of squared residuals / variance {stat:.4g} > {critical:.4g} "
                   f"(chi^2, {dof} degrees of freedom, level {alpha:g}); the worst is {names[worst]}, "
                   f"{np.linalg.norm(resid[worst]):.3g} off ({np.linalg.norm(resid[worst]) * math.sqrt(w[worst]):.2g} std): "
                   "check its name, position and unit")
            warnings.insert(0, why)
            if STATUSES.index("inconsistent") < STATUSES.index(status):
                status = "inconsistent"
                message = f"inconsistent: {why} (calibration: {result.message})"
    M = s * A

    def move_positions(X):
        return X @ M.T + t

    def move_cov(Cn, X):
        out = np.full_like(Cn, np.nan)
        T = s * np.eye(Cn.shape[1])
        T[:dim, :dim] = M
        for k in range(len(Cn)):
            if not np.all(np.isfinite(X[k])):
                continue  # not placed
            if not np.all(np.isfinite(Cn[k])):
                out[k] = np.inf  # undetermined stays undetermined
                continue
            Gk = _frame_jacobian((M @ X[k])[None], fit == "similarity")[0]
            out[k] = T @ Cn[k] @ T.T
            out[k][:dim, :dim] += Gk @ cov_theta @ Gk.T
        return out

    R2, S2 = move_positions(result.receivers), move_positions(result.transmitters)
    rcov, tcov = move_cov(result.receiver_cov, result.receivers), move_cov(result.transmitter_cov, result.transmitters)
    rstd = np.sqrt(np.trace(rcov, axis1=1, axis2=2))
    tstd = np.sqrt(np.trace(tcov[:, :dim, :dim], axis1=1, axis2=2))
    ostd = np.sqrt(tcov[:, dim, dim])
    frame = {
        "fit": fit, "source": anchors.source, "rotation": A.tolist(), "translation": t.tolist(), "scale": s,
        "statistic": stat, "critical": critical, "dof": dof, "passed": None if critical is None else bool(stat <= critical),
        "anchors": [{"name": nm, "position": a[k].tolist(), "residual": resid[k].tolist(),
                     "residual_std": float(np.linalg.norm(resid[k]) * math.sqrt(w[k]))} for k, nm in enumerate(names)],
    }
    if not usable.all():
        left = [n for n, ok in zip(anchors.names, usable) if not ok]
        warnings.append(f"anchors not used (not placed, or undetermined): {', '.join(left)}")
    return replace(result, status=status, message=message, receivers=R2, transmitters=S2,
                   offsets=s * result.offsets, receiver_delays=None if result.receiver_delays is None else
                   s * result.receiver_delays, receiver_std=np.where(np.isnan(result.receiver_std), np.nan, rstd),
                   transmitter_std=np.where(np.isnan(result.transmitter_std), np.nan, tstd),
                   offset_std=np.where(np.isnan(result.offset_std), np.nan, ostd),
                   receiver_cov=rcov, transmitter_cov=tcov, warnings=tuple(warnings), gauge=None, frame=frame,
                   receiver_reliability=None if result.receiver_reliability is None else s * result.receiver_reliability,
                   transmitter_reliability=None if result.transmitter_reliability is None else
                   s * result.transmitter_reliability)
