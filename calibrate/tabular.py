"""Tables as labs save them: spreadsheet dialects and units in the header, read into :mod:`calibrate.data`.

A spreadsheet export differs from the plain CSV that :func:`calibrate.data.parse_csv` reads in two
ways, both handled here before that parser sees the table:

* **Dialect.** The separator (comma, semicolon or tab) is detected by the standard library's
  :class:`csv.Sniffer` restricted to those three (``bench/csv_dialect.py`` measured it beside
  clevercsv and pandas on spreadsheet exports: all three found every separator, the Sniffer fastest
  and without a dependency), or stated. The decimal mark is a comma when numeric cells use one and
  none uses a point, or stated. A byte-order mark, CRLF or CR line ends, blank lines at the end and
  empty columns at the end (Excel's trailing separator) are ignored and said so.
* **Units in the header.** ``speed [mm/s]``, ``speed (mm/s)`` and ``speed_mm_s`` are read as the
  physics input ``speed_m_s`` with the values converted by pint (``load [g]``, a slider's mass, is
  converted to its weight in N with standard gravity). Any other column with a unit in brackets is a
  condition and is converted to SI: ``relative_humidity [%]`` to the fraction ``relative_humidity``,
  ``temperature [degC]`` to ``temperature_K``. A column without brackets that is not a physics input
  with a unit suffix stays as sent (``temperature_C``, ``relative_humidity_pct`` are read in those
  units by the candidate terms), except a temperature in a unit the terms do not read (``temp_F`` is
  read as ``temp_K``). Every name is read by the column registry, :mod:`physics.columns`.

:func:`read_csv` and :func:`read_rows` return the :class:`~calibrate.data.Dataset` with an
:class:`Intake` that says which dialect was used and how each column was read.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from microbearing import physics
from microbearing.physics.columns import (
    STANDARD_GRAVITY_M_S2,
    ColumnError,
    Reading,
    accepted_spellings,
    input_bases,
    read_name,
)

from .data import MU_MEASURED, MU_MEASURED_STD, DataError, Dataset, parse_csv, parse_rows

__all__ = ["DECIMALS", "SEPARATORS", "STANDARD_GRAVITY_M_S2", "Column", "Intake", "accepted_names",
           "read_column", "read_csv", "read_rows"]

#: Separators by the name a request states them with.
SEPARATORS = {"comma": ",", "semicolon": ";", "tab": "\t"}
#: Decimal marks by name.
DECIMALS = {"point": ".", "comma": ","}
_SEPARATOR_NAMES = {v: k for k, v in SEPARATORS.items()}
_SNIFF_LINES = 50
_DECIMAL_COMMA = re.compile(r"^[+-]?(\d+,\d*|,\d+)([eE][+-]?\d+)?$")
_DECIMAL_POINT = re.compile(r"^[+-]?(\d+\.\d*|\.\d+)([eE][+-]?\d+)?$")

#: How one column, as sent, is read (the registry's :class:`physics.columns.Reading`).
Column = Reading


@dataclass
class Intake:
    """What the table was and how it was read: dialect, what was ignored, every column's reading.

    Attributes
    ----------
    format : str
        ``"csv"`` or ``"json"``.
    separator : str or None
        ``"comma"``, ``"semicolon"`` or ``"tab"`` (None for JSON).
    decimal : str or None
        ``"point"`` or ``"comma"`` (None for JSON).
    detected : list of str
        Which of separator and decimal were detected (the others were stated).
    encoding : str or None
        ``"UTF-8"`` or ``"UTF-8 with BOM"``.
    line_endings : str or None
        ``"LF"``, ``"CRLF"`` or ``"CR"``.
    ignored : list of str
        What was ignored, in words (blank lines at the end, empty columns at the end).
    columns : list of Column
        Every column as sent and how it was read.
    """

    format: str
    separator: str | None = None
    decimal: str | None = None
    detected: list[str] = field(default_factory=list)
    encoding: str | None = None
    line_endings: str | None = None
    ignored: list[str] = field(default_factory=list)
    columns: list[Column] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the dialect, what was ignored, ``conversions`` (sentences) and ``columns``."""
        return {"format": self.format, "separator": self.separator, "decimal": self.decimal,
                "detected": list(self.detected), "encoding": self.encoding,
                "line_endings": self.line_endings, "ignored": list(self.ignored),
                "conversions": [c.reading for c in self.columns if c.reading],
                "columns": {c.sent: c.name for c in self.columns}}

    def summary(self) -> str:
        """The intake in one paragraph, for a terminal.

        >>> Intake("csv", "semicolon", "comma", ["separator", "decimal"], "UTF-8", "CRLF").summary()
        'read as CSV: separator semicolon (detected), decimal comma (detected), UTF-8, CRLF line ends'
        """
        if self.format != "csv":
            parts = ["read as JSON rows"]
        else:
            parts = [f"read as CSV: separator {self.separator} "
                     f"({'detected' if 'separator' in self.detected else 'stated'})",
                     f"decimal {self.decimal} ({'detected' if 'decimal' in self.detected else 'stated'})",
                     str(self.encoding), f"{self.line_endings} line ends"]
        parts += self.ignored + [c.reading for c in self.columns if c.reading]
        return ", ".join(parts)


