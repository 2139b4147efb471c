"""The Gröbner basis engine over GF(p) (and over Q through several primes); imports nothing of
:mod:`analysis.formulations` or :mod:`analysis.sweeps`.

Modules: :mod:`~analysis.engine.orderings`, :mod:`~analysis.engine.primes`, :mod:`~analysis.engine.ring`
(rings and polynomials), :mod:`~analysis.engine.f4` (F4, with :mod:`~analysis.engine.linalg`,
:mod:`~analysis.engine.native` and :mod:`~analysis.engine.sparse_kernels` for its matrices),
:mod:`~analysis.engine.quotient` (standard monomials, action matrices, saturation, FGLM),
:mod:`~analysis.engine.homogenize` (lex and block orders of positive-dimensional ideals),
:mod:`~analysis.engine.degree` (the degree checked across primes), :mod:`~analysis.engine.modular`
(characteristic 0), :mod:`~analysis.engine.io` and :mod:`~analysis.engine.polytext` (systems as text),
:mod:`~analysis.engine.msolve` (msolve as an external program), :mod:`~analysis.engine.systems`
(katsura, cyclic, dense random).

The names most users need are re-exported here::

    from analysis.engine import Ring, groebner, standard_monomials, action_matrix
"""
from .degree import DegreeReport, PrimeDisagreement, analyse
from .f4 import F4Options, GroebnerResult, groebner
from .io import InputError, read_system
from .quotient import (NotZeroDimensional, action_matrix, count_standard_monomials, degree, dimension,
                       is_zero_dimensional, normal_form, saturate, saturated_degree, standard_monomials)
from .ring import Poly, Ring

__all__ = ["DegreeReport", "F4Options", "GroebnerResult", "InputError", "NotZeroDimensional", "Poly",
           "PrimeDisagreement", "Ring", "action_matrix", "analyse", "count_standard_monomials", "degree",
           "dimension", "groebner", "is_zero_dimensional", "normal_form", "read_system", "saturate",
           "saturated_degree", "standard_monomials"]
