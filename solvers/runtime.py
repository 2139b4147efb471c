"""Online glue of the generated pencil solvers: normalisation, polishing, batched solve.

A generated module (solvers/generated/*.py) holds the solver's constants and the coefficient function
of its equations; what the pencil method needs around its kernel lives here, vectorised over a
leading batch axis:

* data normalisation (divide by the RMS measurement) and the map of roots back to the data scale;
* evaluation of a polynomial system from its coefficient vector, Gauss-Newton polishing;
* :func:`load_solver`, which builds a spec's kernel (``curve-pencil``:
  :class:`solvers.methods.pencil.CurvePencilSolver`), and the batched solve around it.

Each method's own numerics live beside its offline build in :mod:`solvers.methods`; homotopy
solvers are driven by :mod:`solvers.methods.homotopy` alone. Only numpy and scipy are used.
"""
from __future__ import annotations

import json
import os

import numpy as np

from .methods.pencil import CurvePencilSolver

__all__ = [
    "PolySystem",
    "data_scale",
    "load_solver",
    "polish",
    "solve_batch",
    "solve_one",
]


# --------------------------------------------------------------------------------------------------
# normalisation
# --------------------------------------------------------------------------------------------------


def data_scale(F: np.ndarray) -> np.ndarray:
    """Per-instance scale s = RMS of the measurements (batch,); data are divided by s before solving.

    A root of F / s maps back to F by h -> h / s^2, b -> b, o -> o * s (see solvers.codegen).
    """
    s = np.sqrt(np.mean(F * F, axis=(-2, -1)))
    return np.where(s > 0, s, 1.0)


def spec_path(module_file: str, name: str) -> str:
    return os.path.join(os.path.dirname(os.path.abspath(module_file)), name)


# --------------------------------------------------------------------------------------------------
# polynomial systems from coefficient vectors; Gauss-Newton polishing
# --------------------------------------------------------------------------------------------------


class PolySystem:
    """A polynomial system given by its term structure; values come from a coefficient vector.

    exps (T, n): exponents of the T terms; term_eq (T,): the equation of each term. Terms are grouped
    by distinct monomial so that residuals and Jacobians of k candidates of one instance are two small
    matrix products with the instance's (monomials x equations) coefficient matrix.
    """

    def __init__(self, exps: np.ndarray, term_eq: np.ndarray, n_eq: int):
        exps = np.asarray(exps, dtype=np.int64)
        self.n_eq, self.nvars = int(n_eq), exps.shape[1]
        mons, self.term_mon = np.unique(exps, axis=0, return_inverse=True)
        self.term_mon = self.term_mon.ravel()
        self.term_eq = np.asarray(term_eq, dtype=np.intp)
        # derivative d mon_m / d x_v = e_mv * x^(e_m - u_v): index into an extended monomial table
        lowered = [tuple(m - np.eye(self.nvars, dtype=np.int64)[v]) for m in mons for v in range(self.nvars)]
        table = {tuple(m): i for i, m in enumerate(mons)}
        for m in lowered:
            if min(m) >= 0 and m not in table:
                table[m] = len(table)
        ext = np.zeros((len(table), self.nvars), dtype=np.int64)
        for m, i in table.items():
            ext[i] = m
        self.ext = ext
        self.n_mon = len(mons)
        self.dfactor = np.array([[m[v] for v in range(self.nvars)] for m in mons], dtype=float)  # (M, n)
        self.didx = np.array([[table[tuple(m - np.eye(self.nvars, dtype=np.int64)[v])] if m[v] else 0
                               for v in range(self.nvars)] for m in mons], dtype=np.intp)
        self.max_exp = ext.max(axis=0)
        self._variables = np.arange(self.nvars)[None, :]

    def coefficient_matrix(self, coeffs: np.ndarray) -> np.ndarray:
        """(batch, M, n_eq) coefficient matrices from coefficient vectors (batch, T), rows scaled to unit norm."""
        C = np.zeros((coeffs.shape[0], self.n_mon, self.n_eq), dtype=coeffs.dtype)
        np.add.at(C, (slice(None), self.term_mon, self.term_eq), coeffs)
        norm = np.sqrt(np.sum(np.abs(C) ** 2, axis=1, keepdims=True))
        return C / np.where(norm > 0, norm, 1.0)

    def _ext_monomials(self, x: np.ndarray) -> np.ndarray:
        """x (..., n) -> values of the extended monomial table (..., E)."""
        top = int(self.max_exp.max())
        pw = np.concatenate([np.ones(x.shape + (1,), dtype=x.dtype), np.repeat(x[..., None], top, axis=-1)], axis=-1)
        pw = np.cumprod(pw, axis=-1)  # (..., n, top + 1): x_v^0 .. x_v^top
        return np.prod(pw[..., self._variables, self.ext], axis=-1)

    def residual_jacobian(self, x: np.ndarray, C: np.ndarray, jacobian: bool = True):
        """Residuals (B, k, n_eq) and Jacobians (B, k, n_eq, n) at x (B, k, n) with matrices C (B, M, n_eq)."""
        em = self._ext_monomials(x)
        f = em[..., : self.n_mon] @ C
        if not jacobian:
            return f, None
        dm = em[..., self.didx] * self.dfactor  # (B, k, M, n)
        B, k = x.shape[:2]
        J = np.swapaxes(dm.reshape(B, k, self.n_mon, self.nvars), 2, 3).reshape(B, k * self.nvars, self.n_mon) @ C
        return f, np.swapaxes(J.reshape(B, k, self.nvars, self.n_eq), 2, 3)


