"""Polynomial systems as text: the msolve input format in, msolve / Macaulay2 / Singular text out.

This module owns the boundary between files a user writes and the exact algebra of :mod:`analysis.engine.ring`.
A :class:`System` is the exact, field-independent form of an input file (variable names, characteristic,
polynomials as ``{exponent tuple: Fraction}``); :meth:`System.to_ring` maps it to GF(p) for the engine.

msolve's input format (https://msolve.lip6.fr, README "Input File Format")::

    x, y, z          <- line 1: comma-separated variable names
    0                <- line 2: the characteristic, 0 or a prime p < 2^31
    x^2 + 3/4*y,     <- polynomials separated by commas; a polynomial may span several lines
    (x - y)^3 - z    <- extension: parentheses, '**', comments from '#' to end of line

Every problem with an input raises :class:`InputError` whose message is one line naming the source,
the line (and column) and the problem. Unusual but legal input is kept as written: zero polynomials
(stored as empty dicts, which the engine ignores), constants and duplicate polynomials.

The writers emit scripts for cross-checking elsewhere: ``to_msolve`` (round-trips through
:func:`parse_msolve`), ``to_macaulay2`` (prints ``degree I`` and ``dim I``) and ``to_singular`` (prints
``vdim`` and ``dim`` of a standard basis). Variable names that the target system reserves (``dim``,
``det``, ``ord``, ...) are renamed in its script, with the renaming stated in a comment.
"""
from __future__ import annotations

import re
import sys
from dataclasses import dataclass, field
from fractions import Fraction
from numbers import Integral
from pathlib import Path
from typing import Iterable, Literal, Mapping, Sequence

# the parser and its limits, re-exported: users import them from here
from .polytext import (MAX_COEFFICIENT_BITS, MAX_DEGREE, MAX_EXPANSION, MSOLVE_NAME, _VARIABLE_RULE, Coefficients,
                       InputError, _Parser, _check_characteristic, _check_variables, _fraction_str,
                       _split_polynomials, _strip_comment, _tokenize, _where, parse_polynomial, parse_sums)
from .ring import BadPrime, Poly, Ring

__all__ = [
    "InputError",
    "System",
    "parse_msolve",
    "MSOLVE_NAME",
    "parse_polynomial",
    "read_system",
    "decode_text",
    "read_input_bytes",
    "format_polynomial",
    "to_msolve",
    "to_macaulay2",
    "to_singular",
    "write_system",
    "WRITE_FORMATS",
]

def _symmetric(c: int, p: int) -> int:
    """Representative of c mod p in (-p/2, p/2]: keeps small negative coefficients readable."""
    c %= p
    return c - p if c > p // 2 else c

def _p_degree(a: Coefficients) -> int:
    return max((sum(m) for m in a), default=-1)


def _p_constant(a: Coefficients, nvars: int) -> Fraction | None:
    """The value of a constant polynomial (0 for the zero polynomial), None if non-constant."""
    if not a:
        return Fraction(0)
    if len(a) == 1 and (0,) * nvars in a:
        return a[(0,) * nvars]
    return None


