"""A range of a column or a set of its allowed values, spelled the same in every route.

A range is ``[low, high]`` or ``{"low": low, "high": high}`` (with ``"spacing"`` where a route samples it); a
set of allowed values is ``{"values": [v1, v2, ...]}``. Optimization bounds and envelopes, experiment spaces
and envelopes, sweeps and robust designs read their ranges here, so that no JSON means a range in one route
and a set of two values in another (issue 32).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["NO_SPACING", "RANGE_SPELLINGS", "SPAN_SPELLINGS", "Span", "no_range", "read_span"]


@dataclass(frozen=True)
class Span:
    """A range of a column (``values`` None) or a set of allowed values (``low``, ``high`` their ends)."""

    low: float
    high: float
    values: tuple[float, ...] | None = None
    spacing: str = "linear"

    @property
    def is_range(self) -> bool:
        """True for a range, False for a set of allowed values."""
        return self.values is None


#: How a range is spelled, in words (for messages).
RANGE_SPELLINGS = 'a range is [low, high] or {"low": low, "high": high}'
#: How a range and a set of allowed values are spelled, in words (for messages).
SPAN_SPELLINGS = f'{RANGE_SPELLINGS}; a set of allowed values is {{"values": [v1, v2, ...]}}'
#: Why a range with a spacing is refused where the whole range counts (an optimization's bounds and
#: envelope, a surrogate's space), in words.
NO_SPACING = ("spacing applies where a range is spread into levels or points (an experiment space, a "
              f"sweep's ranges); here the whole range counts: {RANGE_SPELLINGS}")


def no_range(value: Any, number: bool = False) -> str | None:
    """Why a value sent where a range is asked for is none, in one sentence; None when it may be one.

    A list of another length than two, a flag, null, and (unless ``number``: a route that takes one value
    too) a number are no range; every route that asks for a range (an optimization's bounds, a surrogate's
    space, a sweep's ranges) says so in these words.

    >>> no_range([0.1]), no_range([0.1, 0.2]), no_range(0.1, number=True)
    ('a list of 1 value is no range here: a range is [low, high] or {"low": low, "high": high}', None, None)
    """
    if isinstance(value, list | tuple) and len(value) != 2:
        what = f"a list of {len(value)} value{'' if len(value) == 1 else 's'}"
    elif isinstance(value, bool) or value is None:
        what = "null" if value is None else str(value).lower()
    elif not number and isinstance(value, int | float | np.integer | np.floating):
        what = "a number"
    else:
        return None
    return f"{what} is no range here: {RANGE_SPELLINGS}"


def _number(field: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ValueError(f"{field}: must hold numbers; got {value!r}")
    if not math.isfinite(float(value)):
        raise ValueError(f"{field}: must hold finite numbers; got {value!r}")
    return float(value)


def read_span(field: str, value: Any, number: bool = True) -> Span:
    """A range or a set of allowed values, spelled the same in every route.

    Parameters
    ----------
    field : str
        The field's name, for errors (``conditions.relative_humidity``).
    value : number, list, tuple or mapping
        ``[low, high]`` or ``{"low", "high"[, "spacing"]}`` (a range); ``{"values": [...]}`` (a set of
        allowed values); ``[value]`` or, when ``number``, a number (a range of one point: the set of it).
    number : bool
        Whether a single number is taken.

    Returns
    -------
    Span

    Raises
    ------
    ValueError
        Starting with ``field``: a list of another length than two (the two spellings explained),
        non-finite values, low > high, an empty set.

    Examples
    --------
    >>> read_span("space.load_N", [0.001, 0.05]).is_range, read_span("x", {"values": [1, 2]}).values
    (True, (1.0, 2.0))
    >>> read_span("x", [1, 2, 3])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: x: a list of 3 values is ambiguous: a range is [low, high] or {"low": low, "high": high}; ...
    """
    if isinstance(value, Mapping):
        if "values" in value:
            given = value["values"]
            if set(value) != {"values"} or not isinstance(given, list | tuple) or not given:
                raise ValueError(f"{field}: a set of allowed values is {{\"values\": [v1, v2, ...]}} (at "
                                 f"least one value, nothing else); got {value!r}")
            values = tuple(_number(field, v) for v in value["values"])
            return Span(min(values), max(values), values)
        if not {"low", "high"} <= set(value) or not set(value) <= {"low", "high", "spacing"}:
            raise ValueError(f"{field}: {SPAN_SPELLINGS}; got {value!r}")
        low, high = _number(field, value["low"]), _number(field, value["high"])
        spacing = value.get("spacing", "linear")
    elif isinstance(value, list | tuple) and len(value) == 1:  # a range of one point: the set of it
        return Span(_number(field, value[0]), _number(field, value[0]), (_number(field, value[0]),))
    elif isinstance(value, list | tuple):
        if len(value) != 2:
            raise ValueError(f"{field}: a list of {len(value)} values is ambiguous: {SPAN_SPELLINGS}")
        low, high, spacing = _number(field, value[0]), _number(field, value[1]), "linear"
    elif number and not isinstance(value, bool) and isinstance(value, int | float | np.integer | np.floating):
        low = high = _number(field, value)
        spacing = "linear"
    else:
        kind = "a number or " if number else ""
        raise ValueError(f"{field}: must be {kind}{SPAN_SPELLINGS}; got {value!r}")
    if low > high:
        raise ValueError(f"{field}: low must not exceed high; got [{low:g}, {high:g}]")
    return Span(low, high, None, spacing)
