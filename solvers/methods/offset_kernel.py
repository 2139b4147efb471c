"""Offset kernel (3D TDOA, one solution): offline build of its spec and online kernel side by side.

Formulation A, B2, B3, B4, C2-Cm and the 4 x 4 minors of the compaction matrix of m >= 9 receivers and
five transmitters in 3D (``9r5s-tdoa3d:A,B2,B3,B4,C2-C9,minors(70)``, one solution up to rotation,
reflection and translation: tables/table3d.*). The construction of :mod:`solvers.methods.pencil`, one
dimension up and without its curve: D~ = c + alpha o_1 + beta o_{j+1} has rank 3, so a vector v != 0
with D~ v = 0 exists; written in z = (v, o_1 sum(v), o_2 v_1, ..., o_5 v_4) that is the linear system
[c | alpha | beta] z = 0 of m - 1 >= 8 rows in 9 unknowns, whose kernel is one-dimensional and gives the
offsets as ratios. With the offsets known, C2-Cm are linear in (H, b): their solutions are a line,
homogeneous coordinates (h, b, kappa) = N (lambda, mu). On it A (quartic after homogenising) and B2-B4
(cubic; multiplied by lambda and mu) are binary quartics with one common root; it is the kernel of their
7 x 5 coefficient matrix, refined by Gauss-Newton in the angle of (lambda, mu).

Offline (:func:`build`): the root count certified over GF(p) (two primes, two seeds, det H saturated,
known root checked: :func:`analysis.sweeps.cell_degrees.cell_degree`) must be 1, then the kernel must find
the known root on seeded room-sized networks. Online (:class:`OffsetKernelSolver`): SVDs of small
matrices, batched over a leading axis; numpy only. Generated modules reach it through the functions
below; this module imports nothing of :mod:`solvers.runtime` or :mod:`solvers.generate`.
"""
from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from .pencil import compaction_pieces

if TYPE_CHECKING:  # the online kernel needs neither sympy nor the exact algebra
    from analysis.formulations.tdoa import Formulation

    from .spec import TemplateOptions, TemplateResult

__all__ = ["ANGLE_STEPS", "OffsetKernelSolver", "build", "offset_kernel_formulation", "solve_scaled"]

#: Gauss-Newton steps in the angle of (lambda, mu) after the kernel of the quartics' coefficient matrix
#: (that kernel alone loses up to 1e-5 on networks whose quartics nearly share a second root).
ANGLE_STEPS = 4
#: Upper-triangle order of H's unknowns (h11, h12, h13, h22, h23, h33).
_IU = np.triu_indices(3)
#: Five projective sample points of (lambda, mu) and the quartic monomials there: binary quartics are
#: interpolated from their values (unit vectors, so the 5 x 5 system is well conditioned).
_ANGLES = np.arange(5) * np.pi / 5
_LM = np.stack([np.cos(_ANGLES), np.sin(_ANGLES)], axis=1)
_POWERS = np.arange(5)
_QUARTIC_AT_SAMPLES = _LM[:, :1] ** (4 - _POWERS) * _LM[:, 1:] ** _POWERS


def offset_kernel_formulation(m: int) -> str:
    """The formulation an m-receiver five-transmitter offset-kernel solver solves (m >= 9)."""
    return f"{m}r5s-tdoa3d:A,B2,B3,B4,C2-C{m},minors({_minors(m)})"


def _minors(m: int) -> int:
    from math import comb

    return comb(m - 1, 4)


# --------------------------------------------------------------------------------------------------
# offline: certified count and check on seeded networks
# --------------------------------------------------------------------------------------------------


def _room_trials(m: int, trials: int) -> tuple[np.ndarray, np.ndarray]:
    """Seeded noiseless room networks (seeds 0..trials-1): data and the root (h, b, o)."""
    from ..synthetic import room_network, true_root

    F, X = [], []
    for seed in range(trials):
        net = room_network(m, 5, np.random.default_rng(seed))
        H, b, o = true_root(net)
        F.append(net.measurements())
        X.append(np.concatenate([H[_IU], b, o]))
    return np.array(F), np.array(X)


