"""Can one elimination template solve a formulation? GF(p) relation counts and numerical checks.

An action-matrix solver (Kukelova et al. 2008; Larsson et al. 2017) needs, for a quotient basis B
and an action unknown a, the normal forms of the reducible monomials R = a B \\ B. A single template
is a set of monomial multiples t f_i of the input equations whose Macaulay matrix, once its other
("excess") columns E are eliminated, expresses every monomial of R in B. Over GF(p) this is a rank
count: the template reaches

    relations = rank [M_E M_R] - rank M_E

independent relations of R modulo B, and is complete when that equals |R|. This module measures it
for families of multiplier sets (:data:`MULTIPLIER_FAMILIES`), so that a user can see how large a
single template of their formulation must be before building one, and checks in floating point
what such a template would give (:func:`template_numerics`) and how well any action matrix on a
basis can separate the roots (:func:`basis_condition`).

scripts/template_evidence.py runs these on the paper's 9r/3s formulation and writes
tables/template_evidence_9r3s.csv, the evidence for solving it by parameter homotopy instead
(the action-matrix template generator, retired). Ranks are exact (FLINT ``nmod_mat``).
"""
from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from typing import Mapping, Sequence

import flint
import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg

from analysis.engine.f4 import groebner
from analysis.engine.linalg import pivot_columns
from analysis.formulations.tdoa import (
    Formulation,
    as_formulation,
    evaluate_gf,
    gf_equations,
    real_equations,
    sample_gf_instance,
)
from analysis.engine.orderings import MonomialOrder
from analysis.engine.quotient import standard_monomials
from analysis.engine.ring import Ring

__all__ = [
    "BASES",
    "ELIMINATIONS",
    "MULTIPLIER_FAMILIES",
    "RelationCount",
    "basis_condition",
    "count_relations",
    "gf_basis",
    "multipliers",
    "relation_count",
    "system_basis",
    "template_numerics",
    "template_relations",
]

Exponent = tuple[int, ...]

#: Multiplier families: every monomial of total degree <= d; monomials in the offsets o_j only
#: (degree <= d); (H, b)-degree <= 1 times offset-degree <= d.
MULTIPLIER_FAMILIES = ("total", "offsets", "linear-offsets")
#: Quotient bases: standard monomials of the grevlex basis; or of the elimination ideal in the offsets
#: (block order (H, b) > o, then grevlex in o), whose monomials involve the offsets only.
BASES = ("grevlex", "offsets")
#: The prime on which :func:`gf_basis` confirms the number of roots (65521 if the instance's prime is this one).
SECOND_PRIME = 32749
#: Eliminations of the excess columns tried by :func:`template_numerics`.
ELIMINATIONS = ("svd", "lu", "splu-natural", "splu-colamd")


@dataclass(frozen=True)
class RelationCount:
    """How many of the action-matrix relations a multiplier set reaches over GF(p)."""

    family: str
    degree: int
    basis: str
    action: str
    rows: int
    columns: int
    relations: int
    needed: int

    @property
    def complete(self) -> bool:
        return self.relations == self.needed


def _offset_mask(unknowns: Sequence[str]) -> np.ndarray:
    return np.array([u.startswith("o") for u in unknowns])


def _monomials(nvars: int, degree: int) -> list[Exponent]:
    """All exponents of total degree <= degree in nvars variables, by degree then lexicographically."""
    out: list[Exponent] = []
    for d in range(degree + 1):
        out.extend(sorted((a for a in itertools.product(range(d + 1), repeat=nvars) if sum(a) == d), reverse=True))
    return out


