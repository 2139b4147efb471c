"""Shared numeric kernels of the generated solvers: replay a staged elimination template, build the
action matrix, solve the eigenproblem, read off the roots and polish them by Gauss-Newton.

A generated module (solvers/generated/*.py) computes the equation coefficients from the data and
hands them, with its spec (solvers/generated/*.json, built by :mod:`solvers.template`), to
:class:`StagedSolver`. All kernels are vectorised over a leading batch axis; index arrays are
precomputed once per spec, so a solve is a fixed sequence of numpy calls:

1. fill each step's template from the polynomial table V (one fancy-indexed assignment);
2. reduce the non-pivot rows by the pivot rows (unit triangular block: ``numpy.linalg.solve``);
3. keep the rows with new leading monomials, normalised by a least-squares (QR) solve, into V;
4. final step: [T | C_B] with T unit upper triangular; NF(r) = -(T^-1 C_B)[r] for r in R;
5. action matrix on B, ``numpy.linalg.eig``, eigenvectors normalised by the entry of monomial 1;
6. optional Gauss-Newton polishing of every candidate on all input equations.

Only numpy is used. Reference: Kukelova et al. (ECCV 2008) for the action-matrix template;
Faugère (JPAA 1999) for the F4 steps whose trace the template replays.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass

import numpy as np

__all__ = ["StagedSolver", "load_solver", "polish"]


@dataclass(frozen=True)
class _Step:
    nrows: int
    ncols: int
    fill_row: np.ndarray
    fill_col: np.ndarray
    fill_src: np.ndarray
    pivots: np.ndarray
    reduce: np.ndarray
    pivot_cols: np.ndarray
    free_cols: np.ndarray
    lead_in_free: np.ndarray
    new_row: np.ndarray  # for every stored coefficient: row of H
    new_col: np.ndarray  # ... and its column (position among free columns)
    new_dst: np.ndarray  # ... and its slot in V


class StagedSolver:
    """Numeric replay of a staged elimination template spec (see :mod:`solvers.template`).

    Parameters
    ----------
    spec: the parsed JSON spec.
    scale_powers: per unknown, the power w of the data scale s such that a root of the data F / s
        maps back by x = x_s * s**w (None: no data normalisation).
    """

    def __init__(self, spec: dict, scale_powers: tuple[float, ...] | None = None):
        self.spec = spec
        self.unknowns = tuple(spec["unknowns"])
        self.nvars = len(self.unknowns)
        self.scale_powers = None if scale_powers is None else np.asarray(scale_powers, dtype=float)
        mons = [tuple(m) for m in spec["monomials"]]
        self._mons = mons
        polys = spec["polys"]
        lengths = np.array([len(s) for s in polys], dtype=np.int64)
        self._offsets = np.concatenate([[0], np.cumsum(lengths)])
        self.table_size = int(self._offsets[-1])
        self.n_inputs = len(spec["inputs"])
        self.n_input_coeffs = int(self._offsets[self.n_inputs])

        def add(a: int, b: int) -> tuple:
            return tuple(x + y for x, y in zip(mons[a], mons[b]))

        def fill(rows, columns):
            pos = {mons[c]: j for j, c in enumerate(columns)}
            fr, fc, fs = [], [], []
            for r, (pid, shift) in enumerate(rows):
                off = int(self._offsets[pid])
                for k, m in enumerate(polys[pid]):
                    fr.append(r)
                    fc.append(pos[add(m, shift)])
                    fs.append(off + k)
            return (np.array(fr, dtype=np.intp), np.array(fc, dtype=np.intp), np.array(fs, dtype=np.intp))

        self.steps: list[_Step] = []
        for st in spec["steps"]:
            fr, fc, fs = fill(st["rows"], st["columns"])
            ncols = len(st["columns"])
            pivots = np.array(st["pivots"], dtype=np.intp)
            # a pivot row's lead column: the position of its largest monomial
            pcols = np.array([fc[np.flatnonzero(fr == r)].min() for r in pivots], dtype=np.intp) if len(pivots) else np.zeros(0, np.intp)
            free = np.setdiff1d(np.arange(ncols), pcols)
            free_pos = {int(c): i for i, c in enumerate(free)}
            leads = [free_pos[nw[1]] for nw in st["new"]]
            nr, nc, nd = [], [], []
            for h, (pid, _, support) in enumerate(st["new"]):
                off = int(self._offsets[pid])
                for k, c in enumerate(support):
                    nr.append(h)
                    nc.append(free_pos[c])
                    nd.append(off + k)
            self.steps.append(_Step(len(st["rows"]), ncols, fr, fc, fs, pivots,
                                    np.array(st["reduce"], dtype=np.intp), pcols, free,
                                    np.array(leads, dtype=np.intp), np.array(nr, dtype=np.intp),
                                    np.array(nc, dtype=np.intp), np.array(nd, dtype=np.intp)))
        final = spec["final"]
        self._final_fill = fill(final["rows"], final["columns"])
        self._final_shape = (len(final["rows"]), len(final["columns"]))
        self._n_lead = final["n_lead"]
        basis = spec["basis"]
        self.basis_size = len(basis)
        bpos = {mons[b]: j for j, b in enumerate(basis)}
        std_cols = [bpos[mons[c]] for c in final["columns"][self._n_lead:]]
        self._std_cols = np.array(std_cols, dtype=np.intp)
        target_row = {mons[m]: t for m, t in zip(final["target_monomials"], final["targets"])}
        a = self.unknowns.index(spec["action"])
        unit = tuple(int(i == a) for i in range(self.nvars))
        ur, uc, rr, rt = [], [], [], []
        for j, b in enumerate(basis):
            m = tuple(x + y for x, y in zip(mons[b], unit))
            if m in bpos:
                ur.append(j)
                uc.append(bpos[m])
            else:
                rr.append(j)
                rt.append(target_row[m])
        self._unit = (np.array(ur, dtype=np.intp), np.array(uc, dtype=np.intp))
        self._red = (np.array(rr, dtype=np.intp), np.array(rt, dtype=np.intp))
        zero = (0,) * self.nvars
        if zero not in bpos:
            raise ValueError("the standard monomial basis must contain 1")
        self._one = bpos[zero]
        read_basis, read_target = [], []
        for i in range(self.nvars):
            m = tuple(int(k == i) for k in range(self.nvars))
            if m in bpos:
                read_basis.append((i, bpos[m]))
            else:
                read_target.append((i, target_row[m]))
        self._read_basis = read_basis
        self._read_target = read_target
        # input equations as (term exponents, equation of each term) for polishing
        exps = [mons[m] for eq in spec["inputs"] for m in eq]
        self._term_exps = np.array(exps, dtype=np.int64)
        self._term_eq = np.concatenate([np.full(len(eq), i) for i, eq in enumerate(spec["inputs"])])

    # ------------------------------------------------------------------------------------------
    def action_matrices(self, coeffs: np.ndarray) -> np.ndarray:
        """Action matrices (batch, |B|, |B|) from input coefficients (batch, n_input_coeffs)."""
        batch = coeffs.shape[0]
        V = np.zeros((batch, self.table_size))
        V[:, : self.n_input_coeffs] = coeffs
        for st in self.steps:
            A = np.zeros((batch, st.nrows, st.ncols))
            A[:, st.fill_row, st.fill_col] = V[:, st.fill_src]
            Q = A[:, st.reduce]
            if len(st.pivots):
                P = A[:, st.pivots]
                X = np.linalg.solve(np.swapaxes(P[:, :, st.pivot_cols], 1, 2),
                                    np.swapaxes(Q[:, :, st.pivot_cols], 1, 2))
                Qf = Q[:, :, st.free_cols] - np.swapaxes(X, 1, 2) @ P[:, :, st.free_cols]
            else:
                Qf = Q
            q, r = np.linalg.qr(Qf[:, :, st.lead_in_free])
            H = np.linalg.solve(r, np.swapaxes(q, 1, 2) @ Qf)
            V[:, st.new_dst] = H[:, st.new_row, st.new_col]
        fr, fc, fs = self._final_fill
        A = np.zeros((batch,) + self._final_shape)
        A[:, fr, fc] = V[:, fs]
        n = self._n_lead
        Y = np.linalg.solve(A[:, :, :n], A[:, :, n:])
        self._last_Y = Y
        M = np.zeros((batch, self.basis_size, self.basis_size))
        M[:, self._unit[0], self._unit[1]] = 1.0
        rr, rt = self._red
        block = np.zeros((batch, len(rr), self.basis_size))
        block[:, :, self._std_cols] = -Y[:, rt]
        M[:, rr] = block
        return M

    def roots(self, coeffs: np.ndarray) -> np.ndarray:
        """Candidate roots (batch, |B|, nvars), complex, in the scaled frame of the coefficients."""
        with np.errstate(all="ignore"):
            try:
                M = self.action_matrices(coeffs)
            except np.linalg.LinAlgError:  # a singular step in the batch: solve one by one
                if coeffs.shape[0] > 1:
                    return np.concatenate([self.roots(coeffs[i : i + 1]) for i in range(coeffs.shape[0])])
                return np.full((1, self.basis_size, self.nvars), np.nan + 0j)
            bad = ~np.all(np.isfinite(M), axis=(1, 2))
            M[bad] = 0.0
            _, vecs = np.linalg.eig(M)
            one = vecs[:, self._one, :]
            out = np.empty((coeffs.shape[0], self.basis_size, self.nvars), dtype=complex)
            for i, j in self._read_basis:
                out[:, :, i] = vecs[:, j, :] / one
            if self._read_target:
                Y = self._last_Y
                for i, t in self._read_target:
                    nf = np.zeros((coeffs.shape[0], self.basis_size))
                    nf[:, self._std_cols] = -Y[:, t]
                    out[:, :, i] = np.einsum("bk,bks->bs", nf, vecs) / one
            out[bad] = np.nan
        return out

    def polish(self, coeffs: np.ndarray, roots: np.ndarray, iterations: int = 2) -> np.ndarray:
        """Gauss-Newton steps on all input equations, for every candidate (see :func:`polish`)."""
        return polish(coeffs, self._term_exps, self._term_eq, self.n_inputs, roots, iterations)


def _power_table(x: np.ndarray, max_exp: np.ndarray) -> list[np.ndarray]:
    """Per variable j, the powers x_j^0..x_j^max_exp[j] stacked on a last axis."""
    out = []
    for j, d in enumerate(max_exp):
        p = np.ones(x.shape[:-1] + (int(d) + 1,), dtype=x.dtype)
        for k in range(1, int(d) + 1):
            p[..., k] = p[..., k - 1] * x[..., j]
        out.append(p)
    return out


def _cmatmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Complex (batch, r, T) times real (batch, T, q), as two real batched products."""
    return (a.real @ b) + 1j * (a.imag @ b)


