"""Long lists of numbers in a large JSON body, read straight into NumPy arrays.

A JSON parser makes a Python float of every number: a batch of six columns of 2e6 points (228 MiB)
became about 570 MB of Python objects, and validating them as a model's fields held about 1 GB per
body. :func:`lift_number_lists` reads each list of at least :data:`MIN_LIST_BYTES` of numbers into a
float64 array instead (8 bytes a number), piece by piece with the same JSON parser, so its grammar and
its numbers are exactly the parser's; the list's place in the body becomes a placeholder string, the
rest of the body (a few keys) is parsed as usual, and :func:`place_arrays` puts the arrays back where
a model's fields accept them (:func:`array_column`), as lists elsewhere.

Anything unusual falls back to the plain parse, which then answers as before: a list that is not only
numbers (text, ``true``, nested lists) is left in the text; a body whose skeleton does not parse
(it was malformed, or a list stood inside a string) or puts a placeholder in a key gives None.
"""

from __future__ import annotations

import json
import re
import secrets
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import TypeAdapter, ValidationError
from pydantic_core import InitErrorDetails, from_json

__all__ = ["MIN_LIST_BYTES", "LiftedBody", "array_column", "lift_number_lists", "place_arrays"]

#: Shortest text of a list read into an array [bytes]; shorter lists are parsed as usual.
MIN_LIST_BYTES = 256 * 1024

#: Text read by the parser at once [bytes], cut at a comma: its Python floats are all a list costs.
_PIECE_BYTES = 1 << 20

#: A list of at least MIN_LIST_BYTES of what numbers are written with (NaN and Infinity included,
#: which the parser reads and a model refuses as not finite): no string, object or nested list.
_NUMBER_LIST = re.compile(rb"\[([-+0-9.eE,\s NaIfinity]{%d,})\]" % MIN_LIST_BYTES)

#: Most elements of one array column named in a refusal [1].
MAX_ERRORS_PER_COLUMN = 20


@dataclass(frozen=True)
class LiftedBody:
    """A body with its long lists of numbers taken out.

    Attributes
    ----------
    skeleton : bytes
        The body, each lifted list replaced by a JSON string of its placeholder.
    arrays : dict
        Placeholder -> the list's numbers as a float64 array.
    """

    skeleton: bytes
    arrays: dict[str, np.ndarray]


def _numbers(text: bytes) -> np.ndarray | None:
    """The numbers of a list's text (without its brackets), or None when it is not a JSON list of numbers."""
    pieces = []
    start, end = 0, len(text)
    stop = 0
    while start < end:
        stop = text.find(b",", start + _PIECE_BYTES) if start + _PIECE_BYTES < end else -1
        stop = end if stop < 0 else stop
        try:
            values = np.asarray(from_json(b"[" + text[start:stop] + b"]"), dtype=np.float64)
        except (ValueError, TypeError, OverflowError):
            return None  # malformed, or not numbers only: the plain parse answers
        if values.size == 0:
            return None  # an empty element between two commas, or after the last
        pieces.append(values)
        start = stop + 1
    # the last piece must end the text: a comma there is a trailing one
    return np.concatenate(pieces) if pieces and stop == end else None


def lift_number_lists(body: bytes | bytearray) -> LiftedBody | None:
    """``body`` with each list of at least :data:`MIN_LIST_BYTES` of numbers read into an array.

    Returns None when there is no such list. Each placeholder holds a random token, so no string a
    client sends is taken for one.
    """
    token = secrets.token_hex(8)
    pieces: list[bytes] = []
    arrays: dict[str, np.ndarray] = {}
    view = memoryview(body)
    done = 0
    for match in _NUMBER_LIST.finditer(body):
        values = _numbers(match.group(1))
        if values is None:
            continue
        placeholder = f"\u0000numbers {token} {len(arrays)}"
        pieces += [bytes(view[done:match.start()]), json.dumps(placeholder).encode()]
        arrays[placeholder] = values
        done = match.end()
    if not arrays:
        return None
    pieces.append(bytes(view[done:]))
    return LiftedBody(b"".join(pieces), arrays)


def place_arrays(lifted: LiftedBody, array_objects: Collection[str], everywhere: bool = False) -> Any | None:
    """The document of a lifted body, each array in its place: as the array in a member of one of the
    top-level objects ``array_objects`` (whose fields accept arrays, :func:`array_column`), as a list
    anywhere else; as the array everywhere with ``everywhere`` (for a schema that takes no long list of
    numbers at all, which then refuses it without reading it into Python floats). None when the skeleton
    is not JSON or a placeholder is not a value once."""
    try:
        document = from_json(lifted.skeleton)
    except ValueError:
        return None
    placed: list[str] = []

    def place(value: Any, arrays_here: bool) -> Any:
        if isinstance(value, str) and value in lifted.arrays:
            placed.append(value)
            return lifted.arrays[value] if arrays_here or everywhere else lifted.arrays[value].tolist()
        if isinstance(value, list):
            return [place(item, False) for item in value]
        if isinstance(value, dict):
            if any(key in lifted.arrays for key in value):
                placed.append("")  # a list where a key stood: the body was not JSON
            return {key: place(item, False) for key, item in value.items()}
        return value

    if isinstance(document, dict):
        document = {key: ({name: place(item, True) for name, item in value.items()}
                          if key in array_objects and isinstance(value, dict) else place(value, False))
                    for key, value in document.items()}
    else:
        document = place(document, False)
    return document if sorted(placed) == sorted(lifted.arrays) else None


def array_column(scalar: Any, refused: Callable[[np.ndarray], np.ndarray]) -> Callable[[Any, Any], Any]:
    """A wrap validator for a field of a scalar or a list of ``scalar`` that also takes a float64 array
    (:func:`place_arrays`), answered as it is.

    Parameters
    ----------
    scalar : type
        The annotated scalar type of an element (its bounds, finiteness).
    refused : callable
        ``refused(array) -> bool array``, True at every element ``scalar`` may refuse (at least those):
        only they are validated one by one, with ``scalar``'s own words.

    An array with refused elements raises pydantic's errors of its first :data:`MAX_ERRORS_PER_COLUMN`,
    each at the element's index, as a list's validation names them.
    """
    adapter = TypeAdapter(scalar)

    def validate(value: Any, handler: Any) -> Any:
        if not isinstance(value, np.ndarray):
            return handler(value)
        errors: list[InitErrorDetails] = []
        for index in np.flatnonzero(refused(value)):
            element = value[index].item()
            try:
                adapter.validate_python(element)
            except ValidationError as exc:
                errors += [InitErrorDetails(type=error["type"], loc=(int(index), *error["loc"]),
                                            input=element, ctx=error.get("ctx", {}))
                           for error in exc.errors()]
            if len(errors) >= MAX_ERRORS_PER_COLUMN:
                break
        if errors:
            raise ValidationError.from_exception_data("column", errors)
        return value

    return validate