def multipliers(unknowns: Sequence[str], family: str, degree: int) -> list[Exponent]:
    """The multiplier exponents of a family (see :data:`MULTIPLIER_FAMILIES`) up to ``degree``."""
    if family not in MULTIPLIER_FAMILIES:
        raise ValueError(f"unknown multiplier family {family!r}; valid: {', '.join(MULTIPLIER_FAMILIES)}")
    if degree < 0:
        raise ValueError(f"degree must be >= 0, got {degree}")
    n = len(unknowns)
    if family == "total":
        return _monomials(n, degree)
    offsets = np.flatnonzero(_offset_mask(unknowns))
    others = np.flatnonzero(~_offset_mask(unknowns))
    if not len(offsets):
        raise ValueError(f"family {family!r} needs offset unknowns (names o1, o2, ...); got {tuple(unknowns)}")
    heads: list[Exponent] = [(0,) * n]
    if family == "linear-offsets":
        heads += [tuple(int(j == k) for j in range(n)) for k in others]
    out = []
    for head in heads:
        for a in _monomials(len(offsets), degree):
            e = list(head)
            for k, ak in zip(offsets, a):
                e[k] += ak
            out.append(tuple(e))
    return out


def count_relations(equations: Sequence[Mapping[Exponent, int]], multiplier_set: Sequence[Exponent],
                    basis: Sequence[Exponent], action: int, p: int) -> tuple[int, int, int, int]:
    """Rows, columns, relations reached and relations needed for one template over GF(p).

    Every equation is multiplied by every exponent of ``multiplier_set``; R = x_action B \\ B.
    Returns (rows, columns, rank[M_E M_R] - rank M_E, |R|).
    """
    bset = set(map(tuple, basis))
    nv = len(next(iter(bset)))
    reducible = sorted({tuple(b[j] + (j == action) for j in range(nv)) for b in bset} - bset)
    rows = [(i, t) for i in range(len(equations)) for t in multiplier_set]
    reached, excess = template_relations(equations, rows, reducible, basis, p)
    columns = {tuple(a + b for a, b in zip(e, t)) for i, t in rows for e in equations[i]}
    return len(rows), len(columns), reached, len(reducible)


def _macaulay_rows(equations: Sequence[Mapping[Exponent, object]], multiplier_set: Sequence[Exponent]) -> list[dict]:
    """t f for every equation f and multiplier t (equation-major), as {exponent: coefficient}."""
    return [{tuple(a + b for a, b in zip(e, t)): c for e, c in f.items()} for f in equations for t in multiplier_set]


def template_relations(equations: Sequence[Mapping[Exponent, int]], rows: Sequence[tuple[int, Exponent]],
                       reducible: Sequence[Exponent], basis: Sequence[Exponent], p: int) -> tuple[int, list[Exponent]]:
    """Relations of R modulo B that a template reaches over GF(p), and its excess columns E (sorted).

    rows: (equation index, multiplier exponent) pairs; returns (rank [M_E M_R] - rank M_E, E). A
    monomial of R that no row contains counts as not reached. The template is complete when the
    count is |R| (:func:`count_relations`; :func:`solvers.methods.action_matrix.build_template`).
    """
    polys = _template_rows(equations, rows, p)
    columns = set().union(*polys) if polys else set()
    excess = sorted(columns - set(reducible) - set(basis))
    present = [r for r in reducible if r in columns]
    return _rank(polys, excess + present, p) - _rank(polys, excess, p), excess


def _template_rows(equations, rows, p: int) -> list[dict]:
    return [{tuple(a + b for a, b in zip(e, t)): c % p for e, c in equations[i].items()} for i, t in rows]


def _macaulay_rank(equations, rows: Sequence[tuple[int, Exponent]], columns: Sequence[Exponent], p: int) -> int:
    """Rank over GF(p) of the template rows (equation index, multiplier) restricted to ``columns``."""
    return _rank(_template_rows(equations, rows, p), list(columns), p)


def _pivot_columns(equations, rows: Sequence[tuple[int, Exponent]], columns: Sequence[Exponent], p: int) -> list[Exponent]:
    """A maximal set of linearly independent columns (the first ones, in the given order) over GF(p)."""
    if not rows or not columns:
        return []
    R, rank = _nmod(_template_rows(equations, rows, p), list(columns), p).rref()
    out, j = [], 0
    for i in range(rank):
        while int(R[i, j]) == 0:
            j += 1
        out.append(columns[j])
    return out


