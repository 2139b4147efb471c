"""Exact algebra for the workbench, in three layers (each imports only the ones above it):

* :mod:`analysis.engine` - the Gröbner basis engine over GF(p): rings and orders, the F4 algorithm and
  its compiled kernels, the quotient ring (standard monomials, action matrices, saturation), degrees
  checked across primes, characteristic 0 by several primes, polynomial text in and out, msolve as an
  external reference.
* :mod:`analysis.formulations` - the polynomial problems: one builder for TDOA and TOA equations in 2D
  and 3D (compaction unknowns), the positions formulations, user-given parametric systems.
* :mod:`analysis.sweeps` - complexity sweeps over formulations (process pool or Dask), Tables 2 and 3,
  the exhaustive search, minimal-problem counts, and the shared paths, progress and provenance helpers.

This module imports nothing, so ``import analysis.engine.ring`` costs only what it uses.
"""
