"""Shared numeric kernels of the generated solvers.

A generated module (solvers/generated/*.py) holds the solver's constants and the coefficient function
of its equations; the numerics live here, vectorised over a leading batch axis:

* data normalisation (divide by the RMS measurement) and the map of roots back to the data scale;
* evaluation of a polynomial system from its coefficient vector, Gauss-Newton polishing;
* :class:`CurvePencilSolver` (6r4s): the rank-2 condition on the compaction matrix makes the offsets a
  rational curve with an explicit linear parametrisation; on it, C2..C6 are linear in (H, b) and B2
  is quadratic, so the roots are the eigenvalues of an 11 x 11 quartic matrix polynomial (bordered
  matrix), solved by the QZ algorithm on its companion pencil;
* :class:`StagedSolver`: the legacy replay of a staged F4-trace template (kept as the fallback path).

Why not a single elimination template: see :mod:`solvers.template` (degree falls make the single
Macaulay template exceed thousands of rows; the staged replay amplifies rounding without bound).
Only numpy and scipy are used.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack

__all__ = [
    "CurvePencilSolver",
    "PolySystem",
    "StagedSolver",
    "data_scale",
    "load_solver",
    "polish",
    "solve_batch",
    "solve_one",
]


# --------------------------------------------------------------------------------------------------
# normalisation
# --------------------------------------------------------------------------------------------------


def data_scale(F: np.ndarray) -> np.ndarray:
    """Per-instance scale s = RMS of the measurements (batch,); data are divided by s before solving.

    A root of F / s maps back to F by h -> h / s^2, b -> b, o -> o * s (see solvers.codegen).
    """
    s = np.sqrt(np.mean(F * F, axis=(-2, -1)))
    return np.where(s > 0, s, 1.0)


def spec_path(module_file: str, name: str) -> str:
    return os.path.join(os.path.dirname(os.path.abspath(module_file)), name)


# --------------------------------------------------------------------------------------------------
# polynomial systems from coefficient vectors; Gauss-Newton polishing
# --------------------------------------------------------------------------------------------------


class PolySystem:
    """A polynomial system given by its term structure; values come from a coefficient vector.

    exps (T, n): exponents of the T terms; term_eq (T,): the equation of each term. Terms are grouped
    by distinct monomial so that residuals and Jacobians of k candidates of one instance are two small
    matrix products with the instance's (monomials x equations) coefficient matrix.
    """

    def __init__(self, exps: np.ndarray, term_eq: np.ndarray, n_eq: int):
        exps = np.asarray(exps, dtype=np.int64)
        self.n_eq, self.nvars = int(n_eq), exps.shape[1]
        mons, self.term_mon = np.unique(exps, axis=0, return_inverse=True)
        self.term_mon = self.term_mon.ravel()
        self.term_eq = np.asarray(term_eq, dtype=np.intp)
        # derivative d mon_m / d x_v = e_mv * x^(e_m - u_v): index into an extended monomial table
        lowered = [tuple(m - np.eye(self.nvars, dtype=np.int64)[v]) for m in mons for v in range(self.nvars)]
        table = {tuple(m): i for i, m in enumerate(mons)}
        for m in lowered:
            if min(m) >= 0 and m not in table:
                table[m] = len(table)
        ext = np.zeros((len(table), self.nvars), dtype=np.int64)
        for m, i in table.items():
            ext[i] = m
        self.ext = ext
        self.n_mon = len(mons)
        self.dfactor = np.array([[m[v] for v in range(self.nvars)] for m in mons], dtype=float)  # (M, n)
        self.didx = np.array([[table[tuple(m - np.eye(self.nvars, dtype=np.int64)[v])] if m[v] else 0
                               for v in range(self.nvars)] for m in mons], dtype=np.intp)
        self.max_exp = ext.max(axis=0)
        self._variables = np.arange(self.nvars)[None, :]

    def coefficient_matrix(self, coeffs: np.ndarray) -> np.ndarray:
        """(batch, M, n_eq) coefficient matrices from coefficient vectors (batch, T), rows scaled to unit norm."""
        C = np.zeros((coeffs.shape[0], self.n_mon, self.n_eq), dtype=coeffs.dtype)
        np.add.at(C, (slice(None), self.term_mon, self.term_eq), coeffs)
        norm = np.sqrt(np.sum(np.abs(C) ** 2, axis=1, keepdims=True))
        return C / np.where(norm > 0, norm, 1.0)

    def _ext_monomials(self, x: np.ndarray) -> np.ndarray:
        """x (..., n) -> values of the extended monomial table (..., E)."""
        top = int(self.max_exp.max())
        pw = np.concatenate([np.ones(x.shape + (1,), dtype=x.dtype), np.repeat(x[..., None], top, axis=-1)], axis=-1)
        pw = np.cumprod(pw, axis=-1)  # (..., n, top + 1): x_v^0 .. x_v^top
        return np.prod(pw[..., self._variables, self.ext], axis=-1)

    def residual_jacobian(self, x: np.ndarray, C: np.ndarray, jacobian: bool = True):
        """Residuals (B, k, n_eq) and Jacobians (B, k, n_eq, n) at x (B, k, n) with matrices C (B, M, n_eq)."""
        em = self._ext_monomials(x)
        f = em[..., : self.n_mon] @ C
        if not jacobian:
            return f, None
        dm = em[..., self.didx] * self.dfactor  # (B, k, M, n)
        B, k = x.shape[:2]
        J = np.swapaxes(dm.reshape(B, k, self.n_mon, self.nvars), 2, 3).reshape(B, k * self.nvars, self.n_mon) @ C
        return f, np.swapaxes(J.reshape(B, k, self.nvars, self.n_eq), 2, 3)


#: Candidates whose imaginary parts are below this (relative to their largest entry) are polished, as
#: real points; the others are not physical calibrations and are returned as computed.
POLISH_REAL_TOL = 1e-4


def polish(system: PolySystem, coeffs: np.ndarray, roots: np.ndarray, iterations: int = 1,
           real_tol: float = POLISH_REAL_TOL) -> np.ndarray:
    """Gauss-Newton steps on the (possibly overdetermined) input system for every near-real candidate.

    coeffs (batch, T) from the generated coefficient function, roots (batch, k, n). A candidate with
    max |Im x| <= real_tol * max |x| is replaced by its real part and polished in real arithmetic (the
    candidates of the whole batch in one stack); complex candidates are returned unchanged. Equations
    are scaled to unit coefficient norm; the step is the least-squares solution by QR. A candidate keeps
    its old value when it is not finite or when the step does not decrease its residual, so polishing
    never spoils an accurate root.
    """
    roots = np.asarray(roots)
    with np.errstate(all="ignore"):
        finite = np.all(np.isfinite(roots), axis=-1)
        scale = np.max(np.abs(np.where(finite[..., None], roots, 0.0)), axis=-1)
        near_real = finite & (np.max(np.abs(roots.imag), axis=-1) <= real_tol * scale)
    bi, ki = np.nonzero(near_real)
    if not len(bi):
        return roots
    C = system.coefficient_matrix(coeffs.real if np.iscomplexobj(coeffs) else coeffs)[bi]  # (P, M, n_eq)
    x = roots[bi, ki].real[:, None, :]  # (P, 1, n): one candidate per stack entry
    with np.errstate(all="ignore"):
        f, J = system.residual_jacobian(x, C)
        for it in range(iterations):
            ok = np.all(np.isfinite(J), axis=(2, 3)) & np.all(np.isfinite(f), axis=2)
            Jc = np.where(ok[..., None, None], J, np.eye(J.shape[2], J.shape[3]))
            q, r = np.linalg.qr(Jc)
            rhs = np.swapaxes(q, 2, 3) @ np.where(ok[..., None], f, 0.0)[..., None]
            try:
                step = np.linalg.solve(r, rhs)[..., 0]
            except np.linalg.LinAlgError:
                step = (np.linalg.pinv(r) @ rhs)[..., 0]
            xn = x - np.where(ok[..., None], step, 0.0)
            last = it == iterations - 1
            fn, Jn = system.residual_jacobian(xn, C, jacobian=not last)
            better = ok & np.all(np.isfinite(xn), axis=-1) & (np.linalg.norm(fn, axis=2) < np.linalg.norm(f, axis=2))
            x = np.where(better[..., None], xn, x)
            if not last:
                f = np.where(better[..., None], fn, f)
                J = np.where(better[..., None, None], Jn, J)
    out = roots.astype(complex)
    out[bi, ki] = x[:, 0]
    return out


# --------------------------------------------------------------------------------------------------
# 6r4s: rank-2 curve and bordered quartic pencil
# --------------------------------------------------------------------------------------------------


def compaction_pieces(F: np.ndarray):
    """The compaction matrix D~ = c + alpha o_1 + beta o_{j+1} of data F (..., m, n) and g_i = f_i1^2 - f_11^2.

    Returns c (..., m-1, n-1), alpha (..., m-1), beta (..., m-1, n-1), g (..., m-1); the differences
    of squares are formed as products (a - b)(a + b) to avoid cancellation.
    """
    d0 = F[..., 1:, :] - F[..., :1, :]
    s0 = F[..., 1:, :] + F[..., :1, :]
    sq = d0 * s0  # f_ij^2 - f_1j^2
    c = sq[..., 1:] - sq[..., :1]
    alpha = 2.0 * d0[..., 0]
    beta = -2.0 * d0[..., 1:]
    return c, alpha, beta, sq[..., 0]


#: Degree in nu of each column of the bordered matrix K (rows and columns: v = (1, h^, b^), then the
#: five multipliers of C2..C6): L and sigma are linear, X and Y quadratic, so the column of 1 has
#: degree 1, those of h^ degree 4 (X^2, XY, Y^2; E), those of b^ degree 2 (2X, 2Y; sigma w1) and the
#: multiplier columns (rows of C) degree 4. K is symmetric, so entry (a, b) has degree <= min(d_a, d_b).
PENCIL_COLUMN_DEGREES = (1, 4, 4, 4, 2, 2, 4, 4, 4, 4, 4)
#: Sample points of nu at which K is evaluated; its coefficients are their inverse DFT (unitary, so
#: no error amplification, unlike a real Vandermonde interpolation).
_NU_POINTS = np.exp(-2j * np.pi * np.arange(5) / 5)


class _ColumnDegreePencil:
    """Index arrays of the column-degree linearisation of an n x n matrix polynomial K(nu).

    States z_(j, k) = nu^k x_j for k < d_j (column degrees d_j): size N = sum d_j (37 for the 6r4s
    matrix, against 44 for the block companion form, which pads every column to degree 4 and adds 7
    more infinite eigenvalues). Rows: nu z_(j, k) = z_(j, k+1) for k < d_j - 1, then the n rows of
    sum_(j, k < d_j) K_k[:, j] z_(j, k) + nu sum_j K_(d_j)[:, j] z_(j, d_j - 1) = 0, i.e. A z = nu B z.
    The pencil has N - deg det K infinite eigenvalues.
    """

    def __init__(self, degrees: tuple[int, ...]):
        self.degrees = np.asarray(degrees, dtype=np.intp)
        n = len(degrees)
        states = [(j, k) for j in range(n) for k in range(degrees[j])]
        index = {s: i for i, s in enumerate(states)}
        self.size = len(states)
        self.n_shift = self.size - n
        self.A0 = np.zeros((self.size, self.size))
        self.B0 = np.zeros((self.size, self.size))
        row = 0
        for j in range(n):
            for k in range(degrees[j] - 1):
                self.A0[row, index[(j, k + 1)]] = 1.0
                self.B0[row, index[(j, k)]] = 1.0
                row += 1
        self.k_of_state = np.array([k for _, k in states], dtype=np.intp)
        self.j_of_state = np.array([j for j, _ in states], dtype=np.intp)
        self.first = np.array([index[(j, 0)] for j in range(n)], dtype=np.intp)
        self.top = np.array([index[(j, degrees[j] - 1)] for j in range(n)], dtype=np.intp)
        self.columns = np.arange(n)
        self.mask = (np.arange(int(max(degrees)) + 1)[:, None, None]
                     <= np.minimum(self.degrees[:, None], self.degrees[None, :])[None])

    def pencil(self, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(A, B) for the coefficients K (degree + 1, n, n) of one instance."""
        A, B = self.A0.copy(), self.B0.copy()
        A[self.n_shift:] = -K[self.k_of_state, :, self.j_of_state].T
        B[self.n_shift:, self.top] = K[self.degrees, :, self.columns].T
        return A, B

    def eigenvector_heads(self, V: np.ndarray, nu: np.ndarray) -> np.ndarray:
        """x (n, k) from pencil eigenvectors V (N, k): z_(j,0), or z_(j, d_j-1) / nu^(d_j-1) when |nu| > 1."""
        top = V[self.top] / nu[None] ** (self.degrees[:, None] - 1)
        return np.where(np.abs(nu)[None] > 1.0, top, V[self.first])


