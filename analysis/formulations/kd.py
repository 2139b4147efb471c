"""TOA beside TDOA, in 2D and 3D: equations, known roots and samplers of every configuration other than the
paper's own 2D TDOA formulation (which :mod:`analysis.formulations.tdoa` builds with its vectorised builder).

:mod:`analysis.formulations.tdoa` dispatches here (``gf_equations``, ``real_equations``, ``sample_gf_instance``,
``sample_real_instance``) when a :class:`~analysis.formulations.tdoa.TDOAConfig` has ``model="toa"``,
``dim=3`` or ``parametrization="direct"``; callers never import this module themselves.

Compaction parametrization in K dimensions (paper Section 2.1, written for any K). With d_ij^2 =
(f_ij - o_j)^2 (TDOA) or f_ij^2 (TOA), the compaction matrix D~ (m-1) x (n-1) has
D~_ij = d^2_{i+1,j+1} - d^2_{1,j+1} - d^2_{i+1,1} + d^2_{11} = -2 R^T S. Its first K columns give
D^ = R~^T with S~ = [I | X]: for TDOA only the first K + 1 transmitters enter (X would depend on the
unknown offsets), for TOA X = D^[:K]^{-1} D~[:K, K:] is known from the data (so every transmitter gives a
B equation). Unknowns: the upper triangle of the symmetric K x K matrix H = (L^T L)^{-1}, b in R^K and,
for TDOA, the offsets. Equations (each "= 0"):

* ``A``:  d11^2 det(H) - b^T adj(H) b;
* ``Bj``: (d1j^2 - d11^2) det(H) - 1/4 s^T adj(H) s + b^T adj(H) s,  s = S~_{j-1} (a unit vector for j <= K+1);
  for 3D TDOA and j >= K + 2, s = M^{-1} D~[:K, j-1] with M = D~[:K, :K] affine in the offsets, written
  with u = adj(M) D~[:K, j-1] and multiplied by det(M)^2:
  (d1j^2 - d11^2) det(M)^2 det(H) - 1/4 u^T adj(H) u + det(M) b^T adj(H) u (saturate by det M too;
  the paper's 2D family has no such equations, and keeps none here);
* ``Ci``: d_i1^2 - d11^2 - (r^T H r - 2 b^T r),  r = R~_{i-1} = row i-1 of D^;
* minors (TDOA): the (K+1) x (K+1) minors of D~ (rank K), named as in 2D.

For K = 2 and TDOA these are exactly the paper's equations (tests check this builder against the
vectorised one). Known root: S = [s_2 - s_1, ..., s_{K+1} - s_1], L = -2 S, H = (4 S^T S)^{-1},
b = -1/2 S^{-1} s_1, and S~_{j-1} = S^{-1} (s_j - s_1); it is invariant under the orthogonal group, so
every solution stands for one network up to rotation, reflection and translation.

Direct parametrization: unknowns the positions in the gauge r_1 = 0, r_2 = (x, 0[, 0]), r_3 = (x, y, 0)
(3D) and the offsets; equations ``D<i>_<j>``: d_ij^2 - |r_i - s_j|^2. The sign changes of the K
coordinate axes keep the gauge, so each network appears 2^K times
(:attr:`~analysis.formulations.tdoa.TDOAConfig.gauge_group_order`): the cross-check of the compaction degree.

Instances are drawn in the gauge frame (over GF(p) a rotation into it may not exist, and the compaction
root does not depend on the frame). Everything over GF(p) is exact; the float path exists to check
numeric work at a real root. This module never imports ``solvers``.
"""
from __future__ import annotations

import itertools
from typing import Sequence

import numpy as np

from .base import (RECEIVERS_FIRST_LIMIT, Formulation, Instance, SamplingFailed, TDOAConfig, _family,
                               _parse_minor, _residue_mask, _rng, sqrt_mod)

__all__ = ["build_equations", "det_h_terms", "nonzero_conditions", "sample_gf_instance_kd", "sample_real_instance_kd", "solve_mod"]

Exponent = tuple[int, ...]


# --------------------------------------------------------------------------------------------------
# Exact small linear algebra mod p
# --------------------------------------------------------------------------------------------------


def solve_mod(a: Sequence[Sequence[int]], b: Sequence[Sequence[int]], p: int) -> list[list[int]] | None:
    """X with A X = B over GF(p) for a square A (Gauss-Jordan), or None when A is singular mod p."""
    k = len(a)
    rows = [[int(x) % p for x in a[i]] + [int(x) % p for x in b[i]] for i in range(k)]
    for col in range(k):
        pivot = next((r for r in range(col, k) if rows[r][col]), None)
        if pivot is None:
            return None
        rows[col], rows[pivot] = rows[pivot], rows[col]
        inv = pow(rows[col][col], -1, p)
        rows[col] = [x * inv % p for x in rows[col]]
        for r in range(k):
            if r != col and rows[r][col]:
                factor = rows[r][col]
                rows[r] = [(x - factor * y) % p for x, y in zip(rows[r], rows[col])]
    return [row[k:] for row in rows]


