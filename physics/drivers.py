"""Kinds of condition column that drive effects and drift laws, recognised by name, with their units.

A humidity column contains ``humid`` or ``rh`` (a fraction in [0, 1), or percent when the name contains
``pct``, ``percent`` or ``percentage``); a temperature column ``temp`` (degC, or kelvin when the name says
``k``, ``kelvin`` or ``kelvins``). Each unit declares the values a micro bearing's test rig plausibly records
(:attr:`DriverUnit.plausible`), which :mod:`calibrate.plausibility` reads; a law declares the values its
formula holds for as a :class:`Domain`. :mod:`physics.effects` re-exports every name here.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

__all__ = ["DRIVER_KINDS", "HUMIDITY", "TEMPERATURE", "Domain", "DriverKind", "DriverUnit", "glued_unit",
           "humidity_fraction", "name_matches", "name_words", "temperature_kelvin"]


@dataclass(frozen=True)
class Domain:
    """The values a law's driver may take, in the unit of the law's formula: an interval, each end open
    (excluded) or closed.

    Attributes
    ----------
    low, high : float
        Its ends (may be infinite).
    low_open, high_open : bool
        Whether the end itself is excluded (an infinite end is never reached).

    Examples
    --------
    >>> Domain(0.0, 1.0, low_open=True, high_open=True).contains([0.0, 0.5, 1.0]).tolist()
    [False, True, False]
    >>> Domain(0.0).text(), Domain(0.0, 1.0, True, True).in_unit(lambda x: x / 100.0).text()
    ('[0, inf)', '(0, 100)')
    """

    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False
    high_open: bool = False

    def contains(self, values) -> np.ndarray:
        """Whether each value lies in the domain (NaN does not)."""
        x = np.asarray(values, dtype=float)
        above = x > self.low if self.low_open else x >= self.low
        return above & (x < self.high if self.high_open else x <= self.high)

    def text(self) -> str:
        """The interval in words, e.g. ``(0, 1)`` or ``[0, inf)``."""
        left = "(" if self.low_open or math.isinf(self.low) else "["
        right = ")" if self.high_open or math.isinf(self.high) else "]"
        return f"{left}{self.low:g}, {self.high:g}{right}"

    def in_unit(self, to_formula: Callable) -> Domain:
        """The same domain in a column's unit, given the increasing affine map from that unit to the
        formula's (percent to a fraction, degC to K)."""
        offset = float(to_formula(np.asarray(0.0)))
        slope = float(to_formula(np.asarray(1.0))) - offset
        return replace(self, low=(self.low - offset) / slope, high=(self.high - offset) / slope)


@dataclass(frozen=True)
class DriverUnit:
    """One unit a kind of driver column may be recorded in, chosen by the words of the column's name.

    Attributes
    ----------
    unit : str
        ``"1"``, ``"%"``, ``"degC"``, ``"K"``.
    keywords : tuple of str
        Words of the name that select this unit, whole (``k`` of ``temp_k``, never the k of ``kiln``);
        empty for the default unit.
    excluded : tuple of str
        Words that veto it, whole (a temperature named with a word ``c`` or ``degc`` is not in kelvin;
        ``chamber temperature [K]`` is).
    plausible : (float, float)
        Values a micro bearing's test rig plausibly records, in this unit: beyond them the column is
        refused as a unit slip (:mod:`calibrate.plausibility`).
    """

    unit: str
    keywords: tuple[str, ...]
    excluded: tuple[str, ...]
    plausible: tuple[float, float]

    def selected_by(self, column: str) -> bool:
        """Whether a column of this name is recorded in this unit."""
        words = set(name_words(column))
        return ((not self.keywords or not words.isdisjoint(self.keywords))
                and words.isdisjoint(self.excluded))


@dataclass(frozen=True)
class DriverKind:
    """A kind of condition column that drives effects and drift laws, recognised by name.

    Attributes
    ----------
    name : str
        The quantity in words.
    keywords : tuple of str
        Prefixes of a column name's words that make it this kind (``humid``, ``rh``).
    units : tuple of DriverUnit
        The units it may be recorded in, the first selected by the name wins (the last is the default).
    """

    name: str
    keywords: tuple[str, ...]
    units: tuple[DriverUnit, ...]

    def matches(self, column: str) -> bool:
        """Whether a column of this name is of this kind."""
        return name_matches(column, self.keywords)

    def unit_of(self, column: str) -> DriverUnit:
        """The unit a column of this name is recorded in."""
        return next(u for u in self.units if u.selected_by(column))


