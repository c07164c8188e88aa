"""API keys: with ``MICROBEARING_API_KEYS`` set, every request needs ``Authorization: Bearer <key>``.

The keys are a comma-separated list (``MICROBEARING_API_KEYS=key-one,key-two``); several keys let
an operator rotate them without downtime. When the list is empty the API is open.

Which paths are protected: everything except :data:`OPEN_PATHS` (deny by default, so a router
added later is protected without any change here). The open paths are the liveness probe
``/healthz``, the Prometheus scrape endpoint ``/metrics`` (counts and latencies by route
template only: no request data, no keys; expose it on a trusted network, as usual for
Prometheus targets) and the API description (``/openapi.json``, ``/docs``, ``/redoc`` and their
assets under ``/docs/assets``), which holds no data either; the readiness probe ``/readyz`` is open too,
and so are the files of the lab's page under ``/ui/`` (:data:`service.routes.web.PAGE_PATHS`: no data; the
API calls the page makes carry the key the user gives it) and the manual under ``/manual/``
(:data:`OPEN_PATH_PREFIXES`: the docs site, no data).

Ownership: a request with a valid key runs with :data:`service.store.REQUESTER` set to that key's
id (the first 16 hex digits of its SHA-256; the key itself is never stored), so the jobs,
surrogates and calibrations it creates belong to the key, and it sees only those (others get
404). ``MICROBEARING_ADMIN_API_KEY`` is accepted too and sees everything. Without keys every
request sees every row, as before keys existed.

On the UM-Bridge protocol's paths (:mod:`service.umbridge`) the key may also come as HTTP Basic
credentials (the password, or the user name when there is no password), which UM-Bridge clients
send from a URL such as ``http://umbridge:KEY@host:8000/umbridge``.

A missing, malformed or unknown key is answered ``401`` as ``application/problem+json`` with a
``WWW-Authenticate: Bearer`` challenge (RFC 6750), before the body is read. The presented key is
hashed with SHA-256 and compared with :func:`hmac.compare_digest` against the hash of *every*
configured key, without stopping at a match: the time taken depends neither on which key
matched nor on the length of the keys. Keys are never logged; the settings hold them as a
:class:`pydantic.SecretStr`.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import hmac
import logging
from typing import Any

from fastapi import FastAPI
from starlette.types import ASGIApp, Receive, Scope, Send

from .limits import app_path
from .problems import PROBLEM_MEDIA_TYPE, ProblemError, ProblemResponse
from .routes.manual import PREFIX as MANUAL_PREFIX
from .routes.web import PAGE_PATHS
from .schemas.umbridge import PREFIX as UMBRIDGE_PREFIX
from .settings import Settings
from .store import REQUESTER, Requester

__all__ = ["ANONYMOUS", "DOCS_ASSETS_PATH", "OPEN_PATHS", "OPEN_PATH_PREFIXES", "SECURITY_SCHEME_NAME",
           "UMBRIDGE_METADATA_PATHS", "ApiKeyMiddleware", "app_path", "document_openapi", "install", "key_id",
           "parse_api_keys"]

logger = logging.getLogger("microbearing.service.security")

#: Where the Swagger UI and ReDoc assets are served from the package (no CDN; see service.app).
DOCS_ASSETS_PATH = "/docs/assets"
_DOCS_ASSETS = ("swagger-ui-bundle.js", "swagger-ui.css", "redoc.standalone.js", "favicon.png")

#: Paths answered without a key (relative to the ASGI root path).
OPEN_PATHS = frozenset({"/healthz", "/readyz", "/metrics", "/openapi.json", "/docs", "/docs/oauth2-redirect",
                        "/redoc", *(f"{DOCS_ASSETS_PATH}/{name}" for name in _DOCS_ASSETS), *PAGE_PATHS,
                        MANUAL_PREFIX})
#: Folders whose every path is answered without a key: the manual's pages (built files, no data).
OPEN_PATH_PREFIXES = (f"{MANUAL_PREFIX}/",)

#: UM-Bridge paths a client calls before it evaluates (models, support, sizes). Without a valid key
#: they answer for the plain physics only (never a stored model), so that the stock clients reach
#: Evaluate and show its 401 in the protocol's error form instead of failing on a missing field.
UMBRIDGE_METADATA_PATHS = frozenset(f"{UMBRIDGE_PREFIX}/{name}"
                                    for name in ("Info", "ModelInfo", "InputSizes", "OutputSizes"))
#: Who asks for UM-Bridge metadata without a valid key: sees the physics only.
ANONYMOUS = Requester(key_id="anonymous", sees_all=False)

#: Name of the bearer scheme in the OpenAPI spec.
SECURITY_SCHEME_NAME = "ApiKeyBearer"

AUTH_TYPE = "urn:microbearing:problem:unauthorized"


def parse_api_keys(text: str) -> tuple[str, ...]:
    """The keys of a comma-separated list, stripped of blanks; empty items are ignored.

    Parameters
    ----------
    text : str
        E.g. ``"key-one, key-two"``.

    Returns
    -------
    tuple of str
        The keys, in order.

    Raises
    ------
    ValueError
        When a key contains whitespace or a non-printable or non-ASCII character, which an
        ``Authorization`` header could not carry.
    """
    keys = tuple(key.strip() for key in text.split(",") if key.strip())
    for position, key in enumerate(keys):
        if not all(33 <= ord(char) <= 126 for char in key):
            raise ValueError(f"MICROBEARING_API_KEYS: key number {position + 1} must consist of printable "
                             "ASCII characters without spaces or commas")
    return keys


def _digest(token: bytes) -> bytes:
    return hashlib.sha256(token).digest()


def key_id(key: str) -> str:
    """The id under which a key owns rows: the first 16 hex digits of its SHA-256.

    >>> key_id("alpha-key-0123456789") == key_id("alpha-key-0123456789") != key_id("beta-key")
    True
    """
    return _digest(key.encode("ascii")).hex()[:16]


def _bearer_token(headers: list[tuple[bytes, bytes]], basic: bool = False) -> bytes | None:
    """The token of the first ``Authorization: Bearer`` header, or None.

    With ``basic``, ``Authorization: Basic`` credentials are read too: the key is the password, or
    the user name when the password is empty (``http://user:KEY@host/`` or ``http://KEY@host/``).
    """
    for name, value in headers:
        if name.lower() == b"authorization":
            scheme, _, token = value.strip().partition(b" ")
            token = token.strip()
            if scheme.lower() == b"bearer" and token:
                return token
            if basic and scheme.lower() == b"basic" and token:
                try:
                    user, _, password = base64.b64decode(token, validate=True).partition(b":")
                except binascii.Error:
                    return None
                return password or user or None
            return None
    return None


class ApiKeyMiddleware:
    """Refuse requests outside :data:`OPEN_PATHS` that lack a configured bearer key.

    Parameters
    ----------
    app : ASGI app
        The wrapped application.
    keys : sequence of str
        Accepted keys; when empty (and no admin key) every request passes.
    admin_key : str, optional
        A key that sees every key's rows.
    """

    def __init__(self, app: ASGIApp, keys: tuple[str, ...], admin_key: str = ""):
        self.app = app
        self._digests = tuple(_digest(key.encode("ascii")) for key in (*keys, *filter(None, [admin_key])))
        self._admin = len(self._digests) - 1 if admin_key else -1

    def _requester(self, token: bytes | None) -> Requester | None:
        """Who presents ``token``, or None when it is no configured key."""
        presented = _digest(token or b"")
        matched = -1
        for index, expected in enumerate(self._digests):  # every key, no early exit: the time reveals nothing
            if hmac.compare_digest(presented, expected):
                matched = index
        if matched < 0 or token is None:
            return None
        return Requester(key_id=presented.hex()[:16], sees_all=matched == self._admin)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or not self._digests:
            await self.app(scope, receive, send)
            return
        path = app_path(scope)
        if path in OPEN_PATHS or path.startswith(OPEN_PATH_PREFIXES):
            await self.app(scope, receive, send)
            return
        # UM-Bridge clients cannot set headers; the requests library under the Python one sends
        # the credentials of the URL as HTTP Basic.
        token = _bearer_token(scope["headers"], basic=path.startswith(UMBRIDGE_PREFIX + "/"))
        requester = self._requester(token)
        if requester is None and path in UMBRIDGE_METADATA_PATHS:
            requester = ANONYMOUS
        if requester is not None:
            reset = REQUESTER.set(requester)
            try:
                await self.app(scope, receive, send)
            finally:
                REQUESTER.reset(reset)
            return
        if token is None and path.startswith(UMBRIDGE_PREFIX + "/"):
            detail = ("This API needs a key: put it in the URL as the password, "
                      "http://umbridge:<key>@host:port/umbridge (or send 'Authorization: Bearer <key>').")
            challenge = 'Bearer realm="microbearing"'
        elif token is None:
            detail = "This API needs a key: send the header 'Authorization: Bearer <key>'."
            challenge = 'Bearer realm="microbearing"'
        else:
            detail = "The API key is not valid."
            challenge = 'Bearer realm="microbearing", error="invalid_token"'
        reason = "missing" if token is None else "invalid"
        logger.warning("refused a request without a valid API key",
                       extra={"method": scope.get("method"), "path": path[:200], "reason": reason})
        problem = ProblemError(401, detail, type_=AUTH_TYPE, headers={"WWW-Authenticate": challenge})
        response = ProblemResponse(problem.to_dict(instance=scope["path"]), status_code=401,
                                   headers=problem.headers)
        await response(scope, receive, send)


def install(app: FastAPI, settings: Settings) -> None:
    """Require the keys of ``settings.api_keys`` or the admin key on ``app`` (no-op while there are none)."""
    admin = parse_api_keys(settings.admin_api_key.get_secret_value())
    if len(admin) > 1:
        raise ValueError("MICROBEARING_ADMIN_API_KEY must hold one key")
    app.add_middleware(ApiKeyMiddleware, keys=parse_api_keys(settings.api_keys.get_secret_value()),
                       admin_key=admin[0] if admin else "")


def document_openapi(spec: dict[str, Any]) -> dict[str, Any]:
    """Declare the bearer scheme, and a 401 problem, on every operation outside :data:`OPEN_PATHS`.

    Generated clients then send ``Authorization: Bearer <key>`` (e.g. openapi-python-client's
    ``AuthenticatedClient(base_url, token=key)``). The server asks for it only when keys are
    configured.
    """
    components = spec.setdefault("components", {})
    components.setdefault("securitySchemes", {})[SECURITY_SCHEME_NAME] = {
        "type": "http", "scheme": "bearer",
        "description": "An API key from MICROBEARING_API_KEYS, required when the server has keys.",
    }
    unauthorized = {
        "description": "Unauthorized",
        "headers": {"WWW-Authenticate": {"description": "The Bearer challenge (RFC 6750).",
                                         "schema": {"type": "string"}}},
        "content": {PROBLEM_MEDIA_TYPE: {"schema": {"$ref": "#/components/schemas/Problem"}}},
    }
    for path, path_item in spec.get("paths", {}).items():
        if path in OPEN_PATHS:
            continue
        for operation in path_item.values():
            if isinstance(operation, dict) and "responses" in operation:
                operation["security"] = [{SECURITY_SCHEME_NAME: []}]
                operation["responses"]["401"] = unauthorized
    return spec
