"""Validate and benchmark the generated 3D solvers; writes tables/solvers3d.{csv,md}, solvers3d_noise.csv
and solvers3d.meta.json.

Per 3D solver (solvers/generated/tdoa_*3d_*) and network family, on N seeded networks (seeds 0..N-1):
``room`` (solvers.synthetic.room_network: receivers and transmitters uniform in an 8 x 6 x 3 m room,
offsets N(0, 1 m^2)) and ``paper`` (solvers.synthetic.random_network with dim=3: coordinates N(0, 10^2),
offsets N(0, 1), the paper's 2D distribution one dimension up). Noise-free figures: log10 relative error
of the root (H, b, o) against the true root (median, 90th and 99th percentile, maximum), failures (root
error above 1e-6, or no calibration recovered), the positions and offsets from solvers.api.calibrations
(relative position error after rigid alignment, relative offset error; no refinement), the RMS
measurement residual, the number of real candidates, the median time of one ``solve`` (best of three
rounds of single calls, one thread) and of ``solve_batch`` per network. The noise curve
(solvers3d_noise.csv): room networks with i.i.d. Gaussian noise of sigma on every f_ij, median and 90th
percentile of the position and offset errors of the calibration, before and after Levenberg-Marquardt on
all measurements (solvers.refine, as the 2D Table 4 rows), and the number of networks without one.

The minimal cells' solvers built on numerical evidence (spec "evidence": 7r/5s; thousands of paths, 15-35 s
and more a solve) run on fewer room networks (MINIMAL_TRIALS, or --minimal-trials), one ``solve`` each, and each
network's figures are cached ($TDOA_WORKBENCH_CACHE/bench_solvers3d/<solver>-<spec sha>/seed<k>.json) so that a
rerun or an interrupted run does not solve it again. Their root error is the distance to the nearest image of the
true root under the gauge reflections; "found" counts the networks where a calibration lies within 1e-6
(position error) of the true network, and the position and offset errors are that calibration's (minimal data:
several real networks fit exactly, the residual cannot rank them). Every EIG_EVERY-th network also times a
complex eig of a seeded random matrix of the paths' size, interleaved with the solves; the times (ms per solve,
microseconds per path, the ratio to the eig) go to the untracked tables/solvers3d.timing.json and are printed,
not into the committed table.

Usage: OPENBLAS_NUM_THREADS=1 python scripts/bench_solvers3d.py [--trials 1000] [--noise-trials 200]
       [--solvers 9r5s3d 7r5s3d] [--minimal-trials N] [--fill-only [--reverse | --first-seed K]]
(--solvers: rerun these only; the other solvers' rows are kept from the committed CSVs.)

The table (solvers3d.md) is written from the two CSVs alone (tests/test_solver3d.py checks it is current,
and that every committed 3D solver has rows with its spec's sha256); the date, commit and the indices of
the failed networks go to the meta file.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ["TDOA_WORKBENCH_THREADS"] = "1"  # the trackers on one core, as the eigensolves they are compared with
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import datetime  # noqa: E402
import hashlib  # noqa: E402
import importlib  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from analysis.sweeps.paths import cache_dir  # noqa: E402
from solvers import generate as gen  # noqa: E402
from solvers.api import calibrations  # noqa: E402
from solvers.continuation.tracking import unresolved  # noqa: E402
from solvers.metrics import offset_error, position_error  # noqa: E402
from solvers.refine import refine  # noqa: E402
from solvers.recovery import to_gauge  # noqa: E402
from solvers.synthetic import random_network, room_network, true_root  # noqa: E402

TABLES = os.path.join(ROOT, "tables")
FAIL_TOL = 1e-6
REAL_TOL = 1e-6
SINGLE_ROUNDS = 3
#: Network families: name -> (description, sampler m, n, rng -> Network).
FAMILIES = {
    "room": ("uniform in an 8 x 6 x 3 m room, offsets N(0, 1)", lambda m, n, rng: room_network(m, n, rng)),
    "paper": ("coordinates N(0, 10^2), offsets N(0, 1)", lambda m, n, rng: random_network(m, n, rng, dim=3)),
}
NOISE_SIGMAS = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2)
COLUMNS = ["solver", "formulation", "method", "roots", "certified_primes", "size", "network", "trials",
           "root_median_log10_err", "root_p90_log10_err", "root_p99_log10_err", "root_max_log10_err", "failures",
           "recovered", "position_median_log10_err", "position_p99_log10_err", "position_max_log10_err",
           "offset_median_log10_err", "offset_max_log10_err", "residual_median_log10", "mean_real",
           "single_ms", "batch_us_per_network", "spec_sha256", "found"]
#: Room networks per solver built on numerical evidence (each solve tracks thousands of paths; CPU budget).
MINIMAL_TRIALS = {"7r5s3d": 100, "6r6s3d": 100}
#: Every EIG_EVERY-th network of those also times a complex eig of the paths' size (seeded random matrix).
EIG_EVERY = 10
NOISE_COLUMNS = ["solver", "network", "sigma_m", "trials", "position_median_log10_err", "position_p90_log10_err",
                 "offset_median_log10_err", "offset_p90_log10_err", "refined_position_median_log10_err",
                 "refined_position_p90_log10_err", "refined_offset_median_log10_err", "no_calibration"]


def solvers3d() -> list[str]:
    """Committed 3D solver labels (their module names carry the dimension: ``9r5s3d``)."""
    names = os.listdir(gen.GENERATED_DIR)
    return [label for label in gen.SOLVERS if label.endswith("3d")
            and any(f.startswith(f"tdoa_{label}_") and f.endswith(".py") for f in names)]


def module_for(label: str):
    stem = next(f[:-3] for f in sorted(os.listdir(gen.GENERATED_DIR)) if f.startswith(f"tdoa_{label}_") and f.endswith(".py"))
    return importlib.import_module(f"solvers.generated.{stem}")


def _truth(net) -> np.ndarray:
    H, b, o = true_root(net)
    return np.concatenate([H[np.triu_indices(net.dim)], b, o])


def _log(values) -> np.ndarray:
    return np.log10(np.maximum(np.asarray(values, dtype=float), 1e-17))


def _q(values, q: float) -> float:
    return round(float(np.percentile(_log(values), q)), 2)


def _single_ms(module, F: np.ndarray, calls: int) -> float:
    best = np.inf
    for _ in range(SINGLE_ROUNDS):
        times = []
        for k in range(calls):
            t0 = time.perf_counter()
            module.solve(F[k % len(F)])
            times.append(time.perf_counter() - t0)
        best = min(best, float(np.median(times)))
    return 1e3 * best


def bench(label: str, family: str, trials: int, calls: int) -> tuple[dict, list[int]]:
    """One row of solvers3d.csv and the seeds of the failed networks."""
    module = module_for(label)
    m, n = module.CONFIG
    nets = [FAMILIES[family][1](m, n, np.random.default_rng(seed)) for seed in range(trials)]
    F = np.stack([net.measurements() for net in nets])
    truths = np.stack([_truth(net) for net in nets])
    t0 = time.perf_counter()
    roots = module.solve_batch(F)
    batch_s = time.perf_counter() - t0
    err = np.min(np.linalg.norm(roots - truths[:, None, :], axis=2), axis=1) / np.linalg.norm(truths, axis=1)
    err = np.where(np.isfinite(err), err, np.inf)
    pos, off, res, failed = [], [], [], []
    for seed, (net, x) in enumerate(zip(nets, roots)):
        cals = calibrations(module, F[seed], x)
        if not cals or err[seed] > FAIL_TOL:
            failed.append(seed)
        if cals:
            pos.append(position_error(cals[0], net))
            off.append(offset_error(cals[0], net))
            res.append(cals[0].residual)
    scale = np.max(np.abs(roots), axis=2)
    real = np.max(np.abs(roots.imag), axis=2) <= REAL_TOL * np.maximum(scale, 1e-300)
    with open(os.path.join(gen.GENERATED_DIR, module.SPEC_FILE), encoding="utf-8") as fh:
        spec = json.load(fh)
    row = {
        "solver": label, "formulation": module.SYSTEM, "method": module.METHOD, "roots": module.DEGREE,
        "certified_primes": " ".join(map(str, spec["certified"]["primes"])), "size": "x".join(map(str, module.SIZE)),
        "network": family, "trials": trials,
        "root_median_log10_err": _q(err, 50), "root_p90_log10_err": _q(err, 90), "root_p99_log10_err": _q(err, 99),
        "root_max_log10_err": _q(err, 100), "failures": len(failed), "recovered": len(pos),
        "position_median_log10_err": _q(pos, 50), "position_p99_log10_err": _q(pos, 99),
        "position_max_log10_err": _q(pos, 100), "offset_median_log10_err": _q(off, 50),
        "offset_max_log10_err": _q(off, 100), "residual_median_log10": _q(res, 50),
        "mean_real": round(float(np.mean(real.sum(axis=1))), 3),
        "single_ms": round(_single_ms(module, F, calls), 3), "batch_us_per_network": round(1e6 * batch_s / trials, 1),
        "spec_sha256": module.SPEC_SHA256,
    }
    return row, failed


def _direct_truth(net, unknowns) -> np.ndarray:
    """The true root of a direct-parametrization solver: the network in the gauge frame, its offsets."""
    rec, tra = to_gauge(net.receivers, net.transmitters)
    axis = {"x": 0, "y": 1, "z": 2}
    values = []
    for u in unknowns:
        if u[0] == "o":
            values.append(net.offsets[int(u[1:]) - 1])
        else:
            values.append((rec if u[0] == "r" else tra)[int(u[1:-1]) - 1, axis[u[-1]]])
    return np.array(values)


def _network_record(module, spec: dict, seed: int, eig: bool) -> dict:
    """One room network's figures for a minimal-cell solver: one ``solve`` (timed), the root error up to the
    gauge reflections, the calibrations, and (``eig``) the seconds of a complex eig of the paths' size."""
    m, n = module.CONFIG
    net = room_network(m, n, np.random.default_rng(seed))
    F = net.measurements()
    truth = _direct_truth(net, module.UNKNOWNS)
    t0 = time.perf_counter()
    roots = module.solve(F)
    solve_s = time.perf_counter() - t0
    signs = np.array(spec["group"]["signs"], dtype=float) if spec.get("group") else np.ones((1, len(truth)))
    with np.errstate(all="ignore"):
        err = min(float(np.nanmin(np.linalg.norm(roots * g - truth, axis=1))) for g in signs) / np.linalg.norm(truth)
        cals = calibrations(module, F, roots)
    finite = np.all(np.isfinite(roots), axis=1)
    x = np.where(finite[:, None], roots, 0)
    real = finite & (np.max(np.abs(x.imag), axis=1) <= REAL_TOL * np.maximum(np.max(np.abs(x), axis=1), 1e-300))
    record = {"seed": seed, "root_err": err if np.isfinite(err) else None, "finite": int(finite.sum()),
              "real": int(real.sum()), "calibrations": len(cals), "solve_s": solve_s,
              "duplicates": int(unresolved(roots).sum() - (~finite).sum()),
              "orbit_jumps": int(unresolved(roots, signs).sum() - (~finite).sum())}
    if cals:
        errors = [position_error(c, net) for c in cals]
        best = cals[int(np.argmin(errors))]
        record.update({"position_err": min(errors), "offset_err": offset_error(best, net), "residual": best.residual})
    if eig:
        rng = np.random.default_rng(seed)
        A = rng.normal(size=(module.PATHS,) * 2) + 1j * rng.normal(size=(module.PATHS,) * 2)
        t0 = time.perf_counter()
        np.linalg.eig(A)
        record["eig_s"] = time.perf_counter() - t0
    return record


