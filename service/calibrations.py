"""Calibrations in the service: run, store as data, view, and load as a ``mu_model`` callable.

A calibration is stored once, as a model of kind ``"calibration"`` in the SQLite store: its
report and the calibrated model as JSON metadata, its plots as PNG bytes (``uint8`` arrays).
:func:`load_mu_model` turns ``"physics"`` or ``"calibrated:<id>"`` into a model
(:func:`service.models.resolve`), callable as ``mu_model(points) -> mu``, for /v1/friction,
optimization and surrogates; :func:`with_conditions`
adds the condition columns a calibrated model's effect reads.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from microbearing import physics
from microbearing.calibrate import CalibrationReport, DataError, Dataset, Prediction, calibrate

from .models import CalibratedPhysicsModel, Model, resolve
from .problems import ProblemError, validation_problem
from .schemas.calibrations import MODEL_PATTERN
from .store import Store

__all__ = ["KIND", "MODEL_PATTERN", "MODEL_PREFIX", "calibration_view", "data_problem",
           "evaluate_point_with_model", "interval_at", "load_calibration", "load_mu_model",
           "prediction_fields",
           "run_calibration",
           "with_conditions"]

KIND = "calibration"
MODEL_PREFIX = "calibrated:"
_MAX_LISTED_ERRORS = 200


def data_problem(errors: list[dict[str, Any]], fixed_pointer: str | None = "/fixed",
                 data_pointer: str | None = "/data") -> ProblemError:
    """A 422 problem listing the row-by-row errors of :class:`calibrate.DataError`.

    Parameters
    ----------
    errors : list of dict
        ``{"row", "column", "message"}`` items (rows 1-based).
    fixed_pointer : str or None
        JSON pointer of the fixed values; None when they come as the query parameter ``fixed``
        (the CSV upload), whose errors then name that parameter.
    data_pointer : str or None
        JSON pointer of the rows; None for a CSV body: every error then points at ``/body`` (the
        uploaded file) and its detail names the row (the data line, 1 after the header) and column.

    Returns
    -------
    ProblemError
    """
    items: list[dict[str, str]] = []
    for e in errors[:_MAX_LISTED_ERRORS]:
        row, column, message = e["row"], e["column"], e["message"]
        if row is None and column is not None and message.startswith("fixed"):
            if fixed_pointer is None:
                items.append({"parameter": "fixed", "detail": f"{column}: {message}"})
            else:
                items.append({"pointer": f"{fixed_pointer}/{column}", "detail": message})
        elif data_pointer is None:
            items.append({"pointer": "/body", "detail": DataError.describe(e)})
        elif row is not None:
            tail = "" if column is None else "/" + column.replace("~", "~0").replace("/", "~1")
            items.append({"pointer": f"{data_pointer}/{row - 1}{tail}", "detail": message})
        else:
            items.append({"pointer": data_pointer, "detail": DataError.describe(e)})
    if len(errors) > _MAX_LISTED_ERRORS:
        items.append({"pointer": "/body" if data_pointer is None else data_pointer,
                      "detail": f"... and {len(errors) - _MAX_LISTED_ERRORS} more problems in the data"})
    return validation_problem(items, total=len(errors))


def calibration_view(calibration_id: str, metadata: Mapping[str, Any]) -> dict[str, Any]:
    """The public result of a stored calibration: its report with ids and plot URLs."""
    report = dict(metadata["report"])
    plots = report.pop("plots")
    return {
        "id": calibration_id,
        "model_id": MODEL_PREFIX + calibration_id,
        **report,
        "plots": {name: f"/v1/calibrations/{calibration_id}/plots/{name}.png" for name in plots},
    }


def run_calibration(store: Store, dataset: Dataset, fit_parameters: list[str], folds: int, convention: str,
                    progress: Callable[[float], None] | None = None) -> dict[str, Any]:
    """Calibrate, store the report, model and plots, and return the public result.

    Parameters
    ----------
    store : Store
        Where the calibration is kept.
    dataset : calibrate.Dataset
        Parsed measurements.
    fit_parameters : list of str
        Declared parameters to fit.
    folds : int
        Cross-validation folds. [1]
    convention : str
        See :data:`physics.CONVENTIONS`.
    progress : callable, optional
        Fraction done, 0..1 (a job's progress, which also checks cancellation).

    Returns
    -------
    dict
        As :func:`calibration_view`.
    """
    report: CalibrationReport = calibrate(dataset, fit_parameters, folds=folds, progress=progress,
                                          convention=convention)
    metadata = {"report": report.to_dict(), "model": report.model.to_json()}
    arrays = {name: np.frombuffer(png, dtype=np.uint8) for name, png in report.plots.items()}
    name = " + ".join(e["name"] for e in report.effects) or "none"
    calibration_id = store.save_model(KIND, metadata, arrays, name=f"{report.n_points} points, effect {name}")
    return calibration_view(calibration_id, metadata)


def load_calibration(store: Store, calibration_id: str):
    """The stored calibration, or a 404 problem."""
    stored = store.load_model(calibration_id)
    if stored is None or stored.kind != KIND:
        raise ProblemError(404, f"There is no calibration {calibration_id!r}.")
    return stored


def _condition_problems(model: Any, conditions: Mapping[str, Any], pointer: str) -> None:
    """422 naming every condition that is a physics input, or a column the calibration never saw."""
    items = [{"pointer": f"{pointer}/{name}", "detail": "is a physics input; give it as a field of its own"}
             for name in sorted(set(conditions) & set(physics.PARAMETERS))]
    known = getattr(model, "conditions", None)
    if getattr(model, "domain", None) is not None:
        items += [{"pointer": f"{pointer}/{name}",
                   "detail": f"unknown condition column; the calibration data had: "
                             f"{', '.join(known) or 'none'}"}
                  for name in sorted(set(conditions) - set(physics.PARAMETERS) - set(known))]
    if items:
        raise validation_problem(items)


def prediction_fields(prediction: Prediction) -> dict[str, Any]:
    """The interval and domain fields of one point's :class:`calibrate.Prediction`, JSON-ready.

    Returns
    -------
    dict
        ``mu_lower``, ``mu_upper`` [1] (None for a model stored before intervals), ``in_domain``
        (None likewise) and ``domain_warnings`` (list of str).
    """
    def number(value):
        return None if value is None else float(np.asarray(value))

    return {"mu_lower": number(prediction.mu_lower), "mu_upper": number(prediction.mu_upper),
            "in_domain": None if prediction.in_domain is None else bool(np.all(prediction.in_domain)),
            "domain_warnings": list(prediction.warnings)}


def interval_at(model: Any,
                conditions: Mapping[str, float] | None) -> Callable[[Mapping[str, Any]], dict] | None:
    """For a calibrated model, a function of one design point giving :func:`prediction_fields` there.

    Parameters
    ----------
    model : Model
        A resolved model (:func:`service.models.resolve`); only a calibrated one has these fields.
    conditions : mapping or None
        Its condition columns, one value each (as given to :func:`with_conditions`).

    Returns
    -------
    callable or None
        ``fields(point) -> dict`` (``mu_lower``, ``mu_upper``, ``in_domain``, ``domain_warnings``) for a
        point of physics inputs; None for other models.
    """
    if not isinstance(model, CalibratedPhysicsModel):
        return None

    def fields(point: Mapping[str, Any]) -> dict[str, Any]:
        with np.errstate(all="ignore"):
            return prediction_fields(model.predict({**point, **dict(conditions or {})}))

    return fields


def evaluate_point_with_model(store: Store, model: str, given: Mapping[str, Any],
                              conditions: Mapping[str, float] | None) -> dict[str, Any]:
    """The /v1/friction answer of a calibrated model at one point.

    Parameters
    ----------
    store : Store
        Where calibrations are kept.
    model : str
        ``"calibrated:<id>"``.
    given : mapping
        Physics inputs the client gave explicitly; they override the model's fixed and fitted values.
    conditions : mapping or None
        Condition columns the model's terms read (e.g. ``relative_humidity`` [1]).

    Returns
    -------
    dict
        ``convention`` (the model's), every physics output with the model's fitted parameters, ``mu``
        [1] including the terms, ``mu_effect`` [1] (the terms' share of ``mu``), ``mu_lower`` and
        ``mu_upper`` [1] (95 % prediction interval of a measurement), ``in_domain``,
        ``domain_warnings`` and ``model``.

    Raises
    ------
    ProblemError
        404 for an unknown model, 422 naming an unknown, missing or invalid condition, or for
        non-finite outputs.
    """
    from .evaluation import evaluate_point

    mu_model = load_mu_model(store, model)
    conditions = dict(conditions or {})
    _condition_problems(mu_model, conditions, "/conditions")
    inputs = {**mu_model.fixed, **mu_model.fitted, **given}
    outputs = evaluate_point(inputs, mu_model.convention)
    try:
        with np.errstate(all="ignore"):
            prediction = mu_model.predict({**given, **conditions})
    except ValueError as exc:
        raise validation_problem([{"pointer": "/conditions", "detail": str(exc)}]) from None
    mu = float(np.asarray(prediction.mu))
    if not np.isfinite(mu):
        raise validation_problem([{"pointer": "/conditions",
                                   "detail": "the calibrated model's mu is not finite at these conditions"}])
    return {**outputs, "convention": mu_model.convention, "mu": mu, "mu_effect": mu - outputs["mu"],
            **prediction_fields(prediction), "model": model}


def with_conditions(model: Callable[[Mapping[str, Any]], Any], reference: str,
                    conditions: Mapping[str, float] | None,
                    pointer: str = "/conditions") -> Callable[[Mapping[str, Any]], Any]:
    """A model's ``mu_model(points)`` with constant condition columns added to every point.

    Shared by every route that runs a stored model on points it generates itself
    (optimizations, surrogates trained on a calibrated model).

    Parameters
    ----------
    model : callable
        ``mu_model(points) -> mu`` [1]; a :class:`calibrate.CalibratedModel` names the extra
        columns it needs in ``required_columns``.
    reference : str
        The model reference of the request (``"calibrated:<id>"``), for errors.
    conditions : mapping or None
        Condition columns by name (e.g. ``relative_humidity`` [1]), one value each, in the
        units of the calibration data.
    pointer : str
        JSON pointer of the conditions in the request, for errors.

    Returns
    -------
    callable
        ``mu_model(points) -> mu`` [1] reading the conditions as columns broadcast like the points.

    Raises
    ------
    ProblemError
        422 when a condition is a physics input or unknown to the calibration, or a column the model
        needs is missing.
    """
    conditions = dict(conditions or {})
    _condition_problems(model, conditions, pointer)
    missing = [c for c in getattr(model, "required_columns", []) if c not in conditions]
    if missing:
        raise validation_problem([{"pointer": pointer, "detail": f"the model {reference} needs "
                                   f"{', '.join(missing)}"}])
    if not conditions:
        return model

    def mu_model(points: Mapping[str, Any]) -> Any:
        shape = np.broadcast_shapes(*(np.shape(v) for v in points.values()))
        return model({**points, **{k: np.full(shape, v) for k, v in conditions.items()}})

    return mu_model


def load_mu_model(store: Store, model: str, pointer: str = "/model") -> Model:
    """The :class:`~service.models.Model` of ``"physics"`` or ``"calibrated:<id>"``.

    Parameters
    ----------
    store : Store
        Where calibrations are kept.
    model : str
        ``"physics"`` (the declared model with its defaults) or ``"calibrated:<id>"``.
    pointer : str
        JSON pointer of the reference in the request, for errors.

    Returns
    -------
    Model
        Callable as ``mu_model(points: dict[str, array]) -> array`` of μ [1]; a calibrated model also
        reads the extra columns its effect needs (e.g. ``relative_humidity``).

    Raises
    ------
    ProblemError
        422 for a malformed reference, 404 for an unknown calibration.
    """
    return resolve(store, model, pointer, kinds=("physics", "calibrated"))