def _det_mod(a: Sequence[Sequence[int]], p: int) -> int:
    """Determinant mod p of a small square matrix (Leibniz)."""
    k = len(a)
    total = 0
    for perm in itertools.permutations(range(k)):
        inversions = sum(1 for x, y in itertools.combinations(perm, 2) if x > y)
        term = -1 if inversions % 2 else 1
        for i, j in enumerate(perm):
            term = term * a[i][j] % p
        total += term
    return total % p


# --------------------------------------------------------------------------------------------------
# Sparse polynomial arithmetic with one coefficient field (GF(p) or floats)
# --------------------------------------------------------------------------------------------------


class _Field:
    """Coefficients mod p (ints, reduced after each product) or floats (p None)."""

    def __init__(self, p: int | None):
        self.p = p

    def norm(self, c):
        return c % self.p if self.p is not None else float(c)

    def quarter(self):
        return pow(4, -1, self.p) if self.p is not None else 0.25

    def add(self, *polys: dict) -> dict:
        out: dict = {}
        for poly in polys:
            for exp, c in poly.items():
                out[exp] = out.get(exp, 0) + c
        return self.clean(out)

    def scale(self, poly: dict, c) -> dict:
        return self.clean({exp: v * c for exp, v in poly.items()})

    def mul(self, a: dict, b: dict) -> dict:
        out: dict = {}
        for ea, ca in a.items():
            for eb, cb in b.items():
                exp = tuple(x + y for x, y in zip(ea, eb))
                out[exp] = out.get(exp, 0) + ca * cb
        return self.clean(out)

    def clean(self, poly: dict) -> dict:
        out = {}
        for exp, c in poly.items():
            c = self.norm(c)
            if c != 0:
                out[exp] = c
        return out

    def det(self, matrix: Sequence[Sequence[dict]]) -> dict:
        """Determinant of a square matrix of polynomials (Laplace along the first row, sub-minors memoised)."""
        k = len(matrix)
        memo: dict[tuple[int, ...], dict] = {}

        def minor(cols: tuple[int, ...]) -> dict:  # rows k - len(cols) .. k-1, these columns
            if len(cols) == 1:
                return matrix[k - 1][cols[0]]
            if cols not in memo:
                row = k - len(cols)
                terms = []
                for idx, c in enumerate(cols):
                    entry = matrix[row][c]
                    if entry:
                        sub = minor(cols[:idx] + cols[idx + 1:])
                        terms.append(self.scale(self.mul(entry, sub), -1 if idx % 2 else 1))
                memo[cols] = self.add(*terms)
            return memo[cols]

        return minor(tuple(range(k)))

    def adjugate(self, matrix: Sequence[Sequence[dict]]) -> list[list[dict]]:
        """adj(M)[a][c] = (-1)^(a+c) det(M without row c and column a)."""
        k = len(matrix)
        out = [[{} for _ in range(k)] for _ in range(k)]
        for a in range(k):
            for c in range(k):
                sub = [[matrix[r][q] for q in range(k) if q != a] for r in range(k) if r != c]
                out[a][c] = self.scale(self.det(sub), -1 if (a + c) % 2 else 1)
        return out


# --------------------------------------------------------------------------------------------------
# The builder
# --------------------------------------------------------------------------------------------------


