"""Characteristic 0 through primes: lucky primes by majority, the basis over Q by Chinese remaindering.

A system over Q is computed modulo primes. A prime p is *unlucky* when the reduced Gröbner basis mod p
is not the reduction of the one over Q; this happens for finitely many primes (those dividing one
nonzero integer determined by the input: Pauer 1992, Arnold 2003), and then the degree, the dimension
or the leading monomials (the Hilbert function) may come out wrong. This module

* draws primes at random from the 50,697,537 primes 2^30 < p < 2^31 (:func:`random_primes`, seeded);
* rejects a prime before any work when it divides a denominator or a leading coefficient of the input
  (:func:`unlucky_reason`: the reduction would change the input's leading monomials or be undefined);
* compares what the primes give (dimension, degree and the set of leading monomials) and accepts it
  only when at least three primes agree and they are a strict majority of the primes computed
  (:func:`analyse_rational`), drawing more primes until then;
* for the basis over Q (:func:`rational_basis`), combines the coefficients of the majority's bases by
  the Chinese remainder theorem, recovers fractions by rational reconstruction, and accepts them when
  they reduce to the basis computed modulo a fresh prime (as msolve and Singular's ``modStd`` do).

Residual error. Let U be the number of unlucky primes of an input among the N primes drawn from. A
majority of m >= 3 of k primes is wrong only if m of the k drawn primes are unlucky and agree, which
has probability at most C(k, m) (U / N)^m; a reconstructed basis that is wrong must in addition reduce
to the basis modulo the fresh prime, which only a prime dividing the difference's numerators allows.
For U = 1000 (an input whose unlucky 31-bit primes multiply to a number of more than 9,000 digits)
and 3 of 3 primes, the bound is 7.7e-15 (U = 100: 7.7e-18); :func:`error_bound` computes it.

References: W. Pauer, "On lucky ideals for Gröbner basis computations", JSC 14 (1992); E. A. Arnold,
"Modular algorithms for computing Gröbner bases", JSC 35 (2003); P. S. Wang, "A p-adic algorithm for
univariate partial fractions", SYMSAC 1981 (rational reconstruction).
"""
from __future__ import annotations

import hashlib
import random
import time
from dataclasses import dataclass
from fractions import Fraction
from math import comb, gcd, isqrt
from typing import Callable, Iterator, Sequence

from .degree import DegreeReport, PrimeDisagreement, PrimeResult, _agreed
from .exact import coprime_fraction
from .io import Coefficients, System, to_msolve
from .orderings import MonomialOrder
from .ring import is_prime

PRIME_RANGE = (1 << 30, 1 << 31)
"""Random primes are drawn from the open interval (2^30, 2^31): 31-bit primes, every one supported by
the engine (and by msolve)."""

PRIMES_IN_RANGE = 50_697_537
"""pi(2^31) - pi(2^30) = 105,097,565 - 54,400,028: the number of primes drawn from (used in the bound
of :func:`error_bound` only)."""

MIN_AGREE = 3
"""The fewest primes that must agree on a characteristic-0 answer (and be a strict majority)."""

MAX_PRIMES = 12
"""Primes computed for a majority before giving up with :class:`PrimeDisagreement`."""

MAX_SKIPPED = 50
"""Random primes rejected by :func:`unlucky_reason` before giving up (an input with 50 rejected 31-bit
primes in a row has a leading coefficient or denominator of more than 1500 digits' worth of them)."""

MAX_FRESH_UNLUCKY = 3
"""Fresh primes in a row whose leading monomials differ from the majority's before the majority itself is
taken for unlucky (:class:`PrimeDisagreement`)."""

MAX_RECONSTRUCTION_PRIMES = 2500
"""Primes spent on one reconstruction of a basis over Q: numerators and denominators of up to about
11,600 digits (31-bit primes, 9.3 digits each, half of the modulus for each of the two)."""

EVERY_PRIME_UNTIL = 32
"""Reconstruction is tried after every prime up to this many primes, then once the primes grew by an eighth."""

RACE_MAX_BASIS = 50

#: A linear system with an input coefficient above 2^46 and at most this many matrix cells (polynomials x
#: (unknowns + 1)) gets its exact basis in this process (:func:`rational_basis`); a larger one races in a child.
INPROCESS_LINEAR_CELLS = 10_000
"""The exact basis races the primes after a failed candidate only for a reduced basis of at most this many
elements (katsura-6, 41 elements: FLINT's Buchberger 0.7 s; katsura-7: over 100 s, a core spent for
nothing); for an input coefficient above 2^46 it races at once, whatever the size."""

