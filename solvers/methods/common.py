"""What every method's runtime shares (numpy only, no exact algebra): the spec format check and the
check of a built solver on seeded real instances. :mod:`solvers.methods.spec` holds the offline side."""
from __future__ import annotations

import json

import numpy as np

__all__ = ["load_format", "verify_found"]


def load_format(text: str, spec_format: str, error: type[Exception], what: str) -> dict:
    """A spec from its JSON text; raises ``error`` unless its format is ``spec_format`` (``what``: the method)."""
    spec = json.loads(text)
    if spec.get("format") != spec_format:
        raise error(f"unknown {what} spec format {spec.get('format')!r}; expected {spec_format}")
    return spec


def verify_found(name: str, roots, trials, count: int, error: type[Exception]) -> str:
    """Solve ``count`` seeded real instances (seed -> (normalised q, known root)) by ``roots(q) -> (k, n)``;
    "found/count", or ``error`` when the known root is missed in more than 10 % of them."""
    found = 0
    for seed in range(count):
        q, xt = trials(seed)
        x = roots(q)
        found += bool(np.nanmin(np.linalg.norm(x - xt, axis=1) / (1.0 + np.linalg.norm(xt))) < 1e-6)
    if found < 0.9 * count:
        raise error(f"{name}: the solver finds the known root in only {found}/{count} seeded instances")
    return f"{found}/{count}"
