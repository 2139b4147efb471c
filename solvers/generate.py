"""The one solver generator: a configuration, a formulation or a user's parametric system -> spec + module.

:func:`generate` takes a committed configuration label (:data:`SOLVERS`), a TDOA formulation label
(``7r3s:B2,B3,C2-C7``) or an :class:`analysis.formulations.parametric.ParametricSystem` (e.g. read from a text
file by :func:`analysis.formulations.parametric.parse`) and writes ``<name>_<method><size>.json`` (plain-text
spec) and ``.py`` (the module of :mod:`solvers.codegen`'s one template: do-not-edit header with the
command that regenerates it and the spec's sha256, coefficient function, ``solve(F)``) into the
directory ``out``, and nowhere else. Methods are strategies behind one interface (:data:`METHODS`):

* ``curve-pencil`` (6r4s, paper Section 3.2): the eigenvalue construction of :mod:`solvers.methods.pencil`;
* ``homotopy``: parameter homotopy (:mod:`solvers.methods.homotopy`), the general method: every
  square system with a certified root count gets one;
* ``offset-kernel`` (3D TDOA mr/5s, m >= 9, one solution): the linear construction of
  :mod:`solvers.methods.offset_kernel`;
* ``action-matrix`` (asked for by name): an elimination template built over GF(p) and an eigenvalue
  solve (:mod:`solvers.methods.action_matrix`), for square systems with linear equations to eliminate
  and one non-vanishing factor (TOA 2D 3r/3s); its module sits beside the homotopy one
  (``<name>_action<roots>``).

Every homotopy solver's root count is certified over GF(p) first (two primes, two seeds, known root
checked); monodromy on complete graphs (:func:`graph_growth`) must reach exactly that count. When F4 cannot
certify (its matrices do not fit, as for the 3D TDOA minimal cells), ``evidence="monodromy"`` builds on
numerical evidence alone: the solutions of a count of :func:`solvers.count.count` (graphs closed on two seeds,
their sets equal, every solution proven: "at least N, proven") or of a settled monodromy checkpoint; the spec
then has "evidence" instead of "certified" and the module's header says the count is not certified. Its start pair (generic complex parameters with
one known root) comes from a complex network for TDOA systems, is drawn for a system linear in its
parameters, or is given by the user; a system not linear in its parameters without one is refused
before any work. An over-determined formulation is squared by random integer combinations of its
minors (5r4s) or by a choice of them (5r5s: its four principal minors); the full system's count is
certified too, and only the start roots that satisfy it are tracked (5r/5s: 64 of the square system's 330).

The committed solvers (solvers/generated/) are written by ``scripts/generate_solvers.py``;
:func:`emit_committed` re-emits one from its committed spec (no numerics recomputed).
"""
from __future__ import annotations

import dataclasses
import json
import os
import re
import shlex
import time
from dataclasses import dataclass
from typing import Callable, Protocol, Union

import numpy as np

from analysis.formulations.tdoa import Formulation
from analysis.formulations.parametric import ParametricSystem, from_formulation, from_positions, square, squared_name

from . import codegen
from .instances import gauge_reflections, positions_start, positions_trials, tdoa_start, tdoa_trials
from .continuation import graph, monodromy, tape_native, tracker, tracking
from .methods import action_matrix, homotopy, offset_kernel, pencil
from .methods.spec import METHODS as METHOD_NAMES
from .methods.spec import TemplateOptions, dump_spec, solver_method

__all__ = ["EVIDENCE", "GENERATED_DIR", "METHODS", "SOLVERS", "Generated", "GenerationError", "committed_command",
           "emit_committed", "generate", "solver_system"]

#: Where the committed solvers live (written by scripts/generate_solvers.py, read by solvers.api).
GENERATED_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "generated")

#: Configuration label -> formulation of its committed solver (Section 3.2 pencil and Table 3 cells).
SOLVERS = {
    "6r4s": "6r4s:B2,C2-C6,minors(10)",
    "9r3s": "9r3s:C2-C9",
    "8r3s": "8r3s:B2,C2-C8",
    "7r3s": "7r3s:B2,B3,C2-C7",
    "6r3s": "6r3s:A,B2,B3,C2-C6",
    "5r4s": "5r4s:A,B2,B3,C2-C5,minors",
    "5r5s": "5r5s:B2,B3,C2-C5,minors",
    "4r5s": "4r5s:positions-receivers-orbits",
    "9r5s3d": offset_kernel.offset_kernel_formulation(9),
    # TOA (synchronised transmitters): the minimal cells, compaction unknowns (H, b) with det H saturated
    "3r3stoa": "3r3s-toa2d:A,B2,B3,C2-C3",
    "4r6s3dtoa": "4r6s-toa3d:A,B2,B3,B4,B5,B6,C2-C4",
    "5r5s3dtoa": "5r5s-toa3d:A,B2,B3,B4,B5,C2-C5",
    "6r4s3dtoa": "6r4s-toa3d:A,B2,B3,B4,C2-C6",
    # 4r/6s in the receivers' Gram matrix (6 unknowns instead of 9; 2-3.5x faster than its compaction solver,
    # docs/minimal-3d.md); 6r/4s and 5r/5s in it (12 and 9 unknowns) are slower than their compaction solvers
    "4r6s3dgram": "4r6s-toa3d-gram:all",
    # 3D TDOA minimal cells, direct parametrization (receivers in the gauge frame, transmitters, offsets), built
    # on numerical evidence from a monodromy checkpoint (MONODROMY_CHECKPOINTS): F4 cannot count them
    "7r5s3d": "7r5s-tdoa3d-direct:all",
    "6r6s3d": "6r6s-tdoa3d-direct:all",
}

