"""The parameter table: every input of the friction model in one place.

Each :class:`Parameter` states its name, unit, default, allowed range and
meaning. Validation (:func:`validate`), the REST API's request schemas and the
column names of measured data are all built from :data:`PARAMETERS`, so a
parameter is declared exactly once.

Names carry their SI unit (``load_N``, ``speed_m_s``); angles are the one
exception to SI, given in degrees (``groove_angle_deg``) because that is how a
groove is specified, and converted to radians inside the model.

The bounds are those of a physically meaningful micro bearing, wide enough for
any design (a load of 1 nN to 1 MN, balls of 0.1 um to 10 cm, groove angles of
0.01 to 89.99 deg, moduli of a soft
polymer to beyond diamond); inside them every output is finite, which a test
checks at every corner of the box.
"""

from __future__ import annotations

import functools
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "Parameter",
    "PARAMETERS",
    "CONVENTIONS",
    "DEFAULT_CONVENTION",
    "validate",
    "validate_all",
    "defaults",
    "unit_suffix",
]


@dataclass(frozen=True)
class Parameter:
    """One input of the friction model.

    Attributes
    ----------
    name : str
        Keyword of :func:`physics.evaluate`, REST field and data column name.
    symbol : str
        Symbol in Olaru et al. (2005).
    unit : str
        SI unit (``"1"`` for dimensionless, ``"deg"`` for the groove angle).
    description : str
        What the parameter means, in one sentence.
    default : float, bool or None
        Default value; ``None`` marks a required design or operating input.
    minimum, maximum : float or None
        Bounds of the allowed range.
    exclusive_minimum, exclusive_maximum : bool
        Whether the bound itself is excluded.
    kind : {"float", "int", "bool"}
        Value type: integers must be whole numbers, booleans true/false.
    """

    name: str
    symbol: str
    unit: str
    description: str
    default: float | bool | None = None
    minimum: float | None = None
    maximum: float | None = None
    exclusive_minimum: bool = False
    exclusive_maximum: bool = False
    kind: str = "float"

    @property
    def required(self) -> bool:
        """True for design and operating inputs that have no default."""
        return self.default is None

    @functools.cached_property
    def closed_range(self) -> tuple[float, float]:
        """The allowed range as closed finite bounds: an excluded bound moved to the next float."""
        if self.kind == "bool":
            return math.inf, -math.inf  # no number is a boolean
        low = -sys.float_info.max if self.minimum is None else float(self.minimum)
        high = sys.float_info.max if self.maximum is None else float(self.maximum)
        return (math.nextafter(low, math.inf) if self.exclusive_minimum else low,
                math.nextafter(high, -math.inf) if self.exclusive_maximum else high)

    def accepts(self, value: float) -> bool:
        """Whether a plain Python number lies in the allowed range (scalar fast path).

        NaN and infinities fail the comparison with the finite bounds.
        """
        low, high = self.closed_range
        return low <= value <= high and (self.kind != "int" or value == round(value))

    def range_text(self, convert: Callable[[float], float] | None = None) -> str:
        """The allowed range in words, e.g. ``"> 0"`` or ``"in (0, 90)"``; with ``convert`` (an increasing
        map, e.g. from SI to the unit a column was sent in) its ends in that other unit.

        >>> PARAMETERS["speed_m_s"].range_text(lambda v: v * 1000)
        'in [0, 1e+06]'
        """
        if self.kind == "bool":
            return "true or false"
        lo, hi = self.minimum, self.maximum
        if convert is not None:
            lo, hi = (None if v is None else convert(v) for v in (lo, hi))
        whole = "a whole number " if self.kind == "int" else ""
        if lo is not None and hi is not None:
            left = "(" if self.exclusive_minimum else "["
            right = ")" if self.exclusive_maximum else "]"
            return f"{whole}in {left}{lo:g}, {hi:g}{right}"
        if lo is not None:
            return f"{whole}{'>' if self.exclusive_minimum else '>='} {lo:g}"
        if hi is not None:
            return f"{whole}{'<' if self.exclusive_maximum else '<='} {hi:g}"
        return f"{whole}finite"


def unit_suffix(name: str) -> str:
    """The unit written after a value of ``name`` in words: ``" N"`` for load_N, ``""`` for a
    dimensionless input (unit ``1``) and for a name that is not in :data:`PARAMETERS`.

    >>> unit_suffix("load_N"), unit_suffix("mu_pivot"), unit_suffix("relative_humidity")
    (' N', '', '')
    """
    unit = PARAMETERS[name].unit if name in PARAMETERS else ""
    return "" if unit in ("", "1", "-") else f" {unit}"


