"""A cheap structural check of every JSON request body, before any route parses it.

Parsers build the whole document before a schema can refuse it: a batch of 20 million points
written as ``[1,1,1,...]`` (40 MB, under the body limit) costs tens of seconds and gigabytes
inside pydantic before the point limit answers 413, and a list of millions of wrong values
makes as many error objects. :class:`JsonGuardMiddleware` looks at the raw text first and
answers, as problems:

* 400 when the body is not UTF-8, nests deeper than :data:`MAX_DEPTH` arrays and objects, or
  repeats a key within one object (RFC 8259 leaves duplicates to the parser: Python keeps the
  last, others the first; refusing them removes the ambiguity);
* 413 when one array or object holds more than ``max_items`` elements, or the body holds more
  than ``max_items`` strings or containers.

The scan touches each byte in C (regular expressions and ``str.count``) and runs Python code
only per string and bracket, of which a numeric batch has a handful; it does not check the
rest of the grammar, which the route's parser does. Bodies with another content type (CSV,
multipart) pass untouched; a body without a content type is checked, because FastAPI reads it
as JSON.
"""

from __future__ import annotations

import json
import re

from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from .problems import VALIDATION_TYPE, ProblemError, ProblemResponse

__all__ = ["MAX_DEPTH", "JsonGuardMiddleware", "check_json_structure"]

#: Deepest nesting of arrays and objects accepted [1]; the API's own bodies nest at most 4 deep.
MAX_DEPTH = 64

#: Bodies up to this size [bytes] are checked on the event loop; larger ones in a worker thread.
_INLINE_BYTES = 64 * 1024

# A whole string (with escapes) and whether a colon follows it (a key), or a bracket.
_TOKEN = re.compile(r'"(?:[^"\\]|\\.)*"(\s*:)?|[\[\]{}]', re.DOTALL)


def _too_large(detail: str) -> ProblemError:
    return ProblemError(413, detail, title="Request too large")


def _malformed(detail: str) -> ProblemError:
    return ProblemError(400, detail, title="Malformed JSON", type_=VALIDATION_TYPE)


def check_json_structure(body: bytes, max_items: int, max_depth: int = MAX_DEPTH) -> None:
    """Refuse a JSON body that is not UTF-8, too deep, too long or has duplicate keys.

    Parameters
    ----------
    body : bytes
        The raw request body.
    max_items : int
        Most elements of one array or object, and most strings and containers in the body [1].
    max_depth : int, default 64
        Deepest nesting of arrays and objects [1].

    Raises
    ------
    ProblemError
        400 (not UTF-8, too deep, duplicate key) or 413 (too many elements), naming the place.
    """
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise _malformed(f"The request body is not valid UTF-8 (byte {exc.start}).") from None
    strings = text.count('"') // 2
    containers = text.count("[") + text.count("{")
    if strings > max_items or containers > max_items:
        raise _too_large(f"The body holds more than {max_items} strings or arrays and objects.")
    # Each open container: [is_object, commas so far, end of its last child token, keys seen].
    stack: list[list] = []
    for token in _TOKEN.finditer(text):
        start = token.start()
        char = text[start]
        if stack:
            top = stack[-1]
            top[1] += text.count(",", top[2], start)
        if char == '"':
            if stack:
                top[2] = token.end()
                if token.group(1) and top[0]:
                    try:
                        key = json.loads(text[start:token.end(1)].rstrip(": \t\r\n"))
                    except ValueError:
                        raise _malformed(f"The key at character {start} is not a JSON string.") from None
                    if key in top[3]:
                        raise _malformed(f"The key {key[:100]!r} appears twice in one object.")
                    top[3].add(key)
        elif char in "[{":
            if len(stack) >= max_depth:
                raise _malformed(f"The body nests arrays and objects more than {max_depth} deep.")
            stack.append([char == "{", 0, token.end(), set()])
        elif stack:
            closed = stack.pop()
            if closed[1] + 1 > max_items:
                kind = "An object" if closed[0] else "An array"
                raise _too_large(f"{kind} in the body has more than {max_items} elements; the limit is "
                                 f"{max_items} (MICROBEARING_MAX_BATCH_POINTS).")
            if stack:
                stack[-1][2] = token.end()
    if stack and stack[-1][1] + 1 > max_items:  # an unterminated container (the parser says 400)
        raise _too_large(f"An array or object in the body has more than {max_items} elements.")


def _is_json(content_type: bytes | None) -> bool:
    if content_type is None:
        return True
    media = content_type.split(b";", 1)[0].strip().lower()
    return media == b"application/json" or (media.startswith(b"application/") and media.endswith(b"+json"))


class JsonGuardMiddleware:
    """Check JSON request bodies with :func:`check_json_structure` before the app reads them.

    Install it inside the body-size limit (added before it), so that the body it buffers is
    already bounded.

    Parameters
    ----------
    app : ASGI app
        The wrapped application.
    max_items : int
        Most elements of one array or object [1].
    """

    def __init__(self, app: ASGIApp, max_items: int):
        self.app = app
        self.max_items = max_items

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or not _is_json(dict(scope["headers"]).get(b"content-type")):
            await self.app(scope, receive, send)
            return
        chunks: list[bytes] = []
        try:
            while True:
                message = await receive()
                if message["type"] != "http.request":
                    break  # the client left; the app will see the disconnect
                chunks.append(message.get("body", b""))
                if not message.get("more_body", False):
                    break
        except HTTPException as exc:  # the body-size limit, counting a streamed body
            problem = ProblemError(exc.status_code, str(exc.detail))
            await self._answer(problem, scope, receive, send)
            return
        body = b"".join(chunks)
        if body:
            try:
                if len(body) <= _INLINE_BYTES:
                    check_json_structure(body, self.max_items)
                else:
                    await run_in_threadpool(check_json_structure, body, self.max_items)
            except ProblemError as problem:
                await self._answer(problem, scope, receive, send)
                return
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        await self.app(scope, replay, send)

    @staticmethod
    async def _answer(problem: ProblemError, scope: Scope, receive: Receive, send: Send) -> None:
        response = ProblemResponse(problem.to_dict(instance=scope.get("path")), status_code=problem.status)
        await response(scope, receive, send)