#: Configurations whose committed solver is built from a settled monodromy count (numerical evidence, no GF(p)
#: certificate): the checkpoint scripts/monodromy_counts.py wrote, in $TDOA_WORKBENCH_CACHE/monodromy/, read by
#: ``generate(..., from_monodromy=PATH)`` (scripts/generate_solvers.py passes this file by default).
MONODROMY_CHECKPOINTS = {"7r5s3d": "7r5s-seed0.json",
                         # seed 1 (3920 orbits): seed 0 settled at 3919 and lacks one root, whose Newton steps
                         # stall at seed 0's instance (carried there, 3917 of seed 1's land on seed 0's, 3 lost)
                         "6r6s3d": "6r6s-seed1.json"}

#: Loops without a new root that settle a checkpoint's count (scripts/monodromy_counts.py --stall, default 10).
SETTLED_LOOPS = 10

#: Seeded real instances a solver built from a checkpoint is verified on (each solve tracks thousands of paths:
#: about 20 s for 7r/5s; the bench, scripts/bench_solvers3d.py, validates it on 100).
CHECKPOINT_VERIFY_TRIALS = 3

#: Configurations solved in a positions formulation (analysis.formulations.positions) instead of (H, b, o).
POSITIONS = {"4r5s": "receivers-orbits"}

#: Over-determined formulations (dependent rank-2 minors): keep this many leading equations and replace
#: the minors by random integer combinations (analysis.formulations.parametric.square); counted on one seed.
SQUARED = {"5r4s": 7}

#: Over-determined formulations squared by a choice of their minors instead (the square system is the
#: formulation's other equations and these minors; the full system's count is certified too and only its
#: roots are tracked, as for SQUARED). 5r/5s: the four principal 3 x 3 minors of the 4 x 4 compaction matrix
#: (each receiver row and transmitter column left out once) have 330 roots with B2, B3, C2-C5 (det H
#: saturated), the 64 of the full system among them, where four random combinations of all 16 minors have
#: 710: the program evaluates 4 minors instead of 16 (full tape 1011 instructions against 1887), and its
#: plain track took 199 against 252 us per path (same attempts, 1000 networks: the same failure, 819;
#: tables/NOTES.md).
SQUARE_MINORS = {"5r5s": ("M123_123", "M124_124", "M134_134", "M234_234")}

#: Step control of a configuration's tracking, written into its spec over the method's defaults: "tracker"
#: (the plain track, :class:`solvers.continuation.tracker.TrackerOptions` fields) and "retrack" (fields replaced
#: in :data:`solvers.continuation.tracker.TIGHT` for the retracks and detours). 4r/5s: 5-40 of its 344 paths
#: crawl through an ill-conditioned stretch (Jacobian condition 1e8-1e10, also in projective coordinates)
#: at steps of 1e-5; a plain limit of 400 (600) hands them sooner to the retracks: on the 1000 seeded
#: networks of tables/solvers.csv the same two failures (406, 665), 6 % less time on 20 of them. Lower
#: retrack limits lose true roots whose paths need thousands of tight steps (1000: networks 440 and 986;
#: plain 250 with retrack 150: 10 more of 1000), so "retrack" is left at TIGHT's (tables/NOTES.md).
#: "starts": tracked from this many start systems (the spec's and seeded others, :func:`homotopy.extra_starts`),
#: endpoints pooled, nothing retracked: 4r/5s's stalled paths are cheaper to replace by two more plain tracks
#: than to retrack (tables/NOTES.md, "Three start systems").
#: "predictor": "pade" (the tape tracker's Pade predictor for the plain track, Newton corrector): on the 1000 seeded
#: networks of tables/solvers.csv it missed the true root on the same networks as RK4 (9r/3s 49, 8r/3s 53, 6r/3s
#: none, 4r/5s 665) and lost no more roots in all (9r/3s 23 against 24, 8r/3s 31 and 31, 6r/3s 168 against 243,
#: 4r/5s: 616 instances short of their roots against 624), at 0.67-0.92 (9r/3s), 0.74-0.94 (8r/3s), 0.63-0.83
#: (6r/3s) and 0.68 (4r/5s) of RK4's median solve in the same runs. Not for 7r/3s (0.8-0.94, but 28 roots lost
#: against 21), the 3D TOA solvers (6r/4s 3x slower, 4r/6s Gram 1.2x) nor 5r/5s TOA (chord: as fast, other
#: networks missed); squared systems already run Pade (tracker.FAMILY); the chord corrector lost more paths in
#: nearly every solver (scripts/bench_tracker_variants.py; docs/findings/homotopy-speed.md, "Pade by default").
#: 9r/3s from its imaginary start (:data:`START_POSITIONS`): "contract" 0.2 (a step is kept when the second Newton
#: correction is under 0.2 of the first, not 0.1: 46-49 step attempts per path against 51-52) and "final_newton" 5
#: (two more Newton steps on the target: network 442's true root sits 1.3e-3 from another root, and three steps
#: left it 2.9e-6 off, five 4e-12). On three sets of 1000 seeded networks (seeds 0, 1, 2 of bench_solvers' sequence)
#: the same missed networks (49; none; none) and no more roots lost (23, 2, 2 against 23, 2, 4) than the complex
#: start with the defaults; contraction 0.3, or target 0.02 with 0.2, lost more (docs/findings/homotopy-speed.md,
#: "Imaginary start networks").
STEP_CONTROL = {"9r3s": {"tracker": {"predictor": "pade", "contract": 0.2, "final_newton": 5}},
                "8r3s": {"tracker": {"predictor": "pade"}},
                "6r3s": {"tracker": {"predictor": "pade"}},
                "4r5s": {"tracker": {"max_steps": 400, "predictor": "pade"}, "starts": 3}}

