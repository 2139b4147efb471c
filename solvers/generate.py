"""One generator for every solver: a formulation or a user's parametric system -> spec + module.

``generate(label)`` builds a committed TDOA solver (see :data:`SOLVERS`); ``generate_system(system)``
builds one for any square :class:`analysis.parametric.ParametricSystem` (e.g. read from a text file by
:func:`analysis.parametric.parse`). Methods:

* ``pencil`` (6r4s): the eigenvalue construction of :mod:`solvers.methods.pencil` (curve pencil);
* ``homotopy``: parameter homotopy (:mod:`solvers.methods.homotopy`), the general method: every
  square system with a certified root count gets one.

Every homotopy solver's root count is certified over GF(p) first (two primes, two seeds, known root
checked); monodromy must reach exactly that count. An over-determined formulation (5r4s, 5r5s) is
squared by random integer combinations of its minors; the full system's count is certified too, and
only the start roots that satisfy it are tracked (5r/5s: 64 of the squared system's 710). Output: ``<name>.json`` (plain-text spec) and
``<name>.py`` (do-not-edit header with the spec's sha256; coefficient function; ``solve(F)``).
"""
from __future__ import annotations

import dataclasses
import json
import os
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from analysis.parametric import ParametricSystem, from_formulation, from_positions, square

from .methods import homotopy, tracker
from .methods.spec import dump_spec, spec_sha256

__all__ = ["GENERATED_DIR", "SOLVERS", "Generated", "emit_homotopy_module", "generate", "generate_system",
           "homotopy_module_name"]

GENERATED_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "generated")

#: Configuration label -> formulation of its committed homotopy solver (Table 3 cells).
SOLVERS = {
    "9r3s": "9r3s:C2-C9",
    "8r3s": "8r3s:B2,C2-C8",
    "7r3s": "7r3s:B2,B3,C2-C7",
    "6r3s": "6r3s:A,B2,B3,C2-C6",
    "5r4s": "5r4s:A,B2,B3,C2-C5,minors",
    "5r5s": "5r5s:B2,B3,C2-C5,minors",
    "4r5s": "4r5s:positions-receivers-orbits",
}

#: Configurations solved in a positions formulation (analysis.positions) instead of (H, b, o).
POSITIONS = {"4r5s": "receivers-orbits"}

#: Over-determined formulations (dependent rank-2 minors): keep this many leading equations and replace
#: the minors by random integer combinations (analysis.parametric.square); counted on one seed.
SQUARED = {"5r4s": 7, "5r5s": 6}


def solver_system(label: str) -> ParametricSystem:
    """The (square) parametric system of a registered configuration, det H saturated."""
    if label in POSITIONS:
        m, n = (int(v) for v in label[:-1].split("r"))
        return from_positions(m, n, POSITIONS[label])
    system = from_formulation(SOLVERS[label], saturate_det_h=True)
    if label in SQUARED:
        system = square(system, SQUARED[label], seed=0, name=f"{system.name} (minors squared, seed 0)")
    return system


@dataclass(frozen=True)
class Generated:
    """What a generation built (printed by the CLI as a readable summary)."""

    name: str
    system: str
    method: str
    degree: int
    paths: int
    seconds: float
    module: str
    report: dict

    def summary(self) -> str:
        extra = ", ".join(f"{k} {v}" for k, v in self.report.items() if k not in ("method", "degree", "paths", "seconds"))
        return (f"{self.system}: {self.method}, {self.degree} roots certified over GF(p), {self.paths} paths; "
                f"{extra}; {self.seconds:.1f} s -> {self.module}")


# --------------------------------------------------------------------------------------------------
# TDOA start instances and trials (complex networks; real seeded networks)
# --------------------------------------------------------------------------------------------------


