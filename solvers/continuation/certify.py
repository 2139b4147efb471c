"""Proofs that numerical solutions are solutions: Krawczyk's test in ball arithmetic (python-flint's acb).

For a square system F(x) = 0 (N equations, N unknowns; the coefficients evaluated exactly at the parameters
q, which are taken as the binary numbers they are) and an approximate solution x~, take Y ~ F'(x~)^-1 and the
box X = x~ + [-r, r]^N (real and imaginary parts of every coordinate). Krawczyk's operator

    K(X) = x~ - Y F(x~) + (I - Y F'(X)) (X - x~)

evaluated in ball arithmetic (F'(X) an enclosure of the Jacobian over the whole box) lies in the interior of X
only if X holds exactly one solution of F, and it is non-singular (Krawczyk 1969; Moore 1977; the test of
HomotopyContinuation.jl's ``certify``, Breiding, Rose, Timme, "Certifying zeros of polynomial systems using
interval arithmetic", ACM TOMS 49 (2023)). Every evaluation here is in arb's balls (Johansson, "Arb",
IEEE Trans. Comput. 66 (2017)), so the inclusion is a proof, not a floating-point estimate.

What a proven set says: each box holds one solution; boxes that are pairwise disjoint (with a group acting on
the solutions, also every box against every image of every other) hold distinct solutions (distinct orbits),
so their number is a proven lower bound on the number of solutions (orbits). The non-vanishing conditions of
the system (det H != 0 of the TDOA formulations) are proven too: their enclosure over the box excludes 0. A
point that is not near a solution (a fake) cannot pass: the inclusion would prove a solution in its box.

Ill-conditioned solutions (norm 10^3-10^6, where double precision leaves Newton's step at 1e-7-1e-5) fail at
53 bits and are proven at :data:`HIGH_PRECISION` bits after Newton's method at that precision.
"""
from __future__ import annotations

import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Callable

import numpy as np
import sympy
from flint import acb, acb_mat, arb, ctx

__all__ = ["BallSystem", "Certificate", "TapeBalls", "certify", "disjoint", "refine", "HIGH_PRECISION"]

#: Precision (bits) of the second attempt on a solution that double precision cannot prove.
HIGH_PRECISION = 160

#: Radii tried, relative to 1 + |x~|_inf, after the one sized by the Newton step (smallest first: small boxes
#: are disjoint and hold one solution; a larger one can be needed where F' varies fast).
RADII = (1e-11, 1e-8)

#: Largest move of Newton's refinement, relative to 1 + |x|_inf, for the proof to be the given point's (the
#: tolerance under which monodromy takes two points for one solution).
MOVED = 1e-6

#: Margin of the floating-point disjointness test (relative to the boxes' sizes; far above rounding).
MARGIN = 1e-9


def _exact(z: complex) -> acb:
    return acb(float(z.real), float(z.imag))


class _Precision:
    """``with _Precision(bits):`` arb's working precision for the block, restored after it."""

    def __init__(self, bits: int):
        self.bits = bits

    def __enter__(self):
        self.saved = ctx.prec
        ctx.prec = self.bits

    def __exit__(self, *exc):
        ctx.prec = self.saved


def _ball_value(expr: sympy.Expr, gens: tuple, values: list) -> acb:
    """An expression polynomial in ``gens`` (rational coefficients) at ball values."""
    if not expr.free_symbols:
        r = sympy.Rational(expr)
        return acb(int(r.p)) / int(r.q)
    poly = sympy.Poly(expr, *gens)
    out = acb(0)
    for mon, c in poly.terms():
        r = sympy.Rational(c)
        t = acb(int(r.p)) / int(r.q)
        for v, e in zip(values, mon):
            if e:
                t *= v ** e
        out += t
    return out


