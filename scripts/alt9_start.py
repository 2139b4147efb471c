"""The start pair of Alt's problem (examples/alt9.sys): examples/alt9.start.json, one linkage and the precision
points its coupler passes through, drawn once (seed 0) and committed, so that `count --start` reads data.

The system's rotation equations g_j h_j + g_j + h_j = 0 hold no parameter, so no random point solves them for some
parameters; a linkage does. Drawn: the linkage (x, a, y, b and their independent "conjugates" xc, ac, yc, bc) and
the coupler rotations g_j at random complex values, h_j = -g_j / (1 + g_j). For each j the two dyad equations are
then two quadrics in (d_j, e_j) with the same d_j e_j term: their difference is linear, e_j in terms of d_j, and the
first becomes a quadratic in d_j (the root with +sqrt taken). Every equation is checked at the pair before it is written.

Usage: python scripts/alt9_start.py [--seed 0] [--out examples/alt9.start.json]
"""
from __future__ import annotations

import argparse
import cmath
import json
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from analysis.formulations.parametric import parse  # noqa: E402

SYSTEM = os.path.join(ROOT, "examples", "alt9.sys")
POSITIONS = 8


def dyad(z: complex, zc: complex, p: complex, pc: complex, g: complex, h: complex) -> tuple[complex, complex, complex]:
    """The dyad equation (pc - e) z g + (p - d) zc h + (pc - zc) d + (p - z) e - d e as c + alpha d + beta e - d e."""
    return pc * z * g + p * zc * h, pc - zc - zc * h, p - z - z * g


def draw(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(parameters d1, e1, .., d8, e8; root x, a, y, b, xc, ac, yc, bc, g1..g8, h1..h8) of one drawn linkage."""
    rng = np.random.default_rng(seed)
    x, a, y, b, xc, ac, yc, bc = rng.normal(size=8) + 1j * rng.normal(size=8)
    g = rng.normal(size=POSITIONS) + 1j * rng.normal(size=POSITIONS)
    h = -g / (1 + g)
    d, e = np.zeros(POSITIONS, complex), np.zeros(POSITIONS, complex)
    for j in range(POSITIONS):
        c1, a1, b1 = dyad(x, xc, a, ac, g[j], h[j])
        c2, a2, b2 = dyad(y, yc, b, bc, g[j], h[j])
        # e = u + v d from the difference; then c1 + a1 d + (b1 - d)(u + v d) = 0
        u, v = -(c1 - c2) / (b1 - b2), -(a1 - a2) / (b1 - b2)
        qa, qb, qc = -v, a1 + b1 * v - u, c1 + b1 * u
        d[j] = (-qb + cmath.sqrt(qb * qb - 4 * qa * qc)) / (2 * qa)  # closed form: the same bits on any machine
        e[j] = u + v * d[j]
    q = np.ravel(np.column_stack([d, e]))
    root = np.concatenate([[x, a, y, b, xc, ac, yc, bc], g, h])
    return q, root


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=os.path.join(ROOT, "examples", "alt9.start.json"))
    args = parser.parse_args(argv)
    q, root = draw(args.seed)
    with open(SYSTEM, encoding="utf-8") as fh:
        system = parse(fh.read(), "alt9.sys")
    values = dict(zip(system.q_symbols + system.x_symbols, [complex(z) for z in np.concatenate([q, root])]))
    residual = max(abs(complex(f.evalf(subs=values))) for f in system.exprs)
    if residual > 1e-10:
        raise SystemExit(f"alt9_start: the drawn pair does not solve the system (residual {residual:.1e})")
    pair = {"parameters": [[float(z.real), float(z.imag)] for z in q],
            "root": [[float(z.real), float(z.imag)] for z in root]}
    with open(args.out, "w", encoding="utf-8") as fh:
        json.dump(pair, fh, indent=1)
        fh.write("\n")
    print(f"wrote {args.out} (largest residual {residual:.1e})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
