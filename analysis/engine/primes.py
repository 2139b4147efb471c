"""Characteristics the engine supports: primes 2 <= p < 2^31, checked by deterministic Miller-Rabin.

The lowest layer of :mod:`analysis`: :mod:`analysis.engine.ring` (which re-exports these names) and the
polynomial parser :mod:`analysis.engine.polytext` both check a characteristic here.
"""
from __future__ import annotations

MAX_PRIME = 2**31


class BadPrime(ValueError):
    """The characteristic is not a prime in the supported range 2 <= p < 2**31."""


def is_prime(n: int) -> bool:
    """Deterministic Miller-Rabin for n < 3.3e24 (enough for every supported characteristic)."""
    if n < 2:
        return False
    small = (2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41)
    for q in small:
        if n % q == 0:
            return n == q
    d, s = n - 1, 0
    while d % 2 == 0:
        d //= 2
        s += 1
    for a in small:
        x = pow(a, d, n)
        if x in (1, n - 1):
            continue
        for _ in range(s - 1):
            x = x * x % n
            if x == n - 1:
                break
        else:
            return False
    return True


def check_prime(p: int) -> int:
    """Return p if it is a supported characteristic, else raise :class:`BadPrime`."""
    if not isinstance(p, int) or isinstance(p, bool):
        raise BadPrime(f"characteristic must be an integer, got {p!r}")
    if not 2 <= p < MAX_PRIME:
        raise BadPrime(f"characteristic {p} out of range: need a prime 2 <= p < 2^31")
    if not is_prime(p):
        raise BadPrime(f"characteristic {p} is not prime")
    return p
