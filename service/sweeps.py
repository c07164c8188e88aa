"""Sweeps: points of a full-factorial grid or of a design of experiments, evaluated in chunks.

:func:`design_size` checks a sweep request and counts its points without building them (422
problems name the offending field by JSON pointer; :func:`check_result_size` answers 413 for a
result that could exceed the size limit, bounded before any point is computed);
:func:`design_columns` builds its input columns (the values of :mod:`surrogate.designs`: grid axes,
Sobol' and Latin-hypercube samples);
:func:`run_sweep` evaluates them chunk by chunk, reporting progress so that a sweep run as a job
can be followed and cancelled. A sweep job builds its columns when it starts: a queued job holds
only its request.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Executor
from typing import Any

import numpy as np

from microbearing import physics
from microbearing.physics.slips import input_slips
from microbearing.surrogate.designs import grid_values, sampled_values

from .executor import evaluate_in_chunks
from .models import physics_in
from .problems import ProblemError, pointer_at, validation_problem
from .schemas.friction import InputKeys
from .schemas.sweeps import GridSweep, LatinHypercubeSweep, SobolSweep
from .store import json_bytes

__all__ = ["CHUNK_POINTS", "MAX_NUMBER_BYTES", "SweepPlan", "check_result_size", "design_columns",
           "design_size", "input_warnings", "result_bytes_bound", "run_sweep", "sent_columns",
           "sent_factors", "stored_request"]

#: Points evaluated per chunk: bounds memory and sets how often progress is reported.
CHUNK_POINTS = 65_536

AnySweep = GridSweep | SobolSweep | LatinHypercubeSweep

#: Longest JSON text of a float64 in a result (the shortest round-trip form :func:`json_bytes` writes):
#: a sign, 17 significant digits, a point and a three-digit exponent, as in -2.2250738585072014e-308.
MAX_NUMBER_BYTES = 24


class SweepPlan:
    """The points of a sweep, ready to evaluate.

    Attributes
    ----------
    varied : dict of numpy.ndarray
        Column of every varied input, one value per point, in the input's unit.
    fixed : dict
        Values of the inputs held constant.
    count : int
        Number of points [1].
    """

    def __init__(self, varied: dict[str, np.ndarray], fixed: dict[str, Any], count: int):
        self.varied = varied
        self.fixed = fixed
        self.count = count


def _sent(owner: InputKeys, base: str, name: str) -> tuple[str, str]:
    """The pointer to input ``name`` of ``owner`` (at ``base``) by its key as sent (``load [mN]`` of
    load_N), and the words a refusal of its value ends with (empty when it was sent under its own name)."""
    renamed = owner.sent_as(name)
    if renamed is None:
        return f"{base}/{name}", ""
    unit = physics.PARAMETERS[name].unit
    return pointer_at(base, renamed[0]), f" (sent as {renamed[0]}, read as {name} [{unit}])"


def _check_value(name: str, value: float, pointer: str, errors: list[dict[str, str]],
                 words: str = "") -> None:
    try:
        physics.validate(name, value)
    except ValueError as exc:
        errors.append({"pointer": pointer, "detail": str(exc) + words})


def _grid_axes(request: GridSweep, errors: list[dict[str, str]]) -> dict[str, np.ndarray]:
    axes: dict[str, np.ndarray] = {}
    for name, axis in request.axes.model_dump(exclude_none=True).items():
        pointer, words = _sent(request.axes, "/axes", name)
        if "values" in axis:
            for i, value in enumerate(axis["values"]):
                _check_value(name, value, f"{pointer}/values/{i}", errors, words)
            if not errors:
                whole = physics.PARAMETERS[name].kind == "int"
                axes[name] = np.asarray(axis["values"], dtype=np.int64 if whole else np.float64)
            continue
        _check_value(name, axis["start"], f"{pointer}/start", errors, words)
        _check_value(name, axis["stop"], f"{pointer}/stop", errors, words)
        if axis["spacing"] == "log" and min(axis["start"], axis["stop"]) <= 0:
            errors.append({"pointer": f"{pointer}/spacing", "detail": "log spacing needs start and stop > 0"})
        if errors:
            continue
        axes[name] = grid_values(name, axis["start"], axis["stop"], axis["num"], axis["spacing"])
    return axes


def _check_ranges(request: SobolSweep | LatinHypercubeSweep, errors: list[dict[str, str]]) -> None:
    for name in request.ranges.model_dump(exclude_none=True):
        span = getattr(request.ranges, name)
        pointer, words = _sent(request.ranges, "/ranges", name)
        low, high = (f"{pointer}/{span.pointer(end)}" for end in ("low", "high"))
        _check_value(name, span.low, low, errors, words)
        _check_value(name, span.high, high, errors, words)
        if span.low > span.high:
            errors.append({"pointer": high, "detail": "high must be >= low"})
        if span.spacing == "log" and span.low <= 0:
            errors.append({"pointer": f"{pointer}/spacing", "detail": "log spacing needs low > 0"})


def design_size(request: AnySweep, max_points: int) -> int:
    """Check a sweep request and count its points, without building them.

    Parameters
    ----------
    request : GridSweep, SobolSweep or LatinHypercubeSweep
        The validated request.
    max_points : int
        Most points allowed [1].

    Returns
    -------
    int
        Number of points [1] that :func:`design_columns` builds.

    Raises
    ------
    ProblemError
        422 naming every offending field by JSON pointer.
    """
    errors: list[dict[str, str]] = []
    fixed = request.fixed.model_dump(exclude_none=True)
    where = "/axes" if request.design == "grid" else "/ranges"
    if request.design == "grid":
        varied_names = list(request.axes.model_dump(exclude_none=True))
        count = 1
        for axis in request.axes.model_dump(exclude_none=True).values():
            count *= len(axis["values"]) if "values" in axis else axis["num"]
    else:
        varied_names = list(request.ranges.model_dump(exclude_none=True))
        count = request.points
    if not varied_names:
        errors.append({"pointer": where, "detail": "vary at least one input"})
    for name in varied_names:
        if name in fixed:
            errors.append({"pointer": _sent(request.fixed, "/fixed", name)[0],
                           "detail": f"{name} is varied; do not fix it too"})
    for name, spec in physics.PARAMETERS.items():
        if spec.required and name not in fixed and name not in varied_names:
            detail = f"{name} is required: vary it or fix it ({spec.range_text()} [{spec.unit}])"
            errors.append({"pointer": f"/fixed/{name}", "detail": detail})
    if count > max_points:
        errors.append({"pointer": where, "detail": f"the design has {count} points; at most {max_points} "
                       "(MICROBEARING_MAX_SWEEP_POINTS)"})
    if errors:
        raise validation_problem(errors)
    if request.design == "grid":
        # Axes of whole numbers lose repeated values: the count is that of the distinct ones.
        count = int(np.prod([len(values) for values in _grid_axes(request, errors).values()]))
    else:
        _check_ranges(request, errors)
    if errors:
        raise validation_problem(errors)
    return count


def _numbers(value: Any) -> list[Any]:
    """The numbers of a varied input as sent: a pair, a set's values, a range's or an axis's ends."""
    if isinstance(value, dict):
        return list(value["values"]) if "values" in value else [value[k] for k in ("start", "stop", "low",
                                                                                  "high") if k in value]
    return list(value) if isinstance(value, list | tuple) else [value]


