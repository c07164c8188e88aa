"""Sweeps: points of a full-factorial grid or of a design of experiments, evaluated in chunks.

:func:`design_columns` turns a validated sweep request into input columns (422 problems name
the offending field by JSON pointer); :func:`run_sweep` evaluates them chunk by chunk,
reporting progress so that a sweep run as a job can be followed and cancelled.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from concurrent.futures import Executor
from typing import Any

import numpy as np
from scipy.stats import qmc

import physics

from .executor import evaluate_in_chunks
from .problems import validation_problem
from .schemas.sweeps import GridSweep, LatinHypercubeSweep, SobolSweep

__all__ = ["CHUNK_POINTS", "SweepPlan", "design_columns", "run_sweep"]

#: Points evaluated per chunk: bounds memory and sets how often progress is reported.
CHUNK_POINTS = 65_536

AnySweep = GridSweep | SobolSweep | LatinHypercubeSweep


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


def _check_value(name: str, value: float, pointer: str, errors: list[dict[str, str]]) -> None:
    try:
        physics.validate(name, value)
    except ValueError as exc:
        errors.append({"pointer": pointer, "detail": str(exc)})


def _spaced(low: float, high: float, fractions: np.ndarray, spacing: str) -> np.ndarray:
    """``low`` to ``high`` at ``fractions`` of the way, evenly or in even logarithms."""
    if spacing == "log":
        return np.exp(np.log(low) + fractions * (np.log(high) - np.log(low)))
    return low + fractions * (high - low)


def _grid_axes(request: GridSweep, errors: list[dict[str, str]]) -> dict[str, np.ndarray]:
    axes: dict[str, np.ndarray] = {}
    for name, axis in request.axes.model_dump(exclude_none=True).items():
        pointer = f"/axes/{name}"
        _check_value(name, axis["start"], f"{pointer}/start", errors)
        _check_value(name, axis["stop"], f"{pointer}/stop", errors)
        if axis["spacing"] == "log" and min(axis["start"], axis["stop"]) <= 0:
            errors.append({"pointer": f"{pointer}/spacing", "detail": "log spacing needs start and stop > 0"})
        if errors:
            continue
        fractions = np.linspace(0.0, 1.0, axis["num"])
        values = _spaced(axis["start"], axis["stop"], fractions, axis["spacing"])
        if physics.PARAMETERS[name].kind == "int":
            axes[name] = np.unique(np.round(values)).astype(np.int64)
        else:
            axes[name] = np.clip(_clean_decimals(values), min(axis["start"], axis["stop"]),
                                 max(axis["start"], axis["stop"]))
    return axes


def _clean_decimals(values: np.ndarray) -> np.ndarray:
    """``values`` rounded to 15 significant digits, so grid values read as typed.

    ``0.15 * 1/3`` is 0.049999999999999996 in binary; 15 digits (all that a double
    carries exactly in decimal) give back 0.05 and change a value by at most 5e-15 of itself.

    >>> _clean_decimals(0.0 + np.linspace(0.0, 1.0, 4) * 0.15).tolist()
    [0.0, 0.05, 0.1, 0.15]
    """
    return np.char.mod("%.15g", values).astype(np.float64)




def _sampled(request: SobolSweep | LatinHypercubeSweep, errors: list[dict[str, str]]
             ) -> dict[str, np.ndarray]:
    ranges = request.ranges.model_dump(exclude_none=True)
    for name, span in ranges.items():
        pointer = f"/ranges/{name}"
        _check_value(name, span["low"], f"{pointer}/low", errors)
        _check_value(name, span["high"], f"{pointer}/high", errors)
        if span["low"] > span["high"]:
            errors.append({"pointer": f"{pointer}/high", "detail": "high must be >= low"})
        if span["spacing"] == "log" and span["low"] <= 0:
            errors.append({"pointer": f"{pointer}/spacing", "detail": "log spacing needs low > 0"})
    if errors or not ranges:
        return {}
    sampler_class = qmc.Sobol if request.design == "sobol" else qmc.LatinHypercube
    # scipy >= 1.15 names the generator "rng"; older releases call it "seed".
    key = "rng" if "rng" in inspect.signature(sampler_class).parameters else "seed"
    sampler = sampler_class(len(ranges), **{key: np.random.default_rng(request.seed)})
    if request.design == "sobol":
        # The first n points of the sequence; drawing a power of two avoids scipy's balance warning.
        unit = sampler.random_base2(int(np.ceil(np.log2(max(request.points, 1)))))[: request.points]
    else:
        unit = sampler.random(request.points)
    columns = {}
    for j, (name, span) in enumerate(ranges.items()):
        low, high = span["low"], span["high"]
        if physics.PARAMETERS[name].kind == "int":
            # Each whole number in [low, high] gets an equal share of the unit interval.
            columns[name] = np.minimum(np.floor(low + unit[:, j] * (high - low + 1)), high).astype(np.int64)
        else:
            columns[name] = _spaced(low, high, unit[:, j], span["spacing"])
    return columns


def design_columns(request: AnySweep, max_points: int) -> SweepPlan:
    """The points of a sweep request.

    Parameters
    ----------
    request : GridSweep, SobolSweep or LatinHypercubeSweep
        The validated request.
    max_points : int
        Most points allowed [1].

    Returns
    -------
    SweepPlan
        Varied columns, fixed values and the number of points.

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
            count *= axis["num"]
    else:
        varied_names = list(request.ranges.model_dump(exclude_none=True))
        count = request.points
    if not varied_names:
        errors.append({"pointer": where, "detail": "vary at least one input"})
    for name in varied_names:
        if name in fixed:
            errors.append({"pointer": f"/fixed/{name}", "detail": f"{name} is varied; do not fix it too"})
    for name, spec in physics.PARAMETERS.items():
        if spec.required and name not in fixed and name not in varied_names:
            detail = f"{name} is required: vary it or fix it ({spec.range_text()} [{spec.unit}])"
            errors.append({"pointer": f"/fixed/{name}", "detail": detail})
    if count > max_points:
        errors.append({"pointer": where, "detail": f"the design has {count} points; at most {max_points}"})
    if errors:
        raise validation_problem(errors)

    if request.design == "grid":
        axes = _grid_axes(request, errors)
        if errors:
            raise validation_problem(errors)
        grids = np.meshgrid(*axes.values(), indexing="ij")
        varied = {name: grid.reshape(-1) for name, grid in zip(axes, grids, strict=True)}
    else:
        varied = _sampled(request, errors)
        if errors:
            raise validation_problem(errors)
    count = len(next(iter(varied.values())))
    return SweepPlan(varied, fixed, count)


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
        ``design``, ``count``, ``varied`` (names) and ``columns``: the varied inputs then the
        outputs, as arrays.
    """
    outputs = [str(name) for name in request.outputs] if request.outputs else list(physics.OUTPUTS)
    columns: dict[str, np.ndarray] = {name: values for name, values in plan.varied.items()}
    columns.update(evaluate_in_chunks(executor, {**plan.fixed, **plan.varied}, plan.count, outputs,
                                      request.convention, progress=progress, chunk_points=CHUNK_POINTS))
    return {"design": request.design, "count": plan.count, "varied": list(plan.varied), "columns": columns}
