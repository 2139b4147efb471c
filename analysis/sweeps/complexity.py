"""Complexity of TDOA formulations: |B| over GF(p) on several consistent instances, and sweeps.

This module owns the step "formulation -> polynomials over GF(p) -> Gröbner basis -> standard
monomials" for many formulations at once (paper Sections 3.1-3.2, Tables 2-3):

* :func:`compute_formulation` samples one consistent instance per (prime, seed)
  (:func:`analysis.formulations.tdoa.sample_gf_instance`), checks its known root, computes the reduced
  Gröbner basis (grevlex, F4), and records per instance the degree |B| as generated, the dimension,
  the rank of the Jacobian at the known root and, when cheap, the degree after saturating by
  det H = h11 h22 - h12^2. The reported degree is the one most instances give; disagreement is kept in
  ``instance_degrees`` (reference/NOTES.md: a single consistent instance can be non-generic).
* :func:`sweep` runs many formulations in worker processes (spawn-safe, one BLAS thread each), with a
  wall-clock timeout per formulation (the worker is killed and replaced), a matrix-size cap through
  :class:`analysis.engine.f4.F4Options`, a progress bar, and a JSON cache on disk so that a rerun is instant
  and an interrupted sweep resumes.

Why the Jacobian at the known root: the instances are sampled from random networks, so the known root
is a generic point of the incidence variety. If the generic system is zero-dimensional there, the root
is a simple root (generic smoothness), so the Jacobian has full rank n. A rank-deficient Jacobian
therefore shows (with the probability of a random instance being generic) that the root lies on a
positive-dimensional component of local dimension at most ``tangent_dim = n - rank``; such systems
often make F4 blow up, so they run with a smaller matrix cap and are reported "positive-dimensional"
even when the Gröbner basis is out of reach (``dimension`` is then empty).

Why the saturated degree is cheap for zero-dimensional ideals: GF(p)[x]/I is a product of local
algebras, multiplication by f = det H is nilpotent on the factors at roots with f = 0 and invertible
on the others, so deg(I : f^inf) = rank(M_f^N) for N >= |B| (M_f the action matrix of f). The action
matrices of the variables are built by the border recursion of FGLM (numpy, no polynomial division).
For positive-dimensional ideals saturation needs a Gröbner basis of an extended system
(:func:`analysis.engine.quotient.saturate`) and runs only when requested (``saturate=True``).

Statuses (``FormulationResult.status``):
``ok``                    zero-dimensional; ``degree`` is the majority degree over all instances;
``positive-dimensional``  the majority of instances are positive-dimensional (or rank-deficient at
                          the known root with F4 over the cap);
``too-large``             an F4 matrix exceeded ``max_matrix_cells`` on a full-rank instance;
``timeout``               the wall-clock limit of :func:`sweep` killed the worker;
``disagree``              no unique majority, or a prime none of whose instances gives the majority;
``error``                 an unexpected exception (bad prime, sampling failure, engine bug), in
                          ``message``.
"""
from __future__ import annotations

import collections
import contextlib
import dataclasses
import hashlib
import json
import os
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Iterator, Literal, Mapping, Sequence

import flint
import numpy as np

from ..engine.degree import DEFAULT_PRIMES
from ..engine.f4 import F4Options, GroebnerResult, groebner, tighter_cells
from ..formulations.tdoa import Formulation, as_formulation, check_root, gf_equations, sample_gf_instance
from ..engine.linalg import MatrixTooLarge
from ..engine.msolve import MsolveRun, MsolveTimeout
from .paths import cache_dir
from .progress import Progress
from ..engine.quotient import dimension, is_zero_dimensional, saturate as saturate_ideal, standard_monomials
from ..engine.quotient import saturated_degree, variable_action_matrices as _variable_action_matrices
from ..engine.ring import Poly, Ring

__all__ = [
    "DEFAULT_CELLS",
    "DEFAULT_PRIMES",
    "DEFAULT_SEEDS",
    "ENGINE_VERSION",
    "FormulationResult",
    "InstanceOutcome",
    "LocalPool",
    "POSITIVE_DIMENSIONAL_CELLS",
    "STATUSES",
    "SweepTask",
    "compute_formulation",
    "default_cache_dir",
    "jacobian_rank",
    "load_cached",
    "repo_root",
    "root_ranks",
    "saturated_degree",
    "sweep",
]

ENGINE_VERSION = "tdoa-complexity/1"
"""Part of every cache key. Bump it when a change can alter a recorded result (equations, sampling,
engine semantics, statuses); refactors that cannot change results need no bump."""

DEFAULT_SEEDS = (0, 1)
"""Instance seeds per prime: 2 primes x 2 seeds = 4 consistent instances per formulation."""