#: Start networks of a configuration's homotopy other than complex normal (:func:`complex_instance`'s ``positions``):
#: "imaginary", receivers and transmitters i times real normal. The start parameters q0 are then close to i times a
#: real network's data, and the straight segments from there to real data pass farther from the systems whose
#: paths meet: 9r/3s plain tracks took 49-57 step attempts per path from such starts against 64 from its complex
#: one (docs/findings/homotopy-speed.md, "Imaginary start networks").
START_POSITIONS = {"9r3s": "imaginary"}


def step_control_fields(step_control: dict | None, squared: bool) -> dict:
    """The spec's "tracker" and "retrack" fields of a homotopy solver: :data:`tracker.FAMILY` for a squared system
    (a jump to another family is invisible to the duplicate test), under the configuration's ``step_control``
    (:data:`STEP_CONTROL`; its "starts" count is not a spec field)."""
    fields = {"tracker": dict(tracker.FAMILY) if squared else {}}
    for key, values in (step_control or {}).items():
        if key != "starts":
            fields[key] = {**fields.get(key, {}), **values}
    return fields


def committed_spec_text(json_path: str) -> str:
    """The committed homotopy spec at json_path with its configuration's current step control (the "tracker" and
    "retrack" fields of :func:`step_control_fields`) written in, nothing else changed (no numerics recomputed;
    other specs unchanged): what ``scripts/generate_solvers.py --emit-only`` writes back."""
    with open(json_path, encoding="utf-8") as fh:
        text = fh.read()
    spec = json.loads(text)
    if spec.get("kind") != "homotopy":
        return text
    label = os.path.basename(json_path).split("_")[1]
    fields = step_control_fields(STEP_CONTROL.get(label), squared="full_system" in spec)
    if "retrack" not in fields:
        spec.pop("retrack", None)
    starts = spec.pop("starts", None)  # a generation writes the further start systems last
    spec.update(fields)
    if starts is not None:
        spec["starts"] = starts
    return dump_spec(spec)


#: A start pair: generic complex parameters q0 and one root x0 there, or a function rng -> such a pair.
Start = Union[tuple[np.ndarray, np.ndarray], Callable[[np.random.Generator], tuple[np.ndarray, np.ndarray]]]


class GenerationError(ValueError):
    """A generation that cannot be run as asked (unknown target or method, missing output directory)."""


def solver_system(label: str) -> ParametricSystem:
    """The (square) parametric system of a registered homotopy configuration, det H saturated."""
    if label in POSITIONS:
        m, n = (int(v) for v in label[:-1].split("r"))
        return from_positions(m, n, POSITIONS[label])
    if label in SQUARE_MINORS:
        kept = SOLVERS[label].rsplit(",", 1)[0]  # the formulation without its family of minors
        return from_formulation(kept + "," + ",".join(SQUARE_MINORS[label]), saturate_det_h=True)
    direct = Formulation.parse(SOLVERS[label]).config.parametrization == "direct"  # no H to saturate
    system = from_formulation(SOLVERS[label], saturate_det_h=not direct)
    if label in SQUARED:
        system = square(system, SQUARED[label], seed=0, name=squared_name(system.name, 0))
    return system


@dataclass(frozen=True)
class Generated:
    """What a generation built (printed by the CLI as a readable summary).

    candidates: rows of ``solve(F)`` (the pencil's roots; the homotopy's tracked paths).
    """

    name: str
    system: str
    method: str
    degree: int
    candidates: int
    seconds: float
    module: str
    report: dict
    evidence: str = "gf"

    def summary(self) -> str:
        extra = ", ".join(f"{k} {v}" for k, v in self.report.items() if k not in ("method", "degree", "paths", "seconds"))
        how = "by monodromy alone (numerical evidence, not certified)" if self.evidence == "monodromy" else "certified over GF(p)"
        return (f"{self.system}: {self.method}, {self.degree} roots {how}, {self.candidates} candidates; "
                f"{extra}; {self.seconds:.1f} s -> {self.module}")


# --------------------------------------------------------------------------------------------------
# the methods: one interface
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Job:
    """One generation: the solver's name and what it solves, with what the methods need to build it.

    formulation: a TDOA formulation label (pencil; the homotopy's system came from it) or None;
    system: the square parametric system (homotopy); full: the over-determined system it squares;
    start / trials: start pair and seeded real instances (TDOA targets; a user's start pair);
    seeds: the GF(p) certification's seeds; step_control: the spec's tracking options (:data:`STEP_CONTROL`);
    checkpoint: a monodromy checkpoint whose q0 and roots the solver starts from (evidence "monodromy");
    counted: a :class:`solvers.count.CountResult` whose first seed's q0 and proven solutions the solver starts
    from (evidence "monodromy");
    group: sign vectors (G, N) whose orbits the roots come in (the direct parametrization's gauge reflections),
    one root per orbit tracked.
    """

    name: str
    formulation: str | None = None
    system: ParametricSystem | None = None
    config: tuple[int, int] | None = None
    start: Callable | None = None
    trials: Callable | None = None
    full: ParametricSystem | None = None
    seeds: tuple[int, ...] = (0, 1)
    step_control: dict | None = None
    evidence: str = "gf"
    checkpoint: str | None = None
    group: np.ndarray | None = None
    counted: object | None = None


@dataclass(frozen=True)
class Built:
    """A method's result: the JSON-ready spec, the module's coefficient function (source) and a report."""

    spec: dict
    coefficients: str
    degree: int
    candidates: int
    report: dict


