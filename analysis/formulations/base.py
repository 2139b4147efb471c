"""Configurations, equation names, formulations and instances: the definitions that
:mod:`analysis.formulations.tdoa` (the paper's 2D TDOA builder) and :mod:`analysis.formulations.kd` (TOA, 3D and
the direct parametrization) share, with the GF(p) square roots their samplers draw with.

Both modules build on this one, so neither imports the other's foundations; users import these names from
:mod:`analysis.formulations.tdoa`, which re-exports them (see its docstring for the paper's equations).
This module never imports ``solvers``.
"""
from __future__ import annotations

import fnmatch
import itertools
import math
import re
from dataclasses import dataclass
from typing import Iterator, NamedTuple, Sequence

import numpy as np

Exponent = tuple[int, ...]
GFPolynomial = dict[Exponent, int]
RealPolynomial = dict[Exponent, float]


class InconsistentSample(ArithmeticError):
    """The known root of an instance does not satisfy every equation of a formulation."""


class SamplingFailed(RuntimeError):
    """No consistent GF(p) instance was found within the attempt budget (usually: p is too small)."""


# --------------------------------------------------------------------------------------------------
# Configuration and equation names
# --------------------------------------------------------------------------------------------------

_CONFIG_RE = re.compile(
    r"^\s*(\d+)\s*r\s*/?\s*(\d+)\s*s(?:\s*-\s*(tdoa|toa)\s*(\d+)\s*d)?(?:\s*-\s*(direct|gram))?\s*$", re.IGNORECASE)


MODELS: tuple[str, ...] = ("tdoa", "toa")
"""Measurement models: ``tdoa`` (synchronised receivers, unknown transmitter offsets o_j, paper Section 2.2)
and ``toa`` (everything synchronised, no offsets, paper Section 2.1)."""

DIMENSIONS: tuple[int, ...] = (2, 3)
"""Spatial dimensions K the builder supports."""

PARAMETRIZATIONS: tuple[str, ...] = ("compaction", "direct", "gram")
"""Unknowns of a formulation: ``compaction`` (the paper's factorisation of the compaction matrix: H, b and,
for TDOA, the offsets), ``direct`` (the positions themselves in the gauge r_1 = 0, r_2 on the x axis,
r_3 in the xy plane, and the offsets; equations |r_i - s_j|^2 = d_ij^2) or ``gram`` (TOA only: the Gram
matrix G = R R^T of the receivers r_2..r_{K+1} relative to r_1, upper triangle g11, g12, ..., and for each
further receiver i its coordinates a<i>_1..a<i>_K in the basis r_2..r_{K+1}; invariant under the
Euclidean group. Equations ``S<j>``: w_j^T adj(G) w_j - 4 d_1j^2 det G with w_j,a = G_aa + d_1j^2 -
d_{a+1,j}^2 (|s_j - r_1|^2 = d_1j^2 once R s_j = w_j / 2 is solved); ``E<i>_<j>``: a_i^T G a_i + d_1j^2 -
d_ij^2 - a_i^T w_j (receiver i's range to s_j). Saturate by det G.)"""

_AXES = "xyz"


