"""Benchmark solvers.calibrate: is the default call (sigma estimated) never confidently wrong?

Writes tables/calibration.csv, tables/calibration.md and tables/calibration.meta.json; with --dim 3
tables/calibration3d.{csv,md} (no run facts in them: the seconds per call and the provenance go to
the untracked calibration3d.timing.json).

3D grid (--dim 3): cells 9r/5s, 10r/6s, 12r/8s, 16r/10s, 24r/16s in an 8 x 6 x 3 m room
(solvers.synthetic.room_network: positions uniform in the room, offsets N(0, 1 m)) x sigma 1e-4, 1e-3,
1e-2 m x the same conditions (gaps keep >= 4 per receiver, >= 5 per transmitter); scale rows 100r/60s,
sigma 1e-2: 20 % missing, clean; 5 % gross errors, sigma given only.

Grid: cells 9r/3s, 7r/3s, 6r/4s, 5r/5s, 8r/5s, 10r/8s, 20r/10s, 12r/20s x noise sigma 1e-4, 1e-3, 1e-2
(the scene is 10 across: positions uniform in [-5, 5]^2, offsets uniform in [-2, 2]) x condition
clean / 5 % gross errors / 30 % missing x sigma given / estimated; `--networks` networks a cell (the
same networks for both calls). Scale rows: 100r/100s and 200r/150s, 20 % missing, sigma 1e-2, clean.
Gaps and gross errors: solvers.synthetic.corrupt_measurements (gross errors uniform in the data range;
gaps keep >= 3 measurements per receiver and >= 4 per transmitter, so a small network gets fewer).

Columns per (cell, sigma, condition, mode):
  kept          share of the true inliers kept as inliers
  gross_rejected share of the gross errors rejected (empty without gross errors)
  placed        share of networks with every node placed
  err_ratio_med, err_ratio_p95   median / p95 position error (relative, after rigid alignment) over
                the same quantile of the sigma-given call on the same networks
  sigma_ratio   median estimated sigma / true sigma; sigma_within2: share within a factor 2
  over3std      share of placed nodes whose position error (in the result's gauge) exceeds 3 reported
                standard deviations (a 2-D normal: between 1e-4 and 0.27 %)
  ok_over5std   share of networks with status "ok" and a node farther than 5 reported std from the truth
  status counts (ok / uncontrolled / partial / inconsistent / ambiguous / unconverged / failed)
  sec_med, sec_p95   seconds per call

Wrong inputs (conditions "shuffled column", "transposed", "squared", sigma 1e-3, `--wrong-networks` a
cell, both modes; `wrong_input`): the clean matrix of the same seeded networks handed in wrongly. No
network fits them: the honest answer is never "ok".

Usage: python scripts/bench_calibrate.py [--networks 200] [--jobs 2] [--quick] [--only 9r3s,8r5s]
       [--conditions clean,gross,missing,shuffled,transposed,squared] [--wrong-networks 10]
       python scripts/bench_calibrate.py --compare OLD.csv [--dim 3]   (the rows whose results moved)
       python scripts/bench_calibrate.py --render   (calibration.md from calibration.csv, no computing)
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ["TDOA_WORKBENCH_THREADS"] = "1"  # the trackers on one core, as the eigensolves they are compared with
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import datetime  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from solvers.calibration import STATUSES, calibrate  # noqa: E402
from solvers.metrics import calibration_errors, standardised_node_errors  # noqa: E402
from solvers.synthetic import Network, corrupt_measurements, room_network  # noqa: E402

CELLS = ((9, 3), (7, 3), (6, 4), (5, 5), (8, 5), (10, 8), (20, 10), (12, 20))
CELLS_3D = ((9, 5), (10, 6), (12, 8), (16, 10), (24, 16))
SCALE_3D = ((100, 60),)
SIGMAS = (1e-4, 1e-3, 1e-2)
CONDITIONS = {"clean": (0.0, 0.0), "gross 5%": (0.0, 0.05), "missing 30%": (0.3, 0.0)}
#: wrong inputs (`wrong_input`): the clean matrix of each network handed in wrongly, at one sigma; no
#: network fits such data, so the honest answer is never "ok" (a shuffled column: the rest may be placed
#: and the column's source said to rest on few entries)
WRONG = ("shuffled column", "transposed", "squared")
WRONG_SIGMA = 1e-3
SCALE = ((100, 100), (200, 150))
SCALE_CONDITION = ("missing 20%", 0.2, 0.0)
#: 3D scale cell with gross errors, sigma given only (sigma estimated takes minutes a call at 100r/60s)
SCALE_GROSS_3D = ("gross 5%", 0.0, 0.05)
MODES = ("given", "estimated")


def network(m, n, sigma, missing, gross, seed, dim=2):
    """(network, F, gross-error mask) of one seeded trial."""
    rng = np.random.default_rng(seed)
    if dim == 3:
        net = room_network(m, n, rng)
        F, bad = corrupt_measurements(net.measurements(sigma, rng), rng, missing, gross, min_per_receiver=4,
                                      min_per_transmitter=5)
        return net, F, bad
    net = Network(rng.uniform(-5, 5, (m, 2)), rng.uniform(-5, 5, (n, 2)), rng.uniform(-2, 2, n))
    F, bad = corrupt_measurements(net.measurements(sigma, rng), rng, missing, gross)
    return net, F, bad


def wrong_input(kind: str, F: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(F handed in wrongly, mask of the wrong entries) for one of WRONG; seeded by the network's seed.

    "shuffled column": one transmitter's column cycled along a random order of the receivers (every entry
    moves; the moved entries are the mask); "transposed": F.T (offsets then run along the rows, which
    no network has; empty mask); "squared": every entry squared (empty mask).
    """
    if kind == "transposed":
        return F.T.copy(), np.zeros(F.T.shape, dtype=bool)
    if kind == "squared":
        return F * F, np.zeros(F.shape, dtype=bool)
    if kind != "shuffled column":
        raise ValueError(f"unknown wrong input {kind!r}; valid: {', '.join(WRONG)}")
    rng = np.random.default_rng([seed, 52])
    j = int(rng.integers(F.shape[1]))
    order = rng.permutation(F.shape[0])
    out = F.copy()
    out[order, j] = F[np.roll(order, 1), j]
    bad = np.zeros(F.shape, dtype=bool)
    bad[:, j] = True
    return out, bad