class Method(Protocol):
    """A solving method as the generator sees it: it builds a spec and the coefficient source."""

    kind: str

    def build(self, job: Job, seed: int, progress: Callable[[str], None] | None) -> Built: ...


@dataclass(frozen=True)
class FormulationMethod:
    """A method built from a TDOA formulation by its module's ``build`` (no parametric system): the
    curve pencil (:mod:`solvers.methods.pencil`) and the 3D offset kernel (:mod:`solvers.methods.offset_kernel`).

    kind: the spec kind; example: a formulation it builds (named when a parametric system is given);
    doing: what the build does (the progress line); builder: formulation, options -> TemplateResult;
    coefficients: spec -> the module's coefficient source (:mod:`solvers.codegen`).
    """

    kind: str
    example: str
    doing: str
    builder: Callable
    coefficients: Callable[[dict], str]

    def build(self, job: Job, seed: int, progress: Callable[[str], None] | None) -> Built:
        if job.formulation is None:
            raise GenerationError(f"{job.name}: the {self.kind} method is built from its TDOA formulation, such as "
                                  f"{self.example}, not from a parametric system")
        if progress:
            progress(f"{job.formulation}: {self.doing}")
        result = self.builder(job.formulation, TemplateOptions())
        spec = result.spec
        report = dict(result.candidates[0]) if result.candidates else {}
        report["size"] = "x".join(map(str, spec["size"]))
        return Built(spec, self.coefficients(spec), int(spec["degree"]), int(spec["degree"]), report)


#: Graphs of :func:`graph_growth` before a build that has not reached its certified count is an error.
GRAPH_ATTEMPTS = 6


def graph_growth(seed: int) -> Callable[..., tuple[np.ndarray, dict]]:
    """The root growth of a homotopy build with a certified count (``grow`` of :func:`homotopy.build`): monodromy
    on complete graphs (:func:`solvers.continuation.graph.graph_monodromy`), graph a = 0, 1, ... with 4 + 2a
    nodes at radius 2^a (seed + 1000 a), each from every root known so far and stopped as soon as the base point
    holds the count; :class:`tracking.HomotopyError` after :data:`GRAPH_ATTEMPTS` graphs short of it (or beyond it).

    The loops q0 -> qa -> qb -> q0 of radius 1 stopped short on small user systems (two cubics in 2 unknowns:
    8 of 9 after 88 loops; three cubics in 3 unknowns: 26 of 27 after 56, seed 0); on examples/circle.sys,
    two_cubics.sys and three_cubics.sys these graphs reached the count on 60 of 60 seeds within 3 graphs
    (radius 1 every time: 59 of 60 within 8).
    """
    def grow(solver, q0: np.ndarray, x0: np.ndarray, count: int, progress, excluded) -> tuple[np.ndarray, dict]:
        roots, paths = np.atleast_2d(x0), 0
        for attempt in range(GRAPH_ATTEMPTS):
            nodes, radius = 4 + 2 * attempt, 2.0 ** attempt
            result = graph.graph_monodromy(solver, q0, roots, graph.GraphOptions(
                nodes=nodes, seed=seed + 1000 * attempt, radius=radius, target=count), excluded=excluded)
            roots, paths = result.roots, paths + result.paths
            if progress:
                progress(f"monodromy graph {attempt + 1} ({nodes} nodes, radius {radius:g}): {len(roots)}/{count} roots, "
                         f"{paths} paths")
            if len(roots) >= count:
                break
        if len(roots) != count:
            raise tracking.HomotopyError(
                f"monodromy found {len(roots)} of the certified {count} roots in {attempt + 1} graphs (seed {seed}); "
                + ("numerical duplicates or a wrong count" if len(roots) > count else "the solver would miss roots"))
        return roots, {"graphs": attempt + 1, "nodes": nodes, "paths_tracked": paths}

    return grow


def _checked_count(system: ParametricSystem, counted):
    """A count of :func:`solvers.count.count` a build on numerical evidence starts from (its first seed's q0 and
    solutions), checked: :class:`GenerationError` without one, for another system, or unless its graphs closed and
    its seeds' sets are equal (the count is then what the graphs found, not a settled guess)."""
    if counted is None or counted.roots is None:
        raise GenerationError(f"{system.name}: evidence 'monodromy' builds on a count: pass counted=solvers.count.count"
                              "(target, CountOptions(seeds=(seed, seed + 1))) (the CLI's generate --evidence monodromy "
                              "runs it), or from_monodromy=CHECKPOINT")
    if counted.system != system.name or counted.roots.shape[1] != len(system.unknowns):
        raise GenerationError(f"{system.name}: the count given is of {counted.system}")
    if not all(s.closed and s.carried in ("", "equal as sets") for s in counted.seeds) or not len(counted.roots):
        raise GenerationError(f"{system.name}: the monodromy count is not consistent ({counted.evidence}; "
                              f"{'; '.join(counted.notes) or counted.loops_checked}); no solver from it (another seed draws other "
                              "graphs)")
    return counted


def _compile_tapes_early(system: ParametricSystem) -> None:
    """Start compiling a user's system's tapes as C (:func:`tape_native.addresses`, in a background thread) before
    F4 certifies its count: the build's first Newton step, and the generated module's first solve in any later
    process, load that library (cached by a hash of its source)."""
    if tracking.evaluator_for(system.name) != "tape":
        return
    exps, eq = tracking.structure(system)
    spec = {"system": system.name, "unknowns": list(system.unknowns), "parameters": list(system.parameters),
            "exponents": exps.tolist(), "term_equation": eq.tolist()}
    coefficients = tracking.load_coefficients(tracking.coefficient_source(system))
    tape_native.addresses(tracking._tapes(spec, coefficients, "tape"), wait=False)


