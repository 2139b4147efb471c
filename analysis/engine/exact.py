"""The reduced Gröbner basis over Q by exact arithmetic: FLINT's Buchberger algorithm over Z.

For a small system with large coefficients, exact arithmetic is what Singular's ``std`` over Q does and
it beats primes by far: a basis whose fractions have D digits needs about 2D / 9.3 primes of 31 bits
(one F4 run each), while FLINT's ``fmpz_mpoly_vec.buchberger_naive`` on two or three polynomials with
10,000-digit coefficients takes milliseconds. On a harder system it may take forever (katsura-7: over
100 s, where primes take seconds), and it cannot be interrupted in-process. :class:`ExactRace` therefore
runs it in a forked child process while the caller goes on with primes; the caller polls between primes,
takes the child's basis when it comes first, and kills the child otherwise.

Buchberger's algorithm returns a Gröbner basis of the input's ideal (it only adds elements of it, and
stops when every S-pair reduces to zero); its autoreduction, made monic, is the reduced basis. The caller
checks it against the basis modulo a prime not used for it (:func:`analysis.engine.modular.rational_basis`).
FLINT's own Gröbner test (``is_groebner``, every S-pair of the result reduced again) is left to the tests:
on a fuzz case with 24,000-digit fractions it took 10 s where the basis took 0.5 s.

Reference: B. Buchberger, "Ein Algorithmus zum Auffinden der Basiselemente des Restklassenringes nach
einem nulldimensionalen Polynomideal", thesis, Innsbruck 1965; FLINT's ``fmpz_mpoly_vec`` (Buchberger,
autoreduction, Gröbner test).
"""
from __future__ import annotations

import os
import select
import signal
from dataclasses import dataclass
from fractions import Fraction
from math import lcm
from typing import Sequence

from .io import Coefficients

ECHELON = "row echelon form over Z (FLINT; a linear system)"
"""The method of :func:`_linear_basis`, as a status line names it."""

FLINT_ORDERS = {"grevlex": "degrevlex", "lex": "lex", "deglex": "deglex"}
"""The orders FLINT's multivariate polynomials know (first variable largest, as here); a block order is
left to the primes."""


@dataclass(frozen=True)
class ExactBasis:
    """An exact reduced Gröbner basis over Q: monic polynomials (exponents -> Fraction), leading term first,
    as FLINT's autoreduction orders them; ``groebner``: the result of FLINT's ``is_groebner`` (every S-pair
    reduces to 0) when it was asked for, else None; ``method``: how it was computed, for a status line."""

    basis: tuple[Coefficients, ...]
    groebner: bool | None = None
    method: str = "Buchberger over Z (FLINT)"


def supported(order: str) -> bool:
    """Whether :func:`exact_basis` can compute in ``order`` (grevlex, lex, deglex)."""
    return order.strip().lower() in FLINT_ORDERS


def _integer_terms(f: Coefficients) -> dict[tuple[int, ...], int]:
    """f times the lcm of its denominators: the same polynomial up to a unit, with integer coefficients."""
    den = lcm(*(c.denominator for c in f.values())) if f else 1
    return {e: int(c * den) for e, c in f.items()}


def exact_basis(generators: Sequence[Coefficients], order: str, nvars: int, certify: bool = False) -> ExactBasis:
    """The reduced Gröbner basis over Q of the ideal of ``generators`` (exact, no time limit: see
    :class:`ExactRace` for a bounded run); ``certify``: also run FLINT's Gröbner test on it (can take
    much longer than the basis). Raises ValueError for an order FLINT does not have."""
    import flint

    name = order.strip().lower()
    if name not in FLINT_ORDERS:
        raise ValueError(f"no exact basis in the order {order!r}; exact orders: {', '.join(FLINT_ORDERS)}")
    if all(sum(e) <= 1 for f in generators for e in f):
        return _linear_basis(generators, nvars)
    ctx = flint.fmpz_mpoly_ctx.get(tuple(f"x{i}" for i in range(nvars)), FLINT_ORDERS[name])
    polys = [ctx.from_dict(_integer_terms(f)) for f in generators if f]
    if not polys:
        return ExactBasis((), True)
    reduced = flint.fmpz_mpoly_vec(polys, ctx).buchberger_naive().autoreduction()
    basis = []
    for g in reduced:
        lead = g.leading_coefficient()
        basis.append({tuple(int(a) for a in e): _fraction(flint.fmpq(c, lead)) for e, c in zip(g.monoms(), g.coeffs())})
    return ExactBasis(tuple(basis), bool(reduced.is_groebner()) if certify else None)


def _linear_basis(generators: Sequence[Coefficients], nvars: int) -> ExactBasis:
    """The reduced basis of linear polynomials: the rows of the reduced row echelon form of their integer
    coefficient matrix (FLINT's fraction-free ``fmpz_mat.rref``), columns x_1 > ... > x_n > 1 (the order
    of the degree-one monomials in grevlex, lex and deglex alike). A pivot in the constant column: the unit
    ideal. Exact, hence certified (``groebner`` True: a linear basis in echelon form has no S-pair left)."""
    import flint

    monomials = [tuple(int(i == j) for j in range(nvars)) for i in range(nvars)] + [(0,) * nvars]
    rows = [[terms.get(m, 0) for m in monomials] for f in generators if f for terms in (_integer_terms(f),)]
    if not rows:
        return ExactBasis((), True, ECHELON)
    echelon, den, rank = flint.fmpz_mat(rows).rref()
    basis = []
    for i in range(rank):
        row = [echelon[i, k] for k in range(nvars + 1)]
        pivot = next(k for k, c in enumerate(row) if c != 0)
        if pivot == nvars:
            return ExactBasis(({(0,) * nvars: Fraction(1)},), True, ECHELON)
        basis.append({monomials[k]: _fraction(flint.fmpq(c, den)) for k, c in enumerate(row) if k >= pivot and c != 0})
    return ExactBasis(tuple(basis), True, ECHELON)


