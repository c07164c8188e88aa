"""Measured friction data: parse CSV text or JSON rows into a checked :class:`Dataset`.

Columns are physics parameter names (:data:`physics.PARAMETERS`), ``mu_measured``,
optionally ``mu_measured_std``, and any other numeric column describing the
conditions of each measurement (humidity, temperature, run, ...), which the
calibration treats as candidate drivers of the residual. Physics parameters
absent from the columns take the values fixed in the request or their defaults.

A **factor** is a condition column of labels: specimens, builds, batches, operators. A condition
column none of whose cells is a number is one (``S1``, ``S2``, ...); a column of integer codes is
one when the request declares it (``factors``). A factor is never a continuous driver of the
residual: the calibration fits how much the model varies from one group to the next
(:mod:`calibrate.groups`). A condition column with numbers in some cells and labels in others is
an error on each label, which says how to declare the column a factor.

A condition column whose every cell is an ISO 8601 date or date-time (``2026-11-28T09:30:00Z``) is
**time**, never labels: it is read as the hours elapsed since its earliest row (the session's start),
a number like any other condition, and :attr:`Dataset.clock` keeps that start. Times without a zone
are taken as UTC when some cells carry one.

Every bad cell is reported, row by row, in one :class:`DataError`; no row is
ever dropped silently. Rows are numbered from 1, the first data row (the CSV
header is not a row).
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

import numpy as np

from microbearing import physics
from microbearing.physics.columns import ColumnError, Reading, read_name
from microbearing.physics.effects import SESSION_KEYWORDS, name_matches

__all__ = ["MU_MEASURED", "MU_MEASURED_STD", "DataError", "Dataset", "factor_label", "hours_since",
           "parse_assignments", "parse_csv", "parse_rows"]

#: Column of the measured friction coefficient. [1]
MU_MEASURED = "mu_measured"
#: Optional column of its standard deviation (measurement noise). [1]
MU_MEASURED_STD = "mu_measured_std"

#: Prefixes of condition and factor columns in :meth:`Dataset.to_columns`.
_CONDITION, _FACTOR, _HEADER, _CLOCK = "condition.", "factor.", "header.", "clock."

# An ISO 8601 date, optionally with a time (seconds and fraction optional) and a zone.
_ISO_TIME = re.compile(r"\d{4}-\d{2}-\d{2}([T ]\d{2}:\d{2}(:\d{2}(\.\d+)?)?(Z|[+-]\d{2}:?\d{2})?)?")
# A date or time of day written otherwise (28.11.2026, 11/28/2026, 08:07): not read as a time, never a label
_OTHER_TIME = re.compile(r"(\d{1,2}[./]\d{1,2}[./]\d{2,4}|\d{1,2}:\d{2})")
_SECONDS_PER_HOUR = 3600.0
_TRUE = {"true", "1", "yes"}
_FALSE = {"false", "0", "no"}
_MAX_LISTED = 20


class DataError(ValueError):
    """Measured data with bad cells, rows or columns.

    Attributes
    ----------
    errors : list of dict
        One ``{"row": int | None, "column": str | None, "message": str}`` per problem; ``row`` is
        1-based (first data row), None for a problem of a whole column or of the request. A value out of
        a physics parameter's range also has ``value``, the value read (SI), for a reader that knows the
        unit it was sent in (:func:`calibrate.tabular.in_sent_units`).
    """

    def __init__(self, errors: list[dict[str, Any]]):
        self.errors = errors
        lines = [self.describe(e) for e in errors[:_MAX_LISTED]]
        more = f"\n... and {len(errors) - _MAX_LISTED} more" if len(errors) > _MAX_LISTED else ""
        super().__init__(f"{len(errors)} problem(s) in the measured data:\n" + "\n".join(lines) + more)


    @staticmethod
    def describe(error: Mapping[str, Any]) -> str:
        """One problem in words: ``"row 3, column load_N: ..."``, naming only what it has.

        Examples
        --------
        >>> DataError.describe({"row": 3, "column": None, "message": "is empty"})
        'row 3: is empty'
        >>> DataError.describe({"row": None, "column": None, "message": "CSV is empty"})
        'CSV is empty'
        """
        where = ", ".join(f"{label} {error[label]}" for label in ("row", "column")
                          if error.get(label) is not None)
        return f"{where}: {error['message']}" if where else str(error["message"])


@dataclass(frozen=True)
class Dataset:
    """Checked measurements, column by column, each column an array of ``n_points`` values.

    Attributes
    ----------
    physics_columns : dict of str to numpy.ndarray
        Physics parameters given per row, in their units (see :data:`physics.PARAMETERS`).
    conditions : dict of str to numpy.ndarray
        Other numeric columns (measurement conditions), in the data's units.
    mu_measured : numpy.ndarray
        Measured μ, > 0. [1]
    mu_measured_std : numpy.ndarray or None
        Standard deviation of each measured μ, > 0. [1]
    fixed : dict
        Physics parameters fixed for every row by the request (not columns), validated.
    factors : dict of str to numpy.ndarray
        Factor columns (group labels as strings, e.g. specimens), one label per row.
    clock : dict of str to str
        Condition columns read from ISO 8601 times (hours since the start [h]): name -> the start, ISO 8601.
    design : numpy.ndarray or None
        Design point of each row (equal inputs and conditions up to jitter, order and time aside), set
        by :func:`calibrate.measurement.inspect` when some are replicated: folds keep a point's
        replicates together. None: every row its own point.
    censored : numpy.ndarray or None
        Per row, +1 where the reading sits at a sensor's upper clip (the true μ is at least it), -1 at a
        lower clip (at most it), 0 measured (:mod:`calibrate.censored`); None: no clip.
    censor_scale : float
        Standard deviation of log μ of the censored likelihood (0: not yet known). [1]
    headers : dict of str to str
        The header cell or JSON key each column was sent under when it was sent in another unit than its
        own (``{"speed_m_s": "speed [mm/s]"}``), so that reports and plots speak the upload's units
        (:func:`physics.columns.read_name` reads the header back: ``sent_value``, ``sent_unit``).
    search_groups : numpy.ndarray or None
        Group code (0, 1, ...) of each row, set on the rows forward selection searches when a factor
        labels groups (:func:`calibrate.select.with_search_groups`): the fits the search scores then give
        each group its own level of log μ (:func:`calibrate.fit.fit`). None: one population; never stored.
    """

    physics_columns: dict[str, np.ndarray]
    conditions: dict[str, np.ndarray]
    mu_measured: np.ndarray
    mu_measured_std: np.ndarray | None
    fixed: dict[str, float | bool]
    factors: dict[str, np.ndarray] = field(default_factory=dict)
    clock: dict[str, str] = field(default_factory=dict)
    design: np.ndarray | None = field(default=None, repr=False)
    censored: np.ndarray | None = field(default=None, repr=False)
    censor_scale: float = 0.0
    headers: dict[str, str] = field(default_factory=dict)
    search_groups: np.ndarray | None = field(default=None, repr=False)

    @property
    def n_points(self) -> int:
        """Number of measurements."""
        return int(self.mu_measured.size)

    def columns(self) -> dict[str, np.ndarray]:
        """Every data column that may drive the residual: physics columns and conditions."""
        return {**self.physics_columns, **self.conditions}

    def session_columns(self) -> tuple[str, ...]:
        """Condition columns of order or time: read from ISO 8601 times (:attr:`clock`), or named so
        (``run_index``, ``time_h``, ``date``; :data:`physics.effects.SESSION_KEYWORDS`)."""
        return tuple(n for n in self.conditions if n in self.clock or name_matches(n, SESSION_KEYWORDS))

    def sent_reading(self, name: str) -> Reading | None:
        """How the column ``name`` was read from the header it was sent under (:attr:`headers`), to give its
        values back in that unit and under that header (``Reading.sent_value``, ``Reading.sent_unit``,
        ``Reading.label``: ``temperature [K]`` for ``temperature_K``, though unconverted); None when it was
        sent under its own name."""
        header = self.headers.get(name)
        try:
            reading = None if header is None else read_name(header)
        except ColumnError:  # a header stored by another version: its own unit
            return None
        return reading if reading is not None and reading.name == name and (
            reading.reading or reading.sent.strip() != name) else None

    def inputs(self) -> dict[str, Any]:
        """Keyword inputs of :func:`physics.evaluate`: fixed values and physics columns."""
        return {**self.fixed, **self.physics_columns}

    def subset(self, rows: np.ndarray) -> Dataset:
        """The measurements at the given row indices (0-based)."""
        return Dataset(
            {k: v[rows] for k, v in self.physics_columns.items()},
            {k: v[rows] for k, v in self.conditions.items()},
            self.mu_measured[rows],
            None if self.mu_measured_std is None else self.mu_measured_std[rows],
            dict(self.fixed),
            {k: v[rows] for k, v in self.factors.items()},
            dict(self.clock),
            None if self.design is None else self.design[rows],
            None if self.censored is None else self.censored[rows],
            self.censor_scale,
            dict(self.headers),
            None if self.search_groups is None else self.search_groups[rows],
        )

    def to_columns(self) -> dict[str, np.ndarray]:
        """The measurements as named columns: the one serialized form of a dataset.

        Physics columns under their names, conditions as ``condition.<name>``, factors as
        ``factor.<name>``, then :data:`MU_MEASURED` and, when given, :data:`MU_MEASURED_STD`, and each
        column's header as sent (:attr:`headers`) as ``header.<name>``, an array of that one text, and the
        start of each column read from ISO 8601 times (:attr:`clock`) as ``clock.<name>``, likewise. Stored
        as ``.npz`` arrays or JSON lists; :meth:`from_columns` reads them back. The fixed values are
        not columns (stored beside them).

        Returns
        -------
        dict of str to numpy.ndarray
            One array of ``n_points`` values per column (physics and conditions in their units, μ [1]);
            one text per header and per clock start.

        Examples
        --------
        >>> d = parse_rows([{"load_N": 0.01, "rh": 0.4, "mu_measured": 0.02}],
        ...                fixed={"balls": 4, "speed_m_s": 0.1})
        >>> sorted(d.to_columns())
        ['condition.rh', 'load_N', 'mu_measured']
        >>> again = Dataset.from_columns(d.to_columns(), d.fixed)
        >>> again.fixed == d.fixed and float(again.conditions["rh"][0])
        0.4
        """
        columns = {name: np.asarray(values) for name, values in self.physics_columns.items()}
        columns |= {_CONDITION + name: np.asarray(values, dtype=float)
                    for name, values in self.conditions.items()}
        columns |= {_FACTOR + name: np.asarray(labels, dtype=str) for name, labels in self.factors.items()}
        columns[MU_MEASURED] = np.asarray(self.mu_measured, dtype=float)
        if self.mu_measured_std is not None:
            columns[MU_MEASURED_STD] = np.asarray(self.mu_measured_std, dtype=float)
        columns |= {_HEADER + name: np.asarray([header], dtype=str) for name, header in self.headers.items()}
        columns |= {_CLOCK + name: np.asarray([start], dtype=str) for name, start in self.clock.items()}
        return columns

    @classmethod
    def from_columns(cls, columns: Mapping[str, Any], fixed: Mapping[str, Any]) -> Dataset:
        """The dataset of :meth:`to_columns`' columns (arrays or lists) and its fixed values."""
        physics_columns, conditions, factors, headers, clock = {}, {}, {}, {}, {}
        for name, values in columns.items():
            if name in (MU_MEASURED, MU_MEASURED_STD):
                continue
            if name.startswith(_HEADER):
                headers[name[len(_HEADER):]] = str(np.asarray(values).reshape(-1)[0])
            elif name.startswith(_CLOCK):
                clock[name[len(_CLOCK):]] = str(np.asarray(values).reshape(-1)[0])
            elif name.startswith(_CONDITION):
                conditions[name[len(_CONDITION):]] = np.asarray(values, dtype=float)
            elif name.startswith(_FACTOR):
                factors[name[len(_FACTOR):]] = np.asarray(values, dtype=str)
            else:
                physics_columns[name] = np.asarray(values)
        std = columns.get(MU_MEASURED_STD)
        return cls(physics_columns, conditions, np.asarray(columns[MU_MEASURED], dtype=float),
                   None if std is None else np.asarray(std, dtype=float), dict(fixed), factors, clock,
                   headers=headers)


