"""Degree (number of solutions) of a polynomial system, checked across primes.

A degree counts only when two primes agree (STYLE.md, habit 6): :func:`analyse` computes a Gröbner basis
modulo every requested prime and raises :class:`PrimeDisagreement` when the primes disagree on the
dimension or the degree.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

from .f4 import F4Options, GroebnerResult, groebner
from .quotient import dimension, is_zero_dimensional, saturate, standard_monomials
from .ring import Poly

DEFAULT_PRIMES = (65521, 32749)
"""Two primes below 2^16: their F4 matrices reduce exactly in float64 BLAS without limb splitting."""


class PrimeDisagreement(RuntimeError):
    """Different primes gave different degrees or dimensions (an unlucky prime or a non-generic input)."""


@dataclass(frozen=True)
class PrimeResult:
    """What one prime gave."""

    prime: int
    degree: int | None
    dimension: int
    gb_size: int
    max_matrix: tuple[int, int]
    seconds: float
    gb: GroebnerResult = field(repr=False, compare=False)


@dataclass(frozen=True)
class DegreeReport:
    """Degree and dimension of a system agreed by all primes.

    degree: number of standard monomials |B| (None when not zero-dimensional; 0 when inconsistent).
    dimension: Krull dimension (-1 for an inconsistent system, 0 for finitely many solutions).
    seconds: engine time (Gröbner bases plus counting, all primes).
    """

    degree: int | None
    dimension: int
    zero_dimensional: bool
    primes: tuple[int, ...]
    gb_size: int
    max_matrix: tuple[int, int]
    seconds: float
    per_prime: tuple[PrimeResult, ...] = field(repr=False, compare=False)

    def standard_basis(self) -> list[str]:
        """The standard monomials (as strings) of the first prime, or [] if not zero-dimensional."""
        r = self.per_prime[0]
        if r.degree is None:
            return []
        return [r.gb.ring.monomial_str(k) for k in standard_monomials(r.gb)]

    def as_dict(self) -> dict:
        return {
            "degree": self.degree,
            "dimension": self.dimension,
            "zero_dimensional": self.zero_dimensional,
            "primes": list(self.primes),
            "gb_size": self.gb_size,
            "max_matrix": list(self.max_matrix),
            "seconds": round(self.seconds, 6),
        }


def analyse_prime(polys: Sequence[Poly], options: F4Options = F4Options(), saturate_by: Poly | None = None) -> PrimeResult:
    """Gröbner basis, dimension and degree over one prime (optionally after saturating by a polynomial)."""
    t0 = time.perf_counter()
    gb = saturate(polys, saturate_by, options) if saturate_by is not None else groebner(polys, options)
    dim = dimension(gb)
    deg = len(standard_monomials(gb)) if is_zero_dimensional(gb) else None
    return PrimeResult(
        prime=polys[0].ring.prime,
        degree=deg,
        dimension=dim,
        gb_size=len(gb.basis),
        max_matrix=gb.max_matrix,
        seconds=time.perf_counter() - t0,
        gb=gb,
    )


def analyse(
    system: Callable[[int], Sequence[Poly]],
    primes: Sequence[int] = DEFAULT_PRIMES,
    options: F4Options = F4Options(),
    saturate_by: Callable[[int], Poly] | None = None,
) -> DegreeReport:
    """Degree and dimension of a system, computed modulo each prime and required to agree.

    Parameters
    ----------
    system: prime -> the polynomials of the system over GF(prime).
    primes: at least one prime; two or more for a checked degree.
    saturate_by: optional prime -> polynomial f; the ideal is replaced by its saturation I : f^inf.
    """
    if not primes:
        raise ValueError("at least one prime is needed")
    results = []
    for p in primes:
        polys = list(system(p))
        if not polys:
            raise ValueError("empty system: no polynomials given")
        results.append(analyse_prime(polys, options, saturate_by(p) if saturate_by else None))
    first = results[0]
    for r in results[1:]:
        if (r.degree, r.dimension) != (first.degree, first.dimension):
            summary = ", ".join(f"p={x.prime}: degree {x.degree}, dimension {x.dimension}" for x in results)
            raise PrimeDisagreement(f"primes disagree ({summary}); try other primes or check the input")
    return DegreeReport(
        degree=first.degree,
        dimension=first.dimension,
        zero_dimensional=first.degree is not None,
        primes=tuple(r.prime for r in results),
        gb_size=first.gb_size,
        max_matrix=max((r.max_matrix for r in results), key=lambda rc: rc[0] * rc[1]),
        seconds=sum(r.seconds for r in results),
        per_prime=tuple(results),
    )