_STEEL_E_PA = 2.1e11
_SILICON_E_PA = 1.5e11

#: Every input of :func:`physics.evaluate`, keyed by name.
PARAMETERS: dict[str, Parameter] = {
    p.name: p
    for p in [
        Parameter(
            "balls", "z", "1",
            "Total number of balls carrying the slider, both grooves together (the paper's "
            "case B, 9 balls per groove, is balls=18); each ball carries load_N / balls.",
            minimum=1, maximum=1_000_000, kind="int",
        ),
        Parameter(
            "groove_angle_deg", "theta", "deg",
            "V-groove flank angle, equal to the angle between each ball-race contact "
            "normal and the vertical; 54.7 deg for KOH-etched (111) silicon flanks. "
            "Inside (0, 90); the last 0.01 deg at either end is a flat plate or a vertical "
            "wall that locates no ball and is refused.",
            default=54.7, minimum=0.01, maximum=89.99,
        ),
        Parameter(
            "load_N", "G", "N",
            "Normal load on the slider: slider weight m*g plus any external load.",
            minimum=1e-9, maximum=1e6,
        ),
        Parameter(
            "speed_m_s", "V", "m/s",
            "Slider speed relative to the stator; the balls roll at V/2.",
            minimum=0, maximum=1e3,
        ),
        Parameter(
            "ball_diameter_m", "d", "m",
            "Ball diameter (285 um in Olaru et al. and Lin et al.).",
            default=285e-6, minimum=1e-7, maximum=0.1,
        ),
        Parameter(
            "balls_touching", "", "1",
            "Whether neighbouring balls touch, adding the ball-ball capillary "
            "friction moment of eq 17 to every ball; a single ball (balls=1) has no "
            "neighbour, so there it adds nothing.",
            default=False, kind="bool",
        ),
        Parameter(
            "mu_pivot", "mu_s", "1",
            "Sliding friction coefficient in the ball-race contact, used by the "
            "pivoting moment (eq 16); Olaru et al. use 0.5 and 1.",
            default=0.5, minimum=0, maximum=10,
        ),
        Parameter(
            "mu_ball", "mu_b", "1",
            "Friction coefficient between two touching balls (eq 17); Olaru et al. "
            "use 0.5 and 1.",
            default=0.5, minimum=0, maximum=10,
        ),
        Parameter(
            "adhesion_energy_J_m2", "gamma", "J/m^2",
            "Interfacial energy of the JKR adhesion at the ball-race contacts; 0 "
            "turns adhesion off. 0.18 J/m^2 gives the 200-300 uN pull-off forces "
            "that Olaru et al. quote.",
            default=0.18, minimum=0, maximum=10,
        ),
        Parameter(
            "water_surface_tension_N_m", "gamma_w", "N/m",
            "Surface tension of the condensed water film driving the ball-ball "
            "capillary force (0.0717 N/m at 27 degC).",
            default=0.0717, minimum=0, maximum=1,
        ),
        Parameter(
            "viscosity_Pa_s", "eta_0", "Pa*s",
            "Dynamic viscosity of the water film at ambient pressure.",
            default=1e-3, minimum=0, maximum=1e3,
        ),
        Parameter(
            "pressure_viscosity_1_Pa", "alpha", "1/Pa",
            "Pressure-viscosity coefficient of the water film.",
            default=1e-8, minimum=1e-12, maximum=1e-6,
        ),
        Parameter(
            "ball_youngs_modulus_Pa", "E_1", "Pa",
            "Young's modulus of the balls (stainless steel, 2.1e11 Pa).",
            default=_STEEL_E_PA, minimum=1e6, maximum=1e13,
        ),
        Parameter(
            "ball_poisson_ratio", "nu_1", "1",
            "Poisson's ratio of the balls.",
            default=0.3, minimum=0, maximum=0.5, exclusive_maximum=True,
        ),
        Parameter(
            "race_youngs_modulus_Pa", "E_2", "Pa",
            "Young's modulus of slider and stator (silicon, 1.5e11 Pa).",
            default=_SILICON_E_PA, minimum=1e6, maximum=1e13,
        ),
        Parameter(
            "race_poisson_ratio", "nu_2", "1",
            "Poisson's ratio of slider and stator.",
            default=0.3, minimum=0, maximum=0.5, exclusive_maximum=True,
        ),
    ]
}