def parse_csv(text: str | bytes, fixed: Mapping[str, Any] | None = None,
              factors: Sequence[str] = ()) -> Dataset:
    """Parse measured data from CSV text with a header row.

    Parameters
    ----------
    text : str or bytes
        CSV (comma-separated, UTF-8) with column names in the first line. Every later line
        is a data row (row 1 is the second line); a blank one is reported as a bad row, never
        skipped. Only the newline that ends the last line is ignored.
    fixed : mapping, optional
        Physics parameters fixed for every row, e.g. ``{"balls": 4}``.
    factors : sequence of str
        Condition columns to read as group labels even when they hold numbers (integer codes of
        specimens, builds, batches); a column with no number in it is a factor anyway.

    Returns
    -------
    Dataset

    Raises
    ------
    DataError
        Listing every bad cell, row or column.

    Examples
    --------
    >>> d = parse_csv("load_N,speed_m_s,mu_measured\\n0.01,0.1,0.011\\n", fixed={"balls": 4})
    >>> d.n_points, float(d.physics_columns["load_N"][0])
    (1, 0.01)
    """
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise DataError([{"row": None, "column": None, "message": f"CSV is not UTF-8: {exc}"}]) from None
    reader = csv.reader(io.StringIO(text.lstrip("\ufeff")))
    try:
        # Every line counts, blank or not, so that row numbers are data lines of the file.
        lines = list(reader)
    except csv.Error as exc:  # e.g. a cell over the csv module's field size limit (128 KiB)
        raise DataError([{"row": None, "column": None, "message": f"CSV cannot be read: {exc}"}]) from None
    if not any(any(cell.strip() for cell in line) for line in lines):
        raise DataError([{"row": None, "column": None, "message": "CSV is empty; expected a header row"}])
    if not any(cell.strip() for cell in lines[0]):
        raise DataError([{"row": None, "column": None,
                          "message": "the first line is blank; expected the header row (column names)"}])
    header = [h.strip() for h in lines[0]]
    errors = []
    if len(set(header)) != len(header) or "" in header:
        errors.append({"row": None, "column": None,
                       "message": f"header must name every column once; got {header}"})
        raise DataError(errors)
    rows: list[Mapping[str, Any] | None] = []
    for number, cells in enumerate(lines[1:], start=1):
        if not any(cell.strip() for cell in cells):
            # A blank line (or only separators) is a bad row, never silently skipped; the csv
            # module already ignores the newline that ends the last line.
            errors.append({"row": number, "column": None,
                           "message": "is blank (no value in any cell); remove the line or fill it"})
            rows.append(None)
            continue
        if len(cells) > len(header):
            errors.append({"row": number, "column": None,
                           "message": f"has {len(cells)} cells but the header has {len(header)}"})
        rows.append({name: (cells[i].strip() if i < len(cells) else "") for i, name in enumerate(header)})
    return _build(rows, header, fixed or {}, from_text=True, errors=errors, factors=factors)


