"""Monomial orders as integer weight matrices, and their packing into order-preserving integer keys.

A monomial order here is given by a nonnegative integer matrix W (rows x nvars) of full column rank:
x^a > x^b iff the vector W a is lexicographically larger than W b. grevlex, lex, deglex and block
(elimination) orders are all of this form. Packing the row values W a into fixed-width bit fields, most significant
row first, gives an integer key that is

* order preserving: key(a) > key(b) iff x^a > x^b, so sorting monomials is sorting Python ints;
* additive: key(a + b) = key(a) + key(b), so multiplying by a monomial is one integer addition.

For grevlex the rows are the partial degrees (a_1 + ... + a_n, a_1 + ... + a_{n-1}, ..., a_1): equal total
degree is broken by the smaller exponent of the last variable, which is the larger partial sum.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

FIELD_BITS = 32
"""Width of one packed row value: every row value (e.g. a total degree) must stay below 2**32 (the parser
allows total degrees below 2**31, see analysis.engine.io.MAX_DEGREE; 16 bits refused x^65536 - 1).

A multiple of 8 dividing 64, so that keys decode in bulk through their bytes (see Ring.decode_many) and
whole fields fill 64-bit words (see MonomialCodes.to_keys)."""

OrderName = Literal["grevlex", "lex", "deglex", "block", "graded"]
ORDER_NAMES = ("grevlex", "lex", "deglex", "block")
"""The orders a user names; "graded" (total degree, then another order on all variables but the last) is
built by :mod:`analysis.engine.homogenize` for the homogenizing variable."""


def _grevlex_rows(nvars: int, offset: int, total: int) -> list[list[int]]:
    """Rows of grevlex on variables offset..offset+nvars-1 (partial degree sums)."""
    rows = []
    for k in range(nvars, 0, -1):
        rows.append([1 if offset <= i < offset + k else 0 for i in range(total)])
    return rows


@dataclass(frozen=True)
class MonomialOrder:
    """A monomial order given by a weight matrix; see the module docstring.

    Parameters
    ----------
    name: "grevlex", "lex", "deglex" (total degree, then lex) or "block" (block grevlex orders; the first
        block is eliminated first).
    nvars: number of variables.
    blocks: for "block", the sizes of the consecutive variable blocks (summing to nvars).
    inner: for "graded", the order (name, blocks) that breaks ties of total degree on the first nvars - 1
        variables (the last, a homogenizing variable, only counts in the degree). graded(lex) is deglex.
    """

    name: OrderName
    nvars: int
    blocks: tuple[int, ...] = ()
    inner: tuple = ()

    def __post_init__(self) -> None:
        if self.name == "graded":
            if not self.inner or self.nvars < 2:
                raise ValueError("a graded order needs an inner order and at least two variables")
            MonomialOrder(self.inner[0], self.nvars - 1, tuple(self.inner[1]))
            return
        if self.name not in ORDER_NAMES:
            raise ValueError(f"unknown monomial order {self.name!r}; valid: {', '.join(ORDER_NAMES)}")
        if self.nvars < 1:
            raise ValueError("a ring needs at least one variable")
        if self.name == "block":
            if not self.blocks or sum(self.blocks) != self.nvars or min(self.blocks) < 1:
                raise ValueError(f"block sizes {self.blocks} must be positive and sum to {self.nvars}")

    @staticmethod
    def parse(spec: str, nvars: int) -> "MonomialOrder":
        """Parse 'grevlex', 'lex' or 'block:k1,k2,...' (block sizes; grevlex inside each block)."""
        spec = spec.strip().lower()
        if spec.startswith("block"):
            _, _, sizes = spec.partition(":")
            try:
                blocks = tuple(int(s) for s in sizes.split(",") if s.strip())
            except ValueError:
                raise ValueError(f"bad block order {spec!r}; expected block:k1,k2,...") from None
            if len(blocks) == 1 and blocks[0] < nvars:
                blocks = (blocks[0], nvars - blocks[0])
            return MonomialOrder("block", nvars, blocks)
        return MonomialOrder(spec, nvars)  # type: ignore[arg-type]

    @property
    def weight_rows(self) -> list[list[int]]:
        """The weight matrix, most significant row first."""
        n = self.nvars
        if self.name == "graded":
            inner = MonomialOrder(self.inner[0], n - 1, tuple(self.inner[1])).weight_rows
            return [[1] * n] + [row + [0] for row in inner]
        if self.name == "grevlex":
            return _grevlex_rows(n, 0, n)
        if self.name == "lex":
            return [[1 if i == k else 0 for i in range(n)] for k in range(n)]
        if self.name == "deglex":  # total degree, then lex (the last exponent follows from the others)
            return [[1] * n] + [[1 if i == k else 0 for i in range(n)] for k in range(n - 1)]
        rows: list[list[int]] = []
        offset = 0
        for size in self.blocks:
            rows.extend(_grevlex_rows(size, offset, n))
            offset += size
        return rows

    @property
    def variable_weights(self) -> tuple[int, ...]:
        """Packed key of each variable: key(x^a) = sum_i a_i * variable_weights[i]."""
        rows = self.weight_rows
        nrows = len(rows)
        return tuple(
            sum(rows[r][i] << (FIELD_BITS * (nrows - 1 - r)) for r in range(nrows)) for i in range(self.nvars)
        )

    @property
    def max_row_value(self) -> int:
        return (1 << FIELD_BITS) - 1

    def __str__(self) -> str:
        if self.name == "graded":
            return f"graded({MonomialOrder(self.inner[0], self.nvars - 1, tuple(self.inner[1]))})"
        if self.name == "block":
            return "block:" + ",".join(map(str, self.blocks))
        return self.name
