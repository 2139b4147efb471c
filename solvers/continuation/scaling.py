"""Where exact numbers become floats: an equation over Q whose coefficients lie beyond float64's comfortable
range is multiplied by a power of two first (its solutions unchanged), then each coefficient rounded once.

One rule for every verb that starts numerics from exact coefficients: ``solve`` (the input equations'
floats for Newton, :mod:`solvers.system_solve`) and the homotopy coefficient code of ``count`` and
``generate`` (:func:`solvers.continuation.tracking.coefficient_source`). It lives in this package because
the continuation imports only itself (tests/test_generate.py); it needs nothing but :mod:`fractions`.
"""
from __future__ import annotations

from fractions import Fraction
from typing import Iterable

__all__ = ["SCALE_BITS", "log2_floor", "scaled_float", "equation_shift"]

SCALE_BITS = 500
"""An equation whose largest coefficient lies outside [2^-SCALE_BITS, 2^SCALE_BITS] (about 1e+-150) is
scaled by the power of two that brings its largest coefficient into [1, 2): its float coefficients are
then finite, and a product of two of them (Newton's Jacobian, a monomial's value) stays within float64's
range. Equations within the range keep their coefficients as written (and committed outputs their bytes)."""


def log2_floor(c: Fraction) -> int:
    """floor(log2 |c|) of a nonzero rational, within one: exact enough to choose a power of two."""
    return abs(c.numerator).bit_length() - c.denominator.bit_length()


def scaled_float(c: Fraction, k: int) -> float:
    """The float of c * 2^-k: the scaling exact, one rounding (0.0 below float64's range; OverflowError
    above it)."""
    n, d = c.numerator, c.denominator
    n, d = (n, d << k) if k >= 0 else (n << -k, d)
    return n / d  # Python's int division: correctly rounded for integers of any size


def equation_shift(coefficients: Iterable[Fraction]) -> int:
    """The k of an equation's scaling by 2^-k: 0 when its largest nonzero coefficient lies within
    2^+-SCALE_BITS, else that coefficient's floor(log2)."""
    top = max((log2_floor(c) for c in coefficients if c), default=0)
    return top if abs(top) > SCALE_BITS else 0