def build(formulation: Formulation | str, options: TemplateOptions | None = None) -> TemplateResult:
    """Spec of the offset-kernel solver (:class:`OffsetKernelSolver`).

    Checks: the formulation is the one of :func:`offset_kernel_formulation`; its count with det H != 0
    is 1 on two primes for each of the seeds 0 and 1 (the known root vanishing on each Gröbner basis);
    on ``options.verify_trials`` seeded room networks the kernel finds the known root (relative error
    below 1e-6) in all but at most 10 %. Raises :class:`~solvers.methods.spec.TemplateError` otherwise.
    """
    from analysis.sweeps.cell_degrees import cell_degree
    from analysis.engine.degree import DEFAULT_PRIMES
    from analysis.formulations.tdoa import as_formulation

    from .spec import TemplateError, TemplateOptions, TemplateResult, solver_method, spec_header

    t0 = time.perf_counter()
    options = options or TemplateOptions()
    formulation = as_formulation(formulation)
    if solver_method(formulation) != "offset-kernel":
        raise TemplateError(f"{formulation.label}: the offset kernel needs a 3D TDOA cell mr/5s (m >= 9) with "
                            "A, B2-B4, C2-Cm and all 4 x 4 minors")
    seeds = (0, 1)
    for seed in seeds:
        record = cell_degree(formulation, primes=DEFAULT_PRIMES, seed=seed)
        if record.status != "ok" or record.degree != 1:
            raise TemplateError(f"{formulation.label} (seed {seed}): {record.status}, degree {record.degree} over "
                                f"GF(p) for p in {record.primes}; the offset kernel needs exactly one solution")
    config = formulation.config
    spec = spec_header(formulation, options, "offset-kernel", 1)
    spec["certified"] = {"primes": list(DEFAULT_PRIMES), "seeds": list(seeds), "degree": 1, "saturated_by": ["det H"]}
    spec["config"] = [config.m, config.n]
    spec["dim"] = config.dim
    spec["size"] = [config.m - 1, 9]
    spec["kernel"] = {"lifted": [config.m - 1, 9], "c_line": [config.m - 1, 10], "quartics": [7, 5],
                      "angle_steps": ANGLE_STEPS}
    F, X = _room_trials(config.m, options.verify_trials)
    roots = OffsetKernelSolver(spec).solve(F)[:, 0]
    err = np.linalg.norm(roots - X, axis=1) / np.linalg.norm(X, axis=1)
    found = int(np.sum(err < 1e-6))
    if found < 0.9 * len(F):
        raise TemplateError(f"the offset kernel finds the known root in only {found}/{len(F)} seeded room networks")
    return TemplateResult(spec, time.perf_counter() - t0, ({"method": "offset-kernel", "degree": 1,
                                                            "verified": found, "trials": len(F)},))


# --------------------------------------------------------------------------------------------------
# online
# --------------------------------------------------------------------------------------------------


def _symmetric(h: np.ndarray) -> np.ndarray:
    """(..., 6) upper triangles -> (..., 3, 3) symmetric matrices."""
    H = np.empty(h.shape[:-1] + (3, 3), dtype=h.dtype)
    H[..., _IU[0], _IU[1]] = h
    H[..., _IU[1], _IU[0]] = h
    return H


def _adjugate(H: np.ndarray) -> np.ndarray:
    """Adjugate of (..., 3, 3) matrices: cross products of the columns."""
    a, b, c = H[..., :, 0], H[..., :, 1], H[..., :, 2]
    return np.stack([np.cross(b, c), np.cross(c, a), np.cross(a, b)], axis=-2)


def _smallest_right_singular(M: np.ndarray, k: int = 1) -> np.ndarray:
    """The k right singular vectors of the smallest singular values of (..., r, c), r < c allowed: (..., c, k)."""
    _, _, vt = np.linalg.svd(M, full_matrices=True)
    return np.swapaxes(vt[..., -k:, :], -1, -2)


