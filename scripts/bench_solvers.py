"""Benchmark the generated solvers; writes tables/solvers.csv and tables/solvers.meta.json.

Per solver: construction method and the size of its numeric core (companion pencil, or homotopy paths x
unknowns), the number of roots |B| (GF(p) degree), generation time (a fresh build into a temporary
directory, not timed in tests), the first call in this process (loading the compiled tracker from its
on-disk cache) apart, median runtime of one solve (best of three rounds), its ratio to numpy's ``eig`` of an
eig_n x eig_n complex matrix timed in the same process (eig_n = |B|; a pencil solver's own pencil size), time per path,
for homotopy solvers the evaluator of the tracker (``tape``: straight-line program, solvers.continuation.tape_kernel;
``tape (compiled)``: its C code, solvers.continuation.tape_native; ``monomials``: tracker.track) and its evaluations of H, dH/dx, dH/ds per second at |B| paths per call
(scripts/bench_tape.py), batched throughput, and, on N seeded
noiseless networks (positions
N(0, 10^2), offsets N(0, 1), via solvers.synthetic.random_network): median / 90th / 99th percentile of the
log10 relative error of the best candidate against the true root (H, b, o), the failure fraction (no
candidate within 1e-6), the mean number of real candidates; both for the raw solution (``polish=0``:
eigen-solution of the pencil; homotopy endpoints, which include Newton steps on the target system) and
for the solver output (default Gauss-Newton polishing on the input equations; no LM, no recovery).

Usage: OPENBLAS_NUM_THREADS=1 python scripts/bench_solvers.py [--trials 1000] [--seed 0] [--no-generate]
       [--solvers 9r3s 6r3s ...] [--merge] [--jobs N]

``--merge`` replaces only the rows of the solvers run in the existing table (a file lock serialises
concurrent runs, e.g. the fast solvers on 1000 trials beside the slow ones on 100); with
``--no-generate`` a row keeps its previous generation time. The provenance of every row (commit,
date, trials, timing calls, where its generation time comes from, and the indices of the failed
networks in the seeded sequence, to diagnose them without a rerun) is in the meta file's ``rows``.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ["TDOA_WORKBENCH_THREADS"] = "1"  # the trackers on one core, as the eigensolves they are compared with
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import datetime  # noqa: E402
import fcntl  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402
import scipy  # noqa: E402

import tempfile  # noqa: E402

from solvers import generate as gen  # noqa: E402
from solvers.api import SOLVER_ORDER  # noqa: E402
from solvers.subsystem import SUBSYSTEMS, module_for  # noqa: E402
from solvers.synthetic import random_network, true_root  # noqa: E402

FAIL_TOL = 1e-6
#: Rounds of single-solve timing; the best round's median is reported (as bench_engine's best of 3).
SINGLE_ROUNDS = 3
REAL_TOL = 1e-6
#: Every benchmarked solver, in the table's row order: the dispatch order, then subsystem solvers.
DEFAULT_SOLVERS = list(SOLVER_ORDER) + list(SUBSYSTEMS)


def _truth(module, net) -> np.ndarray:
    """The true root in the solver's unknowns: (H, b, o), or receiver coordinates (positions solvers)."""
    label = getattr(getattr(module, "base", module), "SYSTEM", "")  # a subsystem solver: its base's unknowns
    if "positions" in label:
        from analysis.formulations.positions import _root_from_network, _to_gauge, positions_system

        system = positions_system(*module.CONFIG, label.split("positions-")[1])
        rec, tra = _to_gauge(np.asarray(net.receivers, float), np.asarray(net.transmitters, float))
        return np.array(_root_from_network(system, rec, tra, np.asarray(net.offsets, float)), dtype=float)
    H, b, o = true_root(net)
    return np.concatenate([[H[0, 0], H[0, 1], H[1, 1]], b, o])


