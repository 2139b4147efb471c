"""Public entry points: from TDOA measurements to calibrations (paper Section 3 pipeline).

``solve_network(F)`` validates the data, runs the cheapest generated solver that fits the network on a
subset (the first receivers and transmitters; :data:`SOLVER_ORDER`), recovers positions and offsets from every
real candidate with all receivers (:mod:`solvers.recovery`), places the transmitters the solver did
not use by linear TDOA multilateration, refines with Levenberg-Marquardt on all m*n measurements
(:mod:`solvers.refine`) and returns the calibrations best first. ``solve_roots(F)`` is the lower-level
entry: the raw candidate roots (H, b, o) of the dispatched solver. ``calibrations(module, F)`` turns
the roots of any generated TDOA solver (committed or written by ``solvers.generate``) on its own data
into positions and offsets.
"""
from __future__ import annotations

import importlib
import os
import re
import warnings
from dataclasses import dataclass

import numpy as np

from .recovery import Calibration, recover, rms_residual, to_gauge
from .refine import refine as _refine

__all__ = ["KD_SOLVERS", "SOLVER_ORDER", "SolverChoice", "calibrations", "degrees_of_freedom", "minimal_configuration",
           "select_solver", "select_solver_kd", "solve_network", "solve_roots"]

_GENERATED = os.path.join(os.path.dirname(os.path.abspath(__file__)), "generated")


@dataclass(frozen=True)
class SolverChoice:
    """Which generated solver handles a network, and on which subset of nodes."""

    label: str
    m: int
    n: int
    module: str


#: Where a configuration has committed solvers of two methods, the one solve_network runs: the faster in
#: scripts/bench_minimal.py (same run, interleaved), and only if it is at least as reliable
#: (tables/solvers_minimal.md). 3r3stoa: the homotopy (1000/1000 networks) over the action matrix (992/1000;
#: both 0.56 ms a solve in the same run, docs/action-matrix.md). Without an entry, the solver that is not
#: an action matrix is used.
PREFERRED_METHOD = {"3r3stoa": "homotopy"}

#: Method -> the tag in its module names (solvers.codegen.module_name).
_METHOD_TAG = {"homotopy": "homotopy", "curve-pencil": "pencil", "offset-kernel": "kernel", "action-matrix": "action"}


def _module_for(label: str, method: str | None = None):
    """The committed module of a configuration: of ``method`` if given, else the preferred one
    (:data:`PREFERRED_METHOD`)."""
    names = sorted(f[:-3] for f in os.listdir(_GENERATED) if f.startswith(f"tdoa_{label}_") and f.endswith(".py"))
    if not names:
        raise RuntimeError(f"no generated solver for {label} in {_GENERATED}; run scripts/generate_solvers.py")
    if method is not None and method not in _METHOD_TAG:
        raise ValueError(f"unknown method {method!r}; valid: {', '.join(_METHOD_TAG)}")
    want = method or PREFERRED_METHOD.get(label)
    if want is not None:
        chosen = [n for n in names if re.fullmatch(rf"tdoa_{re.escape(label)}_{_METHOD_TAG[want]}\d+", n)]
        if not chosen:
            raise RuntimeError(f"no committed {want} solver for {label} in {_GENERATED}")
    else:
        chosen = [n for n in names if "_action" not in n] or names
    return importlib.import_module(f"solvers.generated.{chosen[-1]}")


#: Solvers by expected cost (paths or pencil size, measured in tables/solvers.csv): the first one
#: whose configuration fits inside the network (m >= m_s and n >= n_s) is used.
SOLVER_ORDER = ("6r4s", "9r3s", "8r3s", "7r3s", "6r3s", "5r5s", "5r4s", "4r5s")

#: Solvers whose unknowns are receiver coordinates (analysis.formulations.positions variant), not (H, b, o).
POSITIONS = {"4r5s": "receivers-orbits"}

#: Configurations with as many measurements as degrees of freedom (2m + 3n - 3 = mn).
MINIMAL = ((6, 3), (4, 5))

#: The committed solvers of the other dimensions and models, (dim, model) -> labels by cost (root count):
#: the first whose configuration fits inside the network is used. TOA: the minimal cells (2D 3r/3s,
#: 8 roots; 3D 4r/6s and 6r/4s, 38; 5r/5s, 42), compaction unknowns (H, b), but 4r/6s in the receivers' Gram
#: matrix (6 unknowns, the fastest of the three measured); 3D TDOA: 9r/5s (1 root), then the minimal cells 7r/5s
#: (2321 paths) and 6r/6s (3920 paths), one path per orbit of the gauge reflections (direct parametrization,
#: count by monodromy, not certified).
KD_SOLVERS = {(2, "toa"): ("3r3stoa",), (3, "toa"): ("4r6s3dgram", "6r4s3dtoa", "5r5s3dtoa"),
              (3, "tdoa"): ("9r5s3d", "7r5s3d", "6r6s3d")}

