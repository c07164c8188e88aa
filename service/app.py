"""The ASGI application: ``service.app:app``, built by :func:`create_app`.

``create_app(settings)`` wires the pieces: settings (:mod:`service.settings`), problem+json
errors (:mod:`service.problems`), the request-body limit (:mod:`service.limits`, a 413
problem), the SQLite store and job manager (:mod:`service.deps`, opened at startup or
on first use) and one router per resource from :data:`ROUTERS`. See :mod:`service.routes` for
how to add a resource.
"""

from __future__ import annotations

import inspect
import logging
import re
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import FastAPI
from fastapi.routing import APIRoute, APIRouter
from fastapi_offline import FastAPIOffline
from starlette.requests import Request
from starlette.responses import Response
from starlette.routing import Match, Route
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from . import connections, models, observability, problems, security, umbridge
from .deps import DataFolderError, close_runtime, get_runtime
from .job_kinds import register_job_kinds
from .jsonguard import JsonGuardMiddleware
from .limits import BodySizeLimitMiddleware, HeavyRequestMiddleware
from .problems import ProblemError
from .routes import calibrations, experiments, friction, jobs, meta, optimizations, surrogates, sweeps, web
from .routes import manual as manual_routes
from .routes import umbridge as umbridge_routes
from .routes.meta import package_version
from .schemas.base import add_raw_body_schemas
from .settings import Settings
from .tables import accepts_any

__all__ = ["ROUTERS", "AcceptMiddleware", "HeadMiddleware", "PlainRoute", "app", "create_app",
           "json_scan_limits", "plain_routes"]

logger = logging.getLogger("microbearing.service")

#: The routes that take columns of data, up to MICROBEARING_MAX_BODY_BYTES: a batch, a surrogate's
#: predict, the CSV uploads and UM-Bridge. Any other body is a document, up to
#: MICROBEARING_MAX_DOCUMENT_BYTES.
DATA_PATHS = re.compile(r"/v1/friction/batch$|/v1/surrogates/[^/]+/predict$|/v1/calibrations/csv(/intake)?$|"
                        + re.escape(umbridge.PREFIX) + "/")

#: The routers of every resource, in the order of the OpenAPI spec. Add yours here.
ROUTERS = [meta.router, friction.router, sweeps.router, jobs.router, calibrations.router, experiments.router,
           surrogates.router, optimizations.router, umbridge_routes.router, web.router, manual_routes.router]

DESCRIPTION = """Friction of micro linear ball bearings for MEMS by the model of Olaru, Prisacaru,
Ianus and Lorenz (COMEC 2005). All quantities are SI (the groove angle in degrees); every field
states its unit in brackets. Errors are RFC 9457 problem details (application/problem+json).
Long work answers 202 Accepted with a Location header to poll under /v1/jobs/{id}."""


class HeadMiddleware:
    """Answer ``HEAD`` wherever ``GET`` is served (RFC 9110): the GET answer's status and headers, no body.

    FastAPI routes declare GET only, so HEAD would be 405. A HEAD request to a path with a GET
    route runs that route and drops the body; other paths keep their 404 or 405 (whose ``Allow``
    lists HEAD next to GET, see :mod:`service.problems`). The OpenAPI spec documents GET only.

    Parameters
    ----------
    app : ASGI app
        The wrapped application.
    """

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "HEAD" or not any(
                route.matches({**scope, "method": "GET"})[0] == Match.FULL
                for route in scope["app"].router.routes):
            await self.app(scope, receive, send)
            return

        async def without_body(message: Message) -> None:
            if message["type"] == "http.response.body":
                message = {**message, "body": b""}
            await send(message)

        await self.app({**scope, "method": "GET"}, receive, without_body)


