"""Structured JSON logs with a request id, and Prometheus metrics at ``GET /metrics``.

Request ids
    Every request gets an id: the client's ``X-Request-ID`` when it is a sane token (1 to 128
    characters of ``A-Z a-z 0-9 . _ : -``), else a fresh UUID. The response echoes it in
    ``X-Request-ID`` and every log record written while the request is handled carries it
    (also from worker threads: :func:`starlette.concurrency.run_in_threadpool` copies the
    context, and so does :class:`service.jobs.JobManager` for the job a request creates, whose
    lines carry ``job_id`` too). An unexpected exception's traceback is logged with the id; its
    500 answer, made by Starlette's outermost error middleware, does not carry the header.

Logs
    :func:`configure_logging` writes the ``microbearing`` loggers as one JSON object per line
    (``time``, ``level``, ``logger``, ``message``, ``request_id`` and the record's extra
    fields). Each request is logged once by ``microbearing.access`` with method, path, route
    template, status and duration; headers, query strings and bodies are never logged, so API
    keys cannot leak into the logs. ``microbearing serve`` turns uvicorn's plain-text access
    log off in favour of this one.

Metrics
    ``microbearing_http_requests_total`` (counter) and
    ``microbearing_http_request_duration_seconds`` (histogram), both labelled by ``method``,
    ``route`` (the route template such as ``/v1/jobs/{job_id}``, or ``<unmatched>``, so that
    hostile paths cannot create unbounded series) and ``status``. ``/metrics`` answers the
    Prometheus text format and needs no API key (see :mod:`service.security`).

Several worker processes
    With ``microbearing serve --workers N`` (N > 1) the command sets ``PROMETHEUS_MULTIPROC_DIR``
    to ``<data dir>/prometheus`` (emptied at start) before the workers start, so that
    prometheus_client's multiprocess mode sums the counts of every worker, whichever worker
    answers the scrape. Under another process manager (gunicorn), set ``PROMETHEUS_MULTIPROC_DIR``
    to an empty folder yourself before the workers start. Without it, each worker reports only
    its own requests.
"""

from __future__ import annotations

import json
import logging
import os
import re
import shutil
import sys
import time
import uuid
from collections.abc import Callable
from contextvars import ContextVar
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from fastapi import FastAPI
from fastapi.responses import Response
from prometheus_client import (
    CONTENT_TYPE_LATEST,
    REGISTRY,
    CollectorRegistry,
    Counter,
    Histogram,
    generate_latest,
    multiprocess,
)
from starlette.datastructures import MutableHeaders
from starlette.types import ASGIApp, Message, Receive, Scope, Send

__all__ = [
    "REQUEST_ID_HEADER",
    "JsonFormatter",
    "OtherLibraries",
    "ObservabilityMiddleware",
    "configure_logging",
    "current_request_id",
    "install",
    "metrics_text",
    "prepare_multiprocess_dir",
    "uvicorn_log_config",
]

REQUEST_ID_HEADER = "X-Request-ID"
MULTIPROC_ENV = "PROMETHEUS_MULTIPROC_DIR"

_VALID_REQUEST_ID = re.compile(r"[A-Za-z0-9._:-]{1,128}")
_KNOWN_METHODS = frozenset({"GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS"})
_UNMATCHED_ROUTE = "<unmatched>"
#: Record attributes of the stdlib that are not "extra" fields (and uvicorn's ANSI-coloured copy).
_STANDARD_ATTRIBUTES = frozenset(vars(logging.LogRecord("", 0, "", 0, "", None, None))) | {
    "message", "asctime", "color_message"}

_request_id: ContextVar[str | None] = ContextVar("microbearing_request_id", default=None)

access_logger = logging.getLogger("microbearing.access")

REQUESTS = Counter("microbearing_http_requests_total", "HTTP requests answered.",
                   ["method", "route", "status"])
LATENCY = Histogram("microbearing_http_request_duration_seconds",
                    "Time from the request's arrival to the end of its response [s].",
                    ["method", "route", "status"],
                    buckets=(0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0,
                             30.0, 60.0))


def current_request_id() -> str | None:
    """The id of the request being handled in this context, or None outside a request."""
    return _request_id.get()


class JsonFormatter(logging.Formatter):
    """One JSON object per record: time, level, logger, message, request_id and extra fields."""

    def format(self, record: logging.LogRecord) -> str:
        entry: dict[str, Any] = {
            "time": datetime.fromtimestamp(record.created, UTC).isoformat(timespec="milliseconds")
            .replace("+00:00", "Z"),
            "level": record.levelname,
            "logger": record.name,
            "message": record.getMessage(),
            "request_id": getattr(record, "request_id", None),
        }
        for key, value in vars(record).items():
            if key not in _STANDARD_ATTRIBUTES and key not in entry:
                entry[key] = value
        if record.exc_info:
            entry["exception"] = self.formatException(record.exc_info)
        return json.dumps(entry, default=str, ensure_ascii=False)