def parse_rows(rows: Sequence[Mapping[str, Any]], fixed: Mapping[str, Any] | None = None,
               factors: Sequence[str] = ()) -> Dataset:
    """Check measured data given as JSON-like rows.

    Parameters
    ----------
    rows : sequence of mapping
        One mapping per measurement, column name -> number (or boolean for ``balls_touching``; or a
        label string in a factor column).
    fixed : mapping, optional
        Physics parameters fixed for every row.
    factors : sequence of str
        Condition columns to read as group labels even when they hold numbers (as :func:`parse_csv`).

    Returns
    -------
    Dataset

    Raises
    ------
    DataError
        Listing every bad cell, row or column.

    Examples
    --------
    >>> parse_rows([{"balls": 4, "load_N": -1, "speed_m_s": 0, "mu_measured": 0.01}])
    Traceback (most recent call last):
    ...
    microbearing.calibrate.data.DataError: 1 problem(s) in the measured data:
    row 1, column load_N: load_N must be in [1e-09, 1e+06] [N]; got -1.0
    """
    errors = []
    names: list[str] = []
    for number, row in enumerate(rows, start=1):
        if not isinstance(row, Mapping):
            errors.append({"row": number, "column": None, "message": "must be an object of column: value"})
            continue
        names.extend(k for k in row if k not in names)
    good_rows = [r if isinstance(r, Mapping) else {} for r in rows]
    return _build(good_rows, names, fixed or {}, from_text=False, errors=errors, factors=factors)


