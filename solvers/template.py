"""Elimination templates over GF(p): the plain-text spec from which a numeric solver is generated.

This module owns step 1 of solver generation (Kukelova et al. 2008; Larsson et al. 2017): on one
consistent random instance over GF(p) it computes the Gröbner basis (grevlex, unknowns h11, h12, h22,
b1, b2, o1..on), the standard monomial basis B, and a recipe that, replayed in floating point on real
data, yields the normal forms of the reducible monomials R = x_a * B minus B for an action variable x_a.

Why staged templates. A single Macaulay template (all multiples t * f_i up to degree D, columns
[excessive | reducible | basis]) needs a very large D here: for 9r3s (C2-C9, |B| = 75) the degree-8
Macaulay matrix (10296 rows) still reduces only 28 of the 35 reducible monomials, and for 6r4s
(B2, C2-C6, 10 minors, |B| = 22) the degree-7 one (10945 rows) only 13 of 15 (see
:func:`macaulay_reducible_rank`). The C equations are linear in (H, b) with offset-dependent
coefficients, so their syzygies only appear at high degree. F4 instead reaches the basis through
polynomials of degree <= 5 with small matrices. The template is therefore a sequence of *steps*, each an
elimination template whose rows are monomial multiples of the polynomials produced by earlier steps
(the trace of F4 with the normal selection strategy, Faugère 1999; Traverso's Gröbner trace idea):

* step 0 inter-reduces the input equations;
* each F4 round builds rows t * g (pair halves and symbolic-preprocessing reducers), reduces the
  non-pivot rows by the pivot rows (a unit triangular solve) and keeps the rows with new leading
  monomials, normalised to leading coefficient 1 (a least-squares solve in floating point);
* the final step is a classic action-matrix template: rows t * g for one reducer of every non-standard
  monomial reachable from R, columns [non-standard | B]; its unit upper triangular block gives
  NF(r) for every r in R (and for unknowns not in B, needed to read off the root).

Rounds whose output no later step uses are dropped. The spec is plain JSON (monomials as exponent
lists in a table, rows as [polynomial id, multiplier id]) and is checked on the GF(p) instance: the
final step's normal forms must equal :func:`analysis.quotient.normal_form`.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from analysis.f4 import F4Options, _State, _build_matrix, _symbolic_preprocessing, groebner
from analysis.formulations import Formulation, coefficient_expressions, gf_equations, sample_gf_instance
from analysis.linalg import get_backend
from analysis.quotient import normal_form, standard_monomials
from analysis.ring import Poly, Ring

__all__ = [
    "SPEC_FORMAT",
    "TemplateError",
    "TemplateOptions",
    "TemplateResult",
    "build_template",
    "load_spec",
    "dump_spec",
    "spec_sha256",
    "macaulay_reducible_rank",
]

SPEC_FORMAT = "tdoa-staged-template/1"


class TemplateError(RuntimeError):
    """The template could not be built or failed its check on the GF(p) instance."""


@dataclass(frozen=True)
class TemplateOptions:
    """Options of template construction.

    prime: characteristic of the instance (< 2^16 so that every product is exact in float64).
    seed: seed of the GF(p) instance (printed in errors).
    actions: candidate action variables (None: every unknown); the smallest template wins.
    """

    prime: int = 65521
    seed: int = 1
    actions: tuple[str, ...] | None = None


@dataclass(frozen=True)
class TemplateResult:
    """A built template: the JSON-ready spec and generation statistics."""

    spec: dict
    seconds: float
    candidates: tuple[dict, ...] = field(default=())

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.spec["final"]["shape"])


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
        d, sel = state.pop_pairs()
        row_set: set[tuple[int, int]] = set()
        for i, j, le in sel:
            for k in (i, j):
                t_exps = tuple(a - b for a, b in zip(le, ring.exps(state.lms[k])))
                row_set.add((ring.key(t_exps), k))
        rows_tk, columns = _symbolic_preprocessing(state, sorted(row_set))
        matrix = _build_matrix(state, rows_tk, columns)
        order = sorted(range(len(matrix)), key=lambda r: len(matrix[r][0]))
        pivots: dict[int, int] = {}
        to_reduce: list[int] = []
        for r in order:
            lead = matrix[r][0][0]
            if lead not in pivots:
                pivots[lead] = r
            else:
                to_reduce.append(r)
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
    if isinstance(formulation, str):
        formulation = Formulation.parse(formulation)
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
        "format": SPEC_FORMAT,
        "formulation": formulation.label,
        "equations": list(formulation.equations),
        "unknowns": list(formulation.unknowns),
        "order": "grevlex",
        "prime": options.prime,
        "seed": options.seed,
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
    spec = json.loads(text)
    if spec.get("format") != SPEC_FORMAT:
        raise TemplateError(f"unknown template spec format {spec.get('format')!r}; expected {SPEC_FORMAT}")
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
    if isinstance(formulation, str):
        formulation = Formulation.parse(formulation)
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
