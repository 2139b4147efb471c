"""The README's tour pictures, one per use: reproduce, explore, generate, calibrate.

    python scripts/make_docs_figures.py [--out DIR]

writes ``docs/figures/tour-{reproduce,explore,generate,calibrate}.png`` (default DIR: docs/figures of the
repository). Every picture is computed from seeded inputs or committed tables, and saved without dates
(PNG metadata: matplotlib's version only), so a rerun on the same versions writes the same bytes
(``tests/test_docs.py`` checks it, marked slow). About 15 s.
"""
from __future__ import annotations

import argparse
import io
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # this checkout's packages, not whichever one is installed
FIGURES = REPO / "docs" / "figures"
#: The explore picture's formulations: Table 2's 9r/3s and 6r/3s rows (degrees 75 and 181).
EXPLORE = ("9r3s:C2-C9", "6r3s:A,B2,B3,C2-C6")


def _finish(fig, ax, xlabel: str, ylabel: str, title: str, path: Path) -> Path:
    """Label the axes, add the legend and save."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def _save(fig, path: Path) -> Path:
    """Write ``fig`` as PNG at 100 dpi; the file is rewritten only when its bytes change."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)  # PNG metadata: matplotlib's version only, no date
    plt.close(fig)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_bytes() != buffer.getvalue():
        path.write_bytes(buffer.getvalue())
    return path


def reproduce(out: Path) -> Path:
    """Fig. 1 of the paper as `reproduce` wrote it (tables/figures/fig1_histograms.csv): 9r/3s position
    errors after LM from the solver's start and from a random one."""
    bins = pd.read_csv(REPO / "tables" / "figures" / "fig1_histograms.csv")
    fig, ax = plt.subplots(figsize=(6.4, 3.2))
    for init, color in (("solver", "#1f77b4"), ("random", "#d62728")):
        rows = bins[(bins.config == "9r3s") & (bins.init == init) & (bins.quantity == "position")]
        ax.stairs(rows["count"].to_numpy(), np.append(rows.bin_lo.to_numpy(), rows.bin_hi.iloc[-1]),
                  fill=True, alpha=0.6, color=color, label=f"LM from {init} start")
    return _finish(fig, ax, "log10 position error (9r/3s, 1000 noise-free trials)", "trials",
                   "reproduce: the paper's Fig. 1 (left), recomputed", out / "tour-reproduce.png")


def _rounds(label: str):
    """F4 statistics of one seeded GF(65521) instance of a TDOA formulation (known root checked)."""
    from analysis.formulations import tdoa as tf
    from analysis.engine.f4 import groebner
    from analysis.engine.ring import Ring

    formulation = tf.as_formulation(label)
    config = formulation.config
    instance = tf.sample_gf_instance(config, 65521, 0)
    tf.check_root(formulation, instance)
    ring = Ring(config.unknowns, 65521)
    return groebner([ring.from_terms(eq) for eq in tf.gf_equations(formulation, instance, 65521)])


def explore(out: Path) -> Path:
    """Matrix sizes of the F4 rounds that give Table 2's degrees 75 (9r/3s) and 181 (6r/3s)."""
    from analysis.engine.quotient import standard_monomials

    fig, ax = plt.subplots(figsize=(6.4, 3.2))
    for label, marker in zip(EXPLORE, "os"):
        gb = _rounds(label)
        cells = [r.rows * r.cols for r in gb.rounds]
        ax.plot(range(1, len(cells) + 1), cells, marker=marker,
                label=f"{label}: degree {len(standard_monomials(gb))}, {len(gb.rounds)} rounds")
    ax.set_yscale("log")
    return _finish(fig, ax, "F4 round", "matrix rows x columns", "explore: the Groebner engine's rounds behind a degree",
                   out / "tour-explore.png")


def generate(out: Path) -> Path:
    """The committed 6r/4s eigenvalue-pencil solver on a seeded network: its 22 candidate offsets o1 in
    the complex plane, the true one marked."""
    from solvers.generated import tdoa_6r4s_pencil37 as solver
    from solvers.synthetic import random_network, true_root

    net = random_network(6, 4, np.random.default_rng(0))
    roots = solver.solve(net.measurements())
    o1 = roots[:, solver.UNKNOWNS.index("o1")]
    fig, ax = plt.subplots(figsize=(6.4, 3.2))
    ax.plot(o1.real, o1.imag, "o", ms=5, color="#7f7f7f", label=f"{len(o1)} candidate roots")
    truth = true_root(net)[2][0]
    gap = float(np.min(np.abs(o1 - truth)))
    # the gap is at rounding level, and its printed digits depend on the CPU's BLAS kernels (AVX2 and
    # AVX-512 OpenBLAS print 3e-12 and 4e-12): the legend states a bound, so the picture's bytes do not
    near = "a candidate within 1e-9 of it" if gap <= 1e-9 else f"the nearest candidate {gap:.0e} from it"
    ax.plot([truth], [0.0], "*", ms=14, color="#d62728", label=f"the true o1 ({near})")
    return _finish(fig, ax, "Re o1", "Im o1", "generate: solver tdoa_6r4s_pencil37 on a 6r/4s network",
                   out / "tour-generate.png")


def calibrate(out: Path) -> Path:
    """``tdoa-workbench calibrate examples/network_10r8s.csv --sigma 0.01 --units m --plot ...``."""
    from solvers import calibrate as run
    from solvers.calibrate_io import plot_calibration, read_measurements

    data = read_measurements(str(REPO / "examples" / "network_10r8s.csv"))
    result = run(data.F, sigma=0.01, seed=0)
    path = out / "tour-calibrate.png"
    out.mkdir(parents=True, exist_ok=True)
    plot_calibration(result, str(path), data, units="m")
    return path


def main(argv: list[str] | None = None) -> list[Path]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=FIGURES, help="directory of the pictures (default docs/figures)")
    args = parser.parse_args(argv)
    paths = [make(args.out) for make in (reproduce, explore, generate, calibrate)]
    for path in paths:
        print(path)
    return paths


if __name__ == "__main__":
    main()