def parse_assignments(items: Sequence[str]) -> dict[str, float | bool]:
    """Fixed physics values from ``name=value`` strings (command line, query parameters).

    Parameters
    ----------
    items : sequence of str
        E.g. ``["balls=4", "balls_touching=false"]``; values in the units of :data:`physics.PARAMETERS`.

    Returns
    -------
    dict
        Name -> number or boolean (checked against the physics when the data are parsed).

    Raises
    ------
    DataError
        For an item without ``=``, an unknown name, a repeated name or a value of the wrong type.

    Examples
    --------
    >>> parse_assignments(["balls=4", "balls_touching=true"])
    {'balls': 4.0, 'balls_touching': True}
    """
    errors, values = [], {}
    for item in items:
        name, sep, text = (part.strip() for part in str(item).partition("="))
        spec = physics.PARAMETERS.get(name)
        if not sep or spec is None:
            errors.append({"row": None, "column": name or None,
                           "message": f"fixed value {item!r} must be name=value with a physics parameter "
                                      f"name ({', '.join(physics.PARAMETERS)})"})
            continue
        if name in values:
            errors.append({"row": None, "column": name, "message": "fixed value given twice"})
            continue
        value, problem = _boolean(text, True) if spec.kind == "bool" else _number(text, True)
        if problem is not None:
            errors.append({"row": None, "column": name, "message": f"fixed value: {problem}"})
        else:
            values[name] = value
    if errors:
        raise DataError(errors)
    return values


