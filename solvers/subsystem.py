"""Over-determined configurations solved on a square sub-configuration, the extra nodes filtering.

4r/6s: every square subsystem of the 4r/6s positions equations has the 344 roots of the minimal 4r/5s
problem, and only the true network satisfies all six transmitters' equations (1 solution over GF(p),
two primes: tables/NOTES.md). So the 4r/5s solver runs on the first five transmitters and the sixth
filters its 344 candidates (when none passes, on the next five-transmitter subset):
with the receivers of a candidate (gauge r_1 = 0), the four range
equations (f_i6 - o_6)^2 = |r_i - s_6|^2 minus the first are three linear equations in (s_6, o_6);
their solution must also satisfy the first equation. Complex candidates are filtered the same way
(bilinear, not Hermitian, products), so the filter is a polynomial condition, not a real-only one.

:class:`SubsystemSolver` has the attributes of a generated solver module that the benchmark and the
CLI read (``CONFIG``, ``SYSTEM``, ``METHOD``, ``DEGREE``, ``PATHS``, ``UNKNOWNS``, ``solve``,
``solve_batch``); its ``DEGREE`` is the count of the over-determined system (1), its ``PATHS`` the
base solver's.
"""
from __future__ import annotations

import itertools

import numpy as np

from .api import _module_for, _multilaterate, multilateration_system
from .methods.homotopy import solve_scaled
from .refine import refine

__all__ = ["SUBSYSTEMS", "FILTER_TOL", "SubsystemSolver", "extra_transmitter_residuals", "orbits_from_receivers",
           "polish_on_all", "receivers_from_orbits"]

#: Over-determined label -> (square base label, roots of the over-determined system). The count is
#: established by analysis.formulations.positions (tests/test_positions.py::test_4r6s_full_system_keeps_only_the_true_network_two_primes).
SUBSYSTEMS = {"4r6s": ("4r5s", 1)}

#: Largest relative residual of an extra transmitter's equation for a candidate to be kept.
FILTER_TOL = 1e-6
#: Residual evaluations of :func:`polish_on_all`'s Levenberg-Marquardt refinement on all measurements.
POLISH_EVALUATIONS = 20
#: A kept candidate is polished when its imaginary part is below this, relative to its size.
REAL_TOL = 1e-6


def receivers_from_orbits(x: np.ndarray) -> np.ndarray:
    """Receivers (..., 4, 2) in the gauge r_1 = 0, r_2 = (x2, 0) from 4r/5s roots (..., 5) in the
    sign-group invariants (X, Y, xi3, xi4, eta4); principal square roots pick one orbit member (the
    other members are reflections, which no range equation can tell apart)."""
    x = np.asarray(x, dtype=complex)
    x2, y3 = np.sqrt(x[..., 0]), np.sqrt(x[..., 1])
    zero = np.zeros_like(x2)
    rec = np.stack([np.stack([zero, zero], -1), np.stack([x2, zero], -1), np.stack([x[..., 2] * x2, y3], -1),
                    np.stack([x[..., 3] * x2, x[..., 4] * y3], -1)], axis=-2)
    return rec


def orbits_from_receivers(rec: np.ndarray) -> np.ndarray:
    """The 4r/5s unknowns (X, Y, xi3, xi4, eta4) of receivers (4, 2) in the gauge r_1 = 0, r_2 = (x2, 0)
    (the inverse of :func:`receivers_from_orbits`)."""
    x2, x3, y3, x4, y4 = rec[1, 0], rec[2, 0], rec[2, 1], rec[3, 0], rec[3, 1]
    return np.array([x2 * x2, y3 * y3, x3 / x2, x4 / x2, y4 / y3])