@dataclass(frozen=True)
class TDOAConfig:
    """A self-calibration configuration with m receivers and n transmitters (paper Sections 2.1-2.2).

    Parameters
    ----------
    m : number of receivers.
    n : number of transmitters.
    model : ``"tdoa"`` (default, unknown offsets) or ``"toa"`` (no offsets); see :data:`MODELS`.
    dim : spatial dimension K, 2 (default) or 3.
    parametrization : ``"compaction"`` (default; unknowns H, b, offsets) or ``"direct"`` (unknowns the
        gauge-fixed positions and offsets); see :data:`PARAMETRIZATIONS`.

    Bounds (the factorisation D^ = D~[:, :K] = R~^T S~ with S~ = I needs K + 1 transmitters, and K + 1
    receivers for TOA, whose S~ is solved from the first K rows of D~): TDOA compaction m >= K + 2,
    n >= K + 1 (2D: m >= 4, n >= 3); TOA compaction m, n >= K + 1; direct m >= K, n >= 1.
    Underdetermined configurations such as 4r/3s are allowed: they are still well-defined systems.
    The defaults are the paper's 2D TDOA formulation; its label has no suffix (``6r4s``), every other
    configuration's label names model and dimension (``4r6s-toa3d``, ``6r6s-tdoa3d-direct``).
    """

    m: int
    n: int
    model: str = "tdoa"
    dim: int = 2
    parametrization: str = "compaction"

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ValueError(f"unknown model {self.model!r}; valid: {', '.join(MODELS)}")
        if not isinstance(self.dim, int) or isinstance(self.dim, bool) or self.dim not in DIMENSIONS:
            raise ValueError(f"unsupported dimension {self.dim!r}; valid: {', '.join(map(str, DIMENSIONS))}")
        if self.parametrization not in PARAMETRIZATIONS:
            raise ValueError(f"unknown parametrization {self.parametrization!r}; valid: {', '.join(PARAMETRIZATIONS)}")
        k = self.dim
        if self.parametrization == "gram" and self.model != "toa":
            raise ValueError("the gram parametrization is for TOA (the offsets of TDOA do not enter it)")
        if self.parametrization == "direct":
            lows = (k, 1)
        elif self.parametrization == "gram":
            lows = (k + 1, 1)
        else:
            lows = (k + 2, k + 1) if self.model == "tdoa" else (k + 1, k + 1)
        for name, value, low in (("m (receivers)", self.m, lows[0]), ("n (transmitters)", self.n, lows[1])):
            if not isinstance(value, int) or isinstance(value, bool):
                raise ValueError(f"{name} must be an integer, got {value!r}")
            if value < low:
                raise ValueError(f"{name} must be >= {low} for {self.model} {self.parametrization} in {k}D, got {value}")

    @classmethod
    def parse(cls, text: str, model: str | None = None, dim: int | None = None,
              parametrization: str | None = None) -> "TDOAConfig":
        """Parse ``"6r4s"``, ``"6r/4s"``, ``"4r6s-toa3d"`` or ``"6r6s-tdoa3d-direct"`` (case and spaces
        ignored); the keyword arguments set what the text leaves out and must agree with what it says."""
        match = _CONFIG_RE.match(text)
        if match is None:
            raise ValueError(f"cannot parse configuration {text!r}; expected e.g. '6r4s', '6r/4s' or '4r6s-toa3d'")
        said_model = match.group(3).lower() if match.group(3) else None
        said_dim = int(match.group(4)) if match.group(4) else None
        said_param = match.group(5).lower() if match.group(5) else None
        values = {}
        for what, said, given, default in (("model", said_model, model, "tdoa"), ("dim", said_dim, dim, 2),
                                           ("parametrization", said_param, parametrization, "compaction")):
            if said is not None and given is not None and said != given:
                raise ValueError(f"configuration {text!r} says {what} {said}, but {given} was asked for")
            values[what] = said if said is not None else given if given is not None else default
        return cls(int(match.group(1)), int(match.group(2)), **values)

    @property
    def is_planar_tdoa(self) -> bool:
        """True for the paper's own formulation (2D TDOA, compaction unknowns)."""
        return (self.model, self.dim, self.parametrization) == ("tdoa", 2, "compaction")

    @property
    def label(self) -> str:
        """Short label, e.g. ``"6r4s"`` (paper's 2D TDOA), ``"4r6s-toa3d"``, ``"3r3s-toa2d-direct"``."""
        if self.is_planar_tdoa:
            return f"{self.m}r{self.n}s"
        suffix = "" if self.parametrization == "compaction" else f"-{self.parametrization}"
        return f"{self.m}r{self.n}s-{self.model}{self.dim}d{suffix}"

    @property
    def unknowns(self) -> tuple[str, ...]:
        """Unknown names in a fixed order.

        compaction: the upper triangle of H row by row (h11, h12, h22 in 2D; h11, h12, h13, h22, h23, h33
        in 3D), b1..bK, then (TDOA) o1..on. direct: the free receiver coordinates r2x, r3x, r3y, ...
        (gauge r_1 = 0, r_k has its first k - 1 coordinates free for k <= K), the transmitters s1x, s1y, ...,
        then (TDOA) o1..on. gram (TOA): the upper triangle of G (g11, g12, g22 in 2D), then a<i>_1..a<i>_K
        for every receiver i >= K + 2.
        """
        k = self.dim
        offsets = tuple(f"o{j}" for j in range(1, self.n + 1)) if self.model == "tdoa" else ()
        if self.parametrization == "direct":
            rec = tuple(f"r{i}{_AXES[a]}" for i in range(2, self.m + 1) for a in range(min(i - 1, k)))
            tra = tuple(f"s{j}{_AXES[a]}" for j in range(1, self.n + 1) for a in range(k))
            return rec + tra + offsets
        if self.parametrization == "gram":
            g = tuple(f"g{a}{c}" for a in range(1, k + 1) for c in range(a, k + 1))
            return g + tuple(f"a{i}_{a}" for i in range(k + 2, self.m + 1) for a in range(1, k + 1))
        h = tuple(f"h{a}{c}" for a in range(1, k + 1) for c in range(a, k + 1))
        return h + tuple(f"b{a}" for a in range(1, k + 1)) + offsets

    @property
    def n_unknowns(self) -> int:
        """Number of unknowns (5 + n for the paper's 2D TDOA)."""
        return len(self.unknowns)

    @property
    def n_minors(self) -> int:
        """Number of (K+1) x (K+1) minors of the (m-1) x (n-1) compaction matrix (TDOA compaction only)."""
        if self.model != "tdoa" or self.parametrization != "compaction":
            return 0
        return math.comb(self.m - 1, self.dim + 1) * math.comb(self.n - 1, self.dim + 1)

    @property
    def degrees_of_freedom(self) -> int:
        """K (m + n) + n - G (TDOA) or K (m + n) - G (TOA), G = K (K + 1) / 2 the Euclidean gauge (paper
        Section 1)."""
        k = self.dim
        return k * (self.m + self.n) + (self.n if self.model == "tdoa" else 0) - k * (k + 1) // 2

    @property
    def excess(self) -> int:
        """Measurements minus degrees of freedom, m n - DoF: 0 minimal, > 0 over-determined, < 0 under."""
        return self.m * self.n - self.degrees_of_freedom

    @property
    def gauge_group_order(self) -> int:
        """How many solutions in the unknowns represent one network up to rotation, reflection and
        translation: 2^K for direct (sign changes of the coordinate axes keep the gauge), 1 for compaction
        (H, b and the offsets are invariant under the orthogonal group)."""
        return 2 ** self.dim if self.parametrization == "direct" else 1

    def __str__(self) -> str:
        return self.label