def _eig_ms(k: int, rng: np.random.Generator, rounds: int = 30) -> float:
    """Median ms of numpy.linalg.eig on a k x k complex matrix (the eigen step of a k-root action-matrix solver)."""
    A = rng.normal(size=(k, k)) + 1j * rng.normal(size=(k, k))
    times = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        np.linalg.eig(A)
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def _errors(roots: np.ndarray, truths: np.ndarray) -> np.ndarray:
    """Relative error of the best candidate per network (inf where there is none)."""
    with np.errstate(all="ignore"):
        err = np.nanmin(np.linalg.norm(roots - truths[:, None, :], axis=2), axis=1) / np.linalg.norm(truths, axis=1)
    return np.where(np.isfinite(err), err, np.inf)


def _accuracy(roots: np.ndarray, truths: np.ndarray) -> dict:
    """Best-candidate log10 relative errors, failures and real-candidate counts for a batch."""
    err = _errors(roots, truths)
    log = np.log10(np.maximum(err, 1e-17))
    finite = np.all(np.isfinite(roots), axis=2)
    scale = np.max(np.abs(np.where(finite[..., None], roots, 0)), axis=2)
    real = finite & (np.max(np.abs(roots.imag), axis=2) <= REAL_TOL * np.maximum(scale, 1e-300))
    return {
        "median_log10_err": float(np.median(log)),
        "p90_log10_err": float(np.percentile(log, 90)),
        "p99_log10_err": float(np.percentile(log, 99)),
        "failure_fraction": float(np.mean(err > FAIL_TOL)),
        "mean_real": float(np.mean(real.sum(axis=1))),
    }


def _solve_chunk(label: str, F: np.ndarray) -> tuple[np.ndarray, float]:
    """solve_batch on (a chunk of) the trials; roots and the seconds it took."""
    module = module_for(label)
    t0 = time.perf_counter()
    roots = module.solve_batch(F)
    return roots, time.perf_counter() - t0


def _solve_all(label: str, F: np.ndarray, jobs: int) -> tuple[np.ndarray, float]:
    """Roots of every trial and the seconds of solve_batch summed over the processes (one thread each):
    with ``jobs`` > 1 the trials are split into contiguous chunks solved in parallel, after the timing."""
    if jobs <= 1:
        return _solve_chunk(label, F)
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    chunks = [c for c in np.array_split(F, 8 * jobs) if len(c)]  # several per process: chunks differ in cost
    with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("fork")) as pool:
        parts = list(pool.map(_solve_chunk, [label] * len(chunks), chunks))
    return np.concatenate([p[0] for p in parts]), float(sum(p[1] for p in parts))


