"""Action-matrix solver with an elimination template: offline build over GF(p), online kernel.

Method ``action-matrix`` (Kukelova-Bujnak-Pajdla's automatic generator; Larsson et al., "Efficient
solvers for minimal problems by syzygy-based reduction", CVPR 2017, and "Upgrade methods for
stratified sensor network self-calibration", ICASSP 2020, for TOA). For a square parametric system
(:class:`analysis.formulations.parametric.ParametricSystem`) with linear equations and one
non-vanishing condition (det H):

1. *Linear equations out.* The equations of total degree 1 (TOA's C_i in (H, b)) are solved: the
   unknowns are x = x0 + N y on their solution set (N: a basis of the kernel, y: k free coordinates).
   The other equations become dense polynomials g_i(y) (:class:`Composer`).
2. *Template* (offline, exact over GF(p), :func:`build_template`): on a random consistent instance, the
   grevlex basis of the g_i (the project's F4) gives the standard monomials B. The g_i are not
   saturated by det H: |B| may exceed the certified count, by roots on det H = 0 that must be isolated
   (2D TOA: the one point H = 0); :func:`build` checks that t det H - 1 added gives exactly the
   certified count. For the action variable y_a, R = y_a B minus B. Monomial multiples of the g_i are
   added degree by degree (a Macaulay-type template) until the row space expresses every monomial of R
   by B modulo the other ("excess") monomials E: rank [E R] = rank E + |R|. Then rows are removed
   while this holds (greedy, in halving chunks, largest multiples first). The template is checked on
   a second instance and on a second prime (same supports, same excess columns, same rank condition).
   Only a maximal independent set of the excess columns is kept (:func:`_square`): the others lie in
   their span, so the relations are the same, and [E R] becomes square when the rows are minimal.
3. *Online* (:class:`ActionMatrixSolver`, numpy/scipy only): the coefficients of the data, the kernel of
   the linear equations by SVD (orthonormal N), the g_i(y) by products of linear forms (a vectorised
   tensor expansion), the template filled (rows scaled to unit norm), R in terms of B by one LU solve
   of the square [E R] block (else: the left kernel of the excess block by pivoted QR, its rank known
   from GF(p), then a solve), the
   |B| x |B| action matrix, eig, y_j = v[y_j] / v[1] from the eigenvectors, the |B| - degree
   candidates with the smallest |det H| dropped, Newton steps on g(y) = 0, x = x0 + N y.

The exact algebra (F4, flint) is imported by the offline build alone.
"""
from __future__ import annotations

import itertools
import time
from dataclasses import dataclass

import numpy as np

from .common import load_format, verify_found

__all__ = ["SPEC_FORMAT", "ActionMatrixError", "ActionMatrixSolver", "Composer", "Template", "build", "build_template",
           "extended_system", "load_spec", "solve_scaled", "verify"]

SPEC_FORMAT = "tdoa-action-matrix/1"

#: Newton steps on g(y) = 0 after the eigensolve, at most (written into the spec). 2D TOA 3r/3s, 1000 room
#: networks, true root within 1e-6, QR elimination of the 44 x 56 template: 986 with 1 step, 990 with 2,
#: 993 with 4 and with 8; the square 44 x 53 template (LU) with 4: 991.
NEWTON_STEPS = 4


class ActionMatrixError(RuntimeError):
    """The template could not be built, or failed its check on a second instance or prime."""


# --------------------------------------------------------------------------------------------------
# composition f(x0 + N y): one code path for GF(p) (int64) and floats
# --------------------------------------------------------------------------------------------------


