"""Tables as labs save them: spreadsheet dialects and units in the header, read into :mod:`calibrate.data`.

A spreadsheet export differs from the plain CSV that :func:`calibrate.data.parse_csv` reads in two
ways, both handled here before that parser sees the table:

* **Dialect.** The separator (comma, semicolon or tab) is detected by the standard library's
  :class:`csv.Sniffer` restricted to those three (``bench/csv_dialect.py`` measured it beside
  clevercsv and pandas on spreadsheet exports: all three found every separator, the Sniffer fastest
  and without a dependency), or stated. The decimal mark is a comma when numeric cells use one and
  none uses a point, or stated. A byte-order mark, CRLF or CR line ends, blank lines at the end and
  empty columns at the end (Excel's trailing separator) are ignored and said so. Excel's
  ``sep=;`` first line (``sep=,``, ``sep=<tab>``) states the separator; the header is then line 2.
* **Encoding.** UTF-8 with or without a byte-order mark, UTF-16 with one (Excel's "Unicode text"),
  and otherwise Windows-1252 (Excel's plain "CSV" in Western Europe, a superset of Latin-1's
  printable characters: ``temperature [°C]``), which the intake states.
* **Units in the header.** ``speed [mm/s]``, ``speed (mm/s)`` and ``speed_mm_s`` are read as the
  physics input ``speed_m_s`` with the values converted by pint (``load [g]``, a slider's mass, is
  converted to its weight in N with standard gravity). Any other column with a unit in brackets is a
  condition and is converted to SI: ``relative_humidity [%]`` to the fraction ``relative_humidity``,
  ``temperature [degC]`` to ``temperature_K``. A column without brackets that is not a physics input
  with a unit suffix stays as sent (``temperature_C``, ``relative_humidity_pct`` are read in those
  units by the candidate terms), except a temperature in a unit the terms do not read (``temp_F`` is
  read as ``temp_K``). Every name is read by the column registry, :mod:`physics.columns`.

:func:`read_csv` and :func:`read_rows` return the :class:`~calibrate.data.Dataset` with an
:class:`Intake` that says which dialect was used, how each column was read, what each text column
became (random-effect groups, numbers) and what was ignored (``ignore``). Problems in a file are
placed as the spreadsheet shows them (:class:`TableError`): the file's line and the column's letter,
``line 9, column C (speed [mm/s]): ...``.
"""

from __future__ import annotations

import codecs
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

__all__ = ["DECIMALS", "SEPARATORS", "STANDARD_GRAVITY_M_S2", "Column", "Intake", "Table", "TableError",
           "accepted_names", "column_letter", "in_sent_units", "read_column", "read_csv", "read_rows",
           "read_table"]

#: Separators by the name a request states them with.
SEPARATORS = {"comma": ",", "semicolon": ";", "tab": "\t"}
#: Decimal marks by name.
DECIMALS = {"point": ".", "comma": ","}
_SEPARATOR_NAMES = {v: k for k, v in SEPARATORS.items()}
_SNIFF_LINES = 50
_DECIMAL_COMMA = re.compile(r"^[+-]?(\d+,\d*|,\d+)([eE][+-]?\d+)?$")
_DECIMAL_POINT = re.compile(r"^[+-]?(\d+\.\d*|\.\d+)([eE][+-]?\d+)?$")
#: Excel's first line stating the separator: ``sep=;`` (quoted, or followed by empty cells, when a
#: spreadsheet wrote it back as a cell).
_SEP_LINE = re.compile(r'^"?sep=(\\t|.)"?[,;\t]*$', re.IGNORECASE)
#: Starts of files that are not text: a workbook saved instead of exported.
_BINARY_SIGNATURES = {b"PK\x03\x04": "an Excel workbook (.xlsx) or another zip archive",
                      b"\xd0\xcf\x11\xe0": "an Excel 97-2003 workbook (.xls)"}

#: How one column, as sent, is read (the registry's :class:`physics.columns.Reading`).
Column = Reading


def column_letter(index: int) -> str:
    """The spreadsheet's letter of the column at ``index`` (0-based): A, ..., Z, AA, AB, ...

    >>> [column_letter(i) for i in (0, 2, 25, 26, 27, 701, 702)]
    ['A', 'C', 'Z', 'AA', 'AB', 'ZZ', 'AAA']
    """
    letters = ""
    index += 1
    while index:
        index, rest = divmod(index - 1, 26)
        letters = chr(ord("A") + rest) + letters
    return letters


