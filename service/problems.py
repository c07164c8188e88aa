"""RFC 9457 problem details: every error of the API as ``application/problem+json``.

Raise :class:`ProblemError` anywhere in a route (or in code a route calls) to answer with a
problem; :func:`install` makes FastAPI turn its own errors (unknown path 404, wrong method 405
with ``Allow``, request validation 400/422, body too large 413, unexpected exceptions 500) into
problems too. :data:`PROBLEM_RESPONSES` documents the problem media type on a route::

    @router.post("/v1/things", responses=problem_responses(404, 413))

Validation problems list the offending fields in ``errors`` as JSON pointers into the request
body (``{"pointer": "/points/load_N/3", "detail": "..."}``) or, for path and query parameters,
by name (``{"parameter": "job_id", ...}``).
"""

from __future__ import annotations

import http
import json
import logging
import re
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field, ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from microbearing import physics
from microbearing.physics.columns import ColumnError, read_name

__all__ = [
    "PROBLEM_MEDIA_TYPE",
    "pointer_at",
    "FieldError",
    "Problem",
    "ProblemError",
    "ProblemResponse",
    "body_problem",
    "install",
    "truncated",
    "problem_responses",
    "validation_problem",
]

PROBLEM_MEDIA_TYPE = "application/problem+json"
VALIDATION_TYPE = "urn:microbearing:problem:validation"
INTERNAL_TYPE = "urn:microbearing:problem:internal"

logger = logging.getLogger("microbearing.service")


class FieldError(BaseModel):
    """One offending field of a request."""

    pointer: str | None = Field(
        default=None, description="JSON pointer (RFC 6901) into the request body, e.g. /load_N.")
    parameter: str | None = Field(default=None, description="Name of a path, query or header parameter.")
    detail: str = Field(description="What is wrong and what is allowed.")


class Problem(BaseModel):
    """An error as RFC 9457 problem details."""

    model_config = ConfigDict(extra="allow")

    type: str = Field(default="about:blank", description="URI identifying the kind of problem.")
    title: str = Field(description="Short summary of the kind of problem.")
    status: int = Field(ge=100, le=599, description="HTTP status code [1].")
    detail: str = Field(description="Explanation of this occurrence.")
    instance: str | None = Field(default=None, description="URI of this occurrence (the request path).")
    errors: list[FieldError] | None = Field(default=None, description="Offending fields, for validation.")


class ProblemResponse(JSONResponse):
    """A JSON response with the ``application/problem+json`` media type."""

    media_type = PROBLEM_MEDIA_TYPE


class ProblemError(Exception):
    """An error that the API answers as a problem.

    Parameters
    ----------
    status : int
        HTTP status code [1].
    detail : str
        Explanation of this occurrence for the client.
    title : str, optional
        Summary of the kind of problem; the HTTP reason phrase by default.
    type_ : str, optional
        URI of the kind of problem; ``about:blank`` by default.
    errors : list of dict, optional
        Offending fields: ``{"pointer": "/load_N", "detail": "..."}``.
    headers : dict, optional
        Extra response headers.
    """

    def __init__(self, status: int, detail: str, *, title: str | None = None, type_: str = "about:blank",
                 errors: list[dict[str, str]] | None = None, headers: dict[str, str] | None = None):
        super().__init__(detail)
        self.status = status
        self.detail = detail
        self.title = title or http.HTTPStatus(status).phrase
        self.type = type_
        self.errors = errors
        self.headers = headers

    def __reduce__(self) -> tuple[Any, ...]:
        # Pickled across a process pool or a dask cluster (service/executor.py): rebuilt from
        # status and detail, with the other attributes restored as state.
        return (type(self), (self.status, self.detail), dict(vars(self)))

    def to_dict(self, instance: str | None = None) -> dict[str, Any]:
        """The problem as a JSON-ready dict, its texts cut to bounded lengths (see :func:`truncated`)."""
        body: dict[str, Any] = {"type": self.type, "title": self.title, "status": self.status,
                                "detail": truncated(self.detail, MAX_DETAIL_CHARS)}
        if instance is not None:
            body["instance"] = truncated(instance, MAX_FIELD_CHARS)
        if self.errors:
            body["errors"] = [{key: truncated(value, MAX_FIELD_CHARS) if isinstance(value, str) else value
                               for key, value in error.items()} for error in self.errors]
        return body