class Composer:
    """Coefficients of polynomials f_i(x) after the affine substitution x = x0 + N y.

    exps (T, n): exponents of the terms; term_eq (T,): the polynomial of each term (n_eq of them).
    Every term of total degree <= d is a product of d entries of x^ = (1, x) (index 0 is 1), and
    x^ = M y^ with y^ = (1, y), M = [[1, 0], [x0, N]] ((n+1) x (k+1)). The product of d linear forms is
    an outer-product tensor ((k+1)^d entries), summed into the monomials of y (degree <= d) by a fixed
    0/1 matrix. Output columns: the monomials of y, in :attr:`monomials` order (exponent tuples).
    """

    def __init__(self, exps: np.ndarray, term_eq: np.ndarray, n_eq: int, k: int):
        exps = np.asarray(exps, dtype=np.int64)
        self.n_eq, self.k = int(n_eq), int(k)
        self.d = int(exps.sum(axis=1).max()) if len(exps) else 0
        self.term_eq = np.asarray(term_eq, dtype=np.intp)
        idx = np.zeros((len(exps), self.d), dtype=np.intp)
        for t, e in enumerate(exps):
            factors = [v + 1 for v in range(exps.shape[1]) for _ in range(int(e[v]))]
            idx[t, : len(factors)] = factors
        self.factor_index = idx
        cells = list(itertools.product(range(k + 1), repeat=self.d))
        mons = sorted({tuple(int(sum(1 for c in cell if c == j + 1)) for j in range(k)) for cell in cells},
                      key=lambda e: (sum(e), e))
        self.monomials = mons
        where = {m: i for i, m in enumerate(mons)}
        self.cell_monomial = np.array([where[tuple(sum(1 for c in cell if c == j + 1) for j in range(k))]
                                       for cell in cells], dtype=np.intp)
        self.gather = np.zeros(((k + 1) ** self.d, len(mons)))
        self.gather[np.arange(len(cells)), self.cell_monomial] = 1.0
        self.select = np.zeros((self.n_eq, len(exps)))
        self.select[self.term_eq, np.arange(len(exps))] = 1.0

    def compose(self, coeffs: np.ndarray, M: np.ndarray, p: int | None = None) -> np.ndarray:
        """(n_eq, monomials) coefficients in y of the polynomials with term coefficients ``coeffs`` (T,).

        p: a prime for exact int64 arithmetic mod p (inputs reduced mod p), None for floats/complex.
        """
        L = M[self.factor_index]  # (T, d, k+1)
        T = L.shape[0]
        prod = L[:, 0, :]
        for j in range(1, self.d):
            prod = (prod[:, :, None] * L[:, j, None, :]).reshape(T, -1)
            if p is not None:
                prod %= p
        if p is None:
            return (self.select * coeffs[None, :]) @ prod @ self.gather
        weighted = (np.asarray(coeffs, dtype=np.int64)[:, None] * prod) % p
        out = np.zeros((self.n_eq, len(self.monomials)), dtype=np.int64)
        for e in range(self.n_eq):
            tensor = weighted[self.term_eq == e].sum(axis=0) % p
            np.add.at(out[e], self.cell_monomial, tensor)
        return out % p


# --------------------------------------------------------------------------------------------------
# offline: the instance in y over GF(p), the template
# --------------------------------------------------------------------------------------------------


def _kernel_mod(A: list[list[int]], p: int) -> tuple[list[int], list[list[int]]]:
    """(particular solution, kernel basis) of A [1; x] = 0 over GF(p): A (l x (n + 1)), column 0 the constants.

    The reduced row echelon form is FLINT's (``nmod_mat.rref``), of [A_x | A_1] with the constants last so
    that they never take a pivot of a consistent system."""
    import flint

    n = len(A[0]) - 1
    M = flint.nmod_mat(len(A), n + 1, [int(v) % p for r in A for v in (*r[1:], r[0])], p)
    R, rank = M.rref()
    pivots = [next(c for c in range(n + 1) if int(R[i, c])) for i in range(rank)]
    if n in pivots:
        raise ValueError("the linear equations of the instance are inconsistent over GF(p)")
    x0 = [0] * n
    for i, c in enumerate(pivots):
        x0[c] = -int(R[i, n]) % p
    basis = []
    for f in (c for c in range(n) if c not in pivots):
        v = [0] * n
        v[f] = 1
        for i, c in enumerate(pivots):
            v[c] = -int(R[i, f]) % p
        basis.append(v)
    return x0, basis