class TableError(DataError):
    """A :class:`~calibrate.data.DataError` of a file, whose problems say where the spreadsheet shows them.

    Each problem keeps ``row`` (the data row, 1 after the header) and ``column`` (the name it is read
    as), and adds, when known, ``line`` (the file's line, the header's counted: line 1, or 2 after a
    ``sep=`` line), ``letter`` (the column's letter, A for the first) and ``sent`` (its header cell).
    """

    @staticmethod
    def describe(error: Mapping[str, Any]) -> str:
        """One problem in words, placed as in the spreadsheet.

        >>> TableError.describe({"row": 8, "line": 9, "column": "speed_m_s", "letter": "C",
        ...                      "sent": "speed [mm/s]", "message": "must be > 0"})
        'line 9, column C (speed [mm/s]): must be > 0'
        >>> TableError.describe({"row": 2, "column": None, "message": "is blank"})
        'row 2: is blank'
        """
        if error.get("line") is None and error.get("letter") is None:
            return DataError.describe(error)
        where = []
        if error.get("line") is not None:
            where.append(f"line {error['line']}")
        if error.get("letter") is not None:
            where.append(f"column {error['letter']} ({error.get('sent') or error.get('column')})")
        elif error.get("column") is not None:
            where.append(f"column {error['column']}")
        return f"{', '.join(where)}: {error['message']}"


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
        Which of separator and decimal were detected (the others were stated, by the request or by
        the file's ``sep=`` line).
    encoding : str or None
        ``"UTF-8"``, ``"UTF-8 with BOM"``, ``"UTF-16 with BOM"`` or ``"Windows-1252"``.
    line_endings : str or None
        ``"LF"``, ``"CRLF"`` or ``"CR"``.
    ignored : list of str
        What was ignored, in words (blank lines at the end, empty columns at the end, the columns
        the request named in ``ignore``).
    columns : list of Column
        Every column read, as sent and how it was read.
    header_line : int or None
        The file's line of the header row: 1, or 2 after a ``sep=`` line (None for JSON).
    notes : list of str
        How the file was read where it is not plain, in words: the ``sep=`` line, an encoding other
        than UTF-8, how it was uploaded.
    text_columns : dict of str to str
        Each column with text in its cells (as sent) -> what it became, e.g. ``"random-effect groups
        (3 levels)"``.
    fitting : str or None
        What the calibration fits, in words (set by the caller that knows the request): the named
        parameters, or that none is named and what that means.
    row_lines : list of int
        The file's line of each data row (1-based; empty for JSON): where :meth:`locate` places a
        problem of a row.
    letters : dict of str to tuple of str
        Each column, as sent and as read, -> its letter and its header cell (empty for JSON): where
        :meth:`locate` places a problem of a column.
    """

    format: str
    separator: str | None = None
    decimal: str | None = None
    detected: list[str] = field(default_factory=list)
    encoding: str | None = None
    line_endings: str | None = None
    ignored: list[str] = field(default_factory=list)
    columns: list[Column] = field(default_factory=list)
    header_line: int | None = None
    notes: list[str] = field(default_factory=list)
    text_columns: dict[str, str] = field(default_factory=dict)
    fitting: str | None = None
    row_lines: list[int] = field(default_factory=list, repr=False)
    letters: dict[str, tuple[str, str]] = field(default_factory=dict, repr=False)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the dialect, what was ignored, ``conversions`` (sentences), ``columns``, the
        notes, the text columns and what is fitted."""
        return {"format": self.format, "separator": self.separator, "decimal": self.decimal,
                "detected": list(self.detected), "encoding": self.encoding,
                "line_endings": self.line_endings, "ignored": list(self.ignored),
                "conversions": [c.reading for c in self.columns if c.reading],
                "columns": {c.sent: c.name for c in self.columns},
                "header_line": self.header_line, "notes": list(self.notes),
                "text_columns": dict(self.text_columns), "fitting": self.fitting}

    def summary(self) -> str:
        """The intake in one paragraph, for a terminal.

        >>> Intake("csv", "semicolon", "comma", ["separator", "decimal"], "UTF-8", "CRLF").summary()
        'read as CSV: separator semicolon (detected), decimal comma (detected), UTF-8, CRLF line ends'
        """
        if self.format != "csv":
            parts = ["read as JSON rows"]
        else:
            source = ("detected" if "separator" in self.detected
                      else "sep= line" if self.header_line == 2 else "stated")
            parts = [f"read as CSV: separator {self.separator} ({source})",
                     f"decimal {self.decimal} ({'detected' if 'decimal' in self.detected else 'stated'})",
                     str(self.encoding), f"{self.line_endings} line ends"]
        parts += self.ignored + [c.reading for c in self.columns if c.reading]
        parts += [f"{name}: {became}" for name, became in self.text_columns.items()]
        return ", ".join(parts + self.notes + ([self.fitting] if self.fitting else []))

    def locate(self, errors: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
        """The problems of :class:`~calibrate.data.DataError` with the file's ``line`` and the column's
        ``letter`` and ``sent`` header cell added where known (see :class:`TableError`)."""
        placed = []
        for error in in_sent_units(errors, self.columns):
            row = error.get("row")
            if row is not None and 1 <= row <= len(self.row_lines):
                error["line"] = self.row_lines[row - 1]
            column = error.get("column")
            if column is not None and column in self.letters:
                error["letter"], error["sent"] = self.letters[column]
            placed.append(error)
        return placed


def in_sent_units(errors: Sequence[Mapping[str, Any]], columns: Sequence[Column]) -> list[dict[str, Any]]:
    """The problems with each out-of-range value of a column sent in another unit restated in that unit.

    A value out of a physics parameter's range is checked in SI (the problem carries it as ``value``,
    see :class:`~calibrate.data.DataError`); a lab that sent ``speed [mm/s]`` reads it back, and the
    range, in mm/s too.

    >>> in_sent_units([{"row": 4, "column": "speed_m_s", "value": -0.005,
    ...                 "message": "speed_m_s must be in [0, 1000] [m/s]; got -0.005"}],
    ...               [read_column("speed [mm/s]")])[0]["message"].split("; ")[1:]
    ['got -0.005 (as sent in speed [mm/s]: -5 mm/s', 'it must be in [0, 1e+06] mm/s)']
    """
    readings = {c.name: c for c in columns if c.reading and c.sent_unit}
    out = []
    for error in errors:
        error = dict(error)
        column, value = readings.get(error.get("column")), error.get("value")
        spec = physics.PARAMETERS.get(error.get("column"))
        if column is not None and spec is not None and isinstance(value, float):
            unit = column.sent_unit
            error["message"] = (f"{error['message']} (as sent in {column.sent}: {column.sent_value(value):g} "
                                f"{unit}; it must be {spec.range_text(column.sent_value)} {unit})")
        out.append(error)
    return out


@dataclass(frozen=True)
class Table:
    """A CSV file read as a table (:func:`read_table`), before its columns are checked as measurements.

    Attributes
    ----------
    header : list of str
        The column names as sent (empty columns at the end dropped).
    rows : list of list of str
        The cells of every row after the header, as sent.
    columns : list of Column or None
        How each column is read (None when a column has no name).
    intake : Intake
        The dialect and encoding used, what was ignored, each row's file line (``intake.row_lines``)
        and, with ``columns``, how every column was read.
    """

    header: list[str]
    rows: list[list[str]]
    columns: list[Column] | None
    intake: Intake

    def converted_rows(self, units: bool = True) -> list[list[str]]:
        """The cells with a decimal point and in SI (each column converted as :attr:`columns` reads it);
        with ``units`` False in the units of the header (a door that reads the keys itself)."""
        columns = self.columns or []
        decimal = self.intake.decimal or "point"
        return [[_cell(c, columns[i] if units and i < len(columns) else None, decimal)
                 for i, c in enumerate(r)] for r in self.rows]


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


def _unreadable(message: str) -> DataError:
    return DataError([{"row": None, "column": None, "message": message}])


def _line_of(data: bytes, position: int) -> int:
    """The file's line (1-based) of the byte at ``position``."""
    return data.count(b"\n", 0, position) + 1


def _decode(data: str | bytes) -> tuple[str, str, str | None]:
    """The text, its encoding's name and, for an encoding other than UTF-8, a sentence saying so."""
    if isinstance(data, str):
        return (data[1:], "UTF-8 with BOM", None) if data.startswith("\ufeff") else (data, "UTF-8", None)
    for signature, what in _BINARY_SIGNATURES.items():
        if data.startswith(signature):
            raise _unreadable(f"CSV is not UTF-8: the file is {what}; save it as CSV UTF-8 "
                              f"(in Excel: File > Save As > CSV UTF-8)")
    if data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        try:
            return data.decode("utf-16"), "UTF-16 with BOM", "read as UTF-16 (its byte-order mark says so)"
        except UnicodeDecodeError as exc:
            raise _unreadable(f"CSV is not UTF-8: it starts with UTF-16's byte-order mark but is not UTF-16 "
                              f"either ({exc}); save it as CSV UTF-8") from None
    nul = data.find(b"\x00")
    if nul >= 0:
        raise _unreadable(f"CSV is not UTF-8: line {_line_of(data, nul)} holds a NUL byte (a binary "
                          f"file, or UTF-16 without a byte-order mark); save it as CSV UTF-8")
    if data.startswith(codecs.BOM_UTF8):
        try:
            return data[len(codecs.BOM_UTF8):].decode("utf-8"), "UTF-8 with BOM", None
        except UnicodeDecodeError as exc:
            at = len(codecs.BOM_UTF8) + exc.start
            raise _unreadable(f"CSV is not UTF-8: byte 0x{data[at]:02x} on line {_line_of(data, at)} is not, "
                              f"after its UTF-8 byte-order mark; save it as CSV UTF-8") from None
    try:
        return data.decode("utf-8"), "UTF-8", None
    except UnicodeDecodeError:
        pass
    try:
        text = data.decode("cp1252")
    except UnicodeDecodeError as exc:
        raise _unreadable(f"CSV is not UTF-8: nor Windows-1252, as byte 0x{data[exc.start]:02x} on line "
                          f"{_line_of(data, exc.start)} is neither; save it as CSV UTF-8") from None
    seen = "".join(dict.fromkeys(c for c in text if ord(c) > 127))
    shown = ", ".join(repr(c) for c in seen[:8]) + (", ..." if len(seen) > 8 else "")
    return text, "Windows-1252", (f"not UTF-8: read as Windows-1252 (Excel's plain CSV in Western Europe, "
                                  f"Latin-1's characters included), which reads its special characters "
                                  f"as {shown}; if they look wrong, save the file as CSV UTF-8")


def _sep_line(first: str) -> str | None:
    """The separator an Excel ``sep=`` first line states (the character as written), or None."""
    match = _SEP_LINE.match(first.strip(" "))
    if match is None:
        return None
    return "\t" if match.group(1) == "\\t" else match.group(1)


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
             decimal: str | None = None, factors: Sequence[str] = (),
             ignore: Sequence[str] = ()) -> tuple[Dataset, Intake]:
    """Read measured data from a CSV file as spreadsheets export it.

    Parameters
    ----------
    data : str or bytes
        The file: UTF-8 with or without a byte-order mark, UTF-16 with one, or else Windows-1252
        (Latin-1); LF, CRLF or CR line ends; optionally Excel's ``sep=;`` first line.
    fixed : mapping, optional
        Physics inputs fixed for every row, in their units (as :func:`calibrate.data.parse_csv`).
    separator : str, optional
        ``"comma"``, ``"semicolon"`` or ``"tab"``; when None, the file's ``sep=`` line or detected.
    decimal : str, optional
        ``"point"`` or ``"comma"``; detected when None (a comma when numeric cells have one and none a
        point).
    factors : sequence of str, optional
        Condition columns of whole-number codes to read as group labels (as
        :func:`calibrate.data.parse_csv`).
    ignore : sequence of str, optional
        Columns to leave out, by their header cell (as sent) or the name they are read as (e.g. a
        ``comment`` or an ``operator`` column that should not become groups).

    Returns
    -------
    dataset : calibrate.Dataset
        As :func:`calibrate.data.parse_csv`, every column converted to its SI name and unit.
    intake : Intake
        The dialect and encoding used, how every column was read, what each text column became and
        what was ignored.

    Raises
    ------
    TableError
        A :class:`~calibrate.data.DataError`: a file that cannot be read as a table (one error saying
        why; a stated separator that the ``sep=`` line contradicts, or an ``ignore`` naming no column,
        carry ``parameter``), a bad column name or unit (naming the column as sent and the accepted
        names), or bad cells, each placed at its file line and column letter (``line 9, column C
        (speed [mm/s])``) besides its data ``row`` (1 after the header).

    Examples
    --------
    >>> text = "\\ufeffload [mN];speed [mm/s];mu_measured;\\r\\n8,8;50;0,011;\\r\\n\\r\\n"
    >>> d, intake = read_csv(text, fixed={"balls": 4})
    >>> float(d.physics_columns["load_N"][0]), float(d.physics_columns["speed_m_s"][0])
    (0.0088, 0.05)
    >>> intake.separator, intake.decimal, intake.line_endings, intake.ignored
    ('semicolon', 'comma', 'CRLF', ['1 blank line at the end', '1 empty column at the end'])
    >>> d, intake = read_csv("sep=;\\nload [mN];speed [mm/s];mu_measured;operator\\n8,8;50;0,011;Ann\\n",
    ...                      fixed={"balls": 4}, ignore=["operator"])
    >>> intake.separator, intake.header_line, intake.ignored
    ('semicolon', 2, ['column D (operator), as ignore asks'])
    """
    intake, lines, sep, header, body = _split(data, separator, decimal)
    header, body = _leave_out(header, body, ignore, intake)
    decimal = _decimal(body, sep, decimal, intake)
    try:
        dataset = _parse(header, body, fixed or {}, factors, intake, plain="\n".join(lines) + "\n")
    except DataError as exc:
        raise TableError(intake.locate(exc.errors)) from None
    texts = {c.sent: [_cell(r[i], None, decimal) if i < len(r) else "" for r in body]
             for i, c in enumerate(intake.columns)}
    intake.text_columns = _text_columns(intake.columns, texts, dataset)
    return dataset, intake


def read_table(data: str | bytes, separator: str | None = None, decimal: str | None = None) -> Table:
    """Read a CSV file as spreadsheets export it: its dialect, header and cells, before any column is
    checked as measured data (the command line reads points to evaluate with it; :func:`read_csv` reads
    measured data the same way).

    Parameters
    ----------
    data : str or bytes
        The file, as :func:`read_csv` takes it (UTF-8, UTF-16 with a byte-order mark, or Windows-1252;
        optionally Excel's ``sep=;`` first line).
    separator : str, optional
        ``"comma"``, ``"semicolon"`` or ``"tab"``; when None, the file's ``sep=`` line or detected.
    decimal : str, optional
        ``"point"`` or ``"comma"``; detected when None.

    Returns
    -------
    Table
        The header, the cells and the intake (the dialect; ``intake.columns`` every column's reading).

    Raises
    ------
    DataError
        A file that cannot be read as a table (one error saying why), or a bad column name or unit
        (naming the column as sent and the accepted names).

    Examples
    --------
    >>> table = read_table("balls;speed [mm/s]\\r\\n4;50,5\\r\\n")
    >>> [c.name for c in table.columns], table.converted_rows(), table.intake.decimal
    (['balls', 'speed_m_s'], [['4', '0.0505']], 'comma')
    """
    intake, _, sep, header, body = _split(data, separator, decimal)
    _decimal(body, sep, decimal, intake)
    columns = _columns([h.strip() for h in header]) if all(h.strip() for h in header) else None
    if columns is not None:
        intake.columns = columns
    return Table(header, body, columns, intake)


def _split(data: str | bytes, separator: str | None, decimal: str | None
           ) -> tuple[Intake, list[str], str, list[str], list[list[str]]]:
    """The file decoded and split into its header and rows at its separator (stated, from its ``sep=``
    line, or detected), with the intake that says how; the stated options checked first."""
    if separator is not None and separator not in SEPARATORS:
        raise ValueError(f"separator must be one of {', '.join(SEPARATORS)}; got {separator!r}")
    if decimal is not None and decimal not in DECIMALS:
        raise ValueError(f"decimal must be one of {', '.join(DECIMALS)}; got {decimal!r}")
    text, encoding, note = _decode(data)
    intake = Intake("csv", encoding=encoding, header_line=1, notes=[note] if note else [])
    lines = _lines(text, intake)
    sep = _separator(lines, separator, intake)
    header, body = _table(lines, sep, separator, intake)
    return intake, lines, sep, header, body


def _lines(text: str, intake: Intake) -> list[str]:
    """The file's lines without their ends and without blank lines at the end (said in ``intake``)."""
    intake.line_endings = "CRLF" if "\r\n" in text else ("CR" if "\r" in text else "LF")
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    if lines and lines[-1] == "":
        lines.pop()  # the newline that ends the last line
    blank_end = 0
    while lines and not lines[-1].strip(",;\t "):
        lines.pop()  # a blank line (or one of separators only) at the end
        blank_end += 1
    if blank_end:
        intake.ignored.append(f"{blank_end} blank line{'s' * (blank_end > 1)} at the end")
    if not any(line.strip() for line in lines):
        raise _unreadable("CSV is empty; expected a header row (column names) and data rows")
    return lines


def _separator(lines: list[str], stated: str | None, intake: Intake) -> str:
    """The separator: the ``sep=`` first line's (removed from ``lines``), the stated one, or detected."""
    written = _sep_line(lines[0])
    if written is not None:
        first = lines.pop(0)
        if written not in _SEPARATOR_NAMES:
            raise _unreadable(f"line 1 {first!r} states the separator {written!r}; the separators read are "
                              f"comma, semicolon and tab")
        name = _SEPARATOR_NAMES[written]
        if stated is not None and stated != name:
            raise DataError([{"row": None, "column": None, "parameter": "separator",
                              "message": f"separator={stated} was stated, but the file's first line "
                                         f"{first!r} states {name}; drop the parameter or state "
                                         f"separator={name}"}])
        intake.header_line = 2
        intake.notes.append(f"line 1 {first!r} (Excel's separator line) states the separator {name}; the "
                            f"header is line 2")
        if not any(line.strip() for line in lines):
            raise _unreadable("CSV has only its sep= line; expected a header row (column names) and data "
                              "rows")
        intake.separator = name
        return written
    sep = SEPARATORS[stated] if stated else _sniff_separator(lines)
    if stated is None:
        intake.detected.append("separator")
    intake.separator = _SEPARATOR_NAMES[sep]
    return sep


def _table(lines: list[str], sep: str, stated: str | None, intake: Intake
           ) -> tuple[list[str], list[list[str]]]:
    """The header and the data rows split at ``sep``, each row's file line kept in ``intake``."""
    reader = csv.reader(io.StringIO("\n".join(lines)), delimiter=sep)
    rows, starts, read = [], [], 0
    try:
        for row in reader:
            rows.append(row)
            starts.append(read + intake.header_line)  # a quoted cell may span lines: its row's first
            read = reader.line_num
    except csv.Error as exc:
        raise _unreadable(f"the file cannot be read as CSV: {exc}") from None
    if not rows or not any(cell.strip() for cell in rows[0]):
        raise _unreadable("the first line is blank; expected the header row (column names)")
    intake.row_lines = starts[1:]
    header, body, dropped, trimmed = _strip_trailing_empty(rows[1:], rows[0])
    if dropped:
        intake.ignored.append(f"{dropped} empty column{'s' * (dropped > 1)} at the end")
    if trimmed and not dropped:
        intake.ignored.append(f"empty cells past the last column in {trimmed} row{'s' * (trimmed > 1)}")
    others = {s for s in SEPARATORS.values() if s != sep}
    if len(header) == 1 and any(s in header[0] for s in others):
        found = next(_SEPARATOR_NAMES[s] for s in (";", "\t", ",") if s in header[0])
        how = "detected" if "separator" in intake.detected else "stated" if stated else "from the sep= line"
        raise _unreadable(f"the header {header[0]!r} is one column when split at the {intake.separator} "
                          f"({how}); it looks separated by {found}: state separator={found}")
    filled = [r for r in body if any(c.strip() for c in r)]
    if filled and all(len(r) > len(header) for r in filled):
        raise _unreadable(f"every row has more cells than the {len(header)} of the header (line "
                          f"{intake.header_line + 1}: {len(filled[0])}): numbers with a decimal comma in a "
                          f"file separated by {intake.separator}? Separate by semicolon or tab, or quote "
                          f"the numbers")
    return header, body


def _leave_out(header: list[str], body: list[list[str]], ignore: Sequence[str], intake: Intake
               ) -> tuple[list[str], list[list[str]]]:
    """The table without the columns ``ignore`` names (said in ``intake``); every kept column's letter."""
    sent = [h.strip() for h in header]
    wanted = list(dict.fromkeys(str(name).strip() for name in ignore))
    by_name: dict[str, int] = {}
    for i, name in enumerate(sent):
        by_name.setdefault(name, i)
        try:
            by_name.setdefault(read_column(name).name, i)
        except DataError:  # an unreadable name may still be ignored as sent
            pass
    unknown = [name for name in wanted if name not in by_name]
    if unknown:
        raise DataError([{"row": None, "column": None, "parameter": "ignore",
                          "message": f"ignore names {', '.join(repr(n) for n in unknown)}, not a column of "
                                     f"the file; its columns are {', '.join(repr(s) for s in sent if s)}"}])
    dropped = sorted({by_name[name] for name in wanted})
    for i in dropped:
        intake.ignored.append(f"column {column_letter(i)} ({sent[i]}), as ignore asks")
    kept = [i for i in range(len(header)) if i not in set(dropped)]
    intake.letters = {sent[i]: (column_letter(i), sent[i]) for i in kept if sent[i]}
    if not dropped:
        return header, body
    return [header[i] for i in kept], [[r[i] for i in kept if i < len(r)] + r[len(header):] for r in body]


def _decimal(body: list[list[str]], sep: str, stated: str | None, intake: Intake) -> str:
    """The decimal mark: stated, or a comma when numeric cells use one and none a point."""
    if stated is None:
        intake.detected.append("decimal")
        cells = [c.strip() for r in body for c in r]
        commas = any(_DECIMAL_COMMA.match(c) for c in cells)
        points = next((c for c in cells if _DECIMAL_POINT.match(c)), None)
        if commas and points is not None:
            example = next(c for c in cells if _DECIMAL_COMMA.match(c))
            raise _unreadable(f"numbers are written with a decimal comma ({example!r}) and with a decimal "
                              f"point ({points!r}); state decimal=comma or decimal=point")
        stated = "comma" if commas and sep != "," else "point"
    intake.decimal = stated
    return stated


def _parse(header: list[str], body: list[list[str]], fixed: Mapping[str, Any], factors: Sequence[str],
           intake: Intake, plain: str) -> Dataset:
    """The data set of the split table, its columns read through the registry (kept in ``intake``)."""
    if not all(h.strip() for h in header):  # an unnamed column: the parser's header error says so
        return parse_csv(_write(header, body), fixed, factors)
    columns = _columns([h.strip() for h in header])
    intake.columns = columns
    for c in columns:
        intake.letters.setdefault(c.name, intake.letters[c.sent])
    _check_required(columns, fixed)
    if (intake.separator == "comma" and intake.decimal == "point" and intake.ignored == []
            and all(c.name == c.sent and not c.reading for c in columns)):
        return parse_csv(plain, fixed, factors)  # plain CSV: the parser reads it as is
    converted = [[_cell(c, columns[i] if i < len(columns) else None, intake.decimal or "point")
                  for i, c in enumerate(r)] for r in body]
    return _with_headers(parse_csv(_write([c.name for c in columns], converted), fixed, factors), columns)


def _with_headers(dataset: Dataset, columns: Sequence[Column]) -> Dataset:
    """The dataset with the header each column sent under another name was sent under (reports speak its
    unit; a slip is judged in the unit it states)."""
    headers = {c.name: c.sent for c in columns if c.reading or c.sent != c.name}
    return dataclasses.replace(dataset, headers=headers) if headers else dataset


def _text_columns(columns: Sequence[Column], cells: Mapping[str, Sequence[Any]], dataset: Dataset
                  ) -> dict[str, str]:
    """Each condition column with text among its cells (as sent) -> what the data set made of it."""
    became = {}
    # ISO 8601 times read as hours since their start (Dataset.clock, where calibrate.data reads them)
    clock: Mapping[str, str] = getattr(dataset, "clock", {})
    for c in columns:
        if c.name in physics.PARAMETERS or c.name in (MU_MEASURED, MU_MEASURED_STD):
            continue
        if not any(_is_text(value) for value in cells.get(c.sent, ())):
            continue
        if c.name in dataset.factors:
            levels = len(set(dataset.factors[c.name].tolist()))
            became[c.sent] = f"random-effect groups ({levels} level{'s' * (levels != 1)})"
        elif c.name in clock:
            became[c.sent] = f"hours since {clock[c.name]}: the condition {c.name} [h]"
        elif c.name in dataset.conditions:
            became[c.sent] = f"numbers: the condition {c.name}"
        else:
            became[c.sent] = "not in the data"
    return became


def _is_text(value: Any) -> bool:
    if not isinstance(value, str) or not value.strip():
        return False
    try:
        float(value)
    except ValueError:
        return True
    return False


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


def _refuse_text_quantities(rows: Sequence[Any], by_sent: Mapping[str, Column]) -> None:
    """Refuse text in a JSON row's physics input or converted column (``"balls": "4"``,
    ``"cycles [kcycles]": "5"``): a JSON row gives a quantity as a number, and text would pass its unit
    by. Text is a CSV file's cell, and a factor's label among the conditions."""
    errors = [{"row": i + 1, "column": key,
               "message": (f"a physics input takes a number, not text ({value!r})"
                           if by_sent[key].name in physics.PARAMETERS else
                           f"a column with a unit ({by_sent[key].reading}) takes a number, not text "
                           f"({value!r})")}
              for i, row in enumerate(rows) if isinstance(row, Mapping) for key, value in row.items()
              if isinstance(value, str) and str(key) in by_sent
              and (by_sent[str(key)].name in physics.PARAMETERS or by_sent[str(key)].reading)]
    if errors:
        raise DataError(errors)


def read_rows(rows: Sequence[Mapping[str, Any]], fixed: Mapping[str, Any] | None = None,
              factors: Sequence[str] = (), ignore: Sequence[str] = ()) -> tuple[Dataset, Intake]:
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
    ignore : sequence of str, optional
        Keys to leave out, as sent or by the name they are read as.

    Returns
    -------
    dataset : calibrate.Dataset
    intake : Intake
        How every key was read, what each text column became and what was ignored.

    Raises
    ------
    DataError
        As :func:`read_csv` (an ``ignore`` naming no key carries ``parameter``).

    Examples
    --------
    >>> d, intake = read_rows([{"balls": 4, "load [g]": 0.9, "speed_m_s": 0.05, "mu_measured": 0.01}])
    >>> round(float(d.physics_columns["load_N"][0]), 9), intake.to_dict()["conversions"]
    (0.008825985, ['load [g] read as load_N = mass x standard gravity 9.80665 m/s^2 (x 0.00980665)'])
    """
    names: list[str] = []
    for row in rows:
        if isinstance(row, Mapping):
            names.extend(str(k) for k in row if str(k) not in names)
    if any(not name.strip() for name in names):  # an unnamed index column: as a CSV header refuses it
        unnamed = [n for n in names if not n.strip()]
        raise DataError([{"row": None, "column": None,
                          "message": f"every key must name its column; got {unnamed}"}])
    wanted = list(dict.fromkeys(str(name).strip() for name in ignore))
    read_as = {}
    for name in names:
        try:
            read_as[name] = read_column(name).name
        except DataError:  # an unreadable key may still be ignored; _columns names it otherwise
            read_as[name] = name
    unknown = [w for w in wanted if w not in names and w not in read_as.values()]
    if unknown:
        raise DataError([{"row": None, "column": None, "parameter": "ignore",
                          "message": f"ignore names {', '.join(repr(n) for n in unknown)}, not a column of "
                                     f"the data; its columns are {', '.join(repr(n) for n in names)}"}])
    left_out = [n for n in names if n in wanted or read_as[n] in wanted]
    columns = _columns([n for n in names if n not in left_out])
    _check_required(columns, fixed or {})
    by_sent = {c.sent: c for c in columns}
    _refuse_text_quantities(rows, by_sent)
    converted = []
    for row in rows:
        if not isinstance(row, Mapping):
            converted.append(row)
            continue
        out = {}
        for key, value in row.items():
            if str(key) in left_out:
                continue
            column = by_sent[str(key)]
            if column.reading and isinstance(value, int | float) and not isinstance(value, bool):
                value = column.convert(float(value))
            out[column.name] = value
        converted.append(out)
    try:
        dataset = _with_headers(parse_rows(converted, fixed, factors), columns)
    except DataError as exc:
        raise DataError(in_sent_units(exc.errors, columns)) from None
    intake = Intake("json", columns=columns, ignored=[f"column {n}, as ignore asks" for n in left_out])
    cells = {c.sent: [row.get(c.sent) for row in rows if isinstance(row, Mapping)] for c in columns}
    intake.text_columns = _text_columns(columns, cells, dataset)
    return dataset, intake
