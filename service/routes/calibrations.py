"""``/v1/calibrations``: calibrate the model on measured data (a job), the report and its plots."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Body, Depends, Query, Request
from fastapi.responses import JSONResponse, Response
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import UploadFile

from microbearing import physics
from microbearing.calibrate import (
    DataError,
    Dataset,
    Intake,
    check_request,
    default_folds,
    parse_assignments,
    read_csv,
    read_rows,
)
from microbearing.calibrate.fit import check_fit_parameters
from microbearing.calibrate.plausibility import check_plausible
from microbearing.calibrate.tabular import DECIMALS, SEPARATORS, accepted_names

from ..calibrations import (
    DATA_PREFIX,
    KIND,
    calibration_summary,
    calibration_view,
    data_problem,
    delete_calibration,
    fitting_statement,
    load_calibration,
)
from ..deps import JobsDep, SettingsDep, StoreDep
from ..job_kinds import calibration_inputs, calibration_work
from ..jobs import JobManager
from ..limits import check_table, csv_data_rows, csv_header_columns
from ..problems import ProblemError, problem_responses, validation_problem
from ..schemas import examples
from ..schemas.base import Convention, ConventionName, read_body
from ..schemas.calibrations import (
    CalibrationList,
    CalibrationRequest,
    CalibrationResult,
    CsvReading,
    FittableParameterName,
)
from ..store import Store
from .jobs import ACCEPTED_RESPONSE, accepted, calibration_links
from .pages import DEFAULT_PAGE_LIMIT, PageToken, page_limit, page_of, page_start

__all__ = ["router"]

router = APIRouter(prefix="/v1/calibrations", tags=["calibrations"])

Separator = Literal["auto", "comma", "semicolon", "tab"]
Decimal = Literal["auto", "point", "comma"]
assert set(Separator.__args__) == {"auto", *SEPARATORS} and set(Decimal.__args__) == {"auto", *DECIMALS}

_DEFAULT_CONVENTION = Convention(physics.DEFAULT_CONVENTION)

_CSV_TEXT = ("CSV with a header row: physics input columns, mu_measured [1], optionally mu_measured_std [1], "
             "and any other condition columns: numbers, or labels (a factor, e.g. specimen S1, S2, ...). "
             "Separated by comma, semicolon or tab (detected, stated by Excel's first line sep=; or stated "
             "by the query parameter separator); decimal point or, with semicolon or tab, decimal "
             "comma (detected, or stated by decimal); UTF-8 with or without BOM, UTF-16 with BOM, or "
             "else Windows-1252 (Latin-1), as the intake says; blank lines and empty columns at the end "
             "are ignored, and the columns named in ignore. Column names may carry units, converted to "
             "SI: " + accepted_names() + ".")
_CSV_EXAMPLE = ("balls;load [mN];speed [mm/s];relative humidity [%];mu_measured\r\n"
                "4;13,2;70;38;0,01448\r\n4;4,4;92;65;0,02287\r\n4;4,4;113;63;0,02302\r\n")
# The body is read as CSV whatever its declared type; application/octet-stream is listed too because
# generated clients (openapi-python-client) send raw bytes that way and have no text bodies. A
# browser's form and `curl -F file=@lab.csv` send the file as multipart/form-data, in the field file.
_CSV_BODY = {"requestBody": {"required": True, "content": {
    "text/csv": {"schema": {"type": "string", "description": _CSV_TEXT}, "example": _CSV_EXAMPLE},
    "application/octet-stream": {"schema": {"type": "string", "format": "binary",
                                            "description": _CSV_TEXT}},
    "multipart/form-data": {"schema": {
        "type": "object", "required": ["file"], "additionalProperties": False,
        "properties": {"file": {"type": "string", "format": "binary", "description": _CSV_TEXT}}},
        "encoding": {"file": {"contentType": "text/csv, application/octet-stream"}}}}}}
#: Most form fields a multipart upload may carry (the one read is file; the others are named in a 422).
_MAX_FORM_FIELDS = 20


def _check(dataset: Dataset, fit_parameters: list[str], folds: int, query: bool,
           intake: Intake | None = None, rows: Sequence[Mapping[str, Any]] = ()) -> None:
    try:
        check_request(dataset, fit_parameters, folds)
    except DataError as exc:  # implausible values (calibrate.plausibility), one item per column
        # a column named by its key as sent (temp [K], not temp_K); a file's by its letter and header cell
        errors = ([{**e, "column": dataset.headers.get(e.get("column"), e.get("column"))} for e in exc.errors]
                  if intake is None else intake.locate(exc.errors))
        raise data_problem(errors, data_pointer=None if query else "/data", rows=rows) from None
    except ValueError as exc:
        field = str(exc).split(" ", 1)[0].rstrip(":")
        raise validation_problem([{"parameter": field, "detail": str(exc)} if query and field != "data"
                                  else {"pointer": f"/{field}", "detail": str(exc)}]) from None


def _submit(jobs: JobManager, store: Store, record: dict, dataset: Dataset, fit_parameters: list[str],
            folds: int, convention: str, intake: dict) -> JSONResponse:
    inputs = calibration_inputs(dataset, fit_parameters, folds, convention, intake)
    work = calibration_work(store, dataset, fit_parameters, folds, convention, intake)
    store.check_model_room()  # 507 now rather than a failed job later
    return accepted(jobs.submit("calibration", record, work, inputs=inputs))


def _columns_of(dataset: Dataset) -> list[str]:
    """Every column of the data by its name in SI: physics inputs, conditions and factors (groups)."""
    return sorted([*dataset.columns(), *dataset.factors])


@router.post("", operation_id="create_calibration", status_code=202,
             responses={**ACCEPTED_RESPONSE, **problem_responses(507)})
def create_calibration(body: Annotated[CalibrationRequest, Body(openapi_examples=examples.media_examples(
                           small=("mu_pivot fitted on 24 measurements", examples.CALIBRATION),
                           units=("The same, load in mN and speed in mm/s", examples.CALIBRATION_UNITS)))],
                       store: StoreDep, jobs: JobsDep,
                       settings: SettingsDep) -> JSONResponse:
    """Calibrate on JSON rows: fit the named parameters, add the terms the data need, report (a job).

    The job's result is the calibration report (see ``GET /v1/calibrations/{id}``). More than
    MICROBEARING_MAX_CALIBRATION_ROWS rows or MICROBEARING_MAX_CALIBRATION_COLUMNS columns get 413.
    """
    check_table(len(body.data), settings.max_calibration_rows, "rows", "/data")
    check_table(len(set().union(*body.data)), settings.max_calibration_columns, "columns", "/data")
    fixed = body.fixed.model_dump(exclude_none=True)
    try:
        dataset, intake = read_rows(body.data, fixed, body.factors, body.ignore)
    except DataError as exc:
        raise data_problem(exc.errors, rows=body.data) from None
    fit_parameters = [str(name) for name in body.fit_parameters]
    folds = body.folds if "folds" in body.model_fields_set else default_folds(dataset.n_points)
    _check(dataset, fit_parameters, folds, query=False, rows=body.data)
    intake.fitting = fitting_statement(dataset, fit_parameters)
    record = {"rows": dataset.n_points, "columns": _columns_of(dataset),
              "factors": sorted(dataset.factors), "fixed": fixed,
              "fit_parameters": fit_parameters, "folds": folds, "convention": str(body.convention),
              "intake": intake.to_dict()}
    return _submit(jobs, store, record, dataset, fit_parameters, folds, str(body.convention),
                   intake.to_dict())


class CsvDialect:
    """The query parameters of a CSV upload's dialect: its separator and decimal mark (None: detected)."""

    def __init__(self, separator: Annotated[Separator, Query(
                     description="Column separator: auto (the file's first line sep=; as Excel reads it, or "
                                 "detected among comma, semicolon and tab), comma, semicolon or tab (a "
                                 "sep= line that disagrees gets 422).")] = "auto",
                 decimal: Annotated[Decimal, Query(
                     description="Decimal mark: auto (a comma when numbers use one and none a point), point "
                                 "or comma.")] = "auto") -> None:
        self.separator = None if separator == "auto" else separator
        self.decimal = None if decimal == "auto" else decimal


