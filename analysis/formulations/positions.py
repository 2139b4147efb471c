"""Positions formulations of 2D TDOA self-calibration: unknowns are coordinates (and offsets), not (H, b).

This module owns a second family of problem definitions, beside :mod:`analysis.formulations.tdoa` (the
paper's H, b, o formulation). The paper's formulation is positive-dimensional for m = 4 receivers
(tables/NOTES.md, cells 4/5 and 4/6), so the minimal problem 4r/5s and the over-determined 4r/6s need
equations written directly in the positions. Everything here is exact (sympy over ZZ, GF(p)); the
float paths exist only to check numeric solvers at a real root. This module never imports ``solvers``.

Problem. Measurements f_ij = |r_i - s_j| + o_j, receivers r_i (i = 1..m), transmitters s_j = (u_j, v_j)
(j = 1..n), offsets o_j; every equation below only involves (f_ij - o_j)^2 = |r_i - s_j|^2.

Gauge (paper Section 3): r_1 = 0 and r_2 = (x2, 0); receivers i >= 3 are r_i = (x_i, y_i). This leaves
the group Z2 x Z2 of the reflections y -> -y and x -> -x (their product is the rotation by pi): every
geometric solution appears 4 times, as sign changes of the coordinates (offsets are invariant). The
group is returned as sign vectors on the unknowns (:attr:`PositionsSystem.sign_group`).

Derivation. Subtracting the range equation of receiver 1 (r_1 = 0) from that of receiver i >= 2,

    (f_ij - o_j)^2 - (f_1j - o_j)^2 = |r_i|^2 - 2 r_i . s_j
    <=>  L_ij := a_ij - 2 delta_ij o_j + 2 r_i . s_j - |r_i|^2 = 0,
         a_ij = f_ij^2 - f_1j^2,  delta_ij = f_ij - f_1j,

which is LINEAR in (s_j, o_j) for known receivers. Together with the range of receiver 1,

    R_j := (f_1j - o_j)^2 - u_j^2 - v_j^2 = 0,

the m equations {R_j, L_2j..L_mj} are equivalent to the original m range equations of transmitter j.
The variants eliminate some of the linear unknowns:

``full``          unknowns receivers, offsets, transmitters ((2m-3) + 3n); equations R_j and L_ij
                  (m per transmitter, degrees 2). Exactly the original problem in this gauge; the only
                  nonzero condition is the gauge's x2 != 0 (r_2 != r_1).
``transmitters``  o_j eliminated with L_2j (its coefficient -2 delta_2j is data, nonzero for generic
                  data, so no denominator in the unknowns): unknowns receivers, transmitters
                  ((2m-3) + 2n); equations
                      T_j  := 4 delta_2j^2 R_j with o_j = (a_2j + 2 x2 u_j - x2^2) / (2 delta_2j),
                              i.e. (2 delta_2j f_1j - a_2j - 2 x2 u_j + x2^2)^2 - 4 delta_2j^2 (u_j^2 + v_j^2),
                      E_ij := delta_2j L_ij - delta_ij L_2j   (i = 3..m; o_j cancels),
                  degrees 4 and 2. Equivalent to ``full`` for data with f_2j != f_1j; nonzero: x2.
``offsets``       s_j eliminated with L_2j, L_3j (Cramer, denominator x2 y3): unknowns receivers,
                  offsets ((2m-3) + n); with c_ij = |r_i|^2 - a_ij + 2 delta_ij o_j (so L_ij = 2 r_i.s_j - c_ij),
                      u_j = c_2j / (2 x2),  v_j = (x2 c_3j - x3 c_2j) / (2 x2 y3),
                      P_j  := 4 x2^2 y3^2 R_j = 4 x2^2 y3^2 (f_1j - o_j)^2 - y3^2 c_2j^2 - (x2 c_3j - x3 c_2j)^2,
                      K_ij := x_i y3 c_2j + y_i (x2 c_3j - x3 c_2j) - x2 y3 c_ij   (i = 4..m; x2 y3 L_ij),
                  degrees 6 and 4; saturate by x2 y3 (r_1, r_2, r_3 not collinear).
``receivers``     (s_j, o_j) eliminated with L_2j, L_3j, L_4j (Cramer on A_j w = g_j with rows
                  A_j[i] = (x_i, y_i, -delta_ij), g_ij = (|r_i|^2 - a_ij) / 2, w = (u_j, v_j, o_j)):
                  unknowns the 2m-3 receiver coordinates only; with D_j = det A_j and N_j = adj(A_j) g_j,
                  w = N_j / D_j, and R_j times D_j^2 (then times 4 to keep integer coefficients):
                      Q_j  := (2 f_1j D_j - 2 N_oj)^2 - (2 N_uj)^2 - (2 N_vj)^2,
                      G_ij := x_i 2N_uj + y_i 2N_vj - delta_ij 2N_oj - D_j 2g_ij   (i = 5..m; = D_j L_ij),
                  degrees 8 and 4 (m = 4: 5 equations in 5 unknowns for 4r/5s); saturate by x2 prod D_j.
``receivers-orbits``  the ``receivers`` variant in invariants of the sign group: X = x2^2, Y = y3^2,
                  xi_i = x_i / x2 (i >= 3), eta_i = y_i / y3 (i >= 4). With A_j = A~_j diag(x2, y3, 1),
                  A~_j rows (xi_i, eta_i, -delta_ij) (xi_2 = 1, eta_2 = 0, eta_3 = 1), D_j = x2 y3 D~_j and
                  M_j = adj(A~_j) 2g_j = 2 D~_j (x2 u_j, y3 v_j, o_j):
                      W_j  := X Y (2 f_1j D~_j - M_oj)^2 - Y M_uj^2 - X M_vj^2,
                      V_ij := xi_i M_uj + eta_i M_vj - delta_ij M_oj - D~_j 2g_ij   (i = 5..m; = D~_j L_ij),
                  degrees 10 and 5; saturate by X Y prod D~_j. One unknown vector per geometric solution
                  (x2 = sqrt X, y3 = sqrt Y: the 4 sign choices are the orbit); trivial sign group.
``dual``          the receivers eliminated instead (natural for m > n), in the gauge r_1 = 0, s_1 = (u1, 0)
                  (rotation fixed on transmitter 1 instead of receiver 2; :func:`network_from_root`
                  rotates back to r_2 = (x2, 0)). With c_ij = 2 delta_ij o_j - a_ij (so L_ij =
                  2 r_i.s_j - |r_i|^2 - c_ij), e_ij = c_ij - c_i1 and S = [s_2 - s_1, s_3 - s_1]:
                  L_ij - L_i1 gives 2 S^T r_i = (e_i2, e_i3), so r_i = rho_i / (2P), P = det S,
                  rho_i = adj(S^T) (e_i2, e_i3). Unknowns o_1..o_n, u1, (u_j, v_j) j >= 2 (3n - 1);
                      R_j,
                      J_i  := 4 P^2 L_i1 = 4 P u1 rho_ix - |rho_i|^2 - 4 P^2 c_i1          (i = 2..m),
                      H_ij := P (L_ij - L_i1) = rho_i . (s_j - s_1) - P e_ij              (i = 2..m, j >= 4),
                  degrees 2, 5, 3; saturate by P u1. The sign group acts on (u, v) as before.
``dual-orbits``   ``dual`` in invariants: U = u1^2, V = v2^2, alpha_j = u_j / u1 (j >= 2), beta_j = v_j / v2
                  (j >= 3); P = u1 v2 P~, rho_x = v2 rho~_x, rho_y = u1 rho~_y, and
                      R_j = (f_1j - o_j)^2 - U alpha_j^2 - V beta_j^2,
                      J_i  = 4 U V P~ rho~_x - V rho~_x^2 - U rho~_y^2 - 4 U V P~^2 c_i1   (the same J_i),
                      H_ij / (u1 v2) = rho~_x (alpha_j - 1) + rho~_y beta_j - P~ e_ij,
                  degrees 3, 7, 3; saturate by U V P~. For n = 3 the unknowns (U, V, alpha, beta, o)
                  are the O(2) invariants of the paper's (H, b, o) up to a change of chart: H =
                  (4 S^T S)^-1 and b = -S^-1 s_1 / 2 make J_i the paper's C equation and R_1..R_3 its
                  A, B2, B3 (paper Section 2.1), so 6r/3s must give the paper's 180 (saturated).

Why the eliminations lose no solution. Every complex solution of ``full`` is a network (r, s, o) in the
gauge that produces F. The networks with D_j = 0, x2 = 0, P = 0, u1 = 0 or y3 = 0 form proper
subvarieties of the (2m + 3n - 3)-dimensional network space, so for a minimal configuration their
images under the measurement map are proper subvarieties of the data space: a generic F has no such
solution, and on the complement each elimination is an isomorphism (Cramer). Hence, for generic data,
the saturated degree of every variant is the number of networks in its gauge (4 per geometric
solution: the sign group acts freely when x2 y3 != 0), and the orbit variants give the number of
geometric solutions directly. Measured counts: tables/minimal_problems.md.

Counting: 4r/5s is minimal (20 measurements, 2*4 + 3*5 - 3 = 20 degrees of freedom); ``full``,
``transmitters``, ``offsets``, ``receivers``, ``dual`` and the orbit variants are all square for
minimal configurations. Equations only involve (f_ij - o_j)^2, so solutions with f_ij - o_j < 0
("negative ranges") are solutions all the same.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import Callable, Literal, Sequence

import numpy as np
import sympy
from sympy.polys.rings import PolyElement
from sympy.polys.rings import ring as poly_ring

from .tdoa import InconsistentSample, SamplingFailed, _powmod_vec, _rng, sqrt_mod
from ..engine.ring import Poly, Ring, check_prime

__all__ = [
    "VARIANTS",
    "PositionsSystem",
    "positions_system",
    "gf_system",
    "evaluate_gf",
    "evaluate_real",
    "sample_gf_positions",
    "sample_real_positions",
    "network_from_root",
    "apply_sign",
]

Variant = Literal["full", "transmitters", "offsets", "receivers", "receivers-orbits", "dual", "dual-orbits"]
VARIANTS: tuple[str, ...] = ("full", "transmitters", "offsets", "receivers", "receivers-orbits", "dual", "dual-orbits")
ORBIT_VARIANTS: tuple[str, ...] = ("receivers-orbits", "dual-orbits")
"""Variants whose unknowns are invariants of the sign group (one unknown vector per geometric solution)."""


@dataclass(frozen=True)
class PositionsSystem:
    """A positions formulation for m receivers and n transmitters (see the module docstring).

    Attributes
    ----------
    m, n, variant : configuration and variant name (one of :data:`VARIANTS`).
    unknowns : unknown names, in order (``x2, x3, y3, ..., xm, ym`` then ``o1..on`` and/or ``u1, v1, ...``).
    parameters : data names ``f<i>_<j>`` (1-based, row-major: receiver i, transmitter j), the same
        symbols as :func:`analysis.formulations.tdoa.data_symbols`.
    equation_names : one name per equation (``R3``, ``L2_3``, ``T1``, ``E3_1``, ``P2``, ``K4_2``, ``Q5``, ...).
    equations : polynomial sympy expressions in unknowns and parameters (denominators cleared).
    saturate_by : sympy expressions in the unknowns (and parameters) that are nonzero at every
        geometric solution for generic data; the solution set is V(equations) minus their zeros.
    saturate_names : a short name for each (``D3`` = det A_3, ``x2``, ``P`` = det S, ...).
    sign_group : the Z2 x Z2 gauge symmetry as sign vectors on the unknowns (identity first); each maps
        solutions to solutions for every data matrix.
    """

    m: int
    n: int
    variant: str
    unknowns: tuple[str, ...]
    parameters: tuple[str, ...]
    equation_names: tuple[str, ...]
    saturate_names: tuple[str, ...]
    sign_group: tuple[tuple[int, ...], ...]
    _polys: tuple = ()  # ZZ[unknowns, parameters] elements of the equations, then of saturate_by

    @cached_property
    def equations(self) -> tuple[sympy.Expr, ...]:
        """The equations as expanded sympy expressions (converted on first use: ~1 s for 4r/5s receivers)."""
        return tuple(q.as_expr() for q in self._polys[: len(self.equation_names)])

    @cached_property
    def saturate_by(self) -> tuple[sympy.Expr, ...]:
        return tuple(q.as_expr() for q in self._polys[len(self.equation_names):])

    @property
    def label(self) -> str:
        return f"{self.m}r{self.n}s:positions-{self.variant}"

    @property
    def n_unknowns(self) -> int:
        return len(self.unknowns)

    @property
    def n_equations(self) -> int:
        return len(self.equation_names)

    @property
    def degrees(self) -> tuple[int, ...]:
        """Total degree of each equation in the unknowns."""
        k = self.n_unknowns
        return tuple(max(sum(e[:k]) for e in p.monoms()) for p in self._polys[: self.n_equations])

    def unknown_index(self, name: str) -> int:
        return self.unknowns.index(name)


def _receiver_names(m: int) -> list[str]:
    names = ["x2"]
    for i in range(3, m + 1):
        names += [f"x{i}", f"y{i}"]
    return names


def _check_config(m: int, n: int, variant: str) -> None:
    if variant not in VARIANTS:
        raise ValueError(f"unknown variant {variant!r}; valid: {', '.join(VARIANTS)}")
    if variant in ("dual", "dual-orbits") and n < 3:
        raise ValueError(f"variant {variant!r} eliminates receivers with transmitters 1-3: needs n >= 3")
    if m < 3 or n < 1:
        raise ValueError(f"need m >= 3 receivers and n >= 1 transmitters, got {m}r{n}s")
    if variant in ("receivers", "receivers-orbits") and m < 4:
        raise ValueError(f"variant {variant!r} eliminates (s_j, o_j) with receivers 2-4: needs m >= 4")


def positions_system(m: int, n: int, variant: Variant = "full") -> PositionsSystem:
    """Build the positions formulation ``variant`` for m receivers and n transmitters.

    Parameters
    ----------
    m : receivers, m >= 3 (m >= 4 for ``receivers``).
    n : transmitters, n >= 1.
    variant : ``"full"``, ``"transmitters"``, ``"offsets"`` or ``"receivers"`` (module docstring).

    Returns a :class:`PositionsSystem` (cached per arguments; sympy expressions are immutable).
    """
    _check_config(m, n, variant)
    return _build(m, n, variant)


@lru_cache(maxsize=None)
def _build(m: int, n: int, variant: str) -> PositionsSystem:
    rec = _receiver_names(m)
    offs = [f"o{j}" for j in range(1, n + 1)]
    tra = [name for j in range(1, n + 1) for name in (f"u{j}", f"v{j}")]
    orb = ["X", "Y", "xi3"] + [name for i in range(4, m + 1) for name in (f"xi{i}", f"eta{i}")]
    unknowns = {
        "full": rec + offs + tra,
        "transmitters": rec + tra,
        "offsets": rec + offs,
        "receivers": rec,
        "receivers-orbits": orb,
        "dual": offs + [name for name in tra if name != "v1"],
        "dual-orbits": offs + ["U"] + [f"alpha{j}" for j in range(2, n + 1)] + ["V"] + [f"beta{j}" for j in range(3, n + 1)],
    }[variant]
    params = [f"f{i}_{j}" for i in range(1, m + 1) for j in range(1, n + 1)]
    R, *gens = poly_ring(unknowns + params, sympy.ZZ)
    sym = dict(zip(unknowns + params, gens))
    zero = R.zero

    one = R.one

    def x(i: int):
        return zero if i == 1 else sym[f"x{i}"]

    def y(i: int):
        return zero if i <= 2 else sym[f"y{i}"]

    def xi(i: int):  # x_i / x2
        return one if i == 2 else sym[f"xi{i}"]

    def eta(i: int):  # y_i / y3
        return zero if i == 2 else one if i == 3 else sym[f"eta{i}"]

    def f(i: int, j: int):
        return sym[f"f{i}_{j}"]

    def a(i: int, j: int):
        return f(i, j) ** 2 - f(1, j) ** 2

    def delta(i: int, j: int):
        return f(i, j) - f(1, j)

    def norm2(i: int):
        if variant == "receivers-orbits":
            return sym["X"] * xi(i) ** 2 + sym["Y"] * eta(i) ** 2
        return x(i) ** 2 + y(i) ** 2

    names: list[str] = []
    polys: list[PolyElement] = []
    sat: list[PolyElement] = []
    sat_names: list[str] = []
    if variant in ("dual", "dual-orbits"):
        _dual_equations(m, n, sym, f, a, delta, names, polys, sat, orbits=variant == "dual-orbits")
        sat_names.extend(["U*V*P~"] if variant == "dual-orbits" else ["P", "u1"])
    for j in range(1, n + 1 if variant not in ("dual", "dual-orbits") else 1):
        if variant in ("full", "transmitters"):
            u, v = sym[f"u{j}"], sym[f"v{j}"]
        if variant in ("full", "offsets"):
            o = sym[f"o{j}"]
        if variant == "full":
            names.append(f"R{j}")
            polys.append((f(1, j) - o) ** 2 - u**2 - v**2)
            for i in range(2, m + 1):
                names.append(f"L{i}_{j}")
                polys.append(a(i, j) - 2 * delta(i, j) * o + 2 * (x(i) * u + y(i) * v) - norm2(i))
        elif variant == "transmitters":
            def L(i: int):  # L_ij with o_j's term kept apart: L = rest - 2 delta o
                return a(i, j) + 2 * (x(i) * u + y(i) * v) - norm2(i)

            d2 = delta(2, j)
            names.append(f"T{j}")
            polys.append((2 * d2 * f(1, j) - L(2)) ** 2 - 4 * d2**2 * (u**2 + v**2))
            for i in range(3, m + 1):
                names.append(f"E{i}_{j}")
                polys.append(d2 * L(i) - delta(i, j) * L(2))
        elif variant == "offsets":
            def c(i: int):
                return norm2(i) - a(i, j) + 2 * delta(i, j) * o

            x2, x3, y3 = x(2), x(3), y(3)
            names.append(f"P{j}")
            polys.append(4 * x2**2 * y3**2 * (f(1, j) - o) ** 2 - y3**2 * c(2) ** 2 - (x2 * c(3) - x3 * c(2)) ** 2)
            for i in range(4, m + 1):
                names.append(f"K{i}_{j}")
                polys.append(x(i) * y3 * c(2) + y(i) * (x2 * c(3) - x3 * c(2)) - x2 * y3 * c(i))
        elif variant == "receivers-orbits":
            if j == 1:
                orbit_names, orbit_polys, orbit_sat = receivers_orbits_equations(
                    m, n, [sym[u] for u in unknowns], lambda i, k: sym[f"f{i}_{k}"], zero, one)
                names += orbit_names
                polys += orbit_polys
                sat += orbit_sat
                sat_names += [f"D~{k}" for k in range(1, n + 1)]
        else:  # receivers
            A = [[x(i), y(i), -delta(i, j)] for i in (2, 3, 4)]
            g2 = [norm2(i) - a(i, j) for i in (2, 3, 4)]  # 2 g_ij
            D = _det3(A)
            adj = _adjugate3(A)
            # N = adj(A) g with g = g2 / 2; keep integers: N2 = adj(A) g2 = 2 N
            N2 = [sum((adj[k][l] * g2[l] for l in range(3)), zero) for k in range(3)]
            # Q = (f D - N_o)^2 - N_u^2 - N_v^2, times 4: (2 f D - N2_o)^2 - N2_u^2 - N2_v^2
            names.append(f"Q{j}")
            polys.append((2 * f(1, j) * D - N2[2]) ** 2 - N2[0] ** 2 - N2[1] ** 2)
            for i in range(5, m + 1):
                names.append(f"G{i}_{j}")
                # x_i N2_u + y_i N2_v - delta N2_o - D (2 g_i) = D L_ij  (N2 = 2 D w)
                polys.append(x(i) * N2[0] + y(i) * N2[1] - delta(i, j) * N2[2] - D * (norm2(i) - a(i, j)))
            sat.append(D)
            sat_names.append(f"D{j}")
    if variant == "offsets":
        sat.append(x(2) * y(3))
        sat_names.append("x2*y3")
    if variant in ("receivers", "transmitters", "full"):
        sat.append(x(2))
        sat_names.append("x2")
    if variant == "receivers-orbits":
        sat.append(sym["X"] * sym["Y"])
        sat_names.append("X*Y")
    group = _sign_group(unknowns) if variant not in ORBIT_VARIANTS else ((1,) * len(unknowns),)
    return PositionsSystem(m, n, variant, tuple(unknowns), tuple(params), tuple(names), tuple(sat_names), group,
                           tuple(polys) + tuple(sat))


def _dual_equations(m, n, sym, f, a, delta, names, polys, sat, orbits: bool) -> None:
    """Equations of variants ``dual`` and ``dual-orbits`` (receivers eliminated linearly, gauge v1 = 0).

    ``dual``: (ut, vt) = (u, v), wU = wV = 1. ``dual-orbits``: u_j = u1 alpha_j, v_j = v2 beta_j
    (alpha_1 = 1, beta_1 = 0, beta_2 = 1), (ut, vt) = (alpha, beta), wU = U = u1^2, wV = V = v2^2; then
    P = u1 v2 P~, rho_x = v2 rho~_x, rho_y = u1 rho~_y, and each equation is the ``dual`` one divided
    by a monomial in u1, v2 (J_i by 1, H_ij by u1 v2; module docstring).
    """
    one = sym["o1"] ** 0
    zero = 0 * one
    o = {j: sym[f"o{j}"] for j in range(1, n + 1)}
    if orbits:
        wU, wV = sym["U"], sym["V"]
        ut = {j: (sym[f"alpha{j}"] if j > 1 else one) for j in range(1, n + 1)}
        vt = {j: (sym[f"beta{j}"] if j > 2 else one if j == 2 else zero) for j in range(1, n + 1)}
    else:
        wU = wV = one
        ut = {j: sym[f"u{j}"] for j in range(1, n + 1)}
        vt = {j: (sym[f"v{j}"] if j > 1 else zero) for j in range(1, n + 1)}
    # S = [s2 - s1, s3 - s1] (columns), P = det S; S^T r_i = (e_i2, e_i3) / 2
    s11, s21 = ut[2] - ut[1], vt[2] - vt[1]
    s12, s22 = ut[3] - ut[1], vt[3] - vt[1]
    P = s11 * s22 - s12 * s21
    for j in range(1, n + 1):
        names.append(f"R{j}")
        polys.append((f(1, j) - o[j]) ** 2 - wU * ut[j] ** 2 - wV * vt[j] ** 2)
    for i in range(2, m + 1):
        def c(j: int):  # L_ij = 2 r_i.s_j - |r_i|^2 - c(j)
            return 2 * delta(i, j) * o[j] - a(i, j)

        e2, e3 = c(2) - c(1), c(3) - c(1)
        # (S^T)^{-1} = adj(S^T) / P with adj(S^T) = [[s22, -s21], [-s12, s11]]: r_i = rho / (2 P)
        rho_x, rho_y = s22 * e2 - s21 * e3, -s12 * e2 + s11 * e3
        names.append(f"J{i}")
        polys.append(4 * wU * wV * P * rho_x * ut[1] - wV * rho_x**2 - wU * rho_y**2 - 4 * wU * wV * P**2 * c(1))
        for j in range(4, n + 1):
            names.append(f"H{i}_{j}")
            polys.append(rho_x * (ut[j] - ut[1]) + rho_y * (vt[j] - vt[1]) - P * (c(j) - c(1)))
    if orbits:
        sat.append(wU * wV * P)
    else:
        sat.append(P)
        sat.append(ut[1])


def receivers_orbits_equations(m: int, n: int, unknowns: Sequence, f: Callable, zero, one) -> tuple[list[str], list, list]:
    """The ``receivers-orbits`` equations on any values with ring arithmetic (+, -, *, integer powers
    and integer factors): sympy ring elements, or the values of a straight-line program (which keeps
    the determinants and adjugates unexpanded).

    ``unknowns``: values of X, Y, xi3, then xi_i, eta_i (i = 4..m), the variant's order; ``f(i, j)``:
    the datum f_ij (1-based); ``zero``, ``one``: the constants. Returns the equation names
    (W_j, V_ij per transmitter j), the equations and the denominators D~_j (module docstring).
    """
    X, Y, xi3, *rest = unknowns
    xi = {2: one, 3: xi3, **{i: rest[2 * (i - 4)] for i in range(4, m + 1)}}  # x_i / x2
    eta = {2: zero, 3: one, **{i: rest[2 * (i - 4) + 1] for i in range(4, m + 1)}}  # y_i / y3
    norm2 = {i: X * xi[i] ** 2 + Y * eta[i] ** 2 for i in range(2, m + 1)}
    names: list[str] = []
    polys: list = []
    dets: list = []
    for j in range(1, n + 1):
        def delta(i: int):
            return f(i, j) - f(1, j)

        def a(i: int):
            return f(i, j) ** 2 - f(1, j) ** 2

        A = [[xi[i], eta[i], -delta(i)] for i in (2, 3, 4)]  # A_j = A'_j diag(x2, y3, 1)
        g2 = [norm2[i] - a(i) for i in (2, 3, 4)]
        D = _det3(A)
        adj = _adjugate3(A)
        M2 = [sum((adj[k][l] * g2[l] for l in range(3)), zero) for k in range(3)]  # 2 D' (x2 u, y3 v, o)
        names.append(f"W{j}")
        polys.append(X * Y * (2 * f(1, j) * D - M2[2]) ** 2 - Y * M2[0] ** 2 - X * M2[1] ** 2)
        for i in range(5, m + 1):
            names.append(f"V{i}_{j}")
            polys.append(xi[i] * M2[0] + eta[i] * M2[1] - delta(i) * M2[2] - D * (norm2[i] - a(i)))
        dets.append(D)
    return names, polys, dets


def _det3(A) -> PolyElement:
    return (A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1])
            - A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0])
            + A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0]))


def _adjugate3(A) -> list[list]:
    """adj(A) with A adj(A) = det(A) I (transpose of the cofactor matrix)."""
    cof = [[None] * 3 for _ in range(3)]
    for r in range(3):
        for c in range(3):
            rows = [k for k in range(3) if k != r]
            cols = [k for k in range(3) if k != c]
            minor = A[rows[0]][cols[0]] * A[rows[1]][cols[1]] - A[rows[0]][cols[1]] * A[rows[1]][cols[0]]
            cof[r][c] = minor if (r + c) % 2 == 0 else -minor
    return [[cof[c][r] for c in range(3)] for r in range(3)]


def _sign_group(unknowns: Sequence[str]) -> tuple[tuple[int, ...], ...]:
    """Sign vectors of {identity, y -> -y, x -> -x, rotation by pi} on the unknowns."""
    out = []
    for sx, sy in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
        out.append(tuple(sx if name[0] in "xu" else sy if name[0] in "yv" else 1 for name in unknowns))
    return tuple(out)


def apply_sign(root: Sequence, sign: Sequence[int], p: int | None = None) -> tuple:
    """Image of a root under a sign vector (over GF(p) when p is given)."""
    if p is None:
        return tuple(s * r for s, r in zip(sign, root))
    return tuple((s * int(r)) % p for s, r in zip(sign, root))


# --------------------------------------------------------------------------------------------------
# Specialising to data: GF(p) and real evaluation
# --------------------------------------------------------------------------------------------------


def _data_values(system: PositionsSystem, F) -> list:
    F = [list(r) for r in F]
    if len(F) != system.m or any(len(r) != system.n for r in F):
        raise ValueError(f"data must be {system.m} x {system.n} (receivers x transmitters)")
    return [F[i][j] for i in range(system.m) for j in range(system.n)]


def _specialise_gf(poly: PolyElement, k: int, values: Sequence[int], p: int) -> dict[tuple[int, ...], int]:
    """{exponent in the k unknowns: coefficient mod p} of a ZZ[unknowns, params] polynomial at params."""
    out: dict[tuple[int, ...], int] = {}
    for exp, c in poly.terms():
        term = int(c) % p
        for val, e in zip(values, exp[k:]):
            if e:
                term = term * pow(val, e, p) % p
        if term:
            key = exp[:k]
            out[key] = (out.get(key, 0) + term) % p
    return {e: c for e, c in out.items() if c}


def gf_system(system: PositionsSystem, F, p: int, order: str = "grevlex") -> tuple[list[Poly], list[Poly]]:
    """(equations, saturating polynomials) over GF(p) for the data matrix F (m x n integers).

    Both are :class:`analysis.engine.ring.Poly` in one ring over the unknowns (``order``: any order the
    ring accepts).
    """
    p = check_prime(p)
    ring = Ring(system.unknowns, p, order)
    values = [int(v) % p for v in _data_values(system, F)]
    k = system.n_unknowns
    polys = [ring.from_terms(_specialise_gf(q, k, values, p)) for q in system._polys]
    return polys[: system.n_equations], polys[system.n_equations:]


def evaluate_gf(system: PositionsSystem, F, root: Sequence[int], p: int) -> tuple[list[int], list[int]]:
    """(equation values, saturating-polynomial values) mod p at a point, for data F."""
    values = [int(v) % p for v in _data_values(system, F)]
    point = [int(r) % p for r in root] + values
    out = []
    for q in system._polys:
        total = 0
        for exp, c in q.terms():
            term = int(c) % p
            for val, e in zip(point, exp):
                if e:
                    term = term * pow(val, e, p) % p
            total += term
        out.append(total % p)
    return out[: system.n_equations], out[system.n_equations:]


def evaluate_real(system: PositionsSystem, F, root: Sequence) -> tuple[np.ndarray, np.ndarray]:
    """(equation values, relative residuals |value| / sum|terms|) at a real or complex point."""
    point = list(root) + [float(v) for v in _data_values(system, F)]
    vals, rel = [], []
    for q in system._polys[: system.n_equations]:
        total, scale = 0.0, 0.0
        for exp, c in q.terms():
            term = complex(int(c))
            for val, e in zip(point, exp):
                if e:
                    term *= val**e
            total += term
            scale += abs(term)
        vals.append(total)
        rel.append(abs(total) / max(scale, np.finfo(float).tiny))
    vals = np.array(vals)
    if np.all(np.isreal(vals)):
        vals = vals.real
    return vals, np.array(rel)


# --------------------------------------------------------------------------------------------------
# Instances with a known root
# --------------------------------------------------------------------------------------------------


def _root_from_network(system: PositionsSystem, receivers, transmitters, offsets, p: int | None = None) -> tuple:
    """The root in the unknowns of ``system`` for a network already in the gauge (over GF(p) if p)."""
    value = {"x2": receivers[1][0]}
    for i in range(3, system.m + 1):
        value[f"x{i}"], value[f"y{i}"] = receivers[i - 1][0], receivers[i - 1][1]
    if system.variant == "dual-orbits":
        u1, v2 = transmitters[0][0], transmitters[1][1]
        inv_u1, inv_v2 = (1.0 / u1, 1.0 / v2) if p is None else (pow(int(u1), -1, p), pow(int(v2), -1, p))
        value["U"], value["V"] = u1 * u1, v2 * v2
        for j in range(2, system.n + 1):
            value[f"alpha{j}"] = transmitters[j - 1][0] * inv_u1
            value[f"beta{j}"] = transmitters[j - 1][1] * inv_v2
    if system.variant == "receivers-orbits":
        x2, y3 = receivers[1][0], receivers[2][1]
        if p is None:
            inv_x2, inv_y3 = 1.0 / x2, 1.0 / y3
        else:
            inv_x2, inv_y3 = pow(int(x2), -1, p), pow(int(y3), -1, p)
        value["X"], value["Y"] = x2 * x2, y3 * y3
        for i in range(3, system.m + 1):
            value[f"xi{i}"] = receivers[i - 1][0] * inv_x2
            value[f"eta{i}"] = receivers[i - 1][1] * inv_y3
    for j in range(1, system.n + 1):
        value[f"o{j}"] = offsets[j - 1]
        value[f"u{j}"], value[f"v{j}"] = transmitters[j - 1][0], transmitters[j - 1][1]
    return tuple(value[name] for name in system.unknowns)


def sample_gf_positions(m: int, n: int, p: int, rng: "np.random.Generator | int", variant: Variant = "full", *,
                        max_tries: int = 200) -> tuple[tuple[tuple[int, ...], ...], tuple[int, ...]]:
    """A consistent random GF(p) instance in the gauge r_1 = 0, r_2 = (x2, 0), and its known root.

    Draws receivers (x2 and r_3..r_m uniform in GF(p)), then each transmitter uniformly among the
    points whose squared distances to all receivers are nonzero quadratic residues, then offsets
    uniform in GF(p); f_ij = sqrt(d_ij^2) + o_j (the smaller square root). The draw is repeated until
    the instance is generic for the variant (f_2j != f_1j, every saturating polynomial nonzero at the
    root). Returns (F as m x n nested tuples, root in ``positions_system(m, n, variant).unknowns``).
    Raises :class:`SamplingFailed` (naming the seed) or :class:`InconsistentSample` (a bug).
    """
    system = positions_system(m, n, variant)
    p = check_prime(p)
    gen, seed_text = _rng(rng)
    half = (p - 1) // 2
    dual = variant in ("dual", "dual-orbits")
    for _ in range(max_tries):
        receivers = np.zeros((m, 2), dtype=np.int64)
        receivers[1, 0] = gen.integers(1, p)
        receivers[2:] = gen.integers(0, p, size=(m - 2, 2))
        if dual:  # gauge s_1 = (u1, 0) instead of r_2 = (x2, 0)
            receivers[1, 1] = gen.integers(0, p)
        transmitters = []
        for j in range(n):
            for _b in range(200):
                cand = gen.integers(0, p, size=(256, 2))
                if dual and j == 0:
                    cand[:, 1] = 0
                dx = (cand[:, None, 0] - receivers[None, :, 0]) % p
                dy = (cand[:, None, 1] - receivers[None, :, 1]) % p
                d2 = (dx * dx % p + dy * dy % p) % p
                ok = np.flatnonzero(np.all((d2 != 0) & (_powmod_vec(d2, half, p) == 1), axis=1))
                if ok.size:
                    transmitters.append(cand[ok[0]])
                    break
            else:
                raise SamplingFailed(f"no transmitter with residue distances mod {p} ({m}r{n}s, {seed_text})")
        offsets = gen.integers(0, p, size=n)
        rec = [(int(a) % p, int(b) % p) for a, b in receivers]
        tra = [(int(a), int(b)) for a, b in transmitters]
        offs = [int(o) for o in offsets]
        F = tuple(tuple((sqrt_mod((rx - sx) ** 2 + (ry - sy) ** 2, p) + o) % p for (sx, sy), o in zip(tra, offs))
                  for rx, ry in rec)
        if any(F[1][j] == F[0][j] for j in range(n)):
            continue
        if not dual and rec[1][0] * rec[2][1] % p == 0:
            continue
        if dual and tra[0][0] * tra[1][1] % p == 0:
            continue
        root = tuple(int(v) % p for v in _root_from_network(system, rec, tra, offs, p))
        eq_values, sat_values = evaluate_gf(system, F, root, p)
        if any(v == 0 for v in sat_values):
            continue
        if any(eq_values):
            bad = [nm for nm, v in zip(system.equation_names, eq_values) if v]
            raise InconsistentSample(f"known root fails {', '.join(bad)} of {system.label} mod {p} ({seed_text})")
        return F, root
    raise SamplingFailed(f"no generic instance of {system.label} mod {p} after {max_tries} draws ({seed_text})")


def _to_gauge(receivers: np.ndarray, transmitters: np.ndarray, dual: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Translate r_1 to 0 and rotate r_2 (``dual``: s_1) onto the positive x axis."""
    t = receivers[0].copy()
    rec, tra = receivers - t, transmitters - t
    rec, tra = _rotate_onto_x(rec, tra, tra[0] if dual else rec[1])
    rec[0] = 0.0
    if dual:
        tra[0, 1] = 0.0
    else:
        rec[1, 1] = 0.0
    return rec, tra


