"""Per-request time of ``POST /v1/friction`` and ``GET /healthz`` through the whole ASGI app, in process.

No server, socket or client: the app (every middleware, the route, the answer) is called directly
with a ready body, so the figure is the service's own cost per request, free of the HTTP stack.
Prints the median of ``N`` requests of each (after 200 warm-up requests) as JSON [µs]. Run it as
a module (as a script, ``bench/physics.py`` would shadow the ``physics`` package); to compare two
versions, run it alternately from each tree, which then provides ``service``::

    cd <tree> && <venv>/bin/python -m bench.inprocess 1500

With ``--stages`` it prints where the time goes instead: the own time of each layer of the ASGI
stack (its time less that of the layer it wraps) and, within ``/v1/friction``, FastAPI's part
before the endpoint's work (route matching, the request object), reading and validating the body,
the physics of the point, writing the answer, and FastAPI's part after it; each the minimum over
``N`` requests [µs], the figure least disturbed by other work on the machine::

    <venv>/bin/python -m bench.inprocess 3000 --stages

With ``--routes R`` it alternates R times between the app as served and the same app without its
plain routes (``service.app.PlainRoute``: ``POST /v1/friction`` then goes through FastAPI's route),
and prints the medians of each side by side::

    <venv>/bin/python -m bench.inprocess 3000 --routes 5
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import statistics
import tempfile
import time
from collections.abc import Callable
from typing import Any

from microbearing.service.app import PlainRoute, create_app
from microbearing.service.deps import get_runtime
from microbearing.service.routes import friction
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


def build_app(plain: bool = True):
    """The service in a temporary data folder; ``plain=False`` drops its plain routes (FastAPI's serve)."""
    app = create_app(Settings(data_dir=tempfile.mkdtemp(prefix="microbearing-inprocess-")))
    if not plain:
        app.router.routes[:] = [route for route in app.router.routes if not isinstance(route, PlainRoute)]
    get_runtime(app)
    return app


async def measure(count: int, plain: bool = True) -> dict[str, float]:
    """Median time per request [µs] of each route."""
    app = build_app(plain)
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


class _Timed:
    """Wraps an ASGI layer: records in ``marks`` when it starts and ends, under its name."""

    def __init__(self, name: str, app: Any, marks: dict[str, float]):
        self.name, self.app, self.marks = name, app, marks

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        self.marks[self.name] = time.perf_counter()
        await self.app(scope, receive, send)
        self.marks[self.name + " end"] = time.perf_counter()


def _timed(function: Callable[..., Any], name: str, marks: dict[str, float]) -> Callable[..., Any]:
    """``function`` (sync or async) recording in ``marks`` when it starts and ends, under ``name``."""
    if asyncio.iscoroutinefunction(function):
        async def timed_async(*args: Any, **kwargs: Any) -> Any:
            marks[name] = time.perf_counter()
            result = await function(*args, **kwargs)
            marks[name + " end"] = time.perf_counter()
            return result
        return timed_async

    def timed(*args: Any, **kwargs: Any) -> Any:
        marks[name] = time.perf_counter()
        result = function(*args, **kwargs)
        marks[name + " end"] = time.perf_counter()
        return result
    return timed


#: The stages of /v1/friction's endpoint, in order: the route module's name of each and its label.
_ROUTE_STAGES = {"parse_json_body": "reading and validating the body",
                 "evaluate_point": "the physics of the point", "json_bytes": "writing the answer"}


async def stages(count: int) -> dict[str, dict[str, float]]:
    """Own time of each ASGI layer and of the stages of ``/v1/friction`` [µs]: minimum over ``count``."""
    marks: dict[str, float] = {}
    for attribute, label in _ROUTE_STAGES.items():
        setattr(friction, attribute, _timed(getattr(friction, attribute), label, marks))
    app = build_app()
    layers = [app.build_middleware_stack()]
    while not isinstance(layers[-1], type(app.router)):  # each middleware wraps the next in .app
        layers.append(layers[-1].app)
    names = [type(layer).__name__ for layer in layers]
    names[-1] = "the router: matching, FastAPI, the endpoint"
    for outer, name in zip(layers[:-1], names[1:], strict=True):
        outer.app = _Timed(name, outer.app, marks)
    app.middleware_stack = _Timed(names[0], layers[0], marks)
    for _ in range(200):
        await call(app, "POST", "/v1/friction", BODY)
        await call(app, "GET", "/healthz", b"")
    labels = list(_ROUTE_STAGES.values())
    minima: dict[str, dict[str, float]] = {}
    for kind, method, path, payload in (("healthz", "GET", "/healthz", b""),
                                        ("friction", "POST", "/v1/friction", BODY)):
        rows: dict[str, list[float]] = {}
        for _ in range(count):
            marks.clear()
            await call(app, method, path, payload)
            took = {name: marks[name + " end"] - marks[name] for name in [*names, *labels] if name in marks}
            own = {name: took[name] - took.get(inner, 0.0)
                   for name, inner in zip(names, [*names[1:], ""], strict=True)}
            if labels[0] in marks:  # the friction route: its stages, and FastAPI's part around them
                router, router_end = marks[names[-1]], marks[names[-1] + " end"]
                own["  FastAPI before the endpoint's work (matching, request)"] = marks[labels[0]] - router
                own.update((f"  {label}", took[label]) for label in labels)
                own["  FastAPI after the answer is written"] = router_end - marks[labels[-1] + " end"]
            own["the whole app"] = took[names[0]]
            for name, value in own.items():
                rows.setdefault(name, []).append(value)
        minima[kind] = {name: round(min(values) * 1e6, 1) for name, values in rows.items()}
    return minima


def print_stages(count: int) -> None:
    """The table of :func:`stages`, healthz and friction side by side."""
    minima = asyncio.run(stages(count))
    heading = f"own time per request [us], minimum of {count}"
    print(f"{heading:58s} {'healthz':>8s} {'friction':>9s} {'more':>7s}")
    for name, value in minima["friction"].items():
        if name in minima["healthz"]:
            other = minima["healthz"][name]
            print(f"{name:58s} {other:8.1f} {value:9.1f} {value - other:7.1f}")
        else:  # a stage of the friction route only
            print(f"{name:58s} {'':8s} {value:9.1f}")


def compare_routes(count: int, rounds: int) -> None:
    """Medians per round [µs] with the plain routes (as served) and with FastAPI's routes, alternating."""
    rows = {True: [], False: []}
    for _ in range(rounds):
        for plain in (True, False):
            rows[plain].append(asyncio.run(measure(count, plain)))
    print(f"median per request [us] over {count} requests, {rounds} rounds alternating; min / median / max")
    for plain, label in ((True, "plain route (as served)"), (False, "FastAPI's route")):
        columns = {name: [row[name] for row in rows[plain]] for name in ("friction", "healthz")}
        columns["excess"] = [row["friction"] - row["healthz"] for row in rows[plain]]
        for name, values in columns.items():
            spread = f"{min(values):7.1f} / {statistics.median(values):7.1f} / {max(values):7.1f}"
            print(f"  {label:24s} {name:9s} {spread}" + ("  (friction less healthz, per round)"
                                                          if name == "excess" else ""))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("count", nargs="?", type=int, default=1500, help="requests of each route")
    parser.add_argument("--stages", action="store_true", help="where the time goes, layer by layer")
    parser.add_argument("--routes", type=int, default=0, metavar="ROUNDS",
                        help="alternate ROUNDS times between the app as served and FastAPI's routes only")
    args = parser.parse_args()
    logging.disable(logging.CRITICAL)  # the access log would time the log handler
    if args.stages:
        print_stages(args.count)
    elif args.routes:
        compare_routes(args.count, args.routes)
    else:
        print(json.dumps(asyncio.run(measure(args.count))))
