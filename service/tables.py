"""Columnar results as JSON or CSV, encoded fast enough for a million points.

A *table* is a dict of equally long columns (lists or 1-D arrays). Routes that return tables
honour ``Accept: text/csv`` through :func:`table_response`; a job result holding a table under
``"columns"`` can be downloaded as CSV from ``/v1/jobs/{id}/result``.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping
from typing import Any

import numpy as np
from fastapi import Request
from fastapi.responses import Response

from .store import json_bytes

__all__ = ["CSV_MEDIA_TYPE", "csv_text", "json_bytes", "table_response", "wants_csv"]

CSV_MEDIA_TYPE = "text/csv"


def wants_csv(request: Request) -> bool:
    """Whether the client asked for CSV (``Accept: text/csv``)."""
    return CSV_MEDIA_TYPE in request.headers.get("accept", "")


def csv_text(columns: Mapping[str, Any]) -> str:
    """A table as CSV text with a header row (numbers in shortest round-trip form)."""
    names = list(columns)
    lists = [np.asarray(columns[name]).reshape(-1).tolist() for name in names]
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(names)
    writer.writerows(zip(*lists, strict=True))
    return buffer.getvalue()


def table_response(request: Request, document: Mapping[str, Any], columns: Mapping[str, Any],
                   status_code: int = 200) -> Response:
    """``document`` as JSON, or only its ``columns`` as CSV when the client accepts CSV."""
    if wants_csv(request):
        return Response(csv_text(columns), status_code=status_code, media_type=CSV_MEDIA_TYPE)
    return Response(json_bytes(document), status_code=status_code, media_type="application/json")