@dataclass(frozen=True)
class Structure:
    """Which equations are linear (eliminated), which are nonlinear, the saturation factor's rows."""

    linear: tuple[int, ...]
    nonlinear: tuple[int, ...]
    saturation: tuple[int, ...]


def _structure(exps: np.ndarray, term_eq: np.ndarray, n_eq: int, n_saturation: int) -> Structure:
    degree = np.zeros(n_eq, dtype=np.int64)
    np.maximum.at(degree, term_eq, exps.sum(axis=1))
    square = n_eq - n_saturation
    return Structure(tuple(i for i in range(square) if degree[i] <= 1), tuple(i for i in range(square) if degree[i] > 1),
                     tuple(range(square, n_eq)))


def _gf_instance(extended, structure: Structure, exps: np.ndarray, term_eq: np.ndarray, p: int, seed: int):
    """(term coefficients mod p, M = [[1, 0], [x0, N]], k) of one seeded consistent GF(p) instance: its
    linear equations solved exactly (x0 + N y on their solution set, N in random coordinates on the
    kernel, as generic as the online SVD's). Its known root is checked by the certification before."""
    q, root = extended.sample_gf(p, seed)[:2]
    polys = extended.gf_polys(q, p)
    coeffs = np.zeros(len(exps), dtype=np.int64)
    for t, (e, eq) in enumerate(zip(exps, term_eq)):
        coeffs[t] = dict(polys[eq].terms()).get(tuple(int(v) for v in e), 0)
    n = exps.shape[1]
    A = []
    for i in structure.linear:
        row = [0] * (n + 1)
        for e, c in polys[i].terms():
            row[0 if sum(e) == 0 else 1 + int(np.argmax(e))] = c
        A.append(row)
    x0, basis = _kernel_mod(A, p) if A else ([0] * n, [[int(i == j) for j in range(n)] for i in range(n)])
    rng = np.random.default_rng(10_000 + seed)
    k = len(basis)
    T = rng.integers(1, p, size=(k, k))  # generic coordinates on the kernel, as the online SVD's
    Nmat = (np.array(basis, dtype=np.int64).T @ T) % p  # (n, k)
    x0 = (np.array(x0, dtype=np.int64) + Nmat @ rng.integers(1, p, size=k)) % p
    M = np.zeros((n + 1, k + 1), dtype=np.int64)
    M[0, 0] = 1
    M[1:, 0], M[1:, 1:] = x0, Nmat
    return coeffs, M, k


def _grevlex_key(e: tuple[int, ...]) -> tuple:
    """Sort key: grevlex ascending (total degree, then reversed negated exponents)."""
    return (sum(e), tuple(-v for v in reversed(e)))


def standard_basis(polys: list[dict], nvars: int, p: int) -> list[tuple[int, ...]]:
    """Standard monomials of the grevlex Gröbner basis (the project's F4), increasing grevlex order."""
    from ..feasibility import system_basis

    return sorted(map(tuple, system_basis(polys, [f"y{i}" for i in range(nvars)], p)), key=_grevlex_key)


@dataclass(frozen=True)
class Template:
    """An elimination template: rows (equation, multiplier exponent), columns E | R | B."""

    rows: tuple[tuple[int, tuple[int, ...]], ...]
    excess: tuple[tuple[int, ...], ...]
    reducible: tuple[tuple[int, ...], ...]
    basis: tuple[tuple[int, ...], ...]
    action: int

    @property
    def columns(self) -> tuple[tuple[int, ...], ...]:
        return self.excess + self.reducible + self.basis


def _works(polys, rows, reducible, basis, p) -> tuple[bool, tuple]:
    """Whether the rows express every monomial of ``reducible`` by ``basis`` modulo the others; and E
    (grevlex descending: the monomials eliminated first)."""
    from ..feasibility import template_relations

    reached, excess = template_relations(polys, rows, reducible, basis, p)
    return reached == len(reducible), tuple(sorted(excess, key=_grevlex_key, reverse=True))