# -- the system ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class System:
    """A polynomial system read from a file: exact coefficients, independent of the prime used later.

    Parameters
    ----------
    variables: distinct variable names (as msolve reads them: see ``_VARIABLE_RULE``).
    characteristic: 0 (coefficients in Q) or a prime 2 <= p < 2^31. For p > 0 the coefficients are
        normalised to integers in (-p/2, p/2].
    polynomials: one ``{exponent tuple: coefficient}`` per polynomial; zero coefficients are dropped, so
        a zero polynomial is an empty dict. Treat them as read-only.
    lines: source line where each polynomial starts (0 when not read from text); provenance only, it
        does not take part in equality.
    source: file name or other label used in error messages; not part of equality either.
    """

    variables: tuple[str, ...]
    characteristic: int
    polynomials: tuple[Coefficients, ...]
    lines: tuple[int, ...] = field(default=(), compare=False)
    source: str = field(default="<system>", compare=False)

    def __post_init__(self) -> None:
        where = self.source
        variables = _check_variables(tuple(self.variables), where)
        p = _check_characteristic(self.characteristic, where)
        polys = tuple(self.polynomials)
        if not polys:
            raise InputError(f"{where}: empty system (no polynomials)")
        lines = tuple(self.lines) or (0,) * len(polys)
        if len(lines) != len(polys):
            raise InputError(f"{where}: {len(lines)} line numbers for {len(polys)} polynomials")
        normalised = tuple(
            _normalise(poly, len(variables), p, _poly_name(i, lines[i], where)) for i, poly in enumerate(polys)
        )
        object.__setattr__(self, "variables", variables)
        object.__setattr__(self, "characteristic", p)
        object.__setattr__(self, "polynomials", normalised)
        object.__setattr__(self, "lines", tuple(int(x) for x in lines))

    @classmethod
    def _normal(cls, variables: tuple[str, ...], polynomials: tuple[Coefficients, ...], lines: tuple[int, ...],
                source: str) -> "System":
        """A characteristic-0 system from checked variables and polynomials already in normal form (tuples
        of nonnegative ints of the right length, nonzero Fractions: :func:`parse_sums`' output), without
        checking each term again (files of 10^6 terms)."""
        if not polynomials:
            raise InputError(f"{source}: empty system (no polynomials)")
        obj = object.__new__(cls)
        for name, value in (("variables", variables), ("characteristic", 0), ("polynomials", polynomials),
                            ("lines", lines), ("source", source)):
            object.__setattr__(obj, name, value)
        return obj

    def __hash__(self) -> int:
        return hash((self.variables, self.characteristic, tuple(frozenset(f.items()) for f in self.polynomials)))

    @property
    def nvars(self) -> int:
        return len(self.variables)

    def degrees(self) -> tuple[int, ...]:
        """Total degree of each polynomial (-1 for a zero polynomial)."""
        return tuple(_p_degree(f) for f in self.polynomials)

    def to_ring(self, prime: int, order: str = "grevlex") -> tuple[Ring, list[Poly]]:
        """The system over GF(prime): the ring and one :class:`Poly` per polynomial (zeros included).

        For characteristic p the prime must be p. For characteristic 0 the coefficients are reduced mod
        prime; a denominator divisible by prime raises :class:`InputError` naming the polynomial, and
        the caller may pick another prime. An unsupported prime raises :class:`analysis.engine.ring.BadPrime`.
        """
        p = self.characteristic
        if p and prime != p:
            raise InputError(f"{self.source}: the system has characteristic {p}; it cannot be read over GF({prime})")
        ring = Ring(self.variables, prime, order)
        polys = []
        for i, f in enumerate(self.polynomials):
            for c in f.values():
                if c.denominator % prime == 0:
                    raise InputError(
                        f"{_poly_name(i, self.lines[i], self.source)}: coefficient {c} has a denominator divisible "
                        f"by the prime {prime}; choose another prime"
                    )
            polys.append(ring.from_terms(f))
        return ring, polys

    def saturated_by(self, f: Coefficients, name: str = "t") -> "System":
        """The Rabinowitsch form of the saturation I : f^infinity: one more variable t and the polynomial
        t*f - 1, so that any CAS reading the file sees exactly the points where f does not vanish.

        ``f`` is in this system's variables; t is appended last (named ``name``, with ``_`` appended
        until it is free), so the original variables keep their positions. Cox-Little-O'Shea, ch. 4 sec. 4.
        """
        if not f:
            raise InputError(f"{self.source}: saturating by the zero polynomial leaves no point")
        while name in self.variables:
            name += "_"
        lift = [{e + (0,): c for e, c in g.items()} for g in self.polynomials]
        inverse = {e + (1,): Fraction(c) for e, c in f.items()}
        inverse[(0,) * (self.nvars + 1)] = inverse.get((0,) * (self.nvars + 1), Fraction(0)) - 1
        return System(self.variables + (name,), self.characteristic, tuple(lift) + (inverse,),
                      self.lines + (0,) if self.lines else (), source=f"{self.source} saturated by {name}*f - 1")

    @classmethod
    def from_polys(cls, ring: Ring, polys: Iterable[Poly], source: str = "<polys>") -> "System":
        """The system of polynomials over GF(ring.prime) (characteristic ring.prime)."""
        polys = list(polys)
        for i, f in enumerate(polys):
            if not isinstance(f, Poly) or f.ring != ring:
                raise InputError(f"{source}: polynomial {i + 1} does not belong to {ring!r}")
        return cls(
            variables=ring.variables,
            characteristic=ring.prime,
            polynomials=tuple({e: Fraction(c) for e, c in f.terms()} for f in polys),
            source=source,
        )

    @classmethod
    def from_sympy(
        cls, exprs: Iterable[object], variables: Sequence[object], characteristic: int = 0, source: str = "<sympy>"
    ) -> "System":
        """The system of sympy expressions (or equations lhs = rhs) with rational coefficients.

        Symbols are matched by name, so assumptions (``real=True`` ...) do not matter; strings are read
        by this module's parser (:func:`parse_polynomial`), never evaluated. Floats, unknown symbols and
        non-polynomial expressions raise :class:`InputError`.
        """
        import sympy

        names = _check_variables(tuple(str(v) for v in variables), source)
        canon = [sympy.Symbol(n) for n in names]
        by_name = dict(zip(names, canon))
        polys = []
        for i, expr in enumerate(exprs):
            what = f"{source}: expression {i + 1}"
            if isinstance(expr, str):
                polys.append(parse_polynomial(expr, names, 0, what))
                continue
            try:
                expr = sympy.sympify(expr, strict=True)  # strict: objects only, a string is never parsed
            except sympy.SympifyError:
                raise InputError(f"{what} is not a sympy expression or polynomial text: {expr!r}") from None
            if isinstance(expr, sympy.Equality):
                expr = expr.lhs - expr.rhs
            if not isinstance(expr, sympy.Expr):
                raise InputError(f"{what} is not a polynomial expression: {expr}")
            if expr.has(sympy.Float):
                raise InputError(f"{what} has a floating-point coefficient; use exact rationals: {expr}")
            unknown = sorted({str(s) for s in expr.free_symbols} - set(names))
            if unknown:
                raise InputError(
                    f"{what}: unknown variable(s) {', '.join(unknown)}; variables are {', '.join(names)}"
                )
            expr = expr.xreplace({s: by_name[str(s)] for s in expr.free_symbols})
            try:
                poly = sympy.Poly(expr, *canon, domain="QQ")
            except (sympy.PolynomialError, sympy.polys.polyerrors.CoercionFailed) as err:
                raise InputError(f"{what} is not a polynomial with rational coefficients: {err}") from None
            terms = {}
            for m, c in poly.terms():
                c = sympy.Rational(c)
                terms[tuple(int(e) for e in m)] = Fraction(int(c.p), int(c.q))
            polys.append(terms)
        return cls(names, characteristic, tuple(polys), source=source)


