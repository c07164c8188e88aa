"""A calibrated model as plain JSON data, rebuilt into a ``mu_model(points)`` callable (no pickle).

The model is the physics of :func:`physics.evaluate` with the values fixed by
the calibration request, the fitted declared parameters, and at most one effect
of :data:`physics.effects.EFFECTS` with its fitted parameters, driver columns
and constants.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import physics
from physics.effects import EFFECTS

__all__ = ["CalibratedModel"]

FORMAT_VERSION = 1


@dataclass(frozen=True)
class CalibratedModel:
    """Physics + fitted declared parameters + one optional effect.

    Attributes
    ----------
    fitted : dict of str to float
        Fitted physics parameters, in their units.
    fixed : dict
        Physics parameters fixed by the calibration request.
    effect : dict or None
        ``{"name", "drivers", "parameters", "constants"}`` of the added effect.
    convention : str
        See :data:`physics.CONVENTIONS`.
    """

    fitted: dict[str, float] = field(default_factory=dict)
    fixed: dict[str, Any] = field(default_factory=dict)
    effect: dict[str, Any] | None = None
    convention: str = physics.DEFAULT_CONVENTION

    @property
    def required_columns(self) -> list[str]:
        """Columns a point must give besides the physics inputs: the effect's drivers not in physics."""
        if self.effect is None:
            return []
        return [d for d in self.effect["drivers"] if d not in physics.PARAMETERS]

    def __call__(self, points: Mapping[str, Any]) -> np.ndarray:
        """μ at columnar points.

        Parameters
        ----------
        points : mapping of str to array_like
            Physics inputs by name (broadcasting like :func:`physics.evaluate`; values given here
            override fixed and fitted ones) and the effect's extra driver columns; other keys are
            ignored.

        Returns
        -------
        numpy.ndarray
            μ. [1]

        Raises
        ------
        ValueError
            For invalid physics inputs or a missing effect driver column.
        """
        missing = [c for c in self.required_columns if c not in points]
        if missing:
            raise ValueError(f"the calibrated model needs column(s) {', '.join(missing)} "
                             f"(drivers of its effect {self.effect['name']})")
        inputs = {**self.fixed, **self.fitted,
                  **{k: v for k, v in points.items() if k in physics.PARAMETERS}}
        mu = physics.evaluate(convention=self.convention, outputs=["mu"], **inputs).mu
        if self.effect is None:
            return mu
        extra = {k: np.asarray(v, dtype=float) for k, v in points.items() if k not in physics.PARAMETERS}
        columns = {**physics.defaults(), **inputs, **extra}
        return EFFECTS[self.effect["name"]].apply(mu, columns, self.effect["parameters"],
                                                  tuple(self.effect["drivers"]), self.effect["constants"])

    def to_json(self) -> dict[str, Any]:
        """The model as JSON-ready data (numbers, strings, lists, dicts)."""
        return {
            "format_version": FORMAT_VERSION,
            "convention": self.convention,
            "fixed": dict(self.fixed),
            "fitted": {k: float(v) for k, v in self.fitted.items()},
            "effect": None if self.effect is None else {
                "name": self.effect["name"],
                "drivers": list(self.effect["drivers"]),
                "parameters": {k: float(v) for k, v in self.effect["parameters"].items()},
                "constants": {k: float(v) for k, v in self.effect["constants"].items()},
            },
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> CalibratedModel:
        """Rebuild a model from :meth:`to_json` data, validating every part.

        Parameters
        ----------
        data : mapping
            As written by :meth:`to_json`.

        Returns
        -------
        CalibratedModel

        Raises
        ------
        ValueError
            For an unknown format version, convention, parameter or effect.
        """
        if data.get("format_version") != FORMAT_VERSION:
            raise ValueError(f"format_version must be {FORMAT_VERSION}; got {data.get('format_version')!r}")
        convention = data.get("convention", physics.DEFAULT_CONVENTION)
        if convention not in physics.CONVENTIONS:
            raise ValueError(f"convention must be one of {', '.join(physics.CONVENTIONS)}; "
                             f"got {convention!r}")
        values = {}
        for part in ("fixed", "fitted"):
            for name, value in dict(data.get(part, {})).items():
                if name not in physics.PARAMETERS:
                    raise ValueError(f"{part}: unknown physics parameter {name!r}")
                values[name] = physics.validate(name, value).item()
        effect = data.get("effect")
        if effect is not None:
            spec = EFFECTS.get(effect.get("name"))
            if spec is None:
                raise ValueError(f"effect name must be one of {', '.join(EFFECTS)}; "
                                 f"got {effect.get('name')!r}")
            missing = [n for n in spec.parameter_names if n not in effect.get("parameters", {})]
            if missing or not effect.get("drivers"):
                raise ValueError(f"effect {spec.name} needs drivers and parameters {spec.parameter_names}")
            effect = {"name": spec.name, "drivers": [str(d) for d in effect["drivers"]],
                      "parameters": {n: float(effect["parameters"][n]) for n in spec.parameter_names},
                      "constants": {k: float(v) for k, v in dict(effect.get("constants", {})).items()}}
        fixed = {k: values[k] for k in dict(data.get("fixed", {}))}
        fitted = {k: values[k] for k in dict(data.get("fitted", {}))}
        return cls(fitted, fixed, effect, convention)
