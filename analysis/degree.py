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
from .quotient import (count_standard_monomials, dimension, fglm, is_zero_dimensional, saturate, saturated_degree,
                       standard_monomials)
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


def _groebner(polys: Sequence[Poly], options: F4Options) -> GroebnerResult:
    """Reduced Gröbner basis in the ring's order; for orders other than grevlex, through grevlex and FGLM
    when the ideal is zero-dimensional (F4 in lex can swell far beyond the ideal's degree: katsura-4,
    16 solutions, outgrew 24 GB), else directly."""
    ring = polys[0].ring
    if ring.order.name == "grevlex":
        return groebner(polys, options)
    graded = ring.with_order("grevlex")
    gb = groebner([graded.from_terms(f.terms()) for f in polys], options)
    if not is_zero_dimensional(gb):
        return groebner(polys, options)
    return fglm(gb, ring)


def analyse_prime(polys: Sequence[Poly], options: F4Options = F4Options(), saturate_by: Poly | None = None,
                  saturation: str = "rank") -> PrimeResult:
    """Gröbner basis, dimension and degree over one prime (optionally after saturating by a polynomial).

    saturation: "rank" gives the saturated degree of a zero-dimensional ideal as the rank of a power of
    the action matrix of the saturating polynomial (:func:`analysis.quotient.saturated_degree`; the
    basis kept is then that of the unsaturated ideal); positive-dimensional ideals, and "rabinowitsch",
    compute the saturated ideal's own basis (:func:`analysis.quotient.saturate`).
    """
    if saturation not in ("rank", "rabinowitsch"):
        raise ValueError(f"unknown saturation method {saturation!r}; valid: rank, rabinowitsch")
    t0 = time.perf_counter()
    gb = None
    if saturate_by is None or saturation == "rank":
        gb = _groebner(polys, options)
    if saturate_by is not None and gb is not None and is_zero_dimensional(gb):
        deg = saturated_degree(gb, saturate_by.ring.with_order(gb.ring.order).from_terms(saturate_by.terms()))
        dim = 0 if deg else -1
    else:
        if saturate_by is not None:
            gb = saturate(polys, saturate_by, options)
        dim = dimension(gb)
        deg = count_standard_monomials(gb) if is_zero_dimensional(gb) else None
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
    saturation: str = "rank",
) -> DegreeReport:
    """Degree and dimension of a system, computed modulo each prime and required to agree.

    Parameters
    ----------
    system: prime -> the polynomials of the system over GF(prime).
    primes: at least one prime; two or more for a checked degree.
    saturate_by: optional prime -> polynomial f; the ideal is replaced by its saturation I : f^inf.
    saturation: how (see :func:`analyse_prime`).
    """
    if not primes:
        raise ValueError("at least one prime is needed")
    results = []
    for p in primes:
        polys = list(system(p))
        if not polys:
            raise ValueError("empty system: no polynomials given")
        results.append(analyse_prime(polys, options, saturate_by(p) if saturate_by else None, saturation))
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
