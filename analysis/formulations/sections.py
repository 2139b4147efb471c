"""The sectioned system-file format: its sections and names, read without sympy.

A file in this format (read whole by :func:`analysis.formulations.systemfile.read_system_text`)::

    unknowns: x, y
    parameters: a, b      (optional)
    nonzero: x            (optional)
    equations:
    x^2 + y^2 - a
    x*y - b

This module splits such a text into its sections, each item with its line and column, and checks the
names; the polynomials themselves are read by :func:`analysis.engine.io.parse_polynomial`, by
:mod:`analysis.formulations.systemfile` (a plain system) or :mod:`analysis.formulations.parametric`.
"""
from __future__ import annotations

import keyword
import re
from typing import Sequence

__all__ = ["ParametricError", "SECTIONS", "check_names", "is_sectioned", "sections"]

SECTIONS = ("unknowns", "parameters", "nonzero", "equations")
"""The sections of the sectioned format (``variables:`` is read as ``unknowns:``)."""

_SECTION = re.compile(r"\s*(unknowns|variables|parameters|nonzero|equations)\s*:", re.IGNORECASE)
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")

#: One item of a section: (text, line, column) in the file.
Item = tuple[str, int, int]


class ParametricError(ValueError):
    """A system in the sectioned format that cannot be used as given (bad names, parameters that do not
    occur, ...)."""


def check_names(source: str, kind: str, names: Sequence[str]) -> None:
    """Raise :class:`ParametricError` unless every name is an identifier (and not a Python keyword)."""
    for v in names:
        if not _NAME.match(v) or keyword.iskeyword(v):
            raise ParametricError(f"{source}: {kind} name {v!r} is not a name (a letter followed by letters, "
                                  "digits or '_'; not a Python keyword)")


def is_sectioned(text: str) -> bool:
    """Whether a system file is in the sectioned format (its first line with content opens a section such as
    ``unknowns:``) rather than msolve's."""
    for raw in text.splitlines():
        line = raw.split("#", 1)[0]
        if line.strip():
            return bool(_SECTION.match(line))
    return False


def sections(text: str, name: str = "<system>") -> dict[str, list[Item]]:
    """The sections of a file in the sectioned format: section -> its items with their line and column.

    Items are separated by commas, equations by line ends or ';'; ``#`` starts a comment. 'unknowns:'
    and 'equations:' are required. Errors are :class:`ParametricError` naming ``name`` and the line.
    """
    fields: dict[str, list[Item]] = {}
    current = None
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0]
        if not line.strip():
            continue
        offset = 0
        head, sep, rest = line.partition(":")
        key = head.strip().lower()
        if sep and key in SECTIONS + ("variables",):
            key = "unknowns" if key == "variables" else key
            if key in fields:
                raise ParametricError(f"{name}, line {lineno}: '{key}:' given twice")
            fields[key] = []
            current = key
            offset, line = len(head) + 1, rest
            if not line.strip():
                continue
        if current is None:
            raise ParametricError(f"{name}, line {lineno}: expected 'unknowns:', 'parameters:' or 'equations:' first")
        for piece in re.finditer(r"[^;]+" if current == "equations" else r"[^,]+", line):
            item = piece.group().strip()
            if item:
                col = offset + piece.start() + len(piece.group()) - len(piece.group().lstrip()) + 1
                fields[current].append((item, lineno, col))
    for key in ("unknowns", "equations"):
        if not fields.get(key):
            raise ParametricError(f"{name}: no '{key}:' section (or it is empty)")
    return fields