def _rotate_onto_x(rec: np.ndarray, tra: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotate everything by Q with Q w = (|w|, 0); for complex w, |w| = sqrt(w . w) (Q^T Q = I still)."""
    norm = np.sqrt(w[0] * w[0] + w[1] * w[1] + (0j if np.iscomplexobj(w) else 0.0))
    Q = np.array([[w[0], w[1]], [-w[1], w[0]]]) / norm
    return rec @ Q.T, tra @ Q.T


def sample_real_positions(m: int, n: int, rng: "np.random.Generator | int", variant: Variant = "full",
                          scale: float = 10.0, offset_scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A random real instance (paper Section 4: positions N(0, scale^2), offsets N(0, offset_scale^2)).

    The network is moved into the gauge r_1 = 0, r_2 = (x2, 0) with x2 > 0 (``dual``: s_1 = (u1, 0),
    u1 > 0); distances are unchanged.
    Returns (F, an m x n array; root in ``positions_system(m, n, variant).unknowns``, float64).
    """
    system = positions_system(m, n, variant)
    gen, _ = _rng(rng)
    receivers = gen.normal(0.0, scale, size=(m, 2))
    transmitters = gen.normal(0.0, scale, size=(n, 2))
    offsets = gen.normal(0.0, offset_scale, size=n)
    rec, tra = _to_gauge(receivers, transmitters, dual=variant in ("dual", "dual-orbits"))
    F = np.linalg.norm(rec[:, None, :] - tra[None, :, :], axis=2) + offsets[None, :]
    root = np.array(_root_from_network(system, rec, tra, offsets), dtype=float)
    return F, root


def _principal_sqrt(z):
    """sqrt of a real positive number as a float, of anything else as a complex number."""
    if not np.iscomplexobj(z) and z > 0:
        return np.sqrt(z)
    return np.sqrt(complex(z))


def network_from_root(system: PositionsSystem, root: Sequence, F) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(receivers (m, 2), transmitters (n, 2), offsets (n,)) of a root, in the gauge r_1 = 0, r_2 = (x2, 0).

    Eliminated unknowns are recovered as in the derivation (module docstring): o_j from L_2j
    (``transmitters``), s_j by Cramer on L_2j, L_3j (``offsets``), (s_j, o_j) by solving L_2j..L_4j
    (``receivers``). Values may be complex (complex roots); the dtype follows the root.
    """
    root = np.asarray(root)
    dtype = np.result_type(root.dtype, np.float64)
    F = np.asarray(F, dtype=dtype)
    m, n = system.m, system.n
    value = dict(zip(system.unknowns, root))
    rec = np.zeros((m, 2), dtype=dtype)
    if system.variant in ("dual", "dual-orbits"):
        offs = np.array([value[f"o{j}"] for j in range(1, n + 1)], dtype=dtype)
        if system.variant == "dual":
            tra = np.array([(value[f"u{j}"], value.get(f"v{j}", 0.0)) for j in range(1, n + 1)], dtype=dtype)
        else:  # one representative of the orbit: principal square roots
            u1, v2 = _principal_sqrt(value["U"]), _principal_sqrt(value["V"])
            dtype = np.result_type(dtype, u1, v2)
            alpha = [1.0] + [value[f"alpha{j}"] for j in range(2, n + 1)]
            beta = [0.0, 1.0] + [value[f"beta{j}"] for j in range(3, n + 1)]
            tra = np.array([(al * u1, be * v2) for al, be in zip(alpha, beta)], dtype=dtype)
            offs, F, rec = offs.astype(dtype), F.astype(dtype), rec.astype(dtype)
        c = 2 * (F - F[0]) * offs[None, :] - (F**2 - F[0] ** 2)  # c_ij, L_ij = 2 r_i.s_j - |r_i|^2 - c_ij
        St = np.array([tra[1] - tra[0], tra[2] - tra[0]])  # S^T
        for i in range(1, m):
            rec[i] = np.linalg.solve(2 * St, [c[i, 1] - c[i, 0], c[i, 2] - c[i, 0]])
        rec, tra = _rotate_onto_x(rec, tra, rec[1])  # back to the gauge r_2 = (x2, 0)
        rec[1, 1] = 0.0
        return rec, tra, offs
    if system.variant == "receivers-orbits":  # one representative of the orbit: principal square roots
        x2, y3 = _principal_sqrt(value["X"]), _principal_sqrt(value["Y"])
        dtype = np.result_type(dtype, x2, y3)
        rec = rec.astype(dtype)
        rec[1, 0] = x2
        rec[2] = (value["xi3"] * x2, y3)
        for i in range(4, m + 1):
            rec[i - 1] = (value[f"xi{i}"] * x2, value[f"eta{i}"] * y3)
        F = F.astype(dtype)
    else:
        rec[1, 0] = value["x2"]
        for i in range(3, m + 1):
            rec[i - 1] = (value[f"x{i}"], value[f"y{i}"])
    tra = np.zeros((n, 2), dtype=dtype)
    offs = np.zeros(n, dtype=dtype)
    norm2 = rec[:, 0] ** 2 + rec[:, 1] ** 2
    for j in range(n):
        a = F[:, j] ** 2 - F[0, j] ** 2
        delta = F[:, j] - F[0, j]
        if system.variant in ("full", "transmitters"):
            tra[j] = (value[f"u{j + 1}"], value[f"v{j + 1}"])
        if system.variant in ("full", "offsets"):
            offs[j] = value[f"o{j + 1}"]
        if system.variant == "transmitters":
            offs[j] = (a[1] + 2 * rec[1, 0] * tra[j, 0] - norm2[1]) / (2 * delta[1])
        elif system.variant == "offsets":
            c = norm2 - a + 2 * delta * offs[j]
            tra[j, 0] = c[1] / (2 * rec[1, 0])
            tra[j, 1] = (rec[1, 0] * c[2] - rec[2, 0] * c[1]) / (2 * rec[1, 0] * rec[2, 1])
        elif system.variant in ("receivers", "receivers-orbits"):
            A = np.column_stack([2 * rec[1:4, 0], 2 * rec[1:4, 1], -2 * delta[1:4]])
            w = np.linalg.solve(A, norm2[1:4] - a[1:4])
            tra[j], offs[j] = w[:2], w[2]
    return rec, tra, offs
