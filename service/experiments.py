"""Which measurements to take next, in the service: :mod:`calibrate.experiments` on a stored calibration.

:func:`next_experiments_job` checks a request against the stored calibration at once (422 naming the
field) and returns the job's work: rebuild the calibrated model and its data (stored beside the
report since this feature; older calibrations have no data, so no rivals and nothing drawn under the
runs), refit the rivals, propose. :func:`first_experiments_job` does the same on the declared physics.
The result's plot is drawn from the stored result when asked (:func:`plan_png`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from microbearing import physics
from microbearing.calibrate import CalibratedModel
from microbearing.calibrate.design import DesignError
from microbearing.calibrate.experiments import (
    ExperimentPlan,
    ExperimentRequest,
    check_identifiable,
    check_request,
    first_experiments,
    held_out_scale,
    next_experiments,
    physics_model,
    plan_png,
    rival_models,
    rival_terms,
)
from microbearing.physics.columns import Reading, read_key
from microbearing.physics.slips import read_slip, unstated_unit

from .calibrations import MODEL_PREFIX, ReadConditions, load_calibration, stored_dataset
from .models import stored_calibrated
from .problems import ProblemError, pointer_at, validation_problem
from .schemas.experiments import FirstExperimentsRequest, NextExperimentsRequest
from .store import Store

__all__ = ["JOB_KIND", "first_experiments_job", "next_experiments_job", "plan_png"]

#: Kind of the jobs that propose runs (their results at /v1/jobs/{id}/result).
JOB_KIND = "experiments"


_FIELDS = ("space", "envelope", "fixed", "planned", "goal", "runs")


def _field_problem(exc: ValueError, sent: Mapping[str, ReadConditions] | None = None) -> ProblemError:
    """A 422 naming the field a ValueError of calibrate.experiments starts with (``space.load_N: ...``,
    ``planned.0.RH: ...``); ``sent``: per field (``planned.<i>`` per planned run), its columns as read
    (:func:`_model_columns`), whose keys as sent the pointer names and whose values as sent the words add."""
    message = str(exc)
    head = message.split(": ", 1)[0] if ": " in message else ""
    field, _, key = head.partition(".")
    run, _, name = key.partition(".")
    if field == "planned" and run.isdigit() and name:  # planned.<i>.<column>: a planned run's column
        columns = (sent or {}).get(f"planned.{run}", ReadConditions({}))
        return validation_problem([{"pointer": pointer_at(f"/planned/{run}", columns.key(name)),
                                    "detail": columns.as_sent(name, message)}])
    if field in _FIELDS:
        columns = (sent or {}).get(field, ReadConditions({}))
        pointer = pointer_at(f"/{field}", *([columns.key(key)] if key else []))
        return validation_problem([{"pointer": pointer, "detail": columns.as_sent(key, message)}])
    if head and " " not in head:
        return validation_problem([{"pointer": "/" + head.replace(".", "/"), "detail": message}])
    field = "goal" if "goal" in message else "space"
    return validation_problem([{"pointer": f"/{field}", "detail": message}])


def _check_planned(runs: list[ReadConditions]) -> None:
    """422 naming each value of a planned run that its physics input does not take (``4.5`` balls), by
    its key and value as sent.

    The proposal would otherwise meet the value only inside the job, as a failure of the space.
    """
    errors = []
    for i, run in enumerate(runs):
        for name, value in run.items():
            if name in physics.PARAMETERS:
                try:
                    physics.validate(name, value)
                except ValueError as exc:
                    errors.append({"pointer": pointer_at(f"/planned/{i}", run.key(name)),
                                   "detail": run.as_sent(name, str(exc))})
    if errors:
        raise validation_problem(errors)


def _space(columns: Mapping[str, Any] | None) -> dict[str, Any] | None:
    if columns is None:
        return None
    return {k: (v.model_dump() if hasattr(v, "model_dump") else list(v)) for k, v in columns.items()}


def _span_values(column: Any) -> list[float]:
    """The numbers of a space's column (a range's ends, a set's values) or of a fixed value."""
    if isinstance(column, Mapping):
        given = column["values"] if "values" in column else [column.get("low"), column.get("high")]
    else:
        given = column if isinstance(column, list | tuple) else [column]
    return [v for v in given if isinstance(v, int | float) and not isinstance(v, bool)]


def _converted(reading: Reading, column: Any) -> Any:
    """A space's column (or a fixed value) in the unit of the column ``reading`` reads it as."""
    if not reading.reading or isinstance(column, bool):
        return column
    if isinstance(column, Mapping):
        if "values" in column:
            return {**column, "values": [reading.convert(v) for v in column["values"]]}
        return {**column, "low": reading.convert(column["low"]), "high": reading.convert(column["high"])}
    if isinstance(column, list | tuple):
        return [reading.convert(v) for v in column]
    return reading.convert(column)


