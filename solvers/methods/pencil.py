"""Eigenvalue pencil (6r4s): offline build of its spec and online kernel side by side.

Formulation B2, C2-C6 and the ten 3 x 3 minors of the compaction matrix (paper Section 3.2). The
minors make the offsets a rational curve, parametrised linearly by the kernel of [c | alpha | beta];
on it the roots are the eigenvalues of an 11 x 11 quartic matrix polynomial (:class:`CurvePencilSolver`).

Offline (:func:`build`): the GF(p) degree (22), then the spec (``curve-pencil``: the chart and the
number of spurious eigenvalues to drop), both checked on seeded real networks.
Online (:class:`CurvePencilSolver`): the bordered matrix polynomial of the data, its column-degree
linearisation (37 x 37) solved by QZ, the spurious eigenvalues dropped by count. Generated modules
reach it through :func:`solvers.runtime.load_solver`; the online part needs only numpy and scipy
(the exact algebra of the build is imported by :func:`build` alone). This module imports nothing
of :mod:`solvers.runtime` or :mod:`solvers.generate` (they import it): no import circle.
"""
from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np
from scipy.linalg import lapack

if TYPE_CHECKING:  # the online kernel needs neither sympy nor the exact algebra
    from analysis.formulations.tdoa import Formulation

    from .spec import TemplateOptions, TemplateResult

__all__ = ["PENCIL_COLUMN_DEGREES", "CurvePencilSolver", "build", "compaction_pieces"]


# --------------------------------------------------------------------------------------------------
# offline: the spec, checked on seeded real networks
# --------------------------------------------------------------------------------------------------


def _real_trials(formulation: Formulation, trials: int) -> tuple[np.ndarray, np.ndarray]:
    """Seeded noiseless networks (seeds 0..trials-1): normalised data and the root in that frame."""
    from ..synthetic import random_network, true_root

    m, n = formulation.config.m, formulation.config.n
    F, X = [], []
    for seed in range(trials):
        net = random_network(m, n, np.random.default_rng(seed))
        H, b, o = true_root(net)
        F.append(net.measurements())
        X.append(np.concatenate([[H[0, 0], H[0, 1], H[1, 1]], b, o]))
    F, X = np.array(F), np.array(X)
    s = np.sqrt(np.mean(F * F, axis=(1, 2)))  # the generated module's normalisation (solvers.runtime.data_scale)
    powers = np.array([-2.0] * 3 + [0.0] * 2 + [1.0] * n)
    return F / s[:, None, None], X / s[:, None] ** powers


def _found(roots: np.ndarray, truth: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    err = np.nanmin(np.linalg.norm(roots - truth[:, None, :], axis=2), axis=1) / np.linalg.norm(truth, axis=1)
    return err < tol


def build(formulation: Formulation | str, options: TemplateOptions | None = None) -> TemplateResult:
    """Spec of the rank-2-curve pencil solver (:class:`CurvePencilSolver`).

    Checks: the GF(p) degree is 22; on ``options.verify_trials`` seeded real networks the
    column-degree pencil (37 x 37, :data:`PENCIL_COLUMN_DEGREES`) has exactly 7 eigenvalues with
    beta ~ 0 (a gap of three orders of magnitude to the next) and eight with sigma ~ 0
    (o_1 = infinity), and the remaining 22 contain the known root.
    """
    from scipy.linalg import eigvals

    from analysis.formulations.tdoa import as_formulation

    from .spec import TemplateError, TemplateOptions, TemplateResult, common_spec, gf_degree, solver_method

    t0 = time.perf_counter()
    options = options or TemplateOptions()
    formulation = as_formulation(formulation)
    if solver_method(formulation) != "curve-pencil":
        raise TemplateError(f"{formulation.label}: the curve pencil needs 6r4s with B2, C2-C6 and the 10 minors")
    degree = gf_degree(formulation, options)
    size = sum(PENCIL_COLUMN_DEGREES)
    det_degree = degree + 8  # sigma^8: the C rows degenerate where o_1 = infinity
    spec = common_spec(formulation, options, "curve-pencil", degree)
    spec["size"] = [size, size]
    spec["pencil"] = {"chart_angle": options.chart_angle, "matrix": [11, 11], "polynomial_degree": 4,
                      "linearisation": "column-degree", "column_degrees": list(PENCIL_COLUMN_DEGREES),
                      "drop_infinite": size - det_degree, "drop_sigma": det_degree - degree}
    solver = CurvePencilSolver(spec)
    F, X = _real_trials(formulation, options.verify_trials)
    K, _ = solver.matrix_polynomial(F)
    for i in range(len(F)):
        tops = K[i][list(PENCIL_COLUMN_DEGREES), :, range(11)]
        if np.min(np.max(np.abs(tops), axis=1)) < 1e-8 * np.max(np.abs(K[i])):
            raise TemplateError(f"trial {i}: a column of K is below its stated degree {PENCIL_COLUMN_DEGREES}")
        al, be = eigvals(*solver.linearisation.pencil(K[i]), homogeneous_eigvals=True)
        ratio = np.sort(np.abs(be) / np.maximum(np.abs(al), 1e-300))
        k = spec["pencil"]["drop_infinite"]
        # Jordan chains at infinity: those eigenvalues come out near sqrt(eps), hence a gap of 1e3
        if not (ratio[k - 1] < 1e-3 * ratio[k]):
            raise TemplateError(f"trial {i}: expected {k} infinite eigenvalues, beta/alpha ratios {ratio[:k + 2]}")
    found = _found(solver.roots(F), X)
    if found.mean() < 0.9:
        raise TemplateError(f"the pencil finds the known root in only {found.sum()}/{len(found)} seeded networks")
    return TemplateResult(spec, time.perf_counter() - t0, ({"method": "curve-pencil", "degree": degree,
                                                            "verified": int(found.sum()), "trials": len(found)},))


# --------------------------------------------------------------------------------------------------
# online: rank-2 curve and bordered quartic pencil
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

