"""Numerics: generated minimal solvers, recovery, refinement and the calibration pipeline.

``from solvers import calibrate`` gives the user's function (:func:`solvers.calibrate.calibrate`);
the module's other names are imported from ``solvers.calibrate`` (e.g. ``from solvers.calibrate
import CalibrationOptions``).

The calibration pipeline (scipy.sparse and the solvers) is imported on first use, not with the
package: ``tdoa-workbench degree`` lives in ``solvers.cli`` and needs none of it. The name
``calibrate`` stays the function even after the submodule of the same name is imported.
"""
import sys
import types

__all__ = ["CalibrationOptions", "CalibrationResult", "calibrate"]


def __getattr__(name: str):
    if name not in __all__:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib

    module = importlib.import_module(f"{__name__}.calibrate")  # binds "calibrate" through _Package.__setattr__
    return getattr(module, name)


class _Package(types.ModuleType):
    """The package: importing ``solvers.calibrate`` binds the package's name ``calibrate`` to the
    function of that name, as the eager ``from .calibrate import calibrate`` of the package did."""

    def __setattr__(self, name: str, value) -> None:
        if name == "calibrate" and isinstance(value, types.ModuleType):
            value = value.calibrate
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
