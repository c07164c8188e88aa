"""A rival of a calibrated model as stored with it (:class:`RivalModel`): terms that fit the data about as
well as the chosen ones (:mod:`calibrate.rivals`), refitted, with their own covariance; and the check of a
stored covariance (:func:`covariance_from_json`) the calibrated model reads too (:mod:`calibrate.model`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from microbearing import physics

from .candidates import Term, term_from_json

__all__ = ["RivalModel", "covariance_from_json"]


def covariance_from_json(value: Any, fitted: Mapping[str, float], terms: Sequence[tuple[Any, Sequence]],
                          where: str = "") -> np.ndarray:
    """A stored covariance of the fitted values and the terms' values, checked square of their count (JSON's
    ``[]`` is the 0 x 0 matrix of a model that fits nothing); ValueError, prefixed ``where``, otherwise."""
    covariance = np.asarray(value, dtype=float)
    size = len(fitted) + sum(len(v) for _, v in terms)
    if covariance.size == size == 0:
        covariance = covariance.reshape(0, 0)
    if covariance.shape != (size, size):
        raise ValueError(f"{where}covariance must be {size} x {size}; got {covariance.shape}")
    return covariance


@dataclass(frozen=True)
class RivalModel:
    """A rival of the calibrated model: its terms with one replaced by a term that fits the data about as
    well (:mod:`calibrate.rivals`), refitted, with its own covariance.

    Attributes
    ----------
    label : str
        ``"<rival term> instead of <chosen term>"``, or ``"<rival term> added"`` (a rival by confounding:
        a term on a column that moves with one the model reads).
    fitted : dict of str to float
        Its fitted physics parameters, in their units.
    terms : list of tuple of (Term, list of float)
        Its terms with their fitted values.
    covariance : numpy.ndarray
        Covariance of its fitted values (declared, then each term's).
    gap_se : float
        How much worse it scored held out than the chosen term, in standard errors. [1]
    """

    label: str
    fitted: dict[str, float]
    terms: list[tuple[Term, list[float]]]
    covariance: np.ndarray = field(repr=False)
    gap_se: float = 0.0

    def to_json(self) -> dict[str, Any]:
        """JSON-ready data, as read by :meth:`from_json`."""
        return {"label": self.label, "gap_se": float(self.gap_se),
                "fitted": {k: float(v) for k, v in self.fitted.items()},
                "terms": [t.to_json(v) for t, v in self.terms],
                "covariance": np.asarray(self.covariance, dtype=float).tolist()}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> RivalModel:
        """Rebuild and validate (unknown parameters, effects or laws, a covariance of the wrong size).

        Raises
        ------
        ValueError
            For invalid data.
        """
        fitted = {}
        for name, value in dict(data.get("fitted", {})).items():
            if name not in physics.PARAMETERS:
                raise ValueError(f"rivals: unknown physics parameter {name!r}")
            fitted[name] = physics.validate(name, value).item()
        terms = [term_from_json(t) for t in data.get("terms", [])]
        covariance = covariance_from_json(data.get("covariance", []), fitted, terms, "rivals: ")
        return cls(str(data.get("label", "")), fitted, terms, covariance, float(data.get("gap_se", 0.0)))
