"""Is a fitted mechanism physically plausible? Its values against the ranges the physics declares.

A named law fits the data's shape; whether it is the mechanism depends on the values it needs. A
humidity effect carried by a Young's modulus that falls 6-34x below its default, or a Stribeck rise whose
breakaway speed lies ten times beyond the fastest row, fits but names nothing real. The physics declares
what is plausible (:mod:`physics.effects`):

* a drift's parameter: :attr:`physics.effects.ParameterShare.plausible`, the values it physically takes
  in a micro ball bearing (moduli 50-450 GPa, adhesion 1 mJ/m² to 1 J/m², sliding coefficients 0.01-1.5,
  ...); the drift's value over the data's driver range (its level times the law's factor) must stay in it;
* an effect's parameter: :attr:`physics.effects.EffectParameter.plausible` (a run-in's amplitude is
  positive: friction that rises is not a running-in), and for a scale of the driver
  (:attr:`~physics.effects.EffectParameter.within_data`: a decay length, a Stribeck speed) at most
  :data:`REACH` times the largest driver value in the data.

:func:`implausible` returns the reasons, in words, a term with given values is implausible (empty when it
is plausible). The search (:func:`calibrate.search.search_step`) does not choose an implausible candidate:
it loses to a plausible one or a generic term, and the step's words name it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from microbearing import physics
from microbearing.physics.effects import EFFECTS, PARAMETER_SHARES

from .candidates import DriftTerm, EffectTerm, Term

__all__ = ["REACH", "impossible", "implausible"]

#: A driver scale (decay length, Stribeck speed) beyond this many times the data's largest driver value is
#: not seen by the data: the law then acts as a trend. [1]
REACH = 3.0


def _reference(term: DriftTerm, values: Sequence[float], declared: Mapping[str, float],
               fixed: Mapping[str, Any]) -> float:
    """The drifting parameter's value at the reference condition, in its unit."""
    if term.level and len(values) > 1:
        return float(values[1])
    name = term.parameter
    return float(declared.get(name, fixed.get(name, physics.PARAMETERS[name].default)))


def _drifted(term: DriftTerm, values: Sequence[float], columns: Mapping[str, Any], declared,
             fixed) -> np.ndarray:
    """The drifting parameter's values over the columns' driver (its level times the law's factor), finite
    ones only [its unit]."""
    if term.driver not in columns:
        return np.zeros(0)
    with np.errstate(all="ignore"):
        value = _reference(term, values, declared, fixed) * np.asarray(
            term.factor(columns, float(values[0])), dtype=float)
    return value[np.isfinite(value)]


def _drift(term: DriftTerm, values: Sequence[float], columns: Mapping[str, Any], declared,
           fixed) -> list[str]:
    share = PARAMETER_SHARES.get(term.parameter)
    if share is None or share.plausible is None:
        return []
    value = _drifted(term, values, columns, declared, fixed)
    if value.size == 0:
        return []
    lo, hi = share.plausible
    low, high = float(np.min(value)), float(np.max(value))
    if low >= lo and high <= hi:
        return []
    unit = physics.PARAMETERS[term.parameter].unit
    default = float(physics.PARAMETERS[term.parameter].default)
    worst = low if low < lo else high
    return [f"{term.label} takes {term.parameter} to {worst:.3g} {unit} ({worst / default:.2g}x its default "
            f"{default:.3g}) over the data, outside its physical range {lo:.3g}-{hi:.3g} {unit}"]