def complex_instance(m: int, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A complex network's data F (m, n), normalised by its RMS modulus, and its root in that frame.

    Receivers, transmitters and offsets are complex normal; d_ij is a square root of the (complex)
    squared distance (the equations use only d_ij^2). The root is (H, b, o) with H = (4 S^T S)^-1,
    b = -1/2 S^-1 s_1 (r_1 translated to 0; transposes, not conjugates), as in solvers.synthetic.
    """
    r = rng.normal(size=(m, 2)) + 1j * rng.normal(size=(m, 2))
    t = rng.normal(size=(n, 2)) + 1j * rng.normal(size=(n, 2))
    o = rng.normal(size=n) + 1j * rng.normal(size=n)
    F = np.sqrt(((r[:, None, :] - t[None, :, :]) ** 2).sum(axis=-1)) + o[None, :]
    s1 = t[0] - r[0]
    S = np.column_stack([t[1] - t[0], t[2] - t[0]])
    H = np.linalg.inv(4.0 * S.T @ S)
    b = -0.5 * np.linalg.solve(S, s1)
    x = np.concatenate([[H[0, 0], H[0, 1], H[1, 1]], b, o])
    scale = np.sqrt(np.mean(np.abs(F) ** 2))
    powers = np.array([-2.0] * 3 + [0.0] * 2 + [1.0] * n)
    return F / scale, x / scale**powers


def _tdoa_start(m: int, n: int) -> Callable[[np.random.Generator], tuple[np.ndarray, np.ndarray]]:
    def start(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        F, x = complex_instance(m, n, rng)
        return F.ravel(), x

    return start


def _positions_start(m: int, n: int, variant: str) -> Callable[[np.random.Generator], tuple[np.ndarray, np.ndarray]]:
    """Complex networks in the gauge of analysis.positions, normalised by the RMS modulus of F."""
    from analysis.positions import _root_from_network, _to_gauge, positions_system

    ps = positions_system(m, n, variant)

    def start(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        r = rng.normal(size=(m, 2)) + 1j * rng.normal(size=(m, 2))
        t = rng.normal(size=(n, 2)) + 1j * rng.normal(size=(n, 2))
        o = rng.normal(size=n) + 1j * rng.normal(size=n)
        rec, tra = _to_gauge(r, t)
        F = np.sqrt(((rec[:, None, :] - tra[None, :, :]) ** 2).sum(axis=-1)) + o[None, :]
        s = np.sqrt(np.mean(np.abs(F) ** 2))
        rec, tra, o = rec / s, tra / s, o / s
        return (F / s).ravel(), np.array(_root_from_network(ps, rec, tra, o), dtype=complex)

    return start


def _positions_trials(m: int, n: int, variant: str, powers) -> Callable[[int], tuple[np.ndarray, np.ndarray]]:
    from analysis.positions import sample_real_positions

    def trial(seed: int) -> tuple[np.ndarray, np.ndarray]:
        F, root = sample_real_positions(m, n, 10_000 + seed, variant)
        s = np.sqrt(np.mean(F * F))
        return (F / s).ravel(), root / s ** np.array(powers)

    return trial


def _tdoa_trials(label: str, powers: tuple[float, ...]) -> Callable[[int], tuple[np.ndarray, np.ndarray]]:
    from analysis.formulations import sample_real_instance

    def trial(seed: int) -> tuple[np.ndarray, np.ndarray]:
        inst = sample_real_instance(label, 10_000 + seed)
        F = np.array(inst.F)
        s = np.sqrt(np.mean(F * F))
        return (F / s).ravel(), np.array(inst.root) / s ** np.array(powers)

    return trial


# --------------------------------------------------------------------------------------------------
# emission
# --------------------------------------------------------------------------------------------------

HOMOTOPY_TEMPLATE = '''\
# Generated by solvers.generate from {spec_file} -- DO NOT EDIT (run `tdoa-workbench generate {label}`).
# spec sha256: {spec_sha}
"""Solver for {system}: parameter homotopy with {paths} paths in {nvars} unknowns.

The {paths} roots of a generic complex start instance (certified count over GF(p), found by monodromy)
are tracked to the data by the compiled tracker of solvers.methods.tracker.{tracked_note}
solve(F) -> ({paths}, {nvars}) complex candidate roots in the unknown order {unknown_list};
solve_batch(F) for F of shape (..., {pshape}) -> (..., {paths}, {nvars}). NaN rows for lost paths.
"""
from __future__ import annotations

import os

import numpy as np

from solvers.methods import homotopy as _method

SYSTEM = "{system}"
CONFIG = {config}
UNKNOWNS = {unknowns}
PARAMETERS = {nparams}
METHOD = "homotopy"
DEGREE = {degree}
PATHS = {paths}
START_ROOTS = {start_roots}
SCALE_POWERS = {scale_powers}
SPEC_FILE = "{spec_file}"
SPEC_SHA256 = "{spec_sha}"

_SOLVER = []


{coefficient_source}

def solver():
    """The runtime solver built from the spec (once per process)."""
    if not _SOLVER:
        with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), SPEC_FILE), encoding="utf-8") as fh:
            _SOLVER.append(_method.HomotopySolver(_method.load_spec(fh.read()), coefficients))
    return _SOLVER[0]


def solve_batch(F):
    """Candidate roots for a batch of data F (..., {pshape}) -> (..., {paths}, {nvars}) complex."""
    return _method.solve_scaled(solver(), F, {pshape_tuple}, SCALE_POWERS)


def solve(F):
    """Candidate roots ({paths}, {nvars}) for one instance F ({pshape})."""
    return solve_batch(np.asarray(F)[None])[0]
'''


def homotopy_module_name(spec: dict) -> str:
    return f"{spec['name']}_homotopy{spec['paths']}"


def emit_homotopy_module(spec_text: str, spec_file: str, source: str) -> str:
    spec = homotopy.load_spec(spec_text)
    config = spec.get("config")
    pshape = tuple(config) if config else (len(spec["parameters"]),)
    return HOMOTOPY_TEMPLATE.format(
        spec_file=spec_file, spec_sha=spec_sha256(spec_text), label=spec["name"], system=spec["system"],
        paths=spec["paths"], nvars=len(spec["unknowns"]), unknown_list=", ".join(spec["unknowns"]),
        pshape=", ".join(map(str, pshape)), pshape_tuple=repr(pshape), config=repr(tuple(config)) if config else "None",
        unknowns=repr(tuple(spec["unknowns"])), nparams=len(spec["parameters"]), degree=spec["degree"],
        scale_powers=repr(tuple(spec["scale_powers"])) if spec.get("scale_powers") else "None",
        coefficient_source=source, tracked_note=_tracked_note(spec), start_roots=len(spec["start_roots"]))


def _tracked_note(spec: dict) -> str:
    full = spec.get("full_system")
    if not full:
        return ""
    return (f"\nThe spec stores all {len(spec['start_roots'])} roots of the squared system; only the {spec['paths']} that also\n"
            f"satisfy the full system ({full['equations']} equations, {full['degree']} roots certified over GF(p)) are tracked.")


def _write(spec: dict, source: str, directory: str) -> str:
    name = homotopy_module_name(spec)
    text = dump_spec(spec)
    with open(os.path.join(directory, name + ".json"), "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)
    py_path = os.path.join(directory, name + ".py")
    with open(py_path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(emit_homotopy_module(text, name + ".json", source))
    return py_path


def _remove_stale(prefix: str, keep: str, directory: str) -> None:
    for f in os.listdir(directory):
        stem, ext = os.path.splitext(f)
        if stem.startswith(prefix + "_") and stem != keep and ext in (".py", ".json") and "homotopy" in stem:
            os.remove(os.path.join(directory, f))


def generate_system(system: ParametricSystem, name: str, directory: str = GENERATED_DIR,
                    options: homotopy.HomotopyOptions = homotopy.HomotopyOptions(),
                    start=None, trials=None, config: tuple[int, int] | None = None,
                    progress: Callable[[str], None] | None = None, seeds: tuple[int, ...] = (0, 1),
                    full: ParametricSystem | None = None) -> Generated:
    """Certify the root count over GF(p) (two primes x ``seeds``), build the homotopy solver and write spec + module.

    full: the over-determined system that ``system`` squares (same unknowns and parameters). Its root
    count is certified too (two primes, two seeds), and only the start roots that satisfy it are
    tracked (:func:`solvers.methods.homotopy.full_system_roots`): 5r/5s tracks 64 of 710 paths.
    """
    t0 = time.perf_counter()
    if not system.is_square:
        raise homotopy.HomotopyError(f"{system.name} has {len(system.equations)} equations in "
                                     f"{len(system.unknowns)} unknowns: a homotopy solver needs a square system")
    system.check_parameters_occur()
    full_report = None
    if full is not None:
        if tuple(full.unknowns) != tuple(system.unknowns) or tuple(full.parameters) != tuple(system.parameters):
            raise homotopy.HomotopyError(f"{full.name} and {system.name} differ in unknowns or parameters")
        if progress:
            progress(f"{full.name}: certifying the full system's root count over GF(p) (two primes x 2 seeds)")
        full_report = full.degree(seeds=(0, 1))
        if not full_report.zero_dimensional or full_report.degree == 0:
            raise homotopy.HomotopyError(f"{full.name}: the full system is not zero-dimensional with roots "
                                         f"(dimension {full_report.dimension}, degree {full_report.degree})")
    if progress:
        progress(f"{system.name}: certifying the root count over GF(p) (two primes x {len(seeds)} seed(s))")
    report = system.degree(seeds=seeds)
    if not report.zero_dimensional:
        raise homotopy.HomotopyError(f"{system.name} is positive-dimensional (dimension {report.dimension}): add equations")
    if report.degree == 0:
        raise homotopy.HomotopyError(f"{system.name} has no solutions at generic parameters (inconsistent)")
    # a squared system is verified once, on the paths it will track (below), not on all its roots
    build_options = dataclasses.replace(options, verify_trials=0) if full is not None else options
    spec, source, build = homotopy.build(system, report.degree, start, trials, build_options, progress)
    spec = {"name": name, **spec, "paths": len(spec["start_roots"]),
            "certified": {"primes": list(report.primes), "seeds": list(seeds), "degree": report.degree,
                          "saturated_by": list(system.nonzero)},
            "config": list(config) if config else None,
            "scale_powers": list(system.scale_powers) if system.scale_powers else None}
    if full_report is not None:
        coefficients = homotopy.load_coefficients(source)
        tracked = homotopy.full_system_roots(full, spec, coefficients, full_report.degree)
        spec["full_system"] = {"system": full.name, "equations": len(full.equations), "degree": full_report.degree,
                               "primes": list(full_report.primes), "seeds": [0, 1], "tracked": tracked}
        spec["degree"] = spec["paths"] = full_report.degree
        spec["tracker"] = dict(tracker.FAMILY)  # a jump to another family is invisible to the duplicate test
        build["tracked"] = f"{len(tracked)} of {len(spec['start_roots'])}"
        if trials is not None and options.verify_trials:
            build["verified"] = homotopy.verify(full.name, spec, coefficients, trials, options.verify_trials)
    os.makedirs(directory, exist_ok=True)
    _remove_stale(name, homotopy_module_name(spec), directory)
    py_path = _write(spec, source, directory)
    return Generated(homotopy_module_name(spec), system.name, "homotopy", report.degree, spec["paths"],
                     time.perf_counter() - t0, py_path, build)


def generate(label: str, directory: str = GENERATED_DIR, seed: int = 0,
             progress: Callable[[str], None] | None = None) -> Generated:
    """Build the committed solver of a TDOA configuration (see :data:`SOLVERS`)."""
    if label not in SOLVERS:
        raise ValueError(f"no homotopy solver registered for {label!r}; valid: {', '.join(SOLVERS)}")
    system = solver_system(label)
    m, n = (int(v) for v in label[:-1].split("r"))
    if label in POSITIONS:
        start, trials = _positions_start(m, n, POSITIONS[label]), _positions_trials(m, n, POSITIONS[label], system.scale_powers)
    else:
        start, trials = _tdoa_start(m, n), _tdoa_trials(label, system.scale_powers)
    full = from_formulation(SOLVERS[label], saturate_det_h=True) if label in SQUARED else None
    return generate_system(system, f"tdoa_{label}", directory, homotopy.HomotopyOptions(seed=seed),
                           start, trials, (m, n), progress,
                           seeds=(0,) if label in SQUARED else (0, 1), full=full)