DEFAULT_CELLS = 60_000_000
"""Default cap on rows*cols of one F4 matrix (a dense int64 copy of it is 480 MB)."""

POSITIVE_DIMENSIONAL_CELLS = 15_000_000
"""Smaller cap for instances whose Jacobian at the known root is rank-deficient: their Gröbner basis
only refines the dimension, and positive-dimensional bases are where F4 blows up."""

SATURATION_CHEAP_LIMIT = 3000
"""Largest |B| for which the saturated degree is computed by default (action-matrix rank)."""

Status = Literal["ok", "positive-dimensional", "too-large", "timeout", "disagree", "error"]
STATUSES: tuple[str, ...] = ("ok", "positive-dimensional", "too-large", "timeout", "disagree", "error")
InstanceStatus = Literal["ok", "positive-dimensional", "too-large", "timeout", "error"]


def repo_root() -> Path:
    """The repository root (the directory holding ``analysis/``), independent of the working directory."""
    return Path(__file__).resolve().parents[2]


def default_cache_dir() -> Path:
    """The ``complexity`` directory of the user cache (:func:`analysis.sweeps.paths.cache_dir`)."""
    return cache_dir("complexity")


# --------------------------------------------------------------------------------------------------
# Records
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class InstanceOutcome:
    """What one consistent instance (prime, seed) gave.

    degree: |B| as generated (None unless zero-dimensional). dimension: Krull dimension (None when the
    Gröbner basis was out of reach). jacobian_rank: rank of the Jacobian at the known root (n = full).
    minor_rank: rank of the Jacobian of the minors alone at the known root (their number of independent
    constraints; 3 for the 10 minors of 6r/4s, as the paper counts them).
    saturated_degree: |B| of I : (det H)^inf (None when not computed). max_rows/max_cols: the largest
    F4 matrix (0 when F4 did not finish). seconds: wall time of this instance. engine: what computed
    the Gröbner basis (``"own"``: :func:`analysis.engine.f4.groebner`; ``"msolve"``: the msolve executable).
    """

    prime: int
    seed: int
    status: InstanceStatus
    degree: int | None = None
    dimension: int | None = None
    jacobian_rank: int | None = None
    minor_rank: int | None = None
    saturated_degree: int | None = None
    gb_size: int | None = None
    max_rows: int = 0
    max_cols: int = 0
    seconds: float = 0.0
    message: str = ""
    engine: str = "own"

    @property
    def token(self) -> str:
        """Compact text: ``"75"``, ``"dim1"``, ``"dim?"`` (rank-deficient, basis out of reach),
        ``"too-large"``, ``"timeout"`` or ``"error"``."""
        if self.status == "ok":
            return str(self.degree)
        if self.status == "positive-dimensional":
            return f"dim{self.dimension if self.dimension is not None else '?'}"
        return self.status

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "InstanceOutcome":
        return cls(**{f.name: d[f.name] for f in dataclasses.fields(cls) if f.name in d})


CSV_COLUMNS: tuple[str, ...] = (
    "label", "config", "m", "n", "n_A", "n_B", "n_C", "n_minors", "n_equations", "n_unknowns",
    "independent_equations", "status", "degree", "saturated_degree", "dimension", "tangent_dim", "instance_degrees",
    "instance_saturated_degrees", "instances_agree", "gb_size", "max_rows", "max_cols", "primes", "seeds",
    "engine_version", "message", "seconds",
)
"""Columns of :meth:`FormulationResult.row`; every column but ``seconds`` is deterministic given the
inputs (``timeout`` statuses excepted)."""


