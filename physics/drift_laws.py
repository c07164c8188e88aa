"""Laws by which a declared physics parameter drifts with a condition column (:data:`DRIFT_LAWS`):
linear in the condition, Arrhenius in the temperature, Kelvin-type in the relative humidity.
:mod:`physics.effects` re-exports them beside the effects."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from .drivers import HUMIDITY, TEMPERATURE, Domain, humidity_fraction, name_matches, temperature_kelvin
from .effect_parameter import EffectParameter

__all__ = ["DRIFT_LAWS", "GAS_CONSTANT_J_MOL_K", "DriftLaw"]


#: Universal gas constant [J/(mol K)].
GAS_CONSTANT_J_MOL_K = 8.314462618
# Range of a linear drift's factor p(x) / p_ref over the data. [1]
_DRIFT_FACTOR_MIN, _DRIFT_FACTOR_MAX = 0.1, 10.0


def _kelvin_radius_term(h):
    # a dry run (h = 0) has no Kelvin radius: 1 / ln(1/h) -> 0, the limit taken exactly (as the menisci's)
    with np.errstate(divide="ignore"):
        return 1.0 / np.log(1.0 / np.asarray(h, dtype=float))


@dataclass(frozen=True)
class DriftLaw:
    """How a declared physics parameter p varies with a condition column x: p(x) = p_ref * factor(x).

    ``p_ref`` is the parameter's value in the declared model (fitted or fixed) and ``factor`` is 1 at
    the reference condition ``x_ref`` (the data's median), so the law adds only its coefficient.

    Attributes
    ----------
    name : str
        Key in :data:`DRIFT_LAWS`.
    title : str
        The law in words.
    formula : str
        ``p(x) = p_ref * ...``.
    coefficient : EffectParameter
        The fitted coefficient (bounds narrowed by :meth:`bounds`).
    driver_keywords : tuple of str
        Prefixes of a condition column's name that the law applies to; empty for any column.
    driver_description : str
        Which column drives it and in what unit.
    reference : str
        Where the law comes from.
    min_levels : int
        Fewest distinct values the driver must take. [1]
    variable : callable
        ``variable(name, values)``: the driver as the law's variable (kelvin, 1/ln(1/h), or as given).
    shape : str
        ``"linear"``: factor = 1 + c (v - v_ref), kept within [0.1, 10] over the data by :meth:`bounds`;
        ``"arrhenius"``: factor = exp(c / R (1/v - 1/v_ref)).
    positive_variable : bool
        Whether the law's variable must be > 0 (absolute temperature).
    domain : Domain or None
        The driver's values the law holds for, in the unit ``driver_transform`` gives (None: any);
        :meth:`column_domain` gives it in a column's unit.
    driver_transform : callable or None
        ``driver_transform(name, values)``: the driver in the unit of :attr:`domain` (humidity percent to a
        fraction, degC to K; increasing and affine), None: as given.
    """

    name: str
    title: str
    formula: str
    coefficient: EffectParameter
    driver_keywords: tuple[str, ...]
    driver_description: str
    reference: str
    min_levels: int
    variable: Callable = field(repr=False, compare=False)
    shape: str = "linear"
    positive_variable: bool = False
    domain: Domain | None = None
    driver_transform: Callable | None = field(default=None, repr=False, compare=False)

    def matches(self, name: str) -> bool:
        """Whether a condition column of this name may drive the law (:attr:`driver_keywords`)."""
        return not self.driver_keywords or name_matches(name, self.driver_keywords)

    def column_domain(self, name: str) -> Domain | None:
        """:attr:`domain` in the unit of the driver column ``name`` (degC: T > -273.15)."""
        if self.domain is None or self.driver_transform is None:
            return self.domain
        return self.domain.in_unit(lambda x: self.driver_transform(name, x))

    def accepts(self, name: str, values) -> bool:
        """Whether the column's values lie in the law's domain (humidity in [0, 1), T > 0 K)."""
        domain = self.column_domain(name)
        if domain is not None and not np.all(domain.contains(values)):
            return False
        with np.errstate(divide="ignore", invalid="ignore"):
            v = self.variable(name, values)
        return bool(np.all(np.isfinite(v)) and (not self.positive_variable or np.all(v > 0)))

    def constants(self, name: str, values) -> dict[str, float]:
        """``reference``, ``minimum``, ``maximum`` of the law's variable over the data [its unit]."""
        v = self.variable(name, values)
        return {"reference": float(np.median(v)), "minimum": float(np.min(v)), "maximum": float(np.max(v))}

    def bounds(self, constants: Mapping[str, float]) -> tuple[float, float]:
        """Bounds of the coefficient: a linear factor stays within [0.1, 10] over the data's range.

        A parameter that would have to change more than tenfold across the data is not drifting: some
        other mechanism is at work, and the bound keeps the law from posing as it.
        """
        lo, hi = self.coefficient.minimum, self.coefficient.maximum
        if self.shape == "linear":
            ref, v_min, v_max = constants["reference"], constants["minimum"], constants["maximum"]
            if v_max > ref:
                lo, hi = max(lo, (_DRIFT_FACTOR_MIN - 1) / (v_max - ref)), min(hi, (_DRIFT_FACTOR_MAX - 1)
                                                                              / (v_max - ref))
            if ref > v_min:
                lo, hi = max(lo, (1 - _DRIFT_FACTOR_MAX) / (ref - v_min)), min(hi, (1 - _DRIFT_FACTOR_MIN)
                                                                              / (ref - v_min))
        return lo, hi

    def factor(self, name: str, values, coefficient: float, constants: Mapping[str, float]) -> np.ndarray:
        """p(x) / p_ref at the column's values.

        Parameters
        ----------
        name : str
            Driver column name (fixes its unit).
        values : array_like
            Driver values, in the column's unit.
        coefficient : float
            The law's coefficient, in :attr:`coefficient`'s unit.
        constants : mapping
            From :meth:`constants` at fit time.

        Returns
        -------
        numpy.ndarray
            Factor, 1 at the reference condition. [1]

        Examples
        --------
        >>> law = DRIFT_LAWS["arrhenius"]
        >>> c = law.constants("temperature_C", [20.0, 25.0, 30.0])
        >>> round(float(law.factor("temperature_C", 35.0, 16e3, c)), 4)  # exp(16e3/R (1/308.15 - 1/298.15))
        0.811
        """
        v = self.variable(name, values)
        if self.shape == "arrhenius":
            return np.exp(coefficient / GAS_CONSTANT_J_MOL_K * (1.0 / v - 1.0 / constants["reference"]))
        return 1.0 + coefficient * (v - constants["reference"])


#: Laws by which a declared parameter may drift with a condition column.
DRIFT_LAWS: dict[str, DriftLaw] = {law.name: law for law in [
    DriftLaw(
        name="linear", title="Linear in the condition",
        formula="p(x) = p_ref * (1 + slope * (x - x_ref))",
        coefficient=EffectParameter("slope", "1/driver", "Relative change of the parameter per unit of x.",
                                    -np.inf, np.inf),
        driver_keywords=(), driver_description="any condition column x; x_ref = its median",
        reference="First-order (Taylor) dependence on a condition, e.g. a coating flag (0/1) or a "
                  "coating thickness changing a friction coefficient.",
        min_levels=2, variable=lambda name, x: np.asarray(x, dtype=float)),
    DriftLaw(
        name="arrhenius", title="Arrhenius (thermally activated) in temperature",
        formula="p(T) = p_ref * exp(activation_energy / R * (1/T - 1/T_ref)), T in K",
        coefficient=EffectParameter(
            "activation_energy_J_mol", "J/mol",
            "Activation energy; > 0 when the parameter falls as temperature rises (viscosity).", -2e5, 2e5),
        driver_keywords=TEMPERATURE.keywords,
        driver_description="temperature, degC (or K if the name says K); T_ref = median",
        reference="Andrade-Eyring law of liquid viscosity, eta = A exp(E_a / (R T)) (E.N. da C. Andrade, "
                  "Nature 125, 309-310 (1930)); 16-17 kJ/mol for water near 25 degC.",
        min_levels=3, variable=temperature_kelvin, shape="arrhenius", positive_variable=True,
        domain=Domain(0.0, low_open=True), driver_transform=temperature_kelvin),
    DriftLaw(
        name="kelvin", title="Kelvin-type in relative humidity: proportional to the Kelvin radius",
        formula="p(h) = p_ref * (1 + kelvin_coefficient * (1/ln(1/h) - 1/ln(1/h_ref)))",
        coefficient=EffectParameter(
            "kelvin_coefficient", "1",
            "Relative change of the parameter per unit of 1/ln(1/h) (the Kelvin radius over its value "
            "at h = 1/e).", -np.inf, np.inf),
        driver_keywords=HUMIDITY.keywords,
        driver_description="relative humidity h in [0, 1) (percent if the name says pct; a dry run, h = 0, "
                           "is the limit 1/ln(1/h) -> 0); h_ref = median",
        reference="Kelvin equation, r_K = gamma V_m / (R T ln(1/h)): capillary adhesion grows with the "
                  "meniscus radius (J.N. Israelachvili, Intermolecular and Surface Forces, 3rd ed., 2011, "
                  "ch. 17).",
        min_levels=3, variable=lambda name, x: _kelvin_radius_term(humidity_fraction(name, x)),
        domain=Domain(0.0, 1.0, high_open=True), driver_transform=humidity_fraction),
]}