#: The readings of the paper's ambiguous equations (see :mod:`physics.bearing`).
CONVENTIONS: dict[str, str] = {
    "olaru2005": (
        "The paper as printed: ball-ball radius 1/R* = 2(1/R1 + 1/R2) (R/4 for "
        "equal balls) in eq 6 and the ball-ball moment counted twice per ball in "
        "eq 21. Reproduces the paper's Figs. 5 and 6."
    ),
    "derjaguin": (
        "Physically consistent reading: Derjaguin radius R* = R1 R2/(R1 + R2) "
        "(R/2 for equal balls) and the ball-ball moment counted once per ball. "
        "Gives the same numbers for equal balls; differs for unequal radii."
    ),
}
DEFAULT_CONVENTION = "olaru2005"


def _array_text(values: np.ndarray, mask: np.ndarray) -> str:
    index = int(np.flatnonzero(mask)[0])
    flat = np.asarray(values).reshape(-1)
    shown = flat[index].item()
    if flat.size == 1:
        return f"got {shown!r}"
    return f"got {shown!r} at index {index}"


def _short_repr(value: Any, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit]}..."


def _not_of_kind_text(given: np.ndarray, kind: str) -> str:
    """'got X (a str, not a number) at index i' for the first element of ``given`` that is not ``kind``."""
    flat = given.reshape(-1)
    if given.dtype == object:
        boolean = kind == "a boolean"
        index = next((i for i, item in enumerate(flat)
                      if isinstance(item, bool) != boolean or not isinstance(item, int | float)), 0)
    else:
        index = 0
    item = flat[index] if flat.size else given
    item = item.item() if isinstance(item, np.generic | np.ndarray) else item
    what = "None (no value)" if item is None else f"{_short_repr(item)} ({type(item).__name__}, not {kind})"
    return f"got {what}" + (f" at index {index}" if given.ndim else "")


def _accepted(spec: Parameter, values: np.ndarray, whole: bool = False, chunk: int = 65536) -> bool:
    """Whether ``spec`` accepts every one of the float64 ``values``: the fast path of :func:`validate`.

    Chunk by chunk, so that the second and third passes over a chunk (max after min, and the
    whole-number test of an integer parameter) read it from the CPU's cache rather than from
    memory (about a quarter less time on large arrays); no array-sized temporaries. The min and
    max of a chunk are NaN if any value is. ``whole``: the values are known to be whole numbers
    (they were given as integers), so an integer parameter skips that test.
    """
    test_whole = spec.kind == "int" and not whole
    if not values.flags.c_contiguous:  # a strided view, whole (reshape would copy it)
        return spec.accepts(float(values.min())) and spec.accepts(float(values.max())) and (
            not test_whole or np.array_equal(np.rint(values), values))
    flat = values.reshape(-1)
    buffer = np.empty(min(chunk, flat.size)) if test_whole else None
    for start in range(0, flat.size, chunk):
        part = flat[start:start + chunk]
        if not (spec.accepts(float(part.min())) and spec.accepts(float(part.max()))):
            return False
        if buffer is not None and not np.array_equal(np.rint(part, out=buffer[:part.size]), part):
            return False
    return True


def validate(name: str, value: Any) -> np.ndarray:
    """Check one input against its :class:`Parameter` and return it as an array.

    Parameters
    ----------
    name : str
        A key of :data:`PARAMETERS`.
    value : numeric, bool or array_like
        The value to check, scalar or array.

    Returns
    -------
    numpy.ndarray
        ``float64`` for numbers (whole numbers for ``kind == "int"``), ``bool``
        for booleans, in the shape given.

    Raises
    ------
    ValueError
        Naming the parameter, its allowed range and the offending value, for
        NaN, infinities, values out of range, fractional integers, or
        non-numeric input.

    Examples
    --------
    >>> validate("load_N", -1.0)
    Traceback (most recent call last):
    ...
    ValueError: load_N must be in [1e-09, 1e+06] [N]; got -1.0
    """
    spec = PARAMETERS[name]
    if type(value) in (float, int) and spec.kind != "bool" and spec.accepts(value):
        return np.asarray(value, dtype=np.float64)

    def allowed() -> str:  # written only for an error: every array input passes through here
        return f"{spec.name} must be {spec.range_text()} [{spec.unit}]"

    if value is None:
        raise ValueError(f"{allowed()}; got None (no value)")
    try:
        given = np.asarray(value)
    except (TypeError, ValueError):  # ragged nesting
        raise ValueError(f"{allowed()}; got {_short_repr(value)}") from None
    if spec.kind == "bool":
        if given.dtype != np.bool_:
            raise ValueError(f"{allowed()}; {_not_of_kind_text(given, 'a boolean')}")
        return given
    if given.dtype == np.bool_:
        raise ValueError(f"{allowed()}; got a boolean {_short_repr(value)}")
    if given.dtype.kind not in "iuf":  # strings, None among numbers, complex: never read as numbers
        raise ValueError(f"{allowed()}; {_not_of_kind_text(given, 'a number')}")
    arr = given.astype(np.float64, copy=False)
    if arr.size and _accepted(spec, arr, whole=given.dtype.kind != "f"):
        return arr
    bad = ~np.isfinite(arr)
    if bad.any():
        raise ValueError(f"{allowed()} and finite; {_array_text(arr, bad)}")
    if spec.minimum is not None:
        bad = arr <= spec.minimum if spec.exclusive_minimum else arr < spec.minimum
        if bad.any():
            raise ValueError(f"{allowed()}; {_array_text(arr, bad)}")
    if spec.maximum is not None:
        bad = arr >= spec.maximum if spec.exclusive_maximum else arr > spec.maximum
        if bad.any():
            raise ValueError(f"{allowed()}; {_array_text(arr, bad)}")
    if spec.kind == "int":
        bad = arr != np.round(arr)
        if bad.any():
            raise ValueError(f"{allowed()}; {_array_text(arr, bad)}")
    return arr


