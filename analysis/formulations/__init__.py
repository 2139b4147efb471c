"""The polynomial problems: TDOA and TOA self-calibration in 2D and 3D, and user-given systems.

Modules: :mod:`~analysis.formulations.base` (configurations, equation names, formulations, instances),
:mod:`~analysis.formulations.kd` (one writer of the equations of every model, dimension and
parametrization), :mod:`~analysis.formulations.tdoa` (the paper's 2D TDOA formulations, samplers with a
known root, relabeling symmetry, and the front end for the other models),
:mod:`~analysis.formulations.positions` (coordinates as unknowns), :mod:`~analysis.formulations.parametric`
(equations whose coefficients are polynomials in parameters, from text or from a formulation).
Imports :mod:`analysis.engine`, nothing of :mod:`analysis.sweeps`.

The public names of :mod:`~analysis.formulations.tdoa` are re-exported here::

    from analysis.formulations import Formulation, TDOAConfig, sample_gf_instance
"""
from .tdoa import (DIMENSIONS, MODELS, PARAMETRIZATIONS, BadPrime, EquationCounts, Formulation, InconsistentSample, Instance, Relabeling, SamplingFailed, TDOAConfig, as_formulation, canonical_form, check_root, coefficient_expressions, data_symbols, enumerate_formulations, equation_names, evaluate_gf, evaluate_real, gf_equations, require_planar_tdoa, is_quadratic_residue, parse_equations, real_equations, sample_gf_instance, sample_real_instance, sqrt_mod, symbolic_equations, unknown_symbols)

__all__ = ['DIMENSIONS', 'MODELS', 'PARAMETRIZATIONS', 'BadPrime', 'EquationCounts', 'Formulation', 'InconsistentSample', 'Instance', 'Relabeling', 'SamplingFailed', 'TDOAConfig', 'as_formulation', 'canonical_form', 'check_root', 'coefficient_expressions', 'data_symbols', 'enumerate_formulations', 'equation_names', 'evaluate_gf', 'evaluate_real', 'gf_equations', 'require_planar_tdoa', 'is_quadratic_residue', 'parse_equations', 'real_equations', 'sample_gf_instance', 'sample_real_instance', 'sqrt_mod', 'symbolic_equations', 'unknown_symbols']