def one_call(net, F, bad, sigma_true, given: bool, seed: int) -> dict:
    cpu = time.process_time()
    res = calibrate(F, sigma=sigma_true if given else None, dim=net.dim, seed=seed)
    cpu = time.process_time() - cpu
    good = np.isfinite(F) & ~bad
    placed = bool(np.isfinite(res.receivers).all() and np.isfinite(res.transmitters).all())
    truth = F.shape == (len(net.receivers), len(net.transmitters))  # a transposed matrix has no true network
    err = calibration_errors(res, net).position if placed and truth else np.inf
    z = standardised_node_errors(res, net) if truth else np.array([])
    return {
        "kept": int((res.inliers & good).sum()), "good": int(good.sum()),
        "rejected_bad": int((~res.inliers & bad).sum()), "bad": int(bad.sum()),
        "placed": placed, "err": float(err), "sigma_ratio": float(res.sigma / sigma_true),
        "nodes": int(len(z)), "over3": int((z > 3).sum()), "over5": int((z > 5).sum()),
        "status": res.status, "seconds": float(res.seconds), "cpu_seconds": float(cpu),
    }


def warm_up(dim: int = 2) -> None:
    """Load the solvers and compiled kernels once per process, so that no timed call pays for it."""
    for m, n in ((8, 5), (9, 3)) if dim == 2 else ((12, 8),):  # 2D: the pencil and a homotopy solver
        net, F, _ = network(m, n, 1e-3, 0.0, 0.0, 0, dim)
        calibrate(F, seed=0, dim=dim)
        calibrate(F, sigma=1e-3, seed=0, dim=dim)


