"""What a count may claim: the evidence beside the proven roots of :mod:`solvers.count`.

F4's degree over GF(p) at random parameters (within a budget), Bezout's bound, an incidence variety shown
irreducible (a bundle of affine parameter spaces over the unknowns' space), and from these the scope of the
count's completeness ("whole solution set", "component reached", "lower bound") in the words docs/count.md
explains; and what the roots Krawczyk's test did not prove are (singular: a multiple root or a point of a
positive-dimensional component); and which coordinates the trace test's pencil may take (F4 over GF(p) with some
unknowns fixed). Nothing here tracks a path or counts: it judges what :func:`solvers.count.count` found.
"""
from __future__ import annotations

import re
from typing import Callable

import numpy as np
import sympy

from analysis.engine.degree import DEFAULT_PRIMES, PrimeDisagreement, analyse
from analysis.engine.f4 import F4Options
from analysis.engine.linalg import MatrixTooLarge
from analysis.engine.ring import Ring
from analysis.formulations import tdoa as tf
from analysis.formulations.base import as_formulation
from analysis.formulations.parametric import ParametricError, ParametricSystem

from .continuation import certify as certify_mod

__all__ = ["DEGREE_CELLS", "PENCIL_CELLS", "bezout", "fixed_degree", "gf_degree", "gf_words", "linear_bundle",
           "orbit_total", "pencil_coordinates", "scope_of", "unproven_words"]


#: F4's budget (rows x columns of its largest matrix) for the GF(p) degree count compares with (count's scope): the
#: small systems in seconds (2D 6r/3s, 180: 3 s), the larger ones stop at the cap (4r/5s after 11 s, 3D 7r/5s after 2 s).
DEGREE_CELLS = 20_000_000


def gf_degree(system: ParametricSystem, say: Callable[[str], None]):
    """F4's count over GF(p) of ``system`` at random parameters (two primes, two seeds; saturated by its non-vanishing
    conditions; :meth:`ParametricSystem.degree`) within :data:`DEGREE_CELLS`, or None where F4 does not reach."""
    try:
        report = system.degree(seeds=(0, 1), options=F4Options(max_matrix_cells=DEGREE_CELLS))
    except (MatrixTooLarge, PrimeDisagreement, ParametricError) as exc:
        say(f"F4 over GF(p): no degree within its budget ({' '.join(str(exc).split())[:120]})")
        return None
    say("F4 over GF(p): " + (f"degree {report.degree}" if report.zero_dimensional else
                              f"positive-dimensional (dimension {report.dimension})"))
    return report


def gf_words(gf, proven: int, total: int | None) -> str:
    """The note that compares F4's degree with the proven solutions (``total``: counted with their orbits)."""
    if not gf.zero_dimensional:
        return (f"F4 over GF(p): positive-dimensional (dimension {gf.dimension}): the system also has solutions on a "
                "curve or surface; the count is of isolated solutions")
    if total is not None and total == gf.degree:
        return f"F4 over GF(p): degree {gf.degree}, equal to the proven count"
    have = total if total is not None else proven
    if gf.degree < have:
        return (f"F4 over GF(p): degree {gf.degree}, below the {have} proven: its random parameters mod p were not "
                "generic for this system; not used")
    return (f"F4 over GF(p): degree {gf.degree} (with multiplicity); {gf.degree - have} not found or not proven "
            "(another component, a multiple root, or a path not tracked)")


def orbit_total(roots: np.ndarray, cert, group) -> int | None:
    """The solutions the proven roots stand for: each orbit counted with its size, where every image of every box
    is proven disjoint from the box itself; None where one is not (a point a reflection may fix)."""
    if group is None:
        return len(roots)
    if cert is None:
        return None
    total = 0
    for x, r in zip(cert.centres, cert.radii):
        images = [g for g in group if not np.all(g == 1.0)]
        if not all(np.max(np.abs(x - g * x)) > 2.0 * r for g in images):
            return None
        total += len(group)
    return total


def bezout(system: ParametricSystem) -> int:
    """Bezout's bound: the product of the equations' degrees in the unknowns (their isolated solutions are at most
    as many, at every parameter)."""
    out = 1
    for terms in system.terms:
        out *= max(sum(mon) for mon, _ in terms)
    return out