def _model_columns(model: CalibratedModel | None, columns: Mapping[str, Any] | None, pointer: str
                   ) -> ReadConditions | None:
    """A space's, envelope's, fixed values' or planned run's columns as the calibrated model's (None: the
    declared physics'), as /v1/friction reads its conditions: a physics input under the upload's spelling
    (``load [mN]``) and a condition under the upload's header or another unit of a column's quantity are
    converted (:func:`physics.columns.read_key`), and a column whose values (a range's both ends, a set's
    every value) look like a unit slip is refused (:func:`physics.slips.read_slip`), naming the key as
    sent; each column keeps its key and value as sent (:class:`ReadConditions`) for later refusals."""
    if columns is None:
        return None
    conditions, factors = ((), ()) if model is None else (model.conditions, model.factors)
    headers = {} if model is None else model.headers
    out: dict[str, Any] = {}
    sent_as: dict[str, str] = {}
    readings: dict[str, Reading] = {}
    for sent, column in columns.items():
        reading = read_key(sent, conditions, factors)
        # a key nothing reads: check_request names it, with the model's columns; a factor holds labels
        judged = reading is not None and sent not in factors
        # a slip is refused here, though a door that predicts only warns of a physics input's: the runs
        # proposed become rows of the next upload, which refuses them
        message = (unstated_unit(reading, headers) or read_slip(reading, _span_values(column))
                   if judged else None)
        reading = reading or Reading(sent, sent)
        if isinstance(column, bool) and reading.name not in physics.PARAMETERS:  # a flag is no condition
            message = f"must be a number, not {str(column).lower()}: only a physics flag takes true or false"
        if isinstance(column, str):  # a group label: the runs serve every group alike
            message = (f"{sent} is a factor column (group labels): the runs are planned for the model over "
                       f"its groups, a new one's spread in the interval; leave it out" if sent in factors
                       else f"must be a number, not {column!r}: only a factor column holds labels"
                       + ("" if reading.name == sent else f" (sent as {sent}: {column!r}, read as the column "
                                                          f"{reading.name})"))
        if message is not None:
            raise validation_problem([{"pointer": pointer_at(pointer, sent), "detail": message}])
        if reading.name in out:
            raise validation_problem([{"pointer": pointer_at(pointer, sent), "detail": (
                f"{sent_as[reading.name]!r} is read as {reading.name} too; keep one")}])
        out[reading.name], sent_as[reading.name] = _converted(reading, column), sent
        readings[reading.name] = reading
    return ReadConditions(out, sent_as, {name: columns[key] for name, key in sent_as.items()}, readings)


@dataclass(frozen=True)
class _Read:
    """A request's columns as the model reads them (:func:`_model_columns`), each field keeping its keys and
    values as sent for a refusal's words."""

    space: ReadConditions | None
    envelope: ReadConditions | None
    fixed: ReadConditions | None
    runs: list[ReadConditions]
    planned: list[dict[str, Any]] | None  # the planned runs as plain columns (None: none given)

    def readings(self) -> dict[str, Reading]:
        """How each column was read from its key as sent (the envelope's and fixed values' first, the
        space's winning), for words in the request's units."""
        return {name: reading for columns in (self.fixed, self.envelope, self.space) if columns is not None
                for name, reading in columns.readings.items()}

    @property
    def sent(self) -> dict[str, ReadConditions]:
        """Each field's columns (``planned.<i>`` per planned run), for :func:`_field_problem`."""
        fields = {"space": self.space, "envelope": self.envelope, "fixed": self.fixed}
        return ({field: columns for field, columns in fields.items() if columns is not None}
                | {f"planned.{i}": run for i, run in enumerate(self.runs)})


def _read_request(model: CalibratedModel | None, body: Any) -> _Read:
    """A request's space, envelope, fixed values and planned runs read against ``model`` (None: the
    declared physics), each planned run's physics inputs checked (422 naming the key as sent)."""
    runs = [_model_columns(model, run, f"/planned/{i}") for i, run in enumerate(body.planned or [])]
    read = _Read(_model_columns(model, _space(body.space), "/space"),
                 _model_columns(model, _space(body.envelope), "/envelope"),
                 _model_columns(model, body.fixed, "/fixed"), runs,
                 None if body.planned is None else [dict(run) for run in runs])
    _check_planned(runs)
    return read


def _document(plan: ExperimentPlan, model: str, job_id: str | None,
              read: _Read | None = None) -> dict[str, Any]:
    """The result: the plan, the model, and the plot's URL when it ran as a job (None from the CLI); each
    run also under the request's keys as sent, in their units (:func:`_as_sent`)."""
    url = None if job_id is None else f"/v1/experiments/{job_id}/plot.png"
    document = {**plan.to_dict(), "model": model, "plot_url": url}
    if read is not None:
        document["runs"] = [{**run, "as_sent": _as_sent(run, read)} for run in document["runs"]]
        # the plot draws each column under its key as sent, in its unit (calibrate.plan_plot)
        sent_as = {name: reading.sent for name, reading in read.readings().items()}
        document["plot"] = {**document["plot"], "sent_as": sent_as}
    return document