class _BuilderKD:
    """Equations of one configuration (any model, dimension and parametrization) for one data matrix."""

    def __init__(self, config: TDOAConfig, F: Sequence[Sequence], p: int | None):
        self.config, self.F, self.field = config, F, _Field(p)
        self.k = config.dim
        self.index = {name: i for i, name in enumerate(config.unknowns)}
        self.nvars = len(self.index)
        self.tdoa = config.model == "tdoa"

    # -- monomials
    def const(self, c) -> dict:
        return self.field.clean({(0,) * self.nvars: c})

    def var(self, name: str) -> dict:
        exp = [0] * self.nvars
        exp[self.index[name]] = 1
        return {tuple(exp): 1}

    def d2(self, i: int, j: int) -> dict:
        """d_ij^2 (1-based): (f_ij - o_j)^2 for TDOA, f_ij^2 for TOA."""
        f = self.F[i - 1][j - 1]
        diff = self.field.add(self.const(f), self.field.scale(self.var(f"o{j}"), -1)) if self.tdoa else self.const(f)
        return self.field.mul(diff, diff)

    def compaction(self, i: int, j: int) -> dict:
        """D~_ij (1-based), affine in the offsets (their squares cancel)."""
        fl = self.field
        return fl.add(self.d2(i + 1, j + 1), fl.scale(self.d2(1, j + 1), -1), fl.scale(self.d2(i + 1, 1), -1),
                      self.d2(1, 1))

    # -- compaction parametrization
    def h_matrix(self) -> list[list[dict]]:
        k = self.k
        return [[self.var(f"h{min(a, c) + 1}{max(a, c) + 1}") for c in range(k)] for a in range(k)]

    def b_vector(self) -> list[dict]:
        return [self.var(f"b{a + 1}") for a in range(self.k)]

    def s_tilde(self) -> list[list]:
        """Columns S~_1..S~_{n-1} (TOA) or the unit vectors S~_1..S~_K (TDOA), as coefficient lists."""
        k, fl = self.k, self.field
        units = [[1 if a == c else 0 for a in range(k)] for c in range(k)]
        if self.tdoa:
            return units
        d = [[next(iter(self.compaction(i, j).values()), 0) for j in range(1, self.config.n)]
             for i in range(1, k + 1)]  # D~[:K, :], constants for TOA
        head = [row[:k] for row in d]
        tail = [row[k:] for row in d]
        if not tail[0]:
            return units
        if fl.p is not None:
            x = solve_mod(head, tail, fl.p)
            if x is None:
                raise ValueError(f"{self.config.label}: D~[:K, :K] is singular mod {fl.p}; the data are degenerate")
        else:
            x = np.linalg.solve(np.array(head, dtype=float), np.array(tail, dtype=float)).tolist()
        return units + [[x[a][c] for a in range(k)] for c in range(len(tail[0]))]

    def build_compaction(self, names: Sequence[str]) -> list[dict]:
        fl, k = self.field, self.k
        h, b = self.h_matrix(), self.b_vector()
        need_adj = any(_family(x) in ("A", "B") for x in names)
        det = fl.det(h) if need_adj else {}
        adj = fl.adjugate(h) if need_adj else []
        s_cols = self.s_tilde() if any(_family(x) == "B" for x in names) else []
        out = []
        for name in names:
            fam = _family(name)
            if fam == "B" and int(name[1:]) - 2 >= len(s_cols):
                out.append(self.extended_b(int(name[1:]), h, b, det, adj))
            elif fam == "A":
                b_adj_b = fl.add(*(fl.mul(b[a], fl.mul(adj[a][c], b[c])) for a in range(k) for c in range(k)))
                out.append(fl.add(fl.mul(self.d2(1, 1), det), fl.scale(b_adj_b, -1)))
            elif fam == "B":
                j = int(name[1:])
                s = s_cols[j - 2]
                s_adj_s = fl.add(*(fl.scale(adj[a][c], s[a] * s[c]) for a in range(k) for c in range(k) if s[a] and s[c]))
                b_adj_s = fl.add(*(fl.scale(fl.mul(b[a], adj[a][c]), s[c]) for a in range(k) for c in range(k) if s[c]))
                lhs = fl.add(self.d2(1, j), fl.scale(self.d2(1, 1), -1))
                out.append(fl.add(fl.mul(lhs, det), fl.scale(s_adj_s, -fl.quarter()), b_adj_s))
            elif fam == "C":
                i = int(name[1:])
                r = [self.compaction(i - 1, c) for c in range(1, k + 1)]
                quad = fl.add(*(fl.mul(h[a][c], fl.mul(r[a], r[c])) for a in range(k) for c in range(k)))
                lin = fl.add(*(fl.mul(b[a], r[a]) for a in range(k)))
                lhs = fl.add(self.d2(i, 1), fl.scale(self.d2(1, 1), -1))
                out.append(fl.add(lhs, fl.scale(quad, -1), fl.scale(lin, 2)))
            else:
                rows, cols = _parse_minor(self.config, name)
                out.append(fl.det([[self.compaction(r, c) for c in cols] for r in rows]))
        return out

    def head(self) -> list[list[dict]]:
        """M = D~[:K, :K] (rows and columns 1..K), affine in the offsets for TDOA."""
        return [[self.compaction(a, c) for c in range(1, self.k + 1)] for a in range(1, self.k + 1)]

    def extended_b(self, j: int, h, b, det: dict, adj) -> dict:
        """B_j for TDOA transmitters j >= K + 2 (module docstring), multiplied by det(M)^2."""
        fl, k = self.field, self.k
        M = self.head()
        adj_m, det_m = fl.adjugate(M), fl.det(M)
        column = [self.compaction(a, j - 1) for a in range(1, k + 1)]
        u = [fl.add(*(fl.mul(adj_m[a][c], column[c]) for c in range(k))) for a in range(k)]
        u_adj_u = fl.add(*(fl.mul(u[a], fl.mul(adj[a][c], u[c])) for a in range(k) for c in range(k)))
        b_adj_u = fl.add(*(fl.mul(b[a], fl.mul(adj[a][c], u[c])) for a in range(k) for c in range(k)))
        lhs = fl.add(self.d2(1, j), fl.scale(self.d2(1, 1), -1))
        return fl.add(fl.mul(fl.mul(lhs, fl.mul(det_m, det_m)), det), fl.scale(u_adj_u, -fl.quarter()),
                      fl.mul(det_m, b_adj_u))

    # -- direct parametrization
    def position(self, prefix: str, index: int) -> list[dict]:
        return [self.var(f"{prefix}{index}{'xyz'[a]}") if f"{prefix}{index}{'xyz'[a]}" in self.index else {}
                for a in range(self.k)]

    def build_direct(self, names: Sequence[str]) -> list[dict]:
        fl = self.field
        out = []
        for name in names:
            i, j = (int(x) for x in name[1:].split("_"))
            r, s = self.position("r", i), self.position("s", j)
            dist = fl.add(*(fl.mul(diff, diff) for diff in (fl.add(ra, fl.scale(sa, -1)) for ra, sa in zip(r, s))))
            out.append(fl.add(self.d2(i, j), fl.scale(dist, -1)))
        return out

    # -- Gram parametrization (TOA)
    def g_matrix(self) -> list[list[dict]]:
        k = self.k
        return [[self.var(f"g{min(a, c) + 1}{max(a, c) + 1}") for c in range(k)] for a in range(k)]

    def build_gram(self, names: Sequence[str]) -> list[dict]:
        fl, k = self.field, self.k
        G = self.g_matrix()
        det, adj = fl.det(G), fl.adjugate(G)

        def w(j: int) -> list[dict]:  # w_j,a = G_aa + d_1j^2 - d_{a+1,j}^2
            return [fl.add(G[a][a], self.d2(1, j), fl.scale(self.d2(a + 2, j), -1)) for a in range(k)]

        out = []
        for name in names:
            if name[0] == "S":
                j = int(name[1:])
                wj = w(j)
                quad = fl.add(*(fl.mul(wj[a], fl.mul(adj[a][c], wj[c])) for a in range(k) for c in range(k)))
                out.append(fl.add(quad, fl.scale(fl.mul(self.d2(1, j), det), -4)))
            else:
                i, j = (int(v) for v in name[1:].split("_"))
                alpha = [self.var(f"a{i}_{a + 1}") for a in range(k)]
                wj = w(j)
                gaa = fl.add(*(fl.mul(alpha[a], fl.mul(G[a][c], alpha[c])) for a in range(k) for c in range(k)))
                aw = fl.add(*(fl.mul(alpha[a], wj[a]) for a in range(k)))
                out.append(fl.add(gaa, self.d2(1, j), fl.scale(self.d2(i, j), -1), fl.scale(aw, -1)))
        return out

    def build(self, names: Sequence[str]) -> list[dict]:
        if self.config.parametrization == "direct":
            return self.build_direct(names)
        if self.config.parametrization == "gram":
            return self.build_gram(names)
        return self.build_compaction(names)


