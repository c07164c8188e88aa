"""Optional effects outside the model of Olaru et al. (2005), for calibration against measurements.

The model of :func:`physics.evaluate` leaves out effects a tribologist would
suspect in a real micro bearing: menisci that grow with humidity, viscous drag
on the slider, a constant parasitic drag, a temperature-dependent interfacial
shear strength, running-in. Each is an :class:`Effect` with a formula, its
fitted parameters (unit, bounds, initial guess) and the column(s) of measured
data that drive it. :func:`apply_effect` corrects the μ of the model:

>>> import numpy as np
>>> mu = np.array([0.01, 0.01])
>>> columns = {"load_N": np.array([0.01, 0.02])}
>>> apply_effect(mu, "constant_drag", columns, {"drag_force_N": 1e-4}).round(4).tolist()
[0.02, 0.015]

A calibrated model is then ``apply_effect(physics.evaluate(**p).mu, ...)``
with fitted declared parameters and one effect. ``generic_*`` effects are the
fallback family of low-order terms in log μ for any column when no named
effect fits.

Driver columns are matched by name: a humidity column contains ``humid`` or
``rh`` (a fraction in [0, 1), or percent when the name contains ``pct`` or
``percent``), a temperature column ``temp`` (:mod:`physics.drivers`), a running-in
column ``run``, ``cycle``, ``pass``, ``stroke``, ``count``, ``time`` or ``distance``.

Each effect declares what its callers read rather than re-derive: how it enters μ
(:attr:`Effect.enters`), whether it is monotone in its driver and in which
direction, its stationary point, how μ moves with each fitted value
(:attr:`Effect.value_forms`); :data:`PARAMETER_SHARES` declares how the physics'
μ moves with each parameter a drift may move. :func:`register_effect` adds a law.

Notes
-----
With μ_m the model's μ, z the balls, G the load [N], V the speed [m/s]:

* ``humidity_meniscus``: μ = μ_m + z F_m / (G ln(1/h)), F_m [N]; capillary
  condensation (Kelvin radius ∝ 1/ln(1/h)) [1]_.
* ``viscous_drag``: μ = μ_m + c_v V / G, c_v = η A / h [N s/m]; Couette drag [2]_.
* ``constant_drag``: μ = μ_m + F_0 / G, F_0 [N]; electrostatic or cable drag [3]_.
* ``thermal_shear_strength``: μ = μ_m exp(-β (T - T_ref)), β [1/K], T_ref the
  data's median; thermally activated interfacial shear strength [4]_.
* ``run_in``: μ = μ_m (1 + A exp(-n / n_0)), A [1], n_0 [unit of n]; running-in [5]_.
* ``stribeck_breakaway``: μ = μ_m + a exp(-V / V_0), a fixed excess at rest; ``stribeck_rise``:
  μ = μ_m (1 + r exp(-V / V_0)), the rise a fraction r of the friction it raises.
* ``measurement_drift``, ``measurement_step``: the reading drifts linearly or steps once (at a place
  searched, :mod:`physics.changepoints`) over an order or time column.
* ``generic_linear``, ``generic_quadratic``: μ = μ_m exp(c_1 z + c_2 z²),
  z = (x - mean) / std; ``generic_power``: μ = μ_m (x / median)^c_1.

References
----------
.. [1] L. Bocquet, E. Charlaix, S. Ciliberto, J. Crassous, Nature 396, 735-737 (1998).
.. [2] B.J. Hamrock, Fundamentals of Fluid Film Lubrication, McGraw-Hill, 1994, ch. 4.
.. [3] W.C. Tang, T.H. Nguyen, R.T. Howe, Sensors and Actuators 20, 25-32 (1989).
.. [4] B.J. Briscoe, D.C.B. Evans, Proc. R. Soc. A 380, 389-407 (1982).
.. [5] P.J. Blau, Tribology International 38, 1007-1012 (2005).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from .changepoints import step_places
from .drift_laws import DRIFT_LAWS, GAS_CONSTANT_J_MOL_K, DriftLaw  # re-exported: the drift laws
from .drivers import (
    DRIVER_KINDS,
    HUMIDITY,
    TEMPERATURE,
    Domain,
    DriverKind,
    DriverUnit,
    humidity_fraction,
    name_matches,
    temperature_kelvin,
)
from .effect_parameter import EffectParameter

# re-exported: the parameters a drift or a fit may move, their share of mu and plausible values
from .shares import CONTACT_LOAD_EXPONENTS, DRIFT_PARAMETERS, PARAMETER_SHARES, ParameterShare

__all__ = ["EffectParameter", "Effect", "EFFECTS", "DriftLaw", "DRIFT_LAWS", "DRIFT_PARAMETERS", "Domain",
           "CONTACT_LOAD_EXPONENTS",
           "DriverKind", "DriverUnit", "DRIVER_KINDS", "HUMIDITY", "TEMPERATURE", "ParameterShare",
           "PARAMETER_SHARES", "SESSION_KEYWORDS", "VALUE_FORMS", "apply_effect", "name_matches",
           "register_effect", "humidity_fraction", "temperature_kelvin", "GAS_CONSTANT_J_MOL_K"]


_Columns = Mapping[str, np.ndarray]

#: How μ may move with an effect's fitted value (:attr:`Effect.value_forms`): ``scale``, an added piece
#: linear in it, a(p + h) - a(p) = h basis(x) with the basis monotone in the driver; ``log``, a factor whose
#: logarithm is linear in it, m(p + h) / m(p) = exp(h φ(x)) with φ monotone in the driver; ``log_square``,
#: the same with φ = z², least at the centre of the driver's data.
VALUE_FORMS = ("scale", "log", "log_square")


@dataclass(frozen=True)
class Effect:
    """A named optional correction of μ with fitted parameters and driving columns.

    Attributes
    ----------
    name : str
        Key in :data:`EFFECTS`.
    title : str
        What the effect is, in words.
    formula : str
        The corrected μ in terms of the model's μ (``mu_model``), the driver and the parameters.
    parameters : tuple of EffectParameter
        Fitted parameters, in the order of the formula.
    driver_description : str
        Which column drives the effect and in what unit.
    reference : str
        Where the physics of the effect comes from.
    fixed_drivers : tuple of str
        Physics columns that always drive it (first = the main driver); empty when the driver is a
        measured condition column chosen by name.
    driver_keywords : tuple of str
        Prefixes of the words of a condition column's name that make it a plausible driver; empty and
        no ``fixed_drivers`` means any numeric column (the generic family).
    generic : bool
        True for the generic fallback family.
    min_levels : int
        Fewest distinct values a main driver column must take for the effect to be tried: 3 for
        curved forms (a two-level column cannot tell them from a step); 2 for ``generic_linear``,
        which on a two-level column (e.g. 0/1 for uncoated/coated) is a step of log μ. [1]
    correct : callable
        ``correct(mu, x, columns, values, constants)``: the formula, with ``x`` the main driver in the
        formula's unit and ``values`` the parameters in order.
    make_constants : callable or None
        ``make_constants(x) -> dict`` of constants fixed from the data (None: no constants).
    make_initial : callable
        ``make_initial(mu, x, columns, constants) -> list`` of initial parameter values.
    accepts_values : callable or None
        ``accepts_values(x) -> bool``: a check of the driver beyond :attr:`domain` (None: none).
    driver_transform : callable or None
        ``driver_transform(name, values)``: the driver in the formula's unit (None: as given); increasing
        and affine in the values.
    domain : Domain or None
        The main driver's values the formula holds for, in the formula's unit (None: any);
        :meth:`column_domain` gives it in a column's unit.
    enters : {"add", "mul"} or None
        How the effect enters μ: added, μ + a(x), or multiplying, μ m(x) with m > 0 (both non-decreasing
        in μ); None: undeclared, and no bound over a box of its driver is known for it.
    monotone : bool
        Whether a(x) or m(x) is monotone in the main driver for every fitted value; False for a
        log-quadratic, whose extremes over an interval are at its ends or at :attr:`stationary`.
    direction : callable or None
        ``direction(values) -> 1, -1 or 0``: the sign of the change of μ with the main driver (0: none)
        at the fitted values; None: not known to be monotone.
    stationary : callable or None
        ``stationary(values, constants) -> x or None``: where a non-monotone term is stationary.
    value_forms : tuple of str or None
        Per fitted parameter, how μ moves with it (one of :data:`VALUE_FORMS`), None where it has no
        such closed form (a Stribeck speed, an exponent of speed, a run-in): what the bounds of the
        prediction interval over a box need.
    searched : tuple of str
        Constants the selection searches (a step's place): not fitted smoothly but chosen among the
        values ``search_constants`` gives, one candidate each; each counts as a fitted parameter.
    search_constants : callable or None
        ``search_constants(x) -> list of dict``: the values of the searched constants to try.
    named_form_of : str or None
        The generic effect this one names on its drivers: the same shape with another reference point
        (where the factor is 1). A search that proposes this effect on a driver does not propose that
        generic one there too: their fits differ only by where the physics' level sits, and a
        hair's difference would otherwise name the generic form for a mechanism the catalogue knows.
    identity_at : callable or None
        ``identity_at(constants) -> x``: for a term of the measurement system (the instrument's reading, not
        the bearing), a value of its driver where it is the identity (μ unchanged, and so is its derivative
        in every fitted value): a prediction that does not give the driver is made there, the bearing's μ
        as the reading was true (at the session's start). None: the driver is required.
    """

    name: str
    title: str
    formula: str
    parameters: tuple[EffectParameter, ...]
    driver_description: str
    reference: str
    fixed_drivers: tuple[str, ...] = ()
    driver_keywords: tuple[str, ...] = ()
    generic: bool = False
    min_levels: int = 3
    correct: Callable = field(default=None, repr=False, compare=False)
    make_constants: Callable = field(default=None, repr=False, compare=False)
    make_initial: Callable = field(default=None, repr=False, compare=False)
    accepts_values: Callable = field(default=None, repr=False, compare=False)
    driver_transform: Callable = field(default=None, repr=False, compare=False)
    domain: Domain | None = None
    enters: str | None = None
    monotone: bool = True
    direction: Callable = field(default=None, repr=False, compare=False)
    stationary: Callable = field(default=None, repr=False, compare=False)
    value_forms: tuple[str | None, ...] = ()
    searched: tuple[str, ...] = ()
    search_constants: Callable = field(default=None, repr=False, compare=False)
    named_form_of: str | None = None
    identity_at: Callable = field(default=None, repr=False, compare=False)

    @property
    def parameter_names(self) -> list[str]:
        """Names of the fitted parameters, in order."""
        return [p.name for p in self.parameters]

    def candidate_drivers(self, column_names: Iterable[str]) -> list[tuple[str, ...]]:
        """Driver tuples this effect could use among the given columns.

        Parameters
        ----------
        column_names : iterable of str
            Columns of the measured data (physics parameters and conditions).

        Returns
        -------
        list of tuple of str
            One tuple per plausible driver choice, main driver first.
        """
        names = list(column_names)
        if self.fixed_drivers:
            return [self.fixed_drivers] if set(self.fixed_drivers) <= set(names) else []
        if not self.driver_keywords:
            return [(n,) for n in names]
        return [(n,) for n in names if name_matches(n, self.driver_keywords)]

    def driver_values(self, columns: _Columns, drivers: tuple[str, ...]) -> np.ndarray:
        """The main driver's values in the unit of the formula (humidity percent -> fraction)."""
        x = np.asarray(columns[drivers[0]], dtype=float)
        return x if self.driver_transform is None else self.driver_transform(drivers[0], x)

    def column_domain(self, name: str) -> Domain | None:
        """:attr:`domain` in the unit of the driver column ``name`` (percent humidity: (0, 100))."""
        if self.domain is None or self.driver_transform is None:
            return self.domain
        return self.domain.in_unit(lambda x: self.driver_transform(name, x))

    def accepts(self, columns: _Columns, drivers: tuple[str, ...]) -> bool:
        """Whether the driver values lie in the effect's domain (e.g. humidity in (0, 1))."""
        x = self.driver_values(columns, drivers)
        if self.domain is not None and not np.all(self.domain.contains(x)):
            return False
        return self.accepts_values is None or bool(self.accepts_values(x))

    def constants(self, columns: _Columns, drivers: tuple[str, ...]) -> dict[str, float]:
        """Constants fixed from the data at fit time (centre and scale of a generic term).

        Parameters
        ----------
        columns : mapping of str to array
            The data's columns.
        drivers : tuple of str
            The driver columns.

        Returns
        -------
        dict
            Constant name -> value [unit of the driver]; empty for most named effects.
        """
        if self.make_constants is None:
            return {}
        return self.make_constants(self.driver_values(columns, drivers))

    def initial(self, mu: np.ndarray, columns: _Columns, drivers: tuple[str, ...],
                constants: Mapping[str, float]) -> list[float]:
        """Initial guesses of the parameters from the data's scale.

        Parameters
        ----------
        mu : numpy.ndarray
            μ of the model without the effect. [1]
        columns : mapping of str to array
            The data's columns.
        drivers : tuple of str
            The driver columns.
        constants : mapping
            From :meth:`constants`.

        Returns
        -------
        list of float
            One value per parameter, inside its bounds.
        """
        x = self.driver_values(columns, drivers)
        return list(self.make_initial(np.asarray(mu, dtype=float), x, columns, constants))

    def apply(self, mu, columns: _Columns, params: Mapping[str, float],
              drivers: tuple[str, ...] | None = None, constants: Mapping[str, float] | None = None):
        """μ corrected by this effect.

        Parameters
        ----------
        mu : array_like
            μ of the model. [1]
        columns : mapping of str to array_like
            Driver columns and the physics inputs the formula uses (``balls`` [1], ``load_N`` [N]),
            broadcasting with ``mu``.
        params : mapping of str to float
            Every parameter of :attr:`parameters`, in its unit.
        drivers : tuple of str, optional
            The driver columns; default :attr:`fixed_drivers` (required for the others).
        constants : mapping, optional
            From :meth:`constants` at fit time; required by the generic family.

        Returns
        -------
        numpy.ndarray
            Corrected μ. [1]

        Raises
        ------
        ValueError
            For a missing parameter, driver or constant, or driver values outside the effect's domain.
        """
        drivers = tuple(drivers or self.fixed_drivers)
        if not drivers:
            raise ValueError(f"effect {self.name} needs its driver column(s) in drivers")
        missing = [n for n in self.parameter_names if n not in params]
        if missing:
            raise ValueError(f"effect {self.name} needs parameter(s) {', '.join(missing)}")
        absent = [d for d in drivers if d not in columns]
        if absent:
            raise ValueError(f"effect {self.name} needs column(s) {', '.join(absent)}")
        if not self.accepts(columns, drivers):
            raise ValueError(f"{drivers[0]} is outside the domain of effect {self.name}: "
                             f"{self.driver_description}")
        values = [float(params[n]) for n in self.parameter_names]
        x = self.driver_values(columns, drivers)
        return self.correct(np.asarray(mu, dtype=float), x, columns, values, dict(constants or {}))


def _sign(x: float) -> int:
    return (x > 0) - (x < 0)


def _additive_initial(basis: Callable) -> Callable:
    # Start the added term at a tenth of the median μ: the right order of magnitude for any unit.
    def initial(mu, x, columns, constants):
        b = np.abs(basis(x, columns))
        scale = np.median(b[b > 0]) if np.any(b > 0) else 1.0
        return [0.1 * float(np.median(mu)) / scale]
    return initial


def _meniscus_basis(h, columns):
    # a dry run (h = 0) condenses no meniscus: 1 / ln(1/h) -> 0, the limit taken exactly
    with np.errstate(divide="ignore"):
        return np.asarray(columns["balls"], dtype=float) / (np.asarray(columns["load_N"], dtype=float)
                                                             * np.log(1.0 / np.asarray(h, dtype=float)))


def _viscous_basis(v, columns):
    return v / np.asarray(columns["load_N"], dtype=float)


def _constant_basis(g, columns):
    return 1.0 / g


def _centre_scale(x):
    scale = float(np.std(x))
    return {"centre": float(np.mean(x)), "scale": scale if scale > 0 else 1.0}


def _quadratic_log(x, p, c):
    """c1 z + c2 z^2, z = (x - centre) / scale, z^2 going on along its tangent beyond the data's [low, high]
    (a stored term without them: not), as a natural spline beyond its end knots: exp(c2 z^2) at z = 11 (30 mN
    beyond loads of 2-10 mN) put mu 13x off the truth."""
    z = (x - c["centre"]) / c["scale"]
    at = np.clip(z, (c.get("low", -np.inf) - c["centre"]) / c["scale"], (c.get("high", np.inf) - c["centre"])
                 / c["scale"])
    return p[0] * z + p[1] * at * (2.0 * z - at)


def _median_reference(x):
    return {"reference": float(np.median(x))}


def _zeros(mu, x, columns, constants):
    return [0.0]


_MENISCUS = Effect(
    name="humidity_meniscus",
    title="Capillary menisci condensed around the contacts, growing with relative humidity",
    formula="mu = mu_model + balls * meniscus_force_N / (load_N * ln(1/h))",
    parameters=(EffectParameter(
        "meniscus_force_N", "N",
        "Friction force per ball due to the menisci when ln(1/h) = 1 (h = 37 %).", 0.0, 1.0),),
    driver_description="relative humidity h, a fraction in [0, 1) (percent if the name says pct; a dry run, "
                       "h = 0, adds nothing: 1/ln(1/h) -> 0)",
    reference=("L. Bocquet, E. Charlaix, S. Ciliberto, J. Crassous, Nature 396, 735-737 (1998): "
               "capillary condensation makes friction and cohesion grow as 1/ln(1/h) (Kelvin radius)."),
    driver_keywords=HUMIDITY.keywords,
    correct=lambda mu, x, columns, p, c: mu + p[0] * _meniscus_basis(x, columns),
    make_initial=_additive_initial(_meniscus_basis),
    driver_transform=humidity_fraction,
    domain=Domain(0.0, 1.0, high_open=True),
    enters="add", direction=lambda v: _sign(v[0]),  # + p z / (G ln(1/h)): 1/ln(1/h) grows on (0, 1)
    value_forms=("scale",),
)

_VISCOUS = Effect(
    name="viscous_drag",
    title="Viscous (Couette) drag of the liquid film or air gap under the slider, linear in speed",
    formula="mu = mu_model + drag_coefficient_N_s_m * speed_m_s / load_N",
    parameters=(EffectParameter(
        "drag_coefficient_N_s_m", "N*s/m",
        "Drag force per unit slider speed, eta A / h of a film of viscosity eta, area A, gap h.",
        0.0, 1e3),),
    driver_description="slider speed speed_m_s [m/s] (the drag force is divided by load_N [N])",
    reference="Newton's law of viscosity for a Couette film, F = eta A V / h "
              "(B.J. Hamrock, Fundamentals of Fluid Film Lubrication, 1994, ch. 4).",
    fixed_drivers=("speed_m_s", "load_N"),
    correct=lambda mu, x, columns, p, c: mu + p[0] * _viscous_basis(x, columns),
    make_initial=_additive_initial(_viscous_basis),
    enters="add", direction=lambda v: _sign(v[0]), value_forms=("scale",),  # + p V / G
)

_CONSTANT = Effect(
    name="constant_drag",
    title="Load-independent drag force on the slider (electrostatic attraction, cable or seal drag)",
    formula="mu = mu_model + drag_force_N / load_N",
    parameters=(EffectParameter("drag_force_N", "N",
                                "Tangential drag force independent of load and speed.", 0.0, 1e3),),
    driver_description="load load_N [N]",
    reference="A constant parasitic force F0 adds F0/G to mu; electrostatic drag in MEMS sliders: "
              "W.C. Tang, T.H. Nguyen, R.T. Howe, Sensors and Actuators 20, 25-32 (1989).",
    fixed_drivers=("load_N",),
    correct=lambda mu, x, columns, p, c: mu + p[0] / x,
    make_initial=_additive_initial(_constant_basis),
    enters="add", direction=lambda v: -_sign(v[0]), value_forms=("scale",),  # + p / G
)

_THERMAL = Effect(
    name="thermal_shear_strength",
    title="Thermally activated interfacial shear strength: friction falls as temperature rises",
    formula="mu = mu_model * exp(-thermal_coefficient_1_K * (T - T_reference))",
    parameters=(EffectParameter(
        "thermal_coefficient_1_K", "1/K",
        "Relative decrease of the shear strength per kelvin (Eyring activation).", -1.0, 1.0,
        # Never negative where named: a shear strength rising with temperature is no Eyring activation
        plausible=(0.0, 1.0)),),
    driver_description="temperature T in degC or K (only differences matter); T_reference = median",
    reference="B.J. Briscoe, D.C.B. Evans, Proc. R. Soc. A 380, 389-407 (1982): the interfacial "
              "shear strength of molecular films falls exponentially with temperature.",
    driver_keywords=TEMPERATURE.keywords,
    correct=lambda mu, x, columns, p, c: mu * np.exp(-p[0] * (x - c["reference"])),
    make_constants=_median_reference,
    make_initial=_zeros,
    enters="mul", direction=lambda v: -_sign(v[0]), value_forms=("log",),  # x exp(-p (T - T0))
)

_RUN_IN = Effect(
    name="run_in",
    title="Running-in: friction decays from its initial value as the contacts smooth and transfer films form",
    formula="mu = mu_model * (1 + run_in_amplitude * exp(-n / run_in_length))",
    parameters=(
        # Never negative: friction rising with the count is no run-in (measurement_drift may take it)
        EffectParameter("run_in_amplitude", "1", "Initial excess friction relative to the steady state.",
                        0.0, 100.0, plausible=(0.0, 10.0)),
        EffectParameter("run_in_length", "driver",
                        "Decay length of the excess, in the unit of the run/cycle column.", 0.0, np.inf,
                        within_data=True),
    ),
    driver_description="run, cycle, stroke or time count n >= 0 since the start",
    reference="P.J. Blau, Tribology International 38, 1007-1012 (2005), 'On the nature of running-in'.",
    driver_keywords=("run", "cycle", "pass", "stroke", "count", "time", "distance"),
    correct=lambda mu, x, columns, p, c: mu * (1.0 + p[0] * np.exp(-x / p[1])),
    make_initial=lambda mu, x, columns, c: [0.3, 0.2 * float(np.max(x))],
    domain=Domain(0.0),
    # x (1 + a exp(-n / L)), a > -1, L > 0: falls with n where a > 0
    enters="mul", direction=lambda v: -_sign(v[0]), value_forms=(None, None),
)

#: Name words of an order or clock column: the measurement's place in the session, not the bearing's wear.
SESSION_KEYWORDS = ("index", "order", "sequence", "seq", "time", "date", "hour", "elapsed", "session",
                    "clock")

_MEASUREMENT_DRIFT = Effect(
    name="measurement_drift",
    title="Measurement drift: the instrument's reading drifts over the session (gauge drift), not the "
          "bearing",
    formula="mu = mu_model * exp(session_drift_log * (x - x_start) / (x_end - x_start))",
    parameters=(EffectParameter(
        "session_drift_log", "1",
        "Log of the reading's factor at the session's end over its start (0.073: +7.6 %); the reading is "
        "taken as true at the start.", -1.0, 1.0),),
    driver_description="measurement order (run_index) or time (hours, or ISO 8601 dates) over the session; "
                       "x_start and x_end its first and last value in the data",
    reference="Gauge drift (stability) of a measurement system: AIAG, Measurement Systems Analysis, 4th ed., "
              "2010, ch. I; a linear drift of the tribometer's force reading over the session.",
    driver_keywords=SESSION_KEYWORDS, min_levels=3,  # start < end over the data
    correct=lambda mu, x, columns, p, c: mu * np.exp(p[0] * (x - c["start"]) / (c["end"] - c["start"])),
    make_constants=lambda x: {"start": float(np.min(x)), "end": float(np.max(x))},
    make_initial=_zeros,
    enters="mul", direction=lambda v: _sign(v[0]), value_forms=("log",),  # x exp(d s), s rises with x
    named_form_of="generic_linear",  # exp(c (x - centre) / scale), the reading true at the centre
    identity_at=lambda c: c["start"],  # the reading is taken as true at the session's start
)

_MEASUREMENT_STEP = Effect(
    name="measurement_step",
    title="Measurement step: the instrument's reading steps once during the session (a recalibrated load "
          "cell, a changed sensor), not the bearing",
    formula="mu = mu_model * exp(step_log * [x >= x_step])",
    parameters=(EffectParameter(
        "step_log", "1",
        "Log of the reading's factor after the step over before (0.058: +6 %); the reading is taken as "
        "true before the step.", -1.0, 1.0),),
    driver_description="measurement order (run_index) or time (hours, or ISO 8601 dates) over the session; "
                       "x_step, the step's place, searched over the gaps between its values (midpoints; "
                       "before and after: the values either side)",
    reference="A shift of a measurement system's bias (AIAG, Measurement Systems Analysis, 4th ed., 2010, "
              "ch. I); its place by the least-squares change-point search of D.V. Hinkley, Biometrika 57, "
              "1-17 (1970), charged as a fitted value.",
    driver_keywords=SESSION_KEYWORDS, min_levels=3,
    correct=lambda mu, x, columns, p, c: mu * np.exp(p[0] * (x >= c["step"])),
    make_initial=_zeros,
    enters="mul", direction=lambda v: _sign(v[0]), value_forms=("log",),  # x exp(s [x >= x_step])
    searched=("step",), search_constants=step_places,
    identity_at=lambda c: c["before"],  # the reading before the step is taken as true
)

_C_BOUNDS = (-20.0, 20.0)
_GENERIC_LINEAR = Effect(
    name="generic_linear",
    title="Generic log-linear term in one column",
    formula="mu = mu_model * exp(c1 * z), z = (x - centre) / scale",
    parameters=(EffectParameter("c1", "1", "Slope of log mu per standard deviation of x.", *_C_BOUNDS),),
    driver_description="any numeric column x; centre and scale are its mean and standard deviation",
    reference="Low-order polynomial in log mu: the generic fallback when no named effect fits.",
    generic=True,
    min_levels=2,
    correct=lambda mu, x, columns, p, c: mu * np.exp(p[0] * (x - c["centre"]) / c["scale"]),
    make_constants=_centre_scale,
    make_initial=_zeros,
    enters="mul", direction=lambda v: _sign(v[0]), value_forms=("log",),  # x exp(c z), scale > 0
)

_GENERIC_QUADRATIC = Effect(
    name="generic_quadratic",
    title="Generic log-quadratic term in one column",
    formula="mu = mu_model * exp(c1 * z + c2 * z^2), z = (x - centre) / scale; z^2 continued along its "
            "tangent beyond the data's range [low, high]",
    parameters=(
        EffectParameter("c1", "1", "Linear coefficient of log mu in z.", *_C_BOUNDS),
        EffectParameter("c2", "1", "Quadratic coefficient of log mu in z.", *_C_BOUNDS),
    ),
    driver_description="any numeric column x; centre and scale are its mean and standard deviation, low and "
                       "high its least and largest value",
    reference="Low-order polynomial in log mu: the generic fallback when no named effect fits; linear beyond "
              "the data as a natural spline (Hastie et al., Elements of Statistical Learning, sec. 5.2.1).",
    generic=True,
    correct=lambda mu, x, columns, p, c: mu * np.exp(_quadratic_log(x, p, c)),
    make_constants=lambda x: {**_centre_scale(x), "low": float(np.min(x)), "high": float(np.max(x))},
    make_initial=lambda mu, x, columns, c: [0.0, 0.0],
    # x exp(c1 z + c2 z^2): extreme over an interval at an end or where z = -c1 / (2 c2) (a value it takes)
    enters="mul", monotone=False, stationary=lambda v, c: (
        None if v[1] == 0 else c["centre"] - v[0] * c["scale"] / (2.0 * v[1])),
    value_forms=("log", "log_square"),
)

_GENERIC_POWER = Effect(
    name="generic_power",
    title="Generic power law in one positive column",
    formula="mu = mu_model * (x / reference)^c1",
    parameters=(EffectParameter("c1", "1", "Exponent of the power law.", *_C_BOUNDS),),
    driver_description="any numeric column x > 0; reference is its median",
    reference="Power (log-log linear) term: the generic fallback when no named effect fits.",
    generic=True,
    correct=lambda mu, x, columns, p, c: mu * np.power(x / c["reference"], p[0]),
    make_constants=_median_reference,
    make_initial=_zeros,
    domain=Domain(0.0, low_open=True),
    enters="mul", direction=lambda v: _sign(v[0]), value_forms=("log",),  # x (x / reference)^c, x > 0
)

def _positive_speed_reference(v):
    moving = v[v > 0]
    return {"reference": float(np.median(moving)) if moving.size else 1.0}


_BREAKAWAY = Effect(
    name="stribeck_breakaway",
    title="Low-speed breakaway (Stribeck) rise: static friction in excess of the rolling model, decaying "
          "with speed",
    formula="mu = mu_model + breakaway_excess * exp(-speed_m_s / breakaway_speed_m_s)",
    parameters=(
        EffectParameter("breakaway_excess", "1", "Excess friction coefficient at rest (breakaway).", 0.0,
                        10.0, plausible=(0.0, 1.0)),
        EffectParameter("breakaway_speed_m_s", "m/s", "Stribeck speed over which the excess decays by 1/e.",
                        1e-9, 1e3, within_data=True),
    ),
    driver_description="slider speed speed_m_s [m/s], at least three distinct values",
    reference=("R. Stribeck, Z. VDI 46, 1341-1348 (1902); the exponential form of B. Armstrong-Helouvry, "
               "P. Dupont, C. Canudas de Wit, Automatica 30(7), 1083-1138 (1994)."),
    fixed_drivers=("speed_m_s",),
    correct=lambda mu, x, columns, p, c: mu + p[0] * np.exp(-x / p[1]),
    make_initial=lambda mu, x, columns, c: [0.3 * float(np.median(mu)), max(0.2 * float(np.max(x)), 1e-6)],
    enters="add", direction=lambda v: -_sign(v[0]), value_forms=("scale", None),  # + a exp(-V / V0)
)

_STRIBECK_RISE = Effect(
    name="stribeck_rise",
    title="Low-speed (Stribeck) rise of the friction coefficient itself: the model's friction multiplied by "
          "a factor decaying with speed (a boundary film's friction rising towards rest)",
    formula="mu = mu_model * (1 + rise_ratio * exp(-speed_m_s / rise_speed_m_s))",
    parameters=(
        EffectParameter("rise_ratio", "1", "Static over kinetic friction minus 1: the relative rise at rest.",
                        0.0, 100.0, plausible=(0.0, 10.0)),
        EffectParameter("rise_speed_m_s", "m/s", "Stribeck speed over which the rise decays by 1/e.",
                        1e-9, 1e3, within_data=True),
    ),
    driver_description="slider speed speed_m_s [m/s], at least three distinct values",
    reference=("B. Armstrong-Helouvry, P. Dupont, C. Canudas de Wit, Automatica 30(7), 1083-1138 (1994): "
               "F = F_C + (F_S - F_C) exp(-(v / v_S)^2) with a static force F_S a multiple of the Coulomb "
               "force F_C; exponent 1 here, as stribeck_breakaway. The multiplicative form of that law: the "
               "rise scales with the friction it raises (with load and ball count), where "
               "stribeck_breakaway adds a fixed excess."),
    fixed_drivers=("speed_m_s",),
    correct=lambda mu, x, columns, p, c: mu * (1.0 + p[0] * np.exp(-x / p[1])),
    make_initial=lambda mu, x, columns, c: [0.3, max(0.2 * float(np.max(x)), 1e-6)],
    # x (1 + a exp(-V / V0)), a >= 0: falls with speed; no closed form in a (the run-in's form)
    enters="mul", direction=lambda v: -_sign(v[0]), value_forms=(None, None),
)

_VISCOUS_POWER = Effect(
    name="viscous_power_law",
    title="Viscous drag growing as a power of speed (film thickness and shear of an elastohydrodynamic "
          "or squeezed film)",
    formula="mu = mu_model + drag_force_N * (speed_m_s / reference)^speed_exponent / load_N",
    parameters=(
        EffectParameter("drag_force_N", "N", "Drag force at the reference speed (the data's median "
                        "non-zero speed).", 0.0, 1e3),
        EffectParameter("speed_exponent", "1", "Exponent of speed: 1 for Couette drag, about 0.67 for an "
                        "elastohydrodynamic film; at least 0.3, below which it would pose as a "
                        "constant drag.",
                        0.3, 3.0),
    ),
    driver_description="slider speed speed_m_s [m/s] >= 0, not all zero (the force is divided by load_N [N])",
    reference=("B.J. Hamrock, D. Dowson, ASME J. Lubr. Technol. 99, 264-276 (1977): film thickness, and "
               "with it viscous rolling resistance, grows as a power (about 0.67) of speed."),
    fixed_drivers=("speed_m_s", "load_N"),
    correct=lambda mu, x, columns, p, c: mu + p[0] * np.power(x / c["reference"], p[1])
    / np.asarray(columns["load_N"], dtype=float),
    make_constants=_positive_speed_reference,
    make_initial=lambda mu, x, columns, c: [0.1 * float(np.median(mu * np.asarray(columns["load_N"]))), 1.0],
    domain=Domain(0.0),
    # + p (V / V0)^e / G, e >= 0.3
    enters="add", direction=lambda v: _sign(v[0]), value_forms=("scale", None),
)

#: Every optional effect, keyed by name: named physical effects first, then the generic family.
EFFECTS: dict[str, Effect] = {}


def register_effect(effect: Effect) -> None:
    """Add an effect to :data:`EFFECTS` (a named one before the generic family), its declarations checked.

    Calibration tries every registered effect on the columns its driver keywords name; the bounds and
    robust designs of :mod:`optimize` read what it declares (:attr:`Effect.enters`, ``monotone``,
    ``direction``, ``stationary``, ``value_forms``), so an effect that declares nothing is fitted and
    predicted but never certified over a box.

    Parameters
    ----------
    effect : Effect
        The effect, with a new name.

    Raises
    ------
    ValueError
        For a name already taken or declarations that do not fit its parameters.
    """
    if effect.name in EFFECTS:
        raise ValueError(f"an effect named {effect.name!r} is registered already")
    if effect.enters not in (None, "add", "mul"):
        raise ValueError(f"effect {effect.name}: enters must be 'add', 'mul' or None; got {effect.enters!r}")
    if effect.value_forms and len(effect.value_forms) != len(effect.parameters):
        raise ValueError(f"effect {effect.name}: one value form per parameter ({len(effect.parameters)})")
    unknown = [f for f in effect.value_forms if f is not None and f not in VALUE_FORMS]
    if unknown:
        raise ValueError(f"effect {effect.name}: value forms are {', '.join(VALUE_FORMS)} or None; "
                         f"got {unknown[0]!r}")
    if bool(effect.searched) != (effect.search_constants is not None):
        raise ValueError(f"effect {effect.name}: searched constants need search_constants, and only they")
    if not effect.monotone and effect.stationary is None:
        raise ValueError(f"effect {effect.name}: a term that is not monotone declares its stationary point")
    named = [e for e in EFFECTS.values() if not e.generic]
    generic = [e for e in EFFECTS.values() if e.generic]
    (generic if effect.generic else named).append(effect)
    EFFECTS.clear()
    EFFECTS.update((e.name, e) for e in [*named, *generic])


for _effect in (_MENISCUS, _VISCOUS, _CONSTANT, _THERMAL, _RUN_IN, _BREAKAWAY, _STRIBECK_RISE,
                _VISCOUS_POWER,
                _MEASUREMENT_DRIFT, _MEASUREMENT_STEP, _GENERIC_LINEAR, _GENERIC_QUADRATIC, _GENERIC_POWER):
    register_effect(_effect)


def apply_effect(mu, name: str, columns: _Columns, params: Mapping[str, float],
                 drivers: tuple[str, ...] | None = None,
                 constants: Mapping[str, float] | None = None) -> np.ndarray:
    """μ of the model corrected by the effect ``name`` of :data:`EFFECTS`.

    Parameters
    ----------
    mu : array_like
        μ of the model, e.g. ``physics.evaluate(...).mu``. [1]
    name : str
        Key of :data:`EFFECTS`.
    columns : mapping of str to array_like
        Driver columns and the physics inputs the formula uses.
    params : mapping of str to float
        The effect's parameters in their units.
    drivers : tuple of str, optional
        Driver columns (default: the effect's fixed drivers).
    constants : mapping, optional
        Constants fixed at fit time (generic family).

    Returns
    -------
    numpy.ndarray
        Corrected μ. [1]

    Raises
    ------
    ValueError
        For an unknown effect or invalid inputs (see :meth:`Effect.apply`).
    """
    if name not in EFFECTS:
        raise ValueError(f"effect must be one of {', '.join(EFFECTS)}; got {name!r}")
    return EFFECTS[name].apply(mu, columns, params, drivers, constants)
