"""Flags: what the data cannot decide (collinear or coplanar nodes, mirror positions, alternative hypotheses)."""
from __future__ import annotations

import math

import numpy as np

from .adjustment import n_unknowns, robust_refine
from .placement import _node_residuals
from .scoring import _Model, _residual_matrix


# --------------------------------------------------------------------------------------------------
# Final refinement, classification, flags
# --------------------------------------------------------------------------------------------------


def _principal_ratio(P: np.ndarray) -> float:
    """Smallest / largest principal spread of a point set: 0 when the points lie on a line (2D) or in a
    plane (3D), the hyperplane across which a node they measure has a mirror image."""
    P = P[np.isfinite(P[:, 0])]
    if len(P) < P.shape[1] + 1:
        return 0.0
    s = np.linalg.svd(P - P.mean(axis=0), compute_uv=False)
    return float(s[-1] / s[0]) if s[0] > 0 else 0.0


def _side_of_hyperplane(x: np.ndarray, P: np.ndarray) -> float:
    """Signed distance of point x from the principal hyperplane of the points P."""
    c = P.mean(axis=0)
    normal = np.linalg.svd(P - c)[2][-1]
    return float((x - c) @ normal)


def _typical_std(rstd: np.ndarray, tstd: np.ndarray) -> float:
    """The median finite positive node std: a stand-in for a gauge receiver's std (0 by definition, its
    position as uncertain as a typical node's)."""
    every = np.concatenate([rstd, tstd])
    good = np.isfinite(every) & (every > 0)
    return float(np.median(every[good])) if good.any() else 0.0