def _poly_name(i: int, line: int, source: str) -> str:
    return f"{source}: polynomial {i + 1}" + (f" (line {line})" if line else "")


_INT_ONLY = frozenset({int})


def _normalise(poly: Mapping, nvars: int, p: int, name: str) -> Coefficients:
    """Copy a polynomial with validated exponent tuples and Fraction coefficients, zeros dropped."""
    if not isinstance(poly, Mapping):
        raise InputError(f"{name} must be a mapping from exponent tuples to coefficients, got {type(poly).__name__}")
    out: Coefficients = {}
    for m, c in poly.items():
        if not (type(m) is tuple and len(m) == nvars and _INT_ONLY.issuperset(map(type, m)) and (not m or min(m) >= 0)):
            # the slow, general check (exponents of other integral types, lists); the line above is the
            # common case of tuples of ints, checked at C speed (files of 10^6 terms)
            m = tuple(m) if isinstance(m, (tuple, list)) else m
            if (
                not isinstance(m, tuple)
                or len(m) != nvars
                or not all(isinstance(e, Integral) and not isinstance(e, bool) and e >= 0 for e in m)
            ):
                raise InputError(f"{name}: exponent vector {m!r} is not {nvars} nonnegative integers")
            m = tuple(int(e) for e in m)
        if type(c) is not Fraction:
            if isinstance(c, bool) or not isinstance(c, (int, Fraction)):
                raise InputError(f"{name}: coefficient {c!r} of {m} is not an integer or Fraction")
            c = Fraction(c)
        if sum(m) > MAX_DEGREE:
            raise InputError(f"{name}: total degree {sum(m)} exceeds the supported maximum {MAX_DEGREE}")
        if p:
            if c.denominator % p == 0:
                raise InputError(f"{name}: coefficient {c} is undefined in characteristic {p}")
            c = Fraction(_symmetric(c.numerator * pow(c.denominator, -1, p), p))
        if not c:
            continue
        if m not in out:  # the common case: no Fraction addition
            out[m] = c
            continue
        v = out[m] + c
        if p:
            v = Fraction(_symmetric(int(v), p))
        if v:
            out[m] = v
        else:
            del out[m]
    return out


