"""The design problem: bounds, engineering constraints, speed and fixed physics parameters.

A designer chooses the total number of balls ``balls`` (an integer), the groove
angle ``groove_angle_deg`` and the normal load ``load_N`` inside a box of
:class:`DesignBounds`, subject to the optional limits of :class:`Constraints`,
with every other input of :func:`physics.evaluate` fixed. :class:`DesignProblem`
bundles them and validates everything up front, raising ``ValueError`` that
names the offending field and its allowed range.

Worst case over a speed range
-----------------------------
Speed enters the model only through Houpert's rolling force
F_R = k_R Q^0.47 V^0.66 with k_R >= 0, which adds the term 4 z F_R / G to μ and
4 z F_R to the friction force; every other term and every other output does
not depend on V. Hence, for every design x and V1 <= V2,
μ(x, V1) <= μ(x, V2) and F(x, V1) <= F(x, V2), so that

    max_{V in [V_lo, V_hi]} μ(x, V) = μ(x, V_hi)   for every x,

and min_x max_V μ = min_x μ(x, V_hi) subject to constraints that are also
evaluated at V_hi (the friction-force limit is the only speed-dependent one,
and it is also worst at V_hi). :meth:`DesignProblem.design_speed_m_s` returns
V_hi; ``tests/test_optimize.py`` checks the monotonicity on the exact physics.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from microbearing import physics
from microbearing.physics import DEFAULT_CONVENTION, PARAMETERS

__all__ = ["DESIGN_VARIABLES", "ACTIVE_TOLERANCE", "DesignBounds", "Constraints", "DesignProblem",
           "ConstraintStatus", "constraint_report"]

#: A continuous limit counts as active when the value is within this relative distance of it. [1]
ACTIVE_TOLERANCE = 1e-5

#: The inputs of :func:`physics.evaluate` that the optimizer chooses.
DESIGN_VARIABLES = ("balls", "groove_angle_deg", "load_N")


def _pair(name: str, value: Any, field: str | None = None) -> tuple[float, float]:
    """A validated [lower, upper] pair of parameter ``name``; errors name ``field`` (``bounds.<name>``)."""
    field = f"bounds.{name}" if field is None else field
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{field} must be a pair [lower, upper]; got {value!r}") from None
    for v in (lo, hi):
        try:
            physics.validate(name, v)
        except ValueError as err:
            raise ValueError(f"{field}: {err}") from None
    if lo > hi:
        raise ValueError(f"{field} must have lower <= upper; got [{lo:g}, {hi:g}]")
    return lo, hi


@dataclass(frozen=True)
class DesignBounds:
    """Box bounds of the three design variables (both ends included).

    Parameters
    ----------
    balls : tuple of int
        [lower, upper] total number of balls z, whole numbers >= 1. [1]
    groove_angle_deg : tuple of float
        [lower, upper] groove angle θ, within the bounds of
        ``physics.PARAMETERS["groove_angle_deg"]``. [deg]
    load_N : tuple of float
        [lower, upper] normal load G on the slider, > 0. [N]

    Raises
    ------
    ValueError
        Naming the field, e.g. ``bounds.load_N``, when a pair is malformed,
        out of the physics range or has lower > upper.
    """

    balls: tuple[int, int]
    groove_angle_deg: tuple[float, float]
    load_N: tuple[float, float]

    def __post_init__(self) -> None:
        lo, hi = _pair("balls", self.balls)
        object.__setattr__(self, "balls", (int(lo), int(hi)))
        object.__setattr__(self, "groove_angle_deg", _pair("groove_angle_deg", self.groove_angle_deg))
        object.__setattr__(self, "load_N", _pair("load_N", self.load_N))


@dataclass(frozen=True)
class Constraints:
    """Optional engineering limits; ``None`` switches a limit off.

    Parameters
    ----------
    max_contact_pressure_Pa : float, optional
        Upper limit on the physics output ``max_contact_pressure_Pa``, the
        peak Hertz pressure 3Q/(2πa²) of a ball-race contact. [Pa]
    max_friction_force_N : float, optional
        Upper limit on the total friction force μ G at the worst-case speed. [N]
    min_load_capacity_N : float, optional
        The bearing must be designed for at least this normal load:
        ``load_N >= min_load_capacity_N``. [N]
    max_load_per_ball_N : float, optional
        Upper limit on the load each ball carries, G / z. [N]
    groove_length_m : float, optional
        Length L of each of the two grooves. The z balls are split between them,
        so the fuller groove holds n = ceil(z/2) balls, which must fit with
        the gap below between neighbours: n d + (n - 1) g <= L. When the
        balls are declared apart (``balls_touching=False``, the default) and
        g = 0, the fit is strict, n d < L, so that some positive clearance is
        left between them (see :meth:`DesignProblem.fits_groove`). [m]
    min_ball_gap_m : float, default 0
        Clearance g between neighbouring balls in a groove for
        ``groove_length_m``. With g = 0 and ``balls_touching=True`` neighbours
        may just touch; with ``balls_touching=False`` they must not (strict
        fit); choose g > 0 for a definite clearance. [m]

    Raises
    ------
    ValueError
        Naming the field when a limit is not a finite positive number
        (``min_ball_gap_m`` may be 0).
    """

    max_contact_pressure_Pa: float | None = None
    max_friction_force_N: float | None = None
    min_load_capacity_N: float | None = None
    max_load_per_ball_N: float | None = None
    groove_length_m: float | None = None
    min_ball_gap_m: float = 0.0

    def __post_init__(self) -> None:
        for name in ("max_contact_pressure_Pa", "max_friction_force_N", "min_load_capacity_N",
                     "max_load_per_ball_N", "groove_length_m"):
            value = getattr(self, name)
            if value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, int | float) or not (
                    math.isfinite(value) and value > 0):
                raise ValueError(f"constraints.{name} must be a finite number > 0 or null; got {value!r}")
            object.__setattr__(self, name, float(value))
        gap = self.min_ball_gap_m
        if isinstance(gap, bool) or not isinstance(gap, int | float) or not (math.isfinite(gap) and gap >= 0):
            raise ValueError(f"constraints.min_ball_gap_m must be a finite number >= 0; got {gap!r}")
        object.__setattr__(self, "min_ball_gap_m", float(gap))

    def active_limits(self) -> dict[str, float]:
        """The limits that are switched on, by name (``min_ball_gap_m`` excluded). [SI units]"""
        names = ("max_contact_pressure_Pa", "max_friction_force_N", "min_load_capacity_N",
                 "max_load_per_ball_N", "groove_length_m")
        return {n: getattr(self, n) for n in names if getattr(self, n) is not None}


@dataclass(frozen=True)
class DesignProblem:
    """Minimize μ over the design box under the constraints, other inputs fixed.

    Parameters
    ----------
    bounds : DesignBounds
        Box of ``balls`` [1], ``groove_angle_deg`` [deg] and ``load_N`` [N].
    speed_m_s : float or tuple of float
        Slider speed V, or a [lower, upper] range whose worst case (the upper
        end, see the module docstring) is designed for. [m/s]
    constraints : Constraints, optional
        Engineering limits; none by default.
    fixed : mapping, optional
        Every other input of :func:`physics.evaluate` by name (SI units as in
        :data:`physics.PARAMETERS`); missing ones take their defaults. The
        design variables and ``speed_m_s`` are not allowed here.
    convention : str, default ``physics.DEFAULT_CONVENTION``
        Reading of the paper's ball-ball terms, a key of :data:`physics.CONVENTIONS`.

    Raises
    ------
    ValueError
        Naming the field: an unknown or out-of-range fixed parameter
        (``fixed.<name>``), a design variable or speed inside ``fixed``, a bad
        speed or speed range, or an unknown convention.
    """

    bounds: DesignBounds
    speed_m_s: float | tuple[float, float]
    constraints: Constraints = field(default_factory=Constraints)
    fixed: Mapping[str, Any] = field(default_factory=dict)
    convention: str = DEFAULT_CONVENTION

    def __post_init__(self) -> None:
        if not isinstance(self.bounds, DesignBounds):
            raise ValueError(f"bounds must be a DesignBounds; got {type(self.bounds).__name__}")
        if not isinstance(self.constraints, Constraints):
            raise ValueError(f"constraints must be a Constraints; got {type(self.constraints).__name__}")
        if self.convention not in physics.CONVENTIONS:
            raise ValueError(f"convention must be one of {', '.join(physics.CONVENTIONS)}; "
                             f"got {self.convention!r}")
        speed = self.speed_m_s
        if isinstance(speed, list | tuple):
            speed = _pair("speed_m_s", speed, field="speed_m_s")
        else:
            try:
                speed = float(physics.validate("speed_m_s", speed))
            except ValueError as err:
                raise ValueError(f"speed_m_s: {err}") from None
        object.__setattr__(self, "speed_m_s", speed)
        fixed = dict(self.fixed)
        for name in (*DESIGN_VARIABLES, "speed_m_s"):
            if name in fixed:
                raise ValueError(f"fixed.{name} is not allowed: it is "
                                 f"{'the speed argument' if name == 'speed_m_s' else 'a design variable'}")
        for name, value in fixed.items():
            if name not in PARAMETERS:
                raise ValueError(f"fixed.{name} is not a physics parameter; known: {', '.join(PARAMETERS)}")
            try:
                checked = physics.validate(name, value)
            except ValueError as err:
                raise ValueError(f"fixed.{name}: {err}") from None
            if checked.ndim:
                raise ValueError(f"fixed.{name} must be a scalar; got shape {checked.shape}")
            fixed[name] = checked.item()
        defaults = {k: v for k, v in physics.defaults().items() if k not in DESIGN_VARIABLES}
        object.__setattr__(self, "fixed", {**defaults, **fixed})

    def design_speed_m_s(self) -> float:
        """The speed the exact physics is designed for.

        Returns
        -------
        float
            V itself, or the upper end V_hi of a speed range, where μ and the
            friction force of the exact physics are largest (see the module
            docstring; other μ models are checked over a grid of the range by
            :func:`optimize.optimize_model`). [m/s]
        """
        return self.speed_m_s[1] if isinstance(self.speed_m_s, tuple) else self.speed_m_s

    def physics_inputs(self, balls, groove_angle_deg, load_N, speed_m_s=None) -> dict[str, Any]:
        """Keyword inputs of :func:`physics.evaluate` for designs at the design speed.

        Parameters
        ----------
        balls : int or array_like
            Total number of balls z. [1]
        groove_angle_deg : float or array_like
            Groove angle θ. [deg]
        load_N : float or array_like
            Normal load G. [N]
        speed_m_s : float or array_like, optional
            Speed V to use instead of :meth:`design_speed_m_s`. [m/s]

        Returns
        -------
        dict
            Fixed parameters, the speed [m/s] and the design variables.
        """
        speed = self.design_speed_m_s() if speed_m_s is None else speed_m_s
        return {**self.fixed, "speed_m_s": speed, "balls": balls,
                "groove_angle_deg": groove_angle_deg, "load_N": load_N}

    def balls_per_groove(self, balls: int) -> int:
        """Balls in the fuller of the two grooves, ceil(z / 2). [1]"""
        return -(-int(balls) // 2)

    def groove_fill_m(self, balls: int) -> float:
        """Length n d + (n - 1) g the balls of the fuller groove occupy. [m]"""
        n = self.balls_per_groove(balls)
        return n * float(self.fixed["ball_diameter_m"]) + (n - 1) * self.constraints.min_ball_gap_m

    def fits_groove(self, balls: int) -> bool:
        """Whether z balls fit ``groove_length_m`` (always True without it).

        The fuller groove's n = ceil(z/2) balls fill n d + (n - 1) g, which
        must not exceed the groove length L. Balls declared apart
        (``fixed["balls_touching"]`` False) with no gap g must leave room to
        stand apart: n d < L strictly, so that balls that would just touch do
        not fit.

        Parameters
        ----------
        balls : int
            Total number of balls z. [1]

        Returns
        -------
        bool
            Whether they fit. [-]

        Examples
        --------
        >>> bounds = DesignBounds((1, 20), (40, 60), (0.001, 0.05))
        >>> apart = DesignProblem(bounds, 0.05, Constraints(groove_length_m=2e-3),
        ...                       fixed={"ball_diameter_m": 250e-6, "balls_touching": False})
        >>> apart.fits_groove(14), apart.fits_groove(16)  # 8 x 250 um = 2 mm would touch
        (True, False)
        """
        length = self.constraints.groove_length_m
        if length is None:
            return True
        fill = self.groove_fill_m(balls)
        if self.constraints.min_ball_gap_m == 0 and not self.fixed["balls_touching"]:
            return fill < length
        return fill <= length

    def ball_counts(self) -> list[int]:
        """Every ball count of the bounds that fits ``groove_length_m`` (all of them without it). [1]"""
        lo, hi = self.bounds.balls
        return [z for z in range(lo, hi + 1) if self.fits_groove(z)]


@dataclass(frozen=True)
class ConstraintStatus:
    """One bound or limit evaluated at a design with the exact physics.

    Attributes
    ----------
    name : str
        ``balls_min``, ``balls_max``, ``groove_angle_deg_min``, ``groove_angle_deg_max``,
        ``load_N_min``, ``load_N_max`` or a :class:`Constraints` field name.
    value : float
        The constrained quantity at the design (for ``groove_length_m``: the
        length n d + (n - 1) g the fuller groove's balls occupy). [unit of the quantity]
    limit : float
        The bound or limit. [unit of the quantity]
    sense : str
        ``"<="`` (value must not exceed limit) or ``">="``.
    active : bool
        Whether the design sits on it: within :data:`ACTIVE_TOLERANCE`
        relative for continuous quantities, equal for the ball-count bounds,
        and for ``groove_length_m`` when one more ball would not fit.
    satisfied : bool
        Whether ``value`` meets the limit (no tolerance).
    decided_by : str
        The model whose value decided ``satisfied``: ``"physics"`` for the bounds and the limits
        that do not depend on μ, else the model judging μ (a surrogate's source model when the
        design was verified).
    value_model : float or None
        The quantity under the model that was optimized, when that is not the one that decided
        (a surrogate: its friction force μ G; the exact limits repeat ``value``). [unit of the quantity]
    """

    name: str
    value: float
    limit: float
    sense: str
    active: bool
    satisfied: bool
    decided_by: str = "physics"
    value_model: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields."""
        return {"name": self.name, "value": self.value, "limit": self.limit, "sense": self.sense,
                "active": self.active, "satisfied": self.satisfied, "decided_by": self.decided_by,
                "value_model": self.value_model}


def _status(name: str, value: float, limit: float, sense: str) -> ConstraintStatus:
    satisfied = value <= limit if sense == "<=" else value >= limit
    active = abs(value - limit) <= ACTIVE_TOLERANCE * abs(limit)
    return ConstraintStatus(name, float(value), float(limit), sense, bool(active), bool(satisfied))


def constraint_report(problem: DesignProblem, balls: int, groove_angle_deg: float, load_N: float,
                      result: physics.FrictionResult | None = None,
                      mu: float | None = None, mu_name: str = "physics") -> list[ConstraintStatus]:
    """Every bound and limit of a problem evaluated at one design with the exact physics.

    Parameters
    ----------
    problem : DesignProblem
        The problem whose bounds and limits to check.
    balls : int
        Ball count z. [1]
    groove_angle_deg : float
        Groove angle θ. [deg]
    load_N : float
        Load G. [N]
    result : physics.FrictionResult, optional
        :func:`physics.evaluate` at this design and the design speed, if
        already computed.
    mu : float, optional
        μ of another model (a surrogate or calibrated model) at the design; the
        friction force is then μ G instead of the physics' value. [1]
    mu_name : str, default "physics"
        Name of the model ``mu`` comes from (the friction force's ``decided_by``). [-]

    Returns
    -------
    list of ConstraintStatus
        The six bounds, then the limits that are switched on.
    """
    if result is None:
        result = physics.evaluate(convention=problem.convention,
                                  **problem.physics_inputs(balls, groove_angle_deg, load_N))
    b, c = problem.bounds, problem.constraints
    report = [
        ConstraintStatus("balls_min", float(balls), float(b.balls[0]), ">=", balls == b.balls[0],
                         balls >= b.balls[0]),
        ConstraintStatus("balls_max", float(balls), float(b.balls[1]), "<=", balls == b.balls[1],
                         balls <= b.balls[1]),
        _status("groove_angle_deg_min", groove_angle_deg, b.groove_angle_deg[0], ">="),
        _status("groove_angle_deg_max", groove_angle_deg, b.groove_angle_deg[1], "<="),
        _status("load_N_min", load_N, b.load_N[0], ">="),
        _status("load_N_max", load_N, b.load_N[1], "<="),
    ]
    measured = {
        "max_contact_pressure_Pa": float(result.max_contact_pressure_Pa),
        "max_friction_force_N": float(result.friction_force_N) if mu is None else float(mu) * float(load_N),
        "min_load_capacity_N": float(load_N),
        "max_load_per_ball_N": float(load_N) / balls,
    }
    for name, limit in c.active_limits().items():
        if name == "groove_length_m":
            fill = problem.groove_fill_m(balls)
            report.append(ConstraintStatus(name, fill, limit, "<=", not problem.fits_groove(balls + 1),
                                           problem.fits_groove(balls)))
        else:
            status = _status(name, measured[name], limit, ">=" if name.startswith("min_") else "<=")
            if name == "max_friction_force_N" and mu is not None:
                status = dataclasses.replace(status, decided_by=mu_name)
            report.append(status)
    return report