def require_planar_tdoa(config: "TDOAConfig", what: str) -> None:
    """Raise ValueError unless ``config`` is the paper's 2D TDOA compaction formulation."""
    if not config.is_planar_tdoa:
        raise ValueError(f"{what} supports the paper's 2D TDOA formulation only, not {config.label}")


def _as_config(config: TDOAConfig | str) -> TDOAConfig:
    return TDOAConfig.parse(config) if isinstance(config, str) else config


def as_formulation(formulation: "Formulation | str") -> "Formulation":
    """A formulation, parsed from its label (e.g. ``"6r4s:B2,C2-C6,minors"``) when given as text."""
    return Formulation.parse(formulation) if isinstance(formulation, str) else formulation


def _minor_separator(config: TDOAConfig) -> str:
    return "." if max(config.m - 1, config.n - 1) > 9 else ""


def _minor_size(config: TDOAConfig) -> int:
    return config.dim + 1


def _minor_name(config: TDOAConfig, rows: Sequence[int], cols: Sequence[int]) -> str:
    sep = _minor_separator(config)
    return f"M{sep.join(map(str, rows))}_{sep.join(map(str, cols))}"


def _minor_index_sets(config: TDOAConfig) -> Iterator[tuple[tuple[int, ...], tuple[int, ...]]]:
    """1-based (rows, cols) of every minor, rows-major lexicographic (none unless TDOA compaction)."""
    if not config.n_minors:
        return
    size = _minor_size(config)
    for rows in itertools.combinations(range(1, config.m), size):
        for cols in itertools.combinations(range(1, config.n), size):
            yield rows, cols


