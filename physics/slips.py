"""Unit slips: values that look as if they were meant in another unit than their column's.

The one rule of every door (:mod:`calibrate.plausibility` refuses measured data with a slip, the service
refuses conditions and design spaces with one and warns of physics inputs with one at prediction):

* a physics input beyond :data:`physics.columns.SLIP_LIMITS` (a speed above 10 m/s looks like mm/s, a
  load above 1 N like mN);
* a humidity fraction above 1 (percent);
* a temperature in degC above 200 (kelvin), or in K below 150 (degC).

:func:`slip` judges values by the name of their column. :func:`read_slip` judges values as they were sent:
in the unit their key states when it states one (``temp [degC]: -200`` is a cold test, no kelvin slip;
``load (gf): 1e6`` is said in gf, as sent), else under the names the key is read as.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from .columns import (
    _BRACKETS,
    CONDITIONS,
    SLIP_LIMITS,
    ColumnError,
    Reading,
    _bracket_unit,
    _condition_of,
    _dimension,
    _percent_bracketed,
    _registry,
    _same,
    _stated_units,
    _unit,
    read_name,
    unit_of,
)
from .drivers import HUMIDITY, TEMPERATURE
from .parameters import PARAMETERS

__all__ = ["humidity_rows", "humidity_slip", "input_slips", "physics_slip", "read_slip", "slip",
           "slipped_rows", "temperature_slip", "unstated_unit"]

def _span_text(values: np.ndarray) -> str:
    return f"{float(np.min(values)):.4g} to {float(np.max(values)):.4g}"


def slipped_rows(name: str, values: np.ndarray) -> np.ndarray | None:
    """The rows of a physics input that slipped when only some did, else None: those beyond
    :data:`physics.columns.SLIP_LIMITS` whose values, converted, fall within the range of the others (a
    whole column in mN has no rows in N beside it: its rows below the limit, 0.5 mN read as 0.5 N, lie far
    above its converted ones).

    >>> slipped_rows("load_N", np.array([0.003, 12.0, 0.02])).tolist()
    [1]
    >>> print(slipped_rows("load_N", np.array([3.0, 30.0])))  # the whole column in mN
    None
    """
    limit, _, factor = SLIP_LIMITS[name]
    values = np.asarray(values, dtype=float)
    beyond = values > limit
    if beyond.all() or not beyond.any() or float(np.min(values)) < 0.0:
        return None
    converted = float(np.median(values[beyond] * factor))
    inside = float(np.min(values[~beyond])) <= converted <= float(np.max(values[~beyond]))
    return np.flatnonzero(beyond) if inside else None


def physics_slip(name: str, values: np.ndarray, stated: tuple[str, np.ndarray, str, bool] | None = None
                  ) -> str | None:
    """A physics input's values beyond :data:`physics.columns.SLIP_LIMITS`, in words: a speed of 50 m/s
    looks like mm/s.

    ``stated``: the key as sent, its values as sent, the unit it states and whether that is the input's
    own unit (a slip advice applies then; another stated unit says what was meant)."""
    limit, slip_unit, factor = SLIP_LIMITS[name]
    if float(np.max(values)) <= limit:
        return None
    unit = PARAMETERS[name].unit
    scaled = values * factor
    shown = f"{name} runs {_span_text(values)} {unit}"
    if stated is not None:
        shown = f"{stated[0]} runs {_span_text(stated[1])} {stated[2]} ({name} {_span_text(values)} {unit})"
    if float(np.min(values)) < 0.0:
        cause = f"check the values: {name} is not negative"
    elif stated is not None and not stated[3]:
        cause = "its name states the unit, so check the values"
    elif (rows := slipped_rows(name, values)) is not None:
        others = np.delete(values, rows)
        cause = (f"{rows.size} of {values.size} values lie beyond it: those look like {slip_unit} "
                 f"(times {factor:g}: {_span_text(scaled[rows])} {unit}, within the other values' "
                 f"{_span_text(others)} {unit}); convert those rows only")
    elif float(np.max(scaled)) <= limit:
        cause = f"values look like {slip_unit} (times {factor:g}: {_span_text(scaled)} {unit})"
    else:
        cause = "check the unit of the column"
    return f"{shown}, beyond the {limit:g} {unit} a micro ball bearing sees: {cause}"


def humidity_rows(name: str, values: np.ndarray) -> np.ndarray | None:
    """The rows of a humidity fraction written in percent when only some are, else None: those above the
    fraction's plausible top whose values, divided by 100, fall within the others' range (as
    :func:`slipped_rows` for a physics input).

    >>> humidity_rows("relative_humidity", np.array([0.3, 55.0, 0.6])).tolist()
    [1]
    >>> print(humidity_rows("relative_humidity", np.array([30.0, 55.0])))  # the whole column in percent
    None
    """
    unit = HUMIDITY.unit_of(name)
    values = np.asarray(values, dtype=float)
    above = values > unit.plausible[1]
    if unit.unit == "%" or above.all() or not above.any() or float(np.min(values)) < unit.plausible[0]:
        return None
    converted = float(np.median(values[above] / 100))
    inside = float(np.min(values[~above])) <= converted <= float(np.max(values[~above]))
    return np.flatnonzero(above) if inside else None


def humidity_slip(name: str, values: np.ndarray) -> str | None:
    """A humidity column's values beyond the plausible range its unit declares
    (:data:`physics.drivers.HUMIDITY`), in words: a fraction of 50 looks like percent."""
    unit = HUMIDITY.unit_of(name)
    percent = unit.unit == "%"
    bottom, top = unit.plausible
    if float(np.min(values)) >= bottom and float(np.max(values)) <= top:
        return None
    percent_top = next(u for u in HUMIDITY.units if u.unit == "%").plausible[1]
    rows = None if percent else humidity_rows(name, values)
    if percent:
        cause = f"relative humidity in percent lies in [{bottom:g}, {top:g}]"
    elif rows is not None:
        others = np.delete(values, rows)
        cause = (f"{rows.size} of {values.size} values lie above {top:g}: those look like percent (divided "
                 f"by 100: {_span_text(values[rows] / 100)}, within the other values' {_span_text(others)}); "
                 f"convert those rows only")
    elif float(np.min(values)) >= bottom and float(np.max(values)) <= percent_top:
        cause = (f"values look like percent: give fractions (divide by 100) or name the column "
                 f"{name}_pct")
    else:
        cause = f"relative humidity is a fraction in [{bottom:g}, {top:g}]"
    return f"{name} runs {_span_text(values)} [{'%' if percent else '1'}]: {cause}"


def _named_in(sent: str, unit: str, column: str) -> str:
    """How to send a column's values in ``unit``: the key's brackets with that unit (``temp [degC]``),
    else the ``column`` named so (``temperature_C``)."""
    match = _BRACKETS.match(sent.strip())
    if match and match.group("name"):
        return f"send them as '{match.group('name').strip()} [{unit}]'"
    return f"name the column {column}"


def temperature_slip(name: str, values: np.ndarray, kelvin: bool | None = None,
                     sent: tuple[np.ndarray, str] | None = None) -> str | None:
    """A temperature column's values beyond the plausible range its unit declares
    (:data:`physics.drivers.TEMPERATURE`), in words: degC above 200 looks like kelvin, kelvin below 150
    like degC.

    ``kelvin``: whether the values are in K (else degC); by default as the name says. ``sent``: the
    values as sent and their unit (degF), shown first when the rule judged them converted."""
    kelvin = TEMPERATURE.unit_of(name).unit == "K" if kelvin is None else kelvin
    bottom, top = next(u for u in TEMPERATURE.units if u.unit == ("K" if kelvin else "degC")).plausible
    lo, hi = float(np.min(values)), float(np.max(values))
    shown = f"{_span_text(values)} {'K' if kelvin else 'degC'}"
    if sent is not None:
        shown = f"{_span_text(sent[0])} {sent[1]} ({shown})"
    if kelvin and lo < bottom:
        return (f"{name} runs {shown}, below {bottom:g} K: values look like degC "
                f"({_named_in(name, 'degC', 'temperature_C')})")
    if not kelvin and lo <= bottom:  # absolute zero itself is no temperature
        return f"{name} runs {shown}, at or below absolute zero ({bottom:g} degC): check the unit"
    if not kelvin and hi > top:
        return (f"{name} runs {shown}, above {top:g} degC: values look like kelvin "
                f"({_named_in(name, 'K', 'temperature_K')})")
    return None


def slip(name: str, values: Any) -> str | None:
    """The unit slip that values of a column look like, in words; None when they look right.

    Parameters
    ----------
    name : str
        The column's name (its unit as :func:`physics.columns.unit_of` reads it).
    values : array_like
        Its values, in that unit.

    Examples
    --------
    >>> print(slip("relative_humidity", [50.0]))  # doctest: +NORMALIZE_WHITESPACE
    relative_humidity runs 50 to 50 [1]: values look like percent: give fractions (divide by 100) or
    name the column relative_humidity_pct
    >>> slip("relative_humidity", [0.5]) is None, slip("speed_m_s", [0.05]) is None
    (True, True)
    """
    array = np.asarray(values)
    if array.size == 0 or array.dtype.kind not in "iuf":
        return None
    array = array.astype(float)
    if not np.all(np.isfinite(array)):
        return None  # the range checks name non-finite values
    if name in SLIP_LIMITS:
        return physics_slip(name, array)
    if name in PARAMETERS:
        return None
    condition = _condition_of(name)
    if condition is not None and condition.name == "relative_humidity":
        return humidity_slip(name, array)
    if condition is not None and condition.name == "temperature_K":
        return temperature_slip(name, array)
    return None


def read_slip(reading: Reading, values: Any) -> str | None:
    """The unit slip that values sent under ``reading.sent`` look like (:func:`slip`): in the unit the key
    states when it states one (:func:`_stated_slip`), else judged as sent (27 as ``temperature_K`` is degC
    under a kelvin name, though its -246 degC is no slip of a degC column), then in the column read.

    >>> from microbearing.physics.columns import match_column
    >>> read_slip(match_column("temperature_K", ["temp_degC"]), [27.0])[:48]
    'temperature_K runs 27 to 27 K, below 150 K: valu'
    >>> read_slip(match_column("relative humidity [%]", ["RH"]), [50.0]) is None
    True
    >>> read_slip(match_column("temp [degC]", ["temperature_K"]), [-200.0]) is None  # 73 K: cold, no slip
    True
    """
    array = np.asarray(values)
    if array.size == 0 or array.dtype.kind not in "iuf":
        return None
    array = array.astype(float)
    try:
        first = read_name(reading.sent)
    except ColumnError:
        first = None
    if first is not None:
        judged, message = _stated_slip(first, array)
        if judged or message is not None:
            return message
        message = slip(first.name, first.convert(array))
        if message is not None:
            return message
    return slip(reading.name, reading.convert(array))


def unstated_unit(reading: Reading, headers: Mapping[str, str] | None = None) -> str | None:
    """Why a key that states no unit is not read in the unit its name implies, in one sentence; None when it
    may be.

    A bare ``temperature`` is read in degC (the terms' default). Where the calibration's data gave its
    column in another unit (``temp_F``, or ``temperature_K`` itself), reading it so would be a silent slip:
    the key is refused, naming the upload's unit and header and a name that states its unit. ``headers``:
    each column's header as the upload sent it in another unit than its name's
    (:attr:`calibrate.CalibratedModel.headers`); any other column was sent in its name's unit.

    >>> from microbearing.physics.columns import match_column
    >>> unstated_unit(match_column("temperature", ["temp_K"]), {"temp_K": "temp_F"})[:60]
    "'temperature' states no unit: it would be read in degC, but "
    >>> print(unstated_unit(match_column("temp_C", ["temp_K"]), {"temp_K": "temp_F"}))
    None
    """
    sent, name = reading.sent.strip(), reading.name
    if not reading.reading or sent == name or _condition_of(name) is None or sent in CONDITIONS:
        return None  # a condition's canonical name states its unit (relative_humidity: a fraction)
    match = _BRACKETS.match(sent)
    if (match and match.group("name")) or _percent_bracketed(sent) is not None or _stated_units(sent, sent):
        return None
    header = (headers or {}).get(name, name)
    assumed = unit_of(sent)
    try:
        given = read_name(header).sent_unit or unit_of(name)
    except ColumnError:  # a header stored by another version: nothing to compare
        return None
    if assumed is None or given is None or _same(_unit(given), assumed):
        return None
    said = (f"the calibration's column {name} is in {given}" if header == name else
            f"the calibration's data gave {name} in {given} (as {header!r})")
    return (f"{reading.sent!r} states no unit: it would be read in {assumed}, but {said}; send {header!r}, "
            f"or a name that states its unit, e.g. '{sent} [{assumed}]'")


def _stated_slip(first: Reading, array: np.ndarray) -> tuple[bool, str | None]:
    """Whether the key states a unit of its column's kind, and the slip judged in that unit (None: none).

    ``RH [%]`` at 120 is no humidity in [0, 100]; ``temperature [degC]`` at 250 is kelvin, though its
    reading in K has no upper limit, and at -200 no slip, though 73 K would be degC under a kelvin name;
    ``load (gf)`` at 1e6 is said in gf. Any other key is judged by the names it is read as."""
    match = _BRACKETS.match(first.sent.strip())
    if match and match.group("name"):  # temp [K]: stated, though read as temp_K unconverted
        stated = _bracket_unit(match)
    else:
        stated = first.sent_unit if first.reading else None
    if stated is None:
        return False, None
    if first.name in SLIP_LIMITS:
        try:
            own = _same(_unit(stated), PARAMETERS[first.name].unit)
        except Exception:  # pint's errors: a unit it reads only in another spelling
            own = False
        return True, physics_slip(first.name, np.asarray(first.convert(array), dtype=float),
                                   (first.sent, array, stated, own))
    condition = _condition_of(first.name)
    if condition is CONDITIONS["relative_humidity"]:
        fraction = stated.strip() in ("1", "-", "fraction")  # [-]: a number, as physics.columns reads it
        top, lo, hi = 1.0 if fraction else 100.0, float(np.min(array)), float(np.max(array))
        if lo >= 0.0 and hi <= top:
            return True, None
        shown = "[1]" if fraction else stated
        said = f"{first.sent} runs {_span_text(array)} {shown}: it lies in [0, {top:g}]"
        if fraction and lo >= 0.0 and hi <= 100.0:
            said += f"; values look like percent ({_named_in(first.sent, '%', first.name + '_pct')})"
        return True, said
    if condition is not CONDITIONS["temperature_K"]:
        return False, None
    try:
        unit = _unit(stated)
        if _dimension(unit) != "[temperature]":
            return False, None
        kelvin = _same(unit, "K")
        values = array if kelvin else _registry().Quantity(array, unit).to("degC").magnitude
    except Exception:  # pint's errors: not a unit it reads as a temperature
        return False, None
    return True, temperature_slip(first.sent, np.asarray(values, dtype=float), kelvin,
                                   None if kelvin or _same(unit, "degC") else (array, stated))


def input_slips(inputs: Mapping[str, Any], sent: Mapping[str, tuple[str, Any] | None] | None = None
                ) -> list[str]:
    """The unit slips that physics inputs given at prediction look like (:func:`slip`), in words.

    The model is valid beyond :data:`physics.columns.SLIP_LIMITS` (it answers there): a door that predicts
    warns where the upload refuses, with the same words, so that ``speed_m_s=50`` meant as mm/s is never
    silent. ``sent``: for an input sent under another key, that key and its value as sent
    (``("load [mN]", 2000)``): judged as sent (:func:`read_slip`), as every door judges a key.

    >>> input_slips({"speed_m_s": 50.0, "load_N": 0.01})[0][:60]
    'speed_m_s runs 50 to 50 m/s, beyond the 10 m/s a micro ball '
    >>> input_slips({"load_N": 2.0}, {"load_N": ("load [mN]", 2000)})[0][:44]
    'load [mN] runs 2000 to 2000 mN (load_N 2 to '
    """
    found = []
    for name, (limit, _unit_name, _factor) in SLIP_LIMITS.items():
        value = inputs.get(name)
        if value is None or (isinstance(value, int | float) and not value > limit):
            continue  # the scalar fast path of a single point
        given = (sent or {}).get(name)
        message = slip(name, value)
        if message is not None and given is not None:
            key, as_sent = given
            numbers = list(as_sent.values()) if isinstance(as_sent, Mapping) else as_sent
            try:
                message = read_slip(read_name(key), np.asarray(numbers, dtype=float)) or message
            except (ColumnError, TypeError, ValueError):  # not numbers as sent: said in the input's unit
                pass
        if message is not None:
            found.append(message)
    return found