#: The homotopy runtime's sources: a cached network record is valid for one spec and one version of these.
KERNELS = ("solvers/methods/homotopy.py", "solvers/continuation/tracking.py", "solvers/continuation/tracker.py",
           "solvers/continuation/tape_kernel.py", "solvers/continuation/tape_jit.py", "solvers/continuation/tape_native.py",
           "solvers/continuation/slp.py", "solvers/api.py")


def _kernel_sha() -> str:
    digest = hashlib.sha256()
    for name in KERNELS:
        with open(os.path.join(ROOT, name), "rb") as fh:
            digest.update(fh.read())
    return digest.hexdigest()[:12]


def bench_minimal(label: str, trials: int, fill_only: bool = False, reverse: bool = False,
                  first: int = 0, cached_only: bool = False) -> tuple[dict, list[int], dict] | None:
    """The row of a minimal-cell solver built on numerical evidence (room networks, seeds 0..trials-1, cached per
    network), the seeds of the failed networks and its timing record. ``fill_only``: solve the networks not
    cached yet (``reverse``: from the last seed down, so that a second process fills the cache from the other
    end; ``first``: from this seed up, a third process) and return None. ``cached_only``: the row of the cached
    networks among seeds 0..trials-1 alone (its "trials" is their number; the seeds go to the meta file)."""
    module = module_for(label)
    with open(os.path.join(gen.GENERATED_DIR, module.SPEC_FILE), encoding="utf-8") as fh:
        spec = json.load(fh)
    folder = cache_dir("bench_solvers3d") / f"{label}-{module.SPEC_SHA256[:12]}-{_kernel_sha()}"
    folder.mkdir(parents=True, exist_ok=True)
    records = []
    for seed in sorted(range(first if fill_only else 0, trials), reverse=reverse):
        path = folder / f"seed{seed}.json"
        if path.exists():
            with open(path, encoding="utf-8") as fh:
                records.append(json.load(fh))
            continue
        if cached_only:
            continue
        record = _network_record(module, spec, seed, seed % EIG_EVERY == 0)
        with open(str(path) + ".tmp", "w", encoding="utf-8") as fh:
            json.dump(record, fh)
        os.replace(str(path) + ".tmp", path)
        records.append(record)
        err = record["root_err"] if record["root_err"] is not None else float("nan")
        print(f"  {label} network {seed}: root error {err:.1e}, {record['calibrations']} calibrations, "
              f"{record['solve_s']:.1f} s" + (f", eig {record['eig_s']:.1f} s" if "eig_s" in record else ""), flush=True)
    if fill_only:
        return None
    records.sort(key=lambda r: r["seed"])
    err = np.array([r["root_err"] if r["root_err"] is not None else np.inf for r in records])
    found = [r.get("position_err", np.inf) <= FAIL_TOL for r in records]
    failed = [r["seed"] for r, f, e in zip(records, found, err) if not f or e > FAIL_TOL]
    have = [r for r in records if "position_err" in r]
    trials = len(records)
    row = {
        "solver": label, "formulation": module.SYSTEM, "method": module.METHOD, "roots": module.DEGREE,
        "certified_primes": "monodromy", "size": str(module.PATHS), "network": "room", "trials": trials,
        "root_median_log10_err": _q(err, 50), "root_p90_log10_err": _q(err, 90), "root_p99_log10_err": _q(err, 99),
        "root_max_log10_err": _q(err, 100), "failures": len(failed), "recovered": len(have),
        "position_median_log10_err": _q([r["position_err"] for r in have], 50),
        "position_p99_log10_err": _q([r["position_err"] for r in have], 99),
        "position_max_log10_err": _q([r["position_err"] for r in have], 100),
        "offset_median_log10_err": _q([r["offset_err"] for r in have], 50),
        "offset_max_log10_err": _q([r["offset_err"] for r in have], 100),
        "residual_median_log10": _q([r["residual"] for r in have], 50),
        "mean_real": round(float(np.mean([r["real"] for r in records])), 3),
        "single_ms": "", "batch_us_per_network": "", "spec_sha256": module.SPEC_SHA256, "found": int(sum(found)),
    }
    solve = np.array([r["solve_s"] for r in records])
    paired = [(r["solve_s"], r["eig_s"]) for r in records if "eig_s" in r]
    timing = {"networks": trials, "paths": module.PATHS, "solve_ms_median": round(1e3 * float(np.median(solve)), 1),
              "us_per_path_median": round(1e6 * float(np.median(solve)) / module.PATHS, 1),
              "eig_size": module.PATHS, "eig_networks": len(paired),
              "eig_ms_median": round(1e3 * float(np.median([e for _, e in paired])), 1) if paired else None,
              "solve_over_eig_median": round(float(np.median([s / e for s, e in paired])), 2) if paired else None,
              "solve_over_eig_max": round(float(np.max([s / e for s, e in paired])), 2) if paired else None,
              "seeds": [r["seed"] for r in records],
              "orbit_jump_endpoints_mean": round(float(np.mean([r["orbit_jumps"] for r in records])), 2),
              "orbit_jump_endpoints_max": int(max(r["orbit_jumps"] for r in records)),
              "calibrations_mean": round(float(np.mean([r["calibrations"] for r in records])), 2),
              "note": "solve and eig of the same networks, one thread, interleaved; a network solved in an earlier "
                      "run keeps that run's times (cache)"}
    return row, failed, timing


