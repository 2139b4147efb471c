"""A user's system file, whichever of its two forms: the one reader every verb uses.

A system file is either in msolve's format (:func:`analysis.engine.io.parse_msolve`: line 1 the
variables, line 2 the characteristic, then the polynomials) or in the sectioned format
(:mod:`analysis.formulations.sections`: ``unknowns:``, optional ``parameters:`` and ``nonzero:``,
``equations:``). The content tells them apart (:func:`analysis.formulations.sections.is_sectioned`: the
first line with content opens a section), never the extension.

A file without parameters is a *plain system*, an :class:`analysis.engine.io.System` over Q (or GF(p)
for msolve's format), whose ``nonzero:`` conditions are kept by the Rabinowitsch form of the
saturation (:meth:`analysis.engine.io.System.saturated_by`: one more unknown t and t * product - 1). A
file with parameters is a :class:`analysis.formulations.parametric.ParametricSystem`, the input of the
solver generator.

This module is light on purpose (no sympy): ``degree`` on a plain system starts in a fraction of a
second; the parametric module is imported only for a file with parameters. Nothing in a file is
evaluated: every polynomial is read by the project's parser (:func:`analysis.engine.io.parse_polynomial`).
"""
from __future__ import annotations

from fractions import Fraction
from pathlib import Path

from ..engine.io import Coefficients, InputError, System, decode_text, parse_msolve, parse_polynomial
from .sections import Item, ParametricError, check_names, is_sectioned, sections

__all__ = ["ParametricError", "is_sectioned", "read_system_text", "read_system_file"]


def read_system_text(text: str, name: str = "<system>") -> "System | ParametricSystem":
    """The system in a file's text, whichever format (module docstring): a plain system as an
    :class:`analysis.engine.io.System`, a system with parameters as a ``ParametricSystem``.

    Errors: :class:`analysis.engine.io.InputError` (msolve's format) or :class:`ParametricError` (the
    sectioned one), one line naming ``name``, the line and the column.
    """
    if not is_sectioned(text):
        return parse_msolve(text, source=name)
    fields = sections(text, name)
    if fields.get("parameters"):
        from .parametric import parse

        return parse(text, name)
    unknowns = tuple(item for item, _, _ in fields["unknowns"])
    check_names(name, "unknown", unknowns)
    if len(set(unknowns)) != len(unknowns):
        raise ParametricError(f"{name}: a name is declared twice")

    def read(items: list[Item], what: str) -> list[Coefficients]:
        out = []
        for k, (item, line, col) in enumerate(items):
            try:
                out.append(parse_polynomial(" " * (col - 1) + item, unknowns, 0, name, line, kind="name",
                                            identifiers=True))
            except InputError as exc:
                raise ParametricError(f"{exc} (in {what.format(k + 1)}; a polynomial with rational coefficients is "
                                      "expected)") from None
        return out

    plain = System(unknowns, 0, tuple(read(fields["equations"], "equation {}")),
                   tuple(line for _, line, _ in fields["equations"]), source=name)
    conditions = read(fields.get("nonzero", []), "nonzero condition")
    if not conditions:
        return plain
    product: Coefficients = {(0,) * len(unknowns): Fraction(1)}
    for factor in conditions:
        product = _multiply(product, factor)
    return plain.saturated_by(product)


def _multiply(f: Coefficients, g: Coefficients) -> Coefficients:
    """The product of two exact polynomials ``{exponents: Fraction}``."""
    out: dict[tuple[int, ...], Fraction] = {}
    for e, a in f.items():
        for d, b in g.items():
            k = tuple(x + y for x, y in zip(e, d))
            out[k] = out.get(k, 0) + a * b
    return {k: c for k, c in out.items() if c}


def read_system_file(path: "str | Path") -> "System | ParametricSystem":
    """:func:`read_system_text` of a file (UTF-8, checked by :func:`analysis.engine.io.decode_text`)."""
    path = Path(path)
    return read_system_text(decode_text(path.read_bytes(), str(path)), str(path))
