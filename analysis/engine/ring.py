"""Polynomial rings over GF(p) and their sparse polynomials.

A :class:`Ring` is frozen: variable names, the prime and the monomial order. Monomials are stored as
order-preserving additive integer keys (see :mod:`analysis.engine.orderings`), so a polynomial is two parallel
lists, monomial keys in strictly decreasing order and coefficients in [1, p). The ring caches the
exponent vector of every key it has seen.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Mapping, Sequence

import numpy as np

from .orderings import FIELD_BITS, MonomialOrder
from .polytext import parse_polynomial
from .primes import MAX_PRIME, BadPrime, check_prime, is_prime  # noqa: F401  (re-exported: imported from here)

_PER_WORD = 64 // FIELD_BITS
"""Key fields per 64-bit word."""




@dataclass(frozen=True, eq=False)
class Ring:
    """GF(p)[variables] with a monomial order.

    Parameters
    ----------
    variables: variable names (distinct identifiers).
    prime: the characteristic, a prime 2 <= p < 2**31.
    order: "grevlex", "lex", "block:k1,k2,..." or a :class:`MonomialOrder`.
    """

    variables: tuple[str, ...]
    prime: int
    order: MonomialOrder
    _weights: tuple[int, ...] = field(repr=False, default=())
    _exps: dict = field(repr=False, default_factory=dict)
    _keys: dict = field(repr=False, default_factory=dict)
    _nrows: int = field(repr=False, default=0)
    _winv_t: object = field(repr=False, default=None)
    _winv: tuple = field(repr=False, default=())

    def __init__(self, variables: Sequence[str], prime: int, order: "str | MonomialOrder" = "grevlex"):
        variables = tuple(str(v) for v in variables)
        if not variables:
            raise ValueError("a ring needs at least one variable")
        if len(set(variables)) != len(variables):
            raise ValueError(f"duplicate variable names in {variables}")
        if isinstance(order, str):
            order = MonomialOrder.parse(order, len(variables))
        elif order.nvars != len(variables):
            raise ValueError("order and ring have different numbers of variables")
        object.__setattr__(self, "variables", variables)
        object.__setattr__(self, "prime", check_prime(prime))
        object.__setattr__(self, "order", order)
        object.__setattr__(self, "_weights", order.variable_weights)
        object.__setattr__(self, "_exps", {0: (0,) * len(variables)})
        # exponent tuple -> key, for tuples already checked: a term seen again costs one lookup, not a pass
        # over every variable (a linear system in 250 unknowns: 62,500 terms, 251 monomials)
        object.__setattr__(self, "_keys", {})
        object.__setattr__(self, "_nrows", len(order.weight_rows))
        W = np.array(order.weight_rows, dtype=np.int64)
        winv = np.rint(np.linalg.inv(W.astype(float))).astype(np.int64)
        if not np.array_equal(W @ winv, np.eye(len(variables), dtype=np.int64)):
            raise ValueError(f"order {order} has no integer inverse weight matrix")
        object.__setattr__(self, "_winv_t", np.ascontiguousarray(winv.T[::-1]))
        object.__setattr__(self, "_winv", tuple(tuple(int(x) for x in row) for row in winv))

    # -- identity ---------------------------------------------------------------------------
    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Ring)
            and self.variables == other.variables
            and self.prime == other.prime
            and self.order == other.order
        )

    def __hash__(self) -> int:
        return hash((self.variables, self.prime, self.order))

    def __repr__(self) -> str:
        return f"Ring(GF({self.prime})[{', '.join(self.variables)}], {self.order})"

    def with_prime(self, prime: int) -> "Ring":
        return Ring(self.variables, prime, self.order)

    def with_order(self, order: "str | MonomialOrder") -> "Ring":
        return Ring(self.variables, self.prime, order)

    @property
    def nvars(self) -> int:
        return len(self.variables)

    # -- monomials --------------------------------------------------------------------------
    def key(self, exps: Sequence[int]) -> int:
        """Order key of the monomial with exponent vector exps."""
        if type(exps) is tuple:
            k = self._keys.get(exps)
            if k is not None:
                return k
        if len(exps) != self.nvars:
            raise ValueError(f"exponent vector {tuple(exps)} has length {len(exps)}, ring has {self.nvars} variables")
        k = 0
        for e, w in zip(exps, self._weights):
            if e:
                if e < 0:
                    raise ValueError(f"negative exponent in {tuple(exps)}")
                k += e * w
        if sum(exps) > self.order.max_row_value:
            raise OverflowError(f"total degree {sum(exps)} exceeds the supported 2^{FIELD_BITS}-1")
        ex = self._exps
        if k not in ex:
            ex[k] = tuple(int(e) for e in exps)
        if type(exps) is tuple and all(type(e) is int for e in exps):
            self._keys[exps] = k
        return k

    def exps(self, key: int) -> tuple[int, ...]:
        """Exponent vector of a monomial key (decoded once, then cached)."""
        e = self._exps.get(key)
        if e is None:
            e = self._decode(key)
            self._exps[key] = e
        return e

    def _decode(self, key: int) -> tuple[int, ...]:
        nrows = self._nrows
        mask = (1 << FIELD_BITS) - 1
        fields = [(key >> (FIELD_BITS * (nrows - 1 - r))) & mask for r in range(nrows)]
        # the exponents are the integer inverse of the weight matrix applied to the row values
        return tuple(sum(w * f for w, f in zip(row, fields) if w) for row in self._winv)

    def decode_many(self, keys: Sequence[int]) -> np.ndarray:
        """Exponent vectors (len(keys) x nvars, int64) of many keys at once, through their bytes."""
        nb = FIELD_BITS // 8 * self._nrows
        if not keys:
            return np.zeros((0, self.nvars), dtype=np.int64)
        raw = b"".join(k.to_bytes(nb, "little") for k in keys)
        fields = np.frombuffer(raw, dtype=f"<u{FIELD_BITS // 8}").reshape(len(keys), self._nrows)
        # little-endian fields are the weight rows, last row first: the reversed inverse undoes both
        return fields.astype(np.int64) @ self._winv_t

    def degree(self, key: int) -> int:
        return sum(self.exps(key))

    def divides(self, a: int, b: int) -> bool:
        """Whether monomial a divides monomial b."""
        return all(x <= y for x, y in zip(self.exps(a), self.exps(b)))

    def lcm(self, a: int, b: int) -> int:
        return self.key(tuple(max(x, y) for x, y in zip(self.exps(a), self.exps(b))))

    def variable_key(self, i: int) -> int:
        return self._weights[i]

    def monomial_str(self, key: int) -> str:
        parts = []
        for v, e in zip(self.variables, self.exps(key)):
            if e == 1:
                parts.append(v)
            elif e > 1:
                parts.append(f"{v}^{e}")
        return "*".join(parts) if parts else "1"

    # -- polynomials ------------------------------------------------------------------------
    def zero(self) -> "Poly":
        return Poly(self, [], [])

    def one(self) -> "Poly":
        return Poly(self, [0], [1])

    def gen(self, i: "int | str") -> "Poly":
        if isinstance(i, str):
            try:
                i = self.variables.index(i)
            except ValueError:
                raise ValueError(f"unknown variable {i!r}; ring variables: {', '.join(self.variables)}") from None
        return Poly(self, [self._weights[i]], [1])

    def gens(self) -> list["Poly"]:
        return [self.gen(i) for i in range(self.nvars)]

    def from_terms(self, terms: "Mapping[Sequence[int], int] | Iterable[tuple[Sequence[int], int]]") -> "Poly":
        """Polynomial from {exponent vector: integer (or Fraction) coefficient}; reduced mod p."""
        items = terms.items() if isinstance(terms, Mapping) else terms
        acc: dict[int, int] = {}
        p = self.prime
        for exps, c in items:
            c = _mod(c, p)
            if c:
                k = self.key(tuple(exps))
                acc[k] = (acc.get(k, 0) + c) % p
        return Poly.from_dict(self, acc)

    def from_sympy(self, expr) -> "Poly":
        """Polynomial from a sympy expression in (a subset of) the ring's variables.

        A string is read by the project's polynomial parser (:func:`analysis.engine.polytext.parse_polynomial`),
        never evaluated.
        """
        import sympy

        if isinstance(expr, str):
            return self.from_terms(parse_polynomial(expr, self.variables))
        syms = sympy.symbols(self.variables)
        expr = sympy.sympify(expr, strict=True)  # strict: objects only, no text parsing
        unknown = sorted(str(s) for s in expr.free_symbols if str(s) not in self.variables)
        if unknown:
            raise ValueError(f"unknown variable(s) {', '.join(unknown)}; ring variables: {', '.join(self.variables)}")
        poly = sympy.Poly(expr, *syms, domain="QQ")
        return self.from_terms((m, sympy.Rational(c)) for m, c in poly.terms())

    def to_sympy(self, f: "Poly"):
        import sympy

        syms = sympy.symbols(self.variables)
        out = sympy.Integer(0)
        for k, c in zip(f.mons, f.coeffs):
            term = sympy.Integer(c)
            for s, e in zip(syms, self.exps(k)):
                if e:
                    term *= s**e
            out += term
        return out


class CodeOverflow(OverflowError):
    """A monomial's total degree exceeds what the narrow codes of :class:`MonomialCodes` can hold."""


