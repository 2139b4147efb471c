"""The spec interface of the methods built over GF(p): formats, options, root count, JSON text.

Step 1 of solver generation: on consistent random instances over GF(p) a formulation's number of
roots is fixed (the size of the standard monomial basis of its grevlex Gröbner basis,
:func:`gf_degree`) and a method builds a JSON spec, which :mod:`solvers.codegen` turns into a module
and the method's online kernel executes. This module owns what every such spec shares: its format
tag, :class:`TemplateOptions` and :class:`TemplateResult`, the term structure of the input equations
(the layout of the generated coefficient vector), the choice of method for a formulation
(:func:`solver_method`) and the byte-stable JSON text (:func:`dump_spec`, :func:`load_spec`,
:func:`spec_sha256`). Methods: :mod:`solvers.methods.pencil` (``curve-pencil``) and
:mod:`solvers.methods.homotopy` (``homotopy``; its spec format is its own) and
:mod:`solvers.methods.offset_kernel` (``offset-kernel``, 3D) and :mod:`solvers.methods.action_matrix`
(``action-matrix``: elimination template; its spec format is its own); :mod:`solvers.generate` runs them. This module imports no method (the methods import it), so there is no import circle.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field

from analysis.engine.f4 import F4Options, groebner
from analysis.formulations.tdoa import Formulation, as_formulation, coefficient_expressions, gf_equations, sample_gf_instance
from analysis.engine.quotient import standard_monomials
from analysis.engine.ring import Ring

__all__ = [
    "METHODS",
    "SPEC_FORMAT",
    "TemplateError",
    "TemplateOptions",
    "TemplateResult",
    "common_spec",
    "dump_spec",
    "gf_degree",
    "load_spec",
    "solver_method",
    "spec_header",
    "spec_sha256",
    "term_structure",
]

#: Format of the curve-pencil specs.
SPEC_FORMAT = "tdoa-solver/2"
#: Solver construction methods (solvers.generate runs them).
METHODS = ("curve-pencil", "homotopy", "offset-kernel", "action-matrix")


class TemplateError(RuntimeError):
    """The template could not be built or failed its check on the GF(p) instance."""


@dataclass(frozen=True)
class TemplateOptions:
    """Options of solver construction.

    prime: characteristic of the GF(p) instances (< 2^16 so that every product is exact in float64).
    seed: seed of the GF(p) instance (printed in errors); the degree is confirmed on seed + 1.
    chart_angle: curve-pencil only: the chart nu -> (lambda, mu) = nu (cos a, sin a) + (-sin a, cos a).
    verify_trials: seeded real networks on which a built solver must find the known root.
    """

    prime: int = 65521
    seed: int = 1
    chart_angle: float = 0.3
    verify_trials: int = 20


@dataclass(frozen=True)
class TemplateResult:
    """A built template: the JSON-ready spec and generation statistics."""

    spec: dict
    seconds: float
    candidates: tuple[dict, ...] = field(default=())

    @property
    def shape(self) -> tuple[int, int]:
        """Size of the numeric core: the pencil's (rows, columns)."""
        return tuple(self.spec["size"])



# --------------------------------------------------------------------------------------------------
# root count and term structure over GF(p); the method of a formulation
# --------------------------------------------------------------------------------------------------


def gf_degree(formulation: Formulation | str, options: TemplateOptions = TemplateOptions()) -> int:
    """Number of roots (with multiplicity) over GF(p): |standard monomial basis| of the grevlex basis.

    Computed on the instances with seeds ``options.seed`` and ``options.seed + 1``; raises
    :class:`TemplateError` if they disagree or if the known root of an instance is not a root.
    """
    formulation = as_formulation(formulation)
    p = options.prime
    ring = Ring(formulation.unknowns, p, "grevlex")
    degrees = []
    for seed in (options.seed, options.seed + 1):
        instance = sample_gf_instance(formulation.config, p, seed)
        polys = [ring.from_terms(e) for e in gf_equations(formulation, instance)]
        if any(f.evaluate(instance.root) for f in polys):
            raise TemplateError(f"the known root of the GF({p}) instance (seed {seed}) is not a root")
        degrees.append(len(standard_monomials(groebner(polys, F4Options()))))
    if degrees[0] != degrees[1]:
        raise TemplateError(f"GF({p}) instances with seeds {options.seed}, {options.seed + 1} give "
                            f"different degrees {degrees}")
    return degrees[0]


