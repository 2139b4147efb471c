"""Parametric polynomial systems: equations in unknowns whose coefficients are polynomials in parameters.

A :class:`ParametricSystem` is the input of the general solver generator (``solvers.methods``): the
unknowns x, the parameters q (the data of one instance, e.g. the TDOA measurements f_ij), the
equations f(x; q) = 0, optional non-vanishing conditions (the ideal is saturated by their product, so
roots on which they vanish are not counted), and an optional group of sign changes of the unknowns
that maps roots to roots for every q.

This module is exact algebra: it builds the system from a TDOA formulation or from a user's text file,
specialises it over GF(p) at given parameter values and counts its roots there (two primes and
several parameter points must agree; analysis.engine.degree). It imports nothing from ``solvers``.

Text format (``parse``)::

    # comment
    unknowns: x, y
    parameters: a, b      (a file without parameters is a plain system: analysis.formulations.systemfile)
    nonzero: x            (optional; products and several entries allowed)
    equations:
    x^2 + y^2 - a
    x*y - b

One equation per line (or separated by ';'); ``^`` or ``**`` for powers; rational coefficients
(``3/4*x``; '/' only by constants); parentheses. The file is data: it is read by the project's own
polynomial parser (the one behind the msolve format, :mod:`analysis.engine.io`), parameters and definitions
as further variables, and nothing in it is evaluated.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Callable, Sequence

import numpy as np
import sympy

from ..engine.degree import DEFAULT_PRIMES, DegreeReport, PrimeDisagreement, analyse
from ..engine.io import InputError, parse_polynomial
from ..engine.quotient import saturated_degree
from ..engine.ring import Poly, Ring
from .sections import ParametricError, check_names, sections

__all__ = ["ParametricSystem", "ParametricError", "GFSample", "parse", "from_formulation"]


#: (parameter values mod p, a known root mod p or None) for one prime and one seed.
GFSample = tuple[list[int], "list[int] | None"]

@dataclass(frozen=True)
class ParametricSystem:
    """Equations f(x; q) = 0 in ``unknowns`` x with coefficients polynomial in ``parameters`` q.

    equations / nonzero: polynomial text in the syntax of :func:`analysis.engine.io.parse_polynomial` (kept
    as text so a system is plain data; read by the project's parser, never evaluated; the sympy
    forms built from the parse are cached). symmetry: sign vectors (tuples of +-1, one per unknown), the non-identity
    elements of a group acting on the roots of every instance. gf_sampler: optional
    ``(p, seed) -> (q mod p, root mod p)``; without it, parameters are drawn at random (only sound
    for square systems, whose generic instance has roots). scale_powers: optional weights w_k such
    that scaling the parameters by t scales unknown k by t^w_k (used to normalise data).
    definitions: optional auxiliary names ``(name, expression)`` defined from the parameters (and
    earlier definitions) that the equations may use: a factored form keeps coefficients short and
    accurate in floating point (e.g. differences of measurements), the GF(p) counts substitute them.
    unused: parameters declared on purpose although no equation uses them (a formulation that leaves a
    measurement out, e.g. 3D TOA 5r/5s's f5_5: its solver still takes the whole data matrix).
    """

    name: str
    unknowns: tuple[str, ...]
    parameters: tuple[str, ...]
    equations: tuple[str, ...]
    nonzero: tuple[str, ...] = ()
    symmetry: tuple[tuple[int, ...], ...] = ()
    scale_powers: tuple[float, ...] | None = None
    definitions: tuple[tuple[str, str], ...] = ()
    unused: tuple[str, ...] = ()
    gf_sampler: Callable[[int, int], GFSample] | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        check_names(self.name, "unknown", self.unknowns)
        check_names(self.name, "parameter", self.parameters)
        clash = set(self.unknowns) & set(self.parameters)
        if clash:
            raise ParametricError(f"{self.name}: {sorted(clash)} declared both as unknown and parameter")
        if len(set(self.unknowns)) != len(self.unknowns) or len(set(self.parameters)) != len(self.parameters):
            raise ParametricError(f"{self.name}: a name is declared twice")
        if not self.unknowns:
            raise ParametricError(f"{self.name}: no unknowns")
        if not self.equations:
            raise ParametricError(f"{self.name}: no equations")
        for g in self.symmetry:
            if len(g) != len(self.unknowns) or any(v not in (1, -1) for v in g):
                raise ParametricError(f"{self.name}: symmetry {g} is not a sign vector on the {len(self.unknowns)} unknowns")
        if self.scale_powers is not None and len(self.scale_powers) != len(self.unknowns):
            raise ParametricError(f"{self.name}: scale_powers needs one weight per unknown")

    # ---------------------------------------------------------------------------------------------
    # symbolic forms
    # ---------------------------------------------------------------------------------------------

    @cached_property
    def aux_symbols(self) -> tuple[sympy.Symbol, ...]:
        return tuple(sympy.Symbol(name) for name, _ in self.definitions)

    @cached_property
    def aux_exprs(self) -> tuple[sympy.Expr, ...]:
        """The definitions, each in the parameters and earlier definitions."""
        out = []
        for k, (name, text) in enumerate(self.definitions):
            expr = self._parse_expr(text, f"definition {name}", aux=k)
            if expr.free_symbols & set(self.x_symbols):
                raise ParametricError(f"{self.name}: definition {name} uses an unknown")
            out.append(expr)
        return tuple(out)

    @cached_property
    def aux_degrees(self) -> dict[sympy.Symbol, int]:
        """Degree in the parameters of every definition."""
        deg: dict[sympy.Symbol, int] = {q: 1 for q in self.q_symbols}
        for sym, expr in zip(self.aux_symbols, self.aux_exprs):
            deg[sym] = _weighted_degree(expr, deg)
        return deg

    @cached_property
    def x_symbols(self) -> tuple[sympy.Symbol, ...]:
        return tuple(sympy.Symbol(v) for v in self.unknowns)

    @cached_property
    def q_symbols(self) -> tuple[sympy.Symbol, ...]:
        return tuple(sympy.Symbol(v) for v in self.parameters)

    def _parse_expr(self, text: str, what: str, aux: int | None = None, where: tuple[int, int] | None = None) -> sympy.Expr:
        """One polynomial of the system, read by the project's parser (:func:`analysis.engine.io.parse_polynomial`).

        Unknowns, parameters and the usable definitions are all variables of the parser; its exact
        expansion becomes a sympy expression built from symbols and rationals (no text is evaluated).
        where: (line, column) of the text in its file, for the error message.
        """
        usable = self.aux_symbols if aux is None else self.aux_symbols[:aux]
        symbols = self.x_symbols + self.q_symbols + usable
        line, col = where or (1, 1)
        try:
            terms = parse_polynomial(" " * (col - 1) + text, [s.name for s in symbols], 0,
                                     self.name if where else f"{self.name}: {what}", line, kind="name",
                                     identifiers=True)
        except InputError as exc:
            raise ParametricError(f"{exc} (in {what}; a polynomial with rational coefficients is expected)") from None
        return _as_expr(terms, symbols)

    @cached_property
    def exprs(self) -> tuple[sympy.Expr, ...]:
        return tuple(self._parse_expr(e, f"equation {k + 1}") for k, e in enumerate(self.equations))

    @cached_property
    def nonzero_exprs(self) -> tuple[sympy.Expr, ...]:
        return tuple(self._parse_expr(e, "nonzero condition") for e in self.nonzero)

    @cached_property
    def terms(self) -> tuple[tuple[tuple[tuple[int, ...], sympy.Expr], ...], ...]:
        """Per equation: its terms (exponents in the unknowns, coefficient as an expression in q).

        Sorted by exponent (deterministic); equations without any unknown are an error (they would
        constrain the data, not the roots).
        """
        out = []
        for k, expr in enumerate(self.exprs):
            poly = sympy.Poly(expr, *self.x_symbols)
            terms = tuple(sorted(poly.terms(), key=lambda t: t[0]))
            if not terms or all(sum(m) == 0 for m, _ in terms):
                raise ParametricError(f"{self.name}: equation {k + 1} does not involve the unknowns")
            out.append(terms)
        return tuple(out)

    @cached_property
    def coefficient_degrees(self) -> tuple[int, ...]:
        """Degree in the parameters of every term's coefficient (terms in equation order)."""
        return tuple(_weighted_degree(c, self.aux_degrees) for eq in self.terms for _, c in eq)

    def check_parameters_occur(self) -> None:
        """Raise unless every declared parameter occurs in some coefficient."""
        used: set[str] = set()
        for eq in self.terms:
            for _, c in eq:
                used |= {s.name for s in c.free_symbols}
        for sym, expr in zip(reversed(self.aux_symbols), reversed(self.aux_exprs)):
            if sym.name in used:
                used |= {s.name for s in expr.free_symbols}
        missing = [q for q in self.parameters if q not in used and q not in self.unused]
        if missing:
            raise ParametricError(f"{self.name}: parameters {missing} do not occur in the equations")
        if not self.parameters:
            raise ParametricError(f"{self.name}: no parameters: a solver needs data to vary")

    @cached_property
    def _gf_coefficients(self):
        """Per equation and term: (exponent, [(exponents in q + aux, rational coefficient), ...])."""
        gens = self.q_symbols + self.aux_symbols or (sympy.Symbol("_dummy"),)
        out = []
        for eq in self.terms:
            row = []
            for mon, c in eq:
                cp = sympy.Poly(c, *gens)
                row.append((mon, [(e, sympy.Rational(v)) for e, v in cp.terms()]))
            out.append(row)
        return out

    @cached_property
    def _gf_definitions(self):
        out = []
        for k, expr in enumerate(self.aux_exprs):
            gens = self.q_symbols + self.aux_symbols[:k] or (sympy.Symbol("_dummy"),)
            out.append([(e, sympy.Rational(v)) for e, v in sympy.Poly(expr, *gens).terms()])
        return out

    # ---------------------------------------------------------------------------------------------
    # GF(p)
    # ---------------------------------------------------------------------------------------------

    def ring(self, p: int) -> Ring:
        return Ring(list(self.unknowns), p)

    def gf_polys(self, q: Sequence[int], p: int) -> list[Poly]:
        """The system over GF(p) at parameter values q (integers mod p)."""
        R = self.ring(p)
        qv = [int(v) % p for v in q]
        if len(qv) != len(self.parameters):
            raise ParametricError(f"{self.name}: {len(self.parameters)} parameter values needed, got {len(qv)}")
        for cterms in self._gf_definitions:
            qv.append(_gf_value(cterms, qv, p))
        polys = []
        for row in self._gf_coefficients:
            terms = {mon: v for mon, cterms in row if (v := _gf_value(cterms, qv, p))}
            polys.append(R.from_terms(terms))
        return polys

    def gf_nonzero(self, q: Sequence[int], p: int) -> Poly | None:
        """The product of the non-vanishing conditions over GF(p) at q, or None."""
        if not self.nonzero:
            return None
        sub = ParametricSystem(self.name, self.unknowns, self.parameters, self.nonzero, definitions=self.definitions)
        out = None
        for f in sub.gf_polys(q, p):
            out = f if out is None else out * f
        return out

    def sample_gf(self, p: int, seed: int) -> GFSample:
        """Parameter values mod p (and a known root when the sampler gives one) for one seed."""
        if self.gf_sampler is not None:
            return self.gf_sampler(p, seed)
        rng = np.random.default_rng(seed)
        return [int(v) for v in rng.integers(1, p, size=len(self.parameters))], None

    def degree(self, primes: Sequence[int] = DEFAULT_PRIMES, seeds: Sequence[int] = (0, 1), **kwargs) -> DegreeReport:
        """Number of roots at generic parameters, over every prime and seed (all must agree).

        The known root of each sample (if the sampler gives one) must satisfy the system. With
        non-vanishing conditions the ideal is saturated by their product. Raises
        :class:`PrimeDisagreement` when primes or seeds disagree.
        """
        reports = []
        for seed in seeds:
            cache: dict[int, GFSample] = {}

            def sample(p: int) -> GFSample:
                if p not in cache:
                    cache[p] = self.sample_gf(p, seed)
                return cache[p]

            def system(p: int) -> list[Poly]:
                q, root = sample(p)
                polys = self.gf_polys(q, p)
                if root is not None:
                    bad = [k + 1 for k, f in enumerate(polys) if f.evaluate(root) % p]
                    if bad:
                        raise ParametricError(f"{self.name}: the known root of seed {seed} mod {p} fails equations {bad}")
                return polys

            report = analyse(system, primes, **kwargs)
            if self.nonzero:
                report = self._saturated(report, sample, system, primes, kwargs)
            reports.append(report)
        first = reports[0]
        for seed, r in zip(seeds[1:], reports[1:]):
            if (r.degree, r.dimension) != (first.degree, first.dimension):
                raise PrimeDisagreement(f"{self.name}: seeds disagree (seed {seeds[0]}: degree {first.degree}, "
                                        f"seed {seed}: degree {r.degree}); a non-generic instance?")
        return first

    def _saturated(self, report: DegreeReport, sample, system, primes, kwargs) -> DegreeReport:
        """The report of I : (product of the nonzero conditions)^inf.

        Zero-dimensional I: the rank of a high power of the condition's action matrix on the standard
        monomials (cheap; analysis.engine.quotient.saturated_degree); otherwise the Rabinowitsch trick.
        """
        if report.zero_dimensional:
            sats = {r.prime: saturated_degree(r.gb, self.gf_nonzero(sample(r.prime)[0], r.prime)) for r in report.per_prime}
            if len(set(sats.values())) != 1:
                raise PrimeDisagreement(f"{self.name}: primes disagree on the saturated degree {sats}")
            return replace(report, degree=next(iter(sats.values())))
        return analyse(system, primes, saturate_by=lambda p: self.gf_nonzero(sample(p)[0], p), **kwargs)

    # ---------------------------------------------------------------------------------------------
    # shape
    # ---------------------------------------------------------------------------------------------

    @property
    def is_square(self) -> bool:
        return len(self.equations) == len(self.unknowns)

    def text(self) -> str:
        """The system in the text format read by :func:`parse`."""
        lines = [f"# {self.name}", "unknowns: " + ", ".join(self.unknowns), "parameters: " + ", ".join(self.parameters)]
        if self.nonzero:
            lines.append("nonzero: " + ", ".join(self.nonzero))
        lines.append("equations:")
        lines.extend(self.equations)
        return "\n".join(lines) + "\n"


def _as_expr(terms, symbols: Sequence[sympy.Symbol]) -> sympy.Expr:
    """The sympy expression of a parsed polynomial ``{exponents: Fraction}`` in ``symbols``."""
    out = []
    for exps, c in terms.items():  # Add and Mul put the terms in sympy's canonical order
        factors = [sympy.Rational(c.numerator, c.denominator)]
        factors += [s**k if k > 1 else s for s, k in zip(symbols, exps) if k]
        out.append(sympy.Mul(*factors))
    return sympy.Add(*out)


def _weighted_degree(expr: sympy.Expr, weights: dict) -> int:
    """Degree of a polynomial expression when symbol s has degree weights[s] (others 0)."""
    syms = [s for s in expr.free_symbols if weights.get(s)]
    if not syms:
        return 0
    return max(sum(e * weights[g] for e, g in zip(mon, syms)) for mon in sympy.Poly(expr, *syms).monoms())


def _gf_value(cterms, values: Sequence[int], p: int) -> int:
    """A polynomial given as [(exponents, rational)] evaluated mod p at ``values``."""
    val = 0
    for e, r in cterms:
        t = r.p % p * pow(r.q % p, -1, p) % p
        for qi, ei in zip(values, e):
            if ei:
                t = t * pow(qi, ei, p) % p
        val = (val + t) % p
    return val


def parse(text: str, name: str = "<system>") -> ParametricSystem:
    """Read a parametric system from the text format of the module docstring.

    The text is data: names are checked, every polynomial is read by the project's parser
    (:func:`analysis.engine.io.parse_polynomial`, parameters as further variables) and nothing is evaluated.
    Errors are :class:`ParametricError` naming ``name``, the line and the column.
    """
    fields = sections(text, name)
    texts = {k: tuple(item for item, _, _ in v) for k, v in fields.items()}
    system = ParametricSystem(name, texts["unknowns"], texts.get("parameters", ()), texts["equations"],
                              texts.get("nonzero", ()))
    # read every polynomial now, so that errors name the line and column in the file
    system.__dict__["exprs"] = tuple(system._parse_expr(t, f"equation {k + 1}", where=(ln, col))
                                     for k, (t, ln, col) in enumerate(fields["equations"]))
    system.__dict__["nonzero_exprs"] = tuple(system._parse_expr(t, "nonzero condition", where=(ln, col))
                                             for t, ln, col in fields.get("nonzero", ()))
    return system


def from_formulation(formulation, saturate_det_h: bool = False) -> ParametricSystem:
    """The TDOA formulation (paper Sections 2-3; unknowns h, b, o) as a parametric system in the f_ij.

    Equations A and B carry the factor det H, whose vanishing gives spurious roots; with
    ``saturate_det_h`` (what a solver wants) det H != 0 is a non-vanishing condition and the count
    drops them; without it the count is the paper's |B| as generated (Tables 2-3). The
    sampler draws consistent networks over GF(p) (analysis.formulations.tdoa.sample_gf_instance).
    """
    from .tdoa import as_formulation, data_symbols, definition_order, factored_equations, sample_gf_instance

    formulation = as_formulation(formulation)
    config = formulation.config
    if not config.is_planar_tdoa:
        return _from_formulation_kd(formulation, saturate_det_h)
    polys, defs = factored_equations(formulation)
    params = tuple(s.name for row in data_symbols(config) for s in row)
    definitions = tuple((s.name, sympy.sstr(defs[s])) for s in definition_order(defs))
    powers = tuple(-2.0 if u.startswith("h") else 0.0 if u.startswith("b") else 1.0 for u in config.unknowns)

    def sampler(p: int, seed: int) -> GFSample:
        inst = sample_gf_instance(config, p, seed)
        return [int(v) for row in inst.F for v in row], [int(v) for v in inst.root]

    return ParametricSystem(formulation.label, tuple(config.unknowns), params,
                            tuple(sympy.sstr(p.as_expr()) for p in polys),
                            nonzero=("h11*h22 - h12**2",) if saturate_det_h else (),
                            scale_powers=powers, definitions=definitions, gf_sampler=sampler)


def _from_formulation_kd(formulation, saturate_det_h: bool) -> ParametricSystem:
    """Any other configuration (TOA, 3D, the direct parametrization) as a parametric system in the f_ij:
    :func:`analysis.formulations.kd.formulas` written on sympy symbols.

    Definitions (data only): e<i>_<j> = f_ij - f_1j, p<i>_<j> = f_ij + f_1j, c<i>_<j> the constant part
    of D~_ij; for TOA with B_j, j >= K + 2, also dm = det M, M = D~[:K, :K], and u<j>_<a> = (adj(M)
    D~[:K, j-1])_a (B_j multiplied by dm^2: polynomial in the data, the same roots). 3D TDOA's det M
    depends on the offsets and is a further non-vanishing condition. The sampler is
    analysis.formulations.tdoa.sample_gf_instance (known root checked by every count).
    """
    from .tdoa import data_symbols, sample_gf_instance, unknown_symbols
    from .kd import formulas

    config = formulation.config
    x = dict(zip(config.unknowns, unknown_symbols(config)))
    f = data_symbols(config)
    defs: dict[str, sympy.Expr] = {}

    def define(name: str, expr) -> sympy.Symbol:
        defs[name] = sympy.expand(expr)
        return sympy.Symbol(name)

    out, nonzero = formulas(formulation, x, f, sympy.Integer(0), sympy.Rational(1, 4), define)
    nonzero = [sympy.expand(g) for g in nonzero]
    if config.parametrization == "direct":
        powers = tuple(1.0 for _ in config.unknowns)
    elif config.parametrization == "gram":  # G scales as the squared distances, the coordinates a_i not at all
        if saturate_det_h:
            k = config.dim
            G = sympy.Matrix(k, k, lambda a, c: x[f"g{min(a, c) + 1}{max(a, c) + 1}"])
            nonzero.insert(0, sympy.expand(G.det()))
        powers = tuple(2.0 if u.startswith("g") else 0.0 for u in config.unknowns)
    else:
        if saturate_det_h:
            k = config.dim
            H = sympy.Matrix(k, k, lambda a, c: x[f"h{min(a, c) + 1}{max(a, c) + 1}"])
            nonzero.insert(0, sympy.expand(H.det()))
        powers = tuple(-2.0 if u.startswith("h") else 0.0 if u.startswith("b") else 1.0 for u in config.unknowns)
    unknowns = tuple(x.values())
    polys = [sympy.Poly(sympy.expand(expr), *unknowns).as_expr() for expr in out]
    used = {v.name for g in polys + nonzero for v in g.free_symbols}  # sympy expressions, never text
    for name in reversed(list(defs)):  # keep the definitions the equations use, and what those use
        if name in used:
            used |= {v.name for v in defs[name].free_symbols}
    params = tuple(s.name for row in f for s in row)

    def sampler(p: int, seed: int) -> GFSample:
        inst = sample_gf_instance(config, p, seed)
        return [int(v) for row in inst.F for v in row], [int(v) for v in inst.root]

    return ParametricSystem(formulation.label, tuple(config.unknowns), params, tuple(sympy.sstr(g) for g in polys),
                            nonzero=tuple(sympy.sstr(g) for g in nonzero), scale_powers=powers,
                            definitions=tuple((k_, sympy.sstr(v)) for k_, v in defs.items() if k_ in used),
                            unused=tuple(q for q in params if q not in used), gf_sampler=sampler)


def square(system: ParametricSystem, keep: int, seed: int = 0, name: str | None = None) -> ParametricSystem:
    """A square system: the first ``keep`` equations and random combinations of the others.

    The remaining equations (e.g. dependent rank-2 minors) are replaced by N - keep combinations with
    small random integer coefficients (deterministic given ``seed``; integers keep the system exact over
    GF(p) and in floating point). The square system's roots contain those of the original; its count
    (certified like any other) may be larger, and the extra roots are filtered by the full system.
    """
    N = len(system.unknowns)
    rest = system.equations[keep:]
    if keep > N or N - keep > len(rest):
        raise ParametricError(f"{system.name}: cannot square {len(system.equations)} equations in {N} unknowns "
                              f"keeping {keep}")
    combos = [" + ".join(f"({int(a)})*({e})" for a, e in zip(c, rest))
              for c in square_combinations(len(rest), N - keep, seed)]
    return replace(system, name=name or f"{system.name} squared (seed {seed})",
                   equations=tuple(system.equations[:keep]) + tuple(combos))


def square_combinations(n_rest: int, n_new: int, seed: int = 0) -> np.ndarray:
    """The integer coefficients (n_new, n_rest) of :func:`square`'s combinations: nonzero, |c| <= 9,
    deterministic given ``seed`` (also used to write a squared system as a straight-line program)."""
    rng = np.random.default_rng(seed)
    out = np.empty((n_new, n_rest), dtype=np.int64)
    for k in range(n_new):
        out[k] = rng.integers(1, 10, size=n_rest) * rng.choice([-1, 1], size=n_rest)
    return out


#: Name of a system squared by :func:`square` (the committed 5r/4s and 5r/5s solvers' ``SYSTEM``).
_SQUARED_NAME = re.compile(r"^(?P<name>.+) \(minors squared, seed (?P<seed>\d+)\)$")


def squared_name(name: str, seed: int) -> str:
    """The name of the system ``name`` with its minors squared by :func:`square` (seed ``seed``)."""
    return f"{name} (minors squared, seed {seed})"


def parse_squared_name(text: str) -> tuple[str, int] | None:
    """Inverse of :func:`squared_name`: (name, seed), or None for a name of another form."""
    m = _SQUARED_NAME.match(text)
    return (m.group("name"), int(m.group("seed"))) if m else None


def from_positions(m: int, n: int, variant: str = "receivers-orbits") -> ParametricSystem:
    """A positions formulation (analysis.formulations.positions; unknowns are coordinates) as a parametric system.

    The default variant eliminates transmitters and offsets and writes the receivers in invariants of
    the gauge's sign group, so that each geometric solution is one root (4r/5s: 344). Its nonzero
    conditions (saturation) exclude the spurious components; scaling the data by t scales the squared
    coordinates X, Y by t^2 and leaves the ratios xi, eta unchanged.
    """
    from .positions import positions_system, sample_gf_positions

    ps = positions_system(m, n, variant)

    def sampler(p: int, seed: int) -> GFSample:
        F, root = sample_gf_positions(m, n, p, seed, variant)
        return [int(v) for row in F for v in row], [int(v) for v in root]

    powers = tuple(2.0 if u in ("X", "Y") else 0.0 if u[:2] in ("xi", "et") else 1.0 for u in ps.unknowns)
    system = ParametricSystem(ps.label, tuple(ps.unknowns), tuple(ps.parameters),
                              tuple(sympy.sstr(e) for e in ps.equations),
                              nonzero=tuple(sympy.sstr(e) for e in ps.saturate_by),
                              scale_powers=powers if variant == "receivers-orbits" else None, gf_sampler=sampler)
    # the expressions exist already: parsing their text back (sympify) would take minutes
    system.__dict__["exprs"] = tuple(sympy.expand(e) for e in ps.equations)
    system.__dict__["nonzero_exprs"] = tuple(sympy.expand(e) for e in ps.saturate_by)
    return system
