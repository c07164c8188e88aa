"""Calibrate the friction model against measured data and name the effect it misses.

:func:`calibrate` runs the whole loop: parse and check the measurements
(:mod:`calibrate.data`), fit the declared parameters on log μ
(:mod:`calibrate.fit`), search the residual for a missing effect
(:mod:`calibrate.discover`), compare with a Gaussian-process discrepancy
(:mod:`calibrate.discrepancy`) and report the held-out error before and after
(:mod:`calibrate.report`), the after-error by nested cross-validation of the
search (:func:`calibrate.discover.nested_cross_validate`). The calibrated model is plain JSON data that
:class:`CalibratedModel` turns back into a ``mu_model(points)`` callable.
"""

from .data import MU_MEASURED, MU_MEASURED_STD, DataError, Dataset, parse_assignments, parse_csv, parse_rows
from .model import CalibratedModel
from .report import CalibrationReport, calibrate, check_request

__all__ = [
    "calibrate",
    "check_request",
    "parse_assignments",
    "CalibrationReport",
    "CalibratedModel",
    "Dataset",
    "DataError",
    "parse_csv",
    "parse_rows",
    "MU_MEASURED",
    "MU_MEASURED_STD",
]