def _parse_minor(config: TDOAConfig, name: str) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """1-based (rows, cols) of a minor name (assumed valid)."""
    row_text, col_text = name[1:].split("_")
    if _minor_separator(config):
        return tuple(map(int, row_text.split("."))), tuple(map(int, col_text.split(".")))
    return tuple(map(int, row_text)), tuple(map(int, col_text))


def equation_names(config: TDOAConfig | str) -> tuple[str, ...]:
    """All equation names of a configuration in canonical order: A, B2, B3, C2..Cm, minors.

    Minors are ordered lexicographically by (rows, cols) with 1-based compaction-matrix indices.
    Other models and dimensions (:class:`TDOAConfig`): TOA has B2..Bn (S~ is known from the data) and no
    minors; 3D TDOA has B2..Bn (B5..Bn with S~ solved from D~[:3, :3], affine in the offsets, and multiplied
    by its squared determinant: :mod:`analysis.formulations.kd`) and the 4 x 4 minors; the direct
    parametrization has one range equation ``D<i>_<j>`` per measurement, receiver-major.
    Paper Sections 2.1 (A, B, C), 2.2 (rank constraints), 3.1-3.2 (which ones exist for TDOA).
    """
    config = _as_config(config)
    if config.parametrization == "direct":
        return tuple(f"D{i}_{j}" for i in range(1, config.m + 1) for j in range(1, config.n + 1))
    if config.parametrization == "gram":
        return tuple(f"S{j}" for j in range(1, config.n + 1)) + tuple(
            f"E{i}_{j}" for i in range(config.dim + 2, config.m + 1) for j in range(1, config.n + 1))
    last_b = 3 if config.is_planar_tdoa else config.n
    names = ["A"] + [f"B{j}" for j in range(2, last_b + 1)] + [f"C{i}" for i in range(2, config.m + 1)]
    names += [_minor_name(config, rows, cols) for rows, cols in _minor_index_sets(config)]
    return tuple(names)


def _family(name: str) -> str:
    return "minors" if name.startswith("M") else name[0]


def _describe_names(config: TDOAConfig) -> str:
    """A short human-readable list of the valid names and groups (used in error messages)."""
    names = equation_names(config)
    if config.parametrization == "direct":
        return (f"valid names for {config.label}: D<i>_<j> (receiver i, transmitter j), D1_1..{names[-1]}; "
                "groups: all, D*, D2_*")
    if config.parametrization == "gram":
        extra = f", E<i>_<j> (receiver i >= {config.dim + 2}, transmitter j)" if config.m > config.dim + 1 else ""
        return (f"valid names for {config.label}: S1..S{config.n} (transmitter j's range to receiver 1){extra}; "
                f"groups: all, S*{', E*' if extra else ''}; ranges like S1-S{config.n}")
    minors = [x for x in names if x.startswith("M")]
    bs = [x for x in names if x.startswith("B")]
    text = f"A, {bs[0]}..{bs[-1]}, C2..C{config.m}" if len(bs) > 1 else f"A, {bs[0]}, C2..C{config.m}"
    if minors:
        text += f", {len(minors)} minors {minors[0]}..{minors[-1]}"
    else:
        text += f" ({_no_minors(config)})"
    groups = "all, B*, C*" + (", minors, minors(N), M*" if minors else "")
    return f"valid names for {config.label}: {text}; groups: {groups}; ranges like C2-C{config.m}, {bs[0]}-{bs[-1]}"