def _effect(term: EffectTerm, values: Sequence[float], columns: Mapping[str, Any]) -> list[str]:
    effect = EFFECTS.get(term.name)
    if effect is None:
        return []
    reasons = []
    driver = term.drivers[0] if term.drivers else None
    for spec, value in zip(effect.parameters, values, strict=False):
        value = float(value)
        if spec.plausible is not None and not spec.plausible[0] <= value <= spec.plausible[1]:
            reasons.append(f"{term.label}: {spec.name} = {value:.3g} lies outside its plausible range "
                           f"{spec.plausible[0]:g}-{spec.plausible[1]:g} [{spec.unit}]")
        if spec.within_data and driver in columns:
            top = float(np.nanmax(np.abs(np.asarray(columns[driver], dtype=float))))
            if top > 0 and value > REACH * top:
                reasons.append(f"{term.label}: {spec.name} = {value:.3g} is {value / top:.2g}x the largest "
                               f"{driver} in the data ({top:.3g}): the law's scale lies beyond the data, "
                               f"which see only a trend")
    return reasons


def implausible(term: Term, values: Sequence[float], columns: Mapping[str, Any],
                declared: Mapping[str, float] | None = None, fixed: Mapping[str, Any] | None = None
                ) -> list[str]:
    """Why a term with these values is physically implausible (empty: plausible).

    Parameters
    ----------
    term : Term
        A named effect or a drift (a generic term is always plausible).
    values : sequence of float
        Its fitted values, in the order of its ``parameter_names``.
    columns : mapping of str to numpy.ndarray
        The data's columns (physics inputs and conditions).
    declared : mapping of str to float, optional
        Fitted declared parameters (the reference value of a drift without a fitted level).
    fixed : mapping, optional
        Fixed physics parameters of the data.

    Returns
    -------
    list of str
        One sentence per implausible value.

    Examples
    --------
    A race modulus falling to a fifth of its default over the data's humidity range is not a mechanism:

    >>> from microbearing.calibrate.candidates import DriftTerm
    >>> term = DriftTerm("race_youngs_modulus_Pa", "linear", "relative_humidity",
    ...                  {"reference": 0.4, "minimum": 0.2, "maximum": 0.6})
    >>> columns = {"relative_humidity": np.array([0.2, 0.4, 0.6])}
    >>> len(implausible(term, [-4.0], columns)), implausible(term, [0.1], columns)
    (1, [])
    """
    if getattr(term, "generic", False):
        return []
    declared = declared or {}
    fixed = fixed or {}
    if term.kind == "drift":
        return _drift(term, values, columns, declared, fixed)
    return _effect(term, values, columns)


def impossible(term: Term, values: Sequence[float], columns: Mapping[str, Any],
               declared: Mapping[str, float] | None = None, fixed: Mapping[str, Any] | None = None
               ) -> list[str]:
    """Why a drift with these values takes its parameter where the physics does not go over the columns
    (:data:`physics.PARAMETERS`' minimum and maximum: a friction coefficient below zero), in words (empty:
    possible). Stricter than :func:`implausible`, which also refuses values a bearing does not plausibly
    take; for columns beyond the data (runs to come), where a refit may still move the values within
    reason but not a law that runs on through zero.

    >>> from microbearing.calibrate.candidates import DriftTerm
    >>> term = DriftTerm("mu_pivot", "linear", "cycles", {"reference": 1500.0, "minimum": 0.0,
    ...                                                  "maximum": 3000.0})
    >>> impossible(term, [-7e-5], {"cycles": np.array([0.0, 3000.0])}, {"mu_pivot": 1.0})
    []
    >>> len(impossible(term, [-7e-5], {"cycles": np.array([0.0, 45000.0])}, {"mu_pivot": 1.0}))
    1
    """
    if term.kind != "drift" or getattr(term, "generic", False):
        return []
    value = _drifted(term, values, columns, declared or {}, fixed or {})
    spec = physics.PARAMETERS[term.parameter]
    if value.size == 0 or (float(np.min(value)) >= spec.minimum and float(np.max(value)) <= spec.maximum):
        return []
    worst = float(np.min(value)) if float(np.min(value)) < spec.minimum else float(np.max(value))
    return [f"{term.label} takes {term.parameter} to {worst:.3g} {spec.unit}, where the physics does not go "
            f"({spec.minimum:g}-{spec.maximum:g} {spec.unit})"]