class BallSystem:
    """The equations and non-vanishing conditions of a :class:`analysis.formulations.parametric.ParametricSystem`
    at parameters q, as polynomials in the unknowns with ball coefficients (the parameters exact, the
    definitions and coefficients evaluated in ball arithmetic at :data:`HIGH_PRECISION` bits)."""

    def __init__(self, system, q: np.ndarray):
        self.N = len(system.unknowns)
        q = np.asarray(q, dtype=complex)
        with _Precision(HIGH_PRECISION + 40):
            values = [_exact(v) for v in q]
            gens = tuple(system.q_symbols)
            for sym, expr in zip(system.aux_symbols, system.aux_exprs):
                values.append(_ball_value(expr, gens, values))
                gens = gens + (sym,)
            self.equations = [[(tuple(mon), _ball_value(c, gens, values)) for mon, c in eq] for eq in system.terms]
            self.nonzero = [[(tuple(mon), _ball_value(c, gens, values)) for mon, c in sympy.Poly(g, *system.x_symbols).terms()]
                            for g in system.nonzero_exprs]
        self.degree = np.max([mon for eq in self.equations + self.nonzero for mon, _ in eq], axis=0)
        # the Jacobian's terms: (equation, unknown, coefficient times exponent, the exponents after d/dx_v)
        self.derivatives = []
        for e, terms in enumerate(self.equations):
            for mon, c in terms:
                for v in [v for v, a in enumerate(mon) if a]:
                    dmon = tuple(a - 1 if w == v else a for w, a in enumerate(mon))
                    self.derivatives.append((e, v, c * mon[v], dmon))
        self._dmid = [(e, v, complex(float(c.real.mid()), float(c.imag.mid())), np.array(d))
                      for e, v, c, d in self.derivatives]

    def _powers(self, x: list) -> list:
        out = []
        for v, d in zip(x, self.degree):
            p = [acb(1), v]
            for _ in range(2, int(d) + 1):
                p.append(p[-1] * v)
            out.append(p)
        return out

    @staticmethod
    def _monomial(c: acb, mon: tuple, pw: list) -> acb:
        t = c
        for v, a in enumerate(mon):
            if a:
                t = t * pw[v][a]
        return t

    def _polys(self, polys: list, x: list) -> list:
        pw = self._powers(x)
        return [sum((self._monomial(c, mon, pw) for mon, c in terms), acb(0)) for terms in polys]

    def values(self, x: list) -> list:
        """F at x (a list of N acb balls)."""
        return self._polys(self.equations, x)

    def conditions(self, x: list) -> list:
        """The non-vanishing conditions at x."""
        return self._polys(self.nonzero, x)

    def jacobian(self, x: list) -> acb_mat:
        """F' at x (an enclosure over the box when x holds balls)."""
        pw = self._powers(x)
        J = [[acb(0)] * self.N for _ in range(self.N)]
        for e, v, c, dmon in self.derivatives:
            J[e][v] = J[e][v] + self._monomial(c, dmon, pw)
        return acb_mat(J)

    def jacobians(self, x: np.ndarray) -> np.ndarray:
        """F' at points x (K, N) in floating point (the coefficients' midpoints): (K, N, N), for the
        preconditioners Y ~ F'^-1 (any matrix is sound there: the test proves what it proves whatever Y is)."""
        J = np.zeros((len(x), self.N, self.N), dtype=complex)
        for e, v, c, dmon in self._dmid:
            J[:, e, v] += c * np.prod(x ** dmon, axis=1)
        return J


