"""Stratified 3D TDOA block solver: offsets, a rank-3 factorisation, and a linear upgrade.

For a fully measured block of m >= 10 receivers and five transmitters in 3D, after Larsson, Flood,
Oskarsson, Astrom ("Upgrade methods for stratified sensor network self-calibration", ICASSP 2020)
and the offset kernel of :mod:`solvers.methods.offset_kernel`, but over-determined, so that noise is
averaged instead of amplified:

1. **Offsets.** The compaction matrix D~(o) = c + alpha o_1 + beta o_(j+1) ((m-1) x 4) has rank 3 at
   the true offsets, so D~ v = 0 for some v != 0; in z = (v, o_1 sum(v), o_2 v_1, ..., o_5 v_4) that is
   [c | alpha | beta] z = 0, (m - 1) x 9. Its least-squares kernel (smallest right singular vector;
   m - 1 >= 9 rows: no fewer equations than unknowns) gives the offsets as ratios.
2. **Affine frame.** D~(o) = X Y^T, truncated to rank 3 by the SVD (all four columns, not three chosen
   ones): the receivers r_i - r_1 = A x_i and the transmitters A^T (s_j - s_1) = -y_j / 2 for an unknown
   invertible A (3 x 3).
3. **Upgrade.** With r_1 = 0, |r_i - s_1|^2 - |s_1|^2 = d_i1^2 - d_11^2 reads
   x_i^T H x_i - 2 x_i^T b = d_i1^2 - d_11^2 with H = A^T A and b = A^T s_1: linear in (H, b) (the C
   equations of the paper's formulation), m - 1 >= 9 rows for 9 unknowns, solved homogeneously (the
   smallest right singular vector of the row-normalised system). A = chol(H)^T, s_1 = A^-T b.

A block whose receivers are (nearly) coplanar, or whose upgrade gives an H that is not positive
definite, yields no hypothesis: the sample is reported degenerate (:class:`BlockOutcome`), never
returned as a network. numpy only; about 0.1 ms per block.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .pencil import compaction_pieces

__all__ = ["MIN_RECEIVERS", "TRANSMITTERS", "BlockOutcome", "solve_block"]

#: Receivers a block needs: m - 1 >= 9 rows for the offsets' 9 unknowns and the upgrade's 9.
MIN_RECEIVERS = 10
#: Transmitters of a block (the offset kernel's four columns of D~ beside the reference).
TRANSMITTERS = 5
#: Second smallest singular value of the offsets' kernel system below which the block's receivers count
#: as coplanar whatever the noise (exactly coplanar: their mirror images fit as well, no 3D hypothesis).
COPLANAR_KERNEL = 1e-9

#: With sigma known: that singular value below COPLANAR_NOISE x sigma / RMS(F) is noise (coplanar).
COPLANAR_NOISE = 3.0
#: A non-positive eigenvalue of H is replaced by this fraction of its smallest positive one (solve_block).
H_CLIP = 0.1

_IU = np.triu_indices(3)


@dataclass(frozen=True)
class BlockOutcome:
    """A block's hypothesis (receivers (m, 3), transmitters (5, 3), offsets (5,)) or why there is none."""

    receivers: np.ndarray | None
    transmitters: np.ndarray | None
    offsets: np.ndarray | None
    reason: str = ""

    @property
    def solved(self) -> bool:
        return self.receivers is not None


