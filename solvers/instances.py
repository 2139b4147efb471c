"""Start pairs and trial instances of the TDOA/TOA formulations: complex networks with their known root (the
start of every parameter homotopy and monodromy graph of :mod:`solvers.generate` and :mod:`solvers.count`),
the gauge frame's reflections (the group the direct parametrization's roots come in), and seeded real
networks for the numerical checks.
"""
from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from analysis.formulations.kd import gram_root

__all__ = ["complex_instance", "gauge_reflections", "positions_start", "positions_trials", "tdoa_start", "tdoa_trials"]


def complex_instance(m: int, n: int, rng: np.random.Generator, dim: int = 2, model: str = "tdoa",
                     parametrization: str = "compaction", positions: str = "complex") -> tuple[np.ndarray, np.ndarray]:
    """A complex network's data F (m, n), normalised by its RMS modulus, and its compaction root in that frame
    (``parametrization="direct"``: the network is first put in the gauge frame, r_1 = 0, r_2 on the x-axis,
    r_3 in the xy-plane, by zeroing those coordinates, and the root is the direct unknowns: the receivers'
    free coordinates, the transmitters, the offsets).

    Receivers, transmitters and (TDOA) offsets are complex normal, in ``dim`` dimensions (drawn in this
    order; TOA draws no offsets); with ``positions="imaginary"`` (:data:`START_POSITIONS`) the receivers and
    transmitters are i times real normal (their squared distances negative reals), the offsets complex normal as
    before. d_ij is a square root of the (complex) squared distance (the equations use only d_ij^2). The root
    is (H, b, o) (TOA: (H, b)), H's upper triangle row by row, with H = (4 S^T S)^-1,
    S = [s_2 - s_1, ..., s_{K+1} - s_1], b = -1/2 S^-1 s_1 (r_1 translated to 0; transposes, not conjugates), as in
    solvers.synthetic and analysis.formulations.kd.
    """
    if positions not in ("complex", "imaginary"):
        raise ValueError(f"positions: 'complex' or 'imaginary', not {positions!r}")
    if positions == "imaginary":
        r, t = 1j * rng.normal(size=(m, dim)), 1j * rng.normal(size=(n, dim))
    else:
        r = rng.normal(size=(m, dim)) + 1j * rng.normal(size=(m, dim))
        t = rng.normal(size=(n, dim)) + 1j * rng.normal(size=(n, dim))
    o = rng.normal(size=n) + 1j * rng.normal(size=n) if model == "tdoa" else np.zeros(0)
    if parametrization == "direct":
        for i in range(min(dim, m)):
            r[i, i:] = 0.0
    F = np.sqrt(((r[:, None, :] - t[None, :, :]) ** 2).sum(axis=-1)) + (o[None, :] if len(o) else 0.0)
    scale = np.sqrt(np.mean(np.abs(F) ** 2))
    if parametrization == "direct":
        x = [r[i, a] for i in range(1, m) for a in range(min(i, dim))] + list(t.ravel()) + list(o)
        return F / scale, np.array(x) / scale
    if parametrization == "gram":
        x = gram_root(r, dim)
        return F / scale, x / scale ** np.where(np.arange(len(x)) < dim * (dim + 1) // 2, 2.0, 0.0)
    s1 = t[0] - r[0]
    S = np.column_stack([t[c + 1] - t[0] for c in range(dim)])
    H = np.linalg.inv(4.0 * S.T @ S)
    b = -0.5 * np.linalg.solve(S, s1)
    upper = [H[a, c] for a in range(dim) for c in range(a, dim)]
    x = np.concatenate([upper, b, o])
    powers = np.array([-2.0] * len(upper) + [0.0] * dim + [1.0] * len(o))
    return F / scale, x / scale**powers


def gauge_reflections(unknowns: Sequence[str]) -> np.ndarray:
    """The sign vectors (2^dim, N) of the gauge frame's reflections (each axis x, y (, z) -> minus itself) on
    the direct parametrization's unknowns (receivers' and transmitters' coordinates; offsets fixed): the
    group whose orbits the direct roots come in (TDOAConfig.gauge_group_order elements)."""
    axes = sorted({u[-1] for u in unknowns if u[0] in "rs"})
    out = []
    for flips in np.ndindex(*(2,) * len(axes)):
        sign = {axis: -1.0 if f else 1.0 for axis, f in zip(axes, flips)}
        out.append([sign[u[-1]] if u[0] in "rs" else 1.0 for u in unknowns])
    return np.array(out)


def tdoa_start(m: int, n: int, dim: int = 2, model: str = "tdoa", parametrization: str = "compaction",
                positions: str = "complex") -> Callable[[np.random.Generator], tuple[np.ndarray, np.ndarray]]:
    def start(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        F, x = complex_instance(m, n, rng, dim, model, parametrization, positions)
        return F.ravel(), x

    return start


def positions_start(m: int, n: int, variant: str) -> Callable[[np.random.Generator], tuple[np.ndarray, np.ndarray]]:
    """Complex networks in the gauge of analysis.formulations.positions, normalised by the RMS modulus of F."""
    from analysis.formulations.positions import _root_from_network, _to_gauge, positions_system

    ps = positions_system(m, n, variant)

    def start(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        r = rng.normal(size=(m, 2)) + 1j * rng.normal(size=(m, 2))
        t = rng.normal(size=(n, 2)) + 1j * rng.normal(size=(n, 2))
        o = rng.normal(size=n) + 1j * rng.normal(size=n)
        rec, tra = _to_gauge(r, t)
        F = np.sqrt(((rec[:, None, :] - tra[None, :, :]) ** 2).sum(axis=-1)) + o[None, :]
        s = np.sqrt(np.mean(np.abs(F) ** 2))
        rec, tra, o = rec / s, tra / s, o / s
        return (F / s).ravel(), np.array(_root_from_network(ps, rec, tra, o), dtype=complex)

    return start


def positions_trials(m: int, n: int, variant: str, powers) -> Callable[[int], tuple[np.ndarray, np.ndarray]]:
    from analysis.formulations.positions import sample_real_positions

    def trial(seed: int) -> tuple[np.ndarray, np.ndarray]:
        F, root = sample_real_positions(m, n, 10_000 + seed, variant)
        s = np.sqrt(np.mean(F * F))
        return (F / s).ravel(), root / s ** np.array(powers)

    return trial


def tdoa_trials(label: str, powers: tuple[float, ...]) -> Callable[[int], tuple[np.ndarray, np.ndarray]]:
    from analysis.formulations.tdoa import sample_real_instance

    def trial(seed: int) -> tuple[np.ndarray, np.ndarray]:
        inst = sample_real_instance(label, 10_000 + seed)
        F = np.array(inst.F)
        s = np.sqrt(np.mean(F * F))
        return (F / s).ravel(), np.array(inst.root) / s ** np.array(powers)

    return trial