MODELS = ("tdoa", "toa")


def degrees_of_freedom(m: int, n: int, dim: int = 2, model: str = "tdoa") -> int:
    """Unknowns of an m x n network up to the Euclidean group: K (m + n) positions (+ n offsets for
    TDOA) minus K (K + 1) / 2 (translations and rotations)."""
    return dim * (m + n) + (n if model == "tdoa" else 0) - dim * (dim + 1) // 2


def minimal_configuration(m: int, n: int, dim: int = 2, model: str = "tdoa") -> bool:
    """Whether an m x n network is a minimal problem (as many measurements as degrees of freedom, so that
    its real solutions all fit the data exactly): 2D TDOA 6r/3s, 4r/5s; 3D TDOA 10r/4s, 7r/5s, 6r/6s,
    5r/9s; 2D TOA 3r/3s; 3D TOA 4r/6s, 5r/5s, 6r/4s."""
    return m * n == degrees_of_freedom(m, n, dim, model)


def _validate(F) -> np.ndarray:
    try:
        arr = np.asarray(F, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"F must be a 2-D array of real numbers: {exc}") from None
    if arr.ndim != 2:
        raise ValueError(f"F must be a 2-D (receivers x transmitters) array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("F contains NaN or infinite values")
    select_solver(*arr.shape)
    return arr


def _available() -> list[tuple[str, int, int]]:
    names = os.listdir(_GENERATED)
    out = []
    for label in SOLVER_ORDER:
        if any(f.startswith(f"tdoa_{label}_") and f.endswith(".py") for f in names):
            m, n = (int(v) for v in label[:-1].split("r"))
            out.append((label, m, n))
    return out


def select_solver(m: int, n: int) -> SolverChoice:
    """The cheapest generated solver whose configuration fits an m x n network (see :data:`SOLVER_ORDER`)."""
    avail = _available()
    for label, ms, ns in avail:
        if m >= ms and n >= ns:
            return SolverChoice(label, ms, ns, _module_for(label).__name__)
    have = ", ".join(f"{ms}r/{ns}s" for _, ms, ns in avail)
    raise ValueError(f"too few nodes: {m} receivers x {n} transmitters; the solvers need at least one of {have}")


def solve_roots(F) -> np.ndarray:
    """Raw candidate roots (k, 5 + n_s) of the dispatched solver, unknowns h11, h12, h22, b1, b2, o1..o_ns.

    Uses the first m_s receivers and n_s transmitters of F (see :func:`select_solver`); complex and
    spurious candidates included, non-finite ones removed.
    """
    F = _validate(F)
    choice = select_solver(*F.shape)
    module = importlib.import_module(choice.module)
    with np.errstate(all="ignore"):
        roots = module.solve(F[: choice.m, : choice.n])
    return roots[np.all(np.isfinite(roots), axis=1)]


def _from_positions(F: np.ndarray, choice: SolverChoice, x: np.ndarray, tol: float = 1e-6) -> Calibration | None:
    """A real calibration of the solver's block from a positions root (None for a complex network)."""
    from analysis.formulations.positions import positions_system

    if F.shape[0] > choice.m:
        return None  # receivers beyond the block: a cheaper solver covers such networks
    system = positions_system(choice.m, choice.n, POSITIONS[choice.label])
    return _positions_calibration(system, F[: choice.m, : choice.n], x, tol)


def _positions_calibration(system, block: np.ndarray, x: np.ndarray, tol: float = 1e-6) -> Calibration | None:
    """The calibration of a positions formulation's root x on its data block (None unless real and finite)."""
    from analysis.formulations.positions import network_from_root

    rec, tra, off = network_from_root(system, x, block)
    parts = np.concatenate([rec.ravel(), tra.ravel(), off])
    if not np.all(np.isfinite(parts)) or np.max(np.abs(parts.imag)) > tol * (1.0 + np.max(np.abs(parts))):
        return None
    rec, tra, off = rec.real, tra.real, off.real
    return Calibration(rec, tra, off, rms_residual(block, rec, tra, off))


def _check_kind(dim: int, model: str) -> None:
    if dim not in (2, 3):
        raise ValueError(f"dim must be 2 or 3, got {dim!r}")
    if model not in MODELS:
        raise ValueError(f"model must be one of {', '.join(MODELS)}, got {model!r}")


def select_solver_kd(m: int, n: int, dim: int, model: str) -> SolverChoice:
    """The cheapest committed solver of this dimension and model that fits an m x n network
    (:data:`KD_SOLVERS`; 2D TDOA: :func:`select_solver`)."""
    _check_kind(dim, model)
    if (dim, model) == (2, "tdoa"):
        return select_solver(m, n)
    labels = KD_SOLVERS.get((dim, model), ())
    have = []
    for label in labels:
        ms, ns = (int(v) for v in re.match(r"(\d+)r(\d+)s", label).groups())
        have.append(f"{ms}r/{ns}s")
        if m >= ms and n >= ns:
            return SolverChoice(label, ms, ns, _module_for(label).__name__)
    raise ValueError(f"too few nodes for {dim}D {model.upper()}: {m} receivers x {n} transmitters; the solvers need at "
                     f"least one of {', '.join(have) or 'none (no committed solver)'}")


#: The first unknowns of every (H, b, o) formulation; the offsets o_1..o_n follow.
HBO_UNKNOWNS = ("h11", "h12", "h22", "b1", "b2")
#: The same in 3D: H's upper triangle, then b.
HBO_UNKNOWNS_3D = ("h11", "h12", "h13", "h22", "h23", "h33", "b1", "b2", "b3")


def calibrations(module, F, roots: np.ndarray | None = None) -> list[Calibration]:
    """Positions and offsets from a generated TDOA solver's candidate roots on its own data.

    module: a generated solver module (``SYSTEM``, ``CONFIG``, ``UNKNOWNS``, ``solve``), whether
    committed or written by ``solvers.generate.generate``; F: its (m, n) = ``CONFIG`` data; roots: its
    candidates (default ``module.solve(F)``). (H, b, o) roots, 2D or 3D, go through
    :func:`solvers.recovery.recover`, positions roots (4r/5s) through
    :func:`analysis.formulations.positions.network_from_root`. Returns the real, geometrically valid calibrations
    sorted by RMS residual (best first), in the gauge r_1 = 0, r_2 = (r_2x > 0, 0) (3D: r_2 =
    (r_2x > 0, 0, 0), r_3 = (r_3x, r_3y > 0, 0)); a reflection of the plane (3D: of space in the
    plane of r_1, r_2, r_3) is a second solution the data cannot tell apart, one representative is returned. Nothing is refined (:func:`solve_network` and
    :func:`solvers.calibration.calibrate` do). Raises ValueError for a module whose unknowns are not a
    TDOA formulation's, or for data of another shape.
    """
    F = np.asarray(F, dtype=float)
    m, n = module.CONFIG if getattr(module, "CONFIG", None) else (None, None)
    if F.shape != (m, n):
        raise ValueError(f"{module.__name__}: data of shape {F.shape} given; the solver needs ({m}, {n})")
    roots = module.solve(F) if roots is None else np.asarray(roots)
    system = None
    offsets = tuple(f"o{j}" for j in range(1, n + 1))
    if "positions-" in module.SYSTEM:
        from analysis.formulations.positions import positions_system

        system = positions_system(m, n, module.SYSTEM.split("positions-", 1)[1])
    elif "-direct" in module.SYSTEM:
        return _direct_calibrations(F, module.UNKNOWNS, roots)
    elif "-gram" in module.SYSTEM:
        return _gram_calibrations(F, module.UNKNOWNS, roots)
    elif tuple(module.UNKNOWNS) not in (HBO_UNKNOWNS + offsets, HBO_UNKNOWNS_3D + offsets, HBO_UNKNOWNS,
                                        HBO_UNKNOWNS_3D):
        raise ValueError(f"{module.__name__}: unknowns {module.UNKNOWNS} are neither (H, b[, o]) nor a positions formulation's")
    h, k = (6, 3) if tuple(module.UNKNOWNS[:9]) == HBO_UNKNOWNS_3D else (3, 2)
    toa = system is None and len(module.UNKNOWNS) == h + k  # no offsets: synchronised transmitters (TOA)
    out = []
    with np.errstate(all="ignore"):
        for x in roots[np.all(np.isfinite(roots), axis=1)]:
            cal = (_positions_calibration(system, F, x) if system is not None
                   else recover(F, x[:h], x[h:h + k], np.zeros(n) if toa else x[h + k:]))
            if cal is not None:
                out.append(cal)
    return sorted(out, key=lambda c: c.residual)


_DIRECT_NAME = re.compile(r"([rs])(\d+)([xyz])|o(\d+)")


def _direct_calibrations(F: np.ndarray, unknowns, roots: np.ndarray, tol: float = 1e-6) -> list[Calibration]:
    """:func:`calibrations` of a direct-parametrization solver (unknowns r<i><axis> of the receivers in the gauge
    frame, s<j><axis>, o<j>; analysis.formulations.kd): the real roots whose distances f_ij - o_j are all
    non-negative (the equations square them), moved into the gauge by a rotation (one root per orbit of the
    frame's reflections is enough: the others give the same network or its mirror image)."""
    m, n = F.shape
    fields = [_DIRECT_NAME.fullmatch(u) for u in unknowns]
    if not all(fields):
        raise ValueError(f"unknowns {tuple(unknowns)} are not a direct parametrization's")
    dim = 1 + max("xyz".index(f.group(3)) for f in fields if f.group(3))
    out = []
    scale = float(np.sqrt(np.mean(F * F))) or 1.0
    for x in roots[np.all(np.isfinite(roots), axis=1)]:
        if np.max(np.abs(x.imag)) > tol * (1.0 + np.max(np.abs(x))):
            continue
        rec, tra, off = np.zeros((m, dim)), np.zeros((n, dim)), np.zeros(n)
        for f, v in zip(fields, x.real):
            if f.group(4):
                off[int(f.group(4)) - 1] = v
            else:
                (rec if f.group(1) == "r" else tra)[int(f.group(2)) - 1, "xyz".index(f.group(3))] = v
        if np.min(F - off[None, :]) < -tol * scale:  # a negative distance fits the squared equations only
            continue
        gauged = to_gauge(rec, tra)
        if gauged is None:
            continue
        rec, tra = gauged
        res = rms_residual(F, rec, tra, off)
        if np.isfinite(res):
            out.append(Calibration(rec, tra, off, res))
    return sorted(out, key=lambda c: c.residual)


#: Gauss-Newton steps on the range equations after a Gram root's positions (:func:`_range_newton`).
GRAM_NEWTON = 3


def _range_newton(F: np.ndarray, rec: np.ndarray, tra: np.ndarray, steps: int = GRAM_NEWTON) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Newton steps (minimum-norm, the gauge left free) on |r_i - s_j|^2 - f_ij^2 in the positions, each
    kept only when it lowers the residual. A Gram root maps to positions through G's Cholesky factor, which
    is ill-conditioned when r_1..r_{K+1} are close to coplanar (bench seed 103 of 6r/4s, solved transposed:
    1.8e-7 relative position error); the range equations are not, and the steps restore full accuracy."""
    m, n, k = len(rec), len(tra), rec.shape[1]
    ii, jj = np.divmod(np.arange(m * n), n)

    def res(r, t):
        return (((r[:, None, :] - t[None, :, :]) ** 2).sum(-1) - F ** 2).ravel()

    current = res(rec, tra)
    for _ in range(steps):
        diff = rec[ii] - tra[jj]  # (mn, k)
        J = np.zeros((m * n, (m + n) * k))
        rows = np.arange(m * n)
        for a in range(k):
            J[rows, ii * k + a] = 2.0 * diff[:, a]
            J[rows, (m + jj) * k + a] = -2.0 * diff[:, a]
        step = np.linalg.lstsq(J, -current, rcond=None)[0]
        r2, t2 = rec + step[:m * k].reshape(m, k), tra + step[m * k:].reshape(n, k)
        trial = res(r2, t2)
        if not np.linalg.norm(trial) < np.linalg.norm(current):
            break
        rec, tra, current = r2, t2, trial
    return rec, tra


def _gram_calibrations(F: np.ndarray, unknowns, roots: np.ndarray, tol: float = 1e-6) -> list[Calibration]:
    """:func:`calibrations` of a gram-parametrization solver (TOA; unknowns the upper triangle of the Gram
    matrix G = R R^T of the receivers r_2..r_{K+1} relative to r_1, then a<i>_1..a<i>_K of each further
    receiver: analysis.formulations.kd): the real roots with G positive definite. The receivers are the rows
    of G's Cholesky factor L (r_2 on the x axis, r_3 in the xy plane: the gauge) and r_i = L^T a_i; the
    transmitters solve R s_j = w_j / 2, w_j,a = G_aa + f_1j^2 - f_{a+1,j}^2 (the ranges to r_1..r_{K+1})."""
    m, n = F.shape
    k = {3: 2, 6: 3}.get(sum(u.startswith("g") for u in unknowns))  # G's upper triangle: K (K + 1) / 2 entries
    if k is None or len(unknowns) != k * (k + 1) // 2 + k * max(m - k - 1, 0):
        raise ValueError(f"unknowns {tuple(unknowns)} are not a gram parametrization's")
    iu = np.triu_indices(k)
    out = []
    for x in roots[np.all(np.isfinite(roots), axis=1)]:
        if np.max(np.abs(x.imag)) > tol * (1.0 + np.max(np.abs(x))):
            continue
        G = np.zeros((k, k))
        G[iu] = x.real[:len(iu[0])]
        G = G + np.triu(G, 1).T
        try:
            L = np.linalg.cholesky(G)
        except np.linalg.LinAlgError:  # not positive definite: no real receivers
            continue
        alpha = x.real[len(iu[0]):].reshape(-1, k)
        rec = np.vstack([np.zeros((1, k)), L, alpha @ L])
        w = np.diag(G)[:, None] + F[0][None, :] ** 2 - F[1:k + 1] ** 2
        rec, tra = _range_newton(F, rec, np.linalg.solve(L, 0.5 * w).T)
        gauged = to_gauge(rec, tra)
        if gauged is None:
            continue
        rec, tra = gauged
        res = rms_residual(F, rec, tra, np.zeros(n))
        if np.isfinite(res):
            out.append(Calibration(rec, tra, np.zeros(n), res))
    return sorted(out, key=lambda c: c.residual)


def multilateration_system(receivers: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A (..., m-1, 3), rhs (..., m-1)) of one transmitter's linearised range equations in (s, o).

    (f_i - o)^2 = |r_i - s|^2 minus the same for receiver 1 (r_1 = 0) is linear in (s, o):
    2 r_i.s - 2 (f_i - f_1) o = |r_i|^2 - f_i^2 + f_1^2, i = 2..m. Receivers (..., m, 2) in the gauge,
    real or complex (bilinear products, no conjugation); f (m,) the transmitter's measurements.
    """
    R = np.asarray(receivers)
    f = np.asarray(f, dtype=float)
    delta = np.broadcast_to(-2.0 * (f[1:] - f[0])[:, None], R.shape[:-2] + (len(f) - 1, 1))
    A = np.concatenate([2.0 * R[..., 1:, :], delta], axis=-1)
    rhs = np.einsum("...ij,...ij->...i", R[..., 1:, :], R[..., 1:, :]) - f[1:] ** 2 + f[0] ** 2
    return A, rhs


def _multilaterate(receivers: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, float] | None:
    """Position and offset of one transmitter from its column of measurements (receivers in gauge),
    by least squares on :func:`multilateration_system`."""
    A, rhs = multilateration_system(receivers, f)
    sol, _, rank, _ = np.linalg.lstsq(A, rhs, rcond=1e-12)
    if rank < 3 or not np.all(np.isfinite(sol)):
        return None
    return sol[:2], float(sol[2])


def _extend(F: np.ndarray, cal: Calibration, n_used: int) -> Calibration | None:
    """Add the transmitters n_used..n-1 to a calibration recovered from the first n_used."""
    m, n = F.shape
    if n == n_used:
        return cal
    tra = np.empty((n, 2))
    off = np.empty(n)
    tra[:n_used], off[:n_used] = cal.transmitters, cal.offsets
    for j in range(n_used, n):
        got = _multilaterate(cal.receivers, F[:, j])
        if got is None:
            return None
        tra[j], off[j] = got
    res = rms_residual(F, cal.receivers, tra, off)
    return Calibration(cal.receivers, tra, off, res) if np.isfinite(res) else None


def _place_transmitter(receivers: np.ndarray, f: np.ndarray, toa: bool) -> tuple[np.ndarray, float] | None:
    """Position and offset (TOA: 0) of one transmitter from its column of measurements, by least squares
    on the linearised range equations (:func:`multilateration_system`; TOA without the offset column)."""
    A, rhs = multilateration_system(receivers, f)
    k = receivers.shape[1]
    if toa:
        A = A[:, :k]
    sol, _, rank, _ = np.linalg.lstsq(A, rhs, rcond=1e-12)
    if rank < A.shape[1] or not np.all(np.isfinite(sol)):
        return None
    return sol[:k], 0.0 if toa else float(sol[k])


def _place_receiver(transmitters: np.ndarray, ranges: np.ndarray) -> np.ndarray | None:
    """Position of one receiver from its ranges d_j = f_ij - o_j to known transmitters (least squares on
    |r - s_j|^2 - |r - s_1|^2 = d_j^2 - d_1^2, linear in r)."""
    S = np.asarray(transmitters)
    A = -2.0 * (S[1:] - S[0])
    rhs = ranges[1:] ** 2 - ranges[0] ** 2 - np.einsum("ij,ij->i", S[1:], S[1:]) + S[0] @ S[0]
    sol, _, rank, _ = np.linalg.lstsq(A, rhs, rcond=1e-12)
    if rank < S.shape[1] or not np.all(np.isfinite(sol)):
        return None
    return sol


def _extend_kd(F: np.ndarray, cal: Calibration, toa: bool) -> Calibration | None:
    """Add the transmitters, then the receivers, that a solver's block did not use (any dimension)."""
    m, n = F.shape
    ms, ns = cal.m, cal.n
    k = cal.receivers.shape[1]
    tra, off = np.empty((n, k)), np.zeros(n)
    tra[:ns], off[:ns] = cal.transmitters, cal.offsets
    for j in range(ns, n):
        got = _place_transmitter(cal.receivers, F[:ms, j], toa)
        if got is None:
            return None
        tra[j], off[j] = got
    rec = np.empty((m, k))
    rec[:ms] = cal.receivers
    for i in range(ms, m):
        got = _place_receiver(tra, F[i] - off)
        if got is None:
            return None
        rec[i] = got
    res = rms_residual(F, rec, tra, off)
    return Calibration(rec, tra, off, res) if np.isfinite(res) else None


#: A solve with one root per orbit of the gauge reflections (direct parametrization, 7r/5s, 6r/6s) is suspect when more
#: than this fraction of its endpoints lie on another endpoint or its image: on 100 room networks at most 12 of
#: 2321 did, except seed 12 (2142, the true network missed; with the receivers reordered 0, 3, 4, 1, 2, 5, 6:
#: 2, the true network found). solve_network then solves the reordered network too (:func:`_reordered`).
SUSPECT_FRACTION = 0.01


def _kd_candidates(F: np.ndarray, dim: int, model: str) -> tuple[list[Calibration], bool, bool]:
    """The committed solver's calibrations on its block of F (:func:`calibrations`), extended to every node,
    whether its root set was complete (every path ended on a finite root of its own; a root set with
    lost or coinciding endpoints may miss the true network) and whether it is suspect (one root per orbit
    tracked, and more than :data:`SUSPECT_FRACTION` of the endpoints on an image of another)."""
    from .continuation.tracking import unresolved

    choice = select_solver_kd(*F.shape, dim, model)
    module = importlib.import_module(choice.module)
    block = F[: choice.m, : choice.n]
    cands = []
    with np.errstate(all="ignore"):
        roots = module.solve(block)
        for cal in calibrations(module, block, roots):
            cal = _extend_kd(F, cal, model == "toa")
            if cal is not None:
                cands.append(cal)
    group = getattr(module.solver(), "group", None) if hasattr(module, "GROUP_ORDER") else None
    suspect = group is not None and unresolved(roots, group).mean() > SUSPECT_FRACTION
    return cands, len(roots) == getattr(module, "PATHS", module.DEGREE) and not unresolved(roots).any(), suspect


def _reordered(F: np.ndarray, dim: int, model: str) -> list[Calibration]:
    """The calibrations of F solved with its receivers 2, 3 and 4, 5 swapped (the gauge frame then rests on
    receivers 1, 4, 5), moved back into F's receiver order and gauge."""
    m = F.shape[0]
    order = np.array([0, 3, 4, 1, 2] + list(range(5, m)))
    back = np.argsort(order)
    out = []
    cands, _, _ = _kd_candidates(np.ascontiguousarray(F[order]), dim, model)
    for cal in cands:
        gauged = to_gauge(cal.receivers[back], cal.transmitters)
        if gauged is not None:
            res = rms_residual(F, gauged[0], gauged[1], cal.offsets)
            if np.isfinite(res):
                out.append(Calibration(gauged[0], gauged[1], cal.offsets, res))
    return out


def _transposed(F: np.ndarray, cal: Calibration) -> Calibration | None:
    """A calibration of the TOA network F.T as one of F (receivers and transmitters swap roles), in F's gauge."""
    gauged = to_gauge(cal.transmitters, cal.receivers)
    if gauged is None:
        return None
    rec, tra = gauged
    off = np.zeros(len(tra))
    res = rms_residual(F, rec, tra, off)
    return Calibration(rec, tra, off, res) if np.isfinite(res) else None


def _solver_rank(m: int, n: int, dim: int, model: str) -> int:
    """Position in :data:`KD_SOLVERS` (fastest first) of the solver an m x n network gets; len() when none fits."""
    try:
        label = select_solver_kd(m, n, dim, model).label
    except ValueError:
        return len(KD_SOLVERS.get((dim, model), ()))
    return KD_SOLVERS[(dim, model)].index(label)


def _transposed_candidates(F: np.ndarray, dim: int, model: str) -> tuple[list[Calibration], bool]:
    """The TOA network F.T's calibrations (:func:`_kd_candidates`) as F's (:func:`_transposed`), and whether
    that root set was complete; none when no committed solver fits the transposed shape."""
    try:
        more, complete, _ = _kd_candidates(np.ascontiguousarray(F.T), dim, model)
    except ValueError:
        return [], False
    with np.errstate(all="ignore"):
        return [c for c in (_transposed(F, cal) for cal in more) if c is not None], complete


def _same_networks_once(cands: list[Calibration], tol: float = 1e-5) -> list[Calibration]:
    """The candidates (same gauge, either mirror image) by residual, without those whose positions lie within
    tol (relative to the network's spread) of a better one: one network reached by both orientations, where
    the ill-conditioned orientation's copy is less accurate (relative position errors up to 5e-7 measured)
    than :func:`_dedupe` tolerates."""
    out: list[Calibration] = []
    for c in sorted(cands, key=lambda c: c.residual):
        X = np.vstack([c.receivers, c.transmitters])
        spread = np.linalg.norm(X - X.mean(axis=0))
        mirror = np.ones(X.shape[1])
        mirror[-1] = -1.0
        if not any(min(np.linalg.norm(X - Y), np.linalg.norm(X * mirror - Y)) <= tol * spread
                   for Y in (np.vstack([d.receivers, d.transmitters]) for d in out)):
            out.append(c)
    return out


def _solve_network_kd(F: np.ndarray, dim: int, model: str, refine: bool, max_refined: int) -> list[Calibration]:
    """:func:`solve_network` for 3D and for TOA: the committed solver's calibrations on its block
    (:func:`_kd_candidates`), extended to every node, TDOA refined on all measurements.

    TOA is symmetric under swapping receivers and transmitters (F -> F.T). The orientation whose solver comes
    first in :data:`KD_SOLVERS` (the faster: 6 x 4 data goes to the 4r/6s Gram solver as F.T) is solved first;
    where its root set is incomplete or yields no calibration, the other orientation is solved too and the
    candidates of both are pooled. The compaction unknown H = (4 S^T S)^{-1} is built on the first K + 1 transmitters; where
    they are close to coplanar, H is large (eigenvalues 1e3-9e4 m^-2 on room networks) and paths are lost,
    while the transposed problem's frame (the first receivers) is usually well conditioned
    (docs/minimal-3d.md, section 2)."""
    m, n = F.shape
    toa = model == "toa"
    if toa and _solver_rank(n, m, dim, model) < _solver_rank(m, n, dim, model):
        # the transposed shape has a faster solver (6 x 4 data: the 4r/6s Gram solver): solved first
        cands, complete = _transposed_candidates(F, dim, model)
        if not (complete and cands):
            more, _, _ = _kd_candidates(F, dim, model)
            with np.errstate(all="ignore"):
                cands = _same_networks_once(cands + more)
    else:
        cands, complete, suspect = _kd_candidates(F, dim, model)
        if suspect and m >= 5:  # one root per orbit, and many paths met on one orbit (docs/minimal-3d.md, section 5)
            with np.errstate(all="ignore"):
                cands = _same_networks_once(cands + _reordered(F, dim, model))
        if toa and not (complete and cands):
            with np.errstate(all="ignore"):
                cands = _same_networks_once(cands + _transposed_candidates(F, dim, model)[0])
    cands.sort(key=lambda c: c.residual)
    # solvers.refine estimates offsets: TDOA candidates only
    return _finish(F, cands, refine and not toa, max_refined, minimal_configuration(m, n, dim, model),
                   f"{dim}D {model.upper()} {m}r/{n}s", stacklevel=4)


def _finish(F: np.ndarray, cands: list[Calibration], refine: bool, max_refined: int, minimal: bool, what: str,
            stacklevel: int) -> list[Calibration]:
    """Refine the best candidates (all of them for minimal data) on all measurements, drop repeats and, for
    minimal data, keep the exact fits (warning when several fit: the data cannot tell them apart)."""
    if refine:
        refined = []
        for cal in cands[: len(cands) if minimal else max_refined]:
            try:
                out = _refine(cal, F).calibration
            except ValueError:
                continue
            if np.isfinite(out.residual) and np.all(np.isfinite(out.receivers)) and np.all(np.isfinite(out.transmitters)):
                refined.append(out)
        cands = sorted(refined, key=lambda c: c.residual)
    out = _dedupe(cands)
    if minimal:
        scale = np.sqrt(np.mean(F * F))
        out = [c for c in out if c.residual <= 1e-6 * scale]
        if len(out) > 1:
            warnings.warn(f"minimal data ({what}): {len(out)} real solutions fit the "
                          "measurements exactly; the data cannot tell them apart", stacklevel=stacklevel)
    return out


def solve_network(F, refine: bool = True, max_refined: int = 5, *, dim: int = 2,
                  model: str = "tdoa") -> list[Calibration]:
    """Candidate calibrations of a network from complete, clean TDOA measurements F[i, j] = |r_i - s_j| + o_j.

    The paper's pipeline; for measured data (gaps, gross errors, a status) use :func:`solvers.calibrate`.

    Parameters
    ----------
    F: (m, n) finite array containing at least one solved configuration (6r/3s, 6r/4s, 7r/3s, ...).
    refine: run Levenberg-Marquardt on all m*n measurements from each recovered candidate.
    max_refined: refine only this many candidates (the smallest residuals after recovery); for a
        minimal network (6r/3s) every real solution is refined and returned.

    Returns the calibrations (gauge r_1 = 0, r_2 = (r_2x, 0)) sorted by RMS residual, best first;
    an empty list when no candidate is real and geometrically valid (e.g. collinear receivers).
    For minimal data all real solutions fit exactly and a warning says that the data cannot tell
    them apart.
    dim, model: 2 or 3; ``"tdoa"`` (unknown transmitter offsets) or ``"toa"`` (synchronised, F[i, j] =
        |r_i - s_j|). Other than 2D TDOA, the committed solvers of :data:`KD_SOLVERS` run on the first
        receivers and transmitters (3D TOA: 4r/6s, 6r/4s, 5r/5s; 2D TOA: 3r/3s; 3D TDOA: 9r/5s, 7r/5s, 6r/6s), every
        real candidate with H positive definite becomes a calibration (:func:`calibrations`), the other
        transmitters and then receivers are placed by linear least squares, and TDOA candidates are
        refined (TOA ones are not: solvers.refine frees the offsets). TOA: where the solver's root set is
        incomplete (a lost path, two paths on one root) or gives no calibration, the transposed network F.T
        (receivers and transmitters swapped) is solved too and the candidates pooled. 3D TDOA 7r/5s and 6r/6s
        (one root per orbit of the gauge reflections): a suspect root set (:data:`SUSPECT_FRACTION`) is solved again with
        receivers 2, 3 and 4, 5 swapped and the candidates pooled. 3D gauge: r_1 = 0, r_2 on +x,
        r_3 in the xy half-plane y > 0; the mirror image z -> -z fits the data equally and is not
        returned (one representative per network).

    Raises ValueError for malformed input (wrong shape, NaN/inf, too few nodes, unknown dim or model).
    Paper Section 3.1 (steps 1-4) and 3.2 (trilateration of the remaining transmitters).
    """
    _check_kind(dim, model)
    if (dim, model) != (2, "tdoa"):
        arr = np.asarray(F, dtype=float)
        if arr.ndim != 2 or not np.all(np.isfinite(arr)):
            raise ValueError(f"F must be a finite 2-D (receivers x transmitters) array, got shape {arr.shape}")
        return _solve_network_kd(arr, dim, model, refine, max_refined)
    F = _validate(F)
    choice = select_solver(*F.shape)
    roots = solve_roots(F)
    cands: list[Calibration] = []
    ns = choice.n
    with np.errstate(all="ignore"):
        for x in roots:
            if choice.label in POSITIONS:
                cal = _from_positions(F, choice, x)
            else:
                cal = recover(F[:, :ns], x[:3], x[3:5], x[5 : 5 + ns])
            if cal is None:
                continue
            cal = _extend(F, cal, ns)
            if cal is not None:
                cands.append(cal)
    cands.sort(key=lambda c: c.residual)
    return _finish(F, cands, refine, max_refined, minimal_configuration(*F.shape), f"{F.shape[0]}r/{F.shape[1]}s",
                   stacklevel=3)


def _dedupe(cands: list[Calibration], tol: float = 1e-8) -> list[Calibration]:
    """Drop calibrations that repeat an earlier one (same offsets and receiver layout)."""
    out: list[Calibration] = []
    for c in cands:
        key = np.concatenate([c.offsets, np.abs(c.receivers).ravel()])
        if any(np.allclose(key, np.concatenate([d.offsets, np.abs(d.receivers).ravel()]), rtol=tol, atol=tol * (1 + np.abs(key).max()))
               for d in out):
            continue
        out.append(c)
    return out
