"""Bounded connections: header time and size limits, a connection cap with a file-descriptor reserve.

uvicorn holds a connection for as long as the client takes to send its request line and headers,
reads headers of any size (httptools), and logs each failed ``accept()`` when the process runs out
of file descriptors. :class:`BoundedHttpProtocol` (``microbearing serve`` runs uvicorn with it)
adds, per connection:

* a time limit on the request line and headers (``MICROBEARING_HEADER_TIMEOUT_S``), from the
  moment the connection opens or the previous answer was sent: a connection that has not sent a
  whole request head by then is closed;
* a size limit on the request line and headers (``MICROBEARING_MAX_HEADER_BYTES``): past it, a
  ``431`` problem and the connection is closed, before the headers are parsed;
* a cap on open connections of the process: ``MICROBEARING_MAX_CONNECTIONS``, lowered to the
  file-descriptor limit less ``MICROBEARING_FD_RESERVE`` (descriptors kept for the database,
  logs, the dask client, the answers of the connections already open and the connections
  accepted in a burst before the cap sees them: the listen backlog is a quarter of the
  reserve). A connection past the cap closes the oldest connection still waiting for its
  headers (a slow or idle client), or itself when every connection is busy with a request. So a
  flood of connections that never finish their headers cannot exhaust the descriptors, and
  ``/healthz`` keeps answering.

:func:`raise_fd_limit` raises the soft limit of open files to the hard limit at start (uvicorn
processes start with the shell's 1,024 on many systems), and :class:`RepeatFilter` writes a
log line that repeats (the same logger, message and OS error) at most once a second, with the
count of the lines it held back. :class:`ConcurrencyLimitMiddleware` answers ``503`` past
``MICROBEARING_MAX_CONCURRENT_REQUESTS`` requests in progress (health probes excepted).

The protocol is uvicorn's httptools protocol with these checks added; settings are read from
the environment, as the app reads them.
"""

from __future__ import annotations

import asyncio
import json
import logging
import resource
import time
from collections import OrderedDict
from collections.abc import Callable
from typing import Any, ClassVar

from starlette.types import ASGIApp, Receive, Scope, Send
from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

from .problems import ProblemError, ProblemResponse
from .settings import Settings

__all__ = ["BoundedHttpProtocol", "ConcurrencyLimitMiddleware", "RepeatFilter", "accept_backlog",
           "connection_cap", "install_repeat_filter", "raise_fd_limit"]

logger = logging.getLogger("microbearing.service.connections")

#: Paths answered even past the concurrency limit: the probes of a load balancer or orchestrator.
PROBE_PATHS = frozenset({"/healthz", "/readyz"})


def raise_fd_limit(ceiling: int = 1 << 20) -> int:
    """Raise this process's soft limit of open files to its hard limit (at most ``ceiling``).

    Parameters
    ----------
    ceiling : int
        Highest soft limit set [file descriptors], for a hard limit of "unlimited".

    Returns
    -------
    int
        The soft limit now [file descriptors].
    """
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = ceiling if hard == resource.RLIM_INFINITY else min(hard, ceiling)
    if soft == resource.RLIM_INFINITY or soft >= target:
        return soft if soft != resource.RLIM_INFINITY else ceiling
    try:
        resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
    except (ValueError, OSError) as exc:  # a sandbox may refuse; keep what we have
        logger.warning("could not raise the open-file limit from %d to %d: %s", soft, target, exc)
        return soft
    logger.info("raised the open-file limit from %d to %d", soft, target)
    return target


def connection_cap(settings: Settings) -> int:
    """Most open connections of this process [1]: the setting, within the descriptors less the reserve."""
    soft = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    available = settings.max_connections if soft == resource.RLIM_INFINITY else soft - settings.fd_reserve
    return max(1, min(settings.max_connections, available))