def linear_bundle(system: ParametricSystem) -> str | None:
    """Why the incidence variety {(x, q) : F(x; q) = 0} is irreducible, or None where this does not decide it.

    Decided for a system affine in its parameters, F = A(x) q + b(x), whose parameters that enter with constant
    coefficients (only in terms free of the unknowns) give a constant block of A of rank N: for every x the
    parameters solving F = 0 are an affine space of dimension P - N, the same everywhere, so the incidence variety
    is an affine-space bundle over the unknowns' space (or over the open set the non-vanishing conditions leave):
    irreducible. Exact arithmetic on the coefficients (sympy rationals)."""
    if system.definitions or any(c > 1 for c in system.coefficient_degrees):
        return None
    N, P = len(system.unknowns), len(system.parameters)
    constant = [k for k, q in enumerate(system.q_symbols)
                if all(not (sum(mon) and sympy.diff(c, q) != 0) for terms in system.terms for mon, c in terms)]
    block = sympy.Matrix([[sum((sympy.diff(c, system.q_symbols[k]) for mon, c in terms if not sum(mon)), sympy.Integer(0))
                           for k in constant] for terms in system.terms]) if constant else sympy.zeros(N, 1)
    if block.rank() < N:
        return None
    names = ", ".join(system.parameters[k] for k in constant)
    return (f"the incidence variety is irreducible: the parameters enter linearly and {names} with constant "
            f"coefficients of rank {N}, so the parameters solving the system at any point form an affine space of "
            f"dimension {P - N}: a bundle over the unknowns' space")


def scope_of(system: ParametricSystem, roots: np.ndarray, cert, proven: int, group, gf, trace_record
           ) -> tuple[str, str]:
    """(scope, words) of the count's completeness: "whole solution set" (F4's degree or Bezout's bound equals the
    proven solutions, or the trace test passed on an irreducible incidence variety), "component reached" (the trace
    test passed, nothing shows the incidence variety irreducible) or "lower bound" (no completeness shown)."""
    found = len(roots)
    if not found or proven != found:
        return "lower bound", ""
    total = orbit_total(roots, cert, group)
    if total is not None and gf is not None and gf.zero_dimensional and gf.degree == total:
        return "whole solution set", f"complete: F4's degree over GF(p) is {gf.degree} (2 primes, 2 seeds)"
    # F4 sees more solutions (or multiplicity): nothing is complete for the whole solution set, whatever else holds
    more = gf is not None and gf.zero_dimensional and (total is None or gf.degree > total)
    bound = bezout(system)
    if total is not None and total == bound and not more:
        return "whole solution set", f"complete: Bezout's bound (the product of the degrees) is {bound}"
    if trace_record is None or trace_record["status"] != "passed":
        return "lower bound", ""
    passed = f"by trace test (residual {trace_record['residual']:.0e})"
    bundle = None if more else linear_bundle(system)
    if bundle is not None:
        return "whole solution set", f"complete {passed}; {bundle}"
    return "component reached", (f"complete for the component reached ({found} found) {passed}; another component "
                                 "may exist")


#: A root not proven is named singular where Newton's method converges only linearly there (each step at least this
#: fraction of the one before, the steps above rounding level: a multiple root or a positive-dimensional component,
#: where the step halves at a double root) or its Jacobian's condition number is above :data:`SINGULAR_COND`.
LINEAR_RATE = 0.1
SINGULAR_COND = 1e8


def unproven_words(system: ParametricSystem, solver, q0: np.ndarray, xs: np.ndarray, gf) -> str:
    """What the solutions Krawczyk's test did not prove are, by how Newton's method converges there and their
    Jacobians' condition numbers (in the words of ``generate``: a multiple root, a positive-dimensional component)."""
    ball = certify_mod.BallSystem(system, q0)
    inst = np.zeros(len(xs), dtype=np.int64)
    with np.errstate(all="ignore"):
        ys = [xs]
        for _ in range(4):
            ys.append(solver.newton(ys[-1], q0[None], steps=1, inst=inst))
        size = 1.0 + np.linalg.norm(xs, axis=1)
        steps = [np.linalg.norm(b - a, axis=1) / size for a, b in zip(ys[:-1], ys[1:])]
        linear = (steps[-1] > LINEAR_RATE * steps[-2]) & (steps[-1] > 1e-13)
        cond = np.array([np.linalg.cond(J) for J in ball.jacobians(ys[-1])])
    singular = int((linear | ~(cond <= SINGULAR_COND)).sum())
    parts = []
    if singular:
        what = ("points of a positive-dimensional component (F4 over GF(p): dimension "
                f"{gf.dimension}) or multiple roots" if gf is not None and not gf.zero_dimensional
                else "multiple roots or points of a positive-dimensional component")
        parts.append(f"{singular} singular (Newton's method converges only linearly or the Jacobian is singular: {what})")
    if len(xs) - singular:
        parts.append(f"{len(xs) - singular} regular but not proven")
    return "; ".join(parts) + "; none counted"


