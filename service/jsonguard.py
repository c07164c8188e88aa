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
  than ``max_values`` strings or containers (by default ``max_items``; the app sets it from the batch
  and calibration limits, so that no body those allow is refused here);
* 400 for any request with more than one ``Content-Type`` header: this check and the app could
  otherwise read different ones (Starlette reads the first), and a JSON body declared as
  something else too would skip the check.

The scan finds quotes, brackets, commas and colons with NumPy and runs Python code only per
bracket and per object key, of which a numeric batch has a handful (a 2-million-point batch is
checked in a fraction of its parsing time); it does not check the rest of the grammar, which
the route's parser does. A CSV body, and a multipart/form-data upload (a CSV file sent by a
browser's form or ``curl -F``), have their lines' length checked (:class:`CsvLineScanner`), and so do
bodies of any other type, which the CSV routes read as CSV (``application/octet-stream``); a body without
a content type, or on the paths the middleware is told read JSON whatever the type (UM-Bridge's), is
checked as JSON.
"""

from __future__ import annotations

import codecs
import json
import re
from dataclasses import dataclass

import numpy as np
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from .limits import app_path
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


_QUOTE, _COLON, _COMMA, _BACKSLASH, _NEWLINE = (ord(c) for c in '":,\\\n')
_OPEN_OBJECT = ord("{")
_OPENERS = frozenset(b"[{")
#: Bytes that matter to the structure: quotes, brackets, commas and colons.
_MARKED = np.zeros(256, dtype=bool)
_MARKED[list(b'"[]{},:')] = True
_BRACKET = np.zeros(256, dtype=bool)
_BRACKET[list(b"[]{}")] = True


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


def _unescaped(block: bytes, quotes: np.ndarray, carried_backslashes: int) -> np.ndarray:
    """The quotes of ``block`` no odd run of backslashes escapes (a run may begin in an earlier block)."""
    if not len(quotes) or (b"\\" not in block and not carried_backslashes):
        return quotes
    keep = []
    for position in quotes.tolist():  # rare: only blocks with escapes pay for this loop
        backslashes = 0
        while position - backslashes - 1 >= 0 and block[position - backslashes - 1] == _BACKSLASH:
            backslashes += 1
        if backslashes == position:  # the run reaches the block's start: it goes on before it
            backslashes += carried_backslashes
        if backslashes % 2 == 0:
            keep.append(position)
    return np.asarray(keep, dtype=np.int64)


def _trailing_backslashes(block: bytes, carried: int) -> int:
    run = len(block) - len(block.rstrip(b"\\"))
    return run + carried if run == len(block) else run


@dataclass
class _Container:
    """An array or object open at the scanner's position."""

    kind: int
    commas: int = 0
    keys: set[str] | None = None


class JsonScanner:
    """The structure check of a JSON body fed block by block, as it arrives.

    Each :meth:`feed` looks at one block with NumPy, carrying what it needs across blocks (inside a
    string or not, a run of backslashes, the open containers and their element counts, the keys of
    open objects, the last string closed): a body past a limit is refused in the block that passes
    it, whatever comes after, and nothing of the body is kept. :meth:`close` checks the end.

    Parameters
    ----------
    max_items : int
        Most elements of one array or object [1].
    max_depth : int, default 64
        Deepest nesting of arrays and objects [1].
    max_string_bytes : int, optional
        Longest string, quotes and escapes included [bytes] (``MICROBEARING_MAX_FIELD_BYTES``).
    max_values : int, optional
        Most strings and containers in the body [1] (default ``max_items``).
    max_members : int, optional
        Most members of one object [1] (default ``max_items``): the app's objects are its schemas' and a
        calibration row's, so millions of keys are refused at once, not after each is read.
    max_objects : int, optional
        Most objects in the body [1] (default ``max_values``): only a calibration's rows come in thousands.

    Raises
    ------
    ProblemError
        From :meth:`feed` or :meth:`close`: 400 (not UTF-8, too deep, duplicate key) or 413 (too
        many elements, a string too long), naming the place or the setting.
    """

    #: Longest object key whose duplicates are looked for [bytes]; longer keys are refused.
    max_key_bytes = 65_536

    def __init__(self, max_items: int, max_depth: int = MAX_DEPTH, max_string_bytes: int | None = None,
                 max_values: int | None = None, max_members: int | None = None,
                 max_objects: int | None = None):
        self.max_items = max_items
        self.max_values = max_items if max_values is None else max_values
        self.max_members = max_items if max_members is None else max_members
        self.max_objects = self.max_values if max_objects is None else max_objects
        self._objects = 0
        self.max_depth = max_depth
        self.max_string_bytes = max_string_bytes
        self._offset = 0  # bytes fed so far
        self._decoder = codecs.getincrementaldecoder("utf-8")()
        self._in_string = False
        self._string_start = -1  # where the open string's quote is [byte]
        self._open_prefix: bytes | None = b""  # the open string so far, while short enough to be a key
        self._last_closed: bytes | None = None  # the last string closed in an earlier block, if short
        self._backslashes = 0
        self._last_mark = -1  # where the last quote or structural byte outside a string is [byte]
        self._stack: list[_Container] = []
        self._containers = 0
        self._strings = 0

    @property
    def bytes_fed(self) -> int:
        """Bytes looked at so far [bytes]."""
        return self._offset

    def feed(self, block: bytes) -> None:
        """Look at the next ``block`` of the body; raises :class:`ProblemError` past a limit."""
        if not block:
            return
        self._check_utf8(block)
        data = np.frombuffer(block, dtype=np.uint8)
        special = np.flatnonzero(_MARKED[data])
        kinds = data[special]
        quotes = _unescaped(block, special[kinds == _QUOTE], self._backslashes)
        self._backslashes = _trailing_backslashes(block, self._backslashes)
        others = special[kinds != _QUOTE]
        outside = others[(np.searchsorted(quotes, others) + self._in_string) % 2 == 0]
        closes, literals = self._strings_of(block, quotes)
        self._check_runs(len(block), outside, quotes)
        marks = data[outside]
        brackets = outside[_BRACKET[marks]]
        self._walk(block, brackets, outside[marks == _COMMA], outside[marks == _COLON], closes, literals)
        self._offset += len(block)

    def close(self) -> None:
        """Check the end of the body: its last bytes are UTF-8, and it closes every string, array and
        object it opened (a body cut short, e.g. by a Content-Length smaller than what was sent, is
        refused here instead of being parsed whole to find it out)."""
        try:
            self._decoder.decode(b"", final=True)
        except UnicodeDecodeError:
            raise _malformed(f"The request body is not valid UTF-8 (byte {self._offset}).") from None
        if self._in_string:
            raise _malformed(f"The request body ends inside a string (opened at byte {self._string_start}).")
        if self._stack:
            raise _malformed(f"The request body ends inside {len(self._stack)} unclosed arrays or objects "
                             f"(at byte {self._offset}).")

    def _check_utf8(self, block: bytes) -> None:
        buffered = len(self._decoder.getstate()[0])
        try:
            self._decoder.decode(block)
        except UnicodeDecodeError as exc:
            raise _malformed(f"The request body is not valid UTF-8 "
                             f"(byte {self._offset - buffered + exc.start}).") from None

    def _too_long(self, length: int) -> None:
        if self.max_string_bytes is not None and length > self.max_string_bytes:
            raise _too_large(f"A string in the body (at byte {self._string_start}) is longer than "
                             f"{self.max_string_bytes} bytes (MICROBEARING_MAX_FIELD_BYTES).")

    def _check_runs(self, size: int, outside: np.ndarray, quotes: np.ndarray) -> None:
        """Refuse a run of bytes between quotes and structural bytes longer than the field limit.

        Outside strings such a run is a number, a literal or whitespace, which the parser would hold
        whole; inside one it is the string's text, which :meth:`_too_long` bounds alike first.
        """
        if self.max_string_bytes is None:
            return
        base, previous = self._offset, self._last_mark
        marks = np.sort(np.concatenate((outside, quotes))) + base
        runs = np.diff(marks, prepend=previous) - 1
        if len(marks):
            self._last_mark = int(marks[-1])
        trailing = base + size - self._last_mark - 1
        longest = int(np.argmax(runs)) if len(runs) else -1
        if longest >= 0 and runs[longest] > self.max_string_bytes:
            start = (previous if longest == 0 else int(marks[longest - 1])) + 1
        elif trailing > self.max_string_bytes and not self._in_string:
            start = self._last_mark + 1
        else:
            return
        raise _too_large(f"A value or a run of whitespace in the body (at byte {start}) is longer than "
                         f"{self.max_string_bytes} bytes (MICROBEARING_MAX_FIELD_BYTES).")

    def _strings_of(self, block: bytes, quotes: np.ndarray) -> tuple[np.ndarray, list[bytes | None]]:
        """Where strings close in ``block`` and their literals (None when too long to be a key)."""
        base = self._offset
        opening = quotes[int(self._in_string)::2]
        closing = quotes[1 - int(self._in_string)::2]
        starts = np.concatenate(([self._string_start - base], opening)) if self._in_string else opening
        lengths = closing - starts[:len(closing)] + 1
        if len(lengths):
            longest = int(np.argmax(lengths))
            self._string_start = base + int(starts[longest])
            self._too_long(int(lengths[longest]))
        self._strings += len(opening)
        if self._strings > self.max_values:
            raise _too_large(_too_many_values(self.max_values))
        literals: list[bytes | None] = [None] * len(closing)
        # Only the literals a caller may need as keys are cut: those shorter than the key limit.
        for index in np.flatnonzero(lengths <= self.max_key_bytes).tolist():
            start, stop = int(starts[index]), int(closing[index]) + 1
            if start < 0:
                literals[index] = None if self._open_prefix is None else self._open_prefix + block[:stop]
            else:
                literals[index] = block[start:stop]
        open_at_end = self._in_string != bool(len(quotes) % 2)
        if open_at_end and len(quotes):  # the block's last quote opens a string it does not close
            start = int(quotes[-1])
            self._string_start = base + start
            self._open_prefix = block[start:] if len(block) - start <= self.max_key_bytes else None
        elif open_at_end and self._open_prefix is not None:  # a string open across the whole block
            self._open_prefix = (self._open_prefix + block
                                 if len(self._open_prefix) + len(block) <= self.max_key_bytes else None)
        self._in_string = open_at_end
        if open_at_end:
            self._too_long(base + len(block) - self._string_start)
        return closing, literals

    def _walk(self, block: bytes, brackets: np.ndarray, commas: np.ndarray, colons: np.ndarray,
              closes: np.ndarray, literals: list[bytes | None]) -> None:
        """Follow the brackets in order, counting the commas and reading the keys between them."""
        gaps = len(brackets) + 1
        commas_per_gap = (np.bincount(np.searchsorted(brackets, commas), minlength=gaps) if len(commas)
                          else None)
        colon_gaps = np.searchsorted(brackets, colons).tolist() if len(colons) else []
        colons_list = colons.tolist()
        # the string closed last before each colon: its key (one search for the block, not one per key)
        befores = (np.searchsorted(closes, colons) - 1).tolist() if len(colons) else []
        next_colon = 0
        for gap in range(gaps):
            top = self._stack[-1] if self._stack else None
            if commas_per_gap is not None and commas_per_gap[gap] and top is not None:
                top.commas += int(commas_per_gap[gap])
                if top.kind == _OPEN_OBJECT and top.commas + 1 > self.max_members:
                    raise _too_large(f"An object in the body has more than {self.max_members} members; the "
                                     f"limit is {self.max_members} (it follows "
                                     "MICROBEARING_MAX_CALIBRATION_COLUMNS: a row's columns).")
                if top.commas + 1 > self.max_items:
                    kind = "An object" if top.kind == _OPEN_OBJECT else "An array"
                    raise _too_large(f"{kind} in the body has more than {self.max_items} elements; the limit "
                                     f"is {self.max_items} (MICROBEARING_MAX_BATCH_POINTS).")
            while next_colon < len(colon_gaps) and colon_gaps[next_colon] == gap:
                if top is not None and top.kind == _OPEN_OBJECT:
                    before = befores[next_colon]
                    literal = literals[before] if before >= 0 else self._last_closed
                    self._key(top, colons_list[next_colon], literal)
                next_colon += 1
            if gap < len(brackets):
                self._bracket(block[int(brackets[gap])])
        if len(closes):
            self._last_closed = literals[-1]

    def _bracket(self, byte: int) -> None:
        if byte in _OPENERS:
            if len(self._stack) >= self.max_depth:
                raise _malformed(f"The body nests arrays and objects more than {self.max_depth} deep.")
            self._containers += 1
            if self._containers > self.max_values:
                raise _too_large(_too_many_values(self.max_values))
            if byte == _OPEN_OBJECT:
                self._objects += 1
                if self._objects > self.max_objects:
                    raise _too_large(f"The body holds more than {self.max_objects} objects; the limit is "
                                     f"{self.max_objects} (it follows MICROBEARING_MAX_CALIBRATION_ROWS: a "
                                     "calibration's rows).")
            self._stack.append(_Container(byte, keys=set() if byte == _OPEN_OBJECT else None))
        elif self._stack:
            self._stack.pop()

    def _key(self, container: _Container, colon: int, literal: bytes | None) -> None:
        if literal is None:
            raise _too_large(f"An object key in the body (before byte {self._offset + colon}) is longer than "
                             f"{self.max_key_bytes} bytes.")
        try:
            # without escapes a key is its text (UTF-8 already checked); json.loads costs ten times more
            key = literal[1:-1].decode("utf-8") if b"\\" not in literal else json.loads(literal)
        except ValueError:
            raise _malformed(f"The key before byte {self._offset + colon} is not a JSON string.") from None
        if not isinstance(key, str):
            raise _malformed(f"The key before byte {self._offset + colon} is not a JSON string.")
        assert container.keys is not None
        if key in container.keys:
            raise _malformed(f"The key {key[:100]!r} appears twice in one object.")
        container.keys.add(key)


#: Bytes a scan reads into blocks of at least this size before looking at them [bytes].
BLOCK_BYTES = 256 * 1024


def _too_many_values(limit: int) -> str:
    return (f"The body holds more than {limit} strings or arrays and objects (a limit that follows "
            "MICROBEARING_MAX_BATCH_POINTS and MICROBEARING_MAX_CALIBRATION_ROWS x _COLUMNS).")


def check_json_structure(body: bytes, max_items: int, max_depth: int = MAX_DEPTH,
                         max_string_bytes: int | None = None, max_values: int | None = None) -> None:
    """Refuse a JSON body that is not UTF-8, too deep, too long or has duplicate keys.

    Parameters
    ----------
    body : bytes
        The raw request body.
    max_items : int
        Most elements of one array or object [1].
    max_depth : int, default 64
        Deepest nesting of arrays and objects [1].
    max_string_bytes : int, optional
        Longest string [bytes].
    max_values : int, optional
        Most strings and containers in the body [1] (default ``max_items``).

    Raises
    ------
    ProblemError
        400 (not UTF-8, too deep, duplicate key) or 413 (too many elements, a string too long),
        naming the place.
    """
    containers = body.count(b"[") + body.count(b"{")
    values = max_items if max_values is None else max_values
    if (len(body) <= _INLINE_BYTES and containers <= max_depth
            and (max_string_bytes is None or len(body) <= max_string_bytes)
            and body.count(b",") + 1 <= max_items and max(body.count(b'"') // 2, containers) <= values):
        try:
            text = body.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise _malformed(f"The request body is not valid UTF-8 (byte {exc.start}).") from None
        # Small and shallow, so no limit can be passed: only duplicate keys remain to be found,
        # and the stdlib parser finds them faster than the scan. One flat object without
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
    scanner = JsonScanner(max_items, max_depth, max_string_bytes, max_values)
    view = memoryview(body)
    for start in range(0, len(body), BLOCK_BYTES):
        scanner.feed(bytes(view[start:start + BLOCK_BYTES]))
    scanner.close()


class CsvLineScanner:
    """The longest line of a CSV body fed block by block: past ``max_line_bytes`` it is refused (413).

    A field, quoted or not, is never longer than its line, so this bounds fields too, while the
    body streams in, before any of it is parsed. A multipart/form-data body holding the file is
    scanned alike: its boundaries and part headers are short lines among the file's.

    Parameters
    ----------
    max_line_bytes : int
        Longest line [bytes] (``MICROBEARING_MAX_FIELD_BYTES``).
    body : str, default "the CSV body"
        What the body is, for the message (e.g. "the multipart body").
    """

    def __init__(self, max_line_bytes: int, body: str = "the CSV body"):
        self.max_line_bytes = max_line_bytes
        self.body = body
        self._offset = 0
        self._line_start = 0  # where the current line starts [byte]
        self._line_number = 1

    @property
    def bytes_fed(self) -> int:
        """Bytes looked at so far [bytes]."""
        return self._offset

    def feed(self, block: bytes) -> None:
        """Look at the next ``block``; raises a 413 :class:`ProblemError` on a line too long."""
        ends = np.flatnonzero(np.frombuffer(block, dtype=np.uint8) == _NEWLINE) + self._offset
        starts = np.concatenate(([self._line_start], ends[:-1] + 1))
        lengths = np.append(ends - starts, self._offset + len(block) - (ends[-1] + 1 if len(ends) else
                                                                          self._line_start))
        if len(lengths) and lengths.max() > self.max_line_bytes:
            line = self._line_number + int(np.argmax(lengths > self.max_line_bytes))
            raise _too_large(f"Line {line} of {self.body} is longer than {self.max_line_bytes} bytes "
                             f"(MICROBEARING_MAX_FIELD_BYTES): a field that long is not a measurement.")
        if len(ends):
            self._line_start = int(ends[-1]) + 1
            self._line_number += len(ends)
        self._offset += len(block)


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
    """Check JSON bodies with :class:`JsonScanner`, and CSV and multipart bodies' lines, while they stream in.

    A body is looked at in blocks of :data:`BLOCK_BYTES` as they arrive; one past a limit is answered
    (400 or 413) from the block that passes it, and nothing of it is kept. uvicorn drops the rest of
    the body as it comes, for its keep-alive timeout at most (5 s) before it closes the connection:
    a client that sends its whole body before it reads (httpx, requests) hears the answer when it
    has sent it within that time; curl reads the answer at once and stops sending. A JSON body that
    passes reaches the app as one message (a ``bytearray`` once it came in several pieces), other bodies
    as they came, in their pieces. Install it inside the body-size limit (added before
    it), so that what it reads is bounded.

    Parameters
    ----------
    app : ASGI app
        The wrapped application.
    max_items : int
        Most elements of one array or object [1].
    max_field_bytes : int, optional
        Longest JSON string and longest CSV line [bytes] (``MICROBEARING_MAX_FIELD_BYTES``).
    max_values : int, optional
        Most strings and containers in a JSON body [1] (default ``max_items``).
    json_prefixes : tuple of str, default ()
        Paths whose routes read the body as JSON whatever its declared type (UM-Bridge's).
    max_members, max_objects : int, optional
        Most members of one object, and objects in a body [1] (:class:`JsonScanner`); a body up to 64 KiB,
        checked at once, is left to the schema for these.
    """

    def __init__(self, app: ASGIApp, max_items: int, max_field_bytes: int | None = None,
                 max_values: int | None = None, json_prefixes: tuple[str, ...] = (),
                 max_members: int | None = None, max_objects: int | None = None):
        self.app = app
        self.json_prefixes = json_prefixes
        self.max_items = max_items
        self.max_field_bytes = max_field_bytes
        self.max_values = max_values
        self.max_members = max_members
        self.max_objects = max_objects

    def _scanner(self, content_type: bytes | None, path: str) -> JsonScanner | CsvLineScanner | None:
        if is_json_media_type(content_type) or path.startswith(self.json_prefixes):
            return JsonScanner(self.max_items, max_string_bytes=self.max_field_bytes,
                               max_values=self.max_values, max_members=self.max_members,
                               max_objects=self.max_objects)
        if self.max_field_bytes is None:
            return None
        media = (content_type or b"").split(b";", 1)[0].strip().lower()
        if media == b"multipart/form-data":  # a CSV file uploaded
            return CsvLineScanner(self.max_field_bytes, "the multipart body")
        # The CSV routes read a body of any other type as CSV (application/octet-stream from generated
        # clients, text/plain); the other routes refuse it (415), so bounding its lines costs them nothing.
        named = media.decode("latin-1")[:60] or "untyped"
        what = "the CSV body" if media == b"text/csv" else f"the {named} body"
        return CsvLineScanner(self.max_field_bytes, what)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        content_types = [value for name, value in scope["headers"] if name.lower() == b"content-type"]
        scanner = self._scanner(content_types[0] if content_types else None, app_path(scope))
        if len(content_types) == 1 and scanner is None:
            await self.app(scope, receive, send)
            return
        if len(content_types) > 1:
            scanner = None  # refused whatever the body holds, once it is read
        # A JSON body grows one buffer (in place: a large one is its own mapping of memory) and reaches the
        # app as one message, which the app may free once parsed; kept as pieces, the C library held on
        # to their memory after the app had joined them, doubling a large body (228 MiB held 470 MB).
        json_body = isinstance(scanner, JsonScanner)
        joined: bytearray | None = None  # from the second piece of a JSON body on
        chunks: list[bytes] = []
        block: list[bytes] = []  # pieces not yet looked at
        waiting = 0
        problem: ProblemError | None = None
        try:
            while True:
                message = await receive()
                if message["type"] != "http.request":
                    break  # the client left; the app will see the disconnect
                piece = message.get("body", b"")
                more = message.get("more_body", False)
                if json_body and chunks:
                    joined = bytearray(chunks.pop())
                if joined is None:
                    chunks.append(piece)
                else:
                    joined += piece
                block.append(piece)
                waiting += len(piece)
                if scanner is not None and (waiting >= BLOCK_BYTES or not more):
                    problem = await self._look(scanner, b"".join(block), last=not more)
                    block, waiting = [], 0
                    if problem is not None:
                        # Answered now: the server drops what follows (for its keep-alive time at most).
                        chunks, joined = [], None
                        break
                if not more:
                    break
        except HTTPException as exc:  # the body's size or time limit (service.limits)
            problem = ProblemError(exc.status_code, str(exc.detail), headers=exc.headers)
        if problem is None and len(content_types) > 1:
            # answered once the body is read: a client may not read before it sent all
            problem = ProblemError(400, f"The request has {len(content_types)} Content-Type headers; "
                                        "send one.", title="Ambiguous content type", type_=VALIDATION_TYPE)
        if problem is not None:
            await self._answer(problem, scope, receive, send)
            return
        # Handed to the app and not kept here: the app may free the body once parsed.
        pending = chunks[::-1] if joined is None else [joined]
        del chunks, joined

        async def replay() -> Message:
            if pending:
                piece = pending.pop()
                return {"type": "http.request", "body": piece, "more_body": bool(pending)}
            return await receive()

        await self.app(scope, replay, send)

    async def _look(self, scanner: JsonScanner | CsvLineScanner, block: bytes,
                    last: bool) -> ProblemError | None:
        """Feed ``block`` to ``scanner``; the problem it finds, or None."""
        try:
            if last and scanner.bytes_fed == 0 and isinstance(scanner, JsonScanner) \
                    and len(block) <= _INLINE_BYTES:  # a small body at once: the fast check
                check_json_structure(block, self.max_items, max_string_bytes=self.max_field_bytes,
                                     max_values=self.max_values)
                return None
            if len(block) <= _INLINE_BYTES:
                scanner.feed(block)
            else:
                await run_in_threadpool(scanner.feed, block)
            if last and isinstance(scanner, JsonScanner):
                scanner.close()
        except ProblemError as problem:
            return problem
        return None

    @staticmethod
    async def _answer(problem: ProblemError, scope: Scope, receive: Receive, send: Send) -> None:
        response = ProblemResponse(problem.to_dict(instance=scope.get("path")), status_code=problem.status,
                                   headers=problem.headers)
        await response(scope, receive, send)
