"""Generic root counts of the positions formulations (:mod:`analysis.formulations.positions`) over GF(p).

This module owns the counting protocol for the minimal and near-minimal configurations (4r/5s, 4r/6s,
6r/3s): a system (or a square subsystem of an over-determined one) is specialised to a consistent
random GF(p) instance, the nonzero conditions are imposed by the Rabinowitsch variable ``t_`` with
``t_ * f - 1`` (f the product of the chosen saturating polynomials) and a grevlex Gröbner basis is
computed by F4. Because V(I + (t f - 1)) is isomorphic to V(I) minus V(f), its degree is the degree of
the saturation I : f^inf, i.e. the number of solutions with f != 0 counted with multiplicity; no
elimination order is needed (cheaper than :func:`analysis.engine.quotient.saturate`).

Per instance it also records: the known root (extended by t = 1/f(root)) vanishing on the basis, the
Jacobian rank at the known root, whether the sign group acts freely (the ideal plus the coordinates a
group element negates is empty, for every non-identity element), and whether all roots are simple
(the characteristic polynomial of the action matrix of a random linear form is squarefree). A degree
counts only when every (prime, seed) agrees (STYLE.md habit 6); :func:`count` raises otherwise.
"""
from __future__ import annotations

import re
import time
from dataclasses import dataclass, field
from typing import Literal, Sequence

import flint
import numpy as np

from .complexity import _variable_action_matrices, jacobian_rank
from ..engine.degree import DEFAULT_PRIMES, PrimeDisagreement
from ..engine.f4 import F4Options, groebner
from ..formulations.tdoa import InconsistentSample
from ..engine.linalg import MatrixTooLarge
from ..formulations.positions import PositionsSystem, gf_system, positions_system, sample_gf_positions
from ..engine.quotient import dimension, standard_monomials
from ..engine.ring import Poly, Ring

__all__ = ["Subsystem", "InstanceCount", "CountRecord", "count_instance", "count"]

Saturation = Literal["all", "none"] | tuple[str, ...]


@dataclass(frozen=True)
class Subsystem:
    """Which equations of a system to use.

    kind ``"all"``: every equation; ``"drop"``: all but the equations named in ``names``;
    ``"random"``: ``k`` random GF(p) linear combinations of the equations named in ``names`` (all other
    equations kept), the combination matrix drawn from ``seed`` (of the instance) + 1000.
    """

    kind: Literal["all", "drop", "random"] = "all"
    names: tuple[str, ...] = ()
    k: int = 0

    @property
    def label(self) -> str:
        if self.kind == "all":
            return "all"
        if self.kind == "drop":
            return "drop " + " ".join(self.names)
        return f"{self.k} random combinations of " + " ".join(self.names)


@dataclass(frozen=True)
class InstanceCount:
    """What one (prime, seed) gave.

    degree: number of solutions off V(f) with multiplicity (None if positive-dimensional).
    dimension: Krull dimension of I + (t f - 1).
    root_ok: the known root (with t = 1/f) vanishes on the Gröbner basis.
    jacobian_rank: rank of the Jacobian of the equations (in the original unknowns) at the known root.
    free_action: the sign group has no fixed point among the solutions (None if not checked).
    simple_roots: all roots are simple (None if not checked or not zero-dimensional).
    satisfy_full: for a subsystem, how many of its roots (with multiplicity) satisfy every equation of
        the system (degree of the subsystem's basis plus all equations); None for the full system.
    status: ``"ok"`` or ``"too-large"`` (an F4 matrix exceeded the cap; degree and dimension are None,
        ``max_matrix`` is the refused matrix and ``refused_degree`` its F4 degree).
    """

    prime: int
    seed: int
    degree: int | None
    dimension: int | None
    root_ok: bool
    jacobian_rank: int
    free_action: bool | None
    simple_roots: bool | None
    gb_size: int
    max_matrix: tuple[int, int]
    seconds: float
    satisfy_full: int | None = None
    status: str = "ok"
    refused_degree: int | None = None


@dataclass(frozen=True)
class CountRecord:
    """A degree agreed by every instance, with the system's description (one CSV row)."""

    label: str
    variant: str
    m: int
    n: int
    subsystem: str
    saturate_by: str
    unknowns: int
    equations: int
    equation_degrees: str
    group_order: int
    status: str
    degree: int | None
    dimension: int | None
    orbits: int | None
    free_action: bool | None
    simple_roots: bool | None
    satisfy_full: int | None
    primes: tuple[int, ...]
    seeds: tuple[int, ...]
    instance_degrees: tuple
    max_matrix: tuple[int, int]
    seconds: float
    per_instance: tuple[InstanceCount, ...] = field(repr=False, compare=False)

    def row(self) -> dict:
        return {
            "label": self.label, "variant": self.variant, "config": f"{self.m}r{self.n}s",
            "subsystem": self.subsystem, "saturate_by": self.saturate_by, "unknowns": self.unknowns,
            "equations": self.equations, "equation_degrees": self.equation_degrees,
            "group_order": self.group_order, "status": self.status, "degree": self.degree,
            "dimension": self.dimension, "orbits": self.orbits, "free_action": self.free_action,
            "simple_roots": self.simple_roots, "satisfy_full": self.satisfy_full,
            "primes": " ".join(map(str, self.primes)), "seeds": " ".join(map(str, self.seeds)),
            "instance_degrees": " ".join(str(d) for d in self.instance_degrees),
            "max_matrix": f"{self.max_matrix[0]}x{self.max_matrix[1]}" + (
                f" at degree {self.per_instance[-1].refused_degree}" if self.status == "too-large" else ""),
            "seconds": round(self.seconds, 2),
        }