class HomotopyMethod:
    """Parameter homotopy (:mod:`solvers.methods.homotopy`) of a square parametric system."""

    kind = "homotopy"

    def build(self, job: Job, seed: int, progress: Callable[[str], None] | None) -> Built:
        system, full = job.system, job.full
        options = tracking.HomotopyOptions(seed=seed)
        if not system.is_square:
            raise tracking.HomotopyError(f"{system.name} has {len(system.equations)} equations in "
                                         f"{len(system.unknowns)} unknowns: a homotopy solver needs a square system")
        system.check_parameters_occur()
        _check_names(system)
        if job.start is None:
            _check_linear_in_parameters(system)
        if job.checkpoint is None:
            _compile_tapes_early(system)
        full_report = None
        if full is not None:
            if tuple(full.unknowns) != tuple(system.unknowns) or tuple(full.parameters) != tuple(system.parameters):
                raise tracking.HomotopyError(f"{full.name} and {system.name} differ in unknowns or parameters")
            if progress:
                progress(f"{full.name}: certifying the full system's root count over GF(p) (two primes x 2 seeds)")
            full_report = full.degree(seeds=(0, 1))
            if not full_report.zero_dimensional or full_report.degree == 0:
                raise tracking.HomotopyError(f"{full.name}: the full system is not zero-dimensional with roots "
                                             f"(dimension {full_report.dimension}, degree {full_report.degree})")
        # verified once, below: a squared system on the paths it will track (not on all its roots), a system
        # with its own step control as it will run
        build_options = dataclasses.replace(options, verify_trials=0) if full is not None or job.step_control else options
        if job.evidence == "monodromy" and job.checkpoint is not None:
            if full is not None:
                raise GenerationError(f"{system.name}: a squared system needs the full system's GF(p) count")
            if progress:
                progress(f"{system.name}: no GF(p) certificate; the roots of the monodromy checkpoint {job.checkpoint}, "
                         "checked against the system")
            checkpoint = monodromy.read_checkpoint(job.checkpoint)
            ck_options = dataclasses.replace(build_options, stall_loops=SETTLED_LOOPS,
                                             verify_trials=min(build_options.verify_trials, CHECKPOINT_VERIFY_TRIALS))
            spec, source, build = homotopy.build(system, None, None, job.trials, ck_options, progress,
                                                 checkpoint=checkpoint, group=job.group)
            certified = None
            evidence = {"method": "monodromy", "degree": spec["degree"], "orbits": len(spec["start_roots"]),
                        "group_order": 1 if job.group is None else len(job.group), "checkpoint": os.path.basename(job.checkpoint),
                        "loops": checkpoint.loops, "paths_tracked": checkpoint.paths, "stall_loops": SETTLED_LOOPS,
                        "loops_without_new": checkpoint.stall, "saturated_by": list(system.nonzero),
                        "note": "numerical evidence only: no GF(p) certificate and no trace test; the roots of a settled "
                                "monodromy count (scripts/monodromy_counts.py), checked to satisfy the system at q0"}
        elif job.evidence == "monodromy":
            if full is not None:
                raise GenerationError(f"{system.name}: a squared system needs the full system's GF(p) count")
            if progress:
                progress(f"{system.name}: no GF(p) certificate asked; the solutions of the monodromy count "
                         f"({job.counted.evidence if job.counted is not None else 'none given'})")
            counted = _checked_count(system, job.counted)
            q0, roots = counted.q0, counted.roots
            spec, source, build = homotopy.build(system, None, lambda rng: (q0, roots[0]), job.trials, build_options,
                                                 progress, group=counted.group,
                                                 grow=lambda *args: (roots, {"count": counted.evidence}))
            certified = None
            evidence = {"method": "monodromy", "degree": spec["degree"], "seeds": [s.seed for s in counted.seeds],
                        "count": counted.evidence, "proven": counted.proven,
                        "graphs": [f"seed {s.seed}: {s.solutions}, {'closed' if s.closed else 'not closed'}"
                                   + (f", {s.carried}" if s.carried else "") for s in counted.seeds],
                        "loops_checked": counted.loops_checked, "notes": list(counted.notes),
                        "saturated_by": list(system.nonzero),
                        "note": "numerical evidence only: no GF(p) certificate (F4 could not be run or was not asked); "
                                "the count of solvers.count, a lower bound unless its words say it is complete"}
        else:
            if progress:
                progress(f"{system.name}: certifying the root count over GF(p) (two primes x {len(job.seeds)} seed(s))")
            report = system.degree(seeds=job.seeds)
            if not report.zero_dimensional:
                raise tracking.HomotopyError(f"{system.name} is positive-dimensional (dimension {report.dimension}): add equations")
            if report.degree == 0:
                raise tracking.HomotopyError(f"{system.name} has no solutions at generic parameters (inconsistent)")
            spec, source, build = homotopy.build(system, report.degree, job.start, job.trials, build_options, progress,
                                                 grow=graph_growth(seed))
            certified = {"primes": list(report.primes), "seeds": list(job.seeds), "degree": report.degree,
                         "saturated_by": list(system.nonzero)}
            evidence = None
        spec = {"name": job.name, **spec, "paths": len(spec["start_roots"]),
                **({"certified": certified} if certified else {"evidence": evidence}),
                "config": list(job.config) if job.config else None,
                **({"unused_parameters": list(system.unused)} if system.unused else {}),
                "scale_powers": list(system.scale_powers) if system.scale_powers else None}
        coefficients = tracking.load_coefficients(source)
        if full_report is not None:
            tracked = homotopy.full_system_roots(full, spec, coefficients, full_report.degree)
            spec["full_system"] = {"system": full.name, "equations": len(full.equations), "degree": full_report.degree,
                                   "primes": list(full_report.primes), "seeds": [0, 1], "tracked": tracked}
            spec["degree"] = spec["paths"] = full_report.degree
            build["tracked"] = f"{len(tracked)} of {len(spec['start_roots'])}"
        spec.update(step_control_fields(job.step_control, squared=full_report is not None))
        if (job.step_control or {}).get("starts", 1) > 1:
            if progress:
                progress(f"{system.name}: solving {job.step_control['starts'] - 1} further start system(s)")
            spec["starts"] = homotopy.extra_starts(spec, tracking.load_coefficients(source), job.step_control["starts"] - 1)
        if (full_report is not None or job.step_control) and job.trials is not None and options.verify_trials:
            # verified on the paths and with the step control it will run with
            build["verified"] = homotopy.verify(full.name if full_report is not None else system.name, spec,
                                                coefficients, job.trials, options.verify_trials)
        return Built(spec, source, spec["degree"] if certified is None else report.degree, spec["paths"], build)


