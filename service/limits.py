"""Request-body limits as pure ASGI middleware: size (413), arrival time (408), content coding (415).

Starlette's own size limit (FastAPI's ``max_body_size``) answers a declared oversize body with a
plain-text 413; this one keeps every error ``application/problem+json``. A declared
``Content-Length`` above the limit is refused before anything is read; a body without one
(chunked) is counted as it streams, and the route reading it gets an HTTP 413 exception that
the problem handlers answer.

A body must arrive whole within ``timeout_s`` of the first read: a client that sends its body
slowly, or never finishes it, gets 408 and the connection is closed, instead of holding it for as
long as it likes. A body sent with a ``Content-Encoding`` other than ``identity`` (gzip, deflate,
br) gets 415 with ``Accept-Encoding: identity``: the service reads plain bodies only, and a
compressed one would otherwise be read as malformed text.

:class:`HeavyRequestMiddleware` bounds the memory of requests with large bodies: at most
``MICROBEARING_MAX_HEAVY_REQUESTS`` of them are in progress at once (from before their body is read
until their answer is sent, streamed or not); the others wait for a turn, then get 503.

Finally, :func:`check_table` is the one place that refuses a table with more rows or columns than
allowed (413); :func:`csv_data_rows` and :func:`csv_header_columns` count them in a CSV body before
it is parsed.
"""

from __future__ import annotations

import asyncio
import csv
import ctypes
import functools
import gc
import re
import threading
import time
from collections.abc import Callable
from typing import Any, Literal

from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from .problems import ProblemError, ProblemResponse

__all__ = ["HEAVY_BODY_BYTES", "BodySizeLimitMiddleware", "BodyTimeout", "BodyTooLarge",
           "HeavyRequestMiddleware", "app_path", "check_table", "csv_data_rows", "csv_header_columns",
           "return_freed_memory"]

def app_path(scope: Scope) -> str:
    """The request's path relative to the ASGI root path (the app's own routes start there)."""
    path = scope["path"]
    root_path = scope.get("root_path", "")
    if root_path and path.startswith(root_path):
        path = path[len(root_path):] or "/"
    return path


#: A request whose body is declared larger than this, or not declared (chunked), is heavy [bytes].
HEAVY_BODY_BYTES = 2**20


class BodyTooLarge(HTTPException):
    """The streamed body passed the limit (an HTTPException, so FastAPI re-raises it as is)."""

    def __init__(self, max_bytes: int, setting: str = "MICROBEARING_MAX_BODY_BYTES"):
        super().__init__(413, f"The request body exceeds the limit of {max_bytes} bytes ({setting}).")


class BodyTimeout(HTTPException):
    """The body did not arrive within the time limit; the connection is closed after the answer."""

    def __init__(self, timeout_s: float):
        super().__init__(408, f"The request body did not arrive within {timeout_s:g} s "
                              "(MICROBEARING_BODY_TIMEOUT_S).", headers={"Connection": "close"})


#: The setting bounding each dimension of a table of measurements.
_TABLE_SETTINGS = {"rows": "MICROBEARING_MAX_CALIBRATION_ROWS",
                   "columns": "MICROBEARING_MAX_CALIBRATION_COLUMNS"}


def check_table(count: int, limit: int, dimension: Literal["rows", "columns"],
                what: str = "The data") -> None:
    """Refuse a table of more than ``limit`` rows or columns with a 413 problem naming the limit.

    Parameters
    ----------
    count : int
        Rows or columns received [1].
    limit : int
        Most accepted [1] (``MICROBEARING_MAX_CALIBRATION_ROWS`` or ``..._COLUMNS``, which the
        message names).
    dimension : {"rows", "columns"}
        Which one ``count`` counts.
    what : str
        What the table is, for the message.

    Raises
    ------
    ProblemError
        413 "Too many rows" or "Too many columns" when ``count > limit``.
    """
    if count > limit:
        raise ProblemError(413, f"{what} has {count} {dimension}; the limit is {limit} "
                                f"({_TABLE_SETTINGS[dimension]}).", title=f"Too many {dimension}")