def _nmod(rows: Sequence[Mapping[Exponent, int]], columns: Sequence[Exponent], p: int) -> "flint.nmod_mat":
    index = {c: j for j, c in enumerate(columns)}
    M = flint.nmod_mat(len(rows), len(columns), p)
    for r, row in enumerate(rows):
        for mon, c in row.items():
            j = index.get(mon)
            if j is not None:
                M[r, j] = c
    return M


def _rank(rows: Sequence[Mapping[Exponent, int]], columns: Sequence[Exponent], p: int) -> int:
    if not rows or not columns:
        return 0
    return _nmod(rows, columns, p).rank()


def _instance_equations(formulation: Formulation, prime: int, seed: int) -> list[dict]:
    """Equations of a seeded consistent GF(p) instance, after checking that its known root is a root."""
    instance = sample_gf_instance(formulation.config, prime, seed)
    equations = gf_equations(formulation, instance)
    if any(evaluate_gf(e, instance.root, prime) for e in equations):
        raise ValueError(f"the known root does not satisfy {formulation.label} over GF({prime}), seed {seed}")
    return equations


def gf_basis(formulation: Formulation | str, basis: str = "grevlex", prime: int = 65521,
             seed: int = 1) -> tuple[list[dict], list[Exponent]]:
    """Equations of a consistent GF(p) instance and a quotient basis of their ideal (see :data:`BASES`).

    The number of roots is confirmed on a second instance (seed + 1) over a second prime; a
    disagreement (a non-generic instance) raises ``ValueError``, as does a known root that is not one.
    """
    formulation = as_formulation(formulation)
    if basis not in BASES:
        raise ValueError(f"unknown basis {basis!r}; valid: {', '.join(BASES)}")
    unknowns = formulation.unknowns
    equations = _instance_equations(formulation, prime, seed)
    if basis == "grevlex":
        B = system_basis(equations, unknowns, prime)
    else:
        mask = _offset_mask(unknowns)
        k = int(mask.sum())
        if not k or not np.all(mask[len(unknowns) - k:]):
            raise ValueError("the offsets basis needs the offsets as the last unknowns")
        ring = Ring(unknowns, prime, MonomialOrder("block", len(unknowns), (len(unknowns) - k, k)))
        gb = groebner([ring.from_terms(e) for e in equations])
        head = len(unknowns) - k
        elim = [g for g in gb.basis if all(not any(ring.exps(m)[:head]) for m in g.mons)]
        sub = Ring(unknowns[head:], prime, "grevlex")
        gb_o = groebner([sub.from_terms({e[head:]: c for e, c in g.terms()}) for g in elim])
        B = [(0,) * head + sub.exps(m) for m in standard_monomials(gb_o)]
    other = SECOND_PRIME if prime != SECOND_PRIME else 65521
    check = len(system_basis(_instance_equations(formulation, other, seed + 1), unknowns, other))
    if check != len(B):
        raise ValueError(f"{formulation.label}: {len(B)} roots over GF({prime}) (seed {seed}) but {check} over "
                         f"GF({other}) (seed {seed + 1}); a non-generic instance - try another seed")
    return equations, B


def system_basis(equations: Sequence[Mapping[Exponent, int]], variables: Sequence[str], prime: int) -> list[Exponent]:
    """Grevlex standard monomials of any polynomial system over GF(prime) (a user's own system).

    Raises ``ValueError`` if the system has no solutions or is not zero-dimensional.
    """
    from analysis.engine.quotient import is_zero_dimensional

    ring = Ring(tuple(variables), prime, "grevlex")
    gb = groebner([ring.from_terms({e: c % prime for e, c in f.items()}) for f in equations])
    if gb.is_unit:
        raise ValueError("the system has no solutions (its Groebner basis is {1})")
    if not is_zero_dimensional(gb):
        raise ValueError("the system is not zero-dimensional: no finite quotient basis, no action matrix")
    return [ring.exps(m) for m in standard_monomials(gb)]