def trial(args) -> dict:
    (m, n), sigma, cond, missing, gross, seed, dim, modes = args
    net, F, bad = network(m, n, sigma, missing, gross, seed, dim)
    if cond in WRONG:
        F, bad = wrong_input(cond, F, seed)
    return {mode: one_call(net, F, bad, sigma, mode == "given", seed) for mode in modes}


def summarise(cell: str, sigma: float, cond: str, mode: str, trials: list[dict]) -> dict:
    rows = [t[mode] for t in trials]
    ref = np.array([t["given"]["err"] for t in trials])
    err = np.array([r["err"] for r in rows])
    bad = sum(r["bad"] for r in rows)
    ratio = np.array([r["sigma_ratio"] for r in rows])
    nodes = sum(r["nodes"] for r in rows)
    sec = np.array([r["seconds"] for r in rows])

    def q(a, p):
        a = a[np.isfinite(a)]
        return float(np.percentile(a, p)) if a.size else np.inf

    out = {
        "cell": cell, "sigma": f"{sigma:g}", "condition": cond, "sigma_mode": mode, "networks": len(rows),
        "kept": round(sum(r["kept"] for r in rows) / max(sum(r["good"] for r in rows), 1), 4),
        "gross_rejected": round(sum(r["rejected_bad"] for r in rows) / bad, 4) if bad else "",
        "placed": round(float(np.mean([r["placed"] for r in rows])), 3),
        "err_ratio_med": round(float(np.median(err)) / max(float(np.median(ref)), 1e-300), 3)
        if np.isfinite(np.median(err)) else "inf",
        "err_ratio_p95": round(q(err, 95) / max(q(ref, 95), 1e-300), 3),
        "sigma_ratio": round(float(np.median(ratio)), 3),
        "sigma_within2": round(float(np.mean((ratio >= 0.5) & (ratio <= 2.0))), 3),
        "over3std": round(sum(r["over3"] for r in rows) / max(nodes, 1), 4),
        "ok_over5std": round(float(np.mean([r["status"] == "ok" and r["over5"] > 0 for r in rows])), 4),
    }
    for s in STATUSES[::-1]:
        out[s] = sum(r["status"] == s for r in rows)
    out["sec_med"] = round(float(np.median(sec)), 3)
    out["sec_p95"] = round(float(np.percentile(sec, 95)), 3)
    cpu = np.array([r["cpu_seconds"] for r in rows])  # (the process's CPU time: what a loaded machine does not inflate)
    out["cpu_med"], out["cpu_p95"] = round(float(np.median(cpu)), 3), round(float(np.percentile(cpu, 95)), 3)
    return out


def markdown(rows: list[dict]) -> str:
    cols = [c for c in ["cell", "sigma", "condition", "sigma_mode", "networks", "kept", "gross_rejected", "placed",
                        "err_ratio_med", "err_ratio_p95", "sigma_ratio", "sigma_within2", "over3std", "ok_over5std",
                        *STATUSES[::-1], "sec_med", "sec_p95"] if c in rows[0]]
    out = ["# calibrate: sigma given and estimated (scripts/bench_calibrate.py)", "",
           "Columns: see the script's docstring. err_ratio: position error over the sigma-given call's on the "
           "same networks; over3std: share of nodes with error > 3 reported std; ok_over5std: share of networks "
           "reported \"ok\" with a node > 5 std off.", ""]
    if any(r["condition"] in WRONG for r in rows):
        out += ["Wrong inputs (conditions " + ", ".join(WRONG) + f"; sigma {WRONG_SIGMA:g}): each network's clean matrix "
                "handed in wrongly: one transmitter's column cycled across the receivers (every entry moved; "
                "gross_rejected is the share of that column rejected), the matrix transposed (the offsets then run "
                "along the rows: no network has them; no truth to compare with, err inf), every entry squared. No "
                "network fits such data: every network's status is counted, and any \"ok\" is a wrong answer.", ""]
    out += ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        out.append("| " + " | ".join(str(r[c]) for c in cols) + " |")
    out += ["", "## Summary at sigma 1e-2 (the table of docs/calibrate.md)", "", summary(rows)]
    return "\n".join(out)


