"""Every solution of a user's zero-dimensional system: the count certified over GF(p), the points in floats.

Method ``action matrix over Q``:

1. *Count.* The system's reduced grevlex Gröbner basis modulo random 31-bit primes until a majority of
   at least three agree (:func:`analysis.engine.modular.analyse_rational`): its standard monomials B
   give the degree |B|, the number of solutions counted with multiplicity ("certified over GF(p)").
2. *Basis over Q.* Chinese remaindering and rational reconstruction of the primes' bases, checked
   modulo a fresh prime (:func:`analysis.engine.modular.rational_basis`).
3. *Action matrices.* For every unknown x_i the matrix of multiplication by x_i on Q[x]/I in the basis
   B, exactly (normal forms over Q of the border monomials x_i b), then in float64.
4. *Eigenvectors.* The transposed action matrix of a random (seeded) linear form has the evaluation
   vectors (b(z))_b of the solutions z as eigenvectors; x_i(z) = (v A_i)[1] / v[1].
5. *Polish and check.* Newton steps on the input polynomials (least squares when there are more
   equations than unknowns); the residual is max |f_k(z)|. The solutions are complete when there
   are |B| of them, pairwise distinct, each with a nonsingular Jacobian (then every one is simple and
   none is missing): the status says so, or says what failed.

A nonzero condition (``nonzero:`` of a ``.sys`` file) saturates the ideal by Rabinowitsch's extra
unknown t (t f - 1), which is solved for and then dropped from the solutions.

Reference: Cox, Little, O'Shea, *Using Algebraic Geometry*, ch. 2 sec. 4 (eigenvectors of action
matrices); Arnold, "Modular algorithms for computing Gröbner bases", JSC 2003 (the basis over Q).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from fractions import Fraction
from typing import Callable, Mapping, Sequence

import numpy as np

from analysis.engine.polytext import InputError, read_number

from .continuation.scaling import SCALE_BITS, equation_shift, log2_floor, scaled_float

__all__ = ["HOMOTOPY", "METHOD", "SolveError", "Solution", "SystemSolutions", "generated_solver", "instance_system",
           "parameter_values", "solve_by_homotopy",
           "solve_system"]

METHOD = "action matrix over Q"

NEWTON_STEPS = 6
"""Newton steps at most per solution (stopped early once a step no longer lowers the residual)."""

REAL_TOL = 1e-8
"""A solution is marked real when every coordinate's imaginary part is below this times max(1, |x|)
(after Newton): a numerical judgement, said so in the output."""

DISTINCT_TOL = 1e-6
"""Two solutions closer than this (relative, max norm) count as one (then the count check fails)."""

SINGULAR_COND = 1e10
"""A Jacobian with condition number above this counts as singular (a multiple root, or no check)."""


class SolveError(ValueError):
    """The system cannot be solved by this method (not characteristic 0, not zero-dimensional, ...)."""


@dataclass(frozen=True)
class Solution:
    """One solution: complex coordinates (in the system's unknowns), whether it is real, its residual
    max |f_k(z)| and the condition number of its Jacobian."""

    values: tuple[complex, ...]
    real: bool
    residual: float
    condition: float


@dataclass(frozen=True)
class SystemSolutions:
    """All solutions of a zero-dimensional system and what was checked.

    degree: the number of solutions with multiplicity, certified over GF(p) (``certificate`` says by
    which primes). complete: |solutions| == degree, pairwise distinct, every Jacobian nonsingular.
    status: one line: what was checked, or what failed.
    """

    unknowns: tuple[str, ...]
    degree: int
    dimension: int
    solutions: tuple[Solution, ...]
    certificate: str
    basis_status: str
    method: str
    complete: bool
    status: str
    primes: tuple[int, ...]
    seconds: float
    seed: int = 0
    timings: dict = field(default_factory=dict, compare=False)

    @property
    def max_residual(self) -> float:
        return max((s.residual for s in self.solutions), default=0.0)

    @property
    def n_real(self) -> int:
        return sum(s.real for s in self.solutions)

    def as_dict(self) -> dict:
        """JSON-ready values; a coordinate is a number when the solution is real, else [re, im]."""
        def value(z: complex, real: bool):
            return float(z.real) if real else [float(z.real), float(z.imag)]

        return {
            "unknowns": list(self.unknowns),
            "degree": self.degree,
            "dimension": self.dimension,
            "certificate": self.certificate,
            "basis_status": self.basis_status,
            "method": self.method,
            "complete": self.complete,
            "status": self.status,
            "n_solutions": len(self.solutions),
            "n_real": self.n_real,
            "max_residual": self.max_residual,
            "primes": list(self.primes),
            "seed": self.seed,
            "seconds": round(self.seconds, 6),
            "solutions": [{"values": {u: value(z, s.real) for u, z in zip(self.unknowns, s.values)},
                           "real": s.real, "residual": s.residual, "condition": s.condition}
                          for s in self.solutions],
        }


# --------------------------------------------------------------------------------------------------
# input: parameter values, instances of parametric systems
# --------------------------------------------------------------------------------------------------

def parameter_values(items: Sequence[str], where: str = "--param") -> dict[str, Fraction]:
    """``name=value`` texts to exact values: a value is an integer, a decimal, scientific notation
    (``-1.25e-3`` is -1/800, ``1e300`` is 10^300) or a fraction (``3/4``), read exactly by the project's
    number reader (:func:`analysis.engine.polytext.read_number`, the one of system files; no evaluation);
    a name given twice, a missing ``=`` or a value like ``nan`` is a :class:`SolveError`."""
    out: dict[str, Fraction] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name, text = name.strip(), text.strip()
        if not sep or not name or not text:
            raise SolveError(f"{where}: expected name=value, got {item!r}")
        try:
            value = read_number(text, f"{where}: {name}")
        except InputError as exc:
            raise SolveError(str(exc)) from None
        if name in out:
            raise SolveError(f"{where}: {name} given twice")
        out[name] = value
    return out


def _polynomial(text: str, names: Sequence[str], where: str):
    from analysis.engine.polytext import parse_polynomial

    return parse_polynomial(text, names, 0, source=where)


def _evaluate(poly: Mapping[tuple[int, ...], Fraction], values: Sequence[Fraction]) -> Fraction:
    total = Fraction(0)
    for e, c in poly.items():
        for v, k in zip(values, e):
            if k:
                c = c * v ** k
        total += c
    return total


def instance_system(system, values: Mapping[str, Fraction], source: str = "<system>", saturate: bool = True):
    """The instance of a parametric system (:class:`analysis.formulations.parametric.ParametricSystem`)
    at exact parameter values: an :class:`analysis.engine.io.System` over Q in the unknowns (definitions
    evaluated exactly from the parameters), with ``saturate`` saturated by the product of its nonzero
    conditions (one more unknown t, last). Every parameter needs a value (:class:`SolveError` names the
    missing and the unknown ones); a parameter the system declares unused may be left out."""
    from analysis.engine.io import System

    missing = [q for q in system.parameters if q not in values and q not in system.unused]
    unknown = [q for q in values if q not in system.parameters]
    if missing or unknown:
        raise SolveError("parameter values: " + "; ".join(
            ([f"missing {', '.join(missing)} (give --param NAME=VALUE)"] if missing else [])
            + ([f"{', '.join(unknown)} not a parameter of the system (its parameters: "
                f"{', '.join(system.parameters) or 'none'})"] if unknown else [])))
    known = {q: values.get(q, Fraction(0)) for q in system.parameters}
    for name, text in system.definitions:  # data only, in order: each may use the earlier ones
        names = tuple(known)
        known[name] = _evaluate(_polynomial(text, names, f"{source}: definition {name}"), [known[k] for k in names])
    names = tuple(system.unknowns) + tuple(known)
    n = len(system.unknowns)
    q = list(known.values())

    def substitute(text: str, what: str) -> dict:
        out: dict[tuple[int, ...], Fraction] = {}
        for e, c in _polynomial(text, names, f"{source}: {what}").items():
            for v, k in zip(q, e[n:]):
                if k:
                    c = c * v ** k
            if c:
                key = tuple(e[:n])
                out[key] = out.get(key, Fraction(0)) + c
        return {e: c for e, c in out.items() if c}

    polys = tuple(substitute(t, f"equation {k + 1}") for k, t in enumerate(system.equations))
    instance = System(tuple(system.unknowns), 0, polys, source=source)
    if system.nonzero and saturate:
        from analysis.formulations.systemfile import _multiply

        product: dict = {(0,) * n: Fraction(1)}
        for k, t in enumerate(system.nonzero):
            product = _multiply(product, substitute(t, f"nonzero condition {k + 1}"))
        instance = instance.saturated_by(product)
    return instance


# --------------------------------------------------------------------------------------------------
# exact part: count and basis over Q, action matrices
# --------------------------------------------------------------------------------------------------

def _grevlex_key(e: tuple[int, ...]) -> tuple:
    return (sum(e), tuple(-x for x in reversed(e)))


def _action_matrices(basis: Sequence[Mapping[tuple[int, ...], Fraction]], standard: list[tuple[int, ...]],
                     nvars: int) -> list[list[dict[int, Fraction]]]:
    """For every unknown x_i the columns NF(x_i b), b in ``standard``, as {index in standard: coefficient}.

    A border monomial m is in B, or the leading monomial of a basis element g (NF = lm - g), or a
    multiple x_k m' of a monomial m' outside B: NF(m) = sum c_b NF(x_k b) over NF(m') = sum c_b b, whose
    monomials x_k b are below m in grevlex (the recursion ends)."""
    index = {b: j for j, b in enumerate(standard)}
    lead: dict[tuple[int, ...], dict[int, Fraction]] = {}
    for g in basis:
        lm = max(g, key=_grevlex_key)
        c = g[lm]
        lead[lm] = {index[e]: -v / c for e, v in g.items() if e != lm}  # reduced basis: tails lie in B
    memo: dict[tuple[int, ...], dict[int, Fraction]] = {}

    def nf(m: tuple[int, ...]) -> dict[int, Fraction]:
        if m in index:
            return {index[m]: Fraction(1)}
        if m in lead:
            return lead[m]
        if m in memo:
            return memo[m]
        k = next(k for k in range(nvars) if m[k] and m[:k] + (m[k] - 1,) + m[k + 1:] not in index)
        inner = nf(m[:k] + (m[k] - 1,) + m[k + 1:])
        out: dict[int, Fraction] = {}
        for j, c in inner.items():
            b = standard[j]
            for i, d in nf(b[:k] + (b[k] + 1,) + b[k + 1:]).items():
                out[i] = out.get(i, 0) + c * d
        memo[m] = out = {i: c for i, c in out.items() if c}
        return out

    return [[nf(b[:i] + (b[i] + 1,) + b[i + 1:]) for b in standard] for i in range(nvars)]


def _standard_monomials(basis: Sequence[Mapping[tuple[int, ...], Fraction]], nvars: int) -> list[tuple[int, ...]]:
    """The monomials divisible by no leading monomial (grevlex), increasing; finite for a zero-dimensional
    ideal (every unknown has a pure power among the leading monomials)."""
    leads = [max(g, key=_grevlex_key) for g in basis]
    bounds = []
    for i in range(nvars):
        powers = [lm[i] for lm in leads if sum(lm) == lm[i]]
        if not powers:
            raise SolveError("not zero-dimensional (no pure power of an unknown leads the basis)")
        bounds.append(min(powers))
    out, frontier = [], [(0,) * nvars]
    seen = set(frontier)
    while frontier:
        m = frontier.pop()
        if any(all(a >= b for a, b in zip(m, lm)) for lm in leads):
            continue
        out.append(m)
        for i in range(nvars):
            n = m[:i] + (m[i] + 1,) + m[i + 1:]
            if n[i] < bounds[i] and n not in seen:
                seen.add(n)
                frontier.append(n)
    return sorted(out, key=_grevlex_key)


# --------------------------------------------------------------------------------------------------
# numeric part: evaluation, eigenvectors, Newton
# --------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class FloatScaling:
    """How a system over Q became floats: the power of two 2^-k each equation was multiplied by (0: as
    written) and how many of its nonzero coefficients fell below float64's range after that (dropped)."""

    shifts: tuple[int, ...]
    dropped: int = 0

    def describe(self) -> str:
        """One clause for a status ('' when every equation kept its coefficients as written)."""
        scaled = [(k + 1, s) for k, s in enumerate(self.shifts) if s]
        if not scaled and not self.dropped:
            return ""
        text = ("equations scaled for float64 (largest coefficient in [1, 2); the solutions are unchanged, "
                "residuals are of the scaled equations): " + ", ".join(f"{k} by 2^{-s}" for k, s in scaled)) if scaled else ""
        if self.dropped:
            text += ("; " if text else "") + (f"{self.dropped} coefficient(s) below float64's range relative to their "
                                              "equation's largest were dropped: the floating-point system is not the "
                                              "exact one")
        return text


def float_coefficients(polys: Sequence[Mapping[tuple[int, ...], Fraction]]
                       ) -> tuple[list[dict[tuple[int, ...], float]], FloatScaling]:
    """The polynomials' coefficients as floats, where the numerics start: each equation as written when
    its largest coefficient lies within 2^+-SCALE_BITS, else scaled by the power of two that brings it
    into [1, 2) (exactly, before rounding); see :class:`FloatScaling`."""
    out, shifts, dropped = [], [], 0
    for f in polys:
        k = equation_shift(Fraction(c) for c in f.values())
        row = {e: scaled_float(Fraction(c), k) for e, c in f.items() if c}
        dropped += sum(1 for v in row.values() if v == 0.0)
        out.append({e: v for e, v in row.items() if v})
        shifts.append(k)
    return out, FloatScaling(tuple(shifts), dropped)


def unknown_shifts(columns: Sequence[Sequence[Mapping[int, Fraction]]], standard: Sequence[tuple[int, ...]],
                   nvars: int) -> tuple[int, ...]:
    """Powers of two s_i for the unknowns (x_i = 2^s_i y_i) when some entry of the exact action matrices lies
    beyond 2^+-SCALE_BITS (else all 0: the unknowns as written): s_i = log2 of the geometric mean of |x_i| over
    the solutions where x_i != 0, exactly from the characteristic polynomial of x_i's action matrix (its
    eigenvalues are x_i's values: with lowest nonzero coefficient c_k of the monic degree-n polynomial, the
    product of the n - k nonzero ones is +-c_k). In y the coordinates are then near 1 in magnitude when the
    solutions share a scale, so that the float64 eigenvectors, the distinctness and realness tolerances and
    Newton's steps work at that scale (solutions near 1e-150 or 1e200). (Balancing the entries themselves, by a
    linear program on their log2, was tried first: it brings a negligible 1e-5000 entry up at the price of
    overflowing the others.)"""
    import flint

    if all(abs(log2_floor(c)) <= SCALE_BITS for cols in columns for col in cols for c in col.values()):
        return (0,) * nvars
    size = len(standard)
    shifts = []
    for cols in columns:
        M = flint.fmpq_mat(size, size)
        for k, col in enumerate(cols):
            for j, c in col.items():
                M[j, k] = flint.fmpq(c.numerator, c.denominator)
        coeffs = [Fraction(int(c.p), int(c.q)) for c in M.charpoly().coeffs()]  # lowest first, monic
        low = next(k for k, c in enumerate(coeffs) if c)
        nonzero_roots = len(coeffs) - 1 - low
        shifts.append(round(log2_floor(coeffs[low]) / nonzero_roots) if nonzero_roots else 0)
    return tuple(shifts)


def _shift(c: Fraction, k: int) -> Fraction:
    """c * 2^k, exactly."""
    return Fraction(c.numerator << k, c.denominator) if k >= 0 else Fraction(c.numerator, c.denominator << -k)


class _Evaluator:
    """The input polynomials and their Jacobian at a batch of complex points: every monomial that the
    polynomials and their derivatives use is evaluated once per point, then two matrix products. The
    coefficients are those of :func:`float_coefficients` (``scaling`` says how they were scaled)."""

    def __init__(self, polys: Sequence[Mapping[tuple[int, ...], Fraction]], nvars: int):
        self.nvars = nvars
        polys, self.scaling = float_coefficients([f for f in polys if f])
        columns: dict[tuple[int, ...], int] = {}
        entries_f, entries_j = [], []  # (monomial column, equation[, unknown], coefficient)
        for r, f in enumerate(polys):
            for e, c in f.items():
                entries_f.append((columns.setdefault(e, len(columns)), r, c))
                for i in range(nvars):
                    if e[i]:
                        d = e[:i] + (e[i] - 1,) + e[i + 1:]
                        entries_j.append((columns.setdefault(d, len(columns)), r, i, c * e[i]))
        self.exponents = np.array(list(columns), dtype=np.int64).reshape(len(columns), nvars)
        self.C = np.zeros((len(columns), len(polys)), dtype=complex)
        for u, r, c in entries_f:
            self.C[u, r] += c
        self.G = np.zeros((len(columns), len(polys) * nvars), dtype=complex)
        for u, r, i, c in entries_j:
            self.G[u, r * nvars + i] += c
        self.m = len(polys)

    def _monomials(self, X: np.ndarray) -> np.ndarray:
        return np.prod(X[:, None, :] ** self.exponents[None, :, :], axis=2)

    def values(self, X: np.ndarray) -> np.ndarray:
        """(K, n) points -> (K, m) values."""
        return self._monomials(X) @ self.C

    def jacobian(self, X: np.ndarray) -> np.ndarray:
        """(K, n) points -> (K, m, n) Jacobians."""
        return (self._monomials(X) @ self.G).reshape(len(X), self.m, self.nvars)


def _newton(ev: _Evaluator, X: np.ndarray, steps: int = NEWTON_STEPS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Newton (Gauss-Newton for more equations) from every point of X (K, n), a step kept only where it
    lowers the residual: (points, max |f| per point, condition number of each Jacobian with its rows
    scaled to unit norm, so that an equation's scale does not count as ill-conditioning)."""
    X = np.array(X, dtype=complex)
    with np.errstate(all="ignore"):
        res = np.abs(ev.values(X)).max(axis=1)
        for _ in range(steps):
            J, f = ev.jacobian(X), ev.values(X)
            step = -np.einsum("kij,kj->ki", np.linalg.pinv(J), f)
            trial = X + step
            r = np.abs(ev.values(trial)).max(axis=1)
            better = np.isfinite(r) & (r < res)
            if not better.any():
                break
            X[better], res[better] = trial[better], r[better]
        J = ev.jacobian(X)
        J = J / np.maximum(np.linalg.norm(J, axis=2, keepdims=True), np.finfo(float).tiny)  # rows equilibrated
        sv = np.linalg.svd(J, compute_uv=False)
        cond = np.where(sv[:, -1] > 0, sv[:, 0] / sv[:, -1], np.inf)
    return X, res, cond


def _eigen_points(A: list[np.ndarray], rng: np.random.Generator) -> np.ndarray:
    """The solutions' coordinates from the action matrices (A_i[j, k]: coefficient of b_j in NF(x_i b_k);
    b_0 = 1): eigenvectors v of the transposed action matrix of a random form give x_i = (v A_i)[0] / v[0]."""
    weights = rng.standard_normal(len(A))
    L = sum(w * a for w, a in zip(weights, A))
    _, V = np.linalg.eig(L.T)
    V = V.T  # rows: left eigenvectors of L (evaluation vectors up to scale)
    return np.stack([(V @ a)[:, 0] / V[:, 0] for a in A], axis=1)


def _distinct(points: np.ndarray) -> bool:
    if len(points) < 2:
        return True
    scale = np.maximum(1.0, np.abs(points).max(axis=1))
    for k in range(1, len(points)):
        gaps = np.abs(points[:k] - points[k]).max(axis=1) / np.maximum(scale[:k], scale[k])
        if gaps.min() < DISTINCT_TOL:
            return False
    return True


def _polish_and_check(points: np.ndarray, ev: "_Evaluator", degree: int, shown: int, lost: int = 0,
                      shifts: Sequence[int] = (), source: str = "<system>", lost_what: str = "path(s) lost") -> tuple[tuple["Solution", ...], bool, str]:
    """Newton on every point, real ones marked, sorted (real first); complete when there are ``degree``
    points, pairwise distinct, each with a nonsingular Jacobian. Returns (solutions, complete, status).
    ``shifts``: the points are in y, x_i = 2^shifts[i] y_i (:func:`unknown_shifts`): checked in y, reported
    in x; a coordinate outside float64's range is a :class:`SolveError` naming its size."""
    X, residuals, conditions = _newton(ev, np.asarray(points, dtype=complex).reshape(-1, ev.nvars))
    shifts = np.array(list(shifts) or [0] * ev.nvars, dtype=np.int64)
    if shifts.any():
        with np.errstate(divide="ignore"):
            size = np.log2(np.abs(X[:, :shown])) + shifts[:shown]
        if np.any(size[np.isfinite(size)] > 1023) or np.any(size[np.isfinite(size)] < -1021):
            top = size[np.isfinite(size)]
            worst = top.max() if top.max() > 1023 else top.min()
            raise SolveError(f"{source}: solutions with coordinates of about 2^{worst:.0f} (1e{worst * 0.30103:.0f}): "
                             "outside float64's range; rescale the unknowns (x = 10^k y)")
    solutions = []
    for z, res, cond in zip(X, residuals, conditions):
        real = bool(np.all(np.abs(z.imag) <= REAL_TOL * np.maximum(1.0, np.abs(z))))
        if real:
            z = z.real.astype(complex)
            res = float(np.abs(ev.values(z[None])).max())
        x = np.ldexp(z.real, shifts) + 1j * np.ldexp(z.imag, shifts) if shifts.any() else z
        solutions.append(Solution(tuple(complex(v) for v in x[:shown]), real, float(res), float(cond)))
    order = sorted(range(len(solutions)), key=lambda k: (not solutions[k].real,
                                                         tuple(round(v.real, 12) for v in solutions[k].values),
                                                         tuple(round(v.imag, 12) for v in solutions[k].values)))
    solutions = [solutions[k] for k in order]
    distinct = _distinct(X)
    simple = all(s.condition < SINGULAR_COND for s in solutions)
    complete = len(solutions) == degree and distinct and simple
    worst = max((s.residual for s in solutions), default=0.0)
    scaled = ev.scaling.describe()
    if shifts.any():
        scaled = "; ".join(filter(None, [f"unknowns scaled for float64 (x = 2^s y; checked and residuals in y): " + ", ".join(
            f"s = {k} for unknown {i + 1}" for i, k in enumerate(shifts) if k), scaled]))
    if complete:
        status = (f"all {degree} solutions: pairwise distinct, each with a nonsingular Jacobian (condition "
                  f"<= {max((s.condition for s in solutions), default=0.0):.2g}), residual <= {worst:.2g}; real ones "
                  f"judged numerically (|imaginary part| <= {REAL_TOL:g} relative)")
    else:
        why = ([f"{lost} {lost_what}"] if lost else []) + \
            (["points closer than the distinctness tolerance (a multiple root or lost accuracy)"] if not distinct else []) + \
            (["a singular Jacobian (a multiple root?)"] if not simple else []) + \
            ([f"{len(solutions)} points for degree {degree}"] if len(solutions) != degree else [])
        status = (f"NOT checked complete: {'; '.join(why)}; {len(solutions)} points for degree {degree} (with "
                  f"multiplicity), residual <= {worst:.2g}")
    if scaled:
        status += f"; {scaled}"
    return tuple(solutions), complete, status


# --------------------------------------------------------------------------------------------------
# the drivers
# --------------------------------------------------------------------------------------------------

def solve_system(system, seed: int = 0, prime_seed: int = 0, options=None, hidden: int | None = None,
                 progress: Callable[[str], None] | None = None) -> SystemSolutions:
    """Every solution of a zero-dimensional system over Q (:class:`analysis.engine.io.System`).

    Parameters
    ----------
    system: characteristic 0; more equations than unknowns are allowed.
    seed: seed of the random linear form whose action matrix is diagonalised.
    prime_seed: seed of the random primes (mixed with a hash of the system, as ``degree`` does).
    options: F4 options (:class:`analysis.engine.f4.F4Options`; default: F4's defaults with the linear
        inputs substituted first).
    hidden: the number of leading unknowns reported (default all; a saturated instance from
        :func:`instance_system` hides its last unknown t).
    progress: called with one line per phase (the CLI prints them on stderr).

    Returns a :class:`SystemSolutions`; raises :class:`SolveError` for a system of characteristic p, or
    one that is not zero-dimensional, and the engine's errors (MatrixTooLarge, PrimeDisagreement,
    ReconstructionFailed) when the count or the basis over Q cannot be had.
    """
    from analysis.engine.degree import analyse_prime
    from analysis.engine.f4 import F4Options
    from analysis.engine.modular import analyse_rational, input_seed, rational_basis

    say = progress or (lambda line: None)
    t0 = time.perf_counter()
    if system.characteristic:
        raise SolveError(f"{system.source}: characteristic {system.characteristic}: solve needs a system over Q "
                         "(characteristic 0); degree counts solutions over GF(p)")
    options = options or F4Options(linear_substitution=True)
    nvars = system.nvars
    exact = list(system.polynomials)

    def compute(p: int):
        return analyse_prime(system.to_ring(p)[1], options)

    key = input_seed(system.variables, exact, prime_seed)
    rational = analyse_rational(exact, "grevlex", nvars, compute, None, key)
    report = rational.report
    t_count = time.perf_counter()
    shown = tuple(system.variables[:nvars if hidden is None else hidden])
    if report.dimension < 0:  # inconsistent: no solution, certified like a degree
        return SystemSolutions(shown, 0, -1, (), f"certified over GF(p): {rational.status}", "", METHOD, True,
                               "no solution: the ideal is the whole ring over the agreeing primes", report.primes,
                               time.perf_counter() - t0, seed)
    if report.dimension != 0:
        raise SolveError(f"{system.source}: not zero-dimensional (dimension {report.dimension}): infinitely many "
                         "solutions; add equations or fix unknowns")
    say(f"[solve] degree {report.degree} ({t_count - t0:.2f} s): {rational.status}")
    basis, basis_status = rational_basis(rational, exact, "grevlex", nvars, compute, key, generators=exact,
                                         progress=say)
    t_basis = time.perf_counter()
    say(f"[solve] basis over Q ({t_basis - t_count:.2f} s): {basis_status}")
    standard = _standard_monomials(basis, nvars)
    if len(standard) != report.degree:
        raise SolveError(f"internal: {len(standard)} standard monomials over Q, degree {report.degree} over GF(p)")
    columns = _action_matrices(basis, standard, nvars)
    shifts = unknown_shifts(columns, standard, nvars)
    if any(shifts):  # x = 2^s y, exactly: the action matrices and the equations in y
        columns = [[{j: _shift(c, sum(shifts[v] * (standard[j][v] - standard[k][v]) for v in range(nvars)) - shifts[i])
                     for j, c in col.items()} for k, col in enumerate(cols)] for i, cols in enumerate(columns)]
        exact = [{e: _shift(c, sum(a * b for a, b in zip(shifts, e))) for e, c in f.items()} for f in exact]
    A = []
    for i, cols in enumerate(columns):
        M = np.zeros((len(standard), len(standard)))
        for k, col in enumerate(cols):
            for j, c in col.items():
                if abs(log2_floor(c)) > 1020 and log2_floor(c) > 0:
                    raise SolveError(f"{system.source}: the action matrix of {system.variables[i]} has an entry of about "
                                     f"2^{log2_floor(c)} (above float64's 1.8e308): solutions this large cannot be had in "
                                     "floating point; rescale the unknowns (x = 10^k y)")
                M[j, k] = scaled_float(c, 0)
        A.append(M)
    t_action = time.perf_counter()
    say(f"[solve] {nvars} action matrices {len(standard)} x {len(standard)} ({t_action - t_basis:.2f} s)")
    with np.errstate(all="ignore"):
        points = _eigen_points(A, np.random.default_rng(seed))
    finite = np.all(np.isfinite(points), axis=1)  # an eigenvector without its constant entry: lost in float64
    solutions, complete, status = _polish_and_check(
        points[finite], _Evaluator(exact, nvars), report.degree, len(shown), lost=int((~finite).sum()), shifts=shifts,
        source=system.source, lost_what="eigenvector(s) lost in float64 (solutions whose coordinates span more than "
                                        "float64's precision?)")
    t_newton = time.perf_counter()
    say(f"[solve] eigenvectors and Newton ({t_newton - t_action:.2f} s)")
    return SystemSolutions(shown, report.degree, 0, solutions, f"certified over GF(p): {rational.status}",
                           basis_status, METHOD,
                           complete, status, report.primes, time.perf_counter() - t0, seed,
                           {"count": t_count - t0, "basis": t_basis - t_count, "action": t_action - t_basis,
                            "newton": t_newton - t_action})


# --------------------------------------------------------------------------------------------------
# parameter homotopy: a generated solver of the parametric system, built once and cached
# --------------------------------------------------------------------------------------------------

HOMOTOPY = "parameter homotopy"

CACHE_KIND = "solve"
"""Subdirectory of the cache (:func:`analysis.sweeps.paths.cache_dir`) holding the generated solvers."""


def _system_key(system, target, seed: int) -> str:
    import hashlib
    import json

    from importlib.metadata import PackageNotFoundError, version

    try:
        release = version("tdoa-workbench")
    except PackageNotFoundError:
        release = "source"
    text = json.dumps({"target": target if isinstance(target, str) else None, "unknowns": list(system.unknowns),
                       "parameters": list(system.parameters), "equations": list(system.equations),
                       "nonzero": list(system.nonzero), "definitions": [list(d) for d in system.definitions],
                       "seed": seed, "version": release}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def generated_solver(system, target=None, seed: int = 0, progress: Callable[[str], None] | None = None,
                     _retry: bool = False):
    """(module, spec) of the parameter-homotopy solver of a parametric system: generated by
    :func:`solvers.generate.generate` (root count certified over GF(p), start roots by monodromy) the first
    time into the cache (``<cache>/solve/<key>/``, key: a hash of the system and the seed), imported from
    there afterwards. ``target``: what to generate from (a TDOA formulation label draws TDOA start
    instances; default the system itself)."""
    import importlib.util
    import json
    import os
    import shutil
    import tempfile

    from analysis.sweeps.paths import cache_dir
    from solvers.generate import generate

    key = _system_key(system, target, seed)
    home = cache_dir(CACHE_KIND) / key
    found = sorted(home.glob("*.py")) if home.is_dir() else []
    if not found:
        home.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{key}-", dir=home.parent))
        try:
            built = generate(target if target is not None else system, "homotopy", out=str(tmp), name=f"solve_{key}",
                             seed=seed, progress=progress)
            if progress:
                progress(f"[solve] {built.summary()}")
            try:
                os.replace(tmp, home)
            except OSError:  # another process wrote it first: use theirs
                shutil.rmtree(tmp, ignore_errors=True)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)
        found = sorted(home.glob("*.py"))
    path = found[0]
    spec = json.loads(path.with_suffix(".json").read_text())
    loader = importlib.util.spec_from_file_location(f"_tdoa_solve_{key}", path)
    module = importlib.util.module_from_spec(loader)
    try:
        loader.loader.exec_module(module)
    except (ImportError, AttributeError):  # written by an older layout of the package: build it again
        if _retry:
            raise
        shutil.rmtree(home, ignore_errors=True)
        return generated_solver(system, target, seed, progress, _retry=True)
    return module, spec


def solve_by_homotopy(system, values: Mapping[str, Fraction], target=None, seed: int = 0, source: str = "<system>",
                      progress: Callable[[str], None] | None = None) -> SystemSolutions:
    """Every solution of a parametric system's instance by parameter homotopy.

    The generated solver (:func:`generated_solver`) tracks its start roots (a generic complex instance,
    as many as the count certified over GF(p)) to the parameter values; the endpoints are polished by
    Newton steps on the exact instance and checked as by :func:`solve_system` (as many distinct, simple
    points as the certified count). A nonzero condition is honoured by the solver's start roots.
    """
    say = progress or (lambda line: None)
    t0 = time.perf_counter()
    instance = instance_system(system, values, source, saturate=False)
    for name, v in values.items():  # the homotopy tracks in float64: a value it cannot hold is refused by name
        if v and log2_floor(v) > SCALE_BITS:
            raise SolveError(f"{name} = 2^{log2_floor(v)} (about): beyond "
                             f"2^{SCALE_BITS}, too far from the generated solver's start values for tracking in "
                             "float64; --method action-matrix solves the instance exactly")
    module, spec = generated_solver(system, target, seed, progress)
    t_build = time.perf_counter()
    q = np.array([float(values.get(p, 0)) for p in spec["parameters"]])
    arg = q.reshape(spec["config"]) if spec.get("config") else q  # a TDOA solver takes its data matrix F
    with np.errstate(all="ignore"):
        ends = np.asarray(module.solve(arg))
    finite = np.all(np.isfinite(ends), axis=1)
    t_track = time.perf_counter()
    degree = int(spec["degree"])
    say(f"[solve] {len(ends)} paths tracked, {int((~finite).sum())} lost ({t_track - t_build:.2f} s)")
    solutions, complete, status = _polish_and_check(ends[finite], _Evaluator(instance.polynomials, instance.nvars),
                                                    degree, instance.nvars, lost=int((~finite).sum()))
    certified = spec.get("certified")
    certificate = (f"certified over GF(p) for generic parameters: primes {', '.join(map(str, certified['primes']))} "
                   f"x seeds {', '.join(map(str, certified['seeds']))} (the generated solver's count)" if certified else
                   "not certified: the generated solver's count is numerical evidence from monodromy")
    t_end = time.perf_counter()
    say(f"[solve] Newton and checks ({t_end - t_track:.2f} s)")
    return SystemSolutions(tuple(instance.variables), degree, 0, solutions, certificate,
                           f"solver {spec['name']} ({spec['paths']} paths, monodromy seed {seed})", HOMOTOPY,
                           complete, status, tuple(certified["primes"]) if certified else (), t_end - t0, seed,
                           {"build": t_build - t0, "track": t_track - t_build, "newton": t_end - t_track})
