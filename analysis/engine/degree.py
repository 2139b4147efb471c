"""Degree (number of solutions) of a polynomial system, checked across primes.

A degree counts only when two primes agree (STYLE.md, habit 6): :func:`analyse` computes a Gröbner basis
modulo every requested prime and raises :class:`PrimeDisagreement` when the primes disagree on the
dimension or the degree.

Each prime's basis comes from an engine: ``"own"`` (:func:`analysis.engine.f4.groebner`) or ``"msolve"`` (the
msolve executable run as an external program, :mod:`analysis.engine.msolve`). :func:`analyse_by_msolve` is
msolve checked by the own engine: msolve on the first prime, the own engine on the second when that
is affordable (a smaller matrix cap), msolve on it otherwise; with a single prime the own engine
recomputes that prime and must give the same reduced basis.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Callable, Literal, Sequence

from .f4 import F4Options, GroebnerResult, groebner, tighter_cells
from .linalg import MatrixTooLarge
from .quotient import (count_standard_monomials, dimension, fglm, is_zero_dimensional, saturate, saturated_degree,
                       standard_monomials)
from .ring import Poly

DEFAULT_PRIMES = (65521, 32749)
"""Two primes below 2^16: their F4 matrices reduce exactly in float64 BLAS without limb splitting."""

Engine = Literal["own", "msolve"]
ENGINES: tuple[str, ...] = ("own", "msolve")
"""Gröbner engines: the workbench's F4, or msolve as an external program."""

CHECK_CELLS = 20_000_000
"""Matrix cap (rows x cols) of the own engine's check of an msolve result: above it the check is not
affordable (the F4 matrix alone would need 160 MB and seconds) and msolve computes the second prime too."""


class PrimeDisagreement(RuntimeError):
    """Different primes gave different degrees or dimensions (an unlucky prime or a non-generic input)."""


class EngineDisagreement(PrimeDisagreement):
    """The own engine and msolve gave different reduced bases over the same prime (a bug in one of them)."""


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
    engine: str = "own"


@dataclass(frozen=True)
class DegreeReport:
    """Degree and dimension of a system agreed by all primes.

    degree: number of standard monomials |B| (None when not zero-dimensional; 0 when inconsistent).
    dimension: Krull dimension (-1 for an inconsistent system, 0 for finitely many solutions).
    seconds: engine time (Gröbner bases plus counting, all primes; for msolve the wall time of its process).
    engines: the engine that computed each prime's basis.
    check: what cross-checked an msolve result ("" when only the own engine ran).
    """

    degree: int | None
    dimension: int
    zero_dimensional: bool
    primes: tuple[int, ...]
    gb_size: int
    max_matrix: tuple[int, int]
    seconds: float
    per_prime: tuple[PrimeResult, ...] = field(repr=False, compare=False)
    engines: tuple[str, ...] = ()
    check: str = ""

    def standard_basis(self) -> list[str]:
        """The standard monomials (as strings) of the first prime, or [] if not zero-dimensional."""
        r = self.per_prime[0]
        if r.degree is None:
            return []
        return [r.gb.ring.monomial_str(k) for k in standard_monomials(r.gb)]

    def as_dict(self) -> dict:
        """The report as JSON-ready values; ``engines`` and ``check`` only when msolve took part."""
        out = {
            "degree": self.degree,
            "dimension": self.dimension,
            "zero_dimensional": self.zero_dimensional,
            "primes": list(self.primes),
            "gb_size": self.gb_size,
            "max_matrix": list(self.max_matrix),
            "seconds": round(self.seconds, 6),
        }
        if any(e != "own" for e in self.engines):
            out["engines"] = list(self.engines)
            out["check"] = self.check
        return out