def _select(system: PositionsSystem, eqs: list[Poly], sub: Subsystem, seed: int) -> tuple[list[Poly], list[str]]:
    names = list(system.equation_names)
    unknown = [x for x in sub.names if x not in names]
    if unknown:
        raise ValueError(f"unknown equation(s) {', '.join(unknown)} of {system.label}; it has {', '.join(names)}")
    if sub.kind == "all":
        return eqs, names
    if sub.kind == "drop":
        kept = [(e, nm) for e, nm in zip(eqs, names) if nm not in sub.names]
        return [e for e, _ in kept], [nm for _, nm in kept]
    if sub.kind == "random":
        p = eqs[0].ring.prime
        chosen = [e for e, nm in zip(eqs, names) if nm in sub.names]
        rest = [(e, nm) for e, nm in zip(eqs, names) if nm not in sub.names]
        gen = np.random.default_rng(seed + 1000)
        C = gen.integers(1, p, size=(sub.k, len(chosen)))
        combos = []
        for row in C:
            acc = eqs[0].ring.zero()
            for c, e in zip(row, chosen):
                acc = acc + e * int(c)
            combos.append(acc)
        return [e for e, _ in rest] + combos, [nm for _, nm in rest] + [f"comb{k + 1}" for k in range(sub.k)]
    raise ValueError(f"unknown subsystem kind {sub.kind!r}; valid: all, drop, random")


def _saturating(system: PositionsSystem, sat: list[Poly], saturate: Saturation, ring: Ring) -> tuple[Poly | None, str]:
    if saturate == "none":
        return None, "none"
    if saturate == "all":
        polys, text = sat, "all listed"
    else:
        polys = [ring.from_sympy(expr) for expr in saturate]
        text = "*".join(saturate)
    if not polys:
        return None, "none"
    f = polys[0]
    for g in polys[1:]:
        f = f * g
    return f, text


def _simple_roots(gb, p: int, rng: np.random.Generator) -> bool:
    """True iff the characteristic polynomial of a random linear form's action matrix is squarefree."""
    basis = standard_monomials(gb)
    if not basis:
        return True
    mats = _variable_action_matrices(gb, basis)
    coeffs = rng.integers(1, p, size=mats.shape[0])
    L = np.zeros(mats.shape[1:], dtype=np.int64)
    for c, X in zip(coeffs, mats):
        L = (L + int(c) * X) % p
    chi = flint.nmod_mat(L.shape[0], L.shape[1], [int(x) for x in L.ravel()], p).charpoly()
    return chi.gcd(chi.derivative()).degree() == 0


def count_instance(system: PositionsSystem, p: int, seed: int, *, subsystem: Subsystem = Subsystem(),
                   saturate: Saturation = "all", options: F4Options = F4Options(max_matrix_cells=60_000_000),
                   check_group: bool = True, check_simple: bool = True) -> InstanceCount:
    """Degree of one instance of a (sub)system off the zeros of the saturating polynomials.

    Parameters
    ----------
    system : a positions formulation.
    p, seed : prime and sampler seed (:func:`analysis.formulations.positions.sample_gf_positions`).
    subsystem : which equations (default all).
    saturate : ``"all"`` (the system's ``saturate_by``), ``"none"``, or sympy strings in the unknowns.
    check_group, check_simple : run the free-action and simple-roots checks (zero-dimensional only).

    Raises :class:`InconsistentSample` if the known root is not on the computed variety.
    """
    t0 = time.perf_counter()
    F, root = sample_gf_positions(system.m, system.n, p, seed, system.variant)
    all_eqs, sat = gf_system(system, F, p)
    eqs, _ = _select(system, all_eqs, subsystem, seed)
    base = eqs[0].ring
    jac = jacobian_rank([dict(e.terms()) for e in eqs], root, p)
    f, _ = _saturating(system, sat, saturate, base)
    if f is None:
        ring, point = base, list(root)

        def lift(g: Poly) -> Poly:
            return g
    else:
        ring = Ring(("t_",) + base.variables, p)

        def lift(g: Poly) -> Poly:
            return ring.from_terms(((0,) + e, c) for e, c in g.terms())

        fval = f.evaluate(root)
        if fval == 0:
            raise InconsistentSample(f"saturating polynomial vanishes at the known root ({system.label}, p={p}, seed {seed})")
        point = [pow(fval, -1, p)] + list(root)
    polys = [lift(g) for g in eqs if g] + ([] if f is None else [ring.gen(0) * lift(f) - 1])
    try:
        gb = groebner(polys, options)
    except MatrixTooLarge as exc:
        found = re.search(r"(\d+) x (\d+) at degree (\d+)", str(exc))
        shape = (int(found.group(1)), int(found.group(2))) if found else (0, 0)
        return InstanceCount(p, seed, None, None, False, jac, None, None, 0, shape, time.perf_counter() - t0,
                             status="too-large", refused_degree=int(found.group(3)) if found else None)
    root_ok = all(g.evaluate(point) == 0 for g in gb.basis)
    if not root_ok:
        raise InconsistentSample(f"known root not on the variety of {system.label} (p={p}, seed {seed})")
    dim = dimension(gb)
    deg = len(standard_monomials(gb)) if dim == 0 else None
    free = simple = full = None
    if deg is not None and check_group and len(system.sign_group) > 1:
        free = True
        offset = 0 if f is None else 1
        for sign in system.sign_group[1:]:
            fixed = [ring.gen(k + offset) for k, s in enumerate(sign) if s == -1]
            if not groebner(list(gb.basis) + fixed, options).is_unit:
                free = False
                break
    if deg is not None and check_simple:
        simple = _simple_roots(gb, p, np.random.default_rng(seed + 2000))
    if deg is not None and subsystem.kind != "all":
        full_gb = groebner(list(gb.basis) + [lift(g) for g in all_eqs if g], options)
        full = len(standard_monomials(full_gb)) if dimension(full_gb) == 0 else None
    mx = max(((r.rows, r.cols) for r in gb.rounds), key=lambda rc: rc[0] * rc[1], default=(0, 0))
    return InstanceCount(p, seed, deg, dim, root_ok, jac, free, simple, len(gb.basis), mx, time.perf_counter() - t0,
                         satisfy_full=full)


