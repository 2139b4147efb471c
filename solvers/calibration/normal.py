"""The normal equations of a TDOA network by blocks: each transmitter eliminated by its Schur complement.

Every entry e_ij touches the receiver i's free coordinates and the transmitter j's position and offset
(dim + 1 unknowns), so the normal matrix of a network in the parameter layout of solvers.refine.pack is

    N = [[A, B], [B^T, D]],   A: receivers (k0 x k0),  B: k0 x (dim + 1) n,  D: n diagonal blocks
                                                                              of (dim + 1)^2,

and N x = g is solved by eliminating the transmitters: the Schur complement S = A - B D^-1 B^T
(k0 x k0: 138 unknowns for 48 receivers in 3D, whatever the number of transmitters), then
x_r = S^-1 (g_r - B D^-1 g_t) and x_t = D^-1 (g_t - B^T x_r) block by block. The inverse is never
formed densely either (`BlockInverse`): with G = B D^-1 and P = S^+,

    N^- = [[P, -P G], [-G^T P, D^- + G^T P G]],

of which the adjustment needs selected entries (the blocks of one measurement's unknowns: redundancy
numbers, predictions), the diagonal (standard deviations) and products with sparse right-hand sides
(external reliability). For a singular N (a rank-deficient fit) D^- and P are pseudo-inverses of
their blocks; the result is a generalised inverse of N (N = J^T J is positive semi-definite, so the
columns of B^T lie in the range of D), and every estimable quantity - j_k^T N^- j_k of a measured
entry, the variance of a determined coordinate - is the same for every generalised inverse.

Reference: the reduced camera system of bundle adjustment (Triggs et al., "Bundle adjustment - a
modern synthesis", 2000, Sec. 6.1); block inverse by the Schur complement (Golub and Van Loan, 2013).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

__all__ = ["BlockLayout", "BlockNormal", "BlockInverse", "pseudo_inverse"]

#: Relative eigenvalue of a transmitter block below which its direction counts as not determined.
BLOCK_RTOL = 1e-13


def pseudo_inverse(N: np.ndarray, rtol: float = 1e-10, top: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(N^+, null) of a symmetric positive semi-definite N by its eigendecomposition; null marks the
    parameters touched by an eigenvector of eigenvalue below rtol x top (default top: N's largest
    eigenvalue; not determined)."""
    if N.size == 0:
        return N.copy(), np.zeros(0, bool)
    lam, V = np.linalg.eigh(N)
    top = max(float(lam[-1]) if top is None else top, 1e-300)
    small = lam <= rtol * top
    inv = np.where(small, 0.0, 1.0 / np.where(small, 1.0, lam))
    Ninv = (V * inv) @ V.T
    null = np.zeros(N.shape[0], bool)
    if small.any():
        null = np.linalg.norm(V[:, small], axis=1) > 1e-6
    return Ninv, null


