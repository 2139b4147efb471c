"""Compare the tracker's predictor and corrector on the committed homotopy solvers (issue 44, item 3).

Per solver and variant (the plain track's ``predictor`` and ``corrector``, :class:`solvers.continuation.tracker.
TrackerOptions`, replaced in the spec's own step control; retracks and detours unchanged), on N seeded
noiseless networks (2D TDOA: solvers.synthetic.random_network as scripts/bench_solvers.py, same seed and
sequence; TOA: room networks with offsets 0, seeds 0..N-1): the median time of one ``solve`` over the first
``--single`` networks (best of ``--rounds`` rounds, the variants interleaved within each round, so that they see
the same periods of this shared machine's speed), its ratio to the first variant's, microseconds per path,
the networks whose true root is missed (no candidate within 1e-6 relative error; solvers whose unknowns are not
(H, b, o) or the positions of 4r/5s: not checked, "-"), the instances with fewer distinct finite roots than
paths and the roots they lack (lost or coinciding endpoints), and the plain track's step attempts per path (first ``--single`` networks, one track each).

Usage: OPENBLAS_NUM_THREADS=1 python scripts/bench_tracker_variants.py [--solvers 9r3s 6r3s ...] [--trials 100]
       [--single 20] [--rounds 3] [--variants rk4/newton pade/newton pade/chord,target=0.02 ...] [--out tables/tracker_variants.csv]

Timings are of this run on this machine: the CSV is a run record (ratios are what compare), not a committed
result.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ["TDOA_WORKBENCH_THREADS"] = "1"  # one core, as scripts/bench_solvers.py
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import dataclasses  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "scripts"))

import numpy as np  # noqa: E402

from solvers.continuation import tracker  # noqa: E402
from solvers.continuation.tracking import unresolved  # noqa: E402
from solvers.generate import GENERATED_DIR  # noqa: E402

#: Committed homotopy solvers (label -> module stem prefix) in the order of the issue's list.
SOLVERS = ("9r3s", "8r3s", "7r3s", "6r3s", "5r4s", "5r5s", "4r5s", "3r3stoa", "4r6s3dtoa", "6r4s3dtoa", "5r5s3dtoa",
           "4r6s3dgram")
VARIANTS = ("rk4/newton", "pade/newton", "pade/chord")
FAIL_TOL = 1e-6


def _module(label: str):
    import importlib

    stem = next(f[:-3] for f in sorted(os.listdir(GENERATED_DIR))
                if f.startswith(f"tdoa_{label}_homotopy") and f.endswith(".py"))
    return importlib.import_module(f"solvers.generated.{stem}")


def _networks(module, trials: int, seed: int):
    """Seeded networks and their measurements for the module's configuration, dimension and model."""
    from solvers.synthetic import random_network, room_network

    m, n = module.CONFIG
    dim = 3 if "3d" in module.SYSTEM else 2
    if "toa" in module.SYSTEM:
        room = (8.0, 6.0, 3.0)[:dim]
        nets = [room_network(m, n, np.random.default_rng(s), room=room, offset_sigma=0.0) for s in range(trials)]
    else:
        rng = np.random.default_rng(seed)
        nets = [random_network(m, n, rng, dim=dim) for _ in range(trials)]
    return nets, np.stack([net.measurements() for net in nets])


def _truth(module, net) -> np.ndarray | None:
    """The true root in the module's unknowns, or None where they are not (H, b, o) or 4r/5s's positions."""
    from solvers.synthetic import true_root

    if "positions" in module.SYSTEM:
        from bench_solvers import _truth as positions_truth

        return positions_truth(module, net)
    H, b, o = true_root(net)
    values = {f"b{k + 1}": v for k, v in enumerate(b)} | {f"o{k + 1}": v for k, v in enumerate(o)}
    values |= {f"h{i + 1}{j + 1}": H[i, j] for i in range(len(H)) for j in range(i, len(H))}
    if not all(u in values for u in module.UNKNOWNS):
        return None
    return np.array([values[u] for u in module.UNKNOWNS], dtype=float)