class CsvOptions:
    """How to read an uploaded CSV file: fixed inputs, factors, the dialect (query parameters)."""

    def __init__(
        self,
        fixed: Annotated[list[str], Query(description=(
            "Physics inputs fixed for every row, as name=value in their units (repeatable)."))] = [],  # noqa: B006
        factors: Annotated[list[str], Query(max_length=20, description=(
            "Condition columns to read as group labels even when they hold numbers (repeatable); a column "
            "with no number in it is a factor anyway."))] = [],  # noqa: B006
        ignore: Annotated[list[str], Query(max_length=100, description=(
            "Columns to leave out, by their header cell as in the file or the name they are read as "
            "(repeatable), e.g. a comment, or an operator column that should not become groups."))
        ] = [],  # noqa: B006
        dialect: Annotated[CsvDialect, Depends()] = None,  # type: ignore[assignment]  (FastAPI fills it)
    ) -> None:
        self.fixed, self.factors, self.ignore, self.dialect = fixed, factors, ignore, dialect


async def _uploaded(request: Request) -> tuple[bytes | bytearray, str | None]:
    """The uploaded file: the raw body, or a multipart/form-data upload's field ``file``; and, for the
    latter, a sentence saying how it came."""
    media = request.headers.get("content-type", "").split(";", 1)[0].strip().lower()
    if media != "multipart/form-data":
        return await read_body(request), None
    # Starlette spools a file part to disk past 1 MB; the body-size limit holds while it streams.
    async with request.form(max_files=1, max_fields=_MAX_FORM_FIELDS) as form:
        others = sorted({name for name in form if name != "file"})
        items = form.getlist("file")
        if others or len(items) != 1:
            errors = [{"pointer": f"/{name}", "detail": f"the form field {name!r} is not read: send the CSV "
                                                        "in the field file, and options as query parameters "
                                                        f"(?{name}=...)"} for name in others]
            if len(items) != 1:
                fields = f"{len(items) or 'no'} field{'s' * (len(items) != 1)} file"
                errors.append({"pointer": "/file", "detail": (
                    "a multipart/form-data upload carries the CSV file in one field named file (curl -F "
                    f"file=@lab.csv); this one has {fields}")})
            raise validation_problem(errors)
        item = items[0]
        if isinstance(item, UploadFile):
            return await item.read(), f"uploaded as multipart/form-data, field file ({item.filename!r})"
        return item.encode("utf-8"), "uploaded as multipart/form-data, field file (a text field)"


