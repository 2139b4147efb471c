"""The ``tdoa-workbench`` command line.

Subcommands
-----------
degree     number of solutions (|B|), dimension and Gröbner basis of a system file (msolve's format or
           the sectioned one, analysis.formulations.systemfile), or of a TDOA formulation
           (``--tdoa 6r4s --equations B2,C2-C6,minors``; ``--model toa``, ``--dim 3``,
           ``--parametrization direct`` for TOA, 3D and the positions as unknowns)
tables     the complexity sweep: Tables 2 and 3 of the paper and tables/formulations.csv
generate   build a numeric solver (spec over GF(p) + module) into --out DIR and print its statistics
count      number of solutions of a parametric system beyond F4 (graph monodromy, Krawczyk proofs, seeds compared)
template-check  how many action-matrix relations single elimination templates of a formulation or of
           a system file reach over GF(p), per multiplier family and degree (solvers.feasibility)
reproduce  the main job: Tables 2, 3 and 4 and Figures 1 and 2, with a comparison to the paper
calibrate  calibrate a network from a CSV of measurements or a recording (gaps, outliers; solvers.calibration)
tdoa       the measurement matrix of a recording: sound events, GCC-PHAT time differences (solvers.audio)

Every error a user can cause (bad file, bad prime, unknown equation...) is reported as one line on
stderr with exit status 2; a disagreement between primes exits with status 3.

The verbs live in one module per group: :mod:`solvers.cli.complexity` (degree, tables, template-check,
reproduce), :mod:`solvers.cli.systems` (solve, generate, count), :mod:`solvers.cli.networks` (calibrate,
tdoa); :mod:`solvers.cli.common` holds what they share and :mod:`solvers.cli.app` the parser and ``main``.
"""
from __future__ import annotations

import os
import sys

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # F4 matrices are small: BLAS threads only add overhead


def _set_numba_cache() -> None:
    """numba's compiled kernels go to the user cache (by default numba writes next to the module, i.e. into
    site-packages for an installed package); only before numba is imported, and never over a user's choice."""
    from analysis.sweeps.paths import cache_dir

    if "numba" not in sys.modules and "NUMBA_CACHE_DIR" not in os.environ:
        os.environ["NUMBA_CACHE_DIR"] = str(cache_dir("numba"))


_set_numba_cache()


from solvers.cli.app import build_parser, main  # noqa: E402  (after the environment is set)

__all__ = ["build_parser", "main"]
