"""Designs over physics inputs given by their ranges: axes of a full-factorial grid and space-filling samples.

The REST API's sweeps (``/v1/sweeps``) evaluate the physics at these points. Samples are drawn by
:func:`surrogate.sampling.unit_design`, the sampler a surrogate's designs use, then mapped to each
input's range: evenly or evenly in logarithm, whole-number inputs (``balls``) to whole numbers.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from microbearing import physics

from .sampling import unit_design

__all__ = ["SPACINGS", "grid_values", "sampled_values"]

#: How values are spread between the ends of a range: evenly, or evenly in logarithm (ends > 0).
SPACINGS = ("linear", "log")


def _spaced(low: float, high: float, fractions: np.ndarray, spacing: str) -> np.ndarray:
    """``low`` to ``high`` at ``fractions`` of the way, evenly or in even logarithms."""
    if spacing == "log":
        return np.exp(np.log(low) + fractions * (np.log(high) - np.log(low)))
    return low + fractions * (high - low)


def _clean_decimals(values: np.ndarray) -> np.ndarray:
    """``values`` rounded to 15 significant digits, so grid values read as typed.

    ``0.15 * 1/3`` is 0.049999999999999996 in binary; 15 digits (all that a double
    carries exactly in decimal) give back 0.05 and change a value by at most 5e-15 of itself.

    >>> _clean_decimals(0.0 + np.linspace(0.0, 1.0, 4) * 0.15).tolist()
    [0.0, 0.05, 0.1, 0.15]
    """
    return np.char.mod("%.15g", values).astype(np.float64)


def grid_values(name: str, start: float, stop: float, num: int, spacing: str = "linear") -> np.ndarray:
    """The values of one axis of a grid over the physics input ``name``.

    Parameters
    ----------
    name : str
        A key of :data:`physics.PARAMETERS`.
    start, stop : float
        The axis's ends, included (``start > stop`` runs backwards). [unit of the input]
    num : int
        Number of values, >= 1. [1]
    spacing : {"linear", "log"}, default "linear"
        Evenly spaced, or evenly in logarithm (ends > 0).

    Returns
    -------
    numpy.ndarray
        A whole-number input's distinct rounded values (int64, ascending); another input's ``num``
        values written to 15 significant digits (0.05 as typed, not 0.049999999999999996), within
        the ends. [unit of the input]

    Examples
    --------
    >>> grid_values("load_N", 0.0, 0.15, 4).tolist()
    [0.0, 0.05, 0.1, 0.15]
    >>> grid_values("balls", 3, 5, 5).tolist()
    [3, 4, 5]
    """
    values = _spaced(start, stop, np.linspace(0.0, 1.0, num), spacing)
    if physics.PARAMETERS[name].kind == "int":
        return np.unique(np.round(values)).astype(np.int64)
    return np.clip(_clean_decimals(values), min(start, stop), max(start, stop))


def sampled_values(ranges: Mapping[str, tuple[float, float, str]], n: int, method: str = "sobol",
                   seed: int | None = None) -> dict[str, np.ndarray]:
    """``n`` points of a scrambled Sobol' or plain Latin-hypercube design over ranges of physics inputs.

    Parameters
    ----------
    ranges : mapping of str to (float, float, str)
        ``name -> (low, high, spacing)`` for each varied input (:data:`physics.PARAMETERS`), ``spacing``
        one of :data:`SPACINGS`. [unit of the input]
    n : int
        Number of points, >= 1. [1]
    method : {"sobol", "latin_hypercube"}, default "sobol"
        The design (:func:`surrogate.sampling.unit_design`, its Latin hypercube not optimized).
    seed : int or None, default None
        Seed of the scrambling; None draws a fresh one.

    Returns
    -------
    dict of str to numpy.ndarray
        One column of ``n`` values per input: whole-number inputs as int64, each whole number of
        ``[low, high]`` with an equal share of the unit interval (log spacing: k with a share in
        proportion to log((k + 1) / k)). [unit of the input]

    Examples
    --------
    >>> columns = sampled_values({"balls": (3, 6, "linear"), "load_N": (1e-3, 1e-1, "log")}, 8, seed=0)
    >>> sorted(set(columns["balls"].tolist())) <= [3, 4, 5, 6], bool(columns["load_N"].min() >= 1e-3)
    (True, True)
    """
    unit = unit_design(len(ranges), n, method, np.random.default_rng(seed), lhs_optimization=None)
    columns = {}
    for j, (name, (low, high, spacing)) in enumerate(ranges.items()):
        if physics.PARAMETERS[name].kind == "int" and spacing == "log":
            # Each whole number k in [low, high] gets the share log((k + 1) / k) of [low, high + 1).
            spread = np.exp(np.log(low) + unit[:, j] * np.log((high + 1.0) / low))
            columns[name] = np.minimum(np.floor(spread), high).astype(np.int64)
        elif physics.PARAMETERS[name].kind == "int":
            # Each whole number in [low, high] gets an equal share of the unit interval.
            columns[name] = np.minimum(np.floor(low + unit[:, j] * (high - low + 1)), high).astype(np.int64)
        else:
            columns[name] = _spaced(low, high, unit[:, j], spacing)
    return columns