#: Longest ``detail`` of a problem, and longest pointer, parameter or detail of one field error
#: [characters]: a problem echoes parts of the request (a key, a value), which can be megabytes.
MAX_DETAIL_CHARS = 4000
MAX_FIELD_CHARS = 500


def truncated(text: str, limit: int) -> str:
    """``text``, or its first characters and a note of how many were left out.

    >>> truncated("abcdef", 10), truncated("a" * 30, 20)
    ('abcdef', 'aaaaaaaaaaaaaaaaaaaa... (10 more characters)')
    """
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text) - limit} more characters)"


#: Most offending fields listed in one problem, and in its detail: a body with a million bad
#: values gets a bounded answer.
MAX_LISTED_ERRORS = 100
_SUMMARIZED_ERRORS = 10
_EXAMINED_ERRORS = 10 * MAX_LISTED_ERRORS


def pointer_at(base: str, *keys: str) -> str:
    """A JSON pointer to ``keys`` below ``base``, each key one token (RFC 6901: ``~`` is ``~0``, ``/`` is
    ``~1``), so that a key as sent (``speed [mm/s]``) is one step.

    >>> pointer_at("/space", "speed [mm/s]")
    '/space/speed [mm~1s]'
    """
    return base + "".join("/" + str(k).replace("~", "~0").replace("/", "~1") for k in keys)


def validation_problem(errors: list[dict[str, str]], status: int = 422, total: int | None = None
                       ) -> ProblemError:
    """A validation problem listing offending fields.

    Parameters
    ----------
    errors : list of dict
        ``{"pointer": "/fixed/load_N", "detail": "..."}`` items.
    status : int, default 422
        HTTP status code [1].
    total : int, optional
        How many errors there were in all, when ``errors`` holds only the first ones [1].

    Returns
    -------
    ProblemError
        Ready to raise; at most :data:`MAX_LISTED_ERRORS` fields are listed.
    """
    total = max(total or 0, len(errors))
    # the whole body (pointer "") is named by no place: its detail alone
    summary = "; ".join(f"{place}: {e['detail']}" if (place := e.get('pointer', e.get('parameter', '')))
                        else e["detail"] for e in errors[:_SUMMARIZED_ERRORS])
    if total > _SUMMARIZED_ERRORS:
        summary += f"; and more ({total} errors in all, the first {min(len(errors), MAX_LISTED_ERRORS)} "
        summary += "listed in errors)"
    return ProblemError(status, f"The request is invalid: {summary}", title="Invalid request",
                        type_=VALIDATION_TYPE, errors=errors[:MAX_LISTED_ERRORS])