class AcceptMiddleware:
    """Answer ``406 Not Acceptable`` when ``Accept`` admits none of the media types a route produces.

    A route's media types are those of its 2xx answers in the OpenAPI spec (``application/json``,
    ``text/csv`` for tables, ``image/png`` for plots), read once; the request's path is matched
    against the spec's path templates. Paths outside the spec (the API docs, metrics) and answers
    without content (204) are not checked; an absent, ``*/*`` or ``application/json`` Accept passes
    without any lookup (``application/json`` is looked up only among the few routes that do not offer it,
    the plots). The 406 is a problem listing what the route offers.

    Parameters
    ----------
    app : ASGI app
        The wrapped application.
    """

    _PASS = frozenset({b"", b"*/*"})

    def __init__(self, app: ASGIApp):
        self.app = app
        self._offered: list[tuple[re.Pattern[str], str, list[str]]] | None = None
        self._no_json: list[tuple[re.Pattern[str], str, list[str]]] | None = None

    def offered(self, app: FastAPI, path: str, method: str) -> list[str]:
        """Media types of the 2xx answers of the spec's operation at ``path`` (empty when none)."""
        if self._offered is None:
            offered = []
            for template, item in app.openapi()["paths"].items():
                pattern = re.compile("^" + re.sub(r"\\\{[^/]+?\\\}", "[^/]+", re.escape(template)) + "$")
                for verb, operation in item.items():
                    types = {media for code, answer in operation.get("responses", {}).items()
                             if code.startswith("2") for media in answer.get("content", {})}
                    if types:
                        offered.append((pattern, verb.upper(), sorted(types)))
            self._offered = offered
        matching = (types for pattern, verb, types in self._offered if verb == method and pattern.match(path))
        return next(matching, [])

    def without_json(self, app: FastAPI, path: str, method: str) -> list[str]:
        """:meth:`offered` at ``path`` when the route does not offer ``application/json`` (empty when it
        does, or is outside the spec)."""
        self.offered(app, path, method)  # the table, read once
        if self._no_json is None:
            self._no_json = [(p, v, t) for p, v, t in self._offered or [] if "application/json" not in t]
        return next((t for p, v, t in self._no_json if v == method and p.match(path)), [])

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        accept = next((value for name, value in scope["headers"] if name == b"accept"), b"") \
            if scope["type"] == "http" else b""
        if accept.strip() in self._PASS:
            await self.app(scope, receive, send)
            return
        method = "GET" if scope["method"] == "HEAD" else scope["method"]
        if accept.strip() == b"application/json":  # the JSON routes pass without a lookup among them
            types = self.without_json(scope["app"], security.app_path(scope), method)
        else:
            types = self.offered(scope["app"], security.app_path(scope), method)
        text = accept.decode("latin-1")
        if not types or accepts_any(text, types):
            await self.app(scope, receive, send)
            return
        problem = ProblemError(406, f"The Accept header {text[:200]!r} admits none of the media types of "
                                    f"this resource: {', '.join(types)}.", title="Not Acceptable")
        await problems.ProblemResponse(problem.to_dict(instance=scope["path"]), status_code=406)(
            scope, receive, send)


class PlainRoute(Route):
    """Starlette's own route to an endpoint of :data:`ROUTERS` that uses none of FastAPI's request handling.

    FastAPI's handling of a request (its route matching over included routers, dependency
    resolution, parameter and body validation, response-model serialization) costs about 110 us
    per request (``python -m bench.inprocess``: ``POST /v1/friction`` 306-324 us through FastAPI's
    route, 146-218 us through this one, ``GET /healthz`` 145-225 us). An endpoint that takes
    nothing but the request, parses its own body (:func:`service.schemas.base.parse_json_body`)
    and returns a :class:`~starlette.responses.Response` needs none of it: :func:`plain_routes`
    serves it through this route, registered ahead of FastAPI's. Every middleware (size limit,
    JSON guard, API keys, Accept, logs and metrics) and the exception handlers (problem+json) run
    as before; FastAPI's route stays in the OpenAPI document.
    """

    def matches(self, scope: Scope) -> tuple[Match, Scope]:
        """Starlette's match, with the route in the scope as FastAPI puts it (logs and metrics read it)."""
        match, child_scope = super().matches(scope)
        if match is not Match.NONE:  # a method it does not serve (405) is labelled too, as FastAPI does
            child_scope["route"] = self
        return match, child_scope


def plain_routes(routers: list[APIRouter]) -> list[PlainRoute]:
    """A :class:`PlainRoute` for each route of ``routers`` that takes only the request and returns a Response.

    Parameters
    ----------
    routers : list of fastapi.APIRouter
        Routers whose routes carry their full paths (prefix included).

    Returns
    -------
    list of PlainRoute
        One per qualifying route: same path, methods, name and endpoint.
    """
    plain = []
    for router in routers:
        for route in router.routes:
            # Exactly FastAPI's route class (a subclass may handle requests its own way, as the
            # UM-Bridge routes do), no dependency (the router's own included), one parameter: the request.
            if type(route) is not APIRoute or route.dependant.dependencies:
                continue
            try:
                signature = inspect.signature(route.endpoint, eval_str=True)
            except NameError:  # an annotation its module cannot resolve: left to FastAPI
                continue
            takes = [parameter.annotation for parameter in signature.parameters.values()]
            answer = signature.return_annotation
            if (len(takes) == 1 and inspect.isclass(takes[0]) and issubclass(takes[0], Request)
                    and inspect.isclass(answer) and issubclass(answer, Response)):
                plain.append(PlainRoute(route.path, route.endpoint, methods=list(route.methods),
                                        name=route.name))
    return plain