def groebner_in_order(polys: Sequence[Poly], options: F4Options, engine: Engine = "own", msolve: str | None = None
              ) -> GroebnerResult:
    """Reduced Gröbner basis in the ring's order; for orders other than grevlex, through grevlex and FGLM
    when the ideal is zero-dimensional (F4 in lex can swell far beyond the ideal's degree: katsura-4,
    16 solutions, outgrew 24 GB), a positive-dimensional lex or block basis through homogenization
    (:mod:`analysis.engine.homogenize`: F4 in lex stopped at a 400M-cell cap on two cubics in 3 unknowns), deglex
    directly (own engine only). msolve computes the grevlex basis."""
    ring = polys[0].ring
    if engine == "msolve":
        from .msolve import groebner_msolve

        if msolve is None:
            raise ValueError("engine 'msolve' needs the path of an msolve executable")
        gb = groebner_msolve(polys, msolve)
        if ring.order.name == "grevlex":
            return gb
        if not is_zero_dimensional(gb):
            raise ValueError(f"msolve computes grevlex bases; a {ring.order} basis of a positive-dimensional "
                             "ideal needs the own engine")
        return fglm(gb, ring)
    if engine != "own":
        raise ValueError(f"unknown engine {engine!r}; valid: {', '.join(ENGINES)}")
    if ring.order.name == "grevlex":
        return groebner(polys, options)
    graded = ring.with_order("grevlex")
    gb = groebner([graded.from_terms(f.terms()) for f in polys], options)
    if is_zero_dimensional(gb):
        return fglm(gb, ring)
    if ring.order.name in ("lex", "block"):
        from .homogenize import by_homogenization

        return by_homogenization(polys, options)
    return groebner(polys, options)


def analyse_prime(polys: Sequence[Poly], options: F4Options = F4Options(), saturate_by: Poly | None = None,
                  saturation: str = "rank", engine: Engine = "own", msolve: str | None = None) -> PrimeResult:
    """Gröbner basis, dimension and degree over one prime (optionally after saturating by a polynomial).

    saturation: "rank" gives the saturated degree of a zero-dimensional ideal as the rank of a power of
    the action matrix of the saturating polynomial (:func:`analysis.engine.quotient.saturated_degree`; the
    basis kept is then that of the unsaturated ideal); positive-dimensional ideals, and "rabinowitsch",
    compute the saturated ideal's own basis (:func:`analysis.engine.quotient.saturate`, own engine: it needs an
    elimination order; ``engine`` then names the engine that computed the basis kept).
    """
    if saturation not in ("rank", "rabinowitsch"):
        raise ValueError(f"unknown saturation method {saturation!r}; valid: rank, rabinowitsch")
    if saturate_by is not None or polys[0].ring.order.name != "grevlex":
        # normal forms (saturation, FGLM) read the tails: those need the reduced basis
        options = dataclasses.replace(options, reduced=True)
    t0 = time.perf_counter()
    gb = None
    if saturate_by is None or saturation == "rank":
        gb = groebner_in_order(polys, options, engine, msolve)
    if saturate_by is not None and gb is not None and is_zero_dimensional(gb):
        deg = saturated_degree(gb, saturate_by.ring.with_order(gb.ring.order).from_terms(saturate_by.terms()))
        dim = 0 if deg else -1
    else:
        if saturate_by is not None:
            gb, engine = saturate(polys, saturate_by, options), "own"
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
        engine=engine,
    )


def analyse(
    system: Callable[[int], Sequence[Poly]],
    primes: Sequence[int] = DEFAULT_PRIMES,
    options: F4Options = F4Options(),
    saturate_by: Callable[[int], Poly] | None = None,
    saturation: str = "rank",
    engines: Sequence[Engine] | None = None,
    msolve: str | None = None,
) -> DegreeReport:
    """Degree and dimension of a system, computed modulo each prime and required to agree.

    Parameters
    ----------
    system: prime -> the polynomials of the system over GF(prime).
    primes: at least one prime; two or more for a checked degree.
    saturate_by: optional prime -> polynomial f; the ideal is replaced by its saturation I : f^inf.
    saturation: how (see :func:`analyse_prime`).
    engines: the engine of each prime (default: the own engine for all); ``msolve`` is the executable
        an ``"msolve"`` engine runs.
    """
    if not primes:
        raise ValueError("at least one prime is needed")
    engines = tuple(engines) if engines is not None else ("own",) * len(primes)
    if len(engines) != len(primes):
        raise ValueError(f"{len(engines)} engines for {len(primes)} primes")
    results = [_analyse_one(system, p, options, saturate_by, saturation, e, msolve) for p, e in zip(primes, engines)]
    return _agreed(results)


