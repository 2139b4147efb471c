"""Complexity sweeps and the tables built from them; imports :mod:`analysis.engine` and
:mod:`analysis.formulations`.

Modules: :mod:`~analysis.sweeps.complexity` (the degree of a formulation on several consistent instances
and primes, cached; sweeps), :mod:`~analysis.sweeps.executors` (process pool or Dask cluster),
:mod:`~analysis.sweeps.tables` (Tables 2 and 3), :mod:`~analysis.sweeps.search` (the exhaustive search),
:mod:`~analysis.sweeps.cell_degrees` (TOA and 3D cells), :mod:`~analysis.sweeps.minimal` (counts of the
positions formulations), :mod:`~analysis.sweeps.benchmarks` (seeded systems), and the helpers
:mod:`~analysis.sweeps.paths` (data, caches, outputs), :mod:`~analysis.sweeps.progress` and
:mod:`~analysis.sweeps.provenance`.

Nothing is re-exported here: the sweep modules import pandas and sympy, and the helpers are imported
by the solvers, which should not pay for those.
"""
