"""Batched placement of single nodes: multilateration of receivers and transmitters (with offsets)
against placed partners, and the extension of a block hypothesis to the whole network."""
from __future__ import annotations

import numpy as np

from .scoring import MAD_TO_SIGMA, _classify, _residual_matrix


def _solve_batched(A: np.ndarray, b: np.ndarray, rcond: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """Solve the small systems A[k] x = b[k]; returns (x, solved) with NaN rows where A[k] is not
    finite or nearly singular (|det A| below rcond times the product of its row norms)."""
    k = A.shape[-1]
    x = np.full(b.shape, np.nan)
    finite = np.isfinite(A).all(axis=(1, 2)) & np.isfinite(b).all(axis=1)
    A_ok = np.where(finite[:, None, None], A, np.eye(k))
    hadamard = np.prod(np.linalg.norm(A_ok, axis=2), axis=1)
    good = finite & (np.abs(np.linalg.det(A_ok)) > rcond * hadamard)
    if good.any():
        x[good] = np.linalg.solve(A_ok[good], b[good][..., None])[:, :, 0]
    return x, good


def _linear_system(g: np.ndarray, P: np.ndarray, with_offset: bool) -> tuple[np.ndarray, np.ndarray]:
    """Rows of the linearised multilateration |p - P_k|^2 = (g_k - q)^2 in (p, [q,] |p|^2 - q^2).

    -2 P_k.p [+ 2 g_k q] + t = g_k^2 - |P_k|^2; g (..., K), P (..., K, dim) -> A (..., K, dim + 1|2), rhs (..., K).
    """
    cols = [-2.0 * P] + ([2.0 * g[..., None]] if with_offset else []) + [np.ones(g.shape + (1,))]
    return np.concatenate(cols, axis=-1), g * g - np.einsum("...k,...k->...", P, P)


def _node_residuals(X: np.ndarray, G: np.ndarray, P: np.ndarray, with_offset: bool):
    """e_k = g_k - q - |p - P_k| for nodes X (..., dim [+ 1 offset]) against partners P (K, dim); also
    p - P and |p - P|."""
    d = P.shape[-1]
    diff = X[..., None, :d] - P
    dist = np.sqrt(np.einsum("...k,...k->...", diff, diff))
    q = X[..., d : d + 1] if with_offset else 0.0
    return G - q - dist, diff, dist


def _multilaterate(G, P, with_offset, X, c, rng, trials=24, steps=3):
    """Robust batched multilateration of nodes (rows of G) against placed partners P.

    Each node solves g_k - q = |p - P_k| over its measured partners k (G finite): position p (dim)
    and, for a transmitter, its offset q. Nodes without an estimate (NaN rows of X) start from the
    best of the all-partner linear solution and `trials` linear solutions of random minimal subsets
    (dim + 1 partners for a receiver, dim + 2 for a transmitter), scored by the median e^2 (LMedS);
    then `steps` Cauchy-IRLS Gauss-Newton steps. Nodes with too few partners keep their value.
    """
    N, K = G.shape
    d = P.shape[-1]
    need = d + 2 if with_offset else d + 1
    use = np.isfinite(G)
    able = use.sum(axis=1) >= need
    X = X.copy()
    start = np.flatnonzero(able & ~np.isfinite(X[:, 0]))
    if start.size:
        Gs, us = G[start], use[start]
        # A transmitter's offset only shifts its row: where it dwarfs the partners' extent (offsets of
        # seconds x the speed of sound beside distances of a few metres: rooms from audio), solve for
        # q - g_ref, g_ref its first measured entry; the minimal subsets look singular otherwise (3D).
        # Elsewhere the system is left as it was.
        ref = np.zeros(len(start))
        if with_offset:
            first = Gs[np.arange(len(start)), np.argmax(us, axis=1)]
            extent = float(np.max(np.linalg.norm(P - P.mean(axis=0), axis=1)))
            ref = np.where(np.abs(first) > 10.0 * extent, first, 0.0)
        Gs = Gs - ref[:, None]
        A, rhs = _linear_system(np.where(us, Gs, 0.0), np.broadcast_to(P, (len(start), K, d)), with_offset)
        w = us.astype(float)
        full, _ = _solve_batched(np.einsum("nk,nki,nkj->nij", w, A, A), np.einsum("nk,nki,nk->ni", w, A, rhs))
        keys = rng.random((trials, len(start), K))
        keys[:, ~us] = np.inf
        idx = np.argsort(keys, axis=2)[:, :, :need]  # (T, n, need)
        rows = np.arange(len(start))[None, :, None]
        sub, _ = _solve_batched(A[rows, idx].reshape(-1, need, need), rhs[rows, idx].reshape(-1, need))
        cand = np.concatenate([full[None], sub.reshape(trials, len(start), need)])[..., : need - 1]
        e, _, _ = _node_residuals(cand, Gs, P, with_offset)
        # LMedS over the node's partners: needs no noise level and tolerates up to half outliers.
        e2 = np.sort(np.where(us, np.nan_to_num(e, nan=np.inf) ** 2, np.inf), axis=2)
        cost = e2[:, np.arange(len(start)), (us.sum(axis=1) - 1) // 2]
        cost[~np.isfinite(cand).all(axis=2)] = np.inf
        pick = np.argmin(cost, axis=0)
        X[start] = cand[pick, np.arange(len(start))]
        if with_offset:
            X[start, d] += ref
    active = np.flatnonzero(able & np.isfinite(X[:, 0]))
    ua = use[active]
    G0 = np.where(ua, G[active], 0.0)
    rows = np.arange(len(active))
    median_index = (ua.sum(axis=1) - 1) // 2
    for _ in range(steps):
        e, diff, dist = _node_residuals(X[active], G0, P, with_offset)
        e = np.where(ua, e, 0.0)
        # Per-node scale max(c, 3 x 1.4826 x median |e|): a badly started node is not frozen by c.
        med = np.sort(np.where(ua, np.abs(e), np.inf), axis=1)[rows, median_index]
        scale = np.maximum(c, 3.0 * MAD_TO_SIGMA * np.where(np.isfinite(med), med, 0.0))
        w = ua / (1.0 + (e / scale[:, None]) ** 2)  # Cauchy weights, 0 for unmeasured partners
        u = diff / np.maximum(dist, 1e-300)[..., None]
        J = np.concatenate([-u, -np.ones(dist.shape + (1,))], axis=2) if with_offset else -u
        step, good = _solve_batched(np.einsum("nk,nki,nkj->nij", w, J, J), -np.einsum("nk,nki,nk->ni", w, J, e))
        X[active[good]] += step[good]
    return X


def _place(F, mask, R, S, O, c, rng, receivers: bool, fresh=None, refine_all=True, trials=24):
    """Place receivers (receivers=True) or transmitters from their measured placed partners.

    fresh: bool mask of nodes placed from scratch (their current value is dropped); unplaced nodes
    are always placed from scratch. refine_all: IRLS steps on every node, not only the new ones.
    """
    if receivers:
        placed = np.isfinite(S[:, 0])
        G = np.where(mask & placed[None, :], F - O[None, :], np.nan)[:, placed]
        X = R.copy()
        P = S[placed]
    else:
        placed = np.isfinite(R[:, 0])
        G = np.where(mask & placed[:, None], F, np.nan)[placed].T
        X = np.column_stack([S, O])
        P = R[placed]
    if fresh is not None:
        X[fresh] = np.nan
    new = ~np.isfinite(X[:, 0])
    if refine_all:
        X = _multilaterate(G, P, not receivers, X, c, rng, trials)
    elif new.any():
        X[new] = _multilaterate(G[new], P, not receivers, X[new], c, rng, trials)
    if receivers:
        return X, S, O
    d = R.shape[1]
    return R, X[:, :d].copy(), X[:, d].copy()


def _extend(F, mask, R, S, O, c, rng, sample_r, best_ratio=None, trials=10):
    """Extend a hypothesis on a sample block (sample_r placed with its transmitters) to the network.

    Receivers from the sample transmitters, transmitters from all receivers, receivers afresh from
    all transmitters (the sample's only refined), then IRLS on all transmitters. Early exit (the
    T(d,d) idea of randomised RANSAC): after the first two passes, a hypothesis explaining fewer than
    half as many measurements as the best one so far is returned partially placed (and scores badly).
    `trials` minimal subsets per node: 10 leave a node with 10 % bad partners misplaced with
    probability ~3e-5 (4-subsets; LMedS picks the clean one).
    """
    R = _place(F, mask, R, S, O, c, rng, True, refine_all=False, trials=trials)[0]
    S, O = _place(F, mask, R, S, O, c, rng, False, refine_all=False, trials=trials)[1:]
    if best_ratio is not None and np.mean(_classify(_residual_matrix(F, R, S, O), mask, c)[mask]) < 0.5 * best_ratio:
        return R, S, O
    R = _place(F, mask, R, S, O, c, rng, True, fresh=~sample_r, trials=trials)[0]
    S, O = _place(F, mask, R, S, O, c, rng, False, trials=trials)[1:]
    return R, S, O


def _fill(F, mask, R, S, O, c, rng):
    """Place the nodes that are still unplaced (NaN), receivers first; placed nodes are kept."""
    R = _place(F, mask, R, S, O, c, rng, True, refine_all=False)[0]
    return (R,) + _place(F, mask, R, S, O, c, rng, False, refine_all=False)[1:]