DEFAULT_PRIME_SEED = 0
"""Seed of the default random primes: a run is reproducible; another seed draws other primes."""


class ReconstructionFailed(RuntimeError):
    """The basis over Q was not recovered within :data:`MAX_RECONSTRUCTION_PRIMES` primes."""


def input_seed(variables: Sequence[str], exact: Sequence[Coefficients], seed: int = DEFAULT_PRIME_SEED) -> int:
    """A seed for :func:`random_primes` drawn from the input itself (SHA-256 of its msolve text) and ``seed``.

    With a fixed seed, an input built from the primes it draws (a determinant that is their product) is
    answered wrongly by all of them; with the seed a hash of the input, building one means finding an input
    whose own hash picks primes dividing it, which is as hard as inverting the hash. Reruns stay identical.
    """
    text = to_msolve(System(tuple(variables), 0, tuple(exact))) + f"seed {seed}\n"
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], "big")


def random_primes(seed: int = DEFAULT_PRIME_SEED, exclude: Sequence[int] = ()) -> Iterator[int]:
    """Distinct primes drawn uniformly at random from (2^30, 2^31), from a generator seeded by ``seed``
    (the same seed gives the same primes on every machine); primes in ``exclude`` are skipped."""
    rng = random.Random(seed)
    seen = set(exclude)
    lo, hi = PRIME_RANGE
    while True:
        n = rng.randrange(lo + 1, hi, 2)
        if n not in seen and is_prime(n):
            seen.add(n)
            yield n


def order_key(order: str, nvars: int) -> Callable[[tuple[int, ...]], int]:
    """exponents -> the packed key of the monomial in the order (larger key: larger monomial)."""
    weights = MonomialOrder.parse(order, nvars).variable_weights
    return lambda e: sum(a * w for a, w in zip(e, weights))


def leading_terms(polys: Sequence[Coefficients], order: str, nvars: int) -> list[tuple[tuple[int, ...], Fraction]]:
    """The leading term (exponents, coefficient) of each nonzero exact polynomial in the order."""
    key = order_key(order, nvars)
    return [(lead, f[lead]) for f in polys if f for lead in (max(f, key=key),)]


def unlucky_reason(polys: Sequence[Coefficients], p: int, order: str, nvars: int) -> str | None:
    """Why p cannot be used for these exact polynomials (a denominator or a leading coefficient in the
    order divisible by p), or None. Such a prime changes the input itself; the remaining unlucky primes
    are found by comparing primes (:func:`analyse_rational`)."""
    for i, f in enumerate(polys):
        for c in f.values():
            if c.denominator % p == 0:
                return f"polynomial {i + 1}: the denominator of {c} is divisible by {p}"
    for i, (_, c) in enumerate(leading_terms(polys, order, nvars)):
        if c.numerator % p == 0:
            return f"polynomial {i + 1}: the leading coefficient {c} is divisible by {p}"
    return None


def signature(result: PrimeResult) -> tuple:
    """What lucky primes agree on: dimension, degree and the leading monomials of the reduced basis
    (these determine the Hilbert function)."""
    return result.dimension, result.degree, tuple(sorted(result.gb.ring.exps(m) for m in result.gb.leading_monomials))


def error_bound(agree: int, computed: int, unlucky: int = 1000) -> float:
    """Probability bound C(computed, agree) (unlucky / N)^agree that ``agree`` of ``computed`` random
    primes are unlucky (see the module docstring), for an input with ``unlucky`` unlucky primes."""
    return comb(computed, agree) * (unlucky / PRIMES_IN_RANGE) ** agree


@dataclass(frozen=True)
class RationalReport:
    """A characteristic-0 answer: the report of the agreeing primes and what was checked.

    report: degree, dimension and bases of the majority primes (``report.per_prime``).
    computed: every prime computed, in order; disagreeing: those outside the majority.
    skipped: (prime, reason) of primes rejected before any work.
    status: one line saying what was checked and the residual error probability.
    """

    report: DegreeReport
    computed: tuple[int, ...]
    disagreeing: tuple[int, ...]
    skipped: tuple[tuple[int, str], ...]
    status: str


def _majority(results: Sequence[PrimeResult]) -> list[PrimeResult]:
    groups: dict[tuple, list[PrimeResult]] = {}
    for r in results:
        groups.setdefault(signature(r), []).append(r)
    return max(groups.values(), key=len)


