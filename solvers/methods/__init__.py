"""Solving methods, one module each, offline build over GF(p) and online kernel side by side.

:mod:`.spec` (the interface of the GF(p)-built specs), :mod:`.pencil` (eigenvalue pencil, 6r4s),
:mod:`.homotopy` with the compiled path tracker :mod:`.tracker` (parameter homotopy, the general
method). :mod:`solvers.generate` runs them behind one interface; they import neither it nor each
other's builds (spec <- pencil; tracker <- homotopy), so the import graph has no circle.
"""
