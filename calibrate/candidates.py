"""Step 2 of the pipeline: the terms a calibration may add, and :func:`mu_of`, a model with them.

A **term** is one candidate explanation of what the declared model misses:

* an :class:`EffectTerm`, an effect of :data:`physics.effects.EFFECTS` (a named
  correction of μ such as ``humidity_meniscus`` or ``stribeck_breakaway``, or a
  generic low-order term) bound to its driver columns;
* a :class:`DriftTerm`, a declared physics parameter that drifts with a
  condition column by a law of :data:`physics.effects.DRIFT_LAWS` (linear,
  Arrhenius in temperature, Kelvin-type in humidity). It acts through
  :func:`physics.evaluate`, so a viscosity that falls with temperature moves
  only the terms of μ that depend on viscosity.

:func:`candidate_terms` proposes every term that fits the data's columns;
:func:`mu_of` evaluates declared values plus terms (drifts change the inputs of
the physics, effects then correct its μ, in order). Screening uses a frozen
base (:class:`FrozenBase`): μ of the current model and its sensitivity to each
drifting parameter, so that a drift is screened by its first-order effect on
log μ without re-running the physics.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from microbearing import physics
from microbearing.physics.columns import driver_unit
from microbearing.physics.effects import (
    DRIFT_LAWS,
    DRIFT_PARAMETERS,
    EFFECTS,
    SESSION_KEYWORDS,
    DriftLaw,
    Effect,
)

from .data import Dataset

__all__ = [
    "LEVEL_RANGE",
    "DriftTerm",
    "EffectTerm",
    "FrozenBase",
    "Term",
    "candidate_terms",
    "drifted_inputs",
    "mu_of",
    "place_profile",
    "placed_on",
    "term_from_json",
]


#: A drift's fitted level stays within this factor of the parameter's default, either way. [1]
LEVEL_RANGE = 1e3


@dataclass(frozen=True)
class EffectTerm:
    """An effect of :data:`physics.effects.EFFECTS` bound to its driver columns.

    Attributes
    ----------
    name : str
        Effect name.
    drivers : tuple of str
        Driving columns, main driver first.
    constants : dict
        Constants fixed from the whole data set (centre and scale of a generic term, a reference).
    """

    name: str
    drivers: tuple[str, ...]
    constants: dict[str, float] = field(default_factory=dict)

    kind = "effect"

    @property
    def effect(self) -> Effect:
        """The :class:`physics.effects.Effect`."""
        return EFFECTS[self.name]

    @property
    def label(self) -> str:
        """The term in a few words, e.g. ``humidity_meniscus on relative_humidity``, with its searched
        constants (``measurement_step on run_index at step 59.5``)."""
        at = "".join(f" at {n} {self.constants[n]:.6g}" for n in self.searched if n in self.constants)
        return f"{self.name} on {', '.join(self.drivers)}{at}"

    @property
    def searched(self) -> tuple[str, ...]:
        """Constants the selection chose by search (a step's place): each counts as a fitted value."""
        return self.effect.searched

    @property
    def generic(self) -> bool:
        """Whether it is a generic fallback term rather than a named mechanism."""
        return self.effect.generic

    @property
    def identity_value(self) -> float | None:
        """Where a term of the measurement system is the identity in its driver
        (:attr:`physics.effects.Effect.identity_at`); None for a term of the bearing."""
        at = self.effect.identity_at
        return None if at is None else float(at(self.constants))

    @property
    def parameter_names(self) -> list[str]:
        """Names of the fitted parameters, with their units."""
        return self.effect.parameter_names

    @property
    def units(self) -> dict[str, str]:
        """Unit of each fitted parameter, one declared per unit of the driver in the driver's
        (:func:`physics.columns.driver_unit`: ``run_in_length`` on cycles in cycles)."""
        return {p.name: driver_unit(p.unit, self.drivers[0]) for p in self.effect.parameters}

    def bounds(self) -> list[tuple[float, float]]:
        """Bounds of each fitted parameter."""
        return [(p.minimum, p.maximum) for p in self.effect.parameters]

    def initial(self, mu: np.ndarray, columns: Mapping[str, Any]) -> list[float]:
        """Initial values from the data's scale (see :meth:`physics.effects.Effect.initial`)."""
        return self.effect.initial(mu, columns, self.drivers, self.constants)

    def describe(self, values: Sequence[float], std: Sequence[float]) -> dict[str, Any]:
        """JSON-ready description with fitted values and standard deviations."""
        spec = self.effect
        return {
            "kind": self.kind,
            "name": spec.name,
            "label": self.label,
            "title": spec.title,
            "drivers": list(self.drivers),
            "formula": spec.formula,
            "parameters": dict(zip(spec.parameter_names, map(float, values), strict=True)),
            "parameter_std": dict(zip(spec.parameter_names, map(float, std), strict=True)),
            "parameter_units": self.units,
            "constants": dict(self.constants),
            "reference": spec.reference,
        }

    def to_json(self, values: Sequence[float]) -> dict[str, Any]:
        """The term with its fitted values, as stored in a calibrated model."""
        return {
            "kind": self.kind,
            "name": self.name,
            "drivers": list(self.drivers),
            "parameters": dict(zip(self.parameter_names, map(float, values), strict=True)),
            "constants": {k: float(v) for k, v in self.constants.items()},
        }


@dataclass(frozen=True)
class DriftTerm:
    """A declared physics parameter drifting with a condition column by a law of :data:`DRIFT_LAWS`.

    Attributes
    ----------
    parameter : str
        Name in :data:`physics.PARAMETERS`.
    law : str
        Key of :data:`physics.effects.DRIFT_LAWS`.
    driver : str
        Condition column.
    constants : dict
        Reference, minimum and maximum of the law's variable over the data.
    level : bool
        Whether the parameter's level at the reference condition, ``<parameter>_ref`` in its unit, is
        fitted with the law's coefficient: a parameter that is neither fitted nor fixed nor a data
        column would otherwise drift from its default, and the coefficient would bend to make up for
        a wrong level (an activation energy twice its value when the film is ten times more viscous
        than the default).
    """

    parameter: str
    law: str
    driver: str
    constants: dict[str, float] = field(default_factory=dict)
    level: bool = False

    kind = "drift"
    generic = False
    identity_value = None  # a drift moves the bearing: its driver is always read
    searched: tuple[str, ...] = ()

    @property
    def spec(self) -> DriftLaw:
        """The :class:`physics.effects.DriftLaw`."""
        return DRIFT_LAWS[self.law]

    @property
    def name(self) -> str:
        """A name for tables: ``mu_pivot~linear``."""
        return f"{self.parameter}~{self.law}"

    @property
    def drivers(self) -> tuple[str, ...]:
        """The driver column, as a one-element tuple like :attr:`EffectTerm.drivers`."""
        return (self.driver,)

    @property
    def label(self) -> str:
        """The term in a few words, e.g. ``viscosity_Pa_s drifts with temperature_C (arrhenius)``."""
        return f"{self.parameter} drifts with {self.driver} ({self.law})"

    @property
    def level_name(self) -> str:
        """Name of the fitted level, ``<parameter>_ref`` (fitted only when :attr:`level`)."""
        return f"{self.parameter}_ref"

    @property
    def parameter_names(self) -> list[str]:
        """The law's coefficient name, and the level's when it is fitted."""
        return [self.spec.coefficient.name] + ([self.level_name] if self.level else [])

    @property
    def units(self) -> dict[str, str]:
        """Unit of the coefficient (declared ``1/driver``: per unit of the driver column, written in the
        driver's unit, ``1/K`` on a temperature: :func:`physics.columns.driver_unit`) and of the level."""
        units = {self.spec.coefficient.name: driver_unit(self.spec.coefficient.unit, self.driver)}
        if self.level:
            units[self.level_name] = physics.PARAMETERS[self.parameter].unit
        return units

    def bounds(self) -> list[tuple[float, float]]:
        """Bounds of the coefficient (see :meth:`physics.effects.DriftLaw.bounds`) and of the level: within
        :data:`LEVEL_RANGE` of the default either way, inside the parameter's own range."""
        out = [self.spec.bounds(self.constants)]
        if self.level:
            spec = physics.PARAMETERS[self.parameter]
            default = float(spec.default)
            lo, hi = default / LEVEL_RANGE, default * LEVEL_RANGE
            if spec.minimum is not None:
                lo = max(lo, float(spec.minimum))
            if spec.maximum is not None:
                hi = min(hi, float(spec.maximum) * (1 - 1e-9))
            out.append((lo, hi))
        return out

    def initial(self, mu: np.ndarray, columns: Mapping[str, Any]) -> list[float]:
        """No drift to start with (and the level at the parameter's current value)."""
        if not self.level:
            return [0.0]
        current = columns.get(self.parameter, physics.PARAMETERS[self.parameter].default)
        return [0.0, float(np.asarray(current))]

    def factor(self, columns: Mapping[str, Any], coefficient: float) -> np.ndarray:
        """Parameter value over its reference value at each row. [1]"""
        return self.spec.factor(self.driver, columns[self.driver], coefficient, self.constants)

    def describe(self, values: Sequence[float], std: Sequence[float]) -> dict[str, Any]:
        """JSON-ready description with the fitted coefficient and its standard deviation."""
        spec = self.spec
        unit = physics.PARAMETERS[self.parameter].unit
        return {
            "kind": self.kind,
            "name": self.name,
            "label": self.label,
            "title": f"{self.parameter} [{unit}] varies with {self.driver}: {spec.title}",
            "drivers": [self.driver],
            "parameter": self.parameter,
            "law": self.law,
            "formula": spec.formula.replace("p(", f"{self.parameter}(").replace(
                "p_ref", f"{self.parameter}_ref"
            ),
            "parameters": dict(zip(self.parameter_names, map(float, values), strict=True)),
            "parameter_std": dict(zip(self.parameter_names, map(float, std), strict=True)),
            "parameter_units": self.units,
            "constants": dict(self.constants),
            "reference": f"{DRIFT_PARAMETERS[self.parameter]}; {spec.reference}",
            "level_fitted": self.level,
        }

    def to_json(self, values: Sequence[float]) -> dict[str, Any]:
        """The term with its fitted coefficient (and level), as stored in a calibrated model."""
        return {
            "kind": self.kind,
            "parameter": self.parameter,
            "law": self.law,
            "driver": self.driver,
            "parameters": dict(zip(self.parameter_names, map(float, values), strict=True)),
            "constants": {k: float(v) for k, v in self.constants.items()},
            **({"level": True} if self.level else {}),
        }


Term = EffectTerm | DriftTerm


def term_from_json(data: Mapping[str, Any]) -> tuple[Term, list[float]]:
    """A term and its values from :meth:`EffectTerm.to_json` or :meth:`DriftTerm.to_json` data.

    Raises
    ------
    ValueError
        For an unknown effect, law or parameter, or missing values.
    """
    constants = {k: float(v) for k, v in dict(data.get("constants", {})).items()}
    values = dict(data.get("parameters", {}))
    if data.get("kind", "effect") == "drift":
        if data.get("law") not in DRIFT_LAWS or data.get("parameter") not in DRIFT_PARAMETERS:
            raise ValueError(
                f"drift term needs a law in {', '.join(DRIFT_LAWS)} and a parameter in "
                f"{', '.join(DRIFT_PARAMETERS)}; got {data.get('law')!r}, {data.get('parameter')!r}"
            )
        if not data.get("driver") or {"reference", "minimum", "maximum"} - set(constants):
            raise ValueError("drift term needs a driver and constants reference, minimum, maximum")
        term: Term = DriftTerm(str(data["parameter"]), str(data["law"]), str(data["driver"]), constants,
                               bool(data.get("level", False)))
    else:
        if data.get("name") not in EFFECTS:
            raise ValueError(f"effect name must be one of {', '.join(EFFECTS)}; got {data.get('name')!r}")
        if not data.get("drivers"):
            raise ValueError(f"effect {data['name']} needs its drivers")
        term = EffectTerm(str(data["name"]), tuple(str(d) for d in data["drivers"]), constants)
    missing = [n for n in term.parameter_names if n not in values]
    if missing:
        raise ValueError(f"{term.label} needs parameter(s) {', '.join(missing)}")
    return term, [float(values[n]) for n in term.parameter_names]


@dataclass(frozen=True)
class FrozenBase:
    """The current model frozen at every row, for screening a new term without re-running the physics.

    Attributes
    ----------
    mu : numpy.ndarray
        μ of the current model. [1]
    sensitivity : dict of str to numpy.ndarray
        ∂ log μ / ∂ log p of the current model for each parameter p that a drift may move or the
        screening may shift. [1]
    declared : tuple of str
        Fitted declared parameters whose relative shifts a screening fit adjusts to first order
        (μ_base · exp(Σ s_p δ_p)), so that a candidate is screened as if the declared parameters were
        refitted with it.
    """

    mu: np.ndarray = field(repr=False)
    sensitivity: dict[str, np.ndarray] = field(repr=False)
    declared: tuple[str, ...] = ()

    def shifted(self, shifts) -> FrozenBase:
        """The base with the declared parameters shifted by relative amounts ``shifts`` (log scale, in
        :attr:`declared` order), to first order."""
        if not self.declared:
            return self
        log_factor = sum(self.sensitivity[n] * d for n, d in zip(self.declared, shifts, strict=True))
        return FrozenBase(self.mu * np.exp(log_factor), self.sensitivity, ())


def _rows(values, rows):
    arr = np.asarray(values)
    return arr if rows is None or arr.ndim == 0 else arr[rows]


def drifted_inputs(
    inputs: Mapping[str, Any],
    conditions: Mapping[str, Any],
    terms: Sequence[Term],
    values: Sequence[Sequence[float]],
) -> dict[str, Any]:
    """Physics inputs with every drift term applied (other terms ignored).

    A law extrapolated past a parameter's physical bound stops at it.
    """
    out = dict(inputs)
    for term, v in zip(terms, values, strict=True):
        if term.kind == "drift":
            spec = physics.PARAMETERS[term.parameter]
            base = np.asarray(v[1] if term.level else out.get(term.parameter, spec.default), dtype=float)
            drifted = base * term.factor(conditions, v[0])
            lo = -np.inf if spec.minimum is None else spec.minimum
            hi = np.inf if spec.maximum is None else spec.maximum
            out[term.parameter] = np.clip(drifted, lo, np.nextafter(hi, lo) if spec.exclusive_maximum else hi)
    return out


def mu_of(
    inputs: Mapping[str, Any],
    conditions: Mapping[str, Any],
    terms: Sequence[Term] = (),
    values: Sequence[Sequence[float]] = (),
    base: FrozenBase | None = None,
    rows=None,
    convention: str = physics.DEFAULT_CONVENTION,
) -> np.ndarray:
    """μ of the physics with declared values and terms.

    Parameters
    ----------
    inputs : mapping
        Physics inputs (fixed values, physics columns and fitted declared values), broadcasting.
    conditions : mapping
        Condition columns the terms read.
    terms : sequence of Term
        Terms applied in order: drifts change the physics inputs, effects then correct μ.
    values : sequence of sequence of float
        Each term's parameter values, in order.
    base : FrozenBase, optional
        Instead of the physics, the frozen current model: drifts act to first order,
        μ_base · factor^sensitivity, effects as usual.
    rows : array of int, optional
        Row indices of ``inputs``, ``conditions`` and ``base`` to evaluate (default all).
    convention : str
        See :data:`physics.CONVENTIONS`.

    Returns
    -------
    numpy.ndarray
        μ. [1]
    """
    inputs = {k: _rows(v, rows) for k, v in inputs.items()}
    conditions = {k: _rows(v, rows) for k, v in conditions.items()}
    if base is None:
        physics_inputs = drifted_inputs(inputs, conditions, terms, values)
        mu = physics.evaluate(convention=convention, outputs=["mu"], **physics_inputs).mu
    else:
        physics_inputs = inputs
        mu = _rows(base.mu, rows)
        for term, v in zip(terms, values, strict=True):
            if term.kind == "drift":
                factor = term.factor(conditions, v[0])
                if term.level:  # the level moves from the value the base was computed at
                    now = inputs.get(term.parameter, physics.PARAMETERS[term.parameter].default)
                    factor = factor * (v[1] / np.asarray(now, dtype=float))
                mu = mu * np.power(factor, _rows(base.sensitivity[term.parameter], rows))
    effects = [(t, v) for t, v in zip(terms, values, strict=True) if t.kind == "effect"]
    if not effects:
        return np.asarray(mu, dtype=float)
    columns = {**physics.defaults(), **physics_inputs, **conditions}
    for term, v in effects:
        mu = term.effect.apply(
            mu, columns, dict(zip(term.parameter_names, v, strict=True)), term.drivers, term.constants
        )
    return np.asarray(mu, dtype=float)


def candidate_terms(dataset: Dataset, chosen: Sequence[Term] = (), fitted: Sequence[str] = ()) -> list[Term]:
    """Every term that fits the data's columns and is not already chosen.

    Parameters
    ----------
    dataset : Dataset
        Measurements; a main driver must take at least the effect's or law's ``min_levels`` distinct
        values and lie in its domain. A drift is proposed for every parameter of
        :data:`physics.effects.DRIFT_PARAMETERS` that is not a data column, on every condition column
        its law accepts except order and time columns (:data:`physics.effects.SESSION_KEYWORDS`, ISO 8601
        times), which drive the reading's ``measurement_drift`` and ``measurement_step`` instead. An
        effect with searched constants (the step's place) is proposed once per value of them. A generic
        effect is not proposed on drivers where a named form of it is (:attr:`Effect.named_form_of`).
    chosen : sequence of Term
        Terms already in the model: the same effect, or the same parameter on the same driver, is
        not proposed again.
    fitted : sequence of str
        Declared parameters fitted. A drift of a parameter that is neither fitted nor fixed, nor
        drifting already, fits its level too (:attr:`DriftTerm.level`).

    Returns
    -------
    list of Term
        Named effects, then drifts, then the generic family.
    """
    columns = {**physics.defaults(), **dataset.inputs(), **dataset.conditions}
    levels = {n: np.unique(v).size for n, v in dataset.columns().items() if v.dtype != bool}
    varying = [n for n, count in levels.items() if count >= 2]
    names = varying + [n for n in columns if n not in varying]
    taken_effects = {t.name for t in chosen if t.kind == "effect"}
    taken_drifts = {(t.parameter, t.driver) for t in chosen if t.kind == "drift"}
    sessions = dataset.session_columns()  # order and time columns: named so, or read from ISO times
    named, generic = [], []
    for effect in EFFECTS.values():
        if effect.name in taken_effects:
            continue
        candidates = effect.candidate_drivers(names)
        if effect.driver_keywords == SESSION_KEYWORDS:  # a clock column is the session's time, any name
            candidates += [(n,) for n in names if n in sessions and (n,) not in candidates]
        for drivers in candidates:
            if levels.get(drivers[0], 0) >= effect.min_levels and effect.accepts(columns, drivers):
                constants = effect.constants(columns, drivers)
                # A searched constant (a step's place): one candidate per value, screened; the search keeps
                # the best of them (calibrate.search._best_places) and searches the place again per fold
                searched = ([{}] if effect.search_constants is None
                            else effect.search_constants(effect.driver_values(columns, drivers)))
                (generic if effect.generic else named).extend(
                    EffectTerm(effect.name, drivers, {**constants, **more}) for more in searched)
    drifts = []
    drifting = {t.parameter for t in chosen if t.kind == "drift"}
    for parameter in DRIFT_PARAMETERS:
        if parameter in dataset.physics_columns:
            continue
        level = parameter not in fitted and parameter not in dataset.fixed and parameter not in drifting
        for driver, values in dataset.conditions.items():
            # An order or time column moves the reading (measurement_drift), not a parameter of the bearing:
            # its wear runs with cycles or distance, which have their own columns.
            if (parameter, driver) in taken_drifts or driver in sessions:
                continue
            for law in DRIFT_LAWS.values():
                if law.name == "linear" and DRIFT_LAWS["arrhenius"].matches(driver):
                    continue  # over a test's range of temperature a linear drift is the Arrhenius law
                if (
                    law.matches(driver)
                    and levels.get(driver, 0) >= law.min_levels
                    and law.accepts(driver, values)
                ):
                    drifts.append(
                        DriftTerm(parameter, law.name, driver, law.constants(driver, values), level)
                    )
    # A named form of a generic effect on the same drivers (a measurement drift on an order column is the
    # log-linear term there with the session's start as its reference) stands for it: not both.
    forms = {(t.effect.named_form_of, t.drivers) for t in named if t.effect.named_form_of}
    generic = [t for t in generic if (t.name, t.drivers) not in forms]
    return named + drifts + generic


def place_profile(term: EffectTerm, columns: Mapping[str, Any], log_residual: np.ndarray,
                  rows: np.ndarray) -> tuple[list[dict[str, float]], np.ndarray]:
    """Each place of a term with a searched place (a step) and the residual sum of squares there.

    Parameters
    ----------
    term : EffectTerm
        A term whose effect declares ``searched`` constants and one ``log``-form value.
    columns : mapping
        Every row's columns (the driver's values give the places, :attr:`Effect.search_constants`).
    log_residual : numpy.ndarray
        ``log(mu_measured / mu)`` of every row, ``mu`` the model without the term. [1]
    rows : numpy.ndarray
        Rows (indices) the profile is taken on (a fold's training rows).

    Returns
    -------
    places : list of dict
        The searched constants of each place.
    rss : numpy.ndarray
        Least-squares residual sum of squares on ``rows`` of a level plus the term's value at each place
        (the term's log factor at value 1 is its shape there). [1]
    """
    effect = term.effect
    places = effect.search_constants(effect.driver_values(columns, term.drivers))
    r = np.asarray(log_residual, dtype=float)[rows]
    name, ones = term.parameter_names[0], np.ones(np.size(log_residual))
    rss = np.empty(len(places))
    for i, place in enumerate(places):
        shape = np.log(effect.apply(ones, columns, {name: 1.0}, term.drivers, {**term.constants, **place}))
        design = np.column_stack([np.ones(r.size), shape[rows]])
        fitted = design @ np.linalg.lstsq(design, r, rcond=None)[0]
        rss[i] = float(np.sum(np.square(r - fitted)))
    return places, rss


def placed_on(term: Term, columns: Mapping[str, Any], log_residual: np.ndarray, rows: np.ndarray) -> Term:
    """The term at its best place on ``rows`` (:func:`place_profile`); any other term as it is. A fold's
    refit searches the place on its own training rows, so that the held-out rows never chose it."""
    if term.kind != "effect" or not term.searched:
        return term
    places, rss = place_profile(term, columns, log_residual, rows)
    if not places:
        return term
    return EffectTerm(term.name, term.drivers, {**term.constants, **places[int(np.argmin(rss))]})