def build_equations(formulation: Formulation, rows: Sequence[Sequence], p: int | None) -> list[dict]:
    """The equations of a formulation for one data matrix, over GF(p) (ints in [1, p)) or the reals
    (p None, floats); one {exponent: coefficient} dict per equation in the formulation's order. Called by
    :func:`analysis.formulations.tdoa.gf_equations` and :func:`~analysis.formulations.tdoa.real_equations`."""
    return _BuilderKD(formulation.config, rows, p).build(formulation.equations)


def nonzero_conditions(formulation: Formulation, rows: Sequence[Sequence], p: int) -> list[dict]:
    """Polynomials that vanish only on spurious solutions of a compaction formulation over GF(p): det H
    (A and B were multiplied by it) and, when 3D TDOA's B_j with j >= K + 2 are used, det D~[:K, :K]."""
    builder = _BuilderKD(formulation.config, rows, p)
    if formulation.config.parametrization == "gram":
        return [builder.field.det(builder.g_matrix())]
    out = [builder.field.det(builder.h_matrix())]
    if any(_family(x) == "B" and int(x[1:]) > formulation.config.dim + 1 for x in formulation.equations) \
            and formulation.config.model == "tdoa":
        out.append(builder.field.det(builder.head()))
    return out


def det_h_terms(config: TDOAConfig) -> dict[Exponent, int]:
    """det H as {exponent: integer coefficient} in the configuration's unknowns (compaction only): the
    polynomial to saturate by, since A and B were multiplied by it."""
    if config.parametrization != "compaction":
        raise ValueError(f"det H needs the compaction parametrization; {config.label} has none")
    builder = _BuilderKD(config, [[0] * config.n for _ in range(config.m)], None)
    return {exp: int(round(c)) for exp, c in builder.field.det(builder.h_matrix()).items()}


