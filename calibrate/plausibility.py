"""Before any fitting: values a micro ball bearing cannot see, and the unit slips that produce them.

:func:`plausibility_findings` reads the parsed measurements (SI values, column by column) and
returns what looks wrong, each finding naming the column, the range of its values, the likely cause
and whether it is an ``error`` (the calibration is refused: a 422 in the service, naming the column)
or a ``warning`` (the calibration runs and the report says it). :func:`check_plausible` raises the
errors as one :class:`calibrate.data.DataError` and returns the warnings.

The rules (decided once, in :mod:`physics.slips`, for every door; listed here for the upload):

======================  ===============================================  ==========  ==================
column                  rule                                             severity    likely cause
======================  ===============================================  ==========  ==================
``speed_m_s``           largest value above 10 m/s                       error       mm/s (or mm/min)
``load_N``              largest value above 1 N                          error       mN (or gram-force)
``ball_diameter_m``     largest value above 1 cm                         error       mm (or um)
humidity (fraction)     a value above 1 or below 0                       error       percent
humidity (percent)      a value above 100 or below 0                     error       not percent
temperature (degC)      a value at or below -273.15 degC                 error       impossible
temperature (degC)      a value above 200 degC                           error       kelvin
temperature (K)         a value below 150 K                              error       degC
``mu_measured``         a value above 1                                  warning     percent, or a force
``mu_measured_std``     larger than ``mu_measured`` on some row          warning     percent of mu
======================  ===============================================  ==========  ==================

The bounds are those of the micro linear ball bearings this library models (Olaru et al. 2005:
balls of a few tenths of a millimetre, loads of millinewtons, speeds of 0 to 150 mm/s), with a
margin of about two orders of magnitude: a value beyond them is not a bold design but a different
machine, or a unit slip. Humidity and temperature columns, their units and plausible ranges are the
ones the effects declare (:data:`physics.drivers.HUMIDITY`, :data:`physics.drivers.TEMPERATURE`:
``humid``/``rh``, ``pct``/``percent`` for percent; ``temp``, ``k``/``kelvin`` for kelvin). The physics'
own validation still applies to every physics column first (a negative load is refused by
:func:`calibrate.data.parse_rows`).

A column sent under a header that states its unit (``speed [mm/s]``, ``relative humidity [%]``,
``temperature [degC]``, ``temp [K]``) is judged in that unit, as a key stating it is at every other door
(:func:`physics.slips.read_slip`): ``temp [degC]`` at -200 is a cold test (no kelvin slip), at 250 it
looks like kelvin; the finding says the header and values as sent and advises in the header's own
spelling (``send them as 'temp [K]'``); a physics input beyond its limit says its name states the unit,
so the values are what to check.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from microbearing import physics
from microbearing.physics.columns import (
    SLIP_LIMITS,
    ColumnError,
    counted_from_zero,
    physical_range,
    read_name,
    unit_of,
)
from microbearing.physics.drivers import HUMIDITY, TEMPERATURE
from microbearing.physics.slips import (
    humidity_rows,
    humidity_slip,
    physics_slip,
    read_slip,
    slipped_rows,
    temperature_slip,
)

from .data import MU_MEASURED, MU_MEASURED_STD, DataError, Dataset

__all__ = ["LIMITS", "Finding", "check_plausible", "plausibility_findings"]

#: Largest value of a physics column a micro ball bearing plausibly sees, with the likely unit slip and
#: its factor to SI (:data:`physics.columns.SLIP_LIMITS`, the one rule of every door). [unit of the column]
LIMITS: dict[str, tuple[float, str, float]] = SLIP_LIMITS
#: Largest measured friction coefficient before a warning. [1]
MU_WARNING = 1.0


@dataclass(frozen=True)
class Finding:
    """One implausible column.

    Attributes
    ----------
    column : str
        The column's name.
    severity : {"error", "warning"}
        Whether the calibration is refused.
    message : str
        The values' range, the rule and the likely cause, in words.
    row : int or None
        The first row (1-based) of a physics input's slip of some rows (:func:`physics.slips.slipped_rows`),
        where the error points (one of those rows, not the column's first); None for the column as a whole.
    """

    column: str
    severity: str
    message: str
    row: int | None = None


def _span(values: np.ndarray) -> str:
    return f"{float(np.min(values)):.4g} to {float(np.max(values)):.4g}"


def _outside_physical_range(name: str, values: np.ndarray, reading: Any = None) -> Finding | None:
    """A condition column outside its quantity's physical range (a time or count run below zero), said in
    the unit of the header (``reading``: how it was read, or None when as sent)."""
    low, high = physical_range(name)
    if (low is None or float(np.min(values)) >= low) and (high is None or float(np.max(values)) <= high):
        return None
    bounds = f"[{'-inf' if low is None else f'{low:g}'}, {'inf' if high is None else f'{high:g}'}]"
    counted = " (it is counted from zero, at the start of the run)" if counted_from_zero(name) else ""
    said = f"{name} runs {_span(values)} [{unit_of(name) or '1'}]"
    if reading is not None:
        said = f"{reading.sent} runs {_span(reading.sent_value(values))} {reading.sent_unit} ({said})"
    return Finding(name, "error", f"{said}, outside its physical range {bounds}{counted}")


def _sent_slip(dataset: Dataset, name: str, values: np.ndarray) -> tuple[bool, str | None]:
    """A column sent under another name (``temp [degC]``, ``speed [mm/s]``, ``RH [1]``) judged as sent, in the
    unit its header states (:func:`physics.slips.read_slip`, as every door judges a key): whether it was,
    and the slip in words (None: none)."""
    header = dataset.headers.get(name)
    try:
        reading = None if header is None else read_name(header)
    except ColumnError:  # a header stored by another version: judged by its name
        reading = None
    if reading is None or reading.name != name:
        return False, None
    return True, read_slip(reading, reading.sent_value(values))


def plausibility_findings(dataset: Dataset) -> list[Finding]:
    """Every implausible column of parsed measurements, by the rules of this module.

    Parameters
    ----------
    dataset : Dataset
        Parsed measurements (physics columns in SI units, conditions in the data's units).

    Returns
    -------
    list of Finding
        Errors and warnings, in column order.

    Examples
    --------
    >>> from microbearing.calibrate import parse_rows
    >>> rows = [{"balls": 4, "load_N": 0.01, "speed_m_s": v, "mu_measured": 0.01} for v in (5.0, 300.0)]
    >>> print(plausibility_findings(parse_rows(rows))[0].message)  # doctest: +NORMALIZE_WHITESPACE
    speed_m_s runs 5 to 300 m/s, beyond the 10 m/s a micro ball bearing sees: values look like mm/s
    (times 0.001: 0.005 to 0.3 m/s)
    """
    found: list[Finding] = []
    columns: Mapping[str, np.ndarray] = dataset.columns()
    for name, values in columns.items():
        if values.dtype == bool or values.size == 0:
            continue
        condition = name not in physics.PARAMETERS
        if name in LIMITS or (condition and (HUMIDITY.matches(name) or TEMPERATURE.matches(name))):
            # the one unit-slip rule of every door (physics.slips), in the unit a header states
            judged, message = _sent_slip(dataset, name, values)
            row = None
            if not judged and name in LIMITS:
                message = physics_slip(name, values)
                some = slipped_rows(name, values)  # a slip of some rows: the error points at the first
                row = None if some is None else int(some[0]) + 1
            elif not judged:
                message = (humidity_slip if HUMIDITY.matches(name) else temperature_slip)(name, values)
                some = humidity_rows(name, values) if HUMIDITY.matches(name) else None
                row = None if some is None or message is None else int(some[0]) + 1
            found += [] if message is None else [Finding(name, "error", message, row)]
        elif condition:  # said in the header's unit itself: no plausible range
            finding = _outside_physical_range(name, values, dataset.sent_reading(name))
            found += [] if finding is None else [finding]
    mu = dataset.mu_measured
    if mu.size and float(np.max(mu)) > MU_WARNING:
        count = int(np.sum(mu > MU_WARNING))
        found.append(Finding(MU_MEASURED, "warning",
                             f"{MU_MEASURED} runs {_span(mu)}, above {MU_WARNING:g} on {count} row(s): a "
                             f"rolling micro bearing's friction coefficient is far below 1; is it in "
                             f"percent, or a force?"))
    std = dataset.mu_measured_std
    if std is not None and np.any(std > mu):
        count = int(np.sum(std > mu))
        found.append(Finding(MU_MEASURED_STD, "warning",
                             f"{MU_MEASURED_STD} exceeds {MU_MEASURED} on {count} row(s): is it a percentage "
                             f"of mu rather than a standard deviation [1]?"))
    return found


def check_plausible(dataset: Dataset) -> list[str]:
    """Refuse implausible measurements, before any fitting; return the warnings.

    Parameters
    ----------
    dataset : Dataset
        Parsed measurements.

    Returns
    -------
    list of str
        The warnings of :func:`plausibility_findings`, each starting with its column's name.

    Raises
    ------
    calibrate.data.DataError
        One ``{"row", "column", "message"}`` item per column in error (``row`` 1-based, or None: the
        column as a whole).
    """
    found = plausibility_findings(dataset)
    errors = [{"row": f.row, "column": f.column, "message": f.message}
              for f in found if f.severity == "error"]
    if errors:
        raise DataError(errors)
    return [f.message for f in found if f.severity == "warning"]
