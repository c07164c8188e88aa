"""Time the streaming JSON check takes to refuse bodies of many keys or many small objects, side by side.

Each shape is fed to :class:`service.jsonguard.JsonScanner` in the middleware's 256 KiB blocks, once with
the limits the app sets from the default settings (members of one object and objects in a body follow
the calibration limits) and once with the element limit alone (what refused them before: each key read
by Python code first). A body the app accepts (20,000 calibration rows, a UM-Bridge batch of 1.9e6
points) is timed too: the limits must pass it::

    .venv/bin/python bench/guard_shapes.py
"""

from __future__ import annotations

import time

from microbearing.service.app import json_scan_limits
from microbearing.service.jsonguard import BLOCK_BYTES, JsonScanner
from microbearing.service.problems import ProblemError
from microbearing.service.settings import Settings


def shapes() -> dict[str, bytes]:
    n = 2_100_000
    return {
        "2.1e6 keys in one object": b'{"points": {' + b", ".join(b'"k%d": 1' % i for i in range(n)) + b"}}",
        "2.1e6 empty objects": b'{"points": [' + b", ".join([b"{}"] * n) + b"]}",
        "3.5e6 one-key rows": b'{"data": [' + b", ".join([b'{"a": 1}'] * 3_500_000) + b"]}",
        "20,000 rows (accepted)": b'{"data": [' + b", ".join(
            [b'{"balls": 4, "load_N": 0.01, "speed_m_s": 0.1, "mu_measured": 0.02}'] * 20_000) + b"]}",
        "1.9e6 UM-Bridge points (accepted)": b'{"name": "physics", "input": [' + b", ".join(
            [b"[4, 0.01, 0.05]"] * 1_900_000) + b"]}",
    }


def scan(body: bytes, **limits: int) -> tuple[float, str]:
    scanner = JsonScanner(**limits)
    started = time.perf_counter()
    try:
        for start in range(0, len(body), BLOCK_BYTES):
            scanner.feed(body[start:start + BLOCK_BYTES])
        scanner.close()
        verdict = "passed"
    except ProblemError as problem:
        verdict = f"{problem.status}: {str(problem.detail)[:60]}"
    return time.perf_counter() - started, verdict


def main() -> None:
    now = json_scan_limits(Settings())
    before = {name: now[name] for name in ("max_items", "max_string_bytes", "max_values")}
    print(f"{'shape':36s} {'MiB':>6s} {'element limit alone':>22s} {'with member/object limits':>28s}")
    for name, body in shapes().items():
        (t_before, v_before), (t_now, v_now) = scan(body, **before), scan(body, **now)
        print(f"{name:36s} {len(body) / 2**20:6.1f} {t_before:8.3f} s {v_before[:11]:>11s} "
              f"{t_now:8.3f} s {v_now[:60]}")


if __name__ == "__main__":
    main()