def noise_curve(label: str, trials: int) -> list[dict]:
    """Rows of solvers3d_noise.csv: room networks, noise sigma on every measurement (seeds 0..trials-1)."""
    module = module_for(label)
    m, n = module.CONFIG
    rows = []
    for sigma in NOISE_SIGMAS:
        pos, off, rpos, roff, missing = [], [], [], [], 0
        for seed in range(trials):
            rng = np.random.default_rng(seed)
            net = room_network(m, n, rng)
            F = net.measurements(sigma, rng)
            cals = calibrations(module, F)
            if not cals:
                missing += 1
                continue
            pos.append(position_error(cals[0], net))
            off.append(offset_error(cals[0], net))
            refined = refine(cals[0], F).calibration
            rpos.append(position_error(refined, net))
            roff.append(offset_error(refined, net))
        rows.append({"solver": label, "network": "room", "sigma_m": f"{sigma:g}", "trials": trials,
                     "position_median_log10_err": _q(pos, 50), "position_p90_log10_err": _q(pos, 90),
                     "offset_median_log10_err": _q(off, 50), "offset_p90_log10_err": _q(off, 90),
                     "refined_position_median_log10_err": _q(rpos, 50), "refined_position_p90_log10_err": _q(rpos, 90),
                     "refined_offset_median_log10_err": _q(roff, 50), "no_calibration": missing})
    return rows