@dataclass(frozen=True, eq=False)
class BlockLayout:
    """Where each entry's 2 dim + 1 derivatives go in the blocks of N.

    slots : (k, 2 dim + 1) parameter columns (receiver coordinates, transmitter coordinates, offset) of
        each entry in the pack layout; n_params marks a fixed gauge coordinate (receivers only)
    k0 : free receiver coordinates (the first k0 parameters); n: transmitters; dim
    jj : (k,) the transmitter of each entry
    """

    slots: np.ndarray
    jj: np.ndarray
    k0: int
    n: int
    dim: int

    @property
    def n_params(self) -> int:
        return self.k0 + (self.dim + 1) * self.n

    @cached_property
    def to_block(self) -> np.ndarray:
        """(dim + 1) n: the block-ordered position (transmitter j's coordinates, then its offset) of each
        transmitter parameter of the pack layout (coordinates of all, then offsets of all)."""
        d1, n, dim = self.dim + 1, self.n, self.dim
        pos = np.empty(d1 * n, int)
        j = np.arange(n)
        for a in range(dim):
            pos[dim * j + a] = d1 * j + a
        pos[dim * n + j] = d1 * j + dim
        return pos

    @cached_property
    def index(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Flat bincount indices of the receiver-receiver products into (k0 + 1)^2, of the
        receiver-transmitter products into (k0 + 1) x (dim + 1) n (block order), and of the
        transmitter-transmitter products into n (dim + 1)^2 (the fixed coordinate k0 collects the
        products of gauge coordinates, then dropped)."""
        dim, d1, k0 = self.dim, self.dim + 1, self.k0
        r = np.minimum(self.slots[:, :dim], k0)
        rr = (r[:, :, None] * (k0 + 1) + r[:, None, :]).ravel()
        t = d1 * self.jj[:, None] + np.arange(d1)[None, :]
        rt = (r[:, :, None] * (d1 * self.n) + t[:, None, :]).ravel()
        tt = (self.jj[:, None, None] * d1 * d1 + np.arange(d1)[None, :, None] * d1
              + np.arange(d1)[None, None, :]).ravel()
        return rr, rt, tt

    def to_blocks(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(receiver part (k0, ...), transmitter part (n, dim + 1, ...)) of x in the pack layout."""
        xt = np.empty((self.n * (self.dim + 1),) + x.shape[1:])
        xt[self.to_block] = x[self.k0:]
        return x[: self.k0], xt.reshape((self.n, self.dim + 1) + x.shape[1:])

    def from_blocks(self, xr: np.ndarray, xt: np.ndarray) -> np.ndarray:
        """The pack layout of (receiver part, transmitter part in blocks): the inverse of to_blocks."""
        xt = xt.reshape((self.n * (self.dim + 1),) + xt.shape[2:])
        return np.concatenate([xr, xt[self.to_block]])


@dataclass(frozen=True, eq=False)
class BlockNormal:
    """J^T W J = [[A, B], [B^T, D]] and J^T W e of a problem (see the module docstring).

    A : (k0, k0); B : (k0, n, dim + 1) (block order); D : (n, dim + 1, dim + 1); g: (n_params,) in the
    pack layout.
    """

    layout: BlockLayout
    A: np.ndarray
    B: np.ndarray
    D: np.ndarray
    g: np.ndarray

    @classmethod
    def accumulate(cls, layout: BlockLayout, v: np.ndarray, w: np.ndarray, e: np.ndarray) -> BlockNormal:
        """From the (k, 2 dim + 1) derivatives v of the entries, their weights w and residuals e."""
        dim, d1, k0, n = layout.dim, layout.dim + 1, layout.k0, layout.n
        rr, rt, tt = layout.index
        wv = w[:, None] * v
        vr, vt, wr, wt = v[:, :dim], v[:, dim:], wv[:, :dim], wv[:, dim:]
        A = np.bincount(rr, (wr[:, :, None] * vr[:, None, :]).ravel(), minlength=(k0 + 1) ** 2)
        B = np.bincount(rt, (wr[:, :, None] * vt[:, None, :]).ravel(), minlength=(k0 + 1) * d1 * n)
        D = np.bincount(tt, (wt[:, :, None] * vt[:, None, :]).ravel(), minlength=n * d1 * d1)
        size = layout.n_params + 1
        g = np.bincount(layout.slots.ravel(), (wv * e[:, None]).ravel(), minlength=size)[:-1]
        return cls(layout, A.reshape(k0 + 1, k0 + 1)[:-1, :-1], B.reshape(k0 + 1, n, d1)[:-1],
                   D.reshape(n, d1, d1), g)

    def diagonal(self) -> np.ndarray:
        """diag N in the pack layout."""
        return self.layout.from_blocks(np.diag(self.A).copy(), np.einsum("naa->na", self.D).copy())

    def dense(self) -> np.ndarray:
        """N as a dense matrix in the pack layout (tests and small problems only)."""
        lay = self.layout
        k0, T = lay.k0, lay.n * (lay.dim + 1)
        Nb = np.zeros((k0 + T, k0 + T))
        Nb[:k0, :k0] = self.A
        Nb[:k0, k0:] = self.B.reshape(k0, T)
        Nb[k0:, :k0] = self.B.reshape(k0, T).T
        d1 = lay.dim + 1
        for j in range(lay.n):
            Nb[k0 + d1 * j: k0 + d1 * (j + 1), k0 + d1 * j: k0 + d1 * (j + 1)] = self.D[j]
        perm = np.concatenate([np.arange(k0), k0 + lay.to_block])
        return Nb[np.ix_(perm, perm)]

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """N x for x in the pack layout."""
        lay = self.layout
        xr, xt = lay.to_blocks(x)
        yr = self.A @ xr + np.einsum("knc,nc->k", self.B, xt)
        yt = np.einsum("knc,k->nc", self.B, xr) + np.einsum("ncd,nd->nc", self.D, xt)
        return lay.from_blocks(yr, yt)

    def solve(self, rhs: np.ndarray, shift: np.ndarray | None = None) -> np.ndarray | None:
        """(N + diag(shift))^-1 rhs by the Schur complement and Cholesky factorisations, or None when
        the matrix is not positive definite (a transmitter block or the reduced receiver system)."""
        from scipy.linalg import lapack

        lay = self.layout
        k0, n, d1 = lay.k0, lay.n, lay.dim + 1
        A, D = self.A, self.D
        if shift is not None:
            sr, st = lay.to_blocks(shift)
            A = A + np.diag(sr)
            D = D + st[:, :, None] * np.eye(d1)[None]
        try:
            np.linalg.cholesky(D)
        except np.linalg.LinAlgError:
            return None
        Dinv = np.linalg.inv(D)
        br, bt = lay.to_blocks(rhs)
        G = np.einsum("knc,ncd->knd", self.B, Dinv)  # B D^-1
        if k0:
            S = A - G.reshape(k0, n * d1) @ self.B.reshape(k0, n * d1).T
            c, info = lapack.dpotrf(S, lower=0, clean=0, overwrite_a=1)
            if info != 0:
                return None
            xr, info = lapack.dpotrs(c, br - np.einsum("knc,nc->k", G, bt), lower=0)
            if info != 0:
                return None
        else:
            xr = np.zeros(0)
        xt = np.einsum("ncd,nd->nc", Dinv, bt) - np.einsum("knc,k->nc", G, xr)
        return lay.from_blocks(xr, xt)

    def inverse(self, rtol: float = 1e-10) -> BlockInverse:
        """The generalised inverse of N (`BlockInverse`); eigenvalues of a transmitter block below
        BLOCK_RTOL x its largest, and of the reduced system S below rtol x (an estimate of N's largest eigenvalue,
        within a factor 2), count as zero and mark their coordinates not determined."""
        lay = self.layout
        k0, n, d1 = lay.k0, lay.n, lay.dim + 1
        lamD, VD = np.linalg.eigh(self.D) if n else (np.zeros((0, d1)), np.zeros((0, d1, d1)))
        topA = float(np.linalg.eigvalsh(self.A)[-1]) if k0 else 0.0
        top = max(topA, float(lamD.max(initial=0.0)), 1e-300)
        # a transmitter block is inverted on its own: its rank is judged against its own largest
        # eigenvalue, at BLOCK_RTOL (a far-field source 30 m from a 25 cm array has a range/offset
        # eigenvalue 1e-10 of its largest, and its 4 x 4 block still inverts to 1e-6; an exact
        # deficiency, a transmitter measured by too few receivers, is 1e-16 of it)
        small = lamD <= BLOCK_RTOL * np.maximum(lamD[:, -1:], 1e-300 * top)
        inv = np.where(small, 0.0, 1.0 / np.where(small, 1.0, lamD))
        Dinv = np.einsum("nab,nb,ncb->nac", VD, inv, VD)
        null_t = np.zeros((n, d1), bool)
        if small.any():
            null_t = np.einsum("nab,nb->na", VD**2, small.astype(float)) > 1e-12
        G = np.einsum("knc,ncd->knd", self.B, Dinv)
        S = self.A - G.reshape(k0, n * d1) @ self.B.reshape(k0, n * d1).T
        S = 0.5 * (S + S.T)
        P, null_r = pseudo_inverse(S, rtol, top)
        if null_r.any():
            # a null vector v of S is (v, -G^T v) of N: the transmitters it moves are not determined
            lam, V = np.linalg.eigh(S)
            Vs = V[:, lam <= rtol * top]
            Wt = -np.einsum("knc,kq->ncq", G, Vs)
            scale = np.sqrt(1.0 + np.sum(Wt**2, axis=(0, 1)))
            null_t |= np.any(np.abs(Wt / scale) > 1e-6, axis=2)
        Y = np.einsum("kl,lnc->knc", P, G)  # P G
        return BlockInverse(lay, P, Dinv, G, Y, lay.from_blocks(null_r, null_t))


@dataclass(frozen=True, eq=False)
class BlockInverse:
    """A generalised inverse of N = [[A, B], [B^T, D]] kept by blocks (see the module docstring).

    P : (k0, k0) S^+; Dinv : (n, dim + 1, dim + 1) the blocks' D^+; G : (k0, n, dim + 1) B D^+;
    Y : P G; null : (n_params,) coordinates not determined (pack layout).
    """

    layout: BlockLayout
    P: np.ndarray
    Dinv: np.ndarray
    G: np.ndarray
    Y: np.ndarray
    null: np.ndarray

    @cached_property
    def transmitter_blocks(self) -> np.ndarray:
        """(n, dim + 1, dim + 1) the diagonal blocks D^+ + G^T P G of the transmitters."""
        return self.Dinv + np.einsum("knc,knd->ncd", self.G, self.Y)

    def diagonal(self) -> np.ndarray:
        """diag N^- in the pack layout."""
        return self.layout.from_blocks(np.diag(self.P).copy(), np.einsum("naa->na", self.transmitter_blocks).copy())

    def entries(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """N^-[a, b] for parameter index arrays a, b (broadcast together; n_params, a fixed gauge
        coordinate, gives 0). Two transmitter coordinates of different transmitters are computed by
        a dot product of length k0 each (the uses here only ask for a transmitter's own block)."""
        lay = self.layout
        k0, d1 = lay.k0, lay.dim + 1
        a, b = np.broadcast_arrays(np.asarray(a), np.asarray(b))
        out = np.zeros(a.shape)
        fixed = lay.n_params
        ra, rb = a < k0, b < k0
        ta, tb = (a >= k0) & (a < fixed), (b >= k0) & (b < fixed)
        pa = np.where(ta, lay.to_block[np.clip(a - k0, 0, max(len(lay.to_block) - 1, 0))], 0) if lay.n else a * 0
        pb = np.where(tb, lay.to_block[np.clip(b - k0, 0, max(len(lay.to_block) - 1, 0))], 0) if lay.n else b * 0
        Yf = self.Y.reshape(k0, -1)
        sel = ra & rb
        out[sel] = self.P[a[sel], b[sel]]
        sel = ra & tb
        out[sel] = -Yf[a[sel], pb[sel]]
        sel = ta & rb
        out[sel] = -Yf[b[sel], pa[sel]]
        ja, jb = pa // d1, pb // d1
        same = ta & tb & (ja == jb)
        out[same] = self.transmitter_blocks[ja[same], pa[same] % d1, pb[same] % d1]
        cross = ta & tb & (ja != jb)
        if cross.any():
            Gf = self.G.reshape(k0, -1)
            out[cross] = np.einsum("kq,kq->q", Gf[:, pa[cross]], Yf[:, pb[cross]])
        return out

    def quadratic(self, slots: np.ndarray, v: np.ndarray) -> np.ndarray:
        """v_k^T N^- v_k of every entry k, v_k (2 dim + 1) on its parameter columns `slots` (receiver
        coordinates, then one transmitter's coordinates and offset; n_params: fixed), as the sum of two
        positive semi-definite forms, w^T P w + v_t^T D_j^+ v_t with w = v_r - G_j v_t: never negative,
        and no cancellation between the large entries of a nearly singular transmitter block (the
        entry-wise N^-[a, b] sum gave -3 for a rejected entry of such a transmitter).
        Reference: the block inverse of the module docstring, regrouped."""
        lay = self.layout
        dim, d1, k0 = lay.dim, lay.dim + 1, lay.k0
        if len(slots) == 0:
            return np.zeros(0)
        jj = lay.to_block[slots[:, dim] - k0] // d1
        vr, vt = v[:, :dim], v[:, dim:]
        WT = np.zeros((k0, len(v)))  # w of every entry, one per column
        for c in range(d1):
            WT -= self.G[:, jj, c] * vt[:, c]
        rs = slots[:, :dim]
        free = rs < k0
        cols = np.broadcast_to(np.arange(len(v))[:, None], rs.shape)
        np.add.at(WT, (rs[free], cols[free]), vr[free])
        h = np.einsum("kK,kK->K", self.P @ WT, WT)
        return h + np.einsum("Kc,Kcd,Kd->K", vt, self.Dinv[jj], vt)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """N^- rhs for rhs (n_params, c) in the pack layout."""
        lay = self.layout
        k0, T = lay.k0, lay.n * (lay.dim + 1)
        br, bt = lay.to_blocks(rhs)
        cols = rhs.shape[1:]
        Gf = self.G.reshape(k0, T)
        btf = bt.reshape((T, -1))
        xr = self.P @ (br.reshape(k0, -1) - Gf @ btf) if k0 else br.reshape(0, btf.shape[1])
        xt = np.einsum("ncd,nd...->nc...", self.Dinv, bt).reshape((T, -1)) - Gf.T @ xr
        return lay.from_blocks(xr.reshape((k0,) + cols), xt.reshape((lay.n, lay.dim + 1) + cols))