def _counted(text: bytes) -> bytes:
    """The body as its rows and columns are counted: without Excel's ``sep=`` first line."""
    start = 3 if text.startswith(b"\xef\xbb\xbf") else 0
    if text[start:start + 4].lower() == b"sep=":
        return text[text.find(b"\n", start) + 1:] if b"\n" in text else b""
    return text


async def _read_upload(request: Request, settings: Any, options: CsvOptions) -> tuple[Dataset, Intake, dict]:
    """The uploaded CSV as a data set, its intake and the fixed values, or a 4xx problem."""
    text, how = await _uploaded(request)
    counted = _counted(text)  # counted before parsing
    check_table(csv_data_rows(counted), settings.max_calibration_rows, "rows", "The CSV body")
    separator = SEPARATORS.get(options.dialect.separator or "")
    check_table(csv_header_columns(counted, separator), settings.max_calibration_columns, "columns",
                "The CSV body's header")
    try:
        fixed_values = parse_assignments(options.fixed)
    except DataError as exc:
        raise validation_problem([{"parameter": "fixed", "detail": f"{e['column']}: {e['message']}"}
                                  for e in exc.errors]) from None
    try:
        dataset, intake = await run_in_threadpool(read_csv, text, fixed_values, options.dialect.separator,
                                                  options.dialect.decimal, options.factors, options.ignore)
    except DataError as exc:
        raise data_problem(exc.errors, fixed_pointer=None, data_pointer=None) from None
    if how is not None:
        intake.notes.append(how)
    return dataset, intake, fixed_values


@router.post("/csv", operation_id="create_calibration_from_csv", status_code=202,
             responses={**ACCEPTED_RESPONSE, **problem_responses(507)}, openapi_extra=_CSV_BODY)
async def create_calibration_from_csv(
    request: Request, store: StoreDep, jobs: JobsDep, settings: SettingsDep,
    fit_parameters: Annotated[list[FittableParameterName], Query(  # type: ignore[valid-type]
        description="Declared parameters to fit (repeat the parameter for several).")] = [],  # noqa: B006
    folds: Annotated[int, Query(ge=2, le=20, description=(
        "Cross-validation folds [1]; when not given, 5, or half the rows when there are fewer "
        "than 10."))] = 5,
    convention: Annotated[ConventionName, Query(  # type: ignore[valid-type]
        description="Reading of the paper's ambiguous ball-ball terms.")] = _DEFAULT_CONVENTION,
    options: Annotated[CsvOptions, Depends()] = None,  # type: ignore[assignment]  (FastAPI fills it)
) -> JSONResponse:
    """Calibrate on an uploaded CSV file (``Content-Type: text/csv`` or ``application/octet-stream``,
    or ``multipart/form-data`` with the file in the field ``file``), as ``POST /v1/calibrations``.

    Spreadsheet exports are read as saved: Excel's ``sep=;`` first line states the separator, or it
    and the decimal mark are detected (or stated); a BOM, CRLF line ends, blank lines and empty
    columns at the end are ignored; a file that is not UTF-8 is read as Windows-1252 (Latin-1); units
    in the header (``speed [mm/s]``, ``load (mN)``, ``speed_mm_s``, ``relative humidity [%]``,
    ``temperature [°C]``) are converted to SI. The report's ``intake`` says which dialect and
    encoding were used, how each column was read, what each text column became (groups) and what is
    fitted; ``POST /v1/calibrations/csv/intake`` says it before any fit. Problems name the file's line
    and the column's letter, as the spreadsheet shows them.
    """
    dataset, intake, fixed_values = await _read_upload(request, settings, options)
    names = [str(name) for name in fit_parameters]
    if "folds" not in request.query_params:
        folds = default_folds(dataset.n_points)
    _check(dataset, names, folds, query=True, intake=intake)
    intake.fitting = fitting_statement(dataset, names)
    record = {"rows": dataset.n_points, "columns": _columns_of(dataset),
              "factors": sorted(dataset.factors), "fixed": fixed_values,
              "fit_parameters": names, "folds": folds, "convention": str(convention),
              "intake": intake.to_dict()}
    return _submit(jobs, store, record, dataset, names, folds, str(convention), intake.to_dict())


