"""The ASGI application: ``service.app:app``, built by :func:`create_app`.

``create_app(settings)`` wires the pieces: settings (:mod:`service.settings`), problem+json
errors (:mod:`service.problems`), the request-body limit (:mod:`service.limits`, a 413
problem), the SQLite store and job manager (:mod:`service.deps`, opened at startup or
on first use) and one router per resource from :data:`ROUTERS`. See :mod:`service.routes` for
how to add a resource.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import FastAPI
from fastapi_offline import FastAPIOffline
from starlette.routing import Match
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from . import observability, problems, security
from .deps import close_runtime, get_runtime
from .jsonguard import JsonGuardMiddleware
from .limits import BodySizeLimitMiddleware
from .routes import calibrations, friction, jobs, meta, optimizations, surrogates, sweeps
from .routes.meta import package_version
from .schemas.base import add_raw_body_schemas
from .settings import Settings

__all__ = ["ROUTERS", "HeadMiddleware", "app", "create_app"]

#: The routers of every resource, in the order of the OpenAPI spec. Add yours here.
ROUTERS = [meta.router, friction.router, sweeps.router, jobs.router, calibrations.router, surrogates.router,
           optimizations.router]

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


@asynccontextmanager
async def _lifespan(app: FastAPI) -> AsyncIterator[None]:
    get_runtime(app)  # open the database and recover interrupted jobs before serving
    try:
        yield
    finally:
        close_runtime(app)


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
    # /docs and /redoc load Swagger UI and ReDoc from the assets fastapi-offline ships, not from a CDN,
    # so they work on an isolated network.
    app = FastAPIOffline(title="microbearing", version=package_version(), description=DESCRIPTION,
                         lifespan=_lifespan, static_url=security.DOCS_ASSETS_PATH)
    app.state.settings = settings
    app.state.runtime = None
    problems.install(app)
    # Outermost last: request ids, logs and metrics see every answer; API keys are checked
    # before the body is read; the JSON check runs on a body the size limit has bounded; HEAD
    # becomes GET innermost, so logs, metrics and the key check see the method sent.
    app.add_middleware(HeadMiddleware)
    app.add_middleware(JsonGuardMiddleware, max_items=settings.max_batch_points)
    app.add_middleware(BodySizeLimitMiddleware, max_bytes=settings.max_body_bytes)
    security.install(app, settings)
    observability.install(app)
    for router in ROUTERS:
        app.include_router(router)

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            app.openapi_schema = security.document_openapi(
                problems.rewrite_openapi(add_raw_body_schemas(FastAPI.openapi(app))))
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
    return app


app = create_app()
