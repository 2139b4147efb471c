"""Action-matrix elimination template (``staged``, the fallback): offline build and online replay.

Offline (:func:`build`): F4 over GF(p) is run once with every step recorded (pair selection,
symbolic preprocessing, pivots), pruned to the steps the action matrix of the chosen action
variable needs, and checked exactly against the Gröbner basis's normal forms; the result is a
``staged`` spec. Online (:class:`StagedSolver`): the recorded steps replayed in floating point on
the data's coefficients, then the eigenvectors of the action matrix. :func:`macaulay_reducible_rank`
is the diagnostic behind the choice of the other methods:

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
* the staged replay (:func:`build`) is exact over GF(p), but in floating point its ~10
  chained eliminations, with pivots fixed by the trace, multiply the coefficients' rounding errors by
  more than 1e10; even replayed in 3000-bit arithmetic on exact rational coefficients, the grevlex
  action matrix of 6r4s has eigenvector condition numbers up to 5e10, and on a 9r3s instance the
  replay meets a zero pivot that the GF(p) trace did not have.

The staged template (``macaulay_reducible_rank`` included) is kept for these diagnostics and as a
fallback; the generated solvers use the other two kinds.
"""
from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
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

from .spec import STAGED_FORMAT, TemplateError, TemplateOptions, TemplateResult, spec_header

__all__ = ["StagedSolver", "build", "macaulay_reducible_rank"]


# --------------------------------------------------------------------------------------------------
# offline: GF(p) run with recording
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


def build(formulation: Formulation | str, options: TemplateOptions = TemplateOptions()) -> TemplateResult:
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
        **spec_header(formulation, options, "staged", len(basis), STAGED_FORMAT),
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


# --------------------------------------------------------------------------------------------------
# online: numeric replay of the staged template
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
    """Numeric replay of a staged elimination template spec (see :func:`build`).

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