def polish(coeffs: np.ndarray, exps: np.ndarray, term_eq: np.ndarray, n_eq: int, roots: np.ndarray,
           iterations: int = 2) -> np.ndarray:
    """Gauss-Newton polishing of candidate roots on the (possibly overdetermined) input system.

    coeffs (batch, T) coefficients of the T terms with exponents exps (T, n), term_eq (T,) the equation
    of each term; roots (batch, k, n). Each equation is scaled by the norm of its coefficients; the step
    is the least-squares solution through the pseudo-inverse. Candidates whose Jacobian or residual is
    not finite are left alone. Derivatives use prefix/suffix products (no division by x_j).
    """
    x = roots.astype(complex)
    n = exps.shape[1]
    S = np.zeros((n_eq, len(exps)))
    S[term_eq, np.arange(len(exps))] = 1.0
    weight = 1.0 / np.sqrt(np.maximum((coeffs**2) @ S.T, 1e-300))  # (batch, n_eq)
    C = (coeffs[:, None, :] * S[None]) * weight[:, :, None]  # (batch, n_eq, T)
    Ct = np.ascontiguousarray(np.swapaxes(C, 1, 2))  # (batch, T, n_eq)
    max_exp = exps.max(axis=0)
    dexp = np.maximum(exps - 1, 0)
    with np.errstate(all="ignore"):
        for _ in range(iterations):
            pw = _power_table(x, max_exp)
            factors = [pw[j][..., exps[:, j]] for j in range(n)]  # each (b, k, T)
            prefix = [np.ones_like(factors[0])]
            for j in range(n - 1):
                prefix.append(prefix[-1] * factors[j])
            suffix = [np.ones_like(factors[0])]
            for j in range(n - 1, 0, -1):
                suffix.append(suffix[-1] * factors[j])
            suffix = suffix[::-1]
            mon = prefix[-1] * factors[-1]
            f = _cmatmul(mon, Ct)  # (b, k, n_eq)
            D = np.stack([prefix[j] * suffix[j] * (pw[j][..., dexp[:, j]] * exps[:, j]) for j in range(n)], axis=2)
            b_, k_ = x.shape[:2]
            J = np.swapaxes(_cmatmul(D.reshape(b_, k_ * n, -1), Ct).reshape(b_, k_, n, n_eq), 2, 3)
            ok = np.all(np.isfinite(J), axis=(2, 3)) & np.all(np.isfinite(f), axis=2)
            Jc = np.where(ok[..., None, None], J, 0.0)
            fc = np.where(ok[..., None], f, 0.0)
            step = (np.linalg.pinv(Jc) @ fc[..., None])[..., 0]
            x = np.where(ok[..., None], x - step, x)
    return x


