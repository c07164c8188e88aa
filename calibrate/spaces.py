"""What a lab can set, and the candidate runs of a design drawn from it (:mod:`calibrate.experiments`).

A space gives each column a range, ``[low, high]`` or ``{"low", "high", "spacing"}``, or a set of allowed
values ``{"values": [...]}``, as every route reads them (:func:`physics.spans.read_span`); the
candidates are a grid over the ranges (every whole ball count of a ``balls`` range, evenly thinned past
a dozen) with scrambled Sobol' points added.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy.stats import qmc

from microbearing import physics
from microbearing.physics.spans import read_span

__all__ = ["MAX_CANDIDATES", "candidate_points", "check_space", "read_space", "space_points"]

#: Candidate points of a design at most (grid and Sobol' set together). [1]
MAX_CANDIDATES = 3000
# Levels of each continuous column on the candidate grid (ends and middle), fewer when many columns. [1]
_GRID_LEVELS = (5, 5, 5, 3, 3)
# Ball counts on the candidate grid at most (evenly spread over an integer range, ends included). [1]
_MAX_BALL_LEVELS = 12
# Scrambled Sobol' points added to the grid (a power of two). [1]
_SOBOL_POINTS = 256


def read_space(space: Mapping[str, Any], field_name: str = "space") -> dict[str, dict[str, Any]]:
    """A space as ranges ``{"low", "high", "spacing"}`` and sets ``{"values": [...]}``, whichever spelling
    of :func:`physics.spans.read_span` each column used (``[low, high]`` is a range).

    Raises
    ------
    ValueError
        Starting with ``<field_name>.<column>``: a list of another length than two, a bad range or set.
    """
    read = {}
    for name, spec in space.items():
        span = read_span(f"{field_name}.{name}", spec, number=False)
        read[name] = ({"low": span.low, "high": span.high, "spacing": span.spacing} if span.is_range
                      else {"values": list(span.values)})
    return read


def _levels(name: str, spec: Any, levels: int) -> np.ndarray:
    """The values of one column of a space: a set as given, a range at ``levels`` levels."""
    if "values" in spec:
        return np.asarray(spec["values"], dtype=float)
    low, high = float(spec["low"]), float(spec["high"])
    if name == "balls":
        values = np.arange(int(np.ceil(low)), int(np.floor(high)) + 1)
        if values.size > _MAX_BALL_LEVELS:
            values = np.unique(np.round(np.linspace(values[0], values[-1], _MAX_BALL_LEVELS)).astype(int))
        return values.astype(float)
    return _spaced(low, high, np.linspace(0.0, 1.0, levels), spec.get("spacing", "linear"))


def _spaced(low: float, high: float, fractions: np.ndarray, spacing: str) -> np.ndarray:
    if spacing == "log":
        return np.exp(np.log(low) + fractions * (np.log(high) - np.log(low)))
    return low + fractions * (high - low)


def check_space(space: Mapping[str, Any], conditions: Sequence[str], field_name: str = "space") -> None:
    """Refuse a space column that is neither a physics input nor a known condition, or a bad range.

    Raises
    ------
    ValueError
        Starting with ``<field_name>.<column>``: an unknown column, ``low`` > ``high``, a log spacing
        of a range that is not positive, an empty list, a ball range without a whole number, or a
        value outside the physics input's range.
    """
    for name, spec in read_space(space, field_name).items():
        where = f"{field_name}.{name}"
        if name not in physics.PARAMETERS and name not in conditions:
            known = ", ".join(conditions) or "none"
            raise ValueError(f"{where}: not a physics input nor a condition column of the data ({known})")
        if "values" not in spec:
            low, high = float(spec["low"]), float(spec["high"])
            if not low <= high:
                raise ValueError(f"{where}: low must not exceed high; got {low:g} > {high:g}")
            if spec.get("spacing", "linear") == "log" and low <= 0:
                raise ValueError(f"{where}: log spacing needs low > 0")
            if name == "balls" and int(np.floor(high)) < int(np.ceil(low)):
                raise ValueError(f"{where}: the range holds no whole number of balls")
            values = [low, high]
        else:
            values = list(spec["values"])
            if not values:
                raise ValueError(f"{where}: give at least one value")
            if any(isinstance(v, bool) or not np.isfinite(float(v)) for v in values):
                raise ValueError(f"{where}: values must be finite numbers")
        if name in physics.PARAMETERS:  # a count of 6.5 refused in the words of every other door
            for value in values:
                try:
                    physics.validate(name, value)
                except ValueError as exc:
                    raise ValueError(f"{where}: {exc}") from None


def space_points(space: Mapping[str, Any], max_points: int = MAX_CANDIDATES, seed: int = 0,
                 sobol_points: int = _SOBOL_POINTS) -> dict[str, np.ndarray]:
    """Points covering a space: its grid (every allowed value and ball count, each continuous range at
    its ends and middle levels), thinned at random past ``max_points``, plus a scrambled Sobol' set.

    Parameters
    ----------
    space : mapping
        Column -> a range, ``[low, high]`` or ``{"low", "high", "spacing"}`` (``balls``: every whole
        count in it), or a set of allowed values ``{"values": [...]}``, in the column's unit.
    max_points : int
        Points at most. [1]
    seed : int
        Seed of the thinning and of the Sobol' scramble.
    sobol_points : int
        Sobol' points added when the space has a continuous range. [1]

    Returns
    -------
    dict of str to numpy.ndarray
        One column per name of ``space``, one value per point.
    """
    space = read_space(space)
    names = list(space)
    continuous = [n for n in names if "values" not in space[n] and n != "balls"]
    levels = _GRID_LEVELS[min(len(continuous), len(_GRID_LEVELS) - 1)] if continuous else 1
    axes = [_levels(n, space[n], levels) for n in names]
    rng = np.random.default_rng(seed)
    grid_size = math.prod(a.size for a in axes) if axes else 0  # exact: 200 values on 12 columns is 4e27
    extra = sobol_points if continuous else 0
    keep = max(max_points - extra, 1)
    if grid_size <= keep:
        mesh = np.meshgrid(*axes, indexing="ij")
        columns = {n: m.ravel() for n, m in zip(names, mesh, strict=True)}
    else:  # grid points drawn at random, each column's level independently, duplicates dropped
        index = np.unique(np.column_stack([rng.integers(0, a.size, keep) for a in axes]), axis=0)
        columns = {n: a[index[:, j]] for j, (n, a) in enumerate(zip(names, axes, strict=True))}
    if extra:
        sample = qmc.Sobol(len(continuous), scramble=True, seed=seed).random(extra)
        added = {n: _spaced(float(space[n]["low"]), float(space[n]["high"]), sample[:, j],
                            space[n].get("spacing", "linear")) for j, n in enumerate(continuous)}
        for n, a in zip(names, axes, strict=True):
            if n not in added:
                added[n] = a[rng.integers(0, a.size, extra)]
        columns = {n: np.concatenate([columns[n], added[n]]) for n in names}
    return columns


def candidate_points(space: Mapping[str, Any], seed: int = 0) -> dict[str, np.ndarray]:
    """The candidate points of a design over ``space`` (:func:`space_points`, at most
    :data:`MAX_CANDIDATES`)."""
    return space_points(space, MAX_CANDIDATES, seed)
