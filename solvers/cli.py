"""The ``tdoa-workbench`` command line.

Subcommands
-----------
degree     number of solutions (|B|), dimension and Gröbner basis of a system in msolve format,
           or of a TDOA formulation (``--tdoa 6r4s --equations B2,C2-C6,minors``)
tables     the complexity sweep: Tables 2 and 3 of the paper and tables/formulations.csv
generate   regenerate a numeric solver (spec over GF(p) -> solvers/generated/) and print its statistics
template-check  how many action-matrix relations single elimination templates of a formulation or of
           a system file reach over GF(p), per multiplier family and degree (solvers.feasibility)
reproduce  the main job: Tables 2, 3 and 4 and Figures 1 and 2, with a comparison to the paper
calibrate  calibrate a network from a CSV of measurements (gaps, outliers; solvers.calibrate)

Every error a user can cause (bad file, bad prime, unknown equation...) is reported as one line on
stderr with exit status 2; a disagreement between primes exits with status 3.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # F4 matrices are small: BLAS threads only add overhead


class UserError(Exception):
    """An error caused by the input; printed as one line."""


def _add_degree(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "degree",
        help="degree (number of solutions) and dimension of a polynomial system",
        description=(
            "Compute the reduced Groebner basis of a system and report its degree |B| (the number of "
            "standard monomials), or its dimension if it is not zero-dimensional. FILE is in msolve's "
            "format: line 1 comma-separated variables, line 2 the characteristic (0 or a prime), then "
            "comma-separated polynomials. Characteristic 0 systems are reduced modulo two primes "
            "(default 65521 and 32749, or those given with --prime) which must agree."
        ),
    )
    p.add_argument("file", nargs="?", help="system in msolve format ('-' for stdin)")
    p.add_argument("--tdoa", metavar="CONFIG", help="a TDOA configuration instead of FILE, e.g. 6r4s or 9r/3s")
    p.add_argument(
        "--equations",
        metavar="SPEC",
        help="with --tdoa: equations, e.g. 'B2,C2-C6,minors', 'C*', 'A,B2,B3,C2-C6', 'M123_123,...', 'all'",
    )
    p.add_argument("--seed", type=int, default=0, help="with --tdoa: seed of the consistent random instance")
    p.add_argument("--saturate-det-h", action="store_true", help="with --tdoa: saturate by det H = h11*h22 - h12^2")
    p.add_argument(
        "--export", nargs=2, metavar=("FORMAT", "PATH"),
        help="write the (first prime's) system for msolve|m2|singular to PATH and continue",
    )
    p.add_argument("--prime", type=int, action="append", help="prime to compute modulo (repeatable)")
    p.add_argument("--order", default="grevlex", help="monomial order: grevlex, lex, block:k (default grevlex)")
    p.add_argument("--saturate", metavar="POLY", help="saturate the ideal by this polynomial first")
    p.add_argument("--basis", action="store_true", help="also print the standard monomial basis")
    p.add_argument("--gb", action="store_true", help="also print the reduced Groebner basis (first prime)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--max-cells", type=int, default=400_000_000, help="cap on F4 matrix rows*cols")
    p.add_argument("--backend", default="numpy", help="linear algebra backend: numpy (fast) or python (reference)")
    p.add_argument("-v", "--verbose", action="store_true", help="per-round F4 statistics on stderr")
    p.set_defaults(func=cmd_degree)


def cmd_degree(args: argparse.Namespace) -> int:
    from analysis.degree import DEFAULT_PRIMES, analyse
    from analysis.f4 import F4Options
    from analysis.io import InputError, System, parse_msolve, parse_polynomial
    from analysis.ring import check_prime, BadPrime

    if args.tdoa:
        if args.file:
            raise UserError("give either FILE or --tdoa, not both")
        return _degree_tdoa(args)
    if args.equations or args.saturate_det_h:
        raise UserError("--equations and --saturate-det-h need --tdoa CONFIG")
    if args.file is None:
        raise UserError("give a FILE in msolve format, or --tdoa CONFIG --equations SPEC")
    try:
        text = sys.stdin.read() if args.file == "-" else open(args.file, encoding="utf-8").read()
    except OSError as e:
        raise UserError(f"cannot read {args.file}: {e.strerror}") from None
    try:
        system: System = parse_msolve(text, source=args.file)
    except InputError as e:
        raise UserError(str(e)) from None
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
    elif primes is None:
        primes = DEFAULT_PRIMES
    options = F4Options(backend=args.backend, max_matrix_cells=args.max_cells, verbose=args.verbose)

    def polys(p: int):
        try:
            return system.to_ring(p, args.order)[1]
        except InputError as e:
            raise UserError(str(e)) from None
        except ValueError as e:
            raise UserError(str(e)) from None

    sat = None
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
        from analysis.io import write_system

        write_system(system, args.export[1], args.export[0])
    report = analyse(polys, primes, options, saturate_by=sat)
    out = report.as_dict()
    if args.basis:
        out["standard_basis"] = report.standard_basis()
    if args.gb:
        out["groebner_basis"] = [str(g) for g in report.per_prime[0].gb.basis]
    _print_report(out, args.json)
    return 0


def _degree_tdoa(args: argparse.Namespace) -> int:
    """Degree of one TDOA formulation on consistent random instances (known root checked per prime)."""
    from analysis import formulations as tf
    from analysis.degree import DEFAULT_PRIMES, analyse
    from analysis.f4 import F4Options
    from analysis.ring import BadPrime, Ring, check_prime

    try:
        config = tf.TDOAConfig.parse(args.tdoa)
        formulation = tf.Formulation(config, tf.parse_equations(config, args.equations or "all"))
        primes = tuple(check_prime(p) for p in args.prime) if args.prime else DEFAULT_PRIMES
    except (ValueError, BadPrime) as e:
        raise UserError(str(e)) from None
    options = F4Options(backend=args.backend, max_matrix_cells=args.max_cells, verbose=args.verbose)
    rings: dict[int, Ring] = {}

    def polys(p: int):
        instance = tf.sample_gf_instance(config, p, args.seed)
        tf.check_root(formulation, instance)
        ring = rings.setdefault(p, Ring(config.unknowns, p, args.order))
        return [ring.from_terms(eq) for eq in tf.gf_equations(formulation, instance, p)]

    def det_h(p: int):
        ring = rings.setdefault(p, Ring(config.unknowns, p, args.order))
        return ring.gen("h11") * ring.gen("h22") - ring.gen("h12") ** 2

    if args.export:
        from analysis.io import System, write_system

        ring = Ring(config.unknowns, primes[0], args.order)
        write_system(System.from_polys(ring, polys(primes[0])), args.export[1], args.export[0])
    report = analyse(polys, primes, options, saturate_by=det_h if args.saturate_det_h else None)
    out = {"formulation": formulation.label, "seed": args.seed, **report.as_dict()}
    if args.saturate_det_h:
        out["saturated_by"] = "det H"
    if args.basis:
        out["standard_basis"] = report.standard_basis()
    if args.gb:
        out["groebner_basis"] = [str(g) for g in report.per_prime[0].gb.basis]
    if not args.json:
        print(f"formulation {formulation.label} (seed {args.seed})")
    _print_report(out, args.json)
    return 0


def _print_report(out: dict, as_json: bool) -> None:
    if as_json:
        print(json.dumps(out))
        return
    if out["dimension"] == -1:
        print("inconsistent system (the ideal is the whole ring): degree 0")
    elif out["zero_dimensional"]:
        print(f"degree {out['degree']}  (zero-dimensional)")
    else:
        print(f"positive-dimensional: dimension {out['dimension']} (no finite count of solutions)")
    print(f"primes {', '.join(map(str, out['primes']))}; Groebner basis: {out['gb_size']} elements; "
          f"largest F4 matrix {out['max_matrix'][0]} x {out['max_matrix'][1]}; {out['seconds']:.3f} s")
    for key in ("standard_basis", "groebner_basis"):
        if key in out:
            print(f"{key.replace('_', ' ')}:")
            for s in out[key]:
                print(f"  {s}")


QUICK_DIR = "tables/quick"
"""Where quick runs write, so that they never overwrite the full reproduction under tables/."""


def _add_tables(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("tables", help="reproduce Tables 2 and 3 (complexity sweep, cached and parallel)",
                       description="Run the complexity sweep over TDOA formulations and write tables/table2.*, "
                       "tables/table3.*, tables/section32.csv and tables/formulations.csv (--quick: a small budget, "
                       f"written to {QUICK_DIR}/). Results are cached under .cache/complexity, so a rerun is instant "
                       "and an interrupted sweep resumes.")
    p.add_argument("--quick", action="store_true", help=f"Table 2 and two formulations per cell, into {QUICK_DIR}/")
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--no-cache", action="store_true", help="recompute instead of reading .cache/complexity")
    p.set_defaults(func=cmd_tables)


def _run_tables(quick: bool, jobs: int, use_cache: bool = True) -> None:
    from analysis.complexity import repo_root
    from analysis.tables import make_tables

    out_dir = repo_root() / QUICK_DIR if quick else None
    summary = make_tables(quick=quick, jobs=jobs, use_cache=use_cache, out_dir=out_dir)
    print(summary.report())


def cmd_tables(args: argparse.Namespace) -> int:
    if args.jobs < 1:
        raise UserError("--jobs must be at least 1")
    _run_tables(args.quick, args.jobs, use_cache=not args.no_cache)
    return 0


def _add_generate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("generate", help="regenerate a numeric solver from its formulation (spec + module)",
                       description="Build the solver spec over GF(p) (root count, structure) for a configuration "
                       "(9r3s or 6r4s), emit solvers/generated/tdoa_<config>_<method><size>.{py,json} and print "
                       "the template statistics.")
    p.add_argument("config", help="solver configuration: 9r3s or 6r4s")
    p.set_defaults(func=cmd_generate)


def cmd_generate(args: argparse.Namespace) -> int:
    from solvers.codegen import SOLVERS, generate

    label = args.config.replace("/", "")
    if label not in SOLVERS:
        raise UserError(f"unknown solver configuration {args.config!r}; valid: {', '.join(SOLVERS)}")
    stats = generate(label)
    print(stats)
    return 0


def _add_template_check(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "template-check", help="do single elimination templates of a system reach the action-matrix relations?",
        description="Multiply the equations of a TDOA formulation (a label such as 9r3s:C2-C9) or of your own "
        "system (a FILE in msolve format) by a family of monomials up to each degree and count, over GF(p), how "
        "many of the relations x*B \\ B -> B that the action matrix of ACTION needs the Macaulay matrix reaches "
        "(exact ranks). A template is complete when it reaches all of them. Families: total (all monomials of "
        "degree <= d), offsets (monomials in o_j), linear-offsets ((H, b)-degree <= 1 times offsets). Bases: "
        "grevlex standard monomials, or (formulations) those of the elimination ideal in the offsets. A "
        "formulation is sampled as a consistent GF(p) instance; a characteristic-0 file is reduced mod p, and "
        "its number of roots is confirmed mod a second prime.")
    p.add_argument("system", help="formulation label (e.g. 9r3s:C2-C9) or a system FILE in msolve format")
    p.add_argument("--family", default="total", help="multiplier family: total, offsets, linear-offsets (default total)")
    p.add_argument("--degrees", default="1-3", help="multiplier degrees, e.g. 2 or 1-4 (default 1-3)")
    p.add_argument("--action", help="action unknown (default: the first offset, else the first unknown)")
    p.add_argument("--basis", default="grevlex", help="quotient basis: grevlex or offsets (default grevlex)")
    p.add_argument("--prime", type=int, default=65521, help="prime (default 65521; a file of characteristic p uses p)")
    p.add_argument("--seed", type=int, default=1, help="formulations: seed of the consistent GF(p) instance (default 1)")
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
    from analysis.io import InputError, read_system
    from analysis.ring import BadPrime, check_prime
    from solvers.feasibility import SECOND_PRIME, system_basis

    if basis != "grevlex":
        raise UserError(f"--basis {basis} needs a TDOA formulation; a system file uses the grevlex basis")
    try:
        system = read_system(path)
        prime = system.characteristic or check_prime(prime)
        polys = system.to_ring(prime)[1]
    except (InputError, BadPrime) as e:
        raise UserError(str(e)) from None
    except OSError as e:
        raise UserError(f"cannot read {path}: {e.strerror}") from None
    equations = [dict(f.terms()) for f in polys if f]
    B = system_basis(equations, system.variables, prime)
    note = f"GF({prime})"
    if not system.characteristic:
        other = SECOND_PRIME if prime != SECOND_PRIME else 65521
        check = system_basis([dict(f.terms()) for f in system.to_ring(other)[1] if f], system.variables, other)
        if len(check) != len(B):
            raise UserError(f"{path}: {len(B)} roots mod {prime} but {len(check)} mod {other}; try another --prime")
        note += f", confirmed mod {other}"
    return equations, tuple(system.variables), B, prime, note


def cmd_template_check(args: argparse.Namespace) -> int:
    import time

    from analysis.formulations import as_formulation
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
                       "Figures 1 and 2 (synthetic experiments, 1000 trials per row as in the paper) under tables/, "
                       "with progress output and a final comparison with the paper. Cached: a rerun resumes where "
                       f"the last one stopped. --quick: small sweep budget and 100 trials, written to {QUICK_DIR}/.")
    p.add_argument("--quick", action="store_true", help=f"a few minutes: fewer formulations and trials, into {QUICK_DIR}/")
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    p.set_defaults(func=cmd_reproduce)


def cmd_reproduce(args: argparse.Namespace) -> int:
    import time

    from analysis.complexity import repo_root
    from solvers.experiments import reproduce

    if args.jobs < 1:
        raise UserError("--jobs must be at least 1")
    t0 = time.perf_counter()
    print("== Tables 2 and 3: complexity sweep ==", flush=True)
    _run_tables(args.quick, args.jobs)
    print("== Table 4 and Figures 1, 2: synthetic experiments ==", flush=True)
    out = repo_root() / (QUICK_DIR if args.quick else "tables")
    reproduce(quick=args.quick, jobs=args.jobs, tables_dir=out)
    print(f"reproduce: done in {time.perf_counter() - t0:.0f} s; outputs under {out}")
    return 0


def _add_calibrate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "calibrate", help="calibrate a network from a CSV of TDOA measurements (missing entries, outliers)",
        description="Calibrate receivers, transmitters and transmitter offsets from MEAS.csv: one row per receiver, "
        "one column per transmitter, f_ij = |r_i - s_j| + o_j; an empty cell or NaN is a missing measurement; an "
        "optional header row and column name the nodes. LO-RANSAC over the minimal solvers, extension and robust "
        "refinement (solvers.calibrate). Exit status 0 when the calibration converged (read the warnings), 1 when "
        "it did not or failed, 2 for a malformed file or option.")
    p.add_argument("file", metavar="MEAS.csv", help="measurement matrix (CSV)")
    p.add_argument("--sigma", type=float, help="noise standard deviation of the measurements (default: estimated)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random sampling (default 0)")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.add_argument("--out", metavar="FILE.json", help="also write the JSON result to FILE.json")
    p.add_argument("--plot", metavar="FILE.png", help="draw the map (rejected measurements dashed red) to FILE.png")
    p.set_defaults(func=cmd_calibrate)


def cmd_calibrate(args: argparse.Namespace) -> int:
    from solvers.calibrate import calibrate
    from solvers.calibrate_io import MeasurementFileError, plot_calibration, read_measurements, report_dict, write_json

    if args.sigma is not None and not args.sigma >= 0:
        raise UserError(f"--sigma must be >= 0, got {args.sigma}")
    try:
        meas = read_measurements(args.file)
    except MeasurementFileError as e:
        raise UserError(str(e)) from None
    result = calibrate(meas.F, sigma=args.sigma, seed=args.seed)
    report = report_dict(result, meas)
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
                plot_calibration(result, args.plot, meas)
            except OSError as e:
                raise UserError(f"cannot write {args.plot}: {e.strerror}") from None
    if args.json:
        print(json.dumps(report))
    else:
        _print_calibration(result, meas)
    return 0 if result.ok else 1


def _print_calibration(result, meas) -> None:
    print(result.message)
    if result.status != "failed":
        print(f"sigma {result.sigma:.3g} ({'estimated' if result.sigma_estimated else 'given'}); "
              f"hypotheses from {result.solver}: {result.samples} samples, {result.hypotheses} hypotheses, "
              f"{result.seconds:.2f} s")
        print(f"{'node':<12} {'x':>12} {'y':>12} {'offset':>12} {'std':>10}")
        for k, name in enumerate(meas.receivers):
            x, y = result.receivers[k]
            print(f"{'r ' + name:<12} {x:12.5g} {y:12.5g} {'':>12} {result.receiver_std[k]:10.3g}")
        for k, name in enumerate(meas.transmitters):
            x, y = result.transmitters[k]
            print(f"{'s ' + name:<12} {x:12.5g} {y:12.5g} {result.offsets[k]:12.5g} {result.transmitter_std[k]:10.3g}")
    for w in result.warnings:
        print(f"warning: {w}")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tdoa-workbench",
        description="Polynomial-system complexity analysis and minimal-solver generation for 2D TDOA self-calibration.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    _add_degree(sub)
    _add_tables(sub)
    _add_generate(sub)
    _add_template_check(sub)
    _add_reproduce(sub)
    _add_calibrate(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    from analysis.degree import PrimeDisagreement
    from analysis.linalg import MatrixTooLarge
    from analysis.quotient import NotZeroDimensional

    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return args.func(args)
    except (UserError, MatrixTooLarge, NotZeroDimensional, ValueError, OverflowError) as e:
        print(f"tdoa-workbench {args.command}: error: {e}", file=sys.stderr)
        return 2
    except PrimeDisagreement as e:
        print(f"tdoa-workbench {args.command}: error: {e}", file=sys.stderr)
        return 3
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
