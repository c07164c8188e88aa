"""The JSON structure check as a body streams in, block by block, and what a refused body costs.

The scanner (:class:`JsonScanner`) is compared with a reference that parses the whole document
(the stdlib parser, keeping duplicate keys) and measures it: any split of the body into blocks must
give the reference's verdict. Then the middleware meets bodies of hundreds of MiB that it must
refuse: they are generated piece by piece as a client would send them, and the memory Python
allocates meanwhile (tracemalloc) stays a few MiB, however large the body.
"""

from __future__ import annotations

import asyncio
import json
import tracemalloc

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from microbearing.service.jsonguard import CsvLineScanner, JsonGuardMiddleware, JsonScanner
from microbearing.service.problems import ProblemError

# ---------------------------------------------------------------- the reference


def serialize(node, ensure_ascii: bool, space: str) -> str:
    """JSON text of a tree whose objects are lists of (key, value) pairs (so keys may repeat)."""
    if isinstance(node, tuple) and node[0] == "object":
        pairs = (json.dumps(key, ensure_ascii=ensure_ascii) + space + ":" + space
                 + serialize(value, ensure_ascii, space) for key, value in node[1])
        return "{" + ("," + space).join(pairs) + "}"
    if isinstance(node, list):
        return "[" + ("," + space).join(serialize(item, ensure_ascii, space) for item in node) + "]"
    return json.dumps(node, ensure_ascii=ensure_ascii)


def verdict(node, ensure_ascii: bool, max_items: int, max_depth: int, max_string: int) -> set[str]:
    """The reference: the limits the whole document passes, measured on the parsed tree."""
    counts = {"strings": 0, "containers": 0}
    problems = set()

    def walk(item, depth: int) -> None:
        if isinstance(item, tuple) and item[0] == "object":
            pairs = item[1]
            keys = [key for key, _ in pairs]
            if len(set(keys)) != len(keys):
                problems.add("duplicate")
            children = [value for _, value in pairs]
            counts["strings"] += len(keys)
            for key in keys:
                if len(json.dumps(key, ensure_ascii=ensure_ascii).encode()) > max_string:
                    problems.add("string")
        elif isinstance(item, list):
            children = item
        else:
            if isinstance(item, str):
                counts["strings"] += 1
                if len(json.dumps(item, ensure_ascii=ensure_ascii).encode()) > max_string:
                    problems.add("string")
            return
        counts["containers"] += 1
        if depth + 1 > max_depth:
            problems.add("depth")
        if max(len(children), 1) > max_items:
            problems.add("items")
        for child in children:
            walk(child, depth + 1)

    walk(node, 0)
    if counts["strings"] > max_items or counts["containers"] > max_items:
        problems.add("items")
    return problems


def longest_run(body: bytes) -> int:
    """The most bytes between two quotes or structural bytes (outside strings), from the body's start."""
    longest, last, inside, escaped = 0, -1, False, False
    for position, byte in enumerate(body):
        if inside and escaped:
            escaped = False
        elif inside and byte == ord("\\"):
            escaped = True
        elif byte == ord('"') or (not inside and byte in b"[]{},:"):
            longest, last = max(longest, position - last - 1), position
            inside = inside != (byte == ord('"'))
    return max(longest, len(body) - last - 1)


STATUS = {"duplicate": 400, "depth": 400, "items": 413, "string": 413}

keys = st.sampled_from(["a", "b", "ab", "é", 'q"', "c\\d", "x:y", "[{", ",", "\u2603"])
leaves = st.one_of(st.integers(-5, 5), st.floats(allow_nan=False, allow_infinity=False), st.booleans(),
                   st.none(), st.text(alphabet='ab,:[]{}"\\é\u2603 \n', max_size=12))
trees = st.recursive(leaves, lambda inner: st.one_of(
    st.lists(inner, max_size=5),
    st.tuples(st.just("object"), st.lists(st.tuples(keys, inner), max_size=4))), max_leaves=25)


def scan(body: bytes, cuts: list[int], **limits) -> int | None:
    scanner = JsonScanner(**limits)
    previous = 0
    try:
        for cut in [*sorted(cuts), len(body)]:
            scanner.feed(body[previous:cut])
            previous = cut
        scanner.close()
    except ProblemError as problem:
        return problem.status
    return None


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(tree=trees, ensure_ascii=st.booleans(), space=st.sampled_from(["", " ", "\n  "]),
       max_items=st.integers(1, 8), max_depth=st.integers(1, 5), max_string=st.integers(3, 16),
       data=st.data())
def test_any_split_of_the_body_gives_the_whole_documents_verdict(tree, ensure_ascii, space, max_items,
                                                                 max_depth, max_string, data):
    body = serialize(tree, ensure_ascii, space).encode()
    cuts = data.draw(st.lists(st.integers(0, len(body)), max_size=6))
    expected = verdict(tree, ensure_ascii, max_items, max_depth, max_string)
    if longest_run(body) > max_string:  # a number, a literal or spaces longer than a field may be
        expected.add("string")
    got = scan(body, cuts, max_items=max_items, max_depth=max_depth, max_string_bytes=max_string)
    # With limits of one status passed, the status is theirs; with both, the first met in the body.
    statuses = {STATUS[problem] for problem in expected}
    assert got in statuses if statuses else got is None, (body, expected, got)