def build_template(polys: list[dict], basis: list[tuple[int, ...]], p: int, action: int, max_degree: int = 14,
                   progress=None) -> Template:
    """The smallest Macaulay-type template (degree by degree), then pruned row by row (see the module doc)."""
    from ..feasibility import _monomials

    nvars = len(basis[0])
    bset = set(basis)
    step = tuple(int(v == action) for v in range(nvars))
    reducible = tuple(sorted({tuple(a + b for a, b in zip(m, step)) for m in basis} - bset, key=_grevlex_key,
                             reverse=True))
    degrees = [max(sum(e) for e in f) for f in polys]
    for D in range(max(degrees), max_degree + 1):
        rows = [(i, m) for i in range(len(polys)) for m in _monomials(nvars, D - degrees[i])]
        ok, excess = _works(polys, rows, reducible, basis, p)
        if progress:
            progress(f"degree {D}: {len(rows)} rows, {'works' if ok else 'not enough'}")
        if ok:
            break
    else:
        raise ActionMatrixError(f"no template up to degree {max_degree}")
    # prune: largest multiples first, in halving chunks then one by one
    rows = sorted(rows, key=lambda r: (sum(r[1]) + degrees[r[0]], _grevlex_key(r[1])), reverse=True)
    chunk = max(1, len(rows) // 8)
    while chunk >= 1:
        i = 0
        while i < len(rows):
            trial = rows[:i] + rows[i + chunk:]
            ok, _ = _works(polys, trial, reducible, basis, p)
            if ok:
                rows = trial
            else:
                i += chunk
        if progress:
            progress(f"pruned in chunks of {chunk}: {len(rows)} rows")
        chunk //= 2 if chunk > 1 else 2
    ok, excess = _works(polys, rows, reducible, basis, p)
    assert ok
    return Template(tuple(rows), excess, reducible, tuple(basis), action)


# --------------------------------------------------------------------------------------------------
# online: fill, eliminate, eig
# --------------------------------------------------------------------------------------------------


class ActionMatrixSolver:
    """The online kernel of an ``action-matrix`` spec; ``coefficients``: the module's coefficient function
    (parameters (K, P) -> term coefficients (K, T) of the square system followed by its saturation factor)."""

    def __init__(self, spec: dict, coefficients):
        from scipy.linalg import qr

        self._qr = qr
        self.spec, self.coefficients = spec, coefficients
        exps = np.array(spec["exponents"], dtype=np.int64)
        term_eq = np.array(spec["term_equation"], dtype=np.intp)
        self.n = exps.shape[1]
        st = spec["structure"]
        self.linear, self.nonlinear, self.saturation = (np.array(st[key], dtype=np.intp)
                                                        for key in ("linear", "nonlinear", "saturation"))
        self.k = self.n - len(self.linear)
        self.composer = Composer(exps, term_eq, int(term_eq.max()) + 1, self.k)
        # linear equations: (l, n + 1) matrix [constant | x] from the term coefficients
        lin_terms = np.nonzero(np.isin(term_eq, self.linear))[0]
        where_eq = {int(e): i for i, e in enumerate(self.linear)}
        self.lin_terms = lin_terms
        self.lin_row = np.array([where_eq[int(term_eq[t])] for t in lin_terms], dtype=np.intp)
        self.lin_col = np.array([0 if exps[t].sum() == 0 else 1 + int(np.argmax(exps[t])) for t in lin_terms], dtype=np.intp)
        # template filling: entries (row, column) <- composed coefficient (equation, monomial)
        tpl = spec["template"]
        columns = [tuple(c) for c in tpl["excess"] + tpl["reducible"] + tpl["basis"]]
        col = {c: i for i, c in enumerate(columns)}
        mon = {m: i for i, m in enumerate(self.composer.monomials)}
        supports = [[tuple(e) for e in s] for s in tpl["supports"]]  # per equation of the (y, t) system
        rows, cols, src_eq, src_mon = [], [], [], []
        if spec["saturation"] != "dropped":
            raise ActionMatrixError(f"unknown saturation {spec['saturation']!r}; the kernel runs 'dropped'")
        for r, (i, mult) in enumerate(tpl["rows"]):
            for e in supports[i]:
                c = col.get(tuple(a + b for a, b in zip(e, mult)))
                if c is not None:
                    rows.append(r)
                    cols.append(c)
                    src_eq.append(self.nonlinear[i])
                    src_mon.append(mon[tuple(e)])
        self.fill = tuple(np.array(v, dtype=np.intp) for v in (rows, cols, src_eq, src_mon))
        self.shape = (len(tpl["rows"]), len(columns))
        self.n_excess, self.n_reducible, self.n_basis = len(tpl["excess"]), len(tpl["reducible"]), len(tpl["basis"])
        self.rank_excess = int(tpl["rank_excess"])
        basis = [tuple(b) for b in tpl["basis"]]
        red = {tuple(r): i for i, r in enumerate(tpl["reducible"])}
        bidx = {b: i for i, b in enumerate(basis)}
        a = int(tpl["action"])
        self.shift_basis, self.shift_reducible = [], []  # action matrix rows: x_a b in B or in R
        for i, b in enumerate(basis):
            t = tuple(v + int(j == a) for j, v in enumerate(b))
            (self.shift_basis if t in bidx else self.shift_reducible).append((i, bidx.get(t, red.get(t))))
        one = bidx[(0,) * len(basis[0])]
        self.read = np.array([bidx[tuple(int(j == v) for j in range(len(basis[0])))] for v in range(self.k)], dtype=np.intp)
        self.one = one
        self.degree = int(spec["degree"])
        # Newton on g(y) = 0 (the linear equations hold exactly on x0 + N y): the monomials of y degree by
        # degree (each one a lower one times a variable), the derivatives as one matrix on the coefficients
        mons = [tuple(m) for m in self.composer.monomials]
        where = {m: i for i, m in enumerate(mons)}
        self.levels = []
        for d in range(1, max(sum(m) for m in mons) + 1):
            idx = [i for i, m in enumerate(mons) if sum(m) == d]
            var = [next(v for v in range(self.k) if mons[i][v]) for i in idx]
            parent = [where[tuple(e - (v == j) for j, e in enumerate(mons[i]))] for i, v in zip(idx, var)]
            self.levels.append(tuple(np.array(a, dtype=np.intp) for a in (idx, parent, var)))
        self.derivative = np.zeros((len(mons), self.k * len(mons)))  # d/dy_j: column block j
        for i, m in enumerate(mons):
            for j in range(self.k):
                if m[j]:
                    self.derivative[i, j * len(mons) + where[tuple(e - (v == j) for v, e in enumerate(m))]] = m[j]
        self.newton_steps = int(spec["newton_steps"])

    def _kernel(self, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        L = np.zeros((len(self.linear), self.n + 1), dtype=c.dtype)
        np.add.at(L, (self.lin_row, self.lin_col), c[self.lin_terms])
        U, s, Vt = np.linalg.svd(L[:, 1:])
        r = len(self.linear)
        x0 = -Vt[:r].T @ ((U.T @ L[:, 0]) / s)
        return x0, Vt[r:].T

    def roots_one(self, c: np.ndarray) -> np.ndarray:
        """Candidate roots (degree, n) of one instance from its term coefficients c (T,)."""
        x0, N = self._kernel(c)
        M = np.zeros((self.n + 1, self.k + 1), dtype=c.dtype)
        M[0, 0] = 1.0
        M[1:, 0], M[1:, 1:] = x0, N
        G = self.composer.compose(c, M)  # (n_eq, monomials)
        rows, cols, src_eq, src_mon = self.fill
        T = np.zeros(self.shape, dtype=G.dtype)
        T[rows, cols] = G[src_eq, src_mon]
        T /= np.linalg.norm(T, axis=1, keepdims=True)
        ne, nr = self.n_excess, self.n_reducible
        if self.shape[0] == ne + nr and self.rank_excess == ne:  # square [E R]: one LU solve
            X = np.linalg.solve(T[:, : ne + nr], T[:, ne + nr:])[ne:]
        else:  # left kernel of the excess block (its rank is known from GF(p)), then R in terms of B
            Q = self._qr(T[:, :ne], pivoting=True, mode="full")[0] if ne else np.eye(self.shape[0])
            W = Q[:, self.rank_excess:]
            P, Bpart = W.T @ T[:, ne: ne + nr], W.T @ T[:, ne + nr:]
            X = np.linalg.solve(P, Bpart) if P.shape[0] == nr else np.linalg.lstsq(P, Bpart, rcond=None)[0]
        A = np.zeros((self.n_basis, self.n_basis), dtype=X.dtype)
        for i, j in self.shift_basis:
            A[i, j] = 1.0
        ri = [i for i, _ in self.shift_reducible]
        A[ri] = -X[[j for _, j in self.shift_reducible]]
        _, V = np.linalg.eig(A)
        with np.errstate(all="ignore"):
            y = (V[self.read] / V[self.one]).T  # (|B|, k)
            if self.n_basis > self.degree:  # spurious roots of the unsaturated ideal: det H ~ 0, dropped by count
                sat = self._monomial_values(y) @ G[self.saturation[0]]
                size = 1.0 + np.linalg.norm(x0[None, :] + y @ N.T, axis=1)
                keep = np.argsort(-np.abs(sat) / size ** 2, kind="stable")[: self.degree]
                y = y[np.sort(keep)]
            y = self._newton(y, G[self.nonlinear])
            x = x0[None, :] + y @ N.T
        return x

    def _monomial_values(self, y: np.ndarray) -> np.ndarray:
        """Values (c, Mn) of the composer's monomials at the points y (c, k)."""
        V = np.empty((len(y), len(self.composer.monomials)), dtype=y.dtype)
        V[:, 0] = 1.0
        for idx, parent, var in self.levels:
            V[:, idx] = V[:, parent] * y[:, var]
        return V

    def _newton(self, y: np.ndarray, G: np.ndarray) -> np.ndarray:
        """Newton steps on g(y) = 0 (G: (k, Mn) composed coefficients) for every candidate; a step is kept
        only where it lowers the residual, so an accurate root is never spoilt; at most ``newton_steps``,
        fewer once no candidate's residual decreases."""
        k, Mn = G.shape
        DG = (G @ self.derivative).reshape(k, k, Mn).transpose(2, 0, 1).reshape(Mn, k * k)  # J[c] = V[c] @ DG
        V = self._monomial_values(y)
        f = V @ G.T
        res = np.linalg.norm(f, axis=1)
        for _ in range(self.newton_steps):
            J = (V @ DG).reshape(len(y), k, k)
            try:
                step = np.linalg.solve(J, f[..., None])[..., 0]
            except np.linalg.LinAlgError:  # a singular Jacobian somewhere: least squares for all
                step = (np.linalg.pinv(J) @ f[..., None])[..., 0]
            yn = y - step
            Vn = self._monomial_values(yn)
            fn = Vn @ G.T
            rn = np.linalg.norm(fn, axis=1)
            better = rn < res  # False for NaN
            if not better.any():  # converged to rounding everywhere
                break
            y = np.where(better[:, None], yn, y)
            V = np.where(better[:, None], Vn, V)
            f = np.where(better[:, None], fn, f)
            res = np.where(better, rn, res)
        return y


# --------------------------------------------------------------------------------------------------
# offline: the spec
# --------------------------------------------------------------------------------------------------


def extended_system(system):
    """The square system followed by its non-vanishing factor (det H) as an extra row: one coefficient
    function gives both (the factor ranks the candidates online and saturates over GF(p))."""
    from analysis.formulations.parametric import ParametricSystem

    if len(system.nonzero) != 1:
        raise ActionMatrixError(f"{system.name}: the action-matrix method needs one non-vanishing factor (det H), "
                                f"got {len(system.nonzero)}")
    return ParametricSystem(system.name, system.unknowns, system.parameters, system.equations + system.nonzero,
                            definitions=system.definitions, scale_powers=system.scale_powers, unused=system.unused,
                            gf_sampler=system.gf_sampler)


def _instance_polys(ext, structure, exps, term_eq, p: int, seed: int):
    """(g_i(y) of the nonlinear equations, the same with t * det - 1) over GF(p) for one seed, as dicts."""
    coeffs, M, k = _gf_instance(ext, structure, exps, term_eq, p, seed)
    composer = Composer(exps, term_eq, len(ext.equations), k)
    C = composer.compose(coeffs, M, p)
    polys = [{m: int(c) for m, c in zip(composer.monomials, C[i]) if c} for i in structure.nonlinear]
    det = {m + (1,): int(c) for m, c in zip(composer.monomials, C[structure.saturation[0]]) if c}
    det[(0,) * (k + 1)] = p - 1
    return polys, [{m + (0,): c for m, c in f.items()} for f in polys] + [det], k


def _square(tpl: Template, instance, checks, name: str) -> tuple[Template, int]:
    """The template with only a maximal independent set of its excess columns (pivot columns over GF(p)).

    Every other excess column lies in their span on a generic instance, so a row combination that
    vanishes on them vanishes on all: the relations are the same. When the rows are then exactly
    |E'| + |R|, [E' R] is square and invertible, and the online elimination is one LU solve. Checked on
    the other instances: the dropped columns add no rank there either. Returns (template, rank of E).
    """
    from ..feasibility import _macaulay_rank, _pivot_columns

    polys, p = instance
    kept = tuple(_pivot_columns(polys, tpl.rows, tpl.excess, p))
    for other, q in checks:
        ranks = {_macaulay_rank(other, tpl.rows, cols, q) for cols in (tpl.excess, kept)}
        if ranks != {len(kept)} or _macaulay_rank(other, tpl.rows, kept + tpl.reducible, q) != len(kept) + len(tpl.reducible):
            raise ActionMatrixError(f"{name}: the independent excess columns differ on GF({q})")
    return Template(tpl.rows, kept, tpl.reducible, tpl.basis, tpl.action), len(kept)


def build(system, degree: int, primes: tuple[int, int] = (65521, 65519), progress=None,
          actions: tuple[int, ...] | None = None) -> dict:
    """The ``action-matrix`` spec of a square parametric system with ``degree`` certified roots.

    The linear equations are eliminated, the template is built for the unsaturated equations g_i(y)
    (their extra roots lie on det H = 0: counted exactly as |B| - degree and dropped online by the
    smallest |det H|); the action variable is the one whose template is smallest (among ``actions``,
    default all). Raises
    :class:`ActionMatrixError` when the saturated count differs from ``degree``, when a variable is
    not a standard monomial, or when the template fails on seed 1 or on the second prime.
    """
    from ..continuation.tracking import structure as term_structure

    t0 = time.perf_counter()
    ext = extended_system(system)
    exps, term_eq = term_structure(ext)
    st = _structure(exps, term_eq, len(ext.equations), 1)
    if not st.linear:
        raise ActionMatrixError(f"{system.name}: no linear equations to eliminate")
    p = primes[0]
    polys, saturated, k = _instance_polys(ext, st, exps, term_eq, p, 0)
    sat_count = len(standard_basis(saturated, k + 1, p))
    if sat_count != degree:
        raise ActionMatrixError(f"{system.name}: saturated count {sat_count} over GF({p}) in the eliminated "
                                f"coordinates, certified {degree}")
    try:
        basis = standard_basis(polys, k, p)
    except ValueError:
        raise ActionMatrixError(f"{system.name}: without det H != 0 the equations are not zero-dimensional (their "
                                "roots on det H = 0 are not isolated: 3D TOA has rank H <= 1), so the unsaturated "
                                "template cannot be built (docs/action-matrix.md)") from None
    if progress:
        progress(f"{system.name}: {k} free unknowns, |B| = {len(basis)} ({len(basis) - degree} on det H = 0)")
    missing = [v for v in range(k) if tuple(int(j == v) for j in range(k)) not in set(basis)]
    if missing:
        raise ActionMatrixError(f"{system.name}: y{missing} not standard monomials; the unknowns cannot be read")
    best = None
    for a in actions if actions is not None else range(k):
        tpl = build_template(polys, basis, p, a)
        if progress:
            progress(f"action y{a}: template {len(tpl.rows)} x {len(tpl.columns)}")
        if best is None or len(tpl.rows) * len(tpl.columns) < len(best.rows) * len(best.columns):
            best = tpl
    checks = []
    for q, seed in ((p, 1), (primes[1], 0)):  # the same rows work on another instance and prime
        other, _, _ = _instance_polys(ext, st, exps, term_eq, q, seed)
        checks.append((other, q))
        if [set(f) for f in other] != [set(f) for f in polys]:
            raise ActionMatrixError(f"{system.name}: supports differ on GF({q}) seed {seed}")
        ok, excess = _works(other, list(best.rows), best.reducible, best.basis, q)
        if not ok or excess != best.excess:
            raise ActionMatrixError(f"{system.name}: the template fails on GF({q}) seed {seed}")
    best, rank_excess = _square(best, (polys, p), checks, system.name)
    return {
        "format": SPEC_FORMAT,
        "kind": "action-matrix",
        "system": system.name,
        "unknowns": list(system.unknowns),
        "parameters": list(system.parameters),
        "degree": degree,
        "saturation": "dropped",
        "newton_steps": NEWTON_STEPS,
        "structure": {"linear": list(st.linear), "nonlinear": list(st.nonlinear), "saturation": list(st.saturation)},
        "primes": list(primes),
        "term_equation": [int(v) for v in term_eq],
        "exponents": [[int(v) for v in e] for e in exps],
        "template": {
            "action": best.action,
            "size": [len(best.rows), len(best.columns)],
            "rank_excess": rank_excess,
            "rows": [[i, list(m)] for i, m in best.rows],
            "excess": [list(m) for m in best.excess],
            "reducible": [list(m) for m in best.reducible],
            "basis": [list(m) for m in best.basis],
            "supports": [[list(m) for m in sorted(f, key=_grevlex_key)] for f in polys],
        },
    }


def verify(name: str, spec: dict, coefficients, trials, count: int) -> str:
    """Solve ``count`` seeded real instances (seed -> (normalised q, known root)); "found/count", or
    :class:`ActionMatrixError` when the known root is missed in more than 10 % of them."""
    solver = ActionMatrixSolver(spec, coefficients)
    return verify_found(name, lambda q: solver.roots_one(coefficients(np.asarray(q, dtype=float)[None])[0]), trials,
                        count, ActionMatrixError)


def load_spec(text: str) -> dict:
    """A spec from its JSON text; raises :class:`ActionMatrixError` for another format."""
    return load_format(text, SPEC_FORMAT, ActionMatrixError, "action-matrix")


def solve_scaled(solver: ActionMatrixSolver, F, shape: tuple[int, ...], powers) -> np.ndarray:
    """Roots for data F (..., *shape): each instance divided by its RMS, solved, the roots mapped back."""
    F = np.asarray(F, dtype=float)
    if F.shape[F.ndim - len(shape):] != tuple(shape):
        raise ValueError(f"data of shape {F.shape} given; the solver needs (..., {', '.join(map(str, shape))})")
    batch = F.shape[: F.ndim - len(shape)]
    Q = F.reshape(-1, int(np.prod(shape)))
    s = np.sqrt(np.mean(Q * Q, axis=1))
    s = np.where(s > 0, s, 1.0)
    coeffs = solver.coefficients(Q / s[:, None])
    out = np.full((len(Q), solver.degree, solver.n), np.nan + 0j)
    with np.errstate(all="ignore"):
        for i in range(len(Q)):
            try:
                x = solver.roots_one(coeffs[i])
            except np.linalg.LinAlgError:
                continue
            out[i, : len(x)] = x * (s[i] ** np.asarray(powers)[None, :] if powers is not None else 1.0)
    return out.reshape(batch + out.shape[1:])
