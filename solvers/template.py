"""Solver construction over GF(p): the plain-text specs from which numeric solvers are generated.

This module owns step 1 of solver generation: on consistent random instances over GF(p) it fixes the
number of roots of a formulation (the size of the standard monomial basis of its grevlex Gröbner basis,
:func:`gf_degree`) and builds a JSON spec that :mod:`solvers.codegen` turns into a module and
:mod:`solvers.runtime` executes. Three kinds of spec:

* ``curve-pencil`` (6r4s: B2, C2-C6, the ten 3 x 3 minors): the minors make the offsets a rational
  curve, parametrised linearly by the kernel of [c | alpha | beta]; on it the roots are the eigenvalues
  of an 11 x 11 quartic matrix polynomial (:class:`solvers.runtime.CurvePencilSolver`). The spec holds
  the chart and the number of spurious eigenvalues to drop, both checked here on seeded real data.
* ``homotopy`` (9r3s: C2-C9 and every other square formulation): built by :mod:`solvers.generate`
  with the general parameter homotopy of :mod:`solvers.methods.homotopy`.
* ``staged`` (fallback, :func:`build_template`): the trace of F4 over GF(p) replayed in floating point.

Why not one elimination template (Kukelova et al. 2008; Larsson et al. 2017). The C equations are
linear in (H, b) with offset-dependent coefficients, so their top-degree forms vanish on the whole
section H = b = 0 at infinity, and the affine ideal is reached only through long chains of degree
falls. Measured over GF(65521) (9r3s rows: scripts/template_evidence.py ->
tables/template_evidence_9r3s.csv, via :mod:`solvers.feasibility`; action o1):

* uniform Macaulay templates: at degree 6 (3355 rows) the 6r4s matrix contains 154 of the 198
  independent relations of degree <= 3 that the action matrix needs; for 9r3s on the grevlex basis
  (75 monomials of (H, b)-degree <= 2), all multipliers of total degree <= 4 (3960 x 4520) reach 46
  of the 63 relations, (H, b)-degree <= 1 times offset-degree <= 5 (2688 x 2253) 61 of 63;
* eliminating (H, b) instead (the elimination ideal of 9r3s in the offsets, block order, has 9
  generators of degree 6 and 19 of degree 7, and 75 standard monomials up to degree 6, like 75
  generic points): offset-only multiples o^k C_i reach 3, 9, 21, 25 and 27 of the 27 relations for
  k = 7..11; the first complete single template is 2912 x 3020;
* that template in floating point (three seeded real networks, rows and columns equilibrated): the
  singular values of its excess block fall below 1e-16 of the largest before its exact rank (no
  numerical gap). Eliminated orthogonally (SVD, ~10 s per instance) it gives the offsets to
  10^-9.6..10^-10.7; the square part chosen over GF(p) (condition ~1e18) gives 10^-5.8..10^-7.3 by
  dense LU (0.4 s), 10^-6.5..10^-8.8 by SuperLU in template order (0.19 s) and 10^-0.2..10^-2.1 with
  COLAMD (0.07 s). The roots' monomial matrices on either basis have condition numbers 1e8-1e12, a
  limit for any action matrix on them. The homotopy is faster (~90 ms) and more accurate (10^-12.6);
* expanding the F4 trace into multiples of the input equations (needed(g) = union of t' needed(g'))
  gives 777760 rows for 6r4s; tracking exact cofactors instead still gives 176222 rows, of degree up
  to 11;
* the staged replay (:func:`build_template`) is exact over GF(p), but in floating point its ~10
  chained eliminations, with pivots fixed by the trace, multiply the coefficients' rounding errors by
  more than 1e10; even replayed in 3000-bit arithmetic on exact rational coefficients, the grevlex
  action matrix of 6r4s has eigenvector condition numbers up to 5e10, and on a 9r3s instance the
  replay meets a zero pivot that the GF(p) trace did not have.

The staged template (``macaulay_reducible_rank`` included) is kept for these diagnostics and as a
fallback; the generated solvers use the other two kinds.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from analysis.f4 import (
    F4Options,
    _State,
    _build_matrix,
    _symbolic_preprocessing,
    groebner,
    select_pairs,
    split_pivots,
)
from analysis.formulations import Formulation, as_formulation, coefficient_expressions, gf_equations, sample_gf_instance
from analysis.linalg import get_backend
from analysis.quotient import normal_form, standard_monomials
from analysis.ring import Poly, Ring

__all__ = [
    "SPEC_FORMAT",
    "STAGED_FORMAT",
    "METHODS",
    "TemplateError",
    "TemplateOptions",
    "TemplateResult",
    "build_pencil_spec",
    "build_spec",
    "build_template",
    "dump_spec",
    "gf_degree",
    "load_spec",
    "macaulay_reducible_rank",
    "monodromy",
    "solver_method",
    "spec_sha256",
    "term_structure",
]

#: Format of the curve-pencil and homotopy specs.
SPEC_FORMAT = "tdoa-solver/2"
#: Format of the staged F4-trace templates (fallback).
STAGED_FORMAT = "tdoa-staged-template/1"
#: Solver construction methods.
METHODS = ("curve-pencil", "homotopy", "staged")


class TemplateError(RuntimeError):
    """The template could not be built or failed its check on the GF(p) instance."""


@dataclass(frozen=True)
class TemplateOptions:
    """Options of solver construction.

    prime: characteristic of the GF(p) instances (< 2^16 so that every product is exact in float64).
    seed: seed of the GF(p) instance (printed in errors); the degree is confirmed on seed + 1.
    actions: staged templates only: candidate action variables (None: every unknown).
    chart_angle: curve-pencil only: the chart nu -> (lambda, mu) = nu (cos a, sin a) + (-sin a, cos a).
    verify_trials: seeded real networks on which a built solver must find the known root.
    """

    prime: int = 65521
    seed: int = 1
    actions: tuple[str, ...] | None = None
    chart_angle: float = 0.3
    verify_trials: int = 20


@dataclass(frozen=True)
class TemplateResult:
    """A built template: the JSON-ready spec and generation statistics."""

    spec: dict
    seconds: float
    candidates: tuple[dict, ...] = field(default=())

    @property
    def shape(self) -> tuple[int, int]:
        """Size of the numeric core: final template (staged), companion pencil, or (paths, unknowns)."""
        if self.spec.get("kind", "staged") == "staged":
            return tuple(self.spec["final"]["shape"])
        return tuple(self.spec["size"])


# --------------------------------------------------------------------------------------------------
# GF(p) run with recording
# --------------------------------------------------------------------------------------------------


class _Recorder:
    """Numeric polynomial table: id -> support (monomial keys, decreasing); steps reference ids."""

    def __init__(self, ring: Ring):
        self.ring = ring
        self.supports: list[list[int]] = []
        self.steps: list[dict] = []

    def new_poly(self, mons: Sequence[int]) -> int:
        self.supports.append(list(mons))
        return len(self.supports) - 1


def _trace_groebner(ring: Ring, inputs: list[Poly], input_supports: list[list[int]]):
    """F4 (normal strategy, Gebauer-Möller) that records every step as an elimination template.

    Mirrors :func:`analysis.f4.groebner` decision for decision (same pair selection, same
    symbolic preprocessing, same pivot choice) so that its result is the same basis.
    Returns (state, recorder, poly id of every state polynomial).
    """
    p = ring.prime
    backend = get_backend("numpy")
    rec = _Recorder(ring)
    state = _State(ring)
    input_ids = [rec.new_poly(s) for s in input_supports]
    state_ids: list[int] = []

    # step 0: inter-reduction of the inputs (rows to reduce only)
    cols = sorted({k for s in input_supports for k in s}, reverse=True)
    col_of = {m: c for c, m in enumerate(cols)}
    rows = [([col_of[k] for k in f.mons], f.monic().coeffs) for f in inputs]
    ech = backend.reduce({}, rows, len(cols), p)
    new = []
    for c, v in sorted(ech, key=lambda r: r[0][0]):
        h = Poly(ring, [cols[j] for j in c], list(v))
        pid = rec.new_poly(h.mons)
        new.append({"id": pid, "lead": c[0], "support": list(c)})
        state.add(h)
        state_ids.append(pid)
    rec.steps.append({
        "rows": [(input_ids[i], 0) for i in range(len(inputs))],
        "columns": cols, "pivots": [], "reduce": list(range(len(inputs))), "new": new,
    })
    while state.npairs:
        d, sel, rows_tk = select_pairs(state)
        rows_tk, columns = _symbolic_preprocessing(state, rows_tk)
        matrix = _build_matrix(state, rows_tk, columns)
        pivots, to_reduce = split_pivots(matrix)
        new_rows = backend.reduce({c: matrix[r] for c, r in pivots.items()}, [matrix[r] for r in to_reduce],
                                  len(columns), p)
        new = []
        for c, v in sorted(new_rows, key=lambda r: r[0][0]):
            h = Poly(ring, [columns[j] for j in c], list(v))
            if h.is_constant():
                raise TemplateError("the system is inconsistent on the sample instance")
            pid = rec.new_poly(h.mons)
            new.append({"id": pid, "lead": c[0], "support": list(c)})
            for k in h.mons:
                ring.exps(k)
            state.add(h)
            state_ids.append(pid)
        if new:
            rec.steps.append({
                "rows": [(state_ids[k], t) for t, k in rows_tk],
                "columns": columns,
                "pivots": [pivots[c] for c in sorted(pivots)],
                "reduce": to_reduce,
                "new": new,
            })
    return state, rec, state_ids


def _final_step(ring: Ring, state: _State, state_ids: list[int], basis: list[int], targets: list[int]) -> dict:
    """Action-matrix template: one reducer t * g for every non-standard monomial reachable from targets."""
    bset = set(basis)
    rows: list[tuple[int, int]] = []
    lead_of: dict[int, int] = {}
    todo = list(targets)
    seen = set(todo)
    while todo:
        m = todo.pop()
        if m in bset:
            continue
        k = state.find_reducer(m)
        if k < 0:
            raise TemplateError(f"no reducer for {ring.monomial_str(m)}: the basis is not a Gröbner basis")
        g = state.polys[k]
        t = m - g.lm
        lead_of[m] = len(rows)
        rows.append((k, t))
        for mm in g.mons:
            mm += t
            ring.exps(mm)
            if mm not in seen:
                seen.add(mm)
                todo.append(mm)
    non_std = sorted(lead_of, reverse=True)
    std = sorted((m for m in seen if m in bset), reverse=True)
    row_order = [lead_of[m] for m in non_std]
    return {
        "rows": [(state_ids[rows[r][0]], rows[r][1]) for r in row_order],
        "columns": non_std + std,
        "n_lead": len(non_std),
        "targets": [non_std.index(m) for m in targets],
        "basis_columns": std,
    }


# --------------------------------------------------------------------------------------------------
# public entry
# --------------------------------------------------------------------------------------------------


def _prune_steps(steps: list[dict], final: dict) -> list[dict]:
    """Drop steps none of whose new polynomials is used later."""
    needed = {pid for pid, _ in final["rows"]}
    kept = []
    for step in reversed(steps):
        if any(nw["id"] in needed for nw in step["new"]):
            kept.append(step)
            needed.update(pid for pid, _ in step["rows"])
    return kept[::-1]


def _build_for_action(formulation: Formulation, ring: Ring, polys: list[Poly], supports: list[list[int]],
                      action: str, gb_basis: list[int], ref_gb) -> dict:
    a = ring.variables.index(action)
    xa = ring.variable_key(a)
    bset = set(gb_basis)
    reducible = sorted({xa + b for b in gb_basis} - bset, reverse=True)
    extra = [ring.variable_key(i) for i in range(ring.nvars) if ring.variable_key(i) not in bset]
    targets = reducible + [m for m in extra if m not in reducible]
    state, rec, state_ids = _trace_groebner(ring, polys, supports)
    final = _final_step(ring, state, state_ids, gb_basis, targets)
    steps = _prune_steps(rec.steps, final)
    # exact check of the final step: NF(r) from the triangular block equals the GB normal form
    _check_final(ring, state, state_ids, final, gb_basis, targets, ref_gb)
    return {"action": action, "reducible": reducible, "extra": extra, "targets": targets,
            "final": final, "steps": steps, "supports": rec.supports}


def _check_final(ring, state, state_ids, final, basis, targets, ref_gb) -> None:
    p = ring.prime
    id_to_state = {pid: k for k, pid in enumerate(state_ids)}
    cols = final["columns"]
    pos = {m: i for i, m in enumerate(cols)}
    n = final["n_lead"]
    M = np.zeros((len(final["rows"]), len(cols)), dtype=np.int64)
    for r, (pid, t) in enumerate(final["rows"]):
        g = state.polys[id_to_state[pid]]
        for k, c in zip(g.mons, g.coeffs):
            M[r, pos[k + t]] = c
    import flint

    T = flint.nmod_mat(M[:, :n].tolist(), p)
    C = flint.nmod_mat(M[:, n:].tolist(), p) if len(cols) > n else None
    Y = T.solve(C)
    std = final["basis_columns"]
    for ti, m in zip(final["targets"], targets):
        got = {std[j]: (-int(Y[ti, j])) % p for j in range(len(std)) if int(Y[ti, j])}
        want = normal_form(Poly(ring, [m], [1]), ref_gb).to_dict()
        if got != want:
            raise TemplateError(f"final template gives a wrong normal form for {ring.monomial_str(m)}")


def _template_cost(cand: dict) -> int:
    cost = 0
    for step in cand["steps"]:
        cost += len(step["rows"]) * len(step["columns"])
    f = cand["final"]
    cost += len(f["rows"]) * len(f["columns"])
    return cost


def build_template(formulation: Formulation | str, options: TemplateOptions = TemplateOptions()) -> TemplateResult:
    """Build the staged elimination template of a formulation (see the module docstring).

    Parameters
    ----------
    formulation: a :class:`Formulation` or its label, e.g. ``"6r4s:B2,C2-C6,minors(10)"``.
    options: prime, instance seed and action-variable candidates.

    Returns a :class:`TemplateResult` whose ``spec`` is JSON-ready; the candidate with the fewest
    matrix cells (all steps) wins, ties broken by the order of ``options.actions``.
    Raises :class:`TemplateError` if the final template fails its exact check.
    """
    t0 = time.perf_counter()
    formulation = as_formulation(formulation)
    config = formulation.config
    p = options.prime
    ring = Ring(formulation.unknowns, p, "grevlex")
    instance = sample_gf_instance(config, p, options.seed)
    symbolic = coefficient_expressions(formulation)
    equations = gf_equations(formulation, instance)
    polys, supports, term_exps = [], [], []
    for name, sym, eq in zip(formulation.equations, symbolic, equations):
        exps = sorted(sym, key=ring.key, reverse=True)
        missing = [e for e in exps if e not in eq]
        if missing:
            raise TemplateError(f"equation {name} has a coefficient that vanishes mod {p} on the instance "
                                f"(seed {options.seed}); use another seed")
        term_exps.append(exps)
        supports.append([ring.key(e) for e in exps])
        polys.append(ring.from_terms(eq))
    ref_gb = groebner(polys, F4Options())
    basis = standard_monomials(ref_gb)
    if not basis:
        raise TemplateError("the system has no solutions on the sample instance")
    actions = options.actions or formulation.unknowns
    candidates, best = [], None
    for action in actions:
        cand = _build_for_action(formulation, ring, polys, supports, action, basis, ref_gb)
        cost = _template_cost(cand)
        candidates.append({"action": action, "cells": cost, "final_shape": [len(cand["final"]["rows"]),
                                                                          len(cand["final"]["columns"])],
                           "steps": len(cand["steps"])})
        if best is None or cost < best[0]:
            best = (cost, cand)
    spec = _to_spec(formulation, ring, options, basis, term_exps, best[1])
    return TemplateResult(spec, time.perf_counter() - t0, tuple(candidates))


def _to_spec(formulation: Formulation, ring: Ring, options: TemplateOptions, basis: list[int],
             term_exps: list[list[tuple]], cand: dict) -> dict:
    """JSON-ready spec: monomials as exponent lists in one table, everything else as indices."""
    keys: set[int] = set(basis)
    for sup in cand["supports"]:
        keys.update(sup)
    for step in cand["steps"]:
        keys.update(step["columns"])
        keys.update(t for _, t in step["rows"])
    keys.update(cand["final"]["columns"])
    keys.update(t for _, t in cand["final"]["rows"])
    keys.update(cand["targets"])
    table = sorted(keys, key=lambda k: (ring.degree(k), k))
    idx = {k: i for i, k in enumerate(table)}
    used = sorted(set(range(len(term_exps)))
                  | {pid for step in cand["steps"] for pid, _ in step["rows"]}
                  | {nw["id"] for step in cand["steps"] for nw in step["new"]}
                  | {pid for pid, _ in cand["final"]["rows"]})
    renum = {pid: i for i, pid in enumerate(used)}
    n_inputs = len(term_exps)
    if used[:n_inputs] != list(range(n_inputs)):
        raise TemplateError("internal: input polynomials must come first")

    def step_spec(step: dict) -> dict:
        cols = step["columns"]
        return {
            "rows": [[renum[pid], idx[t]] for pid, t in step["rows"]],
            "columns": [idx[m] for m in cols],
            "pivots": list(step["pivots"]),
            "reduce": list(step["reduce"]),
            "new": [[renum[nw["id"]], nw["lead"], list(nw["support"])] for nw in step["new"] if nw["id"] in renum],
        }

    final = cand["final"]
    spec = {
        "format": STAGED_FORMAT,
        "kind": "staged",
        "formulation": formulation.label,
        "equations": list(formulation.equations),
        "unknowns": list(formulation.unknowns),
        "order": "grevlex",
        "prime": options.prime,
        "seed": options.seed,
        "degree": len(basis),
        "action": cand["action"],
        "monomials": [list(ring.exps(k)) for k in table],
        "basis": [idx[k] for k in basis],
        "reducible": [idx[k] for k in cand["reducible"]],
        "inputs": [[idx[ring.key(e)] for e in exps] for exps in term_exps],
        "polys": [[idx[k] for k in cand["supports"][pid]] for pid in used],
        "steps": [step_spec(s) for s in cand["steps"]],
        "final": {
            "rows": [[renum[pid], idx[t]] for pid, t in final["rows"]],
            "columns": [idx[m] for m in final["columns"]],
            "n_lead": final["n_lead"],
            "targets": list(final["targets"]),
            "target_monomials": [idx[m] for m in cand["targets"]],
            "shape": [len(final["rows"]), len(final["columns"])],
        },
    }
    return spec


# --------------------------------------------------------------------------------------------------
# shared pieces of the curve-pencil and homotopy specs
# --------------------------------------------------------------------------------------------------


def gf_degree(formulation: Formulation | str, options: TemplateOptions = TemplateOptions()) -> int:
    """Number of roots (with multiplicity) over GF(p): |standard monomial basis| of the grevlex basis.

    Computed on the instances with seeds ``options.seed`` and ``options.seed + 1``; raises
    :class:`TemplateError` if they disagree or if the known root of an instance is not a root.
    """
    formulation = as_formulation(formulation)
    p = options.prime
    ring = Ring(formulation.unknowns, p, "grevlex")
    degrees = []
    for seed in (options.seed, options.seed + 1):
        instance = sample_gf_instance(formulation.config, p, seed)
        polys = [ring.from_terms(e) for e in gf_equations(formulation, instance)]
        if any(f.evaluate(instance.root) for f in polys):
            raise TemplateError(f"the known root of the GF({p}) instance (seed {seed}) is not a root")
        degrees.append(len(standard_monomials(groebner(polys, F4Options()))))
    if degrees[0] != degrees[1]:
        raise TemplateError(f"GF({p}) instances with seeds {options.seed}, {options.seed + 1} give "
                            f"different degrees {degrees}")
    return degrees[0]


def term_structure(formulation: Formulation | str) -> tuple[list[list[int]], list[list[int]]]:
    """(monomial table, per equation the indices of its terms) of a formulation's symbolic equations.

    Terms are the exponents with a nonzero coefficient polynomial in the data, in decreasing grevlex
    order; the table lists the monomials by (degree, grevlex). This is the layout of the coefficient
    vector emitted by :mod:`solvers.codegen` (used for polishing and residuals).
    """
    formulation = as_formulation(formulation)
    ring = Ring(formulation.unknowns, 65521, "grevlex")
    symbolic = coefficient_expressions(formulation, "ring")
    per_eq = [sorted((e for e, c in eq.items() if c), key=ring.key, reverse=True) for eq in symbolic]
    table = sorted({e for eq in per_eq for e in eq}, key=lambda e: (sum(e), ring.key(e)))
    idx = {e: i for i, e in enumerate(table)}
    return [list(e) for e in table], [[idx[e] for e in eq] for eq in per_eq]


def solver_method(formulation: Formulation | str) -> str:
    """The construction used for a formulation: ``curve-pencil``, ``homotopy`` or ``staged``."""
    formulation = as_formulation(formulation)
    config, eqs = formulation.config, tuple(formulation.equations)
    c_eqs = tuple(f"C{i}" for i in range(2, config.m + 1))
    minors = tuple(e for e in eqs if e.startswith("M"))
    if (config.m == 6 and config.n == 4 and set(eqs) == {"B2", *c_eqs, *minors} and len(minors) == 10):
        return "curve-pencil"
    if config.n == 3 and all(e.startswith("C") for e in eqs) and len(eqs) == len(formulation.unknowns):
        return "homotopy"
    return "staged"


def build_spec(formulation: Formulation | str, options: TemplateOptions = TemplateOptions(),
               method: str | None = None) -> TemplateResult:
    """Build the spec of a formulation's solver by ``method`` (default :func:`solver_method`)."""
    formulation = as_formulation(formulation)
    method = method or solver_method(formulation)
    if method == "curve-pencil":
        return build_pencil_spec(formulation, options)
    if method == "homotopy":
        raise TemplateError(f"{formulation.label}: homotopy solvers are built by solvers.generate "
                            "(tdoa-workbench generate)")
    if method == "staged":
        return build_template(formulation, options)
    raise ValueError(f"unknown method {method!r}; valid: {', '.join(METHODS)}")