def accepted_names() -> str:
    """The names a column may have, in words, examples first (:func:`physics.columns.accepted_spellings`).

    >>> text = accepted_names(); "speed [mm/s]" in text, len(text) < 600
    (True, True)
    """
    return accepted_spellings()


def read_column(sent: str) -> Column:
    """How a column named ``sent`` (header cell or JSON key) is read (:func:`physics.columns.read_name`).

    Parameters
    ----------
    sent : str
        E.g. ``"speed [mm/s]"``, ``"load (mN)"``, ``"speed_mm_s"``, ``"load_N"``,
        ``"relative_humidity [%]"`` or ``"temp_F"``.

    Returns
    -------
    Column

    Raises
    ------
    DataError
        Naming the column as sent: an unknown unit, a unit not convertible to the input's, a
        condition's unit of a dimension without an SI name here, or a name that states another unit.

    Examples
    --------
    >>> read_column("speed [mm/s]").reading
    'speed [mm/s] read as speed_m_s / 1000'
    >>> read_column("load (mN)").name, read_column("speed_mm_s").divisor, read_column("load_N").reading
    ('load_N', 1000, '')
    >>> c = read_column("temperature [degC]"); c.name, c.convert(25.0)
    ('temperature_K', 298.15)
    >>> read_column("relative humidity [%]").reading
    'relative humidity [%] read as relative_humidity / 100'
    """
    try:
        return read_name(sent, plain=(MU_MEASURED, MU_MEASURED_STD))
    except ColumnError as exc:
        raise DataError([{"row": None, "column": exc.column, "message": str(exc)}]) from None


def _columns(names: Sequence[str]) -> list[Column]:
    errors, columns = [], []
    for sent in names:
        try:
            columns.append(read_column(sent))
        except DataError as exc:
            errors.extend(exc.errors)
    by_name: dict[str, list[str]] = {}
    for c in columns:
        by_name.setdefault(c.name, []).append(c.sent)
    for name, sents in by_name.items():
        if len(sents) > 1:
            errors.append({"row": None, "column": sents[0],
                           "message": f"columns {', '.join(repr(s) for s in sents)} are all read as {name}; "
                                      "keep one"})
    if errors:
        raise DataError(errors)
    return columns