@router.post("/csv/intake", operation_id="read_calibration_csv", response_model=CsvReading,
             responses=problem_responses(), openapi_extra=_CSV_BODY)
async def read_calibration_csv(
    request: Request, settings: SettingsDep, options: Annotated[CsvOptions, Depends()],
    fit_parameters: Annotated[list[FittableParameterName], Query(  # type: ignore[valid-type]
        description="Declared parameters the calibration would fit (repeatable): the intake's fitting "
                    "says what that means.")] = [],  # noqa: B006
) -> CsvReading:
    """Read an uploaded CSV file as ``POST /v1/calibrations/csv`` would, without fitting or storing it.

    The answer says how it was read (separator, decimal mark, encoding, what was ignored, each unit
    conversion, each column's name in SI, what each text column became, the factors, what the
    calibration would fit): check it, then submit the same file with the same query parameters to
    calibrate. Bad files get the same problems as the calibration route.
    """
    dataset, intake, fixed_values = await _read_upload(request, settings, options)
    names = [str(name) for name in fit_parameters]
    try:  # the values the calibration would refuse, refused here with its words
        check_plausible(dataset)
    except DataError as exc:
        raise data_problem(intake.locate(exc.errors), data_pointer=None) from None
    try:
        check_fit_parameters(dataset, names)
    except ValueError as exc:
        raise validation_problem([{"parameter": "fit_parameters", "detail": str(exc)}]) from None
    intake.fitting = fitting_statement(dataset, names)
    return CsvReading(rows=dataset.n_points, columns=_columns_of(dataset),
                      factors=sorted(dataset.factors), fixed=fixed_values, intake=intake.to_dict())


_CalibrationsLimit = page_limit("calibrations")


@router.get("", operation_id="list_calibrations", response_model=CalibrationList, responses={
    200: {"description": "A page of the stored calibrations the caller sees.",
          "links": calibration_links("$response.body#/calibrations/0", "the first calibration listed")},
    **problem_responses()})
def list_calibrations(request: Request, store: StoreDep, limit: _CalibrationsLimit = DEFAULT_PAGE_LIMIT,
                      page_token: PageToken = None) -> JSONResponse:
    """The stored calibrations the caller sees (with API keys: its key's, or all for the admin key),
    newest first, summarized; ``url`` gives the full report.

    ``limit`` per page; ``next_url`` fetches the next page.
    """
    rows = store.list_models(KIND, limit + 1, page_start(page_token))
    page, next_url = page_of(request, rows, limit)
    return JSONResponse({"calibrations": [calibration_summary(row) for row in page], "next_url": next_url})



@router.delete("/{calibration_id}", operation_id="delete_calibration", status_code=204,
               response_class=Response, responses=problem_responses(404))
def delete_calibration_route(calibration_id: str, store: StoreDep) -> Response:
    """Delete a stored calibration: its report, model and plots (the key that created it, or the admin key).

    The model ``calibrated:<id>`` is then gone from every list, from UM-Bridge and from every request
    that names it (404).
    """
    delete_calibration(store, calibration_id)
    return Response(status_code=204)


@router.get("/{calibration_id}", operation_id="get_calibration", response_model=CalibrationResult,
            responses={200: {"description": "The calibration's report.", "links": {
                name: link for name, link in calibration_links("$response.body#", "this calibration").items()
                if name != "GetCalibration"}}, **problem_responses(404)})
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
    plots = sorted(name for name in stored.arrays if not name.startswith(DATA_PREFIX))
    if plot_name not in plots:
        raise ProblemError(404, f"Calibration {calibration_id} has no plot {plot_name!r}; it has "
                                f"{', '.join(plots) or 'none'}.")
    return Response(stored.arrays[plot_name].tobytes(), media_type="image/png")
