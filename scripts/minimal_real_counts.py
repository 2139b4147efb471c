"""Numerical companion of the 4r/5s count: monodromy finds the 344 orbits, then real/physical counts.

The 4r/5s `receivers` formulation (analysis.positions; 5 unknowns, Q_1..Q_5) is solved numerically by a
parameter homotopy in the data F (complex straight segments, batched predictor-corrector in numpy):

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
(about 7 minutes on the loaded 2-core machine; numbers in tables/minimal_problems.md).
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
import sympy  # noqa: E402

from analysis.positions import evaluate_real, network_from_root, positions_system, sample_real_positions  # noqa: E402

M, N = 4, 5
SCALE = 10.0


def compile_q():
    """Q(x; f) of one transmitter (f = its column of F) with gradients in x and f, as numpy functions.

    Written unexpanded, Q = (2 f_1 D - N_o)^2 - N_u^2 - N_v^2 with N = adj(A) g (analysis.positions,
    variant ``receivers``), so that differentiation and common-subexpression elimination stay cheap; it
    is checked against the expanded equation Q1 of positions_system(4, 5, "receivers") at a random point.
    """
    system = positions_system(M, N, "receivers")
    xs = sympy.symbols(system.unknowns)
    x2, x3, y3, x4, y4 = xs
    fs = sympy.symbols("g1:5")
    rec = [(x2, 0), (x3, y3), (x4, y4)]
    A = sympy.Matrix([[r[0], r[1], -(fs[i + 1] - fs[0])] for i, r in enumerate(rec)])
    g2 = sympy.Matrix([r[0] ** 2 + r[1] ** 2 - (fs[i + 1] ** 2 - fs[0] ** 2) for i, r in enumerate(rec)])
    D = A.det()
    N2 = A.adjugate() * g2
    q = (2 * fs[0] * D - N2[2]) ** 2 - N2[0] ** 2 - N2[1] ** 2
    grads = [sympy.diff(q, v) for v in xs] + [sympy.diff(q, v) for v in fs]
    fn = sympy.lambdify(xs + fs, [q] + grads, "numpy", cse=True)
    rng = np.random.default_rng(0)
    point = rng.normal(size=5)
    fcol = rng.normal(size=4)
    F = np.ones((M, N))
    F[:, 0] = fcol
    ref = evaluate_real(system, F, point)[0][0]
    assert abs(fn(*point, *fcol)[0] - ref) <= 1e-9 * (1 + abs(ref)), "compiled Q disagrees with positions Q1"
    return system, fn


class Homotopy:
    """H(x, s) = [Q(x; F(s)[:, j])]_j with F(s) = Fa + s (Fb - Fa), s in [0, 1]; batched over paths."""

    def __init__(self, fn, Fa: np.ndarray, Fb: np.ndarray):
        self.fn, self.Fa, self.dF = fn, Fa.astype(complex), (Fb - Fa).astype(complex)

    def eval(self, x: np.ndarray, s: np.ndarray):
        """(H (P, 5), H_x (P, 5, 5), H_s (P, 5)) at points x (P, 5) and parameters s (P,)."""
        P = x.shape[0]
        F = self.Fa[None] + s[:, None, None] * self.dF[None]  # (P, M, N)
        H = np.empty((P, N), complex)
        J = np.empty((P, N, 5), complex)
        Hs = np.empty((P, N), complex)
        for j in range(N):
            out = self.fn(*x.T, *F[:, :, j].T)
            out = [np.broadcast_to(o, (P,)) for o in out]
            H[:, j] = out[0]
            J[:, j, :] = np.stack(out[1:6], axis=1)
            Hs[:, j] = sum(out[6 + i] * self.dF[i, j] for i in range(M))
        return H, J, Hs


def _solve(J: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched J x = b; rows whose J is singular get NaN (their path is then rejected)."""
    try:
        return np.linalg.solve(J, b[..., None])[..., 0]
    except np.linalg.LinAlgError:
        out = np.full(b.shape, np.nan, complex)
        for k in range(J.shape[0]):
            try:
                out[k] = np.linalg.solve(J[k], b[k])
            except np.linalg.LinAlgError:
                pass
        return out


def track(hom: Homotopy, x0: np.ndarray, h0: float = 0.02, min_step: float = 1e-9, max_steps: int = 4000):
    """Track every row of x0 from s = 0 to s = 1. Returns (x (P, 5), ok (P,))."""
    x = x0.astype(complex).copy()
    P = x.shape[0]
    s = np.zeros(P)
    h = np.full(P, h0)
    active = np.ones(P, bool)
    ok = np.zeros(P, bool)
    for _ in range(max_steps):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        xi, si, hi = x[idx], s[idx], np.minimum(h[idx], 1.0 - s[idx])

        def velocity(xx, ss):
            _, J, Hs = hom.eval(xx, ss)
            return -_solve(J, Hs)

        k1 = velocity(xi, si)
        k2 = velocity(xi + 0.5 * hi[:, None] * k1, si + 0.5 * hi)
        k3 = velocity(xi + 0.5 * hi[:, None] * k2, si + 0.5 * hi)
        k4 = velocity(xi + hi[:, None] * k3, si + hi)
        xp = xi + hi[:, None] / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        sp = si + hi
        good = np.ones(idx.size, bool)
        for it in range(3):
            H, J, _ = hom.eval(xp, sp)
            dx = _solve(J, H)
            xp = xp - dx
            size = np.linalg.norm(dx, axis=1) / (1 + np.linalg.norm(xp, axis=1))
            if it == 0:
                good &= np.nan_to_num(size, nan=1.0) < 1e-3
        good &= np.nan_to_num(size, nan=1.0) < 1e-9
        good &= np.all(np.isfinite(xp), axis=1)
        acc, rej = idx[good], idx[~good]
        x[acc], s[acc] = xp[good], sp[good]
        h[acc] = np.minimum(h[acc] * 1.6, 0.1)
        h[rej] = h[rej] / 2
        done = acc[s[acc] >= 1.0 - 1e-15]
        ok[done] = True
        active[done] = False
        dead = rej[h[rej] < min_step]
        active[dead] = False
    return x, ok


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
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    system, fn = compile_q()
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
            x, ok = track(Homotopy(fn, Fa, Fb), x)
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
        x, ok1 = track(Homotopy(fn, F0, Fmid), reps)
        x, ok2 = track(Homotopy(fn, Fmid, F), x)
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
    out = os.path.join(ROOT, "tables", "minimal_real_counts.csv")
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