#: Longest header row parsed as CSV to count its columns [bytes]; a longer one is counted by its separators.
_PARSED_HEADER_BYTES = 2**20


def csv_header_columns(text: bytes, separator: str | None = None) -> int:
    r"""Columns of a CSV body's header row, read without parsing the rest.

    Parameters
    ----------
    text : bytes
        The body (without a ``sep=`` first line).
    separator : str, optional
        The separator character the request states; None (detected later): the most columns any of
        comma, semicolon and tab would make, so that a header the parser would split on semicolons or
        tabs is bounded too.

    A header the csv module refuses (a field of more than 128 kB), or longer than
    :data:`_PARSED_HEADER_BYTES` (a body sent whole on one line), is counted by its separators (quoted ones
    too); the parser answers the former with a 422 problem.

    >>> csv_header_columns(b"a,b,c\n1,2,3\n"), csv_header_columns(b'"x,y",b\r\n1,2'), csv_header_columns(b"")
    (3, 2, 0)
    >>> csv_header_columns(b"a;b;c;d\n1;2;3;4\n"), csv_header_columns(b"a;b;c;d\n", separator=",")
    (4, 1)
    """
    end = text.find(b"\n")
    header = (text if end < 0 else text[:end]).rstrip(b"\r")
    if not header:
        return 0
    separators = (separator,) if separator else (",", ";", "\t")
    if len(header) > _PARSED_HEADER_BYTES:  # parsed, 228 MB on one line made 12 million strings (1.5 GB)
        return max(header.count(sep.encode()) + 1 for sep in separators)
    line = header.decode("utf-8", errors="replace")
    counts = []
    for sep in separators:
        try:
            counts.append(len(next(csv.reader([line], delimiter=sep))))
        except csv.Error:  # a field past the csv module's limit (128 kB): count the separators instead
            counts.append(line.count(sep) + 1)
    return max(counts)


def csv_data_rows(text: bytes) -> int:
    r"""Data rows of a CSV body with a header row, counted by line breaks without parsing it.

    >>> csv_data_rows(b"a,b\n1,2\n3,4\n"), csv_data_rows(b"a,b\r\n1,2\r\n3,4"), csv_data_rows(b"a,b")
    (2, 2, 0)
    """
    lines = text.count(b"\n") + (bool(text) and not text.endswith(b"\n"))
    return max(lines - 1, 0)


class _Resume:
    """Await the rest of a coroutine that :func:`receive_within` started and that is waiting on ``future``."""

    def __init__(self, coroutine: Any, future: Any):
        self.coroutine = coroutine
        self.future = future

    def __await__(self) -> Any:
        try:
            yield self.future  # the task waits for the client's bytes, then resumes the coroutine
        except BaseException as exc:  # cancelled by the deadline: the coroutine ends with it
            self.coroutine.throw(exc)
            raise
        return (yield from self.coroutine.__await__())


async def receive_within(receive: Receive, deadline: float) -> Message:
    """``await receive()``, failing with :class:`TimeoutError` past ``deadline`` (event-loop time).

    A message already there (the common case: a small body arrives with its headers) is returned
    without a timer, which would cost more than the rest of the request's body handling; only a
    read that has to wait for the client runs under :func:`asyncio.timeout_at`.
    """
    coroutine = receive()
    try:
        future = coroutine.send(None)  # runs the read up to its first wait, if it has to wait
    except StopIteration as done:
        return done.value
    async with asyncio.timeout_at(deadline):
        return await _Resume(coroutine, future)