def pencil_coordinates(system: ParametricSystem, group, say: Callable[[str], None]) -> tuple[tuple[int, ...] | None, str]:
    """The trace test's pencil coordinates (None: every unknown) and the words that justify them.

    The compaction formulations': b alone. b goes to infinity wherever a root escapes (no base point on the curve),
    and it has fewer witnesses than all unknowns (2D 9r/3s: 1290 against 2045 for 75 roots).

    The direct TDOA parametrization's: the fewest offsets that determine the network up to the group. The witnesses
    are the poles of the pencil's form, about as many per offset (2D 6r/3s direct, 180 orbits: 734, 1,256 and 1,778
    witness orbits on one, two and three offsets, 7,384 on every unknown), and the test is then the trace test of
    the curve's image in (those offsets, lam) (trace.py), sound when that image is birational to the curve up to
    the group: exactly when the system with those offsets fixed has |G| solutions at a random consistent instance,
    which F4 decides over GF(p). With every offset fixed the data are TOA data (7r/5s, 6r/6s, 5r/9s: 8 solutions in
    0.1-0.5 s); each offset freed makes F4's work larger, so offsets are freed one at a time while the basis stays
    within :data:`PENCIL_CELLS` (6r/6s: three offsets fixed, 12,605 x 12,500, about a minute; one fixed, not
    finished for 7r/5s in 15 minutes). Where F4 does not give |G| with every offset fixed, every unknown."""
    names = system.unknowns
    b = tuple(k for k, u in enumerate(names) if re.fullmatch(r"b\d", u))
    if b:
        return b, "b"
    offsets = tuple(k for k, u in enumerate(names) if re.fullmatch(r"o\d+", u))
    if not offsets or group is None or not re.fullmatch(r"\d+r\d+s-tdoa[23]d-direct:all", system.name or ""):
        return None, "every unknown"
    chosen = None
    for k in range(len(offsets), 0, -1):
        fixed = tuple(names[j] for j in offsets[:k])
        degree = fixed_degree(system.name, fixed)
        say(f"trace test: with {', '.join(fixed)} fixed, {degree if degree is not None else 'no degree within F4 budget'}"
            f" (group order {len(group)})")
        if degree != len(group):
            break
        chosen = k
    if chosen is None:
        say("trace test: pencil on every unknown (the offsets do not determine each orbit over GF(p))")
        return None, "every unknown"
    fixed = [names[j] for j in offsets[:chosen]]
    words = (f"{', '.join(fixed)} (with {'it' if chosen == 1 else 'them'} fixed the system has {len(group)} solutions "
             f"over GF(p), the group's order: {'it determines' if chosen == 1 else 'they determine'} each orbit)")
    say(f"trace test: pencil on {words}")
    return offsets[:chosen], words


#: F4's budget (rows x columns of its largest matrix) for :func:`pencil_coordinates`' checks.
PENCIL_CELLS = 200_000_000


def fixed_degree(label: str, fixed: tuple[str, ...]) -> int | None:
    """The degree of a formulation with the unknowns ``fixed`` set to their values at the known root of a consistent
    random instance, modulo two primes (the root checked), or None when the primes disagree, the ideal is not
    zero-dimensional or F4 exceeds :data:`PENCIL_CELLS`."""
    formulation = as_formulation(label)
    unknowns = list(formulation.config.unknowns)

    def polys(p: int):
        instance = tf.sample_gf_instance(formulation.config, p, 0)
        tf.check_root(formulation, instance)
        ring = Ring(unknowns, p)
        eqs = [ring.from_terms(eq) for eq in tf.gf_equations(formulation, instance, p)]
        for name in fixed:
            k = unknowns.index(name)
            eqs.append(ring.from_terms({tuple(int(j == k) for j in range(len(unknowns))): 1,
                                        (0,) * len(unknowns): (-int(instance.root[k])) % p}))
        return eqs

    try:
        return analyse(polys, DEFAULT_PRIMES, F4Options(max_matrix_cells=PENCIL_CELLS)).degree
    except (PrimeDisagreement, MatrixTooLarge):
        return None
