"""Numerical continuation: path tracking, monodromy and the trace test, the numerical counterpart of
:mod:`analysis.engine`.

Where :mod:`analysis.engine` answers "how many solutions?" exactly over GF(p), this package follows the
solutions of a parametric system over C: it imports no solving method (:mod:`solvers.methods`) and nothing
of :mod:`solvers.generate`; the solver methods (the parameter homotopy, :mod:`solvers.methods.homotopy`)
and root counts import it, so the import graph has no circle.

Modules, from the kernels up:

* :mod:`~solvers.continuation.scaling`: where exact coefficients become floats (an equation beyond 2^+-500
  scaled by a power of two first), for the coefficient code here and for ``solve``'s Newton steps;
* :mod:`~solvers.continuation.tracker`: the compiled predictor-corrector on an expanded monomial system
  (numba), :class:`~solvers.continuation.tracker.TrackerOptions`;
* :mod:`~solvers.continuation.slp`: straight-line programs of a system and of its homotopy (tapes);
* :mod:`~solvers.continuation.tape_kernel`, :mod:`~solvers.continuation.tape_jit` and
  :mod:`~solvers.continuation.tape_native`: the batched tracker on those tapes (its Python calls, threads and
  batches; everything numba compiles; the tapes written out as C);
* :mod:`~solvers.continuation.tracking`: :class:`~solvers.continuation.tracking.HomotopySolver`, which
  tracks a complete root set from start parameters to targets (retracks, detours, pooled routes), and
  the structure and coefficient code of a parametric system;
* :mod:`~solvers.continuation.monodromy`: root sets grown by monodromy loops (to a certified count, or
  without one, with checkpoints);
* :mod:`~solvers.continuation.trace`: the trace test, whether a root set is complete;
* :mod:`~solvers.continuation.dask_tracks`: a monodromy loop's paths tracked on a Dask cluster.
"""