def summary(rows: list[dict]) -> str:
    """The compact table of docs/calibrate.md: per cell at sigma 1e-2, the clean default call, and the gross-error
    cells with sigma given and estimated; then the scale rows. Rows may come from the CSV (strings)."""
    def get(cell, cond, mode):
        for r in rows:
            if r["cell"] == cell and str(r["sigma"]) == "0.01" and r["condition"] == cond and r["sigma_mode"] == mode:
                return r
        return None

    def other(r, *named):
        return sum(int(r[s]) for s in STATUSES if s not in named)

    out = ["| cell | clean, σ est.: kept / placed / σ̂/σ / ok·unc·other / s | 5 % gross, σ given: rejected / kept / "
           "ok·unc·part·other | 5 % gross, σ est.: rejected / kept / ok·unc·inc·amb·other / s |", "|---|---|---|---|"]
    cells = list(dict.fromkeys(r["cell"] for r in rows if r["condition"] in CONDITIONS))
    for cell in cells:
        c, g, e = get(cell, "clean", "estimated"), get(cell, "gross 5%", "given"), get(cell, "gross 5%", "estimated")
        cols = [f"{c['kept']} / {c['placed']} / {c['sigma_ratio']} / {c['ok']}·{c['uncontrolled']}·"
                f"{other(c, 'ok', 'uncontrolled')} / {c.get('sec_med', '-')}" if c else "",
                f"{g['gross_rejected']} / {g['kept']} / {g['ok']}·{g['uncontrolled']}·{g['partial']}·"
                f"{other(g, 'ok', 'uncontrolled', 'partial')}" if g else "",
                f"{e['gross_rejected']} / {e['kept']} / {e['ok']}·{e['uncontrolled']}·{e['inconsistent']}·"
                f"{e['ambiguous']}·{other(e, 'ok', 'uncontrolled', 'inconsistent', 'ambiguous')} / {e.get('sec_med', '-')}"
                if e else ""]
        out.append(f"| {cell} | " + " | ".join(cols) + " |")
    for r in rows:
        if r["condition"] == SCALE_CONDITION[0] and r["sigma_mode"] == "estimated":
            given = next((x for x in rows if x["cell"] == r["cell"] and x["condition"] == r["condition"]
                          and x["sigma_mode"] == "given"), None)
            note = f" (σ given {given.get('sec_med', '-')})" if given else ""
            out.append(f"| {r['cell']}, {r['condition']} | {r['kept']} / {r['placed']} / {r['sigma_ratio']} / "
                       f"{r['ok']}·{r['uncontrolled']}·{other(r, 'ok', 'uncontrolled')} / {r.get('sec_med', '-')}{note} "
                       "| | |")
    return "\n".join(out) + "\n"


