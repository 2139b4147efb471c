"""Numerics: generated minimal solvers, recovery, refinement and the calibration pipeline.

``from solvers import calibrate`` gives the user's function (:func:`solvers.calibration.calibrate`);
the pipeline's other names are imported from the package ``solvers.calibration`` (e.g. ``from
solvers.calibration import CalibrationOptions``).

The calibration pipeline (scipy and the solvers) is imported on first use, not with the package:
``tdoa-workbench degree`` lives in ``solvers.cli`` and needs none of it.
"""
__all__ = ["CalibrationOptions", "CalibrationResult", "calibrate"]


def __getattr__(name: str):
    if name not in __all__:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(f"{__name__}.calibration"), name)