def _common_spec(formulation: Formulation, options: TemplateOptions, kind: str, degree: int) -> dict:
    monomials, inputs = term_structure(formulation)
    return {
        "format": SPEC_FORMAT,
        "kind": kind,
        "formulation": formulation.label,
        "equations": list(formulation.equations),
        "unknowns": list(formulation.unknowns),
        "order": "grevlex",
        "prime": options.prime,
        "seed": options.seed,
        "degree": degree,
        "monomials": monomials,
        "inputs": inputs,
    }


def _real_trials(formulation: Formulation, trials: int) -> tuple[np.ndarray, np.ndarray]:
    """Seeded noiseless networks (seeds 0..trials-1): normalised data and the root in that frame."""
    from .runtime import data_scale
    from .synthetic import random_network, true_root

    m, n = formulation.config.m, formulation.config.n
    F, X = [], []
    for seed in range(trials):
        net = random_network(m, n, np.random.default_rng(seed))
        H, b, o = true_root(net)
        F.append(net.measurements())
        X.append(np.concatenate([[H[0, 0], H[0, 1], H[1, 1]], b, o]))
    F, X = np.array(F), np.array(X)
    s = data_scale(F)
    powers = np.array([-2.0] * 3 + [0.0] * 2 + [1.0] * n)
    return F / s[:, None, None], X / s[:, None] ** powers