def bench(label: str, trials: int, seed: int, generate: bool, single_calls: int, jobs: int = 1) -> dict:
    module = module_for(label)
    homotopy = module.METHOD == "homotopy"
    m, n = module.CONFIG
    gen_s = float("nan")
    if generate and label not in SUBSYSTEMS:  # a subsystem solver generates nothing of its own
        t0 = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            gen.generate(label, out=tmp)
        gen_s = time.perf_counter() - t0
    rng = np.random.default_rng(seed)
    nets = [random_network(m, n, rng) for _ in range(trials)]
    F = np.stack([net.measurements() for net in nets])
    truths = np.array([_truth(module, net) for net in nets])
    t0 = time.perf_counter()
    module.solve(F[0])  # first call: spec, index arrays, compiled kernels from the disk cache
    first_ms = 1e3 * (time.perf_counter() - t0)
    # the eigen step of a |B|-root action-matrix solver; a pencil solver's own eigen step is its pencil's
    # size (6r4s: 37 x 37 for |B| = 22, the "eig37"); an over-determined configuration solved on
    # a square subsystem (4r6s: |B| = 1) is compared with the subsystem's |B| (its paths)
    eig_n = module.PATHS if label in SUBSYSTEMS else (module.DEGREE if homotopy else module.SIZE[0])
    # best of SINGLE_ROUNDS medians of the solver and of eig, rounds interleaved: this shared VM's speed
    # drifts by up to 2x between minutes (eig64 4.3 and 7.7 ms in one session), so both see the same periods
    medians, eigs = [], []
    for _ in range(SINGLE_ROUNDS):
        single = []
        for k in range(min(trials, single_calls)):
            t0 = time.perf_counter()
            module.solve(F[k])
            single.append(time.perf_counter() - t0)
        medians.append(float(np.median(single)))
        eigs.append(_eig_ms(eig_n, rng))
    eig = min(eigs)
    evaluator, evals_per_s = "", ""
    if homotopy and label not in SUBSYSTEMS:  # the tracker's evaluations of H, dH/dx, dH/ds at |B| paths per call
        from bench_tape import rates as tape_rates  # scripts/ is on the path of a script (tests import this file)

        solver = module.solver()
        evaluator = "tape" if solver.tapes is not None else "monomials"
        rates = tape_rates(solver, solver.n_paths, np.random.default_rng(seed + 1), repeat=3)
        kind = "full_native" if "full_native" in rates else ("full" if solver.tapes is not None else "changing")
        evaluator += " (compiled)" if kind == "full_native" else ""
        evals_per_s = round(1.0 / rates[kind])
    polished, batch_s = _solve_all(label, F, jobs)
    batch_s /= trials
    raw = polished if homotopy else module.solve_batch(F, polish=0)
    paths = module.PATHS if homotopy else None
    single_ms = 1e3 * min(medians)
    row = {
        "solver": label,
        "formulation": module.SYSTEM,
        "method": module.METHOD,
        "basis_size": module.DEGREE,
        "size": f"{paths}x{len(module.UNKNOWNS)}" if homotopy else f"{module.SIZE[0]}x{module.SIZE[1]}",
        "generation_s": round(gen_s, 2),
        "first_call_ms": round(first_ms, 1),
        "single_ms": round(single_ms, 3),
        "eig_n": eig_n,
        "eig_ms": round(eig, 3),
        "x_eig": round(single_ms / eig, 2),
        "us_per_path": round(1e3 * single_ms / paths, 1) if paths else "",
        "evaluator": evaluator,
        "evals_per_s": evals_per_s,
        "batch_ms_per_instance": round(1e3 * batch_s, 3),
        "polish_iterations": 0 if homotopy else module.POLISH_ITERATIONS,
        "trials": trials,
    }
    for prefix, roots in (("raw", raw), ("solver", polished)):
        for key, value in _accuracy(roots, truths).items():
            row[f"{prefix}_{key}"] = round(value, 4)
    # not a CSV column: the meta file's row provenance lists them, to diagnose without a rerun
    row["failed_networks"] = [int(k) for k in np.flatnonzero(_errors(polished, truths) > FAIL_TOL)]
    return row


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=1000)
    parser.add_argument("--single-calls", type=int, default=100, help="solve() calls per timing round")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-generate", action="store_true", help="skip timing a fresh template search")
    parser.add_argument("--solvers", nargs="*", default=DEFAULT_SOLVERS)
    parser.add_argument("--out", default=os.path.join(ROOT, "tables", "solvers.csv"))
    parser.add_argument("--merge", action="store_true", help="replace only these solvers' rows in --out")
    parser.add_argument("--jobs", type=int, default=1,
                        help="processes for the accuracy run on all trials (after the single-solve timing; "
                             "batch time is then the sum over processes, per instance on one thread)")
    args = parser.parse_args(argv)
    unknown = sorted(set(args.solvers) - set(DEFAULT_SOLVERS))
    if args.jobs < 1:
        parser.error("--jobs must be at least 1")
    if unknown:
        parser.error(f"unknown solvers {', '.join(unknown)}; valid: {', '.join(DEFAULT_SOLVERS)}")
    # dirty: changes beside this script's own outputs (rows of an earlier run not yet committed are not code)
    outputs = [":(exclude)tables/solvers.csv", ":(exclude)tables/solvers.md", ":(exclude)tables/solvers.meta.json",
               ":(exclude)docs/solvers.md"]
    commit = _git("rev-parse", "--short", "HEAD")
    dirty = bool(_git("status", "--porcelain", "--untracked-files=no", "--", ".", *outputs))
    rows = []
    for label in args.solvers:
        row = bench(label, args.trials, args.seed, not args.no_generate, args.single_calls, args.jobs)
        rows.append(row)
        print(", ".join(f"{k}={v}" for k, v in row.items()), flush=True)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    meta_path = os.path.splitext(args.out)[0] + ".meta.json"
    with open(meta_path + ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # concurrent --merge runs write one after the other
        _write(args, rows, meta_path, commit, dirty)
    print(f"wrote {args.out}")
    return 0


def _write(args, rows: list[dict], meta_path: str, commit: str, dirty: bool) -> None:
    old_rows, old_meta = {}, {}
    if args.merge and os.path.exists(args.out):
        with open(args.out, newline="", encoding="utf-8") as fh:
            old_rows = {r["solver"]: r for r in csv.DictReader(fh)}
        if os.path.exists(meta_path):
            with open(meta_path, encoding="utf-8") as fh:
                old_meta = json.load(fh)
    provenance = old_meta.get("rows") if isinstance(old_meta.get("rows"), dict) else {}
    date = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    for row in rows:
        label = row["solver"]
        generation = "not timed" if args.no_generate else "this run"
        if args.no_generate and label in old_rows and old_rows[label].get("generation_s") not in ("", "nan"):
            row["generation_s"] = float(old_rows[label]["generation_s"])
            generation = "kept from the previous row (" + provenance.get(label, {}).get("commit", "earlier run") + ")"
        provenance[label] = {"commit": commit + ("+dirty" if dirty else ""), "date": date, "trials": args.trials,
                             "single_calls": args.single_calls, "seed": args.seed, "generation_s": generation,
                             "jobs": args.jobs,
                             "failed_networks": row.pop("failed_networks")}
        old_rows[label] = row
    for label in SUBSYSTEMS:
        if label in provenance:
            provenance[label]["generation_s"] = f"none of its own (its base {SUBSYSTEMS[label][0]} is generated)"
    order = {label: k for k, label in enumerate(DEFAULT_SOLVERS)}
    merged = sorted(old_rows.values(), key=lambda r: order.get(r["solver"], len(order)))
    with open(args.out, "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]), restval="", extrasaction="ignore")
        writer.writeheader()
        writer.writerows(merged)
    meta = {
        "date": date,
        "rows": {label: provenance[label] for label in (r["solver"] for r in merged) if label in provenance},
        "networks": "solvers.synthetic.random_network: positions N(0, 10^2), offsets N(0, 1), noiseless",
        "error": "log10 of min over candidates ||x - x_true|| / ||x_true||, x = (h11, h12, h22, b1, b2, o), "
                 "or for 4r5s the receivers in sign-group invariants (X, Y, xi3, xi4, eta4)",
        "failure": f"no candidate within {FAIL_TOL} relative error",
        "raw": "polish=0: eigen-solutions of the 6r4s pencil; homotopy endpoints (tracking ends with "
               "Newton steps on the target system; no polishing); solver_*: the module's default polishing",
        "eig": "numpy.linalg.eig of an eig_n x eig_n complex normal matrix, median of 30, best of 3 rounds, same "
               "process, each round right after a round of the solver's single calls; eig_n = |B| for homotopy solvers, the pencil size for the 6r4s pencil (37, its own eigen "
               "step), the subsystem's |B| for 4r6s (|B| = 1, solved on its 4r5s subsystem: 344)",
        "subsystems": "4r6s: the 4r5s solver on transmitters 1-5 (where no candidate passes, the next 5-subset), "
                      "candidates kept when the other transmitter's range equations hold, then polished on all "
                      "measurements (solvers.subsystem); mean_real counts the kept real candidates",
        "real": f"finite candidates with max |imag| <= {REAL_TOL} max |x|",
        "evals_per_s": "evaluations of H, dH/dx and dH/ds per second at |B| paths per call (tape: one run of the "
                       "full tape for all paths, per path, by its compiled code where it is built (evaluator 'tape "
                       "(compiled)'), else by the interpreter; monomials: tracker._evaluate_many with s changing), best of "
                       "3 interleaved rounds (scripts/bench_tape.rates)",
        "timing": f"single: best of {SINGLE_ROUNDS} medians of --single-calls solve() calls each; first_call_ms "
                  "apart (first solve in the process: spec, compiled tracker loaded from numba's disk cache); "
                  "batch: solve_batch on all trials / trials (with jobs > 1: the trials split into chunks "
                  "solved in parallel processes, their solve_batch seconds summed)",
        "versions": {"python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__},
        "threads": {k: os.environ.get(k, "") for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")},
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
    }
    with open(meta_path, "w", encoding="utf-8") as fh:
        json.dump(meta, fh, indent=2)
        fh.write("\n")
    table = markdown(merged)
    with open(os.path.splitext(args.out)[0] + ".md", "w", encoding="utf-8") as fh:
        fh.write(table)
    if os.path.abspath(args.out) == os.path.join(ROOT, "tables", "solvers.csv"):
        _update_docs_page(table)


README_MARKERS = ("<!-- solvers.md -->\n", "<!-- /solvers.md -->\n")
#: The page that shows tables/solvers.md verbatim between :data:`README_MARKERS`.
DOCS_PAGE = os.path.join("docs", "solvers.md")


def _update_docs_page(table: str) -> None:
    """Put the table between the markers of docs/solvers.md (the page shows tables/solvers.md verbatim)."""
    path = os.path.join(ROOT, DOCS_PAGE)
    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    start, end = README_MARKERS
    if start not in text or end not in text:
        print(f"{DOCS_PAGE} has no {start.strip()} ... {end.strip()} markers; table not copied", file=sys.stderr)
        return
    head, rest = text.split(start, 1)
    _, tail = rest.split(end, 1)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(head + start + table + end + tail)


def _label(solver: str) -> str:
    m, n = solver[:-1].split("r")
    return f"{m}r/{n}s"


def markdown(rows: list[dict]) -> str:
    """The table of docs/solvers.md (tables/solvers.md): one line per solver."""
    out = ["| solver | method | roots (paths) | trials | raw median / p90 log10 error | failures | ms single (x eig of n) "
           "| us per path | generation s |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        method = {"curve-pencil": f"eigenvalue pencil {r['size'].replace('x', ' x ')}"}.get(r["method"], "parameter homotopy")
        if r["solver"] in SUBSYSTEMS:
            method += f" ({SUBSYSTEMS[r['solver']][0]} + filter)"
        paths = r["size"].split("x")[0] if r["method"] == "homotopy" else "-"
        gen = "-" if r["generation_s"] in ("", "nan") or r["generation_s"] != r["generation_s"] else f"{float(r['generation_s']):.1f}"
        upp = f"{float(r['us_per_path']):.0f}" if r["us_per_path"] not in ("", None) else "-"
        out.append(f"| {_label(r['solver'])} | {method} | {r['basis_size']} ({paths}) | {r['trials']} | "
                   f"{float(r['raw_median_log10_err']):.2f} / {float(r['raw_p90_log10_err']):.2f} | "
                   f"{100 * float(r['raw_failure_fraction']):.1f} % | {float(r['single_ms']):.1f} "
                   f"({float(r['x_eig']):.1f}x eig{r['eig_n']}) | {upp} | {gen} |")
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    sys.exit(main())
