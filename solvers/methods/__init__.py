"""Solving methods, one module each, offline build over GF(p) and online kernel side by side.

:mod:`.spec` (the interface of the GF(p)-built specs), :mod:`.pencil` (eigenvalue pencil, 6r4s),
:mod:`.homotopy` (parameter homotopy, the general method; its path tracking, monodromy and trace test
are the package :mod:`solvers.continuation`, which imports no method). :mod:`solvers.generate` runs
them behind one interface; they import neither it nor each other's builds (spec <- pencil;
continuation <- homotopy), so the import graph has no circle.
"""