def _reflect_across_hyperplane(x: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Reflection of point x across the principal hyperplane of the points P (a line in 2D, a plane in 3D)."""
    c = P.mean(axis=0)
    _, _, Vt = np.linalg.svd(P - c)
    normal = Vt[-1]  # full_matrices: defined for as few points as the hyperplane needs
    v = x - c
    return x - 2.0 * (v @ normal) * normal


def _mirror_alternatives(F, inl, R, S, O) -> list[tuple[str, int, np.ndarray, float, float]]:
    """For every placed node: its mirror image across the principal hyperplane (2D: line, 3D: plane) of
    its inlier partners, re-fitted to those measurements by Gauss-Newton (partners fixed).

    Returns (kind "receiver"/"transmitter", index, alternative (coordinates[, offset]), SSR of the
    alternative, SSR of the current position) per node with enough partners (flip ambiguity).
    """
    out = []
    dim = R.shape[1]
    for kind, X, partners in (("receiver", R, S), ("transmitter", np.column_stack([S, O]), R)):
        with_offset = kind == "transmitter"
        for k in np.flatnonzero(np.isfinite(X[:, 0])):
            idx = np.flatnonzero(inl[:, k] if with_offset else inl[k])
            if len(idx) < (dim + 1 if with_offset else dim):
                continue
            G = F[idx, k] if with_offset else F[k, idx] - O[idx]
            P = partners[idx]
            alt = X[k].copy()
            alt[:dim] = _reflect_across_hyperplane(X[k, :dim], P)
            for _ in range(8):
                e, diff, dist = _node_residuals(alt, G, P, with_offset)
                u = diff / np.maximum(dist, 1e-300)[:, None]
                J = np.column_stack([-u, -np.ones(len(idx))]) if with_offset else -u
                alt = alt + np.linalg.lstsq(J, -e, rcond=None)[0]
            if _side_of_hyperplane(alt[:dim], P) * _side_of_hyperplane(X[k, :dim], P) > 0:
                # the refit went back to the node's own side: no mirror image (a far-field source slides
                # along its range valley instead, 48 x 540: 20 such "mirrors" within 9 sigma^2)
                continue
            e_alt = _node_residuals(alt, G, P, with_offset)[0]
            e_now = _node_residuals(X[k], G, P, with_offset)[0]
            out.append((kind, int(k), alt, float(np.sum(e_alt**2)), float(np.sum(e_now**2))))
    return out


def _mirror_warnings(F, inl, R, S, O, sigma, rstd, tstd, opts, floor) -> list[str]:
    """Nodes whose mirror image across the line (3D: plane) of their partners fits nearly as well."""
    out = []
    var = max(sigma, floor) ** 2
    dim = R.shape[1]
    across = "line" if dim == 2 else "plane"
    typical = _typical_std(rstd, tstd)
    for kind, k, alt, ssr_alt, ssr_now in _mirror_alternatives(F, inl, R, S, O):
        X, std = (R, rstd) if kind == "receiver" else (S, tstd)
        delta = (ssr_alt - ssr_now) / var
        own = float(np.nan_to_num(std[k], nan=0.0, posinf=0.0))
        apart = np.linalg.norm(alt[:dim] - X[k]) > max(3.0 * (own if own > 0 else typical), 1e3 * floor)
        if apart and delta < opts.ambiguity_chi2:
            partners = "transmitters" if kind == "receiver" else "receivers"
            where = ", ".join(f"{v:.4g}" for v in alt[:dim])
            out.append(f"{kind} {k + 1}: its mirror position ({where}) across the {across} of its "
                       f"{partners} fits its measurements as well (cost {delta:+.2g} sigma^2)")
    return out


def _repair_flips(F, inl, R, S, O, sigma, floor):
    """Move every node whose re-fitted mirror position explains its inliers better by > 1 sigma^2.

    Returns (R, S, O, changed). A flipped node is a local minimum of the joint cost that the
    refinement cannot leave (the other side is beyond a ridge); the mirror test finds the other side.
    """
    var = max(sigma, floor) ** 2
    R, S, O = R.copy(), S.copy(), O.copy()
    changed = False
    for kind, k, alt, ssr_alt, ssr_now in _mirror_alternatives(F, inl, R, S, O):
        if ssr_alt < ssr_now - var and np.all(np.isfinite(alt)):
            changed = True
            if kind == "receiver":
                R[k] = alt
            else:
                S[k], O[k] = alt[: R.shape[1]], alt[R.shape[1]]
    return R, S, O, changed


#: Directions of the jumps of _probe_basins: 8 in the plane; in space the 6 axes and 8 diagonals.
_PROBE_DIRECTIONS = {
    2: np.column_stack([np.cos(np.arange(8) * np.pi / 4), np.sin(np.arange(8) * np.pi / 4)]),
    3: np.vstack([np.vstack([np.eye(3), -np.eye(3)]),
                  np.array([[a, b, c] for a in (1, -1) for b in (1, -1) for c in (1, -1)]) / np.sqrt(3.0)]),
}


#: Networks with more unknowns than this screen each probe jump by refitting the moved node alone first.
PROBE_SCREEN_PARAMS = 400


def _node_refit(F, inl, R, S, O, kind: str, k: int, iterations: int = 20):
    """Gauss-Newton on one node's unknowns (a receiver's position; a transmitter's position and offset)
    on its inlier entries, every other node fixed: where a jump of that node leads by itself."""
    if kind == "r":
        cols = np.flatnonzero(inl[k])
        x = R[k].copy()
        for _ in range(iterations):
            d = x - S[cols]
            dist = np.maximum(np.linalg.norm(d, axis=1), 1e-300)
            e = F[k, cols] - O[cols] - dist
            J = d / dist[:, None]
            step = np.linalg.lstsq(J, e, rcond=None)[0]
            x = x + step
            if np.linalg.norm(step) <= 1e-12 * max(np.linalg.norm(x), 1.0):
                break
        return x
    rows = np.flatnonzero(inl[:, k])
    x = np.append(S[k], O[k])
    dim = R.shape[1]
    for _ in range(iterations):
        d = x[:dim] - R[rows]
        dist = np.maximum(np.linalg.norm(d, axis=1), 1e-300)
        e = F[rows, k] - x[dim] - dist
        J = np.column_stack([d / dist[:, None], np.ones(len(rows))])
        step = np.linalg.lstsq(J, e, rcond=None)[0]
        x = x + step
        if np.linalg.norm(step) <= 1e-12 * max(np.linalg.norm(x), 1.0):
            break
    return x[:dim]


def _probe_basins(F, work, inl, R, S, O, sigma, opts):
    """Other least-squares minima on the inliers near the answer, reached by moving one node whose
    measurements were rejected (a gross error pulls its node during the robust stage; the refit
    without it can stay in that basin: a simulated room left a receiver 22 cm off, every node 12-15
    std off, at a minimum 6 sigma^2 above the truth's). Each such node (fewest inliers first, at most
    `probe_nodes`) jumps by `probe_radii` x the network's spread in 8 directions (3D: 14, _PROBE_DIRECTIONS); least squares on the
    inliers follows; in a network of more than PROBE_SCREEN_PARAMS unknowns only where the node, refitted
    alone from its jump (`_node_refit`), does not fall back to where it was (48 x 540 in 3D: 112 jumps
    of a least squares on 2,298 unknowns each took 44 s). Returns (R, S, O, better, alternative): the best minimum found (`better` when it
    beats the answer by more than sigma^2), and a distinct minimum within ambiguity_chi2 sigma^2 of
    it, as (extra cost in sigma^2, node label), or None.
    """
    placed_r, placed_t = np.isfinite(R[:, 0]), np.isfinite(S[:, 0])
    rejected = work & ~inl & placed_r[:, None] & placed_t[None, :]
    nodes = [("r", i, int(inl[i].sum())) for i in np.flatnonzero(rejected.any(axis=1))]
    nodes += [("s", j, int(inl[:, j].sum())) for j in np.flatnonzero(rejected.any(axis=0))]
    dim = R.shape[1]
    dof = int(inl.sum()) - n_unknowns(int(placed_r.sum()), int(placed_t.sum()), dim)
    if not nodes or dof < 1:
        return R, S, O, False, None
    nodes = sorted(nodes, key=lambda t: t[2])[: opts.probe_nodes]

    def ssr_of(R, S, O):
        E = _residual_matrix(F, R, S, O)[inl]
        return float(np.sum(E**2)) if np.all(np.isfinite(E)) else np.inf

    ssr0 = ssr_of(R, S, O)
    var = sigma**2 if sigma is not None else ssr0 / dof
    if not np.isfinite(ssr0) or var <= 0:
        return R, S, O, False, None
    P = np.vstack([R[placed_r], S[placed_t]])
    spread = float(np.sqrt(np.mean(np.sum((P - P.mean(axis=0)) ** 2, axis=1))))
    found = [(ssr0, "", (R, S, O))]
    screen = n_unknowns(int(placed_r.sum()), int(placed_t.sum()), dim) > PROBE_SCREEN_PARAMS
    for kind, k, _ in nodes:
        for radius in opts.probe_radii:
            for direction in _PROBE_DIRECTIONS[dim]:
                R2, S2 = R.copy(), S.copy()
                X = R2 if kind == "r" else S2
                X[k] += radius * spread * direction
                if screen:
                    back = _node_refit(F, inl, R2, S2, O, kind, k)
                    if np.linalg.norm(back - (R if kind == "r" else S)[k]) <= 1e-3 * radius * spread:
                        continue
                ls = robust_refine(F, work, R2, S2, O, loss="linear", max_iter=opts.max_iterations, use=inl)
                found.append((ssr_of(ls.R, ls.S, ls.O), f"{'receiver' if kind == 'r' else 'transmitter'} {k + 1}",
                              (ls.R, ls.S, ls.O)))
    best = min(found, key=lambda f: f[0])
    better = best[0] < ssr0 - var
    top = best if better else found[0]
    top_model = _Model(*top[2], 0.0, 0.0)
    alternative = None
    for ssr, label, x in sorted(found, key=lambda f: f[0]):
        if (ssr - top[0]) / var >= opts.ambiguity_chi2:
            break
        if x is not top[2] and _distinct(_Model(*x, 0.0, 0.0), top_model, 1e-3):
            alternative = ((ssr - top[0]) / var, label or "the first answer")
            break
    return (*top[2], better, alternative)


def _distinct(a: _Model, b: _Model, tol: float) -> bool:
    """True when two models differ beyond a rigid motion (reflections allowed)."""
    from ..metrics import align_rigid

    ok = np.isfinite(a.R[:, 0]) & np.isfinite(b.R[:, 0])
    okt = np.isfinite(a.S[:, 0]) & np.isfinite(b.S[:, 0])
    X = np.vstack([a.R[ok], a.S[okt]])
    Y = np.vstack([b.R[ok], b.S[okt]])
    if len(X) < 3:
        return False
    aligned = align_rigid(X, Y).apply(X)
    return float(np.linalg.norm(aligned - Y) / max(np.linalg.norm(Y - Y.mean(axis=0)), 1e-300)) > tol



def _beyond_std(R2, S2, R, S, rstd, tstd, atol: float) -> bool:
    """True when another fit (R2, S2) puts a node farther than 3 reported std (plus atol) from (R, S)
    after a rigid alignment (reflections allowed), or places other nodes."""
    ok = np.isfinite(R[:, 0]).tolist() + np.isfinite(S[:, 0]).tolist()
    if ok != np.isfinite(R2[:, 0]).tolist() + np.isfinite(S2[:, 0]).tolist():
        return True
    shift, ok = _aligned_shift(R2, S2, R, S)
    if shift is None:
        return False
    std = _node_std(rstd, tstd)[ok]
    tol = 3.0 * np.where(np.isfinite(std), std, np.inf) + atol
    return bool((shift > tol).any())


def _aligned_shift(R2, S2, R, S):
    """(distance of each node placed in both fits after a rigid alignment of (R2, S2) onto (R, S),
    reflections allowed; the mask of those nodes), or (None, mask) when too few nodes are placed in both."""
    from ..metrics import align_rigid

    X = np.vstack([R, S])
    Y = np.vstack([R2, S2])
    ok = np.isfinite(X[:, 0]) & np.isfinite(Y[:, 0])
    if ok.sum() <= X.shape[1]:
        return None, ok
    return np.linalg.norm(align_rigid(Y[ok], X[ok]).apply(Y[ok]) - X[ok], axis=1), ok


def _node_std(rstd, tstd) -> np.ndarray:
    """Receivers' then transmitters' reported std, a gauge receiver (std 0) given a typical node's: it
    moves with an alignment like any node (48 x 540: every node 4e-7 apart after aligning two fits of
    equal cost, the gauge receiver "beyond 3 std")."""
    std = np.concatenate([rstd, tstd])
    return np.where(std == 0.0, _typical_std(rstd, tstd), std)


def _standardised_shift(R2, S2, rstd2, tstd2, R, S, rstd, tstd) -> float:
    """The largest distance between two fits' nodes (after a rigid alignment) over the root sum of
    squares of their reported stds; inf when too few nodes are placed in both to align them."""
    shift, ok = _aligned_shift(R2, S2, R, S)
    if shift is None:
        return math.inf
    std = np.hypot(_node_std(rstd, tstd), _node_std(rstd2, tstd2))[ok]
    if not (np.isfinite(std).all() and (std > 0).all()):
        return math.inf  # a node without a finite std: no comparison
    return float(np.max(shift / std))


def _flags(F, work, inl, R, S, O, sigma, rstd, tstd, opts, floor, deficient, search, best, sigma_given, rms,
           already=()) -> tuple[list[str], list[str]]:
    """(warnings, undecided): warnings for what the data cannot decide (see CalibrationResult.warnings),
    and among them those that leave two answers the data do not tell apart (a node's mirror image, an
    alternative calibration of similar cost): the status is then "ambiguous", never "ok"."""
    out = []
    undecided: list[str] = []
    placed_r, placed_t = np.isfinite(R[:, 0]), np.isfinite(S[:, 0])
    for i in np.flatnonzero(~placed_r & work.any(axis=1)):
        if not any(w.startswith(f"receiver {i + 1}: ") for w in already):
            out.append(f"receiver {i + 1}: could not be placed from its measurements")
    for j in np.flatnonzero(~placed_t & work.any(axis=0)):
        if not any(w.startswith(f"transmitter {j + 1}: ") for w in already):
            out.append(f"transmitter {j + 1}: could not be placed from its measurements")
    dim = R.shape[1]
    shape, across = ("collinear", "line") if dim == 2 else ("coplanar", "plane")
    ratio = _principal_ratio(R)
    if ratio < opts.collinear_ratio:
        out.append(f"receivers are nearly {shape} (spread ratio {ratio:.2g}): transmitters have mirror "
                   f"positions across their {across} that fit about as well")
    ratio = _principal_ratio(S)
    if ratio < opts.collinear_ratio:
        out.append(f"transmitters are nearly {shape} (spread ratio {ratio:.2g}): receivers have mirror "
                   f"positions across their {across} that fit about as well")
    n_in, rejected = int(inl.sum()), int((work & ~inl & placed_r[:, None] & placed_t[None, :]).sum())
    redundancy = n_in - n_unknowns(int(placed_r.sum()), int(placed_t.sum()), dim)
    if rejected and redundancy <= 3 * rejected:
        out.append(f"low redundancy: {n_in} inliers for {n_in - redundancy} unknowns with {rejected} measurements "
                   "rejected; another choice of rejected measurements may fit as well")
    if deficient:
        out.append("the Jacobian on the inliers is rank-deficient: some coordinates are not determined by the data "
                   "(their std is inf)")
    mirrors = _mirror_warnings(F, inl, R, S, O, sigma, rstd, tstd, opts, floor)
    out += mirrors
    if mirrors:
        nodes = ", ".join(w.split(":")[0] for w in mirrors[:4]) + (", ..." if len(mirrors) > 4 else "")
        undecided.append(f"{len(mirrors)} node(s) ({nodes}) have a mirror image that fits their measurements as "
                         "well: the data do not decide their side")
    # An alternative hypothesis (after local optimisation) of similar cost that is a different network.
    var = max(sigma, floor) ** 2
    best_cost = float(np.sum(np.minimum(_residual_matrix(F, R, S, O)[work] ** 2, (opts.threshold_sigmas ** 2) * var)))
    for other in search.others:
        E = _residual_matrix(F, other.R, other.S, other.O)[work]
        cost = float(np.sum(np.minimum(np.nan_to_num(E, nan=np.inf) ** 2, (opts.threshold_sigmas ** 2) * var)))
        if (cost - best_cost) / var >= opts.ambiguity_chi2:
            continue
        # The search's models are only locally optimised: one is another answer only if least squares on
        # the same inliers from it ends at another minimum, a node beyond 3 reported std from this one.
        ls = robust_refine(F, work, other.R, other.S, other.O, loss="linear", max_iter=opts.max_iterations, use=inl)
        E = _residual_matrix(F, ls.R, ls.S, ls.O)[work]
        cost = float(np.sum(np.minimum(np.nan_to_num(E, nan=np.inf) ** 2, (opts.threshold_sigmas ** 2) * var)))
        if (cost - best_cost) / var < opts.ambiguity_chi2 and _beyond_std(ls.R, ls.S, R, S, rstd, tstd, 1e3 * floor):
            note = (f"an alternative calibration fits nearly as well (cost +{(cost - best_cost) / var:.2g} sigma^2); "
                    "the data may not decide between them")
            out.append(note)
            undecided.append(note)
            break
    if sigma_given is not None and sigma_given > 0 and rms > 3.0 * sigma_given:
        out.append(f"the inlier RMS {rms:.3g} is {rms / sigma_given:.1f} x the given sigma; is sigma right?")
    return out, undecided