def accept_backlog(settings: Settings) -> int:
    """The listen backlog of ``microbearing serve``: a quarter of the descriptor reserve (16 to 2048) [1].

    asyncio accepts up to the backlog's number of connections at each wake-up, before any of them
    reaches :class:`BoundedHttpProtocol`'s cap: two wake-ups' worth stays within the reserve.
    """
    return max(16, min(2048, settings.fd_reserve // 4))


class RepeatFilter(logging.Filter):
    """Let a repeating log line through at most once per ``interval_s``, with the count held back.

    Lines repeat when they have the same logger, message template and OS error number (or
    exception type). The first of a burst passes at once; the next that passes ``interval_s``
    later says how many were held back since, e.g. ``(and 4,512 more like it in the last 1.0 s)``.

    Parameters
    ----------
    interval_s : float, default 1
        Shortest time between two lines of one kind [s].
    clock : callable, optional
        Monotonic clock [s] (for tests).
    """

    def __init__(self, interval_s: float = 1.0, clock: Callable[[], float] = time.monotonic):
        super().__init__()
        self.interval_s = interval_s
        self.clock = clock
        #: kind -> (time the last line of that kind passed, lines held back since)
        self._seen: dict[tuple[Any, ...], tuple[float, int]] = {}

    @staticmethod
    def _kind(record: logging.LogRecord) -> tuple[Any, ...]:
        error = record.exc_info[1] if record.exc_info else None
        detail = error.errno if isinstance(error, OSError) else type(error).__name__
        return record.name, str(record.msg), detail

    def filter(self, record: logging.LogRecord) -> bool:
        kind = self._kind(record)
        now = self.clock()
        last, held = self._seen.get(kind, (None, 0))
        if last is not None and now - last < self.interval_s:
            self._seen[kind] = (last, held + 1)
            return False
        if held:
            record.msg = f"{record.msg} (and {held:,} more like it in the last {now - last:.1f} s)"
        if len(self._seen) > 1000:  # bounded: forget kinds that have been quiet
            self._seen = {k: v for k, v in self._seen.items() if now - v[0] < self.interval_s}
        self._seen[kind] = (now, 0)
        return True


#: Loggers whose repeated lines are held back: asyncio (a failing accept()), uvicorn's errors.
REPEAT_FILTERED_LOGGERS = ("asyncio", "uvicorn.error", "microbearing.service.connections")


def install_repeat_filter() -> None:
    """Put one :class:`RepeatFilter` on each of :data:`REPEAT_FILTERED_LOGGERS` (once per process)."""
    for name in REPEAT_FILTERED_LOGGERS:
        target = logging.getLogger(name)
        if not any(isinstance(existing, RepeatFilter) for existing in target.filters):
            target.addFilter(RepeatFilter())


class BoundedHttpProtocol(HttpToolsProtocol):
    """uvicorn's httptools protocol with a header time limit, a header size limit (431) and a connection cap.

    Run it with ``uvicorn.run(..., http="microbearing.service.connections:BoundedHttpProtocol")``
    (``microbearing serve`` does). The limits come from :class:`~service.settings.Settings`.
    """

    #: Settings and connection cap of this process, read on the first connection.
    _settings: ClassVar[Settings | None] = None
    _cap: ClassVar[int] = 0
    #: Connections waiting for a request head, oldest first (evicted first past the cap).
    _waiting: ClassVar[OrderedDict[BoundedHttpProtocol, None]] = OrderedDict()

    @classmethod
    def limits(cls) -> Settings:
        """The settings of this process (read once)."""
        if cls._settings is None:
            cls._settings = Settings()
            cls._cap = connection_cap(cls._settings)
        return cls._settings

    def __init__(self, *args: Any, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self._head_bytes = 0
        self._tail = b""
        self._head_timer: asyncio.TimerHandle | None = None

    def _await_head(self) -> None:
        """Start waiting for a request head: the timer runs, and the connection may be evicted."""
        settings = self.limits()
        self._head_bytes = 0
        self._tail = b""
        self._waiting[self] = None
        self._waiting.move_to_end(self)
        if self._head_timer is not None:
            self._head_timer.cancel()
        self._head_timer = self.loop.call_later(settings.header_timeout_s, self._head_timed_out)

    def _head_done(self) -> None:
        self._waiting.pop(self, None)
        if self._head_timer is not None:
            self._head_timer.cancel()
            self._head_timer = None

    def _head_timed_out(self) -> None:
        self._head_timer = None
        if self in self._waiting and not self.transport.is_closing():
            self._waiting.pop(self, None)
            self.transport.close()

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._await_head()
        if len(self.connections) > self._cap:
            # Past the cap: the oldest connection still waiting for its head goes (never this one
            # while another waits), so a flood of idle connections cannot lock a real client out.
            victim = next((c for c in self._waiting if c is not self), self)
            self._waiting.pop(victim, None)
            victim.transport.close()
            logger.warning("%d connections open, the limit (MICROBEARING_MAX_CONNECTIONS, within the "
                           "open-file limit less MICROBEARING_FD_RESERVE) is %d: closed the oldest one "
                           "waiting for its request head", len(self.connections), self._cap)

    def connection_lost(self, exc: Exception | None) -> None:
        self._head_done()
        super().connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        if self in self._waiting:
            limit = self.limits().max_header_bytes
            if self._head_bytes + len(data) > limit:
                # The head must end (a blank line) within the bytes still allowed; a body may follow.
                seen = self._tail + data
                end = seen.find(b"\r\n\r\n")
                if end < 0 or self._head_bytes - len(self._tail) + end + 4 > limit:
                    self._refuse_head(limit)
                    return
            self._head_bytes += len(data)
            self._tail = data[-3:]
        super().data_received(data)

    def _refuse_head(self, limit: int) -> None:
        self._head_done()
        self._close_with(ProblemError(431, f"The request line and headers exceed {limit} bytes "
                                           "(MICROBEARING_MAX_HEADER_BYTES).",
                                      title="Request Header Fields Too Large"))

    def _close_with(self, problem: ProblemError) -> None:
        """Write ``problem`` as the connection's last answer (application/problem+json) and close it."""
        body = json.dumps(problem.to_dict()).encode()
        status = f"HTTP/1.1 {problem.status} {problem.title}\r\n".encode()
        self.transport.write(status + b"content-type: application/problem+json\r\n"
                             b"content-length: " + str(len(body)).encode() + b"\r\n"
                             b"connection: close\r\n\r\n" + body)
        self.transport.close()

    def send_400_response(self, msg: str) -> None:
        """uvicorn's answer to bytes that are not an HTTP request, as a problem (its own is plain text).

        Among them the bytes a client sends past its body's ``Content-Length``, read as the next
        request: a Content-Length smaller than the body gets this answer, and the connection closes.
        """
        self._head_done()
        detail = (f"{msg.rstrip('.')}: the request line or headers are malformed, or bytes followed a body "
                  "past its Content-Length. The connection is closed.")
        self._close_with(ProblemError(400, detail, title="Bad Request"))

    def on_headers_complete(self) -> None:
        self._head_done()
        super().on_headers_complete()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        # The next request's head, on this kept-alive connection; unless a pipelined request's head
        # came already (its cycle is the current one, still unanswered).
        if not self.transport.is_closing() and (self.cycle is None or self.cycle.response_complete):
            self._await_head()


class ConcurrencyLimitMiddleware:
    """Answer ``503`` (a problem with ``Retry-After``) past ``max_requests`` requests in progress.

    ``/healthz`` and ``/readyz`` are always served, so that probes see a busy server as alive.

    Parameters
    ----------
    app : ASGI app
        The wrapped application.
    max_requests : int
        Most HTTP requests in progress in this process [1] (``MICROBEARING_MAX_CONCURRENT_REQUESTS``).
    """

    def __init__(self, app: ASGIApp, max_requests: int):
        self.app = app
        self.max_requests = max_requests
        self.active = 0

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["path"] in PROBE_PATHS:
            await self.app(scope, receive, send)
            return
        if self.active >= self.max_requests:
            problem = ProblemError(503, f"The server has {self.active} requests in progress, its limit "
                                        f"(MICROBEARING_MAX_CONCURRENT_REQUESTS={self.max_requests}); retry "
                                        "later.", title="Server busy", headers={"Retry-After": "1"})
            await ProblemResponse(problem.to_dict(instance=scope["path"]), status_code=503,
                                  headers=problem.headers)(scope, receive, send)
            return
        self.active += 1
        try:
            await self.app(scope, receive, send)
        finally:
            self.active -= 1
