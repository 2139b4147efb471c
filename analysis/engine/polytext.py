"""Polynomial text: msolve's polynomial syntax, read exactly over Q by the project's own tokenizer and
recursive-descent parser (no text is ever evaluated).

:mod:`analysis.engine.ring` (``Ring.from_sympy`` of a string) and :mod:`analysis.engine.io` (whole systems in msolve's
file format, which re-exports :func:`parse_polynomial`, :class:`InputError` and the limits) both build on
this module; it needs only the orderings' field width and the prime check.
"""
from __future__ import annotations

import re
from fractions import Fraction
from math import gcd
from typing import Literal, NamedTuple, Sequence

from .orderings import FIELD_BITS
from .primes import BadPrime, check_prime

Coefficients = dict[tuple[int, ...], Fraction]
"""A polynomial over Q (or GF(p) with integer representatives): exponent vector -> nonzero coefficient."""

MAX_EXPANSION = (1 << 16) - 1
"""Largest power of a sum the parser expands ((x + y)^65535 already has 65,536 terms of 65,535-bit
coefficients); powers of a single term (x^100000) go up to MAX_DEGREE."""

MAX_COEFFICIENT_BITS = 1 << 22
"""Largest coefficient a power may produce (about 1.26 million digits): 9^9^9 would have 370 million."""

MAX_DEGREE = (1 << 31) - 1
"""Largest total degree accepted (the ring's packed keys hold 2^FIELD_BITS - 1; F4's packed divisibility
tests need the top bit of a 32-bit field free); larger exponents are input errors."""

_OPERATORS = r"\s+\-*/^(),#"
MSOLVE_NAME = rf"[^{_OPERATORS}0-9.][^{_OPERATORS}]*"
"""A variable name as msolve reads it (regular expression): no blank, operator, comma or '#', and not
starting with a digit or '.'. Used for files, their tokens and msolve's own output."""
_VARIABLE_NAME = re.compile(MSOLVE_NAME + r"\Z")
_VARIABLE_RULE = ("as msolve reads them: any characters but blanks, the operators + - * / ^ ( ), commas and '#', "
                  "not starting with a digit or '.' (e.g. x1, x_1, x', x[1], a.b)")


_CHUNK = 4000
"""Digits converted at a time: Python refuses int <-> str conversions above 4300 digits by default
(``sys.set_int_max_str_digits``); a file's integers may be longer, and are converted in chunks instead
of lifting that process-wide limit."""


def _int_from_digits(text: str) -> int:
    """The integer written in decimal digits, of any length (above :data:`_CHUNK` digits by FLINT's
    subquadratic conversion: a million digits in 0.08 s, where Python's int() takes 4.5 s)."""
    if len(text) <= _CHUNK:
        return int(text)
    import flint

    return int(flint.fmpz(text))


def _int_to_digits(n: int) -> str:
    """Decimal digits of an integer of any size (with a leading '-' when negative; FLINT above 10^3600:
    a million digits in 0.06 s, where chunked divmod took 11.5 s)."""
    if n < 0:
        return "-" + _int_to_digits(-n)
    if n.bit_length() < 3 * _CHUNK:  # below 10^3600: within the limit
        return str(n)
    import flint

    return str(flint.fmpz(n))


NUMBER = r"(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
"""A number as written in a system file, a parameter value or a definition (regular expression): an
integer, a decimal or scientific notation (``12``, ``1.5``, ``.5``, ``1e300``, ``1.5e-3``), read exactly
(:func:`number_value`: 1e300 is 10^300, 1.5e-3 is 3/2000), never as a float."""
_NUMBER = re.compile(NUMBER + r"\Z")
_DECIMAL = re.compile(r"([0-9]*)(?:\.([0-9]*))?(?:[eE]([+-]?[0-9]+))?\Z")

