"""Columnar results as JSON or CSV, encoded fast enough for a million points.

A *table* is a dict of equally long columns (lists or 1-D arrays). Routes that return tables
honour ``Accept: text/csv`` through :func:`table_response`; a job result holding a table under
``"columns"`` can be downloaded as CSV from ``/v1/jobs/{id}/result``.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np
from fastapi import Request
from fastapi.responses import Response

from microbearing.physics.columns import ColumnError, read_name

from .store import json_bytes

__all__ = ["CSV_MEDIA_TYPE", "accepts_any", "best_match", "csv_text", "json_bytes", "json_column_pieces",
           "media_ranges", "prefers_csv", "sent_values", "sweep_table", "table_response", "wants_csv"]

CSV_MEDIA_TYPE = "text/csv"


def wants_csv(request: Request) -> bool:
    """Whether the client asked for CSV: ``text/csv`` named in ``Accept`` with a quality above 0
    and at least that of JSON (RFC 9110, 12.5.1); JSON otherwise, the default."""
    return prefers_csv(request.headers.get("accept", ""))


def prefers_csv(accept: str) -> bool:
    """:func:`wants_csv` on the text of an ``Accept`` header.

    >>> prefers_csv("text/csv"), prefers_csv("text/csv;q=0"), prefers_csv("*/*")
    (True, False, False)
    >>> prefers_csv("application/json;q=0.5, text/csv;q=0.8"), prefers_csv("text/*;q=0.9, application/json")
    (True, False)
    >>> prefers_csv("text/*")  # JSON not admitted: the table it does admit
    True
    """
    ranges = media_ranges(accept)
    csv_q, json_q = best_match(ranges, CSV_MEDIA_TYPE), best_match(ranges, "application/json")
    if csv_q is None or csv_q[1] <= 0.0:
        return False
    if json_q is None or json_q[1] <= 0.0:
        return True  # JSON not admitted at all (text/*): CSV, which is
    if csv_q[0] < 2:
        return False  # CSV only when named: */* leaves the default, JSON
    return csv_q[1] >= json_q[1]


def media_ranges(accept: str) -> list[tuple[str, str, float]]:
    """(type, subtype, quality) of each media range of an ``Accept`` header, lower case."""
    ranges = []
    for item in accept.split(","):
        media_range, *params = (part.strip() for part in item.split(";"))
        quality = 1.0
        for param in params:
            key, _, value = param.partition("=")
            if key.strip().lower() == "q":
                try:
                    quality = min(max(float(value), 0.0), 1.0)
                except ValueError:
                    quality = 0.0
        kind, _, subtype = media_range.lower().partition("/")
        ranges.append((kind, subtype, quality))
    return ranges


def best_match(ranges: list[tuple[str, str, float]], media_type: str) -> tuple[int, float] | None:
    """(specificity, quality) of the most specific range matching ``media_type`` (the first of equals)."""
    kind, subtype = media_type.split("/")
    best = None
    for r_kind, r_subtype, quality in ranges:
        specificity = {(kind, subtype): 2, (kind, "*"): 1, ("*", "*"): 0}.get((r_kind, r_subtype))
        if specificity is not None and (best is None or specificity > best[0]):
            best = (specificity, quality)
    return best


def accepts_any(accept: str, offered: list[str]) -> bool:
    """Whether an ``Accept`` header admits one of the ``offered`` media types (RFC 9110, 12.5.1).

    >>> accepts_any("image/png", ["application/json"]), accepts_any("text/*", ["text/csv"])
    (False, True)
    >>> accepts_any("application/json;q=0, */*", ["application/json"]), accepts_any("", ["application/json"])
    (False, True)
    """
    if not accept.strip():
        return True
    ranges = media_ranges(accept)
    matches = (best_match(ranges, media_type) for media_type in offered)
    return any(match is not None and match[1] > 0 for match in matches)


def csv_text(columns: Mapping[str, Any]) -> str:
    """A table as CSV text with a header row (numbers in shortest round-trip form)."""
    names = list(columns)
    lists = [np.asarray(columns[name]).reshape(-1).tolist() for name in names]
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(names)
    writer.writerows(zip(*lists, strict=True))
    return buffer.getvalue()


def sweep_table(document: Mapping[str, Any]) -> dict[str, Any]:
    """The columns of a table result with its fixed inputs as columns: varied inputs, fixed ones, outputs.

    A result without ``fixed`` (or ``varied``) gives its ``columns`` as they are. An input the request sent
    under another key (``as_sent``) is that column, under that key and in its unit, as the request said it:
    a fixed one's ``values``, a varied one's column converted (:func:`sent_values`).

    >>> sweep_table({"count": 2, "varied": ["speed_m_s"], "fixed": {"load_N": 0.01},
    ...              "columns": {"speed_m_s": [0.0, 0.1], "mu": [0.01, 0.02]}})
    {'speed_m_s': [0.0, 0.1], 'load_N': [0.01, 0.01], 'mu': [0.01, 0.02]}
    >>> sweep_table({"count": 2, "varied": ["speed_m_s"], "fixed": {"load_N": 0.01},
    ...              "columns": {"speed_m_s": [0.0, 0.1], "mu": [0.01, 0.02]},
    ...              "as_sent": {"speed [mm/s]": {"column": "speed_m_s", "factor": 1000.0, "offset": 0.0}}})
    {'speed [mm/s]': [0.0, 100.0], 'load_N': [0.01, 0.01], 'mu': [0.01, 0.02]}
    """
    columns = document["columns"]
    fixed = document.get("fixed") or {}
    varied = document.get("varied") or []
    if not fixed:
        table = dict(columns)
    else:
        count = int(document.get("count", len(next(iter(columns.values()), []))))
        table = {name: columns[name] for name in varied if name in columns}
        table.update({name: [value] * count for name, value in fixed.items() if name not in columns})
        table.update({name: values for name, values in columns.items() if name not in table})
    sent = {part["column"]: (key, part) for key, part in (document.get("as_sent") or {}).items()}
    if not sent:
        return table
    count = len(next(iter(table.values()), []))
    out = {}
    for name, values in table.items():
        if name not in sent:
            out[name] = values
            continue
        key, part = sent[name]
        given = part.get("values")
        out[key] = (given if isinstance(given, list) else [given] * count if given is not None
                    else sent_values(key, part, values))
    return out


def sent_values(key: str, part: Mapping[str, Any], values: Any) -> list[float]:
    """A column's values (SI) in the unit of the key it was sent under, to the digits each holds
    (:meth:`physics.columns.Reading.set_point`: 1000, not 999.9999999999), from the key as the request read
    it; from ``part``'s ``factor`` and ``offset`` should the key not read (value x factor + offset)."""
    try:
        reading = read_name(key)
    except ColumnError:
        reading = None
    numbers = np.asarray(values, dtype=float).tolist()
    if reading is not None and reading.reading and reading.name == part["column"]:
        return [reading.set_point(v) for v in numbers]
    factor, offset = float(part.get("factor", 1.0)), float(part.get("offset", 0.0))
    return [v * factor + offset for v in numbers]