def term_structure(formulation: Formulation | str) -> tuple[list[list[int]], list[list[int]]]:
    """(monomial table, per equation the indices of its terms) of a formulation's symbolic equations.

    Terms are the exponents with a nonzero coefficient polynomial in the data, in decreasing grevlex
    order; the table lists the monomials by (degree, grevlex). This is the layout of the coefficient
    vector emitted by :mod:`solvers.codegen` (used for polishing and residuals).
    """
    formulation = as_formulation(formulation)
    ring = Ring(formulation.unknowns, 65521, "grevlex")
    symbolic = coefficient_expressions(formulation, "ring")
    per_eq = [sorted((e for e, c in eq.items() if c), key=ring.key, reverse=True) for eq in symbolic]
    table = sorted({e for eq in per_eq for e in eq}, key=lambda e: (sum(e), ring.key(e)))
    idx = {e: i for i, e in enumerate(table)}
    return [list(e) for e in table], [[idx[e] for e in eq] for eq in per_eq]


def solver_method(formulation: Formulation | str) -> str:
    """The construction used for a formulation: ``curve-pencil`` (6r4s with B2, C2-C6 and its ten
    minors, paper Section 3.2), ``offset-kernel`` (3D TDOA mr/5s, m >= 9, with A, B2-B4, C2-Cm and all
    4 x 4 minors) or ``homotopy`` (every other formulation; it must be square)."""
    from math import comb

    formulation = as_formulation(formulation)
    config, eqs = formulation.config, tuple(formulation.equations)
    c_eqs = tuple(f"C{i}" for i in range(2, config.m + 1))
    minors = tuple(e for e in eqs if e.startswith("M"))
    if (config.dim == 3 and config.model == "tdoa" and config.parametrization == "compaction" and config.n == 5
            and config.m >= 9 and set(eqs) == {"A", "B2", "B3", "B4", *c_eqs, *minors}
            and len(set(minors)) == comb(config.m - 1, 4)):
        return "offset-kernel"
    if (config.m == 6 and config.n == 4 and set(eqs) == {"B2", *c_eqs, *minors} and len(minors) == 10):
        return "curve-pencil"
    return "homotopy"


def spec_header(formulation: Formulation, options: TemplateOptions, kind: str, degree: int,
                spec_format: str = SPEC_FORMAT) -> dict:
    """The fields every spec built over GF(p) starts with: format, kind, formulation, prime, seed, degree."""
    return {
        "format": spec_format,
        "kind": kind,
        "formulation": formulation.label,
        "equations": list(formulation.equations),
        "unknowns": list(formulation.unknowns),
        "order": "grevlex",
        "prime": options.prime,
        "seed": options.seed,
        "degree": degree,
    }


def common_spec(formulation: Formulation, options: TemplateOptions, kind: str, degree: int) -> dict:
    """The header of a ``tdoa-solver/2`` spec and the term structure of its input equations."""
    monomials, inputs = term_structure(formulation)
    return {**spec_header(formulation, options, kind, degree), "monomials": monomials, "inputs": inputs}



# --------------------------------------------------------------------------------------------------
# JSON I/O (byte-stable)
# --------------------------------------------------------------------------------------------------


def dump_spec(spec: dict) -> str:
    """Byte-stable JSON text: one top-level key per line, inner lists compact."""
    lines = ["{"]
    keys = list(spec)
    for i, k in enumerate(keys):
        sep = "," if i < len(keys) - 1 else ""
        value = spec[k]
        if isinstance(value, list) and value and isinstance(value[0], (list, dict)):
            lines.append(f"  {json.dumps(k)}: [")
            for j, item in enumerate(value):
                s2 = "," if j < len(value) - 1 else ""
                lines.append(f"    {json.dumps(item, separators=(',', ':'))}{s2}")
            lines.append(f"  ]{sep}")
        else:
            lines.append(f"  {json.dumps(k)}: {json.dumps(value, separators=(',', ':'))}{sep}")
    lines.append("}")
    return "\n".join(lines) + "\n"


def load_spec(text: str) -> dict:
    """Parse a spec; raises :class:`TemplateError` for an unknown format."""
    spec = json.loads(text)
    if spec.get("format") != SPEC_FORMAT:
        raise TemplateError(f"unknown template spec format {spec.get('format')!r}; expected {SPEC_FORMAT}")
    return spec


def spec_sha256(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()