def _no_minors(config: TDOAConfig) -> str:
    if config.model == "toa":
        return "no minors: TOA's rank constraints involve only the data"
    return f"no minors: they need n >= {config.dim + 2}"


_RANGE_RE = re.compile(r"^([BCS])(\d+)\s*-\s*([BCS])?(\d+)$", re.IGNORECASE)
_MINORS_COUNT_RE = re.compile(r"^minors\((\d+)\)$", re.IGNORECASE)


def parse_equations(config: TDOAConfig | str, spec: str) -> tuple[str, ...]:
    """Parse an equation specification into names, deduplicated, in canonical order.

    Parameters
    ----------
    config : the configuration (or its label).
    spec : comma-separated tokens; each token is a name (``A``, ``B2``, ``C5``, ``M123_124``), a
        range within one family (``C2-C6``, ``C2-6``, ``B2-B3``), a glob (``C*``, ``M*_123``), or a group
        (``all``, ``minors``, ``minors(N)`` where N must equal the number of minors). Names are
        case-insensitive.

    Raises ValueError naming the offending token and listing the valid names.
    """
    config = _as_config(config)
    names = equation_names(config)
    by_lower = {x.lower(): x for x in names}
    minors = [x for x in names if x.startswith("M")]
    chosen: set[str] = set()
    if not spec.strip():
        raise ValueError(f"empty equation specification; {_describe_names(config)}")
    for raw in spec.split(","):
        token = raw.strip()
        low = token.lower()
        if not token:
            raise ValueError(f"empty token in equation specification {spec!r}")
        if low == "all":
            chosen.update(names)
        elif low == "minors" or _MINORS_COUNT_RE.match(token):
            if not minors:
                raise ValueError(f"token {token!r}: {config.label} has {_no_minors(config)}")
            count = _MINORS_COUNT_RE.match(token)
            if count and int(count.group(1)) != len(minors):
                raise ValueError(f"token {token!r}: {config.label} has {len(minors)} minors, not {count.group(1)}")
            chosen.update(minors)
        elif any(ch in token for ch in "*?["):
            hits = [x for x in names if fnmatch.fnmatchcase(x.lower(), low)]
            if not hits:
                raise ValueError(f"pattern {token!r} matches no equation; {_describe_names(config)}")
            chosen.update(hits)
        elif (match := _RANGE_RE.match(token)) is not None:
            family, lo, family2, hi = match.groups()
            family = family.upper()
            if family2 is not None and family2.upper() != family:
                raise ValueError(f"range {token!r} mixes families {family} and {family2.upper()}")
            lo_name, hi_name = f"{family}{int(lo)}", f"{family}{int(hi)}"
            for end in (lo_name, hi_name):
                if end not in by_lower.values():
                    raise ValueError(f"range {token!r}: {end} does not exist; {_describe_names(config)}")
            if int(lo) > int(hi):
                raise ValueError(f"range {token!r} is empty (start after end)")
            chosen.update(f"{family}{k}" for k in range(int(lo), int(hi) + 1))
        elif low in by_lower:
            chosen.add(by_lower[low])
        else:
            raise ValueError(f"unknown equation {token!r}; {_describe_names(config)}")
    return tuple(x for x in names if x in chosen)


# --------------------------------------------------------------------------------------------------
# Formulations
# --------------------------------------------------------------------------------------------------