class CurvePencilSolver:
    """6r4s solver (formulation B2, C2-C6 and the ten 3 x 3 minors): rank-2 curve + bordered pencil.

    Offsets: rank D~ = 2 iff D~ w = 0 for some w, i.e. sum_j w_j c_j + alpha (o_1 sum w) +
    sum_j beta_j (o_{j+1} w_j) = 0: the vector (w, s = o_1 sum w, u_j = o_{j+1} w_j) lies in the 2-dim
    kernel of G = [c | alpha | beta] (5 x 7), so every o_j is a Moebius function of one projective
    parameter (lambda, mu) (the offsets lie on a rational curve), with o_1 = s/sigma (sigma = sum w),
    o_{j+1} = u_j/w_j. On the curve, with the scaled unknowns h11 = sigma w1^2 h^11,
    h12 = sigma w1 w2 h^12, h22 = sigma w2^2 h^22, b1 = w1 b^1, b2 = w2 b^2, the equations C2..C6
    become C(nu) v = 0 (5 x 6, v = (1, h^, b^)) and B2 becomes v^T Q(nu) v = 0, both polynomial
    (degree <= 4) in the chart parameter nu. With C of full row rank, v^T Q v = 0 on ker C iff the
    bordered matrix K(nu) = [[Q, C^T], [C, 0]] (11 x 11) is singular, so the roots are the
    eigenvalues of a quartic matrix polynomial, and its eigenvectors carry v.

    Numerics: K is evaluated at five points on the unit circle and its coefficients recovered by an
    inverse DFT; the column-degree linearisation (:class:`_ColumnDegreePencil`, 37 x 37; spec
    ``linearisation``) is solved by LAPACK dggev (QZ: no inversion of an ill-conditioned
    coefficient). det K has degree 30 = 22 roots + sigma^8 (o_1 = infinity); the other 7 eigenvalues
    are infinite. Both kinds of spurious eigenvalues are dropped by count (spec: ``drop_infinite``,
    ``drop_sigma``). Each kept eigenvalue gets one Newton step on the symmetric eigen-equation,
    nu <- nu - x^T K(nu) x / x^T K'(nu) x (K symmetric: x is also the left eigenvector), which brings
    the offsets back to the accuracy of the 44 x 44 block companion form.

    Eigenvalue sensitivity does not depend on the separation between eigenvalues, which is why this
    is robust where the scalar eliminant (the same 22 roots as a univariate polynomial) is not: roots
    whose o_1 nearly coincide are separated by (H, b).
    """

    def __init__(self, spec: dict):
        self.spec = spec
        p = spec["pencil"]
        self.phi = float(p["chart_angle"])
        self.drop_infinite = int(p["drop_infinite"])
        self.drop_sigma = int(p["drop_sigma"])
        self.basis_size = int(spec["degree"])
        self.nvars = len(spec["unknowns"])
        self.linearisation = _ColumnDegreePencil(tuple(p["column_degrees"]))

    # polynomial matrix ---------------------------------------------------------------------------
    def matrix_polynomial(self, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """K (batch, 5, 11, 11) (coefficients of nu^0..nu^4) and the linear forms (batch, 7, 2)."""
        B = F.shape[0]
        c, alpha, beta, g = compaction_pieces(F)
        G = np.concatenate([c, alpha[..., None], beta], axis=-1)  # (B, 5, 7)
        N = np.linalg.svd(G)[2][:, -2:, :].transpose(0, 2, 1)  # (B, 7, 2)
        cs, sn = np.cos(self.phi), np.sin(self.phi)
        # (lambda, mu) = nu (cos, sin) + (-sin, cos): each form is const + slope * nu
        forms = np.stack([-N[..., 0] * sn + N[..., 1] * cs, N[..., 0] * cs + N[..., 1] * sn], axis=-1)
        fv = forms[..., :1] + forms[..., 1:] * _NU_POINTS  # (B, 7, 5): the forms at the sample points
        w1, w2, w3, s, u1, u2, u3 = (fv[:, k] for k in range(7))
        sig = w1 + w2 + w3
        sw1, sw2 = sig * w1, sig * w2
        row = lambda v: v[:, None, :]  # noqa: E731  (B, 5 points) -> (B, 1, 5)
        X = row(sw1) * c[:, :, 0, None] + row(s * w1) * alpha[..., None] + row(u1 * sig) * beta[:, :, 0, None]
        Y = row(sw2) * c[:, :, 1, None] + row(s * w2) * alpha[..., None] + row(u2 * sig) * beta[:, :, 1, None]
        L = row(sig) * g[..., None] - row(s) * alpha[..., None]
        a = F[:, 0, 1][:, None] * w1 - u1
        b = F[:, 0, 0][:, None] * sig - s
        E = (a * a) * (sig * sig) - (b * b) * (w1 * w1)
        Cm = np.moveaxis(np.stack([L, -X * X, -2.0 * X * Y, -Y * Y, 2.0 * X, 2.0 * Y], axis=2), -1, 1)  # (B, 5, 5, 6)
        K = np.zeros((B, 5, 11, 11), dtype=complex)
        K[:, :, 1, 3] = K[:, :, 3, 1] = 0.5 * E
        K[:, :, 2, 2] = -E
        K[:, :, 0, 3] = K[:, :, 3, 0] = -sig / 8.0
        K[:, :, 4, 3] = K[:, :, 3, 4] = 0.5 * sw1
        K[:, :, 5, 2] = K[:, :, 2, 5] = -0.5 * sw1
        K[:, :, :6, 6:] = np.swapaxes(Cm, 2, 3)
        K[:, :, 6:, :6] = Cm
        return np.fft.ifft(K, axis=1).real * self.linearisation.mask, forms

    def roots(self, F: np.ndarray) -> np.ndarray:
        """Candidate roots (batch, 22, 9), complex, of the normalised data F (batch, 6, 4)."""
        K, forms = self.matrix_polynomial(F)
        lin = self.linearisation
        B = K.shape[0]
        powers = np.arange(K.shape[1])
        keep_n = lin.size - self.drop_infinite
        out = np.full((B, self.basis_size, self.nvars), np.nan + 0j)
        for i in range(B):
            A, Bm = lin.pencil(K[i])
            if not (np.all(np.isfinite(A)) and np.all(np.isfinite(Bm))):
                continue
            ar, ai, be, _, vr, _, info = lapack.dggev(A, Bm, compute_vl=0, compute_vr=1)
            if info != 0:
                continue
            al = ar + 1j * ai
            # infinite eigenvalues: smallest |beta| / |alpha|
            order = np.argsort(-np.abs(be) / np.maximum(np.abs(al), 1e-300), kind="stable")[:keep_n]
            with np.errstate(all="ignore"):
                f = forms[i]
                forms_at = lambda nu: f[:, 1:] * nu[None] + f[:, :1]  # noqa: E731  forms at (nu, 1): (7, k)
                nu = al[order] / be[order]
                fv = forms_at(nu)
                sig = fv[0] + fv[1] + fv[2]
                # o_1 = infinity: sigma = 0 (relative to |(nu, 1)|)
                sel = np.argsort(-np.abs(sig) / np.sqrt(1.0 + np.abs(nu) ** 2), kind="stable")
                sel = sel[: min(self.basis_size, len(sel) - self.drop_sigma)]
                nu, fv, sig = nu[sel], fv[:, sel], sig[sel]
                x = lin.eigenvector_heads(_complex_eigenvectors(vr, ai, order[sel]), nu)  # (11, k)
                # H, b from the eigenvector, with the scalings at the eigenvalue it belongs to
                w1, w2 = fv[0], fv[1]
                v = x[:6] / x[:1]
                # one Newton step on x^T K(nu) x = 0 for the offsets
                q = np.einsum("akc,ac->kc", (K[i] @ x).transpose(1, 0, 2), x)  # x^T K_k x: (5, k)
                value = np.sum(q * nu[None] ** powers[:, None], axis=0)
                slope = np.sum(q[1:] * powers[1:, None] * nu[None] ** (powers[1:, None] - 1), axis=0)
                nu = nu - value / slope
                fn = forms_at(nu)
                h = np.stack([sig * w1**2 * v[1], sig * w1 * w2 * v[2], sig * w2**2 * v[3], w1 * v[4], w2 * v[5],
                              fn[3] / (fn[0] + fn[1] + fn[2]), fn[4] / fn[0], fn[5] / fn[1], fn[6] / fn[2]], axis=-1)
            out[i, : len(sel)] = h
        return out


def _complex_eigenvectors(vr: np.ndarray, ai: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """LAPACK real storage of eigenvectors (conjugate pairs as re, im columns) -> the complex columns wanted.

    LAPACK stores a pair at consecutive columns j, j+1 with the positive imaginary part first:
    v_j = vr_j + i vr_(j+1), v_(j+1) = vr_j - i vr_(j+1).
    """
    cols = np.asarray(columns)
    a = ai[cols]
    first, second = a > 0, a < 0
    re = vr[:, np.where(second, cols - 1, cols)]
    im = vr[:, np.where(first, np.minimum(cols + 1, len(ai) - 1), cols)]
    return re + 1j * np.where(first, 1.0, np.where(second, -1.0, 0.0)) * im


# --------------------------------------------------------------------------------------------------
# legacy: replay of a staged F4-trace template (fallback path, not used by the generated solvers)
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Step:
    nrows: int
    ncols: int
    fill_row: np.ndarray
    fill_col: np.ndarray
    fill_src: np.ndarray
    pivots: np.ndarray
    reduce: np.ndarray
    pivot_cols: np.ndarray
    free_cols: np.ndarray
    lead_in_free: np.ndarray
    new_row: np.ndarray
    new_col: np.ndarray
    new_dst: np.ndarray


class StagedSolver:
    """Numeric replay of a staged elimination template spec (see :func:`solvers.template.build_template`).

    Kept as the fallback: in floating point the ~10 chained eliminations with pivots fixed by the
    GF(p) trace amplify the rounding of the coefficients without bound (tables/solvers.csv history).
    """

    def __init__(self, spec: dict):
        self.spec = spec
        self.unknowns = tuple(spec["unknowns"])
        self.nvars = len(self.unknowns)
        mons = [tuple(m) for m in spec["monomials"]]
        self._mons = mons
        polys = spec["polys"]
        lengths = np.array([len(s) for s in polys], dtype=np.int64)
        self._offsets = np.concatenate([[0], np.cumsum(lengths)])
        self.table_size = int(self._offsets[-1])
        self.n_inputs = len(spec["inputs"])
        self.n_input_coeffs = int(self._offsets[self.n_inputs])

        def add(a: int, b: int) -> tuple:
            return tuple(x + y for x, y in zip(mons[a], mons[b]))

        def fill(rows, columns):
            pos = {mons[c]: j for j, c in enumerate(columns)}
            fr, fc, fs = [], [], []
            for r, (pid, shift) in enumerate(rows):
                off = int(self._offsets[pid])
                for k, m in enumerate(polys[pid]):
                    fr.append(r)
                    fc.append(pos[add(m, shift)])
                    fs.append(off + k)
            return (np.array(fr, dtype=np.intp), np.array(fc, dtype=np.intp), np.array(fs, dtype=np.intp))

        self.steps: list[_Step] = []
        for st in spec["steps"]:
            fr, fc, fs = fill(st["rows"], st["columns"])
            ncols = len(st["columns"])
            pivots = np.array(st["pivots"], dtype=np.intp)
            pcols = (np.array([fc[np.flatnonzero(fr == r)].min() for r in pivots], dtype=np.intp)
                     if len(pivots) else np.zeros(0, np.intp))
            free = np.setdiff1d(np.arange(ncols), pcols)
            free_pos = {int(c): i for i, c in enumerate(free)}
            leads = [free_pos[nw[1]] for nw in st["new"]]
            nr, nc, nd = [], [], []
            for hh, (pid, _, support) in enumerate(st["new"]):
                off = int(self._offsets[pid])
                for k, c in enumerate(support):
                    nr.append(hh)
                    nc.append(free_pos[c])
                    nd.append(off + k)
            self.steps.append(_Step(len(st["rows"]), ncols, fr, fc, fs, pivots,
                                    np.array(st["reduce"], dtype=np.intp), pcols, free,
                                    np.array(leads, dtype=np.intp), np.array(nr, dtype=np.intp),
                                    np.array(nc, dtype=np.intp), np.array(nd, dtype=np.intp)))
        final = spec["final"]
        self._final_fill = fill(final["rows"], final["columns"])
        self._final_shape = (len(final["rows"]), len(final["columns"]))
        self._n_lead = final["n_lead"]
        basis = spec["basis"]
        self.basis_size = len(basis)
        bpos = {mons[b]: j for j, b in enumerate(basis)}
        self._std_cols = np.array([bpos[mons[c]] for c in final["columns"][self._n_lead:]], dtype=np.intp)
        target_row = {mons[m]: t for m, t in zip(final["target_monomials"], final["targets"])}
        a = self.unknowns.index(spec["action"])
        unit = tuple(int(i == a) for i in range(self.nvars))
        ur, uc, rr, rt = [], [], [], []
        for j, b in enumerate(basis):
            m = tuple(x + y for x, y in zip(mons[b], unit))
            if m in bpos:
                ur.append(j)
                uc.append(bpos[m])
            else:
                rr.append(j)
                rt.append(target_row[m])
        self._unit = (np.array(ur, dtype=np.intp), np.array(uc, dtype=np.intp))
        self._red = (np.array(rr, dtype=np.intp), np.array(rt, dtype=np.intp))
        zero = (0,) * self.nvars
        if zero not in bpos:
            raise ValueError("the standard monomial basis must contain 1")
        self._one = bpos[zero]
        self._read_basis, self._read_target = [], []
        for i in range(self.nvars):
            m = tuple(int(k == i) for k in range(self.nvars))
            if m in bpos:
                self._read_basis.append((i, bpos[m]))
            else:
                self._read_target.append((i, target_row[m]))

    def _action_matrices(self, coeffs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        batch = coeffs.shape[0]
        V = np.zeros((batch, self.table_size))
        V[:, : self.n_input_coeffs] = coeffs
        for st in self.steps:
            A = np.zeros((batch, st.nrows, st.ncols))
            A[:, st.fill_row, st.fill_col] = V[:, st.fill_src]
            Q = A[:, st.reduce]
            if len(st.pivots):
                P = A[:, st.pivots]
                X = np.linalg.solve(np.swapaxes(P[:, :, st.pivot_cols], 1, 2),
                                    np.swapaxes(Q[:, :, st.pivot_cols], 1, 2))
                Qf = Q[:, :, st.free_cols] - np.swapaxes(X, 1, 2) @ P[:, :, st.free_cols]
            else:
                Qf = Q
            q, r = np.linalg.qr(Qf[:, :, st.lead_in_free])
            H = np.linalg.solve(r, np.swapaxes(q, 1, 2) @ Qf)
            V[:, st.new_dst] = H[:, st.new_row, st.new_col]
        fr, fc, fs = self._final_fill
        A = np.zeros((batch,) + self._final_shape)
        A[:, fr, fc] = V[:, fs]
        n = self._n_lead
        Y = np.linalg.solve(A[:, :, :n], A[:, :, n:])
        M = np.zeros((batch, self.basis_size, self.basis_size))
        M[:, self._unit[0], self._unit[1]] = 1.0
        rr, rt = self._red
        block = np.zeros((batch, len(rr), self.basis_size))
        block[:, :, self._std_cols] = -Y[:, rt]
        M[:, rr] = block
        return M, Y

    def roots_from_coefficients(self, coeffs: np.ndarray) -> np.ndarray:
        """Candidate roots (batch, |B|, nvars) from input coefficients (batch, n_input_coeffs)."""
        with np.errstate(all="ignore"):
            try:
                M, Y = self._action_matrices(coeffs)
            except np.linalg.LinAlgError:
                if coeffs.shape[0] > 1:
                    return np.concatenate([self.roots_from_coefficients(coeffs[i : i + 1])
                                           for i in range(coeffs.shape[0])])
                return np.full((1, self.basis_size, self.nvars), np.nan + 0j)
            bad = ~np.all(np.isfinite(M), axis=(1, 2))
            M[bad] = 0.0
            _, vecs = np.linalg.eig(M)
            one = vecs[:, self._one, :]
            out = np.empty((coeffs.shape[0], self.basis_size, self.nvars), dtype=complex)
            for i, j in self._read_basis:
                out[:, :, i] = vecs[:, j, :] / one
            for i, t in self._read_target:
                nf = np.zeros((coeffs.shape[0], self.basis_size))
                nf[:, self._std_cols] = -Y[:, t]
                out[:, :, i] = np.einsum("bk,bks->bs", nf, vecs) / one
            out[bad] = np.nan
        return out


# --------------------------------------------------------------------------------------------------
# module glue
# --------------------------------------------------------------------------------------------------


class _Solver:
    """A solver kernel with the term structure of its input equations (for polishing)."""

    def __init__(self, spec: dict, scale_powers: tuple[float, ...]):
        self.spec = spec
        kind = spec.get("kind", "staged")
        if kind == "curve-pencil":
            self.kernel = CurvePencilSolver(spec)
        elif kind == "staged":
            self.kernel = StagedSolver(spec)
        else:
            raise ValueError(f"unknown solver kind {kind!r}; valid: curve-pencil, staged (homotopy: solvers.methods)")
        self.kind = kind
        self.basis_size = self.kernel.basis_size
        self.nvars = len(spec["unknowns"])
        self.scale_powers = np.asarray(scale_powers, dtype=float)
        mons = [tuple(m) for m in spec["monomials"]]
        term_exps = np.array([mons[m] for eq in spec["inputs"] for m in eq], dtype=np.int64)
        term_eq = np.concatenate([np.full(len(eq), i) for i, eq in enumerate(spec["inputs"])])
        self.system = PolySystem(term_exps, term_eq, len(spec["inputs"]))

    def roots(self, Fn: np.ndarray, coeffs: np.ndarray) -> np.ndarray:
        if self.kind == "staged":
            return self.kernel.roots_from_coefficients(coeffs)
        return self.kernel.roots(Fn)


def load_solver(json_path: str, scale_powers: tuple[float, ...]) -> _Solver:
    """Read a spec next to a generated module and build its solver (precomputed once per process)."""
    with open(json_path, encoding="utf-8") as fh:
        spec = json.load(fh)
    return _Solver(spec, scale_powers)


#: Instances per chunk in batched solves (bounds the memory of the per-instance matrices).
CHUNK = 64


def _check_data(F: np.ndarray, config: tuple[int, int]) -> np.ndarray:
    F = np.asarray(F, dtype=float)
    if F.shape[-2:] != tuple(config):
        raise ValueError(f"data must have shape (..., {config[0]}, {config[1]}), got {F.shape}")
    return F


def _coefficients(coefficients, Fn: np.ndarray) -> np.ndarray:
    """Coefficient vectors (batch, T); one instance runs on Python floats (much faster than 1-arrays)."""
    if len(Fn) == 1:
        return np.array(coefficients(tuple(Fn[0].ravel().tolist())), dtype=float)[None]
    cols = Fn.reshape(len(Fn), -1).T
    values = coefficients(tuple(cols))
    out = np.empty((len(Fn), len(values)))
    for j, v in enumerate(values):
        out[:, j] = v
    return out


def _solve_chunk(solver: _Solver, coefficients, block: np.ndarray, polish_iterations: int) -> np.ndarray:
    s = data_scale(block)
    Fn = block / s[:, None, None]
    coeffs = _coefficients(coefficients, Fn)
    with np.errstate(all="ignore"):
        roots = solver.roots(Fn, coeffs)
        if polish_iterations:
            roots = polish(solver.system, coeffs, roots, polish_iterations)
        return roots * (s[:, None, None] ** solver.scale_powers[None, None, :])


def solve_one(solver: _Solver, coefficients, F: np.ndarray, config: tuple[int, int],
              polish_iterations: int) -> np.ndarray:
    """Candidate roots (k, nvars) for one data matrix."""
    F = _check_data(F, config)
    if F.ndim != 2:
        raise ValueError(f"solve takes one ({config[0]}, {config[1]}) matrix; use solve_batch for {F.shape}")
    return _solve_chunk(solver, coefficients, F[None], polish_iterations)[0]


def solve_batch(solver: _Solver, coefficients, F: np.ndarray, config: tuple[int, int],
                polish_iterations: int) -> np.ndarray:
    """Candidate roots (..., k, nvars) for data (..., m, n)."""
    F = _check_data(F, config)
    lead = F.shape[:-2]
    flat = F.reshape((-1,) + tuple(config))
    out = np.empty((len(flat), solver.basis_size, solver.nvars), dtype=complex)
    for start in range(0, len(flat), CHUNK):
        out[start : start + CHUNK] = _solve_chunk(solver, coefficients, flat[start : start + CHUNK], polish_iterations)
    return out.reshape(lead + out.shape[1:])