@dataclass(frozen=True)
class FormulationResult:
    """The complexity of one formulation, combined over its instances (paper Tables 2-3).

    label, config, m, n: the formulation (``"6r4s:B2,C2-C6,minors(10)"``) and its configuration.
    n_A, n_B, n_C, n_minors, n_equations, n_unknowns: the paper's "abc" counts plus minors.
    status: see the module docstring.
    degree: majority |B| as generated (the equations A and B are multiplied by det H).
    saturated_degree: majority |B| after saturating by det H (None when not computed).
    dimension: majority Krull dimension (0 when ok; None when unknown).
    tangent_dim: n_unknowns - majority Jacobian rank at the known root (0: the root is a simple root).
    minor_rank: majority rank of the minors' Jacobian at the known root; independent_equations is
        n_A + n_B + n_C + minor_rank, the paper's count of equations (Section 3.2: "10 equations in the
        offsets, out of which only 3 are independent"). Square formulations have it equal to n_unknowns;
        larger means over-determined (on exact data these typically keep only the true root: |B| = 1).
    instance_degrees, instance_saturated_degrees: one token per instance in (prime, seed) order,
        e.g. ``"75,75,74,75"``; instances_agree: whether all instances gave the same token.
    gb_size, max_rows, max_cols: size of the reduced Gröbner basis and the largest F4 matrix (of the
        first instance giving the majority; max over instances for the matrix).
    seconds: total wall time of the instances (not deterministic; kept apart from the rest).
    primes, seeds: the instances are every (prime, seed) pair.
    max_matrix_cells, timeout: the limits in force (a cached too-large/timeout result is reused only
        under limits no larger than these).
    instances: the per-instance outcomes.
    engine: the Gröbner engine of the instances (``"own"`` or ``"msolve"``; not a CSV column).
    """

    label: str
    config: str
    m: int
    n: int
    n_A: int
    n_B: int
    n_C: int
    n_minors: int
    n_equations: int
    n_unknowns: int
    status: Status
    degree: int | None
    saturated_degree: int | None
    dimension: int | None
    tangent_dim: int | None
    minor_rank: int | None
    independent_equations: int | None
    instance_degrees: str
    instance_saturated_degrees: str
    instances_agree: bool
    gb_size: int | None
    max_rows: int
    max_cols: int
    seconds: float
    primes: tuple[int, ...]
    seeds: tuple[int, ...]
    message: str = ""
    engine_version: str = ENGINE_VERSION
    max_matrix_cells: int = DEFAULT_CELLS
    timeout: float | None = None
    saturation_requested: bool = False
    instances: tuple[InstanceOutcome, ...] = field(default=(), repr=False)
    engine: str = "own"

    @property
    def formulation(self) -> Formulation:
        return Formulation.parse(self.label)

    def row(self) -> dict:
        """Flat record for CSV/pandas (columns :data:`CSV_COLUMNS`)."""
        d = {name: getattr(self, name) for name in CSV_COLUMNS}
        d["primes"] = " ".join(map(str, self.primes))
        d["seeds"] = " ".join(map(str, self.seeds))
        d["seconds"] = round(self.seconds, 2)
        return d

    def to_dict(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["primes"], d["seeds"] = list(self.primes), list(self.seeds)
        d["instances"] = [o.to_dict() for o in self.instances]
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> "FormulationResult":
        kw = {f.name: d[f.name] for f in dataclasses.fields(cls) if f.name in d}
        kw["primes"], kw["seeds"] = tuple(kw["primes"]), tuple(kw["seeds"])
        kw["instances"] = tuple(InstanceOutcome.from_dict(o) for o in d.get("instances", ()))
        return cls(**kw)


# --------------------------------------------------------------------------------------------------
# Exact tools: Jacobian rank at a point, action matrices, saturated degree
# --------------------------------------------------------------------------------------------------


def jacobian_rank(polys: Sequence[Mapping[tuple[int, ...], int]], point: Sequence[int], p: int) -> int:
    """Rank over GF(p) of the Jacobian of exponent-dict polynomials at a point."""
    nvars = len(point)
    point = [int(x) % p for x in point]
    entries = []
    for poly in polys:
        row = [0] * nvars
        for exp, c in poly.items():
            for k, e in enumerate(exp):
                if e:
                    term = c * e % p
                    for i, ei in enumerate(exp):
                        power = ei - 1 if i == k else ei
                        if power:
                            term = term * pow(point[i], power, p) % p
                    row[k] = (row[k] + term) % p
        entries.extend(row)
    if not polys:
        return 0
    return flint.nmod_mat(len(polys), nvars, entries, p).rank()


def root_ranks(formulation: Formulation | str, prime: int = DEFAULT_PRIMES[0], seed: int = 0) -> tuple[int, int]:
    """(rank of the Jacobian, rank of the minors' Jacobian) at the known root of one instance.

    Cheap (no Gröbner basis): used to pick square formulations (n_A + n_B + n_C + minor rank equal to
    the number of unknowns) before a sweep.
    """
    formulation = as_formulation(formulation)
    instance = sample_gf_instance(formulation.config, prime, seed)
    equations = gf_equations(formulation, instance)
    minors = [e for name, e in zip(formulation.equations, equations) if name.startswith("M")]
    return (jacobian_rank(equations, instance.root, prime),
            jacobian_rank(minors, instance.root, prime) if minors else 0)


def _det_h(ring: Ring) -> Poly:
    h11, h12, h22 = (ring.gen(name) for name in ("h11", "h12", "h22"))
    return h11 * h22 - h12 * h12


# --------------------------------------------------------------------------------------------------
# One formulation
# --------------------------------------------------------------------------------------------------


def _instance(formulation: Formulation, prime: int, seed: int, options: F4Options, saturate: bool,
              positive_dimensional_cells: int, skip_f4: str | None = None,
              msolve: MsolveRun | None = None) -> InstanceOutcome:
    """Everything about one consistent instance; exceptions become status "error" (never raised).

    skip_f4: when set (an earlier instance exceeded the cap), only the Jacobian ranks are computed and
    this text becomes the message. msolve: compute the Gröbner basis with the msolve executable instead
    of the own engine (no matrix cap; its wall-clock limit gives status "timeout"); saturation, when
    requested, still runs on the own engine.
    """
    t0 = time.perf_counter()
    n = formulation.config.n_unknowns
    ranks: dict = {}

    engine = "own" if msolve is None else "msolve"

    def outcome(status: InstanceStatus, **kw) -> InstanceOutcome:
        return InstanceOutcome(prime, seed, status, **ranks, seconds=time.perf_counter() - t0, engine=engine, **kw)

    try:
        instance = sample_gf_instance(formulation.config, prime, seed)
        check_root(formulation, instance)
        equations = gf_equations(formulation, instance)
        minor_eqs = [e for name, e in zip(formulation.equations, equations) if name.startswith("M")]
        ranks["jacobian_rank"] = jacobian_rank(equations, instance.root, prime)
        ranks["minor_rank"] = jacobian_rank(minor_eqs, instance.root, prime) if minor_eqs else 0
        singular = ranks["jacobian_rank"] < n
        over_cap = "positive-dimensional" if singular else "too-large"
        if skip_f4 is not None:
            return outcome(over_cap, message=skip_f4)
        ring = Ring(formulation.unknowns, prime, "grevlex")
        polys = [ring.from_terms(t) for t in equations]
        cap = tighter_cells(options.max_matrix_cells, positive_dimensional_cells) if singular else options.max_matrix_cells
        capped = dataclasses.replace(options, max_matrix_cells=cap)
        try:
            gb = groebner(polys, capped) if msolve is None else msolve.groebner(polys)
        except MatrixTooLarge as e:
            return outcome(over_cap, message=str(e))
        except MsolveTimeout as e:
            return outcome("timeout", message=str(e))
        if any(g.evaluate(instance.root) for g in gb.basis):
            raise ArithmeticError("the known root does not vanish on the Gröbner basis")
        sizes = dict(gb_size=len(gb.basis), max_rows=gb.max_matrix[0], max_cols=gb.max_matrix[1])
        if is_zero_dimensional(gb):
            basis = standard_monomials(gb)
            sat = saturated_degree(gb, _det_h(ring), basis) if len(basis) <= SATURATION_CHEAP_LIMIT else None
            return outcome("ok", degree=len(basis), dimension=0, saturated_degree=sat, **sizes)
        sat, message = None, ""
        if saturate:
            try:
                sgb = saturate_ideal(polys, _det_h(ring), capped)
                if is_zero_dimensional(sgb):
                    sat = len(standard_monomials(sgb))
                else:
                    message = f"still dimension {dimension(sgb)} after saturation by det H"
            except MatrixTooLarge as e:
                message = f"saturation: {e}"
        return outcome("positive-dimensional", dimension=dimension(gb), saturated_degree=sat, message=message,
                       **sizes)
    except Exception as e:  # recorded, never hidden: the prime and seed are in the message
        return outcome("error", message=f"{type(e).__name__}: {e} (prime {prime}, seed {seed})")


def _majority(values: Sequence) -> tuple[object, bool]:
    """(most common value, unique?) of a non-empty sequence."""
    counts = collections.Counter(values).most_common()
    return counts[0][0], len(counts) == 1 or counts[0][1] > counts[1][1]


def combine(formulation: Formulation, outcomes: Sequence[InstanceOutcome], primes: Sequence[int],
            seeds: Sequence[int], options: F4Options, timeout: float | None = None,
            saturation_requested: bool = False) -> FormulationResult:
    """Combine per-instance outcomes into one :class:`FormulationResult` (majority rule; see module doc)."""
    config = formulation.config
    counts = formulation.counts
    tokens = [o.token for o in outcomes]
    sat_tokens = [str(o.saturated_degree) if o.saturated_degree is not None else "-" for o in outcomes]
    status: Status
    degree = dim = sat = None
    message = ""
    ranks = [o.jacobian_rank for o in outcomes if o.jacobian_rank is not None]
    tangent = config.n_unknowns - _majority(ranks)[0] if ranks else None
    mranks = [o.minor_rank for o in outcomes if o.minor_rank is not None]
    mrank = _majority(mranks)[0] if mranks else None
    chosen: InstanceOutcome | None = None
    if any(o.status == "error" for o in outcomes):
        status = "error"
        message = next(o.message for o in outcomes if o.status == "error")
    elif any(o.status == "timeout" for o in outcomes):
        status = "timeout"
        message = next(o.message for o in outcomes if o.status == "timeout")
    elif any(o.status == "too-large" for o in outcomes):
        status = "too-large"
        message = next(o.message for o in outcomes if o.status == "too-large")
    else:
        # majority over categories: a degree, or "positive-dimensional"
        category = [o.degree if o.status == "ok" else "pos" for o in outcomes]
        top, unique = _majority(category)
        missing = [p for p in primes if not any(o.prime == p and c == top for o, c in zip(outcomes, category))]
        if not unique or missing:
            status = "disagree"
            message = ("no unique majority" if not unique else
                       f"prime(s) {', '.join(map(str, missing))} never give the majority {top}")
        elif top == "pos":
            status = "positive-dimensional"
            dims = [o.dimension for o in outcomes if o.status == "positive-dimensional" and o.dimension is not None]
            dim = _majority(dims)[0] if dims else None
            if dim is None:
                message = next((o.message for o in outcomes if o.message), "")
        else:
            status = "ok"
            degree, dim = top, 0
        if status != "disagree":
            chosen = next(o for o, c in zip(outcomes, category) if c == top)
            sats = [o.saturated_degree for o, c in zip(outcomes, category)
                    if c == top and o.saturated_degree is not None]
            if sats:
                value, sat_unique = _majority(sats)
                sat = value if sat_unique else None
        else:
            chosen = outcomes[0] if outcomes else None
    return FormulationResult(
        label=formulation.label, config=config.label, m=config.m, n=config.n,
        n_A=counts.A, n_B=counts.B, n_C=counts.C, n_minors=counts.minors,
        n_equations=formulation.n_equations, n_unknowns=config.n_unknowns,
        status=status, degree=degree, saturated_degree=sat, dimension=dim, tangent_dim=tangent,
        minor_rank=mrank, independent_equations=None if mrank is None else counts.A + counts.B + counts.C + mrank,
        instance_degrees=",".join(tokens), instance_saturated_degrees=",".join(sat_tokens),
        instances_agree=len(set(tokens)) == 1 and len(tokens) == len(primes) * len(seeds),
        gb_size=chosen.gb_size if chosen else None,
        max_rows=chosen.max_rows if chosen else max((o.max_rows for o in outcomes), default=0),
        max_cols=chosen.max_cols if chosen else max((o.max_cols for o in outcomes), default=0),
        seconds=sum(o.seconds for o in outcomes), primes=tuple(primes), seeds=tuple(seeds), message=message,
        max_matrix_cells=options.max_matrix_cells, timeout=timeout, saturation_requested=saturation_requested,
        instances=tuple(outcomes), engine="msolve" if any(o.engine == "msolve" for o in outcomes) else "own",
    )


def compute_formulation(formulation: Formulation | str, primes: Sequence[int] = DEFAULT_PRIMES,
                        seeds: Sequence[int] = DEFAULT_SEEDS, options: F4Options | None = None,
                        saturate: bool = False, *,
                        positive_dimensional_cells: int = POSITIVE_DIMENSIONAL_CELLS,
                        on_instance: Callable[[InstanceOutcome], None] | None = None,
                        msolve: MsolveRun | None = None) -> FormulationResult:
    """Degree |B| (and more) of one formulation over every (prime, seed) instance.

    Parameters
    ----------
    formulation : a :class:`Formulation` or its label (``"9r3s:C2-C9"``).
    primes, seeds : one consistent instance per pair (``sample_gf_instance(config, prime, seed)``).
    options : F4 options; ``max_matrix_cells`` bounds the work (default :data:`DEFAULT_CELLS`).
    saturate : also saturate positive-dimensional ideals by det H (expensive); zero-dimensional ones
        get their saturated degree anyway when |B| <= :data:`SATURATION_CHEAP_LIMIT` (cheap).
    positive_dimensional_cells : matrix cap for instances rank-deficient at the known root.
    on_instance : called with each :class:`InstanceOutcome` as soon as it is known (used by workers).
    msolve : compute the Gröbner bases with this msolve executable instead of the own engine (no
        matrix cap; a run over its wall-clock limit gives "timeout"); the result's ``engine`` says so.

    After the first instance exceeds the cap, the remaining ones only get their Jacobian rank.
    Returns the combined :class:`FormulationResult`. Paper Section 3, Tables 2-3; reference/NOTES.md.
    """
    formulation = as_formulation(formulation)
    if options is None:
        options = F4Options(max_matrix_cells=DEFAULT_CELLS)
    primes, seeds = tuple(int(p) for p in primes), tuple(int(s) for s in seeds)
    if not primes or not seeds:
        raise ValueError("compute_formulation needs at least one prime and one seed")
    outcomes: list[InstanceOutcome] = []
    skip: str | None = None
    for prime in primes:
        for seed in seeds:
            outcome = _instance(formulation, prime, seed, options, saturate, positive_dimensional_cells, skip, msolve)
            if skip is None and outcome.status in ("too-large", "positive-dimensional", "timeout") \
                    and outcome.gb_size is None:
                skip = f"Gröbner basis skipped: instance (prime {prime}, seed {seed}) exceeded the cap"
            outcomes.append(outcome)
            if on_instance is not None:
                on_instance(outcome)
    return combine(formulation, outcomes, primes, seeds, options, None if msolve is None else msolve.timeout,
                   saturation_requested=saturate)


# --------------------------------------------------------------------------------------------------
# Cache
# --------------------------------------------------------------------------------------------------


def _cache_key(label: str, primes: Sequence[int], seeds: Sequence[int], backend: str = "own") -> str:
    key = {"label": label, "primes": list(primes), "seeds": list(seeds), "engine": ENGINE_VERSION}
    if backend != "own":  # the own engine's keys predate backends: unchanged, so existing caches stay valid
        key["backend"] = backend
    return json.dumps(key, sort_keys=True)


def _cache_path(cache_dir: Path, label: str, primes: Sequence[int], seeds: Sequence[int], backend: str = "own") -> Path:
    digest = hashlib.sha256(_cache_key(label, primes, seeds, backend).encode()).hexdigest()[:20]
    return cache_dir / f"{label.split(':', 1)[0]}-{digest}.json"


def _usable(result: FormulationResult, options: F4Options, timeout: float | None, saturate: bool) -> bool:
    """Whether a cached result answers a request made under these limits."""
    if result.status == "error":
        return False
    if saturate and not result.saturation_requested and result.status in ("positive-dimensional", "disagree"):
        return False
    if result.status == "too-large" or (result.status == "positive-dimensional" and result.dimension is None):
        asked, tried = options.max_matrix_cells, result.max_matrix_cells  # None: no cap
        return tried is None or (asked is not None and asked <= tried)
    if result.status == "timeout":
        return timeout is not None and result.timeout is not None and timeout <= result.timeout
    return True


def load_cached(formulation: Formulation | str, primes: Sequence[int] = DEFAULT_PRIMES,
                seeds: Sequence[int] = DEFAULT_SEEDS, cache_dir: Path | str | None = None,
                backend: str = "own") -> FormulationResult | None:
    """The cached result of a formulation (computed by ``backend``: "own" or "msolve"), or None."""
    label = formulation if isinstance(formulation, str) else formulation.label
    path = _cache_path(Path(cache_dir) if cache_dir else default_cache_dir(), label, primes, seeds, backend)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if data.get("key") != json.loads(_cache_key(label, primes, seeds, backend)):
        return None
    try:
        return FormulationResult.from_dict(data["result"])
    except (KeyError, TypeError):
        return None


def _store(cache_dir: Path, result: FormulationResult) -> None:
    cache_dir.mkdir(parents=True, exist_ok=True)
    path = _cache_path(cache_dir, result.label, result.primes, result.seeds, result.engine)
    payload = {"key": json.loads(_cache_key(result.label, result.primes, result.seeds, result.engine)),
               "result": result.to_dict()}
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    tmp.write_text(json.dumps(payload, indent=1, sort_keys=True), encoding="utf-8")
    os.replace(tmp, path)  # atomic: an interrupted sweep never leaves a half-written entry


# --------------------------------------------------------------------------------------------------
# Sweep: worker processes with a wall-clock limit
# --------------------------------------------------------------------------------------------------

THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
_THREAD_VARS = THREAD_VARIABLES


@contextlib.contextmanager
def single_threaded_blas_env() -> Iterator[None]:
    """Set one BLAS thread in the environment, for spawned workers that read it before importing numpy."""
    saved = {name: os.environ.get(name) for name in THREAD_VARIABLES}
    os.environ.update({name: "1" for name in THREAD_VARIABLES})
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _worker_main(conn) -> None:  # pragma: no cover - runs in a child process
    """Worker loop: receive (label, primes, seeds, options dict, saturate, cells), send outcomes back.

    The parent puts OPENBLAS_NUM_THREADS=1 into the environment before spawning, so it is in place
    before this module (and numpy) is imported in the child; it is set again here for safety.
    """
    for name in _THREAD_VARS:
        os.environ.setdefault(name, "1")
    while True:
        try:
            task = conn.recv()
        except EOFError:
            return
        if task is None:
            return
        label, primes, seeds, opts, saturate, cells = task
        try:
            result = compute_formulation(
                label, primes, seeds, F4Options(**opts), saturate, positive_dimensional_cells=cells,
                on_instance=lambda o: conn.send(("instance", o.to_dict())))
            conn.send(("result", result.to_dict()))
        except Exception:
            conn.send(("crash", traceback.format_exc()))


class _Progress(Progress):
    """The sweep's progress line: one phase, one step per formulation, the last label and status."""

    def __init__(self, total: int, enabled: bool, phase: str = "complexity sweep"):
        super().__init__(phase, total, enabled, "formulations")

    def update(self, label: str, status: str) -> None:  # type: ignore[override]
        super().update(1, f"{label[:50]} {status}")


@dataclass
class _Slot:
    process: object
    conn: object
    label: str | None = None
    started: float = 0.0
    partial: list = field(default_factory=list)


@dataclass(frozen=True)
class SweepTask:
    """What every formulation of a sweep is computed with (the limits are the per-task caps).

    timeout: wall-clock seconds per formulation (None: no time cap). options: F4 options as a dict
    (``max_matrix_cells``, ``max_memory``: the size and memory caps)."""

    primes: tuple[int, ...]
    seeds: tuple[int, ...]
    options: dict
    saturate: bool
    positive_dimensional_cells: int
    timeout: float | None

    def key(self, labels: Sequence[str]) -> str:
        """Content key of a chunk of this task: the same inputs give the same key."""
        text = json.dumps({"labels": list(labels), "task": dataclasses.asdict(self), "engine": ENGINE_VERSION},
                          sort_keys=True)
        return "tdoa-sweep-" + hashlib.sha256(text.encode()).hexdigest()[:24]


@dataclass(frozen=True)
class LocalPool:
    """``jobs`` spawned worker processes on this machine (one BLAS thread each); with ``jobs <= 1`` and no
    time cap, this process computes the formulations itself."""

    jobs: int = 2

    def run(self, labels: list[str], task: SweepTask, finish: Callable[[FormulationResult], None]) -> None:
        options = F4Options(**task.options)
        if self.jobs <= 1 and task.timeout is None:
            for label in labels:
                finish(compute_formulation(label, task.primes, task.seeds, options, task.saturate,
                                           positive_dimensional_cells=task.positive_dimensional_cells))
            return
        _run_pool(labels, task.primes, task.seeds, options, task.saturate, max(1, self.jobs),
                  task.timeout, task.positive_dimensional_cells, finish)


def sweep(formulations: Iterable[Formulation | str], *, primes: Sequence[int] = DEFAULT_PRIMES,
          seeds: Sequence[int] = DEFAULT_SEEDS, options: F4Options | None = None, saturate: bool = False,
          jobs: int = 2, cache_dir: Path | str | None = None, use_cache: bool = True, progress: bool = True,
          timeout: float | None = 600.0, positive_dimensional_cells: int = POSITIVE_DIMENSIONAL_CELLS,
          on_result: Callable[[FormulationResult, bool], None] | None = None,
          phase: str = "complexity sweep", executor=None) -> list[FormulationResult]:
    """:func:`compute_formulation` for many formulations, in parallel, cached on disk.

    Parameters
    ----------
    formulations : formulations or labels; duplicates are computed once.
    primes, seeds, options, saturate, positive_dimensional_cells : as in :func:`compute_formulation`.
    jobs : worker processes (spawned; each runs with one BLAS thread). ``jobs <= 1`` with
        ``timeout=None`` computes in this process.
    cache_dir : JSON cache directory (default :func:`default_cache_dir`); each result is stored as
        soon as it is known, keyed by label, primes, seeds and :data:`ENGINE_VERSION`.
    use_cache : read the cache (results are written either way).
    progress : progress on stderr (:class:`analysis.sweeps.progress.Progress`), named ``phase``.
    timeout : wall-clock seconds per formulation; on expiry the worker is killed and replaced and the
        result has status "timeout" (the instances finished before it are kept).
    on_result : called as ``on_result(result, from_cache)`` with each result as it becomes known (cached
        ones first).
    executor : where to compute (:mod:`analysis.sweeps.executors`): default a local pool of ``jobs`` processes;
        a :class:`analysis.sweeps.executors.DaskExecutor` runs the same tasks on a Dask cluster.

    Returns the results in input order.
    """
    if options is None:
        options = F4Options(max_matrix_cells=DEFAULT_CELLS)
    primes, seeds = tuple(int(p) for p in primes), tuple(int(s) for s in seeds)
    cache = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    labels = [f if isinstance(f, str) else f.label for f in formulations]
    labels = [Formulation.parse(x).label for x in labels]  # validate and normalise before any work
    unique = list(dict.fromkeys(labels))
    results: dict[str, FormulationResult] = {}
    bar = _Progress(len(unique), progress, phase)

    def finish(result: FormulationResult) -> None:
        results[result.label] = result
        _store(cache, result)
        bar.update(result.label, result.status if result.status != "ok" else f"|B|={result.degree}")
        if on_result is not None:
            on_result(result, False)

    todo = []
    for label in unique:
        cached = load_cached(label, primes, seeds, cache) if use_cache else None
        if cached is not None and _usable(cached, options, timeout, saturate):
            results[label] = cached
            bar.update(label, "cached")
            if on_result is not None:
                on_result(cached, True)
        else:
            todo.append(label)
    try:
        if todo:
            task = SweepTask(primes, seeds, dataclasses.asdict(options), saturate, positive_dimensional_cells, timeout)
            (executor or LocalPool(jobs)).run(todo, task, finish)
    finally:
        bar.close()
    return [results[label] for label in labels]


def _run_pool(todo: list[str], primes, seeds, options: F4Options, saturate: bool, jobs: int,
              timeout: float | None, cells: int, finish: Callable[[FormulationResult], None]) -> None:
    import multiprocessing as mp
    from multiprocessing.connection import wait

    ctx = mp.get_context("spawn")
    opts = dataclasses.asdict(options)
    pending = collections.deque(todo)
    slots: list[_Slot] = []

    def start() -> _Slot:
        parent, child = ctx.Pipe()
        with single_threaded_blas_env():  # inherited by the child before it imports numpy
            proc = ctx.Process(target=_worker_main, args=(child,), daemon=True)
            proc.start()
        child.close()
        return _Slot(proc, parent)

    def stop(slot: _Slot) -> None:
        try:
            slot.process.kill()
        except Exception:
            pass
        slot.process.join(5)
        slot.conn.close()

    def abandon(slot: _Slot, status: InstanceStatus, message: str) -> None:
        formulation = Formulation.parse(slot.label)
        done = [InstanceOutcome.from_dict(d) for d in slot.partial]
        elapsed = time.perf_counter() - slot.started
        left = [(p, s) for p in primes for s in seeds][len(done):]
        spent = elapsed - sum(o.seconds for o in done)
        marks = [InstanceOutcome(p, s, status, seconds=spent if k == 0 else 0.0, message=message)
                 for k, (p, s) in enumerate(left)]
        finish(combine(formulation, done + marks, primes, seeds, options, timeout, saturate))

    try:
        for _ in range(min(jobs, len(pending))):
            slots.append(start())
        while True:
            for slot in slots:
                if slot.label is None and pending:
                    slot.label, slot.started, slot.partial = pending.popleft(), time.perf_counter(), []
                    slot.conn.send((slot.label, primes, seeds, opts, saturate, cells))
            busy = [s for s in slots if s.label is not None]
            if not busy:
                break
            now = time.perf_counter()
            wait_for = 1.0 if timeout is None else max(0.05, min(s.started + timeout - now for s in busy))
            ready = wait([s.conn for s in busy], timeout=min(wait_for, 5.0))
            for slot in busy:
                if slot.conn in ready:
                    try:
                        kind, payload = slot.conn.recv()
                    except (EOFError, OSError):
                        slot.process.join(2)
                        code = slot.process.exitcode
                        abandon(slot, "error", f"worker died (exit code {code}; out of memory?)")
                        stop(slot)
                        slots[slots.index(slot)] = start()
                        continue
                    if kind == "instance":
                        slot.partial.append(payload)
                    elif kind == "result":
                        finish(FormulationResult.from_dict(payload))
                        slot.label = None
                    else:  # crash: the traceback is the message
                        abandon(slot, "error", payload.strip().splitlines()[-1])
                        slot.label = None
                elif timeout is not None and time.perf_counter() - slot.started > timeout:
                    abandon(slot, "timeout", f"wall-clock limit of {timeout:g} s exceeded")
                    stop(slot)
                    slots[slots.index(slot)] = start()
    finally:
        for slot in slots:
            if slot.process.is_alive():
                try:
                    slot.conn.send(None)
                except (OSError, BrokenPipeError):
                    pass
        for slot in slots:
            slot.process.join(2)
            if slot.process.is_alive():
                slot.process.kill()
                slot.process.join(2)
            slot.conn.close()
