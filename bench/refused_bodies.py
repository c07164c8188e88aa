"""Memory and time of bodies the server refuses: ``--clients`` at once, of each kind, side by side.

Starts ``microbearing serve`` (one process, default settings) on a free loopback port with a
temporary data folder; for each kind of body, ``--clients`` threads send one each at once, streamed
from a generator (the client holds 64 KiB at a time), and read the answer. Kinds:

* ``string``: a JSON batch with one string field of ``--mib`` MiB (refused: the field limit);
* ``batch``: a JSON batch of 5e6 points, ~200 MiB (refused: the point limit);
* ``csv``: a calibration CSV with one field of ``--mib`` MiB (refused: the field limit);
* ``columns``: a JSON batch of six columns of nearly 2e6 numbers each, ~228 MiB, one of them not an input
  (refused by the schema, 422, after the body is parsed: the check while it streams passes it);
* ``predict``: the same body sent to a surrogate's ``predict`` (of a surrogate that does not exist: the
  body is refused first);
* ``umbridge``: the same body sent to UM-Bridge's ``Evaluate`` (400, ``InvalidInput``: no model name);
* ``sweep``: the same body sent to ``/v1/sweeps``, a document route (413 as it streams, past
  MICROBEARING_MAX_DOCUMENT_BYTES);
* ``csvjson``: the same body sent to the CSV upload as JSON (413: its header row has millions of columns).

Reports each kind's statuses, the slowest answer, the time from the first byte sent to the answer
of one request alone, and the server's resident memory: at start, and its peak (``VmHWM``) after
each kind::

    .venv/bin/python bench/refused_bodies.py --clients 6 --mib 238
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import threading
import time
from collections.abc import Iterator

import httpx
from flood import rss_mib
from load import start_server, stop_server

CHUNK = 65_536


def pieces(head: bytes, filler: bytes, total: int, tail: bytes) -> Iterator[bytes]:
    yield head
    sent = len(head)
    block = filler * (CHUNK // len(filler))
    while sent + len(block) < total - len(tail):
        yield block
        sent += len(block)
    yield filler * ((total - len(tail) - sent) // len(filler)) + tail


def kinds(mib: int) -> dict[str, tuple[str, str, callable]]:
    size = mib * 2**20
    return {
        "string": ("/v1/friction/batch", "application/json",
                   lambda: pieces(b'{"points": {"balls": 4, "name": "', b"a", size, b'"}}')),
        "batch": ("/v1/friction/batch", "application/json",
                  lambda: pieces(b'{"points": {"balls": 4, "speed_m_s": 0.1, "load_N": [',
                                 b"0.012345678901, ", 5_000_000 * 16, b"0.01]}}")),
        "csv": ("/v1/calibrations/csv", "text/csv",
                lambda: pieces(b"balls,load_N,speed_m_s,mu,note\n4,0.01,0.1,0.1,", b"x", size, b"\n")),
        "columns": ("/v1/friction/batch", "application/json", columns),
        "predict": ("/v1/surrogates/no-such-surrogate/predict", "application/json", columns),
        "umbridge": ("/umbridge/Evaluate", "application/json", columns),
        "sweep": ("/v1/sweeps", "application/json", columns),
        "csvjson": ("/v1/calibrations/csv", "application/json", columns),
    }


#: The columns of the ``columns`` kind: five inputs and one name that is none (ball_radius_m).
COLUMNS = ("load_N", "speed_m_s", "groove_angle_deg", "ball_radius_m", "mu_pivot", "mu_ball")


def columns(count: int = 1_990_000) -> Iterator[bytes]:
    number = b"0.0123456789012345, "
    yield b'{"points": {"balls": 4'
    for name in COLUMNS:
        yield f', "{name}": ['.encode()
        for _ in range((count - 1) // 4096):
            yield number * 4096
        yield number * ((count - 1) % 4096) + b"0.01]"
    yield b"}}"


#: The status each kind is refused with.
EXPECTED = {"string": 413, "batch": 413, "csv": 413, "columns": 422, "predict": 422, "umbridge": 400,
            "sweep": 413, "csvjson": 413}


def send(url: str, path: str, content_type: str, body, report: dict) -> None:
    started = time.perf_counter()
    try:
        with httpx.Client(base_url=url, timeout=httpx.Timeout(600.0)) as http:
            response = http.post(path, content=body(), headers={"Content-Type": content_type})
            report.update(status=response.status_code, detail=response.json().get("detail", "")[:120])
    except httpx.TransportError as exc:
        report.update(status=f"dropped ({type(exc).__name__})")
    report["seconds"] = time.perf_counter() - started


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--clients", type=int, default=6)
    parser.add_argument("--mib", type=int, default=238, help="size of the long field [MiB]")
    parser.add_argument("--kinds", default=None, help="comma-separated kinds to send (default: all)")
    args = parser.parse_args()
    failed = False
    with tempfile.TemporaryDirectory() as data_dir:
        process, url = start_server(1, data_dir)
        try:
            print(f"server RSS at start: {rss_mib(process.pid):.0f} MiB")
            chosen = kinds(args.mib)
            for name, (path, content_type, body) in chosen.items():
                if args.kinds and name not in args.kinds.split(","):
                    continue
                alone: dict = {}
                send(url, path, content_type, body, alone)
                reports = [{} for _ in range(args.clients)]
                threads = [threading.Thread(target=send, args=(url, path, content_type, body, report))
                           for report in reports]
                for thread in threads:
                    thread.start()
                for thread in threads:
                    thread.join()
                statuses = sorted(str(r.get("status")) for r in reports)
                print(f"{name:7s} one alone: {alone.get('status')} in {alone['seconds']:.2f} s; "
                      f"{args.clients} at once: {', '.join(statuses)}, slowest "
                      f"{max(r['seconds'] for r in reports):.1f} s; server peak RSS so far "
                      f"{rss_mib(process.pid, 'VmHWM'):.0f} MiB (VmHWM), now {rss_mib(process.pid):.0f} MiB")
                print(f"        {alone.get('detail')}")
                failed |= any(r.get("status") != EXPECTED[name] for r in [alone, *reports])
        finally:
            stop_server(process)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
