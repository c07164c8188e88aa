"""Calibrations in the service: run, store as data, view, and load as a ``mu_model`` callable.

A calibration is stored once, as a model of kind ``"calibration"`` in the SQLite store: its
report and the calibrated model as JSON metadata, its plots as PNG bytes (``uint8`` arrays).
:func:`load_mu_model` turns ``"physics"`` or ``"calibrated:<id>"`` into a model
(:func:`service.models.resolve`), callable as ``mu_model(points) -> mu``, for /v1/friction,
optimization and surrogates; :func:`read_conditions` reads conditions as the model's columns through
the column registry (:mod:`physics.columns`: other units converted, unit slips refused) and
:func:`check_conditions` refuses those a model cannot read,
:func:`with_conditions` adds the condition columns a calibrated model's effect reads, and
:func:`evaluate_point_with_model` and :func:`evaluate_batch_with_model` answer /v1/friction and
/v1/friction/batch through :meth:`~service.models.CalibratedPhysicsModel.evaluate`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Executor
from typing import Any

import numpy as np

from microbearing import physics
from microbearing.calibrate import CalibrationReport, DataError, Dataset, Prediction, calibrate
from microbearing.calibrate.data import MU_MEASURED, hours_since
from microbearing.calibrate.tabular import TableError
from microbearing.physics.columns import Reading, read_key, unknown_column
from microbearing.physics.model import NOT_FINITE
from microbearing.physics.slips import read_slip, unstated_unit

from .evaluation import column_arrays
from .executor import evaluate_in_chunks
from .models import CalibratedPhysicsModel, InputError, Model, problems, resolve
from .problems import ProblemError, pointer_at, validation_problem
from .schemas.base import read_value
from .schemas.calibrations import MODEL_PATTERN
from .store import Store

__all__ = ["ReadConditions", "DATA_PREFIX", "KIND", "MODEL_PATTERN", "MODEL_PREFIX", "calibration_summary",
           "calibration_view", "check_conditions", "data_arrays", "data_problem", "delete_calibration",
           "evaluate_batch_with_model", "evaluate_point_with_model", "fitting_statement", "interval_at",
           "load_calibration", "load_mu_model", "prediction_fields", "read_conditions", "run_calibration",
           "store_calibration",
           "stored_dataset", "with_conditions"]

KIND = "calibration"
MODEL_PREFIX = "calibrated:"
#: Prefix of a stored calibration's data columns among its arrays (the others are its plots).
DATA_PREFIX = "data."
_MAX_LISTED_ERRORS = 200


def data_problem(errors: list[dict[str, Any]], fixed_pointer: str | None = "/fixed",
                 data_pointer: str | None = "/data", rows: Sequence[Mapping[str, Any]] = ()) -> ProblemError:
    """A 422 problem listing the row-by-row errors of :class:`calibrate.DataError`.

    Parameters
    ----------
    errors : list of dict
        ``{"row", "column", "message"}`` items (rows 1-based); a file's also ``line``, ``letter`` and
        ``sent`` (:class:`calibrate.tabular.TableError`), and one about a request parameter
        ``parameter`` (its name).
    fixed_pointer : str or None
        JSON pointer of the fixed values; None when they come as the query parameter ``fixed``
        (the CSV upload), whose errors then name that parameter.
    data_pointer : str or None
        JSON pointer of the rows; None for a CSV body: every error then points at ``/body`` (the
        uploaded file) and its detail places it as the spreadsheet shows it: the file's line and the
        column's letter and header cell (``line 9, column C (speed [mm/s]): ...``).

    Returns
    -------
    ProblemError
    """
    items: list[dict[str, str]] = []
    for e in errors[:_MAX_LISTED_ERRORS]:
        row, column, message = e["row"], e["column"], e["message"]
        if e.get("parameter"):  # a request parameter the data contradict (separator, ignore)
            if data_pointer is None:
                items.append({"parameter": e["parameter"], "detail": message})
            else:
                items.append({"pointer": f"/{e['parameter']}", "detail": message})
        elif row is None and column is not None and message.startswith("fixed"):
            if fixed_pointer is None:
                items.append({"parameter": "fixed", "detail": f"{column}: {message}"})
            else:
                items.append({"pointer": pointer_at(fixed_pointer, column), "detail": message})
        elif data_pointer is None:
            items.append({"pointer": "/body", "detail": TableError.describe(e)})
        elif row is not None:
            cell = [str(row - 1)] + ([] if column is None else [column])
            items.append({"pointer": pointer_at(data_pointer, *cell), "detail": message})
        else:
            first = next((i for i, row in enumerate(rows) if column in row), None)
            at = data_pointer if first is None else pointer_at(data_pointer, str(first), column)
            items.append({"pointer": at, "detail": DataError.describe(e)})
    if len(errors) > _MAX_LISTED_ERRORS:
        items.append({"pointer": "/body" if data_pointer is None else data_pointer,
                      "detail": f"... and {len(errors) - _MAX_LISTED_ERRORS} more problems in the data"})
    return validation_problem(items, total=len(errors))


def fitting_statement(dataset: Dataset, fit_parameters: list[str]) -> str:
    """What a calibration fits, in words: the parameters named, or that none is and what that means.

    Parameters
    ----------
    dataset : calibrate.Dataset
        The data (their columns and fixed values are not fitted).
    fit_parameters : list of str
        Declared parameters the request names to fit.

    Returns
    -------
    str
        E.g. ``"fits mu_pivot [1] and the terms the data need"``, or for none named, that the declared
        parameters keep their defaults (naming a few) and only added terms are fitted.
    """
    if fit_parameters:
        named = ", ".join(f"{name} [{physics.PARAMETERS[name].unit}]" for name in fit_parameters)
        return f"fits {named} (fit_parameters) and the terms the data need"
    free = [name for name, spec in physics.PARAMETERS.items()
            if spec.kind == "float" and not spec.required and name not in dataset.physics_columns
            and name not in dataset.fixed]
    # the friction coefficients first: what a lab most often means to fit
    free.sort(key=lambda name: not name.startswith("mu_"))
    defaults = ", ".join(f"{name} {physics.PARAMETERS[name].default:g} [{physics.PARAMETERS[name].unit}]"
                         for name in free[:3])
    return (f"fit_parameters is empty, so no declared parameter is fitted: all keep their defaults "
            f"({defaults}, ...) and only the terms the data need are chosen and fitted; name some in "
            f"fit_parameters (e.g. mu_pivot) to fit them")


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


def data_arrays(dataset: Dataset) -> dict[str, np.ndarray]:
    """A calibration's data as arrays to store beside its plots (``data.<column>`` of
    :meth:`calibrate.Dataset.to_columns`, the one serialization of measurements)."""
    return {DATA_PREFIX + name: values for name, values in dataset.to_columns().items()}


def stored_dataset(arrays: Mapping[str, np.ndarray], fixed: Mapping[str, Any],
                   headers: Mapping[str, str] | None = None) -> Dataset | None:
    """The calibration's data from its stored arrays, or None for a calibration stored before data were.

    ``headers`` (column -> its header as sent: the stored model's, which
    :func:`service.models.stored_calibrated` restores from the report's intake) are the data's when the
    arrays have none (``header.<column>``: a calibration stored before the upload's headers were kept), so
    that the plots and refits of its data speak the upload's units (``temp_F [degF]``, not ``temp_K [K]``).
    """
    if DATA_PREFIX + MU_MEASURED not in arrays:
        return None
    dataset = Dataset.from_columns({key[len(DATA_PREFIX):]: value for key, value in arrays.items()
                                    if key.startswith(DATA_PREFIX)}, fixed)
    if dataset.headers or not headers:
        return dataset
    return dataclasses.replace(dataset, headers={str(name): str(sent) for name, sent in headers.items()})


def run_calibration(store: Store, dataset: Dataset, fit_parameters: list[str], folds: int, convention: str,
                    progress: Callable[[float], None] | None = None,
                    intake: Mapping[str, Any] | None = None) -> dict[str, Any]:
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
    intake : mapping, optional
        How the data were read (:meth:`calibrate.Intake.to_dict`), kept in the report as ``intake``.

    Returns
    -------
    dict
        As :func:`calibration_view`.
    """
    report: CalibrationReport = calibrate(dataset, fit_parameters, folds=folds, progress=progress,
                                          convention=convention)
    return store_calibration(store, report, dataset, intake)


def store_calibration(store: Store, report: CalibrationReport, dataset: Dataset,
                      intake: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Store a calibration's report, model, plots and data (as :func:`run_calibration` does; the command
    line's ``calibrate`` stores its report this way) and return the public result.

    Parameters
    ----------
    store : Store
        Where the calibration is kept.
    report : calibrate.CalibrationReport
        The calibration of ``dataset``.
    dataset : calibrate.Dataset
        The measurements it was calibrated on (kept beside the plots).
    intake : mapping, optional
        How the data were read (:meth:`calibrate.Intake.to_dict`), kept in the report as ``intake``.

    Returns
    -------
    dict
        As :func:`calibration_view`.
    """
    metadata = {"report": {**report.to_dict(), "intake": None if intake is None else dict(intake)},
                "model": report.model.to_json()}
    arrays = {name: np.frombuffer(png, dtype=np.uint8) for name, png in report.plots.items()}
    # The data stay beside the plots: proposing the next runs refits the rivals on them and draws them.
    arrays |= data_arrays(dataset)
    name = " + ".join(e["name"] for e in report.effects) or "none"
    calibration_id = store.save_model(KIND, metadata, arrays, name=f"{report.n_points} points, effect {name}")
    return calibration_view(calibration_id, metadata)


def calibration_summary(row: Mapping[str, Any]) -> dict[str, Any]:
    """A stored calibration (a row of :meth:`Store.list_models`) as :class:`CalibrationSummary` data."""
    report = row["metadata"]["report"]
    model = row["metadata"].get("model", {})
    effects = report.get("effects")
    if effects is None:  # stored before forward selection: at most one effect
        effects = [] if report.get("missing_effect") is None else [report["missing_effect"]]
    domain = model.get("domain") or {}
    return {"id": row["id"], "model_id": MODEL_PREFIX + row["id"], "name": row["name"],
            "created_at": row["created_at"], "n_points": report["n_points"],
            "fit_parameters": list(report["fit_parameters"]),
            "effects": [e["name"] for e in effects], "error_before": report["error_before"],
            "error_after": report["error_after"],
            "columns": sorted(domain) if isinstance(domain, dict) else [],
            "url": f"/v1/calibrations/{row['id']}"}


def delete_calibration(store: Store, calibration_id: str) -> None:
    """Delete a stored calibration (report, model, plots), or a 404 problem.

    Surrogates trained on it keep their predictions; optimizing one then answers 404 naming the
    calibration, since the model it stands for is gone.
    """
    load_calibration(store, calibration_id)
    if not store.delete_model(calibration_id):
        raise ProblemError(404, f"There is no calibration {calibration_id!r}.")


def load_calibration(store: Store, calibration_id: str):
    """The stored calibration, or a 404 problem."""
    stored = store.load_model(calibration_id)
    if stored is None or stored.kind != KIND:
        raise ProblemError(404, f"There is no calibration {calibration_id!r}.")
    return stored


def check_conditions(model: Model, conditions: Mapping[str, Any], pointer: str = "/conditions") -> None:
    """Refuse conditions a model cannot read, and a calibrated model's missing ones.

    Parameters
    ----------
    model : Model
        A resolved model (:func:`service.models.resolve`); only a calibrated one reads conditions.
    conditions : mapping
        Condition columns by name (values are not looked at).
    pointer : str
        JSON pointer of the conditions in the request.

    Raises
    ------
    ProblemError
        422 naming every condition that is a physics input (``<pointer>/<name>``), or a column the
        calibration data did not have (its names listed); else 422 at ``pointer`` naming the columns
        the model's terms read and were not given.
    """
    items = [{"pointer": pointer_at(pointer, name),
              "detail": "is a physics input; give it as a field of its own"}
             for name in sorted(set(conditions) & set(physics.PARAMETERS))]
    if isinstance(model, CalibratedPhysicsModel):
        factors = model.calibrated.factors
        items += [{"pointer": pointer_at(pointer, name),
                   "detail": "must be a number or a list of numbers: only a "
                   f"factor column ({', '.join(factors) or 'none'}) takes labels"}
                  for name, value in conditions.items() if name not in factors and _has_text(value)]
        if model.domain is not None:
            items += [{"pointer": pointer_at(pointer, name), "detail": unknown_column(
                           name, [*model.conditions, *factors], "condition column")}
                      for name in sorted(set(conditions) - set(physics.PARAMETERS) - set(model.conditions)
                                         - set(factors))]
        if not items:
            try:
                model.calibrated.check_columns(list(conditions))
            except ValueError as exc:
                items.append({"pointer": pointer, "detail": str(exc)})
    if items:
        raise validation_problem(items)


class ReadConditions(dict):
    """Conditions by the model's column names (a dict), with :attr:`sent_as`: each column's key as sent,
    for a refusal's pointer, and :attr:`sent_values`: its value as sent, for a refusal's words."""

    def __init__(self, read: Mapping[str, Any], sent_as: Mapping[str, str] | None = None,
                 sent_values: Mapping[str, Any] | None = None, readings: Mapping[str, Reading] | None = None):
        super().__init__(read)
        self.sent_as = dict(sent_as or {})
        self.sent_values = dict(sent_values or {})
        self.readings = dict(readings or {})

    def in_sent_units(self, name: str, value: Any) -> Any:
        """A value of column ``name`` (in the model's unit), or a list of them, in the unit its key was sent
        in (``RH (%)``: 0.85 -> 85), to the digits the value holds (:meth:`physics.columns.Reading.set_point`:
        70 degF, not 69.9999999998); as it is when it was sent in the model's unit."""
        reading = self.readings.get(name)
        if isinstance(value, list | tuple):
            return [self.in_sent_units(name, v) for v in value]
        if reading is None or not reading.reading or isinstance(value, bool | str):
            return value
        return reading.set_point(value)

    def shown_as_sent(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Columns' values (in the model's units) under their keys as sent, each in its key's unit
        (:meth:`in_sent_units`): what every ``as_sent`` of a result shows."""
        return {self.key(name): self.in_sent_units(name, value) for name, value in values.items()}

    @classmethod
    def from_readings(cls, readings: Mapping[str, Reading]) -> ReadConditions:
        """None read, only how each column was sent (its key, :attr:`physics.columns.Reading.sent`, and unit):
        for showing a result's figures as sent (:meth:`shown_as_sent`)."""
        return cls({}, {name: r.sent for name, r in readings.items()}, readings=readings)

    @classmethod
    def of(cls, conditions: Any) -> ReadConditions:
        """``conditions`` when :func:`read_conditions` read them, else none read (keys as they are)."""
        return conditions if isinstance(conditions, ReadConditions) else cls({})

    def key(self, name: str) -> str:
        """A column's key as sent (its own name when it was sent so)."""
        return self.sent_as.get(name, name)

    def as_sent(self, name: str, detail: str) -> str:
        """A refusal's words about column ``name`` (which give its values in the model's unit), with
        the key and value as sent when they were read as another column or unit.

        >>> ReadConditions({"time_min": -60.0}, {"time_min": "time [h]"}, {"time_min": -1}).as_sent(
        ...     "time_min", "value -60 lies outside [0, inf)")
        'value -60 lies outside [0, inf) (sent as time [h]: -1, read as time_min: -60)'
        >>> ReadConditions({"time_min": "-1"}, {"time_min": "time [h]"}, {"time_min": "-1"}).as_sent(
        ...     "time_min", "must be a number")
        "must be a number (sent as time [h]: '-1', read as the column time_min)"
        """
        key = self.key(name)
        if key == name or name not in self.sent_values or name not in self:
            return detail
        if _has_text(self[name]):  # text is read unconverted: its column, not a value, is what was read
            return f"{detail} (sent as {key}: {self.sent_values[name]!r}, read as the column {name})"
        return (f"{detail} (sent as {key}: {shown(self.sent_values[name])}, read as {name}: "
                f"{shown(self[name])})")


def shown(value: Any) -> str:
    """A sent value in a few characters: numbers as %g, a list as [a, b], a range as {low, high}."""
    if isinstance(value, bool | str):
        return str(value)
    if isinstance(value, int | float):
        return f"{value:g}"
    if isinstance(value, Mapping):  # a range or a set: its numbers (a spacing is no value)
        return "{" + ", ".join(f"{k}: {shown(v)}" for k, v in value.items() if not isinstance(v, str)) + "}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(shown(v) for v in value) + "]"
    return str(value)


def read_conditions(model: Model, conditions: Mapping[str, Any] | None,
                    pointer: str = "/conditions") -> ReadConditions:
    """The conditions as the columns of a calibrated model, converted to their units and checked.

    A key that is not one of the model's columns is read by :func:`physics.columns.match_column`: the
    upload's header or another unit of a column's quantity (``temperature_C`` for a model of
    ``temperature_K``, ``relative_humidity_pct`` for ``relative_humidity``) is converted. Values that
    look like a unit slip (:func:`physics.slips.slip`, the upload's rule: a humidity fraction of 50)
    are refused.

    Parameters
    ----------
    model : Model
        A resolved model (:func:`service.models.resolve`); only a calibrated one reads conditions.
    conditions : mapping or None
        Condition columns by name as sent: a value, a list of values or a [low, high] range each.
    pointer : str
        JSON pointer of the conditions in the request.

    Returns
    -------
    ReadConditions
        The conditions by the model's column names, in the calibration data's units, with each one's key
        as sent.

    Raises
    ------
    ProblemError
        422 naming the condition as sent: a unit slip, and every refusal of :func:`check_conditions`.
    """
    if isinstance(conditions, ReadConditions):  # read once (keys now the model's columns): never again
        return conditions
    conditions = dict(conditions or {})
    if not isinstance(model, CalibratedPhysicsModel):
        check_conditions(model, conditions, pointer)
        return ReadConditions(conditions)
    factors, clock = model.calibrated.factors, model.calibrated.clock
    read: dict[str, Any] = {}
    readings: dict[str, Reading] = {}
    unmatched: set[str] = set()
    for sent, value in list(conditions.items()):
        reading = read_key(sent, model.conditions, factors)
        if reading is None:  # check_conditions names it, with the model's columns
            reading = Reading(sent, sent)
            unmatched.add(sent)
        name = reading.name
        if name in clock and _has_text(value):  # ISO 8601 times: hours since the start, as calibrated
            conditions[sent] = value = _clock_hours(value, clock[name])
        if name in read:
            raise validation_problem([{"pointer": pointer_at(pointer, sent), "detail": (
                f"{readings[name].sent!r} is read as {name} too; keep one")}])
        read[name], readings[name] = read_value(reading, value), reading
    items = []
    for name, value in read.items():
        # judged as sent (27 under a kelvin name is degC) and as read, every value of a range
        sent_values = conditions[readings[name].sent]
        unstated = None if name in unmatched else unstated_unit(readings[name], model.headers)
        message = (None if name in factors or name in unmatched or _has_text(value) or unstated
                   else read_slip(readings[name], read_value(Reading("", ""), sent_values)))
        if unstated is not None:
            items.append({"pointer": pointer_at(pointer, readings[name].sent), "detail": unstated})
        if message is not None:
            items.append({"pointer": pointer_at(pointer, readings[name].sent),
                          "detail": f"{message} (a key may "
                          f"carry its unit, as the upload's header: e.g. 'relative humidity [%]', "
                          f"'temperature [degC]')"})
    answer = ReadConditions(read, {name: reading.sent for name, reading in readings.items()},
                            {name: conditions[reading.sent] for name, reading in readings.items()}, readings)
    if not items:  # each value within its column's physical range (a time counted from zero), as sent
        items = [{"pointer": pointer_at(pointer, answer.key(name)), "detail": answer.as_sent(name, detail)}
                 for name, detail in _outside_ranges(model, read, factors).items()]
    if items:
        raise validation_problem(items)
    try:
        check_conditions(model, read, pointer)
    except ProblemError as exc:  # named by the keys as sent
        raise _as_sent(exc, answer, pointer) from None
    return answer


def _outside_ranges(model: CalibratedPhysicsModel, read: Mapping[str, Any], factors: Sequence[str]
                    ) -> dict[str, str]:
    """The refusal of each numeric condition a column check of the model refuses, by column."""
    refused = {}
    for name, value in read.items():
        check = model.column_checks.get(name)
        if check is None or name in factors or _has_text(value):
            continue
        try:
            values = np.asarray(value, dtype=float)
        except (TypeError, ValueError):  # not numbers: the model's own checks name it
            continue
        try:
            check.check(values)
        except InputError as exc:
            refused[name] = str(exc)
    return refused


def _clock_hours(value: Any, start: str) -> Any:
    """ISO 8601 times as hours since ``start`` (a value or a list), as the calibration read its column;
    the value as sent when a cell is no ISO 8601 time (refused as it was)."""
    cells = value if isinstance(value, list) else [value]
    hours = hours_since(cells, start)
    if hours is None:
        return value
    return hours.tolist() if isinstance(value, list) else float(hours[0])


def _has_text(value: Any) -> bool:
    return isinstance(value, str) or (isinstance(value, list) and any(isinstance(v, str) for v in value))


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


def _surrogate_fields(model: Any) -> Callable[[Mapping[str, Any]], dict]:
    """A surrogate's :func:`interval_at`: its interval at a point, each input outside its trained space."""
    space = model.estimator.space

    def fields(point: Mapping[str, Any]) -> dict[str, Any]:
        point = {name: value for name, value in point.items() if name in physics.PARAMETERS}
        prediction = model.estimator.predict_points(point)
        words = space.outside_words(point)
        return {"mu_lower": float(prediction.mu_lower[0]), "mu_upper": float(prediction.mu_upper[0]),
                "in_domain": not words,
                "domain_warnings": [f"{word}: the surrogate extrapolates there and its interval does not "
                                    "apply" for word in words]}

    return fields


def interval_at(model: Any,
                conditions: Mapping[str, float] | None) -> Callable[[Mapping[str, Any]], dict] | None:
    """For a calibrated model or a surrogate, a function of one design point giving
    :func:`prediction_fields` there (a surrogate's: its interval, and whether the point lies in its trained
    space, each input that leaves it said).

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
        point of physics inputs; None for the physics.
    """
    if getattr(model, "kind", None) == "surrogate":
        return _surrogate_fields(model)
    if not isinstance(model, CalibratedPhysicsModel):
        return None

    held = {*model.fixed, *model.fitted}
    shown = ReadConditions.of(conditions).readings  # the warnings speak the keys and units as sent

    def fields(point: Mapping[str, Any]) -> dict[str, Any]:
        # The model's own values are left to it: given as columns, a fitted value would be read as known
        # and its uncertainty left out of the interval.
        point = {name: value for name, value in point.items() if name not in held}
        with np.errstate(all="ignore"):
            return prediction_fields(model.predict({**point, **dict(conditions or {})}, shown=shown))

    return fields


def _as_sent(problem: ProblemError, conditions: ReadConditions, pointer: str = "/conditions") -> ProblemError:
    """The problem with each condition's pointer (under ``pointer``) naming its key as sent, and its words
    the value as sent (the summary in ``detail`` too)."""
    head = pointer + "/"
    items, changed = [], False
    for item in problem.errors or []:
        pointer = str(item.get("pointer", ""))
        if pointer.startswith(head):
            name = pointer[len(head):]
            new = {**item, "pointer": head + conditions.key(name),
                   "detail": conditions.as_sent(name, str(item.get("detail", "")))}
            changed, item = changed or new != item, new
        items.append(item)
    return validation_problem(items, problem.status) if changed else problem


def _input_problem(error: InputError, pointer: str, conditions: ReadConditions) -> ProblemError:
    """The 422 problem of an input a calibrated model refuses: a physics input under ``pointer``, a
    condition under ``/conditions`` by its key as sent (``conditions``: :func:`read_conditions`'s)."""
    where = (f"{pointer}/{error.name}" if error.name in physics.PARAMETERS
             else pointer_at("/conditions", conditions.key(error.name)))
    return validation_problem([{"pointer": where, "detail": str(error)}])


def _model_fields(model: CalibratedPhysicsModel, values: Mapping[str, Any], outside: Any,
                  warnings: list[str]) -> dict[str, Any]:
    """What a calibrated model adds to an answer: its reference, interval bounds and domain.

    ``mu_lower`` and ``mu_upper`` [1] are None for a model stored before intervals (NaN from
    :meth:`CalibratedPhysicsModel.evaluate`), ``in_domain`` None for one stored before domains;
    arrays stay arrays (one value per point).
    """
    bounds = {name: values[name] for name in ("mu_lower", "mu_upper") if name in values}
    if any(np.isnan(value).any() for value in bounds.values()):
        bounds = dict.fromkeys(bounds)
    return {**bounds, "in_domain": None if model.domain is None else ~np.asarray(outside, dtype=bool),
            "domain_warnings": list(warnings), "model": model.reference}


def _load_in_convention(store: Store, model: str, convention: str | None) -> Model:
    """The calibrated model, or a 422 at ``/convention`` when the request names another convention."""
    mu_model = load_mu_model(store, model)
    if convention is not None and convention != mu_model.convention:
        raise validation_problem([{"pointer": "/convention", "detail": f"the model {model} was calibrated "
                                   f"with convention {mu_model.convention!r}; omit convention"}])
    return mu_model


def evaluate_point_with_model(store: Store, model: str, given: Mapping[str, Any],
                              conditions: Mapping[str, float] | None,
                              convention: str | None, input_readings: Mapping[str, Reading] | None = None
                              ) -> dict[str, Any]:
    """The /v1/friction answer of a calibrated model at one point (:meth:`CalibratedPhysicsModel.evaluate`).

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
    convention : str or None
        The convention the request named, None when it named none.
    input_readings : mapping, optional
        How each physics input sent under another key was read (``load [mN]``:
        :attr:`service.schemas.friction.InputKeys.readings`): the domain warnings word it so.

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
        404 for an unknown model, 422 naming a convention other than the model's, an unknown,
        missing or invalid condition, or for non-finite outputs.
    """
    mu_model = _load_in_convention(store, model, convention)
    conditions = read_conditions(mu_model, conditions)
    try:
        with problems():
            evaluation = mu_model.evaluate({**given, **conditions}, mu_model.outputs,
                                           shown={**conditions.readings, **(input_readings or {})})
    except InputError as exc:
        raise _input_problem(exc, "", conditions) from None
    except ProblemError as exc:  # a condition outside its law's domain, by its key as sent
        raise _as_sent(exc, conditions) from None
    values = {name: float(value) for name, value in evaluation.values.items()}
    # NaN bounds are a model stored before intervals (answered null); anything else not finite (an
    # interval overflowing far outside the data, an output out of range) is the inputs' fault.
    bad = next((name for name, value in values.items() if not math.isfinite(value)
                and not (math.isnan(value) and name in ("mu_lower", "mu_upper"))), None)
    if bad is not None:
        raise _not_finite(mu_model, {**given, **conditions}, conditions,
                          f"the model output {bad} is not finite: the inputs are {NOT_FINITE}")
    fields = _model_fields(mu_model, values, evaluation.outside_domain, evaluation.warnings)
    return {**values, "convention": mu_model.convention, **fields,
            "in_domain": None if fields["in_domain"] is None else bool(fields["in_domain"])}


def _not_finite(mu_model: Model, columns: Mapping[str, Any], conditions: ReadConditions, detail: str,
                inputs_at: str = "", index: int | None = None) -> ProblemError:
    """422 for an output that is not finite, at the columns whose values (at point ``index`` of columns)
    lie outside the calibration data, where the interval overflows (a condition by its key as sent); at
    ``inputs_at`` (or ``/``) when none does."""
    pointers = []
    for name, ends in (getattr(mu_model, "domain", None) or {}).items():
        try:
            values = np.asarray(columns[name], dtype=float)
            low, high = float(ends[0]), float(ends[1])
        except (KeyError, TypeError, ValueError, IndexError):  # not given, a factor's labels, no range
            continue
        if index is not None and values.ndim:
            values = values[index]
        if np.any((values < low) | (values > high)):
            pointers.append(pointer_at("/conditions", conditions.key(name)) if name in conditions
                            else pointer_at(inputs_at, name))
    return validation_problem([{"pointer": pointer, "detail": detail}
                               for pointer in pointers or [inputs_at or "/"]])


def _refuse_non_finite(mu_model: Model, points: Mapping[str, Any], conditions: ReadConditions,
                       columns: Mapping[str, Any]) -> None:
    """422 naming the first output and point that is not finite (NaN interval bounds, a model stored
    before intervals, excepted): the interval overflows far outside the data, at the columns outside it."""
    for name, column in columns.items():
        values = np.asarray(column, dtype=float)
        bad = ~np.isfinite(values)
        if name in ("mu_lower", "mu_upper"):
            bad &= ~np.isnan(values)
        if bad.any():
            index = int(np.flatnonzero(bad)[0])
            raise _not_finite(mu_model, points, conditions, f"the model output {name} is not finite at point "
                              f"{index}: the inputs are {NOT_FINITE}", "/points", index)


def evaluate_batch_with_model(store: Store, executor: Executor | None, model: str, points: Mapping[str, Any],
                              conditions: Mapping[str, Any] | None, outputs: list[str] | None,
                              convention: str | None, max_points: int,
                              input_readings: Mapping[str, Reading] | None = None) -> dict[str, Any]:
    """The /v1/friction/batch answer of a calibrated model: columns in, columns out, chunk by chunk.

    The points run through :meth:`CalibratedPhysicsModel.evaluate` (the answer of /v1/friction too)
    on the executor's chunks, each chunk in one vectorized call; the domain is checked once over the
    whole batch, so that each warning counts the batch's points outside.

    Parameters
    ----------
    store : Store
        Where calibrations are kept.
    executor : concurrent.futures.Executor or None
        Where the chunks run (None: inline).
    model : str
        ``"calibrated:<id>"``.
    points : mapping
        Physics inputs the client gave, by name: scalars or lists (they override the model's fixed
        and fitted values).
    conditions : mapping or None
        Condition columns by name (e.g. ``relative_humidity`` [1]): a scalar for every point or a list
        of one value per point.
    outputs : list of str or None
        Physics outputs wanted (all when None); ``mu_effect``, ``mu_lower`` and ``mu_upper`` [1] come
        with ``mu``.
    convention : str or None
        The convention the request named, None when it named none.
    max_points : int
        Most points allowed [1].
    input_readings : mapping, optional
        How each physics input sent under another key was read (``load [mN]``:
        :attr:`service.schemas.friction.InputKeys.readings`): the domain warnings word it so.

    Returns
    -------
    dict
        The outputs as arrays of one value per point, ``model``, ``in_domain`` (bool per point; absent
        for a model stored before domains) and ``domain_warnings`` (one sentence per column outside
        the data: the column, values, range and the number of points).

    Raises
    ------
    ProblemError
        404 for an unknown model; 413 above ``max_points``; 422 naming the field: a convention other
        than the model's, an unknown, missing or invalid condition, lists of different lengths, or a
        point where an output is not finite.
    """
    mu_model = _load_in_convention(store, model, convention)
    conditions = read_conditions(mu_model, conditions)
    inputs, count = column_arrays(dict(points), max_points)
    columns, condition_count = column_arrays(conditions, max_points, "/conditions", conditions.key)
    listed = [name for name, value in conditions.items() if isinstance(value, list)]
    if listed and count != condition_count and any(isinstance(value, list | np.ndarray)
                                                                 for value in points.values()):
        raise validation_problem([{"pointer": pointer_at("/conditions", conditions.key(name)),
                                   "detail": f"has {condition_count} "
                                   f"values but the points have {count}; lists must share one length"}
                                  for name in listed])
    count = max(count, condition_count)
    everything = {**inputs, **columns}
    names = [str(name) for name in outputs] if outputs else list(physics.OUTPUTS)
    if "mu" in names:
        names += ["mu_effect", "mu_lower", "mu_upper"]
    # The conditions the terms do not read matter to the domain only, checked below on the whole batch.
    # The data cloud of the domain (and so the interval's widening) reads them too.
    read = {name: value for name, value in everything.items() if name in mu_model.column_checks}
    try:
        values = evaluate_in_chunks(executor, read, count, names, mu_model, pointer="/points")
    except InputError as exc:
        raise _input_problem(exc, "/points", conditions) from None
    except ProblemError as exc:
        raise _as_sent(exc, conditions) from None
    _refuse_non_finite(mu_model, everything, conditions, values)
    with np.errstate(all="ignore"):
        inside, warnings = mu_model.calibrated.domain_check(everything,
                                                            {**conditions.readings, **(input_readings or {})})
    outside = None if inside is None else ~np.broadcast_to(inside, (count,))
    answer = {**values, **_model_fields(mu_model, values, outside, warnings)}
    return {name: value for name, value in answer.items() if value is not None}


def with_conditions(model: Model, conditions: Mapping[str, float] | None,
                    pointer: str = "/conditions") -> Callable[[Mapping[str, Any]], Any]:
    """A model's ``mu_model(points)`` with constant condition columns added to every point.

    Shared by every route that runs a stored model on points it generates itself
    (optimizations, surrogates trained on a calibrated model).

    Parameters
    ----------
    model : Model
        A resolved model (:func:`service.models.resolve`); a calibrated one names the extra columns
        it needs in ``required_columns``.
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
        needs is missing, or a value looks like a unit slip (:func:`read_conditions`).
    """
    conditions = read_conditions(model, conditions, pointer)
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