def _check_required(columns: Sequence[Column], fixed: Mapping[str, Any]) -> None:
    """A required physics input missing: one error naming the column that looks like it, or the columns
    read as conditions, with the accepted names."""
    names = {c.name for c in columns}
    errors = []
    conditions = [c.sent for c in columns if c.name not in physics.PARAMETERS
                  and c.name not in (MU_MEASURED, MU_MEASURED_STD)]
    for base, name in input_bases().items():
        spec = physics.PARAMETERS[name]
        if not spec.required or name in names or name in fixed:
            continue
        alike = [c for c in columns if c.sent.strip().lower().startswith(base) and c.name != name]
        if not alike and conditions:
            errors.append({"row": None, "column": None,
                           "message": f"the required {name} [{spec.unit}] is neither a column nor fixed; the "
                                      f"columns {', '.join(repr(c) for c in conditions)} were read as "
                                      f"conditions. Accepted names: {accepted_names()}"})
        for c in alike:
                errors.append({"row": None, "column": c.sent,
                               "message": f"column {c.sent!r} is read as the condition {c.name!r}, so "
                                          f"the required {name} [{spec.unit}] is missing: name it {name} or "
                                          f"{base} [{spec.unit}] (or another {spec.unit}-convertible unit); "
                                          f"accepted names: {accepted_names()}"})
    if errors:
        raise DataError(errors)


def _decode(data: str | bytes) -> tuple[str, str]:
    if isinstance(data, bytes):
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise DataError([{"row": None, "column": None,
                              "message": f"CSV is not UTF-8: {exc}; save it as CSV UTF-8"}]) from None
    else:
        text = data
    if text.startswith("\ufeff"):
        return text[1:], "UTF-8 with BOM"
    return text, "UTF-8"


def _sniff_separator(lines: list[str]) -> str:
    sample = "\n".join(lines[:_SNIFF_LINES])
    try:
        separator = csv.Sniffer().sniff(sample, delimiters=",;\t").delimiter
    except csv.Error:
        separator = None
    header = lines[0] if lines else ""
    counts = {s: header.count(s) for s in (";", "\t", ",")}
    if separator is None or header.count(separator) == 0:
        # a file of one column, or too few lines to sniff: the separator the header uses most
        best = max(counts, key=lambda s: counts[s])
        separator = best if counts[best] else ","
    return separator


def _strip_trailing_empty(rows: list[list[str]], header: list[str]
                          ) -> tuple[list[str], list[list[str]], int, int]:
    """Drop empty columns at the end (no name, no value) and cells beyond the header that are empty."""
    dropped = 0
    while header and not header[-1].strip() and all(
            len(r) < len(header) or not r[len(header) - 1].strip() for r in rows):
        header = header[:-1]
        dropped += 1
    trimmed = 0
    out = []
    for r in rows:
        if len(r) > len(header) and not any(c.strip() for c in r[len(header):]):
            r = r[:len(header)]
            trimmed += 1
        out.append(r)
    return header, out, dropped, trimmed