def parse_msolve(text: str, source: str = "<string>") -> System:
    """Parse msolve's input format (see the module docstring) into a :class:`System`.

    Blank lines and ``#`` comments are skipped everywhere, so the variable line is the first line with
    content and the characteristic line the next one. Raises :class:`InputError` (one line, naming
    ``source``, the line and the problem) on any malformed input.
    """
    lines = [(i + 1, _strip_comment(t)) for i, t in enumerate(text.splitlines())]
    content = [(n, t) for n, t in lines if t.strip()]
    if not content:
        raise InputError(f"{source}: missing variable line (the input is empty)")
    var_line, var_text = content[0]
    variables = _check_variables([v.strip() for v in var_text.split(",")], _where(source, var_line))
    if len(content) < 2:
        raise InputError(f"{source}: missing characteristic line after the variable line (line {var_line})")
    char_line, char_text = content[1]
    char_text = char_text.strip()
    if not re.fullmatch(r"[+-]?[0-9]+", char_text):
        raise InputError(
            f"{_where(source, char_line)}: characteristic must be an integer (0 or a prime), got {char_text!r}"
        )
    if len(char_text.lstrip("+-")) > 30:
        raise InputError(f"{_where(source, char_line)}: characteristic of {len(char_text.lstrip('+-'))} digits; it "
                         "must be 0 or a prime below 2^31")
    p = _check_characteristic(int(char_text), _where(source, char_line))

    body = [t for n, t in lines if n > char_line]
    fast = parse_sums("\n".join(body), variables, p)
    if fast is not None:  # sums of terms (most files): no tokens, no recursive descent
        text, starts = "\n".join(body), fast[1]
        numbers, line, at = [], char_line + 1, 0
        for start in starts:
            line += text.count("\n", at, start)
            at = start
            numbers.append(line)
        if p:
            return System(variables, p, tuple(fast[0]), lines=tuple(numbers), source=source)
        return System._normal(variables, tuple(fast[0]), tuple(numbers), source)
    tokens = _tokenize([(n, t) for n, t in lines if n > char_line], source)
    groups = _split_polynomials(tokens, source)
    if not groups:
        raise InputError(f"{source}: empty system (no polynomials after the characteristic line {char_line})")
    polys = tuple(_Parser(g, variables, p, source).parse() for g in groups)
    return System(variables, p, polys, lines=tuple(g[0].line for g in groups), source=source)