class ActionMatrixMethod:
    """Action matrix with an elimination template (:mod:`solvers.methods.action_matrix`) of a square
    parametric system: the root count certified over GF(p) first (as for the homotopy), then the template
    built and checked on a second instance and prime, then the solver checked on seeded real instances."""

    kind = "action-matrix"

    def build(self, job: Job, seed: int, progress: Callable[[str], None] | None) -> Built:
        system = job.system
        if system is None or not system.is_square or job.full is not None:
            raise GenerationError(f"{job.name}: the action-matrix method needs a square parametric system")
        if progress:
            progress(f"{system.name}: certifying the root count over GF(p) (two primes x {len(job.seeds)} seed(s))")
        report = system.degree(seeds=job.seeds)
        if not report.zero_dimensional or report.degree == 0:
            raise GenerationError(f"{system.name}: not zero-dimensional with roots (dimension {report.dimension})")
        spec = action_matrix.build(system, report.degree, progress=progress)
        spec = {"name": job.name, **spec, "certified": {"primes": list(report.primes), "seeds": list(job.seeds),
                                                        "degree": report.degree, "saturated_by": list(system.nonzero)},
                "config": list(job.config) if job.config else None,
                **({"unused_parameters": list(system.unused)} if system.unused else {}),
                "scale_powers": list(system.scale_powers) if system.scale_powers else None}
        source = tracking.coefficient_source(action_matrix.extended_system(system))
        build = {"template": "x".join(map(str, spec["template"]["size"])), "action": f"y{spec['template']['action']}"}
        if job.trials is not None:
            build["verified"] = action_matrix.verify(system.name, spec, tracking.load_coefficients(source), job.trials, 20)
        return Built(spec, source, report.degree, report.degree, build)


#: Method name -> strategy (names as in solvers.methods.spec.METHODS).
METHODS: dict[str, Method] = {
    "curve-pencil": FormulationMethod("curve-pencil", SOLVERS["6r4s"], "certifying the root count over GF(p) and "
                                      "building the pencil", pencil.build, codegen.pencil_coefficients),
    "homotopy": HomotopyMethod(),
    "offset-kernel": FormulationMethod("offset-kernel", SOLVERS["9r5s3d"], "certifying the root count over GF(p) "
                                       "(two primes x 2 seeds), checking the kernel on seeded room networks",
                                       offset_kernel.build, codegen.offset_kernel_coefficients),
    "action-matrix": ActionMatrixMethod(),
}
assert tuple(METHODS) == METHOD_NAMES


#: Names the generated coefficient function uses itself (solvers.methods.tracking.coefficient_source:
#: its argument q, numpy, its result, sympy.cse's t_0, t_1, ...): a system's names must differ.
GENERATED_CODE_NAMES = re.compile(r"q|np|out|coefficients|t_\d+")


def _check_names(system: ParametricSystem) -> None:
    names = system.unknowns + system.parameters + tuple(name for name, _ in system.definitions)
    taken = [v for v in names if GENERATED_CODE_NAMES.fullmatch(v)]
    if taken:
        raise tracking.HomotopyError(f"{system.name}: the names {', '.join(taken)} are used by the generated solver "
                                     "code (q, np, out, coefficients, t_0, t_1, ...); rename them")


def _check_linear_in_parameters(system: ParametricSystem) -> None:
    """Raise unless the generator can draw a start pair itself (coefficients affine in the parameters)."""
    degrees = system.coefficient_degrees
    if system.definitions or max(degrees) > 1:
        k = next((i for i, d in enumerate(degrees) if d > 1), None)
        where = ""
        if k is not None:
            sizes = np.cumsum([len(eq) for eq in system.terms])
            where = f" (equation {int(np.searchsorted(sizes, k, side='right')) + 1} has a coefficient of degree {degrees[k]})"
        raise tracking.HomotopyError(
            f"{system.name}: the parameters enter non-linearly{where}; the generator draws a start pair (generic "
            "complex parameters with a known root) only for systems linear in their parameters. Give one: "
            "`tdoa-workbench generate FILE --out DIR --start START.json` (parameters and a root there) or "
            "solvers.generate.generate(system, start=(q0, x0), out=...)")


# --------------------------------------------------------------------------------------------------
# the entry
# --------------------------------------------------------------------------------------------------