def test_one_byte_blocks_find_what_the_whole_body_finds():
    cases = [(b'{"a": 1, "a\\u0062": 2, "ab": 3}', 400),  # the same key, escaped differently
             (b'{"k": "\\\\", "k": 1}', 400),              # an escaped backslash closes nothing
             (b'["\\"[[[{{{", "]]]}}}"]', None),           # brackets and quotes inside strings
             (b'[1, 2, 3, 4]', 413),
             ('{"\u00e9": [1, 2], "x": {"\u00e9": 1}}'.encode(), None),
             (b'\xc3\x28', 400)]
    for body, status in cases:
        assert scan(body, list(range(len(body))), max_items=3) == status, body
        assert scan(body, [], max_items=3) == status, body


def test_a_utf8_character_cut_between_blocks_is_read_whole():
    body = '["\u2603\u2603"]'.encode()
    for cut in range(len(body)):
        assert scan(body, [cut], max_items=3) is None


def test_a_long_string_is_refused_in_the_block_that_passes_the_limit():
    scanner = JsonScanner(max_items=10, max_string_bytes=1000)
    scanner.feed(b'{"name": "' + b"a" * 500)
    with pytest.raises(ProblemError) as caught:
        scanner.feed(b"a" * 600)
    assert caught.value.status == 413 and "MICROBEARING_MAX_FIELD_BYTES" in caught.value.detail
    assert "at byte 9" in caught.value.detail


def test_an_object_of_too_many_keys_or_a_body_of_too_many_objects_is_refused_in_the_block_that_passes():
    # Each key costs Python code (its duplicate check): millions of them had taken seconds before the
    # element limit; no object of the app has more than a calibration row's columns, and only rows come
    # in thousands.
    keys = b'{"points": {' + b", ".join(b'"k%d": 1' % i for i in range(100)) + b"}}"
    scanner = JsonScanner(max_items=1000, max_members=50)
    with pytest.raises(ProblemError) as caught:
        scanner.feed(keys)
    assert caught.value.status == 413 and "more than 50 members" in caught.value.detail
    JsonScanner(max_items=1000, max_members=100).feed(keys)  # 100 keys: at the limit, not past it
    rows = b'{"data": [' + b", ".join([b'{"a": 1}'] * 30) + b"]}"
    scanner = JsonScanner(max_items=1000, max_objects=30)
    with pytest.raises(ProblemError) as caught:
        for start in range(0, len(rows), 7):  # passed in any block, counted across blocks
            scanner.feed(rows[start:start + 7])
    assert caught.value.status == 413 and "more than 30 objects" in caught.value.detail
    whole = JsonScanner(max_items=1000, max_objects=31)
    whole.feed(rows)
    whole.close()  # the 30 rows and the envelope


def test_a_long_number_or_run_of_spaces_is_refused_like_a_long_string():
    # the parser would hold a number of hundreds of MiB whole (a 238 MiB one cost the server 2.4 GB)
    for head, filler in ((b'{"load_N": 0.', b"1"), (b'{"load_N": ', b" "), (b"[1, tru", b"e")):
        scanner = JsonScanner(max_items=10, max_string_bytes=1000)
        scanner.feed(head + filler * 500)
        with pytest.raises(ProblemError) as caught:
            scanner.feed(filler * 600)
        assert caught.value.status == 413 and "MICROBEARING_MAX_FIELD_BYTES" in caught.value.detail
        assert f"at byte {len(head.rstrip(b'0.1tru '))}" in caught.value.detail, caught.value.detail
    fine = JsonScanner(max_items=10, max_string_bytes=1000)
    fine.feed(b'{"load_N": ' + b"1" * 999 + b', "s": "' + b"a" * 998 + b'"}')
    fine.close()


def test_a_body_cut_short_is_refused_at_its_end_without_being_parsed():
    # a Content-Length smaller than what the client sends cuts the body: a batch of 200 MiB cut
    # mid-array reached pydantic and cost the server 1.6 GB with six at once
    for body in (b'{"points": {"load_N": [0.01, 0.02', b'{"points": {"name": "abc', b"[[[1], [2]"):
        scanner = JsonScanner(max_items=10, max_string_bytes=1000)
        scanner.feed(body)
        with pytest.raises(ProblemError) as caught:
            scanner.close()
        assert caught.value.status == 400 and "ends inside" in caught.value.detail, caught.value.detail
    whole = JsonScanner(max_items=10, max_string_bytes=1000)
    whole.feed(b'{"points": {"load_N": [0.01, 0.02]}, "s": "a]"}')
    whole.close()