@asynccontextmanager
async def _lifespan(app: FastAPI) -> AsyncIterator[None]:
    # Descriptors for connections up to the hard limit; repeated OS errors logged once a second.
    connections.raise_fd_limit()
    connections.install_repeat_filter()
    try:
        runtime = get_runtime(app)  # open the database and recover interrupted jobs before serving
    except DataFolderError as exc:
        # One clear line before the server's traceback; the server then exits non-zero.
        logger.critical("%s", exc)
        raise
    logger.info("data folder %s (database %s)", runtime.store.data_dir, runtime.store.path,
                extra={"data_dir": str(runtime.store.data_dir)})
    try:
        yield
    finally:
        close_runtime(app)


def json_scan_limits(settings: Settings) -> dict[str, int]:
    """The limits of the streaming JSON check (:class:`service.jsonguard.JsonScanner`'s keywords), as they
    follow the settings: a body's strings and containers are a batch's points (a UM-Bridge input is an array
    per point) or a calibration's rows as objects of keys, and the envelope around them; no object but a
    calibration's row has more than a schema's few fields, and only rows come in thousands."""
    return {"max_items": settings.max_batch_points, "max_string_bytes": settings.max_field_bytes,
            "max_values": max(settings.max_batch_points,
                              settings.max_calibration_rows * (settings.max_calibration_columns + 1)) + 1024,
            "max_members": settings.max_calibration_columns + 256,
            "max_objects": settings.max_calibration_rows + 1024}


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the service.

    Parameters
    ----------
    settings : Settings, optional
        Configuration; read from ``MICROBEARING_*`` environment variables when omitted.

    Returns
    -------
    fastapi.FastAPI
        The ASGI app. Its database opens at startup (or on first request without a lifespan).
    """
    settings = settings or Settings()
    # The kinds of job this app's processes rebuild from stored inputs (service/job_kinds.py).
    register_job_kinds()
    # /docs and /redoc load Swagger UI and ReDoc from the assets fastapi-offline ships, not from a CDN,
    # so they work on an isolated network.
    app = FastAPIOffline(title="microbearing", version=package_version(), description=DESCRIPTION,
                         lifespan=_lifespan, static_url=security.DOCS_ASSETS_PATH)
    app.state.settings = settings
    models.configure_physics(settings.physics_kernel, settings.physics_threads)
    app.state.runtime = None
    problems.install(app)
    # Outermost last: request ids, logs and metrics see every answer; API keys are checked
    # before the body is read; the JSON check runs on a body the size limit has bounded; HEAD
    # becomes GET innermost, so logs, metrics and the key check see the method sent.
    app.add_middleware(HeadMiddleware)
    app.add_middleware(AcceptMiddleware)
    scan = json_scan_limits(settings)
    app.add_middleware(JsonGuardMiddleware, max_items=scan["max_items"],
                       max_field_bytes=scan["max_string_bytes"], max_values=scan["max_values"],
                       max_members=scan["max_members"],
                       max_objects=scan["max_objects"], json_prefixes=(umbridge.PREFIX + "/",))
    # A large body waits for its turn, and holds a place of the job admission control, before it is read.
    app.add_middleware(HeavyRequestMiddleware, max_requests=settings.max_heavy_requests,
                       wait_s=settings.heavy_request_wait_s,
                       admit=lambda scope: get_runtime(scope["app"]).jobs.admit_request("request"))
    app.add_middleware(BodySizeLimitMiddleware, max_bytes=settings.max_body_bytes,
                       timeout_s=settings.body_timeout_s, max_document_bytes=settings.max_document_bytes,
                       data_paths=DATA_PATHS)
    security.install(app, settings)
    # Requests in progress past the limit get 503 before any work (inside the logs and metrics).
    app.add_middleware(connections.ConcurrencyLimitMiddleware, max_requests=settings.max_concurrent_requests)
    # Problems answered on the UM-Bridge paths (a refused key, a body too large, the server busy) in its
    # error form: outside every middleware that may refuse.
    app.add_middleware(umbridge.ProtocolErrorMiddleware)
    observability.install(app)
    for router in ROUTERS:
        app.include_router(router)
    # Checked first: a plain route costs one regular-expression match to the routes it does not serve.
    app.router.routes[:0] = plain_routes(ROUTERS)

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            app.openapi_schema = security.document_openapi(
                problems.rewrite_openapi(add_raw_body_schemas(FastAPI.openapi(app))))
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
    return app


app = create_app()