def factor_label(value: Any) -> str:
    """A group label as text: integer-valued numbers without a decimal point, strings stripped.

    The same label whether it came from CSV text, a JSON number or a JSON string.

    Examples
    --------
    >>> factor_label(3), factor_label(3.0), factor_label(" 3 "), factor_label("S1"), factor_label(2.5)
    ('3', '3', '3', 'S1', '2.5')
    """
    if isinstance(value, bool | np.bool_):
        return str(bool(value)).lower()
    if isinstance(value, str):
        text = value.strip()
        number, problem = _number(text, True)
        return text if problem is not None else factor_label(number)
    number = float(value)
    return str(int(number)) if number.is_integer() else repr(number)


def _missing(value) -> bool:
    return value is None or (isinstance(value, str) and value.strip() == "")


def _number(value, from_text: bool) -> tuple[float | None, str | None]:
    if isinstance(value, bool) or isinstance(value, np.bool_):
        return None, f"expected a number; got the boolean {value!r}"
    if isinstance(value, str):
        try:
            number = float(value)
        except ValueError:
            return None, f"expected a number; got {'the string ' if not from_text else ''}{value!r}"
    elif isinstance(value, int | float | np.integer | np.floating):
        number = float(value)
    else:
        return None, f"expected a number; got {type(value).__name__} {value!r}"
    if not math.isfinite(number):
        return None, f"must be finite; got {value!r}"
    return number, None


def _boolean(value, from_text: bool) -> tuple[bool | None, str | None]:
    if isinstance(value, bool | np.bool_):
        return bool(value), None
    if from_text and isinstance(value, str) and value.strip().lower() in _TRUE | _FALSE:
        return value.strip().lower() in _TRUE, None
    if isinstance(value, int) and value in (0, 1):
        return bool(value), None
    return None, f"expected true or false; got {value!r}"


def _range_message(spec: physics.Parameter, value: float) -> str | None:
    try:
        physics.validate(spec.name, value)
    except ValueError as exc:
        return str(exc)
    return None


