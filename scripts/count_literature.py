"""`count` on problems from the literature, each written here from its published formulation as a system file in
examples/ (with a start pair where an equation holds no parameter): tables/count_literature.{csv,md} (results)
and tables/count_literature.meta.json (wall and CPU times, the load, and the committed Alt's-problem run as a
reference). Each row is `count FILE [--start FILE.start.json] --trace` with the default two seeds, every solution
proven; the published count and its source stand beside what `count` finds. The table is never adjusted: a row
whose count differs from the published one, or whose trace test fails on a complete set, is a finding.

The systems are written by the builders below (``--write-examples`` rewrites examples/*.sys and the start pairs,
each checked to solve its system; tests/test_count_literature.py checks that the committed files are the builders'
output). A start pair is a closed form: random complex unknowns on the parameter-free equations (a unit vector, a
rotation, a Study point), random parameters for all but a few, and those few solved for in closed form.

Usage: python scripts/count_literature.py [--threads 2] [--only NAME ...] [--write-examples]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import itertools  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from analysis.formulations.parametric import parse  # noqa: E402

EXAMPLES = os.path.join(ROOT, "examples")
TABLES = os.path.join(ROOT, "tables")
#: the trace test runs on sets up to this size (issue 54: "--trace passing on every complete set up to 500")
TRACE_MAX = 500


# --- the systems -------------------------------------------------------------------------------------------------

def _mon(xs, m) -> str:
    return "*".join(f"{x}^{e}" if e > 1 else x for x, e in zip(xs, m) if e) or "1"


def _monomials(n: int, d: int) -> list[tuple[int, ...]]:
    return [m for k in range(d + 1) for m in itertools.product(range(d + 1), repeat=n) if sum(m) == k]


def ed_text(n: int, d: int) -> str:
    """The ED degree problem of a general degree-d hypersurface f = 0 in C^n: the critical points x of the squared
    distance to a data point u on f = 0, x - u = l grad f (unknowns x, l; parameters u and f's coefficients)."""
    xs = [f"x{i}" for i in range(1, n + 1)]
    mons = _monomials(n, d)
    cs = [f"c{k}" for k in range(len(mons))]
    eqs = [" + ".join(f"{c}*{_mon(xs, m)}" if any(m) else c for c, m in zip(cs, mons))]
    for i in range(n):
        terms = []
        for c, m in zip(cs, mons):
            if m[i]:
                dm = list(m)
                dm[i] -= 1
                terms.append(f"{m[i]}*{c}*l" + (f"*{_mon(xs, dm)}" if any(dm) else ""))
        eqs.append(f"{xs[i]} - u{i + 1} - (" + " + ".join(terms) + ")")
    head = (f"# ED degree of a general degree-{d} hypersurface in C^{n} (Draisma, Horobet, Ottaviani, Sturmfels, Thomas "
            f"2016:\n# d (1 + (d-1) + ... + (d-1)^(n-1)) = {ed_degree(n, d)}): the points x of f = 0 where x - u is "
            "parallel to grad f.\n# Written by scripts/count_literature.py (ed_text); every coefficient of f is a "
            "parameter.\n")
    return (head + f"unknowns: {', '.join(xs)}, l\nparameters: {', '.join([f'u{i + 1}' for i in range(n)] + cs)}\n"
            "equations:\n" + "\n".join(eqs) + "\n")


def ed_degree(n: int, d: int) -> int:
    """The published formula (Draisma et al. 2016, the ED degree of a general hypersurface)."""
    return d * sum((d - 1) ** i for i in range(n))


def dense_text(n: int, d: int) -> str:
    """n dense equations of degree d in n unknowns, every coefficient a parameter."""
    xs = [f"x{i}" for i in range(1, n + 1)]
    mons = _monomials(n, d)
    names = [[f"c{i + 1}_{k}" for k in range(len(mons))] for i in range(n)]
    eqs = [" + ".join(f"{c}*{_mon(xs, m)}" if any(m) else c for c, m in zip(row, mons)) for row in names]
    head = (f"# A dense system: {n} equations of degree {d} in {n} unknowns, every coefficient a parameter. Bezout's "
            f"theorem:\n# at most {d}^{n} = {d ** n} isolated solutions, reached at generic coefficients. Written by "
            "scripts/count_literature.py (dense_text).\n")
    return (head + f"unknowns: {', '.join(xs)}\nparameters: {', '.join(c for row in names for c in row)}\n"
            "equations:\n" + "\n".join(eqs) + "\n")


def stewart_text() -> str:
    """Stewart-Gough forward kinematics in Study's coordinates (the soma of Wampler 1996): the pose as the
    quaternion e (rotation, e0 = 1 as the chart) and g = t e / 2 (t the translation), on Study's quadric
    e.g = 0. Leg k from base anchor a_k to platform anchor b_k has squared length L_k:
    |R b_k + t - a_k|^2 = L_k, times |e|^2, is |e b_k - a_k e + 2 g|^2 = L_k |e|^2 (quaternion products)."""
    lines = []
    for k in range(1, 7):
        a = [f"a{k}{i}" for i in "xyz"]
        b = [f"b{k}{i}" for i in "xyz"]
        s = [f"({a[i]} + {b[i]})" for i in range(3)]
        w0 = f"({a[0]} - {b[0]})*e1 + ({a[1]} - {b[1]})*e2 + ({a[2]} - {b[2]})*e3 + 2*g0"
        w1 = f"{b[0]} - {a[0]} + e2*{s[2]} - e3*{s[1]} + 2*g1"
        w2 = f"{b[1]} - {a[1]} + e3*{s[0]} - e1*{s[2]} + 2*g2"
        w3 = f"{b[2]} - {a[2]} + e1*{s[1]} - e2*{s[0]} + 2*g3"
        lines.append(f"({w0})^2 + ({w1})^2 + ({w2})^2 + ({w3})^2 - L{k}*(1 + e1^2 + e2^2 + e3^2)")
    params = [f"{p}{k}{i}" for k in range(1, 7) for p in "ab" for i in "xyz"] + [f"L{k}" for k in range(1, 7)]
    return ("# Stewart-Gough platform, forward kinematics (general: 40 assembly modes; Raghavan 1993, Ronga and Vust "
            "1995,\n# Lazard 1993; this formulation: Study's soma coordinates, Wampler 1996). The pose: the rotation "
            "quaternion\n# e = (1, e1, e2, e3) (the chart e0 = 1) and g = t e / 2 for the translation t, on Study's "
            "quadric e.g = 0\n# (no parameter: count needs a start pair, stewart40.start.json, drawn by "
            "scripts/count_literature.py).\n# Leg k, base anchor a_k, platform anchor b_k, squared length L_k: "
            "|e b_k - a_k e + 2 g|^2 = L_k |e|^2.\n"
            "unknowns: e1, e2, e3, g0, g1, g2, g3\n"
            f"parameters: {', '.join(params)}\nequations:\ng0 + e1*g1 + e2*g2 + e3*g3\n" + "\n".join(lines) + "\n")


def _cross(u, v):
    return [f"({u[1]})*({v[2]}) - ({u[2]})*({v[1]})", f"({u[2]})*({v[0]}) - ({u[0]})*({v[2]})",
            f"({u[0]})*({v[1]}) - ({u[1]})*({v[0]})"]


def fivepoint_text() -> str:
    """Five-point relative pose: y_k . (t x R x_k) = 0 for five correspondences x_k <-> y_k (third coordinates 1),
    R the rotation of the quaternion (1, q1, q2, q3) times its norm 1 + q.q, t = (t1, t2, 1); w (1 + q.q) = 1 keeps
    the quaternion off the null cone (where q x q* has rank 1, a surface of spurious solutions)."""
    eqs = []
    for k in range(1, 6):
        x = [f"x{k}1", f"x{k}2", "1"]
        vx = f"(q1*x{k}1 + q2*x{k}2 + q3)"
        n = "(1 - q1^2 - q2^2 - q3^2)"
        vc = _cross(["q1", "q2", "q3"], x)
        m = [f"{n}*{x[i]} + 2*{vx}*q{i + 1} + 2*({vc[i]})" for i in range(3)]
        tm = _cross(["t1", "t2", "1"], m)
        eqs.append(f"y{k}1*({tm[0]}) + y{k}2*({tm[1]}) + {tm[2]}")
    params = [f"{p}{k}{i}" for k in range(1, 6) for p in "xy" for i in "12"]
    return ("# Five-point relative pose (calibrated cameras): 10 essential matrices (Demazure 1988; Nister 2004), each "
            "with two\n# rotations (the twisted pair; Hartley and Zisserman 2004, 9.6.2) for the translation's sign "
            "fixed by t3 = 1:\n# 20 solutions (R, t). y_k . (t x R x_k) = 0 with R from the quaternion (1, q1, q2, q3) "
            "times its norm;\n# w (1 + q.q) = 1 holds no parameter (count needs a start pair, fivepoint20.start.json, "
            "drawn by\n# scripts/count_literature.py) and keeps q off the null cone, where q x q* has rank 1 (a surface of "
            "spurious solutions).\n"
            "unknowns: q1, q2, q3, t1, t2, w\n"
            f"parameters: {', '.join(params)}\nequations:\n" + "\n".join(eqs) + "\nw*(1 + q1^2 + q2^2 + q3^2) - 1\n")


def sixr_text() -> str:
    """General 6R inverse kinematics with the joint axes as unknowns (Wampler and Morgan 1991; Sommese and Wampler
    2005): z2 .. z5 unit vectors, z_k . z_(k+1) = c_k the twists' cosines, and the position equation
    sum_k A_k z_k x z_(k+1) + sum_k d_k z_k = P (A_k = a_k / sin alpha_k; z1, z6 and P from the hand's pose)."""
    z = {k: [f"z{k}{i}" for i in "xyz"] for k in range(1, 7)}
    eqs = [f"z{k}x^2 + z{k}y^2 + z{k}z^2 - 1" for k in range(2, 6)]
    eqs += [f"z{k}x*z{k + 1}x + z{k}y*z{k + 1}y + z{k}z*z{k + 1}z - c{k}" for k in range(1, 6)]
    for i in range(3):
        terms = [f"A{k}*({_cross(z[k], z[k + 1])[i]})" for k in range(1, 6)] + [f"d{k}*{z[k][i]}" for k in range(2, 6)]
        eqs.append(" + ".join(terms) + f" - P{'xyz'[i]}")
    params = (z[1] + z[6] + [f"c{k}" for k in range(1, 6)] + [f"A{k}" for k in range(1, 6)]
              + [f"d{k}" for k in range(2, 6)] + ["Px", "Py", "Pz"])
    unknowns = [v for k in range(2, 6) for v in z[k]]
    return ("# General 6R inverse kinematics: 16 solutions (Primrose 1986, Lee and Liang 1988, Raghavan and Roth 1993); "
            "this\n# formulation with the joint axes z2 .. z5 as unknowns: Wampler and Morgan 1991; Sommese and Wampler "
            "2005, ch. 9.\n# z1, z6 (and the point P) follow from the base and the hand's pose; c_k = cos(alpha_k), "
            "A_k = a_k / sin(alpha_k),\n# d_k the offsets. z_k . z_k = 1 holds no parameter (count needs a start pair, "
            "sixr16.start.json, drawn by\n# scripts/count_literature.py).\n"
            f"unknowns: {', '.join(unknowns)}\nparameters: {', '.join(params)}\nequations:\n" + "\n".join(eqs) + "\n")


# --- start pairs (closed forms) -------------------------------------------------------------------------------------

def _c(rng: np.random.Generator, *shape) -> np.ndarray:
    return rng.normal(size=shape) + 1j * rng.normal(size=shape)


def _qmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    return np.array([p[0] * q[0] - p[1:] @ q[1:], *(p[0] * q[1:] + q[0] * p[1:] + np.cross(p[1:], q[1:]))])


def stewart_start(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A random complex pose (e with e0 = 1, g on Study's quadric), random anchors, and the leg lengths they give."""
    e = np.concatenate([[1.0 + 0j], _c(rng, 3)])
    gv = _c(rng, 3)
    g = np.concatenate([[-(e[1:] @ gv)], gv])
    params, lengths = [], []
    for _ in range(6):
        a, b = _c(rng, 3), _c(rng, 3)
        w = _qmul(e, np.concatenate([[0], b])) - _qmul(np.concatenate([[0], a]), e) + 2 * g
        lengths.append((w @ w) / (e @ e))
        params += [*a, *b]
    return np.array(params + lengths), np.concatenate([e[1:], g])


def fivepoint_start(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A random complex rotation and translation, x_k and y_k1 random, y_k2 solved from the (linear) epipolar equation."""
    q = _c(rng, 3)
    t = np.array([*_c(rng, 2), 1.0])
    n = 1 - q @ q
    params = []
    for _ in range(5):
        x = np.array([*_c(rng, 2), 1.0])
        m = n * x + 2 * (q @ x) * q + 2 * np.cross(q, x)
        u = np.cross(t, m)
        y1 = _c(rng, 1)[0]
        params += [x[0], x[1], y1, -(u[2] + y1 * u[0]) / u[1]]
    return np.array(params), np.array([*q, t[0], t[1], 1 / (1 + q @ q)])


def sixr_start(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Random complex unit axes z2 .. z5 (v / sqrt(v.v)), random z1, z6, A_k, d_k; c_k and P computed."""
    z = {1: _c(rng, 3), 6: _c(rng, 3)}
    for k in range(2, 6):
        v = _c(rng, 3)
        z[k] = v / np.sqrt(v @ v)
    c = [z[k] @ z[k + 1] for k in range(1, 6)]
    A, d = _c(rng, 5), _c(rng, 4)
    P = sum(A[k - 1] * np.cross(z[k], z[k + 1]) for k in range(1, 6)) + sum(d[k - 2] * z[k] for k in range(2, 6))
    q = np.concatenate([z[1], z[6], c, A, d, P])
    return q, np.concatenate([z[k] for k in range(2, 6)])


def residual(system, q: np.ndarray, x: np.ndarray) -> float:
    """The largest |f_i(x; q)| (the parsed polynomials, evaluated by substitution: nothing is evaluated as code)."""
    values = {s: complex(v) for s, v in zip(system.q_symbols + system.x_symbols, np.concatenate([q, x]))}
    return max(abs(complex(f.xreplace(values).evalf())) for f in system.exprs)


# --- the rows -------------------------------------------------------------------------------------------------------

#: (file stem, problem, published count, its source, builder of the system text or None (a file written by hand),
#: start-pair drawer or None (count draws its own), the drawer's seed)
PROBLEMS = [
    ("rpr3", "3-RPR planar parallel robot, forward kinematics", 6,
     "Gosselin, Sefrioui, Richard 1994 (at most 6 assembly modes; Hunt 1983)", None, "file", 0),
    ("stewart40", "Stewart-Gough platform, forward kinematics (Study coordinates)", 40,
     "Raghavan 1993; Ronga, Vust 1995; Lazard 1993 (formulation: Wampler 1996)", stewart_text, stewart_start, 0),
    ("sixr16", "general 6R serial arm, inverse kinematics (joint axes)", 16,
     "Primrose 1986; Lee, Liang 1988; Raghavan, Roth 1993 (formulation: Wampler, Morgan 1991)", sixr_text, sixr_start, 0),
    ("fivepoint20", "5-point relative pose, (R, t) with t3 = 1", 20,
     "10 essential matrices (Demazure 1988; Nister 2004) x 2 rotations (twisted pair, Hartley, Zisserman 2004)",
     fivepoint_text, fivepoint_start, 0),
    ("ed2_3", "ED degree, general plane cubic", ed_degree(2, 3), "Draisma et al. 2016, d (1 + (d-1) + ...)",
     lambda: ed_text(2, 3), None, 0),
    ("ed2_4", "ED degree, general plane quartic", ed_degree(2, 4), "Draisma et al. 2016", lambda: ed_text(2, 4), None, 0),
    ("ed3_3", "ED degree, general cubic surface in C^3", ed_degree(3, 3), "Draisma et al. 2016",
     lambda: ed_text(3, 3), None, 0),
    ("ed3_4", "ED degree, general quartic surface in C^3", ed_degree(3, 4), "Draisma et al. 2016",
     lambda: ed_text(3, 4), None, 0),
    ("ed4_3", "ED degree, general cubic hypersurface in C^4", ed_degree(4, 3), "Draisma et al. 2016",
     lambda: ed_text(4, 3), None, 0),
    ("ed4_4", "ED degree, general quartic hypersurface in C^4", ed_degree(4, 4), "Draisma et al. 2016",
     lambda: ed_text(4, 4), None, 0),
    ("dense3_2", "dense system, 3 quadrics in 3 unknowns", 2 ** 3, "Bezout's theorem", lambda: dense_text(3, 2), None, 0),
    ("dense3_4", "dense system, 3 quartics in 3 unknowns", 4 ** 3, "Bezout's theorem", lambda: dense_text(3, 4), None, 0),
    ("dense4_3", "dense system, 4 cubics in 4 unknowns", 3 ** 4, "Bezout's theorem", lambda: dense_text(4, 3), None, 0),
    ("dense5_3", "dense system, 5 cubics in 5 unknowns", 3 ** 5, "Bezout's theorem", lambda: dense_text(5, 3), None, 0),
    ("dense8_2", "dense system, 8 quadrics in 8 unknowns", 2 ** 8, "Bezout's theorem", lambda: dense_text(8, 2), None, 0),
]

#: Alt's problem is above TRACE_MAX and takes minutes: not rerun here; its committed run (docs/count.md) is kept in the
#: meta file as a reference, never as a computed row.
ALT_REFERENCE = {
    "file": "examples/alt9.sys", "start": "examples/alt9.start.json", "published": 8652,
    "source": "Alt 1923; Wampler, Morgan, Sommese 1992",
    "committed_run": "docs/count.md, 'Alt's problem: 8652 from a given start' (2026-12-02): 8652 proven, both seeds' "
                     "graphs closed (61,002 and 60,974 paths), equal as sets, 64 of 64 loops; scope lower bound (no trace "
                     "test above 500 solutions); 208 s of CPU, 210 s wall at load 4-6",
}

COLUMNS = ["problem", "file", "published", "source", "unknowns", "parameters", "start", "solutions", "proven", "found",
           "graphs", "seed_sets", "trace_test", "trace_residual", "witnesses", "trace_note", "scope", "evidence", "agrees"]


def paths(stem: str) -> tuple[str, str]:
    return os.path.join(EXAMPLES, f"{stem}.sys"), os.path.join(EXAMPLES, f"{stem}.start.json")


def start_json(q: np.ndarray, x: np.ndarray) -> str:
    pair = {"parameters": [[float(z.real), float(z.imag)] for z in q], "root": [[float(z.real), float(z.imag)] for z in x]}
    return json.dumps(pair, indent=1) + "\n"


def write_examples() -> None:
    """Rewrite the builders' system files and start pairs (each pair checked against its system first)."""
    for stem, _, _, _, build, draw, seed in PROBLEMS:
        sys_path, start_path = paths(stem)
        if build is not None:
            with open(sys_path, "w", encoding="utf-8", newline="\n") as fh:
                fh.write(build())
        if callable(draw):
            q, x = draw(np.random.default_rng(seed))
            system = parse(build(), f"{stem}.sys")
            r = residual(system, q, x)
            if r > 1e-10:
                raise SystemExit(f"{stem}: the drawn start pair does not solve the system (residual {r:.1e})")
            with open(start_path, "w", encoding="utf-8", newline="\n") as fh:
                fh.write(start_json(q, x))
            print(f"wrote {os.path.relpath(start_path, ROOT)} (largest residual {r:.1e})")


def run_row(stem: str, threads: int | None = None) -> tuple[dict, dict]:
    """One row: `count` with the default seeds and --trace (sets up to TRACE_MAX) on examples/STEM.sys; its times."""
    from solvers import count as counting  # noqa: PLC0415
    from solvers.cli.systems import _read_start  # noqa: PLC0415

    _, problem, published, source, _, draw, _ = next(p for p in PROBLEMS if p[0] == stem)
    sys_path, start_path = paths(stem)
    with open(sys_path, encoding="utf-8") as fh:
        system = parse(fh.read(), f"{stem}.sys")
    start = None
    if draw is not None:
        start = _read_start(start_path, system)
        r = residual(system, *start)
        if r > 1e-10:
            raise SystemExit(f"{start_path}: not a start pair of {stem}.sys (residual {r:.1e})")
    t0, c0 = time.perf_counter(), os.times()
    result = counting.count(system, counting.CountOptions(seeds=(0, 1), trace=published <= TRACE_MAX), start=start)
    c1 = os.times()
    cpu = (c1.user - c0.user) + (c1.system - c0.system) + (c1.children_user - c0.children_user) \
        + (c1.children_system - c0.children_system)
    t = result.trace or {}
    res = t.get("residual")
    row = {"problem": problem, "file": f"examples/{stem}.sys", "published": published, "source": source,
           "unknowns": result.unknowns, "parameters": result.parameters,
           "start": f"examples/{stem}.start.json" if start is not None else "drawn by count",
           "solutions": result.count, "proven": result.proven, "found": result.found,
           "graphs": "; ".join(s.graph for s in result.seeds),
           "seed_sets": "; ".join(s.carried for s in result.seeds[1:]),
           "trace_test": t.get("status", "not run"),
           "trace_residual": "" if res is None or res != res else f"{res:.0e}",
           "witnesses": t.get("witnesses", ""), "trace_note": t.get("why", ""), "scope": result.scope, "evidence": result.evidence}
    row["agrees"] = "yes" if (result.count == result.proven == published and result.complete
                              and (published > TRACE_MAX or t.get("status") == "passed")) else "no"
    times = {"wall_seconds": round(time.perf_counter() - t0, 1), "cpu_seconds": round(cpu, 1),
             "trace_residual": res, "trace_rounding_level": t.get("floor"), "notes": list(result.notes)}
    return row, times


def write_tables(rows: list[dict], meta: dict) -> None:
    with open(os.path.join(TABLES, "count_literature.csv"), "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    lines = ["<!-- Regenerate: python scripts/count_literature.py; times in count_literature.meta.json -->", "",
             "**`count` on problems from the literature** (`count FILE [--start FILE.start.json] --trace`, the default "
             "seeds 0 1, every solution proven by Krawczyk's test; agrees: the count equals the published one, all "
             "proven, complete for the whole solution set, trace test passed)", "",
             "| problem | file | published | source | count | proven | graphs | seed sets | trace test | residual "
             "| witnesses | scope | agrees |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r['problem']} | `{r['file']}` | {r['published']} | {r['source']} | {r['solutions']} | {r['proven']} "
              f"| {r['graphs']} | {r['seed_sets']} | {r['trace_test']} | {r['trace_residual']} | {r['witnesses']} "
              f"| {r['scope']} | {r['agrees']} |" for r in rows]
    lines += ["", "Evidence, in `count`'s words:", ""]
    lines += [f"- `{r['file']}`: {r['evidence']}" + (f" (trace test: {r['trace_note']})" if r["trace_note"] else "")
              for r in rows]
    with open(os.path.join(TABLES, "count_literature.md"), "w", encoding="utf-8", newline="\n") as fh:
        fh.write("\n".join(lines) + "\n")
    with open(os.path.join(TABLES, "count_literature.meta.json"), "w", encoding="utf-8", newline="\n") as fh:
        json.dump(meta, fh, indent=1)
        fh.write("\n")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=2, metavar="N")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="these rows only (printed, no table written)")
    parser.add_argument("--write-examples", action="store_true", help="rewrite the system files and start pairs, then stop")
    args = parser.parse_args(argv)
    if args.write_examples:
        write_examples()
        return 0
    from solvers.continuation import tape_kernel  # noqa: PLC0415

    tape_kernel.set_threads(args.threads)
    rows, times = [], {}
    for stem, *_ in PROBLEMS:
        if args.only and stem not in args.only:
            continue
        row, times[stem] = run_row(stem)
        rows.append(row)
        print(f"{stem}: {row['solutions']} (published {row['published']}); trace {row['trace_test']} "
              f"{row['trace_residual']}; {row['scope']}; agrees {row['agrees']}; {times[stem]['cpu_seconds']} s CPU, "
              f"{times[stem]['wall_seconds']} s wall", flush=True)
    if args.only:
        return 0 if all(r["agrees"] == "yes" for r in rows) else 1
    meta = {"script": "scripts/count_literature.py", "threads": args.threads, "load_average": list(os.getloadavg()),
            "cpu_seconds": "os.times() around each count: this process's threads and the child processes it has waited "
                           "for (the proofs' pools); the first run of a system also compiles its programs",
            "date": time.strftime("%Y-%m-%d", time.gmtime()), "rows": times, "reference_not_rerun": ALT_REFERENCE}
    write_tables(rows, meta)
    return 0 if all(r["agrees"] == "yes" for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