def read_csv(data: str | bytes, fixed: Mapping[str, Any] | None = None, separator: str | None = None,
             decimal: str | None = None, factors: Sequence[str] = ()) -> tuple[Dataset, Intake]:
    """Read measured data from a CSV file as spreadsheets export it.

    Parameters
    ----------
    data : str or bytes
        The file (UTF-8, with or without a byte-order mark; LF, CRLF or CR line ends).
    fixed : mapping, optional
        Physics inputs fixed for every row, in their units (as :func:`calibrate.data.parse_csv`).
    separator : str, optional
        ``"comma"``, ``"semicolon"`` or ``"tab"``; detected when None.
    decimal : str, optional
        ``"point"`` or ``"comma"``; detected when None (a comma when numeric cells have one and none a
        point).
    factors : sequence of str, optional
        Condition columns of whole-number codes to read as group labels (as
        :func:`calibrate.data.parse_csv`).

    Returns
    -------
    dataset : calibrate.Dataset
        As :func:`calibrate.data.parse_csv`, every column converted to its SI name and unit.
    intake : Intake
        The dialect used and how every column was read.

    Raises
    ------
    DataError
        A file that cannot be read as a table (one error saying why), a bad column name or unit
        (naming the column as sent and the accepted names), or bad cells (row by row, rows counted
        from 1 after the header).

    Examples
    --------
    >>> text = "\\ufeffload [mN];speed [mm/s];mu_measured;\\r\\n8,8;50;0,011;\\r\\n\\r\\n"
    >>> d, intake = read_csv(text, fixed={"balls": 4})
    >>> float(d.physics_columns["load_N"][0]), float(d.physics_columns["speed_m_s"][0])
    (0.0088, 0.05)
    >>> intake.separator, intake.decimal, intake.line_endings, intake.ignored
    ('semicolon', 'comma', 'CRLF', ['1 blank line at the end', '1 empty column at the end'])
    """
    if separator is not None and separator not in SEPARATORS:
        raise ValueError(f"separator must be one of {', '.join(SEPARATORS)}; got {separator!r}")
    if decimal is not None and decimal not in DECIMALS:
        raise ValueError(f"decimal must be one of {', '.join(DECIMALS)}; got {decimal!r}")
    text, encoding = _decode(data)
    line_endings = "CRLF" if "\r\n" in text else ("CR" if "\r" in text else "LF")
    text = text.replace("\r\n", "\n").replace("\r", "\n")
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()  # the newline that ends the last line
    intake = Intake("csv", encoding=encoding, line_endings=line_endings)
    blank_end = 0
    while lines and not lines[-1].strip(",;\t "):
        lines.pop()  # a blank line (or one of separators only) at the end
        blank_end += 1
    if blank_end:
        intake.ignored.append(f"{blank_end} blank line{'s' * (blank_end > 1)} at the end")
    if not any(line.strip() for line in lines):
        raise DataError([{"row": None, "column": None,
                          "message": "CSV is empty; expected a header row (column names) and data rows"}])
    sep = SEPARATORS[separator] if separator else _sniff_separator(lines)
    if separator is None:
        intake.detected.append("separator")
    intake.separator = _SEPARATOR_NAMES[sep]
    try:
        rows = list(csv.reader(io.StringIO("\n".join(lines)), delimiter=sep))
    except csv.Error as exc:
        raise DataError([{"row": None, "column": None, "message": f"the file cannot be read as CSV: {exc}"}]
                        ) from None
    if not rows or not any(cell.strip() for cell in rows[0]):
        raise DataError([{"row": None, "column": None,
                          "message": "the first line is blank; expected the header row (column names)"}])
    header, body, dropped, trimmed = _strip_trailing_empty(rows[1:], rows[0])
    if dropped:
        intake.ignored.append(f"{dropped} empty column{'s' * (dropped > 1)} at the end")
    if trimmed and not dropped:
        intake.ignored.append(f"empty cells past the last column in {trimmed} row{'s' * (trimmed > 1)}")
    others = {s for s in SEPARATORS.values() if s != sep}
    if len(header) == 1 and any(s in header[0] for s in others):
        found = next(_SEPARATOR_NAMES[s] for s in (";", "\t", ",") if s in header[0])
        raise DataError([{"row": None, "column": None,
                          "message": f"the header {header[0]!r} is one column when split at the "
                                     f"{intake.separator} ({'detected' if separator is None else 'stated'}); "
                                     f"it looks separated by {found}: state separator={found}"}])
    filled = [r for r in body if any(c.strip() for c in r)]
    if filled and all(len(r) > len(header) for r in filled):
        raise DataError([{"row": None, "column": None,
                          "message": f"every row has more cells than the {len(header)} of the header (row "
                                     f"1: {len(filled[0])}): numbers with a decimal comma in a file "
                                     f"separated by {intake.separator}? Separate by semicolon or tab, or "
                                     f"quote the numbers"}])
    cells = [c.strip() for r in body for c in r]
    if decimal is None:
        intake.detected.append("decimal")
        commas = any(_DECIMAL_COMMA.match(c) for c in cells)
        points = next((c for c in cells if _DECIMAL_POINT.match(c)), None)
        if commas and points is not None:
            example = next(c for c in cells if _DECIMAL_COMMA.match(c))
            raise DataError([{"row": None, "column": None,
                              "message": f"numbers are written with a decimal comma ({example!r}) and "
                                         f"with a decimal point ({points!r}); state decimal=comma or "
                                         f"decimal=point"}])
        decimal = "comma" if commas and sep != "," else "point"
    intake.decimal = decimal
    columns = _columns([h.strip() for h in header]) if all(h.strip() for h in header) else None
    if columns is None:  # an unnamed column: the parser's header error says so
        return parse_csv(_write(header, body), fixed, factors), intake
    intake.columns = columns
    _check_required(columns, fixed or {})
    if (sep == "," and decimal == "point" and not dropped and not trimmed
            and all(c.name == c.sent and not c.reading for c in columns)):
        # plain CSV: the parser reads it as is
        return parse_csv("\n".join(lines) + "\n", fixed, factors), intake
    converted = [[_cell(c, columns[i] if i < len(columns) else None, decimal) for i, c in enumerate(r)]
                 for r in body]
    dataset = parse_csv(_write([c.name for c in columns], converted), fixed, factors)
    return _with_headers(dataset, columns), intake


