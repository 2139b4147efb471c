"""Numerics: generated minimal solvers, recovery, refinement and the calibration pipeline.

``from solvers import calibrate`` gives the user's function (:func:`solvers.calibration.calibrate`);
the pipeline's other names are imported from the package ``solvers.calibration`` (e.g. ``from
solvers.calibration import CalibrationOptions``).
"""
from .calibration import CalibrationOptions, CalibrationResult, calibrate

__all__ = ["CalibrationOptions", "CalibrationResult", "calibrate"]