def test_a_csv_line_too_long_is_refused_naming_the_line():
    scanner = CsvLineScanner(max_line_bytes=10)
    scanner.feed(b"load_N,mu\n0.01,0.1\n0.0")
    with pytest.raises(ProblemError) as caught:
        scanner.feed(b"2" * 20)
    assert caught.value.status == 413 and "Line 3" in caught.value.detail
    assert "MICROBEARING_MAX_FIELD_BYTES" in caught.value.detail
    fine = CsvLineScanner(max_line_bytes=10)
    fine.feed(b"a,b\r\n1234567,8\n")  # 9 bytes and a CR: within


# ---------------------------------------------------------------- the middleware


def pieces(head: bytes, filler: bytes, total: int, tail: bytes, chunk: int = 65_536):
    """A body of ``total`` bytes as a client sends it: ``head``, ``filler`` repeated, ``tail``."""
    yield head
    sent = len(head)
    block = filler * (chunk // len(filler))
    while sent + len(block) < total - len(tail):
        yield block
        sent += len(block)
    yield filler * ((total - len(tail) - sent) // len(filler)) + tail


def run_guard(body_pieces, content_type: bytes, max_field_bytes: int = 2**20) -> tuple[int, bytes, int]:
    """The middleware on one request: (status, answer, bytes the app read), with allocations traced."""
    reached = {"app": 0}

    async def app(scope, receive, send):
        while True:
            message = await receive()
            reached["app"] += len(message.get("body", b""))
            if not message.get("more_body"):
                break
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"ok"})

    guard = JsonGuardMiddleware(app, max_items=2_000_000, max_field_bytes=max_field_bytes)
    source = iter(body_pieces)
    answer = {"status": 0, "body": b""}

    async def receive():
        piece = next(source, None)
        if piece is None:
            return {"type": "http.request", "body": b"", "more_body": False}
        return {"type": "http.request", "body": piece, "more_body": True}

    async def send(message):
        if message["type"] == "http.response.start":
            answer["status"] = message["status"]
        else:
            answer["body"] += message.get("body", b"")

    scope = {"type": "http", "method": "POST", "path": "/v1/friction/batch",
             "headers": [(b"content-type", content_type)]}
    asyncio.run(guard(scope, receive, send))
    return answer["status"], answer["body"], reached["app"]


def peak_mib(function) -> tuple[object, float]:
    tracemalloc.start()
    try:
        result = function()
        return result, tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("name, body, content_type, detail", [
    ("a 238 MiB string", pieces(b'{"points": {"balls": 4, "name": "', b"a", 238 * 2**20, b'"}}'),
     b"application/json", "MICROBEARING_MAX_FIELD_BYTES"),
    ("a 5e6-point batch", pieces(b'{"points": {"balls": 4, "load_N": [', b"0.0123456789, ", 70_000_000,
                                 b"0.01]}}"), b"application/json", "MICROBEARING_MAX_BATCH_POINTS"),
    ("a 238 MiB number", pieces(b'{"points": {"balls": 4, "speed_m_s": 0.1, "load_N": 0.', b"1",
                                238 * 2**20, b"}}"), b"application/json", "MICROBEARING_MAX_FIELD_BYTES"),
    ("238 MiB of spaces", pieces(b'{"points": {"balls": 4,', b" ", 238 * 2**20, b'"load_N": 0.01}}'),
     b"application/json", "MICROBEARING_MAX_FIELD_BYTES"),
    ("a 238 MiB CSV field", pieces(b"load_N,mu,note\n0.01,0.1,", b"x", 238 * 2**20, b"\n"),
     b"text/csv", "MICROBEARING_MAX_FIELD_BYTES"),
])
def test_a_body_that_will_be_refused_is_refused_as_it_streams(name, body, content_type, detail):
    (status, answer, reached), peak = peak_mib(lambda: run_guard(body, content_type))
    print(f"{name}: {status}, Python's peak allocation {peak:.1f} MiB")
    assert status == 413 and detail in json.loads(answer)["detail"], answer
    assert reached == 0  # the app never saw it
    assert peak < 40, f"{name}: {peak:.1f} MiB allocated for a refused body"


def test_a_large_body_cut_short_never_reaches_the_app():
    body = json.dumps({"points": {"balls": 4, "load_N": [0.0123456789] * 400_000}}).encode()[:-100]
    status, answer, reached = run_guard([body[i:i + 65_536] for i in range(0, len(body), 65_536)],
                                        b"application/json")
    assert status == 400 and "ends inside 3 unclosed" in json.loads(answer)["detail"], answer
    assert reached == 0


def test_an_accepted_body_reaches_the_app_whole():
    body = json.dumps({"points": {"balls": 4, "load_N": [0.01] * 300_000, "speed_m_s": 0.1}}).encode()
    chunks = [body[i:i + 65_536] for i in range(0, len(body), 65_536)]
    status, answer, reached = run_guard(chunks, b"application/json")
    assert (status, answer, reached) == (200, b"ok", len(body))