def _options(base: tracker.TrackerOptions, variant: str) -> tracker.TrackerOptions:
    """PREDICTOR/CORRECTOR[,FIELD=NUMBER...] (further TrackerOptions fields, e.g. pade/newton,target=0.02)."""
    head, *extra = variant.split(",")
    predictor, corrector = head.split("/")
    fields = {}
    for item in extra:
        key, value = item.split("=")
        if key not in {f.name for f in dataclasses.fields(tracker.TrackerOptions)} - {"predictor", "corrector"}:
            raise ValueError(f"no numeric TrackerOptions field {key!r}")
        fields[key] = type(getattr(base, key))(float(value))
    return dataclasses.replace(base, predictor=predictor, corrector=corrector, **fields)


def bench(label: str, variants: list[str], trials: int, single: int, rounds: int, seed: int) -> list[dict]:
    module = _module(label)
    solver = module.solver()
    base = solver.options
    nets, F = _networks(module, trials, seed)
    truths = [_truth(module, net) for net in nets]
    module.solve(F[0])  # compiled kernels loaded
    options = {v: _options(base, v) for v in variants}

    def use(variant: str) -> None:
        solver.options = options[variant]
        solver.__dict__.pop("_midpoints", None)  # midpoint root sets tracked with this variant's options

    best = {v: np.inf for v in variants}
    for _ in range(rounds):
        for v in variants:
            use(v)
            times = []
            for k in range(min(single, trials)):
                t0 = time.perf_counter()
                module.solve(F[k])
                times.append(time.perf_counter() - t0)
            best[v] = min(best[v], float(np.median(times)))
        print(f"  {label} round: " + ", ".join(f"{v} {1e3 * best[v]:.2f} ms" for v in variants), file=sys.stderr, flush=True)
    rows = []
    for v in variants:
        use(v)
        roots = module.solve_batch(F)
        missed, checked = [], 0
        for k, (x, t) in enumerate(zip(roots, truths)):
            if t is None:
                continue
            checked += 1
            with np.errstate(all="ignore"):
                err = np.nanmin(np.linalg.norm(x - t[None], axis=1)) / np.linalg.norm(t)
            if not err <= FAIL_TOL:
                missed.append(k)
        lost = np.array([int(unresolved(x, solver.group).sum()) for x in roots])
        q = F[:single].reshape(min(single, trials), -1).astype(complex)
        q /= np.sqrt(np.mean(np.abs(q) ** 2, axis=1, keepdims=True))
        K = solver.n_paths
        _, stats = solver.track(solver.q0[None], q, np.tile(solver.x0, (len(q), 1)), np.repeat(np.arange(len(q)), K))
        rows.append({"solver": label, "variant": v, "paths": K, "trials": trials,
                     "single_ms": round(1e3 * best[v], 3), "ratio": round(best[v] / best[variants[0]], 3),
                     "us_per_path": round(1e6 * best[v] / K, 1),
                     "true_root_missed": len(missed) if checked else "-",
                     "missed_networks": " ".join(map(str, missed)),
                     "incomplete": int(np.sum(lost > 0)), "roots_lost": int(lost.sum()),
                     "attempts_per_path": round(float(np.mean(stats[:, 1] + stats[:, 2])), 1),
                     "plain_not_ended": int(np.sum(stats[:, 0] != 0))})
        print(", ".join(f"{k}={val}" for k, val in rows[-1].items()), flush=True)
    solver.options = base
    solver.__dict__.pop("_midpoints", None)
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--solvers", nargs="+", default=list(SOLVERS), choices=list(SOLVERS), metavar="SOLVER")
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), metavar="PREDICTOR/CORRECTOR")
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--single", type=int, default=20)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=os.path.join(ROOT, "tables", "tracker_variants.csv"))
    args = ap.parse_args(argv)
    for v in args.variants:
        try:
            _options(tracker.TrackerOptions(), v)
        except ValueError as exc:
            ap.error(f"variant {v!r}: {exc}")
    rows = []
    for label in args.solvers:
        rows += bench(label, args.variants, args.trials, args.single, args.rounds, args.seed)
        with open(args.out, "w", newline="", encoding="utf-8") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