def _kernel(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(smallest right singular vector, singular values) of M."""
    _, s, vt = np.linalg.svd(M, full_matrices=True)
    return vt[-1], s


def _offsets(F: np.ndarray) -> tuple[np.ndarray | None, float]:
    """(offsets or None, second smallest singular value of the row-normalised kernel system)."""
    c, alpha, beta, _ = compaction_pieces(F)
    M = np.concatenate([c, alpha[:, None], beta], axis=1)
    z, s = _kernel(M / np.linalg.norm(M, axis=1, keepdims=True))
    v = z[:4]
    if np.min(np.abs(v)) <= 1e-12 * np.max(np.abs(v)) or abs(v.sum()) <= 1e-12 * np.max(np.abs(v)):
        return None, float(s[-2])
    return np.concatenate([[z[4] / v.sum()], z[5:] / v]), float(s[-2])


def _coplanar(s2: float, sigma: float | None, scale: float) -> bool:
    """Whether the second smallest singular value s2 of the offsets' kernel system is noise (solve_block)."""
    return not s2 > max(COPLANAR_KERNEL, 0.0 if sigma is None else COPLANAR_NOISE * sigma / scale)


def _trim(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows, columns) of the sub-block with one receiver left out and the reference transmitter first
    whose offsets' kernel system fits best (smallest over second smallest singular value of the
    row-normalised system):
    a gross error in one entry leaves it out (its row, or as the reference column, all rows), so a
    sample with at most one gross error still gives its hypothesis."""
    m, n = F.shape
    rows = np.array([np.delete(np.arange(m), k) for k in range(m)])  # (m, m - 1)
    cols = np.array([[c] + [j for j in range(n) if j != c] for c in range(n)])  # (n, n)
    blocks = F[rows[None, :, :, None], cols[:, None, None, :]]  # (n, m, m - 1, n)
    c, alpha, beta, _ = compaction_pieces(blocks)
    M = np.concatenate([c, alpha[..., None], beta], axis=-1)
    M = M / np.linalg.norm(M, axis=-1, keepdims=True)
    sv = np.linalg.svd(M, compute_uv=False)
    # the smallest singular value against the second: a gross error raises the first, and a choice that
    # makes the kernel ill-determined (both small) is no better for it
    score = sv[..., -1] / np.maximum(sv[..., -2], 1e-300)  # (n, m)
    ci, ri = np.unravel_index(int(np.argmin(score)), score.shape)
    return rows[ri], cols[ci]


def solve_block(F: np.ndarray, sigma: float | None = None, trim: bool = False) -> BlockOutcome:
    """One hypothesis from a fully measured block F (m >= 10 receivers x 5 transmitters) in 3D.

    trim: leave out the receiver (and choose the reference transmitter) that explain the block worst
    (`_trim`, m >= 11), so that one gross error in the block does not spoil the hypothesis; the
    receiver left out is returned as NaN (the caller places it from the others).
    """
    F = np.asarray(F, dtype=float)
    m, n = F.shape
    if trim and m > MIN_RECEIVERS and n == TRANSMITTERS and np.all(np.isfinite(F)):
        scale = float(np.sqrt(np.mean(F * F))) or 1.0
        s2 = _offsets(F / scale)[1]  # coplanar on the whole block (a sub-block may look less so)
        if _coplanar(s2, sigma, scale):
            return BlockOutcome(None, None, None, f"coplanar receivers (second kernel singular value {s2:.2g})")
        rows, cols = _trim(F)
        out = _solve(F[np.ix_(rows, cols)], sigma, coplanar_checked=True)
        if not out.solved:
            return out
        R = np.full((m, 3), np.nan)
        S = np.empty((n, 3))
        O = np.empty(n)
        R[rows], S[cols], O[cols] = out.receivers, out.transmitters, out.offsets
        return BlockOutcome(R, S, O)
    return _solve(F, sigma)


def _solve(F: np.ndarray, sigma: float | None = None, coplanar_checked: bool = False) -> BlockOutcome:
    """One hypothesis from a fully measured block F (m >= 10 receivers x 5 transmitters) in 3D.

    sigma: the noise level of F when known. Coplanar receivers make D~ of rank 2 at the true offsets, so
    the offsets' kernel system has a kernel of dimension 2: its second smallest singular value s is
    noise (about 3 sigma / RMS(F), at most 20 in 99 % of seeded room samples), while a 3D block's is set
    by its geometry (above 0.0018 in 99 %; docs/calibration-3d.md). The block is coplanar when s is
    below COPLANAR_KERNEL (exact coplanarity, sigma unknown) or below COPLANAR_NOISE x sigma / RMS(F).
    The two overlap at sigma >= 1 mm in a room: with COPLANAR_NOISE = 3, 12r/5s room samples keep a
    hypothesis in 100 / 100 / 87.5 % at sigma 1e-4 / 1e-3 / 1e-2 m and coplanar ones are refused in
    62 / 62 / 70 % (200 seeded samples each; 5 would refuse 80-87 % but drop 31 % of the 3D samples at
    1 cm). A coplanar network is flagged by the pipeline whatever its samples gave (never "ok").
    Returns a BlockOutcome in the gauge of the construction (r_1 = 0; the caller moves it to its own);
    `reason` says why a degenerate or inconsistent block gave none.
    """
    F = np.asarray(F, dtype=float)
    m, n = F.shape
    if m < MIN_RECEIVERS or n != TRANSMITTERS:
        raise ValueError(f"a stratified block has >= {MIN_RECEIVERS} receivers x {TRANSMITTERS} transmitters, "
                         f"got {m} x {n}")
    if not np.all(np.isfinite(F)):
        raise ValueError("the block must be fully measured")
    scale = float(np.sqrt(np.mean(F * F))) or 1.0
    F = F / scale
    o, s2 = _offsets(F)
    if not coplanar_checked and _coplanar(s2, sigma, scale):
        return BlockOutcome(None, None, None, f"coplanar receivers (second kernel singular value {s2:.2g})")
    if o is None:
        return BlockOutcome(None, None, None, "offset kernel without a usable solution")
    d2 = (F - o[None, :]) ** 2
    D = d2[1:, 1:] - d2[:1, 1:] - d2[1:, :1] + d2[0, 0]
    U, sv, Vt = np.linalg.svd(D, full_matrices=False)
    if not sv[2] > 1e-12 * sv[0]:
        return BlockOutcome(None, None, None, "compaction matrix of rank < 3")
    X = U[:, :3] * sv[:3]
    Y = Vt[:3].T
    x0, x1, x2 = X[:, 0], X[:, 1], X[:, 2]
    quad = np.stack([x0 * x0, 2 * x0 * x1, 2 * x0 * x2, x1 * x1, 2 * x1 * x2, x2 * x2], axis=1)
    rhs = d2[1:, 0] - d2[0, 0]
    C = np.concatenate([quad, -2.0 * X, -rhs[:, None]], axis=1)
    z, _ = _kernel(C / np.linalg.norm(C, axis=1, keepdims=True))
    if abs(z[9]) <= 1e-12 * np.max(np.abs(z)):
        return BlockOutcome(None, None, None, "upgrade at infinity")
    z = z / z[9]
    H = np.empty((3, 3))
    H[_IU] = z[:6]
    H[(_IU[1], _IU[0])] = z[:6]
    b = z[6:9]
    lam, V = np.linalg.eigh(H)
    if not lam[-1] > 0:
        return BlockOutcome(None, None, None, "upgrade H negative definite")
    # Noise can push a small eigenvalue of H below 0 (a flat direction of the affine frame): replaced by
    # a fraction of the smallest positive one, the upgrade is a rough start that the block's least
    # squares often repairs (docs/calibration-3d.md: the share of blocks in the right basin).
    positive = lam[lam > 0]
    lam = np.where(lam > 0, lam, H_CLIP * positive.min())
    A = (V * np.sqrt(lam)) @ V.T  # symmetric square root: A^T A = H
    s1 = np.linalg.solve(A.T, b)
    R = np.vstack([np.zeros(3), X @ A.T])
    S = np.vstack([s1, s1 - 0.5 * np.linalg.solve(A.T, Y.T).T])
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(S))):
        return BlockOutcome(None, None, None, "non-finite upgrade")
    return BlockOutcome(R * scale, S * scale, o * scale)
