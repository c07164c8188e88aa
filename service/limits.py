"""Request-body size limit as pure ASGI middleware, answering 413 as a problem.

Starlette's own limit (FastAPI's ``max_body_size``) answers a declared oversize body with a
plain-text 413; this one keeps every error ``application/problem+json``. A declared
``Content-Length`` above the limit is refused before anything is read; a body without one
(chunked) is counted as it streams, and the route reading it gets an HTTP 413 exception that
the problem handlers answer.
"""

from __future__ import annotations

from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from .problems import ProblemError, ProblemResponse

__all__ = ["BodySizeLimitMiddleware"]


class BodyTooLarge(HTTPException):
    """The streamed body passed the limit (an HTTPException, so FastAPI re-raises it as is)."""

    def __init__(self, max_bytes: int):
        super().__init__(413, f"The request body exceeds the limit of {max_bytes} bytes.")


class BodySizeLimitMiddleware:
    """Refuse request bodies larger than ``max_bytes`` with ``413 Content Too Large``.

    Parameters
    ----------
    app : ASGI app
        The wrapped application.
    max_bytes : int
        Largest accepted body [bytes].
    """

    def __init__(self, app: ASGIApp, max_bytes: int):
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = dict(scope["headers"]).get(b"content-length")
        if declared is not None and (not declared.isdigit() or int(declared) > self.max_bytes):
            if declared.isdigit():
                status, detail = 413, f"The body has {int(declared)} bytes; the limit is {self.max_bytes}."
            else:
                status, detail = 400, "Content-Length must be a whole number of bytes."
            problem = ProblemError(status, detail)
            response = ProblemResponse(problem.to_dict(instance=scope.get("path")), status_code=status,
                                       headers={"Connection": "close"})
            await response(scope, receive, send)
            return
        received = 0

        async def counted_receive() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.max_bytes:
                    raise BodyTooLarge(self.max_bytes)
            return message

        await self.app(scope, counted_receive, send)