#: Candidates whose imaginary parts are below this (relative to their largest entry) are polished, as
#: real points; the others are not physical calibrations and are returned as computed.
POLISH_REAL_TOL = 1e-4


def polish(system: PolySystem, coeffs: np.ndarray, roots: np.ndarray, iterations: int = 1,
           real_tol: float = POLISH_REAL_TOL) -> np.ndarray:
    """Gauss-Newton steps on the (possibly overdetermined) input system for every near-real candidate.

    coeffs (batch, T) from the generated coefficient function, roots (batch, k, n). A candidate with
    max |Im x| <= real_tol * max |x| is replaced by its real part and polished in real arithmetic (the
    candidates of the whole batch in one stack); complex candidates are returned unchanged. Equations
    are scaled to unit coefficient norm; the step is the least-squares solution by QR. A candidate keeps
    its old value when it is not finite or when the step does not decrease its residual, so polishing
    never spoils an accurate root.
    """
    roots = np.asarray(roots)
    with np.errstate(all="ignore"):
        finite = np.all(np.isfinite(roots), axis=-1)
        scale = np.max(np.abs(np.where(finite[..., None], roots, 0.0)), axis=-1)
        near_real = finite & (np.max(np.abs(roots.imag), axis=-1) <= real_tol * scale)
    bi, ki = np.nonzero(near_real)
    if not len(bi):
        return roots
    C = system.coefficient_matrix(coeffs.real if np.iscomplexobj(coeffs) else coeffs)[bi]  # (P, M, n_eq)
    x = roots[bi, ki].real[:, None, :]  # (P, 1, n): one candidate per stack entry
    with np.errstate(all="ignore"):
        f, J = system.residual_jacobian(x, C)
        for it in range(iterations):
            ok = np.all(np.isfinite(J), axis=(2, 3)) & np.all(np.isfinite(f), axis=2)
            Jc = np.where(ok[..., None, None], J, np.eye(J.shape[2], J.shape[3]))
            q, r = np.linalg.qr(Jc)
            rhs = np.swapaxes(q, 2, 3) @ np.where(ok[..., None], f, 0.0)[..., None]
            try:
                step = np.linalg.solve(r, rhs)[..., 0]
            except np.linalg.LinAlgError:
                step = (np.linalg.pinv(r) @ rhs)[..., 0]
            xn = x - np.where(ok[..., None], step, 0.0)
            last = it == iterations - 1
            fn, Jn = system.residual_jacobian(xn, C, jacobian=not last)
            better = ok & np.all(np.isfinite(xn), axis=-1) & (np.linalg.norm(fn, axis=2) < np.linalg.norm(f, axis=2))
            x = np.where(better[..., None], xn, x)
            if not last:
                f = np.where(better[..., None], fn, f)
                J = np.where(better[..., None, None], Jn, J)
    out = roots.astype(complex)
    out[bi, ki] = x[:, 0]
    return out