def _with_headers(dataset: Dataset, columns: Sequence[Column]) -> Dataset:
    """The dataset with the header each converted column was sent under (reports speak its unit)."""
    headers = {c.name: c.sent for c in columns if c.reading}
    return dataclasses.replace(dataset, headers=headers) if headers else dataset


def _cell(text: str, column: Column | None, decimal: str) -> str:
    value = text.strip()
    if decimal == "comma" and _DECIMAL_COMMA.match(value):
        value = value.replace(",", ".")
    if column is None or not column.reading or not value:
        return value
    try:
        number = float(value)
    except ValueError:
        return value  # the parser names the bad cell
    return repr(column.convert(number))


def _write(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return out.getvalue()


def read_rows(rows: Sequence[Mapping[str, Any]], fixed: Mapping[str, Any] | None = None,
              factors: Sequence[str] = ()) -> tuple[Dataset, Intake]:
    """Check measured data given as JSON rows whose keys may carry units (as :func:`read_csv`'s header).

    Parameters
    ----------
    rows : sequence of mapping
        One mapping per measurement, column name (e.g. ``"speed [mm/s]"``) -> number.
    fixed : mapping, optional
        Physics inputs fixed for every row, in their units.
    factors : sequence of str, optional
        Condition columns of whole-number codes to read as group labels (as
        :func:`calibrate.data.parse_rows`).

    Returns
    -------
    dataset : calibrate.Dataset
    intake : Intake
        How every key was read.

    Raises
    ------
    DataError
        As :func:`read_csv`.

    Examples
    --------
    >>> d, intake = read_rows([{"balls": 4, "load [g]": 0.9, "speed_m_s": 0.05, "mu_measured": 0.01}])
    >>> round(float(d.physics_columns["load_N"][0]), 9), intake.to_dict()["conversions"]
    (0.008825985, ['load [g] read as load_N = mass x standard gravity 9.80665 m/s^2 (x 0.00980665)'])
    """
    names: list[str] = []
    for row in rows:
        if isinstance(row, Mapping):
            names.extend(k for k in row if k not in names)
    columns = _columns([str(n) for n in names])
    _check_required(columns, fixed or {})
    by_sent = {c.sent: c for c in columns}
    converted = []
    for row in rows:
        if not isinstance(row, Mapping):
            converted.append(row)
            continue
        out = {}
        for key, value in row.items():
            column = by_sent[str(key)]
            if column.reading and isinstance(value, int | float) and not isinstance(value, bool):
                value = column.convert(float(value))
            out[column.name] = value
        converted.append(out)
    return _with_headers(parse_rows(converted, fixed, factors), columns), Intake("json", columns=columns)