def _found(roots: np.ndarray, truth: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    err = np.nanmin(np.linalg.norm(roots - truth[:, None, :], axis=2), axis=1) / np.linalg.norm(truth, axis=1)
    return err < tol


# --------------------------------------------------------------------------------------------------
# curve-pencil (6r4s)
# --------------------------------------------------------------------------------------------------


def build_pencil_spec(formulation: Formulation | str, options: TemplateOptions = TemplateOptions()) -> TemplateResult:
    """Spec of the rank-2-curve pencil solver (:class:`solvers.runtime.CurvePencilSolver`).

    Checks: the GF(p) degree is 22; on ``options.verify_trials`` seeded real networks the
    column-degree pencil (37 x 37, :data:`solvers.runtime.PENCIL_COLUMN_DEGREES`) has exactly 7
    eigenvalues with beta ~ 0 (a gap of three orders of magnitude to the next) and eight with sigma ~ 0
    (o_1 = infinity), and the remaining 22 contain the known root.
    """
    t0 = time.perf_counter()
    formulation = as_formulation(formulation)
    if solver_method(formulation) != "curve-pencil":
        raise TemplateError(f"{formulation.label}: the curve pencil needs 6r4s with B2, C2-C6 and the 10 minors")
    from scipy.linalg import eigvals

    from .runtime import PENCIL_COLUMN_DEGREES, CurvePencilSolver

    degree = gf_degree(formulation, options)
    size = sum(PENCIL_COLUMN_DEGREES)
    det_degree = degree + 8  # sigma^8: the C rows degenerate where o_1 = infinity
    spec = _common_spec(formulation, options, "curve-pencil", degree)
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
# JSON I/O (byte-stable)
# --------------------------------------------------------------------------------------------------


def dump_spec(spec: dict) -> str:
    """Byte-stable JSON text: one top-level key per line, inner lists compact."""
    lines = ["{"]
    keys = list(spec)
    for i, k in enumerate(keys):
        sep = "," if i < len(keys) - 1 else ""
        value = spec[k]
        if isinstance(value, list) and value and isinstance(value[0], (list, dict)):
            lines.append(f"  {json.dumps(k)}: [")
            for j, item in enumerate(value):
                s2 = "," if j < len(value) - 1 else ""
                lines.append(f"    {json.dumps(item, separators=(',', ':'))}{s2}")
            lines.append(f"  ]{sep}")
        else:
            lines.append(f"  {json.dumps(k)}: {json.dumps(value, separators=(',', ':'))}{sep}")
    lines.append("}")
    return "\n".join(lines) + "\n"


def load_spec(text: str) -> dict:
    """Parse a spec; raises :class:`TemplateError` for an unknown format."""
    spec = json.loads(text)
    if spec.get("format") not in (SPEC_FORMAT, STAGED_FORMAT):
        raise TemplateError(f"unknown template spec format {spec.get('format')!r}; "
                            f"expected {SPEC_FORMAT} or {STAGED_FORMAT}")
    return spec


def spec_sha256(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


# --------------------------------------------------------------------------------------------------
# diagnostics: why a single Macaulay template is not used
# --------------------------------------------------------------------------------------------------


def macaulay_reducible_rank(formulation: Formulation | str, degree: int, action: str,
                            options: TemplateOptions = TemplateOptions()) -> tuple[int, int, int]:
    """(rows, rank of the reducible part after eliminating the excessive monomials, |R|) of the
    single Macaulay template with all multiples up to ``degree`` (exact, sparse elimination over GF(p)).

    The single template works iff the middle number equals |R|.
    """
    formulation = as_formulation(formulation)
    p = options.prime
    ring = Ring(formulation.unknowns, p, "grevlex")
    instance = sample_gf_instance(formulation.config, p, options.seed)
    eqs = gf_equations(formulation, instance)
    gb = groebner([ring.from_terms(e) for e in eqs], F4Options())
    basis = [ring.exps(k) for k in standard_monomials(gb)]
    nv = ring.nvars
    a = ring.variables.index(action)
    unit = tuple(int(i == a) for i in range(nv))
    bset = set(basis)
    red = sorted({tuple(x + y for x, y in zip(unit, b)) for b in basis} - bset, key=ring.key, reverse=True)
    rset = set(red)
    rows = []
    for f in eqs:
        df = max(map(sum, f))
        for d in range(degree - df + 1):
            for c in itertools.combinations_with_replacement(range(nv), d):
                t = [0] * nv
                for i in c:
                    t[i] += 1
                rows.append({tuple(x + y for x, y in zip(t, e)): v for e, v in f.items()})
    cols = sorted(set().union(*rows), key=ring.key, reverse=True)
    exc = [e for e in cols if e not in rset and e not in bset]
    ci = {e: i for i, e in enumerate(exc + red)}
    srows = [{ci[e]: v for e, v in r.items() if e in ci} for r in rows]
    rest = _sparse_eliminate(srows, len(exc), p)
    import flint

    sub = [[r.get(len(exc) + k, 0) for k in range(len(red))] for r in rest]
    rank = flint.nmod_mat(sub, p).rank() if sub else 0
    return len(rows), rank, len(red)


def _sparse_eliminate(rows: list[dict], n_exc: int, p: int) -> list[dict]:
    """Eliminate the columns < n_exc (Markowitz-style pivots); return the rows free of them."""
    import heapq

    rows = [dict(r) for r in rows]
    colrows: dict[int, set] = {}
    for i, r in enumerate(rows):
        for c in r:
            colrows.setdefault(c, set()).add(i)
    heap = [(len(s), c) for c, s in colrows.items() if c < n_exc]
    heapq.heapify(heap)
    alive = {i for i, r in enumerate(rows) if r}
    while heap:
        cnt, c = heapq.heappop(heap)
        rs = colrows.get(c)
        if not rs:
            continue
        if len(rs) != cnt:
            heapq.heappush(heap, (len(rs), c))
            continue
        piv = min(rs, key=lambda i: len(rows[i]))
        prow = rows[piv]
        inv = pow(prow[c], -1, p)
        for cc in prow:
            colrows[cc].discard(piv)
        alive.discard(piv)
        items = [(cc, v * inv % p) for cc, v in prow.items()]
        for i in list(rs):
            r = rows[i]
            f = r[c]
            for cc, v in items:
                nv = (r.get(cc, 0) - f * v) % p
                if nv:
                    if cc not in r:
                        colrows[cc].add(i)
                        if cc < n_exc:
                            heapq.heappush(heap, (len(colrows[cc]), cc))
                    r[cc] = nv
                elif cc in r:
                    del r[cc]
                    colrows[cc].discard(i)
        colrows[c] = set()
    return [rows[i] for i in sorted(alive) if rows[i]]
