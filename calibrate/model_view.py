"""A calibrated model as a :class:`physics.model.Model`: μ with its 95 % interval, its domain, derivatives.

:class:`CalibratedPhysicsModel` wraps a :class:`calibrate.CalibratedModel` (the physics with fitted
parameters and the terms calibration added) in the interface every layer uses: the service answers
it for ``"calibrated:<id>"``, the optimizer takes it directly.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from microbearing import physics
from microbearing.physics.columns import physical_range, unit_of
from microbearing.physics.model import (
    Evaluation,
    Model,
    ModelError,
    ModelInput,
    evaluate_finite,
    physics_inputs,
)

from .domain import outside_law_domains
from .model import CalibratedModel, Prediction

__all__ = ["CalibratedPhysicsModel"]


class CalibratedPhysicsModel(Model):
    """A stored calibration: the physics with fitted parameters and the terms calibration added.

    Its outputs are the physics outputs with the fitted parameters, except ``mu``, which includes
    the added terms, and ``friction_force_N``, the force at that ``mu`` (``mu`` x ``load_N``, what a
    tribometer reads and what a friction-force limit judges); ``mu_effect`` [1], the terms' share of
    ``mu``; and ``mu_lower``, ``mu_upper`` [1],
    the 95 % prediction interval of a measurement (:meth:`calibrate.CalibratedModel.predict`; NaN for
    a model stored before intervals). ``outside_domain`` flags points outside the calibration data.

    Parameters
    ----------
    reference : str
        ``"calibrated:<id>"``.
    calibrated : calibrate.CalibratedModel
        The stored model.
    """

    kind = "calibrated"
    outputs = (*physics.OUTPUTS, "mu_effect", "mu_lower", "mu_upper")
    has_interval = True

    def __init__(self, reference: str, calibrated: CalibratedModel):
        self.reference = reference
        self.calibrated = calibrated
        self.convention = calibrated.convention
        self.fixed, self.fitted = dict(calibrated.fixed), dict(calibrated.fitted)
        self.required_columns = calibrated.required_columns
        # the columns of the measurement system's terms (an instrument's drift over a session): a point that
        # does not give one is answered for the bearing, the reading as it is taken to be true
        self.column_defaults = calibrated.column_defaults
        # The condition columns of the calibration data and the range of every column it was fitted
        # on (None for a model stored before domains were kept).
        self.conditions, self.domain = calibrated.conditions, calibrated.domain
        self.inputs = physics_inputs({**self.fixed, **self.fitted})
        # each with its quantity's physical range (a time counted from zero, a humidity fraction)
        self.inputs.update({name: ModelInput(name, _unit(name), "A condition column "
                                             "the calibrated model's terms read.", "float",
                                             *physical_range(name))
                            for name in self.required_columns})
        # The factor columns (group labels): a known label moves mu to its group's level; a new one, or
        # none, carries the spread between groups in the interval.
        self.inputs.update({name: ModelInput(name, "label", "A group label of a factor column of the "
                                             "calibration data (e.g. a specimen).", "label", default="")
                            for name in calibrated.factors})
        # The other condition columns of the data: a point may give them, and they are checked against
        # the data's range only (they are no input: nothing the model computes depends on them).
        self.unread_conditions = {name: ModelInput(name, _unit(name), "A condition column "
                                                   "of the calibration data the terms do not read.", "float",
                                                   *physical_range(name))
                                  for name in self.conditions if name not in self.inputs}

    @property
    def headers(self) -> dict[str, str]:
        """The upload's header of each column sent in another unit (:attr:`CalibratedModel.headers`)."""
        return dict(self.calibrated.headers)

    @property
    def column_checks(self) -> dict[str, ModelInput]:
        """Every column a point may give: the inputs and the conditions the terms do not read."""
        return {**self.inputs, **self.unread_conditions}

    def predict(self, points: Mapping[str, Any], *, domain: bool = True,
                shown: Mapping[str, Any] | None = None) -> Prediction:
        """μ with its 95 % interval and (unless ``domain`` is False) the domain check:
        :meth:`calibrate.CalibratedModel.predict` (``shown``: its warnings' words)."""
        return self.calibrated.predict(points, domain=domain, shown=shown)

    def evaluate(self, points: Mapping[str, Any], outputs: Sequence[str], *, pointer: str = "",
                 first_index: int = 0, shown: Mapping[str, Any] | None = None) -> Evaluation:
        """As :meth:`Model.evaluate`; the answer of a calibrated model wherever it is asked.

        ``points`` may also give the condition columns the terms do not read
        (:attr:`unread_conditions`): they enter the domain check only. The physics outputs other than
        ``mu`` are computed only when asked for; the warnings name every column outside the data.
        A value outside the domain of a term's law is a :class:`ModelError` naming its field
        (``/conditions/<name>``); a non-finite μ one at ``/conditions``, naming the point's index for
        columns. ``shown`` words the warnings' columns as a request sent them
        (:meth:`calibrate.CalibratedModel.domain_check`).
        """
        unread = {name: self.unread_conditions[name].check(value) for name, value in points.items()
                  if name in self.unread_conditions}
        checked = self.check({name: value for name, value in points.items() if name not in unread})
        given = {k: v for k, v in checked.items() if k in physics.PARAMETERS}
        wanted = list(dict.fromkeys(["mu", *(name for name in outputs if name in physics.OUTPUTS)]))
        base = evaluate_finite({**self.fixed, **self.fitted, **given}, wanted, self.convention, pointer,
                                first_index)
        outside = outside_law_domains(self.calibrated.terms, {**checked, **unread})
        if outside:  # named where it stands: a condition, or an input a term reads (speed for a power law)
            raise ModelError([{"pointer": f"{pointer}/{name}" if name in physics.PARAMETERS
                               else f"/conditions/{name}", "detail": detail}
                              for name, detail in outside.items()])
        try:
            with np.errstate(all="ignore"):
                prediction = self.calibrated.predict({**checked, **unread}, shown=shown)
        except ValueError as exc:  # a condition outside the law of a term (relative humidity 1)
            raise ModelError([{"pointer": "/conditions", "detail": str(exc)}]) from None
        mu = np.asarray(prediction.mu, dtype=float)
        finite = np.isfinite(mu)
        if not finite.all():
            at = f" (point {first_index + int(np.flatnonzero(~finite.reshape(-1))[0])})" if mu.ndim else ""
            raise ModelError([{"pointer": "/conditions", "detail": "the calibrated model's mu is not "
                               f"finite at these conditions{at}"}])
        no_interval = np.full(mu.shape, np.nan)
        if "friction_force_N" in base:  # the force at the model's mu, as the physics' is at its own
            base = {**base, "friction_force_N": base["friction_force_N"] * (mu / base["mu"])}
        upper = prediction.mu_upper
        if upper is not None:  # an interval computed: a NaN in it is its overflow far outside the data
            # (mu 0 x inf), not a model stored without one (NaN, answered null): inf, refused as not finite
            upper = np.where(np.isnan(upper), np.inf, upper)
        values = {**base, "mu": mu, "mu_effect": mu - base["mu"],
                  "mu_lower": no_interval if prediction.mu_lower is None else prediction.mu_lower,
                  "mu_upper": no_interval if upper is None else upper}
        shape = np.broadcast_shapes(*(np.shape(v) for v in values.values()))
        inside = np.ones(shape, dtype=bool) if prediction.in_domain is None else prediction.in_domain
        return Evaluation({name: values[name] for name in outputs},
                          ~np.broadcast_to(np.asarray(inside, dtype=bool), shape), list(prediction.warnings))

    def __call__(self, points: Mapping[str, Any]) -> np.ndarray:
        return self.calibrated(points)


def _unit(name: str) -> str:
    """A condition column's unit as its name says it (:func:`physics.columns.unit_of`), or the data's."""
    return unit_of(name) or "as in the calibration data"