def render(out_dir: str, name: str = "calibration") -> None:
    """Rewrite NAME.md from NAME.csv (no computing)."""
    with open(os.path.join(out_dir, f"{name}.csv"), newline="") as handle:
        rows = list(csv.DictReader(handle))
    with open(os.path.join(out_dir, f"{name}.md"), "w") as handle:
        handle.write(markdown(rows))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--networks", type=int, default=200, help="networks per cell (default 200)")
    ap.add_argument("--scale-networks", type=int, default=3, help="networks per scale row (default 3)")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", help="comma-separated cells, e.g. 9r3s,8r5s (default all; 'scale' for the scale rows)")
    ap.add_argument("--conditions", help="comma-separated conditions (clean, gross, missing; default all)")
    ap.add_argument("--gross-networks", type=int, help="networks per gross-error cell (default: --networks)")
    ap.add_argument("--wrong-networks", type=int, help="networks per wrong-input row (default: --networks)")
    ap.add_argument("--quick", action="store_true", help="10 networks a cell, 1 per scale row, into tables/quick/")
    ap.add_argument("--out", help="output directory (default tables/, or tables/quick/ with --quick)")
    ap.add_argument("--render", action="store_true", help="only rewrite calibration.md from calibration.csv")
    ap.add_argument("--compare", metavar="OLD_CSV", help="only print the rows of the table (in --out or tables/) "
                    "whose results moved against OLD_CSV, each said better or worse")
    ap.add_argument("--dim", type=int, choices=(2, 3), default=2, help="3: the 3D grid into calibration3d.* "
                    "(see the docstring)")
    args = ap.parse_args(argv)
    name = "calibration" if args.dim == 2 else "calibration3d"
    networks = 10 if args.quick else args.networks
    scale_networks = 1 if args.quick else args.scale_networks
    out_dir = args.out or os.path.join(ROOT, "tables", "quick" if args.quick else "")
    os.makedirs(out_dir, exist_ok=True)
    if args.render:
        render(out_dir, name)
        return 0
    if args.compare:
        for line in compare(_read(args.compare), _read(os.path.join(out_dir, f"{name}.csv"))):
            print(line)
        return 0
    only = set(args.only.split(",")) if args.only else None

    jobs = []
    for (m, n) in (CELLS if args.dim == 2 else CELLS_3D):
        if only and f"{m}r{n}s" not in only:
            continue
        for sigma in SIGMAS:
            for cond, (missing, gross) in CONDITIONS.items():
                if args.conditions and cond.split()[0] not in args.conditions.split(","):
                    continue
                count = args.gross_networks if gross and args.gross_networks else networks
                jobs.append(((m, n), sigma, cond, missing, gross, count, MODES))
        for cond in WRONG:
            if not args.conditions or cond.split()[0] in args.conditions.split(","):
                jobs.append(((m, n), WRONG_SIGMA, cond, 0.0, 0.0, args.wrong_networks or networks, MODES))
    if not only or "scale" in only:
        for (m, n) in (SCALE if args.dim == 2 else SCALE_3D):
            scale_jobs = [(SCALE_CONDITION, MODES)] + ([(SCALE_GROSS_3D, ("given",))] if args.dim == 3 else [])
            for cond, modes in scale_jobs:
                if not args.conditions or cond[0].split()[0] in args.conditions.split(","):
                    jobs.append(((m, n), 1e-2, *cond, scale_networks, modes))

    # provenance read before anything is written (the outputs themselves would make the tree dirty)
    commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    dirty = bool(subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT,
                                capture_output=True, text=True).stdout.strip())
    t_start = time.perf_counter()
    rows = []
    if args.jobs <= 1:
        warm_up(args.dim)
    with (ProcessPoolExecutor(max_workers=args.jobs, initializer=warm_up, initargs=(args.dim,)) if args.jobs > 1
          else _Serial()) as pool:
        for shape, sigma, cond, missing, gross, count, modes in jobs:
            t0 = time.perf_counter()
            tasks = [(shape, sigma, cond, missing, gross, args.seed + 1000 * k + 7, args.dim, modes)
                     for k in range(count)]
            trials = list(pool.map(trial, tasks))
            cell = f"{shape[0]}r/{shape[1]}s"
            for mode in modes:
                row = summarise(cell, sigma, cond, mode, trials)
                rows.append(row)
                print(f"{cell:>9} sigma {sigma:<6g} {cond:<11} {mode:<9} kept {row['kept']:.4f} gross "
                      f"{row['gross_rejected']!s:<6} placed {row['placed']:.2f} err x{row['err_ratio_med']} sigma "
                      f"x{row['sigma_ratio']} >3std {row['over3std']:.4f} ok>5std {row['ok_over5std']:.3f} ok "
                      f"{row['ok']} unc {row['uncontrolled']} inc {row['inconsistent']} amb {row['ambiguous']} "
                      f"part {row['partial']} {row['sec_med']:.2f}s/{row['sec_p95']:.2f}s", file=sys.stderr, flush=True)
            print(f"  ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
            if only or args.conditions:  # a partial run keeps each finished row (a stopped run resumes by cell)
                _write_rows(out_dir, name, _merge(out_dir, name, _results_only(rows, args.dim), args.dim)[0])

    seconds = {f"{r['cell']} {r['sigma']} {r['condition']} {r['sigma_mode']}": [r["sec_med"], r["sec_p95"]]
               for r in rows}
    cpu_seconds = {f"{r['cell']} {r['sigma']} {r['condition']} {r['sigma_mode']}": [r["cpu_med"], r["cpu_p95"]]
                   for r in rows}
    rows = _results_only(rows, args.dim)
    old_meta = {}
    if only or args.conditions:
        # a partial run replaces its rows in the existing table and keeps the others (in grid order)
        rows, old_meta = _merge(out_dir, name, rows, args.dim)
    _write_rows(out_dir, name, rows)
    meta = {
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "commit": commit, "worktree_dirty": dirty, "networks_per_cell": networks, "scale_networks": scale_networks,
        "gross_networks_per_cell": args.gross_networks or networks,
        "seed": args.seed, "seconds": round(time.perf_counter() - t_start, 1), "jobs": args.jobs,
        "networks": "positions uniform in [-5, 5]^2, offsets uniform in [-2, 2], Gaussian noise sigma; network k of "
                    "a cell uses numpy.random.default_rng(seed + 1000 k + 7)",
        "corruption": "solvers.synthetic.corrupt_measurements (gaps keep >= 3 per receiver, >= 4 per transmitter; "
                      "gross errors uniform in [min F, max F])",
        "calls": "solvers.calibrate(F, sigma=true sigma or None, seed=network seed), default options",
        "versions": {"python": platform.python_version(), "numpy": np.__version__},
        "threads": {k: os.environ.get(k) for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")},
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
    }
    if old_meta.get("seconds_per_call"):
        seconds = {**old_meta["seconds_per_call"], **seconds}
    if old_meta.get("cpu_seconds_per_call"):
        cpu_seconds = {**old_meta["cpu_seconds_per_call"], **cpu_seconds}
    if args.dim == 3:
        meta["networks"] = ("solvers.synthetic.room_network: uniform in an 8 x 6 x 3 m room, offsets N(0, 1 m), Gaussian "
                            "noise sigma; network k of a cell uses numpy.random.default_rng(seed + 1000 k + 7)")
        meta["corruption"] = meta["corruption"].replace(">= 3 per receiver, >= 4", ">= 4 per receiver, >= 5")
        meta["seconds_per_call"] = seconds  # median, p95 (wall)
        meta["cpu_seconds_per_call"] = cpu_seconds  # median, p95 (the process's CPU time)
    if old_meta and (only or args.conditions):
        # a partial run: the record of the run that made the other rows stays, this one is added to its reruns
        rerun = {k: meta[k] for k in ("date", "commit", "worktree_dirty", "seconds", "jobs", "seed")}
        rerun.update(only=args.only, conditions=args.conditions, networks_per_cell=networks,
                     gross_networks_per_cell=args.gross_networks or networks,
                     wrong_networks_per_cell=args.wrong_networks or networks, scale_networks=scale_networks)
        kept = {k: v for k, v in old_meta.items() if k not in ("seconds_per_call", "cpu_seconds_per_call")}
        meta = {**kept, **{k: meta[k] for k in ("seconds_per_call", "cpu_seconds_per_call") if k in meta},
                "reruns": old_meta.get("reruns", []) + [rerun]}
    meta_name = f"{name}.meta.json" if args.dim == 2 else f"{name}.timing.json"
    with open(os.path.join(out_dir, meta_name), "w") as handle:
        json.dump(meta, handle, indent=2)
        handle.write("\n")
    print(f"wrote {out_dir}/{name}.csv, {name}.md, {meta_name} in {meta['seconds']} s", file=sys.stderr)
    return 0


def _read(path: str) -> list[dict]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


#: (column, +1 when more is better): what makes a row worse than before (ok_over5std: a confident wrong answer)
JUDGED = (("ok_over5std", -1), ("ok", +1), ("placed", +1), ("kept", +1), ("gross_rejected", +1))


def compare(old: list[dict], new: list[dict]) -> list[str]:
    """One line per row of `new` whose results moved against `old` (same cell, sigma, condition, mode): the
    status counts before -> after and which judged columns (JUDGED) got better or worse; rows with other
    network counts are said, not compared. A row only in `new` is said new."""
    before = {_key(r): r for r in old}
    lines = []
    for r in new:
        o = before.get(_key(r))
        label = f"{r['cell']} {r['sigma']} {r['condition']} {r['sigma_mode']}"
        if o is None:
            lines.append(f"{label}: new, " + " ".join(f"{s} {r[s]}" for s in STATUSES if int(r[s])))
            continue
        if o["networks"] != r["networks"]:
            lines.append(f"{label}: {o['networks']} -> {r['networks']} networks, not compared")
            continue
        moved = [s for s in STATUSES if o[s] != r[s]]
        worse, better = [], []
        for col, sign in JUDGED:
            a, b = o.get(col, ""), r.get(col, "")
            if a in ("", "inf", "nan") or b in ("", "inf", "nan") or float(a) == float(b):
                continue
            (better if sign * (float(b) - float(a)) > 0 else worse).append(f"{col} {a} -> {b}")
        if moved or worse or better:
            counts = ", ".join(f"{s} {o[s]} -> {r[s]}" for s in moved)
            verdict = "WORSE" if worse else "better" if better else "moved"
            lines.append(f"{label}: {verdict}: " + "; ".join(x for x in (counts, ", ".join(worse + better)) if x))
    return lines


def _results_only(rows: list[dict], dim: int) -> list[dict]:
    """The rows without run facts: CPU seconds never, wall seconds not in 3D (calibration3d.timing.json)."""
    drop = ("cpu_med", "cpu_p95") + (("sec_med", "sec_p95") if dim == 3 else ())
    return [{k: v for k, v in r.items() if k not in drop} for r in rows]


def _write_rows(out_dir: str, name: str, rows: list[dict]) -> None:
    with open(os.path.join(out_dir, f"{name}.csv"), "w", newline="") as handle:
        w = csv.DictWriter(handle, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    with open(os.path.join(out_dir, f"{name}.md"), "w") as handle:
        handle.write(markdown(rows))


def _key(row) -> tuple:
    return row["cell"], float(row["sigma"]), row["condition"], row["sigma_mode"]


def _merge(out_dir: str, name: str, rows: list[dict], dim: int) -> tuple[list[dict], dict]:
    """The rows of the existing {name}.csv with the rerun ones replaced (new ones appended), in grid
    order, and the existing run record (its seconds per call are kept for the rows not rerun)."""
    path = os.path.join(out_dir, f"{name}.csv")
    if not os.path.exists(path):
        return rows, {}
    with open(path, newline="") as handle:
        old = list(csv.DictReader(handle))
    fresh = {_key(r): r for r in rows}
    merged = [fresh.pop(_key(r), None) or r for r in old] + list(fresh.values())  # old rows as read (text)
    cells = [f"{m}r/{n}s" for m, n in (CELLS if dim == 2 else CELLS_3D) + (SCALE if dim == 2 else SCALE_3D)]
    conds = list(CONDITIONS) + list(WRONG) + [SCALE_CONDITION[0]]
    merged.sort(key=lambda r: (cells.index(r["cell"]), float(r["sigma"]), conds.index(r["condition"]),
                               ("given", "estimated").index(r["sigma_mode"])))
    record = os.path.join(out_dir, f"{name}.meta.json" if dim == 2 else f"{name}.timing.json")
    meta = {}
    if os.path.exists(record):
        with open(record) as handle:
            meta = json.load(handle)
    return merged, meta


class _Serial:
    """The executor interface, run in this process (--jobs 1)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def map(self, fn, items):
        return map(fn, items)


if __name__ == "__main__":
    sys.exit(main())