def hours_since(cells: Sequence[Any], start: str) -> np.ndarray | None:
    """Hours since ``start`` (ISO 8601, as :attr:`Dataset.clock` keeps it) of ISO 8601 dates or date-times,
    read as the calibration read its column (a cell without a zone is UTC when the start has one); None
    when a cell is no ISO 8601 time.

    Examples
    --------
    >>> hours_since(["2026-11-28T11:30:00+02:00", "2026-11-29"], "2026-11-28T09:00:00+00:00").tolist()
    [0.5, 15.0]
    """
    times = _iso_times(cells)
    if times is None or None in times:
        return None
    origin = datetime.fromisoformat(start)
    if origin.tzinfo is not None:
        times = [t if t.tzinfo is not None else t.replace(tzinfo=UTC) for t in times]
    elif any(t.tzinfo is not None for t in times):
        return None  # a zone against a start without one: no common clock
    return _hours_from(times, origin)


def _iso_times(cells: Sequence[Any]) -> list[datetime | None] | None:
    """Each cell as a date-time (a missing cell None) when every given cell is an ISO 8601 date or
    date-time; None otherwise, and for a date that does not exist (2026-02-30)."""
    given = [c for c in cells if not _missing(c)]
    if not given or not all(isinstance(c, str) and _ISO_TIME.fullmatch(c.strip()) for c in given):
        return None
    try:
        return [None if _missing(c) else datetime.fromisoformat(c.strip()) for c in cells]
    except ValueError:
        return None


def _hours_from(times: Sequence[datetime | None], start: datetime) -> np.ndarray:
    """Hours from ``start`` to each time (NaN for None)."""
    return np.array([np.nan if t is None else (t - start).total_seconds() / _SECONDS_PER_HOUR for t in times])


def _clock_hours(cells: Sequence[Any]) -> tuple[np.ndarray, str] | None:
    """Hours since the earliest of the cells when every given cell is an ISO 8601 date or date-time, with
    that start (ISO 8601); None otherwise (a missing cell reads as NaN: the caller reports it)."""
    times = _iso_times(cells)
    if times is None:
        return None
    zoned = any(t is not None and t.tzinfo is not None for t in times)
    if zoned:
        times = [t if t is None or t.tzinfo is not None else t.replace(tzinfo=UTC) for t in times]
    start = min(t for t in times if t is not None)
    return _hours_from(times, start), start.isoformat()


def _written_time(cells: Sequence[Any]) -> str | None:
    """The first cell when every given cell is a date or time of day written otherwise than ISO 8601
    (``28.11.2026 08:07``, ``11/28/2026 8:07 AM``, ``08:07:00``), which as text would make a group of each
    row; None otherwise."""
    given = [c for c in cells if not _missing(c)]
    if given and all(isinstance(c, str) and _OTHER_TIME.search(c) for c in given):
        return str(given[0]).strip()
    return None


def _is_factor(name: str, cells: Sequence[Any], declared: Sequence[str]) -> bool:
    """A condition column read as labels: declared a factor, or without a number in any cell."""
    if name in physics.PARAMETERS or name in (MU_MEASURED, MU_MEASURED_STD):
        return False
    if name in declared:
        return True
    given = [c for c in cells if not _missing(c)]
    return bool(given) and all(_number(c, True)[1] is not None for c in given)


