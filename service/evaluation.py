"""Evaluating the physics for the API: columns in, finite outputs out, errors as problems."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from microbearing import physics
from microbearing.physics.model import NOT_FINITE, ModelError, evaluate_finite

from .problems import ProblemError, pointer_at, validation_problem

__all__ = ["column_arrays", "evaluate_checked", "evaluate_point"]

# Columns read as booleans; every other column (a physics number, a calibrated model's condition) is float.
_BOOLEAN_INPUTS = frozenset(name for name, spec in physics.PARAMETERS.items() if spec.kind == "bool")


def _evaluate(function: Callable[..., Any], inputs: dict[str, Any], convention: str, pointer: str,
              **options: Any) -> Any:
    """``function(convention=..., **options, **inputs)`` (a physics evaluation), errors as problems."""
    try:
        # Extreme but allowed inputs (a groove angle next to 90 deg) overflow; the callers
        # turn non-finite outputs into 422 problems.
        with np.errstate(all="ignore"):
            return function(convention=str(convention), **options, **inputs)
    except ValueError as exc:
        name = str(exc).split(" ", 1)[0]
        where = pointer_at(pointer, name) if name in physics.PARAMETERS else pointer
        raise validation_problem([{"pointer": where, "detail": str(exc)}]) from None


def evaluate_point(inputs: dict[str, Any], convention: str) -> dict[str, float]:
    """Every output of :func:`physics.evaluate_point` at one point, as finite floats.

    Parameters
    ----------
    inputs : dict
        Scalar physics inputs by name.
    convention : str
        Key of :data:`physics.CONVENTIONS`.

    Returns
    -------
    dict of float
        Every output of :data:`physics.OUTPUTS` in its unit.

    Raises
    ------
    ProblemError
        422 for inputs the model rejects or that drive an output out of floating-point range.
    """
    values = _evaluate(physics.evaluate_point, inputs, convention, "")
    if not all(map(math.isfinite, values.values())):
        name = next(name for name, value in values.items() if not math.isfinite(value))
        raise validation_problem([{"pointer": "/", "detail": f"the model output {name} is not finite: "
                                   f"the inputs are {NOT_FINITE}"}])
    return values


def evaluate_checked(inputs: dict[str, Any], outputs: list[str] | None, convention: str,
                     pointer: str = "", first_index: int = 0) -> dict[str, np.ndarray]:
    """:func:`physics.model.evaluate_finite`, its errors as problems.

    Parameters
    ----------
    inputs : dict
        Physics inputs by name (scalars or arrays that broadcast).
    outputs : list of str or None
        Outputs to keep (all when None).
    convention : str
        Key of :data:`physics.CONVENTIONS`.
    pointer : str, default ""
        JSON pointer of the inputs in the request body, for error messages.
    first_index : int, default 0
        Index of the first point in the whole request [1], for error messages.

    Returns
    -------
    dict of numpy.ndarray
        The chosen outputs.

    Raises
    ------
    ProblemError
        422 for inputs the model rejects or that drive an output out of floating-point range.
    """
    try:
        return evaluate_finite(inputs, outputs, convention, pointer, first_index)
    except ModelError as exc:
        raise validation_problem(exc.errors) from None


def _column_array(name: str, value: list | np.ndarray) -> np.ndarray:
    """One column as an array: labels as text, a yes/no input as booleans, numbers as float64 (a large
    body's column is one already, :mod:`service.schemas.number_lists`)."""
    if isinstance(value, list) and any(isinstance(v, str) for v in value):
        return np.asarray([str(v) for v in value])
    return np.asarray(value, dtype=bool if name in _BOOLEAN_INPUTS else np.float64)


def column_arrays(points: dict[str, Any], max_points: int, pointer: str = "/points",
                  key: Callable[[str], str] = str) -> tuple[dict[str, Any], int]:
    """Turn columnar inputs into arrays and check that the lists share one length.

    Parameters
    ----------
    points : dict
        Input name (a physics input or a calibrated model's condition column) to scalar or list.
    max_points : int
        Most points allowed [1].
    pointer : str, default "/points"
        JSON pointer of ``points`` in the request body.
    key : callable, default str
        A column's key as sent, for a refusal (:meth:`service.calibrations.ReadConditions.key`).

    Returns
    -------
    inputs : dict
        Lists as NumPy arrays, scalars unchanged.
    count : int
        Number of points [1] (1 when every input is a scalar).

    Raises
    ------
    ProblemError
        422 naming the fields whose lengths differ or that are empty; 413 above ``max_points``.
    """
    lengths = {name: len(value) for name, value in points.items() if isinstance(value, list | np.ndarray)}
    empty = [name for name, length in lengths.items() if length == 0]
    if empty:
        raise validation_problem([{"pointer": pointer_at(pointer, key(name)),
                                   "detail": "a list must not be empty"} for name in empty])
    distinct = sorted(set(lengths.values()))
    if len(distinct) > 1:
        first = next(iter(lengths))
        raise validation_problem([
            {"pointer": pointer_at(pointer, key(name)),
             "detail": f"has {length} values but {key(first)} has {lengths[first]}; lists must share one "
                       "length"}
            for name, length in lengths.items() if length != lengths[first]
        ])
    count = distinct[0] if distinct else 1
    if count > max_points:
        raise ProblemError(413, f"The request has {count} points; the limit is {max_points} per request "
                                "(MICROBEARING_MAX_BATCH_POINTS).")
    inputs = {name: _column_array(name, value) if isinstance(value, list | np.ndarray) else value
              for name, value in points.items()}
    return inputs, count