MAX_EXPONENT10 = MAX_COEFFICIENT_BITS * 3 // 10
"""Largest power of ten scientific notation may write, either way (1,258,291: a coefficient of about
MAX_COEFFICIENT_BITS bits, the cap on a power's coefficient); beyond, the number is refused, not rounded."""

_TOO_FAR = (f"a power of ten beyond 10^{MAX_EXPONENT10} or 10^-{MAX_EXPONENT10} (numbers are read exactly; "
            "the value would have more digits than a coefficient may)")
NUMBER_RULE = ("an integer, a decimal or scientific notation (12, 1.5, 1e300, 1.5e-3), read exactly, or p/q")


def number_value(text: str) -> Fraction | None:
    """The exact value of a number written as :data:`NUMBER` (1e300 -> 10^300, 1.5e-3 -> 3/2000); None
    when its power of ten is beyond :data:`MAX_EXPONENT10` (the caller names the number in its error)."""
    if text.isdigit():
        return Fraction(_int_from_digits(text))
    whole, frac, exp = _DECIMAL.match(text).groups()
    frac = frac or ""
    e = (int(exp) if exp and len(exp.lstrip("+-")) < 12 else 10**12 if exp else 0) - len(frac)
    digits = (whole + frac).lstrip("0") or "0"
    if abs(e) > MAX_EXPONENT10 and digits != "0":
        return None
    n = _int_from_digits(digits)
    return Fraction(n * 10**e) if e >= 0 else Fraction(n, 10**-e)


def read_number(text: str, where: str) -> Fraction:
    """A number's text (:data:`NUMBER`, or p/q of two such numbers) read exactly, else :class:`InputError`
    naming ``where`` and the text (used for ``--param`` values and every other number given as text)."""
    t = text.strip()
    sign = -1 if t[:1] == "-" else 1
    body = t[1:].strip() if t[:1] in "+-" else t
    num, slash, den = body.partition("/")
    num, den = num.strip(), den.strip()
    if not _NUMBER.match(num) or (slash and not _NUMBER.match(den)):
        raise InputError(f"{where}: {text!r} is not a number ({NUMBER_RULE})")
    values = [number_value(num), number_value(den) if slash else Fraction(1)]
    if None in values:
        raise InputError(f"{where}: {text!r}: {_TOO_FAR}")
    if values[1] == 0:
        raise InputError(f"{where}: {text!r}: division by zero")
    return sign * values[0] / values[1]


def _short(n: "int | Fraction") -> str:
    """A number for an error message: as it is, or its size when it is very long."""
    n = Fraction(n)
    digits = len(_int_to_digits(abs(n.numerator)))
    return _fraction_str(n) if digits <= 30 else f"of {digits} digits"


class InputError(ValueError):
    """A polynomial system (file, text or objects) that cannot be read; the message is one line."""

    def __init__(self, message: str):
        super().__init__(" ".join(str(message).split()))


def _where(source: str, line: int | None = None, col: int | None = None) -> str:
    if line is None:
        return source
    if col is None:
        return f"{source}, line {line}"
    return f"{source}, line {line}, column {col}"


def _check_variables(names: Sequence[str], where: str) -> tuple[str, ...]:
    """Validate variable names (identifiers, distinct, at least one) and return them as a tuple."""
    names = tuple(names)
    if not names:
        raise InputError(f"{where}: no variables")
    seen: set[str] = set()
    for v in names:
        if not isinstance(v, str):
            raise InputError(f"{where}: variable names must be strings, got {v!r}")
        if v == "":
            raise InputError(f"{where}: empty variable name (two commas in a row or a trailing comma?)")
        if not _VARIABLE_NAME.match(v):
            if re.fullmatch(r"[0-9][0-9/]*", v):
                raise InputError(f"{where}: variable name {v!r} collides with a number; names are {_VARIABLE_RULE}")
            raise InputError(f"{where}: invalid variable name {v!r}; names are {_VARIABLE_RULE}")
        if v in seen:
            raise InputError(f"{where}: duplicate variable name {v!r}")
        seen.add(v)
    return names


