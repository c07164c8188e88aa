"""Calibrate the friction model against measured data and name the effects it misses.

:func:`calibrate` runs a one-direction pipeline, one module a step: parse and
check the measurements (:mod:`calibrate.data`); propose candidate terms, named
effects and drifts of the model's own parameters (:mod:`calibrate.candidates`);
fit robustly on log μ (:mod:`calibrate.fit`); choose terms by forward selection
and judge the whole procedure by nested cross-validation (:mod:`calibrate.select`);
say how sure the result is (:mod:`calibrate.uncertainty`), what rival terms
that fit about as well would predict off the data (:mod:`calibrate.rivals`) and
what the data cannot decide (:mod:`calibrate.decidability`); draw it
(:mod:`calibrate.plots`); report (:mod:`calibrate.report`). Before any fitting,
values a micro bearing cannot see (unit slips) are refused
(:mod:`calibrate.plausibility`). The calibrated model
is plain JSON data that :class:`CalibratedModel` turns back into a callable
whose :meth:`CalibratedModel.predict` gives μ with its 95 % interval and a
domain check.
"""

from .data import MU_MEASURED, MU_MEASURED_STD, DataError, Dataset, parse_assignments, parse_csv, parse_rows
from .model import CalibratedModel, Prediction
from .report import CalibrationReport, calibrate, check_request, default_folds
from .tabular import Intake, read_csv, read_rows

__all__ = [
    "calibrate",
    "check_request",
    "default_folds",
    "parse_assignments",
    "CalibrationReport",
    "CalibratedModel",
    "Prediction",
    "Dataset",
    "DataError",
    "parse_csv",
    "parse_rows",
    "Intake",
    "read_csv",
    "read_rows",
    "MU_MEASURED",
    "MU_MEASURED_STD",
]
