"""Numerical companion of the 4r/5s count: monodromy finds the 344 orbits, then real/physical counts.

The 4r/5s `receivers` formulation (analysis.formulations.positions; 5 unknowns, Q_1..Q_5) is solved numerically by
the project's parameter homotopy in the data F (solvers.continuation.tracking: complex straight segments,
the compiled tracker, Newton steps on the endpoints):

1. Monodromy: from the known root of a seeded real instance F0, track one root per known orbit (the
   equations are invariant under the sign group for all data, so paths map to paths) around random
   complex triangles F0 -> F1 -> F2 -> F0 and keep the endpoints of new orbits until three loops in a
   row add none. An independent numerical check of the GF(p) count: the orbits
   found can never exceed the true count, and the loop stops at 344 only if it is reached.
2. Real counts: from the solutions at F0, track one root per orbit to each seeded real instance
   (paper Section 4 distribution: positions N(0, 10^2), offsets N(0, 1); F divided by 10, which scales
   every solution by 1/10 and changes no count) through a random complex midpoint; count the real
   orbits and the physical ones (real, with every f_ij - o_j >= 0, transmitters and offsets recovered by
   network_from_root), and check that the true network is among them.

Writes tables/minimal_real_counts.csv (one row per instance) and prints a summary.
Usage: OPENBLAS_NUM_THREADS=1 python scripts/minimal_real_counts.py [--instances 12] [--seed 0] [--max-loops 30]
(about 4 minutes on the loaded 2-core machine; numbers in tables/minimal_problems.md).
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from analysis.formulations.parametric import from_positions  # noqa: E402
from analysis.formulations.positions import network_from_root, positions_system, sample_real_positions  # noqa: E402
from solvers.continuation import tracking  # noqa: E402

M, N = 4, 5
SCALE = 10.0


def homotopy_solver(system) -> tracking.HomotopySolver:
    """The project's parameter homotopy (solvers.continuation.tracking, compiled tracker) on a positions system.

    The parameters are the data F (row-major). No start system is stored: the monodromy below finds
    the roots and every segment is given explicitly (``start_parameters`` is a placeholder).
    """
    exps, eq = tracking.structure(system)
    spec = {"exponents": exps.tolist(), "term_equation": eq.tolist(),
            "coefficient_degree": int(max(system.coefficient_degrees)),
            "start_parameters": [[0.0, 0.0]] * len(system.parameters), "start_roots": []}
    return tracking.HomotopySolver(spec, tracking.load_coefficients(tracking.coefficient_source(system)))


def track(solver: tracking.HomotopySolver, Fa: np.ndarray, Fb: np.ndarray, x: np.ndarray):
    """Track every finite row of x from the data Fa to Fb (straight segment), then two Newton steps at Fb.

    Returns (x (P, 5), ok (P,)); rows that did not reach Fb are NaN.
    """
    qa, qb = Fa.ravel()[None].astype(complex), Fb.ravel()[None].astype(complex)
    out = np.full(x.shape, np.nan, complex)
    start = np.flatnonzero(np.all(np.isfinite(x), axis=1))
    if len(start):
        end, stats = solver.track(qa, qb, x[start])
        reached = stats[:, 0] == 0
        if reached.any():
            out[start[reached]] = solver.newton(end[reached], qb, steps=2)
    return out, np.all(np.isfinite(out), axis=1)


def orbit(x: np.ndarray, group) -> np.ndarray:
    return np.concatenate([x * np.array(g)[None, :] for g in group])


def random_complex_data(rng, F0):
    return F0 + rng.normal(0, 1, F0.shape) + 1j * rng.normal(0, 1, F0.shape)


def orbit_representatives(sols: np.ndarray, group) -> np.ndarray:
    reps = np.zeros((0, sols.shape[1]), complex)
    for x in sols:
        imgs = orbit(x[None], group)
        if reps.size == 0 or min(np.min(np.linalg.norm(reps - y[None], axis=1)) for y in imgs) > 1e-6 * (1 + np.linalg.norm(x)):
            reps = np.vstack([reps, x[None]])
    return reps


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--instances", type=int, default=12)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-loops", type=int, default=40)
    ap.add_argument("--output", default=os.path.join(ROOT, "tables", "minimal_real_counts.csv"))
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    system = positions_system(M, N, "receivers")
    solver = homotopy_solver(from_positions(M, N, "receivers"))
    group = system.sign_group
    rng = np.random.default_rng(args.seed)
    F0, root0 = sample_real_positions(M, N, 1000 + args.seed, "receivers")
    F0, root0 = F0 / SCALE, root0 / SCALE
    reps = root0[None].astype(complex)  # one root per orbit: the homotopy commutes with the sign group
    stale = 0
    for loop in range(args.max_loops):
        F1, F2 = random_complex_data(rng, F0), random_complex_data(rng, F0)
        x = reps
        ok_all = np.ones(len(x), bool)
        for Fa, Fb in ((F0, F1), (F1, F2), (F2, F0)):
            x, ok = track(solver, Fa, Fb, x)
            ok_all &= ok
        before = len(reps)
        reps = orbit_representatives(np.vstack([reps, x[ok_all]]), group)
        print(f"loop {loop + 1}: {len(reps)} orbits, {np.sum(~ok_all)} failed paths, "
              f"{time.perf_counter() - t0:.0f} s", flush=True)
        stale = stale + 1 if len(reps) == before else 0
        if stale >= 3:
            break
    print(f"monodromy: {len(reps)} orbits ({4 * len(reps)} solutions) at F0")
    rows = []
    for k in range(args.instances):
        seed = args.seed + k
        F, root = sample_real_positions(M, N, seed, "receivers")
        F, root = F / SCALE, root / SCALE
        Fmid = random_complex_data(rng, 0.5 * (F0 + F))
        x, ok1 = track(solver, F0, Fmid, reps)
        x, ok2 = track(solver, Fmid, F, x)
        ok = ok1 & ok2
        sols = x[ok]
        real = [s for s in sols if np.max(np.abs(s.imag)) < 1e-8 * (1 + np.max(np.abs(s)))]
        physical, true_found = 0, False
        for s in real:
            rec, tra, offs = network_from_root(system, s.real, F)
            d = F - offs[None, :]
            if np.all(d >= -1e-9):
                physical += 1
            if min(np.linalg.norm(s.real * np.array(g) - root) for g in group) < 1e-6 * (1 + np.linalg.norm(root)):
                true_found = True
        distinct = len(orbit_representatives(sols, group)) if len(sols) else 0
        rows.append(dict(instance_seed=seed, orbits_tracked=len(reps), paths_ok=int(ok.sum()), distinct_orbits=distinct,
                         real_orbits=len(real), physical_orbits=physical, true_network_found=true_found))
        print(rows[-1], flush=True)
    out = args.output
    with open(out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    real = np.array([r["real_orbits"] for r in rows])
    phys = np.array([r["physical_orbits"] for r in rows])
    print(f"real orbits: min {real.min()} median {np.median(real)} max {real.max()}; physical: min {phys.min()} "
          f"median {np.median(phys)} max {phys.max()}; true network found {sum(r['true_network_found'] for r in rows)}/"
          f"{len(rows)}; {time.perf_counter() - t0:.0f} s; wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