class TapeBalls:
    """A homotopy's Newton tape (:class:`.slp.HomotopyTapes`' ``newton``: H and its Jacobian) at parameters q (s = 0),
    run in arb's complex balls instruction by instruction on many points at once (numpy arrays of acb): Newton's
    method at more than double precision for a system that is a program rather than a :class:`ParametricSystem`
    (the trace test's curve, :mod:`.trace`). The parameters and the tape's constants are the binary numbers they
    are."""

    def __init__(self, tapes, q: np.ndarray):
        tape = tapes.newton
        q = np.asarray(q, dtype=complex)
        self.N = tape.n_inputs - 1 - 2 * len(q)  # inputs: x, s, q0, dq
        if self.N < 1 or self.N * (self.N + 1) != tape.n_outputs:
            raise ValueError(f"a Newton tape of {tape.n_inputs} inputs and {tape.n_outputs} outputs does not take "
                             f"{len(q)} parameters")
        self._tape, self._q = tape, q

    def run(self, x: list) -> list:
        """The tape's outputs (H, then H' row by row) at the points x: N arrays (K,) of acb, one per unknown."""
        from .tape_jit import ADD, AXPY, CADD, CMUL, CONST, MUL, MULADD, NEG, OUT, SQR, SUB

        tape, K = self._tape, len(x[0])
        zero = np.array([acb(0)] * K, dtype=object)
        R = [zero] * tape.n_registers
        R[:self.N] = x
        for k, z in enumerate(self._q):  # s and dq stay 0
            R[self.N + 1 + k] = np.array([_exact(z)] * K, dtype=object)
        out = [zero] * tape.n_outputs
        imm = [arb(float(v)) for v in tape.imm]
        for k, (op, d, a, b, c) in enumerate(tape.code.tolist()):
            if op == MULADD:
                R[d] = R[c] + (R[a] * R[b]) * imm[k]
            elif op == AXPY:
                R[d] = R[a] + R[b] * imm[k]
            elif op == MUL:
                R[d] = R[a] * R[b]
            elif op == ADD:
                R[d] = R[a] + R[b]
            elif op == SUB:
                R[d] = R[a] - R[b]
            elif op == CMUL:
                R[d] = R[a] * imm[k]
            elif op == SQR:
                R[d] = R[a] * R[a]
            elif op == CADD:
                R[d] = R[a] + imm[k]
            elif op == NEG:
                R[d] = -R[a]
            elif op == CONST:
                R[d] = np.array([acb(imm[k])] * K, dtype=object)
            elif op == OUT:
                out[d] = R[a]
            else:
                raise ValueError(f"unknown opcode {op} at instruction {k}")
        return out

    def refine(self, x: np.ndarray, bits: int = HIGH_PRECISION, steps: int = 6) -> tuple[np.ndarray, np.ndarray]:
        """Newton's method on the points x (K, N) at ``bits`` bits, all at once: (the points rounded to double, the
        mask of those that converged there to a relative step below 2^-(bits/2) within 1e-3 (relative) of x), as
        :func:`refine`. From a point whose double-precision step stalls at 1e-6 (condition 1e12) six steps reach
        160 bits."""
        x = np.atleast_2d(np.asarray(x, dtype=complex))
        K, N = x.shape
        size = 1.0 + np.max(np.abs(x), axis=1)
        last = np.full(K, np.inf)
        with _Precision(bits):
            y = [np.array([_exact(v) for v in x[:, k]], dtype=object) for k in range(N)]
            live = np.ones(K, dtype=bool)
            for _ in range(steps):
                out = self.run(y)
                for i in range(K):
                    if not live[i]:
                        continue
                    F = acb_mat([[out[e][i]] for e in range(N)]).mid()
                    J = acb_mat([[out[N + e * N + k][i] for k in range(N)] for e in range(N)]).mid()
                    try:
                        dx = J.solve(F)
                    except (ZeroDivisionError, ValueError):
                        live[i] = False
                        continue
                    for k in range(N):
                        y[k][i] = (y[k][i] - dx[k, 0]).mid()
                    last[i] = max(float(abs(dx[k, 0]).mid()) for k in range(N))
        z = np.array([[complex(float(v.real.mid()), float(v.imag.mid())) for v in col] for col in y]).T
        ok = (np.all(np.isfinite(z), axis=1) & (last <= 2.0 ** (-bits // 2) * size)
              & (np.max(np.abs(z - x), axis=1) <= 1e-3 * size))
        return np.where(ok[:, None], z, x), ok


@dataclass(frozen=True)
class Certificate:
    """Per solution: proven (Krawczyk's inclusion and the non-vanishing conditions), the box's centre (complex,
    rounded to double) and half-width r (an upper bound, including that rounding), and the bits it took (0:
    not proven); with the number proven and the seconds."""

    proven: np.ndarray
    centres: np.ndarray
    radii: np.ndarray
    bits: np.ndarray
    seconds: float

    @property
    def count(self) -> int:
        return int(self.proven.sum())


def _krawczyk(ball: BallSystem, xm: list, r: float, Y: acb_mat) -> bool:
    """Whether K(X) lies in the interior of X = xm + [-r, r]^N (real and imaginary parts), with the conditions'
    enclosures over X excluding 0 (Y: an exact matrix, the preconditioner)."""
    N = ball.N
    F = acb_mat([[v] for v in ball.values(xm)])
    d = acb(arb(0, r), arb(0, r))
    X = [v + d for v in xm]
    JX = ball.jacobian(X)
    M = acb_mat([[acb(1) if i == j else acb(0) for j in range(N)] for i in range(N)]) - Y * JX
    K = acb_mat([[v] for v in xm]) - Y * F + M * acb_mat([[d] for _ in range(N)])
    if not all(X[k].contains_interior(K[k, 0]) for k in range(N)):
        return False
    return all(not c.contains(0) for c in ball.conditions(X))


def _newton(ball: BallSystem, x: list, steps: int) -> list:
    """Newton steps on ball midpoints at the current precision (the midpoints stay exact)."""
    for _ in range(steps):
        F = acb_mat([[v] for v in ball.values(x)])
        try:
            dx = ball.jacobian(x).mid().solve(F.mid())
        except (ZeroDivisionError, ValueError):
            return x
        x = [(x[k] - dx[k, 0]).mid() for k in range(ball.N)]
    return x


def refine(ball: BallSystem, x: np.ndarray, bits: int = HIGH_PRECISION, steps: int = 30) -> tuple[np.ndarray, bool]:
    """Newton's method on x (N,) at ``bits`` bits: (the point rounded to double, whether it converged there to a
    relative step below 2^-(bits/2) within 1e-3 (relative) of x). For an endpoint whose double-precision Newton
    step stalls above a tolerance (ill-conditioned, large norm: 3D TDOA 6r/6s, norm ~3000, step 1e-5)."""
    size = 1.0 + float(np.max(np.abs(x)))
    with _Precision(bits):
        xm = _newton(ball, [_exact(v) for v in x], steps)
        try:
            F = acb_mat([[v] for v in ball.values(xm)]).mid()
            step = ball.jacobian(xm).mid().solve(F)
        except (ZeroDivisionError, ValueError):
            return np.asarray(x, dtype=complex), False
        last = max(float(abs(step[k, 0]).mid()) for k in range(ball.N))
    y = np.array([complex(float(v.real.mid()), float(v.imag.mid())) for v in xm])
    ok = bool(np.all(np.isfinite(y)) and last <= 2.0 ** (-bits // 2) * size and np.max(np.abs(y - x)) <= 1e-3 * size)
    return y, ok


def _exact_matrix(Y: np.ndarray) -> acb_mat:
    return acb_mat([[acb(float(v.real), float(v.imag)) for v in row] for row in Y])


def _prove(ball: BallSystem, x: np.ndarray, Y: np.ndarray | None) -> tuple[bool, np.ndarray, float, int]:
    """(proven, centre, r, bits) of one approximate solution x (N,); Y: F'(x)^-1 in floating point (None where
    it could not be formed)."""
    size = 1.0 + float(np.max(np.abs(x)))
    if Y is not None and np.all(np.isfinite(Y)):
        xm = [_exact(v) for v in x]
        Ym = _exact_matrix(Y)
        newton = float(np.max(np.abs(Y @ np.array([complex(float(v.real.mid()), float(v.imag.mid()))
                                                    for v in ball.values(xm)]))))
        for r in (max(4.0 * newton, RADII[0] * size), RADII[1] * size):
            if _krawczyk(ball, xm, r, Ym):
                return True, np.asarray(x, dtype=complex), r * (1.0 + 1e-12), 53
    with _Precision(HIGH_PRECISION):  # Newton's method and the test at HIGH_PRECISION bits
        xm = _newton(ball, [_exact(v) for v in x], 12)
        try:
            Ym = ball.jacobian(xm).mid().inv().mid()
            F = acb_mat([[v] for v in ball.values(xm)]).mid()
        except (ZeroDivisionError, ValueError):
            return False, np.asarray(x, dtype=complex), float("inf"), 0
        step = Ym * F
        newton = max(float(abs(step[k, 0]).mid()) for k in range(ball.N))
        centre = np.array([complex(float(v.real.mid()), float(v.imag.mid())) for v in xm])
        if not np.max(np.abs(centre - x)) <= MOVED * size:  # a solution near x, not x's: x is no solution
            return False, np.asarray(x, dtype=complex), float("inf"), 0
        for r in (max(4.0 * newton, 1e-30 * size), 1e-20 * size, 1e-12 * size):
            if _krawczyk(ball, xm, r, Ym):
                rounding = float(np.max(np.abs(centre))) * 2.0 ** -52  # the centre rounded to double
                return True, centre, r * (1.0 + 1e-12) + rounding, HIGH_PRECISION
    return False, np.asarray(x, dtype=complex), float("inf"), 0


def certify(system, q: np.ndarray, roots: np.ndarray, progress: Callable[[str], None] | None = None,
            processes: int = 1) -> Certificate:
    """Krawczyk's test on every approximate solution (K, N) of ``system`` at parameters q; ``processes``: the
    solutions shared among that many forked processes (the tests are independent; arb holds the GIL)."""
    t0 = time.perf_counter()
    ball = BallSystem(system, q)
    roots = np.atleast_2d(np.asarray(roots, dtype=complex))
    K = len(roots)
    finite = np.all(np.isfinite(roots), axis=1)
    chunks = [np.arange(K)[i:i + CHUNK] for i in range(0, K, CHUNK)]
    _WORK.update(ball=ball, roots=roots, finite=finite)
    proven = np.zeros(K, dtype=bool)
    centres = roots.copy()
    radii = np.full(K, np.inf)
    bits = np.zeros(K, dtype=np.int64)
    last = t0
    pool = None
    if processes > 1 and len(chunks) > 1 and "fork" in multiprocessing.get_all_start_methods():
        pool = ProcessPoolExecutor(processes, mp_context=multiprocessing.get_context("fork"))
    try:
        results = pool.map(_prove_chunk, chunks) if pool else map(_prove_chunk, chunks)
        done = 0
        for idx, (p_, c_, r_, b_) in zip(chunks, results):
            proven[idx], centres[idx], radii[idx], bits[idx] = p_, c_, r_, b_
            done += len(idx)
            if progress and time.perf_counter() - last > 10.0:
                last = time.perf_counter()
                progress(f"certify: {done} of {K} solutions tested, {int(proven.sum())} proven, {last - t0:.0f} s")
    finally:
        if pool is not None:
            pool.shutdown()
        _WORK.clear()
    return Certificate(proven, centres, radii, bits, time.perf_counter() - t0)


#: Solutions per task of :func:`certify` (forked processes share the work by chunks).
CHUNK = 64

#: What :func:`certify`'s chunks read (set before the processes fork, so that they inherit it).
_WORK: dict = {}


def _prove_chunk(idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Krawczyk's test on the solutions idx, each with Y ~ F'(x)^-1 formed here for the chunk alone: the (K, N, N)
    Jacobians and inverses of the whole set at once took 1.2 GB each for 5r/9s (36,947 solutions, 45 unknowns) and
    their copies in cond and inv the rest of count's 5.3 GB peak."""
    ball, roots, finite = (_WORK[k] for k in ("ball", "roots", "finite"))
    x = roots[idx]
    ok = finite[idx]
    Y = np.full((len(idx), ball.N, ball.N), np.nan, dtype=complex)
    with np.errstate(all="ignore"):
        J = ball.jacobians(np.where(ok[:, None], x, 0.0))
        good = ok & (np.linalg.cond(J) < 1e14)
        Y[good] = np.linalg.inv(J[good])
    out = [np.zeros(len(idx), dtype=bool), x.copy(), np.full(len(idx), np.inf), np.zeros(len(idx), dtype=np.int64)]
    for j in range(len(idx)):
        if ok[j]:
            out[0][j], out[1][j], out[2][j], out[3][j] = _prove(ball, x[j], Y[j] if good[j] else None)
    return tuple(out)


def disjoint(centres: np.ndarray, radii: np.ndarray, group: np.ndarray | None = None) -> np.ndarray:
    """Mask of the boxes (centre (K, N), half-width (K,): real and imaginary parts of every coordinate within
    it of the centre's) that meet another box, or (``group``: sign vectors (G, N), the identity among them)
    an image of another box or a non-trivial image of themselves; all False proves the boxes' solutions
    distinct (distinct orbits). Candidates by a sweep along a random projection, then every coordinate."""
    centres = np.asarray(centres, dtype=complex)
    K, N = centres.shape
    signs = np.ones((1, N)) if group is None else np.asarray(group, dtype=float)
    boxes = np.vstack([centres * g for g in signs])  # image g of box k at row gi * K + k (sign flips are exact)
    owner = np.tile(np.arange(K), len(signs))
    identity = np.repeat([bool(np.all(g == 1.0)) for g in signs], K)
    rad = np.tile(np.asarray(radii, dtype=float), len(signs))
    u = np.random.default_rng(0).normal(size=N)
    proj = boxes.real @ u
    reach = rad * np.abs(u).sum() * (1.0 + MARGIN) + MARGIN * np.abs(boxes.real) @ np.abs(u)
    lo, hi = proj - reach, proj + reach
    order = np.argsort(lo, kind="stable")
    meets = np.zeros(K, dtype=bool)
    active: list[int] = []
    for a in order:
        active = [b for b in active if hi[b] >= lo[a]]
        for b in active:
            if owner[a] == owner[b] and (identity[a] == identity[b]):
                continue
            if not (identity[a] or identity[b]) and owner[a] != owner[b]:
                continue  # two images: the same pair is met as identity against an image
            gap = np.maximum(np.abs(boxes[a].real - boxes[b].real), np.abs(boxes[a].imag - boxes[b].imag))
            if np.all(gap <= (rad[a] + rad[b]) * (1.0 + MARGIN) + MARGIN * (np.abs(boxes[a]) + np.abs(boxes[b]))):
                meets[owner[a]] = meets[owner[b]] = True
        active.append(a)
    return meets