def problem_responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` entries documenting problems for the given status codes.

    400, 404 (no route), 405, 413, 422 and 500 can come from any route, so they are always
    included; pass extra codes a route raises itself (e.g. 404 for an unknown id).
    """
    codes = sorted({400, 404, 405, 413, 422, 500, *statuses})
    return {code: {"model": Problem, "description": http.HTTPStatus(code).phrase} for code in codes}


def _respond(request: Request, problem: ProblemError) -> ProblemResponse:
    return ProblemResponse(problem.to_dict(instance=request.url.path), status_code=problem.status,
                           headers=problem.headers)


_HTTP_METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")


def _allowed_methods(request: Request) -> list[str]:
    # Starlette reports only the first route matching the path; a path served by several
    # routes (GET and DELETE /v1/jobs/{id}) must list every method in Allow. HEAD is answered
    # wherever GET is (service.app.HeadMiddleware).
    allowed = {method for method in _HTTP_METHODS
               if any(route.matches({**request.scope, "method": method})[0] == Match.FULL
                      for route in request.app.router.routes)}
    if "GET" in allowed:
        allowed.add("HEAD")
    return [method for method in _HTTP_METHODS if method in allowed]


def _is_union_tag(part: Any) -> bool:
    # pydantic names the member of a plain union in the location ("list[constrained-float]",
    # "int", a model's class name "SpaceRange"); field names are snake_case identifiers, so such tags
    # are recognised by their form (a key of the document is never taken for one: see the caller).
    return isinstance(part, str) and ("[" in part or "-" in part or part in {"float", "int", "bool", "str"}
                                      or re.fullmatch(r"[A-Z][a-z]+(?:[A-Z][a-z]+)+", part) is not None)


def _sent_key(node: dict, name: Any) -> str | None:
    """The key of ``node`` that a physics input ``name`` was sent under (``load [mN]`` for load_N, which
    the schema renamed before validating), or None."""
    if not isinstance(name, str) or name not in physics.PARAMETERS or name in node:
        return None
    for key in node:
        try:
            if isinstance(key, str) and read_name(key).name == name:
                return key
        except ColumnError:
            continue
    return None


def _key_named(parts: list[str], document: Any, detail: str, error: dict[str, Any]) -> str | None:
    """The key of the object at ``parts`` that a validator's message starts with (``RH [mm]: the unit
    ...``), for the pointer to name it; None otherwise."""
    if error.get("type") != "value_error" or not isinstance(document, dict):
        return None
    node: Any = document
    for part in parts:
        if isinstance(node, dict) and part in node:
            node = node[part]
        elif isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        else:
            return None
    if not isinstance(node, dict):
        return None
    return next((key for key in node if isinstance(key, str) and detail.startswith(f"{key}: ")), None)


def _pointer_parts(loc: tuple[Any, ...], document: Any, renamed: dict[str, str] | None = None) -> list[str]:
    """The location parts that exist in the request document (plus a final missing key); a physics
    input renamed by the schema is named by its key as sent (recorded in ``renamed``, sent -> read)."""
    parts: list[str] = []
    node = document
    located = True
    for position, part in enumerate(loc):
        sent = _sent_key(node, part) if located and isinstance(node, dict) else None
        if sent is not None:
            (renamed if renamed is not None else {})[sent] = str(part)
            part = sent
        # a key of the document is never a tag, whatever its form (a column sent as "speed [mm]")
        if _is_union_tag(part) and not (located and isinstance(node, dict) and part in node):
            continue
        last = position == len(loc) - 1
        if located and isinstance(node, dict) and part in node:
            node = node[part]
        elif located and isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node):
            node = node[part]
        elif located and (isinstance(node, dict | list)) and not last:
            continue  # a discriminated union's tag ("grid"), not a key of the document
        else:
            located = False
        parts.append(str(part))
    return parts


def _parameter_value(parts: list[str], error: dict[str, Any]) -> Any:
    """The physics parameter whose own value (or list element) the error is about, or None.

    Its range is worth appending to the error only then: not for another field under a
    parameter's name (a sweep axis's ``num``), nor for a bound of the schema that is not the
    parameter's (``bounds.balls`` stops at 100,000 balls, the physics at a million).
    """
    names = [p for p in parts if not p.isdigit()]
    spec = physics.PARAMETERS.get(names[-1]) if names else None
    if spec is None:
        return None
    limits = [(error.get("ctx") or {}).get(key) for key in ("ge", "gt", "le", "lt")]
    if any(limit is not None and float(limit) not in (spec.minimum, spec.maximum) for limit in limits):
        return None
    return spec


def _as_sent(sent: str, read: str, spec: Any, value: Any) -> str:
    """The words a refusal of a key the schema renamed ends with: the key and value as sent, as read, and
    the range in the unit sent when the key carries one (``speed [mm/s]``: "in mm/s it must be in
    [0, 1e+06]")."""
    try:
        reading = read_name(sent)
    except ColumnError:
        reading = None
    if reading is None or reading.name != read or not reading.sent_unit:
        return f" (sent as {sent}, read as {read})"
    number = isinstance(value, int | float) and not isinstance(value, bool)
    given = f": {reading.sent_value(value):g}" if number else ""
    as_read = f": {float(value):g}" if number else ""
    limit = ("" if spec is None else
             f"; in {reading.sent_unit} it must be {spec.range_text(reading.sent_value)}")
    return f" (sent as {sent}{given}, read as {read}{as_read}{limit})"


#: The fields that hold physics inputs by name (an optimization's bounds, fixed values and tolerances, a
#: surrogate's space, a sweep's ranges and axes): a key none reads there is no physics input.
_INPUT_FIELDS = {("bounds",), ("fixed",), ("tolerances",), ("space",), ("ranges",), ("axes",)}


def _in_words(error: dict[str, Any]) -> str:
    """pydantic's message of an error, said without its own terms (tags, models, "instance of")."""
    kind, ctx, message = error.get("type"), error.get("ctx") or {}, error.get("msg", "invalid")
    tag = str(ctx.get("discriminator", "")).strip("'")
    if kind == "union_tag_not_found":
        return f"{tag} is required: it says which kind of object this is"
    if kind == "union_tag_invalid":
        return f"{ctx.get('tag')!r} is not a known {tag}; choose one of {ctx.get('expected_tags')}"
    if kind == "value_error":
        return message.removeprefix("Value error, ")
    name = str((error.get("loc") or ("",))[-1])
    if kind == "extra_forbidden" and name in physics.PARAMETERS:  # a known input this field does not vary
        return f"{name} is a physics input, but not one this field takes; give it in fixed instead"
    if kind == "extra_forbidden" and tuple(error.get("loc") or ())[-2:-1] in _INPUT_FIELDS:
        return (f"{name} is no physics input (GET /v1/parameters lists them): a condition column of a "
                f"calibrated model (humidity, temperature, a specimen) goes in conditions, a calibration's "
                f"in its data")
    if kind in {"model_type", "model_attributes_type", "dict_type"}:
        return "must be an object with named fields ({...}), not " + _what(error.get("input"))
    return message


def _what(value: Any) -> str:
    """A JSON value's kind in words: ``a list``, ``a number``..."""
    if isinstance(value, list):
        return "a list"
    if isinstance(value, bool) or value is None:
        return json.dumps(value)
    if isinstance(value, int | float):
        return "a number"
    return "a string" if isinstance(value, str) else "that"


def _field_errors(exc: RequestValidationError) -> list[dict[str, str]]:
    by_place: dict[tuple[str, str], list[str]] = {}
    # Only the first errors are examined (at most MAX_LISTED_ERRORS are listed anyway): the cost
    # of answering a body with a million bad values stays bounded.
    for error in exc.errors()[:_EXAMINED_ERRORS]:
        loc = tuple(error.get("loc", ()))
        source, rest = (loc[0], loc[1:]) if loc else ("body", ())
        if error.get("type") in {"union_tag_invalid", "union_tag_not_found"}:
            rest = (*rest, str(error.get("ctx", {}).get("discriminator", "")).strip("'"))
        renamed: dict[str, str] = {}
        parts = _pointer_parts(rest, exc.body if source == "body" else None, renamed)
        detail = _in_words(error)
        spec = (None if error.get("type") == "extra_forbidden" else
                _parameter_value([renamed.get(p, p) for p in parts], error))
        if spec is not None:
            detail = f"{detail} ({spec.name} must be {spec.range_text()} [{spec.unit}])"
        for sent, read in renamed.items():  # the value given is in the unit of the name read
            detail = f"{detail}{_as_sent(sent, read, spec, error.get('input'))}"
        key = _key_named(parts, exc.body if source == "body" else None, detail, error)
        if key is not None:  # a mapping's validator refusing one of its keys ("RH [mm]: ...")
            parts = [*parts, key]
        if source == "body":
            place = ("pointer", "".join("/" + p.replace("~", "~0").replace("/", "~1") for p in parts))
        else:
            place = ("parameter", parts[0] if parts else str(source))
        by_place.setdefault(place, [])
        if detail not in by_place[place]:
            by_place[place].append(detail)
    # For a union (scalar or list) a bad list element also fails the scalar branch at the
    # field itself; the deeper pointer is the useful one.
    # Every pointer that is a parent of another (a set, not a pairwise search: a request can
    # carry a million bad list elements).
    parents = {value[:i] for kind, value in by_place if kind == "pointer"
               for i in range(len(value)) if value[i] == "/"}
    return [
        {kind: value, "detail": "; ".join(details)}
        for (kind, value), details in by_place.items()
        if kind != "pointer" or value not in parents
    ]


def body_problem(exc: ValidationError, document: Any) -> ProblemError:
    """The 422 problem of a request body that failed validation outside a route (the CLI's JSON files).

    Parameters
    ----------
    exc : pydantic.ValidationError
        The error of ``Model.model_validate(document)``.
    document : Any
        The parsed JSON document, to tell field names from union tags.
    """
    errors = [{**error, "loc": ("body", *error["loc"])} for error in exc.errors(include_url=False)]
    return validation_problem(_field_errors(RequestValidationError(errors, body=document)), total=len(errors))


async def _on_problem(request: Request, exc: ProblemError) -> ProblemResponse:
    return _respond(request, exc)


async def _on_http_exception(request: Request, exc: StarletteHTTPException) -> ProblemResponse:
    headers = dict(exc.headers or {})
    status = exc.status_code
    phrase = http.HTTPStatus(status).phrase
    detail = exc.detail if exc.detail and exc.detail != phrase else None
    if status == 404 and detail is None:
        detail = f"No resource at {request.url.path}."
    elif status == 405:
        allowed = _allowed_methods(request)
        headers["Allow"] = ", ".join(allowed)
        detail = f"{request.method} is not allowed on {request.url.path}; allowed: {', '.join(allowed)}."
    return _respond(request, ProblemError(status, detail or phrase, headers=headers or None))


async def _on_validation_error(request: Request, exc: RequestValidationError) -> ProblemResponse:
    if any(error.get("type") == "json_invalid" for error in exc.errors()):
        problem = ProblemError(400, "The request body is not valid JSON.", title="Malformed JSON",
                               type_=VALIDATION_TYPE)
        return _respond(request, problem)
    whole = _whole_body_problem(request, exc)
    if whole is not None:
        return _respond(request, whole)
    return _respond(request, validation_problem(_field_errors(exc), total=len(exc.errors())))


def _whole_body_problem(request: Request, exc: RequestValidationError) -> ProblemError | None:
    """The problem of a JSON body that is missing or was not sent as JSON (the schema then read no field):
    422 saying the body is missing; 415 naming the media type sent; None for other errors."""
    errors = exc.errors()
    if len(errors) != 1 or tuple(errors[0].get("loc", ())) != ("body",):
        return None
    media = request.headers.get("content-type", "").split(";")[0].strip()
    if errors[0].get("type") == "missing":
        return validation_problem([{"pointer": "", "detail": "the request has no body: send a JSON object "
                                                             "with Content-Type: application/json"}])
    if isinstance(errors[0].get("input"), bytes) and media != "application/json":
        return not_json_problem(media)
    return None


def not_json_problem(media_type: str) -> ProblemError:
    """The 415 problem of a body sent as another media type than JSON (``""``: none declared)."""
    sent = repr(media_type[:100].lower()) if media_type else "a body without a Content-Type"
    return ProblemError(415, f"The body must be application/json, not {sent}.",
                        title="Unsupported Media Type", headers={"Accept": "application/json"})


async def _on_unexpected(request: Request, exc: Exception) -> ProblemResponse:
    logger.exception("unexpected error on %s %s", request.method, request.url.path)
    problem = ProblemError(500, "The server failed to handle the request; the error is logged.",
                           type_=INTERNAL_TYPE)
    return _respond(request, problem)


def install(app: FastAPI) -> None:
    """Answer every error of ``app`` as a problem and document problems in its OpenAPI spec."""
    app.add_exception_handler(ProblemError, _on_problem)
    app.add_exception_handler(StarletteHTTPException, _on_http_exception)
    app.add_exception_handler(RequestValidationError, _on_validation_error)
    app.add_exception_handler(Exception, _on_unexpected)


def rewrite_openapi(spec: dict[str, Any]) -> dict[str, Any]:
    """Give every error response of ``spec`` the problem media type and schema.

    FastAPI documents error models as ``application/json`` and adds its own
    ``HTTPValidationError``; the API answers ``application/problem+json`` with :class:`Problem`.
    """
    ref = {"$ref": "#/components/schemas/Problem"}
    for path_item in spec.get("paths", {}).values():
        for operation in path_item.values():
            for code, response in operation.get("responses", {}).items():
                if code.isdigit() and int(code) >= 400:
                    response["content"] = {PROBLEM_MEDIA_TYPE: {"schema": ref}}
                    response["description"] = http.HTTPStatus(int(code)).phrase
    schemas = spec.get("components", {}).get("schemas", {})
    for unused in ("HTTPValidationError", "ValidationError"):
        schemas.pop(unused, None)
    return spec