def defaults() -> dict[str, float | bool]:
    """The default of every optional parameter, keyed by name."""
    return dict(_DEFAULTS)


_DEFAULTS = {n: p.default for n, p in PARAMETERS.items() if p.default is not None}
_REQUIRED = frozenset(n for n, p in PARAMETERS.items() if p.default is None)
#: The defaults, validated once: Python floats and bools, as :func:`checked_inputs` returns scalars.
_CHECKED_DEFAULTS = {n: validate(n, v).item() for n, v in _DEFAULTS.items()}


def validate_all(params: dict[str, Any]) -> dict[str, np.ndarray]:
    """Fill defaults, reject unknown or missing names, validate every value.

    Parameters
    ----------
    params : dict
        Keyword inputs of :func:`physics.evaluate`.

    Returns
    -------
    dict of numpy.ndarray
        Every parameter of :data:`PARAMETERS`, validated.

    Raises
    ------
    ValueError
        For an unknown name, a missing required one, an invalid value, or
        array inputs whose shapes do not broadcast together.
    """
    return {name: np.asarray(value) for name, value in checked_inputs(params)[0].items()}


def checked_inputs(params: dict[str, Any]) -> tuple[dict[str, float | bool | np.ndarray], tuple[int, ...]]:
    """:func:`validate_all` with scalars as Python ``float`` and ``bool`` (for speed), and the shape.

    The validation of :func:`physics.evaluate`: arrays come back as from
    :func:`validate`, scalars as plain Python numbers, so that a single-point
    evaluation stays in cheap scalar arithmetic; the second item is the
    broadcast shape of the arrays (``()`` when every input is a scalar).
    """
    if not params.keys() <= PARAMETERS.keys():
        unknown = sorted(set(params) - set(PARAMETERS))
        raise ValueError(
            f"unknown parameter(s) {', '.join(unknown)}; "
            f"known: {', '.join(PARAMETERS)}"
        )
    if not _REQUIRED <= params.keys():
        missing = [n for n in PARAMETERS if n in _REQUIRED and n not in params]
        raise ValueError(f"missing required parameter(s): {', '.join(missing)}")
    checked: dict[str, float | bool | np.ndarray] = dict(_CHECKED_DEFAULTS)
    shapes: set[tuple[int, ...]] = set()
    for name, value in params.items():
        spec = PARAMETERS[name]
        kind = type(value)
        if kind is bool and spec.kind == "bool":
            checked[name] = value
        elif (kind is float or kind is int) and spec.accepts(value):  # a boolean parameter accepts no number
            checked[name] = float(value)
        elif (kind is np.ndarray and value.ndim == 0 and value.dtype == np.float64
              and spec.accepts(number := float(value))):  # a float held as a 0-d array: the same number
            checked[name] = number
        else:
            array = validate(name, value)
            checked[name] = array.item() if array.ndim == 0 else array
            if array.ndim:
                shapes.add(array.shape)
    if len(shapes) <= 1:
        return checked, shapes.pop() if shapes else ()
    try:
        return checked, np.broadcast_shapes(*shapes)
    except ValueError:
        named = {n: a.shape for n, a in checked.items() if isinstance(a, np.ndarray)}
        raise ValueError(f"array parameters do not broadcast together: {named}") from None