def relation_count(formulation: Formulation | str, family: str, degree: int, action: str,
                   basis: str = "grevlex", prime: int = 65521, seed: int = 1) -> RelationCount:
    """:func:`count_relations` for a TDOA formulation on its seeded GF(p) instance."""
    formulation = as_formulation(formulation)
    if action not in formulation.unknowns:
        raise ValueError(f"unknown action {action!r}; valid: {', '.join(formulation.unknowns)}")
    equations, B = gf_basis(formulation, basis, prime, seed)
    mult = multipliers(formulation.unknowns, family, degree)
    rows, cols, rel, need = count_relations(equations, mult, B, formulation.unknowns.index(action), prime)
    return RelationCount(family, degree, basis, action, rows, cols, rel, need)


def basis_condition(roots: np.ndarray, basis: Sequence[Exponent]) -> float:
    """Condition number of the roots' monomial matrix V[k, b] = x_k^b, rows normalised.

    V diagonalises every action matrix on the basis (A = V^-1 diag(a(x_k)) V), so its condition bounds
    how accurately any action-matrix solver on that basis can return the roots' monomial vectors.
    """
    roots = np.asarray(roots)
    E = np.asarray(basis)
    if roots.ndim != 2 or E.ndim != 2 or roots.shape[1] != E.shape[1]:
        raise ValueError(f"roots (K, n) and basis (|B|, n) must agree in n; got {roots.shape}, {E.shape}")
    V = np.prod(roots[:, None, :] ** E[None, :, :], axis=2)
    V = V / np.linalg.norm(V, axis=1, keepdims=True)
    return float(np.linalg.cond(V))


