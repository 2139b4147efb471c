"""Numerics: generated minimal solvers, recovery, refinement and the calibration pipeline.

``from solvers import calibrate`` gives the user's function (:func:`solvers.calibrate.calibrate`);
the module's other names are imported from ``solvers.calibrate`` (e.g. ``from solvers.calibrate
import CalibrationOptions``).
"""
from .calibration import CalibrationOptions, CalibrationResult, calibrate

__all__ = ["CalibrationOptions", "CalibrationResult", "calibrate"]