def committed_command(label: str, method: str | None = None) -> str:
    """The command that regenerates a committed solver (run from the repository root); ``method``: one
    asked for by name (the action-matrix solvers committed beside the homotopy ones). A solver built from a
    monodromy checkpoint (:data:`MONODROMY_CHECKPOINTS`) needs that file in $TDOA_WORKBENCH_CACHE/monodromy/."""
    return f"python scripts/generate_solvers.py {label}" + (f" --method {method}" if method else "")


def _config(label: str) -> tuple[int, int]:
    """(m, n) of a configuration or formulation label, any model and dimension (``7r3s:...``, ``9r5s-tdoa3d:...``)."""
    found = re.match(r"(\d+)r(\d+)s", label)
    if found is None:
        raise GenerationError(f"{label!r} does not start with a configuration such as 7r3s")
    return int(found.group(1)), int(found.group(2))


def _job(target, name: str | None, start: Start | None, method: str | None,
         full: ParametricSystem | None = None) -> tuple[Job, str, str | None]:
    """The job, its method and (for a committed configuration) its label."""
    if full is not None and not isinstance(target, ParametricSystem):
        raise GenerationError("full= is for a parametric system that squares it; TDOA targets square their own")
    if isinstance(target, ParametricSystem):
        if method not in (None, "homotopy"):
            raise GenerationError(f"{target.name}: a parametric system is solved by the homotopy method, not {method!r}")
        if start is not None and not callable(start):
            q0, x0 = (np.asarray(v, dtype=complex) for v in start)
            start = lambda rng, q0=q0, x0=x0: (q0, x0)  # noqa: E731 (the build draws nothing from rng)
        return Job(name or _identifier(target.name), system=target, start=start, full=full), "homotopy", None
    if not isinstance(target, str):
        raise GenerationError(f"target must be a configuration label, a formulation label or a ParametricSystem, "
                              f"got {type(target).__name__}")
    label = target.replace("/", "") if target.replace("/", "") in SOLVERS else None
    formulation = SOLVERS[label] if label else target
    if label is None and ":" not in target:
        raise GenerationError(f"unknown configuration {target!r}; committed: {', '.join(SOLVERS)}; or give a "
                              "formulation label such as 7r3s:B2,B3,C2-C7 or a parametric system")
    if start is not None:
        raise GenerationError(f"{target}: TDOA targets draw their own start pair (a complex network)")
    config = _config(formulation)
    name = name or "tdoa_" + (label or re.sub(r"\W+", "_", target).strip("_"))
    if label in POSITIONS:
        if method not in (None, "homotopy"):
            raise GenerationError(f"{label}: its positions formulation is solved by the homotopy method, not {method!r}")
        system, variant = solver_system(label), POSITIONS[label]
        return (Job(name, formulation, system, config, positions_start(*config, variant),
                    positions_trials(*config, variant, system.scale_powers), step_control=STEP_CONTROL.get(label)),
                "homotopy", label)
    chosen = method or solver_method(Formulation.parse(formulation))
    if chosen in ("curve-pencil", "offset-kernel"):
        return Job(name, formulation, config=config), chosen, label
    kind = Formulation.parse(formulation).config
    direct = kind.parametrization == "direct"
    system = solver_system(label) if label else from_formulation(formulation, saturate_det_h=not direct)
    squared = label in SQUARED or label in SQUARE_MINORS
    full = from_formulation(formulation, saturate_det_h=True) if squared else None
    trials = tdoa_trials(formulation.split(":")[0], system.scale_powers) if label else None
    group = gauge_reflections(system.unknowns) if direct else None
    start = tdoa_start(*config, kind.dim, kind.model, kind.parametrization, START_POSITIONS.get(label, "complex"))
    return (Job(name, formulation, system, config, start,
                trials, full, seeds=(0,) if squared else (0, 1), step_control=STEP_CONTROL.get(label), group=group),
            chosen, label)


def _identifier(text: str) -> str:
    return re.sub(r"\W+", "_", text).strip("_") or "system"


def _remove_stale(out: str, name: str, keep: str) -> None:
    """Remove this solver's older modules and specs in ``out`` (other sizes or methods); nothing else. An
    action-matrix solver lives beside the others: it replaces only an older action-matrix file, and they
    replace it never."""
    kinds = "action" if keep.rsplit("_", 1)[-1].startswith("action") else "pencil|homotopy|kernel"
    stale = re.compile(re.escape(name) + rf"_({kinds})\d+")
    for f in os.listdir(out):
        stem, ext = os.path.splitext(f)
        if ext in (".py", ".json") and stem != keep and stale.fullmatch(stem):
            os.remove(os.path.join(out, f))