def _analyse_one(system, p: int, options: F4Options, saturate_by, saturation: str, engine: Engine,
                 msolve: str | None) -> PrimeResult:
    polys = list(system(p))
    if not polys:
        raise ValueError("empty system: no polynomials given")
    return analyse_prime(polys, options, saturate_by(p) if saturate_by else None, saturation, engine, msolve)


def _agreed(results: Sequence[PrimeResult], check: str = "") -> DegreeReport:
    """The report of per-prime results; :class:`PrimeDisagreement` unless they agree."""
    first = results[0]
    for r in results[1:]:
        if (r.degree, r.dimension) != (first.degree, first.dimension):
            summary = ", ".join(f"p={x.prime} ({x.engine}): degree {x.degree}, dimension {x.dimension}"
                                for x in results)
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
        engines=tuple(r.engine for r in results),
        check=check,
    )


def analyse_by_msolve(
    system: Callable[[int], Sequence[Poly]],
    msolve: str,
    primes: Sequence[int] = DEFAULT_PRIMES,
    options: F4Options = F4Options(),
    saturate_by: Callable[[int], Poly] | None = None,
    saturation: str = "rank",
    check: bool = True,
    check_cells: int = CHECK_CELLS,
) -> DegreeReport:
    """:func:`analyse` by msolve, checked by the own engine where that is affordable.

    msolve computes every prime but the last; the last is the own engine's (its matrices capped at
    ``min(check_cells, options.max_matrix_cells)``), and the primes must agree as always. When the own
    engine would need a larger matrix, or ``check`` is False, msolve computes the last prime too and the
    report's ``check`` says so. With a single prime the own engine recomputes it and must find the same
    reduced basis (:class:`EngineDisagreement` otherwise).
    """
    if not primes:
        raise ValueError("at least one prime is needed")
    primes = tuple(primes)
    head = primes[:-1] if len(primes) > 1 else primes
    results = [_analyse_one(system, p, options, saturate_by, saturation, "msolve", msolve) for p in head]
    if not check:
        results += [_analyse_one(system, p, options, saturate_by, saturation, "msolve", msolve) for p in primes[len(head):]]
        return _agreed(results, "none (not requested)")
    capped = dataclasses.replace(options, max_matrix_cells=tighter_cells(check_cells, options.max_matrix_cells),
                                 reduced=options.reduced and len(primes) > 1)  # one prime: bases compared
    p = primes[-1]
    try:
        own = _analyse_one(system, p, capped, saturate_by, saturation, "own", None)
    except MatrixTooLarge as e:
        note = f"own engine not run: {e} (the check's cap)"
        if len(primes) > 1:
            results.append(_analyse_one(system, p, options, saturate_by, saturation, "msolve", msolve))
        return _agreed(results, note)
    if len(primes) > 1:
        return _agreed(results + [own], f"own engine on {p} agrees (degree and dimension)")
    mine = results[0]
    if (own.degree, own.dimension) != (mine.degree, mine.dimension) or set(own.gb.basis) != set(mine.gb.basis):
        raise EngineDisagreement(f"msolve and the own engine disagree over GF({p}): msolve degree {mine.degree}, "
                                 f"dimension {mine.dimension}, {mine.gb_size} basis elements; own engine degree "
                                 f"{own.degree}, dimension {own.dimension}, {own.gb_size} elements")
    return _agreed(results, f"own engine on {p}: the same reduced basis")