def table_response(request: Request, document: Mapping[str, Any], columns: Mapping[str, Any],
                   status_code: int = 200) -> Response:
    """``document`` as JSON, or only its ``columns`` as CSV when the client accepts CSV."""
    if wants_csv(request):
        return Response(csv_text(columns), status_code=status_code, media_type=CSV_MEDIA_TYPE)
    return Response(json_bytes(document), status_code=status_code, media_type="application/json")


def json_column_pieces(columns: Sequence[tuple[str, str]], bounds: Sequence[tuple[int, int]],
                       chunks: list[dict[str, Any]], tail: dict[str, Any] | None = None) -> Iterator[bytes]:
    """The JSON object of columns given chunk by chunk, in pieces of one chunk of one column.

    The pieces joined are the bytes :func:`json_bytes` writes for the joined columns (the same
    numbers, digits and separators), but no more than one chunk of one column is encoded at a
    time, and a chunk's output is dropped once its last column is written: a streamed answer of
    millions of points costs the outputs' arrays, not their JSON as well.

    Parameters
    ----------
    columns : sequence of (str, str)
        ``(key in the answer, output name in the chunks)``, in the answer's order; an output may
        appear under several keys (an alias).
    bounds : sequence of (int, int)
        ``(start, stop)`` of each chunk [points].
    chunks : list of dict
        Each chunk's outputs, an array of its points or a scalar shared by them; emptied as written.
    tail : dict, optional
        Other keys of the object, written after the columns (e.g. ``input_warnings``).

    Yields
    ------
    bytes
        Pieces of one JSON object.

    Raises
    ------
    ValueError
        For a NaN or infinite number (callers check outputs before streaming, see
        :func:`service.executor.evaluate_chunks`).
    """
    uses: dict[str, int] = {}
    for _, name in columns:
        uses[name] = uses.get(name, 0) + 1
    yield b"{"
    for index, (key, name) in enumerate(columns):
        yield (b"]," if index else b"") + json_bytes(key) + b":["
        for position, (chunk, (start, stop)) in enumerate(zip(chunks, bounds, strict=True)):
            values = np.broadcast_to(np.asarray(chunk[name], dtype=float), (stop - start,))
            text = json_bytes(values)
            if b"NaN" in text or b"Infinity" in text:
                raise ValueError(f"{name} has a value JSON cannot represent")
            yield (b"," if position else b"") + text[1:-1]
        uses[name] -= 1
        if not uses[name]:
            for chunk in chunks:
                chunk.pop(name, None)
    extra = b"".join((b"," if columns or i else b"") + json_bytes(key) + b":" + json_bytes(value)
                     for i, (key, value) in enumerate((tail or {}).items()))
    yield (b"]" if columns else b"") + extra + b"}"