class OffsetKernelSolver:
    """The online kernel of a spec of kind ``offset-kernel`` (module docstring)."""

    def __init__(self, spec: dict):
        if spec.get("kind") != "offset-kernel":
            raise ValueError(f"not an offset-kernel spec: kind {spec.get('kind')!r}")
        self.m, self.n = spec["config"]
        self.nvars = len(spec["unknowns"])
        self.angle_steps = int(spec["kernel"]["angle_steps"])

    def offsets(self, F: np.ndarray) -> np.ndarray:
        """Offsets (batch, 5) from the kernel of [c | alpha | beta] (batch, m-1, 9)."""
        c, alpha, beta, _ = compaction_pieces(F)
        z = _smallest_right_singular(np.concatenate([c, alpha[..., None], beta], axis=-1))[..., 0]
        v = z[..., :4]
        return np.concatenate([z[..., 4:5] / np.sum(v, axis=-1, keepdims=True), z[..., 5:] / v], axis=-1)

    def line(self, F: np.ndarray, o: np.ndarray) -> np.ndarray:
        """Kernel basis N (batch, 10, 2) of C2-Cm in homogeneous (h11..h33, b1..b3, kappa)."""
        d2 = (F - o[..., None, :]) ** 2
        D = d2[..., 1:, 1:4] - d2[..., :1, 1:4] - d2[..., 1:, :1] + d2[..., :1, :1]  # D~[:, :3]: rows r_i
        r0, r1, r2 = D[..., 0], D[..., 1], D[..., 2]
        quad = np.stack([r0 * r0, 2 * r0 * r1, 2 * r0 * r2, r1 * r1, 2 * r1 * r2, r2 * r2], axis=-1)
        rhs = d2[..., 1:, 0] - d2[..., :1, 0]
        C = np.concatenate([quad, -2.0 * D, -rhs[..., None]], axis=-1)
        C = C / np.linalg.norm(C, axis=-1, keepdims=True)
        return _smallest_right_singular(C, 2)

    def quartics(self, F: np.ndarray, o: np.ndarray, N: np.ndarray) -> np.ndarray:
        """Coefficients (batch, 7, 5) in lambda^4, lambda^3 mu, ..., mu^4 of A and lambda B_j, mu B_j (j = 2..4)
        on the line, rows scaled to unit norm."""
        d2 = (F[..., 0, :] - o) ** 2  # receiver 1
        x = np.einsum("...vk,sk->...sv", N, _LM)  # (batch, 5 samples, 10)
        H, b, kappa = _symmetric(x[..., :6]), x[..., 6:9], x[..., 9]
        det, adj = np.linalg.det(H), _adjugate(H)
        values = [d2[..., :1] * det * kappa - np.einsum("...i,...ij,...j->...", b, adj, b)]
        for j in range(1, 4):
            bj = ((d2[..., j:j + 1] - d2[..., :1]) * det - 0.25 * adj[..., j - 1, j - 1] * kappa
                  + np.einsum("...i,...i->...", b, adj[..., :, j - 1]))
            values += [bj * _LM[:, 0], bj * _LM[:, 1]]
        P = np.linalg.solve(_QUARTIC_AT_SAMPLES, np.stack(values, axis=-1))  # (batch, 5 coefficients, 7)
        P = np.swapaxes(P, -1, -2)
        return P / np.linalg.norm(P, axis=-1, keepdims=True)

    def common_root(self, P: np.ndarray) -> np.ndarray:
        """(lambda, mu) (batch, 2) of unit length: the kernel of P, then Gauss-Newton in the angle."""
        w = _smallest_right_singular(P)[..., 0]  # ~ (lambda^4, lambda^3 mu, ..., mu^4)
        k = np.argmax(np.abs(w[..., :-1]) + np.abs(w[..., 1:]), axis=-1)
        pair = np.take_along_axis(w, np.stack([k, k + 1], axis=-1), axis=-1)
        theta = np.arctan2(pair[..., 1], pair[..., 0])
        for _ in range(self.angle_steps):
            cs, sn = np.cos(theta)[..., None], np.sin(theta)[..., None]
            mono = cs ** (4 - _POWERS) * sn ** _POWERS
            # d/dtheta cos^(4-k) sin^k = -(4-k) cos^(3-k) sin^(k+1) + k cos^(5-k) sin^(k-1)
            dmono = (-(4 - _POWERS) * cs ** np.maximum(3 - _POWERS, 0) * sn ** (_POWERS + 1)
                     + _POWERS * cs ** (5 - _POWERS) * sn ** np.maximum(_POWERS - 1, 0))
            r = np.einsum("...ek,...k->...e", P, mono)
            J = np.einsum("...ek,...k->...e", P, dmono)
            theta = theta - np.sum(J * r, axis=-1) / np.sum(J * J, axis=-1)
        return np.stack([np.cos(theta), np.sin(theta)], axis=-1)

    def solve(self, F: np.ndarray) -> np.ndarray:
        """Roots (batch, 1, 14) of normalised data F (batch, m, 5): (h11, ..., h33, b1, b2, b3, o1, ..., o5)."""
        o = self.offsets(F)
        N = self.line(F, o)
        lm = self.common_root(self.quartics(F, o, N))
        x = np.einsum("...vk,...k->...v", N, lm)
        hb = x[..., :9] / x[..., 9:]
        return np.concatenate([hb, o], axis=-1)[..., None, :]


def solve_scaled(solver: OffsetKernelSolver, F, scale_powers) -> np.ndarray:
    """Roots (..., 1, 14) of data F (..., m, 5) at its own scale: solved on F / RMS(F), mapped back."""
    F = np.asarray(F, dtype=float)
    if F.shape[-2:] != (solver.m, solver.n):
        raise ValueError(f"data must have shape (..., {solver.m}, {solver.n}), got {F.shape}")
    if not np.all(np.isfinite(F)):
        raise ValueError("data contain NaN or infinite values")
    lead = F.shape[:-2]
    flat = F.reshape((-1, solver.m, solver.n))
    s = np.sqrt(np.mean(flat * flat, axis=(-2, -1)))
    if np.any(s == 0):
        raise ValueError("data are all zero")
    with np.errstate(all="ignore"):
        roots = solver.solve(flat / s[:, None, None]) * s[:, None, None] ** np.asarray(scale_powers)
    return roots.reshape(lead + roots.shape[-2:]).astype(complex)
