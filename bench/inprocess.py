"""Per-request time of ``POST /v1/friction`` and ``GET /healthz`` through the whole ASGI app, in process.

No server, socket or client: the app (every middleware, the route, the answer) is called directly
with a ready body, so the figure is the service's own cost per request, free of the HTTP stack.
Prints the median of ``N`` requests of each (after 200 warm-up requests) as JSON [µs]. Run it as
a module (as a script, ``bench/physics.py`` would shadow the ``physics`` package); to compare two
versions, run it alternately from each tree, which then provides ``service``::

    cd <tree> && <venv>/bin/python -m bench.inprocess 1500
"""

from __future__ import annotations

import asyncio
import json
import logging
import statistics
import sys
import tempfile
import time

from microbearing.service.app import create_app
from microbearing.service.deps import get_runtime
from microbearing.service.settings import Settings

BODY = json.dumps({"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}).encode()


async def call(app, method: str, path: str, payload: bytes) -> None:
    """One request through the ASGI app; the answer is discarded."""
    sent = False

    async def receive() -> dict:
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": payload, "more_body": False}
        await asyncio.sleep(3600)  # no disconnect while the answer is written
        return {"type": "http.disconnect"}

    async def send(message: dict) -> None:
        pass

    headers = [(b"host", b"bench"), (b"accept", b"*/*")]
    if payload:
        headers += [(b"content-type", b"application/json"), (b"content-length", str(len(payload)).encode())]
    scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": method,
             "scheme": "http", "path": path, "raw_path": path.encode(), "root_path": "", "query_string": b"",
             "headers": headers, "client": ("127.0.0.1", 1), "server": ("127.0.0.1", 80), "state": {},
             "app": app}
    await app(scope, receive, send)


async def measure(count: int) -> dict[str, float]:
    """Median time per request [µs] of each route."""
    app = create_app(Settings(data_dir=tempfile.mkdtemp(prefix="microbearing-inprocess-")))
    get_runtime(app)
    for _ in range(200):
        await call(app, "POST", "/v1/friction", BODY)
        await call(app, "GET", "/healthz", b"")
    medians = {}
    for name, method, path, payload in (("friction", "POST", "/v1/friction", BODY),
                                        ("healthz", "GET", "/healthz", b"")):
        times = []
        for _ in range(count):
            started = time.perf_counter()
            await call(app, method, path, payload)
            times.append(time.perf_counter() - started)
        medians[name] = round(statistics.median(times) * 1e6, 1)
    return medians


if __name__ == "__main__":
    logging.disable(logging.CRITICAL)  # the access log would time the log handler
    print(json.dumps(asyncio.run(measure(int(sys.argv[1]) if len(sys.argv) > 1 else 1500))))