def markdown(rows: list[dict], noise: list[dict]) -> str:
    """tables/solvers3d.md from the rows of the two CSVs (as read back: strings)."""
    lines = ["<!-- Regenerate: OPENBLAS_NUM_THREADS=1 python scripts/bench_solvers3d.py; provenance in "
             "solvers3d.meta.json -->", "",
             "**Generated 3D solvers: noise-free validation** (log10 relative errors: median / p99 / max; failures: "
             "root error > 1e-6 or no calibration; positions and offsets from solvers.api.calibrations, not refined)", "",
             "| solver | method | roots (certified on) | networks | trials | root error | position error | "
             "offset error (median / max) | failures | true network found | ms per call | us per network (batch) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        m, n = r["solver"][:-2].split("r")
        lines.append(
            f"| {m}r/{n} 3D | {r['method']} {r['size']} | {r['roots']} ({r['certified_primes']}) | "
            f"{FAMILIES[r['network']][0]} | {r['trials']} | {r['root_median_log10_err']} / {r['root_p99_log10_err']} / "
            f"{r['root_max_log10_err']} | {r['position_median_log10_err']} / {r['position_p99_log10_err']} / "
            f"{r['position_max_log10_err']} | {r['offset_median_log10_err']} / {r['offset_max_log10_err']} | "
            f"{r['failures']} | {r.get('found') or 'not counted'} | {r['single_ms'] or 'timing.json'} | "
            f"{r['batch_us_per_network'] or 'timing.json'} |")
    lines += ["", "**Noise** (room networks, Gaussian noise of sigma on every measurement; log10 relative errors "
              "median / p90 of the solver's calibration, then after Levenberg-Marquardt on all 45 measurements)", "",
              "| solver | sigma [m] | trials | position error | offset error | refined: position error | "
              "refined: offset error (median) | no calibration |", "|---|---|---|---|---|---|---|---|"]
    for r in noise:
        lines.append(f"| {r['solver']} | {r['sigma_m']} | {r['trials']} | {r['position_median_log10_err']} / "
                     f"{r['position_p90_log10_err']} | {r['offset_median_log10_err']} / {r['offset_p90_log10_err']} | "
                     f"{r['refined_position_median_log10_err']} / {r['refined_position_p90_log10_err']} | "
                     f"{r['refined_offset_median_log10_err']} | {r['no_calibration']} |")
    return "\n".join(lines) + "\n"


def read_csv(name: str) -> list[dict]:
    with open(os.path.join(TABLES, name), newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _write_csv(name: str, columns: list[str], rows: list[dict]) -> None:
    with open(os.path.join(TABLES, name), "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)


def _git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=False).stdout.strip()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=1000, help="noise-free networks per family (default 1000)")
    parser.add_argument("--noise-trials", type=int, default=200, help="networks per noise level (default 200)")
    parser.add_argument("--single-calls", type=int, default=200, help="timed single calls per round (default 200)")
    parser.add_argument("--solvers", nargs="+", choices=solvers3d(), default=None,
                        help="rerun these solvers only (default all); the others' rows are kept from the committed CSVs")
    parser.add_argument("--minimal-trials", type=int, default=None,
                        help="room networks per minimal-cell solver built on numerical evidence (default MINIMAL_TRIALS)")
    parser.add_argument("--fill-only", action="store_true", help="minimal-cell solvers: solve the networks not cached "
                        "yet and stop (no table); --reverse from the last seed down (a second process)")
    parser.add_argument("--reverse", action="store_true", help="with --fill-only: from the last seed down")
    parser.add_argument("--first-seed", type=int, default=0, help="with --fill-only: from this seed up")
    parser.add_argument("--cached-only", action="store_true", help="minimal-cell solvers: the row of the networks "
                        "already cached (no solve; their seeds go to the meta file)")
    args = parser.parse_args(argv)
    if args.fill_only:
        for label in [label for label in args.solvers or solvers3d() if label in MINIMAL_TRIALS]:
            bench_minimal(label, args.minimal_trials or MINIMAL_TRIALS.get(label, 20), True, args.reverse, args.first_seed)
        return 0
    if min(args.trials, args.noise_trials, args.single_calls, args.minimal_trials or 1) < 1:
        parser.error("--trials, --noise-trials, --single-calls and --minimal-trials must be positive")
    chosen = args.solvers or solvers3d()
    old_meta = {}
    if args.solvers and os.path.exists(os.path.join(TABLES, "solvers3d.meta.json")):
        with open(os.path.join(TABLES, "solvers3d.meta.json"), encoding="utf-8") as fh:
            old_meta = json.load(fh)
    kept = [r for r in read_csv("solvers3d.csv") if r["solver"] not in chosen] if args.solvers else []
    rows = {r["solver"]: [] for r in kept}
    for r in kept:
        rows[r["solver"]].append(r)
    noise = [r for r in read_csv("solvers3d_noise.csv") if r["solver"] not in chosen] if args.solvers else []
    failed = {k: v for k, v in old_meta.get("failed_networks", {}).items() if k.split()[0] not in chosen}
    timing_path = os.path.join(TABLES, "solvers3d.timing.json")
    timing = {}
    if os.path.exists(timing_path):
        with open(timing_path, encoding="utf-8") as fh:
            timing = json.load(fh)
    for label in chosen:
        rows[label] = []
        if "evidence" in json.load(open(os.path.join(gen.GENERATED_DIR, module_for(label).SPEC_FILE), encoding="utf-8")):
            row, bad, timing[label] = bench_minimal(label, args.minimal_trials or MINIMAL_TRIALS.get(label, 20),
                                                    cached_only=args.cached_only)
            rows[label].append(row)
            failed[f"{label} room"] = bad
            t = timing[label]
            print(f"{label} room: found {row['found']}/{row['trials']}, root median {row['root_median_log10_err']}, "
                  f"max {row['root_max_log10_err']}; failures {row['failures']}; {t['solve_ms_median']} ms per solve, "
                  f"{t['us_per_path_median']} us per path, {t['solve_over_eig_median']}x an eig({t['eig_size']})", flush=True)
            continue
        for family in FAMILIES:
            row, bad = bench(label, family, args.trials, args.single_calls)
            rows[label].append(row)
            failed[f"{label} {family}"] = bad
            print(f"{label} {family}: root median {row['root_median_log10_err']}, max {row['root_max_log10_err']}; "
                  f"failures {row['failures']}/{args.trials}; {row['single_ms']} ms per call", flush=True)
        noise += noise_curve(label, args.noise_trials)
    order = solvers3d()
    rows = [r for label in sorted(rows, key=order.index) for r in rows[label]]
    noise.sort(key=lambda r: order.index(r["solver"]))
    _write_csv("solvers3d.csv", COLUMNS, rows)
    _write_csv("solvers3d_noise.csv", NOISE_COLUMNS, noise)
    with open(os.path.join(TABLES, "solvers3d.md"), "w", encoding="utf-8", newline="\n") as fh:
        fh.write(markdown(read_csv("solvers3d.csv"), read_csv("solvers3d_noise.csv")))
    with open(timing_path, "w", encoding="utf-8", newline="\n") as fh:
        json.dump(timing, fh, indent=2)
        fh.write("\n")
    meta = {"date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
            "commit": _git("rev-parse", "--short", "HEAD"), "dirty": bool(_git("status", "--porcelain", "--", "solvers")),
            "trials": args.trials, "noise_trials": args.noise_trials, "single_calls": args.single_calls,
            "seeds": f"0..{args.trials - 1}", "threads": os.environ.get("OPENBLAS_NUM_THREADS"),
            "load_average_at_end": list(os.getloadavg()), "failed_networks": failed,
            "rerun": chosen, "minimal_seeds": {**{k: v for k, v in old_meta.get("minimal_seeds", {}).items() if k not in chosen},
                                               **{label: t["seeds"] for label, t in timing.items() if label in chosen}}}
    with open(os.path.join(TABLES, "solvers3d.meta.json"), "w", encoding="utf-8", newline="\n") as fh:
        json.dump(meta, fh, indent=2)
        fh.write("\n")
    print("wrote tables/solvers3d.csv, solvers3d_noise.csv, solvers3d.md, solvers3d.meta.json (times: solvers3d.timing.json)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