def count(system: PositionsSystem | tuple[int, int, str], *, primes: Sequence[int] = DEFAULT_PRIMES,
          seeds: Sequence[int] = (0, 1), subsystem: Subsystem = Subsystem(), saturate: Saturation = "all",
          options: F4Options = F4Options(max_matrix_cells=60_000_000), check_group: bool = True,
          check_simple: bool = True) -> CountRecord:
    """Degree agreed by every (prime, seed); raises :class:`PrimeDisagreement` (listing them) otherwise.

    ``orbits`` = degree / |sign group| when the group acts freely (checked), else None. When an F4
    matrix exceeds ``options.max_matrix_cells`` the record has status ``"too-large"`` (the remaining
    instances are skipped) and ``max_matrix`` is the refused matrix.
    """
    if not isinstance(system, PositionsSystem):
        system = positions_system(*system)
    t0 = time.perf_counter()
    results = []
    for p in primes:
        for s in seeds:
            r = count_instance(system, p, s, subsystem=subsystem, saturate=saturate, options=options,
                               check_group=check_group, check_simple=check_simple)
            results.append(r)
            if r.status == "too-large":  # the other instances would only hit the cap again
                break
        if results[-1].status == "too-large":
            break
    status = "too-large" if any(r.status == "too-large" for r in results) else "ok"
    if status == "ok":
        keys = {(r.degree, r.dimension) for r in results}
        if len(keys) != 1:
            summary = ", ".join(f"p={r.prime} seed {r.seed}: degree {r.degree} dim {r.dimension}" for r in results)
            raise PrimeDisagreement(f"{system.label} ({subsystem.label}): instances disagree ({summary})")
    first = results[0]

    def agreed(values):
        values = set(values)
        return values.pop() if len(values) == 1 else None

    free = agreed(r.free_action for r in results)
    simple = agreed(r.simple_roots for r in results)
    group = len(system.sign_group)
    orbits = first.degree // group if (status == "ok" and first.degree is not None and (free or group == 1)) else None
    n_eq = system.n_equations if subsystem.kind == "all" else (
        system.n_equations - len(subsystem.names) if subsystem.kind == "drop" else
        system.n_equations - len(subsystem.names) + subsystem.k)
    return CountRecord(
        label=system.label, variant=system.variant, m=system.m, n=system.n, subsystem=subsystem.label,
        saturate_by=_sat_names(system, saturate), unknowns=system.n_unknowns, equations=n_eq,
        equation_degrees=" ".join(map(str, system.degrees)), group_order=group, status=status,
        degree=first.degree if status == "ok" else None, dimension=first.dimension if status == "ok" else None,
        orbits=orbits, free_action=free, simple_roots=simple, satisfy_full=agreed(r.satisfy_full for r in results),
        primes=tuple(primes), seeds=tuple(seeds),
        instance_degrees=tuple(r.status if r.status != "ok" else ("dim" + str(r.dimension) if r.degree is None else r.degree)
                               for r in results),
        max_matrix=max((r.max_matrix for r in results), key=lambda rc: rc[0] * rc[1]),
        seconds=time.perf_counter() - t0, per_instance=tuple(results))


def _sat_names(system: PositionsSystem, saturate: Saturation) -> str:
    if saturate == "none" or (saturate == "all" and not system.saturate_by):
        return "none"
    if saturate == "all":
        return "*".join(system.saturate_names)
    return "*".join(saturate)