# --------------------------------------------------------------------------------------------------
# Known roots and samplers
# --------------------------------------------------------------------------------------------------


def _gauge_coordinates(config: TDOAConfig, receivers: Sequence[Sequence], transmitters: Sequence[Sequence]) -> list:
    """Free coordinates of a network already in the gauge frame, in :attr:`TDOAConfig.unknowns` order."""
    k = config.dim
    out = [receivers[i - 1][a] for i in range(2, config.m + 1) for a in range(min(i - 1, k))]
    return out + [transmitters[j][a] for j in range(config.n) for a in range(k)]


def _root_gf(config: TDOAConfig, receivers, transmitters, offsets, p: int) -> tuple[int, ...] | None:
    """Known root over GF(p), or None when S = [s_2 - s_1, ..., s_{K+1} - s_1] is singular."""
    offs = tuple(int(o) % p for o in offsets) if config.model == "tdoa" else ()
    if config.parametrization == "direct":
        return tuple(int(x) % p for x in _gauge_coordinates(config, receivers, transmitters)) + offs
    k = config.dim
    if config.parametrization == "gram":
        R = [[int(x) % p for x in receivers[i]] for i in range(1, k + 1)]  # rows r_2..r_{K+1} (r_1 = 0)
        g = tuple(sum(R[a][q] * R[c][q] for q in range(k)) % p for a in range(k) for c in range(a, k))
        if config.m <= k + 1:
            return g
        RT = [[R[c][a] for c in range(k)] for a in range(k)]
        alpha = solve_mod(RT, [[int(receivers[i][a]) % p for i in range(k + 1, config.m)] for a in range(k)], p)
        if alpha is None:
            return None
        return g + tuple(alpha[a][i] for i in range(config.m - k - 1) for a in range(k))
    s1 = [int(x) for x in transmitters[0]]
    S = [[(int(transmitters[c + 1][a]) - s1[a]) % p for c in range(k)] for a in range(k)]  # column c = s_{c+2} - s_1
    m4 = [[4 * sum(S[q][a] * S[q][c] for q in range(k)) % p for c in range(k)] for a in range(k)]  # 4 S^T S
    identity = [[int(a == c) for c in range(k)] for a in range(k)]
    H = solve_mod(m4, identity, p)
    x = solve_mod(S, [[v] for v in s1], p)
    if H is None or x is None:
        return None
    half = pow(2, -1, p)
    h = tuple(H[a][c] for a in range(k) for c in range(a, k))
    b = tuple(-half * x[a][0] % p for a in range(k))
    return h + b + offs


def _root_real(config: TDOAConfig, receivers: np.ndarray, transmitters: np.ndarray, offsets: np.ndarray) -> tuple:
    offs = tuple(map(float, offsets)) if config.model == "tdoa" else ()
    if config.parametrization == "direct":
        return tuple(float(x) for x in _gauge_coordinates(config, receivers, transmitters)) + offs
    k = config.dim
    if config.parametrization == "gram":
        return tuple(float(v) for v in gram_root(receivers, k))
    S = (transmitters[1:k + 1] - transmitters[0]).T
    H = np.linalg.inv(4.0 * S.T @ S)
    b = -0.5 * np.linalg.solve(S, transmitters[0])
    return tuple(float(H[a, c]) for a in range(k) for c in range(a, k)) + tuple(map(float, b)) + offs


def gram_root(receivers: np.ndarray, k: int) -> np.ndarray:
    """The gram parametrization's root of a network (receivers (m, K), real or complex, r_1 first; any frame):
    the upper triangle of G = R R^T, R = [r_2 - r_1; ...; r_{K+1} - r_1], then for each further receiver i
    its coordinates a_i in that basis (r_i - r_1 = R^T a_i; transposes, not conjugates)."""
    rel = np.asarray(receivers) - np.asarray(receivers)[0]
    R = rel[1:k + 1]
    G = R @ R.T
    upper = [G[a, c] for a in range(k) for c in range(a, k)]
    alpha = np.linalg.solve(R.T, rel[k + 1:].T).T.ravel() if len(rel) > k + 1 else np.zeros(0)
    return np.concatenate([upper, alpha])