def _check_characteristic(value: object, where: str) -> int:
    """0 or a supported prime (see :func:`analysis.engine.ring.check_prime`), else :class:`InputError`."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{where}: characteristic must be an integer (0 or a prime), got {value!r}")
    if value == 0:
        return 0
    try:
        return check_prime(value)
    except BadPrime as err:
        raise InputError(f"{where}: {err}") from None



# -- exact polynomial arithmetic over Q while parsing ---------------------------------------------

_FIELD = FIELD_BITS + 2
"""Bits per variable in a packed parser monomial: a product of two monomials of degree <= MAX_DEGREE
cannot carry into the next variable's field (the parser checks degrees before multiplying)."""


class _Expr:
    """A polynomial over Q during parsing: integer coefficients over one positive common denominator,
    monomials packed into integers (``_FIELD`` bits per variable), and an upper bound on the degree.

    Integer arithmetic with packed monomials is several times faster than Fractions on exponent tuples,
    which matters for expansions such as ``(x + y + z - 1/3)^20`` and for files with 10^5 terms.
    """

    __slots__ = ("terms", "den", "deg")

    def __init__(self, terms: dict[int, int], den: int = 1, deg: int = 0):
        self.terms = terms
        self.den = den
        self.deg = deg if terms else -1

    def exact_degree(self, nvars: int) -> int:
        mask = (1 << _FIELD) - 1
        self.deg = max((sum((m >> (_FIELD * i)) & mask for i in range(nvars)) for m in self.terms), default=-1)
        return self.deg

    def constant(self) -> Fraction | None:
        """The value of a constant polynomial (0 for the zero polynomial), None if non-constant."""
        if not self.terms:
            return Fraction(0)
        if len(self.terms) == 1 and 0 in self.terms:
            return Fraction(self.terms[0], self.den)
        return None

    def add_into(self, other: "_Expr", sign: int) -> None:
        """self += sign * other, in place (self is always a fresh object owned by the parser)."""
        if not other.terms:
            return
        fb = 1
        if other.den != self.den:
            lcm = self.den * other.den // gcd(self.den, other.den)
            fa, fb = lcm // self.den, lcm // other.den
            if fa != 1:
                self.terms = {m: c * fa for m, c in self.terms.items()}
            self.den = lcm
        t = self.terms
        f = sign * fb
        for m, c in other.terms.items():
            v = t.get(m, 0) + f * c
            if v:
                t[m] = v
            else:
                del t[m]
        self.deg = max(self.deg, other.deg) if t else -1

    def neg(self) -> "_Expr":
        return _Expr({m: -c for m, c in self.terms.items()}, self.den, self.deg)

    def mul(self, other: "_Expr") -> "_Expr":
        a, b = (self, other) if len(self.terms) >= len(other.terms) else (other, self)
        if not b.terms:
            return _Expr({})
        out: dict[int, int] = {}
        if len(b.terms) == 1:
            ((mb, cb),) = b.terms.items()
            out = {ma + mb: ca * cb for ma, ca in a.terms.items()}
        else:
            get = out.get
            for mb, cb in b.terms.items():
                for ma, ca in a.terms.items():
                    m = ma + mb
                    out[m] = get(m, 0) + ca * cb
            out = {m: c for m, c in out.items() if c}
        den = a.den * b.den
        if den > 1:
            g = gcd(den, *out.values())
            if g > 1:
                out = {m: c // g for m, c in out.items()}
                den //= g
        return _Expr(out, den, self.deg + other.deg)

    def div(self, q: Fraction) -> "_Expr":
        n, d = q.numerator, q.denominator
        if n < 0:
            n, d = -n, -d
        terms = self.terms if d == 1 else {m: c * d for m, c in self.terms.items()}
        return _Expr(terms, self.den * n, self.deg)

    def to_coefficients(self, nvars: int) -> Coefficients:
        mask = (1 << _FIELD) - 1
        den = self.den
        return {
            tuple((m >> (_FIELD * i)) & mask for i in range(nvars)): Fraction(c, den) for m, c in self.terms.items()
        }


# -- tokenizer and recursive-descent parser ------------------------------------------------------

def _token_pattern(name: str) -> re.Pattern:
    return re.compile(rf"\s*(?:(?P<num>{NUMBER})|(?P<name>{name})|(?P<op>\*\*|[-+*/^(),])|(?P<bad>\S))")


_TOKEN = _token_pattern(MSOLVE_NAME)
_IDENTIFIER_TOKEN = _token_pattern(r"[A-Za-z_][A-Za-z0-9_]*")
"""Tokens of formats whose names are identifiers (the parametric systems: their names become Python
names in a generated solver); anything else in a name is an unexpected character."""


class _Token(NamedTuple):
    kind: Literal["num", "name", "op", "end"]
    text: str
    line: int
    col: int  # 1-based

    def describe(self) -> str:
        return "end of polynomial" if self.kind == "end" else repr(self.text)


def _tokenize(lines: Sequence[tuple[int, str]], source: str, pattern: re.Pattern = _TOKEN) -> list[_Token]:
    """Tokens of (line number, text with comments removed) pairs."""
    out: list[_Token] = []
    for lineno, text in lines:
        for m in pattern.finditer(text):
            kind = m.lastgroup
            if kind == "bad":
                ch = m.group(kind)
                where = _where(source, lineno, m.start(kind) + 1)
                if ch == "." and out and out[-1].kind == "num" and out[-1].line == lineno:
                    raise InputError(f"{where}: malformed number {out[-1].text + ch!r}; numbers are {NUMBER_RULE}")
                raise InputError(f"{where}: unexpected character {ch!r}")
            token = _Token(kind, m.group(kind), lineno, m.start(kind) + 1)  # type: ignore[arg-type]
            prev = out[-1] if out else None
            if (prev is not None and prev.kind == "num" and prev.line == lineno
                    and prev.col + len(prev.text) == token.col
                    and (kind == "num" or (kind == "name" and token.text[0] in "eE"))):
                product = f"; a product is {prev.text}*{token.text}" if kind == "name" else ""
                raise InputError(f"{_where(source, lineno, prev.col)}: malformed number {prev.text + token.text!r} "
                                 f"(scientific notation is 1e300 or 1.5e-3{product}); numbers are {NUMBER_RULE}")
            out.append(token)
    return out


class _Parser:
    """Recursive descent over one polynomial's tokens, expanding exactly over Q (see :class:`_Expr`).

    Grammar (usual precedence; '^' binds tighter than unary minus and is right-associative)::

        poly   := term (('+' | '-') term)*
        term   := unary (('*' | '/') unary)*
        unary  := ('+' | '-') unary | power
        power  := atom [('^' | '**') unary]
        atom   := INTEGER | VARIABLE | '(' poly ')'
    """

    def __init__(self, tokens: list[_Token], variables: tuple[str, ...], characteristic: int, source: str,
                 kind: str = "variable"):
        self.variables = variables
        self.kind = kind
        self.index = {v: i for i, v in enumerate(variables)}
        self.nvars = len(variables)
        self.p = characteristic
        self.source = source
        last = tokens[-1]
        self.tokens = tokens + [_Token("end", "", last.line, last.col + len(last.text))]
        self.pos = 0

    def fail(self, tok: _Token, message: str) -> InputError:
        return InputError(f"{_where(self.source, tok.line, tok.col)}: {message}")

    def peek(self) -> _Token:
        return self.tokens[self.pos]

    def take(self) -> _Token:
        tok = self.tokens[self.pos]
        self.pos += 1
        return tok

    def parse(self) -> Coefficients:
        poly = self.poly()
        tok = self.peek()
        if tok.kind != "end":
            prev = self.tokens[self.pos - 1]
            if tok.text == ")":
                raise self.fail(tok, "unmatched ')'")
            if tok.kind == "name" and tok.text not in self.index:
                raise self.fail(tok, f"unknown {self.kind} {tok.text!r}; {self.kind}s are {', '.join(self.variables)}")
            if tok.kind in ("num", "name") or tok.text == "(":
                if tok.line > prev.line:
                    hint = f"missing ',' at the end of line {prev.line}?"
                else:
                    hint = "missing '*'?"
                raise self.fail(tok, f"unexpected {tok.describe()} after {prev.describe()} ({hint})")
            raise self.fail(tok, f"unexpected {tok.describe()}")
        return poly.to_coefficients(self.nvars)

    def poly(self) -> _Expr:
        acc = self.term()
        while self.peek().kind == "op" and self.peek().text in ("+", "-"):
            sign = 1 if self.take().text == "+" else -1
            acc.add_into(self.term(), sign)
        return acc

    def term(self) -> _Expr:
        acc = self.unary()
        while self.peek().kind == "op" and self.peek().text in ("*", "/"):
            op = self.take()
            start = self.peek()
            rhs = self.unary()
            if op.text == "*":
                n = self.nvars
                if acc.deg + rhs.deg > MAX_DEGREE and acc.exact_degree(n) + rhs.exact_degree(n) > MAX_DEGREE:
                    raise self.fail(op, f"total degree exceeds the supported maximum {MAX_DEGREE}")
                acc = acc.mul(rhs)
                continue
            d = rhs.constant()
            if d is None:
                raise self.fail(start, "division by a non-constant polynomial (only constants may divide)")
            if d == 0:
                raise self.fail(op, "division by zero")
            if self.p and d.numerator % self.p == 0:
                raise self.fail(op, f"division by {d}, which is zero in characteristic {self.p}")
            acc = acc.div(d)
        return acc

    def unary(self) -> _Expr:
        tok = self.peek()
        if tok.kind == "op" and tok.text in ("+", "-"):
            self.take()
            inner = self.unary()
            return inner if tok.text == "+" else inner.neg()
        return self.power()

    def power(self) -> _Expr:
        base = self.atom()
        op = self.peek()
        if not (op.kind == "op" and op.text in ("^", "**")):
            return base
        self.take()
        start = self.peek()
        if start.kind == "end":
            raise self.fail(start, f"missing exponent after {op.describe()}")
        e = self.unary().constant()
        if e is None:
            raise self.fail(start, "exponent must be a nonnegative integer constant, got a polynomial")
        if e.denominator != 1:
            raise self.fail(start, f"non-integer exponent {_short(e)}")
        if e < 0:
            raise self.fail(start, f"negative exponent {_short(e)}")
        n = int(e)
        if n > MAX_DEGREE or n * max(base.exact_degree(self.nvars), 0) > MAX_DEGREE:
            raise self.fail(start, f"exponent {_short(n)} too large (total degrees are limited to {MAX_DEGREE})")
        if len(base.terms) > 1 and n > MAX_EXPANSION:
            raise self.fail(start, f"exponent {_short(n)} too large for expanding a sum (at most {MAX_EXPANSION})")
        bits = max((abs(c).bit_length() for c in base.terms.values()), default=1) + base.den.bit_length() - 2
        if n * bits > MAX_COEFFICIENT_BITS:  # bits: about log2 of the largest numerator and the denominator
            raise self.fail(start, f"exponent {_short(n)} too large: the coefficient would have about "
                                   f"{n * bits * 3 // 10} digits (at most {MAX_COEFFICIENT_BITS * 3 // 10})")
        if len(base.terms) == 1:  # a term: no expansion needed (the common case x^5 in a file)
            ((m, c),) = base.terms.items()
            return _Expr({m * n: c**n}, base.den**n, base.deg * n)
        out = _Expr({0: 1})
        while n:
            if n & 1:
                out = out.mul(base)
            n >>= 1
            if n:
                base = base.mul(base)
        return out

    def atom(self) -> _Expr:
        tok = self.take()
        if tok.kind == "num":
            value = number_value(tok.text)
            if value is None:
                raise self.fail(tok, f"{tok.text!r}: {_TOO_FAR}")
            if not value:
                return _Expr({})  # the zero polynomial has no terms
            return _Expr({0: value.numerator}, value.denominator)
        if tok.kind == "name":
            i = self.index.get(tok.text)
            if i is None:
                raise self.fail(tok, f"unknown {self.kind} {tok.text!r}; {self.kind}s are {', '.join(self.variables)}")
            return _Expr({1 << (_FIELD * i): 1}, 1, 1)
        if tok.text == "(":
            inner = self.poly()
            close = self.take()
            if close.text != ")" or close.kind != "op":
                raise self.fail(
                    close, f"expected ')' to close '(' at line {tok.line}, column {tok.col}, got {close.describe()}"
                )
            return inner
        if tok.kind == "end":
            raise self.fail(tok, "unexpected end of polynomial (missing operand)")
        raise self.fail(tok, f"unexpected {tok.describe()} (expected a number, a variable or '(')")


# -- fast path: files that are sums of terms ----------------------------------------------------------

_FACTOR = rf"(?>{MSOLVE_NAME})(?:\s*+(?:\^|\*\*)\s*+[0-9]++)?"
_MONOMIAL = rf"{_FACTOR}(?:\s*+\*\s*+{_FACTOR})*+"
_PIECES = re.compile(rf"(,)|([+-]?)\s*+(?:((?>{NUMBER}))(?:\s*+/\s*+([0-9]++))?(?:\s*+\*\s*+({_MONOMIAL}))?"
                     rf"|({_MONOMIAL}))|(\S)")
"""The pieces of a text of sums of terms, in one pass: (comma, sign, numerator, denominator, monomial
after a number, monomial alone, any other character: not a sum of terms)."""
_FACTOR_PARTS = re.compile(rf"({MSOLVE_NAME})(?:\s*(?:\^|\*\*)\s*([0-9]+))?")
_SIMPLE_EXPONENT = len(str(MAX_DEGREE)) - 1
"""Exponents of at most this many digits are below MAX_DEGREE without a check."""


def parse_sums(text: str, variables: Sequence[str], characteristic: int = 0
               ) -> tuple[list[Coefficients], list[int]] | None:
    """The polynomials of comma-separated text when every one is a sum of terms ``[+-] [c[/d]] [*]
    x^k*y...`` (no parentheses, no powers of numbers, no division by a variable): the form CAS and
    generators write, read in one regular-expression pass and one Python step per term (about a million
    terms a second); None for anything else (or any error), which the recursive-descent parser then
    reads (and reports, with line and column). Same result as that parser on every text it accepts
    (tests compare). Returns (polynomials, offset in text of each polynomial's first character)."""
    index = {v: i for i, v in enumerate(variables)}
    nvars = len(variables)
    factors = _FACTOR_PARTS.findall
    keys: dict[str, tuple[int, ...]] = {}  # monomial text -> exponents (files repeat their monomials)
    out: list[Coefficients] = []
    poly: dict[tuple[int, ...], "int | Fraction"] = {}
    terms = 0
    for comma, sign, num, den, mono, bare, bad in _PIECES.findall(text):
        if bad or (comma and not terms) or (not comma and terms and not sign):
            return None  # another character, an empty polynomial, or two terms without an operator
        if comma:
            out.append(poly)
            poly, terms = {}, 0
            continue
        terms += 1
        if num:
            if not num.isdigit():  # a decimal or scientific notation, exactly
                c = number_value(num)
                if c is None or (characteristic and c.denominator % characteristic == 0):
                    return None
            else:
                c = int(num) if len(num) <= _CHUNK else _int_from_digits(num)
            if den:
                d = _int_from_digits(den)
                if d == 0 or (characteristic and d % characteristic == 0):
                    return None
                c = Fraction(c, d)
        else:
            c, mono = 1, bare
        if sign == "-":
            c = -c
        key = keys.get(mono)
        if key is None:
            e = [0] * nvars
            for name, k in factors(mono):
                i = index.get(name)
                if i is None or len(k) > _SIMPLE_EXPONENT:
                    return None
                e[i] += int(k) if k else 1
            if sum(e) > MAX_DEGREE:
                return None
            keys[mono] = key = tuple(e)
        if key in poly:
            v = poly[key] + c
            if v:
                poly[key] = v
            else:
                del poly[key]
        elif c:
            poly[key] = c
    if terms:
        out.append(poly)  # no trailing comma: the last polynomial ends the text
    if not out:
        return None
    starts, offset = [], 0
    for chunk in text.split(",")[:len(out)]:
        starts.append(offset + len(chunk) - len(chunk.lstrip()))
        offset += len(chunk) + 1
    return [{k: Fraction(c) if type(c) is int else c for k, c in f.items()} for f in out], starts


def _strip_comment(text: str) -> str:
    i = text.find("#")
    return text if i < 0 else text[:i]


def _split_polynomials(tokens: list[_Token], source: str) -> list[list[_Token]]:
    """Split at top-level commas; a trailing comma is tolerated, an empty polynomial elsewhere is not."""
    groups: list[list[_Token]] = [[]]
    opened: list[_Token] = []
    for tok in tokens:
        if tok.kind == "op" and tok.text == "(":
            opened.append(tok)
        elif tok.kind == "op" and tok.text == ")" and opened:
            opened.pop()
        elif tok.kind == "op" and tok.text == ",":
            if opened:
                o = opened[-1]
                raise InputError(
                    f"{_where(source, tok.line, tok.col)}: ',' inside parentheses; "
                    f"missing ')' for '(' at line {o.line}, column {o.col}?"
                )
            if not groups[-1]:
                raise InputError(f"{_where(source, tok.line, tok.col)}: empty polynomial before ','")
            groups.append([])
            continue
        groups[-1].append(tok)
    if not groups[-1]:
        groups.pop()
    return groups


def parse_polynomial(
    text: str, variables: Sequence[str], characteristic: int = 0, source: str = "<string>", line: int = 1,
    kind: str = "variable", identifiers: bool = False,
) -> Coefficients:
    """One polynomial in msolve syntax as ``{exponents: Fraction}`` (not reduced mod the characteristic).

    ``line`` is the line number of the text's first line in its source (for error messages); ``kind``
    is the word for the names in the message about an unknown one (e.g. ``"name"`` where parameters
    are read as further variables, :mod:`analysis.formulations.parametric`). ``identifiers``: names are
    identifiers (letters, digits, '_'), not msolve's wider names.
    """
    variables = _check_variables(variables, source)
    p = _check_characteristic(characteristic, source)
    tokens = _tokenize([(line + k, _strip_comment(t)) for k, t in enumerate(text.split("\n"))], source,
                       _IDENTIFIER_TOKEN if identifiers else _TOKEN)
    if not tokens:
        raise InputError(f"{_where(source, line)}: empty polynomial")
    groups = _split_polynomials(tokens, source)
    if len(groups) != 1:
        g = groups[1][0]
        raise InputError(f"{_where(source, g.line, g.col)}: expected one polynomial, found a ',' before it")
    return _Parser(groups[0], variables, p, source, kind).parse()


def _fraction_str(c: Fraction) -> str:
    num = _int_to_digits(c.numerator)
    return num if c.denominator == 1 else f"{num}/{_int_to_digits(c.denominator)}"