def read_input_bytes(path: str, empty_ok: bool = False) -> bytes:
    """The bytes of an input file ('-': standard input), in the same words for the same problem whichever verb
    reads it (a system file here, a measurement CSV in solvers.calibrate_io; the recording reader, solvers.audio,
    says the same): ``cannot read PATH: no such file`` / ``: it is a directory`` / ``: <the system's reason>``,
    and ``PATH: no data (empty file)`` for a file of 0 bytes (unless ``empty_ok``). Raises :class:`InputError`."""
    try:
        if path == "-":
            stream = getattr(sys.stdin, "buffer", None)
            data = stream.read() if stream is not None else sys.stdin.read().encode("utf-8")
        else:
            with open(path, "rb") as handle:
                data = handle.read()
    except FileNotFoundError:
        raise InputError(f"cannot read {path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"cannot read {path}: it is a directory") from None
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    if not data and not empty_ok:
        raise InputError(f"{'stdin' if path == '-' else path}: no data (empty file)")
    return data


def decode_text(data: bytes, source: str) -> str:
    """UTF-8 text of a file's bytes (a UTF-8 byte-order mark is dropped); :class:`InputError` naming the
    source for anything else (UTF-16, binary files)."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise InputError(f"{source}: UTF-16 text; save it as UTF-8 (msolve input is plain text)")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise InputError(f"{source}: not UTF-8 text (byte 0x{data[e.start]:02x} at offset {e.start}); "
                         "msolve input is plain text, save it as UTF-8") from None
    if "\x00" in text:
        raise InputError(f"{source}: binary file (NUL byte at offset {text.index(chr(0))}); msolve input is plain text")
    return text


def read_system(path: "str | Path") -> System:
    """Read a system from a file in msolve's input format (see :func:`parse_msolve`)."""
    return parse_msolve(decode_text(read_input_bytes(str(path)), str(path)), source=str(path))


# -- writers -------------------------------------------------------------------------------------

def _grevlex_key(m: tuple[int, ...]) -> tuple:
    return (sum(m), tuple(-e for e in reversed(m)))


def format_polynomial(poly: Mapping[tuple[int, ...], Fraction], variables: Sequence[str], spaced: bool = True,
                      key=_grevlex_key) -> str:
    """``x^2*y - 3/4*x + 1``: terms in decreasing order (grevlex, or of ``key``: exponents -> sort key),
    explicit '*' and '^', rationals as a/b."""
    if not poly:
        return "0"
    plus, minus = (" + ", " - ") if spaced else ("+", "-")
    out = []
    for k, m in enumerate(sorted(poly, key=key, reverse=True)):
        c = Fraction(poly[m])
        mono = "*".join(v if e == 1 else f"{v}^{e}" for v, e in zip(variables, m) if e)
        a = abs(c)
        if not mono:
            term = _fraction_str(a)
        elif a == 1:
            term = mono
        else:
            term = f"{_fraction_str(a)}*{mono}"
        if k == 0:
            out.append(("-" if c < 0 else "") + term)
        else:
            out.append((minus if c < 0 else plus) + term)
    return "".join(out)


def to_msolve(system: System) -> str:
    """msolve input text: variables, characteristic, one expanded polynomial per line.

    The output uses only what msolve's own reader understands (no parentheses, spaces or comments;
    integer coefficients for characteristic p). A zero polynomial is written as ``0``.
    """
    body = ",\n".join(format_polynomial(f, system.variables, spaced=False) for f in system.polynomials)
    return f"{','.join(system.variables)}\n{system.characteristic}\n{body}\n"


# Names a target system will not accept as ring variables (it reserves them, or they are protected
# globals). Singular 4.3.1: reservedNameList() plus names(Top) of a fresh session. Macaulay2 1.21:
# protected symbols of Core and the preloaded packages with at most 6 characters or a digit; longer
# all-letter names are renamed for Macaulay2 regardless, since its list of protected names is long.
_SINGULAR_RESERVED = frozenset(
    """
ASSUME ERROR Float GCD IN L LIB NF QQ RETURN Standard TRACE Top ZZ alias align and apply attrib
bareiss betti bigint bigintmat bracket branchTo break breakpoint char char_series charstr
chinrem cleardenom close coef coeffs continue contract convhull create_ring cring crossprod
datetime dbprint def defined deg degBound degree delete denominator det diff dim div division
dump echo eliminate else envelope eval example execute exit export exportto extgcd facstd
factmodd factorize farey fetch fglm fglmquot find finduni for forif fprintf freemodule fres
frwalk gcd gen getdump groebner help highcorner hilb hilbRing homog hres ideal if imap impart
importfrom indepSet insert int interpolation interred intersect intmat intvec jacob janet jet
kbase keepring kernel kill killattrib koszul kres laguerre lead leadcoef leadexp leadmonom lift
liftstd link list listvar load lres ludecomp luinverse lusolve map matrix max maxideal memory
min minbase minor minpoly minres mod module modulo monitor monomial mpresmat mres mstd mult
multBound multiplicity nameof names nc_algebra ncalgebra ncols newline newstruct noether not
npars nres nrows number numerator nvars open oppose opposite option or ord ordstr package
pagewidth par par2varRing parameter pardeg parstr pause poly polyBucket preimage prime
primefactors print printf printlevel proc prune pyobject qhweight qrds qring qslimgb quit quot
quote quotient quotient1 quotient2 quotient3 quotient4 quotient5 quotientList random rank read
reduce regularity repart res reservedName reservedNameList resolution restart resultant return
rightstd ring ring_list ringlist rtimer rvar sba setring short simplex simplify size slimgb
smatrix sortvec sprintf sqrfree sres status std stdfglm stdhilb string subst system syz tensor
test timer trace transpose twostd type typeof univariate uressolve vandermonde var variables
varstr vdim vector verbose voice waitall waitfirst wedge weight weightKB while whileif write
""".split()
)
_M2_PROTECTED = frozenset(
    """
Array BKZ Bag Bayer Beta Binary Body Boxes CC Caveat Center Date Degree Dense Divide Down Email
End Engine Ext Fano File First Format GF GLex GTZ Gamma Givens Global HH Heft Height Holder Hom
Homogeneous2 Hybrid Ideal Index Inputs Join Keep Key LLL Layout Left Lex Limit Linear List Local
Matrix Minus Module Monoid NCLex NTL Name Net Number OO Option Order POSIX Power Prefix Print
Proj Prune QQ RR RRi RadicalCodim1 Range RealFP RealQP RealQP1 RealRR RealXD Reduce Reload
Result RevLex Right Ring SPACE SVD Set Sort Spec Strict String Sum Symbol TEST Table Tally Task
Test Thing Time Tor Toric Tries Trim Type URL Undo Unique Up Usage Vector Verify WebApp Wrap ZZ
about abs acos acosh acot acoth agm alarm all and ann any append apply arXiv ascii asin asinh
ass assert atan atan2 atanh basis betti borel break cache catch char check chi class clean close
code codim coker cone copy cos cosh cot coth cover csc csch dd debug degree delete demark depth
det diff dim do doc drop dual echoOn edit eint else end endl erase erf erfc error euler eulers
even exec exit exp expm1 export extend factor false first flip floor flush fold for fork format
fpLLL frac frames from gb gcd gcdLLL genera gens genus get getWWW getc getenv global gramm hash
heft height help hh hold hooks html icMap id ideal if ii image in index info input insert isLLL
isOpen isReal isRing isUnit isc join ker kernel keys kill koszul last lcm left length lift lines
list load local locate log log1p lookup makeS2 map match mathML matrix max member merge method
min mingle minors minus mkdir mod module modulo monoid needs net new next norm not null number
odd oeis of on openIn or order pack pad pager pairs parent part parts pdim peek pi pivots plus
poly power pretty print prune quit random rank read regex remove res return right ring roots
rotate round rowAdd rsort run same scan sec sech select set setup sheaf shield show sin sinh
size size2 sleep solve sort source span splice sqrt stack status stderr stdio step sub sum super
switch symbol syz table take tally tan tanh target tensor terms tests tex then throw time times
timing to toCC toDual toList toRR toRRi top trace trim true try unbag unique use utf8 utf8check
utf8substring value values vars vector wait when while width wrap xor zero zeta
""".split()
)


def _singular_ok(name: str) -> bool:
    return re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", name) is not None and name not in _SINGULAR_RESERVED


def _identifier(name: str, keep: str = "") -> str:
    """The letters and digits of a name (and the characters in ``keep``), from its first letter on."""
    return re.sub(r"^[^A-Za-z]+", "", "".join(ch for ch in name if ch.isascii() and (ch.isalnum() or ch in keep)))


def _m2_ok(name: str) -> bool:
    return (
        re.fullmatch(r"[A-Za-z][A-Za-z0-9]*", name) is not None
        and name not in _M2_PROTECTED
        and (len(name) <= 6 or any(ch.isdigit() for ch in name))
    )


def _rename(variables: Sequence[str], ok, clean=lambda s: s) -> dict[str, str]:
    """Map each variable to a name the target accepts: unchanged when possible, else a fresh variant."""
    taken = {v for v in variables if ok(v)}
    out = {}
    for v in variables:
        if ok(v):
            out[v] = v
            continue
        base = clean(v) or "v"
        k, cand = 0, base
        while not ok(cand) or cand in taken:
            cand = f"{base}{k}"
            k += 1
        taken.add(cand)
        out[v] = cand
    return out


def _fresh(base: str, taken: set[str], ok) -> str:
    cand, k = base, 0
    while cand in taken or not ok(cand):
        cand = f"{base}{k}"
        k += 1
    return cand


def _one_line(text: str) -> str:
    return " ".join(text.split())


def _renaming_note(names: dict[str, str], comment: str, target: str) -> list[str]:
    renamed = [f"{a} -> {b}" for a, b in names.items() if a != b]
    return [f"{comment} variables renamed for {target}: {', '.join(renamed)}"] if renamed else []


def to_macaulay2(system: System) -> str:
    """A Macaulay2 script: the ring (GRevLex), the ideal, then ``print degree I; print dim I``."""
    names = _rename(system.variables, _m2_ok, clean=_identifier)
    new = list(names.values())
    ring = _fresh("R", set(new), _m2_ok)
    ideal = _fresh("I", set(new) | {ring}, _m2_ok)
    field = f"ZZ/{system.characteristic}" if system.characteristic else "QQ"
    gens = []
    for f in system.polynomials:
        s = format_polynomial(f, new)
        # an all-constant list would make an ideal of ZZ or QQ, not of the ring
        gens.append(f"promote({s}, {ring})" if _p_constant(f, system.nvars) is not None else s)
    lines = [f"-- generated by analysis.engine.io from {_one_line(system.source)}"]
    lines += _renaming_note(names, "--", "Macaulay2")
    lines.append(f"{ring} = {field}[{', '.join(new)}, MonomialOrder => GRevLex];")
    lines.append(f"{ideal} = ideal(")
    lines.append(",\n".join(f"    {g}" for g in gens))
    lines.append(");")
    lines.append(f"print degree {ideal}; print dim {ideal}")
    return "\n".join(lines) + "\n"


def to_singular(system: System) -> str:
    """A Singular script: ``ring r = p,(x,y),dp;`` the ideal, ``std``, then ``vdim`` and ``dim``."""
    names = _rename(system.variables, _singular_ok, clean=lambda v: _identifier(v, "_"))
    new = list(names.values())
    taken = set(new)
    r = _fresh("r", taken, _singular_ok)
    i = _fresh("i", taken | {r}, _singular_ok)
    g = _fresh("g", taken | {r, i}, _singular_ok)
    gens = [format_polynomial(f, new) for f in system.polynomials]
    lines = [f"// generated by analysis.engine.io from {_one_line(system.source)}"]
    lines += _renaming_note(names, "//", "Singular")
    lines.append(f"ring {r} = {system.characteristic},({','.join(new)}),dp;")
    lines.append(f"ideal {i} =")
    lines.append(",\n".join(f"  {s}" for s in gens) + ";")
    lines.append(f"ideal {g} = std({i});")
    lines.append(f"print(vdim({g}));")
    lines.append(f"print(dim({g}));")
    lines.append("quit;")
    return "\n".join(lines) + "\n"


WRITE_FORMATS = {"msolve": to_msolve, "m2": to_macaulay2, "singular": to_singular}
"""Formats accepted by :func:`write_system`."""


def write_system(system: System, path: "str | Path", fmt: Literal["msolve", "m2", "singular"] = "msolve") -> Path:
    """Write the system as msolve input, a Macaulay2 script or a Singular script; returns the path."""
    writer = WRITE_FORMATS.get(fmt)
    if writer is None:
        raise ValueError(f"unknown format {fmt!r}; valid formats: {', '.join(WRITE_FORMATS)}")
    path = Path(path)
    path.write_text(writer(system), encoding="utf-8")
    return path
