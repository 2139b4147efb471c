"""The verbs of a user's own polynomial systems: solve, generate, count (solutions, solver modules, root counts
beyond F4)."""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import re
import sys

from solvers.cli.common import (
    UserError,
    _add_f4_caps,
    _check_outputs,
    _delayed_progress,
    _f4_options,
    _integer_at_least,
    _nonnegative,
    read_system_arg,
)


def _read_text(path: str) -> str:
    """A text file's content (may be empty: --params with no values), or a one-line UserError naming it in
    the words of every input file (analysis.engine.io.read_input_bytes)."""
    from analysis.engine.io import InputError, read_input_bytes

    try:
        data = read_input_bytes(path, empty_ok=True)
    except InputError as exc:
        raise UserError(str(exc)) from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise UserError(f"{path}: not a UTF-8 text file") from None


def _add_solve(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "solve", help="every solution of a zero-dimensional system, real ones marked, with residuals",
        description=(
            "Every solution of a zero-dimensional polynomial system over Q. SYSTEM is in msolve's format "
            "(as for degree, characteristic 0) or a parametric system ('unknowns:', 'parameters:', 'equations:' "
            "and optional 'nonzero:' lines, as for generate) with its parameter values given by --param or "
            "--params. The number of solutions (with multiplicity) is the degree certified over GF(p) by a "
            "majority of random 31-bit primes; the points come from the action matrices of the basis over Q "
            "(Chinese remaindering and rational reconstruction), their eigenvectors in floating point and "
            "Newton steps on the input. The status says whether every solution was found (as many distinct "
            "points as the degree, each with a nonsingular Jacobian). See docs/cli.md."
        ),
    )
    p.add_argument("system", metavar="SYSTEM",
                   help="system file (.ms or a parametric system; '-' for stdin) or a TDOA formulation label such as "
                   "6r3s-tdoa2d-direct:all (parameters f<i>_<j>, the TDOA measurements)")
    p.add_argument("--method", choices=("auto", "action-matrix", "homotopy"), default="auto",
                   help="action-matrix (the basis over Q, eigenvectors), homotopy (a parametric system: its generated "
                   "parameter-homotopy solver, built once into the cache) or auto (default: homotopy for a formulation "
                   "label, action-matrix for a file)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="a parameter's value: an integer, a decimal or p/q, read exactly (repeatable)")
    p.add_argument("--params", metavar="FILE", help="parameter values, one NAME=VALUE a line ('#' comments)")
    out = p.add_mutually_exclusive_group()
    out.add_argument("--json", action="store_true", help="print one JSON object")
    out.add_argument("--csv", action="store_true",
                     help="print one CSV row per solution: index, real, residual, condition, then NAME_re, NAME_im "
                     "per unknown")
    p.add_argument("--seed", type=_nonnegative("--seed"), default=0,
                   help="seed of the random linear form whose action matrix is diagonalised, or of the homotopy "
                   "solver's monodromy (default 0)")
    p.add_argument("--prime-seed", type=_nonnegative("--prime-seed"), default=0, metavar="N",
                   help="the random 31-bit primes are drawn by a seed hashed from the system and N (default 0)")
    _add_f4_caps(p)
    p.set_defaults(func=cmd_solve)


def _solve_input(args: argparse.Namespace):
    """(system, parameter values, target, unknowns shown) of solve's SYSTEM: a plain system (values None) read
    by the one reader (read_system_arg), a parametric system with its values, or a formulation label's
    parametric system with the label as target."""
    from analysis.engine.io import System
    from analysis.formulations.parametric import from_formulation
    from solvers.system_solve import parameter_values

    items = list(args.param)
    if args.params:
        items += [line.split("#", 1)[0].strip() for line in _read_text(args.params).splitlines()]
        items = [item for item in items if item]
    values = parameter_values(items, "--param/--params")
    if args.system != "-" and ":" in args.system and not os.path.exists(args.system):
        from analysis.formulations.tdoa import as_formulation

        label = as_formulation(args.system).label
        system = from_formulation(label)
        return system, values, label, len(system.unknowns)
    system = read_system_arg(args.system)
    if not isinstance(system, System):
        return system, values, None, len(system.unknowns)
    if values:
        raise UserError(f"{args.system} has no parameters; --param/--params are for parametric systems")
    # a plain file's nonzero: conditions come as one more unknown t (System.saturated_by), not printed
    saturated = system.source.endswith("*f - 1")
    return system, None, None, system.nvars - 1 if saturated else system.nvars


def cmd_solve(args: argparse.Namespace) -> int:
    import csv
    import json

    from solvers.system_solve import instance_system, solve_by_homotopy, solve_system

    system, values, target, shown = _solve_input(args)
    method = args.method if args.method != "auto" else "homotopy" if target else "action-matrix"

    def progress(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    if method == "homotopy":
        if values is None:
            raise UserError("--method homotopy is for parametric systems (a system in msolve's format has no "
                            "parameters to move); use --method action-matrix")
        from solvers.generate import GenerationError
        from solvers.methods.homotopy import HomotopyError

        try:
            result = solve_by_homotopy(system, values, target, seed=args.seed, source=args.system, progress=progress)
        except (HomotopyError, GenerationError) as exc:
            raise UserError(f"{exc}; another --seed draws another monodromy") from None
    else:
        options = _f4_options(argparse.Namespace(backend="auto", max_cells=args.max_cells, max_memory=args.max_memory,
                                                 verbose=False, threads=1), linear_substitution=True)
        instance = system if values is None else instance_system(system, values, args.system)
        result = solve_system(instance, seed=args.seed, prime_seed=args.prime_seed, options=options, hidden=shown,
                              progress=progress)
    if args.json:
        print(json.dumps(result.as_dict()))
    elif args.csv:
        writer = csv.writer(sys.stdout, lineterminator="\n")
        writer.writerow(["index", "real", "residual", "condition"]
                        + [f"{u}_{part}" for u in result.unknowns for part in ("re", "im")])
        for k, s in enumerate(result.solutions, 1):
            writer.writerow([k, int(s.real), f"{s.residual:.3e}", f"{s.condition:.3e}"]
                            + [repr(float(getattr(z, part))) for z in s.values for part in ("real", "imag")])
    else:
        print(f"degree {result.degree}  ({result.certificate})")
        print(f"method: {result.method}" + (f"; {result.basis_status}" if result.basis_status else ""))
        print(f"status: {result.status}")
        print(f"{len(result.solutions)} solutions, {result.n_real} real; max residual {result.max_residual:.2g}; "
              f"{result.seconds:.2f} s")
        if result.solutions:
            print("  #  real  residual  " + "  ".join(result.unknowns))
            for k, s in enumerate(result.solutions, 1):
                coords = "  ".join(f"{z.real:.15g}" if s.real else f"{z.real:.15g}{z.imag:+.15g}i" for z in s.values)
                print(f"{k:3d}  {'real' if s.real else '-   '}  {s.residual:8.1e}  {coords}")
    return 0 if result.complete else 3


def _add_generate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "generate", help="build a numeric solver: a Table 3 configuration, any formulation, or your own system",
        description="Certify the root count over GF(p) (two primes, two seeds), build the solver and write "
        "<name>_<method><size>.json (spec) and .py (module with solve(F)) into DIR, and nowhere else. TARGET is "
        "a committed configuration (6r4s: eigenvalue pencil; 9r3s, 8r3s, 7r3s, 6r3s, 5r4s, 5r5s, 4r5s: parameter "
        "homotopy; 4r6s is solved by the 4r5s solver, the sixth transmitter filtering; 9r5s3d: the 3D offset kernel "
        "of 9r5s-tdoa3d, one root; the committed copies in "
        "solvers/generated/ are written by scripts/generate_solvers.py), a TDOA formulation label such as "
        "7r3s:B2,B3,C2-C7, or a FILE with a parametric system (lines 'unknowns: x, y', 'parameters: a, b', "
        "optional 'nonzero: x', then 'equations:' and one polynomial per line). A system whose coefficients are "
        "not linear in its parameters needs --start.")
    p.add_argument("target", help="configuration (6r4s, 9r3s, 8r3s, 7r3s, 6r3s, 5r4s, 5r5s, 4r5s, 4r6s, 9r5s3d), "
                   "formulation label or system FILE")
    p.add_argument("--out", metavar="DIR", required=True, help="output directory (created if needed)")
    p.add_argument("--seed", type=int, default=0, help="monodromy seed (default 0)")
    p.add_argument("--method", choices=("curve-pencil", "homotopy", "offset-kernel", "action-matrix"),
                   help="solving method (default: the target's own; action-matrix: an elimination template over "
                   "GF(p) and an eigensolve, docs/action-matrix.md)")
    p.add_argument("--evidence", choices=("gf", "monodromy"), default="gf",
                   help="gf (default): certify the root count over GF(p) first; monodromy: numerical evidence "
                   "alone, for systems F4 cannot count: the solutions of `count` (graphs on seeds SEED and SEED+1, "
                   "every solution proven; refused unless the graphs closed and the sets are equal); the spec and the "
                   "module's header give its evidence and say the count is not certified")
    p.add_argument("--from-monodromy", metavar="CHECKPOINT",
                   help="start from the roots of a settled monodromy count (a checkpoint of scripts/monodromy_counts.py "
                   "for the same system) instead of growing them again; each root is checked to satisfy the system at "
                   "the checkpoint's parameters. Implies --evidence monodromy")
    p.add_argument("--start", metavar="JSON",
                   help="system FILE only: a start pair, {\"parameters\": [...], \"root\": [...]} with one value per "
                   "parameter and per unknown (numbers or [re, im]); generic complex values, the root satisfying the "
                   "system there. Needed when the parameters enter non-linearly")
    p.set_defaults(func=cmd_generate)


def _read_start(path: str, system) -> tuple:
    """(q0, x0) of a --start JSON file, checked against the system's parameters and unknowns."""
    import numpy as np

    try:
        data = json.loads(_read_text(path))
    except json.JSONDecodeError as exc:
        raise UserError(f"{path}: not JSON ({exc})") from None

    def values(key: str, names) -> np.ndarray:
        raw = data.get(key) if isinstance(data, dict) else None
        if not isinstance(raw, list) or len(raw) != len(names):
            raise UserError(f"{path}: '{key}' must be a list of {len(names)} values ({', '.join(names)})")
        out = []
        for v in raw:
            parts = v if isinstance(v, list) and len(v) == 2 else [v, 0.0]
            if not all(isinstance(t, (int, float)) and not isinstance(t, bool) for t in parts):
                raise UserError(f"{path}: '{key}' values must be numbers or [re, im] pairs, got {v!r}")
            try:
                z = complex(float(parts[0]), float(parts[1]))
            except OverflowError:
                z = complex(math.inf)
            if not (math.isfinite(z.real) and math.isfinite(z.imag)):  # 1e400 and NaN read by json
                raise UserError(f"{path}: '{key}' value {v!r} is not a finite float64 (a start pair is numerics: "
                                "give generic values of modest size)")
            out.append(z)
        return np.array(out)

    return values("parameters", system.parameters), values("root", system.unknowns)


def cmd_generate(args: argparse.Namespace) -> int:
    import shlex

    from analysis.engine.io import System
    from analysis.formulations.parametric import ParametricError
    from solvers import generate as gen
    from solvers.continuation.tracking import HomotopyError
    from solvers.methods.action_matrix import ActionMatrixError
    from solvers.subsystem import SUBSYSTEMS

    if args.seed < 0:
        raise UserError(f"--seed must be a non-negative integer, got {args.seed}")
    _check_outputs({}, directories={"--out": args.out})

    def progress(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    target = args.target
    committed = ", ".join(sorted(set(gen.SOLVERS) | set(SUBSYSTEMS)))
    is_file = ":" not in target and os.path.exists(target)
    if ":" not in target and not is_file:
        label = target.replace("/", "")
        if label in SUBSYSTEMS:
            base = SUBSYSTEMS[label][0]
            print(f"{label} is solved by the {base} solver on its first transmitters, the others filtering the "
                  f"candidates (solvers.subsystem); generating {base}", file=sys.stderr)
            label = base
        if label in gen.SOLVERS:
            target = label
        elif re.fullmatch(r"\d+r/?\d+s", target):
            raise UserError(f"no committed solver for {target}; committed: {committed}; otherwise give a "
                            "formulation label such as 7r3s:B2,B3,C2-C7")
        else:
            raise UserError(f"{target}: no such file (and not a configuration or formulation label)")
    if args.start and not is_file:
        raise UserError("--start is for a system FILE; TDOA targets draw their own start pair (a complex network)")
    command = f"tdoa-workbench generate {shlex.quote(args.target)} --out {shlex.quote(args.out)}"
    command += f" --seed {args.seed}" if args.seed else ""
    command += f" --start {shlex.quote(args.start)}" if args.start else ""
    command += f" --evidence {args.evidence}" if args.evidence != "gf" else ""
    command += f" --method {args.method}" if args.method else ""
    command += f" --from-monodromy {shlex.quote(args.from_monodromy)}" if args.from_monodromy else ""
    try:
        if is_file:
            system = read_system_arg(target, os.path.basename(target))
            if isinstance(system, System):
                raise UserError(f"{target} is a plain system (no parameters): a solver needs data to vary; declare "
                                "the data as 'parameters:' (docs/generate.md), or count the solutions with "
                                f"`tdoa-workbench degree {target}`")
            name = re.sub(r"\W+", "_", os.path.splitext(os.path.basename(target))[0])
            start = _read_start(args.start, system) if args.start else None
            counted = _generate_count(args, system, start, progress)
            result = gen.generate(system, args.method, out=args.out, name=name, seed=args.seed, start=start,
                                  command=command, progress=progress, evidence=args.evidence,
                                  from_monodromy=args.from_monodromy, counted=counted)
        else:
            counted = _generate_count(args, target, None, progress)
            result = gen.generate(target, args.method, out=args.out, seed=args.seed, command=command,
                                  progress=progress, evidence=args.evidence, from_monodromy=args.from_monodromy,
                                  counted=counted)
        if counted is not None:  # the count ran before generate: its seconds are the build's too
            result = dataclasses.replace(result, seconds=result.seconds + counted.seconds)
        print(result.summary())
    except (ParametricError, HomotopyError, ActionMatrixError, gen.GenerationError) as exc:
        raise UserError(str(exc)) from None
    except OSError as exc:
        raise UserError(f"{args.out}: {exc.strerror or exc}") from None
    return 0


def _generate_count(args: argparse.Namespace, target, start, progress):
    """generate --evidence monodromy (without --from-monodromy): the count of solvers.count (seeds SEED and SEED + 1,
    every solution proven) the solver is built from; None otherwise."""
    if args.evidence != "monodromy" or args.from_monodromy:
        return None
    from solvers.count import CountOptions, count

    # numerical evidence alone, as asked: no F4 inside the count either (its scope from Bezout's bound or a trace test)
    return count(target, CountOptions(seeds=(args.seed, args.seed + 1), degree=False), progress=progress, start=start)


def _add_count(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "count", help="number of solutions of a parametric system beyond F4: graph monodromy, every solution proven",
        description="The number of isolated solutions of a square parametric system at a generic complex parameter "
        "(solvers.count): monodromy on a complete graph of parameter nodes until it closes, for every seed; every "
        "solution of the first seed proven by Krawczyk's test in ball arithmetic, boxes disjoint; the other seeds' "
        "sets carried to the first and compared as sets; random solutions carried around a fresh loop. The "
        "count shown is the proven number (the number found numerically beside it, named as such), and the evidence "
        "is printed in words: 'at least N, proven', with 'complete: ...' where F4's degree over GF(p) or Bezout's "
        "bound equals it or the trace test (--trace) passed on an irreducible incidence variety, 'complete for the "
        "component reached (N found) ...; another component may exist' where the trace test passed and nothing "
        "shows the incidence variety irreducible (docs/count.md). Exit status 0 when the count is complete for the "
        "whole solution set, 3 when it is a lower bound (the JSON's scope), 2 for bad input. Progress on stderr.")
    p.add_argument("system", nargs="?", metavar="FILE", help="a parametric system file (the generate verb's format); "
                   "or give --tdoa")
    p.add_argument("--tdoa", metavar="CONFIG", help="a configuration (7r5s with --dim 3; 3r3s with --model toa) or a "
                   "formulation label (10r4s-tdoa3d:A,B2,B3,B4,C2-C10)")
    p.add_argument("--dim", type=int, choices=(2, 3), default=2, help="with --tdoa: the dimension (default 2)")
    p.add_argument("--model", choices=("tdoa", "toa"), default="tdoa", help="with --tdoa: the model (default tdoa)")
    p.add_argument("--seeds", type=_nonnegative("--seeds"), nargs="+", default=[0, 1], metavar="K",
                   help="start pairs, one per seed (default 0 1); every set is compared with the first")
    p.add_argument("--nodes", type=_integer_at_least("--nodes", 2), default=4, metavar="K",
                   help="parameter nodes of the monodromy graph (default 4)")
    p.add_argument("--trace", action="store_true", help="also run the trace test on the first seed's set "
                   "(formulations without a group; slow for large sets)")
    p.add_argument("--no-certify", action="store_true", help="skip the Krawczyk proofs (the count is then a lower "
                   "bound, numerical)")
    p.add_argument("--seconds", type=float, default=float("inf"), metavar="S",
                   help="wall-time cap of each seed's graph (then not closed: a lower bound)")
    p.add_argument("--checkpoint", metavar="DIR", help="resumable files of the graphs in DIR (written every minute)")
    p.add_argument("--threads", type=_integer_at_least("--threads", 1), default=None, metavar="N",
                   help="track each batch on N threads (default $TDOA_WORKBENCH_THREADS or 1; the same numbers)")
    p.add_argument("--dask", metavar="ADDRESS", help="track the graphs' batches on a Dask cluster: a scheduler address, "
                   "or 'local' for a LocalCluster of one process per core (the same numbers; pip install -e \".[dask]\")")
    p.add_argument("--dask-chunk", type=_integer_at_least("--dask-chunk", 1), default=2000, metavar="N",
                   help="paths per Dask task (default 2000)")
    p.add_argument("--start", metavar="JSON", help="FILE only: a start pair for the first seed, as for generate --start; "
                   "every other seed's (and the trace test's) is drawn from it, its root tracked to random parameters")
    p.add_argument("--json", metavar="OUT", help="also write the result as JSON to OUT")
    p.set_defaults(func=cmd_count)


def cmd_count(args: argparse.Namespace) -> int:
    from analysis.formulations.parametric import ParametricError, ParametricSystem
    from solvers import count as counting
    from solvers.continuation import tape_kernel
    from solvers.continuation.tracking import HomotopyError
    from solvers.generate import GenerationError

    if (args.system is None) == (args.tdoa is None):
        raise UserError("give a system FILE or --tdoa CONFIG (one of them)")
    if args.start and args.system is None:
        raise UserError("--start is for a system FILE; TDOA targets draw their own start pairs (complex networks)")
    if not args.seconds > 0:
        raise UserError(f"--seconds must be positive, got {args.seconds}")
    # before hours of tracking, not after
    _check_outputs({"--json": (args.json, None)}, [args.system] if args.system else [],
                   directories={"--checkpoint": args.checkpoint})
    tape_kernel.set_threads(args.threads)
    try:
        if args.system is not None:
            target = read_system_arg(args.system, os.path.basename(args.system))
            if not isinstance(target, ParametricSystem):
                raise UserError(f"{args.system}: a system without parameters has one instance, not a generic one; "
                                "count its solutions with: tdoa-workbench degree " + args.system)
            if not target.is_square:
                raise UserError(f"{args.system}: {len(target.equations)} equations in {len(target.unknowns)} unknowns; "
                                "count needs a square system")
        else:
            target = counting.tdoa_target(args.tdoa, args.dim, args.model)
        options = counting.CountOptions(seeds=tuple(args.seeds), nodes=args.nodes, certify=not args.no_certify,
                                        trace=args.trace, seconds=args.seconds, checkpoints=args.checkpoint,
                                        dask=args.dask, dask_chunk=args.dask_chunk)
        start = _read_start(args.start, target) if args.start else None
        result = counting.count(target, options, progress=_delayed_progress(), start=start)
    except (ParametricError, HomotopyError, GenerationError, ValueError) as exc:
        raise UserError(" ".join(str(exc).split())) from None
    print(result.summary())
    if args.json:
        try:
            counting.write_record(result, args.json)
        except OSError as exc:
            raise UserError(f"--json: cannot write {args.json}: {exc.strerror or exc}") from None
    return 0 if result.complete else 3