def uvicorn_log_config() -> dict[str, Any]:
    """A :func:`logging.config.dictConfig` for uvicorn (``log_config=``): its own lines as JSON too.

    Returns
    -------
    dict
        uvicorn's loggers (startup, shutdown, errors and, when on, its access log) written to
        stderr by :class:`JsonFormatter`, so that every line of ``microbearing serve`` is JSON.
    """
    return {
        "version": 1,
        "disable_existing_loggers": False,
        "formatters": {"json": {"()": "microbearing.service.observability.JsonFormatter"}},
        "filters": {"others": {"()": "microbearing.service.observability.OtherLibraries"}},
        "handlers": {"json": {"formatter": "json", "class": "logging.StreamHandler",
                              "stream": "ext://sys.stderr"},
                     "others": {"formatter": "json", "class": "logging.StreamHandler",
                                "stream": "ext://sys.stderr", "filters": ["others"]}},
        "loggers": {"uvicorn": {"handlers": ["json"], "level": "INFO", "propagate": False},
                    "uvicorn.error": {"level": "INFO"},
                    "uvicorn.access": {"handlers": ["json"], "level": "INFO", "propagate": False}},
        # Every other library's records (dask.distributed, tornado, asyncio) reach the root logger:
        # JSON too. A handler on the root also stops distributed from adding its plain-text one when
        # it is imported (distributed.config.initialize_logging).
        "root": {"handlers": ["others"], "level": "WARNING"},
    }


class OtherLibraries(logging.Filter):
    """Passes records of loggers other than ``microbearing``'s (which has its own JSON handler)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.name != "microbearing" and not record.name.startswith("microbearing.")


_HANDLER_MARK = "_microbearing_json_handler"


class _RequestIdStamp:
    """A log record factory that stamps each record with the id of the request being handled."""

    def __init__(self, factory: Callable[..., logging.LogRecord]):
        self.factory = factory

    def __call__(self, *args: Any, **kwargs: Any) -> logging.LogRecord:
        record = self.factory(*args, **kwargs)
        record.request_id = current_request_id()
        return record


def configure_logging(level: int | str = logging.INFO) -> None:
    """Write the ``microbearing`` loggers to stderr as JSON lines (idempotent).

    Parameters
    ----------
    level : int or str, default INFO
        Lowest level written.
    """
    # Every record made while a request is handled carries its id, whatever handler formats it.
    if not isinstance(logging.getLogRecordFactory(), _RequestIdStamp):
        logging.setLogRecordFactory(_RequestIdStamp(logging.getLogRecordFactory()))
    root = logging.getLogger("microbearing")
    root.setLevel(level)
    if not any(getattr(handler, _HANDLER_MARK, False) for handler in root.handlers):
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(JsonFormatter())
        setattr(handler, _HANDLER_MARK, True)
        root.addHandler(handler)


def _request_id_from(headers: list[tuple[bytes, bytes]]) -> str:
    for name, value in headers:
        if name.lower() == b"x-request-id":
            text = value.decode("latin-1")
            if _VALID_REQUEST_ID.fullmatch(text):
                return text
            break
    return uuid.uuid4().hex


class ObservabilityMiddleware:
    """Assign request ids, log each request as JSON and record Prometheus metrics.

    Parameters
    ----------
    app : ASGI app
        The wrapped application.
    """

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        request_id = _request_id_from(scope["headers"])
        token = _request_id.set(request_id)
        started = time.perf_counter()
        status = 500  # if the app fails before answering, the server answers 500

        async def send_with_id(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
                MutableHeaders(scope=message)[REQUEST_ID_HEADER] = request_id
            await send(message)

        failed = True
        try:
            await self.app(scope, receive, send_with_id)
            failed = False
        finally:
            duration_s = time.perf_counter() - started
            route = getattr(scope.get("route"), "path", None) or _UNMATCHED_ROUTE
            method = scope["method"] if scope["method"] in _KNOWN_METHODS else "OTHER"
            REQUESTS.labels(method, route, str(status)).inc()
            LATENCY.labels(method, route, str(status)).observe(duration_s)
            access_logger.info("%s %s %d", method, route, status, extra={
                "method": method, "path": scope["path"][:200], "route": route, "status": status,
                "duration_ms": round(duration_s * 1e3, 3)})
            if not failed:
                # After an exception the id stays set, so that the server's error handler (outside
                # this middleware) logs the traceback with it; the request's context ends anyway.
                _request_id.reset(token)


def metrics_text() -> bytes:
    """The metrics in the Prometheus text format (summed over worker processes in multiprocess mode)."""
    if os.environ.get(MULTIPROC_ENV):
        registry = CollectorRegistry()
        multiprocess.MultiProcessCollector(registry)
        return generate_latest(registry)
    return generate_latest(REGISTRY)


def prepare_multiprocess_dir(data_dir: Path) -> Path:
    """Empty ``<data_dir>/prometheus`` and point ``PROMETHEUS_MULTIPROC_DIR`` at it.

    Call it in the parent process before worker processes start (they inherit the variable and
    must import prometheus_client after it is set); the files of a previous run are removed so
    that counts start at zero.

    Parameters
    ----------
    data_dir : pathlib.Path
        The service's data folder.

    Returns
    -------
    pathlib.Path
        The metrics folder.
    """
    folder = Path(data_dir) / "prometheus"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    os.environ[MULTIPROC_ENV] = str(folder)
    return folder


def install(app: FastAPI) -> None:
    """Add request ids, JSON access logs and metrics to ``app``, and the ``GET /metrics`` route.

    Install it after every other middleware so that it wraps them and sees every answer
    (including 401 and 413).
    """
    configure_logging()

    async def get_metrics() -> Response:
        return Response(metrics_text(), media_type=CONTENT_TYPE_LATEST)

    app.add_api_route("/metrics", get_metrics, methods=["GET"], include_in_schema=False)
    app.add_middleware(ObservabilityMiddleware)