# --------------------------------------------------------------------------------------------------
# module glue
# --------------------------------------------------------------------------------------------------


class _Solver:
    """A solver kernel with the term structure of its input equations (for polishing)."""

    def __init__(self, spec: dict, scale_powers: tuple[float, ...]):
        self.spec = spec
        kind = spec.get("kind")
        if kind != "curve-pencil":
            raise ValueError(f"unknown solver kind {kind!r}; valid: curve-pencil (homotopy: solvers.methods.homotopy)")
        self.kernel = CurvePencilSolver(spec)
        self.kind = kind
        self.basis_size = self.kernel.basis_size
        self.nvars = len(spec["unknowns"])
        self.scale_powers = np.asarray(scale_powers, dtype=float)
        mons = [tuple(m) for m in spec["monomials"]]
        term_exps = np.array([mons[m] for eq in spec["inputs"] for m in eq], dtype=np.int64)
        term_eq = np.concatenate([np.full(len(eq), i) for i, eq in enumerate(spec["inputs"])])
        self.system = PolySystem(term_exps, term_eq, len(spec["inputs"]))

    def roots(self, Fn: np.ndarray, coeffs: np.ndarray) -> np.ndarray:
        return self.kernel.roots(Fn)


def load_solver(json_path: str, scale_powers: tuple[float, ...]) -> _Solver:
    """Read a spec next to a generated module and build its solver (precomputed once per process)."""
    with open(json_path, encoding="utf-8") as fh:
        spec = json.load(fh)
    return _Solver(spec, scale_powers)


#: Instances per chunk in batched solves (bounds the memory of the per-instance matrices).
CHUNK = 64


def _check_data(F: np.ndarray, config: tuple[int, int]) -> np.ndarray:
    F = np.asarray(F, dtype=float)
    if F.shape[-2:] != tuple(config):
        raise ValueError(f"data must have shape (..., {config[0]}, {config[1]}), got {F.shape}")
    return F


def _coefficients(coefficients, Fn: np.ndarray) -> np.ndarray:
    """Coefficient vectors (batch, T); one instance runs on Python floats (much faster than 1-arrays)."""
    if len(Fn) == 1:
        return np.array(coefficients(tuple(Fn[0].ravel().tolist())), dtype=float)[None]
    cols = Fn.reshape(len(Fn), -1).T
    values = coefficients(tuple(cols))
    out = np.empty((len(Fn), len(values)))
    for j, v in enumerate(values):
        out[:, j] = v
    return out


def _solve_chunk(solver: _Solver, coefficients, block: np.ndarray, polish_iterations: int) -> np.ndarray:
    s = data_scale(block)
    Fn = block / s[:, None, None]
    coeffs = _coefficients(coefficients, Fn)
    with np.errstate(all="ignore"):
        roots = solver.roots(Fn, coeffs)
        if polish_iterations:
            roots = polish(solver.system, coeffs, roots, polish_iterations)
        return roots * (s[:, None, None] ** solver.scale_powers[None, None, :])


def solve_one(solver: _Solver, coefficients, F: np.ndarray, config: tuple[int, int],
              polish_iterations: int) -> np.ndarray:
    """Candidate roots (k, nvars) for one data matrix."""
    F = _check_data(F, config)
    if F.ndim != 2:
        raise ValueError(f"solve takes one ({config[0]}, {config[1]}) matrix; use solve_batch for {F.shape}")
    return _solve_chunk(solver, coefficients, F[None], polish_iterations)[0]


def solve_batch(solver: _Solver, coefficients, F: np.ndarray, config: tuple[int, int],
                polish_iterations: int) -> np.ndarray:
    """Candidate roots (..., k, nvars) for data (..., m, n)."""
    F = _check_data(F, config)
    lead = F.shape[:-2]
    flat = F.reshape((-1,) + tuple(config))
    out = np.empty((len(flat), solver.basis_size, solver.nvars), dtype=complex)
    for start in range(0, len(flat), CHUNK):
        out[start : start + CHUNK] = _solve_chunk(solver, coefficients, flat[start : start + CHUNK], polish_iterations)
    return out.reshape(lead + out.shape[1:])

