"""The column registry: every input and condition column, its SI unit, the spellings and units it
accepts, its range and its unit-slip rule, for every door (tables, API points, envelopes, the CLI).

A column is sent under a name that may carry a unit: in brackets (``speed [mm/s]``,
``relative humidity [%]``), as a suffix (``speed_mm_s``, ``load_mN``, ``temp_F``) or as its SI
name (``speed_m_s``). :func:`read_name` says how such a name is read: which column, and how its
values convert to that column's unit, through pint's one unit registry (a slider mass in g is read
as its weight in N). :func:`match_column` reads a name sent at prediction against the columns a
model knows, so that the upload's header (``relative humidity [%]``) or another unit of the same
quantity (``temperature_C`` for a model of ``temperature_K``) is converted, never read in the wrong
unit. :mod:`physics.slips` holds the one rule for values that look like a unit slip (speed above
10 m/s: mm/s; a humidity fraction of 50: percent). :mod:`physics.spans` reads a range (``[low, high]``
or ``{"low", "high"}``) or a set of allowed values (``{"values": [...]}``) the same way in every route.

Physics inputs are those of :data:`physics.parameters.PARAMETERS`, in their units. Conditions are
columns of measured data that only a calibrated model reads; the named ones (:data:`CONDITIONS`)
are recognised by the words of their names as the terms of :mod:`physics.effects` recognise their
drivers, and read in the unit the terms read them in (:func:`physics.effects.humidity_fraction`,
:func:`physics.effects.temperature_kelvin`); any other condition is read as sent.
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .drivers import glued_unit, name_words
from .effects import humidity_fraction, temperature_kelvin
from .parameters import PARAMETERS

__all__ = ["CONDITIONS", "SLIP_LIMITS", "STANDARD_GRAVITY_M_S2", "ColumnError", "Condition",
           "Reading", "accepted_spellings", "counted_from_zero", "driver_unit", "from_si", "input_bases",
           "match_column", "outside_mask", "outside_range", "physical_range", "read_key", "read_name",
           "unit_of", "unknown_column", "whole_number"]

#: Standard gravity, the weight of a slider mass given in g. [m/s^2]
STANDARD_GRAVITY_M_S2 = 9.80665

#: Largest value of a physics input a micro ball bearing plausibly sees, with the likely unit slip and its
#: factor to SI: measured data beyond it are refused. [unit of the input]
SLIP_LIMITS: dict[str, tuple[float, str, float]] = {
    "speed_m_s": (10.0, "mm/s", 1e-3),
    "load_N": (1.0, "mN", 1e-3),
    "ball_diameter_m": (1e-2, "mm", 1e-3),
}


class ColumnError(ValueError):
    """A column name (or its unit) that no door can read; ``column`` is the name as sent."""

    def __init__(self, column: str, message: str):
        super().__init__(message)
        self.column = column


@dataclass(frozen=True)
class Condition:
    """A named condition column: a quantity that only a calibrated model's terms read.

    Attributes
    ----------
    name : str
        The canonical name, with its SI unit (``relative_humidity`` [1], ``temperature_K``).
    unit : str
        Its unit, as pint reads it (``"1"`` for a fraction).
    description : str
        What it is, in one sentence.
    keywords : tuple of str
        Prefixes of the words of a column's name that make it this condition (as the terms read them).
    minimum, maximum : float or None
        Its physical range in ``unit``.
    exclusive_minimum : bool
        Whether ``minimum`` itself lies outside (a temperature above 0 K).
    integer : bool
        Whether its values are whole numbers.
    from_zero : bool
        Whether it is counted from zero (a run's cycles or time): 0, its first value, is never an
        extrapolation, however its measured values spread.
    """

    name: str
    unit: str
    description: str
    keywords: tuple[str, ...]
    minimum: float | None = None
    maximum: float | None = None
    exclusive_minimum: bool = False
    integer: bool = False
    from_zero: bool = False

    def matches(self, name: str) -> bool:
        """Whether a column's name is this condition (a word of it starts with a keyword)."""
        return any(w.startswith(k) for w in name_words(name) for k in self.keywords)


#: The named conditions, by canonical name.
CONDITIONS: dict[str, Condition] = {c.name: c for c in [
    Condition("relative_humidity", "1", "Relative humidity of the air around the bearing, a fraction "
              "(percent when the name says pct or percent).", ("humid", "rh"), 0.0, 1.0),
    Condition("temperature_K", "K", "Temperature of the bearing (degC unless the name says K).",
              ("temp",), 0.0, exclusive_minimum=True),
    Condition("cycles", "1", "Strokes, passes or cycles run since the start (running-in).",
              ("cycle", "pass", "stroke"), 0.0, integer=True, from_zero=True),
    Condition("time_h", "h", "Time run since the start (running-in), in the unit its name says.",
              ("time",), 0.0, from_zero=True),
]}

# Units the words of a condition's name may say, by the condition; the first word found counts.
_UNIT_WORDS = {
    "relative_humidity": {"pct": "percent", "percent": "percent", "percentage": "percent"},
    "temperature_K": {"k": "K", "degk": "K", "kelvin": "K", "kelvins": "K", "c": "degC", "degc": "degC",
                      "celsius": "degC", "f": "degF", "degf": "degF", "fahrenheit": "degF", "r": "degR",
                      "degr": "degR", "rankine": "degR"},
    "time_h": {"s": "s", "sec": "s", "min": "min", "h": "h", "hr": "h", "hours": "h", "d": "day",
               "days": "day"},
}
# Temperature units the terms of physics.effects do not read: a name saying one is converted to kelvin.
_UNREAD_TEMPERATURES = {"degF", "degR"}
# Words of a condition's name that state a unit; dropped when brackets give the unit, so that the terms,
# which read units from names (pct, C, K), do not convert twice.
_DROPPED_WORDS = {"pct", "percent", "percentage", "c", "k", "degk", "degc", "kelvin", "kelvins", "celsius",
                  "f", "degf", "fahrenheit", "r", "degr", "rankine"}
# Unit symbols of the physics names' suffixes (load_N -> N, speed_m_s -> m/s, ...).
_SUFFIXES = {"N": "N", "m/s": "m_s", "deg": "deg", "m": "m", "J/m^2": "J_m2", "N/m": "N_m", "Pa*s": "Pa_s",
             "1/Pa": "1_Pa", "Pa": "Pa"}
# SI units of other conditions by dimension, with the suffix their new name gets (dimensionless: none).
_SI_BY_DIMENSION = {"[length]": ("m", "m"), "[time]": ("s", "s"), "[length] / [time]": ("m/s", "m_s"),
                    "[length] * [mass] / [time] ** 2": ("N", "N"), "[mass]": ("kg", "kg"),
                    "[mass] / [length] / [time] ** 2": ("Pa", "Pa"), "[temperature]": ("K", "K"),
                    "1 / [time]": ("1/s", "1_s")}
_BRACKETS = re.compile(r"^(?P<name>.*?)\s*(\[(?P<square>[^\]]*)\]|\((?P<round>[^)]*)\))\s*$")
_DEGREE = "(?:deg(?:ree)?s?|[\u00b0\u00ba\u02da])\\s*"  # deg, degrees, the degree sign or look-alikes (º, ˚)
_UNIT_SPELLINGS = [(re.compile(f"(?i){_DEGREE}C|\u2103|(?:{_DEGREE})?celsius"), "degC"),
                   (re.compile(f"(?i){_DEGREE}F|\u2109|(?:{_DEGREE})?fahrenheit"), "degF"),
                   (re.compile(f"(?i){_DEGREE}K|\u212a|(?:{_DEGREE})?kelvins?"), "K"),
                   (re.compile(f"(?i){_DEGREE}R|(?:{_DEGREE})?rankine"), "degR"),
                   (re.compile("(?i)\uff05|percent"), "%")]  # and the full-width percent sign


# A humidity's % written beside its name rather than in brackets (RH%, humidity_%, %RH): RH [%].
_PERCENT = re.compile(r"^\s*(?:%[\s_]*(?P<after>[^\s_%].*?)|(?P<before>.*?[^\s_%])[\s_]*%)\s*$")


def _bracket_unit(match: re.Match, as_written: bool = False) -> str:
    """The unit text in the brackets of a name :data:`_BRACKETS` matched (``mm/s`` of ``speed [mm/s]``), as
    pint spells it (unambiguous spellings it does not read, ``℃``, ``deg C``: :data:`_UNIT_SPELLINGS`)."""
    text = match.group("square") if match.group("square") is not None else match.group("round")
    return text if as_written else next((u for p, u in _UNIT_SPELLINGS if p.fullmatch(text.strip())), text)


@functools.cache
def _registry():
    import pint

    return pint.UnitRegistry()


def _unit(text: str):
    """A pint unit from a unit text (``m2`` as ``m**2``, ``°C`` as ``degC``, empty or 1: none)."""
    cleaned = text.strip().replace("°C", "degC").replace("°F", "degF").replace("°", "deg")
    cleaned = re.sub(r"(?<=[A-Za-z])(\d)", r"**\1", cleaned.replace("µ", "u").replace("μ", "u"))
    if cleaned in {"", "1", "-"}:
        return _registry().dimensionless
    return _registry().Unit(cleaned)


def _dimension(unit) -> str:
    """A unit's dimension as text in one order whatever the unit's (gf is [length] * [mass] as N is)."""
    dims = (1.0 * unit).dimensionality
    return str(type(dims)(dict(sorted(dims.items()))))


@dataclass(frozen=True)
class Reading:
    """How one column, as sent, is read.

    Attributes
    ----------
    sent : str
        The header cell, JSON key or ``NAME=`` as sent.
    name : str
        The column it is read as: a physics input, a condition, or a name the caller reads as it is.
    scale : float
        Values are read as ``value * scale + offset`` (1 and 0 when not converted).
    offset : float
        See ``scale`` (273.15 for degC to K).
    divisor : int or None
        When set, values are read as ``value / divisor`` (exact for mm -> m: ``scale`` is then
        ``1 / divisor``).
    reading : str
        The conversion in words, e.g. ``"speed [mm/s] read as speed_m_s / 1000"``; empty when the
        column is read as sent.
    """

    sent: str
    name: str
    scale: float = 1.0
    offset: float = 0.0
    divisor: int | None = None
    reading: str = ""

    def convert(self, value: Any) -> Any:
        """The value (a number or an array) in the unit of the column it is read as.

        >>> Reading("speed [mm/s]", "speed_m_s", 0.001, 0.0, 1000).convert(50.0)
        0.05
        """
        if self.divisor is not None:
            return value / self.divisor if isinstance(value, np.ndarray) else float(value) / self.divisor
        if isinstance(value, np.ndarray):
            return value * float(self.scale) + float(self.offset)
        return float(value) * float(self.scale) + float(self.offset)


    def sent_value(self, value: Any) -> Any:
        """A value of the column (SI) in the unit it was sent in, for a report or plot in the lab's units
        (the inverse of :meth:`convert`).

        >>> r = read_name("speed [mm/s]"); r.sent_value(0.05), r.sent_unit
        (50.0, 'mm/s')
        """
        if self.divisor is not None:
            return value * self.divisor if isinstance(value, np.ndarray) else float(value) * self.divisor
        if isinstance(value, np.ndarray):
            return (value - float(self.offset)) / float(self.scale)
        return (float(value) - float(self.offset)) / float(self.scale)

    def set_point(self, value: Any) -> float:
        """A value of the column (SI, as runs and results keep it: at most 12 significant digits) in the unit
        it was sent in, to the digits that value holds there: the round trip's last digits are not shown
        (70 degF kept as 294.261111111 K is 70, not 69.9999999998).

        >>> read_name("T [degF]").set_point(294.261111111), read_name("RH [%]").set_point(0.85)
        (70.0, 85.0)
        """
        shown = float(self.sent_value(float(value)))
        scale = self.scale if self.divisor is None else 1.0 / self.divisor
        step = abs(float(value)) * 1e-11 / abs(scale)  # the SI value's 12th digit, in the unit sent
        if self.reading and step > 0 and math.isfinite(shown):
            shown = round(shown, math.floor(-math.log10(step)))
        return float(f"{shown:.12g}")

    def said(self, value: float) -> str:
        """A value of the column (in the column's unit) as a report's words give it: under the key as sent,
        in the unit sent (:meth:`set_point`), the column and its value in brackets where they differ.

        >>> read_name("T [degF]").said(294.261111111), read_name("relative_humidity").said(0.6)
        ('T [degF] at 70 (temperature_K 294.261)', 'relative_humidity at 0.6')
        """
        if not self.reading:
            return f"{self.sent} at {float(value):g}"
        return f"{self.sent} at {self.set_point(value):g} ({self.name} {float(value):g})"

    @property
    def label(self) -> str:
        """The column as a report, warning or plot names it: the header as sent, with the unit it was sent
        in where the header does not state it in brackets or parentheses.

        >>> read_name("load [mN]").label, read_name("load_mN").label, read_name("balls").label
        ('load [mN]', 'load_mN [mN]', 'balls')
        """
        header = self.sent.strip()
        unit = self.sent_unit
        return header if header.endswith(("]", ")")) or not unit else f"{header} [{unit}]"

    @property
    def sent_unit(self) -> str | None:
        """The unit the column was sent in, as written (``mm/s`` of ``speed [mm/s]`` or ``speed_mm_s``);
        None when it was sent in the column's own unit."""
        if not self.reading:
            return None
        match = _BRACKETS.match(self.sent.strip())
        if match and match.group("name"):
            return _bracket_unit(match, as_written=True)
        base = next((b for b in sorted(input_bases(), key=len, reverse=True)
                     if self.sent.lower().startswith(b + "_")), None)
        if base is not None:
            parts = self.sent[len(base) + 1:].split("_")
            return "/".join(parts)
        if _percent_bracketed(self.sent.strip()) is not None:  # RH%
            return "%"
        return unit_of(self.sent)


def _converter(sent: str, name: str, source, target: str, weight: bool = False) -> Reading:
    """The :class:`Reading` converting ``source`` (a pint unit) into ``target`` (a unit text)."""
    registry = _registry()
    if weight:  # a slider mass: its weight
        scale = registry.Quantity(1.0, source).to("kg").magnitude * STANDARD_GRAVITY_M_S2
        return Reading(sent, name, scale, 0.0, None,
                       f"{sent} read as {name} = mass x standard gravity {STANDARD_GRAVITY_M_S2} m/s^2 "
                       f"(x {scale:.10g})")
    low = registry.Quantity(0.0, source).to(_unit(target)).magnitude
    high = registry.Quantity(1.0, source).to(_unit(target)).magnitude
    scale, offset = high - low, low
    if scale == 1.0 and offset == 0.0:
        return Reading(sent, name)
    if offset:
        return Reading(sent, name, scale, offset, None,
                       f"{sent} read as {name} = value" + (f" x {scale:.10g}" if scale != 1 else "")
                       + f" + {offset:.10g}")
    inverse = round(1.0 / scale)
    if inverse >= 2 and math.isclose(1.0 / scale, inverse, rel_tol=1e-12):
        return Reading(sent, name, 1.0 / inverse, 0.0, inverse, f"{sent} read as {name} / {inverse}")
    return Reading(sent, name, scale, 0.0, None, f"{sent} read as {name} x {scale:.10g}")


@functools.cache
def input_bases() -> dict[str, str]:
    """Physics input names by their name without the unit suffix (``speed`` -> ``speed_m_s``)."""
    bases = {}
    for name, spec in PARAMETERS.items():
        if spec.unit == "1":
            continue
        suffix = _SUFFIXES[spec.unit]
        if not name.endswith("_" + suffix):
            raise AssertionError(f"{name} does not end with its unit {spec.unit}")  # a new parameter's unit
        bases[name[: -len(suffix) - 1].lower()] = name
    return bases


def accepted_spellings() -> str:
    """The names a column may have, in words, examples first (for error messages; under 600 characters).

    >>> text = accepted_spellings(); "speed [mm/s]" in text, "temp_F" in text, len(text) < 600
    (True, True, True)
    """
    units = ", ".join(f"{base} [{PARAMETERS[name].unit}]" for base, name in input_bases().items())
    return (f"e.g. speed [mm/s], speed_mm_s, load [mN], load [g] (slider mass), relative_humidity [%], "
            f"temperature [degC], temp_F; inputs with units: {units}; other names as in GET /v1/parameters, "
            f"or a condition")


def _physics_reading(sent: str, name: str, unit, unit_text: str | None = None) -> Reading:
    """A physics input's reading from ``unit``; ColumnError when the unit is not of its kind."""
    spec = PARAMETERS.get(name)
    target = "1" if spec is None else spec.unit
    source_dim, target_dim = _dimension(unit), _dimension(_unit(target))
    if source_dim == target_dim:
        return _converter(sent, name, unit, target)
    if target == "N" and source_dim == _dimension(_registry().kilogram):
        return _converter(sent, name, unit, target, weight=True)
    raise ColumnError(sent, f"{name} is in {target}, and {unit_text or format(unit, '~')} is not convertible "
                            f"to it (dimension {source_dim} instead of {target_dim}); accepted names: "
                            f"{accepted_spellings()}")


def _percent_bracketed(text: str) -> str | None:
    """A humidity's name with a bare % (``RH%``, ``humidity_%``, ``%RH``) as the bracketed name it means
    (``RH [%]``); None for any other name (a % beside another quantity is not read as its unit here)."""
    match = _PERCENT.match(text)
    if match is None:
        return None
    base = match.group("after") or match.group("before")
    if _condition_of(_condition_base(base)) is not CONDITIONS["relative_humidity"]:
        return None
    return f"{base} [%]"


def _same(unit, target: str) -> bool:
    """Whether ``unit`` is the unit ``target`` (not merely convertible to it)."""
    try:
        return (1.0 * unit).to(_unit(target)).magnitude == 1.0
    except Exception:  # pint's DimensionalityError: another kind of quantity
        return False


def _condition_base(text: str) -> str:
    words = [w for w in re.split(r"[^A-Za-z0-9]+", text.strip()) if w]  # temp °F, temperature.F: temp, F
    if words and (glued := glued_unit(words[-1])) is not None:  # tempF: temp, F
        words[-1:] = list(glued)
    while len(words) > 1 and words[-1].lower() in _DROPPED_WORDS:
        words.pop()
    return "_".join(words)


def _condition_of(name: str) -> Condition | None:
    """The named condition a column is (None: a physics input, or no named condition)."""
    if name in PARAMETERS:
        return None
    found = next((c for c in CONDITIONS.values() if c.matches(name)), None)
    if found is None:
        # T with a temperature unit (T [K] read as T_K, T_degC): a temperature, though T alone is no name
        words = name_words(name)
        if "t" in words and any(w in _UNIT_WORDS["temperature_K"] for w in words if w != "t"):
            return CONDITIONS["temperature_K"]
    return found


def counted_from_zero(name: str) -> bool:
    """Whether a column is counted from zero (:attr:`Condition.from_zero`: cycles, passes, time run).

    >>> counted_from_zero("cycles"), counted_from_zero("time_min"), counted_from_zero("speed_m_s")
    (True, True, False)
    """
    condition = _condition_of(name)
    return condition is not None and condition.from_zero


def physical_range(name: str) -> tuple[float | None, float | None]:
    """A condition column's physical range (:attr:`Condition.minimum`, ``maximum``) in the unit its name
    says (:func:`unit_of`); (None, None) for a physics input (its own bounds) or no named condition.

    >>> physical_range("time_min"), physical_range("RH_pct"), physical_range("temp_C")
    ((0.0, None), (0.0, 100.0), (-273.15, None))
    """
    condition = _condition_of(name)
    if condition is None:
        return None, None
    unit, quantity = unit_of(name) or condition.unit, _registry().Quantity
    return tuple(None if b is None else round(float(quantity(b, condition.unit).to(unit).magnitude), 10)
                 for b in (condition.minimum, condition.maximum))


def outside_mask(name: str, values: Any, low: float | None, high: float | None) -> np.ndarray:
    """Which values leave a column's physical range ``[low, high]`` (None: unbounded), its low end excluded
    where the condition declares so (:attr:`Condition.exclusive_minimum`: no temperature is 0 K).

    >>> outside_mask("temp_K", [0.0, 1.0], 0.0, None).tolist(), outside_mask("cycles", [0.0], 0.0, None)
    ([True, False], array([False]))
    """
    values = np.asarray(values, dtype=float)
    below = values <= low if low is not None and _excludes_minimum(name) else (
        values < (-np.inf if low is None else low))
    return below | (values > (np.inf if high is None else high))


def _excludes_minimum(name: str) -> bool:
    condition = _condition_of(name)
    return condition is not None and condition.exclusive_minimum


def outside_range(name: str, values: Any, low: float | None, high: float | None, unit: str) -> str | None:
    """The sentence that values outside a physical range ``[low, high]`` (None: open) get, naming the first
    few of them; None when every value lies inside (:func:`outside_mask`). The one wording of every door's
    range check.

    >>> outside_range("time_min", [-5.0, 60.0], 0.0, None, "min")
    'value -5 lies outside [0, inf] [min], the physical range of time_min'
    >>> outside_range("temp_K", [0.0], 0.0, None, "K")
    'value 0 lies outside (0, inf] [K], the physical range of temp_K'
    """
    values = np.asarray(values, dtype=float).reshape(-1)
    bad = np.unique(values[outside_mask(name, values, low, high)])
    if not bad.size:
        return None
    shown = ", ".join(f"{v:g}" for v in bad[:3]) + (", ..." if bad.size > 3 else "")
    left = "(" if _excludes_minimum(name) else "["
    bounds = f"{left}{'-inf' if low is None else f'{low:g}'}, {'inf' if high is None else f'{high:g}'}]"
    plural = bad.size > 1
    return (f"value{'s' if plural else ''} {shown} lie{'' if plural else 's'} outside {bounds} [{unit}], the "
            f"physical range of {name}")


def whole_number(name: str) -> bool:
    """Whether a column's values are whole numbers: a physics input of kind int (balls) or a condition
    declared integer (cycles), so that grids and axis ticks stay whole.

    >>> whole_number("balls"), whole_number("passes"), whole_number("load_N"), whole_number("time_h")
    (True, True, False, False)
    """
    spec = PARAMETERS.get(name)
    if spec is not None:
        return spec.kind == "int"
    condition = _condition_of(name)
    return condition is not None and condition.integer


def unit_of(name: str) -> str | None:
    """The unit a column's name says its values are in, as pint reads it; None when it says none.

    A physics input is in its unit; a named condition (:data:`CONDITIONS`) in the unit the terms of
    :mod:`physics.effects` read from its name (a humidity is a fraction unless the name says pct, a
    temperature degC unless it says K, F or R); a time in the unit its last word says.

    >>> unit_of("speed_m_s"), unit_of("relative_humidity_pct"), unit_of("temperature_C"), unit_of("temp_K")
    ('m/s', 'percent', 'degC', 'K')
    >>> unit_of("temp_F"), unit_of("time_h"), unit_of("time"), unit_of("specimen")
    ('degF', 'h', None, None)
    """
    spec = PARAMETERS.get(name)
    if spec is not None:
        return None if spec.kind == "bool" else spec.unit
    condition = _condition_of(name)
    if condition is None:
        return None
    said = [_UNIT_WORDS.get(condition.name, {}).get(w) for w in name_words(name)]
    said = [u for u in said if u is not None]
    if condition.name == "relative_humidity":
        return "percent" if float(humidity_fraction(name, [1.0])[0]) != 1.0 else "1"
    if condition.name == "temperature_K":
        if any(u in _UNREAD_TEMPERATURES for u in said):
            return next(u for u in said if u in _UNREAD_TEMPERATURES)
        return "K" if float(temperature_kelvin(name, [0.0])[0]) == 0.0 else "degC"
    if condition.name == "time_h":
        return said[-1] if said else None
    return condition.unit


def driver_unit(unit: str, driver: str) -> str:
    """A declared unit that names its driver's (``"driver"``, ``"1/driver"``: an effect parameter's unit,
    :class:`physics.effects.EffectParameter`) written in the unit of the driving column (:func:`unit_of`):
    a count or a column without a unit (a run index) by its name, a fraction as 1.

    >>> driver_unit("1/driver", "temperature_K"), driver_unit("driver", "time_h")
    ('1/K', 'h')
    >>> driver_unit("driver", "cycles"), driver_unit("1/driver", "run_index")
    ('cycles', '1/run_index')
    >>> driver_unit("1/driver", "relative_humidity"), driver_unit("1/driver", "RH_pct")
    ('1', '1/%')
    >>> driver_unit("m/s", "x")
    'm/s'
    """
    if "driver" not in unit:
        return unit
    said, condition = unit_of(driver), _condition_of(driver)
    if said is None or (condition is not None and condition.integer):
        said = driver
    if said == "1":
        return "1"
    return unit.replace("driver", {"percent": "%"}.get(said, said))


# Words of a count's unit (cycles [kcycles]): counts, not pint's cycle or turn, which are angles of 2 pi.
_COUNT_WORDS = re.compile(r"(revolutions?|cycles?|pass(?:es)?|strokes?|revs?|turns?)(?![A-Za-z])",
                          re.IGNORECASE)


def _angle(unit) -> bool:
    """Whether a unit is an angle (degree, turn, pint's cycle): dimensionless in pint, never a condition's."""
    return "radian" in str((1.0 * unit).to_root_units().units)


def _condition_unit(sent: str, name_text: str, unit_text: str, unit):
    """The unit of a bracketed condition checked against its quantity's (a humidity is a number, a
    temperature a temperature, a run's time a time, its cycles a count): None for a name that is no
    condition; else the unit, a count's words read as counts (``cycles [kcycles]`` is 1000 cycles).

    Raises
    ------
    ColumnError
        A unit of another kind (``RH [mm]``, ``cycles [m]``, ``RH [deg]``): never read silently.
    """
    condition = _condition_of(_condition_base(name_text))
    if condition is None:
        return None
    own = {"relative_humidity": _HUMIDITY_UNITS, "cycles": _COUNT_UNITS}.get(condition.name)  # not g/kg, dB
    if own is not None and not own.fullmatch(_COUNT_WORDS.sub("count", unit_text).strip()):
        raise ColumnError(sent, f"{name_text.strip()} is read as {condition.name}, whose unit is "
                                f"{_EXAMPLE_UNITS[condition.name]}, not {unit_text!r}")
    if condition.integer:
        try:
            unit = _unit(_COUNT_WORDS.sub("count", unit_text))
        except Exception:  # pint's errors: never fall back to its reading (a revolution is an angle)
            raise ColumnError(sent, f"the unit {unit_text!r} of {name_text.strip()} is not known as a count; "
                                    f"e.g. {_EXAMPLE_UNITS[condition.name]}") from None
    expected = _dimension(_unit(condition.unit))
    if _dimension(unit) != expected or _angle(unit):
        kind = {"dimensionless": "a number"}.get(expected, f"of dimension {expected}")
        raise ColumnError(sent, f"{name_text.strip()} is read as {condition.name}, whose unit is {kind} "
                                f"(e.g. {_EXAMPLE_UNITS[condition.name]}), not {unit_text!r}")
    return unit


# "-" is a number's unit as a table writes it ([-], as :func:`_unit` reads it for every other column)
_HUMIDITY_UNITS, _COUNT_UNITS = re.compile(r"(?i)%|percent|pct|1|-|fraction"), re.compile(r"[kM]?count|1|-")
_EXAMPLE_UNITS = {"relative_humidity": "[%] or [1]", "temperature_K": "[degC], [K] or [degF]",
                  "cycles": "[1] or [kcycles]", "time_h": "[s], [min] or [h]"}


def _is_unit(text: str) -> bool:
    """Whether pint reads ``text`` as a unit (``degF``), not a word (``normal`` of ``load (normal) [mN]``)."""
    try:
        _unit(text)
    except Exception:  # pint's errors: an undefined unit or bad syntax
        return False
    return True


# A condition's unit as labs write it in brackets, where pint reads another quantity (C, coulomb; F, farad;
# %RH): by the condition, the spelling (lower case, no spaces) and the unit it means.
_CONDITION_UNIT_SPELLINGS = {"temperature_K": {"c": "degC", "f": "degF"},
                             "relative_humidity": {"%rh": "%", "rh%": "%", "%r.h.": "%", "pctrh": "%"}}


def _condition_unit_text(name_text: str, unit_text: str) -> str:
    """The unit a condition's brackets mean (``Temperature (C)``: degC; ``Humidity [%RH]``: %), else the
    brackets' text as written."""
    base = _condition_base(name_text)
    condition = _condition_of(base)
    if condition is None and name_words(base) == ["t"]:
        condition = CONDITIONS["temperature_K"]  # T (C): the temperature, as T [degC] is
    spellings = _CONDITION_UNIT_SPELLINGS.get(condition.name, {}) if condition is not None else {}
    return spellings.get(re.sub(r"\s+", "", unit_text).lower(), unit_text)


def _stated_units(sent: str, name_text: str, unit_text: str | None = None) -> list[str]:
    """The units the words of a named condition's name state (``temp_F_avg``: degF, ``time_min``: min); a
    name stating two (``temp_K_C``, ``time_h_min``), or one its brackets contradict (``temp_F [degC]``,
    ``RH_pct [1]``, ``time_h [min]``), is refused, never read in one of them."""
    condition = _condition_of(name_text)
    words = _UNIT_WORDS.get(condition.name, {}) if condition is not None else {}
    said = list(dict.fromkeys(words[w] for w in name_words(name_text) if w in words))
    if unit_text is not None and said:
        try:
            stated = _unit(unit_text)
            other = [u for u in said if [_registry().Quantity(v, stated).to(u).magnitude for v in (0.0, 1.0)]
                     != [0.0, 1.0]]
        except Exception:  # pint's errors: not this quantity's unit, said by the caller
            return said
        if other:
            raise ColumnError(sent, f"{sent!r} states two units ({other[0]} in its name, {unit_text} in "
                                    f"its brackets); keep one, e.g. '{_without_unit_words(name_text, words)} "
                                    f"[{unit_text}]'")
    elif len(said) > 1:
        raise ColumnError(sent, f"{sent!r} states two units ({' and '.join(said)}); keep one, e.g. "
                                f"'{_without_unit_words(name_text, words)} [{said[0]}]'")
    return said


def _without_unit_words(text: str, units: Mapping[str, str] = _UNIT_WORDS["temperature_K"]) -> str:
    """A condition's name without the words that state its unit (a temperature's by default), wherever they
    stand (``temp_F_avg``: ``temp_avg``), so that the name it is read under states kelvin alone."""
    words = [w for w in re.split(r"[^A-Za-z0-9]+", text.strip()) if w]
    words = [glued[0] if (glued := glued_unit(w)) else w for w in words]  # tempF_avg: temp, avg
    kept = [w for w in words if w.lower() not in units]
    return "_".join(kept or words[:1])


def _bracketed(sent: str, match: re.Match, plain: Sequence[str]) -> Reading:
    name_text = match.group("name")
    unit_text = _condition_unit_text(name_text, _bracket_unit(match))
    _stated_units(sent, name_text, unit_text)
    inner = _BRACKETS.match(name_text.strip())
    first = _bracket_unit(inner) if inner and inner.group("name") else None
    if first is not None and _is_unit(first):  # temp (degF) [degC]: which? never converted twice
        raise ColumnError(sent, f"{sent!r} states two units ({first} and {unit_text}); keep one, e.g. "
                                f"'{inner.group('name').strip()} [{unit_text}]'")
    try:
        unit = _unit(unit_text)
    except Exception:  # pint's errors (undefined units, bad syntax) derive from several built-ins
        unit = None
    key = re.sub(r"[\s\-]+", "_", name_text.strip())
    bases = input_bases()
    if key not in PARAMETERS and key not in plain and key.lower() not in bases:
        try:
            unit = _condition_unit(sent, name_text, unit_text, unit) or unit
        except ColumnError:
            raise
        except Exception:  # pint's errors: an unknown unit, said below
            pass
    if unit is None:
        raise ColumnError(sent, f"the unit {unit_text!r} is not known; accepted names: "
                                f"{accepted_spellings()}")
    if key in PARAMETERS or key in plain:
        spec = PARAMETERS.get(key)
        if spec is not None and spec.unit != "1" and not _same(unit, spec.unit):
            raise ColumnError(sent, f"the name {key} says {spec.unit} and the brackets say {unit_text}; "
                                    f"write {key[: -len(_SUFFIXES[spec.unit]) - 1]} [{unit_text}]")
        return _physics_reading(sent, key, unit, unit_text)
    if key.lower() in bases:
        return _physics_reading(sent, bases[key.lower()], unit, unit_text)
    dimension = _dimension(unit)
    base = _condition_base(name_text)
    _refuse_qualified_input(sent, base, dimension, unit_text)
    if dimension == "dimensionless":
        return _converter(sent, base, unit, "1")
    if dimension not in _SI_BY_DIMENSION:
        raise ColumnError(sent, f"a condition in {unit_text} (dimension {dimension}) has no SI unit here; "
                                f"give it without a unit or in one of "
                                f"{', '.join(u for u, _ in _SI_BY_DIMENSION.values())}, or as a "
                                f"dimensionless number")
    si, suffix = _SI_BY_DIMENSION[dimension]
    if dimension == "[temperature]" and name_words(base) == ["t"]:
        base = "temperature"  # T [K]: the temperature, as the terms' drivers read it
    return _converter(sent, f"{base}_{suffix}", unit, si)


def _refuse_qualified_input(sent: str, base: str, dimension: str, unit_text: str) -> None:
    """Refuse a name that holds a physics input's name among other words, in that input's kind of unit.

    ``load (normal) [mN]`` or ``drive speed [mm/s]`` would otherwise become a condition beside the
    physics input (``load_(normal)_N``), which the physics never reads: which quantity it is, the user
    says, by the input's own name or by a name without it.
    """
    words = name_words(base)
    for input_base, name in input_bases().items():
        parts = input_base.split("_")
        inside = any(words[i:i + len(parts)] == parts for i in range(len(words) - len(parts) + 1))
        if inside and words != parts and _dimension(_unit(PARAMETERS[name].unit)) == dimension:
            spoken = input_base.replace("_", " ")
            raise ColumnError(sent, f"{sent!r} reads like the physics input {name} ({spoken}) with other "
                                    f"words: send it as '{spoken} [{unit_text}]' if it is the bearing's "
                                    f"{spoken}, or give another quantity a name without '{spoken}'")


def read_name(sent: str, plain: Sequence[str] = ()) -> Reading:
    """How a column named ``sent`` (header cell, JSON key, ``NAME=`` of the CLI) is read.

    Parameters
    ----------
    sent : str
        E.g. ``"speed [mm/s]"``, ``"load (mN)"``, ``"speed_mm_s"``, ``"load_N"``,
        ``"relative_humidity [%]"`` or ``"temp_F"``.
    plain : sequence of str
        Other names read as they are, dimensionless (the caller's own columns, e.g. ``mu_measured``).

    Returns
    -------
    Reading
        A physics input in its unit; a condition with a unit in brackets in SI (a humidity in % as the
        fraction ``relative_humidity``, a temperature as ``<name>_K``); a temperature whose name says
        F or R as ``<name>_K``; any other name as sent.

    Raises
    ------
    ColumnError
        Naming the column as sent: an unknown unit, a unit not convertible to the input's, a condition's
        unit of a dimension without an SI name here, or a name that states another unit.

    Examples
    --------
    >>> read_name("speed [mm/s]").reading
    'speed [mm/s] read as speed_m_s / 1000'
    >>> r = read_name("temperature [degC]"); r.name, r.convert(25.0)
    ('temperature_K', 298.15)
    >>> r = read_name("temp_F"); r.name, round(r.convert(212.0), 2)
    ('temp_K', 373.15)
    """
    text = sent.strip()
    match = _BRACKETS.match(text)
    if match and match.group("name"):
        return _bracketed(sent, match, plain)
    if text in PARAMETERS or text in plain:
        return Reading(sent, text)
    percent = _percent_bracketed(text)
    if percent is not None:  # RH%: the unit of RH [%], never a fraction named RH%
        return _bracketed(sent, _BRACKETS.match(percent), plain)
    bases = input_bases()
    # name_unit: a physics input's name without its unit, then a unit (speed_mm_s, load_mN)
    for base in sorted(bases, key=len, reverse=True):
        if text.lower().startswith(base + "_") and len(text) > len(base) + 1:
            parts = text[len(base) + 1:].split("_")
            quotient = "/".join([parts[0], *[f"({p})" for p in parts[1:]]])
            for unit_text in (quotient, "*".join(parts)):
                try:
                    return _physics_reading(sent, bases[base], _unit(unit_text))
                except Exception:  # no unit, or not this input's kind: try the next reading
                    continue
    said = unit_of(text) if _stated_units(sent, text) else None
    if said in _UNREAD_TEMPERATURES:  # the terms would read it as degC: convert it to kelvin
        return _converter(sent, f"{_without_unit_words(text)}_K", _unit(said), "K")
    return Reading(sent, text)


def match_column(sent: str, known: Iterable[str]) -> Reading:
    """How a name sent at prediction is read as one of the columns a model knows.

    Parameters
    ----------
    sent : str
        The name as sent: a known column, the upload's header (``relative humidity [%]``), or another
        unit of a known column's quantity (``temperature_C`` for ``temperature_K``).
    known : iterable of str
        The model's columns (conditions and factors of its data).

    Returns
    -------
    Reading
        Into the known column, converted when the units differ.

    Raises
    ------
    ColumnError
        When no known column matches: the message lists the known columns and the accepted spellings.

    Examples
    --------
    >>> match_column("relative humidity [%]", ["relative_humidity"]).convert(50.0)
    0.5
    >>> r = match_column("temperature_C", ["temperature_K"]); r.name, r.convert(25.0)
    ('temperature_K', 298.15)
    """
    known = list(known)
    if sent in known:
        return Reading(sent, sent)
    same = [k for k in known if k.casefold() == sent.strip().casefold()]  # HUMIDITY for Humidity
    if len(same) == 1:
        return Reading(sent, same[0])
    bracketed = _BRACKETS.match(sent.strip())
    try:
        first = read_name(sent)
    except ColumnError:
        if bracketed and bracketed.group("name"):  # brackets stating a unit it cannot be read in
            raise
        _stated_units(sent, sent.strip())  # temp_K_C: two units, refused here as at the upload
        first = Reading(sent, sent)
    if first.name in known:
        return first
    source = unit_of(first.name)
    condition = _condition_of(first.name)
    alike = [k for k in known
             if condition is not None and _condition_of(k) is condition and unit_of(k) is not None]
    # Another column of the same quantity when the name sent states its unit (brackets, a unit word such
    # as temperature_K, or a unit other than the known column's); a bare synonym (humidity for
    # relative_humidity, cycles for passes) is not guessed.
    words = _UNIT_WORDS.get(condition.name, {}) if condition is not None else {}
    stated = any(w in words for w in name_words(first.name)) or bool(bracketed and bracketed.group("name"))
    # a condition's canonical name declares its unit (relative_humidity: a fraction); a count's does not
    # say what it counts (a cycle may be two passes), so cycles is not read as passes
    stated = stated or (condition is not None and first.name == condition.name and not condition.integer)
    if source is not None and len(alike) == 1 and (stated or first.reading or source != unit_of(alike[0])):
        target = unit_of(alike[0])
        if _dimension(_unit(source)) == _dimension(_unit(target)):
            second = _converter(sent, alike[0], _unit(source), target)
            scale, offset = first.scale * second.scale, first.offset * second.scale + second.offset
            if (scale, offset) == (1.0, 0.0):
                return Reading(sent, alike[0], reading=f"{sent} read as {alike[0]}")
            words = (f" x {scale:.10g}" if scale != 1 else "") + (f" + {offset:.10g}" if offset else "")
            return Reading(sent, alike[0], scale, offset, None, f"{sent} read as {alike[0]}{words}")
    raise ColumnError(sent, unknown_column(sent, known))


def read_key(sent: str, columns: Iterable[str], labels: Iterable[str] = ()) -> Reading | None:
    """How a key sent to a model is read against the model's own columns: a physics input (under any of
    its spellings: ``load [mN]`` is ``load_N``, converted), one of ``columns`` or of ``labels`` (factor
    columns, whose values are labels: read by their own name only) as it is; another spelling or unit of
    one of ``columns`` converted (:func:`match_column`); None when none reads it (the caller names it
    unknown, with the model's columns).

    >>> read_key("RH [%]", ["relative_humidity"]).convert(50.0), read_key("humidity", ["RH_chamber"])
    (0.5, None)
    >>> read_key("load [mN]", []).name, read_key("load [mN]", []).convert(10.0)  # a physics input's
    ('load_N', 0.01)
    """
    columns = list(columns)
    if sent in PARAMETERS or sent in columns or sent in labels:
        return Reading(sent, sent)
    try:
        return match_column(sent, columns)
    except ColumnError:
        pass
    try:  # a physics input under the upload's spelling (load [mN] is load_N), as every door reads it
        first = read_name(sent)
    except ColumnError:
        return None
    return first if first.name in PARAMETERS else None


def unknown_column(sent: str, known: Iterable[str], what: str = "column") -> str:
    """The one message of every door for a column it does not know: the known columns and the spellings.

    >>> unknown_column("humidity", ["relative_humidity"])[:71]
    "unknown column 'humidity'; the columns known here are relative_humidity"
    """
    return (f"unknown {what} {sent!r}; the columns known here are {', '.join(known) or 'none'} (each also "
            f"under a name with its unit, e.g. relative humidity [%], temperature [degC]); accepted "
            f"names: {accepted_spellings()}")


def from_si(name: str, values: Any, unit: str) -> np.ndarray:
    """Values of a physics input in its SI unit, in another unit of its kind (a report's or plot's unit).

    >>> from_si("speed_m_s", [0.05], "mm/s").tolist(), from_si("load_N", 0.0088, "mN").tolist()
    ([50.0], 8.8)
    """
    source = _unit(PARAMETERS[name].unit if name in PARAMETERS else (unit_of(name) or "1"))
    return np.asarray(_registry().Quantity(np.asarray(values, dtype=float), source).to(_unit(unit)).magnitude)