def input_warnings(request: AnySweep) -> list[str]:
    """The unit slips the sweep's inputs look like (:func:`physics.slips.input_slips`: a speed above 10 m/s
    as mm/s), in the words /v1/friction warns with, each judged as its key was sent; the sweep runs as
    asked. A varied input is judged by its values or the ends of its range."""
    varied = request.axes if request.design == "grid" else request.ranges
    inputs: dict[str, Any] = dict(request.fixed.model_dump(exclude_none=True))
    sent = dict(request.fixed.renamed)
    for name, value in varied.model_dump(exclude_none=True).items():
        inputs[name] = np.asarray(_numbers(value), dtype=float)
        renamed = varied.sent_as(name)
        if renamed is not None:
            sent[name] = (renamed[0], _numbers(renamed[1]))
    return input_slips(inputs, sent)


def result_bytes_bound(request: AnySweep, count: int) -> int:
    """The most bytes the JSON of a sweep's result can take, computed before any point is.

    Exact but for the digits of values not known before they are computed: the document's
    structure (keys, brackets, separators), the design, the count, the fixed inputs and the names are
    counted byte for byte, and so are the varied inputs of a grid (each axis's values, as written, times
    the times they repeat). An output value, and an input of a Sobol or Latin hypercube design,
    is counted at the longest form of a double (:data:`MAX_NUMBER_BYTES`); the result is never
    longer, and shorter by what those values' digits fall short of it.

    Parameters
    ----------
    request : GridSweep, SobolSweep or LatinHypercubeSweep
        The validated request.
    count : int
        Number of points [1], from :func:`design_size`.

    Returns
    -------
    int
        Upper bound of ``len(json_bytes(run_sweep(...)))`` [bytes].
    """
    outputs = list(request.outputs or physics.OUTPUTS)
    if request.design == "grid":
        axes = _grid_axes(request, [])
        varied = list(axes)
    else:
        axes = {}
        varied = list(request.ranges.model_dump(exclude_none=True))
    columns = [*varied, *outputs]
    skeleton = {"design": request.design, "count": count, "varied": varied,
                "fixed": request.fixed.model_dump(exclude_none=True),
                "columns": {name: [] for name in columns}}
    if warnings := input_warnings(request):
        skeleton["input_warnings"] = warnings
    # each input sent under another key, its key, unit and factors (sent_columns), a fixed one's value as it
    # will be written: none of it grows with the count
    sent = sent_columns(request, SweepPlan({name: np.empty(0) for name in varied}, skeleton["fixed"], 0))
    if sent:
        skeleton["as_sent"] = sent
    size = len(json_bytes(skeleton)) + len(columns) * max(count - 1, 0)  # the commas between values
    for name in varied:
        if name in axes:
            values = axes[name]
            digits = len(json_bytes(values)) - 2 - max(values.size - 1, 0)  # without brackets and commas
            size += digits * (count // max(values.size, 1))
        else:
            size += count * MAX_NUMBER_BYTES
    return size + len(outputs) * count * MAX_NUMBER_BYTES


def check_result_size(request: AnySweep, count: int, max_result_bytes: int) -> None:
    """413 when a sweep's result could exceed ``max_result_bytes`` of JSON (:func:`result_bytes_bound`).

    A sweep accepted here never fails for its size once computed.

    Parameters
    ----------
    request : GridSweep, SobolSweep or LatinHypercubeSweep
        Its outputs and varied inputs.
    count : int
        Number of points [1], from :func:`design_size`.
    max_result_bytes : int
        Largest stored result [bytes].

    Raises
    ------
    ProblemError
        413 naming the limit.
    """
    bound = result_bytes_bound(request, count)
    if bound > max_result_bytes:
        raise ProblemError(413, f"The result of {count} points could take up to {bound} bytes of JSON (every "
                                f"value not known in advance counted at {MAX_NUMBER_BYTES} characters), more "
                                f"than the limit of {max_result_bytes} (MICROBEARING_MAX_RESULT_BYTES); ask "
                                "for fewer points or outputs.", title="Result too large")


def design_columns(request: AnySweep, max_points: int) -> SweepPlan:
    """The points of a sweep request (arguments as :func:`design_size`).

    Returns
    -------
    SweepPlan
        Varied columns, fixed values and the number of points.

    Raises
    ------
    ProblemError
        422 naming every offending field by JSON pointer (see :func:`design_size`).
    """
    count = design_size(request, max_points)
    if request.design == "grid":
        axes = _grid_axes(request, [])
        grids = np.meshgrid(*axes.values(), indexing="ij")
        varied = {name: grid.reshape(-1) for name, grid in zip(axes, grids, strict=True)}
    else:
        ranges = {name: (span["low"], span["high"], span["spacing"])
                  for name, span in request.ranges.model_dump(exclude_none=True).items()}
        # The first points of a scrambled Sobol' sequence, or a plain (unoptimized) Latin hypercube.
        varied = sampled_values(ranges, request.points, request.design, request.seed)
    return SweepPlan(varied, request.fixed.model_dump(exclude_none=True), count)


def stored_request(request: AnySweep) -> dict[str, Any]:
    """The request as a job keeps it (JSON, rebuilt by its kind in any process, after a restart too): its
    dump with each input sent under another key back under that key and as sent, so that the job answers
    in them as a sweep answered at once does (:func:`sent_columns`)."""
    stored = request.model_dump(mode="json")
    for part in ("fixed", "axes", "ranges"):
        owner = getattr(request, part, None)
        if isinstance(owner, InputKeys) and isinstance(stored.get(part), dict):
            for name, (key, value) in owner.renamed.items():
                stored[part].pop(name, None)
                stored[part][key] = value
    return stored


def _sent_readings(request: AnySweep) -> dict[str, Any]:
    """How each input the request sent under another key was read (:class:`physics.columns.Reading`)."""
    varied = getattr(request, "axes", None) or getattr(request, "ranges", None)
    return {**request.fixed.readings, **(varied.readings if isinstance(varied, InputKeys) else {})}


def sent_columns(request: AnySweep, plan: SweepPlan) -> dict[str, dict[str, Any]]:
    """Each input the request sent under another key (``speed [mm/min]``), under that key: ``column``, the
    input it was read as, how its values convert into the key's unit (:func:`sent_factors`: ``unit``,
    ``factor``, ``offset``) and, for a fixed input, its value (``values``) in that unit
    (:meth:`physics.columns.Reading.set_point`: 1000, not 999.9999999999). A varied input's values are not
    repeated here (they would double the JSON of a large sweep): ``columns`` holds them in SI, the factors
    give them in the key's unit, and the CSV form of the table gives them so (:func:`service.tables.
    sweep_table`)."""
    out: dict[str, dict[str, Any]] = {}
    for name, reading in _sent_readings(request).items():
        if name in plan.varied:
            part: dict[str, Any] = {"column": name, **sent_factors(reading)}
        elif name in plan.fixed and not isinstance(plan.fixed[name], bool):
            value = reading.set_point(plan.fixed[name]) if reading.reading else plan.fixed[name]
            part = {"column": name, **sent_factors(reading), "values": value}
        else:
            continue
        out[reading.sent] = part
    return out


def sent_factors(reading: Any) -> dict[str, Any]:
    """How a column's values (SI) convert into the unit its key was sent in: ``value as sent = column value x
    factor + offset`` (the inverse of :meth:`physics.columns.Reading.convert`); ``unit`` is that unit (the
    column's own when the key only renamed it).

    >>> from microbearing.physics.columns import read_name
    >>> sent_factors(read_name("speed [mm/min]")), sent_factors(read_name("load [N]"))
    ({'unit': 'mm/min', 'factor': 60000.0, 'offset': 0.0}, {'unit': 'N', 'factor': 1.0, 'offset': 0.0})
    """
    if not reading.reading:
        return {"unit": physics.PARAMETERS[reading.name].unit, "factor": 1.0, "offset": 0.0}
    factor = float(reading.divisor) if reading.divisor is not None else 1.0 / float(reading.scale)
    return {"unit": reading.sent_unit, "factor": factor, "offset": 0.0 - float(reading.offset) * factor}


def run_sweep(request: AnySweep, plan: SweepPlan,
              progress: Callable[[float], None] | None = None,
              executor: Executor | None = None) -> dict[str, Any]:
    """Evaluate a sweep chunk by chunk.

    Parameters
    ----------
    request : GridSweep, SobolSweep or LatinHypercubeSweep
        The request (design, outputs, convention).
    plan : SweepPlan
        Its points, from :func:`design_columns`.
    progress : callable, optional
        Called with the fraction done [1] after each chunk; may raise to stop the sweep.
    executor : concurrent.futures.Executor, optional
        Runs the chunks (the app's pool or dask cluster, see :mod:`service.executor`); inline when None.

    Returns
    -------
    dict
        ``design``, ``count``, ``varied`` (names), ``fixed`` (the request's fixed inputs, name ->
        value in its unit) and ``columns``: the varied inputs then the outputs, as arrays
        (:func:`service.tables.sweep_table` adds the fixed inputs as columns for CSV).
    """
    columns: dict[str, np.ndarray] = {name: values for name, values in plan.varied.items()}
    columns.update(evaluate_in_chunks(executor, {**plan.fixed, **plan.varied}, plan.count, request.outputs,
                                      physics_in(request.convention), progress=progress,
                                      chunk_points=CHUNK_POINTS))
    document = {"design": request.design, "count": plan.count, "varied": list(plan.varied),
                "fixed": dict(plan.fixed), "columns": columns}
    if sent := sent_columns(request, plan):
        document["as_sent"] = sent
    if warnings := input_warnings(request):
        document["input_warnings"] = warnings
    return document