def write(out: str, name: str, spec: dict, coefficients: str, command: str) -> str:
    """Write ``<module>.json`` and ``<module>.py`` into ``out`` (older files of the solver removed); the module path."""
    stem = codegen.module_name(name, spec)
    text = dump_spec(spec)
    os.makedirs(out, exist_ok=True)
    _remove_stale(out, name, stem)
    with open(os.path.join(out, stem + ".json"), "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)
    py_path = os.path.join(out, stem + ".py")
    with open(py_path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(codegen.emit_module(text, stem + ".json", coefficients, command))
    return py_path


#: How a homotopy solver's root count is established: "gf" (certified over GF(p), two primes x two seeds,
#: before any monodromy) or "monodromy" (numerical evidence alone: the solutions of a count of solvers.count, or of
#: a settled monodromy checkpoint; for systems whose F4 count does not fit, e.g. the 3D TDOA minimal cells). The spec
#: then carries "evidence" instead of "certified", and the module's header says so.
EVIDENCE = ("gf", "monodromy")


def generate(target: "str | ParametricSystem", method: str | None = None, *, out: str, name: str | None = None,
             seed: int = 0, start: Start | None = None, full: ParametricSystem | None = None,
             command: str | None = None, progress: Callable[[str], None] | None = None,
             evidence: str = "gf", from_monodromy: str | None = None, counted=None) -> Generated:
    """Build a solver and write its spec and module into ``out`` (and nowhere else).

    target: a committed configuration (:data:`SOLVERS`, e.g. ``"9r3s"``), a TDOA formulation label
    (``"7r3s:B2,B3,C2-C7"``) or a square :class:`ParametricSystem`. method: one of :data:`METHODS`
    (default: ``curve-pencil`` for the pencil's formulation, ``homotopy`` otherwise). out: output
    directory (created). name: file-name prefix (default ``tdoa_<label>``, or the system's name).
    seed: monodromy seed. evidence: :data:`EVIDENCE` ("monodromy": no GF(p) certificate, numerical
    evidence alone, stated in the spec and the module's header). start: a start pair (q0, x0) for a system not linear in its parameters
    (refused without one). full: the over-determined system that a parametric ``target`` squares (its
    count is certified too and only the start roots satisfying it are tracked; same unknowns and
    parameters). command: the regenerating command printed in the module's header (default:
    :func:`committed_command` for a committed configuration written to :data:`GENERATED_DIR`, the
    ``tdoa-workbench generate`` command for another label, else a description of this call).
    from_monodromy: a checkpoint of :func:`solvers.continuation.monodromy.monodromy_count` (scripts/monodromy_counts.py,
    the same system and settled: :data:`SETTLED_LOOPS` loops without a new root) whose start parameters and roots
    the solver takes instead of growing them again; every root is checked to satisfy the system there (implies
    evidence "monodromy"; the spec's evidence records the checkpoint's loops, paths and loops without a new root).
    counted: a :class:`solvers.count.CountResult` of the same target (:func:`solvers.count.count`, two seeds or
    more) whose first seed's parameters and proven solutions the solver starts from (implies evidence
    "monodromy"; refused unless its graphs closed and its seeds' sets are equal; the spec's evidence records the
    count's words, such as "at least 27, proven (Krawczyk's test, disjoint boxes)").
    """
    if method is not None and method not in METHODS:
        raise GenerationError(f"unknown method {method!r}; valid: {', '.join(METHODS)}")
    if evidence not in EVIDENCE:
        raise GenerationError(f"unknown evidence {evidence!r}; valid: {', '.join(EVIDENCE)}")
    if from_monodromy is not None:
        if not os.path.isfile(from_monodromy):
            raise GenerationError(f"{from_monodromy}: no such monodromy checkpoint (scripts/monodromy_counts.py writes them)")
        evidence = "monodromy"
    if counted is not None:
        evidence = "monodromy"
    t0 = time.perf_counter()
    job, kind, label = _job(target, name, start, method, full)
    if evidence != "gf":
        if kind != "homotopy":
            raise GenerationError(f"{job.name}: evidence {evidence!r} is for the homotopy method, not {kind}")
        job = dataclasses.replace(job, evidence=evidence, checkpoint=from_monodromy, counted=counted)
    built = METHODS[kind].build(job, seed, progress)
    if command is None:
        if label is not None and job.name == f"tdoa_{label}" and os.path.abspath(out) == GENERATED_DIR:
            command = committed_command(label, kind if kind == "action-matrix" else None)
        elif isinstance(target, str) and name is None and method in (None, kind):
            command = f"tdoa-workbench generate {shlex.quote(target)} --out {shlex.quote(out)}"
            command += f" --seed {seed}" if seed else ""
        else:
            what = repr(target) if isinstance(target, str) else f"the system {target.name!r}"
            command = f"call solvers.generate.generate({what}, method={kind!r}, out=..., seed={seed})"
    py_path = write(out, job.name, built.spec, built.coefficients, command)
    system = job.system.name if job.system is not None else job.formulation
    report = built.report
    note = tracking.scaling_note(job.system) if job.system is not None else ""
    if note:  # said, not hidden: the solver's float coefficients are the scaled equations'
        report = {**report, "scaling": note}
    return Generated(codegen.module_name(job.name, built.spec), system, kind, built.degree, built.candidates,
                     time.perf_counter() - t0, py_path, report, evidence)


def emit_committed(json_path: str) -> tuple[str, str]:
    """(module path, module text) of a committed solver re-emitted from its spec (no numerics recomputed)."""
    with open(json_path, encoding="utf-8") as fh:
        text = fh.read()
    stem = os.path.splitext(os.path.basename(json_path))[0]
    label = stem.split("_")[1]
    if label not in SOLVERS:
        raise GenerationError(f"{json_path}: not a committed configuration ({', '.join(SOLVERS)})")
    if "_pencil" in stem:
        coefficients = codegen.pencil_coefficients(codegen.read_spec(text))
    elif "_kernel" in stem:
        coefficients = codegen.offset_kernel_coefficients(codegen.read_spec(text))
    elif "_action" in stem:
        coefficients = tracking.coefficient_source(action_matrix.extended_system(solver_system(label)))
        return json_path[:-5] + ".py", codegen.emit_module(text, stem + ".json", coefficients,
                                                           committed_command(label, "action-matrix"))
    else:
        coefficients = tracking.coefficient_source(solver_system(label))
    return json_path[:-5] + ".py", codegen.emit_module(text, stem + ".json", coefficients, committed_command(label))


def committed_specs(directory: str = GENERATED_DIR) -> list[str]:
    """Paths of the committed specs (one per solver in ``directory``)."""
    return [os.path.join(directory, f) for f in sorted(os.listdir(directory))
            if f.startswith("tdoa_") and f.endswith(".json")]


