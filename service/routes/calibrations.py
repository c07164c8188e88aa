"""``/v1/calibrations``: calibrate the model on measured data (a job), the report and its plots."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Request
from fastapi.responses import JSONResponse, Response
from starlette.concurrency import run_in_threadpool

from microbearing import physics
from microbearing.calibrate import DataError, Dataset, check_request, parse_assignments, parse_csv, parse_rows

from ..calibrations import calibration_view, data_problem, load_calibration, run_calibration
from ..deps import JobsDep, SettingsDep, StoreDep
from ..jobs import JobContext, JobManager
from ..limits import check_rows, csv_data_rows
from ..problems import ProblemError, problem_responses, validation_problem
from ..schemas.base import Convention, ConventionName
from ..schemas.calibrations import CalibrationRequest, CalibrationResult, FittableParameterName
from ..store import Store
from .jobs import ACCEPTED_RESPONSE, accepted

__all__ = ["router"]

router = APIRouter(prefix="/v1/calibrations", tags=["calibrations"])

_DEFAULT_CONVENTION = Convention(physics.DEFAULT_CONVENTION)

_CSV_TEXT = ("CSV with a header row: physics input columns, mu_measured [1], optionally mu_measured_std [1], "
             "and any other condition columns: numbers, or labels (a factor, e.g. specimen S1, S2, ...).")
# The body is read as CSV whatever its declared type; application/octet-stream is listed too because
# generated clients (openapi-python-client) send raw bytes that way and have no text bodies.
_CSV_BODY = {"requestBody": {"required": True, "content": {
    "text/csv": {"schema": {"type": "string", "description": _CSV_TEXT}},
    "application/octet-stream": {"schema": {"type": "string", "format": "binary",
                                            "description": _CSV_TEXT}}}}}


def _check(dataset: Dataset, fit_parameters: list[str], folds: int, query: bool) -> None:
    try:
        check_request(dataset, fit_parameters, folds)
    except ValueError as exc:
        field = str(exc).split(" ", 1)[0].rstrip(":")
        raise validation_problem([{"parameter": field, "detail": str(exc)} if query and field != "data"
                                  else {"pointer": f"/{field}", "detail": str(exc)}]) from None


def _submit(jobs: JobManager, store: Store, record: dict, dataset: Dataset, fit_parameters: list[str],
            folds: int, convention: str) -> JSONResponse:
    def work(ctx: JobContext) -> dict:
        return run_calibration(store, dataset, fit_parameters, folds, convention, progress=ctx.progress)

    return accepted(jobs.submit("calibration", record, work))


@router.post("", operation_id="create_calibration", status_code=202,
             responses={**ACCEPTED_RESPONSE, **problem_responses()})
def create_calibration(body: CalibrationRequest, store: StoreDep, jobs: JobsDep,
                       settings: SettingsDep) -> JSONResponse:
    """Calibrate on JSON rows: fit the named parameters, add the terms the data need, report (a job).

    The job's result is the calibration report (see ``GET /v1/calibrations/{id}``). More than
    MICROBEARING_MAX_CALIBRATION_ROWS rows get 413.
    """
    check_rows(len(body.data), settings.max_calibration_rows, "/data")
    fixed = body.fixed.model_dump(exclude_none=True)
    try:
        dataset = parse_rows(body.data, fixed, body.factors)
    except DataError as exc:
        raise data_problem(exc.errors) from None
    fit_parameters = [str(name) for name in body.fit_parameters]
    _check(dataset, fit_parameters, body.folds, query=False)
    record = {"rows": dataset.n_points, "columns": sorted(dataset.columns()),
              "factors": sorted(dataset.factors), "fixed": fixed,
              "fit_parameters": fit_parameters, "folds": body.folds, "convention": str(body.convention)}
    return _submit(jobs, store, record, dataset, fit_parameters, body.folds, str(body.convention))


@router.post("/csv", operation_id="create_calibration_from_csv", status_code=202,
             responses={**ACCEPTED_RESPONSE, **problem_responses()}, openapi_extra=_CSV_BODY)
async def create_calibration_from_csv(
    request: Request, store: StoreDep, jobs: JobsDep, settings: SettingsDep,
    fit_parameters: Annotated[list[FittableParameterName], Query(  # type: ignore[valid-type]
        description="Declared parameters to fit (repeat the parameter for several).")] = [],  # noqa: B006
    fixed: Annotated[list[str], Query(
        description="Physics inputs fixed for every row, as name=value in their units (repeatable).")] = [],  # noqa: B006
    folds: Annotated[int, Query(ge=2, le=20, description="Cross-validation folds [1].")] = 5,
    factors: Annotated[list[str], Query(max_length=20, description=(
        "Condition columns to read as group labels even when they hold numbers (repeatable); a column "
        "with no number in it is a factor anyway."))] = [],  # noqa: B006
    convention: Annotated[ConventionName, Query(  # type: ignore[valid-type]
        description="Reading of the paper's ambiguous ball-ball terms.")] = _DEFAULT_CONVENTION,
) -> JSONResponse:
    """Calibrate on an uploaded CSV file (``Content-Type: text/csv`` or ``application/octet-stream``),
    as ``POST /v1/calibrations``."""
    text = await request.body()
    check_rows(csv_data_rows(text), settings.max_calibration_rows, "The CSV body")  # before parsing it
    try:
        fixed_values = parse_assignments(fixed)
    except DataError as exc:
        raise validation_problem([{"parameter": "fixed", "detail": f"{e['column']}: {e['message']}"}
                                  for e in exc.errors]) from None
    try:
        dataset = await run_in_threadpool(parse_csv, text, fixed_values, factors)
    except DataError as exc:
        raise data_problem(exc.errors, fixed_pointer=None, data_pointer=None) from None
    names = [str(name) for name in fit_parameters]
    _check(dataset, names, folds, query=True)
    record = {"rows": dataset.n_points, "columns": sorted(dataset.columns()),
              "factors": sorted(dataset.factors), "fixed": fixed_values,
              "fit_parameters": names, "folds": folds, "convention": str(convention)}
    return _submit(jobs, store, record, dataset, names, folds, str(convention))


@router.get("/{calibration_id}", operation_id="get_calibration", response_model=CalibrationResult,
            responses=problem_responses(404))
def get_calibration(calibration_id: str, store: StoreDep) -> JSONResponse:
    """The report of a finished calibration."""
    stored = load_calibration(store, calibration_id)
    return JSONResponse(calibration_view(stored.id, stored.metadata))


@router.get("/{calibration_id}/plots/{plot_name}.png", operation_id="get_calibration_plot",
            response_class=Response,
            responses={200: {"description": "The plot as PNG.",
                             "content": {"image/png": {"schema": {"type": "string", "format": "binary"}}}},
                       **problem_responses(404)})
def get_calibration_plot(calibration_id: str, plot_name: str, store: StoreDep) -> Response:
    """A plot of a calibration: ``effect_<k>``, ``residuals``, ``measured_vs_predicted`` (older calibrations:
    ``residual_before``, ``residual_after`` or ``residual``)."""
    stored = load_calibration(store, calibration_id)
    if plot_name not in stored.arrays:
        raise ProblemError(404, f"Calibration {calibration_id} has no plot {plot_name!r}; it has "
                                f"{', '.join(sorted(stored.arrays)) or 'none'}.")
    return Response(stored.arrays[plot_name].tobytes(), media_type="image/png")