def template_numerics(formulation: Formulation | str, family: str, degree: int, action: str, F: np.ndarray,
                      truth: np.ndarray, basis: str = "offsets", method: str = "svd", prime: int = 65521,
                      seed: int = 1) -> dict:
    """Build a single template in floating point for data F and report what it gives.

    The Macaulay matrix of the multipliers is filled with the real equations of F (rows and columns
    equilibrated). The excess columns E are then eliminated in one of two ways:

    * ``"svd"``: projection on the left singular vectors of M_E beyond its exact (GF(p)) rank, then
      least squares for the relations of R (orthogonal, all rows kept; cubic in the template size);
    * ``"lu"``: the square system a sparse-LU solver would factor: a maximal independent set of E
      columns and then of rows, both chosen over GF(p) (:func:`analysis.engine.linalg.pivot_columns`),
      solved by dense LU with partial pivoting;
    * ``"splu-natural"``, ``"splu-colamd"``: the same square system by SuperLU (scipy), with the
      columns in template order (excess monomials by decreasing degree, then R) or reordered by COLAMD
      for sparsity.

    The action matrix's eigenvectors then give the roots. Returns the singular value of M_E at its
    exact rank relative to the largest (``sv_at_rank``; a well-conditioned template has a clear gap
    there), the condition number of the matrix that is solved, the relative error of the closest
    root to ``truth`` (unknown order) over the unknowns that are degree-1 monomials of the basis, and
    the seconds of the elimination alone (``seconds``).
    """
    if method not in ELIMINATIONS:
        raise ValueError(f"unknown elimination {method!r}; valid: {', '.join(ELIMINATIONS)}")
    formulation = as_formulation(formulation)
    unknowns = formulation.unknowns
    act = unknowns.index(action)
    equations_gf, B = gf_basis(formulation, basis, prime, seed)
    bset = set(B)
    nv = len(unknowns)
    R = sorted({tuple(b[j] + (j == act) for j in range(nv)) for b in bset} - bset)
    mult = multipliers(unknowns, family, degree)
    gf_rows = _macaulay_rows(equations_gf, mult)
    E = sorted(set().union(*gf_rows) - set(R) - bset, key=lambda e: (-sum(e), e))
    cols = E + R + list(B)
    index = {c: j for j, c in enumerate(cols)}
    nE, nR = len(E), len(R)
    M_gf = np.zeros((len(gf_rows), len(cols)), dtype=np.int64)
    for r, row in enumerate(gf_rows):
        for mon, c in row.items():
            M_gf[r, index[mon]] = c
    excess = pivot_columns(M_gf[:, :nE], prime)
    rank_e = len(excess)
    M = np.zeros(M_gf.shape)
    for r, row in enumerate(_macaulay_rows(real_equations(formulation, F), mult)):
        for mon, c in row.items():
            M[r, index[mon]] = c
    col_scale = np.ones(len(cols))
    for _ in range(3):
        M /= np.linalg.norm(M, axis=1, keepdims=True)
        cn = np.linalg.norm(M, axis=0)
        cn[cn == 0] = 1.0
        M /= cn
        col_scale *= cn
    t0 = time.perf_counter()
    if method == "svd":
        U, s, _ = np.linalg.svd(M[:, :nE], full_matrices=True)
        N = U[:, rank_e:]
        A1, A2 = N.T @ M[:, nE:nE + nR], N.T @ M[:, nE + nR:]
        X = -np.linalg.lstsq(A1, A2, rcond=None)[0]
        solved = A1
        seconds = time.perf_counter() - t0
    else:
        keep = np.concatenate([excess, np.arange(nE, nE + nR)])
        rows = pivot_columns(M_gf[:, keep].T, prime)
        if len(rows) != len(keep):
            raise ValueError(f"the template has no square nonsingular part ({len(rows)} rows for {len(keep)} columns)")
        solved = M[np.ix_(rows, keep)]
        rhs = M[np.ix_(rows, np.arange(nE + nR, len(cols)))]
        t0 = time.perf_counter()
        if method == "lu":
            X = -scipy.linalg.lu_solve(scipy.linalg.lu_factor(solved), rhs)[-nR:]
        else:
            permc = "NATURAL" if method == "splu-natural" else "COLAMD"
            lu = scipy.sparse.linalg.splu(scipy.sparse.csc_matrix(solved), permc_spec=permc)
            X = -lu.solve(rhs)[-nR:]
        seconds = time.perf_counter() - t0
        s = np.linalg.svd(M[:, :nE], compute_uv=False)
    # back to unscaled monomials: w'_c = w_c * col_scale_c
    X = X / col_scale[nE:nE + nR, None] * col_scale[None, nE + nR:]
    order = {b: k for k, b in enumerate(B)}
    rpos = {m: k for k, m in enumerate(R)}
    A = np.zeros((len(B), len(B)))
    for k, b in enumerate(B):
        shifted = tuple(b[j] + (j == act) for j in range(nv))
        if shifted in order:
            A[k, order[shifted]] = 1.0
        else:
            A[k] = X[rpos[shifted]]
    _, V = np.linalg.eig(A)
    one = order.get((0,) * nv)
    if one is None:
        raise ValueError("the basis must contain 1")
    V = V / V[one]
    present = [j for j in range(nv) if tuple(int(i == j) for i in range(nv)) in order]
    est = np.array([V[order[tuple(int(i == j) for i in range(nv))]] for j in present]).T
    ref = np.asarray(truth)[present]
    err = float(np.min(np.linalg.norm(est - ref[None, :], axis=1)) / np.linalg.norm(ref))
    return {"rows": M.shape[0], "columns": M.shape[1], "exact_rank_excess": rank_e, "excess_columns": nE,
            "sv_at_rank": float(s[rank_e - 1] / s[0]), "solved_condition": float(np.linalg.cond(solved)),
            "root_error": err, "seconds": seconds, "compared": tuple(unknowns[j] for j in present)}