class MonomialCodes:
    """Monomials of a ring as numpy integer *codes*, for array-at-a-time work (F4's symbolic
    preprocessing and matrix construction).

    A code packs the weight-row values of a monomial into fields of ``bits`` bits, most significant row
    first: the layout of the ring's keys (see :mod:`analysis.engine.orderings`) with narrower fields. Codes are
    therefore order preserving and additive too, as long as no field overflows. Every row value of the
    supported orders is a partial sum of exponents, so that holds while the total degree is at most
    ``max_degree``; callers check degrees and raise :class:`CodeOverflow` beyond it.

    Narrow codes (the default) use ``64 // rows`` bits per field (at most 16) and live in uint64 arrays;
    wide codes are the ring's keys themselves in object arrays: slower, with the ring's own limits.
    """

    def __init__(self, ring: Ring, wide: bool = False):
        self.ring = ring
        nrows = ring._nrows
        self.wide = wide or 64 // nrows == 0
        self.bits = FIELD_BITS if self.wide else min(FIELD_BITS, 64 // nrows)
        self.max_degree = (1 << self.bits) - 1
        self.dtype = np.dtype(object) if self.wide else np.dtype(np.uint64)
        rows = ring.order.weight_rows
        weights = [sum(rows[r][i] << (self.bits * (nrows - 1 - r)) for r in range(nrows)) for i in range(ring.nvars)]
        self._weights = np.array(weights, dtype=self.dtype)
        # field j, least significant first (weight row nrows-1-j), sits at bit bits*j of a code and at
        # bit FIELD_BITS*(j % _PER_WORD) of word j // _PER_WORD of a key
        self._code_shifts = np.arange(nrows, dtype=np.uint64) * np.uint64(self.bits)
        self._key_shifts = np.arange(nrows, dtype=np.uint64) % np.uint64(_PER_WORD) * np.uint64(FIELD_BITS)
        # the total degree is a combination of a few fields (for grevlex the top one alone)
        degree_weights = ring._winv_t.sum(axis=1)
        self._degree_fields = np.flatnonzero(degree_weights)
        self._degree_weights = degree_weights[self._degree_fields]

    def encode(self, exps: np.ndarray) -> np.ndarray:
        """Codes of exponent vectors (N x nvars)."""
        return np.asarray(exps).astype(self.dtype) @ self._weights

    def decode(self, codes: np.ndarray) -> np.ndarray:
        """Exponent vectors (N x nvars, int64) of codes."""
        if self.wide:
            return self.ring.decode_many(codes.tolist())
        return self._fields(codes).astype(np.int64) @ self.ring._winv_t

    def degrees(self, codes: np.ndarray) -> np.ndarray:
        """Total degrees of codes (int64)."""
        if self.wide:
            return self.decode(codes).sum(axis=1)
        fields = (codes[:, None] >> self._code_shifts[self._degree_fields]) & np.uint64(self.max_degree)
        return fields.astype(np.int64) @ self._degree_weights

    def from_keys(self, keys: Sequence[int]) -> np.ndarray:
        """Codes of ring keys; raises :class:`CodeOverflow` if a total degree exceeds max_degree."""
        if self.wide or not len(keys):
            return np.array(list(keys), dtype=self.dtype)
        exps = self.ring.decode_many(keys)
        top = int(exps.sum(axis=1).max())
        if top > self.max_degree:
            raise CodeOverflow(f"degree {top} exceeds the {self.bits}-bit fields of the monomial codes")
        return self.encode(exps)

    def to_keys(self, codes: np.ndarray) -> list[int]:
        """Ring keys of codes, as Python ints."""
        if self.wide:
            return codes.tolist()
        placed = self._fields(codes) << self._key_shifts
        words = [np.bitwise_or.reduce(placed[:, j : j + _PER_WORD], axis=1) for j in range(0, placed.shape[1], _PER_WORD)]
        if len(words) == 1:
            return words[0].tolist()
        # a key is its words, least significant first: one int.from_bytes per key (twice as fast as
        # shifting word by word)
        raw = np.stack(words, axis=1).astype("<u8").tobytes()
        size = 8 * len(words)
        from_bytes = int.from_bytes
        return [from_bytes(raw[i : i + size], "little") for i in range(0, len(raw), size)]

    def _fields(self, codes: np.ndarray) -> np.ndarray:
        """Field values of narrow codes (N x rows, uint64), least significant first."""
        return (codes[:, None] >> self._code_shifts) & np.uint64(self.max_degree)


def _mod(c, p: int) -> int:
    """Reduce an integer or rational coefficient mod p (raises ZeroDivisionError if p | denominator)."""
    if isinstance(c, int):
        return c % p
    num, den = int(c.numerator), int(c.denominator)
    if den % p == 0:
        raise ZeroDivisionError(f"denominator {den} is divisible by the characteristic {p}")
    return num * pow(den, -1, p) % p


class Poly:
    """A sparse polynomial over GF(p): monomial keys strictly decreasing, coefficients in [1, p)."""

    __slots__ = ("ring", "mons", "coeffs")

    def __init__(self, ring: Ring, mons: list[int], coeffs: list[int]):
        self.ring = ring
        self.mons = mons
        self.coeffs = coeffs

    @staticmethod
    def from_dict(ring: Ring, d: Mapping[int, int]) -> "Poly":
        mons = sorted((k for k, c in d.items() if c), reverse=True)
        return Poly(ring, mons, [d[k] for k in mons])

    def to_dict(self) -> dict[int, int]:
        return dict(zip(self.mons, self.coeffs))

    # -- basic queries ----------------------------------------------------------------------
    def __bool__(self) -> bool:
        return bool(self.mons)

    def __len__(self) -> int:
        return len(self.mons)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Poly):
            return NotImplemented
        return self.ring == other.ring and self.mons == other.mons and self.coeffs == other.coeffs

    def __hash__(self) -> int:
        return hash((tuple(self.mons), tuple(self.coeffs)))

    @property
    def lm(self) -> int:
        return self.mons[0]

    @property
    def lc(self) -> int:
        return self.coeffs[0]

    def total_degree(self) -> int:
        return max((self.ring.degree(k) for k in self.mons), default=-1)

    def is_constant(self) -> bool:
        return len(self.mons) == 1 and self.mons[0] == 0

    def terms(self) -> list[tuple[tuple[int, ...], int]]:
        return [(self.ring.exps(k), c) for k, c in zip(self.mons, self.coeffs)]

    def __repr__(self) -> str:
        return str(self)

    def __str__(self) -> str:
        if not self.mons:
            return "0"
        parts = []
        for k, c in zip(self.mons, self.coeffs):
            m = self.ring.monomial_str(k)
            parts.append(str(c) if m == "1" else (m if c == 1 else f"{c}*{m}"))
        return " + ".join(parts)

    # -- arithmetic -------------------------------------------------------------------------
    def monic(self) -> "Poly":
        if not self.mons or self.coeffs[0] == 1:
            return self
        p = self.ring.prime
        inv = pow(self.coeffs[0], -1, p)
        return Poly(self.ring, self.mons, [c * inv % p for c in self.coeffs])

    def scale(self, c: int) -> "Poly":
        p = self.ring.prime
        c %= p
        if not c:
            return self.ring.zero()
        return Poly(self.ring, self.mons, [x * c % p for x in self.coeffs])

    def mul_term(self, key: int, c: int = 1) -> "Poly":
        """Multiply by the term c * x^key."""
        p = self.ring.prime
        return Poly(self.ring, [k + key for k in self.mons], [x * c % p for x in self.coeffs] if c != 1 else self.coeffs)

    def _coerce(self, other: "Poly | int") -> "Poly":
        if isinstance(other, Poly):
            if other.ring != self.ring:
                raise ValueError("polynomials from different rings")
            return other
        if isinstance(other, int):
            return self.ring.one().scale(other)
        return NotImplemented

    def __add__(self, other: "Poly | int") -> "Poly":
        other = self._coerce(other)
        if other is NotImplemented:
            return NotImplemented
        p = self.ring.prime
        d = self.to_dict()
        for k, c in zip(other.mons, other.coeffs):
            d[k] = (d.get(k, 0) + c) % p
        return Poly.from_dict(self.ring, d)

    def __neg__(self) -> "Poly":
        p = self.ring.prime
        return Poly(self.ring, self.mons, [p - c for c in self.coeffs])

    __radd__ = __add__

    def __sub__(self, other: "Poly | int") -> "Poly":
        other = self._coerce(other)
        if other is NotImplemented:
            return NotImplemented
        return self + (-other)

    def __rsub__(self, other: int) -> "Poly":
        return (-self) + other

    def __mul__(self, other: "Poly | int") -> "Poly":
        if isinstance(other, int):
            return self.scale(other)
        p = self.ring.prime
        d: dict[int, int] = {}
        for k1, c1 in zip(self.mons, self.coeffs):
            for k2, c2 in zip(other.mons, other.coeffs):
                k = k1 + k2
                d[k] = (d.get(k, 0) + c1 * c2) % p
        for k in d:
            self.ring.exps(k)
        return Poly.from_dict(self.ring, d)

    __rmul__ = __mul__

    def __pow__(self, e: int) -> "Poly":
        out = self.ring.one()
        base = self
        while e:
            if e & 1:
                out = out * base
            base = base * base
            e >>= 1
        return out

    def evaluate(self, point: Sequence[int]) -> int:
        """Value mod p at a point of GF(p)^n."""
        p = self.ring.prime
        total = 0
        for k, c in zip(self.mons, self.coeffs):
            t = c
            for x, e in zip(point, self.ring.exps(k)):
                if e:
                    t = t * pow(int(x), e, p) % p
            total += t
        return total % p