def _gauge_ok(config: TDOAConfig, receivers: np.ndarray, p: int) -> bool:
    """The gauge's pivots r_2x, r_3y (3D) are nonzero; for compaction also det[r_2..r_{K+1}] != 0 (the rows
    of D~ that S~ is solved from: D~[:K, :K] = -2 R[:, :K]^T S)."""
    k = config.dim
    if any(receivers[i, i - 1] % p == 0 for i in range(1, min(k, config.m))):
        return False
    if config.parametrization in ("compaction", "gram"):
        return _det_mod(receivers[1:k + 1].tolist(), p) != 0
    return True


def sample_gf_instance_kd(config: TDOAConfig, p: int, rng: "np.random.Generator | int", *,
                          max_batches: int = 200) -> Instance:
    """A consistent random GF(p) instance with its known root (see the module docstring).

    Draws, in this order: receivers r_2..r_m uniform in GF(p)^K with the gauge's zeros (r_2 on the x axis,
    r_3 in the xy plane), redrawn while a gauge pivot vanishes; each transmitter uniform among the points
    whose squared distance to every receiver is a nonzero quadratic residue (s_{K+1} also redrawn while
    S is singular); TDOA offsets uniform in GF(p) (TOA: zero). f_ij = sqrt(d_ij^2) + o_j with the smaller
    square root. Raises :class:`~analysis.formulations.tdoa.SamplingFailed` for more than
    :data:`~analysis.formulations.tdoa.RECEIVERS_FIRST_LIMIT` receivers or when the budget runs out.
    """
    gen, seed_text = _rng(rng)
    m, n, k = config.m, config.n, config.dim
    if m > RECEIVERS_FIRST_LIMIT:
        raise SamplingFailed(f"{config.label}: the {k}D sampler draws receivers first and accepts at most "
                             f"{RECEIVERS_FIRST_LIMIT} receivers (acceptance about 2^-m per transmitter)")
    for _ in range(max_batches):
        receivers = np.zeros((m, k), dtype=np.int64)
        receivers[1:] = gen.integers(0, p, size=(m - 1, k))
        for i in range(1, min(k, m)):
            receivers[i, i:] = 0
        if _gauge_ok(config, receivers, p):
            break
    else:
        raise SamplingFailed(f"no receivers with nonzero gauge pivots mod {p} ({config.label}, {seed_text})")
    batch = int(min(max(64, 4 * 2 ** m), 1 << 16))

    def singular(points: list) -> bool:
        s = np.array(points[1:k + 1]) - np.array(points[0])
        return _det_mod(s.T.tolist(), p) == 0

    transmitters: list[np.ndarray] = []
    need_s = config.parametrization == "compaction"
    for j in range(n):
        for _ in range(max_batches):
            cand = gen.integers(0, p, size=(batch, k))
            hit = next((c for c in cand[_residue_mask(cand, receivers, p)]
                        if not (need_s and j == k and singular(transmitters + [c]))), None)
            if hit is not None:
                transmitters.append(hit)
                break
        else:
            raise SamplingFailed(f"no transmitter position with all squared distances nonzero residues mod {p} "
                                 f"after {max_batches} batches of {batch} ({config.label}, {seed_text}); "
                                 "use a larger prime or another seed")
    offsets = gen.integers(0, p, size=n) if config.model == "tdoa" else np.zeros(n, dtype=np.int64)
    rec = tuple(tuple(int(x) for x in r) for r in receivers)
    tra = tuple(tuple(int(x) for x in s) for s in transmitters)
    offs = tuple(int(o) for o in offsets)
    F = tuple(tuple((sqrt_mod(sum((a - c) ** 2 for a, c in zip(r, s)), p) + o) % p for s, o in zip(tra, offs))
              for r in rec)
    root = _root_gf(config, rec, tra, offs, p)
    assert root is not None  # S was accepted as nonsingular
    return Instance(config, p, F, rec, tra, offs, root)


