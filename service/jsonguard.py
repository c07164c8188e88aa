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
  than ``max_items`` strings or containers;
* 400 for any request with more than one ``Content-Type`` header: this check and the app could
  otherwise read different ones (Starlette reads the first), and a JSON body declared as
  something else too would skip the check.

The scan finds quotes, brackets, commas and colons with NumPy and runs Python code only per
bracket and per object key, of which a numeric batch has a handful (a 2-million-point batch is
checked in a fraction of its parsing time); it does not check the rest of the grammar, which
the route's parser does. Bodies with another content type (CSV,
multipart) pass untouched; a body without a content type is checked, because FastAPI reads it
as JSON.
"""

from __future__ import annotations

import json
import re

import numpy as np
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from .problems import VALIDATION_TYPE, ProblemError, ProblemResponse

__all__ = ["MAX_DEPTH", "JsonGuardMiddleware", "check_json_structure", "is_json_media_type"]

#: Deepest nesting of arrays and objects accepted [1]; the API's own bodies nest at most 4 deep.
MAX_DEPTH = 64

#: Bodies up to this size [bytes] are checked on the event loop; larger ones in a worker thread.
_INLINE_BYTES = 64 * 1024


def _too_large(detail: str) -> ProblemError:
    return ProblemError(413, detail, title="Request too large")


def _malformed(detail: str) -> ProblemError:
    return ProblemError(400, detail, title="Malformed JSON", type_=VALIDATION_TYPE)


_QUOTE, _COLON, _BACKSLASH = ord('"'), ord(":"), ord("\\")
_OPENERS = frozenset(b"[{")
#: Bytes that matter to the structure: quotes and brackets.
_STRUCTURAL = np.zeros(256, dtype=bool)
_STRUCTURAL[list(b'"[]{}')] = True


#: A JSON string without escapes, and the colon after it when it is an object's key.
_STRING = re.compile(r'"([^"]*)"(\s*:)?')


class _DuplicateKeyError(ValueError):
    pass


def _unique_keys(pairs: list[tuple[str, object]]) -> dict[str, object]:
    document = dict(pairs)
    if len(document) != len(pairs):
        seen: set[str] = set()
        repeated = next(key for key, _ in pairs if key in seen or seen.add(key))
        raise _DuplicateKeyError(f"The key {repeated[:100]!r} appears twice in one object.")
    return document


def _unescaped_quotes(body: bytes, quotes: np.ndarray) -> np.ndarray:
    if b"\\" not in body:
        return quotes
    keep = []
    for position in quotes.tolist():  # rare: only bodies with escapes pay for this loop
        backslashes = 0
        while position - backslashes - 1 >= 0 and body[position - backslashes - 1] == _BACKSLASH:
            backslashes += 1
        if backslashes % 2 == 0:
            keep.append(position)
    return np.asarray(keep, dtype=np.int64)


def _outside_strings(positions: np.ndarray, quotes: np.ndarray) -> np.ndarray:
    # A position is outside every string when an even number of quotes precede it.
    return positions[np.searchsorted(quotes, positions) % 2 == 0]


def _commas_per_container(body: bytes, brackets: list[int], enclosing_after: list[int], quotes: list[int],
                          containers: int) -> list[int]:
    """Commas directly inside each container, outside strings, counted gap by gap between brackets."""
    counts = [0] * containers
    string = 0  # index of the next string (pair of quotes) not yet passed
    previous = 0
    for index, position in enumerate(brackets):
        owner = enclosing_after[index - 1] if index else -1
        commas = body.count(b",", previous, position) if owner >= 0 else 0
        while string < len(quotes) // 2 and quotes[2 * string] < position:
            if owner >= 0:
                commas -= body.count(b",", quotes[2 * string], quotes[2 * string + 1])
            string += 1
        if owner >= 0:
            counts[owner] += commas
        previous = position + 1
    return counts


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
    containers = body.count(b"[") + body.count(b"{")
    if (len(body) <= _INLINE_BYTES and containers <= max_depth
            and max(body.count(b",") + 1, body.count(b'"') // 2, containers) <= max_items):
        # Small and shallow, so no limit can be passed: only duplicate keys remain to be found,
        # and the stdlib parser finds them faster than the scan below. One flat object without
        # escapes (a single point's body) needs no parser: its keys are its strings before a colon,
        # compared as written.
        if containers == 1 and b"\\" not in body:
            keys = [string for string, colon in _STRING.findall(text) if colon]
            if len(set(keys)) == len(keys):
                return
        try:
            json.loads(text, object_pairs_hook=_unique_keys)
        except ValueError as exc:
            if isinstance(exc, _DuplicateKeyError):
                raise _malformed(str(exc)) from None
        return
    data = np.frombuffer(body, dtype=np.uint8)
    special = np.flatnonzero(_STRUCTURAL[data])
    kinds = data[special]
    quotes = _unescaped_quotes(body, special[kinds == _QUOTE])
    if len(quotes) % 2:
        return  # an unterminated string: the parser answers 400
    brackets = _outside_strings(special[kinds != _QUOTE], quotes)
    if len(quotes) // 2 > max_items or len(brackets) > 2 * max_items:
        raise _too_large(f"The body holds more than {max_items} strings or arrays and objects.")

    # One pass over the brackets: depth, and which container encloses what follows each bracket.
    enclosing_after = np.empty(len(brackets), dtype=np.int64)
    open_ids: list[int] = []
    container_kinds: list[int] = []
    for index, position in enumerate(brackets.tolist()):
        if body[position] in _OPENERS:
            if len(open_ids) >= max_depth:
                raise _malformed(f"The body nests arrays and objects more than {max_depth} deep.")
            open_ids.append(len(container_kinds))
            container_kinds.append(body[position])
        elif open_ids:
            open_ids.pop()
        enclosing_after[index] = open_ids[-1] if open_ids else -1
    if not container_kinds:
        return

    def container_of(positions: np.ndarray) -> np.ndarray:
        before = np.searchsorted(brackets, positions) - 1
        return np.where(before >= 0, enclosing_after[np.maximum(before, 0)], -1)

    if body.count(b",") + 1 > max_items:  # only then can one container hold too many elements
        counts = _commas_per_container(body, brackets.tolist(), enclosing_after.tolist(), quotes.tolist(),
                                       len(container_kinds))
        if max(counts) + 1 > max_items:
            kind = "An object" if container_kinds[counts.index(max(counts))] == ord("{") else "An array"
            raise _too_large(f"{kind} in the body has more than {max_items} elements; the limit is "
                             f"{max_items} (MICROBEARING_MAX_BATCH_POINTS).")

    # Keys: the strings that a colon (outside strings) follows.
    colons = _outside_strings(np.flatnonzero(data == _COLON), quotes)
    closing = quotes[1::2]
    key_index = np.searchsorted(closing, colons) - 1
    key_index = key_index[key_index >= 0]
    seen: dict[int, set[str]] = {}
    for string_index, owner in zip(key_index.tolist(), container_of(quotes[0::2][key_index]).tolist(),
                                   strict=True):
        literal = body[quotes[2 * string_index]:quotes[2 * string_index + 1] + 1]
        try:
            key = json.loads(literal)
        except ValueError:
            raise _malformed(f"The key at byte {quotes[2 * string_index]} is not a JSON string.") from None
        keys = seen.setdefault(owner, set())
        if key in keys:
            raise _malformed(f"The key {key[:100]!r} appears twice in one object.")
        keys.add(key)


def is_json_media_type(content_type: bytes | None) -> bool:
    """Whether a ``Content-Type`` value declares JSON (``application/json`` or ``application/*+json``);
    a missing one (None) counts as JSON, as FastAPI reads such a body as JSON.

    >>> [is_json_media_type(v) for v in (b"application/json; charset=utf-8", b"application/problem+json",
    ...                                  b"text/csv", None)]
    [True, True, False, True]
    """
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
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        content_types = [value for name, value in scope["headers"] if name.lower() == b"content-type"]
        if len(content_types) == 1 and not is_json_media_type(content_types[0]):
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
        except HTTPException as exc:  # the body's size or time limit (service.limits)
            problem = ProblemError(exc.status_code, str(exc.detail), headers=exc.headers)
            await self._answer(problem, scope, receive, send)
            return
        if len(content_types) > 1:  # answered once the body is read: a client may not read before it sent all
            problem = ProblemError(400, f"The request has {len(content_types)} Content-Type headers; "
                                        "send one.", title="Ambiguous content type", type_=VALIDATION_TYPE)
            await self._answer(problem, scope, receive, send)
            return
        body = b"".join(chunks)
        del chunks  # the pieces: only the joined body is kept
        if body:
            try:
                if len(body) <= _INLINE_BYTES:
                    check_json_structure(body, self.max_items)
                else:
                    await run_in_threadpool(check_json_structure, body, self.max_items)
            except ProblemError as problem:
                await self._answer(problem, scope, receive, send)
                return
        # Handed to the app once and not kept here: the app may free a large body once it is parsed.
        pending = [body]
        del body

        async def replay() -> Message:
            if pending:
                return {"type": "http.request", "body": pending.pop(), "more_body": False}
            return await receive()

        await self.app(scope, replay, send)

    @staticmethod
    async def _answer(problem: ProblemError, scope: Scope, receive: Receive, send: Send) -> None:
        response = ProblemResponse(problem.to_dict(instance=scope.get("path")), status_code=problem.status,
                                   headers=problem.headers)
        await response(scope, receive, send)