def load_solver(json_path: str, scale_powers: tuple[float, ...] | None = None) -> StagedSolver:
    """Read a spec next to a generated module and build its solver (index arrays precomputed)."""
    with open(json_path, encoding="utf-8") as fh:
        spec = json.load(fh)
    return StagedSolver(spec, scale_powers)


def data_scale(F: np.ndarray) -> np.ndarray:
    """Per-instance scale s = RMS of the measurements (batch,); data are divided by s before solving."""
    s = np.sqrt(np.mean(F * F, axis=(-2, -1)))
    return np.where(s > 0, s, 1.0)


def spec_path(module_file: str, name: str) -> str:
    return os.path.join(os.path.dirname(os.path.abspath(module_file)), name)


#: Instances per chunk in batched solves (bounds the memory of the step matrices).
CHUNK = 64


def _check_data(F: np.ndarray, config: tuple[int, int]) -> np.ndarray:
    F = np.asarray(F, dtype=float)
    if F.shape[-2:] != tuple(config):
        raise ValueError(f"data must have shape (..., {config[0]}, {config[1]}), got {F.shape}")
    return F


def _finish(solver: StagedSolver, coeffs: np.ndarray, scale: np.ndarray, polish_iterations: int) -> np.ndarray:
    roots = solver.roots(coeffs)
    if polish_iterations:
        roots = solver.polish(coeffs, roots, polish_iterations)
    if solver.scale_powers is not None:
        roots = roots * (scale[:, None, None] ** solver.scale_powers[None, None, :])
    return roots