def _to_gauge(receivers: np.ndarray, transmitters: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Translate r_1 to the origin and rotate (QR of [r_2 .. r_K]) so that r_2 is on the x axis and, in 3D,
    r_3 in the xy plane; distances are unchanged."""
    receivers, transmitters = receivers - receivers[0], transmitters - receivers[0]
    q, _ = np.linalg.qr(receivers[1:k].T, mode="complete")
    return receivers @ q, transmitters @ q


def sample_real_instance_kd(config: TDOAConfig, rng: "np.random.Generator | int", scale: float = 10.0,
                            offset_scale: float = 1.0) -> Instance:
    """A random real instance with its known root, in the gauge frame.

    Draws, in this order: receivers (m x K) and transmitters (n x K) from N(0, scale^2), then (TDOA) offsets
    from N(0, offset_scale^2); moves the network into the gauge frame (translation and an orthogonal map);
    f_ij = |r_i - s_j| + o_j.
    """
    gen, _ = _rng(rng)
    m, n, k = config.m, config.n, config.dim
    receivers = gen.normal(0.0, scale, size=(m, k))
    transmitters = gen.normal(0.0, scale, size=(n, k))
    offsets = gen.normal(0.0, offset_scale, size=n) if config.model == "tdoa" else np.zeros(n)
    receivers, transmitters = _to_gauge(receivers, transmitters, k)
    for i in range(1, min(k, m)):
        receivers[i, i:] = 0.0  # exact zeros where QR leaves rounding noise
    F = np.linalg.norm(receivers[:, None, :] - transmitters[None, :, :], axis=2) + offsets[None, :]
    root = _root_real(config, receivers, transmitters, offsets)
    return Instance(config, None, tuple(tuple(map(float, r)) for r in F), tuple(tuple(map(float, r)) for r in receivers),
                    tuple(tuple(map(float, s)) for s in transmitters), tuple(map(float, offsets)), root)



# --------------------------------------------------------------------------------------------------
# The formulas on any arithmetic (sympy expressions for parametric systems, program values for tapes)
# --------------------------------------------------------------------------------------------------


def _det_generic(a: Sequence[Sequence], zero):
    """Determinant by cofactors of the first row (K <= 4: at most 24 products), any ring elements."""
    k = len(a)
    if k == 1:
        return a[0][0]
    if k == 2:
        return a[0][0] * a[1][1] - a[0][1] * a[1][0]
    out = zero
    for c in range(k):
        sub = [[a[r][q] for q in range(k) if q != c] for r in range(1, k)]
        term = a[0][c] * _det_generic(sub, zero)
        out = out + term if c % 2 == 0 else out - term
    return out


def _adjugate_generic(a: Sequence[Sequence], zero) -> list[list]:
    """adj(A)[r][c] = (-1)^(r+c) det(A without row c and column r)."""
    k = len(a)
    if k == 1:
        return [[zero + 1]]
    out = [[zero] * k for _ in range(k)]
    for r in range(k):
        for c in range(k):
            minor = _det_generic([[a[i][j] for j in range(k) if j != r] for i in range(k) if i != c], zero)
            out[r][c] = minor if (r + c) % 2 == 0 else zero - minor
    return out


def formulas(formulation: Formulation, x, f: Sequence[Sequence], zero, quarter, define=None) -> tuple[list, list]:
    """The equations of any configuration written on given ring elements: (equations, further
    non-vanishing conditions besides det H), in ``formulation.equations`` order.

    x: mapping unknown name -> element; f: the m x n measurements as elements; zero: the ring's 0;
    quarter: the element 1/4; define(name, element) -> element: names a data-only subexpression (a
    parametric system's definition; default: the element itself). The same formulas as the builder above
    (module docstring): e_ij = f_ij - f_1j, p_ij = f_ij + f_1j, d_ij^2 - d_1j^2 = e (p - 2 o_j) (TOA:
    e p), D~_ij = c_ij + 2 e_{i+1,1} o_1 - 2 e_{i+1,j+1} o_{j+1} with c_ij = e p - e p; B_j for
    j >= K + 2 with u = adj(M) D~[:K, j-1], M = D~[:K, :K], multiplied by det(M)^2 (for TDOA det M
    depends on the offsets and is returned as a condition). Used by analysis.formulations.parametric (sympy) and
    solvers.continuation.slp (straight-line programs), so that a system and its program cannot diverge.
    """
    config = formulation.config
    k, m, n, tdoa = config.dim, config.m, config.n, config.model == "tdoa"
    define = define or (lambda name, value: value)
    o = [x[f"o{j}"] if tdoa else zero for j in range(1, n + 1)]
    cache: dict = {}

    def e(i: int, j: int):
        if ("e", i, j) not in cache:
            cache["e", i, j] = define(f"e{i}_{j}", f[i - 1][j - 1] - f[0][j - 1])
        return cache["e", i, j]

    def p(i: int, j: int):
        if ("p", i, j) not in cache:
            cache["p", i, j] = define(f"p{i}_{j}", f[i - 1][j - 1] + f[0][j - 1])
        return cache["p", i, j]

    def d2(i: int, j: int):
        diff = f[i - 1][j - 1] - o[j - 1] if tdoa else f[i - 1][j - 1]
        return diff * diff

    def d2_diff(i: int, j: int):  # d_ij^2 - d_1j^2, i >= 2
        return e(i, j) * (p(i, j) - 2 * o[j - 1]) if tdoa else e(i, j) * p(i, j)

    def comp(i: int, j: int):  # D~_ij, 1-based
        if ("c", i, j) not in cache:
            cache["c", i, j] = define(f"c{i}_{j}", e(i + 1, j + 1) * p(i + 1, j + 1) - e(i + 1, 1) * p(i + 1, 1))
        c = cache["c", i, j]
        return c + (2 * (e(i + 1, 1) * o[0]) - 2 * (e(i + 1, j + 1) * o[j])) if tdoa else c

    out, conditions = [], []
    if config.parametrization == "direct":
        def position(prefix: str, i: int) -> list:
            return [x.get(f"{prefix}{i}{'xyz'[a]}", zero) for a in range(k)]

        for name in formulation.equations:
            i, j = (int(v) for v in name[1:].split("_"))
            dist = zero
            for ra, sa in zip(position("r", i), position("s", j)):
                dist = dist + (ra - sa) * (ra - sa)
            out.append(d2(i, j) - dist)
        return out, conditions
    if config.parametrization == "gram":
        G = [[x[f"g{min(a, c) + 1}{max(a, c) + 1}"] for c in range(k)] for a in range(k)]
        det, adj = _det_generic(G, zero), _adjugate_generic(G, zero)
        ws: dict = {}

        def w(j: int) -> list:  # w_j,a = G_aa + d_1j^2 - d_{a+1,j}^2 = G_aa - e p
            if j not in ws:
                ws[j] = [G[a][a] - e(a + 2, j) * p(a + 2, j) for a in range(k)]
            return ws[j]

        for name in formulation.equations:
            if name[0] == "S":
                j = int(name[1:])
                wj, quad = w(j), zero
                for a in range(k):
                    row = zero
                    for c in range(k):
                        row = row + adj[a][c] * wj[c]
                    quad = quad + wj[a] * row
                out.append(quad - 4 * (d2(1, j) * det))
            else:
                i, j = (int(v) for v in name[1:].split("_"))
                alpha = [x[f"a{i}_{a + 1}"] for a in range(k)]
                wj, gaa, aw = w(j), zero, zero
                for a in range(k):
                    row = zero
                    for c in range(k):
                        row = row + G[a][c] * alpha[c]
                    gaa = gaa + alpha[a] * row
                    aw = aw + alpha[a] * wj[a]
                out.append(gaa - e(i, j) * p(i, j) - aw)
        return out, conditions
    H = [[x[f"h{min(a, c) + 1}{max(a, c) + 1}"] for c in range(k)] for a in range(k)]
    b = [x[f"b{a + 1}"] for a in range(k)]
    det, adj = _det_generic(H, zero), _adjugate_generic(H, zero)

    def form(u, v):  # u^T adj(H) v
        acc = zero
        for a in range(k):
            for c in range(k):
                acc = acc + u[a] * (adj[a][c] * v[c])
        return acc

    head = None
    for name in formulation.equations:
        fam = _family(name)
        if fam == "A":
            out.append(d2(1, 1) * det - form(b, b))
        elif fam == "B" and int(name[1:]) <= k + 1:
            j = int(name[1:])
            out.append((d2(1, j) - d2(1, 1)) * det - quarter * adj[j - 2][j - 2] + form(b, [zero + int(a == j - 2) for a in range(k)]))
        elif fam == "B":
            j = int(name[1:])
            if head is None:
                M = [[comp(a, c) for c in range(1, k + 1)] for a in range(1, k + 1)]
                dm = _det_generic(M, zero)
                if tdoa:
                    conditions.append(dm)
                else:
                    dm = define("dm", dm)
                head = (dm, _adjugate_generic(M, zero))
            dm, adj_m = head
            column = [comp(a, j - 1) for a in range(1, k + 1)]
            u = []
            for a in range(k):
                acc = zero
                for c in range(k):
                    acc = acc + adj_m[a][c] * column[c]
                u.append(acc if tdoa else define(f"u{j}_{a + 1}", acc))
            out.append((d2(1, j) - d2(1, 1)) * (dm * dm) * det - quarter * form(u, u) + dm * form(b, u))
        elif fam == "C":
            i = int(name[1:])
            r = [comp(i - 1, a) for a in range(1, k + 1)]
            quad, lin = zero, zero
            for a in range(k):
                lin = lin + b[a] * r[a]
                for c in range(k):
                    quad = quad + H[a][c] * (r[a] * r[c])
            out.append(d2_diff(i, 1) - quad + 2 * lin)
        else:
            rows, cols = _parse_minor(config, name)
            out.append(_det_generic([[comp(r, c) for c in cols] for r in rows], zero))
    return out, conditions