#: Relative humidity: a fraction in [0, 1], or percent when the name says ``pct`` or ``percent``.
HUMIDITY = DriverKind("relative humidity", ("humid", "rh"), (
    DriverUnit("%", ("pct", "percent", "percentage"), (), (0.0, 100.0)),
    DriverUnit("1", (), (), (0.0, 1.0))))
#: Temperature: degC, or kelvin when the name says ``k`` or ``kelvin`` (and not ``c``/``degc``); a degC
#: column above 200 looks like kelvin, a kelvin one below 150 like degC.
TEMPERATURE = DriverKind("temperature", ("temp",), (
    DriverUnit("K", ("k", "degk", "kelvin", "kelvins"), ("c", "degc"), (150.0, math.inf)),
    DriverUnit("degC", (), (), (-273.15, 200.0))))
#: The kinds of driver column the effects and laws declare, with their units and plausible ranges.
DRIVER_KINDS: tuple[DriverKind, ...] = (HUMIDITY, TEMPERATURE)


# Units a lab glues to a quantity's word (tempF, temperatureK, rhpct), by the quantity's words: such a word
# is read as the two words it joins, so that tempF is in degF as temp_F is (never degC by default). A bare
# r (tempr, a temperature's abbreviation) is no unit here.
_GLUED_UNITS = {
    ("temperature", "temp"): ("f", "degf", "fahrenheit", "c", "degc", "celsius", "k", "degk", "kelvin",
                              "kelvins", "degr", "rankine"),
    ("humidity", "humid", "rh"): ("pct", "percent", "percentage"),
}


def glued_unit(word: str) -> tuple[str, str] | None:
    """The quantity's word and the unit's of a word that glues a unit to a quantity (``tempF``: ``temp``,
    ``F``), in the case written; None for any other word.

    >>> glued_unit("tempF"), glued_unit("RHpct"), glued_unit("temperature"), glued_unit("tempr")
    (('temp', 'F'), ('RH', 'pct'), None, None)
    """
    lower = word.lower()
    for prefixes, units in _GLUED_UNITS.items():
        for prefix in prefixes:
            if lower.startswith(prefix) and lower[len(prefix):] in units:
                return word[:len(prefix)], word[len(prefix):]
    return None


def name_words(name: str) -> list[str]:
    """The words of a column's name, lower case, split at non-alphanumerics and where a unit is glued to a
    quantity's word (:func:`glued_unit`).

    >>> name_words("T_degF"), name_words("tempF"), name_words("relative humidity [%]")
    (['t', 'degf'], ['temp', 'f'], ['relative', 'humidity'])
    """
    words = []
    for w in re.split(r"[^a-z0-9]+", name.lower()):
        glued = glued_unit(w) if w else None
        words.extend(glued if glued else [w] if w else [])
    return words


def name_matches(name: str, prefixes: tuple[str, ...]) -> bool:
    """Whether a word of a column's name (split at non-alphanumerics) starts with one of the prefixes."""
    return any(w.startswith(p) for w in name_words(name) for p in prefixes)


def humidity_fraction(name: str, values) -> np.ndarray:
    """Relative humidity as a fraction: percent when the column name says ``pct`` or ``percent``.

    Parameters
    ----------
    name : str
        Column name.
    values : array_like
        Relative humidity [1] or [%].

    Returns
    -------
    numpy.ndarray
        Relative humidity h. [1]

    Examples
    --------
    >>> humidity_fraction("relative_humidity_pct", [40.0]).tolist()
    [0.4]
    """
    x = np.asarray(values, dtype=float)
    return x / 100.0 if HUMIDITY.unit_of(name).unit == "%" else x


def temperature_kelvin(name: str, values) -> np.ndarray:
    """Temperature in kelvin: the column is in kelvin when its name says ``k`` or ``kelvin``, else degC.

    Parameters
    ----------
    name : str
        Column name, e.g. ``temperature_C`` or ``temperature_K``.
    values : array_like
        Temperature [degC] or [K].

    Returns
    -------
    numpy.ndarray
        Absolute temperature. [K]

    Examples
    --------
    >>> temperature_kelvin("temperature_C", [25.0]).tolist(), temperature_kelvin("temp_K", [300.0]).tolist()
    ([298.15], [300.0])
    """
    x = np.asarray(values, dtype=float)
    return x if TEMPERATURE.unit_of(name).unit == "K" else x + 273.15