class EquationCounts(NamedTuple):
    """How many equations of each family a formulation uses (the paper's "abc" notation + minors)."""

    A: int
    B: int
    C: int
    minors: int


@dataclass(frozen=True)
class Formulation:
    """A configuration together with a set of named equations (paper Section 3).

    Parameters
    ----------
    config : the TDOA configuration.
    equations : equation names (see :func:`equation_names`). They are validated and stored
        deduplication-free in canonical order, so two formulations with the same set compare equal.
    """

    config: TDOAConfig
    equations: tuple[str, ...]

    def __post_init__(self) -> None:
        if isinstance(self.equations, str):
            raise ValueError("equations must be a tuple of names; use Formulation.from_spec for a string")
        names = equation_names(self.config)
        given = tuple(self.equations)
        unknown = [x for x in given if x not in names]
        if unknown:
            raise ValueError(f"unknown equation(s) {', '.join(map(repr, unknown))}; {_describe_names(self.config)}")
        if len(set(given)) != len(given):
            dup = sorted({x for x in given if given.count(x) > 1})
            raise ValueError(f"duplicate equation(s) {', '.join(dup)}")
        if not given:
            raise ValueError("a formulation needs at least one equation")
        chosen = set(given)
        object.__setattr__(self, "equations", tuple(x for x in names if x in chosen))

    @classmethod
    def from_spec(cls, config: TDOAConfig | str, spec: str) -> "Formulation":
        """Build from a configuration and an equation specification (see :func:`parse_equations`)."""
        config = _as_config(config)
        return cls(config, parse_equations(config, spec))

    @classmethod
    def parse(cls, label: str) -> "Formulation":
        """Inverse of :attr:`label`: ``"6r4s:B2,C2-C6,minors(10)"``."""
        if ":" not in label:
            raise ValueError(f"formulation label {label!r} needs the form '<config>:<equations>', e.g. '6r4s:C2-C9'")
        config_text, spec = label.split(":", 1)
        return cls.from_spec(TDOAConfig.parse(config_text), spec)

    @property
    def counts(self) -> EquationCounts:
        """Numbers of A, B, C equations and minors."""
        fam = [_family(x) for x in self.equations]
        return EquationCounts(fam.count("A"), fam.count("B"), fam.count("C"), fam.count("minors"))

    @property
    def n_equations(self) -> int:
        """Total number of equations."""
        return len(self.equations)

    @property
    def unknowns(self) -> tuple[str, ...]:
        """Unknown names (same as the configuration's)."""
        return self.config.unknowns

    @property
    def label(self) -> str:
        """Compact round-trippable label, e.g. ``"6r4s:B2,C2-C6,minors(10)"``.

        C runs of two or more consecutive receivers are written as ranges; the full set of minors is
        written ``minors(N)``, a proper subset by explicit names; every range equation of a direct
        formulation is ``all``.
        """
        if self.config.parametrization in ("direct", "gram"):
            whole = len(self.equations) == len(equation_names(self.config))
            return f"{self.config.label}:{'all' if whole else ','.join(self.equations)}"
        parts = [x for x in self.equations if _family(x) in ("A", "B")]
        cs = [int(x[1:]) for x in self.equations if _family(x) == "C"]
        for _, run in itertools.groupby(enumerate(cs), key=lambda t: t[1] - t[0]):
            run = [c for _, c in run]
            parts.append(f"C{run[0]}" if len(run) == 1 else f"C{run[0]}-C{run[-1]}")
        minors = [x for x in self.equations if _family(x) == "minors"]
        if minors and len(minors) == self.config.n_minors:
            parts.append(f"minors({len(minors)})")
        else:
            parts.extend(minors)
        return f"{self.config.label}:{','.join(parts)}"

    def __str__(self) -> str:
        return self.label