def _as_sent(run: Mapping[str, Any], read: _Read) -> dict[str, Any]:
    """A run's settings under the space's and fixed values' keys as sent, each in its unit (what a technician
    sets: ``{"load [mN]": 3, "RH (%)": 85}``, where the run's own columns say load_N 0.003 and RH 0.85)."""
    settings: dict[str, Any] = {}
    for columns in (read.space, read.fixed):
        values = {name: run.get(name, run["inputs"].get(name, run["conditions"].get(name)))
                  for name in columns or {}}
        if columns is not None:
            settings.update(columns.shown_as_sent({k: v for k, v in values.items() if v is not None}))
    return settings


def next_experiments_job(store: Store, calibration_id: str, body: NextExperimentsRequest
                         ) -> Callable[[Any], dict[str, Any]]:
    """Check a request for the next runs of a stored calibration; the job's work.

    Raises
    ------
    ProblemError
        404 for an unknown calibration; 422 naming the field for an invalid space, fixed value or
        planned run, or ``goal: discriminate`` on a calibration stored before its data were (its rivals
        cannot be refitted; one with no rival explores where the data say least).
    """
    stored = load_calibration(store, calibration_id)
    model = stored_calibrated(stored.metadata)
    report = stored.metadata["report"]
    # a planned run's conditions read as the space's (the upload's headers and units)
    read = _read_request(model, body)
    space, envelope, fixed, planned, sent = read.space, read.envelope, read.fixed, read.planned, read.sent
    try:
        check_request(model, space, fixed, envelope, planned)
        if model.covariance is None or model.noise_std_log is None:
            raise DesignError("the calibration was stored before models had a covariance; calibrate again")
    except ValueError as exc:
        raise _field_problem(exc, sent) from None
    if body.goal == "predict" and envelope is None:
        raise validation_problem([{"pointer": "/envelope", "detail": "goal predict needs an envelope"}])
    dataset = stored_dataset(stored.arrays, model.fixed, model.headers)  # an old one's headers: its intake's
    # predict also hedges against the laws that came near to replacing a chosen term
    near = body.goal == "predict"
    has_rivals = dataset is not None and bool(rival_terms(report, dataset, [t for t, _ in model.terms], near))
    if body.goal == "discriminate":
        if dataset is None:
            raise validation_problem([{"pointer": "/goal", "detail": (
                "this calibration was stored before calibrations kept their data, so its rivals cannot be "
                "refitted; calibrate again, or use goal parameters or predict")}])
        # Without a rival the runs explore where the data say least (calibrate.experiments: the reason
        # is the result's first warning).

    # predict hedges over the rivals too when there are any (model-robust: bench/RESULTS.md, issue 26).
    def work(ctx) -> dict[str, Any]:
        rivals = (rival_models(report, dataset, model, near=near) if body.goal != "parameters" and has_rivals
                  else [])
        # a refit of the model's terms, for the promise of predict alone (its rivals read held out)
        scale = held_out_scale(report, dataset, model) if rivals and body.goal == "predict" else 1.0
        ctx.progress(0.2)
        try:
            request = ExperimentRequest(space, body.runs, body.goal, envelope=envelope, fixed=fixed,
                                        planned=planned, seed=body.seed, shown=read.readings())
            plan = next_experiments(model, request, rivals=rivals,
                                    data=None if dataset is None else dataset.columns(),
                                    progress=lambda f: ctx.progress(0.2 + 0.8 * f),
                                    held_out_scale=scale)
        except ValueError as exc:
            raise _field_problem(exc, sent) from None
        document = _document(plan, MODEL_PREFIX + calibration_id, ctx.job_id, read)
        return {**document, "calibration_id": calibration_id}

    return work


def first_experiments_job(body: FirstExperimentsRequest) -> Callable[[Any], dict[str, Any]]:
    """Check a request for a first design on the physics; the job's work.

    Raises
    ------
    ProblemError
        422 naming the field.
    """
    read = _read_request(None, body)
    space, envelope, fixed, planned, sent = read.space, read.envelope, read.fixed, read.planned, read.sent
    fit_parameters = [str(p) for p in body.fit_parameters]
    unknown = [k for k in (body.guess or {}) if k not in fit_parameters]
    if unknown:
        raise validation_problem([{"pointer": pointer_at("/guess", k), "detail": "not one of fit_parameters"}
                                  for k in unknown])
    if body.goal == "predict" and envelope is None:
        raise validation_problem([{"pointer": "/envelope", "detail": "goal predict needs an envelope"}])

    try:  # the request's checks, at once (the solve comes in the job)
        model, fixed_all = physics_model(fit_parameters, body.noise_std_log, body.guess, fixed,
                                         str(body.convention))
        response = check_request(model, space, fixed_all, envelope, planned)
        request = ExperimentRequest(space, body.runs, body.goal, envelope, fixed, planned, body.seed,
                                    read.readings())
        check_identifiable(response, request)  # no job for parameters no run can tell
    except ValueError as exc:
        raise _field_problem(exc, sent) from None

    def work(ctx) -> dict[str, Any]:
        try:
            plan = first_experiments(fit_parameters, request, body.noise_std_log, body.guess,
                                     str(body.convention), ctx.progress)
        except ValueError as exc:
            raise _field_problem(exc, sent) from None
        return {**_document(plan, "physics", ctx.job_id, read), "calibration_id": None}

    return work