def solve_one(solver: StagedSolver, coefficients, F: np.ndarray, config: tuple[int, int],
              polish_iterations: int) -> np.ndarray:
    """Candidate roots (k, nvars) for one data matrix; coefficients run on Python floats."""
    F = _check_data(F, config)
    if F.ndim != 2:
        raise ValueError(f"solve takes one ({config[0]}, {config[1]}) matrix; use solve_batch for {F.shape}")
    s = data_scale(F[None])
    coeffs = np.array(coefficients(tuple((F / s[0]).ravel().tolist())), dtype=float)[None]
    return _finish(solver, coeffs, s, polish_iterations)[0]


def solve_batch(solver: StagedSolver, coefficients, F: np.ndarray, config: tuple[int, int],
                polish_iterations: int) -> np.ndarray:
    """Candidate roots (..., k, nvars) for data (..., m, n); coefficients run on numpy arrays."""
    F = _check_data(F, config)
    lead = F.shape[:-2]
    flat = F.reshape((-1,) + tuple(config))
    out = np.empty((len(flat), solver.basis_size, solver.nvars), dtype=complex)
    for start in range(0, len(flat), CHUNK):
        block = flat[start : start + CHUNK]
        s = data_scale(block)
        cols = (block / s[:, None, None]).reshape(len(block), -1).T
        values = coefficients(tuple(cols))
        coeffs = np.empty((len(block), len(values)))
        for j, v in enumerate(values):
            coeffs[:, j] = v
        out[start : start + CHUNK] = _finish(solver, coeffs, s, polish_iterations)
    return out.reshape(lead + out.shape[1:])