def coprime_fraction(n: int, d: int) -> Fraction:
    """n/d for coprime n and d > 0, without the gcd that ``Fraction(n, d)`` computes (quadratic in CPython:
    0.6 s for the six 100,000-digit fractions of a basis, where FLINT's reduction took 0.1 s)."""
    make = getattr(Fraction, "_from_coprime_ints", None)  # Python >= 3.12
    if make is not None:
        return make(n, d)
    try:
        return Fraction(n, d, _normalize=False)  # Python <= 3.11
    except TypeError:
        return Fraction(n, d)


def _fraction(q) -> Fraction:
    """A FLINT rational (in lowest terms, positive denominator) as a Fraction."""
    return coprime_fraction(int(q.p), int(q.q))


# -- the child process and its text ------------------------------------------------------------------

def _encode(result: ExactBasis) -> bytes:
    """One line per polynomial, terms ``e1,e2,..:num/den`` in hexadecimal (no decimal digit limit)."""
    lines = [f"groebner {result.groebner} {result.method}"]
    for f in result.basis:
        lines.append(" ".join(f"{','.join(map(str, e))}:{c.numerator:x}/{c.denominator:x}" for e, c in f.items()))
    return ("\n".join(lines) + "\n").encode()


def _decode(data: bytes) -> ExactBasis:
    head, *rows = data.decode().splitlines()
    basis = []
    for row in rows:
        f = {}
        for term in row.split():
            e, _, c = term.partition(":")
            num, _, den = c.partition("/")
            f[tuple(int(a) for a in e.split(",") if a)] = coprime_fraction(int(num, 16), int(den, 16))
        basis.append(f)
    _, groebner, method = head.split(" ", 2)
    return ExactBasis(tuple(basis), {"True": True, "False": False}.get(groebner), method)


CHILD_MEMORY_SHARE = 0.25
"""The child may grow its data by this share of the machine's physical memory (an exact Buchberger that
blows up then fails in the child, and the primes go on)."""


def _limit_memory(share: float) -> None:
    """Cap this process's data segment (heap and mmap) at its current size plus ``share`` of physical memory."""
    try:
        import resource

        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
        with open("/proc/self/statm") as f:
            used = int(f.read().split()[5]) * os.sysconf("SC_PAGE_SIZE")  # data + stack pages
        cap = used + int(share * total)
        soft, hard = resource.getrlimit(resource.RLIMIT_DATA)
        if hard != resource.RLIM_INFINITY:
            cap = min(cap, hard)
        resource.setrlimit(resource.RLIMIT_DATA, (cap, hard))
    except (ImportError, OSError, ValueError):
        pass  # no such limit here: the child runs uncapped (it is killed when the primes finish)


class ExactRace:
    """:func:`exact_basis` in a forked child process, polled by the caller between its own steps.

    ``poll()`` returns the child's :class:`ExactBasis` once it is done, ``None`` while it runs (and for
    good after a failure); ``close()`` kills a child still running. Use as a context manager. Without
    ``os.fork`` (Windows) nothing is started and ``poll()`` stays ``None``.
    """

    def __init__(self, generators: Sequence[Coefficients], order: str, nvars: int) -> None:
        self.pid: int | None = None
        self.fd: int | None = None
        self.failed = not hasattr(os, "fork") or not supported(order)
        if self.failed:
            return
        import flint  # noqa: F401  (imported here, once, rather than in every child)

        read, write = os.pipe()
        try:
            pid = os.fork()
        except OSError:  # no process to spare (a limit on processes or memory): the primes go on alone
            os.close(read)
            os.close(write)
            self.failed = True
            return
        if pid == 0:  # the child: compute, write, leave without running the parent's cleanup
            code = 1
            try:
                os.close(read)
                os.dup2(os.open(os.devnull, os.O_WRONLY), 2)  # GMP's "cannot allocate" is the child's affair
                _limit_memory(CHILD_MEMORY_SHARE)
                data = _encode(exact_basis(generators, order, nvars))
                view = memoryview(data)
                while view:
                    view = view[os.write(write, view):]
                code = 0
            finally:
                os._exit(code)
        os.close(write)
        self.pid, self.fd = pid, read

    def poll(self, wait: float = 0.0) -> ExactBasis | None:
        """The child's basis when it has finished, else None (after waiting at most ``wait`` seconds for it)."""
        if self.fd is None or not select.select([self.fd], [], [], max(0.0, wait))[0]:
            return None
        chunks = []
        while chunk := os.read(self.fd, 1 << 20):  # the child writes only once it is done: no long wait
            chunks.append(chunk)
        _, status = os.waitpid(self.pid, 0)
        os.close(self.fd)
        self.pid = self.fd = None
        if status != 0 or not chunks:
            self.failed = True
            return None
        return _decode(b"".join(chunks))

    def close(self) -> None:
        if self.pid is not None:
            try:
                os.kill(self.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            os.waitpid(self.pid, 0)
        if self.fd is not None:
            os.close(self.fd)
        self.pid = self.fd = None

    def __enter__(self) -> "ExactRace":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
