"""Problem definitions for 2D TDOA self-calibration: equations, samplers with a known root, symmetry.

This module owns the polynomial formulations of the paper (Sections 2-3): which equations exist for an
m-receiver / n-transmitter configuration, their exact form (symbolic, over GF(p), over the reals, or as
coefficient expressions for code generation), consistent random instances together with their known
root, and the relabeling symmetry used to enumerate formulations up to equivalence.

Problem (paper Section 2.2). Measurements f_ij (receiver i = 1..m, transmitter j = 1..n) satisfy
d_ij^2 = (f_ij - o_j)^2 with unknown transmitter offsets o_j. The compaction matrix, (m-1) x (n-1), is

    D~_ij = d^2_{i+1,j+1} - d^2_{1,j+1} - d^2_{i+1,1} + d^2_{11}

(the paper prints d_{i+1,j} for the third term; see reference/NOTES.md). The squared offsets cancel, so
every entry is affine in the offsets:

    D~_ij = c_ij + alpha_i o_1 + beta_ij o_{j+1},
    c_ij    = f^2_{i+1,j+1} - f^2_{1,j+1} - f^2_{i+1,1} + f^2_{11},
    alpha_i = 2 (f_{i+1,1} - f_{11}),        beta_ij = -2 (f_{i+1,j+1} - f_{1,j+1}).

Factorisation (paper Section 3.1): D^ = D~[:, :2] = R~^T S~ with R~ = D^^T and S~ = I (transmitters 1-3).
Unknowns, always in this order: h11, h12, h22 (symmetric H = (L^T L)^{-1}), b1, b2, o1..on.

Equation families and sign conventions (each is exactly the expression below, "= 0"):

* ``A``:  d11^2 det(H) - b^T adj(H) b  (paper's (A) times det H; adj(H) = det(H) H^{-1}).
* ``Bj`` (j = 2, 3): (d1j^2 - d11^2) det(H) - 1/4 e^T adj(H) e + b^T adj(H) e,  e = e_{j-1}
  (paper's (B) times det H; only j = 2, 3 because S~ = I is 2 x 2).
* ``Ci`` (i = 2..m): d_i1^2 - d11^2 - (R~_{i-1}^T H R~_{i-1} - 2 b^T R~_{i-1}),  R~_{i-1} = row i-1 of D^.
* minors (n >= 4): det of the 3 x 3 submatrix of the full D~ with rows and columns in increasing order,
  named ``M<rows>_<cols>`` with 1-based D~ indices, e.g. ``M123_123``; when m-1 > 9 or n-1 > 9 the
  indices of every minor of that configuration are separated by dots, e.g. ``M1.2.10_1.2.3``.

Degrees in (H, b): A 3, B 2, C 1; total degrees: A 4, B 4, C 3; minors have degree 3 in the offsets.
Multiplying (A) and (B) by det H may add spurious roots with det H = 0 (NOTES.md): saturate downstream.

Known root (derivation, paper eq. (toa_upgrade)): with r_1 = 0, s_1 = L b, s_j = L(-1/2 S~_{j-1} + b) and
S~ = I we get S := [s_2 - s_1, s_3 - s_1] = -1/2 L, so L = -2 S, H = (L^T L)^{-1} = (4 S^T S)^{-1},
b = L^{-1} s_1 = -1/2 S^{-1} s_1. Consistency check: r_i = L^{-T} R~_{i-1} gives R~^T = R^T L = -2 R^T S = D^,
the TOA factorisation D~ = -2 R^T S of Section 2.1. The root is invariant under rotations and
reflections of the network (L -> Q L leaves L^T L and L^{-1} s_1 unchanged), so no rotation gauge is
needed (the paper's r_2 = [r_2x, 0] gauge only matters when recovering positions); translation is fixed
by r_1 = 0.

Other models and dimensions: :class:`TDOAConfig` also takes ``model="toa"`` (no offsets), ``dim=3`` and
``parametrization="direct"`` (positions as unknowns); their equations, samplers and roots live in
:mod:`analysis.formulations.kd`, to which the public functions here dispatch. The definitions both share
(:class:`TDOAConfig`, :class:`Formulation`, :class:`Instance`, equation names, GF(p) square roots) live in
:mod:`analysis.formulations.base`, below both, and are re-exported here. The symbolic reference,
code generation and the relabeling symmetry stay with the paper's 2D TDOA formulation.

The GF(p) and QQ[f] paths are exact. The float paths (:func:`real_equations`,
:func:`sample_real_instance`) exist only to check numeric solvers at a real root. This module never
imports ``solvers``.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Iterable, Iterator, Literal, Mapping, Sequence, Union

import numpy as np

# the shared definitions, re-exported: users and solvers import them from here
from .base import (DIMENSIONS, MODELS, PARAMETRIZATIONS, RECEIVERS_FIRST_LIMIT, REJECTION_LIMIT,
                               EquationCounts, Exponent, Formulation, GFPolynomial, InconsistentSample, Instance,
                               RealPolynomial, SamplingFailed, TDOAConfig, _as_config, _describe_names, _family,
                               _minor_name, _no_minors, _parse_minor, _powmod_vec, _residue_mask, _rng,
                               as_formulation, equation_names, is_quadratic_residue, parse_equations,
                               require_planar_tdoa, sqrt_mod)
from .kd import build_equations, sample_gf_instance_kd, sample_real_instance_kd
from ..engine.ring import BadPrime, check_prime

# sympy is imported by the functions that use it (the symbolic reference, code generation): the GF(p)
# and real equations, and with them `tdoa-workbench degree --tdoa`, do without its 0.4 s import.

__all__ = [
    "DIMENSIONS",
    "MODELS",
    "PARAMETRIZATIONS",
    "BadPrime",
    "EquationCounts",
    "Formulation",
    "InconsistentSample",
    "Instance",
    "Relabeling",
    "SamplingFailed",
    "TDOAConfig",
    "as_formulation",
    "canonical_form",
    "check_root",
    "coefficient_expressions",
    "data_symbols",
    "enumerate_formulations",
    "equation_names",
    "evaluate_gf",
    "evaluate_real",
    "gf_equations",
    "require_planar_tdoa",
    "is_quadratic_residue",
    "parse_equations",
    "real_equations",
    "sample_gf_instance",
    "sample_real_instance",
    "sqrt_mod",
    "symbolic_equations",
    "unknown_symbols",
]


# Index of each (H, b) unknown; the offset o_j (1-based j) sits at index 4 + j.
_H11, _H12, _H22, _B1, _B2 = range(5)



# --------------------------------------------------------------------------------------------------
# Symbols and the symbolic reference
# --------------------------------------------------------------------------------------------------


def unknown_symbols(config: TDOAConfig) -> tuple[sympy.Symbol, ...]:
    """sympy symbols of the unknowns, in unknown order."""
    import sympy

    return tuple(sympy.Symbol(x) for x in config.unknowns)


def data_symbols(config: TDOAConfig) -> tuple[tuple[sympy.Symbol, ...], ...]:
    """sympy symbols ``f<i>_<j>`` of the measurements, as an m x n nested tuple (1-based names)."""
    import sympy

    return tuple(tuple(sympy.Symbol(f"f{i}_{j}") for j in range(1, config.n + 1)) for i in range(1, config.m + 1))


def symbolic_equations(formulation: Formulation) -> dict[str, sympy.Expr]:
    """The equations as expanded sympy expressions in the unknowns and the data symbols.

    This is the slow, obviously-correct reference: it writes the paper's formulas with sympy matrices
    (d^2 = (f - o)^2, compaction matrix, adjugate, determinants) and is independent of the sparse
    builder behind :func:`gf_equations`, :func:`real_equations` and :func:`coefficient_expressions`.

    Returns a dict name -> expression in the order of ``formulation.equations``. Paper Sections 2-3.
    """
    import sympy

    config = formulation.config
    require_planar_tdoa(config, "symbolic_equations")
    m, n = config.m, config.n
    h11, h12, h22, b1, b2, *offsets = unknown_symbols(config)
    f = sympy.Matrix(data_symbols(config))
    d2 = sympy.Matrix(m, n, lambda i, j: (f[i, j] - offsets[j]) ** 2)
    compaction = sympy.Matrix(m - 1, n - 1, lambda i, j: d2[i + 1, j + 1] - d2[0, j + 1] - d2[i + 1, 0] + d2[0, 0])
    H = sympy.Matrix([[h11, h12], [h12, h22]])
    b = sympy.Matrix([b1, b2])
    adj, det = H.adjugate(), H.det()
    r_tilde = compaction[:, :2].T  # column i-1 is R~_{i-1}
    out: dict[str, sympy.Expr] = {}
    for name in formulation.equations:
        fam = _family(name)
        if fam == "A":
            expr = d2[0, 0] * det - (b.T * adj * b)[0, 0]
        elif fam == "B":
            j = int(name[1:])
            e = sympy.Matrix([1, 0]) if j == 2 else sympy.Matrix([0, 1])
            expr = (d2[0, j - 1] - d2[0, 0]) * det - sympy.Rational(1, 4) * (e.T * adj * e)[0, 0] + (b.T * adj * e)[0, 0]
        elif fam == "C":
            i = int(name[1:])
            r = r_tilde[:, i - 2]
            expr = d2[i - 1, 0] - d2[0, 0] - ((r.T * H * r)[0, 0] - 2 * (b.T * r)[0, 0])
        else:
            rows, cols = _parse_minor(config, name)
            expr = compaction.extract([r - 1 for r in rows], [c - 1 for c in cols]).det(method="berkowitz")
        out[name] = sympy.expand(expr)
    return out


def _symbols(prefix: str, m: int, n: int, first: int = 1) -> list[list[sympy.Symbol]]:
    import sympy

    return [[sympy.Symbol(f"{prefix}{i}_{j}") for j in range(1, n + 1)] for i in range(first, m + 1)]


def definition_order(symbols) -> list:
    """The factored data symbols of :func:`factored_equations` in dependency order: e, p (from f), then c."""
    return sorted(symbols, key=lambda s: ("epc".index(s.name[0]), tuple(int(v) for v in s.name[1:].split("_"))))


def factored_equations(formulation: Formulation) -> tuple[list[sympy.Poly], dict[sympy.Symbol, sympy.Expr]]:
    """The equations as polynomials in the unknowns whose coefficients are expressions in the factored
    data symbols, and the definitions of those symbols in terms of f<i>_<j>.

    Symbols: e<i>_<j> = f_ij - f_1j and p<i>_<j> = f_ij + f_1j (i >= 2), c<i>_<j> = e p - e p (the
    constant of D~_ij), f1_<j>. Same conventions as :func:`analysis.formulations.tdoa.symbolic_equations`
    (paper Sections 2-3); checked against it numerically in tests/test_generated.py.
    """
    import sympy

    config = formulation.config
    require_planar_tdoa(config, "factored_equations")
    m, n = config.m, config.n
    unknowns = unknown_symbols(config)
    h11, h12, h22, b1, b2, *offsets = unknowns
    f = _symbols("f", m, n)
    e = [[None] * n] + _symbols("e", m, n, first=2)
    p = [[None] * n] + _symbols("p", m, n, first=2)
    c = _symbols("c", m - 1, n - 1)
    defs: dict[sympy.Symbol, sympy.Expr] = {}
    for i in range(1, m):
        for j in range(n):
            defs[e[i][j]] = f[i][j] - f[0][j]
            defs[p[i][j]] = f[i][j] + f[0][j]
    for i in range(m - 1):
        for j in range(n - 1):
            defs[c[i][j]] = e[i + 1][j + 1] * p[i + 1][j + 1] - e[i + 1][0] * p[i + 1][0]

    def comp(i: int, j: int):  # D~_ij, 1-based
        return c[i - 1][j - 1] + 2 * e[i][0] * offsets[0] - 2 * e[i][j] * offsets[j]

    def d2_diff(i: int, j: int):  # d_ij^2 - d_1j^2, i >= 2
        return e[i - 1][j - 1] * (p[i - 1][j - 1] - 2 * offsets[j - 1])

    H = sympy.Matrix([[h11, h12], [h12, h22]])
    b = sympy.Matrix([b1, b2])
    adj, det = H.adjugate(), H.det()
    d2_11 = (f[0][0] - offsets[0]) ** 2
    out = []
    for name in formulation.equations:
        if name == "A":
            expr = d2_11 * det - (b.T * adj * b)[0, 0]
        elif name.startswith("B"):
            j = int(name[1:])
            ev = sympy.Matrix([1, 0]) if j == 2 else sympy.Matrix([0, 1])
            lhs = (f[0][j - 1] - offsets[j - 1]) ** 2 - d2_11
            expr = lhs * det - sympy.Rational(1, 4) * (ev.T * adj * ev)[0, 0] + (b.T * adj * ev)[0, 0]
        elif name.startswith("C"):
            i = int(name[1:])
            r = sympy.Matrix([comp(i - 1, 1), comp(i - 1, 2)])
            expr = d2_diff(i, 1) - ((r.T * H * r)[0, 0] - 2 * (b.T * r)[0, 0])
        else:
            rows_s, cols_s = name[1:].split("_")
            sep = "." if "." in name else ""
            rows = [int(x) for x in (rows_s.split(".") if sep else rows_s)]
            cols = [int(x) for x in (cols_s.split(".") if sep else cols_s)]
            expr = sympy.Matrix(3, 3, lambda a, bb: comp(rows[a], cols[bb])).det(method="berkowitz")
        out.append(sympy.Poly(sympy.expand(expr), *unknowns))
    return out, defs


# --------------------------------------------------------------------------------------------------
# Fast sparse builder (one implementation for GF(p), float and sympy coefficients)
# --------------------------------------------------------------------------------------------------

_Kind = Literal["gf", "real", "sym"]


@dataclass(frozen=True)
class _Coefficients:
    """Coefficient arithmetic of the builder: integers mod p, floats, or polynomials in QQ[f]."""

    kind: _Kind
    prime: int | None = None
    ring: object = None  # QQ[f] for kind "sym"

    def quarter(self):
        if self.kind == "gf":
            return pow(4, -1, self.prime)
        if self.kind == "real":
            return 0.25
        import sympy

        return sympy.QQ(1, 4)

    def finish(self, value):
        """Final normal form of a coefficient (reduced mod p, float, or an element of QQ[f]).

        Symbolic coefficients are sparse polynomials over QQ in the data (``sympy.polys.rings``), which
        expand exactly and much faster than ``sympy.expand`` on expression trees.
        """
        if self.kind == "gf":
            return int(value) % self.prime
        if self.kind == "real":
            return float(value)
        from sympy.polys.rings import PolyElement

        return value if isinstance(value, PolyElement) else self.ring(value)

    def array(self, rows) -> np.ndarray:
        dtype = {"gf": np.int64, "real": np.float64, "sym": object}[self.kind]
        return np.array(rows, dtype=dtype)

    def mul_array(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        # p < 2^31, so a product of two reduced residues fits in int64.
        return a * b % self.prime if self.kind == "gf" else a * b

    def reduce_array(self, a: np.ndarray) -> np.ndarray:
        return a % self.prime if self.kind == "gf" else a


def _padd(*polys: Mapping) -> dict:
    out: dict = {}
    for poly in polys:
        for exp, c in poly.items():
            out[exp] = out.get(exp, 0) + c
    return out


def _pscale(poly: Mapping, c) -> dict:
    return {exp: c * v for exp, v in poly.items()}


def _pmul(a: Mapping, b: Mapping) -> dict:
    out: dict = {}
    for ea, ca in a.items():
        for eb, cb in b.items():
            exp = tuple(x + y for x, y in zip(ea, eb))
            out[exp] = out.get(exp, 0) + ca * cb
    return out


class _Builder:
    """Builds the equations of one configuration for one data matrix with sparse dict arithmetic."""

    def __init__(self, config: TDOAConfig, data: Sequence[Sequence], coeffs: _Coefficients):
        self.config, self.coeffs = config, coeffs
        self.nvars = config.n_unknowns
        m, n = config.m, config.n
        F = data
        fin = coeffs.finish if coeffs.kind != "sym" else (lambda v: v)
        # Compaction matrix D~ = const + alpha o1 + beta o_{j+1} (module docstring).
        self.const = [[fin(F[i + 1][j + 1] ** 2 - F[0][j + 1] ** 2 - F[i + 1][0] ** 2 + F[0][0] ** 2)
                       for j in range(n - 1)] for i in range(m - 1)]
        self.alpha = [fin(2 * (F[i + 1][0] - F[0][0])) for i in range(m - 1)]
        self.beta = [[fin(-2 * (F[i + 1][j + 1] - F[0][j + 1])) for j in range(n - 1)] for i in range(m - 1)]
        self.F = F

    def unit(self, *indices: int) -> Exponent:
        exp = [0] * self.nvars
        for k in indices:
            exp[k] += 1
        return tuple(exp)

    def var(self, k: int) -> dict:
        return {self.unit(k): 1}

    def offset_index(self, j: int) -> int:
        """Unknown index of o_j (1-based transmitter j)."""
        return 4 + j

    def d2(self, i: int, j: int) -> dict:
        """d_ij^2 = (f_ij - o_j)^2, 1-based indices."""
        f, k = self.F[i - 1][j - 1], self.offset_index(j)
        return {self.unit(): f * f, self.unit(k): -2 * f, self.unit(k, k): 1}

    def compaction(self, i: int, j: int) -> dict:
        """Entry D~_ij (1-based) as an affine polynomial in the offsets."""
        return {self.unit(): self.const[i - 1][j - 1], self.unit(self.offset_index(1)): self.alpha[i - 1],
                self.unit(self.offset_index(j + 1)): self.beta[i - 1][j - 1]}

    def hb(self) -> tuple[dict, dict, dict, dict, dict]:
        return tuple(self.var(k) for k in (_H11, _H12, _H22, _B1, _B2))

    def det_h(self) -> dict:
        h11, h12, h22, _, _ = self.hb()
        return _padd(_pmul(h11, h22), _pscale(_pmul(h12, h12), -1))

    def equation_a(self) -> dict:
        h11, h12, h22, b1, b2 = self.hb()
        b_adj_b = _padd(_pmul(h22, _pmul(b1, b1)), _pscale(_pmul(h12, _pmul(b1, b2)), -2), _pmul(h11, _pmul(b2, b2)))
        return _padd(_pmul(self.d2(1, 1), self.det_h()), _pscale(b_adj_b, -1))

    def equation_b(self, j: int) -> dict:
        h11, h12, h22, b1, b2 = self.hb()
        if j == 2:  # e = e_1: e^T adj e = h22, b^T adj e = b1 h22 - b2 h12
            e_adj_e, b_adj_e = h22, _padd(_pmul(b1, h22), _pscale(_pmul(b2, h12), -1))
        else:  # e = e_2: e^T adj e = h11, b^T adj e = -b1 h12 + b2 h11
            e_adj_e, b_adj_e = h11, _padd(_pscale(_pmul(b1, h12), -1), _pmul(b2, h11))
        lhs = _padd(self.d2(1, j), _pscale(self.d2(1, 1), -1))
        return _padd(_pmul(lhs, self.det_h()), _pscale(e_adj_e, -self.coeffs.quarter()), b_adj_e)

    def equation_c(self, i: int) -> dict:
        h11, h12, h22, b1, b2 = self.hb()
        x, y = self.compaction(i - 1, 1), self.compaction(i - 1, 2)
        quad = _padd(_pmul(h11, _pmul(x, x)), _pscale(_pmul(h12, _pmul(x, y)), 2), _pmul(h22, _pmul(y, y)))
        lin = _padd(_pmul(b1, x), _pmul(b2, y))
        lhs = _padd(self.d2(i, 1), _pscale(self.d2(1, 1), -1))
        return _padd(lhs, _pscale(quad, -1), _pscale(lin, 2))

    def minors(self, index_sets: Sequence[tuple[tuple[int, ...], tuple[int, ...]]]) -> list[dict]:
        """3 x 3 minors of D~ in normal form, vectorised over all requested (rows, cols) (1-based).

        D~ is multilinear in its columns and column j is const_j + alpha o1 + beta_j o_{j+1}, so a minor is
        the sum over choices (const | alpha | beta) per column of numeric determinants times the monomial
        o1^{#alpha} prod o_{j+1}^{[beta]}; the alpha column does not depend on j, so choices with two or
        more alphas vanish, leaving 20 determinants per minor.
        """
        if not index_sets:
            return []
        cf = self.coeffs
        rows = np.array([r for r, _ in index_sets], dtype=np.int64) - 1  # (K, 3)
        cols = np.array([c for _, c in index_sets], dtype=np.int64) - 1  # (K, 3)
        const, alpha, beta = cf.array(self.const), cf.array(self.alpha), cf.array(self.beta)
        vectors = []
        for q in range(3):
            col = cols[:, q][:, None]
            vectors.append((const[rows, col], alpha[rows], beta[rows, col]))  # each (K, 3)
        mul = cf.mul_array
        # Choices giving the same monomial (alpha in a different column, same beta columns) are summed
        # in the vectorised stage; "pattern" = (has alpha, beta positions).
        patterns: dict[tuple, object] = {}
        for t in itertools.product(range(3), repeat=3):
            if t.count(1) > 1:
                continue
            u, v, w = (vectors[q][t[q]] for q in range(3))
            m0 = cf.reduce_array(mul(v[:, 1], w[:, 2]) - mul(v[:, 2], w[:, 1]))
            m1 = cf.reduce_array(mul(v[:, 0], w[:, 2]) - mul(v[:, 2], w[:, 0]))
            m2 = cf.reduce_array(mul(v[:, 0], w[:, 1]) - mul(v[:, 1], w[:, 0]))
            det = cf.reduce_array(mul(u[:, 0], m0) - mul(u[:, 1], m1) + mul(u[:, 2], m2))
            key = (1 in t, tuple(q for q in range(3) if t[q] == 2))
            patterns[key] = det if key not in patterns else cf.reduce_array(patterns[key] + det)
        keys = list(patterns)
        values = np.stack([patterns[k] for k in keys], axis=1).tolist()  # (K, #patterns)
        o1 = self.offset_index(1)
        exponents: dict[tuple[int, ...], list[Exponent]] = {}
        out = []
        for (_, col_set), vals in zip(index_sets, values):
            exps = exponents.get(col_set)
            if exps is None:
                exps = []
                for has_alpha, betas in keys:
                    exp = [0] * self.nvars
                    exp[o1] += has_alpha
                    for q in betas:
                        exp[self.offset_index(col_set[q] + 1)] += 1
                    exps.append(tuple(exp))
                exponents[col_set] = exps
            finished = (cf.finish(x) for x in vals) if cf.kind == "sym" else vals
            out.append({e: x for e, x in zip(exps, finished) if x != 0})
        return out

    def build(self, names: Sequence[str]) -> list[dict]:
        """Equations in the given order, coefficients in normal form, zero terms dropped."""
        minor_names = [x for x in names if _family(x) == "minors"]
        minor_polys = dict(zip(minor_names, self.minors([_parse_minor(self.config, x) for x in minor_names])))
        result = []
        for name in names:
            fam = _family(name)
            if fam == "A":
                poly = self.equation_a()
            elif fam == "B":
                poly = self.equation_b(int(name[1:]))
            elif fam == "C":
                poly = self.equation_c(int(name[1:]))
            else:
                result.append(minor_polys[name])  # already in normal form
                continue
            finished = {exp: self.coeffs.finish(c) for exp, c in poly.items()}
            result.append({exp: c for exp, c in finished.items() if c != 0})
        return result


def _data_matrix(config: TDOAConfig, data) -> list[list]:
    rows = [list(r) for r in (data.F if isinstance(data, Instance) else data)]
    if len(rows) != config.m or any(len(r) != config.n for r in rows):
        shape = (len(rows), len(rows[0]) if rows else 0)
        raise ValueError(f"data must be {config.m} x {config.n} (receivers x transmitters) for {config.label}, got {shape}")
    return rows


def gf_equations(formulation: Formulation, data: "Instance | Sequence[Sequence[int]]", p: int | None = None) -> list[GFPolynomial]:
    """The equations of a formulation for one data matrix over GF(p).

    Parameters
    ----------
    formulation : which equations.
    data : an :class:`Instance` over GF(p) or an m x n array of integers (reduced mod p here).
    p : the prime; optional when ``data`` is a GF(p) instance (must agree with it if given).

    Returns one dict {exponent tuple in unknown order: coefficient in [1, p)} per equation, in the order
    of ``formulation.equations``. Built with sparse dict arithmetic (no sympy) and minors vectorised
    in numpy: about 6 ms for all 571 equations of 9r/6s. Paper Sections 2.1-2.2, 3.1-3.2.
    """
    if isinstance(data, Instance):
        if data.prime is None:
            raise ValueError("gf_equations needs a GF(p) instance; this one is over the reals (use real_equations)")
        if p is not None and p != data.prime:
            raise BadPrime(f"prime {p} disagrees with the instance's prime {data.prime}")
        p = data.prime
    if p is None:
        raise BadPrime("gf_equations needs a prime p when data is a plain matrix")
    p = check_prime(p)
    rows = [[int(x) % p for x in r] for r in _data_matrix(formulation.config, data)]
    if not formulation.config.is_planar_tdoa:
        return build_equations(formulation, rows, p)
    return _Builder(formulation.config, rows, _Coefficients("gf", p)).build(formulation.equations)


def real_equations(formulation: Formulation, data: "Instance | Sequence[Sequence[float]]") -> list[RealPolynomial]:
    """The equations of a formulation for one real data matrix, float coefficients.

    Same layout as :func:`gf_equations` (exact zeros dropped). Used to evaluate at a real root.
    Paper Sections 2.1-2.2, 3.1-3.2.
    """
    if isinstance(data, Instance) and data.prime is not None:
        raise ValueError("real_equations needs a real instance; this one is over GF(p) (use gf_equations)")
    rows = [[float(x) for x in r] for r in _data_matrix(formulation.config, data)]
    if not formulation.config.is_planar_tdoa:
        return build_equations(formulation, rows, None)
    return _Builder(formulation.config, rows, _Coefficients("real")).build(formulation.equations)


def coefficient_expressions(formulation: Formulation, form: Literal["expr", "ring"] = "expr") -> list[dict[Exponent, object]]:
    """Per equation, {exponent tuple: coefficient as an exact polynomial in the data ``f<i>_<j>``}.

    The same sparse builder as :func:`gf_equations`, with coefficients in QQ[f]; meant for generating
    numeric solver code (coefficients as functions of the measurements). Paper Sections 3.1-3.2.

    Parameters
    ----------
    formulation : which equations.
    form : ``"expr"`` (default) for expanded sympy expressions, ``"ring"`` for the underlying
        ``sympy.polys.rings.PolyElement`` over QQ (much faster for many minors: the conversion to
        expressions dominates, about 0.1 s per minor).
    """
    if form not in ("expr", "ring"):
        raise ValueError(f"form must be 'expr' or 'ring', got {form!r}")
    import sympy
    from sympy.polys.rings import ring as poly_ring

    config = formulation.config
    require_planar_tdoa(config, "coefficient_expressions")
    symbols = data_symbols(config)
    qq_ring, *gens = poly_ring(list(itertools.chain.from_iterable(symbols)), sympy.QQ)
    data = [gens[i * config.n:(i + 1) * config.n] for i in range(config.m)]
    polys = _Builder(config, data, _Coefficients("sym", ring=qq_ring)).build(formulation.equations)
    if form == "ring":
        return polys
    return [{exp: c.as_expr() for exp, c in poly.items()} for poly in polys]


def evaluate_gf(poly: Mapping[Exponent, int], point: Sequence[int], p: int) -> int:
    """Value in [0, p) of a GF(p) polynomial (exponent dict) at a point."""
    total = 0
    for exp, c in poly.items():
        term = c
        for x, e in zip(point, exp):
            if e:
                term = term * pow(int(x), e, p) % p
        total += term
    return total % p


def evaluate_real(poly: Mapping[Exponent, float], point: Sequence[float]) -> tuple[float, float]:
    """(value, scale) of a real polynomial at a point; scale = sum of |terms|, for relative residuals."""
    value = scale = 0.0
    for exp, c in poly.items():
        term = float(c)
        for x, e in zip(point, exp):
            if e:
                term *= float(x) ** e
        value += term
        scale += abs(term)
    return value, scale



def _gf_root(receivers, transmitters, offsets, p: int) -> tuple[int, ...] | None:
    """Known root (H, b, o) over GF(p) for r_1 = 0, or None if S = [s2-s1, s3-s1] is singular."""
    (s1x, s1y), (s2x, s2y), (s3x, s3y) = transmitters[:3]
    a, bb, c, d = (s2x - s1x) % p, (s3x - s1x) % p, (s2y - s1y) % p, (s3y - s1y) % p  # S = [[a, bb], [c, d]]
    det_s = (a * d - bb * c) % p
    if det_s == 0:
        return None
    # M = 4 S^T S, H = M^{-1}
    m11, m12, m22 = 4 * (a * a + c * c) % p, 4 * (a * bb + c * d) % p, 4 * (bb * bb + d * d) % p
    inv_det_m = pow((m11 * m22 - m12 * m12) % p, -1, p)  # det M = 16 det(S)^2 != 0
    h11, h12, h22 = m22 * inv_det_m % p, -m12 * inv_det_m % p, m11 * inv_det_m % p
    # b = -1/2 S^{-1} s_1, S^{-1} = [[d, -bb], [-c, a]] / det S
    k = -pow(2 * det_s, -1, p)
    b1, b2 = k * (d * s1x - bb * s1y) % p, k * (-c * s1x + a * s1y) % p
    return (h11, h12, h22, b1, b2) + tuple(int(o) % p for o in offsets)



def sample_gf_instance(config: TDOAConfig | str, p: int, rng: "np.random.Generator | int", *,
                       max_batches: int = 200) -> Instance:
    """A consistent random instance over GF(p) with its known root.

    For m <= :data:`RECEIVERS_FIRST_LIMIT` receivers it draws, in this order: receivers r_2..r_m uniform
    in GF(p)^2 (r_1 = 0 fixes translation); then each transmitter s_1, s_2, ... uniformly among the
    points whose squared distance to every receiver is a nonzero quadratic residue (rejection in
    vectorised batches; s_3 is also redrawn while S = [s_2 - s_1, s_3 - s_1] is singular); then offsets
    o_j uniform in GF(p). A random point passes with probability about 2^-m, so for more receivers the
    roles swap: transmitters s_1..s_n uniform (s_3 redrawn while S is singular), then receivers among the
    points at residue squared distance from every transmitter (probability about 2^-n; several per
    batch), then the offsets, and the network is translated so that r_1 = 0. Measurements are
    f_ij = sqrt(d_ij^2) + o_j with the smaller square root.

    Parameters
    ----------
    config : configuration or label.
    p : prime, 2 < p < 2^31 (``BadPrime`` otherwise).
    rng : ``numpy.random.default_rng(seed)`` or an integer seed.
    max_batches : rejection budget per point; ``SamplingFailed`` (naming the seed) if exceeded.

    Raises ``SamplingFailed`` at once when both m and n exceed :data:`REJECTION_LIMIT`, and when the
    budget runs out (only plausible for small p, where few points qualify).
    Paper Sections 2.1 and 3.1 (known root: module docstring).
    """
    config = _as_config(config)
    p = check_prime(p)
    if p == 2:  # every prime is a characteristic of the engine; the sampler takes square roots
        raise BadPrime("the instance sampler needs an odd prime (it takes square roots of squared distances)")
    if not config.is_planar_tdoa:
        return sample_gf_instance_kd(config, p, rng, max_batches=max_batches)
    gen, seed_text = _rng(rng)
    m, n = config.m, config.n
    if min(m, n) > REJECTION_LIMIT:
        raise SamplingFailed(
            f"{config.label}: cannot sample a GF(p) instance with more than {REJECTION_LIMIT} receivers and more "
            f"than {REJECTION_LIMIT} transmitters (every point must lie at a square distance from all points on the "
            f"other side, probability about 2^-{min(m, n)} per candidate); use fewer receivers or transmitters")
    receivers_first = m <= RECEIVERS_FIRST_LIMIT

    def singular_s(s1, s2, s3) -> bool:
        return ((s2[0] - s1[0]) * (s3[1] - s1[1]) - (s3[0] - s1[0]) * (s2[1] - s1[1])) % p == 0

    if receivers_first:
        receivers = np.zeros((m, 2), dtype=np.int64)
        receivers[1:] = gen.integers(0, p, size=(m - 1, 2))
        batch = int(min(max(64, 4 * 2 ** m), 1 << 16))

        def draw_transmitter(extra_ok=None) -> np.ndarray:
            for _ in range(max_batches):
                cand = gen.integers(0, p, size=(batch, 2))
                for idx in np.flatnonzero(_residue_mask(cand, receivers, p)):
                    if extra_ok is None or extra_ok(cand[idx]):
                        return cand[idx]
            raise SamplingFailed(f"no transmitter position with all squared distances nonzero residues mod {p} "
                                 f"after {max_batches} batches of {batch} ({config.label}, {seed_text}); "
                                 "use a larger prime or another seed")

        transmitters: list[np.ndarray] = []
        for j in range(n):
            if j == 2:
                s1, s2 = transmitters
                transmitters.append(draw_transmitter(lambda s3: not singular_s(s1, s2, s3)))
            else:
                transmitters.append(draw_transmitter())
    else:
        tx = gen.integers(0, p, size=(n, 2))
        for _ in range(max_batches):
            if not singular_s(*tx[:3]):
                break
            tx[2] = gen.integers(0, p, size=2)
        else:
            raise SamplingFailed(f"no nonsingular S = [s2 - s1, s3 - s1] mod {p} ({config.label}, {seed_text})")
        batch = int(min(max(64, 4 * 2 ** n * m), 1 << 16))
        found: list[np.ndarray] = []
        for _ in range(max_batches * m):
            cand = gen.integers(0, p, size=(batch, 2))
            found.extend(cand[_residue_mask(cand, tx, p)][: m - len(found)])
            if len(found) == m:
                break
        else:
            raise SamplingFailed(f"no receiver position with all squared distances nonzero residues mod {p} "
                                 f"after {max_batches * m} batches of {batch} ({config.label}, {seed_text}); "
                                 "use a larger prime or another seed")
        origin = found[0].copy()
        receivers = (np.array(found, dtype=np.int64) - origin) % p
        transmitters = list((tx - origin) % p)
    offsets = gen.integers(0, p, size=n)
    rec = tuple((int(x), int(y)) for x, y in receivers)
    tra = tuple((int(x), int(y)) for x, y in transmitters)
    offs = tuple(int(o) for o in offsets)
    F = tuple(tuple((sqrt_mod((rx - sx) ** 2 + (ry - sy) ** 2, p) + o) % p for (sx, sy), o in zip(tra, offs))
              for rx, ry in rec)
    root = _gf_root(rec, tra, offs, p)
    assert root is not None  # guaranteed by the S acceptance test (S is invariant under translation)
    return Instance(config, p, F, rec, tra, offs, root)


def sample_real_instance(config: TDOAConfig | str, rng: "np.random.Generator | int", scale: float = 10.0,
                         offset_scale: float = 1.0) -> Instance:
    """A random real instance with its known root (paper Section 4's synthetic setting).

    Draws, in this order: receivers (m x 2) and transmitters (n x 2) from N(0, scale^2), offsets from
    N(0, offset_scale^2). The whole network is then translated so that r_1 = 0 (distances unchanged);
    the returned positions are the translated ones. f_ij = |r_i - s_j| + o_j.

    Parameters
    ----------
    config : configuration or label.
    rng : ``numpy.random.default_rng(seed)`` or an integer seed.
    scale, offset_scale : standard deviations of positions and offsets.
    """
    config = _as_config(config)
    if not config.is_planar_tdoa:
        return sample_real_instance_kd(config, rng, scale, offset_scale)
    gen, _ = _rng(rng)
    m, n = config.m, config.n
    receivers = gen.normal(0.0, scale, size=(m, 2))
    transmitters = gen.normal(0.0, scale, size=(n, 2))
    offsets = gen.normal(0.0, offset_scale, size=n)
    transmitters = transmitters - receivers[0]
    receivers = receivers - receivers[0]
    F = np.linalg.norm(receivers[:, None, :] - transmitters[None, :, :], axis=2) + offsets[None, :]
    S = np.column_stack([transmitters[1] - transmitters[0], transmitters[2] - transmitters[0]])
    H = np.linalg.inv(4.0 * S.T @ S)
    b = -0.5 * np.linalg.solve(S, transmitters[0])
    root = (float(H[0, 0]), float(H[0, 1]), float(H[1, 1]), float(b[0]), float(b[1])) + tuple(map(float, offsets))
    return Instance(config, None, tuple(tuple(map(float, r)) for r in F), tuple(tuple(map(float, r)) for r in receivers),
                    tuple(tuple(map(float, s)) for s in transmitters), tuple(map(float, offsets)), root)


def check_root(formulation: Formulation, instance: Instance, rtol: float = 1e-9) -> None:
    """Raise :class:`InconsistentSample` unless the instance's known root satisfies every equation.

    Exact over GF(p); over the reals |value| <= rtol * sum |terms| per equation.
    """
    if instance.config != formulation.config:
        raise ValueError(f"instance is {instance.config.label}, formulation is {formulation.config.label}")
    bad = []
    if instance.prime is not None:
        for name, poly in zip(formulation.equations, gf_equations(formulation, instance)):
            value = evaluate_gf(poly, instance.root, instance.prime)
            if value:
                bad.append(f"{name} = {value} mod {instance.prime}")
    else:
        for name, poly in zip(formulation.equations, real_equations(formulation, instance)):
            value, scale = evaluate_real(poly, instance.root)
            if abs(value) > rtol * max(scale, np.finfo(float).tiny):
                bad.append(f"{name}: residual {value:.3e} (scale {scale:.3e})")
    if bad:
        raise InconsistentSample(f"known root fails {len(bad)} equation(s) of {formulation.label}: " + "; ".join(bad))


# --------------------------------------------------------------------------------------------------
# Relabeling symmetry and canonical forms
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Relabeling:
    """A relabeling of receivers and transmitters that maps formulations to equivalent formulations.

    Parameters
    ----------
    config : the configuration.
    receivers : ``receivers[i-1]`` is the new label of receiver i (1-based); must fix receiver 1.
    transmitters : ``transmitters[j-1]`` is the new label of transmitter j; must fix 1, map {2, 3} onto
        itself and {4..n} onto itself.

    Why these are symmetries (for generic data). Write E(F) for the polynomial system of equation set E
    on data F, and g(F) for the relabeled data, ``g(F)[sigma(i)][tau(j)] = F[i][j]``.

    * Receivers 2..m: D~ and R~ only have their rows/columns permuted, H, b and the offsets are
      untouched, so C_i(F) = C_{sigma(i)}(g F) identically, minors map to minors up to sign, A and B are
      unchanged. Receiver 1 is the origin and the reference row of D~, so it is not permutable.
    * Transmitters 2 <-> 3: D^ becomes D^ P (P the 2 x 2 swap), R~ becomes P R~, and
      C(gF)(H, b, o) = C(F)(P H P, P b, o o tau); with adj(P H P) = P adj(H) P (det P = -1 cancels)
      the same substitution maps B3(F) to B2(gF) and fixes A. So E(F)(x) = +-g(E)(gF)(pi x) with pi the
      coordinate permutation h11 <-> h22, b1 <-> b2, o2 <-> o3 (:meth:`unknown_permutation`).
    * Transmitters 4..n: only D~ columns 3..n-1 and the offsets o4..on are permuted; A, B, C do not
      involve them.

    In each case the two systems are related by a permutation of the data (which preserves genericity)
    and a permutation of the unknowns, so they have the same number of solutions, the same degree and,
    after saturation, the same saturated degree. Receiver relabelings do not even move the unknowns,
    so they also preserve order-dependent quantities (Groebner basis shape, template size); transmitter
    relabelings permute unknowns and may change those under a fixed monomial order. Paper Section 3.
    """

    config: TDOAConfig
    receivers: tuple[int, ...]
    transmitters: tuple[int, ...]

    def __post_init__(self) -> None:
        require_planar_tdoa(self.config, "Relabeling")
        m, n = self.config.m, self.config.n
        if sorted(self.receivers) != list(range(1, m + 1)) or self.receivers[0] != 1:
            raise ValueError(f"receivers must be a permutation of 1..{m} fixing 1, got {self.receivers}")
        t = self.transmitters
        if sorted(t) != list(range(1, n + 1)) or t[0] != 1 or set(t[1:3]) != {2, 3}:
            raise ValueError(f"transmitters must be a permutation of 1..{n} fixing 1, mapping {{2,3}} and "
                             f"{{4..{n}}} onto themselves, got {t}")

    @classmethod
    def identity(cls, config: TDOAConfig) -> "Relabeling":
        """The identity relabeling."""
        return cls(config, tuple(range(1, config.m + 1)), tuple(range(1, config.n + 1)))

    def equation_name(self, name: str) -> str:
        """Image of one equation name."""
        fam = _family(name)
        if fam == "A":
            return name
        if fam == "B":
            return f"B{self.transmitters[int(name[1:]) - 1]}"
        if fam == "C":
            return f"C{self.receivers[int(name[1:]) - 1]}"
        rows, cols = _parse_minor(self.config, name)
        # D~ row r is receiver r+1, column c is transmitter c+1.
        new_rows = sorted(self.receivers[r] - 1 for r in rows)
        new_cols = sorted(self.transmitters[c] - 1 for c in cols)
        return _minor_name(self.config, new_rows, new_cols)

    def apply(self, formulation: Formulation) -> Formulation:
        """Image of a formulation."""
        if formulation.config != self.config:
            raise ValueError(f"relabeling is for {self.config.label}, formulation is {formulation.config.label}")
        return Formulation(self.config, tuple(self.equation_name(x) for x in formulation.equations))

    def permute_data(self, F: Sequence[Sequence]) -> tuple[tuple, ...]:
        """Relabeled data: ``new[sigma(i)][tau(j)] = F[i][j]``."""
        m, n = self.config.m, self.config.n
        out = [[None] * n for _ in range(m)]
        for i in range(m):
            for j in range(n):
                out[self.receivers[i] - 1][self.transmitters[j] - 1] = F[i][j]
        return tuple(tuple(r) for r in out)

    def unknown_permutation(self) -> tuple[int, ...]:
        """``perm[k]`` is the index of the unknown that old unknown k becomes.

        For relabeled equations on relabeled data, a term with exponent e corresponds to the term with
        exponent e' where e'[perm[k]] = e[k] (up to an overall sign per equation for minors).
        """
        swap = self.transmitters[1] == 3
        hb = (_H22, _H12, _H11, _B2, _B1) if swap else (_H11, _H12, _H22, _B1, _B2)
        return hb + tuple(4 + self.transmitters[j - 1] for j in range(1, self.config.n + 1))


_Key = tuple  # encoded equation: (0,) A, (1, c) B_{c+1}, (2, r) C_{r+1}, (3, rows, cols) minor


def _decode(config: TDOAConfig, key: _Key) -> str:
    if key[0] == 0:
        return "A"
    if key[0] == 1:
        return f"B{key[1] + 1}"
    if key[0] == 2:
        return f"C{key[1] + 1}"
    return _minor_name(config, key[1], key[2])


def _canonical_rows(n_rows: int, head: tuple, c_rows: frozenset, minors: frozenset) -> tuple:
    """Smallest encoded image over the row permutations reached by individualisation-refinement.

    Rows are split into C rows then the rest (so C maps onto rows 1..k), refined by an equivariant
    signature (the minors through a row, described by the cells of their other rows and their
    columns), and remaining ties are broken by individualising each candidate row in the first
    non-singleton cell. Rows u, v whose transposition fixes the equation set are twins: only one of
    them is individualised (the two subtrees have identical leaves). This is a canonical labeling:
    the set of explored leaves is equivariant, so the minimum is an orbit invariant.
    """
    incidence: dict[int, list[tuple[tuple[int, ...], tuple[int, ...]]]] = {r: [] for r in range(1, n_rows + 1)}
    for rows, cols in minors:
        for r in rows:
            incidence[r].append((tuple(x for x in rows if x != r), cols))
    twin_cache: dict[tuple[int, int], bool] = {}

    def twins(u: int, v: int) -> bool:
        key = (min(u, v), max(u, v))
        if key not in twin_cache:
            swap = {u: v, v: u}
            twin_cache[key] = (u in c_rows) == (v in c_rows) and all(
                (tuple(sorted(swap.get(x, x) for x in rows)), cols) in minors for rows, cols in minors)
        return twin_cache[key]

    def refine(cells: list[list[int]]) -> list[list[int]]:
        while True:
            cell_of = {r: idx for idx, cell in enumerate(cells) for r in cell}
            new: list[list[int]] = []
            for cell in cells:
                if len(cell) == 1:
                    new.append(cell)
                    continue
                sig = {r: tuple(sorted((tuple(sorted(cell_of[x] for x in others)), cols) for others, cols in incidence[r]))
                       for r in cell}
                for value in sorted(set(sig.values())):
                    new.append([r for r in cell if sig[r] == value])
            if len(new) == len(cells):
                return new
            cells = new

    def leaf_key(cells: list[list[int]]) -> tuple:
        target = {cell[0]: t + 1 for t, cell in enumerate(cells)}
        c_part = tuple(sorted((2, target[r]) for r in c_rows))
        m_part = tuple(sorted((3, tuple(sorted(target[x] for x in rows)), cols) for rows, cols in minors))
        return head + c_part + m_part

    def search(cells: list[list[int]]) -> tuple:
        cells = refine(cells)
        if len(cells) == n_rows:
            return leaf_key(cells)
        idx = next(t for t, cell in enumerate(cells) if len(cell) > 1)
        cell = cells[idx]
        best, reps = None, []
        for v in cell:
            if any(twins(u, v) for u in reps):
                continue
            reps.append(v)
            key = search(cells[:idx] + [[v], [w for w in cell if w != v]] + cells[idx + 1:])
            if best is None or key < best:
                best = key
        return best

    rows = range(1, n_rows + 1)
    initial = [cell for cell in ([r for r in rows if r in c_rows], [r for r in rows if r not in c_rows]) if cell]
    return search(initial)


def _column_permutations(config: TDOAConfig, has_minors: bool) -> Iterator[dict[int, int]]:
    """Column (transmitter - 1) permutations of the symmetry group: {1,2} and {3..n-1} separately."""
    tail = list(range(3, config.n))
    tails = itertools.permutations(tail) if has_minors else [tuple(tail)]
    for tail_image in tails:
        for head_image in ((1, 2), (2, 1)):
            yield dict(zip([1, 2] + tail, list(head_image) + list(tail_image)))


def canonical_form(formulation: Formulation) -> Formulation:
    """Canonical representative of a formulation under relabeling of receivers 2..m, transmitters
    {2, 3} and transmitters {4..n} (see :class:`Relabeling` for why these preserve the degree).

    Two formulations are equivalent iff their canonical forms are equal, and the canonical form is
    an image of the input under the group. Column relabelings (at most 2 (n-3)!) are enumerated; row
    relabelings use individualisation-refinement (:func:`_canonical_rows`). The representative always
    uses C2..C_{k+1} for k C-equations and B2 when exactly one B-equation is present.
    """
    config = formulation.config
    require_planar_tdoa(config, "canonical_form")
    has_a = "A" in formulation.equations
    b_cols = [int(x[1:]) - 1 for x in formulation.equations if _family(x) == "B"]
    c_rows = frozenset(int(x[1:]) - 1 for x in formulation.equations if _family(x) == "C")
    minors = [_parse_minor(config, x) for x in formulation.equations if _family(x) == "minors"]
    best = None
    for perm in _column_permutations(config, bool(minors)):
        head = ((0,),) if has_a else ()
        head += tuple(sorted((1, perm[c]) for c in b_cols))
        images = frozenset((rows, tuple(sorted(perm[c] for c in cols))) for rows, cols in minors)
        key = _canonical_rows(config.m - 1, head, c_rows, images)
        if best is None or key < best:
            best = key
    return Formulation(config, tuple(_decode(config, k) for k in best))


def _as_counts(value: int | Iterable[int] | None, upper: int, what: str) -> list[int]:
    if value is None:
        return list(range(upper + 1))
    values = [value] if isinstance(value, int) else sorted(set(value))
    for v in values:
        if not 0 <= v <= upper:
            raise ValueError(f"{what} count {v} out of range 0..{upper}")
    return values


MinorSets = Union[Literal["none", "all"], int, Iterable[int], Iterable[Iterable[str]]]


def _minor_candidates(config: TDOAConfig, minor_sets: MinorSets, limit: int) -> list[tuple[str, ...]]:
    minors = [x for x in equation_names(config) if x.startswith("M")]
    if isinstance(minor_sets, str):
        if minor_sets == "none":
            return [()]
        if minor_sets == "all":
            if not minors:
                raise ValueError(f"{config.label} has {_no_minors(config)}")
            return [tuple(minors)]
        raise ValueError(f"minor_sets {minor_sets!r} not understood; use 'none', 'all', a size k, sizes, or explicit sets")
    if isinstance(minor_sets, int):
        minor_sets = [minor_sets]
    items = list(minor_sets)
    if all(isinstance(k, int) for k in items):
        total = sum(math.comb(len(minors), k) for k in items)
        if total > limit:
            raise ValueError(f"{total} minor subsets exceed the limit {limit}; pass explicit sets or raise limit")
        for k in items:
            if not 0 <= k <= len(minors):
                raise ValueError(f"minor subset size {k} out of range 0..{len(minors)} for {config.label}")
        return [c for k in items for c in itertools.combinations(minors, k)]
    out = []
    for item in items:
        if isinstance(item, str):
            raise ValueError("explicit minor sets must be collections of names, not a single string")
        names = tuple(item)
        bad = [x for x in names if x not in minors]
        if bad:
            raise ValueError(f"not minors of {config.label}: {', '.join(bad)}; {_describe_names(config)}")
        out.append(names)
    return out


def enumerate_formulations(config: TDOAConfig | str, nA: int | Iterable[int] | None = None,
                           nB: int | Iterable[int] | None = None, nC: int | Iterable[int] | None = None,
                           minor_sets: MinorSets = "none", total: int | None = None,
                           limit: int = 1_000_000) -> Iterator[Formulation]:
    """Yield one canonical representative per equivalence class of formulations.

    Parameters
    ----------
    config : configuration or label.
    nA, nB, nC : number (or numbers; None = every feasible number) of A (0..1), B (0..2) and C
        (0..m-1) equations.
    minor_sets : ``"none"`` (default), ``"all"``, a subset size k or several sizes (all k-subsets of
        the minors), or an explicit iterable of collections of minor names.
    total : keep only formulations with exactly this many equations (A + B + C + minors).
    limit : refuse to enumerate more than this many minor subsets.

    Every orbit contains a formulation using B2..B_{b+1} and C2..C_{c+1}, so only those are combined
    with the candidate minor sets, canonicalised (:func:`canonical_form`) and deduplicated. Yields in
    order of increasing (A, B, C) counts, then candidate order. Paper Section 3 (Table 2's abc).
    """
    config = _as_config(config)
    require_planar_tdoa(config, "enumerate_formulations")
    candidates = _minor_candidates(config, minor_sets, limit)
    seen: set[tuple[str, ...]] = set()
    for a in _as_counts(nA, 1, "A"):
        for b in _as_counts(nB, 2, "B"):
            for c in _as_counts(nC, config.m - 1, "C"):
                base = ("A",) * a + tuple(f"B{j}" for j in range(2, 2 + b)) + tuple(f"C{i}" for i in range(2, 2 + c))
                for minors in candidates:
                    if total is not None and len(base) + len(minors) != total:
                        continue
                    if not base and not minors:
                        continue
                    rep = canonical_form(Formulation(config, base + tuple(minors)))
                    if rep.equations not in seen:
                        seen.add(rep.equations)
                        yield rep