# --------------------------------------------------------------------------------------------------
# Instances with a known root
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Instance:
    """One consistent data matrix together with the network that produced it and its known root.

    Attributes
    ----------
    config : the configuration.
    prime : p for a GF(p) instance, None for a real one.
    F : m x n measurements f_ij (python ints in [0, p) or floats), nested tuples.
    receivers, transmitters : positions as coordinate tuples (K per point); receivers[0] is the origin.
    offsets : o_1..o_n (zeros for TOA).
    root : the known root in the configuration's unknown order (h11, h12, h22, b1, b2, o1..on for the
        paper's 2D TDOA; :attr:`TDOAConfig.unknowns` in general).
    """

    config: TDOAConfig
    prime: int | None
    F: tuple[tuple, ...]
    receivers: tuple[tuple, ...]
    transmitters: tuple[tuple, ...]
    offsets: tuple
    root: tuple

    def data_array(self) -> np.ndarray:
        """F as a numpy array (int64 over GF(p), float64 over the reals)."""
        return np.array(self.F, dtype=np.int64 if self.prime is not None else np.float64)


def _rng(rng: "np.random.Generator | int") -> tuple[np.random.Generator, str]:
    if isinstance(rng, np.random.Generator):
        return rng, "a caller-supplied Generator"
    return np.random.default_rng(rng), f"seed {rng!r}"


def is_quadratic_residue(a: int, p: int) -> bool:
    """Euler's criterion: True iff a is a nonzero square mod the odd prime p."""
    a %= p
    return a != 0 and pow(a, (p - 1) // 2, p) == 1


def sqrt_mod(a: int, p: int) -> int:
    """A square root of a mod the odd prime p (Tonelli-Shanks); the smaller of the two roots.

    Raises ValueError if a is not a square mod p.
    """
    a %= p
    if a == 0:
        return 0
    if not is_quadratic_residue(a, p):
        raise ValueError(f"{a} is not a quadratic residue mod {p}")
    if p % 4 == 3:
        x = pow(a, (p + 1) // 4, p)
    else:
        q, s = p - 1, 0
        while q % 2 == 0:
            q //= 2
            s += 1
        z = 2
        while pow(z, (p - 1) // 2, p) != p - 1:
            z += 1
        mm, c, t, x = s, pow(z, q, p), pow(a, q, p), pow(a, (q + 1) // 2, p)
        while t != 1:
            i, t2 = 0, t
            while t2 != 1:
                t2 = t2 * t2 % p
                i += 1
            bb = pow(c, 1 << (mm - i - 1), p)
            mm, c, t, x = i, bb * bb % p, t * bb * bb % p, x * bb % p
    return min(x, p - x)


def _powmod_vec(a: np.ndarray, e: int, p: int) -> np.ndarray:
    """Elementwise a^e mod p for int64 arrays with entries in [0, p), p < 2^31."""
    result = np.ones_like(a)
    base = a % p
    while e:
        if e & 1:
            result = result * base % p
        base = base * base % p
        e >>= 1
    return result

RECEIVERS_FIRST_LIMIT = 16
"""Up to this many receivers, receivers are drawn first and each transmitter by rejection against all of
them (acceptance about 2^-m per candidate); beyond it the roles swap (acceptance about 2^-n)."""

REJECTION_LIMIT = 16
"""Largest min(m, n) the rejection sampler accepts: each point of the later side needs its squared
distances to all points of the earlier side to be squares, which a random point satisfies with
probability about 2^-min(m, n)."""


def _residue_mask(points: np.ndarray, anchors: np.ndarray, p: int) -> np.ndarray:
    """Rows of points whose squared distance to every anchor is a nonzero quadratic residue mod p."""
    diff = (points[:, None, :] - anchors[None, :, :]) % p  # (batch, anchors, K)
    d2 = (diff * diff % p).sum(axis=2) % p  # (batch, anchors); K p^2 < 2^63 for p < 2^31, K <= 3
    return np.all((d2 != 0) & (_powmod_vec(d2, (p - 1) // 2, p) == 1), axis=1)