class BodySizeLimitMiddleware:
    """Refuse bodies larger than ``max_bytes`` (413), slower than ``timeout_s`` (408) or encoded (415).

    Parameters
    ----------
    app : ASGI app
        The wrapped application.
    max_bytes : int
        Largest accepted body [bytes].
    timeout_s : float, optional
        Time allowed for the whole body to arrive, from the first read [s]; unlimited when None.
    max_document_bytes : int, optional
        Largest body of a request whose path is no data route [bytes] (``MICROBEARING_MAX_DOCUMENT_BYTES``):
        a document (a sweep, a design) has no use for the hundreds of MB a batch may send, and the
        parsed form of a refused one cost several times its size.
    data_paths : re.Pattern, optional
        The paths (after the root path) that take up to ``max_bytes``; all paths when None.
    """

    def __init__(self, app: ASGIApp, max_bytes: int, timeout_s: float | None = None,
                 max_document_bytes: int | None = None, data_paths: re.Pattern[str] | None = None):
        self.app = app
        self.max_bytes = max_bytes
        self.timeout_s = timeout_s
        self.max_document_bytes = min(max_bytes, max_document_bytes or max_bytes)
        self.data_paths = data_paths

    def _limit(self, scope: Scope) -> tuple[int, str]:
        """The largest body of this request [bytes] and the setting that says so."""
        if self.data_paths is None or self.max_document_bytes == self.max_bytes:
            return self.max_bytes, "MICROBEARING_MAX_BODY_BYTES"
        if self.data_paths.match(app_path(scope)):
            return self.max_bytes, "MICROBEARING_MAX_BODY_BYTES"
        return self.max_document_bytes, "MICROBEARING_MAX_DOCUMENT_BYTES"

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = dict(scope["headers"])
        declared = headers.get(b"content-length")
        encoding = headers.get(b"content-encoding", b"identity").strip().lower()
        problem = None
        max_bytes, setting = self._limit(scope)
        if declared is not None and (not declared.isdigit() or int(declared) > max_bytes):
            if declared.isdigit():
                problem = ProblemError(413, f"The body has {int(declared)} bytes; the limit is "
                                            f"{max_bytes} ({setting}).", headers={"Connection": "close"})
            else:
                problem = ProblemError(400, "Content-Length must be a whole number of bytes.",
                                       headers={"Connection": "close"})
        elif encoding not in (b"identity", b"") and (declared not in (None, b"0")
                                                     or b"transfer-encoding" in headers):  # a body is coming
            coding = encoding.decode("latin-1")[:50]
            problem = ProblemError(415, f"Content-Encoding {coding!r} is not supported; send the body "
                                        "uncompressed.", title="Unsupported Media Type",
                                   headers={"Accept-Encoding": "identity", "Connection": "close"})
        if problem is not None:
            response = ProblemResponse(problem.to_dict(instance=scope.get("path")),
                                       status_code=problem.status, headers=problem.headers)
            await response(scope, receive, send)
            return
        received = 0
        # Without a declared body (GET, Content-Length 0) the server answers the first read at once:
        # no timer, which costs more than the rest of this middleware.
        complete = declared in (None, b"0") and b"transfer-encoding" not in headers
        deadline: float | None = None

        async def counted_receive() -> Message:
            nonlocal received, complete, deadline
            if complete or self.timeout_s is None:  # after the body only a disconnect is awaited: no limit
                message = await receive()
            else:
                loop = asyncio.get_running_loop()
                if deadline is None:
                    deadline = loop.time() + self.timeout_s
                try:
                    message = await receive_within(receive, deadline)
                except TimeoutError:
                    raise BodyTimeout(self.timeout_s) from None
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > max_bytes:
                    raise BodyTooLarge(max_bytes, setting)
                complete = not message.get("more_body", False)
            return message

        await self.app(scope, counted_receive, send)


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim``, or None where the C library has none (musl, macOS)."""
    try:
        return ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return None


def return_freed_memory() -> bool:
    """Give the memory the process has freed back to the operating system (glibc's ``malloc_trim(0)``:
    every malloc arena, the threads' included); whether the C library could. After a large request, the
    lists and parse trees of its body are freed but glibc keeps their pages for the process: six refused
    batches of six 2e6-number columns left 6.2 GB held."""
    gc.collect()  # what only a cycle holds (a refusal's exception, its traceback and the parsed body)
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True


class HeavyRequestMiddleware:
    """At most ``max_requests`` requests with a body over :data:`HEAVY_BODY_BYTES` in progress at once.

    A heavy request (a body declared over 1 MiB, or of undeclared size) waits for a turn before
    its body is read, up to ``wait_s``, then gets 503 with ``Retry-After``. When its answer is sent, the
    memory the process freed goes back to the system (:func:`return_freed_memory`) before the turn is
    given up. With its turn it also
    takes a place of the job admission control (``admit``, which may refuse with 503 or 429, as
    for a job), so heavy requests and jobs share one bound. Turn and place are held until the
    answer is sent, a streamed one included, or the client leaves. Other requests pass at once.

    Parameters
    ----------
    app : ASGI app
        The wrapped application.
    max_requests : int
        Heavy requests in progress at once [1] (``MICROBEARING_MAX_HEAVY_REQUESTS``).
    wait_s : float
        Longest wait for a turn [s] (``MICROBEARING_HEAVY_REQUEST_WAIT_S``).
    admit : callable, optional
        ``admit(scope)`` takes an admission place and returns what frees it, or raises a
        :class:`~service.problems.ProblemError` (see :meth:`service.jobs.JobManager.admit_request`).
    """

    #: How often a waiting request looks for a free turn [s].
    poll_s = 0.05

    def __init__(self, app: ASGIApp, max_requests: int, wait_s: float,
                 admit: Callable[[Scope], Callable[[], None]] | None = None):
        self.app = app
        self.max_requests = max_requests
        self.wait_s = wait_s
        self.admit = admit
        self.turns = threading.BoundedSemaphore(max_requests)  # shared by the threads of a TestClient too

    @staticmethod
    def heavy(scope: Scope) -> bool:
        """Whether the request's body is declared over :data:`HEAVY_BODY_BYTES`, or chunked."""
        declared = None
        chunked = False
        for name, value in scope["headers"]:
            if name == b"content-length":
                declared = value
            elif name == b"transfer-encoding":
                chunked = True
        if declared is not None:
            return not declared.isdigit() or int(declared) > HEAVY_BODY_BYTES
        return chunked

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or not self.heavy(scope):
            await self.app(scope, receive, send)
            return
        deadline = time.monotonic() + self.wait_s
        while not self.turns.acquire(blocking=False):
            if time.monotonic() >= deadline:
                problem = ProblemError(
                    503, f"{self.max_requests} requests with bodies over {HEAVY_BODY_BYTES} bytes or of "
                         "undeclared size (chunked: send a Content-Length) are in progress "
                         "(MICROBEARING_MAX_HEAVY_REQUESTS) and none finished within "
                         f"{self.wait_s:g} s (MICROBEARING_HEAVY_REQUEST_WAIT_S); retry later.",
                    title="Server busy", headers={"Retry-After": "5", "Connection": "close"})
                await self._answer(problem, scope, receive, send)
                return
            await asyncio.sleep(self.poll_s)
        try:
            try:
                release = self.admit(scope) if self.admit is not None else None
            except ProblemError as problem:
                problem.headers = {**(problem.headers or {}), "Connection": "close"}
                await self._answer(problem, scope, receive, send)
                return
            try:
                await self.app(scope, receive, send)
            finally:
                if release is not None:
                    release()
        finally:
            try:  # the answer is sent: what the body was read into goes back to the system before the
                # next heavy request may take the turn (in a thread: a collection of GBs takes a moment)
                await asyncio.get_running_loop().run_in_executor(None, return_freed_memory)
            finally:
                self.turns.release()

    @staticmethod
    async def _answer(problem: ProblemError, scope: Scope, receive: Receive, send: Send) -> None:
        response = ProblemResponse(problem.to_dict(instance=scope.get("path")), status_code=problem.status,
                                   headers=problem.headers)
        await response(scope, receive, send)