def polish_on_all(root: np.ndarray, F: np.ndarray) -> np.ndarray:
    """A real 4r/5s candidate polished on all measurements F (4, n): receivers from the candidate, each
    transmitter by :func:`solvers.api._multilaterate`, then :func:`solvers.refine.refine` (at most
    :data:`POLISH_EVALUATIONS` residual evaluations). Returns the polished candidate, or the candidate
    unchanged when it is not real, a transmitter cannot be placed, or the residual does not drop."""
    root = np.asarray(root)
    if not np.all(np.isfinite(root)) or np.max(np.abs(root.imag)) > REAL_TOL * np.max(np.abs(root)):
        return root
    rec = receivers_from_orbits(root.real).real
    placed = [_multilaterate(rec, f) for f in F.T]
    if any(p is None for p in placed):
        return root
    result = refine((rec, np.array([p[0] for p in placed]), np.array([p[1] for p in placed])), F,
                    max_iter=POLISH_EVALUATIONS)
    if not result.calibration.residual < result.initial_residual:
        return root
    with np.errstate(all="ignore"):
        polished = orbits_from_receivers(result.calibration.receivers)
    return polished.astype(root.dtype) if np.all(np.isfinite(polished)) else root


def extra_transmitter_residuals(receivers: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Relative residual of one transmitter's range equations for candidate receivers (..., m, 2).

    f (m,): the transmitter's measurements. (s, o) from the m - 1 differences of the range equations
    (:func:`solvers.api.multilateration_system`; least squares when m > 4); the residual is that of the
    first equation, (f_1 - o)^2 - s.s (r_1 = 0), relative to f_1^2 + |s|^2. NaN where the candidate is
    not finite.
    """
    A, rhs = multilateration_system(np.asarray(receivers, dtype=complex), f)
    f0 = float(np.asarray(f, dtype=float)[0])
    out = np.full(A.shape[:-2], np.nan)
    ok = np.all(np.isfinite(A), axis=(-2, -1)) & np.all(np.isfinite(rhs), axis=-1)
    with np.errstate(all="ignore"):
        sol = (np.linalg.pinv(A[ok]) @ rhs[ok][..., None])[..., 0]
        s, o = sol[..., :2], sol[..., 2]
        first = (f0 - o) ** 2 - np.einsum("...i,...i->...", s, s)
        out[ok] = np.abs(first) / (f0**2 + np.einsum("...i,...i->...", np.abs(s), np.abs(s)))
    return out


def _real_network(x: np.ndarray) -> np.ndarray:
    """Mask of the 4r/5s roots (..., 5) that are real networks: real (to :data:`REAL_TOL`) with X = x2^2 > 0
    and Y = y3^2 > 0. The filter passes complex candidates too; a pass is final only with a real one (on
    exact real data the true network is one): 4r/6s networks 113 and 199 have a real root near infinity
    with Y < 0 (|X| ~ 4e5 in scaled units) whose extra-transmitter residual is 2e-7 - 6e-7 relative to its
    own huge terms."""
    x = np.asarray(x)
    with np.errstate(invalid="ignore"):
        finite = np.all(np.isfinite(x), axis=-1)
        real = np.max(np.abs(x.imag), axis=-1) <= REAL_TOL * np.max(np.abs(x), axis=-1)
        return finite & real & (x[..., 0].real > 0) & (x[..., 1].real > 0)


class SubsystemSolver:
    """The solver of an over-determined configuration (:data:`SUBSYSTEMS`): its base solver on the
    first transmitters (then on the other subsets while no candidate passes), candidates kept only when
    every further transmitter's equations hold. A homotopy base runs its plain track alone on every
    subset first, then its full solve (retracks, detours) on every subset still without a candidate."""

    def __init__(self, label: str):
        if label not in SUBSYSTEMS:
            raise ValueError(f"unknown over-determined configuration {label!r}; valid: {', '.join(SUBSYSTEMS)}")
        base_label, degree = SUBSYSTEMS[label]
        self.base = _module_for(base_label)
        self.label = label
        self.CONFIG = tuple(int(v) for v in label[:-1].split("r"))
        self.SYSTEM = f"{label}: {self.base.SYSTEM.split(':', 1)[1]} on {self.base.CONFIG[1]} transmitters (1-{self.base.CONFIG[1]} first), filtered by the rest"
        self.METHOD = self.base.METHOD
        self.DEGREE = degree
        self.PATHS = self.base.PATHS
        self.UNKNOWNS = self.base.UNKNOWNS
        if "receivers-orbits" not in self.base.SYSTEM:
            raise ValueError(f"{label}: the filter reads receivers from the 4r/5s orbit invariants, not {self.base.SYSTEM}")

    def subsets(self) -> list[tuple[int, ...]]:
        """The transmitter subsets the base solver is tried on, in order: first transmitters 1..n_base,
        then the other n_base-subsets in lexicographic order (:meth:`solve_batch`)."""
        return list(itertools.combinations(range(self.CONFIG[1]), self.base.CONFIG[1]))

    def solve_batch(self, F) -> np.ndarray:
        """Candidate roots (..., PATHS, N) of the base solver on a subset of the transmitters; NaN rows
        for candidates that a transmitter outside the subset rejects.

        The first subset is transmitters 1..n_base; an instance where no candidate passes (the base
        solver lost the true root's path, or ended it too far off for the filter) is solved again on
        the next subset (:meth:`subsets`), until one passes or all were tried (a pass is final when a
        candidate that passes is a real network; complex ones that pass are kept unless a later pass finds
        candidates of its own). A homotopy base goes
        through the subsets twice: its plain track alone first (:meth:`HomotopySolver.plain_roots`,
        a third of its full solve for 4r/5s), then its full solve. The roots describe the
        receivers only, so every subset's candidates are in the same unknowns. The filter is for exact
        data (relative tolerance :data:`FILTER_TOL`): on noisy data every subset is tried and nothing
        passes; measured networks go through :func:`solvers.api.solve_network`, which solves 4 x 6 data
        with the 4r/5s solver and refines on all measurements.
        """
        F = np.asarray(F, dtype=float)
        if F.shape[-2:] != self.CONFIG:
            raise ValueError(f"data of shape {F.shape} given; the solver needs (..., {self.CONFIG[0]}, {self.CONFIG[1]})")
        flat = F.reshape((-1,) + self.CONFIG)
        passes = [(subset, plain) for plain in ((True, False) if self._plain_pass() else (False,))
                  for subset in self.subsets()]
        out = self._filtered(flat, *passes[0])
        for subset, plain in passes[1:]:
            todo = np.flatnonzero(~np.any(_real_network(out), axis=-1))
            if not len(todo):
                break
            new = self._filtered(flat[todo], subset, plain)
            found = np.any(np.all(np.isfinite(new), axis=-1), axis=-1)
            out[todo[found]] = new[found]  # where this pass keeps nothing, the earlier candidates stay
        return out.reshape(F.shape[:-2] + out.shape[-2:])

    def _plain_pass(self) -> bool:
        """Whether the base solver has a plain pass (a homotopy: its plain track alone, no retracks)."""
        return getattr(self.base, "METHOD", None) == "homotopy" and hasattr(self.base, "solver")

    def _filtered(self, F: np.ndarray, subset: tuple[int, ...], plain: bool = False) -> np.ndarray:
        """The base solver's candidates (k, PATHS, N) on these transmitters of F (k, m, n), NaN rows for
        those that a further transmitter rejects. ``plain``: from its plain track alone (a first pass over
        every subset: the filter tells whether the true root was among the candidates; 4r/5s's plain track
        holds it on 95.6 % of seeded networks for a fraction of its full solve, tables/NOTES.md)."""
        if plain:
            roots = np.array(solve_scaled(self.base.solver(), F[..., list(subset)], self.base.CONFIG,
                                          self.base.SCALE_POWERS, plain=True))
        else:
            roots = np.array(self.base.solve_batch(F[..., list(subset)]))
        rec = receivers_from_orbits(roots)
        keep = np.ones(roots.shape[:-1], dtype=bool)
        for k in range(len(F)):
            for j in sorted(set(range(F.shape[-1])) - set(subset)):
                with np.errstate(all="ignore"):
                    keep[k] &= extra_transmitter_residuals(rec[k], F[k][:, j]) < FILTER_TOL
        roots[~keep] = np.nan
        for k, i in zip(*np.nonzero(keep)):
            roots[k, i] = polish_on_all(roots[k, i], F[k])
        return roots

    def solve(self, F) -> np.ndarray:
        return self.solve_batch(np.asarray(F)[None])[0]


def module_for(label: str):
    """A generated solver module, or the :class:`SubsystemSolver` of an over-determined configuration."""
    return SubsystemSolver(label) if label in SUBSYSTEMS else _module_for(label)