def analyse_rational(
    exact: Sequence[Coefficients],
    order: str,
    nvars: int,
    compute: Callable[[int], PrimeResult],
    primes: Sequence[int] | None = None,
    seed: int = DEFAULT_PRIME_SEED,
) -> RationalReport:
    """Degree, dimension and leading monomials of a characteristic-0 system, by a majority of primes.

    Parameters
    ----------
    exact: the exact polynomials (input and saturating polynomial), for :func:`unlucky_reason`.
    compute: prime -> that prime's :class:`PrimeResult`.
    primes: the user's primes: each is checked by :func:`unlucky_reason` (a :class:`ValueError` names a
        bad one), all must agree, and they must agree with the random primes' majority, which is drawn as
        without them (:class:`PrimeDisagreement` otherwise): a given prime is checked like a random one.
    seed: seed of the random primes: at least :data:`MIN_AGREE` of them must agree and be a strict
        majority; primes are drawn until then (at most :data:`MAX_PRIMES`).
    """
    given: list[PrimeResult] = []
    if primes:
        for p in primes:
            reason = unlucky_reason(exact, p, order, nvars)
            if reason:
                raise ValueError(f"--prime {p} is unlucky for this system ({reason}); choose another prime, or "
                                 "leave out --prime for random 31-bit primes")
        given = [compute(p) for p in primes]
        if len({signature(r) for r in given}) > 1:
            summary = ", ".join(f"p={r.prime}: degree {r.degree}, dimension {r.dimension}, {r.gb_size} leading "
                                "monomials" for r in given)
            raise PrimeDisagreement(f"primes disagree ({summary}); at least one is unlucky: try other primes, "
                                    "or leave out --prime for a majority of random primes")
    best, results, skipped = _random_majority(exact, order, nvars, compute, seed, exclude=tuple(primes or ()))
    if given and signature(given[0]) != signature(best[0]):
        mine, theirs = given[0], best[0]
        raise PrimeDisagreement(
            f"--prime {', '.join(map(str, primes))} is unlucky for this system: degree {mine.degree}, dimension "
            f"{mine.dimension} there, but {len(best)} of {len(results)} random 31-bit primes (seed {seed}) agree on "
            f"degree {theirs.degree}, dimension {theirs.dimension}; try another --prime")
    agreeing = {r.prime for r in best}
    others = tuple(r.prime for r in results if r.prime not in agreeing)
    report = _agreed(given + best)
    k, m = len(results), len(best)
    status = ((f"the given prime(s) {', '.join(map(str, primes))} and " if given else "")
              + f"{m} of {k} random 31-bit primes (seed {seed}) agree on degree, dimension and leading monomials"
              + (f"; {len(others)} unlucky prime(s) outvoted: {', '.join(map(str, others))}" if others else "")
              + (f"; {len(skipped)} skipped (leading coefficient or denominator)" if skipped else "")
              + f"; wrong with probability <= {error_bound(m, k):.1e} if the input has 1000 unlucky primes")
    computed = tuple(r.prime for r in given) + tuple(r.prime for r in results)
    return RationalReport(report, computed, others, tuple(skipped), status)


def _random_majority(
    exact: Sequence[Coefficients],
    order: str,
    nvars: int,
    compute: Callable[[int], PrimeResult],
    seed: int,
    exclude: Sequence[int] = (),
) -> tuple[list[PrimeResult], list[PrimeResult], list[tuple[int, str]]]:
    """Random primes (not in ``exclude``) drawn until at least :data:`MIN_AGREE` agree and are a strict
    majority: (the majority, every prime computed, the (prime, reason) of those rejected by
    :func:`unlucky_reason`). Raises :class:`PrimeDisagreement` after :data:`MAX_PRIMES` primes."""
    draw = random_primes(seed, exclude)
    results: list[PrimeResult] = []
    skipped: list[tuple[int, str]] = []
    while True:
        p = next(draw)
        reason = unlucky_reason(exact, p, order, nvars)
        if reason:
            skipped.append((p, reason))
            if len(skipped) > MAX_SKIPPED:
                raise ValueError(f"{len(skipped)} random primes divide a leading coefficient or denominator "
                                 f"(last: {reason}); try another --prime-seed")
            continue
        results.append(compute(p))
        best = _majority(results)
        if len(best) >= MIN_AGREE and 2 * len(best) > len(results):
            return best, results, skipped
        if len(results) >= MAX_PRIMES:
            summary = ", ".join(f"p={r.prime}: degree {r.degree}, dimension {r.dimension}" for r in results)
            raise PrimeDisagreement(f"no majority of {MIN_AGREE} among {len(results)} random primes ({summary}); "
                                    "try another --prime-seed")