def _build(rows, names, fixed, from_text, errors, factors=()) -> Dataset:
    """Check every cell; a row given as None is already reported (a blank CSV line) and skipped."""
    n = len(rows)
    factors = list(dict.fromkeys(str(f) for f in factors))
    for name in factors:
        if name not in names:
            errors.append({"row": None, "column": name,
                           "message": "declared a factor but the data have no such column"})
        elif name in physics.PARAMETERS or name in (MU_MEASURED, MU_MEASURED_STD):
            errors.append({"row": None, "column": name,
                           "message": "declared a factor but it is a physics input or mu_measured; only a "
                                      "condition column can be a factor"})
    if n == 0:
        errors.append({"row": None, "column": None, "message": "no data rows"})
    checked_fixed: dict[str, Any] = {}
    for name, value in fixed.items():
        if name not in physics.PARAMETERS:
            errors.append({"row": None, "column": name,
                           "message": f"fixed value of an unknown physics parameter; known: "
                                      f"{', '.join(physics.PARAMETERS)}"})
        elif name in names:
            errors.append({"row": None, "column": name, "message": "fixed value given for a data column too"})
        else:
            try:
                checked_fixed[name] = physics.validate(name, value).item()
            except ValueError as exc:
                errors.append({"row": None, "column": name, "message": f"fixed value: {exc}"})
    if MU_MEASURED not in names:
        errors.append({"row": None, "column": MU_MEASURED, "message": "required column is missing"})
    for name, spec in physics.PARAMETERS.items():
        if spec.required and name not in names and name not in fixed:
            errors.append({"row": None, "column": name,
                           "message": f"required physics parameter is neither a column nor fixed "
                                      f"({spec.range_text()} [{spec.unit}])"})

    physics_columns, conditions, labels, clock = {}, {}, {}, {}
    mu = std = None
    for name in names:
        cells = [None if row is None else row.get(name) for row in rows]
        if all(_missing(c) for c in cells):
            errors.append({"row": None, "column": name, "message": "column has no values; fill or remove it"})
            continue
        reserved = name in physics.PARAMETERS or name in (MU_MEASURED, MU_MEASURED_STD) or name in factors
        timed = None if reserved else _clock_hours(cells)
        if timed is not None:
            errors += [{"row": i + 1, "column": name, "message": "missing time (ISO 8601)"}
                       for i, cell in enumerate(cells) if rows[i] is not None and _missing(cell)]
            conditions[name], clock[name] = timed
            continue
        written = None if reserved else _written_time(cells)
        if written is not None:
            errors.append({"row": None, "column": name, "message": (
                f"holds dates or times written as text ({written!r}), which are read only as ISO 8601: write "
                f"them so (e.g. 2026-11-28T08:07) to read hours since the first, or declare {name} a factor "
                f"to read them as group labels")})
            continue
        if _is_factor(name, cells, factors):
            column = np.empty(n, dtype=object)
            for i, cell in enumerate(cells):
                if rows[i] is None:
                    continue
                if _missing(cell):
                    errors.append({"row": i + 1, "column": name,
                                   "message": "missing label of a factor column"})
                elif isinstance(cell, Mapping | list):
                    errors.append({"row": i + 1, "column": name,
                                   "message": f"expected a label (text or number); got {cell!r}"})
                else:
                    column[i] = factor_label(cell)
            labels[name] = column.astype(str)
            continue
        spec = physics.PARAMETERS.get(name)
        values = np.zeros(n, dtype=bool if spec is not None and spec.kind == "bool" else float)
        for i, cell in enumerate(cells):
            if rows[i] is None:
                continue
            if _missing(cell):
                errors.append({"row": i + 1, "column": name, "message": "missing value"})
                continue
            value, problem = (_boolean(cell, from_text) if values.dtype == bool
                              else _number(cell, from_text))
            if problem is None and spec is not None:
                problem = _range_message(spec, value)
            elif problem is None and name == MU_MEASURED and value <= 0:
                problem = f"must be > 0 [1]; got {value!r}"
            elif problem is None and name == MU_MEASURED_STD and value <= 0:
                problem = f"must be > 0 [1]; got {value!r}"
            if problem is not None:
                condition = spec is None and name not in (MU_MEASURED, MU_MEASURED_STD)
                if condition and "expected a number" in problem:
                    problem += (f" (a condition column of labels is a factor: give every row a label, or "
                                f"declare {name} in factors)")
                error = {"row": i + 1, "column": name, "message": problem}
                if spec is not None and isinstance(value, float):
                    error["value"] = value  # out of the parameter's range (SI): a reader may restate it
                errors.append(error)
            else:
                values[i] = value
        if spec is not None:
            physics_columns[name] = values
        elif name == MU_MEASURED:
            mu = values
        elif name == MU_MEASURED_STD:
            std = values
        else:
            conditions[name] = values
    if errors:
        raise DataError(sorted(errors, key=lambda e: (e["row"] is not None, e["row"] or 0)))
    return Dataset(physics_columns, conditions, mu, std, checked_fixed, labels, clock)