# -- the basis over Q -------------------------------------------------------------------------------

LATTICE_BITS = 4000
"""Moduli of more bits are reconstructed by lattice reduction (:func:`_lattice_reconstruction`), smaller
ones by Wang's loop (20,000 digits: 0.03 s against 0.27 s)."""


def rational_reconstruction(a: int, m: int) -> Fraction | None:
    """The fraction n/d with n = a d (mod m), |n|, |d| <= sqrt(m/2), gcd(n, d) = 1 and gcd(d, m) = 1, or
    None. There is at most one such fraction (two would give n d' - n' d = 0 mod m with |n d' - n' d| < m).
    Wang's algorithm (the half-extended Euclidean algorithm stopped at the bound) below
    :data:`LATTICE_BITS`, lattice reduction above (which may miss it, giving None: more primes, never
    another fraction)."""
    if m.bit_length() > LATTICE_BITS:
        return _lattice_reconstruction(a, m)
    return wang_reconstruction(a, m)


def _lattice_reconstruction(a: int, m: int) -> Fraction | None:
    """The fraction of :func:`rational_reconstruction` among short vectors (n, d) of the lattice
    {(x, y): x = a y mod m}, basis (m, 0), (a, 1): FLINT's LLL, then the reduced rows and their sum and
    difference are tried against the same conditions as Wang's (the conditions make the answer unique)."""
    import flint

    reduced = flint.fmpz_mat([[m, 0], [a % m, 1]]).lll()
    b1 = (int(reduced[0, 0]), int(reduced[0, 1]))
    b2 = (int(reduced[1, 0]), int(reduced[1, 1]))
    bound = isqrt(m // 2)
    fm = flint.fmpz(m)
    for x, y in (b1, b2, (b1[0] + b2[0], b1[1] + b2[1]), (b1[0] - b2[0], b1[1] - b2[1])):
        if y < 0:
            x, y = -x, -y
        if 0 < y <= bound and abs(x) <= bound and flint.fmpz(x).gcd(y) == 1 and fm.gcd(y) == 1:
            return coprime_fraction(x, y)
    return None


def wang_reconstruction(a: int, m: int) -> Fraction | None:
    """:func:`rational_reconstruction` by Wang's algorithm (the reference: quadratic, in Python)."""
    bound = isqrt(m // 2)
    r0, r1, s0, s1 = m, a % m, 0, 1
    while r1 > bound:
        q = r0 // r1
        r0, r1 = r1, r0 - q * r1
        s0, s1 = s1, s0 - q * s1
    if s1 == 0 or abs(s1) > bound or gcd(r1, s1) != 1 or gcd(s1, m) != 1:
        return None
    return coprime_fraction(-r1, -s1) if s1 < 0 else coprime_fraction(r1, s1)  # gcd checked: no second one


def _coefficient_table(result: PrimeResult) -> dict[tuple, dict[tuple, int]]:
    """The reduced basis of one prime: leading exponents -> {exponents: coefficient}."""
    ring = result.gb.ring
    return {ring.exps(g.lm): {ring.exps(k): c for k, c in zip(g.mons, g.coeffs)} for g in result.gb.basis}


def _reduce_mod(basis: dict[tuple, Coefficients], p: int) -> dict[tuple, dict[tuple, int]] | None:
    """The basis over Q reduced mod p, or None when p divides a denominator."""
    out = {}
    for lead, f in basis.items():
        terms = {}
        for e, c in f.items():
            if c.denominator % p == 0:
                return None
            v = c.numerator * pow(c.denominator, -1, p) % p
            if v:
                terms[e] = v
        out[lead] = terms
    return out


def _reconstruct(values: dict[tuple, int], modulus: int, first: tuple | None) -> tuple[dict | None, tuple | None]:
    """Every coefficient recovered as a fraction (lead -> {exponents: Fraction}), or (None, the key that
    failed). ``first``: the key that failed last time, tried first (it usually fails again: one Euclid)."""
    keys = ([first] if first in values else []) + [k for k in values if k != first]
    candidate: dict[tuple, Coefficients] = {}
    for key in keys:
        c = rational_reconstruction(values[key], modulus)
        if c is None:
            return None, key
        if c:
            candidate.setdefault(key[0], {})[key[1]] = c
    return candidate, None


def _digits(basis: Sequence[Coefficients]) -> int:
    """Decimal digits of the largest numerator or denominator (of any size)."""
    from .polytext import _int_to_digits

    return len(_int_to_digits(max((max(abs(c.numerator), c.denominator) for f in basis for c in f.values()),
                                  default=1)))


def rational_basis(
    rational: RationalReport,
    exact: Sequence[Coefficients],
    order: str,
    nvars: int,
    compute: Callable[[int], PrimeResult],
    seed: int = DEFAULT_PRIME_SEED,
    generators: Sequence[Coefficients] | None = None,
    progress: Callable[[str], None] | None = None,
) -> tuple[list[Coefficients], str]:
    """The reduced Gröbner basis over Q (monic, sorted by leading monomial) and a status line.

    The coefficients of the majority primes' bases are combined by the Chinese remainder theorem and
    recovered as fractions by :func:`rational_reconstruction`; a candidate is accepted when it reduces
    to the basis computed modulo a fresh prime (one not used for it). A fresh prime that gives other
    leading monomials is unlucky and dropped; one that disagrees with a candidate joins the remaindering.
    Reconstruction is tried after every prime up to :data:`EVERY_PRIME_UNTIL` primes, then only once the
    primes have grown by an eighth (the failed coefficient first), so its cost stays a constant times that
    of the last, successful, try.

    ``generators``: the polynomials whose ideal this is (not given for a saturation). With them, once the
    first candidate fails (at once for an input coefficient above 2^46), FLINT's exact Buchberger over Z
    runs alongside in a child process (:class:`analysis.engine.exact.ExactRace`, grevlex, lex and
    deglex); when it finishes first with the majority's leading monomials and reduces to the basis modulo
    the last prime computed (not used for it), that basis is returned (other leading monomials:
    :class:`PrimeDisagreement`, the majority was unlucky). Raises :class:`ReconstructionFailed` after
    :data:`MAX_RECONSTRUCTION_PRIMES` primes; ``progress`` hears of the primes now and then.
    """
    from .exact import ExactRace, supported

    target = signature(rational.report.per_prime[0])
    used = list(rational.report.per_prime)
    modulus, values = 1, {}  # (lead, exponents) -> residue mod modulus
    say = progress or (lambda line: None)

    def combine(result: PrimeResult) -> None:
        nonlocal modulus
        p, table = result.prime, _coefficient_table(result)
        keys = set(values) | {(lead, e) for lead, f in table.items() for e in f}
        inv = pow(modulus, -1, p)
        for key in keys:
            x = values.get(key, 0)
            r = table[key[0]].get(key[1], 0)
            values[key] = x + modulus * ((r - x) * inv % p)
        modulus *= p

    def fresh() -> PrimeResult:
        """The next fresh prime's result with the majority's signature (unlucky ones dropped)."""
        nonlocal fresh_unlucky
        in_a_row = 0
        while True:
            q = next(draw)
            if unlucky_reason(exact, q, order, nvars) is None:
                check = compute(q)
                if signature(check) == target:
                    return check
                fresh_unlucky += 1
                in_a_row += 1
                if in_a_row >= MAX_FRESH_UNLUCKY:
                    raise PrimeDisagreement(
                        f"{in_a_row} fresh primes in a row (last {q}: degree {check.degree}, dimension "
                        f"{check.dimension}) disagree with the majority of {len(rational.report.per_prime)} primes "
                        f"(degree {target[1]}, dimension {target[0]}): the majority's primes were unlucky; try "
                        "another --prime-seed")

    def matches(candidate: dict[tuple, Coefficients] | None, check: PrimeResult) -> bool:
        return candidate is not None and len(candidate) == len(target[2]) and \
            _reduce_mod(candidate, check.prime) == _coefficient_table(check)

    def finish(candidate: dict[tuple, Coefficients], how: str, check: PrimeResult,
               fresh: bool = True) -> tuple[list[Coefficients], str]:
        basis = [candidate[lead] for lead in sorted(candidate, key=order_key(order, nvars))]
        status = (f"over Q: {how} (largest numerator or denominator {_digits(basis)} digits), checked modulo the "
                  + (f"fresh prime {check.prime}" if fresh else f"prime {check.prime} (not used to compute it)")
                  + (f"; {fresh_unlucky} unlucky fresh prime(s) dropped" if fresh_unlucky else ""))
        return basis, status

    def confirmed(found) -> dict[tuple, Coefficients] | None:
        """The child's exact basis when it has the majority's leading monomials and reduces to the basis
        modulo the last prime computed (which played no part in it), else None."""
        leads = tuple(sorted(next(iter(f)) for f in found.basis if f))
        if leads != target[2]:
            raise PrimeDisagreement(
                f"the exact basis over Q ({found.method}) has {len(found.basis)} elements with "
                f"other leading monomials than the majority of {len(rational.report.per_prime)} primes "
                f"(degree {target[1]}, dimension {target[0]}): the majority's primes were unlucky; try "
                "another --prime-seed")
        table = {next(iter(f)): f for f in found.basis if f}
        return table if found.groebner is not False and matches(table, used[-1]) else None

    for r in used:
        combine(r)
    draw = random_primes(seed + 1, exclude=rational.computed)
    fresh_unlucky = 0
    attempt_at, witness = len(used), None
    can_race = generators is not None and supported(order)
    small = len(target[2]) <= RACE_MAX_BASIS  # after a failed candidate, a large basis is left to the primes
    race = None
    # A coefficient above 2^46 cannot come back from the majority's three primes: the race starts at once,
    # and the primes yield half the time to it (each waits for the child as long as it took), since exact
    # arithmetic usually wins there; on a loaded machine the two would otherwise share one core's time.
    big = can_race and max((max(abs(c.numerator), c.denominator).bit_length() for f in generators
                            for c in f.values()), default=0) > 46
    if big and len(generators) * (nvars + 1) <= INPROCESS_LINEAR_CELLS and \
            all(sum(e) <= 1 for f in generators for e in f):
        # a small linear system: FLINT's fraction-free row echelon form here, not in a child (its cost is
        # bounded by the matrix's size; forking and polling a child cost more than the echelon form itself:
        # B x - A with 10,000-digit A and B, 0.5 ms against 4-8 ms)
        from .exact import exact_basis

        try:
            found = exact_basis(generators, order, nvars)
        except (MemoryError, ValueError, ArithmeticError):  # the race and the primes go on, as after a child's failure
            found = None
        table = confirmed(found) if found is not None else None
        if table is not None:
            return finish(table, f"exact {found.method}, done after {len(used)} primes", used[-1], fresh=False)
    if big:
        race = ExactRace(generators, order, nvars)
    per_prime = rational.report.seconds / max(1, len(rational.report.per_prime))
    first_wait = min(4 * per_prime, per_prime + 0.05)  # the child's head start, once: a few primes' time at most
    head_start = first_wait
    try:
        while True:
            if race is not None and can_race:
                found = race.poll(head_start)
                head_start = 0.0
                if found is not None:
                    table = confirmed(found)
                    if table is not None:
                        return finish(table, f"exact {found.method}, done while {len(used)} primes ran",
                                      used[-1], fresh=False)
                    can_race = False  # not confirmed: the primes go on alone
            candidate = None
            if len(used) >= attempt_at:
                candidate, witness = _reconstruct(values, modulus, witness)
                if candidate is None:
                    # every prime while they are few (a prime costs more than a reconstruction), then
                    # each eighth more (and at the cap): the tries cost a constant times the last one
                    attempt_at = len(used) + 1 if len(used) < EVERY_PRIME_UNTIL else \
                        min((9 * len(used) + 7) // 8, MAX_RECONSTRUCTION_PRIMES)
            started = time.perf_counter()
            check = fresh()
            if big:
                head_start = time.perf_counter() - started
            if matches(candidate, check):
                return finish(candidate, f"Chinese remaindering of {len(used)} primes and rational reconstruction",
                              check)
            used.append(check)
            combine(check)
            if race is None and can_race and small:
                race = ExactRace(generators, order, nvars)
                head_start = first_wait
            if len(used) % 200 == 0:
                say(f"[gb over Q] {len(used)} primes (fractions up to about {len(used) * 93 // 20} digits), "
                    "no basis yet" + (" (the exact basis computed alongside)" if race is not None and can_race else ""))
            if len(used) > MAX_RECONSTRUCTION_PRIMES:  # the last try was at the cap
                raise ReconstructionFailed(f"the basis over Q was not recovered from {len(used)} primes "
                                           f"(coefficients above {len(used) * 93 // 20} digits)")
    finally:
        if race is not None:
            race.close()
